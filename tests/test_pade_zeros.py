"""Padé and Thiran approximations as functions, discrete delays absorbed, and the zeros of delay systems (issue 33).

Every reference is independent of the code under test: Padé coefficients from the Taylor series of exp(-x) by
scipy's ``pade`` and from python-control's ``pade``; the Padé error against its known leading term; Thiran's
filter against its closed forms for orders 1 and 2 (Laakso et al. 1996) and a delay's group delay from the phase;
zeros against closed forms and python-control's ``zeros`` (and scipy's generalized eigenvalues) at zero delay.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.interpolate
import scipy.linalg

import delaykit as dk
from delaykit import InvalidTypeError, InvalidValueError, delay, feedback, tf
from delaykit.systems.discrete import DiscreteLTI, thiran_coefficients
from delaykit.models.interop import pade_coefficients

control = pytest.importorskip("control")


# -- Padé --------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("T, n", [(1.0, 1), (0.368, 2), (2.5, 3), (7.0, 5), (0.01, 6)])
def test_pade_coefficients_match_the_taylor_series_and_python_control(T, n):
    # reference 1: scipy.interpolate.pade of the Taylor series of exp(-x), x = T s
    p, q = scipy.interpolate.pade([(-1.0) ** k / math.factorial(k) for k in range(2 * n + 1)], n)
    num, den = pade_coefficients(T, n)
    # p(x)/q(x) in x = T s: the coefficient of s^k is that of x^k times T^k; compare after making den monic
    k = np.arange(n + 1)
    pn, qn = p.coeffs[::-1] * T ** k, q.coeffs[::-1] * T ** k          # ascending powers of s
    pn, qn = pn / qn[-1], qn / qn[-1]
    assert np.allclose(num[::-1], pn, rtol=1e-9, atol=0)
    assert np.allclose(den[::-1], qn, rtol=1e-9, atol=0)
    # reference 2: python-control's pade, whose normalisation (monic denominator) these follow
    cn, cd = control.pade(T, n)
    assert np.allclose(num, cn, rtol=1e-12, atol=0) and np.allclose(den, cd, rtol=1e-12, atol=0)


def test_pade_error_falls_with_the_order_and_follows_its_leading_term():
    # the (n, n) Padé approximant of exp(-x) errs by x^(2n+1) (n!)^2 / ((2n)! (2n+1)!) + O(x^(2n+2)) (Baker and
    # Graves-Morris, Padé Approximants, eq. 1.2.7's remainder); on the imaginary axis |error| is that at x = w T
    T, x = 1.0, 0.1
    for n in (1, 2, 3):
        lead = x ** (2 * n + 1) * math.factorial(n) ** 2 / (math.factorial(2 * n) * math.factorial(2 * n + 1))
        e = dk.pade_error(delay(T), n, [x / T]).max_error
        assert abs(e / lead - 1) < 0.01
    w = np.linspace(0.05, 2.0, 40)
    errs = [dk.pade_error(tf("exp(-s)/(s+1)"), n, w).max_error for n in range(1, 6)]
    assert all(b < a / 5 for a, b in zip(errs, errs[1:]))


def test_pade_of_a_system_matches_python_control_through_to_control():
    # the rational part times control.pade's block, built by python-control alone
    G = tf("2*exp(-0.7*s)/(1.3*s+1)")
    ref = control.tf([2.0], [1.3, 1.0]) * control.tf(*control.pade(0.7, 4))
    w = np.array([0.0, 0.1, 1.0, 3.0])
    ours = dk.pade(G, 4).frequency_response(w).response[0, 0]
    assert np.allclose(ours, ref(1j * w), rtol=1e-12, atol=1e-14)
    pc = G.to_control(pade_order=4)
    assert np.allclose(pc(1j * w).ravel(), ref(1j * w), rtol=1e-12, atol=1e-14)


def test_pade_of_an_internal_delay_converges_to_the_certified_poles():
    # a delay inside a loop: the approximation's eigenvalues approach the exact rightmost pole (certified root
    # finder) as the order grows
    T = feedback(tf("exp(-0.5*s)/s"), 1)
    r = dk.poles(T).rightmost
    gaps = [float(np.min(np.abs(np.linalg.eigvals(dk.pade(T, n).A) - r))) for n in (1, 2, 3, 4)]
    assert all(b < a for a, b in zip(gaps, gaps[1:])) and gaps[-1] < 1e-5
    P = dk.pade(T, 3)
    assert P.ndelays == 0 and P.nstates == 4 and P.inputs == T.inputs


def test_pade_of_a_number_and_of_a_mimo_system():
    # exp(-0.5 s) ~ (4 - s)/(4 + s): the first-order approximant in closed form
    h = dk.pade(0.5, 1).frequency_response([2.0]).response[0, 0, 0]
    assert abs(h - (4 - 2j) / (4 + 2j)) < 1e-15
    assert dk.pade(0.0, 3).nstates == 0
    WB = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
             ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]])
    e = dk.pade_error(WB, 6, np.linspace(0.0, 0.3, 20))
    assert e.max_error < 1e-3 and e.order == 6
    assert np.allclose(dk.pade(WB, 2).dcgain(), WB.dcgain(), atol=1e-12)


def test_pade_error_of_a_loop_is_that_of_its_open_loop():
    loop = dk.AltitudeLoop(kp=1.31, delay=0.368)
    from delaykit.models.interop import pade_error as loop_error

    w = [0.5, 1.31, 3.0]
    assert dk.pade_error(loop, 3, w).max_error == loop_error(loop, 3, w).max_error


def test_pade_bad_input_is_named():
    with pytest.raises(InvalidValueError, match="order must be an integer from 1 to 40, got 0"):
        dk.pade(tf("exp(-s)/(s+1)"), 0)
    with pytest.raises(InvalidValueError, match="got 1.5"):
        dk.pade(1.0, 1.5)
    with pytest.raises(InvalidValueError, match="delay T"):
        dk.pade(-1.0, 2)
    with pytest.raises(InvalidTypeError, match="DelayLTI or a delay"):
        dk.pade("exp(-s)", 2)
    with pytest.raises(InvalidValueError, match="saturate"):
        dk.pade(tf("1/(s+1)") * dk.saturation(-1, 1), 2)
    with pytest.raises(InvalidTypeError, match="pade_error takes"):
        dk.pade_error([1.0], 2, [1.0])
    with pytest.raises(InvalidValueError, match="w >= 0"):
        dk.pade_error(delay(1.0), 2, [-1.0])
    with pytest.raises(InvalidValueError, match="imaginary axis"):
        dk.pade_error(tf("exp(-s)/s"), 2, [0.0, 1.0])


# -- Thiran and discrete delays ----------------------------------------------------------------------------------

@pytest.mark.parametrize("D", [0.3, 1.5, 2.75])
def test_thiran_coefficients_follow_the_closed_forms_of_orders_1_and_2(D):
    # Laakso, Välimäki, Karjalainen and Laine, "Splitting the unit delay", IEEE SP Magazine 13(1), 1996, table 1:
    # N = 1: a1 = -(D - 1)/(D + 1); N = 2: a1 = -2 (D - 2)/(D + 1), a2 = (D - 1)(D - 2)/((D + 1)(D + 2))
    _, den1 = thiran_coefficients(D, 1)
    assert np.allclose(den1, [1.0, -(D - 1) / (D + 1)], rtol=1e-14)
    if D > 1:
        _, den2 = thiran_coefficients(D, 2)
        assert np.allclose(den2, [1.0, -2 * (D - 2) / (D + 1), (D - 1) * (D - 2) / ((D + 1) * (D + 2))], rtol=1e-14)


@pytest.mark.parametrize("tau, h, N", [(0.25, 0.1, 2), (0.037, 0.01, 3), (0.5, 0.2, 1), (0.03, 0.1, 1)])
def test_thiran_is_all_pass_with_the_delay_as_dc_group_delay_and_maximally_flat(tau, h, N):
    F = dk.thiran(tau, h, N)
    assert isinstance(F, DiscreteLTI) and F.period == h
    w = np.array([1e-4, 1e-3]) / h
    H = F.frequency_response(np.concatenate([w, [0.3 / h, 2.0 / h]])).response[0, 0]
    assert np.allclose(np.abs(H), 1.0, atol=1e-12)                      # all-pass
    gd = -np.unwrap(np.angle(H[:2])) / w                                   # phase delay ~ group delay at w -> 0
    assert np.allclose(gd, tau, rtol=1e-6)
    # maximally flat: the phase delay departs from tau by O((w h)^(2N)), far below first order at w h = 0.3
    assert abs(-np.angle(H[2]) / (0.3 / h) - tau) / tau < 0.3 ** 2
    assert np.all(np.abs(np.linalg.eigvals(F.A)) < 1) if F.A.size else True


def test_thiran_of_whole_periods_is_the_exact_shift_and_c2d_uses_it():
    F = dk.thiran(0.3, 0.1, 2)            # 3 whole periods: z^-3 exactly
    w = np.array([0.5, 7.0, 25.0])
    assert np.allclose(F.frequency_response(w).response[0, 0], np.exp(-1j * w * 0.3), atol=1e-13)
    # c2d with thiran_order on a pure delay is the Thiran filter (the delay-free part sampled is a unit gain)
    d = dk.c2d(delay(0.37), 0.1, thiran_order=3)
    assert np.allclose(d.frequency_response(w).response, dk.thiran(0.37, 0.1, 3).frequency_response(w).response,
                       atol=1e-13)


def test_thiran_bad_input_is_named():
    with pytest.raises(InvalidValueError, match="more than 2 periods"):
        dk.thiran(0.15, 0.1, 3)
    with pytest.raises(InvalidValueError, match="from 0 to 10"):
        dk.thiran(1.0, 0.1, -1)
    with pytest.raises(InvalidValueError, match="period"):
        dk.thiran(1.0, 0.0, 1)


def test_absorb_delay_keeps_the_response_and_converts_to_python_control():
    rng = np.random.default_rng(3)
    A = np.diag([0.5, -0.3])
    B, C, D = rng.normal(size=(2, 2)), rng.normal(size=(2, 2)), rng.normal(size=(2, 2))
    g = DiscreteLTI(A, B, C, D, 0.2, ("a", "b"), ("y", "z"), input_delay=(2, 0), output_delay=(1, 3))
    w = np.array([0.0, 1.0, 4.0, 10.0])
    z = np.exp(1j * w * 0.2)
    # the closed form: z^-d_out,i (C (zI - A)^-1 B + D)_ij z^-d_in,j
    ref = np.stack([np.diag(zk ** -np.array([1.0, 3.0])) @ (C @ np.linalg.solve(zk * np.eye(2) - A, B) + D)
                    @ np.diag(zk ** -np.array([2.0, 0.0])) for zk in z], axis=-1)
    assert np.allclose(g.frequency_response(w).response, ref, atol=1e-12)
    a = dk.absorb_delay(g)
    assert a.input_delay == () and a.output_delay == () and a.A.shape == (2 + 2 + 4, 2 + 2 + 4)
    assert np.allclose(a.frequency_response(w).response, ref, atol=1e-12)
    pc = g.to_control()
    assert pc.dt == 0.2 and np.allclose(np.moveaxis(pc(z), -1, -1), ref, atol=1e-12)
    assert dk.absorb_delay(a) is a
    with pytest.raises(InvalidValueError, match="input_delay must be 2 whole numbers"):
        DiscreteLTI(A, B, C, D, 0.2, ("a", "b"), ("y", "z"), input_delay=(1,))
    with pytest.raises(InvalidTypeError, match="absorb_delay takes a DiscreteLTI"):
        dk.absorb_delay(tf("1/(s+1)"))


# -- zeros -------------------------------------------------------------------------------------------------------

def test_zeros_of_a_rational_part_times_a_delay():
    G = tf("(s-1)*exp(-s)/(s+2)^2")
    sp = dk.zeros(G)
    assert sp.certified and sp.roots.size == 1 and abs(sp.roots[0] - 1.0) < 1e-12
    assert not dk.is_minimum_phase(G) and not G.is_minimum_phase()
    assert dk.is_minimum_phase(tf("(s+1)*exp(-s)/(s+2)^2"))     # the delay itself is not counted as a zero
    assert dk.is_minimum_phase(delay(2.0)) and dk.zeros(delay(2.0)).roots.size == 0
    assert G.zeros((-3, 3, -1, 1)).roots.size == 1


def test_zeros_of_a_delayed_numerator_are_its_closed_form_chain():
    # (1 - 0.5 exp(-s))/(s+1): zeros where exp(-s) = 2, s = -ln 2 + 2 pi k i
    G = tf("(1 - 0.5*exp(-s))/(s+1)")
    sp = dk.zeros(G, (-2, 1, -20, 20))
    ref = -math.log(2) + 2j * math.pi * np.arange(-3, 4)
    assert sp.certified and sp.roots.size == ref.size
    assert np.allclose(sorted(sp.roots, key=lambda z: z.imag), ref, atol=1e-10)
    assert dk.is_minimum_phase(G)
    # 1 - 2 exp(-s): the chain at Re s = ln 2, right of the axis
    assert not dk.is_minimum_phase(tf("(1 - 2*exp(-s))/(s+1)"))
    with pytest.raises(InvalidValueError, match="give a region"):
        dk.zeros(G)


def test_zeros_of_delay_free_systems_match_python_control():
    G = tf("(s^2 + 3*s - 4)/(s^3 + 2*s^2 + 3*s + 1)")
    ref = np.roots([1, 3, -4])
    assert np.allclose(np.sort_complex(dk.zeros(G, (-6, 3, -1, 1)).roots), np.sort_complex(ref), atol=1e-10)
    A = np.array([[-1.0, 0.5, 0.0], [0.0, -2.0, 1.0], [0.3, 0.0, -3.0]])
    B = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    C = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 2.0]])
    D = np.array([[0.0, 0.0], [0.0, 0.0]])
    S = dk.ss(A, B, C, D)
    ref = control.zeros(control.ss(A, B, C, D))
    # and scipy's generalized eigenvalues of the system matrix pencil (finite ones)
    M = np.block([[A, B], [-C, -D]])
    N = np.block([[np.eye(3), np.zeros((3, 2))], [np.zeros((2, 5))]])
    ev = scipy.linalg.eigvals(M, N)
    ev = ev[np.isfinite(ev)]
    assert np.allclose(np.sort_complex(ref), np.sort_complex(ev), atol=1e-9)
    got = dk.zeros(S, (-10, 10, -10, 10))
    assert got.certified and np.allclose(np.sort_complex(got.roots), np.sort_complex(ref), atol=1e-9)
    assert dk.is_minimum_phase(S) == bool(np.all(ref.real < 0))


def test_mimo_zeros_with_delays():
    # det H = 2/((s+1)(s+3)) - exp(-s)/(s+1)^2: zeros where 2 (s+1) = (s+3) exp(-s) (one real, in (0, 1)), and the
    # entry-by-entry realisation's repeated mode s = -1 (an invariant zero of the non-minimal realisation)
    G = tf([["1/(s+1)", "exp(-s)/(s+1)"], ["1/(s+1)", "2/(s+3)"]])
    import scipy.optimize

    r = scipy.optimize.brentq(lambda s: 2 * (s + 1) - (s + 3) * math.exp(-s), 0.0, 1.0, xtol=1e-15)
    sp = dk.zeros(G, (-3, 2, -1, 1))
    assert sp.certified
    assert np.min(np.abs(sp.roots - r)) < 1e-10 and np.min(np.abs(sp.roots + 1)) < 1e-8
    assert not dk.is_minimum_phase(G)


def test_zeros_bad_input_is_named():
    with pytest.raises(InvalidValueError, match="square"):
        dk.zeros(tf([["1/(s+1)", "1/(s+2)"]]))
    with pytest.raises(InvalidValueError, match="singular for every s"):
        dk.zeros(tf([["1/(s+1)", "1/(s+1)"], ["1/(s+1)", "1/(s+1)"]]))
    with pytest.raises(InvalidValueError, match="singular for every s"):      # rank 1 with delays: g v^T
        dk.zeros(tf([["1/(s+1)", "exp(-s)/(s+1)"], ["exp(-s)/(s+1)", "exp(-2*s)/(s+1)"]]))
    with pytest.raises(InvalidTypeError, match="DelayLTI"):
        dk.zeros("s+1")
    with pytest.raises(InvalidValueError, match="advanced"):
        dk.zeros(tf("(1 + s*exp(-s))/(s^2+s+1)"))
    assert not dk.is_minimum_phase(tf("(1 + s*exp(-s))/(s^2+s+1)"))


def test_pade_of_chosen_channels_keeps_the_others_exact():
    # the first entry exact, the second approximated: the response is exp(-jw)/(jw+1) and the Padé of exp(-2 s)
    # over (s+1), each in closed form
    G = tf([["exp(-s)/(s+1)", "exp(-2*s)/(s+1)"]])
    P = dk.pade(G, 3, channels=1)
    assert P.delays == (1.0,)
    w = np.array([0.3, 1.0, 2.0])
    num, den = control.pade(2.0, 3)
    H = P.frequency_response(w).response[0]
    assert np.allclose(H[0], np.exp(-1j * w) / (1j * w + 1), atol=1e-14)
    assert np.allclose(H[1], np.polyval(num, 1j * w) / np.polyval(den, 1j * w) / (1j * w + 1), atol=1e-13)
    assert dk.pade(G, 3, channels=[]).delays == G.delays
    with pytest.raises(InvalidValueError, match="channel 2 is out of range"):
        dk.pade(G, 3, channels=[2])
    with pytest.raises(InvalidTypeError, match="indices"):
        dk.pade(G, 3, channels=["a"])
