"""The exact sampled model of loops with a delay compensator (a Smith predictor, the filtered Smith predictor,
predictor feedback), held commands and two delays.

References: the simulator's own samples (an independent method, the method of steps on the continuous law with
the held command), the closed form of the perfect-model Smith predictor (its samples follow the delay-free
sampled loop, pole ``1 - Kc h``), and the continuous loop's rightmost root as the period shrinks.
"""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit import InvalidValueError
from delaykit.models import Loop
from delaykit.models.compensators import Compensator
from delaykit.simulate.simulation import simulate
from delaykit.spectrum.sampled import sampled_margins, sampled_model, sampled_spectrum
from delaykit.spectrum.stability import rightmost

TM = 0.37
H = 0.065  # the paper's period: 0.37 = 5 h + 0.045


def comps() -> dict[str, Compensator]:
    return {"smith": Compensator.smith("1/s", TM, closed_loop_time=0.2),
            "filtered-smith": Compensator.filtered_smith("1/s", TM, closed_loop_time=0.3),
            "predictor": Compensator.predictor("1/s", TM, closed_loop_time=0.3),
            "smith-lag": Compensator.smith("2/(0.5*s+1)", TM, closed_loop_time=0.3)}


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
    plant = "2/(0.5*s+1)" if name == "smith-lag" else "1/s"
    lp = Loop(plant, comps()[name], delay=ratio * TM, period=H)
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


def test_margins_of_a_sampled_compensated_loop_are_refused_and_roots_work_from_the_command_line():
    from delaykit.cli import app

    lp = Loop("1/s", comps()["smith"], delay=0.42, period=H)
    from delaykit.spectrum.sampled import sampled_frequency_response, sampled_response

    for f in (sampled_margins, sampled_response, lambda x: sampled_frequency_response(x, 1.0)):
        with pytest.raises(InvalidValueError, match="compensator reads the held command"):
            f(lp)
    res = CliRunner().invoke(app, ["roots", "--controller", "smith", "--delay", "0.42", "--model-delay", "0.37",
                                   "--period", "0.065", "--json"])
    assert res.exit_code == 0, res.output
    import json

    got = json.loads(res.stdout)
    assert got["radius"] == pytest.approx(sampled_spectrum(Loop("1/s", _cli_design(), delay=0.42,
                                                                umin=-1, umax=1, period=H)).radius, rel=1e-12)


def _cli_design() -> Compensator:
    from delaykit.design.compensators import tune_compensator

    return tune_compensator("smith", "1/s", 0.37)
