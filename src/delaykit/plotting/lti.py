"""Plots of any system: Bode, Nyquist, singular values, Nichols, a MIMO step-response grid and a pole map, for a
:class:`~delaykit.systems.DelayLTI`, a loop or a response object (python-control's ``bode_plot``, ``nyquist_plot``,
``singular_values_plot``, ``nichols_plot``, ``step_response(sys).plot()`` and ``pole_zero_plot``).

Everything drawn is computed exactly by the lower layers: a system's response element by element with
:func:`~delaykit.spectrum.frequency.frequency_response` (a rational function times one dead time has its phase in
closed form, ``arg N/D - w T``; any other element is unwrapped on a grid refined until the delays turn by 45 degrees
at most between points), so a delay's phase keeps falling over as many decades as asked, with no Padé
approximation; the Nyquist count from :func:`~delaykit.spectrum.systems.nyquist_count` (its open-loop pole count
certified); the poles from :func:`~delaykit.spectrum.systems.poles` (certified in the region drawn).  A
``SystemResponse`` given as it is has only its values: its phase is unwrapped between its own frequencies
(right when they are dense enough); give the system to have the exact phase.

Every function takes ``ax=`` (or makes a new :class:`~matplotlib.figure.Figure`), returns the figure, labels its
units (frequencies in rad/s, times in s: read "per time unit of the model" for a model in minutes) and writes a
file only when given ``path``; nothing chooses a backend.

Examples
--------
>>> from delaykit import tf
>>> G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
...         ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]], inputs=["R", "S"], outputs=["xD", "xB"])
>>> fig = bode_plot(G)
>>> len(fig.axes), fig.axes[0].get_title()
(8, 'from R')
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..errors import InvalidTypeError, InvalidValueError
from ..models.altitude import AltitudeLoop
from ..models.loop import Loop
from ..spectrum.frequency import FrequencyResponse
from .figures import _axes, save_figure
from .frequency import _labels, plot_bode, plot_nyquist

__all__ = ["bode_plot", "nyquist_plot", "sigma_plot", "nichols_plot", "step_grid", "pole_map"]

_POINTS = 1000  # frequencies of a default grid


@dataclass(frozen=True)
class _Data:
    """One object's frequency response, element by element: ``H[i, j, k]``, ``phase_deg`` the same shape."""

    w: np.ndarray
    H: np.ndarray
    phase_deg: np.ndarray
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    source: Any  # the loop or system (for margins, the Nyquist count), or None for a response given as it is

    def siso(self, k: int = 0) -> FrequencyResponse:
        with np.errstate(all="ignore"):
            mag = 20.0 * np.log10(np.abs(self.H[0, 0]))
        return FrequencyResponse(w=self.w, L=self.H[0, 0], magnitude_db=mag, phase_deg=self.phase_deg[0, 0])


def _is_system(x: Any) -> bool:
    from ..systems.lti import DelayLTI

    return isinstance(x, DelayLTI)


def _grid(sys: Any) -> np.ndarray:
    from ..spectrum.frequency import frequency_grid
    from ..spectrum.system_margins import system_frequency_grid

    if (sys.ninputs, sys.noutputs) == (1, 1):
        return frequency_grid(sys, _POINTS)
    return system_frequency_grid(sys.without_limits() if sys.saturations else sys, _POINTS)


def _data(x: Any, w: Any) -> _Data:
    """The exact frequency response of a system, loop or response object."""
    from ..spectrum.frequency import frequency_response
    from ..systems.lti import SystemResponse

    if isinstance(x, FrequencyResponse):
        return _Data(x.w, x.L[None, None], x.phase_deg[None, None], ("e",), ("L",), None)
    if isinstance(x, (Loop, AltitudeLoop)):
        r = frequency_response(x, w)
        return _Data(r.w, r.L[None, None], r.phase_deg[None, None], ("e",), ("L",), x)
    if isinstance(x, SystemResponse):
        order = np.argsort(x.omega, kind="stable")
        ph = np.empty(x.response.shape)
        ph[..., order] = np.degrees(np.unwrap(np.angle(x.response[..., order]), axis=-1))
        return _Data(x.omega, x.response, ph, tuple(x.inputs), tuple(x.outputs), None)
    if _is_system(x):
        ww = _grid(x) if w is None else w
        rows = [[frequency_response(x[i, j], ww) for j in range(x.ninputs)] for i in range(x.noutputs)]
        H = np.array([[r.L for r in row] for row in rows])
        ph = np.array([[r.phase_deg for r in row] for row in rows])
        return _Data(rows[0][0].w, H, ph, tuple(x.inputs), tuple(x.outputs), x)
    raise InvalidTypeError(f"expected a DelayLTI, a Loop, an AltitudeLoop, a FrequencyResponse or a SystemResponse, "
                           f"got {type(x).__name__}")


