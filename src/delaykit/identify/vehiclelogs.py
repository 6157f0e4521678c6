"""Vehicle flight logs: PX4 ULog (``.ulg``), ArduPilot DataFlash (``.bin``, ``.log``) and MAVLink telemetry logs
(``.tlog``): their signals, each on its own clock, and what a log holds.  :mod:`.logalign` puts the signals on one
clock and makes the :class:`~delaykit.identify.iodata.Experiment` and :class:`~delaykit.identify.flightlog.FlightLog`
objects the CSV readers give.

Signals are named by *specs*, ``[-]topic[instance].field[*scale]``:

* ULog: the topic and field as PX4 names them, ``vehicle_local_position.z``; an array field with its index,
  ``trajectory_setpoint.velocity[2]``; instance 1 of a multi-instance topic, ``vehicle_local_position[1].z``.
* DataFlash: the message and field, ``CTUN.CRt``; ``BARO[1].Alt`` picks the instance of a message that has an
  instance field.
* tlog: the MAVLink message and field, ``LOCAL_POSITION_NED.vz``.
* A leading ``-`` flips the sign: PX4's ``vehicle_local_position`` and MAVLink's ``*_NED`` messages are NED, so
  ``-vehicle_local_position.z`` is the height *up* (:func:`ned_to_up` says the same in words).  ``*0.01`` scales.

Time is the log's own: PX4's ``timestamp`` and DataFlash's ``TimeUS`` (microseconds) or ``TimeMS``, in seconds
(since the vehicle booted, as its log viewers show it; a PX4 simulator may stamp Unix time instead), and for a tlog
the vehicle's ``time_boot_ms`` when every message asked for carries it, else the tlog's own receive stamps (the
ground station's clock, Unix seconds), never a mix.

Units: with ``si=True`` (the default) a field the log *declares* in centimetres (DataFlash's format units, as
ArduCopter 3.6's ``CTUN.CRt`` in cm/s, or pymavlink's MAVLink field units, as ``GLOBAL_POSITION_INT.vz``) is
converted to metres; millimetres too.  PX4 fields are SI already.  A ``*scale`` on the spec applies on top.

Only the topics or messages asked for are parsed (pyulog's ``message_name_filter_list``; pymavlink's type filter
for DataFlash).  A tlog is scanned whole (every packet is decoded to find the ones asked for).

Damaged files raise :class:`~delaykit.identify.flightlog.LogError` naming the file and the problem: empty, not of
the format its suffix says, a ULog that pyulog finds corrupt, a DataFlash log with bytes between its messages that
are not messages, a tlog packet that fails MAVLink's checksum, a topic, field or instance that is not there (the
message lists what is), a text field named as a signal.  A log that ends inside a message (cut short: a vehicle that
lost power, a copy interrupted) is refused too, unless ``allow_truncated=True``: it is then read up to its last
whole message.  Damage that keeps the framing intact (a changed value inside a ULog or DataFlash message: those
formats have no checksums) cannot be seen.

Examples
--------
>>> Spec.parse("-trajectory_setpoint.velocity[2]")
Spec('-trajectory_setpoint.velocity[2]': topic trajectory_setpoint, field velocity[2], sign -1)
>>> log_format("flight.ulg"), log_format("00000042.BIN"), log_format("flight.csv")
('ulog', 'dataflash', None)
"""

from __future__ import annotations

import contextlib
import io
import math
import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from ..errors import InvalidTypeError
from .flightlog import LogError

__all__ = ["FORMATS", "Spec", "Signal", "LogTopic", "LogListing", "log_format", "ned_to_up", "read_signals",
           "list_log"]

FORMATS = {".ulg": "ulog", ".bin": "dataflash", ".log": "dataflash", ".tlog": "tlog"}
"""The file suffixes (any case) read as vehicle logs, and their formats."""

