"""Identification's kernels compiled ahead of time (``identify/_fitkernel.py``, ``_noisekernel.py``; see
``delaykit._native`` and docs/guide/first-calls.md): built by the set-up, the fits run on them, and every mode
(Cython's extension, numba's compilation of the same source, the interpreter) gives the same numbers.

The reference for "the same numbers" is numba's compilation of the source: what the package ran before the
extension existed (the loops were moved unchanged), and what it falls back to without one.  Where a kernel has a
closed form or an independent dense computation, the test checks it against that too.  No timing is asserted
here: ``benchmarks/bench_startup.py --first-calls`` and ``benchmarks/bench_identify.py`` measure.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from delaykit import _native
from delaykit.identify import _fit as F
from delaykit.identify import noise as N
from delaykit.identify import structures as S
from delaykit.identify.identification import identify
from delaykit.identify.iodata import read_experiment
from delaykit.identify.structures import STRUCTURES

from shared_data import data_path

LINEAR = [n for n, st in STRUCTURES.items() if not st.limited]  # (ipdt_accel: test_identify_accel.py)

PKG = "delaykit.identify"
# the real logs, read from ../shared/data (tests/shared_data.py: the tests on them skip, saying why, where absent);
# the kernels' agreement does not depend on which part of a log they see, so the PX4 flight is the full log
HEATER = ("tclab", "step_test.csv")
PX4 = ("px4-altitude", "HAYDEN_01.csv")
# the PX4 flights' outer loop (data README): a sampled P law on the altitude with limits
PX4_LAW = F._Law(0.95, 0.0, -1.0, 3.0, 0.02)


@pytest.fixture(scope="module")
def fit_kernels():
    return {mode: _native.load(PKG, "_fitkernel", mode) for mode in _native.MODES}


def close(a, b, rtol=1e-12):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape
    assert np.all(np.abs(a - b) <= rtol * np.maximum(1.0, np.abs(b))), np.max(np.abs(a - b))


def test_the_set_up_builds_the_identification_kernels_and_the_fits_use_them():
    # `make` (pip install -e .) compiles them; without a C compiler they would be numba's copies, and this fails
    for name in ("_fitkernel", "_noisekernel"):
        assert _native.built(PKG, name), f"the Cython extension of {name} is not built (or is stale): run `make`"
    assert F.FK.COMPILED and S._FK is F.FK
    assert not _native.load(PKG, "_fitkernel", "numba").COMPILED
    assert not _native.load(PKG, "_noisekernel", "python").COMPILED


def _problem(case: str, name: str) -> F._Problem:
    """A fit's problem: the heater's open-loop log, or a PX4 flight in closed loop with its rate and an offset."""
    st = STRUCTURES[name]
    if case == "heater":
        e = read_experiment(data_path(*HEATER), outputs=["z"], input="u", u_before=0.0)
        prep = F._prepare(e, ("z",), None, None, fresh_only=False)
        return F._Problem(st, [prep], None, {"z": 1.0}, False)
    e = read_experiment(data_path(*PX4), outputs=["z", "vz"], reference="z_ref")
    prep = F._prepare(e, ("z",), "vz", PX4_LAW, fresh_only=True)
    return F._Problem(st, [prep], PX4_LAW, {"z": 0.01, "vz": 0.05}, True)


CASES = [("heater", n) for n in LINEAR] + [("px4", "ipdt"), ("px4", "ipdt_speed"), ("px4", "ipdt_lag")]


@pytest.mark.parametrize("case,name", CASES)
def test_each_fit_kernel_gives_numbas_numbers_compiled_by_cython_and_interpreted(case, name, fit_kernels):
    prob = _problem(case, name)
    st = prob.st
    p = F._guesses(st, prob.preps, prob.law)[1]  # a point off the optimum: residuals and slopes of every size
    p[-1] = 2.5 * prob.h + 0.3 * prob.h  # a delay with a fraction of a period (both held-input matrices)
    z = prob.to_fit(p)
    lb, ub = prob.bounds()
    lb[-1], ub[-1] = 0.0, F._delay_bound(prob.preps)
    data = prob._data()
    got = {}
    for mode, fk in fit_kernels.items():
        out_p, out_z, r0, col = (np.empty(prob.size) for _ in range(4))
        J = np.empty((prob.size, st.size))
        status = (fk.evaluate(st.code, p, *data, out_p), fk.evaluate_fit(st.code, z, prob._pos8, prob._rw, *data, out_z))
        r0[:] = out_z
        status += (fk.jacobian_fit(st.code, z, prob._pos8, lb, ub, r0, prob._rw, *data, col, J),)
        A, g = fk.normal_equations(J, r0)
        got[mode] = {"status": status, "realise": fk.realise(st.code, p), "raw": out_p, "weighted": out_z, "J": J,
                     "A": A, "g": g, "dot": fk.dot(r0, r0)}
    ref = got["numba"]
    assert ref["status"] == (0, 0, 0) and np.all(np.isfinite(ref["J"])) and np.abs(ref["J"]).max() > 0
    for mode in ("cython", "python"):
        g = got[mode]
        assert g["status"] == ref["status"]
        for a, b in zip(g["realise"], ref["realise"]):
            assert np.array_equal(a, b)
        for key in ("raw", "weighted", "J", "A", "g", "dot"):
            close(g[key], ref[key])
    # (the residuals themselves are checked against the public simulators and np.linalg.lstsq in
    # test_identification.py's test_compiled_residuals_equal_the_public_simulators)


@pytest.mark.parametrize("name", LINEAR)
def test_the_compiled_realisation_is_the_structures_transfer_function(name, fit_kernels):
    # independent: C (sI - A)^-1 B against the structure's polynomial ratio, at a few points of the plane
    st = STRUCTURES[name]
    p = {"ipdt": [0.8, 0.3], "ipdt_lag": [0.9, 0.25, 0.2], "ipdt_speed": [0.79, 1.5, 2.3, 3.8, 0.1],
         "fopdt": [0.7, 146.6, 16.6], "sopdt": [0.7, 141.4, 19.6, 0.0]}[name]
    tf = st.plant(p)
    for mode, fk in fit_kernels.items():
        A, B, C = fk.realise(st.code, np.array(p, float))
        for s in (0.3j, 1.0 + 2.0j, -0.05 + 0.7j):
            h = C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B)
            assert h == pytest.approx(np.polyval(tf.num, s) / np.polyval(tf.den, s), rel=1e-12), mode


@pytest.mark.parametrize("case,name", [("heater", "sopdt"), ("px4", "ipdt_speed")])
def test_a_trial_point_leaves_nothing_in_the_work_arrays_for_the_next(case, name, fit_kernels):
    # the kernels reuse one fit's work arrays from point to point: a point with a fractional delay (both
    # held-input vectors, a third-order or second-order state) followed by one of whole periods (no early
    # vector) must give what that point gives on fresh arrays, in every mode
    for mode, fk in fit_kernels.items():
        used, fresh = _problem(case, name), _problem(case, name)
        p = F._guesses(used.st, used.preps, used.law)[1]
        q = p.copy()
        p[-1] = 3.4 * used.h
        q[-1] = 2.0 * used.h
        out, ref = np.empty(used.size), np.empty(used.size)
        assert fk.evaluate(used.st.code, p, *used._data(), out) == fk.OK
        assert fk.evaluate(used.st.code, q, *used._data(), out) == fk.OK
        assert fk.evaluate(fresh.st.code, q, *fresh._data(), ref) == fk.OK
        assert np.array_equal(out, ref), mode
        # and the Jacobian, whose shifted points share the arrays with the point itself
        z = used.to_fit(q)
        lb, ub = used.bounds()
        J, Jf = np.empty((used.size, q.size)), np.empty((used.size, q.size))
        r0 = np.empty(used.size)
        fk.evaluate_fit(used.st.code, z, used._pos8, used._rw, *used._data(), r0)
        fk.jacobian_fit(used.st.code, used.to_fit(p), used._pos8, lb, ub, r0, used._rw, *used._data(),
                        np.empty(used.size), J)
        fk.jacobian_fit(used.st.code, z, used._pos8, lb, ub, r0, used._rw, *used._data(), np.empty(used.size), J)
        fk.jacobian_fit(fresh.st.code, z, fresh._pos8, lb, ub, r0, fresh._rw, *fresh._data(), np.empty(used.size),
                        Jf)
        assert np.array_equal(J, Jf), mode


def test_the_kernels_status_values_agree_in_every_mode(fit_kernels):
    prob = _problem("heater", "fopdt")
    data = prob._data()
    for mode, fk in fit_kernels.items():
        out = np.empty(prob.size)
        assert fk.evaluate(3, np.array([0.7, 146.6, -1.0]), *data, out) == fk.NEGATIVE, mode
        # a lag of 1e-9 s sampled every second: far too stiff for the compiled exponential (SciPy's takes it)
        assert fk.evaluate(3, np.array([0.7, 1e-9, 16.0]), *data, out) == fk.STIFF_PLANT, mode
        # a gain of 1e308 on a 50 % step: the simulated temperature overflows (NumPy's scalars warn in Python)
        with np.errstate(over="ignore", invalid="ignore"):
            status = fk.evaluate_fit(3, np.array([1e308, 0.0, 16.0]), prob._pos8, prob._rw, *data, out)
        assert status == fk.NONFINITE, mode
        assert fk.evaluate_fit(3, np.array([0.7, 5.0, 16.0]), prob._pos8, prob._rw, *data, out) == fk.OK, mode


def test_the_projection_leaves_residuals_orthogonal_to_the_nuisance_columns(fit_kernels):
    # least squares' property, independent of the kernel's formulas: the projected residuals have no component
    # along the columns projected out (a constant offset and the response to a held unit input)
    rng = np.random.default_rng(7)
    n = 50
    y, dy, uy, udy = (rng.normal(size=n) for _ in range(4))
    starts = np.array([0, n], np.int64)
    k0 = np.arange(n, dtype=np.int64)
    m0 = rng.normal(size=n)
    for mode, fk in fit_kernels.items():
        out = np.empty(n)
        fk.residual_blocks(y, dy, uy, udy, starts, k0, np.array([0, n], np.int64), m0, np.zeros(0, np.int64),
                           np.zeros(2, np.int64), np.zeros(0), 1.0, 1.0, True, True, out)
        assert abs(out.sum()) < 1e-10 and abs(out @ uy) < 1e-10, mode
        beta = np.linalg.lstsq(np.column_stack([uy, np.ones(n)]), m0 - y, rcond=None)[0]
        close(out, m0 - y - beta[0] * uy - beta[1], rtol=1e-10)


def test_the_vector_noise_kernel_is_a_backward_solve_of_the_whitening_matrix():
    # independent: X = L^-1 J for the block upper-triangular L with identity blocks and -phi_i' above them
    rng = np.random.default_rng(3)
    n, d, q, p = 30, 2, 3, 2
    J = rng.normal(size=(n, d, q))
    phi = 0.3 * rng.normal(size=(p, d, d))
    L = np.eye(n * d)
    for m in range(n):
        for i in range(p):
            if m + 1 + i < n:
                L[m * d:(m + 1) * d, (m + 1 + i) * d:(m + 2 + i) * d] = -phi[i].T
    dense = np.linalg.solve(L, J.reshape(n * d, q)).reshape(n, d, q)
    got = {mode: _native.load(PKG, "_noisekernel", mode).var_backward(J, phi) for mode in _native.MODES}
    for mode, X in got.items():
        close(X, dense, rtol=1e-12)
        close(X, got["numba"])


def test_identify_gives_the_same_model_with_the_kernels_compiled_by_numba(fit_kernels, monkeypatch):
    e = read_experiment(data_path(*HEATER), outputs=["z"], input="u", u_before=0.0)
    compiled = identify(e, model="fopdt", per_log=False).to_dict()
    monkeypatch.setattr(F, "FK", fit_kernels["numba"])
    monkeypatch.setattr(S, "_FK", fit_kernels["numba"])
    by_numba = identify(e, model="fopdt", per_log=False).to_dict()
    for key in ("params", "stderr"):
        close(list(compiled[key].values()), list(by_numba[key].values()))
    # the heater's published fit (docs/guide/identification.md, equal to an independent SciPy fit in
    # test_identification.py): K 0.698 degC/%, T 146.6 s, dead time 16.6 s
    assert compiled["params"]["gain"] == pytest.approx(0.6976, abs=5e-5)
    assert compiled["params"]["time_constant"] == pytest.approx(146.6, abs=0.05)
    assert compiled["params"]["delay"] == pytest.approx(16.6, abs=0.05)


@pytest.fixture(scope="module")
def identify_run():
    """What a fresh process that runs the command line's library call (``identify`` of the heater log) loaded."""
    heater = data_path(*HEATER)
    code = textwrap.dedent(f"""
        import sys
        from delaykit.identify.identification import identify
        from delaykit.identify.iodata import read_experiment
        m = identify(read_experiment({str(heater)!r}, outputs=["z"], input="u", u_before=0.0), model="auto")
        print("@@", m.model, *(name in sys.modules for name in ("numba", "scipy.stats", "scipy.signal",
                                                                  "delaykit.identify.estimation")))
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "DELAYKIT_KERNELS": ""})
    assert run.returncode == 0, run.stderr
    model, *loaded = run.stdout.rpartition("@@")[2].split()
    return model, dict(zip(("numba", "scipy.stats", "scipy.signal", "estimation"), [v == "True" for v in loaded]))


def test_identify_loads_neither_scipy_stats_nor_scipy_signal_nor_the_flight_estimators(identify_run):
    model, loaded = identify_run
    assert model == "sopdt"  # the heater's choice (test_identification.py)
    assert not loaded["scipy.stats"] and not loaded["scipy.signal"] and not loaded["estimation"], loaded


def test_identify_loads_no_numba(identify_run):
    # nothing is compiled at run time: the library call the command line makes runs on the extensions alone
    assert not identify_run[1]["numba"]


@pytest.mark.parametrize("order", [0, 1, 3, 8])
def test_the_noise_filters_give_scipys_numbers_in_every_mode(order):
    # reference: scipy.signal.lfilter, which the noise models called before (imported here, not by the package)
    from scipy.signal import lfilter

    rng = np.random.default_rng(order)
    coeffs = np.r_[1.0, 0.4 * rng.normal(size=order)]
    model = N.ARNoise(coeffs, 1.0, 300)
    for shape in ((300,), (300, 3), (1,)):
        x = rng.normal(size=shape)
        close(model.whiten(x), lfilter(coeffs, [1.0], x, axis=0))
        ref = lfilter([1.0], coeffs, x, axis=0)
        close(N._filter(np.eye(1, coeffs.size)[0], coeffs, x), ref)
        x2 = np.ascontiguousarray(x.reshape(x.shape[0], -1))
        for mode in _native.MODES:
            y = np.empty_like(x2)
            _native.load(PKG, "_noisekernel", mode).linear_filter(np.eye(1, coeffs.size)[0], coeffs, x2, y)
            close(y.reshape(x.shape), ref)
