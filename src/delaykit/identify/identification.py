"""Identify a plant and its dead time from logs: open or closed loop, any input, several logs, honest errors.

:func:`identify` fits one of the :mod:`.structures` (or every one, ``model="auto"``) to one or more
:class:`~.iodata.Experiment` logs by output error: the whole log is simulated exactly from its input (open loop)
or its reference through the known controller (closed loop: the controller's gains, limits and period from a
:class:`~delaykit.models.loop.Loop`), sample by sample (:mod:`delaykit.simulate.discrete`), and the squared
differences to the measured outputs are minimised.  Several logs share the plant; each keeps its own initial
steady state (deviation variables).  Several outputs (altitude and its rate) are fitted jointly, each weighted
by its own residual level.

Uncertainty: residuals are modelled as autoregressive noise per log (:mod:`.noise`): one scalar model per
output, or, where several outputs are fitted jointly (altitude and its rate, one disturbance seen twice in closed
loop), one vector autoregressive model for them together.  Standard errors and 95 % intervals (Wald, from the
sandwich covariance) so stay honest when the residuals are coloured and correlated.
Model selection: BIC from the autoregressive likelihood; with two logs or more, leave-one-log-out prediction
error decides (BIC is still reported).

Examples
--------
>>> import numpy as np
>>> from delaykit.models.transfer import TransferFunction
>>> from delaykit.simulate.discrete import held_delay_model, held_response
>>> t = np.arange(0, 600.0, 1.0); u = np.where(t >= 20, 50.0, 0.0)
>>> y = 20 + held_response(held_delay_model(TransferFunction.parse("0.6/(150*s+1)"), 1.0, 12.0), u).y
>>> y += np.random.default_rng(0).normal(0, 0.05, t.size)
>>> m = identify([Experiment.from_arrays(t, {"T": y}, u=u)], model="fopdt")
>>> m
IdentifiedModel(fopdt: gain=0.600... ± ..., time_constant=15... ± ... s, delay=1... ± ... s; rms=0.04..., 1 log)
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
from scipy import special  # (its functions only: scipy.stats would import ten times more at start-up)

from ..errors import DelaykitError, InvalidTypeError, InvalidValueError, check_path, check_real, writing
from ..models.loop import Loop
from ..models.transfer import TransferFunction
from ._fit import (IdentificationError, _fit, _guesses, _jacobian, _Law, _law, _law_dict, _law_from_dict, _prepare,
                   _Prepared, _Problem, _simulate)
from .iodata import Experiment
from .noise import ar_covariance, cross_correlation, fit_ar, fit_var, ljung_box
from .structures import STRUCTURES, Structure, structure

__all__ = ["IdentifiedModel", "Candidate", "LogFit", "Prediction", "identify", "predict", "simulate_experiment",
           "load_model", "IdentificationError", "CORRELATION_WARNING", "candidate_status", "PLAUSIBLE_SPAN",
           "PLAUSIBLE_TIME", "UNDETERMINED_PERIODS", "UNREACHED_LIMIT", "undetermined_reason"]

CORRELATION_WARNING = 0.9
"""Above this absolute correlation two time parameters are reported as traded against each other."""
Z95 = float(special.ndtri(0.975))  # the normal distribution's 97.5 % point (scipy.stats.norm.ppf's own code)


# -- results ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LogFit:
    """How the model fits one log: RMS error per output, the hover/initial wander, their ratio, its noise order."""

    file: str
    rms: dict[str, float]
    wander: dict[str, float]
    samples: int
    noise_order: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``rms`` is the first output's; ``rms_by_output`` all)."""
        first = next(iter(self.rms))
        w = self.wander[first]
        return {"file": self.file, "rms": self.rms[first], "rms_by_output": dict(self.rms),
                "wander": None if math.isnan(w) else w,
                "rms_over_wander": None if not w or math.isnan(w) else self.rms[first] / w,
                "samples": self.samples, "noise_order": self.noise_order}


@dataclass(frozen=True)
class Candidate:
    """One structure tried by ``model="auto"``: its fit, the criteria, and whether its parameters are believable.

    ``status`` is ``"ok"``, ``"implausible"`` (a parameter the data cannot show: see :func:`candidate_status`) or
    ``"undetermined"`` (non-finite parameters or errors: the fit did not converge to a point); ``reason`` says why
    (``None`` when ok).  ``model="auto"`` chooses among the ``ok`` candidates when there are any.
    """

    model: str
    params: dict[str, float]
    k: int
    rms: float
    aic: float
    bic: float
    lolo_rms: float | None = None
    status: str = "ok"
    reason: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"model": self.model, "params": dict(self.params), "k": self.k, "rms": self.rms, "aic": self.aic,
                "bic": self.bic, "lolo_rms": self.lolo_rms, "status": self.status, "reason": self.reason}


PLAUSIBLE_SPAN = 100.0
"""A fitted open-loop model is implausible when its own response to the logged input (the gain's size times the
input's largest deviation from rest; for an integrating plant, times the largest integral of that deviation) would
span this many times the measured output."""

PLAUSIBLE_TIME = 10.0
"""A fitted time (a lag, a time constant, a zero; not the delay) over this many times the longest log is implausible:
the data cannot show it."""


def candidate_status(st: Structure, p: np.ndarray, cov: np.ndarray, preps: list[_Prepared],
                     closed: bool) -> tuple[str, str | None]:
    """``(status, reason)`` of a fitted structure (see :class:`Candidate`).

    Examples
    --------
    >>> import types
    >>> e = Experiment.from_arrays(np.arange(20.0), {"y": np.arange(20.0)}, u=np.where(np.arange(20) > 2, 1.0, 0.0))
    >>> prep = types.SimpleNamespace(exp=e, drive=e.u, meas={"y": e.outputs["y"]}, outputs=("y",))
    >>> candidate_status(STRUCTURES["ipdt"], np.array([1.0, 2.0]), np.eye(2), [prep], False)
    ('ok', None)
    >>> candidate_status(STRUCTURES["ipdt"], np.array([-4e11, 1.0]), np.eye(2), [prep], False)[0]
    'implausible'
    """
    se = np.sqrt(np.abs(np.diag(cov))) if cov.size else np.zeros(0)
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(se))):
        return "undetermined", "non-finite parameters or standard errors: the fit did not settle on a point"
    longest = max(q.exp.duration for q in preps)
    for name, unit, v in zip(st.params, st.units, p):
        if unit == "s" and name != "delay" and abs(v) > PLAUSIBLE_TIME * longest:
            return "implausible", (f"{name} = {v:.4g} s, over {PLAUSIBLE_TIME:g} times the longest log "
                                   f"({longest:.4g} s): the data cannot show it")
    if not closed and st.params[0] == "gain":
        span = max(float(np.ptp(q.meas[q.outputs[0]])) for q in preps)
        reach = max(float(np.max(np.abs(np.cumsum(q.drive[:-1] * np.diff(q.exp.t)) if st.integrating
                                        else q.drive))) for q in preps)
        if span > 0 and abs(p[0]) * reach > PLAUSIBLE_SPAN * span:
            return "implausible", (f"gain = {p[0]:.4g}: the model's response to the input would span "
                                   f"{abs(p[0]) * reach / span:.3g} times the measured output")
    return "ok", None



