"""The exact open-loop frequency response of a continuous delay loop, and the crossings of its Nyquist curve.

Private machinery of :mod:`delaykit.spectrum.frequency` (which documents the method): :class:`OpenLoop` holds
``L(s) = N(s) / D(s) exp(-s T)`` with the roots of ``N`` and ``D``, evaluates ``L(jw)``, its unwrapped phase (a
sum of the angles of the root factors minus ``w T``) and the phase's derivative; :func:`gain_crossovers` finds
``|L(jw)| = 1`` from a polynomial in ``w^2``; :func:`scan_phase` finds the phase crossovers on a dense grid and
counts the encirclements of -1; :func:`cutoff_frequency` and :func:`dense_grid` choose where to look.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidValueError
from ..models.loop import Loop

__all__ = ["OpenLoop", "PhaseScan", "gain_crossovers", "scan_phase", "cutoff_frequency", "dense_grid",
           "positive_real_roots", "snap_half_turns", "horner", "solve_bracketed", "newton_bracketed",
           "refine_minimum", "TWO_PI"]

_AXIS_TOL = 1e-9  # a root with |Re r| <= _AXIS_TOL |r| is taken to lie on the imaginary axis
_LEVEL_TOL = 1e-11  # phases within this many (relative) half-turns of an odd multiple of pi are on it
_PER_DECADE = 100
_MAX_PHASE_CROSSOVERS = 10_000
TWO_PI = 2.0 * math.pi


def horner(c: Sequence[float], s: Any) -> Any:
    """The polynomial with coefficients ``c`` (highest power first, Python floats) at ``s`` (a number or an
    array): Horner's rule, several times faster than :func:`numpy.polyval` on the few coefficients of a loop."""
    y = 0.0 * s
    for a in c:
        y = y * s + a
    return y


def _trim(p: np.ndarray) -> np.ndarray:
    """Leading zeros stripped (an empty array for the zero polynomial)."""
    nz = np.flatnonzero(p)
    return p[nz[0]:] if nz.size else p[:0]


def _nonzero_roots(polys: Sequence[np.ndarray]) -> tuple[np.ndarray, int]:
    """The roots other than 0 of the product of ``polys`` (each factored on its own), and how many are 0."""
    roots: list[complex] = []
    zeros = 0
    for p in polys:
        c = [float(x) for x in p]  # a few coefficients: plain Python is faster than NumPy here
        while c and c[0] == 0:
            c.pop(0)
        while len(c) > 1 and c[-1] == 0:
            c.pop()
            zeros += 1
        if len(c) == 2:
            roots.append(complex(-c[1] / c[0]))
        elif len(c) == 3:  # the quadratic formula, without cancellation, and exact conjugates
            a, b, d = c
            disc = b * b - 4 * a * d
            if disc < 0:
                z = complex(-b / (2 * a), math.sqrt(-disc) / (2 * abs(a)))
                roots += [z, z.conjugate()]
            else:
                q = -0.5 * (b + math.copysign(math.sqrt(disc), b))
                roots += [complex(q / a), complex(d / q if q != 0 else q / a)]
        elif len(c) > 3:
            roots += [complex(z) for z in np.roots(c)]
    snapped = [complex(0.0, z.imag) if abs(z.real) <= _AXIS_TOL * abs(z) else z for z in roots]
    zeros += sum(z == 0 for z in snapped)  # a root at rounding level of 0 is one
    return np.array([z for z in snapped if z != 0], complex), zeros


