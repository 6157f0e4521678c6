"""The benchmark scripts run, and reach their accuracy targets, on a small case (no timing is asserted)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_simulation_benchmark_small(tmp_path):
    out = tmp_path / "r.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_simulate.py"), "--loops", "300",
                    "--reference", "3", "--no-cold", "--json", str(out)], check=True, capture_output=True, text=True)
    res = json.loads(out.read_text())
    # delaykit against the independent reference solver: far inside the 1e-3 pp / 1 ms target
    assert res["delaykit"]["error"]["overshoot"] < 1e-9
    assert max(res["delaykit"]["error"][k] for k in ("peak_time", "rise_time", "settling_time")) < 1e-5
    assert res["targets_met"] == {"delaykit": True, "jitcdde": True}


@pytest.mark.slow
def test_general_loop_benchmark_small(tmp_path):
    """The PID loop benchmark: delaykit (continuous and sampled) and jitcdde reach the accuracy target against
    the independent oracle (tests/oracle_loop.py) on a small case."""
    out = tmp_path / "g.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_general.py"), "--loops", "60",
                    "--reference", "2", "--jit-loops", "60", "--no-cold", "--json", str(out)],
                   check=True, capture_output=True, text=True)
    res = json.loads(out.read_text())
    assert res["targets_met"] == {"delaykit_continuous": True, "delaykit_sampled": True, "jitcdde": True}
    assert res["delaykit"]["continuous"]["error"]["overshoot"] < 1e-6


@pytest.mark.slow
def test_estimation_benchmark_small(tmp_path):
    out = tmp_path / "e.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_estimate.py"), "--flights", "12",
                    "--json", str(out)], check=True, capture_output=True, text=True)
    res = json.loads(out.read_text())
    tr = res["trajectory"]
    assert tr["answered"] == 12 and tr["median_error"] < 2e-3
    assert res["overshoot"]["answered"] <= 12


@pytest.mark.slow
def test_roots_benchmark_quick_runs(tmp_path):
    out = tmp_path / "r.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_roots.py"), "--quick", "--json", str(out)],
                   check=True, capture_output=True, text=True)
    res = json.loads(out.read_text())
    assert all(c["certified"] for c in res["cases"])
    assert all(c["qpmr_found_by_delaykit"] == c["qpmr_roots"] for c in res["cases"] if "mazanti" not in c["case"])


@pytest.mark.slow
def test_frequency_benchmark_quick_runs(tmp_path):
    """The frequency benchmark's quick mode: delaykit's L(jw) equals both anchors' (python-control's response of
    the delay-free part times exp(-jwT), and plain NumPy) to rounding, the stability map equals the full certified
    search point by point, and the exact phase margin is close to the Padé-8 approximation's."""
    out = tmp_path / "f.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_frequency.py"), "--quick", "--json", str(out)],
                   check=True, capture_output=True, text=True)
    res = json.loads(out.read_text())
    assert all(r["error_control"] < 1e-12 and r["error_numpy"] < 1e-12 for r in res["bode"])
    assert res["map"]["error"] < 1e-9 and 0 < res["map"]["stable_points"] < res["map"]["points"]
    assert all(r["pade_pm_error_deg"] < 0.5 for r in res["margins"])
    assert set(res["targets_met"]) == {"margins", "bode", "map"}
