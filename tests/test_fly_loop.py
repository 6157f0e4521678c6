"""``delaykit fly --loop FILE``: the controller of a loop file (as ``tune --save`` writes it) flown on the emulator.

Reference for the flight: delaykit's exact simulation of the same sampled loop (the file's PI on the emulator's
integrator, the delay the controller saw, the flight's packet interval), as in tests/test_tuning_flights.py, with
the same tolerances and their reasons.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit import Loop, load_loop, simulate
from delaykit.cli import app
from delaykit.hardware.emulator import DroneEmulator, EmulatorConfig
from delaykit.identify.flightlog import FlightLog
from delaykit.simulate.metrics import step_metrics

runner = CliRunner()


def _tuned(tmp_path, limits=("--vmax", "1")):
    path = tmp_path / "pi.toml"
    res = runner.invoke(app, ["tune", "--plant", "1/s", "--delay", "0.37", "--controller", "pi", "--ms", "1.4",
                              *limits, "--save", str(path)])
    assert res.exit_code == 0, res.output
    return path


def test_fly_loop_refuses_gains_beside_the_file(tmp_path):
    path = _tuned(tmp_path)
    res = runner.invoke(app, ["fly", "--host", "127.0.0.1", "--loop", str(path), "--kp", "2"])
    assert res.exit_code == 2 and "--loop" in res.output


def test_fly_loop_refuses_asymmetric_limits(tmp_path):
    path = _tuned(tmp_path, ("--umin", "-1", "--umax", "3"))
    res = runner.invoke(app, ["fly", "--host", "127.0.0.1", "--loop", str(path), "--log", str(tmp_path / "f.csv")])
    assert res.exit_code == 2 and "symmetric" in res.output and "Traceback" not in res.output


@pytest.mark.realtime
def test_a_tuned_pi_flies_from_its_loop_file(tmp_path):
    path = _tuned(tmp_path)
    loop = load_loop(path)
    assert loop.controller.ki > 0  # the file holds a PI, which fly could not fly before --loop
    config = EmulatorConfig(at_port=0, navdata_port=0, video_port=0, control_port=0, vehicle="lag", lag=0.0,
                            delay=0.37, noise=0.002, seed=3)
    log = tmp_path / "flight.csv"
    with DroneEmulator(config) as emu:
        res = runner.invoke(app, ["fly", "--host", "127.0.0.1", "--at-port", str(emu.ports["at"]), "--navdata-port",
                                  str(emu.ports["navdata"]), "--loop", str(path), "--duration", "12", "--hover", "0.8",
                                  "--log", str(log), "--json"])
        truth = emu.true_delay
    assert res.exit_code == 0, res.output
    result = json.loads(res.stdout)
    flown_log = FlightLog.from_csv(result["logs"][0])
    seen = truth + float(np.mean(np.asarray(flown_log.extra["latency_ms"], dtype=float))) / 1e3
    period = float(result["packet_interval"])
    flown = step_metrics(flown_log.t, flown_log.z, step=flown_log.step, step_time=flown_log.step_time)
    simulated = simulate(Loop("1/s", loop.controller, delay=seen, umin=-1, umax=1, period=period), 1.0,
                         t_end=12.0).metrics
    # tolerances of tests/test_tuning_flights.py: 5 points of overshoot, 1.5 packet intervals of rise time
    assert flown.overshoot == pytest.approx(simulated.overshoot, abs=5.0)
    assert flown.rise_time == pytest.approx(simulated.rise_time, abs=1.5 * period)
