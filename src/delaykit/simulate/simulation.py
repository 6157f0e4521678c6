"""Exact simulation of any delayed loop, one loop at a time or thousands at once.

The solver (:mod:`delaykit.simulate._kernel`, compiled by numba or, for a single run after
:func:`~delaykit.simulate._jit.use_interpreter`, interpreted) is the method of steps with Taylor polynomials between
breakpoints: saturation switches, their images one delay later, sample instants, reference knots and the
jumps of neutral loops are all located to machine precision, so the responses and their metrics are exact
up to rounding.  The largest discarded Taylor coefficient is reported as ``truncation`` (typically below
1e-16); a loop too stiff to simulate in the allowed number of pieces raises an error saying so.
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
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _native
from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.altitude import AltitudeLoop, as_loop
from ..models.budget import MAX_GRID_POINTS, check_count, sample_count
from ..models.compensators import Compensator
from ..models.controllers import controller_branches, parallel
from ..models.loop import Loop
from ..models.signals import LoadStep, Ramp, Samples, Step, as_reference
from . import _jit
from . import _layout as K
from ._layout import LoopMatrices, loop_matrices, param_row, step_rate
from .metrics import StepMetrics, peak_time_of

__all__ = ["Response", "BatchMetrics", "Sampler", "simulate", "simulate_many", "as_loop", "SWEEPABLE"]

_CAP0 = 4096
_CAP_MAX = 1 << 21
"""The most polynomial pieces one run may use: some 1.3 kB each (the kernel's work arrays and the response's
copy), so under 3 GB (the work arrays grew eightfold past the old 1 << 22, to 16.8 million pieces and 20 GB)."""
_NO_T = np.empty(0)
_ROWS_PER_THREAD = 8  # the fewest loops of a batch per thread (a paper P loop's run: 11 us; a PID loop's: 100 us)
SWEEPABLE = ("kp", "ki", "kd", "kv", "delay", "output_delay", "umin", "umax", "vmax", "step", "sample_offset")
"""The parameters :func:`simulate_many` sweeps (arrays broadcast together)."""


class _Workspace:
    """Work arrays for the kernel, grown eightfold (up to ``_CAP_MAX`` pieces) when a run needs more.

    ``store`` keeps the output's pieces (for a :class:`Response`); ``t`` are times at which to evaluate y.  A run
    goes to the interpreted kernel while the process runs interpreted (:mod:`._jit`) and its piece budget lasts;
    one that reaches the budget (the kernel's capacity status) is redone compiled.  Batches are always compiled.
    """

    def __init__(self, store: bool, t: np.ndarray = _NO_T) -> None:
        self.store = store
        self.t = t
        self.cap = _CAP0
        self._alloc()

    def _alloc(self) -> None:
        c = self.cap
        self.u = (np.empty(c), np.empty(c), np.zeros((c, K.NC)), np.empty(c, dtype=np.int64),
                  np.empty(c, dtype=np.int8))
        self.y = (np.empty(c), np.empty(c), np.empty((c, K.NC)), np.empty((c, K.NC)), np.empty(c, dtype=np.int8))
        self.out = np.empty(K.NOUT)
        self.ez = np.empty(self.t.size)

    def run(self, row: np.ndarray, knots: tuple[np.ndarray, np.ndarray, np.ndarray]) -> int:
        """Run the kernel on one parameter row; returns the number of pieces."""
        nstates = int(row[K.HEAD["n"]])
        t_end, hmax = row[K.HEAD["t_end"]], row[K.HEAD["hmax"]]
        if t_end > 4 * _CAP_MAX * K.GROW * hmax:  # past what the longest pieces could cover: refused before any work
            with np.errstate(over="ignore", divide="ignore"):  # (hmax of 1e-308: an infinite count, refused)
                need = float(t_end / (K.GROW * hmax))
            self._too_many(row, need, None)
        while True:
            allowed = _jit.budget(nstates)  # pieces the interpreter may run (0: compiled)
            cap = min(self.cap, allowed) if allowed else self.cap
            kern = _jit.kernel(compiled=not allowed)
            n = kern.run_one(row, *knots, cap, *self.u, *self.y, self.out, self.store, self.t, self.ez)
            status = self.out[K.OUT["status"]]
            if status == K.STATUS_STALLED:
                raise InvalidValueError(_stall_message(row, self.out[K.OUT["t_stop"]]))
            if status == K.STATUS_CAPACITY:  # the pieces a whole run takes at this rate, refused if far too many
                t_stop, t_end = self.out[K.OUT["t_stop"]], row[K.HEAD["t_end"]]
                projected = n * t_end / t_stop if t_stop > 0 else math.inf
                if projected > 4 * _CAP_MAX or n >= _CAP_MAX:  # (the first pieces may be the shortest)
                    self._too_many(row, projected, n)
            if allowed:
                _jit.spend(nstates, n)
                if status == K.STATUS_CAPACITY and cap < self.cap:
                    continue  # the interpreter's budget is spent (n = cap): redo the run compiled
            if status == K.STATUS_OK:
                return n
            self.cap = min(self.cap * 8, _CAP_MAX)
            self._alloc()

    @staticmethod
    def _too_many(row: np.ndarray, projected: float, n: int | None) -> None:
        """Refuse a run that needs more than the piece budget: ``projected`` pieces, estimated at the rate of its
        first ``n`` (or, with ``None``, at the longest piece the loop's fastest rate allows)."""
        how = f"at the rate of the first {n}" if n is not None else "at the longest pieces its rates allow"
        raise InvalidValueError(
            f"the response needs more than {_CAP_MAX} polynomial pieces (about {projected:.3g} {how}; the loop's "
            f"fastest rate is {1 / row[K.HEAD['hmax']]:.3g} 1/s over t_end = {row[K.HEAD['t_end']]:g} s): the "
            "loop is too stiff or too long to simulate exactly; shorten t_end or remove the fast dynamics")


def _stall_message(row: np.ndarray, t_stop: float) -> str:
    """Why the kernel stopped advancing (its stalled status): pieces shorter than ``1e-9 max(1, t_end)`` one after
    another, named from the loop's row: delays that short, or else the command switching at its limits."""
    t_end = row[K.HEAD["t_end"]]
    delays = [d for d in (row[K.HEAD["ti"]], row[K.HEAD["to"]]) if d > 0]
    where = f"the simulation stalls at t = {t_stop:.6g} s"
    if delays and min(delays) < 1e-6 * max(1.0, t_end):
        return (f"{where}: the delay {min(delays):.3g} s is too short against t_end = {t_end:g} s for the method of "
                "steps on this loop: its breakpoints do not fade (a neutral loop whose jumps do not shrink), so each piece "
                "is at most one delay long; simulate the loop without the delay (delay=0) if so short a delay does "
                "not matter")
    if math.isfinite(row[K.HEAD["umin"]]) or math.isfinite(row[K.HEAD["umax"]]):
        return (f"{where}: the command switches at its limit without advancing (report the loop; "
                "antiwindup='backcalc' avoids such switching)")
    return f"{where}: its pieces shrink to nothing (report the loop)"


_SHORTEST = 1e-10
"""s: the shortest t_end a loop is simulated over.  The kernel resolves times to 1e-12 s (its tolerance is
``1e-12 max(1, t_end)``): a horizon of 1e-12 s or less ran no piece at all (metrics of nothing, an output that
could not be read), and one below 1e-10 s is resolved to no better than 1 %."""


def _check_run(t_end: float, band: float) -> tuple[float, float]:
    t_end = check_real("t_end (s)", t_end, minimum=0.0, strict=True)
    if t_end < _SHORTEST:
        raise InvalidValueError(f"t_end (s) must be at least {_SHORTEST:g} s (the simulator resolves times to 1e-12 s), "
                                f"got {t_end:g}; a system's own responses (delaykit.tf(...).step) take shorter times")
    band = check_real("band", band, minimum=0.0, strict=True, maximum=1.0)
    return t_end, band


def _nan_to_none(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


def _metrics_from_row(out: np.ndarray, norm: float, z0: float, band: float) -> StepMetrics | None:
    o = K.OUT
    if norm == 0.0:
        return None
    return StepMetrics(
        overshoot=float(out[o["overshoot"]]),
        peak_time=_nan_to_none(out[o["peak_time"]]),
        rise_time=_nan_to_none(out[o["rise_time"]]),
        settling_time=_nan_to_none(out[o["settling_time"]]),
        steady_state_error=float(out[o["final_error"]]),
        peak=float(z0 + out[o["peak"]] * norm),
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
    """The exact response of one loop, as piecewise polynomials.

    Evaluate it anywhere with :meth:`output` (alias :meth:`altitude`), :meth:`velocity` and
    :meth:`command`, or on a grid with :meth:`sample`.  ``metrics`` holds the exact step metrics, relative
    to the reference's final value (``None`` for a ramp, or when the reference ends where it started).
    """

    loop: Any
    reference: Step | Ramp | Samples
    disturbance: LoadStep | None
    z0: float
    t_end: float
    metrics: StepMetrics | None
    truncation: float
    starts: np.ndarray = field(repr=False)
    lengths: np.ndarray = field(repr=False)
    coeffs: np.ndarray = field(repr=False)
    dcoeffs: np.ndarray = field(repr=False)
    u_starts: np.ndarray = field(repr=False)
    u_lengths: np.ndarray = field(repr=False)
    u_coeffs: np.ndarray = field(repr=False)

    @property
    def step(self) -> float:
        """The reference's final value relative to its start (the step size, for a step)."""
        return self.reference.final_value(self.t_end)

    @property
    def breakpoints(self) -> np.ndarray:
        """Start times of the polynomial pieces of y (switches, delay images, samples, length caps)."""
        return self.starts.copy()

    def _locate(self, t: Any, starts: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, dtype=float)
        if not np.all(np.isfinite(t)):
            raise InvalidValueError("times to evaluate at must be finite")
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, starts.size - 1)
        x = np.clip((t - starts[idx]) / lengths[idx], 0.0, 1.0)
        return t, idx, x

    def output(self, t: Any) -> Any:
        """The output z0 + y(t) (z0 before t = 0; held at its last value after ``t_end``).

        A float for a scalar ``t``, an array for an array.
        """
        t, idx, x = self._locate(t, self.starts, self.lengths)
        z = self.z0 + _horner(self.coeffs[idx], x)
        return _out(np.where(t < 0, self.z0, z))

    altitude = output

    def velocity(self, t: Any) -> Any:
        """The output's derivative y'(t) (right-continuous at a neutral loop's jumps; 0 outside the run)."""
        t, idx, x = self._locate(t, self.starts, self.lengths)
        v = _horner(self.dcoeffs[idx], x)
        return _out(np.where((t < 0) | (t > self.t_end), 0.0, v))

    def command(self, t: Any) -> Any:
        """The command u(t) (before the input delay); 0 before t = 0."""
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
            sample_count(f"dt = {dt:g} s over t_end = {self.t_end:g} s", self.t_end, dt, "give a larger dt")
            t = np.arange(0.0, self.t_end + 0.5 * dt, dt)
            t = t[t <= self.t_end + 1e-12]
        t = np.asarray(t, dtype=float)
        return {"t": t, "z": self.output(t), "z_ref": self.z0 + self.reference.value(t), "u": self.command(t)}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary: the loop, the inputs and the metrics."""
        m = self.metrics.to_dict() if self.metrics is not None else {}
        return {
            "loop": self.loop.to_dict(),
            "step": self.step,
            "reference": self.reference.to_dict(),
            "disturbance": self.disturbance.to_dict() if self.disturbance is not None else None,
            "z0": self.z0,
            "t_end": self.t_end,
            **m,
            "pieces": int(self.starts.size),
            "truncation": self.truncation,
        }

    def __repr__(self) -> str:
        ref = (f"step={self.step:g}" if isinstance(self.reference, Step) else type(self.reference).__name__.lower())
        return f"Response({self.loop!r}, {ref}: {self.metrics!r})"


def _inputs(reference: Any, step: Any, disturbance: LoadStep | None) -> tuple[Step | Ramp | Samples, LoadStep | None]:
    ref = as_reference(step if reference is None else reference)
    if disturbance is not None and not isinstance(disturbance, LoadStep):
        raise InvalidTypeError(f"disturbance must be a LoadStep, got {type(disturbance).__name__}")
    if isinstance(ref, Step) and ref.size == 0.0 and disturbance is None:
        raise InvalidValueError("step must not be zero (metrics are relative to the step size)")
    return ref, disturbance


def simulate(
    loop: Any,
    step: float = 1.0,
    *,
    z0: float = 0.0,
    t_end: float = 15.0,
    band: float = 0.02,
    reference: Step | Ramp | Samples | None = None,
    disturbance: LoadStep | None = None,
) -> Response:
    """Simulate a loop's response to a reference step (or ramp, or samples) and a load disturbance.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        The loop.
    step : float
        Step size (either sign; zero only with a disturbance), at t = 0 from the level ``z0``.
    z0 : float
        The output's level before t = 0 (the response is ``z0 + y``).
    t_end : float
        End of the simulation (s).
    band : float
        Settling band as a fraction of the step.
    reference : Step, Ramp or Samples, optional
        Another reference instead of the step.
    disturbance : LoadStep, optional
        A step load disturbance at the plant's input: after the input delay (``LoadStep(..., at="plant")``, the
        default) or on the command before it (``at="command"``: the plant feels it one input delay later).

    Returns
    -------
    Response

    Examples
    --------
    >>> r = simulate(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered"), step=-0.5, z0=1.5)
    >>> round(r.metrics.overshoot, 4)
    1.6579
    >>> from delaykit.models import Controller, Loop
    >>> pid = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2, umin=-2, umax=2)
    >>> round(simulate(pid).metrics.settling_time, 3)
    5.696
    """
    gen = as_loop(loop)
    t_end, band = _check_run(t_end, band)
    z0 = check_real("z0", z0)
    ref, dist = _inputs(reference, step, disturbance)
    lay = loop_matrices(gen)
    norm = 0.0 if isinstance(ref, Ramp) else ref.final_value(t_end)
    knots = ref.knots()
    row = param_row(gen, lay, step=float(knots[1][0]), slope=0.0, norm=norm, t_end=t_end, band=band, dist=dist)
    with np.errstate(over="ignore", invalid="ignore"):
        reach = float(np.max(np.abs(ref.value(np.array([0.0, t_end])))))
    if not math.isfinite(reach):  # a ramp of 1e308 per s: the reference itself is beyond the floats by t_end
        raise InvalidValueError(f"the reference reaches {reach} by t_end = {t_end:g} s (beyond the floats): give a "
                                "smaller slope or a shorter run")
    ws = _Workspace(store=True)
    with np.errstate(over="ignore", invalid="ignore"):  # a response that overflows is an answer (its metrics say
        n = ws.run(row, knots)                           # inf, as for a diverging loop): no numpy warnings on the way
    out = ws.out
    (tu0, thu, tuc, _, _), (ty0, tyh, tyc, tyd, _) = ws.u, ws.y
    nu = int(out[K.OUT["u_pieces"]])
    return Response(
        loop=loop, reference=ref, disturbance=dist, z0=z0, t_end=t_end,
        metrics=_metrics_from_row(out, norm, z0, band), truncation=float(out[K.OUT["truncation"]]),
        starts=ty0[:n].copy(), lengths=tyh[:n].copy(), coeffs=tyc[:n].copy(), dcoeffs=tyd[:n].copy(),
        u_starts=tu0[:nu].copy(), u_lengths=thu[:nu].copy(), u_coeffs=tuc[:nu].copy(),
    )


class Sampler:
    """Evaluates a loop's exact step response at given times, fast and repeatedly (for fitting).

    Holds the work arrays, so that thousands of calls (one per trial parameter set) allocate nothing.

    Examples
    --------
    >>> s = Sampler(t=np.array([0.5, 1.0, 2.0]))
    >>> np.round(s(AltitudeLoop(kp=1.31, delay=0.368), step=1.0), 4).tolist()
    [0.132, 0.6315, 1.022]
    """

    def __init__(self, t: Any, t_end: float | None = None) -> None:
        self.t = np.ascontiguousarray(np.asarray(t, dtype=float))
        if self.t.ndim != 1 or self.t.size and np.any(np.diff(self.t) < 0):
            raise InvalidValueError("sample times must be a sorted 1-D array")
        self.t_end = float(t_end if t_end is not None else (self.t[-1] if self.t.size else 1.0)) + 1e-9
        self._ws = _Workspace(store=False, t=self.t)

    def __call__(self, loop: Any, step: float, z0: float = 0.0) -> np.ndarray:
        """The output at the sample times (relative to the step at t = 0)."""
        gen = as_loop(loop)
        row = param_row(gen, loop_matrices(gen), step=step, slope=0.0, norm=step, t_end=max(self.t_end, 1e-6),
                        band=0.02, dist=None)
        self._ws.run(row, (np.zeros(1), np.array([step]), np.zeros(1)))
        return z0 + self._ws.ez


@dataclass(frozen=True, repr=False, eq=False)
class BatchMetrics:
    """Step metrics of many loops, as arrays (NaN where a value is absent: no peak, not settled).

    Attributes
    ----------
    params : dict of str to ndarray
        The swept parameters, broadcast to a common shape.
    overshoot, peak_time, rise_time, settling_time, steady_state_error : ndarray
        As in :class:`~delaykit.simulate.metrics.StepMetrics`, in percent, seconds and output units.
    truncation : float
        The largest discarded Taylor coefficient over all loops (relative to the step).
    """

    params: dict[str, np.ndarray]
    overshoot: np.ndarray
    peak_time: np.ndarray
    rise_time: np.ndarray
    settling_time: np.ndarray
    steady_state_error: np.ndarray
    truncation: float

    def __getattr__(self, name: str) -> np.ndarray:
        params = self.__dict__.get("params", {})
        if name in params:
            return params[name]
        raise AttributeError(name)

    def __len__(self) -> int:
        return int(self.overshoot.size)

    def row(self, i: int) -> dict[str, Any]:
        """One loop's swept parameters and metrics as a JSON-ready dict."""
        keys = ("overshoot", "peak_time", "rise_time", "settling_time", "steady_state_error")
        d = {k: _nan_to_none(float(v.flat[i])) for k, v in self.params.items()}
        d.update({k: _nan_to_none(float(getattr(self, k).flat[i])) for k in keys})
        return d

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: a list of rows."""
        return {"loops": [self.row(i) for i in range(len(self))], "truncation": self.truncation}

    def __repr__(self) -> str:
        mo = self.overshoot
        return (
            f"BatchMetrics({len(self)} loops, overshoot {np.nanmin(mo):.4g} to {np.nanmax(mo):.4g} %, "
            f"{int(np.count_nonzero(np.isnan(self.settling_time)))} not settled)"
        )


def _check_array(name: str, value: Any, minimum: float | None = None, strict: bool = False,
                 maximum: float | None = None, allow_inf: bool = False) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except OverflowError:  # an integer of hundreds of digits
        raise InvalidValueError(f"{name} must be finite, got an integer beyond the floats") from None
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be numbers, got {value!r:.80}") from exc
    bad = np.isnan(arr) if allow_inf else ~np.isfinite(arr)
    if minimum is not None:
        bad |= (arr <= minimum) if strict else (arr < minimum)
    if maximum is not None:
        bad |= arr > maximum
    if np.any(bad):
        i = np.flatnonzero(bad.ravel())[0]
        lim = ""
        if minimum is not None:
            lim += f" and {'>' if strict else '>='} {minimum:g}"
        if maximum is not None:
            lim += f" and <= {maximum:g}"
        where = f"{name}[{i}]" if arr.ndim else name
        raise InvalidValueError(f"{where} must be {'a number' if allow_inf else 'finite'}{lim}, got {arr.ravel()[i]:g}")
    return arr


def simulate_many(loop: Any, *, t_end: float = 15.0, band: float = 0.02, **sweep: Any) -> BatchMetrics:
    """Exact step metrics of many variants of one loop at once (arrays broadcast together), on all cores.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        The loop whose parameters are swept (its values are used for the parameters not swept).
    t_end, band : float
        As in :func:`simulate`, shared by all loops.
    **sweep : array_like
        Any of ``kp, ki, kd, kv`` (the controller's gains, as the controller uses them; for a
        :class:`~delaykit.models.Compensator`, its primary controller's, or a predictor's own ``kp, ki``), ``delay,
        output_delay, umin, umax`` (or ``vmax`` for both), ``step`` (default 1) and ``sample_offset``.

    Returns
    -------
    BatchMetrics

    Examples
    --------
    Table 1 of the paper in one call:

    >>> import numpy as np
    >>> m = simulate_many(AltitudeLoop(kp=1.31, delay=0.3), delay=np.array([4.0, 5.0, 5.6]) * 0.065)
    >>> np.round(m.overshoot, 3).tolist()
    [0.0, 0.398, 2.038]
    """
    if isinstance(loop, AltitudeLoop) and "kv" in sweep and loop.kv == 0.0:
        loop = loop.replace(kv=1.0)  # the PV structure, swept from Kv = 0 (where it is the P loop)
    gen = as_loop(loop)
    c0 = gen.controller
    if "kv" in sweep and c0.kind == "pv" and c0.velocity == "filtered" and c0.kv == 0.0:
        gen = gen.replace(kv=1.0)  # the filter's states exist; rows with Kv = 0 get the P structure below
    t_end, band = _check_run(t_end, band)
    unknown = sorted(set(sweep) - set(SWEEPABLE))
    if unknown:
        raise InvalidValueError(f"simulate_many cannot sweep {', '.join(unknown)}; it sweeps {', '.join(SWEEPABLE)}")
    c = gen.controller
    owner = c.primary if isinstance(c, Compensator) and c.primary is not None else c  # whose gains are swept
    own = (owner.gain_names if owner is not c or not isinstance(c, Compensator)
           else ("kp", "ki"))  # a predictor: its kp and ki
    for g in ("ki", "kd", "kv"):
        if g in sweep and g not in own:
            what = f"the {c.kind} compensator's {owner.kind} primary controller" if owner is not c else f"a {c.kind} controller"
            raise InvalidValueError(f"{what} has no {g} to sweep")
    if owner.kind == "tf" and "kp" in sweep:
        raise InvalidValueError("a tf controller has no kp to sweep")
    if "vmax" in sweep and ("umin" in sweep or "umax" in sweep):
        raise InvalidValueError("sweep vmax or umin/umax, not both")
    arrays: dict[str, np.ndarray] = {}
    for name, v in sweep.items():
        check_count(name, np.size(v), MAX_GRID_POINTS, "values", "sweep fewer loops at once")  # (before any copy)
        if name in ("kp", "ki", "kd", "kv", "step"):
            arrays[name] = _check_array(name, v)
        elif name in ("delay", "output_delay", "sample_offset"):
            arrays[name] = _check_array(name, v, minimum=0.0)
        elif name == "vmax":
            arrays[name] = _check_array(name, np.inf if v is None else v, minimum=0.0, strict=True, allow_inf=True)
        elif name == "umin":
            arrays[name] = _check_array(name, v, maximum=0.0, allow_inf=True)
        else:
            arrays[name] = _check_array(name, v, minimum=0.0, allow_inf=True)
    if "step" not in arrays:
        arrays["step"] = np.asarray(1.0)
    if np.any(arrays["step"] == 0):
        raise InvalidValueError("step must not be zero (metrics are relative to the step size)")
    try:
        shape = np.broadcast_shapes(*(a.shape for a in arrays.values()))
    except ValueError as exc:
        raise InvalidValueError(f"{', '.join(arrays)} do not broadcast together: {exc}") from None
    check_count(f"a sweep of shape {shape}", math.prod(shape), MAX_GRID_POINTS, "loops", "sweep fewer loops at once")
    flat = {k: np.broadcast_to(a, shape).ravel() for k, a in arrays.items()}
    m = int(np.prod(shape))
    if not isinstance(c, Compensator) and c.filtered and "kv" in flat and np.any(flat["kv"] == 0):
        # a filtered PV law with Kv = 0 is the P law: those loops get the P structure (no filter states)
        zero = flat["kv"] == 0
        pars = np.empty((m, K.NPAR))
        for mask, base in ((zero, gen.replace(kv=0.0)), (~zero, gen)):
            if np.any(mask):
                sub = {k: v[mask] for k, v in flat.items() if not (k == "kv" and base.controller.kind == "p")}
                pars[mask] = _sweep_rows(base, int(mask.sum()), sub, t_end, band)
        rows = _Sweep.of_rows(pars)
    else:
        rows = _sweep(gen, m, flat, t_end, band)
    out = _batch(rows)
    o = K.OUT
    col = lambda name: out[:, o[name]].reshape(shape)  # noqa: E731
    params = {k: np.broadcast_to(a, shape).copy() for k, a in arrays.items()}
    return BatchMetrics(
        params=params, overshoot=col("overshoot"), peak_time=peak_time_of(col("overshoot"), col("peak_time")),
        rise_time=col("rise_time"),
        settling_time=col("settling_time"), steady_state_error=col("final_error"),
        truncation=float(np.max(out[:, o["truncation"]])) if m else 0.0,
    )


class _Sweep:
    """Parameter rows of ``m`` loops, compactly: one shared row and the columns that differ from loop to loop (what
    :func:`._kernel.run_sweep` reads; 10,000 loops' rows written out are 35 MB, 7 ms of the paper's batch to write).

    ``self[j]`` is column ``j``: its ``m`` values where the loops differ in it, else the shared value (a float).
    """

    def __init__(self, row: np.ndarray, m: int) -> None:
        self.row = row
        self.m = m
        self.cols: dict[int, np.ndarray] = {}  # column -> its m values (the row's entry there is unused)

    @classmethod
    def of_rows(cls, pars: np.ndarray) -> _Sweep:
        """The sweep of whole rows (those of loops whose structures differ): the columns where any row differs."""
        sw = cls(pars[0].copy() if len(pars) else np.zeros(K.NPAR), len(pars))
        if len(pars):
            for j in np.flatnonzero(np.any(pars.view(np.int64) != pars[:1].view(np.int64), axis=0)):
                sw.cols[int(j)] = pars[:, j].copy()
        return sw

    def __getitem__(self, j: int) -> Any:
        c = self.cols.get(j)
        return float(self.row[j]) if c is None else c

    def __setitem__(self, j: int, values: Any) -> None:
        """Column ``j`` set to ``values``: one value shared by every loop, or one per loop."""
        v = np.asarray(values, dtype=float)
        if v.ndim == 0:
            self.row[j] = v
            self.cols.pop(j, None)
        else:
            self.cols[j] = np.array(np.broadcast_to(v, (self.m,)))

    def put(self, j: int, i: Any, values: Any) -> None:
        """Column ``j``'s values of the loops ``i`` set to ``values``."""
        c = self.cols.get(j)
        if c is None:
            c = self.cols[j] = np.full(self.m, self.row[j])
        c[i] = values

    def one(self, i: int) -> np.ndarray:
        """Loop ``i``'s row."""
        r = self.row.copy()
        for j, c in self.cols.items():
            r[j] = c[i]
        return r

    def rows(self, which: Any = slice(None)) -> np.ndarray:
        """The rows written out (of the loops ``which``, an index or mask)."""
        n = np.arange(self.m)[which].size
        pars = np.repeat(self.row[None, :], n, axis=0)
        for j, c in self.cols.items():
            pars[:, j] = c[which]
        return pars

    def compact(self, which: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """The columns that differ and their values, ``(m, k)`` (of the loops ``which``), for
        :func:`._kernel.run_sweep` (with :attr:`row`); a column every loop has the same bits in goes to the row."""
        for j in [j for j, c in self.cols.items() if not np.any(c.view(np.int64) != c[:1].view(np.int64))]:
            self.row[j] = self.cols.pop(j)[0]  # (no loops: no columns)
        cols = np.array(sorted(self.cols), dtype=np.int64)
        vals = np.empty((self.m, cols.size))
        for k, j in enumerate(cols):
            vals[:, k] = self.cols[int(j)]
        return cols, vals if which is None else np.ascontiguousarray(vals[which])


def _sweep_rows(gen: Loop, m: int, flat: dict[str, np.ndarray], t_end: float, band: float) -> np.ndarray:
    """Parameter rows of ``m`` variants of a loop, written out (see :func:`_sweep`)."""
    return _sweep(gen, m, flat, t_end, band).rows()


def _sweep(gen: Loop, m: int, flat: dict[str, np.ndarray], t_end: float, band: float) -> _Sweep:
    """Parameter rows of ``m`` variants of a loop: its row, with the swept columns written over."""
    lay = loop_matrices(gen)
    row0 = param_row(gen, lay, step=1.0, slope=0.0, norm=1.0, t_end=t_end, band=band, dist=None)
    H = K.HEAD
    swept = [name for name in ("kp", "ki", "kd", "kv") if name in flat]
    lays = [lay] * m
    if swept and isinstance(gen.controller, Compensator):
        # a compensator's gains enter its realisation through the model: each variant's row is built whole
        pars = np.repeat(row0[None, :], m, axis=0)
        for i in range(m):
            v = gen.replace(controller=_with_gains(gen.controller, {k: float(flat[k][i]) for k in swept}))
            lays[i] = loop_matrices(v)
            pars[i] = param_row(v, lays[i], step=1.0, slope=0.0, norm=1.0, t_end=t_end, band=band, dist=None)
        sw = _Sweep.of_rows(pars)
    else:
        sw = _Sweep(row0, m)
    if swept and not isinstance(gen.controller, Compensator):
        g = {name: flat.get(name, np.full(m, getattr(gen.controller, name))) for name in ("kp", "ki", "kd", "kv")}
        _gain_columns(gen, lay, sw, g)
    for name, col in (("delay", "ti"), ("output_delay", "to"), ("umin", "umin"), ("umax", "umax"),
                      ("sample_offset", "offset")):
        if name in flat:
            sw[H[col]] = flat[name]
    if "vmax" in flat:
        sw[H["umin"]] = -flat["vmax"]
        sw[H["umax"]] = flat["vmax"]
    umin, umax = np.broadcast_to(sw[H["umin"]], (m,)), np.broadcast_to(sw[H["umax"]], (m,))
    if np.any(umin >= umax):
        i = int(np.flatnonzero(umin >= umax)[0])
        raise InvalidValueError(f"umin must be below umax; loop {i} has umin={umin[i]:g}, umax={umax[i]:g}")
    per = gen.period
    off = np.broadcast_to(sw[H["offset"]], (m,))
    if per is None and np.any(off != 0):
        raise InvalidValueError("sample_offset needs a sampled loop (period set)")
    if per is not None and np.any(off >= per):
        i = int(np.flatnonzero(off >= per)[0])
        raise InvalidValueError(f"sample_offset[{i}] must be less than the period {per:g} s, got {off[i]:g}")
    st = flat["step"]
    sw[H["step"]] = st
    sw[H["norm"]] = st
    sw[H["scale"]] = np.maximum(1.0, np.maximum(np.abs(sw[H["dvr"]] * st), np.abs(st)))
    if not gen.sampled:  # short delays (0 included): the rates of the loop without them too (see step_rate)
        delay = np.broadcast_to(np.maximum(sw[H["ti"]], sw[H["to"]]), (m,))
        short = np.flatnonzero(delay <= K.SELF * np.broadcast_to(sw[H["hmax"]], (m,)))
        for i in short:
            row = sw.one(i)
            cv = row[K.OFF_CV:K.OFF_CV + lays[i].M.shape[0]]
            rate = step_rate(lays[i], row[H["dvy"]], row[H["dvv"]], cv, float(delay[i]), False)
            sw.put(H["hmax"], i, 1.0 / max(rate, 1e-9))
    return sw


def _with_gains(c: Compensator, gains: dict[str, float]) -> Compensator:
    """The compensator with swept gains: its primary controller's (Smith predictors) or its own (predictor)."""
    if c.primary is not None:
        return c.replace(primary=c.primary.replace(**gains))
    return c.replace(**gains)


def _gain_columns(loop: Loop, lay: LoopMatrices, sw: _Sweep, g: dict[str, np.ndarray]) -> None:
    """Write the controller's gain-dependent entries of many rows (the structure is the loop's): the law of
    :func:`~delaykit.models.controllers.controller_branches` evaluated at the arrays of gains; only the entries
    that vary with them become per-loop columns."""
    c = loop.controller
    H = K.HEAD
    if c.antiwindup == "backcalc" and np.any(g["ki"] == 0):
        raise InvalidValueError("back-calculation anti-windup needs ki != 0 in every swept loop")
    rz = parallel(controller_branches(c, **g))
    npl, nc = lay.npl, rz.order
    for name in ("dvr", "dvy", "dvv"):
        sw[H[name]] = getattr(rz, name)
    for off, mat in ((K.OFF_CV, rz.Cc), (K.OFF_BAW, rz.Baw)):
        mat = np.asarray(mat, dtype=float)
        for k in range(nc):
            sw[off + npl + k] = mat[..., k]
    rate0 = float(np.max(np.abs(np.linalg.eigvals(lay.M)))) if lay.M.size else 0.0
    sw[H["hmax"]] = 1.0 / np.maximum(np.maximum(rate0, np.abs(np.asarray(sw[H["dvy"]]) * lay.dyd)), 1e-9)


def _event_stepped(sw: _Sweep | np.ndarray) -> np.ndarray:
    """Which loops of a sweep (or parameter rows) :mod:`._sampled_batch` simulates (stepping exactly from sample to
    sample with matrix exponentials): a sampled controller, no output delay, no anti-windup and no predictor (no
    command or model-delay terms).  The batch's reference is a step or ramp and its load, if any, a step: both
    qualify."""
    if isinstance(sw, np.ndarray):
        sw = _Sweep.of_rows(sw)
    H = K.HEAD
    ok = (sw[H["period"]] > 0.0) & (sw[H["to"]] == 0.0) & (sw[H["aw"]] == 0.0) & (sw[H["tm"]] == 0.0)
    lo, hi = K.OFF_BU, K.OFF_BUM + K.MAXN  # the command's and the delayed command's couplings: none
    shared = sw.row[lo:hi].copy()
    for j, c in sw.cols.items():
        if lo <= j < hi:
            shared[j - lo] = 0.0
            ok = ok & (c == 0.0)
    return np.broadcast_to(ok & (not np.any(shared != 0.0)), (sw.m,))


def _threads(kern: Any, rows: int) -> int:
    """The threads a batch kernel module runs ``rows`` loops on: numba's where numba compiled it, else the CPUs this
    process may use (OpenMP's default; ``OMP_NUM_THREADS`` where set); fewer where a thread would get less than
    ``_ROWS_PER_THREAD`` loops (waking a thread costs more than a few runs: 10 ms, not 0.04, for 2 loops on 2 threads
    at load 9)."""
    return max(1, min(_cores(kern), rows // _ROWS_PER_THREAD))


def _cores(kern: Any) -> int:
    if kern.__name__.endswith("_numba"):
        import numba

        return int(numba.get_num_threads())
    env = os.environ.get("OMP_NUM_THREADS", "").split(",")[0].strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:  # (not on macOS or Windows)
        return os.cpu_count() or 1


def _batch(sw: _Sweep) -> np.ndarray:
    m = sw.m
    if m == 0:
        return np.empty((0, K.NOUT))
    out = np.empty((m, K.NOUT))
    fast = _event_stepped(sw)
    if np.any(fast):  # sampled loops: from event to event with matrix exponentials
        sb = _native.load("delaykit.simulate", "_sampled_batch")
        sub = sw.rows(fast)
        threads = _threads(sb, sub.shape[0])  # one work set per thread (it ran on one before, whatever the machine)
        out[fast] = sb.run_batch(sub, max(1, min(sub.shape[0], 8 * threads)), threads)
    rest = np.flatnonzero(~fast)
    if rest.size == 0:
        return out
    kern = _jit.kernel(compiled=True)
    # the shared row and the columns that differ (the usual case, every loop here: no copy of the values)
    cols, vals = sw.compact(None if rest.size == m else rest)
    threads = _threads(kern, rest.size)
    res = kern.run_sweep(sw.row, cols, vals, _CAP0, max(1, min(rest.size, 8 * threads)), threads)
    redo = np.flatnonzero(res[:, K.OUT["status"]] != K.STATUS_OK)  # a stall raises its error from run()
    for i in redo:
        row = sw.one(int(rest[i]))
        ws = _Workspace(store=False)
        ws.run(row, (np.zeros(1), np.array([row[K.HEAD["step"]]]), np.zeros(1)))
        res[i] = ws.out
    if rest.size == m:
        return res
    out[rest] = res
    return out
