"""Honest intervals for the identified delay when two outputs share a coloured disturbance (issue #10).

In closed loop the controller turns an altitude wander into the commanded speed, so the residuals of the altitude
and of its rate are one disturbance seen twice.  The covariance describes the pair jointly (a vector
autoregressive model, :func:`delaykit.identify.noise.fit_var`); describing each output alone, as before, made the
intervals too narrow.  References: the exact covariance of a stationary VAR(1) (closed form: the Lyapunov
equation and powers of its matrix), and the known truth of synthetic closed-loop logs with a binomial tolerance.
The emulated demo flights themselves are in benchmarks/bench_identify_coverage.py (200 flights).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import linalg, stats

from delaykit.errors import InvalidValueError
from delaykit.identify import Experiment, identify
from delaykit.identify.noise import VARNoise, ar_covariance, fit_ar, fit_var
from delaykit.models.controllers import Controller
from delaykit.models.loop import Loop
from delaykit.models.transfer import TransferFunction
from delaykit.simulate.discrete import closed_loop_response, held_delay_model

H = 1.0 / 15  # the emulator's navdata period (s)
WANDER, WANDER_TIME = 0.007, 2.0  # the emulator's hover wander: 7 mm RMS, 2 s correlation time


def _var1_exact(phi: np.ndarray, sigma: np.ndarray, n: int) -> np.ndarray:
    """Covariance of ``n`` stacked samples (time-major) of the stationary VAR(1) ``x[k] = phi x[k-1] + e[k]``:
    ``G0 = phi G0 phi' + sigma`` (Lyapunov), ``E[x[k+j] x[k]'] = phi^j G0``."""
    d = sigma.shape[0]
    g = [linalg.solve_discrete_lyapunov(phi, sigma)]
    for _ in range(1, n):
        g.append(phi @ g[-1])
    R = np.empty((n * d, n * d))
    for i in range(n):
        for j in range(n):
            R[i * d:(i + 1) * d, j * d:(j + 1) * d] = g[i - j] if i >= j else g[j - i].T
    return R


def test_joint_covariance_equals_the_closed_form_of_a_var1():
    # two series driven by one slow disturbance: the second is the first one sample late and scaled (phi's
    # lower-left entry), plus a little of its own
    n = 400
    phi = np.array([[0.95, 0.0], [0.8, 0.0]])
    sigma = np.array([[1.0, 0.0], [0.0, 0.05]])
    t = np.arange(n) / n
    J = np.stack([np.column_stack([np.sin(6 * t), t]), np.column_stack([np.sin(6 * t - 0.3), 0.5 * t])], axis=1)
    Jf = J.reshape(n * 2, 2)  # rows (k, series): the stacking of _var1_exact
    R = _var1_exact(phi, sigma, n)
    Hi = np.linalg.inv(Jf.T @ Jf)
    exact = Hi @ (Jf.T @ R @ Jf) @ Hi
    mine = ar_covariance([(J, VARNoise(phi[None], sigma, n))])
    # the formula starts the disturbance at rest, not stationary: a start-up term, 0.3 % here
    np.testing.assert_allclose(mine, exact, rtol=0.01)
    # what treating the two series as independent gives (the exact variances of each, cross terms dropped): 0.52
    # of the exact variance
    Ra = R.copy()
    Ra[0::2, 1::2] = 0.0
    Ra[1::2, 0::2] = 0.0
    apart = Hi @ (Jf.T @ Ra @ Jf) @ Hi
    assert apart[0, 0] < 0.7 * exact[0, 0]


def test_fit_var_recovers_a_var1_and_refuses_bad_input():
    rng = np.random.default_rng(5)
    phi = np.array([[0.9, 0.0], [0.6, 0.3]])
    n = 20000
    e = rng.standard_normal((n, 2)) @ np.diag([1.0, 0.5])
    x = np.zeros((n, 2))
    for k in range(1, n):
        x[k] = phi @ x[k - 1] + e[k]
    m = fit_var(x)
    assert m.order == 1
    np.testing.assert_allclose(m.phi[0], phi, atol=0.02)  # (standard errors ~ 1/sqrt(n) = 0.007)
    np.testing.assert_allclose(m.sigma, np.diag([1.0, 0.25]), atol=0.03)
    # one series: the same model as fit_ar's (scalar Yule-Walker, BIC)
    one = fit_var(x[:3000, :1])
    np.testing.assert_allclose(-one.phi[:, 0, 0], fit_ar(x[:3000, 0]).coeffs[1:], atol=1e-12)
    with pytest.raises(InvalidValueError, match="finite"):
        fit_var(np.array([[0.0, np.nan]] * 30))
    with pytest.raises(InvalidValueError, match=r"\(n, d\)"):
        fit_var(np.zeros(30))
    with pytest.raises(InvalidValueError, match="2 series"):
        ar_covariance([(np.zeros((30, 2)), VARNoise(np.zeros((0, 2, 2)), np.eye(2), 30))])


def _wander_log(seed: int, n: int = 900) -> Experiment:
    """A closed-loop altitude log on the emulator's clock: the plant 1/(s (1.0 s + 1)) behind 0.30 s of delay,
    P control (Kp 0.8, ±1 m/s), steps of ±1 m every 7 s; the altitude carries an Ornstein-Uhlenbeck wander (AR(1)
    at the sample rate, 7 mm, 2 s) that the controller sees, plus 1 mm of white noise; the logged rate is the
    plant's (the wander reaches it only through the controller, as on the emulator)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * H
    r = np.zeros(n)
    for i in range(int(t[-1] // 7)):
        r[t >= 1.0 + 7 * i] += (-1.0) ** i
    a = math.exp(-H / WANDER_TIME)
    w = np.empty(n)
    w[0] = rng.normal(0.0, WANDER)
    for k in range(1, n):
        w[k] = a * w[k - 1] + rng.normal(0.0, WANDER * math.sqrt(1.0 - a * a))
    model = held_delay_model(TransferFunction.parse("1/(s*(1.0*s+1))"), H, 0.30)
    # the controller acts on z + w: the same as the reference r - w on the plant's own altitude
    res = closed_loop_response(model, r - w, kp=0.8, umin=-1.0, umax=1.0)
    z = 0.8 + res.y + w + rng.normal(0.0, 0.001, n)
    return Experiment.from_arrays(t, {"z": z, "vz": res.dy}, r=0.8 + r, name=f"wander-{seed}")


def test_delay_intervals_cover_the_truth_when_altitude_and_rate_share_a_wander():
    # 100 logs of 60 s; an honest 95 % interval misses Binomial(100, 0.05) times: more than 11 misses has
    # probability 0.4 %.  The old covariance (each output's residuals described alone) missed 15 of these 100 and
    # its standard errors were 0.74 of the estimates' actual spread (RMS error about the truth); now 8 misses and
    # 0.97.
    loop = Loop("1/s", Controller.p(0.8), umin=-1.0, umax=1.0, period=H)
    err, se, misses = [], [], 0
    for seed in range(100):
        m = identify(_wander_log(seed), model="ipdt_lag", loop=loop, outputs="z", rate="vz", baseline="fit",
                     per_log=False)
        lo, hi = m.ci["delay"]
        misses += not lo <= 0.30 <= hi
        err.append(m.delay - 0.30)
        se.append(m.stderr["delay"])
    limit = int(stats.binom.isf(0.005, 100, 0.05))
    assert misses <= limit, (misses, limit)
    # the spread of 100 estimates about the truth against the mean reported error: the RMS of 100 normal draws
    # about their mean is within 0.83 to 1.18 of their standard deviation with probability 99 % (chi-square)
    ratio = math.sqrt(np.mean(np.square(err))) / float(np.mean(se))
    lo_r, hi_r = (math.sqrt(stats.chi2.ppf(q, 100) / 100) for q in (0.005, 0.995))
    assert lo_r < ratio < hi_r, (ratio, lo_r, hi_r)
