"""``delaykit report``, ``reproduce`` and ``demo``: the paper's tables checked, and the emulated flight demo."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import FlightInterruptedError, InvalidValueError, check_real
from .common import check_output, confirm_real, err, fmt_ci, friendly, out, print_error, print_json, progress_bar, warn

__all__ = ["demo", "report", "reproduce"]


@friendly
def report(
    out_dir: Path = typer.Option(Path("out"), "--out", help="Folder to write the report into."),
    as_json: bool = typer.Option(False, "--json", help="Print the results as JSON."),
) -> None:
    """Regenerate only the paper's Table 1, with a figure, into --out (see `reproduce` for everything)."""
    from ..paper.report import table1_markdown, write_report

    check_output("--out", out_dir, "folder")
    with err.status("writing the report…") as status:
        rep = write_report(out_dir, progress=lambda m: status.update(m))
    if as_json:
        print_json(rep.to_dict())
        return
    from rich.markdown import Markdown

    out.print(Markdown("## Table 1 (Kp = 1.31, P control, ±1 m/s)\n\n" + table1_markdown(rep.rows)))
    out.print(f"\nVerdict: {rep.verdict}.\n", highlight=False)
    out.print("Wrote " + ", ".join(str(f) for f in rep.files), highlight=False)


@friendly
def reproduce(
    out_dir: Path = typer.Option(Path("out"), "--out", help="Folder for report.md, index.html and the figures."),
    as_json: bool = typer.Option(False, "--json", help="Print the verdicts as JSON."),
) -> None:
    """Regenerate the paper's tables and figures, with the paper's values beside delaykit's and a verdict each."""
    from ..paper.reproduce import reproduce as run

    check_output("--out", out_dir, "folder")
    with progress_bar() as bar:
        task = bar.add_task("reproducing the paper", total=None)  # the total comes with the first report
        rep = run(out_dir, progress=lambda name, done, total: bar.update(task, completed=done, total=total,
                                                                           description=name))
    if as_json:
        print_json(rep.to_dict())
        return
    from rich.table import Table

    table = Table(title="The paper, regenerated")
    table.add_column("item", justify="left")
    table.add_column("verdict", justify="left")
    for it in rep.items:
        table.add_row(it.title, it.verdict)
    out.print(table)
    out.print(f"Wrote {out_dir / 'report.md'} and {out_dir / 'index.html'} (open it in a browser).", highlight=False)


