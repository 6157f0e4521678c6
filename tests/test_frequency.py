"""Exact frequency response and margins of continuous delay loops (delaykit.spectrum.frequency), the Bode and
Nyquist plots, the ``margins`` command and the python-control interop (delaykit.models.interop).

References: closed forms (the P loop on an integrator, a delay-free second-order loop, an open-loop unstable first
order plant), python-control's own evaluation and margins of the delay-free part, the exact characteristic roots
of the loop with its gain or delay changed by the margin (spectrum.stability.rightmost), spectrum.stability's
delay margin, a brute-force dense grid for the peak sensitivity, np.unwrap on a dense grid for the phase, and the
certified root count in the right half-plane for the Nyquist count.
"""

from __future__ import annotations

import json
import math
import sys

import numpy as np
import pytest
from scipy.optimize import brentq
from typer.testing import CliRunner

from delaykit import AltitudeLoop, Controller, Loop, TransferFunction
from delaykit.cli import app
from delaykit.errors import InvalidTypeError, InvalidValueError, MissingDependencyError
from delaykit.models.interop import pade_error, to_control
from delaykit.spectrum.frequency import frequency_grid, frequency_response, margins
from delaykit.spectrum.roots import find_roots, root_bound
from delaykit.spectrum.stability import delay_margin, rightmost

control = pytest.importorskip("control")

PLANT3 = "1/((s+1)*(0.5*s+1)*(0.2*s+1))"
PID3 = Loop(PLANT3, Controller.pid(2.0, 1.0, 0.3, 0.05), delay=0.2)
PAPER_P = AltitudeLoop(kp=1.31, delay=0.368)
PAPER_PV = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3)
PAPER_PV_FILTERED = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered")
UNSTABLE_PLANT = Loop("1/(s-1)", Controller.p(2.0), delay=0.1)
# stable closed loops of several kinds: each row is checked against its exact characteristic roots
STABLE = {
    "paper P": PAPER_P,
    "paper PV (neutral)": PAPER_PV,
    "paper PV, filtered velocity": PAPER_PV_FILTERED,
    "PID, 3rd-order plant": PID3,
    "PD, integrator with lag": Loop("1/(s*(0.05*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=0.3),
    "PI, integrator (two integrators in L)": Loop("1/s", Controller.pi(0.8, 0.1), delay=0.25),
    "P, open-loop unstable": UNSTABLE_PLANT,
    "P, two unstable poles": Loop("(s+1)/(s^2-2*s+5)", Controller.p(4.0), delay=0.05),
    "PD, unstable and split delays": Loop("1/((s-1)*(s+5))", Controller.pd(10.0, 2.0, 0.01), delay=0.03,
                                          output_delay=0.02),
    "P, lightly damped": Loop("1/(s^2+0.2*s+1)", Controller.p(0.5), delay=0.1),
    "PD, undamped oscillator (poles on the axis)": Loop("1/(s^2+1)", Controller.pd(1.0, 0.5, 0.05), delay=0.1),
    "P, zeros on the axis": Loop("(s^2+4)/((s+1)*(s+2)*(s+3))", Controller.p(2.0), delay=0.1),
    "PI, slow heater": Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02), delay=12.0),
}


def run(*args):
    return CliRunner().invoke(app, list(args))


def scaled(loop, k):
    """The loop with its loop gain multiplied by k (the plant scaled)."""
    loop = loop.to_loop() if isinstance(loop, AltitudeLoop) else loop
    return loop.replace(plant=loop.plant * k)


def total_delay(loop, t):
    """The loop with its total delay set to t (the input delay changed)."""
    loop = loop.to_loop() if isinstance(loop, AltitudeLoop) else loop
    return loop.replace(delay=t - loop.output_delay)


def spectral(loop):
    """The exact rightmost root (spectrum.stability.rightmost); for a long delay the search starts nearer the axis
    (the default start, Re s = -1, would make the root bound grow like exp(T))."""
    loop = loop.to_loop() if isinstance(loop, AltitudeLoop) else loop
    t = loop.total_delay
    return rightmost(loop.characteristic(), re_min=-0.5 / t if t > 1 else None)


