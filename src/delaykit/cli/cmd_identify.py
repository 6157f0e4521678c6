"""``delaykit estimate``, ``identify``, ``predict`` and ``log``: the delay and the plant from logs (CSV, or PX4 ULog,
ArduPilot DataFlash and MAVLink tlog flight logs), free-run prediction, and what a flight log holds."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Optional

import typer

from ..errors import InvalidValueError
from .common import (check_output, ci_list, err, fmt, fmt_ci, friendly, out, parse_delays, print_json, print_rms,
                     progress_bar, warn)
from .loopopts import build_loop, with_loop

__all__ = ["estimate", "identify", "predict", "log"]

# the loop options `estimate` leaves out: the delay is what it finds, the controller runs at the logs' samples
_ESTIMATE_OMITS = ("delay", "model_delay", "closed_loop_time", "sample_offset")


@friendly
@with_loop(omit=_ESTIMATE_OMITS)
def estimate(
    flights: Optional[list[Path]] = typer.Argument(None, help="Flight logs: CSV (t, z, z_ref[, u]), or PX4 .ulg, ArduPilot .bin/.log, MAVLink .tlog with --output and --reference."),
    method: str = typer.Option("trajectory", "--method", help="trajectory | overshoot | lambert."),
    variant: str = typer.Option("paper", "--variant", help="For lambert: paper | damping."),
    free: str = typer.Option("", "--free", help="Extra fitted parameters for trajectory: gain,lag."),
    step_time: Optional[float] = typer.Option(None, "--step-time", help="Step time in the logs' clock, if not at a sample."),
    skip_bad: bool = typer.Option(False, "--skip-bad", help="Skip (and count) unreadable rows instead of failing."),
    output: Optional[str] = typer.Option(None, "--output", help="A flight log's altitude, up positive (e.g. -vehicle_local_position.z: NED z is down)."),
    reference: Optional[str] = typer.Option(None, "--reference", help="A flight log's altitude reference, up positive (e.g. -trajectory_setpoint.position[2])."),
    input_col: Optional[str] = typer.Option(None, "--input", help="A flight log's commanded climb rate (optional)."),
    window: Optional[str] = typer.Option(None, "--window", help="T0:T1, the part of the logs used, in the log's own seconds (since boot, as `delaykit log` shows)."),
    steps: str = typer.Option("all", "--steps", help="all: each step of the reference is fitted (jointly, one delay) | first: each log as one step."),
    allow_truncated: bool = typer.Option(False, "--allow-truncated", help="Read a flight log cut short up to its last whole message."),
    overshoot: Optional[float] = typer.Option(None, "--overshoot", help="Measured overshoot, % (no files needed)."),
    peak_time: Optional[float] = typer.Option(None, "--peak-time", help="Measured peak time, s."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Overlay data, fit and residuals here (trajectory)."),
    loop_options: Any = None,
) -> None:
    """Estimate the loop delay from flight logs, or from a measured overshoot and peak time.

    A log whose reference holds several steps is cut into one log per step, fitted jointly (--steps first: the
    log as one step). A flight log (.ulg, .bin, .log, .tlog) names its altitude and reference with --output and
    --reference; its steps are timed by the reference's own time stamps.
    The loop the flights used comes from the loop options (--kp, --kv, --vmax, --period, or --loop FILE.toml).
    It must be the paper's: the plant gain/s or gain/(s (lag s + 1)), P or PV control, symmetric limits.
    `delaykit identify` fits any other plant.  A delay in the loop file is ignored: it is what is estimated."""
    from ..identify import estimation as E
    from ..identify.flightlog import FlightLog
    from ..models.altitude import AltitudeLoop
    from ..simulate.metrics import step_metrics

    check_output("--plot", plot, "figure")
    methods = ("trajectory", "overshoot", "lambert")
    if method not in methods:
        raise InvalidValueError(f"--method must be one of {', '.join(methods)}; got {method!r}")
    loop, _ = build_loop({**loop_options, "delay": "0"}, parse_delays)
    base = AltitudeLoop.from_loop(loop)
    kp = base.kp
    free_t = tuple(x.strip() for x in free.split(",") if x.strip())
    if not flights:
        if overshoot is None:
            raise InvalidValueError("give flight logs, or --overshoot (and --peak-time) for the paper's methods")
        if method == "lambert":
            if peak_time is None:
                raise InvalidValueError("--method lambert needs --peak-time as well as --overshoot")
            est = E.estimate_lambert(overshoot, peak_time, base, variant=variant)
        elif method == "overshoot":
            est = E.estimate_overshoot(overshoot, base, peak_time=peak_time)
        else:
            raise InvalidValueError("the trajectory method needs flight logs")
        if as_json:
            print_json(est.to_dict())
            return
        out.print(repr(est), highlight=False)
        out.print("no interval" if est.ci is None else f"95 % interval: {fmt_ci(est.ci)}", highlight=False)
        if est.delay_imag is not None:
            out.print(f"complex delay: {est.delay:.4f} {est.delay_imag:+.4f}j s", highlight=False)
        for w in est.warnings:
            warn(w)
        return
    kw = {"step_time": step_time} if step_time is not None else {}
    logs = [_flight_log(f, skip_bad=skip_bad, output=output, reference=reference, input_col=input_col,
                        window=window, allow_truncated=allow_truncated, **kw) for f in flights]
    if steps not in ("all", "first"):
        raise InvalidValueError(f"--steps must be all or first; got {steps!r}")
    if steps == "all" and step_time is None:  # (a step time given says where the one step is)
        from ..identify.steps import split_steps

        logs = [piece for log in logs for piece in split_steps(log)]
    if method == "trajectory":
        with err.status(f"fitting {len(logs)} flight(s)…"):
            pooled, each = E.estimate_flights(logs, base, free=free_t, steps="first")
    else:
        each = []
        for log in logs:
            m = step_metrics(log.t, log.z, step=log.step, z0=log.z0, step_time=log.step_time)
            if method == "overshoot":
                each.append(E.estimate_overshoot(m.overshoot, base, peak_time=m.peak_time, step=abs(log.step)))
            else:
                if m.peak_time is None:
                    raise E.EstimationError(f"{log.name}: no overshoot, so no damping ratio for the Lambert method")
                each.append(E.estimate_lambert(m.overshoot, m.peak_time, base, variant=variant))
        import numpy as np

        d = np.array([e.delay for e in each])
        se = float(np.std(d, ddof=1) / np.sqrt(d.size)) if d.size > 1 else None
        ci = (float(d.mean() - 1.96 * se), float(d.mean() + 1.96 * se)) if se else None
        pooled = E.DelayEstimate(delay=float(d.mean()), stderr=se, ci=ci, method=method, flights=d.size,
                                 diagnostics=E.Diagnostics(note="mean of the flights; error from their spread"))
    rows = [{"file": log.name, "delay": e.delay, "stderr": e.stderr, "ci": ci_list(e.ci),
             "skipped_rows": log.skipped, "warnings": e.warnings} for log, e in zip(logs, each)]
    result = {"flights": rows, "pooled": {"delay": pooled.delay, "stderr": pooled.stderr, "ci": ci_list(pooled.ci),
                                          "spread": pooled.diagnostics.spread,
                                          "warnings": pooled.warnings}, "method": method}
    if plot is not None and method == "trajectory":
        from ..plotting.figures import plot_fit

        fits = [(log.t, E.fitted_altitude(log, pooled, base, i)) for i, log in enumerate(logs)]
        plot_fit(logs, fits, plot, title=f"pooled delay {pooled.delay:.4f} s")
    if as_json:
        print_json(result)
        return
    from rich.table import Table

    table = Table(title=f"Delay by the {method} method (Kp = {kp:g})")
    for col in ("flight", "delay (s)", "± stderr", "95 % interval", "skipped rows"):
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(Path(r["file"]).name, f"{r['delay']:.4f}", fmt(r["stderr"]), fmt_ci(r["ci"]), str(r["skipped_rows"]))
    if len(rows) > 1:
        table.add_row("pooled", f"{pooled.delay:.4f}", fmt(pooled.stderr), fmt_ci(pooled.ci), "")
    out.print(table)
    # the pooled fit's warnings, then each flight's own (named) where it adds something: one flight's fit is the
    # pooled fit, whose warnings are not repeated
    said = set(pooled.warnings)
    lines = list(pooled.warnings)
    for r in rows:
        lines += [w if len(rows) == 1 else f"{Path(r['file']).name}: {w}" for w in r["warnings"] if w not in said]
    for w in lines:
        warn(w)


def _flight_log(path: Path, *, skip_bad: bool, output: Optional[str], reference: Optional[str],
                input_col: Optional[str], window: Optional[str], allow_truncated: bool, **kw: Any) -> Any:
    """A FlightLog from a CSV file or a vehicle log (its signals named by --output, --reference, --input)."""
    from ..identify.flightlog import FlightLog
    from ..identify.logalign import parse_window, read_log_flight
    from ..identify.vehiclelogs import log_format

    win = parse_window(window) if window is not None else None
    if log_format(path) is None:
        if output is not None or reference is not None or input_col is not None or allow_truncated:
            raise InvalidValueError(f"{path}: --output, --reference, --input and --allow-truncated name a flight "
                                    "log's signals (.ulg, .bin, .log, .tlog); a CSV log has the columns t, z, z_ref, u")
        log = FlightLog.from_csv(path, skip_bad=skip_bad, **kw)
        return log if win is None else _window_log(log, win, **kw)
    if output is None or (reference is None and "step_time" not in kw):
        raise InvalidValueError(f"{path}: a flight log needs --output (the altitude, up positive, e.g. "
                                "-vehicle_local_position.z) and --reference (its setpoint); `delaykit log FILE` "
                                "lists the signals")
    return read_log_flight(path, z=output, z_ref=reference, u=input_col, window=win,
                           allow_truncated=allow_truncated, **kw)


def _window_log(log: Any, win: tuple[float, float], **kw: Any) -> Any:
    from ..identify.flightlog import FlightLog, LogError

    if win[0] < log.t[0] or win[1] > log.t[-1]:
        raise LogError(f"{log.name}: the window {win[0]:g}:{win[1]:g} s is not within the log ({log.t[0]:g} to "
                       f"{log.t[-1]:g} s)")
    k = (log.t >= win[0]) & (log.t <= win[1])
    return FlightLog.from_arrays(log.t[k], log.z[k], log.z_ref[k], None if log.u is None else log.u[k],
                                 name=log.name, **kw)


# the loop options `identify` leaves out: the plant and its delay are what it finds, a compensator is refused
_IDENTIFY_OMITS = ("plant", "delay", "output_delay", "model_delay", "closed_loop_time")


@friendly
@with_loop(omit=_IDENTIFY_OMITS)
def identify(
    logs: list[Path] = typer.Argument(..., help="Logs: CSV with a header (time, the input or reference, outputs), or PX4 .ulg, ArduPilot .bin/.log, MAVLink .tlog (columns then named topic.field, e.g. --input trajectory_setpoint.velocity[2] --output -vehicle_local_position.vz; a leading - flips NED down to up)."),
    closed_loop: bool = typer.Option(False, "--closed-loop", help="Closed-loop fit from the reference through the controller given by the loop options (--controller p | pv | pi | pd | pid | a transfer function, its gains, --umin/--umax, --antiwindup, --period = the log's; pi, pd, pid and tf may be continuous: no --period; p and pv must be sampled)."),
    input_col: str = typer.Option("u", "--input", help="The plant's command column (open-loop fit)."),
    reference: str = typer.Option("z_ref", "--reference", help="The reference column (with --closed-loop)."),
    output: str = typer.Option("z", "--output", help="The output column."),
    rate: Optional[str] = typer.Option(None, "--rate", help="A column holding the output's rate (e.g. vz), fitted jointly."),
    time_col: str = typer.Option("t", "--time", help="The time column (s)."),
    model: str = typer.Option("auto", "--model", help="auto | ipdt | ipdt_lag | ipdt_speed | fopdt | sopdt | ipdt_accel (an acceleration limit: open loop only)."),
    baseline: str = typer.Option("initial", "--baseline", help="initial (mean before the drive moves) | fit (an offset per log)."),
    u_before: Optional[float] = typer.Option(None, "--u-before", help="The input before the log, when the log starts with the step (default 0)."),
    u0: Optional[float] = typer.Option(None, "--u0", help="With --closed-loop: the absolute command at rest before the logs, which places the limits (needed for an integrating controller, limits and a self-regulating plant)."),
    command: Optional[str] = typer.Option(None, "--command", help="With --closed-loop: the logs' command column; its value at rest is --u0."),
    resample: Optional[float] = typer.Option(None, "--resample", help="Put the logs on this uniform period first, s (the drive held, the outputs interpolated; timing then known to this period). Optional: logs are fitted on their own clock, even an irregular one; only a closed loop sampled at the log's samples needs a uniform clock."),
    candidates: Optional[str] = typer.Option(None, "--candidates", help="With --model auto: the structures tried, comma-separated, e.g. ipdt,ipdt_lag (default: all those of the fit's kind; ipdt_accel is simulated in Python, about 4 ms per thousand samples per trial point: leave it out of long logs that show no acceleration limit)."),
    accel_limit: Optional[float] = typer.Option(None, "--accel-limit", help="The vehicle's acceleration limit (the input's unit per second, m/s^2 for a speed command; ArduCopter's WPNAV_ACCEL_Z), held by ipdt_accel instead of fitted."),
    fresh_only: bool = typer.Option(False, "--fresh-only", help="Count only output samples that changed (a sensor slower than the log repeats its values)."),
    window: Optional[str] = typer.Option(None, "--window", help="T0:T1, the part of the logs used, in the log's own seconds (a flight log: since boot, as `delaykit log` shows)."),
    allow_truncated: bool = typer.Option(False, "--allow-truncated", help="Read a flight log cut short up to its last whole message."),
    save: Optional[Path] = typer.Option(None, "--save", help="Write the model here (JSON), for `delaykit predict`."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Overlay each log and the model's free-run prediction here."),
    loop_options: Any = None,
) -> None:
    """Identify a plant and its dead time from logs, open loop (from the command) or closed loop (from the reference).

    With --model auto every structure is fitted and one is chosen: by leave-one-log-out prediction error with
    two logs or more, by BIC with one. Standard errors allow for coloured residuals (an autoregressive noise model).
    A delay in a loop file (--loop) is ignored: it is what is identified.
    """
    from ..identify.identification import identify as run_identify
    from ..identify.identification import predict as run_predict
    from ..identify.iodata import read_experiment
    from .loopopts import build_loop

    check_output("--plot", plot, "figure")
    check_output("--save", save)
    given = {k: v for k, v in loop_options.items() if v is not None}
    loop = None
    if closed_loop:
        opts = {**loop_options, "delay": "0"}
        if str(given.get("controller", "p")).lower() not in ("p", "pv") and "loop_file" not in given:
            opts["plant"] = "1/s"  # (ignored) so that the paper's P/PV loop's +-1 limits are not assumed
        loop, _ = build_loop(opts, parse_delays)
    elif given:
        raise InvalidValueError(f"the loop options ({', '.join('--' + k.replace('_', '-') for k in given)}) describe "
                                "the controller of a closed-loop fit: add --closed-loop, or drop them")
    if (u0 is not None or command is not None) and not closed_loop:
        raise InvalidValueError("--u0 and --command give the command at rest of a closed-loop fit: add --closed-loop")
    drive = {"reference": reference} if closed_loop else {"input": input_col, "u_before": u_before}
    cols = [output] + ([rate] if rate else []) + ([command] if command else [])
    win = None
    if window is not None:
        from ..identify.logalign import parse_window

        win = parse_window(window)
    with err.status(f"reading {len(logs)} log(s)…"):  # (a log of millions of rows takes seconds)
        exps = [read_experiment(f, outputs=cols, time=time_col, resample=resample, window=win,
                                allow_truncated=allow_truncated, **drive) for f in logs]
    tried = None if candidates is None else [c.strip() for c in candidates.split(",") if c.strip()]
    with progress_bar(spinner=True) as bar:
        task = bar.add_task("identifying…", total=None)
        m = run_identify(exps, model=model, loop=loop, outputs=[output], rate=rate,
                         baseline=baseline, fresh_only=fresh_only, u0=u0, command=command, accel_limit=accel_limit,
                         candidates=tried,
                         progress=lambda msg: bar.update(task, description=msg))
    if save is not None:
        m.save(save)
    if plot is not None:
        from ..plotting.identification import model_title, plot_predictions

        plot_predictions([run_predict(m, e, u0=u0, command=command) for e in exps], path=plot,
                         title=model_title(m))
    if as_json:
        print_json(m.to_dict())
        return
    from rich.table import Table

    table = Table(title=f"{m.structure.title} ({m.model}), {'closed' if closed_loop else 'open'} loop, {len(exps)} log(s)")
    for col in ("parameter", "unit", "value", "± stderr", "95 % interval"):
        table.add_column(col, justify="right")
    drive_col = reference if closed_loop else input_col
    for p, unit in zip(m.structure.params, m.structure.units):
        table.add_row(p, _unit(unit, output, drive_col), f"{m.params[p]:.5g}", f"{m.stderr[p]:.2g}",
                      fmt_ci(m.ci[p]) if m.is_determined(p) else "not determined")
    out.print(table, highlight=False)
    if m.candidates:
        ct = Table(title=f"candidates (chosen by {m.criterion} among those whose status is ok)")
        for col in ("model", f"rms ({output})", "BIC", f"leave-one-out rms ({output})", "status"):
            ct.add_column(col, justify="right")
        for c in m.candidates:
            ct.add_row(c.model, f"{c.rms:.4g}", f"{c.bic:.1f}", fmt(c.lolo_rms), c.status)
        out.print(ct, highlight=False)
        for c in m.candidates:
            if c.status != "ok":
                warn(f"{c.model}: {c.reason or ''}", label=c.status)
    print_rms("logs", [(d["file"], d["rms"], d["wander"]) for d in (g.to_dict() for g in m.logs)])
    for w in m.warnings:
        warn(w)
    if save is not None:
        out.print(f"model written to {save}", highlight=False)


def _unit(unit: str, output: str, drive: str) -> str:
    """A structure's unit with its placeholders named: ``y`` the output column's unit, ``u`` the drive's.

    Examples
    --------
    >>> _unit("y/(u s)", "z", "u"), _unit("s", "T1", "Q1"), _unit("rad/s", "z", "u")
    ('z/(u s)', 's', 'rad/s')
    """
    return re.sub(r"\b[yu]\b", lambda m_: output if m_.group(0) == "y" else drive, unit)


@friendly
def predict(
    model_file: Path = typer.Argument(..., help="A model written by `delaykit identify --save`."),
    logs: list[Path] = typer.Argument(..., help="Logs to predict (same columns as the model was fitted on)."),
    time_col: str = typer.Option("t", "--time", help="The time column (s)."),
    u_before: Optional[float] = typer.Option(None, "--u-before", help="The input before the log, when it starts with the step."),
    u0: Optional[float] = typer.Option(None, "--u0", help="A closed-loop model: the absolute command at rest before the logs (see identify --u0)."),
    command: Optional[str] = typer.Option(None, "--command", help="A closed-loop model: the logs' command column; its value at rest is --u0."),
    resample: Optional[float] = typer.Option(None, "--resample", help="Put the logs on this uniform period first, s (the drive held, the outputs interpolated; timing then known to this period). Optional: logs are fitted on their own clock, even an irregular one; only a closed loop sampled at the log's samples needs a uniform clock."),
    window: Optional[str] = typer.Option(None, "--window", help="T0:T1, the part of the logs predicted, in the log's own seconds (a flight log: since boot, as `delaykit log` shows)."),
    allow_truncated: bool = typer.Option(False, "--allow-truncated", help="Read a flight log cut short up to its last whole message."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Overlay each log and the prediction here."),
) -> None:
    """Predict logs with an identified model, free-run from each log's input or reference (not one step ahead)."""
    from ..identify.identification import load_model
    from ..identify.identification import predict as run_predict
    from ..identify.iodata import read_experiment

    check_output("--plot", plot, "figure")
    m = load_model(model_file)
    if (u0 is not None or command is not None) and m.closed_loop is None:
        raise InvalidValueError("--u0 and --command are for a closed-loop model; this one is open loop")
    outs = list(m.outputs) + ([m.rate] if m.rate else []) + ([command] if command else [])
    drive = ({"reference": m.drive_column} if m.closed_loop is not None
             else {"input": m.drive_column, "u_before": u_before})
    win = None
    if window is not None:
        from ..identify.logalign import parse_window

        win = parse_window(window)
    with err.status(f"reading and predicting {len(logs)} log(s)…"):
        exps = [read_experiment(f, outputs=outs, time=time_col, resample=resample, window=win,
                                allow_truncated=allow_truncated, **drive) for f in logs]
        preds = [run_predict(m, e, u0=u0, command=command) for e in exps]
    if plot is not None:
        from ..plotting.identification import plot_predictions

        plot_predictions(preds, path=plot, title=f"{m.model} predicting {len(preds)} log(s)")
    rows = [p.to_dict() for p in preds]
    if as_json:
        print_json(rows[0] if len(rows) == 1 else {"logs": rows})
        return
    print_rms(f"free-run prediction by {m!r}", [(r["file"], r["rms"], r["wander"][m.outputs[0]]) for r in rows])


