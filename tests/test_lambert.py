"""Lambert W roots of first-order delay equations: residuals, branch cuts, the branch point, Hayes' theorem."""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.special import lambertw

from delaykit.errors import InvalidValueError
from delaykit.spectrum.lambert import (complex_delays_for_root, delay_for_damping, dominant_root,
                                       kp_delay_for_damping, lambert_roots, lambert_w)


@given(a0=st.complex_numbers(max_magnitude=5, allow_nan=False, allow_infinity=False),
       a1=st.complex_numbers(min_magnitude=0.01, max_magnitude=5, allow_nan=False, allow_infinity=False),
       td=st.floats(0.01, 3.0))
def test_roots_solve_the_characteristic_equation(a0, a1, td):
    r = lambert_roots(a0, a1, td, branches=range(-3, 4))
    for s in r.roots:
        scale = abs(s) + abs(a0) + abs(a1 * np.exp(-s * td))
        assert abs(s - a0 - a1 * np.exp(-s * td)) <= 1e-12 * scale


@pytest.mark.parametrize("k", [-2, -1, 0, 1, 2])
def test_against_mpmath_on_and_around_the_branch_cut(k):
    # the negative real axis is the branch cut; -1/e is the branch point of branches 0 and -1
    xs = [-5.0, -1.0, -0.5, -1 / math.e - 1e-9, -1 / math.e + 1e-9, -1 / math.e + 1e-4, -0.2, 0.3, 4.0,
          -0.3 + 1e-12j, -0.3 - 1e-12j, -2 + 0.5j, 1j]
    for x in xs:
        ours = complex(lambert_w(x, k))
        ref = complex(mpmath.lambertw(mpmath.mpc(x), k))
        assert abs(ours - ref) <= 1e-10 * max(1.0, abs(ref)), (x, k, ours, ref)


