"""Monte Carlo of the step metrics (delaykit.simulate.montecarlo): the batched path (a constant delay per run drawn
from a DelayDistribution, all runs in one simulate_many call) against per-run simulate() calls and the independent
DOP853 reference solver (tests/oracle_loop.py); compensator loops (the true delay drawn, the model delay fixed);
percentiles against numpy's; seeds; runs beyond the stability limit; the distributions against scipy.stats; bad
parameters; the per-packet (event) path moved here from test_varying.py; and the benchmark script on a small case."""

from __future__ import annotations

import importlib
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

import delaykit
from delaykit import InvalidTypeError, InvalidValueError, simulate
from delaykit.models import Compensator, Controller, Loop
from delaykit.simulate.montecarlo import DelayDistribution, MonteCarlo, monte_carlo
from delaykit.simulate.varying import DelaySchedule, Jitter
from oracle_loop import LoopOracle, LoopSpec

ROOT = Path(__file__).resolve().parents[1]
METRICS = ("overshoot", "peak_time", "rise_time", "settling_time")
P_LOOP = Loop("1/s", Controller.p(1.31), umin=-1, umax=1)  # the paper's P loop, continuous


def per_run(loop, delays, **kw):
    """The reference the batched path must equal: simulate() once per delay, in a Python loop, with the loop's
    input delay set by Loop.replace(delay=d) (None metrics as NaN)."""
    rows = [simulate(loop.replace(delay=float(d)), **kw).metrics for d in delays]
    return {m: np.array([math.nan if getattr(r, m) is None else getattr(r, m) for r in rows]) for m in METRICS}


def assert_same(a, b, tol):
    for m in METRICS:
        x, y = np.asarray(getattr(a, m) if not isinstance(a, dict) else a[m]), np.asarray(b[m])
        assert np.array_equal(np.isnan(x), np.isnan(y)), m
        assert np.max(np.abs(x - y), initial=0.0, where=~np.isnan(x)) <= tol, m


BATCH_LOOPS = [
    P_LOOP,
    P_LOOP.replace(period=0.065),
    Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), umin=-0.5, umax=2.0, output_delay=0.05),
    Loop("0.62/(15*s+1)", Controller.pi(2.0, 0.2), umin=-5, umax=5, period=0.1),
]


@pytest.mark.parametrize("loop", BATCH_LOOPS, ids=lambda lp: repr(lp)[:60])
def test_batched_metrics_equal_per_run_simulate(loop):
    # reference: simulate() called once per drawn delay (the anchor a user would write); it builds its own
    # parameter row per loop, so this checks the draws, the sweep of the delay and the plumbing of the metrics
    mc = monte_carlo(loop, DelayDistribution.uniform(0.1, 0.9), n=20, seed=5, t_end=12.0)
    assert mc.method == "batched" and mc.delays.shape == (20,) and mc.model_delay is None
    assert_same(mc, per_run(loop, mc.delays, t_end=12.0), 1e-9)


def test_batched_metrics_match_the_independent_reference_solver():
    # reference: tests/oracle_loop.py (SciPy DOP853 at rtol 1e-12 by the method of steps, sharing no code with
    # delaykit) on three of the drawn delays of the paper's P loop
    mc = monte_carlo(P_LOOP, DelayDistribution.uniform(0.3, 0.45), n=3, seed=8)
    for i, d in enumerate(mc.delays):
        ref = LoopOracle(LoopSpec(A=np.zeros((1, 1)), B=np.ones(1), C=np.ones(1), Ti=float(d), controller="p",
                                  kp=1.31, umin=-1.0, umax=1.0, t_end=15.0)).metrics()
        for m in METRICS:
            assert getattr(mc, m)[i] == pytest.approx(ref[m], abs=1e-8), m


def test_a_compensator_loop_draws_the_true_delay_and_keeps_the_model_delay():
    comp = Compensator.smith("1/s", model_delay=0.37, closed_loop_time=0.3)
    loop = Loop("1/s", comp, delay=0.37, umin=-1, umax=1)
    mc = monte_carlo(loop, DelayDistribution.normal(0.37, 0.08), n=12, seed=3, t_end=12.0)
    assert mc.method == "batched" and mc.model_delay == 0.37
    assert "compensator's model delay fixed at 0.37 s" in repr(mc) and mc.to_dict()["model_delay"] == 0.37
    # reference: simulate() per run on loop.replace(delay=d), whose compensator keeps its 0.37 s model
    assert all(loop.replace(delay=float(d)).controller.model_delay == 0.37 for d in mc.delays)
    assert_same(mc, per_run(loop, mc.delays, t_end=12.0), 1e-9)
    # and not the matched design (model delay = true delay), which differs wherever the delay is off 0.37 s
    matched = [simulate(Loop("1/s", comp.replace(model_delay=float(d)), delay=float(d), umin=-1, umax=1),
                        t_end=12.0).metrics.settling_time for d in mc.delays]
    assert np.max(np.abs(mc.settling_time - np.array(matched))) > 1e-3