def rhp_roots(loop):
    """Closed-loop roots with Re s >= 0, counted with multiplicity from the certified root finder."""
    q = loop.characteristic()
    r = root_bound(q, 0.0)
    sp = find_roots(q, (0.0, r, 0.0, r))
    assert sp.certified
    return int(sum(m * (1 if abs(z.imag) < 1e-9 else 2) for z, m in zip(sp.roots, sp.multiplicities)))


# ----------------------------------------------------------------------------------------- closed forms
@pytest.mark.parametrize("kp, td", [(1.31, 0.368), (0.5, 1.0), (3.0, 0.2), (2.0, 0.05), (1.0, 1.5)])
def test_p_loop_on_an_integrator_has_its_closed_form_margins(kp, td):
    # L = Kp exp(-s T) / s: |L| = 1 at w = Kp; phase -90 - w T (deg: * 180/pi); -180 at w = pi / (2 T)
    for loop in (AltitudeLoop(kp=kp, delay=td), Loop("1/s", Controller.p(kp), delay=td)):
        m = margins(loop)
        assert m.stable and m.open_loop_rhp_poles == 0 and m.encirclements == 0
        assert m.crossover == pytest.approx(kp, rel=1e-13)
        assert m.phase_margin == pytest.approx(90.0 - kp * td * 180.0 / math.pi, rel=1e-12, abs=1e-12)
        assert m.delay_margin == pytest.approx(math.pi / (2 * kp) - td, rel=1e-12)
        assert m.critical_delay == pytest.approx(math.pi / (2 * kp), rel=1e-13)
        assert m.gain_margin == pytest.approx(math.pi / (2 * td * kp), rel=1e-12)
        assert m.phase_crossover == pytest.approx(math.pi / (2 * td), rel=1e-13)
        assert m.lower_gain_margin == 0.0
        # every listed phase crossover: w_k = (pi/2 + 2 pi k) / T with |L| = Kp / w_k
        phase = [c for c in m.crossovers if c.kind == "phase"]
        assert len(phase) > 10
        for k, c in enumerate(phase):
            wk = (math.pi / 2 + 2 * math.pi * k) / td
            assert c.frequency == pytest.approx(wk, rel=1e-13)
            assert c.magnitude == pytest.approx(kp / wk, rel=1e-12)
            assert c.phase_deg == pytest.approx(-180.0 - 360.0 * k, rel=1e-13)
            assert c.direction == -1
        # nothing beyond the cut-off can do better: |L| < 1e-3 there (Kp / w < 1e-3)
        assert m.cutoff >= 1e3 * kp


def test_delay_free_second_order_loop_against_its_closed_form_and_python_control():
    k = 3.0
    m = margins(Loop("1/((s+1)*(s+2))", Controller.p(k)))
    # |L| = 1: (w^2 + 1)(w^2 + 4) = k^2; phase -atan(w) - atan(w/2) never reaches -180: no phase crossover
    wc = math.sqrt((-5 + math.sqrt(9 + 4 * k * k)) / 2)
    pm = 180.0 - math.degrees(math.atan(wc) + math.atan(wc / 2))
    assert m.crossover == pytest.approx(wc, rel=1e-13)
    assert m.phase_margin == pytest.approx(pm, rel=1e-12)
    assert m.delay_margin == pytest.approx(math.radians(pm) / wc, rel=1e-12)
    assert math.isinf(m.gain_margin) and m.phase_crossover is None
    assert [c.kind for c in m.crossovers] == ["gain"]
    gm, pm_c, sm, wpc, wgc, wms = control.stability_margins(control.tf([k], [1, 3, 2]))
    assert math.isinf(gm) and pm_c == pytest.approx(m.phase_margin, rel=1e-9) and wgc == pytest.approx(wc, rel=1e-9)
    assert 1.0 / sm == pytest.approx(m.ms, rel=1e-6)  # python-control's stability margin is 1 / Ms
    d = m.to_dict()
    assert d["gain_margin"] is None and d["gain_margin_db"] is None  # inf -> null


