"""Closed-loop identification through any linear controller: the general simulator as the fit's model.

The compiled sample-to-sample path of :mod:`._fit` covers a static P or PV (true velocity) law sampled at the
log's rate.  Every other :class:`~delaykit.models.controllers.Controller` (PI, PID, PD, PV through its derivative
filter, a transfer function on the error), continuous or sampled, with the loop's limits and anti-windup, is fitted
here: each trial plant and delay is put inside the given loop and the loop is simulated exactly
(:mod:`delaykit.simulate.simulation`'s kernel), the log's reference held between its samples, and the output
read at the log's sample times.

Deviation variables and the initial state.  The log starts at rest: every state of the loop at its equilibrium,
the output at its baseline ``y0``, the reference at ``r0`` (means before the reference moves).  With an integrator
in the controller the loop rests at zero error, so ``y0 = r0`` exactly: the output's rest is taken from the
reference, not from the noisy mean of its first samples (whose error would sit in every residual, unaccounted for
by the intervals; ``baseline="fit"`` fits an offset instead, for an output logged with a bias).  The simulated loop
runs in deviations from that rest: reference ``r - r0``, output ``y - y0``, command ``u - u0``, the controller's
states (its integrator, its filters) starting from their rest values, which in deviations are zero.  A linear
controller needs nothing more; only the limits need the absolute command at rest ``u0``, as ``[umin - u0,
umax - u0]`` around it.  ``u0`` is

* given (``u0=`` or the logged command column ``command=``: its mean before the reference moves);
* irrelevant when the loop has no limits;
* ``C(0) (r0 - y0)`` for a controller without an integrator (its output at rest: no feedforward bias assumed);
* ``0`` for an integrator in the controller and an integrating plant: the plant rests only at zero input
  (the model has no input offset; a hover command or another bias must be given as ``u0``);
* undetermined for an integrator in the controller and a self-regulating plant (the integrator holds whatever
  command the rest needed): :class:`~._fit.IdentificationError` asks for it.

Private: :mod:`._fit` dispatches here; :mod:`.identification` is the public face.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.closed_loop import realisation_of
from ..models.compensators import Compensator
from ..models.controllers import Controller
from ..models.loop import Loop
from ..models.transfer import TransferFunction
from ..simulate import _layout as K
from ..simulate.simulation import _horner, _Workspace
from . import _fit as F
from .iodata import Experiment
from .structures import STRUCTURES, Structure

__all__ = ["GeneralLaw", "general_law", "from_static", "rest_commands", "GeneralProblem", "prepare", "simulate",
           "guesses", "check_rest", "law_to_dict", "law_from_dict"]

_FASTEST = 8.0
"""A trial plant's fastest rate is at most this many times the sample rate (time constants at least 1/8 of a
period, natural frequencies at most 8 rad per period): faster modes have all but died out within a sample, so the
data cannot tell them from a slightly longer delay, and they would make the exact simulation take many pieces per
sample."""

_SHORT_DELAY = 0.125
"""Delays shorter than this fraction of the sample period are interpolated (see :func:`_outputs`)."""


@dataclass(frozen=True, eq=False)
class GeneralLaw:
    """The controller of a closed-loop fit through the general simulator: the law, its limits and sampling.

    Examples
    --------
    >>> law = general_law(Loop("1/s", Controller.pi(2.0, 0.5), umin=-1, umax=3, period=0.05))
    >>> law.integral, law.saturated, law.static_gain
    (True, True, inf)
    """

    controller: Controller
    umin: float
    umax: float
    period: float | None
    offset: float

    @property
    def integral(self) -> bool:
        """True when the controller integrates the error (a pole at 0)."""
        return bool(self.controller.feedback_polynomials()[1][-1] == 0.0)

    @property
    def saturated(self) -> bool:
        """True when the command has a finite limit."""
        return math.isfinite(self.umin) or math.isfinite(self.umax)

    @property
    def static_gain(self) -> float:
        """``C(0)``, the controller's output per unit of a constant error (``inf`` with an integrator)."""
        num, den = self.controller.feedback_polynomials()
        return math.inf if den[-1] == 0.0 else float(num[-1] / den[-1])

    @property
    def kp(self) -> float:
        """The proportional gain (0 for a transfer-function controller)."""
        return 0.0 if self.controller.kind == "tf" else self.controller.kp

    def magnitude(self, w: float) -> float:
        """``|C(jw)|`` of the feedback part."""
        num, den = self.controller.feedback_polynomials()
        return float(abs(np.polyval(num, 1j * w) / np.polyval(den, 1j * w)))


