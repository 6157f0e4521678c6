"""Delay systems as objects (delaykit.systems): construction, algebra, conversions and the exact frequency response.

Reference values come from independent computations: python-control (when every delay is 0), the transfer
functions evaluated by hand with numpy (with the delays as exp(-j w T)), and the loop's own frequency response
(delaykit.spectrum.frequency, which uses L = N/D exp(-sT) directly, not this package).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import delaykit as dk
from delaykit import (AltitudeLoop, Controller, DelayLTI, InvalidTypeError, InvalidValueError, Loop, append, delay,
                      feedback, from_loop, interconnect, ss, summing_junction, tf)
from delaykit.spectrum import find_roots
from delaykit.systems import gain, to_control

control = pytest.importorskip("control")

W = np.concatenate([[0.0], np.geomspace(1e-3, 1e2, 61)])


def close_to(a, b, rtol=1e-12):
    """Entry-wise agreement relative to the larger of the two magnitudes (and 1e-300)."""
    a, b = np.asarray(a), np.asarray(b)
    scale = np.maximum(np.maximum(np.abs(a), np.abs(b)), 1e-300)
    return bool(np.all(np.abs(a - b) <= rtol * np.maximum(scale, 1e-3)))


def fr(sys, w=W):
    return sys.frequency_response(w).response


def cfr(csys, w=W):
    """python-control's H(jw), shaped (outputs, inputs, len(w))."""
    return np.asarray(csys(1j * np.asarray(w), squeeze=False))


# ----------------------------------------------------------------------------------------------- delay-free
def _random_tf(rng, ny, nu, order=2):
    """A random stable transfer matrix as python-control and as nested (num, den) pairs."""
    rows = []
    for _ in range(ny):
        row = []
        for _ in range(nu):
            den = np.real(np.poly(-rng.uniform(0.3, 5.0, order)))
            num = rng.normal(size=order)  # strictly proper
            row.append((num.tolist(), den.tolist()))
        rows.append(row)
    num = [[r[0] for r in row] for row in rows]
    den = [[r[1] for r in row] for row in rows]
    return control.tf(num, den), rows


def _random_ss(rng, ny, nu, n=3):
    A = rng.normal(size=(n, n)) - 4 * np.eye(n)
    B, C, D = rng.normal(size=(n, nu)), rng.normal(size=(ny, n)), 0.2 * rng.normal(size=(ny, nu))
    return control.ss(A, B, C, D), ss(A, B, C, D)


@pytest.mark.parametrize("seed", range(4))
def test_algebra_agrees_with_python_control_without_delays(seed):
    # reference: python-control's own series, parallel, feedback and append of the same state-space systems
    rng = np.random.default_rng(seed)
    cG, g = _random_ss(rng, 2, 2)
    cH, h = _random_ss(rng, 2, 2)
    assert close_to(fr(g), cfr(cG))
    assert close_to(fr(g * h), cfr(cG * cH))
    assert close_to(fr(g + h), cfr(cG + cH))
    assert close_to(fr(g - h), cfr(cG - cH))
    assert close_to(fr(-g), cfr(-cG))
    assert close_to(fr(2.5 * g), cfr(2.5 * cG))
    assert close_to(fr(feedback(g, h)), cfr(control.feedback(cG, cH)))
    assert close_to(fr(feedback(g, h, sign=1)), cfr(control.feedback(cG, cH, sign=1)))
    assert close_to(fr(feedback(g)), cfr(control.feedback(cG, np.eye(2))))
    assert close_to(fr(append(g, h)), cfr(control.append(cG, cH)))
    assert close_to(fr(g[1, 0]), cfr(cG[1, 0]))
    # a transfer matrix given as (num, den) pairs, and SISO loops of transfer functions
    cT, T = _random_tf(rng, 2, 3)
    assert close_to(fr(tf(T)), cfr(cT))
    a, b = tf(T[0][0]), tf(T[1][2])
    assert close_to(fr(feedback(a, b)), cfr(control.feedback(cT[0, 0], cT[1, 2])))