@pytest.mark.parametrize("num, den, k", [([10.0], [1, 6, 11, 6], 1.0), ([1.0], [1, 6, 11, 6], 30.0),
                                         ([2.0, 1.0], [1.0, 4.0, 6.0, 4.0, 0.0], 1.0)])
def test_delay_free_margins_agree_with_python_control(num, den, k):
    loop = Loop((num, den), Controller.p(k))
    m = margins(loop)
    gm, pm, sm, wpc, wgc, wms = control.stability_margins(control.tf(np.multiply(num, k), den))
    assert m.stable
    assert m.gain_margin == pytest.approx(gm, rel=1e-8)
    assert m.phase_crossover == pytest.approx(wpc, rel=1e-8)
    assert m.phase_margin == pytest.approx(pm, rel=1e-8)
    assert m.crossover == pytest.approx(wgc, rel=1e-8)
    assert m.ms == pytest.approx(1.0 / sm, rel=1e-6)


def test_open_loop_unstable_first_order_plant():
    # L = Kp exp(-s T) / (s - 1): phase -180 + atan(w) - w T (deg: rad * 180/pi), |L| = Kp / sqrt(1 + w^2)
    kp, td = 2.0, 0.1
    m = margins(UNSTABLE_PLANT)
    assert m.stable and m.open_loop_rhp_poles == 1 and m.encirclements == 1 and m.nyquist_rhp_roots == 0
    wc = math.sqrt(kp * kp - 1)
    assert m.crossover == pytest.approx(wc, rel=1e-13)
    assert m.phase_margin == pytest.approx(math.degrees(math.atan(wc) - wc * td), rel=1e-12)
    w1 = brentq(lambda w: math.atan(w) - w * td, 1.0, 100.0, xtol=1e-15)  # the phase back at -180
    assert m.phase_crossover == pytest.approx(w1, rel=1e-12)
    assert m.gain_margin == pytest.approx(math.sqrt(1 + w1 * w1) / kp, rel=1e-12)
    # L(0) = -Kp: a real root reaches s = 0 when the gain falls below 1 / Kp
    assert m.lower_gain_margin == pytest.approx(1.0 / kp, rel=1e-15)
    assert m.crossovers[0].frequency == 0.0 and m.crossovers[0].kind == "phase"
    # the closed loop is unstable below that gain, and the margins say so instead of numbers
    weak = margins(Loop("1/(s-1)", Controller.p(0.5), delay=0.1))
    assert not weak.stable and weak.nyquist_rhp_roots == rhp_roots(Loop("1/(s-1)", Controller.p(0.5), delay=0.1))
    assert all(math.isnan(x) for x in (weak.gain_margin, weak.phase_margin, weak.delay_margin, weak.ms))
    d = json.loads(json.dumps(weak.to_dict(), allow_nan=False))
    assert d["stable"] is False and d["gain_margin"] is None and d["delay_margin"] is None
    assert "UNSTABLE" in repr(weak)


# ------------------------------------------------------------------------------------------ python-control
def test_frequency_response_equals_python_control_times_the_delay():
    w = np.logspace(-3, 3, 1000)
    s = control.tf("s")
    plant = control.tf([1], [1, 1]) * control.tf([1], [0.5, 1]) * control.tf([1], [0.2, 1])
    pid = 2.0 + 1.0 / s + 0.3 * s / (0.05 * s + 1)  # Kp + Ki/s + Kd s/(Tf s + 1), built by python-control
    ref = control.frequency_response(plant * pid, w).complex * np.exp(-1j * w * 0.2)
    r = frequency_response(PID3, w)
    assert np.max(np.abs(r.L - ref) / np.abs(ref)) < 1e-12
    assert np.allclose(r.magnitude_db, 20 * np.log10(np.abs(ref)), rtol=0, atol=1e-10)


