"""Flight logs: reading, checking, and finding the step.

A flight log is a CSV file with a header and the columns ``t`` (s), ``z`` (m), ``z_ref`` (m) and optionally
``u`` (the commanded vertical speed, m/s); other names can be mapped with ``columns=``.  Extra columns are
kept but not used.  Sample times may be irregular and may start at any time.

The step is found from ``z_ref`` (one step per log): the step time is the first sample whose reference
differs from the initial one (the reference in force at that sample), the starting altitude is the mean of
the samples before it, and the step size is the last reference minus the first.  Each can be given instead
(for a continuous controller whose step fell between two samples, give the step time).

The file is UTF-8 text (a byte-order mark, as spreadsheets write, is allowed) with any line ends (``\n``,
``\r\n``, ``\r``), separated by commas; a header separated by semicolons or tabs is refused with an error
saying so (the separator is not guessed).  Values are checked up front: all finite, times increasing and
within ``±MAX_TIME`` (1e10 s), altitudes, references and commands within ``±MAX_ALTITUDE`` (1e6 m).

Bad files get an error naming the file, the row (1-based, counting the header as row 1) and what is
wrong.  Nothing is dropped silently: with ``skip_bad=True`` rows with text, non-finite or out-of-range
numbers are skipped, and how many is recorded in ``FlightLog.skipped``.

Examples
--------
>>> import numpy as np
>>> t = np.arange(0, 5, 0.065)
>>> log = FlightLog.from_arrays(t, z=np.where(t >= 1.04, 1.0, 0.5), z_ref=np.where(t >= 1.0, 1.5, 0.5))
>>> log
FlightLog(<arrays>: 77 samples, step +1 m at t = 1.04 s from 0.5 m)
"""

from __future__ import annotations

import array
import csv
import io
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

from ..errors import InvalidValueError, check_path, check_real, writing
from ..models.budget import MAX_LOG_BYTES, open_regular
from ..models.ranges import parse_number

__all__ = ["FlightLog", "LogError", "REQUIRED", "MAX_ALTITUDE", "MAX_TIME", "read_csv_rows", "iter_csv_rows", "write_log",
           "synthetic_log"]

REQUIRED = ("t", "z", "z_ref")
MAX_ALTITUDE = 1e6  # m: the largest |z|, |z_ref| (and |u|, m/s) accepted; beyond it is garbage, not a flight
MAX_TIME = 1e10  # s: the largest |t| accepted (a Unix time stamp fits; 1e300 does not)
_BOUNDS = {"t": (MAX_TIME, "s"), "z": (MAX_ALTITUDE, "m"), "z_ref": (MAX_ALTITUDE, "m"), "u": (MAX_ALTITUDE, "m/s")}


def _out_of_range(key: str, v: float) -> str | None:
    """Why the value ``v`` of column ``key`` is unusable, or None."""
    if not math.isfinite(v):
        return f"{key} is {v} (NaN or inf)"
    bound, unit = _BOUNDS.get(key, (math.inf, ""))
    if abs(v) > bound:
        return f"{key} is {v:g} {unit}, outside [-{bound:g}, {bound:g}] {unit}"
    return None


_MAX_LINE = 1 << 20
"""Characters of one line of a CSV log (a row of a log is some 100): a longer one is refused as it is read."""


class LogError(InvalidValueError):
    """A flight log that cannot be used, with the file and row named."""


def read_csv_rows(path: Path) -> tuple[list[str], list[tuple[list[str], int]]]:
    """A CSV file's header and its non-blank rows, each with the file line it starts on (all held in memory:
    for a large file, :func:`iter_csv_rows` reads one row at a time).

    Raises
    ------
    LogError
        As :func:`iter_csv_rows`.
    """
    header, records = iter_csv_rows(path)
    return header, list(records)


