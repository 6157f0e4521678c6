"""djitellopy flies delaykit's Tello emulator, inside two network namespaces this script makes (run by
tests/test_tello.py as ``unshare -n python tello_netns.py client``; not a test module itself).

djitellopy sends to the Tello's fixed address 192.168.10.1 and binds ports 8889 and 8890 on every interface, so
the emulator cannot share its namespace (its own port 8889 would clash).  So: this process (already in a fresh
namespace: the client's) starts the emulator in a second fresh namespace (``unshare -n``), joins the two by a veth
pair (client 192.168.10.2, emulator 192.168.10.1), flies, and prints one JSON line of what it saw.  No packet
leaves the two namespaces.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
import traceback


def sh(*args: str) -> None:
    subprocess.run(args, check=True, capture_output=True)


def emulator() -> None:
    """In the emulator's namespace: wait for the veth's end, address it, run the emulator until stdin closes."""
    print("ns", flush=True)
    deadline = time.monotonic() + 10
    while subprocess.run(["ip", "link", "show", "te0"], capture_output=True).returncode != 0:
        if time.monotonic() > deadline:
            sys.exit("no veth end te0 came")
        time.sleep(0.05)
    sh("ip", "link", "set", "lo", "up")
    sh("ip", "addr", "add", "192.168.10.1/24", "dev", "te0")
    sh("ip", "link", "set", "te0", "up")
    from delaykit.hardware.emulator_config import EmulatorConfig
    from delaykit.hardware.emulator_tello import TelloEmulator

    cfg = EmulatorConfig(host="192.168.10.1", rate=10.0, vehicle="lag", lag=0.0, noise=0.0, delay=0.1, seed=1,
                         takeoff_speed=1.5, landing_speed=1.5)
    with TelloEmulator(cfg, command_port=8889, state_port=8890, speed_per_percent=0.01) as emu:
        print("up", flush=True)
        sys.stdin.read()  # until the client closes it
        summary = emu.summary()
    print(json.dumps({"stats": summary["stats"], "sdk": summary["sdk"], "altitude": emu.altitude}), flush=True)


def client() -> None:
    sh("ip", "link", "set", "lo", "up")
    emu = subprocess.Popen(["unshare", "-n", sys.executable, __file__, "emulator"], stdin=subprocess.PIPE,
                           stdout=subprocess.PIPE, text=True, env=os.environ)
    try:
        assert emu.stdout.readline().strip() == "ns"
        sh("ip", "link", "add", "tc0", "type", "veth", "peer", "name", "te0", "netns", str(emu.pid))
        sh("ip", "addr", "add", "192.168.10.2/24", "dev", "tc0")
        sh("ip", "link", "set", "tc0", "up")
        assert emu.stdout.readline().strip() == "up"
        from djitellopy import Tello

        tello = Tello()  # 192.168.10.1, ports 8889 and 8890: its defaults, untouched
        tello.connect()
        tello.takeoff()
        time.sleep(0.5)
        h0, tof0 = tello.get_height(), tello.get_distance_tof()
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.0:  # half throttle up for a second
            tello.send_rc_control(0, 0, 50, 0)
            time.sleep(0.05)
        tello.send_rc_control(0, 0, 0, 0)
        time.sleep(0.6)
        h1, tof1 = tello.get_height(), tello.get_distance_tof()
        tello.land()
        emu.stdin.close()
        summary = json.loads(emu.stdout.readline())
        print(json.dumps({"h0": h0, "h1": h1, "tof0": tof0, "tof1": tof1, "emulator": summary}), flush=True)
        code = 0
    except BaseException:
        traceback.print_exc()
        code = 1
    finally:
        emu.kill()
        emu.wait()
    sys.stderr.flush()
    os._exit(code)  # (djitellopy's receiver threads never end)


if __name__ == "__main__":
    {"client": client, "emulator": emulator}[sys.argv[1]]()
