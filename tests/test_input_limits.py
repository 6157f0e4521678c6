"""Hostile input (issue 25): work limits refused up front, numbers read as files mean them, and clear errors.

Each case asserts the exit status 2 (command line) or delaykit's exception type (library) and that the message
names the bad value; or, where a result was silently wrong before, the now-correct result against an independent
reference.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit import AltitudeLoop, InvalidTypeError, InvalidValueError, simulate
from delaykit.cli import app
from delaykit.identify.flightlog import FlightLog, LogError
from delaykit.identify.iodata import Experiment, read_experiment
from delaykit.models.budget import MAX_GRID_POINTS, MAX_RANGE_POINTS, MAX_SAMPLES
from delaykit.models.ranges import parse_integer, parse_number, parse_range

runner = CliRunner()


def run(*args: str):
    return runner.invoke(app, list(args))


def one_line(text: str) -> str:
    """The output with rich's line wrapping undone (wrapping is not what these tests are about)."""
    return " ".join(text.split())


def refused(res, *fragments: str) -> str:
    """Assert a one-message refusal with status 2 whose text holds every fragment; return the text."""
    text = one_line(res.output)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    for f in fragments:
        assert f in text, text
    return text


# -- numbers as text -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("text", ["1_0", "１２", "٣", "1 0", "0x10", "", "1e", "--1"])
def test_parse_number_refuses_what_float_reads_but_a_file_does_not_mean(text):
    with pytest.raises(InvalidValueError, match="not a number"):
        parse_number(text, "z")


@pytest.mark.parametrize("text", ["0", "-1.5", "+2", ".5", "5.", "2e-3", "1E+300", " 7 ", "nan", "-inf"])
def test_parse_number_reads_ascii_decimal_as_float_does(text):
    got, want = parse_number(text), float(text)  # Python's own reading, for these plain numbers
    assert got == want or (math.isnan(got) and math.isnan(want))


@pytest.mark.parametrize("text", ["12", "-3", "+4"])
def test_parse_integer(text):
    assert parse_integer(text) == int(text)


@pytest.mark.parametrize("text", ["1_0", "１２", "1.0", "", "+-1"])
def test_parse_integer_refuses(text):
    with pytest.raises(InvalidValueError, match="not an integer"):
        parse_integer(text)


@pytest.mark.parametrize("spec", ["1_0", "１２", "0:1_0:3", "0:1:1_0", "0:1:３", "1,２"])
def test_ranges_refuse_underscores_and_unicode_digits(spec):
    from delaykit.errors import RangeSpecError

    with pytest.raises(RangeSpecError, match="START:STOP:N"):
        parse_range(spec, "kp")


@pytest.mark.parametrize("cell", ["1_0", "１２"])
def test_a_log_cell_that_python_would_read_is_not_a_number(tmp_path, cell):
    rows = "".join(f"{k * 0.1:.1f},{0.0 if k < 3 else 1.0},{0.1 * k}\n" for k in range(12))
    p = tmp_path / "log.csv"
    p.write_text("t,u,y\n" + rows.replace("0.5\n", f"{cell}\n", 1), encoding="utf-8")
    with pytest.raises(LogError, match=f"row 7: y is '{cell}', not a number"):
        read_experiment(p, outputs=["y"], input="u")
    q = tmp_path / "flight.csv"
    q.write_text("t,z,z_ref\n" + "".join(f"{k * 0.1:.1f},{'0' if k != 4 else cell},{0 if k < 3 else 1}\n"
                                         for k in range(12)), encoding="utf-8")
    with pytest.raises(LogError, match=f"row 6: z is '{cell}', not a number"):
        FlightLog.from_csv(q)


