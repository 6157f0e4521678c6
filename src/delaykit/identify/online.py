"""Online delay estimation: the loop delay from one window of a flight's logged packets and commands.

During a real-time flight the loop re-estimates its delay after each reference step, from what it logged: the
altitudes it received (at the packets' arrival times, not uniform) and the commands it sent (at their send times).
Whatever controller flew (P, PV, a Smith predictor...), the plant is fitted from the commands *actually sent*:
an integrator behind a first-order speed lag, with gain ``g`` and input delay ``D``::

    v_in(t) = g u(t - D),   L v'(t) = v_in(t) - v(t)   (L = 0: v = v_in),   z'(t) = v(t)

where ``u`` holds each command ``u[k]`` from its send time ``s[k]`` to the next one (``u_before`` before the first).
This is an output-error fit: the data are logged in closed loop (a command depends on earlier noisy altitudes), but
the command is known exactly and the measurement noise is white and never enters the plant, so the fit stays
consistent.

The response to a piecewise-constant input is written in closed form, as a sum of step responses: a command change
``du`` that reaches the plant at ``tau = s + D`` adds ``g du R(t - tau)`` to the altitude, with
``R(a) = a - L (1 - exp(-a / L))`` for ``a > 0`` (``R(a) = a`` when ``L = 0``) and 0 before.  Changes that reached
the plant long before the window (``40 L`` earlier, when their exponential is below double precision) contribute
a ramp at the command level they left, so the plant's state at ``t_from`` comes from the whole command history at
no extra cost, and the window's start speed is not a free parameter.  The altitude offset and ``g`` enter linearly
and are profiled out (linear least squares at each delay).

Examples
--------
>>> import numpy as np
>>> send = np.arange(0.0, 8.0, 1 / 15)                       # commands at 15 Hz
>>> u = np.clip(1.3 * (np.sin(send) - 0.2), -1, 1)           # whatever the controller sent
>>> t = np.arange(0.0, 8.0, 0.055) + 0.004                   # packets
>>> du = np.diff(u, prepend=0.0)                             # the plant: g = 0.9, D = 0.3 s, no lag
>>> z = 0.9 * np.maximum(t[:, None] - send[None, :] - 0.3, 0.0) @ du
>>> est = estimate_window(t, np.round(z, 3), send, u, t_from=2.0, t_to=6.0)   # altitudes to the mm
>>> est
WindowEstimate(delay=0.2999 s ± 0.0003, lag 0 s, 73 samples)
>>> est.ci[0] < 0.3 < est.ci[1], round(est.gain, 3)
(True, 0.9)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import brentq, minimize_scalar

from ..errors import InvalidTypeError, InvalidValueError, check_real

__all__ = ["LAG_MAX", "MIN_SAMPLES", "WindowEstimate", "estimate_window"]

MIN_SAMPLES = 8
"""The fewest samples a window may hold."""
LAG_MAX = 1.0
"""The largest speed lag (s) searched when the lag is fitted (``lag=None``)."""

_TAIL = 40.0  # lags after which exp(-a / L) < 5e-18: a change that old has settled to a ramp
_GRID_STEP = 0.025  # s: coarse delay grid (fixed lag); the RSS basin is wider than a few of these
_GRID_STEP_2D = 0.05  # s: coarse delay grid (lag fitted, at L = 0)
_LAG_GRID = (0.0, 0.03, 0.1, 0.3)  # s: coarse lag grid (lag fitted)
_H = 1e-5  # s: step of the numerical derivatives of the model
_Z95 = 1.96


@dataclass(frozen=True, repr=False)
class WindowEstimate:
    """The delay fitted to one window of a flight.

    Attributes
    ----------
    delay : float
        The input delay ``D`` (s).
    stderr : float
        Its standard error (s): Gauss-Newton, inflated for residual autocorrelation, with the altitude rounding's
        timing resolution in quadrature; very large, or ``inf``, when the curvature vanishes (the window cannot
        tell the delay from the offset and gain, or, with the lag fitted near 0, from the lag).
    ci : tuple of float
        95 % interval (s), within the searched ``delay_range``: ``delay ± 1.96 stderr`` with the lag fixed, the
        profile-likelihood interval with the lag fitted.
    lag : float
        The speed lag ``L`` (s): the fixed value given, or the fitted one.
    gain : float
        The fitted speed gain ``g``.
    samples : int
        Residuals used (samples in the window).
    rms : float
        Residual rms (m).
    t_from, t_to : float
        The window (s).
    """

    delay: float
    stderr: float
    ci: tuple[float, float]
    lag: float
    gain: float
    samples: int
    rms: float
    t_from: float
    t_to: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: plain floats and lists (a non-finite ``stderr`` is written as None)."""
        se = float(self.stderr) if math.isfinite(self.stderr) else None
        return {"delay": float(self.delay), "stderr": se, "ci": [float(self.ci[0]), float(self.ci[1])],
                "lag": float(self.lag), "gain": float(self.gain), "samples": int(self.samples),
                "rms": float(self.rms), "t_from": float(self.t_from), "t_to": float(self.t_to)}

    def __repr__(self) -> str:
        return (f"WindowEstimate(delay={self.delay:.4f} s ± {self.stderr:.4f}, lag {self.lag:.4g} s, "
                f"{self.samples} samples)")


