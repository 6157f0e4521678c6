"""Relay feedback (Astrom and Hagglund's autotuner) on a plant with a dead time, solved exactly offline.

Under the relay ``u = +d`` when ``e = r - y > eps``, ``-d`` when ``e < -eps`` (held in between: hysteresis
``eps``), a stable or integrating plant settles into a symmetric limit cycle of half-period ``h``.  Its exact form
follows from the plant's state space ``x' = A x + B v``, ``y = C x`` with the delayed relay output
``v(t) = u(t - θ)``: starting at a switch to ``+d`` (``y = -eps``, falling), the half-period's input is piecewise
constant, so ``x(h) = e^{Ah} x0 + F(h)`` in closed form (matrix exponentials), and symmetry ``x(h) = -x0`` gives
``x0 = -(I + e^{Ah})^{-1} F(h)``.  The half-period solves ``C x0(h) = -eps`` (root-bracketed on a grid, the
smallest above ``θ`` whose output stays between the switching levels until ``h``).  No describing function and no simulation.

The classic describing-function estimate of the ultimate point, ``Ku ~ 4 d / (pi a)`` (``a`` the output's
amplitude) and ``Pu ~ 2 h``, ignores the cycle's harmonics: for an integrator with a delay the cycle is a triangle
of period exactly ``4θ`` = ``Pu`` and amplitude ``K d θ``, so the estimate ``4 / (pi K θ)`` is 19 % below the exact
``Ku = pi / (2 K θ)``.  :func:`relay_cycle` reports both and the model's exact ultimate point
(:func:`~delaykit.design.pid_rules.ultimate_point`), and the model's gain at the cycle's own frequency.

Examples
--------
>>> c = relay_cycle("1/s", 0.37, amplitude=1.0)
>>> round(c.period, 12), round(c.output_amplitude, 12)       # 4 θ and K d θ
(1.48, 0.37)
>>> round(c.ku_describing / c.ultimate.ku, 4)               # (4/pi) / (pi/2) = 8 / pi^2
0.8106
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidValueError, check_real
from ..models.hold import hold_matrices
from ..models.transfer import TransferFunction
from .pid_rules import UltimatePoint, ultimate_point

__all__ = ["RelayCycle", "relay_cycle"]


@dataclass(frozen=True, repr=False)
class RelayCycle:
    """The exact relay limit cycle: ``period`` (s, ``2 h``), the output's amplitude (half its peak-to-peak), the
    describing-function estimates ``ku_describing`` and ``pu_describing`` (= ``period``), the model's gain margin at
    the cycle's frequency ``ku_at_period`` (``1/|P(j 2 pi/period)|``), and the model's exact ``ultimate`` point."""

    amplitude: float
    hysteresis: float
    period: float
    output_amplitude: float
    ku_describing: float
    ku_at_period: float
    ultimate: UltimatePoint | None

    @property
    def pu_describing(self) -> float:
        """The describing-function estimate of the ultimate period: the cycle's period."""
        return self.period

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"amplitude": self.amplitude, "hysteresis": self.hysteresis, "period": self.period,
                "output_amplitude": self.output_amplitude, "ku_describing": self.ku_describing,
                "pu_describing": self.pu_describing, "ku_at_period": self.ku_at_period,
                "ultimate": None if self.ultimate is None else self.ultimate.to_dict()}

    def __repr__(self) -> str:
        ex = "" if self.ultimate is None else f"; exact ku {self.ultimate.ku:.4g}, pu {self.ultimate.pu:.4g} s"
        return (f"RelayCycle(period {self.period:.4g} s, output amplitude {self.output_amplitude:.4g}: "
                f"describing ku {self.ku_describing:.4g}{ex})")


def _switch(theta: float, h: float, d: float) -> tuple[float, float]:
    """``(t_break, v0)``: the first switch of the plant's input ``v(t) = u(t - θ)`` in ``[0, h)`` (``h``: none) and
    its value before it, for the cycle that switches ``u`` to ``+d`` at ``t = 0`` (``u`` = ``+d`` on ``[0, h)``,
    ``-d`` on ``[h, 2h)``, periodic)."""
    ph = (-theta) % (2 * h)  # where t = 0 falls in u's period
    return ((h - ph) % h if ph % h else h), (d if ph < h else -d)


