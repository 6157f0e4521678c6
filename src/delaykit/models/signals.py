"""What drives a loop: the reference (a step, a ramp, or samples) and a step load disturbance.

References are deviations from the level the loop rests at before t = 0 and are piecewise linear:
every one is a list of *knots* ``(time, value, slope)``, which the simulator turns into breakpoints.

Examples
--------
>>> Samples([0.0, 1.0, 2.0], [0.0, 1.0, 1.0]).knots()
(array([0., 1., 2.]), array([0., 1., 1.]), array([1., 0., 0.]))
>>> Ramp(slope=0.5).value(2.0)
1.0
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real

__all__ = ["Step", "Ramp", "Samples", "LoadStep", "Reference", "as_reference"]


def _out(t: Any, v: np.ndarray) -> Any:
    """A float for a scalar time, an array for an array of times."""
    return float(v) if np.ndim(t) == 0 else v


@dataclass(frozen=True)
class Step:
    """A reference step of ``size`` at t = 0.

    Examples
    --------
    >>> Step(-0.5).final_value(10.0)
    -0.5
    """

    size: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", check_real("step", self.size))

    def knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Knot times, values and slopes."""
        return np.zeros(1), np.array([self.size]), np.zeros(1)

    def value(self, t: Any) -> Any:
        """The reference at times ``t`` (0 before the step)."""
        return _out(t, np.where(np.asarray(t, dtype=float) >= 0, self.size, 0.0))

    def final_value(self, t_end: float) -> float:
        """The reference at ``t_end``."""
        return self.size

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"kind": "step", "size": self.size}


@dataclass(frozen=True)
class Ramp:
    """A ramp ``size + slope t`` from t = 0 (``size`` is an initial step, 0 by default).

    Examples
    --------
    >>> Ramp(slope=0.2, size=0.1).final_value(5.0)
    1.1
    """

    slope: float = 1.0
    size: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "slope", check_real("ramp slope", self.slope))
        object.__setattr__(self, "size", check_real("ramp initial step", self.size))
        if self.slope == 0.0 and self.size == 0.0:
            raise InvalidValueError("a ramp needs a non-zero slope or initial step")

    def knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Knot times, values and slopes."""
        return np.zeros(1), np.array([self.size]), np.array([self.slope])

    def value(self, t: Any) -> Any:
        """The reference at times ``t`` (0 before t = 0)."""
        tt = np.asarray(t, dtype=float)
        return _out(t, np.where(tt >= 0, self.size + self.slope * tt, 0.0))

    def final_value(self, t_end: float) -> float:
        """The reference at ``t_end``."""
        return self.size + self.slope * t_end

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"kind": "ramp", "slope": self.slope, "size": self.size}


@dataclass(frozen=True, eq=False)
class Samples:
    """An arbitrary reference given as samples ``(t_i, r_i)``, joined linearly or held.

    Before the first sample (from t = 0) the reference is ``r_0``; after the last, ``r_N``.

    Parameters
    ----------
    t, r : array_like
        Strictly increasing times (s, the first at or after 0) and the reference there.
    hold : {"linear", "hold"}
        Piecewise-linear interpolation, or zero-order hold (``r_i`` on ``[t_i, t_{i+1})``).

    Examples
    --------
    >>> s = Samples([0.0, 2.0], [0.0, 1.0])
    >>> float(s.value(1.0)), float(Samples([0.0, 2.0], [0.0, 1.0], hold="hold").value(1.0))
    (0.5, 0.0)
    """

    t: Any
    r: Any
    hold: Literal["linear", "hold"] = "linear"

    def __post_init__(self) -> None:
        try:
            t = np.array(self.t, dtype=float).ravel()
            r = np.array(self.r, dtype=float).ravel()
        except OverflowError:  # an integer of hundreds of digits
            raise InvalidValueError("reference samples must be finite, got an integer beyond the floats") from None
        except (TypeError, ValueError) as exc:
            raise InvalidTypeError(f"reference samples must be numbers: {exc}") from None
        if t.size == 0 or t.size != r.size:
            raise InvalidValueError(f"reference samples need as many times as values, at least one; got {t.size} "
                                    f"times and {r.size} values")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(r))):
            raise InvalidValueError("reference samples must be finite")
        if t[0] < 0:
            raise InvalidValueError(f"reference sample times start at t >= 0; got {t[0]:g}")
        if np.any(np.diff(t) <= 0):
            i = int(np.flatnonzero(np.diff(t) <= 0)[0])
            raise InvalidValueError(f"reference sample times must increase; t[{i + 1}] = {t[i + 1]:g} "
                                    f"follows t[{i}] = {t[i]:g}")
        if self.hold not in ("linear", "hold"):
            raise InvalidValueError(f"hold must be 'linear' or 'hold'; got {self.hold!r}")
        t.flags.writeable = False
        r.flags.writeable = False
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "r", r)

    def knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Knot times, values and slopes (a knot at 0 holding ``r_0`` when the first sample is later)."""
        t, r = self.t, self.r
        slopes = np.zeros(t.size)
        if self.hold == "linear" and t.size > 1:
            slopes[:-1] = np.diff(r) / np.diff(t)
        if t[0] > 0:
            return np.r_[0.0, t], np.r_[r[0], r], np.r_[0.0, slopes]
        return t.copy(), r.copy(), slopes

    def value(self, t: Any) -> Any:
        """The reference at times ``t`` (0 before t = 0)."""
        tt = np.asarray(t, dtype=float)
        if self.hold == "linear":
            v = np.interp(tt, self.t, self.r)
        else:
            i = np.clip(np.searchsorted(self.t, tt, side="right") - 1, 0, self.t.size - 1)
            v = self.r[i]
        return _out(t, np.where(tt >= 0, v, 0.0))

    def final_value(self, t_end: float) -> float:
        """The reference at ``t_end``."""
        return float(self.value(t_end))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"kind": "samples", "t": self.t.tolist(), "r": self.r.tolist(), "hold": self.hold}


