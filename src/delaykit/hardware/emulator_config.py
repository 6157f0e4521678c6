"""The emulated drone's settings: :class:`EmulatorConfig` and the checks of its schedules, traces and bursts.

The vehicles it can fly (:data:`VEHICLES`), with the PX4 speed loop's and hover wander's defaults and where they
come from, are documented beside the constants below; :mod:`.emulator` runs them.

Examples
--------
>>> EmulatorConfig(vehicle="lag", lag=0.05).wander_rms
0.0
"""

from __future__ import annotations

import bisect
import math
import numbers
import re
import sys
from dataclasses import dataclass
from typing import Any

from ..errors import InvalidTypeError, InvalidValueError, PortNumberError, check_real

__all__ = ["EmulatorConfig", "VEHICLES", "check_bursts", "PX4_SPEED_WN", "PX4_SPEED_ZETA", "PX4_SPEED_ZERO",
           "PX4_WANDER", "PX4_WANDER_TIME"]


def _check_schedule(value: Any) -> tuple[tuple[float, float], ...] | None:
    """``delay_schedule`` as a tuple of ``(t, delay)`` floats, or a delaykit error naming the bad value."""
    if value is None:
        return None
    if hasattr(value, "times") and hasattr(value, "delays") and getattr(value, "function", None) is None:
        value = list(zip(value.times, value.delays))  # a delaykit.simulate.varying.DelaySchedule
    if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
        raise InvalidValueError(f"delay_schedule must be a list of (t, delay) pairs, got {value!r}")
    pairs: list[tuple[float, float]] = []
    for i, pair in enumerate(value):
        try:
            t, d = pair
        except (TypeError, ValueError):
            raise InvalidValueError(f"delay_schedule[{i}] must be a (t, delay) pair, got {pair!r}") from None
        t = check_real(f"delay_schedule[{i}] time (s since start)", t, minimum=0.0)
        d = check_real(f"delay_schedule[{i}] delay (s)", d, minimum=0.0, maximum=5.0)
        if pairs and not t > pairs[-1][0]:
            raise InvalidValueError(f"delay_schedule times must increase: delay_schedule[{i}] time {t:g} s is not "
                                    f"after {pairs[-1][0]:g} s")
        pairs.append((t, d))
    if not pairs:
        raise InvalidValueError("delay_schedule must hold at least one (t, delay) pair (or be None)")
    return tuple(pairs)


_VARYING = __name__.rsplit(".", 2)[0] + ".simulate.varying"  # its classes, recognised without importing it
_MAX_DELAY = 5.0  # the largest actuator delay (s)

#: The vehicles the emulator flies (``EmulatorConfig.vehicle``).
VEHICLES = ("lag", "speed_loop")

# The speed loop identified from the 18 full PX4 flights of ../shared/data (docs/guide/identification.md:
# structure ipdt_speed, gain 0.79, wn 1.53 rad/s, zeta 2.4, zero 3.9 s, delay 0.101 s).  The gain is left at 1
# (see the module docstring).
PX4_SPEED_WN = 1.53
PX4_SPEED_ZETA = 2.4
PX4_SPEED_ZERO = 3.9

# The hover wander, measured on the same PX4 logs: the hover before each step (t from 10 to 15 s, the step comes
# at 15.0 s; 249 samples every 20 ms) of all 18 flights.  The RMS about each segment's mean: median 4.9 mm (2.4
# to 12.7 mm).  The correlation time: the segments' autocorrelation (mean removed) crosses zero at 1.35 s (median;
# 0.97 to 1.87 s).  Five seconds are too short to fix it: removing the mean of an OU process seen through the
# same window (its exact expected autocovariance M C M, M the centring matrix) moves that crossing to 1.06 s for a
# correlation time of 2 s, 1.23 s for 3 s and at most 1.46 s (a random walk), so the segments say "at least about
# 2 s" (they are also smoother at short lags than an OU: a position held by a loop).  We take 2 s.  The RMS then
# follows from the same window: the expected variance about a 5 s mean is 0.493 sigma^2 for 2 s, so the median
# 4.9 mm means sigma = 4.9 / sqrt(0.493) = 7.0 mm.  These are the PX4's closed-loop hover numbers used as the
# disturbance itself: a controller flying the emulator takes out the slowest part of it.
PX4_WANDER = 0.007
PX4_WANDER_TIME = 2.0
_WANDER_TICK = 0.002  # the wander's time grid (s), as fine as the recorded trajectory


