"""The figures show what they are given: each line's data against the arrays it was drawn from, the labels, the
number of series, the axes used, the files written only when asked; and importing the plotting layer leaves
matplotlib's backend alone.  References: the Response, Spectrum, StabilityMap and FlightLog objects drawn (their
own arrays), and closed forms (the derivative filter's gain, its -3 dB frequency)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from delaykit import AltitudeLoop, Controller, InvalidTypeError, InvalidValueError, Loop, simulate
from delaykit.models.signals import Ramp
from delaykit.plotting.figures import (plot_filter_bode, plot_fit, plot_iterations, plot_responses, plot_spectrum,
                                       plot_stability_map, save_figure)
from delaykit.plotting.compensation import plot_robustness_map

SRC = Path(__file__).resolve().parents[1] / "src"


def _lines(ax: Axes, label: str):
    return [line for line in ax.lines if line.get_label() == label]


# ---- the backend -----------------------------------------------------------------------------------------------

def test_importing_and_drawing_leave_the_backend_and_pyplot_alone(tmp_path):
    """A user's backend (here svg, set the way a notebook or an application sets it) is still in force after
    importing delaykit's plotting layer and drawing and saving a figure; no figure is registered with pyplot."""
    script = f"""
import json, sys
import matplotlib
before = matplotlib.get_backend()
import delaykit.plotting
from delaykit import AltitudeLoop, simulate
from delaykit.plotting.figures import plot_responses
after_import = matplotlib.get_backend()
fig = plot_responses([simulate(AltitudeLoop(kp=1.31, delay=0.368), t_end=3.0)], {str(tmp_path / "r.png")!r})
pyplot = sys.modules.get("matplotlib.pyplot")
print(json.dumps({{"before": before, "after_import": after_import, "after_plot": matplotlib.get_backend(),
                  "pyplot_figures": pyplot.get_fignums() if pyplot else [], "canvas": type(fig.canvas).__name__}}))
"""
    env = {**os.environ, "MPLBACKEND": "svg", "PYTHONPATH": str(SRC) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout.strip().splitlines()[-1])
    assert got["before"] == got["after_import"] == got["after_plot"] == "svg"
    assert got["pyplot_figures"] == []
    assert (tmp_path / "r.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"  # the file is a PNG whatever the backend


# ---- responses ---------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def responses():
    return [simulate(AltitudeLoop(kp=1.31, delay=0.368), 1.0, t_end=5.0),
            simulate(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3), 1.0, t_end=5.0)]


def test_plot_responses_draws_each_response_and_the_reference(responses):
    fig = plot_responses(responses, dt=0.01)
    assert isinstance(fig, Figure) and len(fig.axes) == 2
    top, bottom = fig.axes
    # one line per response in each panel, labelled by its loop (the default), plus the reference on top
    assert [ln.get_label() for ln in top.lines] == ["Td=0.368 s", "Td=0.37 s, Kv=0.3", "reference"]
    assert [ln.get_label() for ln in bottom.lines] == ["Td=0.368 s", "Td=0.37 s, Kv=0.3"]
    for i, r in enumerate(responses):
        s = r.sample(dt=0.01)
        assert np.array_equal(top.lines[i].get_xdata(), s["t"]) and np.array_equal(top.lines[i].get_ydata(), s["z"])
        assert np.array_equal(bottom.lines[i].get_ydata(), s["u"])
        assert top.lines[i].get_color() == bottom.lines[i].get_color()
    assert np.array_equal(top.lines[2].get_ydata(), responses[0].sample(dt=0.01)["z_ref"])
    # the settling band of the first response: 1 +- 2 %
    band = [p for p in top.patches if "band" in p.get_label()]
    assert len(band) == 1
    lo, hi = band[0].get_y(), band[0].get_y() + band[0].get_height()  # a rectangle in data units along y
    assert math.isclose(lo, 0.98) and math.isclose(hi, 1.02)
    assert top.get_ylabel() == "altitude z (m)" and bottom.get_ylabel() == "command u (m/s)"


