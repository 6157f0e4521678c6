"""Figures of delay compensation: the robustness map of a compensated loop.

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

from .figures import _axes, save_figure

__all__ = ["plot_robustness_map"]


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
    a = np.clip(rmap.abscissa, -5.0, 5.0)
    g, d = np.meshgrid(rmap.gain_ratios, rmap.delay_ratios)
    mesh = ax.pcolormesh(g, d, a, cmap="RdBu_r", vmin=-5.0, vmax=5.0, shading="auto")
    if a.shape[0] > 1 and a.shape[1] > 1 and a.min() < 0 < a.max():
        ax.contour(g, d, rmap.abscissa, levels=[0.0], colors="k", linewidths=1.5)
    ax.plot([1.0], [1.0], marker="*", color="gold", markersize=12, markeredgecolor="k", linestyle="none",
            label="design point")
    ax.set_xlabel("true / model gain")
    ax.set_ylabel("true / model delay")
    ax.set_title(title or f"{rmap.kind}: spectral abscissa (1/s), stable where blue")
    fig.colorbar(mesh, ax=ax, label="rightmost root real part (clipped to ±5)")
    ax.legend(loc="upper right")
    if path is not None:
        save_figure(fig, path)
    return fig