def test_python_control_plants_and_controllers_are_accepted():
    ss = control.ss(control.tf([1], [0.1, 1.2, 2.1, 1]))  # a StateSpace plant, (s+1)^2 (0.1 s+1)
    ctrl = Controller.transfer(control.tf([2.0, 1.0], [0.1, 1.0]))  # a python-control controller
    a = Loop(ss, ctrl, delay=0.2)
    b = Loop("1/((s+1)*(0.1*s+1)*(s+1))", Controller.transfer("(2*s+1)/(0.1*s+1)"), delay=0.2)
    w = np.logspace(-2, 2, 50)
    assert np.allclose(frequency_response(a, w).L, frequency_response(b, w).L, rtol=1e-10, atol=0)
    assert margins(a).delay_margin == pytest.approx(margins(b).delay_margin, rel=1e-9)


def test_to_control_with_pade_approaches_the_exact_response():
    w = np.linspace(0.05, 6.0, 200)
    exact = frequency_response(PID3, w).L
    errors = []
    for n in range(1, 7):
        L = to_control(PID3, pade_order=n)
        assert isinstance(L, control.TransferFunction)
        errors.append(np.max(np.abs(L(1j * w) - exact)))
        pe = pade_error(PID3, n, w)
        assert pe.max_error == pytest.approx(errors[-1], rel=1e-9)
        assert pe.order == n and pe.frequency in w
    assert all(b < a for a, b in zip(errors, errors[1:]))  # decreases with the order
    assert errors[-1] < 1e-9
    # the delay-free part alone is exact, and its closed loop is python-control's feedback of it
    free = Loop(PLANT3, Controller.pid(2.0, 1.0, 0.3, 0.05))
    Lf = to_control(free)
    assert np.max(np.abs(Lf(1j * w) - frequency_response(free, w).L)) < 1e-12
    assert float(np.max(np.real(control.poles(control.feedback(Lf, 1))))) == pytest.approx(
        rightmost(free).abscissa, rel=1e-9)


def test_pade_order_is_required_and_checked():
    with pytest.raises(InvalidValueError, match="pade_order"):
        to_control(PAPER_P)  # a delay, and no order
    for bad in (0, -2, 2.5, True):
        with pytest.raises(InvalidValueError, match="pade_order"):
            to_control(PAPER_P, pade_order=bad)
    with pytest.raises(InvalidValueError, match="order must be an integer"):  # (pade_error's parameter: order)
        pade_error(PAPER_P, 0, [1.0])
    with pytest.raises(InvalidValueError, match="empty"):
        pade_error(PAPER_P, 2, [])
    with pytest.raises(InvalidValueError, match="finite"):
        pade_error(PAPER_P, 2, [1.0, float("inf")])


def test_missing_python_control_is_an_import_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "control", None)  # makes `import control` fail
    with pytest.raises(MissingDependencyError, match="pip install control") as info:
        to_control(PAPER_P, pade_order=2)
    assert isinstance(info.value, ImportError)


# --------------------------------------------------------------------------------- margins against roots
@pytest.mark.parametrize("name", list(STABLE))
def test_margins_put_a_root_on_the_imaginary_axis(name):
    loop = STABLE[name]
    m = margins(loop)
    assert m.stable and spectral(loop).stable
    assert m.nyquist_rhp_roots == 0
    base = loop.to_loop() if isinstance(loop, AltitudeLoop) else loop
    # the gain margin: at k = GM a root sits at j w_pc; a little more gain is unstable, a little less is not
    if math.isfinite(m.gain_margin) and math.isfinite(m.phase_crossover):
        r = spectral(scaled(base, m.gain_margin))
        assert abs(r.abscissa) < 1e-7
        assert abs(abs(r.root.imag) - m.phase_crossover) < 1e-6 * m.phase_crossover
        assert not spectral(scaled(base, m.gain_margin * 1.01)).stable
        assert spectral(scaled(base, m.gain_margin * 0.99)).stable
    if m.lower_gain_margin > 0:
        assert abs(spectral(scaled(base, m.lower_gain_margin)).abscissa) < 1e-7
        assert not spectral(scaled(base, m.lower_gain_margin * 0.99)).stable
    # the delay margin: at T + DM a root sits at j w_c
    r = spectral(total_delay(base, base.total_delay + m.delay_margin))
    assert abs(r.abscissa) < 1e-7
    assert abs(abs(r.root.imag) - m.crossover) < 1e-6 * m.crossover
    assert not spectral(total_delay(base, base.total_delay + 1.01 * m.delay_margin)).stable
    assert m.critical_delay == base.total_delay + m.delay_margin