class OpenLoop:
    """``L(jw)`` of a continuous loop, its exact unwrapped phase and the phase's derivative."""

    def __init__(self, loop: Loop) -> None:
        nc, dc = loop.controller.feedback_polynomials()
        p = loop.plant
        num, den = np.convolve(p.num, nc), np.convolve(p.den, dc)  # loop.open_loop(), without poly1d's overhead
        self.num = _trim(num)
        self.den = _trim(den)
        self.T = float(loop.total_delay)
        self.zero = self.num.size == 0 or not self.num.any()
        if self.zero:
            self.num = np.zeros(1)
        self.cn, self.cd = [float(c) for c in self.num], [float(c) for c in self.den]
        self.cdn = [c * (len(self.cn) - 1 - i) for i, c in enumerate(self.cn[:-1])] or [0.0]  # N' and D'
        self.cdd = [c * (len(self.cd) - 1 - i) for i, c in enumerate(self.cd[:-1])] or [0.0]
        # N, D, N', D', N'', D'' as the columns of one matrix on the powers of s (highest first): one product
        # evaluates all
        n = max(self.num.size, self.den.size)
        self.K = np.zeros((n, 6))
        for j, c in enumerate((self.cn, self.cd, self.cdn, self.cdd)):
            self.K[n - len(c):, j] = c
        self.K[1:, 4:] = self.K[:-1, 2:4] * np.arange(n - 1, 0, -1)[:, None] if n > 1 else 0.0
        self.zr, self.z0 = _nonzero_roots([p.num, nc])
        self.pr, self.p0 = _nonzero_roots([p.den, dc])
        self.integrators = self.p0 - self.z0  # net poles at s = 0
        self.k_term = 0.0 if self.zero or self.num[0] / self.den[0] > 0 else -math.pi
        # |L(j inf)|: nonzero only for a biproper loop
        self.l_inf = abs(self.num[0] / self.den[0]) if self.num.size == self.den.size and not self.zero else 0.0
        self.zparts, self.pparts = self._split(self.zr), self._split(self.pr)
        self.offset = 0.0
        # the phase at w = 0 without the offset: each real root right of the axis gives pi (atan2(0, -a)), the
        # other factors 0
        raw0 = ((self.z0 - self.p0) * math.pi / 2 + self.k_term
                + math.pi * (int(np.sum(self.zparts[0] > 0)) - int(np.sum(self.pparts[0] > 0))))
        self.offset = TWO_PI * round((-self.integrators * math.pi / 2 - raw0) / TWO_PI)

    # -- values -------------------------------------------------------------------------------------
    def _polys(self, s: np.ndarray, cols: slice) -> np.ndarray:
        """Columns ``cols`` of ``[N, D, N', D']`` at the points ``s`` (one row a point)."""
        return np.vander(s.ravel(), self.K.shape[0]) @ self.K[:, cols]

    def value(self, w: np.ndarray) -> np.ndarray:
        w = np.asarray(w, float)
        s = 1j * w
        with np.errstate(all="ignore"):
            if s.size > 64:  # (on many points Horner's rule is the faster)
                return horner(self.cn, s) / horner(self.cd, s) * np.exp(-s * self.T)
            nd = self._polys(s, slice(0, 2))
            return (nd[:, 0] / nd[:, 1]).reshape(w.shape) * np.exp(-s * self.T)

    def sensitivity_slope(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Half the first and second derivatives of ``|1 + L(jw)|^2`` in ``w``: ``Re(conj(1 + L) L_w)`` and
        ``|L_w|^2 + Re(conj(1 + L) L_ww)`` (``L_w = j L_s``, ``L_ww = -L_ss``), for Newton's method on the first."""
        w = np.asarray(w, float).ravel()
        s = 1j * w
        with np.errstate(all="ignore"):
            n, d, dn, dd, ddn, ddd = self._polys(s, slice(0, 6)).T
            e = np.exp(-s * self.T)
            r, r1 = n / d, (dn * d - n * dd) / (d * d)
            r2 = (ddn * d - n * ddd) / (d * d) - 2.0 * dd * r1 / d
            T = self.T
            one = 1.0 + r * e
            lw = 1j * (r1 - T * r) * e
            lww = -(r2 - 2.0 * T * r1 + T * T * r) * e
        return (one.conj() * lw).real, (np.abs(lw) ** 2 + (one.conj() * lww).real)

    def slope(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``L(jw)`` and ``dL/dw`` (``j dL/ds``), without dividing by ``N`` (finite at a zero of ``L``)."""
        w = np.asarray(w, float).ravel()
        s = 1j * w
        with np.errstate(all="ignore"):
            n, d, dn, dd = self._polys(s, slice(0, 4)).T
            e = np.exp(-s * self.T)
            L = n / d * e
            dL = ((dn * d - n * dd) / (d * d) * e - self.T * L) * 1j
        return L, dL

    @staticmethod
    def _split(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The roots as single real roots, quadratic factors ``s^2 + p s + q`` (``q > 0``, ``p != 0``: a complex
        pair, or two real roots on the same side of the axis) and the frequencies ``b`` of pairs ``+-jb``."""
        rs = [complex(x) for x in r]  # a few roots: plain Python is faster than NumPy here
        key = lambda z: (z.real, z.imag)  # noqa: E731
        up = sorted((z for z in rs if z.imag > 0), key=key)
        down = sorted((z.conjugate() for z in rs if z.imag < 0), key=key)
        if up != down:  # not exact conjugates (rounding): average each root with its nearest mirror image
            up = [(u + min(down, key=lambda d: abs(d - u))) / 2 for u in up]
        p = [-2.0 * z.real for z in up if z.real != 0]
        q = [abs(z) ** 2 for z in up if z.real != 0]
        singles: list[float] = []
        for half in (sorted(z.real for z in rs if z.imag == 0 and z.real < 0),
                     sorted(z.real for z in rs if z.imag == 0 and z.real > 0)):
            for i in range(0, len(half) - 1, 2):
                p.append(-(half[i] + half[i + 1]))
                q.append(half[i] * half[i + 1])
            singles += half[len(half) // 2 * 2:]
        return (np.array(singles), np.array([p, q], float).reshape(2, -1),
                np.array([z.imag for z in up if z.real == 0]))

    def _angles(self, w: np.ndarray, parts: tuple[np.ndarray, np.ndarray, np.ndarray], side: float) -> np.ndarray:
        """Sum of the angles of ``jw - r`` over roots ``r``, continuous in ``w >= 0`` up to a constant multiple of
        2 pi (fixed by the offset in ``__init__``)."""
        real, quad, axis = parts
        out = np.zeros(w.shape)
        if real.size:  # atan2(w, -a): in [0, pi/2) left of the axis, (pi/2, pi] right of it
            out += np.arctan2(w[:, None], -real[None, :]).sum(axis=1)
        if quad.shape[1]:  # (q - w^2) + j p w: the imaginary part keeps the sign of p, so no branch cut is crossed
            out += np.arctan2(quad[0][None, :] * w[:, None], quad[1][None, :] - (w * w)[:, None]).sum(axis=1)
        if axis.size:  # (jw)^2 + b^2 is real: angle 0 below b, pi above, side pi/2 +- pi/2 at b
            d = w[:, None] - axis[None, :]
            out += (math.pi / 2 * (1.0 + np.where(d > 0, 1.0, np.where(d < 0, -1.0, side)))).sum(axis=1)
        return out

    def phase(self, w: np.ndarray, side: float = 0.0) -> np.ndarray:
        """Unwrapped phase (rad) at ``w >= 0``; at a root on the axis, its left (side=-1) or right (+1) limit."""
        w = np.asarray(w, float)
        with np.errstate(over="ignore", invalid="ignore"):  # w T beyond the floats (a delay of 1e308 s): -inf
            return (self.offset + (self.z0 - self.p0) * math.pi / 2 + self.k_term - w * self.T
                    + self._angles(w, self.zparts, side) - self._angles(w, self.pparts, side))

    def dphase(self, w: np.ndarray) -> np.ndarray:
        """d(phase)/dw (rad s); roots on the axis contribute only their jumps, which are left out."""
        w = np.asarray(w, float)
        out = np.full(w.shape, -self.T)
        for r, sign in ((self.zr, 1.0), (self.pr, -1.0)):
            r = r[r.real != 0]
            if r.size:
                a, b = r.real, r.imag
                out += sign * np.sum(-a / ((w[:, None] - b) ** 2 + a * a), axis=1)
        return out

    def phase_at_infinity(self) -> float:
        """The limit of the phase as ``w -> inf`` without the delay's ``- w T``."""
        def lim(parts: tuple[np.ndarray, np.ndarray, np.ndarray]) -> float:
            real, quad, axis = parts
            return math.pi / 2 * real.size + math.pi * float(np.sum(np.sign(quad[0]))) + math.pi * axis.size

        return (self.offset + (self.z0 - self.p0) * math.pi / 2 + self.k_term + lim(self.zparts)
                - lim(self.pparts))

    # -- polynomials in x = w^2 ------------------------------------------------------------------------
    @staticmethod
    def _sq(p: np.ndarray) -> np.ndarray:
        """``|p(jw)|^2`` as a polynomial in ``x = w^2``, highest power first."""
        n = p.size - 1
        pj = p * (1j) ** np.arange(n, -1, -1)
        return np.convolve(pj, np.conj(pj)).real[::2]

    def squares(self) -> tuple[np.ndarray, np.ndarray]:
        a, b = self._sq(self.num), self._sq(self.den)
        n = max(a.size, b.size)
        return np.pad(a, (n - a.size, 0)), np.pad(b, (n - b.size, 0))


def positive_real_roots(p: np.ndarray, scale: float) -> np.ndarray:
    """Real roots ``x > 0`` of the polynomial ``p`` (coefficients below 1e-14 ``scale`` at the top dropped)."""
    p = np.asarray(p, float)
    big = np.flatnonzero(np.abs(p) > 1e-14 * scale)
    if big.size == 0:
        return np.zeros(0)
    p = p[big[0]:]
    if p.size < 2:
        return np.zeros(0)
    r = np.roots(p)
    keep = (r.real > 0) & (np.abs(r.imag) <= 1e-6 * np.abs(r))
    return np.sort(r.real[keep])


def gain_crossovers(ol: OpenLoop, grid: np.ndarray | None = None, known: np.ndarray | None = None) -> np.ndarray:
    """Frequencies ``w > 0`` with ``|L(jw)| = 1``: roots of ``|N|^2 - |D|^2`` in ``w^2``, polished.

    With ``grid``, sign changes of ``log|L|`` between its points are candidates too (a net under the polynomial);
    with ``known`` (this function's earlier result), those are taken as found and only grid intervals that hold
    none of them are searched."""
    if ol.zero:
        return np.zeros(0)
    if known is None:
        a, b = ol.squares()
        scale = max(np.abs(a).max(), np.abs(b).max())
        if not np.isfinite(scale):
            big = max(float(np.abs(ol.cn).max()), float(np.abs(ol.cd).max()))
            raise InvalidValueError(f"the margins cannot be computed: a coefficient of the open loop L(s) "
                                    f"({big:.3g}) is too large for |L(jw)|^2 in double precision; scale the gains "
                                    "and the plant to sizes below 1e150")
        if np.abs(a - b).max() <= 1e-13 * scale:
            raise InvalidValueError("the margins are undefined: |L(jw)| = 1 at every frequency (an all-pass loop "
                                    "with unit gain), so every frequency is a gain crossover")
        # a coefficient of |N|^2 - |D|^2 is dropped only where it is the rounding of a cancellation, not for being
        # small beside the others (-w^2 + kp^2, kp = 1e8, has its crossover at kp)
        p = a - b
        p[np.abs(p) <= 1e-13 * np.maximum(np.abs(a), np.abs(b))] = 0.0
        cands = list(np.sqrt(positive_real_roots(p, 0.0)))
    else:
        cands = []
    if grid is not None and grid.size > 1:  # a net under the polynomial: sign changes of log|L| on the grid
        with np.errstate(all="ignore"):
            g = np.log(np.abs(ol.value(grid)))
        k = np.flatnonzero(np.isfinite(g[:-1]) & np.isfinite(g[1:]) & (np.sign(g[:-1]) * np.sign(g[1:]) < 0))
        if known is not None and known.size:
            k = k[~np.any((known[None, :] >= grid[k, None]) & (known[None, :] <= grid[k + 1, None]), axis=1)]
        cands += [0.5 * (grid[i] + grid[i + 1]) for i in k]
    if known is not None and not cands:
        return known
    found: list[float] = [] if known is None else [float(x) for x in known]
    for w in map(float, cands):
        for _ in range(60):
            s = 1j * w
            n, d = horner(ol.cn, s), horner(ol.cd, s)
            if n == 0 or d == 0:
                break
            g = math.log(abs(n)) - math.log(abs(d))
            gp = -(horner(ol.cdn, s) / n).imag + (horner(ol.cdd, s) / d).imag
            if gp == 0 or not math.isfinite(gp):
                break
            step = g / gp
            w_new = w - step
            w = w_new if w_new > 0 else 0.5 * w
            if abs(step) <= 1e-15 * w:
                break
        n, d = horner(ol.cn, 1j * w), horner(ol.cd, 1j * w)
        if w > 0 and d != 0 and abs(math.log(abs(n) / abs(d))) < 1e-9 and \
                not any(abs(w - f) <= 1e-9 * w for f in found):
            found.append(float(w))
    return np.array(sorted(found))


def newton_bracketed(fdf: Any, a: np.ndarray, b: np.ndarray, x0: np.ndarray, f: Any) -> np.ndarray:
    """Roots in the brackets ``[a, b]`` by Newton's method from ``x0`` (``fdf(x)`` gives ``f`` and ``f'`` at every
    point), to rounding; where a step leaves its bracket or Newton has not converged in 8 steps,
    :func:`solve_bracketed` (with ``f``, on those brackets only) takes over.  Quadratic from a good first guess:
    two or three steps."""
    a, b = a.astype(float), b.astype(float)
    x = np.minimum(np.maximum(x0.astype(float), a), b)
    done = np.zeros(x.size, bool)
    close = np.zeros(x.size, bool)  # the last step was below 1e-8 relative: one more reaches rounding
    bad = np.zeros(x.size, bool)
    with np.errstate(all="ignore"):
        for _ in range(8):
            live = ~(done | bad)
            if not live.any():
                break
            fx, dx = fdf(x)
            xn = x - fx / dx
            step = np.abs(xn - x)
            out = live & ~(np.isfinite(xn) & (xn >= a) & (xn <= b))
            bad |= out
            go = live & ~out
            done |= go & (close | (fx == 0) | (step <= 4e-16 * np.abs(xn)))
            close = go & (step <= 1e-8 * np.abs(xn))
            x = np.where(go, xn, x)
    rest = ~done
    if rest.any():
        idx = np.flatnonzero(rest)
        x[idx] = solve_bracketed(lambda y: f(y, idx), a[idx], b[idx])
    return x


def solve_bracketed(f: Any, a: np.ndarray, b: np.ndarray, rtol: float = 4e-16, x0: np.ndarray | None = None
                    ) -> np.ndarray:
    """Roots of the vectorised ``f`` bracketed by ``[a, b]`` (a sign change, or a zero at an end), to rounding.

    The Illinois form of false position (the end that stays is given half its weight), with a bisection step
    whenever an end has stayed four times in a row and every step at least ``rtol / 2.5`` from the ends (so a
    root at an end is closed in on at once): superlinear on smooth functions, and never much slower than
    bisection.  Each bracket is kept, so the result is where ``f`` changes sign, to ``rtol`` relative (by default
    to rounding).  ``x0``, inside the brackets, replaces the first false-position point (a better first guess).
    """
    a, b = a.astype(float).copy(), b.astype(float).copy()
    if a.size == 0:
        return a
    with np.errstate(all="ignore"):
        fa, fb = f(a).astype(float), f(b).astype(float)
        wa, wb = np.ones(a.size), np.ones(a.size)  # Illinois weights of the two ends
        stay = np.zeros(a.size, int)  # > 0: the left end stayed that many steps, < 0: the right end
        for _ in range(200):
            scale = np.maximum(np.abs(a), np.abs(b))
            live = ((b - a) > rtol * scale) & (fa != 0) & (fb != 0)
            if not live.any():
                break
            ga, gb = wa * fa, wb * fb
            m = (a * gb - b * ga) / (gb - ga) if x0 is None else x0.astype(float)
            x0 = None
            mid = 0.5 * (a + b)
            bis = ~np.isfinite(m) | (np.abs(stay) >= 4)
            m[bis] = mid[bis]
            tol = 0.4 * rtol * scale  # a step at least this far in from each end
            m = np.minimum(np.maximum(m, a + tol), b - tol)
            out = (m <= a) | (m >= b)
            m[out] = mid[out]
            fm = f(m).astype(float)
            left = live & (np.sign(fm) == np.sign(fa)) & (fm != 0)  # the root is right of m: a moves
            right = live & ~left  # (a zero at m closes the bracket there)
            zero = right & (fm == 0)
            a[left], fa[left] = m[left], fm[left]
            b[right], fb[right] = m[right], fm[right]
            a[zero], fa[zero] = m[zero], 0.0
            stay[left] = np.minimum(stay[left], 0) - 1
            stay[right] = np.maximum(stay[right], 0) + 1
            wa = np.where(stay >= 2, 0.5 * wa, np.where(stay < 0, 1.0, wa))  # halve a stale end's weight
            wb = np.where(stay <= -2, 0.5 * wb, np.where(stay > 0, 1.0, wb))
    return np.where(fa == 0, a, np.where(fb == 0, b, 0.5 * (a + b)))


def refine_minimum(fun: Any, grid: np.ndarray, values: np.ndarray, keep: int = 12) -> tuple[float, float]:
    """The smallest of ``values`` (``fun`` on ``grid``), with each of the ``keep`` lowest local minima refined by a
    bounded scalar search between its neighbours: ``(value, where)``."""
    from scipy.optimize import minimize_scalar

    i = int(np.argmin(values))
    best, where = float(values[i]), float(grid[i])
    if grid.size < 3:
        return best, where
    k = 1 + np.flatnonzero((values[1:-1] <= values[:-2]) & (values[1:-1] <= values[2:]))
    for j in k[np.argsort(values[k])][:keep]:
        res = minimize_scalar(lambda x: float(fun(np.array([x]))[0]), bounds=(grid[j - 1], grid[j + 1]),
                              method="bounded", options={"xatol": 1e-13 * grid[j]})
        if res.fun < best:
            best, where = float(res.fun), float(res.x)
    return best, where


@dataclass(frozen=True)
class PhaseScan:
    """What :func:`scan_phase` found: the phase crossovers as ``(w, |L|, phase in rad, direction)`` (those with
    a finite ``|L|``), the counterclockwise encirclements of -1 (``None`` when there is no finite count) and the
    points it used (the grid with the phase's extrema added)."""

    crossings: list
    ccw: int | None
    grid: np.ndarray


def scan_phase(ol: OpenLoop, grid: np.ndarray, w_hi: float) -> PhaseScan:
    """Phase crossovers on ``[0, w_hi]`` and the Nyquist encirclement count.

    See :func:`delaykit.spectrum.frequency.margins` for the counting rules.  In half-turns ``u = phase / pi``,
    the crossovers are the odd integers crossed between consecutive points (the phase is monotone between
    them).  An odd integer exactly at a point belongs to the interval where it is the upper end (rule A: the
    negative real axis turned by a vanishing angle one way) for the curve ``w >= 0``, and to the interval where
    it is the lower end (rule B, the other way, which is the mirror curve ``w <= 0`` seen from this side).
    """
    axis = {}  # frequency of a root on the positive imaginary axis -> net pole multiplicity
    for r, sign in ((ol.pr, 1), (ol.zr, -1)):
        for b in r.imag[(r.real == 0) & (r.imag > 0)]:
            key = next((k for k in axis if abs(k - b) <= 1e-9 * b), float(b))
            axis[key] = axis.get(key, 0) + sign
    breaks = sorted(b for b in axis if b < w_hi)
    edges = [0.0, *breaks, w_hi]
    crossings: list[tuple[float, float, float, int]] = []
    ccw = 0
    pts_all = []
    for j in range(len(edges) - 1):
        lo, hi = edges[j], edges[j + 1]
        inner = grid[(grid > lo) & (grid < hi)]
        pts = np.concatenate([[lo], inner, [hi]])
        # extrema of the phase, so that it is monotone between the points
        d = ol.dphase(pts)
        k = np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0)
        if k.size:
            inner = np.sort(np.concatenate([inner, solve_bracketed(ol.dphase, pts[k], pts[k + 1])]))
            pts = np.concatenate([[lo], inner, [hi]])
        phi = np.concatenate([ol.phase(pts[:1], side=1.0), ol.phase(inner), ol.phase(pts[-1:], side=-1.0)])
        pts_all.append(pts)
        u = snap_half_turns(phi / math.pi)
        ua, ub = u[:-1], u[1:]
        lo_u, hi_u = np.minimum(ua, ub), np.maximum(ua, ub)
        # odd integers m in [lo_u, hi_u]: rule A counts (lo, hi], rule B counts [lo, hi)
        m0 = 2 * np.floor((lo_u - 1) / 2) + 1  # the largest odd integer <= lo_u, then the smallest >= lo_u
        m0 = np.where(m0 < lo_u, m0 + 2, m0)
        with np.errstate(invalid="ignore"):  # (counted as floats: a phase of 1e300 half-turns has no int)
            count_f = np.where((hi_u >= m0) & (ua != ub), np.floor((hi_u - m0) / 2) + 1, 0.0)
        if not count_f.sum() <= 4 * _MAX_PHASE_CROSSOVERS:
            raise InvalidValueError(f"too many phase crossovers below {w_hi:g} rad/s to list")
        count = count_f.astype(int)
        iv = np.repeat(np.arange(ua.size), count)
        m = m0[iv] + 2 * (np.arange(iv.size) - np.repeat(np.cumsum(count) - count, count))
        wa, wb, fa, fb = pts[iv], pts[iv + 1], ua[iv], ub[iv]
        at_a, at_b = m == fa, m == fb
        interior = ~(at_a | at_b)
        wx = np.where(at_a, wa, wb)
        if interior.any():
            lev = m[interior] * math.pi
            ga, gb = fa[interior] * math.pi - lev, fb[interior] * math.pi - lev
            w0 = wa[interior] - ga * (wb[interior] - wa[interior]) / (gb - ga)  # the phase taken as linear
            wx[interior] = newton_bracketed(lambda x, lev=lev: (ol.phase(x) - lev, ol.dphase(x)), wa[interior],
                                            wb[interior], w0, lambda x, i, lev=lev: ol.phase(x) - lev[i])
        direction = np.sign(fb - fa).astype(int)
        rule_a = (m > np.minimum(fa, fb)) & (m <= np.maximum(fa, fb))
        rule_b = (m >= np.minimum(fa, fb)) & (m < np.maximum(fa, fb))
        mag = np.abs(ol.value(wx))
        poles = [b for b in breaks if axis[b] > 0]
        zeros = [b for b in breaks if axis[b] <= 0]
        mag = np.where(((wx == 0) & (ol.integrators > 0)) | np.isin(wx, poles), np.inf, mag)
        mag = np.where(np.isin(wx, zeros), np.nan, mag)
        big = mag > 1
        ccw += int(np.sum(direction * (rule_a.astype(int) + rule_b.astype(int)) * big))
        crossings += [(float(x), float(g), float(p * math.pi), int(s))
                      for x, g, p, s in zip(wx, mag, m, direction) if math.isfinite(g)]
    # the arc at infinity around the poles on the positive imaginary axis (and its mirror): clockwise
    for b in breaks:
        if axis[b] > 0:
            up = snap_half_turns(ol.phase(np.array([b]), side=-1.0) / math.pi)[0]
            dn = snap_half_turns(ol.phase(np.array([b]), side=1.0) / math.pi)[0]
            ccw -= _odd_between(dn, up, True) + _odd_between(dn, up, False)
    # the arc around the integrators at s = 0, from phase phi0 + n pi clockwise to phi0
    if ol.integrators > 0:
        u0 = snap_half_turns(ol.phase(np.zeros(1)) / math.pi)[0]
        ccw -= _odd_between(u0, u0 + ol.integrators, True)
    if ol.T == 0 and not ol.zero:
        # the curve closes through the point L(j inf): a crossing may sit there (a biproper loop, L(j inf) < -1)
        uh = snap_half_turns(ol.phase(np.array([w_hi])) / math.pi)[0]
        ui = snap_half_turns(np.array([ol.phase_at_infinity() / math.pi]))[0]
        if ui == round(ui) and int(round(ui)) % 2 and uh != ui and ol.l_inf > 1:
            ccw += 1 if ui > uh else -1  # rule A counts it when the phase rises to it, rule B when it falls
    elif ol.l_inf >= 1:
        ccw = None  # the curve keeps circling at |L| >= 1: no finite count (a neutral loop that is not stable)
    crossings.sort()
    merged: list[tuple[float, float, float, int]] = []
    for c in crossings:
        if merged and abs(c[0] - merged[-1][0]) <= 1e-12 * max(c[0], 1e-300):
            continue
        merged.append(c)
    return PhaseScan(merged, ccw, np.unique(np.concatenate(pts_all)))


def snap_half_turns(u: np.ndarray) -> np.ndarray:
    """Phases in half-turns, with values within rounding of an odd integer set to it."""
    u = np.asarray(u, float)
    with np.errstate(over="ignore", invalid="ignore"):  # an infinite phase stays as it is
        near = 2 * np.round((u - 1) / 2) + 1
        return np.where(np.abs(u - near) <= _LEVEL_TOL * (1 + np.abs(u)), near, u)


def _odd_between(lo: float, hi: float, upper: bool) -> int:
    """How many odd integers lie in ``(lo, hi]`` (``upper``) or ``[lo, hi)``."""
    if hi <= lo:
        return 0
    first = math.floor((lo - 1) / 2) * 2 + 1
    n = 0
    m = first
    while m <= hi:
        if (lo < m <= hi) if upper else (lo <= m < hi):
            n += 1
        m += 2
    return n


def cutoff_frequency(ol: OpenLoop, gains: np.ndarray) -> tuple[float, float]:
    """The cut-off frequency for the listed phase crossovers, and the last stationary point of ``|L(jw)|``."""
    roots = np.abs(np.concatenate([ol.zr, ol.pr]))
    r_max = float(roots.max()) if roots.size else 0.0
    g_max = float(gains.max()) if gains.size else 0.0
    w_hi = max(1.0, 100 * r_max, 2 * g_max)
    w_m = 0.0
    if ol.T > 0 and not ol.zero:
        w_hi = max(w_hi, 8 * math.pi / ol.T)
        a, b = ol.squares()
        scale = max(np.abs(a).max(), np.abs(b).max())
        if ol.l_inf < 1e-3:
            x3 = positive_real_roots(a - 1e-6 * b, scale)
            if x3.size:
                w_hi = max(w_hi, 1.01 * math.sqrt(x3[-1]))
        c = np.polysub(np.convolve(np.polyder(a), b), np.convolve(a, np.polyder(b))) if a.size > 1 else np.zeros(1)
        xs = positive_real_roots(c, max(1e-300, np.abs(c).max()))
        if xs.size:
            w_m = math.sqrt(xs[-1])
        need = max(1.5 * w_m, 100 * r_max, 2 * g_max)
        w_hi = max(need, min(w_hi, _MAX_PHASE_CROSSOVERS * TWO_PI / ol.T))
    return float(w_hi), float(w_m)


def dense_grid(ol: OpenLoop, gains: np.ndarray, w_hi: float) -> np.ndarray:
    """The dense grid on ``(0, w_hi]``: logarithmic, plus points over each complex root and the crossovers."""
    r = np.concatenate([ol.zr, ol.pr])
    feats = [x for x in np.abs(r) if x > 0] + list(gains) + ([1.0 / ol.T] if ol.T > 0 else [])
    if not math.isfinite(w_hi):  # 2 pi / T beyond the floats: a delay of 1e-320 s
        raise InvalidValueError(f"the delay {ol.T:g} s is too small to scan the phase up to its crossovers (2 pi / "
                                "delay is beyond the floats): give a delay of 0, or one within the floats' range")
    w_lo = min(min(feats) if feats else 1.0, w_hi) * 1e-3
    n = max(int(_PER_DECADE * (math.log10(w_hi) - math.log10(w_lo))), 2) + 1  # (the ratio may overflow: 1/T tiny)
    parts = [np.geomspace(w_lo, w_hi, n)]
    c = r[(r.imag > 0) & (r.real != 0)]
    if c.size:  # 41 points over each complex root, equally spaced in the angle of jw - r
        t = np.tan(np.linspace(-math.pi / 2, math.pi / 2, 43)[1:-1])
        parts.append((c.imag[:, None] + np.abs(c.real)[:, None] * t[None, :]).ravel())
    if gains.size:
        rel = np.array([-0.1, -0.03, -0.01, -1e-3, 0.0, 1e-3, 0.01, 0.03, 0.1])
        parts.append((gains[:, None] * (1 + rel[None, :])).ravel())
    g = np.concatenate(parts)
    return np.unique(g[(g > 0) & (g <= w_hi)])
