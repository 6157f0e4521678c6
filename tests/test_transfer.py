"""TransferFunction: parsing against hand expansions, evaluation against the text itself, realisations against
SciPy and python-control, and the refusals of bad input."""

from __future__ import annotations

import cmath
import dataclasses
import json
import math
import sys

import numpy as np
import pytest
import scipy.signal
from hypothesis import example, given
from hypothesis import strategies as st

from delaykit.errors import InvalidTypeError, InvalidValueError, MissingDependencyError
from delaykit.models.transfer import MAX_ORDER, TransferFunction

POINTS = [0.3 + 2.1j, -0.7 + 0.4j, 1.5, 5j, -3.2 - 11j]

# text, the function written with its raw (unnormalised) coefficients, the normalised coefficients the parser
# must produce, and the delay.  The normalised ones are expanded by hand in the comments.
EXAMPLES = {
    # s (0.05 s + 1) = 0.05 s^2 + s; divided by 0.05: s^2 + 20 s, and 1 / 0.05 = 20
    "1/(s*(0.05*s+1))": (([1], [0.05, 1, 0]), ([20.0], [1.0, 20.0, 0.0]), 0.0),
    # divided by 150
    "0.62/(150*s+1)": (([0.62], [150, 1]), ([0.62 / 150], [1.0, 1 / 150]), 0.0),
    # (s + 1)(0.5 s + 1) = 0.5 s^2 + 1.5 s + 1; divided by 0.5: s^2 + 3 s + 2, and 1 / 0.5 = 2
    "1/((s+1)*(0.5*s+1))": (([1], [0.5, 1.5, 1]), ([2.0], [1.0, 3.0, 2.0]), 0.0),
    # a polynomial over 1 (improper: read with proper=False)
    "4*s+2": (([4, 2], [1]), ([4.0, 2.0], [1.0]), 0.0),
    # common factor (s + 2) kept, not cancelled
    "(s+2)/(s**2+3*s+2)": (([1, 2], [1, 3, 2]), ([1.0, 2.0], [1.0, 3.0, 2.0]), 0.0),
    "1/s": (([1], [1, 0]), ([1.0], [1.0, 0.0]), 0.0),
    "2": (([2], [1]), ([2.0], [1.0]), 0.0),
    # divided by 0.02: 50 s / (s + 50)
    "s/(0.02*s+1)": (([1, 0], [0.02, 1]), ([50.0, 0.0], [1.0, 50.0]), 0.0),
    # 2 * 0.7 * 3 = 4.2
    "1/(s^2 + 2*0.7*3*s + 9)": (([1], [1, 4.2, 9]), ([1.0], [1.0, 4.2, 9.0]), 0.0),
    # the rational part is 0.62/(150 s + 1) as above, the delay 12
    "0.62*exp(-12*s)/(150*s+1)": (([0.62], [150, 1]), ([0.62 / 150], [1.0, 1 / 150]), 12.0),
}
PROPER = [t for t in EXAMPLES if t != "4*s+2"]
RATIONAL = [t for t in PROPER if "exp" not in t]


def oracle(text, s):
    """The text evaluated by Python itself at the point s (the independent reference)."""
    return complex(eval(text.replace("^", "**"), {"__builtins__": {}}, {"s": s, "exp": cmath.exp}))


