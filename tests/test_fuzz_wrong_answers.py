"""Issue 34, the wrong answers: cases that gave a confident result that was false, each now answered correctly or
refused with a delaykit error.  Reference values come from closed forms stated at each test."""

from __future__ import annotations

import math

import numpy as np
import pytest

from delaykit import delay, feedback, hinfnorm, tf
from delaykit.spectrum.stability import far_right_verdict, in_delay_units


def _first_order_boundary(k: float, T: float = 1.0) -> float:
    """The largest delay for which ``k exp(-tau s) / (T s + 1)`` under unity negative feedback is stable, k > 1.

    Closed form: the crossing ``j w`` with ``|k / (j w T + 1)| = 1`` gives ``w T = sqrt(k^2 - 1)`` and the phase
    condition ``w tau = arccos(-1 / k)`` (written without ``k^2``, which overflows past 1e154)."""
    return T * math.acos(-1.0 / k) / (k * math.sqrt(1.0 - 1.0 / k / k))


# -- the characteristic function keeps every term, at every scale ------------------------------------------------
@pytest.mark.parametrize("k", [1.0, 1e14, 1e20, 1e100, 1e300, 1e-300])
def test_characteristic_keeps_the_undelayed_part(k):
    # 1 + k exp(-0.3 s) / (s + 1) = 0  <=>  s + 1 + k exp(-0.3 s) = 0: by hand
    q = feedback(k * tf("exp(-0.3*s)/(s+1)"), 1).characteristic()
    assert q.delays == (0.0, 0.3)
    assert np.allclose(q.polys[0], [1.0, 1.0], rtol=1e-12, atol=0)
    assert len(q.polys[1]) == 1 and abs(q.polys[1][0] - k) <= 1e-12 * k


def test_high_gain_loop_is_unstable_everywhere():
    # the case: 1e20 exp(-0.3 s)/(s+1) is far past its delay margin (closed form: 1.6e-20 s), so unstable;
    # before, the s + 1 was dropped and is_stable said True, hinfnorm 1
    T = feedback(tf("1e20*exp(-0.3*s)/(s+1)"), 1)
    assert T.is_stable() is False
    assert math.isinf(hinfnorm(T).value) and not hinfnorm(T).stable


@pytest.mark.parametrize("plant", ["lag", "integrator"])
def test_stability_boundary_sweeps_the_gain_from_1_to_1e300(plant):
    # closed forms: k exp(-tau s)/(s+1) is stable iff tau < arccos(-1/k)/sqrt(k^2-1) (k > 1); k exp(-tau s)/s is
    # stable iff k tau < pi/2.  Each gain is tried 5 % inside and 5 % outside its boundary.
    wrong = []
    for j in range(0, 301, 10):
        k = 10.0 ** j if j else 1.5
        if plant == "lag":
            G, edge = tf("1/(s+1)"), _first_order_boundary(k)
        else:
            G, edge = tf("1/s"), math.pi / 2 / k
        for f, expected in ((0.95, True), (1.05, False)):
            verdict = feedback(k * delay(f * edge) * G, 1).is_stable()
            if verdict is not expected:
                wrong.append((k, f, verdict))
    assert wrong == []


@pytest.mark.parametrize("T", [1e-6, 60.0, 1e6])
@pytest.mark.parametrize("k", [1e-300, 1e-20, 0.5, 3.0, 1e15, 1e150, 1e300])
def test_stability_at_every_time_scale(T, k):
    # k exp(-0.3 T s)/(T s + 1): microsecond, minute and 11-day plants; closed form as above (time scaled by T);
    # |k| < 1 is stable for every delay (|L(jw)| < 1)
    expected = k < 1 or 0.3 < _first_order_boundary(k)
    assert feedback(k * delay(0.3 * T) * tf(f"1/({T}*s+1)"), 1).is_stable() is expected


