"""Exact frequency response and stability margins of a continuous delay loop.

Broken at the plant input, a :class:`~delaykit.models.loop.Loop` has the loop transfer function

    ``L(s) = Np(s) Nc(s) / (Dp(s) Dc(s)) * exp(-s T)``,   ``T = Ti + To`` (the total delay),

with ``Np/Dp`` the plant and ``Nc/Dc`` the controller's feedback part, so that ``1 + L = 0`` is the loop's
characteristic equation ``Dp Dc + Np Nc exp(-s T) = 0`` (:meth:`~delaykit.models.loop.Loop.characteristic`).
Everything here is evaluated exactly, with the delay: no Padé approximation and no sampled phase unwrapping.

* :func:`frequency_response` gives ``L(jw)`` with its magnitude and *unwrapped* phase.  The phase is the sum
  of the angles of the factors ``jw - r`` over the zeros and poles ``r`` of ``L`` minus ``w T``, a continuous
  function of ``w`` that needs no grid, snapped to ``angle(L)`` modulo 360 degrees.
* :func:`margins` gives the gain, phase and delay margins, the peak sensitivity and every crossover, and the
  closed loop's stability from its exact characteristic roots (the certified count of roots in the right
  half-plane, :func:`~delaykit.spectrum.roots.find_roots`), with the Nyquist count beside it.

A loop whose controller compensates the delay (a Smith predictor, predictor feedback) has two delays and no
rational ``L`` times one delay: :func:`frequency_response`, :func:`frequency_grid` and :func:`margins` hand it
to :mod:`delaykit.spectrum.compensated`, which breaks the loop after the compensator's own command and evaluates
the exact ``L`` on a refined grid.  Sampled loops are refused: their margins come from
:mod:`delaykit.spectrum.sampled`.  The numerical machinery
(roots of ``L``, the phase, the crossings) is the private :mod:`._openloop`.

How the crossovers are found: ``|L(jw)|^2`` is a rational function of ``w^2``, so the gain crossovers are the
positive real roots of the polynomial ``|N(jw)|^2 - |D(jw)|^2`` in ``w^2`` (polished by Newton's method on
``log|L|``).  The phase crossovers (phase = -180 degrees modulo 360) are found on a dense grid (logarithmic,
100 points a decade, plus points spread over every lightly damped pole or zero and the extrema of the
phase, so that the phase is monotone between grid points), each one then refined by bisection to machine
precision.  A delay makes infinitely many phase crossovers; they are listed up to a cut-off frequency
``Margins.cutoff``: the largest of 100 times the largest pole or zero magnitude, twice the largest gain
crossover, 8 pi / T, the frequency beyond which ``|L| < 1e-3`` for good (when ``|L(j inf)| < 1e-3``), and 1.5
times the last stationary point of ``|L(jw)|``, extended until at least one phase crossover lies beyond that
point (at most 10,000 phase crossovers are listed).  Past the last stationary point ``|L|`` is monotone, so
no crossover beyond the cut-off can give a smaller gain margin than the listed ones and the limit
``|L(j inf)|`` (a biproper loop's asymptote, listed as a phase crossover at infinite frequency).

Examples
--------
>>> from delaykit import AltitudeLoop
>>> m = margins(AltitudeLoop(kp=1.31, delay=0.368))
>>> m
Margins(GM 3.258 (10.26 dB) at 4.268 rad/s, PM 62.38 deg at 1.31 rad/s, DM 0.8311 s, Ms 1.561, stable)
>>> round(m.delay_margin, 6) == round(3.141592653589793 / (2 * 1.31) - 0.368, 6)
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.altitude import AltitudeLoop, as_loop
from ..models.budget import MAX_FREQUENCY_DECADES, MAX_RESPONSE_POINTS, check_count
from ..models.loop import Loop
from ._openloop import (TWO_PI, OpenLoop, PhaseScan, cutoff_frequency, dense_grid, gain_crossovers, scan_phase,
                        newton_bracketed, snap_half_turns)

if TYPE_CHECKING:
    from ..systems.lti import DelayLTI

__all__ = ["FrequencyResponse", "Crossover", "Margins", "frequency_response", "frequency_grid", "margins",
           "check_frequency_range", "MAX_DELAY_PHASE"]

MAX_DELAY_PHASE = 1e12
"""The largest phase ``w T`` (rad) of a delay that a frequency range may reach: its rounding error there, some
1e-4 rad, is the most a response may carry."""


# ---------------------------------------------------------------------------------------------- the loop
def _continuous(loop: Any) -> Loop:
    """``loop`` as a continuous :class:`Loop` (an AltitudeLoop through ``to_loop()``), or an error."""
    loop = as_loop(loop)
    if loop.sampled:
        raise InvalidValueError(
            f"the loop is sampled (period {loop.period:g} s): its frequency response and margins are those of a "
            "discrete-time loop and come from delaykit.spectrum.sampled; this module analyses continuous loops "
            "(period=None)")
    return loop


def _system(x: Any) -> Any:
    """``x`` when it is a :class:`~delaykit.systems.DelayLTI` (an open loop ``L``, closed as ``feedback(L, I)``), else
    ``None``; anything that is neither a system nor a loop is refused naming all three."""
    if isinstance(x, (Loop, AltitudeLoop)):
        return None
    from ..systems.lti import DelayLTI

    if isinstance(x, DelayLTI):
        return x
    raise InvalidTypeError(f"expected a Loop, an AltitudeLoop or a DelayLTI open loop (made by delaykit.tf, ss, "
                           f"series, ...: closed as feedback(L, I)), got {type(x).__name__}")


def _compensated(loop: Loop) -> bool:
    """True for a loop whose controller reads its own command (a compensator: see
    :mod:`delaykit.spectrum.compensated`, which analyses it)."""
    return not hasattr(loop.controller, "feedback_polynomials")


def _siso(sys: Any, what: str) -> Any:
    """The SISO system ``sys`` (without its saturations), or an error pointing to the MIMO response."""
    if (sys.ninputs, sys.noutputs) != (1, 1):
        raise InvalidValueError(f"{what} takes a SISO open loop, got {sys!r}; a MIMO system's response is "
                                "sys.frequency_response(w), its loop-at-a-time margins margins(sys)")
    return sys.without_limits() if sys.saturations else sys


# ------------------------------------------------------------------------------------ frequency response
def _frequencies(w: Any) -> np.ndarray:
    """``w`` as a 1-D float array of finite frequencies >= 0, or a delaykit error naming the problem
    (:func:`~delaykit.systems.lti.as_frequencies`)."""
    from ..systems.lti import as_frequencies

    return as_frequencies(w)


@dataclass(frozen=True, repr=False, eq=False)
class FrequencyResponse:
    """``L(jw)`` of a loop at the frequencies ``w`` (rad/s).

    ``L`` is complex, ``magnitude_db`` is ``20 log10 |L|`` and ``phase_deg`` the unwrapped phase in degrees
    (continuous in ``w`` except where a pole or zero sits on the imaginary axis; as ``w -> 0+`` it starts at
    the multiple of 360 degrees nearest to -90 degrees per integrator, so that ``1/(s-1)`` starts at -180).
    At a pole on the imaginary axis ``L`` is infinite.
    """

    w: np.ndarray
    L: np.ndarray
    magnitude_db: np.ndarray
    phase_deg: np.ndarray

    @property
    def magnitude(self) -> np.ndarray:
        """``|L(jw)|``."""
        return np.abs(self.L)

    @property
    def sensitivity(self) -> np.ndarray:
        """``S = 1 / (1 + L)``, complex."""
        with np.errstate(all="ignore"):
            return 1.0 / (1.0 + self.L)

    @property
    def complementary(self) -> np.ndarray:
        """``T = L / (1 + L)``, complex (the complementary sensitivity)."""
        with np.errstate(all="ignore"):
            return np.where(np.isinf(self.L), 1.0 + 0j, self.L / (1.0 + self.L))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: ``w``, ``re``, ``im``, ``magnitude_db``, ``phase_deg`` (infinite values are ``null``)."""
        parts = (("w", self.w), ("re", self.L.real), ("im", self.L.imag), ("magnitude_db", self.magnitude_db),
                 ("phase_deg", self.phase_deg))
        return {k: _jsonable(v.tolist()) for k, v in parts}

    def plot(self, *, ax: Any = None, kind: str = "bode") -> Any:
        """Draw the response, as python-control's ``response.plot()``: ``kind`` ``"bode"``, ``"nyquist"`` or
        ``"nichols"`` (:mod:`delaykit.plotting.lti`, imported here: computing a response never loads matplotlib).
        Returns the figure.  The loop itself (``bode_plot(loop, margins=True)``, ``nyquist_plot(loop)``) adds its
        margins, Nyquist count and Ms circle.

        Examples
        --------
        >>> from delaykit import AltitudeLoop
        >>> fig = frequency_response(AltitudeLoop(kp=1.31, delay=0.368)).plot(kind="nyquist")
        >>> fig.axes[0].get_xlabel()
        'Re L(jω)'
        """
        from ..plotting.lti import bode_plot, nichols_plot, nyquist_plot  # on demand (tests/test_layout.py)

        draw = {"bode": bode_plot, "nyquist": nyquist_plot, "nichols": nichols_plot}.get(kind)
        if draw is None:
            raise InvalidValueError(f"kind must be 'bode', 'nyquist' or 'nichols', got {kind!r}")
        return draw(self, ax=ax)

    def __repr__(self) -> str:
        db = self.magnitude_db[np.isfinite(self.magnitude_db)]
        mag = f", |L| {db.min():.4g} to {db.max():.4g} dB" if db.size else ""
        return (f"FrequencyResponse({self.w.size} frequencies, {self.w.min():.4g} to {self.w.max():.4g} rad/s"
                f"{mag})")


