"""Tuning rules for P, PI, PD and PID control of a plant with a dead time.

A rule maps a few numbers of the plant to the controller's gains:

* **model rules** (SIMC, AMIGO, IMC/lambda) read a low-order model: first order plus dead time (FOPDT,
  ``k e^{-θs} / (τ1 s + 1)``), second order (SOPDT, ``k e^{-θs} / ((τ1 s + 1)(τ2 s + 1))``), integrating
  (``k' e^{-θs} / s``, with a lag ``τ2`` for PID) or double integrating (``k'' e^{-θs} / s^2``).  Any other plant
  with real stable poles is first reduced to one of these by Skogestad's half rule (:func:`reduce_model`), and
  the result says what was neglected;
* **ultimate-point rules** (Ziegler-Nichols, Tyreus-Luyben) read the ultimate gain ``Ku`` and period ``Pu`` of the
  plant under P control, computed here from the exact frequency response with the delay
  (:func:`ultimate_point`), not from a Padé approximation or a step-response fit.

:func:`rule_gains` applies a rule and returns the parallel-form gains ``kp``, ``ki = kp / Ti``, ``kd = kp Td``
(rules stated in series form, SIMC's PID, are converted).  Outside a rule's range of validity (each function's
docstring states it) a :class:`TuningWarning` is issued; a plant outside a rule's family (an unstable plant, complex
poles for a model rule, a double integrator under PI) is an :class:`~delaykit.errors.InvalidValueError`.

Examples
--------
>>> from delaykit.models.plants import first_order
>>> g = rule_gains("simc", "pi", first_order(0.698, 146.6), 16.6)
>>> round(g.kp, 4), round(g.ki, 6)        # Kc = tau1 / (k (tau_c + theta)), tau_I = min(tau1, 4 (tau_c + theta))
(6.3262, 0.047637)
"""

from __future__ import annotations

import math
import sys
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DelaykitWarning, InvalidValueError, check_real
from ..models.controllers import Controller
from ..models.loop import Loop
from ..models.transfer import TransferFunction

__all__ = ["TuningWarning", "ReducedModel", "UltimatePoint", "RuleGains", "RULES", "reduce_model", "ultimate_point",
           "rule_gains"]

RULES = ("simc", "amigo", "imc", "lambda", "zn", "tyreus-luyben")
"""The rules by name (``imc`` and ``lambda`` are one rule)."""


class TuningWarning(DelaykitWarning):
    """A tuning rule was applied outside the range its authors give for it (the gains are still returned)."""


@dataclass(frozen=True, repr=False)
class ReducedModel:
    """A low-order model of a plant for the model rules.

    ``family`` is ``"fopdt"``, ``"sopdt"``, ``"integrating"`` (``tau2`` a lag, 0 for none) or
    ``"double-integrating"``; ``gain`` is ``k``, ``k'`` or ``k''``; ``tau1 >= tau2`` are time constants (s, 0 when
    absent), ``delay`` the effective dead time (s); ``reduction`` says what the half rule neglected (empty when the
    plant is exactly of the family).
    """

    family: str
    gain: float
    tau1: float
    tau2: float
    delay: float
    reduction: str = ""

    @property
    def exact(self) -> bool:
        """True when the plant is of the family itself (nothing neglected)."""
        return not self.reduction

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"family": self.family, "gain": self.gain, "tau1": self.tau1, "tau2": self.tau2, "delay": self.delay,
                "reduction": self.reduction or None}

    def __repr__(self) -> str:
        lags = "".join(f", tau{i}={t:.4g} s" for i, t in ((1, self.tau1), (2, self.tau2)) if t)
        how = f", half rule: {self.reduction}" if self.reduction else ""
        return f"ReducedModel({self.family}: gain={self.gain:.4g}{lags}, delay={self.delay:.4g} s{how})"


@dataclass(frozen=True, repr=False)
class UltimatePoint:
    """The ultimate gain ``ku`` (P gain that puts a closed-loop root on the imaginary axis) and period ``pu`` (s)."""

    ku: float
    pu: float

    @property
    def frequency(self) -> float:
        """``2 pi / pu`` (rad/s)."""
        return 2.0 * math.pi / self.pu

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"ku": self.ku, "pu": self.pu}

    def __repr__(self) -> str:
        return f"UltimatePoint(ku={self.ku:.6g}, pu={self.pu:.6g} s)"