def test_in_delay_units_has_the_roots_scaled():
    # s + 1 + 1e20 exp(-0.3 s) at s = z / 0.3, divided by 1e20: by hand
    q = in_delay_units(feedback(1e20 * tf("exp(-0.3*s)/(s+1)"), 1).characteristic())
    assert q.delays == (0.0, 1.0)
    assert np.allclose(q.polys[0], [1e-20 / 0.3, 1e-20], rtol=1e-12, atol=0)
    assert q.polys[1] == (1.0,)


def test_far_right_verdict_refuses_neutral():
    from delaykit import QuasiPolynomial

    # s + 1 + s exp(-s) is neutral: not this search's to decide
    assert far_right_verdict(QuasiPolynomial([[1, 1], [1, 0]], [0.0, 1.0])) is None



@pytest.mark.parametrize("k", [1e20, 1e300])
def test_poles_of_a_huge_gain_loop_are_found_in_scale(k):
    # s + 1 + k exp(-tau s) = 0 with u = tau (s + 1): u exp(u) = -k tau exp(tau), so s = W_b(-k tau e^tau)/tau - 1
    # (scipy's Lambert W, branches 0 and -1 hold the rightmost pair); tau half the stability boundary
    from scipy.special import lambertw

    tau = 0.5 * _first_order_boundary(k)
    sp = feedback(k * delay(tau) * tf("1/(s+1)"), 1).poles((-10 * k, 10 * k, -10 * k, 10 * k))
    assert sp.certified
    ref = max((complex(lambertw(-k * tau * math.exp(tau), b)) / tau - 1 for b in (0, -1)), key=lambda z: z.real)
    ref = complex(ref.real, abs(ref.imag))
    assert abs(sp.rightmost - ref) <= 1e-8 * abs(ref)


# -- responses over a horizon shorter than the kernel's time tolerance -------------------------------------------
@pytest.mark.parametrize("t_end", [1e-300, 1e-16, 1e-14, 1e-13])
def test_step_and_initial_over_a_tiny_horizon(t_end):
    # closed forms for 1/(s+1): step 1 - exp(-t), initial from x0 = 1: exp(-t); before, every value was NaN with
    # status "exact" and 0 pieces
    t = np.array([0.0, t_end / 2, t_end])
    r = tf("1/(s+1)").step(t)
    assert r.status == "exact" and r.pieces >= 1
    assert np.allclose(r.outputs[0, 0], -np.expm1(-t), rtol=1e-12, atol=0)
    from delaykit import ss

    r = ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]]).initial(t, X0=1.0)
    assert r.status == "exact" and np.allclose(r.outputs[0], np.exp(-t), rtol=1e-12, atol=0)


def test_tiny_horizon_of_a_picosecond_plant_with_a_femtosecond_delay():
    # 1/(1e-12 s + 1) after a delay of 1e-15 s: 0 until the delay, then 1 - exp(-(t - 1e-15)/1e-12) (closed form)
    t = np.array([0.0, 5e-16, 1e-15, 1e-14, 1e-13])
    r = tf("exp(-1e-15*s)/(1e-12*s+1)").step(t)
    ref = np.where(t > 1e-15, -np.expm1(-(t - 1e-15) / 1e-12), 0.0)
    assert r.status == "exact"
    assert np.allclose(r.outputs[0, 0], ref, rtol=1e-9, atol=1e-300)


def test_many_step_responses_over_a_tiny_horizon():
    # the batch path: k (1 - exp(-t)) for k = 1, 2
    from delaykit.simulate.systems import step_response_many

    r = step_response_many([tf("1/(s+1)"), tf("2/(s+1)")], [0.0, 1e-16])
    assert r.status == ("exact", "exact")
    assert np.allclose(r.outputs[:, 0, 0, 1], [1e-16, 2e-16], rtol=1e-12, atol=0)


