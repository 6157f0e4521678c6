"""Closed-loop identification through a PI, PID or any other linear controller (issue #10).

Every synthetic log here comes from the independent reference solver ``tests/oracle_loop.py`` (SciPy's DOP853 by
the method of steps, saturation and clamping located as events; it shares no code with delaykit), never from
delaykit's own simulator: a known plant and delay inside a known loop, the reference held between the log's
samples, small white noise added.  Identification must give back the known values, inside its 95 % intervals and
within a stated absolute tolerance.  The compiled P path is the second, independent reference for one check
(a P loop fitted both ways).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit.cli import app
from delaykit.errors import InvalidValueError
from delaykit.identify import Experiment, IdentificationError, expected_errors, identify, load_model, predict
from delaykit.identify import _closed_general as G
from delaykit.identify._fit import _law, _prepare
from delaykit.models.compensators import Compensator
from delaykit.models.controllers import Controller
from delaykit.models.loop import Loop
from delaykit.models.transfer import TransferFunction
from delaykit.simulate.discrete import closed_loop_response, held_delay_model
from oracle_loop import LoopOracle, LoopSpec

runner = CliRunner()
H = 0.05  # the log's (and the sampled controller's) period, s
T_LOG = np.arange(241) * H  # a 12 s log

# the heater-like loop: FOPDT K / (T s + 1) behind a delay, a sampled PI with clamping, the command in [0, 60] %,
# resting at 20 % (ambient 20 degC, so the output rests at 20 + K 20); a +15 degC step that saturates the command
FOPDT = {"gain": 0.6, "time_constant": 3.0, "delay": 0.43}
PI = Controller.pi(4.0, 1.2, antiwindup="clamp")
PI_LOOP = Loop("1/s", PI, umin=0.0, umax=60.0, period=H)
U0 = 20.0
Y0 = 20.0 + FOPDT["gain"] * U0

# the speed-loop-like case: K / (s (lag s + 1)) behind a delay under a PID (derivative on the measurement)
IPDT_LAG = {"gain": 1.5, "lag": 0.3, "delay": 0.27}
PID = Controller.pid(1.2, 0.3, 0.2, 0.05, antiwindup="clamp")


def _oracle(A, B, C, delay, controller: Controller, *, umin, umax, period, t, r):
    """The oracle's loop in deviations: output and command at the times ``t`` for the reference ``r`` (held
    between the samples ``t``; only its changes are passed, the same signal)."""
    k = np.r_[0, np.flatnonzero(np.diff(r)) + 1]
    c = controller
    spec = LoopSpec(A=A, B=B, C=C, Ti=delay, controller=c.kind, kp=c.kp, ki=c.ki, kd=c.kd, tf=c.derivative_filter,
                    antiwindup=c.antiwindup, umin=umin, umax=umax, period=period,
                    reference=("samples", t[k], r[k], "hold"), t_end=float(t[-1]) + 1e-9)
    o = LoopOracle(spec)
    return o.y(t), o.u(t)


def _fopdt_log(seed, *, step=15.0, noise=0.05, name="heater"):
    K, T, D = FOPDT["gain"], FOPDT["time_constant"], FOPDT["delay"]
    r = np.where(T_LOG >= 1.0, step, 0.0)
    y, u = _oracle([[-1.0 / T]], [K / T], [1.0], D, PI, umin=0.0 - U0, umax=60.0 - U0, period=H, t=T_LOG, r=r)
    y = Y0 + y + np.random.default_rng(seed).normal(0.0, noise, T_LOG.size)
    return Experiment.from_arrays(T_LOG, {"T": y, "u": U0 + u}, r=Y0 + r, name=name), U0 + u


def _ipdt_lag_log(seed, *, period=H, noise=0.005):
    K, lag, D = IPDT_LAG["gain"], IPDT_LAG["lag"], IPDT_LAG["delay"]
    r = np.where(T_LOG >= 1.0, 1.0, 0.0) + np.where(T_LOG >= 7.0, -0.6, 0.0)
    y, u = _oracle([[-1.0 / lag, 0.0], [1.0, 0.0]], [K / lag, 0.0], [0.0, 1.0], D, PID, umin=-2.0, umax=2.0,
                   period=period, t=T_LOG, r=r)
    y = 3.0 + y + np.random.default_rng(seed).normal(0.0, noise, T_LOG.size)
    return Experiment.from_arrays(T_LOG, {"z": y}, r=3.0 + r, name="speed"), u


def _recovered(m, truth, tol):
    for k, v in truth.items():
        lo, hi = m.ci[k]
        assert lo <= v <= hi, (k, m.params[k], m.ci[k])
        assert abs(m.params[k] - v) <= tol[k], (k, m.params[k], v)


# -- fits -----------------------------------------------------------------------------------------------------
def test_fopdt_under_a_sampled_pi_whose_limit_is_hit():
    e, u = _fopdt_log(seed=3)
    assert np.sum(u >= 60.0 - 1e-9) >= 10  # the command sits at its upper limit for a while (clamping acts)
    m = identify(e, model="fopdt", loop=PI_LOOP, u0=U0, outputs="T")
    _recovered(m, FOPDT, {"gain": 0.01, "time_constant": 0.1, "delay": 0.02})
    assert m.logs[0].rms["T"] == pytest.approx(0.05, rel=0.2)  # residuals at the noise level
    # the logged command column gives the same command at rest (its mean before the step is U0)
    m2 = identify(e, model="fopdt", loop=PI_LOOP, command="u")
    assert m2.params == pytest.approx(m.params, rel=1e-9)
    assert m.closed_loop["controller"] == {"kind": "pi", "kp": 4.0, "ki": 1.2, "antiwindup": "clamp"}


@pytest.mark.parametrize("period", [H, None], ids=["sampled", "continuous"])
def test_integrating_plant_with_a_lag_under_a_pid(period):
    # an integrating plant rests at zero command: no u0 needed; the controller sampled at the log's rate, or
    # continuous (the log samples it)
    e, u = _ipdt_lag_log(seed=11, period=period)
    loop = Loop("1/s", PID, umin=-2.0, umax=2.0, period=period)
    m = identify(e, model="ipdt_lag", loop=loop)
    _recovered(m, IPDT_LAG, {"gain": 0.03, "lag": 0.02, "delay": 0.01})


def test_auto_picks_fopdt_under_the_pi():
    e, _ = _fopdt_log(seed=5)
    m = identify(e, model="auto", loop=PI_LOOP, u0=U0, outputs="T")
    assert m.model == "fopdt", [(c.model, c.bic) for c in m.candidates]
    _recovered(m, FOPDT, {"gain": 0.01, "time_constant": 0.1, "delay": 0.02})


def test_auto_picks_ipdt_lag_under_the_pid():
    e, _ = _ipdt_lag_log(seed=12)
    loop = Loop("1/s", PID, umin=-2.0, umax=2.0, period=H)
    m = identify(e, model="auto", loop=loop, u0=0.0)  # the true command at rest, so fopdt and sopdt can compete
    assert m.model == "ipdt_lag", [(c.model, c.bic) for c in m.candidates]
    _recovered(m, IPDT_LAG, {"gain": 0.03, "lag": 0.02, "delay": 0.01})


def test_joint_fit_of_the_output_and_its_rate_under_the_pid():
    # the oracle's output and its rate (y' = C A x + C B w at each sample), noise 0.005 and 0.05
    K, lag, D = IPDT_LAG["gain"], IPDT_LAG["lag"], IPDT_LAG["delay"]
    r = np.where(T_LOG >= 1.0, 1.0, 0.0) + np.where(T_LOG >= 7.0, -0.6, 0.0)
    k = np.r_[0, np.flatnonzero(np.diff(r)) + 1]
    c = PID
    o = LoopOracle(LoopSpec(A=[[-1.0 / lag, 0.0], [1.0, 0.0]], B=[K / lag, 0.0], C=[0.0, 1.0], Ti=D, controller="pid",
                            kp=c.kp, ki=c.ki, kd=c.kd, tf=c.derivative_filter, antiwindup="clamp", umin=-2.0,
                            umax=2.0, period=H, reference=("samples", T_LOG[k], r[k], "hold"),
                            t_end=float(T_LOG[-1]) + 1e-9))
    y, vz = o.y(T_LOG), np.array([o._dy_scalar(t) for t in T_LOG])
    rng = np.random.default_rng(21)
    e = Experiment.from_arrays(T_LOG, {"z": 3.0 + y + rng.normal(0, 0.005, y.size),
                                       "vz": vz + rng.normal(0, 0.05, y.size)}, r=3.0 + r)
    loop = Loop("1/s", PID, umin=-2.0, umax=2.0, period=H)
    m = identify(e, model="ipdt_lag", loop=loop, outputs="z", rate="vz")
    _recovered(m, IPDT_LAG, {"gain": 0.03, "lag": 0.02, "delay": 0.01})
    assert 5 < m.logs[0].rms["vz"] / m.logs[0].rms["z"] < 20  # each output at its own noise level (truth: 10)
    # the free run of the true model reproduces the oracle's noise-free output and rate
    exact = Experiment.from_arrays(T_LOG, {"z": 3.0 + y, "vz": vz}, r=3.0 + r)
    true = m.__class__.from_dict({**m.to_dict(), "params": IPDT_LAG})
    p = predict(true, exact)
    assert p.rms["z"] < 1e-9 and p.rms["vz"] < 1e-8, p.rms


def test_two_logs_share_the_plant_and_leave_one_out_chooses():
    e1, _ = _fopdt_log(seed=3)
    e2, _ = _fopdt_log(seed=8, step=10.0, name="smaller step")
    m = identify([e1, e2], model="fopdt", loop=PI_LOOP, u0=[U0, U0], outputs="T")
    _recovered(m, FOPDT, {"gain": 0.01, "time_constant": 0.1, "delay": 0.02})
    assert [p["file"] for p in m.per_log] == ["heater", "smaller step"]
    auto = identify([e1, e2], model="auto", loop=PI_LOOP, u0=U0, outputs="T",
                    candidates=["ipdt_lag", "fopdt", "sopdt"])
    assert auto.criterion == "leave-one-log-out" and auto.model == "fopdt"


# -- the model the fit uses, against the oracle ------------------------------------------------------------------
@pytest.mark.parametrize("case", ["pi-clamp-sampled", "pid-continuous", "pd-sampled", "tf-continuous"])
def test_free_run_of_the_true_model_equals_the_oracle(case):
    # reference: the oracle's noise-free log; delaykit's free run of the true plant in the same loop must match it
    K, T, D = 0.8, 1.5, 0.33
    r = np.where(T_LOG >= 0.5, 2.0, 0.0) + np.where(T_LOG >= 6.0, -1.0, 0.0)
    lo, hi = 0.0, 3.5
    # the controller, its period, the command at rest given to identify (None: found from the controller) and
    # the oracle's (the PD and the tf controller rest at C(0) (r0 - y0) = 0: the lower limit)
    ctrl, period, given, u0 = {
        "pi-clamp-sampled": (Controller.pi(2.0, 1.0, antiwindup="clamp"), H, 1.0, 1.0),
        "pid-continuous": (Controller.pid(1.5, 0.8, 0.1, 0.05), None, 1.0, 1.0),
        "pd-sampled": (Controller.pd(2.0, 0.2, 0.1), H, None, 0.0),
        "tf-continuous": (Controller.transfer("(2*s + 1)/(0.1*s + 1)"), None, None, 0.0),
    }[case]
    c = ctrl
    if c.kind == "tf":
        A, B, Cc, Dc = c.transfer_function.state_space()
        spec = LoopSpec(A=[[-1.0 / T]], B=[K / T], C=[1.0], Ti=D, controller="tf",
                        ctrl_ss=(A, np.ravel(B), np.ravel(Cc), float(Dc)), umin=lo - u0, umax=hi - u0,
                        period=period, reference=("samples", T_LOG[[0, 10, 120]], r[[0, 10, 120]], "hold"),
                        t_end=float(T_LOG[-1]) + 1e-9)
        yo = LoopOracle(spec).y(T_LOG)
    else:
        yo, _ = _oracle([[-1.0 / T]], [K / T], [1.0], D, ctrl, umin=lo - u0, umax=hi - u0, period=period, t=T_LOG,
                        r=r)
    e = Experiment.from_arrays(T_LOG, {"y": 5.0 + yo}, r=5.0 + r, name=case)
    m = identify(e, model="fopdt", loop=Loop("1/s", ctrl, umin=lo, umax=hi, period=period), u0=given)
    for k, v in {"gain": K, "time_constant": T, "delay": D}.items():  # no noise: the truth itself, to rounding
        assert m.params[k] == pytest.approx(v, rel=1e-7), k
    model = m.__class__.from_dict({**m.to_dict(), "params": {"gain": K, "time_constant": T, "delay": D}})
    p = predict(model, e, u0=given)
    assert p.rms["y"] < 1e-8, p.rms


def test_a_p_loop_fitted_through_the_general_simulator_agrees_with_the_compiled_path():
    # reference: the compiled sample-to-sample P path (an independent simulator: exact held-input matrices)
    h, n = 0.02, 500
    t = np.arange(n) * h
    r = 1.2 + np.where(t >= 2.0, -1.0, 0.0) + np.where(t >= 6.0, 0.6, 0.0)
    res = closed_loop_response(held_delay_model(TransferFunction.parse("0.8/(s*(0.15*s+1))"), h, 0.117),
                               r - 1.2, kp=0.95, umin=-1.0, umax=3.0)
    z = 1.2 + res.y + np.random.default_rng(2).normal(0.0, 0.003, n)
    e = Experiment.from_arrays(t, {"z": z}, r=r)
    loop = Loop("1/s", Controller.p(0.95), umin=-1.0, umax=3.0, period=h)
    fast = identify(e, model="ipdt_lag", loop=loop)
    general = identify(e, model="ipdt_lag", loop=loop, u0=0.0)  # a command at rest sends it the general way
    assert "controller" in general.closed_loop and "controller" not in fast.closed_loop
    for k in fast.params:
        assert general.params[k] == pytest.approx(fast.params[k], rel=1e-5, abs=1e-7), k
        assert general.stderr[k] == pytest.approx(fast.stderr[k], rel=1e-3), k


def test_short_delays_are_interpolated_closely():
    # reference: the exact simulation at that delay (many pieces, so the fit interpolates below T1 = h / 8); a
    # response smooth in the delay (the 3 s lag, 60 periods) is interpolated to 1e-4 of its size or better
    e, _ = _fopdt_log(seed=1, noise=0.0)
    law = _law(PI_LOOP, general=True)
    prep = _prepare(e, ("T",), None, law, False, u0=U0)
    run = G._LogRun(prep, law, 0.0 - U0, 60.0 - U0)
    abc = (np.array([[-1 / 3.0]]), np.array([0.6 / 3.0]), np.array([1.0]))
    for d in (0.1, 0.37, 0.8):
        delay = d * G._SHORT_DELAY * H
        got = G._outputs([run], abc, delay, law, H)[0][0]
        exact = G._exact([run], abc, delay, law)[0][0]
        assert np.max(np.abs(got - exact)) < 1e-4 * np.max(np.abs(exact)), d


# -- prediction and the saved model --------------------------------------------------------------------------
def test_saved_model_rebuilds_the_controller_and_predicts_another_log(tmp_path):
    e, _ = _fopdt_log(seed=7)
    m = identify(e, model="fopdt", loop=PI_LOOP, u0=U0, outputs="T")
    path = tmp_path / "m.json"
    m.save(path)
    back = load_model(path)
    assert back.closed_loop["kind"] == "pi" and back.closed_loop["umax"] == 60.0
    other, _ = _fopdt_log(seed=8, step=10.0, name="other")
    p = predict(back, other, u0=U0)
    assert p.rms["T"] < 0.065  # the noise is 0.05: a correct model predicts to about that
    with pytest.raises(IdentificationError, match="command at rest is unknown"):
        predict(back, other)


# -- bad input ------------------------------------------------------------------------------------------------
def test_planned_errors_of_a_pi_loop_at_rest_off_zero_match_monte_carlo():
    # expected_errors for the heater-like PI loop, whose limits act on the absolute command (resting at U0), against
    # the spread of 20 actual fits of oracle-made logs.  The plan at the true command at rest must match (the fits
    # project out nothing the plan keeps: +-45 % allows for 20 samples' spread, the sd of an sd being 16 %); a plan
    # that put the rest command near the upper limit (saturating longer) predicts errors far off that spread.
    r = np.where(T_LOG >= 1.0, 15.0, 0.0)
    plan = expected_errors("fopdt", FOPDT, T_LOG, r, noise=0.05, loop=PI_LOOP, u0=U0)
    wrong = expected_errors("fopdt", FOPDT, T_LOG, r, noise=0.05, loop=PI_LOOP, u0=50.0)
    fits = {k: [] for k in FOPDT}
    for seed in range(20):
        e, _ = _fopdt_log(seed=500 + seed)
        m = identify(e, model="fopdt", loop=PI_LOOP, u0=U0, outputs="T", per_log=False)
        for k in fits:
            fits[k].append(m.params[k])
    for k in FOPDT:
        sd = float(np.std(fits[k], ddof=1))
        assert 0.7 * plan.stderr[k] < sd < 1.45 * plan.stderr[k], (k, sd, plan.stderr[k])
    sd = float(np.std(fits["delay"], ddof=1))
    assert not 0.7 * wrong.stderr["delay"] < sd < 1.45 * wrong.stderr["delay"], (sd, wrong.stderr["delay"])
    # without u0 the plan cannot place the limits: the error says to give it, and expected_errors now takes it
    with pytest.raises(IdentificationError, match="give it"):
        expected_errors("fopdt", FOPDT, T_LOG, r, noise=0.05, loop=PI_LOOP)
    with pytest.raises(InvalidValueError, match="give the loop too"):
        expected_errors("fopdt", FOPDT, T_LOG, r, noise=0.05, u0=U0)


def test_bad_input_is_refused_with_a_named_reason():
    e, _ = _fopdt_log(seed=4)
    with pytest.raises(IdentificationError, match="must have no delay"):
        identify(e, model="fopdt", loop=PI_LOOP.replace(delay=0.1), u0=U0, outputs="T")
    with pytest.raises(IdentificationError, match=r"period \(0.1 s\) must equal the log's sample period"):
        identify(e, model="fopdt", loop=PI_LOOP.replace(period=0.1), u0=U0, outputs="T")
    with pytest.raises(IdentificationError, match="command at rest is unknown.*give it"):
        identify(e, model="fopdt", loop=PI_LOOP, outputs="T")
    with pytest.raises(IdentificationError, match="fopdt and sopdt plants rest at any command"):
        identify(e, model="auto", loop=PI_LOOP, outputs="T")
    with pytest.raises(IdentificationError, match="u0 = 70 lies outside the loop's limits"):
        identify(e, model="fopdt", loop=PI_LOOP, u0=70.0, outputs="T")
    with pytest.raises(IdentificationError, match="u0 has 2 values for 1 logs"):
        identify(e, model="fopdt", loop=PI_LOOP, u0=[1.0, 2.0], outputs="T")
    with pytest.raises(IdentificationError, match="no command column 'cmd'"):
        identify(e, model="fopdt", loop=PI_LOOP, command="cmd", outputs="T")
    with pytest.raises(IdentificationError, match="give the loop too"):
        identify(e, model="fopdt", u0=U0, outputs="T")
    smith = Compensator.smith("0.6/(3*s+1)", 0.4, closed_loop_time=2.0)
    with pytest.raises(IdentificationError, match="compensator"):
        identify(e, model="fopdt", loop=Loop("1/s", smith, period=H), outputs="T")


# -- the command line -----------------------------------------------------------------------------------------
def _csv(path, e, u):
    rows = ["t,r,T,u"] + [f"{t:.6f},{r:.9g},{y:.9g},{c:.9g}" for t, r, y, c in zip(e.t, e.r, e.outputs["T"], u)]
    path.write_text("\n".join(rows) + "\n")


def test_cli_identify_and_predict_with_a_pi_loop(tmp_path):
    e, u = _fopdt_log(seed=3)
    log = tmp_path / "heater.csv"
    _csv(log, e, u)
    model = tmp_path / "m.json"
    base = ["identify", str(log), "--closed-loop", "--controller", "pi", "--kp", "4", "--ki", "1.2", "--antiwindup",
            "clamp", "--umin", "0", "--umax", "60", "--period", str(H), "--reference", "r", "--output", "T",
            "--model", "fopdt"]
    r = runner.invoke(app, base + ["--u0", "20", "--save", str(model), "--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    for k, v in FOPDT.items():
        assert d["ci"][k][0] <= v <= d["ci"][k][1], (k, d["params"][k])
    assert d["closed_loop"]["controller"]["kind"] == "pi"
    r = runner.invoke(app, base + ["--command", "u", "--json"])  # the command column instead of --u0
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["params"] == pytest.approx(d["params"], rel=1e-9)
    r = runner.invoke(app, ["predict", str(model), str(log), "--u0", "20", "--json"])
    assert r.exit_code == 0, r.output
    assert json.loads(r.stdout)["rms"] < 0.065
    r = runner.invoke(app, base)  # no command at rest: a clear refusal, exit status 2
    assert r.exit_code == 2 and "command at rest is unknown" in r.output and "Traceback" not in r.output
    r = runner.invoke(app, base[:-2] + ["--model", "fopdt", "--delay", "0.2"])  # not an option of identify
    assert r.exit_code == 2 and "No such option" in r.output
