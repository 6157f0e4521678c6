"""Honest intervals: a parameter the data do not determine is reported as "not determined", never as a huge interval.

The logs are made with delaykit's exact held-input simulator (``held_response``) of a known plant, so the truth is
known; one log changes only the size of its single input step, so the verdict flips with what the data can show.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit.cli import app
from delaykit.identify.identification import (IdentifiedModel, identify, load_model, undetermined_reason)
from delaykit.identify.iodata import Experiment
from delaykit.models.transfer import TransferFunction
from delaykit.simulate.discrete import held_delay_model, held_response

H = 0.05  # 20 Hz, as the logs
T = np.arange(0.0, 60.0, H)
TRUE_DELAY = 0.25
PLANT = TransferFunction.parse("0.9/(s*(0.2*s+1))")  # ipdt_lag: gain 0.9, lag 0.2 s
STEP = np.where(T >= 30.0, 1.0, 0.0)
RESPONSE = held_response(held_delay_model(PLANT, H, TRUE_DELAY), STEP).y  # exact response to the unit step


def _log(amplitude: float, seed: int = 0) -> Experiment:
    """One step of ``amplitude`` at 30 s, altitude with 2 cm of white noise (the plant is linear: the response
    scales with the step)."""
    z = 1.0 + amplitude * RESPONSE + np.random.default_rng(seed).normal(0.0, 0.02, T.size)
    return Experiment.from_arrays(T, {"z": z}, u=amplitude * STEP, name=f"step{amplitude:g}")


@pytest.mark.parametrize("seed", [0, 3])
def test_a_tiny_step_in_noise_leaves_the_delay_not_determined(seed):
    # a step of 2 mm/s: the altitude moves 6 cm in 30 s under 2 cm of noise, no timing is visible
    m = identify(_log(0.002, seed), model="ipdt_lag", baseline="fit")
    assert not m.is_determined("delay")
    assert m.ci["delay"] is None and "delay" in m.undetermined
    assert any(w.startswith("not determined: delay") for w in m.warnings)
    assert "(not determined)" in repr(m)
    d = m.to_dict()
    assert d["ci"]["delay"] is None and d["ci_status"]["delay"] == "not determined"
    assert d["ci_status"]["gain"] == "determined"  # the gain (the ramp's slope) is still shown by the data
    json.dumps(d, allow_nan=False)


def test_the_same_log_with_a_real_step_determines_the_delay_and_its_interval_holds_the_truth():
    # the verdict flips with the step's size alone: 1 m/s instead of 2 mm/s, same noise
    m = identify(_log(1.0), model="ipdt_lag", baseline="fit")
    assert m.is_determined("delay") and not m.undetermined
    lo, hi = m.ci["delay"]
    assert lo <= TRUE_DELAY <= hi and hi - lo < 0.2  # truth: the simulated delay
    assert m.to_dict()["ci_status"] == {"gain": "determined", "lag": "determined", "delay": "determined"}


def test_not_determined_survives_save_and_load(tmp_path):
    m = identify(_log(0.002), model="ipdt_lag", baseline="fit", per_log=False)
    path = tmp_path / "m.json"
    m.save(path)
    back = load_model(path)
    assert back.ci["delay"] is None and not back.is_determined("delay")
    assert back.undetermined == m.undetermined
    assert IdentifiedModel.from_dict(json.loads(path.read_text())).undetermined == m.undetermined


def test_the_rule():
    # the intervals: 0 +- 2558 s ([0, 5013] s) on a 60 s log, and 0.22 +- 4.1 s on a 20 Hz log
    assert "wider than the longest log" in undetermined_reason("delay", "s", 0.0, 2558.0, 60.0, 0.05)
    assert "cannot be told from 0" in undetermined_reason("delay", "s", 0.22, 4.1, 60.0, 0.05)
    # a small delay near its bound with a small error is determined ([0, 0.08] s says something)
    assert undetermined_reason("delay", "s", 0.02, 0.03, 60.0, 0.05) is None
    # singular information: no standard error
    assert "singular" in undetermined_reason("lag", "s", 0.2, math.nan, 60.0, 0.05)
    # a gain: undetermined only when even its sign and size are not known
    assert undetermined_reason("gain", "y/(u s)", 0.9, 0.4, 60.0, 0.05) is None
    assert undetermined_reason("gain", "y/(u s)", 0.9, 1.0, 60.0, 0.05) is not None


def test_cli_prints_not_determined_and_json_null(tmp_path):
    e = _log(0.002)
    path = tmp_path / "tiny.csv"
    np.savetxt(path, np.column_stack([e.t, e.u, e.outputs["z"]]), delimiter=",", header="t,u,z", comments="")
    runner = CliRunner()
    res = runner.invoke(app, ["identify", str(path), "--model", "ipdt_lag", "--baseline", "fit"])
    assert res.exit_code == 0, res.output
    assert "not determined" in res.stdout
    res = runner.invoke(app, ["identify", str(path), "--model", "ipdt_lag", "--baseline", "fit", "--json"])
    assert res.exit_code == 0, res.output

    def refuse(token):
        raise AssertionError(f"not strict JSON: {token}")

    d = json.loads(res.stdout, parse_constant=refuse)
    assert d["ci"]["delay"] is None and d["ci_status"]["delay"] == "not determined"