def test_nan_is_never_labelled_exact():
    # the last guard: an "exact" run with an output missing at a time asked says where it stalled
    from delaykit.simulate.systems import _honest

    out = np.array([[0.0, 1.0, np.nan, np.nan]])
    assert _honest("exact", 3.0, out, np.array([0.0, 1.0, 2.0, 3.0])) == ("stalled", 2.0)
    assert _honest("exact", 3.0, out[:, :2], np.array([0.0, 1.0])) == ("exact", 3.0)
    assert _honest("overflow", 1.5, out, np.array([0.0, 1.0, 2.0, 3.0])) == ("overflow", 1.5)


# -- relay cycles: the one the relay settles into ------------------------------------------------------------------
def _ultimate_period(order: int, theta: float) -> float:
    """The exact ultimate period of exp(-theta s)/(s+1)^order: order atan(w) + theta w = pi (closed form phase)."""
    from scipy.optimize import brentq

    w = brentq(lambda w: order * math.atan(w) + theta * w - math.pi, 1e-9, math.pi / theta)
    return 2 * math.pi / w


@pytest.mark.parametrize("order", [6, 12])
def test_relay_cycle_of_a_high_order_lag_is_the_slow_stable_one(order):
    # the case: 1/(s+1)^12 with a 0.1 s delay gave a 0.57 s "cycle" of amplitude 4e-13 (an unstable
    # periodic solution).  The relay's cycle of a lag this smooth is nearly sinusoidal, so its period is within
    # 1 % of the exact ultimate period (closed-form phase) and its amplitude within 3 % of the describing
    # function's 4 d |P(j w)| / pi there; the issue measured 23.5 s and 0.84 for order 12
    from delaykit import relay_cycle

    c = relay_cycle(f"1/(s+1)^{order}", 0.1)
    pu = _ultimate_period(order, 0.1)
    assert abs(c.period / pu - 1) < 0.01
    w = 2 * math.pi / c.period
    assert abs(c.output_amplitude / (4 / math.pi * (1 + w * w) ** (-order / 2)) - 1) < 0.03


def test_relay_cycle_refuses_an_h_max_below_the_delay():
    # the integrator's cycle has h = 2 theta = 0.74 s (period 4 theta, closed form); h_max = 1e-9 made it 0.296 s
    from delaykit import InvalidValueError, relay_cycle

    with pytest.raises(InvalidValueError, match="h_max"):
        relay_cycle("1/s", 0.37, h_max=1e-9)
    with pytest.raises(InvalidValueError, match="no stable relay limit cycle"):
        relay_cycle("1/s", 0.37, h_max=0.5)
    assert abs(relay_cycle("1/s", 0.37, h_max=1.0).period - 4 * 0.37) < 1e-12


# -- tuning: find what was asked, or refuse saying why (truly) -----------------------------------------------------
def test_tune_refuses_an_unstable_plant_instead_of_returning_an_unstable_loop():
    # 1/(s-1) with a 0.2 s delay gave kp > 0, ki = 0, UNSTABLE; the optimisation grows gains from zero (unstable
    # for this plant), so it refuses, naming the pole at s = 1
    from delaykit import InvalidValueError, tune

    with pytest.raises(InvalidValueError, match=r"unstable \(a pole at 1\)"):
        tune("1/(s-1)", "pi", delay=0.2)


@pytest.mark.parametrize("kind", ["p", "pi"])
def test_tune_without_delay_says_the_gains_are_unbounded(kind):
    # 1/(s+1) without delay: with kp = ki the loop is kp/s, Ms = 1 for every kp (by hand), so MIGO's largest
    # gain does not exist; it said "no gains meet Ms <= 1.4", which is false
    from delaykit import InvalidValueError, tune

    with pytest.raises(InvalidValueError, match="no largest value"):
        tune("1/(s+1)", kind, delay=0.0)
    # a microsecond delay bounds them: a stable design at the limit
    t = tune("1/(s+1)", kind, delay=1e-6)
    assert t.stable and abs(t.ms - 1.4) < 1e-6


