"""Logs with an irregular clock: identified on their own clock, or put on a uniform clock (``resample=``) first.

The truth is a closed form: a first-order plant with dead time, ``y = K (1 - exp(-(t - t_u - L) / T))`` after
the logged input step at ``t_u``, evaluated at each irregular sample time (no simulator involved).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit.cli import app
from delaykit.errors import InvalidValueError
from delaykit.identify import Experiment, LogError, identify, read_experiment

K, T, L = 0.8, 3.0, 0.7


def _jittered_log(seed: int = 3, noise: float = 0.002) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.cumsum(np.r_[0.0, rng.uniform(0.07, 0.13, 299)])  # a 0.1 s logger that writes when it can (+-30 %)
    t_u = float(t[t >= 2.0][0])  # the command steps at a logged sample (it is logged when it is sent)
    u = np.where(t >= t_u, 1.0, 0.0)
    age = np.clip(t - t_u - L, 0.0, None)
    y = K * (1.0 - np.exp(-age / T)) + rng.normal(0.0, noise, t.size)
    return t, u, y


def test_an_irregular_clock_is_taken_as_it_is_and_identified_on_it():
    # the fit simulates at the samples' own times: no grid error, so the truth is within the stated errors alone
    t, u, y = _jittered_log()
    e = Experiment.from_arrays(t, {"y": y}, u=u)
    assert not e.uniform and e.resampled_from is None and np.array_equal(e.t, t)
    assert "irregular clock" in repr(e)
    m = identify(e, model="fopdt")
    assert abs(m.params["gain"] - K) < 4 * m.stderr["gain"]
    assert abs(m.params["time_constant"] - T) < 4 * m.stderr["time_constant"]
    assert abs(m.params["delay"] - L) < 4 * m.stderr["delay"]


def test_resampling_holds_the_drive_and_interpolates_the_outputs():
    t, u, y = _jittered_log(noise=0.0)
    e = Experiment.from_arrays(t, {"y": y}, u=u, resample=0.01)
    assert e.resampled_from == t.size and math.isclose(e.period, 0.01)
    assert np.allclose(np.diff(e.t), 0.01, rtol=0, atol=1e-12)
    # the held input is the last logged value at or before each grid time (the command holds until the next)
    last = np.searchsorted(t, e.t, side="right") - 1
    assert np.array_equal(e.u, u[last])
    # the interpolated output is within dt^2 max|y''| / 8 of the closed form (max|y''| = K / T^2 after the dead
    # time), plus, across the kink at t_u + L (the slope jumps by K / T), at most dt * K / T / 4
    t_u = float(t[u > 0][0])
    exact = K * (1.0 - np.exp(-np.clip(e.t - t_u - L, 0.0, None) / T))
    dt = float(np.max(np.diff(t)))
    assert np.max(np.abs(e.outputs["y"] - exact)) <= dt * K / T / 4 + dt**2 * K / T**2 / 8
    assert "resampled from 300" in repr(e)


def test_a_resampled_jittered_log_identifies_the_plant():
    # the dead time comes out within the new grid's period (plus its own error): the switch of the held input
    # moves to the next grid point, at most 0.01 s late
    t, u, y = _jittered_log()
    e = Experiment.from_arrays(t, {"y": y}, u=u, resample=0.01)
    m = identify(e, model="fopdt")
    assert abs(m.params["gain"] - K) < 4 * m.stderr["gain"] + 1e-3
    assert abs(m.params["time_constant"] - T) < 4 * m.stderr["time_constant"] + 0.01
    assert abs(m.params["delay"] - L) < 4 * m.stderr["delay"] + 0.01


def test_bad_resample_periods_are_refused():
    t, u, y = _jittered_log()
    for bad in (0.0, -0.1, float("nan")):
        with pytest.raises(InvalidValueError, match="resample"):
            Experiment.from_arrays(t, {"y": y}, u=u, resample=bad)
    with pytest.raises(InvalidValueError, match="leaves 8 samples"):
        Experiment.from_arrays(t, {"y": y}, u=u, resample=float(t[-1] - t[0]) / 7.5)


def test_cli_identify_resample(tmp_path):
    t, u, y = _jittered_log()
    p = tmp_path / "jittery.csv"
    p.write_text("t,u,y\n" + "".join(f"{a:.6f},{b:g},{c:.6f}\n" for a, b, c in zip(t, u, y)))
    runner = CliRunner()
    res = runner.invoke(app, ["identify", str(p), "--input", "u", "--output", "y", "--model", "fopdt", "--json"])
    assert res.exit_code == 0, res.output  # the log's own clock
    res = runner.invoke(app, ["identify", str(p), "--input", "u", "--output", "y", "--model", "fopdt",
                              "--resample", "0.01", "--json"])
    assert res.exit_code == 0, res.output
    import json

    got = json.loads(res.stdout)
    assert abs(got["params"]["delay"] - L) < 4 * got["stderr"]["delay"] + 0.01
    with pytest.raises(LogError, match="resample"):
        read_experiment(p, outputs=["y"], input="u", resample=-1.0)
