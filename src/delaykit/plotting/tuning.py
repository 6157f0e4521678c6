"""Figures of a PID tuning (:func:`delaykit.design.pid.tune`): the stable region of PI gains with the Ms
contour and the chosen point, and the Nyquist curve with the Ms circle.

Examples
--------
>>> from delaykit import tune
>>> fig = plot_tuning_nyquist(tune("1/s", "pi", delay=0.37, ms=1.4))
>>> len(fig.axes)
1
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import InvalidValueError
from .figures import _axes, save_figure
from .frequency import plot_nyquist

__all__ = ["plot_stable_region", "plot_tuning_nyquist", "plot_tuning"]


def plot_stable_region(tuning: Any, path: str | Path | None = None, *, ax: Axes | None = None, n: int = 41,
                       span: float = 2.5) -> Figure:
    """The certified stable region of PI gains ``(kp, ki)`` (shaded), the contour ``Ms = ms`` and the chosen point.

    The grid runs from 0 to ``span`` times the chosen gains (``n`` by ``n`` points); stability is the certified
    spectral abscissa (:func:`~delaykit.spectrum.stability.stability_map`), Ms the exact frequency response on a
    dense grid (:func:`~delaykit.design.pid_optimise.ms_map`).

    Examples
    --------
    >>> from delaykit import tune
    >>> fig = plot_stable_region(tune("1/s", "pi", delay=0.37, ms=1.4), n=9)
    >>> fig.axes[0].get_xlabel()
    'kp'
    """
    from ..design.pid_optimise import ms_map
    from ..spectrum.stability import stability_map

    if tuning.kind != "pi":
        raise InvalidValueError(f"the (kp, ki) region is drawn for a pi tuning, not {tuning.kind}")
    fig, (a,), _ = _axes(ax, 1, (6.0, 4.5))
    loop = tuning.loop.replace(period=None) if tuning.loop.sampled else tuning.loop
    kps = np.linspace(0.0, span * tuning.kp, n)[1:]
    kis = np.linspace(0.0, span * tuning.ki, n)[1:]
    sm = stability_map(loop.replace(antiwindup="none"), "kp", kps, "ki", kis)
    ms = ms_map(loop, kps, kis)
    stable = sm.stable
    # the edge is the zero contour of the spectral abscissa, interpolated between grid points (the contour of the
    # stable/unstable booleans would be a staircase of half cells)
    absc = np.where(np.isfinite(sm.abscissa), sm.abscissa, np.nanmax(np.abs(sm.abscissa[np.isfinite(sm.abscissa)]),
                                                                       initial=1.0))
    floor = min(float(absc.min()), -1.0)
    a.contourf(kps, kis, absc, levels=[2.0 * floor, 0.0], colors=["#cfe8cf"])
    a.contour(kps, kis, absc, levels=[0.0], colors="tab:green", linewidths=1.0)
    level = tuning.ms_limit or tuning.ms
    cs = a.contour(kps, kis, np.where(stable, ms, np.nan), levels=[level], colors="tab:blue", linewidths=1.2)
    a.clabel(cs, fmt={level: f"Ms = {level:.3g}"}, fontsize=8)
    a.plot([tuning.kp], [tuning.ki], "o", color="tab:red", label=f"{tuning.how}: kp={tuning.kp:.3g}, ki={tuning.ki:.3g}")
    a.set_xlabel("kp")
    a.set_ylabel("ki (1/s)")
    a.set_title("stable PI gains (shaded) and the Ms contour")
    a.legend(fontsize=8, loc="upper right")
    a.grid(alpha=0.3)
    return save_figure(fig, path)


def plot_tuning_nyquist(tuning: Any, path: str | Path | None = None, *, ax: Axes | None = None,
                        radius: float = 2.0) -> Figure:
    """The tuned loop's Nyquist curve with the circle ``|1 + L| = 1/Ms`` (centre -1) of its Ms limit (or its Ms).

    Examples
    --------
    >>> from delaykit import tune
    >>> fig = plot_tuning_nyquist(tune("1/s", "pi", delay=0.37, rule="amigo"))
    >>> fig.axes[0].get_aspect()
    1.0
    """
    from ..spectrum.frequency import frequency_grid, frequency_response

    loop = tuning.loop.replace(period=None) if tuning.loop.sampled else tuning.loop
    fr = frequency_response(loop, frequency_grid(loop, 3000))
    fig = plot_nyquist(fr, ax=ax, labels=[f"{tuning.how} {tuning.kind}"], radius=radius)
    a = fig.axes[0] if ax is None else ax
    level = tuning.ms_limit or tuning.ms
    t = np.linspace(0.0, 2 * np.pi, 361)
    a.plot(-1.0 + np.cos(t) / level, np.sin(t) / level, color="tab:blue", lw=1.0, ls=":",
           label=f"|1 + L| = 1/{level:.3g}")
    a.legend(fontsize=8)
    return save_figure(fig, path)


def plot_tuning(tuning: Any, path: str | Path | None = None) -> Figure:
    """The Nyquist curve with the Ms circle and, for a PI tuning, the stable region beside it.

    Examples
    --------
    >>> from delaykit import tune
    >>> len(plot_tuning(tune("1/s", "pd", delay=0.37, ms=1.4)).axes)
    1
    """
    if tuning.kind == "pi":
        fig = Figure(figsize=(11.0, 5.0), layout="constrained")
        a, b = fig.subplots(1, 2)
        plot_stable_region(tuning, ax=a)
        plot_tuning_nyquist(tuning, ax=b)
    else:
        fig = plot_tuning_nyquist(tuning)
    return save_figure(fig, path)
