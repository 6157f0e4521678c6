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
import os
import threading
from concurrent.futures import ThreadPoolExecutor
import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from .. import _native
from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.altitude import AltitudeLoop
from ..models.budget import MAX_GRID_POINTS, check_count
from ..models.loop import Loop
from ..models.quasipolynomial import QuasiPolynomial
from .lambert import lambert_roots
from .roots import (RK, _CAP, _MAX_PHASE, _RELIABLE, RootStatus, Spectrum, _count, _Eval, _nudged_count,
                    find_roots, neutral_lines, root_bound)

__all__ = ["Rightmost", "DelayMargin", "StabilityMap", "rightmost", "delay_margin", "stability_map",
           "right_half_plane_count", "in_delay_units", "far_right_verdict"]


@dataclass(frozen=True, repr=False)
class Rightmost:
    """The rightmost root and the spectral abscissa of a quasi-polynomial.

    ``abscissa`` is the supremum of the real parts of all roots: the rightmost root's real part, or a neutral
    line if that lies further right (root chains approach it).  ``stable`` means ``abscissa < 0``; for a
    neutral loop that also requires the neutral line to lie left of the imaginary axis (``|Kv| < 1`` for the PV loop).
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


# -- the search for the rightmost root ---------------------------------------------------------------------------
_TILE_POINTS = 2_000_000
"""The most candidate-grid points one :func:`find_roots` call may use (its grid costs 8 bytes a point); a larger
region is split, and its parts that hold no root (by the argument principle) are dropped unsearched."""
_MAX_PARTS = 4096
"""The most parts (root searches and counts) one region may be split into."""
_MAX_STRIPS = 400
"""The most strips a rightmost-root search moves left by before it stops, uncertified."""


def _grid_points(box: tuple[float, float, float, float], taumax: float) -> float:
    """Candidate-grid points :func:`find_roots` would use on ``box`` (its own default grid and 5 % margin)."""
    x0, x1, y0, y1 = box
    w, h = x1 - x0, y1 - y0
    dy = min(h / 24.0, 2 * math.pi / (6.0 * taumax) if taumax > 0 else math.inf)
    dx = min(w / 24.0, 4 * dy)
    grow = 0.1 * max(w, h)
    return ((w + grow) / dx + 3.0) * ((h + grow) / dy + 3.0)


def _contour_samples(box: tuple[float, float, float, float], taumax: float) -> float:
    """The samples the argument principle starts with on the boundary of ``box`` (before any refinement)."""
    x0, x1, y0, y1 = box
    return 2.0 * ((x1 - x0) + (y1 - y0)) * (taumax + 0.25) / _MAX_PHASE + 32.0


def _merge(q: QuasiPolynomial, box: tuple[float, float, float, float], parts: list[Spectrum],
           failure: tuple[RootStatus, str] | None, lines: tuple[float, ...]) -> Spectrum:
    """One :class:`Spectrum` for ``box`` from the spectra of its parts (a root on a shared edge counted once)."""
    roots = np.concatenate([p.roots for p in parts]) if parts else np.zeros(0, complex)
    mult = np.concatenate([p.multiplicities for p in parts]) if parts else np.zeros(0, int)
    keep_r: list[complex] = []
    keep_m: list[int] = []
    for z, m in zip(roots, mult):
        hit = next((i for i, k in enumerate(keep_r) if abs(k - z) <= 1e-9 * (1.0 + abs(z))), None)
        if hit is None:
            keep_r.append(complex(z))
            keep_m.append(int(m))
        else:
            keep_m[hit] = max(keep_m[hit], int(m))
    r, m = np.array(keep_r, complex), np.array(keep_m, int)
    order = np.lexsort((-r.imag, -r.real)) if r.size else np.zeros(0, int)
    bad = failure or next(((p.status, p.reason) for p in parts if not p.certified), None)
    return Spectrum(roots=r[order], multiplicities=m[order], region=box,
                    count=int(m.sum()) if bad is None else None, certified=bad is None,
                    reason="" if bad is None else bad[1], kind=q.kind, neutral_lines=lines,
                    evaluations=sum(p.evaluations for p in parts),
                    status=RootStatus.CERTIFIED if bad is None else bad[0])


def _search(q: QuasiPolynomial, box: tuple[float, float, float, float], lines: tuple[float, ...]) -> Spectrum:
    """Every root of ``q`` in ``box``, in bounded memory.

    A region whose candidate grid would exceed :data:`_TILE_POINTS` is split in two across its longer side; a part
    is first counted by the argument principle and, with no root in it, dropped.  So a tall strip that holds a few
    roots (or none) costs a few boundary integrals, not a grid over all of it.
    """
    taumax = max(q.delays)
    if _contour_samples(box, taumax) > _CAP:
        where = tuple(round(v, 6) for v in box)
        return _merge(q, box, [], (RootStatus.SAMPLE_BUDGET, f"the region {where} is too large to certify: its "
                                   f"boundary needs more than {_CAP} samples"), lines)
    ev = _Eval(q)
    parts: list[Spectrum] = []
    stack = [box]
    used = 0
    while stack:
        b = stack.pop()
        used += 1
        if used > _MAX_PARTS:
            return _merge(q, box, parts, (RootStatus.SAMPLE_BUDGET,
                                          f"the region {box} needs more than {_MAX_PARTS} parts to search"), lines)
        if _grid_points(b, taumax) <= _TILE_POINTS:
            parts.append(find_roots(q, b))
            continue
        _, cnt = _nudged_count(ev, b)
        if not cnt.ok:
            return _merge(q, box, parts, (cnt.status, cnt.reason), lines)
        if cnt.n == 0:
            continue
        x0, x1, y0, y1 = b
        if (x1 - x0) >= (y1 - y0):
            c = 0.5 * (x0 + x1)
            stack += [(x0, c, y0, y1), (c, x1, y0, y1)]
        else:
            c = 0.5 * (y0 + y1)
            stack += [(x0, x1, y0, c), (x0, x1, c, y1)]
    return _merge(q, box, parts, None, lines)


def _without_zero_root(sp: Spectrum, k: int) -> Spectrum:
    """``sp`` without ``k`` of the multiplicity of its root at ``s = 0`` (a compensator's structural roots that
    :meth:`~delaykit.models.loop.Loop.characteristic` could not divide out), and its count reduced to match."""
    if not sp.roots.size:
        return sp
    scale = max(1.0, float(np.max(np.abs(sp.roots))))
    at = np.flatnonzero(np.abs(sp.roots) <= 1e-7 * scale)
    if not at.size:
        return sp
    i = int(at[np.argmin(np.abs(sp.roots[at]))])
    mult = sp.multiplicities.copy()
    mult[i] -= min(k, int(mult[i]))
    keep = mult > 0
    count = None if sp.count is None else sp.count - (int(sp.multiplicities[i]) - int(mult[i]))
    return dataclasses.replace(sp, roots=sp.roots[keep], multiplicities=mult[keep], count=count)


def rightmost(q: QuasiPolynomial | AltitudeLoop | Loop, *, re_min: float | None = None,
              neutral: Any = None) -> Rightmost:
    """The rightmost root (Im >= 0) and the spectral abscissa, from a region that provably holds it.

    For a retarded quasi-polynomial every root with ``Re s >= x`` has ``|s| <= R(x)`` (:func:`root_bound`), so
    the roots in ``[x, R] x [0, R]`` include the rightmost one as soon as there is any.  The search starts at
    ``x = re_min``, by default ``-1/T`` with ``T`` the largest delay (the loop's own time scale: the root chains
    that a delay makes lie a few ``1/T`` left of the axis), and while it finds no root it moves left by strips
    ``[x', x] x [0, R(x')]``, each of which holds every root with ``x' <= Re s < x``.  The strips start
    ``1/T`` wide and widen while ``R`` grows slowly, narrowing where it grows fast (``R`` grows like
    ``exp(-x T)``); a strip is searched in bounded memory (split where large, parts without roots dropped after
    one boundary integral), so a long delay with a slow plant, where ``R`` is large, costs neither minutes nor
    gigabytes.  For a neutral quasi-polynomial ``x`` stays right of the neutral line, where the bound holds, and
    approaches it (to ``2e-5 / T``); if no root lies there, the abscissa is the line itself.  A polynomial
    (no delay) is searched once, in the disc that holds all its roots.

    ``neutral`` replaces the polygon bound of a neutral ``q``'s difference operator by a sharper one known from
    its structure: an object with ``abscissa`` (no root chain right of it) and ``lead(x)`` (a lower bound on the
    difference operator's modulus over ``Re s >= x``), as a system's
    :func:`~delaykit.spectrum.neutral.channel_abscissa`.

    If a strip cannot be certified (its boundary would need more samples than the root finder's budget, or it
    needs more than 4096 parts), or 400 strips hold no root, the result says ``certified=False``; if no root
    was found by then, ``root`` is None and ``abscissa`` is the left edge of the last certified strip, an upper
    bound on the spectral abscissa (so ``stable`` is still right when it is negative).

    Examples
    --------
    >>> rightmost(AltitudeLoop(kp=1.31, delay=0.368)).root
    (-2.2246...+1.9683...j)
    >>> from delaykit import Controller, Loop
    >>> rightmost(Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02), delay=12.0))   # 12 s delay, 150 s lag
    Rightmost(root=-0.0077+0.0057j, abscissa=-0.0077, stable)
    """
    kept = q.structural_roots_kept() if isinstance(q, Loop) else 0
    q = _as_qp(q)
    if q.kind == "advanced":
        raise InvalidValueError("an advanced quasi-polynomial has no rightmost root (its roots are unbounded to the "
                                "right)")
    if q.kind == "neutral" and neutral is not None:
        lines = (float(neutral.abscissa),)
        bound = lambda q_, x_: root_bound(q_, x_, lead=neutral.lead(x_))  # noqa: E731
    else:
        lines = neutral_lines(q) if q.kind == "neutral" else ()
        bound = root_bound
    if kept:  # a compensator's structural roots at 0 left in the quasi-polynomial: not the loop's
        search = lambda q_, box, lines_: _without_zero_root(_search(q_, box, lines_), kept)  # noqa: E731
    else:
        search = _search
    tmax = max(q.delays)
    sym = all(c.imag == 0 for p in q.polys for c in p)

    def lower(R: float) -> float:
        return 0.0 if sym else -R

    def result(sp: Spectrum, bound: float | None = None) -> Rightmost:
        # ``bound``: no root lies right of it (certified); the abscissa when an uncertified search found none
        root = sp.rightmost
        xs = ([root.real] if root is not None else []) + list(lines)
        if root is None and not sp.certified and bound is not None:
            xs.append(bound)
        return Rightmost(root=root, abscissa=max(xs) if xs else -math.inf, neutral_lines=lines,
                         certified=sp.certified, spectrum=sp)

    if tmax == 0.0:  # a polynomial: every root lies in |s| <= R
        R = root_bound(q, 0.0)
        return result(search(q, (-R, R, lower(R), R), lines))
    unit = 1.0 / tmax
    line = max(lines) if lines else -math.inf
    closest = line + 2e-5 * unit
    x = -unit if re_min is None else check_real("re_min", re_min)
    step = unit
    if lines:
        x = max(x, line + 0.02 * unit) if re_min is None else max(x, closest)
    elif re_min is None:
        free = _delay_free_scale(q)
        if free < 0.01 * unit:  # delays far shorter than the loop's own time scale: start there, not at -1/T
            x, step = -free, free
    R = bound(q, x)
    right = max(R, x + step)  # no root lies right of R
    sp = search(q, (x, right, lower(R), R), lines)
    for _ in range(_MAX_STRIPS):
        if not sp.certified and not sp.roots.size and not lines and not kept:
            far = _rightmost_from_right(q)  # too large a region here (a huge gain): searched from the right
            if far is not None:
                return result(far)
        if sp.roots.size or not sp.certified:
            return result(sp, right)
        if lines and x - closest <= 1e-12 * unit:
            return result(sp)  # no root right of the line (to 2e-5 / T): the abscissa is the line
        right = x
        x_new = x - step
        if lines:
            x_new = max(x_new, line + 0.1 * (x - line), closest)
        R_new = bound(q, x_new)
        while not lines and R_new > 8.0 * R and step > unit / 64:  # R grows fast here: a narrower strip
            step /= 2.0
            x_new = x - step
            R_new = bound(q, x_new)
        if R_new < 2.0 * R:
            step *= 2.0
        x, R = x_new, R_new
        sp = search(q, (x, right, lower(R), R), lines)
    return result(_merge(q, sp.region, [], (RootStatus.SAMPLE_BUDGET,
                                             f"no root found in {_MAX_STRIPS} strips down to Re s = {x:.6g}"), lines),
                  x)


def _delay_free_scale(q: QuasiPolynomial) -> float:
    """1 + twice the largest root magnitude of ``q`` with its delays set to 0 (the loop's time scale without the
    delay: a loop whose delays are far shorter has its rightmost roots near these)."""
    n = max(len(p) for p in q.polys)
    total = np.zeros(n, dtype=complex)
    for p in q.polys:
        total[n - len(p):] += np.asarray(p, dtype=complex)
    nz = np.flatnonzero(np.abs(total) > 0)
    if nz.size == 0:
        return 1.0
    r = np.roots(total[nz[0]:])
    r = r[np.isfinite(r)]
    return 1.0 + 2.0 * float(np.max(np.abs(r))) if r.size else 1.0


def in_delay_units(q: QuasiPolynomial) -> QuasiPolynomial:
    """``Q(s / tau_max)`` divided by its largest coefficient: the same roots times ``tau_max`` (the longest delay
    becomes 1), with coefficients of order one however large the loop gain or the time scales.

    The scaling is done on the logarithms of the coefficients, so ``1e300 exp(-1e-300 s)`` is no overflow; only a
    coefficient below 1e-308 of the largest (negligible wherever a root can be represented) underflows to 0.  A
    polynomial (no delay) is only divided by its largest coefficient.

    Examples
    --------
    >>> in_delay_units(QuasiPolynomial([[1, 1], [1e20]], [0.0, 0.3]))   # s + 1 + 1e20 exp(-0.3 s), s = z / 0.3
    QuasiPolynomial(3.33333e-20·s + 1e-20 + 1·exp(-1 s))
    """
    q = _as_qp(q)
    tmax = max(q.delays)
    polys = _unit_scaled(q.polys, 1.0 / tmax if tmax > 0 else 1.0)
    return QuasiPolynomial(polys, [t / tmax if tmax > 0 else t for t in q.delays])


def _first_strip_from_right(q: QuasiPolynomial, stop: float) -> tuple[str, Any]:
    """Walk strips ``[x - 1, x] x [-R(x - 1), R(x - 1)]`` of a retarded quasi-polynomial in delay units (its
    longest delay 1) leftwards from where no root can lie, down to ``Re s = stop``, counting each by the argument
    principle.  Returns ``("roots", box)`` for the first strip that holds a root, ``("none", None)`` when none
    down to ``stop`` does, ``("fail", None)`` when a strip cannot be counted (too long a boundary, a root on it)."""
    ev = _Eval(q)
    x = max(1.0, stop + 1.0)
    while root_bound(q, x) > x:
        x *= 2.0
        if x > 1e6:
            return "fail", None
    lo = max(stop, 0.5 * x) if x > 1.0 else stop
    for _ in range(60):  # no root right of x: brought down to where the bound meets the line (R(x) = x)
        if not math.isfinite(lo) or x - lo <= 0.5:
            break
        mid = 0.5 * (lo + x)
        lo, x = (lo, mid) if root_bound(q, mid) <= mid else (mid, x)
    right = x
    spent = 0.0  # boundary samples, all strips together: at most 4 single searches' budget (seconds, not minutes)
    for _ in range(_MAX_STRIPS):
        if right <= stop:
            return "none", None
        left = max(stop, right - 1.0)
        R = root_bound(q, left)
        box = (left, right, -R, R)
        spent += _contour_samples(box, 1.0)
        if spent > 4 * _CAP:
            return "fail", None
        c = _count(ev, box)
        if not c.ok:
            return "fail", None
        if c.n > 0:
            return "roots", box
        right = left
    return "fail", None


def far_right_verdict(q: QuasiPolynomial) -> bool | None:
    """Stability of a retarded quasi-polynomial whose right half-plane is too large to search directly (a huge
    loop gain): True when no root has ``Re s >= 0``, False when one has, None when it cannot be decided.

    Worked in :func:`in_delay_units`.  First one argument-principle count of the right half-plane
    (:func:`right_half_plane_count`); if its boundary is too long, the roots are sought from the right: every
    root lies left of the first ``x`` with ``R(x) <= x`` (:func:`~delaykit.spectrum.roots.root_bound`), and strips
    ``[x - 1, x] x [-R(x - 1), R(x - 1)]`` are counted moving left down to the axis; the first strip right of the
    axis that holds a root proves instability (a high-gain loop's rightmost roots lie near ``ln(gain) / tau``, where
    these strips are small, while its root chain up the axis reaches ``|s| ~ gain``).  With one delay, a delay
    below the exact delay margin (:func:`delay_margin`: no root has crossed the axis yet) proves stability, as for
    a loop whose fast modes and long delay put its roots too far apart to count.

    Examples
    --------
    >>> q = QuasiPolynomial([[1, 1], [1e20]], [0.0, 0.3])     # 1e20 exp(-0.3 s) / (s + 1), unity feedback
    >>> far_right_verdict(q)
    False
    """
    q = in_delay_units(q)
    if q.kind != "retarded" or max(q.delays) == 0.0:
        return None
    n = right_half_plane_count(q)
    if n is not None:
        return n == 0
    if len(q.delays) == 2:  # one delay (1 in these units): stable below its exact delay margin
        dm = delay_margin(q)
        if dm.delay > 1.0 + 1e-9:
            return True
    found, _ = _first_strip_from_right(q, 0.0)
    return {"roots": False, "none": True}.get(found)


def _rightmost_from_right(q: QuasiPolynomial) -> Spectrum | None:
    """The roots of a retarded quasi-polynomial in the first strip from the right that holds any
    (:func:`_first_strip_from_right`, in delay units, scaled back): the rightmost root among them, certified; None
    when not found so.  For a loop gain so large that the search from the loop's own time scale cannot be
    certified (the right half-plane up to ``|s| ~ gain``)."""
    if q.kind != "retarded" or max(q.delays) == 0.0:
        return None
    t = max(q.delays)
    qs = in_delay_units(q)
    found, box = _first_strip_from_right(qs, -math.inf)
    if found != "roots":
        return None
    sp = _search(qs, box, ())
    if not sp.certified:
        return None
    return dataclasses.replace(sp, roots=sp.roots / t, region=tuple(v / t for v in box))


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
    # s = sigma z with sigma the roots' scale, both polynomials divided by their largest coefficient: |P(jw)|^2
    # below squares the coefficients (a gain of 1e300 overflowed); crossings w = sigma nu, delays tau = t / sigma
    # (only for coefficients outside 1e-100..1e100: other loops' margins are computed as they always were)
    mags = np.abs(np.concatenate([p0, p1]))
    mags = mags[mags > 0]
    sigma = 1.0
    if mags.size and (mags.max() > 1e100 or mags.min() < 1e-100):
        sigma = _root_scale(np.polyadd(p0, p1))
        p0, p1 = _unit_scaled([p0, p1], sigma)
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
        crossings.append((float(w * sigma), float(tau if tau > 0 else 2 * math.pi / w) / sigma))
    if not crossings:
        return DelayMargin(math.inf, None, ())
    w, tau = min(crossings, key=lambda c: c[1])
    return DelayMargin(tau, w, tuple(crossings))


def _root_scale(p: np.ndarray) -> float:
    """The geometric mean of the nonzero roots' moduli of the polynomial ``p`` (highest degree first), from its
    coefficients' logarithms (no overflow): ``|a_j / a_n|^(1/(n-j))`` with ``a_j`` the lowest nonzero coefficient;
    1 for a constant or a monomial."""
    a = np.abs(np.asarray(p, complex))
    nz = np.flatnonzero(a)
    if nz.size < 2:
        return 1.0
    first, last = nz[0], nz[-1]
    return float(math.exp((math.log(a[last]) - math.log(a[first])) / (last - first)))


def _unit_scaled(polys: Sequence[Any], sigma: float) -> list[np.ndarray]:
    """Each polynomial (highest degree first) at ``sigma z``, all divided by the largest coefficient among them,
    computed on the coefficients' logarithms (no overflow; a coefficient below 1e-308 of the largest underflows
    to 0)."""
    ls = math.log(sigma)
    out, logs = [], []
    for p in polys:
        a = np.asarray(p, complex)
        with np.errstate(divide="ignore"):
            logs.append(np.log(np.abs(a)) + ls * np.arange(a.size - 1, -1, -1))
    top = max(float(np.max(lg)) for lg in logs)
    for p, lg in zip(polys, logs):
        a = np.asarray(p, complex)
        unit = np.divide(a, np.abs(a), out=np.zeros_like(a), where=a != 0)
        out.append(unit * np.exp(lg - top))
    return out


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


def _arrays(q: QuasiPolynomial) -> tuple[np.ndarray, np.ndarray]:
    """``q`` as the root finder's arrays: coefficients (one row a term, highest degree first, padded) and delays."""
    deg = q.degree
    C = np.zeros((len(q.delays), deg + 1), complex)
    for i, p in enumerate(q.polys):
        C[i, deg + 1 - len(p):] = p
    return C, np.array(q.delays, float)


