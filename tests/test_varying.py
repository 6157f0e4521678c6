"""The simulator with a time-varying command delay (delaykit.simulate.varying): against the exact sampled simulator
for constant delays, against a brute-force ODE integration written here for switching delays, the delay models,
the packet-order rules and bad input (Monte Carlo, moved to delaykit.simulate.montecarlo, is in test_montecarlo.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import tf2ss

from delaykit import InvalidTypeError, InvalidValueError, simulate
from delaykit.models import Controller, Loop
from delaykit.simulate.varying import (Burst, CombinedDelay, DelaySchedule, DelayTrace, Jitter, VaryingResponse,
                                       arrival_plan, as_delay_model, simulate_varying)

CONSTANT_LOOPS = [
    Loop("1/s", Controller.p(1.31), delay=0.368, umin=-1, umax=1, period=0.065),
    Loop("1/s", Controller.pv(2.0, 0.3), delay=6 * 0.065, umin=-1, umax=1, period=0.065),  # arrivals on samples
    Loop("1/s", Controller.pv(2.0, 0.3, velocity="filtered"), delay=0.37, umin=-1, umax=1, period=0.065,
         sample_offset=0.03),
    Loop("1/(s*(0.05*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=0.3, umin=-1, umax=3, period=0.02),
    Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2, umin=-2, umax=2, period=0.05),
    Loop("0.62/(15*s+1)", Controller.pi(2.0, 0.2), delay=1.2, output_delay=0.35, umin=-5, umax=5, period=0.1),
    Loop("1/s", Controller.transfer("2*(s+1)/(0.1*s+1)"), delay=0.13, umin=-1, umax=1, period=0.04),
    Loop("(s+2)/(s^2+0.4*s+1)", Controller.p(0.8), delay=0.0, period=0.05),  # direct path through the zero
]


@pytest.mark.parametrize("loop", CONSTANT_LOOPS, ids=lambda lp: repr(lp)[:60])
def test_a_constant_delay_equals_the_exact_sampled_simulator(loop):
    # reference: delaykit.simulate.simulate, the method-of-steps solver (an independent algorithm), on the same grid
    ref = simulate(loop, -0.7, z0=0.4, t_end=12.0)
    for model in (DelaySchedule.constant(loop.delay), Jitter(loop.delay, "uniform", spread=0.0, keep_order=True)):
        r = simulate_varying(loop, model, step=-0.7, z0=0.4, t_end=12.0)
        assert np.max(np.abs(r.output - ref.output(r.t))) < 1e-9
        assert r.dropped == 0
        # the metrics: the peak is refined exactly enough, the times by interpolation on the record
        if ref.metrics.peak_time is not None and ref.metrics.overshoot > 1e-3:
            assert abs(r.metrics.overshoot - ref.metrics.overshoot) < 1e-4
            assert abs(r.metrics.peak_time - ref.metrics.peak_time) < 2e-3
        if ref.metrics.settling_time is not None:
            assert abs(r.metrics.settling_time - ref.metrics.settling_time) < 1e-4


def test_the_default_delay_is_the_loops_own_and_a_number_is_a_constant():
    loop = CONSTANT_LOOPS[0]
    ref = simulate(loop, t_end=6.0)
    for r in (simulate_varying(loop, t_end=6.0), simulate_varying(loop, 0.368, t_end=6.0)):
        assert np.max(np.abs(r.output - ref.output(r.t))) < 1e-9


def _brute_force(plant, kp, ki, umin, umax, h, delay_of, t_end, keep_order, t_rec):
    """An independent simulation: the plant realised by scipy.signal.tf2ss, a PI law on the sampled error with
    its integrator running on the continuous error, the packets' arrivals and the receiver's rule worked out
    here, and SciPy's DOP853 (rtol 1e-12) between consecutive events."""
    A, B, C, D = tf2ss(*plant)
    n = A.shape[0]
    send = np.arange(0.0, t_end + 1e-9, h)
    d = np.array([delay_of(t) for t in send])
    arrive = send + d
    if keep_order:
        arrive = np.maximum.accumulate(arrive)

    def applied(t):  # the newest packet arrived by t (-1: none yet)
        got = np.flatnonzero(arrive <= t + 1e-12)
        return int(got.max()) if got.size else -1

    events = np.unique(np.concatenate([send, arrive[arrive <= t_end], [t_end]]))
    x = np.zeros(n + 1)  # plant states, then the integral of the error
    cmds = np.zeros(send.size)
    out_t, out_y = [], []
    r = 1.0
    for a, b in zip(events[:-1], events[1:]):
        j = applied(a)
        w = cmds[j] if j >= 0 else 0.0
        k = np.flatnonzero(np.abs(send - a) < 1e-12)
        if k.size:  # a sample: read y (input before any switch at this instant), send the command
            w_left = cmds[applied(a - 1e-9)] if applied(a - 1e-9) >= 0 else 0.0
            y = float((C @ x[:n])[0] + D[0, 0] * w_left)
            cmds[k[0]] = min(max(kp * (r - y) + ki * x[n], umin), umax)
            j = applied(a)
            w = cmds[j] if j >= 0 else 0.0

        def f(t, xx, w=w):
            y = C @ xx[:n] + D[:, 0] * w
            return np.concatenate([A @ xx[:n] + B[:, 0] * w, [r - y[0]]])

        sol = solve_ivp(f, (a, b), x, method="DOP853", rtol=1e-12, atol=1e-13, dense_output=True)
        inside = t_rec[(t_rec >= a) & (t_rec < b)]
        if inside.size:
            out_t.extend(inside)
            out_y.extend((C @ sol.sol(inside)[:n]).ravel() + D[0, 0] * w)
        x = sol.y[:, -1]
    return np.array(out_t), np.array(out_y)