_SI = {"cm": ("m", 0.01), "cm/s": ("m/s", 0.01), "cm/s/s": ("m/s/s", 0.01), "cm/s^2": ("m/s^2", 0.01),
       "cm/s2": ("m/s2", 0.01), "mm": ("m", 1e-3), "mm/s": ("m/s", 1e-3)}
_SPEC = re.compile(r"^\s*(?P<sign>[-+]?)\s*(?P<topic>[A-Za-z_][A-Za-z0-9_]*)(?:\[(?P<inst>\d+)\])?"
                   r"\.(?P<field>[A-Za-z_][A-Za-z0-9_]*(?:\[\d+\])?)"
                   r"(?:\s*\*\s*(?P<scale>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?))?\s*$")
_ULOG_MAGIC = b"ULog\x01\x12\x35"
_DF_HEAD = b"\xa3\x95"


def log_format(path: str | Path) -> str | None:
    """The vehicle-log format a file's suffix names (``ulog``, ``dataflash``, ``tlog``), or None (a CSV).

    Examples
    --------
    >>> log_format("a.tlog"), log_format("a.LOG")
    ('tlog', 'dataflash')
    """
    return FORMATS.get(Path(path).suffix.lower())

def ned_to_up(spec: str) -> str:
    """The spec of the same signal with its sign flipped: NED's ``z`` (down) as a height up, or back.

    Examples
    --------
    >>> ned_to_up("vehicle_local_position.z"), ned_to_up("-LOCAL_POSITION_NED.vz")
    ('-vehicle_local_position.z', 'LOCAL_POSITION_NED.vz')
    """
    s = Spec.parse(spec)
    return s.text[1:].lstrip() if s.text.lstrip().startswith("-") else "-" + s.text.lstrip().lstrip("+")


@dataclass(frozen=True, repr=False)
class Spec:
    """A signal of a log: ``[-]topic[instance].field[*scale]`` (see the module docstring).

    Attributes
    ----------
    text : str
        As given.
    topic : str
        Topic (ULog) or message (DataFlash, MAVLink).
    instance : int or None
        The instance asked for (``None``: instance 0, or the only one).
    field : str
        The field, with its index for an array field (``velocity[2]``).
    sign : int
        +1, or -1 for a leading ``-``.
    scale : float
        A factor applied (1 unless ``*scale`` is given).
    """

    text: str
    topic: str
    instance: int | None
    field: str
    sign: int
    scale: float

    @classmethod
    def parse(cls, text: str) -> "Spec":
        """Parse a spec; a :class:`LogError` says what is expected.

        Examples
        --------
        >>> Spec.parse("CTUN.CRt*0.01").scale
        0.01
        """
        if not isinstance(text, str):
            raise InvalidTypeError(f"a log signal is named by text (topic.field), got {type(text).__name__}")
        m = _SPEC.match(text)
        if m is None:
            raise LogError(f"{text!r} is not a log signal: expected [-]topic[instance].field[*scale], e.g. "
                           "-vehicle_local_position.z, trajectory_setpoint.velocity[2], CTUN.CRt, "
                           "LOCAL_POSITION_NED.vz")
        scale = float(m["scale"]) if m["scale"] else 1.0
        if not math.isfinite(scale) or scale == 0.0:
            raise LogError(f"{text!r}: the scale must be a finite non-zero number, got {m['scale']}")
        return cls(text=text.strip(), topic=m["topic"], instance=None if m["inst"] is None else int(m["inst"]),
                   field=m["field"], sign=-1 if m["sign"] == "-" else 1, scale=scale)

    @property
    def source(self) -> str:
        """The signal as logged, without sign and scale: ``topic[instance].field``."""
        inst = "" if self.instance is None else f"[{self.instance}]"
        return f"{self.topic}{inst}.{self.field}"

    def __repr__(self) -> str:
        inst = "" if self.instance is None else f", instance {self.instance}"
        sc = "" if self.scale == 1.0 else f", scale {self.scale:g}"
        return f"Spec({self.text!r}: topic {self.topic}{inst}, field {self.field}, sign {self.sign:+d}{sc})"