def _items(x: Any) -> list[Any]:
    """One object or a list or tuple of them (a DelayLTI is iterable by no one: it is one object)."""
    items = list(x) if isinstance(x, (list, tuple)) else [x]
    if not items:
        raise InvalidValueError("nothing to draw: give a system, a loop or a response (or a list of them)")
    return items


def _siso_items(x: Any, w: Any, what: str) -> list[_Data]:
    data = [_data(i, w) for i in _items(x)]
    for d in data:
        if d.H.shape[:2] != (1, 1):
            raise InvalidValueError(f"{what} draws SISO loops; got {d.H.shape[0]} outputs x {d.H.shape[1]} inputs "
                                    "(sigma_plot draws a MIMO system's gains, bode_plot each element)")
    return data


def _margins_of(d: _Data) -> Any:
    """The source's margins (SISO loop or system), or None when there is no source."""
    from ..spectrum.frequency import margins

    return None if d.source is None else margins(d.source)


def _one_axes(ax: Any, figsize: tuple[float, float]) -> tuple[Figure, Axes]:
    if ax is not None and not isinstance(ax, Axes):
        raise InvalidTypeError(f"ax must be a matplotlib Axes, got {type(ax).__name__}")
    fig, (a,), _ = _axes(ax, 1, figsize)
    return fig, a


# ---- Bode ----------------------------------------------------------------------------------------------------

def bode_plot(sys: Any, w: Any = None, *, ax: Any = None, margins: bool = False,
              labels: Sequence[str] | None = None, path: str | Path | None = None) -> Figure:
    """Bode plot (magnitude in dB, exact unwrapped phase in degrees, against log frequency in rad/s) of a system,
    loop or response, or of a list of them (all of one shape), each element ``H_ij`` in its own pair of panels.

    Parameters
    ----------
    sys : DelayLTI, Loop, AltitudeLoop, FrequencyResponse or SystemResponse, or a list of them
        A loop is drawn as its open loop ``L``; a system element by element (column ``j``: from input ``j``; rows
        ``2 i``, ``2 i + 1``: magnitude and phase of output ``i``).
    w : array_like, optional
        Frequencies (rad/s); by default a logarithmic grid over the first object's poles, zeros and delays.  A
        delay's phase is exact at each, however far apart.
    ax : Axes array, optional
        ``(2 * outputs, inputs)`` axes (a pair ``(ax_magnitude, ax_phase)`` for a SISO object).
    margins : bool
        Mark each SISO loop's gain and phase crossovers with its margins, in its colour.
    labels : sequence of str, optional
        Legend entries, one per object.
    path : str or Path, optional
        Write the figure here (PNG, PDF or SVG by the suffix).

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> import numpy as np
    >>> from delaykit import tf
    >>> fig = bode_plot(tf("exp(-s)/(s+1)"), np.geomspace(1e-2, 1e3, 300))
    >>> phase = fig.axes[1].lines[0].get_ydata()
    >>> round(float(phase[-1]), 6), round(float(np.degrees(-1e3 - np.arctan(1e3))), 6)  # -w - atan(w)
    (-57385.722217, -57385.722217)
    """
    items = _items(sys)
    first = _data(items[0], w)
    data = [first] + [_data(x, first.w if w is None else w) for x in items[1:]]
    names = _labels(labels, len(data))
    shape = first.H.shape[:2]
    if any(d.H.shape[:2] != shape for d in data):
        raise InvalidValueError(f"bode_plot draws objects of one shape; got {[d.H.shape[:2] for d in data]}")
    ny, nu = shape
    if (ny, nu) == (1, 1):
        fig = plot_bode([d.siso() for d in data], ax=ax,
                        margins=[_margins_of(d) for d in data] if margins else None, labels=labels)
        if any(d.source is None or _is_system(d.source) for d in data):  # not only loops' L
            fig_axes = ax if ax is not None else fig.axes[:2]
            one = len(data) == 1 and first.source is not None
            fig_axes[0].set_ylabel(f"|{first.outputs[0]}/{first.inputs[0]}| (dB)" if one else "magnitude (dB)")
            fig_axes[1].set_ylabel("phase (deg)")
        return save_figure(fig, path)
    if margins:
        raise InvalidValueError("margins=True marks a SISO loop's margins; a MIMO system's loop-at-a-time margins "
                                "are margins(sys), its gains sigma_plot(sys)")
    if ax is None:
        fig = Figure(figsize=(3.6 * nu + 1.0, 2.4 * ny + 1.0), layout="constrained")
        grid = np.asarray(fig.subplots(2 * ny, nu, sharex=True, squeeze=False))
    else:
        grid = np.asarray(ax, dtype=object)
        if grid.shape != (2 * ny, nu) or not all(isinstance(a, Axes) for a in grid.ravel()):
            raise InvalidTypeError(f"a Bode plot of {ny} outputs x {nu} inputs needs a {2 * ny} x {nu} array of "
                                   f"Axes, got {getattr(grid, 'shape', None)}")
        fig = grid[0, 0].figure
    for i in range(ny):
        for j in range(nu):
            mag, ph = grid[2 * i, j], grid[2 * i + 1, j]
            for d, name in zip(data, names):
                keep = d.w > 0
                with np.errstate(all="ignore"):
                    db = 20.0 * np.log10(np.abs(d.H[i, j, keep]))
                (line,) = mag.semilogx(d.w[keep], db, lw=1.3, label=name)
                ph.semilogx(d.w[keep], d.phase_deg[i, j, keep], lw=1.3, color=line.get_color())
            for a in (mag, ph):
                a.grid(alpha=0.3, which="both")
            if i == 0:
                mag.set_title(f"from {first.inputs[j]}")
            if j == 0:
                mag.set_ylabel(f"to {first.outputs[i]}\n|H| (dB)")
                ph.set_ylabel("phase (deg)")
            if i == ny - 1:
                ph.set_xlabel("ω (rad/s)")
    if any(names):
        grid[0, 0].legend(fontsize=8)
    return save_figure(fig, path)


