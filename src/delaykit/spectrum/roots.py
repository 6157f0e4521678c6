"""Every root of a retarded or neutral quasi-polynomial in a rectangle, with a certificate.

The method is "find cheaply, then certify":

1. candidates: the local minima of ``|Q|`` on a grid over the rectangle, each refined by Newton's method (all
   at once, vectorised);
2. certificate: the argument principle on the rectangle's boundary counts the roots inside.  The phase of ``Q``
   is tracked along each edge with adaptive sampling: between samples the phase may turn by at most 0.6 rad
   and the step times ``|Q'/Q|`` must stay below 0.6, so no root within reach of an edge can slip through.
   If a root sits on the boundary (``|Q|`` at rounding level), that edge is moved outwards by a small amount
   and the roots are reported in the closed original rectangle;
3. if the roots found are fewer than the count, the rectangle is split (along a line kept away from the roots
   already known) and each part is counted and searched again, with contour-integral (Delves-Lyness)
   estimates as Newton's starting points, until every part's count is matched.  A part whose boundary can no
   longer be evaluated above rounding noise while it still holds ``m >= 2`` roots is a cluster: its centroid,
   refined by Newton's method on ``Q^(m-1)``, is reported as one root of multiplicity ``m``.

The result says whether the count was matched (``certified``) and, if not, why: ``status`` (a
:class:`RootStatus`, for code) and ``reason`` (a sentence, for people).

Examples
--------
>>> from delaykit import AltitudeLoop
>>> sp = find_roots(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3).characteristic(), (-10, 2, 0, 100))
>>> sp.certified, sp.count, sp.status
(True, 7, <RootStatus.CERTIFIED: 'certified'>)
>>> sp.rightmost
(-3.1950...+5.5819...j)
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .. import _native
from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.budget import MAX_ROOT_GRID_POINTS, check_count
from ..models.quasipolynomial import QuasiPolynomial
from .neutral import difference_operator, neutral_abscissa

RK = _native.load("delaykit.spectrum", "_rootkernel")  # the compiled root-finding kernels (Cython, else numba)

__all__ = ["RootStatus", "Spectrum", "find_roots", "neutral_lines", "root_bound"]

_RELIABLE = 32.0  # |Q| must exceed this many times its rounding-error bound on a boundary
_MAX_PHASE = 0.6
_CAP = 4_000_000


class RootStatus(enum.Enum):
    """How a root search ended: certified, or the cause that stopped the certificate.

    Code decides by this (``sp.status is RootStatus.SAMPLE_BUDGET``); the result's ``reason`` says the same in
    words, with the numbers, for people.  The value is the name used in JSON.
    """

    #: the roots found (with multiplicity) match the argument principle's count
    CERTIFIED = "certified"
    #: a root lies on or next to a boundary edge (``|Q|`` there is at rounding level), and moving the edges
    #: outwards did not clear it
    ROOT_ON_BOUNDARY = "root_on_boundary"
    #: tracking the phase along the boundary needs more samples than the budget allows
    SAMPLE_BUDGET = "sample_budget"
    #: the argument principle gave a count that is not an integer
    NON_INTEGER_COUNT = "non_integer_count"
    #: the subdivision reached its depth limit with a part still unmatched
    DEPTH_LIMIT = "depth_limit"
    #: the counts of the two halves of a part do not add up to the part's count
    INCONSISTENT_COUNTS = "inconsistent_counts"
    #: fewer (or more) roots were found than the argument principle counts
    COUNT_MISMATCH = "count_mismatch"
    #: the certificate was not asked for (``certify=False``)
    NOT_REQUESTED = "not_requested"

    @property
    def ok(self) -> bool:
        """True for :attr:`CERTIFIED`."""
        return self is RootStatus.CERTIFIED

    @property
    def retryable(self) -> bool:
        """True when the count may succeed on a slightly larger box (a root on the boundary); a sample budget or
        a non-integer count is not cured by moving the edges."""
        return self is RootStatus.ROOT_ON_BOUNDARY


class _Eval:
    """A quasi-polynomial as the arrays the compiled kernels take (coefficients padded, highest degree first,
    their moduli, the delays), and a vectorised evaluation of Q for the real-axis scan."""

    def __init__(self, q: QuasiPolynomial) -> None:
        deg = q.degree
        nt = len(q.delays)
        self.tau = np.array(q.delays, dtype=float)
        self.C = np.zeros((nt, deg + 1), dtype=complex)
        for i, p in enumerate(q.polys):
            self.C[i, deg + 1 - len(p):] = p
        self.A = np.ascontiguousarray(np.abs(self.C))
        self.deg = deg
        self.real = bool(np.all(self.C.imag == 0))
        self.evals = 0

    def value(self, s: np.ndarray) -> np.ndarray:
        self.evals += s.size
        with np.errstate(over="ignore", invalid="ignore"):  # far left, exp overflows: Q is inf there
            E = np.exp(-np.multiply.outer(s, self.tau))
            return np.einsum("ij,ij->i", (s[:, None] ** np.arange(self.deg, -1, -1)) @ self.C.T, E)


def _contour(ev: _Eval, corners: list[complex], cap: int | None = None) -> _Count:
    """Track the phase of Q around a closed polygon (adaptive, compiled); the count and the samples."""
    cap = _CAP if cap is None else cap
    taumax = float(ev.tau.max()) if ev.tau.size else 0.0
    cs = np.array(corners, dtype=complex)
    n_edges = 8 + np.abs(np.roll(cs, -1) - cs) * (taumax + 0.25) / _MAX_PHASE
    if not n_edges.sum() <= cap:  # (as floats: a region of size 1e30, from a huge gain, is past any integer)
        return _Count(0, RootStatus.SAMPLE_BUDGET, f"the boundary needs more than {cap} samples (too coarse to certify)",
                      np.zeros(0, complex), np.zeros(0, complex))
    n_init = n_edges.astype(np.int64)
    size = int(min(cap, 4 * int(n_init.sum()) + 4096))
    while True:
        out_s = np.empty(size, complex)
        out_dl = np.empty(size, complex)
        status, total, m, where = RK.contour(ev.C, ev.A, ev.tau, cs, n_init, _MAX_PHASE, _RELIABLE, cap, out_s, out_dl)
        ev.evals += m
        if status == 1:
            return _Count(0, RootStatus.ROOT_ON_BOUNDARY,
                          f"a root lies on or next to the boundary near {complex(where):.6g}",
                          np.zeros(0, complex), np.zeros(0, complex))
        if status == 2:
            return _Count(0, RootStatus.SAMPLE_BUDGET,
                          f"the boundary needs more than {cap} samples (too coarse to certify)",
                          np.zeros(0, complex), np.zeros(0, complex))
        if m <= size:
            break
        size = m + 16
    n = int(round(total))
    if abs(total - n) > 0.05 or n < 0:
        return _Count(0, RootStatus.NON_INTEGER_COUNT, f"the argument principle gave a non-integer count {total:.3f}",
                      np.zeros(0), np.zeros(0))
    return _Count(n, RootStatus.CERTIFIED, "", out_s[:m], out_dl[:m])


@dataclass
class _Count:
    """The argument principle's count on a contour: ``status`` is CERTIFIED when ``n`` is valid, else why not
    (``reason`` in words)."""

    n: int
    status: RootStatus
    reason: str
    s: np.ndarray
    dlog: np.ndarray

    @property
    def ok(self) -> bool:
        return self.status is RootStatus.CERTIFIED


def _count(ev: _Eval, box: tuple[float, float, float, float]) -> _Count:
    x0, x1, y0, y1 = box
    return _contour(ev, [complex(x0, y0), complex(x1, y0), complex(x1, y1), complex(x0, y1)])


def _moments(c: _Count, m: int) -> np.ndarray:
    """Power sums p_k = (1/2 pi i) contour integral of s^k Q'/Q ds, k = 0..m, from the boundary samples."""
    return np.array([np.sum(c.s**k * c.dlog) / (2j * math.pi) for k in range(m + 1)])


