"""Controllers that compensate the delay: the Smith predictor, the filtered Smith predictor, predictor feedback.

Each one carries a *model* of the plant, ``Gn(s)``, and of the loop's delay, ``Tm``, and feeds back a
prediction of the output one delay ahead instead of the delayed measurement, so that its primary controller
can be tuned as if there were no delay.  The model runs inside the controller on the command ``u`` as
applied (after the actuator's limits), so the prediction stays right while the command saturates.

=====================  ===================================================================================
``smith``              Smith (1957).  The primary controller ``C`` acts on ``r - yp`` with the prediction
                       ``yp = ym + Gn (u - u(t - Tm))``.  Stable or integrating models.  With an integrating
                       plant it cannot reject a step load disturbance (a steady error
                       ``d (1/Kc + K Tm)`` with P control): that is why the next one exists.
``filtered-smith``     The filtered Smith predictor of Normey-Rico and Camacho (2007, 2009):
                       ``yp = Fr ym + Gn u - Gn Fr u(t - Tm)`` with a robustness filter ``Fr`` (``Fr(0) = 1``).
                       For ``K / s``, ``Fr = (1 + beta s) / (1 + T0 s)^2`` with ``beta = Tm + 2 T0 + Tc`` (so
                       that a step load disturbance leaves no steady error, see :meth:`Compensator.filtered_smith`);
                       for ``K / (T s + 1)``, ``Fr = 1 / (1 + T0 s)``.  Chosen over the modified Smith predictor
                       of Matausek and Micic because its one filter separates the set-point response (unchanged
                       from the Smith predictor's) from disturbance rejection and robustness, and it has a
                       stable realisation for integrating plants.
``predictor``          Predictor feedback (finite spectrum assignment, Manitius and Olbrot 1979) for the
                       integrator ``K / s`` with integral action: the state ``(y, xi)`` is predicted ``Tm``
                       ahead from the command's history over the last ``Tm`` seconds and fed back with gains
                       that put the closed-loop poles at ``-1 / Tc`` and ``-1 / Ti``.  The integral runs on
                       the error against the reference *delayed* by ``Tm`` (the error the loop could not have
                       avoided), whose prediction is ``xi - Tm ym - K q`` with ``xi' = r - ym``: so the
                       dead time does not wind the integral up, and a load disturbance leaves no steady error.
=====================  ===================================================================================

All three are finite-dimensional: the distributed terms are written with the states ``p = int_{t-Tm}^t u``
(``p' = u - u(t - Tm)``) and, for predictor feedback, ``q = int_{t-Tm}^t (t - s) u(s) ds``
(``q' = p - Tm u(t - Tm)``); these are fixed by the command's history, so their eigenvalue at ``s = 0`` is
never excited (it is divided out of the characteristic function, see :meth:`Compensator.structural_zeros`).
The loop then has two delays, the plant's and the model's, and the simulator treats both exactly.

References
----------
O. J. M. Smith, "Closer control of loops with dead time", Chem. Eng. Prog. 53 (1957) 217-219.
J. E. Normey-Rico and E. F. Camacho, *Control of Dead-time Processes*, Springer (2007), ch. 5-6.
J. E. Normey-Rico and E. F. Camacho, "Unified approach for robust dead-time compensator design",
J. Process Control 19 (2009) 38-47.
A. Manitius and A. Olbrot, "Finite spectrum assignment problem for systems with delays", IEEE TAC 24 (1979).

Examples
--------
>>> c = Compensator.smith("1/s", model_delay=0.37, closed_loop_time=0.1)
>>> c
Compensator(smith: model 1/s, model delay 0.37 s, primary p: kp=10)
>>> c.realisation().order
1
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from .controllers import Controller, Realisation
from .transfer import TransferFunction

__all__ = ["Compensator", "COMPENSATOR_KINDS"]

COMPENSATOR_KINDS = ("smith", "filtered-smith", "predictor")

_SUPPORT = {
    "smith": "a strictly proper model; without a primary controller given, K/s (P) or K/(T*s+1) (PI)",
    "filtered-smith": "the models K/s and K/(T*s+1)",
    "predictor": "the integrator K/s",
}


def _model_family(model: TransferFunction) -> tuple[str, float, float]:
    """``("integrator", K, 0)``, ``("first_order", K, T)`` or ``("other", nan, nan)``."""
    num, den = model.num, model.den
    if num.size == 1 and den.size == 2:
        if den[1] == 0.0:
            return "integrator", float(num[0] / den[0]), 0.0
        if den[1] > 0.0 and den[0] > 0.0:
            return "first_order", float(num[0] / den[1]), float(den[0] / den[1])
    return "other", math.nan, math.nan


def _default_tc(model_delay: float) -> float:
    return model_delay / 4.0 if model_delay > 0 else 0.1


def _ss(tf: TransferFunction) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    A, B, C, D = tf.state_space()
    n = np.atleast_2d(A).shape[0] if np.size(A) else 0
    return (np.atleast_2d(np.asarray(A, float)).reshape(n, n), np.asarray(B, float).reshape(n),
            np.asarray(C, float).reshape(n), float(D))


def _blockdiag(*mats: np.ndarray) -> np.ndarray:
    n = sum(m.shape[0] for m in mats)
    out = np.zeros((n, n))
    k = 0
    for m in mats:
        out[k:k + m.shape[0], k:k + m.shape[0]] = m
        k += m.shape[0]
    return out


@dataclass(frozen=True, repr=False)
class Compensator:
    """A delay-compensating controller (see the module docstring); build one with :meth:`smith`,
    :meth:`filtered_smith` or :meth:`predictor`.

    Parameters
    ----------
    kind : {"smith", "filtered-smith", "predictor"}
    model : TransferFunction
        The delay-free model ``Gn`` of the plant (strictly proper).
    model_delay : float
        The model's delay ``Tm`` (s): the loop's total delay as the design believes it.
    primary : Controller or None
        The primary controller (smith and filtered-smith).
    robustness_filter : TransferFunction or None
        ``Fr`` of the filtered Smith predictor.
    kp, ki : float
        Predictor feedback's gains on the predicted output and the predicted integral of the error.
    setpoint_weight : float
        Predictor feedback: the share ``b`` of the reference in the proportional term (``b = 1/2`` with
        both poles at ``-1/Tc`` makes the nominal set-point response first order).
    closed_loop_time : float
        The design's closed-loop time constant ``Tc`` (s), kept for the record.

    Examples
    --------
    >>> Compensator.predictor("1/s", model_delay=0.5, closed_loop_time=0.1).ki
    10.0
    """

    kind: str
    model: TransferFunction
    model_delay: float
    primary: Controller | None = None
    robustness_filter: TransferFunction | None = None
    kp: float = 0.0
    ki: float = 0.0
    setpoint_weight: float = 1.0
    closed_loop_time: float = math.nan

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        if not isinstance(self.kind, str) or self.kind.lower() not in COMPENSATOR_KINDS:
            raise InvalidValueError(f"compensator must be one of {', '.join(COMPENSATOR_KINDS)}; got {self.kind!r}")
        set_("kind", self.kind.lower())
        set_("model", TransferFunction.coerce(self.model, name="model"))
        set_("model_delay", check_real("model_delay (s)", self.model_delay, minimum=0.0))
        if not self.model.is_strictly_proper:
            raise InvalidValueError(f"the {self.kind} compensator needs a strictly proper model; got "
                                    f"{self.model.to_string(times=' ')} ({_SUPPORT[self.kind]})")
        family, gain, _ = _model_family(self.model)
        if self.kind == "predictor" and family != "integrator":
            raise InvalidValueError(f"predictor feedback supports {_SUPPORT['predictor']}; got the model "
                                    f"{self.model.to_string(times=' ')}")
        if self.kind == "filtered-smith" and family == "other":
            raise InvalidValueError(f"the filtered Smith predictor supports {_SUPPORT['filtered-smith']}; got the "
                                    f"model {self.model.to_string(times=' ')}")
        if self.kind != "predictor":
            if not isinstance(self.primary, Controller):
                raise InvalidTypeError(f"the {self.kind} compensator needs a primary Controller, got "
                                       f"{type(self.primary).__name__}")
            if self.primary.uses_velocity:
                raise InvalidValueError("the primary controller of a predictor cannot read the true velocity "
                                        "(the prediction has none); use velocity='filtered'")
            if self.primary.antiwindup == "clamp":
                raise InvalidValueError("clamping anti-windup watches the measured error, not the predicted one; "
                                        "use antiwindup='backcalc' for a predictor's primary controller")
            poles = self.model.poles()
            if np.any(poles.real > 1e-9) or np.sum(np.abs(poles) <= 1e-9) > 1:
                raise InvalidValueError(
                    f"a Smith predictor needs a stable model or one integrator; the model "
                    f"{self.model.to_string(times=' ')} has poles {np.round(poles, 6).tolist()}")
        if self.kind == "filtered-smith":
            if self.robustness_filter is None:
                raise InvalidValueError("the filtered Smith predictor needs its robustness filter Fr")
            fr = TransferFunction.coerce(self.robustness_filter, name="robustness_filter")
            if abs(fr.dc_gain() - 1.0) > 1e-9:
                raise InvalidValueError(f"the robustness filter must have unit static gain, Fr(0) = 1; got "
                                        f"{fr.dc_gain():g}")
            set_("robustness_filter", fr)
        elif self.robustness_filter is not None:
            raise InvalidValueError(f"a robustness filter is only for the filtered Smith predictor, not {self.kind}")
        for name in ("kp", "ki", "setpoint_weight"):
            set_(name, check_real(name, getattr(self, name)))
        if self.kind == "predictor" and not (self.kp * gain > 0 and self.ki * gain >= 0):
            raise InvalidValueError(f"predictor feedback needs kp*K > 0 and ki*K >= 0 (K = {gain:g}); got "
                                    f"kp={self.kp:g}, ki={self.ki:g}")

    # -- constructors -------------------------------------------------------------------------------------
    @classmethod
    def smith(cls, model: Any, model_delay: float, *, primary: Controller | None = None,
              closed_loop_time: float | None = None) -> "Compensator":
        """The Smith predictor.  Without ``primary``, the primary controller puts the nominal (delay-free)
        loop's pole at ``-1 / Tc``: P with ``Kc = 1 / (K Tc)`` for ``K / s``, PI with ``Kp = T / (K Tc)``,
        ``Ki = 1 / (K Tc)`` for ``K / (T s + 1)``.  ``Tc`` defaults to a quarter of the model delay.

        Examples
        --------
        >>> Compensator.smith("2/(5*s+1)", 1.0, closed_loop_time=0.5).primary
        Controller(pi: kp=5, ki=1)
        """
        tm = check_real("model_delay (s)", model_delay, minimum=0.0)
        g = TransferFunction.coerce(model, name="model")
        tc = _default_tc(tm) if closed_loop_time is None else check_real(
            "closed_loop_time (Tc, s)", closed_loop_time, minimum=0.0, strict=True)
        if primary is None:
            family, k, t = _model_family(g)
            if family == "integrator":
                primary = Controller.p(1.0 / (k * tc))
            elif family == "first_order":
                primary = Controller.pi(t / (k * tc), 1.0 / (k * tc))
            else:
                raise InvalidValueError(f"no default primary controller for the model {g.to_string(times=' ')}: "
                                        f"give primary=Controller... ({_SUPPORT['smith']})")
        return cls("smith", g, tm, primary=primary, closed_loop_time=tc)

    @classmethod
    def filtered_smith(cls, model: Any, model_delay: float, *, closed_loop_time: float | None = None,
                       filter_time: float | None = None) -> "Compensator":
        """The filtered Smith predictor (Normey-Rico and Camacho).

        The primary controller is the Smith predictor's default (P for ``K / s``, PI for ``K / (T s + 1)``).
        For ``K / s`` the filter ``Fr = (1 + beta s) / (1 + T0 s)^2`` has ``beta = Tm + 2 T0 + Tc``: the
        load-disturbance response's steady value is proportional to ``1 - K Kc (beta - 2 T0 - Tm)``, which
        this zeroes.  For ``K / (T s + 1)``, ``Fr = 1 / (1 + T0 s)``.  ``T0`` (``filter_time``) defaults to
        the model delay: larger is more robust to a wrong model and slower to reject a disturbance.

        Examples
        --------
        >>> c = Compensator.filtered_smith("1/s", 0.37, closed_loop_time=0.1, filter_time=0.37)
        >>> c.robustness_filter
        TransferFunction((8.83857 s + 7.3046)/(s^2 + 5.40541 s + 7.3046))
        """
        tm = check_real("model_delay (s)", model_delay, minimum=0.0)
        g = TransferFunction.coerce(model, name="model")
        tc = _default_tc(tm) if closed_loop_time is None else check_real(
            "closed_loop_time (Tc, s)", closed_loop_time, minimum=0.0, strict=True)
        t0 = (tm if tm > 0 else tc) if filter_time is None else check_real(
            "filter_time (T0, s)", filter_time, minimum=0.0, strict=True)
        family, k, t = _model_family(g)
        if family == "integrator":
            beta = tm + 2.0 * t0 + tc
            fr = TransferFunction([beta, 1.0], [t0 * t0, 2.0 * t0, 1.0])
            primary = Controller.p(1.0 / (k * tc))
        elif family == "first_order":
            fr = TransferFunction([1.0], [t0, 1.0])
            primary = Controller.pi(t / (k * tc), 1.0 / (k * tc))
        else:
            raise InvalidValueError(f"the filtered Smith predictor supports {_SUPPORT['filtered-smith']}; got "
                                    f"the model {g.to_string(times=' ')}")
        return cls("filtered-smith", g, tm, primary=primary, robustness_filter=fr, closed_loop_time=tc)

    @classmethod
    def predictor(cls, model: Any, model_delay: float, *, closed_loop_time: float | None = None,
                  integral_time: float | None = None) -> "Compensator":
        """Predictor feedback for ``K / s`` with integral action.  The predicted loop's poles are put at
        ``-1 / Tc`` (tracking) and ``-1 / Ti`` (the integral, which rejects a load disturbance):
        ``Kp = (1/Tc + 1/Ti) / K``, ``Ki = 1 / (K Tc Ti)``; the set-point weight ``b = Ti / (Ti + Tc)``
        cancels the slow pole, so the nominal set-point response is ``exp(-Tm s) / (Tc s + 1)``, as the
        Smith predictor's.  ``Ti`` defaults to twice the model delay; ``Ti = inf`` drops the integral (the
        law is then the Smith predictor with P control).  While the command saturates, the integral is
        pulled back (back-calculation, tracking time ``Tc``): with the delay, the predicted integral is the
        integral of the *predicted* loop, so this is back-calculation on the delay-free loop.

        Examples
        --------
        >>> c = Compensator.predictor("1/s", 0.4, closed_loop_time=0.1, integral_time=0.4)
        >>> round(c.kp, 6), round(c.ki, 6), c.setpoint_weight
        (12.5, 25.0, 0.8)
        """
        tm = check_real("model_delay (s)", model_delay, minimum=0.0)
        g = TransferFunction.coerce(model, name="model")
        tc = _default_tc(tm) if closed_loop_time is None else check_real(
            "closed_loop_time (Tc, s)", closed_loop_time, minimum=0.0, strict=True)
        ti = (2.0 * tm if tm > 0 else 10.0 * tc) if integral_time is None else check_real(
            "integral_time (Ti, s)", integral_time, minimum=0.0, strict=True, allow_inf=True)
        family, k, _ = _model_family(g)
        if family != "integrator":
            raise InvalidValueError(f"predictor feedback supports {_SUPPORT['predictor']}; got the model "
                                    f"{g.to_string(times=' ')}")
        if math.isinf(ti):  # no integral action: the Smith predictor with P control, written as a predictor
            return cls("predictor", g, tm, kp=1.0 / (k * tc), ki=0.0, setpoint_weight=1.0, closed_loop_time=tc)
        return cls("predictor", g, tm, kp=(1.0 / tc + 1.0 / ti) / k, ki=1.0 / (k * tc * ti),
                   setpoint_weight=ti / (ti + tc), closed_loop_time=tc)

    @classmethod
    def design(cls, kind: str, model: Any, model_delay: float, **options: Any) -> "Compensator":
        """The compensator of a kind (``smith``, ``filtered-smith`` or ``predictor``) by its default rule.

        Examples
        --------
        >>> Compensator.design("smith", "1/s", 0.37).primary.kp
        10.81081081081081
        """
        makers = {"smith": cls.smith, "filtered-smith": cls.filtered_smith, "predictor": cls.predictor}
        k = str(kind).lower().replace("_", "-")
        if k not in makers:
            raise InvalidValueError(f"compensator must be one of {', '.join(COMPENSATOR_KINDS)}; got {kind!r}")
        return makers[k](model, model_delay, **options)

    # -- what the loop and the simulator read ---------------------------------------------------------------
    uses_velocity = False
    filtered = False

    @property
    def has_integrator(self) -> bool:
        """True when the law integrates the error (predictor feedback, or a PI/PID primary controller)."""
        return self.kind == "predictor" or (self.primary is not None and self.primary.has_integrator)

    @property
    def antiwindup(self) -> str:
        """The anti-windup the simulator applies: back-calculation with tracking time ``Tc`` for predictor
        feedback's integral, else the primary controller's."""
        if self.kind == "predictor":
            return "backcalc" if self.ki > 0 else "none"
        return self.primary.antiwindup  # type: ignore[union-attr]

    def structural_zeros(self) -> int:
        """Roots at ``s = 0`` of the characteristic function that the loop never excites: the window
        integral ``p = int_{t-Tm}^t u`` of an integrating model (and ``q`` of predictor feedback) is fixed by
        the command's history.

        Examples
        --------
        >>> Compensator.smith("1/(2*s+1)", 0.5).structural_zeros()
        0
        """
        if self.kind == "predictor":
            return 2 if self.ki else 3
        return 1 if self.model.integrators >= 1 else 0

    def replace(self, **changes: Any) -> "Compensator":
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def realisation(self) -> Realisation:
        """The law as state-space matrices with the command and the delayed command as inputs.

        Examples
        --------
        >>> r = Compensator.predictor("1/s", 0.37, closed_loop_time=0.1).realisation()
        >>> r.order, r.model_delay, r.integ
        (3, 0.37, 2)
        """
        tm = self.model_delay
        if self.kind == "predictor":
            k = _model_family(self.model)[1]
            k1, k2, b = self.kp, self.ki, self.setpoint_weight
            Ac = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
            aw = 1.0 / (k2 * self.closed_loop_time) if k2 > 0 else 0.0  # back-calculation, tracking time Tc
            return Realisation(Ac, np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0]), np.zeros(3),
                               np.array([0.0, 0.0, aw]),
                               np.array([-k1 * k, -k2 * k, k2]), b * k1, -(k1 + k2 * tm), 0.0, 2,
                               Bcu=np.array([1.0, 0.0, 0.0]), Bcm=np.array([-1.0, -tm, 0.0]), model_delay=tm)
        # the prediction yp = Cs xs + Ds ym from the model block, then the primary controller on r - yp
        Am, Bm, Cm, _ = _ss(self.model)
        blocks, bsy, bsu, bsm, cs, ds = [Am], [np.zeros(Am.shape[0])], [Bm], [-Bm], [Cm], 1.0
        if self.kind == "filtered-smith":
            fr = self.robustness_filter
            g1 = TransferFunction(np.polymul(self.model.num, np.polysub(fr.den, fr.num)),
                                  np.polymul(self.model.den, fr.den)).minimal()
            A1, B1, C1, _ = _ss(g1)
            Af, Bf, Cf, Df = _ss(fr)
            blocks += [A1, Af]
            bsy += [np.zeros(A1.shape[0]), Bf]
            bsu += [np.zeros(A1.shape[0]), np.zeros(Af.shape[0])]
            bsm += [B1, np.zeros(Af.shape[0])]
            cs += [C1, Cf]
            ds = Df
        As = _blockdiag(*blocks)
        Bsy, Bsu, Bsm, Cs = (np.concatenate(v) for v in (bsy, bsu, bsm, cs))
        rp = self.primary.realisation()  # type: ignore[union-attr]
        npr, ns = rp.order, As.shape[0]
        Ac = np.zeros((npr + ns, npr + ns))
        Ac[:npr, :npr] = rp.Ac
        Ac[:npr, npr:] = np.outer(rp.Bcy, Cs)
        Ac[npr:, npr:] = As
        zp, zs = np.zeros(npr), np.zeros(ns)
        return Realisation(Ac, np.r_[rp.Bcr, zs], np.r_[rp.Bcy * ds, Bsy], np.zeros(npr + ns), np.r_[rp.Baw, zs],
                           np.r_[rp.Cc, rp.dvy * Cs], rp.dvr, rp.dvy * ds, 0.0, rp.integ,
                           Bcu=np.r_[zp, Bsu], Bcm=np.r_[zp, Bsm], model_delay=tm)

    # -- output -------------------------------------------------------------------------------------------
    def params(self) -> dict[str, Any]:
        """The design's parameters, JSON-ready.

        Examples
        --------
        >>> Compensator.smith("1/s", 0.37, closed_loop_time=0.1).params()["primary"]
        {'kind': 'p', 'kp': 10.0}
        """
        d: dict[str, Any] = {"model": self.model.to_string(digits=17), "model_delay": self.model_delay,
                             "closed_loop_time": self.closed_loop_time if math.isfinite(self.closed_loop_time)
                             else None}
        if self.primary is not None:
            d["primary"] = self.primary.to_dict()
        if self.robustness_filter is not None:
            d["robustness_filter"] = self.robustness_filter.to_string(digits=17)
        if self.kind == "predictor":
            d.update(kp=self.kp, ki=self.ki, setpoint_weight=self.setpoint_weight)
        return d

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: the kind and :meth:`params`."""
        return {"kind": self.kind, **self.params()}

    def __repr__(self) -> str:
        parts = [f"model {self.model.to_string(times=' ')}", f"model delay {self.model_delay:.4g} s"]
        if self.primary is not None:
            parts.append("primary " + repr(self.primary)[len("Controller("):-1])
        if self.robustness_filter is not None:
            parts.append(f"Fr {self.robustness_filter.to_string(times=' ')}")
        if self.kind == "predictor":
            parts.append(f"kp={self.kp:.4g}, ki={self.ki:.4g}, b={self.setpoint_weight:g}")
        return f"Compensator({self.kind}: {', '.join(parts)})"
