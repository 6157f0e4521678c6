"""Decentralised PI for square delay systems: RGA, Niederlinski index and Luyben's BLT tuning (delaykit.design.mimo).

References are computed here independently of the module (the four first-order-plus-dead-time elements of the
Wood-Berry column evaluated by hand with numpy, the ultimate points from their closed-form phase condition) or
taken from the published paper (Luyben 1986), as each test says.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from delaykit import (BLTResult, InvalidTypeError, InvalidValueError, blt, feedback, niederlinski, nyquist_count,
                      poles, rga, tf)

# Wood and Berry (1973), minutes: (gain, time constant, dead time) of each element, and the same as a system
WB = [[(12.8, 16.7, 1.0), (-18.9, 21.0, 3.0)],
      [(6.6, 10.9, 7.0), (-19.4, 14.4, 3.0)]]


def wood_berry(rows=(0, 1)):
    text = [[f"{k}*exp(-{th}*s)/({tau}*s+1)" for k, tau, th in WB[i]] for i in rows]
    return tf(text, inputs=["R", "S"], outputs=[["xD", "xB"][i] for i in rows], name="Wood-Berry")


def wb_by_hand(w):
    """G(jw) of Wood-Berry from the formulas, shaped (len(w), 2, 2)."""
    s = 1j * np.asarray(w, float)
    return np.stack([np.stack([k * np.exp(-th * s) / (tau * s + 1) for k, tau, th in row], -1) for row in WB], -2)


def fopdt_ultimate(k, tau, theta):
    """Exact ultimate gain and period of k exp(-theta s)/(tau s + 1): the phase condition theta w + atan(tau w) = pi
    solved by Brent's method, Ku = sqrt(1 + (tau w)^2) / |k|."""
    wu = brentq(lambda w: theta * w + math.atan(tau * w) - math.pi, 1e-9, math.pi / theta, xtol=1e-15)
    return math.sqrt(1 + (tau * wu) ** 2) / abs(k), 2 * math.pi / wu


@pytest.fixture(scope="module")
def wb_blt():
    return blt(wood_berry())


# ------------------------------------------------------------------------------------------ pairing measures
def test_niederlinski_and_steady_state_rga_of_wood_berry():
    # closed forms from the steady-state gains: NI = 1 - g12 g21 / (g11 g22), lambda11 = 1 / NI for two loops
    (g11, g12), (g21, g22) = [[e[0] for e in row] for row in WB]
    ni = 1 - g12 * g21 / (g11 * g22)
    lam11 = 1 / ni
    assert lam11 == pytest.approx(2.01, abs=0.005)  # the value quoted for the column (Luyben 1986, Bristol's RGA)
    G = wood_berry()
    assert niederlinski(G) == pytest.approx(ni, rel=1e-12)
    L = rga(G, [0.0])[:, :, 0]
    assert np.allclose(L, [[lam11, 1 - lam11], [1 - lam11, lam11]], rtol=1e-12, atol=0)
    # the off-diagonal pairing: the paired gains g12, g21 on the diagonal of G with its columns swapped
    ni_off = (g12 * g21 - g11 * g22) / (g12 * g21)
    assert ni_off < 0  # Niederlinski: unstable under integral control whatever the settings
    assert niederlinski(G, pairing=[1, 0]) == pytest.approx(ni_off, rel=1e-12)


def test_rga_over_frequency_matches_the_two_by_two_closed_form():
    # lambda11(jw) = 1 / (1 - G12 G21 / (G11 G22)) with each element evaluated by hand
    w = np.array([0.0, 0.01, 0.1, 0.3, 1.0, 3.0])
    g = wb_by_hand(w)
    lam11 = 1 / (1 - g[:, 0, 1] * g[:, 1, 0] / (g[:, 0, 0] * g[:, 1, 1]))
    L = rga(wood_berry(), w)
    assert L.shape == (2, 2, len(w)) and np.iscomplexobj(L)
    assert np.allclose(L[0, 0], lam11, rtol=1e-11, atol=0)
    assert np.allclose(L[1, 1], lam11, rtol=1e-11, atol=0)
    assert np.allclose(L[0, 1], 1 - lam11, rtol=1e-10, atol=1e-12)
    # rows and columns sum to one at every frequency
    assert np.allclose(L.sum(axis=0), 1, atol=1e-12) and np.allclose(L.sum(axis=1), 1, atol=1e-12)


def test_rga_of_a_triangular_system_is_the_identity():
    # a known closed form: the RGA of any (lower) triangular matrix is I, at every frequency, whatever the delays
    G = tf([["2*exp(-0.5*s)/(s+1)", "0", "0"],
            ["exp(-2*s)/(3*s+1)", "-1/(s+2)", "0"],
            ["0.5", "exp(-s)/(s^2+s+1)", "4*exp(-0.1*s)/(0.2*s+1)"]])
    L = rga(G, np.geomspace(1e-3, 1e2, 11))
    assert np.allclose(L, np.eye(3)[:, :, None], atol=1e-12)


