"""The jitter margin (delaykit.spectrum.jitter): against dense brute-force grids, against the constant-delay margin
(a theorem), and in the time domain with the varying-delay simulator: random and worst-case switching inside
the margin decays; a documented switching delay inside the constant-delay-stable range diverges."""

from __future__ import annotations

import math

import numpy as np
import pytest

from delaykit import AltitudeLoop, InvalidValueError, margins
from delaykit.models import Controller, Loop
from delaykit.simulate.varying import DelaySchedule, Jitter, simulate_varying
from delaykit.spectrum.jitter import JitterMargin, jitter_bound, jitter_margin, stable_for
from delaykit.spectrum.sampled import sampled_spectrum


@pytest.mark.parametrize("kp, T", [(1.31, 0.368), (2.0, 0.37), (1.0, 0.5), (0.5, 1.2), (3.0, 0.05)])
def test_integrator_loop_against_a_dense_grid(kp, T):
    # L = kp e^{-sT} / s, so |1 + L|^2 / (w |L|)^2 = (w^2 + kp^2 - 2 kp w sin(w T)) / (kp w)^2: its minimum on
    # 4 million frequencies up to 400 / T, refined by nothing (the grid is the reference)
    w = np.linspace(1e-3, 400.0 / T, 4_000_001)
    g = np.sqrt(w**2 + kp**2 - 2 * kp * w * np.sin(w * T)) / (kp * w)
    i = int(np.argmin(g))
    jm = jitter_margin(AltitudeLoop(kp=kp, delay=T, vmax=None))
    assert jm.margin <= g[i] + 1e-12 and jm.margin == pytest.approx(g[i], rel=1e-7)
    assert jm.frequency == pytest.approx(w[i], abs=2 * (w[1] - w[0]))
    assert jm.margin < 1.0 / kp  # below the limit at high frequency when T > 0
    assert jm.nominal_delay == T


def test_a_general_loop_against_a_dense_grid():
    # PD on 1/(s (0.5 s + 1)) with the derivative filter Tf: L written out here by hand, evaluated on a dense grid
    kp, kd, tf, T = 2.0, 0.4, 0.05, 0.2
    loop = Loop("1/(s*(0.5*s+1))", Controller.pd(kp, kd, tf), delay=T)
    w = np.geomspace(1e-3, 2e3, 3_000_001)
    s = 1j * w
    L = (kp + kd * s / (tf * s + 1)) / (s * (0.5 * s + 1)) * np.exp(-s * T)
    g = np.abs(1 + L) / (w * np.abs(L))
    jm = jitter_margin(loop)
    assert jm.margin == pytest.approx(g.min(), rel=1e-6) and jm.margin <= g.min() + 1e-12
    assert np.allclose(jitter_bound(loop, w[::1000]), g[::1000], rtol=1e-12)


LOOPS = [
    AltitudeLoop(kp=1.31, delay=0.368),
    AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered"),
    Loop("1/s", Controller.pi(1.0, 0.2), delay=0.2, output_delay=0.15),
    Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02), delay=12.0),
    Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2),
    Loop("1/(s-1)", Controller.p(2.0), delay=0.1),
]


@pytest.mark.parametrize("loop", LOOPS, ids=lambda lp: repr(lp)[:50])
def test_the_jitter_margin_never_exceeds_the_constant_delay_margin(loop):
    # a constant extra delay is one admissible variation, so J <= DM (a theorem; the module docstring proves it);
    # the constant-delay margin is delaykit's margins(), computed from the gain crossovers
    jm = jitter_margin(loop)
    dm = margins(loop).delay_margin
    assert jm.delay_margin == dm
    assert 0.0 < jm.margin <= dm
    d = jm.to_dict()
    assert d["margin"] == jm.margin and d["nominal_delay"] == pytest.approx(jm.nominal_delay)
    assert repr(jm).startswith("JitterMargin(")


def test_limits_at_high_frequency():
    # T = 0: |j w + kp| / (kp w) decreases towards 1/kp, never reached (the infimum is the limit)
    jm = jitter_margin(AltitudeLoop(kp=2.0, delay=0.0, vmax=None))
    assert jm.margin == 0.5 and math.isinf(jm.frequency)
    assert isinstance(jm, JitterMargin) and jm.guaranteed == (0.0, 0.5)
    # the PV law with the true velocity: L = (kv s + kp) e^{-sT} / s is biproper, |L(j inf)| = kv > 0, so the
    # bound |1 + L| / (w |L|) falls to 0: no variation at all is guaranteed
    pv = jitter_margin(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3))
    assert pv.margin == 0.0 and pv.delay_margin > 0.4


def test_stable_for_and_bad_input():
    loop = AltitudeLoop(kp=1.31, delay=0.1)
    m = jitter_margin(loop.replace(delay=0.3)).margin  # the nominal loop at tmin = 0.3
    assert stable_for(loop, 0.3, 0.3 + 0.99 * m) and not stable_for(loop, 0.3, 0.3 + 1.01 * m)
    assert stable_for(loop, 1.0, 1.0)  # constant 1.0 s < pi / (2 kp) = 1.199 s: stable
    assert not stable_for(loop, 1.25, 1.3)  # the nominal loop is unstable: nothing to keep
    with pytest.raises(InvalidValueError, match="unstable with its constant delay 1.25 s"):
        jitter_margin(loop.replace(delay=1.25))
    with pytest.raises(InvalidValueError, match="tmax must be at least tmin"):
        stable_for(loop, 0.5, 0.4)
    with pytest.raises(InvalidValueError, match="tmin \\(smallest delay, s\\) must be at least 0, got -0.1"):
        stable_for(loop, -0.1, 0.4)
    with pytest.raises(InvalidValueError, match="sampled"):
        jitter_margin(loop.replace(period=0.065))
    with pytest.raises(InvalidValueError, match="above 0"):
        jitter_bound(loop, [0.0, 1.0])


