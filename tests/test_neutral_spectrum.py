"""The spectrum of a neutral quasi-polynomial's difference operator: the polygon bound, and neutral systems' stability.

The reference for the issue's example is computed here independently of delaykit: the closure of the real parts of
the roots of ``1 + 0.5 e^{-s} + 0.45 e^{-sqrt(2) s}`` is the set of ``x`` where the three moduli ``1``,
``0.5 e^{-x}``, ``0.45 e^{-sqrt(2) x}`` close a triangle (Kronecker: the two phases are dense on the torus); its
largest point is found by SciPy's brentq on the triangle inequality, and cross-checked by sampling the phases.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from delaykit import InvalidValueError, delay, feedback, is_stable, tf
from delaykit.models import QuasiPolynomial
from delaykit.spectrum import neutral_lines, rightmost
from delaykit.spectrum.neutral import neutral_abscissa, polygon_abscissa

R2 = math.sqrt(2.0)
# s + 2 + 0.5 s e^{-s} + (0.45 s + 0.1) e^{-sqrt(2) s}: the example of issue 21
Q = QuasiPolynomial([[1, 2], [0.5, 0], [0.45, 0.1]], [0.0, 1.0, R2])


def _triangle_sup() -> float:
    """The largest x at which 1, 0.5 e^-x, 0.45 e^-sqrt2 x satisfy the triangle inequality (brentq)."""
    def slack(x: float) -> float:  # >= 0 where the triangle closes
        r = np.array([1.0, 0.5 * math.exp(-x), 0.45 * math.exp(-R2 * x)])
        return float(r.sum() - 2 * r.max())
    return brentq(slack, -1.0, 1.0, xtol=1e-15)


def test_the_issue_example_bound_is_the_triangle_supremum():
    ref = _triangle_sup()
    # the issue printed -0.0429; the closure's supremum is -0.042847 (the issue's figure is within 1e-4)
    assert abs(ref - (-0.0429)) < 1e-4
    na = neutral_abscissa(Q)
    assert abs(na.abscissa - ref) < 1e-12
    assert na.independent and na.strongly_stable
    assert neutral_lines(Q) == (na.abscissa,)
    # the old sampled answer, -0.0465, was below the closure: the new one is conservative
    assert na.abscissa > -0.0465 + 3e-3


def test_brute_force_phases_reach_the_bound_and_never_pass_it():
    # min over phases of |1 + 0.5 e^{-x} e^{i a} + 0.45 e^{-sqrt2 x} e^{i b}| is 0 exactly on the closure
    a, b = np.meshgrid(np.linspace(0, 2 * np.pi, 1441), np.linspace(0, 2 * np.pi, 1441))

    def gap(x: float) -> float:
        return float(np.abs(1 + 0.5 * np.exp(-x + 1j * a) + 0.45 * np.exp(-R2 * x + 1j * b)).min())

    x = neutral_abscissa(Q).abscissa
    assert gap(x - 0.01) < 1e-4        # inside: the polygon closes (up to the sampling of the phases)
    assert gap(x) < 1e-4
    assert gap(x + 0.01) > 5e-3        # outside: it cannot close for any phases
    # the real parts of actual roots of D come close to the bound (Kronecker), and none exceeds it
    D = QuasiPolynomial([[1.0], [0.5], [0.45]], [0.0, 1.0, R2])
    from delaykit.spectrum import find_roots
    sp = find_roots(D, (-0.6, 0.2, 0.0, 400.0))
    assert sp.certified and sp.roots.size > 50
    assert sp.roots.real.max() <= x + 1e-9
    assert sp.roots.real.max() > x - 0.01


def test_one_delay_is_the_classical_line_and_the_bound_flips_at_sum_one():
    assert math.isclose(polygon_abscissa(1.0, [0.3], [0.37]), math.log(0.3) / 0.37, rel_tol=1e-13)
    # sum |b| = 1 exactly: the abscissa is 0 (the closure touches the axis); just below, negative; above, positive
    assert abs(polygon_abscissa(1.0, [0.5, 0.5], [1.0, R2])) < 1e-14
    assert polygon_abscissa(1.0, [0.5, 0.5 - 1e-6], [1.0, R2]) < 0 < polygon_abscissa(1.0, [0.5, 0.5 + 1e-6],
                                                                                      [1.0, R2])
    assert polygon_abscissa(0.0, [1.0], [1.0]) == math.inf
    assert polygon_abscissa(1.0, [0.0], [1.0]) == -math.inf


def test_commensurate_delays_are_reported_as_a_bound():
    # 1 + 0.5 e^{-s} + 0.45 e^{-2s}: a quadratic in z = e^{-s}; its roots' real parts are -ln|z| exactly
    q = QuasiPolynomial([[1, 2], [0.5, 0], [0.45, 0.1]], [0.0, 1.0, 2.0])
    na = neutral_abscissa(q)
    assert not na.independent
    exact = max(-math.log(abs(z)) for z in np.roots([0.45, 0.5, 1.0]))  # z^2 0.45 + 0.5 z + 1 = 0 in z = e^{-s}
    assert exact <= na.abscissa + 1e-12


def test_rightmost_of_the_issue_example_is_conservative():
    rm = rightmost(Q)
    assert rm.abscissa >= neutral_abscissa(Q).abscissa - 1e-12


def test_neutral_system_stability_decided_and_refused():
    # y(t) = u(t-1) - c y(t-1): the difference operator 1 + c e^{-s}; strongly stable iff |c| < 1
    assert is_stable(feedback(delay(1.0), 0.5))
    with pytest.raises(InvalidValueError, match="not strongly stable"):
        is_stable(feedback(delay(1.0), 1.2))
    # a neutral system with dynamics: 1/(s+1) + 0.4 e^{-0.5 s} with the gain k in the loop; its characteristic
    # function is s + 1 + k + 0.4 (s + 1) e^{-0.5 s}.  For k = 1 no root has Re s >= 0, since there
    # |0.4 (s + 1) e^{-0.5 s}| <= 0.4 |s + 1| < |s + 2|; for k = -2 it is -0.6 at s = 0 and grows without bound
    # along the real axis, so a real root is positive.
    for k, stable in ((1.0, True), (-2.0, False)):
        T = feedback(tf(f"{k}/(s+1)") + tf("0.4*exp(-0.5*s)"), 1)
        assert T.characteristic().kind == "neutral"
        assert is_stable(T) is stable
    # a large delayed feedthrough: the difference operator 1 + 3 e^{-0.5 s} has roots on Re s = 2 ln 3: refused
    with pytest.raises(InvalidValueError, match="strongly stable"):
        is_stable(feedback(tf("1/(s+1)") + tf("3*exp(-0.5*s)"), 1))
