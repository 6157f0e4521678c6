"""Several reference steps in one flight log: finding them, and cutting the log into one log per step.

A flight log often holds several steps of its altitude reference (up, hold, down, ...).  The paper's estimators
model one step from rest, so a log of three steps fitted as one step fails (its "step" is the net change from the
first reference to the last, its peak the largest excursion anywhere).  :func:`find_steps` finds each change of a
piecewise-constant reference; :func:`split_steps` cuts the log into one :class:`~.flightlog.FlightLog` per step,
each from a little before its step (the rest it starts from, ``before`` seconds, no more than half the time since
the previous step) to the next step.  :func:`~.estimation.estimate_flights` then fits them jointly: one delay, each
step with its own offset and scale (and gain or lag when free), and the spread between steps.

A reference that moves at most of its samples (a ramp, a smoothed trajectory) is not a sequence of steps: it is
refused with an error saying so (fit such a log with ``identify``).

Examples
--------
>>> import numpy as np
>>> t = np.arange(0.0, 30.0, 0.1)
>>> r = np.where(t >= 10, 1.0, 0.0) + np.where(t >= 20, 0.5, 0.0)
>>> [round(float(t[i]), 6) for i in find_steps(t, r)]
[10.0, 20.0]
>>> for piece in split_steps(FlightLog.from_arrays(t, r, r, name="two")):
...     print(piece)
FlightLog(two step 1 of 2: 200 samples, step +1 m at t = 10 s from 0 m)
FlightLog(two step 2 of 2: 110 samples, step +0.5 m at t = 20 s from 1 m)
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import check_real
from .flightlog import FlightLog, LogError
from .logalign import change_time

__all__ = ["find_steps", "split_steps"]

STEP_TOLERANCE = 1e-9
"""A reference sample differs from the previous one when by more than this fraction of ``1 + |value|``."""


def find_steps(t: Any, z_ref: Any, *, min_gap: int = 10) -> list[int]:
    """The indices of the samples where a piecewise-constant reference changes (each the first at its new value).

    Parameters
    ----------
    t, z_ref : array_like
        Sample times (s) and the reference.
    min_gap : int
        The fewest samples between two steps: a reference that changes more often is not a sequence of steps.

    Raises
    ------
    LogError
        No step, or changes closer than ``min_gap`` samples (a ramp or a smoothed reference).

    Examples
    --------
    >>> find_steps([0, 1, 2, 3, 4, 5], [0, 0, 1, 1, 1, 1], min_gap=2)
    [2]
    """
    t = np.asarray(t, dtype=float)
    r = np.asarray(z_ref, dtype=float)
    if r.size < 2:
        raise LogError(f"a reference of {r.size} samples has no step")
    moved = np.abs(np.diff(r)) > STEP_TOLERANCE * (1.0 + np.abs(r[:-1]))
    idx = (np.flatnonzero(moved) + 1).tolist()
    if not idx:
        raise LogError(f"no step in the reference (it stays at {r[0]:g})")
    gaps = np.diff([0, *idx, r.size])
    close = np.flatnonzero(gaps[1:-1] < min_gap) if len(idx) > 1 else np.array([], int)
    if close.size:
        k = int(close[0])
        raise LogError(f"the reference is not a sequence of steps: it changes at {len(idx)} of its {r.size} samples, "
                       f"twice within {int(gaps[k + 1])} samples at t = {t[idx[k]]:.3f} and {t[idx[k + 1]]:.3f} s "
                       f"(fewer than {min_gap}: a ramp or a smoothed reference; fit such a log with `identify`)")
    return idx


def split_steps(log: FlightLog, *, before: float = 1.0, min_after: int = 10) -> list[FlightLog]:
    """One log per step of the reference of ``log`` (see the module docstring); a log of one step gives itself.

    Parameters
    ----------
    log : FlightLog
        A flight whose ``z_ref`` holds one or more steps.
    before : float
        Seconds of rest kept before each step (at most half the time since the previous step): the start
        altitude is their mean.
    min_after : int
        The fewest samples after each step.

    Returns
    -------
    list of FlightLog
        Named ``"<name> step k of n"``; each with its step time, size (the reference after it minus before it),
        start altitude, and the samples from ``before`` ahead of its step to the next step.  The step time is the
        first sample showing the new reference, or, where the log keeps its reference's own change times
        (``extra["z_ref_changes"]``, as :func:`~delaykit.identify.logalign.read_log_flight` does), the change
        between that sample and the one before.

    Raises
    ------
    LogError
        As :func:`find_steps`, or a step followed by fewer than ``min_after`` samples.

    Examples
    --------
    >>> t = np.arange(0.0, 20.0, 0.5)
    >>> r = np.where(t >= 5, 2.0, 1.0)
    >>> split_steps(FlightLog.from_arrays(t, r, r, name="one"))[0].step
    1.0
    """
    before = check_real("before (s)", before, minimum=0.0)
    idx = find_steps(log.t, log.z_ref, min_gap=min_after)
    if len(idx) == 1:
        return [log]
    out = []
    n = len(idx)
    changes = log.extra.get("z_ref_changes")  # the reference's own change times (a flight log's setpoint stamps)
    for k, i in enumerate(idx):
        ts = float(log.t[i]) if changes is None else change_time(log.t, i, np.asarray(changes, dtype=float))
        prev = float(log.t[idx[k - 1]]) if k else float(log.t[0])
        start = ts - min(before, 0.5 * (ts - prev)) if k else float(log.t[0])
        end = idx[k + 1] if k + 1 < n else log.t.size
        sel = np.flatnonzero(log.t >= start - 1e-12)
        sel = sel[sel < end]
        if end - i < min_after:
            raise LogError(f"{log.name}: only {end - i} samples after the step at {ts:g} s before the next; need at "
                           f"least {min_after}")
        step = float(log.z_ref[i] - log.z_ref[i - 1])
        pre = sel[sel < i]
        z0 = float(np.mean(log.z[pre])) if pre.size else float(log.z[i - 1])
        u = None if log.u is None else log.u[sel]
        out.append(FlightLog.from_arrays(log.t[sel], log.z[sel], log.z_ref[sel], u, name=f"{log.name} step {k + 1} "
                                         f"of {n}", step_time=ts, step=step, z0=z0, min_after=min_after,
                                         extra={} if changes is None else {"z_ref_changes": changes}))
    return out
