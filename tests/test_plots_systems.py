"""Plots of any system and the plot bugs found by trying (issue 33).

References: closed forms (the phase of exp(-s)/(s+1) is -w - atan(w); the PI stability boundary of exp(-tau s)/s is
kp = w sin(w tau), ki = w^2 cos(w tau), from 1 + (kp + ki/s) exp(-tau s)/s = 0 at s = jw), the responses and
margins objects drawn (their own arrays), and the line colours matplotlib gave each response.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # inside the tests only: the library itself never chooses a backend

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_rgba  # noqa: E402

from delaykit import Controller, InvalidValueError, Loop, frequency_response, margins  # noqa: E402
from delaykit.plotting.frequency import plot_bode, plot_nyquist  # noqa: E402


def _loops():
    return [Loop("1/(s*(0.05*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=d) for d in (0.1, 0.2, 0.3)]


# ---- found by trying -------------------------------------------------------------------------------------------

def test_bode_margin_labels_take_their_own_loops_colour():
    """Three loops on one Bode plot, margins of the first: its labels and crossover lines are in the first
    loop's colour (they were in fixed green, the third loop's default colour)."""
    loops = _loops()
    fig = plot_bode([frequency_response(lp) for lp in loops], margins=margins(loops[0]), labels=["a", "b", "c"])
    ax_mag, ax_ph = fig.axes
    first = to_rgba(ax_mag.lines[0].get_color())
    third = to_rgba(ax_mag.lines[2].get_color())
    notes = [t for a in (ax_mag, ax_ph) for t in a.texts]
    assert {t.get_text()[:2] for t in notes} == {"PM", "GM"}
    assert all(to_rgba(t.get_color()) == first for t in notes)
    assert all(to_rgba(t.get_color()) != third for t in notes)


def test_bode_margins_one_per_loop():
    loops = _loops()
    fig = plot_bode([frequency_response(lp) for lp in loops], margins=[margins(lp) for lp in loops])
    ax_mag, ax_ph = fig.axes
    colours = [to_rgba(line.get_color()) for line in ax_mag.lines[:3]]
    pm = [to_rgba(t.get_color()) for t in ax_ph.texts if t.get_text().startswith("PM")]
    assert pm == colours
    with pytest.raises(InvalidValueError, match="2 given for 3"):
        plot_bode([frequency_response(lp) for lp in loops], margins=[margins(lp) for lp in loops[:2]])


def test_nyquist_default_view_is_the_neighbourhood_of_minus_one():
    """An integrating loop's curve starts at infinity: the default view is still the region around -1 (the unit
    circle around -1 spans at least 40 % of the width), not 4 units either side."""
    fig = plot_nyquist(frequency_response(_loops()[0]))
    lo, hi = fig.axes[0].get_xlim()
    ylo, yhi = fig.axes[0].get_ylim()
    assert lo <= -2.0 and hi >= 0.0 and ylo <= -1.0 and yhi >= 1.0
    assert 2.0 / (hi - lo) >= 0.4


def test_stable_region_edge_follows_the_exact_boundary():
    """tune --plot's stable region of PI gains on exp(-0.37 s)/s: its edge lies on the closed-form boundary
    (kp, ki) = (w sin(w tau), w^2 cos(w tau)) to 0.5 % of the span drawn; a staircase of half cells (the contour of
    the stable booleans) is 2 % off on this 21 x 21 grid."""
    from delaykit import tune
    from delaykit.plotting.tuning import plot_stable_region

    tau = 0.37
    t = tune("1/s", "pi", delay=tau, ms=1.4)
    fig = plot_stable_region(t, n=21)
    edge = [c for c in fig.axes[0].collections
            if len(c.get_edgecolor()) and to_rgba(c.get_edgecolor()[0]) == to_rgba("tab:green")]
    assert len(edge) == 1
    v = np.concatenate([p.vertices for p in edge[0].get_paths()])
    v = v[(v[:, 0] > 0) & (v[:, 1] > 0)]
    assert len(v) > 5
    w = np.linspace(1e-4, np.pi / (2 * tau), 40001)
    kp, ki = w * np.sin(w * tau), w ** 2 * np.cos(w * tau)
    d = np.min(np.hypot((v[:, :1] - kp) / (2.5 * t.kp), (v[:, 1:] - ki) / (2.5 * t.ki)), axis=1)
    assert d.max() < 0.005


def test_identified_model_title_is_one_line():
    """identify --plot's title: one line on the figure (the model's repr, with standard errors, wrapped to three)."""
    from delaykit.identify import Experiment, identify, predict
    from delaykit.plotting.identification import model_title, plot_predictions

    t = np.arange(0, 60.0, 0.5)
    u = np.where(t >= 5, 1.0, 0.0)
    e = Experiment.from_arrays(t, {"y": 2 * (1 - np.exp(-np.maximum(t - 8, 0) / 10))}, u=u)
    m = identify(e, model="fopdt")
    fig = plot_predictions([predict(m, e)], title=model_title(m))
    title = fig.axes[0].get_title()
    assert "\n" not in title and "±" not in title
    assert title.startswith("fopdt: gain 2, time constant 10 s, delay 3 s")


def test_a_sum_with_a_delay_keeps_its_phase_falling_between_sparse_frequencies():
    """frequency_response of exp(-s)/(s+1) + 0.5/(s+2) (not one rational function times one delay) at two
    frequencies 6 decades apart: the phase at 1e3 rad/s is -w - atan(w) + arg(1 + 0.5 (jw+1)/(jw+2) exp(jw)) (closed
    form), thousands of degrees below what unwrapping the two given points alone gives."""
    from delaykit import tf

    w = 1e3
    ref = np.degrees(-w - np.arctan(w) + np.angle(1 + 0.5 * (1j * w + 1) / (1j * w + 2) * np.exp(1j * w)))
    r = frequency_response(tf("exp(-s)/(s+1)") + tf("0.5/(s+2)"), [1e-3, w])
    assert r.phase_deg[1] == pytest.approx(ref, abs=1e-6)


# ---- plots of any system ---------------------------------------------------------------------------------------

def _wood_berry():
    from delaykit import tf

    return tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
               ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]],
              inputs=["R", "S"], outputs=["xD", "xB"], name="Wood-Berry")


def _wood_berry_closed_form(w):
    """Wood and Berry's G(jw) written out by hand (numpy only), shaped (len(w), 2, 2)."""
    s = 1j * np.asarray(w, float)
    return np.stack([np.stack([12.8 * np.exp(-s) / (16.7 * s + 1), -18.9 * np.exp(-3 * s) / (21 * s + 1)], -1),
                     np.stack([6.6 * np.exp(-7 * s) / (10.9 * s + 1), -19.4 * np.exp(-3 * s) / (14.4 * s + 1)], -1)],
                    -2)


