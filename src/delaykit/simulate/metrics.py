"""Step-response metrics, and the second-order relations the paper uses.

Definitions (continuous time, relative to the step time, for steps up and down alike; ``w`` is the response
normalised so that it starts at 0 and its final value is 1):

* overshoot: ``100 * max(0, max w - 1)`` percent of the step;
* peak time: the time of that maximum (``None`` for a response with no overshoot: an overshoot of at most
  :data:`OVERSHOOT_TOLERANCE`, which is rounding, or a monotone response's last digits);
* rise time: from the first crossing of ``w = 0.1`` to the first crossing of ``w = 0.9``;
* settling time: the last time ``|w - 1| >= band`` (2 % by default); ``None`` when the response is still
  outside the band at the end of the record ("never settles" within it);
* steady-state error: the reference minus the final altitude (metres).

For simulated responses (:mod:`delaykit.simulate.simulation`) these are computed exactly on the piecewise-polynomial
solution.  For sampled responses, :func:`step_metrics` interpolates crossings linearly between samples
and refines the peak with a quadratic least-squares fit around the highest sample; noisy samples are
handled by that local fit (``peak_window`` samples) and by an optional Savitzky-Golay smoother
(``smooth``), and the noise level is estimated and reported (``noise``) so that a settling time that noise
alone could move is recognisable: a band narrower than about three noise standard deviations cannot be
judged.

Examples
--------
>>> so = SecondOrder.from_step(overshoot=2.300, peak_time=3.055)
>>> so
SecondOrder(zeta=0.7684, omega_n=1.6069 rad/s, roots=-1.2348 ± 1.0283j)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..errors import InvalidValueError, check_finite_array, check_real

__all__ = ["StepMetrics", "SecondOrder", "step_metrics", "noise_level", "OVERSHOOT_TOLERANCE", "peak_time_of",
           "load_recovery"]

OVERSHOOT_TOLERANCE = 1e-3
"""Percent of the step: an overshoot up to this is no overshoot, and has no peak time (it prints as 0.000 %)."""


def load_recovery(with_load: "StepMetrics", load_time: float) -> float | None:
    """Seconds from a load step at ``load_time`` (after the reference step) until the response is back in the
    settling band for good: 0 when the load never pushes it out, ``None`` when it is still out at the end.

    ``with_load`` are the metrics of the run with the load, whose settling time is the last time outside the band
    over the whole run, the load's excursion included; the setpoint's own settling is that of the run without
    the load.  A response that has not settled from the step by ``load_time`` counts its remaining settling here.

    Examples
    --------
    >>> m = StepMetrics(overshoot=0.0, peak_time=None, rise_time=1.0, settling_time=62.5, steady_state_error=0.0,
    ...                 peak=1.0)
    >>> load_recovery(m, 50.0), load_recovery(m, 70.0)
    (12.5, 0.0)
    """
    if with_load.settling_time is None:
        return None
    return max(0.0, float(with_load.settling_time) - float(load_time))


def peak_time_of(overshoot: Any, peak_time: Any) -> Any:
    """The peak time where the overshoot (%) exceeds :data:`OVERSHOOT_TOLERANCE`; ``None`` (NaN in arrays) where not.

    Examples
    --------
    >>> peak_time_of(2.3, 1.5), peak_time_of(4e-4, 1.5)
    (1.5, None)
    >>> peak_time_of(np.array([2.3, 0.0]), np.array([1.5, 9.0])).tolist()
    [1.5, nan]
    """
    if np.ndim(overshoot) == 0:
        return peak_time if overshoot is not None and overshoot > OVERSHOOT_TOLERANCE else None
    return np.where(np.asarray(overshoot) > OVERSHOOT_TOLERANCE, peak_time, np.nan)


def _fmt(x: float | None, unit: str, digits: int = 4) -> str:
    return "None" if x is None else f"{x:.{digits}f}{unit}"


@dataclass(frozen=True, repr=False)
class StepMetrics:
    """Metrics of one step response.

    Attributes
    ----------
    overshoot : float
        Percent of the step.
    peak_time : float or None
        Seconds after the step; ``None`` when there is no overshoot (none above :data:`OVERSHOOT_TOLERANCE`).
    rise_time : float or None
        10 to 90 % rise time in seconds; ``None`` if the response never reaches 90 %.
    settling_time : float or None
        Seconds after the step; ``None`` if the response has not settled by the end.
    steady_state_error : float
        Reference minus final altitude, metres.
    peak : float
        The extreme altitude reached in the direction of the step, metres.
    band : float
        The settling band as a fraction of the step.
    noise : float or None
        Estimated standard deviation of the measurement noise (sampled responses only), metres.
    """

    overshoot: float
    peak_time: float | None
    rise_time: float | None
    settling_time: float | None
    steady_state_error: float
    peak: float
    band: float = 0.02
    noise: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "peak_time", peak_time_of(self.overshoot, self.peak_time))

    @property
    def settled(self) -> bool:
        """True if the response entered the band and stayed there until the end."""
        return self.settling_time is not None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``None`` for absent values)."""
        return {
            "overshoot": self.overshoot,
            "peak_time": self.peak_time,
            "rise_time": self.rise_time,
            "settling_time": self.settling_time,
            "steady_state_error": self.steady_state_error,
            "peak": self.peak,
            "band": self.band,
            "settled": self.settled,
            "noise": self.noise,
        }

    def __repr__(self) -> str:
        settle = _fmt(self.settling_time, " s") if self.settled else "not settled"
        return (
            f"StepMetrics(overshoot={self.overshoot:.4f} %, peak_time={_fmt(self.peak_time, ' s')}, "
            f"rise_time={_fmt(self.rise_time, ' s')}, settling_time={settle})"
        )