def iter_csv_rows(path: Path) -> tuple[list[str], Iterator[tuple[list[str], int]]]:
    """A CSV file's header, and an iterator over its non-blank rows, each with the file line it starts on.

    The file is read as the rows are (memory does not grow with its length).  It must be UTF-8 text (a
    byte-order mark and ``\\r\\n`` line ends, as spreadsheets save, are fine) separated by commas: a semicolon- or
    tab-separated header is refused with an error saying the separator must be a comma (it is not guessed, so a
    decimal comma is never misread).

    Raises
    ------
    LogError
        A file that cannot be read, is not UTF-8 text, is empty, is not comma-separated or is not a readable CSV
        (the header's problems at once, a later row's when the iterator reaches it).
    """
    name = str(path)
    try:  # a regular file of bounded size only: /dev/zero never ends, a FIFO blocks the reader
        fh = io.TextIOWrapper(open_regular(path, "CSV log", MAX_LOG_BYTES, error=LogError), encoding="utf-8-sig",
                              newline="")  # (newline="": the reader takes \n, \r\n and \r)
    except OSError as exc:
        raise LogError(f"{name}: cannot be read ({exc.strerror or exc})") from None

    def lines() -> Iterator[str]:
        while True:
            line = fh.readline(_MAX_LINE)  # (capped: a binary file without line ends is not read whole)
            if not line:
                break
            if "\x00" in line:
                raise LogError(f"{name} is not a UTF-8 text CSV (it holds NUL bytes at byte "
                               f"{_bad_byte(path, True)[0]}): a binary file?")
            if len(line) >= _MAX_LINE and not line.endswith(("\n", "\r")):
                raise LogError(f"{name}: line {reader.line_num + 1} is longer than {_MAX_LINE} characters: not a "
                               "CSV log (a binary file?)")
            yield line

    reader = csv.reader(lines())

    def fail(exc: Exception) -> LogError:
        fh.close()
        if isinstance(exc, LogError):
            return exc
        if isinstance(exc, UnicodeDecodeError):
            at, byte = _bad_byte(path, False)
            return LogError(f"{name} is not a UTF-8 text CSV (byte {at} is {byte:#04x}); save it as CSV UTF-8")
        if isinstance(exc, OSError):
            return LogError(f"{name}: cannot be read ({exc.strerror or exc})")
        return LogError(f"{name}: row {reader.line_num}: not a readable CSV ({exc})")  # e.g. a field too long

    try:
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise LogError(f"{name}: the file is empty") from None
        if len(header) == 1:
            for sep, what in ((";", "semicolons"), ("\t", "tabs")):
                if sep in header[0]:
                    raise LogError(f"{name}: the header {header[0][:60]!r} is separated by {what}; the "
                                   "separator must be a comma (save as CSV with commas)")
    except (LogError, UnicodeDecodeError, OSError, csv.Error) as exc:
        raise fail(exc) from None

    def records() -> Iterator[tuple[list[str], int]]:
        try:
            yield None  # type: ignore[misc]  # (primed below: close() then closes the file even before a row)
            while True:
                lineno = reader.line_num + 1  # the file row (line) this record starts on
                try:
                    row = next(reader)
                except StopIteration:
                    break
                if row and any(c.strip() for c in row):
                    yield row, lineno
        except (LogError, UnicodeDecodeError, OSError, csv.Error) as exc:
            raise fail(exc) from None
        finally:
            fh.close()

    rows = records()
    next(rows)
    return header, rows


def _text_columns(path: Path, where: Mapping[str, int], keep: set[int]) -> dict[str, list[str]]:
    """The columns ``where`` (name to index) of a CSV file as text, for the rows whose line is in ``keep``."""
    out: dict[str, list[str]] = {h: [] for h in where}
    for row, lineno in iter_csv_rows(path)[1]:
        if lineno in keep:
            for h, j in where.items():
                out[h].append(row[j] if j < len(row) else "")
    return out


def _bad_byte(path: Path, nul: bool) -> tuple[int, int]:
    """Where a file fails as UTF-8 text: the offset and value of its first NUL byte (``nul``), or of its first byte
    that is not UTF-8.  (Only on the way to an error: the whole file is read.)"""
    data = path.read_bytes()
    if nul:
        at = data.index(0)
    else:
        try:
            data.decode("utf-8-sig")
            at = len(data) - 1
        except UnicodeDecodeError as exc:
            at = exc.start
    return at, data[at]


