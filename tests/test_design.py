"""Controller design, gain searches (serial, process pool, Dask), the filter analysis, and the reproduction."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess

import numpy as np
import pytest
from argument_principle import zeros_in_box

from delaykit import AltitudeLoop, simulate
from delaykit.design.tuning import design_sweep, filter_analysis, gain_search, parse_range
from delaykit.errors import InvalidValueError
from delaykit.spectrum.stability import rightmost


def test_design_sweep_rows_against_an_independent_solver_and_the_argument_principle():
    """Each row of the paper's Kv sweep (Kp = 2.0, Td = 0.37 s) checked without delaykit's own solvers: the step
    metrics against the DOP853 oracle (tests/oracle.py); the rightmost root as a root of
    s + (Kv s + Kp) exp(-s Td) (mpmath, 30 digits) with no root to its right (argument principle on a box that
    provably holds every root with Re s > abscissa); for Kv = 0, the Lambert W closed form W_0(-Kp Td) / Td."""
    import mpmath

    from oracle import Oracle

    kp, td = 2.0, 0.37
    d = design_sweep(AltitudeLoop(kp=1.0, delay=td), kp, [0.0, 0.3, 0.7])
    for r in d.rows:
        ref = Oracle(kp=kp, td=td, kv=r.kv, vmax=1.0, step=1.0, t_end=15.0).metrics()
        assert math.isclose(r.overshoot, ref["overshoot"], abs_tol=1e-6)
        for key in ("rise_time", "settling_time"):
            assert math.isclose(getattr(r, key), ref[key], abs_tol=1e-6), (r.kv, key)
        if ref["overshoot"] > 1e-6:  # a peak exists only with an overshoot above rounding
            assert math.isclose(r.peak_time, ref["peak_time"], abs_tol=1e-6)
        s, kv = r.rightmost, r.kv
        with mpmath.workdps(30):
            sm = mpmath.mpc(s.real, s.imag)
            resid = abs(sm + (kv * sm + kp) * mpmath.exp(-sm * td)) / (abs(sm) + abs(kv * sm + kp))
        assert resid < 1e-12
        assert r.abscissa == s.real and r.stable == (s.real < 0)
        # every root with Re s >= a has |s| = |Kv s + Kp| e^{-Re s Td} <= (Kp + Kv |s|) e^{-a Td}, so |s| <= H
        a = s.real + 1e-6
        g = math.exp(-a * td)
        H = kp * g / (1 - kv * g) + 1.0
        f = lambda z, kv=kv: z + (kv * z + kp) * np.exp(-z * td)  # noqa: E731
        assert zeros_in_box(f, a, H, -H, H) == 0  # nothing to the right of the reported rightmost root
        assert zeros_in_box(f, s.real - 1e-6, H, -H, H) >= 1
        if kv == 0.0:
            w = complex(mpmath.lambertw(-kp * td, 0)) / td
            assert abs(s - w) < 1e-12
    # the best by the abscissa: Kv = 0.3, as in the paper (Table 3), and the most negative of the three
    assert d.best.kv == 0.3 and d.best.abscissa == min(r.abscissa for r in d.rows) and "spectral abscissa" in d.reason


def test_design_criteria_and_no_candidate():
    d = design_sweep(AltitudeLoop(kp=1.0, delay=0.37), 2.0, "0:0.7:8", criterion="settling")
    settled = [r for r in d.rows if r.stable and r.settling_time is not None]
    assert d.best.settling_time == min(r.settling_time for r in settled)
    d2 = design_sweep(AltitudeLoop(kp=1.0, delay=0.37), 2.0, "0:0.2:3", criterion="overshoot", overshoot_limit=3.0)  # Mo 12.2, 7.5, 2.9 %
    assert d2.best is not None and d2.best.kv == 0.2 and d2.best.overshoot <= 3.0
    none = design_sweep(AltitudeLoop(kp=1.0, delay=0.37), 2.0, [0.0, 0.1], criterion="overshoot", overshoot_limit=0.5)
    assert none.best is None and "no candidate meets" in none.reason
    unstable = design_sweep(AltitudeLoop(kp=1.0, delay=1.0), 3.0, [0.0], criterion="abscissa")
    assert unstable.best is None and "no candidate is stable" in unstable.reason
    assert json.loads(json.dumps(d.to_dict()))["best"]["kv"] == d.best.kv


@pytest.mark.parametrize("spec, fragment", [("0.5:0.2:3", "reversed"), ("0:1:0", "N must be"), ("a,b", "START:STOP:N")])
def test_bad_ranges(spec, fragment):
    with pytest.raises(InvalidValueError, match=fragment):
        parse_range(spec, "kv")
    with pytest.raises(InvalidValueError, match="criterion"):
        design_sweep(AltitudeLoop(kp=1.0, delay=0.37), 2.0, [0.3], criterion="fastest")


def test_gain_search_pool_equals_serial_and_is_robust():
    args = (AltitudeLoop(kp=1.0, delay=0.3), [0.30, 0.37, 0.44], [1.0, 1.5, 2.0, 2.5], [0.0, 0.2, 0.4])
    serial = gain_search(*args, workers=1)
    pooled = gain_search(*args, workers=2)
    assert np.array_equal(serial.abscissa, pooled.abscissa)
    assert np.array_equal(np.nan_to_num(serial.settling), np.nan_to_num(pooled.settling))
    # worst case over the delays: each cell's abscissa is the largest of the three single-delay ones
    kp, kv = serial.best
    single = [rightmost(AltitudeLoop(kp=kp, delay=d, kv=kv)).abscissa for d in args[1]]
    j, i = list(args[2]).index(kp), list(args[3]).index(kv)
    assert serial.abscissa[i, j] == max(single)


def test_gain_search_on_a_local_dask_cluster_gives_the_same_results():
    distributed = pytest.importorskip("distributed")
    args = (AltitudeLoop(kp=1.0, delay=0.3), [0.33, 0.41], [1.0, 2.0], [0.0, 0.3])
    serial = gain_search(*args, workers=1)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  host="127.0.0.1") as cluster:
        with distributed.Client(cluster) as client:
            via_dask = gain_search(*args, scheduler=client)
            by_address = gain_search(*args, scheduler=cluster.scheduler_address)
    assert np.array_equal(serial.abscissa, via_dask.abscissa) and np.array_equal(serial.abscissa, by_address.abscissa)
    assert serial.best == via_dask.best


def test_gain_search_keeps_the_loops_lag_and_gain():
    """The searched loop's plant (speed gain and lag) is used, not the paper's ideal integrator: each cell is the
    worst case over the delays of the loop with those gains, checked against rightmost() directly."""
    base = AltitudeLoop(kp=1.0, delay=0.3, gain=0.7, lag=0.12)
    g = gain_search(base, [0.3, 0.4], [1.5, 2.5], [0.0, 0.3], workers=1)
    ideal = gain_search(AltitudeLoop(kp=1.0, delay=0.3), [0.3, 0.4], [1.5, 2.5], [0.0, 0.3], workers=1)
    for i, kv in enumerate([0.0, 0.3]):
        for j, kp in enumerate([1.5, 2.5]):
            want = max(rightmost(base.replace(kp=kp, kv=kv, delay=d)).abscissa for d in (0.3, 0.4))
            assert g.abscissa[i, j] == want
    assert not np.array_equal(g.abscissa, ideal.abscissa)


def test_design_sweep_on_a_general_loop():
    """A general P loop becomes PV when Kv is swept; rows agree with the same loops built by hand."""
    from delaykit import Controller, Loop

    loop = Loop("1/(s*(0.1*s+1))", Controller.p(1.0), delay=0.3, umin=-1, umax=3)
    d = design_sweep(loop, [1.0, 1.5], [0.0, 0.2], step=-1.0, t_end=12.0)
    for r in d.rows:
        ctrl = Controller.pv(r.kp, r.kv) if r.kv else Controller.p(r.kp)
        by_hand = loop.replace(controller=ctrl)
        assert r.abscissa == rightmost(by_hand).abscissa
        assert r.overshoot == simulate(by_hand, -1.0, t_end=12.0).metrics.overshoot


def test_filter_analysis_closed_forms():
    f = filter_analysis(38.0, 1.0)
    assert f.poles == (complex(-38), complex(-38))
    # the low-pass part wf^2/(s + wf)^2 is 3 dB down where w^2 + wf^2 = sqrt(2) wf^2
    assert math.isclose(f.lowpass_cutoff, 38 * math.sqrt(math.sqrt(2) - 1), rel_tol=1e-6)
    # the band-pass derivative filter's edges: w wf^2 / (w^2 + wf^2) = (wf / 2) / sqrt(2)
    lo = 38 * (math.sqrt(2) - 1)
    assert math.isclose(f.band[0], lo, rel_tol=1e-6) and math.isclose(f.band[1], 38**2 / lo, rel_tol=1e-6)
    assert f.verdict.startswith("not reproduced")


def test_reproduce_writes_every_item(tmp_path):
    from delaykit.paper.reproduce import reproduce

    calls = []
    rep = reproduce(tmp_path, progress=lambda name, done, total: calls.append((name, done, total)))
    keys = [i.key for i in rep.items]
    assert keys == ["table1", "section511", "section512", "table3", "table4", "fig5", "filter"]
    # progress: one report per item and a last one, each with the number of items as its total
    assert [c[1:] for c in calls] == [(i, 7) for i in range(8)] and calls[-1][0] == "writing"
    # Table 2's five flights (the paper's printed Mo and tp) in section 5.1.1, each with its delay by the same method
    from delaykit.identify.estimation import estimate_overshoot
    from delaykit.paper.data import TABLE2

    header, flights = rep.items[1].tables[1]
    assert header[0] == "Table 2 flight" and len(flights) == 5
    assert [float(r[1]) for r in flights] == list(TABLE2["overshoot"])
    assert [float(r[2]) for r in flights] == list(TABLE2["peak_time"])
    assert flights[0][3] == f"{estimate_overshoot(2.300, 1.31).delay:.4f}"
    verdicts = {i.key: i.verdict for i in rep.items}
    assert verdicts["table1"].startswith("reproduced to within solver error")
    assert verdicts["table4"].startswith("reproduced to within solver error by the configuration 'filter, saturation, sampled")
    assert "4 of 5 rows reproduced" in verdicts["table3"]
    statuses = {i.key: i.status for i in rep.items}
    assert statuses == {"table1": "reproduced", "section511": "reproduced", "section512": "reproduced",
                        "table3": "not reproduced", "table4": "reproduced", "fig5": "reproduced",
                        "filter": "not reproduced"}
    assert all(i.verdict.startswith(i.status) for i in rep.items)
    assert json.loads((tmp_path / "report.json").read_text())["items"][0]["status"] == "reproduced"
    md = (tmp_path / "report.md").read_text()
    for fig in ("fig7_iterations.png", "fig8_spectra.png", "fig9_pv_responses.png"):
        assert (tmp_path / fig).stat().st_size > 10_000 and fig in md


def test_cli_reproduce_progress_takes_its_total_from_the_reproduction(tmp_path, monkeypatch):
    # the bar's total is whatever the reproduction reports (here 3 stages), not a number of the command's own
    from rich.progress import Progress
    from typer.testing import CliRunner

    import delaykit.paper.reproduce as R
    from delaykit.cli import app

    def fake(out, progress=None):
        for i, name in enumerate(("a", "b", "c", "writing")):
            progress(name, i, 3)
        return R.Reproduction(out=out, items=(), files=())

    seen = []
    update = Progress.update
    monkeypatch.setenv("FORCE_COLOR", "1")  # a bar is drawn (off a terminal, the command draws none)
    monkeypatch.setattr(R, "reproduce", fake)
    monkeypatch.setattr(Progress, "update", lambda self, task, **kw: (seen.append(kw), update(self, task, **kw))[1])
    res = CliRunner().invoke(app, ["reproduce", "--out", str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    assert [(kw["completed"], kw["total"]) for kw in seen] == [(0, 3), (1, 3), (2, 3), (3, 3)]


def test_report_page_renders_in_headless_chromium(tmp_path):
    from delaykit.paper.reproduce import reproduce

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("Debian's chromium is not installed (make test installs it where apt can reach its registry)")
    rep = reproduce(tmp_path)
    page = tmp_path / "index.html"
    cmd = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=5000", "--dump-dom", page.as_uri()]
    dom = subprocess.run(cmd, capture_output=True, text=True, timeout=120).stdout
    body = re.search(r"<body([^>]*)>", dom)
    assert body, dom[:500]
    attrs = dict(re.findall(r'data-([a-z-]+)="(\d+)"', body.group(1)))
    n_figs = sum(len(i.figures) for i in rep.items)
    n_tables = sum(len(i.tables) for i in rep.items)
    assert int(attrs["images"]) == n_figs and int(attrs["images-ok"]) == n_figs
    assert int(attrs["tables"]) == n_tables
    for item in rep.items:
        assert f'id="{item.key}"' in dom


def test_cli_design_and_reproduce(tmp_path):
    from typer.testing import CliRunner

    from delaykit.cli import app

    runner = CliRunner()
    res = runner.invoke(app, ["design", "--delay", "0.37", "--kp", "2.0", "--kv", "0:0.7:8", "--json"])
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    assert len(got["rows"]) == 8 and got["best"]["kv"] == 0.3
    assert set(got["rows"][0]) >= {"kp", "kv", "rightmost", "overshoot", "peak_time", "settling_time", "stable"}
    res = runner.invoke(app, ["design", "--delay", "0.37", "--kp", "1:2:3", "--kv", "0,0.3", "--delays", "0.3:0.45:3",
                              "--json", "--plot", str(tmp_path / "map.png")])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["best"] is not None and (tmp_path / "map.png").exists()
    res = runner.invoke(app, ["reproduce", "--out", str(tmp_path / "paper"), "--json"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "paper" / "index.html").exists()
    res = runner.invoke(app, ["design", "--delay", "0.37", "--kv", "0.5:0.2:3"])
    assert res.exit_code == 2 and "reversed" in res.output
