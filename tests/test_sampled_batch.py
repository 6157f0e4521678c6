"""The batch simulator's fast path for sampled loops (delaykit.simulate._sampled_batch), against the Taylor kernel.

Both are exact (the event stepper with matrix exponentials, the Taylor kernel with polynomial pieces), and they
share no arithmetic: so on random sampled loops their metrics must agree to 1e-9 (percentage points and
seconds), where the answer is not a tie between two equal maxima or a graze of the settling band's edge.  The
independent reference is tests/oracle_loop.py (SciPy's DOP853, 1e-12, breakpoints located), on a few named
loops; the matrix exponential is checked against SciPy's; and the dispatch in simulation._batch is checked to
send only the eligible rows to the fast path (anti-windup, an output delay or a predictor go to the Taylor
kernel and get exactly its results).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from delaykit import AltitudeLoop, _native
from delaykit.models import Compensator, Controller, LoadStep, Loop, Ramp, plants
from delaykit.simulate import _jit, _layout as K, simulate, simulate_many
from delaykit.simulate import simulation as S
from oracle_loop import LoopOracle
from strategies import plant_denominators
from test_loop_simulation import spec_for

F = _native.load("delaykit.simulate", "_sampled_batch")  # compiled (Cython, or numba without the extension)
EK = _native.load("delaykit.models", "_expmkernel")  # the one matrix exponential, which F calls (compiled too)

KEYS = ("overshoot", "peak_time", "peak", "t10", "t90", "rise_time", "settling_time", "final_error")
CAP = 1 << 16  # pieces the Taylor kernel may use on one loop here


def row_of(loop, step=1.0, slope=0.0, t_end=8.0, dist=None, band=0.02):
    """A loop's parameter row, as simulate_many builds them (metrics relative to ``step``)."""
    gen = S.as_loop(loop)
    return K.param_row(gen, K.loop_matrices(gen), step=step, slope=slope, norm=step, t_end=t_end, band=band,
                       dist=dist)


def both(rows):
    """The metrics rows of the fast path and of the Taylor kernel (run directly, compiled) on the same rows."""
    pars = np.ascontiguousarray(np.atleast_2d(rows))
    fast = F.run_batch(pars, 2)
    taylor = _jit.kernel(compiled=True).run_batch(pars, CAP, 2)
    assert np.all(taylor[:, K.OUT["status"]] == K.STATUS_OK)
    assert np.all(fast[:, K.OUT["status"]] == K.STATUS_OK)
    return fast, taylor


def assert_agree(fast, taylor, loop=None, step=1.0, t_end=8.0, dist=None, tol=1e-9, slope=0.0):
    """Every metric to ``tol``, except a peak time at a tie of two maxima or a settling time at a graze of the
    band's edge (checked on the exact response of simulate, where the two answers must be equally good)."""
    o = K.OUT
    for key in KEYS:
        a, b = float(fast[o[key]]), float(taylor[o[key]])
        if math.isnan(a) and math.isnan(b):
            continue
        if not (math.isnan(a) or math.isnan(b)) and abs(a - b) <= tol * max(1.0, abs(b)):
            continue
        if key == "settling_time" and math.isnan(a) != math.isnan(b):
            # settled in one and not the other: only where the final value is on the band's edge (to rounding)
            final = 1.0 - float(taylor[o["final_error"]]) / step
            assert abs(abs(final - 1.0) - 0.02) < 1e-12, (key, a, b, final)
            continue
        assert loop is not None, (key, a, b)
        ref = Ramp(slope=slope, size=step) if slope else None  # (the rows' reference: step + slope t)
        resp = simulate(loop, step, t_end=t_end, disturbance=dist, reference=ref)
        w = lambda t: resp.output(t) / step  # noqa: E731
        if key == "peak_time":  # two maxima of (nearly) equal height (either may be a left limit at a jump)
            top = lambda t: max(float(w(t)), float(w(t - 1e-12)))  # noqa: E731
            assert abs(top(a) - top(b)) < 1e-9, (key, a, b)
        elif key == "settling_time":  # the response grazes the band's edge between the two answers
            lo, hi = sorted(x for x in (a, b) if not math.isnan(x))
            dev = np.abs(w(np.linspace(lo, hi, 2001)) - 1.0).max()
            assert abs(dev - 0.02) < 1e-6, (key, a, b, dev)
        else:
            raise AssertionError((key, a, b))
    assert fast[o["truncation"]] < 1e-15


