"""The emulator's navdata bursts (EmulatorConfig.bursts: the navdata rate falls for a while, a Wi-Fi scan) and its
replayed delay trace (EmulatorConfig.delay_trace), with `delaykit emulate --burst / --delay-trace`: input checks
and exit status 2, the sending plan and the physics driven with chosen times (no sockets), and loopback runs in
which the rate and the delay are measured from the packets' kernel arrival stamps.  No packet leaves 127.0.0.1."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from test_emulator_varying import _altitude, _drive, ramp_start
from test_flight import Client

from delaykit import InvalidTypeError, InvalidValueError
from delaykit.cli import app
from delaykit.hardware.ardrone import NavState
from delaykit.hardware.emulator import DroneEmulator, EmulatorConfig, _wakeups, check_bursts
from delaykit.simulate.varying import Burst, DelaySchedule, DelayTrace

FREE = dict(at_port=0, navdata_port=0, video_port=0, control_port=0)
PORTS = ["--at-port", "0", "--navdata-port", "0", "--video-port", "0", "--control-port", "0"]
runner = CliRunner()


# ------------------------------------------------------------------------------------------ bursts: checks
@pytest.mark.parametrize("bursts, message", [
    ([(-1.0, 1.0, 2.0)], r"bursts\[0\] start \(s since start\) must be at least 0, got -1"),
    ([(1.0, 0.0)], r"bursts\[0\] duration \(s\) must be greater than 0, got 0"),
    ([(1.0, -2.0)], r"bursts\[0\] duration \(s\) must be greater than 0, got -2"),
    ([(1.0, float("inf"))], r"bursts\[0\] duration \(s\) must be finite"),
    ([(float("nan"), 1.0)], r"bursts\[0\] start \(s since start\) must be finite"),
    ([(1.0, 1.0, -3.0)], r"bursts\[0\] rate \(Hz\) must be at least 0, got -3"),
    ([(1.0, 1.0, 15.0)], r"bursts\[0\] rate 15 Hz must be below the normal navdata rate 15 Hz"),
    ([(1.0, 1.0, 40.0)], r"bursts\[0\] rate 40 Hz must be below"),
    ([(5.0, 1.0), (1.0, 1.0), (5.5, 1.0)], r"bursts\[2\] \(from 5.5 s\) overlaps bursts\[0\] \(5 to 6 s\)"),
    ([(1.0, 2.0), (2.5, 1.0)], r"bursts\[1\] \(from 2.5 s\) overlaps bursts\[0\] \(1 to 3 s\)"),
    ([(1.0,)], r"bursts\[0\] must be \(start, duration\) or \(start, duration, rate\), got \(1.0,\)"),
    ([(1.0, 1.0, 2.0, 3.0)], r"bursts\[0\] must be \(start, duration\)"),
    ([3.0], r"bursts\[0\] must be \(start, duration\)"),
])
def test_bad_bursts_are_refused_naming_the_burst(bursts, message):
    with pytest.raises(InvalidValueError, match=message):
        EmulatorConfig(rate=15.0, bursts=bursts)


def test_bursts_of_the_wrong_kind_are_refused():
    with pytest.raises(InvalidTypeError, match=r"bursts\[0\] start \(s since start\) must be a real number"):
        EmulatorConfig(bursts=[("a", 1.0)])
    # the simulator's Burst adds delay to commands; the emulator's bursts lower the navdata rate
    with pytest.raises(InvalidTypeError, match=r"bursts\[0\] is a simulator Burst .* adds command delay"):
        EmulatorConfig(bursts=[Burst(5.0, 6.0, 0.3)])
    with pytest.raises(InvalidTypeError, match="list of \\(start, duration, rate\\) triples"):
        EmulatorConfig(bursts=Burst(5.0, 6.0, 0.3))
    with pytest.raises(InvalidTypeError, match="list of \\(start, duration, rate\\) triples"):
        EmulatorConfig(bursts="5:1")


def test_bursts_accepted_forms():
    assert EmulatorConfig().bursts == () and EmulatorConfig(bursts=None).bursts == ()
    # a pair means rate 0; kept sorted by start; bursts may touch (one ends where the next starts)
    cfg = EmulatorConfig(rate=15.0, bursts=[(4.0, 1.0, 5), [1, 3]])
    assert cfg.bursts == ((1.0, 3.0, 0.0), (4.0, 1.0, 5.0))
    assert all(isinstance(x, float) for b in cfg.bursts for x in b)
    assert EmulatorConfig(bursts=[(1.0, 1.0), (2.0, 1.0)]).bursts == ((1.0, 1.0, 0.0), (2.0, 1.0, 0.0))
    assert check_bursts([(1.0, 1.0)], 15.0, labels=["--burst '1:1'"]) == ((1.0, 1.0, 0.0),)
    with pytest.raises(InvalidValueError, match="--burst '1:1:99' rate 99 Hz"):
        check_bursts([(1.0, 1.0, 99.0)], 15.0, labels=["--burst '1:1:99'"])
    # the config stays valid through dataclasses.replace (the demo changes configs that way)
    from dataclasses import replace
    assert replace(cfg, delay=0.2).bursts == cfg.bursts
    assert DroneEmulator(cfg).summary()["bursts"] == [[1.0, 3.0, 0.0], [4.0, 1.0, 5.0]]


def test_the_sending_plan_lowers_the_rate_only_inside_a_burst():
    # 50 Hz, a 10 Hz burst over [1, 2) and a silent one over [2.5, 3.5): the closed form is the normal grid k / 50
    # outside the bursts, 1.0 + j / 10 inside the first, nothing inside the second, and the wake-ups (physics,
    # watchdog) keep the normal grid throughout
    plan = list(itertools.takewhile(lambda w: w[0] < 4.0, _wakeups(50.0, ((1.0, 1.0, 10.0), (2.5, 1.0, 0.0)))))
    t = np.array([w[0] for w in plan])
    send = np.array([w[1] for w in plan])
    assert np.all(np.diff(t) >= 0)

    def sent(a, b):
        return t[send & (t >= a - 1e-12) & (t < b - 1e-12)]

    assert sent(0.0, 1.0).size == 49  # k = 1 ... 49
    assert np.allclose(sent(1.0, 2.0), 1.0 + np.arange(10) / 10)
    assert sent(2.0, 2.5).size == 25 and sent(2.5, 3.5).size == 0 and sent(3.5, 4.0).size == 25
    normal = t[~np.isin(np.arange(t.size), np.flatnonzero(send & (t >= 1.0 - 1e-12) & (t < 2.0 - 1e-12)))]
    assert np.allclose(normal, np.arange(1, 200) / 50)  # every grid point wakes the thread, sending or not
    # no burst: the grid alone, every wake a send (the plan before bursts existed)
    plain = list(itertools.islice(_wakeups(15.0, ()), 30))
    assert all(s for _, s in plain) and np.allclose([w for w, _ in plain], np.arange(1, 31) / 15)


# ------------------------------------------------------------------------------------------- trace: checks
@pytest.mark.parametrize("trace, message", [
    ([(1.0, 0.3), (0.5, 0.4)], r"delay_trace times must increase: delay_trace\[1\] time 0.5 s is not after 1 s"),
    ([(0.0, -0.2)], r"delay_trace\[0\] delay \(s\) must be at least 0, got -0.2"),
    ([(0.0, float("nan"))], r"delay_trace\[0\] delay \(s\) must be finite"),
    ([(1.0,)], r"delay_trace\[0\] must be a \(t, delay\) record"),
    ([], "at least one"),
    ("trace.csv", "a DelayTrace or a list of \\(t, delay\\) records"),
    ([(0.0, 0.1), (1.0, 4.8)], r"delay_trace record 1 \(t = 1 s\): delay 0.3 s \+ 4.8 s = 5.1 s is above the "
                               r"emulator's largest actuator delay, 5 s"),
    (DelayTrace([0.0, 1.0], [0.1, 0.2], interpolation="linear"), "interpolation='linear'"),
])
def test_bad_traces_are_refused_naming_the_value(trace, message):
    with pytest.raises(InvalidValueError, match=message):
        EmulatorConfig(delay=0.3, delay_trace=trace)


def test_a_trace_with_a_schedule_or_of_the_wrong_kind_is_refused():
    with pytest.raises(InvalidValueError, match="give delay_schedule or delay_trace, not both"):
        EmulatorConfig(delay_schedule=[(1.0, 0.3)], delay_trace=[(0.0, 0.1)])
    with pytest.raises(InvalidTypeError, match="a DelaySchedule goes to delay_schedule"):
        EmulatorConfig(delay_trace=DelaySchedule([0.0, 1.0], [0.2, 0.3]))
    # a record before the trace's start is never replayed, so it is not checked against the 5 s limit
    assert EmulatorConfig(delay=0.3, delay_trace=DelayTrace([0.0, 1.0], [4.9, 0.1], start=2.0)).delay_trace == \
        ((0.0, 0.1),)


@pytest.mark.parametrize("start", [None, 98.7, 101.2, 104.0])
def test_the_trace_replayed_is_the_delay_traces_own_value_plus_delay(start):
    # the reference is DelayTrace.packet_delays (varying.py evaluates the trace itself), at times on both sides of
    # every record and before and after the trace; the emulator's actuator delay is `delay` plus that
    trace = DelayTrace([100.0, 101.0, 101.5, 103.0], [0.05, 0.20, 0.10, 0.15], start=start)
    emu = DroneEmulator(EmulatorConfig(delay=0.25, delay_trace=trace))
    s = trace.start
    times = np.r_[0.0, [x - s + e for x in trace.times for e in (-1e-6, 1e-6)], 7.0, 50.0]  # (not at a record:
    # the emulator's clock, monotonic seconds, rounds there)
    times = times[times >= 0]
    got = [emu.actuator_delay(emu._t0 + x) for x in times]
    assert got == pytest.approx(0.25 + trace.packet_delays(times), abs=1e-12)
    assert emu.true_delay == pytest.approx(0.25 + float(trace.packet_delays([0.0])[0]))


def test_trace_forms_files_and_summary(tmp_path):
    csv_file = tmp_path / "delays.csv"
    csv_file.write_text("t,delay\n10,0.10\n11,0.30\n12.5,0.20\n")
    log = tmp_path / "flight.csv"
    log.write_text("t,z,latency_ms\n0.0,0.8,3.5\n0.1,0.8,40.0\n")
    # (t, delay) records are a trace replayed from its first record: the same as DelayTrace(times, delays)
    cfg = EmulatorConfig(delay=0.2, delay_trace=[(10.0, 0.1), (11.0, 0.3), (12.5, 0.2)])
    assert cfg.delay_trace == EmulatorConfig(delay=0.2, delay_trace=DelayTrace.from_csv(csv_file)).delay_trace \
        == ((0.0, 0.1), (1.0, 0.3), (2.5, 0.2))
    assert EmulatorConfig(delay_trace=DelayTrace.from_flight_log(log)).delay_trace == ((0.0, 0.0035), (0.1, 0.04))
    s = DroneEmulator(cfg).summary()
    assert s["delay_trace"] == {"records": 3, "actuator_delay_min": pytest.approx(0.3),
                                "actuator_delay_max": pytest.approx(0.5)}
    assert s["true_delay"] == pytest.approx(0.3) and s["delay_schedule"] == [] and s["bursts"] == []


def test_a_command_gets_the_traced_delay_in_force_when_it_arrives():
    # the ramp method of test_emulator_varying: with no lag a 0.35 m/s command makes the altitude a ramp from the
    # moment it takes effect; that moment minus the arrival is the delay: delay 0.05 s plus the record in force
    # (0.20 s before 2 s, 0.35 s from 2 s, 0.05 s from 3.5 s)
    emu, enc = _drive(delay=0.05, delay_trace=DelayTrace([7.0, 9.0, 10.5], [0.20, 0.35, 0.05]))
    t0 = emu._t0
    measured = []
    for t_cmd in (1.5, 2.5, 3.6):
        z_hover = _altitude(emu, t0 + t_cmd)
        emu._handle(enc.pcmd(gaz=0.5), t0 + t_cmd)
        z1 = _altitude(emu, t0 + t_cmd + 0.45)
        measured.append((t_cmd + 0.45) - (z1 - z_hover) / 0.35 - t_cmd)
        emu._handle(enc.pcmd(progressive=False), t0 + t_cmd + 0.45)
        _altitude(emu, t0 + t_cmd + 0.95)
    assert measured == pytest.approx([0.25, 0.40, 0.10], abs=1e-9)
    assert emu.stats["stale"] == 0


# ---------------------------------------------------------------------------------------- command line
@pytest.mark.parametrize("args, message", [
    (["--burst", "abc"], "--burst 'abc' is not START:DURATION[:RATE]"),
    (["--burst", "5"], "--burst '5' is not START:DURATION[:RATE]"),
    (["--burst", "1:2:3:4"], "--burst '1:2:3:4' is not START:DURATION[:RATE]"),
    (["--burst", "1:1,"], "--burst '' is not START:DURATION[:RATE]"),
    (["--burst", "-1:1"], "--burst '-1:1' start (s since start) must be at least 0, got -1"),
    (["--burst", "1:0"], "--burst '1:0' duration (s) must be greater than 0, got 0"),
    (["--burst", "1:1:nan"], "--burst '1:1:nan' rate (Hz) must be finite"),
    (["--burst", "1:1:20"], "--burst '1:1:20' rate 20 Hz must be below the normal navdata rate 15 Hz"),
    (["--burst", "1:1:20", "--rate", "30"], None),
    (["--burst", "1:2", "--burst", "2.5:1"], "--burst '2.5:1' (from 2.5 s) overlaps --burst '1:2' (1 to 3 s)"),
    (["--burst", "1:2,2.5:1"], "--burst '2.5:1' (from 2.5 s) overlaps --burst '1:2' (1 to 3 s)"),
    (["--delay-trace", "{missing}"], "cannot be read"),
    (["--delay-trace", "{bad}"], "row 3: t = 9 does not increase (after 10)"),
    (["--delay-trace", "{nocol}"], "has no column 'delay' (s) or 'latency_ms'"),
    (["--delay-trace", "{good}", "--delay", "4.95"], "delay 4.95 s + 0.3 s = 5.25 s is above"),
    (["--delay-trace", "{good}", "--delay-schedule", "1:0.3"], "give --delay-schedule or --delay-trace, not both"),
])
def test_emulate_bad_bursts_and_traces_exit_2_naming_the_value(tmp_path, args, message):
    files = {"missing": tmp_path / "none.csv", "bad": tmp_path / "bad.csv", "nocol": tmp_path / "nocol.csv",
             "good": tmp_path / "good.csv"}
    files["bad"].write_text("t,delay\n10,0.1\n9,0.2\n")
    files["nocol"].write_text("t,z\n0,1\n")
    files["good"].write_text("t,delay\n0,0.1\n1,0.3\n")
    args = [a.format(**files) for a in args]
    res = runner.invoke(app, ["emulate", *PORTS, "--duration", "0.05", *args])
    if message is None:  # (the rate check is against --rate: below 30 Hz it is accepted)
        assert res.exit_code == 0, res.output
        return
    assert res.exit_code == 2, res.output
    assert message in " ".join(res.output.split()) and "Traceback" not in res.output


def test_emulate_with_bursts_and_a_trace_reports_them(tmp_path):
    log = tmp_path / "flight.csv"
    log.write_text("t,z,latency_ms\n3.0,0.8,20\n3.5,0.8,60\n")
    res = runner.invoke(app, ["emulate", *PORTS, "--duration", "0.2", "--delay", "0.25", "--rate", "20",
                              "--burst", "4:1:2,0.5:0.5", "--burst", "2:1", "--delay-trace", str(log)])
    assert res.exit_code == 0, res.output
    summary = json.loads(next(line for line in res.stdout.splitlines() if line.startswith("{")))
    assert summary["bursts"] == [[0.5, 0.5, 0.0], [2.0, 1.0, 0.0], [4.0, 1.0, 2.0]]
    assert summary["delay_trace"] == {"records": 2, "actuator_delay_min": pytest.approx(0.27),
                                      "actuator_delay_max": pytest.approx(0.31)}
    assert summary["true_delay"] == pytest.approx(0.27)  # 0.25 s plus the first record, 20 ms


# ---------------------------------------------------------------------------------------------- loopback
class _Client(Client):
    """test_flight's loopback client, patient through a silent burst."""

    def __init__(self, emu: DroneEmulator) -> None:
        super().__init__(emu)
        self.sock.settimeout(3.0)  # (a burst without navdata is a silence of a second or more)