def test_plot_responses_into_given_axes_and_labels(responses):
    host = Figure()
    a, b = host.subplots(1, 2)
    fig = plot_responses(responses, ax=(a, b), labels=["P", "PV"], title="two loops", t_max=4.0)
    assert fig is a.figure is host and len(host.axes) == 2  # drawn where asked, nothing added
    assert [ln.get_label() for ln in a.lines][:2] == ["P", "PV"] and a.get_title() == "two loops"
    assert len(b.lines) == 2 and a.get_xlim() == (-0.2, 4.0)
    # one Axes: the output only
    single = Figure().subplots()
    fig = plot_responses(responses[:1], ax=single)
    assert fig is single.figure and len(fig.axes) == 1 and len(single.lines) == 2  # the response and the reference
    with pytest.raises(InvalidValueError, match="labels must name each of the 2 responses, got 1"):
        plot_responses(responses, labels=["only one"])
    with pytest.raises(InvalidTypeError, match="ax must be a matplotlib Axes"):
        plot_responses(responses, ax="top")
    with pytest.raises(InvalidValueError, match="2 panel"):
        plot_responses(responses, ax=Figure().subplots(1, 3))


def test_plot_responses_of_a_general_loop_and_a_ramp():
    # a general Loop has no .kv of its own (the default label reads the controller's); a ramp has no step metrics
    pd = simulate(Loop("1/(s*(0.05*s+1))", Controller.pd(2.0, 0.1, 0.02), delay=0.3, umin=-1, umax=3), 1.0, t_end=4.0)
    pv = simulate(Loop("1/s", Controller.pv(2.0, 0.3), delay=0.3), 1.0, t_end=4.0)
    fig = plot_responses([pd, pv])
    assert [ln.get_label() for ln in fig.axes[0].lines][:2] == ["Td=0.3 s", "Td=0.3 s, Kv=0.3"]
    ramp = simulate(AltitudeLoop(kp=1.31, delay=0.368), reference=Ramp(slope=0.2), t_end=4.0)
    assert ramp.metrics is None
    fig = plot_responses([ramp], dt=0.5)
    ref = _lines(fig.axes[0], "reference")[0]
    assert np.allclose(ref.get_ydata(), 0.2 * np.arange(0, 4.01, 0.5))  # the ramp itself
    assert not [p for p in fig.axes[0].patches if "band" in p.get_label()]


def test_files_are_written_only_when_asked(tmp_path, monkeypatch, responses):
    monkeypatch.chdir(tmp_path)
    plot_responses(responses)
    assert list(tmp_path.iterdir()) == []
    fig = plot_responses(responses, tmp_path / "deep" / "r.svg")
    assert (tmp_path / "deep" / "r.svg").read_text().lstrip().startswith("<?xml")
    assert save_figure(fig, None) is fig and save_figure(fig, tmp_path / "r.pdf").figure is fig
    assert (tmp_path / "r.pdf").read_bytes()[:5] == b"%PDF-"
    # axes on a subfigure: the whole figure is written
    sub = Figure().subfigures(1, 2)[0]
    fig = plot_responses(responses, tmp_path / "sub.png", ax=sub.subplots())
    assert fig is sub and (tmp_path / "sub.png").read_bytes()[:4] == b"\x89PNG"


