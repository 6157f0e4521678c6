"""Relay autotuning: the ultimate point from a measured relay limit cycle.

A relay experiment (Astrom and Hagglund) logs the output ``y`` and the relay's command ``u = ±d``.
:func:`measure_cycle` reads the settled cycle from such a log: its period (between the switches to ``+d``), the
RMS of the output about its mean over whole cycles, and the half peak-to-peak amplitude.  :func:`relay_ultimate`
then finds the ultimate point *exactly* when the plant's form is known up to its gain and dead time,
``P(s) = K G(s) e^{-θs}`` with ``G`` given (``"1/s"`` for the integrator of the drone's altitude): the exact cycle of
:func:`~delaykit.design.relay.relay_cycle` is matched to the measured period and RMS (without hysteresis the period
fixes ``θ`` alone, a scalar root; with hysteresis ``θ`` and ``K`` are solved together), and the ultimate point of
the model so found is :func:`~delaykit.design.pid_rules.ultimate_point`'s exact one.  For the integrator the match
is in closed form: the cycle is a triangle of amplitude ``a = eps + K d θ`` and period ``4 a / (K d)``, and its RMS
is ``a / sqrt(3)``.

The RMS is used, not the peaks, because it is an average over every sample of the cycle: sampling at a packet rate
and measurement noise barely move it, while the largest sample of a rounded peak falls short of the peak.  The
classic describing-function estimate ``Ku ~ 4 d / (pi a)``, ``Pu ~`` the period (``a`` the peak amplitude) is
reported alongside, as such: it is 19 % low for an integrator with delay.

A relay acting on sampled measurements (navdata at 15 Hz) switches on the first sample after each crossing, on
average half a sample period late: the found ``θ`` includes that half period, as it should for a controller run at
the same rate (the hold's phase lag is ``ω T / 2``).

Examples
--------
>>> import numpy as np
>>> t = np.linspace(0.0, 6 * 1.48, 6 * 1480 + 1)           # the exact cycle of 1/s with θ = 0.37, d = 1
>>> ph = (t + 0.37) % 1.48                                  # the output's phase; the relay switches at y = 0
>>> y = np.where(ph < 0.74, -0.37 + ph, 1.11 - ph)           # triangle between -0.37 and 0.37
>>> u = np.where(t % 1.48 < 0.74, 1.0, -1.0)
>>> r = relay_ultimate(measure_cycle(t, y, u, skip=1), "1/s")
>>> round(r.delay, 4), round(r.gain, 3), round(r.pu, 4)
(0.37, 1.0, 1.48)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidValueError, check_finite_array, check_real
from ..models.transfer import TransferFunction
from .pid_rules import UltimatePoint, ultimate_point
from .relay import _output_over, _times_over, relay_cycle

__all__ = ["MeasuredCycle", "RelayUltimate", "measure_cycle", "relay_ultimate"]


@dataclass(frozen=True, repr=False)
class MeasuredCycle:
    """A relay limit cycle read from a log: the mean ``period`` (s) and the spread of single periods
    ``period_std``, the output's ``rms`` about its ``offset`` (its mean) over whole cycles, the mean half
    peak-to-peak ``peak_amplitude``, how many whole ``cycles``, and the relay's ``amplitude`` and ``hysteresis``."""

    period: float
    period_std: float
    rms: float
    offset: float
    peak_amplitude: float
    cycles: int
    amplitude: float
    hysteresis: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"period": self.period, "period_std": self.period_std, "rms": self.rms, "offset": self.offset,
                "peak_amplitude": self.peak_amplitude, "cycles": self.cycles, "amplitude": self.amplitude,
                "hysteresis": self.hysteresis}

    def __repr__(self) -> str:
        return (f"MeasuredCycle(period={self.period:.4g} s ± {self.period_std:.2g}, rms={self.rms:.4g}, "
                f"peak amplitude={self.peak_amplitude:.4g}, cycles={self.cycles})")