@pytest.mark.parametrize("name", ["paper P", "paper PV (neutral)", "paper PV, filtered velocity",
                                  "PID, 3rd-order plant", "P, lightly damped", "PI, slow heater"])
def test_critical_delay_equals_the_quasi_polynomial_delay_margin(name):
    # these loops are stable at every delay from 0 to their own, so the first crossing from 0 is the next one
    loop = STABLE[name]
    assert margins(loop).critical_delay == pytest.approx(delay_margin(loop).delay, rel=1e-9)


def test_neutral_pv_loop_lists_its_asymptote():
    # L = (Kv s + Kp) exp(-s T) / s is biproper: |L(j inf)| = Kv, a gain factor 1/Kv moves the root chains to Re s = 0
    m = margins(PAPER_PV)
    last = m.crossovers[-1]
    assert math.isinf(last.frequency) and last.magnitude == pytest.approx(0.3) and last.kind == "phase"
    assert last.to_dict()["frequency"] is None
    assert m.gain_margin < 1 / 0.3
    assert m.ms >= 1 / (1 - 0.3)  # |S| approaches 1/(1 - Kv) at high frequency
    unstable = margins(AltitudeLoop(kp=2.0, delay=0.37, kv=1.2))
    assert not unstable.stable and unstable.encirclements is None


@pytest.mark.parametrize("loop", [Loop("1/s^2", Controller.p(1.0), delay=0.1),
                                  Loop(PLANT3, Controller.pid(8.0, 4.0, 0.3, 0.05), delay=0.2),
                                  AltitudeLoop(kp=5.0, delay=0.368),
                                  Loop("1/(s-1)", Controller.p(2.0), delay=0.8),
                                  Loop("1/((s+1)*(s+2)*(s+3))", Controller.p(100.0)),
                                  Loop("1/(s*(s^2+4))", Controller.pd(0.5, 1.0, 0.05), delay=0.02),
                                  Loop("1/(s^2+1)", Controller.pd(1.0, 0.5, 0.05), delay=1.1),
                                  Loop("1/(s-1)", Controller.p(0.0), delay=0.2)])
def test_nyquist_count_equals_the_unstable_roots(loop):
    m = margins(loop)
    assert not m.stable
    assert m.nyquist_rhp_roots == rhp_roots(loop.to_loop() if isinstance(loop, AltitudeLoop) else loop) > 0


def _random_loop(seed):
    """A random strictly proper plant of order 1 to 4 (poles anywhere, integrators included) under P, PI, PD or
    PID, with or without a delay."""
    rng = np.random.default_rng(seed)
    poles: list[complex] = []
    n = int(rng.integers(1, 5))
    while len(poles) < n:
        if rng.random() < 0.3 and len(poles) <= n - 2:
            a, b = rng.uniform(-3, 0.5), rng.uniform(0.2, 4)
            poles += [complex(a, b), complex(a, -b)]
        else:
            poles.append(complex(0.0 if rng.random() < 0.3 else rng.uniform(-5, 1), 0.0))
    den = np.real(np.poly(poles))
    num = [rng.uniform(0.2, 3)] if n == 1 or rng.random() < 0.6 else \
        np.real(np.poly([rng.uniform(-4, -0.2)])) * rng.uniform(0.2, 2)
    kp, ki, kd = rng.uniform(0.2, 4), rng.uniform(0.05, 1), rng.uniform(0.0, 0.5)
    ctrl = [Controller.p(kp), Controller.pi(kp, ki), Controller.pd(kp, kd, 0.05), Controller.pid(kp, ki, kd, 0.05)]
    return Loop((num, den), ctrl[int(rng.integers(4))], delay=float(rng.choice([0.0, rng.uniform(0.01, 1.0)])))