@dataclass(frozen=True, repr=False, eq=False)
class Signal:
    """One signal read from a log, on its own clock.

    Attributes
    ----------
    spec : Spec
        What was asked for.
    t : ndarray
        Its sample times (s, the log's clock).
    values : ndarray
        Its values (sign, unit conversion and scale applied).
    unit : str or None
        The unit the log declares (after conversion to SI), or None.
    clock : str
        Which clock ``t`` is: ``timestamp``, ``TimeUS``, ``TimeMS``, ``time_boot_ms`` or ``tlog``.
    """

    spec: Spec
    t: np.ndarray
    values: np.ndarray
    unit: str | None
    clock: str

    @property
    def rate(self) -> float:
        """Samples per second (the median interval's inverse; 0 for fewer than two samples)."""
        return float(1.0 / np.median(np.diff(self.t))) if self.t.size > 1 and np.median(np.diff(self.t)) > 0 else 0.0

    def to_dict(self) -> dict[str, Any]:
        """A summary (not the samples)."""
        return {"spec": self.spec.text, "samples": int(self.t.size), "rate_hz": self.rate, "unit": self.unit,
                "clock": self.clock, "start": float(self.t[0]) if self.t.size else None,
                "end": float(self.t[-1]) if self.t.size else None}

    def __repr__(self) -> str:
        span = f"{self.t[0]:.3f} to {self.t[-1]:.3f} s" if self.t.size else "empty"
        unit = f" {self.unit}" if self.unit else ""
        return f"Signal({self.spec.text!r}{unit}: {self.t.size} samples at {self.rate:.3g} Hz, {span} ({self.clock}))"


@dataclass(frozen=True, repr=False)
class LogTopic:
    """One topic (ULog) or message type (DataFlash, MAVLink) of a log: what ``delaykit log`` lists."""

    name: str
    instance: int | None
    fields: tuple[str, ...]
    units: tuple[str, ...] | None
    samples: int
    rate_hz: float
    start: float | None
    end: float | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"name": self.name, "instance": self.instance, "fields": list(self.fields),
                "units": None if self.units is None else list(self.units), "samples": self.samples,
                "rate_hz": self.rate_hz, "start": self.start, "end": self.end}

    def __repr__(self) -> str:
        inst = "" if self.instance is None else f"[{self.instance}]"
        return (f"LogTopic({self.name}{inst}: {len(self.fields)} fields, {self.samples} samples at "
                f"{self.rate_hz:.3g} Hz)")


@dataclass(frozen=True, repr=False)
class LogListing:
    """What a log holds: its format, clock, and topics or messages."""

    name: str
    format: str
    clock: str
    topics: tuple[LogTopic, ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"name": self.name, "format": self.format, "clock": self.clock,
                "topics": [t.to_dict() for t in self.topics]}

    def __repr__(self) -> str:
        return f"LogListing({self.name!r}: {self.format}, {len(self.topics)} topics, clock {self.clock})"


# ---------------------------------------------------------------------------------------------------------------
# readers: each returns {spec text: Signal} for the specs asked, reading only their topics


def _si(unit: str | None, si: bool) -> tuple[str | None, float]:
    if unit is None or not si or unit not in _SI:
        return (unit or None), 1.0
    return _SI[unit]


