"""Poles, stability, H-infinity norm, Nyquist count and loop-at-a-time margins of delay systems.

References: Lambert W (the roots of s + exp(-sT) are W_k(-T)/T), the delay margin pi/2 of 1/s, python-control's
eigenvalues of a delay-free closed loop, the determinant of the block matrix evaluated directly, a brute-force
frequency grid 50 times finer, the second-order resonance peak in closed form, and delaykit.spectrum.frequency's
margins of the same SISO loop (its own method: L = N/D exp(-sT)).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.special import lambertw

import delaykit as dk
from delaykit import (Controller, InvalidValueError, Loop, delay, feedback, hinfnorm, is_stable, loop_margins,
                      nyquist_count, poles, tf)
from delaykit.spectrum import find_roots, rightmost, root_bound

control = pytest.importorskip("control")

WB = [["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
      ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]]
BLT = [["0.375*(1 + 1/(8.29*s))", 0], [0, "-0.075*(1 + 1/(23.6*s))"]]


def test_poles_of_a_delayed_integrator_loop_are_lambert_w():
    # s + exp(-sT) = 0  <=>  s = W_k(-T) / T
    T = 0.5
    sp = feedback(tf(f"exp(-{T}*s)/s"), 1).poles((-6, 1, 0, 40))
    assert sp.certified
    ref = [complex(lambertw(-T, k)) / T for k in range(0, 12)]
    ref = [r for r in ref if -6 <= r.real <= 1 and 0 <= r.imag <= 40]
    assert len(ref) == sp.roots.size
    for r in ref:
        assert np.min(np.abs(sp.roots - r)) < 1e-9 * abs(r)


@pytest.mark.parametrize("T, stable", [(1.5, True), (1.6, False)])
def test_is_stable_flips_at_the_delay_margin_of_an_integrator(T, stable):
    # 1/s under unity feedback loses stability at T = pi/2 = 1.5708
    L = tf(f"exp(-{T}*s)/s")
    assert is_stable(feedback(L, 1)) is stable
    assert nyquist_count(L).stable is stable  # the frequency-domain count agrees


def test_poles_without_delays_are_python_controls_eigenvalues():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(4, 4)) - np.eye(4)
    B, C = rng.normal(size=(4, 2)), rng.normal(size=(2, 4))
    T = feedback(dk.ss(A, B, C), 0.7)
    ref = np.sort_complex(control.feedback(control.ss(A, B, C, 0), 0.7 * np.eye(2)).poles())
    R = 2 * np.max(np.abs(ref)) + 1
    sp = T.poles((-R, R, -R, R))
    assert sp.certified and sp.roots.size + int(np.sum(sp.roots.imag > 0)) >= 1
    got = np.sort_complex(np.repeat(sp.roots, sp.multiplicities))
    assert got.size == ref.size and np.allclose(got, ref, atol=1e-8 * R)


def test_characteristic_function_equals_the_block_determinant():
    # several incommensurate delays: det([[sI - A, -B2 E], [-C2, I - D22 E]]) computed directly
    G = tf(WB)
    T = feedback(G * tf(BLT), 1)
    q = T.characteristic()
    assert q.kind == "retarded" and len(q.delays) >= 4
    rng = np.random.default_rng(0)
    for s in rng.normal(size=6) * 0.3 + 1j * rng.normal(size=6):
        E = np.exp(-s * np.array(T.delays))
        M = np.block([[s * np.eye(T.nstates) - T.A, -T.B2 * E], [-T.C2, np.eye(T.ndelays) - T.D22 * E]])
        d = np.linalg.det(M)
        assert abs(q(s) - d) <= 1e-10 * max(abs(d), 1e-6)


def test_characteristic_function_of_a_stiff_system():
    # time scales from 0.01 to 100 s^-1 around a delayed loop: still the block determinant to 1e-11
    A = np.diag(-np.array([1e-2, 1e-1, 1.0, 10.0, 100.0]))
    T = feedback(dk.ss(A, np.ones((5, 1)), np.ones((1, 5))) * delay(0.3), 0.5)
    q = T.characteristic()
    for s in (0.01j, 0.5 + 0.2j, 50j, -0.02 + 0.001j, -3 + 7j):
        E = np.exp(-s * np.array(T.delays))
        d = np.linalg.det(np.block([[s * np.eye(5) - T.A, -T.B2 * E], [-T.C2, np.eye(1) - T.D22 * E]]))
        assert abs(q(s) - d) <= 1e-11 * abs(d)


def test_wood_berry_blt_loop_is_stable_and_five_times_the_gains_is_not():
    # Luyben's BLT settings are detuned for stability; the certified root finder and the Nyquist count agree
    G, K = tf(WB), tf(BLT)
    assert is_stable(feedback(G * K, 1))
    assert nyquist_count(G * K).stable
    # five times the BLT gains: unstable, with 4 roots right of the axis by the certified count below
    K3 = tf([["1.875*(1 + 1/(8.29*s))", 0], [0, "-0.375*(1 + 1/(23.6*s))"]])
    T3 = feedback(G * K3, 1)
    nq = nyquist_count(G * K3)
    assert not is_stable(T3)
    # the Nyquist count equals the number of closed-loop roots right of the axis (certified count)
    q = T3.characteristic()
    R = root_bound(q, 0.0)
    sp = find_roots(q, (nq.sigma, R + 1, -(R + 1), R + 1))
    assert sp.certified and nq.closed_loop_unstable == int(sp.multiplicities.sum()) > 0


def test_hinfnorm_of_a_resonance_is_the_closed_form_peak():
    zeta = 0.1
    value, w = hinfnorm(tf(f"1/(s^2+{2 * zeta}*s+1)"))
    assert abs(value - 1 / (2 * zeta * math.sqrt(1 - zeta ** 2))) < 1e-9
    assert abs(w - math.sqrt(1 - 2 * zeta ** 2)) < 1e-5


def test_hinfnorm_of_delayed_loops_against_a_finer_grid():
    # reference: the max over a uniform grid (a different grid, far denser than the ripple of the delays needs)
    _, _, T = None, None, feedback(tf(WB) * tf(BLT), 1)
    h = hinfnorm(T)
    w = np.linspace(1e-4, 3.0, 60_000)
    brute = float(np.max(T.frequency_response(w).singular_values()[0]))
    assert h.stable and brute <= h.value * (1 + 1e-9) and h.value <= brute * (1 + 1e-6)
    assert abs(T.singular_values([h.frequency])[0, 0] - h.value) <= 1e-12 * h.value
    # the sensitivity of the FOPDT loop: a peak and then the ripple of the delay towards |S| -> 1
    S = feedback(1, tf("2*exp(-0.7*s)/(1.3*s+1)"))
    hs = hinfnorm(S)
    w = np.linspace(1e-4, 60.0, 120_000)
    brute = float(np.max(np.abs(S.frequency_response(w).response[0, 0])))
    assert brute <= hs.value * (1 + 1e-9) and hs.value <= brute * (1 + 1e-6)


def test_hinfnorm_finds_a_sharp_resonance_of_the_delay_loop():
    # 1/s with a delay of 1.55 s, just inside its delay margin pi/2: a peak of width ~0.01 rad/s near w = 1;
    # reference: the max over 200001 points across it
    T = feedback(tf("exp(-1.55*s)/s"), 1)
    h = hinfnorm(T)
    w = np.linspace(0.95, 1.07, 200_001)
    brute = float(np.max(np.abs(T.frequency_response(w).response[0, 0])))
    assert brute > 50 and brute <= h.value * (1 + 1e-9) and h.value <= brute * (1 + 1e-7)


def test_hinfnorm_high_frequency_limit_and_unstable():
    # 1 - 0.5 exp(-s): sup |1 - 0.5 e^{-jwT}| = 1.5, reached only as a limit of the ripple
    value, w = hinfnorm(1 - 0.5 * delay(1.0))
    assert abs(value - 1.5) < 1e-9
    h = hinfnorm(tf("1/(s-1)"))
    assert h.value == math.inf and not h.stable and h.frequency is None
    assert "unstable" in repr(h)


def test_loop_margins_of_a_siso_loop_match_the_loop_margins():
    # reference: delaykit.spectrum.frequency.margins of the same loop (its own exact N/D exp(-sT) method)
    loop = Loop("0.62/(150*s+1)", Controller.pi(6.0, 0.05), delay=12.0)
    ref = dk.margins(loop)
    L = tf("6*(1 + 0.05/(6*s))") * tf("0.62*exp(-12*s)/(150*s+1)")
    m = loop_margins(L)
    assert abs(m.gain_margin - ref.gain_margin) <= 1e-9 * ref.gain_margin
    assert abs(m.phase_margin - ref.phase_margin) <= 1e-7
    assert abs(m.delay_margin - ref.delay_margin) <= 1e-8 * ref.delay_margin
    assert abs(m.gain_crossover - ref.crossover) <= 1e-9 * ref.crossover


def test_gain_margin_is_where_the_certified_stability_flips():
    # an altitude P loop around a PI speed loop with two delays: the closed loop is stable just below
    # Kp * gain_margin and unstable just above (two independent methods: the Nyquist curve and the roots)
    blocks = [tf("1/(0.3*s+1)", inputs="a", outputs="v"), tf("2*(1 + 1/(0.5*s))", inputs="ev", outputs="a_req"),
              delay(0.05, inputs="a_req", outputs="a"), tf("1/s", inputs="v", outputs="z"),
              delay(0.1, inputs="z", outputs="zm"), dk.summing_junction(["v_ref", "-v"], "ev")]
    inner = dk.interconnect(blocks, inputs=["v_ref"], outputs=["zm"])
    m = loop_margins(1.2 * inner)
    k = 1.2 * m.gain_margin
    assert is_stable(feedback((k * (1 - 1e-4)) * inner, 1))
    assert not is_stable(feedback((k * (1 + 1e-4)) * inner, 1))


def test_loop_at_a_time_margins_of_wood_berry():
    # loop 1 broken, loop 2 closed: L1 = g11 k1 - g12 k1 g21 k2 / (1 + g22 k2) by hand, at the crossovers found
    m = loop_margins(tf(WB) * tf(BLT), channel=0)

    def L1(w):
        s = 1j * w
        g11, g12 = 12.8 * np.exp(-s) / (16.7 * s + 1), -18.9 * np.exp(-3 * s) / (21 * s + 1)
        g21, g22 = 6.6 * np.exp(-7 * s) / (10.9 * s + 1), -19.4 * np.exp(-3 * s) / (14.4 * s + 1)
        k1, k2 = 0.375 * (1 + 1 / (8.29 * s)), -0.075 * (1 + 1 / (23.6 * s))
        return g11 * k1 - g12 * k1 * g21 * k2 / (1 + g22 * k2)

    assert m.gain_crossover is not None and abs(abs(L1(m.gain_crossover)) - 1) < 1e-9
    assert abs(180 + math.degrees(np.angle(L1(m.gain_crossover))) - m.phase_margin) < 1e-6
    assert m.phase_crossover is not None and abs(L1(m.phase_crossover).imag) < 1e-9 * abs(L1(m.phase_crossover))
    assert abs(1 / abs(L1(m.phase_crossover)) - m.gain_margin) < 1e-8 * m.gain_margin
    assert m.gain_margin > 1 and m.phase_margin > 0  # the BLT loop is stable


def test_spectrum_errors():
    neutral = feedback(delay(1.0), 1.5)  # 1 + 1.5 e^{-s}: roots on Re s = ln 1.5 > 0
    with pytest.raises(InvalidValueError, match="neutral and its difference operator is not strongly stable"):
        is_stable(neutral)
    with pytest.raises(InvalidValueError, match="square"):
        nyquist_count(tf([["1/(s+1)", "1/(s+2)"]]))
    with pytest.raises(InvalidValueError, match="delayed direct feedthrough"):
        nyquist_count(tf("2*exp(-s)"))
    with pytest.raises(InvalidValueError, match="channel"):
        loop_margins(tf(WB), channel=2)
    with pytest.raises(dk.InvalidTypeError, match="DelayLTI"):
        poles("1/(s+1)", (-1, 1, -1, 1))


@st.composite
def random_loops(draw):
    """A 1x1 or 2x2 loop L = G K: first-order or integrating entries with 1 to 4 delays, a static or PI K."""
    n = draw(st.integers(1, 2))
    delays = [draw(st.floats(0.05, 2.0)) for _ in range(draw(st.integers(1, 4)))]
    rows = []
    for _ in range(n):
        row = []
        for _ in range(n):
            k = draw(st.floats(0.2, 3.0)) * draw(st.sampled_from([1, -1]))
            T = draw(st.sampled_from(delays))
            den = "s" if draw(st.integers(0, 3)) == 0 else f"({draw(st.floats(0.2, 5.0))!r}*s+1)"
            row.append(f"{k!r}*exp(-{T!r}*s)/{den}")
        rows.append(row)
    kp = [draw(st.floats(0.05, 1.0)) for _ in range(n)]
    ki = [draw(st.sampled_from([0.0, 0.1, 0.5])) for _ in range(n)]
    K = [[f"{kp[i]!r} + {ki[i]!r}/s" if (i == j and ki[i]) else (kp[i] if i == j else 0) for j in range(n)]
         for i in range(n)]
    return tf(rows) * tf(K)


@settings(max_examples=15, deadline=None)
@given(random_loops())
def test_nyquist_count_agrees_with_the_certified_roots(L):
    # two independent methods: the winding of det(I + L(jw)) against the argument-principle root count of the
    # closed loop's characteristic quasi-polynomial
    T = feedback(L, 1)
    q = T.characteristic()
    rm = rightmost(q)
    assume(rm.certified and abs(rm.abscissa) > 1e-3)  # a root on the axis is a matter of tolerance
    nq = nyquist_count(L)
    assert nq.stable is rm.stable
    R = root_bound(q, -1e-3)
    sp = find_roots(q, (-1e-3, 2 * R + 1, -(R + 1), R + 1))
    # a mode hidden from L (say two integrators where one output sees their sum) stays a root at 0 within rounding
    assume(sp.certified and not np.any((np.abs(sp.roots.real) > 1e-10) & (np.abs(sp.roots.real) < 1e-4)))
    assert nq.closed_loop_unstable == int(sp.multiplicities[sp.roots.real > 1e-4].sum())
