"""What the spectrum and the frequency response of a delay system say: poles, stability, H-infinity norm, Nyquist.

For a :class:`~delaykit.systems.DelayLTI` ``sys`` (or a :class:`~delaykit.models.Loop` / ``AltitudeLoop``, which
stands for its closed loop :attr:`Loop.system <delaykit.models.loop.Loop.system>`):

* :func:`poles` and :func:`is_stable`: the roots of its characteristic quasi-polynomial
  (:meth:`~delaykit.systems.DelayLTI.characteristic`) by the certified root finder
  (:func:`~delaykit.spectrum.roots.find_roots`, :func:`~delaykit.spectrum.stability.rightmost`), for any number of
  incommensurate delays.  Stability is decided for retarded systems and for neutral ones whose difference
  operator is strongly stable, channel by channel (:func:`~delaykit.spectrum.neutral.channel_abscissa`); other
  neutral systems are refused with the reason.
* :func:`hinfnorm`: the peak of the largest singular value of ``H(jw)`` on a grid that resolves every feature
  (the eigenvalues of ``A``, the delays' ripple), each local peak refined by a bounded scalar search; the
  limit as ``w -> inf`` is added.
* :func:`nyquist_count`: the closed-loop poles of ``feedback(L, I)`` in the right half-plane from the winding of
  ``det(I + L(s))`` on the imaginary axis (moved right by ``sigma`` to pass the integrators), tracked on a grid
  refined until the phase turns by less than 0.5 rad between points.
* :func:`loop_margins` (deprecated: :func:`delaykit.margins` takes a system): gain, phase and delay margins of one
  channel of a MIMO loop, the others closed.

Examples
--------
>>> from delaykit import tf, feedback
>>> T = feedback(tf("exp(-0.5*s)/s"), 1)
>>> is_stable(T)
True
>>> round(poles(T, (-3, 1, -10, 10)).rightmost.real, 6)
-1.588047
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..systems.build import system_of
from ..systems.difference import ChannelAbscissa, channel_abscissa
from ..systems.lti import DelayLTI
from .roots import RootStatus, Spectrum, find_roots, root_bound
from .stability import far_right_verdict, in_delay_units, right_half_plane_count, rightmost

__all__ = ["poles", "neutral_spectrum", "is_stable", "hinfnorm", "HinfNorm", "nyquist_count", "NyquistCount", "loop_margins",
           "LoopMargins", "zeros", "zero_function", "is_minimum_phase"]

_PHASE_STEP = 0.5  # rad: the largest turn of det(I + L) between two points of the Nyquist grid
_MAX_POINTS = 400_000


def _system(sys: Any) -> DelayLTI:
    """``sys``, or a loop's closed-loop system (:attr:`Loop.system <delaykit.models.loop.Loop.system>`)."""
    sys = system_of(sys)
    if not isinstance(sys, DelayLTI):
        raise InvalidTypeError(f"expected a DelayLTI (made by delaykit.tf, ss, feedback, ...) or a Loop, got "
                               f"{type(sys).__name__}")
    return sys


def poles(sys: DelayLTI, region: Sequence[float] | None = None) -> Spectrum:
    """Every pole of ``sys`` in the rectangle ``region = (re_min, re_max, im_min, im_max)``, certified.

    Without a region: the region that :func:`~delaykit.spectrum.stability.rightmost` finds, which provably holds
    the rightmost poles: every pole with ``Im s >= 0`` right of its left edge (``.region[0]``; the poles below
    the real axis are the conjugates, the coefficients being real), so ``.rightmost`` is the system's rightmost
    pole and ``.roots`` every pole at least as far right as the region's left edge.

    The poles are the roots of ``det(sI - A) det(I - P22(s) Delta(s))`` (hidden modes included), found by
    :func:`~delaykit.spectrum.roots.find_roots`: ``.roots``, ``.multiplicities``, ``.certified``.  For a
    neutral system ``.neutral_lines`` holds the supremum of its root chains' real parts for its delays, from the
    channels (:func:`~delaykit.spectrum.neutral.channel_abscissa`'s ``lines``), not from the expanded
    determinant.

    Examples
    --------
    >>> from delaykit import tf, feedback
    >>> sp = poles(feedback(tf("2/(s+1)"), 1), (-5, 1, -1, 1))
    >>> sp.roots.round(12).tolist(), sp.certified
    ([(-3+0j)], True)
    >>> r = poles(feedback(tf("exp(-0.5*s)/s"), 1)).rightmost    # no region: one that holds the rightmost
    >>> round(r.real, 6), round(r.imag, 6)
    (-1.588047, 1.540224)
    """
    import dataclasses

    sys = _system(sys)
    q = sys.characteristic()
    if region is not None:
        sp = find_roots(q, region)
        if sp.status is RootStatus.SAMPLE_BUDGET and q.kind == "retarded" and max(q.delays) > 0:
            # a region far larger than 1 s (a huge gain's poles): searched again in the delays' units, where the
            # boundary's samples do not grow with the scale
            t = max(q.delays)
            scaled = find_roots(in_delay_units(q), tuple(float(v) * t for v in region))
            if scaled.certified:
                sp = dataclasses.replace(scaled, roots=scaled.roots / t, region=sp.region)
    elif q.degree == 0 and len(q.polys) == 1:  # a constant: no poles at all (a static system, pure delays)
        sp = find_roots(q, (-1.0, 1.0, 0.0, 1.0))
    elif q.degree == 0:
        raise InvalidValueError(f"{sys!r} has only the poles of its difference operator, infinitely many up every "
                                "vertical line where they lie (neutral_spectrum(sys) gives the lines): give a region")
    else:
        sp = _rightmost(sys, q).spectrum
    if q.kind == "neutral" and q.degree > 0:
        sp = dataclasses.replace(sp, neutral_lines=(neutral_spectrum(sys).lines,))
    return sp


