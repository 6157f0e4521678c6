"""A built-in AR.Drone 2.0 emulator on loopback: the default "drone" on any machine.

It speaks the real protocol (:mod:`delaykit.hardware.ardrone`): AT commands on UDP ``at_port``; navdata on UDP
``navdata_port`` to whoever sent it bytes there (bootstrap packets until ``general:navdata_demo`` is set,
then demo packets at ``rate`` Hz); TCP accepted on the video and control ports (the control port answers
``AT*CTRL=<seq>,4,0`` with a configuration text).  It binds to 127.0.0.1 unless told otherwise.

The vertical motion: while flying, a progressive PCMD commands the speed ``gaz * control_vz_max``; it takes
effect ``delay`` seconds after the command arrives (the actuator delay), plus ``link_delay`` on the way in,
and the actual speed follows it through a first-order lag ``lag``.  The altitude is integrated exactly
between events.  The altitude and the vertical speed in navdata are the true ones ``link_delay`` before
sending (the altitude plus Gaussian ultrasonic noise, in millimetres).  Navdata packets go out every ``1 / rate``
seconds, each one late by a uniform random ``[0, jitter]`` seconds, and dropped with probability ``loss`` (the
sequence number still counts it, so a receiver sees the gap).  Take-off climbs to 0.8 m, landing descends to the
ground; the state bits follow take-off, flying, landing, emergency and the communication watchdog (2 s without a
command: hover).

**The loop delay** a controller sees is ``delay + 2 * link_delay`` (:attr:`DroneEmulator.true_delay`):
actuator plus the network both ways; on loopback the real network adds microseconds.

**A delay that changes mid-flight**: ``delay_schedule``, a list of ``(t, delay)`` pairs (``t`` in seconds since
:meth:`DroneEmulator.start`, increasing; delays from 0 to 5 s), replaces the actuator delay from each time on
(``delay`` holds before the first).  The delay in force when a command reaches the drone is the one it gets
(:meth:`DroneEmulator.actuator_delay`, :meth:`DroneEmulator.true_delay_at`).  When the delay falls, a newer
command can take effect before older ones still pending: the drone applies the newest, and the older ones,
stale, are dropped (counted in ``stats["stale"]``), as :mod:`delaykit.simulate.varying` models it with
``keep_order=False``.  The controller's
sampling (one command per navdata packet) is not a delay but a sample-and-hold, which the estimator models.

**A recorded delay replayed**: ``delay_trace``, a :class:`~delaykit.simulate.varying.DelayTrace` (from a CSV of
``t,delay`` or the ``latency_ms`` column of a flight log) or its ``(t, delay)`` records, is *added* to ``delay``
(as ``delaykit simulate --delay-trace`` adds it; give ``delay=0`` for a trace of whole delays).  The trace is
replayed from its ``start`` (by default its first record) at :meth:`DroneEmulator.start`, each record held until
the next (the trace's ``interpolation="previous"``; a linear one is refused), the first before it and the last
after it: exactly ``delay + trace.packet_delays([t])`` at ``t`` seconds since start.  It is a schedule with many
steps and takes the same path as ``delay_schedule`` (the delay in force when a command arrives, stale commands
dropped); the two cannot be given together.

**Bursts** (a Wi-Fi scan): ``bursts``, ``(start, duration, rate)`` triples (seconds since start, seconds, Hz;
``rate`` 0 by default: no navdata at all), lower the navdata rate: during ``[start, start + duration)`` packets
go out at ``start + j / rate`` (``j = 0, 1, ...``) instead of on the normal grid ``k / rate``, which resumes at
its first point from ``start + duration``.  Only the sending slows: the emulator still wakes on the normal grid
to run the physics and the watchdog.  The sequence number counts the packets sent, so a burst shows as a slower
rate, not as lost packets.  :class:`~delaykit.simulate.varying.Burst` models the same event in the simulator
from the other side, as extra command *delay*: a controller that acts on each navdata packet sends its commands
at the navdata rate, so a burst at ``rate`` Hz makes each command's measurement up to ``1 / rate`` s old instead
of ``1 / config.rate`` (with ``rate`` 0, up to ``duration``): about ``Burst(start, start + duration, extra)``
with ``extra`` between 0 and ``1 / rate - 1 / config.rate`` (a sample-and-hold, not a fixed delay).

Every datagram that fails to parse is counted (``stats["bad"]``) and ignored; the emulator never stops on one.

**Threads and shared state.**  Four threads (AT commands, navdata-port datagrams, navdata sending, TCP) share the
emulator's state; one lock, ``_lock``, guards all of it: the physics, the counters, the configuration, the
navdata client, and the control connection (``_control_conn``, None until a client connects).  Sockets are
used outside the lock.  :attr:`DroneEmulator.stats` and :meth:`DroneEmulator.summary` are snapshots taken
under the lock, safe to read while it runs.

Examples
--------
>>> with DroneEmulator(EmulatorConfig(at_port=0, navdata_port=0, video_port=0, control_port=0)) as emu:
...     emu.ports["at"] > 0
True
"""