# -- the matrix exponential it calls (delaykit's one, models/_expmkernel.py) ----------------------------------------
@pytest.mark.parametrize("n", [1, 2, 4, 7, 12, 19])
@pytest.mark.parametrize("scale", [1e-3, 0.3, 2.0, 40.0])
def test_expm_matches_scipy(n, scale):
    rng = np.random.default_rng(n * 1000 + int(scale * 10))
    A = rng.normal(size=(n, n)) * scale / math.sqrt(n)
    ref = scipy.linalg.expm(A)
    got = EK.expm(A)
    # relative to the result's size (scipy's own error grows like this for large norms too)
    assert np.max(np.abs(got - ref)) <= 1e-13 * max(1.0, np.max(np.abs(ref))) * max(1.0, scale), (n, scale)


def test_expm_closed_forms():
    t = 0.7
    rot = EK.expm(np.array([[0.0, t], [-t, 0.0]]))
    np.testing.assert_allclose(rot, [[math.cos(t), math.sin(t)], [-math.sin(t), math.cos(t)]], rtol=0, atol=5e-16)
    jordan = EK.expm(np.array([[-3.0, 1.0], [0.0, -3.0]]) * 5.0)  # exp(-15) [[1, 5], [0, 1]]
    np.testing.assert_allclose(jordan, math.exp(-15.0) * np.array([[1.0, 5.0], [0.0, 1.0]]), rtol=1e-14, atol=0)
    np.testing.assert_array_equal(EK.expm(np.zeros((3, 3))), np.eye(3))


def test_expm_of_a_loops_augmented_matrix():
    """The matrix the fast path exponentiates: a PID loop's states with the held input, the reference and its
    slope appended (a stiff derivative filter, a nilpotent tail), over a sampling interval and a long one."""
    lay = K.loop_matrices(Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.01)))
    n = lay.M.shape[0]
    Z = np.zeros((n + 3, n + 3))
    Z[:n, :n] = lay.M + np.outer(lay.bym, lay.cy)
    Z[:n, n] = lay.bw + lay.bym * lay.dy
    Z[:n, n + 1] = lay.br
    Z[n + 1, n + 2] = 1.0
    for tau in (0.013, 0.02, 3.0):
        ref = scipy.linalg.expm(Z * tau)
        assert np.max(np.abs(EK.expm(Z * tau) - ref)) <= 1e-13 * np.max(np.abs(ref))


# -- certified crossings ----------------------------------------------------------------------------------------
def _crossings(coef, target=0.0):
    c = np.zeros(25)
    c[:len(coef)] = coef
    poly = _native.load("delaykit.simulate", "_poly")  # the certified search the sampled batch calls, compiled
    xs = np.zeros(poly.MAXX)
    k = poly.crossings(c, len(coef), target, xs, np.zeros(poly.STACK), np.zeros(poly.STACK, dtype=np.int64))
    return xs[:k]


@pytest.mark.parametrize("roots, lead", [
    ((0.51, 0.52), 1.0),  # two roots inside one grid cell, the cell's ends of one sign
    ((0.02, 0.04), -1.0),  # the same in the first cell, starting from a root at 0
    ((0.0, 0.03), 1.0),  # a root at 0 (not a crossing) and one right after it
    ((0.2, 0.7, 0.71, 0.9), 1.0),
])
def test_crossings_are_certified(roots, lead):
    """The sign changes of a polynomial on (0, 1), against its roots from numpy (distinct, simple): a grid
    cell whose ends agree is opened when the bounds of f' and f'' allow a pair of roots inside it."""
    coef = lead * np.polynomial.polynomial.polyfromroots(roots)
    got = _crossings(coef)
    want = [r for r in roots if 0.0 < r < 1.0]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # a plain sign scan on the 16-cell grid sees no sign change in a cell that holds two roots
    g = np.polynomial.polynomial.polyval(np.arange(17) / 16, coef)
    if roots == (0.51, 0.52):
        assert np.all(g[8:10] > 0)


def test_a_tangency_is_resolved_to_rounding():
    """f touches 0 at 0.3 and crosses at 0.8: the crossing is found, and the touch is either left out or
    reported where it is (its sign there is rounding noise; a touch counts as reaching the level)."""
    coef = np.polynomial.polynomial.polyfromroots([0.3, 0.3, 0.8])
    got = _crossings(coef)
    assert abs(got[-1] - 0.8) < 1e-12
    assert np.all(np.abs(got[:-1] - 0.3) < 1e-6) and got.size <= 3