def neutral_spectrum(sys: DelayLTI) -> ChannelAbscissa:
    """Where the root chains of a system's difference operator ``det(I - D22 Delta(s))`` lie, per channel.

    :func:`~delaykit.spectrum.neutral.channel_abscissa` of the small-signal system's ``D22`` and delays:
    ``.abscissa`` (strong stability when negative), ``.lines`` (the supremum for these delays).  A retarded
    system has none (``-inf``).

    Examples
    --------
    >>> from delaykit import append, feedback, delay
    >>> T = append(feedback(delay(1.0), -0.6), feedback(delay(2 ** 0.5), -0.7))   # w = 0.6 w(t-1), ...
    >>> neutral_spectrum(T)
    ChannelAbscissa(-0.252207 (strongly stable, exact), 2 channels)
    """
    sys = _system(sys).without_limits()
    return channel_abscissa(sys.D22, sys.delays)


def _rightmost(sys: DelayLTI, q: Any) -> Any:
    """:func:`~delaykit.spectrum.stability.rightmost` of the characteristic function, a neutral one with its
    channels' bound (the polygon bound of the expanded determinant is conservative)."""
    return rightmost(q, neutral=neutral_spectrum(sys) if q.kind == "neutral" else None)


def _retarded(sys: DelayLTI, what: str) -> Any:
    q = sys.characteristic()
    if q.kind != "retarded":
        raise InvalidValueError(f"{what} is decided for retarded systems only; this one is {q.kind} (a delay "
                                "channel feeds another directly, D22 != 0), whose difference operator's spectrum is "
                                "not bounded conservatively yet")
    return q


def is_stable(sys: DelayLTI) -> bool:
    """True when every pole of the system lies left of the imaginary axis, certified.

    A retarded system is stable when its rightmost pole is (:func:`~delaykit.spectrum.stability.rightmost`).  A
    neutral one (a delay channel feeds another directly) has chains of poles that accumulate on the spectrum of
    its difference operator ``det(I - D22 Delta(s))``; it must be *strongly stable*, channel by channel
    (:func:`neutral_spectrum`'s abscissa below 0: stable under every small change of each channel's delay), and
    then it is stable when its rightmost pole, searched right of that abscissa, is.

    Raises
    ------
    InvalidValueError
        For a neutral system whose difference operator is not strongly stable (the message gives the bound), or
        when the rightmost root cannot be certified.

    Examples
    --------
    >>> from delaykit import tf, feedback
    >>> is_stable(feedback(tf("exp(-2*s)/s"), 1))   # the delay margin of 1/s is pi/2
    False
    >>> is_stable(feedback(tf("exp(-s)"), 0.5))      # y(t) = u(t-1) - 0.5 y(t-1): poles on Re s = ln(0.5)
    True
    """
    sys = _system(sys)
    q = sys.characteristic()
    if q.kind == "neutral":
        na = neutral_spectrum(sys)
        if not na.strongly_stable:
            how = "" if na.exact else " (an upper bound)"
            now = (f"; for these exact delays the chains reach {na.lines:.6g}, but an arbitrarily small change of "
                   "the delays moves them right" if na.exact_lines and na.lines < 0 else "")
            raise InvalidValueError(
                f"{sys!r} is neutral and its difference operator is not strongly stable: with the channels' delays "
                f"changed independently its root chains reach Re s = {na.abscissa:.6g}{how} >= 0{now}, so no "
                "stability verdict is given")
        if q.degree == 0:
            return True  # only the difference operator's roots, all left of its (negative) abscissa
        # every root right of the axis lies in |s| <= R (the channels' bound on the difference operator there):
        # one argument-principle count on [0, R] x [-R, R] decides, the chains being left of the axis
        lead = na.lead(0.0)
        if lead > 0:
            n = right_half_plane_count(q, radius=root_bound(q, 0.0, lead=lead))
            if n is not None:
                return n == 0
    if q.degree == 0 and len(q.polys) == 1:
        return True  # a constant: no poles at all (a static system, pure delays)
    rm = _rightmost(sys, q)
    if not rm.certified and not rm.abscissa < 0:
        # too large a region from the loop's own time scale (a huge gain): decided in the delays' units instead
        verdict = far_right_verdict(q) if q.kind == "retarded" else None
        if verdict is None:
            raise InvalidValueError(f"the stability of {sys!r} could not be certified: {rm!r}")
        return verdict
    return rm.stable