def general_law(loop: Loop) -> GeneralLaw:
    """The law of a closed-loop fit of ``loop`` (no delay: the delay is what is fitted; checked by the caller).

    Raises
    ------
    IdentificationError
        A compensator (Smith predictor, predictor feedback): it holds a model of the plant, which is what is
        identified.

    Examples
    --------
    >>> general_law(Loop("1/s", Controller.pid(1.0, 0.2, 0.1, 0.02))).period is None
    True
    """
    c = loop.controller
    if isinstance(c, Compensator) or not isinstance(c, Controller):
        raise F.IdentificationError(
            f"closed-loop identification takes a controller (p, pv, pi, pd, pid or a transfer function); the loop's "
            f"is a {getattr(c, 'kind', type(c).__name__)} compensator, which holds a model of the plant: identify "
            "open loop from the logged command instead")
    return GeneralLaw(c, loop.umin, loop.umax, loop.period, loop.sample_offset)


def from_static(law: F._Law) -> GeneralLaw:
    """The general form of a compiled path's P/PV law (to run it with a given command at rest).

    Examples
    --------
    >>> from_static(F._Law(0.95, 0.0, -1.0, 3.0, 0.02)).controller
    Controller(p: kp=0.95)
    """
    c = Controller.pv(law.kp, law.kv) if law.kv else Controller.p(law.kp)
    return GeneralLaw(c, law.umin, law.umax, law.period, 0.0)


def rest_commands(u0: Any, command: str | None, n: int) -> list[Any]:
    """The command at rest of each of ``n`` logs as :func:`prepare` takes it: a column name, a number, ``None``.

    Examples
    --------
    >>> rest_commands(None, "u", 2), rest_commands(3.0, None, 2), rest_commands([1, 2], None, 2)
    (['u', 'u'], [3.0, 3.0], [1, 2])
    """
    if command is not None:
        if not isinstance(command, str):
            raise InvalidTypeError(f"command must be a column name, got {type(command).__name__}")
        return [command] * n
    if u0 is None or np.ndim(u0) == 0:
        return [u0] * n
    vals = list(u0)
    if len(vals) != n:
        raise F.IdentificationError(f"u0 has {len(vals)} values for {n} logs: give one per log, or one for all")
    return vals