@dataclass(frozen=True, repr=False)
class RelayUltimate:
    """The ultimate point found from a relay cycle: ``ultimate`` (exact, of the fitted model ``gain * shape`` with
    ``delay``), the describing-function estimates ``ku_describing`` and ``pu_describing``, and the ``cycle``."""

    ultimate: UltimatePoint
    gain: float
    delay: float
    shape: str
    ku_describing: float
    pu_describing: float
    cycle: MeasuredCycle

    @property
    def ku(self) -> float:
        """The ultimate gain (exact for the fitted model)."""
        return self.ultimate.ku

    @property
    def pu(self) -> float:
        """The ultimate period (s, exact for the fitted model)."""
        return self.ultimate.pu

    @property
    def plant(self) -> TransferFunction:
        """The fitted plant ``gain * shape`` (without its delay)."""
        return TransferFunction.coerce(self.shape) * self.gain

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"ku": self.ku, "pu": self.pu, "gain": self.gain, "delay": self.delay, "shape": self.shape,
                "ku_describing": self.ku_describing, "pu_describing": self.pu_describing,
                "cycle": self.cycle.to_dict()}

    def __repr__(self) -> str:
        return (f"RelayUltimate(ku={self.ku:.5g}, pu={self.pu:.5g} s of {self.gain:.4g} * ({self.shape}), delay "
                f"{self.delay:.4g} s; describing function ku {self.ku_describing:.4g})")


