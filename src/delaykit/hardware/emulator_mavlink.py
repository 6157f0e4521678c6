"""The emulator's MAVLink front end: the same emulated vehicle, reached as PX4's or ArduPilot's simulator is.

:class:`MavlinkEmulator` is a :class:`~delaykit.hardware.emulator.DroneEmulator` (one physics: the vehicle
models, the actuator and link delays, jitter, loss, bursts, delay schedules and traces, the acceleration limit)
with MAVLink in place of the AR.Drone's protocol.  It is reached as the autopilots' simulators are:

* ``to="udp:127.0.0.1:14540"``: it sends to a ground station listening there, and answers whoever sends back
  to its socket (as PX4's simulator does);
* ``listen="tcp:127.0.0.1:5760"``: it serves one TCP client at a time (as ArduPilot's does).

Loopback only (127.0.0.0/8): it is an emulator.  It speaks MAVLink 2 (pymavlink's ``ardupilotmega`` dialect)
and reads MAVLink 1 too, as system 1, component 1, and behaves as ``autopilot="px4"`` or ``"ardupilot"``:

* HEARTBEAT once a second (the autopilot's id, a quadrotor, armed flag and custom mode), SYS_STATUS with the
  pre-arm check bit (healthy once ready), EXTENDED_SYS_STATE (landed state);
* modes and arming with COMMAND_ACK (``MAV_CMD_DO_SET_MODE``, or the SET_MODE message;
  ``MAV_CMD_COMPONENT_ARM_DISARM``): PX4's OFFBOARD is refused without a setpoint stream (one in the last
  0.5 s), as PX4 does; ArduPilot's ``MAV_CMD_NAV_TAKEOFF`` (GUIDED and armed) climbs to its height (param 7);
* velocity-only ``SET_POSITION_TARGET_LOCAL_NED`` (NED: ``vz`` positive down) in OFFBOARD (PX4; armed on the
  ground, a climb command lifts off) or GUIDED (ArduPilot, once airborne): the vertical speed command of the
  physics; a target that ignores the velocity is refused and counted;
* the setpoint-timeout failsafe: PX4 lands (AUTO.LAND) after ``setpoint_timeout`` s without a setpoint in
  OFFBOARD (default 1 s, ``COM_OF_LOSS_T``); ArduPilot drops the velocity target and holds after 3 s
  (``GUID_TIMEOUT``); both disarm on landing, and both say so in a STATUSTEXT;
* ``LOCAL_POSITION_NED`` (``time_boot_ms`` the emulator's clock since start, ``z`` and ``vz`` down positive) at
  the interval asked by ``MAV_CMD_SET_MESSAGE_INTERVAL`` (rounded to the sampling grid of ``config.rate``): PX4
  streams it at ``config.rate`` unasked, ArduPilot sends none until asked, as the real ones do; loss, jitter and
  bursts act on it as on navdata;
* ``TIMESYNC`` requests answered (``tc1`` the emulator's clock in ns);
* pre-arm refusal when asked (``refuse_arming``: arming always refused with that reason, COMMAND_ACK FAILED and
  a STATUSTEXT; the pre-arm bit stays unhealthy), and a vehicle not ready for ``ready_after`` s after start
  (arming TEMPORARILY_REJECTED, as an estimator still converging);
* LAND (ArduPilot mode 9, PX4 AUTO.LAND, ``MAV_CMD_NAV_LAND``) lands.

Bytes that are not MAVLink, and messages to another system, are ignored and counted (``stats["bad"]``,
``stats["other_system"]``).  Other commands get COMMAND_ACK UNSUPPORTED.

Examples
--------
>>> from delaykit.hardware.emulator_config import EmulatorConfig
>>> with MavlinkEmulator(EmulatorConfig(rate=50), autopilot="ardupilot", listen="tcp:127.0.0.1:0") as emu:
...     emu.ports["mavlink"] > 0
True
"""

from __future__ import annotations

import ipaddress
import math
import socket
import threading
import time
from collections import deque
from dataclasses import replace
from typing import Any

from ..errors import InvalidTypeError, InvalidValueError, check_real
from .ardrone import CtrlState
from .emulator import DroneEmulator
from .emulator_config import EmulatorConfig

__all__ = ["MavlinkEmulator", "AUTOPILOTS", "parse_endpoint"]

