"""Flying a vehicle (an AR.Drone 2.0, a PX4 or ArduPilot autopilot, or the built-in emulator): the real-time
altitude loop, on any :class:`~delaykit.hardware.link.VehicleLink`.

:func:`fly` does what the paper's Simulink set-up did:

1. reach the vehicle and wait until it is ready (:meth:`~delaykit.hardware.link.VehicleLink.connect`,
   :meth:`~delaykit.hardware.link.VehicleLink.ready`; for the AR.Drone, the navdata start-up of
   :class:`~delaykit.hardware.ardrone_link.DroneLink`);
2. take-off, and a steady hover (its mean altitude is the first reference);
3. the steps in ``z_ref``; for each altitude sample the command is computed and sent at once as a vertical
   velocity: the paper's ``u = sat(Kp (z_ref - z) - Kv w, vmax)`` (``w`` the vehicle's vertical speed, or the
   derivative filter of the altitude), or any controller or compensator of delaykit
   (:class:`~delaykit.hardware.laws.FlightLaw`: exact between samples, whatever their spacing);
4. with a :class:`~delaykit.hardware.monitor.DelayMonitor`, after each step: hover, re-estimate the delay from
   the step's samples and commands, raise the alarm when it left the controller's design range, and with
   scheduling fly the re-designed law from the next step;
5. hover and land.

Each step is logged to its own CSV (``t, z, z_ref, u, vz, seq, recv_time, latency_ms``, and ``vehicle_time``
when the link has the vehicle's clock, as MAVLink does; from one second before the step), flushed every line so
a crash loses nothing; ``delaykit estimate`` reads them as they are.  Arrival times are the link's (the
kernel's on the AR.Drone link: :mod:`~delaykit.hardware.stamps`).  Samples that arrive while the loop hovers
to estimate are logged with the hover's command and ``latency_ms`` nan (they were not answered).
Ctrl-C (or SIGTERM or SIGHUP, within :func:`land_on_signals`), a gap in the samples longer than ``gap_timeout``
(the link lost: on a MAVLink vehicle its own failsafe takes over), or an altitude outside ``[z_min, z_max]``
makes it hover and land at once, and the result says why.  The command never leaves ``±vmax``.  The loop's own
latency (sample received to command sent) is measured and reported (median and 99th percentile).
"""

from __future__ import annotations

import time
from collections import deque
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterator

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_path, check_real, writing
from ..models.budget import MAX_FLIGHT_SECONDS, check_count
from ..models.compensators import Compensator
from ..models.controllers import Controller
from .ardrone_link import VZ_MAX_LIMIT, DroneLink
from .laws import FlightLaw, Relay
from .link import AltitudeSample, LinkError, VehicleLink

if TYPE_CHECKING:  # (the monitor pulls in the estimator and the design: imported when a flight uses one)
    from .monitor import DelayMonitor, OnlineEstimate

__all__ = ["LinkError", "DroneLink", "FlightPlan", "FlightResult", "fly", "land_on_signals"]


class _SignalInterrupt(KeyboardInterrupt):
    """A stop signal (SIGTERM, SIGHUP) arrived during a flight: :func:`fly` hovers and lands, as on Ctrl-C, and its
    result's reason names the signal (``signal_name``).  Raised by the handlers of :func:`land_on_signals`; a
    KeyboardInterrupt, so that code which lets Ctrl-C through lets it through too."""

    def __init__(self, signal_name: str) -> None:
        super().__init__(signal_name)
        self.signal_name = signal_name


@contextmanager
def land_on_signals(names: tuple[str, ...] = ("SIGTERM", "SIGHUP")) -> Iterator[None]:
    """Within the block, the stop signals ``names`` end a flight as Ctrl-C does: the vehicle lands, and the result
    says which signal (``interrupted (SIGTERM)``), instead of the process dying in the air.

    The first signal raises a ``KeyboardInterrupt`` whose ``signal_name`` names it, in the main thread; one more while the vehicle lands is
    ignored (a second SIGTERM would otherwise cut the landing short).  The previous handlers come back at the end.
    Outside the main thread (where Python cannot handle signals), and for a signal the system does not have,
    nothing is installed.

    Examples
    --------
    >>> import signal
    >>> before = signal.getsignal(signal.SIGTERM)
    >>> with land_on_signals():
    ...     signal.getsignal(signal.SIGTERM) is before
    False
    >>> signal.getsignal(signal.SIGTERM) is before
    True
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    raised: list[str] = []

    def stop(signum: int, _frame: Any) -> None:
        if not raised:
            raised.append(signal.Signals(signum).name)
            raise _SignalInterrupt(raised[0])

    old = {}
    for name in names:
        sig = getattr(signal, name, None)
        if sig is not None:
            old[sig] = signal.signal(sig, stop)
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)


class _LogFile:
    """A flight log open for writing, line-buffered; a failure to write it (the disk full, the folder gone) an
    :class:`~delaykit.errors.OutputError` naming the log, raised through the flight (which then lands)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        with writing("the flight log", path):
            self.fh = open(path, "w", buffering=1)

    def write(self, text: str) -> None:
        with writing("the flight log", self.path):
            self.fh.write(text)

    def flush(self) -> None:
        with writing("the flight log", self.path):
            self.fh.flush()

    def close(self) -> None:
        try:
            self.fh.close()
        except OSError:  # (the error was reported by the write that failed)
            pass


