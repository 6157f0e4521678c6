"""delaykit's exceptions: every one is exported from the package and derives from DelaykitError; code tells them
apart by type (the range parser, the port errors, the demo's failed flight), and ``import delaykit`` stays light."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import subprocess
import sys

import pytest

import delaykit
from delaykit.errors import (DelaykitError, FlightError, InvalidValueError, PortError, PortNumberError,
                             RangeSpecError)


def _exception_classes() -> dict[str, type]:
    """Every public exception class defined in a module of delaykit (found by importing them all)."""
    found: dict[str, type] = {}
    for info in pkgutil.walk_packages(delaykit.__path__, "delaykit."):
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if (inspect.isclass(obj) and issubclass(obj, BaseException) and obj.__module__ == module.__name__
                    and not name.startswith("_")):
                found[name] = obj
    return found


def test_every_exception_class_is_exported_and_is_a_delaykit_error():
    classes = _exception_classes()
    # the ones the package is known to have (a guard against the walk finding nothing)
    assert {"DelaykitError", "InvalidValueError", "InvalidTypeError", "RangeSpecError", "PortError",
            "PortNumberError", "FlightError", "ProtocolError", "ATError", "NavdataError", "LinkError",
            "EstimationError", "LogError"} <= set(classes)
    for name, cls in classes.items():
        assert getattr(delaykit, name) is cls, f"delaykit.{name} is not {cls.__module__}.{name}"
        assert name in delaykit.__all__, f"{name} is not in delaykit.__all__"
        if issubclass(cls, Warning):  # warnings have their own base class
            assert issubclass(cls, delaykit.DelaykitWarning), f"{cls.__module__}.{name} is not a DelaykitWarning"
            continue
        assert issubclass(cls, DelaykitError), f"{cls.__module__}.{name} is not a DelaykitError"


def test_import_delaykit_stays_light():
    code = ("import delaykit, sys\n"
            "from delaykit import DelaykitError, InvalidValueError, PortError, RangeSpecError, FlightError\n"
            "heavy = [m for m in ('numba', 'numpy', 'scipy', 'matplotlib') if m in sys.modules]\n"
            "assert not heavy, heavy\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_port_errors_are_os_errors_not_bad_values():
    assert issubclass(PortError, DelaykitError) and issubclass(PortError, OSError)
    assert not issubclass(PortError, ValueError)
    # a port number out of range is a bad value, and a port error
    assert issubclass(PortNumberError, PortError) and issubclass(PortNumberError, InvalidValueError)
    e = PortError("at port 5556 on 127.0.0.1 is already in use")
    assert str(e) == "at port 5556 on 127.0.0.1 is already in use"
    from delaykit.hardware.emulator import EmulatorConfig

    with pytest.raises(PortNumberError, match="0 to 65535"):
        EmulatorConfig(at_port=70000)


def test_cli_prints_a_port_error_in_one_line_with_status_2():
    import typer

    from delaykit.cli.common import friendly as _friendly

    @_friendly
    def busy() -> None:
        raise PortError("at port 5556 on 127.0.0.1 is already in use")

    with pytest.raises(typer.Exit) as info:
        busy()
    assert info.value.exit_code == 2


def test_range_parser_raises_a_type_the_command_line_catches():
    from delaykit.cli.app import parse_delays
    from delaykit.design.tuning import parse_range

    for bad in ("soon", "1:2", "a:b:c", "0.1,x"):
        with pytest.raises(RangeSpecError, match="START:STOP:N"):
            parse_range(bad, "kv")
    for bad, fragment in (("0.5:0.2:3", "reversed"), ("0:1:0", "at least 1"), ("nan", "finite")):
        with pytest.raises(InvalidValueError, match=fragment) as info:
            parse_range(bad, "kv")
        assert not isinstance(info.value, RangeSpecError)
    with pytest.raises(RangeSpecError, match="is not a delay"):
        parse_delays("soon")
    with pytest.raises(InvalidValueError, match="STOP must exceed START") as info:
        parse_delays("0.5:0.2:3")  # a well-formed range with bad values keeps its own message
    assert not isinstance(info.value, RangeSpecError)


def _no_logs(*_args, **_kwargs):
    from delaykit.hardware.flight import FlightResult

    return FlightResult((), "no navdata from the drone", False, 0, 0, None, None, None, ())


def test_demo_with_a_flight_that_gives_no_logs_raises_a_flight_error(tmp_path, monkeypatch):
    import delaykit.paper.demo as demo

    monkeypatch.setattr(demo, "fly", _no_logs)
    with pytest.raises(FlightError, match="the P flight did not fly: no navdata from the drone"):
        demo.run_demo(tmp_path, host="127.0.0.1", p_steps=1)
    # the same through the command line: one line, status 2, no traceback
    from typer.testing import CliRunner

    from delaykit.cli import app

    res = CliRunner().invoke(app, ["demo", "--out", str(tmp_path), "--host", "127.0.0.1", "--yes", "--p-steps", "1"])
    assert res.exit_code == 2, res.output
    assert "the P flight did not fly" in res.output and "Traceback" not in res.output