def frequency_grid(loop: Loop | AltitudeLoop | DelayLTI, n: int = 500, *, wmin: float | None = None,
                   wmax: float | None = None) -> np.ndarray:
    """A logarithmic frequency grid (rad/s) that covers a loop's poles, zeros, crossovers and delay.

    From 1/100 of the lowest to 10 times the highest of: the magnitudes of the poles and zeros of ``L``
    (not 0), ``1/T`` and the gain crossovers; ``wmin``/``wmax`` replace either end.  A SISO
    :class:`~delaykit.systems.DelayLTI` open loop is taken as in :func:`frequency_response`.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> w = frequency_grid(AltitudeLoop(kp=1.31, delay=0.368), 5)
    >>> w.round(4).tolist()
    [0.0131, 0.0884, 0.5966, 4.0265, 27.1739]
    """
    sys = _system(loop)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise InvalidValueError(f"n (number of frequencies) must be an integer of at least 2, got {n!r:.40}")
    check_count("n (number of frequencies)", int(n), MAX_RESPONSE_POINTS, "frequencies")
    if sys is not None:
        from .system_margins import as_exact_loop, system_frequency_grid

        loop = as_exact_loop(_siso(sys, "frequency_grid"))
        if loop is None:
            w = system_frequency_grid(sys, int(n))
            lo = w[0] if wmin is None else check_real("wmin (rad/s)", wmin, minimum=0.0, strict=True)
            hi = w[-1] if wmax is None else check_real("wmax (rad/s)", wmax, minimum=0.0, strict=True)
            if not hi > lo:
                raise InvalidValueError(f"the frequency range is empty or reversed: wmin = {lo:g} rad/s must be "
                                        f"below wmax = {hi:g} rad/s")
            check_frequency_range(lo, hi, max(sys.delays, default=0.0))
            return np.geomspace(lo, hi, int(n))
    loop = _continuous(loop)
    if _compensated(loop):
        from .compensated import compensated_grid

        lo = None if wmin is None else check_real("wmin (rad/s)", wmin, minimum=0.0, strict=True)
        hi = None if wmax is None else check_real("wmax (rad/s)", wmax, minimum=0.0, strict=True)
        return compensated_grid(loop, int(n), wmin=lo, wmax=hi)
    ol = OpenLoop(loop)
    feats = [abs(r) for r in np.concatenate([ol.zr, ol.pr]) if abs(r) > 0]
    if ol.T > 0:
        feats.append(1.0 / ol.T)
    try:
        feats += list(gain_crossovers(ol))
    except InvalidValueError:  # |L| = 1 everywhere: no crossover to cover
        pass
    lo, hi = (min(feats) / 100, max(feats) * 10) if feats else (0.01, 100.0)
    lo = lo if wmin is None else check_real("wmin (rad/s)", wmin, minimum=0.0, strict=True)
    hi = hi if wmax is None else check_real("wmax (rad/s)", wmax, minimum=0.0, strict=True)
    if not hi > lo:
        raise InvalidValueError(f"the frequency range is empty or reversed: wmin = {lo:g} rad/s must be below "
                                f"wmax = {hi:g} rad/s")
    if wmin is not None or wmax is not None:  # (a range from the loop's own features is left as it is)
        check_frequency_range(lo, hi, ol.T)
    return np.geomspace(lo, hi, int(n))


