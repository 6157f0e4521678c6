"""Any controller of delaykit run packet by packet on a real vehicle: the flight law.

A flight has only what the packets bring: the altitude ``y`` and the vertical speed ``vm`` at each arrival time,
at uneven intervals.  :class:`FlightLaw` runs a :class:`~delaykit.models.controllers.Controller` or a
:class:`~delaykit.models.compensators.Compensator` on them through the realisation the simulator uses
(:class:`~delaykit.models.controllers.Realisation`)::

    xc' = Ac xc + Bcr r + Bcy y + Bcv vm + Baw (u - v) + Bcu u + Bcm u(t - Tm),   v = Cc xc + dvr r + dvy y + dvv vm

When a packet arrives, the states are advanced over the interval since the previous packet with the new packet's
reference and measurements held over it (the newest values: the law reacts to a packet in the packet's own update,
not one packet later), the command ``u`` at the one it sent at the previous packet, and ``u(t - Tm)`` (a
predictor's model input) read from the law's own history of commands, so it may change inside the interval: the
interval is cut there.  Every piece is
advanced exactly (the matrix exponential of the piece's linear system), whatever its length: the law does not
assume a period.  At each packet the law computes ``v`` and sends ``u = min(max(v, umin), umax)``.

Saturation, as in the simulator's controllers:

* back-calculation (``antiwindup="backcalc"``, and predictor feedback): over an interval that follows a saturated
  command, the term ``Baw (u - v(t))`` is active (``v(t)`` moves with the states: it is part of the linear system);
* clamping: over an interval that follows a saturated command, the integrator is frozen if its input at the packet
  pushes the command further into the limit;
* a compensator's model reads the command as sent, that is, saturated.

The states start at rest on the first packet's values (the least-squares rest point, e.g. the derivative filter of
the paper's PV law settled on the first altitude, integrators at zero), the command history empty (``u = 0``
before: a hover).

Examples
--------
>>> from delaykit.models import Compensator
>>> law = FlightLaw(Compensator.smith("1/s", 0.37, closed_loop_time=0.1), umin=-1.0, umax=1.0)
>>> law.update(0.0, r=1.0, y=0.0, vm=0.0)   # a 1 m step: the primary P law saturates
1.0
>>> round(law.update(0.065, r=1.0, y=0.0, vm=0.0), 6)
1.0
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.compensators import Compensator
from ..models.controllers import Controller
from ..models.hold import hold_matrices

__all__ = ["FlightLaw", "Relay", "RelayLaw"]


class FlightLaw:
    """A controller run on packets (see the module docstring).

    Parameters
    ----------
    controller : Controller or Compensator
        The law.
    umin, umax : float
        The command's limits (m/s).

    Attributes
    ----------
    order : int
        The number of controller states.
    model_delay : float
        The compensator's model delay ``Tm`` (0 for a plain controller).

    Examples
    --------
    >>> law = FlightLaw(Controller.pv(2.0, 0.3), umin=-1.0, umax=1.0)
    >>> round(law.update(0.0, r=1.2, y=1.0, vm=0.1), 12)   # 2 * 0.2 - 0.3 * 0.1
    0.37
    """

    def __init__(self, controller: Controller | Compensator, *, umin: float, umax: float) -> None:
        if not isinstance(controller, (Controller, Compensator)):
            raise InvalidTypeError(f"a flight law needs a Controller or a Compensator, got {type(controller).__name__}")
        self.umin = check_real("umin (m/s)", umin)
        self.umax = check_real("umax (m/s)", umax)
        if not self.umin < self.umax:
            raise InvalidValueError(f"umin must be below umax, got {self.umin:g} and {self.umax:g}")
        self.controller = controller
        r = controller.realisation()
        n = r.order
        self.order = n
        self.model_delay = float(r.model_delay)
        zero = np.zeros(n)
        self._A = np.asarray(r.Ac, float).reshape(n, n)
        # inputs in this order: r, y, vm, u, u(t - Tm)
        self._B = np.column_stack([np.asarray(b, float).reshape(n) if b is not None else zero
                                   for b in (r.Bcr, r.Bcy, r.Bcv, r.Bcu, r.Bcm)]) if n else np.zeros((0, 5))
        self._Baw = np.asarray(r.Baw, float).reshape(n) if n else zero
        self._C = np.asarray(r.Cc, float).reshape(n) if n else zero
        self._d = np.array([r.dvr, r.dvy, r.dvv])
        self._integ = int(r.integ)
        self._aw = controller.antiwindup if controller.has_integrator else "none"
        self._x: np.ndarray | None = None
        self._last: tuple[float, float, float] | None = None  # the previous packet's t, u and v
        self._hist_t: list[float] = []
        self._hist_u: list[float] = []

    # -- the pieces ----------------------------------------------------------------------------------------
    def _u_at(self, t: float) -> float:
        """The command in force at time ``t`` (0 before the first)."""
        k = bisect.bisect_right(self._hist_t, t) - 1
        return self._hist_u[k] if k >= 0 else 0.0

    def _system(self, saturated: bool, frozen: bool) -> tuple[np.ndarray, np.ndarray]:
        A, B = self._A, self._B
        if saturated and self._aw == "backcalc" and np.any(self._Baw):
            # Baw (u - v), with v = C x + dvr r + dvy y + dvv vm: a change of the linear system
            A = A - np.outer(self._Baw, self._C)
            B = B.copy()
            B[:, :3] -= np.outer(self._Baw, self._d)
            B[:, 3] += self._Baw
        if frozen:
            A, B = A.copy(), B.copy()
            A[self._integ, :] = 0.0
            B[self._integ, :] = 0.0
        return A, B

    def _advance(self, t0: float, t1: float, w: np.ndarray, saturated: bool, frozen: bool) -> None:
        """States from t0 to t1 with r, y and vm held at ``w[:3]``; u and u(t - Tm) from the history."""
        A, B = self._system(saturated, frozen)
        tm = self.model_delay
        cuts = {t0, t1}
        k = bisect.bisect_right(self._hist_t, t0)
        while k < len(self._hist_t) and self._hist_t[k] < t1:  # commands recorded between packets (a hover)
            cuts.add(self._hist_t[k])
            k += 1
        if tm > 0:
            k = bisect.bisect_right(self._hist_t, t0 - tm)
            while k < len(self._hist_t) and self._hist_t[k] + tm < t1:
                cuts.add(self._hist_t[k] + tm)
                k += 1
        edges = sorted(cuts)
        x = self._x
        wi = w.copy()
        for a, b in zip(edges[:-1], edges[1:]):
            h = b - a
            if h <= 0.0:
                continue
            mid = 0.5 * (a + b)  # (at the midpoint: a cut that rounding puts a hair off a command's time is harmless)
            wi[3] = self._u_at(mid)
            wi[4] = self._u_at(mid - tm) if tm > 0 else 0.0
            Phi, Gam = hold_matrices(A, B, h)
            x = Phi @ x + Gam @ wi
        self._x = x

    def _rest(self, r: float, y: float, vm: float) -> np.ndarray:
        """The least-squares rest point of the states for these inputs and no command."""
        n = self.order
        if n == 0:
            return np.zeros(0)
        rhs = -(self._B @ np.array([r, y, vm, 0.0, 0.0]))
        x, *_ = np.linalg.lstsq(self._A, rhs, rcond=None)
        if self._integ >= 0:
            x[self._integ] = 0.0
        return x

    # -- the law ---------------------------------------------------------------------------------------------
    def output(self, r: float, y: float, vm: float) -> float:
        """The law's unsaturated output ``v`` for these values at the current states."""
        return float(self._C @ self._x + self._d @ np.array([r, y, vm])) if self.order else float(
            self._d @ np.array([r, y, vm]))

    def update(self, t: float, *, r: float, y: float, vm: float = 0.0, sent: float | None = None) -> float:
        """Advance the states to the packet at ``t`` (s) and return the command to send.

        Parameters
        ----------
        t : float
            The packet's arrival time (s, increasing).
        r, y, vm : float
            The reference, the altitude and the measured vertical speed.
        sent : float, optional
            The command actually sent at ``t``, when it was not this law's (replaying a log to warm the law up
            before it takes over); the law's states and history then follow that command.

        Returns
        -------
        float
            The saturated command (``sent`` when given).

        Examples
        --------
        >>> law = FlightLaw(Controller.p(1.31), umin=-1.0, umax=1.0)
        >>> law.update(0.0, r=1.0, y=0.5)
        0.655
        """
        for name, val in (("t", t), ("r", r), ("y", y), ("vm", vm)):
            if not math.isfinite(val):
                raise InvalidValueError(f"{name} must be finite, got {val!r}")
        if self._last is None:
            self._x = self._rest(r, y, vm)
        else:
            t0, u0, v0 = self._last
            if t < t0:
                raise InvalidValueError(f"packet times must not go back: {t!r} after {t0!r}")
            if self.order:
                saturated = u0 != v0
                frozen = False
                w = np.array([r, y, vm, u0, 0.0])
                if saturated and self._aw == "clamp" and self._integ >= 0:
                    w[4] = self._u_at(t0 - self.model_delay) if self.model_delay else 0.0
                    rate = float(self._A[self._integ] @ self._x + self._B[self._integ] @ w)
                    frozen = rate * self._C[self._integ] * (u0 - v0) < 0  # (u - v < 0: at the upper limit)
                self._advance(t0, t, w, saturated, frozen)
        v = self.output(r, y, vm)
        u = min(max(v, self.umin), self.umax)
        if sent is not None:
            if not math.isfinite(sent):
                raise InvalidValueError(f"sent must be finite, got {sent!r}")
            u = v = float(sent)
        self._last = (t, u, v)
        self._hist_t.append(t)
        self._hist_u.append(u)
        # keep the history two model delays and a second long (what the next intervals can read), not the flight
        cut = bisect.bisect_left(self._hist_t, t - 2 * self.model_delay - 1.0)
        if cut > 64:
            del self._hist_t[:cut - 1], self._hist_u[:cut - 1]
        return u

    def record(self, t: float, u: float) -> None:
        """Note a command sent between packets by someone else (a hover while the flight loop estimates).

        Examples
        --------
        >>> law = FlightLaw(Controller.p(1.0), umin=-1, umax=1)
        >>> law.update(0.0, r=0.5, y=0.0)
        0.5
        >>> law.record(0.05, 0.0)
        """
        if self._hist_t and t < self._hist_t[-1]:
            raise InvalidValueError(f"a recorded command's time must not go back: {t!r} after {self._hist_t[-1]!r}")
        self._hist_t.append(float(t))
        self._hist_u.append(float(u))

    def describe(self) -> dict[str, Any]:
        """The law as JSON: the controller's own form and the limits.

        Examples
        --------
        >>> FlightLaw(Controller.p(1.31), umin=-1, umax=1).describe()["umax"]
        1.0
        """
        return {"controller": self.controller.to_dict(), "umin": self.umin, "umax": self.umax}


