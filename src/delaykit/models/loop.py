"""The loop: a plant, a controller, delays, an actuator's limits and an optional sampling period.

::

    r --> controller --v--> sat[umin, umax] --u--> delay Ti --(+ d)--> plant --y--+
          ^                                                                      |
          +--------------------------- delay To <--------------------------------+

* the **plant** is any proper rational transfer function (:class:`~delaykit.models.transfer.TransferFunction`),
  written as text (``"1/(s*(0.05*s+1))"``), coefficients, a state-space quadruple, a python-control object,
  or made by one of the families in :mod:`delaykit.models.plants`;
* the **input delay** ``delay`` (``Ti``) acts on the command, the **output delay** ``output_delay`` (``To``) on
  the measurement.  They are equivalent (the output is the same, shifted by ``To``) when nothing enters
  the loop between them: with a load disturbance at the plant input, or a measured output read before
  the output delay, they differ (see docs/guide/loops.md);
* the **controller** is a :class:`~delaykit.models.controllers.Controller`;
* the **actuator** clips the command to ``[umin, umax]`` (either may be infinite; ``umin <= 0 <= umax``
  so that rest is an equilibrium);
* **sampling**: with ``period`` set, the command is sampled at ``sample_offset + k period`` and held
  (zero-order hold); the controller's own states run in continuous time.

All signals are deviations from the operating point at which the loop rests before t = 0.

Examples
--------
>>> loop = Loop("1/(s*(0.05*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=0.3, umin=-1, umax=3)
>>> loop
Loop(plant 1/(0.05 s^2 + s), pd: kp=2, kd=0.1, Tf=0.02 s, delay=0.3 s, u in [-1, 3], continuous)
>>> loop.characteristic().kind
'retarded'
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_path, check_real
from .compensators import Compensator
from .controllers import Controller, input_transfer
from .quasipolynomial import QuasiPolynomial
from .transfer import TransferFunction

__all__ = ["Loop", "LOOP_KEYS", "loop_from_dict", "load_loop", "loop_to_toml", "check_sampling", "read_toml"]


def check_sampling(period: Any, sample_offset: Any) -> tuple[float | None, float]:
    """A validated sampling period (``None``: continuous) and first-sample offset in ``[0, period)``.

    Examples
    --------
    >>> check_sampling(0.065, 0.03)
    (0.065, 0.03)
    """
    if period is None:
        return None, check_real("sample_offset (s)", sample_offset, minimum=0.0, maximum=0.0)
    per = check_real("period (s)", period, minimum=0.0, strict=True)
    off = check_real("sample_offset (s)", sample_offset, minimum=0.0)
    if off >= per:
        raise InvalidValueError(f"sample_offset must be less than the period {per:g} s, got {off:g}")
    return per, off


@dataclass(frozen=True, repr=False, eq=False)
class Loop:
    """A delayed feedback loop (see the module docstring).

    Parameters
    ----------
    plant : TransferFunction, str, tuple or python-control object
        The plant from the (delayed) command to the output.
    controller : Controller
        The control law.
    delay : float
        Input delay ``Ti`` (s), on the command.
    output_delay : float
        Output delay ``To`` (s), on the measurement.
    umin, umax : float
        The actuator's limits (``-inf`` and ``inf`` for none).
    period : float or None
        Controller period (s); ``None`` for a continuous controller.
    sample_offset : float
        Time of the first sample at or after t = 0, in ``[0, period)``.
    name : str
        A label for presets (shown by ``repr`` when set).

    Examples
    --------
    >>> Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02), delay=12.0, umin=-50, umax=50).plant.dc_gain()
    0.62
    """

    plant: Any
    controller: Controller = field(default_factory=lambda: Controller.p(1.0))
    delay: float = 0.0
    output_delay: float = 0.0
    umin: float = -math.inf
    umax: float = math.inf
    period: float | None = None
    sample_offset: float = 0.0
    name: str = ""

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        set_("plant", TransferFunction.coerce(self.plant, name="plant"))
        if not isinstance(self.controller, (Controller, Compensator)):
            raise InvalidTypeError(
                f"controller must be a Controller or a Compensator, got {type(self.controller).__name__}")
        set_("delay", check_real("delay (input delay, s)", self.delay, minimum=0.0))
        set_("output_delay", check_real("output_delay (s)", self.output_delay, minimum=0.0))
        lo = check_real("umin (lower command limit)", self.umin, maximum=0.0, allow_neg_inf=True)
        hi = check_real("umax (upper command limit)", self.umax, minimum=0.0, allow_inf=True)
        if not lo < hi:
            raise InvalidValueError(f"umin must be below umax; got umin={lo:g}, umax={hi:g}")
        set_("umin", lo)
        set_("umax", hi)
        per, off = check_sampling(self.period, self.sample_offset)
        set_("period", per)
        set_("sample_offset", off)
        if self.controller.uses_velocity and not self.plant.is_strictly_proper:
            raise InvalidValueError(
                "the PV law with the true velocity needs a strictly proper plant (its output's derivative "
                f"must exist); the plant {self.plant.to_string(times=' ')} has a direct feedthrough")
        if not isinstance(self.name, str):
            raise InvalidTypeError(f"name must be text, got {type(self.name).__name__}")

    # -- properties -------------------------------------------------------------------------------------
    @property
    def total_delay(self) -> float:
        """The delay around the loop, ``Ti + To`` (s)."""
        return self.delay + self.output_delay

    @property
    def sampled(self) -> bool:
        """True for a sampled (zero-order hold) controller."""
        return self.period is not None

    @property
    def saturated(self) -> bool:
        """True when the command has a finite limit."""
        return math.isfinite(self.umin) or math.isfinite(self.umax)

    @cached_property
    def system(self) -> Any:
        """The closed loop as a :class:`~delaykit.systems.DelayLTI`, built once (then cached) by
        :func:`~delaykit.systems.from_loop`: inputs ``["r", "d"]`` (reference, load disturbance), outputs
        ``["y", "u"]`` (plant output, command), the limits as a saturation channel.

        A loop is a named constructor (a preset) of this system: ``poles``, ``is_stable``, ``step_response``,
        ``forced_response`` and ``hinfnorm`` take the loop itself and analyse this system.  A sampled loop has none
        (:class:`~delaykit.errors.InvalidValueError`).

        Examples
        --------
        >>> loop = Loop("1/(s+1)", Controller.pi(2.0, 1.0), delay=0.1)
        >>> loop.system
        DelayLTI(loop: 2 inputs ['r', 'd'] -> 2 outputs ['y', 'u'], 2 states, delays [0.1] s)
        >>> loop.system is loop.system
        True
        """
        from ..systems.build import from_loop  # layer 2: the loop is a preset of the system it builds

        return from_loop(self)

    def replace(self, **changes: Any) -> "Loop":
        """A copy with some fields changed (validated again); controller fields may be given directly.

        Examples
        --------
        >>> Loop("1/s", Controller.p(1.0), delay=0.3).replace(kp=2.0, delay=0.4).controller.kp
        2.0
        """
        ctrl = {k: changes.pop(k) for k in list(changes) if k in _CONTROLLER_FIELDS}
        if "vmax" in changes:
            if "umin" in changes or "umax" in changes:
                raise InvalidValueError("give vmax or umin/umax, not both")
            v = changes.pop("vmax")
            v = math.inf if v is None else check_real("vmax (command limit)", v, minimum=0.0, strict=True, allow_inf=True)
            changes.update(umin=-v, umax=v)
        if ctrl:
            changes["controller"] = changes.get("controller", self.controller).replace(**ctrl)
        try:
            return dataclasses.replace(self, **changes)
        except TypeError as exc:
            raise InvalidValueError(f"a loop has no field among {sorted(changes)}: {exc}") from None

    # -- analysis ---------------------------------------------------------------------------------------
    def characteristic(self) -> QuasiPolynomial:
        """The characteristic quasi-polynomial ``Dp(s) Dc(s) + Np(s) Nc(s) exp(-s (Ti + To))`` of the
        linear loop (saturation ignored), with ``Np/Dp`` the plant and ``Nc/Dc`` the controller's
        feedback part.

        Raises
        ------
        InvalidValueError
            For a sampled controller, whose characteristic function is not a quasi-polynomial.

        Examples
        --------
        >>> Loop("1/s", Controller.pv(2.0, 0.3), delay=0.37).characteristic()
        QuasiPolynomial(s + (0.3·s + 2)·exp(-0.37 s))
        """
        if self.sampled:
            raise InvalidValueError(
                f"a sampled controller (period {self.period:g} s) has no quasi-polynomial characteristic "
                "function; use the continuous loop (period=None) for roots")
        if isinstance(self.controller, Compensator):
            return self._compensated_characteristic()
        num, den = self.open_loop()
        return QuasiPolynomial([den, num], [0.0, self.total_delay])

    def _compensated_characteristic(self) -> QuasiPolynomial:
        """``Dc Dp - Nu Dp - Nm Dp exp(-s Tm) - Ny Np exp(-s T)``: the law ``u = Gy ym + Gu u + Gm u(t - Tm)``
        (each ``N / Dc``) closed around the plant, with the structural roots at 0 divided out where the three
        polynomials share them (see :meth:`structural_roots_kept`)."""
        polys = self.compensated_polynomials()
        return QuasiPolynomial(list(polys), [0.0, self.controller.model_delay, self.total_delay])

    def compensated_polynomials(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The three polynomials ``(A0, A1, A2)`` of a compensated loop's characteristic function
        ``A0(s) + A1(s) exp(-s Tm) + A2(s) exp(-s T)`` (``Tm`` the model's delay, ``T`` the loop's), kept apart
        even when ``Tm = T``; the loop transfer function broken at the plant input, after the branch where the
        compensator reads the command, is ``A2 exp(-s T) / (A0 + A1 exp(-s Tm))``.

        Examples
        --------
        >>> from delaykit.models.compensators import Compensator
        >>> c = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)
        >>> [p.round(12).tolist() for p in Loop("1/s", c, delay=0.37).compensated_polynomials()]
        [[1.0, 5.0], [-5.0], [5.0]]
        """
        return self._compensated_split()[0]

    def structural_roots_kept(self) -> int:
        """How many roots at ``s = 0`` of :meth:`characteristic` are the compensator's structural ones, left in.

        A compensator with an integrating model fixes a window integral of the command by its history: a root
        at 0 that the loop never excites (:meth:`Compensator.structural_zeros`).  It is divided out of the three
        polynomials when they all vanish at 0; when the plant lacks the model's integrator (a model mismatch)
        only their sum does, and the quotient is not a quasi-polynomial, so the root stays in
        :meth:`characteristic` and this says how many stay. :func:`~delaykit.spectrum.stability.rightmost` and
        the margins' stability leave them out; a root search of the quasi-polynomial lists them.

        Examples
        --------
        >>> from delaykit.models.compensators import Compensator
        >>> c = Compensator.smith("1/s", 0.4, closed_loop_time=1.0)
        >>> Loop("1/s", c, delay=0.4).structural_roots_kept(), Loop("1/(s+0.1)", c, delay=0.4).structural_roots_kept()
        (0, 1)
        """
        if not isinstance(self.controller, Compensator):
            return 0
        return self._compensated_split()[1]

    def _compensated_split(self) -> tuple[tuple[np.ndarray, np.ndarray, np.ndarray], int]:
        if not isinstance(self.controller, Compensator):
            raise InvalidValueError("compensated_polynomials() is for a loop whose controller is a Compensator; "
                                    f"this one has a {self.controller.kind} controller (see open_loop())")
        rz = self.controller.realisation()
        dc = input_transfer(rz, rz.Bcy, rz.dvy)[1]

        def num(b: np.ndarray, d: float) -> np.ndarray:  # Cc adj(sI - Ac) b + d Dc
            return input_transfer(rz, b, d)[0]

        np_, dp = self.plant.num, self.plant.den
        polys = [np.polysub(np.polymul(dc, dp), np.polymul(num(rz.Bcu, 0.0), dp)),
                 -np.polymul(num(rz.Bcm, 0.0), dp), -np.polymul(num(rz.Bcy, rz.dvy), np_)]
        k = self.controller.structural_zeros()
        scale = max(float(np.max(np.abs(p))) for p in polys)
        polys = [np.where(np.abs(p) <= 1e-12 * scale, 0.0, p) for p in polys]  # cancellations' rounding
        kept = k
        for _ in range(k):
            if any(abs(p[-1]) > 1e-9 * scale for p in polys if p.size):
                break  # not a root of each (a plant without the model's integrator): it stays, counted in `kept`
            polys = [p[:-1] if p.size > 1 else np.zeros(1) for p in polys]
            kept -= 1
        return (polys[0], polys[1], polys[2]), kept

    def open_loop(self) -> tuple[np.ndarray, np.ndarray]:
        """Numerator and denominator of the loop transfer function without its delay, broken at the plant
        input: ``L(s) exp(s (Ti + To)) = Np(s) Nc(s) / (Dp(s) Dc(s))`` (saturation and sampling ignored).

        Examples
        --------
        >>> [c.tolist() for c in Loop("1/s", Controller.pv(2.0, 0.3)).open_loop()]
        [[0.3, 2.0], [1.0, 0.0]]
        """
        if isinstance(self.controller, Compensator):
            raise InvalidValueError(
                f"a loop with a {self.controller.kind} compensator has two delays, so its loop transfer function "
                "is not a rational function times one delay; use its characteristic function (roots) instead")
        nc, dc = self.controller.feedback_polynomials()
        return np.polymul(self.plant.num, nc), np.polymul(self.plant.den, dc)

    # -- input and output -------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (infinite limits and no period are ``null``)."""
        return {
            "plant": self.plant.to_string(digits=17),
            "controller": self.controller.to_dict(),
            "delay": self.delay,
            "output_delay": self.output_delay,
            "umin": self.umin if math.isfinite(self.umin) else None,
            "umax": self.umax if math.isfinite(self.umax) else None,
            "period": self.period,
            "sample_offset": self.sample_offset,
            **({"name": self.name} if self.name else {}),
        }

    def __repr__(self) -> str:
        law = repr(self.controller)
        parts = [f"plant {self.plant.to_string(times=' ')}", law[law.index("(") + 1:-1],
                 f"delay={self.delay:.4g} s"]
        if self.output_delay:
            parts.append(f"output delay={self.output_delay:.4g} s")
        if self.saturated:
            parts.append(f"u in [{self.umin:g}, {self.umax:g}]")
        else:
            parts.append("no saturation")
        parts.append(
            f"sampled every {self.period:g} s" + (f" from {self.sample_offset:g} s" if self.sample_offset else "")
            if self.sampled else "continuous")
        label = f"{self.name}: " if self.name else ""
        return f"Loop({label}{', '.join(parts)})"