# ---- Nyquist -------------------------------------------------------------------------------------------------

def _count_text(d: _Data) -> str:
    """The Nyquist count of a SISO loop: ``Z = P - N`` with ``P`` certified."""
    from ..spectrum.systems import nyquist_count

    if d.source is None:
        return ""
    try:
        if _is_system(d.source):
            c = nyquist_count(d.source)
            n, p, z = c.encirclements, c.open_loop_unstable, c.closed_loop_unstable
        else:
            m = _margins_of(d)
            if m.encirclements is None:
                return "no Nyquist count"
            n, p, z = m.encirclements, m.open_loop_rhp_poles, m.nyquist_rhp_roots
    except InvalidValueError as exc:
        return f"no Nyquist count: {exc}"
    return f"N = {n} encirclement{'' if abs(n) == 1 else 's'} of -1, P = {p}: Z = P - N = {z} " + \
           ("(stable)" if z == 0 else "(UNSTABLE)")


def nyquist_plot(sys: Any, w: Any = None, *, ax: Axes | None = None, radius: float = 2.0, ms_circle: bool = True,
                 labels: Sequence[str] | None = None, path: str | Path | None = None) -> Figure:
    """Nyquist plot of one or more SISO open loops ``L`` (closed by unity negative feedback): the critical point
    -1, the count of its encirclements and the closed-loop poles right of the axis ``Z = P - N`` (``P`` the
    open-loop poles there, certified), and the circle ``|1 + L| = 1/Ms`` of each loop's peak sensitivity.

    Parameters
    ----------
    sys : DelayLTI, Loop, AltitudeLoop or FrequencyResponse, or a list of them
        SISO open loops (a response given as it is gets no count and no circle: it has no system).
    w : array_like, optional
        Frequencies (rad/s); by default each loop's grid.
    ax : matplotlib Axes, optional
    radius : float
        Half-width of the view at most (default 2: the neighbourhood of -1).
    ms_circle : bool
        Draw each loop's Ms circle (centre -1, radius ``1/Ms``), dotted in its colour.
    labels : sequence of str, optional
    path : str or Path, optional

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import tf
    >>> fig = nyquist_plot(tf("exp(-0.5*s)/s"))
    >>> fig.axes[0].get_title()
    'N = 0 encirclements of -1, P = 0: Z = P - N = 0 (stable)'
    """
    data = _siso_items(sys, w, "nyquist_plot")
    fig = plot_nyquist([d.siso() for d in data], ax=ax, labels=labels, radius=radius)
    a = fig.axes[0] if ax is None else ax
    colours = [line.get_color() for line in a.lines[0:2 * len(data):2]]
    texts = []
    t = np.linspace(0.0, 2 * np.pi, 361)
    for d, colour, name in zip(data, colours, _labels(labels, len(data))):
        text = _count_text(d)
        texts.append(f"{name}: {text}" if name and text else text)
        if ms_circle and d.source is not None:
            try:
                m = _margins_of(d)
            except InvalidValueError:  # no margins (a neutral loop without a verdict): the curve without its circle
                continue
            if m.stable and math.isfinite(m.ms) and m.ms > 0:
                a.plot(-1.0 + np.cos(t) / m.ms, np.sin(t) / m.ms, color=colour, lw=1.0, ls=":",
                       label=f"|1 + L| = 1/Ms, Ms = {m.ms:.3g}")
    shown = [x for x in texts if x]
    if shown:
        a.set_title("\n".join(shown) if len(shown) > 1 else shown[0], fontsize=9)
    if any(not str(line.get_label()).startswith("_") for line in a.lines):
        a.legend(fontsize=8)
    return save_figure(fig, path)


