"""Delay estimation: the paper's section 5.1 reproduced, and the trajectory fit on synthetic flights from the
exact simulator (the truth is known; the simulator itself is checked against the oracle elsewhere)."""

from __future__ import annotations

import cmath
import json
import math

import mpmath
import numpy as np
import pytest
from scipy import stats

from delaykit import AltitudeLoop
from delaykit.identify.estimation import (EstimationError, estimate_flights, estimate_lambert, estimate_overshoot,
                                          estimate_trajectory, fitted_altitude)
from delaykit.identify.flightlog import FlightLog, LogError, synthetic_log, write_log


def _oracle_overshoot(kp: float, delay: float, vmax: float | None = 1.0) -> float:
    """The overshoot (%) of the P loop by the independent DOP853 solver (tests/oracle.py), accurate to 1e-6 pp."""
    from oracle import Oracle

    return Oracle(kp=kp, td=delay, vmax=vmax, step=1.0, t_end=12.0).metrics()["overshoot"]


def test_section_511_overshoot_method():
    # the paper's measurement (Mo = 2.300 % at Kp = 1.31): the estimate is the delay at which the loop overshoots
    # by exactly 2.300 %, checked with the independent solver (not delaykit's)
    est = estimate_overshoot(2.300, kp=1.31, peak_time=3.055)
    assert math.isclose(_oracle_overshoot(1.31, est.delay), 2.300, abs_tol=1e-5)
    # and the model's peak time there (its own) does not explain the measured 3.055 s: a warning says so
    assert est.diagnostics.model_peak_time < 2.5 and any("peak time" in w for w in est.warnings)
    # the same for other assumed gains and without saturation (the sensitivities the reproduction prints)
    for kp, vmax in ((1.20, 1.0), (1.40, 1.0), (1.31, None)):
        e = estimate_overshoot(2.300, kp=kp, vmax=vmax)
        assert math.isclose(_oracle_overshoot(kp, e.delay, vmax), 2.300, abs_tol=1e-5), (kp, vmax)


def test_overshoot_method_recovers_a_known_delay():
    # a synthetic measurement with a known truth: the oracle's overshoot at Td = 0.35 s, fed back, gives 0.35 s
    # (to the oracle's 1e-6 pp over the 58 pp/s slope: a few 1e-8 s)
    for kp, td in ((1.31, 0.35), (1.8, 0.27)):
        mo = _oracle_overshoot(kp, td)
        assert abs(estimate_overshoot(mo, kp=kp).delay - td) < 1e-6


def test_section_512_lambert_method_both_variants():
    # closed forms, independent of delaykit: (Mo, tp) -> zeta, wn -> the dominant root s; the paper's relation
    # s = W_0(-Kp T) / T then means exp(-s T) = -s / Kp, so T = -Log(-s / Kp) / s on the principal logarithm
    kp, mo, tp = 1.31, 2.300, 3.055
    lm = math.log(mo / 100)
    zeta = -lm / math.sqrt(math.pi**2 + lm**2)
    wn = math.pi / (tp * math.sqrt(1 - zeta**2))
    s = complex(-zeta * wn, wn * math.sqrt(1 - zeta**2))
    T = -cmath.log(-s / kp) / s
    paper = estimate_lambert(mo, tp, kp=kp, variant="paper")
    assert abs(paper.diagnostics.root - s) < 1e-12
    assert abs(complex(paper.delay, paper.delay_imag) - T) < 1e-12
    assert abs(complex(mpmath.lambertw(-kp * T, 0)) / T - s) < 1e-12  # branch 0 (mpmath), as the paper's relation
    assert round(paper.delay, 3) == 0.374  # the paper's printed 0.374 s is this delay's real part
    it = paper.diagnostics.iterations
    assert it[0] == 0.2 and len(it) > 3
    # the damping variant: the real delay whose dominant root W_0(-Kp Td) / Td (mpmath) has the measured damping
    damping = estimate_lambert(mo, tp, kp=kp, variant="damping")
    r = complex(mpmath.lambertw(-kp * damping.delay, 0)) / damping.delay
    assert math.isclose(-r.real / abs(r), zeta, abs_tol=1e-10) and damping.delay_imag is None
    with pytest.raises(ValueError, match="variant"):
        estimate_lambert(2.3, 3.0, kp=1.31, variant="fsolve")


def test_overshoot_method_fails_clearly_without_overshoot():
    with pytest.raises(EstimationError, match="overshoot is 0"):
        estimate_overshoot(0.0, kp=1.31)


