"""The altitude loop of a quadrotor flown over a delayed link: the one model every part of delaykit uses.

The loop (the paper's Figs. 1-4)::

    z'(t)  = u(t - Td)                                   integrator plant, delay on the command
    u(t)   = sat(Kp (z_ref(t) - z(t)) - Kv w(t), vmax)   P (Kv = 0) or PV control
    w(t)   = z'(t)                                       velocity = "true"     -> neutral delay equation
    W(s)   = wf^2 s / (s^2 + 2 zf wf s + wf^2) Z(s)      velocity = "filtered" -> retarded delay equation

With ``period`` set, the controller samples z and w at ``sample_offset + k*period`` and holds its command
between samples.  Before the step (t < 0) the drone hovers: u = 0 and z = z0.

The derivative filter is a second-order low-pass filter in series with a differentiator.  It is the
transfer function whose poles are the paper's "-38 repeated" (wf = 38 rad/s, zf = 1), it has unit gain
at low frequency (so it measures the velocity and the loop keeps the same steady state), it is proper, and
as wf grows it tends to the true velocity.  See docs/guide/loops.md for how the paper's "cutoff 5.68 rad/s" fits.

Examples
--------
>>> loop = AltitudeLoop(kp=1.31, delay=0.368)
>>> loop
AltitudeLoop(kp=1.31, delay=0.368 s, vmax=±1 m/s, continuous)
>>> loop.characteristic()
QuasiPolynomial(s + 1.31·exp(-0.368 s))
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any, Literal

from ..errors import InvalidTypeError, InvalidValueError, check_real
from .loop import check_sampling
from .quasipolynomial import QuasiPolynomial

if TYPE_CHECKING:
    from .loop import Loop

__all__ = ["AltitudeLoop", "VELOCITY_CHOICES", "PAPER_PERIOD", "as_loop"]

VELOCITY_CHOICES = ("true", "filtered")
PAPER_PERIOD = 0.065
"""The AR.Drone 2.0 navdata and control period used in the paper, Ts = 0.065 s."""


@dataclass(frozen=True, repr=False)
class AltitudeLoop:
    """A P or PV altitude loop with a delay on the command.

    Parameters
    ----------
    kp : float
        Proportional gain (1/s), non-negative.
    delay : float
        The loop delay Td in seconds (any non-negative real).
    kv : float
        Velocity gain (dimensionless); 0 gives P control.
    vmax : float or None
        Saturation of the vertical-speed command, m/s; ``None`` for no saturation.
    velocity : {"true", "filtered"}
        The velocity fed to the Kv term: the true vertical speed, or the derivative filter's output.
    filter_wn, filter_zeta : float
        Natural frequency (rad/s) and damping of the derivative filter.
    period : float or None
        Controller period in seconds; ``None`` for a continuous controller.
    sample_offset : float
        Time of the first sample at or after the step, in ``[0, period)``.
    gain : float
        Effective gain of the drone's vertical speed: the plant moves at ``gain * u(t - Td)`` (1 = ideal).
    lag : float
        Time constant (s) of the drone's own vertical-speed loop, a first-order lag between the delayed
        command and the actual speed (0 = none, the paper's model).  With a lag the true-velocity loop is
        retarded, not neutral.

    Examples
    --------
    >>> AltitudeLoop(kp=2.0, delay=0.37, kv=0.3).characteristic().kind
    'neutral'
    >>> AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered").characteristic().kind
    'retarded'
    """

    kp: float
    delay: float
    kv: float = 0.0
    vmax: float | None = 1.0
    velocity: Literal["true", "filtered"] = "true"
    filter_wn: float = 38.0
    filter_zeta: float = 1.0
    period: float | None = None
    sample_offset: float = 0.0
    gain: float = 1.0
    lag: float = 0.0

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        set_("kp", check_real("kp (proportional gain)", self.kp, minimum=0.0))
        set_("kv", check_real("kv (velocity gain)", self.kv, minimum=0.0))
        set_("delay", check_real("delay", self.delay, minimum=0.0))
        if self.vmax is not None:
            v = check_real("vmax (command limit, m/s)", self.vmax, minimum=0.0, strict=True, allow_inf=True)
            set_("vmax", None if math.isinf(v) else v)
        if self.velocity not in VELOCITY_CHOICES:
            raise InvalidValueError(f"velocity must be one of {', '.join(VELOCITY_CHOICES)}; got {self.velocity!r}")
        set_("filter_wn", check_real("filter_wn (rad/s)", self.filter_wn, minimum=0.0, strict=True))
        set_("filter_zeta", check_real("filter_zeta", self.filter_zeta, minimum=0.0, strict=True))
        set_("gain", check_real("gain (effective speed gain)", self.gain, minimum=0.0, strict=True))
        set_("lag", check_real("lag (s)", self.lag, minimum=0.0))
        per, off = check_sampling(self.period, self.sample_offset)
        set_("period", per)
        set_("sample_offset", off)

    @property
    def filtered(self) -> bool:
        """True when the Kv term sees the derivative filter's output (and Kv > 0)."""
        return self.velocity == "filtered" and self.kv > 0.0

    @property
    def sampled(self) -> bool:
        """True for a sampled (zero-order hold) controller."""
        return self.period is not None

    def replace(self, **changes: Any) -> "AltitudeLoop":
        """A copy with some fields changed (validated again).

        Examples
        --------
        >>> AltitudeLoop(kp=1.31, delay=0.368).replace(delay=0.3).delay
        0.3
        """
        return dataclasses.replace(self, **changes)

    def characteristic(self) -> QuasiPolynomial:
        """The characteristic quasi-polynomial of the linearised loop (saturation ignored).

        P and PV with true velocity: ``s + (Kv s + Kp) exp(-s Td)`` (neutral when Kv > 0).
        PV with the filter ``F(s) = wf^2 s / D(s)``, ``D = s^2 + 2 zf wf s + wf^2``:
        ``s D(s) + (Kp D(s) + Kv wf^2 s) exp(-s Td)`` (retarded).  A lag ``T`` multiplies the first term by
        ``(T s + 1)`` and a gain ``g`` the delayed one.

        Raises
        ------
        InvalidValueError
            For a sampled controller, whose characteristic function is not a quasi-polynomial.

        Examples
        --------
        >>> AltitudeLoop(kp=2.0, delay=0.37, kv=0.3).characteristic()
        QuasiPolynomial(s + (0.3·s + 2)·exp(-0.37 s))
        """
        if self.sampled:
            raise InvalidValueError(
                f"a sampled controller (period {self.period:g} s) has no quasi-polynomial characteristic "
                "function; use the continuous loop (period=None) for roots"
            )
        import numpy as np

        plant = np.polymul([self.lag, 1.0], [1.0, 0.0]) if self.lag > 0 else np.array([1.0, 0.0])
        g = self.gain
        if not self.filtered:
            return QuasiPolynomial([plant, [g * self.kv, g * self.kp]], [0.0, self.delay])
        w, zeta = self.filter_wn, self.filter_zeta
        d = np.array([1.0, 2 * zeta * w, w * w])
        delayed = g * np.polyadd(self.kp * d, [self.kv * w * w, 0.0])
        return QuasiPolynomial([np.polymul(plant, d), delayed], [0.0, self.delay])

    @cached_property
    def system(self) -> Any:
        """The closed loop as a :class:`~delaykit.systems.DelayLTI` (built once): :attr:`Loop.system
        <delaykit.models.loop.Loop.system>` of :meth:`to_loop`.

        Examples
        --------
        >>> AltitudeLoop(kp=1.31, delay=0.368, vmax=None).system
        DelayLTI(loop: 2 inputs ['r', 'd'] -> 2 outputs ['y', 'u'], 1 state, delays [0.368] s)
        """
        return self.to_loop().system

    def to_loop(self) -> "Loop":
        """This loop as the general :class:`~delaykit.models.loop.Loop` (the paper's loops are its presets).

        The plant is ``gain / s`` (``gain / (s (lag s + 1))`` with a lag), the controller P or PV, the
        command limited to ``[-vmax, vmax]``.

        Examples
        --------
        >>> AltitudeLoop(kp=2.0, delay=0.37, kv=0.3).to_loop()
        Loop(paper: plant 1/s, pv: kp=2, kv=0.3, true velocity, delay=0.37 s, u in [-1, 1], continuous)
        """
        from .controllers import Controller
        from .loop import Loop
        from .plants import integrator, integrator_lag

        plant = integrator_lag(self.gain, self.lag) if self.lag > 0 else integrator(self.gain)
        if self.kv > 0:
            ctrl = Controller.pv(self.kp, self.kv, velocity=self.velocity, filter_wn=self.filter_wn,
                                 filter_zeta=self.filter_zeta)
        else:
            ctrl = Controller.p(self.kp)
        v = math.inf if self.vmax is None else self.vmax
        return Loop(plant, ctrl, delay=self.delay, umin=-v, umax=v, period=self.period,
                    sample_offset=self.sample_offset, name="paper")

    @classmethod
    def from_loop(cls, loop: Any) -> "AltitudeLoop":
        """The paper's loop that a general loop is (the inverse of :meth:`to_loop`), or an error saying why not.

        The paper's family: the plant ``gain / s`` or ``gain / (s (lag s + 1))`` with ``lag > 0``, P or PV
        control, the command limited symmetrically (``umin = -umax``, or no limit), the whole delay on the
        command (no ``output_delay``).  The estimators of :mod:`delaykit.identify.estimation` model this family
        only; :func:`delaykit.identify.identification.identify` takes any plant.

        Parameters
        ----------
        loop : Loop or AltitudeLoop
            The loop (an ``AltitudeLoop`` is returned as it is).

        Returns
        -------
        AltitudeLoop

        Raises
        ------
        InvalidValueError
            When the loop is outside the paper's family; the message names the part that is.
        InvalidTypeError
            When ``loop`` is not a loop object.

        See Also
        --------
        to_loop, as_loop

        Examples
        --------
        >>> from delaykit.models import Loop, Controller
        >>> AltitudeLoop.from_loop(Loop("0.9/(s*(0.1*s+1))", Controller.p(1.2), delay=0.3, umin=-1, umax=1))
        AltitudeLoop(kp=1.2, delay=0.3 s, vmax=±1 m/s, gain=0.9, lag=0.1 s, continuous)
        >>> lp = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, period=0.065)
        >>> AltitudeLoop.from_loop(lp.to_loop()) == lp
        True
        """
        from .loop import Loop

        if isinstance(loop, AltitudeLoop):
            return loop
        if not isinstance(loop, Loop):
            raise InvalidTypeError(f"expected a Loop or an AltitudeLoop, got {type(loop).__name__}: {loop!r}")
        where = f"the loop {loop!r} is not the paper's altitude loop"
        num, den = loop.plant.num, loop.plant.den
        order = den.size - 1
        if not (num.size == 1 and 1 <= order <= 2 and den[-1] == 0.0 and den[-2] != 0.0
                and (order == 1 or den[0] / den[1] > 0.0)):
            raise InvalidValueError(f"{where}: its plant {loop.plant.to_string(times=' ')} is not gain/s or "
                                    "gain/(s (lag s + 1)) with lag > 0")
        gain = float(num[0] / den[-2])
        lag = float(den[0] / den[-2]) if order == 2 else 0.0
        c = loop.controller
        if c.kind not in ("p", "pv"):
            raise InvalidValueError(f"{where}: its controller is {c.kind!r}, not P or PV")
        if loop.output_delay != 0.0:
            raise InvalidValueError(f"{where}: it has a measurement delay ({loop.output_delay:g} s); give the "
                                    "whole loop delay as the input delay")
        if loop.umin != -loop.umax:
            raise InvalidValueError(f"{where}: its command limits [{loop.umin:g}, {loop.umax:g}] are not "
                                    "symmetric (the paper's +-vmax)")
        pv = c.kind == "pv"
        return cls(kp=c.kp, delay=loop.delay, kv=c.kv if pv else 0.0,
                   vmax=None if math.isinf(loop.umax) else float(loop.umax),
                   velocity=c.velocity if pv else "true", filter_wn=c.filter_wn if pv else 38.0,
                   filter_zeta=c.filter_zeta if pv else 1.0, period=loop.period, sample_offset=loop.sample_offset,
                   gain=gain, lag=lag)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``vmax`` and ``period`` are ``null`` when absent)."""
        return dataclasses.asdict(self)

    def __repr__(self) -> str:
        parts = [f"kp={self.kp:g}", f"delay={self.delay:.4g} s"]
        if self.kv:
            parts.append(f"kv={self.kv:g}")
            parts.append(
                f"filtered velocity (wn={self.filter_wn:g} rad/s, zeta={self.filter_zeta:g})"
                if self.filtered
                else "true velocity"
            )
        parts.append(f"vmax=±{self.vmax:g} m/s" if self.vmax is not None else "no saturation")
        if self.gain != 1.0:
            parts.append(f"gain={self.gain:g}")
        if self.lag:
            parts.append(f"lag={self.lag:g} s")
        parts.append(
            f"sampled every {self.period:g} s" + (f" from {self.sample_offset:g} s" if self.sample_offset else "")
            if self.sampled
            else "continuous"
        )
        return f"AltitudeLoop({', '.join(parts)})"


def as_loop(loop: Any) -> "Loop":
    """The general :class:`~delaykit.models.loop.Loop` of a loop object (an ``AltitudeLoop`` is a preset).

    Examples
    --------
    >>> as_loop(AltitudeLoop(kp=1.31, delay=0.368)).plant.to_string()
    '1/s'
    """
    from .loop import Loop

    if isinstance(loop, Loop):
        return loop
    if isinstance(loop, AltitudeLoop):
        return loop.to_loop()
    raise InvalidTypeError(f"loop must be a Loop or an AltitudeLoop, got {type(loop).__name__}")