def check_bursts(bursts: Any, rate: float, *, labels: Any = None) -> tuple[tuple[float, float, float], ...]:
    """Navdata bursts as ``(start, duration, rate)`` floats sorted by start, or a delaykit error naming the bad one.

    Parameters
    ----------
    bursts : iterable of (start, duration[, rate]) or None
        ``start`` (s since the emulator started, at least 0), ``duration`` (s, more than 0) and the navdata
        ``rate`` during the burst (Hz, at least 0 and below ``rate``; 0 if left out: no navdata at all).  Bursts
        may touch but not overlap.
    rate : float
        The normal navdata rate (Hz).
    labels : sequence of str, optional
        How the errors name each burst (default ``bursts[i]``; the command line passes its ``--burst`` texts).

    Returns
    -------
    tuple of (float, float, float)

    Raises
    ------
    InvalidValueError, InvalidTypeError
        Naming the burst and the value at fault.

    Examples
    --------
    >>> check_bursts([(5.0, 1.0, 2.0), (2, 0.5)], 15.0)
    ((2.0, 0.5, 0.0), (5.0, 1.0, 2.0))
    """
    if bursts is None:
        return ()
    varying = sys.modules.get(_VARYING)
    if isinstance(bursts, (str, bytes)) or not hasattr(bursts, "__iter__") or (
            varying is not None and isinstance(bursts, varying.DelayModel)):
        raise InvalidTypeError(f"bursts must be a list of (start, duration, rate) triples, got {bursts!r}")
    items = list(bursts)
    name = (lambda i: f"bursts[{i}]") if labels is None else (lambda i: str(labels[i]))
    checked: list[tuple[int, float, float, float]] = []
    for i, item in enumerate(items):
        if varying is not None and isinstance(item, varying.Burst):
            raise InvalidTypeError(f"{name(i)} is a simulator Burst ({item!r}), which adds command delay; the "
                                   "emulator's bursts lower the navdata rate: give (start, duration, rate)")
        parts = tuple(item) if hasattr(item, "__iter__") and not isinstance(item, (str, bytes)) else None
        if parts is None or len(parts) not in (2, 3):
            raise InvalidValueError(f"{name(i)} must be (start, duration) or (start, duration, rate), got {item!r}")
        start = check_real(f"{name(i)} start (s since start)", parts[0], minimum=0.0)
        duration = check_real(f"{name(i)} duration (s)", parts[1], minimum=0.0, strict=True)
        if not math.isfinite(start + duration):
            raise InvalidValueError(f"{name(i)} must end at a finite time, got start {start:g} s, duration "
                                    f"{duration:g} s")
        r = check_real(f"{name(i)} rate (Hz)", parts[2] if len(parts) == 3 else 0.0, minimum=0.0)
        if not r < rate:
            raise InvalidValueError(f"{name(i)} rate {r:g} Hz must be below the normal navdata rate {rate:g} Hz "
                                    "(a burst lowers the rate)")
        checked.append((i, start, duration, r))
    checked.sort(key=lambda b: b[1])
    for (i, s0, d0, _), (j, s1, _, _) in zip(checked, checked[1:]):
        if s1 < s0 + d0:
            raise InvalidValueError(f"{name(j)} (from {s1:g} s) overlaps {name(i)} ({s0:g} to {s0 + d0:g} s): "
                                    "bursts must not overlap")
    return tuple((s0, d0, r) for _, s0, d0, r in checked)