@dataclass(frozen=True, repr=False, eq=False)
class FlightLog:
    """One flight: samples, and the step found in (or given for) its reference.

    Attributes
    ----------
    t, z, z_ref : ndarray
        Sample times (s), altitudes (m), references (m).
    u : ndarray or None
        Commanded vertical speed (m/s), if logged.
    name : str
        File name, or ``<arrays>``.
    step_time, z0, step : float
        The step: when (s, in the log's time), from which altitude (m), and its size (m).
    skipped : int
        Rows skipped under ``skip_bad=True``.
    extra : dict
        Other columns, by name.
    """

    t: np.ndarray
    z: np.ndarray
    z_ref: np.ndarray
    u: np.ndarray | None
    name: str
    step_time: float
    z0: float
    step: float
    skipped: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def after(self) -> np.ndarray:
        """Boolean mask of the samples at or after the step."""
        return self.t >= self.step_time

    @classmethod
    def from_arrays(
        cls,
        t: Any,
        z: Any,
        z_ref: Any | None = None,
        u: Any | None = None,
        *,
        name: str = "<arrays>",
        step_time: float | None = None,
        z0: float | None = None,
        step: float | None = None,
        min_after: int = 10,
        skipped: int = 0,
        extra: Mapping[str, Any] | None = None,
        rows: Any | None = None,
    ) -> "FlightLog":
        """Build a log from arrays (or pandas Series); ``z_ref`` may be omitted if the step is given.

        Parameters
        ----------
        t, z, z_ref, u : array_like
            Samples: finite, ``t`` increasing and within ±:data:`MAX_TIME`, the others within
            ±:data:`MAX_ALTITUDE`.
        step_time, z0, step : float, optional
            Override what is found from ``z_ref``.
        min_after : int
            Fewest samples needed at or after the step.
        rows : array_like of int, optional
            The file row of each sample, for error messages (default: sample ``i`` is row ``i + 2``, after a
            header).
        """
        arrs = {}
        for key, val in (("t", t), ("z", z), ("z_ref", z_ref), ("u", u)):
            if val is None:
                continue
            try:
                a = np.asarray(val, dtype=float).ravel()
            except (TypeError, ValueError, OverflowError) as exc:
                raise LogError(f"{name}: column {key!r} is not numeric: {exc}") from None
            arrs[key] = a
        n = arrs["t"].size
        if n == 0:
            raise LogError(f"{name}: no samples")
        row_of = np.arange(n) + 2 if rows is None else np.asarray(rows, dtype=int).ravel()
        if row_of.size != n:
            raise LogError(f"{name}: {row_of.size} row numbers for {n} samples")
        for key, a in arrs.items():
            if a.size != n:
                raise LogError(f"{name}: column {key!r} has {a.size} values, column 't' has {n}")
            bound = _BOUNDS[key][0]
            with np.errstate(invalid="ignore"):
                bad = np.flatnonzero(~(np.abs(a) <= bound))  # NaN, inf, or too large
            if bad.size:
                raise LogError(f"{name}: row {row_of[bad[0]]}: {_out_of_range(key, float(a[bad[0]]))}")
        tt = arrs["t"]
        back = np.flatnonzero(np.diff(tt) <= 0)
        if back.size:
            i = back[0] + 1
            raise LogError(f"{name}: row {row_of[i]}: time {tt[i]:g} does not increase (previous row has "
                           f"{tt[i - 1]:g})")
        zr = arrs.get("z_ref")
        if step_time is None:
            if zr is None:
                raise LogError(f"{name}: no z_ref column, so the step time must be given")
            moved = np.flatnonzero(np.abs(zr - zr[0]) > 1e-9 * (1 + abs(zr[0])))
            if moved.size == 0:
                raise LogError(f"{name}: no step in z_ref (it stays at {zr[0]:g} m)")
            i = moved[0]
            step_time = float(tt[i])
        step_time = check_real("step_time", step_time)
        h = float(np.median(np.diff(tt))) if n > 1 else 0.0
        if not tt[0] - h <= step_time <= tt[-1]:  # (a step up to one sample before the first is the log's start)
            raise LogError(f"{name}: the step time {step_time:g} s is outside the log, which runs from {tt[0]:g} s "
                           f"to {tt[-1]:g} s")
        if step is None:
            if zr is None:
                raise LogError(f"{name}: no z_ref column, so the step size must be given")
            # one step per log: from the reference's first value to its last
            step = float(zr[-1] - zr[0])
        step = check_real("step", step)
        if step == 0:
            raise LogError(f"{name}: the step size is zero")
        pre = tt < step_time
        if z0 is None:
            z0 = float(np.mean(arrs["z"][pre])) if np.any(pre) else float(arrs["z"][0])
        z0 = check_real("z0", z0)
        n_after = int(np.count_nonzero(tt >= step_time))
        if n_after < min_after:
            raise LogError(f"{name}: only {n_after} samples after the step at {step_time:g} s; need at least {min_after}")
        return cls(t=tt, z=arrs["z"], z_ref=zr if zr is not None else np.where(tt >= step_time, z0 + step, z0),
                   u=arrs.get("u"), name=name, step_time=step_time, z0=z0, step=step, skipped=skipped,
                   extra=dict(extra or {}))

    @classmethod
    def from_csv(
        cls,
        path: str | Path,
        *,
        columns: Mapping[str, str] | None = None,
        skip_bad: bool = False,
        **kwargs: Any,
    ) -> "FlightLog":
        """Read a CSV flight log.

        The file must be UTF-8 text (a byte-order mark and ``\\r\\n`` line ends, as spreadsheets save, are fine)
        separated by commas: a semicolon- or tab-separated header is refused with an error saying the
        separator must be a comma (it is not guessed, so a decimal comma is never misread).  Every value is
        checked (finite, within the bounds of the module docstring) and errors name the file, row and column.

        Parameters
        ----------
        path : str or Path
            The file.
        columns : mapping, optional
            Our name to the file's name, e.g. ``{"z": "altitude_m", "t": "time"}``.
        skip_bad : bool
            Skip (and count) rows with text or non-finite numbers instead of failing.
        **kwargs
            Passed to :meth:`from_arrays` (``step_time``, ``z0``, ``step``, ``min_after``).
        """
        path = Path(path)
        name = str(path)
        header, records = iter_csv_rows(path)
        mapping = {k: k for k in (*REQUIRED, "u")}
        mapping.update(columns or {})
        idx: dict[str, int] = {}
        for ours, theirs in mapping.items():
            if theirs in header:
                idx[ours] = header.index(theirs)
            elif ours in ("t", "z"):
                records.close()
                raise LogError(f"{name}: missing column {theirs!r} (header: {', '.join(header)})")
        if "z_ref" not in idx and "step_time" not in kwargs:
            records.close()
            raise LogError(f"{name}: missing column {mapping['z_ref']!r} (header: {', '.join(header)}); "
                           "without it give the step time and size")
        # numbers go into packed arrays as they are read (8 bytes a value: a list of float objects takes 32)
        rows: dict[str, array.array] = {k: array.array("d") for k in idx}
        used = {mapping[k] for k in idx}
        others: dict[str, int] = {}  # each other column's index (the first, for a repeated name)
        for j, h in enumerate(header):
            if h not in used:
                others.setdefault(h, j)
        extra_num: dict[str, array.array] = {h: array.array("d") for h in others}  # numbers, while they are
        text_cols: set[str] = set()  # other columns that hold text: read again, as text, at the end
        skipped = 0
        linenos = array.array("q")
        for row, lineno in records:
            vals = {}
            bad = None
            for k, j in idx.items():
                cell = row[j].strip() if j < len(row) else ""
                try:
                    v = parse_number(cell)
                except ValueError:
                    bad = f"{k} is {cell[:40]!r}, not a number"
                    break
                bad = _out_of_range(k, v)
                if bad:
                    break
                vals[k] = v
            if bad:
                if skip_bad:
                    skipped += 1
                    continue
                records.close()
                raise LogError(f"{name}: row {lineno}: {bad}")
            for k, v in vals.items():
                rows[k].append(v)
            linenos.append(lineno)
            for h, j in others.items():
                if h not in text_cols:
                    try:
                        extra_num[h].append(parse_number(row[j] if j < len(row) else ""))
                    except ValueError:
                        text_cols.add(h)
                        extra_num[h] = array.array("d")
        if not rows["t"]:
            raise LogError(f"{name}: no data rows")
        extra: dict[str, Any] = {h: np.frombuffer(a, dtype=float) for h, a in extra_num.items() if h not in text_cols}
        if text_cols:
            extra.update(_text_columns(path, {h: others[h] for h in text_cols}, set(linenos)))
            extra = {h: extra[h] for h in others}  # the file's order
        arrays = {k: np.frombuffer(v, dtype=float) for k, v in rows.items()}
        return cls.from_arrays(arrays["t"], arrays["z"], arrays.get("z_ref"), arrays.get("u"), name=name,
                               skipped=skipped, extra=extra, rows=np.frombuffer(linenos, dtype=np.int64), **kwargs)

    @classmethod
    def from_dataframe(cls, df: Any, *, columns: Mapping[str, str] | None = None, **kwargs: Any) -> "FlightLog":
        """A log from a pandas DataFrame (columns as in the CSV, or mapped with ``columns=``)."""
        mapping = {k: k for k in (*REQUIRED, "u")}
        mapping.update(columns or {})
        get = lambda k: df[mapping[k]].to_numpy() if mapping[k] in df.columns else None  # noqa: E731
        if get("t") is None or get("z") is None:
            raise LogError(f"the DataFrame needs columns {mapping['t']!r} and {mapping['z']!r}")
        return cls.from_arrays(get("t"), get("z"), get("z_ref"), get("u"), name=kwargs.pop("name", "<DataFrame>"),
                               **kwargs)

    def to_dict(self) -> dict[str, Any]:
        """Summary (not the samples)."""
        return {"name": self.name, "samples": int(self.t.size), "step_time": self.step_time, "z0": self.z0,
                "step": self.step, "skipped": self.skipped}

    def __repr__(self) -> str:
        sk = f", {self.skipped} rows skipped" if self.skipped else ""
        return (f"FlightLog({self.name}: {self.t.size} samples, step {self.step:+g} m at t = {self.step_time:g} s "
                f"from {self.z0:g} m{sk})")