def test_percentiles_are_numpys_and_seeds_reproduce():
    dist = DelayDistribution.uniform(0.3, 0.45)
    a = monte_carlo(P_LOOP, dist, n=40, seed=11, levels=(10.0, 50.0, 90.0))
    # reference for the draws: numpy's generator seeded the same way, drawn here
    assert np.array_equal(a.delays, np.random.default_rng(11).uniform(0.3, 0.45, 40))
    # reference for the percentiles: numpy's percentile of per-run simulate() values (computed independently of
    # the batch's arrays)
    ref = per_run(P_LOOP, a.delays)
    for m in METRICS:
        vals = ref[m][np.isfinite(ref[m])]
        got = a.percentiles(m)
        for p in (10.0, 50.0, 90.0):
            assert got[p] == pytest.approx(float(np.percentile(vals, p)), abs=1e-9)
    b = monte_carlo(P_LOOP, dist, n=40, seed=11, levels=(10.0, 50.0, 90.0))
    c = monte_carlo(P_LOOP, dist, n=40, seed=12, levels=(10.0, 50.0, 90.0))
    assert np.array_equal(a.delays, b.delays) and np.array_equal(a.overshoot, b.overshoot)
    assert not np.array_equal(a.delays, c.delays) and not np.array_equal(a.overshoot, c.overshoot)
    d = a.to_dict(arrays=True)
    assert d["method"] == "batched" and d["delay"] == {"kind": "uniform", "lo": 0.3, "hi": 0.45}
    assert d["percentiles"]["overshoot"]["p50"] == a.percentiles("overshoot")[50.0] and len(d["delays"]) == 40
    assert repr(a).startswith("MonteCarlo(40 runs, percentiles 10/50/90: overshoot ")
    assert repr(a).endswith("0 unsettled; method batched)") and "\n" not in repr(a)


def test_delays_beyond_the_stability_limit_are_counted_unsettled():
    # reference: the linear P loop on 1/s has the characteristic function s + kp exp(-s T), stable iff
    # kp T < pi / 2 (the crossover w = kp has phase -pi/2 - kp T), so T > pi / (2 * 1.31) = 1.199 s is unstable:
    # the saturated loop then oscillates in a limit cycle and never settles
    limit = math.pi / (2 * 1.31)
    mc = monte_carlo(P_LOOP, DelayDistribution.uniform(0.3, 1.6), n=60, seed=3, t_end=30.0)
    beyond = mc.delays > limit
    assert beyond.sum() >= 10
    assert np.all(np.isnan(mc.settling_time[beyond]))
    assert not np.any(np.isnan(mc.settling_time[mc.delays < 0.9]))  # well inside: settled within 30 s
    # the count: runs beyond the limit, plus stable ones too slow to settle within t_end (near the limit)
    assert mc.unsettled >= beyond.sum() and mc.unsettled == int(np.isnan(mc.settling_time).sum())
    assert f"{mc.unsettled} unsettled" in repr(mc) and mc.to_dict()["unsettled"] == mc.unsettled


def test_the_distributions_draw_what_they_say():
    n = 20000
    se = lambda sd: 5 * sd / math.sqrt(n)  # noqa: E731 (5 standard errors)
    u = DelayDistribution.uniform(0.3, 0.45).draw(n, rng=1)
    assert u.min() >= 0.3 and u.max() <= 0.45 and abs(u.mean() - 0.375) < se(0.15 / math.sqrt(12))
    # reference: scipy.stats.truncnorm, the normal truncated to [0, inf), its mean and standard deviation
    for mean, sd in ((0.35, 0.05), (0.05, 0.1), (-0.2, 0.1)):
        x = DelayDistribution.normal(mean, sd).draw(n, rng=2)
        ref = stats.truncnorm(-mean / sd, np.inf, loc=mean, scale=sd)
        assert x.min() >= 0.0 and abs(x.mean() - ref.mean()) < se(ref.std())
        assert abs(x.std() - ref.std()) < 0.05 * ref.std()
        assert stats.kstest(x, ref.cdf).pvalue > 1e-3
    # reference: scipy.stats.lognorm with s = sigma and scale = median
    g = DelayDistribution.lognormal(0.35, 0.2).draw(n, rng=3)
    assert stats.kstest(g, stats.lognorm(0.2, scale=0.35).cdf).pvalue > 1e-3
    assert DelayDistribution.normal(0.3, 0.0).draw(4, rng=0).tolist() == [0.3] * 4
    assert DelayDistribution.lognormal(0.3, 0.0).draw(3, rng=0) == pytest.approx([0.3] * 3)
    assert DelayDistribution.from_array([0.3, 0.1, 0.2]).draw().tolist() == [0.3, 0.1, 0.2]
    assert DelayDistribution.uniform(0.3, 0.45).bounds() == (0.3, 0.45)
    assert DelayDistribution.normal(0.35, 0.05).bounds() == (0.0, math.inf)
    assert DelayDistribution.from_array([0.3, 0.1]).bounds() == (0.1, 0.3)


