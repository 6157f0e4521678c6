"""Step metrics of sampled responses, and the second-order relations of the paper's section 3."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

from delaykit import AltitudeLoop, InvalidValueError, SecondOrder, noise_level, simulate, step_metrics


def test_paper_second_order_numbers():
    # Section 5.1.2: Mo = 2.300 %, tp = 3.055 s give zeta 0.7684, wn 1.6069 rad/s, s = -1.2347 +- 1.0284j.
    so = SecondOrder.from_step(2.300, 3.055)
    assert round(so.zeta, 4) == 0.7684
    assert round(so.omega_n, 4) == 1.6069
    # The printed roots come from the rounded zeta and wn; unrounded they are -1.23478 +- 1.02834j.
    paper = SecondOrder(0.7684, 1.6069).root
    assert round(paper.real, 4) == -1.2347 and round(paper.imag, 4) == 1.0284
    assert abs(so.root - paper) < 1e-4


@pytest.mark.parametrize("zeta, wn", [(0.1, 3.0), (0.5, 2.0), (0.7684, 1.6069), (0.95, 0.3)])
def test_second_order_round_trips(zeta, wn):
    so = SecondOrder(zeta, wn)
    back = SecondOrder.from_step(so.overshoot, so.peak_time)
    assert math.isclose(back.zeta, zeta, rel_tol=1e-12) and math.isclose(back.omega_n, wn, rel_tol=1e-12)
    again = SecondOrder.from_root(so.root)
    assert math.isclose(again.zeta, zeta, rel_tol=1e-12) and math.isclose(again.omega_n, wn, rel_tol=1e-12)


def test_second_order_formulas_match_the_analytic_step_response():
    # The closed-form step response of wn^2 / (s^2 + 2 zeta wn s + wn^2), sampled finely.
    so = SecondOrder(0.4, 2.5)
    t = np.linspace(0, 12, 120001)
    wd = so.omega_n * math.sqrt(1 - so.zeta**2)
    y = 1 - np.exp(-so.zeta * so.omega_n * t) * (np.cos(wd * t) + so.zeta / math.sqrt(1 - so.zeta**2) * np.sin(wd * t))
    m = step_metrics(t, y, step=1.0)
    assert math.isclose(m.overshoot, so.overshoot, abs_tol=1e-8)
    assert math.isclose(m.peak_time, so.peak_time, abs_tol=1e-6)


def test_bad_second_order_inputs():
    with pytest.raises(InvalidValueError, match="overshoot"):
        SecondOrder.from_step(0.0, 1.0)
    with pytest.raises(InvalidValueError, match="peak_time"):
        SecondOrder.from_step(5.0, -1.0)
    with pytest.raises(InvalidValueError, match="zeta"):
        SecondOrder(1.2, 1.0)
    with pytest.raises(InvalidValueError, match="root"):
        SecondOrder.from_root(1 + 1j)


@pytest.mark.parametrize("loop", [AltitudeLoop(kp=1.31, delay=0.368), AltitudeLoop(kp=2.0, delay=0.37, kv=0.1),
                                  AltitudeLoop(kp=1.8, delay=0.45)])
def test_sampled_metrics_agree_with_python_control_step_info(loop):
    # python-control's step_info works on samples without interpolation: its times are sample times,
    # so the two definitions coincide to within one sample interval.
    dt = 1e-3
    s = simulate(loop, 1.0).sample(dt=dt)
    ours = step_metrics(s["t"], s["z"], step=1.0)
    info = control.step_info(s["z"], s["t"], yfinal=1.0, SettlingTimeThreshold=0.02, RiseTimeLimits=(0.1, 0.9))
    assert math.isclose(ours.overshoot, info["Overshoot"], abs_tol=1e-4)
    assert abs(ours.peak_time - info["PeakTime"]) <= dt
    assert abs(ours.rise_time - info["RiseTime"]) <= dt
    assert abs(ours.settling_time - info["SettlingTime"]) <= dt


@pytest.mark.parametrize("step, z0", [(1.0, 0.0), (-0.7, 2.0), (2.5, 1.2)])
def test_sampled_metrics_converge_to_the_exact_ones(step, z0):
    loop = AltitudeLoop(kp=1.6, delay=0.41)
    resp = simulate(loop, step, z0=z0)
    exact = resp.metrics
    for dt in (0.02, 0.005):
        s = resp.sample(dt=dt)
        m = step_metrics(s["t"], s["z"], step=step, z0=z0)
        # linear interpolation of crossings: error ~ dt^2 |z''| / 8; quadratic peak: error ~ dt^3
        tol = 2 * dt**2
        assert abs(m.rise_time - exact.rise_time) < tol
        assert abs(m.settling_time - exact.settling_time) < tol
        assert abs(m.peak_time - exact.peak_time) < 10 * tol
        assert abs(m.overshoot - exact.overshoot) < 100 * tol


def test_irregular_sampling_and_step_time():
    resp = simulate(AltitudeLoop(kp=1.31, delay=0.368), 1.0, z0=0.5)
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(-2.0, 15.0, 4000))
    z = resp.altitude(t)
    m = step_metrics(t + 100.0, z, step=1.0, step_time=100.0)
    assert abs(m.rise_time - resp.metrics.rise_time) < 1e-3
    assert abs(m.overshoot - resp.metrics.overshoot) < 1e-3


def test_noise_is_estimated_and_smoothing_recovers_the_metrics():
    resp = simulate(AltitudeLoop(kp=1.31, delay=0.45), 1.0)
    s = resp.sample(dt=0.01)
    rng = np.random.default_rng(1)
    noisy = s["z"] + 0.003 * rng.standard_normal(s["z"].size)
    m = step_metrics(s["t"], noisy, step=1.0, smooth=21, peak_window=31)
    assert 0.0025 < m.noise < 0.0035
    exact = resp.metrics
    assert abs(m.overshoot - exact.overshoot) < 0.2
    assert abs(m.peak_time - exact.peak_time) < 0.1
    assert abs(m.rise_time - exact.rise_time) < 0.02
    assert 0.0025 < noise_level(noisy) < 0.0035


def test_record_that_never_settles_and_one_with_no_overshoot():
    t = np.linspace(0, 10, 1001)
    y = 1 + 0.3 * np.sin(3 * t) - np.exp(-t)  # keeps oscillating outside a 2 % band
    m = step_metrics(t, y, step=1.0)
    assert m.settling_time is None and not m.settled
    mono = step_metrics(t, 1 - np.exp(-t), step=1.0)
    assert mono.overshoot == 0.0 and mono.peak_time is None
    assert math.isclose(mono.rise_time, math.log(9), abs_tol=1e-4)
    assert math.isclose(mono.settling_time, math.log(50), abs_tol=1e-3)
    # "tail" takes the final value from the last 10 % of a record, which must have settled
    tl = np.linspace(0, 30, 3001)
    tail = step_metrics(tl, 0.9 * (1 - np.exp(-tl)), step=1.0, final="tail")
    assert tail.overshoot < 1e-6 and math.isclose(tail.steady_state_error, 0.1, abs_tol=1e-3)


@pytest.mark.parametrize(
    "t, z, kw, fragment",
    [
        ([0, 1, 1, 2], [0, 1, 2, 3], {}, r"t\[2\]"),
        ([0, 1, 2, 3], [0, float("nan"), 2, 3], {}, r"z\[1\]"),
        ([0, 1, 2], [0, 1], {}, "equal length"),
        ([0, 1, 2, 3], [0, 1, 2, 3], {"step": 0.0}, "step"),
        ([0, 1, 2, 3], [0, 1, 2, 3], {"step_time": 2.5}, "at least 3 samples"),
        ([0, 1, 2, 3, 4], [0, 1, 2, 3, 4], {"peak_window": 4}, "peak_window"),
    ],
)
def test_bad_records(t, z, kw, fragment):
    kw = {"step": 1.0, **kw}
    with pytest.raises(InvalidValueError, match=fragment):
        step_metrics(t, z, **kw)