UNDETERMINED_PERIODS = 10.0
"""A time parameter whose 95 % interval, before it is cut at 0, reaches more than this many sample periods below 0
is not determined (see :func:`undetermined_reason`)."""


UNREACHED_LIMIT = 0.01
"""An acceleration limit (``ipdt_accel``) whose ramp over the command's whole range takes less than this fraction
of a sample period is one the log never shows: not determined."""


def undetermined_reason(name: str, unit: str, value: float, stderr: float, longest: float,
                        period: float) -> str | None:
    """Why the data do not determine a fitted parameter, or ``None`` when its 95 % interval stands.

    The rule reads only the fit's own information (its value ``value``, its standard error ``stderr``, the
    longest log's duration ``longest`` and the sample period ``period``, in seconds):

    * the standard error is not finite: the sensitivities (the information matrix) are singular in that
      direction, so no interval exists;
    * a time (unit ``"s"``: the delay, a lag, a time constant, a zero) whose 95 % Wald interval is wider than the
      longest log: the data say nothing a log can show;
    * a time whose interval, before it is cut at the bound 0, reaches more than :data:`UNDETERMINED_PERIODS`
      sample periods below 0 (``value - 1.96 stderr < -10 period``): the data cannot tell it from 0 and the
      linear approximation behind the interval fails at its ends (a delay of ``0.2 ± 4 s`` in a 20 Hz log);
    * any other parameter (a gain, a frequency, a damping) whose interval contains 0 and reaches below it by
      more than the value itself (``1.96 stderr > 2 |value|``): not even its size is known.

    Such a parameter is reported as not determined (:attr:`IdentifiedModel.undetermined`, its interval
    ``None``), never as a huge interval.

    Examples
    --------
    >>> undetermined_reason("delay", "s", 0.26, 0.01, 60.0, 0.05) is None
    True
    >>> undetermined_reason("delay", "s", 0.0, 2558.0, 60.0, 0.05)
    'delay: its 95 % interval (0 to 5014 s) is wider than the longest log (60 s)'
    >>> print(undetermined_reason("delay", "s", 0.22, 4.1, 60.0, 0.05))
    delay = 0.22 ± 4.1 s cannot be told from 0: its 95 % interval reaches 7.82 s below 0, over 10 sample periods
    """
    if not math.isfinite(stderr) or not math.isfinite(value):
        return f"{name}: the data do not determine it (its sensitivities are singular: no standard error)"
    half = Z95 * stderr
    if unit == "s":
        if 2.0 * half > longest:
            return (f"{name}: its 95 % interval ({max(value - half, 0.0):.4g} to {value + half:.4g} s) is wider "
                    f"than the longest log ({longest:.4g} s)")
        if value - half < -UNDETERMINED_PERIODS * period:
            return (f"{name} = {value:.4g} ± {stderr:.2g} s cannot be told from 0: its 95 % interval reaches "
                    f"{half - value:.3g} s below 0, over {UNDETERMINED_PERIODS:g} sample periods")
        return None
    if half > 2.0 * abs(value):
        return f"{name} = {value:.4g} ± {stderr:.2g}: its 95 % interval reaches below 0 by more than its size"
    return None