@friendly
def demo(
    out_dir: Path = typer.Option(Path("out/demo"), "--out", help="Folder for the report, logs and figures."),
    host: Optional[str] = typer.Option(None, "--host", help="A real drone (default: the built-in emulator)."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the emulator (its hidden delay and noise)."),
    p_steps: int = typer.Option(5, "--p-steps", help="P-control step tests."),
    step_duration: float = typer.Option(8.0, "--step-duration", help="Seconds after each step."),
    compensate: bool = typer.Option(True, "--compensate/--no-compensate", help="Also design the delay compensators and fly the best."),
    varying_steps: int = typer.Option(6, "--varying-steps", help="Emulator only: steps of the flight whose delay grows mid-flight (0: none)."),
    delay_jump: float = typer.Option(0.15, "--delay-jump", help="Emulator only: how much that flight's delay grows, s."),
    vehicle: str = typer.Option("speed_loop", "--vehicle", help="Emulator only: speed_loop (the PX4's speed loop and hover wander, not the estimator's model) | lag."),
    identify_plant: bool = typer.Option(True, "--identify/--no-identify", help="Identify the plant from the P flights and predict the PV flight with it."),
    protocol: str = typer.Option("ardrone", "--protocol", help="Emulator only: how it is flown, ardrone (navdata, 15 Hz) | mavlink (its MAVLink front end, 50 Hz: --autopilot) | tello (its Tello front end, 10 Hz)."),
    autopilot: str = typer.Option("ardupilot", "--autopilot", help="Emulator only, with --protocol mavlink: ardupilot | px4."),
    connect: Optional[str] = typer.Option(None, "--connect", help="A real MAVLink vehicle (PX4 or ArduPilot): pymavlink's connection string (instead of --host)."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask before taking off a real drone."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """The whole pipeline: fly P step tests, estimate the delay, identify the plant, design PV gains and the delay
    compensators, fly them, fly once more while the emulator's delay grows (the delay monitor's alarm), and report."""
    from ..paper.demo import run_demo

    check_output("--out", out_dir, "folder")
    if p_steps < 1:
        raise InvalidValueError(f"--p-steps must be at least 1, got {p_steps}")
    if varying_steps < 0:
        raise InvalidValueError(f"--varying-steps must be at least 0, got {varying_steps}")
    check_real("--delay-jump (s)", delay_jump, minimum=0.0, maximum=2.0)
    if protocol not in ("ardrone", "mavlink", "tello") or autopilot not in ("ardupilot", "px4"):
        raise InvalidValueError(f"--protocol must be ardrone, mavlink or tello and --autopilot ardupilot or px4, got "
                                f"{protocol!r} and {autopilot!r}")
    if host is not None and connect is not None:
        raise InvalidValueError("give --host (an AR.Drone) or --connect (a MAVLink vehicle), not both")
    from ..hardware.flight import land_on_signals
    from .vehicle_opts import connection_is_loopback, link_factory

    link = link_factory("mavlink", connect) if connect is not None else None
    real = host or (None if connect is None or connection_is_loopback(connect) else connect)

    try:
        # SIGTERM and SIGHUP land a flight as Ctrl-C does; an interrupted flight stops the demo (no next take-off)
        with land_on_signals(), err.status("starting") as st:
            rep = run_demo(out_dir, host=host, seed=seed, p_steps=p_steps, step_duration=step_duration,
                           compensate=compensate, varying_steps=varying_steps, delay_jump=delay_jump,
                           vehicle=vehicle, identify_plant=identify_plant, protocol=protocol,
                           autopilot=autopilot, link=link,
                           confirm=confirm_real(real, yes) if real else None, status=lambda m: st.update(m))
    except FlightInterruptedError as exc:
        print_error(str(exc))
        raise typer.Exit(1) from None
    except KeyboardInterrupt as exc:  # between flights (estimating, designing): nothing was in the air
        print_error(f"interrupted ({getattr(exc, 'signal_name', 'Ctrl-C')}) between flights; the demo stops")
        raise typer.Exit(1) from None
    if as_json:
        print_json(rep.to_dict(), default=str)
        return
    e = rep.estimate
    interval = "no interval" if e.ci is None else f"95 % {fmt_ci(e.ci)}"
    out.print(f"Estimated delay {e.delay:.4f} s ± {e.stderr or 0:.4f} ({interval}) from "
              f"{e.flights} step tests" + (f"; the emulator's truth is {rep.true_delay:.4f} s (error "
                                          f"{1e3 * rep.error:+.1f} ms)" if rep.true_delay is not None else "") + ".",
              highlight=False)
    import numpy as np

    def settling(ms: list[dict]) -> str:
        ts = [m["settling_time"] for m in ms]
        done = [t for t in ts if t is not None and np.isfinite(t)]
        text = f"{np.mean(done):.2f} s" if done else "none settled"
        return text + (f" ({len(ts) - len(done)} of {len(ts)} not settled)" if done and len(done) < len(ts) else "")

    ident = rep.identification
    if ident and "structure" in ident:
        interval = "not determined" if ident["delay_ci"] is None else "{:.4f} to {:.4f}".format(*ident["delay_ci"])
        truth = "" if ident["true_delay"] is None else f"; truth {ident['true_delay']:.4f} s"
        pv = ident["pv_flight"]
        out.print(f"Identified: {ident['structure']}, dead time {ident['delay']:.4f} s (95 % {interval}"
                  f"{truth}); PV flight predicted within {1e3 * pv['identified_rms']:.1f} mm RMS (the paper model: "
                  f"{1e3 * pv['paper_rms']:.1f} mm).", highlight=False)
    elif ident:
        warn(f"the plant was not identified: {ident.get('error')}")
    out.print(f"PV design: Kp = {rep.pv_kp:g}, Kv = {rep.kv:g} ({rep.kv_source}). Mean settling time: P "
              f"{settling(rep.p_metrics)}, PV {settling(rep.pv_metrics)}.", highlight=False)
    if rep.comp_metrics:
        out.print(f"Compensator flown: {rep.compensator['chosen']} (model delay {rep.compensator['model_delay']:.4f} s); "
                  f"mean settling time {settling(rep.comp_metrics)}.", highlight=False)
    if rep.varying_flight is not None:
        v = rep.varying_flight
        out.print(f"Delay moving from {rep.varying_truth['before']:.3f} to {rep.varying_truth['after']:.3f} s: "
                  f"{len(v.online)} online estimates, {v.alarms} alarm(s), "
                  f"{sum(o.action == 'redesigned' for o in v.online)} re-design(s).", highlight=False)
    out.print(f"Report: {out_dir / 'demo.md'}", highlight=False)