def _check_file(path: Path, fmt: str) -> bytes:
    """The file's first bytes, after the checks every format shares."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(16)
    except OSError as exc:
        raise LogError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if not head:
        raise LogError(f"{path}: the file is empty")
    if fmt == "ulog" and not head.startswith(_ULOG_MAGIC[:4]):
        raise LogError(f"{path} is not a ULog file (it does not start with the ULog signature)")
    if fmt == "dataflash" and not head.startswith(_DF_HEAD):
        raise LogError(f"{path} is not a DataFlash binary log (it does not start with a message header 0xA3 0x95; "
                       "text .log files are not read)")
    return head


def _ulog_end(path: Path) -> int | None:
    """Where a ULog file's last complete message ends, when the file ends inside a message (None: it does not).

    The messages are walked by their size fields (3-byte headers), not parsed."""
    data = path.read_bytes()
    pos, n = 16, len(data)
    if n < 16:
        return 0
    unpack = struct.Struct("<H").unpack_from
    while pos + 3 <= n:
        size = unpack(data, pos)[0]
        if pos + 3 + size > n:
            return pos
        pos += 3 + size
    return None if pos == n else pos


def _open_ulog(path: Path, topics: list[str] | None, allow_truncated: bool) -> Any:
    """pyulog's reading of the topics asked (all for None), after the checks of damage and truncation."""
    from pyulog import ULog

    try:
        with _quiet():
            ulog = ULog(str(path), message_name_filter_list=topics)
    except Exception as exc:  # a third-party parser on arbitrary bytes: any failure is a damaged file
        raise LogError(f"{path}: not a readable ULog ({type(exc).__name__}: {exc})") from None
    if getattr(ulog, "file_corruption", False):
        raise LogError(f"{path}: the ULog is corrupt (pyulog found damaged messages)")
    end = _ulog_end(path)
    if end is not None and not allow_truncated:
        raise LogError(f"{path}: the ULog is cut short: it ends inside a message after byte {end} of "
                       f"{path.stat().st_size} (pass allow_truncated=True, --allow-truncated, to read it up to there)")
    return ulog


def _read_ulog(path: Path, specs: Sequence[Spec], allow_truncated: bool) -> dict[str, Signal]:
    _check_file(path, "ulog")
    ulog = _open_ulog(path, sorted({s.topic for s in specs}), allow_truncated)
    by = {(d.name, d.multi_id): d for d in ulog.data_list}
    out = {}
    for s in specs:
        inst = 0 if s.instance is None else s.instance
        d = by.get((s.topic, inst))
        if d is None:
            have = sorted({n for n, _ in by})
            insts = sorted(i for n, i in by if n == s.topic)
            if insts:
                raise LogError(f"{path}: topic {s.topic} has no instance {inst} (instances: "
                               f"{', '.join(map(str, insts))})")
            raise LogError(f"{path}: no topic {s.topic!r} in the log (run `delaykit log {path.name}` to list them)"
                           + (f"; found among those asked: {', '.join(have)}" if have else ""))
        if s.field not in d.data:
            fields = [f for f in d.data if f != "timestamp"]
            raise LogError(f"{path}: topic {s.topic} has no field {s.field!r} (fields: {', '.join(fields)})")
        t = np.asarray(d.data["timestamp"], dtype=float) * 1e-6
        v = np.asarray(d.data[s.field], dtype=float)
        out[s.text] = Signal(spec=s, t=t, values=s.sign * s.scale * v, unit=None, clock="timestamp")
    return out


@contextlib.contextmanager
def _quiet() -> Iterator[None]:
    """pymavlink prints what it skips, from Python and from its compiled indexer (to the file descriptors 1 and 2
    themselves): keep it off the user's terminal.  (What the damage means is said by a LogError instead.)"""
    import os
    import sys

    saved: list[tuple[int, int]] = []
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            for fd in (1, 2):
                saved.append((fd, os.dup(fd)))
                os.dup2(null, fd)
        finally:
            os.close(null)
    except OSError:  # no such descriptor (a daemon): nothing to silence there
        pass
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            yield
    finally:
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)


