"""Where the tests read real measured data that nobody on this project made.

The project holds no copies of such data: it is read in place from ``../shared/data`` beside the project's folder
(the CI machine lays it there), or from the folder named by the environment variable ``DELAYKIT_DATA``.  A test
that needs a file calls :func:`data_path`, which skips the test, saying which file is absent and where it was looked
for, when the data is not there.  The library itself never reads this folder.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

__all__ = ["DATA", "data_path", "have_data"]

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("DELAYKIT_DATA") or ROOT.parent / "shared" / "data")


def have_data(*parts: str) -> bool:
    """Whether ``DATA/parts...`` exists (for ``pytest.mark.skipif`` and parametrisation at collection time)."""
    return DATA.joinpath(*parts).exists()


def data_path(*parts: str) -> Path:
    """The path of ``DATA/parts...``; skips the calling test, saying why, where it is absent."""
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"the real data {p} is absent: it is read from ../shared/data beside the project "
                    "(or from $DELAYKIT_DATA), and the project holds no copy of it")
    return p
