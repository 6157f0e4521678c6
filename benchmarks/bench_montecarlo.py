"""Benchmark: Monte Carlo over a delay distribution, batched on the fast kernel, against a Python loop of simulate().

The loop: the paper's P loop, plant 1/s, Kp = 1.31, command clipped to [-1, 1], continuous, 15 s, unit step.
n = 1000 constant delays drawn uniform on [0.3, 0.45] s (seed 2024).  Two ways to get the four step metrics of
every run, side by side in this one process:

* ``monte_carlo(loop, DelayDistribution.uniform(0.3, 0.45), n=1000)``: the draws, then ONE call of
  ``simulate_many(loop, delay=delays)`` (the exact kernel, parallel over numba's threads), then the percentiles;
* the anchor users would write: ``[simulate(loop.replace(delay=d)).metrics for d in delays]``, one call each.

Both use the same exact solver, so their metrics must agree to rounding: the largest difference is printed
(not asserted).  The kernel is compiled (or loaded from numba's cache) before timing; each way is timed as
the best of ``--repeat`` whole runs (wall clock); the process's CPU time is kept too, since the machine may be
shared.  No assertion: this prints a table (and writes JSON with ``--json``).

Run: ``python benchmarks/bench_montecarlo.py [--runs N] [--repeat R] [--json PATH]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

import delaykit as dk
from delaykit.models import Controller, Loop
from delaykit.simulate.montecarlo import DelayDistribution, monte_carlo

KEYS = ("overshoot", "peak_time", "rise_time", "settling_time")
LO, HI = 0.3, 0.45
T_END = 15.0
SEED = 2024


def one_by_one(loop: Loop, delays: np.ndarray) -> dict[str, np.ndarray]:
    """The anchor: simulate() once per delay in a Python loop (None metrics as NaN)."""
    rows = [dk.simulate(loop.replace(delay=float(d)), t_end=T_END).metrics for d in delays]
    return {k: np.array([math.nan if getattr(r, k) is None else getattr(r, k) for r in rows]) for k in KEYS}


def timed(fn, repeat: int):
    """Best wall time of ``repeat`` calls, the CPU time of that call, and its result."""
    best, cpu, out = math.inf, math.nan, None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = time.perf_counter() - t0
        if wall < best:
            best, cpu = wall, time.process_time() - c0
    return best, cpu, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions of each way (best is kept)")
    ap.add_argument("--json", type=Path, default=None, help="also write the results here")
    args = ap.parse_args()
    console = Console(width=140)
    loop = Loop("1/s", Controller.p(1.31), umin=-1, umax=1)
    dist = DelayDistribution.uniform(LO, HI)
    load_before = os.getloadavg()

    t0 = time.perf_counter()
    monte_carlo(loop, dist, n=2, seed=0, t_end=T_END)  # compile or load the kernel (both ways share it)
    dk.simulate(loop.replace(delay=LO), t_end=T_END)
    first = time.perf_counter() - t0

    t_mc, cpu_mc, mc = timed(lambda: monte_carlo(loop, dist, n=args.runs, seed=SEED, t_end=T_END), args.repeat)
    delays = mc.delays
    t_sm, cpu_sm, _ = timed(lambda: dk.simulate_many(loop, delay=delays, t_end=T_END), args.repeat)
    t_py, cpu_py, ref = timed(lambda: one_by_one(loop, delays), args.repeat)
    load_after = os.getloadavg()

    diff = {}
    for k in KEYS:
        a, b = getattr(mc, k), ref[k]
        same_nan = np.array_equal(np.isnan(a), np.isnan(b))
        diff[k] = float(np.max(np.abs(a - b), initial=0.0, where=~np.isnan(a))) if same_nan else math.inf
    worst = max(diff.values())

    table = Table(title=f"{args.runs:,} runs of the paper's P loop (1/s, Kp 1.31, u in [-1, 1], {T_END:g} s), "
                        f"constant delay ~ uniform({LO}, {HI}) s")
    for col in ("way", "calls", "wall s", "µs/run", "CPU s", "time ÷ batched"):
        table.add_column(col, justify="right", no_wrap=col == "way")
    table.add_row("monte_carlo, batched (draws + simulate_many + percentiles)", "1", f"{t_mc:.4f}",
                  f"{1e6 * t_mc / args.runs:.1f}", f"{cpu_mc:.3f}", "1")
    table.add_row("  of which simulate_many alone", "1", f"{t_sm:.4f}", f"{1e6 * t_sm / args.runs:.1f}",
                  f"{cpu_sm:.3f}", f"{t_sm / t_mc:.2f}")
    table.add_row("simulate() in a Python loop", f"{args.runs:,}", f"{t_py:.4f}", f"{1e6 * t_py / args.runs:.1f}",
                  f"{cpu_py:.3f}", f"{t_py / t_mc:.1f}")
    console.print(table)
    console.print(
        f"Both ways use the same exact kernel: largest difference of their metrics {worst:.1e} "
        f"({', '.join(f'{k} {v:.1e}' for k, v in diff.items())}). {mc!r}. "
        f"Times are the best of {args.repeat} whole runs after a first call that compiled or loaded the kernel "
        f"({first:.2f} s). numba threads: {__import__('numba').get_num_threads()}; load average "
        f"{load_before[0]:.1f} before, {load_after[0]:.1f} after (the machine may be shared). "
        f"CPU-time ratio (all threads): {cpu_py / cpu_mc:.1f}.")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({
            "runs": args.runs, "loop": loop.to_dict(), "distribution": dist.to_dict(), "seed": SEED,
            "t_end": T_END, "first_call": first,
            "batched": {"method": mc.method, "wall": t_mc, "cpu": cpu_mc, "simulate_many_wall": t_sm,
                        "simulate_many_cpu": cpu_sm},
            "one_by_one": {"wall": t_py, "cpu": cpu_py},
            "ratio": t_py / t_mc, "cpu_ratio": cpu_py / cpu_mc, "max_difference": worst, "difference": diff,
            "numba_threads": __import__("numba").get_num_threads(), "loadavg_before": load_before,
            "loadavg_after": load_after,
        }, indent=2, default=lambda o: None))


if __name__ == "__main__":
    main()