def test_a_wide_log_reads_every_column_in_place(tmp_path):
    """A log with 3,000 columns (reading was quadratic in them): the used columns and every extra column come back
    as written, each extra kept under its own name (the first of a repeated name)."""
    ncol, nrow = 3000, 20
    names = ["t", "z", "z_ref"] + [f"c{j}" for j in range(ncol - 4)] + ["c5"]  # the last repeats c5
    lines = [",".join(names)]
    for i in range(nrow):
        lines.append(",".join([f"{0.1 * i:.1f}", f"{i}", "1" if i >= 5 else "0"]
                              + [f"{i * 10000 + j}" for j in range(ncol - 3)]))
    p = tmp_path / "wide.csv"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    log = FlightLog.from_csv(p)
    assert np.array_equal(log.z, np.arange(nrow)) and log.step_time == 0.5
    assert len(log.extra) == ncol - 4
    for j in (0, 1, 5, 1234, ncol - 5):
        # (a column of numbers comes back as a float array: the log is read into arrays, not kept as text)
        assert np.array_equal(log.extra[f"c{j}"], [i * 10000 + j for i in range(nrow)])
    e = read_experiment(p, outputs=["c1234", "c5"], input="z_ref")
    assert np.array_equal(e.outputs["c1234"], [i * 10000 + 1234 for i in range(nrow)])
    assert np.array_equal(e.outputs["c5"], [i * 10000 + 5 for i in range(nrow)])


# -- ranges and grids ----------------------------------------------------------------------------------------
def test_a_range_beyond_the_limit_is_refused_before_it_is_built():
    with pytest.raises(InvalidValueError, match=f"above the limit of {MAX_RANGE_POINTS}"):
        parse_range("0.2:0.5:100000000", "--delay")
    assert len(parse_range(f"0:1:{MAX_RANGE_POINTS}")) == MAX_RANGE_POINTS  # the limit itself is allowed


@pytest.mark.parametrize("args", [
    ["simulate", "--kp", "1.31", "--delay", "0.2:0.5:100000000"],
    ["design", "--kv", "0:0.7:100000000", "--delay", "0.3"],
])
def test_cli_range_limit(args):
    refused(run(*args), "100000000 values", f"above the limit of {MAX_RANGE_POINTS}", "MAX_RANGE_POINTS")


def test_design_grid_limit():
    refused(run("design", "--kv", "0:0.7:10000", "--kp", "0:1:1000", "--delay", "0.3"),
            "kp x kv: 10000000 candidates", f"above the limit of {MAX_GRID_POINTS}")


@pytest.mark.parametrize("spec, fragment", [
    ("-100000000:100000000", "200000001 branches"),
    ("99999999999999999999", "branch 99999999999999999999 is out of range"),
    ("1_0", "--branches '1_0' must be K1:K2"),
])
def test_lambert_branches_refused(spec, fragment):
    refused(run("lambert", "--a1", "-1", "--delay", "0.3", "--branches", spec), fragment)


def test_lambert_library_branches():
    from delaykit.spectrum.lambert import lambert_roots

    with pytest.raises(InvalidValueError, match="above the limit"):
        lambert_roots(0, -1, 0.3, branches=range(-10**8, 10**8))
    with pytest.raises(InvalidValueError, match="branch 99999999999999999999"):
        lambert_roots(0, -1, 0.3, branches=[99999999999999999999])
    with pytest.raises(InvalidTypeError, match="must be an integer, got 0.5"):
        lambert_roots(0, -1, 0.3, branches=[0.5])


# -- records -------------------------------------------------------------------------------------------------
def test_csv_sampling_limit_is_checked_before_the_simulation(tmp_path):
    out = tmp_path / "r.csv"
    refused(run("simulate", "--kp", "1.31", "--delay", "0.3", "--csv", str(out), "--dt", "1e-9"),
            "15000000001 samples", f"above the limit of {MAX_SAMPLES}", "--dt")
    assert not out.exists()


def test_response_sample_limit():
    r = simulate(AltitudeLoop(kp=1.31, delay=0.3), t_end=2.0)
    with pytest.raises(InvalidValueError, match="MAX_SAMPLES"):
        r.sample(dt=1e-9)
    assert r.sample(dt=0.5)["t"].tolist() == [0.0, 0.5, 1.0, 1.5, 2.0]


def test_resample_limit():
    t = np.linspace(0.0, 10.0, 30) ** 1.1
    with pytest.raises(InvalidValueError, match="resample=1e-09 s.*MAX_SAMPLES"):
        Experiment.from_arrays(t, {"y": t}, u=(t > 2.0) * 1.0, resample=1e-9)