# ---- singular values, Nichols --------------------------------------------------------------------------------

def sigma_plot(sys: Any, w: Any = None, *, ax: Axes | None = None, labels: Sequence[str] | None = None,
               path: str | Path | None = None) -> Figure:
    """Singular values of ``H(jw)`` in dB against log frequency (rad/s): the gains of a MIMO system in its best and
    worst input directions (python-control's ``singular_values_plot``); ``|H|`` for a SISO one.

    Parameters
    ----------
    sys : DelayLTI, Loop, FrequencyResponse or SystemResponse, or a list of them
    w : array_like, optional
        Frequencies (rad/s); by default the first system's grid.
    ax : matplotlib Axes, optional
    labels : sequence of str, optional
        One per object (each singular value of it numbered after).
    path : str or Path, optional

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import tf
    >>> fig = sigma_plot(tf([["1/(s+1)", "0"], ["0", "2*exp(-s)/(s+1)"]]), [1e-3, 1.0, 10.0])
    >>> [round(float(v), 3) for v in fig.axes[0].lines[0].get_ydata()]       # 20 log10(2 / |jw + 1|)
    [6.021, 3.01, -14.023]
    """
    from ..systems.lti import SystemResponse

    items = _items(sys)
    first = _data(items[0], w)
    data = [first] + [_data(x, first.w if w is None else w) for x in items[1:]]
    names = _labels(labels, len(data))
    fig, a = _one_axes(ax, (7.0, 4.5))
    for d, name in zip(data, names):
        keep = d.w > 0
        with np.errstate(all="ignore"):
            db = 20.0 * np.log10(SystemResponse(d.w, d.H, d.inputs, d.outputs).singular_values().T)
        colour = None
        for k in range(db.shape[1]):
            label = (f"{name}: σ{k + 1}" if name else f"σ{k + 1}") if db.shape[1] > 1 else name
            (line,) = a.semilogx(d.w[keep], db[keep, k], lw=1.3, color=colour, ls=("-", "--", ":", "-.")[k % 4],
                                 label=label)
            colour = line.get_color() if len(data) > 1 else None
    a.axhline(0.0, color="0.4", lw=0.7, ls="--")
    a.set_xlabel("ω (rad/s)")
    a.set_ylabel("singular values (dB)")
    a.grid(alpha=0.3, which="both")
    if any(line.get_label() and not line.get_label().startswith("_") for line in a.lines):
        a.legend(fontsize=8)
    return save_figure(fig, path)