@dataclass(frozen=True)
class FlightPlan:
    """What to fly: the controller and the steps.

    Parameters
    ----------
    kp, kv : float
        Gains (m/s per m, and dimensionless) of the paper's P or PV law.
    velocity : {"true", "filtered"}
        The Kv term's velocity: the navdata vertical speed, or the derivative filter of the altitude.
    controller : Controller, Compensator or Relay, optional
        Any other law (PI, PID, a Smith predictor, predictor feedback...), run by
        :class:`~delaykit.hardware.laws.FlightLaw`, or a relay experiment
        (:class:`~delaykit.hardware.laws.Relay`, its amplitude within ``vmax``); when given, ``kp``, ``kv`` and
        ``velocity`` are not used.
    vmax : float
        Command limit, m/s (at most 2.0, the drone's control_vz_max limit).
    steps : tuple of float
        Reference steps (m), each relative to the previous reference.
    step_duration : float
        Seconds flown after each step.
    hover_time : float
        Seconds of steady hover before the first step.
    z_min, z_max : float
        Safety bounds on the altitude once airborne (m).
    gap_timeout : float
        Longest allowed silence of navdata (s).
    """

    kp: float
    kv: float = 0.0
    velocity: str = "true"
    filter_wn: float = 38.0
    filter_zeta: float = 1.0
    vmax: float = 1.0
    steps: tuple[float, ...] = (1.0,)
    step_duration: float = 12.0
    hover_time: float = 2.0
    z_min: float = 0.15
    z_max: float = 3.5
    gap_timeout: float = 0.5
    controller: Controller | Compensator | Relay | None = None

    def __post_init__(self) -> None:
        if self.controller is not None and not isinstance(self.controller, (Controller, Compensator, Relay)):
            raise InvalidTypeError(f"controller must be a Controller, a Compensator or a Relay, got "
                                   f"{type(self.controller).__name__}")
        check_real("kp", self.kp, minimum=0.0)
        check_real("kv", self.kv, minimum=0.0)
        if self.velocity not in ("true", "filtered"):
            raise InvalidValueError(f"velocity must be true or filtered, got {self.velocity!r}")
        check_real("vmax (m/s)", self.vmax, minimum=0.0, strict=True, maximum=VZ_MAX_LIMIT)
        check_real("step duration (s)", self.step_duration, minimum=0.0, strict=True)
        check_real("hover time (s)", self.hover_time, minimum=0.0)
        check_real("gap_timeout (s)", self.gap_timeout, minimum=0.0, strict=True)
        if not self.steps:
            raise InvalidValueError("the plan needs at least one step")
        for s in self.steps:
            if check_real("step (m)", s) == 0:
                raise InvalidValueError("a step of zero cannot be measured")
        n = len(self.steps)
        check_count(f"a flight of {self.hover_time:g} s of hover and {n} step{'s' * (n != 1)} of "
                    f"{self.step_duration:g} s", self.hover_time + n * self.step_duration, MAX_FLIGHT_SECONDS,
                    "seconds", "fly shorter steps (a battery lasts some 15 minutes)")
        if not self.z_min < self.z_max:
            raise InvalidValueError(f"z_min must be below z_max, got {self.z_min:g} and {self.z_max:g}")
        if isinstance(self.controller, Relay) and self.controller.amplitude > self.vmax:
            raise InvalidValueError(f"relay amplitude {self.controller.amplitude:g} is beyond the actuator's limit "
                                    f"vmax = {self.vmax:g} m/s")

    def law(self) -> Controller | Compensator | Relay:
        """The controller flown: :attr:`controller`, or the P/PV law of ``kp``, ``kv`` and ``velocity``.

        Examples
        --------
        >>> FlightPlan(kp=2.0, kv=0.3).law()
        Controller(pv: kp=2, kv=0.3, true velocity)
        """
        if self.controller is not None:
            return self.controller
        if self.kv == 0.0:
            return Controller.p(self.kp)
        return Controller.pv(self.kp, self.kv, velocity=self.velocity, filter_wn=self.filter_wn,
                             filter_zeta=self.filter_zeta)


