"""One margins and one frequency response for loops and systems (issue 32, first step).

References: closed forms for k exp(-tau s)/s (PM = 90 deg - k tau rad at w = k, DM = pi/(2k) - tau, GM = pi/(2 k tau)
at w = pi/(2 tau)); Lambert W for the roots of s - 1 + 3 exp(-s); python-control's ``stability_margins`` of the
delay-free loop and of a high-order Padé model; delaykit's own Loop margins (today's certified method) for the
same loop built as a Loop; the certified stability of the loop with the delay margin added (just below/above).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.special import lambertw

import delaykit as dk
from delaykit import Controller, InvalidTypeError, InvalidValueError, Loop, delay, feedback, is_stable, margins, tf

control = pytest.importorskip("control")

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.parametrize("k, tau", [(1.31, 0.368), (0.5, 0.2), (2.0, 0.05)])
def test_integrator_with_delay_closed_forms(k, tau):
    m = margins(tf(f"{k}*exp(-{tau}*s)/s"))
    assert m.method == "exact" and m.certified and m.stable
    assert m.phase_margin == pytest.approx(90.0 - math.degrees(k * tau), abs=1e-9)
    assert m.delay_margin == pytest.approx(math.pi / (2 * k) - tau, rel=1e-10)
    assert m.gain_margin == pytest.approx(math.pi / (2 * k * tau), rel=1e-10)
    assert m.crossover == pytest.approx(k, rel=1e-12)
    assert m.phase_crossover == pytest.approx(math.pi / (2 * tau), rel=1e-10)


def test_a_system_gets_the_margins_of_the_same_loop():
    # reference: today's Loop margins (spectrum/frequency.py) of Loop(G, PI, delay)
    loop = Loop("0.62/(150*s+1)", Controller.pi(6.0, 0.05), delay=12.0)
    ref = margins(loop)
    got = margins(tf("6*(1 + 0.05/(6*s))") * tf("0.62*exp(-12*s)/(150*s+1)"))
    assert got.method == "exact" and got.stable == ref.stable
    for f in ("gain_margin", "phase_margin", "delay_margin", "critical_delay", "crossover", "phase_crossover", "ms"):
        assert getattr(got, f) == pytest.approx(getattr(ref, f), rel=1e-9), f
    assert got.open_loop_rhp_poles == ref.open_loop_rhp_poles and got.encirclements == ref.encirclements
    # and its frequency response is the loop's
    w = np.geomspace(1e-3, 10, 50)
    a, b = dk.frequency_response(loop, w), dk.frequency_response(tf("6*(1 + 0.05/(6*s))") *
                                                                 tf("0.62*exp(-12*s)/(150*s+1)"), w)
    assert np.allclose(a.L, b.L, rtol=1e-12) and np.allclose(a.phase_deg, b.phase_deg, atol=1e-9)


def test_an_unstable_closed_loop_gets_no_margins():
    # issue 34: 3 exp(-s)/(s-1) once had "gain margin 2.6"; the closed loop s - 1 + 3 exp(-s) = 0 has the roots
    # s = 1 + W_k(-3/e) (Lambert W), and W_0(-3/e) has a positive real part: unstable
    root = 1 + lambertw(-3 / math.e, 0)
    assert root.real > 0
    L = tf("3*exp(-s)/(s-1)")
    m = margins(L)
    assert not m.stable and math.isnan(m.gain_margin) and math.isnan(m.delay_margin)
    assert not is_stable(feedback(L, 1))
    with pytest.warns(DeprecationWarning, match=r"delaykit\.margins\(L\)"):
        old = dk.loop_margins(L)
    assert math.isnan(old.gain_margin)


def test_zero_delay_matches_python_control():
    # a third-order lag, no delay: python-control's stability_margins (GM 2 at sqrt(3) rad/s in closed form)
    for text, num, den in [("4/(s+1)^3", [4], [1, 3, 3, 1]), ("2*(s+3)/((s+1)*(s^2+s+4))", [2, 6], [1, 2, 5, 4])]:
        m = margins(tf(text))
        gm, pm, _, wpc, wgc, _ = control.stability_margins(control.tf(num, den))
        assert m.method == "exact" and m.stable
        assert m.gain_margin == pytest.approx(gm, rel=1e-7)
        assert m.phase_margin == pytest.approx(pm, rel=1e-7)
        assert m.phase_crossover == pytest.approx(wpc, rel=1e-7)
        assert m.crossover == pytest.approx(wgc, rel=1e-7)
    m = margins(tf("4/(s+1)^3"))   # closed form: GM 2 at sqrt(3) rad/s (the triple pole: bisection to ~1e-11)
    assert m.phase_crossover == pytest.approx(math.sqrt(3), rel=1e-9) and m.gain_margin == pytest.approx(2, rel=1e-9)


def _pade_margins(delays_and_parts, order=12):
    """python-control's stability_margins of sum_k part_k * pade(delay_k)."""
    total = 0
    for T, num, den in delays_and_parts:
        p = control.tf(*control.pade(T, order)) if T > 0 else 1
        total = total + control.tf(num, den) * p
    return control.stability_margins(total)