def nichols_plot(sys: Any, w: Any = None, *, ax: Axes | None = None, labels: Sequence[str] | None = None,
                 path: str | Path | None = None) -> Figure:
    """Nichols plot of one or more SISO open loops: magnitude (dB) against the exact unwrapped phase (deg), with
    the critical points ``(-180 + 360 k deg, 0 dB)`` in the range drawn.

    Parameters
    ----------
    sys : DelayLTI, Loop, AltitudeLoop or FrequencyResponse, or a list of them
    w : array_like, optional
        Frequencies (rad/s); by default each loop's grid.
    ax : matplotlib Axes, optional
    labels : sequence of str, optional
    path : str or Path, optional

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import tf
    >>> fig = nichols_plot(tf("exp(-s)/(s+1)"), [1.0])
    >>> [round(float(v), 3) for v in fig.axes[0].lines[0].get_xydata()[0]]  # -45 - 57.296 deg, -3.010 dB
    [-102.296, -3.01]
    """
    data = _siso_items(sys, w, "nichols_plot")
    names = _labels(labels, len(data))
    fig, a = _one_axes(ax, (6.5, 5.0))
    lo, hi = math.inf, -math.inf
    for d, name in zip(data, names):
        r = d.siso()
        keep = (r.w > 0) & np.isfinite(r.magnitude_db)
        a.plot(r.phase_deg[keep], r.magnitude_db[keep], lw=1.3, label=name)
        if keep.any():
            lo, hi = min(lo, float(r.phase_deg[keep].min())), max(hi, float(r.phase_deg[keep].max()))
    if math.isfinite(lo):
        k0, k1 = math.ceil((lo + 180.0) / 360.0), math.floor((hi + 180.0) / 360.0)
        ks = range(k0, k1 + 1) if k1 - k0 < 50 else range(k1 - 49, k1 + 1)  # the 50 nearest the start
        pts = [-180.0 + 360.0 * k for k in ks]
        a.plot(pts, [0.0] * len(pts), "x", color="tab:red", ms=8, mew=2, label="critical points")
    a.axhline(0.0, color="0.4", lw=0.7, ls="--")
    a.set_xlabel("phase (deg)")
    a.set_ylabel("magnitude (dB)")
    a.grid(alpha=0.3)
    a.legend(fontsize=8)
    return save_figure(fig, path)


# ---- time responses, poles -----------------------------------------------------------------------------------

def step_grid(sys: Any, T: Any = None, *, ax: Any = None, title: str | None = None,
              path: str | Path | None = None) -> Figure:
    """A MIMO step-response grid: panel ``(i, j)`` the output ``i`` for a unit step on input ``j``, columns titled
    by the input's name, rows by the output's (python-control's layout), times in s (the model's time unit).

    Parameters
    ----------
    sys : DelayLTI or SystemTimeResponse
        A system (its exact step response over ``T`` is computed) or a step or impulse response.
    T : array_like, optional
        Times (s); by default :func:`~delaykit.simulate.systems.step_response`'s.
    ax : Axes array, optional
        ``(outputs, inputs)`` axes.
    title : str, optional
        Above the grid (with the response's status when it stopped early).
    path : str or Path, optional

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import tf
    >>> fig = step_grid(tf([["exp(-s)/(s+1)", "0.5/(2*s+1)"]], inputs=["a", "b"], outputs="y"), [0.0, 1.0, 2.0])
    >>> [a.get_title() for a in fig.axes], fig.axes[0].get_ylabel()
    (['from a', 'from b'], 'to y')
    """
    from ..simulate.systems import SystemTimeResponse, step_response

    if _is_system(sys):
        r = step_response(sys, T)
    elif isinstance(sys, SystemTimeResponse):
        if T is not None:
            raise InvalidValueError("T is for a system; a response has its own times")
        r = sys
        if r.outputs.ndim != 3:
            raise InvalidValueError(f"step_grid draws a step or impulse response (outputs x inputs x times); got a "
                                    f"{r.kind} response: use its .plot()")
    else:
        raise InvalidTypeError(f"expected a DelayLTI or a SystemTimeResponse, got {type(sys).__name__}")
    ny, nu, _ = r.outputs.shape
    if ax is None:
        fig = Figure(figsize=(3.4 * nu + 1.0, 2.3 * ny + 1.0), layout="constrained")
        grid = np.asarray(fig.subplots(ny, nu, sharex=True, squeeze=False))
    else:
        grid = np.asarray(ax, dtype=object).reshape(ny, nu) if np.size(np.asarray(ax, dtype=object)) == ny * nu \
            else None
        if grid is None or not all(isinstance(a, Axes) for a in grid.ravel()):
            raise InvalidTypeError(f"a step grid of {ny} outputs x {nu} inputs needs {ny * nu} Axes")
        fig = grid[0, 0].figure
    for i in range(ny):
        for j in range(nu):
            a = grid[i, j]
            a.plot(r.time, r.outputs[i, j], lw=1.3)
            a.axhline(0.0, color="0.5", lw=0.6)
            a.grid(alpha=0.3)
            if i == 0:
                a.set_title(f"from {r.input_labels[j]}")
            if j == 0:
                a.set_ylabel(f"to {r.output_labels[i]}")
            if i == ny - 1:
                a.set_xlabel("time (s)")
    status = r.status
    if title or status != "exact":
        text = (title or "") + ("" if status == "exact" else f" (stopped early: {status} at t = {r.t_reached:g})")
        fig.suptitle(text.strip(), fontsize=11)
    return save_figure(fig, path)