def _df_damage(path: Path, reader: Any, allow_truncated: bool) -> None:
    """Refuse a DataFlash log with bytes that are not messages: in its middle (damage, which pymavlink skips
    silently), or at its end (cut short, unless ``allow_truncated``).

    DataFlash has no checksums: the check is that the messages pymavlink indexed, each of its format's length,
    tile the file."""
    n = int(reader.data_len)
    starts, ends = [np.zeros(1, np.int64)], [np.zeros(1, np.int64)]
    for kind, offsets in enumerate(getattr(reader, "offsets", []) or []):
        if not offsets or kind not in reader.formats:
            continue
        length = int(reader.formats[kind].len)
        o = np.asarray(offsets, dtype=np.int64)
        o = o[o + length <= n]
        starts.append(o)
        ends.append(o + length)
    start, end = np.concatenate(starts), np.concatenate(ends)
    order = np.argsort(start, kind="stable")
    start, end = start[order], end[order]
    gap = np.flatnonzero(start[1:] != end[:-1])
    last = int(end[-1])
    if gap.size:
        k = int(gap[0])
        raise LogError(f"{path}: the DataFlash log is damaged: the bytes from {int(end[k])} to {int(start[k + 1])} "
                       f"are not messages ({int(np.sum(start[1:] - end[:-1]))} such bytes before byte {last})")
    if last < n and not allow_truncated:
        raise LogError(f"{path}: the DataFlash log is cut short: it ends inside a message after byte {last} of {n} "
                       "(pass allow_truncated=True, --allow-truncated, to read it up to there)")


def _df_time(fmt: Any) -> tuple[str, float]:
    cols = list(fmt.columns)
    if "TimeUS" in cols:
        return "TimeUS", 1e-6
    if "TimeMS" in cols:
        return "TimeMS", 1e-3
    raise LogError(f"message {fmt.name} has no time field (TimeUS or TimeMS)")


def _read_dataflash(path: Path, specs: Sequence[Spec], si: bool, allow_truncated: bool) -> dict[str, Signal]:
    _check_file(path, "dataflash")
    from pymavlink import DFReader

    types = sorted({s.topic for s in specs})
    rows: dict[str, list[Any]] = {t: [] for t in types}
    try:
        with _quiet():
            reader = DFReader.DFReader_binary(str(path), zero_time_base=False)
            _df_damage(path, reader, allow_truncated)
            while True:
                msg = reader.recv_match(type=types)
                if msg is None:
                    break
                rows[msg.get_type()].append(msg)
            formats = {f.name: f for f in reader.formats.values()}
    except LogError:
        raise
    except Exception as exc:  # a third-party parser on arbitrary bytes
        raise LogError(f"{path}: not a readable DataFlash log ({type(exc).__name__}: {exc})") from None
    out = {}
    for s in specs:
        fmt = formats.get(s.topic)
        if fmt is None:
            raise LogError(f"{path}: no message {s.topic!r} is defined in the log (run `delaykit log {path.name}` "
                           "to list them)")
        base, index = _split_index(s.field)
        if base not in fmt.columns:
            raise LogError(f"{path}: message {s.topic} has no field {base!r} (fields: {', '.join(fmt.columns)})")
        msgs = rows[s.topic]
        inst_field = getattr(fmt, "instance_field", None)
        if s.instance is not None:
            if inst_field is None:
                if s.instance != 0:
                    raise LogError(f"{path}: message {s.topic} has no instances (no instance field): drop "
                                   f"[{s.instance}]")
            else:
                msgs = [m for m in msgs if int(getattr(m, inst_field)) == s.instance]
        if not msgs:
            raise LogError(f"{path}: no {s.topic}{'' if s.instance is None else f'[{s.instance}]'} message in "
                           "the log (defined, but never written; or the file is cut short)")
        tname, tscale = _df_time(fmt)
        t = np.array([getattr(m, tname) for m in msgs], dtype=float) * tscale
        v = _numbers([_element(getattr(m, base), index, s, path) for m in msgs], s, path)
        units = list(getattr(fmt, "units", None) or [])
        unit = units[fmt.colhash[base]] if fmt.colhash.get(base, len(units)) < len(units) else None
        unit, k = _si(unit, si)
        out[s.text] = Signal(spec=s, t=t, values=s.sign * s.scale * k * v, unit=unit, clock=tname)
    return out