# -- against the Taylor kernel on random sampled loops ---------------------------------------------------------
@st.composite
def sampled_loops(draw):
    order, den, gain = draw(plant_denominators())
    kind = draw(st.sampled_from(["p", "pi", "pd", "pid", "pv-true", "pv-filtered"]))
    num = np.array([gain])
    zero = draw(st.sampled_from([None, None, "zero", "biproper"]))  # a zero; or a direct feedthrough (y jumps)
    if zero == "zero" or (zero == "biproper" and kind != "pv-true"):  # (true velocity needs a strictly proper plant)
        z0 = draw(st.floats(0.5, 4.0))
        num = gain / z0 * np.real(np.poly([-z0]))  # the same gain at s = 0
        if zero == "biproper":
            num = np.polymul(num, np.real(np.poly([-p for p in [draw(st.floats(0.5, 4.0))] * (order - 1)]))) \
                if order > 1 else num
            num = num * (0.5 if order > 1 else 1.0)
    if kind == "pv-true" and len(num) >= len(den):
        num = np.array([gain])
    kp = draw(st.floats(0.2, 2.0))
    if kind == "p":
        c = Controller.p(kp)
    elif kind == "pi":
        c = Controller.pi(kp, draw(st.floats(0.05, 1.0)))
    elif kind == "pd":
        c = Controller.pd(kp, draw(st.floats(0.0, 0.5)), draw(st.floats(0.02, 0.2)))
    elif kind == "pid":
        c = Controller.pid(kp, draw(st.floats(0.05, 1.0)), draw(st.floats(0.0, 0.5)), draw(st.floats(0.02, 0.2)))
    else:
        c = Controller.pv(kp, draw(st.floats(0.0, 0.6)), velocity=kind[3:])
    lim = draw(st.sampled_from([None, (1.0, 1.0), (0.5, 2.0), (0.3, 0.3)]))
    per = draw(st.sampled_from([0.01, 0.02, 0.05, 0.1, 0.25, 1.0, 2.0]))
    how = draw(st.sampled_from(["short", "long", "multiple", "none"]))  # the delay against the period
    if how == "short":
        ti = draw(st.floats(0.001, 0.999)) * per
    elif how == "long":
        ti = draw(st.floats(1.0, 8.0)) * per
    elif how == "multiple":
        ti = draw(st.integers(1, 6)) * per
    else:
        ti = 0.0
    ti = min(ti, 1.5)
    if 0.0 < ti < 0.004:  # (the Taylor kernel's pieces are at most twice the delay: keep its runs short)
        ti = 0.004
    off = draw(st.sampled_from([0.0, draw(st.floats(0.0, 0.99)) * per]))
    loop = Loop((num, den), c, delay=ti, umin=-lim[0] if lim else -math.inf,
                umax=lim[1] if lim else math.inf, period=per, sample_offset=off)
    step = draw(st.sampled_from([1.0, -0.5, 2.0]))
    slope = draw(st.sampled_from([0.0, 0.0, 0.05]))
    dist = draw(st.sampled_from([None, LoadStep(0.3, 2.5), LoadStep(-0.2, 4.0 + off)]))
    return loop, step, slope, dist


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=sampled_loops())
def test_random_sampled_loops_match_the_taylor_kernel(case):
    loop, step, slope, dist = case
    t_end = 8.0
    row = row_of(loop, step, slope, t_end, dist)
    fast, taylor = both(row)
    peak = taylor[0, K.OUT["peak"]]
    if not np.isfinite(peak) or abs(peak) > 1e3:
        return  # an unstable loop diverging: nothing to compare at 1e-9
    # a loop that amplifies rounding (a command chattering between its limits from sample to sample) has no
    # answer to 1e-9: the Taylor kernel itself moves when the gains move by 1e-13
    nudged = row.copy()
    nudged[K.HEAD["dvr"]] *= 1.0 + 1e-13
    nudged[K.HEAD["dvy"]] *= 1.0 + 1e-13
    again = _jit.kernel(compiled=True).run_batch(nudged[None, :], CAP, 1)[0]
    cols = [K.OUT[k] for k in KEYS]
    if np.nanmax(np.abs(again[cols] - taylor[0, cols])) > 1e-7:
        return
    assert_agree(fast[0], taylor[0], loop, step, t_end, dist, slope=slope)


