"""Benchmark: exact time responses of delay systems (``DelayLTI.step``, ``step_response_many``) against a SciPy
method of steps written by hand.

Rows (issue 21's targets in brackets):

* one 2x2 closed-loop step response: the Wood-Berry column under Luyben's decentralised PI (BLT tuning), 100 min,
  201 times, both input columns; delaykit's exact kernel against SciPy's DOP853 integrating the same closed loop
  interval by interval (every delay is a whole number of minutes, so each one-minute interval is free of
  breakpoints; the delayed commands are read from the dense outputs of the earlier intervals), at rtol 1e-10 and
  atol 1e-12 (its difference from the exact answer is printed) [at least 50x];
* ``--many N`` such responses with the PI gains varied (+-30 %), in parallel threads [10,000 under 5 s on two
  cores]: the systems' construction by the algebra is timed apart.

Times are the least CPU time of the calling thread over ``--repeat`` runs for single responses; the batch gives its
wall time and the process's CPU time, with the load average (the machine may be shared: the ratio, taken side by
side, is the figure to read).

Run: ``python benchmarks/bench_systems.py [--repeat 5] [--many 10000] [--quick] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from typing import Any, Callable

import numpy as np
from rich.console import Console
from rich.table import Table

from delaykit import feedback, tf
from delaykit.simulate.systems import step_response_many

# Wood & Berry (1973), minutes; Luyben (1986) BLT PI (as docs/guide/systems.md)
WB = [["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
      ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]]
GAIN = [[12.8, -18.9], [6.6, -19.4]]
LAG = [[16.7, 21.0], [10.9, 14.4]]
DEAD = [[1, 3], [7, 3]]
KC, TI = (0.375, -0.075), (8.29, 23.6)


def wood_berry_pi(kc: tuple[float, float] = KC, ti: tuple[float, float] = TI) -> Any:
    G = tf(WB, inputs=["R", "S"], outputs=["xD", "xB"])
    K = tf([[f"{kc[0]}*(1 + 1/({ti[0]}*s))", 0], [0, f"{kc[1]}*(1 + 1/({ti[1]}*s))"]], inputs=["e1", "e2"],
           outputs=["R", "S"])
    return feedback(G * K, 1)


def scipy_method_of_steps(t_eval: np.ndarray, rtol: float = 1e-10, atol: float = 1e-12) -> np.ndarray:
    """The closed loop's step responses ``(2, 2, nt)`` by DOP853 on [k, k + 1] min (see the module docstring).
    States: the four first-order entries x_ij, the two integrals of the errors."""
    from scipy.integrate import solve_ivp

    out = np.empty((2, 2, t_eval.size))
    for col in range(2):
        r = np.zeros(2)
        r[col] = 1.0
        sols: list[Any] = []

        def command(x: np.ndarray, r: np.ndarray = r) -> np.ndarray:
            e = r - np.array([x[0] + x[1], x[2] + x[3]])
            return np.array([KC[i] * (e[i] + x[4 + i] / TI[i]) for i in range(2)])

        def rhs(t: float, x: np.ndarray, k: int = 0, r: np.ndarray = r) -> np.ndarray:
            dx = np.empty(6)
            for i in range(2):
                for j in range(2):
                    src = k - DEAD[i][j]  # the interval read, ends included
                    u = 0.0 if src < 0 else command(sols[src].sol(t - DEAD[i][j]))[j]
                    dx[2 * i + j] = (-x[2 * i + j] + GAIN[i][j] * u) / LAG[i][j]
            dx[4:] = r - np.array([x[0] + x[1], x[2] + x[3]])
            return dx

        x = np.zeros(6)
        for k in range(int(math.ceil(t_eval[-1]))):
            sol = solve_ivp(rhs, (k, k + 1), x, method="DOP853", rtol=rtol, atol=atol, dense_output=True, args=(k,))
            sols.append(sol)
            x = sol.y[:, -1]
        for n, t in enumerate(t_eval):
            xs = sols[min(int(math.floor(t)), len(sols) - 1)].sol(t)
            out[:, col, n] = [xs[0] + xs[1], xs[2] + xs[3]]
    return out


def best(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    """Least CPU time of this thread over ``repeat`` calls, and the last result."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.thread_time()
        out = fn()
        times.append(time.thread_time() - t0)
    return min(times), out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--many", type=int, default=10_000)
    ap.add_argument("--quick", action="store_true", help="200 systems in the batch, 1 SciPy run")
    ap.add_argument("--json", type=str, default=None)
    args = ap.parse_args(argv)
    many = 200 if args.quick else args.many
    console = Console()
    t = np.linspace(0.0, 100.0, 201)
    T = wood_berry_pi()
    T.step(t)  # the first call (the extension's import) apart
    dk, exact = best(lambda: T.step(t), args.repeat)
    sp, mos = best(lambda: scipy_method_of_steps(t), 1 if args.quick else max(1, args.repeat // 2))
    rows = [{"case": "Wood-Berry PI, 2x2 step, 100 min, 201 times", "delaykit_ms": dk * 1e3, "scipy_ms": sp * 1e3,
             "ratio": sp / dk, "scipy_error": float(np.abs(mos - exact.outputs).max()),
             "pieces": exact.pieces, "status": exact.status}]
    rng = np.random.default_rng(0)
    c0 = time.perf_counter()
    loops = [wood_berry_pi(kc=(KC[0] * rng.uniform(0.7, 1.3), KC[1] * rng.uniform(0.7, 1.3))) for _ in range(many)]
    build = time.perf_counter() - c0
    w0, p0 = time.perf_counter(), time.process_time()
    batch = step_response_many(loops, t)
    wall, cpu = time.perf_counter() - w0, time.process_time() - p0
    check = [0, many // 2, many - 1]
    diff = max(float(np.abs(loops[k].step(t).outputs - batch.outputs[k]).max()) for k in check)
    rows.append({"case": f"{many} Wood-Berry PI loops (gains +-30 %), step_response_many", "wall_s": wall,
                 "cpu_s": cpu, "build_s": build, "threads": os.cpu_count(), "load": os.getloadavg()[0],
                 "not_exact": sum(s != "exact" for s in batch.status), "difference_from_one_by_one": diff})
    table = Table(title="Exact time responses of delay systems")
    for col in ("case", "delaykit", "SciPy MoS", "ratio", "notes"):
        table.add_column(col)
    r0 = rows[0]
    table.add_row(r0["case"], f"{r0['delaykit_ms']:.2f} ms", f"{r0['scipy_ms']:.0f} ms", f"{r0['ratio']:.0f}x",
                  f"{r0['pieces']} pieces, {r0['status']}; SciPy (rtol 1e-10) off by {r0['scipy_error']:.1e}")
    r1 = rows[1]
    table.add_row(r1["case"], f"{r1['wall_s']:.2f} s wall, {r1['cpu_s']:.2f} s CPU", "", "",
                  f"{r1['threads']} threads, load {r1['load']:.1f}; building the systems {r1['build_s']:.1f} s "
                  f"(not timed); {r1['not_exact']} not exact; equal to one by one within "
                  f"{r1['difference_from_one_by_one']:.0e}")
    console.print(table)
    result = {"rows": rows}
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(result, fh, indent=1)
    return result


if __name__ == "__main__":
    main()
