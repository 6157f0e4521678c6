"""Roots of first-order delay equations by the Lambert W function (the paper's section 3).

``x'(t) = a0 x(t) + a1 x(t - Td)`` has the characteristic equation ``s - a0 - a1 exp(-s Td) = 0``, whose roots
are ``s_k = W_k(Td a1 exp(-a0 Td)) / Td + a0`` for the branches ``k`` of Lambert's W.  For real coefficients
the rightmost root is on branch 0 (Shinozaki & Mori, 2006): ``W_0`` has the largest real part of all branches
for any argument, and where the argument is below ``-1/e`` branch -1 gives its complex conjugate, so the
dominant pair is ``{k = 0, k = -1}``.  At the branch point ``-1/e`` the two branches meet at ``W = -1``: a double
root, where SciPy's ``lambertw`` returns NaN on branch -1; delaykit returns the double root there.

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
from scipy.optimize import brentq
from scipy.special import lambertw

from ..errors import InvalidValueError, check_real

__all__ = ["LambertRoots", "lambert_w", "lambert_roots", "dominant_root", "kp_delay_for_damping",
           "delay_for_damping", "complex_delays_for_root"]

_E = math.e


def lambert_w(x: Any, k: int = 0) -> np.ndarray:
    """Lambert W on branch ``k``, vectorised, accurate near and exactly at the branch point -1/e.

    SciPy's ``lambertw`` loses accuracy near ``-1/e`` and gives NaN exactly there on branch -1; this uses the
    branch-point series there and polishes every value with two Halley steps on ``w e^w = x``.

    Examples
    --------
    >>> complex(lambert_w(-1 / np.e, 0)), complex(lambert_w(-1 / np.e, -1))
    ((-1+0j), (-1+0j))
    """
    x = np.asarray(x, dtype=complex)
    w = np.asarray(lambertw(x, k), dtype=complex)
    q = _E * x + 1.0  # distance from the branch point, scaled
    near = np.abs(q) < 1e-3
    if np.any(near) and k in (0, -1):
        # W = -1 + p - p^2/3 + 11/72 p^3 - 43/540 p^4, p = +-sqrt(2 (e x + 1)); the sign picks the branch
        p = np.sqrt(2.0 * q[near])
        # principal sqrt has Re p >= 0; W_0 takes the root with Re(p) >= 0 for x above the cut and the one with
        # Im(p) >= 0 on the cut (x < -1/e real); W_-1 the other
        p = np.where((p.real == 0) & (p.imag < 0), -p, p)
        if k == -1:
            p = -p
        w_near = -1.0 + p - p**2 / 3.0 + 11.0 / 72.0 * p**3 - 43.0 / 540.0 * p**4
        w = w.copy()
        w[near] = w_near
    # Halley polish (skipped exactly at the branch point, where w + 1 = 0)
    with np.errstate(all="ignore"):  # W is -inf at x = 0 on branches other than 0: left as it is
        for _ in range(2):
            ew = np.exp(w)
            f = w * ew - x
            wp1 = w + 1.0
            ok = (np.abs(wp1) > 1e-8) & np.isfinite(w)
            step = f / (ew * wp1 - (w + 2.0) * f / (2.0 * wp1))
            w = np.where(ok & np.isfinite(step), w - step, w)
    return w


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
        score = r.real + 1e-12 * np.sign(r.imag)
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
    if isinstance(branches, (int, np.integer)):
        branches = [int(branches)]
    out = tuple(int(k) for k in branches)
    if not out:
        raise InvalidValueError("branches must name at least one branch")
    return out


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
        a0a = np.asarray(a0, dtype=complex)
        a1a = np.asarray(a1, dtype=complex)
        td = np.asarray(delay, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidValueError(f"a0, a1 and delay must be numbers: {exc}") from exc
    for name, arr in (("a0", a0a), ("a1", a1a), ("delay", td)):
        if not np.all(np.isfinite(arr)):
            raise InvalidValueError(f"{name} must be finite, got {arr}")
    if np.any(td < 0):
        raise InvalidValueError(f"delay must be at least 0, got {td.min():g}")
    a0b, a1b, tdb = np.broadcast_arrays(a0a, a1a, td)
    x = tdb * a1b * np.exp(-a0b * tdb)
    pos = tdb > 0
    roots = np.empty((len(ks),) + tdb.shape, dtype=complex)
    safe_td = np.where(pos, tdb, 1.0)
    for i, k in enumerate(ks):
        w = lambert_w(x, k)
        with np.errstate(all="ignore"):  # at Td = 0 the W value is not used
            roots[i] = np.where(pos, w / safe_td + a0b, a0b + a1b)
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
