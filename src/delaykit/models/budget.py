"""The work limits: how much one call may ask for, checked before the work starts.

A request beyond a limit is refused at once with an :class:`~delaykit.errors.InvalidValueError` that names the
value, the limit and what to change, instead of running for hours or filling the memory.  The limits are
generous (each is far beyond what the paper or a flight needs) and come from memory and time:

* :data:`MAX_RANGE_POINTS` values in one range (``START:STOP:N``, a comma list, Lambert branches ``K1:K2``): each
  value is a simulation, a root search or a design candidate, some milliseconds to a second each;
* :data:`MAX_GRID_POINTS` candidates in one gain search (the product of its ranges);
* :data:`MAX_ROOT_GRID_POINTS` points of a root search's grid, which is finer the longer the delay;
* :data:`MAX_FREQUENCY_DECADES` decades of a frequency range (a plot);
* :data:`MAX_SAMPLES` samples in one record (a response sampled every ``dt``, a log put on a uniform clock):
  each sample is some 32 bytes per column in memory and some 60 bytes of CSV, so the limit keeps a record below a
  gigabyte;
* :data:`MAX_PIECES` Taylor pieces of one exact time response of a delay system, and
  :data:`MAX_PIECE_CHANNELS` pieces times delay channels (each piece keeps a polynomial per channel);
* :data:`MAX_MATRIX_ELEMENTS` elements of one matrix a call builds (a discretised system's state matrix, the
  matrices of a frequency response's solve);
* :data:`MAX_RESPONSE_POINTS` values of one frequency response (frequencies x outputs x inputs), and
  :data:`MAX_SOLVE_WORK` operations of its solves;
* :data:`MAX_TEXT_CHARS` characters of one transfer function written as text;
* :data:`MAX_FLIGHT_SECONDS` seconds of one flight plan;
* :data:`MAX_CONFIG_BYTES` bytes of a loop, system or model file, :data:`MAX_FILE_BYTES` of a data file read
  whole (a delay trace, a reference) and :data:`MAX_LOG_BYTES` of a CSV log read row by row; only regular files
  are read (:func:`open_regular`): a device such as ``/dev/zero`` never ends and a FIFO blocks the reader, so
  both are refused before the read.

The user documentation lists them (``docs/guide/limits.md``).

Examples
--------
>>> check_count("--delay", 100_000_000, MAX_RANGE_POINTS, "values")
Traceback (most recent call last):
...
delaykit.errors.InvalidValueError: --delay: 100000000 values, above the limit of 10000 (delaykit.models.budget.MAX_RANGE_POINTS)
"""

from __future__ import annotations

import math
import os
import stat
from typing import IO, Any, Iterator

from ..errors import InvalidValueError

__all__ = ["MAX_RANGE_POINTS", "MAX_GRID_POINTS", "MAX_ROOT_GRID_POINTS", "MAX_FREQUENCY_DECADES", "MAX_SAMPLES",
           "MAX_PIECES", "MAX_PIECE_CHANNELS", "MAX_MATRIX_ELEMENTS", "MAX_RESPONSE_POINTS", "MAX_SOLVE_WORK",
           "MAX_TEXT_CHARS", "MAX_FLIGHT_SECONDS", "MAX_CONFIG_BYTES", "MAX_FILE_BYTES", "MAX_LOG_BYTES",
           "BLOCK_ELEMENTS", "check_count", "sample_count", "check_response", "blocks", "shorten", "open_regular",
           "read_regular"]

MAX_RANGE_POINTS = 10_000
"""Values in one range (a sweep of delays or gains, Lambert branches)."""

MAX_GRID_POINTS = 1_000_000
"""Candidates in one gain search (Kp values x Kv values x delays); also the loops of one batch simulation
(``simulate_many``), the runs of one Monte Carlo study and a robust design's plants x grid frequencies."""

MAX_ROOT_GRID_POINTS = 20_000_000
"""Points of one root search's candidate grid (some six per ``2 pi / delay`` along Im, 24 or more across the
region): a region that needs more holds more roots than can be listed (a chain puts one every ``2 pi / delay``)."""

MAX_FREQUENCY_DECADES = 24
"""Decades of one frequency range (a Bode or Nyquist plot, a frequency grid): 1e-12 to 1e12 rad/s."""

MAX_SAMPLES = 10_000_000
"""Samples in one record: a response sampled every ``dt``, a log resampled on a uniform clock."""

MAX_PIECES = 1 << 21
"""Taylor pieces of one exact time response of a delay system (``delaykit.step_response`` and its kin): the kernel
keeps every piece's polynomials (some 200 bytes per delay channel each) for the delays to read."""

MAX_PIECE_CHANNELS = 1 << 22
"""Taylor pieces times delay channels of one exact time response: each piece keeps one polynomial (some 216
bytes) per delay channel, so this keeps a run's history under 1 GB; a system of many delay channels gets fewer
pieces (500 channels: 8,388 pieces)."""

