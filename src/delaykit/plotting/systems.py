"""Figures of a delay system's time responses: the step (or impulse) response of each input, every output.

Examples
--------
>>> from delaykit import tf
>>> r = tf([["exp(-s)/(s+1)", "0.5/(2*s+1)"]], inputs=["a", "b"], outputs="y").step([0.0, 1.0, 2.0, 4.0])
>>> fig = plot_system_response(r, title="two lags")
>>> [ax.get_title() for ax in fig.axes], fig.axes[0].get_ylabel(), fig.get_suptitle()
(['step of a', 'step of b'], 'output', 'two lags')
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from matplotlib.figure import Figure

from ..errors import InvalidTypeError, InvalidValueError
from .figures import _axes, save_figure

__all__ = ["plot_system_response"]


def plot_system_response(response: Any, *, ax: Any = None, path: str | Path | None = None,
                         title: str | None = None) -> Figure:
    """A :class:`~delaykit.simulate.systems.SystemTimeResponse`: for a step or an impulse one panel per input, each
    output a line (python-control's ``(outputs, inputs, times)`` layout), side by side; for an initial or forced
    response one panel, each output a line.

    Parameters
    ----------
    response : SystemTimeResponse
        From :func:`delaykit.simulate.systems.step_response` (or ``impulse_response``, or ``sys.step(T)``).
    ax : matplotlib Axes or sequence of Axes, optional
        One per input (a new figure otherwise).
    path : str or Path, optional
        Save the figure here.
    title : str, optional
        Above the panels (with the response's status when it stopped early).

    Returns
    -------
    matplotlib.figure.Figure
    """
    out = getattr(response, "outputs", None)
    if out is None or not hasattr(response, "time"):
        raise InvalidTypeError(f"expected a SystemTimeResponse, got {type(response).__name__}")
    if out.ndim == 2:  # an initial or forced response: one panel, each output a line
        out = out[:, None, :]
        response_inputs = ("the input",) if getattr(response, "kind", "") == "forced" else ("X0",)
    elif out.ndim == 3:
        response_inputs = tuple(response.input_labels)
    else:
        raise InvalidValueError("plot_system_response draws outputs x inputs x times (a step or impulse) or outputs x "
                                f"times (an initial or forced response); got outputs of shape {out.shape}")
    ny, nu, _ = out.shape
    if ax is None:
        fig = Figure(figsize=(min(4.2 * max(nu, 1), 13.0), 3.6), layout="tight")
        axes = list(fig.subplots(1, max(nu, 1), squeeze=False, sharey=True)[0])
    else:
        fig, axes, _ = _axes(ax, max(nu, 1), (4.2, 3.6))
    kind = getattr(response, "kind", "step")
    for j, a in enumerate(axes[:nu]):
        for i in range(ny):
            a.plot(response.time, out[i, j], lw=1.3, label=response.output_labels[i])
        a.set_title(f"{kind} of {response_inputs[j]}" if kind in ("step", "impulse") else f"{kind} response")
        a.set_xlabel("time t")
        a.grid(alpha=0.3)
        if kind == "step":
            a.axhline(1.0, color="0.5", ls="--", lw=0.8)
    axes[0].set_ylabel("output")
    if 0 < ny <= 8:
        axes[0].legend(fontsize=8)
    status = getattr(response, "status", "exact")
    if title or status != "exact":
        text = (title or "") + ("" if status == "exact" else f" (stopped early: {status} at t = {response.t_reached:g})")
        fig.suptitle(text.strip(), fontsize=11)
    return save_figure(fig, path)