def test_bode_and_nyquist_write_files_only_when_asked(tmp_path, monkeypatch):
    """plot_bode and plot_nyquist take a path like the other plot functions: nothing is written without one; with
    one, the file (format by suffix, folder created) is the figure returned, drawn from the response given (read
    back: the PNG's pixel size is the figure's size times save_figure's dpi, and the SVG holds the axis labels)."""
    import matplotlib.image

    from delaykit import frequency_response, margins
    from delaykit.plotting.figures import DPI
    from delaykit.plotting.frequency import plot_bode, plot_nyquist

    monkeypatch.chdir(tmp_path)
    loop = AltitudeLoop(kp=1.31, delay=0.368)
    resp = frequency_response(loop)
    plot_bode(resp, margins=margins(loop))
    plot_nyquist(resp)
    assert list(tmp_path.iterdir()) == []
    fig = plot_bode(resp, tmp_path / "deep" / "bode.png", margins=margins(loop))
    img = matplotlib.image.imread(tmp_path / "deep" / "bode.png")
    w, h = fig.get_size_inches() * DPI
    assert img.shape[:2] == (round(h), round(w))
    # the magnitude drawn is the response's own, in dB
    assert np.allclose(fig.axes[0].lines[0].get_ydata(), resp.magnitude_db[resp.w > 0])
    fig = plot_nyquist(resp, path=tmp_path / "n.svg")
    text = (tmp_path / "n.svg").read_text()
    assert text.lstrip().startswith("<?xml") and "Re L(jω)" in text
    assert np.allclose(fig.axes[0].lines[0].get_xdata(), np.where(np.abs(resp.L) <= 4e3, resp.L, np.nan).real,
                       equal_nan=True)
    # axes given: the whole figure they belong to is written
    outer = Figure()
    a, b, c = outer.subplots(3, 1)
    plot_bode(resp, tmp_path / "two.pdf", axes=(a, b))
    plot_nyquist(resp, tmp_path / "three.pdf", ax=c)
    assert (tmp_path / "two.pdf").read_bytes()[:5] == b"%PDF-" and (tmp_path / "three.pdf").read_bytes()[:5] == b"%PDF-"


# ---- spectra, maps, fits, the filter, the iterations ------------------------------------------------------------

def test_plot_spectrum_shows_each_spectrum_its_rightmost_and_its_neutral_lines():
    from delaykit.spectrum.roots import find_roots

    spectra = [find_roots(AltitudeLoop(kp=2.0, delay=0.37, kv=kv).characteristic(), (-10, 2, 0, 60))
               for kv in (0.3, 0.5)]
    ax = Figure().subplots()
    fig = plot_spectrum(spectra, ax=ax, labels=["Kv = 0.3", "Kv = 0.5"], title="Fig. 8")
    assert fig is ax.figure and ax.get_title() == "Fig. 8"
    for sp, lab in zip(spectra, ["Kv = 0.3", "Kv = 0.5"]):
        (series,) = _lines(ax, lab)
        assert np.array_equal(series.get_xdata(), sp.roots.real) and np.array_equal(series.get_ydata(), sp.roots.imag)
        # its rightmost root, enlarged, in its colour
        big = [ln for ln in ax.lines if ln.get_markersize() == 9 and ln.get_color() == series.get_color()]
        assert len(big) == 1 and big[0].get_xdata()[0] == sp.rightmost.real
        # its neutral line ln(Kv) / Td, dashed, in its colour
        vertical = [ln.get_xdata()[0] for ln in ax.lines
                    if ln.get_linestyle() == "--" and ln.get_color() == series.get_color()]
        assert vertical == pytest.approx([math.log(float(lab.split()[-1])) / 0.37], abs=1e-6)
    assert ax.get_xlim() == (-10, 2) and ax.get_ylim() == (0, 60)


def test_plot_stability_map_shows_the_clipped_abscissa_and_the_boundary():
    from delaykit.spectrum.stability import stability_map

    m = stability_map(AltitudeLoop(kp=1, delay=0.3), "kp", np.linspace(0.5, 6, 12), "delay", np.linspace(0.1, 0.8, 8))
    fig = plot_stability_map(m, title="P loop")
    ax = fig.axes[0]
    mesh, boundary = ax.collections
    assert np.allclose(np.asarray(mesh.get_array()).reshape(m.abscissa.shape), np.clip(m.abscissa, -10, 10))
    # the boundary: the zero level, which for the P loop is Kp Td = pi / 2 (closed form; the contour interpolates
    # linearly between grid points 0.5 apart in Kp and 0.1 s in Td, hence the 6 % tolerance)
    assert list(boundary.levels) == [0.0]
    kp_td = np.prod(np.concatenate([p.vertices for p in boundary.get_paths()]), axis=1)
    assert kp_td.size > 3 and np.allclose(kp_td, math.pi / 2, rtol=0.06)
    assert len(fig.axes) == 2 and fig.axes[1].get_ylabel() == "spectral abscissa (1/s)"  # the colour bar
    assert (ax.get_xlabel(), ax.get_ylabel(), ax.get_title()) == ("kp", "delay", "P loop")