_CONTROLLER_FIELDS = ("kp", "ki", "kd", "kv", "derivative_filter", "velocity", "filter_wn", "filter_zeta",
                      "antiwindup", "tracking_time", "setpoint_weight", "derivative_weight")
LOOP_KEYS = ("plant", "controller", "delay", "output_delay", "umin", "umax", "vmax", "period", "sample_offset",
             "name") + _CONTROLLER_FIELDS


def loop_from_dict(d: dict[str, Any], *, source: str = "loop") -> Loop:
    """A loop from a flat mapping (a loop file's contents): ``plant``, ``controller`` (a kind or a
    transfer function), the gains, the delays, the limits (``umin``/``umax`` or ``vmax``) and sampling.

    Examples
    --------
    >>> loop_from_dict({"plant": "1/s", "controller": "pv", "kp": 2.0, "kv": 0.3, "delay": 0.37, "vmax": 1})
    Loop(plant 1/s, pv: kp=2, kv=0.3, true velocity, delay=0.37 s, u in [-1, 1], continuous)
    """
    if not isinstance(d, dict):
        raise InvalidTypeError(f"{source}: a loop must be a table of keys, got {type(d).__name__}")
    unknown = sorted(set(d) - set(LOOP_KEYS))
    if unknown:
        raise InvalidValueError(f"{source}: unknown key(s) {', '.join(map(repr, unknown))}; "
                                f"expected some of {', '.join(LOOP_KEYS)}")
    if "plant" not in d:
        raise InvalidValueError(f"{source}: the loop needs a plant (for example plant = \"1/s\")")
    g = dict(d)
    if "vmax" in g:
        if "umin" in g or "umax" in g:
            raise InvalidValueError(f"{source}: give vmax or umin/umax, not both")
        v = check_real("vmax (command limit)", g.pop("vmax"), minimum=0.0, strict=True, allow_inf=True)
        g["umin"], g["umax"] = -v, v
    ctrl_kw = {k: g.pop(k) for k in _CONTROLLER_FIELDS if k in g}
    kind = g.pop("controller", "p")
    plant, delay = g.pop("plant"), None
    if isinstance(plant, str):
        try:
            plant, delay = TransferFunction.parse_with_delay(plant)
        except InvalidValueError as exc:
            raise InvalidValueError(f"{source}: plant: {exc}") from None
    if delay:
        g["delay"] = check_real("delay", g.get("delay", 0.0), minimum=0.0) + delay
    return Loop(plant=plant, controller=Controller.make(kind, **ctrl_kw), **g)