def _numbers(values: list[Any], spec: Spec, path: Path) -> np.ndarray:
    """A field's values as floats; a LogError for a text field (a message's name, a flight mode's)."""
    try:
        return np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise LogError(f"{path}: {spec.source} is not numeric (it holds {str(values[0])[:30]!r})") from None


def _split_index(field: str) -> tuple[str, int | None]:
    m = re.match(r"^(.*)\[(\d+)\]$", field)
    return (field, None) if m is None else (m[1], int(m[2]))


def _element(value: Any, index: int | None, spec: Spec, path: Path) -> float:
    if index is None:
        if isinstance(value, (list, tuple, np.ndarray)) or hasattr(value, "__len__") and not isinstance(value, str):
            raise LogError(f"{path}: {spec.source} is an array: give an index, {spec.source}[0]")
        return value
    try:
        return value[index]
    except (IndexError, TypeError):
        raise LogError(f"{path}: {spec.source}: the field is not an array with an element {index}") from None


def _tlog_end(path: Path) -> tuple[int | None, bool]:
    """Walk a tlog's records by their framing (8-byte stamp, then a MAVLink 1 or 2 packet, its length in its
    header): ``(where the last whole record ends, whether the bytes there are not a record's start)``, or
    ``(None, False)`` when the file is whole."""
    data = path.read_bytes()
    pos, n = 0, len(data)
    while pos < n:
        if pos + 10 > n:
            return pos, False
        magic, length = data[pos + 8], data[pos + 9]
        if magic == 0xFE:
            size = 6 + length + 2
        elif magic == 0xFD:
            if pos + 11 > n:
                return pos, False
            size = 10 + length + 2 + (13 if data[pos + 10] & 0x01 else 0)
        else:
            return pos, True
        if pos + 8 + size > n:
            return pos, False
        pos += 8 + size
    return None, False


def _tlog_messages(path: Path, types: set[str] | None, allow_truncated: bool = False) -> list[tuple[float, Any]]:
    """(tlog stamp in s, message) for each packet of the types asked (all for None); a LogError on damage.

    A tlog is a sequence of records: an 8-byte big-endian time stamp (microseconds since the Unix epoch) and one
    MAVLink packet.  The records are walked by their framing first (a file cut inside one is cut short); pymavlink
    decodes the packets, checking their checksums (a packet it cannot decode is damage)."""
    from pymavlink import mavutil

    end, garbage = _tlog_end(path)
    if end is not None and garbage:
        raise LogError(f"{path}: not a readable tlog: byte {end + 8} is not the start of a MAVLink packet (a "
                       "damaged file, or not a MAVLink telemetry log)")
    if end is not None and not allow_truncated:
        raise LogError(f"{path}: the tlog is cut short: it ends inside a record after byte {end} of "
                       f"{path.stat().st_size} (pass allow_truncated=True, --allow-truncated, to read it up to there)")
    out = []
    conn = None
    try:
        with _quiet():
            conn = mavutil.mavlink_connection(str(path), notimestamps=False, robust_parsing=True)
            while True:
                msg = conn.recv_msg()
                if msg is None:
                    break
                kind = msg.get_type()
                if kind == "BAD_DATA":
                    raise LogError(f"{path}: not a readable tlog: undecodable bytes near byte {conn.f.tell()} "
                                   "(a damaged file, or not a MAVLink telemetry log)")
                if types is None or kind in types:
                    out.append((float(getattr(msg, "_timestamp", 0.0)), msg))
    except LogError:
        raise
    except Exception as exc:  # a third-party parser on arbitrary bytes
        raise LogError(f"{path}: not a readable tlog ({type(exc).__name__}: {exc})") from None
    finally:
        if conn is not None:
            with contextlib.suppress(Exception):
                conn.close()
    return out