@dataclass(frozen=True, repr=False)
class SecondOrder:
    """A standard second-order response: damping ratio and natural frequency (paper eqs. 7-8).

    Examples
    --------
    >>> so = SecondOrder(zeta=0.5, omega_n=2.0)
    >>> round(so.overshoot, 4), round(so.peak_time, 4)
    (16.3034, 1.8138)
    >>> back = SecondOrder.from_step(so.overshoot, so.peak_time)
    >>> round(back.zeta, 12), round(back.omega_n, 12)
    (0.5, 2.0)
    """

    zeta: float
    omega_n: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "zeta", check_real("zeta (damping ratio)", self.zeta, minimum=0.0))
        if self.zeta >= 1.0:
            raise InvalidValueError(f"zeta must be below 1 for an oscillatory response, got {self.zeta:g}")
        object.__setattr__(self, "omega_n", check_real("omega_n", self.omega_n, minimum=0.0, strict=True))

    @classmethod
    def from_step(cls, overshoot: float, peak_time: float) -> "SecondOrder":
        """Damping and natural frequency from overshoot (percent) and peak time (s)."""
        mo = check_real("overshoot (%)", overshoot, minimum=0.0, strict=True)
        if mo >= 100.0:
            raise InvalidValueError(f"overshoot must be below 100 % for a damped response, got {mo:g}")
        tp = check_real("peak_time (s)", peak_time, minimum=0.0, strict=True)
        lg = math.log(mo / 100.0)
        zeta = -lg / math.sqrt(math.pi**2 + lg**2)
        return cls(zeta=zeta, omega_n=math.pi / (tp * math.sqrt(1.0 - zeta**2)))

    @classmethod
    def from_root(cls, root: complex) -> "SecondOrder":
        """The pair whose upper root is ``root`` (Re < 0, Im > 0)."""
        root = complex(root)
        if not (root.real < 0 and root.imag > 0):
            raise InvalidValueError(f"root must have Re < 0 and Im > 0 for a damped pair, got {root}")
        wn = abs(root)
        return cls(zeta=-root.real / wn, omega_n=wn)

    @property
    def root(self) -> complex:
        """The upper dominant root ``-zeta wn + j wn sqrt(1 - zeta^2)``."""
        return complex(-self.zeta * self.omega_n, self.omega_n * math.sqrt(1.0 - self.zeta**2))

    @property
    def overshoot(self) -> float:
        """Percent overshoot of the step response."""
        return 100.0 * math.exp(-self.zeta * math.pi / math.sqrt(1.0 - self.zeta**2))

    @property
    def peak_time(self) -> float:
        """Peak time, s."""
        return math.pi / (self.omega_n * math.sqrt(1.0 - self.zeta**2))

    @property
    def settling_time(self) -> float:
        """The 2 % settling-time estimate ``4 / (zeta wn)`` of the paper's eq. 8."""
        return 4.0 / (self.zeta * self.omega_n) if self.zeta > 0 else math.inf

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        r = self.root
        return {"zeta": self.zeta, "omega_n": self.omega_n, "root": [r.real, r.imag],
                "overshoot": self.overshoot, "peak_time": self.peak_time}

    def __repr__(self) -> str:
        r = self.root
        return f"SecondOrder(zeta={self.zeta:.4f}, omega_n={self.omega_n:.4f} rad/s, roots={r.real:.4f} ± {r.imag:.4f}j)"


