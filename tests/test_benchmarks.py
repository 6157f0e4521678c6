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


# ------------------------------------------------------------------ the docs tables (`--write-docs`), fast checks
DOCS = ROOT / "docs" / "benchmarks.md"


def _docs_helper():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import _docs
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return _docs


def test_every_benchmark_table_is_in_its_scripts_block():
    """Each script that writes docs has exactly one begin/end pair in docs/benchmarks.md, and every table line of
    that page lies inside some script's block (so no hand-kept table is left that a script does not regenerate)."""
    helper = _docs_helper()
    writers = sorted(p.name for p in (ROOT / "benchmarks").glob("bench_*.py")
                     if "--write-docs" in p.read_text(encoding="utf-8"))
    assert {"bench_simulate.py", "bench_general.py", "bench_roots.py", "bench_frequency.py",
            "bench_identify.py"} <= set(writers)
    doc = DOCS.read_text(encoding="utf-8")
    for name in writers:
        begin, end = helper.markers(name)
        assert doc.count(begin) == 1 and doc.count(end) == 1 and doc.index(begin) < doc.index(end), name
    inside = None
    for line in doc.splitlines():
        if line.startswith("<!-- bench_") and line.endswith(":begin -->"):
            assert inside is None, f"nested block at {line}"
            inside = line[5:-len(":begin -->")]
            assert inside in writers, f"{inside} has a block but no --write-docs"
        elif line.startswith("<!-- bench_") and line.endswith(":end -->"):
            assert line == f"<!-- {inside}:end -->", line
            inside = None
        elif line.startswith("|"):
            assert inside is not None, f"a table line outside every script's block: {line[:60]}"
    assert inside is None


def test_write_docs_replaces_only_its_block(tmp_path):
    """The helper rewrites one script's block of a copy of the page (the date line and the table as Markdown) and
    leaves every other byte as it was; a page without the markers is refused with an error naming them."""
    from rich.table import Table

    helper = _docs_helper()
    page = tmp_path / "benchmarks.md"
    page.write_text(DOCS.read_text(encoding="utf-8"), encoding="utf-8")
    original = page.read_text(encoding="utf-8")
    table = Table(title="Roots (median times)")
    for col in ("case", "time | ms"):
        table.add_column(col)
    table.add_row("Table 3, Kv = 0", "0.4\nms")
    table.add_row("qpmr example 2", "3.3 s")
    helper.write_docs("bench_roots.py", table, path=page)
    new = page.read_text(encoding="utf-8")
    begin, end = helper.markers("bench_roots.py")
    head, rest = new.split(begin)
    block, tail = rest.split(end)
    old_head, old_rest = original.split(begin)
    assert head == old_head and tail == old_rest.split(end)[1]  # everything outside the block is unchanged
    lines = block.strip().splitlines()
    assert lines[0].startswith("Measured ") and " UTC by `--write-docs` on " in lines[0] and "load average" in lines[0]
    assert "Roots (median times):" in lines
    assert "| case | time \\| ms |" in lines and "|---|---|" in lines
    assert "| Table 3, Kv = 0 | 0.4; ms |" in lines and "| qpmr example 2 | 3.3 s |" in lines
    assert "qpmr's found" not in block  # the old table is gone from this block ...
    sim_begin, sim_end = helper.markers("bench_simulate.py")  # ... and the other scripts' tables are not
    assert new.split(sim_begin)[1].split(sim_end)[0] == original.split(sim_begin)[1].split(sim_end)[0]
    assert "| jitcdde" in new.split(sim_begin)[1].split(sim_end)[0]
    helper.write_docs("bench_roots.py", table, path=page)  # idempotent apart from the time stamp
    assert page.read_text(encoding="utf-8").count(begin) == 1
    page.write_text(original.replace(end, ""), encoding="utf-8")
    with pytest.raises(ValueError, match="bench_roots.py:end"):
        helper.write_docs("bench_roots.py", table, path=page)


def test_poles_benchmark_runs_and_its_anchor_agrees_near_the_dominant_poles(tmp_path):
    """The poles benchmark (Wood-Berry under BLT PI): both boxes certified, with the counts of the guide's example
    (5 poles in the small box); near the dominant poles the Padé-10 model's eigenvalues (python-control) agree with
    the certified roots to 1e-9, while in the larger box the Padé models miss some of the roots."""
    out = tmp_path / "p.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_poles.py"), "--repeats", "1", "--json",
                    str(out)], check=True, capture_output=True, text=True, cwd=ROOT / "benchmarks")
    rows = json.loads(out.read_text())["rows"]
    assert all(r["certified"] for r in rows) and rows[0]["roots"] == 5 and rows[1]["roots"] > 5
    pade10 = {a["order"]: a for a in rows[0]["pade"]}[10]
    assert pade10["max_error"] < 1e-9 and pade10["missed"] == 0
    assert all(a["missed"] > 0 for a in rows[1]["pade"])


@pytest.mark.slow
@pytest.mark.realtime
def test_relay_benchmark_small(tmp_path):
    # every packet arrives, through the relay and directly, and none through the relay before its set delay (no
    # speed is asserted: the p99 target depends on the machine's load)
    out = tmp_path / "relay.json"
    subprocess.run([sys.executable, str(ROOT / "benchmarks" / "bench_relay.py"), "--seconds", "1", "--json",
                    str(out)], check=True, capture_output=True, text=True, timeout=300)
    rows = json.loads(out.read_text())["rows"]
    assert [(r["transport"], r["delay"], r["priority"]) for r in rows] == [
        ("timer", None, None), ("timer", None, 10), ("udp", None, None), ("udp", 0.0, None), ("udp", 0.2, None),
        ("udp", 0.2, 10), ("tcp", None, None), ("tcp", 0.2, None), ("tcp", 0.2, 10)]
    assert all(r["packets"] == r["sent"] == 50 for r in rows)
    assert all(r["scheduling"] == "ordinary" for r in rows if r["priority"] is None)
    assert all(r["scheduling"] == "SCHED_FIFO 10" or r["scheduling"].startswith("refused (")
               for r in rows if r["priority"] is not None)
    assert all(r["min_ms"] > -1.0 for r in rows if r["delay"] is not None)  # never early (1 ms: clock conversion)
    assert all(r["relay_p99_ms"] is not None for r in rows if r["delay"] is not None)
