"""Frequency response, margins and jitter margin of a loop whose controller compensates the delay.

A compensator (:mod:`delaykit.models.compensators`: a Smith predictor, the filtered Smith predictor, predictor
feedback) reads its own command as well as the measurement: its law is ``u = Gy ym + Gu u + Gm u(t - Tm)``
with a model delay ``Tm``.  Closed around its own command it is one controller on the measurement,
``C_eq = -Gy / (1 - Gu - Gm exp(-s Tm))`` (for the Smith predictor the textbook
``C / (1 + C Gn (1 - exp(-s Tm)))``), so the loop broken at the plant input, *after* the branch where the
compensator reads the command, is

    ``L(s) = A2(s) exp(-s T) / (A0(s) + A1(s) exp(-s Tm))``

with ``A0 + A1 exp(-s Tm) + A2 exp(-s T)`` the loop's characteristic function
(:meth:`~delaykit.models.loop.Loop.compensated_polynomials`, the structural roots at 0 divided out) and ``T`` the
plant's true delay.  That is where the uncertainty of a real loop sits: a factor ``k`` on ``L`` is a plant
gain ``k`` times the model's, an extra delay ``dT`` on ``L`` is the true delay ``T + dT`` against the model's
``Tm``, and a varying delay on the way to the plant is the jitter the margin bounds.  So the gain margin is the
plant-to-model gain ratio that reaches instability, the delay margin the delay error (``Td - Tm``, with
``Td = Tm``: ``(critical_delay / Tm)`` is the upper end of the design's stable delay-ratio range), and the
jitter margin the variation the design survives.

``L`` is not a rational function times one delay, so its phase is not a sum of root angles as in
:mod:`delaykit.spectrum.frequency`.  Everything here is the exact ``L(jw)`` evaluated on a grid that is refined
until neighbouring points differ by less than 20 degrees in the angle of ``L`` and of ``1 + L`` and by less than
a factor 1.25 in ``|L|`` (logarithmic from 1/1000 of the loop's slowest feature, plus 16 points per turn of the
longer delay); crossovers are bracketed on it and solved to rounding; the phase is unwrapped along it, starting
at ``w -> 0+`` from ``-90`` degrees per integrator of ``L``.  Phase crossovers are listed up to the ``cutoff``
above which ``|L| < 0.01`` everywhere (a bound from the polynomials, so a gain factor above 100 is not listed).

Stability comes from the characteristic roots (certified argument-principle count, or the rightmost root), as
for other loops.  The Nyquist count uses ``P``, the zeros of ``A0 + A1 exp(-s Tm)`` with ``Re s > 0`` (poles of
``L``, found by the certified root finder), and the signed crossings of the negative real axis left of -1,
with the integrators' arcs as in :func:`~delaykit.spectrum.frequency.margins`; ``P - encirclements`` must be the
closed loop's count of right-half-plane roots, which the tests check against the root finder.

Not covered here: a sampled compensated loop, whose margins (the loop broken at the same place, the plant's
input, with the same meaning) come from its exact discrete-time model in
:func:`delaykit.spectrum.sampled.sampled_margins`; and compensators whose ``L`` is not strictly proper in its
delay-free part (none of delaykit's designs).

Examples
--------
>>> from delaykit.models import Loop
>>> from delaykit.models.compensators import Compensator
>>> c = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)
>>> m = compensated_margins(Loop("1/s", c, delay=0.37))
>>> m
Margins(GM 2.578 (8.224 dB) at 6.101 rad/s, PM 64.19 deg at 1.798 rad/s, DM 0.623 s, Ms 1.659, stable)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import InvalidValueError
from ..models.budget import MAX_RESPONSE_POINTS, check_count
from ..models.compensators import Compensator
from ..models.loop import Loop
from ..models.quasipolynomial import QuasiPolynomial
from ._openloop import TWO_PI, OpenLoop, positive_real_roots, refine_minimum, snap_half_turns, solve_bracketed
from .frequency import Crossover, FrequencyResponse, Margins, _assemble, _closed_loop_stable

__all__ = ["CompensatedOpenLoop", "compensated_response", "compensated_margins", "compensated_jitter",
           "compensated_grid"]

_MAX_ANGLE = math.radians(20.0)  # refinement: largest angle step of L and of 1 + L between grid points
_MAX_LOG_STEP = math.log(1.25)  # and largest ratio of |L|
_PER_DECADE = 100
_PER_TURN = 16
_CUT_LEVEL = 0.01  # phase crossovers are listed while |L| may exceed this
_MAX_POINTS = 2_000_000


def _taylor_at_zero(a0: np.ndarray, a1: np.ndarray, tm: float, n: int) -> np.ndarray:
    """The first ``n`` Taylor coefficients at ``s = 0`` of ``a0(s) + a1(s) exp(-s tm)`` (lowest power first)."""
    c0 = np.zeros(n)
    low0, low1 = a0[::-1], a1[::-1]
    c0[:min(n, low0.size)] += low0[:n]
    e = np.array([(-tm) ** k / math.factorial(k) for k in range(n)])
    c1 = np.convolve(low1, e)[:n]
    c0[:c1.size] += c1
    return c0


def _zero_order(coef: np.ndarray, scale: float) -> int:
    """How many leading (lowest-power) coefficients are zero to rounding."""
    k = 0
    while k < coef.size and abs(coef[k]) <= 1e-10 * scale:
        k += 1
    return k


class CompensatedOpenLoop:
    """``L(jw) = A2 exp(-jw T) / (A0 + A1 exp(-jw Tm))`` of a compensated loop (see the module docstring).

    Examples
    --------
    >>> from delaykit.models import Loop
    >>> c = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)
    >>> ol = CompensatedOpenLoop(Loop("1/s", c, delay=0.37))
    >>> s = 5j                                     # perfect model: L = 5 e^{-sT} / (s + 5 - 5 e^{-sT})
    >>> ol.integrators, bool(abs(ol.value(np.array([5.0]))[0] - 5 * np.exp(-s * 0.37) / (s + 5 - 5 * np.exp(-s * 0.37))) < 1e-15)
    (1, True)
    """

    def __init__(self, loop: Loop) -> None:
        if not isinstance(loop.controller, Compensator):
            raise InvalidValueError("CompensatedOpenLoop takes a loop whose controller is a Compensator")
        a0, a1, a2 = (np.trim_zeros(np.asarray(p, float), "f") for p in loop.compensated_polynomials())
        self.a0 = a0 if a0.size else np.zeros(1)
        self.a1 = a1 if a1.size else np.zeros(1)
        self.a2 = a2 if a2.size else np.zeros(1)
        self.T = float(loop.total_delay)
        self.Tm = float(loop.controller.model_delay)
        self.zero = not self.a2.any()
        deg0 = self.a0.size - 1
        if not self.a0.any() or self.a1.size - 1 >= deg0 and self.a1.any() and self.Tm > 0:
            raise InvalidValueError(
                "the compensated loop's denominator A0 + A1 exp(-s Tm) is neutral or constant (the compensator "
                "feeds its own delayed command through at high frequency): its frequency response is not analysed")
        if not self.zero and self.a2.size - 1 >= deg0:
            raise InvalidValueError("the compensated loop's L is not strictly proper in its delay-free part; its "
                                    "margins are not analysed")
        self.d0, self.d1, self.d2 = (np.polyder(p) if p.size > 1 else np.zeros(1) for p in (self.a0, self.a1, self.a2))
        scale = float(max(np.abs(self.a0).max(), np.abs(self.a1).max()))
        n = self.a0.size + self.a1.size + 2
        den_order = _zero_order(_taylor_at_zero(self.a0, self.a1, self.Tm, n), scale)
        num_order = _zero_order(self.a2[::-1], float(np.abs(self.a2).max()) or 1.0) if not self.zero else 0
        self.integrators = den_order - num_order
        if self.zero:
            self.k_sign = 1.0
        else:
            dt = _taylor_at_zero(self.a0, self.a1, self.Tm, den_order + 1)[den_order]
            self.k_sign = 1.0 if self.a2[::-1][num_order] / dt > 0 else -1.0
        # the phase as w -> 0+: -90 degrees per integrator, and -180 more for a negative low-frequency gain
        self.phase0 = -self.integrators * math.pi / 2 + (0.0 if self.k_sign > 0 else -math.pi)
        roots = [r for p in (self.a0, self.a1, self.a2) if p.size > 1 for r in np.roots(p)]
        self.features = sorted({abs(complex(r)) for r in roots if abs(complex(r)) > 1e-9}
                               | ({1.0 / self.T} if self.T > 0 else set())
                               | ({1.0 / self.Tm} if self.Tm > 0 else set()))
        self.complex_roots = np.array([r for r in roots if complex(r).imag > 0 and complex(r).real != 0], complex)

    # -- values -------------------------------------------------------------------------------------------
    def value(self, w: np.ndarray) -> np.ndarray:
        """``L(jw)``; ``inf`` at a pole on the imaginary axis (``w = 0`` with an integrator)."""
        w = np.asarray(w, float)
        s = 1j * w
        with np.errstate(all="ignore"):
            den = np.polyval(self.a0, s) + np.polyval(self.a1, s) * np.exp(-s * self.Tm)
            L = np.polyval(self.a2, s) * np.exp(-s * self.T) / den
        if self.integrators > 0:
            L = np.where(w == 0, complex(np.inf), L)
        elif self.integrators < 0:
            L = np.where(w == 0, 0j, L)
        return L

    def slope(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``L(jw)`` and ``dL/dw = j dL/ds``."""
        w = np.asarray(w, float)
        s = 1j * w
        with np.errstate(all="ignore"):
            em, et = np.exp(-s * self.Tm), np.exp(-s * self.T)
            den = np.polyval(self.a0, s) + np.polyval(self.a1, s) * em
            dden = np.polyval(self.d0, s) + (np.polyval(self.d1, s) - self.Tm * np.polyval(self.a1, s)) * em
            num = np.polyval(self.a2, s) * et
            dnum = (np.polyval(self.d2, s) - self.T * np.polyval(self.a2, s)) * et
            L = num / den
            dL = (dnum * den - num * dden) / (den * den)
        return L, 1j * dL

    def denominator(self) -> QuasiPolynomial:
        """``A0 + A1 exp(-s Tm)``, whose zeros are the poles of ``L``."""
        return QuasiPolynomial([self.a0, self.a1], [0.0, self.Tm])

    # -- where to look ------------------------------------------------------------------------------------
    def cutoff(self) -> float:
        """A frequency above which ``|L(jw)| < 0.01`` (from ``|A2| + 0.01 |A1| < 0.01 |A0|``, squared)."""
        feats = self.features or [1.0]
        base = 10.0 * max(feats)
        if self.zero:
            return base
        sq = OpenLoop._sq
        a, b, c = sq(self.a0), sq(self.a1), sq(self.a2)
        n = max(a.size, b.size, c.size)
        pad = lambda p: np.pad(p, (n - p.size, 0))  # noqa: E731
        # (|A2| + e |A1|)^2 <= 2 |A2|^2 + 2 e^2 |A1|^2 < e^2 |A0|^2 with e = 0.01 (A0's degree is the highest)
        e = _CUT_LEVEL
        p = e * e * pad(a) - 2.0 * pad(c) - 2.0 * e * e * pad(b)
        x = positive_real_roots(p, float(np.abs(p).max()))
        return float(max(base, 1.01 * math.sqrt(x[-1]) if x.size else 0.0))

    def grid(self, w_lo: float, w_hi: float, extra: np.ndarray | None = None) -> np.ndarray:
        """The refined grid on ``[w_lo, w_hi]`` (see the module docstring)."""
        n = max(int(_PER_DECADE * math.log10(w_hi / w_lo)), 2) + 1
        parts = [np.geomspace(w_lo, w_hi, n)]
        tmax = max(self.T, self.Tm)
        if tmax > 0:
            k = int(w_hi * tmax * _PER_TURN / TWO_PI) + 2
            if k > _MAX_POINTS:
                raise InvalidValueError(f"the frequency range up to {w_hi:g} rad/s holds too many turns of the "
                                        f"{tmax:g} s delay's phase to scan")
            parts.append(np.linspace(w_hi / k, w_hi, k))
        c = self.complex_roots
        if c.size:
            t = np.tan(np.linspace(-math.pi / 2, math.pi / 2, 43)[1:-1])
            parts.append((c.imag[:, None] + np.abs(c.real)[:, None] * t[None, :]).ravel())
        if extra is not None:
            parts.append(np.asarray(extra, float))
        g = np.unique(np.concatenate(parts))
        g = g[(g >= w_lo) & (g <= w_hi)]
        L = self.value(g)
        for _ in range(40):
            with np.errstate(all="ignore"):
                da = np.abs(np.angle(L[1:] / L[:-1]))
                db = np.abs(np.angle((1.0 + L[1:]) / (1.0 + L[:-1])))
                dm = np.abs(np.log(np.abs(L[1:]) / np.abs(L[:-1])))
            bad = ~((da <= _MAX_ANGLE) & (db <= _MAX_ANGLE) & (dm <= _MAX_LOG_STEP))
            bad &= (g[1:] - g[:-1]) > 1e-12 * g[1:]
            if not bad.any():
                break
            k = np.flatnonzero(bad)
            mid = 0.5 * (g[k] + g[k + 1])
            if g.size + mid.size > _MAX_POINTS:
                raise InvalidValueError("the compensated loop's frequency response needs too many points to resolve")
            g = np.insert(g, k + 1, mid)
            L = np.insert(L, k + 1, self.value(mid))
        return g

    def default_range(self) -> tuple[float, float]:
        """``(w_lo, cutoff)``: from 1/1000 of the slowest feature to the cut-off."""
        feats = self.features or [1.0]
        hi = self.cutoff()
        return min(feats) * 1e-3, hi

    def unwrapped(self, g: np.ndarray) -> np.ndarray:
        """The phase (rad) on a refined grid ``g`` that starts low enough, unwrapped from ``phase0``."""
        L = self.value(g)
        ang = np.unwrap(np.angle(L))
        return ang + TWO_PI * np.round((self.phase0 - ang[0]) / TWO_PI)