def _check_trace(value: Any, delay: float) -> tuple[tuple[float, float], ...] | None:
    """``delay_trace`` as ``(t, extra delay)`` steps in emulator time, the first at 0 (see the module docstring)."""
    if value is None:
        return None
    varying = sys.modules.get(_VARYING)
    if varying is not None and isinstance(value, varying.DelayModel):
        if not isinstance(value, varying.DelayTrace):
            raise InvalidTypeError(f"delay_trace must be a DelayTrace or (t, delay) records, got {value!r} (a "
                                   "DelaySchedule goes to delay_schedule)")
        if value.interpolation != "previous":
            raise InvalidValueError(f"the emulator holds each record of delay_trace until the next "
                                    f"(interpolation='previous'); {value.source} has interpolation="
                                    f"{value.interpolation!r}")
        times, delays, start, where = value.times, value.delays, value.start, f" of {value.source}"
    else:
        if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__"):
            raise InvalidValueError(f"delay_trace must be a DelayTrace or a list of (t, delay) records, got "
                                    f"{value!r}")
        times, delays = [], []
        for i, pair in enumerate(value):
            try:
                t, d = pair
            except (TypeError, ValueError):
                raise InvalidValueError(f"delay_trace[{i}] must be a (t, delay) record, got {pair!r}") from None
            t = check_real(f"delay_trace[{i}] time (s)", t)
            d = check_real(f"delay_trace[{i}] delay (s)", d, minimum=0.0)
            if times and not t > times[-1]:
                raise InvalidValueError(f"delay_trace times must increase: delay_trace[{i}] time {t:g} s is not "
                                        f"after {times[-1]:g} s")
            times.append(t)
            delays.append(d)
        if not times:
            raise InvalidValueError("delay_trace must hold at least one (t, delay) record (or be None)")
        start, where = times[0], ""
    first = max(bisect.bisect_right(times, start) - 1, 0)  # the record in force at the start
    steps = [(0.0, float(delays[first]))] + [(float(t) - start, float(d)) for t, d in
                                            zip(times[first + 1:], delays[first + 1:])]
    worst = max(range(first, len(delays)), key=lambda i: delays[i])  # (records before the start are not replayed)
    if delay + delays[worst] > _MAX_DELAY:
        raise InvalidValueError(f"delay_trace record {worst}{where} (t = {times[worst]:g} s): delay {delay:g} s + "
                                f"{delays[worst]:g} s = {delay + delays[worst]:g} s is above the emulator's largest "
                                f"actuator delay, {_MAX_DELAY:g} s")
    return tuple(steps)


def _wakeups(rate: float, bursts: tuple[tuple[float, float, float], ...]) -> Any:
    """The navdata thread's wake-up times (s since start) and whether it sends then, in order, without end.

    The normal grid ``k / rate`` (``k = 1, 2, ...``) always wakes it (physics and watchdog), sending unless the
    time falls in a burst; a burst ``(s, d, r)`` adds the sends ``s + j / r`` (``j = 0, 1, ...``) before ``s + d``.

    Examples
    --------
    >>> import itertools
    >>> [(round(t, 3), send) for t, send in itertools.islice(_wakeups(10.0, ((0.25, 0.3, 5.0),)), 7)]
    [(0.1, True), (0.2, True), (0.25, True), (0.3, False), (0.4, False), (0.45, True), (0.5, False)]
    """
    def burst_sends() -> Any:
        for s, d, r in bursts:
            j = 0
            while r > 0 and s + j / r < s + d:
                yield s + j / r
                j += 1

    sends = burst_sends()
    nb = next(sends, math.inf)
    b, k = 0, 1
    while True:
        tn = k / rate
        if nb <= tn:
            yield nb, True
            nb = next(sends, math.inf)
            continue
        while b < len(bursts) and tn >= bursts[b][0] + bursts[b][1]:
            b += 1
        yield tn, not (b < len(bursts) and tn >= bursts[b][0])
        k += 1


def _check_port(name: str, p: Any) -> int:
    if isinstance(p, bool) or not isinstance(p, int) or not 0 <= p <= 65535:
        raise PortNumberError(f"{name} must be a port number from 0 to 65535 (0 = any free one), got {p!r}")
    return p


def _check_ipv4(name: str, host: Any) -> str:
    """``host`` if it is not an IPv6 address: the AR.Drone (and so its emulator) speaks IPv4 only."""
    import ipaddress

    if not isinstance(host, str):
        raise InvalidTypeError(f"{name} must be an address or a host name (text), got {host!r}")
    try:
        v6 = ipaddress.ip_address(host).version == 6
    except ValueError:  # a name: checked before any lookup (a 300-character one was a UnicodeError from it)
        _check_host_name(name, host)
        v6 = False
    if v6:
        raise InvalidValueError(f"{name} {host!r} is an IPv6 address; the AR.Drone speaks IPv4 only: give an IPv4 "
                                "address such as 127.0.0.1 (loopback) or 192.168.1.1")
    return host


