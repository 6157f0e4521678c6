"""The certified root finder and the stability layer, against closed forms and another library (qpmr)."""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from argument_principle import zeros_in_box

from delaykit import AltitudeLoop, InvalidValueError, QuasiPolynomial
from delaykit.spectrum.lambert import lambert_roots
from delaykit.paper.data import table3
from delaykit.spectrum.roots import find_roots, neutral_lines, root_bound
from delaykit.spectrum.stability import delay_margin, rightmost, stability_map


def lambert_set(kp, td, region):
    """Every root of s + Kp exp(-s Td) = 0 in the region, from the Lambert W branches (exact)."""
    r = lambert_roots(0.0, -kp, td, branches=range(-60, 61)).roots
    x0, x1, y0, y1 = region
    return np.sort_complex(r[(r.real >= x0) & (r.real <= x1) & (r.imag >= y0) & (r.imag <= y1)])


@settings(max_examples=25)
@given(kp=st.floats(0.2, 5.0), td=st.floats(0.05, 2.0))
def test_p_loop_roots_are_the_lambert_w_roots(kp, td):
    region = (-12.0, 3.0, -60.0, 60.0)
    sp = find_roots(QuasiPolynomial([[1, 0], [kp]], [0, td]), region)
    ref = lambert_set(kp, td, region)
    assert sp.certified, sp.reason
    assert sp.roots.size == ref.size
    dist = np.min(np.abs(sp.roots[:, None] - ref[None, :]), axis=0)  # nearest found root to each exact one
    assert np.max(dist / (1 + np.abs(ref))) < 1e-12


def test_polynomials_match_numpy_roots():
    rng = np.random.default_rng(4)
    for _ in range(10):
        r = rng.normal(size=5) + 1j * rng.normal(size=5)
        sp = find_roots(QuasiPolynomial([np.poly(r)], [0.0]), (-4, 4, -4, 4))
        assert sp.certified and sp.roots.size == 5
        assert np.max(np.min(np.abs(sp.roots[:, None] - r[None, :]), axis=1)) < 1e-10


def test_table3_every_qpmr_root_is_found_and_certified():
    import qpmr

    for kv in (0.0, 0.1, 0.3, 0.5, 0.7):
        sp = find_roots(AltitudeLoop(kp=2.0, delay=0.37, kv=kv).characteristic(), (-10, 2, 0, 100))
        theirs, _ = qpmr.qpmr(np.array([[0.0, 1.0], [2.0, kv]]), np.array([0.0, 0.37]), region=[-10, 2, 0, 100])
        assert sp.certified
        for z in np.asarray(theirs):
            assert np.min(np.abs(sp.roots - z)) < 1e-8 * (1 + abs(z))
        # each root solves the equation to working precision, checked in 50-digit arithmetic
        for z in sp.roots:
            s = mpmath.mpc(z.real, z.imag)
            f = s + (2 + kv * s) * mpmath.exp(-s * mpmath.mpf("0.37"))
            df = 1 + (kv - 0.37 * (2 + kv * s)) * mpmath.exp(-s * mpmath.mpf("0.37"))
            assert abs(f / df) < 1e-12 * (1 + abs(z))  # Newton distance to the true root


def test_table3_check():
    rows = table3()
    assert [r.agrees for r in rows] == [True, True, False, True, True]
    kv3 = rows[2]
    assert kv3.printed_is_root and kv3.rank == 2
    assert abs(kv3.rightmost - complex(-3.1951, 5.5820)) < 1e-4
    assert math.isclose(kv3.neutral_line, math.log(0.3) / 0.37, rel_tol=1e-12)


def test_multiple_root_is_found_once_with_its_multiplicity():
    q = QuasiPolynomial([np.poly([-6.025] * 6)], [0.0])
    sp = find_roots(q, (-8, -4, -1, 1))
    assert sp.certified and sp.roots.size == 1 and sp.multiplicities[0] == 6
    assert abs(sp.roots[0] + 6.025) < 1e-8


