"""The MAVLink link: a PX4 or ArduPilot autopilot (or the emulator's MAVLink front end) flown through pymavlink.

:class:`MavlinkLink` is a :class:`~delaykit.hardware.link.VehicleLink`.  Connection strings are pymavlink's:
``udpin:0.0.0.0:14550`` (listen for a vehicle sending there), ``udpout:HOST:PORT``, ``tcp:127.0.0.1:5760``, or a
serial device (``/dev/ttyUSB0``, with ``baud``).  It speaks MAVLink 2 as system 255, component 190 (a ground
station).

* **Connect**: wait for a HEARTBEAT from an autopilot; the autopilot (PX4, ArduPilot) is read from it.  Ask for
  ``LOCAL_POSITION_NED`` at the loop's ``rate`` with ``MAV_CMD_SET_MESSAGE_INTERVAL`` (ArduPilot sends nothing
  useful until asked), and wait for the first one.
* **Ready**: wait until the vehicle's SYS_STATUS says its pre-arm checks pass (where it reports them), showing
  its STATUSTEXT messages as progress; after ``ready_timeout`` a :class:`~delaykit.hardware.link.VehicleRefusedError`
  names its last reason.
* **Take-off**: PX4: stream velocity-only ``SET_POSITION_TARGET_LOCAL_NED`` (zero) for half a second, switch to
  OFFBOARD, arm, climb at ``climb_speed`` to ``takeoff_height``.  ArduPilot: GUIDED, arm (repeated while the
  vehicle says "not yet"), ``MAV_CMD_NAV_TAKEOFF`` to ``takeoff_height``, wait until it is there.  Any refusal
  (COMMAND_ACK DENIED or FAILED, or arming still refused at the timeout) raises
  :class:`~delaykit.hardware.link.VehicleRefusedError` with the vehicle's reason (its result and its STATUSTEXT).
* **Flying**: each command is a velocity-only ``SET_POSITION_TARGET_LOCAL_NED`` (frame LOCAL_NED; position,
  acceleration, yaw and yaw rate ignored; ``vz`` positive down, so ``-u``).  A keep-alive thread resends the last
  one whenever none went out for ``1 / keepalive`` s (10 Hz by default: above PX4's 2 Hz, and ArduPilot drops a
  velocity target after 3 s without one), so the vehicle keeps its target while the loop hovers to estimate.
* **Samples**: from ``LOCAL_POSITION_NED``: altitude ``-z``, vertical speed ``-vz`` (NED: up is minus z), the
  vehicle time ``time_boot_ms`` / 1000, the arrival time (``time.monotonic()`` when pymavlink returned it: no
  kernel stamps through pymavlink's sockets).
* **Land**: mode LAND (ArduPilot) or AUTO.LAND (PX4), then wait until the vehicle disarms (both do on landing).
  When the link is lost, nothing can be sent: the vehicle's own failsafe (PX4's offboard loss, ArduPilot's
  guided timeout and its GCS failsafe, as configured on the vehicle) takes over, and :meth:`MavlinkLink.land`
  returns False after a second of silence.

Bytes that are not MAVLink, messages from another system and stale ``LOCAL_POSITION_NED`` (a ``time_boot_ms``
not after the last) are ignored and counted (:attr:`MavlinkLink.counts`, and ``rejected`` in the flight's result).

Examples
--------
>>> link = MavlinkLink("tcp:127.0.0.1:5760", rate=50)
>>> link.name, link.sample_name, link.has_vehicle_time
('MAVLink vehicle on tcp:127.0.0.1:5760', 'LOCAL_POSITION_NED', True)
"""

from __future__ import annotations

import os
import threading
import time
from typing import Any, Callable

from ..errors import InvalidTypeError, InvalidValueError, check_real
from .link import AltitudeSample, KeepAlive, LinkError, VehicleLink, VehicleRefusedError

__all__ = ["MavlinkLink", "VELOCITY_ONLY", "encode_velocity", "CONNECTION_KINDS"]

#: pymavlink's network connection kinds the link accepts (anything else must be a serial device path)
CONNECTION_KINDS = ("udpin", "udpout", "udp", "udpbcast", "tcp", "tcpin")
#: type_mask of a velocity-only target: position (bits 0-2), acceleration (6-8), yaw (10) and yaw rate (11) ignored
VELOCITY_ONLY = 0b110111000111
_PREARM_BIT = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK
_PX4_OFFBOARD = (1, 6, 0)  # base mode (custom enabled), main mode, sub mode
_PX4_LAND = (1, 4, 6)
_APM_GUIDED, _APM_LAND = 4, 9