def test_agrees_with_scipy_away_from_the_branch_point():
    rng = np.random.default_rng(0)
    x = rng.normal(size=500) * 3 + 1j * rng.normal(size=500)
    for k in (-1, 0, 1):
        assert np.allclose(lambert_w(x, k), lambertw(x, k), rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("r", [5e-4, 1e-5, 1e-7])
@pytest.mark.parametrize("k", [-1, 0, 1])
def test_against_mpmath_all_around_the_branch_point(r, k):
    # x = -1/e + (r/e) e^{i phi}, |e x + 1| = r: inside the region where lambert_w replaces SciPy's value by the
    # branch-point series, in every direction (below the real axis branch 0 meets branch 1 there, not -1).
    # Reference: mpmath at the same double x.  Tolerance: W is ill-conditioned there; e x + 1 carries an absolute
    # rounding error of about 1e-16, which moves p = sqrt(2 (e x + 1)), hence W, by about 1e-16 / sqrt(r).
    for phi in np.linspace(-math.pi, math.pi, 17):
        x = complex(-1 / math.e + r / math.e * np.exp(1j * phi))
        ours = complex(lambert_w(x, k))
        ref = complex(mpmath.lambertw(mpmath.mpc(x.real, x.imag), k))
        assert abs(ours - ref) <= 1e-14 + 2e-16 / math.sqrt(r), (x, k, ours, ref)


def test_at_the_double_precision_branch_point():
    # the double nearest -1/e is 8e-18 below it: there W_0 and W_-1 are -1 +- 8.2e-9j (mpmath, at that double);
    # e x + 1 rounds to 0 in double precision, so delaykit returns the branch point itself, -1 on both branches
    # (SciPy 1.17 returns NaN on both): within 2e-8 of the exact values, the conditioning of W at 1 ulp from -1/e
    x = -1 / math.e
    for k in (0, -1):
        ref = complex(mpmath.lambertw(mpmath.mpf(x), k))
        assert abs(ref + 1) > 1e-9 and abs(ref.imag) < 1e-8  # the exact value is not -1, but within 1e-8 of it
        assert complex(lambert_w(x, k)) == -1.0
        assert abs(complex(lambert_w(x, k)) - ref) < 2e-8


def test_away_from_the_branch_point_the_value_is_scipys_own():
    # SciPy's lambertw is accurate to about 1e-15 there (test_agrees_with_scipy, and mpmath above): lambert_w returns
    # it untouched, and the P loop's roots are W_0(-Kp Td) / Td with no further work (the speed of a million loops)
    rng = np.random.default_rng(5)
    x = rng.normal(size=2000) * 3 + 1j * rng.normal(size=2000)
    x = x[np.abs(math.e * x + 1) > 1.1e-3]
    for k in (-2, -1, 0, 1, 2):
        assert np.array_equal(lambert_w(x, k), lambertw(x, k))
    kp, td = rng.uniform(0.5, 3.0, 1000), rng.uniform(0.05, 0.8, 1000)
    away = np.abs(math.e * kp * td - 1) > 1.1e-3  # two of the thousand are near the branch point: the series there
    assert 0 < np.sum(~away) < 10
    roots = lambert_roots(0.0, -kp, td, branches=[0]).roots[0]
    assert np.array_equal(roots[away], (lambertw(-kp * td, 0) / td)[away])


def test_branch_point_is_a_double_root():
    # Kp Td = 1/e: s Td = W(-1/e) = -1 on branches 0 and -1
    kp, td = 1.0 / (math.e * 0.4), 0.4
    r = lambert_roots(0.0, -kp, td, branches=[0, -1]).roots
    assert np.allclose(r, -1 / td, atol=1e-12)
    s = r[0]
    f = s + kp * np.exp(-s * td)
    df = 1 - kp * td * np.exp(-s * td)
    assert abs(f) < 1e-12 and abs(df) < 1e-12  # a root of Q and Q': double


def test_rightmost_is_branch_zero_and_its_conjugate():
    for kp, td in [(1.31, 0.368), (1.0, 0.2), (2.0, 0.7), (0.5, 0.1)]:
        r = lambert_roots(0.0, -kp, td, branches=range(-6, 7))
        rm = r.rightmost
        b0 = r.roots[list(r.branches).index(0)]
        assert math.isclose(rm.real, b0.real, rel_tol=1e-13)
        if kp * td > 1 / math.e:
            bm1 = r.roots[list(r.branches).index(-1)]
            assert abs(bm1 - np.conj(b0)) < 1e-12
        assert np.all(np.diff(r.sorted().real) <= 0)


def test_no_delay_limit():
    r = lambert_roots(0.3, -1.2, 0.0, branches=[0, -1, 2])
    assert np.allclose(r.roots, 0.3 - 1.2)
    near = lambert_roots(0.3, -1.2, 1e-7, branches=[0]).roots[0]
    assert abs(near - (0.3 - 1.2)) < 1e-5


def hayes_stable(a: float, b: float) -> bool:
    """Hayes (1950): every root of s = a + b e^{-s} has Re s < 0 iff a < 1 and a < -b < sqrt(a1^2 + a^2),
    where a1 in (0, pi) solves a1 = a tan(a1) (a1 = pi/2 for a = 0)."""
    if a >= 1:
        return False
    if a == 0:
        a1 = math.pi / 2
    else:
        from scipy.optimize import brentq

        f = lambda x: x - a * math.tan(x)  # noqa: E731
        a1 = brentq(f, 1e-12, math.pi / 2 - 1e-12) if a > 0 else brentq(f, math.pi / 2 + 1e-12, math.pi - 1e-12)
    return a < -b < math.sqrt(a1**2 + a**2)


def test_stability_matches_hayes_closed_form():
    rng = np.random.default_rng(1)
    checked = 0
    for a, b in rng.uniform(-4, 2, size=(3000, 2)):
        rm = lambert_roots(a, b, 1.0, branches=[0, -1]).rightmost
        if abs(rm.real) < 1e-6:
            continue  # on the boundary
        assert (rm.real < 0) == hayes_stable(a, b), (a, b, rm)
        checked += 1
    assert checked > 2900


def test_damping_inverse_and_the_paper_numbers():
    # the damping ratio of the dominant root depends on Kp Td only
    for kp in (0.7, 1.31, 2.0):
        for zeta in (0.2, 0.5, 0.7684, 0.95):
            td = delay_for_damping(zeta, kp)
            s = dominant_root(kp, td)
            assert math.isclose(-s.real / abs(s), zeta, abs_tol=1e-10)
            assert math.isclose(kp * td, kp_delay_for_damping(zeta), rel_tol=1e-12)
    # paper-notes: matching the damping ratio 0.7684 alone gives a real Td near 0.360 s for Kp = 1.31
    assert abs(delay_for_damping(0.7684, 1.31) - 0.360) < 1e-3
    # and no real Td puts the root at -1.2347 + 1.0284j: the nearest solution is complex, 0.3743 - 0.2507j
    tds = complex_delays_for_root(-1.2347 + 1.0284j, 0.0, -1.31, ks=range(-3, 4))
    assert np.all(np.abs(tds.imag) > 0.1)
    assert abs(tds[3] - (0.3743 - 0.2507j)) < 1e-4
    s = -1.2347 + 1.0284j
    assert abs(s + 1.31 * np.exp(-s * tds[3])) < 1e-12


def test_bad_inputs():
    with pytest.raises(InvalidValueError, match="delay"):
        lambert_roots(0, -1, -0.1)
    with pytest.raises(InvalidValueError, match="a1"):
        lambert_roots(0, float("nan"), 0.1)
    with pytest.raises(InvalidValueError, match="zeta"):
        kp_delay_for_damping(1.0)
    with pytest.raises(InvalidValueError, match="branches"):
        lambert_roots(0, -1, 0.3, branches=[])