def test_plot_fit_shows_data_model_and_difference():
    from delaykit.identify.flightlog import synthetic_log

    logs = [synthetic_log(AltitudeLoop(kp=1.31, delay=d), 1.0, after=4.0, noise=0.003, rng=np.random.default_rng(i),
                          t0=10.0) for i, d in enumerate((0.35, 0.4))]
    fits = [(lg.t, lg.z_ref + 0.001) for lg in logs]
    fig = plot_fit(logs, fits, title="fit")
    top, bottom = fig.axes
    assert len(top.lines) == 4 and len(bottom.lines) == 2 + 1  # data and model per flight; differences and zero
    for i, lg in enumerate(logs):
        data, model = top.lines[2 * i], top.lines[2 * i + 1]
        assert np.array_equal(data.get_xdata(), lg.t - lg.step_time) and np.array_equal(data.get_ydata(), lg.z)
        assert np.array_equal(model.get_ydata(), fits[i][1])
        assert np.allclose(bottom.lines[i].get_ydata(), 1e3 * (lg.z - fits[i][1]))
        assert model.get_color() == data.get_color() == bottom.lines[i].get_color()
    with pytest.raises(InvalidValueError, match="one fit per flight: 2 flights, 1 fits"):
        plot_fit(logs, fits[:1])
    with pytest.raises(InvalidValueError, match="at the log's"):
        plot_fit(logs[:1], [(logs[0].t[:-1], logs[0].z[:-1])])
    ax = Figure().subplots()
    assert plot_fit(logs, fits, ax=ax) is ax.figure and len(ax.lines) == 4


def test_plot_filter_bode_against_the_closed_form():
    from delaykit.design.tuning import filter_analysis

    rep = filter_analysis(38.0, 1.0)
    fig = plot_filter_bode(rep)
    gain, phase = fig.axes
    w = gain.lines[0].get_xdata()
    # W(jw) / (jw) = wf^2 / (wf^2 - w^2 + 2j zf wf w): |.| = wf^2 / (wf^2 + w^2) at zf = 1, phase -2 atan(w / wf)
    assert np.allclose(gain.lines[0].get_ydata(), 20 * np.log10(38.0**2 / (38.0**2 + w**2)), atol=1e-10)
    assert np.allclose(phase.lines[0].get_ydata(), -2 * np.degrees(np.arctan(w / 38.0)), atol=1e-9)
    cutoff = [ln for ln in gain.lines if ln.get_label().startswith("-3 dB")]
    assert cutoff[0].get_xdata()[0] == pytest.approx(38.0 * math.sqrt(math.sqrt(2) - 1), rel=1e-6)
    one = Figure().subplots()
    assert plot_filter_bode(rep, ax=one) is one.figure and len(one.figure.axes) == 1


def test_plot_iterations_shows_both_parts():
    from delaykit.identify.estimation import lambert_paper_iterations

    it = lambert_paper_iterations(complex(-1.2347, 1.0284), 1.31)
    fig = plot_iterations(it, reference=0.374, reference_label="paper")
    ax = fig.axes[0]
    assert np.array_equal(_lines(ax, "Re Td")[0].get_ydata(), np.real(it))
    assert np.array_equal(_lines(ax, "Im Td")[0].get_ydata(), np.imag(it))
    assert _lines(ax, "paper: 0.374 s")[0].get_ydata()[0] == 0.374


# ---- compensation: the robustness map and the delay watched in flight; identification: predictions ----------------

