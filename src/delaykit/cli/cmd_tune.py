"""``delaykit tune``: P, PI, PD, PID and PV controllers for a plant with a dead time, by rule or optimisation."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Optional

import typer

from ..errors import InvalidValueError, writing
from .common import check_output, err, fmt, friendly, out, print_json, warn
from .loopopts import with_loop

__all__ = ["tune"]


def _base(opts: dict[str, Any], model: Optional[Path]) -> Any:
    """The plant to tune: a loop from the loop options, or an identified model with the options' limits."""
    from ..models.altitude import as_loop
    from .app import parse_delays
    from .loopopts import build_loop

    o = {k: v for k, v in opts.items() if v is not None}
    if model is not None:
        from ..identify.identification import load_model
        from ..models.loop import Loop

        if "plant" in o or "loop_file" in o:
            raise InvalidValueError("give --model or --plant/--loop, not both")
        m = load_model(model)
        extra = float(parse_delays(o["delay"])[0]) if "delay" in o else 0.0
        o.pop("delay", None)
        lim, _ = build_loop({**o, "plant": "1/s", "delay": "0", "kp": 1.0, "controller": "p"}, parse_delays)
        return Loop(m.plant, delay=m.delay + extra, umin=lim.umin, umax=lim.umax)
    if "delay" in o and len(parse_delays(o["delay"])) > 1:
        raise InvalidValueError(f"--delay takes one delay for tune, got {o['delay']!r}; give a robust range with "
                                "--delays A:B:N")
    if "delay" not in o and "loop_file" not in o:
        if "plant" not in o:
            raise InvalidValueError("give --plant (with its dead time, '2*exp(-3*s)/(10*s+1)') and --delay, "
                                    "--loop FILE.toml or --model FILE.json")
        o["delay"] = "0"  # the dead time written in the plant's text (exp(-T*s)) is the plant's delay
    o.setdefault("kp", 1.0)
    if "loop_file" not in o:
        o["controller"] = "p"
    loop, _ = build_loop(o, parse_delays)
    return as_loop(loop)


@friendly
@with_loop(omit=("controller", "kp", "ki", "kd", "kv", "derivative_filter", "velocity", "filter_wn", "filter_zeta",
                 "model_delay", "closed_loop_time"))
def tune(
    controller: str = typer.Option("pi", "--controller", help="p | pi | pd | pid | pv (pv: by --method only)."),
    rule: Optional[str] = typer.Option(None, "--rule", help="simc | amigo | imc | lambda | zn | tyreus-luyben."),
    method: Optional[str] = typer.Option(None, "--method", help="migo: optimise (the default without --rule)."),
    objective: str = typer.Option("ki", "--objective", help="ki (MIGO: largest integral gain) | iae-load | abscissa."),
    ms: float = typer.Option(1.4, "--ms", help="Limit on the peak sensitivity Ms (above 1)."),
    mt: Optional[float] = typer.Option(None, "--mt", help="Limit on the peak complementary sensitivity Mt (above 1)."),
    tau_c: Optional[float] = typer.Option(None, "--tau-c", help="SIMC's closed-loop time constant / IMC's lambda, s (default: the delay)."),
    delays_range: Optional[str] = typer.Option(None, "--delays", help="Robust design over delays: START:STOP:N or a comma list (s)."),
    gains_range: Optional[str] = typer.Option(None, "--gains", help="Robust design over gain factors: START:STOP:N or a comma list."),
    overshoot: Optional[float] = typer.Option(None, "--overshoot", help="Setpoint-overshoot target, %: sets the setpoint weight b (pi, pid)."),
    derivative_weight: float = typer.Option(0.0, "--derivative-weight", help="Setpoint weight c of the derivative (pid; 0: derivative on the measurement)."),
    filter_ratio: float = typer.Option(10.0, "--filter-ratio", help="N: the derivative filter's time constant is Td/N."),
    model: Optional[Path] = typer.Option(None, "--model", help="A saved identified model (identify --save) instead of --plant."),
    step: float = typer.Option(1.0, "--step", help="Setpoint step of the report."),
    load: Optional[float] = typer.Option(None, "--load", help="Load step at the plant input for the report (default: half the command limit, or 1)."),
    relay: Optional[float] = typer.Option(None, "--relay", help="Instead of tuning: the exact relay limit cycle of this amplitude (Astrom-Hagglund), its describing-function and exact ultimate points."),
    hysteresis: float = typer.Option(0.0, "--hysteresis", help="The relay's hysteresis, in the output's units (with --relay)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    save: Optional[Path] = typer.Option(None, "--save", help="Write the tuned loop as a loop file (TOML) for simulate, margins and fly."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Nyquist with the Ms circle (and, for pi, the stable (kp, ki) region with the Ms contour)."),
    loop_options: Any = None,
) -> None:
    """Tune a P, PI, PD, PID or PV controller for a plant with a dead time, and check it exactly.

    The plant and its delay come from the loop options (--plant, --delay, limits), --loop FILE.toml or --model (an
    identified model).  By --rule (SIMC, AMIGO, IMC/lambda; Ziegler-Nichols and Tyreus-Luyben from the exact
    ultimate point) or by --method migo: the largest integral gain with Ms <= --ms (and Mt <= --mt), or
    --objective iae-load (least load IAE, exact simulation) or abscissa (rightmost root); with --delays/--gains the
    limit holds at every plant of the range.  Prints the gains, Ms, Mt, the margins, and the setpoint and load
    responses.
    """
    from ..design.pid import tune as tune_

    check_output("--save", save)
    check_output("--plot", plot, "figure")
    from ..models.ranges import parse_range

    base = _base(dict(loop_options), model)
    if relay is not None:
        _relay(base, relay, hysteresis, as_json)
        return
    delays = None if delays_range is None else parse_range(delays_range, "--delays")
    gains = None if gains_range is None else parse_range(gains_range, "--gains")
    import warnings

    from ..design.pid_rules import TuningWarning

    with err.status("tuning…"), warnings.catch_warnings():
        warnings.simplefilter("ignore", TuningWarning)  # each is among the result's notes, printed once below
        t = tune_(base, controller, rule=rule, method=method, objective=objective, ms=ms, mt=mt, tau_c=tau_c,
                  delays=delays, gains=gains, overshoot=overshoot, filter_ratio=filter_ratio, step=step, load=load,
                  derivative_weight=derivative_weight,
                  antiwindup=loop_options.get("antiwindup") or "none")
    if save is not None:
        from ..models.loop import loop_to_toml

        text = loop_to_toml(t.loop)
        with writing("--save", save):
            save.write_text(text)
    if plot is not None:
        from ..plotting.tuning import plot_tuning

        with err.status("drawing…"):
            plot_tuning(t, plot)
    if as_json:
        print_json(t.to_dict())
        return
    _table(t)