def _read_tlog(path: Path, specs: Sequence[Spec], si: bool, allow_truncated: bool) -> dict[str, Signal]:
    _check_file(path, "tlog")
    types = {s.topic for s in specs}
    rows: dict[str, list[tuple[float, Any]]] = {t: [] for t in types}
    for stamp, msg in _tlog_messages(path, types, allow_truncated):
        rows[msg.get_type()].append((stamp, msg))
    for s in specs:
        if s.instance not in (None, 0):
            raise LogError(f"{path}: {s.text}: MAVLink messages have no instances here: drop [{s.instance}]")
        if not rows[s.topic]:
            raise LogError(f"{path}: no {s.topic} message in the tlog (run `delaykit log {path.name}` to list them)")
    boot = all("time_boot_ms" in rows[t][0][1].get_fieldnames() for t in types)
    out = {}
    for s in specs:
        msgs = rows[s.topic]
        base, index = _split_index(s.field)
        names = msgs[0][1].get_fieldnames()
        if base not in names:
            raise LogError(f"{path}: message {s.topic} has no field {base!r} (fields: {', '.join(names)})")
        if boot:
            t = np.array([m.time_boot_ms for _, m in msgs], dtype=float) * 1e-3
        else:
            t = np.array([st for st, _ in msgs], dtype=float)
        v = _numbers([_element(getattr(m, base), index, s, path) for _, m in msgs], s, path)
        unit, k = _si(getattr(msgs[0][1], "fieldunits_by_name", {}).get(base), si)
        out[s.text] = Signal(spec=s, t=t, values=s.sign * s.scale * k * v, unit=unit,
                             clock="time_boot_ms" if boot else "tlog")
    return out


def read_signals(path: str | Path, specs: Sequence[str], *, si: bool = True,
                 allow_truncated: bool = False) -> dict[str, Signal]:
    """Read signals from a vehicle log, each on its own clock, reading only their topics.

    Parameters
    ----------
    path : str or Path
        A ``.ulg``, ``.bin``/``.log`` or ``.tlog`` file.
    specs : sequence of str
        The signals (see the module docstring).
    si : bool
        Convert fields the log declares in centimetres or millimetres to metres.
    allow_truncated : bool
        Read a log that ends inside a message up to its last complete one (otherwise a :class:`LogError`).

    Returns
    -------
    dict of str to Signal
        By spec text.  Samples whose time stamps go backwards or repeat are kept as logged (checked later).

    Raises
    ------
    LogError
        The file's problems (see the module docstring).

    Examples
    --------
    >>> read_signals("flight.csv", ["a.b"])
    Traceback (most recent call last):
    ...
    delaykit.identify.flightlog.LogError: flight.csv is not a vehicle log (.ulg, .bin, .log or .tlog)
    """
    path = Path(path)
    fmt = log_format(path)
    if fmt is None:
        raise LogError(f"{path} is not a vehicle log (.ulg, .bin, .log or .tlog)")
    if isinstance(specs, str):
        specs = [specs]
    parsed = [Spec.parse(s) for s in specs]
    if not parsed:
        raise LogError("no signal asked for")
    if fmt == "ulog":
        return _read_ulog(path, parsed, allow_truncated)
    if fmt == "dataflash":
        return _read_dataflash(path, parsed, si, allow_truncated)
    return _read_tlog(path, parsed, si, allow_truncated)


# ---------------------------------------------------------------------------------------------------------------
# what a log holds


def _topic(name: str, inst: int | None, fields: Sequence[str], units: Sequence[str] | None,
           t: np.ndarray) -> LogTopic:
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    rate = float(1.0 / np.median(dt)) if dt.size and np.median(dt) > 0 else 0.0
    return LogTopic(name=name, instance=inst, fields=tuple(fields), units=None if units is None else tuple(units),
                    samples=int(t.size), rate_hz=rate, start=float(t[0]) if t.size else None,
                    end=float(t[-1]) if t.size else None)


