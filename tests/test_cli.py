"""The command line, run as a user would (in-process through typer's runner, and once as a process)."""

from __future__ import annotations

import csv
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit import AltitudeLoop, simulate
from delaykit.cli import app, parse_delays
from delaykit.paper.data import TABLE1

runner = CliRunner()


def run(*args):
    return runner.invoke(app, list(args))


def test_simulate_json_has_the_metrics_of_the_library():
    res = run("simulate", "--kp", "1.31", "--delay", "0.368", "--json")
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    ref = simulate(AltitudeLoop(kp=1.31, delay=0.368)).metrics
    for k in ("overshoot", "peak_time", "rise_time", "settling_time"):
        assert got[k] == getattr(ref, k)


def test_simulate_pv_sampled_down_step():
    res = run("simulate", "--kp", "2", "--kv", "0.3", "--delay", "0.37", "--velocity", "filtered",
              "--period", "0.065", "--step", "-1", "--z0", "2", "--vmax", "none", "--json")
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    loop = AltitudeLoop(kp=2, kv=0.3, delay=0.37, velocity="filtered", period=0.065, vmax=None)
    assert got["overshoot"] == simulate(loop, -1.0, z0=2.0).metrics.overshoot
    assert got["loop"]["period"] == 0.065 and got["loop"]["vmax"] is None


def test_table1_sweep_shows_the_paper_beside_delaykit():
    res = run("simulate", "--kp", "1.31", "--delay", "table1", "--json")
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)
    assert [r["paper_overshoot"] for r in rows] == [mo for _, _, mo in TABLE1]
    assert all(math.isclose(r["delay"], k * 0.065, abs_tol=1e-12) for r, (k, _, _) in zip(rows, TABLE1))
    table = run("simulate", "--kp", "1.31", "--delay", "table1")
    assert "paper Mo" in table.stdout and "2.300" in table.stdout


@pytest.mark.parametrize("extra", [["--vmax", "none"], ["--period", "0.065"], ["--kv", "0.3"], ["--step", "2"],
                                   ["--output-delay", "0.1"]])
def test_table1_sweep_of_another_loop_has_no_paper_column(extra):
    """Kp = 1.31 and the Table 1 delays, but not the paper's loop (no saturation, a sampled controller, a velocity
    term, another step, a delayed measurement): the paper's overshoots do not apply and must not be shown.  A check
    of ``kp == 1.31`` alone would have shown them."""
    res = run("simulate", "--kp", "1.31", "--delay", "table1", *extra, "--json")
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout)
    assert len(rows) == len(TABLE1)
    assert all(math.isclose(r["delay"], k * 0.065, abs_tol=1e-12) for r, (k, _, _) in zip(rows, TABLE1))
    assert not any("paper_overshoot" in r for r in rows)
    table = run("simulate", "--kp", "1.31", "--delay", "table1", *extra)
    assert table.exit_code == 0, table.output
    assert "Mo %" in table.stdout and "paper Mo" not in table.stdout and "paper−ours" not in table.stdout


def test_sweep_csv_and_plot(tmp_path):
    csv_path, png = tmp_path / "r.csv", tmp_path / "r.png"
    res = run("simulate", "--kp", "1.31", "--delay", "0.2:0.4:3", "--csv", str(csv_path), "--plot", str(png),
              "--t-end", "5", "--dt", "0.5")
    assert res.exit_code == 0, res.output
    assert png.stat().st_size > 10_000
    with open(csv_path) as fh:
        rows = list(csv.DictReader(fh))
    assert set(rows[0]) == {"delay", "t", "z", "z_ref", "u"}
    assert len(rows) == 3 * 11
    r = simulate(AltitudeLoop(kp=1.31, delay=0.3), t_end=5)
    mid = [row for row in rows if float(row["delay"]) == 0.3]
    assert all(math.isclose(float(x["z"]), float(r.altitude(float(x["t"]))), abs_tol=1e-8) for x in mid)


def test_no_figure_unless_asked(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert run("simulate", "--kp", "1.31", "--delay", "0.3").exit_code == 0
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--kp", "1", "--delay", "-0.3"], "delay must be at least 0"),
        (["--kp", "-1", "--delay", "0.3"], "kp"),
        (["--kp", "1", "--delay", "0.3", "--velocity", "magic"], "velocity"),
        (["--kp", "1", "--delay", "0.3", "--period", "0"], "period"),
        (["--kp", "1", "--delay", "0.3", "--t-end", "0"], "t_end"),
        (["--kp", "1", "--delay", "0.3", "--step", "nan"], "step"),
        (["--kp", "1", "--delay", "0.3", "--vmax", "fast"], "--vmax"),
        (["--kp", "1", "--delay", "0.5:0.2:3"], "STOP"),
        (["--kp", "1", "--delay", "soon"], "not a delay"),
    ],
)
def test_bad_input_is_one_line_and_status_2(args, fragment):
    res = run("simulate", *args)
    assert res.exit_code == 2
    assert fragment in res.output
    assert "Traceback" not in res.output


