"""Kernel arrival stamps (delaykit.hardware.stamps): a reader that wakes late still gets the arrival time.
Loopback only."""

from __future__ import annotations

import socket
import time

import pytest

from delaykit.hardware.stamps import enable_stamps, recv_stamped


# real time: on a saturated machine the loopback delivery itself (a deferred softirq) can come after the 80 ms, and
# the stamp is then rightly late; run with the other timing tests, alone
@pytest.mark.realtime
def test_a_late_reader_gets_the_arrival_time_not_its_own():
    # the datagram is sent, then the reader sleeps 80 ms before reading: the time of reading is >= 80 ms late,
    # the kernel's stamp is the send time to within the loopback path (microseconds; 20 ms allows a busy machine)
    a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        a.bind(("127.0.0.1", 0))
        if not enable_stamps(a):
            pytest.skip("this platform gives no kernel arrival stamps (SO_TIMESTAMPNS)")
        t_sent = time.monotonic()
        b.sendto(b"x", a.getsockname())
        time.sleep(0.08)
        data, addr, t = recv_stamped(a, 64)
        t_read = time.monotonic()
        assert data == b"x" and addr[1] == b.getsockname()[1]
        assert t_read - t_sent >= 0.08
        assert t_sent <= t + 1e-6 and t - t_sent < 0.02, (t - t_sent)
    finally:
        a.close()
        b.close()


def test_without_stamps_the_time_of_reading_is_used():
    # a socket without the option: no ancillary data, so the reader's own clock (at least the 50 ms it slept)
    a = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    b = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        a.bind(("127.0.0.1", 0))
        t_sent = time.monotonic()
        b.sendto(b"y", a.getsockname())
        time.sleep(0.05)
        _, _, t = recv_stamped(a, 64)
        assert t - t_sent >= 0.05
    finally:
        a.close()
        b.close()
