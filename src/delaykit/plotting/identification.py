"""Figures of identification: a model's free-run prediction over measured logs.

Examples
--------
>>> import numpy as np
>>> from delaykit.identify import Experiment, identify, predict
>>> t = np.arange(0, 60.0, 0.5); u = np.where(t >= 5, 1.0, 0.0)
>>> e = Experiment.from_arrays(t, {"y": 2 * (1 - np.exp(-np.maximum(t - 8, 0) / 10))}, u=u)
>>> fig = plot_predictions([predict(identify(e, model="fopdt"), e)])
>>> len(fig.axes[0].lines)
2
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from matplotlib.figure import Figure

from .figures import _axes, save_figure

__all__ = ["plot_predictions"]


def plot_predictions(predictions: Sequence[Any], *, ax: Any = None, path: str | Path | None = None,
                     title: str | None = None) -> Figure:
    """Measured outputs and a model's free-run predictions, one pair of lines per log (first output).

    Parameters
    ----------
    predictions : sequence of Prediction
        From :func:`delaykit.identify.predict`.
    ax : matplotlib Axes, optional
        Draw here (a new figure otherwise).
    path : str or Path, optional
        Save the figure here.
    title : str, optional
        The axes' title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, (ax,), _ = _axes(ax, 1, (8, 4.5))
    for p in predictions:
        out = next(iter(p.rms))
        t = p.t - p.t[0]
        line, = ax.plot(t, p.measured[out], lw=1.0, alpha=0.8, label=f"{p.file} measured")
        ax.plot(t, p.predicted[out], lw=1.5, ls="--", color=line.get_color(),
                label=f"predicted (rms {p.rms[out]:.3g})")
    ax.set_xlabel("time from the log's start (s)")
    if predictions:
        ax.set_ylabel(next(iter(predictions[0].rms)))
    if title:
        ax.set_title(title)
    if 0 < len(predictions) <= 6:  # a legend of nothing would only warn
        ax.legend(fontsize=7)
    return save_figure(fig, path)
