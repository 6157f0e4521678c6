"""Experiment data for identification: a log's time, its input or reference, and its outputs.

An :class:`Experiment` is one log: the sample times (a uniform clock or not), the signal that drives the system (the
plant's command ``u`` for an open-loop fit, or the loop's reference for a closed-loop fit) and one or more outputs
(altitude ``z``, vertical speed ``vz``, a temperature).  :func:`read_experiment` reads one from a CSV file with
a header (UTF-8, a byte-order mark and ``\\r\\n`` line ends accepted, commas only), checking every value.

Deviation variables: the initial steady state is the mean of each signal before the drive first moves
(:attr:`Experiment.onset`), or its first sample when the log starts with the move.

A log whose clock is not uniform (a logger that writes when it can: a heater log at "1 Hz" whose intervals are
1.01 s, or jitter) is taken as it is: a continuous-time fit simulates the plant at the samples' own times, each
logged command held until the next (:func:`~delaykit.simulate.discrete.held_response_at`, exact).  Such a log's
:attr:`Experiment.uniform` is False and its :attr:`Experiment.period` the median interval.  Only a closed-loop fit
through a controller sampled at the log's samples needs a uniform clock; for it, ``resample=h`` puts the log on
the clock ``t[0] + k h``: the drive is held and the outputs are interpolated linearly.  Each switch of the drive
then moves to the next point of the new grid, so the timing of the log is known to within ``h`` only: choose ``h``
well below the delay's wanted precision (a tenth of the log's median interval, say).  Linear interpolation errs by
at most ``dt^2 max|y''| / 8`` between samples ``dt`` apart.

Examples
--------
>>> import numpy as np
>>> t = np.arange(0, 10, 0.5)
>>> e = Experiment.from_arrays(t, {"y": np.where(t > 3, 1.0, 0.0)}, u=np.where(t >= 1, 2.0, 0.0), name="demo")
>>> e
Experiment('demo': 20 samples every 0.5 s, input u, output y, moves at 1 s)
>>> e.baseline("y"), e.drive_baseline
(0.0, 0.0)
"""

from __future__ import annotations

import array
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_path, check_real
from ..models.budget import sample_count
from ..models.ranges import parse_number
from .flightlog import LogError, iter_csv_rows

__all__ = ["Experiment", "read_experiment", "CLOCK_TOLERANCE", "MAX_VALUE"]

CLOCK_TOLERANCE = 0.01
"""A clock is uniform when no sample interval departs from the median interval by more than this fraction of it."""

MAX_VALUE = 1e100
"""The largest magnitude of a logged value (times included): beyond it a value is not a measurement, and sums of
squares of such values overflow (an RMS of ``inf``)."""

MOVE_FRACTION = 0.1
"""The drive has moved once it is this fraction of its range away from its first value."""


