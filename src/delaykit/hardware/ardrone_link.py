"""The AR.Drone 2.0 link: AT commands out, navdata in, on UDP (a :class:`~delaykit.hardware.link.VehicleLink`).

Start-up: wake the navdata stream, ask for demo packets, acknowledge, set ``control:control_vz_max`` so that
``gaz`` is the command in m/s (and ``control:altitude_max``); take-off: flat trim, then the take-off bit until the
drone says it hovers (15 s at most); each velocity command is a progressive PCMD, with a watchdog reset every
0.5 s; landing: hover and the landing bit until the drone says it landed.  Navdata carries no time stamp: the
samples' ``vehicle_time`` is None; their arrival is the kernel's (:mod:`~delaykit.hardware.stamps`).

The link binds to an ephemeral local port and talks to ``host``; for the emulator that is 127.0.0.1.

Examples
--------
>>> link = DroneLink("127.0.0.1", 5556, 5554)
>>> link.name, link.has_vehicle_time
('AR.Drone at 127.0.0.1', False)
>>> link.close()
"""

from __future__ import annotations

import ipaddress
import socket
import time
from typing import Callable

from ..errors import InvalidValueError
from .ardrone import ATEncoder, CtrlState, Navdata, NavState, ProtocolError, decode_navdata
from .emulator_config import _check_port, _resolve_ipv4
from .link import AltitudeSample, LinkError, VehicleLink
from .stamps import enable_stamps, recv_stamped

__all__ = ["DroneLink", "VZ_MAX_LIMIT"]

VZ_MAX_LIMIT = 2.0  # m/s: control:control_vz_max accepts at most 2000 mm/s


