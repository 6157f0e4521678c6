"""Kernels compiled ahead of time (``delaykit._native``, ``setup.py``): the root-finding kernel is built by the
set-up, gives numba's numbers in every mode, and spares ``roots`` and ``margins`` numba altogether.

The reference for "numba's numbers" is numba's compilation of the same source (:func:`delaykit._native.load` in mode
``"numba"``: what the package ran before the extension existed, and what it falls back to without one); the roots
themselves are checked against an independent computation (the Lambert W closed form, SciPy's ``lambertw``).
No timing is asserted here: ``benchmarks/bench_native.py`` and ``benchmarks/bench_startup.py --first-calls`` measure.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from delaykit import AltitudeLoop, Controller, Loop, _native
from delaykit.errors import InvalidValueError
from delaykit.spectrum import roots as R
from delaykit.spectrum import stability as S
from delaykit.spectrum.frequency import margins
from delaykit.spectrum.lambert import lambert_roots
from delaykit.spectrum.roots import _Eval

PKG, NAME = "delaykit.spectrum", "_rootkernel"
LOOPS = {
    "paper": AltitudeLoop(kp=1.31, delay=0.368),
    "unstable P": AltitudeLoop(kp=5.0, delay=0.368),
    "PI on a lag": Loop("1/(s*(0.05*s+1))", Controller.pi(0.8, 0.15), delay=0.37),
    "PD, filtered": Loop("1/(s*(0.05*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=0.3),
}


@pytest.fixture(scope="module")
def kernels():
    return {mode: _native.load(PKG, NAME, mode) for mode in _native.MODES}


def close(a, b, rtol=1e-12):
    a, b = np.asarray(a, complex), np.asarray(b, complex)
    assert a.shape == b.shape
    assert np.all(np.abs(a - b) <= rtol * np.maximum(1.0, np.abs(b)))


def test_the_set_up_builds_the_root_kernel_and_the_root_finder_uses_it():
    # `make` (pip install -e .) compiles it; without a C compiler it would be numba's copy, and this fails
    assert _native.built(PKG, NAME), "the Cython extension of _rootkernel is not built (or is stale): run `make`"
    assert R.RK.COMPILED and S.RK is R.RK
    assert not _native.load(PKG, NAME, "numba").COMPILED and not _native.load(PKG, NAME, "python").COMPILED


@pytest.mark.parametrize("name", LOOPS)
def test_each_kernel_gives_numbas_numbers_compiled_by_cython_and_interpreted(name, kernels):
    ev = _Eval(LOOPS[name].characteristic())
    C, A, tau = ev.C, ev.A, ev.tau
    corners = np.array([-8 - 40j, 2 - 40j, 2 + 40j, -8 + 40j])
    n_init = np.array([8 + int(abs(corners[(i + 1) % 4] - corners[i]) * (tau.max() + 0.25) / R._MAX_PHASE)
                       for i in range(4)], dtype=np.int64)
    # Newton from near each root in the rectangle (as the root finder polishes): far starts wander chaotically, and
    # C's complex division (Cython) rounds otherwise than CPython's (numba's), so their end points are not comparable
    near = R.find_roots(LOOPS[name].characteristic(), (-8.0, 2.0, -40.0, 40.0)).roots
    starts = near * (1.0 + 1e-3) + 1e-3j
    xs, ys = np.linspace(-8, 2, 41), np.linspace(-40, 40, 81)
    box = np.array([-50.0, 10.0, -100.0, 100.0])
    got = {}
    for mode, rk in kernels.items():
        size = 4 * int(n_init.sum()) + 4096
        out_s, out_dl = np.empty(size, complex), np.empty(size, complex)
        status, winding, m, where = rk.contour(C, A, tau, corners, n_init, R._MAX_PHASE, R._RELIABLE, R._CAP,
                                               out_s, out_dl)
        got[mode] = {"contour": (status, winding, m, where, out_s[:m].copy(), out_dl[:m].copy()),
                     "newton": rk.newton(C, A, tau, starts, 60, box),
                     "grid": rk.grid_minima(C, tau, xs, ys),
                     "bound": [rk.bound(C, tau, x) for x in (0.0, -0.5, -3.0)]}
    ref = got["numba"]
    assert ref["contour"][0] == 0 and ref["contour"][2] > 0 and ref["newton"][1].all()  # the cases do work
    for mode in ("cython", "python"):
        g = got[mode]
        assert g["contour"][:3] == pytest.approx(ref["contour"][:3], rel=1e-12, abs=1e-12)
        close(g["contour"][4], ref["contour"][4])
        close(g["contour"][5], ref["contour"][5])
        close(g["newton"][0], ref["newton"][0])
        assert g["newton"][1].dtype == bool and np.array_equal(g["newton"][1], ref["newton"][1])
        assert np.array_equal(g["newton"][2], ref["newton"][2])
        close(g["grid"], ref["grid"])
        close(g["bound"], ref["bound"])


@pytest.mark.parametrize("name", LOOPS)
def test_roots_rightmost_and_margins_are_the_same_with_the_kernel_compiled_by_numba(name, kernels, monkeypatch):
    loop = LOOPS[name]

    def results():
        sp = R.find_roots(loop.characteristic(), (-10.0, 3.0, -50.0, 50.0))
        return (np.sort_complex(sp.roots), S.rightmost(loop).root, S.right_half_plane_count(loop.characteristic()),
                margins(loop).to_dict())

    compiled = results()
    monkeypatch.setattr(R, "RK", kernels["numba"])
    monkeypatch.setattr(S, "RK", kernels["numba"])
    by_numba = results()
    close(compiled[0], by_numba[0])
    close(compiled[1], by_numba[1])
    assert compiled[2] == by_numba[2]
    assert json.dumps(compiled[3]) == json.dumps(by_numba[3])  # every margin, crossover and verdict


def test_the_compiled_root_finder_finds_the_lambert_w_roots_of_the_paper_loop():
    # a P loop on kp/s: s + kp exp(-td s) = 0, whose roots are W_k(-kp td) / td (SciPy's lambertw, via lambert_roots)
    kp, td = 1.31, 0.368
    sp = R.find_roots(AltitudeLoop(kp=kp, delay=td).characteristic(), (-25.0, 1.0, -80.0, 80.0))
    ref = lambert_roots(0.0, -kp, td, branches=range(-8, 8)).roots
    ref = np.sort_complex(ref[(ref.real >= -25) & (ref.real <= 1) & (np.abs(ref.imag) <= 80)])
    assert sp.roots.size == ref.size > 4
    close(np.sort_complex(sp.roots), ref, rtol=1e-10)


def test_an_unknown_kernel_mode_is_refused_naming_it(monkeypatch):
    with pytest.raises(InvalidValueError, match="'fortran'"):
        _native.load(PKG, NAME, "fortran")
    monkeypatch.setenv("DELAYKIT_KERNELS", "python")
    assert _native.load(PKG, NAME).__name__ == f"{PKG}.{NAME}_python"


def test_without_the_extension_numba_compiles_the_source(monkeypatch):
    monkeypatch.delenv("DELAYKIT_KERNELS", raising=False)
    monkeypatch.setattr(_native, "built", lambda package, name: False)
    rk = _native.load(PKG, NAME)
    assert rk.__name__ == f"{PKG}.{NAME}_numba" and hasattr(rk.qeval, "py_func")  # numba's dispatchers


def test_an_extension_older_than_its_source_is_stale(tmp_path):
    ext, src, pxd = tmp_path / "_k.cpython-311-x86_64-linux-gnu.so", tmp_path / "_k.py", tmp_path / "_k.pxd"
    for f in (ext, src, pxd):
        f.write_text("")
    t = ext.stat().st_mtime
    os.utime(src, (t + 1.0, t + 1.0))  # written with it (a wheel's install): current
    assert _native._newer_sources(ext, "_k") == []
    os.utime(pxd, (t + 60.0, t + 60.0))  # edited since the build
    assert _native._newer_sources(ext, "_k") == ["_k.pxd"]


def test_a_stale_extension_warns_and_numba_takes_over(monkeypatch):
    monkeypatch.delenv("DELAYKIT_KERNELS", raising=False)
    monkeypatch.setattr(_native, "_newer_sources", lambda ext, name: [f"{name}.py"])
    with pytest.warns(_native.StaleExtensionWarning, match="rebuild"):
        rk = _native.load(PKG, NAME)
    assert rk.__name__ == f"{PKG}.{NAME}_numba"


def test_roots_and_margins_commands_load_no_numba():
    # nothing is compiled at run time: the command line's root finder and margins run on the extension alone
    code = textwrap.dedent("""
        import sys
        from delaykit.cli import main
        for args in (["roots", "--kp", "1.31", "--delay", "0.368", "--json"],
                     ["margins", "--plant", "1/(s*(0.05*s+1))", "--controller", "pi", "--kp", "0.8", "--ki", "0.15",
                      "--delay", "0.37", "--json"]):
            sys.argv = ["delaykit", *args]
            try:
                main()
            except SystemExit as exc:
                assert not exc.code, exc.code
        print("@@", "numba" in sys.modules, "delaykit.spectrum.roots" in sys.modules)
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "DELAYKIT_KERNELS": ""})
    assert run.returncode == 0, run.stderr
    assert run.stdout.rpartition("@@")[2].split() == ["False", "True"]


