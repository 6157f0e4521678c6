"""The Tello link: a DJI/Ryze Tello (or the emulator's Tello front end) over its text SDK 2.0/3.0 on UDP.

:class:`TelloLink` is a :class:`~delaykit.hardware.link.VehicleLink`.  The SDK is text: commands go to the
drone's UDP port 8889 and are answered ``ok`` or ``error`` (an ``rc`` command is not answered); the drone streams
its state, one line of ``key:value;`` fields, to the PC's UDP port 8890 at about 10 Hz.

* **Connect**: ``command`` (enter SDK mode), resent every ``reply_timeout`` s until it is answered, within the
  connect timeout; ``error`` refuses (:class:`~delaykit.hardware.link.VehicleRefusedError`).  Then the first state
  line must arrive.
* **Take-off**: ``takeoff``, answered once the drone hovers (the link waits for the answer, reading the state
  meanwhile so that the hover starts from fresh samples); ``error`` (a low battery, a hot drone) refuses, with the
  drone's words.
* **Flying**: each command is ``rc 0 0 c 0`` with ``c = clip(round(v / speed_per_percent), -100, 100)``: the rc
  "sticks" are percentages, and ``speed_per_percent`` (m/s per percent, default 0.01) maps them to a vertical
  speed.  It is a parameter, not a published constant: a flight's log measures it, since the plant it shows
  (the commanded m/s in, the altitude out) has the gain ``true / assumed`` m/s per percent.  The drone keeps the
  last rc values itself.
* **Keep-alive**: the Tello lands by itself after 15 s without a command; a thread resends the last ``rc``
  whenever none went out for ``1 / keepalive`` s (default 1 Hz), so it stays up while the loop hovers to
  estimate.
* **Samples**: the altitude is ``tof`` by default: the downward time-of-flight sensor, in cm, the distance to the
  floor below, as the AR.Drone's ultrasonic altitude is.  ``h`` (``altitude="h"``) is the drone's own height
  above its take-off point, also in cm, but its ``height?`` query answers in decimetres, and in the emulator ``h``
  moves in 10 cm steps: too coarse to see a loop's detail.  ``baro`` (m) is the barometer's absolute altitude,
  which drifts.  The vertical speed is ``vgz`` in cm/s, taken as up positive (the SDK guides give neither its
  unit nor its sign: check it on a real drone before flying a law on it, or use ``--velocity filtered``).
  The state's ``time`` field is the motors' running time in whole seconds, not a clock: the samples' vehicle time
  is None; their arrival is the kernel's (:mod:`~delaykit.hardware.stamps`), as on the AR.Drone link.
* **Land**: ``rc 0 0 0 0``, then ``land`` (resent every 2 s) until it is answered ``ok``; False after
  ``timeout`` s, or after a second without state (the link lost: the drone's own 15 s timeout lands it).

State lines that do not parse (not text, no altitude field, a field that is not a number) and replies that are
neither ``ok`` nor ``error`` are ignored and counted (:attr:`TelloLink.counts`, ``rejected`` in a flight's
result).

The link sends only to ``host``; on loopback its sockets bind to 127.0.0.1, and ``state_port=0`` binds any free
port (the emulator is then told where to send, its ``state_port``), so tests need no fixed ports.

Examples
--------
>>> link = TelloLink("127.0.0.1", command_port=8889, state_port=0)
>>> link.name, link.has_vehicle_time, link.sample_name
('Tello at 127.0.0.1', False, 'state')
>>> rc_command(0.25, 0.01), rc_command(-3.0, 0.01)
('rc 0 0 25 0', 'rc 0 0 -100 0')
>>> parse_state(b"pitch:0;roll:0;yaw:0;vgx:0;vgy:0;vgz:-12;tof:83;h:80;bat:87;baro:101.25;time:3;")["tof"]
83.0
>>> link.close()
"""

from __future__ import annotations

import ipaddress
import math
import select
import socket
import threading
import time
from typing import Any, Callable

from ..errors import InvalidValueError, check_real
from .emulator_config import _check_port, _resolve_ipv4
from .link import AltitudeSample, KeepAlive, LinkError, VehicleLink, VehicleRefusedError
from .stamps import enable_stamps, recv_stamped