@dataclass(frozen=True, repr=False)
class RuleGains:
    """Parallel-form gains from a rule (``kd`` 0 for p and pi, ``ki`` 0 for p and pd), with what they came from."""

    rule: str
    controller: str
    kp: float
    ki: float
    kd: float
    model: ReducedModel | None = None
    ultimate: UltimatePoint | None = None
    tau_c: float | None = None
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def ti(self) -> float:
        """Integral time ``kp / ki`` (s; inf without integral action)."""
        return self.kp / self.ki if self.ki else math.inf

    @property
    def td(self) -> float:
        """Derivative time ``kd / kp`` (s)."""
        return self.kd / self.kp if self.kp else 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"rule": self.rule, "controller": self.controller, "kp": self.kp, "ki": self.ki, "kd": self.kd,
                "model": None if self.model is None else self.model.to_dict(),
                "ultimate": None if self.ultimate is None else self.ultimate.to_dict(), "tau_c": self.tau_c,
                "notes": list(self.notes)}

    def __repr__(self) -> str:
        return f"RuleGains({self.rule} {self.controller}: kp={self.kp:.6g}, ki={self.ki:.6g}, kd={self.kd:.6g})"


# --------------------------------------------------------------------------------------------- the plant
def _real_roots(p: np.ndarray, what: str, tf: TransferFunction) -> np.ndarray:
    p = np.trim_zeros(np.asarray(p, float), "f")
    r = np.roots(p) if p.size > 1 else np.zeros(0)
    scale = max(1.0, float(np.max(np.abs(r)))) if r.size else 1.0
    if r.size and np.any(np.abs(r.imag) > 1e-7 * scale):
        raise InvalidValueError(
            f"the plant {tf.to_string(times=' ')} has complex {what}: the model rules (SIMC, AMIGO, IMC) are for "
            "plants with real poles and zeros; use an ultimate-point rule (zn, tyreus-luyben) or --method migo")
    return np.sort(r.real)


def _static_gain(tf: TransferFunction, n_int: int) -> float:
    """``lim s^n P(s)`` at ``s = 0`` for a plant with ``n`` integrators (the last ``n`` denominator coefficients 0)."""
    den = np.trim_zeros(np.asarray(tf.den, float), "f")
    return float(tf.num[-1] / den[-1 - n_int])