def test_ss_and_python_control_state_space_agree():
    # reference: python-control's StateSpace of the same matrices, and its feedback
    rng = np.random.default_rng(7)
    A = rng.normal(size=(3, 3)) - 3 * np.eye(3)
    B, C, D = rng.normal(size=(3, 2)), rng.normal(size=(2, 3)), rng.normal(size=(2, 2)) * 0.1
    c = control.ss(A, B, C, D)
    assert close_to(fr(ss(A, B, C, D)), cfr(c))
    assert close_to(fr(tf(c)), cfr(c))  # python-control objects are read as they are
    assert close_to(fr(feedback(ss(A, B, C, D), 0.5)), cfr(control.feedback(c, 0.5 * np.eye(2))))
    back = to_control(ss(A, B, C, D))
    assert close_to(cfr(back), cfr(c))


def test_mimo_python_control_transfer_function_is_read_entry_by_entry():
    cG, _ = _random_tf(np.random.default_rng(3), 2, 3)
    g = tf(cG)
    assert (g.noutputs, g.ninputs) == (2, 3)
    assert close_to(fr(g), cfr(cG))


# ------------------------------------------------------------------------------------------------ with delays
def test_feedback_of_fopdt_is_g_over_one_plus_g():
    # reference: G/(1+G) with G = K exp(-sT)/(tau s + 1), evaluated by numpy
    K, T, tau = 2.0, 0.7, 1.3
    s = 1j * W
    G = K * np.exp(-s * T) / (tau * s + 1)
    assert close_to(fr(feedback(tf("2*exp(-0.7*s)/(1.3*s+1)")))[0, 0], G / (1 + G))
    assert close_to(fr(feedback(tf(([K], [tau, 1.0], T)), 1, sign=1))[0, 0], G / (1 - G))


TEXTS = {  # text with internal delays -> the same expression evaluated by numpy
    "12.8*exp(-s)/(16.7*s+1) + 0.5*exp(-3*s)/(s+1)": lambda s: 12.8 * np.exp(-s) / (16.7 * s + 1)
    + 0.5 * np.exp(-3 * s) / (s + 1),
    "(1 - exp(-2*s))/(s+1)": lambda s: (1 - np.exp(-2 * s)) / (s + 1),
    "1/(1 + exp(-s)/(s+1))": lambda s: 1 / (1 + np.exp(-s) / (s + 1)),
    "2/(s+1)/(1 + 0.5*exp(-0.3*s))": lambda s: 2 / (s + 1) / (1 + 0.5 * np.exp(-0.3 * s)),
    "-exp(-s)/(s+2) - 1": lambda s: -np.exp(-s) / (s + 2) - 1,
    "exp(-s)/(s+1)*(2 + exp(-0.5*s))": lambda s: np.exp(-s) / (s + 1) * (2 + np.exp(-0.5 * s)),
    # a Smith predictor's controller C / (1 + C G0 (1 - exp(-T s))), C = 2, G0 = 1/(s+1), T = 0.37
    "2/(1 + 2/(s+1)*(1 - exp(-0.37*s)))": lambda s: 2 / (1 + 2 / (s + 1) * (1 - np.exp(-0.37 * s))),
}


@pytest.mark.parametrize("text", sorted(TEXTS))
def test_text_with_sums_and_quotients_of_delayed_terms(text):
    w = W[1:]
    assert close_to(fr(tf(text), w)[0, 0], TEXTS[text](1j * w), 1e-12)


@pytest.mark.parametrize("text, words", [
    ("exp(-s)/(s+1) + s", "improper"),
    ("1/exp(-s)", "predict"),
    ("1/(exp(-s)/(s+1))", "predict"),
    ("exp(2*s) + 1", "prediction"),
    ("foo + exp(-s)", "unknown name 'foo'"),
    ("2s + exp(-s)", "write products with"),
])
def test_bad_text_names_the_bad_part(text, words):
    with pytest.raises(InvalidValueError, match=words):
        tf(text)


