"""``delaykit autotune``: a relay experiment in flight, the ultimate point from its cycle, a rule, a step."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import InvalidValueError, check_real
from .common import check_output, confirm_real, err, friendly, out, print_json, warn

__all__ = ["autotune"]


@friendly
def autotune(
    relay: float = typer.Option(..., "--relay", help="The relay's amplitude, m/s (at most --vmax)."),
    hysteresis: float = typer.Option(0.0, "--hysteresis", help="The relay's hysteresis, m."),
    host: Optional[str] = typer.Option(None, "--host", help="The drone (default: an AR.Drone at 192.168.1.1; with --vehicle tello, 192.168.10.1; the emulator: 127.0.0.1)."),
    at_port: int = typer.Option(5556, "--at-port", help="The drone's AT command port."),
    navdata_port: int = typer.Option(5554, "--navdata-port", help="The drone's navdata port."),
    vehicle: str = typer.Option("ardrone", "--vehicle", help="ardrone (--host and its ports; the default) | mavlink (PX4 or ArduPilot: --connect) | tello (--host, --speed-per-percent)."),
    speed_per_percent: Optional[float] = typer.Option(None, "--speed-per-percent", help="With --vehicle tello: m/s per rc throttle percent (default 0.01)."),
    command_port: int = typer.Option(8889, "--command-port", help="With --vehicle tello: the drone's command port."),
    state_port: int = typer.Option(8890, "--state-port", help="With --vehicle tello: the local port its state arrives on."),
    connect: Optional[str] = typer.Option(None, "--connect", help="With --vehicle mavlink: pymavlink's connection string, e.g. tcp:127.0.0.1:5760."),
    mav_rate: float = typer.Option(50.0, "--mavlink-rate", help="With --vehicle mavlink: the LOCAL_POSITION_NED rate asked for, Hz."),
    vmax: float = typer.Option(1.0, "--vmax", help="Command limit, m/s (at most 2)."),
    shape: str = typer.Option("1/s", "--shape", help="The vehicle's form up to gain and delay, e.g. 1/s or 1/(s*(0.05*s+1))."),
    rule: str = typer.Option("simc", "--rule", help="simc | amigo | imc | lambda | zn | tyreus-luyben."),
    controller: str = typer.Option("pi", "--controller", help="p | pi | pd | pid."),
    tau_c: Optional[float] = typer.Option(None, "--tau-c", help="SIMC's closed-loop time constant / IMC's lambda, s (default: the delay found)."),
    offset: float = typer.Option(0.3, "--offset", help="The reference step the relay cycles about, m above the hover."),
    duration: float = typer.Option(12.0, "--duration", help="Seconds of relay flight."),
    skip: int = typer.Option(2, "--skip", help="Relay cycles left out at the start (the approach)."),
    step: float = typer.Option(0.5, "--step", help="The tuned controller's reference step, m."),
    step_duration: float = typer.Option(6.0, "--step-duration", help="Seconds flown after the tuned step (0: no step flight)."),
    hover: float = typer.Option(1.0, "--hover", help="Seconds of steady hover before each step."),
    log: Path = typer.Option(Path("autotune.csv"), "--log", help="The relay flight's log (CSV, flushed every line); the step's is <name>-step.csv."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask before taking off a real drone."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """Relay autotuning in flight (Astrom-Hagglund): fly a relay about a reference, find the ultimate point from
    the settled limit cycle (exact for the vehicle's --shape, which is known up to its gain and delay; the
    describing-function estimate beside it), tune by --rule, and fly a step with the tuned controller.

    Exits with status 1 (saying why) if a flight did not complete."""
    from ..hardware.autotune import autotune as run
    from ..hardware.laws import Relay

    check_real("--vmax (m/s)", vmax, minimum=0.0, strict=True, maximum=2.0)
    if check_real("--relay (m/s)", relay, minimum=0.0, strict=True) > vmax:
        raise InvalidValueError(f"--relay {relay:g} is beyond the actuator's limit --vmax {vmax:g} m/s")
    check_real("--step-duration (s)", step_duration, minimum=0.0)
    check_output("--log", log)
    from .vehicle_opts import connection_is_loopback, default_host, link_factory

    is_tello = vehicle.lower() == "tello"
    resolved = default_host(vehicle, host, command_port, state_port)
    make_link = link_factory(vehicle, connect, rate=mav_rate, host=host, command_port=command_port,
                             state_port=state_port, speed_per_percent=speed_per_percent)
    host = resolved
    if is_tello:
        fly_kw: dict = dict(link=make_link, confirm=confirm_real(host, yes))
    elif make_link is None:
        fly_kw = dict(host=host, at_port=at_port, navdata_port=navdata_port, confirm=confirm_real(host, yes))
    else:
        fly_kw = dict(link=make_link, confirm=confirm_real(
            "127.0.0.1" if connection_is_loopback(connect or "") else str(connect), yes))
    import warnings

    from ..design.pid_rules import TuningWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TuningWarning)  # each is among the tuning's notes, printed once below
        res = run(Relay(relay, hysteresis), log, shape=shape, rule=rule, controller=controller, tau_c=tau_c,
                  offset=offset, relay_duration=duration, skip=skip, step=step if step_duration > 0 else None,
                  step_duration=step_duration if step_duration > 0 else 1.0, hover_time=hover, vmax=vmax,
                  fly_kw=fly_kw,
                  status=lambda m: err.print(m, highlight=False, markup=False))
    if as_json:
        print_json(res.to_dict())
    else:
        _print(res)
    if res.status != "ok":
        err.print(f"autotune did not complete: {res.status}", highlight=False, markup=False)
        raise typer.Exit(1)


def _print(res) -> None:  # noqa: ANN001
    f = res.found
    if f is None:
        out.print(f"Relay flight ended early: {res.relay_flight.reason}", highlight=False, markup=False)
        return
    c = f.cycle
    out.print(f"Relay cycle: period {c.period:.4g} s (± {c.period_std:.2g} over {c.cycles} cycles), RMS "
              f"{c.rms:.4g} m, peak amplitude {c.peak_amplitude:.4g} m.", highlight=False, markup=False)
    out.print(f"Ultimate point (exact for {f.gain:.4g} * {f.shape} with delay {f.delay:.4g} s): ku = {f.ku:.6g}, "
              f"pu = {f.pu:.6g} s.", highlight=False, markup=False)
    out.print(f"Describing-function estimate: ku ~ {f.ku_describing:.6g}, pu ~ {f.pu_describing:.6g} s.",
              highlight=False, markup=False)
    t = res.tuning
    out.print(f"Tuned by {t.how} ({t.kind}): kp {t.kp:.6g}, ki {t.ki:.6g}, kd {t.kd:.6g}; Ms {t.ms:.4g}.",
              highlight=False, markup=False)
    for n in t.notes:
        warn(n, label="Note")
    if res.step_flight is not None:
        s = res.step_flight
        out.print(f"Step flight: {'completed' if s.completed else 'ended early: ' + s.reason}; logs "
                  + ", ".join(str(p) for p in res.relay_flight.logs + s.logs), highlight=False, markup=False)