def _mavutil() -> Any:
    """pymavlink's mavutil, speaking MAVLink 2."""
    os.environ.setdefault("MAVLINK20", "1")
    from pymavlink import mavutil

    return mavutil


def encode_velocity(mav: Any, vz_up: float, time_boot_ms: int = 0, target_system: int = 1,
                    target_component: int = 1) -> bytes:
    """The bytes of a velocity-only ``SET_POSITION_TARGET_LOCAL_NED`` commanding ``vz_up`` m/s up.

    Parameters
    ----------
    mav : pymavlink MAVLink object
        The encoder (its sequence number advances).

    Examples
    --------
    >>> from pymavlink.dialects.v20 import ardupilotmega as m
    >>> enc, dec = m.MAVLink(None, 255, 190), m.MAVLink(None, 1, 1)
    >>> msg = dec.parse_buffer(encode_velocity(enc, 0.5))[0]
    >>> msg.vz, msg.type_mask == VELOCITY_ONLY
    (-0.5, True)
    """
    m = mav
    return m.set_position_target_local_ned_encode(time_boot_ms, target_system, target_component, 1, VELOCITY_ONLY,
                                                  0.0, 0.0, 0.0, 0.0, 0.0, -vz_up, 0.0, 0.0, 0.0, 0.0,
                                                  0.0).pack(mav)


def _check_connection(conn: Any) -> str:
    if not isinstance(conn, str):
        raise InvalidTypeError(f"connection must be text such as udpin:0.0.0.0:14550 or tcp:127.0.0.1:5760, got "
                               f"{conn!r}")
    kind, sep, rest = conn.partition(":")
    if sep and kind in CONNECTION_KINDS:
        host, sep2, port = rest.rpartition(":")
        if not sep2 or not host or not port.isdigit() or not 0 < int(port) <= 65535:
            raise InvalidValueError(f"connection {conn!r} must be {kind}:HOST:PORT (a port from 1 to 65535)")
        return conn
    if conn.startswith("/") or conn.upper().startswith("COM"):
        return conn  # a serial device
    raise InvalidValueError(f"connection {conn!r} is not one of pymavlink's: {', '.join(CONNECTION_KINDS)} followed "
                            "by :HOST:PORT (e.g. udpin:0.0.0.0:14550, tcp:127.0.0.1:5760), or a serial device path")


