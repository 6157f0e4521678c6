"""Exact time responses of DelayLTI systems (delaykit.simulate.systems and its kernel _ltikernel).

Every reference value is independent of the kernel: closed forms, python-control (delay-free systems), delaykit's
Loop kernel (an independent implementation of the method of steps for one loop shape), and SciPy's DOP853 on the
intervals between the delays' breakpoints, written here.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from delaykit import (AltitudeLoop, DelayLTI, InvalidTypeError, InvalidValueError, delay, feedback, from_loop,
                      saturation, simulate, ss, tf)
from delaykit.simulate import systems as S
from delaykit.simulate.systems import (SystemTimeResponse, forced_response, impulse_response, initial_response,
                                       step_response)

control = pytest.importorskip("control")

# Wood & Berry (1973) column, minutes; Luyben's (1986) BLT tuning of the two PI loops (as docs/guide/systems.md)
WB = [["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
      ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]]
WB_K = [[12.8, -18.9], [6.6, -19.4]]
WB_T = [[16.7, 21.0], [10.9, 14.4]]
WB_THETA = [[1.0, 3.0], [7.0, 3.0]]
KC, TI = (0.375, -0.075), (8.29, 23.6)


def wood_berry_pi(kc=KC, ti=TI):
    G = tf(WB, inputs=["R", "S"], outputs=["xD", "xB"])
    K = tf([[f"{kc[0]}*(1 + 1/({ti[0]}*s))", 0], [0, f"{kc[1]}*(1 + 1/({ti[1]}*s))"]], inputs=["e1", "e2"],
           outputs=["R", "S"])
    return feedback(G * K, 1)


# -- closed forms ------------------------------------------------------------------------------------------------

def test_first_order_lag_with_input_delay_is_exact():
    # closed form: K (1 - exp(-(t - L) / T)) for t >= L, 0 before
    K, T, L = 2.5, 1.7, 0.8
    t = np.linspace(0.0, 12.0, 241)
    r = tf(f"{K}*exp(-{L}*s)/({T}*s+1)").step(t)
    exact = np.where(t >= L, K * (1 - np.exp(-(t - L) / T)), 0.0)
    assert r.status == "exact"
    np.testing.assert_allclose(r.outputs[0, 0], exact, rtol=0, atol=1e-13)


def test_pure_delay_and_integrator():
    # closed forms: a delayed unit step; 1/s with a delay is the ramp (t - tau)+
    t = np.array([0.0, 0.49, 0.5, 0.51, 3.0])
    np.testing.assert_array_equal(delay(0.5).step(t).outputs[0, 0], [0, 0, 1, 1, 1])
    r = tf("exp(-0.5*s)/s").step(np.linspace(0, 4, 9))
    np.testing.assert_allclose(r.outputs[0, 0], np.maximum(np.linspace(0, 4, 9) - 0.5, 0), atol=1e-14)


def test_closed_loop_first_interval_and_second_by_hand():
    # y' = -y + 1 - y(t - 1): on [1, 2] y = 1 - exp(-(t - 1)); on [2, 3] y' = -y + exp(-(t - 2)), so
    # y = exp(-(t - 2)) (y(2) + t - 2)  (solved by hand)
    t = np.array([1.5, 2.0, 2.5, 3.0])
    y = feedback(tf("exp(-s)/(s+1)"), 1).step(t).outputs[0, 0]
    y2 = 1 - math.exp(-1)
    exact = [1 - math.exp(-0.5), y2, math.exp(-0.5) * (y2 + 0.5), math.exp(-1) * (y2 + 1)]
    np.testing.assert_allclose(y, exact, atol=1e-14)


def test_impulse_regular_part_and_dirac_terms():
    # closed form: exp(-(t - 1)) after 1 s for exp(-s)/(s+1); a delay's impulse is a Dirac at the delay
    t = np.array([0.5, 1.0, 2.0, 3.5])
    r = tf("exp(-s)/(s+1)").impulse(t)
    np.testing.assert_allclose(r.outputs[0, 0], [0.0, 1.0, math.exp(-1), math.exp(-2.5)], atol=1e-13)
    assert r.impulses == ()
    r = tf("2*exp(-s) + 1/(s+1)").impulse(t)
    assert [(round(tk, 12), i, j, round(w, 12)) for tk, i, j, w in r.impulses] == [(1.0, 0, 0, 2.0)]
    np.testing.assert_allclose(r.outputs[0, 0], np.exp(-t), atol=1e-13)
    # direct feedthrough: a Dirac at 0 of weight D, as python-control's D (which it drops with a warning)
    r = ss([[-2.0]], [[1.0]], [[3.0]], [[0.5]]).impulse([0.0, 1.0])
    assert r.impulses == ((0.0, 0, 0, 0.5),)
    np.testing.assert_allclose(r.outputs[0, 0], [3.0, 3.0 * math.exp(-2.0)], atol=1e-13)


def test_a_response_at_zero_only_is_the_right_limit():
    # y(0+) = D for a step into ss(A, B, C, D) (python-control's step_response gives D at 0 too)
    r = ss([[-1.0]], [[1.0]], [[1.0]], [[0.5]]).step([0.0])
    assert r.status == "exact" and r.outputs.tolist() == [[[0.5]]]


def test_initial_and_forced_closed_forms():
    # x' = -x, x(0) = 2: 2 exp(-t); the delay line is empty before 0
    r = initial_response(ss([[-1.0]], [[0.0]], [[1.0]], [[0.0]]), [0.0, 1.0, 2.0], X0=2.0)
    np.testing.assert_allclose(r.outputs[0], 2 * np.exp(-np.array([0.0, 1.0, 2.0])), atol=1e-14)
    # the integral of a ramp-then-hold input one second late (closed form)
    r = tf("exp(-s)/s").lsim([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(r.outputs[0], [0.0, 0.0, 0.5, 1.5], atol=1e-14)


def test_initial_response_through_a_delayed_loop_by_hand():
    # y' = -y - y(t - 1) with the delay line empty before 0, y(0) = 1 (feedback(exp(-s)/(s+1), 1), r = 0):
    # y = exp(-t) on [0, 1]; y' = -y - exp(-(t - 1)) on [1, 2], so y = exp(-(t - 1)) (exp(-1) - (t - 1))
    r = feedback(tf("exp(-s)/(s+1)"), 1).initial([0.5, 1.0, 1.5, 2.0], X0=1.0)
    exact = [math.exp(-0.5), math.exp(-1), math.exp(-0.5) * (math.exp(-1) - 0.5), math.exp(-1) * (math.exp(-1) - 1)]
    np.testing.assert_allclose(r.outputs[0], exact, atol=1e-14)


def test_forced_response_of_a_saturated_loop_is_its_step_when_held():
    # the same run twice: U = 1 held, given as samples (forced), and the unit step
    sys = feedback(tf("1/s") * delay(0.368) * saturation(-1, 1) * 1.31, 1)
    t = np.linspace(0.0, 10.0, 51)
    np.testing.assert_allclose(sys.lsim(t, np.ones(t.size)).outputs[0], sys.step(t).outputs[0, 0], atol=1e-14)


# -- python-control, every delay 0 ---------------------------------------------------------------------------------

def _random_ss(seed, n=4, nu=2, ny=3, with_d=True):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A -= (np.max(np.linalg.eigvals(A).real) + 0.5) * np.eye(n)  # stable
    B, C = rng.normal(size=(n, nu)), rng.normal(size=(ny, n))
    D = rng.normal(size=(ny, nu)) if with_d else np.zeros((ny, nu))
    return A, B, C, D


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_mimo_without_delays_equals_python_control(seed):
    # reference: python-control's step/forced/initial/impulse responses (matrix exponentials)
    A, B, C, D = _random_ss(seed)
    sys = ss(A, B, C, D)
    ref = control.ss(A, B, C, D)
    t = np.linspace(0.0, 6.0, 121)
    np.testing.assert_allclose(sys.step(t).outputs, control.step_response(ref, t).outputs, rtol=0, atol=1e-10)
    rng = np.random.default_rng(seed + 10)
    U = rng.normal(size=(2, t.size))
    x0 = rng.normal(size=4)
    got = forced_response(sys, t, U, X0=x0).outputs
    np.testing.assert_allclose(got, control.forced_response(ref, t, U, X0=x0).outputs, rtol=0, atol=1e-10)
    got = initial_response(sys, t, X0=x0).outputs
    np.testing.assert_allclose(got, control.initial_response(ref, t, X0=x0).outputs, rtol=0, atol=1e-10)
    ref0 = control.ss(A, B, C, np.zeros_like(D))
    r = impulse_response(ss(A, B, C, D), t)
    np.testing.assert_allclose(r.outputs, control.impulse_response(ref0, t).outputs, rtol=0, atol=1e-10)
    assert sorted((i, j, w) for _, i, j, w in r.impulses) == sorted(
        (i, j, D[i, j]) for i in range(3) for j in range(2))


def test_delay_free_channels_are_eliminated_as_python_control_feedback():
    # a loop closed through a channel without delay (feedback of a MIMO plant): python-control's feedback
    A, B, C, D = _random_ss(5, n=3, nu=2, ny=2, with_d=False)
    sys = feedback(ss(A, B, C, D), np.eye(2) * 0.7)
    ref = control.feedback(control.ss(A, B, C, D), np.eye(2) * 0.7)
    t = np.linspace(0, 5, 51)
    np.testing.assert_allclose(sys.step(t).outputs, control.step_response(ref, t).outputs, atol=1e-10)


# -- the Loop kernel: the paper's P loop --------------------------------------------------------------------------

@pytest.mark.parametrize("vmax", [None, 1.0])
def test_paper_loop_equals_loop_kernel(vmax):
    # reference: delaykit's Loop kernel (simulate), an independent method of steps for this loop shape
    loop = AltitudeLoop(kp=1.31, delay=0.368, vmax=vmax)
    ref = simulate(loop, t_end=15.0)
    t = np.linspace(0.0, 15.0, 301)
    sat = saturation(-1.0, 1.0) if vmax else tf("1")
    built = feedback(tf("1/s") * delay(0.368) * sat * 1.31, 1)   # the loop by algebra
    for sys in (from_loop(loop)[0, 0], built):
        r = sys.step(t)
        assert r.status == "exact"
        np.testing.assert_allclose(r.outputs[0, 0], ref.output(t), rtol=0, atol=1e-9)
    np.testing.assert_allclose(from_loop(loop).step(t).outputs[1, 0], ref.command(t), rtol=0, atol=1e-9)


def test_delayed_saturation_channel_equals_loop_kernel():
    # a saturation channel with a delay (sat(z(t - tau))) is the same loop as the saturation before the delay
    loop = AltitudeLoop(kp=1.31, delay=0.368, vmax=1.0)
    ref = simulate(loop, t_end=10.0)
    sys = DelayLTI(A=[[0.0]], B1=[[0.0]], B2=[[1.0]], C1=[[1.0]], D11=[[0.0]], D12=[[0.0]], C2=[[-1.31]],
                   D21=[[1.31]], D22=[[0.0]], delays=[0.368], limits=[(-1.0, 1.0)])
    t = np.linspace(0.0, 10.0, 201)
    np.testing.assert_allclose(sys.step(t).outputs[0, 0], ref.output(t), rtol=0, atol=1e-9)


# -- Wood-Berry under decentralised PI: SciPy DOP853 by the method of steps -----------------------------------------

def _wood_berry_oracle(t_eval, column, kc=KC, ti=TI):
    """The closed loop's step response for reference ``column`` by SciPy's DOP853 on [k, k + 1] minutes (every
    delay is a whole number of minutes, so every breakpoint is an integer), the delayed commands read from the
    dense outputs of the intervals before.  States: the four first-order entries x_ij, the two integrals of the
    errors."""
    from scipy.integrate import solve_ivp

    r = np.zeros(2)
    r[column] = 1.0
    sols = []

    def command(t, x):
        y = np.array([x[0] + x[1], x[2] + x[3]])
        e = r - y
        return np.array([kc[i] * (e[i] + x[4 + i] / ti[i]) for i in range(2)])

    def delayed(j, t, theta):
        k = len(sols) - int(theta)  # the interval [k, k + 1] is read on the current one, ends included
        return 0.0 if k < 0 else command(t - theta, sols[k].sol(t - theta))[j]

    def rhs(t, x):
        dx = np.empty(6)
        for i in range(2):
            for j in range(2):
                dx[2 * i + j] = (-x[2 * i + j] + WB_K[i][j] * delayed(j, t, WB_THETA[i][j])) / WB_T[i][j]
        y = np.array([x[0] + x[1], x[2] + x[3]])
        dx[4:] = r - y
        return dx

    x = np.zeros(6)
    for k in range(int(math.ceil(t_eval[-1]))):
        sol = solve_ivp(rhs, (k, k + 1), x, method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True)
        sols.append(sol)
        x = sol.y[:, -1]
    out = np.empty((2, t_eval.size))
    for n, t in enumerate(t_eval):
        k = min(int(math.floor(t)), len(sols) - 1)
        xs = sols[k].sol(t)
        out[:, n] = [xs[0] + xs[1], xs[2] + xs[3]]
    return out


@pytest.mark.slow
def test_wood_berry_pi_against_dop853_method_of_steps():
    T = wood_berry_pi()
    t = np.linspace(0.0, 100.0, 201)
    r = T.step(t)
    assert r.status == "exact"
    for column in range(2):
        np.testing.assert_allclose(r.outputs[:, column], _wood_berry_oracle(t, column), rtol=0, atol=1e-8)


def test_wood_berry_pi_first_30_minutes_against_dop853():
    T = wood_berry_pi()
    t = np.linspace(0.0, 30.0, 61)
    r = T.step(t)
    np.testing.assert_allclose(r.outputs[:, 0], _wood_berry_oracle(t, 0), rtol=0, atol=1e-8)


# -- neutral systems --------------------------------------------------------------------------------------------

def _neutral_oracle(t_eval, d):
    """y = x + d e(t - 0.5), x' = -x + e, e = 1 - y (feedback(1/(s+1) + d exp(-0.5 s), 1), unit step): so
    e(t) = 1 - x(t) - d e(t - 0.5), expanded down to t < 0 (e = 0 there); DOP853 on [k/2, (k+1)/2]."""
    from scipy.integrate import solve_ivp

    sols = []

    def e_past(t, k):  # e at t on the interval [k/2, (k+1)/2] (ends included), from the stored solutions
        return 0.0 if k < 0 else 1.0 - sols[k].sol(t)[0] - d * e_past(t - 0.5, k - 1)

    x = np.zeros(1)
    for k in range(int(math.ceil(2 * t_eval[-1]))):
        sol = solve_ivp(lambda t, x, k=k: -x + (1.0 - x - d * e_past(t - 0.5, k - 1)), (k / 2, (k + 1) / 2), x,
                        method="DOP853", rtol=1e-13, atol=1e-15, dense_output=True)
        sols.append(sol)
        x = sol.y[:, -1]
    ks = [min(int(math.floor(2 * t)), len(sols) - 1) for t in t_eval]   # right limits at the breakpoints
    return np.array([sols[k].sol(t)[0] + d * e_past(t - 0.5, k - 1) for t, k in zip(t_eval, ks)])


def test_neutral_strongly_stable_against_dop853():
    sys = feedback(tf("1/(s+1)") + tf("0.4*exp(-0.5*s)"), 1)
    assert not sys.is_retarded
    t = np.linspace(0.0, 8.0, 81)
    r = sys.step(t)
    assert r.status == "exact"
    np.testing.assert_allclose(r.outputs[0, 0], _neutral_oracle(t, 0.4), rtol=0, atol=1e-9)


def test_neutral_tiny_delay_tends_to_the_delay_free_loop():
    # reference: the same loop with the delay 0 (python-control-exact delay-free run); the difference is O(tau)
    # (the step's jump fades through 0.4^k images, each tau later), and the tiny delay costs few pieces
    t = np.linspace(0.0, 8.0, 17)
    r0 = feedback(tf("1/(s+1)") + tf("0.4"), 1).step(t).outputs
    for tau in (1e-3, 1e-6):
        r = feedback(tf("1/(s+1)") + tf(f"0.4*exp(-{tau}*s)"), 1).step(t)
        assert r.status == "exact" and r.pieces < 100
        assert np.abs(r.outputs - r0)[..., 1:].max() < 0.2 * tau


def test_neutral_not_strongly_stable_is_refused():
    sys = feedback(tf("1/(s+1)") + tf("1.5*exp(-0.5*s)"), 1)    # e = 1 - x - 1.5 e(t - 0.5): jumps grow
    with pytest.raises(InvalidValueError, match="not strongly stable"):
        sys.step([1.0])


def test_neutral_two_channels_scaled_bound():
    # D22 = [[0, 2], [0.3, 0]]: rho(|D22|) = sqrt(0.6) < 1, strongly stable though ||D22|| = 2 > 1
    S._check_neutral(np.array([[0.0, 2.0], [0.3, 0.0]]), [0, 1], np.array([1.0, 1.5]))
    # [[1, 1], [1, -1]] / 1.5: rho(|D|) = 1.33 but every phase gives rho 0.943 (a scaling shows it)
    S._check_neutral(np.array([[1.0, 1.0], [1.0, -1.0]]) / 1.5, [0, 1], np.array([1.0, 1.5]))
    with pytest.raises(InvalidValueError, match="reaches"):
        S._check_neutral(np.array([[0.6, 0.6], [0.6, 0.6]]), [0, 1], np.array([1.0, 1.5]))


# -- refusals -------------------------------------------------------------------------------------------------------

def test_ill_posed_algebraic_loop_refused():
    sys = DelayLTI(A=[[-1.0]], B1=[[1.0]], B2=[[0.0]], C1=[[1.0]], C2=[[0.0]], D11=[[0.0]], D12=[[1.0]],
                   D21=[[1.0]], D22=[[1.0]], delays=[0.0])   # w = u + w
    with pytest.raises(InvalidValueError, match="not well posed"):
        sys.step([1.0])


def test_saturations_feeding_each_other_refused():
    sys = DelayLTI(A=[[-1.0]], B1=[[1.0]], B2=[[1.0, 0.0]], C1=[[1.0]], C2=[[1.0], [0.0]], D11=[[0.0]],
                   D12=[[0.0, 0.0]], D21=[[0.0], [1.0]], D22=[[0.0, 0.5], [0.5, 0.0]], delays=[0.0, 0.0],
                   limits=[(-1, 1), (-1, 1)])
    with pytest.raises(InvalidValueError, match="algebraic loop through saturations"):
        sys.step([1.0])


def test_impulse_through_saturation_refused_and_bad_input():
    with pytest.raises(InvalidValueError, match="saturation"):
        from_loop(AltitudeLoop(kp=1.31, delay=0.368)).impulse([1.0])
    g = tf("exp(-s)/(s+1)")
    with pytest.raises(InvalidValueError, match="strictly increasing"):
        g.step([1.0, 0.5])
    with pytest.raises(InvalidValueError, match="shape"):
        g.lsim([0.0, 1.0], [[1.0, 2.0], [3.0, 4.0]])
    with pytest.raises(InvalidTypeError):
        step_response("G", [1.0])
    with pytest.raises(InvalidValueError, match="X0"):
        g.initial([1.0], X0=[1.0, 2.0])


# -- the result -------------------------------------------------------------------------------------------------------

def test_result_repr_json_and_unpacking():
    r = wood_berry_pi().step(np.linspace(0, 20, 5))
    assert isinstance(r, SystemTimeResponse)
    assert r.outputs.shape == (2, 2, 5) and r.output_labels == ("xD", "xB") and r.input_labels == ("e1", "e2")
    assert "\n" not in repr(r) and repr(r).startswith("SystemTimeResponse(step: 2 outputs x 2 inputs at 5 times")
    t, y = r
    assert t is r.time and y is r.outputs
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    assert d["status"] == "exact" and np.allclose(d["outputs"], r.outputs)


def test_truncation_is_reported(monkeypatch):
    monkeypatch.setattr(S, "MAX_PIECES", 16)
    r = tf("exp(-0.1*s)/(s+1)").step(np.linspace(0, 50, 11))   # 10 pieces of 0.1 s after the start at least
    assert r.status == "truncated" and 0 < r.t_reached < 50
    assert np.isnan(r.outputs[0, 0, -1]) and np.isfinite(r.outputs[0, 0, 0])
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    assert d["outputs"][0][0][-1] is None and "truncated" in repr(r)


@pytest.mark.parametrize("tau", [1e-3, 1e-6, 1e-12])
def test_tiny_delays_take_few_pieces(tau):
    # a delay far below the loop's time scale is read from the piece being built (fixed-point passes) once its
    # breakpoints have faded: the piece count stays that of a run without the delay, and the answer exact
    # (references: the closed form of the lag; the Loop kernel for the paper's loop)
    t = np.linspace(0.0, 10.0, 101)
    r = tf(f"exp(-{tau}*s)/(s+1)").step(t)
    np.testing.assert_allclose(r.outputs[0, 0], np.where(t >= tau, 1 - np.exp(-(t - tau)), 0.0), atol=1e-14)
    assert r.pieces < 40
    loop = AltitudeLoop(kp=1.31, delay=tau)
    ref = simulate(loop, t_end=10.0)
    r = from_loop(loop).step(t)
    np.testing.assert_allclose(r.outputs[0, 0], ref.output(t), atol=1e-12)
    np.testing.assert_allclose(r.outputs[1, 0], ref.command(t), atol=1e-12)
    assert r.pieces < 100


def test_default_horizon():
    # 7 time constants of the slowest mode with the delays at 0, plus 3 longest delays
    assert S.default_horizon(tf("exp(-2*s)/(s+1)")) == pytest.approx(13.0)
    r = tf("exp(-2*s)/(s+1)").step()
    assert r.time.size == 1001 and r.time[-1] == pytest.approx(13.0)


# -- one source, three modes ------------------------------------------------------------------------------------

@pytest.mark.parametrize("mode", ["cython", pytest.param("numba", marks=pytest.mark.slow)])
def test_kernel_modes_agree_with_plain_python(monkeypatch, mode):
    # reference: the same kernel source run by the interpreter
    from delaykit import _native

    if mode == "cython" and not _native.built("delaykit.simulate", "_ltikernel"):
        pytest.skip("the extension was not built")
    systems = [wood_berry_pi(), from_loop(AltitudeLoop(kp=1.31, delay=0.368)),
               feedback(tf("1/(s+1)") + tf("0.4*exp(-0.5*s)"), 1)]
    t = np.linspace(0.0, 30.0, 61)
    results = {}
    for m in ("python", mode):
        monkeypatch.setattr(S, "_K", _native.load("delaykit.simulate", "_ltikernel", m))
        results[m] = [s.step(t).outputs for s in systems] + [systems[0].impulse(t).outputs]
    for a, b in zip(results["python"], results[mode]):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)


# -- many systems -----------------------------------------------------------------------------------------------

def test_step_response_many_equals_one_by_one():
    # reference: step_response of each system (the parallel run must change nothing)
    from delaykit.simulate.systems import step_response_many

    rng = np.random.default_rng(3)
    loops = [wood_berry_pi(kc=(0.375 * rng.uniform(0.7, 1.3), -0.075 * rng.uniform(0.7, 1.3))) for _ in range(6)]
    t = np.linspace(0.0, 60.0, 121)
    r = step_response_many(loops, t)
    assert r.outputs.shape == (6, 2, 2, 121) and r.status == ("exact",) * 6 and len(r) == 6
    for k, sysk in enumerate(loops):
        one = sysk.step(t)
        np.testing.assert_array_equal(r.outputs[k], one.outputs)
        assert r.pieces[k] == one.pieces and r[k].status == "exact"
    assert "\n" not in repr(r)
    json.dumps(r.to_dict(), allow_nan=False)
    neutral = [feedback(tf("1/(s+1)") + tf(f"{d}*exp(-0.5*s)"), 1) for d in (0.2, 0.4)]
    r = step_response_many(neutral, t[:41])
    for k, sysk in enumerate(neutral):
        np.testing.assert_array_equal(r.outputs[k], sysk.step(t[:41]).outputs)
    with pytest.raises(InvalidValueError, match="not strongly stable"):
        step_response_many(neutral + [feedback(tf("1/(s+1)") + tf("1.5*exp(-0.5*s)"), 1)], [1.0])
    sat = [feedback(tf("1/s") * delay(0.368) * saturation(-1, 1) * kp, 1) for kp in (0.8, 1.31)]
    r = step_response_many(sat, t[:41])
    for k, sysk in enumerate(sat):
        np.testing.assert_array_equal(r.outputs[k], sysk.step(t[:41]).outputs)


def test_step_response_many_refuses_mixed_shapes():
    from delaykit.simulate.systems import step_response_many

    with pytest.raises(InvalidValueError, match="shape"):
        step_response_many([tf("exp(-s)/(s+1)"), tf("exp(-s)/(s+1)^2")], [1.0])
    with pytest.raises(InvalidValueError, match="empty"):
        step_response_many([], [1.0])