def ss_response(A, B, C, D, s):
    """C (sI - A)^-1 B + D for a SISO realisation with any vector/matrix shapes."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    D = complex(np.asarray(D).reshape(()))
    n = np.asarray(B).size
    if n == 0:
        return D
    x = np.linalg.solve(s * np.eye(n) - A.reshape(n, n), np.asarray(B, dtype=float).reshape(n))
    return complex(np.asarray(C, dtype=float).reshape(n) @ x) + D


def monic(num, den):
    """Coefficients with leading zeros stripped and divided by the leading denominator coefficient."""
    num, den = np.trim_zeros(np.asarray(num, float), "f"), np.trim_zeros(np.asarray(den, float), "f")
    return (num if num.size else np.zeros(1)) / den[0], den / den[0]


def assert_coeffs(g, num, den, rtol=1e-12):
    assert g.num.shape == np.shape(num) and g.den.shape == np.shape(den), (g, num, den)
    np.testing.assert_allclose(g.num, num, rtol=rtol, atol=rtol * np.max(np.abs(num)))
    np.testing.assert_allclose(g.den, den, rtol=rtol, atol=rtol * np.max(np.abs(den)))


# ------------------------------------------------------------------------------------------------- parsing
@pytest.mark.parametrize("text", list(EXAMPLES))
def test_parsed_coefficients_match_the_hand_expansion(text):
    _, (num, den), delay = EXAMPLES[text]
    g, tau = TransferFunction.parse_with_delay(text, proper=False)
    assert_coeffs(g, num, den, rtol=1e-14)
    assert tau == delay
    if text in RATIONAL:
        assert TransferFunction.parse(text) == g


@pytest.mark.parametrize("text", list(EXAMPLES))
def test_raw_coefficients_normalise_to_the_parsed_function(text):
    (raw_num, raw_den), (num, den), _ = EXAMPLES[text]
    assert_coeffs(TransferFunction(raw_num, raw_den, proper=False), num, den, rtol=1e-14)


def test_repr_and_to_string():
    g = TransferFunction.parse("1/(s*(0.05*s+1))")  # an integrator: the text's coefficients, products expanded
    assert repr(g) == "TransferFunction(1/(0.05 s^2 + s))"
    assert g.to_string() == "1/(0.05*s^2 + s)" and TransferFunction.parse(g.to_string()) == g
    assert repr(TransferFunction(g.num, g.den)) == "TransferFunction(20/(s^2 + 20 s))"  # coefficients: monic
    k = TransferFunction.parse("20/(s^2+20*s)")  # the same plant written monic: printed monic, equal to g
    assert repr(k) == "TransferFunction(20/(s^2 + 20 s))" and k == g and hash(k) == hash(g)
    assert g.num.tolist() == [20.0] and g.den.tolist() == [1.0, 20.0, 0.0]  # stored normalised
    i = TransferFunction.parse("2.5/(4*s^2)")  # a double integrator with a scale: as written
    assert repr(i) == "TransferFunction(2.5/(4 s^2))" and i == TransferFunction([0.625], [1, 0, 0])
    assert TransferFunction.parse(i.to_string()) == i  # 2.5/(4*s^2) reads back; 2.5/4*s^2 would be 0.625 s^2
    h = TransferFunction.parse("0.6976/(146.6*s+1)")  # a gain and a time constant: as written
    assert repr(h) == "TransferFunction(0.6976/(146.6 s + 1))" and TransferFunction.parse(h.to_string()) == h
    assert repr(TransferFunction(h.num, h.den)) == "TransferFunction(0.00475853/(s + 0.00682128))"
    assert TransferFunction([-1, 0, -2.5], [1, 0, 0, 3]).to_string() == "(-s^2 - 2.5)/(s^3 + 3)"
    assert TransferFunction([1, 0], [1, 2, 0]).to_string() == "s/(s^2 + 2*s)"
    assert TransferFunction([3], [1, 0, 0]).to_string() == "3/s^2"
    assert TransferFunction([0], [1, 1]).to_string() == "0/(s + 1)"
    assert TransferFunction([0.1], [1, 1]).to_string(digits=17) == "0.10000000000000001/(s + 1)"


def test_operator_forms_and_constant_exponents():
    g = TransferFunction.parse("(s + 1)^(4/2) / (+(s^3) - -2*s^2 + (1*s))^1")  # (s^2 + 2 s + 1)/(s^3 + 2 s^2 + s)
    assert_coeffs(g, [1.0, 2.0, 1.0], [1.0, 2.0, 1.0, 0.0])
    assert TransferFunction.parse("1/(s+1)^12").order == MAX_ORDER == 12
    assert TransferFunction.parse("(s+3)**0/(s+1)") == TransferFunction([1], [1, 1])
    # a sum over a common denominator is kept over it (no product of equal denominators)
    assert TransferFunction.parse("1/(s+1) + 2/(s+1)") == TransferFunction([3], [1, 1])
    assert_coeffs(TransferFunction.parse("1/(s+1) - 1/(s+2)"), [1.0], [1.0, 3.0, 2.0])  # (s+2-(s+1))/((s+1)(s+2))


# ---------------------------------------------------------------------------------------------- evaluation
@pytest.mark.parametrize("text", list(EXAMPLES))
def test_evaluation_matches_the_text_evaluated_by_python(text):
    g, tau = TransferFunction.parse_with_delay(text, proper=False)
    values = g(np.array(POINTS).reshape(1, -1))
    assert values.shape == (1, len(POINTS))
    for s, v in zip(POINTS, values[0]):
        want = oracle(text, s)
        got = g(s)
        assert isinstance(got, complex)
        assert abs(got * cmath.exp(-tau * s) - want) <= 1e-12 * abs(want)
        assert v == got


def test_evaluation_at_a_pole_is_not_finite_and_bad_points_are_refused():
    g = TransferFunction.parse("1/(s*(s+1))")
    assert not cmath.isfinite(g(0.0))
    with pytest.raises(InvalidTypeError, match="evaluated at numbers"):
        g("1j")


# ------------------------------------------------------------------------------------------- realisations
@pytest.mark.parametrize("text", RATIONAL)
def test_state_space_realises_the_function(text):
    g = TransferFunction.parse(text)
    A, B, C, D = g.state_space()
    n = g.order
    assert A.shape == (n, n) and B.shape == (n,) and C.shape == (n,) and isinstance(D, float)
    rng = np.random.default_rng(7)
    for s in rng.normal(size=6) + 4j * rng.normal(size=6):
        assert abs(ss_response(A, B, C, D, s) - g(s)) <= 1e-11 * max(1.0, abs(g(s)))
    # SciPy realises the raw coefficients in the same controllable canonical form
    (raw_num, raw_den), _, _ = EXAMPLES[text]
    As, Bs, Cs, Ds = scipy.signal.tf2ss(raw_num, raw_den)
    if n:
        np.testing.assert_allclose(A, As, rtol=1e-12)
        np.testing.assert_allclose(B, Bs.ravel())
        np.testing.assert_allclose(C, Cs.ravel(), rtol=1e-12, atol=1e-12)
    assert D == pytest.approx(Ds.item(), rel=1e-12)
    for s in POINTS:
        assert abs(ss_response(As, Bs, Cs, Ds, s) - oracle(text, s)) <= 1e-10 * abs(oracle(text, s))


@pytest.mark.parametrize("text", [t for t in RATIONAL if t != "2"])
def test_state_space_agrees_with_python_control(text):
    control = pytest.importorskip("control")
    (raw_num, raw_den), _, _ = EXAMPLES[text]
    ref = control.tf2ss(control.tf(raw_num, raw_den))
    A, B, C, D = TransferFunction.parse(text).state_space()
    for s in POINTS:
        assert abs(ss_response(A, B, C, D, s) - complex(ref(s))) <= 1e-10 * abs(complex(ref(s)))


@pytest.mark.parametrize("text", RATIONAL)
def test_from_state_space_round_trip(text):
    g = TransferFunction.parse(text)
    back = TransferFunction.from_state_space(*g.state_space())
    assert_coeffs(back, g.num, g.den, rtol=1e-9)
    assert back.relative_degree == g.relative_degree


def test_from_state_space_of_a_random_system_matches_the_resolvent_and_scipy():
    rng = np.random.default_rng(3)
    A, B, C, D = rng.normal(size=(4, 4)), rng.normal(size=(4, 1)), rng.normal(size=(1, 4)), np.array([[0.7]])
    g = TransferFunction.from_state_space(A, B, C, D)
    assert g.order == 4 and g.relative_degree == 0
    for s in POINTS:
        assert abs(g(s) - ss_response(A, B, C, D, s)) <= 1e-10 * abs(ss_response(A, B, C, D, s))
    num, den = scipy.signal.ss2tf(A, B, C, D)
    assert_coeffs(g, *monic(num[0], den), rtol=1e-9)
    # a double integrator: C B = 0 exactly gives an exact relative degree 2
    double = TransferFunction.from_state_space([[0, 1], [0, 0]], [[0], [1]], [[1, 0]], 0)
    assert double == TransferFunction([1], [1, 0, 0])
    assert TransferFunction.from_state_space(np.zeros((0, 0)), np.zeros(0), np.zeros(0), 3.0) == TransferFunction(3, 1)


@pytest.mark.parametrize("A, B, C, D, pattern", [
    ([[1, 2, 3]], [1], [1], 0, r"A must be a square matrix, got shape \(1, 3\)"),
    ([[1, 0], [0, 1]], [1, 2, 3], [1, 1], 0, r"B must have shape \(2,\) or \(2, 1\) \(one input\), got \(3,\)"),
    ([[1, 0], [0, 1]], [[1, 0], [0, 1]], [1, 1], 0, r"B must have shape .* got \(2, 2\)"),
    ([[1, 0], [0, 1]], [1, 1], [[1, 1], [1, 1]], 0, r"C must have shape .* got \(2, 2\)"),
    ([[1, 0], [0, 1]], [1, 1], [1, 1], [1, 2], r"D must be a scalar .* got shape \(2,\)"),
    (np.eye(13), np.ones(13), np.ones(13), 0, r"13 states, more than MAX_ORDER = 12"),
    ([[np.nan]], [1], [1], 0, r"A must be finite, got \[\[nan\]\]"),
])
def test_from_state_space_refuses_bad_shapes(A, B, C, D, pattern):
    with pytest.raises(InvalidValueError, match=pattern):
        TransferFunction.from_state_space(A, B, C, D)


def test_from_state_space_refuses_text():
    with pytest.raises(InvalidTypeError, match=r"A must be real numbers, got 'eye'"):
        TransferFunction.from_state_space("eye", [1], [1], 0)


# ----------------------------------------------------------------------------------------------- coercion
def test_coerce_accepts_every_form():
    g = TransferFunction.parse("(s+2)/(s^2+3*s+2)")
    assert TransferFunction.coerce(g) is g
    assert TransferFunction.coerce("(s+2)/(s^2+3*s+2)") == g
    assert TransferFunction.coerce(([2, 4], [2, 6, 4])) == g
    assert TransferFunction.coerce([[1, 2], [1, 3, 2]]) == g
    assert_coeffs(TransferFunction.coerce(g.state_space()), g.num, g.den, rtol=1e-9)
    for gain in (2.5, np.float64(2.5), np.array(2.5)):
        assert TransferFunction.coerce(gain) == TransferFunction([2.5], [1])
    assert TransferFunction.coerce(np.int64(-3)).dc_gain() == -3.0


def test_coerce_python_control_systems():
    control = pytest.importorskip("control")
    g = TransferFunction.coerce(control.tf([1, 2], [2, 6, 4]))
    assert g == TransferFunction([0.5, 1.0], [1.0, 3.0, 2.0])  # divided by 2 exactly
    A, B, C, D = [[0, 1], [-2, -3]], [[0], [1]], [[1, 0]], [[0]]
    h = TransferFunction.coerce(control.ss(A, B, C, D))
    assert_coeffs(h, [1.0], [1.0, 3.0, 2.0], rtol=1e-12)  # det(sI - A) = s^2 + 3 s + 2, C adj(sI - A) B = 1
    assert TransferFunction.coerce(control.tf([1], [1, 1], None)) == TransferFunction([1], [1, 1])  # dt unspecified


def test_coerce_refuses_discrete_time_mimo_and_other_control_objects():
    control = pytest.importorskip("control")
    with pytest.raises(InvalidValueError, match=r"^plant: .*discrete-time \(dt = 0.1\)"):
        TransferFunction.coerce(control.tf([1], [1, -0.5], 0.1))
    with pytest.raises(InvalidValueError, match=r"^controller: .*StateSpace is discrete-time \(dt = True\)"):
        TransferFunction.coerce(control.ss([[0.5]], [[1]], [[1]], [[0]], True), name="controller")
    with pytest.raises(InvalidValueError, match=r"has 2 inputs and 1 outputs; only single-input"):
        TransferFunction.coerce(control.tf([[[1], [1]]], [[[1, 1], [1, 2]]]))
    with pytest.raises(InvalidTypeError, match=r"FrequencyResponseData objects are not supported"):
        TransferFunction.coerce(control.frd([1, 2], [1, 2]))


@pytest.mark.parametrize("obj, pattern", [
    (None, r"^plant must be .* got None \(NoneType\)"),
    ({"num": [1], "den": [1, 1]}, r"^plant must be .* \(dict\)"),
    (["1", "s+1"], r"^plant: numerator coefficients must be real numbers, got '1' \(str\)"),
    (["a", "b", "c"], r"^plant must be .* got \['a', 'b', 'c'\] \(list\)"),
    (True, r"^plant must be .* got True \(bool\)"),
    (1 + 2j, r"^plant must be .* \(complex\)"),
    (([1], ["x"]), r"^plant: denominator coefficients must be real numbers, got \['x'\]"),
])
def test_coerce_refuses_wrong_types(obj, pattern):
    with pytest.raises(InvalidTypeError, match=pattern) as info:
        TransferFunction.coerce(obj)
    assert isinstance(info.value, TypeError)


def test_wrong_types_elsewhere():
    for bad in (None, 3, b"1/s"):
        with pytest.raises(InvalidTypeError, match=r"a transfer function must be text, got .*\(" + type(bad).__name__):
            TransferFunction.parse(bad)
    with pytest.raises(InvalidTypeError, match=r"numerator coefficients must be real numbers, got \['1', '2'\]"):
        TransferFunction(["1", "2"], [1])
    with pytest.raises(InvalidTypeError, match=r"denominator coefficients must be real numbers, got \[True, 1\]"):
        TransferFunction([1], [True, 1])
    with pytest.raises(InvalidTypeError, match=r"feedback path must be"):
        TransferFunction.parse("1/s").feedback(None)
    with pytest.raises(TypeError):
        TransferFunction.parse("1/s") * "s"


# ------------------------------------------------------------------------------------------------ queries
@pytest.mark.parametrize("text, poles, zeros, dc, integrators, rel", [
    ("1/((s+1)*(0.5*s+1))", [-2, -1], [], 1.0, 0, 2),
    ("1/(s*(0.05*s+1))", [-20, 0], [], math.inf, 1, 2),
    ("-3/(s^2*(s+2))", [-2, 0, 0], [], -math.inf, 2, 3),
    ("(s+2)/(s^2+3*s+2)", [-2, -1], [-2], 1.0, 0, 1),
    ("s/(0.02*s+1)", [-50], [0], 0.0, 0, 0),
    ("s/s", [0], [0], 1.0, 1, 0),  # the limit at 0, no cancellation
    # wn = 3, zeta = 0.7: -zeta wn +- j wn sqrt(1 - zeta^2)
    ("1/(s^2 + 2*0.7*3*s + 9)", [-2.1 - 3j * math.sqrt(0.51), -2.1 + 3j * math.sqrt(0.51)], [], 1 / 9, 0, 2),
    ("2", [], [], 2.0, 0, 0),
    ("0/(s+1)", [-1], [], 0.0, 0, 1),
    ("0", [], [], 0.0, 0, 0),  # tends to 0 at infinity although of relative degree 0
])
def test_poles_zeros_dc_gain_integrators(text, poles, zeros, dc, integrators, rel):
    g = TransferFunction.parse(text)
    np.testing.assert_allclose(g.poles(), np.array(poles, dtype=complex), atol=1e-9)
    np.testing.assert_allclose(g.zeros(), np.array(zeros, dtype=complex), atol=1e-9)
    assert g.dc_gain() == pytest.approx(dc, rel=1e-12)
    assert g.integrators == integrators and g.relative_degree == rel and g.order == len(poles)
    assert g.is_strictly_proper == (rel > 0 or text.startswith("0"))


def test_minimal_cancels_common_roots_only():
    m = TransferFunction.parse("(s+2)/(s^2+3*s+2)").minimal()
    assert_coeffs(m, [1.0], [1.0, 1.0], rtol=1e-12)
    g = TransferFunction.parse("(s+3)/(s^2+3*s+2)")
    assert g.minimal() is g
    assert_coeffs(TransferFunction.parse("4*s*(s+0.5)/(s*(s+1)*(s+2))").minimal(), [4.0, 2.0], [1.0, 3.0, 2.0])
    assert TransferFunction.parse("0/(s+1)").minimal() == TransferFunction(0, 1)


# --------------------------------------------------------------------------------------------- arithmetic
LOOPS = [  # (G, H) by text; both are in EXAMPLES so their raw coefficients are known independently
    ("1/(s*(0.05*s+1))", "2"),
    ("1/(s*(0.05*s+1))", "s/(0.02*s+1)"),
    ("0.62/(150*s+1)", "(s+2)/(s**2+3*s+2)"),
    ("1/(s^2 + 2*0.7*3*s + 9)", "1/s"),
]


@pytest.mark.parametrize("g_text, h_text", LOOPS)
def test_feedback_series_parallel_match_python_control(g_text, h_text):
    control = pytest.importorskip("control")
    G, H = TransferFunction.parse(g_text), TransferFunction.parse(h_text)
    Gc, Hc = (control.tf(*EXAMPLES[t][0]) for t in (g_text, h_text))

    def ref(sys):
        return monic(sys.num_array[0][0], sys.den_array[0][0])

    for sign in (-1, 1):
        assert_coeffs(G.feedback(H, sign), *ref(control.feedback(Gc, Hc, sign=sign)), rtol=1e-12)
    assert_coeffs(G * H, *ref(control.series(Gc, Hc)), rtol=1e-12)
    assert_coeffs(G + H, *ref(control.parallel(Gc, Hc)), rtol=1e-12)
    assert_coeffs(G - H, *ref(control.parallel(Gc, -Hc)), rtol=1e-12)
    for s in POINTS:  # and the values, from the texts
        gs, hs = oracle(g_text, s), oracle(h_text, s)
        assert abs(G.feedback(H)(s) - gs / (1 + gs * hs)) <= 1e-10 * abs(gs / (1 + gs * hs))


def test_scalar_arithmetic_and_negation():
    g = TransferFunction.parse("1/(s+1)")
    for two in (2, 2.0, np.float64(2)):
        assert two * g == g * two == TransferFunction([2], [1, 1])
    assert g + 1 == 1 + g == TransferFunction([1, 2], [1, 1])
    assert 1 - g == TransferFunction([1, 0], [1, 1])
    assert -g == TransferFunction([-1], [1, 1])
    assert g.feedback() == TransferFunction([1], [1, 2])
    # positive feedback through s/(0.02 s + 1): (0.02 s + 1) / ((s + 1)(0.02 s + 1) - s)
    #   = (0.02 s + 1) / (0.02 s^2 + 0.02 s + 1), divided by 0.02: (s + 50) / (s^2 + s + 50)
    assert_coeffs(g.feedback("s/(0.02*s+1)", sign=1), [1.0, 50.0], [1.0, 1.0, 50.0])


def test_feedback_refusals():
    with pytest.raises(InvalidValueError, match=r"sign must be -1 \(negative feedback\) or \+1, got 0"):
        TransferFunction.parse("1/s").feedback(1, sign=0)
    with pytest.raises(InvalidValueError, match=r"closed loop of -1 with 1 is undefined"):
        TransferFunction(-1, 1).feedback()
    with pytest.raises(InvalidValueError, match=r"closed loop is improper"):
        TransferFunction.parse("s/(s+1)").feedback(-1)  # den (s+1) - s = 1
    with pytest.raises(InvalidValueError, match=r"degree 13, more than MAX_ORDER"):
        TransferFunction.parse("1/(s+1)^12") * TransferFunction.parse("1/s")


# ------------------------------------------------------------------------------------------ other outputs
def test_equality_hash_and_immutability():
    a, b = TransferFunction.parse("2/(2*s+2)"), TransferFunction([1], [1, 1])
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    assert a != TransferFunction([1], [1, 1.0000001]) and a != TransferFunction([1, 0], [1, 1, 0])
    assert a != "1/(s+1)"
    with pytest.raises(ValueError):
        a.num[0] = 5.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.num = np.ones(1)


def test_to_dict_is_json_ready_and_reads_back():
    g = TransferFunction.parse("(s+2)/(s^2+3*s+2)")
    d = json.loads(json.dumps(g.to_dict()))
    assert d == {"num": [1.0, 2.0], "den": [1.0, 3.0, 2.0]}
    assert TransferFunction(**d) == g


def test_to_control_and_back():
    control = pytest.importorskip("control")
    g = TransferFunction.parse("0.62/(150*s+1)")
    c = g.to_control()
    assert isinstance(c, control.TransferFunction)
    for s in POINTS:
        assert abs(complex(c(s)) - oracle("0.62/(150*s+1)", s)) <= 1e-12 * abs(oracle("0.62/(150*s+1)", s))
    assert TransferFunction.coerce(c) == g


def test_to_control_without_python_control(monkeypatch):
    monkeypatch.setitem(sys.modules, "control", None)  # makes `import control` fail
    with pytest.raises(MissingDependencyError, match=r"python-control"):
        TransferFunction.parse("1/s").to_control()


def test_improper_functions_only_on_request():
    with pytest.raises(InvalidValueError, match=r"'4\*s\+2' is improper.*proper=False"):
        TransferFunction.parse("4*s+2")
    pd = TransferFunction.parse("4*s+2", proper=False)
    assert pd.relative_degree == -1 and not pd.is_strictly_proper
    with pytest.raises(InvalidValueError, match=r"improper and has no state-space realisation"):
        pd.state_space()
    with pytest.raises(InvalidValueError, match=r"^plant TransferFunction\(4 s \+ 2\) is improper"):
        TransferFunction.coerce(pd)
    assert TransferFunction.coerce(pd, name="controller", proper=False) is pd
    # the open loop of a PD law and an integrator plant is proper again
    loop = pd * TransferFunction.parse("1/(s*(0.05*s+1))")
    assert_coeffs(loop, [80.0, 40.0], [1.0, 20.0, 0.0])  # (4 s + 2) * 20 / (s^2 + 20 s)


# ------------------------------------------------------------------------------------------------- refusals
@pytest.mark.parametrize("text, pattern", [
    ("1/(s", r"^could not read the transfer function '1/\(s': '\(' was never closed"),
    ("1/(s+)", r"^could not read the transfer function '1/\(s\+\)': invalid syntax"),
    ("", r"^could not read the transfer function '': it is empty"),
    ("   ", r"^could not read the transfer function '   ': it is empty"),
    ("s s", r"^could not read the transfer function 's s': .*write products with \*"),
    ("2 s", r"^could not read the transfer function '2 s': .*write products with \*"),
    ("2s", r"^could not read the transfer function '2s'"),
    ("1/(x+1)", r"'1/\(x\+1\)' uses the unknown name 'x'; only the variable s and the delay factor exp\(-T\*s\)"),
    ("sin(s)", r"'sin\(s\)' uses the unknown function 'sin'; only the variable s and the delay factor exp"),
    ("__import__('os')", r"unknown function '__import__'"),
    ("s**2/(s+1)", r"'s\*\*2/\(s\+1\)' is improper: the numerator degree 2 exceeds the denominator degree 1; "
                   r"a delayed loop needs a proper plant"),
    ("1/0", r"'1/0': division by zero: '0' is zero"),
    ("1/(s-s)", r"'1/\(s-s\)': division by zero: 's-s' is zero"),
    ("(s+1)/(0*s)", r"'\(s\+1\)/\(0\*s\)': division by zero: '0\*s' is zero"),
    ("1e400/(s+1)", r"'1e400/\(s\+1\)': the number 1e400 is not finite"),
    ("1e200/(s+1)", r"the number 1e200 is too large"),
    ("1" + "0" * 400, r"is too large"),
    ("1/(1e-60*s+1)^2", r"'1/\(1e-60\*s\+1\)\^2' is badly scaled"),
    ("(1e90*s+1)^12/(s+1)^12", r"coefficients of '\(1e90\*s\+1\)\^12' overflow"),
    ("1/s**-1", r"the exponent in 's\^-1' must be a constant integer from 0 to 12, got -1"),
    ("1/s^0.5", r"the exponent in 's\^0.5' must be .* got 0.5"),
    ("1/(s+1)^13", r"the exponent in '\(s\+1\)\^13' must be .* got 13"),
    ("1/s^s", r"the exponent in 's\^s' must be a constant integer"),
    ("1/((s+1)**12*(s+1))", r"'1/\(\(s\+1\)\*\*12\*\(s\+1\)\)' has degree 13, more than MAX_ORDER = 12"),
    ("s" + "*s" * 60, r"has degree over 48"),
    ("1j/(s+1)", r"1j is not a real number"),
    ("s//2", r"the operator in 's//2' is not allowed"),
    ("s.real", r"'s.real' is not allowed"),
    ("x" * 3000, r"longer than 2000 characters"),
])
def test_bad_text_is_refused_naming_it(text, pattern):
    with pytest.raises(InvalidValueError, match=pattern) as info:
        TransferFunction.parse(text)
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize("num, den, pattern", [
    ([1], [0, 0], r"numerator \[1.0\] and denominator \[0.0, 0.0\]: the denominator is zero"),
    ([np.inf], [1, 1], r"numerator coefficients must be finite, got \[inf\]"),
    ([1], [1, np.nan], r"denominator coefficients must be finite, got \[1.0, nan\]"),
    ([1e200], [1, 1], r"badly scaled: .* becomes 1e\+200"),
    ([1, 2, 3], [1, 1], r"numerator degree 2 exceeds the denominator degree 1"),
    ([1], [1] * 14, r"has degree 13, more than MAX_ORDER = 12"),
    ([[1, 2]], [1], r"flat sequences, got shapes \(1, 2\)"),
    ([], [1], r"numerator \[\] and denominator \[1.0\]: a polynomial needs at least one coefficient"),
])
def test_bad_coefficients_are_refused(num, den, pattern):
    with pytest.raises(InvalidValueError, match=pattern):
        TransferFunction(num, den)


# ----------------------------------------------------------------------------------------------- delays
def test_delays_add_and_do_not_depend_on_position():
    read = TransferFunction.parse_with_delay
    assert read("exp(-1*s)*2/(s+1)") == read("2*exp(-s)/(s+1)") == (TransferFunction([2], [1, 1]), 1.0)
    g, tau = TransferFunction.parse_with_delay("exp(-0.25*s)*exp(-s*0.5)/(s+1)*exp(-s/4)")
    assert g == TransferFunction([1], [1, 1]) and tau == pytest.approx(1.0, rel=1e-15)
    assert TransferFunction.parse_with_delay("(exp(-0.5*s))^2/(s+1)")[1] == 1.0
    assert TransferFunction.parse_with_delay("exp(-12*s)") == (TransferFunction(1, 1), 12.0)
    assert TransferFunction.parse_with_delay("-exp(-0.3*s)*(s+1)/(s+2)")[0] == TransferFunction([-1, -1], [1, 2])
    assert TransferFunction.parse_with_delay("0.62/(150*s+1)")[1] == 0.0


@pytest.mark.parametrize("text, pattern", [
    ("1/(exp(-s)*(s+1))", r"'exp\(-s\)\*\(s\+1\)' puts a delay factor exp\(-T\*s\) in a denominator"),
    ("exp(0.3*s)/(s+1)", r"'exp\(0.3\*s\)' is a prediction \(delay -0.3 < 0\)"),
    ("exp(-s)+1/(s+1)", r"a delay factor exp\(-T\*s\) is added to something; it may only multiply"),
    ("1/(s+1) - exp(-s)", r"is added to something"),
    ("exp(-s^2)/(s+1)", r"'exp\(-s\^2\)' is not a delay factor: its argument must be -T\*s"),
    ("exp(-s+1)/(s+1)", r"'exp\(-s\+1\)' is not a delay factor"),
    ("exp(-0.3)/(s+1)", r"'exp\(-0.3\)' is not a delay factor"),
    ("exp(-1/s)", r"'exp\(-1/s\)' is not a delay factor"),
    ("exp(exp(-s))", r"'exp\(exp\(-s\)\)' is not a delay factor"),
    ("exp(-s, 2)", r"exp takes one argument"),
    ("(s+1)^exp(-s)", r"exponent in '\(s\+1\)\^exp\(-s\)' must be a constant integer"),
])
def test_bad_delays_are_refused(text, pattern):
    with pytest.raises(InvalidValueError, match=pattern):
        TransferFunction.parse_with_delay(text)


def test_parse_refuses_a_delay_and_points_elsewhere():
    with pytest.raises(InvalidValueError, match=r"'0.62\*exp\(-12\*s\)/\(150\*s\+1\)' contains a delay factor .*"
                                                r"parse_with_delay.*delay option"):
        TransferFunction.parse("0.62*exp(-12*s)/(150*s+1)")
    with pytest.raises(InvalidValueError, match=r"^plant: .*contains a delay factor"):
        TransferFunction.coerce("exp(-s)/(s+1)")


# ------------------------------------------------------------------------------------------- round trip
_coef = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)
_lead = st.tuples(st.sampled_from([-1.0, 1.0]), st.floats(min_value=1e-2, max_value=1e3)).map(lambda t: t[0] * t[1])


@st.composite
def proper_functions(draw):
    n = draw(st.integers(min_value=0, max_value=MAX_ORDER))
    m = draw(st.integers(min_value=0, max_value=n))
    den = [draw(_lead)] + draw(st.lists(_coef, min_size=n, max_size=n))
    num = draw(st.lists(_coef, min_size=m + 1, max_size=m + 1))
    return num, den


@given(proper_functions())
@example(([5e-324, 0.0], [-2.0, 0.0]))  # the leading numerator coefficient underflows to 0 when normalised
def test_printed_functions_parse_back(pair):
    g = TransferFunction(*pair)
    assert_coeffs(TransferFunction.parse(g.to_string(digits=17)), g.num, g.den, rtol=1e-12)
    short = TransferFunction.parse(g.to_string())  # %g: six significant digits
    assert short.den.shape == g.den.shape
    np.testing.assert_allclose(short.den, g.den, rtol=1e-5, atol=0)