def reduce_model(plant: Any, delay: float, order: int = 1) -> ReducedModel:
    """The plant as FOPDT or SOPDT (``order`` 1 or 2), integrating or double integrating, by the half rule.

    Skogestad's half rule: the largest neglected time constant is split, half added to the delay and half to the
    smallest time constant kept; every other neglected time constant, and the time constant ``1/z`` of each
    right-half-plane zero (an inverse response), is added to the delay.  A left-half-plane zero ``-1/T0`` is
    cancelled against the closest larger time constant ``tau0`` (``(T0 s + 1)/(tau0 s + 1) ~ 1/((tau0 - T0) s + 1)``,
    Skogestad's rule T3).  For an integrating plant the integrator plays the role of the largest time constant.

    Parameters
    ----------
    plant : TransferFunction or str
        The plant without its dead time.
    delay : float
        Its dead time (s).
    order : {1, 2}
        1 keeps one time constant (for P and PI), 2 keeps two (for PD and PID).

    Raises
    ------
    InvalidValueError
        For an unstable plant, complex poles or zeros, a zero at the origin, a left-half-plane zero with no larger
        time constant to cancel, or more than two integrators.

    References
    ----------
    .. [1] S. Skogestad, "Simple analytic rules for model reduction and PID controller tuning", *Journal of
       Process Control* 13 (2003) 291-309, section 3.

    Examples
    --------
    >>> reduce_model("1/((s+1)*(0.2*s+1)*(0.04*s+1))", 0.0, order=1)   # Skogestad's example E1
    ReducedModel(fopdt: gain=1, tau1=1.1 s, delay=0.14 s, half rule: ...)
    """
    tf = TransferFunction.coerce(plant, name="plant")
    theta = check_real("delay (s)", delay, minimum=0.0)
    if order not in (1, 2):
        raise InvalidValueError(f"order must be 1 or 2, got {order!r}")
    n_int = tf.integrators
    if tf.num[-1] == 0:
        raise InvalidValueError(f"the plant {tf.to_string(times=' ')} has a zero at s = 0: no rule family fits it")
    poles = _real_roots(tf.den[:tf.den.size - n_int], "poles", tf)
    zeros = _real_roots(tf.num, "zeros", tf)
    if np.any(poles >= 0):
        raise InvalidValueError(f"the plant {tf.to_string(times=' ')} is unstable (a pole at "
                                f"{float(poles.max()):.4g}): the tuning rules are for stable and integrating plants")
    if n_int > 2:
        raise InvalidValueError(f"the plant {tf.to_string(times=' ')} has {n_int} integrators: no rule family fits it")
    # gain: lim s^n P(s) at 0, from the coefficients (the trailing n coefficients of the denominator are zero)
    gain = _static_gain(tf, n_int)
    taus = sorted((-1.0 / p for p in poles), reverse=True)
    notes: list[str] = []
    for z in zeros:
        t0 = 1.0 / abs(float(z))
        if z > 0:
            theta += t0
            notes.append(f"inverse-response time {t0:.4g} s added to the delay")
            continue
        bigger = [t for t in taus if t >= t0]
        if not bigger:
            raise InvalidValueError(
                f"the plant {tf.to_string(times=' ')} has a zero at {float(z):.4g} with no larger time constant to "
                "cancel it: outside the half rule's family; use an ultimate-point rule or --method migo")
        t_near = min(bigger)
        taus.remove(t_near)
        if t_near - t0 > 0:
            taus.append(t_near - t0)
        taus.sort(reverse=True)
        notes.append(f"zero {float(z):.4g} cancelled against the lag {t_near:.4g} s (leaves {t_near - t0:.4g} s)")
    if n_int == 0 and not taus:
        raise InvalidValueError(f"the plant {tf.to_string(times=' ')} is static (no lag and no integrator): outside "
                                "the rule families; use --method migo")
    keep = order - n_int if n_int < 2 else 0  # an integrator counts as the largest time constant
    kept, rest = list(taus[:max(keep, 0)]), taus[max(keep, 0):]
    if rest:
        first = rest[0]  # the largest neglected: half to the smallest kept time constant (or an integrator)...
        if kept:
            kept[-1] += first / 2.0
        theta += first / 2.0 + sum(rest[1:])  # ... and half to the delay, with every other neglected one
        notes.append("neglected time constants " + ", ".join(f"{t:.4g}" for t in rest) + " s")
    kept += [0.0] * (2 - len(kept))
    family = {0: "fopdt" if order == 1 else "sopdt", 1: "integrating", 2: "double-integrating"}[n_int]
    if n_int == 0 and order == 2 and kept[1] == 0.0:
        family = "fopdt"
    return ReducedModel(family, gain, kept[0], kept[1], theta, "; ".join(notes))


def _phase_crossings(plant: TransferFunction, delay: float) -> list[tuple[float, float, float, int]]:
    """Every phase crossover ``(w, |P|, phase, direction)`` of ``P(jw) exp(-jw delay)`` up to the cut-off of
    :func:`~delaykit.spectrum.frequency.margins` (the same exact phase and bisection)."""
    from ..spectrum._openloop import OpenLoop, cutoff_frequency, dense_grid, gain_crossovers, scan_phase

    ol = OpenLoop(Loop(plant, Controller.p(1.0), delay=delay))
    try:
        gains = gain_crossovers(ol)
    except InvalidValueError:
        gains = np.zeros(0)
    w_hi, w_m = cutoff_frequency(ol, gains)
    for _ in range(20):
        scan = scan_phase(ol, dense_grid(ol, gains, w_hi), w_hi)
        if ol.T == 0 or any(c[0] > w_m for c in scan.crossings):
            break
        w_hi *= 2.0
    return [c for c in scan.crossings if c[0] > 0 and c[1] > 0]


