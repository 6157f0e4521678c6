# pytest collects the doctests of the docs' Markdown pages (see pyproject's doctest glob); these are not pages
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from shared_data import absent_reason, missing_data  # noqa: E402  (where real data is read, for tests and docs)

collect_ignore = ["conf.py", "_build", "api", "tutorials", "jupyter_execute"]


def pytest_runtest_setup(item):
    """A page that says it reads shared data (``<!-- reads shared data: ... -->``) has its doctests skipped,
    saying why, where that data is absent."""
    path = Path(str(getattr(item, "path", "")))
    if path.suffix == ".md" and path.is_file():
        missing = missing_data(path.read_text(encoding="utf-8"))
        if missing:
            pytest.skip(absent_reason(missing[0]))