def _resolve_ipv4(name: str, host: Any) -> str:
    """``host`` as an IPv4 address: checked by :func:`_check_ipv4`, a host name resolved (a delaykit error if it
    cannot be)."""
    import ipaddress
    import socket

    _check_ipv4(name, host)
    try:
        ipaddress.ip_address(host)
    except ValueError:
        try:
            host = socket.gethostbyname(host)
        except (OSError, UnicodeError):
            raise InvalidValueError(f"{name} {host!r:.80} is not an address and cannot be resolved") from None
    return host


def _check_host_name(name: str, host: str) -> None:
    """Refuse, before any lookup, text that cannot be a host name (RFC 1123: at most 253 characters, labels of 1 to
    63 letters, digits, hyphens (and underscores), not starting or ending with a hyphen)."""
    labels = host[:-1].split(".") if host.endswith(".") else host.split(".")
    if not host or len(host) > 253 or not all(_LABEL.fullmatch(x) for x in labels):
        shown = host if len(host) <= 60 else host[:57] + "..."
        raise InvalidValueError(f"{name} {shown!r} ({len(host)} characters) is not an IPv4 address or a host name "
                                "(labels of 1 to 63 letters, digits and hyphens, 253 characters at most)")
    if labels[-1].isdigit():  # (a top-level label is never all digits: 1.2.3 or 256.1.1.1 is a mistyped address)
        raise InvalidValueError(f"{name} {host!r} is not an IPv4 address (four numbers from 0 to 255, such as "
                                "192.168.1.1) nor a host name")


_LABEL = re.compile(r"[A-Za-z0-9_](?:[A-Za-z0-9_-]{0,61}[A-Za-z0-9_])?")  # (an underscore: in use, if not RFC's)


