"""Benchmark: characteristic roots, delaykit against qpmr (a Python port of QPmR), side by side.

Cases: the five Table 3 equations s + (2 + Kv s) exp(-0.37 s) in [-10, 2] x [0, 100]; a sweep of Kv from 0 to
0.95 by 0.01 on the same region (qpmr's time there is unpredictable where a real root sits on Im = 0);
qpmr's own examples 2 (retarded, 9 delays, (-4.5, 2.5) x (0, 800)) and 3 (neutral, 5 delays, (-6, 2) x (0, 200));
the mazanti2021multiplicity example (a six-fold real root near -6.02); and the Lambert W roots of a million
first-order delay equations against SciPy's lambertw alone.

For each case: both times (median of repeats), delaykit's count and certificate, how many of qpmr's roots
delaykit also found (to 1e-8), and how many delaykit found that qpmr did not.

Run: ``python benchmarks/bench_roots.py [--quick] [--lambert-only] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import logging
import statistics
import time
import warnings
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

import delaykit as dk
from delaykit.spectrum.lambert import lambert_roots
from delaykit.spectrum.roots import find_roots

from _docs import write_docs


def qp_from_qpmr(coefs, delays) -> dk.QuasiPolynomial:
    """qpmr stores one row per delay, lowest power first; delaykit highest first."""
    coefs = np.atleast_2d(np.asarray(coefs))
    return dk.QuasiPolynomial([row[::-1] for row in coefs], list(delays))


def timed(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def matched(ours: np.ndarray, theirs: np.ndarray, tol: float = 1e-8) -> tuple[int, int]:
    """(qpmr roots also found by delaykit, delaykit roots that qpmr lacks), to tol relative."""
    theirs = np.asarray(theirs, dtype=complex)
    if theirs.size == 0:
        return 0, ours.size
    found = sum(1 for z in theirs if ours.size and np.min(np.abs(ours - z)) <= tol * (1 + abs(z)))
    extra = sum(1 for z in ours if np.min(np.abs(theirs - z)) > tol * (1 + abs(z)))
    return found, extra


def run_case(name, coefs, delays, region, repeats, qpmr_repeats=None):
    import qpmr

    q = qp_from_qpmr(coefs, delays)
    sp, t_dk = timed(lambda: find_roots(q, region), repeats)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        (r_q, _info), t_q = timed(lambda: qpmr.qpmr(np.asarray(coefs, float), np.asarray(delays, float),
                                                  region=list(region)), qpmr_repeats or repeats)
    r_q = np.asarray(r_q)
    found, extra = matched(sp.roots, r_q)
    return {"case": name, "region": list(region), "qpmr_time": t_q, "delaykit_time": t_dk, "ratio": t_q / t_dk,
            "qpmr_roots": int(r_q.size), "delaykit_roots": int(sp.roots.size),
            "delaykit_count": int(sp.multiplicities.sum()), "argument_principle": sp.count,
            "certified": sp.certified, "qpmr_found_by_delaykit": found, "delaykit_only": extra,
            "max_multiplicity": int(sp.multiplicities.max()) if sp.roots.size else 0}


def lambert_case(console: Console, n: int = 1_000_000, repeats: int = 7) -> dict:
    """The Lambert W roots of ``n`` P loops (branch 0) against SciPy's ``lambertw`` alone (median of ``repeats``,
    the two timed alternately so that a busy machine slows both alike)."""
    from scipy.special import lambertw

    rng = np.random.default_rng(0)
    kp, tds = rng.uniform(0.5, 3.0, n), rng.uniform(0.05, 0.8, n)
    x = -kp * tds
    t_scipy, t_dk = [], []
    for _ in range(repeats):
        _, t = timed(lambda: lambertw(x, 0), 1)
        t_scipy.append(t)
        r, t = timed(lambda: lambert_roots(0.0, -kp, tds, branches=[0]), 1)
        t_dk.append(t)
    ts, td = statistics.median(t_scipy), statistics.median(t_dk)
    s = r.roots[0]
    resid = np.max(np.abs(s + kp * np.exp(-s * tds)) / (np.abs(s) + kp * np.abs(np.exp(-s * tds))))
    console.print(f"Lambert W, {n:,} P loops (branch 0): scipy.special.lambertw alone {ts:.3f} s; "
                  f"delaykit.lambert_roots (roots, with the branch-point handling) {td:.3f} s, {td / ts:.2f}x SciPy's "
                  f"time; largest relative residual {resid:.1e}.")
    return {"scipy": ts, "delaykit": td, "ratio": td / ts, "residual": float(resid), "n": n}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip qpmr example 2 (about 80 s) and shorten the sweep")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--lambert-only", action="store_true", help="only the Lambert W comparison (no qpmr needed)")
    ap.add_argument("--write-docs", action="store_true",
                    help="replace this script's tables in docs/benchmarks.md (between its markers)")
    args = ap.parse_args()
    if args.write_docs and (args.quick or args.lambert_only):
        ap.error("--write-docs writes the full run's tables into the docs: run it without --quick/--lambert-only")
    if args.lambert_only:
        lam = lambert_case(Console(width=120))
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps({"lambert": lam}, indent=2))
        return
    logging.getLogger("qpmr").setLevel(logging.CRITICAL)
    from qpmr.quasipoly import examples as ex

    console = Console(width=120)
    rows = []
    with console.status("Table 3…"):
        for kv in (0.0, 0.1, 0.3, 0.5, 0.7):
            rows.append(run_case(f"Table 3, Kv={kv}", [[0.0, 1.0], [2.0, kv]], [0.0, 0.37], (-10, 2, 0, 100), 7))
    sweep = []
    kvs = np.round(np.arange(0.0, 0.951, 0.01 if not args.quick else 0.05), 2)
    with console.status("Kv sweep…"):
        for kv in kvs:
            sweep.append(run_case(f"sweep Kv={kv}", [[0.0, 1.0], [2.0, kv]], [0.0, 0.37], (-10, 2, 0, 100), 3, 1))
    with console.status("mazanti2021multiplicity…"):
        c, d = ex.mazanti2021multiplicity()
        rows.append(run_case("mazanti2021multiplicity", c, d, (-10, 2, 0, 50), 3, 1))
    with console.status("qpmr example 3…"):
        c, d = ex.vyhlidal2014qpmr_03()
        rows.append(run_case("qpmr example 3 (neutral)", c, d, (-6, 2, 0, 200), 3, 1))
    if not args.quick:
        with console.status("qpmr example 2 (qpmr takes over a minute)…"):
            c, d = ex.vyhlidal2014qpmr_02()
            rows.append(run_case("qpmr example 2 (retarded)", c, d, (-4.5, 2.5, 0, 800), 1, 1))

    table = Table(title="Quasi-polynomial roots: delaykit vs qpmr (median times)")
    for col in ("case", "qpmr", "delaykit", "ratio", "qpmr roots", "delaykit roots", "count", "certified",
                "qpmr's found", "new"):
        table.add_column(col, justify="right")
    fmt = lambda t: f"{t * 1e3:.1f} ms" if t < 1 else f"{t:.1f} s"  # noqa: E731
    for r in rows:
        table.add_row(r["case"], fmt(r["qpmr_time"]), fmt(r["delaykit_time"]), f"{r['ratio']:.0f}×",
                      str(r["qpmr_roots"]), str(r["delaykit_roots"]) + (f" (max mult {r['max_multiplicity']})" if r["max_multiplicity"] > 1 else ""),
                      str(r["argument_principle"]), str(r["certified"]), f"{r['qpmr_found_by_delaykit']}/{r['qpmr_roots']}",
                      str(r["delaykit_only"]))
    console.print(table)
    if args.write_docs:
        write_docs(Path(__file__).name, table)
    tq = np.array([r["qpmr_time"] for r in sweep])
    td = np.array([r["delaykit_time"] for r in sweep])
    slow = [f"{r['case'].split('=')[1]} ({r['qpmr_time']:.1f} s)" for r in sweep if r["qpmr_time"] > 1.0]
    console.print(
        f"Kv sweep ({kvs.size} values): qpmr {tq.min() * 1e3:.1f} ms to {tq.max():.2f} s (over 1 s at Kv = "
        f"{', '.join(slow) or 'none'}); delaykit {td.min() * 1e3:.1f} to {td.max() * 1e3:.1f} ms; smallest ratio "
        f"{np.min(tq / td):.1f}×; all certified: {all(r['certified'] for r in sweep)}; every qpmr root found: "
        f"{all(r['qpmr_found_by_delaykit'] == r['qpmr_roots'] for r in sweep)}."
    )
    lam = lambert_case(console)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"cases": rows, "sweep": sweep, "lambert": lam}, indent=2))


if __name__ == "__main__":
    main()