def test_help_everywhere():
    for cmd in ([], ["simulate"], ["report"], ["roots"], ["lambert"]):
        res = run(*cmd, "--help")
        assert res.exit_code == 0 and "Usage" in res.output


def test_report_writes_table_and_figure(tmp_path):
    res = run("report", "--out", str(tmp_path / "o"), "--json")
    assert res.exit_code == 0, res.output
    rep = json.loads(res.stdout)
    assert rep["verdict"].startswith("reproduced to within solver error")
    assert (tmp_path / "o" / "responses.png").stat().st_size > 10_000
    md = (tmp_path / "o" / "table1.md").read_text()
    assert "| 5.6646 |" in md and "2.300" in md
    # the printed overshoots are above the exact ones, all by the equivalent of under a millisecond of delay
    for row in rep["table1"][1:]:
        assert 0.0 < row["difference"] < 0.05 and 0.0 < row["extra_delay"] < 1e-3


def test_parse_delays():
    assert parse_delays("0.1,0.2") == [0.1, 0.2]
    assert parse_delays("0.3:0.3:1") == [0.3]


def test_installed_script_exits_2_without_traceback():
    proc = subprocess.run([sys.executable, "-m", "delaykit.cli", "simulate", "--kp", "1", "--delay", "-1"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "delay must be at least 0" in proc.stderr and "Traceback" not in proc.stderr


def test_roots_json_matches_the_library(tmp_path):
    from delaykit.spectrum.roots import find_roots

    png = tmp_path / "fig8.png"
    res = run("roots", "--kp", "2", "--kv", "0.3", "--delay", "0.37", "--region", "-10", "2", "0", "100",
              "--json", "--plot", str(png))
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    ref = find_roots(AltitudeLoop(kp=2, kv=0.3, delay=0.37).characteristic(), (-10, 2, 0, 100))
    assert got["certified"] is True and got["stable"] is True
    assert len(got["roots"]) == ref.roots.size == 7
    assert abs(got["rightmost"][0] - (-3.195055)) < 1e-6 and abs(got["rightmost"][1] - 5.581987) < 1e-6
    assert math.isclose(got["neutral_line"], math.log(0.3) / 0.37)
    assert png.stat().st_size > 10_000


def test_roots_filtered_and_unstable_warning():
    res = run("roots", "--kp", "2", "--kv", "0.3", "--delay", "0.37", "--velocity", "filtered", "--json")
    assert res.exit_code == 0 and json.loads(res.stdout)["neutral_line"] is None
    res = run("roots", "--kp", "2", "--kv", "1.2", "--delay", "0.37")
    assert res.exit_code == 0 and "UNSTABLE" in res.stdout and "cannot be stable" in res.stdout


def test_lambert_json():
    res = run("lambert", "--a0", "0", "--a1", "-1.31", "--delay", "0.368", "--branches", "-3:3", "--json")
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    assert [r["branch"] for r in got["roots"]] == list(range(-3, 4))
    for r in got["roots"]:
        s = complex(r["re"], r["im"])
        assert abs(s + 1.31 * np.exp(-0.368 * s)) < 1e-12
    assert got["rightmost"][0] == max(r["re"] for r in got["roots"])


@pytest.mark.parametrize("args, fragment", [
    (["roots", "--kp", "2", "--delay", "0.37", "--region", "2", "1", "0", "5"], "re_min"),
    (["roots", "--kp", "2", "--delay", "-0.37"], "delay"),
    (["lambert", "--a1", "-1", "--delay", "1", "--branches", "3:1"], "reversed"),
    (["lambert", "--a1", "nan", "--delay", "1"], "a1"),
])
def test_roots_and_lambert_bad_input(args, fragment):
    res = run(*args)
    assert res.exit_code == 2 and fragment in res.output and "Traceback" not in res.output


# ---- the demo: an estimate without an interval, and a flight that gives nothing --------------------------------


def _no_interval_estimate():
    from delaykit.identify.estimation import DelayEstimate, EstimateParams

    return DelayEstimate(delay=0.3712, stderr=None, ci=None, method="trajectory", flights=1,
                         params=EstimateParams(offsets=(0.0,), scales=(1.0,), lag=(0.05,)))


def test_demo_command_with_no_interval(tmp_path, monkeypatch):
    from types import SimpleNamespace

    import delaykit.paper.demo as demo

    est = _no_interval_estimate()
    rep = SimpleNamespace(estimate=est, true_delay=0.37, error=est.delay - 0.37, kv=0.3, pv_kp=2.0, kv_source="design",
                          p_metrics=[{"settling_time": 4.0}, {"settling_time": None}],
                          pv_metrics=[{"settling_time": 2.5}], comp_metrics=None, varying_flight=None,
                          identification={"error": "the logs hold no step"},
                          to_dict=lambda: {"estimate": est.to_dict()})
    monkeypatch.setattr(demo, "run_demo", lambda *a, **k: rep)
    res = run("demo", "--out", str(tmp_path))
    assert res.exit_code == 0, res.output
    assert "no interval" in res.stdout and "0.3712" in res.stdout
    # a step that did not settle is counted, not averaged in as nan; a failed identification says why
    said = " ".join(res.stdout.split())
    assert "P 4.00 s (1 of 2 not settled)" in said and "nan" not in said
    assert "not identified" in said and "the logs hold no step" in said
    res = run("demo", "--out", str(tmp_path), "--json")
    assert res.exit_code == 0 and json.loads(res.stdout)["estimate"]["ci"] is None


def test_demo_report_with_no_interval(tmp_path, monkeypatch):
    from types import SimpleNamespace

    import delaykit.paper.demo as demo
    import delaykit.plotting.figures as figures
    from delaykit.identify.flightlog import synthetic_log, write_log

    monkeypatch.setattr(figures, "plot_fit", lambda *a, **k: None)
    log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.37), 1.0, after=5.0)
    path = tmp_path / "p_flight_1.csv"
    write_log(path, {"t": log.t, "z": log.z, "z_ref": log.z_ref})
    flight = SimpleNamespace(logs=(path,), packet_interval=None, latency_median_ms=0.1, latency_p99_ms=0.2,
                             to_dict=lambda: {})
    metrics = demo._metrics((path,))
    files = demo._write(tmp_path, None, _no_interval_estimate(), 0.05, 0.3, SimpleNamespace(reason="fastest"),
                        flight, flight, metrics, metrics)
    md = (tmp_path / "demo.md").read_text()
    assert "(no interval)" in md and "0.3712" in md
    assert json.loads((tmp_path / "demo.json").read_text())["estimate"]["ci"] is None
    assert files[0] == tmp_path / "demo.md"