def ultimate_point(plant: Any, delay: float) -> UltimatePoint:
    """The exact ultimate gain and period of a plant with a dead time under P control.

    ``ku`` is the smallest gain ``k > 0`` that puts a root of ``1 + k P(s) e^{-sθ}`` on the imaginary axis: the
    smallest ``1 / |P(jw)|`` over the frequencies ``w > 0`` where the exact phase of ``P(jw) e^{-jwθ}`` (the
    delay included as ``-wθ``, no Padé approximation) is -180 degrees modulo 360, each found by bisection to
    machine precision (:mod:`delaykit.spectrum._openloop`, as for the gain margin); ``pu = 2 pi / w`` there.

    Raises
    ------
    InvalidValueError
        When the phase never reaches -180 degrees (no ultimate point: a first-order plant without delay), or when
        the plant is unstable under small P gains (the ultimate gain is then not a gain margin).

    Examples
    --------
    >>> u = ultimate_point("1/s", 0.37)          # K/s e^{-sθ}: wu = pi / (2 θ), ku = wu / K, pu = 4 θ
    >>> round(u.ku, 12) == round(math.pi / (2 * 0.37), 12), round(u.pu, 12)
    (True, 1.48)
    """
    tf = TransferFunction.coerce(plant, name="plant")
    theta = check_real("delay (s)", delay, minimum=0.0)
    if np.any(tf.poles().real > 1e-9 * max(1.0, float(np.max(np.abs(tf.poles()), initial=0.0)))):
        raise InvalidValueError(f"the plant {tf.to_string(times=' ')} is unstable: the P loop is unstable at small "
                                "gains, so it has no ultimate gain in the Ziegler-Nichols sense")
    if _static_gain(tf, tf.integrators) < 0:
        raise InvalidValueError(f"the plant {tf.to_string(times=' ')} has a negative gain: reverse the actuator's "
                                "sign (tune -P) first")
    cross = _phase_crossings(tf, theta)
    if not cross:
        raise InvalidValueError(f"the plant {tf.to_string(times=' ')} with delay {theta:g} s never reaches -180 "
                                "degrees of phase: it has no ultimate point (no gain makes it oscillate)")
    w, mag, _, _ = min(cross, key=lambda c: 1.0 / c[1])
    return UltimatePoint(ku=1.0 / mag, pu=2.0 * math.pi / w)


# --------------------------------------------------------------------------------------------- the rules
def _warn(msg: str, notes: list[str]) -> None:
    notes.append(msg)
    warnings.warn(msg, TuningWarning, stacklevel=4)


def _simc(m: ReducedModel, kind: str, tau_c: float) -> tuple[float, float, float]:
    """SIMC settings in Skogestad's series form ``Kc (1 + 1/(tau_I s)) (1 + tau_D s)``, as (Kc, tau_I, tau_D)."""
    k, t1, t2, th = m.gain, m.tau1, m.tau2, m.delay
    if m.family == "double-integrating":
        if kind in ("p", "pi"):
            raise InvalidValueError("simc: a double-integrating plant needs derivative action (pd or pid), "
                                    f"not {kind}")
        kc = 1.0 / (k * 4.0 * (tau_c + th) ** 2)
        return kc, 4.0 * (tau_c + th), 4.0 * (tau_c + th)
    if m.family == "integrating":
        return 1.0 / (k * (tau_c + th)), 4.0 * (tau_c + th), t1
    return t1 / (k * (tau_c + th)), min(t1, 4.0 * (tau_c + th)), t2


def _amigo(m: ReducedModel, kind: str) -> tuple[float, float, float]:
    """AMIGO settings in parallel form (Kp, Ti, Td)."""
    k, t, el = m.gain, m.tau1, m.delay
    if m.family == "integrating":
        return (0.35 / (k * el), 13.4 * el, 0.0) if kind == "pi" else (0.45 / (k * el), 8.0 * el, 0.5 * el)
    if kind == "pi":
        kp = 0.15 / k + (0.35 - el * t / (el + t) ** 2) * t / (k * el)
        return kp, 0.35 * el + 13.0 * el * t * t / (t * t + 12.0 * el * t + 7.0 * el * el), 0.0
    return (0.2 + 0.45 * t / el) / k, (0.4 * el + 0.8 * t) / (el + 0.1 * t) * el, 0.5 * el * t / (0.3 * el + t)


