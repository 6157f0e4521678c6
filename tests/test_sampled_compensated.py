"""The exact sampled model of loops with a delay compensator (a Smith predictor, the filtered Smith predictor,
predictor feedback), held commands and two delays: its poles, its frequency response and its margins.

References, none of which calls delaykit's sampled-loop modules:

* the simulator's own samples (an independent method, the method of steps on the continuous law with the held
  command), and the growth rate of its responses near a margin;
* the one-period transition matrix built in this file by integrating the plant and the compensator's ODEs
  (SciPy's DOP853 at rtol 1e-12) from every basis vector of the lifted state, with the plant realised by
  scipy.signal.tf2ss, the compensator's law from its matrices (:meth:`Compensator.realisation`), the plant's input
  scaled by a gain and delayed by the true delay, the model's input by the model's delay;
* the open loop of that brute-force matrix: with the loop broken at the plant's input,
  ``det(zI - Phi(g)) = det(zI - Phi(0)) (1 + g L(z))`` (a rank-one loop once the plant's held inputs are a second
  history, whose difference from ``g`` times the commands is a nilpotent shift), so
  ``L(z) = det(zI - Phi(1)) / det(zI - Phi(0)) - 1``;
* the closed form of the perfect-model Smith predictor with P control of ``1/s`` (derived below);
* the continuous loop's rightmost root and its exact compensated margins (delaykit.spectrum.compensated), the
  limits of the sampled loop as the period shrinks.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.signal import tf2ss
from typer.testing import CliRunner

from delaykit import InvalidValueError
from delaykit.models import Loop
from delaykit.models.compensators import Compensator
from delaykit.simulate.simulation import simulate
from delaykit.spectrum.compensated import compensated_margins
from delaykit.spectrum.frequency import margins as continuous_margins
from delaykit.spectrum.sampled import (compare_sampling, sampled_frequency_response, sampled_margins, sampled_model,
                                       sampled_response, sampled_spectrum)
from delaykit.spectrum.stability import rightmost

TM = 0.37
H = 0.065  # the paper's period: 0.37 = 5 h + 0.045


def comps() -> dict[str, Compensator]:
    return {"smith": Compensator.smith("1/s", TM, closed_loop_time=0.2),
            "filtered-smith": Compensator.filtered_smith("1/s", TM, closed_loop_time=0.3),
            "predictor": Compensator.predictor("1/s", TM, closed_loop_time=0.3),
            "smith-lag": Compensator.smith("2/(0.5*s+1)", TM, closed_loop_time=0.3)}


def plant_of(name: str) -> str:
    return "2/(0.5*s+1)" if name == "smith-lag" else "1/s"


# -- an independent construction of the transition matrix -------------------------------------------------------
def _split(T: float, h: float) -> tuple[int, float]:
    m = int(math.floor(T / h + 1e-9))
    f = T - m * h
    return (m, 0.0) if f < 1e-9 * h else (m, f)


def brute_phi(loop: Loop, gain: float = 1.0, extra: float = 0.0) -> np.ndarray:
    """Phi column by column, integrating the loop over one period from each basis vector of the lifted state.

    State ``[x(t_k), xc(t_k), u_{k-1}, ..., u_{k-p}]`` with ``p = max(m, mm) + 1``; the plant reads ``gain`` times
    ``u_{k-m-1}`` on ``[0, f)`` and ``u_{k-m}`` on ``[f, h)`` (true delay ``T + extra = m h + f``); the model reads
    ``u_k`` and, one model delay ``Tm = mm h + fm`` back, ``u_{k-mm-1}`` then ``u_{k-mm}``; the sample reads the
    measurement's left limit; ``u_k = Cc xc + dvy y`` (reference 0).
    """
    h = loop.period
    A, B, C, D = tf2ss(loop.plant.num, loop.plant.den)
    n = A.shape[0]
    B, C, D = gain * B.reshape(n), C.reshape(n), gain * float(np.squeeze(D))
    rz = loop.controller.realisation()
    assert not np.any(rz.Bcv) and rz.dvv == 0.0
    nc = rz.Ac.shape[0]
    bu = np.zeros(nc) if rz.Bcu is None else rz.Bcu
    bm = np.zeros(nc) if rz.Bcm is None else rz.Bcm
    m, f = _split(loop.total_delay + extra, h)
    mm, fm = _split(rz.model_delay, h)
    p = max(m, mm) + 1
    N = n + nc + p
    edges = sorted({0.0, f, fm, h})
    cols = []
    for i in range(N):
        e = np.eye(N)[i]
        x, xc, held = e[:n], e[n:n + nc], e[n + nc:]
        uk = float(rz.Cc @ xc + rz.dvy * (C @ x + D * held[m]))

        def cmd(j: int, uk: float = uk, held: np.ndarray = held) -> float:
            return uk if j == 0 else float(held[j - 1])

        s = np.r_[x, xc]
        for a, b in zip(edges[:-1], edges[1:]):
            w, ud = cmd(m + 1 if a < f else m), cmd(mm + 1 if a < fm else mm)

            def rhs(t, s, w=w, ud=ud, uk=uk):
                xx, cc = s[:n], s[n:]
                y = C @ xx + D * w
                return np.r_[A @ xx + B * w, rz.Ac @ cc + rz.Bcy * y + bu * uk + bm * ud]

            s = solve_ivp(rhs, (a, b), s, method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]
        cols.append(np.r_[s, uk, held[:p - 1]])
    return np.column_stack(cols)


def split_structural(Phi: np.ndarray, k: int) -> np.ndarray:
    """The eigenvalues of ``Phi`` without the ``k`` at 1 (checked to be within 1e-5 of 1, and every other one
    more than 1e-3 away, so that the split is unambiguous)."""
    z = np.linalg.eigvals(Phi)
    d = np.abs(z - 1.0)
    idx = np.argsort(d)[:k]
    assert np.all(d[idx] < 1e-5), np.sort(d)[:k + 1]
    rest = np.delete(z, idx)
    assert np.all(np.abs(rest - 1.0) > 1e-3)
    return rest


def loop_radius(Phi: np.ndarray, k: int) -> float:
    return float(np.max(np.abs(split_structural(Phi, k))))


# -- the poles ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("T", [0.37, 0.39, 0.45, 0.2])
def test_perfect_model_smith_predictor_has_the_delay_free_pole(T):
    # with the model's delay equal to the plant's the prediction is exact at the samples, so the sampled loop is
    # the delay-free one on 1/s: yp_{k+1} = yp_k + h Kc (r - yp_k), the pole 1 - Kc h (Kc = 5), the rest at 0
    c = Compensator.smith("1/s", T, closed_loop_time=0.2)
    spec = sampled_spectrum(Loop("1/s", c, delay=T, period=H))
    assert spec.radius == pytest.approx(1 - 5 * H, abs=1e-12)
    # the others are at 0 (the held commands' shift register: a nilpotent block, which rounding splits by about
    # eps^(1/size), so up to 1e-2 for the 8-long block here)
    assert np.sum(np.abs(spec.poles) > 0.02) == 1


CASES = [(name, ratio) for name in ("smith", "filtered-smith", "predictor", "smith-lag") for ratio in (1.0, 1.2, 0.8)]


@pytest.mark.parametrize("name, ratio", CASES)
def test_iterated_model_reproduces_the_simulated_samples(name, ratio):
    # z_{k+1} = Phi z_k + b_ref r from rest, a unit step at the first sample: y at the samples against the
    # simulator's (no limits: the linear loop), over 200 periods
    lp = Loop(plant_of(name), comps()[name], delay=ratio * TM, period=H)
    mdl = sampled_model(lp)
    C = lp.plant.state_space()[2]
    n = mdl.n_plant
    z = np.zeros(mdl.order)
    y = []
    for _ in range(200):
        y.append(float(C @ z[:n]))
        z = mdl.phi @ z + mdl.b_ref
    t = np.arange(200) * H
    ysim = simulate(lp, 1.0, t_end=200 * H + 1).output(t)
    scale = max(1.0, float(np.max(np.abs(ysim))))
    assert np.max(np.abs(np.array(y) - ysim)) < 1e-9 * scale


@pytest.mark.parametrize("name", ["smith", "filtered-smith", "predictor"])
def test_sampled_rate_tends_to_the_continuous_rightmost_root(name):
    # the hold lags by about h/2: first-order convergence in h to the continuous loop's rightmost root
    loop = Loop("1/s", comps()[name], delay=1.1 * TM)
    root = rightmost(loop).root
    err = [abs(sampled_spectrum(loop.replace(period=h)).rate - root) for h in (0.004, 0.002, 0.001)]
    assert err[-1] < 0.02
    assert 1.6 < err[0] / err[1] < 2.4 and 1.6 < err[1] / err[2] < 2.4


def test_an_unstable_mismatch_is_unstable_sampled_too():
    # the continuous Smith predictor with Kc = 5 loses stability near Td = Tm + 0.623 s (its delay margin); far
    # beyond it the sampled loop (small h) is unstable as well, and well inside stable
    c = comps()["smith"]
    assert not sampled_spectrum(Loop("1/s", c, delay=TM + 0.9, period=0.01)).stable
    assert sampled_spectrum(Loop("1/s", c, delay=TM + 0.3, period=0.01)).stable


FEEDTHROUGH = ("smith, plant with feedthrough", Loop("(0.2*s+2)/(0.5*s+1)", comps()["smith-lag"], delay=0.4,
                                                      period=H))
STRUCTURAL_CASES = [(f"{name} x{ratio}", Loop(plant_of(name), comps()[name], delay=ratio * TM, period=H))
                    for name in ("smith", "filtered-smith", "predictor") for ratio in (1.0, 1.25)]
STRUCTURAL_CASES += [("predictor without integral, x0.8",
                      Loop("1/s", Compensator.predictor("1/s", TM, closed_loop_time=0.3, integral_time=math.inf),
                           delay=0.8 * TM, period=H)), FEEDTHROUGH]


@pytest.mark.parametrize("name, loop", STRUCTURAL_CASES, ids=[c[0] for c in STRUCTURAL_CASES])
def test_structural_eigenvalues_stay_at_one_for_every_plant_gain_and_delay(name, loop):
    # the brute-force matrix with the plant's input scaled by g and extra true delay: exactly structural_zeros()
    # eigenvalues at 1 every time (split_structural checks that none other is near 1), and the library's poles are
    # the others: the same number, and the same polynomial prod (z - p) over those of modulus above 0.1 (the
    # shift register's zeros, which rounding splits by up to ~0.05, left out; the coefficients, not the poles, are
    # compared, as a perfect model makes multiple poles that rounding splits by ~1e-4)
    k = loop.controller.structural_zeros()
    for g in (0.4, 1.0, 2.5):
        for extra in (0.0, 0.2):
            ref = split_structural(brute_phi(loop, g, extra), k)
            got = sampled_model(loop.replace(delay=loop.delay + extra)).poles(g)
            assert got.size == ref.size
            a, b = np.poly(ref[np.abs(ref) > 0.1]), np.poly(got[np.abs(got) > 0.1])
            assert a.size == b.size and np.max(np.abs(a - b)) < 1e-8 * np.max(np.abs(a))


# -- the frequency response --------------------------------------------------------------------------------------
@pytest.mark.parametrize("T, h", [(0.37, H), (0.39, H), (0.03, H), (0.25, 0.1)])
def test_perfect_model_smith_predictor_response_closed_form(T, h):
    """P control (Kc = 5) of 1/s with the perfect model (Tm = T = m h + f), broken at the plant's input.

    Sampled at the held input, the plant with the delay is ``Hd_T(z) = ((h - f) z + f) / (z^(m+1) (z - 1))``
    (the input held f seconds from m + 1 samples back, then from m back) and without it ``Hd = h / (z - 1)``.
    The prediction is ``yp = Hd_T w + Hd u - Hd_T u`` (the measurement, plus the model run on the command minus
    the model run on the command one model delay back), the command ``u = -Kc yp``, so
    ``L = -u / w = Kc Hd_T / (1 + Kc Hd - Kc Hd_T)``; and ``1 + L = (1 + Kc Hd) / (1 + Kc Hd - Kc Hd_T)``,
    whose zero ``z = 1 - Kc h`` is the delay-free sampled loop's pole.
    """
    kc = 5.0
    lp = Loop("1/s", Compensator.smith("1/s", T, closed_loop_time=1 / kc), delay=T, period=h)
    m, f = _split(T, h)
    w = np.geomspace(1e-2, math.pi / h, 300)
    z = np.exp(1j * w * h)
    hd = h / (z - 1)
    hdt = ((h - f) * z + f) / (z ** (m + 1) * (z - 1))
    ref = kc * hdt / (1 + kc * hd - kc * hdt)
    got = sampled_frequency_response(lp, w)
    assert np.all(np.abs(got - ref) <= 1e-10 * np.abs(ref) + 1e-14)   # (f = h/2: L = 0 at z = -1)
    r = sampled_response(lp, w)
    assert np.allclose(r.L, ref, rtol=1e-10, atol=1e-14)


RESPONSE_CASES = [("filtered-smith x1.25", Loop("1/s", comps()["filtered-smith"], delay=1.25 * TM, period=H)),
                  ("predictor x0.8", Loop("1/s", comps()["predictor"], delay=0.8 * TM, period=H)),
                  ("smith x1.25", Loop("1/s", comps()["smith"], delay=1.25 * TM, period=H)),
                  ("smith-lag x1.25", Loop("2/(0.5*s+1)", comps()["smith-lag"], delay=1.25 * TM, period=H)),
                  FEEDTHROUGH]


@pytest.mark.parametrize("name, loop", RESPONSE_CASES, ids=[c[0] for c in RESPONSE_CASES])
def test_response_matches_the_brute_force_open_loop(name, loop):
    # L(z) = det(zI - Phi(1)) / det(zI - Phi(0)) - 1 from the brute-force matrices (see the module docstring)
    P1, P0 = brute_phi(loop, 1.0), brute_phi(loop, 0.0)
    w = np.geomspace(0.3, 0.95 * math.pi / H, 25)
    ref = []
    for x in w:
        z = np.exp(1j * x * H)
        eye = np.eye(P1.shape[0])
        ref.append(np.linalg.det(z * eye - P1) / np.linalg.det(z * eye - P0) - 1.0)
    got = sampled_frequency_response(loop, w)
    assert np.max(np.abs(got - np.array(ref)) / np.abs(ref)) < 1e-7


# -- the margins -------------------------------------------------------------------------------------------------
MARGIN_CASES = [(name, ratio) for name in ("smith", "filtered-smith", "predictor") for ratio in (1.0, 1.25)]


@pytest.mark.parametrize("name, ratio", MARGIN_CASES)
def test_margins_put_a_brute_force_pole_on_the_unit_circle(name, ratio):
    # the plant's input scaled by the gain margin, or the true delay raised by the delay margin (the model's
    # unchanged), puts the brute-force matrix's largest pole (the compensator's structural ones at 1 aside) on the
    # unit circle; 0.99 and 1.01 of either margin fall on either side
    loop = Loop("1/s", comps()[name], delay=ratio * TM, period=H)
    k = loop.controller.structural_zeros()
    mg = sampled_margins(loop)
    assert mg.stable and loop_radius(brute_phi(loop), k) < 1.0
    gm, dm = mg.gain_margin, mg.delay_margin
    assert abs(loop_radius(brute_phi(loop, gm), k) - 1.0) < 1e-8
    assert loop_radius(brute_phi(loop, 0.99 * gm), k) < 1.0 < loop_radius(brute_phi(loop, 1.01 * gm), k)
    assert abs(loop_radius(brute_phi(loop, extra=dm), k) - 1.0) < 1e-8
    assert loop_radius(brute_phi(loop, extra=0.99 * dm), k) < 1.0 < loop_radius(brute_phi(loop, extra=1.01 * dm), k)
    # the critical delay is the true delay there, the model's delay unchanged
    assert mg.critical_delay == pytest.approx(ratio * TM + dm, abs=1e-12)


@pytest.mark.parametrize("name", ["smith", "predictor"])
def test_margins_against_the_simulated_growth(name):
    # the simulator (method of steps) with the plant 0.99 / 1.01 gm / s (the model still 1/s), or the true delay
    # 0.99 / 1.01 of the way to the critical delay: the error of the step response shrinks or grows at the rate
    # log(radius) / h of the sampled model (measured by a log-linear fit of the error's peaks per 3 s window)
    loop = Loop("1/s", comps()[name], delay=1.25 * TM, period=H)
    mg = sampled_margins(loop)
    c = loop.controller
    for factor in (0.99, 1.01):
        for lp in (Loop(f"{factor * mg.gain_margin!r}/s", c, delay=loop.delay, period=H),
                   loop.replace(delay=loop.delay + factor * mg.delay_margin)):
            t_end = 60.0
            tk = np.arange(int(t_end / H)) * H
            err = np.abs(simulate(lp, 1.0, t_end=t_end).output(tk) - 1.0)
            win = int(round(3.0 / H))
            starts = np.arange(0, tk.size - win, win)
            peaks = np.array([err[i:i + win].max() for i in starts])
            late = tk[starts] > 15.0  # the faster modes gone
            rate = np.polyfit(tk[starts][late], np.log(peaks[late]), 1)[0]
            predicted = math.log(sampled_model(lp).radius()) / H
            assert np.sign(rate) == np.sign(factor - 1.0)
            assert rate == pytest.approx(predicted, rel=0.1)


@pytest.mark.parametrize("name, ratio", [("smith", 1.0), ("filtered-smith", 1.25)])
def test_sampled_margins_tend_to_the_continuous_compensated_margins(name, ratio):
    # the continuous compensated margins (L = A2 exp(-sT) / (A0 + A1 exp(-s Tm)), exact) are the limit as h -> 0,
    # at first order: halving h halves the gap of the gain, phase and delay margins
    loop = Loop("1/s", comps()[name], delay=ratio * TM)
    ref = compensated_margins(loop)
    errs = []
    for h in (0.04, 0.02, 0.01):
        mg = sampled_margins(loop.replace(period=h))
        errs.append(np.array([mg.gain_margin - ref.gain_margin, mg.phase_margin - ref.phase_margin,
                              mg.delay_margin - ref.delay_margin]))
    assert np.all(np.abs(errs[-1]) < [0.02 * ref.gain_margin, 0.25, 0.01 * ref.delay_margin])
    for a, b in zip(errs[:-1], errs[1:]):
        assert np.all((1.7 < a / b) & (a / b < 2.3))


@pytest.mark.parametrize("name, ratio", MARGIN_CASES)
def test_margins_and_comparison_are_finite_and_consistent(name, ratio):
    loop = Loop("1/s", comps()[name], delay=ratio * TM, period=H)
    mg = sampled_margins(loop)
    assert mg.stable and 1.0 < mg.gain_margin < 10.0 and 0.0 < mg.delay_margin < 1.0
    assert math.isfinite(mg.phase_margin) and mg.lower_gain_margin == 0.0   # integrators: no lower margin
    assert mg.critical_delay == pytest.approx(loop.total_delay + mg.delay_margin, abs=1e-12)
    # the gain margin is 1/|L| at its phase crossover, where L is real and negative; |L| = 1 at every gain crossover
    L = sampled_frequency_response(loop, mg.phase_crossover)
    assert L.real < 0 and abs(L.imag) < 1e-9 * abs(L) and 1 / abs(L) == pytest.approx(mg.gain_margin, rel=1e-9)
    assert np.allclose(np.abs(sampled_frequency_response(loop, np.array(mg.gain_crossovers))), 1.0, rtol=1e-9)
    # beside the continuous loop: its margins are the exact compensated ones, and the hold loses some of each
    c = compare_sampling(loop)
    cont = continuous_margins(loop.replace(period=None))
    assert c.continuous_delay_margin == pytest.approx(cont.delay_margin, rel=1e-12)
    assert c.continuous_critical_delay == pytest.approx(loop.total_delay + cont.delay_margin, rel=1e-12)
    assert c.sampled.delay_margin == pytest.approx(mg.delay_margin, rel=1e-12)
    assert c.sampled.gain_margin == pytest.approx(mg.gain_margin, rel=1e-12)
    assert c.radius == pytest.approx(sampled_spectrum(loop).radius, rel=1e-12)
    assert c.abscissa == pytest.approx(rightmost(loop.replace(period=None)).abscissa, abs=1e-12)
    assert c.continuous_stable and c.sampled.stable
    assert 0.0 < c.delay_margin_lost < 2 * H and mg.gain_margin < cont.gain_margin
    json.dumps(c.to_dict(), allow_nan=False)
    json.dumps(mg.to_dict(), allow_nan=False)


def test_an_unstable_sampled_compensated_loop_has_no_margins():
    mg = sampled_margins(Loop("1/s", comps()["smith"], delay=TM + 0.9, period=0.05))
    assert not mg.stable and math.isnan(mg.gain_margin) and math.isnan(mg.delay_margin)
    assert mg.to_dict()["delay_margin"] is None and mg.crossovers


def test_bad_input_is_refused_clearly():
    cont = Loop("1/s", comps()["smith"], delay=TM)
    for fn in (sampled_margins, compare_sampling, sampled_response, lambda lp: sampled_frequency_response(lp, 1.0)):
        with pytest.raises(InvalidValueError, match="needs a sampled loop"):
            fn(cont)
    lp = cont.replace(period=H)
    for bad in (0.0, -1.0, 2 * math.pi / H, math.nan):
        with pytest.raises(InvalidValueError, match="w must"):
            sampled_frequency_response(lp, bad)
    with pytest.raises(InvalidValueError, match="sampled_margins"):
        compensated_margins(lp)   # the continuous analysis points to the sampled one
    with pytest.raises(InvalidValueError, match="lifted state"):
        sampled_margins(Loop("1/s", Compensator.smith("1/s", 10.0), delay=10.0, period=0.001))


def test_margins_and_roots_from_the_command_line():
    from delaykit.cli import app
    from delaykit.design.compensators import tune_compensator

    def run(*args):
        res = CliRunner().invoke(app, [*args, "--controller", "smith", "--delay", "0.37", "--model-delay", "0.37",
                                       "--closed-loop-time", "0.2", "--period", "0.065", "--json"])
        assert res.exit_code == 0, res.output
        return json.loads(res.stdout)

    lp = Loop("1/s", tune_compensator("smith", "1/s", 0.37, closed_loop_time=0.2), delay=0.37, umin=-1, umax=1,
              period=H)
    got = run("margins")
    ref = sampled_margins(lp)
    assert got["gain_margin"] == pytest.approx(ref.gain_margin, rel=1e-12)
    assert got["delay_margin"] == pytest.approx(ref.delay_margin, rel=1e-12)
    assert got["sampled"] is True and got["radius"] == pytest.approx(sampled_spectrum(lp).radius, rel=1e-12)
    assert run("roots")["radius"] == pytest.approx(sampled_spectrum(lp).radius, rel=1e-12)