def test_bode_phase_of_a_delay_is_exact_over_many_decades_on_a_sparse_grid():
    """exp(-s)/(s+1) on 6 points over 5 decades: the plotted phase is -w - atan(w) in degrees at each, unwrapped
    (no Padé, no unwrapping between points 10 times apart), -57386 degrees at 1e3 rad/s."""
    from delaykit import tf
    from delaykit.plotting import bode_plot

    w = np.geomspace(1e-2, 1e3, 6)
    fig = bode_plot(tf("exp(-s)/(s+1)"), w)
    ax_mag, ax_ph = fig.axes
    assert np.allclose(ax_ph.lines[0].get_ydata(), np.degrees(-w - np.arctan(w)), rtol=0, atol=1e-8)
    assert np.allclose(ax_mag.lines[0].get_ydata(), -10 * np.log10(1 + w ** 2), rtol=0, atol=1e-10)
    assert "dB" in ax_mag.get_ylabel() and "deg" in ax_ph.get_ylabel() and "rad/s" in ax_ph.get_xlabel()


def test_bode_of_a_mimo_system_draws_each_element_exactly():
    """Wood-Berry's 2 x 2: panels titled by input, labelled by output; element (xB, R) = 6.6 exp(-7s)/(10.9s+1)
    against its closed form: magnitude, and phase -7w - atan(10.9w) unwrapped to 10 rad/s (-4100 degrees)."""
    from delaykit.plotting import bode_plot

    w = np.geomspace(1e-3, 10.0, 50)
    fig = bode_plot(_wood_berry(), w)
    assert len(fig.axes) == 8
    grid = np.array(fig.axes).reshape(4, 2)
    assert [a.get_title() for a in grid[0]] == ["from R", "from S"]
    assert grid[0, 0].get_ylabel().startswith("to xD") and grid[2, 0].get_ylabel().startswith("to xB")
    H = _wood_berry_closed_form(w)
    for i in range(2):
        for j in range(2):
            assert np.allclose(grid[2 * i, j].lines[0].get_ydata(), 20 * np.log10(np.abs(H[:, i, j])), atol=1e-9)
    assert np.allclose(grid[3, 0].lines[0].get_ydata(), np.degrees(-7 * w - np.arctan(10.9 * w)), atol=1e-8)
    ph = grid[1, 1].lines[0].get_ydata()  # -18.9 exp(-3s)/(21s+1): -180 - 3w - atan(21w) modulo 360, continuous
    d = (ph - np.degrees(-np.pi - 3 * w - np.arctan(21 * w))) / 360.0
    assert np.allclose(d, np.round(d[0]), atol=1e-9)