def check_frequency_range(wmin: float, wmax: float, delay: float) -> None:
    """Refuse a frequency range wider than :data:`~delaykit.models.budget.MAX_FREQUENCY_DECADES` decades, or one
    that reaches frequencies where the delay's phase ``w T`` exceeds :data:`MAX_DELAY_PHASE` rad (there its
    rounding, ``w T`` times 1.1e-16, leaves fewer than four digits: the response would be noise).

    Examples
    --------
    >>> check_frequency_range(1e-3, 1e3, 0.37)
    >>> check_frequency_range(1e-300, 1e300, 0.0)
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: the frequency range 1e-300 to 1e+300 rad/s: 600 decades, above the limit of 24 (delaykit.models.budget.MAX_FREQUENCY_DECADES); give a narrower range
    """
    check_count(f"the frequency range {wmin:g} to {wmax:g} rad/s", math.log10(wmax) - math.log10(wmin),
                MAX_FREQUENCY_DECADES,
                "decades", "give a narrower range")
    if delay > 0 and wmax * delay > MAX_DELAY_PHASE:
        raise InvalidValueError(f"wmax {wmax:g} rad/s is too high for the delay {delay:g} s: its phase w T = "
                                f"{wmax * delay:.3g} rad exceeds {MAX_DELAY_PHASE:g} rad, where rounding leaves it "
                                f"no precision; give wmax at most {MAX_DELAY_PHASE / delay:.3g} rad/s")


