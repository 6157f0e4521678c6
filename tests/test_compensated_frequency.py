"""Frequency response, margins and jitter margin of loops with a delay-compensating controller.

The references are independent of delaykit.spectrum.compensated: closed forms (the Smith predictor with a
perfect model), the controller's state-space realisation evaluated by a linear solve at each frequency (not the
characteristic polynomials the module uses), brute-force grids a thousand times finer, the certified root
finder on the characteristic quasi-polynomial (a margin must put a root on the imaginary axis), and the design
module's delay-ratio range (a bisection on the rightmost root).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from delaykit import InvalidValueError
from delaykit.design.compensators import delay_ratio_range
from delaykit.models import Loop
from delaykit.models.compensators import Compensator
from delaykit.spectrum.frequency import frequency_response, margins
from delaykit.spectrum.jitter import jitter_bound, jitter_margin, stable_for
from delaykit.spectrum.roots import find_roots, root_bound
from delaykit.spectrum.stability import rightmost

TM = 0.37


def designs() -> dict[str, Compensator]:
    return {"smith": Compensator.smith("1/s", TM, closed_loop_time=0.2),
            "filtered-smith": Compensator.filtered_smith("1/s", TM, closed_loop_time=0.2),
            "predictor": Compensator.predictor("1/s", TM, closed_loop_time=0.2),
            "smith-pi-lag": Compensator.smith("2/(0.5*s+1)", TM, closed_loop_time=0.3)}


def plant_of(name: str) -> str:
    return "2/(0.5*s+1)" if name == "smith-pi-lag" else "1/s"


def realisation_L(loop: Loop, w: np.ndarray) -> np.ndarray:
    """-Gy P e^{-sT} / (1 - Gu - Gm e^{-sTm}) from the realisation's matrices, one linear solve per frequency."""
    rz = loop.controller.realisation()
    n = rz.order
    out = []
    for x in w:
        s = 1j * x
        M = s * np.eye(n) - rz.Ac
        gy = rz.Cc @ np.linalg.solve(M, rz.Bcy) + rz.dvy
        gu = rz.Cc @ np.linalg.solve(M, rz.Bcu)
        gm = rz.Cc @ np.linalg.solve(M, rz.Bcm)
        p = np.polyval(loop.plant.num, s) / np.polyval(loop.plant.den, s) * np.exp(-s * loop.total_delay)
        out.append(-gy * p / (1.0 - gu - gm * np.exp(-s * loop.controller.model_delay)))
    return np.array(out)


def test_perfect_model_smith_predictor_matches_its_closed_form():
    # Kc = 1/Tc = 5 on 1/s with a perfect model: L = 5 e^{-sT} / (s + 5 - 5 e^{-sT}), so 1 + L = (s + 5) / (s + 5 -
    # 5 e^{-sT}): the closed loop is the delay-free first-order loop, delayed
    loop = Loop("1/s", designs()["smith"], delay=TM)
    w = np.geomspace(1e-3, 300.0, 4001)
    s = 1j * w
    closed = 5 * np.exp(-s * TM) / (s + 5 - 5 * np.exp(-s * TM))
    r = frequency_response(loop, w)
    assert np.max(np.abs(r.L - closed) / np.abs(closed)) < 1e-11
    # the unwrapped phase: -90 degrees at w -> 0 (one integrator), then continuous; modulo 360 it is angle(L)
    # (the reference: the closed form's angle unwrapped on a grid 100 times finer, whose steps are below 0.2 deg)
    fine = np.geomspace(1e-3, 300.0, 400_001)
    sf = 1j * fine
    ref = np.degrees(np.unwrap(np.angle(5 * np.exp(-sf * TM) / (sf + 5 - 5 * np.exp(-sf * TM)))))
    assert abs(ref[0] + 90.0) < 0.1
    assert np.max(np.abs(r.phase_deg - ref[::100])) < 1e-8


@pytest.mark.parametrize("name", ["smith", "filtered-smith", "predictor", "smith-pi-lag"])
def test_L_agrees_with_the_realisation_evaluated_by_linear_solves(name):
    # the module builds L from the characteristic polynomials (structural roots divided out); the reference
    # solves the controller's state equations at each frequency, with a true delay 10 % longer than the model's
    loop = Loop(plant_of(name), designs()[name], delay=1.1 * TM)
    w = np.geomspace(0.05, 200.0, 301)
    ref = realisation_L(loop, w)
    got = frequency_response(loop, w).L
    assert np.max(np.abs(got - ref) / np.abs(ref)) < 1e-8