def test_a_simulation_far_beyond_the_piece_limit_is_refused_early():
    """t_end = 1e7 s of a loop whose pieces are at most one delay (0.3 s) long needs some 3e7 pieces, far above
    the limit (the workspace would have grown to gigabytes before); the refusal names the estimate."""
    from delaykit.simulate.simulation import _CAP_MAX

    with pytest.raises(InvalidValueError, match=f"more than {_CAP_MAX} polynomial pieces") as info:
        simulate(AltitudeLoop(kp=1.31, delay=0.3), t_end=1e7)
    estimate = float(str(info.value).split("about ")[1].split()[0])
    assert 1e7 / 0.3 / 2 < estimate < 1e7 / 0.3 * 2  # pieces of about one delay


def test_a_run_no_piece_budget_could_cover_is_refused_before_it_starts():
    """t_end = 1e50 s: even pieces of the longest length the loop's rates allow (4 hmax) would number ~1e49, so the
    run is refused before the kernel starts (it used to stall at t = 904 s, where the kernel's time resolution,
    1e-12 t_end, passed the delay, and blame the delay)."""
    from delaykit.simulate.simulation import _CAP_MAX

    with pytest.raises(InvalidValueError, match=f"more than {_CAP_MAX} polynomial pieces .* longest pieces"):
        simulate(AltitudeLoop(kp=1.31, delay=0.3), t_end=1e50)
    refused(run("simulate", "--kp", "1", "--delay", "0.3", "--t-end", "1e50"), "polynomial pieces")


def test_stall_message_names_the_cause():
    """The stalled status is explained from the loop (its delays and limits), not by one fixed text."""
    from delaykit.models.loop import loop_from_dict
    from delaykit.simulate._layout import loop_matrices, param_row
    from delaykit.simulate.simulation import _stall_message

    def row(loop):
        return param_row(loop, loop_matrices(loop), step=1.0, slope=0.0, norm=1.0, t_end=15.0, band=0.02,
                         dist=None)

    tiny = loop_from_dict({"plant": "1/s", "kp": 1.31, "delay": 1e-9})
    assert "the delay 1e-09 s is too short" in _stall_message(row(tiny), 3.0)
    limited = loop_from_dict({"plant": "1/s", "kp": 1.31, "delay": 0.3, "vmax": 1.0})
    assert "switches at its limit" in _stall_message(row(limited), 3.0)
    free = loop_from_dict({"plant": "1/s", "kp": 1.31, "delay": 0.3})
    assert "limit" not in _stall_message(row(free), 3.0)


# -- seeds ---------------------------------------------------------------------------------------------------
def test_negative_seed():
    refused(run("simulate", "--kp", "1.31", "--delay", "0.3", "--period", "0.065", "--jitter", "0.1", "--seed", "-1"),
            "seed must be at least 0", "-1")


# -- spectra for delays of any size ----------------------------------------------------------------------------
@pytest.mark.parametrize("delay", [0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.3])
def test_rightmost_root_of_the_p_loop_for_tiny_delays(delay):
    """The P loop s + 2 exp(-T s): its rightmost root is W_0(-2 T) / T (Lambert W, SciPy; -2 at T = 0).  With a
    delay of 1e-9 s the search started at -1/T and gave an uncertified abscissa of 10.87 (UNSTABLE)."""
    from scipy.special import lambertw

    from delaykit.spectrum.stability import rightmost

    rm = rightmost(AltitudeLoop(kp=2.0, delay=delay, vmax=None))
    want = -2.0 if delay == 0 else complex(lambertw(-2.0 * delay, 0)) / delay
    assert rm.certified and rm.stable
    assert abs(rm.root - want) <= 1e-9 * abs(want)


@pytest.mark.parametrize("delay", ["0", "1e-12", "1e-9"])
def test_roots_and_margins_agree_for_tiny_delays(delay):
    import json

    roots = run("roots", "--kp", "2", "--delay", delay, "--json")
    assert roots.exit_code == 0, roots.output
    data = json.loads(roots.stdout)
    assert data["stable"] and data["rightmost_certified"] and abs(data["abscissa"] + 2.0) < 1e-6
    margins = run("margins", "--kp", "2", "--delay", delay, "--json")
    assert margins.exit_code == 0, margins.output
    m = json.loads(margins.stdout)
    assert m["stable"]
    if float(delay) > 0:  # the P loop's gain margin pi / (2 Kp T), at w = pi / (2 T) (closed form)
        assert math.isclose(m["gain_margin"], math.pi / (4 * float(delay)), rel_tol=1e-9)


