"""MAVLink: delaykit's link flies the emulator's MAVLink front end (PX4 and ArduPilot behaviours), and clients
delaykit did not write (a plain pymavlink script, MAVSDK-Python) fly the emulator.  Loopback only."""

from __future__ import annotations

import math
import os
import socket
import threading
import time

import numpy as np
import pytest

from delaykit import InvalidValueError, LinkError, VehicleRefusedError
from delaykit.hardware.emulator_config import EmulatorConfig
from delaykit.hardware.emulator_mavlink import MavlinkEmulator
from delaykit.hardware.flight import FlightPlan, fly
from delaykit.hardware.mavlink import VELOCITY_ONLY, MavlinkLink

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mav2  # noqa: E402

# a vehicle whose speed is its command (no lag, no noise, no wander): altitudes are integrals of the commands
# (quick take-offs and landings keep the tests short)
EXACT = dict(rate=50.0, vehicle="lag", lag=0.0, noise=0.0, delay=0.1, seed=1, takeoff_speed=1.5, landing_speed=1.5)


def _free_udp_port() -> int:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def _ardupilot(**kw) -> tuple[MavlinkEmulator, str]:
    cfg = EmulatorConfig(**{**EXACT, **kw.pop("cfg", {})})
    emu = MavlinkEmulator(cfg, autopilot="ardupilot", listen="tcp:127.0.0.1:0", **kw).start()
    return emu, f"tcp:127.0.0.1:{emu.ports['mavlink']}"


def _px4(**kw) -> tuple[MavlinkEmulator, str, int]:
    port = _free_udp_port()
    cfg = EmulatorConfig(**{**EXACT, **kw.pop("cfg", {})})
    emu = MavlinkEmulator(cfg, autopilot="px4", to=f"udp:127.0.0.1:{port}", **kw).start()
    return emu, f"udpin:127.0.0.1:{port}", port


def _read_log(path):
    return np.genfromtxt(path, delimiter=",", names=True)


# ---- no network ------------------------------------------------------------------------------------------------
def test_accel_limit_turns_a_speed_step_into_a_ramp():
    # the physics alone (no sockets): a 0.5 m/s step on a vehicle with no lag and 1 m/s^2 of acceleration limit
    # climbs s^2/2 for s < 0.5 s after the command takes effect, then 0.125 + 0.5 (s - 0.5) (closed form of a
    # ramp of slope 1 to 0.5 m/s)
    emu = MavlinkEmulator(EmulatorConfig(**{**EXACT, "accel_limit": 1.0}), autopilot="ardupilot",
                          listen="tcp:127.0.0.1:0")
    t0 = emu._phys.t = emu._t0 = 1000.0
    with emu._lock:
        emu._phys.mode = 4  # hovering (CtrlState.HOVERING) at 1 m
        emu._phys.z = 1.0
        emu._cmd_speed(0.5, t0)  # takes effect at t0 + 0.1 (the actuator delay)
        out = {}
        for s in (0.2, 0.4, 0.8):
            emu._advance(t0 + 0.1 + s)
            out[s] = emu._phys.z - 1.0
    assert out[0.2] == pytest.approx(0.02, abs=1e-3)
    assert out[0.4] == pytest.approx(0.08, abs=1e-3)
    assert out[0.8] == pytest.approx(0.125 + 0.5 * 0.3, abs=1e-3)


def test_bad_settings_are_clear_errors():
    with pytest.raises(InvalidValueError, match="loopback only"):
        MavlinkEmulator(autopilot="px4", to="udp:192.168.1.5:14540")
    with pytest.raises(InvalidValueError, match="exactly one"):
        MavlinkEmulator(autopilot="px4")
    with pytest.raises(InvalidValueError, match="autopilot"):
        MavlinkEmulator(autopilot="inav", listen="tcp:127.0.0.1:0")
    with pytest.raises(InvalidValueError, match="not one of pymavlink's"):
        MavlinkLink("http://127.0.0.1:5760")
    with pytest.raises(InvalidValueError, match="rate"):
        MavlinkLink("tcp:127.0.0.1:5760", rate=0.0)


