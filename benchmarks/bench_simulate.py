"""Benchmark: 10,000 P loops (Kp = 1.31, Td uniform in [0.2, 0.5] s, 15 s each), all four step metrics.

delaykit's exact batch simulator against jitcdde (an adaptive Bogacki-Shampine DDE solver compiled to C),
side by side in this one process.  Both must reach the accuracy target first: overshoot within 1e-3
percentage points and peak, rise and settling times within 1 ms of an independent reference (the test
suite's DOP853 method-of-steps solver, tests/oracle.py) on a random subset of the loops.  jitcdde is run
at the loosest tolerance that meets the target, and its saturation is its own smoothed `conditional`
(width 1e-5), since it has no event location; its metrics are read off its own dense output (the cubic
Hermite spline through its anchors: extrema and threshold crossings solved exactly on it, vectorised), not
off a sampling grid.  Compile
times are reported apart.

Run: ``make bench`` (or ``python benchmarks/bench_simulate.py [--loops N] [--reference M]``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import delaykit as dk  # noqa: E402
from _docs import write_docs  # noqa: E402
from oracle import Oracle  # noqa: E402

KP = 1.31
KEYS = ("overshoot", "peak_time", "rise_time", "settling_time")
TARGET = {"overshoot": 1e-3, "peak_time": 1e-3, "rise_time": 1e-3, "settling_time": 1e-3}


def errors(got: dict[str, np.ndarray], ref: dict[str, np.ndarray]) -> dict[str, float]:
    """Largest absolute difference per metric; inf where a value exists in one and not the other."""
    out = {}
    for k in KEYS:
        a, b = np.asarray(got[k], float), np.asarray(ref[k], float)
        both_nan = np.isnan(a) & np.isnan(b)
        diff = np.where(both_nan, 0.0, np.abs(a - b))
        out[k] = float(np.max(np.where(np.isnan(diff), np.inf, diff)))
    return out


def agreement(got: dict[str, np.ndarray], ref: dict[str, np.ndarray]) -> tuple[dict[str, float], int]:
    """Largest difference where both define a value, and how many loops define it in only one.

    Peak times are compared only where the overshoot is at least 1e-3 percentage points: below that the
    maximum is micrometres high and seconds wide, and its time is ill-conditioned for any solver.
    """
    out, mismatched = {}, 0
    for k in KEYS:
        a, b = np.asarray(got[k], float), np.asarray(ref[k], float)
        both = ~np.isnan(a) & ~np.isnan(b)
        if k == "peak_time":
            both &= np.asarray(ref["overshoot"]) >= 1e-3
        mismatched += int(np.count_nonzero(np.isnan(a) != np.isnan(b)))
        out[k] = float(np.max(np.abs(a[both] - b[both]))) if np.any(both) else 0.0
    return out, mismatched


def meets(err: dict[str, float]) -> bool:
    return all(err[k] <= TARGET[k] for k in KEYS)


class Jit:
    """jitcdde's model of the same loop, in jitcdde's time tau = t - Td (the command reaches the plant at Td)."""

    def __init__(self) -> None:
        import symengine
        from jitcdde import jitcdde, t, y
        from jitcxde_common.symbolic import conditional

        kp, td = symengine.symbols("kp td")
        x = kp * (1 - y(0, t - td))
        sat = conditional(x, 1.0, conditional(x, -1.0, -1.0, x), 1.0)
        cwd = os.getcwd()
        with tempfile.TemporaryDirectory() as tmp:
            os.chdir(tmp)  # jitcdde builds with setuptools in the working directory
            try:
                t0 = time.perf_counter()
                self.dde = jitcdde([sat], control_pars=[kp, td], max_delay=16.0, verbose=False)
                self.dde.compile_C(simplify=False, do_cse=False, verbose=False)
                self.compile_time = time.perf_counter() - t0
            finally:
                os.chdir(cwd)

    def metrics(self, td: float, rtol: float) -> dict[str, float]:
        """Metrics read off jitcdde's own dense solution (its cubic Hermite spline), with no sampling grid."""
        dde = self.dde
        dde.purge_past()
        dde.constant_past([0.0], time=0.0)
        dde.set_parameters(KP, td)
        dde.set_integration_parameters(rtol=rtol, atol=rtol * 1e-2, first_step=1e-4, min_step=1e-12, max_step=0.05)
        dde.adjust_diff()
        tau_end = 15.0 - td
        dde.integrate(tau_end)
        anchors = dde.get_state()  # the whole past is kept: max_delay covers the run
        t = np.array([a[0] for a in anchors])
        keep = t >= 0.0
        spl = HermiteSpline(t[keep], np.array([a[1][0] for a in anchors])[keep],
                            np.array([a[2][0] for a in anchors])[keep])
        return spline_metrics(spl, td)