@dataclass(frozen=True, repr=False, eq=False)
class Experiment:
    """One log for identification (see the module docstring).

    Attributes
    ----------
    name : str
        Where it came from (a file name).
    t : ndarray
        Sample times (s), increasing.
    period : float
        The sample period (s): the median interval.
    uniform : bool
        True when every interval is within :data:`CLOCK_TOLERANCE` of the period (a resampled log is uniform).
    outputs : dict of str to ndarray
        The measured outputs by name.
    u : ndarray or None
        The plant's command (open-loop identification).
    r : ndarray or None
        The loop's reference (closed-loop identification).
    input_name, reference_name : str
        The columns they came from.
    u_before : float or None
        The command before the log when the log starts with the move (default 0 then).
    resampled_from : int or None
        The number of samples on the log's own, non-uniform clock when it was resampled (``None``: as logged).
    """

    name: str
    t: np.ndarray
    period: float
    outputs: dict[str, np.ndarray]
    u: np.ndarray | None = None
    r: np.ndarray | None = None
    input_name: str = "u"
    reference_name: str = "z_ref"
    u_before: float | None = None
    _onset: int = field(default=0)
    resampled_from: int | None = None
    uniform: bool = True

    @classmethod
    def from_arrays(cls, t: Any, outputs: Mapping[str, Any], *, u: Any = None, r: Any = None, name: str = "data",
                    input_name: str = "u", reference_name: str = "z_ref", u_before: float | None = None,
                    resample: float | None = None) -> "Experiment":
        """Check and wrap arrays (see the class docstring for the fields).

        ``resample``: put the log on the uniform clock ``t[0] + k * resample`` (s), the drive held and the outputs
        interpolated linearly (see the module docstring); ``None`` (the default) keeps the log's own clock,
        uniform or not.

        Raises
        ------
        InvalidValueError
            Non-finite values, times that are not increasing, arrays of
            different lengths, no drive or a drive that never moves (nothing to identify), a ``resample`` period
            that is not positive or leaves fewer than 10 samples.

        Examples
        --------
        >>> t = np.array([0.0, 0.9, 2.1, 3.0, 3.8, 5.2, 6.0, 7.1, 7.9, 9.0, 10.1, 11.0])
        >>> e = Experiment.from_arrays(t, {"y": 0.5 * t}, u=np.where(t >= 3.0, 1.0, 0.0), resample=0.5)
        >>> e
        Experiment('data': 23 samples every 0.5 s, input u, output y, moves at 3 s, resampled from 12)
        >>> e.u[4:8], e.outputs["y"][:3]
        (array([0., 0., 1., 1.]), array([0.  , 0.25, 0.5 ]))
        """
        if not isinstance(name, str):
            raise InvalidTypeError(f"name must be text, got {type(name).__name__}")
        tt = _array(name, "t", t)
        if tt.size < 10:
            raise InvalidValueError(f"{name}: {tt.size} samples; identification needs at least 10")
        dt = np.diff(tt)
        if np.any(dt <= 0):
            i = int(np.flatnonzero(dt <= 0)[0])
            raise InvalidValueError(f"{name}: time is not increasing at sample {i + 1} (t = {tt[i + 1]:g} s after "
                                    f"{tt[i]:g} s)")
        h = float(np.median(dt))
        bad = np.abs(dt - h) > CLOCK_TOLERANCE * h
        if not outputs:
            raise InvalidValueError(f"{name}: no output given")
        outs = {str(k): _array(name, str(k), v, tt.size) for k, v in outputs.items()}
        uu = None if u is None else _array(name, input_name, u, tt.size)
        rr = None if r is None else _array(name, reference_name, r, tt.size)
        logged = None
        if resample is not None:
            hr = check_real("resample (s)", resample, minimum=0.0, strict=True)
            grid = tt[0] + hr * np.arange(sample_count(f"{name}: resample={hr:g} s over the {tt[-1] - tt[0]:g} s log",
                                                       tt[-1] - tt[0], hr, "resample on a longer period"))
            if grid.size < 10:
                raise InvalidValueError(f"{name}: resample={hr:g} s leaves {grid.size} samples of the "
                                        f"{tt[-1] - tt[0]:g} s log; identification needs at least 10")
            held = np.searchsorted(tt, grid * (1 + 1e-15) + 1e-15, side="right") - 1  # the last sample at or before
            outs = {k: np.interp(grid, tt, v) for k, v in outs.items()}
            uu = None if uu is None else uu[held]
            rr = None if rr is None else rr[held]
            logged, tt, h = tt.size, grid, hr
        if (uu is None) == (rr is None):
            raise InvalidValueError(f"{name}: give the input (open-loop fit) or the reference (closed-loop fit), "
                                    "exactly one")
        if u_before is not None and uu is None:
            raise InvalidValueError("u_before applies to an open-loop log (with an input column)")
        if u_before is not None:
            u_before = check_real("u_before (the input before the log)", u_before, minimum=-MAX_VALUE,
                                  maximum=MAX_VALUE)
        drive = uu if uu is not None else rr
        what = input_name if uu is not None else reference_name
        first = float(drive[0]) if u_before is None else float(u_before)
        span = max(float(np.ptp(drive)), float(np.max(np.abs(drive - first))))
        if span <= 1e-12 * max(1.0, float(np.max(np.abs(drive)))):
            hint = (" (if it stepped to this value as the log began, give the value before the log: u_before, "
                    "--u-before)" if uu is not None and u_before is None else "")
            raise InvalidValueError(f"{name}: the {what} column never moves (it is {drive[0]:g} throughout): there is "
                                    f"nothing to identify{hint}")
        onset = int(np.flatnonzero(np.abs(drive - first) > MOVE_FRACTION * span)[0])
        return cls(name=name, t=tt, period=h, outputs=outs, u=uu, r=rr, input_name=input_name,
                   reference_name=reference_name, u_before=None if u_before is None else float(u_before), _onset=onset,
                   resampled_from=logged, uniform=logged is not None or not bool(np.any(bad)))

    # -- baselines --------------------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        """True when the drive is a reference (closed-loop identification)."""
        return self.r is not None

    @property
    def drive(self) -> np.ndarray:
        """The input (open loop) or the reference (closed loop)."""
        return self.u if self.u is not None else self.r  # type: ignore[return-value]

    @property
    def onset(self) -> int:
        """Index of the first sample at which the drive has moved."""
        return self._onset

    @property
    def starts_moving(self) -> bool:
        """True when the log starts with the move (fewer than two samples of the initial steady state)."""
        return self._onset <= 1

    def _pre(self, x: np.ndarray) -> float:
        return float(x[0]) if self.starts_moving else float(np.mean(x[: self._onset]))

    def baseline(self, output: str) -> float:
        """The output's initial steady state (mean before the drive moves, or the first sample)."""
        return self._pre(self.outputs[output])

    @property
    def drive_baseline(self) -> float:
        """The drive's initial value: mean before it moves; for an input logged from its move, ``u_before``
        (0 unless given)."""
        if self.u is not None and self.starts_moving:
            return 0.0 if self.u_before is None else self.u_before
        return self._pre(self.drive)

    @property
    def duration(self) -> float:
        """Length of the log (s)."""
        return float(self.t[-1] - self.t[0])

    def __repr__(self) -> str:
        what = f"input {self.input_name}" if self.u is not None else f"reference {self.reference_name}"
        dt = np.diff(self.t)
        clock = (f"every {self.period:.4g} s" if self.uniform else
                 f"every {self.period:.4g} s on an irregular clock ({dt.min():.4g} to {dt.max():.4g} s)")
        return (f"Experiment({self.name!r}: {self.t.size} samples {clock}, {what}, output"
                f"{'s' if len(self.outputs) > 1 else ''} {', '.join(self.outputs)}, moves at "
                f"{self.t[self._onset] - self.t[0]:.4g} s"
                f"{'' if self.resampled_from is None else f', resampled from {self.resampled_from}'})")