def test_the_link_ignores_and_counts_garbage_other_systems_and_stale_samples():
    # a hand-made vehicle on UDP: garbage bytes, a heartbeat, a position from another system, a stale one
    port = _free_udp_port()
    link = MavlinkLink(f"udpin:127.0.0.1:{port}")
    link._open()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        vehicle, other = mav2.MAVLink(None, 1, 1), mav2.MAVLink(None, 7, 1)
        lpn = vehicle.local_position_ned_encode
        for data in (b"\x00garbage that is not MAVLink\xff" * 3,
                     vehicle.heartbeat_encode(2, 3, 0, 0, 3).pack(vehicle),
                     other.local_position_ned_encode(500, 0, 0, -9.0, 0, 0, 0).pack(other),
                     lpn(1000, 0, 0, -1.25, 0, 0, 0.1).pack(vehicle),
                     lpn(900, 0, 0, -5.0, 0, 0, 0).pack(vehicle),  # older than the last: stale
                     lpn(1020, 0, 0, -1.5, 0, 0, -0.2).pack(vehicle)):
            tx.sendto(data, ("127.0.0.1", port))
        got = [link.recv(1.0) for _ in range(2)]
    finally:
        tx.close()
        link.close()
    # NED: up is -z; MAVLink carries float32
    assert [v for s in got for v in (s.z, s.vz, s.vehicle_time)] == pytest.approx([1.25, -0.1, 1.0, 1.5, 0.2, 1.02])
    assert link.counts["garbage"] >= 1 and link.counts["other_system"] == 1 and link.counts["stale"] == 1
    assert link.rejected == sum(link.counts.values())


# ---- real time on loopback ---------------------------------------------------------------------------------------
@pytest.mark.realtime
@pytest.mark.parametrize("autopilot", ["ardupilot", "px4"])
def test_delaykits_link_flies_a_p_step(tmp_path, autopilot):
    emu, conn = _ardupilot()[:2] if autopilot == "ardupilot" else _px4()[:2]
    seen_during: list[int] = []

    def status(msg: str) -> None:
        if msg == "landing":  # the log is flushed as it is written: its rows are on disk before the flight ends
            seen_during.append(sum(1 for _ in open(tmp_path / "f.csv")))

    try:
        res = fly(FlightPlan(kp=2.0, steps=(0.5,), step_duration=2.5, hover_time=0.5), tmp_path / "f.csv",
                  link=MavlinkLink(conn, rate=50, climb_speed=1.0), status=status)
    finally:
        emu.stop()
    assert res.completed, res.reason
    log = _read_log(res.logs[0])
    # the P loop kp e^(-0.1 s)/s: a time constant of about 1/kp = 0.5 s, so 2.5 s after the step (5 of them)
    # the altitude is within a few mm of the reference (exact vehicle: no noise)
    assert abs(log["z"][-10:].mean() - log["z_ref"][-1]) < 0.02
    assert log["z"][0] < log["z_ref"][-1] - 0.4  # (the log starts at the hover, half a metre below)
    # both time stamps: the vehicle's clock runs with the arrival clock (the emulator keeps real time)
    vt, rt = log["vehicle_time"], log["recv_time"]
    assert np.all(np.diff(vt) > 0) and np.all(np.isfinite(rt))
    assert abs((vt[-1] - vt[0]) - (rt[-1] - rt[0])) < 0.05
    assert seen_during and seen_during[0] == len(log) + 1  # header + every row, before the landing
    assert emu.summary()["armed"] is False  # landed, and disarmed as the autopilots do


