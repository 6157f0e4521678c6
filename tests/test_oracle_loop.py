"""Tests of the independent loop oracle (tests/oracle_loop.py) against references that do not use it:
closed forms, an exact matrix-exponential method of steps, python-control, the published numbers of the
paper's loop, and the older integrator-plant oracle (tests/oracle.py)."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
from scipy.linalg import expm

from oracle import Oracle
from oracle_loop import LoopOracle, LoopSpec

INTEGRATOR = dict(A=[[0.0]], B=[1.0], C=[1.0], D=0.0)


def fopdt(K, tau):
    return dict(A=[[-1.0 / tau]], B=[K / tau], C=[1.0], D=0.0)


def second_order(K=1.5, wn=1.3, z=0.4):
    return dict(A=[[0.0, 1.0], [-wn**2, -2 * z * wn]], B=[0.0, K * wn**2], C=[1.0, 0.0], D=0.0)


# --------------------------------------------------------------------------------------------------
# exact reference: the method of steps for a LINEAR loop (no saturation, continuous control, To = 0,
# Ti = L) done with one matrix exponential.  With q_j(s) = the loop state at t = j L + s, s in [0, L],
# q_j' depends on q_j and on w_j = u_{j-1}, which is an affine form in q_0..q_{j-1}: the stacked system
# is block lower triangular and linear, with q_j(0) = q_{j-1}(L).
# --------------------------------------------------------------------------------------------------
def exact_linear_loop(A, B, C, D, L, ctrl_ss, S, N, t):
    A = np.atleast_2d(np.asarray(A, float))
    B = np.asarray(B, float).ravel()
    C = np.asarray(C, float).ravel()
    Ac, Bc, Cc, Dc = ctrl_ss
    Ac = np.atleast_2d(np.asarray(Ac, float)) if np.size(Ac) else np.zeros((0, 0))
    Bc, Cc = np.asarray(Bc, float).ravel(), np.asarray(Cc, float).ravel()
    n, nc = A.shape[0], Ac.shape[0]
    q = n + nc
    dim = N * q + 1  # last entry: the constant 1
    M = np.zeros((dim, dim))
    one = np.zeros(dim)
    one[-1] = 1.0
    w = np.zeros(dim)  # w_0 = u(t - L) = 0 on the first interval
    ws, ys = [], []
    for j in range(N):
        xj = np.zeros((n, dim))
        xj[:, j * q: j * q + n] = np.eye(n)
        cj = np.zeros((nc, dim))
        cj[:, j * q + n: (j + 1) * q] = np.eye(nc)
        ym = C @ xj + D * w
        e = S * one - ym
        u = Cc @ cj + Dc * e
        M[j * q: j * q + n] = A @ xj + np.outer(B, w)
        if nc:
            M[j * q + n: (j + 1) * q] = Ac @ cj + np.outer(Bc, e)
        ws.append(w)
        ys.append(ym)
        w = u
    E = expm(M * L)
    Q0 = np.zeros(dim)
    Q0[-1] = 1.0
    for j in range(1, N):
        Q0[j * q: (j + 1) * q] = (E @ Q0)[(j - 1) * q: j * q]
    # y at t = j L + s for every interval j at once from Q(s)
    out = np.empty(len(t))
    j = np.minimum((np.asarray(t) // L).astype(int), N - 1)
    s_all = np.asarray(t) - j * L
    for s in np.unique(s_all):
        Qs = expm(M * s) @ Q0
        m = s_all == s
        out[m] = np.array([ys[jj] @ Qs for jj in j[m]])
    return out


def test_fopdt_first_interval_closed_form():
    K, tau, kp, S, L = 2.0, 0.7, 0.8, 1.3, 0.5
    o = LoopOracle(LoopSpec(**fopdt(K, tau), Ti=L, controller="p", kp=kp, reference=("step", S), t_end=3.0))
    t = np.linspace(0.0, L, 41)
    assert np.max(np.abs(o.y(t))) < 1e-13
    t = np.linspace(L, 2 * L, 101)[:-1]
    ref = K * kp * S * (1 - np.exp(-(t - L) / tau))
    assert np.max(np.abs(o.y(t) - ref)) < 1e-10
    np.testing.assert_allclose(o.u(np.linspace(0, L, 11)[:-1]), kp * S, rtol=0, atol=1e-14)


def test_split_delay_first_interval_closed_form():
    # Ti = 0.3, To = 0.2: u = Kp S until the measurement moves (t = Ti + To); y starts at Ti
    K, tau, kp, S, Ti, To = 1.7, 0.4, 0.6, -0.9, 0.3, 0.2
    o = LoopOracle(LoopSpec(**fopdt(K, tau), Ti=Ti, To=To, controller="p", kp=kp, reference=("step", S),
                            t_end=2.0))
    t = np.linspace(Ti, Ti + Ti + To, 101)[:-1]
    assert np.max(np.abs(o.y(t) - K * kp * S * (1 - np.exp(-(t - Ti) / tau)))) < 1e-10


@pytest.mark.parametrize("case", ["p_fopdt", "p_second_order", "pi_second_order", "pi_neutral_D"])
def test_linear_loop_against_exact_method_of_steps(case):
    S, L, N = 1.2, 0.45, 12
    if case == "p_fopdt":
        plant, kp, ki = fopdt(2.0, 0.7), 0.6, 0.0
    elif case == "p_second_order":
        plant, kp, ki = second_order(), 0.5, 0.0
    elif case == "pi_second_order":
        plant, kp, ki = second_order(), 0.3, 0.25
    else:  # D != 0: u(t) depends on u(t - L) directly (neutral), w jumps at every multiple of L
        plant, kp, ki = dict(A=[[-1.0]], B=[1.0], C=[0.5], D=0.6), 0.9, 0.4
    if ki:
        spec = LoopSpec(**plant, Ti=L, controller="pi", kp=kp, ki=ki, reference=("step", S), t_end=N * L)
        css = ([[0.0]], [1.0], [ki], kp)
    else:
        spec = LoopSpec(**plant, Ti=L, controller="p", kp=kp, reference=("step", S), t_end=N * L)
        css = (np.zeros((0, 0)), [], [], kp)
    o = LoopOracle(spec)
    s = np.linspace(0.0, L, 29)[1:-1]  # y jumps at multiples of L when D != 0
    t = (np.arange(N)[:, None] * L + s[None, :]).ravel()
    ref = exact_linear_loop(plant["A"], plant["B"], plant["C"], plant["D"], L, css, S, N, t)
    assert np.max(np.abs(o.y(t) - ref)) < 1e-10
    # the same loop with the controller given as a state-space "tf"
    o2 = LoopOracle(LoopSpec(**plant, Ti=L, controller="tf", ctrl_ss=css, reference=("step", S), t_end=N * L))
    assert np.max(np.abs(o2.y(t) - ref)) < 1e-10


# --------------------------------------------------------------------------------------------------
# delay-free loops against python-control (the oracle supports Ti = To = 0 when D = 0)
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("ctrl", ["pi", "pid", "pd"])
def test_delay_free_against_python_control(ctrl):
    plant = second_order(K=1.2, wn=2.0, z=0.3)
    G = control.ss(np.array(plant["A"]), np.array(plant["B"]).reshape(2, 1), np.array(plant["C"]).reshape(1, 2),
                   0.0)
    kp, ki, kd, tf, S = 0.8, (0.6 if ctrl != "pd" else 0.0), 0.3, 0.05, 1.5
    C1 = control.tf([kp, ki], [1, 0]) if ki else control.tf([kp], [1])  # on the error
    C2 = control.tf([kd, 0], [tf, 1]) if ctrl != "pi" else control.tf([0], [1])  # on the measurement
    # u = C1 (r - y) - C2 y  =>  y = feedback(G, C1 + C2) C1 r
    cl = control.feedback(G, C1 + C2) * C1
    T = 8.0
    t = np.linspace(0.0, T, 4001)
    yref = S * control.step_response(cl, T=t).outputs
    o = LoopOracle(LoopSpec(**plant, controller=ctrl, kp=kp, ki=ki, kd=kd if ctrl != "pi" else 0.0, tf=tf,
                            reference=("step", S), t_end=T))
    assert np.max(np.abs(o.y(t) - yref)) < 1e-8


# --------------------------------------------------------------------------------------------------
# the paper's loop and the older integrator-plant oracle
# --------------------------------------------------------------------------------------------------
def test_paper_loop_published_metrics():
    o = LoopOracle(LoopSpec(**INTEGRATOR, Ti=0.368, controller="p", kp=1.31, umin=-1.0, umax=1.0,
                            reference=("step", 1.0), t_end=10.0))
    m = o.metrics()
    assert abs(m["overshoot"] - 2.2630) < 1e-4
    assert abs(m["peak_time"] - 2.0761) < 1e-4
    assert abs(m["rise_time"] - 0.9050) < 1e-4
    assert abs(m["settling_time"] - 2.2631) < 1e-4


KEYS = ("overshoot", "peak_time", "rise_time", "settling_time", "t10", "t90", "final")


def compare_metrics(m, ref, tol=1e-6):
    for k in KEYS:
        if math.isnan(ref[k]):
            assert math.isnan(m[k]), k
        elif k == "peak_time" and ref["overshoot"] < 1e-3:
            # a peak less than 1e-5 above 1 is nearly flat: the time of a maximum is only determined to
            # about sqrt(rounding / |w''|), and the older oracle's bounded minimisation on w itself
            # stops earlier than this oracle's root of w'; require consistency only
            assert abs(m[k] - ref[k]) < 1e-4, k
        else:
            assert abs(m[k] - ref[k]) < tol, (k, m[k], ref[k])


@pytest.mark.parametrize("case", ["pv_true", "pv_true_low_kv", "pv_filtered", "sampled_p", "sampled_pv_offset",
                                  "sampled_pv_commensurate"])
def test_against_integrator_oracle(case):
    T = 10.0
    if case == "pv_true":
        kw, spec = dict(kp=2.0, td=0.37, kv=0.3), dict(controller="pv", kp=2.0, kv=0.3, Ti=0.37)
    elif case == "pv_true_low_kv":
        kw, spec = dict(kp=2.0, td=0.37, kv=0.1), dict(controller="pv", kp=2.0, kv=0.1, Ti=0.37)
    elif case == "pv_filtered":
        kw = dict(kp=2.0, td=0.37, kv=0.3, filtered=True)
        spec = dict(controller="pv", kp=2.0, kv=0.3, Ti=0.37, velocity="filtered")
    elif case == "sampled_p":
        kw, spec = dict(kp=1.31, td=0.368, period=0.065), dict(controller="p", kp=1.31, Ti=0.368, period=0.065)
    elif case == "sampled_pv_offset":
        kw = dict(kp=2.0, td=0.37, kv=0.1, period=0.065, offset=0.03)
        spec = dict(controller="pv", kp=2.0, kv=0.1, Ti=0.37, period=0.065, offset=0.03)
    else:  # the delay is 6 periods: the velocity sample at t_k needs the LEFT limit of u at t_k - Td
        kw = dict(kp=2.0, td=0.39, kv=0.1, period=0.065)
        spec = dict(controller="pv", kp=2.0, kv=0.1, Ti=0.39, period=0.065)
    ref = Oracle(vmax=1.0, t_end=T, **kw).metrics()
    o = LoopOracle(LoopSpec(**INTEGRATOR, umin=-1.0, umax=1.0, reference=("step", 1.0), t_end=T, **spec))
    compare_metrics(o.metrics(), ref)


# --------------------------------------------------------------------------------------------------
# input / output delay split
# --------------------------------------------------------------------------------------------------
# With no disturbance, ym_A(t) = y_A(t - b) = G[u_A(. - a - b)](t): the command of loop A (Ti = a, To = b)
# obeys the same equation as that of loop B (Ti = a + b, To = 0), whose ym_B = y_B.  Hence u_A = u_B and
# y_A(t - b) = y_B(t), i.e. y_A(t) = y_B(t + b) (all-on-output moves at t = 0, all-on-input at a + b).
SPLIT_LOOPS = {
    "pi_clamp_sat": dict(**fopdt(1.5, 0.8), controller="pi", kp=1.2, ki=0.9, antiwindup="clamp",
                         umin=-0.7, umax=0.7),
    "pid_backcalc_sat": dict(**second_order(), controller="pid", kp=0.6, ki=0.4, kd=0.2, tf=0.05,
                             antiwindup="backcalc", tt=0.3, umin=-1.0, umax=1.0),
    "pv_true_sampled": dict(**INTEGRATOR, controller="pv", kp=1.5, kv=0.2, period=0.07, offset=0.01,
                            umin=-1.0, umax=1.0),
    "pv_true_neutral": dict(**INTEGRATOR, controller="pv", kp=1.5, kv=0.2, umin=-1.0, umax=1.0),
}


@pytest.mark.parametrize("name", list(SPLIT_LOOPS))
def test_delay_split_is_a_time_shift(name):
    a, b, T = 0.25, 0.15, 6.0
    loop = SPLIT_LOOPS[name]
    oa = LoopOracle(LoopSpec(**loop, Ti=a, To=b, reference=("step", 1.1), t_end=T))
    ob = LoopOracle(LoopSpec(**loop, Ti=a + b, To=0.0, reference=("step", 1.1), t_end=T + b))
    t = np.linspace(0.0, T, 1201)
    t = t[np.abs((t - 0.01) / 0.07 - np.round((t - 0.01) / 0.07)) > 1e-6]  # avoid the sampled jumps
    assert np.max(np.abs(oa.y(t) - ob.y(t + b))) < 1e-9
    assert np.max(np.abs(oa.u(t) - ob.u(t))) < 1e-8
    assert np.max(np.abs(oa.y(t))) > 0.5


def test_delay_split_with_disturbance():
    a, b, T, td, d = 0.25, 0.15, 6.0, 2.0, -0.4
    loop = SPLIT_LOOPS["pi_clamp_sat"]
    oa = LoopOracle(LoopSpec(**loop, Ti=a, To=b, reference=("step", 1.1), disturbance=(d, td), t_end=T))
    ob = LoopOracle(LoopSpec(**loop, Ti=a + b, To=0.0, reference=("step", 1.1), disturbance=(d, td), t_end=T + b))
    t = np.linspace(0.0, T, 1201)
    # the disturbance breaks the equivalence...
    diff = np.abs(oa.y(t) - ob.y(t + b))
    assert np.max(diff[t < td - b - 1e-9]) < 1e-9  # y_B(t + b) sees the load from t = td - b
    assert np.max(diff) > 1e-2
    # ...because it reaches the measurement b later in loop A: moving it to td + b in loop B restores it
    oc = LoopOracle(LoopSpec(**loop, Ti=a + b, To=0.0, reference=("step", 1.1), disturbance=(d, td + b),
                             t_end=T + b))
    assert np.max(np.abs(oa.y(t) - oc.y(t + b))) < 1e-9


def test_disturbance_channel_open_loop():
    # Kp = 0: y is the plant's response to the load step alone, with a direct term D
    A, B, C, D, td, d = -2.0, 1.0, 3.0, 0.5, 0.7, 1.3
    o = LoopOracle(LoopSpec(A=[[A]], B=[B], C=[C], D=D, Ti=0.2, controller="p", kp=0.0, reference=("step", 1.0),
                            disturbance=(d, td), t_end=3.0))
    t = np.linspace(0.0, 3.0, 301)
    t = t[np.abs(t - td) > 1e-9]
    ref = np.where(t >= td, d * (D + C * B / -A * (1 - np.exp(A * (t - td)))), 0.0)
    assert np.max(np.abs(o.y(t) - ref)) < 1e-11


# --------------------------------------------------------------------------------------------------
# saturation and anti-windup
# --------------------------------------------------------------------------------------------------
def test_unreached_limits_equal_linear_loop():
    loop = dict(**second_order(), controller="pid", kp=0.6, ki=0.4, kd=0.2, tf=0.05, Ti=0.3, To=0.1,
                antiwindup="clamp", reference=("step", 1.0), t_end=8.0)
    lin = LoopOracle(LoopSpec(**loop))
    wide = LoopOracle(LoopSpec(**loop, umin=-1e9, umax=1e9))
    t = np.linspace(0, 8.0, 801)
    assert np.max(np.abs(lin.y(t) - wide.y(t))) < 1e-10
    assert np.max(np.abs(lin.u(t) - wide.u(t))) < 1e-10


@pytest.mark.parametrize("plant", ["integrator", "fopdt"])
def test_antiwindup_reduces_overshoot(plant):
    P = INTEGRATOR if plant == "integrator" else fopdt(1.0, 2.0)
    T = 20.0
    base = dict(**P, Ti=0.2, controller="pi", kp=1.0, ki=0.5, umin=-0.5, umax=0.5, reference=("step", 2.0),
                t_end=T)
    if plant == "fopdt":
        base.update(umax=2.2, umin=-2.2, kp=1.0, ki=1.0)
    res = {}
    for key, aw, tt in [("none", "none", 1.0), ("clamp", "clamp", 1.0), ("bc", "backcalc", 0.1),
                        ("bc_slow", "backcalc", 1e8)]:
        res[key] = LoopOracle(LoopSpec(**base, antiwindup=aw, tt=tt))
    ov = {k: o.metrics()["overshoot"] for k, o in res.items()}
    assert ov["none"] > 5.0
    assert ov["clamp"] < ov["none"] - 1.0
    assert ov["bc"] < ov["none"] - 1.0
    # back-calculation with an enormous tracking time is no anti-windup at all
    t = np.linspace(0, T, 1001)
    assert np.max(np.abs(res["bc_slow"].y(t) - res["none"].y(t))) < 1e-5
    # clamping at t = 0: v = Kp S > umax and e > 0, so the integrator stays at 0 until v drops below umax
    if plant == "fopdt":
        return
    o = res["clamp"]
    ts = np.linspace(0, T, 4001)
    xi = o.states(ts)[:, -1]
    v = base["kp"] * (2.0 - o.y(ts)) + base["ki"] * xi
    first = np.argmax(v < base["umax"] - 1e-9)
    assert first > 0
    assert np.max(np.abs(xi[:first])) < 1e-13
    assert np.max(np.abs(o.u(ts[:first]) - base["umax"])) < 1e-9


def test_clamp_sliding_mode_is_the_limit_of_fixed_steps():
    # Here both clamp modes push v onto umax for a while (the literal rule chatters): the oracle follows
    # the sliding mode.  Forward Euler on the literal rule (the delay a multiple of h) converges to it
    # at first order.
    K, tau, kp, ki, um, S, L, T = 1.5, 0.8, 1.2, 0.9, 0.7, 1.1, 0.4, 6.0
    o = LoopOracle(LoopSpec(**fopdt(K, tau), controller="pi", kp=kp, ki=ki, antiwindup="clamp", umin=-um,
                            umax=um, Ti=L, reference=("step", S), t_end=T))
    assert o.slide_time > 0.2
    errs = []
    for h in (4e-4, 4e-5):
        N, d = int(round(T / h)), int(round(L / h))
        y = xi = 0.0
        us, ys = np.zeros(N + 1), np.zeros(N + 1)
        for k in range(N):
            e = S - y
            v = kp * e + ki * xi
            us[k] = min(max(v, -um), um)
            w = us[k - d] if k >= d else 0.0
            dxi = 0.0 if ((v > um and e > 0) or (v < -um and e < 0)) else e
            y += h * (-y + K * w) / tau
            xi += h * dxi
            ys[k + 1] = y
        errs.append(np.max(np.abs(ys - o.y(np.arange(N + 1) * h))))
    assert errs[0] < 0.5 * 4e-4
    assert 7 < errs[0] / errs[1] < 13


def test_clamp_slide_entered_at_a_tangency():
    """v = Kp S = umax at t = 0 and nothing moves before the delay: the clamped field is tangent to the
    surface (v' = 0) until the output moves, and then turns below it, so the command slides on umax.
    The plant 1/((s+1)(0.5 s+1)) sees 0.5 from t = 0.2 throughout: y = 0.5 (1 - 2 e^-tau + e^-2tau).
    A third-order plant (y' = 0 and y'' = 0 where it starts to move) is the harder tangency."""
    A = np.array([[-3.0, -2.0], [1.0, 0.0]])
    o = LoopOracle(LoopSpec(A=A, B=np.array([1.0, 0.0]), C=np.array([0.0, 2.0]), Ti=0.2, controller="pi", kp=0.5,
                            ki=0.8, antiwindup="clamp", umin=-0.5, umax=0.5, reference=("step", 1.0), t_end=10.0))
    t = np.linspace(0.0, 10.0, 501)
    tau = np.maximum(t - 0.2, 0.0)
    np.testing.assert_allclose(o.y(t), 0.5 * (1.0 - 2.0 * np.exp(-tau) + np.exp(-2.0 * tau)), atol=1e-10, rtol=0)
    assert o.slide_time > 9.0
    # 1/(s+1)^3 from rest under v = Kp S = umax: the command holds umax while the slide lasts
    A3 = np.array([[-3.0, -3.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    o3 = LoopOracle(LoopSpec(A=A3, B=np.array([1.0, 0.0, 0.0]), C=np.array([0.0, 0.0, 1.0]), Ti=0.1,
                             controller="pi", kp=0.4, ki=0.5, antiwindup="clamp", umin=-0.4, umax=0.4,
                             reference=("step", 1.0), t_end=3.0))
    tau = np.maximum(np.linspace(0.0, 3.0, 301) - 0.1, 0.0)
    step3 = 1.0 - np.exp(-tau) * (1.0 + tau + tau ** 2 / 2.0)
    np.testing.assert_allclose(o3.y(np.linspace(0.0, 3.0, 301)), 0.4 * step3, atol=1e-10, rtol=0)


# --------------------------------------------------------------------------------------------------
# sampling
# --------------------------------------------------------------------------------------------------
def test_sampled_command_is_held():
    period, off, L, kp, S = 0.1, 0.037, 0.25, 1.4, 1.0
    tj = off + 3 * period  # the reference steps down at a sample instant: the sample takes the new value
    rfun = lambda t: S if t < tj else 0.5 * S  # noqa: E731
    o = LoopOracle(LoopSpec(**fopdt(1.0, 0.5), Ti=L, controller="p", kp=kp, umin=-1.0, umax=1.0, period=period,
                            offset=off, reference=("samples", [0.0, tj], [S, 0.5 * S], "hold"), t_end=4.0))
    rng = np.random.default_rng(7)
    assert np.all(o.u(rng.uniform(0, off, 20)) == 0.0)
    for k in range(38):
        tk = off + k * period
        uk = o.u(tk)
        # the sampled command: clip(Kp (r(t_k) - y(t_k)))  (D = 0, To = 0: ym is continuous)
        assert abs(uk - min(max(kp * (rfun(tk) - o.y(tk)), -1.0), 1.0)) < 1e-12
        ts = tk + rng.uniform(0, period, 5) * (1 - 1e-9)
        assert np.all(o.u(ts) == uk)
    assert abs(o.u(tj) - kp * (0.5 * S - o.y(tj))) < 1e-12


# --------------------------------------------------------------------------------------------------
# reference kinds
# --------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("ref,rfun", [
    (("ramp", 0.5, 0.8), lambda t: 0.5 + 0.8 * t),
    (("samples", [0.1, 0.3, 0.6], [1.0, 2.0, -0.5], "linear"),
     lambda t: np.interp(t, [0.1, 0.3, 0.6], [1.0, 2.0, -0.5])),
    (("samples", [0.1, 0.3, 0.6], [1.0, 2.0, -0.5], "hold"),
     lambda t: np.where(t < 0.3, 1.0, np.where(t < 0.6, 2.0, -0.5))),
])
def test_reference_kinds_before_feedback(ref, rfun):
    kp, Ti, To = 0.7, 0.5, 0.3
    o = LoopOracle(LoopSpec(**INTEGRATOR, Ti=Ti, To=To, controller="p", kp=kp, reference=ref, t_end=3.0))
    t = np.linspace(0.0, Ti + To, 401)[:-1]
    t = t[np.min(np.abs(t[:, None] - np.array([0.3, 0.6])[None, :]), axis=1) > 1e-9]
    assert np.max(np.abs(o.u(t) - kp * rfun(t))) < 1e-13
    assert abs(float(o.u(0.0)) - kp * float(rfun(0.0))) < 1e-13
    if ref[0] == "ramp":
        # integrator plant: y(t) = Kp (S (t - Ti) + m (t - Ti)^2 / 2) until the feedback acts at Ti + L
        tt = np.linspace(Ti, 2 * Ti + To, 101)
        s = tt - Ti
        assert np.max(np.abs(o.y(tt) - kp * (0.5 * s + 0.8 * s**2 / 2))) < 1e-11


def test_samples_reference_equal_to_step():
    loop = dict(**fopdt(1.5, 0.8), controller="pi", kp=1.2, ki=0.9, antiwindup="clamp", umin=-0.7, umax=0.7,
                Ti=0.3, To=0.1, t_end=6.0)
    step = LoopOracle(LoopSpec(**loop, reference=("step", 1.3)))
    t = np.linspace(0.0, 6.0, 601)
    for ref in [("samples", [0.0, 2.0], [1.3, 1.3], "linear"), ("samples", [1.0, 4.0], [1.3, 1.3], "hold")]:
        o = LoopOracle(LoopSpec(**loop, reference=ref))
        assert np.max(np.abs(o.y(t) - step.y(t))) < 1e-10
    m1 = step.metrics()
    m2 = LoopOracle(LoopSpec(**loop, reference=("samples", [0.0, 3.0], [1.3, 1.3], "hold"))).metrics()
    for k in KEYS:
        assert m1[k] == pytest.approx(m2[k], abs=1e-9, nan_ok=True)


def test_unsupported():
    with pytest.raises(NotImplementedError):
        LoopOracle(LoopSpec(**INTEGRATOR, controller="pv", kp=1.0, kv=0.2, t_end=1.0))  # zero delay, neutral
    with pytest.raises(NotImplementedError):
        LoopOracle(LoopSpec(A=[[-1.0]], B=[1.0], C=[1.0], D=0.5, controller="p", kp=1.0, t_end=1.0))
    with pytest.raises(NotImplementedError):
        LoopOracle(LoopSpec(A=[[-1.0]], B=[1.0], C=[1.0], D=0.5, Ti=0.1, controller="pv", kp=1.0, kv=0.1,
                            t_end=1.0))
