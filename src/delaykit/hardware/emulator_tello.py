"""The emulator's Tello front end: the same emulated vehicle, reached as a Tello is (its text SDK 2.0/3.0 on UDP).

:class:`TelloEmulator` is a :class:`~delaykit.hardware.emulator.DroneEmulator` (one physics: the vehicle models,
the actuator and link delays, jitter, loss, bursts, delay schedules and traces, the acceleration limit) with the
Tello's SDK in place of the AR.Drone's protocol:

* it listens on UDP ``host:command_port`` (127.0.0.1:8889 by default; port 0: any free one, in
  :attr:`~delaykit.hardware.emulator.DroneEmulator.ports` ``["command"]``) and answers each command to its
  sender, ``ok`` or ``error ...``;
* ``command`` enters SDK mode (answered ``ok``); before it every other command is answered ``error Not in SDK
  mode``.  From then on the state goes to the sender's address at ``state_port`` (8890, where a Tello sends it;
  settable, so that a test's link can listen on a free port), one line of the SDK's fields at ``config.rate``
  (10 Hz by default): ``mid;x;y;z;mpry;pitch;roll;yaw;vgx;vgy;vgz;templ;temph;tof;h;bat;baro;time;agx;agy;agz``
  with ``tof`` the measured altitude (ultrasonic-like noise, cm), ``h`` the true altitude above the take-off point
  in 10 cm steps (cm), ``vgz`` the vertical speed (cm/s, up positive here), ``baro`` 100 m plus the altitude (m),
  ``time`` the motors' running time (s); the attitude, the horizontal speeds and the accelerations are zeros (this
  is a vertical emulator);
* ``takeoff`` climbs to ``config.takeoff_altitude`` and is answered ``ok`` once hovering (``error`` when already
  flying); ``land`` descends and is answered ``ok`` once landed; ``emergency`` stops the motors (``ok``);
  ``keepalive`` is answered ``ok``; ``battery?``, ``height?`` (decimetres, ``12dm``), ``time?`` and ``speed?``
  are answered; other commands ``error Unknown command``;
* ``rc a b c d`` (four whole numbers from -100 to 100, not answered) commands the vertical speed
  ``c * speed_per_percent`` m/s, through the physics' delays; its other sticks are ignored;
* **auto-land**: airborne with no command for ``command_timeout`` s (15 s on a Tello), it lands by itself
  (counted in ``stats["auto_lands"]``).

Datagrams that are not a command (not text, a malformed ``rc``) are ignored and counted (``stats["bad"]``); a
malformed ``rc`` is not answered, as ``rc`` never is.

Examples
--------
>>> with TelloEmulator(command_port=0, state_port=8890) as emu:
...     emu.ports["command"] > 0
True
"""

from __future__ import annotations

import socket
import time
from collections import deque
from dataclasses import replace
from typing import Any

from ..errors import InvalidValueError, check_real
from .ardrone import CtrlState
from .emulator import DroneEmulator
from .emulator_config import EmulatorConfig, _check_port
from .stamps import enable_stamps, recv_stamped
from .tello import SPEED_PER_PERCENT

__all__ = ["TelloEmulator", "COMMAND_TIMEOUT"]

#: the Tello's no-command timeout, s: airborne, it lands by itself after this long without a command
COMMAND_TIMEOUT = 15.0
_AIRBORNE = (CtrlState.FLYING, CtrlState.HOVERING, CtrlState.TAKING_OFF)


