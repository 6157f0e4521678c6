"""The jitter margin: how much a delay may vary, arbitrarily fast, before stability is no longer guaranteed.

A continuous loop with the constant delay ``Tmin`` (its total delay) has the loop transfer function ``L(s)``
(:mod:`delaykit.spectrum.frequency`, the delay included) and the complementary sensitivity ``T = L / (1 + L)``.
Let the command be delayed by a further ``delta(t)``, any measurable function of time with
``0 <= delta(t) <= dmax``: no bound on how fast it changes.  Kao and Lincoln's small-gain criterion [1]_
(Theorem 1) says the loop stays stable if the nominal loop is stable and

    ``|T(jw)| = |L(jw) / (1 + L(jw))| < 1 / (dmax w)``   for all ``w > 0``.

Why: the extra delay is ``1 + (D - 1)`` with ``(D - 1)`` composed with an integrator, whose L2 gain is at most
``dmax`` (``x(t - delta) - x(t) = -int_{t-delta}^t x'``, then Cauchy-Schwarz), around the stable nominal loop
``s T(s)``; the small-gain theorem does the rest.  The **jitter margin** [2]_ is the largest such ``dmax``:

    ``J = inf_{w > 0} |1 + L(jw)| / (w |L(jw)|)``.

It is a sufficient condition: a loop may survive a larger variation, never a smaller one that the criterion
allows.  It can never exceed the constant-delay margin ``DM`` (a constant extra delay is one admissible
``delta``; directly: at the critical crossover ``|L| = 1`` and ``|1 + L| = 2 |sin(w DM / 2)| <= w DM``).  When ``L``
is biproper (a direct feedthrough, e.g. the PV law with the true velocity), ``|L|`` does not vanish at high
frequency and ``J = 0``: nothing is guaranteed.  For a strictly proper ``L`` of relative degree one,
``w |L(jw)| -> c`` and the infimum may be the limit ``1 / c`` (reported at ``frequency = inf``); for the paper's
integrator loop ``Kp e^{-sT} / s`` it is always reached at a finite frequency when ``T > 0``, below ``1 / Kp``.

For a sampled loop with a static law (P, or PV with the true velocity) the held command is the continuous law's
output delayed by the time since its sample, so a packet delay in ``[Tmin, Tmax]`` is a continuous delay in
``[Tmin, Tmax + h]``: check ``stable_for(loop.replace(period=None), tmin, tmax + h)``.

References
----------
.. [1] C.-Y. Kao and B. Lincoln, "Simple stability criteria for systems with time-varying delays",
   *Automatica* 40(8), 1429-1434, 2004.
.. [2] A. Cervin, B. Lincoln, J. Eker, K.-E. Arzen and G. Buttazzo, "The jitter margin and its application in
   the design of real-time control systems", Proc. RTCSA 2004, Goteborg.

Examples
--------
>>> from delaykit import AltitudeLoop
>>> jm = jitter_margin(AltitudeLoop(kp=1.31, delay=0.368))
>>> jm
JitterMargin(0.489 s at 3.079 rad/s; constant-delay margin 0.8311 s, nominal delay 0.368 s)
>>> stable_for(AltitudeLoop(kp=1.31, delay=0.3), 0.368, 0.368 + 0.45)
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidValueError, check_real
from ..models.altitude import AltitudeLoop
from ..models.controllers import Controller
from ..models.loop import Loop
from ._openloop import OpenLoop, cutoff_frequency, dense_grid, gain_crossovers, refine_minimum
from .frequency import _continuous, margins

__all__ = ["JitterMargin", "jitter_margin", "stable_for", "jitter_bound"]

_PER_TURN = 64  # grid points per turn of the delay's phase (2 pi / T in w)
_MAX_POINTS = 1_000_000


@dataclass(frozen=True, repr=False)
class JitterMargin:
    """The jitter margin of a loop beside its constant-delay margin.

    Attributes
    ----------
    margin : float
        The largest extra delay variation ``dmax`` (s) the criterion guarantees (any ``delta(t)`` in
        ``[0, margin)`` on top of the nominal delay).
    frequency : float
        Where ``|1 + L| / (w |L|)`` is smallest (rad/s; ``inf`` for a limit at high frequency).
    delay_margin : float
        The constant extra delay that reaches instability (:func:`~delaykit.spectrum.frequency.margins`).
    nominal_delay : float
        The loop's own (constant) total delay, ``Tmin``.
    """

    margin: float
    frequency: float
    delay_margin: float
    nominal_delay: float

    @property
    def guaranteed(self) -> tuple[float, float]:
        """The delay range ``(Tmin, Tmin + margin)`` within which any variation keeps the loop stable."""
        return self.nominal_delay, self.nominal_delay + self.margin

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (an infinite value is ``null``)."""
        fin = lambda x: x if math.isfinite(x) else None  # noqa: E731
        return {"margin": fin(self.margin), "frequency": fin(self.frequency), "delay_margin": fin(self.delay_margin),
                "nominal_delay": self.nominal_delay}

    def __repr__(self) -> str:
        at = "as w -> inf" if math.isinf(self.frequency) else f"at {self.frequency:.4g} rad/s"
        return (f"JitterMargin({self.margin:.4g} s {at}; constant-delay margin {self.delay_margin:.4g} s, "
                f"nominal delay {self.nominal_delay:.4g} s)")


