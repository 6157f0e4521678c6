"""Where the tests (and the docs) read real measured data that nobody on this project made.

The project holds no copies of such data: it is read in place from ``../shared/data`` beside the project's folder
(the CI machine lays it there), or from the folder named by the environment variable ``DELAYKIT_DATA``.  A test
that needs a file calls :func:`data_path`, which skips the test, saying which file is absent and where it was looked
for, when the data is not there.  The library itself never reads this folder.

A documentation page that reads the data says so on a line of its own, an HTML comment that does not show::

    <!-- reads shared data: tclab/step_test.csv -->

(:func:`data_needed` finds these): where a file it names is absent, ``docs/conf.py`` builds the page without
running it and says so on the page, and ``docs/conftest.py`` skips its doctests, saying why.

The PX4 logs there are the full flights (t = 10 to about 44 s).  The numbers of ``examples/px4-altitude.toml`` and
``examples/px4-vehicle.toml`` were identified on their first part, t = 10 to 30 s (the 1 m step at 15 s and the
15 s after it); :func:`px4_flights` and :func:`write_window` cut the logs there (:data:`PX4_WINDOW`) for the tests
that check those numbers.
"""

from __future__ import annotations

import csv
import os
import re
from pathlib import Path

__all__ = ["DATA", "PX4_WINDOW", "absent_reason", "data_needed", "data_path", "have_data", "missing_data",
           "px4_flights", "window", "write_window"]

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("DELAYKIT_DATA") or ROOT.parent / "shared" / "data")

PX4_WINDOW = 30.0
"""The end (s) of the part of each PX4 log the examples' numbers were identified on (the logs start at 10 s)."""

_MARK = re.compile(r"^<!--\s*reads shared data:\s*(.+?)\s*-->\s*$", re.MULTILINE)


def have_data(*parts: str) -> bool:
    """Whether ``DATA/parts...`` exists (for ``pytest.mark.skipif`` and parametrisation at collection time)."""
    return DATA.joinpath(*parts).exists()


def absent_reason(p: Path) -> str:
    """The one sentence a skipped test or an unexecuted page gives for the absent data file ``p``."""
    return (f"the real data {p} is absent: it is read from ../shared/data beside the project "
            "(or from $DELAYKIT_DATA), and the project holds no copy of it")


def data_path(*parts: str) -> Path:
    """The path of ``DATA/parts...``; skips the calling test, saying why, where it is absent."""
    p = DATA.joinpath(*parts)
    if not p.exists():
        import pytest

        pytest.skip(absent_reason(p))
    return p


def data_needed(text: str) -> list[str]:
    """The data files (relative to ``DATA``) a documentation page's text says it reads (see the module's text)."""
    return [name.strip() for m in _MARK.finditer(text) for name in m.group(1).split(",") if name.strip()]


def missing_data(text: str) -> list[Path]:
    """The files a page's text says it reads that are absent (empty: the page can run)."""
    return [DATA / name for name in data_needed(text) if not (DATA / name).exists()]


def window(e, t_end: float = PX4_WINDOW):
    """The experiment ``e`` (a :class:`delaykit.identify.Experiment` read from a file) up to ``t_end`` s, the same
    arrays as reading a copy of its file cut there."""
    from delaykit.identify import Experiment

    k = e.t <= t_end + 1e-9
    return Experiment.from_arrays(e.t[k], {o: v[k] for o, v in e.outputs.items()},
                                  u=None if e.u is None else e.u[k], r=None if e.r is None else e.r[k],
                                  name=e.name, input_name=e.input_name, reference_name=e.reference_name,
                                  u_before=e.u_before)


def px4_flights(names, *, outputs=("z",), t_end: float | None = PX4_WINDOW, **kw) -> list:
    """The PX4 flights ``names`` (e.g. ``"HAYDEN_01"``) read with :func:`delaykit.identify.read_experiment`
    (``outputs`` and ``kw`` passed on), cut at ``t_end`` s (``None``: the full logs); skips where absent."""
    from delaykit.identify import read_experiment

    logs = [read_experiment(data_path("px4-altitude", f"{n}.csv"), outputs=list(outputs), **kw) for n in names]
    return logs if t_end is None else [window(e, t_end) for e in logs]


def write_window(src: Path, dest: Path, t_end: float = PX4_WINDOW) -> Path:
    """Write the rows of the CSV log ``src`` with ``t <= t_end`` to ``dest`` (a file, or a folder to hold one of
    the same name), for the command line; returns the file written."""
    dest = dest / src.name if dest.is_dir() else dest
    with open(src, newline="", encoding="utf-8") as f, open(dest, "w", newline="", encoding="utf-8") as out:
        rows = csv.reader(f)
        head = next(rows)
        w = csv.writer(out, lineterminator="\n")
        w.writerow(head)
        i = head.index("t")
        w.writerows(r for r in rows if float(r[i]) <= t_end + 1e-9)
    return dest
