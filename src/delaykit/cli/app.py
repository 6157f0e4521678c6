"""The ``delaykit`` command line: a thin layer over the library.

Every command has ``--help``; those that print results have ``--json``; figures are written only where
``--plot FILE`` asks.  Bad input prints one line, ``error: ...``, and exits with status 2.
"""

from __future__ import annotations

import csv
import functools
import json
import math
import sys
from pathlib import Path
from typing import Any, Callable, Optional

import typer
from rich.console import Console
from rich.table import Table

from ..errors import DelaykitError, InvalidValueError, RangeSpecError, check_real
from .loopopts import parse_limit, with_loop

__all__ = ["app", "main", "parse_delays"]

app = typer.Typer(
    help="delaykit: feedback loops with a time delay (the quadrotor altitude loop of Armah & Yi).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
out = Console(soft_wrap=True)
err = Console(stderr=True)


def _friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn delaykit's errors into one line on stderr and exit status 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except DelaykitError as exc:
            err.print(f"[bold red]error:[/] {exc}", highlight=False)
            raise typer.Exit(2) from None

    return wrapper


def parse_delays(spec: str) -> list[float]:
    """Delays from ``0.368``, ``START:STOP:N``, ``a,b,c`` or ``table1`` (the K·Ts of the paper's Table 1).

    Examples
    --------
    >>> parse_delays("0.2:0.5:4")
    [0.2, 0.3, 0.4, 0.5]
    >>> len(parse_delays("table1"))
    7
    """
    from ..models.ranges import parse_range

    spec = spec.strip()
    if spec.lower() == "table1":
        from ..models.altitude import PAPER_PERIOD
        from ..paper.data import TABLE1

        return [k * PAPER_PERIOD for k, _, _ in TABLE1]
    try:
        return parse_range(spec, "--delay")
    except RangeSpecError:
        raise RangeSpecError(f"--delay {spec!r} is not a delay: give seconds (0.368), START:STOP:N, a comma "
                             "list, or 'table1'") from None


def parse_schedule(spec: str) -> list[tuple[float, float]]:
    """A delay schedule from ``T:DELAY`` pairs separated by commas (times and delays in seconds): finite, the
    delays at least 0, the times increasing; an error names the bad item as the user wrote it.

    Examples
    --------
    >>> parse_schedule("20:0.40, 40:0.25")
    [(20.0, 0.4), (40.0, 0.25)]
    """
    pairs: list[tuple[float, float]] = []
    items = [x.strip() for x in spec.split(",")]
    for k, item in enumerate(items):
        parts = item.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            t, d = float(parts[0]), float(parts[1])
        except ValueError:
            raise InvalidValueError(f"--delay-schedule item {k + 1} {item!r} is not T:DELAY (seconds since "
                                    "start, delay in seconds), e.g. 20:0.40") from None
        if not (math.isfinite(t) and math.isfinite(d)):
            raise InvalidValueError(f"--delay-schedule item {k + 1} {item!r}: the time and the delay must be "
                                    "finite numbers")
        if d < 0:
            raise InvalidValueError(f"--delay-schedule item {k + 1} {item!r}: the delay {d:g} s is negative "
                                    "(a delay is at least 0 s)")
        if pairs and not t > pairs[-1][0]:
            raise InvalidValueError(f"--delay-schedule times must increase: item {k + 1} {item!r} (t = {t:g} s) "
                                    f"is not after item {k} {items[k - 1]!r} (t = {pairs[-1][0]:g} s)")
        pairs.append((t, d))
    return pairs


def _fmt(x: Optional[float], digits: int = 4) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def _fmt_ci(ci: Any, digits: int = 4) -> str:
    """A confidence interval as text: ``a to b``, or ``no interval`` when the method gave none (``None``)."""
    return "no interval" if ci is None else f"{ci[0]:.{digits}f} to {ci[1]:.{digits}f}"


def _ci_list(ci: Any) -> Optional[list[float]]:
    """A confidence interval for JSON: ``[a, b]``, or ``None`` (null) when there is none."""
    return None if ci is None else [float(ci[0]), float(ci[1])]


@app.command()
@_friendly
@with_loop
def simulate(
    step: float = typer.Option(1.0, "--step", help="Reference step (either sign), from the level --z0."),
    z0: float = typer.Option(0.0, "--z0", help="Output level before the step (altitude, m)."),
    ramp: Optional[float] = typer.Option(None, "--ramp", help="A ramp reference of this slope (per s) instead of the step."),
    reference_csv: Optional[Path] = typer.Option(None, "--reference", help="A reference given as samples: CSV with columns t, r."),
    hold: str = typer.Option("linear", "--hold", help="Between --reference samples: linear | hold."),
    disturbance: Optional[float] = typer.Option(None, "--disturbance", help="A step load disturbance at the plant input, of this size."),
    disturbance_time: float = typer.Option(0.0, "--disturbance-time", help="When the load disturbance starts, s."),
    t_end: float = typer.Option(15.0, "--t-end", help="Simulated time after the step, s."),
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
    from ..models.altitude import AltitudeLoop
    from ..models.signals import LoadStep, Ramp, Step
    from ..paper.data import paper_loop, table1_overshoot
    from ..simulate.simulation import simulate as sim

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
    ref: Any = Step(step)
    if ramp is not None and reference_csv is not None:
        raise InvalidValueError("give --ramp or --reference, not both")
    if ramp is not None:
        ref = Ramp(slope=ramp, size=0.0)
    elif reference_csv is not None:
        ref = _read_reference(reference_csv, hold)
    dist = LoadStep(disturbance, disturbance_time) if disturbance is not None else None
    with err.status("simulating (the first run compiles the solver, a few seconds)…"):
        responses = [sim(loop.replace(delay=d), step, z0=z0, t_end=t_end, band=band, reference=ref,
                         disturbance=dist) for d in delays]
    paper_cfg = isinstance(loop, AltitudeLoop) and isinstance(ref, Step) and step == 1.0 and dist is None \
        and loop == paper_loop(loop.delay)
    rows = []
    for r in responses:
        row = {"delay": r.loop.delay, **r.to_dict()}
        if paper_cfg and table1_overshoot(r.loop.delay) is not None:
            row["paper_overshoot"] = table1_overshoot(r.loop.delay)
        rows.append(row)
    if csv_path is not None:
        with open(csv_path, "w", newline="") as fh:
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
        print(json.dumps(rows[0] if len(rows) == 1 else rows, indent=2))
        return
    title = repr(loop) if len(delays) == 1 else repr(loop).replace(f"delay={loop.delay:.4g} s, ", "")
    table = Table(title=title)
    table.add_column("Td s", justify="right")
    table.add_column("Mo %", justify="right")
    if any("paper_overshoot" in r for r in rows):
        table.add_column("paper Mo %", justify="right")
        table.add_column("paper−ours", justify="right")
    for col in ("peak s", "rise s", "settle s"):
        table.add_column(col, justify="right")
    for r in rows:
        if "overshoot" not in r:
            table.add_row(f"{r['delay']:.5f}", "–", *(["–", "–"] if any("paper_overshoot" in x for x in rows) else []),
                          "–", "–", "–")
            continue
        cells = [f"{r['delay']:.5f}", _fmt(r["overshoot"])]
        if any("paper_overshoot" in x for x in rows):
            p = r.get("paper_overshoot")
            cells += [_fmt(p, 3), "–" if p is None else f"{p - r['overshoot']:+.4f}"]
        cells += [_fmt(r["peak_time"]), _fmt(r["rise_time"]),
                  _fmt(r["settling_time"]) if r["settled"] else "never"]
        table.add_row(*cells)
    out.print(table)


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
        parts.append(_read_delay_trace(trace))
    model = parts[0]
    for p in parts[1:]:
        model = model + p
    return model


def _read_delay_trace(path: Path) -> Any:
    """``--delay-trace``: a CSV of ``t,delay`` (s), or a flight log with ``latency_ms``, chosen by the header."""
    from ..simulate.varying import DelayTrace

    header: list[str] = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            header = [c.strip() for c in next(csv.reader(fh), [])]
    except (OSError, UnicodeDecodeError, csv.Error):
        return DelayTrace.from_csv(path)  # it says what is wrong with the file
    if not any(header):
        raise InvalidValueError(f"--delay-trace {str(path)!r} is empty: expected a header row t,delay (seconds) or "
                                "a flight log with t and latency_ms")
    if "delay" not in header and "latency_ms" in header:
        return DelayTrace.from_flight_log(path)
    if "delay" not in header:
        raise InvalidValueError(f"--delay-trace {str(path)!r} has no column 'delay' (s) or 'latency_ms' (a flight "
                                f"log); its header is {','.join(header)!r}")
    return DelayTrace.from_csv(path)


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
        with open(csv_path, "w", newline="") as fh:
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
        print(json.dumps(row, indent=2))
        return
    table = Table(title=repr(loop))
    for col in ("delay s", "Mo %", "peak s", "rise s", "settle s", "packets", "dropped"):
        table.add_column(col, justify="right")
    span = f"{row['delay_min']:.5f}" if row["delay_min"] == row["delay_max"] else \
        f"{row['delay_min']:.5f} to {row['delay_max']:.5f}"
    if "overshoot" in row:
        cells = [_fmt(row["overshoot"]), _fmt(row["peak_time"]), _fmt(row["rise_time"]),
                 _fmt(row["settling_time"]) if row["settled"] else "never"]
    else:
        cells = ["–"] * 4
    table.add_row(span, *cells, str(row["packets"]), str(row["dropped"]))
    out.print(table)
    out.print(f"Delay per packet: {model!r}; "
              f"{'kept in order' if order else 'packets may overtake (a stale one is dropped)'}.", highlight=False)


def _read_reference(path: Path, hold: str) -> Any:
    """A reference from a CSV file with columns t and r (a header row naming them)."""
    from ..models.signals import Samples

    try:
        text = Path(path).read_bytes().decode("utf-8-sig")
    except OSError as exc:
        raise InvalidValueError(f"cannot read the reference file {str(path)!r}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InvalidValueError(f"the reference file {str(path)!r} is not UTF-8 text") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows or [c.strip() for c in rows[0][:2]] != ["t", "r"]:
        raise InvalidValueError(f"the reference file {str(path)!r} must start with a header row 't,r'")
    try:
        t = [float(r[0]) for r in rows[1:] if r]
        v = [float(r[1]) for r in rows[1:] if r]
    except (ValueError, IndexError):
        raise InvalidValueError(f"the reference file {str(path)!r} has a row that is not two numbers") from None
    return Samples(t, v, hold=hold)


@app.command()
@_friendly
def report(
    out_dir: Path = typer.Option(Path("out"), "--out", help="Folder to write the report into."),
    as_json: bool = typer.Option(False, "--json", help="Print the results as JSON."),
) -> None:
    """Regenerate only the paper's Table 1, with a figure, into --out (see `reproduce` for everything)."""
    from ..paper.report import table1_markdown, write_report

    with err.status("writing the report…") as status:
        rep = write_report(out_dir, progress=lambda m: status.update(m))
    if as_json:
        print(json.dumps(rep.to_dict(), indent=2))
        return
    from rich.markdown import Markdown

    out.print(Markdown("## Table 1 (Kp = 1.31, P control, ±1 m/s)\n\n" + table1_markdown(rep.rows)))
    out.print(f"\nVerdict: {rep.verdict}.\n", highlight=False)
    out.print("Wrote " + ", ".join(str(f) for f in rep.files), highlight=False)


@app.command()
@_friendly
def reproduce(
    out_dir: Path = typer.Option(Path("out"), "--out", help="Folder for report.md, index.html and the figures."),
    as_json: bool = typer.Option(False, "--json", help="Print the verdicts as JSON."),
) -> None:
    """Regenerate the paper's tables and figures, with the paper's values beside delaykit's and a verdict each."""
    from rich.progress import Progress

    from ..paper.reproduce import reproduce as run

    with Progress(console=err, transient=True) as bar:
        task = bar.add_task("reproducing the paper", total=None)  # the total comes with the first report
        rep = run(out_dir, progress=lambda name, done, total: bar.update(task, completed=done, total=total,
                                                                           description=name))
    if as_json:
        print(json.dumps(rep.to_dict(), indent=2))
        return
    table = Table(title="The paper, regenerated")
    table.add_column("item", justify="left")
    table.add_column("verdict", justify="left")
    for it in rep.items:
        table.add_row(it.title, it.verdict)
    out.print(table)
    out.print(f"Wrote {out_dir / 'report.md'} and {out_dir / 'index.html'} (open it in a browser).", highlight=False)


def _design_compensator(kind: str, opts: dict[str, Any], uncertainty: float, as_json: bool,
                        plot: Optional[Path]) -> None:
    """``design --compensator``: the design, its metrics and robustness (and the map with --plot)."""
    from ..design.compensators import design_compensator, robustness_map
    from .loopopts import build_loop

    import numpy as np

    opts = {k: v for k, v in opts.items() if k not in ("controller", "model_delay")}
    if opts.get("delay") is None and opts.get("loop_file") is None:
        raise InvalidValueError("give --delay (the model delay of the design)")
    loop, _ = build_loop({**opts, "controller": kind}, parse_delays)
    with err.status(f"designing the {kind} compensator…"):
        d = design_compensator(kind, loop.plant, loop.controller.model_delay, umin=loop.umin, umax=loop.umax,
                               delay_uncertainty=uncertainty, closed_loop_time=opts.get("closed_loop_time"))
    if plot is not None:
        from rich.progress import Progress

        from ..plotting.compensation import plot_robustness_map

        dr, gr = np.linspace(0.25, 2.5, 46), np.linspace(0.25, 2.5, 31)
        with Progress(console=err, transient=True) as bar:
            task = bar.add_task("robustness map", total=dr.size * gr.size)
            rm = robustness_map(d.compensator, dr, gr, progress=lambda: bar.advance(task))
        plot_robustness_map(rm, path=plot)
    if as_json:
        print(json.dumps(d.to_dict(), indent=2))
        return
    out.print(repr(d.compensator), highlight=False)
    table = Table(title=f"{kind} design for {loop.plant.to_string(times=' ')}, model delay "
                        f"{d.compensator.model_delay:g} s")
    for col in ("step", "Mo %", "rise s", "settle s", "bound s"):
        table.add_column(col, justify="right")
    for size, m in d.steps.items():
        table.add_row(f"{size:g}", _fmt(None if m is None else m.overshoot),
                      _fmt(None if m is None else m.rise_time),
                      _fmt(None if m is None else m.settling_time), _fmt(d.bounds.get(size)))
    out.print(table)
    lo, hi = d.delay_ratio_range
    out.print(f"Stable for true/model delay ratios {lo:.4f} to {hi:.4f}; {d.disturbance!r}.", highlight=False)


@app.command()
@_friendly
@with_loop(omit=("kp", "kv"))
def design(
    kp: str = typer.Option("2.0", "--kp", help="Kp: a value, a comma list or START:STOP:N."),
    kv: str = typer.Option("0:0.7:8", "--kv", help="Kv: a value, a comma list or START:STOP:N."),
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
    """
    from rich.progress import Progress

    from ..design import tuning as D
    from .loopopts import build_loop

    if compensator is not None:
        _design_compensator(compensator, dict(loop_options), delay_uncertainty, as_json, plot)
        return

    kps = D.parse_range(kp, "--kp")
    kvs = D.parse_range(kv, "--kv")
    opts = dict(loop_options)
    if opts.get("delay") is None and delays_range is not None and opts.get("loop_file") is None:
        opts["delay"] = str(D.parse_range(delays_range, "--delays")[0])
    if opts.get("loop_file") is None:
        opts["kp"] = kps[0]
        opts["kv"] = next((k for k in kvs if k), None)  # a Kv > 0 builds the PV law with its velocity options
    raw = parse_delays(str(opts["delay"])) if opts.get("delay") is not None else None
    base, base_delays = build_loop(opts, parse_delays)
    extra = base_delays[0] - raw[0] if raw else 0.0  # a dead time in the plant's text adds to --delays too
    if delays_range is not None:
        if criterion not in ("abscissa", "settling"):
            raise InvalidValueError(f"--criterion {criterion} is not available with --delays (the robust search "
                                    "ranks by the worst case over the delays): use settling or abscissa")
        dl = [d + extra for d in D.parse_range(delays_range, "--delays")]
        with Progress(console=err, transient=True) as bar:
            task = bar.add_task("gain search", total=None)
            gm = D.gain_search(base, dl, kps, kvs, criterion=criterion, step=step, scheduler=scheduler,
                               progress=lambda k, n: bar.update(task, completed=k, total=n))
        if plot is not None:
            from ..plotting.figures import plot_stability_map
            from ..spectrum.stability import StabilityMap

            plot_stability_map(StabilityMap("kp", "kv", gm.kp, gm.kv, gm.abscissa), plot,
                               title=f"worst-case spectral abscissa over delays {min(dl):g} to {max(dl):g} s")
        if as_json:
            print(json.dumps(gm.to_dict(), indent=2))
            return
        out.print(repr(gm), highlight=False)
        out.print(f"Best: {gm.best} ({gm.reason})." if gm.best else f"No candidate: {gm.reason}.", highlight=False)
        return
    with Progress(console=err, transient=True) as bar:
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
        print(json.dumps({"rows": rows, "best": None if d.best is None else d.best.to_dict(),
                          "criterion": d.criterion, "reason": d.reason}, indent=2))
        return
    table = Table(title=f"Candidates for {base!r}")
    for col in ("Kp", "Kv", "rightmost", "abscissa", "neutral", "stable", "Mo %", "tp s", "ts s"):
        table.add_column(col, justify="right")
    for r in d.rows:
        rm = r.rightmost
        mark = " ←" if d.best is r else ""
        table.add_row(f"{r.kp:g}", f"{r.kv:g}{mark}", "–" if rm is None else f"{rm.real:.2f}±{abs(rm.imag):.2f}j",
                      f"{r.abscissa:.4f}", _fmt(r.neutral_line), "yes" if r.stable else "NO", f"{r.overshoot:.3f}",
                      _fmt(r.peak_time, 3), _fmt(r.settling_time, 3) if r.settling_time is not None else "never")
    out.print(table)
    out.print(f"Best by {d.criterion}: Kp = {d.best.kp:g}, Kv = {d.best.kv:g}: {d.reason}." if d.best
              else f"No candidate meets the criterion: {d.reason}.", highlight=False)


@app.command()
@_friendly
@with_loop
def roots(
    region: tuple[float, float, float, float] = typer.Option(
        (-10.0, 2.0, 0.0, 100.0), "--region", help="RE_MIN RE_MAX IM_MIN IM_MAX."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(
        None, "--plot", help="Draw the spectrum (as the paper's Fig. 8) here; a sampled loop's poles in the z-plane."),
    loop: Any = None,
    delays: Any = None,
) -> None:
    """Every characteristic root of the linearised loop in a region, certified by the argument principle.

    Any continuous loop (the loop options or --loop); saturation is ignored (the linearised loop).  A sampled loop
    (--period) gets its exact discrete-time poles instead (z-plane, every one: --region does not apply), with the
    spectral radius and stability; "abscissa" and "rightmost" are then the equivalent continuous rate log(z)/h.
    --plot then draws them in the z-plane, with the unit circle.
    """
    from ..spectrum.roots import find_roots
    from ..spectrum.stability import rightmost as rightmost_root

    if len(delays) > 1:
        raise InvalidValueError("roots takes one --delay, not a sweep")
    if loop.sampled:
        if plot is not None:
            from ..plotting.figures import plot_z_spectrum
            from ..spectrum.sampled import sampled_spectrum

            plot_z_spectrum(sampled_spectrum(loop), plot, title=repr(loop))
        _sampled_roots(loop, as_json)
        return
    q = loop.characteristic()
    sp = find_roots(q, region)
    rm = rightmost_root(q)
    data = sp.to_dict()
    data["rightmost"] = None if rm.root is None else [rm.root.real, rm.root.imag]
    data["stable"] = rm.stable
    data["abscissa"] = rm.abscissa
    data["rightmost_in_region"] = None if sp.rightmost is None else [sp.rightmost.real, sp.rightmost.imag]
    if plot is not None:
        from ..plotting.figures import plot_spectrum

        plot_spectrum([sp], plot, labels=[repr(loop)], title=str(q))
    if as_json:
        print(json.dumps(data, indent=2))
        return
    table = Table(title=f"{q!r} in {tuple(sp.region)}")
    for col in ("#", "Re s", "Im s", "multiplicity"):
        table.add_column(col, justify="right")
    for i, (z, m) in enumerate(zip(sp.roots, sp.multiplicities), 1):
        table.add_row(str(i), f"{z.real:.6f}", f"{z.imag:.6f}", str(m))
    out.print(table)
    cert = "certified" if sp.certified else f"NOT certified: {sp.reason}"
    nl = f"; neutral line Re s = {sp.neutral_lines[0]:.6f}" if len(sp.neutral_lines) == 1 else ""
    r = rm.root
    out.print(f"{int(sp.multiplicities.sum())} roots, {cert} (argument principle: {sp.count}){nl}.", highlight=False)
    out.print(f"Rightmost root {r.real:.6f} ± {abs(r.imag):.6f}j; spectral abscissa {rm.abscissa:.6f}: "
              f"{'stable' if rm.stable else 'UNSTABLE'}." if r is not None else
              f"Spectral abscissa {rm.abscissa:.6f}: {'stable' if rm.stable else 'UNSTABLE'}.", highlight=False)
    if q.kind == "neutral" and not rm.stable and sp.neutral_lines and max(sp.neutral_lines) >= 0:
        out.print("Warning: this neutral loop's root chains reach the right half-plane (for the paper's loop, "
                  "Kv >= 1): it cannot be stable whatever its other gains.")


def _sampled_roots(loop: Any, as_json: bool) -> None:
    """The roots command for a sampled loop: its poles (z-plane), spectral radius and stability."""
    from ..spectrum.sampled import sampled_spectrum

    sp = sampled_spectrum(loop)
    rate = sp.rate if math.isfinite(sp.rate.real) else None
    data = {**sp.to_dict(), "sampled": True, "abscissa": None if rate is None else rate.real,
            "rightmost": None if rate is None else [rate.real, abs(rate.imag)]}
    if as_json:
        print(json.dumps(data, indent=2))
        return
    table = Table(title=f"Poles of the sampled loop {loop!r} (z-plane, h = {sp.period:g} s)")
    for col in ("#", "Re z", "Im z", "|z|", "rate log|z|/h (1/s)"):
        table.add_column(col, justify="right")
    shown = 30
    for i, z in enumerate(sp.poles.astype(complex)[:shown], 1):
        table.add_row(str(i), f"{z.real:.6f}", f"{z.imag:.6f}", f"{abs(z):.6f}",
                      f"{math.log(abs(z)) / sp.period:.6f}" if z != 0 else "-inf")
    out.print(table)
    more = f" (the {shown} largest shown; --json lists all)" if sp.poles.size > shown else ""
    d = sp.dominant
    out.print(f"{sp.poles.size} poles{more}; spectral radius {sp.radius:.6f} at {d.real:.6f} ± {abs(d.imag):.6f}j "
              f"(decay rate {math.log(sp.radius) / sp.period if sp.radius > 0 else -math.inf:.6f}/s): "
              f"{'stable' if sp.stable else 'UNSTABLE'}.", highlight=False)


@app.command()
@_friendly
@with_loop
def margins(
    wmin: Optional[float] = typer.Option(None, "--wmin", help="Lowest frequency of the plot, rad/s (default: from the loop)."),
    wmax: Optional[float] = typer.Option(None, "--wmax", help="Highest frequency of the plot, rad/s (default: from the loop)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Write a Bode plot, with the Nyquist plot beside it, here."),
    loop: Any = None,
    delays: Any = None,
) -> None:
    """Gain, phase and delay margins, peak sensitivity and every crossover of a loop, exact with the delay.

    Any loop (the loop options or --loop); saturation is ignored (the linearised loop).  A continuous loop's
    stability comes from its exact characteristic roots; a sampled loop's (--period) margins and stability are
    those of its exact discrete-time model (its poles, and L(e^{jwh}) broken at the held command, on (0, pi/h]),
    with the same JSON keys where they exist.  An unstable closed loop gets no margins.

    The jitter margin (Kao & Lincoln 2004; JSON key jitter_margin, s) is the largest extra delay, varying
    arbitrarily fast anywhere between 0 and it on top of the loop's own delay, that is still guaranteed stable.
    It is sufficient only, and never above the delay margin.  Continuous loops only: it is null for a sampled
    loop, whose held command turns a packet delay into a continuous delay up to one period longer (the criterion
    covers the continuous law; for P, or PV with the true velocity, check the loop without --period with the
    range widened by the period).  Also null for an unstable loop, a loop the library's criterion does not take
    (the text output says why), or a margin without bound (no feedback at all).
    """
    from ..spectrum.frequency import frequency_grid, frequency_response
    from ..spectrum.frequency import margins as loop_margins
    from ..spectrum.sampled import sampled_margins, sampled_response, sampled_spectrum

    if len(delays) > 1:
        raise InvalidValueError("margins takes one --delay, not a sweep")
    lo = None if wmin is None else check_real("--wmin", wmin, minimum=0.0, strict=True)
    hi = None if wmax is None else check_real("--wmax", wmax, minimum=0.0, strict=True)
    if lo is not None and hi is not None and not lo < hi:
        raise InvalidValueError(f"--wmin {lo:g} must be below --wmax {hi:g} (rad/s): the frequency range is "
                                f"{'empty' if lo == hi else 'reversed'}")
    sampled = loop.sampled
    if sampled:
        wn = math.pi / loop.period
        for flag, v in (("--wmin", lo), ("--wmax", hi)):
            if v is not None and v > wn:
                raise InvalidValueError(f"{flag} {v:g} rad/s is above pi/h = {wn:.6g} rad/s, the highest frequency "
                                        f"of the loop sampled every {loop.period:g} s")
    m = sampled_margins(loop) if sampled else loop_margins(loop)
    jm: Any = None
    jm_why = "a sampled loop (see --help)" if sampled else "the closed loop is unstable"
    if not sampled and m.stable:
        from ..spectrum.jitter import jitter_margin

        try:
            jm = jitter_margin(loop)
        except DelaykitError as exc:  # a loop the criterion does not take (e.g. a compensator): no margin
            jm_why = str(exc)
    if not sampled and (plot is not None or lo is not None or hi is not None):
        w = frequency_grid(loop, 1000, wmin=lo, wmax=hi)  # checks a range given at one end against the other
    if plot is not None:
        from matplotlib.figure import Figure

        from ..plotting.frequency import plot_bode, plot_nyquist

        if sampled:
            import numpy as np

            a, b = lo or 1e-3 * wn, hi or wn
            if not a < b:
                raise InvalidValueError(f"the frequency range is empty or reversed: {a:g} to {b:g} rad/s")
            resp = sampled_response(loop, np.geomspace(a, b, 1000))
        else:
            resp = frequency_response(loop, w)
        fig = Figure(figsize=(12.0, 6.0), layout="constrained")
        grid = fig.add_gridspec(2, 2)
        ax_mag = fig.add_subplot(grid[0, 0])
        ax_ph = fig.add_subplot(grid[1, 0], sharex=ax_mag)
        fig.suptitle(repr(loop), fontsize=9)
        plot_bode(resp, axes=(ax_mag, ax_ph), margins=None if sampled else m)
        plot_nyquist(resp, plot, ax=fig.add_subplot(grid[:, 1]))  # writes the whole figure
    if as_json:
        data = m.to_dict()
        if sampled:
            data.update(sampled=True, period=loop.period, radius=sampled_spectrum(loop).radius,
                        stability_from="sampled poles")
        data["jitter_margin"] = None if jm is None or not math.isfinite(jm.margin) else jm.margin
        print(json.dumps(data, indent=2))
        return

    def at(w: Optional[float]) -> str:
        return "" if w is None else " at ∞" if math.isinf(w) else f" at {w:.6g} rad/s"

    table = Table(title=f"Margins of {loop!r}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    why = {"roots": "its characteristic roots", "nyquist": "the Nyquist count",
           "neutral chains": "neutral root chains at Re s = ln|L(j∞)|/T ≥ 0"}
    why = (f"its poles, spectral radius {sampled_spectrum(loop).radius:.6f}" if sampled
           else why.get(m.stability_from, m.stability_from))
    table.add_row("closed loop", f"{'stable' if m.stable else 'UNSTABLE'} (from {why})")
    if m.stable:
        table.add_row("gain margin", "∞" if math.isinf(m.gain_margin) else
                      f"{m.gain_margin:.6g} ({m.gain_margin_db:.4f} dB){at(m.phase_crossover)}")
        if m.lower_gain_margin > 0:
            low_db = 20 * math.log10(m.lower_gain_margin)
            table.add_row("lower gain margin", f"{m.lower_gain_margin:.6g} ({low_db:.4f} dB)")
        table.add_row("phase margin", "∞" if math.isinf(m.phase_margin) else f"{m.phase_margin:.4f}°")
        table.add_row("delay margin (extra)", "∞" if math.isinf(m.delay_margin) else
                      f"{m.delay_margin:.6g} s{at(m.crossover)}")
        table.add_row("critical delay (total)", "∞" if math.isinf(m.critical_delay) else f"{m.critical_delay:.6g} s")
        table.add_row("jitter margin (any variation)", "–" if jm is None else "∞" if math.isinf(jm.margin) else
                      f"{jm.margin:.6g} s{at(jm.frequency)}")
        table.add_row("peak sensitivity Ms", f"{m.ms:.6g}{at(getattr(m, 'ms_frequency', None))}")
    if not sampled:
        table.add_row("open-loop RHP poles P", str(m.open_loop_rhp_poles))
        table.add_row("encirclements of -1 (ccw)", "–" if m.encirclements is None else str(m.encirclements))
    out.print(table)
    if m.stable and jm is None:
        out.print(f"No jitter margin: {jm_why.rstrip('.')}.", highlight=False)
    cross = Table(title=f"crossovers up to {math.pi / loop.period if sampled else m.cutoff:.6g} rad/s")
    for col in ("kind", "ω (rad/s)", "|L|", "phase (deg)", "gives"):
        cross.add_column(col, justify="right")
    shown = 12
    for c in m.crossovers[:shown]:
        gives = (f"PM {c.phase_margin:.4f}°" + ("" if sampled else f", DM {c.delay_margin:.6g} s")
                 if c.kind == "gain" else f"gain factor {c.gain_margin:.6g}")
        phase = "–" if math.isnan(c.phase_deg) else f"{c.phase_deg:.4f}"
        cross.add_row(c.kind, "∞" if math.isinf(c.frequency) else f"{c.frequency:.6g}", f"{c.magnitude:.6g}", phase,
                      gives)
    out.print(cross)
    if len(m.crossovers) > shown:
        out.print(f"… and {len(m.crossovers) - shown} more phase crossovers (--json lists them all).",
                  highlight=False)


def _parse_branches(spec: str) -> list[int]:
    try:
        if ":" in spec:
            a, b = (int(x) for x in spec.split(":"))
        else:
            return [int(x) for x in spec.split(",")]
    except ValueError:
        raise InvalidValueError(f"--branches {spec!r} must be K1:K2 or a comma list of integers") from None
    if b < a:
        raise InvalidValueError(f"--branches {spec!r}: the range is reversed (K1 must not exceed K2)")
    return list(range(a, b + 1))


@app.command()
@_friendly
def lambert(
    a0: float = typer.Option(0.0, "--a0", help="a0 in x' = a0 x + a1 x(t - Td)."),
    a1: float = typer.Option(..., "--a1", help="a1 (for the P loop, -Kp)."),
    delay: float = typer.Option(..., "--delay", help="Td, s."),
    branches: str = typer.Option("-3:3", "--branches", help="Lambert W branches: K1:K2 or a list."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Roots s_k = W_k(Td a1 exp(-a0 Td)) / Td + a0 of a first-order delay equation, by branch."""
    from ..spectrum.lambert import lambert_roots

    r = lambert_roots(a0, a1, check_real("--delay", delay, minimum=0.0), branches=_parse_branches(branches))
    data = r.to_dict()
    if as_json:
        print(json.dumps(data, indent=2))
        return
    table = Table(title=f"s - {a0:g} - ({a1:g}) exp(-{delay:g} s) = 0")
    for col in ("branch k", "Re s", "Im s"):
        table.add_column(col, justify="right")
    for row in data["roots"]:
        table.add_row(str(row["branch"]), f"{row['re']:.8f}", f"{row['im']:.8f}")
    out.print(table)
    rm = data["rightmost"]
    out.print(f"Rightmost root {rm[0]:.8f} {rm[1]:+.8f}j (branch 0; for real coefficients branch -1 is its conjugate).",
              highlight=False)


@app.command()
@_friendly
def estimate(
    flights: Optional[list[Path]] = typer.Argument(None, help="Flight logs (CSV: t, z, z_ref[, u])."),
    kp: float = typer.Option(..., "--kp", help="Proportional gain the flights used."),
    kv: float = typer.Option(0.0, "--kv", help="Velocity gain the flights used."),
    vmax: str = typer.Option("1.0", "--vmax", help="Command saturation, m/s, or 'none'."),
    period: Optional[str] = typer.Option(None, "--period", help="Controller period, s (it ran at the log's samples)."),
    method: str = typer.Option("trajectory", "--method", help="trajectory | overshoot | lambert."),
    variant: str = typer.Option("paper", "--variant", help="For lambert: paper | damping."),
    free: str = typer.Option("", "--free", help="Extra fitted parameters for trajectory: gain,lag."),
    step_time: Optional[float] = typer.Option(None, "--step-time", help="Step time in the logs' clock, if not at a sample."),
    skip_bad: bool = typer.Option(False, "--skip-bad", help="Skip (and count) unreadable rows instead of failing."),
    overshoot: Optional[float] = typer.Option(None, "--overshoot", help="Measured overshoot, % (no files needed)."),
    peak_time: Optional[float] = typer.Option(None, "--peak-time", help="Measured peak time, s."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Overlay data, fit and residuals here (trajectory)."),
) -> None:
    """Estimate the loop delay from flight logs, or from a measured overshoot and peak time."""
    from ..identify import estimation as E
    from ..identify.flightlog import FlightLog
    from ..simulate.metrics import step_metrics

    methods = ("trajectory", "overshoot", "lambert")
    if method not in methods:
        raise InvalidValueError(f"--method must be one of {', '.join(methods)}; got {method!r}")
    vm = parse_limit("--vmax", vmax)
    per = parse_limit("--period", period)
    free_t = tuple(x.strip() for x in free.split(",") if x.strip())
    if not flights:
        if overshoot is None:
            raise InvalidValueError("give flight logs, or --overshoot (and --peak-time) for the paper's methods")
        if method == "lambert":
            if peak_time is None:
                raise InvalidValueError("--method lambert needs --peak-time as well as --overshoot")
            est = E.estimate_lambert(overshoot, peak_time, kp, variant=variant)
        elif method == "overshoot":
            est = E.estimate_overshoot(overshoot, kp, peak_time=peak_time, kv=kv, vmax=vm, period=per)
        else:
            raise InvalidValueError("the trajectory method needs flight logs")
        if as_json:
            print(json.dumps(est.to_dict(), indent=2))
            return
        out.print(repr(est), highlight=False)
        out.print("no interval" if est.ci is None else f"95 % interval: {_fmt_ci(est.ci)}", highlight=False)
        if est.delay_imag is not None:
            out.print(f"complex delay: {est.delay:.4f} {est.delay_imag:+.4f}j s", highlight=False)
        for w in est.warnings:
            out.print(f"[yellow]warning:[/] {w}", highlight=False)
        return
    kw = {"step_time": step_time} if step_time is not None else {}
    logs = [FlightLog.from_csv(f, skip_bad=skip_bad, **kw) for f in flights]
    loopkw = dict(kv=kv, vmax=vm, period=per)
    if method == "trajectory":
        with err.status(f"fitting {len(logs)} flight(s)…"):
            pooled, each = E.estimate_flights(logs, kp, free=free_t, **loopkw)
    else:
        each = []
        for log in logs:
            m = step_metrics(log.t, log.z, step=log.step, z0=log.z0, step_time=log.step_time)
            if method == "overshoot":
                each.append(E.estimate_overshoot(m.overshoot, kp, peak_time=m.peak_time, step=abs(log.step), **loopkw))
            else:
                if m.peak_time is None:
                    raise E.EstimationError(f"{log.name}: no overshoot, so no damping ratio for the Lambert method")
                each.append(E.estimate_lambert(m.overshoot, m.peak_time, kp, variant=variant))
        import numpy as np

        d = np.array([e.delay for e in each])
        se = float(np.std(d, ddof=1) / np.sqrt(d.size)) if d.size > 1 else None
        ci = (float(d.mean() - 1.96 * se), float(d.mean() + 1.96 * se)) if se else None
        pooled = E.DelayEstimate(delay=float(d.mean()), stderr=se, ci=ci, method=method, flights=d.size,
                                 diagnostics=E.Diagnostics(note="mean of the flights; error from their spread"))
    rows = [{"file": log.name, "delay": e.delay, "stderr": e.stderr, "ci": _ci_list(e.ci),
             "skipped_rows": log.skipped, "warnings": e.warnings} for log, e in zip(logs, each)]
    result = {"flights": rows, "pooled": {"delay": pooled.delay, "stderr": pooled.stderr, "ci": _ci_list(pooled.ci),
                                          "spread": pooled.diagnostics.spread,
                                          "warnings": pooled.warnings}, "method": method}
    if plot is not None and method == "trajectory":
        from ..plotting.figures import plot_fit

        fits = [(log.t, E.fitted_altitude(log, pooled, kp, i, **loopkw)) for i, log in enumerate(logs)]
        plot_fit(logs, fits, plot, title=f"pooled delay {pooled.delay:.4f} s")
    if as_json:
        print(json.dumps(result, indent=2))
        return
    table = Table(title=f"Delay by the {method} method (Kp = {kp:g})")
    for col in ("flight", "delay (s)", "± stderr", "95 % interval", "skipped rows"):
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(Path(r["file"]).name, f"{r['delay']:.4f}", _fmt(r["stderr"]), _fmt_ci(r["ci"]), str(r["skipped_rows"]))
    if len(rows) > 1:
        table.add_row("pooled", f"{pooled.delay:.4f}", _fmt(pooled.stderr), _fmt_ci(pooled.ci), "")
    out.print(table)
    for w in pooled.warnings + [w for r in rows for w in r["warnings"]]:
        out.print(f"[yellow]warning:[/] {w}", highlight=False)


@app.command()
@_friendly
@with_loop(omit=("plant",))
def identify(
    logs: list[Path] = typer.Argument(..., help="Logs (CSV with a header: time, the input or reference, outputs)."),
    closed_loop: bool = typer.Option(False, "--closed-loop", help="Closed-loop fit from the reference through the controller given by the loop options (P or PV, its limits, --period = the log's)."),
    input_col: str = typer.Option("u", "--input", help="The plant's command column (open-loop fit)."),
    reference: str = typer.Option("z_ref", "--reference", help="The reference column (with --closed-loop)."),
    output: str = typer.Option("z", "--output", help="The output column."),
    rate: Optional[str] = typer.Option(None, "--rate", help="A column holding the output's rate (e.g. vz), fitted jointly."),
    time_col: str = typer.Option("t", "--time", help="The time column (s)."),
    model: str = typer.Option("auto", "--model", help="auto | ipdt | ipdt_lag | ipdt_speed | fopdt | sopdt."),
    baseline: str = typer.Option("initial", "--baseline", help="initial (mean before the drive moves) | fit (an offset per log)."),
    u_before: Optional[float] = typer.Option(None, "--u-before", help="The input before the log, when the log starts with the step (default 0)."),
    fresh_only: bool = typer.Option(False, "--fresh-only", help="Count only output samples that changed (a sensor slower than the log repeats its values)."),
    save: Optional[Path] = typer.Option(None, "--save", help="Write the model here (JSON), for `delaykit predict`."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Overlay each log and the model's free-run prediction here."),
    loop_options: Any = None,
) -> None:
    """Identify a plant and its dead time from logs, open loop (from the command) or closed loop (from the reference).

    With --model auto every structure is fitted and one is chosen: by leave-one-log-out prediction error with
    two logs or more, by BIC with one. Standard errors allow for coloured residuals (an autoregressive noise model).
    """
    from ..identify.identification import identify as run_identify
    from ..identify.identification import predict as run_predict
    from ..identify.iodata import read_experiment
    from .loopopts import build_loop

    given = {k: v for k, v in loop_options.items() if v is not None}
    loop = None
    if closed_loop:
        if given.get("delay") not in (None, "0", "0.0"):
            raise InvalidValueError("identify finds the delay: do not give --delay")
        loop, _ = build_loop(loop_options, parse_delays)
    elif given:
        raise InvalidValueError(f"the loop options ({', '.join('--' + k.replace('_', '-') for k in given)}) describe "
                                "the controller of a closed-loop fit: add --closed-loop, or drop them")
    drive = {"reference": reference} if closed_loop else {"input": input_col, "u_before": u_before}
    exps = [read_experiment(f, outputs=[output] + ([rate] if rate else []), time=time_col, **drive) for f in logs]
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(), console=err,
                  transient=True) as bar:
        task = bar.add_task("identifying…", total=None)
        m = run_identify(exps, model=model, loop=loop, outputs=[output], rate=rate,
                         baseline=baseline, fresh_only=fresh_only,
                         progress=lambda msg: bar.update(task, description=msg))
    if save is not None:
        m.save(save)
    if plot is not None:
        from ..plotting.identification import plot_predictions

        plot_predictions([run_predict(m, e) for e in exps], path=plot, title=repr(m))
    if as_json:
        print(json.dumps(m.to_dict(), indent=2))
        return
    table = Table(title=f"{m.structure.title} ({m.model}), {'closed' if closed_loop else 'open'} loop, {len(exps)} log(s)")
    for col in ("parameter", "value", "± stderr", "95 % interval"):
        table.add_column(col, justify="right")
    for p in m.structure.params:
        table.add_row(p, f"{m.params[p]:.5g}", f"{m.stderr[p]:.2g}", _fmt_ci(m.ci[p]))
    out.print(table)
    if m.candidates:
        ct = Table(title=f"candidates (chosen by {m.criterion})")
        for col in ("model", "rms", "BIC", "leave-one-out rms"):
            ct.add_column(col, justify="right")
        for c in m.candidates:
            ct.add_row(c.model, f"{c.rms:.4g}", f"{c.bic:.1f}", _fmt(c.lolo_rms))
        out.print(ct)
    _print_rms("logs", [(d["file"], d["rms"], d["wander"]) for d in (g.to_dict() for g in m.logs)])
    for w in m.warnings:
        out.print(f"[yellow]warning:[/] {w}", highlight=False)
    if save is not None:
        out.print(f"model written to {save}", highlight=False)


@app.command()
@_friendly
def predict(
    model_file: Path = typer.Argument(..., help="A model written by `delaykit identify --save`."),
    logs: list[Path] = typer.Argument(..., help="Logs to predict (same columns as the model was fitted on)."),
    time_col: str = typer.Option("t", "--time", help="The time column (s)."),
    u_before: Optional[float] = typer.Option(None, "--u-before", help="The input before the log, when it starts with the step."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Overlay each log and the prediction here."),
) -> None:
    """Predict logs with an identified model, free-run from each log's input or reference (not one step ahead)."""
    from ..identify.identification import load_model
    from ..identify.identification import predict as run_predict
    from ..identify.iodata import read_experiment

    m = load_model(model_file)
    outs = list(m.outputs) + ([m.rate] if m.rate else [])
    drive = ({"reference": m.drive_column} if m.closed_loop is not None
             else {"input": m.drive_column, "u_before": u_before})
    exps = [read_experiment(f, outputs=outs, time=time_col, **drive) for f in logs]
    preds = [run_predict(m, e) for e in exps]
    if plot is not None:
        from ..plotting.identification import plot_predictions

        plot_predictions(preds, path=plot, title=f"{m.model} predicting {len(preds)} log(s)")
    rows = [p.to_dict() for p in preds]
    if as_json:
        print(json.dumps(rows[0] if len(rows) == 1 else {"logs": rows}, indent=2))
        return
    _print_rms(f"free-run prediction by {m!r}", [(r["file"], r["rms"], r["wander"][m.outputs[0]]) for r in rows])


def _print_rms(title: str, rows: list[tuple[str, float, Optional[float]]]) -> None:
    """A table of each log's RMS error beside its initial wander (``None`` where the log has none)."""
    table = Table(title=title)
    for col in ("log", "rms", "initial wander", "rms / wander"):
        table.add_column(col, justify="right")
    for file, rms, w in rows:
        table.add_row(file, f"{rms:.4g}", _fmt(w), _fmt(rms / w if w else None, 3))
    out.print(table)


@app.command()
@_friendly
def emulate(
    host: str = typer.Option("127.0.0.1", "--host", help="Address to bind (loopback unless told otherwise)."),
    at_port: int = typer.Option(5556, "--at-port", help="UDP port for AT commands (0 = any free one)."),
    navdata_port: int = typer.Option(5554, "--navdata-port", help="UDP port for navdata (0 = any free one)."),
    video_port: int = typer.Option(5555, "--video-port", help="TCP video port (accepted, nothing sent)."),
    control_port: int = typer.Option(5559, "--control-port", help="TCP control port (configuration text)."),
    delay: float = typer.Option(0.30, "--delay", help="Actuator delay, s."),
    lag: float = typer.Option(0.05, "--lag", help="Lag of the drone's own speed loop, s."),
    link_delay: float = typer.Option(0.0, "--link-delay", help="Extra one-way link delay, s."),
    noise: float = typer.Option(0.005, "--noise", help="Ultrasonic altitude noise (standard deviation), m."),
    rate: float = typer.Option(15.0, "--rate", help="Navdata rate, Hz."),
    loss: float = typer.Option(0.0, "--loss", help="Navdata packet loss, fraction."),
    jitter: float = typer.Option(0.0, "--jitter", help="Navdata send jitter, s."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Random seed."),
    delay_schedule: Optional[str] = typer.Option(None, "--delay-schedule", help="The actuator delay changing mid-run: T:DELAY pairs, e.g. 20:0.40,40:0.25 (s since start, s)."),
    delay_trace: Optional[Path] = typer.Option(None, "--delay-trace", help="Replay a recorded delay, added to --delay (as `simulate --delay-trace`): a CSV with a header t,delay (s), or a flight log of `delaykit fly` (its latency_ms column); each record held until the next, from the first at start. Give --delay 0 for a trace of whole delays. Not with --delay-schedule."),
    burst: Optional[list[str]] = typer.Option(None, "--burst", help="The navdata rate falls (a Wi-Fi scan): START:DURATION[:RATE] (s since start, s, Hz below --rate; RATE 0 by default: no navdata). Repeat it, or separate several by commas."),
    duration: float = typer.Option(0.0, "--duration", help="Run this long, s (0 = until Ctrl-C)."),
) -> None:
    """Run the built-in AR.Drone 2.0 emulator (loopback by default) until Ctrl-C, SIGTERM or --duration; then
    print its summary (ports, counts, rejections) as JSON."""
    import signal
    import threading
    import time as _time

    from ..hardware.emulator import DroneEmulator, EmulatorConfig

    check_real("--duration", duration, minimum=0.0)
    if delay_schedule is not None and delay_trace is not None:
        raise InvalidValueError("give --delay-schedule or --delay-trace, not both: the schedule replaces --delay and "
                                "the trace is added to it")
    cfg = EmulatorConfig(host=host, at_port=at_port, navdata_port=navdata_port, video_port=video_port,
                         control_port=control_port, delay=delay, lag=lag, link_delay=link_delay, noise=noise,
                         rate=rate, loss=loss, jitter=jitter, seed=seed,
                         delay_schedule=None if delay_schedule is None else parse_schedule(delay_schedule),
                         delay_trace=None if delay_trace is None else _read_delay_trace(delay_trace),
                         bursts=_parse_bursts(burst or [], rate))
    terminated = threading.Event()  # SIGTERM ends the run like Ctrl-C: the same summary, exit status 0
    main_thread = threading.current_thread() is threading.main_thread()  # (signal handlers only go there)
    old_term = signal.signal(signal.SIGTERM, lambda *_: terminated.set()) if main_thread else None
    try:
        with DroneEmulator(cfg) as emu:
            err.print(f"emulated drone on {host}: AT {emu.ports['at']}, navdata {emu.ports['navdata']}, video "
                      f"{emu.ports['video']}, control {emu.ports['control']}; loop delay {emu.true_delay:g} s. "
                      "Ctrl-C stops.", highlight=False)
            t0 = _time.monotonic()
            try:
                while not terminated.is_set() and (duration == 0 or _time.monotonic() - t0 < duration):
                    terminated.wait(0.1)
            except KeyboardInterrupt:
                pass
        summary = emu.summary()  # after stop(): the threads are done, so the counts are final
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, old_term)
    print(json.dumps(summary))


def _parse_bursts(specs: list[str], rate: float) -> tuple[tuple[float, float, float], ...]:
    """``--burst`` values (``START:DURATION[:RATE]``, repeated or comma-separated) as checked bursts; an error names
    the item.

    Examples
    --------
    >>> _parse_bursts(["5:1", "8:0.5:2,2:1:5"], 15.0)
    ((2.0, 1.0, 5.0), (5.0, 1.0, 0.0), (8.0, 0.5, 2.0))
    """
    from ..hardware.emulator import check_bursts

    rate = check_real("--rate (Hz)", rate, minimum=1.0, maximum=1000.0)
    items = [x.strip() for spec in specs for x in spec.split(",")]
    bursts = []
    for item in items:
        parts = item.split(":")
        try:
            if len(parts) not in (2, 3):
                raise ValueError
            bursts.append(tuple(float(x) for x in parts))
        except ValueError:
            raise InvalidValueError(f"--burst {item!r} is not START:DURATION[:RATE] (s since start, s, Hz), e.g. 5:1 "
                                    "(no navdata for 1 s from 5 s) or 5:1:2") from None
    return check_bursts(bursts, rate, labels=[f"--burst {x!r}" for x in items])


def _confirm_real(host: str, yes: bool) -> Optional[Callable[[], bool]]:
    import ipaddress

    try:
        loop = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loop = False
    if loop or yes:
        return None
    return lambda: typer.confirm(f"Take off the drone at {host}?", default=False)


@app.command()
@_friendly
def fly(
    host: str = typer.Option("192.168.1.1", "--host", help="The drone (the emulator: 127.0.0.1)."),
    at_port: int = typer.Option(5556, "--at-port", help="The drone's AT command port."),
    navdata_port: int = typer.Option(5554, "--navdata-port", help="The drone's navdata port."),
    controller: str = typer.Option("p", "--controller", help="p | pv (the paper's laws, --kp/--kv) | smith | filtered-smith | predictor (designed for --model-delay)."),
    kp: Optional[float] = typer.Option(None, "--kp", help="Proportional gain (p, pv)."),
    kv: float = typer.Option(0.0, "--kv", help="Velocity gain (pv)."),
    velocity: str = typer.Option("true", "--velocity", help="true (navdata vz) | filtered (derivative filter)."),
    model_delay: Optional[float] = typer.Option(None, "--model-delay", help="Compensators: the delay of the integrator model 1/s they are designed for, s."),
    closed_loop_time: Optional[float] = typer.Option(None, "--closed-loop-time", help="Compensators: Tc, s (default: the fastest surviving --delay-uncertainty)."),
    delay_uncertainty: float = typer.Option(0.2, "--delay-uncertainty", help="The relative delay error the law is designed for (compensators: must survive; --monitor: the design range)."),
    vmax: float = typer.Option(1.0, "--vmax", help="Command limit, m/s (at most 2)."),
    step: float = typer.Option(1.0, "--step", help="Reference step, m."),
    steps: Optional[str] = typer.Option(None, "--steps", help="Several steps, e.g. 1,-1,1 (one log each)."),
    duration: float = typer.Option(12.0, "--duration", help="Seconds flown after each step."),
    hover: float = typer.Option(2.0, "--hover", help="Seconds of steady hover before the first step."),
    monitor: bool = typer.Option(False, "--monitor", help="Re-estimate the delay after each step; alarm when it leaves the design range."),
    design_range: Optional[str] = typer.Option(None, "--design-range", help="The delays the law was designed for, LO,HI in s (default: the design delay ± --delay-uncertainty; p/pv without --design-delay: where the loop on 1/s is stable)."),
    design_delay: Optional[float] = typer.Option(None, "--design-delay", help="p/pv with --monitor: the delay the gains were designed for, s."),
    schedule: bool = typer.Option(False, "--schedule", help="With --monitor: re-design the law for the new estimate after an alarm (p and compensators)."),
    est_lag: float = typer.Option(0.0, "--estimate-lag", help="With --monitor: the vehicle's speed lag the estimator assumes, s (0: the delay absorbs it)."),
    log: Path = typer.Option(Path("flight.csv"), "--log", help="The flight log (CSV, flushed every line)."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask before taking off a real drone."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Fly step tests: navdata start-up, take-off, hover, the steps, land; log every packet.

    The law is the paper's P or PV (--kp, --kv) or a delay compensator designed for --model-delay on the
    integrator model 1/s.  With --monitor the delay is re-estimated after each step (the drone hovers for the
    fraction of a second it takes) and compared with the law's design range; --schedule re-designs the law
    when the alarm goes off.

    Exits with status 1 (saying why) if the flight did not complete: a navdata gap, an altitude out of
    bounds, Ctrl-C, or a declined take-off."""
    from ..hardware.flight import FlightPlan, fly as run
    from ..models.compensators import COMPENSATOR_KINDS

    kind = controller.lower().replace("_", "-")
    law = None
    if kind in COMPENSATOR_KINDS:
        if model_delay is None:
            raise InvalidValueError(f"--controller {kind} needs --model-delay (the delay it is designed for, s)")
        if kp is not None or kv:
            raise InvalidValueError(f"--controller {kind} is designed from --model-delay; --kp/--kv are for p and pv")
        from ..design.compensators import tune_compensator

        check_real("--model-delay (s)", model_delay, minimum=0.0, strict=True)
        law = tune_compensator(kind, "1/s", model_delay, closed_loop_time=closed_loop_time,
                               delay_uncertainty=delay_uncertainty)
    elif kind in ("p", "pv"):
        if kp is None:
            raise InvalidValueError(f"--controller {kind} needs --kp")
        if kind == "p" and kv:
            raise InvalidValueError("--controller p has no --kv; use --controller pv")
        if model_delay is not None or closed_loop_time is not None:
            raise InvalidValueError("--model-delay and --closed-loop-time are for the compensators "
                                    f"({' | '.join(COMPENSATOR_KINDS)})")
    else:
        raise InvalidValueError(f"--controller must be p, pv or one of {', '.join(COMPENSATOR_KINDS)}; got "
                                f"{controller!r}")
    if not monitor and (design_range or schedule or design_delay is not None or est_lag):
        raise InvalidValueError("--design-range, --design-delay, --schedule and --estimate-lag need --monitor")
    sts = tuple(float(x) for x in steps.split(",")) if steps else (step,)
    plan = FlightPlan(kp=kp if kp is not None else 0.0, kv=kv, velocity=velocity, vmax=vmax, steps=sts,
                      step_duration=duration, hover_time=hover, controller=law)
    mon = None
    if monitor:
        from ..hardware.monitor import DelayMonitor

        from ..models.ranges import parse_range

        rng = tuple(parse_range(design_range, "--design-range")) if design_range else None
        mon = DelayMonitor(plan.law(), design_delay=design_delay, design_range=rng, lag=est_lag, schedule=schedule,
                           delay_uncertainty=delay_uncertainty)
    res = run(plan, log, host=host, at_port=at_port, navdata_port=navdata_port, confirm=_confirm_real(host, yes),
              status=lambda m: err.print(m, highlight=False), monitor=mon)
    if as_json:
        print(json.dumps(res.to_dict(), indent=2))
        if not res.completed:  # a flight that ended early (or never took off) is a failure: status 1
            err.print(f"flight did not complete: {res.reason}", highlight=False)
            raise typer.Exit(1)
        return
    out.print(f"{'Flight completed' if res.completed else 'Flight ended early: ' + res.reason}; "
              f"{res.packets} packets, {res.rejected} rejected.", highlight=False)
    if res.latency_median_ms is not None:
        out.print(f"Loop latency (navdata received to command sent): median {res.latency_median_ms:.3f} ms, "
                  f"99th percentile {res.latency_p99_ms:.3f} ms.", highlight=False)
    if res.online:
        from rich.table import Table

        tab = Table("step", "delay (s)", "95 % interval", "design range", "stable range", "alarm", "action")
        for o in res.online:
            tab.add_row(str(o.step), f"{o.delay:.4f}", _fmt_ci(o.estimate.ci), _fmt_ci(o.design_range, 3),
                        _fmt_ci(o.stable_range, 3), "ALARM" if o.alarm else "", o.action)
        out.print(tab)
    out.print("Logs: " + ", ".join(str(p) for p in res.logs), highlight=False)
    if not res.completed:  # the reason is printed above
        raise typer.Exit(1)


@app.command()
@_friendly
def demo(
    out_dir: Path = typer.Option(Path("out/demo"), "--out", help="Folder for the report, logs and figures."),
    host: Optional[str] = typer.Option(None, "--host", help="A real drone (default: the built-in emulator)."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the emulator (its hidden delay and noise)."),
    p_steps: int = typer.Option(5, "--p-steps", help="P-control step tests."),
    step_duration: float = typer.Option(8.0, "--step-duration", help="Seconds after each step."),
    compensate: bool = typer.Option(True, "--compensate/--no-compensate", help="Also design the delay compensators and fly the best."),
    varying_steps: int = typer.Option(6, "--varying-steps", help="Emulator only: steps of the flight whose delay grows mid-flight (0: none)."),
    delay_jump: float = typer.Option(0.15, "--delay-jump", help="Emulator only: how much that flight's delay grows, s."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask before taking off a real drone."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """The whole pipeline: fly P step tests, estimate the delay, design PV gains and the delay compensators, fly
    them, fly once more while the emulator's delay grows (the delay monitor's alarm), and report."""
    from ..paper.demo import run_demo

    if p_steps < 1:
        raise InvalidValueError(f"--p-steps must be at least 1, got {p_steps}")
    if varying_steps < 0:
        raise InvalidValueError(f"--varying-steps must be at least 0, got {varying_steps}")
    check_real("--delay-jump (s)", delay_jump, minimum=0.0, maximum=2.0)
    with err.status("starting") as st:
        rep = run_demo(out_dir, host=host, seed=seed, p_steps=p_steps, step_duration=step_duration,
                       compensate=compensate, varying_steps=varying_steps, delay_jump=delay_jump,
                       confirm=_confirm_real(host, yes) if host else None, status=lambda m: st.update(m))
    if as_json:
        print(json.dumps(rep.to_dict(), indent=2, default=str))
        return
    e = rep.estimate
    interval = "no interval" if e.ci is None else f"95 % {_fmt_ci(e.ci)}"
    out.print(f"Estimated delay {e.delay:.4f} s ± {e.stderr or 0:.4f} ({interval}) from "
              f"{e.flights} step tests" + (f"; the emulator's truth is {rep.true_delay:.4f} s (error "
                                          f"{1e3 * rep.error:+.1f} ms)" if rep.true_delay is not None else "") + ".",
              highlight=False)
    import numpy as np

    pm = np.mean([m["settling_time"] or np.nan for m in rep.p_metrics])
    vm = np.mean([m["settling_time"] or np.nan for m in rep.pv_metrics])
    out.print(f"PV design: Kp = {rep.pv_kp:g}, Kv = {rep.kv:g} ({rep.kv_source}). Mean settling time: P {pm:.2f} s, "
              f"PV {vm:.2f} s.", highlight=False)
    if rep.comp_metrics:
        cm = np.mean([m["settling_time"] or np.nan for m in rep.comp_metrics])
        out.print(f"Compensator flown: {rep.compensator['chosen']} (model delay {rep.compensator['model_delay']:.4f} s); "
                  f"mean settling time {cm:.2f} s.", highlight=False)
    if rep.varying_flight is not None:
        v = rep.varying_flight
        out.print(f"Delay moving from {rep.varying_truth['before']:.3f} to {rep.varying_truth['after']:.3f} s: "
                  f"{len(v.online)} online estimates, {v.alarms} alarm(s), "
                  f"{sum(o.action == 'redesigned' for o in v.online)} re-design(s).", highlight=False)
    out.print(f"Report: {out_dir / 'demo.md'}", highlight=False)


def main() -> None:
    """Entry point of the ``delaykit`` script."""
    app(prog_name="delaykit")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
