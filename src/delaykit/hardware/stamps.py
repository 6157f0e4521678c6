"""Arrival times of datagrams as the kernel saw them, on the monotonic clock.

A thread that reads a socket can wake late: on a loaded machine (or while another thread holds the GIL) the
time it reads after ``recvfrom`` returns can be milliseconds after the datagram arrived.  For a delay
measurement that lateness is an error that nothing records.  Linux stamps every datagram on arrival when
``SO_TIMESTAMPNS`` is set; :func:`recv_stamped` reads that stamp (wall clock) and moves it onto
:func:`time.monotonic`, the clock the rest of delaykit uses, by the age of the datagram at the moment it is
read.  Where the option does not exist (macOS, Windows) it falls back to the time of reading, and
:func:`enable_stamps` returns False so that callers can say so.

Examples
--------
>>> import socket
>>> a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); a.bind(("127.0.0.1", 0))
>>> kernel = enable_stamps(a)
>>> b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
>>> _ = b.sendto(b"hi", a.getsockname())
>>> data, addr, t = recv_stamped(a, 64)
>>> data, t <= time.monotonic()
(b'hi', True)
>>> a.close(); b.close()
"""

from __future__ import annotations

import platform
import socket
import struct
import sys
import time

__all__ = ["enable_stamps", "recv_stamped"]

# Python does not export the option's number; Linux's asm-generic value (also x86's and ARM's) is 35
_LINUX_GENERIC = {"x86_64", "amd64", "i386", "i686", "aarch64", "arm64", "armv7l", "armv6l", "riscv64", "ppc64le",
                  "s390x", "loongarch64"}
_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", None)
if _TIMESTAMPNS is None and sys.platform.startswith("linux") and platform.machine().lower() in _LINUX_GENERIC:
    _TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@ll")  # struct timespec: tv_sec, tv_nsec, both C longs


def enable_stamps(sock: socket.socket) -> bool:
    """Ask the kernel to stamp each datagram ``sock`` receives.

    Parameters
    ----------
    sock : socket.socket
        A datagram socket.

    Returns
    -------
    bool
        True when the kernel stamps arrivals; False when :func:`recv_stamped` will use the time of reading.

    Examples
    --------
    >>> s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    >>> isinstance(enable_stamps(s), bool)
    True
    >>> s.close()
    """
    if _TIMESTAMPNS is None or not hasattr(sock, "recvmsg"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, _TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def recv_stamped(sock: socket.socket, bufsize: int) -> tuple[bytes, object, float]:
    """Receive one datagram with its arrival time on :func:`time.monotonic`.

    Parameters
    ----------
    sock : socket.socket
        A datagram socket (its timeout applies: :class:`socket.timeout` is raised as by ``recvfrom``).
    bufsize : int
        The largest datagram to read.

    Returns
    -------
    data : bytes
    addr : object
        The sender's address.
    t : float
        When the kernel received the datagram (monotonic seconds), never later than now; the time of reading
        where the kernel gave no stamp.

    See Also
    --------
    enable_stamps : switch the stamps on first.

    Examples
    --------
    >>> a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); a.bind(("127.0.0.1", 0)); a.settimeout(0.01)
    >>> try:
    ...     recv_stamped(a, 64)
    ... except socket.timeout:
    ...     print("nothing came")
    nothing came
    >>> a.close()
    """
    if _TIMESTAMPNS is None or not hasattr(sock, "recvmsg"):
        data, addr = sock.recvfrom(bufsize)
        return data, addr, time.monotonic()
    data, ancillary, _flags, addr = sock.recvmsg(bufsize, socket.CMSG_SPACE(_TIMESPEC.size))
    now_mono, now_wall = time.monotonic(), time.time()
    for level, kind, payload in ancillary:
        if level == socket.SOL_SOCKET and kind == _TIMESTAMPNS and len(payload) >= _TIMESPEC.size:
            sec, nsec = _TIMESPEC.unpack_from(payload)
            age = now_wall - (sec + 1e-9 * nsec)
            if 0.0 <= age < 5.0:  # a wall-clock step between the stamp and now: trust the time of reading
                return data, addr, now_mono - age
            break
    return data, addr, now_mono
