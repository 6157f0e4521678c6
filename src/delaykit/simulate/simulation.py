"""Exact simulation of the delayed altitude loop, one loop at a time or thousands at once.

The solver (:mod:`delaykit.simulate._kernel`) is the method of steps with Taylor polynomials between breakpoints:
saturation switches, their images one delay later, sample instants and the jumps of the neutral loop are
all located to machine precision, so the responses and their metrics are exact up to rounding (the
largest discarded Taylor coefficient is reported as ``truncation``; it is typically below 1e-16).
There is no step size to choose and nothing to converge.

Examples
--------
>>> from delaykit import AltitudeLoop, simulate
>>> r = simulate(AltitudeLoop(kp=1.31, delay=0.368))
>>> r.metrics
StepMetrics(overshoot=2.2630 %, peak_time=2.0761 s, rise_time=0.9050 s, settling_time=2.2631 s)
>>> round(r.altitude(2.0761), 4)
1.0226
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InvalidValueError, check_real
from ..models.altitude import VELOCITY_CHOICES, AltitudeLoop
from . import _kernel as K
from .metrics import StepMetrics

__all__ = ["Response", "BatchMetrics", "AltitudeSampler", "simulate", "simulate_many"]

_CAP0 = 4096
_CAP_MAX = 1 << 22
_NO_T = np.empty(0)


def _row(loop: AltitudeLoop, step: float, t_end: float, band: float) -> np.ndarray:
    p = np.empty(K.NPAR)
    p[K.PARAM["kp"]] = loop.kp
    p[K.PARAM["kv"]] = loop.kv
    p[K.PARAM["td"]] = loop.delay
    p[K.PARAM["vmax"]] = np.inf if loop.vmax is None else loop.vmax
    p[K.PARAM["filtered"]] = 1.0 if loop.filtered else 0.0
    p[K.PARAM["wf"]] = loop.filter_wn
    p[K.PARAM["zf"]] = loop.filter_zeta
    p[K.PARAM["period"]] = loop.period or 0.0
    p[K.PARAM["offset"]] = loop.sample_offset
    p[K.PARAM["step"]] = step
    p[K.PARAM["t_end"]] = t_end
    p[K.PARAM["band"]] = band
    p[K.PARAM["gain"]] = loop.gain
    p[K.PARAM["lag"]] = loop.lag
    return p


def _check_run(step: float, t_end: float, band: float) -> tuple[float, float, float]:
    step = check_real("step", step)
    if step == 0.0:
        raise InvalidValueError("step must not be zero (metrics are relative to the step size)")
    t_end = check_real("t_end (s)", t_end, minimum=0.0, strict=True)
    band = check_real("band", band, minimum=0.0, strict=True, maximum=1.0)
    return step, t_end, band


def _nan_to_none(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


def _metrics_from_row(out: np.ndarray, step: float, z0: float, band: float) -> StepMetrics:
    o = K.OUT
    return StepMetrics(
        overshoot=float(out[o["overshoot"]]),
        peak_time=_nan_to_none(out[o["peak_time"]]),
        rise_time=_nan_to_none(out[o["rise_time"]]),
        settling_time=_nan_to_none(out[o["settling_time"]]),
        steady_state_error=float(out[o["final_error"]]),
        peak=float(z0 + out[o["peak"]] * step),
        band=band,
    )


def _out(a: np.ndarray) -> Any:
    return float(a) if a.ndim == 0 else a


def _horner(coef: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Evaluate one polynomial per point: ``coef[..., j]`` multiplies ``x**j``."""
    y = np.zeros_like(x)
    for j in range(coef.shape[-1] - 1, -1, -1):
        y = y * x + coef[..., j]
    return y


