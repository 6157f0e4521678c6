"""Delays of any size, continuously down to the delay-free loop (issue 25).

The kernel images a breakpoint one delay later only while its smoothness order stays within the Taylor degree
(a neutral loop's, while its jump is above rounding), and past those images a piece longer than the delay
reads the delayed signal from itself (docs/guide/small-delays.md).  So the number of pieces stays bounded as
the delay shrinks, and the responses must converge to the delay-free loop's.

References, none of them delaykit's kernel: the independent DOP853 oracle (tests/oracle_loop.py) where it
runs (delays of 1e-2 s and more, and the delay-free loop where it supports it), and for tiny delays the
delay-free response with a bound proportional to the delay, whose constant is the oracle's own sensitivity
to the delay (its responses at 1e-2 s and 0).
"""

from __future__ import annotations

import numpy as np
import pytest

from delaykit import AltitudeLoop, InvalidValueError
from delaykit.models import Controller, Loop
from delaykit.simulate import _jit, simulate
from delaykit.simulate.simulation import as_loop
from oracle_loop import LoopOracle
from test_loop_simulation import spec_for

T_END = 8.0
GRID = np.linspace(0.0, T_END, 321)
TINY = [0.0] + [10.0 ** k for k in range(-12, -2)]  # 0, 1e-12 ... 1e-3 s
LARGE = [1e-2, 1e-1, 1.0]


def _loop(name: str, delay: float) -> Loop:
    if name == "p":  # the paper's loop: an integrator, P control, the command limited to 1 m/s
        return as_loop(AltitudeLoop(kp=1.31, delay=delay))
    if name == "pv":  # P and true velocity feedback: a neutral loop (the command reads y' = u(t - Td))
        return as_loop(AltitudeLoop(kp=1.31, kv=0.3, delay=delay))
    if name == "pid":  # a PID with a derivative filter on a second-order plant, with limits and clamping
        return Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05, antiwindup="clamp"), delay=delay,
                    umin=-1.2, umax=1.2)
    if name == "sampled":  # the paper's loop with its 65 ms controller period
        return as_loop(AltitudeLoop(kp=1.31, delay=delay, period=0.065))
    raise AssertionError(name)


NAMES = ["p", "pv", "pid", "sampled"]
_cache: dict = {}


def _oracle(name: str, delay: float) -> LoopOracle:
    key = (name, delay)
    if key not in _cache:
        _cache[key] = LoopOracle(spec_for(_loop(name, delay), t_end=T_END))
    return _cache[key]


def _oracle_zero(name: str) -> np.ndarray:
    """The delay-free response: the oracle's, or for the neutral PV loop (an algebraic loop the oracle does not
    take) its closed form: without delay y' = u = sat(Kp (r - y) - Kv u), so u = k (1 - y) with
    k = Kp / (1 + Kv) = 1.0077 where that is below the limit of 1 m/s: y = t up to t1 = 1 - 1 / k, then
    y = 1 - exp(-k (t - t1)) / k."""
    if name == "pv":
        k = 1.31 / 1.3
        t1 = 1.0 - 1.0 / k
        return np.where(GRID <= t1, GRID, 1.0 - np.exp(-k * (GRID - t1)) / k)
    return _oracle(name, 0.0).y(GRID)


def _large(name: str) -> list[float]:
    # the oracle evaluates a neutral loop's command by its recursion over every earlier delay: at 1e-2 s that
    # takes minutes, so the PV loop is checked from 0.1 s
    return LARGE[1:] if name == "pv" else LARGE


def _pieces_bound(name: str) -> int:
    """What a run may cost at most, whatever its delay: the delay-free run's pieces, the images of its
    breakpoints (at most DEG + 1 = 25 each, the neutral loop's until its jumps fade), and for the sampled loop
    two pieces per period (the sample and its image)."""
    base = simulate(_loop(name, 0.0), t_end=T_END).starts.size
    if name == "sampled":
        return 2 * int(T_END / 0.065) + 2 * base + 100
    return 4 * base + 200


@pytest.mark.parametrize("name", NAMES)
def test_large_delays_match_the_oracle(name):
    for delay in _large(name):
        r = simulate(_loop(name, delay), t_end=T_END)
        ref = _oracle(name, delay).y(GRID)
        np.testing.assert_allclose(r.output(GRID), ref, atol=1e-7, rtol=0, err_msg=f"{name} at {delay} s")
        assert r.truncation < 1e-12


@pytest.mark.parametrize("name", NAMES)
def test_tiny_delays_converge_to_the_delay_free_loop(name):
    # the delay-free response, checked against the oracle
    y0 = simulate(_loop(name, 0.0), t_end=T_END).output(GRID)
    np.testing.assert_allclose(y0, _oracle_zero(name), atol=1e-7, rtol=0)
    # the oracle's sensitivity to the delay: |y(Td) - y(0)| <= C Td (first order in Td: the command reaches the
    # plant Td later; a saturation switch, a sample's effect, a neutral loop's fading jumps all move by O(Td));
    # a factor 2 covers the curvature between the oracle's smallest delay and 0
    d1 = _large(name)[0]
    c = np.max(np.abs(_oracle(name, d1).y(GRID) - _oracle_zero(name))) / d1
    bound = _pieces_bound(name)
    diffs = {}
    for delay in TINY[1:]:
        r = simulate(_loop(name, delay), t_end=T_END)
        assert r.starts.size <= bound and r.u_starts.size <= bound, (name, delay, r.starts.size, bound)
        assert r.truncation < 1e-12
        diffs[delay] = float(np.max(np.abs(r.output(GRID) - y0)))
        assert diffs[delay] <= 2.0 * c * delay + 1e-13, (name, delay, diffs[delay], c)
    # and the difference does shrink in proportion to the delay (no floor from the method above rounding)
    assert 3.0 < diffs[1e-3] / diffs[1e-4] < 30.0, diffs
    assert 3.0 < diffs[1e-4] / diffs[1e-5] < 30.0, diffs