@dataclass(frozen=True, repr=False)
class FlightResult:
    """How a flight went: the logs written, why it ended, and the loop's own timing."""

    logs: tuple[Path, ...]
    reason: str
    completed: bool
    packets: int
    rejected: int
    latency_median_ms: float | None
    latency_p99_ms: float | None
    packet_interval: float | None
    events: tuple[str, ...] = field(default_factory=tuple)
    controller: dict[str, Any] | None = None
    online: tuple[OnlineEstimate, ...] = field(default_factory=tuple)
    #: what interrupted the flight (``"Ctrl-C"``, ``"SIGTERM"``, ``"SIGHUP"``), or None: the vehicle landed and the
    #: user asked to stop, so a pipeline of several flights stops too
    interrupted: str | None = None

    @property
    def alarms(self) -> int:
        """How many steps' delay estimates raised the alarm."""
        return sum(o.alarm for o in self.online)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"logs": [str(p) for p in self.logs], "reason": self.reason, "completed": self.completed,
                "packets": self.packets, "rejected": self.rejected, "latency_median_ms": self.latency_median_ms,
                "latency_p99_ms": self.latency_p99_ms, "packet_interval": self.packet_interval,
                "events": list(self.events), "controller": self.controller,
                "online": [o.to_dict() for o in self.online], "alarms": self.alarms, "interrupted": self.interrupted}

    def __repr__(self) -> str:
        lat = "" if self.latency_median_ms is None else f", latency {self.latency_median_ms:.3f} ms median"
        return f"FlightResult({self.reason}, {len(self.logs)} logs, {self.packets} packets{lat})"


_COLUMNS = ("t", "z", "z_ref", "u", "vz", "seq", "recv_time", "latency_ms")


def _log_path(base: Path, k: int, n: int) -> Path:
    return base if n == 1 else base.with_name(f"{base.stem}-{k + 1}{base.suffix}")


