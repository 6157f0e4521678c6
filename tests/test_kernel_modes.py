"""The simulator kernel's two modes, compiled (numba) and interpreted (the same source as plain Python).

The interpreted kernel is a separate module built from the same files (``delaykit.simulate._jit``), so both
modes run side by side here on the same parameter rows; the compiled kernel is the reference, and the two
must agree to rounding (1e-12) on every metric, every stored piece of the output and of the command.  The
command line's path (interpreted by default, compiled once a piece budget is spent) runs in subprocesses,
where whether numba was imported at all can be seen.  The compiled kernel itself is checked against the
independent oracles in test_simulation.py and test_loop_simulation.py.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from delaykit import AltitudeLoop, _native
from delaykit.models import Compensator, Controller, LoadStep, Loop, Samples
from delaykit.simulate import _jit, _layout
from delaykit.simulate._layout import loop_matrices as layout_of, param_row as _row
from delaykit.simulate.simulation import as_loop, simulate
from delaykit.models.signals import as_reference

SRC = Path(__file__).resolve().parents[1] / "src"

PID = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(2.0, 0.8, 0.2, 0.05), delay=0.25, umin=-0.5, umax=2.0)
LOOPS = {
    "paper P": (AltitudeLoop(kp=1.31, delay=0.368), None, 15.0),
    "paper PV, true velocity": (AltitudeLoop(kp=1.0, delay=0.37, kv=0.3), None, 15.0),
    "paper PV, filtered": (AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered"), None, 10.0),
    "paper P, sampled": (AltitudeLoop(kp=1.31, delay=0.368, period=0.065), None, 10.0),
    "PID, saturated": (PID, None, 15.0),
    "PID, output delay and a load": (PID.replace(delay=0.1, output_delay=0.15), LoadStep(-0.3, 6.0), 12.0),
    "PI, clamping anti-windup": (Loop("0.62/(150*s+1)", Controller.pi(8.0, 0.1, antiwindup="clamp"), delay=12.0,
                                      umin=0.0, umax=1.0), None, 600.0),
    "PI, back-calculation": (Loop("1/((s+1)*(0.5*s+1))", Controller.pi(2.0, 1.5, antiwindup="backcalc"),
                                  delay=0.2, umin=-1.0, umax=1.2), None, 20.0),
    "Smith predictor": (Loop("1/s", Compensator.smith("1/s", 0.37, closed_loop_time=0.1), delay=0.42, umin=-1.0,
                             umax=1.0), None, 5.0),
    "no delay at all": (Loop("1/((s+1)*(0.5*s+1))", Controller.pi(2.0, 1.0), delay=0.0, umin=-1.0, umax=1.5),
                        None, 10.0),
}


def run(kern, loop, dist, t_end, reference=None):
    """One run of a kernel module on a loop's parameter row: (metrics row, y pieces, u pieces)."""
    gen = as_loop(loop)
    ref = as_reference(1.0 if reference is None else reference)
    knots = ref.knots()
    row = _row(gen, layout_of(gen), step=float(knots[1][0]), slope=0.0, norm=ref.final_value(t_end), t_end=t_end,
               band=0.02, dist=dist)
    cap, nc = 4096, _layout.NC
    u = (np.empty(cap), np.empty(cap), np.zeros((cap, nc)), np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int8))
    y = (np.empty(cap), np.empty(cap), np.zeros((cap, nc)), np.zeros((cap, nc)), np.empty(cap, dtype=np.int8))
    out = np.empty(_layout.NOUT)
    t = np.linspace(0.0, t_end, 7)
    ez = np.empty(t.size)
    n = kern.run_one(row, *knots, cap, *u, *y, out, True, t, ez)
    nu = int(out[_layout.OUT["u_pieces"]])
    return out.copy(), (y[0][:n].copy(), y[2][:n].copy()), (u[0][:nu].copy(), u[2][:nu].copy()), ez.copy()