class TelloEmulator(DroneEmulator):
    """The emulated vehicle behind a Tello SDK front end (see the module docstring).

    Parameters
    ----------
    config : EmulatorConfig, optional
        The physics and the link's imperfections (``host`` is where it listens; its AR.Drone ports are not used;
        ``rate`` is the state rate, 10 Hz by default).
    command_port : int
        The UDP port commands arrive on (8889; 0: any free one).
    state_port : int
        The port the state is sent to, at the address that sent ``command`` (8890).
    speed_per_percent : float
        The vehicle's true map from rc percent to vertical speed, m/s per percent.
    command_timeout : float
        The no-command auto-land timeout, s (15 on a Tello).
    """

    def __init__(self, config: EmulatorConfig | None = None, *, command_port: int = 8889, state_port: int = 8890,
                 speed_per_percent: float = SPEED_PER_PERCENT, command_timeout: float = COMMAND_TIMEOUT,
                 **overrides: Any) -> None:
        cfg = config or EmulatorConfig(rate=10.0)
        cfg = replace(cfg, at_port=0, navdata_port=0, video_port=0, control_port=0, **overrides)
        super().__init__(cfg)
        self.command_port = _check_port("command_port", command_port)
        self.state_port = _check_port("state_port", state_port)
        if state_port == 0:
            raise InvalidValueError("state_port must be given (the client's port for the state, 8890 on a Tello)")
        self.speed_per_percent = check_real("speed_per_percent (m/s per percent)", speed_per_percent, minimum=0.0,
                                            maximum=0.1, strict=True)
        self.command_timeout = check_real("command_timeout (s)", command_timeout, minimum=0.0, strict=True,
                                          maximum=3600.0)
        self._sdk = False
        self._state_to: tuple[str, int] | None = None
        self._waiting: list[tuple[str, tuple[str, int]]] = []  # ("takeoff" | "land", who asked): answered when done
        self._replies: deque = deque()  # (text, address) to send (queued under the lock)
        self._t_motor: float | None = None  # when the motors started
        self._stats.update({"sdk_commands": 0, "rc": 0, "errors": 0, "auto_lands": 0, "state_sent": 0})

    # ---- the front end's hooks ------------------------------------------------------------------------------
    def _bind_ports(self) -> None:
        self._cmd = self._bind(socket.SOCK_DGRAM, self.command_port, "command")
        self._cmd.settimeout(0.02)
        self.kernel_stamps = enable_stamps(self._cmd)

    def _loops(self) -> list:
        return [self._nav_loop, self._cmd_loop]

    def _tick(self, now: float) -> None:
        """The no-command auto-land (under the lock)."""
        if self._phys.mode in _AIRBORNE and now - self._last_cmd > self.command_timeout:
            self._stats["auto_lands"] += 1
            self._last_error = f"no command for {self.command_timeout:g} s: landing"
            self._cmd_land()

    def _snapshot(self) -> Any:
        """The state's target, and the answers due to ``takeoff`` and ``land`` now done (under the lock)."""
        mode = self._phys.mode
        still = []
        for what, addr in self._waiting:
            done = mode in (CtrlState.HOVERING, CtrlState.FLYING) if what == "takeoff" else mode == CtrlState.LANDED
            failed = what == "takeoff" and mode in (CtrlState.LANDED, CtrlState.LANDING)
            if done or failed:
                self._replies.append(("ok" if done else "error Takeoff interrupted", addr))
            else:
                still.append((what, addr))
        self._waiting = still
        if mode == CtrlState.LANDED:
            self._t_motor = None
        elif self._t_motor is None:
            self._t_motor = time.monotonic()
        return self._state_to, self._t_motor

    def _send_sample(self, now: float, z_true: float, v: float, mode: int, snap: Any) -> None:
        target, t_motor = snap
        self._flush_replies()
        if target is None:
            return
        z_meas = self._measure(z_true, mode)
        if z_meas is None:
            return
        h = 10 * int(round(10 * max(z_true, 0.0)))  # cm, in 10 cm steps
        tof = int(round(100 * max(z_meas, 0.0)))
        run = 0 if t_motor is None else int(now - t_motor)
        line = (f"mid:-1;x:-100;y:-100;z:-100;mpry:0,0,0;pitch:0;roll:0;yaw:0;vgx:0;vgy:0;vgz:{int(round(100 * v))};"
                f"templ:60;temph:62;tof:{tof};h:{h};bat:87;baro:{100.0 + z_true:.2f};time:{run};agx:0.00;agy:0.00;"
                "agz:-1000.00;\r\n")
        try:
            self._cmd.sendto(line.encode("ascii"), target)
        except OSError:
            return
        with self._lock:
            self._stats["state_sent"] += 1

    # ---- commands ----------------------------------------------------------------------------------------------
    def _flush_replies(self) -> None:
        with self._lock:
            replies = list(self._replies)
            self._replies.clear()
        for text, addr in replies:
            try:
                self._cmd.sendto(text.encode("ascii"), addr)
            except OSError:
                pass

    def _cmd_loop(self) -> None:
        while not self._stop.is_set():
            self._flush_replies()
            try:
                data, addr, t = recv_stamped(self._cmd, 1024)
            except (socket.timeout, OSError):
                continue
            self._handle_text(data, addr, t)

    def _handle_text(self, data: bytes, addr: tuple[str, int], t: float) -> None:
        try:
            text = data.decode("ascii").strip()
        except UnicodeDecodeError:
            text = ""
        words = text.split()
        with self._lock:
            self._stats["datagrams"] += 1
            if not words or not text.isprintable():
                self._stats["bad"] += 1
                self._last_error = f"a datagram that is not an SDK command ({len(data)} bytes)"
                return
            self._advance(max(t, self._phys.t))  # t is the kernel's arrival stamp: the physics may be past it
            word = words[0].lower()
            if word == "rc":
                try:
                    sticks = [int(w) for w in words[1:]]
                    if len(sticks) != 4 or any(not -100 <= s <= 100 for s in sticks):
                        raise ValueError
                except ValueError:
                    self._stats["bad"] += 1
                    self._last_error = f"rc needs four whole numbers from -100 to 100, got {text[:60]!r}"
                    return
                self._last_cmd = t
                self._stats["commands"] += 1
                if not self._sdk:
                    return
                self._stats["rc"] += 1
                self._cmd_speed(sticks[2] * self.speed_per_percent, t)
                return
            self._last_cmd = t
            self._stats["commands"] += 1
            reply = self._answer(word, addr)
            if reply is not None:
                if reply.startswith("error"):
                    self._stats["errors"] += 1
                self._replies.append((reply, addr))
        self._flush_replies()

    def _answer(self, word: str, addr: tuple[str, int]) -> str | None:
        """The answer to one command (under the lock), or None when it comes later (take-off, landing)."""
        p = self._phys
        if word == "command":
            self._sdk = True
            self._stats["sdk_commands"] += 1
            self._state_to = (addr[0], self.state_port)
            return "ok"
        if not self._sdk:
            return "error Not in SDK mode"
        if word == "takeoff":
            if p.mode != CtrlState.LANDED or not self._cmd_takeoff():
                return "error Already flying"
            self._waiting.append(("takeoff", addr))
            return None
        if word == "land":
            if p.mode == CtrlState.LANDED:
                return "ok"
            self._cmd_land()
            self._waiting.append(("land", addr))
            return None
        if word == "emergency":
            self._cmd_emergency()
            return "ok"
        if word == "keepalive":
            return "ok"
        if word == "battery?":
            return "87"
        if word == "height?":
            return f"{int(round(10 * max(self._true_z(), 0.0)))}dm"
        if word == "time?":
            return "0s" if self._t_motor is None else f"{int(time.monotonic() - self._t_motor)}s"
        if word == "speed?":
            return f"{100 * self.speed_per_percent:.1f}"
        return "error Unknown command"

    def summary(self) -> dict[str, Any]:
        """As :meth:`DroneEmulator.summary`, with the protocol, the ports and the SDK mode."""
        out = super().summary()
        with self._lock:
            out.update({"protocol": "tello", "host": self.config.host, "state_port": self.state_port,
                        "state_to": None if self._state_to is None else list(self._state_to), "sdk": self._sdk,
                        "command_timeout": self.command_timeout, "speed_per_percent": self.speed_per_percent})
        return out