@pytest.mark.realtime
def test_loopback_navdata_rate_inside_and_outside_bursts():
    # 50 Hz, a 10 Hz burst over [1, 2) s and a silent one over [2.5, 3.5) s since start.  The counts per window
    # are the closed form of the plan (the module docstring): 50 Hz outside (35 over [0.3, 1), 25 over half a
    # second), 10 over [1, 2) (1.0, 1.1, ..., 1.9), none over [2.5, 3.5); the silent burst is one gap from the last
    # packet before it (2.48 s) to the first after (3.50 s): 1.02 s.  A packet sent a few ms late can cross a
    # window's edge: counts within 1.  A run where the machine stalled the packets is repeated.
    def measure():
        with DroneEmulator(EmulatorConfig(**FREE, seed=1, rate=50.0,
                                          bursts=((1.0, 1.0, 10.0), (2.5, 1.0, 0.0)))) as emu:
            c = _Client(emu)
            rows = []
            while not rows or rows[-1][1] < 4.1:
                nd, t_arrival = c.stamped()
                rows.append((nd.sequence, t_arrival - emu.start_time))
        seq, t = (np.array(x) for x in zip(*rows))
        gaps = np.diff(t)
        silent = (t[:-1] < 2.5) & (t[1:] >= 3.5)
        normal = ((t[1:] < 1.0) | ((t[:-1] >= 2.0) & (t[1:] < 2.5)) | (t[:-1] >= 3.5)) & (t[:-1] > 0.1)
        disturbed = gaps[~silent].max() > 0.12 or gaps[normal].max() > 0.035
        return disturbed, (seq, t, gaps, silent)

    for _ in range(3):
        disturbed, (seq, t, gaps, silent) = measure()
        if not disturbed:
            break
    else:
        pytest.fail("the packets were stalled in 3 attempts: the machine is busy")

    def count(a, b):
        return int(np.count_nonzero((t >= a) & (t < b)))

    assert abs(count(0.3, 1.0) - 35) <= 1 and abs(count(2.0, 2.5) - 25) <= 1 and abs(count(3.5, 4.0) - 25) <= 1
    assert abs(count(1.0, 2.0) - 10) <= 1
    assert count(2.52, 3.5) == 0  # (a packet planned at 2.48 s and sent up to 40 ms late is not the burst's)
    assert silent.sum() == 1 and abs(gaps[silent][0] - 1.02) < 0.015, gaps[silent]
    inside = (t[:-1] >= 1.0) & (t[1:] < 2.0)
    before = (t[:-1] > 0.3) & (t[1:] < 1.0)
    assert abs(np.median(gaps[inside]) - 0.1) < 0.003 and abs(np.median(gaps[before]) - 0.02) < 0.003
    assert np.all(np.diff(seq) == 1)  # a burst is a slower rate, not lost packets