def test_series_parallel_and_return_path_delays_by_hand():
    # reference: the products, sums and loops written out with numpy
    s = 1j * W
    g1 = np.exp(-s) / (s + 1)
    g2 = 2 * np.exp(-0.5 * s) / (s + 3)
    h = np.exp(-0.25 * s) / (0.1 * s + 1)
    G1, G2, Hs = tf("exp(-s)/(s+1)"), tf("2*exp(-0.5*s)/(s+3)"), tf("exp(-0.25*s)/(0.1*s+1)")
    assert close_to(fr(G1 * G2)[0, 0], g1 * g2)
    assert close_to(fr(G1 + G2)[0, 0], g1 + g2)
    assert close_to(fr(G2 - G1)[0, 0], g2 - g1)
    assert close_to(fr(1 - G1)[0, 0], 1 - g1)
    assert close_to(fr(feedback(G1 * G2, Hs))[0, 0], g1 * g2 / (1 + g1 * g2 * h))
    assert close_to(fr(G1 * delay(0.4))[0, 0], g1 * np.exp(-0.4 * s))
    # a pure delay fed back on itself is a difference equation inside (D22 != 0), still exact
    loop = feedback(delay(1.0), 0.5)
    assert not loop.is_retarded
    e = np.exp(-s)
    assert close_to(fr(loop)[0, 0], e / (1 + 0.5 * e))


WB = [["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
      ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]]


def wood_berry(s):
    """The Wood & Berry (1973) column G(s), by hand."""
    return np.array([[12.8 * np.exp(-s) / (16.7 * s + 1), -18.9 * np.exp(-3 * s) / (21 * s + 1)],
                     [6.6 * np.exp(-7 * s) / (10.9 * s + 1), -19.4 * np.exp(-3 * s) / (14.4 * s + 1)]])


def blt_pi(s):
    """Luyben's BLT decentralised PI: Kc 0.375 and -0.075, tau_I 8.29 and 23.6 min."""
    return np.diag([0.375 * (1 + 1 / (8.29 * s)), -0.075 * (1 + 1 / (23.6 * s))])


def wood_berry_closed_loop():
    G = tf(WB, inputs=["R", "S"], outputs=["xD", "xB"], name="Wood-Berry")
    K = tf([["0.375*(1 + 1/(8.29*s))", 0], [0, "-0.075*(1 + 1/(23.6*s))"]], inputs=["e1", "e2"],
           outputs=["R", "S"])
    return G, K, feedback(G * K, 1)


def test_wood_berry_under_blt_pi_against_numpy():
    # reference: (I + G K)^-1 G K with G and K evaluated by numpy at each frequency
    G, K, T = wood_berry_closed_loop()
    assert T.delays == (1.0, 3.0, 7.0, 3.0) and T.nstates == 6
    w = np.geomspace(1e-4, 10.0, 200)
    H = fr(T, w)
    for k, wk in enumerate(w):
        L = wood_berry(1j * wk) @ blt_pi(1j * wk)
        assert close_to(H[:, :, k], np.linalg.solve(np.eye(2) + L, L), 1e-11)
    # integral action: the closed loop tracks both set points at w = 0 (the LFT is singular only at true poles)
    assert close_to(T.dcgain(), np.eye(2), 1e-12)
    assert close_to(fr(G, w), np.moveaxis(np.array([wood_berry(1j * x) for x in w]), 0, -1))


def test_interconnect_by_names_equals_feedback():
    # the Wood-Berry loop by names: the same response as feedback(G K, I)
    G, K, T = wood_berry_closed_loop()
    Kn = tf([["0.375*(1 + 1/(8.29*s))", 0], [0, "-0.075*(1 + 1/(23.6*s))"]], inputs=["e1", "e2"],
            outputs=["R", "S"])
    blocks = [G, Kn, summing_junction(["r1", "-xD"], "e1"), summing_junction(["r2", "-xB"], "e2")]
    Tn = interconnect(blocks, inputs=["r1", "r2"], outputs=["xD", "xB"])
    assert Tn.inputs == ("r1", "r2") and Tn.outputs == ("xD", "xB")
    assert close_to(fr(Tn), fr(T), 1e-11)
    # indexing by name and by position agree
    assert close_to(fr(Tn["xB", "r1"]), fr(T[1, 0]))


def _fopdt_loop_by_hand(s, kp, ki, plant, Ti, To):
    C = kp + ki / s
    Gd = plant(s)
    return C * Gd * np.exp(-s * Ti) / (1 + C * Gd * np.exp(-s * (Ti + To)))