def _nulls(v: Any) -> Any:
    """``v`` with every float that is not finite replaced by ``None`` (JSON's null), in dicts and lists."""
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, dict):
        return {k: _nulls(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_nulls(x) for x in v]
    return v


def _number(v: Any, what: str = "an uncertainty") -> float:
    """A saved uncertainty: a number, or ``None`` (written for a value the fit could not determine) as NaN; a bool
    (JSON's ``true``) or text is refused, not read as 1.0."""
    if v is None:
        return math.nan
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InvalidTypeError(f"{what} must be a number or null, got {v!r:.40}")
    return float(v)


def _count(v: Any, what: str) -> int:
    """A saved count (samples, an order): an integer of at least 0; a bool, a fraction or text refused."""
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise InvalidValueError(f"{what} must be a whole number of at least 0, got {v!r:.40}")
    return v

@dataclass(frozen=True, repr=False, eq=False)
class IdentifiedModel:
    """An identified plant with its dead time, its uncertainty and how it was chosen.

    ``params``, ``stderr`` and ``ci`` are keyed by the structure's parameter names (``gain``, ``delay``,
    ``time_constant``...).  ``closed_loop`` holds the controller of a closed-loop fit (``None`` for open loop).
    A parameter the data do not determine (:func:`undetermined_reason`) is in ``undetermined`` with the reason,
    and its interval in ``ci`` is ``None`` (JSON: null, and ``ci_status`` ``"not determined"``).
    """

    model: str
    params: dict[str, float]
    stderr: dict[str, float]
    ci: dict[str, tuple[float, float] | None]
    cov: np.ndarray
    rms: float
    aic: float
    bic: float
    n: int
    outputs: tuple[str, ...]
    rate: str | None
    closed_loop: dict[str, Any] | None
    logs: tuple[LogFit, ...]
    candidates: tuple[Candidate, ...] = ()
    criterion: str = "bic"
    warnings: tuple[str, ...] = ()
    per_log: tuple[dict[str, Any], ...] = ()
    combinations: tuple[dict[str, Any], ...] = field(default=())
    drive_column: str = "u"
    undetermined: dict[str, str] = field(default_factory=dict)
    """The parameters the data do not determine, each with the reason (:func:`undetermined_reason`)."""

    def is_determined(self, name: str) -> bool:
        """Whether the data determine parameter ``name`` (its 95 % interval in :attr:`ci` is not ``None``)."""
        ci = self.ci.get(name)
        return name not in self.undetermined and ci is not None and all(math.isfinite(x) for x in ci)

    @property
    def structure(self) -> Structure:
        """The model structure."""
        return STRUCTURES[self.model]

    @property
    def plant(self) -> TransferFunction:
        """The identified plant, without its dead time."""
        return self.structure.plant([self.params[p] for p in self.structure.params])

    @property
    def delay(self) -> float:
        """The identified dead time (s)."""
        return self.params["delay"]

    def correlation(self, a: str, b: str) -> float:
        """Correlation of two parameters' estimates."""
        names = self.structure.params
        i, j = names.index(a), names.index(b)
        d = math.sqrt(self.cov[i, i] * self.cov[j, j])
        return float(self.cov[i, j] / d) if d > 0 else 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the contract of ``delaykit identify --json``), enough to :func:`load_model` it."""
        return {
            "model": self.model, "params": dict(self.params), "stderr": dict(self.stderr),
            "ci": {k: None if v is None else [v[0], v[1]] for k, v in self.ci.items()},
            "ci_status": {k: "determined" if self.is_determined(k) else "not determined" for k in self.ci},
            "undetermined": dict(self.undetermined),
            "correlation": {f"{a},{b}": self.correlation(a, b) for i, a in enumerate(self.structure.params)
                            for b in self.structure.params[i + 1:]},
            "cov": self.cov.tolist(), "rms": self.rms, "aic": self.aic, "bic": self.bic, "n": self.n,
            "criterion": self.criterion, "outputs": list(self.outputs), "rate": self.rate,
            "closed_loop": self.closed_loop, "plant": self.plant.to_string(digits=10),
            "candidates": [c.to_dict() for c in self.candidates], "logs": [g.to_dict() for g in self.logs],
            "per_log": list(self.per_log), "combinations": list(self.combinations), "warnings": list(self.warnings),
            "drive_column": self.drive_column,
        }

    def save(self, path: str | Path) -> None:
        """Write the model as strict JSON (read back with :func:`load_model`).

        A number that is not finite (a standard error the data could not determine is NaN) is written as
        ``null``, which JSON readers other than Python's accept, and read back as NaN."""
        p = check_path("model file", path)
        text = json.dumps(_nulls(self.to_dict()), indent=2, allow_nan=False)
        with writing("the model file", p):
            p.write_text(text)

    @classmethod
    def from_dict(cls, d: dict[str, Any], *, source: str = "model") -> "IdentifiedModel":
        """Rebuild a model from :meth:`to_dict`'s form."""
        try:
            name = d["model"]
            st = structure(name)
            params = {k: check_real(f"parameter {k}", d["params"][k]) for k in st.params}
            stderr = {k: _number(d["stderr"][k]) for k in st.params}
            ci = {k: None if v is None else (_number(v[0]), _number(v[1])) for k, v in d["ci"].items()}
            undetermined = {str(k): str(v) for k, v in (d.get("undetermined") or {}).items()}
            cov = np.array([[_number(x) for x in row] for row in d["cov"]], dtype=float).reshape(st.size, st.size)
            logs = tuple(LogFit(g["file"], {k: _number(v) for k, v in g["rms_by_output"].items()},
                                {k: math.nan for k in g["rms_by_output"]}, _count(g["samples"], "samples"),
                                _count(g["noise_order"], "noise_order"))
                         for g in d.get("logs", []))
            for k, positive in zip(st.params, st.positive):  # what a fit can give: finite, the signs it keeps
                check_real(f"parameter {k}", params[k], minimum=0.0 if positive or k == "delay" else None,
                           strict=positive)
            st.plant([params[k] for k in st.params])  # (a plant it can simulate: not badly scaled)
            closed = d.get("closed_loop")
            if closed is not None:
                if not isinstance(closed, dict):
                    raise InvalidTypeError(f"closed_loop must be a table of the controller's settings, got "
                                           f"{type(closed).__name__}")
                law = _law_from_dict(closed)  # the controller it would run, checked as it is built
                kp = getattr(law, "kp", None)
                if kp is not None and "gain" in params and kp * params["gain"] < 0:
                    raise InvalidValueError(f"the closed loop's kp ({kp:g}) and the plant's gain "
                                            f"({params['gain']:g}) have opposite signs: positive feedback")
            return cls(model=name, params=params, stderr=stderr, ci=ci, cov=cov, rms=_number(d["rms"], "rms"),
                       aic=_number(d["aic"], "aic"), bic=_number(d["bic"], "bic"), n=_count(d["n"], "n"),
                       outputs=tuple(d["outputs"]),
                       rate=d.get("rate"), closed_loop=closed, logs=logs,
                       criterion=d.get("criterion", "bic"), warnings=tuple(d.get("warnings", ())),
                       drive_column=str(d.get("drive_column", "u")), undetermined=undetermined)
        except (KeyError, TypeError, ValueError, IndexError, OverflowError) as exc:
            what = str(exc) if isinstance(exc, DelaykitError) else f"{type(exc).__name__}: {exc}"
            raise IdentificationError(f"{source}: not a usable delaykit model file ({what})") from None

    def __repr__(self) -> str:
        parts = []
        for p, u in zip(self.structure.params, self.structure.units):
            unit = " s" if u == "s" else (" rad/s" if u == "rad/s" else "")
            parts.append(f"{p}={self.params[p]:.4g} ± {self.stderr[p]:.2g}{unit}"
                         + ("" if self.is_determined(p) else " (not determined)"))
        return (f"IdentifiedModel({self.model}: {', '.join(parts)}; rms={self.rms:.4g}, "
                f"{len(self.logs)} log{'s' if len(self.logs) != 1 else ''})")



@dataclass(frozen=True)
class _Outcome:
    st: Structure
    p: np.ndarray
    cov: np.ndarray
    loglik: float
    k: int
    n: int
    rms: float
    blocks: list
    noise: list
    prob: _Problem