# ----------------------------------------------------------------------------------------------------------
# checks


def _series(name: str, values: ArrayLike) -> np.ndarray:
    """``values`` as a finite 1-D float array, or an error naming it."""
    try:
        x = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be a 1-D sequence of real numbers") from exc
    if x.ndim != 1:
        raise InvalidValueError(f"{name} must be 1-D, got an array of shape {x.shape}")
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise InvalidValueError(f"{name} must be finite, got {x[bad[0]]} at index {bad[0]}")
    return x


def _increasing(name: str, x: np.ndarray) -> None:
    bad = np.flatnonzero(np.diff(x) <= 0)
    if bad.size:
        i = int(bad[0])
        raise InvalidValueError(f"{name} must be increasing, got {x[i]:g} then {x[i + 1]:g} at index {i + 1}")


def _delay_range(value: Any) -> tuple[float, float]:
    try:
        lo, hi = value
    except (TypeError, ValueError) as exc:
        raise InvalidValueError(f"delay_range must be a pair (lo, hi) with 0 <= lo < hi, got {value!r}") from exc
    lo = check_real("delay_range[0]", lo)
    hi = check_real("delay_range[1]", hi)
    if not 0.0 <= lo < hi:
        raise InvalidValueError(f"delay_range must satisfy 0 <= lo < hi, got ({lo:g}, {hi:g})")
    return lo, hi


# ----------------------------------------------------------------------------------------------------------
# the model


class _Window:
    """One window's data, prepared once; times are counted from ``t_from`` (small numbers, no cancellation)."""

    def __init__(self, t: np.ndarray, z: np.ndarray, send: np.ndarray, u: np.ndarray, u_before: float,
                 t_from: float) -> None:
        self.t = t - t_from
        self.zc = z - z.mean()
        change = np.diff(u, prepend=u_before) != 0.0  # a repeated command changes nothing: dropped, exactly
        self.s = send[change] - t_from
        self.du = np.diff(u, prepend=u_before)[change]
        self.level = u[change]  # the command after each change
        self.u_before = u_before

    def response(self, delay: float, lag: float, dlag: bool = False) -> tuple[np.ndarray, ...]:
        """The unit-gain altitude (up to a constant) and speed at the samples, exactly; with ``dlag`` also the
        altitude's derivative in the lag (up to a constant)."""
        tau = self.s + delay
        # changes that reached the plant 40 lags before the window (any, without lag) are a ramp there
        m = int(np.searchsorted(tau, -_TAIL * lag, side="right"))
        e = int(np.searchsorted(tau, self.t[-1], side="left"))  # changes after the last sample: no effect
        level = self.level[m - 1] if m else self.u_before
        a = self.t[:, None] - tau[None, m:e]
        np.maximum(a, 0.0, out=a)
        du = self.du[m:e]
        if lag > 0.0:
            a_l = a / lag
            rise = -np.expm1(-a_l)  # the speed after a unit change: 1 - exp(-a / L)
            y = level * self.t + (a - lag * rise) @ du
            x = level + rise @ du
            if dlag:  # d/dL [a - L (1 - exp(-a/L))] = (a/L) exp(-a/L) - (1 - exp(-a/L))
                return y, x, (a_l * (1.0 - rise) - rise) @ du
        else:
            y = level * self.t + a @ du
            x = level + (a > 0.0) @ du
            if dlag:  # the limit L -> 0+
                return y, x, -x
        return y, x

    def parts(self, delay: float, lag: float) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
        """(residuals, gain, unit speed, centred unit response) with the offset and gain profiled out."""
        y, x = self.response(delay, lag)
        r, g, yc = _profiled(self, y)
        return r, g, x, yc

    def rss(self, delay: float, lag: float) -> float:
        """The residual sum of squares, offset and gain profiled out."""
        r = self.parts(delay, lag)[0]
        return float(r @ r)


