"""The flight commands' choice of vehicle link (``--vehicle ardrone|mavlink|tello``, ``--connect``): checked once
here."""

from __future__ import annotations

from typing import Any, Callable, Optional

from ..errors import InvalidValueError

__all__ = ["VEHICLE_LINKS", "link_factory", "connection_is_loopback", "default_host"]

#: the links the flight commands fly
VEHICLE_LINKS = ("ardrone", "mavlink", "tello")


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
                 option: str = "--vehicle", host: Optional[str] = None, command_port: int = 8889,
                 state_port: int = 8890, speed_per_percent: Optional[float] = None) -> Optional[Callable[[], Any]]:
    """None for the AR.Drone (the command's ``--host`` and ports), or a function making the MAVLink link or the
    Tello link (checked now, so that a bad ``--connect`` or Tello setting fails before anything flies).  The Tello
    link takes ``host`` (default its Wi-Fi address, 192.168.10.1), its ports and ``speed_per_percent``.

    Examples
    --------
    >>> link_factory("ardrone", None) is None
    True
    >>> link_factory("mavlink", "tcp:127.0.0.1:5760")().name
    'MAVLink vehicle on tcp:127.0.0.1:5760'
    >>> make = link_factory("tello", None, host="127.0.0.1", state_port=0, speed_per_percent=0.02)
    >>> link = make(); link.name, link.speed_per_percent
    ('Tello at 127.0.0.1', 0.02)
    >>> link.close()
    """
    kind = vehicle.lower()
    if kind not in VEHICLE_LINKS:
        raise InvalidValueError(f"{option} must be one of {', '.join(VEHICLE_LINKS)}, got {vehicle!r}")
    if kind == "tello":
        return _tello_factory(connect, option, host, command_port, state_port, speed_per_percent)
    if speed_per_percent is not None:
        raise InvalidValueError(f"--speed-per-percent is for {option} tello (its rc percent to m/s)")
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


def _tello_factory(connect: Optional[str], option: str, host: Optional[str], command_port: int, state_port: int,
                   speed_per_percent: Optional[float]) -> Callable[[], Any]:
    """A function making the Tello link, its settings checked now (it binds its state port only when made)."""
    from ..hardware.tello import SPEED_PER_PERCENT, TELLO_HOST, TelloLink
    from ..hardware.emulator_config import _check_port

    if connect is not None:
        raise InvalidValueError(f"--connect is for {option} mavlink (the Tello takes --host, default {TELLO_HOST})")
    spp = SPEED_PER_PERCENT if speed_per_percent is None else speed_per_percent
    _check_port("--command-port", command_port)
    _check_port("--state-port", state_port)
    kwargs = dict(command_port=command_port, state_port=state_port, speed_per_percent=spp)
    where = host or TELLO_HOST
    TelloLink(where, **kwargs).close()  # (the checks: binds the state port once and lets it go)
    return lambda: TelloLink(where, **kwargs)


def default_host(vehicle: str, host: Optional[str], command_port: int = 8889, state_port: int = 8890) -> str:
    """``--host`` or the vehicle's own address (an AR.Drone's 192.168.1.1, a Tello's 192.168.10.1); the Tello's
    ports refused for the other vehicles.

    Examples
    --------
    >>> default_host("tello", None), default_host("ardrone", None), default_host("tello", "127.0.0.1")
    ('192.168.10.1', '192.168.1.1', '127.0.0.1')
    """
    tello = vehicle.lower() == "tello"
    if not tello and (command_port != 8889 or state_port != 8890):
        raise InvalidValueError("--command-port and --state-port are for --vehicle tello")
    return host or ("192.168.10.1" if tello else "192.168.1.1")