def test_bode_margins_of_a_system_loop():
    """bode_plot(L, margins=True) marks the margins that margins(L) gives, at its crossovers."""
    from delaykit import tf
    from delaykit.plotting import bode_plot

    L = tf("2*exp(-0.5*s)/(s+1)")
    m = margins(L)
    fig = bode_plot(L, margins=True)
    xs = sorted({float(line.get_xdata()[0]) for line in fig.axes[1].lines[1:] if len(set(line.get_xdata())) == 1})
    assert np.allclose(xs, sorted([m.crossover, m.phase_crossover]))
    assert any(t.get_text().startswith(f"PM {m.phase_margin:.1f}") for t in fig.axes[1].texts)


def test_nyquist_plot_counts_encirclements_and_draws_the_ms_circle():
    """exp(-2s)/s closes into 2 unstable poles (Lambert: s exp(2s) = -1 has W_0 and W_-1 right of the axis):
    the title gives Z = 2; exp(-0.5s)/s is stable and its circle has radius 1/Ms of margins()."""
    from delaykit import tf
    from delaykit.plotting import nyquist_plot

    fig = nyquist_plot(tf("exp(-2*s)/s"))
    assert "Z = P - N = 2 (UNSTABLE)" in fig.axes[0].get_title()
    L = tf("exp(-0.5*s)/s")
    fig = nyquist_plot(L)
    a = fig.axes[0]
    assert a.get_title() == "N = 0 encirclements of -1, P = 0: Z = P - N = 0 (stable)"
    circle = [line for line in a.lines if line.get_label().startswith("|1 + L|")]
    assert len(circle) == 1
    xy = circle[0].get_xydata()
    assert np.allclose(np.hypot(xy[:, 0] + 1, xy[:, 1]), 1 / margins(L).ms)
    lo, hi = a.get_xlim()
    assert lo < -1 - 1 / margins(L).ms and hi > 0
    with pytest.raises(InvalidValueError, match="SISO"):
        nyquist_plot(_wood_berry())


def test_sigma_plot_against_numpys_svd_of_the_closed_form():
    from delaykit.plotting import sigma_plot

    w = np.geomspace(1e-3, 10.0, 40)
    fig = sigma_plot(_wood_berry(), w)
    sv = np.linalg.svd(_wood_berry_closed_form(w), compute_uv=False)
    lines = fig.axes[0].lines
    assert [line.get_label() for line in lines[:2]] == ["σ1", "σ2"]
    for k in range(2):
        assert np.allclose(lines[k].get_ydata(), 20 * np.log10(sv[:, k]), atol=1e-9)


def test_nichols_plot_exact_phase_and_critical_points():
    """exp(-s)/(s+1): x is -w - atan(w) in degrees, y -10 log10(1 + w^2); the critical points (-180 + 360k, 0) in
    the range are marked."""
    from delaykit import tf
    from delaykit.plotting import nichols_plot

    w = np.array([0.1, 1.0, 10.0, 100.0])
    a = nichols_plot(tf("exp(-s)/(s+1)"), w).axes[0]
    xy = a.lines[0].get_xydata()
    assert np.allclose(xy[:, 0], np.degrees(-w - np.arctan(w)), atol=1e-8)
    assert np.allclose(xy[:, 1], -10 * np.log10(1 + w ** 2), atol=1e-10)
    crit = [line for line in a.lines if line.get_label() == "critical points"][0].get_xdata()
    lo = np.degrees(-100 - np.arctan(100))
    assert sorted(crit) == [-180.0 + 360.0 * k for k in range(int(np.ceil((lo + 180) / 360)), 1)]


