"""``delaykit simulate``: one loop's step response and metrics, with a fixed, scheduled, jittered or recorded delay."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any, Optional

import typer

from ..errors import InvalidValueError, check_real, writing
from ..models.budget import MAX_SAMPLES, check_count, sample_count
from .common import (check_output, err, fmt, friendly, out, parse_schedule, print_json, progress_bar,
                     read_delay_trace)
from .loopopts import with_loop

__all__ = ["simulate"]


@friendly
@with_loop
def simulate(
    step: float = typer.Option(1.0, "--step", help="Reference step (either sign), from the level --z0."),
    z0: float = typer.Option(0.0, "--z0", help="Output level before the step (altitude, m)."),
    ramp: Optional[float] = typer.Option(None, "--ramp", help="A ramp reference of this slope (per s) instead of the step."),
    reference_csv: Optional[Path] = typer.Option(None, "--reference", help="A reference given as samples: CSV with columns t, r."),
    hold: str = typer.Option("linear", "--hold", help="Between --reference samples: linear | hold."),
    disturbance: Optional[float] = typer.Option(None, "--disturbance", help="A step load disturbance at the plant input, of this size."),
    disturbance_time: float = typer.Option(0.0, "--disturbance-time", help="When the load disturbance starts, s."),
    disturbance_at: str = typer.Option("plant", "--disturbance-at", help="Where the load enters: plant (at the plant's input, after the input delay) | command (on the command, before the delay: the plant feels it one delay later)."),
    t_end: Optional[float] = typer.Option(None, "--t-end", help="Simulated time after the step, s (default 15; with --system the system's own horizon: 7 time constants of its slowest mode plus 3 times its longest delay)."),
    band: float = typer.Option(0.02, "--band", help="Settling band, fraction of the step."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Write a figure of the response(s) here."),
    csv_path: Optional[Path] = typer.Option(None, "--csv", help="Write t, z, z_ref, u samples here."),
    dt: float = typer.Option(0.01, "--dt", help="Sample interval of --csv, s (with a varying delay, --csv writes the simulation's own record instead)."),
    delay_schedule: Optional[str] = typer.Option(None, "--delay-schedule", help="A delay that changes at given times: T:DELAY pairs, e.g. 5:0.45,10:0.30 (s after the step, s); before the first T the delay is --delay. Needs --period."),
    jitter: Optional[float] = typer.Option(None, "--jitter", help="A random extra delay per packet, at most MAX s: uniform in [0, MAX], or capped at MAX for exponential and gamma. Needs --period."),
    jitter_dist: Optional[str] = typer.Option(None, "--jitter-dist", help="The law of the --jitter extra: uniform (default) | exponential | gamma."),
    jitter_scale: Optional[float] = typer.Option(None, "--jitter-scale", help="--jitter-dist exponential: the mean extra delay; gamma: its scale, s (required for both)."),
    jitter_shape: Optional[float] = typer.Option(None, "--jitter-shape", help="--jitter-dist gamma: the shape (required)."),
    delay_trace: Optional[Path] = typer.Option(None, "--delay-trace", help="Replay a recorded delay, added to --delay: a CSV with a header t,delay (s), or a flight log of `delaykit fly` (its latency_ms column). Give --delay 0 for a trace of whole delays. Needs --period."),
    keep_order: Optional[bool] = typer.Option(None, "--keep-order/--no-keep-order", help="With a varying delay: packets reach the plant in the order sent (a late one holds back the ones behind it), or (the default) a packet may overtake and one arriving after a newer one is dropped."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the --jitter draws (default: new draws every run)."),
    system: Optional[Path] = typer.Option(None, "--system", help="A delay system from a TOML file of blocks connected by name (instead of a loop): the exact step response of each of its inputs, every output (exit status 1 if it stopped early)."),
    loop: Any = None,
    delays: Any = None,
) -> None:
    """Simulate a delayed loop exactly and print its step metrics.

    Any loop: --plant (a transfer function in s), --controller (p, pv, pi, pd, pid or a transfer function),
    the delays, the limits and the sampling, or --loop FILE.toml.  Without --plant it is the paper's loop
    (the integrator 1/s, limits +-1).  With a sweep of delays it prints one row per delay; for the delays of
    the paper's Table 1 (--delay table1 --kp 1.31) the paper's overshoot is shown beside delaykit's.

    A delay that varies from packet to packet (a sampled loop, --period, and one --delay): --delay-schedule,
    --jitter and --delay-trace, which add up packet by packet.  The controller sends a command every period; each
    packet arrives after its own delay and the plant holds the newest one that has arrived.  The response is
    exact between these events; the output adds the smallest and largest delay drawn, the number of packets and
    how many were dropped (overtaken).  A step reference only, with no anti-windup and no compensator.
    """
    if system is not None:
        from .systemfile import system_simulate

        loop_only = (("--step", step, 1.0), ("--z0", z0, 0.0), ("--ramp", ramp, None),
                     ("--reference", reference_csv, None), ("--hold", hold, "linear"),
                     ("--disturbance", disturbance, None), ("--disturbance-time", disturbance_time, 0.0),
                     ("--disturbance-at", disturbance_at, "plant"),
                     ("--band", band, 0.02), ("--csv", csv_path, None), ("--dt", dt, 0.01),
                     ("--delay-schedule", delay_schedule, None), ("--jitter", jitter, None),
                     ("--jitter-dist", jitter_dist, None), ("--jitter-scale", jitter_scale, None),
                     ("--jitter-shape", jitter_shape, None), ("--delay-trace", delay_trace, None),
                     ("--keep-order", keep_order, None), ("--seed", seed, None))
        for flag, value, default in loop_only:
            if value != default:
                raise InvalidValueError(f"simulate --system gives the unit step response of each input; {flag} "
                                        "does not apply to it")
        code = system_simulate(system, t_end, as_json, plot)
        if code:
            raise typer.Exit(code)
        return
    t_end = 15.0 if t_end is None else t_end
    from ..models.altitude import AltitudeLoop
    from ..models.signals import LoadStep, Ramp, Step
    from ..simulate.simulation import simulate as sim

    check_output("--plot", plot, "figure")
    check_output("--csv", csv_path)
    check_real("--dt", dt, minimum=0.0, strict=True)
    if delay_schedule is not None or jitter is not None or delay_trace is not None:
        if ramp is not None or reference_csv is not None or disturbance is not None:
            raise InvalidValueError("a varying delay (--delay-schedule, --jitter, --delay-trace) is simulated for a "
                                    "step reference: --ramp, --reference and --disturbance are not available with it")
        if len(delays) > 1:
            raise InvalidValueError("a varying delay takes one --delay (the delay before the schedule), not a sweep")
        if not loop.sampled:
            raise InvalidValueError("a varying delay (--delay-schedule, --jitter, --delay-trace) acts packet by packet "
                                    "on a sampled controller: give --period (s)")
        model = _varying_delay(loop.delay, delay_schedule, jitter, jitter_dist, jitter_scale, jitter_shape,
                               delay_trace, seed)
        _simulate_varying(loop, model, keep_order, step=step, z0=z0, t_end=t_end, band=band, as_json=as_json,
                          plot=plot, csv_path=csv_path)
        return
    extra = [flag for flag, v in (("--jitter-dist", jitter_dist), ("--jitter-scale", jitter_scale),
                                  ("--jitter-shape", jitter_shape), ("--keep-order", keep_order), ("--seed", seed))
             if v is not None]
    if extra:
        raise InvalidValueError(f"{extra[0]} goes with a varying delay: add --delay-schedule, --jitter or "
                                "--delay-trace")
    if csv_path is not None:  # the record's size, before the work
        each = sample_count(f"--csv every --dt {dt:g} s over --t-end {t_end:g} s", t_end, dt, "give a larger --dt")
        check_count(f"--csv of {len(delays)} delays", each * len(delays), MAX_SAMPLES, "samples",
                    "give a larger --dt or fewer delays")
    from ..simulate import _jit

    with _jit.interpreter():  # short runs as plain Python, without numba's start-up; a long one moves to numba
        ref: Any = Step(step)
        if ramp is not None and reference_csv is not None:
            raise InvalidValueError("give --ramp or --reference, not both")
        if ramp is not None:
            ref = Ramp(slope=ramp, size=0.0)
        elif reference_csv is not None:
            ref = _read_reference(reference_csv, hold)
        if disturbance is None and disturbance_at != "plant":
            raise InvalidValueError(f"--disturbance-at {disturbance_at} places a load: give its size, --disturbance")
        dist = LoadStep(disturbance, disturbance_time, at=disturbance_at) if disturbance is not None else None
        def run(d: float) -> Any:
            return sim(loop.replace(delay=d), step, z0=z0, t_end=t_end, band=band, reference=ref, disturbance=dist)

        if len(delays) == 1:
            with err.status("simulating (the first run compiles the solver, a few seconds)…"):
                responses = [run(delays[0])]
        else:  # a sweep (up to MAX_RANGE_POINTS delays): a bar that counts them
            responses = []
            with progress_bar() as bar:
                task = bar.add_task(f"simulating {len(delays)} delays", total=len(delays))
                for d in delays:
                    responses.append(run(d))
                    bar.advance(task)
        paper_cfg = isinstance(loop, AltitudeLoop) and isinstance(ref, Step) and step == 1.0 and dist is None
        if paper_cfg:  # the paper's loop: its printed overshoot beside ours (other loops need not load the paper)
            from ..paper.data import paper_loop, table1_overshoot

            paper_cfg = loop == paper_loop(loop.delay)
        plain = None
        if dist is not None:  # the setpoint's own settling: the same runs without the load
            from ..simulate.metrics import load_recovery

            plain = [sim(loop.replace(delay=d), step, z0=z0, t_end=t_end, band=band, reference=ref) for d in delays]
        rows = []
        for i, r in enumerate(responses):
            row = {"delay": r.loop.delay, **r.to_dict()}
            if plain is not None and r.metrics is not None and plain[i].metrics is not None:
                row["setpoint_settling_time"] = plain[i].metrics.settling_time
                row["load_recovery_time"] = load_recovery(r.metrics, disturbance_time)
            if paper_cfg and table1_overshoot(r.loop.delay) is not None:
                row["paper_overshoot"] = table1_overshoot(r.loop.delay)
            rows.append(row)
        if csv_path is not None:
            with writing("--csv", csv_path), open(csv_path, "w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow((["delay"] if len(responses) > 1 else []) + ["t", "z", "z_ref", "u"])
                for r in responses:
                    s = r.sample(dt=dt)
                    for i in range(s["t"].size):
                        vals = [f"{s[k][i]:.9g}" for k in ("t", "z", "z_ref", "u")]
                        w.writerow(([f"{r.loop.delay:.9g}"] if len(responses) > 1 else []) + vals)
        if plot is not None:
            from ..plotting.figures import plot_responses

            plot_responses(responses, plot, title=repr(loop) if len(delays) == 1 else None)
        if as_json:
            print_json(rows[0] if len(rows) == 1 else rows)
            return
        title = repr(loop) if len(delays) == 1 else repr(loop).replace(f"delay={loop.delay:.4g} s, ", "")
        from rich.table import Table

        table = Table(title=title)
        table.add_column("Td s", justify="right")
        table.add_column("Mo %", justify="right")
        if any("paper_overshoot" in r for r in rows):
            table.add_column("paper Mo %", justify="right")
            table.add_column("paper−ours", justify="right")
        split = plain is not None
        for col in ("peak s", "rise s") + (("setpoint settle s", "load recovery s") if split else ("settle s",)):
            table.add_column(col, justify="right")
        for r in rows:
            if "overshoot" not in r:
                paper_cols = ["–", "–"] if any("paper_overshoot" in x for x in rows) else []
                table.add_row(fmt(r['delay'], 5), "–", *paper_cols, *["–"] * (4 if split else 3))
                continue
            cells = [fmt(r['delay'], 5), fmt(r["overshoot"])]
            if any("paper_overshoot" in x for x in rows):
                p = r.get("paper_overshoot")
                cells += [fmt(p, 3), "–" if p is None else f"{p - r['overshoot']:+.4f}"]
            cells += [fmt(r["peak_time"]), fmt(r["rise_time"])]
            if split:
                cells += ["never" if r.get(k) is None else fmt(r[k])
                          for k in ("setpoint_settling_time", "load_recovery_time")]
            else:
                cells += [fmt(r["settling_time"]) if r["settled"] else "never"]
            table.add_row(*cells)
        out.print(table)
        if split:
            out.print(f"load step of {disturbance:g} at t = {disturbance_time:g} s: the setpoint settling is the run's "
                      "without the load; the recovery counts from the load step until back in the "
                      f"±{100 * band:g} % band", highlight=False)


def _varying_delay(base: float, schedule: Optional[str], jitter: Optional[float], dist: Optional[str],
                   scale: Optional[float], shape: Optional[float], trace: Optional[Path], seed: Optional[int]) -> Any:
    """The delay model of simulate's varying-delay options: the schedule (or the constant ``base``), plus the
    jitter, plus the trace, added packet by packet."""
    from ..simulate.varying import JITTER_DISTRIBUTIONS, DelaySchedule, Jitter

    parts: list[Any] = []
    if schedule is not None:
        pairs = parse_schedule(schedule)
        if pairs[0][0] > 0:  # before the first time: --delay
            pairs = [(0.0, base), *pairs]
        parts.append(DelaySchedule.from_pairs(pairs))
    else:
        parts.append(DelaySchedule.constant(base))
    given = [f for f, v in (("--jitter-dist", dist), ("--jitter-scale", scale), ("--jitter-shape", shape),
                            ("--seed", seed)) if v is not None]
    if jitter is None and given:
        raise InvalidValueError(f"{given[0]} goes with --jitter MAX (the largest extra delay per packet, s)")
    if jitter is not None:
        cap = check_real("--jitter (the largest extra delay per packet, s)", jitter, minimum=0.0)
        law = (dist or "uniform").strip().lower()
        if law not in JITTER_DISTRIBUTIONS:
            raise InvalidValueError(f"--jitter-dist must be one of {' | '.join(JITTER_DISTRIBUTIONS)}, got {dist!r}")
        if law == "uniform":
            if scale is not None or shape is not None:
                raise InvalidValueError("--jitter-scale and --jitter-shape are for --jitter-dist exponential or gamma; "
                                        "the uniform extra is in [0, --jitter]")
            parts.append(Jitter(0.0, "uniform", spread=cap, seed=seed))
        else:
            if scale is None:
                raise InvalidValueError(f"--jitter-dist {law} needs --jitter-scale (s: "
                                        f"{'the mean extra delay' if law == 'exponential' else 'the scale'})")
            sc = check_real("--jitter-scale (s)", scale, minimum=0.0, strict=True)
            if law == "exponential" and shape is not None:
                raise InvalidValueError("--jitter-shape is for --jitter-dist gamma")
            if law == "gamma" and shape is None:
                raise InvalidValueError("--jitter-dist gamma needs --jitter-shape (the gamma law's shape, > 0)")
            sh = 1.0 if shape is None else check_real("--jitter-shape", shape, minimum=0.0, strict=True)
            parts.append(Jitter(0.0, law, scale=sc, shape=sh, cap=cap, seed=seed))
    if trace is not None:
        parts.append(read_delay_trace(trace))
    model = parts[0]
    for p in parts[1:]:
        model = model + p
    return model


class _Record:
    """A :class:`~delaykit.simulate.varying.VaryingResponse` seen as a response :func:`plot_responses` draws: the
    output between records joined linearly (records are at most 0.01 s apart and at every switch), the input the
    plant applies held between its switches."""

    def __init__(self, r: Any) -> None:
        self.r, self.loop, self.metrics, self.step, self.z0 = r, r.loop, r.metrics, r.step, r.z0

    def sample(self, dt: float = 0.01) -> dict[str, Any]:
        import numpy as np

        r = self.r
        t = np.union1d(np.arange(0.0, r.t_end, dt), r.t)
        held = r.applied_input[np.clip(np.searchsorted(r.t, t, side="right") - 1, 0, r.t.size - 1)]
        return {"t": t, "z": np.interp(t, r.t, r.output), "z_ref": np.full(t.shape, r.z0 + r.step), "u": held}


def _simulate_varying(loop: Any, model: Any, keep_order: Optional[bool], *, step: float, z0: float, t_end: float,
                      band: float, as_json: bool, plot: Optional[Path], csv_path: Optional[Path]) -> None:
    """``simulate`` with a delay that varies from packet to packet (:func:`simulate_varying`)."""
    from ..models.signals import Step
    from ..simulate.varying import simulate_varying

    with err.status("simulating the varying delay (the first run compiles the solver, a few seconds)…"):
        r = simulate_varying(loop, model, step=step, z0=z0, t_end=t_end, band=band, keep_order=keep_order)
    d = r.to_dict()
    order = model.keep_order if keep_order is None else keep_order
    row = {"delay": loop.delay, "delay_model": d.pop("delay"), "keep_order": order, "varying": True,
           "reference": Step(step).to_dict(), "disturbance": None, **d}
    if csv_path is not None:
        with writing("--csv", csv_path), open(csv_path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t", "z", "z_ref", "u"])
            for i in range(r.t.size):
                w.writerow([f"{x:.9g}" for x in (r.t[i], r.output[i], z0 + step, r.applied_input[i])])
    if plot is not None:
        import textwrap

        import numpy as np
        from matplotlib.figure import Figure

        from ..plotting.figures import plot_responses, save_figure

        fig = Figure(figsize=(8, 8), layout="tight")
        ax = fig.subplots(3, 1, sharex=True, height_ratios=[3, 1.4, 1.4])
        plot_responses([_Record(r)], ax=ax[:2], labels=["varying delay"], title=repr(loop))  # type: ignore[list-item]
        ax[1].set_ylabel("plant input u (m/s)")
        ax[1].set_xlabel("")
        ax[2].set_title(textwrap.shorten(repr(model), 140), fontsize=8)
        ax[2].step(r.send_times, r.delays, where="post", lw=1.0, label="delay of the packet sent")
        if r.dropped:
            ax[2].plot(r.send_times[~r.used], r.delays[~r.used], "x", color="C3", ms=4, label="dropped (overtaken)")
        ax[2].set_ylabel("packet delay (s)")
        ax[2].set_xlabel("time after the step (s)")
        ax[2].set_ylim(bottom=min(0.0, float(np.min(r.delays))))
        ax[2].grid(alpha=0.3)
        ax[2].legend(fontsize=8)
        save_figure(fig, plot)
    if as_json:
        print_json(row)
        return
    from rich.table import Table

    table = Table(title=repr(loop))
    for col in ("delay s", "Mo %", "peak s", "rise s", "settle s", "packets", "dropped"):
        table.add_column(col, justify="right")
    span = fmt(row['delay_min'], 5) if row["delay_min"] == row["delay_max"] else \
        f"{fmt(row['delay_min'], 5)} to {fmt(row['delay_max'], 5)}"
    if "overshoot" in row:
        cells = [fmt(row["overshoot"]), fmt(row["peak_time"]), fmt(row["rise_time"]),
                 fmt(row["settling_time"]) if row["settled"] else "never"]
    else:
        cells = ["–"] * 4
    table.add_row(span, *cells, str(row["packets"]), str(row["dropped"]))
    out.print(table)
    out.print(f"Delay per packet: {_as_run(model, order)!r}; "
              f"{'kept in order' if order else 'packets may overtake (a stale one is dropped)'}.", highlight=False)


def _as_run(model: Any, order: bool) -> Any:
    """The delay model with the packet order it ran with (``--keep-order`` overrides the model's own), to print."""
    import dataclasses

    from ..simulate.varying import CombinedDelay

    if isinstance(model, CombinedDelay):
        return CombinedDelay(tuple(_as_run(p, order) for p in model.parts))
    if model.keep_order != order and dataclasses.is_dataclass(model):
        return dataclasses.replace(model, keep_order=order)
    return model


def _read_reference(path: Path, hold: str) -> Any:
    """A reference from a CSV file with columns t and r (a header row naming them)."""
    from ..models.signals import Samples

    from ..models.budget import read_regular

    try:
        text = read_regular(path, "reference file").decode("utf-8-sig")
    except OSError as exc:
        raise InvalidValueError(f"cannot read the reference file {str(path)!r}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InvalidValueError(f"the reference file {str(path)!r} is not UTF-8 text") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows or [c.strip() for c in rows[0][:2]] != ["t", "r"]:
        raise InvalidValueError(f"the reference file {str(path)!r} must start with a header row 't,r'")
    from ..models.ranges import parse_number

    try:
        t = [parse_number(r[0]) for r in rows[1:] if r]
        v = [parse_number(r[1]) for r in rows[1:] if r]
    except (ValueError, IndexError):
        raise InvalidValueError(f"the reference file {str(path)!r} has a row that is not two numbers") from None
    return Samples(t, v, hold=hold)