def _imc(m: ReducedModel, kind: str, lam: float) -> tuple[float, float, float]:
    """IMC / lambda settings in parallel form (Kp, Ti, Td)."""
    k, t, el = m.gain, m.tau1, m.delay
    if m.family == "integrating":
        return (2.0 * lam + el) / (k * (lam + el) ** 2), 2.0 * lam + el, 0.0
    if kind == "pi":
        return t / (k * (lam + el)), t, 0.0
    return (2.0 * t + el) / (k * (2.0 * lam + el)), t + el / 2.0, t * el / (2.0 * t + el)


_ULTIMATE = {  # (kp / Ku, Ti / Pu, Td / Pu)
    ("zn", "p"): (0.5, math.inf, 0.0), ("zn", "pi"): (0.45, 1 / 1.2, 0.0), ("zn", "pid"): (0.6, 0.5, 0.125),
    ("tyreus-luyben", "pi"): (1 / 3.2, 2.2, 0.0), ("tyreus-luyben", "pid"): (1 / 2.2, 2.2, 1 / 6.3),
}


def rule_gains(rule: str, controller: str, plant: Any, delay: float, *, tau_c: float | None = None) -> RuleGains:
    """The gains of a tuning rule for a plant and its dead time (parallel form).

    Rules, their references and the ranges delaykit checks (a :class:`TuningWarning` outside them):

    ``simc``
        Skogestad (2003) [1]_: FOPDT ``Kc = tau1 / (k (tau_c + θ))``, ``tau_I = min(tau1, 4 (tau_c + θ))``;
        SOPDT PID the same with ``tau_D = tau2`` (the derivative cancels the second lag; series form, converted);
        integrating ``Kc = 1 / (k' (tau_c + θ))``, ``tau_I = 4 (tau_c + θ)`` (PID: ``tau_D`` = the lag);
        double integrating ``Kc = 1 / (4 k'' (tau_c + θ)^2)``, ``tau_I = tau_D = 4 (tau_c + θ)``.  ``tau_c``
        defaults to ``θ`` (Skogestad's choice for tight control with good robustness); the paper recommends
        ``tau_c >= θ`` for robustness (warning below ``θ``, where Ms grows above about 1.7).  P and PD are the
        same settings without the integral.
    ``amigo``
        Astrom and Hagglund (2004) [2]_, PI and PID in parallel form, for FOPDT (``K``, ``T``, ``L``) and
        integrating (``Kv``, ``L``) models; designed for Ms about 1.4 on processes with essentially monotone step
        responses.  The PID rule is conservative for lag-dominated processes; delaykit warns when the normalised
        dead time ``tau = L / (L + T)`` is below 0.1 for PID, or when the model needed the half rule (AMIGO itself
        fits the step response; the half rule's model is an approximation of that fit).
    ``imc`` / ``lambda``
        Lambda tuning of PI (Astrom and Hagglund 2006 [3]_: FOPDT ``Kp = T / (K (λ + L))``, ``Ti = T``;
        integrating ``Kp = (2λ + L) / (Kv (λ + L)^2)``, ``Ti = 2λ + L``) and the IMC PID of Rivera, Morari and
        Skogestad (1986) [4]_ for FOPDT (first-order Padé of the delay): ``Kp = (2T + L) / (K (2λ + L))``,
        ``Ti = T + L/2``, ``Td = T L / (2T + L)``, recommended for ``λ > 0.8 L`` (warning below).  ``λ`` is
        ``tau_c`` (default ``θ``).
    ``zn``, ``tyreus-luyben``
        From the exact ultimate gain and period (:func:`ultimate_point`): Ziegler and Nichols (1942) [5]_
        P ``0.5 Ku``; PI ``0.45 Ku``, ``Ti = Pu / 1.2``; PID ``0.6 Ku``, ``Ti = Pu / 2``, ``Td = Pu / 8``.  Tyreus and
        Luyben (1992) [6]_ PI ``Ku / 3.2``, ``Ti = 2.2 Pu``; PID ``Ku / 2.2``, ``Ti = 2.2 Pu``, ``Td = Pu / 6.3``.
        Any stable or integrating plant whose phase reaches -180 degrees; Ziegler-Nichols aims at quarter-amplitude
        damping and gives Ms near 2 or more, so delaykit warns for it when ``θ`` is more than half the largest time
        constant (delay-dominated plants, where the rule is known to be poor [2]_).

    Parameters
    ----------
    rule : {"simc", "amigo", "imc", "lambda", "zn", "tyreus-luyben"}
    controller : {"p", "pi", "pd", "pid"}
    plant : TransferFunction or str
        The plant without the dead time.
    delay : float
        The dead time (s).
    tau_c : float, optional
        SIMC's closed-loop time constant, or IMC's ``λ`` (s); default the (effective) delay.

    Raises
    ------
    InvalidValueError
        An unknown rule, a structure the rule does not give (AMIGO P, ZN PD, ...), or a plant outside the rule's
        family (see :func:`reduce_model` and :func:`ultimate_point`).

    References
    ----------
    .. [1] S. Skogestad, "Simple analytic rules for model reduction and PID controller tuning", *J. Process
       Control* 13 (2003) 291-309.
    .. [2] K. J. Astrom and T. Hagglund, "Revisiting the Ziegler-Nichols step response method for PID control",
       *J. Process Control* 14 (2004) 635-650.
    .. [3] K. J. Astrom and T. Hagglund, *Advanced PID Control*, ISA, 2006, section 7.
    .. [4] D. E. Rivera, M. Morari and S. Skogestad, "Internal model control. 4. PID controller design", *Ind.
       Eng. Chem. Process Des. Dev.* 25 (1986) 252-265.
    .. [5] J. G. Ziegler and N. B. Nichols, "Optimum settings for automatic controllers", *Trans. ASME* 64 (1942)
       759-768.
    .. [6] B. D. Tyreus and W. L. Luyben, "Tuning PI controllers for integrator/dead time processes", *Ind. Eng.
       Chem. Res.* 31 (1992) 2625-2628.

    Examples
    --------
    >>> g = rule_gains("zn", "pi", "1/s", 0.37)
    >>> round(g.kp / g.ultimate.ku, 12), round(g.ti / g.ultimate.pu, 12)
    (0.45, 0.833333333333)
    """
    if not isinstance(rule, str) or rule.lower().replace("_", "-") not in RULES:
        raise InvalidValueError(f"rule must be one of {', '.join(RULES)}; got {rule!r}")
    rule = rule.lower().replace("_", "-")
    kind = str(controller).lower()
    if kind not in ("p", "pi", "pd", "pid"):
        raise InvalidValueError(f"the tuning rules give p, pi, pd or pid controllers; got {controller!r}")
    tf = TransferFunction.coerce(plant, name="plant")
    theta0 = check_real("delay (s)", delay, minimum=0.0)
    notes: list[str] = []
    if rule in ("zn", "tyreus-luyben"):
        if (rule, kind) not in _ULTIMATE:
            raise InvalidValueError(f"the {rule} rule gives "
                                    f"{', '.join(k for r, k in _ULTIMATE if r == rule)} controllers, not {kind}")
        u = ultimate_point(tf, theta0)
        a, b, c = _ULTIMATE[rule, kind]
        kp = a * u.ku
        if rule == "zn":
            taus = [-1.0 / p.real for p in tf.poles() if p.real < 0]
            if not tf.integrators and taus and theta0 > 0.5 * max(taus):
                _warn(f"zn: the delay {theta0:g} s is more than half the largest time constant {max(taus):.4g} s; "
                      "Ziegler-Nichols is poor for delay-dominated plants (little damping, large Ms)", notes)
        return RuleGains(rule, kind, kp, kp / (b * u.pu) if b != math.inf else 0.0, kp * c * u.pu, ultimate=u,
                         notes=tuple(notes))
    if rule == "amigo" and kind not in ("pi", "pid"):
        raise InvalidValueError(f"the amigo rule gives pi and pid controllers, not {kind}")
    if rule in ("imc", "lambda") and kind not in ("pi", "pid"):
        raise InvalidValueError(f"the {rule} rule gives pi and pid controllers, not {kind}")
    order = 2 if rule == "simc" and kind in ("pd", "pid") else 1
    m = reduce_model(tf, theta0, order=order)
    if m.delay <= 0:
        raise InvalidValueError(f"the {rule} rule needs a dead time (an effective delay above 0); the plant "
                                f"{tf.to_string(times=' ')} with delay {theta0:g} s has none")
    tc = m.delay if tau_c is None else check_real("tau_c (s)", tau_c, minimum=0.0, strict=True)
    if rule != "simc" and m.family == "double-integrating":
        raise InvalidValueError(f"the {rule} rule has no setting for a double-integrating plant (use simc)")
    if rule == "imc" or rule == "lambda":
        if kind == "pid" and m.family == "integrating":
            raise InvalidValueError(f"the {rule} PID rule is for FOPDT plants; this plant integrates (use simc)")
    if m.reduction:
        if rule == "amigo":
            _warn(f"amigo: the plant was reduced by the half rule ({m.reduction}); AMIGO is defined on a fitted "
                  "FOPDT or integrating model", notes)
    if rule == "amigo" and kind == "pid" and m.family == "fopdt" and m.delay / (m.delay + m.tau1) < 0.1:
        _warn(f"amigo: normalised dead time tau = {m.delay / (m.delay + m.tau1):.3g} is below 0.1, where the "
              "AMIGO PID rule is conservative", notes)
    if rule != "amigo":
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # (refused by _representable)
            g = _tau_c_rule(rule, kind, m, tc, notes)
        return _representable(g)
    kp, ti, td = _amigo(m, kind)
    return RuleGains(rule, kind, kp, kp / ti, kp * td, model=m, notes=tuple(notes))