@pytest.mark.parametrize("keep_order", [False, True])
def test_a_switching_schedule_matches_a_brute_force_integration(keep_order):
    # the delay rises from 0.12 to 0.31 s at 2 s and falls to 0.07 s at 4 s: after the fall newer packets overtake
    # older ones (dropped, or held back with keep_order); reference: _brute_force above, an ODE solver at 1e-12
    plant = ([1.0], [0.3, 1.0, 0.0])
    loop = Loop("1/(s*(0.3*s+1))", Controller.pi(1.2, 0.3), umin=-1.0, umax=1.0, period=0.05)
    sched = DelaySchedule([0.0, 2.0, 4.0], [0.12, 0.31, 0.07], keep_order=keep_order)
    r = simulate_varying(loop, sched, t_end=8.0, dt=0.01)
    t_ref, y_ref = _brute_force(plant, 1.2, 0.3, -1.0, 1.0, 0.05, sched.value, 8.0, keep_order, r.t)
    assert np.array_equal(t_ref, r.t[r.t < 8.0])
    assert np.max(np.abs(r.output[r.t < 8.0] - y_ref)) < 1e-8
    # packets sent from 3.80 to 3.95 s (delay 0.31) arrive after those sent from 4.0 s (0.07): 4 of them
    assert r.dropped == (0 if keep_order else 4)
    if keep_order:
        assert np.all(np.diff(r.arrival_times) >= 0)


def test_arrival_rules_by_hand():
    send = np.array([0.0, 0.1, 0.2, 0.3])
    d = np.array([0.5, 0.2, 0.35, 0.05])  # arrivals 0.5, 0.3, 0.55, 0.35
    a, used = arrival_plan(send, d, keep_order=False)
    assert a.tolist() == pytest.approx([0.5, 0.3, 0.55, 0.35])
    assert used.tolist() == [False, True, False, True]  # packet 0 arrives after 1, packet 2 after 3
    a, used = arrival_plan(send, d, keep_order=True)
    assert a.tolist() == pytest.approx([0.5, 0.5, 0.55, 0.55]) and used.all()


def test_overtaking_packets_hold_the_newest_command():
    # a P loop on 1/s whose delay falls from 0.4 to 0.1 s at t = 1: with keep_order=False the packets sent in
    # [0.7, 1.0) are stale when they arrive (the ones sent from 1.0 on arrive from 1.1), so the applied input
    # after 1.1 s is the command sent 0.1 s earlier; reference: the held commands themselves
    loop = Loop("1/s", Controller.p(1.0), period=0.1)
    r = simulate_varying(loop, DelaySchedule([0.0, 1.0], [0.4, 0.1]), t_end=3.0, dt=0.05)
    stale = (r.send_times >= 0.65) & (r.send_times < 0.95)
    assert np.array_equal(~r.used, stale)
    for t in (1.15, 1.55, 2.45):
        k = int(math.floor(t / 0.1 + 1e-9)) - 1
        assert r.applied_input[np.argmin(abs(r.t - t))] == pytest.approx(r.commands[k], abs=1e-15)


