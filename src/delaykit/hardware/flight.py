"""Flying an AR.Drone 2.0 (or the built-in emulator): the link, and the real-time altitude loop.

:func:`fly` does what the paper's Simulink set-up did:

1. navdata start-up: wake the navdata stream, ask for demo packets, acknowledge, set
   ``control:control_vz_max`` so that ``gaz`` is the command in m/s;
2. flat trim, take-off, and a steady hover (its mean altitude is the first reference);
3. the steps in ``z_ref``; for each navdata packet the command
   ``u = sat(Kp (z_ref - z) - Kv w, vmax)`` (``w`` the navdata vertical speed, or the derivative filter of
   the altitude) is sent at once as a progressive PCMD; a watchdog reset goes out every 0.5 s;
4. hover and land.

Each step is logged to its own CSV (``t, z, z_ref, u, vz, seq, recv_time, latency_ms``; from one second
before the step), flushed every line so a crash loses nothing; ``delaykit estimate`` reads them as they are.
Ctrl-C, a navdata gap longer than ``gap_timeout``, or an altitude outside ``[z_min, z_max]`` makes it hover and
land at once, and the result says why.  The command never leaves ``±vmax``.  The loop's own latency (packet
received to command sent) is measured and reported (median and 99th percentile).

The link binds to an ephemeral local port and talks to ``host``; for the emulator that is 127.0.0.1.
"""

from __future__ import annotations

import ipaddress
import math
import socket
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import DelaykitError, InvalidValueError, check_real
from .ardrone import ATEncoder, CtrlState, NavState, Navdata, ProtocolError, decode_navdata
from .emulator import _check_port
from .stamps import enable_stamps, recv_stamped

__all__ = ["LinkError", "DroneLink", "FlightPlan", "FlightResult", "fly"]

VZ_MAX_LIMIT = 2.0  # m/s: control:control_vz_max accepts at most 2000 mm/s


class LinkError(DelaykitError, RuntimeError):
    """The drone does not answer (no navdata), so nothing flies."""


class DroneLink:
    """UDP sockets to a drone: AT commands out, navdata in (decoded; malformed packets counted and logged)."""

    def __init__(self, host: str, at_port: int = 5556, navdata_port: int = 5554) -> None:
        try:
            ipaddress.ip_address(host)
        except ValueError:
            try:
                host = socket.gethostbyname(host)
            except OSError:
                raise InvalidValueError(f"host {host!r} is not an address and cannot be resolved") from None
        self.host = host
        self.at_port = _check_port("at_port", at_port)
        self.navdata_port = _check_port("navdata_port", navdata_port)
        if at_port == 0 or navdata_port == 0:
            raise InvalidValueError("the drone's ports must be given (not 0)")
        self.at = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.nav = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.nav.bind(("127.0.0.1" if ipaddress.ip_address(host).is_loopback else "0.0.0.0", 0))
        # a packet's time is its arrival in the kernel, not when this thread woke to read it
        self.kernel_stamps = enable_stamps(self.nav)
        self.enc = ATEncoder()
        self.rejected = 0
        self.rejections: list[str] = []

    def send(self, *cmds: bytes) -> float:
        """Send commands in one datagram; returns the time (monotonic) it went out."""
        self.at.sendto(b"".join(cmds), (self.host, self.at_port))
        return time.monotonic()

    def wake(self) -> None:
        """Ask the drone to stream navdata to this socket."""
        self.nav.sendto(b"\x01\x00\x00\x00", (self.host, self.navdata_port))

    def recv(self, timeout: float) -> tuple[Navdata, float] | None:
        """The next valid navdata packet from the drone and its arrival time, or None on timeout."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self.nav.settimeout(left)
            try:
                data, addr, t = recv_stamped(self.nav, 4096)
            except socket.timeout:
                return None
            if addr[0] != self.host:
                continue
            try:
                return decode_navdata(data), t
            except ProtocolError as exc:
                self.rejected += 1
                if len(self.rejections) < 100:
                    self.rejections.append(str(exc))

    def close(self) -> None:
        self.at.close()
        self.nav.close()


@dataclass(frozen=True)
class FlightPlan:
    """What to fly: the controller and the steps.

    Parameters
    ----------
    kp, kv : float
        Gains (m/s per m, and dimensionless).
    velocity : {"true", "filtered"}
        The Kv term's velocity: the navdata vertical speed, or the derivative filter of the altitude.
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

    def __post_init__(self) -> None:
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
        if not self.z_min < self.z_max:
            raise InvalidValueError(f"z_min must be below z_max, got {self.z_min:g} and {self.z_max:g}")


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

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"logs": [str(p) for p in self.logs], "reason": self.reason, "completed": self.completed,
                "packets": self.packets, "rejected": self.rejected, "latency_median_ms": self.latency_median_ms,
                "latency_p99_ms": self.latency_p99_ms, "packet_interval": self.packet_interval,
                "events": list(self.events)}

    def __repr__(self) -> str:
        lat = "" if self.latency_median_ms is None else f", latency {self.latency_median_ms:.3f} ms median"
        return f"FlightResult({self.reason}, {len(self.logs)} logs, {self.packets} packets{lat})"