def fly(
    plan: FlightPlan,
    log: str | Path,
    *,
    host: str = "192.168.1.1",
    at_port: int = 5556,
    navdata_port: int = 5554,
    connect_timeout: float = 3.0,
    confirm: Callable[[], bool] | None = None,
    status: Callable[[str], None] | None = None,
    monitor: DelayMonitor | None = None,
    link: VehicleLink | Callable[[], VehicleLink] | None = None,
    ready_timeout: float = 60.0,
) -> FlightResult:
    """Fly the plan on a vehicle (by default the AR.Drone at ``host``) and log every altitude sample (see the
    module docstring).

    Parameters
    ----------
    plan : FlightPlan
        The law and the steps.
    log : str or Path
        The log's path (``name-1.csv``, ``name-2.csv``... with several steps).
    host, at_port, navdata_port : str, int, int
        The AR.Drone (or its emulator), when no ``link`` is given.
    connect_timeout : float
        How long to wait for the vehicle to answer before giving up (s).
    confirm : callable, optional
        Asked once the link works, before the take-off; False: nothing flies.
    status : callable, optional
        Called with a short message at each stage.
    monitor : DelayMonitor, optional
        Re-estimate the delay after each step (the vehicle hovers meanwhile), raise the alarm, and with its
        ``schedule`` fly the re-designed law from the next step (warmed up on the last packets).
    link : VehicleLink or callable, optional
        Any other vehicle (:class:`~delaykit.hardware.mavlink.MavlinkLink`...), or a function that makes one (so
        that a pipeline of flights, such as :func:`~delaykit.hardware.autotune.autotune`, opens a fresh link for
        each); ``host`` and the ports are then not used.  :func:`fly` closes it at the end.
    ready_timeout : float
        How long the vehicle may take to be ready to arm (its estimator, its pre-arm checks), s.

    Raises
    ------
    LinkError
        The vehicle did not answer within ``connect_timeout`` seconds (nothing is flown).
    VehicleRefusedError
        The vehicle refused a mode, arming or the take-off, or was not ready in time (its reason in the message).
    """
    say = status or (lambda _m: None)
    check_real("connect_timeout (s)", connect_timeout, minimum=0.0, strict=True)
    check_real("ready_timeout (s)", ready_timeout, minimum=0.0, strict=True)
    if link is not None and not isinstance(link, VehicleLink):
        if not callable(link):
            raise InvalidTypeError(f"link must be a VehicleLink or a function that makes one, got "
                                   f"{type(link).__name__}")
        link = link()
        if not isinstance(link, VehicleLink):
            raise InvalidTypeError(f"the link function must return a VehicleLink, got {type(link).__name__}")
    if monitor is not None:
        from .monitor import DelayMonitor
        if not isinstance(monitor, DelayMonitor):
            raise InvalidTypeError(f"monitor must be a DelayMonitor, got {type(monitor).__name__}")
    chosen = plan.law()
    if isinstance(chosen, Relay):
        if monitor is not None:
            raise InvalidValueError("a relay experiment cannot be flown with a delay monitor (nothing to re-design)")
        law: Any = chosen.law(umin=-plan.vmax, umax=plan.vmax)
    else:
        law = FlightLaw(chosen, umin=-plan.vmax, umax=plan.vmax)
    flown = law.describe()
    online: list[OnlineEstimate] = []
    # every packet of the steps (arrival, altitude, reference, speed) and every command (sent, value): the
    # monitor's data, and the warm-up of a re-designed law
    pk: list[tuple[float, float, float, float, float]] = []  # arrival, altitude, reference, speed, command sent
    holds: list[tuple[float, float]] = []  # commands sent between packets (the hovers while estimating)
    cmd_t: list[float] = []
    cmd_u: list[float] = []
    base = check_path("flight log", log)
    base.parent.mkdir(parents=True, exist_ok=True)
    if link is None:
        link = DroneLink(host, at_port, navdata_port)
    columns = _COLUMNS + (("vehicle_time",) if link.has_vehicle_time else ())

    def row_of(s: AltitudeSample, z_ref: float, u: float, lat: float) -> str:
        vt = "" if not link.has_vehicle_time else (",nan" if s.vehicle_time is None else f",{s.vehicle_time:.6f}")
        return (f"{s.recv_time - t_start:.6f},{s.z:.3f},{z_ref:.9f},{u:.9f},{s.vz:.6f},{s.seq},{s.recv_time:.9f},"
                f"{lat:.4f}{vt}\n")

    events: list[str] = []
    logs: list[Path] = []
    latencies: list[float] = []
    arrivals: list[float] = []
    packets = 0
    reason, completed = "completed", True
    interrupted: str | None = None
    airborne = False
    try:
        # 1. reach the vehicle, wait until it is ready
        link.connect(connect_timeout, vmax=plan.vmax, z_max=plan.z_max, status=say)
        link.ready(ready_timeout, status=say)
        if confirm is not None and not confirm():
            return FlightResult((), "not confirmed: no take-off", False, 0, link.rejected, None, None, None,
                                tuple(events))
        # 2. take-off and hover
        say("take-off")
        airborne = True
        link.takeoff(15.0, status=say)
        say("hovering")
        hover: list[AltitudeSample] = []
        t_start = time.monotonic()
        last: AltitudeSample | None = None
        while time.monotonic() - t_start < plan.hover_time:
            link.hold()
            s = link.recv(plan.gap_timeout)
            if s is not None:
                hover.append(s)
                last = s
        half = [s.z for s in hover if s.recv_time >= t_start + plan.hover_time / 2] or [s.z for s in hover]
        z_ref = float(np.mean(half)) if half else (last.z if last is not None else 0.8)
        # 3. the steps; the log of each starts a second before its step (the hover, for the first)
        # (arrival time, row) of the last second, for the next log's start
        recent: deque = deque((s.recv_time, row_of(s, z_ref, 0.0, 0.0)) for s in hover
                              if s.recv_time >= hover[-1].recv_time - 1.0) if hover else deque()
        for k, step in enumerate(plan.steps):
            path = _log_path(base, k, len(plan.steps))
            logs.append(path)
            fh = _LogFile(path)
            fh.write(",".join(columns) + "\n")
            for _, row in recent:  # the second before the step
                fh.write(row)
            fh.flush()
            z_ref += step
            say(f"step {k + 1}/{len(plan.steps)}: z_ref = {z_ref:.3f} m")
            t_step = time.monotonic()
            try:
                while time.monotonic() - t_step < plan.step_duration:
                    s = link.recv(plan.gap_timeout)
                    if s is None:
                        raise _Abort(f"{link.sample_name} gap longer than {plan.gap_timeout:g} s")
                    z, vz, t_recv = s.z, s.vz, s.recv_time
                    if not plan.z_min <= z <= plan.z_max:
                        raise _Abort(f"altitude {z:.3f} m outside the bounds [{plan.z_min:g}, {plan.z_max:g}] m")
                    u = law.update(t_recv, r=z_ref, y=z, vm=vz)
                    t_sent = link.send_velocity(u)
                    lat = 1e3 * (t_sent - t_recv)
                    latencies.append(lat)
                    arrivals.append(t_recv)
                    packets += 1
                    pk.append((t_recv, z, z_ref, vz, u))
                    cmd_t.append(t_sent)
                    cmd_u.append(u)
                    row = row_of(s, z_ref, u, lat)
                    fh.write(row)
                    recent.append((t_recv, row))
                    while recent and t_recv - recent[0][0] > 1.0:
                        recent.popleft()
                if monitor is not None:
                    law = _watch(monitor, law, link, k, t_step, t_start, pk, holds, cmd_t, cmd_u, online, events,
                                 say)
                    # the packets that queued up meanwhile (answered by the hover): logged, not answered late
                    while (s := link.recv(0.005)) is not None:
                        row = row_of(s, z_ref, 0.0, float("nan"))
                        fh.write(row)
                        recent.append((s.recv_time, row))
            finally:
                fh.close()
    except _Abort as exc:
        reason, completed = str(exc), False
        events.append(reason)
    except KeyboardInterrupt as exc:  # Ctrl-C, or a stop signal (see land_on_signals)
        interrupted = getattr(exc, "signal_name", "Ctrl-C")
        reason = f"interrupted ({interrupted})"
        completed = False
        events.append(reason)
    finally:
        # 4. hover and land, whatever happened (if a take-off was begun)
        try:
            say("landing" if airborne else "no take-off")
            if airborne and not link.land(8.0) and not completed:
                events.append(f"no landing confirmed by {link.name}: its own failsafe is in charge")
        except (OSError, LinkError):
            pass
        link.close()
    lat = np.array(latencies)
    iv = float(np.median(np.diff(arrivals))) if len(arrivals) > 2 else None
    return FlightResult(tuple(logs), reason, completed, packets, link.rejected,
                        float(np.median(lat)) if lat.size else None,
                        float(np.percentile(lat, 99)) if lat.size else None, iv, tuple(events + link.rejections[:5]),
                        flown, tuple(online), interrupted)


