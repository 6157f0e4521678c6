"""``delaykit emulate`` and ``fly``: the AR.Drone emulator on loopback, and flights."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import InvalidValueError, check_real
from .common import (check_output, confirm_real, err, fmt_ci, friendly, out, parse_schedule, print_error, print_json,
                     read_delay_trace)

__all__ = ["emulate", "fly"]


@friendly
def emulate(
    host: str = typer.Option("127.0.0.1", "--host", help="Address to bind (loopback unless told otherwise)."),
    at_port: int = typer.Option(5556, "--at-port", help="UDP port for AT commands (0 = any free one)."),
    navdata_port: int = typer.Option(5554, "--navdata-port", help="UDP port for navdata (0 = any free one)."),
    video_port: int = typer.Option(5555, "--video-port", help="TCP video port (accepted, nothing sent)."),
    control_port: int = typer.Option(5559, "--control-port", help="TCP control port (configuration text)."),
    delay: float = typer.Option(0.30, "--delay", help="Actuator delay, s."),
    vehicle: str = typer.Option("speed_loop", "--vehicle", help="speed_loop: the PX4's identified speed loop and a hover wander (default) | lag: a first-order speed lag, no wander."),
    lag: float = typer.Option(0.05, "--lag", help="With --vehicle lag: the lag of the drone's own speed loop, s."),
    speed_wn: Optional[float] = typer.Option(None, "--speed-wn", help="With --vehicle speed_loop: its natural frequency, rad/s (default 1.53, the PX4's)."),
    speed_zeta: Optional[float] = typer.Option(None, "--speed-zeta", help="With --vehicle speed_loop: its damping ratio (default 2.4)."),
    speed_zero: Optional[float] = typer.Option(None, "--speed-zero", help="With --vehicle speed_loop: its zero's time constant, s (default 3.9)."),
    wander: Optional[float] = typer.Option(None, "--wander", help="Hover wander, stationary RMS, m (default: the vehicle's own, 7 mm on the speed loop, 0 on the lag)."),
    wander_time: Optional[float] = typer.Option(None, "--wander-time", help="The wander's correlation time, s (default 2)."),
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
    """Run the built-in AR.Drone 2.0 emulator (loopback by default) until Ctrl-C, SIGTERM, SIGHUP or --duration; then
    print its summary (ports, counts, rejections) as JSON."""
    import signal
    import threading
    import time as _time

    from ..hardware.emulator import DroneEmulator, EmulatorConfig

    check_real("--duration", duration, minimum=0.0)
    if delay_schedule is not None and delay_trace is not None:
        raise InvalidValueError("give --delay-schedule or --delay-trace, not both: the schedule replaces --delay and "
                                "the trace is added to it")
    vehicle_opts = {k: v for k, v in (("speed_wn", speed_wn), ("speed_zeta", speed_zeta), ("speed_zero", speed_zero),
                                       ("wander_time", wander_time)) if v is not None}
    cfg = EmulatorConfig(host=host, at_port=at_port, navdata_port=navdata_port, video_port=video_port,
                         control_port=control_port, delay=delay, vehicle=vehicle, lag=lag, wander=wander,
                         **vehicle_opts, link_delay=link_delay, noise=noise,
                         rate=rate, loss=loss, jitter=jitter, seed=seed,
                         delay_schedule=None if delay_schedule is None else parse_schedule(delay_schedule),
                         delay_trace=None if delay_trace is None else read_delay_trace(delay_trace),
                         bursts=_parse_bursts(burst or [], rate))
    # Ctrl-C (SIGINT), SIGTERM and SIGHUP end the run alike: the same summary, exit status 0.  Their handler only
    # sets a flag that the main loop polls: it takes no lock (setting a threading.Event from a handler can deadlock, as the
    # handler may run while the main thread holds that Event's own lock) and raises nothing mid-shutdown.
    stop_signal: list[int] = []
    main_thread = threading.current_thread() is threading.main_thread()  # (signal handlers only go there)
    old = ({sig: signal.signal(sig, lambda signum, _frame: stop_signal.append(signum))
            for sig in (signal.SIGINT, signal.SIGTERM, getattr(signal, "SIGHUP", signal.SIGTERM))}
           if main_thread else {})
    try:
        with DroneEmulator(cfg) as emu:
            err.print(f"emulated drone on {host}: AT {emu.ports['at']}, navdata {emu.ports['navdata']}, video "
                      f"{emu.ports['video']}, control {emu.ports['control']}; loop delay {emu.true_delay:g} s. "
                      "Ctrl-C stops.", highlight=False)
            t0 = _time.monotonic()
            try:
                while not stop_signal and (duration == 0 or _time.monotonic() - t0 < duration):
                    _time.sleep(0.05)
            except KeyboardInterrupt:  # not from the handler above: only where it could not be installed
                pass
        summary = emu.summary()  # after stop(): the threads are done, so the counts are final
    finally:
        for sig, handler in old.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
    print_json(summary, indent=None)


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


def _parse_steps(spec: str) -> tuple[float, ...]:
    """``--steps``: reference steps in metres separated by commas; an error names the item.

    Examples
    --------
    >>> _parse_steps("1, -1,0.5")
    (1.0, -1.0, 0.5)
    """
    from ..models.budget import MAX_RANGE_POINTS, check_count, shorten

    items = [x.strip() for x in spec.split(",")]
    check_count("--steps", len(items), MAX_RANGE_POINTS, "steps")
    steps = []
    for k, item in enumerate(items):
        try:
            steps.append(float(item))
        except ValueError:
            raise InvalidValueError(f"--steps item {k + 1} {shorten(item, 40)!r} of {shorten(spec, 80)!r} is not a "
                                    "number: give steps in "
                                    "metres separated by commas, e.g. 1,-1,1") from None
    return tuple(steps)


@friendly
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
    from ..hardware.flight import FlightPlan, land_on_signals
    from ..hardware.flight import fly as run
    from ..models.compensators import COMPENSATOR_KINDS

    check_output("--log", log)
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
    sts = _parse_steps(steps) if steps is not None else (step,)
    plan = FlightPlan(kp=kp if kp is not None else 0.0, kv=kv, velocity=velocity, vmax=vmax, steps=sts,
                      step_duration=duration, hover_time=hover, controller=law)
    mon = None
    if monitor:
        from ..hardware.monitor import DelayMonitor
        from ..models.ranges import parse_range

        rng = tuple(parse_range(design_range, "--design-range")) if design_range else None
        mon = DelayMonitor(plan.law(), design_delay=design_delay, design_range=rng, lag=est_lag, schedule=schedule,
                           delay_uncertainty=delay_uncertainty)
    try:
        with land_on_signals():  # SIGTERM and SIGHUP land the drone as Ctrl-C does, and the result says so
            res = run(plan, log, host=host, at_port=at_port, navdata_port=navdata_port,
                      confirm=confirm_real(host, yes), status=lambda m: err.print(m), monitor=mon)
    except KeyboardInterrupt as exc:  # before the flight began: nothing was flown
        print_error(f"interrupted ({getattr(exc, 'signal_name', 'Ctrl-C')}) before the flight started; nothing was "
                    "flown")
        raise typer.Exit(1) from None
    if as_json:
        print_json(res.to_dict())
        if not res.completed:  # a flight that ended early (or never took off) is a failure: status 1
            print_error(f"flight did not complete: {res.reason}")
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
            tab.add_row(str(o.step), f"{o.delay:.4f}", fmt_ci(o.estimate.ci), fmt_ci(o.design_range, 3),
                        fmt_ci(o.stable_range, 3), "ALARM" if o.alarm else "", o.action)
        out.print(tab)
    out.print("Logs: " + ", ".join(str(p) for p in res.logs), highlight=False)
    if not res.completed:  # the reason is printed above
        raise typer.Exit(1)
