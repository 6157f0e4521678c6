"""The simulator's kernels compiled ahead of time (``setup.py``, ``delaykit._native``): built by the set-up, equal in
every mode, and ``simulate``/``simulate_many`` then import no numba at all.

The reference is numba's compilation of the same source (:func:`delaykit._native.load` in mode ``"numba"``: what the
package ran before the extensions existed, and what it falls back to without them); the plain-Python mode is the
third.  The kernels' own accuracy is checked against independent oracles elsewhere (test_simulation.py,
test_loop_simulation.py, test_sampled_batch.py against SciPy's ``expm`` and a dense evaluation).  No timing is
asserted here: ``benchmarks/bench_native.py`` and ``benchmarks/bench_startup.py --first-calls`` measure.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from delaykit import AltitudeLoop, _native
from delaykit.models import Controller, Loop
from delaykit.simulate import _jit, _layout, simulate_many
from delaykit.simulate import simulation as S
from test_kernel_modes import run

PKG = "delaykit.simulate"
KERNELS = ("_poly", "_taylor", "_kernel", "_sampled_batch")
PID = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(2.0, 0.8, 0.2, 0.05), delay=0.25, umin=-0.5, umax=2.0)
# representative loops, short enough for the interpreter: (loop, load, t_end)
LOOPS = {
    "paper P": (AltitudeLoop(kp=1.31, delay=0.368), None, 10.0),
    "paper PV, true velocity (neutral)": (AltitudeLoop(kp=1.0, delay=0.37, kv=0.3), None, 6.0),
    "PID with limits": (PID, None, 8.0),
    "paper P, sampled": (AltitudeLoop(kp=1.31, delay=0.368, period=0.065), None, 6.0),
    "PI, tiny delay (read from the piece itself)": (Loop("1/(s+1)", Controller.pi(20.0, 1.0), delay=1e-6), None, 3.0),
}


@pytest.fixture(scope="module")
def kernels():
    return {mode: _native.load(PKG, "_kernel", mode) for mode in _native.MODES}


def close(a, b, rtol=1e-12):
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape
    assert np.array_equal(np.isnan(a), np.isnan(b))
    ok = ~np.isnan(b)
    assert np.all(np.abs(a[ok] - b[ok]) <= rtol * np.maximum(1.0, np.abs(b[ok])))


def test_the_set_up_builds_the_simulators_kernels_and_the_simulator_uses_them():
    # `make` (pip install -e .) compiles them; without a C compiler they would be numba's copies, and this fails
    for name in KERNELS:
        assert _native.built(PKG, name), f"the Cython extension of {name} is not built (or is stale): run `make`"
    assert _jit.kernel(compiled=True).COMPILED
    assert not _native.load(PKG, "_kernel", "numba").COMPILED and not _jit.kernel(compiled=False).COMPILED


@pytest.mark.parametrize("name", LOOPS)
def test_one_run_gives_numbas_numbers_compiled_by_cython_and_interpreted(name, kernels):
    loop, dist, t_end = LOOPS[name]
    ref = run(kernels["numba"], loop, dist, t_end)  # (metrics row, y pieces, u pieces, samples of y)
    assert ref[0][_layout.OUT["status"]] == _layout.STATUS_OK
    for mode in ("cython", "python"):
        got = run(kernels[mode], loop, dist, t_end)
        close(got[0], ref[0])
        for g, r in zip(got[1] + got[2], ref[1] + ref[2]):  # the same pieces: their starts and polynomials
            close(g, r)
        close(got[3], ref[3])


def _rows(loop, **sweep):
    """The batch kernels' parameter rows of a sweep, as simulate_many builds them."""
    seen = {}
    real = S._batch

    def grab(sweep):
        seen["pars"] = sweep.rows()
        return real(sweep)

    S._batch = grab
    try:
        simulate_many(loop, t_end=6.0, **sweep)
    finally:
        S._batch = real
    return np.ascontiguousarray(seen["pars"])


def test_a_batch_gives_numbas_numbers_in_every_mode_and_on_any_number_of_threads():
    delays = np.array([0.2, 0.3, 0.368, 0.45, 0.5, 0.62])
    taylor = _rows(PID, delay=delays, kp=np.linspace(1.0, 3.0, delays.size))
    sampled = _rows(AltitudeLoop(kp=1.31, delay=0.3, period=0.065), delay=delays)
    assert not S._event_stepped(taylor).any() and S._event_stepped(sampled).all()
    for name, pars in (("_kernel", taylor), ("_sampled_batch", sampled)):
        mods = {mode: _native.load(PKG, name, mode) for mode in _native.MODES}
        args = (pars, 4096) if name == "_kernel" else (pars,)
        ref = mods["numba"].run_batch(*args, 1, 1)
        assert np.all(ref[:, _layout.OUT["status"]] == _layout.STATUS_OK)
        for mode in ("cython", "python"):
            close(mods[mode].run_batch(*args, 1, 1), ref)
        # the rows split into chunks over work sets run in parallel: the same numbers, bit for bit
        for nchunks, nsets in ((6, 2), (5, 3), (4, 8)):
            np.testing.assert_array_equal(mods["cython"].run_batch(*args, nchunks, nsets), mods["cython"].run_batch(
                *args, 1, 1))


