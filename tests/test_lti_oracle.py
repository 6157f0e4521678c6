"""The time responses of delay systems (DelayLTI) checked against independent references.

First the oracle (tests/oracle_lti.py, SciPy's DOP853 by the method of steps) is checked against references that
do not use it: closed forms, python-control on delay-free systems, and delaykit's exact Loop simulator (a Taylor
method of steps, a different method and code) on the paper's loops built by the system algebra.  Then the
time-domain kernel (``delaykit.simulate.systems``) is checked against the oracle on random interconnections
(hypothesis, tests/strategies_lti.py), against high-order Padé approximations run by python-control (linear
systems, away from the delays' edges), and against python-control exactly when every delay is 0.  The kernel
tests skip, with the reason, while ``delaykit.simulate.systems`` does not exist.
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from delaykit import AltitudeLoop, DelayLTI, feedback, from_loop, simulate, ss, tf
from oracle_lti import LTIOracle
from strategies_lti import delay_free_systems, edge_times, linear_systems, systems

TOL = 1e-8  # the agreement: kernel and oracle to 1e-8 (relative to the response's size, at least 1)

# hypothesis: a few examples in the default run, many more in the slow one
FAST = settings(max_examples=8)
SLOW = settings(max_examples=150)


def kernel():
    """The time-domain kernel, or a clean skip saying why."""
    return pytest.importorskip("delaykit.simulate.systems",
                               reason="the DelayLTI time-domain kernel (delaykit.simulate.systems) has not landed")


def close(a, b, tol=TOL):
    """max |a - b| <= tol * max(1, max |b|), with the worst point in the message."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    assert a.shape == b.shape, (a.shape, b.shape)
    scale = max(1.0, float(np.nanmax(np.abs(b))))
    err = np.abs(a - b)
    k = np.unravel_index(int(np.nanargmax(err)), err.shape)
    assert err[k] <= tol * scale, f"differ by {err[k]:.3g} at index {k}: {a[k]!r} vs {b[k]!r} (scale {scale:.3g})"


# --------------------------------------------------------------------------------------------------------------
# the oracle against closed forms
# --------------------------------------------------------------------------------------------------------------
def test_oracle_first_order_lag_with_input_delay():
    # y = K (1 - exp(-(t - tau)/T)) for t > tau, 0 before (step); K/T exp(-(t - tau)/T) (impulse);
    # K ((t - tau) - T (1 - exp(-(t - tau)/T))) for the ramp u = t (forced, linear between samples: exact)
    K, T, tau = 2.0, 1.5, 0.7
    o = LTIOracle(tf(f"{K}*exp(-{tau}*s)/({T}*s+1)"))
    t = np.linspace(0.0, 6.0, 61)
    s = np.maximum(t - tau, 0.0)
    close(o.step(t)[0, 0], np.where(t > tau, K * (1 - np.exp(-s / T)), 0.0), 1e-11)
    imp = o.impulse(t)[0, 0]
    close(imp[t > tau], K / T * np.exp(-s[t > tau] / T), 1e-11)
    assert np.all(imp[t < tau] == 0.0)
    close(o.forced(t, t)[0], K * (s - T * (1 - np.exp(-s / T))), 1e-11)


def _phi(s):
    """x' = -x(t - 1) with x = 1 on [-1, 0], by the method of steps on [0, 3] (Bellman & Cooke's example)."""
    s = np.asarray(s, float)
    return np.where(s <= 1, 1 - s, np.where(s <= 2, 1 - s + (s - 1) ** 2 / 2,
                                            1 - s + (s - 1) ** 2 / 2 - (s - 2) ** 3 / 6))


def test_oracle_scalar_dde_method_of_steps_polynomials():
    t = np.linspace(0.0, 4.0, 81)
    # x' = -w, w(t) = x(t - 1), x(0) = 1, zero history: x = 1 on [0, 1], then the classical solution shifted by 1
    dde = DelayLTI(A=[[0.0]], B1=[[0.0]], B2=[[-1.0]], C1=[[1.0]], C2=[[1.0]], delays=[1.0])
    close(LTIOracle(dde).initial(t, 1.0)[0], np.where(t <= 1, 1.0, _phi(t - 1)), 1e-12)
    # the unit feedback of exp(-s)/s: y' = 1 - y(t - 1) after t = 1, so 1 - y is the same solution
    close(LTIOracle(feedback(tf("exp(-s)/s"), 1)).step(t)[0, 0], np.where(t <= 1, 0.0, 1 - _phi(t - 1)), 1e-12)


