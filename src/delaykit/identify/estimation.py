"""Estimating the loop delay from flights: the paper's two methods, a whole-trajectory fit, and pooling.

* ``overshoot`` (the paper's section 5.1.1): the delay at which the exact simulation's overshoot equals the
  measured one, by root-finding (not a grid).
* ``lambert`` (section 5.1.2): (Mo, tp) give a damping ratio and natural frequency, hence a dominant root;
  ``variant="paper"`` solves ``s = W(-Kp Td) / Td`` for Td by Newton's method from 0.2 s, as the paper's fsolve
  did, which lands on a *complex* delay (0.3743 - 0.2507j for the paper's numbers; the paper printed the real
  part); ``variant="damping"`` matches the damping ratio only, which has a real solution.
* ``trajectory`` (beyond the paper): least squares on the whole measured response with the exact loop model
  (saturation, controller period, the log's own sample times), optionally with the drone's effective gain and
  speed-loop lag free; the altitude offset is always fitted (profiled out, it is linear).  Standard error
  from the Fisher information, a profile-likelihood interval, and a model-adequacy check.
* several flights: one delay shared by all, with per-flight nuisance parameters, and the spread between
  flights.

Every estimator returns a :class:`DelayEstimate`.

Examples
--------
>>> est = estimate_overshoot(2.300, kp=1.31)
>>> est
DelayEstimate(delay=0.3686 s, method='overshoot', flights=1)
>>> estimate_lambert(2.300, 3.055, kp=1.31, variant="paper").delay_imag
-0.2507...
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np
from scipy import stats
from scipy.optimize import brentq, least_squares

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.altitude import AltitudeLoop
from ..models.loop import Loop
from ..simulate.metrics import SecondOrder, step_metrics
from ..simulate.simulation import Sampler, simulate
from ..spectrum.lambert import delay_for_damping, lambert_w
from .flightlog import FlightLog
from .noise import ljung_box
from .steps import split_steps

__all__ = ["DelayEstimate", "EstimateParams", "Diagnostics", "FlightFit", "EstimationError", "estimate_overshoot", "estimate_lambert", "estimate_trajectory",
           "estimate_flights", "fitted_altitude", "lambert_paper_iterations"]

FREE_CHOICES = ("gain", "lag")
LAG_FLOOR = 0.004


class EstimationError(InvalidValueError):
    """The method cannot estimate a delay from these data (the message says why)."""


class _Record:
    """Shared behaviour of the small result records: ``to_dict`` writes the fields that are set (not None), as
    the dicts they replace did.  Reading them as a mapping (``diag["spread"]``, ``"spread" in diag``,
    ``diag.get("spread")``, ``diag.keys()``, ``dict(diag)``) is kept, read-only, for older code; its keys are
    the dict's: the fields that are set.  Reading a field that is not set, or a name that is not a field,
    raises :class:`KeyError` (whose message lists the fields)."""

    def __getitem__(self, name: str) -> Any:
        if name not in self._present():
            names = [f.name for f in dataclasses.fields(self)]  # type: ignore[arg-type]
            if name in names:
                raise KeyError(f"{name!r} is not set in this {type(self).__name__} (the method does not "
                               f"compute it); the set fields are {', '.join(self._present()) or 'none'}")
            raise KeyError(f"{type(self).__name__} has no field {name!r}; the fields are {', '.join(names)}")
        return getattr(self, name)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self._present()

    def __iter__(self) -> Iterator[str]:
        return iter(self._present())

    def keys(self) -> list[str]:
        """The names of the fields that are set (the keys of the dict this record replaces)."""
        return self._present()

    def get(self, name: str, default: Any = None) -> Any:
        """The field ``name`` if it is set, else ``default`` (as ``dict.get``)."""
        return self[name] if name in self else default

    def _present(self) -> list[str]:
        return [f.name for f in dataclasses.fields(self)  # type: ignore[arg-type]
                if getattr(self, f.name) is not None or f.name in self._always()]

    def _always(self) -> tuple[str, ...]:
        """Fields written even when None."""
        return ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: the fields that are set."""
        return {k: _jsonable(getattr(self, k)) for k in self._present()}


@dataclass(frozen=True)
class EstimateParams(_Record):
    """Values an estimator fitted or used besides the delay; a field is None when the method has none.

    Attributes
    ----------
    kp : float or None
        The proportional gain the flights used (``overshoot``, ``lambert``).
    overshoot : float or None
        The measured overshoot, % (``overshoot``).
    variant : str or None
        ``"paper"`` or ``"damping"`` (``lambert``).
    offsets, scales : tuple of float or None
        Per flight: the altimeter's offset (m) and scale, profiled out of the fit (``trajectory``).
    gain, lag : tuple of float or None
        Per flight: the drone's effective speed gain and speed-loop lag (s), when fitted (``free``).
    """

    kp: float | None = None
    overshoot: float | None = None
    variant: str | None = None
    offsets: tuple[float, ...] | None = None
    scales: tuple[float, ...] | None = None
    gain: tuple[float, ...] | None = None
    lag: tuple[float, ...] | None = None