def measure_cycle(t: Any, y: Any, u: Any, *, skip: int = 2, hysteresis: float = 0.0) -> MeasuredCycle:
    """The settled relay cycle in a log of the output ``y`` and the relay's command ``u`` at times ``t``.

    The cycles run between the switches of ``u`` to its positive value; the first ``skip`` of them (the approach
    to the cycle) are left out, and at least two whole cycles must remain.

    Parameters
    ----------
    t, y, u : array_like
        Increasing times (s), the output (relative to the reference, or not: the offset is removed) and the command.
    skip : int
        Cycles left out at the start.
    hysteresis : float
        The relay's hysteresis (recorded for :func:`relay_ultimate`).

    Raises
    ------
    InvalidValueError
        Arrays of different lengths, times that do not increase, a command that is not a symmetric relay, or
        fewer than two whole cycles.

    Examples
    --------
    >>> t = np.arange(0.0, 10.0, 0.01)
    >>> u = np.where(t % 2.0 < 1.0, 0.5, -0.5)
    >>> c = measure_cycle(t, np.sin(np.pi * t), u, skip=0)
    >>> round(c.period, 6), c.cycles, round(c.amplitude, 3)
    (2.0, 3, 0.5)
    """
    t, y, u = (check_finite_array(name, a).ravel() for name, a in (("t", t), ("y", y), ("u", u)))
    if not t.size == y.size == u.size:
        raise InvalidValueError(f"t, y and u must have one length, got {t.size}, {y.size} and {u.size}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
        raise InvalidValueError("t, y and u must be finite")
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise InvalidValueError("the times must increase")
    if isinstance(skip, bool) or not isinstance(skip, (int, np.integer)) or skip < 0:
        raise InvalidValueError(f"skip must be a whole number of cycles, at least 0; got {skip!r}")
    eps = check_real("hysteresis", hysteresis, minimum=0.0)
    d = float(np.max(u))
    if not d > 0 or not np.isclose(np.min(u), -d, rtol=1e-6):
        raise InvalidValueError(f"u must be a symmetric relay's command (±d), got values from {np.min(u):g} to {d:g}")
    up = np.flatnonzero((u[1:] > 0) & (u[:-1] <= 0)) + 1  # the samples where u switches to +d
    starts = t[up][skip:]
    if starts.size < 3:
        raise InvalidValueError(f"the log holds {max(starts.size - 1, 0)} whole relay cycles after the first {skip}; "
                                "at least 2 are needed (fly longer)")
    n = starts.size - 1
    i0, i1 = up[skip], up[skip + n]
    tt, yy = t[i0:i1 + 1], y[i0:i1 + 1]
    span = tt[-1] - tt[0]
    offset = float(np.trapezoid(yy, tt) / span)
    rms = float(math.sqrt(np.trapezoid((yy - offset) ** 2, tt) / span))
    peaks = [0.5 * (np.max(y[a:b + 1]) - np.min(y[a:b + 1])) for a, b in zip(up[skip:skip + n], up[skip + 1:skip + n + 1])]
    periods = np.diff(starts)
    return MeasuredCycle(float(span / n), float(np.std(periods)), rms, offset, float(np.mean(peaks)), int(n), d, eps)


def _rms_of(shape: TransferFunction, theta: float, d: float, eps: float) -> tuple[float, float]:
    """``(period, rms)`` of the exact relay cycle of ``shape`` with delay ``theta`` (unit gain)."""
    c = relay_cycle(shape, theta, d, eps)
    h = 0.5 * c.period
    A, B, C, _ = shape.state_space()
    A = np.atleast_2d(np.asarray(A, float))
    y = _output_over(A, np.asarray(B, float).ravel(), np.asarray(C, float).ravel(), d, theta, h, n=2000)
    ts = _times_over(theta, h, y.size - 1)
    return c.period, float(math.sqrt(np.trapezoid(y * y, ts) / h))


def relay_ultimate(cycle: MeasuredCycle, shape: Any = "1/s") -> RelayUltimate:
    """The ultimate point from a measured relay cycle, exact for a plant ``K * shape * exp(-θ s)`` (module docstring).

    Parameters
    ----------
    cycle : MeasuredCycle
        From :func:`measure_cycle`.
    shape : TransferFunction or str
        The plant's form up to its gain: ``"1/s"`` (an integrator: closed form), ``"1/(s*(0.05*s+1))"`` (an
        integrator behind a lag), ``"1/(s+1)"``...; strictly proper, with positive gain.

    Raises
    ------
    InvalidValueError
        When no gain and delay of this form give the measured cycle.

    References
    ----------
    .. [1] K. J. Astrom and T. Hagglund, "Automatic tuning of simple regulators with specifications on phase and
       amplitude margins", *Automatica* 20 (1984) 645-651.

    Examples
    --------
    >>> c = MeasuredCycle(1.48, 0.0, 0.37 / math.sqrt(3), 0.0, 0.37, 5, 1.0, 0.0)   # 1/s, θ 0.37, d 1
    >>> r = relay_ultimate(c, "1/(s*(0.05*s+1))")                                   # read with a lag
    >>> r.delay < 0.37 and r.pu == r.ultimate.pu
    True
    """
    if not isinstance(cycle, MeasuredCycle):
        raise InvalidValueError(f"cycle must be a MeasuredCycle (measure_cycle), got {type(cycle).__name__}")
    g = TransferFunction.coerce(shape, name="shape")
    P, rms, d, eps = cycle.period, cycle.rms, cycle.amplitude, cycle.hysteresis
    if not (P > 0 and rms > 0):
        raise InvalidValueError(f"the cycle needs a positive period and RMS, got {P:g} s and {rms:g}")
    # the integrator's closed form (a triangle): a = sqrt(3) rms, K = 4 a / (d P), θ = (a - eps) / (K d)
    a = math.sqrt(3.0) * rms
    k_int = 4.0 * a / (d * P)
    theta_int = max((a - eps) / (4.0 * a / P), 1e-9 * P) if a > eps else None
    name = g.to_string()
    if g == TransferFunction.coerce("1/s") and theta_int is not None:
        K, theta = k_int, theta_int
    elif eps == 0.0:
        from scipy.optimize import brentq

        def f(th: float) -> float:
            try:
                return relay_cycle(g, th, d, 0.0).period - P
            except InvalidValueError:
                return -P
        lo, hi = 1e-6 * P, 0.5 * P
        if not (f(lo) < 0 < f(hi)):
            raise InvalidValueError(f"no delay gives a relay cycle of period {P:g} s for the form {name}")
        theta = brentq(f, lo, hi, xtol=1e-12 * P)
        K = rms / _rms_of(g, theta, d, 0.0)[1]
    else:
        from scipy.optimize import least_squares

        def res(x: np.ndarray) -> np.ndarray:
            th, k = x[0], math.exp(x[1])
            try:
                p1, r1 = _rms_of(g, th, d, eps / k)
            except InvalidValueError:
                return np.array([1.0, 1.0])
            return np.array([p1 / P - 1.0, k * r1 / rms - 1.0])
        x0 = np.array([theta_int if theta_int is not None else 0.25 * P, math.log(max(k_int, 1e-12))])
        sol = least_squares(res, x0, bounds=([1e-6 * P, -50.0], [0.5 * P, 50.0]), xtol=1e-14, ftol=1e-14)
        if np.max(np.abs(sol.fun)) > 1e-8:
            raise InvalidValueError(f"no gain and delay of the form {name} give a relay cycle of period {P:g} s and "
                                    f"RMS {rms:g} with hysteresis {eps:g}")
        theta, K = float(sol.x[0]), math.exp(float(sol.x[1]))
    ult = ultimate_point(g * K, theta)
    return RelayUltimate(ult, float(K), float(theta), name, 4.0 * d / (math.pi * cycle.peak_amplitude), P, cycle)
