"""``delaykit emulate`` and ``fly``: the emulator on loopback (AR.Drone or MAVLink front end), and flights."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Optional

import typer

from ..errors import InvalidValueError, check_real
from .common import (check_output, confirm_real, err, fmt_ci, friendly, out, parse_schedule, print_error, print_json,
                     read_delay_trace, run_until_stopped)

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
    rate: Optional[float] = typer.Option(None, "--rate", help="Navdata rate, Hz (default 15); with --protocol mavlink the sampling grid, the fastest LOCAL_POSITION_NED rate (default 50)."),
    loss: float = typer.Option(0.0, "--loss", help="Navdata packet loss, fraction."),
    jitter: float = typer.Option(0.0, "--jitter", help="Navdata send jitter, s."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Random seed."),
    delay_schedule: Optional[str] = typer.Option(None, "--delay-schedule", help="The actuator delay changing mid-run: T:DELAY pairs, e.g. 20:0.40,40:0.25 (s since start, s)."),
    delay_trace: Optional[Path] = typer.Option(None, "--delay-trace", help="Replay a recorded delay, added to --delay (as `simulate --delay-trace`): a CSV with a header t,delay (s), or a flight log of `delaykit fly` (its latency_ms column); each record held until the next, from the first at start. Give --delay 0 for a trace of whole delays. Not with --delay-schedule."),
    burst: Optional[list[str]] = typer.Option(None, "--burst", help="The navdata rate falls (a Wi-Fi scan): START:DURATION[:RATE] (s since start, s, Hz below --rate; RATE 0 by default: no navdata). Repeat it, or separate several by commas."),
    duration: float = typer.Option(0.0, "--duration", help="Run this long, s (0 = until Ctrl-C)."),
    protocol: str = typer.Option("ardrone", "--protocol", help="ardrone (AT commands and navdata, the default) | mavlink (as PX4's or ArduPilot's simulator: --autopilot, --to or --listen)."),
    autopilot: str = typer.Option("px4", "--autopilot", help="With --protocol mavlink: px4 | ardupilot (whose modes, sequence and failsafe)."),
    to: Optional[str] = typer.Option(None, "--to", help="With --protocol mavlink: send to a ground station listening at udp:127.0.0.1:PORT (as PX4's simulator does, e.g. udp:127.0.0.1:14540)."),
    listen: Optional[str] = typer.Option(None, "--listen", help="With --protocol mavlink: serve one ground station at tcp:127.0.0.1:PORT (as ArduPilot's simulator does, e.g. tcp:127.0.0.1:5760; port 0: any free one)."),
    accel_limit: float = typer.Option(0.0, "--accel-limit", help="Vertical acceleration limit of the speed command, m/s^2 (0: none; ArduPilot's default is 1): a speed step becomes a ramp."),
    refuse_arming: Optional[str] = typer.Option(None, "--refuse-arming", help="With --protocol mavlink: refuse every arming with this pre-arm reason."),
    ready_after: float = typer.Option(0.0, "--ready-after", help="With --protocol mavlink: seconds after start before arming is accepted (an estimator converging)."),
    command_port: int = typer.Option(8889, "--command-port", help="With --protocol tello: the UDP port commands arrive on (0: any free one)."),
    state_port: int = typer.Option(8890, "--state-port", help="With --protocol tello: the port the state goes to, at the address that sent `command`."),
    speed_per_percent: float = typer.Option(0.01, "--speed-per-percent", help="With --protocol tello: the vehicle's true m/s per rc throttle percent."),
    command_timeout: float = typer.Option(15.0, "--command-timeout", help="With --protocol tello: airborne, it lands by itself after this long without a command, s (a Tello's is 15)."),
) -> None:
    """Run the built-in emulator (loopback) until Ctrl-C, SIGTERM, SIGHUP or --duration; then print its summary
    (ports, counts, rejections) as JSON.

    One emulated vehicle (its physics, delays, jitter, loss, bursts and delay traces), two protocol front ends:
    the AR.Drone 2.0's (the default) and MAVLink (--protocol mavlink), which behaves as PX4 or ArduPilot and is
    reached as their simulators are (--to udp:127.0.0.1:14540 or --listen tcp:127.0.0.1:5760); and a Tello's
    (--protocol tello: its text SDK on --host at --command-port 8889, state to the client's --state-port 8890 at
    --rate 10 Hz, the 15 s no-command auto-land)."""
    from dataclasses import replace

    from ..hardware.emulator import DroneEmulator, EmulatorConfig

    check_real("--duration", duration, minimum=0.0)
    kind = protocol.lower()
    if kind not in ("ardrone", "mavlink", "tello"):
        raise InvalidValueError(f"--protocol must be ardrone, mavlink or tello, got {protocol!r}")
    if kind != "mavlink" and (to is not None or listen is not None or refuse_arming is not None or ready_after):
        raise InvalidValueError("--to, --listen, --refuse-arming and --ready-after are for --protocol mavlink")
    if kind != "tello" and (command_port != 8889 or state_port != 8890 or speed_per_percent != 0.01
                            or command_timeout != 15.0):
        raise InvalidValueError("--command-port, --state-port, --speed-per-percent and --command-timeout are for "
                                "--protocol tello")
    if kind == "mavlink" and (to is None) == (listen is None):
        raise InvalidValueError("--protocol mavlink needs exactly one of --to udp:127.0.0.1:PORT (a ground station "
                                "listening there) and --listen tcp:127.0.0.1:PORT (serve one)")
    rate = rate if rate is not None else {"mavlink": 50.0, "tello": 10.0}.get(kind, 15.0)
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
                         bursts=_parse_bursts(burst or [], rate), accel_limit=accel_limit)
    if kind == "mavlink":
        from ..hardware.emulator_mavlink import MavlinkEmulator

        emulator = MavlinkEmulator(replace(cfg, host="127.0.0.1"), autopilot=autopilot.lower(), to=to, listen=listen,
                                   refuse_arming=refuse_arming, ready_after=ready_after)
    elif kind == "tello":
        from ..hardware.emulator_tello import TelloEmulator

        emulator = TelloEmulator(cfg, command_port=command_port, state_port=state_port,
                                 speed_per_percent=speed_per_percent, command_timeout=command_timeout)
    else:
        emulator = DroneEmulator(cfg)
    with run_until_stopped(duration) as wait:  # Ctrl-C, SIGTERM and SIGHUP end the run alike, with the summary
        with emulator as emu:
            if kind == "mavlink":
                where = (f"sending to {to}" if to is not None else
                         f"serving tcp:{emu.endpoint[1]}:{emu.ports['mavlink']}")
                err.print(f"emulated {autopilot} vehicle (MAVLink) {where}; loop delay {emu.true_delay:g} s. "
                          "Ctrl-C stops.", highlight=False)
            elif kind == "tello":
                err.print(f"emulated Tello on {host}: commands on UDP {emu.ports['command']}, state to the client's "
                          f"port {state_port}; loop delay {emu.true_delay:g} s. Ctrl-C stops.", highlight=False)
            else:
                err.print(f"emulated drone on {host}: AT {emu.ports['at']}, navdata {emu.ports['navdata']}, video "
                          f"{emu.ports['video']}, control {emu.ports['control']}; loop delay {emu.true_delay:g} s. "
                          "Ctrl-C stops.", highlight=False)
            wait()
        summary = emu.summary()  # after stop(): the threads are done, so the counts are final
    print_json(summary, indent=None)


def _loop_law(path: Path, vmax: float) -> tuple[Any, float]:
    """The controller of a loop file and the command limit it flies with.

    The file's plant is the model the law was designed on, not what flies (the vehicle is); its delay and sampling
    are what the design assumed, not imposed on the flight (the flight law runs exactly between the vehicle's
    samples, whatever their spacing).  Its limits become the flight's command limit: symmetric limits are flown as
    they are, none keep ``--vmax``; asymmetric ones are refused, as the flight limits the command symmetrically.
    """
    from ..models.altitude import as_loop
    from ..models.loop import load_loop

    loop = as_loop(load_loop(path))
    lo, hi = loop.umin, loop.umax
    if math.isinf(lo) and math.isinf(hi):
        return loop.controller, vmax
    if lo != -hi:
        raise InvalidValueError(f"the loop file {str(path)!r} limits the command to [{lo:g}, {hi:g}]; a flight limits "
                                "it symmetrically (--vmax): write the file with umin = -umax, or none")
    return loop.controller, hi


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
    host: Optional[str] = typer.Option(None, "--host", help="The drone (default: an AR.Drone at 192.168.1.1; with --vehicle tello, 192.168.10.1; the emulator: 127.0.0.1)."),
    at_port: int = typer.Option(5556, "--at-port", help="The drone's AT command port."),
    navdata_port: int = typer.Option(5554, "--navdata-port", help="The drone's navdata port."),
    vehicle: str = typer.Option("ardrone", "--vehicle", help="ardrone (AT commands and navdata: --host and its ports; the default) | mavlink (PX4 or ArduPilot through pymavlink: --connect) | tello (its text SDK over UDP: --host, --speed-per-percent)."),
    speed_per_percent: Optional[float] = typer.Option(None, "--speed-per-percent", help="With --vehicle tello: m/s per rc throttle percent (default 0.01; identify it from a flight)."),
    command_port: int = typer.Option(8889, "--command-port", help="With --vehicle tello: the drone's command port."),
    state_port: int = typer.Option(8890, "--state-port", help="With --vehicle tello: the local port its state arrives on (0: any free one)."),
    connect: Optional[str] = typer.Option(None, "--connect", help="With --vehicle mavlink: pymavlink's connection string, e.g. tcp:127.0.0.1:5760, udpin:0.0.0.0:14550 or a serial device."),
    mav_rate: float = typer.Option(50.0, "--mavlink-rate", help="With --vehicle mavlink: the LOCAL_POSITION_NED rate asked for (the loop's), Hz."),
    takeoff_height: float = typer.Option(1.0, "--takeoff-height", help="With --vehicle mavlink: the hover height after take-off, m."),
    ready_timeout: float = typer.Option(60.0, "--ready-timeout", help="How long the vehicle may take to pass its pre-arm checks, s."),
    controller: str = typer.Option("p", "--controller", help="p | pv (the paper's laws, --kp/--kv) | smith | filtered-smith | predictor (designed for --model-delay)."),
    loop_file: Optional[Path] = typer.Option(None, "--loop", help="Fly the controller (any law: P, PI, PID, a transfer function, a compensator) and the command limits of a loop file, such as `tune --save` or `design --save` writes; not with --controller, --kp or --kv."),
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

    The law is the paper's P or PV (--kp, --kv), a delay compensator designed for --model-delay on the
    integrator model 1/s, or the controller of a loop file (--loop tuned.toml, as `tune --save` writes it: PI,
    PID, any transfer function or compensator, with the file's command limits).  With --monitor the delay is re-estimated after each step (the drone hovers for the
    fraction of a second it takes) and compared with the law's design range; --schedule re-designs the law
    when the alarm goes off.

    The vehicle is an AR.Drone 2.0 (--host) or, with --vehicle mavlink, a PX4 or ArduPilot autopilot (--connect):
    PX4 flies in OFFBOARD, ArduPilot in GUIDED, both by vertical-velocity setpoints; or, with --vehicle tello, a
    Tello (--host, 192.168.10.1 on its Wi-Fi) by rc throttle percentages (--speed-per-percent m/s each).

    Exits with status 1 (saying why) if the flight did not complete: a gap in the altitude samples (the link
    lost: the vehicle's own failsafe takes over), an altitude out of bounds, Ctrl-C, or a declined take-off; with
    status 2 and one line when the vehicle refuses a mode or arming, naming its reason."""
    from ..hardware.flight import FlightPlan, land_on_signals
    from ..hardware.flight import fly as run
    from ..models.compensators import COMPENSATOR_KINDS
    from .vehicle_opts import connection_is_loopback, default_host, link_factory

    check_output("--log", log)
    is_tello = vehicle.lower() == "tello"
    resolved = default_host(vehicle, host, command_port, state_port)
    make_link = link_factory(vehicle, connect, rate=mav_rate, takeoff_height=takeoff_height, host=host,
                             command_port=command_port, state_port=state_port, speed_per_percent=speed_per_percent)
    host = resolved
    kind = controller.lower().replace("_", "-")
    law = None
    if loop_file is not None:
        if kind != "p" or kp is not None or kv or model_delay is not None or closed_loop_time is not None:
            raise InvalidValueError("--loop flies the file's controller: give no --controller, --kp, --kv, "
                                    "--model-delay or --closed-loop-time with it")
        law, vmax = _loop_law(loop_file, vmax)
    elif kind in COMPENSATOR_KINDS:
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
            confirm = (confirm_real(host, yes) if make_link is None or is_tello else
                       confirm_real("127.0.0.1" if connection_is_loopback(connect or "") else str(connect), yes))
            res = run(plan, log, host=host, at_port=at_port, navdata_port=navdata_port, link=make_link,
                      ready_timeout=ready_timeout, confirm=confirm, status=lambda m: err.print(m), monitor=mon)
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
        out.print(f"Loop latency (sample received to command sent): median {res.latency_median_ms:.3f} ms, "
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
