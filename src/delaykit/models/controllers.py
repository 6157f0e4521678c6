"""Controllers of a delayed loop: P, PV, PI, PD, PID and any proper transfer function on the error.

Every controller computes its output ``v`` from the reference ``r``, the measured output ``ym`` and, for
the paper's PV law with the true velocity, the measured velocity ``vm``:

=========  ===========================================================================================
``p``      ``v = Kp e``, with ``e = r - ym``
``pv``     ``v = Kp e - Kv vm`` (true velocity), or ``Kp e - Kv F(s) ym`` through the paper's derivative
           filter ``F(s) = wf^2 s / (s^2 + 2 zf wf s + wf^2)`` (``velocity="filtered"``)
``pi``     ``v = Kp e + Ki xi``, ``xi' = e``
``pd``     ``v = Kp e - Kd s/(Tf s + 1) ym``: the derivative acts on the measurement through a
           first-order filter, so a reference step gives no derivative kick
``pid``    ``v = Kp e + Ki xi - Kd s/(Tf s + 1) ym``
``tf``     ``v = C(s) e`` for any proper transfer function ``C``
=========  ===========================================================================================

The integral runs on the error with no anti-windup by default.  Two options, both acting while the
command is saturated (``u = clip(v, umin, umax) != v``):

* ``antiwindup="clamp"`` (conditional integration): the integrator stops while the command is saturated
  and the error would drive it further into saturation;
* ``antiwindup="backcalc"`` (back-calculation, Astrom & Hagglund): ``xi' = e + (u - v) / (Ki Tt)``, with
  the tracking time ``Tt`` (default ``sqrt(Ti Td)`` for PID and ``Ti`` for PI, with ``Ti = Kp / Ki``
  and ``Td = Kd / Kp``; ``1 / Ki`` when ``Kp = 0``).

Each law is written once, by :func:`controller_branches` (its parallel branches, each a small
:class:`Realisation`): :meth:`Controller.realisation` is their sum (:func:`parallel`),
:meth:`Controller.feedback_polynomials` the sum of their transfer functions (:func:`feedback_transfer`), and a
batch of simulations over arrays of gains evaluates them at the arrays.

Examples
--------
>>> Controller.pid(kp=2.0, ki=0.5, kd=0.1, derivative_filter=0.02)
Controller(pid: kp=2, ki=0.5, kd=0.1, Tf=0.02 s)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from .transfer import TransferFunction

__all__ = ["Controller", "Realisation", "controller_branches", "parallel", "feedback_transfer", "feedback_response", "input_transfer", "CONTROLLER_KINDS", "ANTIWINDUP_CHOICES", "VELOCITY_CHOICES"]

CONTROLLER_KINDS = ("p", "pv", "pi", "pd", "pid", "tf")
ANTIWINDUP_CHOICES = ("none", "clamp", "backcalc")
VELOCITY_CHOICES = ("true", "filtered")


@dataclass(frozen=True)
class Realisation:
    """A controller as state-space matrices, the form the simulator runs.

    ``xc' = Ac xc + Bcr r + Bcy ym + Bcv vm + Baw (u - v) + Bcu u + Bcm u(t - Tm)`` and
    ``v = Cc xc + dvr r + dvy ym + dvv vm``; ``integ`` is the index of the integrator state (-1: none).
    The last two inputs, the command itself and the command one model delay ``Tm`` (``model_delay``) ago,
    are read only by controllers with a model of the plant inside (see :mod:`delaykit.models.compensators`);
    ``None`` stands for zeros.
    """

    Ac: np.ndarray
    Bcr: np.ndarray
    Bcy: np.ndarray
    Bcv: np.ndarray
    Baw: np.ndarray
    Cc: np.ndarray
    dvr: float
    dvy: float
    dvv: float
    integ: int
    Bcu: np.ndarray | None = None
    Bcm: np.ndarray | None = None
    model_delay: float = 0.0

    @property
    def order(self) -> int:
        """Number of controller states."""
        return int(self.Ac.shape[0])

    @property
    def reads_command(self) -> bool:
        """True when the states read the command (a predictor's model)."""
        return self.Bcu is not None or self.Bcm is not None


@dataclass(frozen=True, repr=False)
class Controller:
    """A controller of a delayed loop (see the module docstring for the laws).

    Build one with the named constructors :meth:`p`, :meth:`pv`, :meth:`pi`, :meth:`pd`, :meth:`pid`,
    :meth:`transfer`, or from a kind and keywords with :meth:`make`; ``Controller(G)`` with a transfer function
    ``G`` (delaykit's or python-control's) is ``Controller.transfer(G)``.

    Parameters
    ----------
    kind : {"p", "pv", "pi", "pd", "pid", "tf"}
    kp, ki, kd, kv : float
        Proportional, integral (1/s), derivative (s) and velocity gains.
    derivative_filter : float
        Time constant ``Tf`` (s) of the derivative's filter ``s / (Tf s + 1)``; positive for pd and pid.
    velocity : {"true", "filtered"}
        The velocity of the PV law: the true one, or the paper's filtered derivative.
    filter_wn, filter_zeta : float
        Natural frequency (rad/s) and damping of the paper's derivative filter.
    transfer_function : TransferFunction or None
        The controller of kind ``tf`` (on the error).
    antiwindup : {"none", "clamp", "backcalc"}
    tracking_time : float or None
        Back-calculation tracking time ``Tt`` (s); ``None`` for the default rule.
    setpoint_weight, derivative_weight : float
        The 2-DOF weights ``b`` and ``c`` of pi and pid: the proportional part acts on ``b r - ym`` and the
        derivative (pid) on ``c r - ym``; the integral always on ``r - ym``.  The defaults ``b = 1``, ``c = 0`` are
        the laws above; the weights change the response to the reference only, not the loop's stability.

    Examples
    --------
    >>> Controller.pv(kp=2.0, kv=0.3)
    Controller(pv: kp=2, kv=0.3, true velocity)
    >>> Controller.pi(kp=1.0, ki=0.2, antiwindup="clamp").realisation().order
    1
    """

    kind: Literal["p", "pv", "pi", "pd", "pid", "tf"] = "p"
    kp: float = 0.0
    ki: float = 0.0
    kd: float = 0.0
    kv: float = 0.0
    derivative_filter: float = 0.0
    velocity: Literal["true", "filtered"] = "true"
    filter_wn: float = 38.0
    filter_zeta: float = 1.0
    transfer_function: TransferFunction | None = field(default=None)
    antiwindup: Literal["none", "clamp", "backcalc"] = "none"
    tracking_time: float | None = None
    setpoint_weight: float = 1.0
    derivative_weight: float = 0.0

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        if not isinstance(self.kind, str) and self.transfer_function is None:
            # Controller(G) with G a transfer function (delaykit's, python-control's, (num, den)): Controller.transfer
            try:
                tf = TransferFunction.coerce(self.kind, name="controller")
            except (InvalidValueError, InvalidTypeError) as exc:
                raise type(exc)(f"Controller(...) takes a kind ({', '.join(CONTROLLER_KINDS)}) or a transfer "
                                f"function (as Controller.transfer(...) does); {exc}") from None
            set_("kind", "tf")
            set_("transfer_function", tf)
        if not isinstance(self.kind, str) or self.kind.lower() not in CONTROLLER_KINDS:
            hint = (f"; for a transfer function on the error use Controller.transfer({self.kind!r})"
                    if isinstance(self.kind, str) else "")
            raise InvalidValueError(f"controller must be one of {', '.join(CONTROLLER_KINDS)}; got "
                                    f"{self.kind!r}{hint}")
        set_("kind", self.kind.lower())
        for name in ("kp", "ki", "kd", "kv"):
            set_(name, check_real(f"{name} ({_GAIN_NAMES[name]})", getattr(self, name)))
        for name in ("ki", "kd", "kv"):
            if getattr(self, name) != 0.0 and name not in _USES[self.kind]:
                raise InvalidValueError(f"a {self.kind} controller has no {name}; got {name}={getattr(self, name):g}")
        gains = {name: getattr(self, name) for name in ("kp", "ki", "kd", "kv") if getattr(self, name) != 0.0}
        if any(v > 0 for v in gains.values()) and any(v < 0 for v in gains.values()):
            raise InvalidValueError(
                "a controller's gains must share one sign (all at least 0, or all at most 0 for a plant of negative "
                f"gain); got {', '.join(f'{k}={v:g}' for k, v in gains.items())}")
        if self.kind in ("pd", "pid"):
            set_("derivative_filter", check_real("derivative_filter (Tf, s)", self.derivative_filter,
                                                 minimum=0.0, strict=True))
        else:
            set_("derivative_filter", check_real("derivative_filter (Tf, s)", self.derivative_filter, minimum=0.0))
        if self.velocity not in VELOCITY_CHOICES:
            raise InvalidValueError(f"velocity must be one of {', '.join(VELOCITY_CHOICES)}; got {self.velocity!r}")
        set_("filter_wn", check_real("filter_wn (rad/s)", self.filter_wn, minimum=0.0, strict=True))
        set_("filter_zeta", check_real("filter_zeta", self.filter_zeta, minimum=0.0, strict=True))
        if self.kind == "tf":
            if self.transfer_function is None:
                raise InvalidValueError("a tf controller needs its transfer function (transfer_function=...)")
            set_("transfer_function", TransferFunction.coerce(self.transfer_function, name="controller"))
        elif self.transfer_function is not None:
            raise InvalidValueError(f"transfer_function is only for the tf controller, not {self.kind}")
        if self.antiwindup not in ANTIWINDUP_CHOICES:
            raise InvalidValueError(
                f"antiwindup must be one of {', '.join(ANTIWINDUP_CHOICES)}; got {self.antiwindup!r}")
        if self.antiwindup != "none" and not self.has_integrator:
            raise InvalidValueError(f"anti-windup needs an integrator; a {self.kind} controller has none")
        if self.antiwindup == "backcalc" and self.ki == 0.0:
            raise InvalidValueError("back-calculation anti-windup needs ki != 0")
        set_("setpoint_weight", check_real("setpoint_weight (b)", self.setpoint_weight, minimum=0.0))
        set_("derivative_weight", check_real("derivative_weight (c)", self.derivative_weight, minimum=0.0))
        if self.setpoint_weight != 1.0 and not self.has_integrator:
            raise InvalidValueError(f"a setpoint weight b needs integral action (pi or pid), or the output settles "
                                    f"off the reference; a {self.kind} controller has none (b = {self.setpoint_weight:g})")
        if self.derivative_weight != 0.0 and self.kind != "pid":
            raise InvalidValueError(f"the derivative weight c is for pid, not {self.kind} "
                                    f"(c = {self.derivative_weight:g})")
        if self.tracking_time is not None:
            set_("tracking_time", check_real("tracking_time (Tt, s)", self.tracking_time, minimum=0.0, strict=True))

    # -- constructors -----------------------------------------------------------------------------------
    @classmethod
    def p(cls, kp: float) -> "Controller":
        """Proportional control ``v = Kp e``.

        Examples
        --------
        >>> Controller.p(1.31).kp
        1.31
        """
        return cls("p", kp=kp)

    @classmethod
    def pv(cls, kp: float, kv: float, *, velocity: str = "true", filter_wn: float = 38.0,
           filter_zeta: float = 1.0) -> "Controller":
        """The paper's PV law ``v = Kp e - Kv velocity``.

        Examples
        --------
        >>> Controller.pv(2.0, 0.3, velocity="filtered").velocity
        'filtered'
        """
        return cls("pv", kp=kp, kv=kv, velocity=velocity, filter_wn=filter_wn, filter_zeta=filter_zeta)

    @classmethod
    def pi(cls, kp: float, ki: float, *, antiwindup: str = "none", tracking_time: float | None = None,
           setpoint_weight: float = 1.0) -> "Controller":
        """PI control ``v = Kp e + Ki \\int e``.

        Examples
        --------
        >>> Controller.pi(0.95, 0.1).ki
        0.1
        """
        return cls("pi", kp=kp, ki=ki, antiwindup=antiwindup, tracking_time=tracking_time,
                   setpoint_weight=setpoint_weight)

    @classmethod
    def pd(cls, kp: float, kd: float, derivative_filter: float) -> "Controller":
        """PD control with the derivative on the measurement, filtered by ``1 / (Tf s + 1)``.

        Examples
        --------
        >>> Controller.pd(2.0, 0.1, 0.02).kind
        'pd'
        """
        return cls("pd", kp=kp, kd=kd, derivative_filter=derivative_filter)

    @classmethod
    def pid(cls, kp: float, ki: float, kd: float, derivative_filter: float, *, antiwindup: str = "none",
            tracking_time: float | None = None, setpoint_weight: float = 1.0,
            derivative_weight: float = 0.0) -> "Controller":
        """PID control, the derivative on the measurement through ``s / (Tf s + 1)``.

        Examples
        --------
        >>> Controller.pid(2.0, 0.5, 0.1, 0.02).realisation().order
        2
        """
        return cls("pid", kp=kp, ki=ki, kd=kd, derivative_filter=derivative_filter, antiwindup=antiwindup,
                   tracking_time=tracking_time, setpoint_weight=setpoint_weight, derivative_weight=derivative_weight)

    @classmethod
    def transfer(cls, tf: Any) -> "Controller":
        """Any proper controller ``v = C(s) e`` (a string such as ``"(s+2)/(0.1*s+1)"``, coefficients, ...).

        Examples
        --------
        >>> Controller.transfer("2*(s+1)/(0.1*s+1)").realisation().order
        1
        """
        return cls("tf", transfer_function=TransferFunction.coerce(tf, name="controller"))

    @classmethod
    def make(cls, kind: str, **params: Any) -> "Controller":
        """A controller from its kind and keywords, ignoring keywords the kind does not use when they are
        zero or ``None`` (so one option group can build any controller).

        Examples
        --------
        >>> Controller.make("pi", kp=1.0, ki=0.5, kd=0.0, kv=0.0)
        Controller(pi: kp=1, ki=0.5)
        """
        if not isinstance(kind, str):
            return cls.transfer(kind)
        k = kind.lower()
        if k not in CONTROLLER_KINDS:
            try:
                return cls.transfer(kind)
            except InvalidValueError:
                raise InvalidValueError(
                    f"controller must be one of {', '.join(CONTROLLER_KINDS)} or a transfer function; got {kind!r}"
                ) from None
        keep = {name: v for name, v in params.items() if v is not None and not (name in _GAIN_NAMES and name not in _USES[k] and v == 0)}
        return cls(k, **keep)

    # -- properties -------------------------------------------------------------------------------------
    @property
    def has_integrator(self) -> bool:
        """True for pi and pid."""
        return self.kind in ("pi", "pid")

    @property
    def gain_names(self) -> tuple[str, ...]:
        """The gains the law uses (none for a tf controller, whose law is its transfer function).

        Examples
        --------
        >>> Controller.pid(2.0, 0.5, 0.1, 0.02).gain_names
        ('kp', 'ki', 'kd')
        """
        return () if self.kind == "tf" else ("kp",) + _USES[self.kind]

    @property
    def filtered(self) -> bool:
        """True for the PV law through the derivative filter (with Kv > 0)."""
        return self.kind == "pv" and self.velocity == "filtered" and self.kv > 0.0

    @property
    def uses_velocity(self) -> bool:
        """True when the law reads the true velocity of the output (PV, true velocity, Kv != 0)."""
        return self.kind == "pv" and not self.filtered and self.kv != 0.0

    def default_tracking_time(self) -> float:
        """The back-calculation tracking time: ``tracking_time`` or the default rule."""
        return _tracking_time(self, self.kp, self.ki, self.kd)

    def replace(self, **changes: Any) -> "Controller":
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    # -- the law as matrices -----------------------------------------------------------------------------
    def realisation(self) -> Realisation:
        """The controller as state-space matrices (see :class:`Realisation`): the parallel sum of
        :func:`controller_branches`.

        Examples
        --------
        >>> r = Controller.pi(1.0, 0.5).realisation()
        >>> (r.dvr, r.dvy, r.Cc.tolist())
        (1.0, -1.0, [0.5])
        """
        cached = self.__dict__.get("_realisation")
        if cached is None:  # the controller is immutable: its law is built once, its arrays read-only
            cached = parallel(controller_branches(self))
            for name in ("Ac", "Bcr", "Bcy", "Bcv", "Baw", "Cc"):
                getattr(cached, name).flags.writeable = False
            object.__setattr__(self, "_realisation", cached)
        return cached

    def feedback_polynomials(self) -> tuple[np.ndarray, np.ndarray]:
        """Numerator and denominator of the feedback part ``Cy(s)`` of the law ``v = ... - Cy(s) ym``
        (the loop's characteristic equation is ``Dp Dc + Np Nc exp(-s T) = 0``), the sum of the feedback parts of
        :func:`controller_branches` (each from its realisation; a tf controller's is its transfer function).

        Examples
        --------
        >>> [c.tolist() for c in Controller.pv(2.0, 0.3).feedback_polynomials()]
        [[0.3, 2.0], [1.0]]
        """
        if self.kind == "tf":
            return self.transfer_function.num.copy(), self.transfer_function.den.copy()
        cached = self.__dict__.get("_feedback")
        if cached is None:  # built once (the controller is immutable)
            num, den = np.zeros(1), np.ones(1)
            for b in controller_branches(self):
                nb, db = feedback_transfer(b)
                num, den = _padd(np.convolve(num, db), np.convolve(nb, den)), np.convolve(den, db)
            cached = (_trim(num), den)
            object.__setattr__(self, "_feedback", cached)
        return cached[0].copy(), cached[1].copy()

    # -- output -----------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: the kind and the parameters it uses."""
        d: dict[str, Any] = {"kind": self.kind}
        for name in ("kp", "ki", "kd", "kv"):
            if name == "kp" or name in _USES[self.kind]:
                d[name] = getattr(self, name)
        if self.kind in ("pd", "pid"):
            d["derivative_filter"] = self.derivative_filter
        if self.kind == "pv":
            d["velocity"] = self.velocity
            if self.velocity == "filtered":
                d["filter_wn"] = self.filter_wn
                d["filter_zeta"] = self.filter_zeta
        if self.kind == "tf":
            d.pop("kp")
            d["transfer_function"] = self.transfer_function.to_dict()
        if self.setpoint_weight != 1.0:
            d["setpoint_weight"] = self.setpoint_weight
        if self.derivative_weight != 0.0:
            d["derivative_weight"] = self.derivative_weight
        if self.has_integrator:
            d["antiwindup"] = self.antiwindup
            if self.antiwindup == "backcalc":
                d["tracking_time"] = self.default_tracking_time()
        return d

    def __repr__(self) -> str:
        if self.kind == "tf":
            return f"Controller(tf: {self.transfer_function.to_string(times=' ')})"
        parts = [f"kp={self.kp:g}"]
        for name in ("ki", "kd", "kv"):
            if name in _USES[self.kind]:
                parts.append(f"{name}={getattr(self, name):g}")
        if self.kind in ("pd", "pid"):
            parts.append(f"Tf={self.derivative_filter:g} s")
        if self.kind == "pv":
            parts.append(f"filtered velocity (wn={self.filter_wn:g} rad/s, zeta={self.filter_zeta:g})"
                         if self.velocity == "filtered" else "true velocity")
        if self.setpoint_weight != 1.0 or self.derivative_weight != 0.0:
            parts.append(f"b={self.setpoint_weight:g}" + (f", c={self.derivative_weight:g}" if self.kind == "pid" else ""))
        if self.antiwindup != "none":
            parts.append(f"anti-windup {self.antiwindup}")
        return f"Controller({self.kind}: {', '.join(parts)})"


_GAIN_NAMES = {"kp": "proportional gain", "ki": "integral gain, 1/s", "kd": "derivative gain, s",
               "kv": "velocity gain"}
_USES = {"p": (), "pv": ("kv",), "pi": ("ki",), "pd": ("kd",), "pid": ("ki", "kd"), "tf": ()}


def _tracking_time(c: Controller, kp: Any, ki: Any, kd: Any) -> Any:
    """Back-calculation's tracking time ``Tt`` of ``c``'s structure at gains that may be arrays (see
    :meth:`Controller.default_tracking_time`)."""
    if c.tracking_time is not None:
        return np.full(np.shape(ki), c.tracking_time) if np.ndim(ki) else c.tracking_time
    kp, ki, kd = np.broadcast_arrays(np.asarray(kp, float), np.asarray(ki, float), np.asarray(kd, float))
    with np.errstate(divide="ignore", invalid="ignore"):
        ti = kp / ki
        tt = np.where((kp > 0) & (ki > 0), np.where((c.kind == "pid") & (kd > 0), np.sqrt(ti * kd / kp), ti),
                      np.where(ki != 0, 1.0 / np.abs(ki), 1.0))
    return tt if tt.ndim else float(tt)


def controller_branches(c: Controller, kp: Any = None, ki: Any = None, kd: Any = None,
                        kv: Any = None) -> tuple[Realisation, ...]:
    """The controller's law, defined once: its parallel branches (proportional, integral, derivative, velocity,
    or the transfer function), each a :class:`Realisation` on the reference, the measurement and its velocity.

    :meth:`Controller.realisation` is their parallel sum (:func:`parallel`), :meth:`Controller.feedback_polynomials`
    the sum of their feedback parts (:func:`feedback_transfer`), and the simulator's sweeps of many gains
    (``simulate_many(kp=...)``) evaluate them at arrays of gains: ``kp, ki, kd, kv`` default to the controller's
    and may be arrays of one shape (only the output row ``Cc``, the ``dv*`` terms and ``Baw`` depend on them;
    they then carry a leading axis of that shape).

    Examples
    --------
    >>> [b.order for b in controller_branches(Controller.pid(2.0, 0.5, 0.1, 0.02))]  # P, I, D
    [0, 1, 1]
    >>> import numpy as np
    >>> controller_branches(Controller.pi(1.0, 0.5), kp=np.array([1.0, 2.0]))[0].dvy.tolist()
    [-1.0, -2.0]
    """
    kp = c.kp if kp is None else kp
    ki = c.ki if ki is None else ki
    kd = c.kd if kd is None else kd
    kv = c.kv if kv is None else kv
    z = np.zeros
    scalar = not any(np.ndim(g) for g in (kp, ki, kd, kv))
    zero = 0.0 if scalar else 0.0 * sum(np.asarray(g, float) for g in (kp, ki, kd, kv))  # a gain-shaped zero

    def col(*v: Any) -> np.ndarray:  # an output row, gain-shaped: (..., k)
        if scalar:
            return np.array(v, float)
        return np.stack(np.broadcast_arrays(*(np.asarray(x, float) for x in v)), axis=-1)

    def static(dvr: Any, dvy: Any, dvv: Any = 0.0) -> Realisation:
        return Realisation(z((0, 0)), z(0), z(0), z(0), z(0), z(np.shape(zero) + (0,)), dvr, dvy, dvv, -1)

    if c.kind == "tf":
        A, B, C, D = c.transfer_function.state_space()
        n = A.shape[0]
        return (Realisation(np.atleast_2d(A).reshape(n, n), np.asarray(B, float).reshape(n),
                            -np.asarray(B, float).reshape(n), z(n), z(n), np.asarray(C, float).reshape(n),
                            float(D), -float(D), 0.0, -1),)
    if c.kind == "p":
        return (static(kp, -kp),)
    if c.kind == "pv" and not c.filtered:  # v = kp e - kv vm, the true velocity
        return (static(kp, -kp), static(zero, zero, -kv))
    if c.kind == "pv":  # - kv F(s) ym, F(s) = wf^2 s / (s^2 + 2 zf wf s + wf^2)
        w, zt = c.filter_wn, c.filter_zeta
        return (static(kp, -kp), Realisation(np.array([[0.0, 1.0], [-w * w, -2 * zt * w]]), z(2), np.array([0.0, 1.0]),
                                             z(2), z(2), col(zero, -kv * w * w), zero, zero, 0.0, -1))
    b, cw = c.setpoint_weight, c.derivative_weight
    branches = [static(b * kp, -kp)]  # kp (b r - ym)
    if c.has_integrator:  # ki xi, xi' = r - ym (+ back-calculation (u - v) / (ki Tt))
        aw = 1.0 / (ki * _tracking_time(c, kp, ki, kd)) if c.antiwindup == "backcalc" else zero
        branches.append(Realisation(z((1, 1)), np.array([1.0]), np.array([-1.0]), z(1), col(aw), col(ki), zero,
                                    zero, 0.0, 0))
    if c.kind in ("pd", "pid"):
        # the filter state low-passes ym - c r; the derivative is kd/Tf ((ym - c r) filtered minus (ym - c r))
        tf = c.derivative_filter
        branches.append(Realisation(np.array([[-1.0 / tf]]), np.array([-cw / tf]), np.array([1.0 / tf]), z(1), z(1),
                                    col(kd / tf), cw * kd / tf, -kd / tf, 0.0, -1))
    return tuple(branches)


def parallel(branches: tuple[Realisation, ...]) -> Realisation:
    """The parallel sum of realisations on the same inputs: block-diagonal states, outputs added.

    Examples
    --------
    >>> parallel(controller_branches(Controller.pid(2.0, 0.5, 0.1, 0.02))).Ac.tolist()
    [[0.0, 0.0], [0.0, -50.0]]
    """
    first = branches[0]
    if len(branches) == 1:
        return first
    n = sum(b.order for b in branches)
    Ac = np.zeros((n, n))
    k, integ = 0, -1
    for b in branches:
        Ac[k:k + b.order, k:k + b.order] = b.Ac
        if b.integ >= 0:
            integ = k + b.integ
        k += b.order
    cat = lambda name: np.concatenate([getattr(b, name) for b in branches])  # noqa: E731 (gain-free inputs)
    dv = {}
    for name in ("dvr", "dvy", "dvv"):
        total = getattr(first, name)
        for b in branches[1:]:
            total = total + getattr(b, name)
        dv[name] = total
    if all(np.ndim(b.Cc) == 1 and np.ndim(b.Baw) == 1 for b in branches):  # scalar gains
        Cc, Baw = cat("Cc"), cat("Baw")
    else:
        shape = np.broadcast_shapes(*(np.shape(b.Cc)[:-1] for b in branches),
                                    *(np.shape(b.Baw)[:-1] for b in branches))
        Cc = np.concatenate([np.broadcast_to(b.Cc, shape + (b.order,)) for b in branches], axis=-1)
        Baw = np.concatenate([np.broadcast_to(b.Baw, shape + (b.order,)) for b in branches], axis=-1)
    return Realisation(Ac, cat("Bcr"), cat("Bcy"), cat("Bcv"), Baw, Cc, dv["dvr"], dv["dvy"], dv["dvv"], integ)


def _adjugate(A: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """``det(sI - A)`` (highest power first) and the matrices ``N_k`` with
    ``adj(sI - A) = sum_k s^(n-1-k) N_k`` (Faddeev-LeVerrier: exact in the small controllers' structures)."""
    n = A.shape[0]
    coef, Ns = [1.0], []
    eye = np.eye(n)
    N = eye
    for k in range(1, n + 1):
        Ns.append(N)
        AN = A @ N
        ck = -float(np.trace(AN)) / k + 0.0  # + 0.0: no negative zeros
        coef.append(ck)
        N = AN + ck * eye
    return np.array(coef), Ns


def input_transfer(r: Realisation, b: np.ndarray, d: float) -> tuple[np.ndarray, np.ndarray]:
    """The law's transfer function from one of its inputs (the state input column ``b``, the feedthrough ``d``):
    the numerator ``Cc adj(sI - Ac) b + d det(sI - Ac)`` (``order + 1`` coefficients, highest power first) and the
    denominator ``det(sI - Ac)``.

    Examples
    --------
    >>> r = Controller.pi(2.0, 0.5).realisation()
    >>> [p.tolist() for p in input_transfer(r, r.Bcr, r.dvr)]   # 2 + 0.5/s from the reference
    [[2.0, 0.5], [1.0, 0.0]]
    """
    den, Ns = _adjugate(np.asarray(r.Ac, float))
    cc = np.asarray(r.Cc, float)
    q = np.array([cc @ N @ np.asarray(b, float) for N in Ns])
    return d * den + np.r_[0.0, q], den


def feedback_transfer(r: Realisation) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of the feedback part ``Cy(s)`` of a realisation's law ``v = ... - Cy(s) ym``,
    with the velocity read as ``s ym``: ``Cy = -(dvy + dvv s) - Cc adj(sI - Ac) (Bcy + s Bcv) / det(sI - Ac)``
    (scalar gains; a law that reads the command, a predictor's, has none).

    Examples
    --------
    >>> [p.tolist() for p in feedback_transfer(Controller.pd(2.0, 0.1, 0.02).realisation())]
    [[7.0, 100.0], [1.0, 50.0]]
    """
    ny, den = input_transfer(r, r.Bcy, r.dvy)
    num = -ny
    if r.dvv != 0.0 or np.any(r.Bcv):
        num = _padd(num, -np.r_[input_transfer(r, r.Bcv, r.dvv)[0], 0.0])
    return _trim(num), den


def feedback_response(c: Controller, s: Any, kp: Any = None, ki: Any = None, kd: Any = None,
                      kv: Any = None) -> np.ndarray:
    """The feedback part ``Cy(s)`` of the law ``v = ... - Cy(s) ym`` (the velocity read as ``s ym``) at the points
    ``s``: the sum of :func:`controller_branches`' feedback parts, each ``-(dvy + dvv s) - Cc (sI - Ac)^-1 (Bcy +
    s Bcv)``.  The gains are as there: the controller's, or arrays of one shape ``g``, which lead the result's
    shape, ``g + s.shape``.  (A pole of the law at ``s`` (an integrator's at 0) makes ``sI - Ac`` singular: an
    error.)

    Examples
    --------
    >>> np.round(feedback_response(Controller.pid(1.0, 0.5, 0.2, 0.02), [1j]), 6).tolist()  # 1 + 0.5/j + 0.2j/(0.02j + 1)
    [(1.003998-0.30008j)]
    >>> feedback_response(Controller.p(1.0), [1j, 2j], kp=np.array([1.0, 3.0])).real.tolist()
    [[1.0, 1.0], [3.0, 3.0]]
    """
    s = np.asarray(s, complex)
    z = s.reshape(-1)
    total: Any = 0.0
    for b in controller_branches(c, kp, ki, kd, kv):
        part = -(np.asarray(b.dvy, float)[..., None] + np.asarray(b.dvv, float)[..., None] * z)
        if b.order:  # (sI - Ac)^-1 (Bcy + s Bcv) at each s: (len(z), order)
            x = np.linalg.solve(z[:, None, None] * np.eye(b.order) - b.Ac, (b.Bcy + z[:, None] * b.Bcv)[..., None])
            part = part - np.asarray(b.Cc, float) @ x[..., 0].T
        total = total + part
    total = np.asarray(total)
    return total.reshape(total.shape[:-1] + s.shape)


def _padd(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The sum of two polynomials (highest power first) of any lengths."""
    if a.size < b.size:
        a, b = b, a
    out = a.copy()
    out[a.size - b.size:] += b
    return out


def _trim(p: np.ndarray) -> np.ndarray:
    """A polynomial without its leading zeros (at least one coefficient)."""
    nz = np.flatnonzero(p)
    return p[nz[0]:] + 0.0 if nz.size else np.zeros(1)
