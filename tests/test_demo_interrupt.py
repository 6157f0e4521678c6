"""The demo stops when one of its flights is interrupted (issue 25): Ctrl-C, SIGTERM or SIGHUP lands the flight,
and no further flight takes off; the command exits 1 saying why, on one line."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

import delaykit
import delaykit.paper.demo as demo
from delaykit.cli import app
from delaykit.errors import FlightInterruptedError
from delaykit.hardware.flight import FlightResult


def _interrupted_fly(flown: list, signal_name: str):
    def fake_fly(plan, log, **_kw):  # (the real fly's result for an interrupted flight: landed, no logs)
        flown.append(plan)
        return FlightResult((), f"interrupted ({signal_name})", False, 10, 0, 0.2, 0.4, 0.065,
                            interrupted=signal_name)
    return fake_fly


@pytest.mark.parametrize("signal_name", ["Ctrl-C", "SIGTERM", "SIGHUP"])
def test_run_demo_stops_after_an_interrupted_flight(tmp_path, monkeypatch, signal_name):
    flown: list = []
    monkeypatch.setattr(demo, "fly", _interrupted_fly(flown, signal_name))
    with pytest.raises(FlightInterruptedError, match=rf"the P flight was interrupted \({signal_name}\)") as info:
        demo.run_demo(tmp_path, host="127.0.0.1", p_steps=1, pv_steps=1, compensate=False)
    assert info.value.signal_name == signal_name
    assert len(flown) == 1  # no second take-off


def test_demo_command_exits_1_with_one_line_when_a_flight_is_interrupted(tmp_path, monkeypatch):
    flown: list = []
    monkeypatch.setattr(demo, "fly", _interrupted_fly(flown, "SIGTERM"))
    res = CliRunner().invoke(app, ["demo", "--out", str(tmp_path / "d"), "--host", "127.0.0.1", "--yes",
                                   "--p-steps", "1", "--no-compensate"])
    assert res.exit_code == 1 and len(flown) == 1
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: the P flight was interrupted (SIGTERM)"), res.stderr


def test_a_flight_result_says_what_interrupted_it():
    r = FlightResult((), "interrupted (SIGHUP)", False, 0, 0, None, None, None, interrupted="SIGHUP")
    assert r.to_dict()["interrupted"] == "SIGHUP"
    assert FlightResult((), "completed", True, 0, 0, None, None, None).to_dict()["interrupted"] is None


@pytest.mark.realtime
@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_demo_on_the_emulator_lands_and_stops_on_a_signal(tmp_path, sig):
    # the whole command in its own process on the loopback emulator: the signal arrives during the P flight's
    # first step (its log file appears when the step begins); the flight lands and the PV flight never starts
    src = os.path.dirname(os.path.dirname(delaykit.__file__))
    env = {**os.environ, "PYTHONPATH": src + os.pathsep + os.environ.get("PYTHONPATH", "")}
    out = tmp_path / "demo"
    proc = subprocess.Popen([sys.executable, "-m", "delaykit.cli", "demo", "--out", str(out), "--p-steps", "2",
                             "--step-duration", "4", "--no-compensate", "--no-identify", "--seed", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            # Ctrl-C as a terminal delivers it: a run started in the background of a non-interactive
                            # shell (a CI job) inherits SIGINT ignored, and Python then keeps ignoring it
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 90  # (a first run may compile numba code)
        while not list(out.glob("p_flight*-1.csv")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.5)
        proc.send_signal(getattr(signal, sig))
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    name = "Ctrl-C" if sig == "SIGINT" else sig
    assert proc.returncode == 1, stderr
    assert "Traceback" not in stderr
    assert stderr.strip().splitlines()[-1].startswith(f"error: the P flight was interrupted ({name})"), stderr
    assert not list(out.glob("pv_flight*"))  # the next flight never took off
    assert not list(out.glob("p_flight*-2.csv"))  # nor the P flight's second step