from __future__ import annotations

import bisect
import errno
import math
import random
import socket
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any

from ..errors import InvalidTypeError, InvalidValueError, PortError, PortNumberError, check_real
from .ardrone import CtrlState, Demo, NavState, ProtocolError, REF_EMERGENCY, REF_TAKEOFF, encode_navdata, parse_at
from .stamps import enable_stamps, recv_stamped

__all__ = ["EmulatorConfig", "DroneEmulator", "PortError", "PortNumberError", "check_bursts"]

# PortError (a port that cannot be bound: an OSError, not a bad value) and PortNumberError (a port number out
# of range: a bad value) are defined in delaykit.errors and re-exported here


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

    Examples
    --------
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

    def __post_init__(self) -> None:
        for name in ("at_port", "navdata_port", "video_port", "control_port"):
            _check_port(name, getattr(self, name))
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


@dataclass
class _Physics:
    z: float = 0.0
    v: float = 0.0
    v_in: float = 0.0
    mode: int = CtrlState.LANDED
    t: float = 0.0
    pending: deque = field(default_factory=deque)
    history: deque = field(default_factory=lambda: deque(maxlen=4096))  # (t, z, v) every 2 ms


class DroneEmulator:
    """The emulated drone; ``start()``/``stop()`` or use it as a context manager.

    Attributes
    ----------
    ports : dict
        The bound ports (``at``, ``navdata``, ``video``, ``control``), useful when 0 asked for free ones.
    stats : dict
        Counts (a snapshot): ``datagrams``, ``commands``, ``bad`` (rejected), ``navdata_sent``, ``navdata_dropped``.
    """

    def __init__(self, config: EmulatorConfig | None = None, **overrides: Any) -> None:
        self.config = replace(config or EmulatorConfig(), **overrides) if overrides else (config or EmulatorConfig())
        self.rng = random.Random(self.config.seed)
        c = self.config  # the actuator delay's steps (s since start, s): the schedule's, or delay + the trace's
        steps = c.delay_schedule or tuple((t, c.delay + d) for t, d in c.delay_trace or ())
        self._delay_times = [t for t, _ in steps]
        self._delay_values = [d for _, d in steps]
        self.ports: dict[str, int] = {}
        # everything below that the threads share is guarded by this one lock (see the module docstring)
        self._lock = threading.Lock()
        self._stats = {"datagrams": 0, "commands": 0, "bad": 0, "navdata_sent": 0, "navdata_dropped": 0,
                       "stale": 0}
        self._t0 = time.monotonic()  # the schedule's clock: reset by start()
        self._last_error = ""
        self.kernel_stamps = False  # whether command arrivals carry the kernel's stamp (set by start())
        self._control_conn: socket.socket | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._socks: list[socket.socket] = []
        self._phys = _Physics()
        self._client: tuple[str, int] | None = None
        self._demo = False
        self._ack = False
        self._vz_max = 0.7  # m/s, factory control_vz_max = 700 mm/s
        self._alt_max = 3.0
        self._last_cmd = time.monotonic()
        self._watchdog = False
        self._seq = 0
        self._config_kv: dict[str, str] = {"control:control_vz_max": "700", "control:altitude_max": "3000",
                                           "general:navdata_demo": "FALSE"}
        self._pending_config_send = False

    # ---------------------------------------------------------------------------------------------------
    @property
    def stats(self) -> dict[str, int]:
        """A snapshot of the counts (see the class docstring)."""
        with self._lock:
            return dict(self._stats)

    @property
    def last_error(self) -> str:
        """Why the last rejected datagram was rejected ("" if none was)."""
        with self._lock:
            return self._last_error

    def summary(self) -> dict[str, Any]:
        """What it counted and rejected: ports, counts, the last rejection, and the loop delay (JSON-ready)."""
        c = self.config
        trace = None if c.delay_trace is None else {
            "records": len(c.delay_trace), "actuator_delay_min": min(self._delay_values),
            "actuator_delay_max": max(self._delay_values)}
        with self._lock:
            return {"ports": dict(self.ports), "stats": dict(self._stats), "last_error": self._last_error,
                    "true_delay": self.true_delay,
                    "delay_schedule": [list(p) for p in c.delay_schedule or ()],
                    "delay_trace": trace, "bursts": [list(b) for b in c.bursts]}

    @property
    def true_delay(self) -> float:
        """The loop delay a controller sees: actuator delay plus the link delay both ways (with a
        ``delay_schedule``, the one before its first change; with a ``delay_trace``, the one at the start; see
        :meth:`true_delay_at`)."""
        c = self.config
        return c.delay + (c.delay_trace[0][1] if c.delay_trace else 0.0) + 2 * c.link_delay

    @property
    def start_time(self) -> float:
        """The monotonic time of :meth:`start`: the origin of ``delay_schedule``'s times."""
        return self._t0

    @property
    def elapsed(self) -> float:
        """Seconds since :meth:`start` (the clock of ``delay_schedule``)."""
        return time.monotonic() - self._t0

    def actuator_delay(self, t: float | None = None) -> float:
        """The actuator delay in force at the monotonic time ``t`` (default: now).

        Examples
        --------
        >>> emu = DroneEmulator(EmulatorConfig(delay=0.25, delay_schedule=[(20.0, 0.40)]))
        >>> emu.actuator_delay(emu._t0 + 19.9), emu.actuator_delay(emu._t0 + 20.0)
        (0.25, 0.4)
        """
        since = (time.monotonic() if t is None else t) - self._t0
        i = bisect.bisect_right(self._delay_times, since) - 1  # the last step at or before `since`
        return self._delay_values[i] if i >= 0 else self.config.delay

    def true_delay_at(self, t: float | None = None) -> float:
        """The loop delay a command sent at the monotonic time ``t`` (default: now) sees."""
        return self.actuator_delay((time.monotonic() if t is None else t) + self.config.link_delay) \
            + 2 * self.config.link_delay

    @property
    def altitude(self) -> float:
        """The true altitude now (m)."""
        with self._lock:
            self._advance(time.monotonic())
            return self._phys.z

    @property
    def mode(self) -> int:
        """The major control state (:class:`~delaykit.hardware.ardrone.CtrlState`)."""
        with self._lock:
            return self._phys.mode

    def _bind(self, kind: int, port: int, name: str) -> socket.socket:
        s = socket.socket(socket.AF_INET, kind)
        if kind == socket.SOCK_STREAM:  # (on UDP it would let two emulators share a port silently)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((self.config.host, port))
        except OSError as exc:
            s.close()
            if exc.errno == errno.EADDRINUSE:
                raise PortError(f"{name} port {port} on {self.config.host} is already in use") from None
            raise PortError(f"cannot bind the {name} port {port} on {self.config.host}: {exc.strerror}") from None
        self._socks.append(s)
        self.ports[name] = s.getsockname()[1]
        return s

    def start(self) -> "DroneEmulator":
        """Bind the ports and start the threads."""
        c = self.config
        try:
            self._at = self._bind(socket.SOCK_DGRAM, c.at_port, "at")
            self._nav = self._bind(socket.SOCK_DGRAM, c.navdata_port, "navdata")
            self._video = self._bind(socket.SOCK_STREAM, c.video_port, "video")
            self._control = self._bind(socket.SOCK_STREAM, c.control_port, "control")
        except PortError:
            self.stop()
            raise
        for s in (self._at, self._nav):
            s.settimeout(0.05)
        self.kernel_stamps = enable_stamps(self._at)  # a command's arrival is when the kernel got it
        for s in (self._video, self._control):
            s.listen(4)
            s.settimeout(0.1)
        self._phys.t = time.monotonic()
        self._last_cmd = time.monotonic()
        self._t0 = self._phys.t
        for target in (self._at_loop, self._wake_loop, self._nav_loop, self._tcp_loop):
            th = threading.Thread(target=target, daemon=True, name=f"emulator-{target.__name__}")
            th.start()
            self._threads.append(th)
        return self

    def stop(self) -> None:
        """Stop the threads and close the sockets."""
        self._stop.set()
        for th in self._threads:
            th.join(timeout=2.0)
        for s in self._socks:
            try:
                s.close()
            except OSError:
                pass
        self._socks.clear()

    def __enter__(self) -> "DroneEmulator":
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # ---- physics --------------------------------------------------------------------------------------
    def _integrate(self, dt: float) -> None:
        p, c = self._phys, self.config
        if dt <= 0:
            return
        if p.mode == CtrlState.TAKING_OFF:
            p.z = min(c.takeoff_altitude, p.z + c.takeoff_speed * dt)
            p.v = c.takeoff_speed
            if p.z >= c.takeoff_altitude:
                p.mode, p.v, p.v_in = CtrlState.HOVERING, 0.0, 0.0
                p.pending.clear()
        elif p.mode == CtrlState.LANDING:
            p.z = max(0.0, p.z - c.landing_speed * dt)
            p.v = -c.landing_speed
            if p.z <= 0.0:
                p.mode, p.v, p.v_in = CtrlState.LANDED, 0.0, 0.0
        elif p.mode in (CtrlState.FLYING, CtrlState.HOVERING):
            u = 0.0 if self._watchdog else p.v_in
            if c.lag > 0:
                e = math.exp(-dt / c.lag)
                p.z += u * dt + (p.v - u) * c.lag * (1.0 - e)
                p.v = u + (p.v - u) * e
            else:
                p.z += u * dt
                p.v = u
            if p.z >= self._alt_max and p.v > 0:
                p.z, p.v = self._alt_max, 0.0
            if p.z <= 0.0:
                p.z, p.v = 0.0, 0.0
        else:
            p.v = 0.0
        p.t += dt

    def _advance(self, t: float) -> None:
        p = self._phys
        while p.pending and p.pending[0][0] <= t:
            ta, v = p.pending.popleft()
            self._integrate(max(ta - p.t, 0.0))  # (a command stamped late by a busy thread: apply it now)
            if p.mode in (CtrlState.FLYING, CtrlState.HOVERING):
                p.v_in = v
                p.mode = CtrlState.FLYING if v != 0 else CtrlState.HOVERING
        # record the trajectory finely enough for the link delay's look-back (linear between points)
        while t - p.t > 0.002:
            self._integrate(0.002)
            p.history.append((p.t, p.z, p.v))
        self._integrate(t - p.t)
        p.history.append((p.t, p.z, p.v))

    def _state_at(self, t: float) -> tuple[float, float]:
        """The true altitude and vertical speed at an earlier time t (for the link delay): linear between
        recorded states."""
        h = self._phys.history
        prev = None
        for tt, z, v in reversed(h):
            if tt <= t:
                if prev is None or prev[0] == tt:
                    return z, v
                f = (t - tt) / (prev[0] - tt)
                return z + (prev[1] - z) * f, v + (prev[2] - v) * f
            prev = (tt, z, v)
        return (h[0][1], h[0][2]) if h else (self._phys.z, self._phys.v)

    # ---- commands -------------------------------------------------------------------------------------
    def _handle(self, data: bytes, t: float) -> None:
        try:
            cmds = parse_at(data)
        except ProtocolError as exc:
            with self._lock:
                self._stats["datagrams"] += 1
                self._stats["bad"] += 1
                self._last_error = str(exc)
            return
        c = self.config
        with self._lock:
            self._stats["datagrams"] += 1
            self._advance(max(t, self._phys.t))  # t is the kernel's arrival stamp: the physics may be past it
            self._last_cmd = t
            for cmd in cmds:
                self._stats["commands"] += 1
                p = self._phys
                if cmd.name == "REF":
                    bits = cmd.args[0]
                    if bits & REF_EMERGENCY and p.mode not in (CtrlState.LANDED,):
                        p.mode, p.z, p.v, p.v_in = CtrlState.LANDED, 0.0, 0.0, 0.0
                        p.pending.clear()
                    elif bits & REF_TAKEOFF:
                        if p.mode == CtrlState.LANDED:
                            p.mode = CtrlState.TAKING_OFF
                    elif p.mode in (CtrlState.FLYING, CtrlState.HOVERING, CtrlState.TAKING_OFF):
                        p.mode = CtrlState.LANDING
                        p.pending.clear()
                elif cmd.name in ("PCMD", "PCMD_MAG"):
                    if p.mode in (CtrlState.FLYING, CtrlState.HOVERING):
                        flag = cmd.args[0]
                        gaz = cmd.floats(3, 4)[0]
                        v = gaz * self._vz_max if flag & 1 else 0.0
                        arrive = t + c.link_delay
                        ta = arrive + self.actuator_delay(arrive)
                        while p.pending and p.pending[-1][0] >= ta:  # older, now stale: the newest wins
                            p.pending.pop()
                            self._stats["stale"] += 1
                        p.pending.append((ta, v))
                elif cmd.name == "COMWDG":
                    self._watchdog = False
                elif cmd.name == "CONFIG":
                    key, value = cmd.args
                    self._config_kv[key] = value
                    if key == "general:navdata_demo":
                        self._demo = value.upper() == "TRUE"
                    elif key in ("control:control_vz_max", "control:altitude_max"):
                        lo, hi = (200.0, 2000.0) if key == "control:control_vz_max" else (500.0, 100000.0)
                        try:
                            x = float(value)
                        except ValueError:
                            x = math.nan
                        if math.isfinite(x):
                            x = min(max(x, lo), hi) / 1000.0
                            if key == "control:control_vz_max":
                                self._vz_max = x
                            else:
                                self._alt_max = x
                        else:
                            self._stats["bad"] += 1
                            self._last_error = f"{key} must be a finite number of millimetres, got {value!r}"
                    self._ack = True
                elif cmd.name == "CTRL":
                    if cmd.args[0] == 5:
                        self._ack = False
                    elif cmd.args[0] == 4:
                        self._pending_config_send = True

    def _at_loop(self) -> None:
        while not self._stop.is_set():
            try:
                data, _, t = recv_stamped(self._at, 4096)
            except (socket.timeout, OSError):
                continue
            self._handle(data, t)

    def _wake_loop(self) -> None:
        """Datagrams to the navdata port: any of them makes the sender the navdata client."""
        while not self._stop.is_set():
            try:
                _, addr = self._nav.recvfrom(4096)
            except (socket.timeout, OSError):
                continue
            with self._lock:
                self._client = addr

    def _state_bits(self) -> int:
        p = self._phys
        s = NavState.ALTITUDE_CONTROL | NavState.CONTROL | NavState.PIC_VERSION_OK
        if p.mode in (CtrlState.FLYING, CtrlState.HOVERING, CtrlState.TAKING_OFF, CtrlState.LANDING):
            s |= NavState.FLYING
        s |= NavState.NAVDATA_DEMO if self._demo else NavState.NAVDATA_BOOTSTRAP
        if self._ack:
            s |= NavState.COMMAND_ACK
        if self._watchdog:
            s |= NavState.COM_WATCHDOG
        return int(s)

    def _nav_loop(self) -> None:
        c = self.config
        # wake on the normal grid (physics, watchdog) and send on it except in a burst, plus a burst's own sends
        for t_wake, send in _wakeups(c.rate, c.bursts):
            if self._stop.is_set():
                break
            t_send = self._t0 + t_wake
            if send and c.jitter:
                t_send += self.rng.uniform(0.0, c.jitter)
            delay = t_send - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            with self._lock:
                now = time.monotonic()  # (read under the lock: the state sent is the state at this time)
                if now - self._last_cmd > c.watchdog:
                    self._watchdog = True
                self._advance(now)
                if not send:
                    continue
                z_true, v = self._state_at(now - c.link_delay) if c.link_delay else (self._phys.z, self._phys.v)
                mode = self._phys.mode
                state = self._state_bits()
                client, demo_on = self._client, self._demo
            self._seq += 1
            if client is None:
                continue
            if c.loss and self.rng.random() < c.loss:
                with self._lock:
                    self._stats["navdata_dropped"] += 1
                continue
            if demo_on:
                z_meas = z_true + (self.rng.gauss(0.0, c.noise) if c.noise and mode != CtrlState.LANDED else 0.0)
                demo = Demo(ctrl_state=int(mode) << 16, battery=87, altitude_mm=int(round(1000 * max(z_meas, 0.0))),
                            vz=float(1000 * v))
                pkt = encode_navdata(state, self._seq, demo=demo)
            else:
                pkt = encode_navdata(state, self._seq)
            try:
                self._nav.sendto(pkt, client)
            except OSError:
                continue
            with self._lock:
                self._stats["navdata_sent"] += 1

    def _tcp_loop(self) -> None:
        conns: list[socket.socket] = []
        while not self._stop.is_set():
            for srv in (self._video, self._control):
                try:
                    conn, _ = srv.accept()
                    conn.settimeout(0.1)
                    conns.append(conn)
                    if srv is self._control:
                        with self._lock:
                            self._control_conn = conn
                except (socket.timeout, OSError):
                    pass
            with self._lock:
                target = self._control_conn if self._pending_config_send else None
                if target is not None:
                    text = "".join(f"{k} = {v}\n" for k, v in sorted(self._config_kv.items()))
                    self._pending_config_send = False
            if target is not None:
                try:
                    target.sendall(text.encode())
                except OSError:
                    pass
        with self._lock:
            self._control_conn = None
        for conn in conns:
            try:
                conn.close()
            except OSError:
                pass