def _robustness_map():
    """A map whose abscissa is a plane, 4 (d - g) + 0.2: zero on the line d = g - 0.05 (closed form; a contour of a
    linear function interpolated linearly is exact), and beyond +-5 in two corners (the colour scale spans it)."""
    from delaykit.design.compensators import RobustnessMap

    d, g = np.linspace(0.5, 2.0, 7), np.linspace(0.5, 2.0, 4)
    return RobustnessMap(d, g, 4.0 * (d[:, None] - g[None, :]) + 0.2, "smith")


def test_plot_robustness_map_shows_the_abscissa_the_boundary_and_the_design_point():
    rmap = _robustness_map()
    fig = plot_robustness_map(rmap)
    assert isinstance(fig, Figure) and len(fig.axes) == 2  # the map and its colour bar
    ax, bar = fig.axes
    mesh, boundary = ax.collections
    assert np.abs(rmap.abscissa).max() > 5  # beyond the former fixed +-5 scale
    assert np.array_equal(np.asarray(mesh.get_array()).reshape(rmap.abscissa.shape), rmap.abscissa)
    top = float(np.abs(rmap.abscissa).max())  # a symmetric scale as wide as the data
    assert (mesh.norm.vmin, mesh.norm.vmax) == (-top, top)
    # each cell is centred on its (gain ratio, delay ratio): the mean of its four corners
    corners = mesh.get_coordinates()
    centres = 0.25 * (corners[:-1, :-1] + corners[1:, :-1] + corners[:-1, 1:] + corners[1:, 1:])
    g, d = np.meshgrid(rmap.gain_ratios, rmap.delay_ratios)
    assert np.allclose(centres[..., 0], g) and np.allclose(centres[..., 1], d)
    assert list(boundary.levels) == [0.0]
    vertices = np.concatenate([p.vertices for p in boundary.get_paths()])
    assert len(vertices) >= 2 and np.allclose(vertices[:, 1], vertices[:, 0] - 0.05)
    (star,) = _lines(ax, "design point")
    assert (star.get_xdata().tolist(), star.get_ydata().tolist(), star.get_marker()) == ([1.0], [1.0], "*")
    assert len(ax.lines) == 1
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("true / model gain", "true / model delay")
    assert ax.get_title().startswith("smith:") and bar.get_ylabel().startswith("rightmost root real part")
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["design point"]


def test_plot_robustness_map_into_given_axes_and_without_a_boundary():
    from delaykit.design.compensators import RobustnessMap

    host = Figure()
    ax = host.subplots()
    fig = plot_robustness_map(_robustness_map(), ax=ax, title="Smith predictor")
    assert fig is host and ax.get_title() == "Smith predictor" and len(host.axes) == 2  # ax and its colour bar
    # stable everywhere: the map, no boundary
    d, g = np.array([0.9, 1.0, 1.1]), np.array([0.9, 1.1])
    stable = RobustnessMap(d, g, -np.ones((3, 2)), "smith")
    one = Figure().subplots()
    plot_robustness_map(stable, ax=one)
    assert len(one.collections) == 1 and np.array_equal(np.asarray(one.collections[0].get_array()).ravel(),
                                                        -np.ones(6))
    # a real map, small (the module's example): what is drawn is its own abscissa
    from delaykit.design.compensators import robustness_map
    from delaykit.models.compensators import Compensator

    real = robustness_map(Compensator.smith("1/s", 0.37), [0.8, 1.0, 1.2], [0.9, 1.1])
    fig = plot_robustness_map(real)
    assert np.array_equal(np.asarray(fig.axes[0].collections[0].get_array()).reshape(3, 2), real.abscissa)


