"""Flying the delay compensators on the loopback emulator, the delay monitor (alarm, scheduling) in flight, and
their command-line options.  No packet leaves 127.0.0.1.

The commands in the logs are checked against `test_laws.replay`, an independent DOP853 integration of each law's
equations on the logged packets."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_flight import emulator, plan
from test_laws import replay

from delaykit.design.compensators import tune_compensator
from delaykit.hardware.flight import fly
from delaykit.identify.flightlog import FlightLog


def _fly(emu, tmp_path, **kw):
    return fly(plan(**kw), tmp_path / "f.csv", host="127.0.0.1", at_port=emu.ports["at"],
               navdata_port=emu.ports["navdata"])


@pytest.mark.realtime
@pytest.mark.parametrize("kind", ["smith", "filtered-smith", "predictor"])
def test_each_compensator_flies_its_law_and_settles(tmp_path, kind):
    # designed for the emulator's loop delay (0.27 + 2 x 0.01 s) on the integrator model; the drone is that model
    # (the lag vehicle, no lag).
    # Real time: these designs tolerate a delay error of only -40 to +50 % (filtered Smith, Tc 37 ms), so a
    # loaded machine that delays the law's packets by tens of milliseconds makes them ring; they fly alone.
    law = tune_compensator(kind, "1/s", 0.29)
    with emulator(delay=0.27, link_delay=0.01, vehicle="lag", lag=0.0, noise=0.002, seed=3) as emu:
        res = _fly(emu, tmp_path, controller=law, steps=(0.8,), step_duration=4.0)
    assert res.completed, res.reason
    assert res.controller["controller"]["kind"] == kind
    log = FlightLog.from_csv(res.logs[0])
    step = log.z_ref == log.z_ref[-1]  # the rows flown by the law (before them: the hover's second)
    assert step.sum() > 40
    extra = {k: np.array(v, float) for k, v in log.extra.items()}  # (the log keeps extra columns as text)
    t, z, r, vz = extra["recv_time"][step], log.z[step], log.z_ref[step], extra["vz"][step]
    ref = replay(law, t, r, z, vz)
    # the log keeps 9 decimals of z_ref, u and the arrival times: rounding the inputs of these high-gain laws
    # (primary gains up to ~35, and a history of saturated commands) moves the command by ~1e-6
    assert np.max(np.abs(log.u[step] - ref)) < 2e-5, np.max(np.abs(log.u[step] - ref))
    assert np.all(np.abs(log.u) <= 1.0 + 1e-12) and np.any(np.abs(log.u[step]) == 1.0)  # it saturated
    assert abs(np.mean(z[-15:]) - r[-1]) < 0.02  # settled on the new reference (noise 2 mm)


def test_fly_command_refuses_bad_compensator_options_with_status_2(tmp_path):
    from typer.testing import CliRunner

    from delaykit.cli import app

    runner = CliRunner()
    cases = [
        (["--controller", "smith"], "needs --model-delay"),
        (["--controller", "smith", "--model-delay", "-0.3"], "--model-delay (s) must be"),
        (["--controller", "smith", "--model-delay", "0.3", "--kp", "1"], "--kp/--kv are for p and pv"),
        (["--controller", "pid", "--kp", "1"], "--controller must be p, pv or one of smith"),
        (["--controller", "p"], "--controller p needs --kp"),
        (["--kp", "1", "--model-delay", "0.3"], "are for the compensators"),
        (["--kp", "1", "--schedule"], "need --monitor"),
        (["--kp", "1", "--monitor", "--design-range", "0.5,0.2"], "design_range must have low < high"),
        (["--kp", "1", "--monitor", "--design-range", "abc"], "--design-range"),
    ]
    for args, message in cases:
        res = runner.invoke(app, ["fly", "--host", "127.0.0.1", "--at-port", "9", "--navdata-port", "9",
                                  "--log", str(tmp_path / "x.csv"), *args])
        said = " ".join(res.output.split())  # (the console wraps long lines)
        assert res.exit_code == 2 and message in said and "Traceback" not in said, (args, said)
    assert not (tmp_path / "x.csv").exists()


@pytest.mark.realtime
def test_the_monitor_follows_a_delay_that_moves_raises_the_alarm_and_reschedules(tmp_path):
    # the emulator's actuator delay moves from 0.25 to 0.40 s about 13 s into the run (around the fourth step); the
    # loop delay the estimator sees is that plus the link both ways (2 x 5 ms).  A Smith predictor designed for
    # 0.26 s with a 20 % delay uncertainty has the design range [0.208, 0.312] s, so 0.41 s must raise the alarm,
    # and scheduling re-designs it for the estimate: the steps after that fly a law whose range holds the new delay.
    from typer.testing import CliRunner

    from delaykit.cli import app

    runner = CliRunner()
    change = 13.0
    with emulator(delay=0.25, link_delay=0.005, vehicle="lag", lag=0.0, noise=0.003, seed=8,
                  delay_schedule=[(change, 0.40)]) as emu:
        res = runner.invoke(app, ["fly", "--host", "127.0.0.1", "--at-port", str(emu.ports["at"]), "--navdata-port",
                                  str(emu.ports["navdata"]), "--controller", "smith", "--model-delay", "0.26",
                                  "--steps", "0.5,-0.5,0.5,-0.5,0.5,-0.5,0.5", "--duration", "3", "--hover", "1",
                                  "--monitor", "--schedule", "--log", str(tmp_path / "f.csv"), "--json"])
        t0 = emu._t0
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    online = out["online"]
    assert len(online) == 7
    # which steps flew wholly before or after the change, from the log's own clock (recv_time is monotonic)
    spans = []
    for p in out["logs"]:
        log = FlightLog.from_csv(p)
        rt = np.array(log.extra["recv_time"], float)[log.z_ref == log.z_ref[-1]]
        spans.append((rt[0] - t0, rt[-1] - t0))
    before = [o for o, (a, b) in zip(online, spans) if b < change]
    after = [o for o, (a, b) in zip(online, spans) if a > change + 0.5]
    assert len(before) >= 2 and len(after) >= 2
    for o in before:  # truth 0.26 s: within the interval's reach (3.3 standard errors) and no alarm
        assert abs(o["delay"] - 0.26) < 3.3 * o["estimate"]["stderr"] + 0.005, o
        assert not o["alarm"]
    first_after = after[0]
    assert abs(first_after["delay"] - 0.41) < 3.3 * first_after["estimate"]["stderr"] + 0.005, first_after
    alarms = [o for o in online if o["alarm"]]
    assert alarms and alarms[0]["action"] == "redesigned"
    assert alarms[0]["controller"]["model_delay"] == pytest.approx(alarms[0]["delay"])
    # after the re-design the new law's range holds the new delay: no alarm on the later steps
    later = [o for o in after if o["step"] > alarms[0]["step"]]
    assert later and all(not o["alarm"] and o["design_range"][0] < 0.41 < o["design_range"][1] for o in later)
    assert out["completed"] and out["alarms"] == len(alarms)