@dataclass(frozen=True, repr=False)
class HinfNorm:
    """The H-infinity norm ``max_w sigma_max(H(jw))`` and where it is reached.

    ``frequency`` is ``inf`` when the supremum is the high-frequency limit and ``None`` for an unstable system
    (``value`` is then ``inf``); ``rtol`` is the relative accuracy of the refined peak (the grid's resolution is
    stated in the module docstring).
    """

    value: float
    frequency: float | None
    stable: bool
    rtol: float
    points: int

    def __iter__(self):  # value, frequency = hinfnorm(sys), as python-control's tuple
        return iter((self.value, self.frequency))

    def __len__(self) -> int:
        return 2

    def __getitem__(self, i: int | slice) -> Any:  # hinfnorm(sys)[0], as the tuple it unpacks as
        return (self.value, self.frequency)[i]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (infinite values as null)."""
        from .frequency import _jsonable

        return _jsonable({"value": self.value, "frequency": self.frequency, "stable": self.stable,
                          "rtol": self.rtol, "points": self.points})

    def __repr__(self) -> str:
        if not self.stable:
            return "HinfNorm(inf: unstable)"
        at = "w -> inf" if self.frequency == math.inf else f"w={self.frequency:.6g} rad/s"
        return f"HinfNorm({self.value:.8g} at {at}, rtol {self.rtol:g}, {self.points} points)"


def _features(sys: DelayLTI) -> tuple[float, float, list[float]]:
    """A frequency band ``(lo, hi)`` that holds the system's features, and the features."""
    eig = np.linalg.eigvals(sys.A) if sys.nstates else np.zeros(0)
    feats = [float(abs(e)) for e in eig if abs(e) > 0] + [1.0 / t for t in sys.delays if t > 0]
    feats += [float(abs(e.imag)) for e in eig if abs(e.imag) > 0]
    if not feats:
        feats = [1.0]
    return min(feats) * 1e-3, max(feats) * 1e3, feats


def _grid(sys: DelayLTI, lo: float, hi: float, per_decade: int = 200) -> np.ndarray:
    parts = [np.geomspace(lo, hi, int(per_decade * math.log10(hi / lo)) + 1), [0.0]]
    eig = np.linalg.eigvals(sys.A) if sys.nstates else np.zeros(0)
    c = eig[(eig.imag > 0)]
    if c.size:  # points over each lightly damped mode
        t = np.tan(np.linspace(-math.pi / 2, math.pi / 2, 43)[1:-1])
        parts.append((c.imag[:, None] + np.maximum(np.abs(c.real), 1e-12)[:, None] * t[None, :]).ravel())
    total = sum(sys.delays)
    if total > 0:  # the ripple of the delays: 16 points a period of the longest delay path, up to a cap
        step = 2 * math.pi / (16 * total)
        top = min(hi, step * _MAX_POINTS / 4)
        parts.append(np.arange(0.0, top, step))
    g = np.concatenate([np.asarray(p, float) for p in parts])
    return np.unique(g[(g >= 0) & (g <= hi)])


def _sigma_max(sys: DelayLTI, w: np.ndarray) -> np.ndarray:
    return sys.frequency_response(w).singular_values()[0]


