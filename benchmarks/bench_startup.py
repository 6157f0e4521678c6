"""Benchmark: how long the ``delaykit`` command line takes, start to exit, once the compiled kernels are cached.

Each command runs in a fresh subprocess (so every run pays Python's start-up, the imports and, where a command
needs them, the loading of the cached numba kernels, as a user does), first once untimed to fill numba's cache,
then ``--runs`` times; the table gives the median, fastest and slowest wall times and the median CPU time (user +
system, all threads) of the process. The commands: ``delaykit --help``; ``simulate`` of the paper's loop (Kp =
1.31, delay 0.368 s) and of a general loop (the plant 1/(s(0.05 s + 1)), PD control with a filtered derivative,
limits -1 and 3, a step of -1), both with ``--json``; and ``margins`` and ``roots`` of the paper's loop. The
issue's target is 0.5 s for ``--help`` and both ``simulate`` commands. A first row, ``python -c pass``, is the
interpreter's own start-up, for scale.

Then, for ``--help`` and the two ``simulate`` commands, one more run under ``python -X importtime`` gives where
the imports' time goes: the self time of every module imported, summed by top-level package (the standard
library as one), and whether the heavy packages a short simulation must not need (numba, SciPy, matplotlib,
pydantic, rich's console) were imported at all. Those times are of one run, with the profiler's overhead.

Where ``PYTHONDONTWRITEBYTECODE`` is set, Python compiles every delaykit module from source on every run (some
0.1 s); ``--pycache-prefix DIR`` lets the commands cache their bytecode under DIR instead (not in the source tree),
as an ordinary installation does. Other work on the machine slows every run: compare figures taken side by side.

With ``--first-calls``, the issue-24 table instead: the first call after an install, each in a fresh process with
an empty numba cache (``NUMBA_CACHE_DIR`` pointed at a new temporary directory, so the tree's own cache is neither
used nor disturbed), then the same command once more with that cache filled (warm); the process's CPU time (user
and system, all threads) is given beside the wall time, being far less inflated by other work on the machine. The calls: ``simulate_many``
of the paper's 10,000 P loops (Kp = 1.31, delays uniform in [0.2, 0.5] s; import included), ``delaykit identify``
of the heater log (read from ../shared/data beside the project, or $DELAYKIT_DATA: tests/shared_data.py), ``margins`` and ``roots`` of the paper's loop, and the Smith design of
``1/s`` with delay 0.37 s. Each row gives the cold and warm wall times against the issue's targets; compiled
(ahead-of-time) kernels need no cache, so for them cold and warm differ only by the disk cache.

Run: ``python benchmarks/bench_startup.py [--runs 7] [--only NAME,...] [--pycache-prefix DIR] [--json FILE]``;
``python benchmarks/bench_startup.py --first-calls [--runs 1] [--only NAME,...] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from rich.console import Console
from rich.table import Table

LOOP = ["--kp", "1.31", "--delay", "0.368", "--json"]
GENERAL = ["--plant", "1/(s*(0.05*s+1))", "--delay", "0.3", "--controller", "pd", "--kp", "2", "--kd", "0.1",
           "--derivative-filter", "0.02", "--umin", "-1", "--umax", "3", "--step", "-1", "--json"]
COMMANDS = {
    "help": ["--help"],
    "simulate": ["simulate", *LOOP],
    "simulate-general": ["simulate", *GENERAL],
    "margins": ["margins", *LOOP],
    "roots": ["roots", *LOOP],
}
TARGET = {"help": 0.5, "simulate": 0.5, "simulate-general": 0.5}  # seconds, from the issue
BREAKDOWN = ("help", "simulate", "simulate-general")  # the commands whose imports are broken down
HEAVY = ("numba", "scipy", "matplotlib", "pydantic", "rich.console")  # not needed by a short simulation
PACKAGES = ("numpy", "typer", "rich", "pydantic", "delaykit", "numba", "scipy", "matplotlib")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from shared_data import DATA, absent_reason  # noqa: E402  (where the real data is read: ../shared/data)

HEATER = DATA / "tclab" / "step_test.csv"
P_LOOPS = ("import time; t0 = time.perf_counter(); import numpy as np, delaykit as dk; "
           "td = np.random.default_rng(2024).uniform(0.2, 0.5, 10_000); "
           "b = dk.simulate_many(dk.AltitudeLoop(kp=1.31, delay=0.3), delay=td); "
           "assert b.overshoot.shape == (10_000,); print(time.perf_counter() - t0)")
FIRST_CALLS = {  # name: (argv after the interpreter or the delaykit command, whether it is delaykit's CLI)
    "simulate_many": (["-c", P_LOOPS], False),
    "identify": (["identify", str(HEATER), "--u-before", "0", "--model", "auto", "--json"], True),
    "margins": (["margins", *LOOP], True),
    "roots": (["roots", *LOOP], True),
    "smith": (["design", "--plant", "1/s", "--delay", "0.37", "--compensator", "smith", "--json"], True),
}
FIRST_TARGET = {"simulate_many": (5.0, None), "identify": (5.0, 1.0), "margins": (2.0, None), "roots": (2.0, None),
                "smith": (5.0, None)}  # (cold, warm) seconds, from issue 24
_IMPORT_LINE = re.compile(r"import time:\s+(\d+) \|\s+(\d+) \| (\s*)(\S+)")


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


def import_breakdown(args: list[str], env: dict[str, str]) -> dict[str, object]:
    """One run of ``delaykit ARGS`` under ``python -X importtime``: the imports' self time (s) by top-level
    package (the standard library as ``stdlib``), the total, the module count and which heavy packages loaded."""
    code = "import sys; from delaykit.cli import main; sys.argv[0] = 'delaykit'; main()"
    proc = subprocess.run([sys.executable, "-X", "importtime", "-c", code, *args], capture_output=True, text=True,
                          env=env)
    if proc.returncode != 0:
        raise SystemExit(f"delaykit {' '.join(args)} failed under -X importtime:\n{proc.stderr[-2000:]}")
    by: Counter[str] = Counter()
    names: set[str] = set()
    for line in proc.stderr.splitlines():
        m = _IMPORT_LINE.match(line)
        if not m:
            continue
        name = m.group(4)
        names.add(name)
        top = name.split(".")[0]
        stdlib = top in sys.stdlib_module_names or top.lstrip("_") in sys.stdlib_module_names or \
            top in sys.builtin_module_names
        by["stdlib" if stdlib else top] += int(m.group(1))
    return {"self_time": {k: v / 1e6 for k, v in by.most_common()}, "total": sum(by.values()) / 1e6,
            "modules": len(names), "heavy_loaded": {h: h in names for h in HEAVY}}


def first_calls(names: list[str], runs: int, json_path: Path | None) -> None:
    """The issue-24 table: each call cold (a fresh, empty numba cache) and then warm (that cache), fresh processes."""
    base = delaykit_command()
    results = {}
    for name in names:
        tail, cli = FIRST_CALLS[name]
        argv = (base + tail) if cli else [sys.executable, *tail]
        cold, warm = [], []
        for _ in range(runs):
            with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache:
                env = {**os.environ, "NUMBA_CACHE_DIR": cache}
                cold.append(run_once(argv, env))
                warm.append(run_once(argv, env))
        results[name] = {"command": " ".join(["delaykit" if cli else "python", *tail[:1 if not cli else None]]),
                         "cold": statistics.median(w for w, _ in cold), "warm": statistics.median(w for w, _ in warm),
                         "cold_cpu": statistics.median(c for _, c in cold),
                         "warm_cpu": statistics.median(c for _, c in warm), "runs": runs,
                         "cold_target": FIRST_TARGET[name][0], "warm_target": FIRST_TARGET[name][1]}
    console = Console(width=max(Console().width, 120))
    table = Table(title=f"First calls in fresh processes (issue 24): empty numba cache, then warm "
                        f"(median of {runs}; load {os.getloadavg()[0]:.1f})")
    for col in ("call", "cold s", "target s", "warm s", "warm target s", "cold CPU s", "warm CPU s"):
        table.add_column(col, justify="left" if col == "call" else "right", overflow="fold")
    for name, r in results.items():
        wt = r["warm_target"]
        table.add_row(name, f"{r['cold']:.2f}", f"{r['cold_target']:.1f}", f"{r['warm']:.2f}",
                      "–" if wt is None else f"{wt:.1f}", f"{r['cold_cpu']:.2f}", f"{r['warm_cpu']:.2f}")
    console.print(table)
    if json_path is not None:
        doc = {"python": sys.version.split()[0], "load": os.getloadavg(), "first_calls": results}
        json_path.write_text(json.dumps(doc, indent=2) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first-calls", action="store_true",
                    help="Time the issue-24 first calls (empty numba cache, then warm) instead of the start-up.")
    ap.add_argument("--runs", type=int, default=None,
                    help="Timed runs per command (after one untimed warm-up run); default 7, with --first-calls 1.")
    ap.add_argument("--only", default=None,
                    help=f"Comma-separated commands to time, of {', '.join(COMMANDS)} (default: all).")
    ap.add_argument("--json", type=Path, default=None, help="Also write the results here as JSON.")
    ap.add_argument("--pycache-prefix", type=Path, default=None,
                    help="Cache the commands' bytecode under this directory (PYTHONPYCACHEPREFIX), even where "
                         "PYTHONDONTWRITEBYTECODE is set.")
    args = ap.parse_args()
    if args.runs is None:
        args.runs = 1 if args.first_calls else 7
    if args.runs < 1:
        ap.error("--runs must be at least 1")
    if args.first_calls:
        picked = list(FIRST_CALLS) if args.only is None else [n.strip() for n in args.only.split(",") if n.strip()]
        if not picked or any(n not in FIRST_CALLS for n in picked):
            ap.error(f"with --first-calls, --only takes names of {', '.join(FIRST_CALLS)}; got {args.only!r}")
        if "identify" in picked and not HEATER.exists():
            ap.error(f"{absent_reason(HEATER)} (leave it out: --only with the other names)")
        first_calls(picked, args.runs, args.json)
        return
    names = list(COMMANDS) if args.only is None else [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in names if n not in COMMANDS]
    if unknown or not names:
        ap.error(f"--only takes names of {', '.join(COMMANDS)}; got {args.only!r}")
    env = dict(os.environ)
    if args.pycache_prefix is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(args.pycache_prefix.resolve())
    bytecode = "compiled from source every run" if env.get("PYTHONDONTWRITEBYTECODE") else "cached"
    base = delaykit_command()
    results = {}
    plan = [("python -c pass", [sys.executable, "-c", "pass"], None)]
    plan += [(name, base + COMMANDS[name], name) for name in names]
    for label, argv, name in plan:
        run_once(argv, env)  # warm-up: fills numba's cache (and the bytecode cache, if any)
        runs = [run_once(argv, env) for _ in range(args.runs)]
        times = [wall for wall, _ in runs]
        command = "python -c pass" if name is None else " ".join(["delaykit", *COMMANDS[name]])
        results[label] = {"command": command, "runs": args.runs, "median": statistics.median(times),
                          "min": min(times), "max": max(times),
                          "cpu_median": statistics.median(cpu for _, cpu in runs), "target": TARGET.get(label)}
    breakdown = {name: import_breakdown(COMMANDS[name], env) for name in names if name in BREAKDOWN}

    console = Console(width=max(Console().width, 110))
    table = Table(title=f"delaykit start-up, wall time of a fresh process ({args.runs} runs each, kernels cached, "
                        f"bytecode {bytecode})")
    for col in ("command", "median s", "min s", "max s", "CPU median s", "target s"):
        table.add_column(col, justify="left" if col == "command" else "right", overflow="fold")
    for r in results.values():
        target = "–" if r["target"] is None else f"{r['target']:.1f}"
        table.add_row(r["command"], f"{r['median']:.3f}", f"{r['min']:.3f}", f"{r['max']:.3f}",
                      f"{r['cpu_median']:.3f}", target)
    console.print(table)
    if breakdown:
        seen = {g for b in breakdown.values() for g in b["self_time"]}  # type: ignore[attr-defined]
        others = sorted(seen - set(PACKAGES) - {"stdlib"},
                        key=lambda g: -max(b["self_time"].get(g, 0.0) for b in breakdown.values()))  # type: ignore
        groups = [g for g in PACKAGES if g in seen] + others + ["stdlib"]
        imp = Table(title="Imports, self time by package (s; one run under python -X importtime)")
        imp.add_column("package")
        for name in breakdown:
            imp.add_column(name, justify="right")
        for g in groups:
            imp.add_row(g, *(f"{b['self_time'].get(g, 0.0):.3f}"  # type: ignore[attr-defined]
                             for b in breakdown.values()))
        imp.add_row("all imports", *(f"{b['total']:.3f}" for b in breakdown.values()))
        imp.add_row("modules", *(str(b["modules"]) for b in breakdown.values()))
        for h in HEAVY:
            imp.add_row(f"{h} loaded", *("yes" if b["heavy_loaded"][h] else "no"  # type: ignore[index]
                                         for b in breakdown.values()))
        console.print(imp)
    if args.json is not None:
        doc = {"python": sys.version.split()[0], "bytecode": bytecode, "commands": results, "imports": breakdown}
        args.json.write_text(json.dumps(doc, indent=2) + "\n")


if __name__ == "__main__":
    main()