def test_mazanti_six_fold_root():
    from qpmr.quasipoly import examples as ex

    c, d = ex.mazanti2021multiplicity()
    q = QuasiPolynomial([row[::-1] for row in c], list(d))
    sp = find_roots(q, (-10, 2, 0, 50))
    assert sp.certified
    i = int(np.argmax(sp.multiplicities))
    r = sp.roots[i]
    assert sp.multiplicities[i] == 6 and abs(r.imag) == 0 and abs(r.real + 6.02) < 0.01
    # a six-fold root: Q and its first five derivatives vanish there (relative to their scale), the sixth not
    dq, vals = q, []
    for _ in range(7):
        vals.append(abs(dq(r)))
        dq = dq.derivative()
    assert max(vals[:6]) < 1e-6 * vals[6]


def test_root_on_the_boundary_is_reported_in_the_closed_region():
    # the real roots of the polynomial (s+1)(s+2)(s^2+9) lie on the Im = 0 edge; the pair +-3j on x = 0
    q = QuasiPolynomial([np.poly([-1, -2, 3j, -3j])], [0.0])
    sp = find_roots(q, (-3, 0, 0, 5))
    assert sp.certified
    want = np.array([-2, -1, 3j])
    assert sp.roots.size == 3 and np.max(np.min(np.abs(sp.roots[:, None] - want[None, :]), axis=0)) < 1e-10


def test_qpmr_example_3_all_201_roots():
    from qpmr.quasipoly import examples as ex

    c, d = ex.vyhlidal2014qpmr_03()
    sp = find_roots(QuasiPolynomial([row[::-1] for row in c], list(d)), (-6, 2, 0, 200))
    assert sp.certified and sp.count == 201 and int(sp.multiplicities.sum()) == 201


def test_uncertified_when_the_boundary_cannot_be_resolved(monkeypatch):
    import delaykit.spectrum.roots as R

    monkeypatch.setattr(R, "_CAP", 50)
    sp = find_roots(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3).characteristic(), (-10, 2, 0, 100))
    assert not sp.certified and "samples" in sp.reason


def test_neutral_lines_and_stability():
    q = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3).characteristic()
    assert neutral_lines(q) == (math.log(0.3) / 0.37,)
    assert neutral_lines(AltitudeLoop(kp=2.0, delay=0.37).characteristic()) == ()
    r = rightmost(AltitudeLoop(kp=2.0, delay=0.37, kv=0.5))
    assert r.stable and abs(r.root - complex(-1.8408, 6.9839)) < 1e-4
    bad = rightmost(AltitudeLoop(kp=2.0, delay=0.37, kv=1.2))
    assert not bad.stable and bad.neutral_lines[0] > 0


def test_rightmost_of_p_loop_is_lambert_branch_zero():
    for kp, td in [(1.31, 0.368), (0.5, 0.2), (3.0, 0.6)]:
        r = rightmost(AltitudeLoop(kp=kp, delay=td))
        ref = lambert_roots(0.0, -kp, td, branches=[0]).roots[0]
        ref = complex(ref.real, abs(ref.imag))
        assert abs(r.root - ref) < 1e-10 * (1 + abs(ref))
        assert r.stable == (kp * td < math.pi / 2)


def test_delay_margin_closed_forms():
    # P loop: crossing at w = Kp, margin pi / (2 Kp)
    m = delay_margin(AltitudeLoop(kp=1.31, delay=0.368))
    assert math.isclose(m.delay, math.pi / (2 * 1.31), rel_tol=1e-12) and math.isclose(m.frequency, 1.31)
    # neutral PV: w = Kp / sqrt(1 - Kv^2), tau = arg(j w / (Kp + j Kv w)) ... checked by the root crossing
    loop = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3)
    m = delay_margin(loop)
    assert math.isclose(m.frequency, 2.0 / math.sqrt(1 - 0.09), rel_tol=1e-12)
    q = loop.replace(delay=m.delay).characteristic()
    assert abs(q(1j * m.frequency)) < 1e-12
    assert rightmost(loop.replace(delay=m.delay * 0.98)).stable
    assert not rightmost(loop.replace(delay=m.delay * 1.02)).stable
    assert delay_margin(AltitudeLoop(kp=2.0, delay=0.3, kv=1.0)).delay == 0.0


