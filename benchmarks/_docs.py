"""Shared by the benchmark scripts: write a script's tables into ``docs/benchmarks.md`` (``--write-docs``).

Each script owns one block of that page, between ``<!-- bench_x.py:begin -->`` and ``<!-- bench_x.py:end -->``;
:func:`write_docs` replaces what is between them (and nothing else) with a line saying when and on what machine
the numbers were measured, and the script's rich tables as Markdown.  The prose around the blocks is written by
hand and stays as it is.
"""

from __future__ import annotations

import datetime
import os
import platform
import sys
from pathlib import Path
from typing import Any

__all__ = ["DOCS", "markers", "machine_line", "markdown_table", "replace_block", "write_docs"]

DOCS = Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md"


def markers(script: str) -> tuple[str, str]:
    """The begin and end comments of ``script``'s block (``script`` is a file name such as ``bench_roots.py``)."""
    return f"<!-- {script}:begin -->", f"<!-- {script}:end -->"


def machine_line(now: datetime.datetime | None = None) -> str:
    """When and where: the UTC date, the machine (cores, processor, Python) and whether other jobs loaded it."""
    now = now or datetime.datetime.now(datetime.timezone.utc)
    cores = os.cpu_count() or 1
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    if load == load and load >= 0.5:  # not NaN: a shared machine slows the timings
        busy = f"load average {load:.1f} (shared with other jobs: times are slower than on a quiet machine)"
    else:
        busy = f"load average {load:.1f} (quiet)"
    return (f"Measured {now:%Y-%m-%d %H:%M} UTC by `--write-docs` on {cores} cores, "
            f"{platform.machine() or 'unknown machine'}, {platform.system()}, Python {platform.python_version()}; "
            f"{busy}.")


def _cell(value: Any) -> str:
    return str(value).replace("\n", "; ").replace("|", "\\|")


def markdown_table(table: Any) -> str:
    """A ``rich.table.Table`` as a Markdown table (its title, if any, as a line above it)."""
    heads = [_cell(c.header) for c in table.columns]
    cols = [[_cell(v) for v in c.cells] for c in table.columns]
    rows = [[col[i] if i < len(col) else "" for col in cols] for i in range(max(map(len, cols), default=0))]
    lines = [f"| {' | '.join(heads)} |", "|" + "---|" * len(heads)] + [f"| {' | '.join(r)} |" for r in rows]
    title = f"{_cell(table.title)}:\n\n" if table.title else ""
    return title + "\n".join(lines)


def replace_block(script: str, text: str, path: Path = DOCS) -> None:
    """Replace what is between ``script``'s markers in ``path`` with ``text``; the rest of the file is kept.

    Raises ``ValueError`` naming the file and the marker when either marker is missing, repeated or out of order.
    """
    begin, end = markers(script)
    doc = path.read_text(encoding="utf-8")
    if doc.count(begin) != 1 or doc.count(end) != 1 or doc.index(begin) > doc.index(end):
        raise ValueError(f"{path} must hold exactly one {begin} followed by one {end} "
                         f"(found {doc.count(begin)} and {doc.count(end)})")
    head, rest = doc.split(begin)
    _, tail = rest.split(end)
    path.write_text(f"{head}{begin}\n{text.strip()}\n{end}{tail}", encoding="utf-8")


def write_docs(script: str, *tables: Any, path: Path = DOCS) -> None:
    """Write ``tables`` (rich tables) into ``script``'s block of ``path``, under the date-and-machine line."""
    replace_block(script, "\n\n".join([machine_line()] + [markdown_table(t) for t in tables]), path)
    print(f"wrote {script}'s tables into {path}", file=sys.stderr)
