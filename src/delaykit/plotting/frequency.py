"""Bode and Nyquist plots of a loop's exact frequency response (computed by :mod:`delaykit.spectrum.frequency`).

Each function draws on the axes it is given, or on a new :class:`matplotlib.figure.Figure`, returns the
figure, and writes it to ``path`` (PNG, PDF or SVG by the suffix, its folder created) only when a path is given,
as the other plot functions do (:func:`~delaykit.plotting.figures.save_figure`).  Nothing is computed here beyond
what the drawing needs, and no backend is chosen: a new figure is a plain ``Figure`` (not registered with pyplot).

Examples
--------
>>> from delaykit import AltitudeLoop, frequency_response, margins
>>> loop = AltitudeLoop(kp=1.31, delay=0.368)
>>> fig = plot_bode(frequency_response(loop), margins=margins(loop))
>>> [a.get_ylabel() for a in fig.axes]
['|L| (dB)', 'phase of L (deg)']
"""

from __future__ import annotations

import math

from pathlib import Path
from typing import Any, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import InvalidTypeError, InvalidValueError
from ..spectrum.frequency import FrequencyResponse, Margins
from .figures import save_figure

__all__ = ["plot_bode", "plot_nyquist"]


def _responses(resp_or_list: Any) -> list[FrequencyResponse]:
    items = [resp_or_list] if isinstance(resp_or_list, FrequencyResponse) else list(resp_or_list)
    if not items:
        raise InvalidValueError("nothing to draw: give at least one FrequencyResponse")
    for r in items:
        if not isinstance(r, FrequencyResponse):
            raise InvalidTypeError(f"expected FrequencyResponse objects (from frequency_response), got "
                                   f"{type(r).__name__}")
    return items


def _labels(labels: Sequence[str] | None, n: int) -> list[str | None]:
    if labels is None:
        return [None] * n
    labels = list(labels)
    if len(labels) != n:
        raise InvalidValueError(f"labels: {len(labels)} given for {n} responses")
    return labels


def _margins(margins: Any, n: int) -> list[Margins | None]:
    """One ``Margins`` (or None) per response: a single one belongs to the first response."""
    if margins is None:
        return [None] * n
    if isinstance(margins, Margins):
        return [margins] + [None] * (n - 1)
    ms = list(margins)
    if len(ms) != n:
        raise InvalidValueError(f"margins: {len(ms)} given for {n} responses (give one per response, None for none)")
    for m in ms:
        if m is not None and not isinstance(m, Margins):
            raise InvalidTypeError(f"margins must be Margins objects (from margins(loop)) or None, got "
                                   f"{type(m).__name__}")
    return ms


def _mark_margins(m: Margins, ax_mag: Axes, ax_ph: Axes, colour: str) -> None:
    """The gain crossover (phase and delay margins) and the phase crossover (gain margin) of one loop, drawn and
    labelled in its response's colour (not a fixed colour, which would be another response's)."""
    if m.crossover is not None:
        wc = m.crossover
        gain = next(c for c in m.crossovers if c.kind == "gain" and c.frequency == wc)
        for a in (ax_mag, ax_ph):
            a.axvline(wc, color=colour, lw=0.8, ls=":")
        ax_ph.annotate(f"PM {gain.phase_margin:.1f}°, DM {gain.delay_margin:.3g} s", (wc, gain.phase_deg),
                       textcoords="offset points", xytext=(6, 6), fontsize=8, color=colour)
    wp = m.phase_crossover
    if wp is not None and np.isfinite(wp):
        for a in (ax_mag, ax_ph):
            a.axvline(wp, color=colour, lw=0.8, ls="-.")
        ax_mag.annotate(f"GM {m.gain_margin:.3g} ({m.gain_margin_db:.1f} dB)", (wp, -m.gain_margin_db),
                        textcoords="offset points", xytext=(6, -12), fontsize=8, color=colour)


