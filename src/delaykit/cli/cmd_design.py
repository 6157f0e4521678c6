"""``delaykit design``: PV gains and delay compensators for a loop."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import typer

from ..errors import InvalidValueError
from .common import check_output, err, fmt, friendly, out, parse_delays, print_json, progress_bar
from .loopopts import with_loop

__all__ = ["design"]


def _design_compensator(kind: str, opts: dict[str, Any], uncertainty: float, as_json: bool,
                        plot: Optional[Path]) -> None:
    """``design --compensator``: the design, its metrics and robustness (and the map with --plot)."""
    import numpy as np

    from ..design.compensators import design_compensator, robustness_map
    from .loopopts import build_loop

    from ..models.compensators import COMPENSATOR_KINDS

    if kind.lower().replace("_", "-") not in COMPENSATOR_KINDS:
        raise InvalidValueError(f"--compensator must be one of {' | '.join(COMPENSATOR_KINDS)}, got {kind!r}")
    kind = kind.lower().replace("_", "-")
    opts = {k: v for k, v in opts.items() if k not in ("controller", "model_delay")}
    if opts.get("delay") is None and opts.get("loop_file") is None:
        raise InvalidValueError("give --delay (the model delay of the design)")
    loop, _ = build_loop({**opts, "controller": kind}, parse_delays)
    with err.status(f"designing the {kind} compensator…"):
        d = design_compensator(kind, loop.plant, loop.controller.model_delay, umin=loop.umin, umax=loop.umax,
                               delay_uncertainty=uncertainty, closed_loop_time=opts.get("closed_loop_time"))
    if plot is not None:
        from ..plotting.compensation import plot_robustness_map

        dr, gr = np.linspace(0.25, 2.5, 46), np.linspace(0.25, 2.5, 31)
        with progress_bar() as bar:
            task = bar.add_task("robustness map", total=dr.size * gr.size)
            rm = robustness_map(d.compensator, dr, gr, progress=lambda: bar.advance(task))
        plot_robustness_map(rm, path=plot)
    if as_json:
        print_json(d.to_dict())
        return
    out.print(repr(d.compensator), highlight=False)
    from rich.table import Table

    table = Table(title=f"{kind} design for {loop.plant.to_string(times=' ')}, model delay "
                        f"{d.compensator.model_delay:g} s")
    for col in ("step", "Mo %", "rise s", "settle s", "bound s"):
        table.add_column(col, justify="right")
    for size, m in d.steps.items():
        table.add_row(f"{size:g}", fmt(None if m is None else m.overshoot),
                      fmt(None if m is None else m.rise_time),
                      fmt(None if m is None else m.settling_time), fmt(d.bounds.get(size)))
    out.print(table)
    lo, hi = d.delay_ratio_range
    out.print(f"Stable for true/model delay ratios {lo:.4f} to {hi:.4f}; {d.disturbance!r}.", highlight=False)
    out.print(f"Steps simulated for {d.horizon:.4g} s, the load recovery for {max(d.horizon, 20.0):.4g} s (from the "
              "plant's slowest mode, the delay and the design's speed; 'never' means not within that).",
              highlight=False)


@friendly
@with_loop(omit=("kp", "kv"))
def design(
    kp: str = typer.Option("2.0", "--kp", help="Kp: a value, a comma list or START:STOP:N."),
    kv: Optional[str] = typer.Option(None, "--kv", help="Kv: a value, a comma list or START:STOP:N (default 0:0.7:8 for the PV law)."),
    step: float = typer.Option(1.0, "--step", help="Step size for the simulated metrics."),
    criterion: str = typer.Option("abscissa", "--criterion", help="abscissa | settling | overshoot (overshoot: not with --delays)."),
    overshoot_limit: float = typer.Option(5.0, "--overshoot-limit", help="Overshoot limit for --criterion overshoot, %."),
    delays_range: Optional[str] = typer.Option(None, "--delays", help="A delay range for a robust 2-D search (START:STOP:N)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Dask scheduler address for large searches."),
    compensator: Optional[str] = typer.Option(None, "--compensator", help="Design a delay compensator instead: smith | filtered-smith | predictor."),
    delay_uncertainty: float = typer.Option(0.2, "--delay-uncertainty", help="The relative delay error the law is designed for (compensators: must survive; --monitor: the design range)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Responses (sweep), the gain maps (with --delays), or the robustness map (--compensator)."),
    loop_options: Any = None,
) -> None:
    """Candidate P/PV gains for a loop: rightmost root, abscissa, stability and step metrics, and the best.

    The loop (plant, delay, limits, velocity filter, period) comes from the loop options or --loop; --kp and
    --kv are the candidates.  With --compensator, a Smith predictor, filtered Smith predictor or predictor
    feedback is designed for the plant and delay instead: its parameters, the step metrics of 0.2 and 1 steps,
    the load-disturbance recovery and the range of true-to-model delay ratios it survives.

    A range of delays (--delays, or a --delay range such as 0.2:0.5:4) makes it a robust search: each candidate is
    ranked by its worst case over every delay of the range.
    """
    from ..design import tuning as D
    from .loopopts import build_loop

    check_output("--plot", plot, "figure")
    if compensator is not None:
        _design_compensator(compensator, dict(loop_options), delay_uncertainty, as_json, plot)
        return

    opts = dict(loop_options)
    kind = str(opts.get("controller") or "").lower()
    if kind in ("pi", "pd", "pid"):
        raise InvalidValueError(f"design sweeps P and PV gains; for {kind}: delaykit tune --controller {kind}")
    if kind == "p" and kv is not None and any(D.parse_range(kv, "--kv")):
        raise InvalidValueError(f"--controller p has no Kv; got --kv {kv} (use --controller pv)")
    kps = D.parse_range(kp, "--kp")
    kvs = D.parse_range(kv if kv is not None else ("0" if kind == "p" else "0:0.7:8"), "--kv")
    if opts.get("delay") is None and delays_range is not None and opts.get("loop_file") is None:
        opts["delay"] = str(D.parse_range(delays_range, "--delays")[0])
    if opts.get("loop_file") is None:
        opts["kp"] = kps[0]
        opts["kv"] = next((k for k in kvs if k), None)  # a Kv > 0 builds the PV law with its velocity options
    raw = parse_delays(str(opts["delay"])) if opts.get("delay") is not None else None
    base, base_delays = build_loop(opts, parse_delays)
    extra = base_delays[0] - raw[0] if raw else 0.0  # a dead time in the plant's text adds to --delays too
    dl: Optional[list[float]] = None
    if len(base_delays) > 1:  # a --delay range: design for all of it (the first alone was designed for before)
        if delays_range is not None:
            raise InvalidValueError("give the delays to design for once: a --delay range or --delays, not both")
        dl = list(base_delays)
    elif delays_range is not None:
        dl = [d + extra for d in D.parse_range(delays_range, "--delays")]
    if dl is not None:
        if criterion not in ("abscissa", "settling"):
            raise InvalidValueError(f"--criterion {criterion} is not available with a range of delays (the robust "
                                    "search ranks by the worst case over the delays): use settling or abscissa")
        with progress_bar() as bar:
            task = bar.add_task("gain search", total=None)
            gm = D.gain_search(base, dl, kps, kvs, criterion=criterion, step=step, scheduler=scheduler,
                               progress=lambda k, n: bar.update(task, completed=k, total=n))
        if plot is not None:
            from ..plotting.figures import plot_stability_map
            from ..spectrum.stability import StabilityMap

            plot_stability_map(StabilityMap("kp", "kv", gm.kp, gm.kv, gm.abscissa), plot,
                               title=f"worst-case spectral abscissa over delays {min(dl):g} to {max(dl):g} s")
        if as_json:
            print_json(gm.to_dict())
            return
        out.print(repr(gm), highlight=False)
        out.print(f"Best: {gm.best} ({gm.reason})." if gm.best else f"No candidate: {gm.reason}.", highlight=False)
        return
    with progress_bar() as bar:
        task = bar.add_task("evaluating candidates", total=None)
        d = D.design_sweep(base, kps, kvs, step=step, criterion=criterion, overshoot_limit=overshoot_limit,
                           progress=lambda k, n: bar.update(task, completed=k, total=n))
    if plot is not None:
        from ..plotting.figures import plot_responses
        from ..simulate.simulation import simulate as sim

        plot_responses([sim(D._with_gains(base, r.kp, r.kv), step) for r in d.rows], plot,
                       labels=[f"Kp={r.kp:g}, Kv={r.kv:g}" for r in d.rows], t_max=8.0)
    if as_json:
        rows = [r.to_dict() for r in d.rows]
        print_json({"rows": rows, "best": None if d.best is None else d.best.to_dict(),
                    "criterion": d.criterion, "reason": d.reason})
        return
    from rich.table import Table

    span = lambda xs: f"{min(xs):g} to {max(xs):g}" if len(xs) > 1 else f"{xs[0]:g}"  # noqa: E731
    table = Table(title=f"Candidates Kp {span(kps)}, Kv {span(kvs)} on {base!r}, its gains replaced by each "
                        "candidate's")
    for col in ("Kp", "Kv", "rightmost", "abscissa", "neutral", "stable", "Mo %", "tp s", "ts s"):
        table.add_column(col, justify="right")
    for r in d.rows:
        rm = r.rightmost
        mark = " ←" if d.best is r else ""
        table.add_row(f"{r.kp:g}", f"{r.kv:g}{mark}", "–" if rm is None else f"{rm.real:.2f}±{abs(rm.imag):.2f}j",
                      f"{r.abscissa:.4f}", fmt(r.neutral_line), "yes" if r.stable else "NO", f"{r.overshoot:.3f}",
                      fmt(r.peak_time, 3), fmt(r.settling_time, 3) if r.settling_time is not None else "never")
    out.print(table)
    out.print(f"Best by {d.criterion}: Kp = {d.best.kp:g}, Kv = {d.best.kv:g}: {d.reason}." if d.best
              else f"No candidate meets the criterion: {d.reason}.", highlight=False)
