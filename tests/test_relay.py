"""The delay injector (delaykit.hardware.relay, ``delaykit relay``): loopback only, ports chosen by the OS.

The scheduling rules (FIFO, reorder, loss, trace, seed) are checked on the relay's own queue without sockets,
against the closed forms of the module docstring; the socket tests check what arrives, in which order, and never
earlier than the set delay (a lower bound, which no slowness of the machine can break); the upper bounds, which a
busy machine can break, are in the tests marked ``realtime``.
"""

from __future__ import annotations

import json
import re
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit.errors import InvalidTypeError, InvalidValueError, PortError, PortNumberError
from delaykit.hardware.relay import DelayRelay, Endpoint, RelaySummary, parse_endpoint
from delaykit.simulate.varying import DelayTrace, Jitter

EPS = 1e-3  # the kernel's arrival stamp is moved from the wall clock onto the monotonic one: microseconds apart


# ------------------------------------------------------------------------------------------ the helpers
def _udp(timeout: float = 3.0) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(timeout)
    return s


def _port(s: socket.socket) -> int:
    return s.getsockname()[1]


def _dues(relay: DelayRelay, d: str = "up") -> list[tuple[float, bytes]]:
    """The queued (due, payload) of direction ``d``, in the order they leave."""
    return [(due, p) for due, _, dd, p in sorted(relay._heap) if dd == d]


# ------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("text, error, words", [
    ("127.0.0.1:14550", InvalidValueError, "transport must be udp or tcp"),
    ("udp:127.0.0.1", InvalidValueError, "not TRANSPORT:HOST:PORT"),
    ("sctp:127.0.0.1:1", InvalidValueError, "transport must be udp or tcp"),
    ("udp:drone.example:1", InvalidValueError, "must be an IP address"),
    ("udp:127.0.0.1:70000", PortNumberError, "from 0 to 65535"),
    ("udp:127.0.0.1:-1", PortNumberError, "from 0 to 65535"),
    (14550, InvalidTypeError, "must be text"),
])
def test_bad_endpoints_are_refused_naming_the_text(text, error, words):
    with pytest.raises(error, match=words) as info:
        parse_endpoint(text, "--to")
    assert "--to" in str(info.value)


def test_endpoints_parse_ipv4_ipv6_and_localhost():
    assert parse_endpoint("UDP:localhost:5") == Endpoint("udp", "127.0.0.1", 5)
    assert parse_endpoint("tcp:[::1]:5760").family == socket.AF_INET6
    assert str(parse_endpoint("tcp:[::1]:5760")) == "tcp:[::1]:5760"


@pytest.mark.parametrize("kwargs, error, words", [
    ({"delay": -0.1}, InvalidValueError, "delay"),
    ({"delay": "0.2"}, InvalidTypeError, "delay"),
    ({"jitter": math.nan}, InvalidValueError, "jitter"),
    ({"loss": 1.5}, InvalidValueError, "loss"),
    ({"direction": "sideways"}, InvalidValueError, "up, down, both"),
    ({"seed": -3}, InvalidValueError, "seed"),
    ({"trace": "delays.csv"}, InvalidTypeError, "trace"),
    ({"trace": [(0.0, 0.1), (0.0, 0.2)]}, InvalidValueError, "increase"),
])
def test_bad_settings_are_refused_naming_the_value(kwargs, error, words):
    with pytest.raises(error, match=words):
        DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", **kwargs)


@pytest.mark.parametrize("priority, error", [(0, InvalidValueError), (100, InvalidValueError),
                                             (True, InvalidTypeError), (5.0, InvalidTypeError)])
def test_a_bad_priority_is_refused(priority, error):
    with pytest.raises(error, match="priority"):
        DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", priority=priority)