def frequency_response(loop: Loop | AltitudeLoop | DelayLTI, w: Any = None) -> FrequencyResponse:
    """The exact loop transfer function ``L(jw) = Np Nc / (Dp Dc) (jw) exp(-jw T)`` at the frequencies ``w``.

    Parameters
    ----------
    loop : Loop, AltitudeLoop or DelayLTI
        A continuous loop (a sampled one raises :class:`~delaykit.errors.InvalidValueError`), or a SISO open loop
        ``L`` as a system (``C * G``), closed by unity negative feedback.  A system that is a rational function
        times one dead time is analysed as the equivalent :class:`Loop` (the phase exact, as above); any other
        one (several delays, a delay inside a loop) is evaluated exactly, its phase unwrapped along the sorted
        frequencies (:mod:`delaykit.spectrum.system_margins`).
    w : array_like, optional
        Frequencies in rad/s, finite and at least 0, in any order; by default :func:`frequency_grid`.

    Returns
    -------
    FrequencyResponse
        Vectorised: no Python loop over the frequencies.

    See Also
    --------
    margins : gain, phase and delay margins from the same ``L``.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> r = frequency_response(AltitudeLoop(kp=1.31, delay=0.368), [1.31])
    >>> round(float(r.magnitude[0]), 12), round(float(r.phase_deg[0]), 4)   # -90 - 1.31*0.368*180/pi
    (1.0, -117.6211)
    >>> from delaykit import tf
    >>> r = frequency_response(tf("1.31") * tf("exp(-0.368*s)/s"), [1.31])    # the same loop as a system
    >>> round(float(r.magnitude[0]), 12), round(float(r.phase_deg[0]), 4)
    (1.0, -117.6211)
    """
    sys = _system(loop)
    if sys is not None:
        from .system_margins import as_exact_loop, system_frequency_response

        sys = _siso(sys, "frequency_response")
        exact = as_exact_loop(sys)
        if exact is None:
            w = frequency_grid(sys) if w is None else _frequencies(w)
            return system_frequency_response(sys, w)
        loop = exact
    loop = _continuous(loop)
    w = frequency_grid(loop) if w is None else _frequencies(w)
    if _compensated(loop):
        from .compensated import compensated_response

        return compensated_response(loop, w)
    ol = OpenLoop(loop)
    L = ol.value(w)
    phi = ol.phase(w)
    with np.errstate(all="ignore"):
        ang = np.angle(L)
        snapped = ang + TWO_PI * np.round((phi - ang) / TWO_PI)
        phase = np.where(np.isfinite(L) & (L != 0), snapped, 0.0 if ol.zero else phi)
        mag_db = 20.0 * np.log10(np.abs(L))
    with np.errstate(over="ignore"):  # a phase beyond the floats in degrees (w T near 1e308): -inf
        phase_deg = np.degrees(phase)
    return FrequencyResponse(w=w, L=L, magnitude_db=mag_db, phase_deg=phase_deg)


# --------------------------------------------------------------------------------------------- margins
def _jsonable(x: Any) -> Any:
    """``x`` with every infinite or NaN float replaced by ``None`` (JSON's null), recursively."""
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


