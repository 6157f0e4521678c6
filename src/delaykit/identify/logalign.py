"""Flight-log signals on one clock, and the :class:`~delaykit.identify.iodata.Experiment` and
:class:`~delaykit.identify.flightlog.FlightLog` made of them (the signals read by :mod:`.vehiclelogs`).

Clocks: the signals of different topics are sampled at different instants.  They are put on the clock of the first
output (its own sample times): other outputs are interpolated linearly onto it, and the input or reference is
*held* (zero-order hold: its last logged value at or before each instant, as a vehicle holds the last setpoint it
received).  Instants before the drive's first sample are dropped.

``window=(t0, t1)`` keeps that part of the log, in the log's own seconds (:func:`parse_window` reads ``T0:T1``).
A reference logged on its own clock changes, on the output's clock, at the first output sample after it changed;
:func:`read_log_flight` keeps the reference's own change times (``extra["z_ref_changes"]``), and the step times of
the log and of :func:`~delaykit.identify.steps.split_steps` are taken from them: exact to the reference's time
stamp, not rounded to the next output sample.

Examples
--------
>>> parse_window("120:180")
(120.0, 180.0)
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidValueError
from .flightlog import FlightLog, LogError
from .vehiclelogs import Signal, Spec, read_signals

__all__ = ["parse_window", "align_signals", "read_log_experiment", "read_log_flight", "change_time",
           "REFERENCE_CHANGES"]

REFERENCE_CHANGES = "z_ref_changes"
"""The key, in a :class:`~delaykit.identify.flightlog.FlightLog`'s ``extra``, of the times (s) at which its
reference changed on the reference's own clock (a flight log's setpoint topic)."""


def parse_window(text: str) -> tuple[float, float]:
    """A window ``T0:T1`` (seconds, the log's own clock) as ``(t0, t1)``: finite, ``t0 < t1``.

    Examples
    --------
    >>> parse_window("120:180")
    (120.0, 180.0)
    >>> parse_window("180:120")
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: window '180:120': expected T0:T1 in seconds with T0 < T1
    """
    from ..models.ranges import parse_number

    parts = str(text).split(":")
    try:
        t0, t1 = (parse_number(p.strip(), "window") for p in parts) if len(parts) == 2 else (math.nan, math.nan)
    except ValueError:
        t0 = t1 = math.nan
    if not (math.isfinite(t0) and math.isfinite(t1) and t0 < t1):
        raise InvalidValueError(f"window {text!r}: expected T0:T1 in seconds with T0 < T1")
    return t0, t1



# ---------------------------------------------------------------------------------------------------------------
# onto one clock


def _finite_span(sig: Signal) -> str:
    ok = np.isfinite(sig.values)
    if not ok.any():
        return "it is never set"
    # the longest run of finite samples
    edges = np.diff(np.concatenate([[0], ok.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    k = int(np.argmax(ends - starts))
    return f"it is set from {sig.t[starts[k]]:.6g} to {sig.t[ends[k] - 1]:.6g} s"


def align_signals(path: str | Path, signals: dict[str, Signal], base: str, held: Sequence[str] = (),
                  window: tuple[float, float] | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Put signals on the clock of ``base``: the others interpolated linearly, those in ``held`` held.

    Returns the times (s) and each signal's values at them.  ``window=(t0, t1)`` keeps the times in it (s, the
    log's clock); it must lie within the base signal's span.  Non-finite values at the times kept raise a
    :class:`LogError` naming where the signal is set.

    Examples
    --------
    >>> s = Spec.parse("a.y")
    >>> y = Signal(s, np.arange(5.0), np.arange(5.0) * 2, None, "timestamp")
    >>> u = Signal(Spec.parse("b.u"), np.array([0.5, 2.5]), np.array([1.0, 3.0]), None, "timestamp")
    >>> align_signals("f.ulg", {"a.y": y, "b.u": u}, "a.y", held=["b.u"])
    (array([1., 2., 3., 4.]), {'a.y': array([2., 4., 6., 8.]), 'b.u': array([1., 1., 3., 3.])})
    """
    path = Path(path)
    clocks = {s.clock for s in signals.values()}
    if len(clocks) > 1:
        raise LogError(f"{path}: the signals are on different clocks ({', '.join(sorted(clocks))}): cannot align")
    for name, s in signals.items():
        bad = np.flatnonzero(np.diff(s.t) <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise LogError(f"{path}: {name}: the time stamps do not increase at sample {i} ({s.t[i]:.6f} s after "
                           f"{s.t[i - 1]:.6f} s)")
    b = signals[base]
    t = b.t
    keep = np.ones(t.size, bool)
    if window is not None:
        t0, t1 = (float(w) for w in window)
        if not (math.isfinite(t0) and math.isfinite(t1) and t0 < t1):
            raise LogError(f"the window {t0:g}:{t1:g} s must be two finite times, the first before the second")
        if b.t.size == 0 or t0 < b.t[0] - 1e-9 or t1 > b.t[-1] + 1e-9:
            span = f"{b.t[0]:.6g} to {b.t[-1]:.6g} s" if b.t.size else "no samples"
            raise LogError(f"{path}: the window {t0:.6g}:{t1:.6g} s is not within {base}'s samples ({span}; the "
                           "log's own clock, seconds)")
        keep &= (t >= t0) & (t <= t1)
    for name in held:
        s = signals[name]
        if s.t.size == 0:
            raise LogError(f"{path}: {name} has no samples")
        before = t < s.t[0]
        if window is not None and np.any(before & keep):
            raise LogError(f"{path}: the window starts at {window[0]:.6g} s, before {name}'s first sample at "
                           f"{s.t[0]:.6g} s (its value there is not known)")
        keep &= ~before
    for name, s in signals.items():
        if name != base and name not in held and np.any(keep & ((t < s.t[0]) | (t > s.t[-1]))):
            keep &= (t >= s.t[0]) & (t <= s.t[-1])
    t = t[keep]
    if t.size == 0:
        raise LogError(f"{path}: no sample of {base} where every signal asked for is logged")
    out = {}
    for name, s in signals.items():
        if name == base:
            v = s.values[keep]
        elif name in held:
            v = s.values[np.searchsorted(s.t, t, side="right") - 1]
        else:
            v = np.interp(t, s.t, s.values)
        bad = ~np.isfinite(v)
        if bad.any():
            raise LogError(f"{path}: {name} is not set (NaN) at {int(bad.sum())} of the {t.size} samples used, from "
                           f"{t[bad][0]:.6g} s; {_finite_span(s)}: choose a window there (window=(t0, t1), "
                           "--window T0:T1)")
        out[name] = v
    return t, out


# ---------------------------------------------------------------------------------------------------------------
# into the objects the rest of delaykit fits


def read_log_experiment(path: str | Path, *, outputs: Sequence[str], input: str | None = None,  # noqa: A002
                        reference: str | None = None, window: tuple[float, float] | None = None,
                        u_before: float | None = None, resample: float | None = None, si: bool = True,
                        allow_truncated: bool = False) -> Any:
    """An :class:`~delaykit.identify.iodata.Experiment` from a vehicle log (see the module docstring).

    The outputs and the input (open loop) or reference (closed loop) are specs; the clock is the first output's,
    the drive held between its samples.  The other parameters are those of
    :func:`~delaykit.identify.iodata.read_experiment`, and ``window``, ``si`` and ``allow_truncated`` those of
    :func:`read_signals` and :func:`align_signals`.

    Raises
    ------
    LogError
        The file's problems, and those :meth:`~delaykit.identify.iodata.Experiment.from_arrays` finds.

    Examples
    --------
    >>> read_log_experiment("missing.ulg", outputs=["-vehicle_local_position.z"], input="trajectory_setpoint.vz")
    Traceback (most recent call last):
    ...
    delaykit.identify.flightlog.LogError: missing.ulg: cannot be read (No such file or directory)
    """
    from .iodata import Experiment

    if isinstance(outputs, str):
        outputs = [outputs]
    outputs = list(outputs)
    if not outputs:
        raise LogError("no output signal given")
    if (input is None) == (reference is None):
        raise LogError("give the input (open-loop fit) or the reference (closed-loop fit) signal, exactly one")
    drive = input if input is not None else reference
    wanted = list(dict.fromkeys([*outputs, drive]))
    sigs = read_signals(path, wanted, si=si, allow_truncated=allow_truncated)
    t, vals = align_signals(path, sigs, outputs[0], held=[drive], window=window)
    try:
        return Experiment.from_arrays(t, {o: vals[o] for o in outputs}, u=vals[drive] if input else None,
                                      r=vals[drive] if reference else None, name=Path(path).name,
                                      input_name=input or "u", reference_name=reference or "z_ref",
                                      u_before=u_before, resample=resample)
    except InvalidValueError as exc:
        if isinstance(exc, LogError):
            raise
        raise LogError(str(exc)) from None


def read_log_flight(path: str | Path, *, z: str, z_ref: str | None = None, u: str | None = None,
                    window: tuple[float, float] | None = None, si: bool = True, allow_truncated: bool = False,
                    **kwargs: Any) -> FlightLog:
    """A :class:`~delaykit.identify.flightlog.FlightLog` (altitude, reference, command) from a vehicle log.

    ``z`` is the altitude's spec (up positive: ``-vehicle_local_position.z`` for PX4), ``z_ref`` the altitude
    reference's (held), ``u`` the commanded vertical speed's (held, optional).  ``kwargs`` go to
    :meth:`FlightLog.from_arrays` (``step_time``, ``step``, ``z0``, ``min_after``).  A reference with several
    steps gives a log whose step is the first; :func:`delaykit.identify.steps.split_steps` cuts it into one log
    per step.

    Examples
    --------
    >>> read_log_flight("a.csv", z="x.z")
    Traceback (most recent call last):
    ...
    delaykit.identify.flightlog.LogError: a.csv is not a vehicle log (.ulg, .bin, .log or .tlog)
    """
    held = [s for s in (z_ref, u) if s is not None]
    wanted = list(dict.fromkeys([z, *held]))
    sigs = read_signals(path, wanted, si=si, allow_truncated=allow_truncated)
    t, vals = align_signals(path, sigs, z, held=held, window=window)
    extra: dict[str, Any] = {}
    if z_ref is not None:
        r = sigs[z_ref]
        with np.errstate(invalid="ignore"):
            moved = np.flatnonzero(np.diff(r.values) != 0) + 1
        extra[REFERENCE_CHANGES] = r.t[moved]
        if "step_time" not in kwargs:
            # the first step at the reference's own time stamp, not at the output sample that first shows it
            ref = vals[z_ref]
            first = np.flatnonzero(ref != ref[0])
            if first.size:
                kwargs["step_time"] = change_time(t, int(first[0]), extra[REFERENCE_CHANGES])
    return FlightLog.from_arrays(t, vals[z], None if z_ref is None else vals[z_ref], None if u is None else vals[u],
                                 name=Path(path).name, extra=extra, **kwargs)


def change_time(t: np.ndarray, i: int, changes: np.ndarray) -> float:
    """When a held signal that first shows its new value at sample ``i`` of ``t`` changed: its last logged change
    after sample ``i - 1`` and at or before sample ``i`` (``changes``: the times of its changes, on its own
    clock), or ``t[i]`` when none is known.

    Examples
    --------
    >>> change_time(np.array([0.0, 0.1, 0.2]), 2, np.array([0.13]))
    0.13
    """
    lo = t[i - 1] if i > 0 else -np.inf
    c = changes[(changes > lo) & (changes <= t[i])]
    return float(c[-1]) if c.size else float(t[i])