@dataclass(frozen=True)
class Relay:
    """An Astrom-Hagglund relay for a relay experiment in flight: ``u = +amplitude`` when the error ``r - y`` is
    above ``hysteresis``, ``-amplitude`` when it is below ``-hysteresis``, held in between (it starts at
    ``+amplitude`` when the first error is inside the band).  :meth:`law` gives the packet-by-packet law.

    Examples
    --------
    >>> Relay(0.5, 0.01).law(umin=-1.0, umax=1.0).update(0.0, r=1.0, y=0.8)
    0.5
    >>> Relay(1.5).law(umin=-1.0, umax=1.0)
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: relay amplitude 1.5 is beyond the actuator's limits [-1, 1]
    """

    amplitude: float
    hysteresis: float = 0.0

    def __post_init__(self) -> None:
        check_real("relay amplitude", self.amplitude, minimum=0.0, strict=True)
        check_real("relay hysteresis", self.hysteresis, minimum=0.0)

    def law(self, *, umin: float, umax: float) -> RelayLaw:
        """A fresh relay law for a flight whose command stays within ``[umin, umax]``."""
        return RelayLaw(self, umin=umin, umax=umax)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"kind": "relay", "amplitude": float(self.amplitude), "hysteresis": float(self.hysteresis)}


def _finite(**values: float) -> None:
    """Refuse a packet's value that is not a finite number, naming it."""
    for name, val in values.items():
        if not math.isfinite(val):
            raise InvalidValueError(f"{name} must be finite, got {val!r}")