def _flat(C: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """The arrays as one real vector (real and imaginary parts of the coefficients, then the delays)."""
    return np.concatenate([np.ascontiguousarray(C).ravel().view(float), tau])


def _family(base: Any, x_name: str, xs: np.ndarray, y_name: str, ys: np.ndarray
            ) -> tuple[tuple[int, int], np.ndarray] | None:
    """The characteristic as a bilinear function of the two parameters, when it is one: ``(shape, a)`` with the
    point ``(x, y)`` given by ``a[0] + u a[1] + v a[2] + u v a[3]`` (``u``, ``v`` the positions of ``x``, ``y``
    between the grid's first and last values) in the form of :func:`_flat`.

    Controller gains enter ``Dp Dc + Np Nc exp(-s T)`` linearly, and delays enter ``T`` linearly, so for them the
    quasi-polynomial anywhere follows from its values at the four corners of the grid.  That is checked at four
    more grid points, entry by entry to 1e-9 of the entry's size; when it fails (a parameter that enters
    otherwise, or a term that appears or vanishes), None, and each point is built from the loop itself.
    """
    def probe(a: float, b: float) -> np.ndarray | None:
        C, t = _arrays(_as_qp(base.replace(**{x_name: float(a), y_name: float(b)})))
        return _flat(C, t) if (C.shape, t.size) == (shape, shape[0]) else None

    C0, t0 = _arrays(_as_qp(base.replace(**{x_name: float(xs[0]), y_name: float(ys[0])})))
    shape = C0.shape
    e = [_flat(C0, t0), probe(xs[-1], ys[0]), probe(xs[0], ys[-1]), probe(xs[-1], ys[-1])]
    if any(v is None for v in e):
        return None
    coef = np.array([e[0], e[1] - e[0], e[2] - e[0], e[3] - e[2] - e[1] + e[0]])
    scale = np.max(np.abs(np.array(e)), axis=0)
    rng = np.random.default_rng(12)
    for i, j in [(xs.size // 2, ys.size // 2), *zip(rng.integers(0, xs.size, 3), rng.integers(0, ys.size, 3))]:
        want = probe(xs[i], ys[j])
        if want is None:
            return None
        u, v = _position(xs, xs[i]), _position(ys, ys[j])
        got = coef[0] + u * coef[1] + v * coef[2] + (u * v) * coef[3]
        if np.any(np.abs(got - want) > 1e-9 * np.maximum(scale, np.abs(want)) + 1e-300):
            return None
    return shape, coef


def _position(grid: np.ndarray, value: Any) -> Any:
    """Where ``value`` lies between the grid's first (0) and last (1) values (0 for a grid of one value)."""
    return (value - grid[0]) / (grid[-1] - grid[0]) if grid[-1] != grid[0] else 0.0 * value


TK: Any = None
"""The stability map's compiled loop (``spectrum/_trackkernel.py``: the extension built at install, else numba's
copy), loaded by the first map."""


def _tracker() -> Callable[..., tuple[int, int]]:
    """:data:`TK`'s ``track``, called as ``track(W, nt, n1, k0, starts, nstart, sym, absc, max_phase, reliable,
    cap)`` on the points' quasi-polynomials in the form of :func:`_flat`, one a row of ``W``."""
    global TK
    if TK is None:
        TK = _native.load("delaykit.spectrum", "_trackkernel")
    tk = TK

    def track(W: np.ndarray, nt: int, n1: int, *rest: Any) -> tuple[int, int]:
        n = 2 * nt * n1
        return tk.track(W[:, :n].view(complex), W[:, n:], nt, n1, *rest)

    return track


def right_half_plane_count(q: QuasiPolynomial, *, radius: float | None = None) -> int | None:
    """The number of roots of a retarded (or neutral, with its chains left of the axis) quasi-polynomial in the
    closed right half-plane, by one argument-principle integral; None when it cannot be counted that way (a root
    on the imaginary axis, no bound, or too many samples), for the caller to search instead.

    Every root with ``Re s >= 0`` has ``|s| <= R`` (Cauchy's form of :func:`root_bound`), so the count on
    ``[0, R] x [-R, R]`` is all of them.  (For the frequency module's stability verdict.)  ``radius``, when
    given, is such an ``R`` known from elsewhere (a neutral system's channels:
    :func:`~delaykit.spectrum.systems.is_stable`).

    Examples
    --------
    >>> [right_half_plane_count(AltitudeLoop(kp=kp, delay=0.368).characteristic()) for kp in (1.31, 5.0)]
    [0, 2]
    """
    return _rhp_count(*_arrays(q), radius=radius)


def _bound_underflows(C: np.ndarray, tau: np.ndarray) -> bool:
    """True when the kernel's root bound at ``x = 0`` (``RK.bound``) would divide by a power of its bisection point
    that underflows to 0 (coefficients below the leading one by hundreds of decades, 1e-300·s·exp(-s T) on s²):
    its Fujiwara start ``hi``, halved 60 times and raised to the degree, is 0.  The kernel's error would be
    printed and lost, and its bound meaningless; the caller counts another way."""
    fixed = tau == 0.0
    p0 = np.abs(C[fixed].sum(axis=0))
    oth = np.abs(C[~fixed]).sum(axis=0)
    nz = np.flatnonzero(p0)
    if not nz.size or nz[0] == C.shape[1] - 1 or oth[:nz[0]].any():
        return False  # no bound at all (the kernel says so without dividing)
    k0 = int(nz[0])
    lead = p0[k0] - oth[k0]
    if not lead > 0.0:
        return False
    rest = (p0 + oth)[k0 + 1:]
    ks = np.arange(1, rest.size + 1)
    with np.errstate(all="ignore"):
        hi = float(np.max(2.0 * (rest / lead) ** (1.0 / ks)))
    return 0.0 < hi < 1.0 and (hi * 2.0 ** -61) ** rest.size == 0.0


def _rhp_count(C: np.ndarray, tau: np.ndarray, radius: float | None = None) -> int | None:
    """:func:`right_half_plane_count` on the root finder's arrays (:func:`_arrays`)."""
    if radius is None and _bound_underflows(C, tau):
        return None
    R = RK.bound(C, tau, 0.0) if radius is None else float(radius)
    if R < 0.0:
        return None
    R = R * (1.0 + 1e-9) + 1e-12
    cs = np.array([complex(0.0, -R), complex(R, -R), complex(R, R), complex(0.0, R)])
    n_init = 8 + np.abs(np.roll(cs, -1) - cs) * (float(tau.max()) + 0.25) / _MAX_PHASE
    if not n_init.sum() <= _CAP:  # counted as floats: a bound near 1e30 (a huge gain) is past any integer
        return None
    n_init = n_init.astype(np.int64)
    buf = np.empty(1, complex)
    status, total, _, _ = RK.contour(C, np.abs(C), tau, cs, n_init, _MAX_PHASE, _RELIABLE, _CAP, buf, buf.copy())
    n = int(round(total))
    return n if status == 0 and abs(total - n) <= 0.05 and n >= 0 else None


def stability_map(
    base: AltitudeLoop | Loop,
    x_name: str,
    x: Any,
    y_name: str,
    y: Any,
    progress: Callable[[int, int], None] | None = None,
    *,
    workers: int | None = None,
) -> StabilityMap:
    """Spectral abscissa of ``base`` with two of its fields (``kp``, ``ki``, ``kd``, ``kv``, ``delay``, ...) set over
    a grid, for any continuous loop.

    P loops on an integrator use the Lambert W root directly (vectorised).  Any other loop is followed across the
    grid point by point, each point a neighbour of the one before (rows in alternate directions): Newton's method
    from the neighbour's rightmost roots gives a candidate, and one argument-principle count on the region that
    holds every root right of it confirms that nothing lies further right; where the count disagrees (a root has
    come from elsewhere), the point gets the full certified search, :func:`rightmost`.  So every value is the
    certified abscissa, at a fraction of a millisecond for most points.  The quasi-polynomial of each point is
    interpolated from the grid's corners when the parameters enter it bilinearly (gains and delays do; checked,
    see ``_family``), else built from ``base.replace(...)``.

    Parameters
    ----------
    base : Loop or AltitudeLoop
        The loop (continuous).
    x_name, y_name : str
        Fields of the loop (or of its controller) to vary: ``x`` along the columns, ``y`` along the rows.
    x, y : array_like
        Their values.
    progress : callable, optional
        Called as ``progress(done, total)`` as points are done.
    workers : int, optional
        Threads, each following a block of rows (default: one per CPU).  The compiled part runs without the GIL.

    Returns
    -------
    StabilityMap

    Examples
    --------
    >>> m = stability_map(AltitudeLoop(kp=1.0, delay=0.3), "kp", [1, 4, 6], "delay", [0.3])
    >>> m.stable.tolist()
    [[True, True, False]]
    >>> from delaykit import Controller, Loop
    >>> pid = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.0, 0.5, 0.2, 0.05), delay=0.2)
    >>> stability_map(pid, "kp", [0.5, 2.0, 8.0], "ki", [0.5, 4.0]).stable.astype(int).tolist()
    [[1, 1, 1], [0, 1, 0]]
    """
    xs = np.asarray(x, dtype=float).ravel()
    ys = np.asarray(y, dtype=float).ravel()
    check_count(f"a map of {xs.size} x {ys.size} values", float(xs.size) * ys.size, MAX_GRID_POINTS, "loops",
                "map fewer values")
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
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1):
        raise InvalidValueError(f"workers must be a positive whole number of threads, got {workers!r}")
    family = _family(base, x_name, xs, y_name, ys)
    # each point next to the one before: rows in alternate directions, the rows in blocks, one block a worker
    cols = [np.arange(xs.size) if i % 2 == 0 else np.arange(xs.size)[::-1] for i in range(ys.size)]
    n_workers = max(1, min(int(workers) if workers is not None else (os.cpu_count() or 1), ys.size, 64))
    edges = np.linspace(0, ys.size, n_workers + 1).round().astype(int)
    done = [0]
    lock = threading.Lock()

    def point(i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        if family is not None:
            shape, coef = family
            u, v = _position(xs, xs[j]), _position(ys, ys[i])
            w = coef[0] + u * coef[1] + v * coef[2] + (u * v) * coef[3]
            n = shape[0] * shape[1] * 2
            return w[:n].view(complex).reshape(shape), w[n:]
        return _arrays(_as_qp(base.replace(**{x_name: float(xs[j]), y_name: float(ys[i])})))

    def tick(n: int) -> None:
        if progress:
            with lock:
                done[0] += n
                progress(done[0], out.size)

    def block(r0: int, r1: int) -> None:
        ii = np.concatenate([np.full(xs.size, i) for i in range(r0, r1)])
        jj = np.concatenate([cols[i] for i in range(r0, r1)])
        absc = np.full(ii.size, np.nan)
        starts = np.zeros(64, complex)
        nstart, k = 0, 0
        if family is not None:  # every point's quasi-polynomial at once, for the compiled loop
            shape, coef = family
            u, v = _position(xs, xs[jj]), _position(ys, ys[ii])
            W = coef[0] + u[:, None] * coef[1] + v[:, None] * coef[2] + (u * v)[:, None] * coef[3]
            sym = not np.any(coef[:, 1:2 * shape[0] * shape[1]:2])
        while k < ii.size:
            if nstart and family is not None:  # as far as the points are confirmed
                stop, nstart = track(W, shape[0], shape[1], k, starts, nstart, sym, absc, _MAX_PHASE, _RELIABLE,
                                      _CAP)
                tick(stop - k)
                k = stop
                if k == ii.size:
                    break
            C, tau = point(ii[k], jj[k])
            if nstart and family is None:
                one = np.full(1, np.nan)
                ok, nstart = track(_flat(C, tau)[None, :], C.shape[0], C.shape[1], 0, starts, nstart,
                                    not np.any(C.imag), one, _MAX_PHASE, _RELIABLE, _CAP)
                if ok:
                    absc[k] = one[0]
                    k += 1
                    tick(1)
                    continue
            rm = rightmost(QuasiPolynomial(list(C), list(tau)))  # not confirmed: the full search
            absc[k] = rm.abscissa
            roots = rm.spectrum.roots
            roots = roots[np.argsort(-roots.real)][:8] if roots.size else roots
            starts[:roots.size], nstart = roots, roots.size
            k += 1
            tick(1)
        out[ii, jj] = absc

    track = _tracker()
    # (numba's copy, where no extension was built, compiles here, before the threads)
    track(np.zeros((0, 3)), 1, 1, 0, np.zeros(1, complex), 0, True, np.zeros(0), _MAX_PHASE, _RELIABLE, _CAP)
    if n_workers == 1:
        block(0, ys.size)
    else:
        with ThreadPoolExecutor(n_workers) as pool:  # the compiled loop releases the GIL
            list(pool.map(block, edges[:-1], edges[1:]))
    return StabilityMap(x_name, y_name, xs, ys, out)
