"""Tune P, PI, PD, PID (and the paper's PV) controllers for a plant with a dead time: :func:`tune`.

:func:`tune` takes a plant and its delay (or a :class:`~delaykit.models.loop.Loop`, or an identified model), a
controller structure and either a rule (:mod:`.pid_rules`: SIMC, AMIGO, IMC/lambda, Ziegler-Nichols,
Tyreus-Luyben) or an optimisation (:mod:`.pid_optimise`: MIGO, least load IAE, rightmost root, each with an Ms
limit and robust over lists of delays and gains), then checks the result with delaykit's exact tools and returns a
:class:`Tuning`: the gains, the exact Ms (and Mt on a dense grid), the gain, phase and delay margins, the closed
loop's stability from its certified roots, and the exact simulated responses to a setpoint step and to a load step
at the plant input, reported separately.  With ``overshoot=...`` the setpoint weight ``b`` of a PI or PID is then
chosen, after the feedback tuning, as the largest ``b <= 1`` that keeps the setpoint overshoot within the target.

Examples
--------
>>> t = tune("1/s", "pi", delay=0.37, rule="simc", umin=-1, umax=1)
>>> t
Tuning(simc pi: kp=1.351, ki=0.4565; Ms 1.7, GM 2.96, PM 46.9 deg, DM 0.588 s, stable)
>>> round(t.kp * 2 * 0.37, 12)        # SIMC, integrating plant, tau_c = theta: Kc = 1 / (k (tau_c + theta))
1.0
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.loop import Loop
from ..models.transfer import TransferFunction
from .pid_optimise import OBJECTIVES, _iae, controller_of, optimise, plant_points
from .pid_rules import RULES, ReducedModel, TuningWarning, UltimatePoint, rule_gains

__all__ = ["Tuning", "SetpointReport", "LoadReport", "RobustPoint", "tune", "assess", "METHODS", "TUNE_CONTROLLERS"]

METHODS = ("migo",)
TUNE_CONTROLLERS = ("p", "pi", "pd", "pid", "pv")
RECOVERY_BAND = 0.05
"""A load's recovery time is when the error last leaves this fraction of its peak."""


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


@dataclass(frozen=True, repr=False)
class SetpointReport:
    """The response to a setpoint step of ``step`` (exact simulation with the actuator's limits): overshoot (%),
    rise and settling times (s, None if never), the integrated absolute error ``iae`` (s times the step's unit) and
    the peak error (the step itself, at t = 0)."""

    step: float
    overshoot: float
    rise_time: float | None
    settling_time: float | None
    iae: float
    peak_error: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {k: _num(getattr(self, k)) for k in ("step", "overshoot", "rise_time", "settling_time", "iae",
                                                   "peak_error")}

    def __repr__(self) -> str:
        st = "not settled" if self.settling_time is None else f"settles {self.settling_time:.4g} s"
        return f"SetpointReport(step {self.step:g}: overshoot {self.overshoot:.3g} %, {st}, IAE {self.iae:.4g})"


@dataclass(frozen=True, repr=False)
class LoadReport:
    """The response to a load step of ``size`` at the plant input (exact simulation with the actuator's limits):
    the peak error and when it occurs (s), the integrated absolute error, and the recovery time (s: when the error
    last leaves ``RECOVERY_BAND`` = 5 % of its peak; None if it has not by the end of the simulation)."""

    size: float
    peak_error: float
    peak_time: float
    iae: float
    recovery_time: float | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {k: _num(getattr(self, k)) for k in ("size", "peak_error", "peak_time", "iae", "recovery_time")}

    def __repr__(self) -> str:
        rec = "not recovered" if self.recovery_time is None else f"recovers {self.recovery_time:.4g} s"
        return f"LoadReport(load {self.size:g}: peak error {self.peak_error:.4g}, IAE {self.iae:.4g}, {rec})"