def _high_frequency_limit(sys: DelayLTI) -> float:
    """``limsup sigma_max(H(jw))`` as ``w -> inf``: ``sigma_max(D11 + D12 Theta (I - D22 Theta)^-1 D21)`` over the
    unit phases ``Theta`` the delays take (all of the torus, for incommensurate delays), sampled and refined."""
    D11, D12, D21, D22 = sys.D11, sys.D12, sys.D21, sys.D22
    m = sys.ndelays
    live = [j for j in range(m) if D12[:, j].any() or D22[:, j].any()]
    if not live or not (D12.any() and D21.any()):
        return float(np.linalg.svd(D11, compute_uv=False)[0]) if D11.size else 0.0

    def sig(theta: np.ndarray) -> float:
        e = np.ones(m, complex)
        e[live] = np.exp(1j * theta)
        with np.errstate(all="ignore"):
            M = D11 + (D12 * e) @ np.linalg.solve(np.eye(m) - D22 * e, D21)
        s = np.linalg.svd(M, compute_uv=False)[0] if M.size else 0.0
        return float(s) if np.isfinite(s) else math.inf

    from scipy.optimize import minimize

    rng = np.random.default_rng(0)
    k = len(live)
    samples = (np.linspace(0, 2 * math.pi, 512, endpoint=False)[:, None] if k == 1
               else rng.uniform(0, 2 * math.pi, (4096, k)))
    vals = np.array([sig(t) for t in samples])
    best = float(vals.max())
    for t0 in samples[np.argsort(vals)[-4:]]:
        res = minimize(lambda t: -sig(t), t0, method="Nelder-Mead", options={"xatol": 1e-10, "fatol": 1e-14})
        best = max(best, -float(res.fun))
    return best


def hinfnorm(sys: DelayLTI, *, rtol: float = 1e-10) -> HinfNorm:
    """The H-infinity norm of a stable retarded system and the frequency of its peak.

    Method: ``sigma_max(H(jw))`` on a grid from 1e-3 times the smallest feature (eigenvalue of ``A``, 1/delay) to
    1e3 times the largest, 200 points a decade, 41 points over each complex mode of ``A``, 81 over the system's
    least damped pole (the rightmost, certified) and 16 points per period of the longest delay path; each local maximum refined by a bounded scalar search to ``rtol``, and the
    high-frequency limit (the feedthrough over the delays' phases) added.  A peak narrower than the grid's
    spacing between two of these points could be missed; the value is then a lower bound.  Unstable systems
    have an infinite norm.

    Returns
    -------
    HinfNorm
        Unpacks as ``value, frequency`` and indexes as that pair (``hinfnorm(sys)[0]``), as python-control's tuple.

    Examples
    --------
    >>> from delaykit import tf, feedback
    >>> value, w = hinfnorm(tf("1/(s^2+0.2*s+1)"))
    >>> round(value, 6), round(w, 6)    # 1/(2 zeta sqrt(1 - zeta^2)) at sqrt(1 - 2 zeta^2)
    (5.025189, 0.989949)
    """
    sys = _system(sys)
    rtol = check_real("rtol", rtol, minimum=1e-15, maximum=1e-2)
    if not is_stable(sys):
        return HinfNorm(math.inf, None, False, rtol, 0)
    q = sys.characteristic()
    rm = _rightmost(sys, q) if len(q.polys) > 1 or q.degree > 0 else None
    if sys.ninputs == 0 or sys.noutputs == 0:
        return HinfNorm(0.0, 0.0, True, rtol, 0)
    lo, hi, _ = _features(sys)
    w = _grid(sys, lo, hi)
    if rm is not None and rm.root is not None and rm.root.imag > 0:  # the least damped pole: a resonance
        t = np.tan(np.linspace(-math.pi / 2, math.pi / 2, 83)[1:-1])
        near = rm.root.imag + max(abs(rm.root.real), 1e-12) * t
        w = np.unique(np.concatenate([w, near[near > 0]]))
    s = _sigma_max(sys, w)
    from scipy.optimize import minimize_scalar

    i = int(np.argmax(s))
    best, where = float(s[i]), float(w[i])
    k = 1 + np.flatnonzero((s[1:-1] >= s[:-2]) & (s[1:-1] >= s[2:]))
    for j in k[np.argsort(s[k])][::-1][:24]:
        a, b = w[j - 1], w[j + 1]
        res = minimize_scalar(lambda x: -float(_sigma_max(sys, np.array([x]))[0]), bounds=(a, b), method="bounded",
                              options={"xatol": rtol * max(w[j], 1e-300)})
        if -res.fun > best:
            best, where = float(-res.fun), float(res.x)
    lim = _high_frequency_limit(sys)
    if lim > best * (1 + rtol):
        best, where = lim, math.inf
    return HinfNorm(best, where, True, rtol, int(w.size))


