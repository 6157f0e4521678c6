"""Relay autotuning in flight: a relay experiment, the ultimate point from its cycle, a rule, a step.

:func:`autotune` flies (with :func:`~delaykit.hardware.flight.fly`, so with its safety exits and its log flushed
line by line) a step of the reference under an Astrom-Hagglund :class:`~delaykit.hardware.laws.Relay`; reads the
settled limit cycle from the log (:func:`~delaykit.design.autotune.measure_cycle`, the first cycles left out);
finds the ultimate point exactly for the vehicle's form (:func:`~delaykit.design.autotune.relay_ultimate`,
``"1/s"`` by default: the altitude integrates the commanded speed), with the describing-function estimate alongside;
tunes a controller by a rule (:func:`~delaykit.design.pid.tune`: SIMC, AMIGO and IMC read the fitted model,
Ziegler-Nichols and Tyreus-Luyben its ultimate point); and flies a step with it (a second take-off).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from ..errors import InvalidValueError, check_real
from .flight import FlightPlan, FlightResult, fly
from .laws import Relay

__all__ = ["AutotuneResult", "Relay", "autotune"]


@dataclass(frozen=True, repr=False)
class AutotuneResult:
    """What :func:`autotune` found and flew: ``status`` is ``"ok"``, ``"relay flight incomplete"`` (nothing was
    found) or ``"step flight incomplete"``; ``found`` (a :class:`~delaykit.design.autotune.RelayUltimate`) and
    ``tuning`` (a :class:`~delaykit.design.pid.Tuning`) are None when the relay flight did not complete."""

    status: str
    relay_flight: FlightResult
    found: Any = None
    tuning: Any = None
    step_flight: FlightResult | None = None

    @property
    def ku(self) -> float | None:
        """The ultimate gain found (None without a cycle)."""
        return None if self.found is None else self.found.ku

    @property
    def pu(self) -> float | None:
        """The ultimate period found (s; None without a cycle)."""
        return None if self.found is None else self.found.pu

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"status": self.status, "ku": self.ku, "pu": self.pu,
                "found": None if self.found is None else self.found.to_dict(),
                "tuning": None if self.tuning is None else self.tuning.to_dict(),
                "relay_flight": self.relay_flight.to_dict(),
                "step_flight": None if self.step_flight is None else self.step_flight.to_dict()}

    def __repr__(self) -> str:
        if self.found is None:
            return f"AutotuneResult({self.status}: {self.relay_flight.reason})"
        return f"AutotuneResult({self.status}: ku={self.ku:.4g}, pu={self.pu:.4g} s)"


def autotune(relay: Relay, log: str | Path, *, shape: Any = "1/s", rule: str = "simc", controller: str = "pi",
             offset: float = 0.3, relay_duration: float = 12.0, skip: int = 2, step: float | None = 0.5,
             step_duration: float = 6.0, hover_time: float = 1.0, vmax: float = 1.0,
             antiwindup: str = "clamp", tau_c: float | None = None, fly_kw: dict[str, Any] | None = None,
             status: Callable[[str], None] | None = None) -> AutotuneResult:
    """Fly a relay experiment, find the ultimate point from its cycle, tune by a rule and fly a step with it.

    Parameters
    ----------
    relay : Relay
        The relay's amplitude (m/s, at most ``vmax``) and hysteresis (m).
    log : str or Path
        The relay flight's log; the step flight's is ``<stem>-step<suffix>`` beside it.
    shape : TransferFunction or str
        The vehicle's form up to gain and delay (:func:`~delaykit.design.autotune.relay_ultimate`).
    rule, controller, tau_c, antiwindup
        The tuning (:func:`~delaykit.design.pid.tune`) and the flown controller's anti-windup.
    offset : float
        The reference step under which the relay cycles (m above the hover).
    relay_duration, skip : float, int
        Seconds of relay flight, and the cycles left out at its start.
    step, step_duration : float or None, float
        The tuned controller's step (m; None: no second flight) and its duration (s).
    hover_time, vmax : float
        As in :class:`~delaykit.hardware.flight.FlightPlan`.
    fly_kw : dict, optional
        Passed to :func:`~delaykit.hardware.flight.fly` (host, ports, confirm, connect_timeout).
    status : callable, optional
        Called with a short message at each stage.

    Raises
    ------
    InvalidValueError
        A relay amplitude beyond ``vmax``, a bad shape, rule or controller (before anything flies), or a log
        without two whole cycles.

    References
    ----------
    .. [1] K. J. Astrom and T. Hagglund, "Automatic tuning of simple regulators with specifications on phase and
       amplitude margins", *Automatica* 20 (1984) 645-651.

    Examples
    --------
    >>> from delaykit.hardware.autotune import Relay, autotune
    >>> autotune(Relay(1.5), "relay.csv", vmax=1.0)      # checked before anything flies
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: relay amplitude 1.5 is beyond the actuator's limit vmax = 1 m/s
    """
    from ..design.autotune import measure_cycle, relay_ultimate
    from ..design.pid import tune
    from ..identify.flightlog import FlightLog

    check_real("vmax (m/s)", vmax, minimum=0.0, strict=True)
    if getattr(relay, "amplitude", 0.0) > vmax:  # (FlightPlan says it too; here before anything else is built)
        raise InvalidValueError(f"relay amplitude {relay.amplitude:g} is beyond the actuator's limit vmax = {vmax:g} m/s")
    # everything the analysis and the tuning will read, checked before anything flies
    from ..models.transfer import TransferFunction

    TransferFunction.coerce(shape, name="shape")
    if controller not in ("p", "pi", "pd", "pid"):
        raise InvalidValueError(f"controller must be p, pi, pd or pid; got {controller!r}")
    if tau_c is not None:
        check_real("tau_c (s)", tau_c, minimum=0.0, strict=True)
    # the rule must exist and apply to the form (its family does not depend on the gain and delay the flight will
    # find): tried on the form with a nominal delay, its warnings left for the real tuning
    import warnings

    from ..design.pid_rules import rule_gains

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rule_gains(rule, controller, shape, 0.3, tau_c=tau_c)
    if isinstance(skip, bool) or not isinstance(skip, int) or skip < 0:
        raise InvalidValueError(f"skip must be a whole number of cycles, at least 0; got {skip!r}")
    plan = FlightPlan(kp=0.0, controller=relay, vmax=vmax, steps=(offset,), step_duration=relay_duration,
                      hover_time=hover_time)
    if step is not None:
        check_real("step (m)", step)
        check_real("step duration (s)", step_duration, minimum=0.0, strict=True)
    say = status or (lambda _m: None)
    kw = dict(fly_kw or {})
    base = Path(log)
    res = fly(plan, base, status=say, **kw)
    if not res.completed:
        return AutotuneResult("relay flight incomplete", res)
    fl = FlightLog.from_csv(res.logs[0])
    on = fl.z_ref == fl.z_ref[-1]
    cycle = measure_cycle(fl.t[on], fl.z[on] - fl.z_ref[on], fl.u[on], skip=skip, hysteresis=relay.hysteresis)
    found = relay_ultimate(cycle, shape)
    say(repr(found))
    tuning = tune(found.plant, controller, delay=found.delay, rule=rule, tau_c=tau_c, umin=-vmax, umax=vmax,
                  antiwindup=antiwindup if controller in ("pi", "pid") else "none")
    if step is None:
        return AutotuneResult("ok", res, found, tuning)
    say(f"tuned by {tuning.how}: kp {tuning.kp:.4g}, ki {tuning.ki:.4g}, kd {tuning.kd:.4g}; flying a step")
    plan2 = FlightPlan(kp=0.0, controller=tuning.loop.controller, vmax=vmax, steps=(step,),
                       step_duration=step_duration, hover_time=hover_time)
    kw.pop("confirm", None)  # (the take-off was confirmed once)
    res2 = fly(plan2, base.with_name(f"{base.stem}-step{base.suffix}"), status=say, **kw)
    return AutotuneResult("ok" if res2.completed else "step flight incomplete", res, found, tuning, res2)