Reference = Step | Ramp | Samples


@dataclass(frozen=True)
class LoadStep:
    """A step load disturbance of ``size`` starting at ``time`` (s), added to the plant's input.

    Where it enters, ``at``:

    * ``"plant"`` (the default): at the plant's input, after the loop's input delay (the plant feels it at
      ``time``): a load on the vehicle itself, such as a gust or a payload, with the delay being the link's;
    * ``"command"``: on the command, before the input delay (the plant feels it at ``time`` plus the input delay):
      an offset in the actuator command that travels through the link, as a load is drawn in textbooks that put
      the dead time at the plant's input.

    Either way it is added after the controller's limits (``umin``, ``umax``), which bound the controller's output,
    not the load.

    Examples
    --------
    >>> LoadStep(0.2, time=5.0)
    LoadStep(size=0.2, time=5.0, at='plant')
    >>> LoadStep(0.2, time=5.0, at="command").arrival(delay=0.3)   # when the plant feels it, s
    5.3
    """

    size: float
    time: float = 0.0
    at: Literal["plant", "command"] = "plant"

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", check_real("disturbance size", self.size))
        object.__setattr__(self, "time", check_real("disturbance time (s)", self.time, minimum=0.0))
        if not isinstance(self.at, str):
            raise InvalidTypeError(f"a load step's 'at' must be 'plant' or 'command', got {type(self.at).__name__}")
        if self.at not in ("plant", "command"):
            raise InvalidValueError(f"a load step's 'at' must be 'plant' (after the input delay) or 'command' "
                                    f"(before it), got {self.at!r}")

    def arrival(self, delay: float) -> float:
        """When the plant feels the load, for a loop whose input delay is ``delay`` (s)."""
        return self.time + delay if self.at == "command" else self.time

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"size": self.size, "time": self.time, "at": self.at}


def as_reference(ref: Any) -> Step | Ramp | Samples:
    """A reference from a number (a step of that size) or a reference object.

    Examples
    --------
    >>> as_reference(0.2)
    Step(size=0.2)
    """
    if isinstance(ref, (Step, Ramp, Samples)):
        return ref
    if isinstance(ref, bool) or not isinstance(ref, (int, float, np.floating, np.integer)):
        raise InvalidTypeError(f"reference must be a number (a step) or a Step, Ramp or Samples, got {type(ref).__name__}")
    return Step(float(ref))