def test_step_grid_titles_by_signal_names_and_draws_the_exact_steps():
    """A 1 x 2 system: panels "from a", "from b", "to y"; exp(-s)/(s+1)'s step is 1 - exp(-(t - 1)) after t = 1."""
    from delaykit import tf
    from delaykit.plotting import step_grid

    t = np.linspace(0.0, 5.0, 11)
    fig = step_grid(tf([["exp(-s)/(s+1)", "0.5/(2*s+1)"]], inputs=["a", "b"], outputs="y"), t)
    a, b = fig.axes
    assert (a.get_title(), b.get_title(), a.get_ylabel(), a.get_xlabel()) == ("from a", "from b", "to y", "time (s)")
    assert np.allclose(a.lines[0].get_ydata(), np.where(t > 1, 1 - np.exp(-(t - 1)), 0.0), atol=1e-12)
    assert np.allclose(b.lines[0].get_ydata(), 0.5 * (1 - np.exp(-t / 2)), atol=1e-12)


def test_pole_map_draws_certified_poles_region_and_neutral_lines():
    """feedback(exp(-0.5s)/s, 1): the rightmost poles are W_0(-0.5)/0.5 and its conjugate (Lambert W, scipy);
    feedback(1/(s+1) + 0.6 exp(-0.5s), 1) is neutral: its root chains approach Re s = 2 ln 0.6 (the roots of
    1 + 0.6 exp(-s/2) = 0)."""
    from scipy.special import lambertw

    from delaykit import feedback, tf
    from delaykit.plotting import pole_map

    fig = pole_map(feedback(tf("exp(-0.5*s)/s"), 1))
    a = fig.axes[0]
    pts = a.lines[0].get_xydata()
    s0 = complex(lambertw(-0.5, 0)) / 0.5
    assert np.min(np.abs(pts[:, 0] + 1j * pts[:, 1] - s0)) < 1e-8
    assert np.min(np.abs(pts[:, 0] + 1j * pts[:, 1] - np.conj(s0))) < 1e-8
    assert "certified" in a.get_title() and "NOT" not in a.get_title()
    region = [line for line in a.lines if line.get_label() == "region searched"]
    assert len(region) == 1
    fig = pole_map(feedback(tf("1/(s+1)") + tf("0.6*exp(-0.5*s)"), 1), (-3.0, 1.0, 0.0, 30.0))
    lines = [line for line in fig.axes[0].lines if line.get_label() == "neutral root chains"]
    assert len(lines) == 1 and lines[0].get_xdata()[0] == pytest.approx(2 * np.log(0.6), abs=1e-6)


def test_plots_refuse_what_they_cannot_draw():
    from delaykit import InvalidTypeError
    from delaykit.plotting import bode_plot, pole_map, step_grid

    with pytest.raises(InvalidTypeError, match="DelayLTI"):
        bode_plot("exp(-s)/(s+1)")
    with pytest.raises(InvalidTypeError, match="DelayLTI"):
        step_grid([1.0, 2.0])
    with pytest.raises(InvalidTypeError, match="Spectrum"):
        pole_map(3.0)
    with pytest.raises(InvalidValueError, match="margins"):
        bode_plot(_wood_berry(), margins=True)


# ---- --plot with --system on the command line ------------------------------------------------------------------

def test_cli_margins_and_roots_of_a_system_file_draw_a_figure(tmp_path):
    """margins --system and roots --system write their figures (the Wood-Berry file, two break signals); the output
    path is checked before the file is read (a missing folder is refused even when the system file is missing)."""
    from pathlib import Path

    from typer.testing import CliRunner

    from delaykit.cli.app import app

    wb = str(Path(__file__).resolve().parents[1] / "examples" / "wood-berry.toml")
    runner = CliRunner()
    fig = tmp_path / "m.png"
    res = runner.invoke(app, ["margins", "--system", wb, "--plot", str(fig)])
    assert res.exit_code == 0, res.output
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    fig = tmp_path / "r.svg"
    res = runner.invoke(app, ["roots", "--system", wb, "--region", "-0.5", "0.1", "0", "2", "--plot", str(fig)])
    assert res.exit_code == 0, res.output
    assert fig.read_text().lstrip().startswith("<?xml")
    for cmd in ("margins", "roots"):
        res = runner.invoke(app, [cmd, "--system", str(tmp_path / "missing.toml"),
                                  "--plot", str(tmp_path / "no" / "such" / "folder" / "f.png")])
        assert res.exit_code == 2 and "does not exist" in res.output and "missing.toml" not in res.output