def _fit_structure(st: Structure, preps: list[_Prepared], law: _Law | None, fit_offset: bool,
                   starts: list[np.ndarray], explore: bool = True) -> _Outcome:
    names = {o for p in preps for o in p.outputs + ((p.rate,) if p.rate else ())}
    weights = {o: 1.0 for o in names}
    prob = _Problem(st, preps, law, weights, fit_offset)
    p = _fit(prob, starts, explore)
    if len(names) > 1:  # weight each output by its own residual level, then refit
        sq: dict[str, list[float]] = {o: [] for o in names}
        for _, o, r in prob.blocks(p):
            sq[o].extend((r * r).tolist())
        weights = {o: math.sqrt(max(float(np.mean(v)), 1e-300)) for o, v in sq.items()}
        prob = _Problem(st, preps, law, weights, fit_offset)
        p = _fit(prob, [p] + starts[:1], explore=False)
    p = st.canonical(p)[0]
    fixed = dict(st.fixed)
    free = np.array([nm not in fixed for nm in st.params])
    for i, nm in enumerate(st.params):
        if nm in fixed:
            p[i] = fixed[nm]
    blocks = prob.blocks(p)
    # Jacobian in physical parameters, by central differences (the free ones: a given value has no error)
    with np.errstate(all="ignore"):
        J = _jacobian(prob, p)[:, free]
    noise, loglik, row = [], 0.0, 0
    for _, o, r in blocks:
        rw = r / prob.w[o]
        ar = fit_ar(rw)
        noise.append(ar)
        row += r.size
        loglik += ar.loglik() - r.size * math.log(prob.w[o])
    try:
        if not np.all(np.isfinite(J)):
            raise np.linalg.LinAlgError("sensitivities are not finite")
        models = _noise_models(prob, blocks, noise)
        small = _edge_covariance(prob, p, blocks, models, ar_covariance(_covariance_blocks(blocks, models, J)), free)
        cov = np.zeros((st.size, st.size))
        cov[np.ix_(free, free)] = small
    except np.linalg.LinAlgError:
        cov = np.full((st.size, st.size), np.nan)
    k = int(free.sum()) + sum(a.order for a in noise) + prob.linear_count
    first = preps[0].outputs[0]
    rr = np.concatenate([r for _, o, r in blocks if o == first])
    rms = float(np.sqrt(np.mean(rr * rr)))
    return _Outcome(st, p, cov, loglik, k, row, rms, blocks, noise, prob)


def _noise_models(prob: _Problem, blocks: list, noise: list) -> list:
    """The covariance's noise models: a log's output and its rate share the log's disturbance (in closed loop
    the rate's residual is mostly the output's, a few samples earlier, through the controller), so the pair is
    described jointly by one vector autoregressive model (:func:`.noise.fit_var`) on the log's samples where
    either is kept (with ``fresh_only``, a sample one of them skips is filled in by linear interpolation of its
    own kept ones, for the noise model only); any other block keeps its own autoregressive model.  Returns
    ``(first block, number of blocks, model, where)`` tuples, ``where`` the rows of the pair's common samples
    that each block's residuals occupy."""
    out, i = [], 0
    while i < len(blocks):
        prep, o, r = blocks[i]
        if i + 1 < len(blocks) and blocks[i + 1][0] is prep and o != blocks[i + 1][1]:
            o2, r2 = blocks[i + 1][1], blocks[i + 1][2]
            k1, k2 = prep.keep[o], prep.keep[o2]
            if np.std(r) > 0 and np.std(r2) > 0 and k1.size == r.size and k2.size == r2.size:
                grid = np.union1d(k1, k2)
                x = np.column_stack([np.interp(grid, k1, r / prob.w[o]), np.interp(grid, k2, r2 / prob.w[o2])])
                where = (np.searchsorted(grid, k1), np.searchsorted(grid, k2), grid.size)
                out.append((i, 2, fit_var(x), where))
                i += 2
                continue
        out.append((i, 1, noise[i], None))
        i += 1
    return out


def _covariance_blocks(blocks: list, models: list, J: np.ndarray) -> list:
    """:func:`.noise.ar_covariance`'s blocks: the Jacobian's rows of each block with its model (a jointly
    described pair as one ``(n, 2, q)`` block on its common samples, zero where one of the two is not kept)."""
    starts = np.cumsum([0] + [r.size for _, _, r in blocks])
    out = []
    for i, count, model, where in models:
        if count == 1:
            out.append((J[starts[i]:starts[i + 1]], model))
        else:
            w1, w2, size = where
            pair = np.zeros((size, 2, J.shape[1]))
            pair[w1, 0] = J[starts[i]:starts[i + 1]]
            pair[w2, 1] = J[starts[i + 1]:starts[i + 2]]
            out.append((pair, model))
    return out


def _edge_covariance(prob: _Problem, p: np.ndarray, blocks: list, models: list, cov: np.ndarray,
                     free: np.ndarray) -> np.ndarray:
    """The covariance, honest near a whole number of sample periods of delay.

    Where the delay crosses a multiple of the period a held input's edges cross the samples, and the
    sensitivity of an output that answers an edge at once (a speed, a first-order plant) jumps: the cost has a
    kink there and its curvature on one side can be several times that on the other (on the emulated demo
    flights, a factor 2 to 3 in the delay's standard error).  The covariance at the estimate describes only its
    own side.  When the nearest such delay lies within the 95 % interval given by the other side's curvature
    (the sensitivities just across it), the larger of the two covariances is kept.
    """
    h, d = prob.h, float(p[-1])
    m = round(d / h)
    if m < 1 or not np.all(np.isfinite(cov)):
        return cov
    edge = m * h
    q = np.array(p, dtype=float)
    step = max(1e-3 * h, 1e-5 * d)  # (ten times _jacobian's own step: its differences stay on that side)
    q[-1] = edge + (step if d <= edge else -step)
    with np.errstate(all="ignore"):
        J = _jacobian(prob, q)[:, free]
    if not np.all(np.isfinite(J)):
        return cov
    other = ar_covariance(_covariance_blocks(blocks, models, J))
    if other[-1, -1] > cov[-1, -1] and abs(d - edge) < Z95 * math.sqrt(other[-1, -1]):
        return other
    return cov


def _criteria(o: _Outcome) -> tuple[float, float]:
    return -2.0 * o.loglik + 2.0 * o.k, -2.0 * o.loglik + o.k * math.log(max(o.n, 2))


