"""Benchmark: identification speed and answers, delaykit against the plain SciPy fit users write by hand.

Case 1: one 12 s log at 50 Hz, a step and a step back, a second-order plant plus dead time (four parameters:
gain, two time constants, delay), 5 mm noise.  Case 2: 20 such logs pooled (one plant, each log its own steps).
delaykit: ``identify(model="sopdt")``.  The anchor: ``scipy.optimize.least_squares`` on ``scipy.signal.lsim`` of
the same model, the delay applied by shifting the input (``np.interp`` of the held input at ``t - delay``),
from the same true-value-free start, on the same data.  Both answers (every parameter) are printed beside the
truth.  The anchor interpolates the held input linearly between samples, which delays it by half a sample on
average: its delay comes out about ``h / 2 = 0.01`` s long.

Both are timed in the same process, one after the other: CPU time (``time.process_time``, every thread of the
process) and wall time, the best of ``--repeat`` each.  On a shared machine the CPU times and their ratio are the
figures to read; the wall times move with the load.  The title says which kernels ran (the extension modules
Cython built at install, or numba's compilation of the same source with ``DELAYKIT_KERNELS=numba``).

Run: ``python benchmarks/bench_identify.py [--logs 20] [--repeat 3] [--json FILE]``.  Targets (issue #10): one log
under 50 ms, 20 logs under 1 s (wall time, best of ``--repeat``, on a quiet machine).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
from rich.console import Console
from rich.table import Table
from scipy.optimize import least_squares
from scipy.signal import lsim

from delaykit.identify import Experiment, _fit, identify
from delaykit.identify.structures import STRUCTURES
from delaykit.simulate.discrete import held_delay_model, held_response

from _docs import write_docs

TRUTH = {"gain": 0.8, "time_constant": 0.6, "time_constant2": 0.15, "delay": 0.12}
H = 0.02


def logs(n: int, seed: int = 3) -> list[Experiment]:
    rng = np.random.default_rng(seed)
    t = np.arange(600) * H
    plant = STRUCTURES["sopdt"].plant([TRUTH[k] for k in STRUCTURES["sopdt"].params])
    m = held_delay_model(plant, H, TRUTH["delay"])
    out = []
    for i in range(n):
        a, b = rng.uniform(1.0, 3.0), rng.uniform(6.0, 8.0)
        u = np.where((t >= a) & (t < b), rng.uniform(0.5, 1.5), 0.0)
        y = 1.0 + held_response(m, u).y + rng.normal(0, 0.005, t.size)
        out.append(Experiment.from_arrays(t, {"y": y}, u=u, name=f"log{i}"))
    return out


def timed(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> tuple[Any, float, float]:
    """``fn(*args, **kwargs)`` and its (CPU, wall) seconds."""
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.process_time() - c0, time.perf_counter() - t0


def scipy_fit(exps: list[Experiment]) -> np.ndarray:
    """What a user writes today: lsim inside least_squares, the delay by shifting the input."""
    def res(p):
        K, t1, t2, d = p
        out = []
        for e in exps:
            y0 = e.outputs["y"][: e.onset].mean()
            ud = np.interp(e.t - d, e.t, e.u, left=0.0)
            _, y, _ = lsim(([K], [t1 * t2, t1 + t2, 1.0]), ud, e.t - e.t[0])
            out.append(e.outputs["y"] - y0 - y)
        return np.concatenate(out)

    return least_squares(res, [1.0, 0.5, 0.05, 0.05], bounds=([-10, 1e-3, 1e-3, 0.0], [10, 10, 10, 2.0])).x


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", default=None)
    ap.add_argument("--write-docs", action="store_true",
                    help="replace this script's tables in docs/benchmarks.md (between its markers)")
    a = ap.parse_args()
    identify(logs(1)[0], model="sopdt")  # compile and cache the kernels before timing (numba's copy)
    mode = "cython" if _fit.FK.COMPILED else _fit.FK.__name__.rpartition("_")[2]  # (DELAYKIT_KERNELS)
    kernels = "the extension modules built by Cython" if mode == "cython" else f"the kernels' source run by {mode}"
    rows = {}
    for label, exps in (("one 12 s log", logs(1)), (f"{a.logs} logs pooled", logs(a.logs))):
        runs = [timed(identify, exps, model="sopdt", per_log=False) for _ in range(a.repeat)]
        m = runs[-1][0]
        ref_runs = [timed(scipy_fit, exps) for _ in range(a.repeat)]
        ref = ref_runs[-1][0]
        cpu, wall = min(r[1] for r in runs), min(r[2] for r in runs)
        ref_cpu, ref_wall = min(r[1] for r in ref_runs), min(r[2] for r in ref_runs)
        rows[label] = {
            "delaykit": {"time": wall, "cpu": cpu, "params": m.params, "stderr": m.stderr},
            "scipy": {"time": ref_wall, "cpu": ref_cpu,
                      "params": dict(zip(STRUCTURES["sopdt"].params, map(float, ref)))},
            "ratio": ref_wall / wall,
            "ratio_cpu": ref_cpu / cpu,
        }
    params = STRUCTURES["sopdt"].params
    table = Table(title="Identification (sopdt: gain, two time constants, delay), best of "
                        f"{a.repeat}, CPU time (wall time); {kernels}; truth "
                        + ", ".join(f"{k} {v:g}" for k, v in TRUTH.items()))
    for col in ("case", "delaykit", "SciPy lsim + least_squares", "SciPy / delaykit", "delaykit answer (± s.e.)",
                "SciPy answer"):
        table.add_column(col, justify="right")

    def ms(t: float) -> str:
        return f"{t * 1e3:.1f} ms" if t < 1 else f"{t:.2f} s"

    for label, r in rows.items():
        mine = "\n".join(f"{k} {r['delaykit']['params'][k]:.4f} ± {r['delaykit']['stderr'][k]:.4f}" for k in params)
        ref = "\n".join(f"{k} {r['scipy']['params'][k]:.4f}" for k in params)
        table.add_row(label, f"{ms(r['delaykit']['cpu'])} ({ms(r['delaykit']['time'])})",
                      f"{ms(r['scipy']['cpu'])} ({ms(r['scipy']['time'])})",
                      f"{r['ratio_cpu']:.0f}x ({r['ratio']:.0f}x)", mine, ref)
    Console(width=140).print(table)
    if a.write_docs:
        write_docs(Path(__file__).name, table)
    result = {"truth": TRUTH, "kernels": mode, "cases": rows,
              "targets": {"one_log_s": 0.05, "pooled_s": 1.0},
              "targets_met": {"one_log": rows["one 12 s log"]["delaykit"]["time"] < 0.05,
                              "pooled": rows[f"{a.logs} logs pooled"]["delaykit"]["time"] < 1.0}}
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(result, fh, indent=2, default=float)
    return result


if __name__ == "__main__":
    main()
