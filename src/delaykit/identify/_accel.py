"""The acceleration-limited structure ``ipdt_accel``, simulated exactly between samples, and its fit's residuals.

An autopilot limits the vertical acceleration (ArduCopter's ``WPNAV_ACCEL_Z``, 1 m/s^2 by default; the emulator's
``accel_limit``): a step of the speed command becomes a ramp, which no linear structure has.  ``ipdt_accel`` is

    command ``u`` -> dead time ``delay`` -> rate limit ``accel`` (units of ``u`` per second) -> first-order lag
    ``lag`` -> ``gain`` / s

The limiter's output ``w`` follows the delayed held command at slope ``± accel`` until it reaches it, so it is
piecewise linear, with corners where a delayed command switches and where the ramp reaches its target.  On a
stretch where ``w = w0 + s t`` (``s`` is ``± accel`` or 0) the lag's output ``v`` (``v' = (w - v) / lag``) and the
output ``y`` (``y' = gain v``) have closed forms, with ``c = v0 - w0 + s lag`` and ``e = exp(-t / lag)``::

    v(t) = w0 + s t - s lag + c e
    y(t) = y0 + gain (w0 t + s t^2 / 2 - s lag t + lag c (1 - e))

(``lag`` 0: ``v = w``, ``y = y0 + gain (w0 t + s t^2 / 2)``).  :func:`simulate_accel` chains them from corner to
corner and sample to sample: exact at every sample, on any clock.  It is plain Python (one pass over the log's
samples and command switches, a few microseconds per sample: about 5 ms per evaluation of a 1200-sample log), not
the compiled kernel of the linear structures.  Open loop only.

The limiter commutes with adding a constant (``limit(u + c) = limit(u) + c`` from a rest at ``u + c``), so an
integrating plant's hover level, a constant bias of the command, adds ``gain c t`` to the output, as for the
linear structures: it is projected out with the same compiled code (:func:`._fitkernel.residual_blocks`).

Private: :mod:`._fit` dispatches here for a structure with ``limited`` set; :mod:`.identification` is the public
face.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import InvalidValueError
from . import _fit as F
from .structures import Structure

__all__ = ["simulate_accel", "AccelProblem", "simulate"]


def simulate_accel(t: np.ndarray, drive: np.ndarray, gain: float, accel: float, lag: float,
                   delay: float) -> tuple[np.ndarray, np.ndarray]:
    """The output and its rate at the times ``t`` of ``ipdt_accel`` driven by ``drive``, each value held from its
    sample to the next (the last held on), reaching the limiter ``delay`` later; from rest at 0.

    Examples
    --------
    >>> t = np.arange(0.0, 4.0, 0.5)
    >>> y, v = simulate_accel(t, np.where(t >= 1.0, 1.0, 0.0), 1.0, 1.0, 0.0, 0.5)
    >>> v.tolist()  # the step at 1 s arrives at 1.5 s and ramps at 1 per second to 1 at 2.5 s
    [0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0]
    >>> float(y[-1])  # the ramp's second (area 0.5), then a second at 1
    1.5
    """
    n = t.size
    y_out = np.empty(n)
    v_out = np.empty(n)
    w = v = y = 0.0
    target = 0.0  # the command reaching the limiter (rest: 0)
    now = float(t[0])
    i = 0  # the next command to arrive: drive[i] at t[i] + delay
    for j in range(n):
        tj = float(t[j])
        while True:
            arrive = float(t[i]) + delay if i < n else math.inf
            stop = min(arrive, tj)
            # advance from now to stop under the current target: a ramp (if w is not there yet), then a level
            while now < stop:
                left = stop - now
                if w == target:
                    s, dur, corner = 0.0, left, False
                else:
                    s = accel if target > w else -accel
                    reach = (target - w) / s
                    corner = reach < left
                    dur = reach if corner else left
                if lag > 0.0:
                    c = v - w + s * lag
                    one = -math.expm1(-dur / lag)
                    y += gain * (w * dur + 0.5 * s * dur * dur - s * lag * dur + lag * c * one)
                    v = w + s * dur - s * lag + c * (1.0 - one)
                else:
                    y += gain * (w * dur + 0.5 * s * dur * dur)
                    v = w + s * dur
                if corner:  # the ramp reaches its target: exactly there, no rounding left
                    w = target
                    if lag == 0.0:
                        v = target
                    now += dur
                else:
                    w += s * dur
                    now = stop
            now = stop
            if arrive <= tj:
                target = float(drive[i])
                i += 1
            else:
                break
        y_out[j] = y
        v_out[j] = gain * v
    return y_out, v_out


class AccelProblem(F._Problem):
    """:class:`~._fit._Problem` of the rate-limited structure: every log simulated by :func:`simulate_accel` on its
    own clock, the residual blocks and the projection of the offsets and hover levels the compiled path's."""

    compiled = False
    max_nfev = 200

    def __init__(self, st: Structure, preps: list[Any], law: Any, weights: dict[str, float],
                 fit_offset: bool) -> None:
        if law is not None:
            raise F.IdentificationError(f"{st.name} (an acceleration limit) is fitted open loop only, from the "
                                        "logged command")
        super().__init__(st, preps, law, weights, fit_offset)
        self.accel = dict(st.fixed).get("accel")  # a limit given, not fitted (None: fitted)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`~._fit._Problem.bounds`, with a given limit held at its value."""
        lb, ub = super().bounds()
        if self.accel is not None:
            lb[1] = ub[1] = math.log(self.accel)
        return lb, ub

    def raw(self, p: np.ndarray) -> np.ndarray:
        """Raw residuals as :meth:`~._fit._Problem.raw`, each log simulated by :func:`simulate_accel`."""
        p = np.ascontiguousarray(p, dtype=float)
        if not p[-1] >= 0.0:
            raise InvalidValueError(f"delay (s) must be >= 0, got {p[-1]!r}")
        gain, accel, lag, delay = (float(x) for x in p)
        if self.accel is not None:
            accel = self.accel
        if not (accel > 0.0 and lag >= 0.0 and math.isfinite(gain)):
            return np.full(self._rw.size, np.nan)
        for k in range(len(self.preps)):
            q, a, b = self.preps[k], int(self.starts[k]), int(self.starts[k + 1])
            t = q.exp.t
            y, dy = simulate_accel(t, q.drive, gain, accel, lag, min(delay, q.exp.duration + 2.0 * q.exp.period))
            self._y[a:b], self._dy[a:b] = y, dy
            self._uy[a:b] = gain * (t - t[0])  # a constant bias of the command: a ramp (see the module)
            self._udy[a:b] = gain
        out = np.empty(self._rw.size)
        w1 = float(self.w[self.rate]) if self.rate else 1.0
        F.FK.residual_blocks(self._y, self._dy, self._uy, self._udy, self.starts, self.k0, self.p0, self.m0, self.k1,
                             self.p1, self.m1, float(self.w[self.first]), w1, self.fit_bias, self.fit_offset, out)
        return out


def simulate(prep: Any, values: np.ndarray) -> dict[str, np.ndarray]:
    """The structure's free-run outputs (deviations) over one prepared log at the values ``values``."""
    gain, accel, lag, delay = (float(x) for x in values)
    y, dy = simulate_accel(prep.exp.t, prep.drive, gain, accel, lag, delay)
    out = {prep.outputs[0]: y}
    if prep.rate:
        out[prep.rate] = dy
    return out