def test_plant_dead_time_adds_to_the_delay_option():
    """A dead time written into --plant (exp(-12*s)) adds to --delay, in simulate as in roots."""
    res = run("simulate", "--plant", "0.62*exp(-12*s)/(150*s+1)", "--controller", "pi", "--kp", "2", "--ki", "0.02",
              "--delay", "0.5", "--t-end", "200", "--json")
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["loop"]["delay"] == pytest.approx(12.5)


def test_loop_file_controller_override_and_paper_limits(tmp_path):
    f = tmp_path / "loop.toml"
    f.write_text('plant = "1/((s+1)*(0.5*s+1))"\ncontroller = "pid"\nkp = 1.5\nki = 0.8\nkd = 1.0\n'
                 'derivative_filter = 0.05\ndelay = 0.2\numin = -2\numax = 2\n')
    res = run("simulate", "--loop", str(f), "--controller", "pi", "--json")
    assert res.exit_code == 0, res.output
    ctrl = json.loads(res.stdout)["loop"]["controller"]
    assert ctrl["kind"] == "pi" and ctrl["kp"] == 1.5 and ctrl["ki"] == 0.8 and "kd" not in ctrl
    # the paper's loop keeps its +1 limit when only --umin is given
    res = run("simulate", "--kp", "1.31", "--delay", "0.368", "--umin", "-0.5", "--json")
    loop = json.loads(res.stdout)["loop"]
    assert res.exit_code == 0 and loop["umin"] == -0.5 and loop["umax"] == 1.0
    res = run("simulate", "--kp", "1.31", "--delay", "0.368", "--controller", "p", "--kv", "0.3")
    assert res.exit_code == 2 and "--controller p has no --kv" in res.output


def test_design_keeps_the_filtered_velocity_when_kv_starts_at_zero():
    """--velocity filtered with Kv candidates from 0: the Kv > 0 rows are the filtered PV loop."""
    from delaykit import Controller, Loop
    from delaykit.spectrum.stability import rightmost

    res = run("design", "--plant", "1/(s*(0.05*s+1))", "--velocity", "filtered", "--filter-wn", "5", "--kp", "2",
              "--kv", "0,0.3", "--delay", "0.3", "--json")
    assert res.exit_code == 0, res.output
    row = [r for r in json.loads(res.stdout)["rows"] if r["kv"] == 0.3][0]
    want = rightmost(Loop("1/(s*(0.05*s+1))", Controller.pv(2.0, 0.3, velocity="filtered", filter_wn=5.0),
                          delay=0.3, umin=-math.inf, umax=math.inf)).abscissa
    assert row["abscissa"] == pytest.approx(want, abs=1e-9)
