"""The vehicle-link interface: what :func:`~delaykit.hardware.flight.fly` needs from any vehicle.

A link connects, waits until the vehicle is ready to fly, takes off to a hover, sends vertical-velocity commands
(m/s, up positive), receives altitude samples (:class:`AltitudeSample`: altitude and vertical speed up positive,
the vehicle's own time stamp when it sends one, and the arrival time on this machine), lands and closes.  The
flight loop, the laws, the delay monitor, ``autotune`` and ``demo`` only talk to this interface, so they fly every
link alike:

* :class:`~delaykit.hardware.ardrone_link.DroneLink`: an AR.Drone 2.0 (AT commands and navdata, UDP);
* :class:`~delaykit.hardware.mavlink.MavlinkLink`: a PX4 or ArduPilot autopilot over MAVLink (pymavlink);
* :class:`~delaykit.hardware.tello.TelloLink`: a DJI/Ryze Tello over its text SDK (UDP).

Errors: :class:`LinkError` when the vehicle does not answer (nothing flies), :class:`VehicleRefusedError` when
it answers no (a mode, arming, a take-off refused, or pre-arm checks that do not pass in time), with the
vehicle's own reason in the message.

Examples
--------
>>> s = AltitudeSample(z=1.2, vz=-0.05, vehicle_time=12.34, recv_time=100.0, seq=7)
>>> s
AltitudeSample(z=1.200 m, vz=-0.050 m/s, seq 7, vehicle 12.340 s, arrived 100.000000 s)
>>> s.to_dict()["vehicle_time"]
12.34
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, Callable

from ..errors import DelaykitError

__all__ = ["KeepAlive", "LinkError", "VehicleRefusedError", "AltitudeSample", "VehicleLink"]


class LinkError(DelaykitError, RuntimeError):
    """The vehicle does not answer (no navdata, no heartbeat), so nothing flies."""


class VehicleRefusedError(LinkError):
    """The vehicle answers no: a mode change, arming or take-off refused, or pre-arm checks that do not pass in
    time.  The message names the vehicle's own reason (its COMMAND_ACK result, its STATUSTEXT)."""


@dataclass(frozen=True, repr=False)
class AltitudeSample:
    """One altitude sample from the vehicle.

    Attributes
    ----------
    z : float
        Altitude, m, up positive.
    vz : float
        Vertical speed, m/s, up positive.
    vehicle_time : float or None
        The vehicle's own time stamp, s (MAVLink ``time_boot_ms``), or None when the protocol has none.
    recv_time : float
        Arrival time on this machine, s (monotonic clock; the kernel's stamp where the link has it).
    seq : int
        The sample's sequence number (the protocol's, or the link's count).
    """

    z: float
    vz: float
    vehicle_time: float | None
    recv_time: float
    seq: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"z": self.z, "vz": self.vz, "vehicle_time": self.vehicle_time, "recv_time": self.recv_time,
                "seq": self.seq}

    def __repr__(self) -> str:
        vt = "" if self.vehicle_time is None else f", vehicle {self.vehicle_time:.3f} s"
        return (f"AltitudeSample(z={self.z:.3f} m, vz={self.vz:.3f} m/s, seq {self.seq}{vt}, "
                f"arrived {self.recv_time:.6f} s)")