def test_rga_refuses_a_singular_or_infinite_point():
    with pytest.raises(InvalidValueError, match="singular at w=0"):
        rga(tf([["1/(s+1)", "1/(s+1)"], ["2/(s+1)", "2/(s+1)"]]), [0.0, 1.0])
    with pytest.raises(InvalidValueError, match="infinite at w=0"):
        rga(tf([["1/s", "0"], ["0", "1"]]), [0.0])
    with pytest.raises(InvalidValueError, match="square"):
        rga(tf([["1", "2"]]), [0.0])
    with pytest.raises(InvalidTypeError, match="DelayLTI"):
        rga(np.eye(2), [0.0])


def test_niederlinski_refuses_bad_input():
    G = wood_berry()
    with pytest.raises(InvalidValueError, match="permutation"):
        niederlinski(G, pairing=[0, 0])
    with pytest.raises(InvalidValueError, match="permutation"):
        niederlinski(G, pairing=[0, 1, 2])
    with pytest.raises(InvalidValueError, match="integrator"):
        niederlinski(tf([["1/s", "0"], ["0", "1"]]))
    with pytest.raises(InvalidValueError, match="zero"):
        niederlinski(tf([["0", "1"], ["1", "1"]]))


# ------------------------------------------------------------------------------------------------- BLT
def test_ultimate_points_are_the_exact_ones(wb_blt):
    # each diagonal element's ultimate point from its closed-form phase condition (no Pade), signed as its gain
    for i in range(2):
        k, tau, th = WB[i][i]
        ku, pu = fopdt_ultimate(k, tau, th)
        assert wb_blt.ku[i] == pytest.approx(math.copysign(ku, k), rel=1e-10)
        assert wb_blt.pu[i] == pytest.approx(pu, rel=1e-10)


def test_wood_berry_against_luyben_1986(wb_blt):
    # published (Luyben 1986, Wood-Berry column): F = 2.55, Kc = 0.375 and -0.075, tau_I = 8.29 and 23.6 min.
    # Ours is exact (F = 2.5446); the paper's are rounded to the digits printed (F to 0.05 or so: 2.5446 prints
    # as 2.55 only when rounded up from a coarse search), so each is compared within half its last printed digit
    # and F within 0.3 %.
    r = wb_blt
    assert r.detuning == pytest.approx(2.55, rel=3e-3)
    assert abs(r.kp[0] - 0.375) <= 0.0005 and abs(r.kp[1] - (-0.075)) <= 0.0005
    assert abs(r.ti[0] - 8.29) <= 0.005 and abs(r.ti[1] - 23.6) <= 0.05
    # the settings are the Ziegler-Nichols ones (Ku / 2.2, Pu / 1.2) detuned by F
    assert np.allclose(np.array(r.kp) * r.detuning, np.array(r.ku) / 2.2, rtol=1e-14)
    assert np.allclose(np.array(r.ti) / r.detuning, np.array(r.pu) / 1.2, rtol=1e-14)
    assert np.allclose(r.ki, np.array(r.kp) / np.array(r.ti), rtol=1e-14)
    assert r.target_db == 4.0 and r.lcm == pytest.approx(4.0, abs=1e-8)


def test_the_biggest_log_modulus_is_the_target_by_hand(wb_blt):
    # L_cm of the returned settings from G evaluated by hand on a fine uniform grid around the peak:
    # W = -1 + det(I + G K), 20 log10 |W / (1 + W)|
    r = wb_blt
    w = np.linspace(0.005, 3.0, 300_001)
    g = wb_by_hand(w)
    k = np.array(r.kp)[None, :] * (1 + 1 / (1j * w[:, None] * np.array(r.ti)[None, :]))
    d = np.linalg.det(np.eye(2)[None] + g * k[:, None, :])
    lcm = 20 * np.log10(np.abs((d - 1) / d))
    i = int(np.argmax(lcm))
    assert lcm[i] == pytest.approx(4.0, abs=1e-6)  # the grid's spacing 1e-5 rad/min costs less than 1e-6 dB here
    assert w[i] == pytest.approx(r.frequency, abs=2e-5)
    # and F is where L_cm crosses 4 dB: 0.01 % more detuning stays below, 0.01 % less goes above (the slope is
    # about -3.5 dB per unit of F here, so that is ~9e-4 dB either side, far beyond the grid's 1e-6 dB)
    for F, sign in ((r.detuning * 1.0001, -1), (r.detuning / 1.0001, 1)):
        kp, ti = np.array(r.ku) / 2.2 / F, np.array(r.pu) / 1.2 * F
        k = kp[None, :] * (1 + 1 / (1j * w[:, None] * ti[None, :]))
        d = np.linalg.det(np.eye(2)[None] + g * k[:, None, :])
        assert sign * (20 * np.log10(np.abs((d - 1) / d)).max() - 4.0) > 0