@pytest.mark.realtime
def test_a_plain_pymavlink_script_flies_the_ardupilot_emulator():
    # written against pymavlink only, as an ArduCopter script would be (GUIDED, arm, takeoff, velocity targets,
    # LAND); with 1 m/s^2 of acceleration limit the climb at 0.5 m/s is a symmetric ramp, so the height gained is
    # still 0.5 m/s times the time between the first climb target and the first zero one (closed form)
    emu, conn = _ardupilot(cfg={"accel_limit": 1.0})
    try:
        master = mavutil.mavlink_connection(conn, source_system=255, source_component=190)
        master.wait_heartbeat(timeout=5)
        assert master.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=0.5) is None  # not asked yet
        master.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                     mavutil.mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 20000, 0, 0, 0, 0, 0)
        master.set_mode("GUIDED")
        master.arducopter_arm()
        master.motors_armed_wait()
        master.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 1.0)

        def altitude() -> float:
            m = master.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=1.0)
            return -m.z

        deadline = time.monotonic() + 6
        while altitude() < 0.999 and time.monotonic() < deadline:
            pass

        def target(vz_up: float) -> float:
            master.mav.set_position_target_local_ned_send(0, 1, 1, mavutil.mavlink.MAV_FRAME_LOCAL_NED,
                                                          VELOCITY_ONLY, 0, 0, 0, 0, 0, -vz_up, 0, 0, 0, 0, 0)
            return time.monotonic()

        z0 = altitude()
        t_up = target(0.5)
        while time.monotonic() - t_up < 1.0:  # resent at 20 Hz (ArduPilot drops a target after 3 s)
            time.sleep(0.05)
            target(0.5)
        t_stop = target(0.0)
        for _ in range(40):  # 0.8 s: the delay and the ramp down are over
            time.sleep(0.02)
            target(0.0)
        master.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=1.0)
        while master.recv_match(type="LOCAL_POSITION_NED", blocking=False):
            pass
        climbed = altitude() - z0
        master.set_mode("LAND")
        deadline = time.monotonic() + 6
        while master.motors_armed() and time.monotonic() < deadline:
            master.recv_match(type="HEARTBEAT", blocking=True, timeout=1.0)
        disarmed = not master.motors_armed()
        master.close()
    finally:
        emu.stop()
    assert climbed == pytest.approx(0.5 * (t_stop - t_up), abs=0.03)
    assert disarmed and emu.altitude == 0.0


@pytest.mark.realtime
def test_mavsdk_offboard_velocity_flies_the_px4_emulator():
    mavsdk = pytest.importorskip("mavsdk", reason="MAVSDK-Python is not installed (the test extra)")
    from mavsdk.plugins.action.action import Action
    from mavsdk.plugins.offboard.offboard import Offboard, VelocityNedYaw
    from mavsdk.plugins.telemetry.telemetry import Telemetry

    emu, _, port = _px4()
    try:
        try:
            sdk = mavsdk.Mavsdk(mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION))
        except Exception as exc:  # noqa: BLE001 (its native library could not start here)
            pytest.skip(f"MAVSDK could not start: {exc}")
        sdk.add_any_connection(f"udpin://127.0.0.1:{port}")
        system = sdk.first_autopilot(5.0)
        assert system is not None
        action, offboard, telemetry = Action(system), Offboard(system), Telemetry(system)
        action.arm()
        offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
        offboard.start()
        t_up = time.monotonic()
        offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, -0.5, 0.0))  # up: NED
        time.sleep(1.6)
        t_stop = time.monotonic()
        offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
        time.sleep(0.5)
        down = telemetry.position_velocity_ned().position.down_m
        z_true = emu.altitude
        action.land()
        deadline = time.monotonic() + 5
        while emu.summary()["armed"] and time.monotonic() < deadline:
            time.sleep(0.1)
        armed = emu.summary()["armed"]
    finally:
        emu.stop()
    # the climb is 0.5 m/s for the time between the two velocity calls (the exact vehicle), seen by MAVSDK too
    assert z_true == pytest.approx(0.5 * (t_stop - t_up), abs=0.05)
    assert -down == pytest.approx(z_true, abs=0.03)
    assert not armed


