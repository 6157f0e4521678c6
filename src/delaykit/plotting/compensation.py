"""Figures of delay compensation: the robustness map of a compensated loop, and the delay watched in flight.

Examples
--------
>>> import matplotlib
>>> from delaykit.design.compensators import robustness_map
>>> from delaykit.models.compensators import Compensator
>>> fig = plot_robustness_map(robustness_map(Compensator.smith("1/s", 0.37), [0.8, 1.0, 1.2], [0.9, 1.1]))
>>> fig.axes[0].get_xlabel()
'true / model gain'
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .figures import _axes, save_figure, set_title

__all__ = ["plot_robustness_map", "plot_online"]


def plot_robustness_map(rmap: Any, path: str | Path | None = None, *, ax: Any = None, title: str | None = None) -> Any:
    """The spectral abscissa of a compensated loop over true/model delay and gain ratios, with the
    stability boundary (abscissa = 0) drawn and the design point (1, 1) marked.

    Parameters
    ----------
    rmap : RobustnessMap
        From :func:`delaykit.design.compensators.robustness_map`.
    path : str or Path, optional
        Save the figure here.
    ax : matplotlib Axes, optional
        Draw into these axes.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    See the module docstring.
    """
    fig, axes, _ = _axes(ax, 1, (6.4, 4.8))
    ax = axes[0]
    a = np.asarray(rmap.abscissa, dtype=float)
    finite = a[np.isfinite(a)]
    # a symmetric scale as wide as the data (a heater's roots lie within 0.01 1/s of the axis, a drone's within 5)
    lim = max(float(np.max(np.abs(finite))), 1e-12) if finite.size else 1.0
    a = np.clip(a, -lim, lim)
    g, d = np.meshgrid(rmap.gain_ratios, rmap.delay_ratios)
    mesh = ax.pcolormesh(g, d, a, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
    if a.shape[0] > 1 and a.shape[1] > 1 and a.min() < 0 < a.max():
        ax.contour(g, d, rmap.abscissa, levels=[0.0], colors="k", linewidths=1.5)
    ax.plot([1.0], [1.0], marker="*", color="gold", markersize=12, markeredgecolor="k", linestyle="none",
            label="design point")
    ax.set_xlabel("true / model gain")
    ax.set_ylabel("true / model delay")
    set_title(ax, title or f"{rmap.kind}: spectral abscissa (1/s), stable where blue")
    fig.colorbar(mesh, ax=ax, label="rightmost root real part (1/s)")
    ax.legend(loc="upper right")
    if path is not None:
        save_figure(fig, path)
    return fig


def plot_online(online: Any, path: str | Path | None = None, *, ax: Any = None, t0: float = 0.0,
                truth: Any = None, title: str | None = None) -> Any:
    """The delay re-estimated after each step of a flight: each estimate with its 95 % interval over the step's
    window, the design range it was judged against (shaded), alarms marked, and the true delay when known.

    Parameters
    ----------
    online : sequence of OnlineEstimate
        From :attr:`delaykit.hardware.flight.FlightResult.online`.
    path : str or Path, optional
        Save the figure here.
    ax : matplotlib Axes, optional
        Draw into these axes.
    t0 : float
        The monotonic time shown as 0 (e.g. the emulator's start).
    truth : sequence of (float, float), optional
        The true delay as ``(time since t0, delay)`` changes (a step function).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> est = NS(delay=0.3, ci=(0.29, 0.31), t_from=1.0, t_to=4.0)
    >>> fig = plot_online([NS(estimate=est, delay=0.3, design_range=(0.2, 0.35), alarm=False)], truth=[(0, 0.3)])
    >>> fig.axes[0].get_ylabel()
    'loop delay (s)'
    """
    fig, axes, _ = _axes(ax, 1, (7.0, 4.0))
    ax = axes[0]
    for k, o in enumerate(online):
        a, b = o.estimate.t_from - t0, o.estimate.t_to - t0
        lo, hi = o.design_range
        ax.fill_between([a, b], [lo, lo], [min(hi, 5.0)] * 2, color="tab:green", alpha=0.15, linewidth=0,
                        label="design range" if k == 0 else None)
        mid = 0.5 * (a + b)
        c = "tab:red" if o.alarm else "tab:blue"
        ax.errorbar([mid], [o.delay], yerr=[[o.delay - o.estimate.ci[0]], [o.estimate.ci[1] - o.delay]], fmt="o",
                    color=c, capsize=3, label=("estimate (alarm)" if o.alarm else "estimate, 95 % interval")
                    if k == next(i for i, x in enumerate(online) if x.alarm == o.alarm) else None)
        ax.plot([a, b], [o.delay, o.delay], color=c, linewidth=1)
    if truth:
        ts = [float(t) for t, _ in truth]
        ds = [float(d) for _, d in truth]
        end = max([ts[-1] + 1.0] + [o.estimate.t_to - t0 for o in online])
        ax.step(ts + [end], ds + [ds[-1]], where="post", color="k", linestyle="--", label="true delay")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("loop delay (s)")
    set_title(ax, title or "the delay re-estimated after each step")
    ax.legend(loc="best", fontsize="small")
    if path is not None:
        save_figure(fig, path)
    return fig