# -- one log -------------------------------------------------------------------------------------------------
def prepare(exp: Experiment, law: GeneralLaw, common: dict[str, Any], u0: float | str | None) -> F._Prepared:
    """A closed-loop log prepared for the general law: the reference's deviation ``r - r0`` as the drive, the
    absolute command at rest ``u0`` when it is given (a number, or a column of the log) or follows from a
    controller without an integrator; the limits are set per structure (:func:`rest_command`)."""
    if law.period is not None and abs(law.period - exp.period) > 1e-3 * exp.period:
        raise F.IdentificationError(
            f"{exp.name}: the controller's period ({law.period:g} s) must equal the log's sample period "
            f"({exp.period:.6g} s): the log's reference is what the controller read at each of its samples "
            "(or give a continuous controller: no period)")
    if isinstance(u0, str):
        if u0 not in exp.outputs:
            raise F.IdentificationError(f"{exp.name}: no command column {u0!r} for the command at rest (it has "
                                        f"{', '.join(exp.outputs)})")
        u0 = exp.baseline(u0)
    elif u0 is not None:
        u0 = float(u0)
        if not math.isfinite(u0):
            raise F.IdentificationError(f"{exp.name}: the command at rest u0 must be finite, got {u0!r}")
    r0 = exp.drive_baseline
    if u0 is None and not law.integral:
        e0 = r0 - common["base"][common["outputs"][0]]
        u0 = law.static_gain * e0 if e0 else 0.0
        if law.saturated and not law.umin <= u0 <= law.umax:
            raise F.IdentificationError(
                f"{exp.name}: at rest the controller's output C(0) (r0 - y0) = {u0:.6g} lies outside the limits "
                f"[{law.umin:g}, {law.umax:g}]: the log starts saturated, or the controller adds a bias; give the "
                "command at rest (u0=..., --u0) if it is not saturated")
    if u0 is not None and law.saturated and not law.umin <= u0 <= law.umax:
        raise F.IdentificationError(f"{exp.name}: the command at rest u0 = {u0:g} lies outside the loop's limits "
                                    f"[{law.umin:g}, {law.umax:g}]")
    drive = np.ascontiguousarray(exp.r - r0)  # type: ignore[operator]
    if law.integral:  # the loop rests at zero error: the output's rest is the reference's, known exactly
        first = common["outputs"][0]
        common["base"][first] = r0
        common["meas"][first] = exp.outputs[first] - r0
    return F._Prepared(exp, common["outputs"], common["rate"], drive, math.nan, math.nan, common["meas"],
                       common["keep"], common["base"], common["wander"], u0)


def rest_command(prep: F._Prepared, law: GeneralLaw, integrating: bool, model: str = "") -> float:
    """The absolute command at rest of a log (see the module docstring), for a plant that integrates or not.

    Raises
    ------
    IdentificationError
        Limits, an integrator in the controller, a self-regulating plant and no ``u0``.
    """
    if prep.u0 is not None:
        return float(prep.u0)
    if not law.saturated:
        return 0.0
    if integrating:
        return 0.0
    raise F.IdentificationError(_rest_message(prep.exp.name, law, [model] if model else []))


def _rest_message(name: str, law: GeneralLaw, models: list[str]) -> str:
    what = (f"the {' and '.join(models)} plant{'s rest' if len(models) > 1 else ' rests'}" if models
            else "a self-regulating plant rests")
    return (f"{name}: the command at rest is unknown: the {law.controller.kind} controller's integrator holds it, "
            f"{what} at any command, and the limits [{law.umin:g}, {law.umax:g}] act on the absolute "
            "command; give it (u0=..., or command='COLUMN' naming the logged command; --u0 or --command), or fit "
            "an integrating structure (ipdt, ipdt_lag, ipdt_speed), which rests at zero command")


def check_rest(law: GeneralLaw, preps: list[F._Prepared], names: list[str]) -> None:
    """Refuse, before any fit, structures whose logs lack a command at rest they need (:func:`rest_command`)."""
    if not (law.saturated and law.integral):
        return
    bad = [nm for nm in names if not STRUCTURES[nm].integrating]
    missing = [p for p in preps if p.u0 is None]
    if bad and missing:
        raise F.IdentificationError(_rest_message(missing[0].exp.name, law, bad))


def _integrates(plant: TransferFunction) -> bool:
    return bool(plant.den[-1] == 0.0)