def _start_state(A: np.ndarray, B: np.ndarray, d: float, theta: float, h: float) -> np.ndarray:
    """The state ``x0`` at the switch to ``+d`` of the symmetric cycle of half-period ``h``."""
    t_break, v0 = _switch(theta, h, d)
    E1, G1 = hold_matrices(A, B, t_break)
    forced = G1 * v0
    if t_break < h:
        E2, G2 = hold_matrices(A, B, h - t_break)
        forced = E2 @ forced + G2 * (-v0)
        Eh = E2 @ E1
    else:
        Eh = E1
    return -np.linalg.solve(np.eye(A.shape[0]) + Eh, forced)


def relay_cycle(plant: Any, delay: float, amplitude: float = 1.0, hysteresis: float = 0.0, *,
                h_max: float | None = None) -> RelayCycle:
    """The exact symmetric limit cycle of relay feedback around a plant with a dead time (module docstring).

    Parameters
    ----------
    plant : TransferFunction or str
        A stable or integrating plant with positive gain, strictly proper.
    delay : float
        Its dead time (s).
    amplitude : float
        The relay's amplitude ``d`` (> 0).
    hysteresis : float
        The hysteresis ``eps`` (>= 0) in the output's units.
    h_max : float, optional
        The longest half-period searched (default 50 times the delay plus the plant's largest time constant).

    Raises
    ------
    InvalidValueError
        Bad values, or no stable limit cycle in the range searched (periodic solutions the relay does not settle
        into, by their multipliers, are passed over).

    References
    ----------
    .. [1] K. J. Astrom and T. Hagglund, "Automatic tuning of simple regulators with specifications on phase and
       amplitude margins", *Automatica* 20 (1984) 645-651.
    .. [2] Ya. Z. Tsypkin, *Relay Control Systems*, Cambridge University Press, 1984 (the exact periodic solution).
    .. [3] K. J. Astrom, "Oscillations in systems with relay feedback", in *Adaptive Control, Filtering, and Signal
       Processing*, IMA Vol. Math. Appl. 74, Springer, 1995, 1-25 (the cycle's stability from its multipliers).

    Examples
    --------
    >>> c = relay_cycle("1/(s+1)", 1.0)
    >>> abs(c.period - 2 * (1 + math.log(2 - math.exp(-1)))) < 1e-12   # FOPDT: h = θ + τ ln(2 - e^{-θ/τ})
    True
    """
    tf = TransferFunction.coerce(plant, name="plant")
    theta = check_real("delay (s)", delay, minimum=0.0)
    d = check_real("amplitude (relay)", amplitude, minimum=0.0, strict=True)
    eps = check_real("hysteresis", hysteresis, minimum=0.0)
    if not tf.is_strictly_proper:
        raise InvalidValueError("relay analysis needs a strictly proper plant (no direct feedthrough)")
    A, B, C, _ = tf.state_space()
    A = np.atleast_2d(np.asarray(A, float))
    B = np.asarray(B, float).ravel()
    C = np.asarray(C, float).ravel()
    taus = [1.0 / abs(p.real) for p in tf.poles() if p.real < -1e-12]
    scale = theta + (max(taus) if taus else 0.0) + 1e-3
    if h_max is None and not scale < 1e300:  # (50 times it would overflow)
        raise InvalidValueError(f"the relay's time scale (delay {theta:g} s plus the slowest lag) is beyond what the "
                                "scan of half-periods can cover: give a shorter delay")
    hi = 50.0 * scale if h_max is None else check_real("h_max (s)", h_max, minimum=0.0, strict=True)
    if hi <= theta:
        raise InvalidValueError(f"h_max (s) must exceed the delay {theta:g} s (a relay's half-period is longer than "
                                f"its loop's delay), got {hi:g}")
    # the relay's own cycle has h > θ: after a switch the output keeps its course for a delay before it turns
    # (shorter roots are the delay's high-frequency cycles, which the relay does not settle into)
    hs = np.geomspace(theta * (1 + 1e-9) if theta > 0 else 1e-4 * scale, hi, 120)

    def f(h: float) -> float:
        return float(C @ _start_state(A, B, d, theta, h)) + eps

    vals = np.array([f(h) for h in hs])
    from scipy.optimize import brentq

    for i in np.flatnonzero(np.sign(vals[:-1]) * np.sign(vals[1:]) < 0):
        h = brentq(f, hs[i], hs[i + 1], xtol=1e-14, rtol=1e-15)
        y = _output_over(A, B, C, d, theta, h)
        # no earlier switch (the cycle is consistent), and the relay settles into it (an unstable periodic
        # solution, as the tiny fast ones of a high-order lag, is not the cycle an experiment shows)
        if np.all(y[1:-1] < eps + 1e-12 * max(1.0, abs(eps))) and _multiplier(A, B, C, d, theta, h) < 1.0:
            a = _amplitude(A, B, C, d, theta, h, y)  # the other half-period is -y
            try:
                ult = ultimate_point(tf, theta)
            except InvalidValueError:
                ult = None
            w = math.pi / h
            mag = abs(complex(tf(1j * w)))
            return RelayCycle(d, eps, 2 * h, a, 4 * d / (math.pi * a), 1.0 / mag, ult)
    raise InvalidValueError(f"no stable relay limit cycle with half-period below {hi:g} s for this plant and delay")