def _representable(g: RuleGains) -> RuleGains:
    """``g``, unless a gain its rule makes positive came out below the floats' normal range (``tau_c = 1e300 s``
    makes SIMC's ``ki`` of an integrating plant 1e-601, which is 0.0: silently a P controller)."""
    for name in ("kp", "ki", "kd"):
        value = getattr(g, name)
        if not math.isfinite(value):  # a delay and tau_c of 1e-320 s: kp = 1 / 2e-320 is beyond the floats
            raise InvalidValueError(f"{g.rule}: the delay {g.model.delay:g} s and tau_c = {g.tau_c:g} s make {name} "
                                    f"= {value:g}, beyond the floats: give a longer delay or tau_c")
        if name != "kd" and (name == "kp" or g.controller in ("pi", "pid")) and abs(value) < sys.float_info.min:
            raise InvalidValueError(f"{g.rule}: tau_c = {g.tau_c:g} s makes {name} = {value:g}, below the floats' "
                                    f"range (kp = {g.kp:g}): give a tau_c nearer the delay ({g.model.delay:.4g} s)")
    return g


def _tau_c_rule(rule: str, kind: str, m: ReducedModel, tc: float, notes: list[str]) -> RuleGains:
    """The gains of the rules set by ``tau_c`` (SIMC) or lambda (IMC, lambda tuning)."""
    if rule == "simc":
        if tc < m.delay * (1 - 1e-12):
            _warn(f"simc: tau_c = {tc:g} s is below the effective delay {m.delay:.4g} s; Skogestad recommends "
                  "tau_c >= theta for robustness", notes)
        kc, ti, td = _simc(m, kind, tc)
        if kind == "p":
            return RuleGains(rule, kind, kc, 0.0, 0.0, model=m, tau_c=tc, notes=tuple(notes))
        if kind == "pd":
            return RuleGains(rule, kind, kc, 0.0, kc * td, model=m, tau_c=tc, notes=tuple(notes))
        if kind == "pi":
            return RuleGains(rule, kind, kc, kc / ti, 0.0, model=m, tau_c=tc, notes=tuple(notes))
        # series (1 + 1/(ti s))(1 + td s) = (1 + td/ti) + 1/(ti s) + td s
        return RuleGains(rule, kind, kc * (1 + td / ti), kc / ti, kc * td, model=m, tau_c=tc, notes=tuple(notes))
    if kind == "pid" and tc < 0.8 * m.delay:
        _warn(f"{rule}: lambda = {tc:g} s is below 0.8 times the delay {m.delay:.4g} s, the least Rivera, Morari "
              "and Skogestad recommend", notes)
    kp, ti, td = _imc(m, kind, tc)
    return RuleGains(rule, kind, kp, kp / ti, kp * td, model=m, tau_c=tc, notes=tuple(notes))
