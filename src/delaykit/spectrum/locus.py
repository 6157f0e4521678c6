"""The exact root locus of a delay loop, over a gain or over a delay, with a certified count at every step.

For an open loop ``L(s) = k N(s) / D(s) exp(-s T)`` (``N``, ``D`` real polynomials, one loop delay ``T``) the
closed loop's characteristic function is the quasi-polynomial ``D(s) + k N(s) exp(-s T)``.  :func:`root_locus`
moves one parameter, the gain ``k`` or the delay ``T``, over the values given and at every value:

* finds the roots in a rectangle of the complex plane: Newton's method started from the previous value's roots,
  confirmed by one argument-principle count on the rectangle (:mod:`.roots`); where the count and the roots found
  differ (a root came in across the boundary, or two starts fell on one root) the value gets the full certified
  search, :func:`~delaykit.spectrum.roots.find_roots`.  So no root is lost or invented at any step;
* counts the roots in the closed right half-plane by the argument principle
  (:func:`~delaykit.spectrum.stability.right_half_plane_count`);
* finds, independently of the grid, the exact parameter values where a root crosses the imaginary axis, with the
  frequency and the direction (see :func:`root_locus`), and checks that between any two values the change of the
  right-half-plane count is what these crossings say; where it is not, the frequency scan is refined, and if that
  does not reconcile them the result says so (``consistent`` False, with the reason).

Examples
--------
>>> loc = root_locus(([1.0], [1.0, 0.0], 0.5), gains=np.linspace(0.1, 5.0, 50))
>>> loc.crossings[0]
LocusCrossing(gain=3.141593 at 3.141593 rad/s, into the right half-plane)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.altitude import AltitudeLoop, as_loop
from ..models.loop import Loop
from ..models.quasipolynomial import QuasiPolynomial
from ..models.transfer import TransferFunction
from ..systems.build import plant_of
from ..systems.lti import DelayLTI
from ._openloop import OpenLoop, positive_real_roots, solve_bracketed
from .roots import _check_region, _count, _dedupe, _Eval, _inside, _newton, find_roots, neutral_lines, root_bound
from .stability import _arrays, _rhp_count

__all__ = ["LocusCrossing", "RootLocus", "root_locus", "open_loop_parts"]

_SCAN_PER_RADIAN = 20.0  # samples of the crossing function per radian of the delay's phase (w T)
_MAX_SCAN = 2_000_000


@dataclass(frozen=True, repr=False)
class LocusCrossing:
    """A root on the imaginary axis: the parameter value, the frequency ``w >= 0`` (the roots ``+-j w``) and the
    direction the root moves as the parameter increases: +1 into the right half-plane, -1 out of it, 0 touching.

    Examples
    --------
    >>> LocusCrossing("delay", 0.5, 3.0, 1)
    LocusCrossing(delay=0.5 at 3 rad/s, into the right half-plane)
    """

    parameter: str
    value: float
    frequency: float
    direction: int

    @property
    def roots(self) -> int:
        """How many roots cross here: 2 (a conjugate pair) for ``w > 0``, 1 for a real root through 0."""
        return 2 if self.frequency > 0 else 1

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"parameter": self.parameter, "value": self.value, "frequency": self.frequency,
                "direction": self.direction, "roots": self.roots}

    def __repr__(self) -> str:
        way = {1: "into the right half-plane", -1: "into the left half-plane", 0: "touching the axis"}[self.direction]
        return f"LocusCrossing({self.parameter}={self.value:.7g} at {self.frequency:.7g} rad/s, {way})"


@dataclass(frozen=True, repr=False, eq=False)
class RootLocus:
    """The roots of ``D(s) + k N(s) exp(-s T)`` in a region as the gain ``k`` or the delay ``T`` moves.

    Attributes
    ----------
    parameter : str
        ``"gain"`` or ``"delay"``.
    values : ndarray
        The parameter's values (increasing).
    roots : ndarray of complex, shape (len(values), n)
        The roots in ``region`` at each value (repeated by multiplicity), by decreasing real part, padded with nan.
    counts : ndarray of int
        The argument principle's count of roots in ``region`` at each value; -1 where it could not be certified.
    certified : ndarray of bool
        Whether the roots found at each value match the count.
    unstable : ndarray of int
        Roots in the closed right half-plane at each value (argument principle); -1 where it could not be counted
        (a root on the imaginary axis, or root chains of a neutral loop reaching it).
    stable : ndarray of bool
        ``unstable == 0`` (and, for a neutral loop, its root chains left of the axis).
    crossings : tuple of LocusCrossing
        Where a root crosses the imaginary axis, in increasing parameter order.
    stable_intervals : tuple of (float, float)
        The parameter intervals (within the values' range) where the loop is stable, their ends the crossings'
        exact values (or the range's ends).  When the crossings agree with every count (``consistent``) they
        come from the crossings, so an interval narrower than the grid's step is found too; otherwise from the
        runs of stable values, each end moved to a crossing next to it where there is one.
    region : tuple
        ``(re_min, re_max, im_min, im_max)``.
    gain, delay : float or None
        The open loop's fixed gain and delay; the one that moves is None (its values are ``values``).
    consistent : bool
        Every change of ``unstable`` between two values is what the crossings between them say.
    reason : str
        Why not certified or not consistent ("" when all is well).
    """

    parameter: str
    values: np.ndarray
    roots: np.ndarray
    counts: np.ndarray
    certified: np.ndarray
    unstable: np.ndarray
    stable: np.ndarray
    crossings: tuple[LocusCrossing, ...]
    stable_intervals: tuple[tuple[float, float], ...]
    region: tuple[float, float, float, float]
    gain: float | None
    delay: float | None
    consistent: bool
    reason: str

    @property
    def all_certified(self) -> bool:
        """Every value's roots certified and the crossings consistent with the counts."""
        return bool(np.all(self.certified)) and self.consistent

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (strict JSON: no NaN; a count that could not be made is null)."""
        def roots_at(i: int) -> list[list[float]]:
            r = self.roots[i]
            return [[float(z.real), float(z.imag)] for z in r[np.isfinite(r)]]

        return {"parameter": self.parameter, "values": [float(v) for v in self.values],
                "roots": [roots_at(i) for i in range(self.values.size)],
                "counts": [int(c) if c >= 0 else None for c in self.counts],
                "certified": [bool(c) for c in self.certified],
                "unstable": [int(c) if c >= 0 else None for c in self.unstable],
                "stable": [bool(c) for c in self.stable],
                "crossings": [c.to_dict() for c in self.crossings],
                "stable_intervals": [[lo, hi] for lo, hi in self.stable_intervals],
                "region": list(self.region), "gain": self.gain, "delay": self.delay,
                "consistent": self.consistent, "status": "certified" if self.all_certified else "not_certified",
                "reason": self.reason or None}

    def __repr__(self) -> str:
        v = self.values
        iv = ", ".join(f"[{lo:.6g}, {hi:.6g}]" for lo, hi in self.stable_intervals) or "nowhere"
        cert = "certified" if self.all_certified else f"NOT certified: {self.reason}"
        return (f"RootLocus({self.parameter} over {v.size} values in [{v[0]:.6g}, {v[-1]:.6g}], "
                f"{len(self.crossings)} crossings, stable on {iv}, {cert})")


# -- the open loop ---------------------------------------------------------------------------------------------
def _poly(name: str, p: Any) -> np.ndarray:
    try:
        a = np.atleast_1d(np.asarray(p, dtype=float))
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be real polynomial coefficients (highest power first), got {p!r}") from exc
    if a.ndim != 1 or not np.all(np.isfinite(a)):
        raise InvalidValueError(f"{name} must be a finite 1-D list of coefficients, got {p!r}")
    nz = np.flatnonzero(a)
    if nz.size == 0:
        raise InvalidValueError(f"{name} is the zero polynomial")
    return a[nz[0]:]


def open_loop_parts(L: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """``(N, D, T)`` of an open loop ``N(s) / D(s) exp(-s T)``: from a :class:`~delaykit.models.loop.Loop` or an
    ``AltitudeLoop`` (its loop transfer function broken at the plant input, its whole delay), text
    (``"exp(-0.368*s)/s"``), a :class:`~delaykit.models.transfer.TransferFunction`, a SISO
    :class:`~delaykit.systems.lti.DelayLTI` that is a rational function times one dead time
    (:func:`~delaykit.systems.build.plant_of`), or ``(num, den)`` / ``(num, den, delay)``.

    Examples
    --------
    >>> [np.asarray(x).tolist() for x in open_loop_parts("2*exp(-0.5*s)/(s+1)")]
    [[2.0], [1.0, 1.0], 0.5]
    """
    if isinstance(L, (Loop, AltitudeLoop)):
        loop = as_loop(L)
        if loop.sampled:
            raise InvalidValueError(f"the loop is sampled (period {loop.period:g} s): its root locus is not that of "
                                    "a quasi-polynomial; use the continuous loop (period=None)")
        num, den = loop.open_loop()
        T = loop.total_delay
    elif isinstance(L, str):
        tfn, T = TransferFunction.parse_with_delay(L)
        num, den = tfn.num, tfn.den
    elif isinstance(L, TransferFunction):
        num, den, T = L.num, L.den, 0.0
    elif isinstance(L, DelayLTI):  # rational times one dead time (plant_of says why not, otherwise)
        tfn, T = plant_of(L)
        num, den = tfn.num, tfn.den
    elif isinstance(L, (tuple, list)) and len(L) in (2, 3):
        num, den = L[0], L[1]
        T = L[2] if len(L) == 3 else 0.0
    else:
        raise InvalidTypeError("the open loop must be a Loop, an AltitudeLoop, text such as 'exp(-0.368*s)/s', a "
                               "TransferFunction, a SISO DelayLTI or a tuple (num, den[, delay]); got "
                               f"{type(L).__name__}")
    num, den = _poly("the numerator", num), _poly("the denominator", den)
    if num.size > den.size:
        raise InvalidValueError(f"the open loop is improper (numerator degree {num.size - 1} > denominator degree "
                                f"{den.size - 1}); its closed loop is advanced and has no root locus")
    T = check_real("the loop delay", T, minimum=0.0)
    return num, den, T


def _characteristic(num: np.ndarray, den: np.ndarray, k: float, T: float) -> QuasiPolynomial:
    return QuasiPolynomial([den, k * num], [0.0, T])


def _arrays_of(num: np.ndarray, den: np.ndarray, k: float, T: float) -> tuple[np.ndarray, np.ndarray]:
    """The root finder's arrays (:func:`~delaykit.spectrum.stability._arrays`) of ``D + k N exp(-s T)``, made
    directly (a thousand values: building each :class:`QuasiPolynomial` would cost more than finding its roots)."""
    m = den.size
    if T == 0.0:
        C = np.zeros((1, m), complex)
        C[0] = den
        C[0, m - num.size:] += k * num
        return C, np.zeros(1)
    C = np.zeros((2, m), complex)
    C[0] = den
    C[1, m - num.size:] = k * num
    return C, np.array([0.0, T])


def _eval_of(C: np.ndarray, tau: np.ndarray) -> _Eval:
    """An :class:`~delaykit.spectrum.roots._Eval` on the arrays (the fields its ``__init__`` sets)."""
    ev = _Eval.__new__(_Eval)
    ev.tau, ev.C, ev.A = tau, C, np.ascontiguousarray(np.abs(C))
    ev.deg, ev.real, ev.evals = C.shape[1] - 1, bool(np.all(C.imag == 0)), 0
    return ev


# -- the roots at each value -----------------------------------------------------------------------------------
def _roots_at(num: np.ndarray, den: np.ndarray, k: float, T: float, region: tuple[float, float, float, float],
              prev: np.ndarray, covers: bool) -> tuple[np.ndarray, int, bool, int]:
    """At ``D + k N exp(-s T)``: its roots in ``region`` (by multiplicity), the argument principle's count there
    (-1 if none), whether they match (Newton from ``prev`` confirmed by one count, else the full search), and the
    count in the closed right half-plane (-1 where it cannot be made: a root on the axis, or neutral chains
    reaching it).  ``covers``: the region holds every root with ``Re s >= 0``, so the certified roots give that
    count without a second contour."""
    C, tau = _arrays_of(num, den, k, T)
    neutral = T > 0 and k != 0 and num.size == den.size
    q = _characteristic(num, den, k, T) if neutral else None
    roots: np.ndarray | None = None
    if prev.size:
        ev = _eval_of(C, tau)
        s, conv, clean = _newton(ev, prev)
        got = s[conv & clean]
        if ev.real:
            got = np.concatenate([got, got.conj()])
        got = _dedupe(got)
        got = got[_inside(got, region)]
        c = _count(ev, region)
        if c.ok and c.n == got.size:
            roots, count, ok = got, c.n, True
    if roots is None:
        sp = find_roots(q if q is not None else _characteristic(num, den, k, T), region)
        roots = np.repeat(sp.roots, sp.multiplicities) if sp.roots.size else sp.roots
        count, ok = (sp.count if sp.count is not None else -1), bool(sp.certified)
    if covers and ok:
        on_axis = np.abs(roots.real) <= 1e-9 * (1.0 + np.abs(roots))
        unstable = -1 if np.any(on_axis) else int(np.sum(roots.real > 0))
    else:
        n = _rhp_count(C, tau)
        unstable = -1 if n is None else n
    if unstable == 0 and q is not None and any(x >= 0 for x in neutral_lines(q)):
        unstable = -1
    return roots, count, ok, unstable


# -- the crossings ---------------------------------------------------------------------------------------------
def _bound(num: np.ndarray, den: np.ndarray, kmax: float) -> float:
    """A radius holding every root with ``Re s >= 0`` of ``D + k N exp(-s T)`` for every ``|k| <= kmax`` and every
    ``T >= 0`` (the root bound of ``D`` against the delayed majorant ``kmax |N|``)."""
    if kmax == 0.0:  # the open-loop poles (1 + their largest modulus, so the region is never a point)
        r = np.roots(den)
        return 1.0 + (float(np.max(np.abs(r))) if r.size else 0.0)
    try:
        return root_bound(QuasiPolynomial([den, kmax * num], [0.0, 1.0]), 0.0)
    except InvalidValueError:
        raise InvalidValueError(
            f"at the gain {kmax:g} the closed loop is neutral with root chains reaching the right half-plane "
            f"(|gain x the numerator's leading coefficient| >= the denominator's); no bounded locus exists") from None


def _dsd(num: np.ndarray, den: np.ndarray, k: float, T: float, s: complex) -> tuple[complex, complex]:
    """``Q'(s)`` and ``N(s) exp(-s T)`` for ``Q = D + k N exp(-s T)``."""
    e = np.exp(-s * T)
    nv = np.polyval(num, s)
    dq = np.polyval(np.polyder(den), s) + k * (np.polyval(np.polyder(num), s) - T * nv) * e if den.size > 1 else \
        k * (np.polyval(np.polyder(num), s) - T * nv) * e
    return complex(dq), complex(nv * e)


def _sign(x: float, scale: float) -> int:
    return 0 if abs(x) <= 1e-12 * scale else (1 if x > 0 else -1)


def _gain_crossings(num: np.ndarray, den: np.ndarray, T: float, lo: float, hi: float, W: float,
                    refine: int = 1) -> list[LocusCrossing]:
    """Gains in ``[lo, hi]`` with a root at ``j w``: ``k = -D(jw) exp(jwT) / N(jw)`` real, i.e. the zeros of
    ``h(w) = Im(D(jw) conj(N(jw)) exp(jwT))``; the direction is the sign of ``Re ds/dk = -Re N e^{-sT} / Q'``."""
    out: list[LocusCrossing] = []

    def add(w: float) -> None:
        s = 1j * w
        nv = np.polyval(num, s) * np.exp(-s * T)
        if abs(nv) == 0.0:
            return
        kk = -np.polyval(den, s) / nv
        if abs(kk.imag) > 1e-6 * (1 + abs(kk)) or not lo <= kk.real <= hi:
            return
        k = float(kk.real)
        dq, ne = _dsd(num, den, k, T, s)
        d = -ne / dq if dq != 0 else 0j
        out.append(LocusCrossing("gain", k, float(w), _sign(d.real, abs(d))))

    add(0.0)
    if T == 0.0:  # a polynomial: h(w) = Im(D(jw) conj N(jw)), exactly
        def jw(p: np.ndarray) -> np.ndarray:
            n = p.size - 1
            return p * (1j) ** np.arange(n, -1, -1)
        h = np.polymul(jw(den), np.conj(jw(num))).imag
        h = np.where(np.abs(h) <= 1e-14 * max(np.max(np.abs(h)), 1e-300), 0.0, h)
        nz = np.flatnonzero(h)
        if nz.size:
            r = np.roots(h[nz[0]:])
            for w in sorted({round(float(z.real), 13) for z in r if z.real > 0 and abs(z.imag) <= 1e-7 * abs(z)}):
                add(w)
        return sorted(out, key=lambda c: (c.value, c.frequency))

    def h(w: np.ndarray) -> np.ndarray:
        s = 1j * w
        return (np.polyval(den, s) * np.conj(np.polyval(num, s)) * np.exp(s * T)).imag

    n = int(min(_MAX_SCAN, 64 + refine * _SCAN_PER_RADIAN * W * T + refine * 2000))
    w = np.linspace(0.0, W, n)[1:]
    # log-spaced points near 0 too (h vanishes there for a loop with integrators), and dense ones across each
    # open-loop pole or zero near the axis, where the phase of D conj N turns by pi within a width |Re r|
    near = [np.geomspace(W * 1e-9, w[0], 40 * refine)]
    for r in np.concatenate([np.roots(den), np.roots(num) if num.size > 1 else np.zeros(0)]):
        if r.imag > 0 and r.imag < W:
            wd = abs(r.real) + 1e-12 * r.imag
            near.append(np.clip(r.imag + wd * np.linspace(-8.0, 8.0, 64 * refine + 1), 0.0, W))
    w = np.unique(np.concatenate([*near, w]))
    w = w[w > 0]
    hv = h(w)
    ch = np.flatnonzero(np.sign(hv[:-1]) * np.sign(hv[1:]) < 0)
    exact = np.flatnonzero(hv == 0.0)
    if ch.size:
        for z in solve_bracketed(h, w[ch], w[ch + 1]):
            add(float(z))
    for i in exact:
        add(float(w[i]))
    return sorted(out, key=lambda c: (c.value, c.frequency))


def _delay_crossings(num: np.ndarray, den: np.ndarray, k: float, lo: float, hi: float) -> list[LocusCrossing]:
    """Delays in ``[lo, hi]`` with a root at ``j w``: ``w`` a positive root of ``|D(jw)|^2 - k^2 |N(jw)|^2``
    (a polynomial in ``w^2``), the delays ``tau_0 + 2 pi n / w`` with ``exp(-j w tau_0) = -D(jw) / (k N(jw))``;
    the direction is the sign of ``Re ds/dtau = Re s k N e^{-s tau} / Q'(s)`` at ``s = j w``."""
    if k == 0.0:
        return []
    a, b = OpenLoop._sq(den), OpenLoop._sq(num) * k * k
    m = max(a.size, b.size)
    F = np.pad(a, (m - a.size, 0)) - np.pad(b, (m - b.size, 0))
    out: list[LocusCrossing] = []
    for x in positive_real_roots(F, float(np.max(np.abs(np.concatenate([a, b]))))):
        w = math.sqrt(x)
        s = 1j * w
        z = -np.polyval(den, s) / (k * np.polyval(num, s))
        tau0 = (-np.angle(z)) % (2 * math.pi) / w
        period = 2 * math.pi / w
        n0 = max(0, math.ceil((lo - tau0) / period - 1e-12))
        tau = tau0 + n0 * period
        while tau <= hi * (1 + 1e-12):
            dq, ne = _dsd(num, den, k, tau, s)
            d = s * k * ne / dq if dq != 0 else 0j
            out.append(LocusCrossing("delay", float(tau), float(w), _sign(d.real, abs(d))))
            tau += period
    return sorted(out, key=lambda c: (c.value, c.frequency))


def _check(values: np.ndarray, unstable: np.ndarray, crossings: list[LocusCrossing]) -> str:
    """'' when every change of the right-half-plane count between two counted values matches the crossings there,
    else where it does not."""
    ok = np.flatnonzero(unstable >= 0)
    for a, b in zip(ok[:-1], ok[1:]):
        va, vb = values[a], values[b]
        # (a root on the axis at a value makes its count fail: a crossing lies strictly between counted values)
        want = sum(c.direction * c.roots for c in crossings if va < c.value < vb)
        if unstable[b] - unstable[a] != want:
            return (f"between {va:.6g} and {vb:.6g} the right-half-plane count goes from {unstable[a]} to "
                    f"{unstable[b]}, but the crossings found there change it by {want}")
    return ""


def _intervals(values: np.ndarray, stable: np.ndarray, unstable: np.ndarray, crossings: list[LocusCrossing]
               ) -> tuple[tuple[float, float], ...]:
    """The runs of stable values, each end moved to the crossing that bounds it (the last crossing before the run,
    the first after it, up to the nearest value whose count was made: at an uncounted value a root is on the
    axis, so the crossing may lie at it)."""
    out = []
    i, n = 0, values.size
    counted = np.flatnonzero(unstable >= 0)
    while i < n:
        if not stable[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and stable[j + 1]:
            j += 1
        lo, hi = float(values[i]), float(values[j])
        if i > 0:
            before = counted[counted < i]
            start = values[before[-1]] if before.size else values[0]
            inside = [c.value for c in crossings if start <= c.value <= values[i]]
            lo = max(inside) if inside else lo
        if j < n - 1:
            after = counted[counted > j]
            stop = values[after[0]] if after.size else values[-1]
            inside = [c.value for c in crossings if values[j] <= c.value <= stop]
            hi = min(inside) if inside else hi
        out.append((lo, hi))
        i = j + 1
    return tuple(out)


def _exact_intervals(values: np.ndarray, unstable: np.ndarray, crossings: list[LocusCrossing]
                     ) -> tuple[tuple[float, float], ...]:
    """The stable intervals from one counted value and the crossings (consistent with every count): the count of
    unstable roots is constant between crossings and moves by ``direction x roots`` at each, so an interval
    narrower than the grid's step is found too.  A crossing that leaves the count as it was (a root touching the
    axis, or two at once in opposite directions) still splits an interval: a root is on the axis there."""
    ok = np.flatnonzero(unstable >= 0)
    if ok.size == 0:
        return ()
    lo, hi = float(values[0]), float(values[-1])
    inner = sorted({c.value for c in crossings if lo < c.value < hi})
    edges = [lo, *inner, hi]
    jump = {v: sum(c.direction * c.roots for c in crossings if c.value == v) for v in inner}
    a = float(values[ok[0]])
    seg = min(max(int(np.searchsorted(edges, a, side="right")) - 1, 0), len(edges) - 2)
    counts = [0] * (len(edges) - 1)
    counts[seg] = int(unstable[ok[0]])
    for i in range(seg + 1, len(counts)):
        counts[i] = counts[i - 1] + jump[edges[i]]
    for i in range(seg - 1, -1, -1):
        counts[i] = counts[i + 1] - jump[edges[i + 1]]
    return tuple((float(edges[i]), float(edges[i + 1])) for i, n in enumerate(counts) if n == 0)


def _values(name: str, v: Any, minimum: float | None) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float).ravel()
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be an array of numbers, got {v!r}") from exc
    if a.size == 0:
        raise InvalidValueError(f"{name} is empty: give at least one value")
    if not np.all(np.isfinite(a)):
        raise InvalidValueError(f"{name} must be finite, got {a[~np.isfinite(a)][0]!r}")
    if a.size > 1 and not np.all(np.diff(a) > 0):
        i = int(np.flatnonzero(np.diff(a) <= 0)[0])
        raise InvalidValueError(f"{name} must be strictly increasing; value {i + 1} ({a[i + 1]:g}) follows {a[i]:g}")
    if minimum is not None and a[0] < minimum:
        raise InvalidValueError(f"{name} must be >= {minimum:g}, got {a[0]:g}")
    return a


def root_locus(L: Any, gains: Any = None, *, delays: Any = None, region: Sequence[float] | None = None,
               gain: float = 1.0) -> RootLocus:
    """The closed-loop roots of ``1 + k L(s) = 0`` as the gain ``k`` or the loop's delay moves, certified.

    With ``L(s) = N(s) / D(s) exp(-s T)`` the roots are those of ``D(s) + k N(s) exp(-s T)``.  At every value the
    roots in ``region`` are found and certified by the argument principle, and the roots in the right half-plane are
    counted (see the module's notes).  The crossings of the imaginary axis are found exactly, not from the grid:

    * over the gain: a root ``s = j w`` needs ``k = -D(jw) exp(jwT) / N(jw)`` real, so the frequencies are the
      zeros of ``Im(D(jw) conj N(jw) exp(jwT))`` (a polynomial for ``T = 0``, else scanned on ``[0, R]`` with
      ``R`` a bound on the right-half-plane roots for every gain of the range, and solved to rounding); the
      direction is the sign of ``Re ds/dk = -Re N e^{-sT} / Q'(s)``;
    * over the delay (the stability switches of Cooke & van den Driessche 1986, "On zeroes of some transcendental
      equations", Funkcialaj Ekvacioj 29; Walton & Marshall 1987; Gu, Kharitonov & Chen 2003, ch. 2): a root
      ``j w`` needs ``|D(jw)| = |k N(jw)|``, a polynomial in ``w^2``; for each positive root ``w`` the delays
      ``tau_0 + 2 pi n / w`` with ``exp(-j w tau_0) = -D(jw) / (k N(jw))``, and the direction, the same for every
      ``n``, is the sign of ``Re ds/dtau = Re(s k N e^{-s tau} / Q'(s))`` (Cooke and van den Driessche's
      ``sign F'(w)``, ``F = |D|^2 - k^2 |N|^2``).  Several frequencies can make a loop switch from stable to
      unstable and back as the delay grows.

    Parameters
    ----------
    L : Loop, AltitudeLoop, str, TransferFunction, DelayLTI or tuple
        The open loop (see :func:`open_loop_parts`): a loop's transfer function broken at the plant input with
        its whole delay, text such as ``"exp(-0.368*s)/s"``, a SISO system that is a rational function times one
        dead time (``tf(...)``), or ``(num, den[, delay])``.
    gains : array_like, optional
        Increasing gains ``k`` multiplying ``L`` (the loop's delay fixed).
    delays : array_like, optional
        Increasing delays ``>= 0`` replacing the loop's delay ``T`` (the gain fixed at ``gain``).  Give exactly
        one of ``gains`` and ``delays``.
    region : (re_min, re_max, im_min, im_max), optional
        Where the roots are listed.  Default: the square ``[-R, R] x [-R, R]``, with ``R`` a bound on every root
        in the right half-plane at every value (so every unstable root is listed).
    gain : float
        The gain multiplying ``L`` when the delay moves (default 1).

    Returns
    -------
    RootLocus

    Notes
    -----
    Honest limits: the crossing scan over the gain for ``T > 0`` samples ``Im(D conj N e^{jwT})`` some 20 times a
    radian of ``w T`` (densely across each open-loop pole or zero near the axis) and solves every sign change; a pair of crossings closer than a sample would be missed, but
    then the right-half-plane counts disagree with the crossings, the scan is refined, and if that does not help
    ``consistent`` is False with the place named.  A root that touches the axis without crossing is not found by
    the scan.  Multiple roots are listed repeated by multiplicity.  A biproper open loop whose gain range reaches
    ``|k n_0| >= |d_0|`` (the leading coefficients) makes the closed loop neutral with root chains on or right
    of the axis: that range is refused, with the gain named.

    Examples
    --------
    ``e^{-s}/s`` under gain: the first crossing at ``k = pi/2``, frequency ``pi/2`` (``k tau = pi/2``):

    >>> loc = root_locus("exp(-s)/s", gains=np.linspace(0.5, 3.0, 26))
    >>> loc
    RootLocus(gain over 26 values in [0.5, 3], 1 crossings, stable on [0.5, 1.5708], certified)
    >>> [round(loc.crossings[0].value, 12), round(loc.crossings[0].frequency, 12)] == [round(np.pi / 2, 12)] * 2
    True

    A loop that is stable, unstable and stable again as its delay grows (``s^2 + 0.1 s + 1 + 0.5 e^{-s tau}``):

    >>> loc = root_locus(([0.5], [1.0, 0.1, 1.0]), delays=np.linspace(0.0, 8.0, 81))
    >>> [(round(a, 4), round(b, 4)) for a, b in loc.stable_intervals]
    [(0.0, 0.202), (4.2198, 5.3582)]
    """
    if (gains is None) == (delays is None):
        raise InvalidValueError("give exactly one of gains= and delays=")
    num, den, T = open_loop_parts(L)
    if gains is not None:
        values = _values("gains", gains, None)
        parameter = "gain"
        kmax = float(np.max(np.abs(values)))
        W = _bound(num, den, kmax)
        fixed_gain, fixed_delay = None, T
        make = lambda v: (float(v), T)  # noqa: E731
        crossings = _gain_crossings(num, den, T, float(values[0]), float(values[-1]), W)
    else:
        values = _values("delays", delays, 0.0)
        parameter = "delay"
        g = check_real("gain", gain)
        W = _bound(num, den, abs(g))
        fixed_gain, fixed_delay = g, None
        make = lambda v: (g, float(v))  # noqa: E731
        crossings = _delay_crossings(num, den, g, float(values[0]), float(values[-1]))
    box = _check_region(region) if region is not None else (-W, W, -W, W)
    covers = box[0] <= 0.0 and box[1] >= W and box[2] <= -W and box[3] >= W

    n = values.size
    found: list[np.ndarray] = []
    counts = np.full(n, -1, dtype=int)
    certified = np.zeros(n, dtype=bool)
    unstable = np.full(n, -1, dtype=int)
    stable = np.zeros(n, dtype=bool)
    prev = np.zeros(0, complex)
    for i, v in enumerate(values):
        r, c, ok, unstable[i] = _roots_at(num, den, *make(v), box, prev, covers)
        r = r[np.lexsort((-r.imag, -r.real))] if r.size else r
        found.append(r)
        counts[i], certified[i] = c, ok
        prev = r if ok else np.zeros(0, complex)
        stable[i] = unstable[i] == 0
    reason = _check(values, unstable, crossings)
    if reason and parameter == "gain" and T > 0:  # a finer scan of the crossing function
        crossings = _gain_crossings(num, den, T, float(values[0]), float(values[-1]), W, refine=16)
        reason = _check(values, unstable, crossings)
    consistent = not reason
    if not np.all(certified):
        i = int(np.flatnonzero(~certified)[0])
        reason = (reason + "; " if reason else "") + (
            f"the roots at {parameter} {values[i]:.6g} could not be certified ({int((~certified).sum())} values)")
    # the intervals from the crossings where they agree with every count, else from the grid's stable runs
    intervals = (_exact_intervals(values, unstable, crossings) if consistent
                 else _intervals(values, stable, unstable, crossings))
    width = max((r.size for r in found), default=0)
    roots = np.full((n, width), np.nan + 0j, dtype=complex)
    for i, r in enumerate(found):
        roots[i, :r.size] = r
    return RootLocus(parameter=parameter, values=values, roots=roots, counts=counts, certified=certified,
                     unstable=unstable, stable=stable, crossings=tuple(crossings),
                     stable_intervals=intervals, region=box, gain=fixed_gain,
                     delay=fixed_delay, consistent=consistent, reason=reason)