def test_repr_to_dict_and_construction():
    cases = {
        DelayDistribution("uniform", lo=0.3, hi=0.45): "DelayDistribution(uniform 0.3 to 0.45 s)",
        DelayDistribution("normal", mean=0.35, sd=0.05): "DelayDistribution(normal mean 0.35 s, sd 0.05 s, "
                                                         "truncated at 0)",
        DelayDistribution("lognormal", median=0.35, sigma=0.2): "DelayDistribution(lognormal median 0.35 s, "
                                                                "sigma 0.2)",
        DelayDistribution("array", values=np.array([0.3, 0.4])): "DelayDistribution(array of 2 delays, 0.3 to "
                                                                 "0.4 s)",
    }
    for dist, text in cases.items():
        assert repr(dist) == text
        d = dist.to_dict()
        assert DelayDistribution(**d) == dist and json.loads(json.dumps(d)) == d
    assert DelayDistribution.uniform(0.3, 0.45) == DelayDistribution("uniform", lo=0.3, hi=0.45)
    assert DelayDistribution.normal(0.35, 0.05) == DelayDistribution("normal", mean=0.35, sd=0.05)
    assert DelayDistribution.lognormal(0.35, 0.2) == DelayDistribution("lognormal", median=0.35, sigma=0.2)
    with pytest.raises(TypeError):
        DelayDistribution("uniform", 0.3, 0.45)  # the parameters are keyword-only
    with pytest.raises(AttributeError):
        DelayDistribution.uniform(0.3, 0.45).lo = 0.1  # frozen
    assert delaykit.DelayDistribution is DelayDistribution and delaykit.monte_carlo is monte_carlo
    ds = importlib.import_module("delaykit.simulate")  # the subpackage (delaykit.simulate is the function)
    assert ds.MonteCarlo is MonteCarlo and "DelayDistribution" in ds.__all__


@pytest.mark.parametrize("kwargs, message", [
    (dict(kind="gamma", lo=0.1, hi=0.2), "kind must be one of uniform, normal, lognormal, array; got 'gamma'"),
    (dict(kind="uniform", lo=-0.1, hi=0.2), r"lo \(s\) must be at least 0, got -0.1"),
    (dict(kind="uniform", lo=0.5, hi=0.3), r"hi \(s\) must be at least lo = 0.5 s, got 0.3"),
    (dict(kind="uniform", lo=0.1, hi=math.inf), r"hi \(s\)"),
    (dict(kind="uniform", lo=0.1), "needs lo and hi; hi missing"),
    (dict(kind="uniform", lo=0.1, hi=0.2, sd=0.1), "takes lo and hi, not sd=0.1"),
    (dict(kind="normal", mean=0.35, sd=-0.05), r"sd \(s\) must be at least 0, got -0.05"),
    (dict(kind="normal", mean=-0.1, sd=0.0), r"mean \(s\) must be at least 0, got -0.1"),
    (dict(kind="normal", mean=-4.0, sd=0.1), r"mean \(s\) must be above -30 sd = -3 s .* got -4"),
    (dict(kind="normal", mean=math.nan, sd=0.1), r"mean \(s\)"),
    (dict(kind="lognormal", median=0.0, sigma=0.2), r"median \(s\) must be (greater than|above|more than) 0"),
    (dict(kind="lognormal", median=0.3, sigma=-1.0), r"sigma \(of ln delay\) must be at least 0, got -1"),
    (dict(kind="array", values=[0.3, -0.2]), r"values\[1\] must be a finite delay of at least 0 s, got -0.2"),
    (dict(kind="array", values=[0.3, math.inf]), r"values\[1\] must be a finite delay of at least 0 s, got inf"),
    (dict(kind="array", values=[]), "non-empty 1-D list of delays"),
    (dict(kind="array", values=[[0.3, 0.4]]), "non-empty 1-D list of delays"),
])
def test_bad_distribution_parameters_name_the_value(kwargs, message):
    with pytest.raises(InvalidValueError, match=message):
        DelayDistribution(**kwargs)