def test_stability_map_p_loop_boundary_is_kp_td_pi_over_2():
    kp = np.linspace(0.5, 6.0, 23)
    td = np.linspace(0.1, 0.8, 15)
    m = stability_map(AltitudeLoop(kp=1.0, delay=0.3), "kp", kp, "delay", td)
    K, T = np.meshgrid(kp, td)
    clear = np.abs(K * T - math.pi / 2) > 1e-3
    assert np.array_equal(m.stable[clear], (K * T < math.pi / 2)[clear])
    pv = stability_map(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3), "kv", [0.3, 0.9, 1.1], "kp", [2.0])
    assert pv.stable.tolist() == [[True, True, False]]


def test_root_bound_holds():
    q = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered").characteristic()
    R = root_bound(q, -2.0)
    sp = find_roots(q, (-2.0, 3 * R, 0, 3 * R))
    assert sp.certified and np.all(np.abs(sp.roots) <= R)


@pytest.mark.parametrize("region, fragment", [((2, 1, 0, 1), "re_min"), ((0, 1, 3, 3), "im_min"),
                                              ((0, 1, 0, float("nan")), "finite"), ((0, 1, 2), "four")])
def test_bad_regions(region, fragment):
    with pytest.raises(InvalidValueError, match=fragment):
        find_roots(QuasiPolynomial([[1, 0], [1]], [0, 1]), region)


def test_bad_quasi_polynomials():
    with pytest.raises(InvalidValueError, match="zero"):
        QuasiPolynomial([[0.0]], [0.0])
    with pytest.raises(InvalidValueError, match="advanced"):
        find_roots(QuasiPolynomial([[1], [1, 0]], [0, 1]), (-1, 1, -1, 1))


# ---- statuses: the retry and the result say why by a RootStatus, never by reading the message ----------------


def _recording_count(monkeypatch):
    """Replace the contour count by one that records every box it is asked about."""
    import delaykit.spectrum.roots as R

    boxes = []
    inner = R._count

    def count(ev, box):
        boxes.append(box)
        return inner(ev, box)

    monkeypatch.setattr(R, "_count", count)
    return boxes


def test_sample_budget_failure_is_not_retried(monkeypatch):
    import delaykit.spectrum.roots as R
    from delaykit.spectrum.roots import RootStatus

    q = QuasiPolynomial([np.poly([-1, -2, 3j, -3j])], [0.0])
    monkeypatch.setattr(R, "_CAP", 50)
    boxes = _recording_count(monkeypatch)
    region = (-3.5, 0.5, -0.5, 5.5)  # no root on or near its edges: only the budget stops the count
    grown, c = R._nudged_count(R._Eval(q), region)
    assert c.status is RootStatus.SAMPLE_BUDGET and not c.ok
    assert "samples" in c.reason and "boundary" in c.reason  # the sentence that used to trigger the retries
    assert boxes == [region] and grown == region  # counted once: larger boxes cannot cure a sample budget
    # through find_roots: the region (or a box around it) is counted once, and the status says why
    boxes.clear()
    sp = find_roots(q, region)
    assert not sp.certified and sp.status is RootStatus.SAMPLE_BUDGET and sp.count is None
    around = [b for b in boxes if b[0] <= region[0] and b[1] >= region[1] and b[2] <= region[2] and b[3] >= region[3]]
    assert len(around) == 1
    assert sp.to_dict()["status"] == "sample_budget" and sp.to_dict()["reason"] == sp.reason


def test_root_on_the_boundary_is_retried_and_certified(monkeypatch):
    import delaykit.spectrum.roots as R
    from delaykit.spectrum.roots import RootStatus

    q = QuasiPolynomial([np.poly([-1, -2])], [0.0])
    boxes = _recording_count(monkeypatch)
    region = (-1.0, 0.0, -1.0, 1.0)  # the root -1 sits on the left edge
    assert R._count(R._Eval(q), region).status is RootStatus.ROOT_ON_BOUNDARY
    boxes.clear()
    grown, c = R._nudged_count(R._Eval(q), region)
    assert c.status is RootStatus.CERTIFIED and c.n == 1
    assert len(boxes) >= 2 and boxes[0] == region and grown != region  # retried on a slightly larger box
    assert grown[0] < region[0] and grown[1] > region[1]
    sp = find_roots(q, region)
    assert sp.certified and sp.status is RootStatus.CERTIFIED and sp.reason == ""
    assert sp.roots.size == 1 and abs(sp.roots[0] + 1) < 1e-12


