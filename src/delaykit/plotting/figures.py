"""Figures (matplotlib, drawn off-screen).  Computation lives elsewhere; these only draw.

Examples
--------
>>> import tempfile, os
>>> from delaykit import AltitudeLoop, simulate
>>> path = os.path.join(tempfile.mkdtemp(), "r.png")
>>> plot_responses([simulate(AltitudeLoop(kp=1.31, delay=0.368))], path)
>>> os.path.getsize(path) > 0
True
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..simulate.simulation import Response  # noqa: E402

__all__ = ["plot_responses", "plot_spectrum", "plot_stability_map", "plot_fit", "plot_filter_bode"]


def plot_responses(
    responses: Sequence[Response],
    path: str | Path,
    *,
    labels: Sequence[str] | None = None,
    title: str | None = None,
    dt: float = 0.005,
    t_max: float | None = None,
) -> None:
    """Altitude and command of one or more responses, saved to ``path`` (PNG, PDF or SVG by suffix).

    Parameters
    ----------
    responses : sequence of Response
        The responses to draw.
    path : str or Path
        Output file.
    labels : sequence of str, optional
        Legend entries; by default the delay (and Kv) of each loop.
    title : str, optional
        Figure title.
    dt : float
        Drawing resolution, seconds.
    t_max : float, optional
        Draw up to this time after the step (default: each response's whole length).
    """
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=[3, 1.4])
    for i, r in enumerate(responses):
        s = r.sample(dt=dt)
        lab = labels[i] if labels else (f"Td={r.loop.delay:.4g} s" + (f", Kv={r.loop.kv:g}" if r.loop.kv else ""))
        (line,) = ax1.plot(s["t"], s["z"], lw=1.4, label=lab)
        ax2.plot(s["t"], s["u"], lw=1.0, color=line.get_color())
    if responses:
        r0 = responses[0]
        ref = r0.z0 + r0.step
        ax1.axhline(ref, color="k", lw=0.6, ls="--")
        band = r0.metrics.band * abs(r0.step)
        ax1.axhspan(ref - band, ref + band, color="0.85", zorder=0, label=f"±{100 * r0.metrics.band:g} % band")
    if t_max is not None:
        ax2.set_xlim(-0.05 * t_max, t_max)
    ax1.set_ylabel("altitude z (m)")
    ax2.set_ylabel("command u (m/s)")
    ax2.set_xlabel("time after the step (s)")
    ax1.grid(alpha=0.3)
    ax2.grid(alpha=0.3)
    ax1.legend(fontsize=8, ncol=2)
    if title:
        ax1.set_title(title)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_spectrum(
    spectra: Sequence,
    path: str | Path,
    *,
    labels: Sequence[str] | None = None,
    title: str | None = None,
) -> None:
    """Roots in the complex plane, as in the paper's Fig. 8: roots, neutral lines, the stable half-plane shaded.

    Parameters
    ----------
    spectra : sequence of Spectrum
        Results of :func:`delaykit.spectrum.roots.find_roots` (one per loop).
    path : str or Path
        Output file.
    labels : sequence of str, optional
        Legend entries.
    title : str, optional
        Figure title.

    Examples
    --------
    >>> import tempfile, os
    >>> from delaykit import AltitudeLoop
    >>> from delaykit.spectrum.roots import find_roots
    >>> sp = find_roots(AltitudeLoop(kp=2, delay=0.37, kv=0.3).characteristic(), (-10, 2, 0, 100))
    >>> path = os.path.join(tempfile.mkdtemp(), "s.png")
    >>> plot_spectrum([sp], path)
    >>> os.path.getsize(path) > 0
    True
    """
    fig, ax = plt.subplots(figsize=(7, 6))
    markers = "oxs^vD+*"
    x0 = min(sp.region[0] for sp in spectra)
    x1 = max(sp.region[1] for sp in spectra)
    y1 = max(sp.region[3] for sp in spectra)
    y0 = min(sp.region[2] for sp in spectra)
    ax.axvspan(x0, 0.0, color="#e8f4e8", zorder=0, label="stable half-plane")
    ax.axvline(0.0, color="k", lw=0.8)
    for i, sp in enumerate(spectra):
        lab = labels[i] if labels else None
        pts = ax.plot(sp.roots.real, sp.roots.imag, markers[i % len(markers)], ms=5, mfc="none", label=lab)
        color = pts[0].get_color()
        for xline in sp.neutral_lines:
            ax.axvline(xline, color=color, ls="--", lw=0.8)
        rm = sp.rightmost
        if rm is not None:
            ax.plot([rm.real], [rm.imag], markers[i % len(markers)], ms=9, color=color)
        for z, m in zip(sp.roots, sp.multiplicities):
            if m > 1:
                ax.annotate(f"×{m}", (z.real, z.imag), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_xlabel("Re s")
    ax.set_ylabel("Im s (conjugates not shown)" if y0 >= 0 else "Im s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_stability_map(smap, path: str | Path, *, title: str | None = None) -> None:
    """The spectral abscissa over a parameter grid, with the stability boundary (abscissa = 0) drawn.

    Examples
    --------
    >>> import tempfile, os, numpy as np
    >>> from delaykit import AltitudeLoop
    >>> from delaykit.spectrum.stability import stability_map
    >>> m = stability_map(AltitudeLoop(kp=1, delay=0.3), "kp", np.linspace(0.5, 6, 12), "delay", np.linspace(0.1, 0.8, 8))
    >>> path = os.path.join(tempfile.mkdtemp(), "m.png")
    >>> plot_stability_map(m, path)
    >>> os.path.getsize(path) > 0
    True
    """
    fig, ax = plt.subplots(figsize=(7, 5))
    a = np.clip(smap.abscissa, -10, 10)
    lim = max(1e-9, float(np.nanmax(np.abs(a))))
    cs = ax.pcolormesh(smap.x, smap.y, a, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
    fig.colorbar(cs, ax=ax, label="spectral abscissa (1/s)")
    if np.any(a < 0) and np.any(a >= 0) and min(a.shape) > 1:
        ax.contour(smap.x, smap.y, a, levels=[0.0], colors="k", linewidths=1.5)
    ax.set_xlabel(smap.x_name)
    ax.set_ylabel(smap.y_name)
    ax.set_title(title or "stability map (black line: stability boundary)")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_fit(logs: Sequence, fits: Sequence, path: str | Path, *, title: str | None = None,
             lower_label: str = "residual (mm)") -> None:
    """Measured altitude, the fitted model, and the residuals, one colour per flight.

    ``fits`` holds, per flight, ``(t, z_fit)`` on the log's own times (from
    :func:`delaykit.identify.estimation.fitted_altitude`).
    """
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, height_ratios=[3, 1.3])
    for log, (t, zf) in zip(logs, fits):
        tt = log.t - log.step_time
        pts = ax1.plot(tt, log.z, ".", ms=3, label=f"{Path(log.name).name} (data)")
        c = pts[0].get_color()
        ax1.plot(tt, zf, "-", lw=1.2, color=c)
        ax2.plot(tt, 1e3 * (log.z - zf), ".", ms=3, color=c)
    ax1.set_ylabel("altitude z (m)")
    ax2.set_ylabel(lower_label)
    ax2.set_xlabel("time after the step (s)")
    ax2.axhline(0, color="k", lw=0.6)
    ax1.grid(alpha=0.3)
    ax2.grid(alpha=0.3)
    ax1.legend(fontsize=7, ncol=2)
    ax1.set_title(title or "data (dots) and fitted model (lines)")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_filter_bode(report, path: str | Path) -> None:
    """Bode plot of the derivative filter relative to a true differentiator, with its cutoff, the PV loop's
    crossover, and the paper's quoted 5.68 rad/s marked (``report`` from
    :func:`delaykit.design.tuning.filter_analysis`)."""
    from ..design.tuning import filter_frequency_response

    w = np.logspace(-1, 3, 2000)
    H = filter_frequency_response(report.wn, report.zeta, w)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    a1.semilogx(w, 20 * np.log10(np.abs(H)))
    a2.semilogx(w, np.degrees(np.angle(H)))
    for ax in (a1, a2):
        ax.axvline(report.lowpass_cutoff, color="C1", ls="--", lw=1, label=f"-3 dB: {report.lowpass_cutoff:.2f} rad/s")
        ax.axvline(report.paper_cutoff, color="C3", ls=":", lw=1, label=f"paper's 'cutoff': {report.paper_cutoff:g} rad/s")
        if report.crossover:
            ax.axvline(report.crossover, color="C2", ls="-.", lw=1, label=f"PV loop crossover: {report.crossover:.2f} rad/s")
        ax.grid(alpha=0.3, which="both")
    a1.set_ylabel("gain vs. true velocity (dB)")
    a2.set_ylabel("phase lag (deg)")
    a2.set_xlabel("frequency (rad/s)")
    a1.legend(fontsize=8)
    a1.set_title(f"derivative filter wf = {report.wn:g} rad/s, zf = {report.zeta:g}")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