@pytest.mark.realtime
def test_loopback_watchdog_and_physics_keep_running_in_a_silent_burst():
    # with no lag a 0.5 m/s climb sent at t_cmd takes effect at t_cmd + D (D = 0.1 s) and climbs until the
    # watchdog (W = 0.5 s without a command) stops it, found at the first wake-up (every 1 / 50 s) after
    # t_cmd + W: the climb is 0.5 (W - D) less up to 0.5 / 50 m, 0.19 to 0.20 m.  The watchdog falls inside a
    # 1.2 s burst without navdata; had the emulator slept through the burst, it would have found the watchdog
    # after it and applied it from its last wake-up (before the command took effect): no climb at all.  After
    # the burst the navdata show the hover, the altitude and the watchdog bit.
    D, W, v = 0.1, 0.5, 0.5

    def measure():
        with DroneEmulator(EmulatorConfig(**FREE, seed=1, rate=50.0, delay=D, vehicle="lag", lag=0.0, noise=0.0,
                                          watchdog=W, bursts=((2.6, 1.2),))) as emu:
            c = _Client(emu)
            c.take_off()
            c.hover_until(2.5)
            z_hover = c.packet().demo.altitude_mm / 1000.0
            c.send(c.enc.comwdg() + c.enc.pcmd(gaz=v))
            t_cmd = emu.elapsed
            rows = []
            while not rows or rows[-1][0] < 4.2:
                nd, t_arrival = c.stamped()
                rows.append((t_arrival - emu.start_time, nd.demo.altitude_mm / 1000.0, nd.demo.vz / 1000.0,
                             nd.has(NavState.COM_WATCHDOG)))
            c.send(c.enc.comwdg() + c.enc.ref())
        t = np.array([r[0] for r in rows])
        gaps = np.diff(t)
        return t, (t_cmd, z_hover, rows, gaps)

    for _ in range(3):
        t, (t_cmd, z_hover, rows, gaps) = measure()
        if t_cmd < 2.58 and np.max(np.delete(gaps, np.argmax(gaps))) < 0.035:  # the command before the burst
            break
    else:
        pytest.fail("the packets were stalled in 3 attempts: the machine is busy")
    assert np.argmax(gaps) == int(np.flatnonzero(t < 2.6)[-1]) and 1.2 <= gaps.max() < 1.25  # the silent burst
    after = [r for r in rows if r[0] >= 3.8]
    assert after and all(r[3] for r in after) and all(r[2] == 0.0 for r in after)  # watchdog: hovering
    assert len({r[1] for r in after}) == 1  # the altitude stands still
    climb = after[0][1] - z_hover
    assert v * (W - D) - v / 50 - 0.003 < climb < v * (W - D) + 0.003, climb