def noise_level(z: np.ndarray) -> float:
    """Robust estimate of white measurement noise: the MAD of second differences.

    A smooth response has second differences near zero, so what is left is noise; for white noise of
    standard deviation sigma the second difference has standard deviation ``sqrt(6) sigma``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> t = np.linspace(0, 10, 2001)
    >>> round(noise_level(np.sin(t) + 0.01 * rng.standard_normal(t.size)), 2)
    0.01
    """
    z = check_finite_array("z", z)  # an inf or nan sample would give nan, or a level of 0 that hides it
    if z.size < 5:
        return 0.0
    d2 = np.diff(z, 2)
    return float(np.median(np.abs(d2 - np.median(d2))) / 0.6744897501960817 / math.sqrt(6.0))


def _validate(t: Any, z: Any) -> tuple[np.ndarray, np.ndarray]:
    try:
        t = np.asarray(t, dtype=float)
        z = np.asarray(z, dtype=float)
    except (TypeError, ValueError, OverflowError) as exc:  # (an integer of hundreds of digits: OverflowError)
        raise InvalidValueError(f"times and altitudes must be finite numbers: {exc}") from None
    if t.ndim != 1 or z.ndim != 1 or t.size != z.size:
        raise InvalidValueError(f"t and z must be 1-D of equal length, got shapes {t.shape} and {z.shape}")
    check_finite_array("t", t)
    check_finite_array("z", z)
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = bad[0] + 1
        raise InvalidValueError(f"time must increase: t[{i}] = {t[i]:g} follows t[{i - 1}] = {t[i - 1]:g}")
    return t, z


def _first_crossing(t: np.ndarray, w: np.ndarray, level: float) -> float | None:
    idx = np.flatnonzero(w >= level)
    if idx.size == 0:
        return None
    i = idx[0]
    if i == 0:
        return float(t[0])
    w0, w1 = w[i - 1], w[i]
    return float(t[i - 1] + (level - w0) / (w1 - w0) * (t[i] - t[i - 1]))