class RelayLaw:
    """A :class:`Relay` run on packets, with :class:`FlightLaw`'s interface (``update``, ``record``, ``describe``).

    Raises
    ------
    InvalidValueError
        When the relay's amplitude is beyond the actuator's limits.
    """

    def __init__(self, relay: Relay, *, umin: float, umax: float) -> None:
        self.umin = check_real("umin (m/s)", umin)
        self.umax = check_real("umax (m/s)", umax)
        if not self.umin < self.umax:
            raise InvalidValueError(f"umin must be below umax, got {self.umin:g} and {self.umax:g}")
        if relay.amplitude > min(-self.umin, self.umax):
            raise InvalidValueError(f"relay amplitude {relay.amplitude:g} is beyond the actuator's limits "
                                    f"[{self.umin:g}, {self.umax:g}]")
        self.relay = relay
        self.controller = relay
        self._u: float | None = None

    def update(self, t: float, *, r: float, y: float, vm: float = 0.0, sent: float | None = None) -> float:
        """The relay's command for the packet at ``t`` (``sent``: the command sent instead, which it then holds).
        The relay switches on the error alone; the velocity ``vm`` is checked as the other laws check it."""
        _finite(t=t, r=r, y=y, vm=vm)
        e = r - y
        d, eps = self.relay.amplitude, self.relay.hysteresis
        if e > eps:
            u = d
        elif e < -eps:
            u = -d
        else:
            u = d if self._u is None else self._u
        if sent is not None:
            u = float(sent)
        self._u = u
        return u

    def record(self, t: float, u: float) -> None:
        """A command sent between packets by someone else at time ``t``: the relay holds it."""
        _finite(t=t, u=u)
        self._u = float(u)

    def describe(self) -> dict[str, Any]:
        """The law as JSON."""
        return {"controller": self.relay.to_dict(), "umin": self.umin, "umax": self.umax}
