"""The least-squares machinery of :mod:`.identification`: logs prepared for fitting, the compiled residuals and
their finite-difference Jacobian, the starting points, and a bounded Levenberg-Marquardt solver.

One trial point of a fit is one compiled call: the plant's realisation, the split of the delay into whole periods
and a fraction, the exact held-input matrices, every log simulated (open loop from its input, closed loop through
the known P/PV controller) and each log's offset and hover level projected out.  A closed loop through any other
controller (PI, PID, PD, filtered PV, a transfer function; continuous or sampled) is simulated by the general
simulator instead (:mod:`._closed_general`, dispatched to from here).  Private: :mod:`.identification` is the
public face; only :class:`IdentificationError` is exported (and re-exported there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import _native
from ..errors import InvalidValueError, check_real
from ..models.altitude import as_loop
from ..models.controllers import Controller
from ..models.hold import SNAP
from ..models.loop import Loop
from ..models.transfer import TransferFunction
from ..simulate.discrete import closed_loop_response, held_delay_model, held_matrices_of, held_response
from .iodata import Experiment
from .structures import Structure

__all__ = ["IdentificationError"]

FK = _native.load("delaykit.identify", "_fitkernel")  # the compiled loops of the fits (Cython, else numba)

# the compiled kernels' status values (code reads these, never a message)
_OK, _STIFF, _ALGEBRAIC = FK.OK, FK.STIFF_PLANT, FK.ALGEBRAIC


class IdentificationError(InvalidValueError):
    """The data or the settings do not allow an identification (the message says why)."""


# -- the controller of a closed-loop fit --------------------------------------------------------------------
@dataclass(frozen=True)
class _Law:
    kp: float
    kv: float
    umin: float
    umax: float
    period: float | None


def _law(loop: Loop | None, general: bool = False) -> Any:
    """The controller of a closed-loop fit: a :class:`_Law` (the compiled path) for a static P or PV (true
    velocity) law sampled at the log's rate, unless ``general`` (a command at rest was given); otherwise the
    general simulator's law (:func:`._closed_general.general_law`)."""
    if loop is None:
        return None
    loop = as_loop(loop)
    c = loop.controller
    static = getattr(c, "kind", "") in ("p", "pv") and not c.filtered
    if static and loop.period is None:
        raise IdentificationError(
            "a P or PV (true velocity) controller is simulated at the log's samples in a closed-loop fit, so the "
            "loop must be sampled: give it the log's sample period (period=..., --period on the command line); "
            "this loop's controller is continuous")
    if loop.delay or loop.output_delay:
        raise IdentificationError("the loop given for a closed-loop fit must have no delay: the delay is what is "
                                  f"identified (got delay {loop.delay:g} s, output delay {loop.output_delay:g} s)")
    if not static or general:
        from ._closed_general import general_law

        return general_law(loop)
    return _Law(c.kp, c.kv if c.kind == "pv" else 0.0, loop.umin, loop.umax, loop.period)


def _law_dict(law: Any) -> dict[str, Any] | None:
    """The controller's saved form (:attr:`IdentifiedModel.closed_loop`); ``None`` for open loop."""
    if law is None:
        return None
    if not isinstance(law, _Law):
        from ._closed_general import law_to_dict

        return law_to_dict(law)
    return {"kind": "pv" if law.kv else "p", "kp": law.kp, "kv": law.kv,
            "umin": law.umin if math.isfinite(law.umin) else None,
            "umax": law.umax if math.isfinite(law.umax) else None, "period": law.period}