def test_a_sweep_given_compactly_runs_its_rows_written_out_in_every_mode():
    # run_sweep (the shared row and the columns that differ, what simulate_many passes) against run_batch on the
    # same rows written out: bit for bit in each mode, on any chunking (uneven ones included) and number of sets
    rng = np.random.default_rng(5)
    n = 7
    sweep = S._sweep(S.as_loop(PID), n, {"kp": rng.uniform(1.0, 3.0, n), "delay": rng.uniform(0.1, 0.5, n),
                                         "step": np.ones(n)}, 6.0, 0.02)
    pars = sweep.rows()
    cols, vals = sweep.compact()
    assert 0 < cols.size < 20  # the gains' entries and the delay, not the 440 columns of a row
    for mode in _native.MODES:
        k = _native.load(PKG, "_kernel", mode)
        ref = k.run_batch(pars, 4096, 1, 1)
        assert np.all(ref[:, _layout.OUT["status"]] == _layout.STATUS_OK), mode
        for nchunks, nsets in ((1, 1), (3, 1), (6, 2), (4, 3)) if mode == "cython" else ((3, 1),):
            np.testing.assert_array_equal(k.run_sweep(sweep.row, cols, vals, 4096, nchunks, nsets), ref,
                                          err_msg=f"{mode} {nchunks} chunks {nsets} sets")


def test_the_chunks_of_the_work_sets_cover_every_row_once_in_every_mode():
    # the chunk bounds both batch kernels take (_kernel._chunk): over a set's k = 0 .. nchunks - 1, the sets' chunks
    # partition the rows, in turn (chunk c to set c % nsets), including more chunks or sets than rows
    for mode in _native.MODES:
        chunk = _native.load(PKG, "_kernel", mode)._chunk
        for m, nchunks, nsets in ((10, 3, 2), (7, 7, 3), (2, 5, 2), (0, 1, 1), (10_000, 16, 2), (13, 4, 4)):
            seen = np.zeros(m, dtype=int)
            for s in range(nsets):
                for k in range(nchunks):
                    lo, hi = chunk(m, nchunks, nsets, s, k)
                    assert 0 <= lo <= hi <= m
                    seen[lo:hi] += 1
                    c = s + k * nsets  # the chunk: rows c m / nchunks to (c + 1) m / nchunks, rounded down
                    assert (lo, hi) == ((c * m // nchunks, (c + 1) * m // nchunks) if c < nchunks else (m, m))
            assert np.all(seen == 1), (mode, m, nchunks, nsets)


def test_a_small_batch_runs_on_one_thread_and_a_large_one_on_every_core():
    # waking a second thread costs more than a few runs: a batch gets a thread per _ROWS_PER_THREAD loops, up to
    # the cores the kernel may use (OMP_NUM_THREADS, the affinity mask, or numba's threads)
    kern = _jit.kernel(compiled=True)
    cores = S._cores(kern)
    assert S._threads(kern, 1) == S._threads(kern, 2 * S._ROWS_PER_THREAD - 1) == 1
    assert S._threads(kern, 2 * S._ROWS_PER_THREAD) == min(2, cores)
    assert S._threads(kern, 10_000) == cores >= 1


def test_a_compact_sweep_holds_the_rows_of_each_loop_alone():
    # the sweep's rows against each variant's own row built whole (param_row of the loop with that loop's gains,
    # delay, limits and step): the same numbers, and its compact form and single rows give those same rows
    rng = np.random.default_rng(3)
    n = 5
    kp, ki, td, vmax = rng.uniform(1, 3, n), rng.uniform(0.2, 1, n), rng.uniform(0.1, 0.5, n), rng.uniform(1, 3, n)
    step = rng.uniform(0.5, 2.0, n)
    sweep = S._sweep(S.as_loop(PID), n, {"kp": kp, "ki": ki, "delay": td, "vmax": vmax, "step": step}, 6.0, 0.02)
    rows = sweep.rows()
    for i in range(n):
        loop = S.as_loop(PID.replace(controller=PID.controller.replace(kp=kp[i], ki=ki[i]), delay=td[i],
                                     umin=-vmax[i], umax=vmax[i]))
        alone = _layout.param_row(loop, _layout.loop_matrices(loop), step=step[i], slope=0.0, norm=step[i],
                                  t_end=6.0, band=0.02, dist=None)
        np.testing.assert_array_equal(rows[i], alone)
        np.testing.assert_array_equal(sweep.one(i), rows[i])
    cols, vals = sweep.compact()
    again = np.repeat(sweep.row[None, :], n, axis=0)
    again[:, cols] = vals
    np.testing.assert_array_equal(again, rows)
    np.testing.assert_array_equal(S._Sweep.of_rows(rows).rows(), rows)


def _python(code: str) -> dict:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    env.pop("DELAYKIT_KERNELS", None)
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                         timeout=600, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_simulate_and_simulate_many_import_no_numba():
    got = _python("""
        import json, sys
        import numpy as np
        import delaykit as dk
        m = dk.simulate_many(dk.AltitudeLoop(kp=1.31, delay=0.3), delay=np.array([0.26, 0.325, 0.364]))
        s = dk.simulate_many(dk.AltitudeLoop(kp=1.31, delay=0.3, period=0.065), delay=np.array([0.26, 0.325]))
        r = dk.simulate(dk.AltitudeLoop(kp=1.31, delay=0.368), t_end=30.0)
        print(json.dumps({"numba": "numba" in sys.modules, "overshoot": m.overshoot.tolist(),
                          "sampled": s.overshoot.tolist(), "single": r.metrics.overshoot}))
    """)
    assert got["numba"] is False
    # the same numbers as in this process (where the kernels may be any mode the tests loaded)
    m = simulate_many(AltitudeLoop(kp=1.31, delay=0.3), delay=np.array([0.26, 0.325, 0.364]))
    close(got["overshoot"], m.overshoot)
    # Table 1 of the paper (Armah & Yi): 0 %, 0.398 % and 2.038 % at 4, 5 and 5.6 sample periods of 0.065 s
    close(np.round(got["overshoot"], 3), [0.0, 0.398, 2.038])