def test_a_priority_is_granted_or_the_summary_says_why_not():
    vehicle, gcs = _udp(), _udp()
    try:
        with DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{_port(vehicle)}", 0.01, priority=5) as relay:
            gcs.sendto(b"x", relay.address)
            assert vehicle.recvfrom(64)[0] == b"x"  # it forwards either way
            got = relay.scheduling
            if got == "SCHED_FIFO 5":  # granted: the thread runs under it (read from that thread's own id)
                assert os.sched_getscheduler(relay._thread.native_id) == os.SCHED_FIFO
        s = relay.summary()
    finally:
        vehicle.close()
        gcs.close()
    assert got == "SCHED_FIFO 5" or got.startswith("refused (")
    assert s.scheduling == got
    if hasattr(os, "sched_getscheduler"):
        assert os.sched_getscheduler(0) != os.SCHED_FIFO  # the caller's thread is left as it was


def test_tcp_refuses_loss_and_reorder_and_transports_must_match():
    with pytest.raises(InvalidValueError, match="cannot lose"):
        DelayRelay("tcp:127.0.0.1:0", "tcp:127.0.0.1:9", loss=0.1)
    with pytest.raises(InvalidValueError, match="in order"):
        DelayRelay("tcp:127.0.0.1:0", "tcp:127.0.0.1:9", reorder=True)
    with pytest.raises(InvalidValueError, match="same transport"):
        DelayRelay("udp:127.0.0.1:0", "tcp:127.0.0.1:9")
    with pytest.raises(PortNumberError, match="needs a port"):
        DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:0")


def test_a_taken_port_is_a_port_error():
    taken = _udp()
    try:
        with pytest.raises(PortError, match=f"{_port(taken)}.*in use"):
            DelayRelay(f"udp:127.0.0.1:{_port(taken)}", "udp:127.0.0.1:9").start()
    finally:
        taken.close()


# ------------------------------------------------------------------------- the schedule, without sockets
def test_fifo_holds_a_packet_behind_the_one_ahead():
    # a jitter of 50 ms on packets 5 ms apart: each due time is max(arrival + delay, the previous due time), the
    # running maximum of the free due times (module docstring); with reorder they are the free ones themselves
    arrivals = 100.0 + 0.005 * np.arange(200)
    fifo = DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", 0.1, jitter=0.05, seed=3)
    free = DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", 0.1, jitter=0.05, seed=3, reorder=True)
    for r in (fifo, free):
        r._t0 = 100.0
        for k, t in enumerate(arrivals):
            r._schedule("up", t, k.to_bytes(2, "big"))
    d_free = np.array([due for due, p in sorted(_dues(free), key=lambda x: x[1])]) - arrivals
    assert d_free.min() >= 0.1 and d_free.max() <= 0.15  # the uniform extra is in [0, jitter]
    assert 0.12 < d_free.mean() < 0.13  # its mean, jitter / 2 = 25 ms, to 5 standard errors (14.4 ms / sqrt 200)
    order_free = [int.from_bytes(p, "big") for _, p in _dues(free)]
    assert order_free != sorted(order_free)  # with reorder, some overtake
    dues = [due for due, _ in _dues(fifo)]
    assert [int.from_bytes(p, "big") for _, p in _dues(fifo)] == list(range(200))  # FIFO: in order
    assert np.allclose(dues, np.maximum.accumulate(arrivals + d_free), rtol=0, atol=1e-12)  # same draws, same seed


def test_loss_rate_is_within_a_binomial_bound_and_the_seed_repeats_it():
    n, p = 4000, 0.2
    kept = []
    for _ in range(2):
        r = DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", 0.0, loss=p, seed=11)
        kept.append([r._schedule("up", float(k), b"x") for k in range(n)])
        c = r.counts["up"]
        assert c["received"] == n and c["dropped"] + len(r._heap) == n
    dropped = n - sum(kept[0])
    assert abs(dropped - n * p) < 5 * math.sqrt(n * p * (1 - p))  # 5 standard deviations of Binomial(n, p)
    assert kept[0] == kept[1]  # the same seed drops the same packets


def test_each_direction_draws_from_its_own_generator():
    # the k-th packet of one direction has the same fate whatever the other direction carried (module docstring)
    a = DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", 0.0, jitter=0.1, loss=0.3, seed=5)
    b = DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", 0.0, jitter=0.1, loss=0.3, seed=5)
    for k in range(50):
        a._schedule("up", float(k), b"%d" % k)
        b._schedule("down", float(k) + 0.5, b"d")  # b also carries traffic the other way
        b._schedule("up", float(k), b"%d" % k)
    assert _dues(a) == _dues(b)