# -- the simulation of one log ------------------------------------------------------------------------------
class _LogRun:
    """One log's run of the loop: its reference knots, the times to read the output at, a workspace."""

    def __init__(self, prep: F._Prepared, law: GeneralLaw, lo: float, hi: float) -> None:
        e = prep.exp
        n = e.t.size
        if law.period is None:
            times = e.t - e.t[0]
            at = times
        else:
            times = np.arange(n) * law.period
            at = law.offset + times  # the controller's k-th sample reads the log's k-th reference
        r = prep.drive
        k = np.r_[0, np.flatnonzero(np.diff(r)) + 1]
        self.knots = (np.ascontiguousarray(at[k]), np.ascontiguousarray(r[k]), np.zeros(k.size))
        if self.knots[0][0] > 0.0:
            self.knots = (np.r_[0.0, self.knots[0]], np.r_[r[0], self.knots[1]], np.zeros(k.size + 1))
        self.times = np.ascontiguousarray(times)
        self.t_end = float(times[-1]) + 1e-9
        self.rmax = float(np.max(np.abs(r)))
        self.lo, self.hi = lo, hi
        self.rate = prep.rate is not None
        self.ws = _Workspace(store=self.rate, t=self.times)
        # the loop without its plant: a parameter row whose plant entries each run writes over
        self.law = law
        self.rz = law.controller.realisation()
        self.frame = Loop("1/s", law.controller, delay=1.0, umin=lo, umax=hi, period=law.period,
                          sample_offset=law.offset)
        self.ctrl_rate = float(np.max(np.abs(np.linalg.eigvals(self.rz.Ac)))) if self.rz.order else 0.0
        self.templates: dict[int, np.ndarray] = {}

    def _row(self, A: np.ndarray, B: np.ndarray, C: np.ndarray, delay: float) -> np.ndarray:
        """The kernel's parameter row of the loop around the plant ``(A, B, C)`` (strictly proper) with its
        delay: the controller's part built once (:func:`~delaykit.simulate._layout.param_row`), the plant's
        entries written in place; what :func:`~delaykit.simulate._layout.loop_matrices` and ``param_row`` give
        for the same loop."""
        npl = A.shape[0]
        lay = _matrices(A, B, C, self.rz)
        H = K.HEAD
        base = self.templates.get(npl)
        if base is None:
            base = K.param_row(self.frame, lay, step=float(self.knots[1][0]), slope=0.0, norm=0.0,
                               t_end=self.t_end, band=0.02, dist=None)
            base[H["scale"]] = max(1.0, abs(base[H["dvr"]]) * self.rmax, self.rmax)
            self.templates[npl] = base
        row = base.copy()
        for i in range(npl):
            row[K.OFF_M + i * K.MAXN:K.OFF_M + i * K.MAXN + npl] = A[i]
        row[K.OFF_BW:K.OFF_BW + npl] = B
        row[K.OFF_CY:K.OFF_CY + npl] = C
        row[K.OFF_CYD:K.OFF_CYD + npl] = lay.cyd[:npl]
        row[H["dy"]] = 0.0
        row[H["dyd"]] = lay.dyd
        row[H["ti"]] = delay
        rate = max(float(np.max(np.abs(np.linalg.eigvals(A)))), self.ctrl_rate, abs(self.rz.dvy * lay.dyd))
        if self.law.period is None and delay * rate <= K.SELF:  # a short delay: the closed loop's rates too
            rate = K.step_rate(lay, self.rz.dvy, self.rz.dvv, lay.cv, delay, False)
        row[H["hmax"]] = 1.0 / max(rate, 1e-9)
        return row

    def run(self, A: np.ndarray, B: np.ndarray, C: np.ndarray,
            delay: float) -> tuple[np.ndarray, np.ndarray | None]:
        """The output (and its rate when the log has one) at the log's samples."""
        row = self._row(A, B, C, delay)
        n = self.ws.run(row, self.knots)
        y = self.ws.ez.copy()
        if not self.rate:
            return y, None
        t0, th, _, td, _ = self.ws.y
        starts, lengths = t0[:n], th[:n]
        idx = np.clip(np.searchsorted(starts, self.times, side="right") - 1, 0, n - 1)
        x = np.clip((self.times - starts[idx]) / lengths[idx], 0.0, 1.0)
        return y, _horner(td[:n][idx], x)


