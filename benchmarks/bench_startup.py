"""Benchmark: how long the ``delaykit`` command line takes, start to exit, once the compiled kernels are cached.

Each command runs in a fresh subprocess (so every run pays Python's start-up, the imports and the loading of the
cached numba kernels, as a user does), first once untimed to fill numba's cache, then ``--runs`` times; the table
gives the median, fastest and slowest wall times and the median CPU time (user + system, all threads) of the
process. The commands: ``delaykit --help``, and ``simulate``, ``margins`` and ``roots`` of the paper's loop
(Kp = 1.31, delay 0.368 s) with ``--json``. The issue's target is 0.5 s for ``--help`` and ``simulate``.

Where ``PYTHONDONTWRITEBYTECODE`` is set, Python compiles every delaykit module from source on every run (some
0.1 s); ``--pycache-prefix DIR`` lets the commands cache their bytecode under DIR instead (not in the source tree),
as an ordinary installation does. Other work on the machine slows every run: compare figures taken side by side.

Run: ``python benchmarks/bench_startup.py [--runs 7] [--pycache-prefix DIR] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

LOOP = ["--kp", "1.31", "--delay", "0.368", "--json"]
COMMANDS = {
    "--help": ["--help"],
    "simulate": ["simulate", *LOOP],
    "margins": ["margins", *LOOP],
    "roots": ["roots", *LOOP],
}
TARGET = {"--help": 0.5, "simulate": 0.5}  # seconds, from the issue


def delaykit_command() -> list[str]:
    """The ``delaykit`` console script beside this Python, else ``python -m delaykit.cli``."""
    script = Path(sys.executable).with_name("delaykit")
    if script.exists():
        return [str(script)]
    found = shutil.which("delaykit")
    return [found] if found else [sys.executable, "-m", "delaykit.cli"]


def run_once(argv: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall time, CPU time) of one run, s; the run must succeed (and print JSON when asked)."""
    before = os.times()
    t0 = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True, env=env)
    elapsed = time.perf_counter() - t0
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed with status {proc.returncode}:\n{proc.stderr}")
    if "--json" in argv:
        json.loads(proc.stdout)  # the output is what the command promises
    return elapsed, cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7, help="Timed runs per command (after one untimed warm-up run).")
    ap.add_argument("--json", type=Path, default=None, help="Also write the results here as JSON.")
    ap.add_argument("--pycache-prefix", type=Path, default=None,
                    help="Cache the commands' bytecode under this directory (PYTHONPYCACHEPREFIX), even where "
                         "PYTHONDONTWRITEBYTECODE is set.")
    args = ap.parse_args()
    if args.runs < 1:
        ap.error("--runs must be at least 1")
    env = dict(os.environ)
    if args.pycache_prefix is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(args.pycache_prefix.resolve())
    bytecode = "compiled from source every run" if env.get("PYTHONDONTWRITEBYTECODE") else "cached"
    base = delaykit_command()
    results = {}
    for name, extra in COMMANDS.items():
        argv = base + extra
        run_once(argv, env)  # warm-up: fills numba's cache (and the bytecode cache, if any)
        runs = [run_once(argv, env) for _ in range(args.runs)]
        times = [wall for wall, _ in runs]
        results[name] = {"command": " ".join(["delaykit", *extra]), "runs": args.runs,
                         "median": statistics.median(times), "min": min(times), "max": max(times),
                         "cpu_median": statistics.median(cpu for _, cpu in runs), "target": TARGET.get(name)}
    table = Table(title=f"delaykit start-up, wall time of a fresh process ({args.runs} runs each, kernels cached, "
                        f"bytecode {bytecode})")
    for col in ("command", "median s", "min s", "max s", "CPU median s", "target s"):
        table.add_column(col, justify="left" if col == "command" else "right")
    for r in results.values():
        target = "–" if r["target"] is None else f"{r['target']:.1f}"
        table.add_row(r["command"], f"{r['median']:.3f}", f"{r['min']:.3f}", f"{r['max']:.3f}",
                      f"{r['cpu_median']:.3f}", target)
    Console(width=max(Console().width, 110)).print(table)
    if args.json is not None:
        doc = {"python": sys.version.split()[0], "bytecode": bytecode, "commands": results}
        args.json.write_text(json.dumps(doc, indent=2) + "\n")


if __name__ == "__main__":
    main()
