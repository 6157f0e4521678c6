"""Figures of identification: a model's free-run prediction over measured logs.

Examples
--------
>>> import numpy as np
>>> from delaykit.identify import Experiment, identify, predict
>>> t = np.arange(0, 60.0, 0.5); u = np.where(t >= 5, 1.0, 0.0)
>>> e = Experiment.from_arrays(t, {"y": 2 * (1 - np.exp(-np.maximum(t - 8, 0) / 10))}, u=u)
>>> fig = plot_predictions([predict(identify(e, model="fopdt"), e)])
>>> len(fig.axes[0].lines), [ax.get_ylabel() for ax in fig.axes]
(2, ['y', 'residual y (measured - predicted)', 'input u'])
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from matplotlib.figure import Figure

from .figures import _axes, save_figure, set_title

__all__ = ["plot_predictions", "model_title"]


def model_title(model: Any) -> str:
    """A one-line title for an identified model's figure: the structure and its parameters to 4 digits, with their
    units, then the fit's rms and the number of logs (the standard errors are left to the printed table).

    Parameters
    ----------
    model : IdentifiedModel
        From :func:`delaykit.identify.identify`.

    Returns
    -------
    str

    Examples
    --------
    >>> import numpy as np
    >>> from delaykit.identify import Experiment, identify
    >>> t = np.arange(0, 60.0, 0.5); u = np.where(t >= 5, 1.0, 0.0)
    >>> e = Experiment.from_arrays(t, {"y": 2 * (1 - np.exp(-np.maximum(t - 8, 0) / 10))}, u=u)
    >>> model_title(identify(e, model="fopdt"))[:50]
    'fopdt: gain 2, time constant 10 s, delay 3 s (rms '
    """
    parts = []
    for p, u in zip(model.structure.params, model.structure.units):
        unit = f" {u}" if u in ("s", "rad/s") else ""
        parts.append(f"{p.replace('_', ' ')} {model.params[p]:.4g}{unit}")
    n = len(model.logs)
    return f"{model.model}: {', '.join(parts)} (rms {model.rms:.3g}, {n} log{'' if n == 1 else 's'})"


def plot_predictions(predictions: Sequence[Any], *, ax: Any = None, path: str | Path | None = None,
                     title: str | None = None) -> Figure:
    """Measured outputs and a model's free-run predictions (one pair of lines per log, first output), the
    residuals (measured - predicted) and the logs' input or reference, held between samples: three panels.

    Parameters
    ----------
    predictions : sequence of Prediction
        From :func:`delaykit.identify.predict`.
    ax : matplotlib Axes or sequence of Axes, optional
        Draw here: one Axes draws the outputs only, two add the residuals, three the input (a new figure
        otherwise).
    path : str or Path, optional
        Save the figure here.
    title : str, optional
        The figure's title (wrapped to the figure's width).

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, axes, _ = _axes(ax, 3, (8, 7.5), sharex=True, height_ratios=[3, 1.4, 1.4])
    top = axes[0]
    res = axes[1] if len(axes) > 1 else None
    drv = axes[2] if len(axes) > 2 else None
    for p in predictions:
        out = next(iter(p.rms))
        t = p.t - p.t[0]
        line, = top.plot(t, p.measured[out], lw=1.0, alpha=0.8, label=f"{p.file} measured")
        top.plot(t, p.predicted[out], lw=1.5, ls="--", color=line.get_color(),
                 label=f"predicted (rms {p.rms[out]:.3g})")
        if res is not None:
            res.plot(t, p.measured[out] - p.predicted[out], lw=0.8, color=line.get_color())
        if drv is not None and p.drive is not None:
            drv.plot(t, p.drive, lw=1.0, color=line.get_color(), drawstyle="steps-post")
    axes[-1].set_xlabel("time from the log's start (s)")
    if predictions:
        out = next(iter(predictions[0].rms))
        top.set_ylabel(out)
        if res is not None:
            res.set_ylabel(f"residual {out} (measured - predicted)")
            res.axhline(0.0, color="k", lw=0.6)
        if drv is not None:
            names = sorted({p.drive_name for p in predictions if p.drive is not None})
            kinds = sorted({p.drive_kind for p in predictions if p.drive is not None})
            drv.set_ylabel(f"{' / '.join(kinds) or 'input'} {', '.join(names) if names else '(not logged)'}")
    for a in axes:
        a.grid(alpha=0.3)
    if title:
        set_title(top, title, fontsize=10)
    if 0 < len(predictions) <= 6:  # a legend of nothing would only warn
        top.legend(fontsize=7)
    return save_figure(fig, path)