def _fit_delay(w: _Window, lag: float, lo: float, hi: float) -> float:
    """The delay minimising the RSS at a fixed lag: coarse grid, then bounded Brent around its best point."""
    grid = np.linspace(lo, hi, max(21, math.ceil((hi - lo) / _GRID_STEP) + 1))
    costs = np.array([w.rss(d, lag) for d in grid])
    j = int(np.argmin(costs))
    a, b = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
    res = minimize_scalar(w.rss, bounds=(a, b), args=(lag,), method="bounded", options={"xatol": 1e-8})
    return float(res.x) if res.fun <= costs[j] else float(grid[j])


def _refine(w: _Window, delay: float, lag: float, free: int, lo: float, hi: float,
            tol: float = 1e-9) -> tuple[float, float, float]:
    """Gauss-Newton in one parameter, the other held (``free`` 0: the delay, in [lo, hi]; 1: the lag, in
    [0, LAG_MAX]), with the offset and gain re-profiled at each step and step halving; returns (delay, lag, rss).

    The model's derivatives are exact: minus the speed in the delay, the lag's own in the lag."""
    bounds = ((lo, hi), (0.0, LAG_MAX))[free]

    def evaluate(theta: list[float]) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
        out = w.response(theta[0], theta[1], dlag=free == 1)
        r, g, yc = _profiled(w, out[0])
        return r, g, yc, (-out[1] if free == 0 else out[2])

    theta = [delay, lag]
    r, g, yc, dv = evaluate(theta)
    rss = float(r @ r)
    for _ in range(30):
        # the derivative's part orthogonal to the constant and the response (variable projection)
        J = g * (dv - dv.mean())
        syy = float(yc @ yc)
        if syy > 0.0:
            J -= (float(yc @ J) / syy) * yc
        jj = float(J @ J)
        if not jj > 0.0:
            break
        step = float(J @ r) / jj
        for _ in range(8):
            trial = list(theta)
            trial[free] = min(max(theta[free] + step, bounds[0]), bounds[1])
            new = evaluate(trial)
            if float(new[0] @ new[0]) <= rss:
                break
            step *= 0.5
        else:
            break
        moved = abs(trial[free] - theta[free])
        theta, (r, g, yc, dv) = trial, new
        rss = float(r @ r)
        if moved < tol:
            break
    return theta[0], theta[1], rss


def _fit_delay_lag(w: _Window, lo: float, hi: float) -> tuple[float, float]:
    """Delay and lag together: a coarse grid in both, then the lag by bounded Brent with the delay profiled.

    (A joint Gauss-Newton step is no good near ``L = 0``: there a lag and a delay act alike to first order.)"""
    lags = np.array(_LAG_GRID + (LAG_MAX,))
    # the coarse delay grid at L = 0 (cheap: no exponentials) finds the basin of D + L; at the other grid lags
    # the delay starts at that point less the lag, and a small grid around it guards against a neighbouring basin
    grid = np.linspace(lo, hi, max(11, math.ceil((hi - lo) / _GRID_STEP_2D) + 1))
    d0 = float(grid[int(np.argmin([w.rss(d, 0.0) for d in grid]))])
    profile = []
    for lag in lags[:-1]:
        near = np.clip(d0 - lag + np.array([-_GRID_STEP_2D, 0.0, _GRID_STEP_2D]), lo, hi)
        start = float(near[int(np.argmin([w.rss(d, lag) for d in near]))])
        profile.append(_refine(w, start, lag, 0, lo, hi)[::2])
    j = int(np.argmin([c for _, c in profile]))
    state = {"delay": profile[j][0], "lag": float(lags[j])}

    def cost(lag: float) -> float:
        # a lag trades against the same delay: start from the last solution shifted by the change of lag
        start = min(max(state["delay"] + state["lag"] - lag, lo), hi)
        d, _, c = _refine(w, start, lag, 0, lo, hi)
        if c < best[2]:
            best[:] = [d, lag, c]
        state["delay"], state["lag"] = d, lag
        return c

    best = [profile[j][0], float(lags[j]), profile[j][1]]
    minimize_scalar(cost, bounds=(float(lags[max(j - 1, 0)]), float(lags[j + 1])), method="bounded",
                    options={"xatol": 1e-7})
    return float(best[0]), float(best[1])