@pytest.mark.parametrize("seed", range(30))
def test_random_loops_nyquist_count_and_stability_agree_with_the_roots(seed):
    loop = _random_loop(seed)
    m = margins(loop)
    z = rhp_roots(loop)
    assert m.stable == (z == 0)
    if m.encirclements is not None:
        assert m.nyquist_rhp_roots == z
    if m.stable and math.isfinite(m.delay_margin):
        assert abs(spectral(total_delay(loop, loop.total_delay + m.delay_margin)).abscissa) < 1e-7


def test_loop_without_phase_crossover_and_without_gain_crossover():
    # L = 0.5 exp(-s) / (s + 1): |L| < 1 everywhere, so no gain crossover (PM, DM infinite), but phase crossovers
    m = margins(Loop("1/(s+1)", Controller.p(0.5), delay=1.0))
    assert math.isinf(m.phase_margin) and math.isinf(m.delay_margin) and m.crossover is None
    w1 = brentq(lambda w: math.atan(w) + w - math.pi, 0.1, 10.0, xtol=1e-15)
    assert m.phase_crossover == pytest.approx(w1, rel=1e-12)
    assert m.gain_margin == pytest.approx(2 * math.sqrt(1 + w1 * w1), rel=1e-12)
    # (s+1)/(s+2) * 3 with no delay: neither crossover at all
    m = margins(Loop("(s+1)/(s+2)", Controller.p(3.0)))
    assert m.crossovers == () and math.isinf(m.gain_margin) and math.isinf(m.phase_margin)
    assert m.ms == pytest.approx(0.4, rel=1e-12)  # max |S| = S(0) = 1 / (1 + 3/2)


@pytest.mark.parametrize("name", ["paper P", "paper PV, filtered velocity", "P, open-loop unstable",
                                  "P, lightly damped", "PD, unstable and split delays"])
def test_ms_against_a_dense_grid(name):
    loop = STABLE[name]
    m = margins(loop)
    w = np.linspace(1e-4, 60.0, 2_000_001)
    brute = float(np.max(np.abs(frequency_response(loop, w).sensitivity)))
    assert m.ms >= brute * (1 - 1e-12)
    assert m.ms - brute < 1e-6 * m.ms
    assert abs(1 / abs(1 + frequency_response(loop, [m.ms_frequency]).L[0]) - m.ms) < 1e-12 * m.ms


def test_phase_is_unwrapped_exactly():
    # against np.unwrap on a grid dense enough for it (steps of w T well under pi), started at the low end
    for loop in (PID3, STABLE["P, two unstable poles"], PAPER_PV_FILTERED):
        w = np.linspace(1e-3, 200.0, 400_001)
        r = frequency_response(loop, w)
        ref = np.degrees(np.unwrap(np.angle(r.L)))
        ref += 360.0 * np.round((r.phase_deg[0] - ref[0]) / 360.0)
        assert np.max(np.abs(r.phase_deg - ref)) < 1e-8
        # and the same values at single frequencies, in any order
        pick = w[[300_000, 7, 150_000]]
        assert np.allclose(frequency_response(loop, pick).phase_deg, r.phase_deg[[300_000, 7, 150_000]], rtol=1e-13)
    # the starting phase: -90 per integrator, -180 for 1/(s-1)
    assert frequency_response(Loop("1/s^2", Controller.p(1.0)), [1e-6]).phase_deg[0] == pytest.approx(-180, abs=1e-3)
    assert frequency_response(UNSTABLE_PLANT, [1e-6]).phase_deg[0] == pytest.approx(-180, abs=1e-3)


def test_sensitivities_and_json():
    r = frequency_response(PID3, [0.5, 2.0])
    assert np.allclose(r.sensitivity + r.complementary, 1.0, rtol=0, atol=1e-14)
    assert np.allclose(r.complementary, r.L / (1 + r.L), rtol=1e-14)
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    assert set(d) == {"w", "re", "im", "magnitude_db", "phase_deg"}
    m = margins(PID3).to_dict()
    assert {"gain_margin", "phase_margin", "delay_margin", "critical_delay", "crossover", "ms", "crossovers"} <= set(m)
    json.dumps(m, allow_nan=False)