def test_plot_robustness_map_of_a_slow_plant_scales_its_colours_to_the_data():
    # a heater's roots lie within a few 0.001 1/s of the axis: on the former fixed +-5 1/s scale every cell was
    # white (|a| / 5 < 0.1 %); the scale now spans the data, so the extreme cells take the extreme colours
    from delaykit.design.compensators import RobustnessMap

    d, g = np.linspace(0.5, 2.0, 7), np.linspace(0.5, 2.0, 4)
    a = 0.004 * (d[:, None] - g[None, :]) + 0.0002
    fig = plot_robustness_map(RobustnessMap(d, g, a, "smith"))
    mesh = fig.axes[0].collections[0]
    top = float(np.abs(a).max())
    assert (mesh.norm.vmin, mesh.norm.vmax) == (-top, top)
    rgba = mesh.to_rgba(np.asarray(mesh.get_array()))
    assert np.ptp(rgba[..., :3]) > 0.5  # far from one white

def _online():
    """Three steps of a flight (the monitor's own records): in range, an alarm, and a design range open upwards."""
    from delaykit.hardware.monitor import OnlineEstimate
    from delaykit.identify.online import WindowEstimate

    def window(delay, ci, t_from, t_to):
        return WindowEstimate(delay=delay, stderr=0.01, ci=ci, lag=0.0, gain=1.0, samples=100, rms=0.01,
                              t_from=t_from, t_to=t_to)

    return [OnlineEstimate(1, 14.0, window(0.30, (0.28, 0.33), 110.0, 114.0), (0.2, 0.35), (0.0, 1.0), False),
            OnlineEstimate(2, 19.0, window(0.50, (0.45, 0.56), 115.0, 119.0), (0.2, 0.35), (0.0, 1.0), True),
            OnlineEstimate(3, 24.0, window(0.31, (0.29, 0.34), 120.0, 124.0), (0.2, 9.0), (0.0, 1.0), False)]


def test_plot_online_shows_each_estimate_its_interval_window_and_design_range():
    from delaykit.plotting.compensation import plot_online

    online = _online()
    fig = plot_online(online, t0=100.0, truth=[(0.0, 0.3), (16.0, 0.5)])
    assert isinstance(fig, Figure) and len(fig.axes) == 1
    ax = fig.axes[0]
    bars = ax.containers
    assert len(bars) == len(online)  # one estimate with its interval per step
    fills = [c for c in ax.collections if type(c).__name__ != "LineCollection"]
    assert len(fills) == len(online)
    for o, bar, fill in zip(online, bars, fills):
        a, b = o.estimate.t_from - 100.0, o.estimate.t_to - 100.0
        colour = "tab:red" if o.alarm else "tab:blue"
        point, _, (segment,) = bar
        assert point.get_xdata().tolist() == [0.5 * (a + b)] and point.get_ydata().tolist() == [o.delay]
        assert point.get_color() == colour
        assert np.allclose(segment.get_segments()[0], [[0.5 * (a + b), o.estimate.ci[0]],
                                                       [0.5 * (a + b), o.estimate.ci[1]]])
        # the window: a level line over [t_from, t_to] at the estimate
        (level,) = [ln for ln in ax.lines if ln.get_xdata().tolist() == [a, b]]
        assert level.get_ydata().tolist() == [o.delay, o.delay] and level.get_color() == colour
        # the design range shaded over the window, cut at 5 s when open upwards
        box = fill.get_paths()[0].vertices
        assert box[:, 0].min() == a and box[:, 0].max() == b
        assert box[:, 1].min() == o.design_range[0] and box[:, 1].max() == min(o.design_range[1], 5.0)
    # the truth, a step function held to the last window's end (24 s > 16 s + 1 s)
    (truth,) = _lines(ax, "true delay")
    assert truth.get_xdata().tolist() == [0.0, 16.0, 24.0] and truth.get_ydata().tolist() == [0.3, 0.5, 0.5]
    assert truth.get_drawstyle() == "steps-post"
    # each kind labelled once in the legend
    assert sorted(t.get_text() for t in ax.get_legend().get_texts()) == sorted(
        ["design range", "true delay", "estimate, 95 % interval", "estimate (alarm)"])
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("time (s)", "loop delay (s)")