@friendly
def log(
    file: Path = typer.Argument(..., help="A flight log: PX4 .ulg, ArduPilot .bin/.log or MAVLink .tlog."),
    allow_truncated: bool = typer.Option(False, "--allow-truncated", help="Read a flight log cut short up to its last whole message."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """List a flight log's topics (ULog) or messages (DataFlash, tlog): fields, samples, rates and time spans.

    Times are the log's own, in seconds (PX4's timestamp and ArduPilot's TimeUS: since the vehicle booted; a tlog's
    time_boot_ms where a message has it, else its receive stamps). Name a signal for identify and estimate as
    topic.field (topic[1].field for instance 1, field[2] for an array's element; a leading - flips its sign)."""
    from ..identify.vehiclelogs import list_log

    listing = list_log(file, allow_truncated=allow_truncated)
    if as_json:
        print_json(listing.to_dict())
        return
    out.print(f"{listing.name}: {listing.format}, {len(listing.topics)} topics; time in seconds: {listing.clock}",
              highlight=False, markup=False)
    for t in listing.topics:
        span = "no samples" if t.start is None else f"{t.start:.3f} to {t.end:.3f} s"
        out.print(f"{t.name}{'' if t.instance is None else f'[{t.instance}]'}: {t.samples} samples at "
                  f"{t.rate_hz:.3g} Hz, {span}", highlight=False, markup=False)
        fields = [f if not t.units or not t.units[i] else f"{f} ({t.units[i]})" for i, f in enumerate(t.fields)]
        out.print("    " + ", ".join(fields), highlight=False, markup=False)