@pytest.mark.parametrize("name", ["p", "pv"])
def test_delays_below_the_time_resolution_are_the_delay_free_loop(name):
    # 64 ulp of t_end (about 1e-13 s here): the images could not be placed; the loop runs without the delay,
    # whose effect, C Td with C of order 1 (see above), is below that resolution
    y0 = simulate(_loop(name, 0.0), t_end=T_END).output(GRID)
    for delay in (1e-14, 1e-20, 5e-324):
        np.testing.assert_array_equal(simulate(_loop(name, delay), t_end=T_END).output(GRID), y0)


@pytest.mark.parametrize("name", ["p", "pv"])
def test_the_interpreted_kernel_agrees_at_tiny_delays(name):
    # the interpreted kernel runs the same source with numpy's bounds checks: the delays that read past a
    # polynomial's coefficients before (1e-11 s and below) run, and agree with the compiled kernel
    for delay in (1e-4, 1e-8, 1e-11, 1e-12):
        comp = simulate(_loop(name, delay), t_end=3.0)
        with _jit.interpreter():
            _jit._budget = float(_jit.PIECE_BUDGET)  # a fresh budget: these runs must stay interpreted
            interp = simulate(_loop(name, delay), t_end=3.0)
        assert interp.starts.size == comp.starts.size
        np.testing.assert_allclose(interp.output(GRID[:100]), comp.output(GRID[:100]), atol=1e-12, rtol=0)


def test_a_neutral_loops_jumps_stop_being_imaged_below_rounding():
    # the PV loop's command reads y' = u(t - Td): u(t) = Kp e(t) - Kv u(t - Td), so the kink where the command
    # leaves its limit comes back every delay, its derivative's jump shrinking by Kv = 0.3 each time (it never
    # smooths: a neutral loop).  At 1e-6 s the kernel stops imaging it once its jump over the delay's window is
    # below rounding: a few dozen pieces one delay long (at most 16 / log10(1 / 0.3) = 31 for the value), then
    # long pieces; the response is checked against the delay-free closed form above
    r = simulate(_loop("pv", 1e-6), t_end=T_END)
    short = int(np.sum(r.u_lengths < 2e-6))
    assert 5 <= short <= 40, short
    assert r.u_starts.size < short + 40


def test_a_huge_gain_gives_a_clear_answer_or_error():
    # Kp = 1e10 on the paper's loop (it crashed the compiled kernel): the loop is invariant under t -> t / Kp with
    # Td Kp fixed, so an answer must be the Kp = 1.31 one scaled (Td = Td(1.31) 1.31 / 1e10); or a clear error
    from delaykit.identify.estimation import EstimationError, estimate_overshoot
    ref = estimate_overshoot(2.3, kp=1.31, vmax=None).delay * 1.31
    try:
        est = estimate_overshoot(2.3, kp=1e10, vmax=None)
    except (InvalidValueError, EstimationError) as e:
        assert "\n" not in str(e) and str(e)
    else:
        assert abs(est.delay * 1e10 - ref) < 1e-6 * ref, (est.delay, ref)


@pytest.mark.parametrize("delay", [0.02, 0.005, 0.0])
def test_clean_logs_of_short_delays_are_estimated(delay):
    # a noiseless log of the paper's loop (rounded to the millimetre, as synthetic_log does) whose true delay is
    # short or zero: the trajectory estimate finds it (the fit simulates the loop at every candidate delay, down
    # to 0, which stalled before); its interval covers the truth
    from delaykit.identify.estimation import estimate_trajectory
    from delaykit.identify.flightlog import synthetic_log
    loop = AltitudeLoop(kp=1.31, delay=delay)
    est = estimate_trajectory(synthetic_log(loop, 1.0, z0=2.5, phase=0.031, t0=123.4), kp=1.31)
    assert abs(est.delay - delay) < 1e-3, est
    assert est.ci[0] - 1e-9 <= delay <= est.ci[1] + 1e-9, est


@pytest.mark.parametrize("delay", [0.37, 1e-2, 1e-6, 1e-10, 1e-12, 0.0])
def test_a_matched_smith_predictor_follows_its_closed_form_at_any_delay(delay):
    # a Smith predictor with the exact model of 2/(5 s + 1) and its delay puts the loop's response at
    # y(t) = 1 - exp(-(t - Td) / Tc) for t >= Td (0 before): the delay-free nominal loop, delayed (closed form).
    # The model delay is a second delay in the kernel (read from the piece being built when it is short); at 0
    # the command one model delay ago is the command itself (it was taken as 0 before: y settled at 0.5)
    from delaykit.models.compensators import Compensator
    tc = 0.5
    loop = Loop("2/(5*s+1)", Compensator.smith("2/(5*s+1)", delay, closed_loop_time=tc), delay=delay)
    r = simulate(loop, t_end=6.0)
    t = np.linspace(0.0, 6.0, 241)
    ref = np.where(t >= delay, 1.0 - np.exp(-(t - delay) / tc), 0.0)
    np.testing.assert_allclose(r.output(t), ref, atol=1e-9, rtol=0)
    assert r.starts.size < 100