def test_loop_to_system_pi_with_input_and_output_delays():
    # reference: y/r = C G e^{-s Ti} / (1 + C G e^{-s (Ti + To)}) by numpy
    loop = Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02), delay=8.0, output_delay=4.0)
    T = from_loop(loop)
    w = np.geomspace(1e-4, 1.0, 50)
    s = 1j * w
    ref = _fopdt_loop_by_hand(s, 2.0, 0.02, lambda x: 0.62 / (150 * x + 1), 8.0, 4.0)
    assert close_to(fr(T, w)[0, 0], ref, 1e-11)


def test_altitude_loop_as_system_matches_its_frequency_response():
    # reference: delaykit.spectrum.frequency's L(jw) of the paper's P loop; with no output delay y/r = L/(1+L)
    loop = AltitudeLoop(kp=1.31, delay=0.368, vmax=None)
    w = np.geomspace(1e-2, 1e2, 80)
    T = from_loop(loop)
    assert close_to(fr(T, w)[0, 0], dk.frequency_response(loop, w).complementary, 1e-12)
    # the PV loop: its characteristic roots are the loop's own (AltitudeLoop.characteristic, written by hand)
    pv = AltitudeLoop(kp=2.0, kv=0.3, delay=0.37, vmax=None)
    region = (-10, 2, 0, 60)
    mine = find_roots(from_loop(pv).characteristic(), region).roots
    theirs = find_roots(pv.characteristic(), region).roots
    assert mine.size == theirs.size > 0 and np.allclose(np.sort_complex(mine), np.sort_complex(theirs), atol=1e-9)


@pytest.mark.parametrize("make", [
    lambda: dk.Compensator.predictor("1/s", 0.37, closed_loop_time=0.5),
    lambda: dk.Compensator.smith("0.62/(150*s+1)", 12.0, closed_loop_time=40.0),
    lambda: dk.Compensator.filtered_smith("1/s", 0.37, closed_loop_time=0.5),
])
def test_loop_with_a_compensator_as_system(make):
    # reference: delaykit.spectrum.compensated's L(jw) (the compensator closed around its own command, broken at
    # the plant input); the load disturbance reaches the output as y/d = G / (1 + L)
    from delaykit.spectrum.compensated import compensated_response

    c = make()
    plant = "1/s" if c.model.order == 1 and c.model.integrators else "0.62/(150*s+1)"
    loop = Loop(plant, c, delay=c.model_delay)
    T = from_loop(loop)
    w = np.geomspace(0.01, 10.0, 40) / (1.0 if plant == "1/s" else 30.0)
    L = compensated_response(loop, w).L
    G = loop.plant(1j * w)
    assert close_to(fr(T["y", "d"], w)[0, 0], G / (1 + L), 1e-10)


def test_to_control_pade_matches_python_control_pade():
    # reference: python-control's own product with control.pade(T, n)
    g = tf("2*exp(-0.8*s)/(s+1)")
    c = to_control(g, pade_order=6)
    num, den = control.pade(0.8, 6)
    ref = control.tf([2.0], [1.0, 1.0]) * control.tf(num, den)
    assert close_to(cfr(c), cfr(ref), 1e-10)
    # MIMO: the Wood-Berry loop, high-order Pade, agrees with the exact response where w T is small
    _, _, T = wood_berry_closed_loop()
    cT = to_control(T, pade_order=10)
    w = np.geomspace(1e-3, 0.3, 30)
    assert close_to(cfr(cT, w), fr(T, w), 1e-7)


def test_a_numpy_matrix_times_a_system_is_a_gain():
    G = tf(WB)
    M = np.array([[1.0, 2.0], [0.0, -1.0]])
    assert isinstance(M * G, DelayLTI) and isinstance(G * M, DelayLTI)
    s = 1j * W[1:]
    ref = np.array([M @ wood_berry(x) for x in s])
    assert close_to(fr(M * G, W[1:]), np.moveaxis(ref, 0, -1))


