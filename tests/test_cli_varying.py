"""`delaykit simulate` with a delay that varies from packet to packet, and the jitter margin of `delaykit margins`,
run as a user would (typer's runner).

References:

* the library called directly in the test (``simulate_varying`` on a loop and a delay model built here, the trace
  from arrays rather than from the file): the command line must be a thin layer over it;
* the exact method-of-steps solver (plain ``delaykit simulate --period``), which shares no code with the event
  simulator: with a delay that does not actually change, both must agree;
* for the jitter margin of the paper's loop ``L = Kp e^{-sT} / s``: ``|1 + L| / (w |L|) = |jw + Kp e^{-jwT}| / (Kp w)``,
  minimised here by a dense grid and a bounded scalar search; for ``T = 0`` it falls to ``1 / Kp`` as ``w -> inf``
  (closed form); and the theorem that the jitter margin never exceeds the constant-delay margin.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.optimize import minimize_scalar
from typer.testing import CliRunner

from delaykit.cli import app
from delaykit.models import Controller, Loop
from delaykit.simulate.varying import DelaySchedule, DelayTrace, Jitter, simulate_varying
from delaykit.spectrum.jitter import jitter_margin

runner = CliRunner()
METRICS = ("overshoot", "peak_time", "rise_time", "settling_time", "peak", "settled")
PAPER = ("--kp", "1.31", "--period", "0.065")


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def run_json(*args):
    res = run(*args, "--json")
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def paper_loop(delay: float = 0.25) -> Loop:
    """The paper's loop (P on 1/s, +-1 m/s) sampled every 65 ms, built here without the command line."""
    return Loop("1/s", Controller.p(1.31), delay=delay, umin=-1, umax=1, period=0.065)


def same_metrics(got: dict, ref, tol: float = 1e-12) -> None:
    for k in METRICS:
        want = getattr(ref, k)
        if want is None or isinstance(want, bool):
            assert got[k] == want, k
        else:
            assert got[k] == pytest.approx(want, abs=tol), k


# ------------------------------------------------------------------------------------------ schedule, jitter
def test_schedule_run_is_the_library_call():
    got = run_json("simulate", *PAPER, "--delay", "0.25", "--delay-schedule", "2:0.40,5:0.30")
    ref = simulate_varying(paper_loop(), DelaySchedule([0.0, 2.0, 5.0], [0.25, 0.40, 0.30]))
    same_metrics(got, ref.metrics)
    assert (got["delay_min"], got["delay_max"]) == (0.25, 0.40)
    assert got["packets"] == ref.send_times.size and got["dropped"] == ref.dropped
    assert got["delay"] == 0.25 and got["varying"] is True


def test_schedule_that_falls_drops_packets_unless_order_is_kept():
    # the delay falls by 0.3 s (more than four periods) at t = 2 s: newer packets overtake older ones
    args = ("simulate", *PAPER, "--delay", "0.5", "--delay-schedule", "2:0.2")
    model = DelaySchedule([0.0, 2.0], [0.5, 0.2])
    free, fifo = run_json(*args), run_json(*args, "--keep-order")
    ref_free = simulate_varying(paper_loop(), model)
    ref_fifo = simulate_varying(paper_loop(), model, keep_order=True)
    assert ref_free.dropped > 0 and free["dropped"] == ref_free.dropped and free["keep_order"] is False
    assert fifo["dropped"] == 0 and fifo["keep_order"] is True
    same_metrics(free, ref_free.metrics)
    same_metrics(fifo, ref_fifo.metrics)
    assert free["settling_time"] != fifo["settling_time"]  # the two channels do differ


@pytest.mark.parametrize("order", [[], ["--keep-order"]], ids=["free", "kept"])
def test_the_printed_delay_law_says_the_packet_order_it_ran_with(order):
    # the jitter's own description must not say "may overtake" on a run whose packets were kept in order
    res = run("simulate", *PAPER, "--delay", "0.3", "--jitter", "0.05", "--seed", "1", *order)
    assert res.exit_code == 0, res.output
    line = " ".join(res.output.split()).split("Delay per packet: ")[1]
    if order:
        assert "in order" in line and "overtake" not in line, line
    else:
        assert "may overtake" in line and "in order" not in line, line


