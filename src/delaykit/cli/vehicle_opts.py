"""The flight commands' choice of vehicle link (``--vehicle ardrone|mavlink``, ``--connect``): checked once here."""

from __future__ import annotations

from typing import Any, Callable, Optional

from ..errors import InvalidValueError

__all__ = ["VEHICLE_LINKS", "link_factory", "connection_is_loopback"]

#: the links the flight commands fly
VEHICLE_LINKS = ("ardrone", "mavlink")


def connection_is_loopback(connection: str) -> bool:
    """Whether a pymavlink connection string names a loopback address (the emulator), not a real vehicle.

    Examples
    --------
    >>> connection_is_loopback("tcp:127.0.0.1:5760"), connection_is_loopback("udpin:0.0.0.0:14550")
    (True, False)
    """
    import ipaddress

    parts = connection.split(":")
    if len(parts) != 3:
        return False  # a serial device: a real vehicle
    try:
        return ipaddress.ip_address(parts[1]).is_loopback
    except ValueError:
        return parts[1] == "localhost"


def link_factory(vehicle: str, connect: Optional[str], *, rate: float = 50.0, takeoff_height: float = 1.0,
                 option: str = "--vehicle") -> Optional[Callable[[], Any]]:
    """None for the AR.Drone (the command's ``--host`` and ports), or a function making the MAVLink link (checked
    now, so that a bad ``--connect`` fails before anything flies).

    Examples
    --------
    >>> link_factory("ardrone", None) is None
    True
    >>> link_factory("mavlink", "tcp:127.0.0.1:5760")().name
    'MAVLink vehicle on tcp:127.0.0.1:5760'
    """
    kind = vehicle.lower()
    if kind not in VEHICLE_LINKS:
        raise InvalidValueError(f"{option} must be one of {', '.join(VEHICLE_LINKS)}, got {vehicle!r}")
    if kind == "ardrone":
        if connect is not None:
            raise InvalidValueError(f"--connect is for {option} mavlink (the AR.Drone takes --host and its ports)")
        return None
    if connect is None:
        raise InvalidValueError(f"{option} mavlink needs --connect (pymavlink's connection string, e.g. "
                                "tcp:127.0.0.1:5760 or udpin:0.0.0.0:14550)")
    from ..hardware.mavlink import MavlinkLink

    MavlinkLink(connect, rate=rate, takeoff_height=takeoff_height)  # (the checks; nothing is opened)
    return lambda: MavlinkLink(connect, rate=rate, takeoff_height=takeoff_height)
