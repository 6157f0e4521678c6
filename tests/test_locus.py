"""The exact root locus (spectrum/locus.py): crossings against closed forms, roots against python-control at zero
delay and against Lambert W, stability switches over the delay, bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.special import lambertw

import delaykit
from delaykit import AltitudeLoop, InvalidTypeError, InvalidValueError, LocusCrossing, RootLocus, root_locus
from delaykit.spectrum.locus import _check, open_loop_parts


def _flat(intervals):
    return [x for iv in intervals for x in iv]


def test_integrator_delay_crossings_closed_form():
    # k e^{-tau s}/s: s = jw, jw + k e^{-j w tau} = 0  =>  w = k and w tau = pi/2 + 2 pi n (by hand), every
    # crossing a pair moving right (Re ds/dk > 0): the count of unstable roots is 2 per crossing passed
    tau = 0.5
    gains = np.linspace(0.1, 30.0, 300)
    loc = root_locus(([1.0], [1.0, 0.0], tau), gains=gains)
    want = [(math.pi / 2 + 2 * math.pi * n) / tau for n in range(3)]  # pi, 5 pi, 9 pi: all below 30
    assert [c.value for c in loc.crossings] == pytest.approx(want, rel=1e-12)
    assert [c.frequency for c in loc.crossings] == pytest.approx(want, rel=1e-12)  # w = k
    assert [c.direction for c in loc.crossings] == [1, 1, 1]
    passed = np.searchsorted(want, gains)
    assert np.array_equal(loc.unstable, 2 * passed)
    assert _flat(loc.stable_intervals) == pytest.approx([0.1, math.pi], rel=1e-12)
    assert loc.all_certified and loc.consistent and loc.reason == ""


def test_roots_match_lambert_w():
    # s + k e^{-tau s} = 0 has the roots W_b(-k tau) / tau (scipy's Lambert W, an independent computation); the
    # branches 0 and -1 are the rightmost pair.  Every root listed is a root, and the rightmost is branch 0's.
    tau = 0.368
    gains = np.linspace(0.2, 8.0, 40)
    loc = root_locus(AltitudeLoop(kp=1.0, delay=tau), gains=gains, region=(-15, 5, -40, 40))
    for k, row, cnt in zip(gains, loc.roots, loc.counts):
        r = row[np.isfinite(row)]
        assert r.size == cnt
        assert np.all(np.abs(r + k * np.exp(-tau * r)) <= 1e-9 * (1 + np.abs(r)))
        w0 = complex(lambertw(-k * tau, 0)) / tau
        top = r[np.argmax(r.real)]
        assert top.real == pytest.approx(w0.real, abs=1e-9)
        assert abs(top.imag) == pytest.approx(abs(w0.imag), abs=1e-9)
    # stability from the counts agrees with the sign of Lambert W's branch 0
    assert np.array_equal(loc.stable, [lambertw(-k * tau, 0).real < 0 for k in gains])
    assert loc.crossings[0].value * tau == pytest.approx(math.pi / 2, rel=1e-12)  # k tau = pi/2 (paper: 4.2685)


def test_zero_delay_matches_python_control():
    control = pytest.importorskip("control")
    num, den = [1.0, 2.0], [1.0, 4.0, 3.0, 0.0]  # (s + 2) / (s (s + 1) (s + 3))
    gains = np.linspace(0.5, 20.0, 40)
    loc = root_locus((num, den), gains=gains, region=(-12, 2, -10, 10))
    G = control.tf(num, den)
    for k, row in zip(gains, loc.roots):
        want = np.sort_complex(control.poles(control.feedback(k * G)))
        got = np.sort_complex(row[np.isfinite(row)])
        assert got.size == want.size
        assert np.allclose(got, want, atol=1e-8)
    assert loc.all_certified


def test_zero_delay_crossing_routh():
    # 1 / (s (s + 1) (s + 2)): s^3 + 3 s^2 + 2 s + k, Routh: unstable past k = 6, crossing at w = sqrt(2)
    loc = root_locus(([1.0], [1.0, 3.0, 2.0, 0.0]), gains=np.linspace(0.5, 10.0, 20))
    (c,) = loc.crossings
    assert c.value == pytest.approx(6.0, rel=1e-12) and c.frequency == pytest.approx(math.sqrt(2), rel=1e-12)
    assert c.direction == 1
    assert _flat(loc.stable_intervals) == pytest.approx([0.5, 6.0], rel=1e-12)


def _switches(a: float, b: float, c: float, tmax: float):
    """By hand: s^2 + a s + b + c e^{-s tau}.  A root j w needs (b - w^2)^2 + a^2 w^2 = c^2, a quadratic in
    x = w^2; then e^{-j w tau} = -(b - w^2 + j a w) / c.  Cooke & van den Driessche: the root moves right where
    F(w) = (b - w^2)^2 + a^2 w^2 - c^2 rises (F'(w) > 0), left where it falls."""
    B = 2 * b - a * a
    disc = B * B - 4 * (b * b - c * c)
    out = []
    for x in ((B + math.sqrt(disc)) / 2, (B - math.sqrt(disc)) / 2):
        if x <= 0:
            continue
        w = math.sqrt(x)
        z = -complex(b - x, a * w) / c
        t0 = (-math.atan2(z.imag, z.real)) % (2 * math.pi) / w
        dF = 4 * w ** 3 - 4 * b * w + 2 * a * a * w
        n = 0
        while t0 + 2 * math.pi * n / w <= tmax:
            out.append((t0 + 2 * math.pi * n / w, w, 1 if dF > 0 else -1))
            n += 1
    return sorted(out)


def test_delay_switches_stable_unstable_stable():
    # s^2 + 0.1 s + 1 + 0.5 e^{-s tau}: stable at tau = 0, unstable at 0.202, stable again at 4.220, unstable for
    # good at 5.358 (the crossings' values from _switches, by hand)
    delays = np.linspace(0.0, 15.0, 301)
    loc = root_locus(([0.5], [1.0, 0.1, 1.0]), delays=delays)
    want = _switches(0.1, 1.0, 0.5, 15.0)
    got = [(c.value, c.frequency, c.direction) for c in loc.crossings]
    assert len(got) == len(want) == 5
    for g, w in zip(got, want):
        assert g[0] == pytest.approx(w[0], rel=1e-10) and g[1] == pytest.approx(w[1], rel=1e-10) and g[2] == w[2]
    assert [d for _, _, d in got][:3] == [1, -1, 1]
    assert _flat(loc.stable_intervals) == pytest.approx([0.0, want[0][0], want[1][0], want[2][0]], rel=1e-10)
    # the right-half-plane count between switches: 0, 2, 0, 2, 4, 2 (the last crossing at 13.06 is to the left)
    assert loc.unstable[delays < want[0][0]].tolist() == [0] * int(np.sum(delays < want[0][0]))
    mid = (delays > want[0][0]) & (delays < want[1][0])
    assert set(loc.unstable[mid].tolist()) == {2}
    late = delays > want[4][0]
    assert set(loc.unstable[late].tolist()) == {2}
    assert loc.all_certified


def test_delay_first_switch_is_delay_margin():
    # over the delay of e^{-tau s}/s at gain k, the first switch is the delay margin pi / (2 k)
    loc = root_locus("1/s", delays=np.linspace(0.0, 2.0, 41), gain=1.31)
    assert loc.crossings[0].value == pytest.approx(math.pi / 2 / 1.31, rel=1e-12)
    assert loc.crossings[0].frequency == pytest.approx(1.31, rel=1e-12)
    assert loc.stable_intervals[0][1] == pytest.approx(math.pi / 2 / 1.31, rel=1e-12)


def test_inputs_agree():
    # the same open loop given four ways
    g = np.linspace(0.5, 6.0, 12)
    a = root_locus("exp(-0.368*s)/s", gains=g)
    b = root_locus(AltitudeLoop(kp=1.0, delay=0.368), gains=g)
    c = root_locus(([1.0], [1.0, 0.0], 0.368), gains=g)
    d = root_locus(delaykit.Loop("1/s", delaykit.Controller.p(1.0), delay=0.368), gains=g)
    e = root_locus(delaykit.tf("exp(-0.368*s)/s"), gains=g)
    for x in (b, c, d, e):
        assert np.array_equal(x.unstable, a.unstable)
        assert [cr.value for cr in x.crossings] == pytest.approx([cr.value for cr in a.crossings], rel=1e-13)


def test_result_form():
    loc = root_locus("exp(-s)/s", gains=[0.0, 1.0, 2.0])
    assert isinstance(loc, RootLocus) and isinstance(loc.crossings[0], LocusCrossing)
    assert "\n" not in repr(loc) and repr(loc).startswith("RootLocus(gain over 3 values")
    d = loc.to_dict()
    json.dumps(d, allow_nan=False)  # strict JSON: the padding nan and the uncounted -1 do not leak
    assert d["unstable"][0] is None  # at k = 0 the root s = 0 is on the axis: not counted, not stable
    assert d["stable"] == [False, True, False]
    # the crossing at k = 0 (the integrator's root through 0, moving left) and at pi/2
    assert [(c.value, c.frequency, c.direction) for c in loc.crossings][0] == (0.0, 0.0, -1)
    assert loc.roots.shape[0] == 3 and loc.roots.dtype == complex
    assert (d["gain"], d["delay"]) == (None, 1.0)  # the gain moves; the delay is the loop's


def test_check_reports_a_missing_crossing():
    # the consistency check names where the counts change without a crossing found
    values = np.array([1.0, 2.0, 3.0])
    assert _check(values, np.array([0, 0, 2]), []) != ""
    assert _check(values, np.array([0, 0, 2]), [LocusCrossing("gain", 2.5, 1.0, 1)]) == ""


@pytest.mark.parametrize("kwargs, exc, words", [
    ({}, InvalidValueError, "exactly one"),
    ({"gains": [1.0], "delays": [0.1]}, InvalidValueError, "exactly one"),
    ({"gains": [2.0, 1.0]}, InvalidValueError, "increasing"),
    ({"gains": []}, InvalidValueError, "empty"),
    ({"gains": [1.0, float("nan")]}, InvalidValueError, "finite"),
    ({"gains": ["a"]}, InvalidTypeError, "numbers"),
    ({"delays": [-0.1, 0.2]}, InvalidValueError, ">= 0"),
    ({"gains": [1.0], "region": (1, 0, 0, 1)}, InvalidValueError, "re_min"),
])
def test_bad_input(kwargs, exc, words):
    with pytest.raises(exc, match=words):
        root_locus("exp(-s)/s", **kwargs)


def test_bad_open_loop():
    with pytest.raises(InvalidValueError, match="improper"):
        open_loop_parts(([1.0, 0.0, 0.0], [1.0, 1.0]))
    with pytest.raises(InvalidTypeError, match="open loop"):
        root_locus(3.0, gains=[1.0])
    with pytest.raises(InvalidValueError, match="different delays"):  # not rational times one dead time
        root_locus(delaykit.tf("1/(s+1)") + delaykit.tf("exp(-s)/(s+1)"), gains=[1.0])
    with pytest.raises(InvalidValueError, match="sampled"):
        root_locus(AltitudeLoop(kp=1.0, delay=0.368, period=0.05), gains=[1.0])


def test_plot_root_locus(tmp_path):
    from matplotlib.figure import Figure

    from delaykit.plotting import plot_root_locus

    loc = root_locus("exp(-s)/s", gains=np.linspace(0.2, 8.0, 30))
    ax = Figure().subplots()
    path = tmp_path / "locus.png"
    fig = plot_root_locus(loc, path, ax=ax)
    assert fig is ax.figure and path.stat().st_size > 0
    # every root drawn once, coloured by its gain
    offs = ax.collections[0].get_offsets()
    assert offs.shape[0] == int(np.isfinite(loc.roots).sum())
    assert np.allclose(np.sort(ax.collections[0].get_array()), np.sort(np.broadcast_to(
        loc.values[:, None], loc.roots.shape)[np.isfinite(loc.roots)]))
    # the crossings at +-j w on the axis: pi/2 and 2 pi + pi/2 (k tau = w tau = pi/2 + 2 pi n)
    marks = [line for line in ax.lines if line.get_marker() == "x"]
    ws = sorted(abs(y) for line in marks for y in line.get_ydata())
    assert ws == pytest.approx(sorted([math.pi / 2] * 2 + [2.5 * math.pi] * 2), rel=1e-12)
    with pytest.raises(InvalidTypeError, match="RootLocus"):
        plot_root_locus("not a locus")


def test_third_order_with_delay_phase_crossover():
    # 2 e^{-0.2 s} / (s + 1)^3: a root j w needs the phase -3 atan(w) - 0.2 w = -pi, then k = |1 + j w|^3 / 2
    # (solved here with scipy's brentq, independently of the code's scan)
    from scipy.optimize import brentq

    w = brentq(lambda x: 3 * math.atan(x) + 0.2 * x - math.pi, 0.5, 3.0, xtol=1e-15)
    k = (1 + w * w) ** 1.5 / 2
    loc = root_locus(([2.0], [1.0, 3.0, 3.0, 1.0], 0.2), gains=np.linspace(0.1, 10.0, 100))
    first = loc.crossings[0]
    assert first.value == pytest.approx(k, rel=1e-10) and first.frequency == pytest.approx(w, rel=1e-10)
    assert first.direction == 1
    assert _flat(loc.stable_intervals) == pytest.approx([0.1, k], rel=1e-10)
    assert loc.all_certified


def test_biproper_neutral_range_refused():
    # (s + 2) / (s + 1) e^{-0.5 s} at |k| >= 1: k s e^{-0.5 s} matches s, the root chains reach the axis
    with pytest.raises(InvalidValueError, match="neutral"):
        root_locus(([1.0, 2.0], [1.0, 1.0], 0.5), gains=[0.5, 1.5])
    # below, a neutral loop with its chains left of the axis: stable (Re s -> ln(k) / 0.5 < 0)
    loc = root_locus(([1.0, 2.0], [1.0, 1.0], 0.5), gains=[0.1, 0.3])
    assert loc.stable.tolist() == [True, True] and loc.all_certified
    from delaykit import QuasiPolynomial
    from delaykit.spectrum.stability import rightmost

    # the same verdict from the rightmost-root search (another path through the root finder)
    assert [rightmost(QuasiPolynomial([[1.0, 1.0], [k, 2 * k]], [0.0, 0.5])).stable for k in (0.1, 0.3)] == [True, True]


@pytest.mark.parametrize("a, b, c", [(0.1, 1.0, 0.5), (0.2, 2.0, 0.8), (0.05, 1.0, 0.3)])
def test_delay_switching_sequences(a, b, c):
    # x'' + a x' + b x = -c x(t - tau) (Cooke & Grossman's second-order form): the crossings and, from them, the
    # stable intervals by hand: stable at tau = 0 (s^2 + a s + b + c is Hurwitz), each crossing moves the count of
    # unstable roots by 2 in its direction.  The three cases have two, two and three stable intervals (the last one,
    # 11.07 to 11.21, narrower than three grid steps)
    tmax = 20.0
    want = _switches(a, b, c, tmax)
    loc = root_locus(([c], [1.0, a, b]), delays=np.linspace(0.0, tmax, 401))
    assert [x.value for x in loc.crossings] == pytest.approx([w[0] for w in want], rel=1e-10)
    assert [x.direction for x in loc.crossings] == [w[2] for w in want]
    n, lo, intervals = 0, 0.0, []
    for t, _, d in want:
        if n == 0:
            intervals.append((lo, t))
        n += 2 * d
        lo = t
    if n == 0:
        intervals.append((lo, tmax))
    assert _flat(loc.stable_intervals) == pytest.approx(_flat(intervals), rel=1e-10)
    assert loc.all_certified


def test_narrow_stable_interval_between_grid_values():
    # the third case above is stable on (11.07, 11.21) only, narrower than this grid's step of 0.5: no grid value
    # lands there, but the intervals follow from the crossings (consistent with every count), so it is found
    want = _switches(0.05, 1.0, 0.3, 20.0)
    loc = root_locus(([0.3], [1.0, 0.05, 1.0]), delays=np.linspace(0.0, 20.0, 41))
    assert loc.consistent
    narrow = [iv for iv in loc.stable_intervals if iv[0] > 10.0]
    assert len(narrow) == 1 and narrow[0][1] - narrow[0][0] < 0.5
    ends = [t for t, _, _ in want if 10.0 < t < 12.0]  # the crossings around it, by hand
    assert list(narrow[0]) == pytest.approx(ends, rel=1e-10)
    assert not np.any(loc.stable[(loc.values > 10.0)])  # no grid value sees it


def test_crossings_agree_with_margins():
    # a PID loop with a delay: the gain crossing is the gain margin and the delay crossing the loop's delay plus
    # the delay margin, both from margins() (the frequency module's certified crossovers, another computation)
    loop = delaykit.Loop("1/((s+1)*(0.5*s+1))", delaykit.Controller.pid(1.0, 0.5, 0.2, 0.05), delay=0.2)
    m = delaykit.margins(loop)
    g = root_locus(loop, gains=np.linspace(0.05, 15.0, 60))
    d = root_locus(loop, delays=np.linspace(0.0, 3.0, 60))
    assert [c.value for c in g.crossings] == pytest.approx([m.gain_margin], rel=1e-9)
    assert g.crossings[0].frequency == pytest.approx(m.phase_crossover, rel=1e-9)
    assert d.crossings[0].value == pytest.approx(loop.delay + m.delay_margin, rel=1e-9)
    assert d.crossings[0].frequency == pytest.approx(m.crossover, rel=1e-9)
    assert g.all_certified and d.all_certified


def test_lightly_damped_resonance_crossing():
    # e^{-0.1 s} / (s^2 + 2e-4 s + 1): the phase passes -pi within 1e-3 of w = 1; a root j w needs
    # angle(1 - w^2 + 2e-4 j w) + 0.1 w = pi, then k = |1 - w^2 + 2e-4 j w| (brentq, by hand)
    from scipy.optimize import brentq

    def phase(w):
        return math.atan2(2e-4 * w, 1 - w * w) + 0.1 * w - math.pi

    w = brentq(phase, 0.999, 1.01, xtol=1e-15)
    k = abs(complex(1 - w * w, 2e-4 * w))
    loc = root_locus(([1.0], [1.0, 2e-4, 1.0], 0.1), gains=np.linspace(1e-4, 1e-2, 50))
    assert [c.value for c in loc.crossings] == pytest.approx([k], rel=1e-8)
    assert loc.crossings[0].frequency == pytest.approx(w, rel=1e-12)
    assert loc.all_certified