@pytest.mark.realtime
def test_prearm_refusal_is_one_line_naming_the_vehicles_reason(tmp_path):
    from typer.testing import CliRunner

    from delaykit.cli import app

    emu, conn = _ardupilot(refuse_arming="Throttle below failsafe")
    try:
        # through readiness: the pre-arm bit never turns healthy; the error names the vehicle's STATUSTEXT
        res = CliRunner().invoke(app, ["fly", "--vehicle", "mavlink", "--connect", conn, "--kp", "1",
                                       "--ready-timeout", "1.5", "--log", str(tmp_path / "f.csv")])
        # straight to arming: the COMMAND_ACK refusal, with the same reason
        link = MavlinkLink(conn)
        link.connect(3.0, vmax=1.0, z_max=3.5)
        with pytest.raises(VehicleRefusedError, match="ArduPilot refused arming .failed.: PreArm: Throttle below"):
            link.takeoff(3.0)
        link.close()
    finally:
        emu.stop()
    assert res.exit_code == 2
    lines = [x for x in res.output.splitlines() if x.startswith("error")]
    assert len(lines) == 1 and "not ready to arm" in lines[0] and "PreArm: Throttle below failsafe" in lines[0]
    assert "Traceback" not in res.output
    assert emu.summary()["armed"] is False and not list(tmp_path.glob("*.csv"))  # nothing flew


@pytest.mark.realtime
def test_link_lost_mid_flight_exits_non_zero_with_the_log_intact(tmp_path):
    from typer.testing import CliRunner

    from delaykit.cli import app

    emu, conn = _ardupilot()
    stopper: list[threading.Timer] = []
    orig = emu._send_sample

    def watch(*args):  # once the step began (setpoints flowing), the vehicle vanishes
        if emu._stats["setpoints"] > 60 and not stopper:
            stopper.append(threading.Timer(0.0, emu.stop))
            stopper[0].start()
        return orig(*args)

    emu._send_sample = watch
    try:
        res = CliRunner().invoke(app, ["fly", "--vehicle", "mavlink", "--connect", conn, "--kp", "1.5",
                                       "--step", "0.3", "--duration", "5", "--hover", "0.5",
                                       "--log", str(tmp_path / "f.csv")])
    finally:
        emu.stop()
    assert res.exit_code == 1, res.output
    assert "Flight ended early: LOCAL_POSITION_NED gap longer than 0.5 s" in res.output
    text = (tmp_path / "f.csv").read_text()
    assert text.endswith("\n")
    log = _read_log(tmp_path / "f.csv")
    assert len(log) > 5 and np.all(np.isfinite(log["z"])) and np.all(np.isfinite(log["vehicle_time"]))


@pytest.mark.realtime
def test_the_emulator_ignores_garbage_and_other_systems_and_honours_the_interval():
    emu, conn = _ardupilot()
    try:
        sock = socket.create_connection(("127.0.0.1", emu.ports["mavlink"]), timeout=2.0)
        gcs = mav2.MAVLink(None, 255, 190)
        dec = mav2.MAVLink(None, 255, 190)
        dec.robust_parsing = True
        sock.sendall(b"\xfd\x09garbage\x00\x01" * 4)
        sock.sendall(gcs.command_long_encode(9, 1, mav2.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0,
                                             0).pack(gcs))  # to system 9: not this vehicle
        sock.sendall(gcs.command_long_encode(1, 1, mav2.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                             mav2.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 40000, 0, 0, 0, 0,
                                             0).pack(gcs))  # 25 Hz
        sock.sendall(gcs.timesync_encode(0, 123456789).pack(gcs))  # a TIMESYNC request
        acks, tbm, sync = [], [], []
        deadline = time.monotonic() + 2.5
        while time.monotonic() < deadline:
            try:
                data = sock.recv(65536)
            except socket.timeout:
                break
            for m in dec.parse_buffer(data) or []:
                if m.get_type() == "COMMAND_ACK":
                    acks.append((m.command, m.result))
                elif m.get_type() == "LOCAL_POSITION_NED":
                    tbm.append(m.time_boot_ms)
                elif m.get_type() == "TIMESYNC":
                    sync.append((m.tc1, m.ts1))
        sock.close()
        stats = emu.stats
    finally:
        emu.stop()
    assert acks == [(mav2.MAV_CMD_SET_MESSAGE_INTERVAL, mav2.MAV_RESULT_ACCEPTED)]  # the one to system 9 unanswered
    assert stats["bad"] >= 1 and stats["other_system"] == 1 and emu.summary()["armed"] is False
    assert len(sync) == 1 and sync[0][1] == 123456789 and 0 < sync[0][0] < 10e9  # its clock, ns since start
    # 40 ms asked, on the emulator's 20 ms grid: every second tick, on its own clock
    assert len(tbm) > 30 and np.median(np.diff(tbm)) == pytest.approx(40, abs=1)