def _matrices(A: np.ndarray, B: np.ndarray, C: np.ndarray, rz: Any) -> K.LoopMatrices:
    """:func:`~delaykit.simulate._layout.loop_matrices` of the loop around the strictly proper plant
    ``(A, B, C)`` (a controller without a model of the plant: ``rz`` its realisation)."""
    npl, nc = A.shape[0], rz.order
    n = npl + nc
    if n > K.MAXN:
        raise F.IdentificationError(f"the loop has {n} states (plant {npl}, controller {nc}); the simulator takes "
                                    f"at most {K.MAXN}")
    return realisation_of(A, B, C, 0.0, rz)


def _outputs(runs: list[_LogRun], plant: tuple[np.ndarray, np.ndarray, np.ndarray], delay: float,
             law: GeneralLaw, h: float) -> list[tuple[np.ndarray, np.ndarray | None]]:
    """Each log's output (and rate) with the plant ``(A, B, C)`` and ``delay`` in the loop.

    The simulator's pieces are no longer than the loop's delay, so a delay far below the sample period costs
    many pieces per sample (a million for a microsecond over a minute).  A delay ``0 < T < T1``, with
    ``T1 = _SHORT_DELAY * h``, is therefore interpolated: the quadratic through the exact responses at 0,
    ``T1 / 2`` and ``T1``.  No held edge crosses a sample there, so a response is smooth in the delay and the
    error is of order ``T1^3`` times its third derivative (1e-8 of a 15-unit step for a lag of 60 periods);
    where a sample's command comes off (or onto) a limit inside ``(0, T1)`` the response has a kink in the delay,
    and the error grows to about ``T1`` times the change of slope (a few percent of the delay's effect for a lag of
    4 periods).  At 0 and from ``T1`` on, every response is exact.
    """
    t1 = _SHORT_DELAY * h
    if 0.0 < delay < t1:
        nodes = (0.0, 0.5 * t1, t1)
        sims = [_exact(runs, plant, d, law) for d in nodes]
        x = delay / t1  # Lagrange weights on the nodes 0, 1/2, 1
        w = ((2 * x - 1) * (x - 1), 4 * x * (1 - x), x * (2 * x - 1))
        out = []
        for i in range(len(runs)):
            y = sum(wk * s[i][0] for wk, s in zip(w, sims))
            dy = None if sims[0][i][1] is None else sum(wk * s[i][1] for wk, s in zip(w, sims))
            out.append((y, dy))
        return out
    return _exact(runs, plant, delay, law)


def _exact(runs: list[_LogRun], plant: tuple[np.ndarray, np.ndarray, np.ndarray], delay: float,
           law: GeneralLaw) -> list[tuple[np.ndarray, np.ndarray | None]]:
    return [run.run(*plant, delay) for run in runs]


def simulate(prep: F._Prepared, plant: TransferFunction, delay: float, law: GeneralLaw) -> dict[str, np.ndarray]:
    """The loop's free-run outputs (deviations) at one log's samples, the plant and delay in the given loop."""
    u0 = rest_command(prep, law, _integrates(plant))
    run = _LogRun(prep, law, law.umin - u0, law.umax - u0)
    A, B, C, D = plant.state_space()
    if D:
        raise F.IdentificationError(f"the plant {plant.to_string()} has a direct feedthrough; a closed-loop model's "
                                    "plant is strictly proper")
    A = np.atleast_2d(np.asarray(A, float))
    abc = (A, np.asarray(B, float).reshape(A.shape[0]), np.asarray(C, float).reshape(A.shape[0]))
    y, dy = _outputs([run], abc, delay, law, prep.exp.period)[0]
    out = {prep.outputs[0]: y}
    if prep.rate:
        out[prep.rate] = dy  # type: ignore[assignment]
    return out