def _combinations(st: Structure, p: np.ndarray, cov: np.ndarray) -> tuple[list[dict[str, Any]], list[str]]:
    """Pairs of time parameters traded against each other: their sum's interval and a plain warning."""
    out, warns = [], []
    timey = [i for i, u in enumerate(st.units) if u == "s"]
    for a_i, i in enumerate(timey):
        for j in timey[a_i + 1:]:
            d = math.sqrt(max(cov[i, i] * cov[j, j], 0.0))
            if d <= 0:
                continue
            rho = cov[i, j] / d
            if rho < -CORRELATION_WARNING:
                s = p[i] + p[j]
                se = math.sqrt(max(cov[i, i] + cov[j, j] + 2 * cov[i, j], 0.0))
                a, b = st.params[i], st.params[j]
                out.append({"sum": f"{a}+{b}", "value": s, "stderr": se, "ci": [s - Z95 * se, s + Z95 * se],
                            "correlation": rho})
                warns.append(f"the data determine {a} + {b} = {s:.4g} ± {se:.2g} s, but not each part (their "
                             f"estimates correlate at {rho:.2f}: one trades for the other)")
    return out, warns


def identify(
    experiments: Experiment | Sequence[Experiment],
    *,
    model: str = "auto",
    loop: Loop | None = None,
    outputs: Sequence[str] | None = None,
    rate: str | None = None,
    baseline: str = "initial",
    fresh_only: bool = False,
    candidates: Sequence[str] | None = None,
    per_log: bool = True,
    progress: Callable[[str], None] | None = None,
    u0: float | Sequence[float] | None = None,
    command: str | None = None,
    accel_limit: float | None = None,
) -> IdentifiedModel:
    """Identify a plant and its dead time from one or more logs.

    Parameters
    ----------
    experiments : Experiment or sequence of Experiment
        The logs (:func:`~.iodata.read_experiment`); all open loop (an input column) or all closed loop (a
        reference column), on the same sample period.
    model : str
        A structure name (:data:`~.structures.STRUCTURES`) or ``"auto"`` to fit the candidates and choose.
    loop : Loop, optional
        For closed-loop logs: the controller, its limits, anti-windup and period (the log's, or ``None`` for a
        continuous controller; P and PV with the true velocity must be sampled); its delays must be 0 and its
        plant is ignored (both are what is identified).  The loop is simulated exactly in deviations from the
        log's initial rest, the reference held between the log's samples.
    outputs : sequence of str, optional
        The output column(s) fitted; default: every output of the first log but ``rate``.
    rate : str, optional
        A column holding the first output's rate (e.g. ``vz``), fitted jointly with it.
    baseline : {"initial", "fit"}
        Deviation from the initial steady state (mean before the drive moves), or fit an offset per log.
    fresh_only : bool
        Count only samples whose value changed since the previous one: for a sensor slower than the log, whose
        repeated values are not new measurements (the PX4 logs).  Not for a quantised sensor, whose repeats are
        real (a thermometer that reads 0.1 °C steps).
    candidates : sequence of str, optional
        The structures ``auto`` tries (default: all).
    per_log : bool
        Also fit the chosen structure to each log alone, to compare the logs' delays.
    progress : callable, optional
        Called with a short message before each fit.
    u0 : float or sequence of float, optional
        Closed loop: the absolute command at rest before each log (one value for all, or one per log).  Only the
        limits need it.  Without it: ``C(0) (r0 - y0)`` for a controller without an integrator, 0 for an
        integrating plant under an integrating controller, and an error for a self-regulating plant under an
        integrating controller with limits (the integrator holds a command the data do not show).
    command : str, optional
        Closed loop: a column of the logs (read as one of their outputs, not fitted) holding the command; its
        mean before the reference moves is ``u0``.
    accel_limit : float, optional
        The vehicle's acceleration limit (the command's unit per second, e.g. m/s^2 for a speed command), when
        known from its parameters (ArduCopter's ``WPNAV_ACCEL_Z``): ``ipdt_accel`` then holds its ``accel`` at
        this value instead of fitting it (its standard error 0, one parameter fewer in BIC).  Only with
        ``model="ipdt_accel"`` or ``"auto"`` with it among the candidates.

    Returns
    -------
    IdentifiedModel

    Raises
    ------
    IdentificationError
        Logs that mix open and closed loop or sample clocks, a missing column, a closed-loop fit without a
        controller, a loop with a delay or another period than the logs', a command at rest the limits need and
        the data do not give (``u0``), an unknown model name.

    See Also
    --------
    predict : a model's free-run prediction of another log.
    delaykit.identify.experiment.expected_errors : standard errors to expect from a planned experiment.

    References
    ----------
    .. [1] L. Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall, 1999 (output-error
       models, ch. 4; asymptotic covariance under coloured noise, ch. 9; model validation, ch. 16).
    """
    exps = [experiments] if isinstance(experiments, Experiment) else list(experiments)
    if not exps:
        raise IdentificationError("no logs given")
    for e in exps:
        if not isinstance(e, Experiment):
            raise InvalidTypeError(f"expected Experiment logs, got {type(e).__name__}")
    if len({e.closed for e in exps}) > 1:
        raise IdentificationError("the logs mix open-loop (input) and closed-loop (reference) data")
    h0 = exps[0].period
    for e in exps[1:] if exps[0].closed else ():  # (open loop: each log is simulated on its own clock)
        if abs(e.period - h0) > 1e-6 * h0:
            raise IdentificationError(f"the logs have different sample clocks: {exps[0].name} every {h0:.6g} s, "
                                      f"{e.name} every {e.period:.6g} s; resample them onto one clock")
    if baseline not in ("initial", "fit"):
        raise IdentificationError(f"baseline must be 'initial' or 'fit', got {baseline!r}")
    names = [model] if model != "auto" else list(candidates or (nm for nm in STRUCTURES
                                                                 if loop is None or not STRUCTURES[nm].limited))
    for nm in names:
        structure(nm)
    if accel_limit is not None:
        accel_limit = check_real("accel_limit", accel_limit, minimum=0.0, strict=True)
        if "ipdt_accel" not in names:
            tried = f", candidates {', '.join(names)}" if model == "auto" else ""
            raise IdentificationError(f"accel_limit is the limit of the ipdt_accel structure, which this fit does "
                                      f"not try (model {model!r}{tried})")
    if (u0 is not None or command is not None) and loop is None:
        raise IdentificationError("u0 and command are the command at rest of a closed-loop fit: give the loop too")
    if u0 is not None and command is not None:
        raise IdentificationError("give the command at rest as u0 or as a command column, not both")
    law = _law(loop, general=u0 is not None or command is not None)
    rests: list[Any] = [None] * len(exps)  # (u0 and command need the loop: checked above)
    if loop is not None:
        from ._closed_general import rest_commands  # (the general closed loop's module, for closed-loop fits only)

        rests = rest_commands(u0, command, len(exps))
    if outputs is None:
        outs = tuple(o for o in exps[0].outputs if o not in (rate, command))
    else:
        outs = (outputs,) if isinstance(outputs, str) else outputs
        if not isinstance(outs, Sequence) or not outs or not all(isinstance(o, str) for o in outs):
            raise InvalidTypeError(f"outputs must be an output's name or a non-empty list of them, got "
                                   f"{outputs!r:.60}")
        outs = tuple(outs)
    if len(outs) != 1:
        raise IdentificationError(f"give one output (and its rate with rate=...), got {list(outs)}")
    for o in outs:  # an output that never moves in any log: no response, nothing to fit (a gain of 0 +- 0)
        values = [e.outputs[o] for e in exps if o in e.outputs]
        if values and all(float(np.ptp(v)) == 0.0 for v in values):
            raise IdentificationError(f"the output {o!r} never moves (it is {values[0][0]:g} throughout "
                                      f"{'the log' if len(values) == 1 else 'every log'}): there is nothing to "
                                      "identify")
    preps = [_prepare(e, outs, rate, law, fresh_only, u0=w) for e, w in zip(exps, rests)]
    if law is not None and not isinstance(law, _Law):
        from ._closed_general import check_rest

        check_rest(law, preps, names)
    fit_offset = baseline == "fit"

    say = progress or (lambda msg: None)
    fitted: dict[str, _Outcome] = {}
    for nm in sorted(names, key=_FIT_ORDER.index):  # simpler structures first: they start the richer ones
        st = STRUCTURES[nm]
        if st.limited and accel_limit is not None:
            st = dataclasses.replace(st, fixed=(("accel", accel_limit),))
        say(f"fitting {nm}")
        starts = _guesses(st, preps, law)
        starts += _nested_starts(st, fitted)
        fitted[nm] = _fit_structure(st, preps, law, fit_offset, starts)
    results = {nm: fitted[nm] for nm in names}
    crit = {nm: _criteria(o) for nm, o in results.items()}
    status = {nm: candidate_status(o.st, o.p, o.cov, preps, law is not None) for nm, o in results.items()}
    eligible = [nm for nm in names if status[nm][0] == "ok"] or names  # (all flagged: the least bad of them)
    lolo: dict[str, float] = {}
    if len(names) > 1 and len(preps) >= 2:
        for nm in names:
            say(f"leave-one-log-out {nm}")
            lolo[nm] = _leave_one_out(results[nm], preps, law, fit_offset)
        chosen, criterion = min(eligible, key=lambda nm: lolo[nm]), "leave-one-log-out"
    else:
        chosen, criterion = min(eligible, key=lambda nm: crit[nm][1]), "bic"
    best = results[chosen]
    cands = tuple(Candidate(nm, dict(zip(o.st.params, map(float, o.p))), o.k, o.rms, crit[nm][0], crit[nm][1],
                            lolo.get(nm), *status[nm]) for nm, o in results.items()) if len(names) > 1 else ()
    return _assemble(best, preps, law, crit[chosen], cands, criterion, per_log, fit_offset, say)