@pytest.mark.realtime
def test_px4_setpoint_loss_failsafe_lands():
    # PX4's offboard loss failsafe (COM_OF_LOSS_T, 1 s) switches to AUTO.LAND: it lands and disarms
    emu, conn, _ = _px4()
    try:
        link = MavlinkLink(conn)
        link.connect(3.0, vmax=1.0, z_max=3.5)
        link.takeoff(10.0)
        link._keeper.stop()  # the ground station goes quiet
        t0 = time.monotonic()
        while emu.summary()["armed"] and time.monotonic() - t0 < 6:
            time.sleep(0.1)
        summary = emu.summary()
        link.close()
    finally:
        emu.stop()
    assert summary["stats"]["failsafes"] == 1 and not summary["armed"] and emu.altitude == 0.0
    assert math.isclose(summary["custom_mode"], (6 << 24) | (4 << 16))  # AUTO.LAND


def test_unreachable_vehicle_is_a_link_error(tmp_path):
    port = _free_udp_port()
    with pytest.raises(LinkError, match="no HEARTBEAT"):
        fly(FlightPlan(kp=1.0), tmp_path / "f.csv", link=MavlinkLink(f"udpin:127.0.0.1:{port}"), connect_timeout=0.5)


@pytest.mark.realtime
def test_autotune_flies_the_mavlink_link():
    # a relay on the exact vehicle (its speed is its command, 0.1 s later): the form 1/s is exact, so the relay
    # cycle gives back a gain near 1 and the delay 0.1 s plus the loop's own (sampling at 50 Hz, latency): the
    # emulator's configured values
    from delaykit.hardware.autotune import autotune
    from delaykit.hardware.laws import Relay

    emu, conn = _ardupilot()
    try:
        import tempfile

        with tempfile.TemporaryDirectory() as d:
            res = autotune(Relay(0.3), f"{d}/relay.csv", relay_duration=5.0, skip=1, step=None, hover_time=0.5,
                           fly_kw={"link": lambda: MavlinkLink(conn)})
    finally:
        emu.stop()
    assert res.status == "ok", res
    assert 0.09 <= res.found.delay <= 0.14 and res.found.gain == pytest.approx(1.0, abs=0.1)


@pytest.mark.realtime
@pytest.mark.slow
def test_demo_flies_the_mavlink_emulator(tmp_path):
    from delaykit.paper.demo import run_demo

    rep = run_demo(tmp_path, seed=5, p_steps=2, pv_steps=1, step_duration=5.0, compensate=False,
                   identify_plant=False, protocol="mavlink", autopilot="px4")
    assert rep.p_flight.completed and rep.pv_flight.completed
    log = _read_log(rep.p_flight.logs[0])
    assert "vehicle_time" in log.dtype.names  # flown over MAVLink
    assert abs(rep.estimate.delay - rep.true_delay) < 0.1  # (biased by the speed loop; see docs/guide/flying.md)


