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

from .simulation import Response  # noqa: E402

__all__ = ["plot_responses"]


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
