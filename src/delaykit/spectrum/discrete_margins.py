"""Gain, phase and delay margins of sampled loops, from their exact discrete-time model (:mod:`.sampled`).

The loop is broken at the plant's input: ``L(e^{j w h})`` is the response from the plant's held input back to
it, the gain margin the factor on the plant's input and the delay margin the extra delay on the way to the plant
that bring a pole to the unit circle.  Without a compensator that is the loop broken at the held command (the
same ``L``).  With one (a Smith predictor, predictor feedback: :mod:`delaykit.models.compensators`) the
compensator's model still reads the unscaled command and keeps its own delay, as in the continuous compensated
margins (:mod:`.compensated`): the gain margin is the plant-to-model gain ratio and the delay margin the error of
the model's delay that reach instability, each on the sampled loop.

Every margin is a crossing of the unit circle by the loop's poles, found on the exact transition matrix
(:meth:`~delaykit.spectrum.sampled.SampledModel.poles`: a compensator's structural eigenvalues at 1, which no
gain or plant delay moves, are separated exactly and never count), and the phase margin and the crossovers
come from ``L``.

Examples
--------
>>> from delaykit.models import Loop
>>> from delaykit.models.compensators import Compensator
>>> smith = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)       # continuous: GM 2.578, PM 64.19, DM 0.623 s
>>> sampled_margins(Loop("1/s", smith, delay=0.37, period=0.065))
SampledMargins(gain 2.4058, phase 62.97 deg at 1.8064 rad/s, delay 0.6073 s (critical 0.9773 s), Ms 1.7299, stable)
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from ..errors import InvalidValueError
from ..models.altitude import AltitudeLoop
from ..models.loop import Loop
from .frequency import _jsonable
from .sampled import MAX_ORDER, SampledModel, _response, _sampled_loop, sampled_model, sampled_spectrum
from .stability import delay_margin as _continuous_delay_margin
from .stability import rightmost

__all__ = ["SampledCrossover", "SampledMargins", "SamplingComparison", "sampled_margins", "compare_sampling"]

_GAIN_SCAN_MAX = 1e6
_MARGINAL = 1e-4  # open-loop poles this close to z = 1 are integrators split by rounding


@dataclass(frozen=True, repr=False)
class SampledCrossover:
    """A crossover of the discrete open loop ``L(e^{j w h})``: ``kind`` ``"gain"`` (``|L| = 1``) or ``"phase"``
    (``L`` real and negative: the Nyquist curve crosses the negative real axis), with the value ``L`` there.
    """

    kind: str
    frequency: float
    value: complex

    @property
    def magnitude(self) -> float:
        """``|L|`` at the crossover."""
        return abs(self.value)

    @property
    def phase_deg(self) -> float:
        """``arg L`` in degrees, in (-180, 180]."""
        return math.degrees(cmath.phase(self.value))

    @property
    def phase_margin(self) -> float | None:
        """``180 + arg L`` in (-180, 180] degrees, at a gain crossover (else ``None``)."""
        return math.degrees(cmath.phase(-self.value)) if self.kind == "gain" else None

    @property
    def gain_margin(self) -> float | None:
        """``1 / |L|``, the factor that puts a pole on the unit circle there, at a phase crossover."""
        return 1.0 / abs(self.value) if self.kind == "phase" and self.value != 0 else None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the keys of the continuous crossovers, without their delay margin and direction)."""
        return _jsonable({"kind": self.kind, "frequency": self.frequency, "magnitude": self.magnitude,
                          "phase_deg": self.phase_deg, "gain_margin": self.gain_margin,
                          "phase_margin": self.phase_margin})

    def __repr__(self) -> str:
        if self.kind == "gain":
            return f"SampledCrossover(gain at {self.frequency:.6g} rad/s, PM {self.phase_margin:.4f} deg)"
        return f"SampledCrossover(phase at {self.frequency:.6g} rad/s, |L| {self.magnitude:.6g})"