__all__ = ["TelloLink", "parse_state", "rc_command", "ALTITUDE_SOURCES", "TELLO_HOST", "SPEED_PER_PERCENT"]

#: the Tello's address on its own Wi-Fi
TELLO_HOST = "192.168.10.1"
#: the default map from rc percent to vertical speed, m/s per percent (a parameter: identify it from a flight)
SPEED_PER_PERCENT = 0.01
#: the state fields the altitude can come from
ALTITUDE_SOURCES = ("tof", "h")


def parse_state(data: bytes) -> dict[str, Any]:
    """One state line as a dict: numbers as floats, ``mpry`` (``x,y,z``) kept as text.

    Raises
    ------
    InvalidValueError
        When the datagram is not ASCII text of ``key:value;`` fields, or a numeric field is not a finite number.

    Examples
    --------
    >>> parse_state(b"mid:-1;x:0;mpry:0,0,0;h:120;tof:118;\\r\\n")
    {'mid': -1.0, 'x': 0.0, 'mpry': '0,0,0', 'h': 120.0, 'tof': 118.0}
    """
    try:
        text = data.decode("ascii").strip()
    except UnicodeDecodeError:
        raise InvalidValueError(f"a state datagram that is not ASCII text ({len(data)} bytes)") from None
    out: dict[str, Any] = {}
    for field in text.split(";"):
        if not field.strip():
            continue
        key, sep, value = field.partition(":")
        key = key.strip()
        if not sep or not key:
            raise InvalidValueError(f"a state field {field[:40]!r} is not key:value")
        if key == "mpry":
            out[key] = value
            continue
        try:
            x = float(value)
        except ValueError:
            raise InvalidValueError(f"state field {key} = {value[:20]!r} is not a number") from None
        if not math.isfinite(x):
            raise InvalidValueError(f"state field {key} = {value[:20]!r} is not finite")
        out[key] = x
    if not out:
        raise InvalidValueError("an empty state datagram")
    return out


def rc_command(vz: float, speed_per_percent: float) -> str:
    """The ``rc`` command for a vertical speed ``vz`` (m/s, up positive): throttle ``clip(round(vz / spp))``.

    Examples
    --------
    >>> rc_command(0.126, 0.01), rc_command(0.0, 0.01)
    ('rc 0 0 13 0', 'rc 0 0 0 0')
    """
    c = vz / speed_per_percent
    c = 0 if not math.isfinite(c) else max(-100, min(100, int(round(c))))
    return f"rc 0 0 {c} 0"


