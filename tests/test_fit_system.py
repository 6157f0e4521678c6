"""Fitting a delay system's parameters to logs (delaykit.identify.fit_system) and the PX4 vehicle as a named
interconnection of its loops.

Reference values: the known truth of synthetic logs (made by the same interconnection, with noise added); the
Loop kernel (``delaykit.simulate``), an independent simulator of the same loop written as plant and controller;
closed forms for the small examples; the real flights' own hover wander (their noise floor, data README).

The real flights are read from ../shared/data (tests/shared_data.py; the tests on them skip, saying why, where it is
absent), cut at 30 s: examples/px4-vehicle.toml holds the fit of their 10-30 s part (the step at 15 s and the 15 s
after it), and the bounds below (multiples of the hover wander) were set on that part.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from delaykit import Controller, Loop, delay, interconnect, saturation, simulate, summing_junction, tf
from delaykit.errors import InvalidTypeError, InvalidValueError
from delaykit.identify import Experiment, IdentificationError, fit_system, identify, simulate_log
from shared_data import px4_flights

TRAIN = ["HAYDEN_01", "HAYDEN_02", "HAYDEN_03"]
HELD_OUT = ["SANCHEZ_01", "SANCHEZ_02", "SANCHEZ_03"]
BOUNDS = {"k": (1e-3, 50.0), "tau": (0.0, 1.0)}


def px4(k: float, tau: float, kappa: float):
    """The vehicle as its loops (data README): the altitude P loop (0.95, speed command limited to -1/+3 m/s),
    the dead time, the PI speed loop (P 4, I 2) around the thrust-to-acceleration gain k and the ground effect's
    stiffness kappa, the altitude integrator."""
    blocks = [summing_junction(["z_ref", "-z"], "e"),
              tf(0.95, inputs="e", outputs="u_c"),
              saturation(-1.0, 3.0, inputs="u_c", outputs="u"),
              delay(tau, inputs="u", outputs="v_ref"),
              summing_junction(["v_ref", "-vz"], "e_v"),
              tf("4 + 2/s", inputs="e_v", outputs="c"),
              tf(k, inputs="c", outputs="f"),
              tf(kappa, inputs="z", outputs="g"),
              summing_junction(["f", "-g"], "a"),
              tf("1/s", inputs="a", outputs="vz"),
              tf("1/s", inputs="vz", outputs="z")]
    return interconnect(blocks, inputs=["z_ref"], outputs=["z", "vz"], name="PX4")


def _flights(names, outputs=("z", "vz")):
    return px4_flights(names, outputs=outputs, reference="z_ref")  # t = 10 to 30 s of each (module docstring)


def _synthetic(truth, seed, sigma=(0.004, 0.008), phi=0.8):
    """A 50 Hz log of a 1 m step down at 3 s made by the interconnection itself, z with AR(1) noise (phi 0.8), vz
    with white noise."""
    t = np.round(np.arange(0.0, 15.0, 0.02), 10)
    r = np.where(t >= 3.0, -1.0, 0.0)
    rest = Experiment.from_arrays(t, {"z": np.zeros_like(t), "vz": np.zeros_like(t)}, r=r)
    clean = simulate_log(px4(**truth), rest)
    rng = np.random.default_rng(seed)
    e = rng.standard_normal(t.size) * sigma[0] * math.sqrt(1 - phi**2)
    ar = np.zeros_like(t)
    for i in range(1, t.size):
        ar[i] = phi * ar[i - 1] + e[i]
    noisy = {"z": clean["z"] + ar, "vz": clean["vz"] + sigma[1] * rng.standard_normal(t.size)}
    return Experiment.from_arrays(t, noisy, r=r, name=f"synthetic {seed}")


TRUTH = {"k": 1.4, "tau": 0.08, "kappa": 0.6}
START = {"k": 1.0, "tau": 0.03, "kappa": 0.2}


# -- the interconnection against the Loop kernel ---------------------------------------------------------------
@pytest.mark.parametrize("step", [-1.0, -2.0, 4.0])
def test_interconnection_equals_the_loop_simulation(step):
    # With the speed loop folded into the plant, z/v_ref = k (4 s + 2) / (s (s^2 + 4 k s + kappa + 2 k)) (by hand
    # from the blocks), the vehicle is a Loop: P control, the limits, an input delay.  -2 and +4 m drive the
    # command into its limits (-1 and +3 m/s); -1 m (the flights' step) does not reach them.
    k, tau, kappa = TRUTH.values()
    loop = Loop(([4 * k, 2 * k], [1.0, 4 * k, kappa + 2 * k, 0.0]), Controller.p(0.95), delay=tau, umin=-1.0,
                umax=3.0)
    t = np.linspace(0.0, 10.0, 501)
    ref = simulate(loop, step, t_end=10.0)
    ours = (px4(k, tau, kappa) * step).step(t)
    assert ours.status == "exact"
    np.testing.assert_allclose(ours.outputs[0, 0], ref.output(t), rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours.outputs[1, 0], ref.velocity(t), rtol=0, atol=1e-9)
    u = ref.command(t)
    assert (np.max(np.abs(u)) == 0.95) == (step == -1.0)


# -- the fit on synthetic logs ---------------------------------------------------------------------------------
def test_fit_recovers_known_parameters_within_their_standard_errors():
    fit = fit_system(px4, START, [_synthetic(TRUTH, 1), _synthetic(TRUTH, 2)], bounds=BOUNDS)
    assert fit.status == "converged" and not fit.warnings
    for name, true in TRUTH.items():
        assert abs(fit.params[name] - true) < 3 * fit.stderr[name], (name, fit.params, fit.stderr)
    assert fit.stderr["tau"] < 0.01
    # the residuals are the noise added (AR(1) of std 4 mm on z, white 8 mm/s on vz): rms near 1 x wander
    for g in fit.logs:
        assert 0.7 < g.rms["z"] / 0.004 < 1.3 and 0.8 < g.rms["vz"] / 0.008 < 1.2, g
    d = json.loads(json.dumps(fit.to_dict(), allow_nan=False))
    assert d["params"].keys() == TRUTH.keys() and d["status"] == "converged"
    assert repr(fit).startswith("SystemFit(k 1.") and "\n" not in repr(fit)


@pytest.mark.slow
def test_standard_errors_cover_the_truth_near_95_percent():
    # Monte Carlo over noise draws: the stated standard errors (AR-coloured sandwich) must be honest
    hits, n = {k: 0 for k in TRUTH}, 40
    for seed in range(n):
        fit = fit_system(px4, START, _synthetic(TRUTH, 100 + seed), bounds=BOUNDS)
        for k, v in TRUTH.items():
            hits[k] += abs(fit.params[k] - v) < 1.96 * fit.stderr[k]
    for k, h in hits.items():
        assert 0.82 * n <= h, (k, h)       # 95 % nominal; 33 of 40 is 2.7 binomial sigmas below


def test_small_examples_against_closed_forms():
    t = np.arange(0.0, 20.0, 0.1)
    u = np.where(t >= 2.0, 1.0, 0.0)
    y = 2.0 * (1 - np.exp(-np.clip(t - 2.7, 0, None) / 3.0))      # 2 exp(-0.7 s)/(3 s + 1), the step held at 2 s
    e = Experiment.from_arrays(t, {"y": y}, u=u)

    def plant(gain, tau, T):
        return tf(f"{gain}*exp(-{tau}*s)/({T}*s+1)", outputs="y")

    np.testing.assert_allclose(simulate_log(plant(2.0, 0.7, 3.0), e)["y"], y, atol=1e-8)
    fit = fit_system(plant, {"gain": 1.0, "tau": 0.2, "T": 1.0}, e, bounds={"tau": (0, 5)}, weights={"y": 0.01})
    np.testing.assert_allclose(list(fit.params.values()), [2.0, 0.7, 3.0], atol=1e-6)


def test_bad_input_is_refused_with_a_named_reason():
    e = _synthetic(TRUTH, 3)
    with pytest.raises(InvalidValueError, match="outside its bounds"):
        fit_system(px4, {**START, "tau": -0.1}, e, bounds=BOUNDS)
    with pytest.raises(InvalidValueError, match="not a parameter"):
        fit_system(px4, START, e, bounds={"T": (0, 1)})
    with pytest.raises(InvalidValueError, match="no output of the system"):
        fit_system(lambda k: tf(k, outputs="y"), {"k": 1.0}, e)
    with pytest.raises(InvalidValueError, match="2 inputs"):
        fit_system(lambda k: tf([[k, 1.0]], outputs="z"), {"k": 1.0}, e)
    with pytest.raises(InvalidTypeError, match="must give a DelayLTI"):
        fit_system(lambda k: k, {"k": 1.0}, e)
    def picky(k):                              # refuses every value but its start (as delay() refuses tau < 0)
        return tf(1.0, outputs="z") * delay(k - 1.0 if k >= 1.0 else -1.0)

    with pytest.raises(IdentificationError, match="build refused"):
        fit_system(picky, {"k": 1.0}, e)
    with pytest.raises(InvalidValueError, match="weights"):
        fit_system(px4, START, e, weights={"z": 0.0})


# -- the real flights ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def px4_fit():
    # z and vz update at about 30 Hz in the 50 Hz logs (data README): count fresh samples only
    return fit_system(px4, START, _flights(TRAIN), bounds=BOUNDS, fresh_only=True)


def test_px4_fit_matches_its_flights_near_their_wander(px4_fit):
    assert px4_fit.status == "converged" and not px4_fit.warnings, px4_fit
    for g in px4_fit.logs:                     # identify's ipdt_speed on the same flights: z within 3 x wander
        q = g.rms_over_wander
        assert q["z"] < 3.0 and q["vz"] < 3.5, g
    # the saturation never acts in these steps: |0.95 e| <= 0.95 < 1 m/s (the limit down)
    assert max(abs(0.95 * (e.r - e.outputs["z"])).max() for e in _flights(TRAIN)) < 1.0


def test_px4_fit_predicts_held_out_flights(px4_fit):
    # flights of another compensation variant, never seen by the fit: free-run prediction within 4 x the hover
    # wander (the criterion test_identification applies to identify's model)
    for e in _flights(HELD_OUT):
        p = px4_fit.predict(e)
        assert p.rms["z"] < 4.0 * p.wander["z"] and p.rms["vz"] < 4.0 * p.wander["vz"], (e.name, p.rms, p.wander)


def test_px4_full_logs_give_the_windows_fit_within_its_errors(px4_fit):
    # the shared logs run to about 44 s (hover after the step); examples/px4-vehicle.toml says the full logs give
    # its numbers (the 10-30 s window's fit) to within a tenth of the errors
    full = fit_system(px4, START, px4_flights(TRAIN, outputs=("z", "vz"), reference="z_ref", t_end=None),
                      bounds=BOUNDS, fresh_only=True)
    assert full.status == "converged"
    for name, value in px4_fit.params.items():
        assert abs(full.params[name] - value) < 0.1 * full.stderr[name], (name, full.params[name], value)


@pytest.mark.slow
def test_px4_ground_effect_is_what_kappa_measures(px4_fit):
    # The HIGH_ALTITUDE flights step from 2.1 to 1.1 m, far from the floor (no ground effect, data README): kappa
    # there is near 0, against about 0.6 1/s^2 for the low flights; k and tau stay of the same order.
    high = fit_system(px4, START, _flights(["HIGH_ALTITUDE_01", "HIGH_ALTITUDE_02", "HIGH_ALTITUDE_03"]),
                      bounds=BOUNDS, fresh_only=True)
    assert abs(high.params["kappa"]) < 0.2 < 0.4 < px4_fit.params["kappa"], (high, px4_fit)
    assert px4_fit.params["kappa"] - high.params["kappa"] > 5 * math.hypot(px4_fit.stderr["kappa"],
                                                                           high.stderr["kappa"])


@pytest.mark.slow
def test_px4_delay_agrees_with_identify(px4_fit):
    # identify's ipdt_speed (the speed loop as one identified block, z only) on the same flights
    m = identify(_flights(TRAIN, ["z"]), model="ipdt_speed", fresh_only=True,
                 loop=Loop("1/s", Controller.p(0.95), umin=-1.0, umax=3.0, period=0.02))
    d1, s1 = px4_fit.params["tau"], px4_fit.stderr["tau"]
    d2, s2 = m.params["delay"], m.stderr["delay"]
    assert abs(d1 - d2) < 3 * math.hypot(s1, s2), (d1, s1, d2, s2)


def test_example_file_is_the_fitted_interconnection(px4_fit):
    # examples/px4-vehicle.toml holds the fit's numbers to 4 digits, and is the same system as the blocks above
    # (frequency responses, the small-signal loop's, equal to 1e-10; the limits: test_system_file_saturation.py)
    import tomllib

    from delaykit.systems.files import read_system_file

    path = Path(__file__).parents[1] / "examples" / "px4-vehicle.toml"
    blocks = {b.get("name"): b for b in tomllib.loads(path.read_text())["blocks"]}
    written = {"k": blocks["thrust to acceleration"]["tf"], "tau": blocks["dead time"]["delay"],
               "kappa": blocks["ground effect"]["tf"]}
    assert written == {k: float(f"{v:.4g}") for k, v in px4_fit.params.items()}, (written, px4_fit.params)
    w = np.logspace(-2, 2, 60)
    got = read_system_file(path).system.frequency_response(w).response
    want = px4(**written).without_limits().frequency_response(w).response
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


@pytest.mark.slow
def test_px4_slower_sensor_gives_more_delay():
    # One flight at a time: the APPIUS flights' position updates at 8.5 Hz, the others' at about 30 Hz (data
    # README); the slower sensor's flights must show more dead time than every faster one of the low flights.
    def tau(name):
        return fit_system(px4, START, _flights([name]), bounds=BOUNDS, fresh_only=True).params["tau"]

    slow = [tau(f"APPIUS_0{i}") for i in (1, 2, 3)]
    fast = [tau(n) for n in TRAIN + HELD_OUT + ["CHEESEMAN_01", "NO_COMPENSATION_01"]]
    assert min(slow) > max(fast), (slow, fast)


def test_a_parameter_the_logs_do_not_see_is_reported_not_determined():
    # "unused" never reaches the output: its Jacobian column is zero, and the fit says so (strict JSON still)
    e = _synthetic(TRUTH, 4)
    fit = fit_system(lambda k, tau, kappa, unused: px4(k, tau, kappa), {**START, "unused": 1.0}, e, bounds=BOUNDS)
    assert any("unused is not determined" in w for w in fit.warnings), fit.warnings
    assert fit.params["unused"] == 1.0
    json.dumps(fit.to_dict(), allow_nan=False)
    for name, true in TRUTH.items():           # the others are still found
        assert abs(fit.params[name] - true) < 3 * fit.stderr[name]
