"""Watching the delay during a flight: the estimate after each step, the alarm, and gain scheduling.

After each step of a flight, :class:`DelayMonitor` re-estimates the loop delay from that step's packets with
:func:`~delaykit.identify.online.estimate_window` (a fit of the integrator model to the altitude from the commands
actually sent, whatever the controller), and compares its 95 % interval with the range of delays the controller
was designed for:

* the **design range** is the delay error the law was designed to survive: ``Tm (1 ± u)`` for a compensator
  designed for the model delay ``Tm`` with the delay uncertainty ``u`` (20 % by default, as
  :func:`~delaykit.design.compensators.tune_compensator` designs), ``Td (1 ± u)`` for a plain controller
  designed for the delay ``Td`` (``design_delay``), or a range given by hand;
* the **stable range** (reported beside it) is where the loop is stable at all, exactly: the compensator's
  :func:`~delaykit.design.compensators.delay_ratio_range` times ``Tm``, or from 0 to the critical delay of a plain
  controller's loop on the model plant (:func:`~delaykit.spectrum.frequency.margins`); it is the design range
  of a plain controller given no design delay;
* the **alarm** goes off when the whole interval lies outside the range: the data then say the delay has left it
  (a point estimate outside the range with an interval that still reaches into it is reported, not alarmed: at
  the edge a 95 % interval wrongly alarms at most one step in forty);
* **gain scheduling** (``schedule=True``) re-designs the controller for the new estimate when the alarm goes off:
  a compensator is re-tuned for the estimated delay (:func:`~delaykit.design.compensators.tune_compensator`,
  same kind, model and uncertainty), and a P law keeps ``Kp T`` (the normalised gain of the integrator with a
  delay, which alone fixes its damping) at its designed value.  Other laws are not scheduled (it says so).

Examples
--------
>>> from delaykit.models import Controller
>>> mon = DelayMonitor(Controller.p(1.31), design_delay=0.25)
>>> mon.design_range, [round(x, 3) for x in mon.stable_range]
((0.2, 0.3), [0.0, 1.199])
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..design.compensators import delay_ratio_range, tune_compensator
from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..identify.online import WindowEstimate, estimate_window
from ..models.compensators import Compensator
from ..models.controllers import Controller
from ..models.loop import Loop
from ..models.transfer import TransferFunction
from ..spectrum.frequency import margins

__all__ = ["OnlineEstimate", "DelayMonitor", "stable_range"]


def stable_range(controller: Controller | Compensator, plant: Any = "1/s", delay: float = 0.0) -> tuple[float, float]:
    """The range of loop delays (s) for which a controller's loop on ``plant`` is stable.

    Parameters
    ----------
    controller : Controller or Compensator
        The law.  A compensator's range is its stable delay-ratio range times its model delay (its own model is
        the plant).
    plant : str or TransferFunction
        The plant of a plain controller (default the paper's integrator).
    delay : float
        The delay a plain controller was designed for (only used to check that its loop is stable there).

    Returns
    -------
    (float, float)
        The lowest and highest stable delays.

    Examples
    --------
    >>> from delaykit.models import Compensator
    >>> lo, hi = stable_range(Compensator.smith("1/s", 0.25, closed_loop_time=0.0625))
    >>> round(lo, 3), round(hi, 3)
    (0.156, 0.343)
    """
    if isinstance(controller, Compensator):
        lo, hi = delay_ratio_range(controller)
        return lo * controller.model_delay, hi * controller.model_delay
    if not isinstance(controller, Controller):
        raise InvalidTypeError(f"expected a Controller or a Compensator, got {type(controller).__name__}")
    d = check_real("delay (s)", delay, minimum=0.0)
    m = margins(Loop(TransferFunction.coerce(plant, name="plant"), controller, delay=d))
    if not m.stable:
        raise InvalidValueError(f"the loop of {controller!r} on {plant} is unstable at the delay {d:g} s")
    return 0.0, float(m.critical_delay)


@dataclass(frozen=True, repr=False)
class OnlineEstimate:
    """One step's delay estimate and what the monitor made of it.

    Attributes
    ----------
    step : int
        The step (from 1).
    time : float
        When the estimate was made (s since the flight's steps began).
    estimate : WindowEstimate
        The delay, its standard error and interval.
    design_range : (float, float)
        The range the controller flying that step was designed for.
    stable_range : (float, float)
        Where that controller's loop is stable.
    alarm : bool
        The whole interval lies outside ``design_range``.
    action : str
        ``"none"``, ``"redesigned"`` (the next steps fly the new law), or why scheduling did nothing.
    controller : dict or None
        The new law (``to_dict``) after a re-design.
    """

    step: int
    time: float
    estimate: WindowEstimate
    design_range: tuple[float, float]
    stable_range: tuple[float, float]
    alarm: bool
    action: str = "none"
    controller: dict[str, Any] | None = None

    @property
    def delay(self) -> float:
        """The estimated delay (s)."""
        return self.estimate.delay

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"step": self.step, "time": self.time, "estimate": self.estimate.to_dict(), "delay": self.delay,
                "ci": list(self.estimate.ci), "design_range": list(self.design_range),
                "stable_range": [x if math.isfinite(x) else None for x in self.stable_range], "alarm": self.alarm,
                "action": self.action, "controller": self.controller}

    def __repr__(self) -> str:
        lo, hi = self.estimate.ci
        flag = "ALARM" if self.alarm else "ok"
        return (f"OnlineEstimate(step {self.step}: delay {self.delay:.4f} s [{lo:.4f}, {hi:.4f}], design "
                f"[{self.design_range[0]:.3f}, {self.design_range[1]:.3f}] s, {flag}, {self.action})")


class DelayMonitor:
    """Re-estimate the delay after each step, raise the alarm, and optionally re-design (module docstring).

    Parameters
    ----------
    controller : Controller or Compensator
        The law the flight starts with.
    design_delay : float, optional
        The delay a plain controller was designed for (a compensator's is its model delay).
    design_range : (float, float), optional
        The range by hand (default: the design delay ± ``delay_uncertainty``, or the stable range of a plain
        controller without a design delay).
    plant : str or TransferFunction
        The model plant of a plain controller (default ``"1/s"``).
    lag : float
        The speed lag assumed by the estimator (s); 0: the estimated delay absorbs the vehicle's lag, as the
        integrator model with a delay that the compensators use does.
    schedule : bool
        Re-design when the alarm goes off.
    delay_uncertainty : float
        The relative delay error the law was designed for (and a re-tuned compensator must survive).
    delay_range : (float, float)
        Where the estimator looks (s).

    Examples
    --------
    >>> from delaykit.models import Compensator
    >>> mon = DelayMonitor(Compensator.smith("1/s", 0.25, closed_loop_time=0.0625), schedule=True)
    >>> mon.controller.model_delay
    0.25
    """

    def __init__(self, controller: Controller | Compensator, *, design_delay: float | None = None,
                 design_range: tuple[float, float] | None = None, plant: Any = "1/s", lag: float = 0.0,
                 schedule: bool = False, delay_uncertainty: float = 0.2,
                 delay_range: tuple[float, float] = (0.0, 1.5)) -> None:
        if not isinstance(controller, (Controller, Compensator)):
            raise InvalidTypeError(f"expected a Controller or a Compensator, got {type(controller).__name__}")
        self.plant = TransferFunction.coerce(plant, name="plant")
        self.lag = check_real("lag (s)", lag, minimum=0.0)
        self.schedule = bool(schedule)
        self.delay_uncertainty = check_real("delay_uncertainty", delay_uncertainty, minimum=0.0, maximum=0.9)
        self.delay_range = (float(delay_range[0]), float(delay_range[1]))
        if isinstance(controller, Compensator):
            self.design_delay = controller.model_delay
        else:
            self.design_delay = check_real("design_delay (s)", 0.0 if design_delay is None else design_delay,
                                           minimum=0.0)
        self._fixed = None if design_range is None else self._check_range(design_range)
        self.controller = controller
        self.stable_range = stable_range(controller, self.plant, self.design_delay)
        self.design_range = self._fixed or self._band(self.design_delay) or self.stable_range
        self.history: list[OnlineEstimate] = []

    def _band(self, delay: float) -> tuple[float, float] | None:
        if delay <= 0:
            return None
        return delay * (1 - self.delay_uncertainty), delay * (1 + self.delay_uncertainty)

    @staticmethod
    def _check_range(r: Sequence[float]) -> tuple[float, float]:
        if len(r) != 2:
            raise InvalidValueError(f"design_range must be (lowest, highest) delay, got {r!r}")
        lo = check_real("design_range low (s)", r[0], minimum=0.0)
        hi = check_real("design_range high (s)", r[1], minimum=0.0)
        if not lo < hi:
            raise InvalidValueError(f"design_range must have low < high, got {lo:g} and {hi:g}")
        return lo, hi

    def check(self, step: int, time: float, t: Any, z: Any, send_times: Any, u: Any, *, t_from: float,
              t_to: float | None = None) -> OnlineEstimate:
        """Estimate the delay on one step's window, judge it, and (with scheduling) re-design.

        Parameters
        ----------
        step : int
            The step's number (from 1).
        time : float
            The time of the check (s since the steps began), for the record.
        t, z, send_times, u
            The flight's packets and commands so far (see :func:`~delaykit.identify.online.estimate_window`).
        t_from, t_to : float
            The step's window.

        Returns
        -------
        OnlineEstimate
            Also appended to :attr:`history`; after a re-design :attr:`controller` and :attr:`design_range` are
            the new ones.
        """
        est = estimate_window(np.asarray(t, float), np.asarray(z, float), np.asarray(send_times, float),
                              np.asarray(u, float), t_from=t_from, t_to=t_to, lag=self.lag,
                              delay_range=self.delay_range)
        lo, hi = est.ci
        rng, stable = self.design_range, self.stable_range
        alarm = hi < rng[0] or lo > rng[1]
        action, new = "none", None
        if alarm and self.schedule:
            action, new = self._redesign(est.delay)
        rec = OnlineEstimate(step=int(step), time=float(time), estimate=est, design_range=rng,
                             stable_range=stable, alarm=alarm, action=action,
                             controller=None if new is None else new.to_dict())
        self.history.append(rec)
        return rec

    def _redesign(self, delay: float) -> tuple[str, Controller | Compensator | None]:
        c = self.controller
        if delay <= 0:
            return "not re-designed: the estimated delay is 0", None
        try:
            if isinstance(c, Compensator):
                new: Controller | Compensator = tune_compensator(c.kind, c.model, delay,
                                                                 delay_uncertainty=self.delay_uncertainty)
            elif c.kind == "p" and self.design_delay > 0:
                new = Controller.p(c.kp * self.design_delay / delay)
            else:
                return f"not re-designed: scheduling supports P laws and compensators, not {c.kind}", None
            stable = stable_range(new, self.plant, delay)
        except InvalidValueError as exc:  # no design for this delay: keep flying the old law, and say why
            return f"not re-designed: {exc}", None
        if self._fixed is not None:
            # a range given by hand moves with the design: the same ratios around the new delay
            base = self.design_delay if self.design_delay > 0 else delay
            rng = (self._fixed[0] * delay / base, self._fixed[1] * delay / base)
        else:
            rng = self._band(delay) or stable
        self.controller, self.design_range, self.stable_range, self.design_delay = new, rng, stable, delay
        return "redesigned", new