@dataclass(frozen=True)
class EmulatorConfig:
    """Settings of the emulated drone (see the module docstring).

    ``delay_schedule``: ``(t, delay)`` pairs, ``t`` in seconds since the emulator started, that change the
    actuator delay mid-flight (None: ``delay`` throughout).

    ``delay_trace``: a recorded delay replayed, added to ``delay``: a
    :class:`~delaykit.simulate.varying.DelayTrace` or its ``(t, delay)`` records (replayed from the first); kept as
    ``(t, extra delay)`` steps in seconds since start, the first at 0.  Not with ``delay_schedule``.

    ``bursts``: ``(start, duration, rate)`` triples (s since start, s, Hz below ``rate``; a pair means rate 0)
    during which the navdata rate falls; kept sorted by start (:func:`check_bursts`).

    ``vehicle``: ``"speed_loop"`` (default) or ``"lag"`` (:data:`VEHICLES`).  The speed loop's natural frequency
    ``speed_wn`` (rad/s, above 0), damping ``speed_zeta`` (above 0) and zero ``speed_zero`` (s, 0 for none)
    default to the PX4 fit; ``lag`` (s) is the lag vehicle's time constant and unused by the speed loop.

    ``wander``: the hover wander's stationary RMS (m); None (default) means the vehicle's own, 7 mm for the speed
    loop (measured on the PX4 logs, see ``PX4_WANDER`` in the source) and 0 for the lag vehicle
    (:attr:`wander_rms` resolves it).  ``wander_time``: its correlation time (s, default 2).

    ``accel_limit``: the vertical acceleration limit of the speed command, m/s^2 (0, the default: none), as real
    autopilots have (ArduCopter's ``WPNAV_ACCEL_Z`` is 1 m/s^2 by default): a commanded speed step becomes a ramp
    of that slope before the vehicle's speed loop.

    Examples
    --------
    >>> EmulatorConfig().vehicle, EmulatorConfig().wander_rms, EmulatorConfig(vehicle="lag").wander_rms
    ('speed_loop', 0.007, 0.0)
    >>> EmulatorConfig(delay=0.25, delay_schedule=[(20.0, 0.40)]).delay_schedule
    ((20.0, 0.4),)
    >>> EmulatorConfig(delay=0.2, delay_trace=[(100.0, 0.05), (101.5, 0.1)]).delay_trace
    ((0.0, 0.05), (1.5, 0.1))
    >>> EmulatorConfig(bursts=[(5.0, 1.0)]).bursts
    ((5.0, 1.0, 0.0),)
    """

    host: str = "127.0.0.1"
    at_port: int = 5556
    navdata_port: int = 5554
    video_port: int = 5555
    control_port: int = 5559
    delay: float = 0.30
    lag: float = 0.05
    link_delay: float = 0.0
    noise: float = 0.005
    rate: float = 15.0
    loss: float = 0.0
    jitter: float = 0.0
    seed: int | None = None
    takeoff_altitude: float = 0.8
    takeoff_speed: float = 0.7
    landing_speed: float = 0.6
    watchdog: float = 2.0
    delay_schedule: Any = None
    delay_trace: Any = None
    bursts: Any = ()
    vehicle: str = "speed_loop"
    speed_wn: float = PX4_SPEED_WN
    speed_zeta: float = PX4_SPEED_ZETA
    speed_zero: float = PX4_SPEED_ZERO
    wander: float | None = None
    wander_time: float = PX4_WANDER_TIME
    accel_limit: float = 0.0

    def __post_init__(self) -> None:
        _check_ipv4("host", self.host)
        for name in ("at_port", "navdata_port", "video_port", "control_port"):
            _check_port(name, getattr(self, name))
        for a, b, transport in (("at_port", "navdata_port", "UDP"), ("video_port", "control_port", "TCP")):
            if getattr(self, a) and getattr(self, a) == getattr(self, b):
                raise PortNumberError(f"{a} and {b} are both {getattr(self, a)}: two {transport} services cannot "
                                      "share a port (give different ones, or 0 for any free one)")
        if self.seed is not None and (isinstance(self.seed, bool) or not isinstance(self.seed, numbers.Integral)):
            raise InvalidTypeError(f"seed must be an integer or None, got {self.seed!r:.40} "
                                   f"({type(self.seed).__name__})")
        check_real("delay (s)", self.delay, minimum=0.0, maximum=5.0)
        check_real("lag (s)", self.lag, minimum=0.0, maximum=5.0)
        check_real("link_delay (s)", self.link_delay, minimum=0.0, maximum=2.0)
        check_real("noise (m)", self.noise, minimum=0.0, maximum=1.0)
        check_real("rate (Hz)", self.rate, minimum=1.0, maximum=1000.0)
        check_real("loss", self.loss, minimum=0.0, maximum=0.9)
        check_real("jitter (s)", self.jitter, minimum=0.0, maximum=0.5)
        object.__setattr__(self, "delay_schedule", _check_schedule(self.delay_schedule))
        if self.delay_schedule is not None and self.delay_trace is not None:
            raise InvalidValueError("give delay_schedule or delay_trace, not both: a schedule replaces the actuator "
                                    "delay and a trace is added to it, so together they are ambiguous (merge them "
                                    "into one schedule)")
        object.__setattr__(self, "delay_trace", _check_trace(self.delay_trace, float(self.delay)))
        object.__setattr__(self, "bursts", check_bursts(self.bursts, float(self.rate)))
        if not isinstance(self.vehicle, str):
            raise InvalidTypeError(f"vehicle must be one of {', '.join(VEHICLES)} (text), got {self.vehicle!r}")
        if self.vehicle not in VEHICLES:
            raise InvalidValueError(f"vehicle must be one of {', '.join(VEHICLES)}, got {self.vehicle!r}")
        check_real("speed_wn (rad/s)", self.speed_wn, minimum=0.0, maximum=100.0, strict=True)
        check_real("speed_zeta", self.speed_zeta, minimum=0.0, maximum=100.0, strict=True)
        check_real("speed_zero (s)", self.speed_zero, minimum=0.0, maximum=100.0)
        if self.wander is not None:
            check_real("wander (m)", self.wander, minimum=0.0, maximum=1.0)
        check_real("wander_time (s)", self.wander_time, minimum=0.0, maximum=1000.0, strict=True)
        check_real("accel_limit (m/s^2)", self.accel_limit, minimum=0.0, maximum=100.0)

    @property
    def wander_rms(self) -> float:
        """The hover wander's stationary RMS in force (m): ``wander``, or the vehicle's own when it is None."""
        if self.wander is not None:
            return float(self.wander)
        return PX4_WANDER if self.vehicle == "speed_loop" else 0.0