# -- the fit ---------------------------------------------------------------------------------------------------
class GeneralProblem(F._Problem):
    """:class:`~._fit._Problem` whose residuals come from the general simulator (see the module docstring):
    one exact simulation of the loop per log and trial point, the residual blocks and the offsets' projection
    as in the compiled path."""

    compiled = False
    max_nfev = 100  # a fit converges in a few tens; more only crawls along a valley where a lag runs off

    def __init__(self, st: Structure, preps: list[F._Prepared], law: GeneralLaw, weights: dict[str, float],
                 fit_offset: bool) -> None:
        super().__init__(st, preps, law, weights, fit_offset)
        self.runs = []
        for q in preps:
            u0 = rest_command(q, law, st.integrating, st.name)
            self.runs.append(_LogRun(q, law, law.umin - u0, law.umax - u0))

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`~._fit._Problem.bounds`, with time constants at least ``1 / _FASTEST`` of a period and natural
        frequencies at most ``_FASTEST`` rad per period."""
        lb, ub = super().bounds()
        for i, (pos, unit) in enumerate(zip(self.st.positive, self.st.units)):
            if pos and unit == "s":
                lb[i] = max(lb[i], math.log(self.h / _FASTEST))
            elif pos and unit == "rad/s":
                ub[i] = math.log(_FASTEST / self.h)
        return lb, ub

    def grid_starts(self) -> list[np.ndarray]:
        """The coarse grid of :func:`~._fit._grid_starts`, each point's gain set by :func:`_crossover_gain`."""
        out = []
        for p in F._grid_starts(self.st, self.preps):
            ts = float(p[1]) if self.st.size > 2 else 10.0 * self.h
            p[0] = _crossover_gain(self.st, p, self.law, 1.0 / ts)
            out.append(p)
        return out

    def raw(self, p: np.ndarray) -> np.ndarray:
        """Raw residuals as :meth:`~._fit._Problem.raw`, each log simulated by the general simulator."""
        p = np.ascontiguousarray(p, dtype=float)
        if not p[-1] >= 0.0:
            raise InvalidValueError(f"delay (s) must be >= 0, got {p[-1]!r}")
        A, B, C = self.st.realise(p)
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))) or \
                float(np.max(np.abs(np.linalg.eigvals(A)))) * self.h > _FASTEST * 1.001:
            return np.full(self._rw.size, np.nan)  # faster than the samples can show: rejected
        sims = _outputs(self.runs, (A, B, C), float(p[-1]), self.law, self.h)
        ys = [y for y, _ in sims]
        dys = [dy if dy is not None else np.zeros(0) for _, dy in sims]
        y = np.ascontiguousarray(np.concatenate(ys))
        dy = np.ascontiguousarray(np.concatenate(dys)) if self.rate else np.zeros(y.size)
        out = np.empty(self._rw.size)
        empty = np.zeros(y.size)
        F.FK.residual_blocks(y, dy, empty, empty, self.starts, self.k0, self.p0, self.m0, self.k1, self.p1, self.m1,
                             float(self.w[self.first]), float(self.w[self.rate]) if self.rate else 1.0, False,
                             self.fit_offset, out)
        return out


def _crossover_gain(st: Structure, p: np.ndarray, law: GeneralLaw, wc: float) -> float:
    """The plant gain at which the loop's gain ``|C P|`` is 1 at ``wc`` (the other parameters as in ``p``,
    the delay left out): a loop someone tuned crosses over near the inverse of its response time."""
    q = np.array(p, dtype=float)
    q[0] = 1.0
    unit = st.plant(q)
    with np.errstate(all="ignore"):
        g = law.magnitude(wc) * float(abs(np.polyval(unit.num, 1j * wc) / np.polyval(unit.den, 1j * wc)))
    return 1.0 / g if 0.0 < g < math.inf else 1.0