@dataclass(frozen=True, repr=False)
class NyquistCount:
    """The generalised Nyquist criterion for ``feedback(L, I)``: ``closed_loop_unstable = open_loop_unstable -
    encirclements`` (counterclockwise encirclements of 0 by ``det(I + L(s))``, ``s = sigma + jw``)."""

    encirclements: int
    open_loop_unstable: int
    closed_loop_unstable: int
    sigma: float
    points: int

    @property
    def stable(self) -> bool:
        """No closed-loop pole right of ``Re s = sigma``."""
        return self.closed_loop_unstable == 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"encirclements": self.encirclements, "open_loop_unstable": self.open_loop_unstable,
                "closed_loop_unstable": self.closed_loop_unstable, "stable": self.stable, "sigma": self.sigma,
                "points": self.points}

    def __repr__(self) -> str:
        return (f"NyquistCount({'stable' if self.stable else 'UNSTABLE'}: {self.closed_loop_unstable} closed-loop "
                f"poles right of {self.sigma:.3g} = {self.open_loop_unstable} open-loop - {self.encirclements} "
                f"encirclements, {self.points} points)")


def _rhp_count(sys: DelayLTI, sigma: float) -> int:
    q = _retarded(sys, "the Nyquist count")
    if q.delays == (0.0,):  # det(I - P22 Delta) = 1 (delays on inputs and outputs only): the poles of A
        eig = np.linalg.eigvals(sys.A) if sys.nstates else np.zeros(0)
        return int(np.sum(eig.real > sigma))
    R = root_bound(q, sigma)
    sp = find_roots(q, (sigma, sigma + 2 * R + 1.0, -(R + 1.0), R + 1.0))
    if not sp.certified:
        raise InvalidValueError(f"the open-loop poles right of {sigma:g} could not be certified: {sp.reason}")
    return int(sp.multiplicities.sum())


def nyquist_count(L: DelayLTI, *, sigma: float | None = None) -> NyquistCount:
    """The MIMO Nyquist count of the unity negative feedback loop around the square, retarded ``L``.

    The winding of ``det(I + L(sigma + jw))`` for ``w`` from 0 to infinity (the other half is its conjugate) on a
    grid refined until the phase turns by at most 0.5 rad between points and no point lies near 0; beyond the
    last point ``||(I + L_inf)^-1 (L - L_inf)||`` stays below 1/2, so no winding is left out there.
    ``sigma`` (default ``1e-9`` times the system's fastest feature: eigenvalue of ``A`` or 1/delay) moves the
    contour right of poles on the imaginary axis (integrators); closed-loop poles closer to the axis than that
    count as stable.

    Raises
    ------
    InvalidValueError
        For a non-square ``L``, a delayed feedthrough (``det(I + L)`` keeps circling as ``w -> inf``), or a neutral
        ``L``.

    Examples
    --------
    >>> from delaykit import tf
    >>> nyquist_count(tf("exp(-0.5*s)/s")).stable, nyquist_count(tf("exp(-2*s)/s")).closed_loop_unstable
    (True, 2)
    """
    L = _system(L)
    if L.ninputs != L.noutputs:
        raise InvalidValueError(f"the Nyquist count needs a square loop, got {L!r}")
    lo, hi, feats = _features(L)
    sigma = 1e-9 * max(feats) if sigma is None else check_real("sigma", sigma, minimum=0.0)
    m = L.ndelays
    for j in range(m):
        if L.D12[:, j].any() and (L.D21[j, :].any() or L.D22[j, :].any()):
            raise InvalidValueError("the loop has a delayed direct feedthrough: det(I + L(jw)) keeps circling as "
                                    "w -> inf, so the Nyquist count is not finite")
    n = L.noutputs
    Dinf = np.eye(n) + L.D11
    if abs(np.linalg.det(Dinf)) < 1e-12:
        raise InvalidValueError("I + L(inf) is singular: the closed loop is not well posed")
    Dinv = np.linalg.inv(Dinf)

    def det(w: np.ndarray) -> np.ndarray:
        H = np.moveaxis(L.evaluate(sigma + 1j * w), -1, 0)
        return np.linalg.det(np.eye(n) + H)

    # the top: where ||(I + D)^-1 (L - D)|| < 1/2 for a decade of points
    top = hi
    for _ in range(60):
        ww = np.geomspace(top, 10 * top, 200)
        H = np.moveaxis(L.evaluate(sigma + 1j * ww), -1, 0) - L.D11
        if np.all(np.linalg.norm(Dinv @ H, ord=2, axis=(1, 2)) < 0.5):
            break
        top *= 10
    else:
        raise InvalidValueError("det(I + L(jw)) does not settle at high frequency")
    w = np.unique(np.concatenate([[0.0], np.geomspace(sigma * 1e-3 + 1e-300, top, 2000), _grid(L, lo, top)]))
    d = det(w)
    for _ in range(40):
        ratio = d[1:] / d[:-1]
        with np.errstate(all="ignore"):
            bad = ~(np.abs(np.angle(ratio)) <= _PHASE_STEP) | ~np.isfinite(ratio)
        if not bad.any():
            break
        mid = 0.5 * (w[:-1][bad] + w[1:][bad])
        if w.size + mid.size > _MAX_POINTS:
            raise InvalidValueError(f"the Nyquist curve needs more than {_MAX_POINTS} points to resolve")
        w = np.concatenate([w, mid])
        order = np.argsort(w)
        w, d = w[order], np.concatenate([d, det(mid)])[order]
    else:
        raise InvalidValueError("the phase of det(I + L) could not be resolved (a closed-loop pole near the contour)")
    turn = float(np.sum(np.angle(d[1:] / d[:-1])))
    turn += float(np.angle(np.linalg.det(Dinf) / d[-1]))  # the last point to the limit (less than 1/2 rad)
    enc = int(round(2 * turn / (2 * math.pi)))  # w < 0 mirrors w > 0
    P = _rhp_count(L, sigma)
    return NyquistCount(enc, P, P - enc, sigma, int(w.size))