def test_the_tuned_column_is_stable_by_its_poles_and_by_nyquist(wb_blt):
    G = wood_berry()
    K = wb_blt.controller()
    assert K.inputs == ("e[0]", "e[1]") and K.outputs == ("R", "S")
    assert wb_blt.stable is True
    assert nyquist_count(G * K).stable
    sp = poles(feedback(G * K, 1), (-0.2, 0.5, 0, 2))
    assert sp.certified and sp.roots.size > 0 and sp.roots.real.max() < -0.01
    # the controller is the PI law kp + ki / s, loop i from error i to input i
    s = 0.2j
    k = K(s)
    assert k[0, 0] == pytest.approx(wb_blt.kp[0] * (1 + 1 / (wb_blt.ti[0] * s)), rel=1e-12)
    assert k[1, 1] == pytest.approx(wb_blt.kp[1] * (1 + 1 / (wb_blt.ti[1] * s)), rel=1e-12)
    assert k[0, 1] == 0 and k[1, 0] == 0


def test_a_pairing_with_a_negative_niederlinski_index_is_reported_unstable():
    # the verdict flips: the off-diagonal pairing of Wood-Berry (NI < 0) cannot be stabilised by integral control
    G = wood_berry()
    r = blt(G, pairing=[1, 0])
    assert r.stable is False and "UNSTABLE" in repr(r)
    K = r.controller()
    assert K(0.1j)[1, 0] != 0 and K(0.1j)[0, 0] == 0  # error 0 drives input 1
    assert not nyquist_count(G * K).stable


def test_the_pairing_follows_the_outputs():
    # the column with its outputs listed the other way round, paired output 0 (xB) with input 1 (S): the same loops
    ref = blt(wood_berry(), check_stability=False)
    r = blt(wood_berry(rows=(1, 0)), pairing=[1, 0], check_stability=False)
    assert r.detuning == pytest.approx(ref.detuning, rel=1e-9)
    assert np.allclose(r.kp, ref.kp[::-1], rtol=1e-9) and np.allclose(r.ti, ref.ti[::-1], rtol=1e-9)
    assert r.stable is None and "not checked" in repr(r)


def test_one_loop_is_the_peak_of_the_complementary_sensitivity():
    # N = 1: W = G K, W / (1 + W) = T, so |T| peaks at 2 dB; T and the ultimate point computed here by hand
    k, tau, th = 2.0, 5.0, 1.5
    r = blt(tf(f"{k}*exp(-{th}*s)/({tau}*s+1)"))
    ku, pu = fopdt_ultimate(k, tau, th)
    assert r.ku[0] == pytest.approx(ku, rel=1e-10) and r.pu[0] == pytest.approx(pu, rel=1e-10)
    w = np.linspace(1e-3, 3.0, 300_001)
    L = k * np.exp(-th * 1j * w) / (tau * 1j * w + 1) * r.kp[0] * (1 + 1 / (1j * w * r.ti[0]))
    assert 20 * np.log10(np.abs(L / (1 + L)).max()) == pytest.approx(2.0, abs=1e-6)
    assert r.stable


def test_a_different_target_and_divisors():
    G = wood_berry()
    loose = blt(G, detune_target_db=10, check_stability=False)
    assert loose.lcm == pytest.approx(10, abs=1e-8) and loose.detuning < 2.5  # less detuning for a larger peak
    zn = blt(G, zn=(1 / 0.45, 1.2), check_stability=False)  # Ziegler and Nichols' own 0.45 Ku
    assert np.allclose(np.array(zn.kp) * zn.detuning, 0.45 * np.array(zn.ku), rtol=1e-14)
    # Luyben's printed settings (1986: tau_I 8.29 and 23.6 min) single out his Ku / 2.2: 0.45 Ku misses them
    assert abs(zn.ti[0] - 8.29) > 0.05 and abs(zn.ti[1] - 23.6) > 0.1


def test_result_is_json_ready_and_its_repr_one_line(wb_blt):
    d = wb_blt.to_dict()
    back = json.loads(json.dumps(d, allow_nan=False))
    assert back["detuning"] == wb_blt.detuning and back["kp"] == list(wb_blt.kp) and back["stable"] is True
    assert "\n" not in repr(wb_blt) and repr(wb_blt).startswith("BLTResult(F=2.545")
    assert isinstance(wb_blt, BLTResult)
    with pytest.raises(AttributeError):
        wb_blt.detuning = 1.0  # frozen