def jitter_bound(loop: Loop | AltitudeLoop, w: Any) -> np.ndarray:
    """``|1 + L(jw)| / (w |L(jw)|)``, the largest delay variation the criterion allows at each frequency.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> float(jitter_bound(AltitudeLoop(kp=1.0, delay=0.0), [1.0])[0]) == math.sqrt(2)   # |j + 1| / 1
    True
    """
    loop = _continuous(loop)
    w = np.asarray(w, dtype=float)
    if w.ndim > 1 or not np.all(np.isfinite(w)) or np.any(w <= 0):
        raise InvalidValueError("w must be finite frequencies above 0 rad/s")
    if not isinstance(loop.controller, Controller):  # a compensator: L from its own module
        from .compensated import CompensatedOpenLoop

        with np.errstate(all="ignore"):
            L = CompensatedOpenLoop(loop).value(w)
            g = np.abs(1.0 + 1.0 / L) / w
        return np.where(np.isfinite(g), g, np.inf)
    return _g(OpenLoop(loop), w)


def _g(ol: OpenLoop, w: np.ndarray) -> np.ndarray:
    s = 1j * w
    with np.errstate(all="ignore"):
        inv = np.polyval(ol.den, s) / np.polyval(ol.num, s) * np.exp(s * ol.T)  # 1 / L
        g = np.abs(1.0 + inv) / w
    return np.where(np.isfinite(g), g, np.inf)


def jitter_margin(loop: Loop | AltitudeLoop) -> JitterMargin:
    """The jitter margin of a continuous loop (the criterion of Kao and Lincoln, see the module docstring).

    The infimum of ``|1 + L(jw)| / (w |L(jw)|)`` is searched on a grid that is logarithmic (as for
    :func:`~delaykit.spectrum.frequency.margins`) and, with a delay, also linear with 64 points per turn of the
    delay's phase, up to four times the margins' cut-off frequency; the lowest local minima are refined by a
    bounded scalar search, and the limit at infinite frequency is taken into account.

    Raises
    ------
    InvalidValueError
        For a sampled loop, and a nominal loop that is unstable (there is no stability to keep).  A loop with a
        compensator is analysed with ``L`` broken after the compensator's own command
        (:mod:`delaykit.spectrum.compensated`): the varying delay is the one on the way to the plant.

    References
    ----------
    .. [1] C.-Y. Kao and B. Lincoln, "Simple stability criteria for systems with time-varying delays",
       *Automatica* 40(8), 1429-1434, 2004.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> jm = jitter_margin(AltitudeLoop(kp=2.0, delay=0.0))   # |j w + 2| / (2 w) falls towards 1/2
    >>> jm.margin, jm.frequency
    (0.5, inf)
    """
    loop = _continuous(loop)
    if not isinstance(loop.controller, Controller):  # a compensator: L broken after its own command
        from .compensated import compensated_jitter

        j, w, mc = compensated_jitter(loop)
        return JitterMargin(margin=float(j), frequency=float(w), delay_margin=float(mc.delay_margin),
                            nominal_delay=float(loop.total_delay))
    m = margins(loop)
    T = loop.total_delay
    if not m.stable:
        raise InvalidValueError(f"the loop is unstable with its constant delay {T:g} s: a jitter margin needs a "
                                "stable nominal loop")
    ol = OpenLoop(loop)
    if ol.zero:
        return JitterMargin(math.inf, math.inf, m.delay_margin, T)
    rel = ol.den.size - ol.num.size
    if rel == 0:  # |L(j inf)| > 0: g ~ |1 + L| / (w |L|) -> 0
        return JitterMargin(0.0, math.inf, m.delay_margin, T)
    g_inf = float(abs(ol.den[0] / ol.num[0])) if rel == 1 else math.inf
    gains = gain_crossovers(ol)
    w_hi, _ = cutoff_frequency(ol, gains)
    w_top = 4.0 * w_hi
    parts = [dense_grid(ol, gains, w_top)]
    if T > 0:
        n = min(int(w_top * T * _PER_TURN / (2 * math.pi)) + 2, _MAX_POINTS)
        parts.append(np.linspace(w_top / n, w_top, n))
    grid = np.unique(np.concatenate(parts))
    best, where = refine_minimum(lambda w: _g(ol, w), grid, _g(ol, grid))
    if g_inf <= best:
        best, where = g_inf, math.inf
    return JitterMargin(margin=float(best), frequency=float(where), delay_margin=float(m.delay_margin),
                        nominal_delay=float(T))


def stable_for(loop: Loop | AltitudeLoop, tmin: float, tmax: float) -> bool:
    """Whether the loop is guaranteed stable for any input delay that varies, arbitrarily fast, in
    ``[tmin, tmax]`` (the loop's own input delay is replaced; its output delay is kept).

    True when the loop with the constant delay ``tmin`` is stable and its jitter margin exceeds
    ``tmax - tmin`` (for ``tmax == tmin``, when that loop is stable).  False means *not guaranteed* by the
    criterion, not that some variation destabilises the loop (see :func:`jitter_margin`).

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> stable_for(AltitudeLoop(kp=1.0, delay=0.0), 0.0, 0.99), stable_for(AltitudeLoop(kp=1.0, delay=0.0), 0.0, 1.01)
    (True, False)
    """
    loop = _continuous(loop)
    lo = check_real("tmin (smallest delay, s)", tmin, minimum=0.0)
    hi = check_real("tmax (largest delay, s)", tmax, minimum=0.0)
    if hi < lo:
        raise InvalidValueError(f"tmax must be at least tmin; got tmin={lo:g} s, tmax={hi:g} s")
    nominal = loop.replace(delay=lo)
    if not margins(nominal).stable:
        return False
    if hi == lo:
        return True
    return bool(jitter_margin(nominal).margin > hi - lo)