def test_the_benchmark_batch_matches_the_taylor_kernel():
    """benchmarks/bench_general.py's sampled loop (PID, 20 ms, asymmetric limits) on 300 of its random draws."""
    rng = np.random.default_rng(2024)
    n = 300
    kp, td = rng.uniform(0.8, 2.0, n), rng.uniform(0.1, 0.3, n)
    loop = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2, umin=-0.5, umax=2.0,
                period=0.02)
    pars = S._sweep_rows(S.as_loop(loop), n, {"kp": kp, "delay": td, "step": np.ones(n)}, 15.0, 0.02)
    fast, taylor = both(pars)
    for i in range(n):
        assert_agree(fast[i], taylor[i], loop.replace(kp=kp[i], delay=td[i]), 1.0, 15.0)


def test_a_delay_far_shorter_than_the_period():
    """Ti = 1e-4 s against 50 ms: each sample's image follows it closely (two lengths, one tiny)."""
    loop = Loop("2/((s+1)*(0.3*s+1))", Controller.pid(1.1, 0.6, 0.1, 0.03), delay=1e-4, umin=-1.0, umax=1.0,
                period=0.05, sample_offset=0.02)
    fast, taylor = both(row_of(loop, t_end=3.0))
    assert_agree(fast[0], taylor[0], loop, 1.0, 3.0)


def test_peaks_inside_long_periods_are_found():
    """A fast plant sampled every 2 s: each period holds a whole transient (peaks, crossings and the band's
    edges inside one interval, the expansion cut into sub-pieces, and no cheap bound at all for it)."""
    loop = Loop("25/(s^2 + 4*s + 25)", Controller.pi(0.8, 0.2), delay=0.7, umin=-2.0, umax=2.0, period=2.0,
                sample_offset=0.3)
    fast, taylor = both(row_of(loop, t_end=40.0))
    o = K.OUT
    assert taylor[0, o["overshoot"]] > 1.0 and 1.0 < taylor[0, o["peak_time"]] < 2.3  # inside the first hold
    assert taylor[0, o["settling_time"]] < 40.0
    assert_agree(fast[0], taylor[0], loop, 1.0, 40.0)


# -- against the independent oracle ----------------------------------------------------------------------------
ORACLE_CASES = {
    "benchmark PID, 20 ms": (Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2, umin=-0.5,
                                  umax=2.0, period=0.02), 1.0, 10.0),
    "SOPDT PID, offset samples": (Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2,
                                       umin=-0.5, umax=2.0, period=0.05, sample_offset=0.01), 1.0, 10.0),
    "paper P, sampled": (AltitudeLoop(kp=1.31, delay=0.368, period=0.065).to_loop(), 1.0, 10.0),
    "paper PV filtered, sampled, step down": (
        AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", period=0.065).to_loop(), -0.5, 8.0),
    "PX4-like vehicle, sampled P": (Loop(plants.integrator_speed_loop(kp=4.0, ki=2.0, accel_gain=2.5),
                                         Controller.p(0.95), delay=0.12, umin=-1, umax=3, period=0.02), -1.0, 10.0),
}


@pytest.mark.parametrize("name", list(ORACLE_CASES))
def test_named_sampled_loops_match_the_oracle(name):
    """Through simulate_many (which sends these rows to the fast path) against DOP853, to 1e-6."""
    loop, step, t_end = ORACLE_CASES[name]
    pars = S._sweep_rows(S.as_loop(loop), 1, {"step": np.array([step])}, t_end, 0.02)
    assert S._event_stepped(pars).all()
    m = simulate_many(loop, step=[step], t_end=t_end)
    ref = LoopOracle(spec_for(loop, ("step", step), None, t_end)).metrics()
    assert math.isclose(m.overshoot[0], ref["overshoot"], abs_tol=1e-6), (m.overshoot[0], ref["overshoot"])
    for key in ("peak_time", "rise_time", "settling_time"):
        a, b = float(getattr(m, key)[0]), float(ref[key])
        assert (math.isnan(a) and math.isnan(b)) or abs(a - b) <= 1e-6, (key, a, b)
    assert math.isclose(m.steady_state_error[0], step * (1.0 - ref["final"]), abs_tol=1e-6)


