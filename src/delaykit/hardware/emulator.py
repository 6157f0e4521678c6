"""A built-in AR.Drone 2.0 emulator on loopback: the default "drone" on any machine.

It speaks the real protocol (:mod:`delaykit.hardware.ardrone`): AT commands on UDP ``at_port``; navdata on UDP
``navdata_port`` to whoever sent it bytes there (bootstrap packets until ``general:navdata_demo`` is set,
then demo packets at ``rate`` Hz); TCP accepted on the video and control ports (the control port answers
``AT*CTRL=<seq>,4,0`` with a configuration text).  It binds to 127.0.0.1 unless told otherwise.

The vertical motion: while flying, a progressive PCMD commands the speed ``gaz * control_vz_max``; it takes
effect ``delay`` seconds after the command arrives (the actuator delay), plus ``link_delay`` on the way in,
and the actual speed follows it through the vehicle's speed loop, ``vehicle``:

* ``"speed_loop"`` (the default): the closed second-order speed loop with a zero that delaykit identifies from
  the PX4 flights (docs/guide/identification.md),
  ``v/v_cmd = wn^2 (Tz s + 1)/(s^2 + 2 zeta wn s + wn^2)`` (``speed_wn``, ``speed_zeta``, ``speed_zero``;
  defaults wn 1.53 rad/s, zeta 2.4, Tz 3.9 s), with unit DC gain, so that ``control_vz_max`` keeps meaning the
  speed reached at ``gaz = 1`` (the PX4 fit's gain 0.79 belongs to that vehicle's own command chain, not to a
  speed loop: it is not copied);
  plus a slow coloured wander of the hovering altitude, an Ornstein-Uhlenbeck process of stationary RMS
  ``wander`` (m) and correlation time ``wander_time`` (s), drawn from its own generator seeded by ``seed`` on a
  fixed 2 ms grid from :meth:`DroneEmulator.start` (so a seed gives the same wander whatever the threads'
  timing), and added to the altitude while flying or hovering (it starts at 0 when the emulator starts);
* ``"lag"``: a first-order lag ``lag`` (s), and no wander unless ``wander`` is given: delaykit's simplest
  model, the estimator's own.

The altitude is integrated exactly between events (the command is piecewise constant: the lag's closed form, or
the closed-form step of the speed loop and the altitude, three states, ``DroneEmulator._speed_step``); the wander
is the exact discretisation of its process on its grid, held in between.  The altitude and the vertical speed in
navdata are the true ones ``link_delay`` before sending (the altitude plus Gaussian ultrasonic noise, in
millimetres; the speed is the speed loop's output: the wander, a position disturbance without a derivative, is
not in it).

Navdata packets go out every ``1 / rate`` seconds, each one late by a uniform random ``[0, jitter]`` seconds, and
dropped with probability ``loss`` (the sequence number still counts it, so a receiver sees the gap).  Take-off
climbs to 0.8 m, landing descends to the ground; the state bits follow take-off, flying, landing, emergency and
the communication watchdog (2 s without a command: hover).

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

**An acceleration limit**: ``accel_limit`` (m/s^2, 0 for none) ramps the speed command before the vehicle's
speed loop, as autopilots limit the vertical acceleration (ArduCopter's ``WPNAV_ACCEL_Z``, 1 m/s^2 by default),
held over each step of at most 2 ms.

**One physics, several protocol front ends.**  The protocol lives in a few methods that a front end overrides:
``_bind_ports`` and ``_loops`` (its sockets and threads), ``_tick`` (its watchdog or failsafe, each wake-up),
``_snapshot`` and ``_send_sample`` (a sample of the state going out: navdata here); it drives the physics with
``_cmd_takeoff``, ``_cmd_land``, ``_cmd_emergency`` and ``_cmd_speed``.  The AR.Drone's is this class;
:class:`~delaykit.hardware.emulator_mavlink.MavlinkEmulator` is MAVLink's (PX4, ArduPilot).

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
import threading
import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any

from ..errors import PortError, PortNumberError
from .ardrone import REF_EMERGENCY, REF_TAKEOFF, CtrlState, Demo, NavState, ProtocolError, encode_navdata, parse_at
from .emulator_config import _WANDER_TICK, VEHICLES, EmulatorConfig, _wakeups, check_bursts
from .stamps import enable_stamps, recv_stamped

__all__ = ["EmulatorConfig", "DroneEmulator", "PortError", "PortNumberError", "check_bursts", "VEHICLES"]

# PortError (a port that cannot be bound: an OSError, not a bad value) and PortNumberError (a port number out
# of range: a bad value) are defined in delaykit.errors and re-exported here


@dataclass
class _Physics:
    z: float = 0.0
    v: float = 0.0
    v_in: float = 0.0
    mode: int = CtrlState.LANDED
    t: float = 0.0
    pending: deque = field(default_factory=deque)
    history: deque = field(default_factory=lambda: deque(maxlen=4096))  # (t, z, v) every 2 ms
    x1: float = 0.0  # the speed loop's states (v = wn^2 (x1 + Tz x2), x1' = x2)
    x2: float = 0.0
    u: float = 0.0  # the speed command after the acceleration limit (m/s)
    w: float = 0.0  # the hover wander (m)
    wk: int = 0  # the wander's grid point (ticks since start)


class DroneEmulator:
    """The emulated drone; ``start()``/``stop()`` or use it as a context manager.

    Attributes
    ----------
    ports : dict
        The bound ports (``at``, ``navdata``, ``video``, ``control``), useful when 0 asked for free ones.
    stats : dict
        Counts (a snapshot): ``datagrams``, ``commands``, ``bad`` (rejected), ``navdata_sent``, ``navdata_dropped``,
        ``stale``, ``config_ignored`` (``AT*CONFIG`` of a key the emulated drone does not have: acknowledged, but
        neither kept nor sent back in the configuration text, as the drone ignores a key it does not know).
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
                       "stale": 0, "config_ignored": 0}
        self._t0 = time.monotonic()  # the schedule's clock: reset by start()
        self._last_error = ""
        self.kernel_stamps = False  # whether command arrivals carry the kernel's stamp (set by start())
        self._control_conn: socket.socket | None = None
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._socks: list[socket.socket] = []
        self._phys = _Physics()
        # the wander's own generator (the navdata thread draws noise, loss and jitter from self.rng)
        self._wander_rng = random.Random(None if c.seed is None else f"{c.seed}:wander")
        self._wander = c.wander_rms
        self._wander_step = (math.exp(-_WANDER_TICK / c.wander_time),
                             self._wander * math.sqrt(-math.expm1(-2.0 * _WANDER_TICK / c.wander_time)))
        self._steps: dict[float, tuple[tuple[tuple[float, ...], ...], tuple[float, ...]]] = {}  # speed loop, by dt
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
        self._takeoff_alt = self.config.takeoff_altitude

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
        vehicle: dict[str, Any] = {"kind": c.vehicle, "wander": c.wander_rms, "wander_time": c.wander_time}
        vehicle.update({"wn": c.speed_wn, "zeta": c.speed_zeta, "zero": c.speed_zero} if c.vehicle == "speed_loop"
                       else {"lag": c.lag})
        with self._lock:
            return {"ports": dict(self.ports), "stats": dict(self._stats), "last_error": self._last_error,
                    "true_delay": self.true_delay,
                    "delay_schedule": [list(p) for p in c.delay_schedule or ()],
                    "delay_trace": trace, "bursts": [list(b) for b in c.bursts], "vehicle": vehicle,
                    "accel_limit": c.accel_limit}

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
        """The true altitude now (m): the vehicle's, plus the hover wander while flying."""
        with self._lock:
            self._advance(time.monotonic())
            return self._true_z()

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
            if kind == socket.SOCK_STREAM:  # (with SO_REUSEADDR a taken TCP port fails here, not at bind)
                s.listen(4)
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
        try:
            self._bind_ports()
        except PortError:
            self.stop()
            raise
        self._phys.t = time.monotonic()
        self._last_cmd = time.monotonic()
        self._t0 = self._phys.t
        for target in self._loops():
            th = threading.Thread(target=target, daemon=True, name=f"emulator-{target.__name__}")
            th.start()
            self._threads.append(th)
        return self

    # ---- the protocol front end: what a front end of another protocol overrides -----------------------------
    def _bind_ports(self) -> None:
        """Bind the AR.Drone's ports (AT and navdata on UDP, video and control on TCP)."""
        c = self.config
        self._at = self._bind(socket.SOCK_DGRAM, c.at_port, "at")
        self._nav = self._bind(socket.SOCK_DGRAM, c.navdata_port, "navdata")
        self._video = self._bind(socket.SOCK_STREAM, c.video_port, "video")
        self._control = self._bind(socket.SOCK_STREAM, c.control_port, "control")
        for s in (self._at, self._nav):
            s.settimeout(0.05)
        self.kernel_stamps = enable_stamps(self._at)  # a command's arrival is when the kernel got it
        for s in (self._video, self._control):
            s.settimeout(0.1)

    def _loops(self) -> list:
        """The threads' targets: the physics and sampling loop first, then the front end's own."""
        return [self._at_loop, self._wake_loop, self._nav_loop, self._tcp_loop]

    def _tick(self, now: float) -> None:
        """Each wake-up of the sampling loop, under the lock, before the physics advances: the watchdog."""
        if now - self._last_cmd > self.config.watchdog:
            self._watchdog = True

    def _measure(self, z_true: float, mode: int) -> float | None:
        """The measured altitude of a sample about to go out (ultrasonic noise while airborne), or None when the
        link loses it (counted in ``stats["navdata_dropped"]``).  Draws from :attr:`rng`; outside the lock."""
        c = self.config
        if c.loss and self.rng.random() < c.loss:
            with self._lock:
                self._stats["navdata_dropped"] += 1
            return None
        return z_true + (self.rng.gauss(0.0, c.noise) if c.noise and mode != CtrlState.LANDED else 0.0)

    def _snapshot(self) -> Any:
        """The front end's state a sample needs, read under the lock (the AR.Drone's: state bits, client, demo)."""
        return self._state_bits(), self._client, self._demo

    def _send_sample(self, now: float, z_true: float, v: float, mode: int, snap: Any) -> None:
        """Send one sample (a navdata packet) of the state at ``now``; outside the lock."""
        del now  # (the AR.Drone's navdata carry no time; other front ends stamp their samples with it)
        state, client, demo_on = snap
        self._seq += 1
        if client is None:
            return
        z_meas = self._measure(z_true, mode)
        if z_meas is None:
            return
        if demo_on:
            demo = Demo(ctrl_state=int(mode) << 16, battery=87, altitude_mm=int(round(1000 * max(z_meas, 0.0))),
                        vz=float(1000 * v))
            pkt = encode_navdata(state, self._seq, demo=demo)
        else:
            pkt = encode_navdata(state, self._seq)
        try:
            self._nav.sendto(pkt, client)
        except OSError:
            return
        with self._lock:
            self._stats["navdata_sent"] += 1

    # ---- the physics' commands (under the lock) ------------------------------------------------------------
    def _cmd_takeoff(self, altitude: float | None = None) -> bool:
        """Take off (to ``altitude``, m, or the configured one) if landed; True if it began."""
        p = self._phys
        if p.mode != CtrlState.LANDED:
            return False
        if altitude is not None:
            self._takeoff_alt = altitude
        p.mode = CtrlState.TAKING_OFF
        return True

    def _cmd_land(self) -> None:
        """Begin landing (from flight, hover or take-off)."""
        p = self._phys
        if p.mode in (CtrlState.FLYING, CtrlState.HOVERING, CtrlState.TAKING_OFF):
            p.mode = CtrlState.LANDING
            p.pending.clear()

    def _cmd_emergency(self) -> None:
        """Motors off: on the ground at once."""
        p = self._phys
        if p.mode not in (CtrlState.LANDED,):
            p.mode, p.z, p.v_in = CtrlState.LANDED, 0.0, 0.0
            self._rest()
            p.pending.clear()

    def _cmd_speed(self, v: float, t: float) -> None:
        """A vertical speed command ``v`` (m/s, up) sent at ``t``: it takes effect after the link and actuator
        delays in force when it arrives; older commands it overtakes are dropped as stale."""
        p, c = self._phys, self.config
        if p.mode not in (CtrlState.FLYING, CtrlState.HOVERING):
            return
        arrive = t + c.link_delay
        ta = arrive + self.actuator_delay(arrive)
        while p.pending and p.pending[-1][0] >= ta:  # older, now stale: the newest wins
            p.pending.pop()
            self._stats["stale"] += 1
        p.pending.append((ta, v))

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
    def _true_z(self) -> float:
        """The true altitude: the vehicle's, plus the wander while flying or hovering."""
        p = self._phys
        return p.z + p.w if p.mode in (CtrlState.FLYING, CtrlState.HOVERING) else p.z

    def _rest(self) -> None:
        """The vehicle stops: speed and the speed loop's states to 0."""
        p = self._phys
        p.v = p.x1 = p.x2 = p.u = 0.0

    def _speed_step(self, dt: float) -> tuple[tuple[tuple[float, ...], ...], tuple[float, ...]]:
        """The exact step over ``dt`` of (z, x1, x2) under a held speed command u: ``s' = Phi s + Gamma u``.

        The speed loop ``wn^2 (Tz s + 1)/(s^2 + 2 zeta wn s + wn^2)`` in controllable form: ``x' = A x + b u``
        with ``A = [[0, 1], [-wn^2, -2 zeta wn]]``, ``b = (0, 1)``, speed ``v = c x``, ``c = (wn^2, wn^2 Tz)``, and
        ``z' = v``.  In closed form: ``E = exp(A dt)`` by Cayley-Hamilton, ``exp(m dt) (C I + S (A - m I))`` with
        ``m = -zeta wn``, ``q^2 = wn^2 (zeta^2 - 1)``, ``C = cosh(q dt)``, ``S = sinh(q dt) / q`` (``cos``, ``sin``
        when ``q^2 < 0``; ``1``, ``dt`` when 0), whatever the damping; then ``x -> E x + P b u`` and
        ``z -> z + c (P x + Q b u)`` with ``P = A^-1 (E - I)`` and ``Q = A^-1 (P - dt I)``, the first and second
        integrals of ``exp(A t)``.  Plain Python, no matrix library: the navdata thread calls it between packets
        (SciPy's matrix exponential stalled it for milliseconds on a loaded machine).  Cached by ``dt`` (most
        steps are the history's 2 ms).
        """
        hit = self._steps.get(dt)
        if hit is not None:
            return hit
        c = self.config
        wn, zeta, tz = c.speed_wn, c.speed_zeta, c.speed_zero
        w2 = wn * wn
        m = -zeta * wn
        q2 = w2 * (zeta * zeta - 1.0)
        if q2 > 0:
            q = math.sqrt(q2)
            ch, sh = math.cosh(q * dt), math.sinh(q * dt) / q
        elif q2 < 0:
            q = math.sqrt(-q2)
            ch, sh = math.cos(q * dt), math.sin(q * dt) / q
        else:
            ch, sh = 1.0, dt
        g = math.exp(m * dt)
        # E = g (ch I + sh (A - m I)), A - m I = [[-m, 1], [-w2, -2 zeta wn - m]]
        e00, e01 = g * (ch - sh * m), g * sh
        e10, e11 = -g * sh * w2, g * (ch + sh * (-2.0 * zeta * wn - m))

        def ainv(a: float, b: float, cc: float, d: float) -> tuple[float, float, float, float]:
            # A^-1 [[a, b], [cc, d]], A^-1 = [[-2 zeta wn, -1], [w2, 0]] / w2
            return ((-2.0 * zeta * wn * a - cc) / w2, (-2.0 * zeta * wn * b - d) / w2, a, b)

        p00, p01, p10, p11 = ainv(e00 - 1.0, e01, e10, e11 - 1.0)
        _, q01, _, q11 = ainv(p00 - dt, p01, p10, p11 - dt)
        c0, c1 = w2, w2 * tz
        step = ((1.0, c0 * p00 + c1 * p10, c0 * p01 + c1 * p11), (0.0, e00, e01), (0.0, e10, e11)), \
            (c0 * q01 + c1 * q11, p01, p11)
        if len(self._steps) > 64:  # (keep the 2 ms step; the odd remainders come and go)
            self._steps = {k: v for k, v in self._steps.items() if k == 0.002}
        self._steps[dt] = step
        return step

    def _integrate(self, dt: float) -> None:
        p, c = self._phys, self.config
        if dt <= 0:
            return
        if p.mode == CtrlState.TAKING_OFF:
            p.z = min(self._takeoff_alt, p.z + c.takeoff_speed * dt)
            p.v = c.takeoff_speed
            if p.z >= self._takeoff_alt:
                p.mode, p.v_in = CtrlState.HOVERING, 0.0
                self._rest()
                p.pending.clear()
        elif p.mode == CtrlState.LANDING:
            p.z = max(0.0, p.z - c.landing_speed * dt)
            p.v = -c.landing_speed
            p.x1 = p.x2 = 0.0
            if p.z <= 0.0:
                p.mode, p.v_in = CtrlState.LANDED, 0.0
                self._rest()
        elif p.mode in (CtrlState.FLYING, CtrlState.HOVERING):
            u = 0.0 if self._watchdog else p.v_in
            if c.accel_limit > 0:  # a ramp of the command, held over each (at most 2 ms) step
                du = c.accel_limit * dt
                u = p.u + min(max(u - p.u, -du), du)
            p.u = u
            if c.vehicle == "speed_loop":
                (a, b, d), g = self._speed_step(dt)
                z, x1, x2 = p.z, p.x1, p.x2
                p.z = a[0] * z + a[1] * x1 + a[2] * x2 + g[0] * u
                p.x1 = b[0] * z + b[1] * x1 + b[2] * x2 + g[1] * u
                p.x2 = d[0] * z + d[1] * x1 + d[2] * x2 + g[2] * u
                p.v = c.speed_wn * c.speed_wn * (p.x1 + c.speed_zero * p.x2)
            elif c.lag > 0:
                e = math.exp(-dt / c.lag)
                p.z += u * dt + (p.v - u) * c.lag * (1.0 - e)
                p.v = u + (p.v - u) * e
            else:
                p.z += u * dt
                p.v = u
            if p.z >= self._alt_max and p.v > 0:
                p.z = self._alt_max
                self._rest()
            if p.z <= 0.0:
                p.z = 0.0
                self._rest()
        else:
            self._rest()
        p.t += dt
        if self._wander > 0:
            self._wander_to(p.t)

    def _wander_to(self, t: float) -> None:
        """Advance the wander to the monotonic time ``t``: the Ornstein-Uhlenbeck process on a fixed grid of
        ``_WANDER_TICK`` seconds from :meth:`start`, exactly discretised (AR(1), ``phi = exp(-tick / T)``, one draw
        per tick, so a seed gives the same wander whatever the threads' timing), held between grid points."""
        p = self._phys
        n = math.floor((t - self._t0) / _WANDER_TICK)
        if n > p.wk:
            phi, scale = self._wander_step
            rng = self._wander_rng
            w = p.w
            for _ in range(n - p.wk):
                w = phi * w + scale * rng.gauss(0.0, 1.0)
            p.w, p.wk = w, n

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
            p.history.append((p.t, self._true_z(), p.v))
        self._integrate(t - p.t)
        p.history.append((p.t, self._true_z(), p.v))

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
        return (h[0][1], h[0][2]) if h else (self._true_z(), self._phys.v)

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
        with self._lock:
            self._stats["datagrams"] += 1
            self._advance(max(t, self._phys.t))  # t is the kernel's arrival stamp: the physics may be past it
            self._last_cmd = t
            for cmd in cmds:
                self._stats["commands"] += 1
                if cmd.name == "REF":
                    bits = cmd.args[0]
                    if bits & REF_EMERGENCY:
                        self._cmd_emergency()
                    elif bits & REF_TAKEOFF:
                        self._cmd_takeoff()
                    else:
                        self._cmd_land()
                elif cmd.name in ("PCMD", "PCMD_MAG"):
                    flag = cmd.args[0]
                    gaz = cmd.floats(3, 4)[0]
                    self._cmd_speed(gaz * self._vz_max if flag & 1 else 0.0, t)
                elif cmd.name == "COMWDG":
                    self._watchdog = False
                elif cmd.name == "CONFIG":
                    key, value = cmd.args
                    self._ack = True  # (acknowledged, as the drone does, whatever the key)
                    if key not in self._config_kv:  # a key the drone does not have: ignored, neither kept nor echoed
                        self._stats["config_ignored"] += 1
                        self._last_error = f"unknown configuration key {key!r} ignored"
                        continue
                    if key == "general:navdata_demo":
                        self._demo = value.upper() == "TRUE"
                        value = "TRUE" if self._demo else "FALSE"
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
                            value = str(int(round(1000 * x)))  # what the drone keeps: the value it uses
                        else:
                            self._stats["bad"] += 1
                            self._last_error = f"{key} must be a finite number of millimetres, got {value!r}"
                            continue
                    self._config_kv[key] = value
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
                self._tick(now)
                self._advance(now)
                if not send:
                    continue
                z_true, v = self._state_at(now - c.link_delay) if c.link_delay else (self._true_z(), self._phys.v)
                mode = self._phys.mode
                snap = self._snapshot()
            self._send_sample(now, z_true, v, mode, snap)

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