def _law_from_dict(c: dict[str, Any] | None) -> Any:
    """The controller back from :func:`_law_dict`'s form (a P/PV law by its gains: files written before the kind
    was saved have none)."""
    if c is None:
        return None
    if "controller" in c:
        from ._closed_general import law_from_dict

        return law_from_dict(c)
    kind = c.get("kind", "pv" if c.get("kv") else "p")
    if kind not in ("p", "pv"):
        raise InvalidValueError(f"the closed loop's controller kind must be 'p' or 'pv' (or a 'controller' table), "
                                f"got {kind!r}")
    kp = check_real("the closed loop's kp", c["kp"])
    kv = check_real("the closed loop's kv", c.get("kv") or 0.0)
    Controller(kind, kp=kp, kv=kv)  # (the controllers' rules: no kv for p, the gains of one sign)
    umin = -math.inf if c.get("umin") is None else check_real("the closed loop's umin", c["umin"])
    umax = math.inf if c.get("umax") is None else check_real("the closed loop's umax", c["umax"])
    if not umin < umax:
        raise InvalidValueError(f"the closed loop's umin {umin:g} must be below its umax {umax:g}")
    period = c.get("period")
    if period is not None:
        period = check_real("the closed loop's period (s)", period, minimum=0.0, strict=True)
    return _Law(kp, kv, umin, umax, period)


# -- one log, prepared ------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Prepared:
    exp: Experiment
    outputs: tuple[str, ...]
    rate: str | None
    drive: np.ndarray          # deviation input (open) or reference (closed)
    lo: float
    hi: float
    meas: dict[str, np.ndarray]  # deviation outputs
    keep: dict[str, np.ndarray]  # indices of fresh samples per output
    base: dict[str, float]
    wander: dict[str, float]
    u0: float | None = None      # the absolute command at rest, where known (general closed loop)


def _fresh(x: np.ndarray) -> np.ndarray:
    keep = np.ones(x.size, bool)
    keep[1:] = x[1:] != x[:-1]
    return np.flatnonzero(keep)


def _prepare(exp: Experiment, outputs: tuple[str, ...], rate: str | None, law: Any, fresh_only: bool,
             u0: float | str | None = None) -> _Prepared:
    for o in outputs + ((rate,) if rate else ()):
        if o not in exp.outputs:
            raise IdentificationError(f"{exp.name}: no output column {o!r} (it has {', '.join(exp.outputs)})")
    if law is None and exp.closed:
        raise IdentificationError(f"{exp.name}: a log with a reference needs the controller for a closed-loop fit "
                                  "(give the loop), or give its input column for an open-loop fit")
    if law is not None and not exp.closed:
        raise IdentificationError(f"{exp.name}: a closed-loop fit needs the reference column; this log has an input")
    if law is not None and not exp.uniform and getattr(law, "period", None) is not None:
        dt = np.diff(exp.t)
        raise IdentificationError(
            f"{exp.name}: the controller is sampled at the log's samples, but the log's clock is not uniform "
            f"(intervals {dt.min():.6g} to {dt.max():.6g} s, median {exp.period:.6g} s); put the log on a uniform "
            f"clock with resample=PERIOD (--resample PERIOD), e.g. {exp.period / 10:.3g} s, or fit open loop "
            "from the logged command")
    names = outputs + ((rate,) if rate else ())
    base = {o: exp.baseline(o) for o in names}
    meas = {o: exp.outputs[o] - base[o] for o in names}
    pre = exp.onset if not exp.starts_moving else 0
    wander = {o: float(np.std(exp.outputs[o][:pre])) if pre >= 5 else math.nan for o in names}
    keep = {o: (_fresh(exp.outputs[o]) if fresh_only else np.arange(exp.t.size)) for o in names}
    if law is not None and not isinstance(law, _Law):
        from ._closed_general import prepare

        common = {"outputs": outputs, "rate": rate, "meas": meas, "keep": keep, "base": base, "wander": wander}
        return prepare(exp, law, common, u0)
    if law is None:
        drive = exp.u - exp.drive_baseline  # type: ignore[operator]
        lo, hi = -math.inf, math.inf
    else:
        if law.period is None or abs(law.period - exp.period) > 1e-3 * exp.period:
            raise IdentificationError(
                f"{exp.name}: the controller's period ({law.period} s) must equal the log's sample period "
                f"({exp.period:.6g} s): closed-loop fits simulate the controller at the log's samples")
        r0 = exp.drive_baseline
        y0 = base[outputs[0]]
        u0 = min(max(law.kp * (r0 - y0), law.umin), law.umax)
        # u - u0 = clip(kp (r - y), umin, umax) - u0 = clip(kp (r - y0 - u0 / kp - (y - y0)), umin - u0, umax - u0)
        drive = exp.r - y0 - (u0 / law.kp if law.kp else 0.0)  # type: ignore[operator]
        lo, hi = law.umin - u0, law.umax - u0
    return _Prepared(exp, outputs, rate, np.ascontiguousarray(drive), lo, hi, meas, keep, base, wander)


