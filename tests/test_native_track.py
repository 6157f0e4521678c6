"""The stability map's loop compiled ahead of time (``spectrum/_trackkernel.py``, calling the root kernel's
``newton_into``, ``bound_into`` and ``contour_into`` without the GIL): built by the set-up, numba's numbers in every
mode, and the map's values the certified search's.

"numba's numbers" is numba's compilation of the same source (:func:`delaykit._native.load` in mode ``"numba"``: the
loop the package ran before the extension existed, and what it falls back to without one); the map's values are
checked against an independent computation, :func:`delaykit.spectrum.stability.rightmost` (the full certified root
search, another algorithm).  No timing is asserted: ``benchmarks/bench_native.py``
measures.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from delaykit import AltitudeLoop, Controller, Loop, _native
from delaykit.spectrum import stability as S

PKG, NAME = "delaykit.spectrum", "_trackkernel"
PID = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.0, 0.5, 0.2, 0.05), delay=0.2)
PI = Loop("1/(s*(0.05*s+1))", Controller.pi(0.8, 0.15), delay=0.37)
PV = AltitudeLoop(kp=1.0, kv=0.3, delay=0.3)


def test_the_set_up_builds_the_loop_and_the_map_uses_it():
    assert _native.built(PKG, NAME), "the Cython extension of _trackkernel is not built (or is stale): run `make`"
    S._tracker()
    assert S.TK.COMPILED
    tk = _native.load(PKG, NAME, "numba")
    assert not tk.COMPILED and hasattr(tk.track_points, "py_func")  # numba compiles the GIL-free loop
    assert not hasattr(tk.track, "py_func")  # and leaves the entry that releases the GIL to Python
    assert tk.newton_into is _native.load("delaykit.spectrum", "_rootkernel", "numba").newton_into


@pytest.mark.parametrize("base,x_name,x,y_name,y", [
    (PID, "kp", np.linspace(0.2, 8, 6), "ki", np.linspace(0.1, 4, 4)),
    (PI, "kp", np.linspace(0.1, 3, 6), "delay", np.linspace(0.05, 0.8, 4)),
    (PV, "kp", np.linspace(0.5, 6, 5), "kv", np.linspace(0.0, 1.0, 4)),
])
def test_the_map_is_the_same_with_the_loop_compiled_by_cython_by_numba_and_interpreted(base, x_name, x, y_name, y,
                                                                                       monkeypatch):
    got = {}
    for mode in _native.MODES:
        monkeypatch.setattr(S, "TK", _native.load(PKG, NAME, mode))
        got[mode] = S.stability_map(base, x_name, x, y_name, y, workers=2).abscissa
    ref = got["numba"]
    assert np.all(np.isfinite(ref))
    for mode in ("cython", "python"):
        assert np.all(np.abs(got[mode] - ref) <= 1e-12 * np.maximum(1.0, np.abs(ref)))
    # every value is the certified abscissa (the full search, point by point)
    for i, j in ((0, 0), (len(y) - 1, len(x) - 1), (1, 2)):
        want = S.rightmost(base.replace(**{x_name: float(x[j]), y_name: float(y[i])})).abscissa
        assert ref[i, j] == pytest.approx(want, rel=1e-9, abs=1e-9)


def test_the_loop_grows_its_stacks_and_does_the_point_again(monkeypatch):
    # a first stack far too short for the contour: each point is done again on a longer one, with the same result
    tk = _native.load(PKG, NAME, "python")
    x, y = np.linspace(0.2, 8, 5), np.linspace(0.1, 4, 3)
    monkeypatch.setattr(S, "TK", tk)
    want = S.stability_map(PID, "kp", x, "ki", y, workers=1).abscissa
    monkeypatch.setattr(tk, "_STACK", 8)
    assert np.array_equal(S.stability_map(PID, "kp", x, "ki", y, workers=1).abscissa, want)



def test_a_stability_map_loads_no_numba():
    code = textwrap.dedent("""
        import sys
        from delaykit import Controller, Loop
        from delaykit.spectrum.stability import stability_map
        pid = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.0, 0.5, 0.2, 0.05), delay=0.2)
        m = stability_map(pid, "kp", [0.5, 2.0, 8.0], "ki", [0.5, 4.0])
        print("@@", "numba" in sys.modules, m.stable.astype(int).tolist())
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "DELAYKIT_KERNELS": ""})
    assert run.returncode == 0, run.stderr
    # (the verdicts are stability_map's docstring example's, from the certified search)
    assert run.stdout.rpartition("@@")[2].strip().split(maxsplit=1) == ["False", "[[1, 1, 1], [0, 1, 0]]"]