def test_a_load_step_matches_the_oracle():
    loop = Loop("1/(s*(0.3*s+1))", Controller.pid(1.2, 0.3, 0.2, 0.05), delay=0.17, umin=-1.0, umax=1.5,
                period=0.04, sample_offset=0.015)
    dist = LoadStep(-0.4, 6.0)
    fast, taylor = both(row_of(loop, t_end=25.0, dist=dist))
    assert_agree(fast[0], taylor[0], loop, 1.0, 25.0, dist)
    ref = LoopOracle(spec_for(loop, ("step", 1.0), (dist.size, dist.time), 25.0)).metrics()
    o = K.OUT
    assert fast[0, o["settling_time"]] > 6.0  # the load knocks the output out of the band
    assert math.isclose(fast[0, o["overshoot"]], ref["overshoot"], abs_tol=1e-6)
    for key in ("peak_time", "rise_time", "settling_time"):
        assert abs(fast[0, o[key]] - ref[key]) <= 1e-6, key


# -- dispatch ----------------------------------------------------------------------------------------------------
PID_SAMPLED = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2, umin=-0.5, umax=2.0,
                   period=0.02)


@pytest.mark.parametrize("loop, eligible", [
    (PID_SAMPLED, True),
    (PID_SAMPLED.replace(delay=0.0), True),
    (PID_SAMPLED.replace(period=None), False),  # continuous: the Taylor kernel
    (PID_SAMPLED.replace(output_delay=0.1), False),
    (PID_SAMPLED.replace(controller=Controller.pid(1.5, 0.8, 0.2, 0.05, antiwindup="clamp")), False),
    (PID_SAMPLED.replace(controller=Controller.pid(1.5, 0.8, 0.2, 0.05, antiwindup="backcalc")), False),
    (Loop("1/s", Compensator.smith("1/s", 0.37, closed_loop_time=0.1), delay=0.42, umin=-1, umax=1, period=0.02),
     False),
])
def test_which_rows_take_the_fast_path(loop, eligible):
    assert bool(S._event_stepped(row_of(loop)[None, :])[0]) is eligible


@pytest.mark.parametrize("loop", [
    PID_SAMPLED.replace(controller=Controller.pid(1.5, 0.8, 0.2, 0.05, antiwindup="clamp")),
    PID_SAMPLED.replace(output_delay=0.05),
    Loop("1/s", Compensator.smith("1/s", 0.37, closed_loop_time=0.1), delay=0.42, umin=-1, umax=1, period=0.02),
])
def test_ineligible_loops_get_the_taylor_kernels_results(loop):
    kp = np.array([0.9, 1.4])
    m = simulate_many(loop, delay=np.array([0.25, 0.4]), t_end=6.0)
    pars = S._sweep_rows(S.as_loop(loop), 2, {"delay": np.array([0.25, 0.4]), "step": np.ones(2)}, 6.0, 0.02)
    assert not S._event_stepped(pars).any()
    ref = _jit.kernel(compiled=True).run_batch(pars, CAP, 1)
    np.testing.assert_array_equal(m.overshoot, ref[:, K.OUT["overshoot"]])
    np.testing.assert_array_equal(m.settling_time, ref[:, K.OUT["settling_time"]])
    assert kp.size == 2


def test_a_mixed_batch_is_split_and_put_back_in_order():
    """Sweeping the output delay through 0 puts eligible and ineligible rows in one batch: each row gets its
    own path's result, in its place."""
    to = np.array([0.0, 0.1, 0.0, 0.05])
    m = simulate_many(PID_SAMPLED, output_delay=to, t_end=8.0)
    pars = S._sweep_rows(S.as_loop(PID_SAMPLED), 4, {"output_delay": to, "step": np.ones(4)}, 8.0, 0.02)
    fast_rows = S._event_stepped(pars)
    np.testing.assert_array_equal(fast_rows, to == 0.0)
    fast = F.run_batch(np.ascontiguousarray(pars[fast_rows]), 1)
    slow = _jit.kernel(compiled=True).run_batch(np.ascontiguousarray(pars[~fast_rows]), CAP, 1)
    np.testing.assert_array_equal(m.overshoot[fast_rows], fast[:, K.OUT["overshoot"]])
    np.testing.assert_array_equal(m.overshoot[~fast_rows], slow[:, K.OUT["overshoot"]])
    # and the split agrees with the Taylor kernel on the eligible rows too
    both_fast, both_taylor = both(pars[fast_rows])
    for i in range(both_fast.shape[0]):
        assert_agree(both_fast[i], both_taylor[i], PID_SAMPLED, 1.0, 8.0)