def test_roots_text_says_when_the_rightmost_root_is_not_certified(monkeypatch):
    """The rightmost root's certificate is printed with the verdict (a search that stops short gives a bound)."""
    import delaykit.spectrum.stability as S

    real = S.rightmost

    def uncertified(q, **kw):
        r = real(q, **kw)
        return S.Rightmost(root=r.root, abscissa=r.abscissa, neutral_lines=r.neutral_lines, certified=False,
                           spectrum=r.spectrum)

    monkeypatch.setattr(S, "rightmost", uncertified)
    res = run("roots", "--kp", "2", "--delay", "0.3")
    assert res.exit_code == 0, res.output
    assert "stable (NOT certified" in one_line(res.stdout)
    monkeypatch.setattr(S, "rightmost", real)
    assert "NOT certified" not in run("roots", "--kp", "2", "--delay", "0.3").stdout


@pytest.mark.parametrize("args, fragment", [
    (["roots", "--kp", "2", "--delay", "1e300"], "MAX_ROOT_GRID_POINTS"),
    (["roots", "--kp", "2", "--delay", "0.3", "--region", "-10", "2", "0", "1e6"], "give a smaller region"),
    (["margins", "--kp", "2", "--delay", "1e300"], "too many phase crossovers"),
    (["margins", "--kp", "1e300", "--delay", "0.3"], "(1e+300) is too large"),
])
def test_huge_values_in_spectra_are_refused(args, fragment):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # (NumPy's "invalid value encountered in cast" before)
        res = run(*args)
    assert "all-pass" not in refused(res, fragment)


# -- saved models and loop files -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fopdt_model():
    """A first-order-plus-dead-time model identified from an exact, noise-free step (gain 2, lag 10 s, delay 3 s)
    and the log it came from."""
    from delaykit.identify.identification import identify

    t = np.arange(0, 60.0, 0.1)
    e = Experiment.from_arrays(t, {"z": 2 * (1 - np.exp(-np.maximum(t - 8, 0) / 10))},
                               u=np.where(t >= 5, 1.0, 0.0), name="step")
    return identify([e], model="fopdt"), e


def _saved(tmp_path, fopdt_model, change):
    import copy
    import json

    d = copy.deepcopy(fopdt_model[0].to_dict())
    change(d)
    p = tmp_path / "model.json"
    p.write_text(json.dumps(d), encoding="utf-8")
    return p


@pytest.mark.parametrize("change, fragment", [
    (lambda d: d.update(closed_loop={"kind": "zzz", "kp": 1.0, "kv": 0.0, "umin": None, "umax": None,
                                     "period": 0.1}), "kind must be 'p' or 'pv'"),
    (lambda d: d.update(closed_loop={"kind": "p", "kp": -1.0, "kv": 0.0, "umin": None, "umax": None,
                                     "period": 0.1}), "kp (-1) and the plant's gain (2) have opposite signs"),
    (lambda d: d.update(closed_loop={"kind": "pv", "kp": 1.0, "kv": -0.3, "umin": None, "umax": None,
                                     "period": 0.1}), "gains must share one sign"),
    (lambda d: d.update(closed_loop={"kind": "p", "kp": 1.0, "kv": 0.0, "umin": None, "umax": None,
                                     "period": "0.1"}), "period (s) must be a real number, got '0.1'"),
    (lambda d: d["params"].update(time_constant=-1.0), "time_constant must be greater than 0, got -1"),
    (lambda d: d["params"].update(gain=1e300), "badly scaled"),
    (lambda d: d["params"].update(delay=float("nan")), "delay must be finite"),
])
def test_a_saved_model_is_checked_on_load(tmp_path, fopdt_model, change, fragment):
    from delaykit.identify.identification import IdentificationError, load_model

    with pytest.raises(IdentificationError, match="not a usable delaykit model file") as info:
        load_model(_saved(tmp_path, fopdt_model, change))
    assert fragment in str(info.value)


def test_predict_cli_refuses_a_bad_model(tmp_path, fopdt_model):
    p = _saved(tmp_path, fopdt_model, lambda d: d.update(closed_loop={"kind": "zzz", "kp": 1.0}))
    log = tmp_path / "log.csv"
    log.write_text("t,u,z\n" + "".join(f"{0.1 * k:.1f},{float(k >= 5)},{0.01 * k}\n" for k in range(30)))
    refused(run("predict", str(p), str(log)), "got 'zzz'")


