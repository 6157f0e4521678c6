"""Benchmark: exact time responses of delay systems (``DelayLTI.step``, ``step_response_many``) against a SciPy
method of steps written by hand.

Rows (issue 21's targets in brackets):

* one 2x2 closed-loop step response: the Wood-Berry column under Luyben's decentralised PI (BLT tuning), 100 min,
  201 times, both input columns; delaykit's exact kernel against SciPy's DOP853 integrating the same closed loop
  interval by interval (every delay is a whole number of minutes, so each one-minute interval is free of
  breakpoints; the delayed commands are read from the dense outputs of the earlier intervals), at rtol 1e-10 and
  atol 1e-12 (its difference from the exact answer is printed) [at least 50x], and against jitcdde at rtol 1e-8
  and 1e-10 (its errors printed: it cannot reach the exact answer's rounding) [at least 20x at equal accuracy];
  the anchors are ``benchmarks/anchors_systems.py``'s;
* ``--many N`` such responses with the PI gains varied (+-30 %), in parallel threads [10,000 under 5 s on two
  cores]: the systems' construction by the algebra is timed apart (wall and CPU time, each loop built from text
  by ``anchors_systems.wood_berry_loop`` as a user writes it, and again with the plant built once and only the
  controller per loop, ``feedback(G * K, 1)``), and the table gives build + responses together.

Times are the least CPU time of the calling thread over ``--repeat`` runs for single responses; the batch gives its
wall time and the process's CPU time, with the load average (the machine may be shared: the ratio, taken side by
side, is the figure to read).

Run: ``python benchmarks/bench_systems.py [--repeat 5] [--many 10000] [--quick] [--json FILE] [--write-docs]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console
from rich.table import Table

from delaykit import feedback, tf
from delaykit.simulate.systems import step_response_many

sys.path.insert(0, str(Path(__file__).resolve().parent))
from anchors_systems import (KC, TAU_I, JitcddeAnchor, scipy_method_of_steps, wood_berry_loop,  # noqa: E402
                             wood_berry_plant)
from _docs import write_docs  # noqa: E402
from bench_native import best  # noqa: E402  (least CPU time of this thread over repeated calls)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--many", type=int, default=10_000)
    ap.add_argument("--quick", action="store_true", help="200 systems in the batch, 1 SciPy run")
    ap.add_argument("--json", type=str, default=None)
    ap.add_argument("--no-jitcdde", action="store_true", help="leave out jitcdde (it compiles C code first)")
    ap.add_argument("--write-docs", action="store_true",
                    help="write the table into its block of docs/benchmarks.md (the rest of the page is kept)")
    args = ap.parse_args(argv)
    many = 200 if args.quick else args.many
    console = Console()
    t = np.linspace(0.0, 100.0, 201)
    T = wood_berry_loop()
    T.step(t)  # the first call (the extension's import) apart
    dk, exact = best(lambda: T.step(t), args.repeat)
    sp, mos = best(lambda: scipy_method_of_steps(t)[1], 1 if args.quick else max(1, args.repeat // 2))
    rows = [{"case": "Wood-Berry PI, 2x2 step, 100 min, 201 times", "anchor": "SciPy DOP853 method of steps, rtol 1e-10",
             "delaykit_ms": dk * 1e3, "anchor_ms": sp * 1e3, "ratio": sp / dk,
             "anchor_error": float(np.abs(mos - exact.outputs).max()), "pieces": exact.pieces, "status": exact.status}]
    if not args.no_jitcdde:
        jit = JitcddeAnchor()  # compiled once, not timed
        for rtol in (1e-8, 1e-10):
            tj, yj = best(lambda rtol=rtol: jit.run(t, rtol=rtol, atol=rtol * 1e-2)[1], args.repeat)
            rows.append({"case": "Wood-Berry PI, 2x2 step, 100 min, 201 times", "anchor": f"jitcdde, rtol {rtol:g}",
                         "delaykit_ms": dk * 1e3, "anchor_ms": tj * 1e3, "ratio": tj / dk,
                         "anchor_error": float(np.abs(yj - exact.outputs).max()), "pieces": exact.pieces,
                         "status": exact.status})
    rng = np.random.default_rng(0)
    gains = [(KC[0] * rng.uniform(0.7, 1.3), KC[1] * rng.uniform(0.7, 1.3)) for _ in range(many)]
    c0, b0 = time.perf_counter(), time.process_time()
    loops = [wood_berry_loop(kc=kc) for kc in gains]
    build, build_cpu = time.perf_counter() - c0, time.process_time() - b0
    plant = wood_berry_plant()  # the plant once, the PI controllers as (num, den) pairs per loop
    b0 = time.process_time()
    again = [feedback(plant * tf([[([k[0] * TAU_I[0], k[0]], [TAU_I[0], 0.0]), 0],
                                  [0, ([k[1] * TAU_I[1], k[1]], [TAU_I[1], 0.0])]], inputs=["e1", "e2"],
                                 outputs=["R", "S"]), 1) for k in gains]
    prebuilt_cpu = time.process_time() - b0
    same = all(np.allclose(a.evaluate([0.1j]), b.evaluate([0.1j]), rtol=1e-12, atol=1e-14)
               for a, b in zip(loops[:: max(1, many // 20)], again[:: max(1, many // 20)]))
    w0, p0 = time.perf_counter(), time.process_time()
    batch = step_response_many(loops, t)
    wall, cpu = time.perf_counter() - w0, time.process_time() - p0
    check = [0, many // 2, many - 1]
    diff = max(float(np.abs(loops[k].step(t).outputs - batch.outputs[k]).max()) for k in check)
    rows.append({"case": f"{many} Wood-Berry PI loops (gains +-30 %), step_response_many", "wall_s": wall,
                 "cpu_s": cpu, "build_s": build, "build_cpu_s": build_cpu, "build_ms_each": build_cpu / many * 1e3,
                 "build_prebuilt_plant_cpu_s": prebuilt_cpu, "prebuilt_plant_same_loops": same,
                 "build_and_responses_s": build + wall, "threads": os.cpu_count(), "load": os.getloadavg()[0],
                 "not_exact": sum(s != "exact" for s in batch.status), "difference_from_one_by_one": diff})
    table = Table(title="Exact time responses of delay systems (CPU time, side by side)")
    for col in ("case", "anchor", "delaykit", "anchor time", "ratio", "notes"):
        table.add_column(col)
    for r in rows[:-1]:
        table.add_row(r["case"], r["anchor"], f"{r['delaykit_ms']:.2f} ms", f"{r['anchor_ms']:.1f} ms",
                      f"{r['ratio']:.0f}x", f"delaykit {r['pieces']} pieces, {r['status']}; the anchor is off by "
                      f"{r['anchor_error']:.1e}")
    r1 = rows[-1]
    table.add_row(r1["case"], "", f"{r1['wall_s']:.2f} s wall, {r1['cpu_s']:.2f} s CPU", "", "",
                  f"{r1['threads']} threads, load {r1['load']:.1f}; {r1['not_exact']} not exact; equal to one by one "
                  f"within {r1['difference_from_one_by_one']:.0e}")
    table.add_row(f"building those {many} loops (wood_berry_loop, from text)", "",
                  f"{r1['build_s']:.2f} s wall, {r1['build_cpu_s']:.2f} s CPU", "", "",
                  f"{r1['build_ms_each']:.2f} ms CPU each; with the plant built once and only the controllers per "
                  f"loop {r1['build_prebuilt_plant_cpu_s']:.2f} s CPU (the same loops: "
                  f"{r1['prebuilt_plant_same_loops']})")
    table.add_row(f"build + responses, {many} loops", "", f"{r1['build_and_responses_s']:.2f} s wall", "", "",
                  "the user's whole wait for the sweep")
    console.print(table)
    if args.write_docs:
        write_docs(Path(__file__).name, table)
    result = {"rows": rows}
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(result, fh, indent=1)
    return result


if __name__ == "__main__":
    main()
