"""Benchmark: the certified poles of a delay system in a box, the Wood-Berry column under decentralised PI.

delaykit's ``poles(T, box)`` (the characteristic quasi-polynomial ``det(sI - A) det(I - P22 Delta)`` built from the
``DelayLTI``, then the certified root finder) against the anchor python-control offers for a delay system: each
delay replaced by a Pade approximation of order 3, 5 or 10 (``T.to_control(pade_order=n)``, built once, not timed)
and ``control.poles`` (the eigenvalues of its A).  Times are CPU times (``time.process_time``), medians, the two
timed alternately so that a loaded machine slows both alike.  Accuracy: the Pade model's eigenvalues in the box
are matched to delaykit's certified roots; the table gives the largest distance, and how many roots the Pade
model misses or adds in the box.

The target of issue 21: the poles in a box under 50 ms.

Run: ``python benchmarks/bench_poles.py [--json FILE] [--write-docs]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from delaykit import feedback, tf

from _docs import write_docs

TARGET = 0.050  # s: issue 21's target for the poles in a box


def wood_berry_pi():
    """Wood & Berry's column (1973) under Luyben's BLT PI (1986), closed by unity feedback (times in minutes)."""
    G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
            ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]], inputs=["R", "S"], outputs=["xD", "xB"],
           name="Wood-Berry")
    K = tf([["0.375*(1 + 1/(8.29*s))", 0], [0, "-0.075*(1 + 1/(23.6*s))"]], inputs=["e1", "e2"],
           outputs=["R", "S"], name="BLT PI")
    return feedback(G * K, 1)


def cpu(fn, repeats: int) -> tuple[object, list[float]]:
    out, times = None, []
    for _ in range(repeats):
        t0 = time.process_time()
        out = fn()
        times.append(time.process_time() - t0)
    return out, times


def in_box(p: np.ndarray, box) -> np.ndarray:
    x0, x1, y0, y1 = box
    return p[(p.real >= x0) & (p.real <= x1) & (p.imag >= y0) & (p.imag <= y1)]


def compare(ours: np.ndarray, theirs: np.ndarray, tol: float = 1e-3) -> tuple[float, int, int]:
    """(largest distance from a certified root to the nearest Pade pole, certified roots with no Pade pole within
    tol, Pade poles with no certified root within tol)."""
    if ours.size == 0:
        return 0.0, 0, int(theirs.size)
    if theirs.size == 0:
        return float("inf"), int(ours.size), 0
    d = np.abs(ours[:, None] - theirs[None, :])
    return float(d.min(axis=1).max()), int((d.min(axis=1) > tol).sum()), int((d.min(axis=0) > tol).sum())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--write-docs", action="store_true",
                    help="replace this script's table in docs/benchmarks.md (between its markers)")
    args = ap.parse_args()
    import control

    T = wood_berry_pi()
    orders = (3, 5, 10)
    models = {n: T.to_control(pade_order=n) for n in orders}
    boxes = [(-0.2, 0.1, 0.0, 1.0), (-1.0, 0.1, 0.0, 5.0)]
    rows = []
    for box in boxes:
        t_dk: list[float] = []
        t_pc = {n: [] for n in orders}
        sp = None
        for _ in range(args.repeats):  # alternately
            sp, t = cpu(lambda: T.poles(box), 1)
            t_dk += t
            for n in orders:
                _, t = cpu(lambda: control.poles(models[n]), 1)
                t_pc[n] += t
        med = statistics.median(t_dk)
        row = {"box": list(box), "delaykit_s": med, "roots": int(sp.roots.size), "certified": bool(sp.certified),
               "target_met": med < TARGET, "pade": []}
        for n in orders:
            p = in_box(np.asarray(control.poles(models[n]), complex), box)
            err, missed, spurious = compare(sp.roots, p)
            m = statistics.median(t_pc[n])
            row["pade"].append({"order": n, "states": int(models[n].nstates), "control_s": m,
                                "ratio": med / m, "max_error": err, "missed": missed, "spurious": spurious})
        rows.append(row)

    load = os.getloadavg()[0]
    table = Table(title=f"Poles of the Wood-Berry column under BLT PI in a box (CPU medians of {args.repeats}; "
                        f"load average {load:.1f})")
    for col in ("box (Re x Im)", "delaykit poles()", "roots, certified", "anchor", "anchor time",
                "delaykit / anchor", "anchor's largest error", "missed / spurious"):
        table.add_column(col, justify="right")
    fmt = lambda t: f"{t * 1e3:.2f} ms"  # noqa: E731
    for r in rows:
        x0, x1, y0, y1 = r["box"]
        first = True
        for a in r["pade"]:
            table.add_row(f"({x0:g}, {x1:g}) x ({y0:g}, {y1:g})" if first else "",
                          fmt(r["delaykit_s"]) if first else "",
                          f"{r['roots']}, {'yes' if r['certified'] else 'NO'}" if first else "",
                          f"python-control, Pade {a['order']} ({a['states']} states)", fmt(a["control_s"]),
                          f"{a['ratio']:.0f}x", f"{a['max_error']:.1e}", f"{a['missed']} / {a['spurious']}")
            first = False
    console = Console(width=160)
    console.print(table)
    worst = max(r["delaykit_s"] for r in rows)
    console.print(f"Target (issue 21): the poles in a box under {TARGET * 1e3:.0f} ms: "
                  f"{'met' if worst < TARGET else 'NOT met'} (slowest box {worst * 1e3:.2f} ms of CPU).")
    if args.write_docs:
        write_docs(Path(__file__).name, table)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"rows": rows, "load": load}, indent=2))


if __name__ == "__main__":
    main()