@pytest.mark.parametrize("name", list(LOOPS))
def test_interpreted_kernel_equals_the_compiled_one(name):
    loop, dist, t_end = LOOPS[name]
    comp = run(_jit.kernel(compiled=True), loop, dist, t_end)
    interp = run(_jit.kernel(compiled=False), loop, dist, t_end)
    (oc, (tyc, yc), (tuc, uc), ezc), (oi, (tyi, yi), (tui, ui), ezi) = comp, interp
    assert oc[_layout.OUT["status"]] == oi[_layout.OUT["status"]] == _layout.STATUS_OK
    # the same pieces, at the same times
    assert tyc.size == tyi.size and tuc.size == tui.size
    np.testing.assert_allclose(tyi, tyc, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tui, tuc, rtol=0, atol=1e-12)
    # the same polynomials, metrics and samples of y, to rounding
    np.testing.assert_allclose(yi, yc, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ui, uc, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ezi, ezc, rtol=0, atol=1e-12)
    keys = ("overshoot", "peak_time", "rise_time", "settling_time", "final_error", "truncation")
    for k in keys:
        i = _layout.OUT[k]
        assert np.isnan(oi[i]) == np.isnan(oc[i]), k
        if not np.isnan(oc[i]):
            assert abs(oi[i] - oc[i]) <= 1e-12, (k, oi[i], oc[i])