def test_oracle_pure_difference_equation():
    # a neutral system without states: y(t) = u(t) + a y(t - tau); its step response is the staircase
    # sum_{k <= t/tau} a^k.  Compared between the jumps (the jump times themselves are conventions).
    a, tau = -0.6, 0.45
    sys = DelayLTI(D11=[[1.0]], D12=[[a]], D21=[[1.0]], D22=[[a]], delays=[tau])
    t = np.linspace(0.01, 5.0, 97)
    t = t[np.abs(t / tau - np.round(t / tau)) > 1e-6]
    ref = np.array([sum(a ** k for k in range(int(math.floor(ti / tau)) + 1)) for ti in t])
    close(LTIOracle(sys).step(t)[0, 0], ref, 1e-13)


# --------------------------------------------------------------------------------------------------------------
# the oracle against python-control (no delays) and Padé approximations (linear, away from edges)
# --------------------------------------------------------------------------------------------------------------
@FAST
@given(delay_free_systems())
def test_oracle_matches_python_control_without_delays(sys):
    t = np.linspace(0.0, 6.0, 61)
    P = sys.to_control()
    close(LTIOracle(sys).step(t), np.asarray(control.step_response(P, t).outputs).reshape(sys.noutputs,
                                                                                        sys.ninputs, -1), 1e-9)
    x0 = np.linspace(1.0, -1.0, sys.nstates)
    close(LTIOracle(sys).initial(t, x0), np.asarray(control.initial_response(P, t, x0).outputs
                                                    ).reshape(sys.noutputs, -1), 1e-9)


def test_oracle_matches_pade_on_the_wood_berry_loop():
    # a 6th order Padé per delay, run by python-control: its error dies out away from the delays' edges.  Over
    # t in [40, 100] min it is below 1e-8 (measured: 8.5e-9), as the two computations share nothing.
    T = wood_berry_loop()
    t = np.linspace(0.0, 100.0, 201)
    y = LTIOracle(T).step(t)
    yp = np.asarray(control.step_response(T.to_control(pade_order=6), t).outputs)
    late = t >= 40
    close(y[..., late], yp[..., late], 2e-8)


def wood_berry_loop() -> DelayLTI:
    """Wood & Berry's column under Luyben's BLT PI tuning (docs/guide/systems.md)."""
    G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
            ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]],
           inputs=["R", "S"], outputs=["xD", "xB"], name="Wood-Berry")
    K = tf([["0.375*(1 + 1/(8.29*s))", 0], [0, "-0.075*(1 + 1/(23.6*s))"]],
           inputs=["e1", "e2"], outputs=["R", "S"], name="BLT PI")
    return feedback(G * K, 1)


# --------------------------------------------------------------------------------------------------------------
# the oracle against the exact Loop simulator (Taylor method of steps) on the paper's loops, by the algebra
# --------------------------------------------------------------------------------------------------------------
ALTITUDE = [
    pytest.param(dict(kp=1.31, delay=0.368), id="P-saturated"),
    pytest.param(dict(kp=1.31, delay=0.368, vmax=None), id="P-linear"),
    pytest.param(dict(kp=2.0, delay=0.37, kv=0.3, velocity="filtered"), id="PV-filtered-saturated"),
    pytest.param(dict(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", lag=0.2, vmax=0.5), id="PV-lag-saturated"),
    pytest.param(dict(kp=2.0, delay=0.37, kv=0.3, vmax=None), id="PV-true-neutral"),
]


@pytest.mark.parametrize("params", ALTITUDE)
@pytest.mark.parametrize("step", [1.0, 3.0])
def test_oracle_matches_the_loop_simulator(params, step):
    loop = AltitudeLoop(**params)
    sys = from_loop(loop)
    # off the grid of the loop delay's multiples: in the neutral loop the command jumps there, and a jump's
    # value is a convention (the oracle gives the right limit, Response.command the left); the step is at t[0] = 0
    t = np.concatenate([[0.0], np.linspace(0.0, 12.0, 241) + 0.0123])
    res = LTIOracle(sys).step(t, amplitude=step, inputs=[0])   # input 0 is r
    ref = simulate(loop, step=step, t_end=13.0)
    close(res[0, 0], ref.output(t))
    close(res[1, 0], ref.command(t))


@pytest.mark.slow
def test_oracle_matches_the_loop_simulator_neutral_saturated():
    # the true-velocity PV loop with its limit: neutral (the command feeds back through the velocity without a
    # state) and saturated; the oracle's recursion through the history makes this one slow
    loop = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3)
    t = np.concatenate([[0.0], np.linspace(0.0, 12.0, 241) + 0.0123])
    res = LTIOracle(from_loop(loop)).step(t, amplitude=3.0, inputs=[0])
    ref = simulate(loop, step=3.0, t_end=13.0)
    close(res[0, 0], ref.output(t))
    close(res[1, 0], ref.command(t))
