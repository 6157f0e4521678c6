"""Benchmark: the exact root locus of the paper's P loop, delaykit against python-control's Padé locus.

The open loop ``k exp(-0.368 s) / s`` (``AltitudeLoop(kp=1, delay=0.368)``, gain ``k`` = Kp) over 1,000 gains
from 0.01 to 10.  delaykit: :func:`delaykit.root_locus`, every gain's roots in its default region certified by
the argument principle, the right-half-plane counted, the crossing found exactly.  python-control: its
``root_locus_map`` of ``1/s`` times a Padé approximation of the delay (orders 3 and 6, :func:`delaykit.to_control`),
which has no certificate and no crossing; the crossing is read from its grid (the first gain with a pole in the
right half-plane).  The exact first crossing is ``k = pi / (2 * 0.368)`` (``k tau = pi/2``).

Run: ``python benchmarks/bench_locus.py [--quick] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

import delaykit as dk

TAU = 0.368
EXACT = math.pi / (2 * TAU)


def timed(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="100 gains, one repeat")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    n, repeats = (100, 1) if args.quick else (1000, 3)
    gains = np.linspace(0.01, 10.0, n)
    loop = dk.AltitudeLoop(kp=1.0, delay=TAU)
    dk.root_locus(loop, gains=gains[:5])  # the kernels loaded, outside the timing
    loc, t = timed(lambda: dk.root_locus(loop, gains=gains), repeats)
    rows = [{"method": "delaykit root_locus (exact delay)", "seconds": t,
             "certified": f"{int(loc.certified.sum())}/{n}",
             "first crossing": loc.crossings[0].value if loc.crossings else None, "how": "exact"}]
    try:
        import control
    except ImportError:  # pragma: no cover - control is a dev dependency
        control = None
    if control is not None:
        for order in (3, 6):
            G = dk.to_control(loop, pade_order=order)
            rl, tc = timed(lambda: control.root_locus_map(G, gains=gains), repeats)
            unstable = np.nanmax(rl.loci.real, axis=1) > 0
            first = float(gains[np.argmax(unstable)]) if unstable.any() else None
            rows.append({"method": f"python-control root_locus_map, Padé order {order}", "seconds": tc,
                         "certified": "no certificate", "first crossing": first, "how": "from the grid"})
    table = Table(title=f"Root locus of k exp(-{TAU} s)/s over {n} gains (exact first crossing {EXACT:.6f})")
    for col in ("method", "time (s)", "certified", "first crossing k", "error", "crossing"):
        table.add_column(col)
    for r in rows:
        k = r["first crossing"]
        table.add_row(r["method"], f"{r['seconds']:.3f}", r["certified"], "none" if k is None else f"{k:.6f}",
                      "-" if k is None else f"{abs(k - EXACT):.1e}", r["how"])
    Console(width=150).print(table)
    if args.quick:
        print(f"--quick: {n} gains in {rows[0]['seconds']:.3f} s (the target is for 1,000 gains: run without --quick)")
    else:
        target = rows[0]["seconds"] < 1.0
        verdict = "met" if target else "NOT met"
        print(f"target (1,000 gains certified under 1 s): {verdict} ({rows[0]['seconds']:.3f} s)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"gains": n, "exact_first_crossing": EXACT, "rows": rows}, indent=2))


if __name__ == "__main__":
    main()