@dataclass(frozen=True, repr=False, eq=False)
class Response:
    """The exact response of one loop to one step, as piecewise polynomials.

    Evaluate it anywhere with :meth:`altitude`, :meth:`velocity` and :meth:`command`, or on a grid with
    :meth:`sample`.  ``metrics`` holds the exact step metrics.
    """

    loop: AltitudeLoop
    step: float
    z0: float
    t_end: float
    metrics: StepMetrics
    truncation: float
    starts: np.ndarray = field(repr=False)
    lengths: np.ndarray = field(repr=False)
    coeffs: np.ndarray = field(repr=False)
    u_starts: np.ndarray = field(repr=False)
    u_lengths: np.ndarray = field(repr=False)
    u_coeffs: np.ndarray = field(repr=False)

    @property
    def breakpoints(self) -> np.ndarray:
        """Start times of the polynomial pieces of z (saturation switches, delay images, samples)."""
        return self.starts.copy()

    def _locate(self, t: Any, starts: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        if not np.all(np.isfinite(t)):
            raise InvalidValueError("times to evaluate at must be finite")
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, starts.size - 1)
        x = np.clip((t - starts[idx]) / lengths[idx], 0.0, 1.0)
        return t, idx, x

    def altitude(self, t: Any) -> Any:
        """Altitude z(t) in metres (z0 before the step; held at its last value after ``t_end``).

        A float for a scalar ``t``, an array for an array.
        """
        t, idx, x = self._locate(t, self.starts, self.lengths)
        z = self.z0 + _horner(self.coeffs[idx], x)
        return _out(np.where(t < 0, self.z0, z))

    def velocity(self, t: Any) -> Any:
        """Vertical speed z'(t) = u(t - Td), m/s (right-continuous at the neutral loop's jumps)."""
        t, idx, x = self._locate(t, self.starts, self.lengths)
        c = self.coeffs[idx]
        d = c[..., 1:] * np.arange(1, c.shape[-1])
        v = _horner(d, x) / self.lengths[idx]
        return _out(np.where((t < 0) | (t > self.t_end), 0.0, v))

    def command(self, t: Any) -> Any:
        """The commanded vertical speed u(t) (before the delay), m/s; 0 before the step."""
        t, idx, x = self._locate(t, self.u_starts, self.u_lengths)
        u = _horner(self.u_coeffs[idx], x)
        return _out(np.where(t < 0, 0.0, u))

    def sample(self, dt: float = 0.01, t: Any = None) -> dict[str, np.ndarray]:
        """The response on a grid: ``{"t", "z", "z_ref", "u"}`` (the flight-log columns).

        Examples
        --------
        >>> r = simulate(AltitudeLoop(kp=1.31, delay=0.368), t_end=5.0)
        >>> s = r.sample(dt=0.5)
        >>> [round(float(x), 3) for x in s["z"][:3]]
        [0.0, 0.132, 0.632]
        """
        if t is None:
            dt = check_real("dt (s)", dt, minimum=0.0, strict=True)
            t = np.arange(0.0, self.t_end + 0.5 * dt, dt)
            t = t[t <= self.t_end + 1e-12]
        t = np.asarray(t, dtype=float)
        return {
            "t": t,
            "z": self.altitude(t),
            "z_ref": np.where(t >= 0, self.z0 + self.step, self.z0),
            "u": self.command(t),
        }

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: the loop, the step and the metrics."""
        return {
            "loop": self.loop.to_dict(),
            "step": self.step,
            "z0": self.z0,
            "t_end": self.t_end,
            **self.metrics.to_dict(),
            "pieces": int(self.starts.size),
            "truncation": self.truncation,
        }

    def __repr__(self) -> str:
        return f"Response({self.loop!r}, step={self.step:g} m: {self.metrics!r})"


class _Workspace:
    """Work arrays for the kernel, grown eightfold (up to ``_CAP_MAX`` pieces) when a run needs more pieces.

    ``store`` keeps z's pieces (for a :class:`Response`); ``t`` are times at which to evaluate z.
    """

    def __init__(self, store: bool, t: np.ndarray = _NO_T) -> None:
        self.store = store
        self.t = t
        self.cap = _CAP0
        self._alloc()

    def _alloc(self) -> None:
        c = self.cap
        zc = c if self.store else 1
        self.u = (np.empty(c), np.empty(c), np.zeros((c, K.NC)), np.empty(c, dtype=np.int64))
        self.z = (np.empty(zc), np.empty(zc), np.empty((zc, K.NC)))
        self.out = np.empty(K.NOUT)
        self.ez = np.empty(self.t.size)

    def run(self, row: np.ndarray) -> int:
        """Run the kernel on one parameter row; returns the number of z pieces."""
        while True:
            n = K.run_one(row, self.cap, *self.u, *self.z, self.out, self.store, self.t, self.ez)
            if self.out[K.OUT["status"]] == 0:
                return n
            if self.cap >= _CAP_MAX:
                raise InvalidValueError(
                    f"the response needs more than {_CAP_MAX} polynomial pieces; shorten t_end "
                    f"({row[K.PARAM['t_end']]:g} s)"
                )
            self.cap *= 8
            self._alloc()


def simulate(
    loop: AltitudeLoop,
    step: float = 1.0,
    *,
    z0: float = 0.0,
    t_end: float = 15.0,
    band: float = 0.02,
) -> Response:
    """Simulate the loop's response to a reference step of ``step`` metres at t = 0 from altitude ``z0``.

    Parameters
    ----------
    loop : AltitudeLoop
        The loop.
    step : float
        Step size in metres (either sign, not zero).
    z0 : float
        Altitude before the step, metres.
    t_end : float
        End of the simulation, seconds after the step.
    band : float
        Settling band as a fraction of the step.

    Returns
    -------
    Response

    Examples
    --------
    >>> r = simulate(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered"), step=-0.5, z0=1.5)
    >>> round(r.metrics.overshoot, 4)
    1.6579
    """
    if not isinstance(loop, AltitudeLoop):
        from ..errors import InvalidTypeError

        raise InvalidTypeError(f"loop must be an AltitudeLoop, got {type(loop).__name__}")
    step, t_end, band = _check_run(step, t_end, band)
    z0 = check_real("z0", z0)
    row = _row(loop, step, t_end, band)
    ws = _Workspace(store=True)
    n = ws.run(row)
    out = ws.out
    (tu0, thu, tuc, _), (tz0, th, tzc) = ws.u, ws.z
    nu = int(out[K.OUT["u_pieces"]])
    return Response(
        loop=loop,
        step=step,
        z0=z0,
        t_end=t_end,
        metrics=_metrics_from_row(out, step, z0, band),
        truncation=float(out[K.OUT["truncation"]]),
        starts=tz0[:n].copy(),
        lengths=th[:n].copy(),
        coeffs=tzc[:n].copy(),
        u_starts=tu0[:nu].copy(),
        u_lengths=thu[:nu].copy(),
        u_coeffs=tuc[:nu].copy(),
    )


class AltitudeSampler:
    """Evaluates a loop's exact step response at given times, fast and repeatedly (for fitting).

    Holds the work arrays, so that thousands of calls (one per trial parameter set) allocate nothing.

    Examples
    --------
    >>> s = AltitudeSampler(t=np.array([0.5, 1.0, 2.0]))
    >>> np.round(s(AltitudeLoop(kp=1.31, delay=0.368), step=1.0), 4).tolist()
    [0.132, 0.6315, 1.022]
    """

    def __init__(self, t: Any, t_end: float | None = None) -> None:
        self.t = np.ascontiguousarray(np.asarray(t, dtype=float))
        if self.t.ndim != 1 or self.t.size and np.any(np.diff(self.t) < 0):
            raise InvalidValueError("sample times must be a sorted 1-D array")
        self.t_end = float(t_end if t_end is not None else (self.t[-1] if self.t.size else 1.0)) + 1e-9
        self._ws = _Workspace(store=False, t=self.t)

    def __call__(self, loop: AltitudeLoop, step: float, z0: float = 0.0) -> np.ndarray:
        """Altitude at the sample times (relative to the step at t = 0)."""
        self._ws.run(_row(loop, step, max(self.t_end, 1e-6), 0.02))
        return z0 + self._ws.ez


@dataclass(frozen=True, repr=False, eq=False)
class BatchMetrics:
    """Step metrics of many loops, as arrays (NaN where a value is absent: no peak, not settled).

    Attributes
    ----------
    kp, delay, kv, step : ndarray
        The loops, broadcast to a common shape.
    overshoot, peak_time, rise_time, settling_time, steady_state_error : ndarray
        As in :class:`~delaykit.simulate.metrics.StepMetrics`, in percent, seconds and metres.
    truncation : float
        The largest discarded Taylor coefficient over all loops (relative to the step).
    """

    kp: np.ndarray
    delay: np.ndarray
    kv: np.ndarray
    step: np.ndarray
    overshoot: np.ndarray
    peak_time: np.ndarray
    rise_time: np.ndarray
    settling_time: np.ndarray
    steady_state_error: np.ndarray
    truncation: float

    def __len__(self) -> int:
        return int(self.overshoot.size)

    def row(self, i: int) -> dict[str, Any]:
        """One loop's inputs and metrics as a JSON-ready dict."""
        keys = ("kp", "delay", "kv", "step", "overshoot", "peak_time", "rise_time", "settling_time", "steady_state_error")
        return {k: _nan_to_none(float(getattr(self, k).flat[i])) for k in keys}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: a list of rows."""
        return {"loops": [self.row(i) for i in range(len(self))], "truncation": self.truncation}

    def __repr__(self) -> str:
        mo = self.overshoot
        return (
            f"BatchMetrics({len(self)} loops, overshoot {np.nanmin(mo):.4g} to {np.nanmax(mo):.4g} %, "
            f"{int(np.count_nonzero(np.isnan(self.settling_time)))} not settled)"
        )


def _check_array(name: str, value: Any, minimum: float | None, strict: bool = False, allow_inf: bool = False) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        from ..errors import InvalidTypeError

        raise InvalidTypeError(f"{name} must be numbers, got {value!r}") from exc
    bad = ~np.isfinite(arr) if not allow_inf else (np.isnan(arr) | (arr == -np.inf))
    if minimum is not None:
        bad |= (arr <= minimum) if strict else (arr < minimum)
    if np.any(bad):
        i = np.flatnonzero(bad.ravel())[0]
        rel = ">" if strict else ">="
        lim = f" and {rel} {minimum:g}" if minimum is not None else ""
        where = f"{name}[{i}]" if arr.ndim else name
        raise InvalidValueError(f"{where} must be finite{lim}, got {arr.ravel()[i]:g}")
    return arr


def simulate_many(
    kp: Any,
    delay: Any,
    kv: Any = 0.0,
    step: Any = 1.0,
    *,
    vmax: Any = 1.0,
    velocity: str = "true",
    filter_wn: float = 38.0,
    filter_zeta: float = 1.0,
    period: float | None = None,
    sample_offset: Any = 0.0,
    t_end: float = 15.0,
    band: float = 0.02,
    gain: float = 1.0,
    lag: float = 0.0,
) -> BatchMetrics:
    """Exact step metrics of many loops at once (arrays broadcast together), on all cores.

    Parameters
    ----------
    kp, delay, kv, step, vmax, sample_offset : array_like
        Broadcast against each other; ``vmax`` may be ``inf`` or ``None`` for no saturation.
    velocity, filter_wn, filter_zeta, period, t_end, band, gain, lag
        As in :class:`~delaykit.models.altitude.AltitudeLoop` and :func:`simulate`, shared by all loops.

    Returns
    -------
    BatchMetrics

    Examples
    --------
    Table 1 of the paper in one call:

    >>> import numpy as np
    >>> m = simulate_many(kp=1.31, delay=np.array([4.0, 5.0, 5.6]) * 0.065)
    >>> np.round(m.overshoot, 3).tolist()
    [0.0, 0.398, 2.038]
    """
    kp_a = _check_array("kp", kp, 0.0)
    td_a = _check_array("delay", delay, 0.0)
    kv_a = _check_array("kv", kv, 0.0)
    st_a = _check_array("step", step, None)
    if np.any(st_a == 0):
        raise InvalidValueError("step must not be zero (metrics are relative to the step size)")
    vm_a = _check_array("vmax", np.inf if vmax is None else vmax, 0.0, strict=True, allow_inf=True)
    off_a = _check_array("sample_offset", sample_offset, 0.0)
    if velocity not in VELOCITY_CHOICES:
        raise InvalidValueError(f"velocity must be one of {', '.join(VELOCITY_CHOICES)}; got {velocity!r}")
    proto = AltitudeLoop(kp=1.0, delay=0.0, kv=1.0, velocity=velocity, filter_wn=filter_wn,
                         filter_zeta=filter_zeta, period=period, gain=gain, lag=lag)
    _, t_end, band = _check_run(1.0, t_end, band)
    try:
        shapes = np.broadcast(kp_a, td_a, kv_a, st_a, vm_a, off_a)
    except ValueError as exc:
        raise InvalidValueError(f"kp, delay, kv, step, vmax and sample_offset do not broadcast together: {exc}") from exc
    kp_b, td_b, kv_b, st_b, vm_b, off_b = (np.broadcast_to(a, shapes.shape).ravel() for a in (kp_a, td_a, kv_a, st_a, vm_a, off_a))
    if period is not None and np.any(off_b >= period):
        i = int(np.flatnonzero(off_b >= period)[0])
        raise InvalidValueError(f"sample_offset[{i}] must be less than the period {period:g} s, got {off_b[i]:g}")
    m = kp_b.size
    pars = np.empty((m, K.NPAR))
    P = K.PARAM
    pars[:, P["kp"]] = kp_b
    pars[:, P["kv"]] = kv_b
    pars[:, P["td"]] = td_b
    pars[:, P["vmax"]] = vm_b
    pars[:, P["filtered"]] = 1.0 if proto.velocity == "filtered" else 0.0
    pars[:, P["filtered"]] *= kv_b > 0
    pars[:, P["wf"]] = proto.filter_wn
    pars[:, P["zf"]] = proto.filter_zeta
    pars[:, P["period"]] = proto.period or 0.0
    pars[:, P["offset"]] = off_b
    pars[:, P["step"]] = st_b
    pars[:, P["t_end"]] = t_end
    pars[:, P["band"]] = band
    pars[:, P["gain"]] = proto.gain
    pars[:, P["lag"]] = proto.lag
    out = _batch(pars)
    o = K.OUT
    shape = shapes.shape
    col = lambda name: out[:, o[name]].reshape(shape)  # noqa: E731
    return BatchMetrics(
        kp=kp_b.reshape(shape), delay=td_b.reshape(shape), kv=kv_b.reshape(shape), step=st_b.reshape(shape),
        overshoot=col("overshoot"), peak_time=col("peak_time"), rise_time=col("rise_time"),
        settling_time=col("settling_time"), steady_state_error=col("final_error"),
        truncation=float(np.max(out[:, o["truncation"]])) if m else 0.0,
    )


def _batch(pars: np.ndarray) -> np.ndarray:
    import numba

    m = pars.shape[0]
    if m == 0:
        return np.empty((0, K.NOUT))
    nchunks = max(1, min(m, 8 * numba.get_num_threads()))
    out = K.run_batch(pars, _CAP0, nchunks)
    redo = np.flatnonzero(out[:, K.OUT["status"]] != 0)
    for i in redo:
        ws = _Workspace(store=False)
        ws.run(pars[i])
        out[i] = ws.out
    return out