def test_jitter_distributions_and_seeds():
    t = np.arange(20000) * 0.01
    u = Jitter(0.2, "uniform", spread=0.1, seed=1).packet_delays(t)
    e = Jitter(0.2, "exponential", scale=0.05, seed=1).packet_delays(t)
    g = Jitter(0.2, "gamma", shape=3.0, scale=0.02, seed=1).packet_delays(t)
    c = Jitter(0.2, "exponential", scale=0.05, cap=0.04, seed=1).packet_delays(t)
    # means of 20,000 draws within 5 standard errors of the distributions' means (numpy's generators)
    assert abs(u.mean() - 0.25) < 5 * 0.1 / math.sqrt(12 * t.size) and u.min() >= 0.2 and u.max() <= 0.3
    assert abs(e.mean() - 0.25) < 5 * 0.05 / math.sqrt(t.size)
    assert abs(g.mean() - 0.26) < 5 * math.sqrt(3) * 0.02 / math.sqrt(t.size)
    capped = np.isclose(c, 0.24, rtol=0, atol=1e-15)  # P(extra >= 0.04) = exp(-0.04 / 0.05)
    assert c.max() == pytest.approx(0.24) and capped.mean() == pytest.approx(math.exp(-0.8), abs=0.02)
    assert np.array_equal(u, Jitter(0.2, "uniform", spread=0.1, seed=1).packet_delays(t))
    assert not np.array_equal(u, Jitter(0.2, "uniform", spread=0.1, seed=2).packet_delays(t))
    assert Jitter(0.2, "exponential", scale=0.05).bounds() == (0.2, math.inf)
    assert Jitter(0.2, "exponential", scale=0.05, cap=0.1).bounds() == (0.2, pytest.approx(0.3))


def test_combinations_bursts_and_functions():
    base = DelaySchedule([0.0, 10.0], [0.25, 0.40])
    model = base + Burst(5.0, 6.0, 0.3, every=20.0) + 0.01
    assert isinstance(model, CombinedDelay) and len(model.parts) == 3
    t = np.array([0.0, 5.0, 5.99, 6.01, 10.0, 25.5, 26.5])
    assert model.packet_delays(t).tolist() == pytest.approx([0.26, 0.56, 0.56, 0.26, 0.41, 0.71, 0.41])
    assert model.bounds() == pytest.approx((0.26, 0.71))
    f = DelaySchedule.from_function(lambda s: 0.3 + 0.1 * math.sin(s))
    assert f.packet_delays([0.0, math.pi / 2]).tolist() == pytest.approx([0.3, 0.4])
    assert (Jitter(0.1, spread=0.1, keep_order=True) + base).keep_order
    assert as_delay_model([(0, 0.25), (2, 0.4)]).value(3.0) == 0.4


def test_traces_from_arrays_csv_and_flight_logs(tmp_path):
    tr = DelayTrace([100.0, 100.5, 101.0], [0.30, 0.35, 0.28])
    assert tr.packet_delays([0.0, 0.49, 0.5, 5.0]).tolist() == [0.30, 0.30, 0.35, 0.28]
    lin = DelayTrace([100.0, 101.0], [0.30, 0.40], interpolation="linear")
    assert lin.packet_delays([0.25])[0] == pytest.approx(0.325)
    p = tmp_path / "d.csv"
    p.write_text("t,delay,other\n0.0,0.25,x\n\n1.0,0.30,y\n2.5,0.28,z\n")
    assert DelayTrace.from_csv(p).delays == (0.25, 0.30, 0.28)
    log = tmp_path / "flight.csv"
    log.write_text("t,z,z_ref,u,vz,seq,recv_time,latency_ms\n"
                   "3.0,0.8,0.8,0,0,1,3.0,0.12\n3.066,0.8,0.8,0,0,2,3.066,0.2\n")
    fl = DelayTrace.from_flight_log(log)
    assert fl.delays == pytest.approx((0.00012, 0.0002)) and fl.start == 3.0
    # replayed through the simulator: the loop sees the trace plus a base delay
    loop = Loop("1/s", Controller.p(1.31), umin=-1, umax=1, period=0.065)
    r = simulate_varying(loop, fl + 0.3, t_end=3.0)
    assert r.delays[0] == pytest.approx(0.30012) and r.delays[-1] == pytest.approx(0.3002)