class DroneLink(VehicleLink):
    """UDP sockets to an AR.Drone 2.0: AT commands out, navdata in (decoded; malformed packets counted and kept in
    :attr:`rejections`)."""

    sample_name = "navdata"

    def __init__(self, host: str, at_port: int = 5556, navdata_port: int = 5554) -> None:
        super().__init__()
        self.host = host = _resolve_ipv4("host", host)
        self.name = f"AR.Drone at {host}"
        self.at_port = _check_port("at_port", at_port)
        self.navdata_port = _check_port("navdata_port", navdata_port)
        if at_port == 0 or navdata_port == 0:
            raise InvalidValueError("the drone's ports must be given (not 0)")
        try:
            self.at = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.nav = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.nav.bind(("127.0.0.1" if ipaddress.ip_address(host).is_loopback else "0.0.0.0", 0))
        except OSError as exc:
            self.close()
            raise LinkError(f"cannot open the sockets to talk to {host}: {exc.strerror or exc}") from None
        # a packet's time is its arrival in the kernel, not when this thread woke to read it
        self.kernel_stamps = enable_stamps(self.nav)
        self.enc = ATEncoder()
        self.vz_max = 1.0
        self._last_wdg = 0.0

    # ---- the protocol ------------------------------------------------------------------------------------
    def send(self, *cmds: bytes) -> float:
        """Send AT commands in one datagram; returns the time (monotonic) it went out."""
        try:
            self.at.sendto(b"".join(cmds), (self.host, self.at_port))
        except OSError as exc:
            raise self._failed("send AT commands to", self.at_port, exc) from None
        return time.monotonic()

    def wake(self) -> None:
        """Ask the drone to stream navdata to this socket."""
        try:
            self.nav.sendto(b"\x01\x00\x00\x00", (self.host, self.navdata_port))
        except OSError as exc:
            raise self._failed("wake navdata from", self.navdata_port, exc) from None

    def _failed(self, what: str, port: int, exc: OSError) -> LinkError:
        """The :class:`LinkError` for a socket's failure (the network unreachable, the port refused...)."""
        return LinkError(f"cannot {what} {self.host}:{port}: {exc.strerror or exc}")

    def recv_navdata(self, timeout: float) -> tuple[Navdata, float] | None:
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
            except OSError as exc:  # an ICMP error of an earlier datagram (port unreachable: refused)
                raise self._failed("receive navdata from", self.navdata_port, exc) from None
            if addr[0] != self.host:
                continue
            try:
                return decode_navdata(data), t
            except ProtocolError as exc:
                self._reject(str(exc))

    # ---- the vehicle-link interface ------------------------------------------------------------------------
    def connect(self, timeout: float, *, vmax: float, z_max: float,
                status: Callable[[str], None] | None = None) -> None:
        """Wake navdata, switch to demo packets, set the speed and altitude limits (see the module docstring)."""
        say = status or (lambda _m: None)
        enc = self.enc
        say(f"waking navdata from {self.host}:{self.navdata_port}")
        got = None
        deadline = time.monotonic() + timeout
        while got is None and time.monotonic() < deadline:
            self.wake()
            got = self.recv_navdata(0.3)
        if got is None:
            raise LinkError(f"no navdata from {self.host}:{self.navdata_port} within {timeout:g} s: is the drone (or "
                            "`delaykit emulate`) there, on those ports? Nothing was flown")
        self.vz_max = max(vmax, 1.0)
        deadline = time.monotonic() + timeout
        nd = got[0]
        while not nd.has(NavState.NAVDATA_DEMO) or nd.demo is None:
            if time.monotonic() > deadline:
                raise LinkError(f"{self.host} does not switch to demo navdata; nothing was flown")
            self.send(enc.config("general:navdata_demo", "TRUE"), enc.ctrl(5, 0))
            r = self.recv_navdata(0.3)
            if r:
                nd = r[0]
        self.send(enc.config("control:control_vz_max", str(int(round(1000 * self.vz_max)))))
        self.send(enc.config("control:altitude_max", str(int(round(1000 * max(z_max + 0.5, 3.0))))), enc.ctrl(5, 0))

    def takeoff(self, timeout: float, status: Callable[[str], None] | None = None) -> None:
        """Flat trim, then the take-off bit until the drone hovers."""
        (status or (lambda _m: None))(f"flat trim and take-off of {self.name}")
        enc = self.enc
        self.send(enc.ftrim())
        deadline = time.monotonic() + timeout
        while True:
            self.send(enc.ref(takeoff=True), enc.comwdg())
            r = self.recv_navdata(0.25)
            if r and r[0].demo and r[0].demo.major in (CtrlState.HOVERING, CtrlState.FLYING):
                return
            if time.monotonic() > deadline:
                raise LinkError(f"{self.host} did not reach a hover within {timeout:g} s of take-off")

    def send_velocity(self, vz: float) -> float:
        """A progressive PCMD for ``vz`` m/s (``gaz = vz / control_vz_max``), with a watchdog reset every 0.5 s."""
        cmds = [self.enc.pcmd(gaz=vz / self.vz_max)]
        now = time.monotonic()
        if now - self._last_wdg > 0.5:
            cmds.append(self.enc.comwdg())
            self._last_wdg = now
        return self.send(*cmds)

    def hold(self) -> float:
        """A hover PCMD (not progressive) and a watchdog reset."""
        return self.send(self.enc.pcmd(progressive=False), self.enc.comwdg())

    def recv(self, timeout: float) -> AltitudeSample | None:
        """The next navdata packet with demo data, as a sample (no vehicle time), or None on timeout."""
        deadline = time.monotonic() + timeout
        while True:
            r = self.recv_navdata(deadline - time.monotonic())
            if r is None:
                return None
            nd, t = r
            if nd.demo is not None:
                return AltitudeSample(nd.demo.altitude_mm / 1000.0, nd.demo.vz / 1000.0, None, t, nd.sequence)

    def land(self, timeout: float) -> bool:
        """Hover and send the landing bit until the drone says it landed."""
        enc = self.enc
        t_land = time.monotonic()
        while time.monotonic() - t_land < timeout:
            self.send(enc.pcmd(progressive=False), enc.ref(takeoff=False), enc.comwdg())
            r = self.recv_navdata(0.2)
            if r and r[0].demo and r[0].demo.major == CtrlState.LANDED:
                return True
        return False

    def close(self) -> None:
        """Close the sockets (those that were opened)."""
        for sock in (getattr(self, "at", None), getattr(self, "nav", None)):
            if sock is not None:
                sock.close()