def test_tune_refuses_an_ms_limit_it_cannot_resolve():
    from delaykit import InvalidValueError, tune

    with pytest.raises(InvalidValueError, match="ms must be at most 100, got 1e\\+09"):
        tune("1/(s+1)", "pi", delay=0.2, ms=1e9)
    with pytest.raises(InvalidValueError, match="mt must be at most 100"):
        tune("1/(s+1)", "pi", delay=0.2, mt=1e3)
    assert abs(tune("1/(s+1)", "pi", delay=0.2, ms=100.0).ms - 100.0) < 1e-6   # the largest taken is met


def test_tune_cli_refusals_exit_2():
    from typer.testing import CliRunner

    from delaykit.cli.app import app

    for args in (["--plant", "1/(s-1)", "--delay", "0.2"], ["--plant", "1/(s+1)", "--delay", "0"],
                 ["--plant", "1/(s+1)", "--delay", "0.2", "--ms", "1e9"]):
        res = CliRunner().invoke(app, ["tune", "--controller", "pi", *args])
        assert res.exit_code == 2 and res.output.startswith("error:") and "Traceback" not in res.output, res.output


# -- BLT: an unstable paired element is refused, not tuned into an UNSTABLE design ----------------------------------
def test_blt_refuses_an_unstable_paired_element():
    # exp(-s)/(s-1) has its pole at s = 1 (by hand); BLT returned an UNSTABLE design for it.  The off-diagonal
    # element's own stable pole (s = -1) must not hide it, nor the other elements' poles be blamed on it
    from delaykit import InvalidValueError, blt

    G = tf([["exp(-s)/(s-1)", "0.1*exp(-s)/(s+1)"], ["0.1*exp(-s)/(s+1)", "exp(-s)/(s+1)"]])
    with pytest.raises(InvalidValueError, match=r"G\[0, 0\] is unstable \(a pole at 1\)"):
        blt(G)
    # the check looks at each element's own states only (the realisation keeps all four elements' in G[i, j])
    from delaykit.design.mimo import _element

    assert _element(G, 0, 1).characteristic().polys == ((1.0, 1.0),)
    assert _element(G, 0, 0).characteristic().polys == ((1.0, -1.0),)


def test_blt_still_tunes_an_integrating_element():
    # an integrator (pole at 0) is allowed: the closed loop is certified stable
    from delaykit import blt

    r = blt(tf([["exp(-s)/s", "0.1*exp(-s)/(s+1)"], ["0.1*exp(-s)/(s+1)", "exp(-s)/(s+1)"]]))
    assert r.stable is True


# -- time scales far apart in one system ------------------------------------------------------------------------
@pytest.mark.parametrize("a", [1e-6, 1e-10, 1e-13, 1e-15])
def test_characteristic_of_time_scales_far_apart(a):
    # poles -a and -1/a: det(sI - A) = s^2 + (a + 1/a) s + 1 (by hand); on one circle the 1 and the s^2 were lost
    # past a spread of 1e24, and the stable system was called unstable (a pole at 0)
    from delaykit import ss

    S = ss(np.diag([-a, -1 / a]), [[1.0], [1.0]], [[1.0, 1.0]], [[0.0]])
    q = S.characteristic()
    assert np.allclose(q.polys[0], [1.0, a + 1 / a, 1.0], rtol=1e-9, atol=0)
    assert S.is_stable() is True
    # with 0.5 exp(-s) fed back: + 0.5 (2 s + a + 1/a) exp(-s), again by hand
    q = feedback(0.5 * delay(1.0) * S, 1).characteristic()
    assert q.delays == (0.0, 1.0)
    assert np.allclose(q.polys[1], [1.0, 0.5 * (a + 1 / a)], rtol=1e-9, atol=0)