def spline_metrics(spl: "HermiteSpline", td: float) -> dict[str, float]:
    """The four step metrics solved exactly on a unit-step response's spline, in jitcdde's time shifted by td."""
    wmax, tmax = spl.maximum()
    out = {"overshoot": max(0.0, wmax - 1.0) * 100.0, "peak_time": tmax + td if wmax > 1.0 else math.nan}
    t10, t90 = spl.crossings(0.1), spl.crossings(0.9)
    out["rise_time"] = (t90[0] - t10[0]) if t10.size and t90.size else math.nan
    if abs(spl.y[-1] - 1.0) >= 0.02:
        out["settling_time"] = math.nan
    else:
        hits = np.concatenate([spl.crossings(0.98), spl.crossings(1.02)])
        out["settling_time"] = float(hits.max()) + td
    return {k: out[k] for k in KEYS}


class HermiteSpline:
    """A cubic Hermite spline from anchors (t, y, y'), with exact extrema and level crossings (vectorised)."""

    def __init__(self, t: np.ndarray, y: np.ndarray, dy: np.ndarray) -> None:
        self.t, self.y = t, y
        h = np.diff(t)
        y0, y1, d0, d1 = y[:-1], y[1:], dy[:-1] * h, dy[1:] * h
        # y(s) = c0 + c1 s + c2 s^2 + c3 s^3 on s in [0, 1]
        self.c = np.stack([y0, d0, 3 * (y1 - y0) - 2 * d0 - d1, 2 * (y0 - y1) + d0 + d1], axis=1)
        self.h = h
        c1, c2, c3 = self.c[:, 1], self.c[:, 2], self.c[:, 3]
        a, b, cc = 3 * c3, 2 * c2, c1  # derivative a s^2 + b s + cc
        disc = np.maximum(b * b - 4 * a * cc, 0.0)
        sq = np.sqrt(disc)
        with np.errstate(divide="ignore", invalid="ignore"):
            r1 = np.where(a != 0, (-b - sq) / (2 * a), np.where(b != 0, -cc / b, 0.0))
            r2 = np.where(a != 0, (-b + sq) / (2 * a), 0.0)
        cand = np.stack([np.zeros_like(h), np.ones_like(h), np.clip(r1, 0, 1), np.clip(r2, 0, 1)], axis=1)
        cand = np.where(np.isfinite(cand), cand, 0.0)
        vals = self._eval(np.arange(h.size)[:, None], cand)
        self.seg_max, self.seg_min = vals.max(axis=1), vals.min(axis=1)
        self.arg = cand[np.arange(h.size), vals.argmax(axis=1)]

    def _eval(self, i: np.ndarray, s: np.ndarray) -> np.ndarray:
        c = self.c[i]
        return ((c[..., 3] * s + c[..., 2]) * s + c[..., 1]) * s + c[..., 0]

    def maximum(self) -> tuple[float, float]:
        i = int(np.argmax(self.seg_max))
        return float(self.seg_max[i]), float(self.t[i] + self.arg[i] * self.h[i])

    def crossings(self, level: float) -> np.ndarray:
        idx = np.flatnonzero((self.seg_min <= level) & (self.seg_max >= level))
        out = []
        for i in idx:
            for r in np.roots(self.c[i, ::-1] - np.array([0, 0, 0, level])):
                if abs(r.imag) < 1e-9 and -1e-12 <= r.real <= 1 + 1e-12:
                    out.append(self.t[i] + r.real * self.h[i])
        return np.unique(np.array(out))