@dataclass(frozen=True, repr=False)
class SampledMargins:
    """Stability margins of a sampled loop (see :func:`sampled_margins` for how each is found).

    ``gain_margin``: the factor above 1 on the loop gain (on the plant's input, with a compensator) that puts a
    pole on the unit circle (``inf`` if none up to 1e6); ``lower_gain_margin``: the factor below 1 that does
    (``0`` if lowering the gain never destabilises the loop; positive when the open loop is unstable, or the
    loop only conditionally stable); ``phase_margin`` (degrees) at the gain crossover ``crossover`` (rad/s)
    where it is smallest;
    ``delay_margin``: the extra continuous delay that reaches instability, ``critical_delay`` the total delay
    there; ``ms``: the largest sensitivity ``max |1 / (1 + L)|``; ``crossovers``: the gain and phase
    crossovers in ``(0, pi/h]``.  As for continuous loops, margins are ``inf`` when nothing crosses and
    ``nan`` when the closed loop is already unstable (the crossovers are still listed); both are ``null``
    in :meth:`to_dict`.
    """

    gain_margin: float
    phase_margin: float
    delay_margin: float
    critical_delay: float
    crossover: float | None
    ms: float
    crossovers: tuple[SampledCrossover, ...]
    stable: bool
    lower_gain_margin: float = 0.0

    @property
    def gain_crossovers(self) -> tuple[float, ...]:
        """Frequencies (rad/s) where ``|L| = 1``."""
        return tuple(c.frequency for c in self.crossovers if c.kind == "gain")

    @property
    def gain_margin_db(self) -> float:
        """The gain margin in dB, ``20 log10(gain_margin)``."""
        g = self.gain_margin
        return g if not (math.isfinite(g) and g > 0) else 20.0 * math.log10(g)

    @property
    def phase_crossover(self) -> float | None:
        """The phase crossover (rad/s) whose factor ``1 / |L|`` is the gain margin (``None`` if none is)."""
        return next((c.frequency for c in self.crossovers if c.kind == "phase" and c.gain_margin is not None
                     and abs(c.gain_margin - self.gain_margin) <= 1e-6 * self.gain_margin), None)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: keys ``gain_margin``, ``phase_margin``, ``delay_margin``, ``critical_delay``,
        ``crossover``, ``ms``, ``crossovers`` (a list of :meth:`SampledCrossover.to_dict`), ``stable``,
        ``lower_gain_margin``, ``gain_margin_db`` and ``phase_crossover`` (the keys of the continuous
        :meth:`~delaykit.spectrum.frequency.Margins.to_dict` that a sampled loop has); infinite and NaN values are
        ``None``."""
        return _jsonable({"gain_margin": self.gain_margin, "phase_margin": self.phase_margin,
                          "delay_margin": self.delay_margin, "critical_delay": self.critical_delay,
                          "crossover": self.crossover, "ms": self.ms,
                          "crossovers": [c.to_dict() for c in self.crossovers], "stable": self.stable,
                          "lower_gain_margin": self.lower_gain_margin, "gain_margin_db": self.gain_margin_db,
                          "phase_crossover": self.phase_crossover})

    def __repr__(self) -> str:
        if not self.stable:
            return (f"SampledMargins(closed loop UNSTABLE, {len(self.gain_crossovers)} gain and "
                    f"{len(self.crossovers) - len(self.gain_crossovers)} phase crossovers)")
        w = "" if self.crossover is None else f" at {self.crossover:.4f} rad/s"
        low = f" (lower {self.lower_gain_margin:.4f})" if self.lower_gain_margin > 0 else ""
        return (f"SampledMargins(gain {self.gain_margin:.4f}{low}, phase {self.phase_margin:.2f} deg{w}, delay "
                f"{self.delay_margin:.4f} s (critical {self.critical_delay:.4f} s), Ms {self.ms:.4f}, stable)")


def _turns(mdl: SampledModel) -> int:
    """Whole periods of the longest delay in ``L``: the plant's, or a compensator's model's."""
    return max(mdl.whole_periods, mdl.n_held - 1)


