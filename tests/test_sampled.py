"""Exact stability of sampled delay loops (delaykit.spectrum.sampled), against independent computations.

References used here, none of which calls the module under test:

* the one-period transition matrix rebuilt by integrating the plant and controller ODEs numerically
  (SciPy's DOP853 at rtol 1e-12) from every basis vector of the lifted state, with the controllers written
  out by hand from the laws in delaykit.models.controllers and the plant realised by scipy.signal.tf2ss;
* delaykit's exact simulator (a different algorithm: Taylor polynomials between breakpoints);
* closed forms derived in the tests (P control of an integrator);
* python-control's zero-order-hold discretisation and its stability margins;
* the continuous loop's rightmost root (delaykit.spectrum.stability), the limit of the sampled loop as h -> 0.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import linear_sum_assignment
from scipy.signal import tf2ss

from delaykit import AltitudeLoop, Controller, InvalidTypeError, InvalidValueError, Loop, simulate
from delaykit.spectrum.sampled import (SampledMargins, compare_sampling, sampled_frequency_response,
                                       sampled_margins, sampled_model, sampled_spectrum)
from delaykit.spectrum.stability import rightmost


# -- an independent construction of the transition matrix -----------------------------------------------------
def _controller_ode(c: Controller):
    """The controller by hand: (number of states, xc' = f(xc, y, yd), v = g(xc, y, yd)) with r = 0.

    State coordinates (the same as delaykit's realisation, so that the matrices can be compared):
    pi: xi = integral of e; pid: [xi, q] with q the low-pass of y, Tf q' = y - q, derivative term
    kd (y - q) / Tf = kd s/(Tf s + 1) y; pd: [q]; filtered pv: [q, q'] with
    q'' + 2 zf wf q' + wf^2 q = y, the filtered velocity wf^2 q'.
    """
    kp, ki, kd, kv = c.kp, c.ki, c.kd, c.kv
    if c.kind == "p":
        return 0, lambda xc, y, yd: np.zeros(0), lambda xc, y, yd: -kp * y
    if c.kind == "pv" and c.velocity == "true":
        return 0, lambda xc, y, yd: np.zeros(0), lambda xc, y, yd: -kp * y - kv * yd
    if c.kind == "pv":
        wf, zf = c.filter_wn, c.filter_zeta
        return (2, lambda xc, y, yd: np.array([xc[1], y - wf * wf * xc[0] - 2 * zf * wf * xc[1]]),
                lambda xc, y, yd: -kp * y - kv * wf * wf * xc[1])
    if c.kind == "pi":
        return 1, lambda xc, y, yd: np.array([-y]), lambda xc, y, yd: -kp * y + ki * xc[0]
    tf = c.derivative_filter
    if c.kind == "pd":
        return 1, lambda xc, y, yd: np.array([(y - xc[0]) / tf]), lambda xc, y, yd: -kp * y - kd * (y - xc[0]) / tf
    if c.kind == "pid":
        return (2, lambda xc, y, yd: np.array([-y, (y - xc[1]) / tf]),
                lambda xc, y, yd: -kp * y + ki * xc[0] - kd * (y - xc[1]) / tf)
    raise AssertionError(c.kind)


def brute_force_phi(loop: Loop, h: float) -> np.ndarray:
    """Phi column by column: integrate the loop over one period from each basis vector of the lifted state.

    Lifted state [x(t_k - To), xc(t_k), u_{k-1}, ..., u_{k-p}]; total delay T = m h + f; the plant input is
    u_{k-m-1} on [0, f) and u_{k-m} on [f, h); the sample reads y and y' at the left limit (input u_{k-m-1}).
    """
    A, B, C, D = tf2ss(loop.plant.num, loop.plant.den)
    n = A.shape[0]
    B, C, D = B.reshape(n), C.reshape(n), float(np.squeeze(D))
    nc, fc, gc = _controller_ode(loop.controller)
    T = loop.delay + loop.output_delay
    m = int(math.floor(T / h + 1e-9))
    f = T - m * h
    if f < 1e-9 * h:
        f = 0.0
    reads_input = D != 0.0 or (loop.controller.kind == "pv" and loop.controller.velocity == "true"
                               and float(C @ B) != 0.0)
    p = m + 1 if (f > 0 or reads_input) else m
    N = n + nc + p
    cols = []
    for i in range(N):
        e = np.eye(N)[i]
        x, xc, held = e[:n], e[n:n + nc], e[n + nc:]
        u_left = held[m] if p > m else 0.0
        y0 = C @ x + D * u_left
        yd0 = C @ A @ x + (C @ B) * u_left
        u_k = gc(xc, y0, yd0)
        a = u_left
        b = u_k if m == 0 else held[m - 1]

        def rhs(t, s, w):
            xx, cc = s[:n], s[n:]
            y = C @ xx + D * w
            yd = C @ (A @ xx + B * w)
            return np.r_[A @ xx + B * w, fc(cc, y, yd)]

        s = np.r_[x, xc]
        for w, t0, t1 in ((a, 0.0, f), (b, f, h)):
            if t1 > t0:
                s = solve_ivp(rhs, (t0, t1), s, args=(w,), method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]
        cols.append(np.r_[s, u_k, held[:p - 1]] if p else s)
    return np.column_stack(cols)


def assert_same_eigenvalues(a: np.ndarray, b: np.ndarray, tol: float) -> None:
    ea, eb = np.linalg.eigvals(a), np.linalg.eigvals(b)
    i, j = linear_sum_assignment(np.abs(ea[:, None] - eb[None, :]))
    assert np.max(np.abs(ea[i] - eb[j])) < tol


BRUTE_CASES = [
    # the paper's P loop: delay not a multiple of the period (0.37 = 5 h + 0.045), and a multiple (0.39 = 6 h)
    ("p, T = 5h + f", AltitudeLoop(kp=1.31, delay=0.37, period=0.065).to_loop()),
    ("p, T = 6h", AltitudeLoop(kp=1.31, delay=0.39, period=0.065).to_loop()),
    ("p, no delay", AltitudeLoop(kp=1.31, delay=0.0, period=0.065).to_loop()),
    ("pv true velocity, fraction", AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, period=0.065).to_loop()),
    ("pv true velocity, T = 6h", AltitudeLoop(kp=2.0, delay=0.39, kv=0.3, period=0.065).to_loop()),
    ("pv filtered (Table 4)", AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", period=0.065).to_loop()),
    ("pi, input and output delay", Loop("1/(s*(0.5*s+1))", Controller.pi(1.0, 0.3), delay=0.2, output_delay=0.13,
                                       period=0.1)),
    ("pi, direct feedthrough", Loop("(s+1)/(s+2)", Controller.pi(0.5, 2.0), delay=0.2, period=0.05)),
    ("pi, feedthrough, fraction", Loop("(s+1)/(s+2)", Controller.pi(0.5, 2.0), delay=0.22, period=0.05)),
    ("pid", Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.23, period=0.05)),
    ("pd, third order", Loop("1/(s*(0.05*s+1)*(0.2*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=0.3,
                             output_delay=0.05, period=0.04)),
]


@pytest.mark.parametrize("name, loop", BRUTE_CASES, ids=[c[0] for c in BRUTE_CASES])
def test_transition_matrix_equals_brute_force_integration(name, loop):
    mdl = sampled_model(loop)
    ref = brute_force_phi(loop, loop.period)
    assert ref.shape == mdl.phi.shape
    assert np.max(np.abs(mdl.phi - ref)) < 1e-8 * max(1.0, np.max(np.abs(ref)))
    assert_same_eigenvalues(mdl.phi, ref, 1e-8)


# -- the model describes the system the simulator simulates ------------------------------------------------------
SIM_CASES = [
    ("stable, T = 5h + f", AltitudeLoop(kp=1.31, delay=0.37, period=0.065, vmax=None), True),
    ("stable, T = 6h", AltitudeLoop(kp=1.31, delay=0.39, period=0.065, vmax=None), True),
    ("unstable, T = 5h + f", AltitudeLoop(kp=4.2, delay=0.37, period=0.065, vmax=None), False),
    ("unstable, T = 6h", AltitudeLoop(kp=4.0, delay=0.39, period=0.065, vmax=None), False),
    ("filtered pv, offset", AltitudeLoop(kp=2.0, delay=0.37, kv=0.1, velocity="filtered", period=0.065,
                                         sample_offset=0.03, vmax=None), True),
    ("pi, output delay", Loop("1/(s*(0.5*s+1))", Controller.pi(1.0, 0.3), delay=0.2, output_delay=0.13,
                              period=0.1), True),
]


def _envelope_rate(t: np.ndarray, e: np.ndarray) -> float:
    """Slope of log|e| through its local maxima (the envelope), by least squares, above rounding noise."""
    a = np.abs(e)
    peaks = np.nonzero((a[1:-1] > a[:-2]) & (a[1:-1] >= a[2:]))[0] + 1
    peaks = peaks[a[peaks] > 1e-12]
    assert peaks.size >= 6, "too few oscillations to fit an envelope"
    return float(np.polyfit(t[peaks], np.log(a[peaks]), 1)[0])


@pytest.mark.parametrize("name, loop, stable", SIM_CASES, ids=[c[0] for c in SIM_CASES])
def test_simulated_error_decays_or_grows_at_the_spectral_rate(name, loop, stable):
    spec = sampled_spectrum(loop)
    assert spec.stable is stable
    h = spec.period
    rate = math.log(spec.radius) / h
    # the linear loop, simulated: the error's envelope, late enough for the dominant pair to rule
    t_end = 20.0
    r = simulate(loop, 1.0, t_end=t_end)
    t = np.arange(2.0, t_end, h / 16)
    fit = _envelope_rate(t, 1.0 - r.output(t))
    assert fit == pytest.approx(rate, rel=0.01, abs=0.01)


@pytest.mark.parametrize("name, loop, stable", SIM_CASES, ids=[c[0] for c in SIM_CASES])
def test_iterated_model_reproduces_the_simulated_samples(name, loop, stable):
    # z_{k+1} = Phi z_k + b_ref r from rest, the reference a unit step at the first sample (offset 0 only: with
    # an offset the loop's continuous controller states move before the first sample)
    lp = loop if isinstance(loop, Loop) else loop.to_loop()
    if lp.sample_offset:
        lp = lp.replace(sample_offset=0.0)
    mdl = sampled_model(lp)
    h, n = mdl.period, mdl.n_plant
    C = lp.plant.state_space()[2]
    z = np.zeros(mdl.order)
    y = []
    for _ in range(300):
        y.append(C @ z[:n])             # strictly proper plants: y(t_k - To) = C x(t_k - To)
        z = mdl.phi @ z + mdl.b_ref
    t = np.arange(300) * h - lp.output_delay
    ok = t >= 0
    ysim = simulate(lp, 1.0, t_end=300 * h + 1).output(t[ok])
    scale = max(1.0, float(np.max(np.abs(ysim))))
    assert np.max(np.abs(np.array(y)[ok] - ysim)) < 1e-9 * scale


def test_direct_feedthrough_samples_read_the_left_limit():
    # a plant with D != 0 and T a multiple of h: the sample at t_k reads y(t_k^-), whose input is u_{k-m-1};
    # compared with the simulator just before each sample instant
    lp = Loop("(s+1)/(s+2)", Controller.pi(0.5, 2.0), delay=0.1, output_delay=0.1, period=0.05)
    mdl = sampled_model(lp)
    A, B, C, D = lp.plant.state_space()
    m, nx = mdl.whole_periods, mdl.n_plant + mdl.n_controller
    assert mdl.fraction == 0.0 and mdl.n_held == m + 1
    z = np.zeros(mdl.order)
    y = []
    for _ in range(200):
        y.append(C @ z[:1] + D * z[nx + m])  # u_{k-m-1}
        z = mdl.phi @ z + mdl.b_ref
    t = np.arange(200) * 0.05 - 0.1 - 1e-10
    ok = t > 0
    ysim = simulate(lp, 1.0, t_end=12.0).output(t[ok])
    assert np.max(np.abs(np.array(y)[ok] - ysim)) < 1e-8


def test_sampling_offset_does_not_change_the_model():
    a = sampled_model(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", period=0.065))
    b = sampled_model(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", period=0.065,
                                   sample_offset=0.04))
    assert np.array_equal(a.phi, b.phi)


@pytest.mark.parametrize("plant, ctrl, delay, g", [
    ("(s+1)/(s+2)", Controller.pi(0.5, 2.0), 0.22, 1.7),      # direct feedthrough: the sample reads the input
    ("1/(s*(0.5*s+1))", Controller.pi(1.0, 0.3), 0.2, 0.6),
])
def test_plant_input_part_scales_like_a_plant_gain(plant, ctrl, delay, g):
    # the parts of the model that come through the plant's input (a_plant, b_plant, k_plant), scaled by g, against
    # the brute-force matrix of the loop whose plant is g times larger; and the poles are those of the command
    # scaled by g (closed(g)), the same loop broken elsewhere
    h = 0.05
    loop = Loop(plant, ctrl, delay=delay, period=h)
    mdl = sampled_model(loop)
    d = g - 1.0
    M = (mdl.a_open + d * mdl.a_plant) + np.outer(mdl.b_open + d * mdl.b_plant, mdl.k_row + d * mdl.k_plant)
    tf = loop.plant
    ref = brute_force_phi(loop.replace(plant=(g * tf.num, tf.den)), h)
    assert_same_eigenvalues(M, ref, 1e-7)
    assert_same_eigenvalues(mdl.closed(g), ref, 1e-7)
    assert np.sort_complex(mdl.poles(g)).tolist() == np.sort_complex(np.linalg.eigvals(mdl.closed(g))).tolist()


# -- closed forms -----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("m", [0, 1, 2, 5, 11])
def test_p_integrator_integer_delay_characteristic_polynomial(m):
    # x_{k+1} = x_k + h u_{k-m}, u_k = -Kp x_k  =>  (z - 1) z^m X = -Kp h X  =>  z^{m+1} - z^m + Kp h = 0
    kp, h = 1.7, 0.05
    s = sampled_spectrum(Loop("1/s", Controller.p(kp), delay=m * h, period=h))
    ref = np.zeros(m + 2)
    ref[0], ref[1], ref[-1] = 1.0, -1.0, ref[-1] + kp * h
    if m == 0:
        ref = np.array([1.0, -1.0 + kp * h])
    assert s.characteristic.shape == ref.shape
    assert np.allclose(s.characteristic, ref, atol=1e-12)
    roots = np.roots(ref)
    i, j = linear_sum_assignment(np.abs(s.poles[:, None] - roots[None, :]))
    assert np.max(np.abs(s.poles[i] - roots[j])) < 1e-9
    assert s.radius == pytest.approx(np.max(np.abs(roots)), abs=1e-12)


@pytest.mark.parametrize("m, frac", [(0, 0.3), (3, 0.5), (6, 0.9)])
def test_p_integrator_fractional_delay_closed_forms(m, frac):
    # T = m h + f: x_{k+1} = x_k + f u_{k-m-1} + (h - f) u_{k-m}, so the open loop from u_k to -v_k is
    # L(z) = Kp ((h - f) z + f) / (z^{m+1} (z - 1)) and the poles solve z^{m+2} - z^{m+1} + Kp (h - f) z + Kp f = 0
    kp, h = 1.3, 0.065
    f = frac * h
    lp = Loop("1/s", Controller.p(kp), delay=m * h + f, period=h)
    ref = np.zeros(m + 3)
    ref[0], ref[1] = 1.0, -1.0
    ref[-2] += kp * (h - f)
    ref[-1] += kp * f
    s = sampled_spectrum(lp)
    assert np.allclose(s.characteristic, ref, atol=1e-12)
    roots = np.roots(ref)
    i, j = linear_sum_assignment(np.abs(s.poles[:, None] - roots[None, :]))
    assert np.max(np.abs(s.poles[i] - roots[j])) < 1e-9
    w = np.linspace(0.05, math.pi / h, 200)
    z = np.exp(1j * w * h)
    L = kp * ((h - f) * z + f) / (z ** (m + 1) * (z - 1))
    assert np.max(np.abs(sampled_frequency_response(lp, w) - L) / np.abs(L)) < 1e-11


@pytest.mark.parametrize("m, gm", [(0, 2.0), (1, 1.0), (2, (math.sqrt(5) - 1) / 2)])
def test_p_integrator_gain_margin_closed_form(m, gm):
    # z^{m+1} - z^m + c = 0 on |z| = 1, z = e^{j theta}: c = z^m (1 - z), so c = |1 - z| = 2 sin(theta / 2) and
    # arg c = (m + 1/2) theta - pi/2 = 0, theta = pi / (2m + 1): the first pole reaches the circle at
    # c = 2 sin(pi / (4m + 2)) = 2, 1, (sqrt 5 - 1) / 2 for m = 0, 1, 2; the margin is c / (Kp h)
    kp, h = 1.2, 0.1
    g = sampled_margins(Loop("1/s", Controller.p(kp), delay=m * h, period=h)).gain_margin
    assert g == pytest.approx(gm / (kp * h), rel=1e-10)


# -- the frequency response and margins against python-control -------------------------------------------------
CONTROL_CASES = [
    ("pi", "1/(s*(0.5*s+1))", Controller.pi(1.0, 0.3), 0.3, 0.1),
    ("pid", "1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), 0.2, 0.05),
    ("p, lag", "1/(s*(0.05*s+1))", Controller.p(2.0), 0.3, 0.05),
]


def _control_loop(plant: str, c: Controller, m: int, h: float):
    import control

    from delaykit import TransferFunction

    P = TransferFunction.coerce(plant)
    s = control.tf("s")
    Cy = c.kp + (c.ki / s if c.kind in ("pi", "pid") else 0)
    if c.kind == "pid":
        Cy = Cy + c.kd * s / (c.derivative_filter * s + 1)
    Lc = control.tf(list(P.num), list(P.den)) * Cy
    Ld = control.sample_system(control.minreal(Lc, verbose=False), h, method="zoh")
    return Ld * control.tf([1], [1] + [0] * m, h)


@pytest.mark.filterwarnings("ignore:stability_margins")
@pytest.mark.parametrize("name, plant, ctrl, delay, h", CONTROL_CASES, ids=[c[0] for c in CONTROL_CASES])
def test_frequency_response_and_margins_match_python_control(name, plant, ctrl, delay, h):
    # a continuous controller on the continuous output, sampled: the loop is ZOH -> P(s) Cy(s) -> sample, with
    # a delay of m whole periods: L(z) = z^{-m} Z{ZOH P Cy}(z) (python-control's ZOH discretisation)
    import control

    m = round(delay / h)
    lp = Loop(plant, ctrl, delay=delay, period=h)
    Ld = _control_loop(plant, ctrl, m, h)
    w = np.linspace(0.01, math.pi / h, 300)
    ref = np.asarray(Ld(np.exp(1j * w * h)))
    mine = sampled_frequency_response(lp, w)
    assert np.max(np.abs(mine - ref) / np.abs(ref)) < 1e-8
    gm, pm, _, wpc, wgc, _ = control.stability_margins(Ld)
    mg = sampled_margins(lp)
    assert mg.gain_margin == pytest.approx(gm, rel=1e-6)
    assert mg.phase_margin == pytest.approx(pm, abs=1e-5)
    assert mg.crossover == pytest.approx(wgc, rel=1e-6)


# -- consistency: margins are where the radius reaches 1; h -> 0 gives the continuous loop ------------------------
MARGIN_CASES = [
    ("p paper", AltitudeLoop(kp=1.31, delay=0.368, period=0.065)),
    ("pv filtered", AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", period=0.065)),
    ("pv true, T = 6h", AltitudeLoop(kp=2.0, delay=0.39, kv=0.3, period=0.065)),
    ("pid", Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.23, period=0.05)),
]


@pytest.mark.parametrize("name, loop", MARGIN_CASES, ids=[c[0] for c in MARGIN_CASES])
def test_margins_are_where_the_spectral_radius_reaches_one(name, loop):
    mg = sampled_margins(loop)
    assert mg.stable
    mdl = sampled_model(loop)
    rad = lambda M: np.max(np.abs(np.linalg.eigvals(M)))  # noqa: E731
    g = mg.gain_margin
    assert rad(mdl.closed(g * (1 - 1e-6))) < 1.0 < rad(mdl.closed(g * (1 + 1e-6)))
    # the loop gain scaled by g, built as a loop with every gain multiplied (an independent path to Phi(g))
    lp = loop if isinstance(loop, Loop) else loop.to_loop()
    c = lp.controller
    scaled = lambda k: lp.replace(kp=c.kp * k, ki=c.ki * k, kd=c.kd * k, kv=c.kv * k)  # noqa: E731
    assert sampled_spectrum(scaled(g * (1 - 1e-6))).radius < 1.0 < sampled_spectrum(scaled(g * (1 + 1e-6))).radius
    d = mg.delay_margin
    below = sampled_spectrum(lp.replace(delay=lp.delay + d * (1 - 1e-6))).radius
    above = sampled_spectrum(lp.replace(delay=lp.delay + d * (1 + 1e-6))).radius
    assert below < 1.0 < above
    # and no earlier instability: the radius stays below 1 on a fine scan of extra delay up to the margin
    assert all(sampled_spectrum(lp.replace(delay=lp.delay + x)).radius < 1.0 for x in np.linspace(0, d, 60)[:-1])
    assert mg.critical_delay == pytest.approx(lp.total_delay + d, abs=1e-12)


def test_sampled_rate_tends_to_the_continuous_rightmost_root():
    # the hold adds a lag of about h/2: the sampled rate tends to the continuous root at first order in h,
    # and to the root of the loop with the delay T + h/2 at second order
    for loop in (AltitudeLoop(kp=1.31, delay=0.368),
                 AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered")):
        root = rightmost(loop).root
        err, err2 = [], []
        for h in (0.004, 0.002, 0.001):
            rate = sampled_spectrum(loop.replace(period=h)).rate
            err.append(abs(rate - root))
            err2.append(abs(rate - rightmost(loop.replace(delay=loop.delay + h / 2)).root))
        assert err[-1] < 0.015
        assert 1.7 < err[0] / err[1] < 2.3 and 1.7 < err[1] / err[2] < 2.3   # first order
        assert err2[-1] < 0.05 * err[-1]                                     # the h/2 lag explains it
        assert err2[0] / err2[2] > 10.0                                      # second order


def test_compare_sampling_paper_p_loop():
    # continuous P loop on 1/s: critical delay pi / (2 Kp) (Lambert W / the crossing at w = Kp)
    c = compare_sampling(AltitudeLoop(kp=1.31, delay=0.368, period=0.065))
    assert c.continuous_critical_delay == pytest.approx(math.pi / 2 / 1.31, rel=1e-10)
    assert c.continuous_delay_margin == pytest.approx(math.pi / 2 / 1.31 - 0.368, rel=1e-10)
    assert c.abscissa == pytest.approx(rightmost(AltitudeLoop(kp=1.31, delay=0.368)).abscissa, abs=1e-12)
    # the hold costs about half a period of delay margin
    assert c.delay_margin_lost == pytest.approx(0.065 / 2, rel=0.1)
    assert c.sampled.stable and c.continuous_stable
    assert c.rate == pytest.approx(math.log(c.radius) / 0.065, rel=1e-14)


def test_first_order_lag_small_gain_closed_forms():
    # P control of 1/(s + 1), a = e^{-h}: L(z) = Kp (1 - a) / (z - a) z^{-m}.  |L| <= Kp < 1 on the unit circle:
    # stable for every delay (small gain), no gain crossover; without delay L(-1) = -Kp (1 - a) / (1 + a), so the
    # gain margin is (1 + a) / ((1 - a) Kp)
    kp, h = 0.5, 0.1
    a = math.exp(-h)
    mg = sampled_margins(Loop("1/(s+1)", Controller.p(kp), delay=0.0, period=h))
    assert mg.gain_margin == pytest.approx((1 + a) / ((1 - a) * kp), rel=1e-10)
    assert mg.delay_margin == math.inf and mg.phase_margin == math.inf and mg.gain_crossovers == ()
    # the one phase crossover, z = -1, gives the margin
    assert [(c.kind, c.frequency) for c in mg.crossovers] == [("phase", pytest.approx(math.pi / h, rel=1e-15))]
    assert mg.crossovers[0].gain_margin == pytest.approx(mg.gain_margin, rel=1e-10)
    assert mg.ms == pytest.approx(1 / (1 - kp * (1 - a) / (1 + a)), rel=1e-9)   # |1 + L| smallest at z = -1
    mg = sampled_margins(Loop("1/(s+1)", Controller.p(kp), delay=0.33, period=h))
    assert mg.delay_margin == math.inf and mg.to_dict()["delay_margin"] is None


def test_unstable_loop_has_no_margins():
    # Kp = 5, T = 0.37: unstable (the continuous loop already is, Kp T > pi/2): margins NaN, null in JSON
    mg = sampled_margins(AltitudeLoop(kp=5.0, delay=0.37, period=0.065))
    assert not mg.stable
    assert all(math.isnan(x) for x in (mg.gain_margin, mg.phase_margin, mg.delay_margin, mg.critical_delay))
    d = mg.to_dict()
    assert d["gain_margin"] is None and d["delay_margin"] is None and d["stable"] is False
    gain = [c for c in mg.crossovers if c.kind == "gain"]   # the crossovers are still listed
    assert len(gain) == 1 and gain[0].phase_margin < 0 and gain[0].magnitude == pytest.approx(1.0, rel=1e-12)
    c = compare_sampling(AltitudeLoop(kp=5.0, delay=0.37, period=0.065))
    assert not c.continuous_stable and math.isnan(c.continuous_delay_margin)
    json.dumps(c.to_dict(), allow_nan=False)


@pytest.mark.parametrize("delay", [0.1, 0.12])  # two periods exactly, and 2.4 periods
def test_lower_gain_margin_of_an_open_loop_unstable_plant(delay):
    """P control (Kp = 2) of the unstable 1/(s - 1), h = 0.05 s: lowering the loop gain by the factor g puts a
    pole at z = 1 when g Kp P(0) = -1, i.e. g = 0.5 (closed form, whatever the delay); and the radius of the
    brute-force transition matrix (integrated ODEs, built in this file) crosses 1 there, and at the upper margin."""
    from scipy.optimize import brentq

    h = 0.05
    loop = Loop("1/(s-1)", Controller.p(2.0), delay=delay, period=h)
    mg = sampled_margins(loop)
    assert mg.stable and mg.lower_gain_margin == pytest.approx(0.5, abs=1e-9)
    assert mg.to_dict()["lower_gain_margin"] == mg.lower_gain_margin and "(lower 0.5000)" in repr(mg)

    def radius(g):
        return max(abs(np.linalg.eigvals(brute_force_phi(loop.replace(kp=2.0 * g), h)))) - 1.0

    assert radius(0.45) > 0 > radius(0.55) and radius(1.0) < 0
    assert brentq(radius, 0.45, 0.55, xtol=1e-10) == pytest.approx(mg.lower_gain_margin, abs=1e-7)
    assert brentq(radius, 1.0, mg.gain_margin * 1.5, xtol=1e-10) == pytest.approx(mg.gain_margin, rel=1e-7)
    # an open-loop stable plant under P control: lowering the gain never destabilises it
    assert sampled_margins(Loop("1/(s+1)", Controller.p(2.0), delay=delay, period=h)).lower_gain_margin == 0.0


# -- results and errors -----------------------------------------------------------------------------------------
def test_results_are_json_ready_with_the_margin_keys():
    lp = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", period=0.065)
    mg = sampled_margins(lp)
    assert set(mg.to_dict()) == {"gain_margin", "phase_margin", "delay_margin", "critical_delay", "crossover",
                                 "ms", "crossovers", "stable", "lower_gain_margin", "gain_margin_db",
                                 "phase_crossover"}
    d = mg.to_dict()
    assert d["lower_gain_margin"] == 0.0  # an integrator in the loop: lowering the gain never destabilises it
    assert d["gain_margin_db"] == pytest.approx(20 * math.log10(d["gain_margin"]), rel=1e-12)
    # the phase crossover that sets the gain margin: there 1/|L| is the gain margin
    L = sampled_frequency_response(lp, d["phase_crossover"])
    assert 1 / abs(L) == pytest.approx(d["gain_margin"], rel=1e-6) and L.real < 0
    for obj in (mg, sampled_spectrum(lp), sampled_model(lp), compare_sampling(lp)):
        json.dumps(obj.to_dict(), allow_nan=False)
        assert "\n" not in repr(obj)
    inf = SampledMargins(math.inf, math.inf, math.inf, math.inf, None, 1.0, (), True).to_dict()
    assert inf["gain_margin"] is None and inf["delay_margin"] is None and inf["critical_delay"] is None


def test_bad_input():
    cont = AltitudeLoop(kp=1.31, delay=0.368)
    for fn in (sampled_spectrum, sampled_margins, compare_sampling, sampled_model):
        with pytest.raises(InvalidValueError, match="sampled"):
            fn(cont)
    lp = AltitudeLoop(kp=1.31, delay=0.368, period=0.065)
    for bad in (math.nan, math.inf, [1.0, math.nan]):
        with pytest.raises(InvalidValueError):
            sampled_frequency_response(lp, bad)
    for bad in (0.0, -1.0, 2 * math.pi / 0.065):
        with pytest.raises(InvalidValueError):
            sampled_frequency_response(lp, bad)
    with pytest.raises(InvalidTypeError):
        sampled_frequency_response(lp, "fast")
    with pytest.raises(InvalidTypeError):
        sampled_spectrum("1/s")
    with pytest.raises(InvalidValueError):
        sampled_spectrum(AltitudeLoop(kp=1.0, delay=10.0, period=0.001))   # 10,000 held commands