def _relay(base: Any, amplitude: float, hysteresis: float, as_json: bool) -> None:
    """``tune --relay``: the exact relay cycle of the loop's plant and delay."""
    from ..design.relay import relay_cycle

    lim = min(-base.umin, base.umax)
    if amplitude > lim:
        raise InvalidValueError(f"--relay {amplitude:g} is beyond the actuator's limit {lim:g}")
    c = relay_cycle(base.plant, base.total_delay, amplitude, hysteresis)
    if as_json:
        print_json(c.to_dict())
        return
    out.print(repr(c), highlight=False, markup=False)
    u = c.ultimate
    out.print(f"Describing function: ku ~ {c.ku_describing:.6g}, pu ~ {c.pu_describing:.6g} s; model at the cycle's "
              f"frequency: ku = {c.ku_at_period:.6g}" + ("" if u is None else
                                                        f"; exact: ku = {u.ku:.6g}, pu = {u.pu:.6g} s"),
              highlight=False, markup=False)


def _table(t: Any) -> None:
    from rich.table import Table

    out.print(repr(t.loop), highlight=False, markup=False)
    table = Table(title=f"{t.how} {t.kind} tuning" + ("" if t.stable else " (UNSTABLE)"))
    table.add_column("quantity")
    table.add_column("value", justify="right")
    rows = [("kp", t.kp)]
    if t.kind in ("pi", "pid"):
        rows.append(("ki (1/s)", t.ki))
    if t.kind in ("pd", "pid"):
        rows += [("kd (s)", t.kd), ("Tf (s)", t.tf)]
    if t.kind == "pv":
        rows.append(("kv", t.kd))
    if t.kind in ("pi", "pid"):
        rows.append(("b", t.b))
    if t.kind == "pid":
        rows.append(("c", t.c))
    rows += [("Ms", t.ms), ("Mt", t.mt), ("gain margin", t.gain_margin), ("phase margin (deg)", t.phase_margin),
             ("delay margin (s)", t.delay_margin)]
    if t.setpoint is not None:
        s = t.setpoint
        rows += [(f"setpoint {s.step:g}: overshoot %", s.overshoot), ("setpoint: settling (s)", s.settling_time),
                 ("setpoint: IAE", s.iae)]
    if t.load is not None:
        ld = t.load
        rows += [(f"load {ld.size:g}: peak error", ld.peak_error), ("load: IAE", ld.iae),
                 ("load: recovery (s)", ld.recovery_time)]
    for name, v in rows:
        table.add_row(name, fmt(v))
    out.print(table)
    if t.robust:
        rt = Table(title="robust set")
        for col in ("delay s", "gain", "Ms", "GM", "PM deg", "DM s", "stable", "load IAE"):
            rt.add_column(col, justify="right")
        w = t.worst
        for p in t.robust:
            mark = " ←" if p is w else ""
            rt.add_row(f"{p.delay:g}", f"{p.gain:g}", fmt(p.ms) + mark, fmt(p.gain_margin), fmt(p.phase_margin),
                       fmt(p.delay_margin), "yes" if p.stable else "NO", fmt(p.load_iae))
        out.print(rt)
    if t.model is not None:
        out.print(f"Model: {t.model!r}", highlight=False, markup=False)
    if t.ultimate is not None:
        out.print(f"Ultimate point (exact): {t.ultimate!r}", highlight=False, markup=False)
    for n in t.notes:
        warn(n, label="Note")