def pole_map(sys: Any, region: Sequence[float] | None = None, *, ax: Axes | None = None, title: str | None = None,
             path: str | Path | None = None) -> Figure:
    """The certified poles of a system in a region (crosses; a number beside a multiple one), the region searched
    (dashed rectangle), a neutral system's vertical lines that its root chains approach (dash-dot) and the
    imaginary axis.

    Parameters
    ----------
    sys : DelayLTI or Spectrum
        A system (its poles found by :func:`~delaykit.spectrum.systems.poles`) or a spectrum already found.
    region : (re_min, re_max, im_min, im_max), optional
        Where to search (rad/s); by default the region that provably holds the rightmost poles.  Without a region
        only the upper half is searched: the conjugates below the axis are drawn too (the coefficients are real).
    ax : matplotlib Axes, optional
    title : str, optional
        A first line; the count and whether it is certified follow.
    path : str or Path, optional

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from delaykit import tf, feedback
    >>> fig = pole_map(feedback(tf("2/(s+1)"), 1), (-5, 1, -1, 1))
    >>> fig.axes[0].lines[0].get_xydata().round(12).tolist(), fig.axes[0].get_title()
    ([[-3.0, 0.0]], '1 pole in the region, certified')
    """
    from ..spectrum.roots import Spectrum
    from ..spectrum.systems import poles

    if _is_system(sys):
        sp = poles(sys, region)
    elif isinstance(sys, Spectrum):
        if region is not None:
            raise InvalidValueError("region is for a system; a Spectrum has its own")
        sp = sys
    else:
        raise InvalidTypeError(f"expected a DelayLTI or a Spectrum, got {type(sys).__name__}")
    fig, a = _one_axes(ax, (6.0, 5.0))
    x0, x1, y0, y1 = (float(v) for v in sp.region)
    mirror = y0 >= 0.0 and region is None and _is_system(sys)
    roots = np.asarray(sp.roots, complex)
    shown = np.concatenate([roots, np.conj(roots[roots.imag > 0])]) if mirror else roots
    a.plot(shown.real, shown.imag, "x", color="tab:blue", ms=8, mew=2, label="poles (certified)" if sp.certified
           else "poles (NOT certified)")
    for z, m in zip(roots, sp.multiplicities):
        if m > 1:
            a.annotate(f"×{int(m)}", (z.real, z.imag), textcoords="offset points", xytext=(5, 5), fontsize=8)
    ys = (-y1, y1) if mirror else (y0, y1)
    a.plot([x0, x1, x1, x0, x0], [ys[0], ys[0], ys[1], ys[1], ys[0]], color="0.5", lw=0.9, ls="--",
           label="region searched")
    lines = [float(v) for v in (sp.neutral_lines or ()) if np.isfinite(v)]
    for k, v in enumerate(lines):
        a.axvline(v, color="tab:purple", lw=1.0, ls="-.", label="neutral root chains" if k == 0 else None)
    a.axvline(0.0, color="0.3", lw=0.8)
    a.axhline(0.0, color="0.6", lw=0.6)
    a.set_xlabel("Re s (1/s)")
    a.set_ylabel("Im s (rad/s)")
    a.grid(alpha=0.3)
    n = int(np.sum(sp.multiplicities))
    verdict = "certified" if sp.certified else f"NOT certified: {sp.reason}"
    head = f"{n} pole{'' if n == 1 else 's'} in the region{' (and conjugates)' if mirror and n else ''}, {verdict}"
    a.set_title(head if not title else f"{title}\n{head}", fontsize=10)
    a.legend(fontsize=8)
    return save_figure(fig, path)
