"""Saturation blocks in system files: ``saturation = [lower, upper]`` (or a table with a side left out).

References: the same loop built by the algebra (``delaykit.saturation``), and the paper's saturated P loop
simulated by delaykit's Loop kernel (``simulate(AltitudeLoop(...))``), a method of steps independent of the
delay-system kernel.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit import AltitudeLoop, InvalidValueError, delay, feedback, saturation, simulate, tf
from delaykit.cli.app import app
from delaykit.systems.files import read_system_file, system_from_dict

EXAMPLES = Path(__file__).parents[1] / "examples"


def _paper_loop(limits) -> dict:
    return {"inputs": ["r"], "outputs": ["y"], "break": ["u"],
            "blocks": [{"sum": ["r", "-y"], "outputs": "e"},
                       {"name": "P", "tf": 1.31, "inputs": "e", "outputs": "v"},
                       {"name": "limits", "saturation": limits, "inputs": "v", "outputs": "u"},
                       {"delay": 0.368, "inputs": "u", "outputs": "ud"},
                       {"tf": "1/s", "inputs": "ud", "outputs": "y"}]}


def test_saturated_file_loop_steps_as_the_algebra_and_the_loop_kernel():
    sf = system_from_dict(_paper_loop([-1.0, 1.0]))
    assert sf.system.saturations == (0,) and sf.system.limits[0] == (-1.0, 1.0)
    t = np.linspace(0.0, 12.0, 241)
    got = sf.system.step(t)
    assert got.status == "exact"
    # the loop by algebra: the same system, so the same step to rounding
    built = feedback(tf("1/s") * delay(0.368) * saturation(-1.0, 1.0) * 1.31, 1)
    np.testing.assert_allclose(got.outputs, built.step(t).outputs, rtol=0, atol=1e-12)
    # the Loop kernel (independent): the paper's loop with its command limited to +-1
    ref = simulate(AltitudeLoop(kp=1.31, delay=0.368, vmax=1.0), t_end=12.0)
    np.testing.assert_allclose(got.outputs[0, 0], ref.output(t), rtol=0, atol=1e-9)
    # the limit binds (else this test would not test it): the linear loop differs
    lin = sf.system.without_limits().step(t).outputs[0, 0]
    assert np.max(np.abs(lin - got.outputs[0, 0])) > 0.05


@pytest.mark.parametrize("limits, want", [
    ([-1.0, math.inf], (-1.0, math.inf)),
    ({"upper": 2.0}, (-math.inf, 2.0)),
    ({"lower": -0.5}, (-0.5, math.inf)),
    ({"lower": -0.5, "upper": 3}, (-0.5, 3.0)),
    ([-math.inf, 0.7], (-math.inf, 0.7)),
])
def test_one_sided_and_table_forms(limits, want):
    sys = system_from_dict(_paper_loop(limits)).system
    assert sys.limits[0] == want
    # a one-sided limit is the same as the algebra's saturation with None on the free side
    lo, hi = want
    built = feedback(tf("1/s") * delay(0.368) * saturation(lo, hi) * 1.31, 1)
    t = np.linspace(0.0, 6.0, 61)
    np.testing.assert_allclose(sys.step(t).outputs, built.step(t).outputs, rtol=0, atol=1e-12)


def test_small_signal_analyses_ignore_the_limits():
    # margins and poles are those of the linear loop (each saturation as the identity)
    sat = system_from_dict(_paper_loop([-1.0, 1.0]))
    lin = system_from_dict({**_paper_loop([-1.0, 1.0]),
                            "blocks": [b if "saturation" not in b else {"tf": 1, "inputs": "v", "outputs": "u"}
                                       for b in _paper_loop([-1.0, 1.0])["blocks"]]})
    w = np.linspace(0.0, 5.0, 11)
    np.testing.assert_allclose(sat.loops[0].frequency_response(w).response,
                               lin.loops[0].frequency_response(w).response, rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("limits, words", [
    ([1.0, 2.0], ["block 'limits'", "lower <= 0 <= upper", "[1, 2]"]),
    ([-2.0, -1.0], ["block 'limits'", "[-2, -1]"]),
    ([0.0, 0.0], ["block 'limits'", "lower < upper", "[0, 0]"]),
    ([math.inf, -math.inf], ["block 'limits'", "[inf, -inf]"]),
    (["a", 1.0], ["block 'limits'", "numbers", "'a'"]),
    ([math.nan, 1.0], ["block 'limits'", "nan"]),
    ([True, 1.0], ["block 'limits'", "True"]),
    ([-1.0], ["block 'limits'", "[lower, upper]"]),
    ([-1.0, 0.0, 1.0], ["block 'limits'", "[lower, upper]"]),
    ({"lower": -1.0, "top": 2.0}, ["block 'limits'", "lower", "upper", "'top'"]),
    ({}, ["block 'limits'", "[lower, upper]"]),
    ("-1, 1", ["block 'limits'", "'-1, 1'"]),
])
def test_bad_limits_get_one_line_errors(tmp_path, limits, words):
    with pytest.raises(InvalidValueError) as exc:
        system_from_dict(_paper_loop(limits), source="loop.toml")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith("loop.toml: ")
    for w in words:
        assert w in msg, (w, msg)


def test_bad_limits_from_a_file_on_the_command_line(tmp_path):
    p = tmp_path / "sat.toml"
    p.write_text('inputs = "r"\noutputs = "y"\nbreak = "u"\n[[blocks]]\nsum = ["r", "-y"]\noutputs = "e"\n'
                 '[[blocks]]\nname = "limits"\nsaturation = [0.5, nan]\ninputs = "e"\noutputs = "u"\n'
                 '[[blocks]]\ntf = "exp(-s)/s"\ninputs = "u"\noutputs = "y"\n')
    with pytest.raises(InvalidValueError, match="block 'limits'"):
        read_system_file(p)
    res = CliRunner().invoke(app, ["margins", "--system", str(p)])
    assert res.exit_code == 2 and "Traceback" not in res.output and res.output.startswith("error: ")


def test_px4_vehicle_file_has_the_limits_of_the_fitted_loop():
    # the file's saturation block holds the fit's -1/+3 m/s; a -2 m step drives the speed command into the lower
    # limit; reference: the same vehicle built by the algebra with saturation(-1, 3) (tests/test_fit_system.py's
    # blocks), and the linear loop, which the limit must change
    from delaykit import interconnect, summing_junction

    sf = read_system_file(EXAMPLES / "px4-vehicle.toml")
    assert sf.system.saturations and sf.system.limits[sf.system.saturations[0]] == (-1.0, 3.0)
    k, tau, kappa = 1.454, 0.07508, 0.6536
    blocks = [summing_junction(["z_ref", "-z"], "e"), tf(0.95, inputs="e", outputs="u_c"),
              saturation(-1.0, 3.0, inputs="u_c", outputs="u"), delay(tau, inputs="u", outputs="v_ref"),
              summing_junction(["v_ref", "-vz"], "e_v"), tf("4 + 2/s", inputs="e_v", outputs="c"),
              tf(k, inputs="c", outputs="f"), tf(kappa, inputs="z", outputs="g"),
              summing_junction(["f", "-g"], "a"), tf("1/s", inputs="a", outputs="vz"),
              tf("1/s", inputs="vz", outputs="z")]
    ref = interconnect(blocks, inputs=["z_ref"], outputs=["z", "vz"])
    t = np.linspace(0.0, 8.0, 81)
    u = np.full(t.size, -2.0)
    got = sf.system.lsim(t, u).outputs
    np.testing.assert_allclose(got, ref.lsim(t, u).outputs, rtol=0, atol=1e-10)
    lin = sf.system.without_limits().lsim(t, u).outputs
    assert np.max(np.abs(lin[1] - got[1])) > 0.1      # the speed command is held at -1 m/s for a while