@pytest.mark.parametrize("dist, extra, model", [
    ("uniform", [], Jitter(0.0, "uniform", spread=0.1, seed=7)),
    ("exponential", ["--jitter-scale", "0.03"], Jitter(0.0, "exponential", scale=0.03, cap=0.1, seed=7)),
    ("gamma", ["--jitter-scale", "0.01", "--jitter-shape", "3"],
     Jitter(0.0, "gamma", scale=0.01, shape=3.0, cap=0.1, seed=7)),
])
def test_jitter_with_a_seed_is_the_library_call(dist, extra, model):
    got = run_json("simulate", *PAPER, "--delay", "0.25", "--jitter", "0.1", "--jitter-dist", dist, *extra,
                   "--seed", "7", "--t-end", "8")
    ref = simulate_varying(paper_loop(), DelaySchedule.constant(0.25) + model, t_end=8.0)
    same_metrics(got, ref.metrics)
    assert got["delay_min"] == pytest.approx(float(ref.delays.min()), abs=1e-15)
    assert got["delay_max"] == pytest.approx(float(ref.delays.max()), abs=1e-15)
    assert got["dropped"] == ref.dropped
    assert 0.25 <= got["delay_min"] < got["delay_max"] <= 0.35


def test_constant_schedule_equals_plain_simulate():
    # a schedule whose delay does not change: the event simulator against the method of steps, to 1e-9 (the
    # integrator's output is piecewise linear, so the record's metrics are exact)
    varying = run_json("simulate", *PAPER, "--delay", "0.3", "--delay-schedule", "3:0.3")
    plain = run_json("simulate", *PAPER, "--delay", "0.3")
    assert varying["delay_min"] == varying["delay_max"] == 0.3 and varying["dropped"] == 0
    for k in ("overshoot", "peak_time", "rise_time", "settling_time", "peak", "steady_state_error"):
        assert varying[k] == pytest.approx(plain[k], abs=1e-9), k
    assert varying["settled"] is plain["settled"] is True


def test_constant_schedule_on_a_lag_plant_matches_to_the_record():
    # with a lag the output curves between records; the rise time is read between records 0.01 s apart, so the
    # two solvers agree to O(dt^2), and the peak (refined by a cubic) far closer
    args = ("--plant", "1/(s*(0.2*s+1))", "--kp", "1.5", "--period", "0.065", "--delay", "0.3")
    varying = run_json("simulate", *args, "--jitter", "0", "--seed", "1")
    plain = run_json("simulate", *args)
    assert varying["overshoot"] == pytest.approx(plain["overshoot"], abs=1e-6)
    assert varying["rise_time"] == pytest.approx(plain["rise_time"], abs=1e-4)
    assert varying["settling_time"] == pytest.approx(plain["settling_time"], abs=1e-4)


def test_text_output_and_plot(tmp_path):
    png = tmp_path / "r.png"
    res = run("simulate", *PAPER, "--delay", "0.25", "--delay-schedule", "2:0.40", "--plot", png)
    assert res.exit_code == 0, res.output
    text = " ".join(res.stdout.split())
    assert "0.25000 to 0.40000" in text and "dropped" in text and "DelaySchedule" in text
    assert png.stat().st_size > 10_000
    csv_path = tmp_path / "r.csv"
    res = run("simulate", *PAPER, "--delay", "0.25", "--delay-schedule", "2:0.40", "--csv", csv_path)
    assert res.exit_code == 0, res.output
    data = np.loadtxt(csv_path, delimiter=",", skiprows=1)
    ref = simulate_varying(paper_loop(), DelaySchedule([0.0, 2.0], [0.25, 0.40]))
    assert np.allclose(data[:, 0], ref.t, atol=1e-8) and np.allclose(data[:, 1], ref.output, atol=1e-8)


