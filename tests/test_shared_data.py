"""The project holds no copy of the real data it reads from ../shared/data (tests/shared_data.py), and the tests
and the documentation's pages that read it run where it is present and skip, saying why, where it is absent.

References: the data's own files (their SHA-256 against every file of the project); the old copies' layout (the
rows of the full logs up to 30 s) for the cut the PX4 tests make; pytest's own report of a run without the data.
"""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import shared_data
from shared_data import (DATA, PX4_WINDOW, data_needed, data_path, have_data, missing_data, px4_flights, window,
                         write_window)

ROOT = Path(__file__).resolve().parents[1]
SKIP_DIRS = {".git", "_build", "__pycache__", ".venv", "node_modules", ".hypothesis", "build", "dist"}


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _project_files():
    for dirpath, dirnames, filenames in os.walk(ROOT):
        dirnames[:] = [d for d in dirnames if d not in SKIP_DIRS and not d.endswith(".egg-info")]
        for name in filenames:
            yield Path(dirpath) / name


def test_the_project_holds_no_copy_of_the_shared_data():
    assert not (ROOT / "tests" / "data").exists()  # where the copies were until they moved to ../shared/data
    if not DATA.is_dir():
        pytest.skip(shared_data.absent_reason(DATA))
    shared = {_sha(p): p for p in DATA.rglob("*") if p.is_file()}
    assert len(shared) >= 20  # the README, 18 PX4 logs, the heater log, the flight logs
    copies = [(p.relative_to(ROOT), shared[h]) for p in _project_files() if p.stat().st_size > 0
              and (h := _sha(p)) in shared]
    assert not copies, copies


def test_the_project_holds_no_cut_of_the_px4_logs():
    # a cut copy (fewer rows or columns) hashes differently: look for the full logs' rows of t, z instead
    if not have_data("px4-altitude"):
        pytest.skip(shared_data.absent_reason(DATA / "px4-altitude"))
    rows = set()
    for p in (DATA / "px4-altitude").glob("*.csv"):
        lines = p.read_text().splitlines()[1:]
        rows.update(",".join(line.split(",")[:2]) for line in lines[300:320])  # 16 to 16.4 s: the step's start
    hits = [p.relative_to(ROOT) for p in _project_files() if p.suffix in {".csv", ".txt", ".json", ".md", ".toml"}
            and p.stat().st_size < 5_000_000 and any(r in p.read_text(errors="replace") for r in rows)]
    assert not hits, hits


def test_data_path_skips_saying_why_where_the_data_is_absent(monkeypatch, tmp_path):
    monkeypatch.setattr(shared_data, "DATA", tmp_path / "nowhere")
    with pytest.raises(pytest.skip.Exception, match=r"nowhere/tclab/step_test.csv is absent.*\.\./shared/data"):
        data_path("tclab", "step_test.csv")
    assert not shared_data.have_data("tclab")


def test_the_pages_say_which_data_they_read():
    text = "# A page\n\n<!-- reads shared data: tclab/step_test.csv, px4-altitude -->\n\nsome text\n"
    assert data_needed(text) == ["tclab/step_test.csv", "px4-altitude"]
    assert data_needed("mentions <!-- reads shared data: x --> inline only") == []
    assert [p.name for p in missing_data("<!-- reads shared data: no-such-file.csv -->")] == ["no-such-file.csv"]
    # every page whose run code (a tutorial's cells, a doctest) reads the shared data folder carries the line
    # (docs/conf.py and docs/conftest.py act on it), and names data the shared README describes
    readme = (DATA / "README.md").read_text() if have_data("README.md") else None
    pages = [p for p in sorted((ROOT / "docs").rglob("*.md")) if "_build" not in p.parts]
    reading = []
    for page in pages:
        text = page.read_text(encoding="utf-8")
        if re.search(r'environ\.get\("DELAYKIT_DATA"\)', text):  # code that finds the folder (prose may name it)
            reading.append(page.name)
            assert data_needed(text), f"{page} reads the shared data but has no '<!-- reads shared data: ... -->'"
            for name in data_needed(text):
                assert readme is None or name.split("/")[0] in readme, (page, name)
    assert {"px4.md", "heater.md", "pid-tuning.md", "identify.md"} <= set(reading), reading


def test_the_px4_window_is_the_old_copies_rows():
    # the tests cut the full logs at 30 s: the same rows as the copies the project held (t = 10.02 to 30.00 s)
    data_path("px4-altitude", "HAYDEN_01.csv")
    full = px4_flights(["HAYDEN_01"], outputs=("z", "vz"), reference="z_ref", t_end=None)[0]
    cut = px4_flights(["HAYDEN_01"], outputs=("z", "vz"), reference="z_ref")[0]
    assert full.t[-1] > 40.0 and cut.t[0] == full.t[0] == 10.02 and cut.t[-1] == PX4_WINDOW
    assert cut.t.size == 1000 and np.array_equal(cut.outputs["vz"], full.outputs["vz"][:1000])
    assert cut.name == full.name == "HAYDEN_01.csv"
    assert window(full).t.size == cut.t.size


def test_write_window_keeps_the_header_and_the_rows_up_to_the_end(tmp_path):
    src = data_path("px4-altitude", "SANCHEZ_01.csv")
    out = write_window(src, tmp_path)
    lines, orig = out.read_text().splitlines(), src.read_text().splitlines()
    assert out.name == src.name and lines[0] == orig[0]
    assert lines == orig[:len(lines)] and float(lines[-1].split(",")[0]) == 30.0
    assert float(orig[len(lines)].split(",")[0]) > 30.0


def test_without_the_data_the_tests_and_doctests_that_read_it_skip():
    # pytest run on a page's doctest and a test that read the data, with $DELAYKIT_DATA naming an absent folder
    env = {**os.environ, "DELAYKIT_DATA": str(ROOT / "no-such-data-folder")}
    test = "tests/test_identification.py::test_heater_prefers_the_second_order_structure"
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider",
                          "docs/howto/identify.md", test], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "2 skipped" in run.stdout and "failed" not in run.stdout, run.stdout
    assert run.stdout.count("no-such-data-folder/tclab/step_test.csv is absent") == 2, run.stdout