def test_a_system_response_plots_itself():
    """sys.frequency_response(w).plot(), as python-control's response.plot(): the magnitude of exp(-s)/(s+1) at
    its frequencies (closed form -10 log10(1 + w^2)); kind="sigma" its singular values; anything else refused."""
    from delaykit import tf

    w = np.array([0.1, 1.0, 10.0])
    r = tf("exp(-s)/(s+1)").frequency_response(w)
    fig = r.plot()
    assert np.allclose(fig.axes[0].lines[0].get_ydata(), -10 * np.log10(1 + w ** 2), atol=1e-10)
    assert len(_wood_berry().frequency_response(w).plot(kind="sigma").axes[0].lines) >= 2
    with pytest.raises(InvalidValueError, match="kind"):
        r.plot(kind="nyquist")


def test_a_loop_object_draws_as_its_open_loop_with_its_count():
    """A Loop is drawn as its L: its Nyquist title gives margins()'s count, and the same loop written as a system
    (C * G) gets the same title from nyquist_count."""
    from delaykit import tf
    from delaykit.plotting import nyquist_plot

    loop = Loop("1/(s*(0.05*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=0.1)
    m = margins(loop)
    title = nyquist_plot(loop).axes[0].get_title()
    assert title == (f"N = {m.encirclements} encirclements of -1, P = {m.open_loop_rhp_poles}: "
                     f"Z = P - N = {m.nyquist_rhp_roots} (stable)")
    assert nyquist_plot(tf("2.0*exp(-0.37*s)/s")).axes[0].get_title().endswith("(stable)")


@pytest.mark.slow
def test_plots_benchmark_runs(tmp_path):
    """benchmarks/bench_plots.py runs once through (no timing asserted): three rows, each beside python-control's,
    and the Padé model's phase falls short of the exact one over the range (order 10, the 3-minute delay to 10
    rad/min: 30 rad of delay phase, beyond what a 10th-order Padé follows)."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "p.json"
    env = {**os.environ, "PYTHONPATH": str(root / "src") + os.pathsep + os.environ.get("PYTHONPATH", "")}
    subprocess.run([sys.executable, str(root / "benchmarks" / "bench_plots.py"), "--repeat", "1", "--json", str(out)],
                   check=True, capture_output=True, text=True, env=env, timeout=600)
    res = json.loads(out.read_text())
    assert len(res["rows"]) == 3 and all("control_s" in r for r in res["rows"])
    assert res["pade_phase_error_deg"] > 90.0


def test_a_loop_response_plots_itself():
    """frequency_response(loop).plot(kind=...): the Bode phase is the response's own (exact) phase; Nyquist and
    Nichols draw the same L."""
    fr = frequency_response(_loops()[0])
    fig = fr.plot()
    keep = fr.w > 0
    assert np.array_equal(fig.axes[1].lines[0].get_ydata(), fr.phase_deg[keep])
    assert np.array_equal(fr.plot(kind="nichols").axes[0].lines[0].get_xdata(), fr.phase_deg[keep])
    assert fr.plot(kind="nyquist").axes[0].get_xlabel() == "Re L(jω)"
    with pytest.raises(InvalidValueError, match="kind"):
        fr.plot(kind="sigma")


def test_nyquist_of_a_loop_without_a_count_still_draws_and_says_why():
    """1/(s+1) + exp(-s) has a delayed direct feedthrough: nyquist_count refuses it (no finite count) and margins
    gives no verdict; the curve is drawn, the title says why there is no count."""
    from delaykit import tf
    from delaykit.plotting import nyquist_plot

    a = nyquist_plot(tf("1/(s+1)") + tf("exp(-s)")).axes[0]
    assert a.get_title().startswith("no Nyquist count: ") and "feedthrough" in a.get_title()
    assert len(a.lines[0].get_xdata()) > 100
