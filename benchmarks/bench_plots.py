"""Benchmark: plots of a 2x2 system with four delays (the Wood-Berry column) against python-control's plots of a
Padé model of it.

Rows (issue 33's target in brackets): the Bode plot of the plant (8 panels, the exact response of each element
at 1000 frequencies, each delay's phase exact), its singular values, and the 2x2 step-response grid of the closed
loop under Luyben's BLT PI (exact, 201 times over 100 min); all three together [under 1 s].  Each is timed as
computation and drawing (the figure ready), and again with a PNG written (matplotlib's rendering, the larger part).
Beside each, python-control 0.10's ``bode_plot``, ``singular_values_plot`` and ``step_response(...).plot()`` of the
same plant with each delay replaced by a Padé approximant of order ``--pade`` (python-control has no delays), on
the same frequencies and times; its phase error at the top frequency (against the exact phase, 3 * 10 rad/min for
the 3-minute delay) is printed, as what the Padé model costs in accuracy.

Times are the least CPU time of this thread over ``--repeat`` runs (steadier than the wall time on a shared
machine; the ratio, taken side by side, is the figure to read).  The figures are drawn on the Agg canvas (this
script chooses it; the library never does).

Run: ``python benchmarks/bench_plots.py [--repeat 3] [--pade 10] [--json FILE] [--write-docs]``.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # the benchmark's choice: nothing is shown

import numpy as np  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.table import Table  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from anchors_systems import DELAY, GAIN, KC, LAG, TAU_I, wood_berry_loop, wood_berry_plant  # noqa: E402
from _docs import write_docs  # noqa: E402
from bench_native import best  # noqa: E402  (least CPU time of this thread over repeated calls)

W = np.geomspace(1e-3, 10.0, 1000)  # rad/min
T = np.linspace(0.0, 100.0, 201)    # min


def _png(fig: Any) -> None:
    fig.savefig(io.BytesIO(), format="png", dpi=100)


def delaykit_cases() -> dict[str, Any]:
    from delaykit.plotting import bode_plot, sigma_plot, step_grid

    G, CL = wood_berry_plant(), wood_berry_loop()
    return {"Bode (2x2, 1000 frequencies)": lambda: bode_plot(G, W),
            "singular values": lambda: sigma_plot(G, W),
            "step grid (closed loop, 201 times)": lambda: step_grid(CL, T)}


def control_cases(order: int) -> tuple[dict[str, Any], float]:
    import control as ct
    import matplotlib.pyplot as plt

    def element(i: int, j: int) -> Any:
        num, den = ct.pade(DELAY[i, j], order)
        return ct.tf([GAIN[i, j]], [LAG[i, j], 1.0]) * ct.tf(num, den)

    Gp = ct.combine_tf([[element(0, 0), element(0, 1)], [element(1, 0), element(1, 1)]])
    def gain(D: np.ndarray) -> Any:  # a static matrix as a system
        return ct.ss(np.zeros((0, 0)), np.zeros((0, D.shape[1])), np.zeros((D.shape[0], 0)), D)

    # (python-control converts MIMO transfer functions to state space only with Slycot: each element on its own)
    Gss = gain(np.array([[1.0, 1, 0, 0], [0, 0, 1, 1]])) * ct.append(
        *[ct.ss(element(i, j)) for i in range(2) for j in range(2)]) * gain(np.array([[1.0, 0], [0, 1], [1, 0],
                                                                                       [0, 1]]))
    K = ct.append(*[ct.ss(ct.tf([KC[k] * TAU_I[k], KC[k]], [TAU_I[k], 0])) for k in range(2)])
    CLp = ct.feedback(Gss * K, np.eye(2))
    ph = np.unwrap(np.angle(Gp[0, 1](1j * W)))  # the Padé model of -18.9 exp(-3s)/(21s+1)
    exact = -np.pi - 3 * W - np.arctan(21 * W)
    err = float(np.degrees(abs((ph[-1] - ph[0]) - (exact[-1] - exact[0]))))  # the phase fallen over the range

    def fresh(fn: Any) -> Any:
        def run() -> Any:
            plt.close("all")
            out = fn()
            fig = plt.gcf()
            return fig if out is None else fig
        return run

    return {"Bode (2x2, 1000 frequencies)": fresh(lambda: ct.bode_plot(ct.frequency_response(Gp, W))),
            "singular values": fresh(lambda: ct.singular_values_plot(Gp, W)),
            "step grid (closed loop, 201 times)": fresh(lambda: ct.step_response(CLp, T).plot())}, err


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--pade", type=int, default=10, help="order of each delay's Padé approximant (python-control)")
    ap.add_argument("--json", type=str, default=None)
    ap.add_argument("--write-docs", action="store_true",
                    help="write the table into its block of docs/benchmarks.md (the rest of the page is kept)")
    args = ap.parse_args(argv)
    console = Console()
    ours = delaykit_cases()
    try:
        theirs, err = control_cases(args.pade)
    except ImportError:
        theirs, err = {}, float("nan")
    rows = []
    for name, fn in ours.items():
        fn()  # warm: imports, the kernel's first call
        t_draw, fig = best(fn, args.repeat)
        t_png, _ = best(lambda: _png(fn()), args.repeat)
        row = {"case": name, "delaykit_s": t_draw, "delaykit_png_s": t_png}
        if name in theirs:
            theirs[name]()
            row["control_s"], _ = best(theirs[name], args.repeat)
            row["control_png_s"], _ = best(lambda: _png(theirs[name]()), args.repeat)
        rows.append(row)
    total = sum(r["delaykit_s"] for r in rows)
    total_png = sum(r["delaykit_png_s"] for r in rows)
    table = Table(title="Plots of the Wood-Berry 2x2 (four delays): CPU time, side by side")
    for col in ("plot", "delaykit (exact)", "with PNG", f"python-control (Padé {args.pade})", "with PNG"):
        table.add_column(col, justify="right")
    f = lambda v: "" if v is None else f"{v * 1e3:.0f} ms"  # noqa: E731
    for r in rows:
        table.add_row(r["case"], f(r["delaykit_s"]), f(r["delaykit_png_s"]), f(r.get("control_s")),
                      f(r.get("control_png_s")))
    table.add_row("all three [target < 1 s]", f(total), f(total_png), "", "")
    console.print(table)
    console.print(f"python-control's Padé model ({args.pade} per delay): its phase of -18.9 exp(-3s)/(21s+1) falls "
                  f"{err:.3g} degrees less than the exact one from 1e-3 to 10 rad/min; delaykit's is exact.",
                  highlight=False)
    result = {"rows": rows, "total_s": total, "total_png_s": total_png, "pade_order": args.pade,
              "pade_phase_error_deg": err}
    if args.write_docs:
        write_docs(Path(__file__).name, table)
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(result, fh, indent=1)
    return result


if __name__ == "__main__":
    main()