def test_perfect_smith_margins_against_a_brute_force_grid():
    # |L| = 1, the phase there, and max 1/|1 + L| on a grid of two million points (spacing 2.5e-5 rad/s)
    loop = Loop("1/s", designs()["smith"], delay=TM)
    m = margins(loop)
    w = np.linspace(1e-3, 50.0, 2_000_001)
    s = 1j * w
    L = 5 * np.exp(-s * TM) / (s + 5 - 5 * np.exp(-s * TM))
    i = int(np.argmin(np.abs(np.abs(L) - 1.0)))
    assert m.crossover == pytest.approx(w[i], abs=5e-5)
    lag = (np.angle(L[i]) + math.pi) % (2 * math.pi)
    assert m.delay_margin == pytest.approx(lag / w[i], rel=1e-4)
    assert m.ms == pytest.approx(1.0 / np.min(np.abs(1.0 + L)), rel=1e-8)
    assert m.ms >= 1.0 / np.min(np.abs(1.0 + L))  # the refined peak is at least the grid's
    # the gain margin: the first phase crossover's 1 / |L| (the grid's points where Im L changes sign, Re L < 0)
    k = np.flatnonzero((np.sign(L.imag[:-1]) != np.sign(L.imag[1:])) & (L.real[:-1] < 0))
    assert m.gain_margin == pytest.approx(1.0 / np.abs(L[k[0]]), rel=1e-4)
    assert m.stable and m.encirclements == 0 and m.open_loop_rhp_poles == 0


@pytest.mark.parametrize("name", ["smith", "filtered-smith", "predictor", "smith-pi-lag"])
def test_the_margins_put_a_root_on_the_imaginary_axis(name):
    # the delay margin: the true delay T + DM puts a root at j wc (the characteristic quasi-polynomial vanishes
    # there), a little less is stable and a little more is not (rightmost root); the gain margin likewise on the
    # plant's gain, at the phase crossover
    c = designs()[name]
    plant = plant_of(name)
    loop = Loop(plant, c, delay=TM)
    m = margins(loop)
    assert m.stable and math.isfinite(m.delay_margin) and m.delay_margin > 0
    q = loop.replace(delay=TM + m.delay_margin).characteristic()
    wc = m.crossover
    scale = sum(abs(np.polyval(p, 1j * wc)) for p in q.polys)
    assert abs(q(1j * wc)) < 1e-9 * scale
    assert rightmost(loop.replace(delay=TM + 0.99 * m.delay_margin)).stable
    assert not rightmost(loop.replace(delay=TM + 1.01 * m.delay_margin)).stable
    if math.isfinite(m.gain_margin):
        from delaykit.models.transfer import TransferFunction

        p = TransferFunction.coerce(plant)
        for k, stable in ((0.99, True), (1.01, False)):
            scaled = Loop(TransferFunction(p.num * k * m.gain_margin, p.den), c, delay=TM)
            assert rightmost(scaled).stable is stable
        q = Loop(TransferFunction(p.num * m.gain_margin, p.den), c, delay=TM).characteristic()
        wp = m.phase_crossover
        assert abs(q(1j * wp)) < 1e-8 * sum(abs(np.polyval(pp, 1j * wp)) for pp in q.polys)


@pytest.mark.parametrize("name", ["smith", "filtered-smith", "predictor"])
def test_the_critical_delay_is_the_design_modules_upper_delay_ratio(name):
    # two independent routes to the same number: the rightmost root bisected over Td / Tm (tolerance 1e-4 on the
    # ratio), and the frequency response's delay margin
    c = designs()[name]
    _, hi = delay_ratio_range(c, tol=1e-6)
    m = margins(Loop("1/s", c, delay=TM))
    assert m.critical_delay / TM == pytest.approx(hi, abs=2e-6)


@pytest.mark.parametrize("ratio", [0.8, 1.0, 1.3, 2.5, 3.5])
@pytest.mark.parametrize("name", ["smith", "filtered-smith", "predictor"])
def test_the_nyquist_count_agrees_with_the_roots(name, ratio):
    # P - (counterclockwise encirclements) must be the number of closed-loop roots in the right half-plane, which
    # the certified root finder counts on the characteristic quasi-polynomial (stable and unstable loops)
    loop = Loop("1/s", designs()[name], delay=ratio * TM)
    m = margins(loop)
    q = loop.characteristic()
    R = root_bound(q, 0.0)
    sp = find_roots(q, (1e-9, R, -R, R))
    assert sp.certified
    n_rhp = int(np.sum(sp.multiplicities))
    assert m.stable is (n_rhp == 0)
    assert m.nyquist_rhp_roots == n_rhp
    if not m.stable:
        assert math.isnan(m.gain_margin) and math.isnan(m.delay_margin)