_FIT_ORDER = ("ipdt", "ipdt_lag", "fopdt", "sopdt", "ipdt_speed", "ipdt_accel")


def _nested_starts(st: Structure, done: dict[str, _Outcome]) -> list[np.ndarray]:
    """Start a richer structure from a simpler one already fitted (its delay and gain kept)."""
    out = []
    if st.name == "ipdt_lag" and "ipdt" in done:
        g, d = done["ipdt"].p
        out.append(np.array([g, max(0.25 * d, 1e-3), 0.75 * d]))
    if st.name == "ipdt_speed" and "ipdt_lag" in done:
        g, lag, d = done["ipdt_lag"].p
        out.append(np.array([g, 1.0 / max(lag, 1e-3), 1.0, 0.1 * lag, d]))
        out.append(np.array([g, 2.0 / max(lag, 1e-3), 0.5, lag, d]))
    if st.name == "ipdt_speed" and "sopdt" in done:  # K wn^2 (Tz s + 1)/(s (...)) -> K Tz wn^2/(...) as Tz grows
        g, t1, t2, d = done["sopdt"].p
        tz = 1e3 * (t1 + t2 + d)
        out.append(np.array([g / tz, 1.0 / math.sqrt(t1 * t2), 0.5 * (t1 + t2) / math.sqrt(t1 * t2), tz, d]))
    if st.name == "ipdt_accel" and "ipdt_lag" in done:  # a limit the ramps never reach, then ones they do
        g, lag, d = done["ipdt_lag"].p
        h = done["ipdt_lag"].prob.h
        span = max(float(np.ptp(q.drive)) for q in done["ipdt_lag"].prob.preps) or 1.0
        for reach in (h, 10 * h, 30 * h):  # the time a full-range ramp takes
            out.append(np.array([g, span / reach, max(0.5 * lag, 1e-3), d]))
    if st.name == "sopdt" and "fopdt" in done:
        g, tau, d = done["fopdt"].p
        out.append(np.array([g, 0.9 * tau, 0.1 * tau + 0.2 * d, 0.5 * d]))
        out.append(np.array([g, 0.7 * tau, 0.3 * tau, 0.1 * d]))
    return out


def _free_run(prep: _Prepared, st: Structure, p: np.ndarray, law: Any) -> dict[str, np.ndarray]:
    """A structure's free-run outputs (deviations) over a prepared log: the rate-limited structure by its own
    closed form, the linear ones by the exact discrete simulator."""
    if st.limited:
        from ._accel import simulate

        return simulate(prep, p)
    return _simulate(prep, st.plant(p), float(p[-1]), law)


