"""Fit the free parameters of a delay system (a :class:`~delaykit.systems.DelayLTI`) to measured logs.

:func:`identify` fits the plant families of :mod:`.structures` inside delaykit's own loops.  Many systems are
better written as what they are: an interconnection of named blocks (``tf``, ``delay``, ``saturation``,
``summing_junction``, ``interconnect``) with a few unknown numbers in it.  :func:`fit_system` takes a function that
builds that system from its parameters, simulates it exactly over each log
(:func:`delaykit.simulate.systems.forced_response`, the logged drive as the input, every delay and saturation
acting), and adjusts the parameters by least squares (SciPy's ``least_squares``, trust-region reflective within
the bounds) on the outputs the system and the logs share by name.

The logs are :class:`.iodata.Experiment` objects.  The system runs in deviation variables: its single input is the
log's drive (input or reference) minus its initial value, held between samples; each output is compared with the
measured one minus its initial steady state; every state starts at 0, so a log must begin at rest (as a step test
does).  Each output's residuals are divided by its noise scale: the standard deviation of the output before the
drive moves (its "wander") unless ``weights`` gives one.

Standard errors come from the Jacobian (central differences of the exact simulation at the optimum) and the
residuals' own colour: per log, a vector autoregressive model of the outputs' residuals (an autoregressive one for
a single output), in the sandwich of :func:`.noise.ar_covariance`.  They assume the model's structure is right:
logs that disagree beyond them show a model error, not bad luck.
"""

from __future__ import annotations

import math
import reprlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from ..errors import InvalidTypeError, InvalidValueError, check_real, plain
from ..simulate.systems import forced_response
from ..systems.lti import DelayLTI
from ._fit import IdentificationError
from .identification import CORRELATION_WARNING, Prediction
from .iodata import Experiment
from .noise import ar_covariance, fit_ar, fit_var

__all__ = ["SystemFit", "SystemLogFit", "fit_system", "simulate_log"]

_FAILED = 1e3
"""Weighted residual given to a sample the simulation did not reach (a trial system that overflows): large, so the
optimiser steps back, and finite, so it can."""


