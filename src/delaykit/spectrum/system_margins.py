"""Frequency response and margins of a delay system given as an open loop: :func:`~delaykit.spectrum.frequency.margins`
and :func:`~delaykit.spectrum.frequency.frequency_response` for a :class:`~delaykit.systems.DelayLTI`.

The loop is ``L`` closed by unity negative feedback, ``feedback(L, I)``: the convention of python-control's
``stability_margins`` and of :func:`~delaykit.systems.feedback`.  Two methods, and each result says which one
gave it (:attr:`~delaykit.spectrum.frequency.Margins.method`):

* ``"exact"``: a SISO ``L`` that is a rational function times one dead time (:func:`~delaykit.systems.plant_of`
  gives ``(G, T)``; any realisation without a delay inside a loop) is the open loop of the unity-feedback
  :class:`~delaykit.models.Loop` ``Loop(G, Controller.p(1), delay=T)``, whose margins are computed by the exact
  method of :mod:`delaykit.spectrum.frequency`: crossovers as polynomial roots, closed-loop stability from the
  certified root count.  The denominator of ``G`` is ``det(sI - A)`` of the realisation, so modes hidden in ``L``
  count for stability as they do in ``feedback(L, 1)``.
* ``"grid"``: any other square ``L`` (several delays, a delay inside a loop, neutral): the crossovers are found on
  the grid of :func:`~delaykit.spectrum.systems.hinfnorm` (200 points a decade over the features of ``L``, points
  over each lightly damped mode and 16 a period of the longest delay path) and refined by Brent's method, so a
  crossover between two grid points of the same sign is missed (the margins are then optimistic) and phase
  crossovers are listed up to the grid's top (``cutoff``).  The closed loop's stability is still certified:
  :func:`~delaykit.spectrum.systems.is_stable` of ``feedback(L, 1)``.  The Nyquist count is
  :func:`~delaykit.spectrum.systems.nyquist_count`'s where it applies (``encirclements`` is ``None`` and
  ``open_loop_rhp_poles`` -1 where it does not).

A MIMO (square) ``L`` gets loop-at-a-time margins: channel ``k`` opened, the other channels closed,
``L_k = [feedback(L, E_k)]_kk`` with ``E_k`` the identity without its ``k``-th one; each channel's
:class:`~delaykit.spectrum.frequency.Margins` carries ``channel = k`` and the stability of the whole closed loop
(closing ``L_k`` closes every channel).  Saturation channels are dropped (the small-signal system), as a
:class:`~delaykit.models.Loop`'s margins ignore its limits.

Examples
--------
>>> from delaykit import tf, margins
>>> m = margins(tf("exp(-0.5*s)/s"))       # PM = 90 deg - 0.5 rad, DM = pi/2 - 0.5, GM = pi/(2*0.5)
>>> m
Margins(GM 3.142 (9.943 dB) at 3.142 rad/s, PM 61.35 deg at 1 rad/s, DM 1.071 s, Ms 1.59, stable)
>>> m.method, m.certified
('exact', True)
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, plain
from ..systems.lti import DelayLTI

__all__ = ["as_exact_loop", "system_margins", "channel_margins", "system_frequency_response", "system_frequency_grid"]


def _small_signal(sys: DelayLTI) -> DelayLTI:
    return sys.without_limits() if sys.saturations else sys


def as_exact_loop(L: DelayLTI) -> Any:
    """The unity-feedback :class:`~delaykit.models.Loop` whose open loop is the SISO ``L``, or ``None`` when ``L``
    is not a rational function times one dead time (:func:`~delaykit.systems.plant_of` refuses it) or when the
    rational part is not a loop's plant (improper).

    Examples
    --------
    >>> from delaykit import tf
    >>> as_exact_loop(tf("2*(1 + 1/s)") * tf("exp(-0.1*s)/(s+1)"))
    Loop(plant (2 s + 2)/(s^2 + s), p: kp=1, delay=0.1 s, no saturation, continuous)
    >>> as_exact_loop(tf("1/(s+1)") + tf("exp(-s)/(s+1)")) is None
    True
    """
    from ..models.controllers import Controller
    from ..models.loop import Loop
    from ..systems.build import plant_of

    L = _small_signal(L)
    if (L.ninputs, L.noutputs) != (1, 1):
        return None
    try:
        g, T = plant_of(L)
        return Loop(g, Controller.p(1.0), delay=T)
    except InvalidValueError:
        return None


def _channel(L: DelayLTI, k: int) -> DelayLTI:
    """``[feedback(L, E_k)]_kk``: channel ``k`` opened, the others closed by unity negative feedback."""
    from ..systems.algebra import feedback, gain

    n = L.noutputs
    if n == 1:
        return L
    E = np.eye(n)
    E[k, k] = 0.0
    return feedback(L, gain(E))[k, k]


def _square(L: Any, what: str) -> DelayLTI:
    if not isinstance(L, DelayLTI):
        raise InvalidTypeError(f"{what} takes a Loop, an AltitudeLoop or a DelayLTI open loop, got "
                               f"{type(L).__name__}")
    if L.ninputs != L.noutputs or L.ninputs == 0:
        raise InvalidValueError(f"{what} of a system need a square open loop L (closed as feedback(L, I)), got "
                                f"{L!r}")
    return _small_signal(L)


def system_margins(L: DelayLTI) -> Any:
    """The :class:`~delaykit.spectrum.frequency.Margins` of the unity negative feedback loop around ``L``.

    SISO ``L``: one ``Margins``; MIMO square ``L``: a tuple, one per channel (loop-at-a-time).  See the module
    docstring for the two methods (``Margins.method``).

    Examples
    --------
    >>> from delaykit import tf
    >>> system_margins(tf("3*exp(-s)/(s-1)")).stable     # the closed loop is unstable: no margins
    False
    >>> m = system_margins(tf("exp(-0.1*s)/(s+1)") * tf("2*exp(-0.2*s)/(s+1)") + tf("0.1*exp(-2*s)/(s+1)"))
    >>> m.method, m.certified, m.stable
    ('grid', False, True)
    """
    from .frequency import margins

    L = _square(L, "margins")
    n = L.noutputs
    out = []
    for k in range(n):
        Lk = _channel(L, k)
        loop = as_exact_loop(Lk)
        m = margins(loop) if loop is not None else _grid_margins(Lk)
        out.append(dataclasses.replace(m, channel=k) if n > 1 else m)
    return out[0] if n == 1 else tuple(out)


def channel_margins(L: DelayLTI, channel: int) -> Any:
    """Margins of one channel of a square ``L`` (the others closed), with the channel checked; for
    :func:`~delaykit.spectrum.systems.loop_margins`.

    Examples
    --------
    >>> from delaykit import tf
    >>> channel_margins(tf([["exp(-0.2*s)/s", 0], [0, "2*exp(-0.1*s)/s"]]), 1).channel
    1
    """
    from .frequency import margins

    L = _square(L, "margins")
    n = L.noutputs
    if isinstance(channel, bool) or not isinstance(channel, (int, np.integer)) or not 0 <= channel < n:
        raise InvalidValueError(f"channel must be an integer from 0 to {n - 1}, got {plain(channel)!r}")
    Lk = _channel(L, int(channel))
    loop = as_exact_loop(Lk)
    m = margins(loop) if loop is not None else _grid_margins(Lk)
    return dataclasses.replace(m, channel=int(channel))


def _delayed_feedthrough(L: DelayLTI) -> bool:
    """True when a delayed signal reaches the output directly: ``L(jw)`` keeps circling as ``w -> inf``."""
    return any(L.delays[j] > 0 and L.D12[:, j].any() and (L.D21[j, :].any() or L.D22[j, :].any())
               for j in range(L.ndelays))


def _grid_margins(L: DelayLTI) -> Any:
    """Margins of the SISO ``L`` from a grid scan refined by Brent's method (``method="grid"``)."""
    from scipy.optimize import brentq

    from ..systems.algebra import feedback
    from ._openloop import TWO_PI, refine_minimum
    from .frequency import Crossover, _assemble
    from .systems import _features, _grid, _high_frequency_limit, is_stable, nyquist_count

    lo, hi, _ = _features(L)
    w = _grid(L, lo, hi)
    w = w[w > 0]

    def val(x: Any) -> np.ndarray:
        return L.evaluate(1j * np.atleast_1d(np.asarray(x, float)))[0, 0]

    h = val(w)
    fin = np.isfinite(h)
    with np.errstate(all="ignore"):
        ph = np.full(h.shape, np.nan)
        ph[fin] = np.unwrap(np.angle(h[fin]))

    def phase_at(x: float, v: complex) -> float:  # the unwrapped phase at x, from the nearest grid point
        i = int(np.clip(np.searchsorted(w, x), 0, w.size - 1))
        if not np.isfinite(ph[i]):
            return float(np.angle(v))
        return float(ph[i] + np.angle(v / h[i]))

    crossovers = []
    im = h.imag
    for i in np.flatnonzero(fin[:-1] & fin[1:] & (np.sign(im[:-1]) * np.sign(im[1:]) < 0)):
        x = brentq(lambda t: float(val(t)[0].imag), w[i], w[i + 1], xtol=1e-14 * w[i])
        v = complex(val(x)[0])
        if v.real < 0:
            phi = phase_at(x, v)
            crossovers.append(Crossover("phase", float(x), abs(v), math.degrees(phi),
                                        gain_margin=1.0 / abs(v) if v else math.inf,
                                        direction=int(np.sign(ph[i + 1] - ph[i])) or None))
    l0 = complex(L.evaluate([0.0])[0, 0, 0])
    if np.isfinite(l0) and l0.real < 0 and abs(l0.imag) <= 1e-14 * abs(l0):
        crossovers.append(Crossover("phase", 0.0, abs(l0), -180.0, gain_margin=1.0 / abs(l0)))
    lim = _high_frequency_limit(L)
    if lim > 0 and (_delayed_feedthrough(L) or float(L.D11[0, 0]) < 0):
        crossovers.append(Crossover("phase", math.inf, lim, math.nan, gain_margin=1.0 / lim))
    with np.errstate(divide="ignore"):
        g = np.log(np.abs(h))
    for i in np.flatnonzero(np.isfinite(g[:-1]) & np.isfinite(g[1:]) & (np.sign(g[:-1]) * np.sign(g[1:]) < 0)):
        x = brentq(lambda t: math.log(abs(complex(val(t)[0]))), w[i], w[i + 1], xtol=1e-14 * w[i])
        v = complex(val(x)[0])
        phi = phase_at(x, v)
        lag = (phi + math.pi) % TWO_PI
        crossovers.append(Crossover("gain", float(x), 1.0, math.degrees(phi),
                                    phase_margin=math.degrees(lag if lag <= math.pi else lag - TWO_PI),
                                    delay_margin=lag / x))
    stable = is_stable(feedback(L, 1))
    try:
        nc = nyquist_count(L)
        p_rhp, ccw = nc.open_loop_unstable, nc.encirclements
    except InvalidValueError:
        p_rhp, ccw = -1, None

    def peak() -> tuple[float, float | None]:
        with np.errstate(all="ignore"):
            d = np.abs(1.0 + h)
        best, where = refine_minimum(lambda x: np.abs(1.0 + val(x)), w, np.where(np.isfinite(d), d, np.inf),
                                     keep=8)
        w_ms: float | None = where
        limits = [abs(1.0 + l0)] if np.isfinite(l0) else []
        limits.append(1.0 - lim if _delayed_feedthrough(L) else abs(1.0 + float(L.D11[0, 0])))
        for v in limits:
            if v < best:
                best, w_ms = v, None
        return (1.0 / best if best > 0 else math.inf), w_ms

    m = _assemble(sum(L.delays), crossovers, stable=stable, source="roots", open_loop_rhp_poles=p_rhp,
                  encirclements=ccw, cutoff=float(w[-1]), peak=peak)
    return dataclasses.replace(m, method="grid")