def test_names_repr_and_to_dict():
    g = tf("12.8*exp(-s)/(16.7*s+1)", inputs="R", outputs="xD", name="G11")
    assert repr(g) == "DelayLTI(G11: 1 input ['R'] -> 1 output ['xD'], 1 state, delays [1] s)"
    again = DelayLTI(**g.to_dict())
    assert close_to(fr(again), fr(g), 0.0) and again.inputs == ("R",)
    with pytest.raises(AttributeError):
        g.delays = (2.0,)  # frozen
    assert "neutral" in repr(feedback(delay(1.0), 0.5))
    renamed = tf(feedback(tf(WB), 1), inputs=["r1", "r2"], name="T")  # a MIMO system renamed
    assert renamed.inputs == ("r1", "r2") and renamed.outputs == ("y[0]", "y[1]") and renamed.name == "T"


# --------------------------------------------------------------------------------------------------- errors
@pytest.mark.parametrize("make, kind, words", [
    (lambda: delay(-1.0), InvalidValueError, "delay"),
    (lambda: delay(math.inf), InvalidValueError, "delay"),
    (lambda: tf("exp(2*s)/(s+1)"), InvalidValueError, "prediction"),
    (lambda: tf(([1.0], [1.0, 1.0], -0.5)), InvalidValueError, "delay"),
    (lambda: DelayLTI(D12=[[1.0]], D21=[[1.0]], D11=[[0.0]], delays=[math.nan]), InvalidValueError, "delay 0"),
    (lambda: DelayLTI(D12=[[1.0]], D21=[[1.0]], D11=[[0.0]], delays=["1"]), InvalidTypeError, "delay 0"),
    (lambda: DelayLTI(A=[[1.0, 0.0]]), InvalidValueError, "square"),
    (lambda: DelayLTI(A=[[-1.0]], B1=[[1.0]], C1=[[1.0, 2.0]]), InvalidValueError, "C1"),
    (lambda: tf(WB) * tf("1/(s+1)") * tf(WB[0:1]), InvalidValueError, "sizes"),
    (lambda: tf(WB) + tf([["1", "2", "3"]]), InvalidValueError, "inputs"),
    (lambda: feedback(tf("1"), 1, sign=1), InvalidValueError, "not well posed"),
    (lambda: feedback(tf("1/(s+1)"), 1, sign=2), InvalidValueError, "sign"),
    (lambda: tf([["1/(s+1)", "1"], ["1"]]), InvalidValueError, "rows"),
    (lambda: tf({"a": 1}), InvalidTypeError, "expected"),
    (lambda: tf("1/(s+1)") * "2", InvalidTypeError, "text"),
    (lambda: tf(WB)[2, 0], InvalidValueError, "out of range"),
    (lambda: tf(WB)["x", 0], InvalidValueError, "no output named"),
    (lambda: tf(WB)[0], InvalidTypeError, "sys[outputs, inputs]"),
    (lambda: tf("1/s", inputs=["a", "b"]), InvalidValueError, "inputs"),
    (lambda: to_control(tf("exp(-s)/(s+1)")), InvalidValueError, "pade_order"),
    (lambda: to_control(tf("exp(-s)/(s+1)"), pade_order=0), InvalidValueError, "pade_order"),
    (lambda: from_loop(Loop("1/(s+1)", Controller.pi(1.0, 1.0, antiwindup="clamp"), umax=1.0)), InvalidValueError,
     "clamping"),
    (lambda: to_control(dk.saturation(-1, 1)), InvalidValueError, "saturate"),
    (lambda: dk.c2d(dk.saturation(-1, 1) * tf("1/(s+1)"), 0.1), InvalidValueError, "saturate"),
    (lambda: dk.saturation(1, 2), InvalidValueError, "lower <= 0 <= upper"),
    (lambda: DelayLTI(D12=[[1.0]], D21=[[1.0]], D11=[[0.0]], delays=[1.0], limits=[(-1, 1), (-1, 1)]),
     InvalidValueError, "one per channel"),
    (lambda: from_loop(Loop("1/s", Controller.p(1.0), period=0.1)), InvalidValueError, "samples"),
    (lambda: from_loop("1/s"), InvalidTypeError, "Loop"),
    (lambda: tf("1/(s+1)").frequency_response([-1.0]), InvalidValueError, ">= 0"),
    (lambda: summing_junction("r", "e"), InvalidTypeError, "list"),
])
def test_bad_input_gives_a_clear_delaykit_error(make, kind, words):
    with pytest.raises(kind, match=words):
        make()