def write_log(path: str | Path, columns: Mapping[str, Any]) -> None:
    """Write columns (equal-length arrays) as a CSV flight log, ``t`` first.

    Examples
    --------
    >>> import tempfile, os, numpy as np
    >>> p = os.path.join(tempfile.mkdtemp(), "f.csv")
    >>> t = np.arange(0, 3, 0.1)
    >>> write_log(p, {"t": t, "z": t * 0, "z_ref": (t >= 1.0) * 1.0})
    >>> FlightLog.from_csv(p).step_time
    1.0
    """
    keys = list(columns)
    if "t" in keys:
        keys.remove("t")
        keys.insert(0, "t")
    cols = [np.asarray(columns[k]) for k in keys]
    path = check_path("log", path)
    with writing("the log", path), open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for row in zip(*cols):
            w.writerow([f"{v:.9g}" if isinstance(v, (float, np.floating)) else v for v in row])


def synthetic_log(
    loop: Any,
    step: float,
    *,
    z0: float = 1.0,
    dt: float = 0.065,
    before: float = 1.0,
    after: float = 12.0,
    noise: float = 0.0,
    resolution: float = 0.001,
    phase: float = 0.0,
    t0: float = 0.0,
    rng: Any = None,
    name: str = "<synthetic>",
) -> FlightLog:
    """A flight log made by the exact simulator: samples every ``dt``, noise, rounding, a clock offset.

    For a sampled controller the log's samples are the controller's (the controller runs on each packet),
    so the step falls on a sample and ``phase`` is ignored; for a continuous controller the samples fall at
    ``phase + k dt`` after the step, and the step time is recorded exactly (as the flight software knows it).

    Parameters
    ----------
    loop : AltitudeLoop
        The true loop.
    step, z0 : float
        The step (m) and the altitude before it.
    dt, before, after : float
        Sample interval; seconds logged before and after the step.
    noise, resolution : float
        White measurement noise (m, standard deviation) and the altitude's rounding (m; 0 = none).
    phase : float
        Offset of the samples after the step, in ``[0, dt)`` (continuous controllers).
    t0 : float
        The log's clock at the step.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.368), 1.0, noise=0.003, rng=np.random.default_rng(0))
    >>> log.step, log.z0 > 0.99
    (1.0, True)
    """
    from ..simulate.simulation import simulate

    rng = np.random.default_rng() if rng is None else rng
    sampled = getattr(loop, "period", None) is not None
    if sampled:
        dt = loop.period
        phase = loop.sample_offset
    k0 = int(math.ceil(before / dt))
    t = phase + dt * np.arange(-k0, int(math.floor((after - phase) / dt)) + 1)
    resp = simulate(loop, step, z0=z0, t_end=after)
    z = np.asarray(resp.altitude(t)) + noise * rng.standard_normal(t.size)
    if resolution:
        z = np.round(z / resolution) * resolution
    z_ref = np.where(t >= 0, z0 + step, z0)
    return FlightLog.from_arrays(t + t0, z, z_ref, resp.command(t), name=name, step_time=t0, z0=None, step=step)