def test_status_is_on_every_result():
    from delaykit.spectrum.roots import RootStatus, Spectrum

    q = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3).characteristic()
    sp = find_roots(q, (-10, 2, 0, 100))
    assert sp.status is RootStatus.CERTIFIED and sp.to_dict()["status"] == "certified"
    sp = find_roots(q, (-10, 2, 0, 100), certify=False)
    assert not sp.certified and sp.status is RootStatus.NOT_REQUESTED and sp.reason
    p_loop = QuasiPolynomial([[1, 0], [2.0]], [0, 0.5])
    sp = find_roots(p_loop, (-12, 3, -60, 60), ds=20.0, max_depth=0)  # a coarse grid leaves roots to subdivision
    assert not sp.certified and sp.status is RootStatus.DEPTH_LIMIT and "depth" in sp.reason and sp.count == 10
    assert find_roots(p_loop, (-12, 3, -60, 60), ds=20.0).status is RootStatus.CERTIFIED
    # a Spectrum built by hand without a status gets one that agrees with `certified`, and may not contradict it
    z = np.zeros(0, complex)
    assert Spectrum(z, np.zeros(0, int), (0, 1, 0, 1), 0, True, "", "retarded", ()).status is RootStatus.CERTIFIED
    assert Spectrum(z, np.zeros(0, int), (0, 1, 0, 1), None, False, "?", "retarded", ()).status is \
        RootStatus.COUNT_MISMATCH
    with pytest.raises(InvalidValueError, match="contradicts"):
        Spectrum(z, np.zeros(0, int), (0, 1, 0, 1), 0, True, "", "retarded", (), status=RootStatus.SAMPLE_BUDGET)
    assert {s.value for s in RootStatus} >= {"certified", "root_on_boundary", "sample_budget"}
    import delaykit

    assert delaykit.RootStatus is RootStatus


def test_no_control_flow_reads_message_text():
    """Errors and statuses are told apart by type; no `"..." in str(exc)` or `"..." in c.reason` remains."""
    import re
    from pathlib import Path

    import delaykit

    src = Path(delaykit.__file__).parent
    pattern = re.compile(
        r"""(['"][^'"]*['"]\s+(not\s+)?in\s+(str|repr)\()"""  # "text" in str(exc)
        r"""|(['"][^'"]*['"]\s+(not\s+)?in\s+[\w.]*\b(exc|err|error|e|msg|message|reason|args)\b(?!\())"""
        r"""|(\bin\s+str\((exc|err|error|e)\))"""
    )
    hits = [f"{p.relative_to(src)}:{i}: {line.strip()}" for p in sorted(src.rglob("*.py"))
            for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1) if pattern.search(line)]
    assert not hits, "control flow reads message text:\n" + "\n".join(hits)


