"""Roots of first-order delay equations by the Lambert W function (the paper's section 3).

``x'(t) = a0 x(t) + a1 x(t - Td)`` has the characteristic equation ``s - a0 - a1 exp(-s Td) = 0``, whose roots
are ``s_k = W_k(Td a1 exp(-a0 Td)) / Td + a0`` for the branches ``k`` of Lambert's W.  For real coefficients
the rightmost root is on branch 0 (Shinozaki & Mori, 2006): ``W_0`` has the largest real part of all branches
for any argument, and where the argument is below ``-1/e`` branch -1 gives its complex conjugate, so the
dominant pair is ``{k = 0, k = -1}``.  At the branch point ``-1/e`` the two branches meet at ``W = -1``: a double
root, where SciPy's ``lambertw`` returns NaN (SciPy 1.17, on both branches); delaykit returns the double root there,
and near it uses the branch-point series (see :func:`lambert_w`).  Everywhere else the roots cost one call of
SciPy's ``lambertw`` per branch and a division.

For the P loop (``a0 = 0``, ``a1 = -Kp``), ``s Td = W(-Kp Td)``: the damping ratio of the dominant pair depends on
``Kp Td`` alone (1 at ``Kp Td = 1/e``, 0 at ``pi/2``, the stability limit).

Examples
--------
>>> r = lambert_roots(a0=0.0, a1=-1.31, delay=0.368, branches=[0, -1])
>>> r.rightmost
(-2.2246...+1.9683...j)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real

__all__ = ["LambertRoots", "MAX_BRANCH", "lambert_w", "lambert_roots", "dominant_root", "kp_delay_for_damping",
           "delay_for_damping", "complex_delays_for_root"]

_E = math.e
MAX_BRANCH = 2**31 - 1
"""The largest branch index in size (SciPy's ``lambertw`` takes a C long, 32 bits on some systems)."""
_NEAR = 1e-3  # |e x + 1| below this: the branch-point series replaces SciPy's value (see lambert_w)


def lambert_w(x: Any, k: int = 0) -> np.ndarray:
    """Lambert W on branch ``k``, vectorised, accurate near and exactly at the branch point -1/e.

    SciPy's ``lambertw`` is accurate to a few units of the last place everywhere except close to the branch point
    ``-1/e``, where it loses digits and gives NaN exactly there.  Within ``|e x + 1| < 1e-3`` of it, on the branches
    that meet there (0 and -1 from the upper half-plane and the cut, 0 and 1 from the lower half-plane), this uses
    the branch-point series polished by two Halley steps on ``w e^w = x``; everywhere else it returns SciPy's value
    as it is (a polish there changes nothing: both agree with mpmath to about 1e-15).

    Examples
    --------
    >>> complex(lambert_w(-1 / np.e, 0)), complex(lambert_w(-1 / np.e, -1))
    ((-1+0j), (-1+0j))
    """
    from scipy.special import lambertw  # on first use: importing scipy.special costs roots and margins 0.3 to 1 s

    x = np.asarray(x)
    if x.dtype.kind not in "fc":
        x = x.astype(float)
    w = np.asarray(lambertw(x, k), dtype=complex)
    if k not in (-1, 0, 1):
        return w
    near = np.abs(x + 1.0 / _E) < _NEAR / _E
    if not np.any(near):
        return w
    shape = w.shape
    w = w.reshape(-1)
    idx = np.flatnonzero(near.reshape(-1))
    xn = x.reshape(-1)[idx].astype(complex)
    below = xn.imag < 0  # the cut itself (Im x = +-0) belongs to the upper half-plane, as in SciPy and mpmath
    # which of the two sheets meeting at -1/e: W = -1 + p on branch 0, -1 - p on branch -1 (from above) or 1 (below)
    if k == 0:
        use, sign = np.ones(idx.size, dtype=bool), 1.0
    else:
        use, sign = (~below if k == -1 else below), -1.0
    if not np.any(use):
        return w.reshape(shape)
    idx, xn = idx[use], xn[use]
    q = _E * xn + 1.0
    q = np.where(xn.imag == 0, q.real + 0j, q)  # a real x gives a real q (no -0 imaginary part to flip the sqrt)
    p = sign * np.sqrt(2.0 * q)  # the principal root: Im p has the sign of Im x, and Im p >= 0 on the cut
    # W = -1 + p - p^2/3 + 11/72 p^3 - 43/540 p^4 + O(p^5), p = +-sqrt(2 (e x + 1))
    wn = -1.0 + p * (1.0 + p * (-1.0 / 3.0 + p * (11.0 / 72.0 - p * 43.0 / 540.0)))
    with np.errstate(all="ignore"):
        for _ in range(2):  # Halley on w e^w = x, skipped at the branch point itself (where w + 1 = 0)
            ew = np.exp(wn)
            f = wn * ew - xn
            wp1 = wn + 1.0
            step = f / (ew * wp1 - (wn + 2.0) * f / (2.0 * wp1))
            wn = np.where((np.abs(wp1) > 1e-8) & np.isfinite(step), wn - step, wn)
    w[idx] = wn
    return w.reshape(shape)


@dataclass(frozen=True, repr=False, eq=False)
class LambertRoots:
    """Roots ``s_k`` of ``s - a0 - a1 exp(-s Td) = 0`` on the requested branches.

    Attributes
    ----------
    branches : tuple of int
    roots : ndarray
        Shape ``(len(branches),) + broadcast shape of the parameters``.
    """

    branches: tuple[int, ...]
    roots: np.ndarray
    a0: Any
    a1: Any
    delay: Any

    @property
    def rightmost(self) -> Any:
        """The root of largest real part over the computed branches (with Im >= 0 on a tie)."""
        r = self.roots
        with np.errstate(invalid="ignore"):
            score = r.real + 1e-12 * np.sign(r.imag)
        # a branch without a root (W_k(0) = -inf + nan j for k != 0, where a1 = 0) is never the rightmost
        score = np.where(np.isnan(score), -np.inf, score)
        i = np.argmax(score, axis=0)
        out = np.take_along_axis(r, i[None, ...], axis=0)[0]
        return complex(out) if out.ndim == 0 else out

    def sorted(self) -> np.ndarray:
        """Roots sorted by decreasing real part (for scalar parameters)."""
        r = self.roots.reshape(len(self.branches), -1)[:, 0] if self.roots.ndim > 1 else self.roots
        return r[np.argsort(-r.real, kind="stable")]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form for scalar parameters: ``{"roots": [{"branch", "re", "im"}], "rightmost": [re, im]}``."""
        if self.roots.ndim != 1:
            raise InvalidValueError("to_dict needs scalar a0, a1 and delay")
        rm = self.rightmost
        return {"roots": [{"branch": k, "re": float(s.real), "im": float(s.imag)} for k, s in zip(self.branches, self.roots)],
                "rightmost": [float(rm.real), float(rm.imag)]}

    def __repr__(self) -> str:
        if self.roots.ndim == 1:
            rm = self.rightmost
            return f"LambertRoots({len(self.branches)} branches, rightmost={rm.real:.4f}{rm.imag:+.4f}j)"
        return f"LambertRoots({len(self.branches)} branches × {self.roots.shape[1:]} parameter sets)"


def _branches(branches: Iterable[int] | int) -> tuple[int, ...]:
    """The branch indices: integers of at most :data:`MAX_BRANCH` in size, at most
    :data:`~delaykit.models.budget.MAX_RANGE_POINTS` of them."""
    from ..models.budget import MAX_RANGE_POINTS, check_count

    if isinstance(branches, (int, np.integer)):
        branches = [int(branches)]
    if isinstance(branches, range):  # counted before it is listed (range(-10**8, 10**8) is cheap to hold)
        check_count("branches", len(branches), MAX_RANGE_POINTS, "branches", "ask for fewer branches")
    try:
        if isinstance(branches, (str, bytes)):
            raise TypeError
        items = iter(branches)
    except TypeError:
        raise InvalidTypeError(f"branches must be an integer or integers, got {branches!r:.40} "
                               f"({type(branches).__name__})") from None
    out: list[int] = []
    for k in items:
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, (int, np.integer)):
            raise InvalidTypeError(f"a Lambert W branch must be an integer, got {k!r} ({type(k).__name__})")
        if abs(int(k)) > MAX_BRANCH:
            raise InvalidValueError(f"Lambert W branch {int(k)} is out of range: at most {MAX_BRANCH} in size "
                                    "(SciPy's lambertw takes a C long)")
        out.append(int(k))
        check_count("branches", len(out), MAX_RANGE_POINTS, "branches", "ask for fewer branches")
    if not out:
        raise InvalidValueError("branches must name at least one branch")
    return tuple(out)


def _numbers(v: Any) -> np.ndarray:
    """``v`` as a float array, or a complex one if it has a nonzero imaginary part (TypeError, ValueError if not
    numbers)."""
    a = np.asarray(v)
    if a.dtype.kind == "c":
        return a.real.astype(float) if not np.any(a.imag) else a.astype(complex, copy=False)
    if a.dtype.kind in "biuf":
        return a.astype(float, copy=False)
    return np.asarray(a, dtype=complex)  # objects, strings: numbers or a TypeError / ValueError


def lambert_roots(a0: Any, a1: Any, delay: Any, branches: Iterable[int] | int = (0, -1)) -> LambertRoots:
    """Characteristic roots of ``x' = a0 x + a1 x(t - Td)`` on the given Lambert W branches, vectorised.

    Parameters
    ----------
    a0, a1 : complex or array_like
        Coefficients (real or complex), broadcast with ``delay``.
    delay : float or array_like
        ``Td >= 0``; at ``Td = 0`` the equation is an ODE with the single root ``a0 + a1`` (reported on every
        branch, as the limit of branch 0; the other branches run off to ``-inf``).
    branches : iterable of int
        Lambert W branches.

    Returns
    -------
    LambertRoots

    Examples
    --------
    >>> r = lambert_roots(0.0, -1.31, 0.368, branches=range(-2, 3))
    >>> [round(float(abs(s - 0.0 - (-1.31) * np.exp(-s * 0.368))), 12) for s in r.roots]
    [0.0, 0.0, 0.0, 0.0, 0.0]
    """
    ks = _branches(branches)
    try:
        # real coefficients stay real (no copy for float arrays): real arithmetic up to W
        a0a, a1a = (_numbers(v) for v in (a0, a1))
        td = np.asarray(delay, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidValueError(f"a0, a1 and delay must be numbers: {exc}") from exc
    for name, arr in (("a0", a0a), ("a1", a1a), ("delay", td)):
        if not np.all(np.isfinite(arr)):
            raise InvalidValueError(f"{name} must be finite, got {arr}")
    if np.any(td < 0):
        raise InvalidValueError(f"delay must be at least 0, got {td.min():g}")
    a0b, a1b, tdb = np.broadcast_arrays(a0a, a1a, td)
    shift = bool(np.any(a0a))  # a0 = 0 (the P loop): no exponential factor, no shift of the roots
    with np.errstate(over="ignore", invalid="ignore"):
        x = tdb * a1b * np.exp(-a0b * tdb) if shift else tdb * a1b
    if shift:
        x = np.where(a1b == 0, 0.0, x)  # (a1 = 0 gives 0 whatever the exponential: not inf * 0)
    if not np.all(np.isfinite(x)):  # beyond floating point: exp(-a0 Td) or the product overflows
        bad = np.flatnonzero(~np.isfinite(np.broadcast_to(x, x.shape)).ravel())[0]
        raise InvalidValueError(f"Td a1 exp(-a0 Td) overflows for a0 = {a0b.ravel()[bad]}, a1 = {a1b.ravel()[bad]}, "
                                f"Td = {tdb.ravel()[bad]} (the exponent -a0 Td may be at most about 709)")
    pos = tdb > 0
    every = bool(np.all(pos))
    safe_td = tdb if every else np.where(pos, tdb, 1.0)
    per_branch = []
    for k in ks:
        r = lambert_w(x, k)  # a new array: the root is formed in place
        with np.errstate(all="ignore"):  # at Td = 0 the W value is not used
            np.divide(r, safe_td, out=r)
        if shift:
            r += a0b
        if not every:
            r = np.where(pos, r, a0b + a1b)
        per_branch.append(r)
    roots = per_branch[0][np.newaxis] if len(ks) == 1 else np.stack(per_branch)
    return LambertRoots(branches=ks, roots=roots, a0=a0, a1=a1, delay=delay)


def dominant_root(kp: Any, delay: Any) -> Any:
    """The dominant (upper) root of the P loop ``s + Kp exp(-s Td) = 0``: ``W_0(-Kp Td) / Td``.

    Examples
    --------
    >>> s = dominant_root(1.31, 0.368)
    >>> round(s.real, 4), round(s.imag, 4)
    (-2.2247, 1.9683)
    """
    r = lambert_roots(0.0, -np.asarray(kp, dtype=float), delay, branches=[0]).roots[0]
    r = np.where(r.imag < 0, np.conj(r), r)
    return complex(r) if r.ndim == 0 else r


def _damping(kappa: float) -> float:
    w = complex(lambert_w(-kappa, 0))
    return -w.real / abs(w) if w.imag != 0 else 1.0


def kp_delay_for_damping(zeta: float) -> float:
    """The product ``Kp Td`` at which the P loop's dominant pair has damping ratio ``zeta`` (0 < zeta < 1).

    The dominant root is ``W_0(-Kp Td) / Td``, so its damping depends on ``Kp Td`` only: from 1 at ``1/e``
    (a double real root) down to 0 at ``pi/2`` (the stability limit).

    Examples
    --------
    >>> round(kp_delay_for_damping(0.7684), 4)
    0.4714
    """
    z = check_real("zeta (damping ratio)", zeta, minimum=0.0, strict=True)
    if z >= 1.0:
        raise InvalidValueError(f"zeta must be below 1 (an oscillatory pair), got {z:g}; at zeta = 1, Kp Td = 1/e")
    from scipy.optimize import brentq  # (here: importing scipy.optimize costs every command a good 0.3 s)

    lo, hi = 1.0 / _E + 1e-15, math.pi / 2
    return brentq(lambda k: _damping(k) - z, lo, hi, xtol=1e-15)


def delay_for_damping(zeta: float, kp: float) -> float:
    """The delay at which the P loop with gain ``kp`` has a dominant pair of damping ``zeta``.

    Examples
    --------
    >>> round(delay_for_damping(0.7684, kp=1.31), 4)
    0.3598
    """
    kp = check_real("kp", kp, minimum=0.0, strict=True)
    return kp_delay_for_damping(zeta) / kp


def complex_delays_for_root(root: complex, a0: complex, a1: complex, ks: Iterable[int] = range(-2, 3)) -> np.ndarray:
    """Every (generally complex) ``Td`` for which ``root`` solves ``s - a0 - a1 exp(-s Td) = 0``.

    ``exp(-s Td) = (s - a0) / a1`` gives ``Td_k = -(Log((s - a0) / a1) + 2 pi i k) / s``.  A real delay exists
    only if one of these is real; for the paper's root ``-1.2347 + 1.0284j`` with ``a1 = -1.31`` none is, and
    an unconstrained solver lands on a complex one (section 5.1.2 reports its real part).

    Examples
    --------
    >>> td = complex_delays_for_root(-1.2347 + 1.0284j, 0.0, -1.31, ks=[0])
    >>> complex(np.round(td[0], 4))
    (0.3743-0.2507j)
    """
    s = complex(root)
    if s == 0:
        raise InvalidValueError("root must not be 0")
    if complex(a1) == 0:
        raise InvalidValueError("a1 must not be 0 (there is no delayed term)")
    lg = np.log(complex((s - complex(a0)) / complex(a1)))
    k = np.asarray(list(ks))
    return -(lg + 2j * np.pi * k) / s