@pytest.mark.parametrize("text, message", [
    ("t,delay\n0,0.2\n1,abc\n", "row 3: delay is 'abc', not a finite number"),
    ("t,delay\n0,0.2\n0,0.3\n", "row 3: t = 0 does not increase"),
    ("t,delay\n0,0.2\n1,-0.3\n", "row 3: delay must be at least 0, got -0.3"),
    ("t,delay\n0,nan\n", "row 2: delay is 'nan', not a finite number"),
    ("time,lag\n0,0.2\n", "no column 't'"),
    ("t,delay\n", "no rows after the header"),
])
def test_bad_trace_files_name_the_row_and_value(tmp_path, text, message):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InvalidValueError, match=message.replace("(", r"\(")):
        DelayTrace.from_csv(p)


def test_bad_schedules_and_settings_are_delaykit_errors():
    with pytest.raises(InvalidValueError, match=r"times must increase: times\[2\] = 1 s is not after times\[1\] = 3"):
        DelaySchedule([0.0, 3.0, 1.0], [0.2, 0.3, 0.4])
    with pytest.raises(InvalidValueError, match=r"delays\[1\] must be a finite delay of at least 0 s, got -0.3"):
        DelaySchedule([0.0, 1.0], [0.2, -0.3])
    with pytest.raises(InvalidValueError, match="one delay per time"):
        DelaySchedule([0.0, 1.0], [0.2])
    with pytest.raises(InvalidValueError, match="list of \\(time, delay\\) pairs"):
        DelaySchedule.from_pairs([(0.0, 0.2, 9.0)])
    with pytest.raises(InvalidValueError, match="base \\(s\\) must be at least 0, got -0.1"):
        Jitter(-0.1)
    with pytest.raises(InvalidValueError, match="distribution must be one of"):
        Jitter(0.1, "normal")
    with pytest.raises(InvalidValueError, match="a burst must end after it starts"):
        Burst(3.0, 2.0, 0.1)
    with pytest.raises(InvalidTypeError):
        as_delay_model("0.3")
    loop = Loop("1/s", Controller.p(1.0), period=0.1)
    neg = DelaySchedule.from_function(lambda t: 0.35 - t)
    with pytest.raises(InvalidValueError, match="at t = 0.4 s must be a finite delay of at least 0 s, got -0.05"):
        simulate_varying(loop, neg, t_end=2.0)
    with pytest.raises(InvalidValueError, match="needs a sampled controller"):
        simulate_varying(Loop("1/s", Controller.p(1.0)), 0.3)
    with pytest.raises(InvalidValueError, match="anti-windup"):
        simulate_varying(Loop("1/s", Controller.pi(1.0, 0.5, antiwindup="clamp"), period=0.1), 0.3)
    with pytest.raises(InvalidValueError, match="step must not be zero"):
        simulate_varying(loop, 0.3, step=0.0)


def test_a_continuous_loop_takes_a_period_and_the_result_reports_itself():
    cont = Loop("1/s", Controller.p(1.31), delay=0.3, umin=-1, umax=1)
    r = simulate_varying(cont, Jitter(0.3, spread=0.05, seed=7), period=0.065, t_end=6.0)
    ref_sampled = simulate_varying(cont.replace(period=0.065), Jitter(0.3, spread=0.05, seed=7), t_end=6.0)
    assert np.array_equal(r.output, ref_sampled.output)
    assert isinstance(r, VaryingResponse) and repr(r).startswith("VaryingResponse(step=1, 93 packets (")
    d = r.to_dict(arrays=True)
    assert d["packets"] == 93 and len(d["t"]) == r.t.size and d["delay"]["kind"] == "jitter"
    assert 0.3 <= d["delay_min"] <= d["delay_max"] <= 0.35