def test_plot_online_into_given_axes_without_truth_or_alarm():
    from delaykit.plotting.compensation import plot_online

    online = [o for o in _online() if not o.alarm]
    host = Figure()
    ax = host.subplots()
    fig = plot_online(online, ax=ax, title="flight 3")
    assert fig is host and len(host.axes) == 1 and ax.get_title() == "flight 3"
    assert len(ax.containers) == 2 and not _lines(ax, "true delay")
    # t0 = 0: the windows at their own times
    assert [c[0].get_xdata()[0] for c in ax.containers] == [112.0, 122.0]
    assert sorted(t.get_text() for t in ax.get_legend().get_texts()) == ["design range", "estimate, 95 % interval"]


def _predictions():
    """Two logs' predictions (first output "z", a second output "u" that must not be drawn), built by hand."""
    from delaykit.identify.identification import Prediction

    out = []
    for k, name in enumerate(("a.csv", "b.csv")):
        t = 5.0 + np.arange(0.0, 10.0, 0.5)
        measured = {"z": np.sin(t + k), "u": np.cos(t)}
        predicted = {"z": np.sin(t + k) + 0.01, "u": np.cos(t) + 1.0}
        out.append(Prediction(file=name, t=t, measured=measured, predicted=predicted,
                              rms={"z": 0.01 * (k + 1), "u": 1.0}, wander={"z": 0.0, "u": 0.0}))
    return out


def test_plot_predictions_shows_measured_and_predicted_first_outputs():
    from delaykit.plotting.identification import plot_predictions

    preds = _predictions()
    fig = plot_predictions(preds, title="fopdt")
    assert isinstance(fig, Figure) and len(fig.axes) == 3  # outputs, residuals, input
    ax = fig.axes[0]
    assert len(ax.lines) == 2 * len(preds)  # a measured and a predicted line per log, the first output only
    assert [ln.get_label() for ln in ax.lines] == ["a.csv measured", "predicted (rms 0.01)",
                                                    "b.csv measured", "predicted (rms 0.02)"]
    for i, p in enumerate(preds):
        measured, predicted = ax.lines[2 * i], ax.lines[2 * i + 1]
        assert np.array_equal(measured.get_xdata(), p.t - 5.0) and np.array_equal(predicted.get_xdata(), p.t - 5.0)
        assert np.array_equal(measured.get_ydata(), p.measured["z"])
        assert np.array_equal(predicted.get_ydata(), p.predicted["z"])
        assert predicted.get_color() == measured.get_color() and predicted.get_linestyle() == "--"
    assert ax.lines[0].get_color() != ax.lines[2].get_color()
    assert (ax.get_ylabel(), ax.get_title()) == ("z", "fopdt")
    assert fig.axes[-1].get_xlabel() == "time from the log's start (s)"
    assert len(ax.get_legend().get_texts()) == 4
    # the residual panel: measured - predicted of the first output, per log
    res = fig.axes[1]
    assert res.get_ylabel() == "residual z (measured - predicted)"
    for i, p in enumerate(preds):
        assert np.allclose(res.lines[i].get_ydata(), p.measured["z"] - p.predicted["z"])
    # these hand-made predictions carry no input: the panel says so
    assert fig.axes[2].get_ylabel() == "input (not logged)" and len(fig.axes[2].lines) == 0