def _grid(h: float, m: int) -> np.ndarray:
    wn = math.pi / h
    n = min(2000 + 64 * (m + 1), 200_000)
    w = np.unique(np.r_[np.geomspace(1e-6 * wn, wn, n // 2), np.linspace(wn / n, wn, n)])
    return w[w <= wn]


def _sign_changes(w: np.ndarray, y: np.ndarray, fun: Any) -> list[float]:
    out = []
    idx = np.nonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)[0]
    for i in idx:
        out.append(float(brentq(fun, w[i], w[i + 1], xtol=1e-14 * w[i + 1], rtol=1e-15)))
    out.extend(float(w[i]) for i in np.nonzero(y == 0.0)[0])
    return sorted(out)


def _first_crossing(fun: Any, xs: np.ndarray, x0: float) -> float:
    """The first ``x`` in the scan ``xs`` (after ``x0``, where ``fun < 0``) with ``fun(x) >= 0``, refined."""
    prev = x0
    for x in xs:
        if fun(x) >= 0.0:
            return float(brentq(fun, prev, x, xtol=1e-13 * max(1.0, abs(x)), rtol=1e-14))
        prev = x
    return math.inf


def sampled_margins(loop: Loop | AltitudeLoop) -> SampledMargins:
    """Gain, phase and delay margins of a sampled loop, from its exact discrete-time model.

    The loop is broken at the plant's input (without a compensator, the same as at the held command); ``L`` is
    :func:`~delaykit.spectrum.sampled.sampled_frequency_response` and the poles are
    :meth:`~delaykit.spectrum.sampled.SampledModel.poles` (a compensator's structural eigenvalues at 1 excluded).

    * gain margin (upward): the loop gain is scaled by ``g`` (:meth:`SampledModel.closed
      <delaykit.spectrum.sampled.SampledModel.closed>`: the command, or with a compensator the plant's input
      only, its model still reading the unscaled command) and the spectral radius is scanned upwards from
      ``g = 1`` (a geometric grid up to 1e6, plus the factors ``-1/L`` at every crossing of the negative real
      axis by the discrete Nyquist curve, where a pole can reach the unit circle), the first crossing of 1
      refined by Brent's method;
    * lower gain margin: the same scan downwards from ``g = 1`` to ``1e-6`` (then to 0, when the open loop is
      unstable and the radius has not yet crossed 1), ``0`` when the radius stays below 1;
    * phase margin: ``180 + arg L`` in degrees at each gain crossover ``|L(e^{j w h})| = 1``, the smallest;
    * delay margin: extra continuous delay on the way to the plant (with a compensator the true delay grows and
      the model's stays), scanned from 0 in steps of ``0.1 / w_max`` up to ``2 (2 pi / w_min) + 4 h``
      (``w_min``, ``w_max`` the lowest and highest gain crossovers), the first radius crossing of 1 refined by
      Brent's method.  Without any gain crossover, at the nominal delay and at extra delays of h/4, h/2 and
      3h/4, and with a stable open loop, the loop is taken as stable for every delay (``|L| < 1``: the
      small-gain argument); else the scan goes up to ``20 (T + h)``.  ``inf`` when no crossing is found;
    * ``ms``: the maximum of ``|1 / (1 + L)|`` on a dense grid, refined.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A loop with ``period`` set; any controller, a delay compensator included.

    Returns
    -------
    SampledMargins

    Raises
    ------
    InvalidValueError
        For a continuous loop, or when the lifted state would exceed
        :data:`~delaykit.spectrum.sampled.MAX_ORDER` (also while adding delay for the delay margin).

    See Also
    --------
    delaykit.spectrum.sampled.sampled_frequency_response, delaykit.spectrum.sampled.sampled_spectrum,
    compare_sampling, delaykit.spectrum.compensated.compensated_margins : the continuous compensated loop's.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> sampled_margins(AltitudeLoop(kp=1.0, delay=0.1, period=0.1))   # z^2 - z + g Kp h: g = 1 / (Kp h)
    SampledMargins(gain 10.0000, phase 81.40 deg at 1.0004 rad/s, delay 1.4215 s (critical 1.5215 s), Ms 1.1446, stable)

    A Smith predictor with a model delay 25 % short: the gain margin is the plant-to-model gain ratio, the
    critical delay the true delay, that reach instability.

    >>> from delaykit.models import Loop
    >>> from delaykit.models.compensators import Compensator
    >>> m = sampled_margins(Loop("1/s", Compensator.smith("1/s", 0.37, closed_loop_time=0.2), delay=0.4625,
    ...                          period=0.065))
    >>> round(m.gain_margin, 4), round(m.critical_delay, 4)
    (2.088, 0.9773)
    """
    lp = _sampled_loop(loop, "sampled_margins")
    mdl = sampled_model(lp)
    h = mdl.period
    stable = mdl.radius() < 1.0
    w = _grid(h, _turns(mdl))
    L = _response(mdl, w)
    resp = lambda x: complex(_response(mdl, np.array([x]))[0])  # noqa: E731
    # gain crossovers and the phase margin
    with np.errstate(divide="ignore"):
        logmag = np.log(np.abs(L))
    gains = _sign_changes(w, logmag, lambda x: math.log(abs(resp(x))))
    pms = [(math.degrees(cmath.phase(-resp(x))), x) for x in gains]
    pm, wc = min(pms) if pms else (math.inf, None)
    # phase crossovers: L real and negative (sign changes of Im L where Re L < 0, and w = pi / h)
    imL = L.imag
    phases = []
    for x in _sign_changes(w, np.where(np.isfinite(imL), imL, 0.0), lambda x: resp(x).imag) + [float(w[-1])]:
        v = resp(x)
        if math.isfinite(abs(v)) and v.real < 0 and abs(v.imag) <= 1e-9 * abs(v):
            phases.append(x)
    crossings = sorted([SampledCrossover("gain", x, resp(x)) for x in gains]
                       + [SampledCrossover("phase", x, resp(x)) for x in phases], key=lambda c: c.frequency)
    # the largest sensitivity
    S = np.abs(1.0 + L)
    i = int(np.argmin(S))
    lo, hi = w[max(i - 1, 0)], w[min(i + 1, w.size - 1)]
    smin = S[i]
    if hi > lo:
        r = minimize_scalar(lambda x: abs(1.0 + resp(x)), bounds=(lo, hi), method="bounded",
                            options={"xatol": 1e-12 * hi})
        smin = min(smin, float(r.fun))
    ms = math.inf if smin == 0.0 else 1.0 / float(smin)
    if not stable:
        nan = math.nan
        return SampledMargins(nan, nan, nan, nan, wc, ms, tuple(crossings), False)
    # gain margin: the radius of A + g B K as g grows; a pole can reach the unit circle only where g L = -1
    cands = [g for g in (-1.0 / resp(x).real for x in phases) if 1.0 < g < _GAIN_SCAN_MAX]
    gs = np.unique(np.r_[np.geomspace(1.0, _GAIN_SCAN_MAX, 121)[1:], [g * (1 + 1e-9) for g in cands],
                         [g * (1 - 1e-9) for g in cands]])
    gm = _first_crossing(lambda g: mdl.radius(g) - 1.0, gs, 1.0)
    with np.errstate(all="ignore"):  # (infinite at an integrator)
        at_one = complex(_response(mdl, np.zeros(1))[0])  # L at z = 1, where a real pole can cross
    low = _lower_gain_margin(mdl, [-1.0 / v.real for v in [resp(x) for x in phases] + [at_one]
                                   if math.isfinite(v.real) and v.real < 0.0])
    # delay margin: the radius as extra delay is added
    dm = _delay_margin(lp, h, tuple(gains), mdl)
    return SampledMargins(gm, pm, dm, mdl.total_delay + dm, wc, ms, tuple(crossings), True, low)


def _lower_gain_margin(mdl: SampledModel, factors: list[float]) -> float:
    """The largest gain factor below 1 at which a pole reaches the unit circle (0 if none), scanning ``1 / g``
    upwards from 1 (a geometric grid to 1e6 and the factors ``-1/L`` of the phase crossings and ``z = 1``), then
    down to ``g = 0`` when the open loop itself is unstable."""
    def fun(t: float) -> float:
        return mdl.radius(1.0 / t) - 1.0

    cands = [1.0 / g for g in factors if math.isfinite(g) and 0.0 < g < 1.0]
    ts = np.unique(np.r_[np.geomspace(1.0, _GAIN_SCAN_MAX, 121)[1:], [t * (1 + 1e-9) for t in cands],
                         [t * (1 - 1e-9) for t in cands]])
    t = _first_crossing(fun, ts[ts > 1.0], 1.0)
    if math.isfinite(t):
        return 1.0 / t
    g_min = 1.0 / _GAIN_SCAN_MAX
    # integrators put open-loop poles at z = 1, which rounding splits when they are repeated (by ~1e-8 for two,
    # ~1e-5 for three): those are on the unit circle, not unstable
    z0 = mdl.poles(0.0)
    unstable = (np.abs(z0) > 1.0 + 1e-12) & (np.abs(z0 - 1.0) > _MARGINAL)
    if unstable.any() and mdl.radius(g_min) < 1.0:
        return float(brentq(lambda g: mdl.radius(g) - 1.0, 0.0, g_min, xtol=1e-300, rtol=1e-14))
    return 0.0


def _delay_margin(lp: Loop, h: float, crossovers: tuple[float, ...], mdl: SampledModel) -> float:
    def rad(extra: float) -> float:
        return sampled_model(lp.replace(delay=lp.delay + extra)).radius() - 1.0

    if crossovers:
        step = 0.1 / max(crossovers)  # a tenth of a radian of phase at the highest crossover (>= h / (10 pi))
        cap = 2.0 * (2.0 * math.pi / min(crossovers)) + 4.0 * h
    else:
        # no gain crossover: if none appears at other fractions of extra delay either and the open loop is
        # stable, |L| < 1 on the unit circle for every extra delay and the loop is stable for all of them
        fracs = [h * k / 4.0 for k in (1, 2, 3)]
        w = _grid(h, _turns(mdl))
        crossing = any(np.any(np.abs(_response(sampled_model(lp.replace(delay=lp.delay + d)), w)) >= 1.0)
                       for d in fracs)
        if not crossing and mdl.radius(0.0) < 1.0:
            return math.inf
        step = h / 8.0
        cap = 20.0 * (mdl.total_delay + h)
    room = (MAX_ORDER - mdl.order - 1) * h  # the lifted state grows by one held command per period of delay
    xs = np.arange(1, int(math.ceil(min(cap, room) / step)) + 1) * step
    dm = _first_crossing(rad, xs, 0.0)
    if math.isinf(dm) and room < cap:
        raise InvalidValueError(
            f"the delay margin search reached {MAX_ORDER} lifted states (extra delay {room:g} s at the period "
            f"{h:g} s) without finding instability; use a longer period")
    return dm


# -- sampled against continuous --------------------------------------------------------------------------------
@dataclass(frozen=True, repr=False)
class SamplingComparison:
    """A sampled loop beside the same loop with a continuous controller (``period=None``).

    ``radius`` and ``rate = log(radius) / h`` (1/s) of the sampled loop against the continuous spectral
    abscissa ``abscissa``; the sampled margins (``sampled``) against the continuous loop's extra-delay margin
    ``continuous_delay_margin`` and critical total delay ``continuous_critical_delay`` (exact, from the
    crossing frequencies, or for a compensated loop the compensated margins; ``nan`` when the continuous loop
    is unstable, as the sampled margins are then).
    """

    period: float
    total_delay: float
    radius: float
    rate: float
    abscissa: float
    sampled: SampledMargins
    continuous_delay_margin: float
    continuous_critical_delay: float
    continuous_stable: bool

    @property
    def delay_margin_lost(self) -> float:
        """Continuous minus sampled delay margin, s (about ``h / 2`` for a slow loop: the hold's lag)."""
        return self.continuous_delay_margin - self.sampled.delay_margin

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (infinite and NaN values are ``None``)."""
        return _jsonable({"period": self.period, "total_delay": self.total_delay, "radius": self.radius,
                          "rate": self.rate, "abscissa": self.abscissa, "sampled": self.sampled.to_dict(),
                          "continuous_delay_margin": self.continuous_delay_margin,
                          "continuous_critical_delay": self.continuous_critical_delay,
                          "continuous_stable": self.continuous_stable, "sampled_stable": self.sampled.stable,
                          "delay_margin_lost": self.delay_margin_lost})

    def __repr__(self) -> str:
        return (f"SamplingComparison(h={self.period:g} s: rate {self.rate:.4f}/s vs abscissa {self.abscissa:.4f}/s; "
                f"delay margin {self.sampled.delay_margin:.4f} s vs {self.continuous_delay_margin:.4f} s; "
                f"{'stable' if self.sampled.stable else 'UNSTABLE'} sampled, "
                f"{'stable' if self.continuous_stable else 'UNSTABLE'} continuous)")


def _continuous_extra_margin(cont: Loop, stable: bool) -> float:
    """Extra delay before the continuous loop's first crossing past its own delay (it is stable there)."""
    if not stable:
        return math.nan
    if cont.controller.realisation().reads_command:  # a compensator: extra true delay, the model's unchanged
        from .frequency import margins

        return float(margins(cont).delay_margin)
    T = cont.total_delay
    dm = _continuous_delay_margin(cont.characteristic())
    if math.isinf(dm.delay):
        return math.inf
    nxt = []
    for w, tau in dm.crossings:
        per = 2.0 * math.pi / w
        k = max(0, math.ceil((T - tau) / per - 1e-12))
        nxt.append(tau + k * per)
    return (min(nxt) - T) if nxt else dm.delay - T


def compare_sampling(loop: Loop | AltitudeLoop) -> SamplingComparison:
    """The sampled loop's spectral radius and margins beside those of the same loop sampled continuously.

    For a loop with a delay compensator the continuous delay margin is the exact compensated one
    (:func:`~delaykit.spectrum.compensated.compensated_margins`: extra true delay, the model's unchanged), as the
    sampled one is.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A loop with ``period`` set; its continuous counterpart is ``loop.replace(period=None)``.

    Returns
    -------
    SamplingComparison

    Raises
    ------
    InvalidValueError
        For a continuous loop (see :func:`sampled_margins`).

    See Also
    --------
    sampled_margins, delaykit.spectrum.stability.rightmost, delaykit.spectrum.stability.delay_margin

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> c = compare_sampling(AltitudeLoop(kp=1.31, delay=0.368, period=0.065))
    >>> round(c.sampled.delay_margin, 4), round(c.continuous_delay_margin, 4)
    (0.7984, 0.8311)
    >>> from delaykit.models import Controller, Loop
    >>> from delaykit.models.compensators import Compensator
    >>> smith = Compensator.smith("1/s", 0.368, primary=Controller.p(1.31))     # the same P loop, compensated
    >>> c = compare_sampling(Loop("1/s", smith, delay=0.368, period=0.065))
    >>> round(c.sampled.delay_margin, 4), round(c.continuous_delay_margin, 4)
    (1.4375, 1.461)
    """
    lp = _sampled_loop(loop, "compare_sampling")
    spec = sampled_spectrum(lp)
    margins = sampled_margins(lp)
    cont = lp.replace(period=None, sample_offset=0.0)
    rm = rightmost(cont)
    extra = _continuous_extra_margin(cont, rm.stable)
    rate = math.log(spec.radius) / spec.period if spec.radius > 0 else -math.inf
    return SamplingComparison(period=spec.period, total_delay=lp.total_delay, radius=spec.radius, rate=rate,
                              abscissa=rm.abscissa, sampled=margins, continuous_delay_margin=extra,
                              continuous_critical_delay=lp.total_delay + extra, continuous_stable=rm.stable)