@dataclass(frozen=True, repr=False)
class LoopMargins:
    """Gain, phase and delay margins of channel ``channel`` of a MIMO loop with the other channels closed."""

    channel: int
    gain_margin: float
    phase_crossover: float | None
    phase_margin: float
    gain_crossover: float | None
    delay_margin: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (infinite values as null)."""
        from .frequency import _jsonable

        return _jsonable({"channel": self.channel, "gain_margin": self.gain_margin,
                          "phase_crossover": self.phase_crossover, "phase_margin_deg": self.phase_margin,
                          "gain_crossover": self.gain_crossover, "delay_margin": self.delay_margin})

    def __repr__(self) -> str:
        return (f"LoopMargins(channel {self.channel}: gain {self.gain_margin:.4g}, phase {self.phase_margin:.4g} deg, "
                f"delay {self.delay_margin:.4g} s)")


def loop_margins(L: DelayLTI, channel: int = 0) -> LoopMargins:
    """Deprecated: use :func:`delaykit.margins` (``margins(L)`` for a SISO ``L``, ``margins(L)[channel]`` for a MIMO
    one).

    Loop-at-a-time margins: the loop broken at input ``channel`` of ``L``, the other channels closed, as
    :func:`~delaykit.spectrum.system_margins.channel_margins` gives them (exact for a rational loop times one
    delay, else a refined grid scan), in the old result type: ``gain_crossover`` is the gain crossover of the
    delay margin (``Margins.crossover``).  The margins are ``nan`` when the closed loop is unstable (certified),
    where this function once reported the crossovers' margins of a loop that was already unstable.

    Examples
    --------
    >>> import warnings
    >>> from delaykit import tf
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore", DeprecationWarning)
    ...     m = loop_margins(tf("exp(-0.5*s)/s"))
    >>> round(m.phase_margin, 4), round(m.delay_margin, 6)     # 90 deg - 0.5 rad at w = 1; pi/2 - 0.5
    (61.3521, 1.070796)
    """
    import warnings

    warnings.warn("loop_margins(L, channel) is deprecated and will be removed in the next release: use "
                  "delaykit.margins(L), a Margins for a SISO L and a tuple of them (one per channel) for a MIMO L",
                  DeprecationWarning, stacklevel=2)
    from .system_margins import channel_margins

    m = channel_margins(_system(L), channel)
    return LoopMargins(int(channel), m.gain_margin, m.phase_crossover, m.phase_margin, m.crossover, m.delay_margin)


def zero_function(sys: DelayLTI) -> Any:
    """The quasi-polynomial whose roots are the zeros of a SISO or square MIMO system, the pure delay that
    multiplies every term divided out.

    The determinant of the system matrix ``[[sI - A, -B], [C, D]]`` of the linear-fractional form, with the
    delay channels' rows ``[-C2, I - Delta D22, -D21]`` scaled by ``Delta(s) = diag(exp(-s tau_j))`` (for a SISO
    system, the numerator of ``H(s)`` over ``det(sI - A)``): multilinear in the channels' ``exp(-s tau_j)``, it is
    the sum over the subsets of channels of bordered determinants, each a polynomial found by interpolation
    (:meth:`DelayLTI.characteristic`'s method).  A factor ``exp(-s T)`` common to every term (the system's dead
    time) has no zero, so it is divided out: ``(s - 1) exp(-s)`` gives ``s - 1``.

    Raises
    ------
    InvalidValueError
        For a system that is not square, has more delay channels than supported, or whose system matrix is
        singular for every ``s`` (no isolated zeros, as ``tf([["1/(s+1)", "1/(s+1)"], ["1/(s+1)", "1/(s+1)"]])``).

    Examples
    --------
    >>> from delaykit import tf
    >>> zero_function(tf("(s-1)*exp(-s)/(s+2)^2"))
    QuasiPolynomial(s + -1)
    """
    from ..models.quasipolynomial import QuasiPolynomial
    from ..systems.build import _subset_terms
    from ..systems.lti import _MAX_CHANNELS

    sys = _system(sys).without_limits()
    if sys.ninputs != sys.noutputs:
        raise InvalidValueError(f"zeros are those of a square system (as many inputs as outputs); {sys!r} has "
                                f"{sys.ninputs} inputs and {sys.noutputs} outputs (select a square part with "
                                "sys[rows, cols])")
    if sys.ndelays > _MAX_CHANNELS:
        raise InvalidValueError(f"{sys!r} has {sys.ndelays} delay channels; at most {_MAX_CHANNELS} are supported")
    terms = _subset_terms(sys, transfer=True)
    if not terms or _rank_deficient(sys, terms):
        raise InvalidValueError(f"the system matrix of {sys!r} is singular for every s (its transfer matrix is "
                                "rank deficient): it has no isolated zeros")
    dead = min(terms)
    return QuasiPolynomial([c[::-1] for c in terms.values()], [k - dead for k in terms])


def _rank_deficient(sys: DelayLTI, terms: dict[float, np.ndarray]) -> bool:
    """True when the system matrix's determinant (``terms``, ascending coefficients by delay) is at rounding level
    of Hadamard's bound (the product of the matrix's row norms) at eight points on a circle: singular for every
    ``s``, its interpolated coefficients noise."""
    n = sys.nstates
    eig = np.linalg.eigvals(sys.A) if n else np.zeros(0)
    mags = np.abs(eig[np.abs(eig) > 0])
    radius = float(np.exp(np.mean(np.log(mags)))) if mags.size else 1.0
    for s in radius * np.exp(2j * np.pi * (np.arange(8) + 0.5) / 8):
        delta = np.exp(-s * np.array(sys.delays))
        M = np.block([[s * np.eye(n) - sys.A, -sys.B2, -sys.B1],
                      [-delta[:, None] * sys.C2, np.eye(sys.ndelays) - delta[:, None] * sys.D22,
                       -delta[:, None] * sys.D21],
                      [sys.C1, sys.D12, sys.D11]])
        bound = float(np.prod(np.linalg.norm(M, axis=1)))
        value = abs(sum(np.polyval(c[::-1], s) * np.exp(-s * tau) for tau, c in terms.items()))
        if value > 1e-9 * bound:
            return False
    return True


def zeros(sys: DelayLTI, region: Sequence[float] | None = None) -> Spectrum:
    """Every (transmission) zero of a SISO or square MIMO system in ``region = (re_min, re_max, im_min,
    im_max)``, certified as :func:`poles` certifies poles.

    The zeros are the roots of :func:`zero_function`: for a SISO system the roots of the numerator
    quasi-polynomial of ``H(s)``, for a square MIMO system those of the determinant of its system matrix (the
    invariant zeros, which for a delay-free system are python-control's ``zeros``).  Zeros that a pole cancels
    are kept (as MATLAB's ``tzero`` of a non-minimal model).  A delay ``exp(-s tau)`` has no zero in the finite
    plane and gives none; a delayed sum such as ``1 - 0.5 exp(-s)`` gives a chain of zeros up a vertical line.

    Without a region: one that holds the rightmost zeros, as :func:`poles` without one (every zero with
    ``Im s >= 0`` right of ``.region[0]``; the others are conjugates).  A numerator whose delayed terms outrank its
    delay-free one in degree (advanced) has zeros unbounded to the right, and needs a region.

    Returns
    -------
    Spectrum
        ``.roots`` (the zeros), ``.multiplicities``, ``.certified``; a system without zeros gives none.

    Raises
    ------
    InvalidValueError
        As :func:`zero_function`, or for an advanced numerator without a region.

    Examples
    --------
    >>> from delaykit import tf
    >>> zeros(tf("(s-1)*exp(-s)/(s+2)^2")).roots.round(12).tolist()
    [(1+0j)]
    >>> z = zeros(tf("(1 - 0.5*exp(-s))/(s+1)"), (-2, 1, 0, 7)).roots    # exp(-s) = 2: s = -ln 2 + 2 pi k i
    >>> sorted(z.round(6).tolist(), key=lambda c: c.imag)
    [(-0.693147+0j), (-0.693147+6.283185j)]
    """
    q = zero_function(sys)
    if region is not None:
        return find_roots(q, region)
    if q.degree == 0 and len(q.polys) == 1:  # a constant: no zeros at all
        return find_roots(q, (-1.0, 1.0, 0.0, 1.0))
    if q.kind == "advanced":
        raise InvalidValueError(f"the zeros of {_system(sys)!r} are unbounded to the right (its numerator "
                                f"{q!r} is advanced: a delayed term has the highest degree); give a region")
    if q.degree == 0:
        raise InvalidValueError(f"the zeros of {_system(sys)!r} are those of {q!r}, infinitely many up every "
                                "vertical line where they lie: give a region")
    return rightmost(q).spectrum


def is_minimum_phase(sys: DelayLTI) -> bool:
    """True when the system has no zero with ``Re s >= 0`` (:func:`zeros`), certified.

    A pure delay ``exp(-s tau)`` is not counted: it has no zero in the finite plane, and this function looks at
    zeros only (as MATLAB's ``isminphase`` of a model with an input or output delay); whether the system has a
    dead time is ``sys.delays``, and a dead time limits a loop's bandwidth as a right-half-plane zero does
    (Skogestad and Postlethwaite count both as non-minimum-phase elements).  A numerator whose delayed terms
    outrank its delay-free one in degree (``exp(-s) s + 1``) has zeros unbounded to the right: False.  A neutral
    numerator (``1 - 0.5 exp(-s)``) has chains of zeros approaching vertical lines
    (:func:`~delaykit.spectrum.roots.neutral_lines`): a line at ``Re s >= 0`` gives False; with several delays in
    its top-degree terms the line is an upper bound unless the delays are rationally independent, so False can
    then be conservative.

    The zeros are those of the realisation (:func:`zeros`), cancelled ones included: a transfer matrix made by
    :func:`delaykit.tf` realises each entry on its own, and an unstable mode that two entries share shows up as a
    zero at that mode (``tf([["1/(s-1)", "1/(s-1)"], ["0", "1/(s+1)"]])`` gives a zero at 1 that no minimal
    realisation has): for such a system the answer False may come from the realisation, not the transfer matrix.

    Raises
    ------
    InvalidValueError
        As :func:`zero_function`, or when the rightmost zero cannot be certified.

    Examples
    --------
    >>> from delaykit import tf
    >>> is_minimum_phase(tf("(s-1)*exp(-s)/(s+2)^2")), is_minimum_phase(tf("(s+1)*exp(-s)/(s+2)^2"))
    (False, True)
    >>> is_minimum_phase(tf("(1 - 0.5*exp(-s))/(s+1)"))     # zeros on Re s = -ln 2
    True
    """
    from .roots import neutral_lines

    q = zero_function(sys)
    if q.degree == 0 and len(q.polys) == 1:
        return True
    if q.kind == "advanced":
        return False
    lines = neutral_lines(q)
    if lines and (q.degree == 0 or lines[0] >= 0):  # chains of zeros approach the line (or lie on it)
        return lines[0] < 0
    rm = rightmost(q)
    if not rm.certified and not rm.abscissa < 0:
        raise InvalidValueError(f"the rightmost zero of {_system(sys)!r} could not be certified: {rm!r}")
    return rm.abscissa < 0