def _profiled(w: _Window, y: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """(residuals, gain, centred response) with the offset and gain fitted to the unit response ``y``."""
    yc = y - y.mean()
    syy = float(yc @ yc)
    g = float(yc @ w.zc) / syy if syy > 0.0 else 0.0
    return w.zc - g * yc, g, yc


def _profile_interval(w: _Window, delay: float, lag: float, threshold: float, step: float, lo: float,
                      hi: float) -> tuple[float, float]:
    """The delays where the RSS, lag re-fitted, rises to ``threshold`` on either side (clipped to the range)."""

    def excess(d: float) -> float:
        # along the ridge a lag trades one for one against the delay: start the lag there
        return _refine(w, d, min(max(lag + delay - d, 0.0), LAG_MAX), 1, lo, hi, tol=1e-7)[2] - threshold

    ends = []
    for sign in (-1.0, 1.0):
        a, h = delay, step
        b = delay + sign * h
        for _ in range(16):
            if not lo <= b <= hi:
                b = min(max(b, lo), hi)
                break
            if excess(b) > 0.0:
                break
            a, h = b, 2.0 * h
            b = delay + sign * h
        if b == a or excess(b) <= 0.0:
            ends.append(b)  # the range's end is inside the interval
        elif excess(a) >= 0.0:
            ends.append(a)  # no room at all (a perfect fit)
        else:
            ends.append(brentq(excess, min(a, b), max(a, b), xtol=1e-5))
    return ends[0], ends[1]


def _derivative(w: _Window, gain: float, delay: float, lag: float, which: int) -> np.ndarray:
    """d(model)/d(delay or lag) at fixed offset and gain, by central differences (forward at lag 0)."""
    if which == 0:
        up, down, h = (delay + _H, lag), (delay - _H, lag), 2 * _H
    elif lag >= _H:
        up, down, h = (delay, lag + _H), (delay, lag - _H), 2 * _H
    else:
        up, down, h = (delay, lag + _H), (delay, lag), _H
    return gain * (w.response(*up)[0] - w.response(*down)[0]) / h


def _stderr(w: _Window, r: np.ndarray, yc: np.ndarray, gain: float, delay: float, lag: float,
            lag_free: bool) -> tuple[float, float]:
    """The delay's Gauss-Newton standard error, with the Newey-West (Bartlett) factor (never below 1) applied;
    returns (stderr, factor).

    The columns are the model's derivatives in the nonlinear parameters and its two linear ones (offset, gain):
    the (delay, delay) element of the inverse normal matrix is ``1 / |P J_D|^2``, with ``P`` projecting out the
    linear columns, the Gauss-Newton curvature of the RSS with the offset and gain re-profiled."""
    cols = [_derivative(w, gain, delay, lag, 0)]
    if lag_free:
        cols.append(_derivative(w, gain, delay, lag, 1))
    X = np.column_stack(cols + [np.ones_like(yc), yc])
    n, p = X.shape
    try:
        A = np.linalg.inv(X.T @ X)
    except np.linalg.LinAlgError:
        return math.inf, 1.0
    if not A[0, 0] > 0.0 or not np.all(np.isfinite(A)):
        return math.inf, 1.0
    sigma2 = float(r @ r) / max(n - p, 1)
    se_white = math.sqrt(A[0, 0] * sigma2)
    if se_white == 0.0:
        return 0.0, 1.0
    # residuals correlated in time (a lag the model misses, a flat stretch rounded to millimetres) carry less
    # information than white ones: the Bartlett-weighted sandwich, as in the trajectory fit
    bw = int(min(max(4, round(4 * (n / 100.0) ** (2 / 9))), n // 4))
    G = X * r[:, None]
    S = G.T @ G
    for k in range(1, bw + 1):
        C = G[k:].T @ G[:-k]
        S += (1.0 - k / (bw + 1.0)) * (C + C.T)
    var_hac = float((A @ S @ A)[0, 0]) * n / max(n - p, 1)
    inflation = max(1.0, math.sqrt(max(var_hac, 0.0)) / se_white)
    return se_white * inflation, inflation


# ----------------------------------------------------------------------------------------------------------
# the estimator


def estimate_window(
    t: ArrayLike,
    z: ArrayLike,
    send_times: ArrayLike,
    u: ArrayLike,
    *,
    t_from: float,
    t_to: float | None = None,
    lag: float | None = 0.0,
    u_before: float = 0.0,
    delay_range: tuple[float, float] = (0.0, 1.5),
    quantum: float = 0.001,
) -> WindowEstimate:
    """Fit the input delay to one window of logged altitudes, from the commands actually sent.

    Parameters
    ----------
    t, z : array_like
        Measurement times (s, increasing, not necessarily uniform) and altitudes (m), 1-D, the same length.
    send_times, u : array_like
        The commands: send times (s, increasing) and values, 1-D, the same length.  ``u[k]`` holds from
        ``send_times[k]`` to ``send_times[k + 1]``; the commands before the window set the plant's state at
        ``t_from`` (nothing about it is fitted).
    t_from, t_to : float
        The window: residuals use the samples with ``t_from <= t <= t_to`` (``t_to`` defaults to the last ``t``).
    lag : float or None
        The speed lag ``L`` (s, >= 0), fixed; 0 means none, and the fitted delay then absorbs whatever lag the
        vehicle has (roughly ``D + L``).  None fits the lag too, in ``[0, LAG_MAX]``.
    u_before : float
        The command before ``send_times[0]`` (0: hover).
    delay_range : (float, float)
        Where the delay is searched, ``0 <= lo < hi`` (s).
    quantum : float
        The altitude rounding step (m; 0 if not rounded): rounding limits the timing resolution.

    Returns
    -------
    WindowEstimate
        ``stderr`` is the Gauss-Newton standard error of the delay: the model's derivatives in the delay (and the
        lag, when fitted) by central differences, with the offset and gain as parameters of the same least-squares
        problem (the curvature of the RSS with them re-profiled), ``sigma^2`` from the residuals; multiplied by
        the Newey-West (Bartlett) factor of the residuals when above 1 (never below 1), and combined in quadrature
        with the rounding's timing resolution ``quantum / sqrt(12) / max|z'|`` (``z'`` the fitted model's speed
        in the window).  With the lag fixed, ``ci`` is the Wald interval ``delay ± 1.96 stderr`` clipped to
        ``delay_range``.  With ``lag=None`` it is the profile-likelihood interval instead: the delays at which the
        RSS, with the lag, offset and gain re-fitted, exceeds its minimum by ``1.96^2 sigma^2`` times the squared
        Newey-West factor, each end widened by the resolution in quadrature, clipped to ``delay_range``.  A small
        fitted lag acts like extra delay to first order, so near ``lag = 0`` the curvature in the delay all but
        vanishes and ``stderr`` (local, and honest about that) becomes very large while the profile interval,
        which sees the lag's bound at 0, stays finite: read the interval then.

    Raises
    ------
    InvalidValueError
        Mismatched lengths, times that do not increase, values that are not finite, a negative lag or quantum,
        ``t_from >= t_to``, a window with fewer than ``MIN_SAMPLES`` samples, a window in which no command change
        can reach the plant (the delay cannot be seen), a ``delay_range`` that is not ``0 <= lo < hi``.

    Notes
    -----
    The delay is found by a coarse grid over ``delay_range`` (the RSS is not convex over a wide range: the delay
    trades against the command pattern), then a bounded scalar minimisation around the grid's best point.  With
    ``lag=None``: a coarse grid in both, then a bounded scalar minimisation in the lag with the delay profiled
    (Gauss-Newton in the delay at each lag); a joint Gauss-Newton step would stall near ``L = 0``, where a lag
    and a delay act alike to first order.

    Examples
    --------
    A drone with a 50 ms speed lag, gain 0.9 and 0.35 s of delay, flown by whatever controller:

    >>> import numpy as np
    >>> send = np.arange(0.0, 10.0, 1 / 15)
    >>> u = np.where(send < 1.0, 0.0, np.where(send < 5.0, 0.7 * np.exp(-(send - 1)), -0.5))
    >>> t = np.sort(np.random.default_rng(1).uniform(0.0, 10.0, 180))
    >>> a = np.maximum(t[:, None] - send[None, :] - 0.35, 0.0)        # the step responses, written out
    >>> z = 0.9 * (a - 0.05 * (1 - np.exp(-a / 0.05))) @ np.diff(u, prepend=0.0)
    >>> est = estimate_window(t, z, send, u, t_from=4.0, lag=0.05, quantum=0.0)
    >>> round(est.delay, 6), round(est.gain, 6)
    (0.35, 0.9)
    >>> free = estimate_window(t, z, send, u, t_from=0.0, lag=None, quantum=0.0)
    >>> round(free.delay, 4), round(free.lag, 4)
    (0.35, 0.05)
    >>> round(estimate_window(t, z, send, u, t_from=0.0, quantum=0.0).delay, 2)   # lag 0: the delay absorbs it
    0.4
    """
    t = _series("t", t)
    z = _series("z", z)
    send = _series("send_times", send_times)
    u = _series("u", u)
    if z.size != t.size:
        raise InvalidValueError(f"z must have as many values as t ({t.size}), got {z.size}")
    if u.size != send.size:
        raise InvalidValueError(f"u must have as many values as send_times ({send.size}), got {u.size}")
    _increasing("t", t)
    _increasing("send_times", send)
    t_from = check_real("t_from", t_from)
    if t_to is None:
        if t.size == 0:
            raise InvalidValueError("t is empty: the window holds no samples")
        t_to = float(t[-1])
    t_to = check_real("t_to", t_to)
    if not t_from < t_to:
        raise InvalidValueError(f"t_from must be below t_to ({t_to:g}), got {t_from:g}")
    lag = None if lag is None else check_real("lag", lag, minimum=0.0)
    u_before = check_real("u_before", u_before)
    lo, hi = _delay_range(delay_range)
    quantum = check_real("quantum", quantum, minimum=0.0)

    inside = (t >= t_from) & (t <= t_to)
    n = int(np.count_nonzero(inside))
    if n < MIN_SAMPLES:
        raise InvalidValueError(f"the window [{t_from:g}, {t_to:g}] s holds {n} samples; at least {MIN_SAMPLES} "
                                "are needed")
    change = np.diff(u, prepend=u_before) != 0.0
    seen = change & (send >= t_from - hi) & (send <= t_to - lo)
    if not seen.any():
        raise InvalidValueError(
            f"the command never changes between {t_from - hi:g} s and {t_to - lo:g} s (t_from - {hi:g}, "
            f"t_to - {lo:g}): no change reaches the plant inside the window [{t_from:g}, {t_to:g}] s for any "
            "delay in delay_range, so the delay cannot be seen")

    w = _Window(t[inside], z[inside], send, u, u_before, t_from)
    if lag is None:
        delay, fitted_lag = _fit_delay_lag(w, lo, hi)
    else:
        delay, fitted_lag = _fit_delay(w, lag, lo, hi), lag
    r, gain, x, yc = w.parts(delay, fitted_lag)
    rss = float(r @ r)
    se, _ = _stderr(w, r, yc, gain, delay, fitted_lag, lag is None)
    # rounded altitudes carry a timing resolution of their own: one rounding step takes quantum / |z'| seconds
    # at the response's fastest; that uniform error (std quantum / sqrt(12) / max|z'|) adds in quadrature
    vpeak = abs(gain) * float(np.max(np.abs(x)))
    floor = quantum / math.sqrt(12.0) / vpeak if quantum > 0.0 and vpeak > 0.0 else 0.0
    if lag is None:
        # near L = 0 a lag and a delay act alike to first order, the curvature all but vanishes and a Wald interval
        # means nothing: the profile-likelihood interval (lag, offset and gain re-fitted at each delay), its
        # threshold widened by the Newey-West factor of the fit with the lag held, its ends by the resolution
        se_held, factor = _stderr(w, r, yc, gain, delay, fitted_lag, False)
        threshold = rss * (1.0 + _Z95**2 * factor**2 / max(n - 4, 1))
        a, b = _profile_interval(w, delay, fitted_lag, threshold, max(2.0 * se_held, 1e-4), lo, hi)
        ci = (max(lo, delay - math.hypot(delay - a, _Z95 * floor)),
              min(hi, delay + math.hypot(b - delay, _Z95 * floor)))
        se = math.hypot(se, floor)
    else:
        se = math.hypot(se, floor)
        ci = (max(lo, delay - _Z95 * se), min(hi, delay + _Z95 * se)) if math.isfinite(se) else (lo, hi)
    return WindowEstimate(delay=delay, stderr=se, ci=ci, lag=fitted_lag, gain=gain, samples=n,
                          rms=float(math.sqrt(rss / n)), t_from=t_from, t_to=t_to)