def _from_power_sums(p: np.ndarray, m: int) -> np.ndarray:
    """Roots of the degree-m polynomial whose root power sums are p[1..m] (Newton's identities)."""
    e = np.zeros(m + 1, complex)
    e[0] = 1.0
    for k in range(1, m + 1):
        e[k] = sum((-1) ** (i - 1) * e[k - i] * p[i] for i in range(1, k + 1)) / k
    coeffs = np.array([(-1) ** k * e[k] for k in range(m + 1)])
    return np.roots(coeffs) if m > 0 else np.zeros(0, complex)


def _newton(ev: _Eval, s0: np.ndarray, maxit: int = 60, box: tuple[float, float, float, float] | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton from each start (compiled).  Returns the points, whether each converged, and whether it
    converged *cleanly* (a vanishing step, as at a simple root) rather than by reaching the rounding-noise
    floor (as Newton's linear convergence to a multiple root does)."""
    s0 = np.ascontiguousarray(np.asarray(s0, dtype=complex).ravel())
    bx = np.array(box if box is not None else (-1e300, 1e300, -1e300, 1e300), dtype=float)
    ev.evals += s0.size
    return RK.newton(ev.C, ev.A, ev.tau, s0, maxit, bx)


def _inside(s: np.ndarray, box: tuple[float, float, float, float], tol: float = 0.0) -> np.ndarray:
    x0, x1, y0, y1 = box
    return (s.real >= x0 - tol) & (s.real <= x1 + tol) & (s.imag >= y0 - tol) & (s.imag <= y1 + tol)


def _dedupe(s: np.ndarray) -> np.ndarray:
    if s.size == 0:
        return s
    s = s[np.lexsort((s.imag, s.real))]
    keep = [s[0]]
    for z in s[1:]:
        if all(abs(z - k) > 1e-9 * (1.0 + abs(z)) for k in keep[-8:]):
            keep.append(z)
    return np.array(keep)


def _grid_candidates(ev: _Eval, box: tuple[float, float, float, float], ds: tuple[float, float]) -> np.ndarray:
    """Local minima of |Q| on a grid over the box (compiled)."""
    x0, x1, y0, y1 = box
    dx, dy = ds
    xs = np.arange(x0 - dx, x1 + 1.5 * dx, dx)
    ys = np.arange(y0 - dy, y1 + 1.5 * dy, dy)
    ev.evals += xs.size * ys.size
    return RK.grid_minima(ev.C, ev.tau, xs, ys)


def root_bound(q: QuasiPolynomial, re_min: float = 0.0, *, lead: float | None = None) -> float:
    """A radius R such that every root with ``Re s >= re_min`` has ``|s| <= R`` (retarded, or neutral with
    the delayed leading coefficients smaller than the undelayed one there).

    ``lead``, when given, is a lower bound on the modulus of the difference operator (the top-degree
    coefficients, ``|sum_k b_k exp(-s tau_k)|``) over ``Re s >= re_min``, known from elsewhere (a system's
    channels: :meth:`~delaykit.spectrum.neutral.ChannelAbscissa.lead`); by default it is
    ``|a_0| - sum_k |b_k| exp(-re_min tau_k)``.

    For ``Re s >= re_min``: ``|p_0(s)| >= |a_n| |s|^n - sum_k |a_k| |s|^k`` and each delayed term is at most
    ``sum_k |b_k| |s|^k exp(-re_min tau)``; ``R = 2 max_k (c_k / lead)^(1/k)`` (Fujiwara's form) makes the
    first bound exceed the second for ``|s| >= R``.

    Examples
    --------
    >>> from delaykit import QuasiPolynomial
    >>> R = root_bound(QuasiPolynomial([[1, 0], [1.31]], [0, 0.368]))
    >>> R >= 1.31  # |s| = 1.31 |exp(-0.368 s)| <= 1.31 for Re s >= 0
    True
    """
    zero = [p for p, t in zip(q.polys, q.delays) if t == 0.0]
    if not zero:
        raise InvalidValueError("the quasi-polynomial has no delay-free term; no root bound exists")
    p0 = np.abs(np.array(zero[0]))
    n = p0.size - 1
    if n == 0:
        raise InvalidValueError("the delay-free polynomial is a constant; roots are not bounded")
    others = np.zeros(n + 1)
    for p, t in zip(q.polys, q.delays):
        if t > 0:
            with np.errstate(over="ignore"):  # (coefficients near 1e308: an infinite bound, refused by its users)
                a = np.abs(np.array(p)) * math.exp(-re_min * t)
            if a.size > n + 1:
                raise InvalidValueError("an advanced quasi-polynomial has no root bound")
            others[n + 1 - a.size:] += a
    if lead is None:
        lead = p0[0] - others[0]
    if lead <= 0:
        raise InvalidValueError(
            f"neutral chains reach Re s = {re_min:g}: no bounded region holds every root there"
        )
    rest = p0[1:] + others[1:]
    # Fujiwara-type bound: with R = 2 max_k (rest_k / lead)^(1/k), sum_k rest_k R^(n-k) <= lead R^n sum_k 2^-k
    # < lead R^n, so no root has |s| >= R
    k = np.arange(1, n + 1)
    R = 2.0 * float(np.max((rest / lead) ** (1.0 / k))) if rest.size else 0.0
    return max(R, 1e-12)


def neutral_lines(q: QuasiPolynomial) -> tuple[float, ...]:
    """The vertical lines Re s = x that the root chains of a neutral quasi-polynomial approach.

    With one delay in the top-degree terms, ``a_n + b_n exp(-s tau) = 0`` gives ``x = ln|b_n / a_n| / tau``
    (for the PV loop, ``ln(Kv) / Td``).  With several, the real parts of the difference operator's roots need not
    lie on lines; the one value returned is the supremum of their closure by the polygon condition
    (:func:`~delaykit.spectrum.neutral.neutral_abscissa`): exact for rationally independent delays, an upper bound
    otherwise, so a verdict drawn from it is conservative.  Retarded quasi-polynomials have none.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> round(neutral_lines(AltitudeLoop(kp=2, delay=0.37, kv=0.3).characteristic())[0], 4)
    -3.254
    """
    if q.kind != "neutral":
        return ()
    a0, b, tau = difference_operator(q)
    if len(b) == 1:
        return (math.log(abs(b[0] / a0)) / tau[0],)
    return (neutral_abscissa(q).abscissa,)


@dataclass(frozen=True, repr=False, eq=False)
class Spectrum:
    """The roots of a quasi-polynomial in a rectangle.

    Attributes
    ----------
    roots : ndarray of complex
        Distinct roots, by decreasing real part.
    multiplicities : ndarray of int
    region : tuple
        ``(re_min, re_max, im_min, im_max)`` as asked.
    count : int or None
        Roots in the region by the argument principle (with multiplicity); ``None`` if it could not be counted.
    certified : bool
        True when the roots found (with multiplicity) match ``count``.
    reason : str
        Why not, when not certified (for people; code reads ``status``).
    kind : str
        ``"retarded"`` or ``"neutral"``.
    neutral_lines : tuple of float
        Vertical lines approached by neutral root chains.
    evaluations : int
        How many times Q was evaluated.
    status : RootStatus
        :attr:`RootStatus.CERTIFIED`, or the cause that stopped the certificate.  When not given it follows
        ``certified`` (a bare failure is :attr:`RootStatus.COUNT_MISMATCH`).
    """

    roots: np.ndarray
    multiplicities: np.ndarray
    region: tuple[float, float, float, float]
    count: int | None
    certified: bool
    reason: str
    kind: str
    neutral_lines: tuple[float, ...]
    evaluations: int = 0
    status: RootStatus | None = None

    def __post_init__(self) -> None:
        if self.status is None:
            object.__setattr__(self, "status", RootStatus.CERTIFIED if self.certified else RootStatus.COUNT_MISMATCH)
        elif not isinstance(self.status, RootStatus):
            raise InvalidTypeError(f"status must be a RootStatus, got {self.status!r}")
        elif self.status.ok != bool(self.certified):
            raise InvalidValueError(f"status {self.status.name} contradicts certified={self.certified}")

    @property
    def rightmost(self) -> complex | None:
        """The root of largest real part in the region (Im >= 0 preferred on a tie), or None."""
        if self.roots.size == 0:
            return None
        score = self.roots.real + 1e-12 * np.sign(self.roots.imag)
        return complex(self.roots[int(np.argmax(score))])

    @property
    def abscissa(self) -> float:
        """Largest real part over the roots found and the neutral lines (the spectral abscissa, if the region
        holds the rightmost root)."""
        xs = list(self.roots.real) + list(self.neutral_lines)
        return float(max(xs)) if xs else -math.inf

    @property
    def stable(self) -> bool:
        """Every root found, and every neutral line, is strictly in the left half-plane."""
        return self.abscissa < 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the format of ``delaykit roots --json``)."""
        rm = self.rightmost
        return {
            "roots": [[float(s.real), float(s.imag)] for s in self.roots],
            "multiplicities": [int(m) for m in self.multiplicities],
            "rightmost": None if rm is None else [rm.real, rm.imag],
            "neutral_line": self.neutral_lines[0] if len(self.neutral_lines) == 1 else (list(self.neutral_lines) or None),
            "stable": self.stable,
            "certified": self.certified,
            "status": self.status.value,
            "count": self.count,
            "reason": self.reason or None,
            "region": list(self.region),
            "kind": self.kind,
        }

    def __repr__(self) -> str:
        rm = self.rightmost
        rms = "none" if rm is None else f"{rm.real:.4f}{rm.imag:+.4f}j"
        cert = "certified" if self.certified else f"NOT certified: {self.reason}"
        extra = f", neutral line {self.neutral_lines[0]:.4f}" if len(self.neutral_lines) == 1 else ""
        nm = int(self.multiplicities.sum()) if self.roots.size else 0
        return f"Spectrum({nm} roots in {self.region}, rightmost {rms}{extra}, {cert})"


def _check_region(region: Sequence[float]) -> tuple[float, float, float, float]:
    try:
        vals = [float(v) for v in region]
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"region must be four numbers (re_min, re_max, im_min, im_max), got {region!r}") from exc
    if len(vals) != 4:
        raise InvalidValueError(f"region must be four numbers (re_min, re_max, im_min, im_max), got {len(vals)}")
    if not all(math.isfinite(v) for v in vals):
        raise InvalidValueError(f"region must be finite, got {vals}")
    x0, x1, y0, y1 = vals
    if not x0 < x1:
        raise InvalidValueError(f"region: re_min must be less than re_max, got {x0:g} >= {x1:g}")
    if not y0 < y1:
        raise InvalidValueError(f"region: im_min must be less than im_max, got {y0:g} >= {y1:g}")
    return x0, x1, y0, y1


def _nudged_count(ev: _Eval, box: tuple[float, float, float, float],
                  known: np.ndarray | None = None) -> tuple[tuple[float, float, float, float], _Count]:
    """Count on the box, first moving outwards any edge that a known root sits on or next to, then (if a
    root still spoils an edge) moving all edges out step by step."""
    x0, x1, y0, y1 = box
    scale = max(x1 - x0, y1 - y0)
    if known is not None and known.size:
        near = 2e-3 * scale
        inb = _inside(known, box, near)
        k = known[inb]
        move = 0.01 * scale
        if np.any(np.abs(k.real - x0) < near):
            x0 -= move
        if np.any(np.abs(k.real - x1) < near):
            x1 += move
        if np.any(np.abs(k.imag - y0) < near):
            y0 -= move
        if np.any(np.abs(k.imag - y1) < near):
            y1 += move
    grown = (x0, x1, y0, y1)
    c = _count(ev, grown)
    delta = 1e-4 * scale
    # only a root on the boundary is cured by moving the edges out; a sample budget or a non-integer count is not
    while c.status.retryable and delta < 5e-2 * scale:
        grown = (x0 - delta, x1 + delta, y0 - delta, y1 + delta)
        c = _count(ev, grown)
        delta *= 4.0
    return grown, c


def _split_boxes(box, known: np.ndarray):
    x0, x1, y0, y1 = box
    vertical = (x1 - x0) >= (y1 - y0)
    lo, hi = (x0, x1) if vertical else (y0, y1)
    coord = known.real if vertical else known.imag
    best, best_d = 0.5, -1.0
    for f in (0.5, 0.45, 0.55, 0.4, 0.6, 0.35, 0.65):
        c = lo + f * (hi - lo)
        d = np.min(np.abs(coord - c)) if coord.size else math.inf
        if d > 0.02 * (hi - lo):
            best = f
            break
        if d > best_d:
            best, best_d = f, d
    c = lo + best * (hi - lo)
    if vertical:
        return (x0, c, y0, y1), (c, x1, y0, y1)
    return (x0, x1, y0, c), (x0, x1, c, y1)


def _cluster(q: QuasiPolynomial, ev: _Eval, box, cnt: _Count) -> tuple[complex, int] | None:
    """A cluster of cnt.n roots in a box whose boundary is still reliable: one root of that multiplicity."""
    m = cnt.n
    p = _moments(cnt, 1)
    c0 = p[1] / m
    dq = q
    for _ in range(m - 1):
        dq = dq.derivative()
    ev_d = _Eval(dq)
    s, conv, _ = _newton(ev_d, np.array([c0]))
    ev.evals += ev_d.evals
    r = complex(s[0])
    if not conv[0] or not _inside(np.array([r]), box, 1e-9)[0]:
        return None
    return r, m


def _absorb(q: QuasiPolynomial, ev: _Eval, known: np.ndarray, kmult: np.ndarray, s: np.ndarray,
            clean: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """Add Newton's results to the known roots.  Clean ones are simple roots; points that only reached the
    noise floor are grouped, and each group becomes one root whose multiplicity is counted on the smallest
    box around it with a reliable boundary."""
    simple = _dedupe(s[clean])
    keep = np.array([not np.any(np.abs(known - z) <= 1e-9 * (1 + abs(z))) for z in simple], dtype=bool)
    known = np.concatenate([known, simple[keep]])
    kmult = np.concatenate([kmult, np.ones(int(keep.sum()), dtype=int)])
    noisy = list(s[~clean])
    while noisy:
        z = noisy.pop()
        group = [z] + [w for w in noisy if abs(w - z) <= 1e-2 * (1 + abs(z))]
        noisy = [w for w in noisy if abs(w - z) > 1e-2 * (1 + abs(z))]
        c = complex(np.mean(group))
        if np.any(np.abs(known - c) <= 1e-2 * (1 + abs(c))):
            continue  # already known (simple or a cluster found before)
        r = 1e-3 * (1 + abs(c))
        while r < 0.05 * scale:
            b = (c.real - r, c.real + r, c.imag - r, c.imag + r)
            cnt = _count(ev, b)
            if cnt.ok:
                if cnt.n >= 2:
                    cl = _cluster(q, ev, b, cnt)
                    if cl is not None:
                        known = np.append(known, cl[0])
                        kmult = np.append(kmult, cl[1])
                elif cnt.n == 1:
                    s1, conv1, _ = _newton(ev, np.array([_moments(cnt, 1)[1]]))  # the count says simple
                    if conv1[0]:
                        known = np.append(known, s1[0])
                        kmult = np.append(kmult, 1)
                break
            r *= 2.0
    return known, kmult


def find_roots(
    q: QuasiPolynomial,
    region: Sequence[float],
    *,
    ds: float | None = None,
    certify: bool = True,
    max_depth: int = 40,
) -> Spectrum:
    """All roots of ``q`` in the closed rectangle ``region = (re_min, re_max, im_min, im_max)``.

    Parameters
    ----------
    q : QuasiPolynomial
        Retarded or neutral (``q.kind``); an :class:`~delaykit.models.altitude.AltitudeLoop` is accepted too.
    region : sequence of 4 floats
        The rectangle.
    ds : float, optional
        Grid step for the candidate search (default: from the region and the largest delay).  The certificate
        does not depend on it; a coarse grid only costs time in the subdivision stage.
    certify : bool
        Run the argument-principle certificate and the subdivision stage (default True).
    max_depth : int
        Subdivision depth limit.

    Returns
    -------
    Spectrum

    Examples
    --------
    The six-fold real root of ``(s + 6.025)^6`` is one root of multiplicity 6:

    >>> sp = find_roots(QuasiPolynomial([np.poly([-6.025] * 6)], [0.0]), (-8, -4, -1, 1))
    >>> sp.roots.size, int(sp.multiplicities[0]), round(float(sp.roots[0].real), 6)
    (1, 6, -6.025)
    """
    from ..models.altitude import AltitudeLoop

    if isinstance(q, AltitudeLoop):
        q = q.characteristic()
    if not isinstance(q, QuasiPolynomial):
        raise InvalidTypeError(f"q must be a QuasiPolynomial or an AltitudeLoop, got {type(q).__name__}")
    box = _check_region(region)
    kind = q.kind
    if kind == "advanced":
        raise InvalidValueError("advanced quasi-polynomials (a delayed term of higher degree) have no bounded root sets")
    if ds is not None:
        ds = check_real("ds", ds, minimum=0.0, strict=True)
    ev = _Eval(q)
    x0, x1, y0, y1 = box
    taumax = float(ev.tau.max()) if ev.tau.size else 0.0
    if ds is None:
        # roots of chains are about 2 pi / tau apart along Im; across Re a coarser grid finds the minima
        dy = min((y1 - y0) / 24.0, 2 * math.pi / (6.0 * taumax) if taumax > 0 else math.inf)
        dx = min((x1 - x0) / 24.0, 4 * dy)
        grid = (dx, dy)
    else:
        grid = (ds, ds)
    lines = neutral_lines(q) if kind == "neutral" and q.degree > 0 else ()

    scale = max(x1 - x0, y1 - y0)
    margin = 0.05 * scale
    search = (x0 - margin, x1 + margin, y0 - margin, y1 + margin)
    points = (((search[1] - search[0]) / grid[0] + 3.0) * ((search[3] - search[2]) / grid[1] + 3.0)
              if grid[0] > 0 and grid[1] > 0 else math.inf)  # (a delay near the largest float: 2 pi / 6 tau is 0)
    check_count(f"the root search in region {tuple(box)} with the delay {taumax:g} s", points, MAX_ROOT_GRID_POINTS,
                "grid points", "give a smaller region (the grid has some six points per 2 pi / delay along Im)")
    cand = _grid_candidates(ev, search, grid)
    if ev.real and search[2] <= 0.0 <= search[3]:
        # real roots of a real quasi-polynomial: sign changes of Q along the real axis
        xr = np.linspace(search[0], search[1], 256)
        qr = ev.value(xr.astype(complex)).real
        ch = np.flatnonzero(np.isfinite(qr[:-1]) & np.isfinite(qr[1:]) & (np.sign(qr[:-1]) != np.sign(qr[1:])))
        cand = np.concatenate([cand, 0.5 * (xr[ch] + xr[ch + 1]) + 0j])
    s0, conv, clean = _newton(ev, cand, box=search)
    if ev.real:  # roots of a real quasi-polynomial come in conjugate pairs
        s0, conv, clean = np.concatenate([s0, s0.conj()]), np.tile(conv, 2), np.tile(clean, 2)
    ins = conv & _inside(s0, search)
    known, mult = _absorb(q, ev, np.zeros(0, complex), np.zeros(0, dtype=int), s0[ins], clean[ins], scale)
    if certify:
        grown, cnt = _nudged_count(ev, box, known)
    else:
        grown, cnt = box, _Count(0, RootStatus.NOT_REQUESTED, "not certified (certify=False)", np.zeros(0), np.zeros(0))
    keep0 = _inside(known, grown)
    known, mult = known[keep0], mult[keep0]
    certified, status, reason, count = False, cnt.status, cnt.reason, (cnt.n if cnt.ok else None)

    if certify and cnt.ok:
        ok_all, why, why_status = True, "", RootStatus.CERTIFIED
        stack = [(grown, cnt, 0)]
        while stack:
            b, c, depth = stack.pop()
            inb = _inside(known, b)
            if int(mult[inb].sum()) == c.n:
                continue
            if c.n == 0:
                continue  # Newton roots slightly outside a part are counted by their own part
            # contour-integral estimates for a few missing roots
            if c.n <= 6:
                est = _from_power_sums(_moments(c, c.n), c.n)
                s2, conv2, clean2 = _newton(ev, est)
                ok2 = conv2 & _inside(s2, b, 1e-12)
                known, mult = _absorb(q, ev, known, mult, s2[ok2], clean2[ok2], scale)
                inb = _inside(known, b)
                if int(mult[inb].sum()) == c.n:
                    continue
            if depth >= max_depth:
                ok_all, why_status = False, RootStatus.DEPTH_LIMIT
                why = f"subdivision depth {max_depth} reached near {complex((b[0] + b[1]) / 2, (b[2] + b[3]) / 2):.6g}"
                continue
            b1, b2 = _split_boxes(b, known[inb])
            c1, c2 = _count(ev, b1), _count(ev, b2)
            if not (c1.ok and c2.ok and c1.n + c2.n == c.n):
                if c.n >= 2:
                    cl = _cluster(q, ev, b, c)
                    if cl is not None:
                        known, mult = known[~inb], mult[~inb]
                        known, mult = np.append(known, cl[0]), np.append(mult, cl[1])
                        continue
                bad = c1 if not c1.ok else c2 if not c2.ok else None
                ok_all = False
                if bad is not None:
                    why, why_status = bad.reason, bad.status
                else:
                    why, why_status = f"inconsistent counts {c1.n} + {c2.n} != {c.n}", RootStatus.INCONSISTENT_COUNTS
                continue
            stack.append((b1, c1, depth + 1))
            stack.append((b2, c2, depth + 1))
        inside = _inside(known, grown)
        known, mult = known[inside], mult[inside]
        total = int(mult.sum())
        certified = ok_all and total == cnt.n
        if certified:
            status, reason = RootStatus.CERTIFIED, ""
        elif not ok_all:
            status, reason = why_status, why
        else:
            status, reason = RootStatus.COUNT_MISMATCH, f"found {total} roots but the argument principle counts {cnt.n}"
    # report the roots in the closed original region; snap real roots of real quasi-polynomials
    if ev.real and known.size:
        snap = np.abs(known.imag) <= 1e-10 * (1 + np.abs(known))
        known = np.where(snap, known.real + 0j, known)
    keep = _inside(known, box, 1e-10 * max(x1 - x0, y1 - y0))
    known, mult = known[keep], mult[keep]
    if grown != box and count is not None:
        count = int(mult.sum()) if certified else count
    order = np.lexsort((-known.imag, -known.real))
    return Spectrum(roots=known[order], multiplicities=mult[order], region=box, count=count, certified=certified,
                    reason=reason, kind=kind, neutral_lines=lines, evaluations=ev.evals, status=status)