@pytest.mark.parametrize("text", ["[" * 100_000 + "]" * 100_000, '{"n": ' + "9" * 5000 + "}",
                                  '{"model": "fopdt", "rms": 1' + "0" * 400 + "}"])
def test_model_files_that_crashed_the_reader(tmp_path, text):
    from delaykit.identify.identification import IdentificationError, load_model

    p = tmp_path / "m.json"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(IdentificationError, match="m.json"):
        load_model(p)


def test_a_delay_longer_than_the_log_predicts_no_response(tmp_path, fopdt_model):
    """A delay of 1e300 s (a numba typing error before): nothing arrives within the log, so the prediction is the
    initial rest and its RMS error that of the data about it (computed here directly)."""
    from delaykit.identify.identification import load_model, predict

    e = fopdt_model[1]
    m = load_model(_saved(tmp_path, fopdt_model, lambda d: d["params"].update(delay=1e300)))
    pred = predict(m, e)
    y = e.outputs["z"]
    assert np.array_equal(pred.predicted["z"], np.full(y.size, e.baseline("z")))
    assert math.isclose(pred.rms["z"], float(np.sqrt(np.mean((y - e.baseline("z")) ** 2))), rel_tol=1e-12)


def test_a_deeply_nested_loop_file(tmp_path):
    p = tmp_path / "deep.toml"
    p.write_text("a = " + "[" * 100_000 + "]" * 100_000 + "\n", encoding="utf-8")
    refused(run("simulate", "--loop", str(p)), "nested too deeply")


# -- logs ----------------------------------------------------------------------------------------------------
def test_u_before_must_be_finite():
    t = np.arange(0.0, 3.0, 0.1)
    with pytest.raises(InvalidValueError, match="u_before .* must be finite, got nan"):
        Experiment.from_arrays(t, {"y": t}, u=np.ones(t.size), u_before=math.nan)


def test_huge_log_values_are_refused():
    t = np.arange(0.0, 3.0, 0.1)
    y = np.where(t > 1.0, 1e300, 0.0)
    with pytest.raises(InvalidValueError, match="holds 1e\\+300 at sample 11, beyond"):
        Experiment.from_arrays(t, {"y": y}, u=(t > 0.5) * 1.0)


def test_an_output_that_never_moves_is_refused():
    """Before: a gain of 0 +- 0 with a zero-width interval."""
    from delaykit.identify.identification import IdentificationError, identify

    t = np.arange(0.0, 30.0, 0.1)
    e = Experiment.from_arrays(t, {"z": np.full(t.size, 0.25)}, u=(t > 5.0) * 1.0)
    with pytest.raises(IdentificationError, match="the output 'z' never moves \\(it is 0.25 throughout"):
        identify([e], model="fopdt")


@pytest.mark.parametrize("step_time", [50.0, 500.0])
def test_a_step_time_outside_the_log_is_refused(step_time):
    t = np.arange(99.0, 120.0, 0.1)
    with pytest.raises(LogError, match=f"step time {step_time:g} s is outside the log, which runs from 99 s"):
        FlightLog.from_arrays(t, np.where(t > 100, 1.0, 0.0), None, step_time=step_time, step=1.0, z0=0.0)
    # one sample before the first is the log's start (a log that begins with the move), still accepted
    assert FlightLog.from_arrays(t, np.where(t > 100, 1.0, 0.0), None, step_time=98.95, step=1.0,
                                 z0=0.0).step_time == 98.95


# -- commands that silently did something else ------------------------------------------------------------------
def test_design_with_a_delay_range_designs_for_every_delay():
    """design --delay 0.2:0.5:3 designed for 0.2 s alone; now each candidate's score is its worst case over the
    three delays, here checked against the library's rightmost root of each loop."""
    import json

    from delaykit.spectrum.stability import rightmost

    res = run("design", "--kp", "2", "--kv", "0,0.3", "--delay", "0.2:0.5:3", "--json")
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    assert got["delays"] == [0.2, 0.35, 0.5]
    for i, kv in enumerate((0.0, 0.3)):
        worst = max(rightmost(AltitudeLoop(kp=2.0, kv=kv, delay=d)).abscissa for d in (0.2, 0.35, 0.5))
        assert got["abscissa"][i][0] == pytest.approx(worst, rel=1e-9, abs=1e-12)
    refused(run("design", "--delay", "0.2:0.5:3", "--delays", "0.1:0.2:2"), "not both")


