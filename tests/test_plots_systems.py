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
