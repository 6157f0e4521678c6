"""The root locus of a delay loop (computed by :func:`delaykit.spectrum.locus.root_locus`) in the complex plane.

Like the other plot functions: draws on the axes given (or a new :class:`matplotlib.figure.Figure`), returns the
figure, writes it to ``path`` only when one is given, and chooses no backend.

Examples
--------
>>> import numpy as np
>>> from delaykit import root_locus
>>> fig = plot_root_locus(root_locus("exp(-s)/s", gains=np.linspace(0.2, 3.0, 15)))
>>> fig.axes[0].get_xlabel()
'Re s'
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import InvalidTypeError
from ..spectrum.locus import RootLocus
from .figures import _axes, save_figure, set_title

__all__ = ["plot_root_locus"]


def plot_root_locus(result: RootLocus, path: str | Path | None = None, *, ax: Axes | None = None,
                    title: str | None = None, cmap: str = "viridis") -> Figure:
    """The roots at every value of the locus as points coloured by the parameter (a colour bar names it), the
    imaginary-axis crossings marked ``x`` at ``+-j w`` with their parameter values, the stable half-plane shaded.

    Parameters
    ----------
    result : RootLocus
        From :func:`~delaykit.spectrum.locus.root_locus`.
    path : str or Path, optional
        Write the figure there.
    ax : Axes, optional
        Where to draw.
    title : str, optional
        Figure title (default: the parameter and the stable intervals).
    cmap : str
        The colour map of the parameter.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> import numpy as np
    >>> from delaykit import root_locus
    >>> loc = root_locus(([0.5], [1.0, 0.1, 1.0]), delays=np.linspace(0.0, 8.0, 41))
    >>> fig = plot_root_locus(loc)
    >>> n = int(np.isfinite(loc.roots).sum())
    >>> fig.axes[0].collections[0].get_offsets().shape[0] == n, len(fig.axes)  # the points; the colour bar
    (True, 2)
    """
    if not isinstance(result, RootLocus):
        raise InvalidTypeError(f"result must be a RootLocus (from root_locus), got {type(result).__name__}")
    fig, (ax,), _ = _axes(ax, 1, (7, 6))
    x0, x1, y0, y1 = result.region
    ax.axvspan(x0, min(0.0, x1), color="#e8f4e8", zorder=0, label="stable half-plane")
    ax.axvline(0.0, color="k", lw=0.8)
    vals = np.broadcast_to(result.values[:, None], result.roots.shape)
    ok = np.isfinite(result.roots)
    pts = ax.scatter(result.roots.real[ok], result.roots.imag[ok], c=vals[ok], s=6, cmap=cmap,
                     vmin=float(result.values[0]), vmax=float(result.values[-1]), zorder=2)
    fig.colorbar(pts, ax=ax, label=result.parameter)
    at: dict[float, list[float]] = {}  # the crossings by frequency (a delay's switches repeat at one frequency)
    for c in result.crossings:
        at.setdefault(c.frequency, []).append(c.value)
    for i, (w, values) in enumerate(sorted(at.items())):
        ws = [w, -w] if w > 0 else [0.0]
        ax.plot([0.0] * len(ws), ws, "x", color="C3", ms=9, mew=2, zorder=3,
                label="axis crossings" if i == 0 else None)
        ax.annotate(", ".join(f"{v:.4g}" for v in values), (0.0, w), textcoords="offset points", xytext=(5, 4),
                    fontsize=8)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_xlabel("Re s")
    ax.set_ylabel("Im s")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    iv = ", ".join(f"[{lo:.4g}, {hi:.4g}]" for lo, hi in result.stable_intervals) or "nowhere"
    set_title(ax, title if title is not None else f"root locus over the {result.parameter}: stable on {iv}")
    return save_figure(fig, path)
