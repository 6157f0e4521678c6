"""Benchmark: frequency response, margins and stability maps of delay loops, with anchors side by side.

Rows (targets from issue 12):

* margins of one loop (target under 5 ms): ``delaykit.margins`` on three loops (the paper's P loop, a PID loop on
  a second-order plant, a PI loop on a 150 s lag with a 12 s delay); the anchor is python-control's
  ``stability_margins`` on the loop with the delay replaced by a Padé approximation of order 8 (an approximation:
  its phase margin's difference from delaykit's exact one is reported too);
* a Bode plot's 1,000 frequencies (target under 1 ms): ``delaykit.frequency_response`` against two anchors,
  python-control's ``frequency_response`` of the delay-free part times ``exp(-jwT)``, and plain NumPy
  (``polyval(num, jw) / polyval(den, jw) * exp(-jwT)``); the largest relative difference of ``L`` from each is
  the accuracy check;
* a stability map over a 100 x 100 grid of gains (Kp, Ki) of a general loop (PID on a second-order plant with a
  delay; target under 2 s on both cores): ``stability_map`` against the full certified search
  (``rightmost``) point by point, which is what the map did before, timed on a subset of points (every value of
  the subset compared) and scaled to the grid.

Times are medians of repeats, the two sides timed alternately so that a busy machine slows both alike; the first
call of each (compilation, caches) is left out and reported apart.  Run: ``make bench`` (or
``python benchmarks/bench_frequency.py [--quick] [--json FILE]``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
import warnings
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

import delaykit as dk
from delaykit.spectrum.stability import rightmost, stability_map

from _docs import write_docs

TARGETS = {"margins": 5e-3, "bode": 1e-3, "map": 2.0}


def loops() -> dict[str, object]:
    return {
        "paper P loop, 1/s, Td 0.368 s": dk.AltitudeLoop(kp=1.31, delay=0.368),
        "PID on 1/((s+1)(0.5s+1)), Td 0.2 s": dk.Loop("1/((s+1)*(0.5*s+1))", dk.Controller.pid(1.2, 0.8, 0.2, 0.05),
                                                      delay=0.2),
        "PI on 0.62/(150s+1), Td 12 s": dk.Loop("0.62/(150*s+1)", dk.Controller.pi(2.0, 0.02), delay=12.0),
    }


def alternate(fa, fb, repeats: int) -> tuple[float, float, object, object]:
    """Median times of ``fa`` and ``fb`` run alternately ``repeats`` times (after one untimed call each)."""
    ra, rb = fa(), fb()
    ta, tb = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        ra = fa()
        ta.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        rb = fb()
        tb.append(time.perf_counter() - t0)
    return statistics.median(ta), statistics.median(tb), ra, rb


def first_call(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def margins_rows(repeats: int) -> list[dict]:
    import control

    from delaykit.models.interop import to_control

    rows = []
    for name, loop in loops().items():
        pade = to_control(loop, pade_order=8)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t_dk, t_pc, m, pc = alternate(lambda: dk.margins(loop), lambda: control.stability_margins(pade), repeats)
        pm_pc = float(pc[1])
        rows.append({"case": name, "delaykit": t_dk, "anchor": t_pc, "ratio": t_pc / t_dk,
                     "gain_margin": m.gain_margin, "phase_margin": m.phase_margin, "delay_margin": m.delay_margin,
                     "pade_phase_margin": pm_pc, "pade_pm_error_deg": abs(pm_pc - m.phase_margin),
                     "met": t_dk < TARGETS["margins"]})
    return rows


def bode_rows(repeats: int, n: int = 1000) -> list[dict]:
    import control

    rows = []
    for name, loop in loops().items():
        lp = dk.models.altitude.as_loop(loop) if isinstance(loop, dk.AltitudeLoop) else loop
        num, den = lp.open_loop()
        T = lp.total_delay
        w = dk.frequency_grid(loop, n)
        G = control.tf(num, den)

        def pc():
            return control.frequency_response(G, w).complex * np.exp(-1j * w * T)

        def plain():
            s = 1j * w
            return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * T)

        def ours():
            return dk.frequency_response(loop, w)

        t_dk, t_pc, r, L_pc = alternate(ours, pc, repeats)
        t_dk2, t_np, _, L_np = alternate(ours, plain, repeats)
        t_dk = min(t_dk, t_dk2)
        rel = lambda a: float(np.max(np.abs(r.L - a) / np.abs(a)))  # noqa: E731
        rows.append({"case": name, "n": n, "delaykit": t_dk, "control": t_pc, "numpy": t_np,
                     "ratio_control": t_pc / t_dk, "ratio_numpy": t_np / t_dk, "error_control": rel(L_pc),
                     "error_numpy": rel(L_np), "met": t_dk < TARGETS["bode"]})
    return rows


def map_row(n: int, subset: int, workers: int) -> dict:
    base = dk.Loop("1/((s+1)*(0.5*s+1))", dk.Controller.pid(1.0, 0.5, 0.2, 0.05), delay=0.2)
    kp, ki = np.linspace(0.2, 8.0, n), np.linspace(0.1, 6.0, n)
    cold = first_call(lambda: stability_map(base, "kp", kp[:3], "ki", ki[:3], workers=1))
    times, times1 = [], []
    for _ in range(3):
        t0 = time.perf_counter()
        m = stability_map(base, "kp", kp, "ki", ki, workers=workers)
        times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        m1 = stability_map(base, "kp", kp, "ki", ki, workers=1)
        times1.append(time.perf_counter() - t0)
    assert np.max(np.abs(m.abscissa - m1.abscissa)) < 1e-12  # the same roots, found from other starts
    # the anchor: the full certified search at a subset of the points (a fixed random sample), scaled to the grid
    rng = np.random.default_rng(1)
    idx = rng.choice(n * n, size=min(subset, n * n), replace=False)
    t0 = time.perf_counter()
    ref = np.array([rightmost(base.replace(kp=kp[k % n], ki=ki[k // n])).abscissa for k in idx])
    t_ref = (time.perf_counter() - t0) / idx.size * n * n
    got = m.abscissa.ravel()[idx]
    t = statistics.median(times)
    return {"grid": f"{n} x {n}", "points": n * n, "workers": workers, "delaykit": t,
            "delaykit_one_thread": statistics.median(times1), "first_call": cold, "anchor": t_ref,
            "anchor_points": int(idx.size), "ratio": t_ref / t, "error": float(np.max(np.abs(got - ref))),
            "stable_points": int(m.stable.sum()), "met": t < TARGETS["map"]}


def fmt(t: float) -> str:
    return f"{t * 1e6:.0f} µs" if t < 1e-3 else f"{t * 1e3:.2f} ms" if t < 1 else f"{t:.2f} s"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats and a 20 x 20 map (for the tests)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--write-docs", action="store_true",
                    help="replace this script's tables in docs/benchmarks.md (between its markers)")
    args = ap.parse_args()
    if args.write_docs and (args.quick):
        ap.error("--write-docs writes the full run's tables into the docs: run it without --quick")
    console = Console(width=140)
    reps = 5 if args.quick else 51
    workers = min(2, os.cpu_count() or 1)
    with console.status("margins…"):
        mrows = margins_rows(reps)
    with console.status("Bode…"):
        brows = bode_rows(reps * 4)
    with console.status("stability map…"):
        mp = map_row(20 if args.quick else 100, 40 if args.quick else 500, workers)

    tables = []
    t = Table(title=f"Margins of one loop (median of {reps}; target {fmt(TARGETS['margins'])})")
    for col in ("loop", "delaykit (exact)", "python-control, Padé 8", "ratio", "PM exact", "PM Padé", "met"):
        t.add_column(col, justify="right")
    for r in mrows:
        t.add_row(r["case"], fmt(r["delaykit"]), fmt(r["anchor"]), f"{r['ratio']:.2f}×", f"{r['phase_margin']:.4f}°",
                  f"{r['pade_phase_margin']:.4f}°", "yes" if r["met"] else "NO")
    console.print(t)
    tables.append(t)
    t = Table(title=f"Bode: {brows[0]['n']} frequencies (median of {reps * 4}; target {fmt(TARGETS['bode'])})")
    for col in ("loop", "delaykit", "python-control × e^-jωT", "ratio", "max rel. diff.", "NumPy polyval",
                "ratio", "max rel. diff.", "met"):
        t.add_column(col, justify="right")
    for r in brows:
        t.add_row(r["case"], fmt(r["delaykit"]), fmt(r["control"]), f"{r['ratio_control']:.1f}×",
                  f"{r['error_control']:.1e}", fmt(r["numpy"]), f"{r['ratio_numpy']:.2f}×", f"{r['error_numpy']:.1e}",
                  "yes" if r["met"] else "NO")
    console.print(t)
    tables.append(t)
    t = Table(title=f"Stability map of a PID loop over (Kp, Ki), {mp['grid']} (median of 3; target "
                    f"{fmt(TARGETS['map'])} on 2 cores)")
    for col in ("grid", f"delaykit, {workers} threads", "1 thread", "first call", "rightmost() per point",
                "ratio", "max |diff|", "stable", "met"):
        t.add_column(col, justify="right")
    t.add_row(mp["grid"], fmt(mp["delaykit"]), fmt(mp["delaykit_one_thread"]), fmt(mp["first_call"]),
              f"{fmt(mp['anchor'])} (from {mp['anchor_points']})", f"{mp['ratio']:.0f}×", f"{mp['error']:.1e}",
              f"{mp['stable_points']}/{mp['points']}", "yes" if mp["met"] else "NO")
    console.print(t)
    tables.append(t)
    if args.write_docs:
        write_docs(Path(__file__).name, *tables)
    res = {"margins": mrows, "bode": brows, "map": mp, "targets": TARGETS,
           "targets_met": {"margins": all(r["met"] for r in mrows), "bode": all(r["met"] for r in brows),
                           "map": mp["met"]}}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