def step_metrics(
    t: Any,
    z: Any,
    *,
    step: float,
    z0: float | None = None,
    step_time: float = 0.0,
    band: float = 0.02,
    final: Literal["reference", "tail"] | float = "reference",
    peak_window: int = 3,
    smooth: int | None = None,
) -> StepMetrics:
    """Metrics of a sampled step response (measured or simulated on a grid).

    Parameters
    ----------
    t, z : array_like
        Sample times (s, increasing, irregular spacing allowed) and altitudes (m).
    step : float
        The step in the reference, metres (either sign, not zero).
    z0 : float, optional
        The altitude before the step; by default the mean of the samples at or before ``step_time``
        (the first sample if there are none).
    step_time : float
        When the reference stepped; times are reported from it.
    band : float
        Settling band as a fraction of the step.
    final : "reference", "tail" or float
        What the response settles to: the reference ``z0 + step`` (default, as for an integrating loop),
        the mean of the last 10 % of the samples, or a given altitude.
    peak_window : int
        Odd number of samples around the highest one fitted by a quadratic to refine the peak (3 =
        through the three samples; more averages noise).
    smooth : int, optional
        Odd window of a quadratic Savitzky-Golay smoother applied first, for noisy data.

    Returns
    -------
    StepMetrics

    Examples
    --------
    A sampled second-order response (python-control's ``step_info`` gives the same numbers to within a
    sample interval):

    >>> so = SecondOrder(zeta=0.5, omega_n=2.0)
    >>> t = np.linspace(0, 10, 2001)
    >>> wd = so.omega_n * np.sqrt(1 - so.zeta**2)
    >>> y = 1 - np.exp(-1.0 * t) * (np.cos(wd * t) + 1.0 / wd * np.sin(wd * t))
    >>> m = step_metrics(t, y, step=1.0)
    >>> round(m.overshoot, 3), round(m.peak_time, 3)
    (16.303, 1.814)
    """
    t, z = _validate(t, z)
    step = check_real("step", step)
    if step == 0.0:
        raise InvalidValueError("step must not be zero: the metrics are relative to its size")
    band = check_real("band", band, minimum=0.0, strict=True, maximum=1.0)
    step_time = check_real("step_time", step_time)
    after = t >= step_time
    if np.count_nonzero(after) < 3:
        raise InvalidValueError(f"need at least 3 samples at or after the step time {step_time:g} s, got {np.count_nonzero(after)}")
    noise = noise_level(z[after])
    if smooth is not None:
        from scipy.signal import savgol_filter

        if smooth < 3 or smooth % 2 == 0 or smooth > np.count_nonzero(after):
            raise InvalidValueError(f"smooth must be an odd window of at least 3 samples and at most the record, got {smooth}")
        z = z.copy()
        z[after] = savgol_filter(z[after], smooth, 2)
    if z0 is None:
        before = t <= step_time
        z0 = float(np.mean(z[before])) if np.any(before) else float(z[0])
    z0 = check_real("z0", z0)
    if final == "reference":
        zf = z0 + step
    elif final == "tail":
        za = z[after]
        zf = float(np.mean(za[-max(1, za.size // 10):]))
    else:
        zf = check_real("final", final)
    if zf == z0:
        raise InvalidValueError("the final value equals the initial one; there is no step to measure")
    ta = t[after] - step_time
    with np.errstate(over="ignore"):
        w = (z[after] - z0) / (zf - z0)
    if not np.all(np.isfinite(w)):  # a step of 1e-320: the response over it is beyond the floats
        raise InvalidValueError(f"the step from {z0:g} to {zf:g} is too small for the response to be measured "
                                "against it (the normalised response overflows)")

    i = int(np.argmax(w))
    wpeak, tpeak = float(w[i]), float(ta[i])
    if peak_window < 3 or peak_window % 2 == 0:
        raise InvalidValueError(f"peak_window must be an odd number of at least 3, got {peak_window}")
    h = peak_window // 2
    if h <= i < w.size - h:
        tt = ta[i - h:i + h + 1]
        c = np.polyfit(tt - ta[i], w[i - h:i + h + 1], 2)
        if c[0] < 0:
            tv = -c[1] / (2 * c[0])
            if tt[0] - ta[i] <= tv <= tt[-1] - ta[i]:
                wpeak = float(np.polyval(c, tv))
                tpeak = float(ta[i] + tv)
    overshoot = max(0.0, wpeak - 1.0) * 100.0
    peak_time = tpeak if wpeak > 1.0 else None

    t10 = _first_crossing(ta, w, 0.1)
    t90 = _first_crossing(ta, w, 0.9)
    rise = (t90 - t10) if (t10 is not None and t90 is not None) else None

    dev = np.abs(w - 1.0)
    out = np.flatnonzero(dev >= band)
    if out.size == 0:
        settling: float | None = 0.0
    elif out[-1] == w.size - 1:
        settling = None
    else:
        k = out[-1]
        level = 1.0 + band if w[k] > 1.0 else 1.0 - band
        settling = float(ta[k] + (level - w[k]) / (w[k + 1] - w[k]) * (ta[k + 1] - ta[k]))
    za = z[after]
    tail = float(np.mean(za[-max(1, za.size // 10):]))
    return StepMetrics(
        overshoot=overshoot,
        peak_time=peak_time,
        rise_time=rise,
        settling_time=settling,
        steady_state_error=float(z0 + step - tail),
        peak=float(z0 + wpeak * (zf - z0)),
        band=band,
        noise=noise,
    )