class TelloLink(VehicleLink):
    """A Tello over its SDK (see the module docstring).

    Parameters
    ----------
    host : str
        The drone (192.168.10.1 on its Wi-Fi; the emulator: 127.0.0.1).
    command_port : int
        The drone's command port (8889).
    state_port : int
        The local port the state arrives on (8890, where the Tello sends it; 0: any free one, for the emulator).
    speed_per_percent : float
        m/s per rc percent (the throttle's map to a vertical speed).
    altitude : {"tof", "h"}
        The state field that gives the altitude (``tof``, the default: see the module docstring).
    reply_timeout : float
        How long to wait for an answer before sending a command again, s.
    keepalive : float
        The least command rate, Hz (the last rc resent when the loop is quiet; the Tello lands after 15 s).
    """

    has_vehicle_time = False
    sample_name = "state"

    def __init__(self, host: str = TELLO_HOST, *, command_port: int = 8889, state_port: int = 8890,
                 speed_per_percent: float = SPEED_PER_PERCENT, altitude: str = "tof", reply_timeout: float = 1.0,
                 keepalive: float = 1.0) -> None:
        super().__init__()
        self.host = host = _resolve_ipv4("host", host)
        self.name = f"Tello at {host}"
        self.command_port = _check_port("command_port", command_port)
        if command_port == 0:
            raise InvalidValueError("the Tello's command port must be given (not 0; the Tello's is 8889)")
        self.state_port = _check_port("state_port", state_port)
        self.speed_per_percent = check_real("speed_per_percent (m/s per percent)", speed_per_percent, minimum=0.0,
                                            maximum=0.1, strict=True)
        if altitude not in ALTITUDE_SOURCES:
            raise InvalidValueError(f"altitude must be one of {', '.join(ALTITUDE_SOURCES)} (the state field), got "
                                    f"{altitude!r}")
        self.altitude = altitude
        self.reply_timeout = check_real("reply_timeout (s)", reply_timeout, minimum=0.05, maximum=30.0)
        self.keepalive = check_real("keepalive (Hz)", keepalive, minimum=0.1, maximum=50.0)
        self.counts = {"garbage": 0, "bad_replies": 0, "other_sender": 0}
        self._tx = threading.Lock()
        self._last_rc = "rc 0 0 0 0"
        self._last_tx = 0.0
        self._keeper = KeepAlive("tello-keepalive", 1.0 / self.keepalive, lambda: self._last_tx,
                                 lambda: self.send(self._last_rc), poll=0.25)
        self._seq = 0
        self._t_state = 0.0  # arrival of the last valid state line
        local = "127.0.0.1" if ipaddress.ip_address(host).is_loopback else "0.0.0.0"
        self.cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.state = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.cmd.bind((local, 0))
            self.state.bind((local, state_port))
        except OSError as exc:
            self.close()
            raise LinkError(f"cannot listen for the Tello's state on {local}:{state_port}: {exc.strerror} (is "
                            "another Tello program running?)") from None
        self.state_port = self.state.getsockname()[1]
        self.kernel_stamps = enable_stamps(self.state)

    # ---- the protocol ----------------------------------------------------------------------------------------
    def send(self, text: str) -> float:
        """Send one SDK command; returns the monotonic time it went out."""
        with self._tx:
            try:
                self.cmd.sendto(text.encode("ascii"), (self.host, self.command_port))
            except OSError as exc:
                raise LinkError(f"cannot send to {self.name}: {exc.strerror}") from None
            self._last_tx = time.monotonic()
            return self._last_tx

    def _drain_replies(self) -> None:
        """Forget answers that arrived late (to an earlier try)."""
        self.cmd.setblocking(False)
        try:
            while True:
                self.cmd.recvfrom(1024)
        except (BlockingIOError, OSError):
            pass
        finally:
            self.cmd.setblocking(True)

    def _reply(self, timeout: float) -> str | None:
        """The next answer from the drone (``ok``, ``error ...``, or a read command's value), or None on timeout;
        reads the state meanwhile (so that it does not queue up)."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            ready, _, _ = select.select([self.cmd, self.state], [], [], left)
            if self.state in ready:
                self._read_state(0.0)
            if self.cmd not in ready:
                continue
            try:
                data, addr = self.cmd.recvfrom(1024)
            except OSError:
                continue
            if addr[0] != self.host:
                self.counts["other_sender"] += 1
                self._reject(f"a reply from {addr[0]}, not the Tello at {self.host}")
                continue
            try:
                text = data.decode("ascii").strip()
            except UnicodeDecodeError:
                text = ""
            if not text or not text.isprintable():
                self.counts["bad_replies"] += 1
                self._reject(f"a reply that is not text ({len(data)} bytes)")
                continue
            return text

    def request(self, text: str, timeout: float, *, resend: float | None = None) -> str | None:
        """Send ``text`` and return the answer, resending every ``resend`` s (default: ``reply_timeout``) until
        ``timeout``; None if nothing answered."""
        resend = self.reply_timeout if resend is None else resend
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            self._drain_replies()
            self.send(text)
            answer = self._reply(min(resend, left))
            if answer is not None:
                return answer

    def _read_state(self, timeout: float) -> AltitudeSample | None:
        """The next valid state line from the drone as a sample, or None after ``timeout`` s."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            self.state.settimeout(max(left, 0.0) if left > 0 else 0.0)
            try:
                data, addr, t = recv_stamped(self.state, 2048)
            except (socket.timeout, BlockingIOError):
                return None
            except OSError as exc:
                raise LinkError(f"the state socket of {self.name} failed: {exc.strerror}") from None
            if addr[0] != self.host:
                self.counts["other_sender"] += 1
                self._reject(f"state from {addr[0]}, not the Tello at {self.host}")
                continue
            try:
                st = parse_state(data)
                z_cm = st[self.altitude]
            except InvalidValueError as exc:
                self.counts["garbage"] += 1
                self._reject(str(exc))
                continue
            except KeyError:
                self.counts["garbage"] += 1
                self._reject(f"a state line without {self.altitude}")
                continue
            self._seq += 1
            self._t_state = t
            return AltitudeSample(z_cm / 100.0, st.get("vgz", 0.0) / 100.0, None, t, self._seq)

    # ---- the vehicle-link interface --------------------------------------------------------------------------
    def connect(self, timeout: float, *, vmax: float, z_max: float,
                status: Callable[[str], None] | None = None) -> None:
        """``command`` until answered, then the first state line (see the module docstring)."""
        del z_max  # (the Tello takes off to its own height; the flight checks the altitude bounds itself)
        say = status or (lambda _m: None)
        top = 100 * self.speed_per_percent
        if vmax > top + 1e-12:
            raise InvalidValueError(f"vmax {vmax:g} m/s is above what rc can command: 100 % x speed_per_percent "
                                    f"{self.speed_per_percent:g} = {top:g} m/s")
        say(f"entering SDK mode on {self.host}:{self.command_port}")
        answer = self.request("command", timeout)
        if answer is None:
            raise LinkError(f"no answer to `command` from {self.host}:{self.command_port} within {timeout:g} s: is "
                            "the Tello (or `delaykit emulate --protocol tello`) there, and this machine on its "
                            "Wi-Fi? Nothing was flown")
        if answer.lower() != "ok":
            raise VehicleRefusedError(f"{self.name} answered {answer!r} to `command` (SDK mode)")
        if self._read_state(timeout) is None:
            raise LinkError(f"{self.name} answers but sends no state to port {self.state_port} within {timeout:g} s "
                            "(a firewall? another program on that port?); nothing was flown")

    def takeoff(self, timeout: float, status: Callable[[str], None] | None = None) -> None:
        """``takeoff``, answered once the drone hovers."""
        (status or (lambda _m: None))(f"take-off of {self.name}")
        self._drain_replies()
        self.send("takeoff")
        answer = self._reply(timeout)
        if answer is None:
            raise LinkError(f"{self.name} did not answer `takeoff` within {timeout:g} s")
        if answer.lower() != "ok":
            raise VehicleRefusedError(f"{self.name} refused the take-off: {answer!r}")
        self._last_rc = "rc 0 0 0 0"
        self._keeper.start()

    def send_velocity(self, vz: float) -> float:
        """``rc 0 0 c 0`` for ``vz`` m/s up (see :func:`rc_command`)."""
        cmd = rc_command(vz, self.speed_per_percent)
        self._last_rc = cmd
        return self.send(cmd)

    def recv(self, timeout: float) -> AltitudeSample | None:
        """The next valid state line as a sample (no vehicle time), or None on timeout."""
        return self._read_state(timeout)

    def land(self, timeout: float) -> bool:
        """Stop, then ``land`` until answered ``ok``; False on ``timeout`` or a second without state."""
        self._keeper.stop()
        try:
            self._last_rc = "rc 0 0 0 0"
            self.send(self._last_rc)
            deadline = time.monotonic() + timeout
            self._t_state = time.monotonic()
            while time.monotonic() < deadline:
                if time.monotonic() - self._t_state > 1.0:
                    return False  # the link is lost: the drone's own timeout lands it
                answer = self.request("land", min(2.0, deadline - time.monotonic()), resend=2.0)
                if answer is not None and answer.lower() == "ok":
                    return True
        except (LinkError, OSError):
            return False
        return False

    def close(self) -> None:
        self._keeper.stop()
        for s in (getattr(self, "cmd", None), getattr(self, "state", None)):
            if s is not None:
                s.close()

    def to_dict(self) -> dict[str, Any]:
        """What the link knows and counted (JSON-ready)."""
        return {"host": self.host, "command_port": self.command_port, "state_port": self.state_port,
                "speed_per_percent": self.speed_per_percent, "altitude": self.altitude, "counts": dict(self.counts)}
