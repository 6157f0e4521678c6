"""The difference operator of a system with internal delays: where its neutral root chains lie, channel by channel.

A :class:`~delaykit.systems.DelayLTI` whose delay channels feed one another directly (``D22 != 0`` on a cycle) is
neutral: its poles come in chains whose real parts accumulate on those of the roots of
``det(I - D22 diag(exp(-s tau_j)))``, and its time response jumps at the delays, the jumps fading only when that
operator is strongly stable.  :func:`channel_abscissa` finds the supremum of the chains' real parts over the
channels' independent phases (the structured singular value of complex scalar channels, bracketed from above and
below), ``< 0`` meaning strong stability, and the exact lines for commensurate delays.  It lives in this layer so
that the spectrum (poles, stability) and the time kernel both read it.

Examples
--------
>>> import math
>>> channel_abscissa([[0.5, 0.3], [-0.3, 0.5]], [1.0, math.sqrt(2)]).strongly_stable
True
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidValueError

__all__ = ["ChannelAbscissa", "channel_abscissa", "rationally_independent"]

_RELATION_COEFF = 6  # integer relations between delays searched with coefficients up to this size
_RELATION_TOL = 1e-9


def rationally_independent(tau: Sequence[float]) -> bool:
    """No integer relation ``sum k_j tau_j = 0`` with ``0 < max |k_j| <= 6`` (to a relative 1e-9) between the
    delays; more than four delays are not searched (False).

    Examples
    --------
    >>> rationally_independent([1.0, 2 ** 0.5]), rationally_independent([1.0, 1.5])
    (True, False)
    """
    t = np.asarray(tau, float)
    if t.size <= 1:
        return True
    if t.size > 4:
        return False  # not searched: reported as a bound
    scale = float(np.abs(t).max())
    rng = range(-_RELATION_COEFF, _RELATION_COEFF + 1)
    for k in itertools.product(rng, repeat=t.size):
        if any(k) and abs(float(np.dot(k, t))) <= _RELATION_TOL * scale:
            return False
    return True


_EXACT_TOL = 1e-8  # the two bounds of a channel group's abscissa meet to this (times 1 / the group's shortest delay)
_COMMENSURATE_DENOMINATOR = 64  # delay ratios p/q with q up to this are taken as commensurate
_COMMENSURATE_STATES = 600  # the largest shift register (channels x longest delay in steps) solved exactly


def _scaled_norm(X: np.ndarray, d: np.ndarray) -> float:
    """``sigma_max(S X S^-1)`` with ``S = diag(exp(d))``."""
    e = np.exp(d - d.mean())
    return float(np.linalg.norm(X * (e[:, None] / e[None, :]), 2))


def _best_scaling(X: np.ndarray, d0: np.ndarray) -> tuple[float, np.ndarray]:
    """``min_d sigma_max(diag(e^d) X diag(e^-d))`` (the D-scaled upper bound of the structured singular value for
    complex scalar channels; its logarithm is convex in ``d``, Sezginer & Overton 1990) and the minimiser."""
    from scipy.optimize import minimize, minimize_scalar

    k = X.shape[0]

    def f(v: np.ndarray) -> float:
        return math.log(max(_scaled_norm(X, np.concatenate([[0.0], v])), 1e-300))

    if k == 2:  # one scaling: Brent's method on a convex function of it
        res = minimize_scalar(lambda t: f(np.array([t])), bracket=(d0[0] - 1.0, d0[0] + 1.0), method="brent",
                              options={"xtol": 1e-12})
        v = np.array([float(res.x)])
    else:
        res = minimize(f, d0, method="Nelder-Mead", options={"xatol": 1e-11, "fatol": 1e-15, "maxiter": 4000})
        v = np.asarray(res.x, float)
    return math.exp(f(v)), v


def _torus_radius(X: np.ndarray, enough: float = math.inf) -> float:
    """``max`` over unit phases ``Theta`` of ``rho(X Theta)``, from below: a grid over the phases (one of them
    fixed: a common phase turns the eigenvalues, not their moduli) and the best points refined, until a value
    reaches ``enough``."""
    from scipy.optimize import minimize

    k = X.shape[0]

    def rho(th: np.ndarray) -> np.ndarray:
        th = np.atleast_2d(th)
        ph = np.exp(1j * np.concatenate([np.zeros((th.shape[0], 1)), th], axis=1))
        return np.abs(np.linalg.eigvals(X[None, :, :] * ph[:, None, :])).max(axis=1)

    per = {2: 720, 3: 90, 4: 28}.get(k, 0)
    if per:
        axes = [np.linspace(0, 2 * math.pi, per, endpoint=False)] * (k - 1)
        grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, k - 1)
    else:
        grid = np.random.default_rng(0).uniform(0, 2 * math.pi, (20_000, k - 1))
    vals = rho(grid)
    best = float(vals.max())
    for t0 in grid[np.argsort(vals)[::-1][:6]]:
        if best >= enough:
            break
        res = minimize(lambda t: -float(rho(t)[0]), t0, method="Nelder-Mead",
                       options={"xatol": 1e-12, "fatol": 1e-16, "maxiter": 4000})
        best = max(best, -float(res.fun))
    return best


def _commensurate(tau: np.ndarray) -> tuple[float, np.ndarray] | None:
    """``(h, n)`` with ``tau = n h`` for small integers ``n`` (ratios with denominators up to 64, to a relative
    1e-9), or None."""
    from fractions import Fraction

    base = float(tau.min())
    fr = [Fraction(float(t / base)).limit_denominator(_COMMENSURATE_DENOMINATOR) for t in tau]
    if any(abs(float(f) * base - t) > _RELATION_TOL * t for f, t in zip(fr, tau)):
        return None
    den = math.lcm(*(f.denominator for f in fr))
    n = np.array([int(f * den) for f in fr])
    return base / den, n


def _commensurate_abscissa(M: np.ndarray, h: float, n: np.ndarray) -> float:
    """The real parts' supremum of the roots of ``det(I - M diag(exp(-s n_j h)))``: the difference equation
    ``w_j[t] = sum_i M_ji w_i[t - n_j]`` in steps of ``h`` as a shift register; its eigenvalues ``mu`` give the
    chains ``Re s = ln|mu| / h`` (exactly: vertical lines)."""
    k, L = M.shape[0], int(n.max())
    T = np.zeros((k * L, k * L))
    for j in range(k):  # new w_j from the block of w delayed by n_j steps
        T[j, (n[j] - 1) * k:n[j] * k] = M[j]
    T[k:, :-k] = np.eye(k * (L - 1))
    mu = np.abs(np.linalg.eigvals(T)).max()
    return math.log(mu) / h if mu > 0 else -math.inf


@dataclass(frozen=True, repr=False)
class ChannelAbscissa:
    """Where the root chains of a system's difference operator ``det(I - D22 Delta(s))`` lie, channel by channel.

    Attributes
    ----------
    abscissa : float
        ``x*``: the supremum, over independent phases ``theta_j`` of the delay channels, of the real parts at which
        ``det(I - D22 diag(exp(-tau_j x + i theta_j)))`` vanishes: no root chain lies right of it for any delays,
        it is reached when the channels' delays are rationally independent (Kronecker), and ``x* < 0`` is strong
        stability (stable under every small change of each channel's delay).  An upper bound to ``tol``
        (conservative) in every case.
    lines : float
        The supremum for these delays: ``abscissa`` when the channels that feed one another have independent
        delays; the exact vertical lines when their delays are commensurate (rational ratios with denominators up
        to 64); otherwise ``abscissa`` (then ``exact_lines`` is False).
    delays : tuple of float
        The channels' delays (channels with zero delay eliminated first).
    exact : bool
        True when ``abscissa`` is the supremum to ``tol`` (its upper bound, the D-scaled norm, and its lower bound,
        a search over the phases, meet: always, in theory, for at most three channels feeding one another).
    exact_lines : bool
        True when ``lines`` is the supremum for these delays (not only a bound).
    tol : float
        The accuracy of ``abscissa`` (1/s).
    """

    abscissa: float
    lines: float
    delays: tuple[float, ...]
    exact: bool
    exact_lines: bool
    tol: float
    _groups: tuple = dataclasses.field(default=(), compare=False)
    _a0: float = dataclasses.field(default=1.0, compare=False)

    @property
    def strongly_stable(self) -> bool:
        """``abscissa < 0``: stable for every small change of each channel's delay."""
        return self.abscissa < 0

    def lead(self, x: float) -> float:
        """A lower bound on ``|det(I - D22 Delta(s))|`` over ``Re s >= x`` (0 where none is known).

        Per group of channels that feed one another, with its scaling ``S`` and ``X = S M R(x) S^-1``:
        ``prod_i (1 - sigma_i(X))`` (Weyl: ``sigma_i(I - Y) >= 1 - sigma_(k+1-i)(Y)``, and right of ``x`` the
        singular values of ``S M R Theta S^-1`` only shrink); ``1 - |m| exp(-tau x)`` for a channel that feeds
        only itself.
        """
        out = abs(self._a0)
        for g in self._groups:
            M, tau, d = g
            X = M * np.exp(-tau * x)[None, :]
            e = np.exp(d - d.mean())
            sv = np.linalg.svd(X * (e[:, None] / e[None, :]), compute_uv=False)
            if sv[0] >= 1.0 and M.shape[0] > 1:
                d = np.concatenate([[0.0], _best_scaling(X, d[1:] - d[0])[1]])
                e = np.exp(d - d.mean())
                sv = np.linalg.svd(X * (e[:, None] / e[None, :]), compute_uv=False)
            if sv[0] >= 1.0:
                return 0.0
            out *= float(np.prod(1.0 - sv))
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (infinite values as null)."""
        fin = lambda v: v if math.isfinite(v) else None  # noqa: E731
        return {"abscissa": fin(self.abscissa), "lines": fin(self.lines), "delays": list(self.delays),
                "exact": self.exact, "exact_lines": self.exact_lines, "tol": self.tol,
                "strongly_stable": self.strongly_stable}

    def __repr__(self) -> str:
        verdict = "strongly stable" if self.strongly_stable else "NOT strongly stable"
        how = "exact" if self.exact else "upper bound"
        close = self.lines >= self.abscissa - max(self.tol, 1e-12 * abs(self.abscissa))
        extra = "" if close else f", lines at {self.lines:.6g} for these delays"
        return (f"ChannelAbscissa({self.abscissa:.6g} ({verdict}, {how}){extra}, "
                f"{len(self.delays)} channel{'s' if len(self.delays) != 1 else ''})")


def channel_abscissa(D22: Any, delays: Sequence[float]) -> ChannelAbscissa:
    """The spectrum of the difference operator ``det(I - D22 Delta(s))`` of a system in LFT form, per channel.

    A neutral system's poles come in chains whose real parts accumulate on those of the roots of
    ``det(I - D22 diag(exp(-s tau_j)))``.  Expanding the determinant (:func:`neutral_abscissa` on the
    characteristic quasi-polynomial) gives terms whose delays are sums of the channels' and so are not
    independent, and the polygon bound on them is conservative.  Here the channels are kept:

    1. channels with zero delay are eliminated (``M = D_dd + D_d0 (I - D_00)^-1 D_0d``);
    2. the channels are split into groups that feed one another (the strongly connected components of the graph
       of ``M``): the determinant is the product of the groups' (block triangular form);
    3. for a group, with ``R(x) = diag(exp(-tau_j x))``, a root chain can reach ``Re s = x`` only if
       ``det(I - M R(x) Theta) = 0`` for some unit phases ``Theta``, i.e. ``mu(M R(x)) >= 1`` with ``mu`` the
       structured singular value for complex scalar channels, ``max_Theta rho(M R(x) Theta)`` (the maximum over
       the polydisc is reached on the torus; a common phase turns the eigenvalue to 1).  ``mu`` decreases with
       ``x``; ``x*`` is the root of ``mu(M R(x)) = 1``.  It is found from above by the D-scaled norm
       ``min_S ||S M R S^-1||`` (an upper bound of ``mu``, equal to it for up to three channels: Doyle 1982) and
       checked from below by a search over the phases; a channel that feeds only itself gives its line
       ``ln|m| / tau`` exactly.

    With the channels' delays rationally independent (Kronecker) ``x*`` is the exact supremum; for commensurate
    delays ``tau_j = n_j h`` the chains are vertical lines found exactly from a shift register (``lines``).

    Parameters
    ----------
    D22 : array_like, shape (m, m)
        The direct feedthrough between the delay channels.
    delays : sequence of float
        The channels' delays, ``>= 0``.

    Returns
    -------
    ChannelAbscissa

    Raises
    ------
    InvalidValueError
        For a non-square or non-finite ``D22``, delays that do not match, or zero-delay channels that form an
        algebraic loop that is not well posed (``I - D_00`` singular).

    See Also
    --------
    delaykit.spectrum.neutral.neutral_abscissa : the polygon bound of one quasi-polynomial.

    References
    ----------
    J. C. Doyle, "Analysis of feedback systems with structured uncertainties", IEE Proc. D 129 (1982).
    J. K. Hale and S. M. Verduyn Lunel, "Strong stabilization of neutral functional differential equations",
    IMA J. Math. Control Inform. 19 (2002).
    R. S. Sezginer and M. L. Overton, "The largest singular value of e^X A e^-X is convex on convex sets of
    commuting matrices", IEEE Trans. Automat. Control 35 (1990).

    Examples
    --------
    Two neutral loops side by side, ``1 - 0.6 exp(-s)`` and ``1 - 0.7 exp(-sqrt(2) s)``: the expanded
    determinant's moduli add up to 1.72, so the polygon bound is positive; per channel the lines are
    ``ln 0.6`` and ``ln(0.7) / sqrt(2)``:

    >>> ca = channel_abscissa([[0.6, 0], [0, 0.7]], [1.0, math.sqrt(2)])
    >>> ca
    ChannelAbscissa(-0.252207 (strongly stable, exact), 2 channels)
    >>> round(ca.abscissa - math.log(0.7) / math.sqrt(2), 15)
    0.0
    """
    from scipy.sparse.csgraph import connected_components

    D = np.asarray(D22, dtype=float) if not np.iscomplexobj(D22) else np.asarray(D22, complex)
    tau = np.asarray(delays, float).ravel()
    if D.ndim != 2 or D.shape[0] != D.shape[1] or D.shape[0] != tau.size:
        raise InvalidValueError(f"D22 must be square with one row per delay, got shape {D.shape} and {tau.size} "
                                "delays")
    if not (np.all(np.isfinite(D)) and np.all(np.isfinite(tau)) and np.all(tau >= 0)):
        raise InvalidValueError(f"finite D22 and delays >= 0 expected, got delays {tau.tolist()}")
    zero, pos = np.flatnonzero(tau == 0), np.flatnonzero(tau > 0)
    a0 = 1.0
    if zero.size:
        I0 = np.eye(zero.size) - D[np.ix_(zero, zero)]
        a0 = float(abs(np.linalg.det(I0)))
        if a0 <= 1e-12 * max(1.0, float(np.abs(D).max())) ** zero.size:
            raise InvalidValueError("the channels without delay form an algebraic loop that is not well posed "
                                    "(I - D22 restricted to them is singular)")
        M = D[np.ix_(pos, pos)] + D[np.ix_(pos, zero)] @ np.linalg.solve(I0, D[np.ix_(zero, pos)])
    else:
        M = D
    tau = tau[pos]
    scale = float(np.abs(M).max()) if M.size else 0.0
    if scale == 0.0:
        return ChannelAbscissa(-math.inf, -math.inf, tuple(float(t) for t in tau), True, True, 0.0, (), a0)
    adj = np.abs(M) > 1e-14 * scale
    ncomp, label = connected_components(adj, directed=True, connection="strong")
    groups, xs, lines, exact, exact_lines, tols = [], [], [], True, True, [0.0]
    for c in range(ncomp):
        idx = np.flatnonzero(label == c)
        Mc, tc = M[np.ix_(idx, idx)], tau[idx]
        if idx.size == 1:
            if not adj[idx[0], idx[0]]:
                continue  # a channel in no cycle: no chain
            x = math.log(abs(Mc[0, 0])) / tc[0]
            groups.append((Mc, tc, np.zeros(1)))
            xs.append(x)
            lines.append(x)
            continue
        x, d, ok, tol = _group_abscissa(Mc, tc)
        groups.append((Mc, tc, d))
        xs.append(x)
        tols.append(tol)
        exact &= ok
        if rationally_independent(tc):
            lines.append(x)
            exact_lines &= ok
            continue
        com = _commensurate(tc)
        if com is not None and Mc.shape[0] * int(com[1].max()) <= _COMMENSURATE_STATES:
            lines.append(min(x, _commensurate_abscissa(Mc, *com)))
        else:
            lines.append(x)
            exact_lines = False
    if not xs:
        return ChannelAbscissa(-math.inf, -math.inf, tuple(float(t) for t in tau), True, True, 0.0, (), a0)
    return ChannelAbscissa(float(max(xs)), float(max(lines)), tuple(float(t) for t in tau), exact, exact_lines,
                           float(max(tols)), tuple(groups), a0)


def _group_abscissa(M: np.ndarray, tau: np.ndarray) -> tuple[float, np.ndarray, bool, float]:
    """For channels that feed one another: ``x*`` from above (the root of the D-scaled norm of ``M R(x)`` at 1),
    the scaling there, whether the search over phases confirms it from below, and the tolerance."""
    from scipy.optimize import brentq

    k = M.shape[0]
    tol = _EXACT_TOL / float(tau.min())
    state = {"d": np.zeros(k - 1)}

    def logmu(x: float) -> float:
        nu, v = _best_scaling(M * np.exp(-tau * x)[None, :], state["d"])
        state["d"] = v
        return math.log(nu)

    # bracket: every exp(-tau x) <= 1 / ||M|| above hi; below, mu grows without bound along a cycle
    hi = float(np.max(math.log(float(np.linalg.norm(M, 2))) / tau)) + 1.0 / float(tau.max())
    lo = hi - 1.0 / float(tau.min())
    step = 1.0 / float(tau.min())
    for _ in range(200):
        if logmu(lo) >= 0.0:
            break
        step *= 2.0
        lo -= step
    else:
        return math.inf, np.zeros(k), False, tol  # no cycle reaches 1: not expected for a strongly connected group
    x = float(brentq(logmu, lo, hi, xtol=1e-4 * tol, rtol=4 * np.finfo(float).eps))
    logmu(x + 1e-4 * tol)  # the scaling just right of the root, where it gives a bound below 1
    d = np.concatenate([[0.0], state["d"]])
    ok = _torus_radius(M * np.exp(-tau * (x - tol))[None, :], enough=1.0) >= 1.0
    return x, d, bool(ok), tol