# ------------------------------------------------------------------------------------------------- traces
def test_trace_csv_is_the_library_call(tmp_path):
    times, delays = [0.0, 1.0, 2.5, 4.0], [0.25, 0.31, 0.42, 0.28]
    f = tmp_path / "trace.csv"
    f.write_text("t,delay\n" + "".join(f"{t},{d}\n" for t, d in zip(times, delays)))
    got = run_json("simulate", *PAPER, "--delay", "0", "--delay-trace", f)
    ref = simulate_varying(paper_loop(), DelaySchedule.constant(0.0) + DelayTrace(times, delays))
    same_metrics(got, ref.metrics)
    assert (got["delay_min"], got["delay_max"]) == (0.25, 0.42)
    assert got["dropped"] == ref.dropped


def test_flight_log_latency_is_added_to_the_delay(tmp_path):
    rng = np.random.default_rng(0)
    t = np.round(np.arange(0.0, 20.0, 1 / 15), 6) + 100.0  # a log's clock need not start at 0
    lat = np.round(rng.uniform(2.0, 40.0, t.size), 3)  # ms
    f = tmp_path / "flight.csv"
    f.write_text("t,z,z_ref,u,latency_ms\n" + "".join(f"{a},1.0,1.0,0.0,{b}\n" for a, b in zip(t, lat)))
    got = run_json("simulate", *PAPER, "--delay", "0.3", "--delay-trace", f)
    ref = simulate_varying(paper_loop(), DelaySchedule.constant(0.3) + DelayTrace(t, lat / 1000.0))
    same_metrics(got, ref.metrics)
    assert got["delay_min"] == pytest.approx(float(ref.delays.min()), abs=1e-15)
    assert 0.302 <= got["delay_min"] < got["delay_max"] <= 0.340
    assert got["delay_model"]["kind"] == "sum"


# ---------------------------------------------------------------------------------------------- bad input
@pytest.fixture
def bad_files(tmp_path):
    files = {
        "text": "t,delay\n0,0.25\n1,abc\n",
        "negative": "t,delay\n0,0.25\n1,-0.1\n",
        "column": "t,lateness\n0,0.25\n",
        "empty": "",
    }
    out = {}
    for name, text in files.items():
        out[name] = tmp_path / f"{name}.csv"
        out[name].write_text(text)
    out["missing"] = tmp_path / "no_such_file.csv"
    return out


@pytest.mark.parametrize("args, fragments", [
    (["--delay-schedule", "5:0.3,2:0.4"], ["'2:0.4'", "must increase"]),
    (["--delay-schedule", "2:-0.1"], ["'2:-0.1'", "-0.1 s is negative"]),
    (["--delay-schedule", "2:abc"], ["'2:abc'", "T:DELAY"]),
    (["--delay-trace", "text"], ["row 3", "'abc'"]),
    (["--delay-trace", "negative"], ["row 3", "-0.1"]),
    (["--delay-trace", "column"], ["'delay'", "latency_ms", "t,lateness"]),
    (["--delay-trace", "empty"], ["empty.csv", "is empty"]),
    (["--delay-trace", "missing"], ["no_such_file.csv", "cannot be read"]),
    (["--jitter", "-0.05"], ["--jitter", "-0.05"]),
    (["--jitter", "0.1", "--jitter-dist", "cauchy"], ["--jitter-dist", "'cauchy'"]),
    (["--jitter", "0.1", "--jitter-dist", "gamma", "--jitter-scale", "0.01"], ["--jitter-shape"]),
    (["--seed", "3"], ["--seed", "--jitter"]),
])
def test_bad_input_exits_2_naming_the_value(args, fragments, bad_files):
    args = [str(bad_files[a]) if a in bad_files else a for a in args]
    res = run("simulate", *PAPER, "--delay", "0.3", *args)
    text = " ".join(res.output.split())
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "error:" in text
    squeezed = "".join(res.output.split())  # the console may wrap a long path anywhere
    for frag in fragments:
        assert frag in text or "".join(frag.split()) in squeezed, (frag, text)