# ------------------------------------------------------------------------------------------------- API
def _loop(loop: Any) -> Loop:
    from ..models.altitude import as_loop

    loop = as_loop(loop)
    if not isinstance(loop.controller, Compensator):
        raise InvalidValueError(f"this function is for loops with a compensator; the loop has a "
                                f"{loop.controller.kind} controller (use delaykit.spectrum.frequency)")
    if loop.sampled:
        raise InvalidValueError(
            f"the loop is sampled (period {loop.period:g} s) and its controller is a {loop.controller.kind} "
            "compensator: this module analyses the continuous loop (period=None); the sampled loop's frequency "
            "response and margins come from delaykit.spectrum.sampled (sampled_frequency_response, "
            "sampled_margins)")
    return loop


def compensated_grid(loop: Loop, n: int = 500, *, wmin: float | None = None, wmax: float | None = None
                     ) -> np.ndarray:
    """A logarithmic grid over a compensated loop's features and gain crossovers (as
    :func:`~delaykit.spectrum.frequency.frequency_grid`).

    Examples
    --------
    >>> from delaykit.models import Loop
    >>> c = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)
    >>> w = compensated_grid(Loop("1/s", c, delay=0.37), 3)
    >>> w.size, bool(w[0] < 5.0 < w[-1])
    (3, True)
    """
    ol = CompensatedOpenLoop(_loop(loop))
    lo, hi = ol.default_range()
    gains = _gain_crossovers(ol, ol.grid(lo, hi))
    feats = list(ol.features) + list(gains)
    a, b = (min(feats) / 100, max(feats) * 10) if feats else (0.01, 100.0)
    a = a if wmin is None else float(wmin)
    b = b if wmax is None else float(wmax)
    if not b > a:
        raise InvalidValueError(f"the frequency range is empty or reversed: wmin = {a:g} rad/s must be below "
                                f"wmax = {b:g} rad/s")
    check_count("n (number of frequencies)", int(n), MAX_RESPONSE_POINTS, "frequencies")
    return np.geomspace(a, b, int(n))