@dataclass(frozen=True, repr=False)
class RobustPoint:
    """One plant of a robust design (its delay and gain factor) with the tuned controller: exact Ms, margins,
    stability and the load IAE."""

    delay: float
    gain: float
    ms: float
    gain_margin: float
    phase_margin: float
    delay_margin: float
    stable: bool
    load_iae: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        d = {k: _num(getattr(self, k)) for k in ("delay", "gain", "ms", "gain_margin", "phase_margin",
                                                 "delay_margin", "load_iae")}
        d["stable"] = self.stable
        return d

    def __repr__(self) -> str:
        return (f"RobustPoint(delay={self.delay:.4g} s, gain={self.gain:.4g}: Ms {self.ms:.4g}, "
                f"{'stable' if self.stable else 'UNSTABLE'})")


@dataclass(frozen=True, repr=False)
class Tuning:
    """A tuned controller and its exact checks (see :func:`tune`).

    ``how`` names the rule or the method and objective; ``loop`` is the tuned loop (``loop.controller`` the
    controller); ``kd`` is the velocity gain for the PV law; ``tf`` the derivative filter (pd, pid); ``b`` and ``c``
    the setpoint weights (pi, pid).  ``ms`` is exact (:func:`~delaykit.spectrum.frequency.margins`), ``mt`` the peak
    of ``|L/(1+L)|`` on a dense grid; the margins are ``nan`` (JSON ``null``) when the loop is unstable.  ``model``
    and ``ultimate`` are what a rule read; ``robust`` holds every plant of a robust design and ``worst`` the index of
    the one with the largest Ms.  ``status`` is ``"ok"``, or ``"unstable"`` when the tuned loop is not stable.
    """

    how: str
    kind: str
    kp: float
    ki: float
    kd: float
    tf: float
    b: float
    c: float
    loop: Loop
    ms: float
    mt: float
    gain_margin: float
    phase_margin: float
    delay_margin: float
    stable: bool
    setpoint: SetpointReport | None
    load: LoadReport | None
    ms_limit: float | None = None
    mt_limit: float | None = None
    model: ReducedModel | None = None
    ultimate: UltimatePoint | None = None
    robust: tuple[RobustPoint, ...] = ()
    notes: tuple[str, ...] = field(default=())

    @property
    def controller(self) -> Any:
        """The tuned controller."""
        return self.loop.controller

    @property
    def status(self) -> str:
        """``"ok"`` or ``"unstable"``."""
        return "ok" if self.stable else "unstable"

    @property
    def worst(self) -> RobustPoint | None:
        """The robust design's plant with the largest Ms (an unstable one first), or None."""
        if not self.robust:
            return None
        return max(self.robust, key=lambda p: (not p.stable, p.ms if math.isfinite(p.ms) else math.inf))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (strict: no NaN or infinity, ``null`` instead)."""
        return {
            "status": self.status, "how": self.how, "controller": self.kind,
            **{k: _num(getattr(self, k)) for k in ("kp", "ki", "kd", "tf", "b", "c", "ms", "mt", "gain_margin",
                                                   "phase_margin", "delay_margin", "ms_limit", "mt_limit")},
            "stable": self.stable,
            "setpoint": None if self.setpoint is None else self.setpoint.to_dict(),
            "load": None if self.load is None else self.load.to_dict(),
            "model": None if self.model is None else self.model.to_dict(),
            "ultimate": None if self.ultimate is None else self.ultimate.to_dict(),
            "robust": [p.to_dict() for p in self.robust],
            "worst": None if self.worst is None else self.worst.to_dict(),
            "loop": _json_loop(self.loop.to_dict()),
            "notes": list(self.notes),
        }

    def __repr__(self) -> str:
        gains = f"kp={self.kp:.4g}"
        if self.kind in ("pi", "pid"):
            gains += f", ki={self.ki:.4g}"
        if self.kind in ("pd", "pid"):
            gains += f", kd={self.kd:.4g}"
        if self.kind == "pv":
            gains += f", kv={self.kd:.4g}"
        if self.b != 1.0 and self.kind in ("pi", "pid"):
            gains += f", b={self.b:.3g}"
        if not self.stable:
            return f"Tuning({self.how} {self.kind}: {gains}; UNSTABLE)"
        gm = "inf" if math.isinf(self.gain_margin) else f"{self.gain_margin:.3g}"
        return (f"Tuning({self.how} {self.kind}: {gains}; Ms {self.ms:.3g}, GM {gm}, PM {self.phase_margin:.3g} deg, "
                f"DM {self.delay_margin:.3g} s, stable)")


def _json_loop(d: dict[str, Any]) -> dict[str, Any]:
    return {k: (_num(v) if isinstance(v, float) else v) for k, v in d.items()}


# ---------------------------------------------------------------------------------------------- the plant
def _plant_and_delay(plant: Any, delay: float | None) -> tuple[TransferFunction, float, Loop | None]:
    """The plant, its delay and the loop it came from (None for a bare plant)."""
    from ..models.altitude import AltitudeLoop, as_loop

    if isinstance(plant, AltitudeLoop):
        plant = as_loop(plant)
    if isinstance(plant, Loop):
        if delay is not None:
            raise InvalidValueError("give the delay in the loop, not beside it")
        return plant.plant, plant.total_delay, plant
    if hasattr(plant, "plant") and hasattr(plant, "params") and hasattr(plant, "delay"):  # an IdentifiedModel
        return plant.plant, float(plant.delay) + (0.0 if delay is None else check_real("delay", delay, minimum=0.0)), None
    if isinstance(plant, str):
        tf, extra = TransferFunction.parse_with_delay(plant)
    else:
        tf, extra = TransferFunction.coerce(plant, name="plant"), 0.0
    d = 0.0 if delay is None else check_real("delay (s)", delay, minimum=0.0)
    return tf, d + extra, None


def _range(name: str, values: Any) -> list[float] | None:
    if values is None:
        return None
    if isinstance(values, str):
        from ..models.ranges import parse_range

        return [float(v) for v in parse_range(values, name)]
    if isinstance(values, (int, float)):
        return [check_real(name, values)]
    try:
        out = [check_real(name, v) for v in values]
    except TypeError:
        raise InvalidTypeError(f"{name} must be a list of numbers or START:STOP:N, got {values!r:.60}") from None
    if not out:
        raise InvalidValueError(f"{name} is empty: give at least one value (or None for no robust design)")
    return out


# ---------------------------------------------------------------------------------------------- the checks
def _horizon(loop: Loop, ti: float) -> float:
    """A simulation length that shows the responses settle: 10 time constants of the rightmost root (certified),
    at least 20 delays and 6 integral times, at most 1000 delays."""
    from ..spectrum.stability import rightmost

    t = max(loop.total_delay, 1e-3)
    try:
        a = rightmost(loop).abscissa
    except InvalidValueError:
        a = math.nan
    base = 10.0 / -a if math.isfinite(a) and a < 0 else 50.0 * t
    return float(min(max(base, 20 * t, 6 * ti if math.isfinite(ti) else 0.0), 1000 * max(t, base / 1000)))


def _setpoint(loop: Loop, step: float, t_end: float) -> SetpointReport:
    from ..simulate.simulation import simulate

    r = simulate(loop, step, t_end=t_end)
    m = r.metrics
    return SetpointReport(step=step, overshoot=m.overshoot, rise_time=m.rise_time, settling_time=m.settling_time,
                          iae=_iae(r, t_end, step), peak_error=abs(step))


def _load(loop: Loop, size: float, t_end: float) -> LoadReport:
    from ..models.signals import LoadStep
    from ..simulate.simulation import simulate

    r = simulate(loop, 0.0, disturbance=LoadStep(size), t_end=t_end)
    x = np.linspace(0.0, 1.0, 33)
    t = (r.starts[:, None] + r.lengths[:, None] * x).ravel()
    t = t[t <= t_end]
    e = np.abs(np.asarray(r.output(t)))
    i = int(np.argmax(e))
    peak = float(e[i])
    out = np.flatnonzero(e > RECOVERY_BAND * peak)
    rec = float(t[out[-1]]) if out.size and out[-1] < t.size - 1 else None
    if out.size and out[-1] == t.size - 1:
        rec = None
    return LoadReport(size=size, peak_error=peak, peak_time=float(t[i]), iae=_iae(r, t_end), recovery_time=rec)


def _mt(loop: Loop) -> float:
    from ..spectrum.frequency import frequency_grid, frequency_response

    fr = frequency_response(loop, frequency_grid(loop, 4000))
    t = np.abs(fr.complementary)
    return float(np.max(t[np.isfinite(t)]))


def _choose_b(loop: Loop, target: float, step: float, t_end: float, notes: list[str]) -> float:
    """The largest setpoint weight ``b`` in [0, 1] whose setpoint overshoot is at most ``target`` % (bisection on
    the exact simulation's overshoot, to 1e-4 in ``b``)."""
    from ..simulate.simulation import simulate

    def over(b: float) -> float:
        return simulate(loop.replace(setpoint_weight=b), step, t_end=t_end).metrics.overshoot

    if over(1.0) <= target:
        return 1.0
    if over(0.0) > target:
        notes.append(f"even b = 0 overshoots {over(0.0):.3g} % (target {target:g} %): b = 0 kept")
        warnings.warn(notes[-1], TuningWarning, stacklevel=3)
        return 0.0
    lo, hi = 0.0, 1.0
    while hi - lo > 1e-4:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if over(mid) <= target else (lo, mid)
    return lo


# ---------------------------------------------------------------------------------------------- tune
def tune(plant: Any, controller: str = "pi", *, delay: float | None = None, rule: str | None = None,
         method: str | None = None, objective: str = "ki", ms: float = 1.4, mt: float | None = None,
         tau_c: float | None = None, delays: Any = None, gains: Any = None, overshoot: float | None = None,
         derivative_weight: float = 0.0, filter_ratio: float = 10.0, umin: float | None = None,
         umax: float | None = None, step: float = 1.0, load: float | None = None, t_end: float | None = None,
         antiwindup: str = "none") -> Tuning:
    """Tune a controller for a plant with a dead time, by a rule or by optimisation, and check it exactly.

    Parameters
    ----------
    plant : TransferFunction, str, Loop, AltitudeLoop or IdentifiedModel
        The plant (``"0.698*exp(-16.6*s)/(146.6*s+1)"``: a dead time in the text adds to ``delay``), a loop (its
        plant, total delay and actuator limits; the tuned loop replaces its controller) or an identified model
        (:func:`~delaykit.identify.identification.load_model`).
    controller : {"p", "pi", "pd", "pid", "pv"}
        The structure (``pv``, the paper's law, by optimisation only).
    delay : float, optional
        The dead time (s) of a bare plant.
    rule : {"simc", "amigo", "imc", "lambda", "zn", "tyreus-luyben"}, optional
        A tuning rule (:func:`~delaykit.design.pid_rules.rule_gains`); without it, ``method``.
    method : {"migo"}, optional
        Optimisation (the default when no rule is given) with ``objective`` ``"ki"`` (largest integral gain,
        MIGO), ``"iae-load"`` or ``"abscissa"`` (:func:`~delaykit.design.pid_optimise.optimise`).
    ms, mt : float
        The robustness limits of the optimisation (above 1); ``mt`` optional.
    tau_c : float, optional
        SIMC's closed-loop time constant or IMC's lambda (s; default the delay).
    delays, gains : list of float or "START:STOP:N", optional
        A robust optimisation: every combination of these delays (s) and gain factors; the limits hold at each
        point and the objective is the worst case.  Each point is reported in ``Tuning.robust``.
    overshoot : float, optional
        A setpoint-overshoot target (%) for the setpoint weight ``b`` of pi and pid, chosen after the feedback part.
    derivative_weight : float
        The derivative's setpoint weight ``c`` of a pid (0: derivative on the measurement).
    filter_ratio : float
        ``N``: the derivative filter's time constant is ``Td / N`` (optimisation) or ``Td / N`` of the rule's ``Td``.
    umin, umax : float, optional
        The actuator's limits (default those of the loop, or none).
    step, load : float
        The setpoint step and the load step for the report (``load`` defaults to half the smaller actuator
        limit, or 1 without limits).
    t_end : float, optional
        The simulations' length (default from the rightmost root: see the report's responses).
    antiwindup : {"none", "clamp", "backcalc"}
        The integrator's anti-windup in the tuned loop (pi, pid).

    Returns
    -------
    Tuning

    Raises
    ------
    InvalidValueError
        A negative delay, ``ms <= 1`` or ``mt <= 1`` (or above 100), an unknown rule, method or objective, both a
        rule and a method, a rule outside its plant family or structure, a robust range with a rule; an
        optimisation on an unstable plant, one whose gains have no largest value (no delay), or one that finds no
        stable loop.

    See Also
    --------
    delaykit.design.pid_rules.rule_gains : the rules and their references.
    delaykit.design.pid_optimise.optimise : the optimisation.

    Examples
    --------
    >>> t = tune("0.698*exp(-16.6*s)/(146.6*s+1)", "pi", method="migo", ms=1.4)
    >>> round(t.ms, 6), t.stable
    (1.4, True)
    """
    kind = str(controller).lower()
    if kind not in TUNE_CONTROLLERS:
        raise InvalidValueError(f"controller must be one of {', '.join(TUNE_CONTROLLERS)}; got {controller!r}")
    tf, theta, base = _plant_and_delay(plant, delay)
    ms_ = check_real("ms (peak sensitivity limit)", ms, minimum=1.0, strict=True)
    mt_ = None if mt is None else check_real("mt (peak complementary sensitivity limit)", mt, minimum=1.0, strict=True)
    if rule is not None and method is not None:
        raise InvalidValueError(f"give a rule or a method, not both (rule={rule!r}, method={method!r})")
    if rule is not None and (delays is not None or gains is not None):
        raise InvalidValueError("a robust design over --delays/--gains needs --method migo (a rule reads one model)")
    if rule is not None and objective != "ki":
        raise InvalidValueError(f"the objective {objective!r} is for --method migo, not for a rule")
    if method is not None and str(method).lower() not in METHODS:
        raise InvalidValueError(f"method must be one of {', '.join(METHODS)}; got {method!r}")
    if objective not in OBJECTIVES:
        raise InvalidValueError(f"objective must be one of {', '.join(OBJECTIVES)}; got {objective!r}")
    if rule is not None and (not isinstance(rule, str) or rule.lower().replace("_", "-") not in RULES):
        raise InvalidValueError(f"rule must be one of {', '.join(RULES)}; got {rule!r}")
    if rule is not None and kind == "pv":
        raise InvalidValueError("the tuning rules are for p, pi, pd and pid; tune the PV law with --method migo")
    lo = (base.umin if base is not None else -math.inf) if umin is None else check_real("umin", umin, maximum=0.0,
                                                                                          allow_neg_inf=True)
    hi = (base.umax if base is not None else math.inf) if umax is None else check_real("umax", umax, minimum=0.0,
                                                                                         allow_inf=True)
    n_f = check_real("filter_ratio (N)", filter_ratio, minimum=0.0, strict=True)
    step = check_real("step", step)
    size = (0.5 * min(abs(lo), hi) if math.isfinite(min(abs(lo), hi)) else 1.0) if load is None else check_real(
        "load", load)
    if overshoot is not None:
        overshoot = check_real("overshoot target (%)", overshoot, minimum=0.0)
        if kind not in ("pi", "pid"):
            raise InvalidValueError(f"an overshoot target sets the setpoint weight b of pi or pid, not of {kind}")
    ds = _range("delays", delays)
    gs = _range("gains", gains)
    notes: list[str] = []
    model = ult = None
    if rule is not None:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", TuningWarning)
            g = rule_gains(rule, kind, tf, theta, tau_c=tau_c)
        for w in caught:
            warnings.warn(w.message, TuningWarning, stacklevel=2)
        notes += list(g.notes)
        model, ult = g.model, g.ultimate
        kp, ki, kd = g.kp, g.ki, g.kd
        td = kd / kp if kp else 0.0
        tf_ = td / n_f if td > 0 else max(theta, 1e-3) / 1000.0
        how = g.rule
        if model is not None and model.reduction:
            notes.append(f"half rule: {model.reduction}")
    else:
        pts = plant_points(tf, theta, ds, gs)
        sol = optimise(kind, pts, ms=ms_, mt=mt_, objective=objective, filter_ratio=n_f, umin=lo, umax=hi,
                       load=size, t_end=t_end)
        kp, ki, kd, tf_ = _exact_limit(kind, sol.kp, sol.ki, sol.kd, sol.tf, pts, ms_, notes)
        how = "migo" if objective == "ki" else f"migo {objective}"
        if ds is not None or gs is not None:
            how += " robust"
    extra = {"antiwindup": antiwindup} if kind in ("pi", "pid") else {}
    ctrl = controller_of(kind, kp, ki, kd, tf_, **extra)
    if kind == "pid" and derivative_weight:
        ctrl = ctrl.replace(derivative_weight=check_real("derivative_weight (c)", derivative_weight, minimum=0.0))
    loop = (base.replace(controller=ctrl, umin=lo, umax=hi) if base is not None
            else Loop(tf, ctrl, delay=theta, umin=lo, umax=hi))
    result = _report(loop, how=how, kind=kind, step=step, size=size, t_end=t_end, overshoot=overshoot, notes=notes,
                     ms_limit=None if rule is not None else ms_, mt_limit=None if rule is not None else mt_,
                     model=model, ultimate=ult, points=(ds, gs))
    if rule is None and not result.stable:  # the optimisation asked for a stable loop within the limits
        raise InvalidValueError(f"the optimisation found no stabilising {kind} gains within Ms <= {ms_:g} for "
                                f"{tf.to_string(times=' ')} with delay {theta:g} s (its best, kp={result.kp:.4g}, "
                                f"ki={result.ki:.4g}, leaves the loop UNSTABLE by its certified roots)")
    return result


def assess(loop: Any, *, step: float = 1.0, load: float | None = None, t_end: float | None = None,
           how: str = "given") -> Tuning:
    """The checks of :func:`tune` (exact margins, Ms, Mt, setpoint and load responses) for a loop tuned elsewhere.

    Without integral action a load step leaves a steady error (``load / kp`` on an integrating plant), so the load's
    IAE grows with ``t_end`` and its recovery time is None.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> a = assess(AltitudeLoop(kp=1.31, delay=0.368))      # the paper's P loop
    >>> round(a.ms, 3), a.kind, a.load.recovery_time is None
    (1.561, 'p', True)
    """
    from ..models.altitude import as_loop

    lp = as_loop(loop)
    c = lp.controller
    if not hasattr(c, "feedback_polynomials") or c.kind == "tf":
        raise InvalidValueError("assess takes a p, pv, pi, pd or pid loop")
    size = (0.5 * min(abs(lp.umin), lp.umax) if math.isfinite(min(abs(lp.umin), lp.umax)) else 1.0) if load is None \
        else check_real("load", load)
    return _report(lp, how=how, kind=c.kind, step=check_real("step", step), size=size, t_end=t_end, overshoot=None,
                   notes=[], ms_limit=None, mt_limit=None, model=None, ultimate=None, points=(None, None))


def _exact_limit(kind: str, kp: float, ki: float, kd: float, tf: float, points: Sequence[Any], ms: float,
                 notes: list[str]) -> tuple[float, float, float, float]:
    """The optimised gains, the last one (``ki``, or ``kp`` and ``kd`` together without integral action) scaled
    down where the exact Ms (:func:`~delaykit.spectrum.frequency.margins`) at some plant exceeds the limit by more
    than 1e-9 relative (a peak between the optimiser's grid frequencies), by bisection on the scale to 1e-10."""
    from ..spectrum.frequency import margins

    def worst(a: float) -> float:
        g = (kp, a * ki, kd) if kind in ("pi", "pid") else (a * kp, ki, a * kd)
        c = controller_of(kind, g[0], g[1], g[2], tf)
        ms_ = [margins(Loop(p, c, delay=d)) for p, d in points]
        return max(m.ms if m.stable else math.inf for m in ms_)

    if worst(1.0) <= ms * (1 + 1e-9):
        return kp, ki, kd, tf
    lo, hi = 0.0, 1.0
    while hi - lo > 1e-10:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if worst(mid) <= ms else (lo, mid)
    notes.append(f"the exact Ms exceeded the limit between grid frequencies: the gain scaled by {lo:.8f}")
    return (kp, lo * ki, kd, tf) if kind in ("pi", "pid") else (lo * kp, ki, lo * kd, tf)


def _report(loop: Loop, *, how: str, kind: str, step: float, size: float, t_end: float | None,
            overshoot: float | None, notes: list[str], ms_limit: float | None, mt_limit: float | None,
            model: ReducedModel | None, ultimate: UltimatePoint | None,
            points: tuple[Sequence[float] | None, Sequence[float] | None]) -> Tuning:
    """The exact checks of a tuned loop (margins, Mt, responses, setpoint weight, robust points)."""
    from ..spectrum.frequency import margins

    analysed = loop.replace(period=None) if loop.sampled else loop
    if loop.sampled:
        notes.append(f"the loop is sampled every {loop.period:g} s; margins and responses are of the continuous loop")
    m = margins(analysed)
    c = analysed.controller
    ti = c.kp / c.ki if getattr(c, "ki", 0) else math.inf
    horizon = t_end if t_end is not None else _horizon(analysed, ti)
    b = 1.0
    if m.stable and overshoot is not None:
        b = _choose_b(analysed, overshoot, step, horizon, notes)
        loop, analysed = loop.replace(setpoint_weight=b), analysed.replace(setpoint_weight=b)
    sp = _setpoint(analysed, step, horizon) if m.stable and step else None
    ld = _load(analysed, size, horizon) if m.stable and size else None
    robust: list[RobustPoint] = []
    ds, gs = points
    if ds is not None or gs is not None:
        from .pid_optimise import load_iae

        for d in (ds if ds is not None else [analysed.delay]):
            for g in (gs if gs is not None else [1.0]):
                p = analysed.replace(plant=TransferFunction(analysed.plant.num * g, analysed.plant.den), delay=d)
                mm = margins(p)
                iae = load_iae(p, size, horizon) if mm.stable and c.has_integrator else math.nan
                robust.append(RobustPoint(d, g, mm.ms, mm.gain_margin, mm.phase_margin, mm.delay_margin, mm.stable,
                                          iae))
        if not all(p.stable for p in robust):
            notes.append("UNSTABLE at some plant of the robust set")
    if not m.stable:
        notes.append("the tuned loop is UNSTABLE (certified roots)")
    kd = getattr(c, "kv", 0.0) if kind == "pv" else c.kd
    b = analysed.controller.setpoint_weight
    return Tuning(how=how, kind=kind, kp=c.kp, ki=c.ki, kd=kd, tf=c.derivative_filter, b=b,
                  c=c.derivative_weight, loop=loop, ms=m.ms, mt=_mt(analysed) if m.stable else math.nan,
                  gain_margin=m.gain_margin, phase_margin=m.phase_margin, delay_margin=m.delay_margin,
                  stable=m.stable and all(p.stable for p in robust), setpoint=sp, load=ld, ms_limit=ms_limit,
                  mt_limit=mt_limit, model=model, ultimate=ultimate, robust=tuple(robust), notes=tuple(notes))
