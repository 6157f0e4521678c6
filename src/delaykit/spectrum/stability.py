"""Stability of delay loops: rightmost root, spectral abscissa, delay margin, and stability maps.

Examples
--------
>>> from delaykit import AltitudeLoop
>>> r = rightmost(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3))
>>> r
Rightmost(root=-3.1951+5.5820j, abscissa=-3.1951, neutral line -3.2540, stable)
>>> m = delay_margin(AltitudeLoop(kp=1.31, delay=0.368))
>>> round(m.delay, 6) == round(3.141592653589793 / 2 / 1.31, 6)
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.altitude import AltitudeLoop
from ..models.loop import Loop
from ..models.quasipolynomial import QuasiPolynomial
from .lambert import lambert_roots
from .roots import Spectrum, find_roots, neutral_lines, root_bound

__all__ = ["Rightmost", "DelayMargin", "StabilityMap", "rightmost", "delay_margin", "stability_map"]


@dataclass(frozen=True, repr=False)
class Rightmost:
    """The rightmost root and the spectral abscissa of a quasi-polynomial.

    ``abscissa`` is the supremum of the real parts of all roots: the rightmost root's real part, or a neutral
    line if that lies further right (root chains approach it).  ``stable`` means ``abscissa < 0``; for a
    neutral loop that also requires the neutral line to lie left of the imaginary axis (|Kv| < 1 for the PV loop).
    """

    root: complex | None
    abscissa: float
    neutral_lines: tuple[float, ...]
    certified: bool
    spectrum: Spectrum

    @property
    def stable(self) -> bool:
        """Asymptotically stable (spectral abscissa below zero)."""
        return self.abscissa < 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        r = self.root
        return {"rightmost": None if r is None else [r.real, r.imag], "abscissa": self.abscissa,
                "neutral_lines": list(self.neutral_lines), "stable": self.stable, "certified": self.certified}

    def __repr__(self) -> str:
        r = "none" if self.root is None else f"{self.root.real:.4f}{self.root.imag:+.4f}j"
        nl = f", neutral line {self.neutral_lines[0]:.4f}" if len(self.neutral_lines) == 1 else ""
        return (f"Rightmost(root={r}, abscissa={self.abscissa:.4f}{nl}, {'stable' if self.stable else 'UNSTABLE'}"
                + ("" if self.certified else ", not certified") + ")")


def _as_qp(q: QuasiPolynomial | AltitudeLoop | Loop) -> QuasiPolynomial:
    if isinstance(q, (AltitudeLoop, Loop)):
        return q.characteristic()
    if isinstance(q, QuasiPolynomial):
        return q
    raise InvalidTypeError(f"expected a QuasiPolynomial, a Loop or an AltitudeLoop, got {type(q).__name__}")


def rightmost(q: QuasiPolynomial | AltitudeLoop, *, re_min: float | None = None) -> Rightmost:
    """The rightmost root (Im >= 0) and the spectral abscissa, from a region that provably holds it.

    For a retarded quasi-polynomial every root with ``Re s >= x`` has ``|s| <= R(x)`` (:func:`root_bound`),
    so the roots in ``[x, R] x [0, R]`` include the rightmost one as soon as there is any; ``x`` starts at
    ``re_min`` (default -1) and moves left until a root is found.  For a neutral one ``x`` stays right of the
    neutral line, where the bound holds; if no root lies there, the abscissa is the line itself.

    Examples
    --------
    >>> rightmost(AltitudeLoop(kp=1.31, delay=0.368)).root
    (-2.2246...+1.9683...j)
    """
    q = _as_qp(q)
    lines = neutral_lines(q) if q.kind == "neutral" else ()
    if q.kind == "advanced":
        raise InvalidValueError("an advanced quasi-polynomial has no rightmost root (its roots are unbounded to the right)")
    x = -1.0 if re_min is None else check_real("re_min", re_min)
    tmax = max(q.delays)
    eps = 0.02
    if lines:
        # roots right of the neutral line are bounded (the bound grows like 1 / (x - line)); a root found right
        # of x is the rightmost of all, so x moves towards the line until one is found
        x = max(lines) + eps / tmax if re_min is None else max(x, max(lines) + eps / tmax)
    sym = all(c.imag == 0 for p in q.polys for c in p)
    for _ in range(60):
        R = root_bound(q, x)
        region = (x, R, 0.0 if sym else -R, R)
        sp = find_roots(q, region)
        if sp.roots.size:
            break
        if lines:
            eps /= 10.0
            if eps < 1e-5:
                break
            x = max(lines) + eps / tmax
        else:
            x = 2.0 * x - 1.0
    root = sp.rightmost
    xs = ([root.real] if root is not None else []) + list(lines)
    return Rightmost(root=root, abscissa=max(xs) if xs else -math.inf, neutral_lines=lines,
                     certified=sp.certified, spectrum=sp)


@dataclass(frozen=True, repr=False)
class DelayMargin:
    """The largest delay for which a single-delay loop stays stable, with the crossing frequency.

    ``delay`` is ``inf`` when no crossing exists (stable for every delay) and ``0`` when the loop is unstable
    without delay.
    """

    delay: float
    frequency: float | None
    crossings: tuple[tuple[float, float], ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"delay_margin": self.delay, "frequency": self.frequency,
                "crossings": [{"frequency": w, "first_delay": t} for w, t in self.crossings]}

    def __repr__(self) -> str:
        f = "" if self.frequency is None else f" at {self.frequency:.4f} rad/s"
        return f"DelayMargin({self.delay:.6g} s{f})"


def delay_margin(q: QuasiPolynomial | AltitudeLoop) -> DelayMargin:
    """Delay margin of ``P0(s) + P1(s) exp(-s tau)`` (one delay), exactly from the crossing frequencies.

    Roots cross the imaginary axis at ``s = j w`` only where ``|P0(jw)| = |P1(jw)|``, a polynomial equation in
    ``w``; at each such ``w`` the smallest delay is ``tau = arg(-P1(jw) / P0(jw)) / w`` taken in ``(0, 2 pi / w]``.
    The margin is the smallest of these, provided the loop is stable without delay (``P0 + P1`` Hurwitz).

    Examples
    --------
    >>> delay_margin(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3))
    DelayMargin(0.894551 s at 2.0966 rad/s)
    """
    q = _as_qp(q)
    taus = [t for t in q.delays if t > 0]
    if len(taus) > 1:
        raise InvalidValueError(f"delay_margin needs one delay, the quasi-polynomial has {len(taus)}")
    p0 = np.array(q.polys[0]) if q.delays[0] == 0.0 else np.zeros(1, complex)
    p1 = np.array(q.polys[-1]) if q.delays[-1] > 0 else np.zeros(1, complex)
    if not taus:  # no delay in it: just the polynomial
        p1 = np.zeros(1, complex)
    # stability without delay
    r0 = np.roots(np.polyadd(p0, p1))
    if r0.size and np.max(r0.real) >= 0:
        return DelayMargin(0.0, None, ())
    if len(p0) == len(p1) and abs(p1[0]) >= abs(p0[0]):
        return DelayMargin(0.0, None, ())  # neutral with |Kv| >= 1: not stable for any delay > 0
    # |P0(jw)|^2 - |P1(jw)|^2 = 0 as a polynomial in w
    def sq(p):
        pj = np.array([c * (1j) ** (len(p) - 1 - k) for k, c in enumerate(p)])  # P(jw) in powers of w
        return np.polymul(pj, np.conj(pj)).real
    diff = np.polysub(sq(p0), sq(p1))
    ws = [w.real for w in np.roots(diff) if abs(w.imag) < 1e-9 * (1 + abs(w)) and w.real > 1e-12]
    crossings = []
    for w in sorted(set(round(w, 12) for w in ws)):
        # P0(jw) + P1(jw) exp(-j w tau) = 0  =>  exp(-j w tau) = z = -P0(jw) / P1(jw), |z| = 1
        z = -np.polyval(p0, 1j * w) / np.polyval(p1, 1j * w)
        tau = (-np.angle(z)) % (2 * math.pi) / w
        crossings.append((float(w), float(tau if tau > 0 else 2 * math.pi / w)))
    if not crossings:
        return DelayMargin(math.inf, None, ())
    w, tau = min(crossings, key=lambda c: c[1])
    return DelayMargin(tau, w, tuple(crossings))


@dataclass(frozen=True, repr=False, eq=False)
class StabilityMap:
    """Spectral abscissa over a grid of two loop parameters."""

    x_name: str
    y_name: str
    x: np.ndarray
    y: np.ndarray
    abscissa: np.ndarray  # shape (len(y), len(x))

    @property
    def stable(self) -> np.ndarray:
        """Boolean grid: spectral abscissa below zero."""
        return self.abscissa < 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"x_name": self.x_name, "y_name": self.y_name, "x": self.x.tolist(), "y": self.y.tolist(),
                "abscissa": self.abscissa.tolist()}

    def __repr__(self) -> str:
        return (f"StabilityMap({self.y_name} × {self.x_name}: {self.abscissa.shape[0]}×{self.abscissa.shape[1]}, "
                f"{int(self.stable.sum())} stable points)")


def _integrator_p_gain(loop: Any) -> float | None:
    """The plant gain k of a P loop on k/s with no output delay (so ``s + k Kp exp(-s Td)``), else None."""
    if isinstance(loop, AltitudeLoop):
        return loop.gain if loop.kv == 0 and loop.lag == 0 else None
    if isinstance(loop, Loop) and loop.controller.kind == "p" and loop.output_delay == 0:
        p = loop.plant
        if p.order == 1 and p.integrators == 1 and p.num.size == 1:
            return float(p.num[0])
    return None


def stability_map(
    base: AltitudeLoop | Loop,
    x_name: str,
    x: Any,
    y_name: str,
    y: Any,
    progress: Callable[[int, int], None] | None = None,
) -> StabilityMap:
    """Spectral abscissa of ``base`` with two of its fields (``kp``, ``kv``, ``delay``, ...) set over a grid.

    P loops use the Lambert W root directly (vectorised); others the certified rightmost-root search.

    Examples
    --------
    >>> m = stability_map(AltitudeLoop(kp=1.0, delay=0.3), "kp", [1, 4, 6], "delay", [0.3])
    >>> m.stable.tolist()
    [[True, True, False]]
    """
    xs = np.asarray(x, dtype=float).ravel()
    ys = np.asarray(y, dtype=float).ravel()
    if xs.size == 0 or ys.size == 0:
        raise InvalidValueError("the grid is empty: give at least one value for each parameter")
    out = np.empty((ys.size, xs.size))
    # a P loop on k/s (the paper's, with its speed gain): the Lambert W root, vectorised
    g = _integrator_p_gain(base)
    if g is not None and {x_name, y_name} <= {"kp", "delay"}:
        X, Y = np.meshgrid(xs, ys)
        kp = X if x_name == "kp" else Y
        td = X if x_name == "delay" else Y
        r = lambert_roots(0.0, -g * kp, td, branches=[0]).roots[0]
        return StabilityMap(x_name, y_name, xs, ys, r.real)
    total = xs.size * ys.size
    k = 0
    for i, yv in enumerate(ys):
        for j, xv in enumerate(xs):
            out[i, j] = rightmost(base.replace(**{x_name: float(xv), y_name: float(yv)})).abscissa
            k += 1
            if progress:
                progress(k, total)
    return StabilityMap(x_name, y_name, xs, ys, out)