class VehicleLink(ABC):
    """A link to one vehicle (see the module docstring).  Subclasses set :attr:`name` and :attr:`has_vehicle_time`
    and keep :attr:`rejected` (messages refused: malformed, from another system, stale) and :attr:`rejections`
    (the first reasons, at most 100).

    The flight loop calls, in order: :meth:`connect`, :meth:`ready`, :meth:`takeoff`, then :meth:`recv` and
    :meth:`send_velocity` (or :meth:`hold`) in its loop, and at the end :meth:`land` (if a take-off was begun) and
    :meth:`close`.

    Examples
    --------
    >>> class Still(VehicleLink):
    ...     name = "still"
    ...     def connect(self, timeout, *, vmax, z_max, status=None): pass
    ...     def takeoff(self, timeout, status=None): pass
    ...     def send_velocity(self, vz): return 0.0
    ...     def recv(self, timeout): return None
    ...     def land(self, timeout): return True
    ...     def close(self): pass
    >>> link = Still()
    >>> link.ready(1.0), link.hold(), link.rejected
    (None, 0.0, 0)
    """

    #: what the link flies, for messages ("AR.Drone at 127.0.0.1", "ArduPilot over tcp:...")
    name: str = "vehicle"
    #: whether the samples carry the vehicle's own time stamp (the log then has a ``vehicle_time`` column)
    has_vehicle_time: bool = False
    #: what the samples are called in messages ("navdata", "LOCAL_POSITION_NED")
    sample_name: str = "altitude samples"

    def __init__(self) -> None:
        self.rejected = 0
        self.rejections: list[str] = []

    def _reject(self, why: str) -> None:
        """Count a refused message and keep its reason (the first 100)."""
        self.rejected += 1
        if len(self.rejections) < 100:
            self.rejections.append(why)

    @abstractmethod
    def connect(self, timeout: float, *, vmax: float, z_max: float,
                status: Callable[[str], None] | None = None) -> None:
        """Reach the vehicle and set it up for commands up to ``vmax`` m/s and altitudes up to ``z_max`` m; raise
        :class:`LinkError` if it does not answer within ``timeout`` seconds."""

    def ready(self, timeout: float, status: Callable[[str], None] | None = None) -> None:
        """Wait until the vehicle can take off (estimator, pre-arm checks), showing progress through ``status``;
        raise :class:`VehicleRefusedError` naming the vehicle's reason after ``timeout`` seconds.  Nothing to wait
        for by default."""
        del timeout, status  # (a vehicle with nothing to wait for)

    @abstractmethod
    def takeoff(self, timeout: float, status: Callable[[str], None] | None = None) -> None:
        """Arm and take off to a steady hover; return once hovering.  Raise :class:`VehicleRefusedError` if the
        vehicle refuses, :class:`LinkError` if it does not hover within ``timeout`` seconds."""

    @abstractmethod
    def send_velocity(self, vz: float) -> float:
        """Command the vertical speed ``vz`` (m/s, up positive); return the monotonic time it went out."""

    def hold(self) -> float:
        """Hold the altitude (a zero vertical speed); return the monotonic time the command went out."""
        return self.send_velocity(0.0)

    @abstractmethod
    def recv(self, timeout: float) -> AltitudeSample | None:
        """The next valid altitude sample, or None after ``timeout`` seconds without one."""

    @abstractmethod
    def land(self, timeout: float) -> bool:
        """Land; True once the vehicle says it landed within ``timeout`` seconds."""

    @abstractmethod
    def close(self) -> None:
        """Release the link (sockets, threads)."""


class KeepAlive:
    """A daemon thread that resends a link's last command whenever ``period`` seconds pass without one sent.

    Vehicles drop a setpoint that is not repeated (ArduPilot after about 3 s, PX4's offboard mode below 2 Hz, a
    Tello lands after 15 s), while the flight loop may pause between samples.  ``last_sent()`` gives the monotonic
    time of the last command, ``resend()`` sends it again; the thread stops at :meth:`stop`, or when ``resend``
    raises :class:`LinkError` (the link is gone: the flight loop reports it).

    Examples
    --------
    >>> import time
    >>> sent = []
    >>> k = KeepAlive("demo", 0.02, lambda: sent[-1] if sent else 0.0, lambda: sent.append(time.monotonic()))
    >>> k.start(); time.sleep(0.2); k.stop()
    >>> len(sent) >= 3
    True
    """

    def __init__(self, name: str, period: float, last_sent: Callable[[], float], resend: Callable[[], Any], *,
                 poll: float | None = None) -> None:
        self.name, self.period = name, float(period)
        self._poll = self.period / 2 if poll is None else min(self.period / 2, poll)
        self._last_sent, self._resend = last_sent, resend
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def _loop(self) -> None:
        while not self._stop.wait(self._poll):
            if time.monotonic() - self._last_sent() >= self.period:
                try:
                    self._resend()
                except LinkError:
                    return

    def start(self) -> None:
        """Start the thread (once; again after :meth:`stop`)."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._loop, daemon=True, name=self.name)
            self._thread.start()

    def stop(self) -> None:
        """Stop the thread and wait (up to a second) for it."""
        if self._thread is not None:
            self._stop.set()
            self._thread.join(timeout=1.0)
            self._thread = None
