"""Open-loop fits on the logs' own clocks: a log written at 1.01 s instead of 1 s, with jitter, or logs at
different rates, fitted without resampling.

The compiled path of :mod:`._fit` steps every log with one exact one-period map, which needs one uniform clock.
Here each trial plant is simulated at each log's own sample times instead, every logged command held until the
next and reaching the plant ``delay`` later (:func:`~delaykit.simulate.discrete.held_response_at`'s compiled
stepper: one matrix exponential per stretch between a sample and a command's arrival, exact); the residual blocks
and the projection of each log's offset and hover level are the compiled path's (:func:`._fitkernel.residual_blocks`).
Closed-loop fits through a controller sampled at the log's samples need a uniform clock (resample the log);
a continuous controller's loop is simulated at the samples' own times by :mod:`._closed_general` already.

Private: :mod:`._fit` dispatches here (:func:`any_clock`); :mod:`.identification` is the public face.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import InvalidValueError
from ..models.hold import SNAP
from ..models.transfer import TransferFunction
from ..simulate.discrete import DK
from . import _fit as F
from .structures import Structure

__all__ = ["any_clock", "ClockProblem", "simulate"]


def any_clock(preps: list[Any], law: Any) -> bool:
    """True for an open-loop fit whose logs are not all on one uniform clock (the compiled path's need).

    Examples
    --------
    >>> from types import SimpleNamespace as NS
    >>> log = lambda h, uniform=True: NS(exp=NS(period=h, uniform=uniform))
    >>> any_clock([log(1.0), log(1.0)], None), any_clock([log(1.0, False)], None), any_clock([log(1.0), log(2.0)], None)
    (False, True, True)
    """
    if law is not None:
        return False
    h0 = preps[0].exp.period
    return any(not p.exp.uniform or abs(p.exp.period - h0) > 1e-6 * h0 for p in preps)


def _state_space(plant_abc: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple:
    A, B, C = plant_abc
    A = np.ascontiguousarray(np.atleast_2d(np.asarray(A, dtype=float)))
    B = np.ascontiguousarray(np.asarray(B, dtype=float).reshape(A.shape[0]))
    C = np.ascontiguousarray(np.asarray(C, dtype=float).reshape(A.shape[0]))
    return A, B, C, np.ascontiguousarray(C @ A), float(C @ B)


class ClockProblem(F._Problem):
    """:class:`~._fit._Problem` whose residuals simulate every log on its own clock (see the module docstring)."""

    compiled = False

    def __init__(self, st: Structure, preps: list[Any], law: None, weights: dict[str, float],
                 fit_offset: bool) -> None:
        super().__init__(st, preps, law, weights, fit_offset)
        self.t = np.ascontiguousarray(np.concatenate([q.exp.t for q in preps]))
        self.tol = SNAP * min(q.exp.period for q in preps)

    def raw(self, p: np.ndarray) -> np.ndarray:
        """Raw residuals as :meth:`~._fit._Problem.raw`, each log simulated at its own sample times."""
        p = np.ascontiguousarray(p, dtype=float)
        if not p[-1] >= 0.0:
            raise InvalidValueError(f"delay (s) must be >= 0, got {p[-1]!r}")
        A, B, C, ca, cb = _state_space(self.st.realise(p))
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
            return np.full(self._rw.size, np.nan)
        DK.run_at_logs(A, B, C, 0.0, ca, cb, float(p[-1]), self.tol, self.t, self.drive, self.starts, self.fit_bias,
                     self._y, self._dy, self._uy, self._udy)
        out = np.empty(self._rw.size)
        F.FK.residual_blocks(self._y, self._dy, self._uy, self._udy, self.starts, self.k0, self.p0, self.m0, self.k1,
                             self.p1, self.m1, float(self.w[self.first]), float(self.w[self.rate]) if self.rate else 1.0,
                             self.fit_bias, self.fit_offset, out)
        return out


def simulate(prep: Any, plant: TransferFunction, delay: float) -> dict[str, np.ndarray]:
    """The plant's free-run outputs (deviations) at one log's own sample times, its input held."""
    A, B, C, D = plant.state_space()
    if D:
        raise F.IdentificationError(f"the plant {plant.to_string()} has a direct feedthrough; an identified plant "
                                    "is strictly proper")
    A, B, C, ca, cb = _state_space((A, B, C))
    t = np.ascontiguousarray(prep.exp.t)
    starts = np.array([0, t.size], dtype=np.int64)
    y, dy = np.empty(t.size), np.empty(t.size)
    DK.run_at_logs(A, B, C, 0.0, ca, cb, float(delay), SNAP * prep.exp.period, t, np.ascontiguousarray(prep.drive),
                 starts, False, y, dy, y, dy)
    out = {prep.outputs[0]: y}
    if prep.rate:
        out[prep.rate] = dy
    return out