class _Filter:
    """The derivative filter wf^2 s / (s^2 + 2 zf wf s + wf^2) on the altitude, advanced exactly per packet over the
    time since the previous one, with the newest altitude held over that interval (its first output, when it
    starts at rest on the first altitude, is 0).

    The step uses the closed form of ``exp(A dt)`` for a 2 x 2 matrix (by Cayley-Hamilton,
    ``e^{m dt} [(cosh(d dt) - m sinh(d dt) / d) I + sinh(d dt) / d A]`` with ``m`` half the trace and
    ``d^2 = m^2 - det A``), so every interval is exact, whatever its length, at a few microseconds a packet."""

    def __init__(self, wn: float, zeta: float) -> None:
        self.A = np.array([[0.0, 1.0], [-wn * wn, -2 * zeta * wn]])
        self.wn2 = wn * wn
        self.m = -zeta * wn
        self.d = complex(self.m * self.m - self.wn2) ** 0.5  # imaginary when underdamped, 0 when critical
        self.x: np.ndarray | None = None

    def _step(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(Ad, Bd)``: the state transition over ``dt`` and the response to a unit input held over it."""
        dd = self.d * dt
        if abs(dd) < 1e-6:  # sinh(dd) / d and cosh(dd) to O(dd^4)
            sh, ch = dt * (1.0 + dd * dd / 6.0), 1.0 + dd * dd / 2.0
        else:
            sh, ch = np.sinh(dd) / self.d, np.cosh(dd)
        e = math.exp(self.m * dt)
        Ad = e * ((ch - self.m * sh).real * np.eye(2) + sh.real * self.A)
        # B = (0, 1): the held input's response is A^-1 (Ad - I) B
        Bd = np.linalg.solve(self.A, Ad[:, 1] - np.array([0.0, 1.0]))
        return Ad, Bd

    def update(self, z: float, dt: float) -> float:
        if self.x is None:
            self.x = np.array([z / self.wn2, 0.0])
            return 0.0
        Ad, Bd = self._step(dt)
        self.x = Ad @ self.x + Bd * z
        return float(self.wn2 * self.x[1])


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
) -> FlightResult:
    """Fly the plan against the drone at ``host`` and log every navdata packet (see the module docstring).

    Raises
    ------
    LinkError
        No navdata within ``connect_timeout`` seconds (nothing is flown).
    """
    say = status or (lambda _m: None)
    check_real("connect_timeout (s)", connect_timeout, minimum=0.0, strict=True)
    base = Path(log)
    base.parent.mkdir(parents=True, exist_ok=True)
    link = DroneLink(host, at_port, navdata_port)
    enc = link.enc
    events: list[str] = []
    logs: list[Path] = []
    latencies: list[float] = []
    arrivals: list[float] = []
    packets = 0
    reason, completed = "completed", True
    airborne = False
    try:
        # 1. navdata start-up
        say(f"waking navdata from {host}:{navdata_port}")
        got = None
        deadline = time.monotonic() + connect_timeout
        while got is None and time.monotonic() < deadline:
            link.wake()
            got = link.recv(0.3)
        if got is None:
            raise LinkError(f"no navdata from {host}:{navdata_port} within {connect_timeout:g} s: is the drone (or "
                            "`delaykit emulate`) there, on those ports? Nothing was flown")
        vz_max = max(plan.vmax, 1.0)
        deadline = time.monotonic() + connect_timeout
        nd = got[0]
        while not nd.has(NavState.NAVDATA_DEMO) or nd.demo is None:
            if time.monotonic() > deadline:
                raise LinkError(f"{host} does not switch to demo navdata; nothing was flown")
            link.send(enc.config("general:navdata_demo", "TRUE"), enc.ctrl(5, 0))
            r = link.recv(0.3)
            if r:
                nd = r[0]
        link.send(enc.config("control:control_vz_max", str(int(round(1000 * vz_max)))))
        link.send(enc.config("control:altitude_max", str(int(round(1000 * max(plan.z_max + 0.5, 3.0))))),
                  enc.ctrl(5, 0))
        if confirm is not None and not confirm():
            return FlightResult((), "not confirmed: no take-off", False, 0, link.rejected, None, None, None, tuple(events))
        # 2. take-off and hover
        say("take-off")
        link.send(enc.ftrim())
        airborne = True
        deadline = time.monotonic() + 15.0
        nd = None
        while True:
            link.send(enc.ref(takeoff=True), enc.comwdg())
            r = link.recv(0.25)
            if r:
                nd = r[0]
                if nd.demo and nd.demo.major in (CtrlState.HOVERING, CtrlState.FLYING):
                    break
            if time.monotonic() > deadline:
                raise LinkError(f"{host} did not reach a hover within 15 s of take-off")
        say("hovering")
        hover: list[tuple[float, float, float, int]] = []
        t_start = time.monotonic()
        while time.monotonic() - t_start < plan.hover_time:
            link.send(enc.pcmd(progressive=False), enc.comwdg())
            r = link.recv(plan.gap_timeout)
            if r and r[0].demo:
                hover.append((r[1], r[0].demo.altitude_mm / 1000.0, r[0].demo.vz / 1000.0, r[0].sequence))
        half = [z for t, z, _, _ in hover if t >= t_start + plan.hover_time / 2] or [z for _, z, _, _ in hover]
        z_ref = float(np.mean(half)) if half else (nd.demo.altitude_mm / 1000.0 if nd and nd.demo else 0.8)
        # 3. the steps; the log of each starts a second before its step (the hover, for the first)
        flt = _Filter(plan.filter_wn, plan.filter_zeta) if plan.velocity == "filtered" else None
        # (arrival time, row) of the last second, for the next log's start
        recent: deque = deque((t, f"{t - t_start:.6f},{z:.3f},{z_ref:.6f},0.000000,{vz:.6f},{sq},{t:.6f},0.0000\n")
                              for t, z, vz, sq in hover if t >= hover[-1][0] - 1.0) if hover else deque()
        last_wdg = 0.0
        t_prev = None
        for k, step in enumerate(plan.steps):
            path = _log_path(base, k, len(plan.steps))
            logs.append(path)
            fh = open(path, "w", buffering=1)
            fh.write(",".join(_COLUMNS) + "\n")
            for _, row in recent:  # the second before the step
                fh.write(row)
            fh.flush()
            z_ref += step
            say(f"step {k + 1}/{len(plan.steps)}: z_ref = {z_ref:.3f} m")
            t_step = time.monotonic()
            try:
                while time.monotonic() - t_step < plan.step_duration:
                    r = link.recv(plan.gap_timeout)
                    if r is None:
                        raise _Abort(f"navdata gap longer than {plan.gap_timeout:g} s")
                    nd, t_recv = r
                    if nd.demo is None:
                        continue
                    z = nd.demo.altitude_mm / 1000.0
                    if not plan.z_min <= z <= plan.z_max:
                        raise _Abort(f"altitude {z:.3f} m outside the bounds [{plan.z_min:g}, {plan.z_max:g}] m")
                    dt = (t_recv - t_prev) if t_prev is not None else 1.0 / 15
                    t_prev = t_recv
                    w = flt.update(z, dt) if flt else nd.demo.vz / 1000.0
                    u = plan.kp * (z_ref - z) - plan.kv * w
                    u = min(max(u, -plan.vmax), plan.vmax)
                    cmds = [enc.pcmd(gaz=u / vz_max)]
                    if t_recv - last_wdg > 0.5:
                        cmds.append(enc.comwdg())
                        last_wdg = t_recv
                    t_sent = link.send(*cmds)
                    lat = 1e3 * (t_sent - t_recv)
                    latencies.append(lat)
                    arrivals.append(t_recv)
                    packets += 1
                    row = (f"{t_recv - t_start:.6f},{z:.3f},{z_ref:.6f},{u:.6f},{nd.demo.vz / 1000.0:.6f},"
                           f"{nd.sequence},{t_recv:.6f},{lat:.4f}\n")
                    fh.write(row)
                    recent.append((t_recv, row))
                    while recent and t_recv - recent[0][0] > 1.0:
                        recent.popleft()
            finally:
                fh.close()
    except _Abort as exc:
        reason, completed = str(exc), False
        events.append(reason)
    except KeyboardInterrupt:
        reason, completed = "interrupted (Ctrl-C)", False
        events.append(reason)
    finally:
        # 4. hover and land, whatever happened (if a take-off was begun)
        try:
            say("landing" if airborne else "no take-off")
            t_land = time.monotonic()
            while airborne and time.monotonic() - t_land < 8.0:
                link.send(enc.pcmd(progressive=False), enc.ref(takeoff=False), enc.comwdg())
                r = link.recv(0.2)
                if r and r[0].demo and r[0].demo.major == CtrlState.LANDED:
                    break
        except OSError:
            pass
        link.close()
    lat = np.array(latencies)
    iv = float(np.median(np.diff(arrivals))) if len(arrivals) > 2 else None
    return FlightResult(tuple(logs), reason, completed, packets, link.rejected,
                        float(np.median(lat)) if lat.size else None,
                        float(np.percentile(lat, 99)) if lat.size else None, iv, tuple(events + link.rejections[:5]))


class _Abort(Exception):
    pass
