"""Benchmark: MIGO PI tuning (largest integral gain subject to Ms <= 1.4), side by side with a brute force.

Rows (targets from issue 22):

* one plant (target under 0.5 s): the paper's altitude loop ``1/s`` with a 0.37 s delay;
* robust over 5 delays (target under 2 s): the same plant with delays 0.30 to 0.50 s, the limit held at each.

The brute force scans a (kp, ki) grid: for each kp, ki upward from 0 in steps until Ms (on a dense frequency grid,
plain NumPy) first breaks the limit at any plant, then a finer scan between the last admissible step and the first
that is not.  Its optimum is the reference for the accuracy column (relative difference in ki), and its time the
other side of the ratio.  Times are the best of ``--repeat`` runs (the first, with imports, left out).

Run: ``python benchmarks/bench_tune.py [--quick] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from delaykit.design.pid_optimise import optimise, plant_points
from delaykit.models.plants import integrator

TARGETS = {"one plant": 0.5, "5 delays": 2.0}


def brute(points, ms: float, kps: np.ndarray, n_w: int = 2000, mt: float | None = None) -> tuple[float, float]:
    """The largest admissible ki over the kp grid (see the module docstring), with Mt <= mt too when given;
    returns (kp, ki).  Also the reference of tests/test_tune.py."""
    w = np.geomspace(1e-3, 1e2, n_w)
    s = 1j * w
    Ps = [np.polyval(p.num, s) / np.polyval(p.den, s) * np.exp(-s * d) for p, d in points]

    def ok(kp: float, kis: np.ndarray) -> np.ndarray:
        good = np.ones(kis.size, bool)
        for P in Ps:
            L = P[None, :] * (kp + kis[:, None] / s[None, :])
            d = np.abs(1 + L)
            good &= np.min(d, axis=1) >= 1 / ms
            if mt is not None:
                good &= np.max(np.abs(L) / d, axis=1) <= mt
        return good

    best = (0.0, 0.0)
    for kp in kps:
        lo, hi = 0.0, 2.0
        for _ in range(2):
            kis = np.linspace(lo, hi, 201)[1:]
            bad = np.flatnonzero(~ok(kp, kis))
            if bad.size == 0:
                lo = hi
                break
            if bad[0] == 0:
                hi = kis[0]
                continue
            lo, hi = kis[bad[0] - 1], kis[bad[0]]
        if lo > best[1]:
            best = (float(kp), float(lo))
    return best


def timed(fn, repeat: int) -> tuple[float, object]:
    fn()  # imports and caches
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="a coarser brute force and one repeat")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", help="write the results here")
    a = ap.parse_args()
    repeat = 1 if a.quick else a.repeat
    kps = np.linspace(0.05, 1.5, 15 if a.quick else 59)
    cases = {"one plant": plant_points(integrator(), 0.37),
             "5 delays": plant_points(integrator(), 0.37, list(np.linspace(0.3, 0.5, 5)))}
    rows = {}
    print(f"{'case':<10} {'delaykit s':>11} {'brute s':>9} {'ratio':>7} {'ki delaykit':>12} {'ki brute':>9} "
          f"{'rel. diff':>10} {'target s':>9} {'met':>4}")
    for name, pts in cases.items():
        t_dk, sol = timed(lambda: optimise("pi", pts, ms=1.4), repeat)
        t_bf, (kp_b, ki_b) = timed(lambda: brute(pts, 1.4, kps), 1)
        diff = (sol.ki - ki_b) / ki_b
        met = t_dk < TARGETS[name]
        rows[name] = {"delaykit_s": t_dk, "brute_s": t_bf, "ratio": t_bf / t_dk, "ki": sol.ki, "kp": sol.kp,
                      "ki_brute": ki_b, "kp_brute": kp_b, "relative_difference": diff, "target_s": TARGETS[name],
                      "target_met": met}
        print(f"{name:<10} {t_dk:>11.3f} {t_bf:>9.2f} {t_bf / t_dk:>7.1f} {sol.ki:>12.5f} {ki_b:>9.5f} "
              f"{diff:>10.2e} {TARGETS[name]:>9.1f} {'yes' if met else 'NO':>4}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=2)


if __name__ == "__main__":
    main()