def _simulate(prep: _Prepared, plant: TransferFunction, delay: float, law: Any,
              cache: dict | None = None) -> dict[str, np.ndarray]:
    # nothing sent arrives within the log after more than its length: a longer delay (1e300 s) gives the same
    # response as this one, whose number of samples is an integer
    delay = min(delay, prep.exp.duration + 2.0 * prep.exp.period)
    if law is not None and not isinstance(law, _Law):
        from ._closed_general import simulate

        return simulate(prep, plant, delay, law)
    if law is None and not prep.exp.uniform:
        from ._clock import simulate as on_its_clock

        return on_its_clock(prep, plant, delay)
    key = (prep.exp.period, delay)
    model = None if cache is None else cache.get(key)
    if model is None:
        model = held_delay_model(plant, prep.exp.period, delay)
        if cache is not None:
            cache[key] = model
    if law is None:
        res = held_response(model, prep.drive)
    else:
        res = closed_loop_response(model, prep.drive, kp=law.kp, kv=law.kv, umin=prep.lo, umax=prep.hi)
    out = {prep.outputs[0]: res.y}
    if prep.rate:
        out[prep.rate] = res.dy
    return out


# -- the fit ----------------------------------------------------------------------------------------------
class _Problem:
    """Residuals of one structure on prepared logs, in fitting coordinates (log scale for positive values).

    Every evaluation runs compiled code end to end: the structure's well-scaled realisation, the exact one-period
    matrices (:func:`~delaykit.simulate.discrete.held_matrices_of`), all logs in one pass and the projection of
    the per-log linear nuisance parameters.  Constructed with a law of the general simulator, it is a
    :class:`._closed_general.GeneralProblem`.
    """

    compiled = True  # residuals by the compiled kernels (False: :meth:`raw` is overridden)
    max_nfev = 300  # residual evaluations allowed to one Levenberg-Marquardt run

    def __new__(cls, st: Structure, preps: list[_Prepared], law: Any, *args: Any, **kwargs: Any) -> "_Problem":
        if cls is _Problem and st.limited:
            from ._accel import AccelProblem

            cls = AccelProblem
        elif cls is _Problem and law is not None and not isinstance(law, _Law):
            from ._closed_general import GeneralProblem

            cls = GeneralProblem
        elif cls is _Problem and law is None:
            from ._clock import ClockProblem, any_clock

            if any_clock(preps, law):
                cls = ClockProblem
        return super().__new__(cls)

    def __init__(self, st: Structure, preps: list[_Prepared], law: _Law | None, weights: dict[str, float],
                 fit_offset: bool) -> None:
        self.st, self.preps, self.law, self.w, self.fit_offset = st, preps, law, weights, fit_offset
        self.pos = np.array(st.positive)
        self._pos8 = self.pos.view(np.uint8)  # (the kernels' flags are bytes)
        self.fit_bias = law is None and st.integrating
        self.h = preps[0].exp.period
        self.first, self.rate = preps[0].outputs[0], preps[0].rate
        self.starts = np.cumsum([0] + [q.drive.size for q in preps]).astype(np.int64)
        self.drive = np.ascontiguousarray(np.concatenate([q.drive for q in preps]))
        self.lo = np.array([q.lo for q in preps], dtype=float)
        self.hi = np.array([q.hi for q in preps], dtype=float)
        self.k0, self.p0, self.m0 = self._kept(self.first)
        self.k1, self.p1, self.m1 = self._kept(self.rate) if self.rate else self._kept(None)
        n = self.drive.size
        self._y, self._dy, self._uy, self._udy, self._u = (np.empty(n) for _ in range(5))
        self._mats, self._vecs = FK.workspace(max(st.code, 0), st.size)  # (the kernels' work arrays, made once)
        sizes = []
        for i in range(len(preps)):
            sizes += [(self.first, int(self.p0[i + 1] - self.p0[i]))]
            if self.rate:
                sizes += [(self.rate, int(self.p1[i + 1] - self.p1[i]))]
        self._sizes = sizes
        self._rw = np.concatenate([np.full(k, float(weights[o])) for o, k in sizes])

    def _kept(self, name: str | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if name is None:
            return np.zeros(0, np.int64), np.zeros(len(self.preps) + 1, np.int64), np.zeros(0)
        k = [q.keep[name] for q in self.preps]
        return (np.ascontiguousarray(np.concatenate(k).astype(np.int64)),
                np.cumsum([0] + [x.size for x in k]).astype(np.int64),
                np.ascontiguousarray(np.concatenate([q.meas[name][x] for q, x in zip(self.preps, k)]), dtype=float))

    def to_phys(self, z: np.ndarray) -> np.ndarray:
        return np.where(self.pos, np.exp(np.clip(z, -60.0, 60.0)), z)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds in fitting coordinates: a time constant is at least :data:`_SHORTEST` of a period (shorter lags
        are indistinguishable from none at the samples, and would make the plant too stiff to sample)."""
        lb = np.full(self.st.size, -np.inf)
        ub = np.full(self.st.size, np.inf)
        for i, (pos, unit) in enumerate(zip(self.st.positive, self.st.units)):
            if pos and unit == "s":
                lb[i] = math.log(_SHORTEST * self.h)
        return lb, ub

    def to_fit(self, p: np.ndarray) -> np.ndarray:
        return np.where(self.pos, np.log(np.maximum(p, 1e-300)), p)

    def raw(self, p: np.ndarray) -> np.ndarray:
        """Raw (unweighted) residuals at the fresh samples, all logs, each log's first output then its rate, after
        the per-log linear nuisance parameters (output offsets, the input's hover level) are projected out.
        Non-finite where the trial plant's simulation overflows."""
        p = np.ascontiguousarray(p, dtype=float)
        if not p[-1] >= 0.0:
            raise InvalidValueError(f"delay (s) must be >= 0, got {p[-1]!r}")
        out = np.empty(self._rw.size)
        data = self._data()
        status = FK.evaluate(self.st.code, p, *data, out) if self.st.code >= 0 else _STIFF
        if status == _STIFF:  # a plant far too fast for its period (or without a compiled realisation): SciPy
            A, B, C = self.st.realise(p)
            with np.errstate(all="ignore"):
                phi, ge, gl, m, frac = held_matrices_of(A, B, self.h, float(p[-1]))
                status = FK.core(phi, ge, gl, m, frac, C, np.ascontiguousarray(C @ A), float(C @ B), *data[2:-2],
                                 np.empty(B.size), np.empty(B.size), out)
        if status == _ALGEBRAIC:
            raise InvalidValueError("a sampled loop without delay and a velocity term on a plant whose velocity "
                                    "jumps is an algebraic loop")
        return out

    def blocks(self, p: np.ndarray) -> list[tuple[_Prepared, str, np.ndarray]]:
        """:meth:`raw` as blocks ``(log, output, r)``."""
        r = self.raw(p)
        out, at = [], 0
        per = 2 if self.rate else 1
        for i, (o, k) in enumerate(self._sizes):
            out.append((self.preps[i // per], o, r[at:at + k]))
            at += k
        return out

    @property
    def linear_count(self) -> int:
        """Number of per-log linear nuisance parameters projected out."""
        per = int(self.fit_bias) + (int(self.fit_offset) * len(self.preps[0].outputs))
        return per * len(self.preps)

    def weighted(self, p: np.ndarray) -> np.ndarray:
        """All residual blocks, each divided by its output's weight, in one vector."""
        return self.raw(p) / self._rw

    def _data(self) -> tuple:
        law = self.law
        return (self.h, SNAP, self.drive, self.starts, law is not None, law.kp if law else 0.0,
                law.kv if law else 0.0, self.lo, self.hi, self.fit_bias, self.fit_offset, self.k0, self.p0, self.m0,
                self.k1, self.p1, self.m1, float(self.w[self.first]), float(self.w[self.rate]) if self.rate else 1.0,
                self._y, self._dy, self._uy, self._udy, self._u, self._mats, self._vecs)

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """Weighted residuals at fitting coordinates ``z``; a flat 1e6 where the simulation fails or overflows
        (a trial point far out: its cost rejects it)."""
        z = np.array(z, dtype=float)
        r = self._residuals(z)
        self._last = (z, r)
        return r

    def _residuals(self, z: np.ndarray) -> np.ndarray:
        if self.compiled and self.st.code >= 0:
            r = np.empty(self._rw.size)
            status = FK.evaluate_fit(self.st.code, z, self._pos8, self._rw, *self._data(), r)
            if status == _OK:
                return r
            if status != _STIFF:
                return np.full(self.size, 1e6)
        p = self.to_phys(z)
        try:
            r = self.weighted(p) if np.all(np.isfinite(p)) else None
        except (InvalidValueError, np.linalg.LinAlgError, ValueError):
            r = None
        if r is None or not np.all(np.isfinite(r)):
            return np.full(self.size, 1e6)
        return r

    def jacobian(self, z: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> np.ndarray:
        """Forward differences of :meth:`residuals` at ``z`` (SciPy's "2-point" steps: 1e-6 relative, turned
        back at a bound), computed in one compiled call."""
        z = np.array(z, dtype=float)
        last = getattr(self, "_last", None)
        r0 = last[1] if last is not None and np.array_equal(last[0], z) else self.residuals(z)
        J = np.empty((r0.size, z.size))
        status = _STIFF
        if self.compiled and self.st.code >= 0:
            status = FK.jacobian_fit(self.st.code, z, self._pos8, lb, ub, r0, self._rw, *self._data(),
                                     np.empty(r0.size), J)
        if status == _STIFF:
            for i in range(z.size):
                step = FK.STEP * max(1.0, abs(z[i])) * (1.0 if z[i] >= 0 else -1.0)
                if not lb[i] <= z[i] + step <= ub[i]:
                    step = -step
                zz = z.copy()
                zz[i] += step
                J[:, i] = (self._residuals(zz) - r0) / (zz[i] - z[i])
        return J

    @property
    def size(self) -> int:
        return int(self._rw.size)

    def grid_starts(self) -> list[np.ndarray]:
        """The coarse grid of starting points :func:`_fit` scores (:func:`_grid_starts`)."""
        return _grid_starts(self.st, self.preps)


def _guesses(st: Structure, preps: list[_Prepared], law: Any) -> list[np.ndarray]:
    """Starting points from the data: the response's onset for the delay, its slope or level for the gain."""
    if law is not None and not isinstance(law, _Law):
        from ._closed_general import guesses

        return guesses(st, preps, law)
    prep = preps[0]
    e = prep.exp
    o = prep.outputs[0]
    y = prep.meas[o]
    i0 = e.onset
    span = float(np.ptp(y)) or 1.0
    noise = prep.wander[o] if not math.isnan(prep.wander[o]) else 0.0
    thr = max(4.0 * noise, 0.05 * span)
    moved = np.flatnonzero(np.abs(y[i0:] - y[i0]) > thr)
    t_resp = float(e.t[i0 + moved[0]] - e.t[i0]) if moved.size else 0.1 * e.duration
    t_resp = max(t_resp, 2.0 * e.period)
    h = e.period
    d = prep.drive
    if law is None:
        du = float(d[-max(3, d.size // 20):].mean()) or float(d[np.argmax(np.abs(d))])
        if st.integrating:
            area = float(np.sum(d[:-1]) * h)
            gain = (float(y[-1]) / area) if area else 1.0
        else:
            gain = float(y[-max(3, y.size // 20):].mean()) / du if du else 1.0
    else:
        gain = 1.0
        if not st.integrating:  # the loop's steady state y = K kp (r - y): a small error means a large gain
            ys = float(y[-max(3, y.size // 20):].mean())
            rs = float(d[-1])
            err_ss = abs(rs - ys)
            gain = abs(ys) / (abs(law.kp) * err_ss) if law.kp and err_ss > 0.02 * abs(rs) else 50.0
            gain = min(max(gain, 0.1), 100.0)
    if not math.isfinite(gain) or gain == 0.0:
        gain = 1.0
    # time to 63 % of the final change after the onset, for non-integrating plants
    yf = float(y[-max(3, y.size // 20):].mean())
    cross = np.flatnonzero(np.abs(y[i0:]) >= 0.632 * abs(yf)) if yf else np.array([], int)
    t63 = float(e.t[i0 + cross[0]] - e.t[i0]) if cross.size else 0.3 * e.duration
    starts = []
    for frac in (0.3, 0.7, 1.0):
        td = frac * t_resp
        tau = max(t63 - td, 2.0 * h)
        lag = max(0.5 * t_resp, 2.0 * h)
        if law is not None and not st.integrating:
            tau = max(tau, gain)  # near an integrator of unit gain: K / (tau s + 1) ~ (K / tau) / s
        vals = {"gain": gain, "delay": td, "lag": lag, "time_constant": tau, "time_constant2": max(0.2 * tau, h),
                "wn": 2.0 / lag, "zeta": 0.7, "zero": lag, "accel": _drive_span(preps) / lag}
        if st.name == "sopdt":
            vals["time_constant"] = max(0.8 * tau, 2.0 * h)
        starts.append(np.array([vals[p] for p in st.params]))
    return starts


_SHORTEST = 1e-5
"""The shortest time constant a fit considers, as a fraction of the sample period."""


def _drive_span(preps: list[_Prepared]) -> float:
    """The drive's largest range over the logs (1 where it never moves): the scale of a rate limit's guess."""
    return max(float(np.ptp(p.drive)) for p in preps) or 1.0


def _delay_bound(preps: list[_Prepared]) -> float:
    return min(0.5 * p.exp.duration for p in preps)


def _grid_starts(st: Structure, preps: list[_Prepared]) -> list[np.ndarray]:
    """A coarse grid of delays (0, then geometric from one period to a fifth of the shortest log) and time scales
    (gain 1: it is solved for linearly in open loop)."""
    dur = min(p.exp.duration for p in preps)
    h = preps[0].exp.period
    span = _drive_span(preps)
    out = []
    for td in np.r_[0.0, np.geomspace(h, max(0.2 * dur, 2 * h), 7)]:
        for ts in np.geomspace(2 * h, dur / 3.0, 5):
            vals = {"gain": 1.0, "delay": td, "lag": ts, "time_constant": ts, "time_constant2": 0.25 * ts,
                    "wn": 1.0 / ts, "zeta": 0.8, "zero": ts, "accel": span / ts}
            out.append(np.array([vals[p] for p in st.params]))
    return out


def _with_best_gain(prob: _Problem, p: np.ndarray) -> tuple[np.ndarray, float]:
    """In open loop the output is linear in the gain: solve it exactly.  The residuals are affine in a non-zero
    gain (the hover-level column scales with the gain, so its projection does not change), so the line through
    gains 1 and 2 is exact (through 0 it is not: there the column vanishes)."""
    p = p.copy()
    if prob.law is not None or prob.st.params[0] != "gain":
        r = prob.residuals(prob.to_fit(p))
        return p, float(np.dot(r, r))
    p[0] = 1.0
    with np.errstate(all="ignore"):
        try:
            r1 = prob.weighted(p)
            p[0] = 2.0
            d = prob.weighted(p) - r1
        except (InvalidValueError, np.linalg.LinAlgError, ValueError):
            return p, math.inf
    dd = FK.dot(d, d)
    if not np.isfinite(dd) or dd == 0.0:
        return p, math.inf
    step = -FK.dot(r1, d) / dd
    p[0] = 1.0 + step
    r = r1 + step * d
    return p, FK.dot(r, r)


@dataclass(frozen=True)
class _Solution:
    x: np.ndarray
    cost: float
    nfev: int


def _levenberg_marquardt(prob: _Problem, z0: np.ndarray, lb: np.ndarray, ub: np.ndarray, *, max_nfev: int = 300,
                         xtol: float = 1e-10, ftol: float = 1e-10) -> _Solution:
    """Bounded Levenberg-Marquardt on :meth:`_Problem.residuals` from ``z0``: Marquardt's scaling by the largest
    column norms of the Jacobian so far, Nielsen's damping update, steps projected on the bounds with the
    variables held at a bound by their gradient left out.  Stops as SciPy's ``least_squares`` does: the cost
    falls by less than ``ftol`` of itself on a good step, or the step is below ``xtol`` of the point."""
    z = np.clip(np.asarray(z0, dtype=float), lb, ub)
    r = prob.residuals(z)
    nfev = 1
    cost = 0.5 * FK.dot(r, r)
    A, g = FK.normal_equations(prob.jacobian(z, lb, ub), r)
    d = np.sqrt(np.maximum(np.diag(A), 0.0))
    d[d == 0.0] = 1.0
    lam, nu = 1e-3, 2.0
    while nfev < max_nfev:
        held = ((z <= lb) & (g > 0.0)) | ((z >= ub) & (g < 0.0))
        free = ~held
        if not free.any():
            break
        Af = A[np.ix_(free, free)] + lam * np.diag(d[free] ** 2)
        try:
            step_f = np.linalg.solve(Af, -g[free])
        except np.linalg.LinAlgError:
            step_f = np.linalg.lstsq(Af, -g[free], rcond=None)[0]
        trial = z.copy()
        trial[free] += step_f
        trial = np.clip(trial, lb, ub)
        step = trial - z
        if not np.all(np.isfinite(step)) or np.linalg.norm(step) <= xtol * (xtol + np.linalg.norm(z)):
            break
        r_new = prob.residuals(trial)
        nfev += 1
        cost_new = 0.5 * FK.dot(r_new, r_new)
        predicted = -float(g @ step + 0.5 * step @ A @ step)
        actual = cost - cost_new
        rho = actual / predicted if predicted > 0.0 and np.isfinite(cost_new) else -1.0
        if rho > 1e-4:
            z, r = trial, r_new
            small = actual < ftol * cost and rho > 0.25
            cost = cost_new
            if small:
                break
            A, g = FK.normal_equations(prob.jacobian(z, lb, ub), r)
            d = np.maximum(d, np.sqrt(np.maximum(np.diag(A), 0.0)))
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
        else:
            lam *= nu
            nu *= 2.0
            if lam > 1e20:
                break
    return _Solution(z, cost, nfev)


def _fit(prob: _Problem, starts: list[np.ndarray], explore: bool = True) -> np.ndarray:
    """Least squares (:func:`_levenberg_marquardt`) from the two most promising starts (scored by one evaluation
    each, the gain solved for in open loop); when the fit lost a fast lag or the delay (the two trade against
    each other), once more with half of one given to the other; then the delay hops across sample boundaries,
    where the cost is only piecewise smooth (a held input's edge crossing a sample), until no neighbour is
    better.  Returns the physical parameters."""
    hi_delay = _delay_bound(prob.preps)
    h = prob.preps[0].exp.period
    lb, ub = prob.bounds()
    lb[-1], ub[-1] = 0.0, hi_delay
    cand = [np.array(p0, dtype=float) for p0 in starts] + (prob.grid_starts() if explore else [])
    scored = []
    for p0 in cand:
        p0[-1] = min(max(p0[-1], 0.0), hi_delay * 0.999)
        p0 = np.where(prob.pos, np.maximum(p0, 1e-6), p0)
        p0, c = _with_best_gain(prob, p0) if explore else (p0, float(np.sum(prob.residuals(prob.to_fit(p0)) ** 2)))
        if math.isfinite(c) and (prob.st.params[0] != "gain" or not prob.pos[0] or p0[0] > 0):
            scored.append((c, p0))
    scored.sort(key=lambda x: x[0])

    def run(p0: np.ndarray) -> Any:
        p0 = p0.copy()
        p0[-1] = min(max(p0[-1], 0.0), hi_delay * 0.999)
        z0 = np.clip(prob.to_fit(p0), lb, ub)
        with np.errstate(all="ignore"):
            return _levenberg_marquardt(prob, z0, lb, ub, max_nfev=prob.max_nfev)

    best = None
    for _, p0 in scored[:2]:  # the two most promising starts
        fit = run(p0)
        if fit is not None and (best is None or fit.cost < best.cost):
            best = fit
    if best is None:
        raise IdentificationError(f"the {prob.st.name} fit failed from every starting point")
    # a fast lag and the delay trade against each other: a fit that lost the lag (or the delay) may sit in the
    # other valley's end; try half the delay given to the lag (or half the lag to the delay)
    fast = {"ipdt_lag": "lag", "sopdt": "time_constant2", "fopdt": "time_constant"}.get(prob.st.name)
    if fast is not None:
        i = prob.st.params.index(fast)
        p0 = prob.to_phys(best.x)
        lost_lag = p0[i] < 0.1 * max(p0[-1], h)
        lost_delay = p0[-1] < 0.1 * max(p0[i], h)
        for share in ((0.5,) if lost_lag else ()) + ((-0.5,) if lost_delay else ()):
            q = p0.copy()
            move = share * (p0[-1] if share > 0 else p0[i])
            q[-1] -= move
            q[i] += move
            if q[-1] >= 0 and q[i] > 0:
                fit = run(q)
                if fit is not None and fit.cost < best.cost * (1 - 1e-9):
                    best = fit
    # the cost is only piecewise smooth in the delay, with a kink where a held input's edge crosses a sample:
    # a fit that stopped at a kink may do better across it
    for direction in (-1.0, 1.0):
        while True:
            p0 = prob.to_phys(best.x)
            p0[-1] += direction * h
            if not 0.0 <= p0[-1] < hi_delay:
                break
            fit = run(p0)
            if fit is None or fit.cost >= best.cost * (1 - 1e-9):
                break
            back = abs(prob.to_phys(fit.x)[-1] - prob.to_phys(best.x)[-1]) < 0.5 * h
            best = fit
            if back and not prob.compiled:
                break  # the run came back to the same delay: it polished the fit (a slow valley), no kink crossed
    return prob.to_phys(best.x)


def _jacobian(prob: _Problem, p: np.ndarray) -> np.ndarray:
    """Sensitivities of the weighted residuals to the physical parameters, by central differences (one-sided for
    a delay at its bound 0)."""
    cols = []
    last = p.size - 1
    for i in range(p.size):
        h = 1e-6 * max(abs(p[i]), 1e-3)
        if i == last:
            h = max(h, 1e-7)
        a, b = p.copy(), p.copy()
        a[i] += h
        b[i] -= h
        width = 2 * h
        if i == last and b[i] < 0:
            b[i], width = p[i], h
        cols.append((prob.weighted(a) - prob.weighted(b)) / width)
    # residual = measured - model, so d(residual)/dp = -d(model)/dp; the sign does not matter for covariances
    return np.column_stack(cols)
