"""Delay compensators (issue 11): exact simulation with two delays, robustness, design, command line.

References: the independent DOP853 solver of tests/oracle_predictor.py (two model copies, no delaykit code);
closed forms of the nominal loops (the Smith predictor's set-point response is the delay-free loop's, delayed);
the final value theorem for load disturbances; scipy's root finder on the characteristic equation for the
stability boundary.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import fsolve
from typer.testing import CliRunner

sys.path.insert(0, str(Path(__file__).parent))
from oracle_predictor import PredictorOracle  # noqa: E402

from delaykit import simulate  # noqa: E402
from delaykit.cli.app import app  # noqa: E402
from delaykit.design.compensators import (delay_ratio_range, design_compensator, disturbance_recovery,  # noqa: E402
                                          minimum_settling_time, robustness_map, tune_compensator)
from delaykit.errors import InvalidTypeError, InvalidValueError  # noqa: E402
from delaykit.models.compensators import Compensator  # noqa: E402
from delaykit.models.controllers import Controller  # noqa: E402
from delaykit.models.loop import Loop  # noqa: E402
from delaykit.spectrum.stability import rightmost  # noqa: E402

T = np.linspace(0.0, 5.0, 401)
INT = ([1.0], [1.0, 0.0])


def _oracle(c: Compensator, td: float, step: float, lo: float, hi: float, plant=INT) -> PredictorOracle:
    kw: dict = {}
    if c.kind == "smith":
        kw = dict(kc=c.primary.kp, ki_primary=c.primary.ki)
    elif c.kind == "filtered-smith":
        kw = dict(kc=c.primary.kp, ki_primary=c.primary.ki, fr=(c.robustness_filter.num, c.robustness_filter.den))
    else:
        kw = dict(kp=c.kp, ki=c.ki, b=c.setpoint_weight, tt=c.closed_loop_time)
    model = (c.model.num, c.model.den)
    return PredictorOracle(c.kind, plant, model, td, c.model_delay, umin=lo, umax=hi, step=step, t_end=5.0, **kw)


@pytest.mark.parametrize("c, td, step, lim", [
    (Compensator.smith("1/s", 0.37, closed_loop_time=0.1), 0.42, 1.0, 1.0),       # delay too long, saturated
    (Compensator.smith("1/s", 0.37, closed_loop_time=0.1), 0.31, 0.2, 1.0),       # delay too short
    (Compensator.filtered_smith("1/s", 0.37, closed_loop_time=0.1), 0.33, 1.0, 1.0),
    (Compensator.predictor("1/s", 0.37, closed_loop_time=0.15), 0.40, 0.2, 1.0),
    (Compensator.predictor("1/s", 0.37, closed_loop_time=0.15), 0.37, 1.0, 2.0),
])
def test_two_delays_match_the_oracle(c, td, step, lim):
    # the oracle integrates two copies of the model (u and u(t - Tm)) with DOP853 at rtol 1e-12
    o = _oracle(c, td, step, -lim, lim)
    r = simulate(Loop("1/s", c, delay=td, umin=-lim, umax=lim), step=step, t_end=5.0)
    assert np.max(np.abs(o.y(T) - r.altitude(T))) < 1e-8


def test_smith_pi_on_a_stable_plant_matches_the_oracle():
    c = Compensator.smith("2/(3*s+1)", 0.5, closed_loop_time=0.4)          # PI primary by the default rule
    plant = ([2.4], [3.0, 1.0])                                            # the true gain is 20 % higher
    o = _oracle(c, 0.55, 1.0, -1.0, 1.0, plant=plant)
    r = simulate(Loop("2.4/(3*s+1)", c, delay=0.55, umin=-1, umax=1), step=1.0, t_end=5.0)
    assert np.max(np.abs(o.y(T) - r.altitude(T))) < 1e-8


@pytest.mark.parametrize("kind", ["smith", "filtered-smith", "predictor"])
def test_nominal_set_point_response_is_the_delay_free_one(kind):
    # closed form: y = 1 - exp(-(t - Tm) / Tc) after the delay, for each law's design rule (no saturation)
    c = Compensator.design(kind, "1/s", 0.37, closed_loop_time=0.15)
    r = simulate(Loop("1/s", c, delay=0.37), step=1.0, t_end=5.0)
    exact = np.where(T > 0.37, 1.0 - np.exp(-(T - 0.37) / 0.15), 0.0)
    assert np.max(np.abs(r.altitude(T) - exact)) < 1e-12


def test_smith_with_pi_on_fopdt_is_first_order():
    c = Compensator.smith("0.62/(150*s+1)", 12.0, closed_loop_time=40.0)
    t = np.linspace(0, 200, 401)
    r = simulate(Loop("0.62/(150*s+1)", c, delay=12.0), step=1.0, t_end=200.0)
    exact = np.where(t > 12, 1.0 - np.exp(-(t - 12.0) / 40.0), 0.0)
    assert np.max(np.abs(r.altitude(t) - exact)) < 1e-10


def test_predictor_without_integral_is_the_smith_predictor():
    # for K/s, predictor feedback u = Kc (r - y - K int_{t-T}^t u) is the Smith predictor with P control
    a = simulate(Loop("1/s", Compensator.predictor("1/s", 0.37, closed_loop_time=0.1, integral_time=math.inf),
                      delay=0.45, umin=-1, umax=1), step=1.0, t_end=5.0)
    b = simulate(Loop("1/s", Compensator.smith("1/s", 0.37, closed_loop_time=0.1), delay=0.45, umin=-1, umax=1),
                 step=1.0, t_end=5.0)
    assert np.max(np.abs(a.altitude(T) - b.altitude(T))) < 1e-12


def test_load_disturbance_steady_errors():
    # final value theorem: the Smith predictor with P control on K/s leaves d (1/Kc + K Tm); the filtered Smith
    # predictor (beta chosen for it) and predictor feedback (integral action) leave none
    d = 0.2
    smith = Compensator.smith("1/s", 0.37, closed_loop_time=0.1)
    assert disturbance_recovery(Loop("1/s", smith, delay=0.37), d, t_end=20).final_error == pytest.approx(
        d * (1.0 / smith.primary.kp + 0.37), rel=1e-9)
    for c in (Compensator.filtered_smith("1/s", 0.37, closed_loop_time=0.1),
              Compensator.predictor("1/s", 0.37, closed_loop_time=0.15)):
        rec = disturbance_recovery(Loop("1/s", c, delay=0.37), d, t_end=30)
        assert abs(rec.final_error) < 1e-6 * rec.peak
        assert rec.recovery_time is not None


def test_nominal_characteristic_has_no_delay_left():
    # Smith's point: with a perfect model the delay leaves the characteristic equation, s + Kc K = 0
    q = Loop("1/s", Compensator.smith("1/s", 0.37, closed_loop_time=0.1), delay=0.37).characteristic()
    assert q.delays == (0.0,)
    assert rightmost(q).root == pytest.approx(-10.0)


def test_delay_ratio_range_ends_on_the_imaginary_axis():
    c = Compensator.smith("1/s", 0.37, closed_loop_time=0.0925)
    lo, hi = delay_ratio_range(c)
    assert lo < 0.85 and hi > 1.15
    # independent: solve Q(jw; rho) = 0 for (w, rho) with scipy from the rightmost root near the upper end
    kc, tm = c.primary.kp, 0.37

    def eq(x):
        w, rho = x
        s = 1j * w
        v = s + kc * (1 - np.exp(-s * tm)) + kc * np.exp(-s * rho * tm)
        return [v.real, v.imag]

    w0 = rightmost(Loop("1/s", c, delay=hi * tm).characteristic()).root.imag
    w, rho = fsolve(eq, [w0, hi], xtol=1e-13)
    assert rho == pytest.approx(hi, abs=2e-4)
    # and the verdict flips across it
    assert rightmost(Loop("1/s", c, delay=(hi - 0.01) * tm).characteristic()).stable
    assert not rightmost(Loop("1/s", c, delay=(hi + 0.01) * tm).characteristic()).stable


def test_design_meets_the_issue_targets():
    # against the best PV design (Kp 2, Kv 0.3: 1.55 s for 0.2 m, 1.63 s for 1 m), simulated here too
    pv = Loop("1/s", Controller.pv(2.0, 0.3), delay=0.37, umin=-1, umax=1)
    pv02 = simulate(pv, step=0.2).metrics.settling_time
    assert pv02 == pytest.approx(1.55, abs=0.01)
    for kind in ("smith", "filtered-smith"):
        d = design_compensator(kind, "1/s", 0.37, umin=-1, umax=1)
        assert d.steps[0.2].settling_time <= 0.75 * pv02
        assert d.steps[1.0].settling_time <= 1.5
        assert d.steps[1.0].settling_time >= d.bounds[1.0] - 1e-9    # nobody beats physics
        assert d.delay_ratio_range[0] <= 0.85 and d.delay_ratio_range[1] >= 1.15
    assert minimum_settling_time(0.37, 1.0, 1.0) == pytest.approx(0.37 + 0.98)


def test_robustness_map_agrees_with_the_range():
    c = tune_compensator("smith", "1/s", 0.37)
    lo, hi = delay_ratio_range(c)
    m = robustness_map(c, [lo - 0.02, 1.0, hi + 0.02], [1.0])
    assert m.stable.ravel().tolist() == [False, True, False]
    assert "3 delay ratios" in repr(m)


def test_bad_input():
    with pytest.raises(InvalidValueError, match="supports the integrator"):
        Compensator.predictor("1/(s+1)", 0.3)
    with pytest.raises(InvalidValueError, match="model_delay"):
        Compensator.smith("1/s", -0.1)
    with pytest.raises(InvalidValueError, match="filtered Smith predictor supports"):
        Compensator.filtered_smith("1/(s*(s+1))", 0.3)
    with pytest.raises(InvalidValueError, match="stable model or one integrator"):
        Compensator.smith("1/(s-1)", 0.3, primary=Controller.p(1.0))
    with pytest.raises(InvalidValueError, match="compensator must be one of"):
        design_compensator("otto", "1/s", 0.3)
    with pytest.raises(InvalidTypeError):
        delay_ratio_range(Controller.p(1.0))  # type: ignore[arg-type]
    with pytest.raises(InvalidValueError, match="two delays"):
        Loop("1/s", Compensator.smith("1/s", 0.3), delay=0.3).open_loop()


def cli(*args):
    return CliRunner().invoke(app, list(args))


def test_cli_design_and_simulate():
    res = cli("design", "--compensator", "smith", "--plant", "1/s", "--delay", "0.37", "--umin", "-1", "--umax", "1",
              "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["compensator"] == "smith" and set(d["steps"]) == {"0.2", "1.0"}
    assert set(d["steps"]["1.0"]) >= {"overshoot", "peak_time", "rise_time", "settling_time"}
    lo, hi = d["delay_ratio_range"]
    assert lo <= 0.85 and hi >= 1.15
    res = cli("simulate", "--plant", "1/s", "--delay", "0.42", "--controller", "smith", "--model-delay", "0.37",
              "--umin", "-1", "--umax", "1", "--step", "1", "--json")
    assert res.exit_code == 0, res.output
    s = json.loads(res.stdout)
    # the same design simulated in the library against the true delay
    c = tune_compensator("smith", "1/s", 0.37)
    ref = simulate(Loop("1/s", c, delay=0.42, umin=-1, umax=1), step=1.0).metrics
    assert s["settling_time"] == pytest.approx(ref.settling_time, rel=1e-12)
    res = cli("simulate", "--controller", "predictor", "--plant", "1/(s+1)", "--delay", "0.3")
    assert res.exit_code == 2 and "supports the integrator" in res.output
    res = cli("simulate", "--controller", "pi", "--kp", "1", "--ki", "0.1", "--model-delay", "0.3", "--delay", "0.3")
    assert res.exit_code == 2 and "--model-delay" in res.output


def app_cli():
    from delaykit.cli import app

    return app