def test_interconnect_errors_name_the_signal():
    G = tf("1/(s+1)", inputs="u", outputs="y")
    with pytest.raises(InvalidValueError, match="'e'.*connected to nothing"):
        interconnect([G, tf("2", inputs="e", outputs="u")], inputs=["r"], outputs=["y"])
    with pytest.raises(InvalidValueError, match=r"\['y'\].*more than one block"):
        interconnect([G, tf("2", inputs="u", outputs="y")], inputs=["u"], outputs=["y"])
    with pytest.raises(InvalidValueError, match="'z' is no block's output"):
        interconnect([G], inputs=["u"], outputs=["z"])
    with pytest.raises(InvalidValueError, match=r"\['q'\] feed no block"):
        interconnect([G], inputs=["u", "q"], outputs=["y"])
    # a static algebraic loop with gain 1 around it is not well posed
    with pytest.raises(InvalidValueError, match="not well posed"):
        interconnect([tf("1", inputs="a", outputs="b"), tf("1", inputs="b", outputs="a"), gain(1.0)[0, 0]],
                     inputs=["u[0]"], outputs=["a"])


def test_saturated_loop_records_its_limits_and_is_linear_inside_them():
    # the limits become a saturation channel; the linear analyses are those of the loop without them
    loop = AltitudeLoop(kp=1.31, delay=0.368)  # vmax = 1
    T = from_loop(loop)
    assert T.saturations == (0,) and T.limits[0] == (-1.0, 1.0) and "1 saturation" in repr(T) and T.is_retarded
    w = np.geomspace(1e-2, 10, 20)
    assert close_to(fr(T, w)[0, 0], dk.frequency_response(loop, w).complementary, 1e-12)
    linear = from_loop(loop, ignore_limits=True)
    assert not linear.saturations and close_to(fr(linear, w), fr(T, w), 1e-13)
    again = DelayLTI(**T.to_dict())  # JSON-ready limits (None for no limit) read back
    assert again.limits == T.limits
    assert T.without_limits().saturations == ()


def test_back_calculation_anti_windup_cancels_inside_the_limits():
    # reference: the PI loop by hand; the anti-windup term Baw (u - v) is zero while u = v
    loop = Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02, antiwindup="backcalc"), delay=8.0, output_delay=4.0,
                umin=-50, umax=50)
    T = from_loop(loop)
    assert T.saturations and T.nstates == 2
    w = np.geomspace(1e-4, 1.0, 40)
    ref = _fopdt_loop_by_hand(1j * w, 2.0, 0.02, lambda x: 0.62 / (150 * x + 1), 8.0, 4.0)
    assert close_to(fr(T, w)[0, 0], ref, 1e-11)


# ----------------------------------------------------------------------------- random interconnections
@st.composite
def delayed_blocks(draw, ny, nu, delays):
    """A ny x nu transfer matrix of first-order (or integrating) entries with some of ``delays`` on them,
    as text for tf and as a numpy function of s."""
    entries, funcs = [], []
    for i in range(ny):
        row, frow = [], []
        for j in range(nu):
            k = draw(st.floats(-2.0, 2.0).filter(lambda x: abs(x) > 0.05))
            a = draw(st.floats(0.2, 5.0))
            T = draw(st.sampled_from(delays + [0.0]))
            integ = draw(st.booleans()) and draw(st.booleans())
            den = "s" if integ else f"({a!r}*s+1)"
            row.append(f"{k!r}*exp(-{T!r}*s)/{den}")
            frow.append((k, a, T, integ))
        entries.append(row)
        funcs.append(frow)

    def f(s):
        return np.array([[k * np.exp(-T * s) / (s if integ else a * s + 1) for (k, a, T, integ) in r] for r in funcs])

    return entries, f


@st.composite
def interconnections(draw):
    ny = draw(st.integers(1, 3))
    nu = draw(st.integers(1, 3))
    nd = draw(st.integers(1, 4))
    delays = [draw(st.floats(0.01, 3.0)) for _ in range(nd)]
    G = draw(delayed_blocks(ny, nu, delays))
    K = draw(delayed_blocks(nu, ny, delays))
    H = draw(delayed_blocks(ny, nu, delays))
    return G, K, H


