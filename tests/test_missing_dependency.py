"""A missing optional dependency (python-control) raises delaykit's MissingDependencyError, an ImportError too.

``sys.modules["control"] = None`` makes ``import control`` fail with ImportError, as it does where python-control
is not installed; the tests do not need python-control themselves.
"""

from __future__ import annotations

import sys

import pytest

from delaykit.errors import DelaykitError, MissingDependencyError
from delaykit.models.transfer import TransferFunction


def test_to_control_without_python_control(monkeypatch):
    monkeypatch.setitem(sys.modules, "control", None)
    with pytest.raises(MissingDependencyError, match=r"python-control.*pip install control") as info:
        TransferFunction.parse("2/(s+1)").to_control()
    assert isinstance(info.value, ImportError) and isinstance(info.value, DelaykitError)
    assert not isinstance(info.value, ValueError)  # no longer an InvalidValueError
    assert isinstance(info.value.__cause__, ImportError)  # the original failure is chained


def test_except_import_error_catches_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "control", None)
    try:
        TransferFunction.parse("1/s").to_control()
    except ImportError as exc:  # what code around an optional feature writes
        assert type(exc) is MissingDependencyError
    else:  # pragma: no cover
        pytest.fail("to_control() did not raise")


def test_to_control_with_python_control():
    control = pytest.importorskip("control")
    c = TransferFunction.parse("2/(s+1)").to_control()
    assert isinstance(c, control.TransferFunction) and float(c.dcgain()) == 2.0