def _multiplier(A: np.ndarray, B: np.ndarray, C: np.ndarray, d: float, theta: float, h: float) -> float:
    """The largest modulus of the cycle's multipliers: the eigenvalues of the half-period's switch-to-switch map's
    Jacobian ``W = (I - xdot C / (C xdot)) e^{A h}`` (``xdot`` at the switch; Astrom 1995, valid for ``h > θ``,
    where the delay line holds only the latest switch).  Below 1: the relay settles into the cycle."""
    x0 = _start_state(A, B, d, theta, h)
    t_break, v0 = _switch(theta, h, d)
    xdot = A @ (-x0) + B * (-v0 if t_break < h else v0)
    slope = float(C @ xdot)
    if slope == 0.0:
        return math.inf  # a tangent crossing: not a transversal switch
    E, _ = hold_matrices(A, B, h)
    W = (np.eye(A.shape[0]) - np.outer(xdot, C) / slope) @ E
    return float(np.max(np.abs(np.linalg.eigvals(W))))


def _output_over(A: np.ndarray, B: np.ndarray, C: np.ndarray, d: float, theta: float, h: float,
                 n: int = 400, times: np.ndarray | None = None) -> np.ndarray:
    """The output over one half-period of the cycle (at ``n + 1`` points and the input's switch, or at ``times``),
    from the start state (exact)."""
    x0 = _start_state(A, B, d, theta, h)
    t_break, v0 = _switch(theta, h, d)
    E, G = hold_matrices(A, B, t_break)
    xb = E @ x0 + G * v0
    if times is not None:
        out = np.empty(np.size(times))
        for k, t in enumerate(np.atleast_1d(times)):
            E, G = hold_matrices(A, B, t if t <= t_break else t - t_break)
            out[k] = C @ (E @ x0 + G * v0) if t <= t_break else C @ (E @ xb - G * v0)
        return out
    # n + 1 equal steps over [0, h] and the input's switch, stepped by one exponential per segment
    n1 = max(1, int(round(n * t_break / h))) if t_break > 0 else 0
    n2 = n - n1 if t_break < h else 0
    ys = [float(C @ x0)]
    for length, steps, x, v in ((t_break, n1, x0, v0), (h - t_break, n2, xb, -v0)):
        if steps:
            E, G = hold_matrices(A, B, length / steps)
            for _ in range(steps):
                x = E @ x + G * v
                ys.append(float(C @ x))
    return np.array(ys)


def _times_over(theta: float, h: float, n: int) -> np.ndarray:
    """The times of :func:`_output_over`'s ``n + 1`` points over the half-period (equal steps on each side of the
    input's switch)."""
    t_break, _ = _switch(theta, h, 1.0)
    n1 = max(1, int(round(n * t_break / h))) if t_break > 0 else 0
    if t_break < h:
        return np.concatenate([np.linspace(0.0, t_break, n1 + 1), np.linspace(t_break, h, n - n1 + 1)[1:]])
    return np.linspace(0.0, h, n + 1)


def _amplitude(A: np.ndarray, B: np.ndarray, C: np.ndarray, d: float, theta: float, h: float, y: np.ndarray) -> float:
    """The largest ``|y|`` over the half-period: the best of the samples (the input's switch among them), refined by
    a bounded scalar search between its neighbours."""
    from scipy.optimize import minimize_scalar

    ts = _times_over(theta, h, y.size - 1)
    i = int(np.argmax(np.abs(y)))
    best = float(abs(y[i]))
    lo, hi = ts[max(i - 1, 0)], ts[min(i + 1, ts.size - 1)]
    if hi > lo:
        r = minimize_scalar(lambda t: -abs(float(_output_over(A, B, C, d, theta, h, times=np.array([t]))[0])),
                            bounds=(lo, hi), method="bounded", options={"xatol": 1e-13 * max(h, 1.0)})
        best = max(best, -float(r.fun))
    return best