MAX_MATRIX_ELEMENTS = 1 << 24
"""Elements of one matrix built by a call (a 4096 x 4096 matrix, 128 MiB of floats): the state matrix of a
discretised system (its states plus the inputs held over the longest delay), the matrix solved at each point of a
frequency response and the parts of a system built by the algebra (states plus delay channels, squared)."""

MAX_RESPONSE_POINTS = 16_000_000
"""Values of one frequency response (``len(w) x outputs x inputs``, 16 bytes each: 256 MB), and so at most
16 million frequencies of a single-input single-output one.  The response is computed in blocks of frequencies,
so the work memory stays some 32 MiB whatever the count."""

MAX_SOLVE_WORK = 10**11
"""Operations of one frequency response's solves, counted as ``len(w) x (states + delay channels)^3``: some
minutes of work at most.  A transfer matrix is realised entry by entry, so a 10 x 10 one of first-order entries
with delays has 200 such unknowns, 8e6 operations at each frequency."""

MAX_TEXT_CHARS = 2000
"""Characters of one transfer function written as text (``"12.8*exp(-s)/(16.7*s+1)"``): parsing is quadratic
at worst, and a text this long is no transfer function anyone writes."""

MAX_FLIGHT_SECONDS = 3600.0
"""Seconds of one flight plan (the hover and every step): an hour, several times a battery's charge."""

MAX_CONFIG_BYTES = 1 << 20
"""Bytes of a settings file read whole: a loop, system or model file (a real one is some hundreds of bytes)."""

MAX_FILE_BYTES = 64 * 1024 * 1024
"""Bytes of a data file read whole into memory: a delay trace (a flight log's latency column, some 80 bytes a
row), a reference; its rows as text take some eight times its size."""

MAX_LOG_BYTES = 1 << 30
"""Bytes of a CSV log read row by row (flight logs, identification logs): at some 60 bytes a sample, above
:data:`MAX_SAMPLES` rows."""

_LIMITS = ("MAX_RANGE_POINTS", "MAX_GRID_POINTS", "MAX_ROOT_GRID_POINTS", "MAX_FREQUENCY_DECADES", "MAX_SAMPLES",
           "MAX_PIECES", "MAX_PIECE_CHANNELS", "MAX_MATRIX_ELEMENTS", "MAX_RESPONSE_POINTS", "MAX_SOLVE_WORK",
           "MAX_TEXT_CHARS", "MAX_FLIGHT_SECONDS", "MAX_CONFIG_BYTES", "MAX_FILE_BYTES", "MAX_LOG_BYTES")
_NAMES = {globals()[k]: k for k in _LIMITS}  # a refusal names its limit, found by value: the values differ
assert len(_NAMES) == len(_LIMITS), "two limits of one value: a refusal could name the wrong one"

BLOCK_ELEMENTS = 1 << 21
"""Not a limit: the elements (complex, 32 MiB) of the work arrays of one block of a computation done in blocks
(a frequency response, :func:`blocks`), so that its work memory does not grow with the number of points."""

_MAX_WHAT = 120  # characters of ``what`` quoted in a refusal (a refusal stays one short line)


def shorten(text: str, limit: int = _MAX_WHAT) -> str:
    """``text``, cut to ``limit`` characters with ``...`` (a value quoted in a message stays short).

    Examples
    --------
    >>> shorten("1," * 100, 12)
    '1,1,1,1,1...'
    """
    return text if len(text) <= limit else text[:limit - 3] + "..."


def check_count(what: str, count: float, limit: int, unit: str, hint: str = "") -> int:
    """Return ``count`` as an int, or raise :class:`~delaykit.errors.InvalidValueError` when it exceeds ``limit``.

    Parameters
    ----------
    what : str
        What asks for the work, as the user wrote it (``"--delay"``, ``"dt = 1e-09 s over 15 s"``).
    count : float
        How many items it asks for (a float, so that an astronomically large count is no problem).
    limit : int
        The limit (one of this module's constants).
    unit : str
        What is counted (``"values"``, ``"samples"``).
    hint : str
        What to change, appended to the message.

    Examples
    --------
    >>> check_count("--kp", 5, MAX_RANGE_POINTS, "values")
    5
    """
    if not count <= limit:  # (also refuses NaN)
        try:
            shown = f"{count:.0f}" if count < 1e18 else f"{count:.3g}"
        except OverflowError:  # an integer beyond the floats
            shown = f"about 1e{len(str(int(count))) - 1}"
        raise InvalidValueError(f"{shorten(what)}: {shown} {unit}, above the limit of {limit:.15g}{_where(limit)}"
                                + (f"; {hint}" if hint else ""))
    return int(count)