def test_one_delay_matches_a_high_order_pade_model():
    m = margins(tf("2*exp(-0.2*s)/((s+1)*(0.5*s+1))"))
    gm, pm, _, wpc, wgc, _ = _pade_margins([(0.2, [2], [0.5, 1.5, 1])])
    assert m.method == "exact"
    assert m.gain_margin == pytest.approx(gm, rel=1e-7) and m.phase_margin == pytest.approx(pm, rel=1e-7)
    assert m.phase_crossover == pytest.approx(wpc, rel=1e-7) and m.crossover == pytest.approx(wgc, rel=1e-7)


def test_two_delays_use_the_grid_and_match_pade_and_the_certified_stability():
    text_a, text_b = "2*exp(-0.3*s)/((s+1)*(0.5*s+1))", "0.5*exp(-1.1*s)/(s+1)"
    L = tf(text_a) + tf(text_b)
    m = margins(L)
    assert m.method == "grid" and not m.certified and m.stable
    gm, pm, _, wpc, wgc, _ = _pade_margins([(0.3, [2], [0.5, 1.5, 1]), (1.1, [0.5], [1, 1])], order=14)
    assert m.gain_margin == pytest.approx(gm, rel=1e-6) and m.phase_margin == pytest.approx(pm, rel=1e-6)
    assert m.phase_crossover == pytest.approx(wpc, rel=1e-6) and m.crossover == pytest.approx(wgc, rel=1e-6)
    # the gain and delay margins are where the certified stability flips
    assert is_stable(feedback((m.gain_margin * (1 - 1e-4)) * L, 1))
    assert not is_stable(feedback((m.gain_margin * (1 + 1e-4)) * L, 1))
    assert is_stable(feedback(L * delay(m.delay_margin * (1 - 1e-4)), 1))
    assert not is_stable(feedback(L * delay(m.delay_margin * (1 + 1e-4)), 1))
    d = m.to_dict()
    assert d["method"] == "grid" and d["certified"] is False and d["channel"] is None
    # the response of a system that is not rational times one delay: exact values, continuous phase
    w = np.geomspace(0.01, 30, 400)
    r = dk.frequency_response(L, w)
    assert np.allclose(r.L, L.evaluate(1j * w)[0, 0], rtol=1e-13)
    assert np.all(np.abs(np.diff(r.phase_deg)) < 90)
    assert np.allclose(np.exp(1j * np.radians(r.phase_deg)), r.L / np.abs(r.L), atol=1e-10)
    # its default grid spans its features (poles 1, 2; delays 0.3, 1.1 s): 1/100 of the lowest to 10 x the highest
    g = dk.frequency_grid(L, 5)
    assert g[0] == pytest.approx(1 / 1.1 / 100) and g[-1] == pytest.approx(10 / 0.3)
    assert dk.frequency_response(L).w.size == 500
    assert dk.frequency_grid(L, 3, wmin=0.1, wmax=10.0).tolist() == pytest.approx([0.1, 1.0, 10.0])