def test_the_trace_is_added_to_the_delay_from_the_start():
    # the delay = 0.05 + the trace record in force at t since start (held until the next record)
    trace = DelayTrace([10.0, 10.3, 10.6], [0.0, 0.2, 0.1])  # replayed from its first record, 10.0
    r = DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", 0.05, trace=trace, reorder=True)
    r._t0 = 50.0
    for t in (0.0, 0.29, 0.31, 0.59, 0.61, 5.0):  # (not on a record: 50.3 - 50 is below 0.3 in floats)
        r._schedule("up", 50.0 + t, b"%.2f" % t)
    got = {float(p): round(due - 50.0 - float(p), 12) for due, p in _dues(r)}
    assert got == {0.0: 0.05, 0.29: 0.05, 0.31: 0.25, 0.59: 0.25, 0.61: 0.15, 5.0: 0.15}


def test_only_the_named_direction_is_delayed_and_lossy():
    r = DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", 0.3, loss=1.0, direction="up")
    assert r._schedule("up", 1.0, b"u") is False  # lost: loss 1
    assert r._schedule("down", 1.0, b"d") is True
    assert _dues(r, "down") == [(1.0, b"d")]  # at once


def test_a_delay_model_is_taken_as_it_is():
    r = DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:9", Jitter(0.2, "exponential", scale=0.01), seed=2)
    r._schedule("up", 0.0, b"x")
    assert _dues(r)[0][0] >= 0.2 and r.summary().delay["kind"] == "jitter"


# --------------------------------------------------------------------------------------- UDP on loopback
def test_udp_both_directions_in_order_never_early():
    vehicle, gcs = _udp(), _udp()
    n, delay = 15, 0.08
    try:
        with DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{_port(vehicle)}", delay) as relay:
            sent = {}
            for k in range(n):
                sent[k] = time.monotonic()
                gcs.sendto(k.to_bytes(2, "big"), relay.address)
                time.sleep(0.01)
            got, back = [], {}
            for _ in range(n):
                data, addr = vehicle.recvfrom(64)
                k = int.from_bytes(data, "big")
                got.append(k)
                assert time.monotonic() - sent[k] >= delay - EPS  # never early
                vehicle.sendto(data + b"!", addr)  # the reply goes to the relay's socket
                back[k] = time.monotonic()
            echoed = []
            for _ in range(n):
                data, addr = gcs.recvfrom(64)
                assert addr == relay.address  # the reply comes from the address the ground station used
                k = int.from_bytes(data[:2], "big")
                echoed.append(k)
                assert time.monotonic() - back[k] >= delay - EPS
        s = relay.summary()
    finally:
        vehicle.close()
        gcs.close()
    assert got == list(range(n)) and echoed == list(range(n))
    assert (s.up.received, s.up.forwarded, s.down.received, s.down.forwarded) == (n, n, n, n)
    assert s.up.bytes == 2 * n and s.down.bytes == 3 * n and s.up.unsent == s.down.unsent == 0
    assert s.up.excess_p50_ms is not None and s.up.excess_p50_ms >= 0
    assert isinstance(s, RelaySummary) and repr(s).startswith("RelaySummary(udp:127.0.0.1:") and "\n" not in repr(s)
    assert s.to_dict()["up"] == s.up.to_dict() and json.dumps(s.to_dict(), allow_nan=False)  # strict JSON