# ------------------------------------------------------------------------------------------------ bad input
def test_bad_input():
    with pytest.raises(InvalidValueError, match="empty"):
        frequency_response(PAPER_P, [])
    for bad in ([1.0, float("nan")], [float("inf")], np.array([0.5, -np.inf])):
        with pytest.raises(InvalidValueError, match="finite"):
            frequency_response(PAPER_P, bad)
    with pytest.raises(InvalidValueError, match="at least 0"):
        frequency_response(PAPER_P, [-1.0, 1.0])
    with pytest.raises(InvalidTypeError):
        frequency_response(PAPER_P, "1, 2")
    with pytest.raises(InvalidTypeError):
        frequency_response(PAPER_P, [1j])
    with pytest.raises(InvalidTypeError):
        margins("1/s")
    sampled = AltitudeLoop(kp=1.31, delay=0.368, period=0.065)
    for f in (margins, frequency_response, lambda l: to_control(l, pade_order=2)):
        with pytest.raises(InvalidValueError, match="sampled"):
            f(sampled)
    with pytest.raises(InvalidValueError, match="every frequency"):  # |L| = 1 everywhere: no margins
        margins(Loop("(1-s)/(1+s)", Controller.p(1.0), delay=0.1))
    with pytest.raises(InvalidValueError, match="reversed"):
        frequency_grid(PAPER_P, wmin=10.0, wmax=1.0)


# --------------------------------------------------------------------------------------------- plots and CLI
def test_plots_return_figures_on_given_axes(tmp_path):
    from matplotlib.figure import Figure

    from delaykit.plotting import plot_bode, plot_nyquist

    resp = frequency_response(PID3)
    fig = plot_bode([resp, frequency_response(PAPER_P)], margins=margins(PID3), labels=["pid", "paper"])
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    mine = Figure()
    a, b, c = mine.subplots(3)
    assert plot_bode(resp, axes=(a, b)) is mine and plot_nyquist(resp, ax=c) is mine
    assert len(a.lines) >= 1 and len(c.lines) >= 2
    with pytest.raises(InvalidTypeError):
        plot_bode(resp, ax=a)  # one axes is not enough
    mine.savefig(tmp_path / "f.png")
    assert (tmp_path / "f.png").stat().st_size > 5_000


def test_cli_margins_json_plot_and_errors(tmp_path):
    res = run("margins", "--kp", "1.31", "--delay", "0.368", "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert {"gain_margin", "phase_margin", "delay_margin", "critical_delay", "crossover", "ms", "crossovers"} <= set(d)
    assert d["delay_margin"] == margins(PAPER_P).delay_margin
    png = tmp_path / "bode.png"
    res = run("margins", "--plant", PLANT3, "--controller", "pid", "--kp", "2", "--ki", "1", "--kd", "0.3",
              "--derivative-filter", "0.05", "--delay", "0.2", "--plot", str(png), "--wmin", "0.01", "--wmax", "100")
    assert res.exit_code == 0, res.output
    assert png.stat().st_size > 10_000 and "phase margin" in res.stdout
    res = run("margins", "--kp", "1.31", "--delay", "0.368", "--wmin", "10", "--wmax", "1")
    assert res.exit_code == 2 and "reversed" in res.output
    res = run("margins", "--kp", "1.31", "--delay", "0.368", "--wmin", "-1")
    assert res.exit_code == 2 and "--wmin" in res.output
    res = run("margins", "--kp", "1.31", "--delay", "0.368", "--period", "0.065", "--json")  # tests/test_cli_sampled.py
    assert res.exit_code == 0 and json.loads(res.stdout)["sampled"] is True
    res = run("margins", "--kp", "5", "--delay", "0.368")
    assert res.exit_code == 0 and "UNSTABLE" in res.stdout


def test_transfer_function_scaling_used_by_the_tests():
    # the helper above scales the plant: check it is the loop gain that changes
    loop = scaled(PID3, 2.5)
    w = np.array([0.3, 3.0])
    assert np.allclose(frequency_response(loop, w).L, 2.5 * frequency_response(PID3, w).L, rtol=1e-14)
    assert isinstance(loop.plant, TransferFunction)