@dataclass(frozen=True, repr=False)
class Crossover:
    """One crossover of ``L(jw)`` and what it gives.

    ``kind`` is ``"gain"`` (``|L| = 1``) or ``"phase"`` (phase = -180 degrees modulo 360).  A gain crossover
    gives ``phase_margin`` (degrees, ``180 + phase`` taken in (-180, 180]) and ``delay_margin`` (the extra
    delay, s, that turns ``L(jw)`` onto -1 there: the phase lag to -180 modulo 360, in [0, 360), over ``w``).
    A phase crossover gives ``gain_margin = 1 / |L|`` (the gain factor that puts a root at ``jw``) and
    ``direction`` (+1 when the phase rises through -180, -1 when it falls: the sense in which the Nyquist
    curve crosses the negative real axis).  A phase crossover at ``frequency = inf`` is the limit of a
    biproper loop (``|L(j inf)| > 0``).
    """

    kind: str
    frequency: float
    magnitude: float
    phase_deg: float
    gain_margin: float | None = None
    phase_margin: float | None = None
    delay_margin: float | None = None
    direction: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (an infinite frequency is ``null``)."""
        return _jsonable({"kind": self.kind, "frequency": self.frequency, "magnitude": self.magnitude,
                          "phase_deg": self.phase_deg, "gain_margin": self.gain_margin,
                          "phase_margin": self.phase_margin, "delay_margin": self.delay_margin,
                          "direction": self.direction})

    def __repr__(self) -> str:
        if self.kind == "gain":
            return (f"Crossover(gain at {self.frequency:.6g} rad/s, phase {self.phase_deg:.4f} deg, "
                    f"PM {self.phase_margin:.4f} deg, DM {self.delay_margin:.6g} s)")
        return (f"Crossover(phase at {self.frequency:.6g} rad/s, |L| {self.magnitude:.6g}, "
                f"GM {self.gain_margin:.6g})")


@dataclass(frozen=True, repr=False)
class Margins:
    """Stability margins of a continuous delay loop (see :func:`margins` for the definitions).

    All margins are ``inf`` when nothing crosses, and ``nan`` when the closed loop is already unstable
    (``stable`` False: there is no stability to lose; the crossovers are still listed).  In :meth:`to_dict`
    both are ``null``.

    ``method`` says how the crossovers were found: ``"exact"`` (a rational loop times one delay: the gain
    crossovers are polynomial roots and the phase crossovers are listed up to a cut-off past which none can give
    a smaller margin, so :attr:`certified` is True) or ``"grid"`` (a loop with several delays, a delay inside a
    loop, or a compensator: a grid scan refined to machine precision, which can miss crossovers closer together
    than the grid's spacing).  Either way ``stable`` is the certified stability of the closed loop.  ``channel``
    is the channel opened, for the loop-at-a-time margins of a MIMO system (``None`` for a SISO loop).
    """

    gain_margin: float
    lower_gain_margin: float
    phase_margin: float
    delay_margin: float
    critical_delay: float
    crossover: float | None
    phase_crossover: float | None
    ms: float
    ms_frequency: float | None
    stable: bool
    open_loop_rhp_poles: int
    encirclements: int | None
    cutoff: float
    crossovers: tuple[Crossover, ...]
    stability_from: str = "roots"
    method: str = "exact"
    channel: int | None = None

    @property
    def certified(self) -> bool:
        """True when no crossover can have been missed (``method == "exact"``)."""
        return self.method == "exact"

    @property
    def gain_margin_db(self) -> float:
        """The gain margin in dB, ``20 log10(gain_margin)``."""
        g = self.gain_margin
        return g if not (math.isfinite(g) and g > 0) else 20.0 * math.log10(g)

    @property
    def nyquist_rhp_roots(self) -> int | None:
        """Closed-loop roots in the right half-plane by the Nyquist criterion, ``P - encirclements``."""
        return None if self.encirclements is None else self.open_loop_rhp_poles - self.encirclements

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form; infinite and NaN values become ``None`` (``null`` in JSON).

        Keys: ``gain_margin``, ``phase_margin``, ``delay_margin``, ``critical_delay``, ``crossover``, ``ms``,
        ``crossovers`` (a list of :meth:`Crossover.to_dict`), and also ``gain_margin_db``,
        ``lower_gain_margin``, ``phase_crossover``, ``ms_frequency``, ``stable``, ``open_loop_rhp_poles``,
        ``encirclements``, ``cutoff``, ``stability_from``, ``method``, ``certified`` and ``channel``.
        """
        return _jsonable({
            "gain_margin": self.gain_margin, "phase_margin": self.phase_margin, "delay_margin": self.delay_margin,
            "critical_delay": self.critical_delay, "crossover": self.crossover, "ms": self.ms,
            "crossovers": [c.to_dict() for c in self.crossovers],
            "gain_margin_db": self.gain_margin_db, "lower_gain_margin": self.lower_gain_margin,
            "phase_crossover": self.phase_crossover, "ms_frequency": self.ms_frequency, "stable": self.stable,
            "open_loop_rhp_poles": self.open_loop_rhp_poles, "encirclements": self.encirclements,
            "cutoff": self.cutoff, "stability_from": self.stability_from, "method": self.method,
            "certified": self.certified, "channel": self.channel})

    def __repr__(self) -> str:
        text = self._text()
        return text if self.channel is None else f"Margins(channel {self.channel}: {text[8:]}"

    def _text(self) -> str:
        if not self.stable:
            return (f"Margins(closed loop UNSTABLE, {sum(c.kind == 'gain' for c in self.crossovers)} gain and "
                    f"{sum(c.kind == 'phase' for c in self.crossovers)} phase crossovers)")
        if math.isinf(self.gain_margin):  # (no phase crossover gives one: phase_crossover is None)
            gm = "GM inf"
        else:
            at = "as w -> inf" if math.isinf(self.phase_crossover) else f"at {self.phase_crossover:.4g} rad/s"
            gm = f"GM {self.gain_margin:.4g} ({self.gain_margin_db:.4g} dB) {at}"
        if math.isinf(self.phase_margin):
            pm = "PM inf, DM inf"
        else:
            pm = (f"PM {self.phase_margin:.4g} deg at {self.crossover:.4g} rad/s, DM {self.delay_margin:.4g} s")
        return f"Margins({gm}, {pm}, Ms {self.ms:.4g}, stable)"


def _peak_sensitivity(ol: OpenLoop, pts: np.ndarray) -> tuple[float, float | None]:
    """``max |1 / (1 + L(jw))|`` over ``w >= 0`` and where it is (``None`` for a limit at w = 0 or infinity).

    The smallest ``|1 + L|`` on the points, then at each local minimum on them (the eight smallest) the root of
    ``d|1 + L|^2/dw = 2 Re(conj(1 + L) dL/dw)`` between the neighbouring points: Newton's method (with the exact
    second derivative) from the vertex of the parabola through the three points, safeguarded by the bracket
    (vectorised).
    """
    with np.errstate(all="ignore"):
        d = np.abs(1.0 + ol.value(pts))
    d = np.where(np.isfinite(d), d, np.inf)
    best, where = np.inf, None
    if d.size >= 3:
        k = 1 + np.flatnonzero((d[1:-1] <= d[:-2]) & (d[1:-1] <= d[2:]))
        k = k[np.argsort(d[k])][:8]

        def slope(w: np.ndarray) -> np.ndarray:
            L, dL = ol.slope(w)
            return ((1.0 + L).conj() * dL).real

        lo, mid, hi = pts[k - 1], pts[k], pts[k + 1]
        with np.errstate(all="ignore"):
            ok = (slope(lo) <= 0) & (slope(hi) >= 0)
            # first guess: the vertex of the parabola through the three points' |1 + L|^2
            y0, y1, y2 = d[k - 1] ** 2, d[k] ** 2, d[k + 1] ** 2
            num = (mid - lo) ** 2 * (y1 - y2) - (mid - hi) ** 2 * (y1 - y0)
            den = (mid - lo) * (y1 - y2) - (mid - hi) * (y1 - y0)
            v = mid - 0.5 * num / den
            v = np.where(np.isfinite(v) & (v > lo) & (v < hi), v, mid)
        at = newton_bracketed(ol.sensitivity_slope, lo[ok], hi[ok], v[ok], lambda x, i: slope(x))
        with np.errstate(all="ignore"):
            val = np.abs(1.0 + ol.value(at))
        for v, w in zip(val, at):
            if v < best:
                best, where = float(v), float(w)
    i = int(np.argmin(d))
    if d[i] < best:
        best, where = float(d[i]), float(pts[i])
    limits = []
    if ol.integrators <= 0:
        limits.append(abs(1.0 + ol.value(np.zeros(1))[0]))
    limits.append(1.0 - ol.l_inf if ol.T > 0 else abs(1.0 + ol.num[0] / ol.den[0] * (ol.l_inf > 0)))
    for v in limits:
        if v < best:
            best, where = float(v), None
    return (1.0 / best if best > 0 else math.inf), where


def _closed_loop_stable(loop: Loop) -> bool:
    """Stability from the exact characteristic roots: none in the closed right half-plane.

    The roots with ``Re s >= 0`` lie in ``[0, R] x [-R, R]`` (``R`` a root bound) and the argument principle counts
    them (:func:`~delaykit.spectrum.stability.right_half_plane_count`); where that cannot count (a root on the
    imaginary axis), the certified root finder searches ``[0, R] x [0, R]`` (the coefficients are real, so
    ``Im s >= 0`` suffices).  It runs
    in the time unit of the delay: ``Q(s)`` and ``Q(z / T)`` have the same roots up to the factor ``T > 0``, and
    with the delay scaled to 1 the region fits the loop's own time scale (a 12 s delay on a 150 s lag is
    searched in milliseconds, not seconds).  The caller has ruled out neutral chains at or right of the axis.
    If the count is not certified, :func:`~delaykit.spectrum.stability.rightmost` decides.
    """
    from ..models.quasipolynomial import QuasiPolynomial
    from .roots import find_roots, root_bound
    from .stability import _arrays, _rhp_count, rightmost

    if loop.structural_roots_kept():  # structural roots at 0 left in the quasi-polynomial: rightmost leaves them out
        return bool(rightmost(loop).stable)
    q = None
    if _compensated(loop):  # two delays (the plant's and the model's): the characteristic function's own arrays
        q = loop.characteristic()
        C, tau = _arrays(q)
        t = float(tau.max()) if tau.size else 0.0
    else:  # (built from L directly: no quasi-polynomial object on this fast path)
        num, den = loop.open_loop()
        t = loop.total_delay
        n1 = max(num.size, den.size)
        C = np.zeros((2, n1), complex)
        C[0, n1 - den.size:], C[1, n1 - num.size:] = den, num
        tau = np.array([0.0, t])
    if t > 0:
        C = C * t ** -np.arange(C.shape[1] - 1, -1, -1.0)
        tau = tau / t
    n = _rhp_count(C, tau)  # one boundary integral, usually
    if n is not None:
        return n == 0
    if q is None:
        q = loop.characteristic()
    if t > 0:
        polys = [[c * t ** -(len(p) - 1 - k) for k, c in enumerate(p)] for p in q.polys]
        q = QuasiPolynomial(polys, [d / t for d in q.delays])
    r = root_bound(q, 0.0)
    sp = find_roots(q, (0.0, r, 0.0, r))
    if sp.certified:
        return sp.roots.size == 0
    return bool(rightmost(q).stable)


def margins(loop: Loop | AltitudeLoop | DelayLTI) -> Margins | tuple[Margins, ...]:
    """Gain, phase and delay margins, peak sensitivity and every crossover of a continuous delay loop.

    Definitions (``L`` as in the module docstring; ``phi`` its unwrapped phase):

    * ``gain_margin``: the smallest factor ``k > 1`` on the loop gain at which the closed loop loses stability.
      Roots of ``1 + k L`` reach the imaginary axis only at a phase crossover, with ``k = 1/|L|``, so it is the
      smallest ``1/|L|`` above 1 among the phase crossovers (including ``w = 0`` when ``L(0) < 0``, and
      ``1/|L(j inf)|`` for a biproper loop); ``lower_gain_margin`` is the largest such factor below 1 (``0``
      if none: lowering the gain never destabilises).  ``gain_margin_db`` is ``20 log10`` of it.
    * ``phase_margin`` (degrees): ``180 + phi`` (taken in (-180, 180]) at the gain crossover where it is
      smallest in size; negative means that a phase *lead* of that size reaches -1.
    * ``delay_margin`` (s): the extra delay that first puts a root on the imaginary axis, the minimum over the
      gain crossovers ``wc`` of ``PM / wc`` with ``PM`` the phase lag to -180 degrees in [0, 2 pi);
      ``crossover`` is that ``wc``, and ``critical_delay = loop.total_delay + delay_margin``.
    * ``ms``: the peak of ``|S(jw)| = 1/|1 + L(jw)|``, refined around the best grid points by solving
      ``d|1 + L|/dw = 0`` between their neighbours (``ms_frequency``; ``None`` when the peak is a limit at
      ``w = 0`` or ``w -> inf``).

    Stability comes from the exact characteristic roots of ``loop.characteristic()``, which also see modes that
    cancel in ``L``: none may lie in the closed right half-plane, where the certified root finder counts them
    (:func:`~delaykit.spectrum.stability.rightmost` decides if that count is not certified).  A biproper loop
    with a delay and ``|L(j inf)| >= 1`` is neutral with root chains at or right of the imaginary axis
    (``Re s -> ln|L(j inf)| / T``), so unstable.  ``stability_from`` says which: ``"roots"``,
    ``"neutral chains"``, or ``"nyquist"`` when the root search could not run and the Nyquist count below
    decided.  When the closed loop is unstable the margins are ``nan``.  The margins are also right for
    open-loop unstable loops: they are the factors and delays at which roots cross the imaginary axis, starting
    from a stable loop.

    Nyquist count: ``open_loop_rhp_poles`` (``P``) counts the poles of ``L`` with ``Re s > 0``; poles on the
    imaginary axis (integrators) are indented around on the right and not counted.  ``encirclements`` is the
    number of *counterclockwise* encirclements of -1 by ``L`` along that contour, counted as signed crossings
    of the negative real axis left of -1: twice each phase crossover with ``|L| > 1`` at ``w > 0`` (the curve
    and its mirror image), with the sign of ``d phi / dw``; the arcs at infinity around poles on the axis
    (clockwise, ``n`` half-turns for ``n`` poles); and the points ``w = 0`` and ``w = inf``, where the curve
    meets its mirror image.  A crossing exactly at an end is decided by turning the axis by a vanishing angle.
    Then ``P - encirclements`` (``nyquist_rhp_roots``) is the number of closed-loop roots in the right
    half-plane, which is 0 exactly when the loop is stable.  It is ``None`` when -1 lies on the curve (a
    closed-loop root on the imaginary axis) and for a loop with ``|L(j inf)| >= 1`` and a delay (a neutral loop
    whose root chains reach the imaginary axis).

    Phase crossovers are listed up to ``cutoff`` (rad/s, see the module docstring).

    A :class:`~delaykit.systems.DelayLTI` is taken as the open loop ``L`` of ``feedback(L, I)`` (python-control's
    convention): a SISO ``L`` that is a rational function times one dead time gets the margins of the equivalent
    unity-feedback :class:`Loop` (``method == "exact"``); any other one gets margins from a refined grid scan
    (``method == "grid"``, :attr:`Margins.certified` False), with the closed loop's stability still certified.
    A square MIMO ``L`` gets a tuple of loop-at-a-time margins, one per channel (channel ``k`` opened, the others
    closed).  See :mod:`delaykit.spectrum.system_margins`.

    Raises
    ------
    InvalidValueError
        For a sampled loop (its margins come from :mod:`delaykit.spectrum.sampled`), and when ``|L(jw)| = 1`` at
        every frequency (an all-pass loop of unit gain), where every frequency is a gain crossover and the
        phase and delay margins are undefined.

    See Also
    --------
    frequency_response : ``L(jw)`` itself.
    delaykit.spectrum.stability.delay_margin : the delay margin from zero delay, from the quasi-polynomial.

    References
    ----------
    .. [1] K. J. Astrom and R. M. Murray, *Feedback Systems*, 2nd ed., Princeton University Press, 2021,
       sections 10.2-10.3 (the Nyquist criterion and stability margins).
    .. [2] K. Gu, V. L. Kharitonov and J. Chen, *Stability of Time-Delay Systems*, Birkhauser, 2003, ch. 2
       (crossing frequencies and the delay margin).

    Examples
    --------
    >>> from delaykit import Controller, Loop
    >>> m = margins(Loop("1/(s-1)", Controller.p(2.0), delay=0.1))   # open-loop unstable, stable closed loop
    >>> m.stable, m.open_loop_rhp_poles, m.encirclements, round(m.lower_gain_margin, 6)
    (True, 1, 1, 0.5)
    >>> from delaykit import tf
    >>> margins(tf("2") * tf("exp(-0.1*s)/(s-1)")) == m          # the same loop as a system C * G
    True
    >>> margins(tf("3*exp(-s)/(s-1)")).stable                  # no margins: the closed loop is unstable
    False
    """
    sys = _system(loop)
    if sys is not None:
        from .system_margins import system_margins

        return system_margins(sys)
    loop = _continuous(loop)
    if _compensated(loop):
        from .compensated import compensated_margins

        return compensated_margins(loop)
    ol = OpenLoop(loop)
    gains = gain_crossovers(ol)
    w_hi, w_m = cutoff_frequency(ol, gains)
    for _ in range(20):
        grid = dense_grid(ol, gains, w_hi)
        extra = gain_crossovers(ol, grid, gains)  # the grid's net may add crossovers the polynomial missed
        if extra.size > gains.size:
            gains = extra
            grid = dense_grid(ol, gains, w_hi)
        if ol.zero:  # L = 0: no crossover and no encirclement
            scan = PhaseScan([], 0, grid)
            break
        scan = scan_phase(ol, grid, w_hi)
        if ol.T == 0 or any(c[0] > w_m for c in scan.crossings):
            break
        w_hi *= 2.0
    crossovers: list[Crossover] = []
    for w in map(float, gains):
        phi = float(ol.phase(np.array([w]))[0])
        lag = (phi + math.pi) % TWO_PI
        pm = math.degrees(lag if lag <= math.pi else lag - TWO_PI)
        crossovers.append(Crossover("gain", w, 1.0, math.degrees(phi), phase_margin=pm,
                                    delay_margin=lag / w))
    for w, mag, phi, direction in scan.crossings:
        crossovers.append(Crossover("phase", w, mag, math.degrees(phi),
                                    gain_margin=(1.0 / mag if mag > 0 else math.inf), direction=direction))
    ui = ol.phase_at_infinity() / math.pi
    if ol.l_inf > 0 and (ol.T > 0 or snap_half_turns(np.array([ui]))[0] % 2 == 1):
        with np.errstate(over="ignore"):  # |L| at infinity of 1e-320: a gain margin beyond the floats, inf
            gm_inf = float(np.float64(1.0) / ol.l_inf)
        crossovers.append(Crossover("phase", math.inf, ol.l_inf, math.nan if ol.T > 0 else math.degrees(ui * math.pi),
                                    gain_margin=gm_inf))
    crossovers.sort(key=lambda c: (c.frequency, c.kind))
    ccw = scan.ccw
    l0 = ol.value(np.zeros(1))[0] if ol.integrators <= 0 else math.inf
    if any(min(c.delay_margin * c.frequency, TWO_PI - c.delay_margin * c.frequency) < 1e-12 for c in crossovers
           if c.kind == "gain") or abs(l0 + 1) < 1e-12:
        ccw = None  # -1 lies on the Nyquist curve: a closed-loop root on the imaginary axis, no count
    p_rhp = int(np.sum(ol.pr.real > 0))
    if ol.T > 0 and ol.l_inf >= 1.0:  # neutral, with root chains approaching Re s = ln|L(j inf)| / T >= 0
        stable, source = False, "neutral chains"
    else:
        try:
            stable, source = _closed_loop_stable(loop), "roots"
        except (MemoryError, InvalidValueError):
            # the root search gave up (a neutral loop whose roots all crowd its neutral line can exhaust it):
            # the Nyquist count decides, P - encirclements = 0
            if ccw is None:
                raise
            stable, source = p_rhp - ccw == 0, "nyquist"
    return _assemble(loop.total_delay, crossovers, stable=stable, source=source, open_loop_rhp_poles=p_rhp,
                     encirclements=ccw, cutoff=w_hi, peak=lambda: _peak_sensitivity(ol, np.unique(np.concatenate(
                         [scan.grid, gains, [c[0] for c in scan.crossings]]))))


def _assemble(total_delay: float, crossovers: list[Crossover], *, stable: bool, source: str,
              open_loop_rhp_poles: int, encirclements: int | None, cutoff: float, peak: Any,
              method: str = "exact") -> Margins:
    """The :class:`Margins` from the crossovers (see :func:`margins` for the definitions); ``peak()`` gives
    ``(Ms, where)`` and is called only for a stable loop; ``total_delay`` (s) is the loop's own delay.  Shared with
    :mod:`delaykit.spectrum.compensated` and :mod:`delaykit.spectrum.system_margins`."""
    crossovers = sorted(crossovers, key=lambda c: (c.frequency, c.kind))
    if not stable:
        nan = math.nan
        return Margins(nan, nan, nan, nan, nan, None, None, nan, None, False, open_loop_rhp_poles, encirclements,
                       cutoff, tuple(crossovers), source, method)
    up = [c for c in crossovers if c.kind == "phase" and c.gain_margin >= 1.0]
    gm = min((c.gain_margin for c in up), default=math.inf)
    gm_c = next((c for c in up if c.gain_margin <= gm * (1 + 1e-9)), None)  # the lowest frequency of a tie
    low = [c.gain_margin for c in crossovers if c.kind == "phase" and c.gain_margin < 1.0]
    g_cross = [c for c in crossovers if c.kind == "gain"]
    if g_cross:
        dm_c = min(g_cross, key=lambda c: c.delay_margin)
        pm = min((c.phase_margin for c in g_cross), key=abs)
        dm, wc = dm_c.delay_margin, dm_c.frequency
    else:
        pm, dm, wc = math.inf, math.inf, None
    ms, ms_w = peak()
    return Margins(gain_margin=gm, lower_gain_margin=max(low, default=0.0),
                   phase_margin=pm, delay_margin=dm, critical_delay=total_delay + dm, crossover=wc,
                   phase_crossover=gm_c.frequency if gm_c else None, ms=ms, ms_frequency=ms_w, stable=True,
                   open_loop_rhp_poles=open_loop_rhp_poles, encirclements=encirclements, cutoff=cutoff,
                   crossovers=tuple(crossovers), stability_from=source, method=method)
