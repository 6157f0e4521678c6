"""The Laplace variable ``s = tf("s")`` and its algebra, ``tf(num, den)``, and other python-control habits.

References are independent of the realisation: the transfer functions evaluated directly as complex formulas,
closed-form step responses, the Lambert W function for the roots of ``s + a exp(-s)``, and python-control's own
``tf('s')`` algebra and ``step_response`` on delay-free systems.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import lambertw

import delaykit
from delaykit import (InvalidTypeError, InvalidValueError, LaplaceExpression, exp, hinfnorm, poles, step_response,
                      tf)

W = np.array([0.01, 0.3, 1.0, 2.7, 10.0, 55.0])


def value(sys, w):
    return sys.evaluate(1j * np.asarray(w))[0, 0]


def test_s_is_the_laplace_variable_and_stays_an_expression_while_improper():
    s = tf("s")
    assert isinstance(s, LaplaceExpression) and str(s) == "s"
    pd = 1.5 + 0.2 * s
    assert isinstance(pd, LaplaceExpression) and not pd.is_proper()
    assert str(pd) == "0.2*s + 1.5"
    with pytest.raises(InvalidValueError, match="improper"):
        pd.to_system()
    with pytest.raises(InvalidValueError, match="improper"):  # improper text is refused (a plant is proper);
        tf("s + 1")                                            # improper expressions are built from s


def test_proper_results_are_systems_with_the_exact_transfer_function():
    s = tf("s")
    G = 2 * exp(-0.5 * s) / (s + 1)
    assert isinstance(G, delaykit.DelayLTI) and G.delays == (0.5,)
    jw = 1j * W
    assert np.allclose(value(G, W), 2 * np.exp(-0.5 * jw) / (jw + 1), rtol=1e-13, atol=0)
    L = (1.5 + 0.2 * s) * G / (0.05 * s + 1)  # improper PD times a proper plant: proper again
    assert np.allclose(value(L, W), (1.5 + 0.2 * jw) * 2 * np.exp(-0.5 * jw) / (jw + 1) / (0.05 * jw + 1),
                       rtol=1e-12, atol=0)
    pid = 2 + 1 / s + 0.5 * s
    L2 = pid * G / (0.01 * s + 1)
    assert np.allclose(value(L2, W), (2 + 1 / jw + 0.5 * jw) * 2 * np.exp(-0.5 * jw) / (jw + 1) / (0.01 * jw + 1),
                       rtol=1e-12, atol=0)


def test_numpy_exp_and_numpy_scalars_work_as_pythons():
    s = tf("s")
    d = np.exp(-2 * s)
    assert isinstance(d, delaykit.DelayLTI) and d.delays == (2.0,)
    G = np.float64(3.0) * s / (s * s + np.float64(2.0) * s + 1)
    jw = 1j * W
    assert np.allclose(value(G, W), 3 * jw / (jw**2 + 2 * jw + 1), rtol=1e-13, atol=0)


def test_an_improper_expression_combines_with_a_system_written_as_text():
    s = tf("s")
    P = tf("2*exp(-s)/(s+1)")  # not built from s: read through plant_of as a rational function times a delay
    L = (1.5 + 0.2 * s) * P
    jw = 1j * W
    assert np.allclose(value(L, W), (1.5 + 0.2 * jw) * 2 * np.exp(-jw) / (jw + 1), rtol=1e-12, atol=0)
    two_delays = tf("1/(s+1)") + tf("exp(-s)/(s+1)")  # not rational times one delay
    with pytest.raises(InvalidValueError, match="improper"):
        (1 + s) * two_delays


def test_text_the_reader_refused_before_is_read_by_the_algebra():
    # (s+1)/(s+0.5 e^{-s}): a delay in the denominator's lower term (a neutral-free internal delay)
    H = tf("(s+1)/(s+0.5*exp(-s))")
    jw = 1j * W
    assert np.allclose(value(H, W), (jw + 1) / (jw + 0.5 * np.exp(-jw)), rtol=1e-12, atol=0)
    # its poles are the roots of s + 0.5 e^{-s}: s e^{s} = -0.5, s = W_k(-0.5) (Lambert W, branches k)
    spec = poles(H, (-6.0, 1.0, -20.0, 20.0))
    ref = [complex(lambertw(-0.5, k)) for k in range(-3, 4)]
    ref = [r for r in ref if -6 < r.real < 1 and -20 < r.imag < 20]
    assert spec.certified
    for r in ref:
        assert min(abs(np.asarray(spec.roots) - r)) < 1e-9


def test_step_of_a_system_built_from_s_is_the_closed_form():
    s = tf("s")
    G = 2 * exp(-0.5 * s) / (s + 1)
    t = np.linspace(0.0, 6.0, 61)
    r = step_response(G, t)
    ref = np.where(t > 0.5, 2 * (1 - np.exp(-(t - 0.5))), 0.0)
    assert np.abs(r.outputs[0, 0] - ref).max() < 1e-12


def test_delay_free_algebra_matches_python_control():
    control = pytest.importorskip("control")
    s, cs = tf("s"), control.tf("s")
    ours = (3 * s + 1) / (s**3 + 2 * s**2 + 3 * s + 1) * (1 / (0.5 * s + 1))
    theirs = (3 * cs + 1) / (cs**3 + 2 * cs**2 + 3 * cs + 1) * (1 / (0.5 * cs + 1))
    assert np.allclose(value(ours, W), np.array([complex(theirs(1j * w)) for w in W]), rtol=1e-12, atol=0)
    t = np.linspace(0, 20, 201)
    ref = control.step_response(theirs, t).outputs
    assert np.abs(step_response(ours, t).outputs[0, 0] - ref).max() < 1e-9


def test_tf_of_num_and_den_is_python_controls_two_argument_form():
    a = tf([2.0, 1.0], [1.0, 3.0, 2.0])
    b = tf(([2.0, 1.0], [1.0, 3.0, 2.0]))
    assert np.allclose(value(a, W), value(b, W), rtol=0, atol=0)
    with pytest.raises(InvalidTypeError):
        tf("1/(s+1)", [1.0, 1.0])


@pytest.mark.parametrize("bad, error", [
    (lambda s: exp(s), InvalidValueError),            # exp(+s): a prediction
    (lambda s: exp(-s * s), InvalidValueError),        # not -T*s
    (lambda s: exp("s"), InvalidTypeError),
    (lambda s: s ** 1000, InvalidValueError),          # degree beyond MAX_DEGREE
    (lambda s: s ** 1.5, InvalidValueError),
    (lambda s: s / 0, InvalidValueError),
])
def test_bad_expressions_are_refused_with_delaykit_errors(bad, error):
    with pytest.raises(error):
        bad(tf("s"))


def test_a_prediction_stays_an_expression_and_is_never_realised():
    s = tf("s")
    ahead = 1 / exp(-s)  # exp(+s)
    assert isinstance(ahead, LaplaceExpression) and not ahead.is_proper()
    with pytest.raises(InvalidValueError, match="improper"):
        tf(ahead)


def test_hinfnorm_unpacks_and_indexes_as_its_pair():
    h = hinfnorm(tf("1/(s^2+0.2*s+1)"))
    value_, w = h
    assert (h[0], h[1]) == (value_, w) and len(h) == 2 and h[:] == (value_, w)
    zeta = 0.1  # the closed form of a second-order peak
    assert abs(h[0] - 1 / (2 * zeta * np.sqrt(1 - zeta**2))) < 1e-8


def test_improper_text_points_to_s_not_to_an_option_tf_lacks():
    # tf("s+1") once advised "pass proper=False", which tf does not take
    with pytest.raises(InvalidValueError) as e:
        tf("4*s+2")
    assert "proper=False" not in str(e.value) and "tf('s')" in str(e.value)
