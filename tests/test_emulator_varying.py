"""The emulator with a delay that changes mid-flight (EmulatorConfig.delay_schedule): input checks, the physics
driven with chosen times (no sockets), and a loopback flight in which the delay is measured from the navdata
before and after it moves from 0.25 s to 0.40 s.  No packet leaves 127.0.0.1."""

from __future__ import annotations

import time

import numpy as np
import pytest

from test_flight import Client

from delaykit import InvalidValueError
from delaykit.hardware.ardrone import ATEncoder, CtrlState
from delaykit.hardware.emulator import DroneEmulator, EmulatorConfig
from delaykit.simulate.varying import DelaySchedule

FREE = dict(at_port=0, navdata_port=0, video_port=0, control_port=0)


@pytest.mark.parametrize("schedule, message", [
    ([(1.0, 0.3), (0.5, 0.4)], r"delay_schedule times must increase: delay_schedule\[1\] time 0.5 s is not after 1 s"),
    ([(1.0, 0.3), (1.0, 0.4)], r"delay_schedule\[1\] time 1 s is not after 1 s"),
    ([(0.0, -0.2)], r"delay_schedule\[0\] delay \(s\) must be at least 0, got -0.2"),
    ([(0.0, 6.0)], r"delay_schedule\[0\] delay \(s\) must be at most 5, got 6"),
    ([(-1.0, 0.3)], r"delay_schedule\[0\] time \(s since start\) must be at least 0, got -1"),
    ([(1.0,)], r"delay_schedule\[0\] must be a \(t, delay\) pair"),
    ([], "at least one"),
    ("0.3", "list of \\(t, delay\\) pairs"),
])
def test_bad_schedules_are_refused_naming_the_value(schedule, message):
    with pytest.raises(InvalidValueError, match=message):
        EmulatorConfig(delay_schedule=schedule)


def test_default_behaviour_and_accepted_forms():
    emu = DroneEmulator(EmulatorConfig(delay=0.3, link_delay=0.01))
    assert emu.config.delay_schedule is None
    assert emu.actuator_delay() == 0.3 and emu.true_delay == emu.true_delay_at() == pytest.approx(0.32)
    assert emu.summary()["delay_schedule"] == []
    cfg = EmulatorConfig(delay=0.25, delay_schedule=DelaySchedule([10.0, 20.0], [0.4, 0.3]))
    assert cfg.delay_schedule == ((10.0, 0.4), (20.0, 0.3))
    emu = DroneEmulator(cfg)
    t0 = emu._t0
    assert [emu.actuator_delay(t0 + x) for x in (0.0, 9.99, 10.0, 19.0, 25.0)] == [0.25, 0.25, 0.4, 0.4, 0.3]


def take_off_by_hand(**cfg):
    """An emulator with these settings that is not started (no threads), its clock set by hand: taken off and
    hovering at 0.8 m; returned with the encoder that commanded it (tests/test_emulator_vehicle.py uses it too)."""
    emu = DroneEmulator(EmulatorConfig(**FREE, **cfg))
    emu._phys.t = emu._t0
    enc = ATEncoder()
    emu._handle(enc.ref(takeoff=True), emu._t0 + 0.01)
    emu._advance(emu._t0 + 1.4)  # 0.8 m at 0.7 m/s: 1.15 s
    assert emu.mode == CtrlState.HOVERING
    return emu, enc


def _drive(delay_schedule=None, *, delay=0.25, **cfg):
    """The lag vehicle without lag or noise, taken off by hand (:func:`take_off_by_hand`)."""
    return take_off_by_hand(delay=delay, vehicle="lag", lag=0.0, noise=0.0, delay_schedule=delay_schedule, **cfg)


def _altitude(emu, t):
    with emu._lock:
        emu._advance(t)
        return emu._phys.z


def test_the_delay_in_force_when_a_command_arrives_is_the_one_it_gets():
    # with no lag, a 0.35 m/s command (gaz 0.5 of the factory 0.7 m/s) makes the altitude a ramp that starts
    # exactly when the command takes effect; that start, read off two altitudes, minus the command's arrival
    # time is the delay, and it must be the schedule's value at the arrival: 0.25 s before t = 2, 0.40 s after
    emu, enc = _drive([(2.0, 0.40)])
    t0 = emu._t0
    measured = []
    for t_cmd in (1.5, 2.5):
        z_hover = _altitude(emu, t0 + t_cmd)
        emu._handle(enc.pcmd(gaz=0.5), t0 + t_cmd)
        z1 = _altitude(emu, t0 + t_cmd + 0.5)
        start = (t_cmd + 0.5) - (z1 - z_hover) / 0.35
        measured.append(start - t_cmd)
        emu._handle(enc.pcmd(progressive=False), t0 + t_cmd + 0.5)  # hover again (at its own delay)
        _altitude(emu, t0 + t_cmd + 0.95)
    assert measured == pytest.approx([0.25, 0.40], abs=1e-9)
    assert emu.stats["stale"] == 0