@pytest.mark.parametrize("args", [["--plant", "1/(s+1)"], ["--plant", "1/(s+1)", "--controller", "pi", "--ki", "1"]])
def test_a_gain_law_without_kp_is_refused(args):
    """--plant without --kp ran the loop open (Kp = 0) and printed 'never' settles."""
    refused(run("simulate", *args, "--delay", "0.3"), "give --kp", "--kp 0 for none")


def test_pure_integral_control_with_kp_0_still_runs():
    res = run("simulate", "--plant", "1/(s+1)", "--controller", "pi", "--kp", "0", "--ki", "0.5", "--delay", "0.3",
              "--json")
    assert res.exit_code == 0, res.output


def test_identify_closed_loop_needs_no_delay(tmp_path):
    """identify --closed-loop --kp ... --period ... asked for --delay and then refused it; the fit finds the delay
    of an exact simulation of the paper's sampled loop (0.368 s) within its interval."""
    import json

    from delaykit.identify.flightlog import synthetic_log, write_log

    log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.368, period=0.065), 1.0, noise=0.002,
                        rng=np.random.default_rng(1))
    p = tmp_path / "cl.csv"
    write_log(p, {"t": log.t, "z": log.z, "z_ref": log.z_ref})
    res = run("identify", str(p), "--closed-loop", "--kp", "1.31", "--period", "0.065", "--model", "ipdt", "--json")
    assert res.exit_code == 0, res.output
    lo, hi = json.loads(res.stdout)["ci"]["delay"]
    assert lo <= 0.368 <= hi and hi - lo < 0.01


@pytest.mark.parametrize("wmin, wmax, fragment", [
    ("1e-300", "1e300", "600 decades, above the limit of 24"),
    ("1e-3", "1e14", "its phase w T = 3e+13 rad exceeds 1e+12 rad"),
])
def test_margins_frequency_range_limits(tmp_path, wmin, wmax, fragment):
    refused(run("margins", "--kp", "2", "--delay", "0.3", "--wmin", wmin, "--wmax", wmax, "--plot",
                str(tmp_path / "b.png")), fragment)


def test_bode_plot_of_a_phase_of_billions_of_turns(tmp_path):
    """Up to w T = 3e11 rad the Bode plot drew one dashed line per -180 + 360 k degrees (5e10 of them: it never
    finished); now it draws the -180 line alone, as it does beyond four levels."""
    from delaykit.plotting.frequency import plot_bode
    from delaykit.spectrum.frequency import frequency_grid, frequency_response

    loop = AltitudeLoop(kp=2.0, delay=0.3)
    fig = plot_bode(frequency_response(loop, frequency_grid(loop, 200, wmin=1e-10, wmax=1e12)))
    dashed = [ln for ln in fig.axes[1].lines if ln.get_linestyle() == "--"]
    assert [tuple(ln.get_ydata()) for ln in dashed] == [(-180.0, -180.0)]


# -- one rule for the gains' signs -------------------------------------------------------------------------------
@pytest.mark.parametrize("kind, gains", [("pi", dict(kp=1.0, ki=-1.0)), ("pid", dict(kp=-1.0, ki=-0.5, kd=0.1)),
                                         ("pv", dict(kp=1.0, kv=-0.3))])
def test_gains_of_mixed_signs_are_refused(kind, gains):
    from delaykit.models.controllers import Controller

    with pytest.raises(InvalidValueError, match="gains must share one sign"):
        Controller(kind, **gains, derivative_filter=0.02 if kind == "pid" else 0.0)