def _leave_one_out(o: _Outcome, preps: list[_Prepared], law: _Law | None, fit_offset: bool) -> float:
    errs = []
    for i, held in enumerate(preps):
        rest = preps[:i] + preps[i + 1:]
        sub = _Problem(o.st, rest, law, o.prob.w, fit_offset)
        p = _fit(sub, [o.p], explore=False)
        sim = _free_run(held, o.st, p, law)
        first = held.outputs[0]
        k = held.keep[first]
        r = held.meas[first][k] - sim[first][k]
        if fit_offset:
            r = r - r.mean()
        errs.append(float(np.sqrt(np.mean(r * r))))
    return float(np.mean(errs))


def _assemble(o: _Outcome, preps: list[_Prepared], law: _Law | None, crit: tuple[float, float],
              cands: tuple[Candidate, ...], criterion: str, per_log: bool, fit_offset: bool,
              say: Callable[[str], None]) -> IdentifiedModel:
    st = o.st
    se = np.sqrt(np.maximum(np.diag(o.cov), 0.0))
    params = {nm: float(v) for nm, v in zip(st.params, o.p)}
    stderr = {nm: float(s) for nm, s in zip(st.params, se)}
    # Wald intervals, cut at the parameters' bounds (a time constant or a delay is not negative)
    floor = [0.0 if (pos or nm == "delay") else -math.inf for nm, pos in zip(st.params, st.positive)]
    ci: dict[str, tuple[float, float] | None] = {
        nm: (float(max(v - Z95 * s, f)), float(v + Z95 * s)) for nm, v, s, f in zip(st.params, o.p, se, floor)}
    # an interval the data do not support is reported as not determined, never as a huge interval
    longest = max(p.exp.duration for p in preps)
    period = max(p.exp.period for p in preps)
    undetermined: dict[str, str] = {}
    for nm, unit, v, var in zip(st.params, st.units, o.p, np.diag(o.cov)):
        why = undetermined_reason(nm, unit, float(v), math.sqrt(var) if var >= 0 else math.nan, longest, period)
        if why is not None:
            undetermined[nm] = why
            ci[nm] = None
    if st.limited:  # a limit no ramp of the log reaches: the data show no limit, not its value
        span = max(float(np.ptp(q.drive)) for q in preps)
        ramp = span / params["accel"] if params["accel"] > 0 else math.inf
        if ramp < UNREACHED_LIMIT * period:
            undetermined["accel"] = (f"accel = {params['accel']:.4g}: a ramp over the command's whole range "
                                     f"({span:.4g}) would take {ramp:.2g} s, under {UNREACHED_LIMIT:g} of a sample "
                                     "period: the data show no acceleration limit")
            ci["accel"] = None
    warnings: list[str] = [f"not determined: {why}" for why in undetermined.values()]
    warnings += [f"{nm} is held at the value given ({v:.6g}), not fitted" for nm, v in st.fixed]
    single = [p.exp.name for p in preps if p.exp.starts_moving]
    if single and not fit_offset:
        warnings.append(f"{', '.join(single[:3])}{', ...' if len(single) > 3 else ''}: the log starts with the drive "
                        "moving, so its baseline is one sample (its noise is not in the errors); baseline='fit' "
                        "(--baseline fit) fits it instead")
    if o.p[-1] < 1e-6 * max(1.0, float(np.max(np.abs(o.p[:-1])))):
        warnings.append("the delay is at its bound 0: these data prefer no dead time for this structure (the "
                        "interval's lower end is the bound)")
    combos, w = _combinations(st, o.p, o.cov)
    warnings += w
    for nm, v, s in zip(st.params, o.p, se):
        if (v != 0 and s > 0.5 * abs(v) and nm not in undetermined
                and not any(nm in c["sum"].split("+") for c in combos)):
            warnings.append(f"{nm} is poorly determined by these data ({v:.4g} ± {s:.2g})")
    logs = []
    for prep in preps:
        rms, n, order = {}, 0, 0
        for (pp, out, r), ar in zip(o.blocks, o.noise):
            if pp is prep:
                rms[out] = float(np.sqrt(np.mean(r * r)))
                n += r.size
                order = max(order, ar.order)
        logs.append(LogFit(prep.exp.name, rms, dict(prep.wander), n, order))
    # whiteness of the innovations and their correlation with the drive
    lb_bad, xc_bad = [], []
    for (pp, out, r), ar in zip(o.blocks, o.noise):
        e = ar.whiten(r / o.prob.w[out])
        pval = ljung_box(e)[1]
        if pval < 0.01:
            lb_bad.append(f"{pp.exp.name}:{out}")
        if out == pp.outputs[0] and pp.keep[out].size == pp.exp.t.size:
            rho, lag, bound = cross_correlation(e, ar.whiten(pp.drive))
            if abs(rho) > bound:
                xc_bad.append(f"{pp.exp.name} ({rho:+.2f} at lag {lag})")
    if lb_bad:
        warnings.append(f"the residuals are not white even after their autoregressive noise model in {len(lb_bad)} "
                        f"of {len(o.blocks)} series (Ljung-Box p < 0.01: {', '.join(lb_bad[:4])}"
                        f"{', ...' if len(lb_bad) > 4 else ''}); the intervals may be too narrow")
    if xc_bad:
        warnings.append(f"the residuals still correlate with the drive in {', '.join(xc_bad[:4])}"
                        f"{', ...' if len(xc_bad) > 4 else ''}: dynamics the model misses")
    first = preps[0].outputs[0]
    ratios = [g.rms[first] / g.wander[first] for g in logs if g.wander[first] > 0]  # (NaN compares False)
    if ratios and float(np.median(ratios)) > 2.0:
        warnings.append(f"the fit's residual is {np.median(ratios):.1f} times the initial wander (median over the "
                        "logs): the model misses part of the response")
    per: list[dict[str, Any]] = []
    if per_log and len(preps) > 1:
        say("per-log fits")
        dl, sl = [], []
        for prep in preps:
            try:
                sub = _fit_structure(st, [prep], law, fit_offset, [o.p], explore=False)
            except IdentificationError:
                continue
            s = float(math.sqrt(max(sub.cov[-1, -1], 0.0)))
            per.append({"file": prep.exp.name, "params": dict(zip(st.params, map(float, sub.p))), "delay": float(sub.p[-1]),
                        "delay_stderr": s, "rms": sub.rms})
            if s > 0:
                dl.append(float(sub.p[-1]))
                sl.append(s)
        if len(dl) >= 2:
            d, s = np.array(dl), np.array(sl)
            wmean = float(np.sum(d / s**2) / np.sum(1 / s**2))
            chi2 = float(np.sum(((d - wmean) / s) ** 2))
            pval = float(special.chdtrc(d.size - 1, chi2))  # chi-square's tail (scipy.stats.chi2.sf's own code)
            if pval < 0.05:
                warnings.append(
                    f"the logs' delays disagree beyond their errors ({d.min():.3f} to {d.max():.3f} s, "
                    f"heterogeneity p = {pval:.2g}): the delay varies between logs or the model misses dynamics "
                    "that each log compensates differently; the pooled interval describes the average only")
    return IdentifiedModel(
        model=st.name, params=params, stderr=stderr, ci=ci, cov=o.cov, rms=o.rms, aic=crit[0], bic=crit[1], n=o.n,
        outputs=preps[0].outputs, rate=preps[0].rate,
        closed_loop=_law_dict(law),
        logs=tuple(logs), candidates=cands, criterion=criterion, warnings=tuple(warnings), per_log=tuple(per),
        combinations=tuple(combos), undetermined=undetermined,
        drive_column=preps[0].exp.reference_name if law is not None else preps[0].exp.input_name)