def system_frequency_grid(L: DelayLTI, n: int) -> np.ndarray:
    """A logarithmic grid of ``n`` frequencies from 1/100 of the lowest to 10 times the highest feature of ``L``
    (eigenvalue magnitudes of ``A``, 1/delay): :func:`~delaykit.spectrum.frequency.frequency_grid` of a system
    that is not a rational function times one dead time."""
    from .systems import _features

    _, _, feats = _features(L)
    return np.geomspace(min(feats) / 100, max(feats) * 10, int(n))


def _phase_grid(w: np.ndarray, delay: float) -> np.ndarray:
    """The sorted positive frequencies ``w`` with points added between neighbours until the total delay's phase
    turns by at most 45 degrees and the frequency grows by at most a factor 10^(1/100) from one to the next."""
    from ..models.budget import MAX_GRID_POINTS, check_count

    w = np.unique(w[np.isfinite(w) & (w > 0)])
    if w.size < 2:
        return w
    gaps = np.maximum(np.ceil(np.diff(w) * delay / (np.pi / 4)), np.ceil(100 * np.log10(w[1:] / w[:-1])))
    gaps = np.maximum(gaps, 1).astype(np.int64)
    check_count(f"the points between {w[0]:g} and {w[-1]:g} rad/s that unwrap the phase of delays totalling "
                f"{delay:g}", float(gaps.sum()), MAX_GRID_POINTS, "points", "give a narrower range")
    k = np.repeat(np.arange(gaps.size), gaps)
    frac = (np.arange(k.size) - np.repeat(np.cumsum(gaps) - gaps, gaps)) / np.repeat(gaps, gaps)
    return np.append(w[:-1][k] + frac * np.diff(w)[k], w[-1])


