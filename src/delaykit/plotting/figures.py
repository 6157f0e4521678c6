"""Figures (matplotlib) of what the lower layers compute: responses, spectra, stability maps, fits, Bode plots of the
derivative filter, and the iterations of the paper's section 5.1.2.  Computation lives elsewhere; these only draw.

Every function draws into the axes it is given (``ax``; a pair of axes for the two-panel figures) or, without
one, into a new :class:`matplotlib.figure.Figure`; it returns the figure, and writes it to ``path`` (PNG, PDF or
SVG by the suffix) only when a path is given.  Nothing here imports :mod:`matplotlib.pyplot` or chooses a
backend: a new figure is a plain ``Figure`` (which ``savefig`` renders with the Agg canvas, on any machine), so
importing this module leaves a notebook's or an application's backend as it was.

Examples
--------
>>> from delaykit import AltitudeLoop, simulate
>>> fig = plot_responses([simulate(AltitudeLoop(kp=1.31, delay=0.368))])
>>> [ax.get_ylabel() for ax in fig.axes]
['altitude z (m)', 'command u (m/s)']
"""

from __future__ import annotations

import io
import textwrap
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import InvalidTypeError, InvalidValueError, check_path, writing
from ..simulate.simulation import Response

__all__ = ["plot_responses", "plot_spectrum", "plot_z_spectrum", "plot_stability_map", "plot_fit",
           "plot_filter_bode", "plot_iterations", "save_figure", "set_title", "signal_labels"]

DPI = 120


def save_figure(fig: Figure, path: str | Path | None, dpi: int = DPI) -> Figure:
    """Write ``fig`` to ``path`` (its folder created; the format from the suffix) when ``path`` is given;
    return the figure either way.

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "sub", "empty.png")
    >>> fig = save_figure(Figure(), path)
    >>> os.path.getsize(path) > 0, save_figure(fig, None) is fig
    (True, True)
    """
    if path is not None:
        path = check_path("figure", path)
        root = fig if isinstance(fig, Figure) else fig.figure  # axes given on a subfigure: save the whole figure
        # drawn in memory, then written: matplotlib's own writing lets a failed write pass (/dev/full: no error)
        fmt = path.suffix[1:].lower() or None
        formats = root.canvas.get_supported_filetypes()
        if fmt is not None and fmt not in formats:
            raise InvalidValueError(f"the figure {str(path)!r}: {path.suffix!r} is not a figure format; use one of "
                                    f"{', '.join('.' + f for f in sorted(formats))}")
        buf = io.BytesIO()
        root.savefig(buf, format=fmt, dpi=dpi)
        with writing("the figure", path):
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(buf.getvalue())
    return fig


def set_title(ax: Axes, text: str, **kw: Any) -> None:
    """Set ``ax``'s title wrapped to the figure's width, so that a long title is never clipped.

    Examples
    --------
    >>> ax = Figure(figsize=(4, 3)).subplots()
    >>> set_title(ax, "a title far longer than a figure four inches wide can hold on a single line of text")
    >>> len(ax.get_title().splitlines())
    3
    """
    size = kw.get("fontsize", 12.0)
    size = float(size) if isinstance(size, (int, float)) else 12.0
    width = ax.figure.get_figwidth() * 0.9 * 72.0  # points across, less the margins
    chars = max(20, int(width / (0.6 * size)))  # an average character is about 0.6 of the font size wide
    ax.set_title("\n".join(textwrap.fill(line, chars) for line in str(text).split("\n")), **kw)


def signal_labels(loop: Any) -> tuple[str, str]:
    """The output's and the command's axis labels for a loop's response: the paper's altitude loop draws
    ``altitude z (m)`` and ``command u (m/s)``; any other loop ``output y`` and ``command u`` (a transfer function
    carries no units: give the labels to the plot to name them).

    Examples
    --------
    >>> from delaykit import AltitudeLoop, Loop
    >>> signal_labels(AltitudeLoop(kp=1.31, delay=0.368)), signal_labels(Loop("0.7/(150*s+1)", delay=16))
    (('altitude z (m)', 'command u (m/s)'), ('output y', 'command u'))
    """
    from ..models.altitude import AltitudeLoop

    if isinstance(loop, AltitudeLoop):
        return "altitude z (m)", "command u (m/s)"
    return "output y", "command u"