def test_blt_refuses_bad_input():
    G = wood_berry()
    with pytest.raises(InvalidTypeError, match="DelayLTI"):
        blt([[1, 2], [3, 4]])
    with pytest.raises(InvalidValueError, match="square"):
        blt(tf([["exp(-s)/(s+1)", "1"]]))
    with pytest.raises(InvalidValueError, match="detune_target_db"):
        blt(G, detune_target_db=0)
    with pytest.raises(InvalidValueError, match="permutation"):
        blt(G, pairing=[1, 1])
    with pytest.raises(InvalidValueError, match="zn"):
        blt(G, zn=(2.2,))
    with pytest.raises(InvalidValueError, match=r"G\[0, 0\] has no ultimate point"):
        blt(tf("2/(s+1)"))  # a first-order lag never reaches -180 degrees
    with pytest.raises(InvalidValueError, match="no steady-state gain"):
        blt(tf("s*exp(-s)/(s+1)"))


def test_the_guide_examples_run():
    # docs/guide/mimo-tuning.md shows real output: run its examples as doctests
    import doctest
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "docs" / "guide" / "mimo-tuning.md"
    res = doctest.testfile(str(path), module_relative=False,
                           optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert res.attempted >= 5 and res.failed == 0


def test_the_ultimate_point_is_the_least_gain_over_every_phase_crossover():
    # a resonance makes the second phase crossover (w ~ 12.7) the critical one, not the first (w ~ 6.1); the
    # reference is margins' list of crossovers (exact: polynomial roots, every phase crossover refined), whose least
    # gain factor is the ultimate gain (g's unity loop is unstable, so its margins themselves are nan)
    from delaykit import margins

    g = tf("exp(-0.5*s)*(1/(s+1) + 150/(s^2+0.2*s+100))")
    m = margins(g)
    assert m.method == "exact" and not m.stable
    ultimate = min((c for c in m.crossovers if c.kind == "phase"), key=lambda c: c.gain_margin)
    assert ultimate.frequency > 10
    r = blt(g, check_stability=False)
    assert r.ku[0] == pytest.approx(ultimate.gain_margin, rel=1e-10)
    assert r.pu[0] == pytest.approx(2 * math.pi / ultimate.frequency, rel=1e-10)


def test_an_integrating_element_with_a_negative_gain():
    # k exp(-theta s) / s: phase -pi/2 - theta w = -pi at wu = pi / (2 theta), Ku = wu / |k| (closed form), and the
    # controller's sign follows the gain's
    k, th = -0.5, 2.0
    r = blt(tf(f"{k}*exp(-{th}*s)/s"))
    wu = math.pi / (2 * th)
    assert r.ku[0] == pytest.approx(-wu / abs(k), rel=1e-10) and r.pu[0] == pytest.approx(2 * math.pi / wu, rel=1e-10)
    assert r.kp[0] < 0 and r.stable


def test_three_loops_reach_six_db_by_hand():
    # N = 3: the target is 2N = 6 dB; L_cm of the returned settings from the nine FOPDT elements evaluated by hand,
    # det(I + G K) of the 3x3 stack by numpy, and each ultimate point from the closed-form phase condition
    # (dead times on the diagonal only, which keeps the frequency grid, and the test, small)
    P = [[(1.0, 2.0, 1.0), (0.3, 3.0, 0.0), (-0.2, 1.0, 0.0)],
         [(0.4, 1.5, 0.0), (-2.0, 2.5, 0.5), (0.3, 2.0, 0.0)],
         [(0.2, 1.0, 0.0), (0.5, 4.0, 0.0), (1.5, 1.2, 0.8)]]
    G = tf([[f"{k}*exp(-{th}*s)/({tau}*s+1)" for k, tau, th in row] for row in P])
    r = blt(G)
    assert r.target_db == 6.0 and r.stable
    for i in range(3):
        ku, pu = fopdt_ultimate(*P[i][i])
        assert r.ku[i] == pytest.approx(math.copysign(ku, P[i][i][0]), rel=1e-10)
        assert r.pu[i] == pytest.approx(pu, rel=1e-10)
    w = np.linspace(1e-3, 20.0, 400_001)
    s = 1j * w
    g = np.stack([np.stack([k * np.exp(-th * s) / (tau * s + 1) for k, tau, th in row], -1) for row in P], -2)
    k = np.array(r.kp)[None, :] * (1 + 1 / (s[:, None] * np.array(r.ti)[None, :]))
    d = np.linalg.det(np.eye(3)[None] + g * k[:, None, :])
    lcm = 20 * np.log10(np.abs((d - 1) / d))
    assert lcm.max() == pytest.approx(6.0, abs=1e-5)
    assert w[lcm.argmax()] == pytest.approx(r.frequency, abs=1e-4)
