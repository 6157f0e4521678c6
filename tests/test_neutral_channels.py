"""Neutral systems with several delay channels: the difference operator's spectrum per channel.

``det(I - D22 Delta(s))`` expanded is a sum of exponentials whose delays are sums of the channels' (not
independent), so the polygon bound on it is conservative.  :func:`delaykit.spectrum.neutral.channel_abscissa` keeps
the channels.  The references here are computed independently of it:

* for two channels, ``1 - a e1 - d e2 + Det e1 e2 = 0`` solved for ``e2 = (1 - a e1) / (d - Det e1)`` (a Mobius map):
  a root chain reaches ``Re s = x`` iff ``|e2|`` takes the value ``exp(-tau2 x)`` as the phase of ``e1`` turns, a
  fine brute-force scan of 200,001 phases, with SciPy's brentq on ``x``;
* the roots of the difference operator itself, found by mpmath's ``findroot`` from the minima of ``|D|`` on a grid up
  to ``Im s = 600``: none lies right of the supremum, and the largest real parts come close to it (Kronecker);
* commensurate delays: the polynomial ``det(I - M diag(z^n))`` in ``z = exp(-s h)`` by numpy's ``roots``;
* stability verdicts by the small-gain theorem or Rouche's theorem, argued in each test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from delaykit import DelayLTI, InvalidValueError, append, delay, feedback, is_stable, tf
from delaykit.spectrum.neutral import channel_abscissa, neutral_abscissa, polygon_abscissa
from delaykit.spectrum.systems import neutral_spectrum, poles

R2 = math.sqrt(2.0)
M = np.array([[0.5, 0.3], [-0.3, 0.5]])  # a scaled rotation: ||M|| = rho(M) = 0.583, Det = 0.34


def _mobius_sup(M: np.ndarray, t1: float, t2: float) -> float:
    """Largest x at which det(I - M diag(r1 e^{i a}, r2 e^{i b})) = 0 for some phases a, b (brute force on a)."""
    a, b, c, d = M.ravel()
    det = a * d - b * c
    th = np.linspace(0.0, 2 * np.pi, 200_001)

    def gap(x: float) -> float:  # r2 minus the least |e2| over the phase of e1: positive where a zero exists
        e1 = math.exp(-t1 * x) * np.exp(1j * th)
        return math.exp(-t2 * x) - float((np.abs(1 - a * e1) / np.abs(d - det * e1)).min())

    return brentq(gap, -3.0, 3.0, xtol=1e-13)


def test_two_coupled_channels_match_the_brute_force_scan_and_beat_the_polygon():
    ref = _mobius_sup(M, 1.0, R2)
    ca = channel_abscissa(M, [1.0, R2])
    assert ca.exact and ca.exact_lines
    assert abs(ca.abscissa - ref) < 1e-9
    assert ca.lines == ca.abscissa  # independent delays: the supremum is reached
    # the expanded determinant 1 - 0.5 e1 - 0.5 e2 + 0.34 e1 e2: its moduli add up to 1.34 > 1, so the polygon
    # bound is positive (the old verdict: not strongly stable); per channel it is -0.3895
    det = float(np.linalg.det(M))
    assert polygon_abscissa(1.0, [M[0, 0], M[1, 1], det], [1.0, R2, 1.0 + R2]) > 0.19
    assert ca.abscissa < -0.38 and ca.strongly_stable


def test_roots_of_the_difference_operator_approach_the_supremum_from_below():
    import mpmath

    a, d = M[0, 0], M[1, 1]
    det = float(np.linalg.det(M))
    x_star = channel_abscissa(M, [1.0, R2]).abscissa

    def D(s):
        return 1 - a * np.exp(-s) - d * np.exp(-R2 * s) + det * np.exp(-(1 + R2) * s)

    xs, ys = np.linspace(x_star - 0.8, x_star + 0.3, 56), np.arange(0.0, 600.0, 0.05)
    S = xs[None, :] + 1j * ys[:, None]
    V = np.abs(D(S))
    inner = V[1:-1, 1:-1]
    loc = ((inner < V[:-2, 1:-1]) & (inner < V[2:, 1:-1]) & (inner < V[1:-1, :-2]) & (inner < V[1:-1, 2:]))
    seeds = S[1:-1, 1:-1][loc]
    f = lambda s: 1 - a * mpmath.exp(-s) - d * mpmath.exp(-R2 * s) + det * mpmath.exp(-(1 + R2) * s)  # noqa: E731
    roots = []
    for s0 in seeds:
        try:
            r = complex(mpmath.findroot(f, mpmath.mpc(s0.real, s0.imag), tol=1e-24))
        except (ValueError, ZeroDivisionError):
            continue
        if abs(complex(f(r))) < 1e-10:
            roots.append(r)
    re = np.array([r.real for r in roots])
    assert re.size > 100
    assert re.max() <= x_star + 1e-9            # no chain passes the supremum
    assert re.max() > x_star - 0.02             # and the roots' real parts come close to it


def test_commensurate_delays_give_the_exact_lines():
    a, b, c, d = M.ravel()
    det = a * d - b * c
    # delays 1 and 2: det(I - M diag(z, z^2)) = 1 - a z - d z^2 + det z^3 in z = e^{-s}; lines at -ln|z|
    ref = max(-math.log(abs(z)) for z in np.roots([det, -d, -a, 1.0]))
    ca = channel_abscissa(M, [1.0, 2.0])
    assert ca.exact_lines and abs(ca.lines - ref) < 1e-12
    assert ca.lines <= ca.abscissa + 1e-12
    # a non-normal M: the lines for these delays lie strictly left of the strong abscissa
    N = np.array([[0.2, 0.9], [-0.5, 0.1]])
    a, b, c, d = N.ravel()
    ref = max(-math.log(abs(z)) for z in np.roots([a * d - b * c, -d, -a, 1.0]))
    ca = channel_abscissa(N, [1.0, 2.0])
    assert abs(ca.lines - ref) < 1e-12 and ca.abscissa > ca.lines + 0.01
    assert abs(ca.abscissa - _mobius_sup(N, 1.0, 2.0)) < 1e-9
    # equal delays: det(I - z M) = 0 at z = 1/lambda: lines ln|lambda| / tau
    ca = channel_abscissa(N, [0.5, 0.5])
    assert abs(ca.lines - math.log(max(abs(np.linalg.eigvals(N)))) / 0.5) < 1e-12


def test_the_issue_example_as_two_channels_is_the_triangle_supremum():
    # a rank-one D22 gives det(I - D22 Delta) = 1 + 0.5 e^{-s} + 0.45 e^{-sqrt2 s}: no product term, so the polygon
    # is exact; the triangle inequality on 1, 0.5 e^-x, 0.45 e^{-sqrt2 x} closes up to x* (brentq)
    def slack(x: float) -> float:
        r = np.array([1.0, 0.5 * math.exp(-x), 0.45 * math.exp(-R2 * x)])
        return float(r.sum() - 2 * r.max())

    ref = brentq(slack, -1.0, 1.0, xtol=1e-15)
    ca = channel_abscissa([[-0.5, -0.5], [-0.45, -0.45]], [1.0, R2])
    assert abs(ca.abscissa - ref) < 1e-9 and abs(ref - (-0.042847)) < 1e-6


def test_three_channels_bracketed_by_a_brute_force_scan_of_the_determinant():
    M3 = np.array([[0.3, 0.4, 0.1], [-0.2, 0.35, 0.3], [0.25, -0.1, 0.2]])
    tau = np.array([1.0, R2, math.sqrt(3.0)])
    ca = channel_abscissa(M3, tau)
    assert ca.exact
    a, b, c = np.meshgrid(*[np.linspace(0, 2 * np.pi, 61)] * 3, indexing="ij")
    th = np.stack([a, b, c], axis=-1).reshape(-1, 3)

    def least(x: float) -> float:  # min over the phases of |det(I - M R(x) Theta)|, brute force
        E = np.exp(-tau * x)[None, :] * np.exp(1j * th)
        return float(np.abs(np.linalg.det(np.eye(3)[None] - M3[None] * E[:, None, :])).min())

    # left of x*: the determinant vanishes for some phases (to the 6-degree grid); right of it, bounded away
    assert least(ca.abscissa - 0.02) < 0.01
    assert least(ca.abscissa + 0.02) > 0.04


def test_the_lead_bound_holds_right_of_the_abscissa():
    ca = channel_abscissa(M, [1.0, R2])
    rng = np.random.default_rng(1)
    for x in (ca.abscissa + 0.05, ca.abscissa + 0.5, 2.0):
        low = ca.lead(x)
        assert 0 < low <= 1
        s = x + rng.uniform(0, 3, 2000) + 1j * rng.uniform(-500, 500, 2000)
        E = np.stack([np.exp(-s), np.exp(-R2 * s)], axis=-1)
        dets = np.abs(np.linalg.det(np.eye(2)[None] - M[None] * E[:, None, :]))
        assert dets.min() >= low
    assert ca.lead(ca.abscissa - 0.01) == 0.0


def _coupled_system(eps2: float, J: np.ndarray = np.eye(2)) -> DelayLTI:
    # x' = -x + eps J w, z = eps x + M w, w_j = z_j(t - tau_j): P22(s) = M + eps2 / (s + 1) J
    e = math.sqrt(eps2)
    return DelayLTI(A=-np.eye(2), B1=np.eye(2), B2=e * J, C1=np.eye(2), C2=e * np.eye(2), D11=None,
                    D12=None, D21=None, D22=M, delays=(1.0, R2))


def test_a_stable_coupled_neutral_system_refused_by_the_polygon_is_now_decided():
    T = _coupled_system(0.2)
    q = T.characteristic()
    assert q.kind == "neutral"
    # the old verdict: the polygon bound of the expanded characteristic function is positive -> refused
    assert neutral_abscissa(q).abscissa > 0
    # small gain: for Re s >= 0, ||P22(s) Delta(s)|| <= ||M|| + 0.2 / |s + 1| <= 0.583 + 0.2 < 1, so
    # det(I - P22 Delta) has no zero there, and det(sI - A) = (s + 1)^2 neither: stable
    assert np.linalg.norm(M, 2) + 0.2 < 1
    assert is_stable(T) is True
    # with a large coupling through J = all ones, P22(0) = M + 2 J has the real eigenvalue 2.5 + sqrt(3.91) > 1:
    # det(I - P22(x) R(x)) is negative at x = 0 and tends to 1 as x grows, so a real pole lies right of 0
    J = np.ones((2, 2))
    U = _coupled_system(2.0, J)
    f = lambda x: float(np.linalg.det(np.eye(2) - (M + 2.0 / (x + 1) * J) * np.exp(-np.array([1.0, R2]) * x)))  # noqa: E731
    assert f(0.0) * f(20.0) < 0
    assert is_stable(U) is False


def test_two_neutral_loops_side_by_side_flip_from_refused_to_stable():
    # each loop: (1/(s+1) + c e^{-tau s}) closed by unity feedback; characteristic s + 2 + c (s + 1) e^{-tau s},
    # with no root in Re s >= 0 by Rouche: there |c (s + 1) e^{-tau s}| <= c |s + 1| < |s + 2| (c < 1)
    T1 = feedback(tf("1/(s+1)") + tf("0.6*exp(-0.5*s)"), 1)
    T2 = feedback(tf("1/(s+1)") + tf(f"0.7*exp(-{0.5 * R2}*s)"), 1)
    T = append(T1, T2)
    q = T.characteristic()
    # expanded: 1 + 0.6 e1 + 0.7 e2 + 0.42 e1 e2, moduli adding up to 1.72: the polygon bound refused it
    assert neutral_abscissa(q).abscissa > 0
    na = neutral_spectrum(T)
    assert abs(na.abscissa - max(math.log(0.6) / 0.5, math.log(0.7) / (0.5 * R2))) < 1e-12
    assert is_stable(T) is True
    sp = poles(T, (-3, 1, 0, 30))
    assert sp.certified and sp.neutral_lines == (na.lines,)
    assert abs(na.lines - math.log(0.7) / (0.5 * R2)) < 1e-12     # one delay per chain: the lines are exact


def test_not_strongly_stable_is_refused_with_the_value():
    T = append(feedback(delay(1.0), -1.2), feedback(delay(R2), -0.5))
    with pytest.raises(InvalidValueError, match=r"not strongly stable.*0\.182"):
        is_stable(T)


def test_characteristic_top_coefficient_is_the_channel_determinant():
    # the s^n coefficient of det(sI - A) det(I - P22 Delta) is det(I - D22 Delta): the object channel_abscissa studies
    T = _coupled_system(0.2)
    q = T.characteristic()
    s = 0.3 + 7.1j
    top = sum(p[0] * np.exp(-s * t) for p, t in zip(q.polys, q.delays) if len(p) - 1 == q.degree)
    ref = np.linalg.det(np.eye(2) - M * np.exp(-s * np.array([1.0, R2]))[None, :])
    assert abs(top - ref) < 1e-12


def test_channel_abscissa_input_checks_and_trivial_cases():
    with pytest.raises(InvalidValueError, match="square"):
        channel_abscissa([[1.0, 2.0]], [1.0])
    with pytest.raises(InvalidValueError, match="delays >= 0"):
        channel_abscissa([[0.5]], [-1.0])
    with pytest.raises(InvalidValueError, match="not well posed"):
        channel_abscissa([[1.0, 0.0], [0.0, 0.5]], [0.0, 1.0])
    assert channel_abscissa([[0.0, 1.0], [0.0, 0.0]], [1.0, 2.0]).abscissa == -math.inf  # no cycle: retarded
    # a zero-delay channel folded in: w1 = 0.5 w2(t - 1) + ..., a static 0.5 loop -> M = 0.5 + 0.5 * 1 / (1 - 0.5)
    ca = channel_abscissa([[0.5, 0.5], [0.5, 0.5]], [1.0, 0.0])
    assert abs(ca.abscissa - math.log(0.5 + 0.25 / 0.5)) < 1e-12
