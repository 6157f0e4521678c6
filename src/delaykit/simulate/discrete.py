"""Exact sample-to-sample simulation of a plant driven by a held, delayed command.

When the command is held between samples (a zero-order hold: a logged actuator signal, or a sampled controller)
the plant's state at the next sample is an exact linear function of the state now and of the held commands that
reach the plant during the period.  With the period ``h`` and the delay ``T = m h + f`` (``0 <= f < h``), the plant
input during ``[t_k, t_k + f)`` is the command issued at ``t_{k-m-1}`` and during ``[t_k + f, t_{k+1})`` the one
issued at ``t_{k-m}``, so

    x[k+1] = Phi(h) x[k] + Phi(h - f) Gamma(f) u[k-m-1] + Gamma(h - f) u[k-m],

with ``Phi(t) = exp(A t)`` and ``Gamma(t) = int_0^t exp(A s) ds B``, both read off one matrix exponential of an
augmented matrix.  Nothing is approximated: this is the same trajectory the method of steps computes
(:func:`delaykit.simulate.simulation.simulate`), evaluated only at the samples, in microseconds.  Identification
uses it to fit plants and delays to logs.

Two drives are supported: an **open** loop, where the command sequence is given (a logged input), and a **closed**
loop with a static sampled law ``u = sat(kp (r - y) - kv y')`` (the paper's P and PV laws with the true velocity,
and the PX4 vehicle's outer loop), where the controller samples at the same instants as the log.  Both work in
deviation variables from rest: the state starts at zero and commands issued before the first sample are zero.

A log on a real clock (a logger that writes at 1.01 s instead of 1 s, or with jitter) has no one-period map:
:func:`held_response_at` steps the plant from event to event, the samples and the instants at which each held
command reaches the plant, with one exponential per stretch: exact on any increasing clock.

Examples
--------
>>> import numpy as np
>>> from delaykit.models.transfer import TransferFunction
>>> m = held_delay_model(TransferFunction.parse("1/(2*s+1)"), period=0.5, delay=0.75)
>>> y = held_response(m, np.ones(8)).y                 # a unit step held from t = 0, seen 0.75 s later
>>> bool(np.allclose(y[3:], 1 - np.exp(-(np.arange(3, 8) * 0.5 - 0.75) / 2)))
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass


import numpy as np

from .. import _native
from ..errors import InvalidValueError, check_real
from ..models.hold import hold_matrices, split_delay
from ..models.transfer import TransferFunction

__all__ = ["HeldDelayModel", "HeldResponse", "held_delay_model", "held_response", "closed_loop_response",
           "held_matrices_of", "held_response_at"]


STIFF = 1e6
"""Above this ``sum |A| h`` (a mode a million times faster than the period), :func:`held_matrices_of` leaves the
compiled series (whose rounding grows with the squarings: 1e-13 to 1e-11 below it, as SciPy's) for SciPy's."""


@dataclass(frozen=True, repr=False, eq=False)
class HeldDelayModel:
    """The exact one-period map of a plant whose held command arrives ``delay`` seconds late.

    ``x[k+1] = phi x[k] + g_early u[k-m-1] + g_late u[k-m]``; the output at a sample is ``c x + d u_now`` and its
    derivative ``ca x + cb u_now`` where ``u_now`` is the command acting at the sample instant.
    """

    phi: np.ndarray
    g_early: np.ndarray
    g_late: np.ndarray
    c: np.ndarray
    d: float
    ca: np.ndarray
    cb: float
    m: int
    fractional: bool
    period: float
    delay: float

    def __repr__(self) -> str:
        return (f"HeldDelayModel(order={self.phi.shape[0]}, period={self.period:g} s, delay={self.delay:g} s "
                f"= {self.m} periods + {self.delay - self.m * self.period:.4g} s)")


@dataclass(frozen=True, repr=False, eq=False)
class HeldResponse:
    """Output ``y``, its derivative ``dy`` and the commands ``u`` at the samples (deviation variables)."""

    y: np.ndarray
    dy: np.ndarray
    u: np.ndarray

    def __repr__(self) -> str:
        return f"HeldResponse({self.y.size} samples, y in [{self.y.min():.4g}, {self.y.max():.4g}])"


DK = _native.load("delaykit.simulate", "_discretekernel")
"""The compiled loops (``simulate/_discretekernel.py``): the extension built at install, else numba's copy."""

def _phi_gamma(A: np.ndarray, B: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    if A.shape[0] == 0:
        return np.zeros((0, 0)), np.zeros(0)
    return hold_matrices(np.asarray(A, dtype=float), np.asarray(B, dtype=float).ravel(), float(t))


def held_delay_model(plant: TransferFunction, period: float, delay: float = 0.0) -> HeldDelayModel:
    """The exact sample-to-sample map of ``plant`` driven by a command held for ``period`` and delayed by ``delay``.

    Parameters
    ----------
    plant : TransferFunction
        A proper plant.
    period : float
        The hold period ``h`` (s), > 0.
    delay : float
        The delay ``T`` (s), >= 0; need not be a multiple of the period.

    Returns
    -------
    HeldDelayModel

    Examples
    --------
    >>> held_delay_model(TransferFunction.parse("1/s"), period=0.02, delay=0.205)
    HeldDelayModel(order=1, period=0.02 s, delay=0.205 s = 10 periods + 0.005 s)
    """
    h = check_real("period (s)", period, minimum=0.0, strict=True)
    T = check_real("delay (s)", delay, minimum=0.0)
    if not isinstance(plant, TransferFunction):
        raise InvalidValueError(f"plant must be a TransferFunction, got {type(plant).__name__}")
    A, B, C, D = plant.state_space()
    m, f = split_delay(T, h)
    phi_h, gam_h = _phi_gamma(A, B, h)
    if f > 0.0:
        phi_r, gam_r = _phi_gamma(A, B, h - f)
        _, gam_f = _phi_gamma(A, B, f)
        g_early, g_late = phi_r @ gam_f, gam_r
    else:
        g_early, g_late = np.zeros_like(gam_h), gam_h
    return HeldDelayModel(phi=np.ascontiguousarray(phi_h), g_early=np.ascontiguousarray(g_early),
                          g_late=np.ascontiguousarray(g_late), c=np.ascontiguousarray(C, dtype=float), d=float(D),
                          ca=np.ascontiguousarray(C @ A if A.size else np.zeros(0)), cb=float(C @ B) if A.size else 0.0,
                          m=m, fractional=f > 0.0, period=h, delay=T)


def held_matrices_of(A: np.ndarray, B: np.ndarray, period: float, delay: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, bool]:
    """``(phi, g_early, g_late, m, fractional)`` of :class:`HeldDelayModel` for a realisation ``(A, B)`` given as
    arrays (no checks: the caller's realisation is proper and its period positive).  Identification calls this
    for every trial plant; matrices far from what the compiled exponential is meant for go to SciPy's.

    Examples
    --------
    >>> phi, ge, gl, m, frac = held_matrices_of(np.array([[0.0]]), np.array([2.0]), 0.1, 0.25)
    >>> phi.tolist(), ge.round(12).tolist(), gl.round(12).tolist(), m, frac
    ([[1.0]], [0.1], [0.1], 2, True)
    """
    m, f = split_delay(delay, period)
    if not np.abs(A).sum() * period <= STIFF:
        phi_h, gam_h = _phi_gamma(A, B, period)
        if f > 0.0:
            phi_r, gam_r = _phi_gamma(A, B, period - f)
            _, gam_f = _phi_gamma(A, B, f)
            return phi_h, phi_r @ gam_f, gam_r, m, True
        return phi_h, np.zeros_like(gam_h), gam_h, m, False
    phi, ge, gl = DK.held_arrays(A, B, float(period), float(f))
    return phi, ge, gl, m, f > 0.0


def _drive(name: str, values: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(values, dtype=float)
    if a.ndim != 1 or a.size == 0:
        raise InvalidValueError(f"{name} must be a non-empty 1-d array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InvalidValueError(f"{name} holds a non-finite value at sample {int(np.flatnonzero(~np.isfinite(a))[0])}")
    return a


def held_response(model: HeldDelayModel, u: np.ndarray) -> HeldResponse:
    """The plant's output at the samples when the command ``u[k]`` is held from sample ``k`` to ``k + 1``.

    Deviation variables from rest: the state is zero at the first sample and earlier commands are zero.

    Examples
    --------
    >>> m = held_delay_model(TransferFunction.parse("1/s"), period=0.1, delay=0.25)
    >>> held_response(m, np.ones(6)).y.round(6).tolist()         # a ramp that starts 0.25 s late
    [0.0, 0.0, 0.0, 0.05, 0.15, 0.25]
    """
    a = _drive("u (the held command)", u)
    y, dy, uu = DK.run(model.phi, model.g_early, model.g_late, model.c, model.d, model.ca, model.cb, model.m,
                     model.fractional, a, False, 0.0, 0.0, -math.inf, math.inf)
    return HeldResponse(y=y, dy=dy, u=uu)


def closed_loop_response(model: HeldDelayModel, r: np.ndarray, *, kp: float, kv: float = 0.0,
                         umin: float = -math.inf, umax: float = math.inf) -> HeldResponse:
    """The loop ``u[k] = sat(kp (r[k] - y[k]) - kv y'[k])`` sampled at every sample, the command held and delayed.

    ``r`` is the reference at the samples (deviation from the initial steady state, as are the limits).

    Examples
    --------
    >>> m = held_delay_model(TransferFunction.parse("1/s"), period=0.01, delay=0.0)
    >>> res = closed_loop_response(m, np.ones(400), kp=1.0)       # ~ 1 - exp(-t), sampled every 10 ms
    >>> round(float(res.y[100]), 3), round(1 - 0.99 ** 100, 3)
    (0.634, 0.634)
    """
    a = _drive("r (the reference)", r)
    kp = check_real("kp", kp)
    kv = check_real("kv", kv)
    lo = check_real("umin", umin, allow_neg_inf=True)
    hi = check_real("umax", umax, allow_inf=True)
    if not lo < hi:
        raise InvalidValueError(f"umin must be below umax; got {lo:g} and {hi:g}")
    if model.m == 0 and not model.fractional and (model.d != 0.0 or (kv != 0.0 and model.cb != 0.0)):
        raise InvalidValueError("a sampled loop without delay around a plant with a direct feedthrough (or a "
                                "velocity term on a plant whose velocity jumps) is an algebraic loop")
    y, dy, uu = DK.run(model.phi, model.g_early, model.g_late, model.c, model.d, model.ca, model.cb, model.m,
                     model.fractional, a, True, kp, kv, lo, hi)
    return HeldResponse(y=y, dy=dy, u=uu)


def held_response_at(plant: TransferFunction, t: np.ndarray, u: np.ndarray, delay: float = 0.0) -> HeldResponse:
    """The plant's output at the sample times ``t`` (any increasing clock) when ``u[k]`` is held from ``t[k]``
    to ``t[k + 1]`` and reaches the plant ``delay`` seconds later.

    Exact (one matrix exponential per stretch between a sample and a command's arrival); on a uniform clock it
    is :func:`held_response`.  Deviation variables from rest, as there: the state is zero at ``t[0]`` and
    earlier commands are zero.

    Parameters
    ----------
    plant : TransferFunction
        A proper plant.
    t : array_like
        Sample times (s), increasing.
    u : array_like
        The command issued at each sample, as long as ``t``.
    delay : float
        The delay (s), >= 0.

    Returns
    -------
    HeldResponse

    Examples
    --------
    >>> t = np.array([0.0, 0.4, 1.1, 1.5, 2.3])                   # a clock that is not uniform
    >>> r = held_response_at(TransferFunction.parse("1/s"), t, np.ones(5), delay=0.5)
    >>> r.y.round(12).tolist()                                     # a ramp from t = 0.5 s
    [0.0, 0.0, 0.6, 1.0, 1.8]
    """
    if not isinstance(plant, TransferFunction):
        raise InvalidValueError(f"plant must be a TransferFunction, got {type(plant).__name__}")
    tt = _drive("t (the sample times)", t)
    if tt.size > 1 and not np.all(np.diff(tt) > 0.0):
        i = int(np.flatnonzero(np.diff(tt) <= 0.0)[0])
        raise InvalidValueError(f"t (the sample times) must increase; t[{i + 1}] = {tt[i + 1]:g} s follows "
                                f"t[{i}] = {tt[i]:g} s")
    a = _drive("u (the held command)", u)
    if a.size != tt.size:
        raise InvalidValueError(f"u has {a.size} values for {tt.size} sample times")
    T = check_real("delay (s)", delay, minimum=0.0)
    A, B, C, D = plant.state_space()
    A = np.ascontiguousarray(np.atleast_2d(A), dtype=float).reshape(len(B), len(B))
    B = np.ascontiguousarray(B, dtype=float).ravel()
    C = np.ascontiguousarray(C, dtype=float).ravel()
    y, dy = np.empty(tt.size), np.empty(tt.size)
    tol = 1e-12 * max(abs(float(tt[-1])), T, 1.0)
    DK.run_at_into(A, B, C, float(D), np.ascontiguousarray(C @ A if A.size else np.zeros(0)),
                 float(C @ B) if A.size else 0.0, T, tol, tt, a, y, dy)
    return HeldResponse(y=y, dy=dy, u=a.copy())