def guesses(st: Structure, preps: list[F._Prepared], law: GeneralLaw) -> list[np.ndarray]:
    """Starting points: the delay and time scales from the response's onset and its 63 % time, the gain where
    the loop would cross over at the response's speed, times 1/3, 1 and 3."""
    prep = preps[0]
    e = prep.exp
    o = prep.outputs[0]
    y = prep.meas[o]
    h = e.period
    i0 = e.onset
    span = float(np.ptp(y)) or 1.0
    noise = prep.wander[o] if not math.isnan(prep.wander[o]) else 0.0
    thr = max(4.0 * noise, 0.05 * span)
    moved = np.flatnonzero(np.abs(y[i0:] - y[i0]) > thr)
    t_resp = max(float(e.t[i0 + moved[0]] - e.t[i0]) if moved.size else 0.1 * e.duration, 2.0 * h)
    yf = float(y[-max(3, y.size // 20):].mean())
    cross = np.flatnonzero(np.abs(y[i0:]) >= 0.632 * abs(yf)) if yf else np.array([], int)
    t63 = max(float(e.t[i0 + cross[0]] - e.t[i0]) if cross.size else 0.3 * e.duration, 2.0 * h)
    out = []
    for frac in (0.3, 0.7):
        td = frac * t_resp
        tau = max(t63 - td, 2.0 * h)
        lag = max(0.5 * t_resp, 2.0 * h)
        vals = {"gain": 1.0, "delay": td, "lag": lag, "time_constant": tau, "time_constant2": max(0.2 * tau, h),
                "wn": 2.0 / lag, "zeta": 0.7, "zero": lag}
        p = np.array([vals[nm] for nm in st.params])
        k = _crossover_gain(st, p, law, 1.0 / t63)
        for m in (1.0, 1.0 / 3.0, 3.0):
            q = p.copy()
            q[0] = k * m
            out.append(q)
    return out


# -- the saved form ------------------------------------------------------------------------------------------
def law_to_dict(law: GeneralLaw) -> dict[str, Any]:
    """The JSON form kept in :attr:`IdentifiedModel.closed_loop`: the controller's kind and settings, the limits
    (``None``: none), the period (``None``: continuous) and the sample offset.

    Examples
    --------
    >>> d = law_to_dict(general_law(Loop("1/s", Controller.pi(2.0, 0.5), umin=0, umax=100, period=1.0)))
    >>> d["kind"], d["controller"], d["umax"]
    ('pi', {'kind': 'pi', 'kp': 2.0, 'ki': 0.5, 'antiwindup': 'none'}, 100.0)
    """
    c = law.controller
    d: dict[str, Any] = {"kind": c.kind, "controller": c.to_dict()}
    if c.kind != "tf":
        d["kp"] = c.kp
    d.update({"umin": law.umin if math.isfinite(law.umin) else None,
              "umax": law.umax if math.isfinite(law.umax) else None,
              "period": law.period, "sample_offset": law.offset})
    return d


def law_from_dict(d: dict[str, Any]) -> GeneralLaw:
    """The law back from :func:`law_to_dict`'s form.

    Examples
    --------
    >>> law = general_law(Loop("1/s", Controller.pid(2.0, 0.5, 0.1, 0.02, antiwindup="clamp"), umax=3))
    >>> law_from_dict(law_to_dict(law)).controller
    Controller(pid: kp=2, ki=0.5, kd=0.1, Tf=0.02 s, anti-windup clamp)
    """
    c = dict(d["controller"])
    kind = c.pop("kind")
    if kind == "tf":
        ctrl = Controller.transfer(TransferFunction(**c["transfer_function"]))
    else:
        ctrl = Controller(kind, **c)
    umin = -math.inf if d.get("umin") is None else check_real("umin", d["umin"])  # (numbers, not text)
    umax = math.inf if d.get("umax") is None else check_real("umax", d["umax"])
    per = d.get("period")
    per = None if per is None else check_real("period", per)
    return general_law(Loop("1/s", ctrl, umin=umin, umax=umax, period=per,
                            sample_offset=check_real("sample_offset", d.get("sample_offset") or 0.0)))