def test_jitter_margin_of_a_compensated_loop():
    # the criterion's bound inf |1 + L| / (w |L|): at most the constant-delay margin (a theorem), and for the
    # perfect-model Smith predictor the limit at infinite frequency 1 / Kc = 0.2 s (w |L| -> 5), which a grid of
    # frequencies up to 1e5 rad/s approaches from above
    loop = Loop("1/s", designs()["smith"], delay=TM)
    jm = jitter_margin(loop)
    m = margins(loop)
    assert jm.margin <= m.delay_margin and jm.delay_margin == m.delay_margin
    w = np.geomspace(1e-2, 1e5, 200_001)
    g = jitter_bound(loop, w)
    assert jm.margin <= g.min() + 1e-12 and g.min() - jm.margin < 1e-4
    assert jm.margin == pytest.approx(0.2, abs=1e-12) and math.isinf(jm.frequency)
    assert stable_for(loop, TM, TM + 0.99 * jm.margin) and not stable_for(loop, TM, TM + 1.01 * m.delay_margin)
    for name in ("filtered-smith", "predictor"):
        lp = Loop("1/s", designs()[name], delay=TM)
        j = jitter_margin(lp)
        grid = jitter_bound(lp, np.geomspace(1e-2, 1e4, 100_001))
        assert 0 < j.margin <= margins(lp).delay_margin and j.margin <= grid.min() + 1e-12


def test_margins_command_line_for_a_compensator_continuous_and_sampled():
    from typer.testing import CliRunner

    from delaykit.cli import app
    from delaykit.design.compensators import tune_compensator

    res = CliRunner().invoke(app, ["margins", "--controller", "smith", "--delay", "0.42", "--model-delay", "0.37",
                                   "--json"])
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    ref = margins(Loop("1/s", tune_compensator("smith", "1/s", 0.37), delay=0.42))
    assert got["delay_margin"] == pytest.approx(ref.delay_margin, rel=1e-12)
    assert got["critical_delay"] == pytest.approx(0.42 + ref.delay_margin, rel=1e-12)
    # sampled, the same loop is analysed by the exact discrete-time model (tests/test_sampled_compensated.py checks
    # it against a brute-force transition matrix); here it is unstable, and the command says so rather than failing
    res = CliRunner().invoke(app, ["margins", "--controller", "smith", "--delay", "0.42", "--model-delay", "0.37",
                                   "--period", "0.065", "--json"])
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    from delaykit.spectrum.sampled import sampled_spectrum

    sp = sampled_spectrum(Loop("1/s", tune_compensator("smith", "1/s", 0.37), delay=0.42, period=0.065))
    assert got["sampled"] and got["radius"] == pytest.approx(sp.radius, rel=1e-12)
    assert got["stable"] is sp.stable is False and got["gain_margin"] is None
    with pytest.raises(InvalidValueError, match="sampled"):
        margins(Loop("1/s", Compensator.smith("1/s", TM), delay=TM, period=0.065))


def test_a_model_integrator_the_plant_lacks_leaves_a_structural_root_that_stability_ignores():
    # A Smith predictor with an integrating model on a self-regulating plant: the characteristic quasi-polynomial
    # keeps the window integral's root at 0 (the three polynomials do not vanish there, only their sum), which the
    # loop never excites. The reference is independent of the quasi-polynomial: the exact sampled model's dominant
    # rate (checked against a brute-force transition matrix in test_sampled_compensated.py) extrapolated to h = 0
    # (Richardson: it converges at first order in h).
    from delaykit.spectrum.sampled import sampled_spectrum
    from delaykit.spectrum.stability import rightmost

    law = Compensator.smith("1/s", 0.4, closed_loop_time=1.0)
    lp = Loop("1/(s+0.1)", law, delay=0.4)
    assert lp.structural_roots_kept() == 1 and Loop("1/s", law, delay=0.4).structural_roots_kept() == 0
    assert abs(lp.characteristic()(0.0)) < 1e-12  # the structural root is in the quasi-polynomial
    r1, r2 = (float(sampled_spectrum(lp.replace(period=h)).rates()[0].real) for h in (0.002, 0.001))
    limit = 2.0 * r2 - r1
    rm = rightmost(lp)
    assert rm.stable and rm.abscissa == pytest.approx(limit, abs=2e-5)
    m = margins(lp)
    assert m.stable and math.isfinite(m.delay_margin)
    # the delay margin brings the next root, not the structural one, to the axis
    for f, stable in ((0.99, True), (1.01, False)):
        assert rightmost(lp.replace(delay=0.4 + f * m.delay_margin)).stable is stable