def _axes(ax: Any, panels: int, figsize: tuple[float, float], **grid: Any) -> tuple[Figure, list[Axes], bool]:
    """The figure and ``panels`` axes to draw into: those given (one Axes, or a sequence of them), or new ones.

    Returns ``(figure, axes, new)``; with fewer axes given than ``panels``, only those panels are drawn."""
    if ax is None:
        fig = Figure(figsize=figsize, layout="tight")
        axes = fig.subplots(panels, 1, squeeze=False, **grid)[:, 0] if panels > 1 else [fig.subplots()]
        return fig, list(axes), True
    given = [ax] if isinstance(ax, Axes) else list(ax)
    if not given or not all(isinstance(a, Axes) for a in given):
        raise InvalidTypeError(f"ax must be a matplotlib Axes or a sequence of them, got {ax!r}")
    if len(given) > panels:
        raise InvalidValueError(f"this figure has {panels} panel(s); got {len(given)} axes")
    return given[0].figure, given, False


def _default_label(loop: Any) -> str:
    kv = getattr(loop, "kv", None)
    if kv is None:
        kv = getattr(getattr(loop, "controller", None), "kv", None)
    return f"Td={loop.delay:.4g} s" + (f", Kv={kv:g}" if kv else "")


def plot_responses(
    responses: Sequence[Response],
    path: str | Path | None = None,
    *,
    ax: Axes | Sequence[Axes] | None = None,
    labels: Sequence[str] | None = None,
    title: str | None = None,
    dt: float = 0.005,
    t_max: float | None = None,
    output_label: str | None = None,
    command_label: str | None = None,
) -> Figure:
    """Output and command of one or more responses: one line per response in each panel, the reference (dashed)
    and the first response's settling band (shaded).

    Parameters
    ----------
    responses : sequence of Response
        The responses to draw (from :func:`delaykit.simulate.simulation.simulate`).
    path : str or Path, optional
        Write the figure there (PNG, PDF or SVG by suffix).
    ax : Axes or (Axes, Axes), optional
        Where to draw: one Axes draws the output only; two draw the output and the command.
    labels : sequence of str, optional
        Legend entries; by default the delay (and Kv) of each loop.
    title : str, optional
        Title of the output panel.
    dt : float
        Drawing resolution, seconds.
    t_max : float, optional
        Draw up to this time after the step (default: each response's whole length).
    output_label, command_label : str, optional
        The panels' axis labels, with units (``"temperature T (°C)"``, ``"heater Q (%)"``); by default those of
        the first loop (:func:`signal_labels`).

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import AltitudeLoop, simulate
    >>> r = simulate(AltitudeLoop(kp=1.31, delay=0.368), t_end=4.0)
    >>> fig = plot_responses([r], labels=["paper"], dt=0.5)
    >>> fig.axes[0].lines[0].get_label(), fig.axes[0].lines[0].get_ydata()[:3].round(3).tolist()
    ('paper', [0.0, 0.132, 0.632])
    """
    fig, axes, new = _axes(ax, 2, (8, 6), sharex=True, height_ratios=[3, 1.4])
    if labels is not None and len(labels) != len(responses):
        raise InvalidValueError(f"labels must name each of the {len(responses)} responses, got {len(labels)}")
    ax1 = axes[0]
    ax2 = axes[1] if len(axes) > 1 else None
    for i, r in enumerate(responses):
        s = r.sample(dt=dt)
        lab = labels[i] if labels is not None else _default_label(r.loop)
        (line,) = ax1.plot(s["t"], s["z"], lw=1.4, label=lab)
        if ax2 is not None:
            ax2.plot(s["t"], s["u"], lw=1.0, color=line.get_color(), label=lab)
    if responses:
        r0 = responses[0]
        s0 = r0.sample(dt=dt)
        ax1.plot(s0["t"], s0["z_ref"], color="k", lw=0.6, ls="--", label="reference")
        if r0.metrics is not None and r0.step != 0:
            ref = r0.z0 + r0.step
            band = r0.metrics.band * abs(r0.step)
            ax1.axhspan(ref - band, ref + band, color="0.85", zorder=0, label=f"±{100 * r0.metrics.band:g} % band")
    if t_max is not None:
        for a in axes:
            a.set_xlim(-0.05 * t_max, t_max)
    y_label, u_label = signal_labels(responses[0].loop) if responses else ("output y", "command u")
    ax1.set_ylabel(output_label or y_label)
    last = ax2 if ax2 is not None else ax1
    last.set_xlabel("time after the step (s)")
    ax1.grid(alpha=0.3)
    if ax2 is not None:
        ax2.set_ylabel(command_label or u_label)
        ax2.grid(alpha=0.3)
    ax1.legend(fontsize=8, ncol=2)
    if title:
        set_title(ax1, title)
    return save_figure(fig, path)


