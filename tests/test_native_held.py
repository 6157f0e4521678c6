"""The kernels of held-input stepping compiled ahead of time (``models/_expmkernel.py``,
``simulate/_discretekernel.py``, ``simulate/_varyingkernel.py``): built by the set-up, the same numbers in every mode,
and the one matrix exponential (:func:`delaykit.models.hold.hold_matrices`) right against SciPy's.

"The same numbers" is against numba's compilation of the same source (:func:`delaykit._native.load` in mode
``"numba"``: what the package ran before these extensions existed, and what it falls back to without them); the
exponential itself is checked against an independent computation, :func:`scipy.linalg.expm` (a Pade approximant,
another method), and closed forms.  No timing is asserted: ``benchmarks/bench_native.py`` measures.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from scipy.linalg import expm as scipy_expm

from delaykit import _native
from delaykit.models import Controller, Loop
from delaykit.models.hold import STIFF_NORM, hold_matrices
from delaykit.models.transfer import TransferFunction
from delaykit.simulate import discrete, varying

KERNELS = [("delaykit.models", "_expmkernel"), ("delaykit.simulate", "_discretekernel"),
           ("delaykit.simulate", "_varyingkernel")]
PLANTS = ["1/s", "1/(2*s+1)", "3/((s+1)*(0.5*s+1))", "(s+2)/(s*(0.05*s+1)*(0.3*s+1))", "1/(s^2+0.4*s+4)"]


def modes(package, name):
    return {mode: _native.load(package, name, mode) for mode in _native.MODES}


def close(a, b, rtol=1e-12):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape
    assert np.all(np.abs(a - b) <= rtol * np.maximum(1.0, np.abs(b))), np.max(np.abs(a - b))


def realisation(plant):
    A, B, C, D = TransferFunction.parse(plant).state_space()
    n = len(B)
    return (np.ascontiguousarray(np.reshape(A, (n, n)), dtype=float), np.ascontiguousarray(B, dtype=float).ravel(),
            np.ascontiguousarray(C, dtype=float).ravel(), float(D))


@pytest.mark.parametrize("package,name", KERNELS)
def test_the_set_up_builds_the_kernel_and_its_interface_uses_it(package, name):
    assert _native.built(package, name), f"the Cython extension of {name} is not built (or is stale): run `make`"
    assert not _native.load(package, name, "numba").COMPILED and not _native.load(package, name, "python").COMPILED
    assert discrete.DK.COMPILED and varying.VK.COMPILED


def test_a_kernel_calls_the_exponential_of_its_own_mode():
    # numba's copy must call numba's exponential (numba code cannot call the extension), Python's Python's
    for mode in ("numba", "python"):
        for name in ("_discretekernel", "_varyingkernel", "_sampled_batch"):
            k = _native.load("delaykit.simulate", name, mode)
            assert k.expm_into is _native.load("delaykit.models", "_expmkernel", mode).expm_into


@pytest.mark.parametrize("mode", _native.MODES)
def test_the_compiled_exponential_is_scipys_in_every_mode(mode):
    ek = _native.load("delaykit.models", "_expmkernel", mode)
    rng = np.random.default_rng(24)
    for n in (1, 2, 3, 5, 8):
        for scale in (1e-3, 0.3, 1.0, 7.0, 60.0):
            M = rng.normal(size=(n, n)) * scale / math.sqrt(n)
            want = scipy_expm(M)
            # both methods are accurate to rounding amplified by the squarings (about 1e-16 * ||M||): so 1e-12 here
            assert np.max(np.abs(ek.expm(M) - want)) <= 1e-12 * max(1.0, np.max(np.abs(want))) * max(1.0, scale)
    # closed forms: a rotation (exp of a skew matrix) and a nilpotent matrix (I + N, exactly)
    th = 2.5
    close(ek.expm(np.array([[0.0, th], [-th, 0.0]])), [[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]],
          rtol=1e-14)
    assert ek.expm(np.array([[0.0, 1.0], [0.0, 0.0]])).tolist() == [[1.0, 1.0], [0.0, 1.0]]


@pytest.mark.parametrize("mode", _native.MODES)
def test_the_exponential_reports_its_remainder_and_keeps_its_argument(mode):
    # expm_into returns the bound of its series' remainder (relative): at most 2^-56 / 0.6 where the series was
    # cut, 0 where it ended exactly (a nilpotent matrix); it leaves its argument as it was (the sampled loops' fast
    # path reads the bound; the kernels refill their argument anyway)
    ek = _native.load("delaykit.models", "_expmkernel", mode)
    rng = np.random.default_rng(21)
    for n in (1, 2, 4, 7):
        for scale in (1e-3, 0.4, 9.0):
            A = rng.normal(size=(n, n)) * scale
            A0 = A.copy()
            E, T, W = np.empty((3, n, n))
            rem = ek.expm_into(A, E, T, W)
            assert np.array_equal(A, A0)
            assert 0.0 < rem <= 2.0 ** -56 / 0.6
            want = scipy_expm(A0)  # another method (Pade)
            assert np.max(np.abs(E - want)) <= 1e-12 * max(1.0, np.max(np.abs(want))) * max(1.0, scale)
    E, T, W = np.empty((3, 3, 3))
    N = np.array([[0.0, 2.0, 1.0], [0.0, 0.0, 3.0], [0.0, 0.0, 0.0]])  # N^3 = 0: exp(N) = I + N + N^2 / 2
    assert ek.expm_into(N, E, T, W) == 0.0
    assert E.tolist() == (np.eye(3) + N + N @ N / 2).tolist()
    # a norm beyond half the largest double (the scaling's exponent must not overflow): exp(1e308) is not finite,
    # the zero row stays the identity's (identification's trial plants reach this: a status, not garbage)
    with np.errstate(over="ignore", invalid="ignore"):  # (NumPy's scalars warn in Python)
        ek.expm_into(np.array([[1e308, 0.0], [0.0, 0.0]]), E[:2, :2], T[:2, :2], W[:2, :2])
    assert not np.isfinite(E[0, 0]) and E[1, :2].tolist() == [0.0, 1.0]
    # an infinite entry: NaN, and an infinite bound (not an endless scaling loop)
    assert ek.expm_into(np.array([[math.inf, 0.0], [0.0, 1.0]]), E[:2, :2], T[:2, :2], W[:2, :2]) == math.inf
    assert np.all(np.isnan(E[:2, :2]))


@pytest.mark.parametrize("plant", PLANTS)
def test_hold_matrices_are_scipys_exponential_of_the_augmented_matrix(plant):
    A, B, _, _ = realisation(plant)
    n = A.shape[0]
    G = np.column_stack([B, -2.0 * B, np.ones(n)])
    for tau in (1e-4, 0.065, 0.37, 3.0, 40.0):
        E, J = hold_matrices(A, G, tau)
        M = np.zeros((n + 3, n + 3))
        M[:n, :n], M[:n, n:] = A, G
        X = scipy_expm(M * tau)  # the definition: one exponential of the augmented matrix, by another method
        close(E, X[:n, :n], rtol=1e-12)
        close(J, X[:n, n:], rtol=1e-12)
        e, j = hold_matrices(A, B, tau)  # a vector G gives a vector
        e1, j1 = hold_matrices(A, B[:, None], tau)
        assert j.shape == (n,) and np.array_equal(j, j1[:, 0]) and np.array_equal(e, e1)


def test_hold_matrices_of_a_first_order_lag_are_its_closed_form():
    # x' = -a x + b u: exp(-a t) and (b / a)(1 - exp(-a t))
    for a, t in ((2.0, 0.3), (0.01, 5.0), (400.0, 0.1)):  # the last beyond STIFF_NORM: SciPy's branch
        E, J = hold_matrices(np.array([[-a]]), np.array([[3.0]]), t)
        assert E[0, 0] == pytest.approx(math.exp(-a * t), rel=1e-13)
        assert J[0, 0] == pytest.approx(3.0 / a * -math.expm1(-a * t), rel=1e-12)
    assert 400.0 * 0.1 <= STIFF_NORM < 400.0 * 5.0


@pytest.fixture(scope="module")
def dk():
    return modes("delaykit.simulate", "_discretekernel")


@pytest.mark.parametrize("plant", PLANTS)
def test_the_discrete_kernels_give_numbas_numbers_compiled_by_cython_and_interpreted(plant, dk):
    A, B, C, D = realisation(plant)
    n = A.shape[0]
    rng = np.random.default_rng(7)
    drive = rng.normal(size=240)
    starts = np.array([0, 100, 170, 240], dtype=np.int64)
    lo, hi = np.array([-1.0, -np.inf, -0.5]), np.array([1.0, np.inf, 2.0])
    t = np.cumsum(rng.uniform(0.03, 0.12, drive.size))
    got = {}
    for mode, k in dk.items():
        res = {}
        for h, f in ((0.065, 0.045), (0.1, 0.0)):
            phi, ge, gl = k.held_arrays(A, B, h, f)
            res[("held", h)] = (phi, ge, gl)
            ca, cb = (C @ A, float(C @ B)) if n else (np.zeros(0), 0.0)
            for closed in (False, True):
                m = 5 if f else 3
                res[("run", h, closed)] = k.run(phi, ge, gl, C, D, ca, cb, m, f > 0, drive, closed, 0.8, 0.1, -1.0, 1.0)
                out = [np.zeros(drive.size) for _ in range(4)]
                k.run_logs(phi, ge, gl, C, D, ca, cb, m, f > 0, drive, starts, closed, 0.8, 0.1, lo, hi, True, *out)
                res[("logs", h, closed)] = out
        out = [np.zeros(drive.size) for _ in range(4)]
        k.run_at_logs(A, B, C, D, C @ A, float(C @ B), 0.37, 1e-12, t, drive, starts, True, *out)
        res["at"] = out
        got[mode] = res
    ref = got["numba"]
    assert np.ptp(ref[("run", 0.065, True)][0]) > 0.1  # the cases do move
    for mode in ("cython", "python"):
        for key, want in ref.items():
            for a, b in zip(got[mode][key], want):
                close(a, b)


def test_the_varying_kernel_gives_numbas_numbers_compiled_by_cython_and_interpreted(monkeypatch):
    loops = [Loop("1/(s*(0.05*s+1))", c, umin=-1, umax=1, period=0.065)
             for c in (Controller.p(1.31), Controller.pi(0.8, 0.15), Controller.pd(2.0, 0.1, 0.02))]
    got = {}
    for mode, vk in modes("delaykit.simulate", "_varyingkernel").items():
        monkeypatch.setattr(varying, "VK", vk)
        got[mode] = [varying.simulate_varying(lp, varying.Jitter(0.3, "uniform", spread=0.1, seed=3), t_end=8.0)
                     for lp in loops]
    for mode in ("cython", "python"):
        for r, want in zip(got[mode], got["numba"]):
            for a, b in ((r.t, want.t), (r.output, want.output), (r.applied_input, want.applied_input),
                         (r.commands, want.commands)):
                close(a, b)
    assert abs(got["cython"][0].output[-1] - 1.0) < 1e-2  # a P loop on an integrator settles on the step


def test_the_discrete_and_varying_simulators_load_no_numba():
    code = textwrap.dedent("""
        import sys
        import numpy as np
        from delaykit.models import Controller, Loop
        from delaykit.models.transfer import TransferFunction
        from delaykit.simulate.discrete import held_delay_model, held_response, held_response_at
        from delaykit.simulate.varying import Jitter, simulate_varying
        m = held_delay_model(TransferFunction.parse("1/(2*s+1)"), period=0.5, delay=0.75)
        held_response(m, np.ones(8))
        held_response_at(TransferFunction.parse("1/s"), np.array([0.0, 0.4, 1.1]), np.ones(3), delay=0.5)
        simulate_varying(Loop("1/s", Controller.p(1.31), period=0.065), Jitter(0.3, "uniform", spread=0.1, seed=3),
                         t_end=2.0)
        print("@@", "numba" in sys.modules)
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "DELAYKIT_KERNELS": ""})
    assert run.returncode == 0, run.stderr
    assert run.stdout.rpartition("@@")[2].split() == ["False"]


def test_an_extension_whose_cimported_kernel_is_missing_counts_as_not_built(monkeypatch):
    # setup.py builds each extension optionally: where the exponential's failed, the simulators' cannot load
    import importlib

    real = importlib.import_module

    def failing(name, *args):
        if name == "delaykit.simulate._discretekernel":
            raise ImportError("delaykit.models._expmkernel has no C function expm_into")
        return real(name, *args)

    monkeypatch.setattr(importlib, "import_module", failing)
    assert not _native.built("delaykit.simulate", "_discretekernel")