def test_udp_jitter_keeps_the_order_on_the_wire_unless_reorder():
    # a jitter of 40 ms on datagrams 2 ms apart: in order, none before the base delay; with reorder, some overtake
    # (seed 1 draws an extra 34 ms larger than the next packet's: it is overtaken unless the sends are > 34 ms apart)
    for reorder in (False, True):
        vehicle, gcs = _udp(), _udp()
        try:
            with DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{_port(vehicle)}", 0.02, jitter=0.04, seed=1,
                            reorder=reorder) as relay:
                sent = {}
                for k in range(40):
                    sent[k] = time.monotonic()
                    gcs.sendto(k.to_bytes(2, "big"), relay.address)
                    time.sleep(0.002)
                got = []
                for _ in range(40):
                    data, _ = vehicle.recvfrom(64)
                    got.append(int.from_bytes(data, "big"))
                    assert time.monotonic() - sent[got[-1]] >= 0.02 - EPS
        finally:
            vehicle.close()
            gcs.close()
        assert sorted(got) == list(range(40))
        assert (got == list(range(40))) is not reorder


def test_udp_loss_counts_add_up_on_the_wire():
    vehicle, gcs = _udp(timeout=0.5), _udp()
    n = 200
    try:
        with DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{_port(vehicle)}", 0.0, loss=0.25, seed=4) as relay:
            for k in range(n):
                gcs.sendto(k.to_bytes(2, "big"), relay.address)
                if k % 20 == 19:
                    time.sleep(0.002)
            got = []
            try:
                while True:
                    got.append(int.from_bytes(vehicle.recvfrom(64)[0], "big"))
            except socket.timeout:
                pass
        s = relay.summary()
    finally:
        vehicle.close()
        gcs.close()
    assert s.up.received == n and s.up.forwarded + s.up.dropped == n
    assert len(got) == s.up.forwarded and got == sorted(got)
    assert abs(s.up.dropped - n * 0.25) < 5 * math.sqrt(n * 0.25 * 0.75)  # Binomial(200, 0.25), 5 sd


def test_a_reply_before_any_ground_station_is_unroutable_and_stop_counts_the_waiting():
    vehicle, gcs, stranger = _udp(), _udp(), _udp()
    try:
        relay = DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{_port(vehicle)}", 5.0, direction="up").start()
        try:
            up_addr = relay._up_sock.getsockname()
            stranger.sendto(b"not the vehicle", up_addr)  # the relay's vehicle side hears the vehicle alone
            vehicle.sendto(b"hello?", up_addr)  # no ground station yet: nowhere to send it
            _wait(lambda: relay.counts["down"]["unroutable"] == 1)
            gcs.sendto(b"a", relay.address)  # waits 5 s: still queued at stop()
            _wait(lambda: relay.counts["up"]["received"] == 1)
        finally:
            relay.stop()
        s = relay.summary()
    finally:
        for x in (vehicle, gcs, stranger):
            x.close()
    assert (s.down.received, s.down.unroutable, s.down.forwarded) == (1, 1, 0)
    assert (s.up.received, s.up.unsent, s.up.forwarded) == (1, 1, 0)
    assert not relay.running