@settings(max_examples=40, deadline=None)
@given(interconnections())
def test_random_interconnections_against_direct_evaluation(blocks):
    # reference: the same products, sums and loops of the numpy-evaluated matrices at each frequency
    (G, g), (K, k), (H, h) = blocks
    sG, sK, sH = tf(G), tf(K), tf(H)
    loop = sG * sK
    T = feedback(loop, 1)
    S = sG + sH
    w = np.geomspace(0.05, 20.0, 9)
    rT, rS, rL = fr(T, w), fr(S, w), fr(loop, w)
    for i, x in enumerate(w):
        s = 1j * x
        Lm = g(s) @ k(s)
        M = np.eye(Lm.shape[0]) + Lm
        if np.linalg.cond(M) > 1e8:
            continue  # the closed loop has a pole near this frequency
        assert close_to(rL[:, :, i], Lm, 1e-10)
        assert close_to(rS[:, :, i], g(s) + h(s), 1e-10)
        assert close_to(rT[:, :, i], np.linalg.solve(M, Lm), 1e-8)
    # the same loop by names, one summing junction per channel, equals feedback(G K, I)
    ny = sG.noutputs
    ys, us, es, rs = ([f"{c}{i}" for i in range(n)] for c, n in (("y", ny), ("u", sG.ninputs), ("e", ny), ("r", ny)))
    blocks = [tf(sG, inputs=us, outputs=ys), tf(sK, inputs=es, outputs=us)]
    blocks += [summing_junction([rs[i], "-" + ys[i]], es[i]) for i in range(ny)]
    Tn = interconnect(blocks, inputs=rs, outputs=ys)
    ok = np.array([np.linalg.cond(np.eye(ny) + g(1j * x) @ k(1j * x)) < 1e8 for x in w])
    assert close_to(fr(Tn, w)[:, :, ok], rT[:, :, ok], 1e-8)