def test_mimo_loop_at_a_time_margins_one_per_channel():
    # diagonal: each channel is its own k exp(-tau s)/s loop, closed forms as above
    L = tf([["1.5*exp(-0.2*s)/s", 0], [0, "0.5*exp(-0.4*s)/s"]])
    m0, m1 = margins(L)
    for m, ch, k, tau in ((m0, 0, 1.5, 0.2), (m1, 1, 0.5, 0.4)):
        # the other channel's closed loop (a delay inside a loop) is part of L_k's realisation: the grid method
        assert m.channel == ch and m.method == "grid" and m.stable
        assert m.delay_margin == pytest.approx(math.pi / (2 * k) - tau, rel=1e-10)
        assert m.gain_margin == pytest.approx(math.pi / (2 * k * tau), rel=1e-10)
        assert m.phase_margin == pytest.approx(90.0 - math.degrees(k * tau), abs=1e-8)
    assert repr(m1).startswith("Margins(channel 1: GM")
    # coupled: channel 0 opened with channel 1 closed is L1 = l11 - l12 l21 / (1 + l22), by hand at the crossover
    C = tf([["exp(-0.1*s)/s", "0.3*exp(-0.5*s)/(s+1)"], ["0.2*exp(-0.7*s)/(s+2)", "0.8*exp(-0.2*s)/s"]])
    c0 = margins(C)[0]
    s = 1j * c0.crossover
    l11, l12 = np.exp(-0.1 * s) / s, 0.3 * np.exp(-0.5 * s) / (s + 1)
    l21, l22 = 0.2 * np.exp(-0.7 * s) / (s + 2), 0.8 * np.exp(-0.2 * s) / s
    L1 = l11 - l12 * l21 / (1 + l22)
    assert abs(abs(L1) - 1) < 1e-9 and c0.method == "grid"
    assert c0.phase_margin == pytest.approx(180 + math.degrees(np.angle(L1)), abs=1e-6)


def test_small_eigenvalues_of_zero_do_not_spoil_the_rational_part():
    # the px4 vehicle file's loop: its A has an eigenvalue at 0 computed as ~1e-18; plant_of once interpolated on a
    # circle of that radius and lost a pole. Reference: the LFT evaluated directly (DelayLTI.evaluate)
    from delaykit.systems.files import read_system_file

    sf = read_system_file(EXAMPLES / "px4-vehicle.toml")
    L = sf.loops[0].without_limits()
    g, T = dk.plant_of(L)
    w = np.geomspace(0.01, 100, 40)
    s = 1j * w
    direct = L.evaluate(s)[0, 0]
    assert np.allclose(np.polyval(g.num, s) / np.polyval(g.den, s) * np.exp(-s * T), direct, rtol=1e-9)
    assert np.allclose(dk.frequency_response(sf.loops[0], w).L, direct, rtol=1e-9)


def test_a_loop_without_phase_crossover_has_a_repr():
    # 1/(s+1) and a static gain 2: no phase crossover (the phase never reaches -180), so GM inf; the repr once failed
    # formatting the missing crossover frequency
    for L, pm in ((tf("1/(s+1)"), math.inf), (tf("2"), math.inf)):
        m = margins(L)
        assert m.stable and m.gain_margin == math.inf and m.phase_crossover is None and m.phase_margin == pm
        assert repr(m).startswith("Margins(GM inf, PM inf, DM inf")


def test_bad_input_is_refused_naming_what_is_expected():
    with pytest.raises(InvalidTypeError, match="Loop, an AltitudeLoop or a DelayLTI"):
        margins("1/(s+1)")
    with pytest.raises(InvalidTypeError, match="Loop, an AltitudeLoop or a DelayLTI"):
        dk.frequency_response(3.0, [1.0])
    with pytest.raises(InvalidValueError, match="square"):
        margins(tf([["1/(s+1)", "1/(s+2)"]]))
    with pytest.raises(InvalidValueError, match="SISO"):
        dk.frequency_response(tf([["1/(s+1)", 0], [0, "1/(s+2)"]]), [1.0])


def test_cli_system_margins_says_the_method():
    from typer.testing import CliRunner

    from delaykit.cli import app

    res = CliRunner().invoke(app, ["margins", "--system", str(EXAMPLES / "wood-berry.toml"), "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    from delaykit.systems.files import read_system_file

    ref = margins(read_system_file(EXAMPLES / "wood-berry.toml").loops[0])
    assert d["loops"][0]["method"] == ref.method and d["loops"][0]["gain_margin"] == pytest.approx(ref.gain_margin)