@pytest.mark.parametrize("loop, step", [
    (AltitudeLoop(kp=1.31, delay=0.368), 1.0),
    (AltitudeLoop(kp=1.8, delay=0.42, period=0.065), -1.5),
    (AltitudeLoop(kp=1.0, delay=0.25), 0.8),  # Kp Td < 1/e: no overshoot at all
    (AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered"), 1.2),
])
def test_trajectory_recovers_the_delay_from_noiseless_rounded_data(loop, step):
    log = synthetic_log(loop, step, z0=2.5, phase=0.031, t0=123.4)
    est = estimate_trajectory(log, kp=loop.kp, kv=loop.kv, period=loop.period, velocity=loop.velocity)
    assert abs(est.delay - loop.delay) < 1e-3
    assert est.ci[0] <= loop.delay <= est.ci[1]


def test_trajectory_intervals_cover_the_truth():
    # 40 noisy flights at 5 mm: a 95 % interval that misses more than 8 of 40 would be badly calibrated
    # (binomial probability below 0.2 %); the seed is fixed so the test is deterministic
    rng = np.random.default_rng(11)
    hits, errs = 0, []
    for i in range(40):
        loop = AltitudeLoop(kp=rng.uniform(0.9, 2.0), delay=rng.uniform(0.15, 0.55),
                            period=0.065 if i % 2 else None)
        log = synthetic_log(loop, rng.choice([-1, 1]) * rng.uniform(0.5, 2), noise=0.005, rng=rng,
                            phase=rng.uniform(0, 0.065))
        est = estimate_trajectory(log, kp=loop.kp, period=loop.period)
        hits += est.ci[0] <= loop.delay <= est.ci[1]
        errs.append(abs(est.delay - loop.delay))
    assert hits >= 32
    assert np.median(errs) < 2e-3


@pytest.mark.slow
def test_intervals_cover_the_truth_for_pooled_sampled_flights_with_a_free_lag():
    # the configuration of the flights (delaykit fly + estimate, and the demo): an up and a down step at Kp = 1.31,
    # sampled every 0.065 s, 4 mm noise, the drone's speed-loop lag fitted; 40 pairs with known delays and lags.
    # A calibrated 95 % interval misses binomially: 33 or more hits of 40 has probability 0.9993 (scipy's binom).
    # The standard errors too: sum(z^2) over 40 flights is chi2(40) if calibrated, inside [16.9, 76.1] with
    # probability 0.999 (too wide an error, as a padded interval, fails the lower end; too narrow the upper).
    rng = np.random.default_rng(21)
    hits, z = 0, []
    for _ in range(40):
        td, lag = rng.uniform(0.2, 0.4), rng.uniform(0.03, 0.1)
        loop = AltitudeLoop(kp=1.31, delay=td, lag=lag, period=0.065)
        logs = [synthetic_log(loop, s, noise=0.004, rng=rng, after=6.0) for s in (1.0, -1.0)]
        est = estimate_trajectory(logs, kp=1.31, period=0.065, free=("lag",))
        hits += est.ci[0] <= td <= est.ci[1]
        z.append((est.delay - td) / est.stderr)
    assert hits >= 33
    assert 16.9 < float(np.sum(np.square(z))) < 76.1


def test_free_lag_and_gain_recover_a_slower_drone():
    # the drone's own speed loop: lag 0.2 s, gain 0.9 (the kind of mismatch the paper's flights show)
    true = AltitudeLoop(kp=1.31, delay=0.30, lag=0.2, gain=0.9, period=0.065)
    rng = np.random.default_rng(3)
    logs = [synthetic_log(true, 1.0, noise=0.004, rng=rng) for _ in range(3)]
    plain = estimate_trajectory(logs, kp=1.31, period=0.065)
    assert plain.warnings  # the model without the lag does not explain the data
    full = estimate_trajectory(logs, kp=1.31, period=0.065, free=("gain", "lag"))
    assert abs(full.delay - 0.30) < 0.01
    assert np.allclose(full.params.lag, 0.2, atol=0.03) and np.allclose(full.params.gain, 0.9, atol=0.03)
    assert full.diagnostics.whiteness_p > 0.01
    z = fitted_altitude(logs[0], full, 1.31, 0, period=0.065)
    assert np.sqrt(np.mean((logs[0].z - z) ** 2)) < 0.006


def test_pooling_and_heterogeneity():
    rng = np.random.default_rng(8)
    same = [synthetic_log(AltitudeLoop(kp=1.31, delay=0.37), 1.0, noise=0.003, rng=rng) for _ in range(4)]
    pooled, each = estimate_flights(same, kp=1.31)
    assert pooled.flights == 4 and len(each) == 4
    assert abs(pooled.delay - 0.37) < 2e-3 and pooled.stderr < min(e.stderr for e in each)
    assert pooled.diagnostics.heterogeneity_p > 0.05 and not any("disagree" in w for w in pooled.warnings)
    # flights that agree: the pooled error is the joint fit's, not widened
    joint_same = estimate_trajectory(same, kp=1.31)
    assert pooled.stderr == joint_same.stderr and pooled.ci == joint_same.ci
    varied = [synthetic_log(AltitudeLoop(kp=1.31, delay=d), 1.0, noise=0.003, rng=rng) for d in (0.33, 0.37, 0.41)]
    pooled2, each2 = estimate_flights(varied, kp=1.31)
    assert any("disagree" in w for w in pooled2.warnings)
    assert 0.03 < pooled2.diagnostics.spread < 0.05  # the sample standard deviation of 0.33, 0.37, 0.41 is 0.04
    # the documented widening: chi2 = sum((d_i - d) / se_i)^2 over the flights, p from chi2 with n - 1 degrees of
    # freedom, and when p < 0.05 the joint fit's error and interval are scaled by sqrt(chi2 / (n - 1))
    joint = estimate_trajectory(varied, kp=1.31)
    d = np.array([e.delay for e in each2])
    se = np.array([e.stderr for e in each2])
    chi2 = float(np.sum(((d - joint.delay) / se) ** 2))
    k = math.sqrt(chi2 / 2)
    assert math.isclose(pooled2.diagnostics.heterogeneity_chi2, chi2, rel_tol=1e-12)
    assert math.isclose(pooled2.diagnostics.heterogeneity_p, stats.chi2.sf(chi2, 2), rel_tol=1e-12)
    assert pooled2.diagnostics.heterogeneity_p < 0.05 and k > 3
    assert pooled2.delay == joint.delay and math.isclose(pooled2.stderr, k * joint.stderr, rel_tol=1e-12)
    lo, hi = pooled2.ci
    assert math.isclose(joint.delay - lo, k * (joint.delay - joint.ci[0]), rel_tol=1e-12)
    assert math.isclose(hi - joint.delay, k * (joint.ci[1] - joint.delay), rel_tol=1e-12)
    # widened, the interval takes in the middle flight's truth, which the joint fit's narrow one may not
    assert lo < 0.37 < hi and hi - lo > 3 * (joint.ci[1] - joint.ci[0])


def test_newey_west_factor_and_ljung_box_against_statsmodels():
    """The fit's Newey-West inflation of the standard error, and its Ljung-Box statistic, recomputed by statsmodels
    from the fit's own residuals and Jacobian (the private helpers rebuild them at the estimate)."""
    sm = pytest.importorskip("statsmodels.api")
    from statsmodels.stats.diagnostic import acorr_ljungbox

    from delaykit.identify.estimation import _Flight, _ljung_box, _residuals

    # a drone with a speed lag the model leaves out: the residuals are correlated in time, so the factor is > 1
    log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.33, lag=0.12), 1.0, noise=0.003, rng=np.random.default_rng(4))
    est = estimate_trajectory(log, kp=1.31)
    flights = [_Flight(log, AltitudeLoop(kp=1.31, delay=0.0))]
    theta = np.array([est.delay])
    r = _residuals(theta, flights, ())
    h = 1e-6
    J = ((_residuals(theta + h, flights, ()) - _residuals(theta - h, flights, ())) / (2 * h))[:, None]
    n, p = r.size, 3  # the delay, and the offset and scale profiled out of the residuals
    lags = int(min(max(4, round(4 * (n / 100.0) ** (2 / 9))), n // 4))  # the documented bandwidth rule
    # at the least-squares optimum J'r = 0, so the OLS of r on J has residuals r: its HAC covariance (Bartlett
    # weights, no small-sample correction) is the sandwich (J'J)^-1 S (J'J)^-1 of the fit
    ols = sm.OLS(r, J).fit(cov_type="HAC", cov_kwds={"maxlags": lags, "use_correction": False})
    assert np.allclose(ols.resid, r, atol=1e-9)
    se_hac = math.sqrt(ols.cov_params()[0, 0] * n / (n - p))
    se_white = math.sqrt(float(r @ r) / (n - p) / float(J[:, 0] @ J[:, 0]))
    assert se_hac / se_white > 2
    assert math.isclose(est.diagnostics.stderr_inflation, se_hac / se_white, rel_tol=1e-5)
    # the reported error: the inflated one, with the rounding floor in quadrature
    floor = est.diagnostics.resolution_stderr
    assert math.isclose(est.stderr, math.hypot(se_hac, floor), rel_tol=1e-5)
    # Ljung-Box on the same residuals (10 lags), and on an AR(1) series at several lags
    lb = acorr_ljungbox(r, lags=[10], return_df=True)
    assert math.isclose(est.diagnostics.ljung_box_q, float(lb["lb_stat"].iloc[0]), rel_tol=1e-9)
    assert math.isclose(est.diagnostics.whiteness_p, float(lb["lb_pvalue"].iloc[0]), rel_tol=1e-6)
    e = np.random.default_rng(1).standard_normal(300)
    ar = np.empty_like(e)
    ar[0] = e[0]
    for i in range(1, e.size):
        ar[i] = 0.3 * ar[i - 1] + e[i]
    for lag in (1, 5, 10, 20):
        q, pval = _ljung_box(ar + 5.0, lags=lag)  # a mean of 5: both remove it
        ref = acorr_ljungbox(ar + 5.0, lags=[lag], return_df=True)
        assert math.isclose(q, float(ref["lb_stat"].iloc[0]), rel_tol=1e-10)
        assert math.isclose(pval, float(ref["lb_pvalue"].iloc[0]), rel_tol=1e-8)


def test_estimate_repr_and_dict():
    est = estimate_overshoot(2.300, kp=1.31, overshoot_stderr=0.02)
    assert repr(est).startswith(f"DelayEstimate(delay={est.delay:.4f} s ± {est.stderr:.4f}")
    d = est.to_dict()
    json.dumps(d)
    assert d["method"] == "overshoot" and d["ci"][0] < d["delay"] < d["ci"][1]


# ---- flight logs ---------------------------------------------------------------------------------------------


def write(tmp_path, text, name="f.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def good_csv(n=30, step_at=5):
    rows = ["t,z,z_ref,u"]
    for i in range(n):
        rows.append(f"{0.1 * i:.1f},{1.0 + 0.01 * max(0, i - step_at):.3f},{2.0 if i >= step_at else 1.0},0.5")
    return "\n".join(rows) + "\n"


def test_log_reading_and_step_detection(tmp_path):
    log = FlightLog.from_csv(write(tmp_path, good_csv()))
    assert log.step_time == 0.5 and log.step == 1.0 and log.z0 == 1.0 and log.u is not None


@pytest.mark.parametrize("mutate, fragment", [
    (lambda s: s.replace("t,z,z_ref,u", "time,z,z_ref,u"), "missing column 't'"),
    (lambda s: s.replace("t,z,z_ref,u", "t,z,u"), "missing column 'z_ref'"),
    (lambda s: s.replace("0.3,1.000", "0.3,abc"), "row 5: z is 'abc'"),
    (lambda s: s.replace("0.3,1.000", "0.3,nan"), "row 5: z is nan"),
    (lambda s: s.replace("0.4,1.000", "0.2,1.000"), "row 6: time 0.2 does not increase"),
    (lambda s: s.replace(",2.0,", ",1.0,"), "no step in z_ref"),
])
def test_bad_logs_name_file_row_and_problem(tmp_path, mutate, fragment):
    p = write(tmp_path, mutate(good_csv()))
    with pytest.raises(LogError, match=fragment) as info:
        FlightLog.from_csv(p)
    assert str(p) in str(info.value)


def test_too_few_samples_after_step_and_skip_bad(tmp_path):
    with pytest.raises(LogError, match="only 3 samples after the step"):
        FlightLog.from_csv(write(tmp_path, good_csv(n=30, step_at=27)))
    text = good_csv().replace("0.3,1.000", "0.3,bad").replace("0.9,1.040", "0.9,inf")
    log = FlightLog.from_csv(write(tmp_path, text), skip_bad=True)
    assert log.skipped == 2 and log.t.size == 28
    assert "2 rows skipped" in repr(log)


def test_column_mapping_and_dataframe(tmp_path):
    text = good_csv().replace("t,z,z_ref,u", "time_s,alt,ref,cmd")
    log = FlightLog.from_csv(write(tmp_path, text), columns={"t": "time_s", "z": "alt", "z_ref": "ref", "u": "cmd"})
    assert log.step == 1.0
    pd = pytest.importorskip("pandas")
    df = pd.read_csv(tmp_path / "f.csv")
    log2 = FlightLog.from_dataframe(df, columns={"t": "time_s", "z": "alt", "z_ref": "ref"})
    assert log2.step_time == log.step_time


def test_cli_estimate_files_and_numbers(tmp_path):
    from typer.testing import CliRunner

    from delaykit.cli import app

    rng = np.random.default_rng(2)
    paths = []
    for i in range(2):
        log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.37, period=0.065), 1.0, noise=0.004, rng=rng, t0=50.0)
        p = tmp_path / f"flight{i}.csv"
        write_log(p, {"t": log.t, "z": log.z, "z_ref": log.z_ref})
        paths.append(str(p))
    runner = CliRunner()
    res = runner.invoke(app, ["estimate", *paths, "--kp", "1.31", "--period", "0.065", "--json",
                              "--plot", str(tmp_path / "fit.png")])
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    assert [f["file"] for f in got["flights"]] == paths
    assert abs(got["pooled"]["delay"] - 0.37) < 0.004 and got["pooled"]["ci"][0] < got["pooled"]["delay"]
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    res = runner.invoke(app, ["estimate", "--overshoot", "2.3", "--peak-time", "3.055", "--kp", "1.31",
                              "--method", "lambert", "--variant", "paper", "--json"])
    got = json.loads(res.stdout)
    assert round(got["delay"], 3) == 0.374 and got["delay_imag"] < -0.25
    res = runner.invoke(app, ["estimate", "--kp", "1.31", "--method", "magic", "--overshoot", "2"])
    assert res.exit_code == 2 and "--method" in res.output
    res = runner.invoke(app, ["estimate", str(tmp_path / "missing.csv"), "--kp", "1.31"])
    assert res.exit_code == 2 and "cannot be read" in res.output


# ---- typed params and diagnostics; an estimate without an interval --------------------------------------------


def test_params_and_diagnostics_are_typed_records_with_the_former_json():
    from dataclasses import FrozenInstanceError

    from delaykit.identify.estimation import DelayEstimate, Diagnostics, EstimateParams, FlightFit

    est = estimate_overshoot(2.300, kp=1.31)
    assert isinstance(est.params, EstimateParams) and isinstance(est.diagnostics, Diagnostics)
    assert est.params.kp == 1.31 and est.params.overshoot == 2.3 and est.params.lag is None
    assert est.diagnostics.slope_percent_per_second > 0 and est.diagnostics.measured_peak_time is None
    with pytest.raises(FrozenInstanceError):
        est.params.kp = 2.0  # type: ignore[misc]
    # the JSON has the keys the dicts had: set fields only (the overshoot method always reports the model's peak)
    d = est.to_dict()
    assert set(d["params"]) == {"kp", "overshoot"}
    assert set(d["diagnostics"]) == {"slope_percent_per_second", "warnings", "model_peak_time"}
    assert Diagnostics(slope_percent_per_second=1.0).to_dict() == {
        "warnings": [], "slope_percent_per_second": 1.0, "model_peak_time": None}
    with_tp = estimate_overshoot(2.300, kp=1.31, peak_time=3.055).to_dict()["diagnostics"]
    assert set(with_tp) == {"slope_percent_per_second", "warnings", "model_peak_time", "measured_peak_time"}
    paper = estimate_lambert(2.300, 3.055, kp=1.31, variant="paper").to_dict()
    assert paper["params"] == {"variant": "paper", "kp": 1.31}
    assert set(paper["diagnostics"]) == {"zeta", "omega_n", "root", "warnings", "iterations"}
    assert len(paper["diagnostics"]["root"]) == 2 and paper["diagnostics"]["iterations"][0] == [0.2, 0.0]
    damping = estimate_lambert(2.300, 3.055, kp=1.31, variant="damping").to_dict()
    assert set(damping["diagnostics"]) == {"zeta", "omega_n", "root", "warnings", "model_root"}

    rng = np.random.default_rng(5)
    logs = [synthetic_log(AltitudeLoop(kp=1.31, delay=0.37), 1.0, noise=0.003, rng=rng, after=6.0) for _ in range(2)]
    pooled, each = estimate_flights(logs, kp=1.31, free=("lag",), interval=False)
    assert isinstance(pooled.diagnostics.per_flight[0], FlightFit) and len(pooled.params.lag) == 2
    assert pooled.params.gain is None and len(pooled.diagnostics.per_flight_delays) == 2
    d = json.loads(json.dumps(pooled.to_dict()))
    assert set(d["params"]) == {"offsets", "scales", "lag"}
    assert set(d["diagnostics"]) >= {"ljung_box_q", "whiteness_p", "per_flight", "warnings", "nfev", "samples",
                                     "resolution", "resolution_stderr", "stderr_inflation", "spread",
                                     "per_flight_delays", "heterogeneity_chi2", "heterogeneity_p"}
    assert set(d["diagnostics"]) - {"note"} == {"ljung_box_q", "whiteness_p", "per_flight", "warnings", "nfev",
                                                 "samples", "resolution", "resolution_stderr", "stderr_inflation",
                                                 "spread", "per_flight_delays", "heterogeneity_chi2",
                                                 "heterogeneity_p"}
    assert set(d["diagnostics"]["per_flight"][0]) == {"file", "offset", "scale", "gain", "lag", "residual_rms",
                                                      "measured_overshoot", "model_overshoot", "measured_peak_time",
                                                      "model_peak_time"}
    assert set(each[0].to_dict()["diagnostics"]) - {"note"} == {
        "ljung_box_q", "whiteness_p", "per_flight", "warnings", "nfev", "samples", "resolution",
        "resolution_stderr", "stderr_inflation"}
    # a mapping in the former form is converted; an unknown key is an error that names it
    est2 = DelayEstimate(delay=0.3, stderr=None, ci=None, method="overshoot", params={"kp": 1.0},
                         diagnostics={"warnings": ["w"], "spread": 0.01})
    assert est2.params == EstimateParams(kp=1.0) and est2.warnings == ["w"] and est2.diagnostics.spread == 0.01
    with pytest.raises(ValueError, match="'gains'"):
        DelayEstimate(delay=0.3, stderr=None, ci=None, method="x", params={"gains": [1.0]})
    # fitting altitudes needs a trajectory fit's offsets and scales
    with pytest.raises(ValueError, match="not a trajectory fit"):
        fitted_altitude(logs[0], est, 1.31)


def test_records_read_as_the_former_dicts():
    """``diag["spread"]`` and the other dict reads keep working, read-only, with the keys the dicts had (the
    fields that are set); an unset field or an unknown name is a KeyError that says which."""
    from delaykit.identify.estimation import Diagnostics, EstimateParams

    diag = Diagnostics(warnings=("w",), spread=0.04, per_flight_delays=(0.33, 0.37, 0.41))
    assert diag["spread"] == 0.04 and diag["per_flight_delays"] == (0.33, 0.37, 0.41) and diag["warnings"] == ("w",)
    assert "spread" in diag and "heterogeneity_p" not in diag and "nonsense" not in diag and 3 not in diag
    assert diag.get("spread") == 0.04 and diag.get("heterogeneity_p") is None and diag.get("zeta", 7) == 7
    assert list(diag) == list(diag.keys()) == ["warnings", "spread", "per_flight_delays"]
    # a dict built from the record equals the JSON form here (no value needs converting)
    assert dict(diag) == {"warnings": ("w",), "spread": 0.04, "per_flight_delays": (0.33, 0.37, 0.41)}
    with pytest.raises(KeyError, match="'heterogeneity_p' is not set"):
        diag["heterogeneity_p"]
    with pytest.raises(KeyError, match="no field 'sprad'.*spread"):
        diag["sprad"]
    with pytest.raises(TypeError):  # read-only
        diag["spread"] = 1.0  # type: ignore[index]
    params = EstimateParams(kp=1.31)
    assert params["kp"] == 1.31 and list(params) == ["kp"]
    with pytest.raises(KeyError, match="'lag' is not set"):
        params["lag"]
    # on real estimates: the keys are the JSON's, the values the fields'
    est = estimate_overshoot(2.300, kp=1.31)
    assert set(est.diagnostics) == set(est.to_dict()["diagnostics"])
    assert est.diagnostics["slope_percent_per_second"] == est.diagnostics.slope_percent_per_second
    assert est.diagnostics["model_peak_time"] == est.diagnostics.model_peak_time  # always reported, even None
    assert est.params["overshoot"] == 2.3


def test_cli_estimate_with_no_interval_says_so(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from delaykit.identify import estimation as E  # (delaykit.identify is the function)
    from delaykit.cli import app

    p = tmp_path / "flight.csv"
    log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.37), 1.0, after=5.0)
    write_log(p, {"t": log.t, "z": log.z, "z_ref": log.z_ref})
    no_ci = E.DelayEstimate(delay=0.37, stderr=None, ci=None, method="trajectory",
                            params=E.EstimateParams(offsets=(0.0,), scales=(1.0,)))
    monkeypatch.setattr(E, "estimate_flights", lambda logs, kp, **kw: (no_ci, [no_ci] * len(logs)))
    runner = CliRunner()
    for args in ([str(p), str(p)], [str(p)]):
        res = runner.invoke(app, ["estimate", *args, "--kp", "1.31", "--json"])
        assert res.exit_code == 0, res.output
        got = json.loads(res.stdout)
        assert got["pooled"]["ci"] is None and all(f["ci"] is None for f in got["flights"])
        res = runner.invoke(app, ["estimate", *args, "--kp", "1.31"])
        assert res.exit_code == 0, res.output
        assert "no interval" in res.stdout and "Traceback" not in res.output
    # the overshoot method on one flight has no spread, hence no interval, without any stub
    monkeypatch.undo()
    res = runner.invoke(app, ["estimate", str(p), "--kp", "1.31", "--method", "overshoot", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["pooled"]["ci"] is None
    res = runner.invoke(app, ["estimate", "--overshoot", "2.3", "--kp", "1.31", "--method", "overshoot"])
    assert res.exit_code == 0 and "no interval" in res.stdout


# ---------------------------------------------------------------------------------------------------------------
# the estimators take the loop object (issue 9): AltitudeLoop.from_loop, and `delaykit estimate --loop`


@pytest.mark.parametrize("lp", [
    AltitudeLoop(kp=1.31, delay=0.368),
    AltitudeLoop(kp=2.0, delay=0.2, kv=0.3, vmax=None, period=0.065, sample_offset=0.01),
    AltitudeLoop(kp=0.9, delay=0.1, kv=0.25, velocity="filtered", filter_wn=20.0, filter_zeta=0.8, gain=0.8, lag=0.12),
])
def test_from_loop_inverts_to_loop(lp):
    # the general loop of a paper loop maps back to the same paper loop, field for field (the gain and lag to
    # rounding: the plant's coefficients are normalised to a monic denominator)
    import dataclasses

    back = AltitudeLoop.from_loop(lp.to_loop())
    for f in dataclasses.fields(lp):
        want, got = getattr(lp, f.name), getattr(back, f.name)
        assert got == pytest.approx(want, rel=1e-14) if isinstance(want, float) else got == want, f.name
    assert AltitudeLoop.from_loop(lp) is lp


@pytest.mark.parametrize(("changes", "named"), [
    ({"plant": "1/(s+1)"}, "plant"),
    ({"plant": "1/(s*(s-2))"}, "plant"),  # a "lag" with an unstable pole is not a lag
    ({"controller": "pi"}, "controller"),
    ({"output_delay": 0.05}, "measurement delay"),
    ({"umin": -1.0, "umax": 3.0}, "not symmetric"),
])
def test_from_loop_names_what_is_not_the_papers(changes, named):
    from delaykit.errors import InvalidValueError
    from delaykit.models import Controller

    lp = AltitudeLoop(kp=1.31, delay=0.3).to_loop()
    if changes.get("controller") == "pi":
        lp = lp.replace(controller=Controller.pi(1.0, 0.5))
    else:
        lp = lp.replace(**changes)
    with pytest.raises(InvalidValueError, match=named):
        AltitudeLoop.from_loop(lp)


def test_trajectory_with_a_loop_holds_its_known_lag():
    # flights of a drone with a known 0.1 s speed-loop lag: the loop object carries the lag, so the fit (lag not
    # free) recovers the true delay; the gain-only keywords (lag 0) put the lag into the delay instead. The truth
    # is the simulator's input (the simulator is checked against the oracle elsewhere).
    truth = AltitudeLoop(kp=1.31, delay=0.25, lag=0.1, period=0.065)
    rng = np.random.default_rng(9)
    logs = [synthetic_log(truth, 1.0, noise=0.002, rng=rng) for _ in range(2)]
    with_loop, _ = estimate_flights(logs, truth.to_loop())
    assert abs(with_loop.delay - 0.25) < 3 * with_loop.stderr + 1e-3
    keywords, _ = estimate_flights(logs, 1.31, period=0.065)
    assert keywords.delay > 0.25 + 0.04  # the lag shows up as extra delay
    # the fitted altitude with the loop follows the flight to the noise level
    fit = fitted_altitude(logs[0], with_loop, truth, 0)
    assert np.sqrt(np.mean((fit - logs[0].z) ** 2)) < 0.004
    # the keyword path and an equal loop object are one computation: the same estimate
    a = estimate_overshoot(2.3, kp=1.31, kv=0.1, period=0.065)
    b = estimate_overshoot(2.3, AltitudeLoop(kp=1.31, delay=0.0, kv=0.1, period=0.065))
    assert a.delay == b.delay


def test_a_loop_and_its_keywords_together_are_refused():
    from delaykit.errors import InvalidValueError

    lp = AltitudeLoop(kp=1.31, delay=0.3)
    with pytest.raises(InvalidValueError, match="kv"):
        estimate_overshoot(2.3, lp, kv=0.2)
    with pytest.raises(InvalidValueError, match="Lambert"):
        estimate_lambert(2.3, 3.055, lp.replace(kv=0.2))


def test_cli_estimate_takes_the_loop_file(tmp_path):
    from typer.testing import CliRunner

    from delaykit.cli import app

    rng = np.random.default_rng(4)
    truth = AltitudeLoop(kp=1.1, delay=0.3, kv=0.2, period=0.065)
    paths = []
    for i in range(2):
        log = synthetic_log(truth, 1.0, noise=0.003, rng=rng)
        p = tmp_path / f"f{i}.csv"
        write_log(p, {"t": log.t, "z": log.z, "z_ref": log.z_ref})
        paths.append(str(p))
    (tmp_path / "loop.toml").write_text('plant = "1/s"\ncontroller = "pv"\nkp = 1.1\nkv = 0.2\ndelay = 5.0\n'
                                        'umin = -1.0\numax = 1.0\nperiod = 0.065\n')
    runner = CliRunner()
    by_file = runner.invoke(app, ["estimate", *paths, "--loop", str(tmp_path / "loop.toml"), "--json"])
    by_flags = runner.invoke(app, ["estimate", *paths, "--kp", "1.1", "--kv", "0.2", "--period", "0.065", "--json"])
    assert by_file.exit_code == 0 and by_flags.exit_code == 0, (by_file.output, by_flags.output)
    got, ref = json.loads(by_file.stdout), json.loads(by_flags.stdout)
    assert got == ref  # the file's delay (5 s) is ignored: it is what is estimated
    assert abs(got["pooled"]["delay"] - 0.3) < 0.01
    # a loop of another family: exit 2, naming the plant, and pointing nowhere deep into numpy
    res = runner.invoke(app, ["estimate", *paths, "--plant", "1/(s+1)", "--kp", "1.1"])
    assert res.exit_code == 2 and "1/(s + 1)" in res.output and "Traceback" not in res.output


def test_cli_estimate_says_each_warning_once(tmp_path):
    # a flight of a loop with a speed-loop lag that the estimator's integrator model leaves out: the residuals are
    # not white, and the one-flight fit (which is the pooled fit) says so once, not once as pooled and again per
    # flight; with two flights each flight's own warning is named
    from typer.testing import CliRunner

    from delaykit.cli import app

    rng = np.random.default_rng(3)
    paths = []
    for i in range(2):
        log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.3, lag=0.15, period=0.065), 1.0, noise=0.002, rng=rng,
                            t0=50.0)
        p = tmp_path / f"flight{i}.csv"
        write_log(p, {"t": log.t, "z": log.z, "z_ref": log.z_ref})
        paths.append(str(p))
    runner = CliRunner()
    one = runner.invoke(app, ["estimate", paths[0], "--kp", "1.31", "--period", "0.065"])
    assert one.exit_code == 0, one.output
    said = [line for line in one.output.splitlines() if line.startswith("warning:")]
    assert said and len(said) == len(set(said)), said
    two = runner.invoke(app, ["estimate", *paths, "--kp", "1.31", "--period", "0.065"])
    said = [line for line in two.output.splitlines() if line.startswith("warning:")]
    assert len(said) == len(set(said)) and any("flight0.csv: " in w or "flight1.csv: " in w for w in said), said
