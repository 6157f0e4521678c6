"""Designing a delay compensator from a model, and how much model error the design survives.

* :func:`delay_ratio_range`: the exact range of true-to-model delay ratios ``Td / Tm`` over which the loop
  with a compensator stays stable, from the rightmost roots of its characteristic function (a
  quasi-polynomial with two delays, the plant's and the model's);
* :func:`robustness_map`: the spectral abscissa over a grid of delay ratios and gain ratios (true plant gain
  over model gain);
* :func:`design_compensator`: a compensator of a kind for a model, its speed chosen as the fastest whose
  delay-ratio range covers a stated delay uncertainty, with the nominal step metrics, load-disturbance
  recovery and the physical bound on the settling time;
* :func:`compare_designs`: several controllers on the same plant, in one table.

Examples
--------
>>> d = design_compensator("smith", "1/s", 0.37, umin=-1, umax=1)
>>> d.steps[1.0].settling_time < 1.5, d.delay_ratio_range[0] <= 0.8, d.delay_ratio_range[1] >= 1.2
(True, True, True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.budget import MAX_SAMPLES, check_count
from ..models.compensators import COMPENSATOR_KINDS, Compensator
from ..models.controllers import Controller
from ..models.loop import Loop
from ..models.signals import LoadStep
from ..models.transfer import TransferFunction
from ..simulate.metrics import StepMetrics
from ..simulate.simulation import simulate
from ..spectrum.stability import rightmost

__all__ = ["CompensatorDesign", "RobustnessMap", "DisturbanceRecovery", "delay_ratio_range", "robustness_map",
           "design_compensator", "tune_compensator", "compare_designs", "minimum_settling_time", "disturbance_recovery",
           "design_horizon"]

_RATIO_MAX = 4.0
_SCAN = 0.02
_RATIO_LIMIT = 100.0  # the largest ratio_max: 5000 steps of the scan


def _abscissa(law: Compensator | Controller, plant: TransferFunction, delay: float) -> float:
    return rightmost(Loop(plant, law, delay=delay)).abscissa  # (the loop: its structural roots at 0 left out)


def _edge(law: Any, plant: TransferFunction, tm: float, inside: float, outside: float, tol: float) -> float:
    """The stability boundary between a stable ratio ``inside`` and an unstable ``outside`` (bisection)."""
    while abs(outside - inside) > tol:
        mid = 0.5 * (inside + outside)
        if _abscissa(law, plant, mid * tm) < 0:
            inside = mid
        else:
            outside = mid
    return inside


def delay_ratio_range(compensator: Compensator, plant: Any = None, *, ratio_max: float = _RATIO_MAX,
                      tol: float = 1e-4) -> tuple[float, float]:
    """The connected range of ratios ``Td / Tm`` (true delay over model delay) around 1 for which the loop
    with ``compensator`` on ``plant`` (default: the model itself) is stable.

    Stability is decided by the rightmost root of the characteristic quasi-polynomial (saturation ignored),
    scanned in steps of 0.02 and bisected to ``tol``.  The upper end is capped at ``ratio_max``.  Stability
    may return at other ratios (islands); this range is the one the design sits in.

    Examples
    --------
    >>> lo, hi = delay_ratio_range(Compensator.smith("1/s", 0.37, closed_loop_time=0.0925))
    >>> round(lo, 3), round(hi, 3)
    (0.626, 1.372)

    See Also
    --------
    robustness_map : the abscissa over delay and gain ratios.
    """
    if not isinstance(compensator, Compensator):
        raise InvalidTypeError(f"expected a Compensator, got {type(compensator).__name__}")
    # (a scan in steps of 0.02 up to ratio_max, then a bisection to tol: both bounded, 1e-320 never ends)
    ratio_max = check_real("ratio_max", ratio_max, minimum=1.0, strict=True, maximum=_RATIO_LIMIT)
    tol = check_real("tol", tol, minimum=1e-12, maximum=_SCAN)
    tm = compensator.model_delay
    if tm <= 0:
        raise InvalidValueError("the delay-ratio range needs a positive model delay; got model_delay=0")
    g = compensator.model if plant is None else TransferFunction.coerce(plant)
    if _abscissa(compensator, g, tm) >= 0:
        raise InvalidValueError("the compensated loop is unstable at its own model delay; nothing to measure")
    lo = 0.0
    r = 1.0
    while r > _SCAN:
        r2 = max(r - _SCAN, _SCAN / 2)
        if _abscissa(compensator, g, r2 * tm) >= 0:
            lo = _edge(compensator, g, tm, r, r2, tol)
            break
        r = r2
    hi = ratio_max
    r = 1.0
    while r < ratio_max:
        r2 = min(r + _SCAN, ratio_max)
        if _abscissa(compensator, g, r2 * tm) >= 0:
            hi = _edge(compensator, g, tm, r, r2, tol)
            break
        r = r2
    return lo, hi


@dataclass(frozen=True, repr=False)
class RobustnessMap:
    """The spectral abscissa of a compensated loop over delay ratios (rows) and gain ratios (columns)."""

    delay_ratios: np.ndarray
    gain_ratios: np.ndarray
    abscissa: np.ndarray
    kind: str

    @property
    def stable(self) -> np.ndarray:
        """Where the loop is stable."""
        return self.abscissa < 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"kind": self.kind, "delay_ratios": self.delay_ratios.tolist(),
                "gain_ratios": self.gain_ratios.tolist(), "abscissa": self.abscissa.tolist()}

    def __repr__(self) -> str:
        return (f"RobustnessMap({self.kind}: {self.delay_ratios.size} delay ratios x {self.gain_ratios.size} gain "
                f"ratios, {int(self.stable.sum())} stable)")


def robustness_map(compensator: Compensator, delay_ratios: Sequence[float] = tuple(np.linspace(0.5, 2.0, 31)),
                   gain_ratios: Sequence[float] = tuple(np.linspace(0.5, 2.0, 31)), *,
                   progress: Any = None) -> RobustnessMap:
    """The rightmost root's real part for the true plant ``rho_K Gn`` with delay ``rho_T Tm``, over a grid.

    Examples
    --------
    >>> m = robustness_map(Compensator.smith("1/s", 0.37), [0.9, 1.0, 1.1], [1.0])
    >>> m.stable.ravel().tolist()
    [True, True, True]
    """
    if not isinstance(compensator, Compensator):
        raise InvalidTypeError(f"expected a Compensator, got {type(compensator).__name__}")
    dr = np.asarray([check_real("delay ratio", x, minimum=0.0) for x in delay_ratios])
    gr = np.asarray([check_real("gain ratio", x, minimum=0.0, strict=True) for x in gain_ratios])
    if dr.size == 0 or gr.size == 0:
        raise InvalidValueError("the robustness map needs at least one delay ratio and one gain ratio")
    out = np.empty((dr.size, gr.size))
    for j, k in enumerate(gr):
        plant = compensator.model * float(k)
        for i, r in enumerate(dr):
            out[i, j] = _abscissa(compensator, plant, r * compensator.model_delay)
            if progress is not None:
                progress()
    return RobustnessMap(dr, gr, out, compensator.kind)


@dataclass(frozen=True, repr=False)
class DisturbanceRecovery:
    """The response to a step load disturbance at the plant input, with the reference at rest.

    ``peak``: the largest deviation; ``final_error``: the deviation at the end of the run;
    ``recovery_time``: when the deviation last exceeded 10 % of the peak (``None`` if it never returns).
    """

    size: float
    peak: float
    final_error: float
    recovery_time: float | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"size": self.size, "peak": self.peak, "final_error": self.final_error,
                "recovery_time": self.recovery_time}

    def __repr__(self) -> str:
        rt = "never" if self.recovery_time is None else f"{self.recovery_time:.3f} s"
        return (f"DisturbanceRecovery(peak={self.peak:.4f}, final_error={self.final_error:.2e}, "
                f"recovery={rt})")


def disturbance_recovery(loop: Loop, size: float = 0.2, t_end: float = 20.0, n: int = 4001) -> DisturbanceRecovery:
    """A step load disturbance of ``size`` at t = 0 on the loop at rest: peak deviation and recovery.

    Examples
    --------
    >>> r = disturbance_recovery(Loop("1/s", Controller.p(2.0), delay=0.37))
    >>> round(r.final_error, 4)
    0.1
    """
    size = check_real("size (load disturbance)", size)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        raise InvalidValueError(f"n (number of samples) must be an integer of at least 2, got {n!r}")
    check_count("n (number of samples)", int(n), MAX_SAMPLES, "samples")
    resp = simulate(loop, step=0.0, disturbance=LoadStep(size, 0.0), t_end=t_end)
    t = np.linspace(0.0, t_end, n)
    y = np.abs(np.asarray(resp.altitude(t)))
    peak = float(np.max(y))
    final = float(resp.altitude(t_end))
    above = np.flatnonzero(y > 0.1 * peak)
    rec = None if peak == 0 or abs(final) > 0.1 * peak or above[-1] == n - 1 else float(t[above[-1] + 1])
    return DisturbanceRecovery(size, peak, final, rec)


def minimum_settling_time(delay: float, step: float, umax: float, gain: float = 1.0, band: float = 0.02) -> float:
    """The physical bound on the settling time of an integrator ``K / s`` behind a delay with the command
    limited to ``umax``: nothing moves for one delay, then the output travels at most ``K umax`` until it
    enters the settling band, ``T + |step| (1 - band) / (K umax)``.

    Examples
    --------
    >>> round(minimum_settling_time(0.37, 1.0, 1.0), 4)
    1.35
    """
    return delay + abs(step) * (1.0 - band) / (abs(gain) * umax)


@dataclass(frozen=True, repr=False)
class CompensatorDesign:
    """A designed compensator with its nominal step metrics, disturbance recovery and robustness."""

    compensator: Compensator
    loop: Loop
    steps: dict[float, StepMetrics | None]
    delay_ratio_range: tuple[float, float]
    disturbance: DisturbanceRecovery
    bounds: dict[float, float] = field(default_factory=dict)
    horizon: float = 15.0
    """How long the steps were simulated (s; the load recovery at least 20 s)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: ``compensator``, ``params``, ``steps`` (by step size), ``delay_ratio_range``, ..."""
        return {
            "compensator": self.compensator.kind,
            "params": self.compensator.params(),
            "steps": {f"{k:g}" if k != int(k) else f"{k:.1f}": (m.to_dict() if m is not None else None)
                      for k, m in self.steps.items()},
            "delay_ratio_range": list(self.delay_ratio_range),
            "disturbance": self.disturbance.to_dict(),
            "minimum_settling_time": {f"{k:g}" if k != int(k) else f"{k:.1f}": v for k, v in self.bounds.items()},
            "horizon": self.horizon,
            "loop": self.loop.to_dict(),
        }

    def __repr__(self) -> str:
        lo, hi = self.delay_ratio_range
        st = ", ".join(f"{k:g} m: {m.settling_time:.3f} s" if m is not None and m.settling_time is not None
                       else f"{k:g} m: not settled" for k, m in self.steps.items())
        return f"CompensatorDesign({self.compensator.kind}, settling {st}, delay ratio {lo:.3f}..{hi:.3f})"


def design_horizon(plant: Any, delay: float, closed_loop_time: float, shortest: float = 15.0) -> float:
    """How long a compensator design's steps and load recovery are simulated (s): ``10 (Tm + Tc)`` for the
    reference's response (the compensated loop follows the model with its delay and speed ``Tc``), plus
    ``5 tau`` for the plant's slowest stable mode ``tau`` (a predictor rejects a load only as fast as the open
    plant lets it), and at least ``shortest``.  A heater's 150 s lag and 17 s delay need some 1,000 s; the
    paper's drone keeps ``shortest``.

    Examples
    --------
    >>> round(design_horizon("0.6976/(146.6*s+1)", 16.6, 10.0), 1), design_horizon("1/s", 0.37, 0.1)
    (999.0, 15.0)
    """
    g = TransferFunction.coerce(plant, name="plant")
    rates = [-p.real for p in np.atleast_1d(g.poles()) if p.real < 0]
    slow = 1.0 / float(min(rates)) if rates else 0.0
    return max(float(shortest), 10.0 * (float(delay) + float(closed_loop_time)) + 5.0 * slow)


def _steps(loop: Loop, sizes: Sequence[float], t_end: float) -> dict[float, StepMetrics | None]:
    try:
        items = [] if isinstance(sizes, (str, bytes)) else list(sizes)
    except TypeError:
        items = []
    if not items:
        raise InvalidTypeError(f"steps must be a non-empty list of step sizes, got {sizes!r:.60}")
    values = [check_real("step size", s) for s in items]
    return {s: simulate(loop, step=s, t_end=t_end).metrics for s in values}


def design_compensator(kind: str, plant: Any, delay: float, *, umin: float = -math.inf, umax: float = math.inf,
                       closed_loop_time: float | None = None, delay_uncertainty: float = 0.2,
                       steps: Sequence[float] = (0.2, 1.0), disturbance: float = 0.2, t_end: float | None = None,
                       **options: Any) -> CompensatorDesign:
    """A compensator of ``kind`` for the model ``plant`` with delay ``delay``, and what it achieves.

    Without ``closed_loop_time``, the design's speed ``Tc`` is the smallest (fastest) on a grid from
    ``Tm / 10`` to ``2 Tm`` whose delay-ratio range covers ``[1 - delay_uncertainty, 1 + delay_uncertainty]``,
    refined by bisection: a faster loop tolerates less delay error.  The step metrics are simulated exactly
    on the saturated loop.

    Parameters
    ----------
    kind : {"smith", "filtered-smith", "predictor"}
    plant : transfer function
        The delay-free model ``Gn`` (also the true plant of the nominal metrics).
    delay : float
        The model delay ``Tm`` (s).
    umin, umax : float
        The actuator's limits.
    closed_loop_time : float, optional
        ``Tc`` (s); chosen by the robustness rule when not given.
    delay_uncertainty : float
        The relative delay error the design must survive.
    steps : sequence of float
        Reference step sizes whose metrics are reported.
    disturbance : float
        Size of the load disturbance for :func:`disturbance_recovery`.
    t_end : float, optional
        How long the steps are simulated (s; the load recovery at least 20 s); by default
        :func:`design_horizon` of the plant, the delay and the design's ``Tc`` (a slow plant is simulated long
        enough to settle: a fixed 15 s was shorter than a heater's delay).
    **options
        Passed to the compensator's constructor (``filter_time``, ``integral_time``).

    Examples
    --------
    >>> d = design_compensator("filtered-smith", "1/s", 0.37, umin=-1, umax=1)
    >>> abs(d.disturbance.final_error) < 1e-6
    True

    See Also
    --------
    delaykit.models.compensators.Compensator : the three laws.

    References
    ----------
    J. E. Normey-Rico and E. F. Camacho, *Control of Dead-time Processes*, Springer (2007).
    """
    comp = tune_compensator(kind, plant, delay, closed_loop_time=closed_loop_time,
                            delay_uncertainty=delay_uncertainty, **options)
    g, tm = comp.model, comp.model_delay
    if t_end is None:
        t_end = design_horizon(g, tm, comp.closed_loop_time)
    t_end = check_real("t_end (s)", t_end, minimum=0.0, strict=True)
    loop = Loop(g, comp, delay=tm, umin=umin, umax=umax)
    metrics = _steps(loop, steps, t_end)
    rng = delay_ratio_range(comp, g)
    rec = disturbance_recovery(loop.replace(umin=-math.inf, umax=math.inf), disturbance, t_end=max(t_end, 20.0))
    bounds = {}
    if g.integrators == 1 and g.order == 1 and math.isfinite(umax) and math.isfinite(umin):
        k = float(g.num[-1] / g.den[0])
        bounds = {float(s): minimum_settling_time(tm, s, umax if s * k > 0 else -umin, k) for s in steps}
    return CompensatorDesign(comp, loop, metrics, rng, rec, bounds, horizon=float(t_end))


def tune_compensator(kind: str, plant: Any, delay: float, *, closed_loop_time: float | None = None,
                     delay_uncertainty: float = 0.2, **options: Any) -> Compensator:
    """The compensator of :func:`design_compensator` alone (its speed chosen by the same robustness rule).

    Examples
    --------
    >>> c = tune_compensator("smith", "1/s", 0.37)
    >>> 15 < c.primary.kp < 25
    True
    """
    if not isinstance(kind, str) or kind.lower().replace("_", "-") not in COMPENSATOR_KINDS:
        raise InvalidValueError(f"compensator must be one of {', '.join(COMPENSATOR_KINDS)}; got {kind!r}")
    tm = check_real("delay (model delay, s)", delay, minimum=0.0, strict=True)
    du = check_real("delay_uncertainty", delay_uncertainty, minimum=0.0, maximum=0.9)
    g = TransferFunction.coerce(plant, name="plant")

    def make(tc: float) -> Compensator:
        return Compensator.design(kind, g, tm, closed_loop_time=tc, **options)

    def covers(tc: float) -> bool:
        c = make(tc)
        try:
            if _abscissa(c, g, tm) >= 0:
                return False
            if du == 0:
                return True
            return _abscissa(c, g, (1 - du) * tm) < 0 and _abscissa(c, g, (1 + du) * tm) < 0 and \
                (lambda lh: lh[0] <= 1 - du and lh[1] >= 1 + du)(delay_ratio_range(c, g, ratio_max=1 + du + 0.05))
        except InvalidValueError:
            return False

    if closed_loop_time is None:
        grid = tm * np.geomspace(0.1, 2.0, 14)
        ok = next((i for i, tc in enumerate(grid) if covers(tc)), None)
        if ok is None:
            raise InvalidValueError(f"no {kind} design with Tc up to {grid[-1]:.3g} s survives a delay error of "
                                    f"{du:.0%}; give closed_loop_time or a smaller delay_uncertainty")
        tc = float(grid[ok])
        if ok > 0:
            fast = float(grid[ok - 1])
            for _ in range(12):
                mid = math.sqrt(fast * tc)
                if covers(mid):
                    tc = mid
                else:
                    fast = mid
    else:
        tc = check_real("closed_loop_time (Tc, s)", closed_loop_time, minimum=0.0, strict=True)
    return make(tc)


def compare_designs(loops: dict[str, Loop], *, steps: Sequence[float] = (0.2, 1.0), disturbance: float = 0.2,
                    t_end: float = 15.0) -> list[dict[str, Any]]:
    """Rows of a comparison table: for each named loop, the settling time of each step, the load-disturbance
    recovery and, for compensators, the delay-ratio range (for P and PV loops, the ratio range from the
    delay margin: stable for any delay below the critical one).

    Examples
    --------
    >>> rows = compare_designs({"P 1.31": Loop("1/s", Controller.p(1.31), delay=0.37, umin=-1, umax=1)})
    >>> round(rows[0]["delay_ratio_range"][1], 3)
    3.241
    """
    from ..spectrum.stability import delay_margin

    rows = []
    for name, loop in loops.items():
        m = _steps(loop, steps, t_end)
        rec = disturbance_recovery(loop.replace(umin=-math.inf, umax=math.inf), disturbance, t_end=max(t_end, 20.0))
        if isinstance(loop.controller, Compensator):
            rng = delay_ratio_range(loop.controller, loop.plant)
        else:
            dm = delay_margin(loop)
            rng = (0.0, dm.delay / loop.delay if loop.delay > 0 else math.inf)
        rows.append({"name": name, "settling": {s: (v.settling_time if v is not None else None) for s, v in m.items()},
                     "overshoot": {s: (v.overshoot if v is not None else None) for s, v in m.items()},
                     "disturbance": rec.to_dict(), "delay_ratio_range": list(rng)})
    return rows