def _adversary(kp: float, h: float, m_min: int, m_max: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The worst packet choice for the integrator under P control, as a recursion written here: after each sample
    the plant applies the past command (among those 'm_min' to 'm_max' periods old and no older than the one it
    holds) that drives the error hardest in its current direction, switching direction only when no command
    left does.  The error obeys e[k+1] = e[k] - h kp e[j[k]] (exact for y' = u with the command held).
    Returns the error at the samples and the applied index per period (-1: none yet)."""
    e = np.zeros(n + 1)
    e[0] = 1.0
    j, s = -1, -1.0
    js = np.full(n, -1)
    for k in range(n):
        hi = k - m_min
        if hi >= 0:
            cand = np.arange(max(j, k - m_max, 0), hi + 1)
            push = cand * 0.0 - s * kp * e[cand]  # e' = -kp e[j]: its component along the direction s
            if push.max() <= 0:
                s = -s
                push = -push
            j = int(cand[np.argmax(push)])
        js[k] = j
        e[k + 1] = e[k] - h * kp * (e[j] if j >= 0 else 0.0)
    return e, js


def _replay(js: np.ndarray, h: float, m_max: int) -> DelaySchedule:
    """Per-packet delays that make a receiver that keeps the newest packet apply js[k] during period k: a packet
    arrives when it is first applied; one never applied arrives m_max periods late, when it is already stale."""
    n = js.size
    d = np.full(n, m_max * h)
    for k in range(n):
        i = js[k]
        if i >= 0 and (k == 0 or js[k - 1] != i):
            d[i] = (k - i) * h
    return DelaySchedule(np.arange(n) * h - h / 2, d)


def test_random_switching_inside_the_margin_stays_bounded():
    # P on the integrator, kp = 1.31, packets every h = 10 ms with delays uniform in [Tmin, Tmin + 0.9 J - h]: a
    # held command is the continuous law delayed by its packet's delay plus the time since it was sent (< h), so
    # the continuous delay stays in [Tmin, Tmin + 0.9 J]: Kao and Lincoln guarantee stability
    kp, tmin, h = 1.31, 0.3, 0.01
    jm = jitter_margin(AltitudeLoop(kp=kp, delay=tmin, vmax=None))
    loop = Loop("1/s", Controller.p(kp), period=h)
    for seed in (1, 2, 3):
        r = simulate_varying(loop, Jitter(tmin, "uniform", spread=0.9 * jm.margin - h, seed=seed), t_end=40.0)
        assert r.delays.min() >= tmin and r.delays.max() <= tmin + 0.9 * jm.margin
        assert np.max(np.abs(r.output)) < 2.0 and np.max(np.abs(r.output[r.t > 30] - 1.0)) < 1e-3


def test_worst_case_switching_inside_the_margin_decays():
    # the adversary of _adversary, restricted to [Tmin, Tmin + 0.9 J - h], replayed through the simulator
    kp, tmin, h = 1.31, 0.3, 0.01
    jm = jitter_margin(AltitudeLoop(kp=kp, delay=tmin, vmax=None))
    m_min, m_max = round(tmin / h), int((tmin + 0.9 * jm.margin - h) / h)
    e, js = _adversary(kp, h, m_min, m_max, 4000)
    r = simulate_varying(Loop("1/s", Controller.p(kp), period=h), _replay(js, h, m_max), t_end=40.0)
    k = np.rint(r.t / h).astype(int)
    on = np.abs(r.t - k * h) < 1e-9
    assert np.max(np.abs((1.0 - r.output[on]) - e[k[on]])) < 1e-9  # the simulator replays the recursion
    assert np.max(np.abs(e[3000:])) < 1e-3 * np.max(np.abs(e[:1000]))


def test_fast_switching_inside_the_constant_delay_stable_range_destabilises():
    # documented example: kp = 1, no minimum delay, packet delays in [0, 1.55] s every 10 ms.  Every constant
    # delay there is stable (the exact sampled spectrum: radius < 1; continuous critical delay pi/2 = 1.571 s),
    # and the jitter margin is only 1/kp = 1 s.  The adversary's switching (Myshkis' 3/2 bound is sharp:
    # kp (Tmax + h) = 1.56 > 3/2) makes the oscillation grow.
    kp, h, tmax = 1.0, 0.01, 1.55
    loop = Loop("1/s", Controller.p(kp), period=h)
    for d in np.linspace(0.0, tmax, 12):
        assert sampled_spectrum(loop.replace(delay=float(d))).stable
    assert jitter_margin(AltitudeLoop(kp=kp, delay=0.0, vmax=None)).margin == pytest.approx(1.0)
    m_max = round(tmax / h)
    e, js = _adversary(kp, h, 0, m_max, 8000)
    sched = _replay(js, h, m_max)
    r = simulate_varying(loop, sched, t_end=80.0)
    assert r.delays.min() >= 0.0 and r.delays.max() <= tmax + 1e-12
    err = 1.0 - r.output
    assert np.max(np.abs(err[r.t > 70])) > 3.0 * np.max(np.abs(err[(r.t > 5) & (r.t < 15)]))
    k = np.rint(r.t / h).astype(int)
    on = np.abs(r.t - k * h) < 1e-9
    assert np.max(np.abs(err[on] - e[k[on]])) < 1e-8 * np.max(np.abs(e))