@pytest.mark.realtime
def test_sigterm_lands_the_mavlink_vehicle(tmp_path):
    import signal

    from delaykit.hardware.flight import land_on_signals

    emu, conn = _ardupilot()

    def status(msg: str) -> None:
        if msg.startswith("step 1"):  # mid-flight: the process is asked to stop
            threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGTERM)).start()

    try:
        with land_on_signals():
            res = fly(FlightPlan(kp=2.0, steps=(0.5,), step_duration=5.0, hover_time=0.5), tmp_path / "f.csv",
                      link=MavlinkLink(conn), status=status)
        landed = (emu.summary()["armed"], emu.altitude)
    finally:
        emu.stop()
    assert res.interrupted == "SIGTERM" and not res.completed
    assert landed == (False, 0.0)
    assert len(_read_log(tmp_path / "f.csv")) > 10


def test_emulate_command_runs_the_mavlink_front_end_and_refuses_other_hosts():
    import json

    from typer.testing import CliRunner

    from delaykit.cli import app

    res = CliRunner().invoke(app, ["emulate", "--protocol", "mavlink", "--autopilot", "ardupilot", "--listen",
                                   "tcp:127.0.0.1:0", "--duration", "0.3", "--accel-limit", "1"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["protocol"] == "mavlink" and summary["autopilot"] == "ardupilot" and summary["accel_limit"] == 1.0
    assert summary["endpoint"].startswith("tcp:127.0.0.1:") and not summary["endpoint"].endswith(":0")
    for args, fragment in ((["--to", "udp:10.0.0.1:14540"], "loopback only"),
                           ([], "exactly one of --to"),
                           (["--to", "udp:127.0.0.1:14540", "--listen", "tcp:127.0.0.1:5760"], "exactly one of --to")):
        bad = CliRunner().invoke(app, ["emulate", "--protocol", "mavlink", "--duration", "0.1", *args])
        assert bad.exit_code == 2 and fragment in bad.output and "Traceback" not in bad.output
    bad = CliRunner().invoke(app, ["fly", "--vehicle", "mavlink", "--kp", "1"])
    assert bad.exit_code == 2 and "needs --connect" in bad.output


@pytest.mark.realtime
def test_a_smith_predictor_and_the_delay_monitor_fly_the_mavlink_link(tmp_path):
    # the exact vehicle's loop delay is the emulator's 0.1 s plus the loop's own latency (received to sent, in the
    # result): each step's online estimate must find it, and no alarm (the predictor is designed for 0.1 s)
    from delaykit.hardware.monitor import DelayMonitor
    from delaykit.models import Compensator

    emu, conn = _ardupilot()
    law = Compensator.smith("1/s", 0.1, closed_loop_time=0.3)
    try:
        res = fly(FlightPlan(kp=0.0, controller=law, steps=(0.5, -0.5), step_duration=3.0, hover_time=0.5),
                  tmp_path / "f.csv", link=MavlinkLink(conn), monitor=DelayMonitor(law))
    finally:
        emu.stop()
    assert res.completed and len(res.online) == 2 and res.alarms == 0
    truth = emu.true_delay + 1e-3 * res.latency_median_ms
    assert [o.delay for o in res.online] == pytest.approx([truth, truth], abs=0.005)


@pytest.mark.realtime
def test_readiness_waits_for_the_prearm_checks_with_progress():
    # the emulated vehicle refuses arming as "not yet" for its first 1.5 s (an estimator converging): the link
    # waits, says so, and is ready once the vehicle's SYS_STATUS pre-arm bit turns healthy
    emu, conn = _ardupilot(ready_after=1.5)
    said: list[str] = []
    try:
        link = MavlinkLink(conn)
        link.connect(3.0, vmax=1.0, z_max=3.5)
        link.ready(5.0, status=said.append)
        ready_at = emu.elapsed
        link.close()
    finally:
        emu.stop()
    assert ready_at >= 1.5 and link.prearm_ok is True
    assert any("waiting for ArduPilot's pre-arm checks" in m for m in said) and said[-1] == "ArduPilot ready to arm"