@pytest.mark.realtime
def test_loopback_actuator_delay_follows_a_replayed_trace(tmp_path):
    # a trace recorded from t = 50 s: 0.20 s, then 0.35 s from 53 s, then 0.15 s from 56 s, replayed from the
    # emulator's start on top of delay = 0.05 s: the actuator delay is 0.25 s until 3 s, 0.40 s until 6 s, then
    # 0.20 s (the reference values, from the file).  A 0.5 m/s step at about 1.8, 3.6 and 6.6 s, each measured as
    # test_emulator_varying measures one: with no lag and no noise the altitude is a ramp from the moment the
    # command takes effect, so (t - (z - z_hover) / 0.5) over the packets after it is that moment (1 mm
    # rounding: 2 ms).  The tolerance is the loopback's scheduling; a run where the machine stalled is repeated.
    trace_file = tmp_path / "trace.csv"
    trace_file.write_text("t,delay\n50,0.20\n53,0.35\n56,0.15\n")
    for _ in range(3):
        with DroneEmulator(EmulatorConfig(**FREE, seed=1, delay=0.05, vehicle="lag", lag=0.0, noise=0.0, rate=100.0,
                                          delay_trace=DelayTrace.from_csv(trace_file))) as emu:
            c = _Client(emu)
            c.take_off()
            results = []
            for at in (1.8, 3.6, 6.6):
                c.hover_until(at)
                results.append(ramp_start(c))
            c.send(c.enc.ref())
        if max(r[1] for r in results) < 0.03:  # packets every 10 ms: a longer gap is the machine stalling a thread
            break
    else:
        pytest.fail("the packets were stalled in 3 attempts: the machine is busy")
    measured = [r[0] for r in results]
    assert np.allclose(measured, [0.25, 0.40, 0.20], atol=0.015), measured
    assert all(r[2] for r in results)  # the navdata speed is 0 until the command takes effect