def test_when_the_delay_falls_the_newest_command_wins():
    # at 3.95 s a climb is sent with the 0.40 s delay (due at 4.35 s); at 4.05 s the delay is 0.10 s and a descent
    # is sent (due at 4.15 s): the climb is stale and dropped, so from 4.15 s the altitude only falls
    emu, enc = _drive([(2.0, 0.40), (4.0, 0.10)])
    t0 = emu._t0
    z0 = _altitude(emu, t0 + 3.9)
    emu._handle(enc.pcmd(gaz=0.5), t0 + 3.95)
    emu._handle(enc.pcmd(gaz=-0.5), t0 + 4.05)
    assert emu.stats["stale"] == 1
    z = [_altitude(emu, t0 + x) for x in (4.15, 4.35, 4.60)]
    assert z[0] == pytest.approx(z0, abs=1e-9)  # times are monotonic seconds (~1e5): ~1e-11 s resolution
    assert z[1] - z[0] == pytest.approx(-0.35 * 0.20, abs=1e-9) and z[2] - z[1] == pytest.approx(-0.35 * 0.25, abs=1e-9)


def ramp_start(c: Client, v: float = 0.5) -> tuple[float, float, bool]:
    """Send a climb at ``v`` m/s from a hover and read off the navdata when it took effect, after the send.

    With no lag and no noise the altitude is a ramp from the moment the command takes effect, so
    ``t - (z - z_hover) / v`` over the packets after it is that moment (1 mm rounding: 2 ms).  Returns that
    delay, the longest gap between packets (a stalled machine) and whether the navdata speed was 0 before it."""
    z_hover = c.packet().demo.altitude_mm / 1000.0
    t_cmd = time.monotonic()
    c.send(c.enc.comwdg() + c.enc.pcmd(gaz=v))
    rows = []
    while time.monotonic() - t_cmd < 0.8:
        nd, t_arrival = c.stamped()  # the kernel's arrival time: a test thread woken late does not move it
        rows.append((t_arrival - t_cmd, nd.demo.altitude_mm / 1000.0, nd.demo.vz / 1000.0))
    c.send(c.enc.comwdg() + c.enc.pcmd(progressive=False))
    t, z, vz = np.array(rows).T
    moving = z > z_hover + 0.02
    start = float(np.median(t[moving] - (z[moving] - z_hover) / v))
    return start, float(np.diff(np.r_[0.0, t]).max()), bool(np.all(vz[t < start - 0.01] == 0.0))


@pytest.mark.realtime
def test_loopback_flight_measures_the_delay_moving_from_025_to_040():
    # the emulator's actuator delay is 0.25 s until 4 s after start, then 0.40 s; a 0.5 m/s step is sent before
    # and after, and the delay is measured from the navdata: with no lag and no noise the altitude is a ramp
    # from the moment the command takes effect, so (t - (z - z_hover) / 0.5) over the packets after it is that
    # moment (1 mm rounding: 2 ms).  The reference values are the configured 0.25 and 0.40 s; the tolerance is
    # the loopback's scheduling (a few ms), and a run where the machine stalled the packets is repeated.
    switch = 4.0
    for _ in range(3):
        with DroneEmulator(EmulatorConfig(**FREE, seed=1, delay=0.25, vehicle="lag", lag=0.0, noise=0.0, rate=100.0,
                                          delay_schedule=[(switch, 0.40)])) as emu:
            c = Client(emu)
            c.take_off()
            c.hover_until(2.0)
            before, gap1, quiet1 = ramp_start(c)
            c.hover_until(switch + 0.5)
            after, gap2, quiet2 = ramp_start(c)
            c.send(c.enc.ref())
        if max(gap1, gap2) < 0.03:  # packets every 10 ms: a longer gap is the shared machine stalling a thread
            break
    else:
        pytest.fail("the packets were stalled in 3 attempts: the machine is busy")
    assert abs(before - 0.25) < 0.015, before
    assert abs(after - 0.40) < 0.015, after
    assert quiet1 and quiet2  # the navdata speed is 0 until the command takes effect