@dataclass(frozen=True)
class FlightFit:
    """One flight's part of a trajectory fit: its nuisance parameters and measured-vs-model checks."""

    file: str
    offset: float
    scale: float
    gain: float
    lag: float
    residual_rms: float
    measured_overshoot: float
    model_overshoot: float
    measured_peak_time: float | None
    model_peak_time: float | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (every field, None as null)."""
        return {f.name: _jsonable(getattr(self, f.name)) for f in dataclasses.fields(self)}


@dataclass(frozen=True)
class Diagnostics(_Record):
    """Checks of an estimate and its warnings; a field is None when the method does not compute it.

    Attributes
    ----------
    warnings : tuple of str
        Warnings from the model-adequacy checks (empty when none).
    note : str or None
        A remark on the checks (for example, residuals at the altitude resolution).
    slope_percent_per_second : float or None
        ``overshoot``: the slope of the overshoot in the delay, % per s.
    model_peak_time : float or None
        ``overshoot``: the model's peak time at the estimate (s); None, and still reported, when the model does
        not overshoot.
    measured_peak_time : float or None
        ``overshoot``: the measured peak time, when given.
    zeta, omega_n : float or None
        ``lambert``: the damping ratio and natural frequency from (Mo, tp).
    root : complex or None
        ``lambert``: the dominant root they give.
    iterations : tuple of complex or None
        ``lambert`` ``paper``: Newton's iterates for the complex delay.
    model_root : complex or None
        ``lambert`` ``damping``: the model's dominant root at the estimate.
    ljung_box_q, whiteness_p : float or None
        ``trajectory``: the Ljung-Box statistic of the residuals and its p-value.
    per_flight : tuple of FlightFit or None
        ``trajectory``: each flight's nuisance parameters and checks.
    nfev, samples : int or None
        ``trajectory``: function evaluations of the fit, and samples fitted.
    resolution, resolution_stderr : float or None
        ``trajectory``: the altitude rounding step (m) and the timing error it adds (s).
    stderr_inflation : float or None
        ``trajectory``: the Newey-West factor applied to the standard error.
    spread, per_flight_delays, heterogeneity_chi2, heterogeneity_p
        Pooled estimates: the standard deviation of the flights' delays (s), the delays, and the heterogeneity
        test.
    """

    warnings: tuple[str, ...] = ()
    note: str | None = None
    slope_percent_per_second: float | None = None
    model_peak_time: float | None = None
    measured_peak_time: float | None = None
    zeta: float | None = None
    omega_n: float | None = None
    root: complex | None = None
    iterations: tuple[complex, ...] | None = None
    model_root: complex | None = None
    ljung_box_q: float | None = None
    whiteness_p: float | None = None
    per_flight: tuple[FlightFit, ...] | None = None
    nfev: int | None = None
    samples: int | None = None
    resolution: float | None = None
    resolution_stderr: float | None = None
    stderr_inflation: float | None = None
    spread: float | None = None
    per_flight_delays: tuple[float, ...] | None = None
    heterogeneity_chi2: float | None = None
    heterogeneity_p: float | None = None

    def _always(self) -> tuple[str, ...]:
        # the overshoot method reports the model's peak time even when there is none (null)
        return ("model_peak_time",) if self.slope_percent_per_second is not None else ()


def _record(cls: type, value: Any, name: str) -> Any:
    """``value`` as a ``cls`` record: records pass, mappings (the former form) are converted."""
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(value) - names)
        if unknown:
            raise InvalidValueError(f"{name} has no field(s) {', '.join(map(repr, unknown))}; "
                                    f"the fields are {', '.join(sorted(names))}")
        kw = {k: tuple(v) if isinstance(v, (list, np.ndarray)) else v for k, v in value.items()}
        if kw.get("per_flight") is not None:
            kw["per_flight"] = tuple(x if isinstance(x, FlightFit) else FlightFit(**x) for x in kw["per_flight"])
        if isinstance(kw.get("warnings"), str):
            kw["warnings"] = (kw["warnings"],)
        return cls(**kw)
    raise InvalidTypeError(f"{name} must be a {cls.__name__}, got {type(value).__name__}")


@dataclass(frozen=True, repr=False)
class DelayEstimate:
    """A delay estimate.

    Attributes
    ----------
    delay : float
        Seconds.
    stderr : float or None
        Standard error (s), where the method gives one.
    ci : tuple or None
        95 % confidence interval (s).
    method : str
        ``overshoot``, ``lambert``, ``trajectory``.
    flights : int
        How many flights it rests on.
    delay_imag : float or None
        The imaginary part, for the ``lambert`` ``paper`` variant (whose delay is complex).
    residual_rms : float or None
        RMS of the fit residuals (m), for ``trajectory``.
    params : EstimateParams
        Other fitted values (gain, lag, offsets, ...).
    diagnostics : Diagnostics
        Checks of the fit and warnings (``diagnostics.warnings``).

    A mapping given for ``params`` or ``diagnostics`` is converted to its record.
    """

    delay: float
    stderr: float | None
    ci: tuple[float, float] | None
    method: str
    flights: int = 1
    delay_imag: float | None = None
    residual_rms: float | None = None
    params: EstimateParams = field(default_factory=EstimateParams)
    diagnostics: Diagnostics = field(default_factory=Diagnostics)

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", _record(EstimateParams, self.params, "params"))
        object.__setattr__(self, "diagnostics", _record(Diagnostics, self.diagnostics, "diagnostics"))

    @property
    def warnings(self) -> list[str]:
        """Warnings from the model-adequacy checks (empty when none)."""
        return list(self.diagnostics.warnings)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"delay": self.delay, "stderr": self.stderr, "ci": list(self.ci) if self.ci else None,
                "method": self.method, "flights": self.flights, "delay_imag": self.delay_imag,
                "residual_rms": self.residual_rms, "params": self.params.to_dict(),
                "diagnostics": self.diagnostics.to_dict()}

    def __repr__(self) -> str:
        err = f" ± {self.stderr:.4f}" if self.stderr is not None else ""
        im = f" {self.delay_imag:+.4f}j" if self.delay_imag is not None else ""
        return f"DelayEstimate(delay={self.delay:.4f}{im} s{err}, method={self.method!r}, flights={self.flights})"


def _jsonable(x: Any) -> Any:
    if isinstance(x, (FlightFit, _Record)):
        return x.to_dict()
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, complex):
        return [x.real, x.imag]
    return x


# ----------------------------------------------------------------------------------------------------------
# the paper's numerical method


_LOOP_KEYWORDS = {"kv": 0.0, "vmax": 1.0, "period": None, "velocity": "true", "filter_wn": 38.0, "filter_zeta": 1.0}


def _base_loop(kp: Any, **keywords: Any) -> AltitudeLoop:
    """The loop the flights used, with its delay at 0: from a loop object, or from ``kp`` and the keywords.

    A loop object (``Loop`` or ``AltitudeLoop``) must be of the paper's family (:meth:`AltitudeLoop.from_loop`
    says why not); its known ``gain`` and ``lag`` are the fit's fixed values where they are not ``free``.  The
    keywords then stay at their defaults: the loop gives them."""
    if isinstance(kp, (int, float, np.integer, np.floating)) and not isinstance(kp, bool):
        kp = check_real("kp", kp, minimum=0.0, strict=True)
        return AltitudeLoop(kp=kp, delay=0.0, **keywords)
    given = sorted(k for k, v in keywords.items() if v != _LOOP_KEYWORDS[k])
    if given:
        raise InvalidValueError(f"give the loop, or kp with {', '.join(given)}, not both: the loop object already "
                                "sets its controller, limits and period")
    base = AltitudeLoop.from_loop(kp)
    if base.kp <= 0.0:
        raise InvalidValueError(f"kp must be > 0 to estimate a delay from a closed loop; the loop has kp={base.kp:g}")
    return base.replace(delay=0.0)


def estimate_overshoot(
    overshoot: float,
    kp: float | Loop | AltitudeLoop,
    *,
    peak_time: float | None = None,
    overshoot_stderr: float | None = None,
    kv: float = 0.0,
    vmax: float | None = 1.0,
    period: float | None = None,
    step: float = 1.0,
) -> DelayEstimate:
    """The delay at which the exact loop's overshoot equals the measured one (paper, section 5.1.1).

    Parameters
    ----------
    overshoot : float
        Measured overshoot, percent (> 0).
    kp : float or Loop or AltitudeLoop
        The proportional gain the flights used (with ``kv``, ``vmax`` and ``period``), or the whole loop they
        used, of the paper's family (:meth:`~delaykit.models.altitude.AltitudeLoop.from_loop`); its delay is
        ignored.
    kv, vmax, period : float
        The rest of the loop, when ``kp`` is a number.
    peak_time : float, optional
        Measured peak time (s): compared with the model's at the estimate (a diagnostic, not fitted).
    overshoot_stderr : float, optional
        Standard error of the measured overshoot (percentage points); gives the delay's by the slope.
    step : float
        Step size (m) the flights used (the saturation makes it matter).

    Examples
    --------
    >>> round(estimate_overshoot(2.300, kp=1.31).delay, 4)
    0.3686
    """
    mo = check_real("overshoot (%)", overshoot, minimum=0.0)
    base = _base_loop(kp, kv=kv, vmax=vmax, period=period)
    kp = base.kp
    if mo == 0.0:
        raise EstimationError(
            "the measured overshoot is 0: the overshoot method needs an overshoot (for a P loop the delay is then "
            f"only known to be below about 1/(e Kp) = {1 / (math.e * kp):.3f} s); use the trajectory method"
        )
    f = lambda td: simulate(base.replace(delay=td), step).metrics.overshoot - mo  # noqa: E731
    lo = 0.0
    hi = 0.05 / kp
    while f(hi) < 0:
        lo = hi
        hi *= 1.5
        if hi > 20.0 / kp:
            raise EstimationError(f"no delay gives an overshoot of {mo:g} % for this loop")
    td = brentq(f, lo, hi, xtol=1e-12, rtol=1e-12)
    h = 1e-5
    slope = (f(td + h) - f(td - h)) / (2 * h)
    se = None if overshoot_stderr is None else check_real("overshoot_stderr", overshoot_stderr, minimum=0.0) / slope
    warnings: list[str] = []
    model = simulate(base.replace(delay=td), step).metrics
    tp = None
    if peak_time is not None:
        tp = check_real("peak_time", peak_time, minimum=0.0, strict=True)
        if model.peak_time is not None and abs(model.peak_time - tp) > 0.1 * tp:
            warnings.append(
                f"at this delay the model peaks at {model.peak_time:.4g} s but the flight peaked at {tp:.4g} s: "
                "the model does not explain the measured peak time (the drone's own speed loop adds lag; fit "
                "the trajectory with --free lag)"
            )
    ci = (td - 1.96 * se, td + 1.96 * se) if se is not None else None
    diag = Diagnostics(warnings=tuple(warnings), slope_percent_per_second=slope, model_peak_time=model.peak_time,
                       measured_peak_time=tp)
    return DelayEstimate(delay=td, stderr=se, ci=ci, method="overshoot", params=EstimateParams(kp=kp, overshoot=mo),
                         diagnostics=diag)


# ----------------------------------------------------------------------------------------------------------
# the paper's analytical method


def lambert_paper_iterations(root: complex, kp: float, start: float = 0.2, maxit: int = 50) -> list[complex]:
    """Newton's iterates for ``W_0(-Kp T) / T = root`` in complex T, from ``start`` (as the paper's fsolve).

    Examples
    --------
    >>> it = lambert_paper_iterations(complex(-1.2347, 1.0284), 1.31)
    >>> complex(np.round(it[-1], 4))
    (0.3743-0.2507j)
    """
    s = complex(root)
    T = complex(start)
    out = [T]
    for _ in range(maxit):
        w = complex(lambert_w(-kp * T, 0))
        F = w / T - s
        dw = w / (-kp * T * (1 + w)) * (-kp)  # dW/dT = W'(x) dx/dT, W'(x) = W / (x (1 + W))
        dF = dw / T - w / T**2
        step = F / dF
        T = T - step
        out.append(T)
        if abs(step) < 1e-14 * (1 + abs(T)):
            break
    return out


def estimate_lambert(overshoot: float, peak_time: float, kp: float | Loop | AltitudeLoop, *,
                     variant: str = "paper") -> DelayEstimate:
    """The paper's analytical estimate: (Mo, tp) -> damping and frequency -> dominant root -> delay.

    ``variant="paper"`` reproduces the paper (Newton on the complex Lambert W relation from 0.2 s); its
    result is complex, and ``delay`` is its real part with ``delay_imag`` the rest.  ``variant="damping"``
    finds the real delay whose dominant root has the measured damping ratio (the frequency is then not
    matched; the mismatch is reported).

    ``kp`` is the proportional gain, or the loop (a continuous P loop on ``1/s``, its limits ignored: the method
    models nothing else).

    Examples
    --------
    >>> round(estimate_lambert(2.300, 3.055, kp=1.31, variant="damping").delay, 4)
    0.3598
    """
    so = SecondOrder.from_step(overshoot, peak_time)
    base = _base_loop(kp)
    if base.kv != 0.0 or base.sampled or base.gain != 1.0 or base.lag != 0.0:
        raise InvalidValueError(f"the Lambert method models the continuous P loop on 1/s (linearised: the limits "
                                f"are ignored); got {base!r}: use estimate_overshoot or estimate_trajectory")
    kp = base.kp
    common = dict(zeta=so.zeta, omega_n=so.omega_n, root=so.root)
    if variant == "paper":
        it = lambert_paper_iterations(so.root, kp)
        T = it[-1]
        w = complex(lambert_w(-kp * T, 0)) / T if np.isfinite(T) and T != 0 else complex("nan")
        if not (np.isfinite(T) and abs(w - so.root) <= 1e-8 * abs(so.root)):
            raise EstimationError(
                f"the complex Newton iteration from 0.2 s did not converge for the root {so.root:.4f} "
                f"(last iterate {complex(T):.4g}); the paper's method has no answer here"
            )
        diag = Diagnostics(**common, iterations=tuple(complex(x) for x in it), warnings=(
            f"no real delay puts the dominant root at {so.root:.4f}; the solver converged to the complex delay "
            f"{T.real:.4f}{T.imag:+.4f}j, whose real part is reported (as the paper did)",
        ))
        return DelayEstimate(delay=T.real, stderr=None, ci=None, method="lambert", delay_imag=T.imag,
                             params=EstimateParams(variant="paper", kp=kp), diagnostics=diag)
    if variant == "damping":
        td = delay_for_damping(so.zeta, kp)
        w = complex(lambert_w(-kp * td, 0)) / td
        diag = Diagnostics(**common, model_root=complex(w.real, abs(w.imag)), warnings=(
            f"the damping ratio {so.zeta:.4f} is matched; the model's natural frequency is then {abs(w):.4f} rad/s, "
            f"the flight's {so.omega_n:.4f} rad/s",
        ))
        return DelayEstimate(delay=td, stderr=None, ci=None, method="lambert",
                             params=EstimateParams(variant="damping", kp=kp), diagnostics=diag)
    raise InvalidValueError(f"variant must be 'paper' or 'damping', got {variant!r}")


# ----------------------------------------------------------------------------------------------------------
# the whole-trajectory fit


class _Flight:
    """One log prepared for fitting: times relative to the step, and a sampler at those times."""

    def __init__(self, log: FlightLog, base: AltitudeLoop) -> None:
        self.log = log
        self.t = log.t - log.step_time
        self.z = log.z
        self.sampler = Sampler(self.t, t_end=max(float(self.t[-1]), 1e-3))
        loop = base
        if base.period is not None:
            # the controller runs at the log's samples: its first sample at or after the step
            after = self.t[self.t >= -1e-12]
            off = float(after[0]) if after.size else 0.0
            loop = base.replace(sample_offset=min(max(off, 0.0), base.period * (1 - 1e-9)))
        self.base = loop

    def model(self, delay: float, gain: float, lag: float) -> np.ndarray:
        return self.sampler(self.base.replace(delay=delay, gain=gain, lag=lag), self.log.step, self.log.z0)


def _unpack(theta: np.ndarray, free: tuple[str, ...], nf: int, gain: float = 1.0,
            lag: float = 0.0) -> tuple[float, list[float], list[float]]:
    td = float(theta[0])
    gains = [gain] * nf
    lags = [lag] * nf
    k = 1
    if "gain" in free:
        gains = list(theta[k:k + nf])
        k += nf
    if "lag" in free:
        lags = list(theta[k:k + nf])
    return td, gains, lags


def _residuals(theta, flights, free, offsets_out=None):
    td, gains, lags = _unpack(theta, free, len(flights), flights[0].base.gain, flights[0].base.lag)
    res = []
    for i, f in enumerate(flights):
        m = f.model(td, gains[i], lags[i])
        # the altimeter's offset and scale about the start altitude, profiled out (they enter linearly):
        # z = z0 + offset + scale (m - z0); the scale also absorbs the separate rounding of the two plateaus
        x = m - f.log.z0
        y = f.z - f.log.z0
        xm, ym = float(np.mean(x)), float(np.mean(y))
        sxx = float(np.dot(x - xm, x - xm))
        scale = float(np.dot(x - xm, y - ym)) / sxx if sxx > 0 else 1.0
        off = ym - scale * xm
        if offsets_out is not None:
            offsets_out.append((off, scale))
        res.append(y - off - scale * x)
    return np.concatenate(res)


def _ljung_box(r: np.ndarray, lags: int = 10) -> tuple[float, float]:
    """Ljung-Box ``(Q, p)`` over ``lags`` lags (:func:`.noise.ljung_box`); no test (0, 1) on a series too short
    for that many lags."""
    if np.size(r) <= lags + 1:
        return 0.0, 1.0
    return ljung_box(r, lags)


def estimate_trajectory(
    logs: FlightLog | Sequence[FlightLog],
    kp: float | Loop | AltitudeLoop,
    *,
    kv: float = 0.0,
    vmax: float | None = 1.0,
    period: float | None = None,
    velocity: str = "true",
    filter_wn: float = 38.0,
    filter_zeta: float = 1.0,
    free: Iterable[str] = (),
    delay_range: tuple[float, float] = (0.0, 1.5),
    interval: bool = True,
) -> DelayEstimate:
    """Least-squares fit of the exact loop to whole measured responses; one delay shared by all flights.

    Parameters
    ----------
    logs : FlightLog or sequence of FlightLog
        The flights (each with its own step, start altitude and sample times).
    kp : float or Loop or AltitudeLoop
        The proportional gain the flights used, or the whole loop they used, of the paper's family
        (:meth:`~delaykit.models.altitude.AltitudeLoop.from_loop`; its delay is ignored, and its ``gain`` and
        ``lag`` are held where they are not ``free``).
    kv, vmax, period, velocity, filter_wn, filter_zeta
        The rest of the controller, when ``kp`` is a number (``period``: the controller ran at the log's
        samples).
    free : iterable of {"gain", "lag"}
        Extra parameters fitted per flight: the drone's effective speed gain, and the time constant of its
        own speed loop (at least 4 ms: a shorter lag is indistinguishable from extra delay at navdata rates).
        The altimeter's offset and scale are always fitted per flight (profiled out: they enter linearly).
    delay_range : (float, float)
        Where to look for the delay (s).
    interval : bool
        Compute the profile-likelihood interval (costs a few more fits).

    Returns
    -------
    DelayEstimate
        ``stderr`` from the Fisher information (Gauss-Newton), widened by a Newey-West factor when the
        residuals are correlated in time, plus (in quadrature) the timing resolution of rounded altitudes,
        ``q / sqrt(12) / max|z'|``; ``ci`` the 95 % profile-likelihood interval (threshold widened by the same
        factor, ends by the same resolution).  A nuisance held at its bound (a lag at its floor) is left out of
        the Fisher information, and ``stderr`` is then at least the interval's width / (2 x 1.96): the likelihood
        is one-sided there, and the profile interval, which keeps the bounds, is the honest one.
        ``diagnostics`` with the residual whiteness test and
        measured-vs-model overshoot and peak time.

    Examples
    --------
    >>> from delaykit.simulate.simulation import simulate
    >>> t = np.arange(-1.0, 12.0, 0.065)
    >>> z = simulate(AltitudeLoop(kp=1.31, delay=0.368)).altitude(t)
    >>> log = FlightLog.from_arrays(t, np.round(z, 3), np.where(t >= 0, 1.0, 0.0), step_time=0.0)
    >>> round(estimate_trajectory(log, kp=1.31).delay, 3)
    0.368
    """
    logs = [logs] if isinstance(logs, FlightLog) else list(logs)
    if not logs:
        raise InvalidValueError("no flights given")
    free = tuple(free)
    for name in free:
        if name not in FREE_CHOICES:
            raise InvalidValueError(f"free parameters must be among {', '.join(FREE_CHOICES)}; got {name!r}")
    base = _base_loop(kp, kv=kv, vmax=vmax, period=period, velocity=velocity, filter_wn=filter_wn,
                      filter_zeta=filter_zeta)
    flights = [_Flight(log, base) for log in logs]
    nf = len(flights)
    lo, hi = delay_range
    # a coarse scan of the delay (nuisance at their defaults) avoids local minima
    grid = np.linspace(max(lo, 0.0), hi, 31)
    theta0 = [base.gain] * nf * ("gain" in free) + [max(base.lag, 0.05)] * nf * ("lag" in free)
    costs = [float(np.sum(_residuals(np.array([g, *theta0]), flights, free) ** 2)) for g in grid]
    j = int(np.argmin(costs))
    td0 = float(grid[j])
    # start at the parabola through the scan's three lowest neighbours, inside the range: started on a bound
    # (a delay shorter than the scan's step has its lowest cost at 0), the fit would stay there
    k = min(max(j, 1), grid.size - 2)
    c0, c1, c2 = costs[k - 1], costs[k], costs[k + 1]
    curv = c0 - 2.0 * c1 + c2
    if curv > 0.0:
        step = grid[1] - grid[0]
        td0 = float(grid[k] + 0.5 * step * (c0 - c2) / curv)
    td0 = min(max(td0, grid[0] + 1e-3 * (grid[1] - grid[0])), grid[-1] - 1e-3 * (grid[1] - grid[0]))
    x0 = np.array([td0, *theta0])
    # a lag below a few milliseconds cannot be told from the same extra delay at navdata rates, and would need
    # pieces as short as itself in the exact solver: 4 ms is its floor
    lb = [lo] + [0.2] * nf * ("gain" in free) + [LAG_FLOOR] * nf * ("lag" in free)
    ub = [hi] + [3.0] * nf * ("gain" in free) + [2.0] * nf * ("lag" in free)
    fit = least_squares(_residuals, x0, args=(flights, free), bounds=(lb, ub), x_scale="jac",
                        diff_step=1e-7, xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=400)
    theta = fit.x
    lin: list[tuple[float, float]] = []
    r = _residuals(theta, flights, free, lin)
    offsets = [o for o, _ in lin]
    scales = [c for _, c in lin]
    n, p = r.size, theta.size + 2 * nf  # offsets and scales count as parameters
    rss = float(np.dot(r, r))
    sigma2 = rss / max(n - p, 1)
    # a nuisance held at its bound (a lag at its 4 ms floor) is not free: its column, nearly the delay's own (a
    # short lag looks like extra delay), would make the Fisher information all but singular and the error of the
    # delay absurd (seconds), though the profile interval below, which keeps the bounds, is a few ms wide
    held = np.asarray(fit.active_mask) != 0
    held[0] = False
    J = fit.jac[:, ~held]
    inflation = 1.0
    try:
        JtJ_inv = np.linalg.inv(J.T @ J)
        se_white = float(math.sqrt(max(JtJ_inv[0, 0] * sigma2, 0.0)))
        # Newey-West (Bartlett) sandwich: residuals that are correlated in time (a flat response rounded to
        # millimetres, or a model that misses some dynamics) carry less information than white ones
        L = int(min(max(4, round(4 * (n / 100.0) ** (2 / 9))), n // 4))
        G = J * r[:, None]
        S = G.T @ G
        for k in range(1, L + 1):
            w = 1.0 - k / (L + 1.0)
            C = G[k:].T @ G[:-k]
            S += w * (C + C.T)
        cov_hac = JtJ_inv @ S @ JtJ_inv * (n / max(n - p, 1))
        se_hac = float(math.sqrt(max(cov_hac[0, 0], 0.0)))
        inflation = max(1.0, se_hac / se_white) if se_white > 0 else 1.0
        se = se_white * inflation
    except np.linalg.LinAlgError:
        se = None
    td, gains, lags = _unpack(theta, free, nf, base.gain, base.lag)

    ci = None
    if interval and se is not None and se > 0:
        thresh = rss + stats.chi2.ppf(0.95, 1) * sigma2 * inflation**2

        def profile(d: float) -> float:
            if len(theta) == 1:
                return float(np.sum(_residuals(np.array([d]), flights, free) ** 2)) - thresh
            sub = least_squares(lambda th: _residuals(np.array([d, *th]), flights, free), theta[1:],
                                bounds=(lb[1:], ub[1:]), x_scale="jac", diff_step=1e-7, max_nfev=100)
            return float(2 * sub.cost) - thresh

        ends = []
        for sign in (-1.0, 1.0):
            step_ = 2.0 * se
            a, b = td, td + sign * step_
            for _ in range(12):
                if not (lo <= b <= hi):
                    b = min(max(b, lo), hi)
                    break
                if profile(b) > 0:
                    break
                a, b = b, b + sign * step_
                step_ *= 2.0
            try:
                ends.append(brentq(profile, min(a, b), max(a, b), xtol=1e-9) if profile(b) > 0 else b)
            except ValueError:
                ends.append(b)
        ci = (min(ends), max(ends))

    if ci is not None and se is not None and held[1:].any():
        # with a nuisance at its bound the likelihood is one-sided (the lag can grow as the delay shrinks, not
        # shrink): the Fisher error of the restricted fit understates the interval; the error reported is then
        # the one a normal interval as wide as the profile interval would have, so that "delay +- stderr" and
        # the interval agree
        se = max(se, (ci[1] - ci[0]) / (2.0 * 1.96))
    if ci is not None and se is not None and se > 2.0 * (ci[1] - ci[0]) / (2.0 * 1.96):
        # the Fisher error more than twice what the profile interval spans: the quadratic approximation has failed
        # (a nuisance just off its bound, nearly collinear with the delay, as a lag a fraction of a millisecond
        # above its floor); the interval is the honest answer, and the error reported is its normal equivalent
        se = (ci[1] - ci[0]) / (2.0 * 1.96)

    # rounded altitudes carry a timing resolution of their own: one rounding step takes q / |z'| seconds
    # at the response's fastest; that uniform error (std q / sqrt(12) / max|z'|) is added in quadrature
    zs_all = np.unique(np.concatenate([f.z for f in flights]))
    quantum = float(np.min(np.diff(zs_all))) if zs_all.size > 1 else 0.0
    vpeak = max(float(np.max(np.abs(np.diff(f.z)) / np.diff(f.t))) for f in flights)
    floor = quantum / math.sqrt(12.0) / vpeak / math.sqrt(nf) if quantum > 0 and vpeak > 0 else 0.0
    if se is not None and floor > 0:
        se = math.sqrt(se**2 + floor**2)
        if ci is not None:
            ci = (td - math.hypot(td - ci[0], 1.96 * floor), td + math.hypot(ci[1] - td, 1.96 * floor))

    # model adequacy
    q, pval = _ljung_box(r)
    warnings: list[str] = []
    per_flight = []
    start = 0
    for i, f in enumerate(flights):
        seg = r[start:start + f.z.size]
        start += f.z.size
        meas = step_metrics(f.log.t, f.log.z, step=f.log.step, z0=f.log.z0 + offsets[i], step_time=f.log.step_time)
        mod = simulate(f.base.replace(delay=td, gain=gains[i], lag=lags[i]), f.log.step,
                       t_end=float(f.t[-1])).metrics
        item = FlightFit(file=f.log.name, offset=float(offsets[i]), scale=float(scales[i]), gain=float(gains[i]),
                         lag=float(lags[i]),
                         residual_rms=float(np.sqrt(np.mean(seg**2))), measured_overshoot=meas.overshoot,
                         model_overshoot=mod.overshoot, measured_peak_time=meas.peak_time,
                         model_peak_time=mod.peak_time)
        per_flight.append(item)
        tol_t = 0.1 * (mod.peak_time or 1.0) + 2 * float(np.median(np.diff(f.log.t)))
        if (meas.peak_time is not None and mod.peak_time is not None and abs(meas.peak_time - mod.peak_time) > tol_t):
            warnings.append(f"{f.log.name}: the fitted model peaks at {mod.peak_time:.3f} s, the flight at "
                            f"{meas.peak_time:.3f} s")
    rms = float(math.sqrt(rss / n))
    at_quantum = quantum > 0 and rms <= 0.6 * quantum
    if pval < 0.01 and not at_quantum:
        warnings.append(
            f"the residuals are not white (Ljung-Box p = {pval:.2g}): the model does not explain the data fully"
            + ("" if "lag" in free else "; try freeing the lag of the drone's speed loop")
        )
    note = (f"the residuals are at the altitude resolution ({quantum:g} m): their whiteness is not judged"
            if at_quantum else None)
    diag = Diagnostics(ljung_box_q=q, whiteness_p=pval, per_flight=tuple(per_flight), warnings=tuple(warnings),
                       nfev=int(fit.nfev), samples=int(n), resolution=quantum, resolution_stderr=floor,
                       stderr_inflation=inflation, note=note)
    params = EstimateParams(offsets=tuple(map(float, offsets)), scales=tuple(map(float, scales)),
                            gain=tuple(map(float, gains)) if "gain" in free else None,
                            lag=tuple(map(float, lags)) if "lag" in free else None)
    return DelayEstimate(delay=td, stderr=se, ci=ci, method="trajectory", flights=nf,
                         residual_rms=float(math.sqrt(rss / n)), params=params, diagnostics=diag)


def estimate_flights(logs: Sequence[FlightLog], kp: float | Loop | AltitudeLoop, *, steps: str = "all",
                     **kwargs: Any) -> tuple[DelayEstimate, list[DelayEstimate]]:
    """Each flight's delay, and the pooled delay of all of them, with the spread between flights.

    With ``steps="all"`` (the default) a log whose reference holds several steps is first cut into one log per
    step (:func:`~.steps.split_steps`), and each step counts as a flight: fitting such a log as one step would
    take the net change of its reference for the step and its largest excursion for the peak.
    ``steps="first"`` fits each log as it is, one step from its reference's first change.

    The pooled fit shares the delay and keeps per-flight nuisance parameters (offset, scale, and the free
    gain or lag).  If the flights disagree more than their standard errors allow (a chi-squared
    heterogeneity test, p < 0.05) the delay itself varies between flights; the pooled standard error and
    interval are then widened by ``sqrt(chi2 / dof)`` and a warning says so.

    Parameters
    ----------
    logs : sequence of FlightLog
        The flights.
    kp : float or Loop or AltitudeLoop
        The proportional gain the flights used, or the whole loop (see :func:`estimate_trajectory`).
    steps : {"all", "first"}
        Cut each log into its reference's steps, or fit it as one step.
    **kwargs
        The other arguments of :func:`estimate_trajectory`.

    Returns
    -------
    (pooled, per_flight)
        ``per_flight`` has one estimate per flight, or per step with ``steps="all"`` (in the logs' order).

    Examples
    --------
    >>> from delaykit.identify.flightlog import synthetic_log
    >>> rng = np.random.default_rng(0)
    >>> logs = [synthetic_log(AltitudeLoop(kp=1.31, delay=0.37), 1.0, noise=0.003, rng=rng) for _ in range(3)]
    >>> pooled, each = estimate_flights(logs, kp=1.31)
    >>> pooled.flights, len(each), abs(pooled.delay - 0.37) < 0.003
    (3, 3, True)
    """
    logs = [logs] if isinstance(logs, FlightLog) else list(logs)
    if not logs:
        raise InvalidValueError("no flights given")
    if steps == "all":
        logs = [piece for log in logs for piece in split_steps(log)]
    elif steps != "first":
        raise InvalidValueError(f"steps must be 'all' or 'first', got {steps!r}")
    each = [estimate_trajectory(log, kp, **kwargs) for log in logs]
    if len(logs) == 1:
        return each[0], each
    pooled = estimate_trajectory(logs, kp, **kwargs)
    d = np.array([e.delay for e in each])
    se = np.array([e.stderr or np.nan for e in each])
    warnings = list(pooled.diagnostics.warnings)
    chi2 = float(np.nansum(((d - pooled.delay) / se) ** 2))
    dof = len(d) - 1
    p_het = float(stats.chi2.sf(chi2, dof))
    spread = float(np.std(d, ddof=1))
    stderr, ci = pooled.stderr, pooled.ci
    if p_het < 0.05 and stderr is not None:
        k = math.sqrt(chi2 / dof)
        stderr = stderr * k
        if ci is not None:
            ci = (pooled.delay - k * (pooled.delay - ci[0]), pooled.delay + k * (ci[1] - pooled.delay))
        warnings.append(f"the flights disagree beyond their errors (heterogeneity p = {p_het:.2g}): the delay "
                        f"varies between flights (spread {1e3 * spread:.1f} ms); the pooled error is widened "
                        f"by {k:.2f}")
    diag = dataclasses.replace(pooled.diagnostics, warnings=tuple(warnings), spread=spread,
                               per_flight_delays=tuple(d.tolist()), heterogeneity_chi2=chi2, heterogeneity_p=p_het)
    pooled = DelayEstimate(delay=pooled.delay, stderr=stderr, ci=ci, method=pooled.method, flights=len(logs),
                           residual_rms=pooled.residual_rms, params=pooled.params, diagnostics=diag)
    return pooled, each


def fitted_altitude(log: FlightLog, est: DelayEstimate, kp: float | Loop | AltitudeLoop, index: int = 0,
                    **loop: Any) -> np.ndarray:
    """The fitted model's altitude at the log's sample times (for plots and checks).

    ``index`` picks the flight's nuisance parameters in a pooled estimate; ``kp`` and ``loop`` are what was
    given to the fit: the gain and the controller settings (``kv``, ``vmax``, ``period``, ...), or the loop.

    Examples
    --------
    >>> from delaykit.identify.flightlog import synthetic_log
    >>> lp = AltitudeLoop(kp=1.31, delay=0.3)
    >>> log = synthetic_log(lp, 1.0, noise=0.0)
    >>> est = estimate_trajectory(log, lp, interval=False)
    >>> float(np.max(np.abs(fitted_altitude(log, est, lp) - log.z))) < 1e-3
    True
    """
    base = _base_loop(kp, **loop)
    f = _Flight(log, base)
    if est.params.offsets is None or est.params.scales is None:
        raise InvalidValueError(f"the estimate is not a trajectory fit (method {est.method!r}): it has no fitted "
                                "offsets and scales")
    gains = est.params.gain if est.params.gain is not None else (base.gain,) * est.flights
    lags = est.params.lag if est.params.lag is not None else (base.lag,) * est.flights
    m = f.model(est.delay, gains[index], lags[index])
    off = est.params.offsets[index]
    scale = est.params.scales[index]
    return log.z0 + off + scale * (m - log.z0)