def plot_bode(
    resp_or_list: FrequencyResponse | Sequence[FrequencyResponse],
    path: str | Path | None = None,
    *,
    ax: Any = None,
    axes: tuple[Axes, Axes] | None = None,
    margins: Margins | Sequence[Margins | None] | None = None,
    labels: Sequence[str] | None = None,
) -> Figure:
    """Bode plot (magnitude in dB and unwrapped phase in degrees against log frequency) of one or more responses.

    Parameters
    ----------
    resp_or_list : FrequencyResponse or sequence of them
        From :func:`~delaykit.spectrum.frequency.frequency_response`.
    path : str or Path, optional
        Write the figure here (PNG, PDF or SVG by the suffix); nothing is written without it.  With axes given, the
        whole figure they belong to is written.
    ax, axes : pair of matplotlib Axes, optional
        ``(ax_mag, ax_phase)`` to draw on (``ax`` and ``axes`` are the same argument; give one).  By default a
        new figure with two axes sharing the frequency axis.
    margins : Margins or sequence of (Margins or None), optional
        Mark the gain crossover (phase margin, dotted) and the phase crossover that sets the gain margin (dash-dot),
        with their labels, in the colour of the response they belong to.  One ``Margins`` marks the first
        response; a sequence gives one per response (``None`` for none).
    labels : sequence of str, optional
        Legend entries, one per response.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import Controller, Loop, frequency_response
    >>> loops = [Loop("1/(s*(0.05*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=d) for d in (0.1, 0.3)]
    >>> fig = plot_bode([frequency_response(l) for l in loops], labels=["0.1 s", "0.3 s"])
    >>> len(fig.axes[0].lines)
    3
    """
    items = _responses(resp_or_list)
    names = _labels(labels, len(items))
    if ax is not None and axes is not None:
        raise InvalidValueError("give the two axes as ax or as axes, not both")
    pair = axes if axes is not None else ax
    if pair is None:
        fig = Figure(figsize=(7.5, 6.0), layout="constrained")
        ax_mag, ax_ph = fig.subplots(2, 1, sharex=True)
    else:
        if isinstance(pair, Axes) or not (isinstance(pair, (tuple, list)) and len(pair) == 2
                                          and all(isinstance(a, Axes) for a in pair)):
            raise InvalidTypeError("a Bode plot needs two axes: give ax=(ax_magnitude, ax_phase)")
        ax_mag, ax_ph = pair
        fig = ax_mag.figure
    colours = []
    for r, name in zip(items, names):
        keep = r.w > 0
        (line,) = ax_mag.semilogx(r.w[keep], r.magnitude_db[keep], lw=1.4, label=name)
        ax_ph.semilogx(r.w[keep], r.phase_deg[keep], lw=1.4, color=line.get_color())
        colours.append(line.get_color())
    ax_mag.axhline(0.0, color="0.4", lw=0.7, ls="--")
    lo = min(float(np.nanmin(r.phase_deg)) for r in items)
    hi = max(float(np.nanmax(r.phase_deg)) for r in items)
    k0, k1 = math.floor((lo - 180) / 360), math.ceil((hi + 180) / 360)  # (counted before listed: a long delay's
    levels = [-180.0 + 360.0 * k for k in range(k0, k1 + 1)             # phase spans billions of turns)
              if lo - 1 <= -180.0 + 360.0 * k <= hi + 1] if k1 - k0 <= 8 else [0.0] * 5
    for level in levels if len(levels) <= 4 else [-180.0]:  # -180 modulo 360, unless that clutters the axes
        ax_ph.axhline(level, color="0.4", lw=0.7, ls="--")
    for m, colour in zip(_margins(margins, len(items)), colours):
        if m is not None and m.stable:
            _mark_margins(m, ax_mag, ax_ph, colour)
    ax_mag.set_ylabel("|L| (dB)")
    ax_ph.set_ylabel("phase of L (deg)")
    ax_ph.set_xlabel("frequency ω (rad/s)")
    for a in (ax_mag, ax_ph):
        a.grid(alpha=0.3, which="both")
    if any(names):
        ax_mag.legend(fontsize=8)
    return save_figure(fig, path)


def plot_nyquist(
    resp_or_list: FrequencyResponse | Sequence[FrequencyResponse],
    path: str | Path | None = None,
    *,
    ax: Axes | None = None,
    labels: Sequence[str] | None = None,
    radius: float = 2.0,
) -> Figure:
    """Nyquist plot: ``L(jw)`` for ``w >= 0`` (solid) and its mirror image for ``w <= 0`` (dashed), with -1.

    The view is limited to ``|L| <= radius`` around the origin (a curve that starts at infinity, as with an
    integrator, would otherwise hide the point -1); the default, 2, gives the unit circle around -1, where the
    margins are read, half the view's width.

    Parameters
    ----------
    resp_or_list : FrequencyResponse or sequence of them
        From :func:`~delaykit.spectrum.frequency.frequency_response`.
    path : str or Path, optional
        Write the figure here (PNG, PDF or SVG by the suffix); nothing is written without it.
    ax : matplotlib Axes, optional
        Where to draw; by default a new figure.
    labels : sequence of str, optional
        Legend entries, one per response.
    radius : float
        Half-width of the view at most (default 2; less when the curves stay closer to the origin).

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import AltitudeLoop, frequency_response
    >>> fig = plot_nyquist(frequency_response(AltitudeLoop(kp=1.31, delay=0.368)))
    >>> bool(fig.axes[0].get_xlim()[0] <= -1.0)
    True
    """
    items = _responses(resp_or_list)
    names = _labels(labels, len(items))
    if ax is None:
        fig = Figure(figsize=(6.0, 6.0), layout="constrained")
        ax = fig.subplots()
    elif not isinstance(ax, Axes):
        raise InvalidTypeError(f"ax must be a matplotlib Axes, got {type(ax).__name__}")
    else:
        fig = ax.figure
    if not (isinstance(radius, (int, float)) and not isinstance(radius, bool) and np.isfinite(radius) and radius > 0):
        raise InvalidValueError(f"radius must be a positive number, got {radius!r}")
    reach = 1.2
    for r, name in zip(items, names):
        order = np.argsort(r.w)
        L = r.L[order]
        L = np.where(np.abs(L) <= 1e3 * radius, L, np.nan)  # leave out points at infinity
        (line,) = ax.plot(L.real, L.imag, lw=1.3, label=name)
        ax.plot(L.real, -L.imag, lw=0.9, ls="--", color=line.get_color())
        finite = np.abs(L[np.isfinite(L)])
        if finite.size:
            reach = max(reach, float(min(radius, finite.max())))
    t = np.linspace(0, 2 * np.pi, 361)
    ax.plot(np.cos(t), np.sin(t), color="0.75", lw=0.7)
    ax.plot([-1.0], [0.0], "x", color="tab:red", ms=9, mew=2)
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.axvline(0.0, color="0.5", lw=0.6)
    ax.set_xlim(-1.08 * reach, 1.08 * reach)
    ax.set_ylim(-1.08 * reach, 1.08 * reach)
    ax.set_aspect("equal")
    ax.set_xlabel("Re L(jω)")
    ax.set_ylabel("Im L(jω)")
    ax.grid(alpha=0.3)
    if any(names):
        ax.legend(fontsize=8)
    return save_figure(fig, path)