class MavlinkLink(VehicleLink):
    """A MAVLink vehicle (see the module docstring).

    Parameters
    ----------
    connection : str
        pymavlink's connection string.
    rate : float
        The ``LOCAL_POSITION_NED`` rate asked for, Hz (the loop runs at it).
    takeoff_height : float
        The hover height after take-off, m.
    climb_speed : float
        PX4's climb to ``takeoff_height`` in OFFBOARD, m/s.
    keepalive : float
        The least setpoint rate, Hz (the last command resent when the loop is quiet).
    baud : int
        For a serial device.
    system_id : int, optional
        The vehicle's system id (default: the first autopilot heard).
    """

    has_vehicle_time = True
    sample_name = "LOCAL_POSITION_NED"

    def __init__(self, connection: str, *, rate: float = 50.0, takeoff_height: float = 1.0, climb_speed: float = 0.5,
                 keepalive: float = 10.0, baud: int = 57600, system_id: int | None = None) -> None:
        super().__init__()
        self.connection = _check_connection(connection)
        self.rate = check_real("rate (Hz)", rate, minimum=1.0, maximum=500.0)
        self.takeoff_height = check_real("takeoff_height (m)", takeoff_height, minimum=0.3, maximum=100.0)
        self.climb_speed = check_real("climb_speed (m/s)", climb_speed, minimum=0.05, maximum=2.0)
        self.keepalive = check_real("keepalive (Hz)", keepalive, minimum=2.5, maximum=100.0)
        if isinstance(baud, bool) or not isinstance(baud, int) or baud <= 0:
            raise InvalidValueError(f"baud must be a positive whole number, got {baud!r}")
        if system_id is not None and (isinstance(system_id, bool) or not isinstance(system_id, int)
                                      or not 1 <= system_id <= 255):
            raise InvalidValueError(f"system_id must be from 1 to 255, got {system_id!r}")
        self.baud = baud
        self.name = f"MAVLink vehicle on {connection}"
        self.autopilot: str | None = None
        self.target_system = system_id
        self.target_component = 1
        self.counts = {"garbage": 0, "other_system": 0, "stale": 0}
        self.texts: list[str] = []  # the vehicle's STATUSTEXTs, in order (the last 50)
        self.armed = False
        self.custom_mode = 0
        self.prearm_ok: bool | None = None  # None: the vehicle does not report its pre-arm checks
        self.landed_state: int | None = None
        self._acks: dict[int, int] = {}
        self._last_tbm = -1
        self._seq = 0
        self._conn: Any = None
        self._tx = threading.Lock()
        self._last_vz = 0.0
        self._last_tx = 0.0
        self._keeper = KeepAlive("mavlink-keepalive", 1.0 / self.keepalive, lambda: self._last_tx,
                                 lambda: self.send_velocity(self._last_vz))
        self._say: Callable[[str], None] = lambda _m: None
        self._t_msg = 0.0  # arrival of the last message from the vehicle

    # ---- receiving ---------------------------------------------------------------------------------------------
    def _next(self, timeout: float) -> Any:
        """The next message from the vehicle (after :meth:`_process`), or None after ``timeout`` s."""
        conn = self._conn
        deadline = time.monotonic() + timeout
        while True:
            try:
                msg = conn.recv_msg()
            except OSError as exc:
                raise LinkError(f"the link to {self.connection} failed: {exc}") from None
            if msg is None:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                conn.select(min(left, 0.05))
                continue
            if self._process(msg):
                return msg

    def _process(self, msg: Any) -> bool:
        """Keep what a message says; False for one to ignore (counted when it is bad)."""
        kind = msg.get_type()
        if kind == "BAD_DATA":
            self.counts["garbage"] += 1
            self._reject(f"bytes that are not MAVLink ({len(msg.get_msgbuf())})")
            return False
        src = msg.get_srcSystem()
        if kind == "HEARTBEAT" and self.target_system is None and msg.autopilot != 8 and msg.type != 6:
            self.target_system, self.target_component = src, msg.get_srcComponent()  # (8: no autopilot, 6: a GCS)
        if self.target_system is None:
            return False  # (nothing is the vehicle's before its first heartbeat)
        if src != self.target_system:
            if src != 255 or kind != "HEARTBEAT":  # (other ground stations' heartbeats are not the vehicle's)
                self.counts["other_system"] += 1
                self._reject(f"{kind} from system {src}, not the vehicle's {self.target_system}")
            return False
        self._t_msg = time.monotonic()
        if kind == "HEARTBEAT":
            if msg.get_srcComponent() == self.target_component:
                self.armed = bool(msg.base_mode & 128)  # MAV_MODE_FLAG_SAFETY_ARMED
                self.custom_mode = msg.custom_mode
                if self.autopilot is None:
                    self.autopilot = {12: "px4", 3: "ardupilot"}.get(msg.autopilot, "other")
        elif kind == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else msg.text.decode(errors="replace")
            text = text.rstrip("\x00").strip()
            if not self.texts or self.texts[-1] != text:
                self._say(f"vehicle: {text}")
            self.texts = (self.texts + [text])[-50:]
        elif kind == "COMMAND_ACK":
            self._acks[msg.command] = msg.result
        elif kind == "SYS_STATUS":
            if msg.onboard_control_sensors_present & _PREARM_BIT:
                self.prearm_ok = bool(msg.onboard_control_sensors_health & _PREARM_BIT)
        elif kind == "EXTENDED_SYS_STATE":
            self.landed_state = msg.landed_state
        return True

    def recv(self, timeout: float) -> AltitudeSample | None:
        """The next ``LOCAL_POSITION_NED`` as a sample (stale ones counted and skipped), or None on timeout."""
        deadline = time.monotonic() + timeout
        while True:
            msg = self._next(deadline - time.monotonic())
            if msg is None:
                return None
            if msg.get_type() != "LOCAL_POSITION_NED":
                continue
            t = time.monotonic()
            if msg.time_boot_ms <= self._last_tbm:
                self.counts["stale"] += 1
                self._reject(f"stale LOCAL_POSITION_NED (time_boot_ms {msg.time_boot_ms} after {self._last_tbm})")
                continue
            self._last_tbm = msg.time_boot_ms
            self._seq += 1
            return AltitudeSample(-msg.z, -msg.vz, msg.time_boot_ms / 1000.0, t, self._seq)

    # ---- sending -----------------------------------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        try:
            self._conn.write(data)
        except OSError as exc:
            raise LinkError(f"cannot send to {self.connection}: {exc}") from None

    def send_velocity(self, vz: float) -> float:
        """A velocity-only ``SET_POSITION_TARGET_LOCAL_NED``: ``vz`` m/s up."""
        with self._tx:
            self._write(encode_velocity(self._conn.mav, vz, 0, self.target_system, self.target_component))
            self._last_vz = vz
            self._last_tx = time.monotonic()
            return self._last_tx

    def _command(self, command: int, params: tuple, what: str, timeout: float, *, retry_temporary: bool = False,
                 pump: Callable[[], None] | None = None) -> None:
        """Send a COMMAND_LONG until its COMMAND_ACK; raise VehicleRefusedError on a refusal, LinkError on none."""
        m = self._conn.mav
        deadline = time.monotonic() + timeout
        last: int | None = None
        n_texts = len(self.texts)
        confirmation = 0
        while time.monotonic() < deadline:
            self._acks.pop(command, None)
            with self._tx:
                self._write(m.command_long_encode(self.target_system, self.target_component, command,
                                                  min(confirmation, 255), *params).pack(m))
            confirmation += 1
            t_sent = time.monotonic()
            while time.monotonic() - t_sent < 1.0 and command not in self._acks and time.monotonic() < deadline:
                if pump is not None:
                    pump()
                self._next(0.05)
            result = self._acks.get(command)
            if result is None:
                continue
            if result in (0, 5):  # ACCEPTED, IN_PROGRESS
                return
            last = result
            if result == 1 and retry_temporary:  # TEMPORARILY_REJECTED: the vehicle is not ready yet
                time.sleep(0.2)
                continue
            break
        names = {1: "temporarily rejected", 2: "denied", 3: "unsupported", 4: "failed", 6: "cancelled"}
        if last is None:
            raise LinkError(f"{self.name} did not answer {what} within {timeout:g} s")
        texts = self.texts[n_texts:] or self.texts[-1:]
        reason = f": {texts[-1]}" if texts else ""
        raise VehicleRefusedError(f"{self.autopilot_name} refused {what} ({names.get(last, f'result {last}')})"
                                  f"{reason}")

    @property
    def autopilot_name(self) -> str:
        """``PX4``, ``ArduPilot`` or ``the vehicle``."""
        return {"px4": "PX4", "ardupilot": "ArduPilot"}.get(self.autopilot or "", "the vehicle")

    def _open(self) -> None:
        """Open pymavlink's connection (a LinkError if it cannot be opened)."""
        try:
            self._conn = _mavutil().mavlink_connection(self.connection, baud=self.baud, source_system=255,
                                                       source_component=190, robust_parsing=True, retries=0,
                                                       autoreconnect=False)
        except (OSError, ValueError) as exc:
            raise LinkError(f"cannot open {self.connection}: {exc}; nothing was flown") from None

    # ---- the vehicle-link interface ----------------------------------------------------------------------------
    def connect(self, timeout: float, *, vmax: float, z_max: float,
                status: Callable[[str], None] | None = None) -> None:
        """Open the connection, wait for the autopilot's heartbeat, ask for LOCAL_POSITION_NED at ``rate``."""
        del vmax  # (the autopilot has its own climb-rate limits; the flight clips the command to vmax itself)
        self._say = say = status or (lambda _m: None)
        if self.takeoff_height >= z_max:
            raise InvalidValueError(f"takeoff_height {self.takeoff_height:g} m must be below z_max {z_max:g} m")
        mavutil = _mavutil()
        say(f"connecting to {self.connection}")
        self._open()
        deadline = time.monotonic() + timeout
        m = self._conn.mav
        while self.autopilot is None:
            if time.monotonic() > deadline:
                raise LinkError(f"no HEARTBEAT from an autopilot on {self.connection} within {timeout:g} s: is the "
                                "vehicle (or `delaykit emulate --protocol mavlink`) there? Nothing was flown")
            with self._tx:  # (a udpout/udp link needs to speak first for the vehicle to know where to answer)
                self._write(m.heartbeat_encode(6, 8, 0, 0, 0).pack(m))
            self._next(0.5)
        self.name = f"{self.autopilot_name} (system {self.target_system}) on {self.connection}"
        say(f"{self.name}; asking for LOCAL_POSITION_NED at {self.rate:g} Hz")
        self._command(mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL,
                      (mavutil.mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 1e6 / self.rate, 0, 0, 0, 0, 0),
                      "the LOCAL_POSITION_NED interval", max(deadline - time.monotonic(), 1.0))
        if self.recv(max(deadline - time.monotonic(), 1.0)) is None:
            raise LinkError(f"{self.name} sends no LOCAL_POSITION_NED (no position estimate?); nothing was flown")

    def ready(self, timeout: float, status: Callable[[str], None] | None = None) -> None:
        """Wait for the pre-arm checks (SYS_STATUS), showing the vehicle's messages."""
        say = status or self._say
        now = time.monotonic()
        deadline, t_report, next_say = now + timeout, now + 1.5, 0.0
        while not self.prearm_ok:
            now = time.monotonic()
            if self.prearm_ok is None and now > t_report:
                break  # the vehicle does not report its pre-arm checks: arming will tell
            if now > deadline:
                why = f": {self.texts[-1]}" if self.texts else ""
                raise VehicleRefusedError(f"{self.autopilot_name} not ready to arm after {timeout:g} s (pre-arm "
                                          f"checks failing){why}")
            if now >= next_say and self.prearm_ok is False:
                say(f"waiting for {self.autopilot_name}'s pre-arm checks ({deadline - now:.0f} s left)")
                next_say = now + 5.0
            self._next(0.1)
        say(f"{self.autopilot_name} ready to arm")

    def takeoff(self, timeout: float, status: Callable[[str], None] | None = None) -> None:
        """The autopilot's take-off sequence (see the module docstring)."""
        say = status or self._say
        mavutil = _mavutil()
        c = mavutil.mavlink
        if self.autopilot == "px4":
            t0 = time.monotonic()
            while time.monotonic() - t0 < 0.5:  # the setpoint stream first: PX4 refuses OFFBOARD without it
                self.send_velocity(0.0)
                self._next(0.05)
            self._keeper.start()
            say("OFFBOARD")
            self._command(c.MAV_CMD_DO_SET_MODE, (*_PX4_OFFBOARD, 0, 0, 0, 0), "OFFBOARD mode", 5.0)
            say("arming")
            self._command(c.MAV_CMD_COMPONENT_ARM_DISARM, (1, 0, 0, 0, 0, 0, 0), "arming", timeout,
                          retry_temporary=True)
            self.armed = True
            say(f"climbing to {self.takeoff_height:g} m")
            deadline = time.monotonic() + timeout
            while True:
                self.send_velocity(self.climb_speed)
                s = self.recv(0.5)
                if s is not None and s.z >= self.takeoff_height:
                    break
                if time.monotonic() > deadline:
                    raise LinkError(f"{self.name} did not climb to {self.takeoff_height:g} m within {timeout:g} s")
            self.send_velocity(0.0)
        else:
            say("GUIDED")
            self._command(c.MAV_CMD_DO_SET_MODE, (1, _APM_GUIDED, 0, 0, 0, 0, 0), "GUIDED mode", 5.0)
            say("arming")
            self._command(c.MAV_CMD_COMPONENT_ARM_DISARM, (1, 0, 0, 0, 0, 0, 0), "arming", timeout,
                          retry_temporary=True)
            self.armed = True
            say(f"take-off to {self.takeoff_height:g} m")
            self._command(c.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, self.takeoff_height), "the take-off", 5.0)
            deadline = time.monotonic() + timeout
            while True:
                s = self.recv(0.5)
                if s is not None and s.z >= 0.95 * self.takeoff_height:
                    break
                if time.monotonic() > deadline:
                    raise LinkError(f"{self.name} did not reach {self.takeoff_height:g} m within {timeout:g} s")
            self.send_velocity(0.0)
            self._keeper.start()

    def land(self, timeout: float) -> bool:
        """LAND, then wait until the vehicle disarms; False after ``timeout`` s or a second of silence."""
        self._keeper.stop()
        if self._conn is None:
            return False
        c = _mavutil().mavlink
        mode = (*_PX4_LAND, 0, 0, 0, 0) if self.autopilot == "px4" else (1, _APM_LAND, 0, 0, 0, 0, 0)
        deadline = time.monotonic() + timeout
        t_sent = 0.0
        self._t_msg = time.monotonic()
        while time.monotonic() < deadline:
            now = time.monotonic()
            if now - self._t_msg > 1.0:
                return False  # the link is lost: the vehicle's failsafe is in charge
            if now - t_sent > 1.0:
                m = self._conn.mav
                with self._tx:
                    self._write(m.command_long_encode(self.target_system, self.target_component,
                                                      c.MAV_CMD_DO_SET_MODE, 0, *mode).pack(m))
                t_sent = now
            self._next(0.1)
            if not self.armed:  # (both autopilots disarm once landed)
                return True
        return False

    def close(self) -> None:
        self._keeper.stop()
        if self._conn is not None:
            try:
                self._conn.close()
            except OSError:
                pass
            self._conn = None

    def to_dict(self) -> dict[str, Any]:
        """What the link knows and counted (JSON-ready)."""
        return {"connection": self.connection, "autopilot": self.autopilot, "system": self.target_system,
                "armed": self.armed, "counts": dict(self.counts), "texts": self.texts[-5:]}