def test_rightmost_of_a_long_delay_on_a_slow_lag():
    """A 12 s delay on a 150 s lag under PI (issue 12): the old search started at Re s = -1, where the root bound
    is ~2700 with a delay of 12 s (a grid of ~1e8 points, gigabytes); now it starts at -1/T and finds the root in a
    region of the loop's own size.  Checked without delaykit's root finder: the root is a root of Q to 30 digits
    (mpmath's Newton from it), no root lies right of it (an independent argument-principle count on a box that
    holds every root there, its size from the hand bound below), and the Nyquist count of `margins` agrees."""
    from delaykit import Controller, Loop, margins

    loop = Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02), delay=12.0)
    r = rightmost(loop)
    assert r.certified and r.stable and r.root is not None
    assert max(abs(v) for v in r.spectrum.region) < 1.0  # searched on the loop's scale, not |s| ~ 2700
    # Q(s) = s (150 s + 1) + 0.62 (2 s + 0.02) exp(-12 s), divided by 150
    c2, c1, b1, b0, T = 1.0, 1 / 150, 0.62 * 2 / 150, 0.62 * 0.02 / 150, 12.0

    def q(s):
        return c2 * s * s + c1 * s + (b1 * s + b0) * np.exp(-T * s)

    mpmath.mp.dps = 30
    ref = complex(mpmath.findroot(lambda s: c2 * s * s + c1 * s + (b1 * s + b0) * mpmath.exp(-T * s), r.root))
    assert abs(ref - r.root) < 1e-12 * (1 + abs(ref))
    # every root with Re s >= a has |s|^2 <= c1 |s| + (b1 |s| + b0) exp(-T a): |s| <= H
    a = r.root.real + 1e-6
    g = math.exp(-T * a)
    H = 1.01 * ((c1 + b1 * g) + math.sqrt((c1 + b1 * g) ** 2 + 4 * b0 * g)) / 2
    assert zeros_in_box(q, a, H, -H, H) == 0
    assert zeros_in_box(q, r.root.real - 1e-6, H, -H, H) == 2  # the pair itself
    m = margins(loop)
    assert m.stable and m.nyquist_rhp_roots == 0


def test_rightmost_moves_left_until_it_finds_a_root():
    """A fast loop with a tiny delay: 0.01 s + 1 + 0.5 exp(-0.001 s) has its rightmost root far left of -1/T
    (the search's start is -1000 there, and the root is a real one near -158.6): the real root by Brent's method
    on the real axis (SciPy), and nothing to its right by the independent argument principle."""
    from scipy.optimize import brentq

    from delaykit import Controller, Loop

    r = rightmost(Loop("1/(0.01*s+1)", Controller.p(0.5), delay=0.001))

    def q(s):
        return 0.01 * s + 1 + 0.5 * np.exp(-0.001 * s)

    ref = brentq(lambda x: float(q(x)), -200.0, -100.0, xtol=1e-14)
    assert r.certified and abs(r.root - ref) < 1e-9 * abs(ref)
    a = ref + 1e-6
    H = 2.0 * (1 + 0.5 * math.exp(-0.001 * a)) / 0.01  # |0.01 s| <= 1 + 0.5 e^(-0.001 a) there
    assert zeros_in_box(q, a, H, -H, H) == 0


def test_stability_map_of_a_general_loop():
    """The map of any loop: (1) a P loop on 1/(s + 1) over gain and delay, against its closed-form boundary (the
    critical gain sqrt(1 + w^2) where w T + atan(w) = pi, by Brent's method); (2) a PID loop over (kp, ki), each
    point equal to the full certified search (`rightmost`) at that point, the map following the roots from point to
    point and confirming each by one argument-principle count."""
    from scipy.optimize import brentq

    from delaykit import Controller, Loop

    base = Loop("1/(s+1)", Controller.p(1.0), delay=0.5)
    kp, td = np.linspace(0.2, 6.0, 30), np.linspace(0.1, 2.0, 12)
    m = stability_map(base, "kp", kp, "delay", td, workers=2)
    for i, t in enumerate(td):
        w = brentq(lambda w: w * t + math.atan(w) - math.pi, 1e-9, math.pi / t)
        kc = math.sqrt(1 + w * w)
        clear = np.abs(kp - kc) > 1e-3
        assert np.array_equal(m.stable[i, clear], (kp < kc)[clear])
    pid = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.0, 0.5, 0.2, 0.05), delay=0.2)
    kp, ki = np.linspace(0.3, 8.0, 9), np.linspace(0.1, 5.0, 7)
    seen = []
    m = stability_map(pid, "kp", kp, "ki", ki, progress=lambda k, n: seen.append((k, n)), workers=1)
    ref = np.array([[rightmost(pid.replace(kp=a, ki=b)).abscissa for a in kp] for b in ki])
    assert np.max(np.abs(m.abscissa - ref)) < 1e-9
    assert 0 < m.stable.sum() < m.stable.size  # both verdicts occur
    assert seen[-1] == (kp.size * ki.size, kp.size * ki.size)