def test_interpreted_kernel_follows_a_sampled_reference():
    ref = Samples([0.0, 1.0, 2.0, 4.0], [0.0, 0.5, 0.5, 1.0])
    comp = run(_jit.kernel(compiled=True), PID, None, 8.0, reference=ref)
    interp = run(_jit.kernel(compiled=False), PID, None, 8.0, reference=ref)
    np.testing.assert_allclose(interp[1][1], comp[1][1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(interp[3], comp[3], rtol=0, atol=1e-12)


def test_the_interpreted_kernel_is_a_separate_module_of_the_same_source():
    kc, ki = _jit.kernel(compiled=True), _jit.kernel(compiled=False)
    # compiled: the extension module Cython built from the source (numba's copy of it where none was built)
    assert kc.__name__ in ("delaykit.simulate._kernel", "delaykit.simulate._kernel_numba")
    assert ki.__name__ == "delaykit.simulate._kernel_python"
    assert Path(kc.__file__).with_suffix("").name.split(".")[0] == Path(ki.__file__).stem == "_kernel"
    assert ki.COMPILED is False and type(ki.run_one).__name__ == "function"  # plain Python
    assert ki._horner is _native.load("delaykit.simulate", "_poly", "python").horner  # its helpers are interpreted too
    assert _jit.kernel(compiled=False) is ki  # built once


def test_long_pieces_agree_with_pieces_capped_at_hmax():
    """Pieces grow past 1/rate where the Taylor tail allows; the metrics must equal those of a run whose pieces
    are four times shorter (its own truncation is far smaller), to 1e-10."""
    kern = _jit.kernel(compiled=True)
    gen = as_loop(PID)
    ref = as_reference(1.0)
    knots = ref.knots()
    row = _row(gen, layout_of(gen), step=1.0, slope=0.0, norm=1.0, t_end=15.0, band=0.02, dist=None)
    fine = row.copy()
    fine[_layout.HEAD["hmax"]] /= 16.0  # grown at most 4 times: still a quarter of the original cap
    outs = []
    for r in (row, fine):
        cap, nc = 8192, _layout.NC
        u = (np.empty(cap), np.empty(cap), np.zeros((cap, nc)), np.empty(cap, dtype=np.int64),
             np.empty(cap, dtype=np.int8))
        y = (np.empty(cap), np.empty(cap), np.zeros((cap, nc)), np.zeros((cap, nc)), np.empty(cap, dtype=np.int8))
        out = np.empty(_layout.NOUT)
        n = kern.run_one(r, *knots, cap, *u, *y, out, True, np.empty(0), np.empty(0))
        lengths = y[1][:n]
        outs.append((out.copy(), lengths.max()))
    (o, longest), (of, _) = outs
    assert longest > 1.5 * row[_layout.HEAD["hmax"]]  # the rule did grow pieces
    for k in ("overshoot", "peak_time", "rise_time", "settling_time", "final_error"):
        i = _layout.OUT[k]
        assert abs(o[i] - of[i]) <= 1e-10, (k, o[i], of[i])  # (all defined: this loop overshoots and settles)


def metrics_list(m) -> list:
    return [m.overshoot, m.peak_time, m.rise_time, m.settling_time]


def _python(code: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    res = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                         check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_importing_delaykit_and_the_simulator_does_not_import_numba():
    got = _python("""
        import json, sys
        import delaykit, delaykit.simulate.simulation
        print(json.dumps({"numba": "numba" in sys.modules}))
    """)
    assert got == {"numba": False}


def test_interpreter_runs_a_short_simulation_without_numba():
    expected = simulate(AltitudeLoop(kp=1.31, delay=0.368)).metrics
    got = _python("""
        import json, sys
        from delaykit.simulate import _jit
        _jit.use_interpreter()
        from delaykit import AltitudeLoop, _native
        from delaykit.simulate.simulation import simulate
        m = simulate(AltitudeLoop(kp=1.31, delay=0.368)).metrics
        print(json.dumps({"numba": "numba" in sys.modules, "interpreting": _jit.interpreting(),
                          "m": [m.overshoot, m.peak_time, m.rise_time, m.settling_time]}))
    """)
    assert got["numba"] is False and got["interpreting"] is True
    assert None not in got["m"]
    np.testing.assert_allclose(got["m"], metrics_list(expected), rtol=0, atol=1e-12)


def test_a_run_past_the_piece_budget_is_redone_compiled():
    expected = simulate(PID, t_end=15.0).metrics
    got = _python("""
        import json, sys
        from delaykit.simulate import _jit
        _jit.use_interpreter()
        _jit.spend(1, _jit.PIECE_BUDGET - 20)  # leave 20 one-state pieces: 8 of this 4-state loop
        from delaykit.models import Controller, Loop
        from delaykit.simulate.simulation import simulate
        loop = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(2.0, 0.8, 0.2, 0.05), delay=0.25, umin=-0.5, umax=2.0)
        r = simulate(loop, t_end=15.0)
        m = r.metrics
        print(json.dumps({"numba": "numba" in sys.modules, "interpreting": _jit.interpreting(),
                          "compiled": _jit.kernel().__name__, "pieces": int(r.starts.size),
                          "m": [m.overshoot, m.peak_time, m.rise_time, m.settling_time]}))
    """)
    assert got["interpreting"] is False  # the compiled kernel took over, for good: the extension (no numba) ...
    assert got["compiled"] == _jit.kernel(compiled=True).__name__
    # ... or, where it was not built, numba's copy
    assert got["numba"] is (got["compiled"] == "delaykit.simulate._kernel_numba")
    assert got["pieces"] > 8
    assert None not in got["m"]
    np.testing.assert_allclose(got["m"], metrics_list(expected), rtol=0, atol=1e-12)


def test_budget_counts_pieces_by_the_loops_size():
    before = _jit._budget
    try:
        _jit._budget = float(_jit.PIECE_BUDGET)  # a fresh process's (another test in this worker may have spent it)
        _jit.use_interpreter()
        assert _jit.budget(1) == _jit.PIECE_BUDGET
        assert _jit.budget(4) < _jit.budget(2) < _jit.budget(1)  # bigger loops: fewer interpreted pieces
        _jit.spend(4, _jit.budget(4))
        assert _jit.budget(4) == 0 and not _jit.interpreting()
    finally:
        _jit.use_interpreter(False)
        _jit._budget = before
    assert _jit.budget(1) == 0  # the interpreter is off: every run compiled


def test_the_simulate_command_runs_one_loop_without_numba():
    # `delaykit simulate` of one short loop runs the interpreted kernel: numba is never imported, and the metrics
    # are the compiled kernel's (computed here, in this process, by the library)
    code = ("import sys\nfrom delaykit.cli.app import app\ntry:\n"
            "    app(['simulate', '--kp', '1.31', '--delay', '0.368', '--json'], prog_name='delaykit')\n"
            "except SystemExit as e:\n    assert not e.code, e.code\n"
            "print('numba imported' if 'numba' in sys.modules else 'no numba')\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    *body, last = run.stdout.strip().splitlines()
    assert last == "no numba"
    got = json.loads("\n".join(body))
    ref = simulate(AltitudeLoop(kp=1.31, delay=0.368)).metrics
    for k in ("overshoot", "peak_time", "rise_time", "settling_time"):
        assert got[k] == pytest.approx(getattr(ref, k), rel=1e-12, abs=1e-12), k


def test_the_command_line_restores_the_mode_it_found():
    # `simulate` run in-process (here, through typer's runner) switches the interpreter on for its own run only
    from typer.testing import CliRunner

    from delaykit.cli import app

    assert not _jit._interpreting
    res = CliRunner().invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.368", "--json"])
    assert res.exit_code == 0, res.output
    assert not _jit._interpreting and not _jit.interpreting()