def plot_spectrum(
    spectra: Sequence,
    path: str | Path | None = None,
    *,
    ax: Axes | None = None,
    labels: Sequence[str] | None = None,
    title: str | None = None,
) -> Figure:
    """Roots in the complex plane, as in the paper's Fig. 8: one marker series per spectrum, its rightmost root
    enlarged, its neutral lines dashed, the stable half-plane shaded.

    Parameters
    ----------
    spectra : sequence of Spectrum
        Results of :func:`delaykit.spectrum.roots.find_roots` (one per loop).
    path : str or Path, optional
        Write the figure there.
    ax : Axes, optional
        Where to draw.
    labels : sequence of str, optional
        Legend entries.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> from delaykit.spectrum.roots import find_roots
    >>> sp = find_roots(AltitudeLoop(kp=2, delay=0.37, kv=0.3).characteristic(), (-10, 2, 0, 100))
    >>> fig = plot_spectrum([sp], labels=["Kv = 0.3"])
    >>> series = [line for line in fig.axes[0].lines if line.get_label() == "Kv = 0.3"]
    >>> len(series), len(series[0].get_xdata()) == len(sp.roots)
    (1, True)
    """
    fig, (ax,), _ = _axes(ax, 1, (7, 6))
    if labels is not None and len(labels) != len(spectra):
        raise InvalidValueError(f"labels must name each of the {len(spectra)} spectra, got {len(labels)}")
    markers = "oxs^vD+*"
    if spectra:
        x0 = min(sp.region[0] for sp in spectra)
        x1 = max(sp.region[1] for sp in spectra)
        y0 = min(sp.region[2] for sp in spectra)
        y1 = max(sp.region[3] for sp in spectra)
        ax.axvspan(x0, min(0.0, x1), color="#e8f4e8", zorder=0, label="stable half-plane")
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
    else:
        y0 = 0.0
    ax.axvline(0.0, color="k", lw=0.8)
    for i, sp in enumerate(spectra):
        lab = labels[i] if labels is not None else None
        mk = markers[i % len(markers)]
        pts = ax.plot(sp.roots.real, sp.roots.imag, mk, ms=5, mfc="none", label=lab)
        color = pts[0].get_color()
        for xline in sp.neutral_lines:
            ax.axvline(xline, color=color, ls="--", lw=0.8)
        rm = sp.rightmost
        if rm is not None:
            ax.plot([rm.real], [rm.imag], mk, ms=9, color=color)
        for z, m in zip(sp.roots, sp.multiplicities):
            if m > 1:
                ax.annotate(f"×{m}", (z.real, z.imag), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlabel("Re s")
    ax.set_ylabel("Im s (conjugates not shown)" if y0 >= 0 else "Im s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    if title:
        set_title(ax, title)
    return save_figure(fig, path)


def plot_z_spectrum(
    result: Any,
    path: str | Path | None = None,
    *,
    ax: Axes | None = None,
    label: str | None = None,
    title: str | None = None,
) -> Figure:
    """The poles of a sampled loop in the z-plane: the unit circle (the stability boundary, its inside shaded),
    every pole as a marker at its modulus and angle, the pole(s) of largest modulus circled, and a title that
    gives the spectral radius and says whether the loop is stable.

    Parameters
    ----------
    result : SampledSpectrum
        From :func:`delaykit.spectrum.sampled.sampled_spectrum` (every pole of the loop, conjugates included).
    path : str or Path, optional
        Write the figure there.
    ax : Axes, optional
        Where to draw.
    label : str, optional
        Legend entry of the poles (default: their number).
    title : str, optional
        A first title line (the loop, say); the spectral radius and the verdict follow it.

    Returns
    -------
    matplotlib.figure.Figure

    See Also
    --------
    plot_spectrum : the roots of a continuous loop in the s-plane.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> from delaykit.spectrum.sampled import sampled_spectrum
    >>> sp = sampled_spectrum(AltitudeLoop(kp=5.0, delay=0.1, period=0.1))   # z^2 - z + Kp h: z = (1 ± j) / 2
    >>> fig = plot_z_spectrum(sp, label="poles")
    >>> pts = [line for line in fig.axes[0].lines if line.get_label() == "poles"][0]
    >>> sorted(np.round(pts.get_xdata() + 1j * pts.get_ydata(), 12).tolist(), key=lambda z: z.imag)
    [(0.5-0.5j), (0.5+0.5j)]
    >>> fig.axes[0].get_title()
    'spectral radius 0.707107 < 1: stable (h = 0.1 s)'
    """
    from ..spectrum.sampled import SampledSpectrum

    if not isinstance(result, SampledSpectrum):
        raise InvalidTypeError(f"result must be a SampledSpectrum (from sampled_spectrum), got {type(result).__name__}")
    fig, (ax,), _ = _axes(ax, 1, (6.5, 6))
    poles = np.asarray(result.poles).astype(complex).ravel()
    radius = float(result.radius)
    theta = np.linspace(0.0, 2.0 * np.pi, 721)
    ax.fill(np.cos(theta), np.sin(theta), color="#e8f4e8", zorder=0, label="stable region |z| < 1")
    ax.plot(np.cos(theta), np.sin(theta), color="k", lw=0.9, label="unit circle")
    ax.axhline(0.0, color="0.6", lw=0.6)
    ax.axvline(0.0, color="0.6", lw=0.6)
    lab = label if label is not None else f"{poles.size} pole{'s' if poles.size != 1 else ''}"
    pts = ax.plot(poles.real, poles.imag, "x", ms=7, mew=1.4, label=lab)
    if poles.size:
        top = poles[np.abs(poles) >= radius * (1.0 - 1e-9)]
        ax.plot(top.real, top.imag, "o", ms=13, mfc="none", color=pts[0].get_color(), label=f"|z| = {radius:.6g}")
    lim = 1.15 * max(1.0, float(np.max(np.abs(poles))) if poles.size else 1.0)
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_xlabel("Re z")
    ax.set_ylabel("Im z")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2)
    verdict = (f"spectral radius {radius:.6f} < 1: stable" if result.stable
               else f"spectral radius {radius:.6f} >= 1: UNSTABLE")
    verdict += f" (h = {result.period:g} s)"
    set_title(ax, f"{title}\n{verdict}" if title else verdict, fontsize=10)
    return save_figure(fig, path)


def plot_stability_map(smap: Any, path: str | Path | None = None, *, ax: Axes | None = None,
                       title: str | None = None) -> Figure:
    """The spectral abscissa over a parameter grid (clipped to ±10 1/s, with a colour bar), and the stability
    boundary (abscissa = 0) drawn where the grid crosses it.

    Parameters
    ----------
    smap : StabilityMap
        From :func:`delaykit.spectrum.stability.stability_map` (or a gain search's worst case).
    path : str or Path, optional
        Write the figure there.
    ax : Axes, optional
        Where to draw (the colour bar takes room from it).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> import numpy as np
    >>> from delaykit import AltitudeLoop
    >>> from delaykit.spectrum.stability import stability_map
    >>> m = stability_map(AltitudeLoop(kp=1, delay=0.3), "kp", np.linspace(0.5, 6, 12),
    ...                   "delay", np.linspace(0.1, 0.8, 8))
    >>> fig = plot_stability_map(m)
    >>> fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()
    ('kp', 'delay')
    """
    fig, (ax,), _ = _axes(ax, 1, (7, 5))
    a = np.clip(np.asarray(smap.abscissa, dtype=float), -10, 10)
    lim = max(1e-9, float(np.nanmax(np.abs(a)))) if np.any(np.isfinite(a)) else 1.0
    cs = ax.pcolormesh(smap.x, smap.y, a, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
    fig.colorbar(cs, ax=ax, label="spectral abscissa (1/s)")
    if np.any(a < 0) and np.any(a >= 0) and min(a.shape) > 1:
        ax.contour(smap.x, smap.y, a, levels=[0.0], colors="k", linewidths=1.5)
    ax.set_xlabel(smap.x_name)
    ax.set_ylabel(smap.y_name)
    set_title(ax, title or "stability map (black line: stability boundary)")
    return save_figure(fig, path)


def plot_fit(logs: Sequence, fits: Sequence, path: str | Path | None = None, *,
             ax: Axes | Sequence[Axes] | None = None, title: str | None = None,
             lower_label: str = "residual (mm)") -> Figure:
    """Measured altitude (dots) and a model (lines), one colour per flight, and the difference in millimetres.

    Parameters
    ----------
    logs : sequence of FlightLog
        The flights.
    fits : sequence of (t, z)
        Per flight, the model's altitude ``z`` at the log's own times ``t`` (from
        :func:`delaykit.identify.estimation.fitted_altitude`, or the reference itself).
    path : str or Path, optional
        Write the figure there.
    ax : Axes or (Axes, Axes), optional
        Where to draw: one Axes draws the data and the model only; two add the difference below.
    title : str, optional
        Title of the upper panel.
    lower_label : str
        Label of the lower panel (what the difference is).

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> from delaykit.identify.flightlog import synthetic_log
    >>> log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.37), 1.0, after=4.0)
    >>> fig = plot_fit([log], [(log.t, log.z_ref)])
    >>> len(fig.axes), len(fig.axes[0].lines)
    (2, 2)
    """
    if len(fits) != len(logs):
        raise InvalidValueError(f"one fit per flight: {len(logs)} flights, {len(fits)} fits")
    fig, axes, _ = _axes(ax, 2, (8, 6), sharex=True, height_ratios=[3, 1.3])
    ax1 = axes[0]
    ax2 = axes[1] if len(axes) > 1 else None
    for log, (t_fit, z_fit) in zip(logs, fits):
        t_fit, z_fit = np.asarray(t_fit, dtype=float), np.asarray(z_fit, dtype=float)
        if t_fit.shape != log.t.shape or z_fit.shape != log.z.shape:
            raise InvalidValueError(f"{log.name}: the model must be given at the log's {log.t.size} times, got "
                                    f"{t_fit.size} times and {z_fit.size} values")
        tt = log.t - log.step_time
        pts = ax1.plot(tt, log.z, ".", ms=3, label=f"{Path(log.name).name} (data)")
        c = pts[0].get_color()
        ax1.plot(t_fit - log.step_time, z_fit, "-", lw=1.2, color=c)
        if ax2 is not None:
            ax2.plot(tt, 1e3 * (log.z - z_fit), ".", ms=3, color=c)
    ax1.set_ylabel("altitude z (m)")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=7, ncol=2)
    set_title(ax1, title or "data (dots) and fitted model (lines)")
    if ax2 is not None:
        ax2.set_ylabel(lower_label)
        ax2.axhline(0, color="k", lw=0.6)
        ax2.grid(alpha=0.3)
    (ax2 if ax2 is not None else ax1).set_xlabel("time after the step (s)")
    return save_figure(fig, path)


def plot_filter_bode(report: Any, path: str | Path | None = None, *,
                     ax: Axes | Sequence[Axes] | None = None) -> Figure:
    """Bode plot of the derivative filter relative to a true differentiator, with its -3 dB cutoff, the PV loop's
    crossover, and the paper's quoted 5.68 rad/s marked.

    Parameters
    ----------
    report : FilterReport
        From :func:`delaykit.design.tuning.filter_analysis`.
    path : str or Path, optional
        Write the figure there.
    ax : Axes or (Axes, Axes), optional
        Where to draw: one Axes draws the gain only; two draw the gain and the phase.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit.design.tuning import filter_analysis
    >>> fig = plot_filter_bode(filter_analysis(38.0, 1.0))
    >>> abs(float(fig.axes[0].lines[0].get_ydata()[0])) < 1e-3   # 0 dB at 0.1 rad/s: a true derivative there
    True
    """
    from ..design.tuning import filter_frequency_response

    w = np.logspace(-1, 3, 2000)
    H = filter_frequency_response(report.wn, report.zeta, w)
    fig, axes, _ = _axes(ax, 2, (7, 5), sharex=True)
    axes[0].semilogx(w, 20 * np.log10(np.abs(H)), label="|W(jw)| / w")
    if len(axes) > 1:
        axes[1].semilogx(w, np.degrees(np.angle(H)), label="phase")
    for a in axes:
        a.axvline(report.lowpass_cutoff, color="C1", ls="--", lw=1, label=f"-3 dB: {report.lowpass_cutoff:.2f} rad/s")
        a.axvline(report.paper_cutoff, color="C3", ls=":", lw=1,
                  label=f"paper's 'cutoff': {report.paper_cutoff:g} rad/s")
        if report.crossover:
            a.axvline(report.crossover, color="C2", ls="-.", lw=1,
                      label=f"PV loop crossover: {report.crossover:.2f} rad/s")
        a.grid(alpha=0.3, which="both")
    axes[0].set_ylabel("gain vs. true velocity (dB)")
    if len(axes) > 1:
        axes[1].set_ylabel("phase lag (deg)")
    axes[-1].set_xlabel("frequency (rad/s)")
    axes[0].legend(fontsize=8)
    set_title(axes[0], f"derivative filter wf = {report.wn:g} rad/s, zf = {report.zeta:g}")
    return save_figure(fig, path, dpi=110)


def plot_iterations(iterations: Sequence[complex], path: str | Path | None = None, *, ax: Axes | None = None,
                    reference: float | None = None, reference_label: str = "paper",
                    title: str | None = None) -> Figure:
    """The iterates of a delay estimate (real and imaginary parts against the iteration number), as the paper's
    Fig. 7, with an optional horizontal reference (the printed value).

    Parameters
    ----------
    iterations : sequence of complex
        The iterates, first to last (from :func:`delaykit.identify.estimation.lambert_paper_iterations`).
    path : str or Path, optional
        Write the figure there.
    ax : Axes, optional
        Where to draw.
    reference : float, optional
        A value to mark (dotted).
    reference_label : str
        Its legend entry (the value is appended).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> fig = plot_iterations([0.2, 0.3 - 0.2j, 0.3743 - 0.2507j], reference=0.374)
    >>> [line.get_ydata().tolist() for line in fig.axes[0].lines[:2]]
    [[0.2, 0.3, 0.3743], [0.0, -0.2, -0.2507]]
    """
    fig, (ax,), _ = _axes(ax, 1, (7, 4))
    z = np.asarray(iterations, dtype=complex)
    k = np.arange(z.size)
    ax.plot(k, z.real, "o-", label="Re Td")
    ax.plot(k, z.imag, "s-", label="Im Td")
    if reference is not None:
        ax.axhline(reference, color="k", ls=":", lw=0.8, label=f"{reference_label}: {reference:g} s")
    ax.set_xlabel(f"iteration (from Td = {z[0].real:g} s)" if z.size else "iteration")
    ax.set_ylabel("Td (s)")
    set_title(ax, title or "the iterates of the delay")
    ax.legend()
    ax.grid(alpha=0.3)
    return save_figure(fig, path, dpi=110)