def test_varying_delay_without_period_exits_2():
    res = run("simulate", "--kp", "1.31", "--delay", "0.3", "--delay-schedule", "2:0.4")
    text = " ".join(res.output.split())
    assert res.exit_code == 2 and "--period" in text and "Traceback" not in res.output


def test_varying_delay_refuses_a_sweep_and_a_ramp():
    for extra in (["--delay", "0.2,0.3"], ["--delay", "0.3", "--ramp", "0.5"]):
        res = run("simulate", *PAPER, *extra, "--jitter", "0.1")
        assert res.exit_code == 2 and "Traceback" not in res.output, res.output


# --------------------------------------------------------------------------------------------- margins
def _paper_jitter_margin(kp: float, T: float) -> float:
    """min over w > 0 of |jw + Kp e^{-jwT}| / (Kp w) (see the module docstring), by a dense grid then Brent."""
    g = lambda w: abs(1j * w + kp * np.exp(-1j * w * T)) / (kp * w)  # noqa: E731
    w = np.linspace(1e-4, 40.0, 400_001)
    i = int(np.argmin(g(w)))
    res = minimize_scalar(g, bounds=(w[max(i - 1, 0)], w[i + 1]), method="bounded", options={"xatol": 1e-12})
    return float(res.fun)


@pytest.mark.parametrize("kp, delay", [(1.31, 0.368), (2.0, 0.37), (0.8, 0.1)])
def test_margins_json_has_the_jitter_margin(kp, delay):
    got = run_json("margins", "--kp", kp, "--delay", delay)
    loop = Loop("1/s", Controller.p(kp), delay=delay, umin=-1, umax=1)
    assert got["jitter_margin"] == pytest.approx(jitter_margin(loop).margin, rel=1e-12)
    assert got["jitter_margin"] == pytest.approx(_paper_jitter_margin(kp, delay), rel=1e-7)
    assert 0 < got["jitter_margin"] < got["delay_margin"]  # Kao & Lincoln: never above the delay margin


def test_margins_jitter_margin_of_a_general_loop():
    got = run_json("margins", "--plant", "2/(s*(0.5*s+1))", "--controller", "pi", "--kp", "0.6", "--ki", "0.1",
                   "--delay", "0.2")
    loop = Loop("2/(s*(0.5*s+1))", Controller.pi(0.6, 0.1), delay=0.2, umin=-1, umax=1)
    assert got["jitter_margin"] == pytest.approx(jitter_margin(loop).margin, rel=1e-12)
    assert 0 < got["jitter_margin"] < got["delay_margin"]


def test_margins_jitter_margin_closed_form_without_delay():
    # L = Kp / s: |1 + L| / (w |L|) = sqrt(w^2 + Kp^2) / (Kp w), falling to 1 / Kp as w -> inf
    got = run_json("margins", "--kp", "2", "--delay", "0")
    assert got["jitter_margin"] == pytest.approx(0.5, rel=1e-12)


def test_margins_table_row_and_null_where_not_defined():
    res = run("margins", "--kp", "1.31", "--delay", "0.368")
    assert res.exit_code == 0 and "jitter margin (any variation)" in res.stdout
    assert "0.48" in res.stdout.split("jitter margin (any variation)")[1].splitlines()[0]
    sampled = run_json("margins", "--kp", "1.31", "--delay", "0.368", "--period", "0.065")
    assert sampled["jitter_margin"] is None and sampled["sampled"] is True
    unstable = run_json("margins", "--kp", "5", "--delay", "0.37")  # Kp T > pi/2: unstable, no margins
    assert unstable["stable"] is False and unstable["jitter_margin"] is None
