"""Benchmark: the MAVLink link's own CPU cost per 50 Hz tick (target: under 0.5 ms).

One tick of a flight on :class:`delaykit.hardware.mavlink.MavlinkLink` is: receive a ``LOCAL_POSITION_NED`` (read
the datagram, parse it, check it, make the sample) and send a velocity-only ``SET_POSITION_TARGET_LOCAL_NED``.
Here a stand-in vehicle on loopback UDP hands the link one position datagram per tick (pre-encoded, its
``time_boot_ms`` 20 ms apart) and the link answers each at once, through its real code path (pymavlink's
connection, the sockets, the counters), as fast as it can: no sleeping, so the process CPU time per tick is the
link's cost plus the stand-in's ``sendto``, which is measured alone and subtracted.  The codec alone (encode a
setpoint, decode a position) is reported beside it.

Run: ``python benchmarks/bench_mavlink.py [--ticks N] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mav2  # noqa: E402

from delaykit.hardware.mavlink import MavlinkLink, encode_velocity  # noqa: E402

TARGET_MS = 0.5


def _cpu_per_tick(fn, n: int) -> float:
    t0 = time.process_time()
    fn(n)
    return (time.process_time() - t0) / n


def run(ticks: int = 5000) -> dict:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    link = MavlinkLink(f"udpin:127.0.0.1:{port}")
    link._open()
    vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    vehicle.bind(("127.0.0.1", 0))
    vehicle.setblocking(False)
    enc = mav2.MAVLink(None, 1, 1)
    heartbeat = enc.heartbeat_encode(2, 3, 0, 0, 3).pack(enc)
    vehicle.sendto(heartbeat, ("127.0.0.1", port))
    link.recv(0.2)  # (the heartbeat names the vehicle; no position yet)
    packets = [enc.local_position_ned_encode(20 * (k + 1), 0.0, 0.0, -1.0 - 1e-4 * k, 0.0, 0.0, -0.01).pack(enc)
               for k in range(3 * ticks + 10)]
    it = iter(packets)
    dest = ("127.0.0.1", port)

    def drain() -> None:
        try:
            while True:
                vehicle.recv(4096)
        except BlockingIOError:
            pass

    def flight(n: int) -> None:
        for _ in range(n):
            vehicle.sendto(next(it), dest)
            sample = link.recv(1.0)
            link.send_velocity(0.1 * (sample.z - 1.0))
            if _ % 64 == 0:
                drain()

    def sends_only(n: int) -> None:
        for _ in range(n):
            vehicle.sendto(packets[0], ("127.0.0.1", 9))  # (discard port: the same system call, nobody reads it)

    flight(200)  # warm-up
    per_tick = _cpu_per_tick(flight, ticks)
    sendto = _cpu_per_tick(sends_only, ticks)
    counts = dict(link.counts)
    link.close()
    vehicle.close()

    dec = mav2.MAVLink(None, 255, 190)
    genc = mav2.MAVLink(None, 255, 190)

    def codec(n: int) -> None:
        for k in range(n):
            encode_velocity(genc, 0.1)
            dec.parse_buffer(packets[k % len(packets)])

    codec_tick = _cpu_per_tick(codec, ticks)
    link_ms = 1e3 * max(per_tick - sendto, 0.0)
    return {"ticks": ticks, "link_cpu_ms_per_tick": link_ms, "codec_cpu_ms_per_tick": 1e3 * codec_tick,
            "stand_in_sendto_ms": 1e3 * sendto, "target_ms": TARGET_MS, "met": link_ms < TARGET_MS,
            "share_of_50hz_tick": link_ms / 20.0, "rejected": counts}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ticks", type=int, default=5000)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    r = run(a.ticks)
    print(f"MAVLink link, CPU per 50 Hz tick (receive LOCAL_POSITION_NED + send a velocity setpoint): "
          f"{r['link_cpu_ms_per_tick']:.3f} ms (target < {TARGET_MS} ms: {'met' if r['met'] else 'NOT met'}; "
          f"{100 * r['share_of_50hz_tick']:.1f} % of the 20 ms tick); codec alone {r['codec_cpu_ms_per_tick']:.3f} ms; "
          f"over {r['ticks']} ticks")
    if a.json:
        a.json.write_text(json.dumps(r, indent=1))


if __name__ == "__main__":
    main()