def _wait(condition, timeout: float = 3.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "the relay did not get there"
        time.sleep(0.005)


# --------------------------------------------------------------------------------------- TCP on loopback
def _echo_server() -> tuple[socket.socket, threading.Thread]:
    """A TCP 'vehicle' that echoes what it reads, once, and closes when the other side does."""
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    srv.settimeout(5.0)

    def serve() -> None:
        try:
            conn, _ = srv.accept()
        except OSError:
            return
        with conn:
            conn.settimeout(5.0)
            while True:
                data = conn.recv(4096)
                if not data:
                    break
                conn.sendall(data)

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    return srv, th


def test_tcp_streams_both_ways_with_the_delay_and_closes_cleanly():
    srv, th = _echo_server()
    delay = 0.05
    try:
        with DelayRelay("tcp:127.0.0.1:0", f"tcp:127.0.0.1:{_port(srv)}", delay) as relay:
            c = socket.create_connection(relay.address, timeout=5.0)
            payload = bytes(range(256)) * 40  # 10 kB, several chunks
            t0 = time.monotonic()
            c.sendall(payload[:100])
            first = c.recv(100)
            assert time.monotonic() - t0 >= 2 * delay - EPS  # there and back, never early
            c.sendall(payload[100:])
            c.shutdown(socket.SHUT_WR)  # the end of the stream is relayed after the data
            got = first
            while True:
                data = c.recv(65536)
                if not data:
                    break
                got += data
            c.close()
            th.join(5.0)
            _wait(lambda: relay.counts["down"]["bytes"] == len(payload) and not relay._conns)
        s = relay.summary()
    finally:
        srv.close()
    assert got == payload  # every byte, in order
    assert s.connections == 1 and s.up.bytes == s.down.bytes == len(payload)
    assert s.up.forwarded == s.up.received and s.down.forwarded == s.down.received


def test_tcp_a_vehicle_that_refuses_closes_the_ground_station_and_counts_an_error():
    closed = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    closed.bind(("127.0.0.1", 0))  # bound, never listening: a connection is refused
    try:
        with DelayRelay("tcp:127.0.0.1:0", f"tcp:127.0.0.1:{_port(closed)}", 0.01) as relay:
            c = socket.create_connection(relay.address, timeout=5.0)
            assert c.recv(10) == b""  # closed by the relay
            c.close()
            _wait(lambda: relay.counts["up"]["errors"] == 1)
            assert relay.summary().connections == 0
    finally:
        closed.close()


# ------------------------------------------------------------------------------------------- real time
@pytest.mark.realtime
def test_the_delays_are_the_set_ones_on_loopback():
    # 0.1 s up and a 0.3 s trace step from 0.4 s: each packet's one-way time is within 20 ms above its set delay
    # (loopback adds microseconds; 20 ms allows a busy machine); direction up: the replies come back at once
    vehicle, gcs = _udp(), _udp()
    try:
        with DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{_port(vehicle)}", 0.1,
                        trace=[(0.0, 0.0), (0.4, 0.3)], direction="up") as relay:
            oneway = []
            for k in range(8):
                t_send = time.monotonic()
                gcs.sendto(b"%d" % k, relay.address)
                data, addr = vehicle.recvfrom(64)
                oneway.append((t_send - relay._t0, time.monotonic() - t_send))
                vehicle.sendto(b"r", addr)
                t_back = time.monotonic()
                gcs.recvfrom(64)
                assert time.monotonic() - t_back < 0.02  # not delayed
    finally:
        vehicle.close()
        gcs.close()
    for since, d in oneway:
        want = 0.1 + (0.3 if since >= 0.4 else 0.0)
        assert want - EPS <= d < want + 0.02, (since, d, want)
    assert any(since >= 0.4 for since, _ in oneway) and oneway[0][0] < 0.4


# --------------------------------------------------------------------------------------------- the CLI
def test_cli_bad_input_is_one_line_and_status_2():
    from delaykit.cli.app import app

    res = CliRunner().invoke(app, ["relay", "--listen", "udp:127.0.0.1", "--delay", "0.2"])
    assert res.exit_code == 2 and "error: --listen 'udp:127.0.0.1' is not TRANSPORT:HOST:PORT" in res.output
    res = CliRunner().invoke(app, ["relay", "--delay", "0.2", "--loss", "2"])
    assert res.exit_code == 2 and "--loss must be at most 1" in res.output and "Traceback" not in res.output