@dataclass(frozen=True, repr=False)
class SystemLogFit:
    """How the fitted system matches one log: RMS error and hover wander per output, samples counted."""

    name: str
    rms: dict[str, float]
    wander: dict[str, float]
    samples: int

    @property
    def rms_over_wander(self) -> dict[str, float]:
        """Each output's RMS error over its wander (1 is the floor: the output's own noise at rest)."""
        return {o: (self.rms[o] / w if w > 0 else math.nan) for o, w in self.wander.items()}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (a non-finite number is ``None``)."""
        return {"name": self.name, "rms": _clean(self.rms), "wander": _clean(self.wander),
                "rms_over_wander": _clean(self.rms_over_wander), "samples": self.samples}

    def __repr__(self) -> str:
        q = self.rms_over_wander
        parts = ", ".join(f"{o} rms {r:.4g} ({q[o]:.2f} x wander)" for o, r in self.rms.items())
        return f"SystemLogFit({self.name!r}: {parts}, {self.samples} samples)"


@dataclass(frozen=True, repr=False)
class SystemFit:
    """The result of :func:`fit_system`.

    Attributes
    ----------
    params, stderr : dict of str to float
        The fitted parameters and their standard errors (NaN where the Jacobian does not determine one).
    correlation : ndarray
        The parameters' correlation matrix, in the order of ``params``.
    system : DelayLTI
        The system built at the fitted parameters.
    logs : tuple of SystemLogFit
        The match to each log.
    outputs : tuple of str
        The outputs fitted (the system's outputs that the logs have).
    cost : float
        Mean squared weighted residual (1 would be residuals as small as the wander).
    nfev : int
        Simulations of the optimiser (the Jacobian's are not counted).
    status : str
        ``"converged"`` or ``"stopped"`` (the evaluation limit).
    warnings : tuple of str
        Parameters at a bound, pairs that trade off (correlation beyond 0.9), undetermined ones.
    """

    params: dict[str, float]
    stderr: dict[str, float]
    correlation: np.ndarray
    system: DelayLTI
    logs: tuple[SystemLogFit, ...]
    outputs: tuple[str, ...]
    cost: float
    nfev: int
    status: str
    warnings: tuple[str, ...] = field(default=())
    fresh_only: bool = False

    def predict(self, experiment: Experiment) -> Prediction:
        """The fitted system's free-run prediction of a log (every sample; absolute units).

        Examples
        --------
        See :func:`fit_system`.
        """
        sim = simulate_log(self.system, experiment, self.outputs)
        meas = {o: experiment.outputs[o] for o in sim}
        rms = {o: float(np.sqrt(np.mean((meas[o] - sim[o]) ** 2))) for o in sim}
        wander = {o: _wander(experiment, o) for o in sim}
        return Prediction(experiment.name, experiment.t, meas, sim, rms, wander, drive=experiment.drive,
                          drive_name=experiment.reference_name if experiment.closed else experiment.input_name,
                          drive_kind="reference" if experiment.closed else "input")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (strict JSON: a non-finite number is ``None``)."""
        names = list(self.params)
        return {"params": _clean(self.params), "stderr": _clean(self.stderr),
                "correlation": [[_num(self.correlation[i, j]) for j in range(len(names))] for i in range(len(names))],
                "system": repr(self.system), "outputs": list(self.outputs), "cost": _num(self.cost),
                "nfev": self.nfev, "status": self.status, "warnings": list(self.warnings),
                "fresh_only": self.fresh_only, "logs": [g.to_dict() for g in self.logs]}

    def __repr__(self) -> str:
        ps = ", ".join(f"{k} {v:.4g} ± {self.stderr[k]:.2g}" for k, v in self.params.items())
        q = [x for g in self.logs for x in g.rms_over_wander.values() if math.isfinite(x)]
        span = f", rms {min(q):.2g} to {max(q):.2g} x wander" if q else ""
        return f"SystemFit({ps}; {len(self.logs)} log{'s' if len(self.logs) != 1 else ''}{span}, {self.status})"


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _clean(d: Mapping[str, float]) -> dict[str, float | None]:
    return {k: _num(v) for k, v in d.items()}


def _wander(e: Experiment, o: str) -> float:
    pre = 0 if e.starts_moving else e.onset
    return float(np.std(e.outputs[o][:pre])) if pre >= 5 else math.nan


def _check_system(sys: Any, where: str) -> DelayLTI:
    if not isinstance(sys, DelayLTI):
        raise InvalidTypeError(f"{where} must give a DelayLTI, got {type(sys).__name__}")
    if sys.ninputs != 1:
        raise InvalidValueError(f"{where} gives a system with {sys.ninputs} inputs {list(sys.inputs)}; a log "
                                "drives one (its input or reference)")
    return sys


def simulate_log(system: DelayLTI, experiment: Experiment, outputs: Sequence[str] | None = None
                 ) -> dict[str, np.ndarray]:
    """A system's exact free-run outputs over a log, in the log's absolute units.

    The system's single input is the log's drive minus its initial value, held from each sample to the next (as
    a sampled controller or a logged command holds it); each output starts at the log's initial steady state
    (every state 0 at the first sample).

    Parameters
    ----------
    system : DelayLTI
        One input; its outputs are matched with the log's by name.
    experiment : Experiment
    outputs : sequence of str, optional
        The outputs wanted (default: every output of the system that the log has).

    Examples
    --------
    >>> import numpy as np
    >>> from delaykit import tf
    >>> t = np.arange(0.0, 5.0, 0.5); u = np.where(t >= 1.0, 1.0, 0.0)
    >>> e = Experiment.from_arrays(t, {"y": np.zeros_like(t)}, u=u)
    >>> simulate_log(tf("exp(-0.5*s)/s", outputs="y"), e)["y"][:6].round(6)   # the step held from t = 1
    array([0. , 0. , 0. , 0. , 0.5, 1. ])
    """
    _check_system(system, "system")
    if not isinstance(experiment, Experiment):
        raise InvalidTypeError(f"experiment must be an Experiment, got {type(experiment).__name__}")
    names = _shared(system, [experiment]) if outputs is None else list(outputs)
    out = _run(system, experiment, names)
    return {o: out[o] + experiment.baseline(o) for o in names}


def _shared(sys: DelayLTI, exps: Sequence[Experiment]) -> list[str]:
    names = [o for o in sys.outputs if all(o in e.outputs for e in exps)]
    if not names:
        raise InvalidValueError(f"no output of the system {list(sys.outputs)} is in every log "
                                f"({', '.join(f'{e.name}: {list(e.outputs)}' for e in exps)})")
    return names


_HOLD_EDGE = 1e-9
"""A held drive's jump is a ramp over this fraction of the log's period (the kernel takes its input linear between
times): the error it leaves is of that order times the jump."""


def _held(t: np.ndarray, u: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times and values that make a linear-between-times input equal to ``u`` held from each sample to the next,
    and the indices of the log's own samples among them."""
    jump = np.flatnonzero(np.diff(u) != 0) + 1
    if jump.size == 0:
        return t, u, np.arange(t.size)
    tt = np.insert(t, jump, t[jump] - _HOLD_EDGE * period)
    uu = np.insert(u, jump, u[jump - 1])
    return tt, uu, np.arange(t.size) + np.searchsorted(jump, np.arange(t.size), side="right")


def _run(sys: DelayLTI, e: Experiment, names: Sequence[str]) -> dict[str, np.ndarray]:
    t, u, own = _held(e.t, e.drive - e.drive_baseline, e.period)
    r = forced_response(sys, t, u)
    idx = {o: i for i, o in enumerate(sys.outputs)}
    return {o: r.outputs[idx[o]][own] for o in names}


def _fresh(x: np.ndarray) -> np.ndarray:
    return np.concatenate([[True], np.diff(x) != 0])


def fit_system(build: Callable[..., DelayLTI], p0: Mapping[str, float], experiments: Experiment | Sequence[Experiment],
               *, bounds: Mapping[str, tuple[float, float]] | None = None, weights: Mapping[str, float] | None = None,
               fresh_only: bool = False, max_nfev: int = 200) -> SystemFit:
    """Fit the free parameters of a delay system to logs by exact simulation and least squares.

    Parameters
    ----------
    build : callable
        ``build(**params) -> DelayLTI``: the system (one input) at the given parameter values.  Its outputs are
        compared with the logs' outputs of the same names.
    p0 : mapping of str to float
        The parameters' names and starting values.
    experiments : Experiment or sequence of Experiment
        The logs (see :func:`read_experiment`); each must start at rest.
    bounds : mapping of str to (float, float), optional
        Lower and upper bounds of some parameters (a delay's lower bound is usually 0).
    weights : mapping of str to float, optional
        Each output's noise scale (its residuals are divided by it); default: each log's wander of that output
        (its standard deviation before the drive moves).
    fresh_only : bool
        Count only the samples where an output changed (a sensor slower than the log repeats values).
    max_nfev : int
        Limit on the optimiser's simulations.

    Returns
    -------
    SystemFit

    Raises
    ------
    InvalidValueError
        Bad parameters, bounds or weights, a start outside the bounds, no shared output, a log whose wander is
        not known when no weight is given.
    IdentificationError
        ``build`` refuses a parameter value inside the bounds (narrow the bounds).

    See Also
    --------
    identify : the plant families of :mod:`delaykit.identify.structures`, inside delaykit's own loops.

    References
    ----------
    .. [1] L. Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall, 1999, ch. 7 and 9
       (prediction-error methods; the covariance of the estimate with coloured residuals).

    Examples
    --------
    A first-order lag with a dead time, recovered from a noiseless step (its closed form):

    >>> import numpy as np
    >>> from delaykit import tf
    >>> from delaykit.identify import Experiment
    >>> def plant(gain, tau, T):
    ...     return tf(f"{gain}*exp(-{tau}*s)/({T}*s+1)", outputs="y")
    >>> t = np.arange(0.0, 20.0, 0.1); u = np.where(t >= 2.0, 1.0, 0.0)
    >>> y = 2.0 * (1 - np.exp(-np.clip(t - 2.7, 0, None) / 3.0))
    >>> e = Experiment.from_arrays(t, {"y": y}, u=u)
    >>> fit = fit_system(plant, {"gain": 1.0, "tau": 0.3, "T": 1.0}, e, bounds={"tau": (0, 5)},
    ...                  weights={"y": 0.01})
    >>> {k: round(v, 6) for k, v in fit.params.items()}
    {'gain': 2.0, 'tau': 0.7, 'T': 3.0}
    >>> round(fit.predict(e).rms["y"], 9)
    0.0
    """
    if isinstance(max_nfev, bool) or not isinstance(max_nfev, (int, np.integer)) or max_nfev < 1:
        raise InvalidValueError(f"max_nfev must be a positive integer, got {plain(max_nfev)!r}")
    if not isinstance(fresh_only, (bool, np.bool_)):
        raise InvalidTypeError(f"fresh_only must be True or False, got {plain(fresh_only)!r}")
    for what, m in (("bounds", bounds), ("weights", weights)):
        if m is not None and not isinstance(m, Mapping):
            raise InvalidTypeError(f"{what} must be a mapping of names (a dict), got {reprlib.repr(plain(m))}")
    if not callable(build):
        raise InvalidTypeError(f"build must be a function of the parameters, got {type(build).__name__}")
    if not isinstance(p0, Mapping) or not p0:
        raise InvalidValueError(f"p0 must be a non-empty mapping of parameter names to values, got "
                                f"{reprlib.repr(plain(p0))}")
    names = [str(k) for k in p0]
    x0 = np.array([check_real(f"p0[{k!r}]", v) for k, v in p0.items()])
    try:
        exps = [experiments] if isinstance(experiments, Experiment) else list(experiments)
    except TypeError:
        exps = []
    if not exps or not all(isinstance(e, Experiment) for e in exps):
        raise InvalidTypeError("experiments must be an Experiment or a sequence of them")
    lo = np.full(x0.size, -np.inf)
    hi = np.full(x0.size, np.inf)
    for k, b in (bounds or {}).items():
        if k not in p0:
            raise InvalidValueError(f"bounds name {k!r}, which is not a parameter ({names})")
        if not isinstance(b, (tuple, list)) or len(b) != 2:
            raise InvalidValueError(f"bounds[{k!r}] must be (lower, upper), got {b!r}")
        i = names.index(k)
        lo[i] = -np.inf if b[0] is None else check_real(f"bounds[{k!r}] lower", b[0], allow_neg_inf=True)
        hi[i] = np.inf if b[1] is None else check_real(f"bounds[{k!r}] upper", b[1], allow_inf=True)
        if not lo[i] < hi[i]:
            raise InvalidValueError(f"bounds[{k!r}] = ({lo[i]:g}, {hi[i]:g}): the lower bound must be below the upper")
        if not lo[i] <= x0[i] <= hi[i]:
            raise InvalidValueError(f"p0[{k!r}] = {x0[i]:g} is outside its bounds ({lo[i]:g}, {hi[i]:g})")

    def make(x: np.ndarray, first: bool = False) -> DelayLTI:
        p = dict(zip(names, (float(v) for v in x)))
        try:
            sys = build(**p)
        except Exception as exc:  # the user's function: whatever it raises is reported, with its type
            why = f"{type(exc).__name__}: {exc}" if not isinstance(exc, (ValueError, TypeError)) else str(exc)
            hint = "check build and p0" if first else "bound them"
            raise IdentificationError(f"build refused the parameters {p} ({why}); {hint}") from exc
        return _check_system(sys, "build")

    sys0 = make(x0, first=True)
    outs = _shared(sys0, exps)
    scale: list[dict[str, float]] = []
    keep: list[dict[str, np.ndarray]] = []
    for e in exps:
        s = {}
        for o in outs:
            w = (weights or {}).get(o)
            if w is None:
                w = _wander(e, o)
                if not (math.isfinite(w) and w > 0):
                    raise InvalidValueError(f"{e.name}: the wander of {o!r} is not known (fewer than 5 samples at "
                                            "rest, or constant): give weights={...}")
            else:
                w = check_real(f"weights[{o!r}]", w, minimum=0.0, strict=True)
            s[o] = w
        scale.append(s)
        keep.append({o: (_fresh(e.outputs[o]) if fresh_only else np.ones(e.t.size, bool)) for o in outs})
    dev = [{o: e.outputs[o] - e.baseline(o) for o in outs} for e in exps]

    def blocks(x: np.ndarray) -> list[list[np.ndarray]]:
        """Each log's weighted residuals of each output at every sample."""
        sys = make(x)
        res = []
        for e, d, s in zip(exps, dev, scale):
            y = _run(sys, e, outs)
            res.append([np.where(np.isfinite(r := (y[o] - d[o]) / s[o]), r, _FAILED) for o in outs])
        return res

    def flat(x: np.ndarray) -> np.ndarray:
        return np.concatenate([r[k[o]] for b, k in zip(blocks(x), keep) for r, o in zip(b, outs)])

    sol = least_squares(flat, x0, bounds=(lo, hi), x_scale="jac", diff_step=1e-6, max_nfev=max_nfev)
    x = sol.x
    res = blocks(x)
    r_all = flat(x)
    J = _jacobian(flat, x, lo, hi)
    cov, models_ok = _covariance(J, res, keep, outs)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None)) if models_ok else np.full(x.size, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(se, se)
    warn = []
    for i, k in enumerate(names):
        if x[i] <= lo[i] or x[i] >= hi[i]:
            warn.append(f"{k} = {x[i]:g} is at its bound {lo[i] if x[i] <= lo[i] else hi[i]:g}: its standard error "
                        "means little")
        if not math.isfinite(se[i]) or se[i] == 0.0:
            warn.append(f"{k} is not determined by these logs")
        for j in range(i):
            if abs(corr[i, j]) > CORRELATION_WARNING:
                warn.append(f"{names[j]} and {k} trade off (correlation {corr[i, j]:+.2f})")
    sys = make(x)
    logs = []
    for e, d, k in zip(exps, dev, keep):
        y = _run(sys, e, outs)
        rms = {o: float(np.sqrt(np.mean((y[o] - d[o])[k[o]] ** 2))) for o in outs}
        logs.append(SystemLogFit(e.name, rms, {o: _wander(e, o) for o in outs}, int(sum(v.sum() for v in k.values()))))
    return SystemFit(dict(zip(names, (float(v) for v in x))), dict(zip(names, (float(v) for v in se))), corr, sys,
                     tuple(logs), tuple(outs), float(np.mean(r_all ** 2)), int(sol.nfev),
                     "converged" if sol.status > 0 else "stopped", tuple(warn), bool(fresh_only))


def _jacobian(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Central differences (one-sided at a bound) of the weighted residuals; steps of 1e-5 relative (the
    simulation is exact, so the truncation error, not rounding, sets the step)."""
    cols = []
    for i in range(x.size):
        h = 1e-5 * max(abs(x[i]), 1e-3)
        up, dn = x.copy(), x.copy()
        up[i] = min(x[i] + h, hi[i])
        dn[i] = max(x[i] - h, lo[i])
        cols.append((f(up) - f(dn)) / (up[i] - dn[i]))
    return np.column_stack(cols)


def _covariance(J: np.ndarray, res: list[list[np.ndarray]], keep: list[dict[str, np.ndarray]],
                outs: Sequence[str]) -> tuple[np.ndarray, bool]:
    """The sandwich covariance with each log's residuals coloured: one vector autoregressive model of its outputs
    on the samples where any is kept (an output's Jacobian rows zero where it is not), one autoregressive model
    for a single output."""
    if not np.all(np.isfinite(J)):
        return np.full((J.shape[1], J.shape[1]), np.nan), False
    out = []
    row = 0
    for b, k in zip(res, keep):
        masks = [k[o] for o in outs]
        union = np.logical_or.reduce(masks)
        n = int(union.sum())
        if len(outs) == 1:
            out.append((J[row:row + n], fit_ar(b[0][union])))
            row += n
            continue
        Jb = np.zeros((n, len(outs), J.shape[1]))
        for i, m in enumerate(masks):
            c = int(m.sum())
            Jb[np.flatnonzero(m[union]), i] = J[row:row + c]
            row += c
        out.append((Jb, fit_var(np.column_stack([r[union] for r in b]))))
    return ar_covariance(out), True