def check_response(points: int, outputs: int = 1, inputs: int = 1) -> None:
    """Refuse a frequency response of ``points`` frequencies of a system of ``outputs`` x ``inputs`` beyond
    :data:`MAX_RESPONSE_POINTS` values.

    Examples
    --------
    >>> check_response(10**7, 2, 2)
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: a frequency response at 10000000 frequencies of 2 outputs x 2 inputs: 40000000 values, above the limit of 16000000 (delaykit.models.budget.MAX_RESPONSE_POINTS); ask for fewer frequencies
    """
    check_count(f"a frequency response at {points} frequencies of {outputs} output{'s' * (outputs != 1)} x {inputs} "
                f"input{'s' * (inputs != 1)}", float(points) * outputs * inputs, MAX_RESPONSE_POINTS, "values",
                "ask for fewer frequencies")


def blocks(count: int, per_item: int) -> Iterator[slice]:
    """Slices of ``range(count)`` in blocks of work arrays of about :data:`BLOCK_ELEMENTS` elements, ``per_item``
    of them for each item (at least one item per block).

    Examples
    --------
    >>> [(b.start, b.stop) for b in blocks(5, BLOCK_ELEMENTS // 2)]
    [(0, 2), (2, 4), (4, 5)]
    """
    step = max(1, BLOCK_ELEMENTS // max(int(per_item), 1))
    for i in range(0, count, step):
        yield slice(i, min(i + step, count))


def _where(limit: float, name: str | None = None) -> str:
    name = name or _NAMES.get(limit)  # type: ignore[call-overload]
    return f" (delaykit.models.budget.{name})" if name else ""


_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _kind(mode: int) -> str | None:
    """What a file of this mode is, or ``None`` for a regular file."""
    if stat.S_ISREG(mode):
        return None
    return next((what for test, what in _KINDS if test(mode)), "not a regular file")


def open_regular(path: Any, what: str, max_bytes: int = MAX_FILE_BYTES, *,
                 error: type[InvalidValueError] = InvalidValueError) -> IO[bytes]:
    """Open a regular file of at most ``max_bytes`` for reading (binary), or refuse it before reading a byte.

    The kind is checked before the file is opened (a device such as ``/dev/zero`` never ends, a FIFO blocks the
    reader until a writer comes) and again on the open file (opened without blocking), so a file swapped in
    between is refused too.

    Parameters
    ----------
    path : str or path-like
        The file.
    what : str
        What the file is, for the message (``"loop file"``).
    max_bytes : int
        The largest size accepted (:data:`MAX_FILE_BYTES` or :data:`MAX_LOG_BYTES`).
    error : type
        The :class:`~delaykit.errors.InvalidValueError` subclass to raise (``LogError`` for a log).

    Raises
    ------
    OSError
        A file that does not exist or cannot be opened (the caller words it).
    InvalidValueError
        (or ``error``) A file that is not a regular file, or is larger than ``max_bytes``.

    Examples
    --------
    >>> open_regular("/dev/zero", "loop file")
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: the loop file '/dev/zero' is a character device, not a regular file: only regular files are read
    """
    name = os.fspath(path)
    if isinstance(name, bytes):
        name = os.fsdecode(name)

    def check(st: os.stat_result) -> None:
        kind = _kind(st.st_mode)
        if kind is not None:
            raise error(f"the {what} {shorten(name)!r} is {kind}, not a regular file: only regular files are read")
        if st.st_size > max_bytes:
            raise error(f"the {what} {shorten(name)!r} is {st.st_size} bytes, above the limit of {max_bytes}"
                        f"{_where(max_bytes)}")

    check(os.stat(name))
    fd = os.open(name, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    try:
        check(os.fstat(fd))
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: Any, what: str, max_bytes: int = MAX_FILE_BYTES, *,
                 error: type[InvalidValueError] = InvalidValueError) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (:func:`open_regular`, read with that cap, so a file
    that grows while it is read is refused too).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.NamedTemporaryFile(suffix=".toml") as f:
    ...     _ = f.write(b"kp = 1"); f.flush()
    ...     read_regular(f.name, "loop file")
    b'kp = 1'
    """
    with open_regular(path, what, max_bytes, error=error) as fh:
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise error(f"the {what} {shorten(os.fsdecode(os.fspath(path)))!r} is more than {max_bytes} bytes"
                    f"{_where(max_bytes)}")
    return data


def sample_count(what: str, span: float, step: float, hint: str = "") -> int:
    """The number of samples every ``step`` over ``span`` (both ends included), checked against
    :data:`MAX_SAMPLES`.

    Examples
    --------
    >>> sample_count("dt", 15.0, 0.01)
    1501
    >>> sample_count("--dt 1e-09 s", 15.0, 1e-9)
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: --dt 1e-09 s: 15000000001 samples, above the limit of 10000000 (delaykit.models.budget.MAX_SAMPLES)
    """
    try:
        n = float(span) / float(step) * (1 + 1e-12) + 1 if span > 0 else 1.0  # (Python floats: no numpy warning)
    except (OverflowError, ZeroDivisionError):  # a step of 1e-320: beyond any count
        n = math.inf
    check_count(what, n, MAX_SAMPLES, "samples", hint)
    return math.floor(n)
