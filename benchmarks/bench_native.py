"""Benchmark: the kernels compiled ahead of time by Cython against the same source compiled by numba.

Each is one ``.py`` file: the extension module that ``pip install`` builds (:mod:`delaykit._native`, ``setup.py``)
and numba's copy of the same file, side by side in this one process.  For the root-finding kernel
(``spectrum/_rootkernel.py``) on a realistic input (the quasi-polynomials of the paper's P loop and of a PI loop on a
lagged integrator; a contour around a large rectangle, Newton from a grid of starts, the grid scan for starting
points, the root bound), and for the library calls that use it (``find_roots``, ``rightmost``, ``margins``); for
the kernels of held-input stepping (``models/_expmkernel.py``, ``simulate/_discretekernel.py``,
``simulate/_varyingkernel.py``: the matrix exponential, the one-period map, a closed loop of 10,000 samples, a log on
an uneven clock) and the library calls on them (``hold_matrices``, ``simulate_varying``); and for the stability
map's loop (``spectrum/_trackkernel.py``, with the root kernel of the same mode, in ``stability_map``), the table
gives the least CPU time of the calling
thread over ``--repeat`` runs for each (all run on that one thread) and their ratio (numba / Cython: above 1,
Cython is faster), and the largest difference of the results (relative, over all outputs; the test suite checks
1e-12).  numba's compilation is timed apart (its first call, cached or not as the cache is), and so is the Cython
extension's first call.

The simulator's kernels (``simulate/_kernel.py`` with ``_taylor.py`` and ``_poly.py``, and ``_sampled_batch.py``)
follow: one run of the paper's P loop and of a PID loop with limits (``run_one``), the batch kernels on one work
set (1,000 of the paper's P loops; 300 sampled ones) and ``simulate_many`` of the paper's 10,000 P loops on every
thread.  The batch rows give the CPU time of the whole process (their loops may run on OpenMP's or numba's worker
threads), the least of ``--repeat // 5`` runs (at least 3); ``--only roots`` or ``--only simulator`` runs one part.

Other work on the machine slows both (less so their CPU time than their wall time): the ratio, taken side by side,
is the figure to read.

Run: ``python benchmarks/bench_native.py [--repeat 25] [--only roots|simulator] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
from rich.console import Console
from rich.table import Table

from delaykit import AltitudeLoop, Controller, Loop, _native
from delaykit.models import hold
from delaykit.models.transfer import TransferFunction
from delaykit.simulate import varying as V
from delaykit.spectrum import roots as R
from delaykit.spectrum import stability as S
from delaykit.spectrum.frequency import margins
from delaykit.spectrum.roots import _Eval

PAPER = AltitudeLoop(kp=1.31, delay=0.368)
PI_LOOP = Loop("1/(s*(0.05*s+1))", Controller.pi(0.8, 0.15), delay=0.37)
SIM_PID = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(2.0, 0.8, 0.2, 0.05), delay=0.25, umin=-0.5, umax=2.0)


def best(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """Least CPU time of this thread over ``repeat`` calls, and the last result.  (Every case runs on this one
    thread; its CPU time is far steadier than the wall time on a machine shared with other work.)"""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.thread_time()
        out = fn()
        times.append(time.thread_time() - t0)
    return min(times), out


def flat(x: Any) -> np.ndarray:
    """Every number of a result, as one complex array (for the difference)."""
    if isinstance(x, (tuple, list)):
        parts = [flat(v) for v in x]
        return np.concatenate(parts) if parts else np.zeros(0, complex)
    if hasattr(x, "to_dict"):
        return flat([v for v in _numbers(x.to_dict())])
    return np.atleast_1d(np.asarray(x, dtype=complex)).ravel()


def _numbers(d: Any) -> list[Any]:
    if isinstance(d, dict):
        return [n for v in d.values() for n in _numbers(v)]
    if isinstance(d, (list, tuple)):
        return [n for v in d for n in _numbers(v)]
    return [d] if isinstance(d, (int, float, complex)) and not isinstance(d, bool) and d is not None else []


def difference(a: Any, b: Any) -> float:
    fa, fb = flat(a), flat(b)
    if fa.shape != fb.shape:
        return float("inf")
    if fa.size == 0:
        return 0.0
    both = np.isfinite(fa) & np.isfinite(fb)
    if not np.array_equal(both, np.isfinite(fa)):
        return float("inf")
    return float(np.max(np.abs(fa[both] - fb[both]) / np.maximum(1.0, np.abs(fb[both])), initial=0.0))


def kernel_cases(rk: Any) -> dict[str, Callable[[], Any]]:
    """Each kernel on a large input, for the kernel module ``rk``."""
    cases: dict[str, Callable[[], Any]] = {}
    for label, loop in (("paper", PAPER), ("PI", PI_LOOP)):
        ev = _Eval(loop.characteristic())
        corners = np.array([-30 - 400j, 5 - 400j, 5 + 400j, -30 + 400j])
        n_init = np.array([8 + int(abs(corners[(i + 1) % 4] - corners[i]) * (ev.tau.max() + 0.25) / R._MAX_PHASE)
                           for i in range(4)], dtype=np.int64)
        size = 4 * int(n_init.sum()) + 4096
        out_s, out_dl = np.empty(size, complex), np.empty(size, complex)
        xs, ys = np.linspace(-30, 5, 301), np.linspace(-200, 200, 801)
        starts = (xs[::10][:, None] + 1j * ys[::10][None, :]).ravel()
        box = np.array([-1e300, 1e300, -1e300, 1e300])
        C, A, tau = ev.C, ev.A, ev.tau
        cases[f"contour ({label}, {size} slots)"] = (
            lambda C=C, A=A, tau=tau, n_init=n_init, out_s=out_s, out_dl=out_dl, corners=corners:
            rk.contour(C, A, tau, corners, n_init, R._MAX_PHASE, R._RELIABLE, R._CAP, out_s, out_dl)[:3])
        cases[f"newton ({label}, {starts.size} starts)"] = (
            lambda C=C, A=A, tau=tau, starts=starts, box=box: rk.newton(C, A, tau, starts, 60, box))
        cases[f"grid_minima ({label}, {xs.size}x{ys.size})"] = (
            lambda C=C, tau=tau, xs=xs, ys=ys: rk.grid_minima(C, tau, xs, ys))
        cases[f"bound ({label}) x1000"] = lambda C=C, tau=tau: [rk.bound(C, tau, -0.5 * i) for i in range(1000)]
    return cases


def held_cases(mode: str) -> dict[str, Callable[[], Any]]:
    """The kernels of held-input stepping on large inputs, in ``mode``."""
    ek = _native.load("delaykit.models", "_expmkernel", mode)
    dk = _native.load("delaykit.simulate", "_discretekernel", mode)
    A, B, C, _ = TransferFunction.parse("(s+2)/(s*(0.05*s+1)*(0.3*s+1))").state_space()
    n = len(B)
    A, B, C = np.asarray(A, float).reshape(n, n), np.asarray(B, float).ravel(), np.asarray(C, float).ravel()
    M = np.random.default_rng(3).normal(size=(8, 8))
    phi, ge, gl = dk.held_arrays(A, B, 0.065, 0.045)
    ca, cb = C @ A, float(C @ B)
    r = np.ones(10_000)
    t = np.cumsum(np.random.default_rng(4).uniform(0.03, 0.12, 2_000))
    u = np.random.default_rng(5).normal(size=t.size)
    starts = np.array([0, t.size], dtype=np.int64)
    outs = [np.zeros(t.size) for _ in range(4)]

    def at() -> Any:
        dk.run_at_logs(A, B, C, 0.0, ca, cb, 0.37, 1e-12, t, u, starts, True, *outs)
        return [o.copy() for o in outs]

    return {
        "expm (8x8) x1000": lambda: [ek.expm(M) for _ in range(1000)][-1],
        "held_arrays (3rd order) x1000": lambda: [dk.held_arrays(A, B, 0.065, 0.045) for _ in range(1000)][-1],
        "run, closed loop (3rd order, 10,000 samples)":
            lambda: dk.run(phi, ge, gl, C, 0.0, ca, cb, 5, True, r, True, 0.8, 0.1, -1.0, 1.0),
        "run_at_logs (3rd order, 2,000 uneven samples)": at,
    }


def held_library_cases() -> dict[str, Callable[[], Any]]:
    """Library calls on the held-input kernels and the stability map's loop, with whichever modules are in use."""
    A, B, _, _ = TransferFunction.parse("(s+2)/(s*(0.05*s+1)*(0.3*s+1))").state_space()
    A = np.asarray(A, float).reshape(len(B), len(B))
    G = np.asarray(B, float).reshape(-1, 1)
    jitter = V.Jitter(0.3, "uniform", spread=0.1, seed=3)
    return {
        "hold_matrices (3rd order) x1000": lambda: [hold.hold_matrices(A, G, 0.065) for _ in range(1000)][-1],
        "simulate_varying (PI loop, 20 s)": lambda: V.simulate_varying(PI_SAMPLED, jitter, t_end=20.0).output,
        "stability_map (PI loop, 30 x 20, 1 thread)":
            lambda: S.stability_map(PI_LOOP, "kp", np.linspace(0.1, 3, 30), "delay", np.linspace(0.05, 0.8, 20),
                                    workers=1).abscissa,
    }


