"""The acceleration-limited structure ``ipdt_accel`` (issue 31): its exact simulation and its fit.

References: the linear exact held-input simulator (``held_response``) where the limit is never reached, and a
brute-force simulation on a grid 500 times finer than the log (the limiter stepped at its slope, the lag and the
integrator by their exact one-step maps) where it is.
"""

from __future__ import annotations

import numpy as np
import pytest

from delaykit.errors import InvalidValueError
from delaykit.identify._accel import simulate_accel
from delaykit.identify.identification import IdentificationError, identify, load_model, predict
from delaykit.identify.iodata import Experiment
from delaykit.identify.structures import STRUCTURES
from delaykit.models.controllers import Controller
from delaykit.models.loop import Loop
from delaykit.models.transfer import TransferFunction
from delaykit.simulate.discrete import held_delay_model, held_response

H = 0.05


def _random_command(seconds: float, seed: int, hold: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """A held random speed command (a new value every ``hold`` samples), at rest for the first 2 s."""
    t = np.arange(0.0, seconds, H)
    u = np.repeat(np.random.default_rng(seed).uniform(-1.0, 1.0, t.size // hold + 1), hold)[:t.size]
    u[:40] = 0.0
    return t, u


def _brute(t, u, gain, accel, lag, delay, fine=1e-4):
    """Independent reference: the delayed held command on a fine grid, the limiter stepped by at most
    ``accel * fine``, the lag and the integrator by their exact maps over each fine step (first-order error in
    ``fine``)."""
    tf = np.arange(0.0, t[-1] + 0.5 * fine, fine)
    k = np.floor((tf - delay) / H + 1e-9).astype(int)
    ud = np.where(k >= 0, u[np.clip(k, 0, u.size - 1)], 0.0)
    e = np.exp(-fine / lag)
    w = v = y = 0.0
    ys, every = [], int(round(H / fine))
    for i in range(tf.size):
        if i % every == 0:
            ys.append(y)
        y += gain * (w * fine + (v - w) * lag * (1.0 - e))
        v = w + (v - w) * e
        w += min(max(ud[i] - w, -accel * fine), accel * fine)
    return np.array(ys)


def test_without_reaching_the_limit_it_is_the_linear_ipdt_lag():
    t, u = _random_command(20.0, 0)
    ref = held_response(held_delay_model(TransferFunction.parse("0.9/(s*(0.2*s+1))"), H, 0.237), u)
    y, v = simulate_accel(t, u, 0.9, 1e9, 0.2, 0.237)  # a limit no ramp reaches (1e-9 s per unit)
    assert np.max(np.abs(y - ref.y)) < 1e-7 and np.max(np.abs(v - ref.dy)) < 1e-7
    ref0 = held_response(held_delay_model(TransferFunction.parse("0.9/s"), H, 0.237), u)
    assert np.max(np.abs(simulate_accel(t, u, 0.9, 1e9, 0.0, 0.237)[0] - ref0.y)) < 1e-7  # no lag: ipdt


def test_the_ramps_match_a_fine_brute_force_simulation():
    t, u = _random_command(10.0, 1)
    y, _ = simulate_accel(t, u, 0.9, 1.0, 0.2, 0.237)
    ref = _brute(t, u, 0.9, 1.0, 0.2, 0.237)
    # the ramps change the response by far more than the reference's own step error (~ accel * fine * t)
    assert np.max(np.abs(y - simulate_accel(t, u, 0.9, 1e9, 0.2, 0.237)[0])) > 0.1
    assert np.max(np.abs(y - ref)) < 2e-4


def _accel_log(seed: int, *, accel: float = 1.0, noise: float = 0.01) -> Experiment:
    t, u = _random_command(60.0, seed)
    y, v = simulate_accel(t, u, 1.0, accel, 0.15, 0.25)  # checked against the references above
    rng = np.random.default_rng(100 + seed)
    return Experiment.from_arrays(t, {"z": 1.0 + y + rng.normal(0, noise, t.size),
                                      "vz": v + rng.normal(0, 3 * noise, t.size)}, u=u, name=f"accel{seed}")


def test_fit_recovers_the_limit_the_lag_and_the_delay():
    m = identify(_accel_log(0), model="ipdt_accel", outputs="z", rate="vz", baseline="fit")
    truth = {"gain": 1.0, "accel": 1.0, "lag": 0.15, "delay": 0.25}
    for k, v in truth.items():
        lo, hi = m.ci[k]
        assert lo <= v <= hi, (k, m.params[k], m.ci[k])
    assert abs(m.delay - 0.25) < 0.01


def test_auto_chooses_the_limit_only_where_the_data_have_one():
    m = identify(_accel_log(1), model="auto", outputs="z", rate="vz", baseline="fit",
                 candidates=["ipdt", "ipdt_lag", "ipdt_accel"])
    assert m.model == "ipdt_accel"
    # the same command through the linear ipdt_lag (no limit): the limit is not chosen
    e = _accel_log(1)
    ref = held_response(held_delay_model(TransferFunction.parse("1/(s*(0.15*s+1))"), H, 0.25), e.u)
    rng = np.random.default_rng(7)
    lin = Experiment.from_arrays(e.t, {"z": 1.0 + ref.y + rng.normal(0, 0.01, e.t.size),
                                       "vz": ref.dy + rng.normal(0, 0.03, e.t.size)}, u=e.u)
    m = identify(lin, model="auto", outputs="z", rate="vz", baseline="fit",
                 candidates=["ipdt", "ipdt_lag", "ipdt_accel"])
    assert m.model == "ipdt_lag"
    # fitted alone, the limit runs off to where no ramp shows: reported as not determined, not as a value
    m = identify(lin, model="ipdt_accel", outputs="z", rate="vz", baseline="fit")
    assert not m.is_determined("accel") and m.ci["accel"] is None
    assert m.ci["delay"][0] <= 0.25 <= m.ci["delay"][1]


def test_saved_model_predicts_another_log(tmp_path):
    m = identify(_accel_log(2), model="ipdt_accel", outputs="z", baseline="fit", per_log=False)
    m.save(tmp_path / "m.json")
    back = load_model(tmp_path / "m.json")
    assert back.model == "ipdt_accel" and back.structure.limited
    p = predict(back, _accel_log(3))
    assert p.rms["z"] < 0.05  # a 1 cm noise; a linear model misses the ramps by decimetres


def test_closed_loop_is_refused_and_auto_leaves_it_out():
    t = np.arange(0.0, 10.0, H)
    e = Experiment.from_arrays(t, {"z": np.where(t > 3, 0.1 * (t - 3), 0.0)}, r=np.where(t >= 2, 1.0, 0.0))
    loop = Loop("1/s", Controller.p(1.0), period=H)
    with pytest.raises(IdentificationError, match="open loop only"):
        identify(e, model="ipdt_accel", loop=loop, outputs="z")
    assert STRUCTURES["ipdt_accel"].limited and not STRUCTURES["ipdt_lag"].limited


def test_a_known_limit_is_held_not_fitted():
    e = _accel_log(0)
    m = identify(e, model="ipdt_accel", outputs="z", rate="vz", baseline="fit", per_log=False, accel_limit=1.0)
    assert m.params["accel"] == 1.0 and m.stderr["accel"] == 0.0
    assert any("accel is held at the value given" in w for w in m.warnings)
    free = identify(e, model="ipdt_accel", outputs="z", rate="vz", baseline="fit", per_log=False)
    for k in ("gain", "lag", "delay"):  # the truth (the simulated values) inside the intervals; errors no larger
        lo, hi = m.ci[k]
        assert lo <= {"gain": 1.0, "lag": 0.15, "delay": 0.25}[k] <= hi, (k, m.ci[k])
        assert m.stderr[k] <= free.stderr[k] * 1.05
    # a wrong limit is a worse fit
    wrong = identify(e, model="ipdt_accel", outputs="z", rate="vz", baseline="fit", per_log=False, accel_limit=3.0)
    assert wrong.rms > 2 * m.rms
    with pytest.raises(IdentificationError, match="accel_limit"):
        identify(e, model="ipdt_lag", outputs="z", accel_limit=1.0)
    with pytest.raises(InvalidValueError, match="accel_limit must be greater than 0, got -1"):
        identify(e, model="ipdt_accel", outputs="z", accel_limit=-1.0)


def test_cli_fits_the_limit_or_holds_a_given_one(tmp_path):
    import json

    from typer.testing import CliRunner

    from delaykit.cli import app

    e = _accel_log(0)
    path = tmp_path / "flight.csv"
    np.savetxt(path, np.column_stack([e.t, e.u, e.outputs["z"], e.outputs["vz"]]), delimiter=",",
               header="t,u,z,vz", comments="")
    runner = CliRunner()
    args = ["identify", str(path), "--rate", "vz", "--model", "ipdt_accel", "--baseline", "fit", "--json"]
    res = runner.invoke(app, args + ["--accel-limit", "1.0"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["model"] == "ipdt_accel" and d["params"]["accel"] == 1.0 and d["ci_status"]["delay"] == "determined"
    res = runner.invoke(app, ["identify", str(path), "--model", "ipdt_lag", "--accel-limit", "1.0"])
    assert res.exit_code == 2 and "accel_limit" in res.output and "Traceback" not in res.output


def test_cli_candidates_choose_what_auto_tries(tmp_path):
    import json

    from typer.testing import CliRunner

    from delaykit.cli import app

    e = _accel_log(0)
    path = tmp_path / "flight.csv"
    np.savetxt(path, np.column_stack([e.t, e.u, e.outputs["z"]]), delimiter=",", header="t,u,z", comments="")
    runner = CliRunner()
    res = runner.invoke(app, ["identify", str(path), "--candidates", "ipdt, ipdt_lag", "--json"])
    assert res.exit_code == 0, res.output
    assert [c["model"] for c in json.loads(res.stdout)["candidates"]] == ["ipdt", "ipdt_lag"]
    res = runner.invoke(app, ["identify", str(path), "--candidates", "ipdt,nope"])
    assert res.exit_code == 2 and "nope" in res.output and "Traceback" not in res.output