def test_cli_json_summary_after_duration():
    from delaykit.cli.app import app

    res = CliRunner().invoke(app, ["relay", "--listen", "udp:127.0.0.1:0", "--to", "udp:127.0.0.1:9", "--delay",
                                   "0.2", "--jitter", "0.02", "--seed", "1", "--duration", "0.2", "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["status"] == "ok" and d["up"]["received"] == 0 and d["direction"] == "both" and d["seed"] == 1
    assert d["delay"]["kind"] == "sum" and d["jitter"] == 0.02


def test_cli_table_after_duration():
    from delaykit.cli.app import app

    res = CliRunner().invoke(app, ["relay", "--listen", "udp:127.0.0.1:0", "--to", "udp:127.0.0.1:9", "--delay",
                                   "0.1", "--direction", "down", "--duration", "0.1"], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    rows = [line for line in res.stdout.splitlines() if line.strip("│ ").startswith(("up", "down"))]
    assert len(rows) == 2 and " no " in rows[0] and " yes " in rows[1]  # only down is delayed


def test_cli_a_refused_priority_is_a_warning_and_in_the_summary(monkeypatch):
    from delaykit.cli.app import app

    def refuse(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse, raising=False)
    res = CliRunner().invoke(app, ["relay", "--listen", "udp:127.0.0.1:0", "--to", "udp:127.0.0.1:9", "--delay",
                                   "0.1", "--priority", "20", "--duration", "0.1", "--json"])
    assert res.exit_code == 0, res.output
    assert "warning: --priority 20 refused (Operation not permitted)" in res.stderr
    assert json.loads(res.stdout)["scheduling"] == "refused (Operation not permitted)"


def test_cli_sigterm_prints_the_summary(tmp_path):
    # a real process: SIGTERM ends it cleanly with the summary, status 0
    vehicle, gcs = _udp(), _udp()
    trace = tmp_path / "d.csv"
    trace.write_text("t,delay\n0,0.01\n")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    proc = subprocess.Popen([sys.executable, "-m", "delaykit.cli", "relay", "--listen", "udp:127.0.0.1:0", "--to",
                             f"udp:127.0.0.1:{_port(vehicle)}", "--delay", "0.01", "--trace", str(trace), "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stderr.readline()  # "relay running: DelayRelay(udp:127.0.0.1:PORT -> ...)"
        port = int(re.search(r"\((?:udp|tcp):[^ ]*:(\d+) ->", line).group(1))
        gcs.sendto(b"x", ("127.0.0.1", port))
        assert vehicle.recvfrom(64)[0] == b"x"
        proc.send_signal(signal.SIGTERM)
        stdout, _ = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
        vehicle.close()
        gcs.close()
    assert proc.returncode == 0
    d = json.loads(stdout)
    assert d["up"]["forwarded"] == 1 and d["delay"]["parts"][1]["kind"] == "trace"


# ----------------------------------------------------------------------------- the paper's use, end to end
@pytest.mark.slow
@pytest.mark.realtime
def test_a_flight_through_the_relay_estimates_the_added_delay(tmp_path):
    # the AR.Drone emulator (actuator delay 0.20 s) flown by `delaykit fly` through two relays: the AT commands
    # 0.08 s up, the navdata 0.04 s down; `delaykit estimate` must find 0.20 + 0.08 + 0.04 s plus the flight loop's
    # own mean latency (as tests/test_flight.py's estimate of the emulator alone, and within its 15 ms)
    from typer.testing import CliRunner

    from delaykit.cli import app
    from delaykit.hardware.emulator import DroneEmulator, EmulatorConfig

    runner = CliRunner()
    cfg = EmulatorConfig(at_port=0, navdata_port=0, video_port=0, control_port=0, delay=0.20, vehicle="lag",
                         lag=0.05, noise=0.004, seed=5)
    with DroneEmulator(cfg) as emu, \
            DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{emu.ports['at']}", 0.08, direction="up") as at, \
            DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{emu.ports['navdata']}", 0.04, direction="down") as nav:
        res = runner.invoke(app, ["fly", "--host", "127.0.0.1", "--at-port", str(at.address[1]), "--navdata-port",
                                  str(nav.address[1]), "--kp", "1.31", "--steps", "1,-1", "--duration", "6",
                                  "--hover", "1", "--log", str(tmp_path / "f.csv"), "--json"])
        assert res.exit_code == 0, res.output
        flight = json.loads(res.stdout)
    assert at.summary().up.forwarded > 100 and nav.summary().down.forwarded > 100
    assert at.summary().up.dropped == nav.summary().down.dropped == 0
    res = runner.invoke(app, ["estimate", *flight["logs"], "--kp", "1.31", "--period",
                              f"{flight['packet_interval']:.6f}", "--free", "lag", "--json"])
    assert res.exit_code == 0, res.output
    est = json.loads(res.stdout)["pooled"]
    latency = np.concatenate([np.genfromtxt(f, delimiter=",", names=True)["latency_ms"] for f in flight["logs"]])
    truth = 0.20 + 0.08 + 0.04 + float(np.nanmean(latency)) / 1e3
    assert abs(est["delay"] - truth) < 0.015, (est, truth)