def _watch(monitor: DelayMonitor, law: FlightLaw, link: VehicleLink, k: int, t_step: float, t_start: float,
           pk: list, holds: list, cmd_t: list, cmd_u: list, online: list, events: list,
           say: Callable[[str], None]) -> FlightLaw:
    """After step ``k``: hover, estimate the delay on the step's packets, judge it, maybe switch laws."""
    t_hover = link.hold()  # hold still while computing
    cmd_t.append(t_hover)
    cmd_u.append(0.0)
    holds.append((t_hover, 0.0))
    law.record(t_hover, 0.0)
    t, z = np.array([p[0] for p in pk]), np.array([p[1] for p in pk])
    try:
        rec = monitor.check(k + 1, t_hover - t_start, t, z, cmd_t, cmd_u, t_from=t_step, t_to=t_hover)
    except InvalidValueError as exc:  # (too few packets, a step that never moved the command)
        events.append(f"step {k + 1}: no delay estimate ({exc})")
        return law
    online.append(rec)
    lo, hi = rec.design_range
    say(f"step {k + 1}: delay {rec.delay:.4f} s [{rec.estimate.ci[0]:.4f}, {rec.estimate.ci[1]:.4f}], design range "
        f"[{lo:.3f}, {hi:.3f}] s" + (": ALARM" if rec.alarm else ""))
    if rec.alarm:
        events.append(f"step {k + 1}: alarm, delay {rec.delay:.4f} s outside the design range [{lo:.4f}, {hi:.4f}] s")
    if rec.action == "redesigned":
        new = FlightLaw(monitor.controller, umin=law.umin, umax=law.umax)
        # warm up on the last two model delays and a second of packets, with the commands that were sent
        since = t_hover - 2 * new.model_delay - 1.0
        events_in = sorted([(p[0], 0, p) for p in pk if p[0] >= since] + [(h[0], 1, h) for h in holds if h[0] >= since],
                           key=lambda e: (e[0], e[1]))
        for tt, kind, item in events_in:
            if kind == 0:
                new.update(tt, r=item[2], y=item[1], vm=item[3], sent=item[4])
            else:
                new.record(tt, item[1])
        events.append(f"step {k + 1}: re-designed for {rec.delay:.4f} s: {monitor.controller!r}")
        say(f"re-designed for {rec.delay:.4f} s")
        law = new
    elif rec.action != "none":
        events.append(f"step {k + 1}: {rec.action}")
    return law


class _Abort(Exception):
    pass
