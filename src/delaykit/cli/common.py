"""The command line's shared pieces: the Typer application, the consoles, the error wrapper, parsers and formatters."""

from __future__ import annotations

import csv
import functools
import math
from pathlib import Path
from typing import Any, Callable, Optional

import typer
from rich.console import Console
from rich.table import Table

from ..errors import DelaykitError, InvalidValueError, RangeSpecError

__all__ = [
    "app", "ci_list", "confirm_real", "err", "fmt", "fmt_ci", "friendly", "out", "parse_delays", "parse_schedule",
    "print_rms", "read_delay_trace",
]

app = typer.Typer(
    help="delaykit: feedback loops with a time delay (the quadrotor altitude loop of Armah & Yi).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
out = Console(soft_wrap=True)
err = Console(stderr=True)


def friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn delaykit's errors into one line on stderr and exit status 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except DelaykitError as exc:
            err.print(f"[bold red]error:[/] {exc}", highlight=False)
            raise typer.Exit(2) from None

    return wrapper


def parse_delays(spec: str) -> list[float]:
    """Delays from ``0.368``, ``START:STOP:N``, ``a,b,c`` or ``table1`` (the K·Ts of the paper's Table 1).

    Examples
    --------
    >>> parse_delays("0.2:0.5:4")
    [0.2, 0.3, 0.4, 0.5]
    >>> len(parse_delays("table1"))
    7
    """
    from ..models.ranges import parse_range

    spec = spec.strip()
    if spec.lower() == "table1":
        from ..models.altitude import PAPER_PERIOD
        from ..paper.data import TABLE1

        return [k * PAPER_PERIOD for k, _, _ in TABLE1]
    try:
        return parse_range(spec, "--delay")
    except RangeSpecError:
        raise RangeSpecError(f"--delay {spec!r} is not a delay: give seconds (0.368), START:STOP:N, a comma "
                             "list, or 'table1'") from None


def parse_schedule(spec: str) -> list[tuple[float, float]]:
    """A delay schedule from ``T:DELAY`` pairs separated by commas (times and delays in seconds): finite, the
    delays at least 0, the times increasing; an error names the bad item as the user wrote it.

    Examples
    --------
    >>> parse_schedule("20:0.40, 40:0.25")
    [(20.0, 0.4), (40.0, 0.25)]
    """
    pairs: list[tuple[float, float]] = []
    items = [x.strip() for x in spec.split(",")]
    for k, item in enumerate(items):
        parts = item.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            t, d = float(parts[0]), float(parts[1])
        except ValueError:
            raise InvalidValueError(f"--delay-schedule item {k + 1} {item!r} is not T:DELAY (seconds since "
                                    "start, delay in seconds), e.g. 20:0.40") from None
        if not (math.isfinite(t) and math.isfinite(d)):
            raise InvalidValueError(f"--delay-schedule item {k + 1} {item!r}: the time and the delay must be "
                                    "finite numbers")
        if d < 0:
            raise InvalidValueError(f"--delay-schedule item {k + 1} {item!r}: the delay {d:g} s is negative "
                                    "(a delay is at least 0 s)")
        if pairs and not t > pairs[-1][0]:
            raise InvalidValueError(f"--delay-schedule times must increase: item {k + 1} {item!r} (t = {t:g} s) "
                                    f"is not after item {k} {items[k - 1]!r} (t = {pairs[-1][0]:g} s)")
        pairs.append((t, d))
    return pairs


def fmt(x: Optional[float], digits: int = 4) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def fmt_ci(ci: Any, digits: int = 4) -> str:
    """A confidence interval as text: ``a to b``, or ``no interval`` when the method gave none (``None``)."""
    return "no interval" if ci is None else f"{ci[0]:.{digits}f} to {ci[1]:.{digits}f}"


def ci_list(ci: Any) -> Optional[list[float]]:
    """A confidence interval for JSON: ``[a, b]``, or ``None`` (null) when there is none."""
    return None if ci is None else [float(ci[0]), float(ci[1])]


def print_rms(title: str, rows: list[tuple[str, float, Optional[float]]]) -> None:
    """A table of each log's RMS error beside its initial wander (``None`` where the log has none)."""
    table = Table(title=title)
    for col in ("log", "rms", "initial wander", "rms / wander"):
        table.add_column(col, justify="right")
    for file, rms, w in rows:
        table.add_row(file, f"{rms:.4g}", fmt(w), fmt(rms / w if w else None, 3))
    out.print(table)


def read_delay_trace(path: Path) -> Any:
    """``--delay-trace``: a CSV of ``t,delay`` (s), or a flight log with ``latency_ms``, chosen by the header."""
    from ..simulate.varying import DelayTrace

    header: list[str] = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            header = [c.strip() for c in next(csv.reader(fh), [])]
    except (OSError, UnicodeDecodeError, csv.Error):
        return DelayTrace.from_csv(path)  # it says what is wrong with the file
    if not any(header):
        raise InvalidValueError(f"--delay-trace {str(path)!r} is empty: expected a header row t,delay (seconds) or "
                                "a flight log with t and latency_ms")
    if "delay" not in header and "latency_ms" in header:
        return DelayTrace.from_flight_log(path)
    if "delay" not in header:
        raise InvalidValueError(f"--delay-trace {str(path)!r} has no column 'delay' (s) or 'latency_ms' (a flight "
                                f"log); its header is {','.join(header)!r}")
    return DelayTrace.from_csv(path)


def confirm_real(host: str, yes: bool) -> Optional[Callable[[], bool]]:
    import ipaddress

    try:
        loop = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loop = False
    if loop or yes:
        return None
    return lambda: typer.confirm(f"Take off the drone at {host}?", default=False)