def compensated_response(loop: Loop, w: np.ndarray) -> FrequencyResponse:
    """``L(jw)`` of a compensated loop at ``w`` (checked finite, >= 0), with the unwrapped phase.

    The phase at each ``w`` is the angle of the exact ``L(jw)`` taken in the turn that the unwrapped phase along
    the refined grid gives (see the module docstring).

    Examples
    --------
    >>> from delaykit.models import Loop
    >>> c = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)
    >>> r = compensated_response(Loop("1/s", c, delay=0.37), np.array([5.0]))
    >>> bool(round(float(r.magnitude[0]), 9) == round(abs(5 / (5j + 5 - 5 * np.exp(-5j * 0.37))), 9))   # perfect model
    True
    >>> round(float(r.phase_deg[0]), 4)     # -90 degrees at w -> 0, then continuous
    -162.9577
    """
    ol = CompensatedOpenLoop(_loop(loop))
    w = np.asarray(w, float)
    L = ol.value(w)
    pos = w[w > 0]
    if pos.size:
        lo = min(ol.default_range()[0], float(pos.min()))
        g = ol.grid(lo, float(pos.max()) * (1 + 1e-12), extra=pos)
        phi_g = ol.unwrapped(g)
        ref = np.interp(w, g, phi_g)
    else:
        ref = np.full(w.shape, ol.phase0)
    with np.errstate(all="ignore"):
        ang = np.angle(L)
        phase = np.where(np.isfinite(L) & (L != 0), ang + TWO_PI * np.round((ref - ang) / TWO_PI), ref)
        phase = np.where(w == 0, ol.phase0, phase)
        mag_db = 20.0 * np.log10(np.abs(L))
    return FrequencyResponse(w=w, L=L, magnitude_db=mag_db, phase_deg=np.degrees(phase))