@pytest.mark.slow
def test_the_side_by_side_benchmark_runs_and_finds_the_modes_equal(tmp_path):
    out = tmp_path / "native.json"
    bench = os.path.join(os.path.dirname(__file__), os.pardir, "benchmarks", "bench_native.py")
    # the root kernels' part: the simulator's part compiles numba's copies of the Loop kernels (minutes on a cold
    # cache) and its modes' equality is tested case by case in test_native_simulator.py
    subprocess.run([sys.executable, bench, "--repeat", "1", "--only", "roots", "--json", str(out)], check=True,
                   capture_output=True, text=True, timeout=900)
    rows = json.loads(out.read_text())["rows"]
    assert len(rows) == 19 and all(r["cython"] > 0 and r["numba"] > 0 for r in rows)
    assert max(r["difference"] for r in rows) <= 1e-12


def test_the_source_runs_where_cython_is_not_installed():
    # an install without a C compiler has no Cython at run time either: the .py must not need it
    code = textwrap.dedent("""
        import sys
        sys.modules["cython"] = None  # import cython now raises ImportError
        import numpy as np
        from delaykit import AltitudeLoop, _native
        from delaykit.spectrum.roots import _Eval
        rk = _native.load("delaykit.spectrum", "_rootkernel", "python")
        ev = _Eval(AltitudeLoop(kp=1.31, delay=0.368).characteristic())
        s, conv, clean = rk.newton(ev.C, ev.A, ev.tau, np.array([-1.0 + 1.0j]), 60, np.array([-1e300, 1e300] * 2))
        print("@@", rk.COMPILED, bool(conv[0] and clean[0]), repr(complex(s[0])))
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    compiled, converged, root = run.stdout.rpartition("@@")[2].split()
    assert compiled == "False" and converged == "True"
    # the root it converged to is a root of s + 1.31 exp(-0.368 s) (the paper's loop), to rounding
    s = complex(root)
    assert abs(s + 1.31 * np.exp(-0.368 * s)) < 1e-12


def test_without_extension_or_numba_a_kernel_runs_as_python_and_says_so(monkeypatch):
    # numba is optional (the extra delaykit[numba]): an install without a C compiler and without numba still
    # answers, with the plain source, and warns; asking for numba's copy then names the missing package
    import builtins
    import importlib.util

    from delaykit import MissingDependencyError, SlowKernelWarning

    monkeypatch.delenv("DELAYKIT_KERNELS", raising=False)
    monkeypatch.setattr(_native, "built", lambda package, name: False)
    real_find = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda n, *a: None if n == "numba" else real_find(n, *a))
    with pytest.warns(SlowKernelWarning, match="numba is not installed"):
        mod = _native.load("delaykit.spectrum", "_rootkernel")
    assert mod.__name__ == "delaykit.spectrum._rootkernel_python"
    real_import = builtins.__import__

    def no_numba(name, *args, **kwargs):
        if name == "numba" or name.startswith("numba."):
            raise ImportError("No module named 'numba'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_numba)
    monkeypatch.delitem(_native._loaded, ("delaykit.models._expmkernel", "numba"), raising=False)
    with pytest.raises(MissingDependencyError, match="delaykit\\[numba\\]"):
        _native.load("delaykit.models", "_expmkernel", "numba")