def test_gains_of_one_sign_run_a_reverse_acting_loop():
    """All gains at most 0 on a plant of negative gain: the same loop as all gains at least 0 on the plant of
    positive gain (the signs cancel), so the same response."""
    a = run("simulate", "--plant", "-1/(s+1)", "--controller", "pi", "--kp", "-1", "--ki", "-0.5", "--delay", "0.3",
            "--json")
    b = run("simulate", "--plant", "1/(s+1)", "--controller", "pi", "--kp", "1", "--ki", "0.5", "--delay", "0.3",
            "--json")
    import json

    assert a.exit_code == 0 and b.exit_code == 0, a.output + b.output
    ra, rb = json.loads(a.stdout), json.loads(b.stdout)
    assert rb["settling_time"] is not None
    for k in ("overshoot", "peak_time", "rise_time", "settling_time"):
        assert ra[k] == rb[k] or ra[k] == pytest.approx(rb[k], rel=1e-9)
    refused(run("simulate", "--plant", "1/(s+1)", "--controller", "pi", "--kp", "1", "--ki", "-1", "--delay", "0.3"),
            "share one sign", "kp=1, ki=-1")
    assert "share one sign" in one_line(run("simulate", "--help").output)


def test_ar_noise_fit_of_a_long_series_matches_statsmodels():
    """fit_ar now forms only the autocovariances it uses (np.correlate's full mode was quadratic in the length:
    hours for a 2-million-row log).  Reference: statsmodels' Yule-Walker (biased, 'mle') at the order chosen, on an
    AR(2) series of 200,000 samples."""
    from statsmodels.regression.linear_model import yule_walker

    from delaykit.identify.noise import fit_ar

    rng = np.random.default_rng(3)
    e = rng.standard_normal(200_000)
    x = np.zeros(e.size)
    for k in range(2, e.size):
        x[k] = 1.2 * x[k - 1] - 0.5 * x[k - 2] + e[k]
    ar = fit_ar(x)
    import warnings

    with warnings.catch_warnings():  # (statsmodels announces a new return type)
        warnings.simplefilter("ignore", FutureWarning)
        rho, sigma = yule_walker(x, order=ar.order, method="mle")
    assert ar.order >= 2
    assert np.allclose(ar.coeffs, np.concatenate([[1.0], -rho]), rtol=0, atol=1e-10)
    assert ar.sigma2 == pytest.approx(sigma**2, rel=1e-10)


@pytest.mark.parametrize("kp, fragment", [("1" + "0" * 400, "kp (proportional gain) must be finite, got an integer of about 401 digits"),
                                          ("1" + "0" * 5000, "cannot be read: Exceeds the limit")])
def test_a_loop_file_with_a_huge_integer(tmp_path, kp, fragment):
    p = tmp_path / "big.toml"
    p.write_text(f'plant = "1/s"\nkp = {kp}\ndelay = 0.3\n', encoding="utf-8")
    refused(run("simulate", "--loop", str(p)), fragment)


def test_check_real_of_an_integer_beyond_the_floats():
    from delaykit.errors import check_real

    with pytest.raises(InvalidValueError, match="x must be finite, got an integer of about 5001 digits"):
        check_real("x", 10**5000)


def test_a_string_period_in_a_loop_file(tmp_path):
    p = tmp_path / "sp.toml"
    p.write_text('plant = "1/s"\nkp = 1.31\ndelay = 0.3\nperiod = "0.065"\n', encoding="utf-8")
    refused(run("roots", "--loop", str(p)), "period (s) must be a real number, got '0.065'")


@pytest.mark.parametrize("args, fragment", [(["--vmax", "1_0"], "--vmax must be a number or 'none', got '1_0'"),
                                            (["--period", "０.065"], "--period must be a number"),
                                            (["--period", "0.065", "--delay-schedule", "1_0:0.3"],
                                             "--delay-schedule item 1 '1_0:0.3' is not T:DELAY")])
def test_option_numbers_are_ascii_decimal(args, fragment):
    refused(run("simulate", "--kp", "1", "--delay", "0.3", *args), fragment)


def test_estimate_step_time_before_the_log(tmp_path):
    """A log that starts at 99 s and --step-time 50: an answer before, now a refusal naming both."""
    from delaykit.identify.flightlog import synthetic_log, write_log

    log = synthetic_log(AltitudeLoop(kp=1.31, delay=0.368), 1.0, t0=100.0, rng=np.random.default_rng(0))
    p = tmp_path / "late.csv"
    write_log(p, {"t": log.t, "z": log.z, "z_ref": log.z_ref})
    refused(run("estimate", str(p), "--kp", "1.31", "--step-time", "50"),
            f"step time 50 s is outside the log, which runs from {log.t[0]:g} s")