def load_loop(path: str | Path) -> Loop:
    """Read a loop from a TOML file (keys as in :func:`loop_from_dict`).

    Examples
    --------
    >>> import tempfile, os
    >>> with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
    ...     _ = f.write('plant = "1/s"\\ncontroller = "p"\\nkp = 1.31\\ndelay = 0.368\\nvmax = 1.0\\n')
    >>> load_loop(f.name).controller.kp
    1.31
    >>> os.unlink(f.name)
    """
    return loop_from_dict(read_toml(check_path("loop file", path), "loop file"), source=str(path))


def read_toml(path: str | Path, what: str, *, max_bytes: int | None = None) -> dict[str, Any]:
    """The contents of a TOML file; every failure an :class:`InvalidValueError` naming ``what`` and the path.

    Only a regular file of at most ``max_bytes`` (default :data:`~delaykit.models.budget.MAX_CONFIG_BYTES`) is read.

    Examples
    --------
    >>> read_toml("/nonexistent.toml", "loop file")
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: cannot read the loop file '/nonexistent.toml': No such file or directory
    """
    import tomllib

    from .budget import MAX_CONFIG_BYTES, read_regular

    p = Path(path)
    try:  # (a regular file only, of bounded size: /dev/zero or a FIFO is refused before a byte is read)
        text = read_regular(p, what, MAX_CONFIG_BYTES if max_bytes is None else max_bytes).decode("utf-8-sig")
    except OSError as exc:
        raise InvalidValueError(f"cannot read the {what} {str(p)!r}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InvalidValueError(f"the {what} {str(p)!r} is not UTF-8 text") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InvalidValueError(f"the {what} {str(p)!r} is not valid TOML: {exc}") from None
    except RecursionError:
        raise InvalidValueError(f"the {what} {str(p)!r} is nested too deeply to read") from None
    except ValueError as exc:  # e.g. an integer of thousands of digits (Python's limit on int conversion)
        raise InvalidValueError(f"the {what} {str(p)!r} cannot be read: {exc}") from None


def loop_to_toml(loop: Loop) -> str:
    """A loop file's text (TOML, the flat keys of :func:`loop_from_dict`) that :func:`load_loop` reads back.

    Only a P, PV, PI, PD or PID controller can be written (a transfer-function law or a compensator cannot).

    Examples
    --------
    >>> text = loop_to_toml(Loop("1/s", Controller.pi(0.76, 0.31, setpoint_weight=0.5), delay=0.37, umin=-1, umax=1))
    >>> import tomllib; loop_from_dict(tomllib.loads(text)).controller
    Controller(pi: kp=0.76, ki=0.31, b=0.5)
    """
    import json

    c = loop.controller
    if not isinstance(c, Controller) or c.kind == "tf":
        raise InvalidValueError("only a p, pv, pi, pd or pid loop can be written as a loop file")
    d: dict[str, Any] = {"plant": loop.plant.to_string(digits=17), **{k: v for k, v in c.to_dict().items()}}
    d["controller"] = d.pop("kind")
    if c.tracking_time is None:
        d.pop("tracking_time", None)
    d.update(delay=loop.delay, output_delay=loop.output_delay)
    for k in ("umin", "umax"):
        if math.isfinite(getattr(loop, k)):
            d[k] = getattr(loop, k)
    if loop.period is not None:
        d.update(period=loop.period, sample_offset=loop.sample_offset)
    if loop.name:
        d["name"] = loop.name
    return "".join(f"{k} = {json.dumps(v) if isinstance(v, str) else repr(float(v))}\n" for k, v in d.items())