def test_the_guide_examples_run():
    # docs/guide/systems.md shows real output: run its examples as doctests
    import doctest
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "docs" / "guide" / "systems.md"
    res = doctest.testfile(str(path), module_relative=False,
                           optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert res.attempted > 10 and res.failed == 0


# ------------------------------------------------------------------------------------ zero-order hold
def _discrete_step(d, j, n):
    """The response of a DiscreteLTI to a unit step on input j, n samples (iterated by hand)."""
    x = np.zeros(d.A.shape[0])
    out = []
    for _ in range(n):
        out.append(d.C @ x + d.D[:, j])
        x = d.A @ x + d.B[:, j]
    return np.array(out).T


@pytest.mark.parametrize("h", [0.1, 0.3, 0.7, 1.0])
def test_c2d_wood_berry_steps_are_the_sampled_closed_forms(h):
    # a held step into K e^{-sT}/(tau s + 1) is K (1 - exp(-(t - T)/tau)) for t >= T: exact at every sample,
    # fractional delays (T/h not an integer) included
    d = dk.c2d(tf(WB), h)
    k = np.arange(60)
    t = k * h
    params = [[(12.8, 1, 16.7), (-18.9, 3, 21.0)], [(6.6, 7, 10.9), (-19.4, 3, 14.4)]]
    for j in range(2):
        y = _discrete_step(d, j, k.size)
        for i in range(2):
            K, T, tau = params[i][j]
            ref = np.where(t >= T, K * (1 - np.exp(-np.maximum(t - T, 0) / tau)), 0.0)
            assert np.max(np.abs(y[i] - ref)) <= 1e-12 * abs(K)


def test_c2d_without_delays_matches_python_control():
    # reference: python-control's own zero-order-hold c2d of the same state-space system
    rng = np.random.default_rng(5)
    c, g = _random_ss(rng, 2, 2)
    d = dk.c2d(g, 0.2)
    ref = control.c2d(c, 0.2, method="zoh")
    w = np.linspace(0.0, math.pi / 0.2, 40)
    assert close_to(d.frequency_response(w).response, np.asarray(ref(np.exp(1j * w * 0.2), squeeze=False)), 1e-11)
    assert d.to_control().dt == 0.2


def test_c2d_of_a_delayed_feedthrough_and_its_errors():
    # 2 e^{-0.25 s} sampled every 0.1 s: the output is the input of 3 samples ago (u held, read at t = k h)
    d = dk.c2d(tf("2*exp(-0.25*s)"), 0.1)
    y = _discrete_step(d, 0, 6)[0]
    assert y.tolist() == [0.0, 0.0, 0.0, 2.0, 2.0, 2.0]
    with pytest.raises(InvalidValueError, match="inside a loop"):
        dk.c2d(feedback(tf("exp(-s)/(s+1)")), 0.1)
    with pytest.raises(InvalidValueError, match="period"):
        dk.c2d(tf("1/(s+1)"), 0.0)


@pytest.mark.parametrize("D, N", [(2.3, 3), (0.7, 1), (4.5, 4), (6.0, 2)])
def test_thiran_filter_is_all_pass_with_group_delay_d_at_dc(D, N):
    # Thiran (1971): maximally flat group delay, exactly D periods at w = 0, and |H| = 1
    from delaykit.systems.discrete import thiran_coefficients as thiran

    num, den = thiran(D, N)
    w = np.array([1e-5, 0.3, 1.0, 2.5])
    H = np.polyval(num, np.exp(1j * w)) / np.polyval(den, np.exp(1j * w))
    assert np.allclose(np.abs(H), 1.0, atol=1e-13)
    assert abs(-np.angle(H[0]) / w[0] - D) < 1e-8
    assert np.all(np.abs(np.roots(den)) < 1)  # stable, D > N - 1


def test_c2d_thiran_is_exact_for_whole_periods_and_converges_for_internal_delays():
    # delays that are whole periods on the inputs: the approximation is the exact discretisation
    G = tf(WB)
    w = np.linspace(0.01, math.pi / 0.5, 30)
    exact = dk.c2d(G, 0.5).frequency_response(w).response
    approx = dk.c2d(G, 0.5, thiran_order=3).frequency_response(w).response
    assert close_to(approx, exact, 1e-10)
    # a delay inside a loop: the error against the exact continuous response falls with the period (first order)
    T = feedback(tf("2*exp(-0.7*s)/(1.3*s+1)"), 1)
    w = np.array([0.01, 0.3, 1.0])
    ref = fr(T, w)[0, 0]
    errs = [np.max(np.abs(dk.c2d(T, h, thiran_order=3).frequency_response(w).response[0, 0] - ref))
            for h in (0.1, 0.025)]
    assert errs[1] < errs[0] / 3 and errs[1] < 0.01
    with pytest.raises(InvalidValueError, match="thiran_order"):
        dk.c2d(T, 0.1, thiran_order=-1)


@pytest.mark.parametrize("loop, region", [
    (AltitudeLoop(kp=2.0, kv=0.3, delay=0.37, velocity="filtered", vmax=None), (-10, 2, 0, 60)),
    (Loop("1/(s*(0.05*s+1))", Controller.pid(2.0, 0.5, 0.1, 0.02), delay=0.3, output_delay=0.1), (-10, 2, 0, 60)),
    (Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02), delay=8.0, output_delay=4.0), (-0.5, 0.1, 0, 3)),
], ids=["filtered-pv", "pid", "pi"])
def test_loop_as_system_has_the_loops_characteristic_roots(loop, region):
    # reference: the loop's own characteristic quasi-polynomial (Loop.characteristic, from the controller's
    # feedback polynomials), its roots by the same certified finder
    mine = find_roots(from_loop(loop).characteristic(), region)
    theirs = find_roots(loop.characteristic(), region)
    assert mine.certified and theirs.certified and mine.roots.size == theirs.roots.size > 0
    assert np.allclose(np.sort_complex(mine.roots), np.sort_complex(theirs.roots), atol=1e-9)


def test_frequencies_as_text_or_complex_are_refused_not_converted():
    # as_frequencies is the one check of frequencies (the loop analysis's too): "2" was read as 2 rad/s before
    from delaykit.errors import InvalidTypeError
    from delaykit.systems.lti import as_frequencies

    g = tf("1/(s+1)")
    for bad in ("2", ["1", "2"], [1j]):
        with pytest.raises(InvalidTypeError, match="w must be"):
            g.frequency_response(bad)
    assert as_frequencies([0, 2]).tolist() == [0.0, 2.0]