def system_frequency_response(L: DelayLTI, w: np.ndarray) -> Any:
    """:class:`~delaykit.spectrum.frequency.FrequencyResponse` of a SISO ``L`` that is not a rational function
    times one dead time: ``L(jw)`` exact (:meth:`DelayLTI.evaluate`), the phase unwrapped along the sorted
    frequencies (``numpy.unwrap``), on a grid refined between the given frequencies so that the delays' phase
    (their sum times the spacing) turns by at most 45 degrees and the frequency by at most 1/100 decade from
    one point to the next: so a delay's phase keeps falling over as many decades as asked, however sparse ``w``.
    The refinement bounds the delays' part of the phase exactly and a rational part's on a log grid; a resonance
    sharper than 1/100 decade inside a loop with delays could still be unwrapped wrongly.

    Examples
    --------
    >>> import numpy as np
    >>> from delaykit import tf
    >>> r = system_frequency_response(tf("exp(-s)/(s+1)") + tf("0.5/(s+2)"), np.array([1e-3, 1e3]))
    >>> w = 1e3     # the phase is -w - atan(w) + arg(1 + 0.5 (jw + 1)/(jw + 2) exp(jw)), the last within 30 degrees
    >>> rest = np.angle(1 + 0.5 * (1j * w + 1) / (1j * w + 2) * np.exp(1j * w))
    >>> round(float(np.degrees(-w - np.arctan(w) + rest)), 5)
    -57367.82056
    >>> round(float(r.phase_deg[1]), 5)
    -57367.82056
    """
    from .frequency import FrequencyResponse

    h = L.evaluate(1j * w)[0, 0]
    with np.errstate(all="ignore"):
        ang = np.angle(h)
        dense = _phase_grid(np.asarray(w, float), float(sum(L.delays)))
        hd = L.evaluate(1j * dense)[0, 0] if dense.size else np.zeros(0, complex)
        fin = np.isfinite(hd) & (hd != 0)
        ud = np.angle(hd)
        ud[fin] = np.unwrap(ud[fin])
        phase = ang.copy()
        pos = (w > 0) & np.isfinite(h) & (h != 0)
        if dense.size and pos.any():  # each given frequency's phase: its angle moved by whole turns to the dense one
            near = ud[np.searchsorted(dense, w[pos])]
            phase[pos] = ang[pos] + 2 * np.pi * np.round((near - ang[pos]) / (2 * np.pi))
        if not pos.all():  # w = 0 (and poles, zeros on the axis): as before, unwrapped from its neighbour
            order = np.argsort(w, kind="stable")
            fin0 = np.isfinite(h[order]) & (h[order] != 0)
            srt = phase[order].copy()
            srt[fin0] = np.unwrap(srt[fin0])
            phase[order] = srt
        mag_db = 20.0 * np.log10(np.abs(h))
    return FrequencyResponse(w=w, L=h, magnitude_db=mag_db, phase_deg=np.degrees(phase))