# -- prediction -------------------------------------------------------------------------------------------
@dataclass(frozen=True, repr=False, eq=False)
class Prediction:
    """A model's free-run prediction of a log: the measured and predicted outputs and the RMS error."""

    file: str
    t: np.ndarray
    measured: dict[str, np.ndarray]
    predicted: dict[str, np.ndarray]
    rms: dict[str, float]
    wander: dict[str, float]
    drive: np.ndarray | None = None
    """The log's input (open loop) or reference (closed loop), as logged."""
    drive_name: str = "u"
    """Its column."""
    drive_kind: str = "input"
    """``"input"`` (an open-loop log) or ``"reference"`` (a closed-loop log)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the contract of ``delaykit predict --json``: ``rms`` is the first output's)."""
        first = next(iter(self.rms))
        return {"file": self.file, "rms": self.rms[first], "rms_by_output": dict(self.rms),
                "wander": {k: (None if math.isnan(v) else v) for k, v in self.wander.items()},
                "samples": int(self.t.size)}

    def __repr__(self) -> str:
        first = next(iter(self.rms))
        return f"Prediction({self.file!r}: rms {first} = {self.rms[first]:.4g}, {self.t.size} samples)"


def simulate_experiment(model: IdentifiedModel, experiment: Experiment, *, u0: float | None = None,
                        command: str | None = None) -> dict[str, np.ndarray]:
    """The model's free-run outputs over a log (absolute units: the log's initial steady state added back).

    ``u0`` or ``command``: the log's command at rest, for a closed loop that needs it (see :func:`identify`).
    """
    try:
        law = _law_from_dict(model.closed_loop)
    except (KeyError, TypeError, ValueError) as exc:
        raise IdentificationError(f"the model's closed_loop controller cannot be read ({exc})") from None
    if law is not None and (u0 is not None or command is not None) and isinstance(law, _Law):
        from ._closed_general import from_static

        law = from_static(law)
    prep = _prepare(experiment, model.outputs, model.rate, law, fresh_only=False, u0=command if command else u0)
    sim = _free_run(prep, model.structure, np.array([model.params[k] for k in model.structure.params]), law)
    return {o: y + prep.base[o] for o, y in sim.items()}


def predict(model: IdentifiedModel, experiment: Experiment, *, u0: float | None = None,
            command: str | None = None) -> Prediction:
    """Predict a log with a model, free-run (not one step ahead) from the log's input or reference.

    A closed-loop model runs the saved controller (kind, gains, limits, period); ``u0`` or ``command`` give the
    log's command at rest where the limits need it (see :func:`identify`).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(0, 100.0, 0.5); u = np.where(t >= 5, 1.0, 0.0)
    >>> m = identify([Experiment.from_arrays(t, {"y": 2 * (1 - np.exp(-np.maximum(t - 8, 0) / 10))}, u=u)],
    ...              model="fopdt")
    >>> round(m.delay, 2), round(predict(m, Experiment.from_arrays(t, {"y": 2 * (1 - np.exp(-np.maximum(t - 8, 0) / 10))},
    ...                                                         u=u)).rms["y"], 2)
    (3.0, 0.0)
    """
    if not isinstance(model, IdentifiedModel):
        raise InvalidTypeError(f"model must be an IdentifiedModel, got {type(model).__name__}")
    if not isinstance(experiment, Experiment):
        raise InvalidTypeError(f"experiment must be an Experiment (read_experiment), got {type(experiment).__name__}")
    sim = simulate_experiment(model, experiment, u0=u0, command=command)
    meas = {o: experiment.outputs[o] for o in sim}
    rms = {o: float(np.sqrt(np.mean((meas[o] - sim[o]) ** 2))) for o in sim}
    pre = experiment.onset if not experiment.starts_moving else 0
    wander = {o: float(np.std(meas[o][:pre])) if pre >= 5 else math.nan for o in sim}
    return Prediction(experiment.name, experiment.t, meas, sim, rms, wander, drive=experiment.drive,
                      drive_name=experiment.reference_name if experiment.closed else experiment.input_name,
                      drive_kind="reference" if experiment.closed else "input")


def load_model(path: str | Path) -> IdentifiedModel:
    """Read a model written by :meth:`IdentifiedModel.save`.

    Raises
    ------
    IdentificationError
        A file that cannot be read or is not a model.
    """
    from ..models.budget import MAX_CONFIG_BYTES, read_regular

    p = check_path("model file", path)
    try:  # (a regular file only, of bounded size: /dev/zero or a FIFO is refused before a byte is read)
        d = json.loads(read_regular(p, "model file", MAX_CONFIG_BYTES, error=IdentificationError).decode("utf-8"))
    except OSError as exc:
        raise IdentificationError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    except IdentificationError:  # not a regular file, or too large: already said
        raise
    except RecursionError:
        raise IdentificationError(f"{p}: not a delaykit model file (nested too deeply to read)") from None
    except ValueError as exc:  # not UTF-8, not JSON, an integer of thousands of digits
        raise IdentificationError(f"{p}: not a JSON model file ({exc})") from None
    if not isinstance(d, dict):
        raise IdentificationError(f"{p}: not a delaykit model file")
    return IdentifiedModel.from_dict(d, source=str(p))