def test_bad_monte_carlo_settings():
    dist = DelayDistribution.uniform(0.3, 0.45)
    with pytest.raises(InvalidValueError, match="positive integer, got 0"):
        monte_carlo(P_LOOP, dist, n=0)
    with pytest.raises(InvalidValueError, match="must be None or 2 for an array of 2 delays"):
        monte_carlo(P_LOOP, DelayDistribution.from_array([0.3, 0.4]), n=5)
    assert monte_carlo(P_LOOP, DelayDistribution.from_array([0.3, 0.4])).runs == 2
    assert monte_carlo(P_LOOP, dist, seed=1).runs == 200
    with pytest.raises(InvalidTypeError, match="DelayDistribution.from_array"):
        monte_carlo(P_LOOP, np.array([0.3, 0.4]))
    with pytest.raises(InvalidTypeError, match="seed must be an integer"):
        monte_carlo(P_LOOP, dist, seed=1.5)
    with pytest.raises(InvalidValueError, match="t_end"):
        monte_carlo(P_LOOP, dist, n=3, t_end=-1.0)
    with pytest.raises(InvalidValueError, match="percentile level"):
        monte_carlo(P_LOOP, dist, n=3, levels=(50.0, 101.0))
    with pytest.raises(InvalidValueError, match="needs a sampled controller"):  # the event path needs a period
        monte_carlo(P_LOOP, Jitter(0.3, spread=0.1), n=2)
    with pytest.raises(InvalidValueError, match="metric must be one of"):
        monte_carlo(P_LOOP, dist, n=3).percentiles("peak")


def test_a_period_samples_the_batched_loop():
    # reference: per-run simulate() of the loop sampled every 65 ms
    mc = monte_carlo(P_LOOP, DelayDistribution.uniform(0.3, 0.45), n=6, seed=2, period=0.065)
    assert_same(mc, per_run(P_LOOP.replace(period=0.065), mc.delays), 1e-9)


# ---------------------------------------------------------------------- the per-packet (event) path, moved here
def test_monte_carlo_percentiles_and_reproducibility():
    loop = Loop("1/s", Controller.p(1.31), umin=-1, umax=1, period=0.065)
    # a jitter of zero spread: every run is the constant-delay loop, whose exact metrics come from simulate()
    flat = monte_carlo(loop, Jitter(0.3, spread=0.0), n=5, seed=1, t_end=8.0)
    exact = simulate(loop.replace(delay=0.3), t_end=8.0).metrics
    assert np.allclose(flat.overshoot, exact.overshoot, atol=1e-4)
    assert np.allclose(flat.settling_time, exact.settling_time, atol=1e-4)
    jit = Jitter(0.3, "exponential", scale=0.08)
    a = monte_carlo(loop, jit, n=24, seed=11, t_end=10.0, dt=0.02)
    b = monte_carlo(loop, jit, n=24, seed=11, t_end=10.0, dt=0.02)
    c = monte_carlo(loop, jit, n=24, seed=12, t_end=10.0, dt=0.02)
    assert isinstance(a, MonteCarlo) and np.array_equal(a.overshoot, b.overshoot)
    assert not np.array_equal(a.overshoot, c.overshoot)
    p = a.percentiles("overshoot")
    assert p[50.0] == pytest.approx(float(np.percentile(a.overshoot, 50)))
    assert p[5.0] <= p[50.0] <= p[95.0]
    # extra random delay on top of 0.3 s: the median overshoot exceeds the constant 0.3 s loop's (exact)
    assert p[50.0] > exact.overshoot
    d = a.to_dict()
    assert d["runs"] == 24 and set(d["percentiles"]) == {"overshoot", "peak_time", "rise_time", "settling_time"}
    assert d["method"] == "events" and d["delay"]["kind"] == "jitter" and a.delays is None
    assert repr(a).startswith("MonteCarlo(24 runs, percentiles 5/50/95: overshoot ")
    assert repr(a).endswith("; method events)")
    with pytest.raises(InvalidValueError, match="positive integer"):
        monte_carlo(loop, jit, n=0)


def test_a_number_or_a_schedule_takes_the_event_path():
    # a plain number is a constant per-packet delay (as before the batched path existed): the event simulation,
    # whose metrics equal the exact simulator's for a constant delay (reference: simulate(), tolerance as in
    # test_varying.py)
    loop = Loop("1/s", Controller.p(1.31), umin=-1, umax=1, period=0.065)
    for model in (0.3, DelaySchedule.constant(0.3)):
        mc = monte_carlo(loop, model, n=2, seed=0, t_end=8.0)
        assert mc.method == "events"
        assert mc.settling_time == pytest.approx([simulate(loop.replace(delay=0.3), t_end=8.0)
                                                  .metrics.settling_time] * 2, abs=1e-4)


def test_the_benchmark_runs_on_a_small_case(tmp_path):
    out = tmp_path / "mc.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_montecarlo.py"), "--runs", "30",
                    "--json", str(out)], check=True, capture_output=True, text=True)
    res = json.loads(out.read_text())
    assert res["runs"] == 30 and res["max_difference"] < 1e-9 and res["batched"]["method"] == "batched"