def _array(name: str, col: str, values: Any, n: int | None = None) -> np.ndarray:
    try:
        a = np.asarray(values, dtype=float)
    except OverflowError:  # an integer of hundreds of digits
        raise InvalidValueError(f"{name}: column {col!r} holds an integer beyond the floats") from None
    except (TypeError, ValueError):
        raise InvalidValueError(f"{name}: column {col!r} is not numeric") from None
    if a.ndim != 1:
        raise InvalidValueError(f"{name}: column {col!r} must be 1-d, got shape {a.shape}")
    if n is not None and a.size != n:
        raise InvalidValueError(f"{name}: column {col!r} has {a.size} values, the time column {n}")
    bad = ~np.isfinite(a)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise InvalidValueError(f"{name}: column {col!r} holds a non-finite value ({a[i]}) at sample {i}")
    big = np.abs(a) > MAX_VALUE
    if np.any(big):
        i = int(np.flatnonzero(big)[0])
        raise InvalidValueError(f"{name}: column {col!r} holds {a[i]:g} at sample {i}, beyond +-{MAX_VALUE:g} (not "
                                "a measurement: its square overflows)")
    return a


def read_experiment(path: str | Path, *, outputs: Sequence[str] = ("z",), input: str | None = None,  # noqa: A002
                    reference: str | None = None, time: str = "t", u_before: float | None = None,
                    resample: float | None = None, window: tuple[float, float] | None = None,
                    allow_truncated: bool = False) -> Experiment:
    """Read one log: a CSV file with a header row, or a vehicle log (``.ulg``, ``.bin``/``.log``, ``.tlog``).

    A vehicle log is read by :func:`~delaykit.identify.logalign.read_log_experiment`: ``outputs``, ``input``
    and ``reference`` are then specs such as ``-vehicle_local_position.z`` or ``CTUN.CRt``, on the log's own
    clock (``time`` is not used).

    Parameters
    ----------
    path : str or Path
        The file.
    outputs : sequence of str
        Output columns (one or more: ``("z", "vz")`` fits altitude and vertical speed jointly).
    input : str, optional
        The command column, for an open-loop fit.
    reference : str, optional
        The reference column, for a closed-loop fit (give ``input`` or ``reference``).
    time : str
        The time column (s).
    u_before : float, optional
        The command before the log, when the log starts with the move (default 0).
    resample : float, optional
        A uniform period (s) to put a log with an irregular clock on (see :meth:`Experiment.from_arrays`).
    window : (float, float), optional
        Keep the samples from ``t0`` to ``t1`` (s, the log's own clock).
    allow_truncated : bool
        A vehicle log cut short is read up to its last complete message (see
        :mod:`~delaykit.identify.vehiclelogs`).

    Raises
    ------
    LogError
        A file that cannot be read, a missing column (the message lists the header), a cell that is not a
        number (row and column named), or the problems :meth:`Experiment.from_arrays` checks.

    Examples
    --------
    >>> import tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "step.csv")
    >>> _ = open(p, "w").write("t,u,y\\n" + "".join(f"{k},{1.0 if k else 0.0},{0.1 * k}\\n" for k in range(12)))
    >>> read_experiment(p, outputs=["y"], input="u")
    Experiment('step.csv': 12 samples every 1 s, input u, output y, moves at 1 s)
    """
    from .logalign import read_log_experiment
    from .vehiclelogs import log_format

    path = check_path("experiment file", path)
    name = path.name
    if isinstance(outputs, str):
        outputs = [outputs]
    if not isinstance(outputs, Sequence) or not outputs or not all(isinstance(o, str) for o in outputs):
        raise InvalidTypeError(f"outputs must be a column name or a non-empty list of them, got {outputs!r:.60}")
    if log_format(path) is not None:
        if time != "t":
            raise LogError(f"{path}: a flight log's time is its own (its microsecond stamps): time={time!r} does not "
                           "apply")
        return read_log_experiment(path, outputs=outputs, input=input, reference=reference, window=window,
                                   u_before=u_before, resample=resample, allow_truncated=allow_truncated)
    header, records = iter_csv_rows(path)  # one row at a time: the numbers go into packed arrays
    wanted = [time, *outputs] + ([input] if input else []) + ([reference] if reference else [])
    for col in wanted:
        if col not in header:
            records.close()
            raise LogError(f"{path}: missing column {col!r} (header: {', '.join(header)})")
    cols: dict[str, array.array] = {c: array.array("d") for c in wanted}
    where = {c: header.index(c) for c in wanted}
    for row, line in records:
        for c, j in where.items():
            cell = row[j].strip() if j < len(row) else ""
            try:
                v = parse_number(cell)
            except ValueError:
                records.close()
                raise LogError(f"{path}: row {line}: {c} is {cell[:40]!r}, not a number") from None
            if not math.isfinite(v):
                records.close()
                raise LogError(f"{path}: row {line}: {c} is {cell[:40]!r}, not a finite number")
            cols[c].append(v)
    arr = {c: np.frombuffer(a, dtype=float) for c, a in cols.items()}
    if window is not None:
        t0, t1 = (float(w) for w in window)
        if not (math.isfinite(t0) and math.isfinite(t1) and t0 < t1):
            raise LogError(f"the window {t0:g}:{t1:g} s must be two finite times, the first before the second")
        tt = arr[time]
        if tt.size == 0 or t0 < tt[0] or t1 > tt[-1]:
            raise LogError(f"{path}: the window {t0:g}:{t1:g} s is not within the log "
                           f"({f'{tt[0]:g} to {tt[-1]:g} s' if tt.size else 'no rows'})")
        keep = (tt >= t0) & (tt <= t1)
        arr = {c: a[keep] for c, a in arr.items()}
    try:
        return Experiment.from_arrays(arr[time], {o: arr[o] for o in outputs},
                                      u=arr[input] if input else None, r=arr[reference] if reference else None,
                                      name=name, input_name=input or "u", reference_name=reference or "z_ref",
                                      u_before=u_before, resample=resample)
    except LogError:
        raise
    except InvalidValueError as exc:  # (its message starts with the file's name)
        raise LogError(str(exc)) from None
