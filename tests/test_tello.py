"""The Tello: delaykit's Tello link flies the emulator's Tello front end, the emulator lands by itself without
commands, garbage is counted, a lost link ends the flight with status 1 and the log intact, and djitellopy (a
client delaykit did not write) flies the emulator inside network namespaces the test makes.  Loopback only,
except the djitellopy test's private namespaces."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from delaykit import InvalidValueError, LinkError, VehicleRefusedError
from delaykit.hardware.ardrone import CtrlState
from delaykit.hardware.emulator_config import EmulatorConfig
from delaykit.hardware.emulator_tello import TelloEmulator
from delaykit.hardware.flight import FlightPlan, fly
from delaykit.hardware.tello import TelloLink, parse_state, rc_command

# a vehicle whose speed is its command (no lag, no noise, no wander): altitudes are integrals of the commands
EXACT = dict(rate=10.0, vehicle="lag", lag=0.0, noise=0.0, delay=0.1, seed=1, takeoff_speed=1.5, landing_speed=1.5)


def _pair(spp: float = 0.01, **kw) -> tuple[TelloEmulator, TelloLink]:
    """An emulator on a free command port and a link listening for its state on a free port (loopback)."""
    link = TelloLink("127.0.0.1", command_port=8889, state_port=0, speed_per_percent=spp,
                     **kw.pop("link", {}))
    emu = TelloEmulator(EmulatorConfig(**{**EXACT, **kw.pop("cfg", {})}), command_port=0,
                        state_port=link.state_port, speed_per_percent=spp, **kw).start()
    link.command_port = emu.ports["command"]
    return emu, link


def _free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _read_log(path):
    return np.genfromtxt(path, delimiter=",", names=True)


# ---- no network ------------------------------------------------------------------------------------------------
def test_rc_throttle_is_the_rounded_clipped_percent():
    # c = clip(round(v / speed_per_percent), -100, 100), by hand
    assert rc_command(0.25, 0.01) == "rc 0 0 25 0"
    assert rc_command(-0.304, 0.01) == "rc 0 0 -30 0"
    assert rc_command(0.5, 0.02) == "rc 0 0 25 0"
    assert rc_command(2.0, 0.01) == "rc 0 0 100 0" and rc_command(-2.0, 0.01) == "rc 0 0 -100 0"
    assert rc_command(float("nan"), 0.01) == "rc 0 0 0 0"


def test_state_lines_parse_and_bad_ones_are_clear_errors():
    # the SDK 2.0 state line (fields as the SDK guide lists them)
    line = (b"mid:-1;x:-100;y:-100;z:-100;mpry:0,0,0;pitch:1;roll:-2;yaw:3;vgx:0;vgy:0;vgz:-15;templ:60;temph:62;"
            b"tof:118;h:120;bat:87;baro:101.23;time:7;agx:0.00;agy:1.00;agz:-998.00;\r\n")
    st = parse_state(line)
    assert (st["tof"], st["h"], st["vgz"], st["baro"], st["mpry"]) == (118.0, 120.0, -15.0, 101.23, "0,0,0")
    for bad in (b"\xff\xfe\x00", b"tof:abc;", b"garbage", b"", b"tof:inf;"):
        with pytest.raises(InvalidValueError):
            parse_state(bad)


def test_bad_settings_are_clear_errors():
    with pytest.raises(InvalidValueError, match="speed_per_percent"):
        TelloLink("127.0.0.1", state_port=0, speed_per_percent=0.0)
    with pytest.raises(InvalidValueError, match="altitude must be one of tof, h"):
        TelloLink("127.0.0.1", state_port=0, altitude="baro")
    with pytest.raises(InvalidValueError, match="command port"):
        TelloLink("127.0.0.1", command_port=0, state_port=0)
    with pytest.raises(InvalidValueError, match="IPv6"):
        TelloLink("::1", state_port=0)
    with pytest.raises(InvalidValueError, match="state_port"):
        TelloEmulator(command_port=0, state_port=0)
    with pytest.raises(InvalidValueError, match="command_timeout"):
        TelloEmulator(command_port=0, command_timeout=-1.0)


def test_cli_errors_exit_2_and_help_names_tello():
    from typer.testing import CliRunner

    from delaykit.cli import app

    r = CliRunner()
    for args, words in ((["fly", "--vehicle", "tello", "--kp", "1", "--speed-per-percent", "-1"], "speed_per_percent"),
                        (["fly", "--vehicle", "ardrone", "--kp", "1", "--speed-per-percent", "0.02"], "tello"),
                        (["fly", "--vehicle", "tello", "--kp", "1", "--connect", "tcp:127.0.0.1:5760"], "--connect"),
                        (["fly", "--kp", "1", "--state-port", "9000"], "--vehicle tello"),
                        (["emulate", "--protocol", "tello", "--to", "udp:127.0.0.1:14540"], "--protocol mavlink"),
                        (["emulate", "--protocol", "tello", "--command-timeout", "0"], "command_timeout"),
                        (["emulate", "--state-port", "9000"], "--protocol tello")):
        res = r.invoke(app, args)
        assert res.exit_code == 2, (args, res.output)
        assert words in res.output and "Traceback" not in res.output, (args, res.output)
    assert "tello" in r.invoke(app, ["fly", "--help"]).output
    assert "tello" in r.invoke(app, ["emulate", "--help"]).output


def test_a_state_port_in_use_is_a_link_error_naming_it():
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    port = taken.getsockname()[1]
    try:
        with pytest.raises(LinkError, match=f"127.0.0.1:{port}: Address already in use"):
            TelloLink("127.0.0.1", state_port=port)
    finally:
        taken.close()


def test_vmax_beyond_full_throttle_is_refused_before_anything_is_sent():
    link = TelloLink("127.0.0.1", state_port=0, speed_per_percent=0.005)
    try:
        with pytest.raises(InvalidValueError, match="above what rc can command"):
            link.connect(0.1, vmax=1.0, z_max=3.0)
    finally:
        link.close()


# ---- on loopback, in real time -----------------------------------------------------------------------------------
@pytest.mark.realtime
def test_delaykits_link_flies_a_p_step(tmp_path):
    emu, link = _pair(spp=0.02)
    seen_during: list[int] = []

    def status(msg: str) -> None:
        if msg == "landing":  # the log is flushed as it is written: its rows are on disk before the flight ends
            seen_during.append(sum(1 for _ in open(tmp_path / "f.csv")))

    try:
        res = fly(FlightPlan(kp=1.5, steps=(0.5,), step_duration=3.5, hover_time=0.5), tmp_path / "f.csv",
                  link=link, status=status)
        landed = (emu.mode, emu.altitude)
    finally:
        emu.stop()
    assert res.completed, res.reason
    assert landed == (CtrlState.LANDED, 0.0)
    log = _read_log(res.logs[0])
    # the P loop 1.5 e^(-0.1 s)/s sampled at 10 Hz: a time constant of about 1/1.5 s, so 3.5 s after the step (5
    # of them) the error is e^-5 of 0.5 m, 3 mm, plus the rc's 2 cm/s quantisation held for a sample or two
    assert abs(log["z"][-5:].mean() - log["z_ref"][-1]) < 0.03
    assert log["z"][0] < log["z_ref"][-1] - 0.4  # (the log starts at the hover, half a metre below)
    # both time stamps of this link: the loop's time and the kernel's arrival time (the Tello has no clock to send)
    assert "vehicle_time" not in log.dtype.names
    t, rt = log["t"], log["recv_time"]
    assert np.all(np.diff(rt) > 0) and np.allclose(np.diff(t), np.diff(rt), atol=2e-6)
    assert 0.07 < np.median(np.diff(rt)) < 0.13  # the state's 10 Hz
    assert seen_during and seen_during[0] == len(log) + 1  # header + every row, before the landing
    # the commands were rc percentages of 0.02 m/s: the emulator counted every one
    assert emu.stats["rc"] >= res.packets


@pytest.mark.realtime
def test_the_emulator_lands_by_itself_without_commands_and_the_keepalive_prevents_it():
    # a plain client: command, takeoff, then silence; the emulator's timeout is 1 s here (a Tello's is 15 s)
    emu = TelloEmulator(EmulatorConfig(**EXACT), command_port=0, state_port=_free_udp_port(),
                        command_timeout=1.0).start()
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(3.0)
    try:
        addr = ("127.0.0.1", emu.ports["command"])
        s.sendto(b"takeoff", addr)
        assert s.recvfrom(64)[0] == b"error Not in SDK mode"
        s.sendto(b"command", addr)
        assert s.recvfrom(64)[0] == b"ok"
        t_cmd = time.monotonic()
        s.sendto(b"takeoff", addr)
        assert s.recvfrom(64)[0] == b"ok"  # answered once hovering (0.8 m at 1.5 m/s: 0.53 s)
        assert emu.mode == CtrlState.HOVERING
        time.sleep(max(t_cmd + 0.8 - time.monotonic(), 0.0))
        assert emu.mode == CtrlState.HOVERING and emu.stats["auto_lands"] == 0
        time.sleep(max(t_cmd + 1.5 - time.monotonic(), 0.0))  # more than 1 s since the last command
        assert emu.stats["auto_lands"] == 1
        assert emu.mode in (CtrlState.LANDING, CtrlState.LANDED)
    finally:
        s.close()
        emu.stop()
    # delaykit's link, quiet after the take-off, keeps it up with its keep-alive (5 Hz here)
    emu, link = _pair(command_timeout=1.0, link={"keepalive": 5.0})
    try:
        link.connect(2.0, vmax=1.0, z_max=3.0)
        link.takeoff(10.0)
        time.sleep(2.5)
        up = (emu.mode, emu.stats["auto_lands"])
        assert link.land(5.0)
    finally:
        link.close()
        emu.stop()
    assert up == (CtrlState.HOVERING, 0)


@pytest.mark.realtime
def test_garbage_is_ignored_and_counted_on_both_sides():
    emu, link = _pair()
    junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        link.connect(2.0, vmax=1.0, z_max=3.0)
        for data in (b"\xff\x00\x13", b"rc 0 0 500 0", b"rc 1 2", b""):  # to the emulator
            junk.sendto(data, ("127.0.0.1", emu.ports["command"]))
        for data in (b"\xff\x00\x13", b"tof:??;", b"bat:87;"):  # to the link's state port, from 127.0.0.1
            junk.sendto(data, ("127.0.0.1", link.state_port))
        time.sleep(0.3)
        junk.sendto(b"keepalive", ("127.0.0.1", emu.ports["command"]))
        samples = [link.recv(0.5) for _ in range(4)]
        assert all(s is not None for s in samples)  # the emulator's own lines still come through
    finally:
        junk.close()
        link.close()
        emu.stop()
    assert emu.stats["bad"] == 4  # (the empty datagram too)
    assert link.counts["garbage"] == 3 and link.rejected == 3
    assert any("without tof" in r for r in link.rejections)


@pytest.mark.realtime
def test_unanswered_command_is_a_link_error_and_error_is_a_refusal():
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    link = TelloLink("127.0.0.1", command_port=silent.getsockname()[1], state_port=0, reply_timeout=0.2)
    try:
        with pytest.raises(LinkError, match="no answer to `command`"):
            link.connect(0.7, vmax=1.0, z_max=3.0)
        got = []
        silent.settimeout(0.1)
        while True:
            try:
                got.append(silent.recvfrom(64)[0])
            except socket.timeout:
                break
        assert got.count(b"command") >= 3  # resent every reply_timeout within the timeout
    finally:
        link.close()
        silent.close()
    # a take-off refused (already flying): the drone's words in a VehicleRefusedError
    emu, link = _pair()
    try:
        link.connect(2.0, vmax=1.0, z_max=3.0)
        link.takeoff(10.0)
        with pytest.raises(VehicleRefusedError, match="Already flying"):
            link.takeoff(2.0)
        assert link.land(5.0)
    finally:
        link.close()
        emu.stop()


@pytest.mark.realtime
def test_link_lost_mid_flight_exits_non_zero_with_the_log_intact(tmp_path):
    from typer.testing import CliRunner

    from delaykit.cli import app

    port = _free_udp_port()
    emu = TelloEmulator(EmulatorConfig(**EXACT), command_port=0, state_port=port).start()
    stopper: list[threading.Timer] = []
    orig = emu._send_sample

    def watch(*args):  # once the step began (rc flowing), the drone vanishes
        if emu._stats["rc"] > 15 and not stopper:
            stopper.append(threading.Timer(0.0, emu.stop))
            stopper[0].start()
        return orig(*args)

    emu._send_sample = watch
    try:
        res = CliRunner().invoke(app, ["fly", "--vehicle", "tello", "--host", "127.0.0.1", "--command-port",
                                       str(emu.ports["command"]), "--state-port", str(port), "--kp", "1.5",
                                       "--step", "0.3", "--duration", "5", "--hover", "0.5",
                                       "--log", str(tmp_path / "f.csv")])
    finally:
        emu.stop()
    assert res.exit_code == 1, res.output
    assert "Flight ended early: state gap longer than 0.5 s" in res.output
    text = (tmp_path / "f.csv").read_text()
    assert text.endswith("\n")
    log = _read_log(tmp_path / "f.csv")
    assert len(log) > 5 and np.all(np.isfinite(log["z"])) and np.all(np.isfinite(log["recv_time"]))


@pytest.mark.realtime
def test_sigterm_lands_the_tello(tmp_path):
    import signal

    from delaykit.hardware.flight import land_on_signals

    emu, link = _pair()

    def status(msg: str) -> None:
        if msg.startswith("step 1"):  # mid-flight: the process is asked to stop
            threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()

    try:
        with land_on_signals():
            res = fly(FlightPlan(kp=1.5, steps=(0.5,), step_duration=5.0, hover_time=0.5), tmp_path / "f.csv",
                      link=link, status=status)
        landed = (emu.mode, emu.altitude)
    finally:
        emu.stop()
    assert res.interrupted == "SIGTERM" and not res.completed
    assert landed == (CtrlState.LANDED, 0.0)
    assert len(_read_log(tmp_path / "f.csv")) > 3


@pytest.mark.realtime
def test_djitellopy_flies_the_emulator_in_private_network_namespaces():
    pytest.importorskip("djitellopy")
    # djitellopy talks to 192.168.10.1 on fixed ports bound on every interface: only inside namespaces made here
    probe = subprocess.run(["unshare", "-n", "ip", "link", "add", "va", "type", "veth", "peer", "name", "vb"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"cannot make a network namespace with a veth pair here (unshare -n: "
                    f"{(probe.stderr or 'refused').strip()}); djitellopy needs 192.168.10.1 and fixed ports")
    script = Path(__file__).with_name("tello_netns.py")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    run = subprocess.run(["unshare", "-n", sys.executable, str(script), "client"], capture_output=True, text=True,
                         timeout=90, env=env)
    assert run.returncode == 0, run.stderr[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    # rc 0 0 50 0 for one second at 0.01 m/s per percent climbs 0.5 m (the exact vehicle: speed = command); the
    # sending loop's timing and h's 10 cm steps make that 50 +- 15 cm
    assert abs((got["h1"] - got["h0"]) - 50) <= 15, got
    assert abs((got["tof1"] - got["tof0"]) - 50) <= 12, got
    assert got["emulator"]["sdk"] and got["emulator"]["stats"]["rc"] >= 10
    assert got["emulator"]["altitude"] == 0.0  # djitellopy's land() landed it


@pytest.mark.realtime
def test_the_emulate_command_serves_a_tello_on_loopback():
    cmd_port, state_port = _free_udp_port(), _free_udp_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    proc = subprocess.Popen([sys.executable, "-m", "delaykit.cli", "emulate", "--protocol", "tello", "--host",
                             "127.0.0.1", "--command-port", str(cmd_port), "--state-port", str(state_port),
                             "--vehicle", "lag", "--delay", "0.1"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    link = TelloLink("127.0.0.1", command_port=cmd_port, state_port=state_port)
    try:
        link.connect(20.0, vmax=1.0, z_max=3.0)  # (the command starts in a second or two)
        link.takeoff(10.0)
        s = link.recv(1.0)
        assert s is not None and abs(s.z - 0.8) < 0.05  # the take-off height, 0.8 m, as tof
        assert link.land(8.0)
    finally:
        link.close()
        proc.terminate()  # SIGTERM: the summary, status 0
        out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    summary = json.loads(out)
    assert summary["protocol"] == "tello" and summary["sdk"] and summary["stats"]["state_sent"] > 5
    assert summary["state_to"] == ["127.0.0.1", state_port]


@pytest.mark.realtime
def test_speed_per_percent_is_identifiable_from_a_flight(tmp_path):
    # the link assumes 0.01 m/s per percent, the vehicle does 0.015: the plant the log shows is 1.5 / s
    emu, link = _pair(spp=0.01)
    emu.speed_per_percent = 0.015
    try:
        res = fly(FlightPlan(kp=1.0, steps=(0.5,), step_duration=3.0, hover_time=0.5), tmp_path / "f.csv", link=link)
    finally:
        emu.stop()
    assert res.completed, res.reason
    log = _read_log(res.logs[0])
    # the exact vehicle (speed = command) with a 0.1 s delay at 10 Hz: the command sent after sample k moves the
    # altitude between samples k + 1 and k + 2, so dz/dt there = gain * u_k; least squares for the gain
    z, u, t = log["z"], log["u"], log["recv_time"]
    rate = np.diff(z)[1:] / np.diff(t)[1:]
    gain = float(np.dot(rate, u[:-2]) / np.dot(u[:-2], u[:-2]))
    # the true map over the assumed one, 0.015 / 0.01 (the rc's 1 % steps blur it by about 1 %)
    assert abs(gain - 1.5) < 0.05, gain


@pytest.mark.realtime
def test_autotune_flies_the_tello_link_and_finds_the_rc_map():
    # a relay on the exact vehicle (its speed is its command, 0.1 s later), the link assuming 0.01 m/s per percent:
    # flown once on a vehicle whose map is 0.01 and once on one whose map is 0.015.  The form 1/s is exact but the
    # relay switches only at the 10 Hz samples, which biases the continuous relay's formula (about +10 % in gain
    # here; over MAVLink at 50 Hz it is within 0.1 of 1), the same in both: the ratio of the gains found is the
    # ratio of the maps, 1.5.  The delay is 0.1 s plus the loop's own: up to one 0.1 s sample, plus the latency.
    from delaykit.hardware.autotune import autotune
    from delaykit.hardware.laws import Relay

    found = []
    for spp in (0.01, 0.015):
        state_port = _free_udp_port()
        emu = TelloEmulator(EmulatorConfig(**EXACT), command_port=0, state_port=state_port,
                            speed_per_percent=spp).start()
        try:
            import tempfile

            with tempfile.TemporaryDirectory() as d:
                res = autotune(Relay(0.3), f"{d}/relay.csv", relay_duration=5.0, skip=1, step=None, hover_time=0.5,
                               fly_kw={"link": lambda: TelloLink("127.0.0.1", command_port=emu.ports["command"],
                                                                 state_port=state_port)})
        finally:
            emu.stop()
        assert res.status == "ok", res
        found.append(res.found)
    assert found[1].gain / found[0].gain == pytest.approx(1.5, abs=0.08), found
    assert found[0].gain == pytest.approx(1.0, abs=0.2), found[0]
    assert all(0.1 <= f.delay <= 0.21 for f in found), found


@pytest.mark.realtime
@pytest.mark.slow
def test_demo_flies_the_tello_emulator(tmp_path):
    from delaykit.paper.demo import run_demo

    rep = run_demo(tmp_path, seed=5, p_steps=2, pv_steps=1, step_duration=5.0, compensate=False,
                   identify_plant=False, protocol="tello")
    assert rep.p_flight.completed and rep.pv_flight.completed
    log = _read_log(rep.p_flight.logs[0])
    assert "vehicle_time" not in log.dtype.names  # flown over the Tello link (no vehicle clock)
    assert rep.p_flight.packet_interval == pytest.approx(0.1, abs=0.01)  # at the Tello's 10 Hz
    # (biased by the speed loop and the 10 Hz sampling, as over MAVLink; see docs/guide/flying.md)
    assert abs(rep.estimate.delay - rep.true_delay) < 0.1


@pytest.mark.realtime
def test_the_delay_monitor_flies_on_the_tello_link(tmp_path):
    from delaykit.hardware.monitor import DelayMonitor

    emu, link = _pair(cfg={"delay": 0.25, "vehicle": "lag", "lag": 0.05, "noise": 0.003})
    plan = FlightPlan(kp=1.0, steps=(0.5,), step_duration=4.0, hover_time=0.5)
    try:
        res = fly(plan, tmp_path / "f.csv", link=link, monitor=DelayMonitor(plan.law()))
    finally:
        emu.stop()
    assert res.completed, res.reason
    (o,) = res.online
    # the actuator delay 0.25 s, plus what the pure-delay model absorbs: the 0.05 s speed lag and the 10 Hz
    # sample-and-hold (half a period on average); P with kp 1 is stable up to pi/2 s, so no alarm
    assert 0.25 <= o.delay <= 0.36 and not o.alarm, o
    assert emu.stats["auto_lands"] == 0