def use_held(mode: str) -> None:
    hold._loaded[:] = [_native.load("delaykit.models", "_expmkernel", mode)]
    V.VK = _native.load("delaykit.simulate", "_varyingkernel", mode)
    S.TK = _native.load("delaykit.spectrum", "_trackkernel", mode)


PI_SAMPLED = Loop("1/(s*(0.05*s+1))", Controller.pi(0.8, 0.15), umin=-1, umax=1, period=0.065)


def library_cases() -> dict[str, Callable[[], Any]]:
    """The library calls, with whichever kernel module ``roots.RK`` is now."""
    return {
        "find_roots (paper, [-20, 1] x [-60, 60])":
            lambda: R.find_roots(PAPER.characteristic(), (-20, 1, -60, 60)).roots,
        "rightmost (PI loop)": lambda: S.rightmost(PI_LOOP),
        "margins (PI loop)": lambda: margins(PI_LOOP),
        "margins (paper)": lambda: margins(PAPER),
    }


def best_process(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """Least CPU time of the whole process (every thread) over ``repeat`` calls, and the last result."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        times.append(time.process_time() - t0)
    return min(times), out


def batch_rows(loop: Any, **sweep: Any) -> np.ndarray:
    """The batch kernels' parameter rows of a sweep, as ``simulate_many`` builds them."""
    from delaykit.simulate import simulation as SIM

    seen, real = {}, SIM._batch

    def grab(pars: np.ndarray) -> np.ndarray:
        seen["pars"] = pars.copy()
        return real(pars)

    SIM._batch = grab
    try:
        SIM.simulate_many(loop, **sweep)
    finally:
        SIM._batch = real
    return np.ascontiguousarray(seen["pars"])


def simulator_cases(kern: Any, sb: Any) -> dict[str, tuple[bool, Callable[[], Any]]]:
    """The simulator's kernels in one mode (``kern``: ``_kernel``, ``sb``: ``_sampled_batch``): case name ->
    (whether it runs on worker threads, the call)."""
    from delaykit.simulate import _layout
    from delaykit.simulate._layout import loop_matrices, param_row
    from delaykit.simulate.simulation import as_loop

    def one(loop: Any, t_end: float) -> Callable[[], Any]:
        gen = as_loop(loop)
        row = param_row(gen, loop_matrices(gen), step=1.0, slope=0.0, norm=1.0, t_end=t_end, band=0.02, dist=None)
        cap, nc = 4096, _layout.NC
        u = (np.empty(cap), np.empty(cap), np.zeros((cap, nc)), np.empty(cap, dtype=np.int64),
             np.empty(cap, dtype=np.int8))
        y = (np.empty(cap), np.empty(cap), np.zeros((cap, nc)), np.zeros((cap, nc)), np.empty(cap, dtype=np.int8))
        out, knots = np.empty(_layout.NOUT), (np.zeros(1), np.ones(1), np.zeros(1))

        def call() -> np.ndarray:
            kern.run_one(row, *knots, cap, *u, *y, out, True, np.empty(0), np.empty(0))
            return out.copy()
        return call

    td = np.random.default_rng(2024).uniform(0.2, 0.5, 1000)
    p_rows = batch_rows(PAPER, delay=td)
    s_rows = batch_rows(AltitudeLoop(kp=1.31, delay=0.3, period=0.065), delay=td[:300])
    return {
        "run_one (paper P, 15 s)": (False, one(PAPER, 15.0)),
        "run_one (PID with limits, 15 s)": (False, one(SIM_PID, 15.0)),
        "run_batch (1,000 paper P loops, 1 set)": (True, lambda: kern.run_batch(p_rows, 4096, 1, 1)),
        "run_batch (300 sampled P loops, 1 set)": (True, lambda: sb.run_batch(s_rows, 1, 1)),
    }


def simulate_many_case() -> Callable[[], Any]:
    """The issue's call: ``simulate_many`` of the paper's 10,000 P loops, with the kernels ``DELAYKIT_KERNELS``
    chooses (on every thread)."""
    from delaykit import simulate_many

    td = np.random.default_rng(2024).uniform(0.2, 0.5, 10_000)
    return lambda: simulate_many(AltitudeLoop(kp=1.31, delay=0.3), delay=td).overshoot


def simulator_rows(repeat: int) -> tuple[list[dict[str, Any]], float, float]:
    """The simulator's rows, and the first calls of its Cython and numba kernels (numba's: compiled or cached)."""
    pkg = "delaykit.simulate"
    for name in ("_poly", "_taylor", "_kernel", "_sampled_batch"):
        if not _native.built(pkg, name):
            raise SystemExit(f"the Cython extension of {pkg}.{name} is not built: run `make` or `pip install -e .`")
    cy = simulator_cases(_native.load(pkg, "_kernel", "cython"), _native.load(pkg, "_sampled_batch", "cython"))
    t0 = time.perf_counter()
    next(iter(cy.values()))[1]()
    cy_first = time.perf_counter() - t0
    nb = simulator_cases(_native.load(pkg, "_kernel", "numba"), _native.load(pkg, "_sampled_batch", "numba"))
    t0 = time.perf_counter()
    for _, fn in nb.values():  # compiles (or loads from numba's cache) every kernel
        fn()
    nb_first = time.perf_counter() - t0
    rows = []
    few = max(3, repeat // 5)
    for (name, (threads, f_cy)), (_, f_nb) in zip(cy.items(), nb.values()):
        t_cy, r_cy = best_process(f_cy, few) if threads else best(f_cy, repeat)
        t_nb, r_nb = best_process(f_nb, few) if threads else best(f_nb, repeat)
        rows.append({"case": name, "cython": t_cy, "numba": t_nb, "ratio": t_nb / t_cy,
                     "difference": difference(r_cy, r_nb)})
    call = simulate_many_case()
    before = os.environ.get("DELAYKIT_KERNELS")
    try:
        got = {}
        for mode in ("numba", "cython"):
            os.environ["DELAYKIT_KERNELS"] = mode
            call()  # (numba: compiles the batch's parallel loop, or loads it from the cache)
            got[mode] = best_process(call, few)
    finally:
        if before is None:
            os.environ.pop("DELAYKIT_KERNELS", None)
        else:
            os.environ["DELAYKIT_KERNELS"] = before
    rows.append({"case": "simulate_many (10,000 paper P loops, all threads)", "cython": got["cython"][0],
                 "numba": got["numba"][0], "ratio": got["numba"][0] / got["cython"][0],
                 "difference": difference(got["cython"][1], got["numba"][1])})
    return rows, cy_first, nb_first


def use(rk: Any) -> None:
    R.RK = rk
    S.RK = rk


def root_rows(repeat: int) -> tuple[list[dict[str, Any]], float, float]:
    """The rows of the root kernel and of the held-input and stability-map kernels, and the first calls of the root
    kernel's Cython and numba copies."""
    for package, name in (("delaykit.spectrum", "_rootkernel"), ("delaykit.spectrum", "_trackkernel"),
                          ("delaykit.models", "_expmkernel"), ("delaykit.simulate", "_discretekernel"),
                          ("delaykit.simulate", "_varyingkernel")):
        if not _native.built(package, name):
            raise SystemExit(f"the Cython extension of {package}.{name} is not built: run `make` or "
                             "`pip install -e .` first")
    cy = _native.load("delaykit.spectrum", "_rootkernel", "cython")
    t0 = time.perf_counter()
    next(iter(kernel_cases(cy).values()))()
    cy_first = time.perf_counter() - t0
    nb = _native.load("delaykit.spectrum", "_rootkernel", "numba")
    t0 = time.perf_counter()
    for fn in kernel_cases(nb).values():  # compiles (or loads from numba's cache) every kernel
        fn()

    for fn in held_cases("numba").values():
        fn()
    use_held("numba")
    for fn in held_library_cases().values():
        fn()
    nb_first = time.perf_counter() - t0

    rows = []
    for (name, f_cy), f_nb in zip(kernel_cases(cy).items(), kernel_cases(nb).values()):
        t_cy, r_cy = best(f_cy, repeat)
        t_nb, r_nb = best(f_nb, repeat)
        rows.append({"case": name, "cython": t_cy, "numba": t_nb, "ratio": t_nb / t_cy,
                     "difference": difference(r_cy, r_nb)})
    for name in library_cases():
        use(cy)
        t_cy, r_cy = best(library_cases()[name], repeat)
        use(nb)
        t_nb, r_nb = best(library_cases()[name], repeat)
        use(cy)
        rows.append({"case": name, "cython": t_cy, "numba": t_nb, "ratio": t_nb / t_cy,
                     "difference": difference(r_cy, r_nb)})
    for (name, f_cy), f_nb in zip(held_cases("cython").items(), held_cases("numba").values()):
        t_cy, r_cy = best(f_cy, repeat)
        t_nb, r_nb = best(f_nb, repeat)
        rows.append({"case": name, "cython": t_cy, "numba": t_nb, "ratio": t_nb / t_cy,
                     "difference": difference(r_cy, r_nb)})
    for name in held_library_cases():
        use_held("cython")
        t_cy, r_cy = best(held_library_cases()[name], repeat)
        use_held("numba")
        t_nb, r_nb = best(held_library_cases()[name], repeat)
        use_held("cython")
        rows.append({"case": name, "cython": t_cy, "numba": t_nb, "ratio": t_nb / t_cy,
                     "difference": difference(r_cy, r_nb)})
    return rows, cy_first, nb_first


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=25, help="Runs of each case; the fastest is kept.")
    ap.add_argument("--json", type=Path, default=None, help="Also write the results here as JSON.")
    ap.add_argument("--only", choices=("roots", "simulator"), default=None, help="Run one part only.")
    args = ap.parse_args()
    console = Console(width=max(Console().width, 120))
    doc: dict[str, Any] = {"python": sys.version.split()[0], "load": os.getloadavg(), "repeat": args.repeat}
    if args.only != "simulator":
        rows, cy_first, nb_first = root_rows(args.repeat)
        show(console, "Root kernel", rows, args.repeat)
        console.print(f"first call: Cython {cy_first * 1e3:.1f} ms (nothing compiled); numba {nb_first:.1f} s "
                      "(compiling, or loading numba's cache where it has the kernels)")
        doc.update({"cython_first_call": cy_first, "numba_first_call": nb_first, "rows": rows})
    if args.only != "roots":
        rows, cy_first, nb_first = simulator_rows(args.repeat)
        show(console, "Simulator kernels (batch rows: CPU time of every thread)", rows, args.repeat)
        console.print(f"first call: Cython {cy_first * 1e3:.1f} ms (nothing compiled); numba {nb_first:.1f} s "
                      "(compiling, or loading numba's cache where it has the kernels)")
        doc.update({"simulator_cython_first_call": cy_first, "simulator_numba_first_call": nb_first,
                    "simulator_rows": rows})
    if args.json is not None:
        doc["load_after"] = os.getloadavg()
        args.json.write_text(json.dumps(doc, indent=2) + "\n")


def show(console: Console, title: str, rows: list[dict[str, Any]], repeat: int) -> None:
    table = Table(title=f"{title}: Cython (ahead of time) against numba, same source, least CPU time of "
                        f"{repeat} (load {os.getloadavg()[0]:.1f})")
    for col in ("case", "Cython ms", "numba ms", "numba / Cython", "largest rel. difference"):
        table.add_column(col, justify="left" if col == "case" else "right")
    for r in rows:
        table.add_row(r["case"], f"{1e3 * r['cython']:.3f}", f"{1e3 * r['numba']:.3f}", f"{r['ratio']:.2f}",
                      f"{r['difference']:.1e}")
    console.print(table)


if __name__ == "__main__":
    main()
