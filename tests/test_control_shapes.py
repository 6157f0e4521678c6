"""python-control's shapes (issue 32): t, y = response; response.plot(); series/parallel of several systems;
step_info of any SISO system; poles(T) without a region.

References: python-control 0.10 (its TimeResponseData unpacking, series, parallel and step_info, on delay-free
systems and Padé models), Lambert W for the roots of s + exp(-s T) (s = W_k(-T)/T), closed forms of a first-order
lag's rise and settling times.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import lambertw

import delaykit as dk
from delaykit import (feedback, forced_response, initial_response, parallel, poles, series, ss, step_info,
                      step_response, tf)

control = pytest.importorskip("control")


def test_responses_unpack_as_python_control():
    t = np.linspace(0.0, 5.0, 51)
    mine, theirs = step_response(tf("4/(s^2+2*s+4)"), t), control.step_response(control.tf([4], [1, 2, 4]), T=t)
    (tm, ym), (tc, yc) = mine, theirs
    assert ym.shape == yc.shape == (51,) and np.allclose(ym, yc, atol=1e-9) and np.array_equal(tm, tc)
    assert mine.y.shape == theirs.y.shape == (1, 1, 51) and mine.t is mine.time
    A, B, C = -np.eye(2), np.eye(2), [[1.0, 0.5], [0.0, 1.0]]
    (_, ym), (_, yc) = step_response(ss(A, B, C), t), control.step_response(control.ss(A, B, C, 0 * A), T=t)
    assert ym.shape == yc.shape == (2, 2, 51) and np.allclose(ym, yc, atol=1e-9)
    u = np.sin(t)
    (_, ym), (_, yc) = forced_response(tf("1/(s+1)"), t, u), control.forced_response(control.tf([1], [1, 1]), T=t, U=u)
    assert ym.shape == yc.shape and np.allclose(ym, yc, atol=1e-6)   # python-control: linear input, its own solver
    (_, ym) = initial_response(ss([[-1.0]], [[1.0]], [[1.0]]), t, X0=2.0)
    (_, yc) = control.initial_response(control.ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]]), T=t, X0=2.0)
    assert ym.shape == yc.shape and np.allclose(ym, yc, atol=1e-9)


def test_response_plot_returns_the_figure():
    pytest.importorskip("matplotlib")
    from matplotlib.figure import Figure

    r = step_response(tf("exp(-s)/(s+1)"), np.linspace(0, 4, 41))
    fig = r.plot(title="lag")
    assert isinstance(fig, Figure) and fig.axes[0].lines[0].get_xdata().size == 41
    ax = Figure().subplots()
    assert r.plot(ax=ax) is ax.figure
    f = forced_response(tf("1/(s+1)"), np.linspace(0, 4, 41), 1.0).plot()
    assert np.allclose(f.axes[0].lines[0].get_ydata()[-1], 1 - math.exp(-4), atol=1e-9)


def test_series_and_parallel_of_several_systems_follow_python_control():
    a, b, c = tf("1/(s+1)"), tf("2*exp(-0.5*s)"), tf("(s+3)/(s+2)")
    w = np.geomspace(0.01, 10, 9)
    assert np.allclose(series(a, b, c).frequency_response(w).response, (c * b * a).frequency_response(w).response)
    assert np.allclose(parallel(a, b, c).frequency_response(w).response, (a + b + c).frequency_response(w).response)
    # the order of a MIMO series: the first system first (python-control: series(sys1, sys2) = sys2 * sys1)
    K1, K2 = np.array([[1.0], [2.0]]), np.array([[3.0, 4.0]])
    ref = control.series(control.ss([], [], [], K1), control.ss([], [], [], K2)).D
    got = series(dk.systems.algebra.gain(K1), dk.systems.algebra.gain(K2)).D11
    assert got.shape == ref.shape == (1, 1) and np.allclose(got, ref)
    with pytest.raises(dk.InvalidValueError, match="at least one system"):
        series()


def test_step_info_of_a_delay_free_system_matches_python_control():
    t = np.linspace(0.0, 12.0, 12001)
    sys_c = control.tf([4], [1, 1.2, 4])
    ref = control.step_info(sys_c, T=t)
    m = step_info(tf("4/(s^2+1.2*s+4)"), t)
    dt = t[1] - t[0]
    # python-control reads rise and settling times at samples: agreement to a couple of samples
    assert m.rise_time == pytest.approx(ref["RiseTime"], abs=2 * dt)
    assert m.settling_time == pytest.approx(ref["SettlingTime"], abs=2 * dt)
    assert m.overshoot == pytest.approx(ref["Overshoot"], abs=1e-4)
    assert m.peak == pytest.approx(ref["Peak"], rel=1e-6)
    assert m.peak_time == pytest.approx(ref["PeakTime"], abs=dt)
    # first-order lag, closed forms: rise ln 9 tau, 2 % settling ln 50 tau
    lag = step_info(tf("3/(2*s+1)"), np.linspace(0, 20, 20001))
    assert lag.rise_time == pytest.approx(2 * math.log(9), abs=1e-6)
    assert lag.settling_time == pytest.approx(2 * math.log(50), abs=1e-6)


def test_step_info_of_a_delayed_system_matches_a_pade_model():
    t = np.linspace(0.0, 15.0, 15001)
    pade = control.tf(*control.pade(0.8, 12))
    ref = control.step_info(control.tf([4], [1, 1.2, 4]) * pade, T=t)
    m = step_info(tf("4*exp(-0.8*s)/(s^2+1.2*s+4)"), t)
    # the Padé model's step wiggles near t = 0.8 s (a few 1e-3): its rise and settling times, read at samples,
    # agree to 5 samples; the overshoot and the peak to 1e-3
    dt = t[1] - t[0]
    assert m.rise_time == pytest.approx(ref["RiseTime"], abs=5 * dt)
    assert m.settling_time == pytest.approx(ref["SettlingTime"], abs=5 * dt)
    assert m.overshoot == pytest.approx(ref["Overshoot"], abs=1e-3 * 100)
    assert m.peak_time == pytest.approx(ref["PeakTime"], abs=5 * dt)
    # a loop's step_info is its reference-to-output step, the metrics of simulate(loop)
    loop = dk.Loop("1/((s+1)*(0.5*s+1))", dk.Controller.pi(1.2, 0.6), delay=0.2)
    sim = dk.simulate(loop, t_end=15.0)
    mi = step_info(loop, np.linspace(0, 15, 15001))
    assert mi.overshoot == pytest.approx(sim.metrics.overshoot, abs=1e-3)
    assert mi.settling_time == pytest.approx(sim.metrics.settling_time, abs=5e-3)
    with pytest.raises(dk.InvalidValueError, match="one input and one output"):
        step_info(tf([["1/(s+1)", "1/(s+2)"]]))
    with pytest.raises(dk.InvalidValueError, match="DC gain"):
        step_info(tf("1/s"))


@pytest.mark.parametrize("T", [0.3, 1.0, 1.5])
def test_poles_without_a_region_hold_the_rightmost(T):
    # s + exp(-s T) = 0: s = W_k(-T)/T; W_0 is the rightmost branch (and W_{-1} its conjugate when complex)
    sp = poles(feedback(tf(f"exp(-{T}*s)/s"), 1))
    assert sp.certified
    right = complex(lambertw(-T, 0)) / T
    assert abs(sp.rightmost - complex(right.real, abs(right.imag))) < 1e-9
    # every Lambert root in the region (upper half) is listed, and nothing else
    x0, x1, y0, y1 = sp.region
    ref = [complex(lambertw(-T, k)) / T for k in range(-30, 31)]
    ref = sorted({(round(z.real, 9), round(z.imag, 9)) for z in ref if x0 < z.real < x1 and y0 <= z.imag < y1})
    got = sorted((round(z.real, 9), round(z.imag, 9)) for z in sp.roots)
    assert got == ref