def _gain_crossovers(ol: CompensatedOpenLoop, g: np.ndarray) -> np.ndarray:
    """``|L(jw)| = 1`` between the grid's points, solved to rounding."""
    if ol.zero:
        return np.zeros(0)
    with np.errstate(all="ignore"):
        f = np.log(np.abs(ol.value(g)))
    k = np.flatnonzero(np.isfinite(f[:-1]) & np.isfinite(f[1:]) & (np.sign(f[:-1]) * np.sign(f[1:]) <= 0)
                       & ~((f[:-1] == 0) & (f[1:] == 0)))
    if not k.size:
        return np.zeros(0)
    x = solve_bracketed(lambda w: np.log(np.abs(ol.value(w))), g[k], g[k + 1])
    out: list[float] = []
    for v in np.sort(x):
        if not out or v > out[-1] * (1 + 1e-10):
            out.append(float(v))
    return np.array(out)


def _open_loop_rhp_poles(ol: CompensatedOpenLoop) -> int | None:
    """Zeros of ``A0 + A1 exp(-s Tm)`` with ``Re s > 0`` (certified), or None if they could not be counted."""
    from .roots import find_roots, root_bound

    q = ol.denominator()
    eps = 1e-7 * (min(ol.features) if ol.features else 1.0)  # the integrators' zeros at s = 0 stay outside
    try:
        R = root_bound(q, eps) * (1 + 1e-9) + 1e-9
        sp = find_roots(q, (eps, R, -R, R))
    except (InvalidValueError, MemoryError):
        return None
    if not sp.certified:
        return None
    return int(np.sum(sp.multiplicities))


