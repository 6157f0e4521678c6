"""Where a load step enters: at the plant's input after the input delay (``at="plant"``) or on the command before it
(``at="command"``).

Reference: the same loop built by the algebra of delay systems and simulated by the other kernel (the DelayLTI
Taylor kernel, which shares no code with the Loop kernel): from the load to the output, a load after the delay is
``G / (1 + C G e^{-tau s})`` and a load before it ``G e^{-tau s} / (1 + C G e^{-tau s})``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit import Controller, InvalidValueError, LoadStep, Loop, delay, feedback, simulate, step_response, tf
from delaykit.cli import app

TAU, T0, SIZE = 0.4, 1.0, 0.5


def _loop_response(at):
    loop = Loop("1/(s*(0.5*s+1))", Controller.pi(1.2, 0.4), delay=TAU)
    r = simulate(loop, step=0.0, disturbance=LoadStep(SIZE, T0, at=at), t_end=12.0)
    t = np.linspace(0.0, 12.0, 241)
    return t, np.array([r.altitude(x) for x in t])


@pytest.mark.parametrize("at", ["plant", "command"])
def test_a_load_before_or_after_the_delay_is_the_algebras(at):
    G = tf("1/(s*(0.5*s+1))")
    C = tf(([1.2, 0.4], [1.0, 0.0]))  # PI: kp + ki/s
    d = delay(TAU)
    T_dy = feedback(G, C * d) if at == "plant" else feedback(G * d, C)
    t, y = _loop_response(at)
    ref = SIZE * np.interp(t - T0, *_step(T_dy), left=0.0)
    assert np.abs(y - ref).max() < 1e-9


def _step(sys):
    tt = np.linspace(0.0, 12.0, 24001)
    return tt, step_response(sys, tt).outputs[0, 0]


def test_command_placement_is_the_plant_placement_one_delay_later():
    t, y_cmd = _loop_response("command")
    loop = Loop("1/(s*(0.5*s+1))", Controller.pi(1.2, 0.4), delay=TAU)
    r = simulate(loop, step=0.0, disturbance=LoadStep(SIZE, T0 + TAU), t_end=12.0)
    assert np.abs(y_cmd - np.array([r.altitude(x) for x in t])).max() < 1e-12
    assert LoadStep(SIZE, T0, at="command").to_dict()["at"] == "command"


def test_a_bad_placement_is_refused():
    with pytest.raises(InvalidValueError, match="'inside'"):
        LoadStep(1.0, at="inside")
    res = CliRunner().invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.368", "--disturbance-at", "command"])
    assert res.exit_code == 2 and "--disturbance" in res.output


def test_the_command_line_places_the_load(tmp_path):
    def run(at, time, name):
        path = tmp_path / name
        res = CliRunner().invoke(app, ["simulate", "--plant", "1/s", "--kp", "1.31", "--delay", "0.368",
                                       "--disturbance", "0.2", "--disturbance-time", str(time),
                                       "--disturbance-at", at, "--csv", str(path)])
        assert res.exit_code == 0, res.output
        return np.genfromtxt(path, delimiter=",", names=True)

    a = run("command", 3.0, "a.csv")
    b = run("plant", 3.368, "b.csv")  # the same load at the plant, one delay later
    assert np.abs(a["z"] - b["z"]).max() < 1e-12
    c = run("plant", 3.0, "c.csv")
    assert np.abs(a["z"] - c["z"]).max() > 1e-3  # and it is not the load at the plant at the same time