def cold_compile_time() -> float:
    """Seconds for the first batch call in a new process with an empty numba cache (compilation)."""
    import subprocess

    code = ("import time, numpy as np, delaykit as dk; t0 = time.perf_counter(); "
            "dk.simulate_many(dk.AltitudeLoop(kp=1.31, delay=0.3), delay=np.array([0.3, 0.4])); "
            "print(time.perf_counter() - t0)")
    with tempfile.TemporaryDirectory() as tmp:
        env = {**os.environ, "NUMBA_CACHE_DIR": tmp}
        res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
    return float(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loops", type=int, default=10_000)
    ap.add_argument("--reference", type=int, default=20, help="loops checked against the reference solver")
    ap.add_argument("--jit-loops", type=int, default=None, help="loops jitcdde runs (default: all)")
    ap.add_argument("--json", type=Path, default=None, help="also write the results here")
    ap.add_argument("--no-cold", action="store_true", help="skip timing a cold compile")
    ap.add_argument("--write-docs", action="store_true",
                    help="replace this script's tables in docs/benchmarks.md (between its markers)")
    args = ap.parse_args()
    console = Console(width=110)
    rng = np.random.default_rng(2024)
    td = rng.uniform(0.2, 0.5, args.loops)

    # delaykit: a cold compile (empty numba cache, in a fresh process), then time the whole batch (best of 9: one
    # run is 70 ms, so a single scheduling hiccup on the shared machine moves it by half; the median is printed too)
    dk_cold = cold_compile_time() if not args.no_cold else math.nan
    t0 = time.perf_counter()
    paper = dk.AltitudeLoop(kp=KP, delay=0.3)
    dk.simulate_many(paper, delay=td[:2])
    dk_compile = time.perf_counter() - t0
    runs, cpu = [], []
    for _ in range(9):
        t0, c0 = time.perf_counter(), time.process_time()
        batch = dk.simulate_many(paper, delay=td)
        runs.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    dk_time = min(runs)
    dk_cpu = cpu[int(np.argmin(runs))]
    load = os.getloadavg()

    # the independent reference on a random subset
    ref_idx = rng.choice(args.loops, size=min(args.reference, args.loops), replace=False)
    with console.status(f"reference solver on {ref_idx.size} loops…"):
        ref_rows = [Oracle(kp=KP, td=float(td[i]), t_end=15.0).metrics() for i in ref_idx]
    ref = {k: np.array([r[k] for r in ref_rows]) for k in KEYS}
    dk_err = errors({k: getattr(batch, k)[ref_idx] for k in KEYS}, ref)

    # jitcdde
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        jit = Jit()
        # the loosest tolerance that meets the target on the reference loops and, against delaykit (itself
        # checked against the reference), on every loop jitcdde runs
        n_jit = args.jit_loops or args.loops
        dk_all = {k: getattr(batch, k)[:n_jit] for k in KEYS}
        chosen, tried = None, []
        for rtol in (1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10):
            rows = [jit.metrics(float(td[i]), rtol) for i in ref_idx]
            err = errors({k: np.array([r[k] for r in rows]) for k in KEYS}, ref)
            if meets(err):
                t0 = time.perf_counter()
                with console.status(f"jitcdde on {n_jit} loops at rtol {rtol:g}…"):
                    jrows = [jit.metrics(float(td[i]), rtol) for i in range(n_jit)]
                jit_time = (time.perf_counter() - t0) * args.loops / n_jit
                agree, mismatched = agreement({k: np.array([r[k] for r in jrows]) for k in KEYS}, dk_all)
                err = {k: max(err[k], agree[k]) for k in KEYS}
            tried.append((rtol, err))
            if meets(err):
                chosen = (rtol, err)
                break
        if chosen is None:
            raise SystemExit("jitcdde did not reach the accuracy target at any tolerance tried: "
                             + "; ".join(f"{r:g}: {e}" for r, e in tried))
        rtol, je = chosen
    table = Table(title=f"{args.loops:,} P loops (Kp = {KP}, Td in [0.2, 0.5] s, 15 s), four metrics each")
    for col in ("solver", "compile s", "run s", "µs/loop", "err Mo pp", "err times ms", "target met", "time ratio"):
        table.add_column(col, justify="right")
    terr = lambda e: 1e3 * max(e[k] for k in KEYS[1:])  # noqa: E731
    table.add_row("delaykit", ("cold not timed" if dk_cold != dk_cold else f"{dk_cold:.1f}") + f" ({dk_compile:.2f} cached)", f"{dk_time:.3f}",
                  f"{1e6 * dk_time / args.loops:.1f}", f"{dk_err['overshoot']:.1e}", f"{terr(dk_err):.1e}",
                  str(meets(dk_err)), "1")
    jit_ok = meets(je)
    table.add_row(f"jitcdde rtol {rtol:g}" + ("" if n_jit == args.loops else f" ({n_jit} run, scaled)"),
                  f"{jit.compile_time:.2f}", f"{jit_time:.2f}", f"{1e6 * jit_time / args.loops:.0f}",
                  f"{je['overshoot']:.1e}", f"{terr(je):.1e}", str(jit_ok), f"{jit_time / dk_time:.0f}")
    console.print(table)
    if args.write_docs:
        write_docs(Path(__file__).name, table)
    def short(e: dict[str, float]) -> str:
        return "ok" if meets(e) else f"short: {e['overshoot']:.1e} pp, {terr(e):.1e} ms"

    console.print(
        f"Errors: delaykit's are the largest over {ref_idx.size} random loops against the reference solver "
        "(DOP853, rtol 1e-12, breakpoints located); jitcdde's are the larger of that and its largest difference "
        f"from delaykit over all {n_jit} loops it ran (peak times only where Mo >= 1e-3 pp: below that the peak is "
        "micrometres high and seconds wide, ill-conditioned for any solver). jitcdde tolerances tried: "
        + ", ".join(f"{r:g} ({short(e)})" for r, e in tried)
        + f". {mismatched} values exist in one solver only (a peak time where the overshoot is at rounding level, "
        f"near Kp Td = 1/e). Largest discarded Taylor coefficient: {batch.truncation:.1e}. "
        f"numba threads: {__import__('numba').get_num_threads()}; delaykit's CPU time over its threads "
        f"{dk_cpu:.3f} s (so at best {dk_cpu / 2:.3f} s of wall time on 2 idle cores); load average "
        f"{load[0]:.1f} while it ran (the machine is shared). delaykit's 9 runs: "
        + ", ".join(f"{r:.3f}" for r in sorted(runs)) + f" s; the ratio at their median "
        f"{float(np.median(runs)):.3f} s is {jit_time / float(np.median(runs)):.0f}x."
    )
    result = {"loops": args.loops, "targets_met": {"delaykit": meets(dk_err), "jitcdde": jit_ok},
              "delaykit": {"compile_cold": dk_cold, "compile": dk_compile, "run": dk_time, "runs": runs, "cpu": dk_cpu,
                           "loadavg": load, "error": dk_err},
              "jitcdde": {"compile": jit.compile_time, "run": jit_time, "rtol": rtol, "error": je, "loops_run": n_jit,
                          "tried": [{"rtol": r, "error": e} for r, e in tried]},
              "ratio": jit_time / dk_time, "agreement": agree, "mismatched": mismatched}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