def compensated_margins(loop: Loop) -> Margins:
    """Gain, phase, delay margins, peak sensitivity, crossovers and the Nyquist count of a compensated loop.

    The definitions are those of :func:`~delaykit.spectrum.frequency.margins`, applied to ``L`` of the module
    docstring: the gain margin is the plant gain (against the model's) and the delay margin the extra true delay
    (against the model's) that reach instability; ``critical_delay`` is the true delay at which the loop with
    the design's model loses stability.

    Examples
    --------
    >>> from delaykit.models import Loop
    >>> c = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)
    >>> m = compensated_margins(Loop("1/s", c, delay=0.37))
    >>> L = lambda w: 5 * np.exp(-0.37j * w) / (1j * w + 5 - 5 * np.exp(-0.37j * w))    # perfect model
    >>> round(float(abs(L(m.crossover))), 12), round(m.delay_margin, 6)
    (1.0, 0.623048)
    """
    loop = _loop(loop)
    ol = CompensatedOpenLoop(loop)
    lo, hi = ol.default_range()
    g = ol.grid(lo, hi)
    gains = _gain_crossovers(ol, g)
    if gains.size:
        g = ol.grid(lo, hi, extra=gains)
    L = ol.value(g)
    phi = ol.unwrapped(g)
    crossovers: list[Crossover] = []
    for w in map(float, gains):
        Lw = complex(ol.value(np.array([w]))[0])
        ref = float(np.interp(w, g, phi))
        ph = math.atan2(Lw.imag, Lw.real)
        ph += TWO_PI * round((ref - ph) / TWO_PI)
        lag = (ph + math.pi) % TWO_PI
        pm = math.degrees(lag if lag <= math.pi else lag - TWO_PI)
        crossovers.append(Crossover("gain", w, 1.0, math.degrees(ph), phase_margin=pm, delay_margin=lag / w))
    # phase crossovers: odd multiples of pi crossed by the unwrapped phase between neighbours, counted as in
    # delaykit.spectrum.frequency.scan_phase: an odd multiple exactly at a point counts for the interval where it
    # is the upper end (rule A, the curve w >= 0) and for the one where it is the lower end (rule B, its mirror
    # image); the limit w -> 0+ is the exact phase0 (with |L| infinite when L has integrators)
    ccw = 0
    if not ol.zero:
        gg = np.concatenate([[0.0], g])
        uu = snap_half_turns(np.concatenate([[ol.phase0], phi]) / math.pi)
        ua, ub = uu[:-1], uu[1:]
        lo_u, hi_u = np.minimum(ua, ub), np.maximum(ua, ub)
        m0 = 2 * np.floor((lo_u - 1) / 2) + 1
        m0 = np.where(m0 < lo_u, m0 + 2, m0)  # the smallest odd integer >= lo_u (steps are under 20 degrees)
        rule_a = (m0 > lo_u) & (m0 <= hi_u)
        rule_b = (m0 >= lo_u) & (m0 < hi_u)
        k = np.flatnonzero((rule_a | rule_b) & (ua != ub))
        if k.size:
            wx = np.where(m0[k] == ua[k], gg[k], gg[k + 1])
            inner = (m0[k] != ua[k]) & (m0[k] != ub[k])
            if inner.any():
                # within a bracket the phase stays within 20 degrees of m pi, so the angle of -L passes through 0
                ki = k[inner]
                wx[inner] = solve_bracketed(lambda x: np.angle(-ol.value(x)), gg[ki], gg[ki + 1])
            mag = np.abs(ol.value(wx))
            direction = np.sign(ub[k] - ua[k]).astype(int)
            ccw = int(np.sum(direction * (rule_a[k].astype(int) + rule_b[k].astype(int)) * (mag > 1)))
            for x, mgn, m, d in zip(wx, mag, m0[k], direction):
                if x > 0 and math.isfinite(mgn):
                    crossovers.append(Crossover("phase", float(x), float(mgn), float(m * 180.0),
                                                gain_margin=(1.0 / mgn if mgn > 0 else math.inf),
                                                direction=int(d)))
    if ol.integrators > 0:  # the arc around s = 0, from phase0 + n pi clockwise to phase0
        from ._openloop import _odd_between

        u0 = snap_half_turns(np.array([ol.phase0 / math.pi]))[0]
        ccw -= _odd_between(u0, u0 + ol.integrators, True)
    on_curve = any(abs(abs(c.magnitude) - 1.0) < 1e-9 for c in crossovers if c.kind == "phase")
    p_rhp = _open_loop_rhp_poles(ol)

    def peak() -> tuple[float, float | None]:
        with np.errstate(all="ignore"):
            d = np.abs(1.0 + L)
        best, where = refine_minimum(lambda x: np.abs(1.0 + ol.value(x)), g, np.where(np.isfinite(d), d, np.inf),
                                     keep=8)
        w_ms: float | None = where
        if ol.integrators <= 0:  # the limit at w = 0
            d0 = abs(1.0 + complex(ol.value(np.zeros(1))[0]))
            if d0 < best:
                best, w_ms = d0, None
        return (1.0 / best if best > 0 else math.inf), w_ms

    return _assemble(loop.total_delay, crossovers, stable=_closed_loop_stable(loop), source="roots",
                     open_loop_rhp_poles=p_rhp if p_rhp is not None else -1,
                     encirclements=None if (on_curve or p_rhp is None) else ccw, cutoff=hi, peak=peak,
                     method="grid")