def list_log(path: str | Path, *, allow_truncated: bool = False) -> LogListing:
    """The topics (ULog) or message types (DataFlash, tlog) of a log, with fields, sample counts, rates and spans.

    The whole log is parsed (every topic is listed).

    Raises
    ------
    LogError
        As :func:`read_signals`.

    Examples
    --------
    >>> list_log("nothing.tlog")
    Traceback (most recent call last):
    ...
    delaykit.identify.flightlog.LogError: nothing.tlog: cannot be read (No such file or directory)
    """
    path = Path(path)
    fmt = log_format(path)
    if fmt is None:
        raise LogError(f"{path} is not a vehicle log (.ulg, .bin, .log or .tlog)")
    _check_file(path, fmt)
    topics: list[LogTopic] = []
    if fmt == "ulog":
        ulog = _open_ulog(path, None, allow_truncated)
        for d in sorted(ulog.data_list, key=lambda d: (d.name, d.multi_id)):
            multi = sum(1 for e in ulog.data_list if e.name == d.name) > 1
            topics.append(_topic(d.name, d.multi_id if multi else None, [f for f in d.data if f != "timestamp"],
                                 None, np.asarray(d.data["timestamp"], float) * 1e-6))
        return LogListing(name=path.name, format=fmt, clock="timestamp (µs, in s)", topics=tuple(topics))
    if fmt == "dataflash":
        from pymavlink import DFReader

        times: dict[str, list[float]] = {}
        try:
            with _quiet():
                reader = DFReader.DFReader_binary(str(path), zero_time_base=False)
                _df_damage(path, reader, allow_truncated)
                formats = {f.name: f for f in reader.formats.values()}
                while True:
                    msg = reader.recv_msg()
                    if msg is None:
                        break
                    kind = msg.get_type()
                    f = formats.get(kind)
                    if f is None or kind in ("FMT", "FMTU", "UNIT", "MULT"):
                        continue
                    cols = list(f.columns)
                    tn = "TimeUS" if "TimeUS" in cols else "TimeMS" if "TimeMS" in cols else None
                    if tn is not None:
                        times.setdefault(kind, []).append(getattr(msg, tn) * (1e-6 if tn == "TimeUS" else 1e-3))
                formats = {f.name: f for f in reader.formats.values()}
        except LogError:
            raise
        except Exception as exc:
            raise LogError(f"{path}: not a readable DataFlash log ({type(exc).__name__}: {exc})") from None
        for kind in sorted(times):
            f = formats[kind]
            cols = [c for c in f.columns if c not in ("TimeUS", "TimeMS")]
            units = list(getattr(f, "units", None) or [])
            u = [units[f.colhash[c]] if f.colhash[c] < len(units) else "" for c in cols] if units else None
            topics.append(_topic(kind, None, cols, u, np.array(times[kind])))
        return LogListing(name=path.name, format=fmt, clock="TimeUS (µs, in s)", topics=tuple(topics))
    rows: dict[str, list[tuple[float, Any]]] = {}
    for stamp, msg in _tlog_messages(path, None, allow_truncated):
        rows.setdefault(msg.get_type(), []).append((stamp, msg))
    for kind in sorted(rows):
        m0 = rows[kind][0][1]
        names = list(m0.get_fieldnames())
        boot = "time_boot_ms" in names
        t = np.array([m.time_boot_ms * 1e-3 if boot else st for st, m in rows[kind]])
        fu = getattr(m0, "fieldunits_by_name", {})
        topics.append(_topic(kind, None, [n for n in names if n != "time_boot_ms"],
                             [fu.get(n) or "" for n in names if n != "time_boot_ms"], t))
    return LogListing(name=path.name, format=fmt, clock="time_boot_ms where a message has it, else the tlog's stamps",
                      topics=tuple(topics))