#: the autopilots the MAVLink front end behaves as
AUTOPILOTS = ("px4", "ardupilot")

# PX4's custom modes: main mode in bits 16-23, AUTO's sub mode in bits 24-31
_PX4_POSCTL = 3 << 16
_PX4_OFFBOARD = 6 << 16
_PX4_AUTO = 4
_PX4_TAKEOFF = (2 << 24) | (4 << 16)
_PX4_LOITER = (3 << 24) | (4 << 16)
_PX4_LAND = (6 << 24) | (4 << 16)
# ArduCopter's mode numbers
_APM_STABILIZE, _APM_GUIDED, _APM_LOITER, _APM_LAND = 0, 4, 5, 9
_APM_MODES = {0, 2, 4, 5, 6, 9, 16, 17}  # stabilize, alt_hold, guided, loiter, rtl, land, poshold, brake

_PREARM_BIT = 0x10000000  # MAV_SYS_STATUS_PREARM_CHECK
_USE_VELOCITY = 0b111000  # type_mask bits 3-5: vx, vy, vz ignored when set


def parse_endpoint(text: Any, kinds: tuple[str, ...], option: str) -> tuple[str, str, int]:
    """``udp:HOST:PORT`` or ``tcp:HOST:PORT`` as ``(kind, host, port)``, HOST on loopback (127.0.0.0/8).

    Examples
    --------
    >>> parse_endpoint("udp:127.0.0.1:14540", ("udp",), "--to")
    ('udp', '127.0.0.1', 14540)
    """
    if not isinstance(text, str):
        raise InvalidTypeError(f"{option} must be text such as udp:127.0.0.1:14540, got {text!r}")
    parts = text.split(":")
    want = " or ".join(f"{k}:127.0.0.1:PORT" for k in kinds)
    if len(parts) != 3 or parts[0] not in kinds:
        raise InvalidValueError(f"{option} {text!r} is not {want}")
    kind, host, port_text = parts
    try:
        port = int(port_text)
    except ValueError:
        raise InvalidValueError(f"{option} {text!r}: port {port_text!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise InvalidValueError(f"{option} {text!r}: port {port} is not from 0 to 65535")
    try:
        loop = ipaddress.ip_address(host) in ipaddress.ip_network("127.0.0.0/8")
    except ValueError:
        loop = False
    if not loop:
        raise InvalidValueError(f"{option} {text!r}: the emulator speaks on loopback only (127.0.0.0/8), got host "
                                f"{host!r}")
    return kind, host, port


def _mavlink() -> Any:
    """pymavlink's MAVLink 2 ``ardupilotmega`` dialect (reads MAVLink 1 as well)."""
    from pymavlink.dialects.v20 import ardupilotmega

    return ardupilotmega


class MavlinkEmulator(DroneEmulator):
    """The emulated vehicle behind a MAVLink front end (see the module docstring).

    Parameters
    ----------
    config : EmulatorConfig, optional
        The physics and the link's imperfections (its AR.Drone ports are not used); ``rate`` is the sampling
        grid, the fastest LOCAL_POSITION_NED rate (50 Hz is a good choice).
    autopilot : {"px4", "ardupilot"}
        Whose behaviour.
    to, listen : str
        Exactly one: ``udp:127.0.0.1:PORT`` to send to a ground station there, or ``tcp:127.0.0.1:PORT`` to serve
        one (port 0: any free one, in :attr:`ports` ``["mavlink"]``).
    refuse_arming : str, optional
        Refuse every arming with this reason (a pre-arm failure).
    ready_after : float
        Seconds after start during which arming is refused as not ready yet.
    setpoint_timeout : float, optional
        The setpoint-loss failsafe's timeout, s (default: PX4 1 s, ArduPilot 3 s).
    """

    def __init__(self, config: EmulatorConfig | None = None, *, autopilot: str = "px4", to: str | None = None,
                 listen: str | None = None, refuse_arming: str | None = None, ready_after: float = 0.0,
                 setpoint_timeout: float | None = None, **overrides: Any) -> None:
        if autopilot not in AUTOPILOTS:
            raise InvalidValueError(f"autopilot must be one of {', '.join(AUTOPILOTS)}, got {autopilot!r}")
        if (to is None) == (listen is None):
            raise InvalidValueError("give the MAVLink emulator exactly one of to (udp:127.0.0.1:PORT, a ground "
                                    "station listening there) and listen (tcp:127.0.0.1:PORT, serve one)")
        self.endpoint = (parse_endpoint(to, ("udp",), "to") if to is not None
                         else parse_endpoint(listen, ("tcp",), "listen"))
        if self.endpoint[0] == "udp" and self.endpoint[2] == 0:
            raise InvalidValueError(f"to {to!r}: give the ground station's port (not 0)")
        cfg = config or EmulatorConfig(rate=50.0)
        # (its sockets bind on the endpoint's loopback address; the AR.Drone's ports are not used)
        cfg = replace(cfg, host=self.endpoint[1], at_port=0, navdata_port=0, video_port=0, control_port=0,
                      **overrides)
        super().__init__(cfg)
        if refuse_arming is not None and (not isinstance(refuse_arming, str) or not refuse_arming.strip()):
            raise InvalidValueError(f"refuse_arming must be a reason (non-empty text), got {refuse_arming!r}")
        self.autopilot = autopilot
        self.refuse_arming = refuse_arming
        self.ready_after = check_real("ready_after (s)", ready_after, minimum=0.0, maximum=3600.0)
        default_timeout = 1.0 if autopilot == "px4" else 3.0
        self.setpoint_timeout = check_real("setpoint_timeout (s)",
                                           default_timeout if setpoint_timeout is None else setpoint_timeout,
                                           minimum=0.0, strict=True, maximum=60.0)
        mav = _mavlink()
        self._m = mav
        self._enc = mav.MAVLink(None, srcSystem=1, srcComponent=1)
        self._dec = mav.MAVLink(None, srcSystem=1, srcComponent=1)
        self._dec.robust_parsing = True
        self._tx_lock = threading.Lock()
        self._armed = False
        self._mode = _PX4_LOITER if autopilot == "px4" else _APM_STABILIZE
        self._last_sp = -math.inf  # the last setpoint's arrival (monotonic)
        self._sp_live = False  # a velocity target in force (the failsafe watches it)
        # LOCAL_POSITION_NED interval (s; None: not sent): PX4 streams it unasked, ArduPilot waits to be asked
        self._lpn_interval: float | None = 0.0 if autopilot == "px4" else None
        self._lpn_due = -math.inf  # when the next LOCAL_POSITION_NED is due (monotonic)
        self._texts: deque = deque()  # STATUSTEXTs to send (queued under the lock, sent by the MAVLink thread)
        self._peer: tuple[str, int] | None = None
        self._conn: socket.socket | None = None
        self._stats.update({"mavlink_messages": 0, "other_system": 0, "setpoints": 0, "position_sent": 0,
                            "failsafes": 0})

    # ---- the front end's hooks ------------------------------------------------------------------------------
    def _bind_ports(self) -> None:
        kind, host, port = self.endpoint
        if kind == "udp":
            self._sock = self._bind(socket.SOCK_DGRAM, 0, "mavlink")
            self._peer = (host, port)
            self._sock.settimeout(0.05)
        else:
            self._server = self._bind(socket.SOCK_STREAM, port, "mavlink")
            self._server.settimeout(0.05)

    def _loops(self) -> list:
        return [self._nav_loop, self._mav_loop]

    def _tick(self, now: float) -> None:
        """The setpoint-timeout failsafe (under the lock)."""
        if not (self._sp_live and self._armed and now - self._last_sp > self.setpoint_timeout):
            return
        self._sp_live = False
        self._stats["failsafes"] += 1
        if self.autopilot == "px4":
            self._mode = _PX4_LAND
            self._cmd_land()
            self._texts.append((2, "Failsafe: offboard setpoints lost, landing"))
        else:
            self._hold(now)
            self._texts.append((4, "Guided velocity target timed out: holding"))

    def _snapshot(self) -> Any:
        return self._lpn_interval, self._lpn_due

    def _send_sample(self, now: float, z_true: float, v: float, mode: int, snap: Any) -> None:
        interval, due = snap
        if interval is None or now < due - 0.5 / self.config.rate:
            return
        with self._lock:  # the next one is due an interval after this one was (so the mean rate is the one asked)
            self._lpn_due = due + interval if now - due < interval else now + interval
        z_meas = self._measure(z_true, mode)
        if z_meas is None:
            return
        msg = self._enc.local_position_ned_encode(int(round(1000 * (now - self._t0))), 0.0, 0.0, -z_meas, 0.0, 0.0,
                                                  -v)
        if self._send(msg):
            with self._lock:
                self._stats["position_sent"] += 1

    # ---- sending ----------------------------------------------------------------------------------------------
    def _send(self, msg: Any) -> bool:
        """Pack and send one message to the ground station; False if there is none (or the socket failed)."""
        with self._tx_lock:
            data = msg.pack(self._enc)
            try:
                if self.endpoint[0] == "udp":
                    self._sock.sendto(data, self._peer)
                elif self._conn is not None:
                    self._conn.sendall(data)
                else:
                    return False
            except OSError:
                return False
        return True

    def _send_ack(self, command: int, result: int) -> None:
        self._send(self._enc.command_ack_encode(command, result))

    def _send_text(self, severity: int, text: str) -> None:
        self._send(self._enc.statustext_encode(severity, text.encode()[:50]))

    def _ready(self, now: float) -> bool:
        return self.refuse_arming is None and now - self._t0 >= self.ready_after

    def _housekeeping(self, now: float) -> None:
        """HEARTBEAT, SYS_STATUS and EXTENDED_SYS_STATE (once a second)."""
        m = self._m
        with self._lock:
            self._advance(max(now, self._phys.t))
            armed, mode, flying = self._armed, self._mode, self._phys.mode
        base = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (m.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
        ap = m.MAV_AUTOPILOT_PX4 if self.autopilot == "px4" else m.MAV_AUTOPILOT_ARDUPILOTMEGA
        self._send(self._enc.heartbeat_encode(m.MAV_TYPE_QUADROTOR, ap, base, mode,
                                              m.MAV_STATE_ACTIVE if armed else m.MAV_STATE_STANDBY))
        health = _PREARM_BIT if self._ready(now) else 0
        self._send(self._enc.sys_status_encode(_PREARM_BIT, _PREARM_BIT, health, 0, 12000, -1, -1, 0, 0, 0, 0, 0, 0))
        landed = {CtrlState.LANDED: m.MAV_LANDED_STATE_ON_GROUND, CtrlState.TAKING_OFF: m.MAV_LANDED_STATE_TAKEOFF,
                  CtrlState.LANDING: m.MAV_LANDED_STATE_LANDING}.get(flying, m.MAV_LANDED_STATE_IN_AIR)
        self._send(self._enc.extended_sys_state_encode(m.MAV_VTOL_STATE_UNDEFINED, landed))
        if self.refuse_arming is not None:
            self._send_text(3, f"PreArm: {self.refuse_arming}")

    # ---- the MAVLink thread ----------------------------------------------------------------------------------
    def _mav_loop(self) -> None:
        next_beat = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_beat:
                self._housekeeping(now)
                next_beat = now + 1.0
            with self._lock:
                texts = list(self._texts)
                self._texts.clear()
            for sev, text in texts:
                self._send_text(sev, text)
            had = self._conn
            data = self._receive()
            if self._conn is not None and had is None:
                next_beat = 0.0  # a new client hears the heartbeat at once
            if data:
                self._handle_bytes(data, time.monotonic())
        self._drop_client()

    def _receive(self) -> bytes:
        """Bytes from the ground station (b"" after a short wait); accepts a TCP client when none is connected."""
        try:
            if self.endpoint[0] == "udp":
                data, _addr = self._sock.recvfrom(65536)
                return data
            if self._conn is None:
                conn, _ = self._server.accept()
                conn.settimeout(0.05)
                conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                self._conn = conn
                self._dec = self._m.MAVLink(None, srcSystem=1, srcComponent=1)  # a fresh parser per client
                self._dec.robust_parsing = True
                return b""
            data = self._conn.recv(65536)
            if not data:  # the client closed: serve the next one
                self._drop_client()
            return data
        except (socket.timeout, BlockingIOError):
            return b""
        except OSError:
            self._drop_client()
            return b""

    def _drop_client(self) -> None:
        """Close the TCP client's connection, if any (the next one is then served)."""
        conn, self._conn = self._conn, None
        if conn is not None:
            try:
                conn.close()
            except OSError:
                pass

    def _handle_bytes(self, data: bytes, t: float) -> None:
        try:
            msgs = self._dec.parse_buffer(data) or []
        except self._m.MAVError as exc:  # (robust parsing returns bad data as messages; this is belt and braces)
            with self._lock:
                self._stats["bad"] += 1
                self._last_error = str(exc)
            return
        for msg in msgs:
            try:
                self._handle_message(msg, t)
            except (AttributeError, TypeError, ValueError, OverflowError) as exc:  # (never stop on a message)
                with self._lock:
                    self._stats["bad"] += 1
                    self._last_error = f"{msg.get_type()}: {exc}"

    def _handle_message(self, msg: Any, t: float) -> None:
        m = self._m
        kind = msg.get_type()
        with self._lock:
            if kind == "BAD_DATA":
                self._stats["bad"] += 1
                self._last_error = f"bytes that are not MAVLink ({len(msg.get_msgbuf())} bytes)"
                return
            self._stats["mavlink_messages"] += 1
            target = getattr(msg, "target_system", None)
            if target not in (None, 0, 1):
                self._stats["other_system"] += 1
                return
            self._advance(max(t, self._phys.t))
            self._last_cmd = t
        if kind == "COMMAND_LONG":
            self._command(msg.command, (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                                        msg.param7), t)
        elif kind == "COMMAND_INT":
            self._command(msg.command, (msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z), t)
        elif kind == "SET_MODE":
            self._send_ack(m.MAV_CMD_DO_SET_MODE, self._set_mode(msg.custom_mode, t))
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            self._setpoint(msg, t)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            self._send(self._enc.timesync_encode(time.monotonic_ns() - int(self._t0 * 1e9), msg.ts1))

    def _command(self, command: int, p: tuple, t: float) -> None:
        m = self._m
        if command == m.MAV_CMD_COMPONENT_ARM_DISARM:
            result, why = self._arm(p[0] >= 0.5, p[1] == 21196, t)
            if why:
                self._send_text(3 if result != m.MAV_RESULT_ACCEPTED else 6, why)
            self._send_ack(command, result)
        elif command == m.MAV_CMD_DO_SET_MODE:
            custom = int(p[1]) if self.autopilot == "ardupilot" else (int(p[2]) << 24) | (int(p[1]) << 16)
            self._send_ack(command, self._set_mode(custom, t))
        elif command == m.MAV_CMD_NAV_TAKEOFF:
            self._send_ack(command, self._takeoff(p[6], t))
        elif command == m.MAV_CMD_NAV_LAND:
            with self._lock:
                self._mode = _PX4_LAND if self.autopilot == "px4" else _APM_LAND
                self._cmd_land()
                self._sp_live = False
            self._send_ack(command, m.MAV_RESULT_ACCEPTED)
        elif command == m.MAV_CMD_SET_MESSAGE_INTERVAL:
            if int(p[0]) == m.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
                with self._lock:
                    us = p[1]
                    self._lpn_interval = (None if us < 0 else
                                          (0.0 if self.autopilot == "px4" else None) if us == 0 else us / 1e6)
                    self._lpn_due = -math.inf
                self._send_ack(command, m.MAV_RESULT_ACCEPTED)
            else:
                self._send_ack(command, m.MAV_RESULT_UNSUPPORTED)
        else:
            self._send_ack(command, m.MAV_RESULT_UNSUPPORTED)

    def _arm(self, arm: bool, force: bool, t: float) -> tuple[int, str]:
        m = self._m
        with self._lock:
            p = self._phys
            if not arm:
                if p.mode != CtrlState.LANDED and not force:
                    return m.MAV_RESULT_DENIED, "Disarm refused: flying"
                self._armed = False
                if p.mode != CtrlState.LANDED:
                    self._cmd_emergency()
                return m.MAV_RESULT_ACCEPTED, ""
            if self._armed:
                return m.MAV_RESULT_ACCEPTED, ""
            if self.refuse_arming is not None:
                return m.MAV_RESULT_FAILED, f"PreArm: {self.refuse_arming}"
            if not self._ready(t):
                return m.MAV_RESULT_TEMPORARILY_REJECTED, "PreArm: estimator still initialising"
            if self.autopilot == "ardupilot" and self._mode not in (_APM_GUIDED, _APM_STABILIZE, _APM_LOITER):
                return m.MAV_RESULT_FAILED, "Arm: mode not armable"
            self._armed = True
            return m.MAV_RESULT_ACCEPTED, ""

    def _set_mode(self, custom: int, t: float) -> int:
        m = self._m
        with self._lock:
            if self.autopilot == "px4":
                if custom == _PX4_OFFBOARD and t - self._last_sp > 0.5:
                    self._texts.append((3, "Offboard refused: no setpoint stream"))
                    return m.MAV_RESULT_DENIED
                if custom not in (_PX4_OFFBOARD, _PX4_LOITER, _PX4_LAND, _PX4_POSCTL, _PX4_TAKEOFF):
                    return m.MAV_RESULT_DENIED
                landing = custom == _PX4_LAND
                holding = custom in (_PX4_LOITER, _PX4_POSCTL)
            else:
                if custom not in _APM_MODES:
                    return m.MAV_RESULT_DENIED
                landing = custom == _APM_LAND
                holding = custom != _APM_GUIDED
            self._mode = custom
            self._sp_live = False
            if landing:
                self._cmd_land()
            elif holding:
                self._hold(t)
            return m.MAV_RESULT_ACCEPTED

    def _takeoff(self, height: float, t: float) -> int:
        del t  # (the climb starts at the next tick)
        m = self._m
        height = 2.5 if not math.isfinite(height) or height <= 0 else min(height, self._alt_max)
        with self._lock:
            if not self._armed:
                self._texts.append((3, "Takeoff refused: not armed"))
                return m.MAV_RESULT_FAILED
            if self.autopilot == "ardupilot" and self._mode != _APM_GUIDED:
                self._texts.append((3, "Takeoff refused: not in GUIDED"))
                return m.MAV_RESULT_FAILED
            if not self._cmd_takeoff(height):
                return m.MAV_RESULT_FAILED
            if self.autopilot == "px4":
                self._mode = _PX4_TAKEOFF
            return m.MAV_RESULT_ACCEPTED

    def _hold(self, t: float) -> None:
        """Stop climbing or descending (under the lock): a zero speed command, now."""
        del t  # (now: the hook's time is not needed to stop)
        p = self._phys
        if p.mode in (CtrlState.FLYING, CtrlState.HOVERING):
            p.pending.clear()
            p.v_in = 0.0
            p.mode = CtrlState.HOVERING

    def _setpoint(self, msg: Any, t: float) -> None:
        with self._lock:
            self._stats["setpoints"] += 1
            if msg.type_mask & _USE_VELOCITY == _USE_VELOCITY or not math.isfinite(msg.vz):
                self._stats["bad"] += 1
                self._last_error = f"SET_POSITION_TARGET_LOCAL_NED without a velocity (type_mask {msg.type_mask})"
                return
            self._last_sp = t
            offboard = self._mode == (_PX4_OFFBOARD if self.autopilot == "px4" else _APM_GUIDED)
            if not (offboard and self._armed):
                return
            p = self._phys
            if p.mode == CtrlState.LANDED and self.autopilot == "px4" and -msg.vz > 0:
                p.mode = CtrlState.HOVERING  # lift-off: the speed loop now flies (the ground holds it at 0 below)
            if p.mode == CtrlState.TAKING_OFF:
                return  # (ArduPilot flies its take-off to the end first)
            self._sp_live = True
            self._cmd_speed(-float(msg.vz), t)
        return

    def _integrate(self, dt: float) -> None:
        was = self._phys.mode
        super()._integrate(dt)
        p = self._phys
        if was == CtrlState.LANDING and p.mode == CtrlState.LANDED:
            self._armed = False  # landed: both autopilots disarm
            self._sp_live = False
        elif p.mode == CtrlState.HOVERING and self.autopilot == "px4" and self._mode == _PX4_TAKEOFF:
            self._mode = _PX4_LOITER  # the take-off done, PX4 holds

    def summary(self) -> dict[str, Any]:
        """As :meth:`DroneEmulator.summary`, with the autopilot, the endpoint, the mode and arming."""
        out = super().summary()
        kind, host, port = self.endpoint
        with self._lock:
            out.update({"protocol": "mavlink", "autopilot": self.autopilot,
                        "endpoint": f"{kind}:{host}:{self.ports.get('mavlink', port) if kind == 'tcp' else port}",
                        "armed": self._armed, "custom_mode": self._mode})
        return out

    def stop(self) -> None:
        super().stop()
        self._drop_client()