def compensated_jitter(loop: Loop) -> tuple[float, float, Margins]:
    """``(margin, frequency, margins)``: the Kao-Lincoln jitter margin ``inf |1 + L| / (w |L|)`` of a compensated
    loop (see :mod:`delaykit.spectrum.jitter`), searched on the refined grid to four times the cut-off and
    refined at the lowest local minima.

    Examples
    --------
    >>> from delaykit.models import Loop
    >>> c = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)
    >>> j, w, m = compensated_jitter(Loop("1/s", c, delay=0.37))
    >>> bool(0 < j <= m.delay_margin)
    True
    """
    loop = _loop(loop)
    m = compensated_margins(loop)
    if not m.stable:
        raise InvalidValueError(f"the loop is unstable with its constant delay {loop.total_delay:g} s: a jitter "
                                "margin needs a stable nominal loop")
    ol = CompensatedOpenLoop(loop)
    if ol.zero:
        return math.inf, math.inf, m
    lo, hi = ol.default_range()
    g = ol.grid(lo, 4.0 * hi)

    def fun(w: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            L = ol.value(w)
            v = np.abs(1.0 + 1.0 / L) / w
        return np.where(np.isfinite(v), v, np.inf)

    best, where = refine_minimum(fun, g, fun(g), keep=12)
    if ol.a0.size - ol.a2.size == 1:  # relative degree one: w |L| -> |a2/a0| at infinity, g -> |a0/a2|
        g_inf = float(abs(ol.a0[0] / ol.a2[0]))
        if g_inf <= best:
            best, where = g_inf, math.inf
    return best, where, m