def test_plot_predictions_into_given_axes_and_of_a_real_fit(tmp_path):
    from delaykit.identify import Experiment, identify, predict
    from delaykit.plotting.identification import plot_predictions

    host = Figure()
    ax = host.subplots()
    fig = plot_predictions(_predictions()[:1], ax=ax)
    assert fig is host and len(host.axes) == 1 and len(ax.lines) == 2 and ax.get_title() == ""
    # more than six logs: no legend; none at all: an empty axes without a y label
    many = plot_predictions(_predictions() * 4).axes[0]
    assert len(many.lines) == 16 and many.get_legend() is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "no artists with labels" warning from an empty legend
        empty = plot_predictions([]).axes[0]
    assert len(empty.lines) == 0 and empty.get_ylabel() == "" and empty.get_legend() is None
    # a first-order-plus-dead-time fit of its own model's output (the module's example): the lines are the
    # prediction's arrays
    t = np.arange(0, 60.0, 0.5)
    e = Experiment.from_arrays(t, {"y": 2 * (1 - np.exp(-np.maximum(t - 8, 0) / 10))}, u=np.where(t >= 5, 1.0, 0.0))
    pred = predict(identify(e, model="fopdt"), e)
    fig = plot_predictions([pred], path=tmp_path / "p.svg")
    assert "<svg" in (tmp_path / "p.svg").read_text()
    measured, predicted = fig.axes[0].lines
    assert np.array_equal(measured.get_ydata(), pred.measured["y"])
    assert np.array_equal(predicted.get_ydata(), pred.predicted["y"])
    # the input, held between samples, in the third panel, named by its column
    (drive,) = fig.axes[2].lines
    assert np.array_equal(drive.get_ydata(), e.u) and drive.get_drawstyle() == "steps-post"
    assert fig.axes[2].get_ylabel() == "input u"


def test_response_labels_come_from_the_loop():
    # the paper's loop is an altitude in metres driven by a speed command; a heater is neither
    from delaykit.models.loop import Loop

    drone = plot_responses([simulate(AltitudeLoop(kp=1.31, delay=0.368), t_end=3.0)], dt=0.05)
    assert [a.get_ylabel() for a in drone.axes] == ["altitude z (m)", "command u (m/s)"]
    heater = simulate(Loop("0.6976/(146.6*s+1)", delay=16.6), t_end=600.0)
    fig = plot_responses([heater], dt=5.0)
    assert [a.get_ylabel() for a in fig.axes] == ["output y", "command u"]
    assert not any("altitude" in a.get_ylabel() or "m/s" in a.get_ylabel() for a in fig.axes)
    fig = plot_responses([heater], dt=5.0, output_label="temperature T (°C)", command_label="heater Q (%)")
    assert [a.get_ylabel() for a in fig.axes] == ["temperature T (°C)", "heater Q (%)"]


@pytest.mark.parametrize("width", [4.0, 8.0])
def test_long_titles_are_wrapped_inside_the_figure(width):
    # rendered by the Agg canvas (attached to this figure only: the backend is not switched); the title's box
    # must lie within the figure's
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    title = ("IdentifiedModel(fopdt: gain=0.6976 ± 0.0023, time_constant=146.6 ± 2.3 s, delay=16.63 ± 1.1 s; "
             "rms=0.2688, 1 log) predicting a second log of the heater")
    fig = Figure(figsize=(width, 4), layout="tight")
    ax = fig.subplots()
    from delaykit.plotting.figures import set_title

    set_title(ax, title)
    FigureCanvasAgg(fig).draw()
    box = ax.title.get_window_extent()
    assert box.x0 >= 0 and box.x1 <= fig.bbox.x1 and box.y1 <= fig.bbox.y1
    assert ax.get_title().replace("\n", " ") == title


# ---- callers: the command line and the paper write their figures through these ----------------------------------

def test_command_line_plots_are_written(tmp_path):
    from typer.testing import CliRunner

    from delaykit.cli import app

    runner = CliRunner()
    res = runner.invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.3,0.368", "--plot", str(tmp_path / "s.png")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, ["roots", "--kp", "2", "--kv", "0.3", "--delay", "0.37", "--region", "-10", "2", "0", "40",
                              "--plot", str(tmp_path / "r.svg")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "s.png").read_bytes()[:4] == b"\x89PNG" and "<svg" in (tmp_path / "r.svg").read_text()


def test_table1_figure_of_the_report():
    from delaykit.paper.report import plot_table1_responses

    ax = Figure().subplots()
    fig = plot_table1_responses(ax=ax)
    assert fig is ax.figure
    assert [ln.get_label() for ln in ax.lines] == ["K=4, Td=0.2600 s", "K=5, Td=0.3250 s", "K=5.6, Td=0.3640 s",
                                                   "K=5.6646, Td=0.3682 s", "reference"]