def test_delay_margin_sweeps_the_gain_to_1e300():
    # s + 1 + k exp(-tau s): the closed form of _first_order_boundary; a gain of 1e300 overflowed |P(jw)|^2 into a
    # numpy LinAlgError
    from delaykit import Controller, Loop
    from delaykit.spectrum.stability import delay_margin

    for j in range(1, 301, 11):
        k = 10.0 ** j
        m = delay_margin(Loop("1/(s+1)", Controller.p(k), delay=0.3).characteristic())
        assert abs(m.delay / _first_order_boundary(k) - 1) < 1e-12, (k, m)
        assert abs(m.frequency / (k * math.sqrt(1 - 1 / k / k)) - 1) < 1e-12, (k, m)
    assert math.isinf(delay_margin(Loop("1/(s+1)", Controller.p(1e-300), delay=0.3).characteristic()).delay)


@pytest.mark.parametrize("k", [1e20, 1e300])
def test_rightmost_root_of_a_huge_gain_loop(k):
    # s + 1 + k exp(-0.3 s): s = W_b(-0.3 k e^0.3)/0.3 - 1 (scipy's Lambert W, branches 0 and -1 the rightmost
    # pair); the search from the loop's own scale gave "not certified" with an abscissa of 5e20
    from scipy.special import lambertw

    from delaykit import Controller, Loop
    from delaykit.spectrum.stability import rightmost

    rm = rightmost(Loop("1/(s+1)", Controller.p(k), delay=0.3))
    ref = max((complex(lambertw(-0.3 * k * math.exp(0.3), b)) / 0.3 - 1 for b in (0, -1)), key=lambda z: z.real)
    assert rm.certified and not rm.stable
    assert abs(rm.root - complex(ref.real, abs(ref.imag))) <= 1e-9 * abs(ref)


def test_loop_simulation_refuses_a_horizon_below_its_time_resolution():
    # the loop simulator's tolerance is 1e-12 max(1, t_end) s: t_end = 1e-16 ran no piece, its metrics were of
    # nothing and reading its output raised an IndexError; now one line, and 1e-10 s still runs
    from delaykit import Controller, InvalidValueError, Loop, simulate

    L = Loop("1/(s+1)", Controller.p(1.0), delay=0.3)
    with pytest.raises(InvalidValueError, match="t_end .* at least 1e-10 s"):
        simulate(L, t_end=1e-16)
    r = simulate(L, t_end=1e-10)
    assert r.output(np.array([0.0, 1e-10])).tolist() == [0.0, 0.0]   # the delay (0.3 s) has not passed yet


def test_cli_simulate_tiny_horizons(tmp_path):
    # a system's step over 1e-16 s: 1 - exp(-t) (closed form), no nulls, exit 0; a loop's: refused, exit 2
    import json

    from typer.testing import CliRunner

    from delaykit.cli.app import app

    res = CliRunner().invoke(app, ["simulate", "--kp", "1", "--delay", "0.3", "--t-end", "1e-16"])
    assert res.exit_code == 2 and res.output.startswith("error:") and "1e-10" in res.output
    path = tmp_path / "F.toml"
    path.write_text('inputs = ["r"]\noutputs = ["y"]\n[[blocks]]\ntf = "1/(s+1)"\ninputs = "r"\noutputs = "y"\n')
    res = CliRunner().invoke(app, ["simulate", "--system", str(path), "--t-end", "1e-16", "--json"])
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    y = np.array(got["outputs"], dtype=float).ravel()
    t = np.array(got["time"])
    assert got["status"] == "exact" and np.all(np.isfinite(y))
    assert np.allclose(y, -np.expm1(-t), rtol=1e-12, atol=0)


def test_fast_modes_with_a_long_delay_below_unit_gain_are_stable():
    # |0.0271 / ((5.19e-7 j w + 1)(4.71e-7 j w + 1))| < 1 at every w: stable for every delay (small-gain theorem);
    # the roots' scales (2e6 rad/s modes, a 53.6 s delay) are too far apart to count, so the exact delay margin
    # (infinite here) decides
    G = 0.0271 * tf("1/((5.19e-07*s+1)*(4.71e-07*s+1))") * delay(53.6)
    assert feedback(G, 1).is_stable() is True
