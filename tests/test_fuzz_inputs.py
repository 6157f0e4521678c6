"""Issue 34's input checks and tracebacks: hostile or careless input is answered correctly or refused by name.

Each case of the issue (and those found by trying the same kinds elsewhere) is one test: the Python API raises a
delaykit error (``InvalidValueError``/``InvalidTypeError`` or a subclass) instead of reshaping the input, reading it
as something else, or letting a raw Python exception out; the command line exits 2 with one line ``error: ...`` and
no traceback.  Network failures are simulated by a socket whose ``sendto`` raises ``ENETUNREACH`` (no packet leaves
the machine: the only address used is 127.0.0.1).
"""

from __future__ import annotations

import errno
import json
import math
import os
import socket
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import delaykit
from delaykit import (DelayTrace, IdentificationError, InvalidTypeError, InvalidValueError, LinkError, OutputError,
                      load_loop, load_model, load_system, read_experiment, ss, summing_junction, tf, tune)
from delaykit.cli import app
from delaykit.errors import check_path, writing
from delaykit.systems import c2d
from delaykit.systems import to_control as system_to_control

runner = CliRunner()
HAS_DEV_FULL = os.path.exists("/dev/full")


def _refused(res, *words: str, progress: bool = False) -> str:
    """The CLI's promise for a bad input: exit 2, one line ``error: ...`` on stderr, no traceback (after the lines
    of progress a flight prints on stderr, with ``progress``)."""
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    lines = res.stderr.splitlines()
    if progress:
        assert lines and not any(x.startswith("error") for x in lines[:-1]), res.stderr
        lines = lines[-1:]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    """An open-loop log (the plant 0.8/s with a 0.3 s dead time after a unit step at 1 s) and its model file."""
    tmp = tmp_path_factory.mktemp("inputs")
    t = np.arange(0.0, 6.0, 0.05)
    u = (t >= 1.0).astype(float)
    z = np.where(t >= 1.3, 0.8 * (t - 1.3), 0.0)
    log = tmp / "log.csv"
    log.write_text("t,u,z\n" + "".join(f"{a:.3f},{b:.1f},{c:.6f}\n" for a, b, c in zip(t, u, z)))
    model = delaykit.identify(read_experiment(log, input="u"), model="ipdt")
    model.save(tmp / "model.json")
    return tmp


# ------------------------------------------------------------------------------------ ss: no reshaping
def test_ss_refuses_a_b_with_more_rows_than_states():
    with pytest.raises(InvalidValueError, match=r"B must have 1 row .*got shape \(2, 1\)"):
        ss([[-1.0]], [[1.0], [2.0]], [[1.0]], [[0.0]])  # (it was read as two inputs)
    with pytest.raises(InvalidValueError, match=r"B must have 2 rows .*got shape \(4, 1\)"):
        ss([[-1.0, 0.0], [0.0, -2.0]], [[1.0], [2.0], [3.0], [4.0]], [[1.0, 0.0]], [[0.0]])  # (a scrambled 2x2)
    with pytest.raises(InvalidValueError, match=r"C must have 2 columns"):
        ss([[-1.0, 0.0], [0.0, -2.0]], [[1.0], [1.0]], [[1.0, 0.0, 0.0]], [[0.0]])
    with pytest.raises(InvalidValueError, match=r"D must have shape \(1, 1\)"):
        ss([[-1.0]], [[1.0]], [[1.0]], [[0.0, 1.0]])


def test_ss_reads_vectors_and_zero_d_as_python_control_does():
    control = pytest.importorskip("control")
    A = [[-1.0, 0.0], [0.0, -2.0]]
    for B, C, D in (([1.0, 2.0], [[1.0, 0.0]], 0.0), ([[1.0], [2.0]], [1.0, 0.0], [[0.0]]),
                    ([[1.0, 0.0], [0.0, 1.0]], [[1.0, 1.0]], 0.0)):
        ours, theirs = ss(A, B, C, D), control.ss(A, B, C, D)  # the reference: python-control's reading
        assert ours.B1.shape == theirs.B.shape and ours.C1.shape == theirs.C.shape
        assert np.array_equal(ours.B1, theirs.B) and np.array_equal(ours.D11, theirs.D)


def test_ss_of_one_state_from_vectors_as_python_control():
    control = pytest.importorskip("control")
    ours, theirs = ss([-1.0], [2.0], [3.0], 0.5), control.ss([-1.0], [2.0], [3.0], 0.5)  # the reference
    for a, b in ((ours.A, theirs.A), (ours.B1, theirs.B), (ours.C1, theirs.C), (ours.D11, theirs.D)):
        assert a.shape == b.shape and np.array_equal(a, b)
    with pytest.raises(InvalidValueError, match="A must be a square matrix"):
        ss([-1.0, 2.0], [1.0], [1.0], 0.0)


@pytest.mark.parametrize("bad", [np.array([[-1.0 + 1j]]), [[complex(-1, 1)]], [[np.complex128(-1 + 0j)]]])
def test_ss_refuses_complex_matrices_without_a_warning(bad):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's ComplexWarning was the only sign before
        with pytest.raises(InvalidTypeError, match="A must be a real matrix"):
            ss(bad, [[1.0]], [[1.0]], [[0.0]])


@pytest.mark.parametrize("which", range(3))
def test_ss_refuses_none_for_a_b_or_c(which):
    args = [[[-1.0]], [[1.0]], [[1.0]]]
    args[which] = None  # (numpy read None as nan, and the error blamed a nan)
    with pytest.raises(InvalidTypeError, match=f"{'ABC'[which]} must be a real matrix, got None"):
        ss(*args, [[0.0]])


def test_ss_without_states_needs_a_d():
    with pytest.raises(InvalidValueError, match="needs D"):
        ss([], [], [], [])
    assert ss([], [], [], [[2.0]]).D11.tolist() == [[2.0]]


# ------------------------------------------------------------------------------ summing_junction signs
@pytest.mark.parametrize("term", ["--r", "+-y", "-+y", "++y", "-", "+", " - "])
def test_summing_junction_takes_one_sign_at_most(term):
    with pytest.raises(InvalidValueError, match="one sign at most"):
        summing_junction(["a", term], "e")


def test_summing_junction_signs_that_are_accepted():
    sj = summing_junction(["+r", "- y", "w"], "e")
    assert sj.inputs == ("r", "y", "w") and sj.D11.tolist() == [[1.0, -1.0, 1.0]]


# ---------------------------------------------------------------------------------------- evaluate
@pytest.mark.parametrize("s", [math.nan, complex(1.0, math.nan), math.inf, [0.5, -math.inf]])
def test_evaluate_refuses_points_that_are_not_finite(s):
    G = tf("exp(-2*s)/(s+1)")
    with pytest.raises(InvalidValueError, match="finite points"):
        G.evaluate(s)  # (nan gave inf, as if at a pole)


@pytest.mark.parametrize("s", [None, "1", [True], object()])
def test_evaluate_refuses_what_is_not_a_number(s):
    with pytest.raises(InvalidTypeError, match="complex numbers"):
        tf("1/(s+1)").evaluate(s)


def test_evaluate_still_answers_at_finite_points():
    G = tf("exp(-2*s)/(s+1)")
    got = G.evaluate([1.0, 2j])[0, 0]
    expected = [math.exp(-2.0) / 2.0, np.exp(-4j) / (1 + 2j)]  # the closed form exp(-2 s)/(s + 1)
    assert np.allclose(got, expected, rtol=1e-14, atol=0.0)


# -------------------------------------------------------------------------------- files: type and overflow
@pytest.mark.parametrize("reader", [load_loop, load_system, load_model, read_experiment, DelayTrace.from_csv])
@pytest.mark.parametrize("path", [None, 3, 2.5, b"/tmp/x.toml", ["a"]])
def test_readers_refuse_paths_that_are_not_text(reader, path):
    with pytest.raises(InvalidTypeError, match="must be a path"):
        reader(path)


def test_check_path_refuses_empty_text_and_nul():
    with pytest.raises(InvalidValueError, match="empty"):
        check_path("loop file", "")
    with pytest.raises(InvalidValueError, match="NUL"):
        check_path("loop file", "a\0b")
    assert check_path("loop file", Path("x.toml")) == Path("x.toml")


_BLOCK = 'inputs = "u"\noutputs = "y"\n[[blocks]]\n{}\ninputs = "u"\noutputs = "y"\n'


@pytest.mark.parametrize("line, what", [("delay = " + "9" * 400, "delay"), ("tf = " + "9" * 400, "tf"),
                                        ("saturation = [-1, " + "9" * 400 + "]", "saturation limit"),
                                        ("ss = {A = [[-1]], B = [[" + "9" * 400 + "]], C = [[1]]}", "ss.B")])
def test_system_files_refuse_integers_beyond_the_floats(tmp_path, line, what):
    path = tmp_path / "s.toml"
    path.write_text(_BLOCK.format(line))
    with pytest.raises(InvalidValueError, match=f"{what}.*integer of 400 digits"):
        load_system(path)  # (a raw OverflowError before)


def test_system_files_with_entries_near_the_largest_float(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(_BLOCK.format("ss = {A = [[-1e308]], B = [[1e308]], C = [[1e308]], D = [[1e308]]}"))
    sys_ = load_system(path)  # each entry is a float: accepted as written
    assert sys_.A.tolist() == [[-1e308]] and sys_.D11.tolist() == [[1e308]]


@pytest.mark.parametrize("key, value", [("rms", True), ("n", True), ("n", 2.5), ("aic", "1.0")])
def test_model_files_refuse_true_and_text_for_numbers(scratch, tmp_path, key, value):
    d = json.loads((scratch / "model.json").read_text())
    d[key] = value  # (true was read as 1.0)
    (tmp_path / "m.json").write_text(json.dumps(d))
    with pytest.raises(IdentificationError, match=key):
        load_model(tmp_path / "m.json")


@pytest.mark.parametrize("value", [True, "0.8"])
def test_model_files_refuse_true_and_text_for_parameters(scratch, tmp_path, value):
    d = json.loads((scratch / "model.json").read_text())
    d["params"]["gain"] = value
    (tmp_path / "m.json").write_text(json.dumps(d))
    with pytest.raises(IdentificationError, match="parameter gain must be a real number"):
        load_model(tmp_path / "m.json")
    assert isinstance(IdentificationError("x"), InvalidValueError)


# ------------------------------------------------------------------------------- tune, c2d, to_control
@pytest.mark.parametrize("key", ["delays", "gains"])
def test_tune_refuses_an_empty_robust_range(key):
    with pytest.raises(InvalidValueError, match=f"{key} is empty"):
        tune("1/(s+1)", delay=0.3, **{key: []})  # (an IndexError before)


def test_tune_refuses_a_tau_c_whose_gains_underflow():
    # SIMC on k/s with delay theta: kp = 1/(k (tau_c + theta)), ki = kp / (4 (tau_c + theta)) = 2.5e-601 -> 0.0
    with pytest.raises(InvalidValueError, match=r"tau_c = 1e\+300 s makes ki = 0"):
        tune("1/s", delay=0.3, rule="simc", tau_c=1e300)
    t = tune("1/(s+1)", delay=0.3, rule="simc", tau_c=1e300)  # kp = 1/(1e300 + 0.3), ki = kp / 1: representable
    assert t.kp == pytest.approx(1e-300, rel=1e-12) and t.ki == pytest.approx(1e-300, rel=1e-12)


@pytest.mark.parametrize("T, h", [(1e100, 0.1), (1e300, 0.1), (0.3, 1e-300), (1000.0, 0.001)])
def test_c2d_refuses_more_states_than_it_can_hold(T, h):
    G = tf("1/(s+1)") * delaykit.delay(T)
    with pytest.raises(InvalidValueError, match="states"):
        c2d(G, h)  # (numpy's 'Maximum allowed dimension exceeded', or memory)
    with pytest.raises(InvalidValueError, match="states"):
        c2d(G, h, thiran_order=3)


@pytest.mark.parametrize("order", [10**6, 41, 0, -1, math.nan, math.inf, 2.5, True, "3"])
def test_to_control_refuses_pade_orders_out_of_range(order):
    pytest.importorskip("control")
    with pytest.raises(InvalidValueError, match="pade_order must be an integer from 1 to 40"):
        system_to_control(tf("exp(-0.3*s)/(s+1)"), pade_order=order)
    with pytest.raises(InvalidValueError, match="pade_order must be an integer from 1 to 40"):
        delaykit.to_control(delaykit.AltitudeLoop(kp=1.31, delay=0.368), pade_order=order)


def test_to_control_still_converts_a_valid_order():
    pytest.importorskip("control")
    G = system_to_control(tf("exp(-0.3*s)/(s+1)"), pade_order=3)
    assert G.nstates == 4 and float(np.real(G.dcgain())) == pytest.approx(1.0, rel=1e-12)  # Pade: unit gain at 0


# ------------------------------------------------------------------------- the kernel's root bound
def test_the_stability_count_prints_nothing_where_the_bound_would_underflow(monkeypatch):
    from delaykit import QuasiPolynomial
    from delaykit.spectrum.stability import right_half_plane_count

    lost = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: lost.append(u.exc_type))  # 'Exception ignored' goes here
    q = QuasiPolynomial([[1.0, 0.0, 0.0], [1e-300, 0.0]], [0.0, 0.3])  # s^2 + 1e-300 s exp(-0.3 s): a root at 0
    assert right_half_plane_count(q) is None  # not counted this way: the caller searches
    # s + 1e-300 exp(-0.3 s): its roots are W_k(0.3e-300)/0.3 (Lambert W), the rightmost near -1e-300: none in the
    # closed right half-plane, counted as before
    assert right_half_plane_count(QuasiPolynomial([[1.0, 0.0], [1e-300]], [0.0, 0.3])) == 0
    assert lost == []


# ---------------------------------------------------------------------------------------- the network
class _Unreachable(socket.socket):
    def sendto(self, *args, **kwargs):
        raise OSError(errno.ENETUNREACH, "Network is unreachable")


def test_a_network_failure_is_a_link_error(monkeypatch, tmp_path):
    from delaykit.hardware.flight import DroneLink, FlightPlan, fly

    monkeypatch.setattr(socket, "socket", _Unreachable)
    link = DroneLink("127.0.0.1", 5556, 5554)
    try:
        with pytest.raises(LinkError, match="Network is unreachable"):
            link.wake()
        with pytest.raises(LinkError, match="Network is unreachable"):
            link.send(b"AT*COMWDG=1\r")
    finally:
        link.close()
    with pytest.raises(LinkError, match="cannot wake navdata from 127.0.0.1:5554: Network is unreachable"):
        fly(FlightPlan(kp=1.31), tmp_path / "f.csv", host="127.0.0.1")


@pytest.mark.parametrize("host", ["a" * 300, "x" * 64 + ".example", "bad name", "-leading.example", "a..b", "",
                                  "1.2.3", "256.1.1.1", "127.0.0.1:5556"])
def test_a_host_that_cannot_be_a_name_is_refused_before_any_lookup(monkeypatch, host):
    from delaykit.hardware.flight import DroneLink

    def lookup(name):
        raise AssertionError(f"looked up {name!r}")

    monkeypatch.setattr(socket, "gethostbyname", lookup)
    with pytest.raises(InvalidValueError, match="is not an IPv4 address"):
        DroneLink(host, 5556, 5554)  # (300 characters: a UnicodeError from the resolver; 256.1.1.1 was looked up)


def test_a_name_that_does_not_resolve_is_a_value_error(monkeypatch):
    from delaykit.hardware.flight import DroneLink

    def lookup(name):
        raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")

    monkeypatch.setattr(socket, "gethostbyname", lookup)
    with pytest.raises(InvalidValueError, match="cannot be resolved"):
        DroneLink("no-such-drone.invalid", 5556, 5554)


@pytest.mark.parametrize("command", [["fly", "--kp", "1.31"], ["autotune", "--relay", "0.3"]])
def test_cli_network_unreachable_is_one_line(monkeypatch, tmp_path, command):
    monkeypatch.setattr(socket, "socket", _Unreachable)
    res = runner.invoke(app, [*command, "--host", "127.0.0.1", "--log", str(tmp_path / "f.csv")])
    _refused(res, "Network is unreachable", progress=True)


def test_cli_a_300_character_host_is_one_line(tmp_path):
    res = runner.invoke(app, ["fly", "--kp", "1.31", "--host", "a" * 300, "--log", str(tmp_path / "f.csv")])
    _refused(res, "300 characters")


# ---------------------------------------------------------------------------------------- output paths
def test_writing_turns_an_os_error_into_an_output_error(tmp_path):
    with pytest.raises(OutputError, match="--csv .* could not be written: No such file or directory") as info:
        with writing("--csv", tmp_path / "gone" / "r.csv"):
            open(tmp_path / "gone" / "r.csv", "w")
    assert isinstance(info.value, InvalidValueError) and isinstance(info.value, OSError)


@pytest.mark.skipif(not HAS_DEV_FULL, reason="no /dev/full on this system")
def test_library_writes_to_a_full_device_raise_output_errors(scratch):
    from matplotlib.figure import Figure

    from delaykit.identify import write_log
    from delaykit.plotting.figures import save_figure

    with pytest.raises(OutputError, match="No space left"):
        save_figure(Figure(), "/dev/full")  # (matplotlib let this pass silently)
    with pytest.raises(OutputError, match="No space left"):
        load_model(scratch / "model.json").save("/dev/full")
    with pytest.raises(OutputError, match="No space left"):
        write_log("/dev/full", {"t": [0.0, 1.0], "z": [0.0, 1.0]})


@pytest.mark.skipif(not HAS_DEV_FULL, reason="no /dev/full on this system")
@pytest.mark.parametrize("args, flag", [
    (["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "2", "--csv"], "--csv"),
    (["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "2", "--plot"], "figure"),
    (["tune", "--plant", "1/(s+1)", "--delay", "0.3", "--rule", "simc", "--save"], "--save"),
    (["identify", "LOG", "--model", "ipdt", "--input", "u", "--save"], "model file"),
])
def test_cli_a_write_that_fails_after_the_work_is_one_line(scratch, args, flag):
    args = [str(scratch / "log.csv") if a == "LOG" else a for a in args]
    _refused(runner.invoke(app, [*args, "/dev/full"]), flag, "No space left on device")


def test_cli_a_dangling_link_into_a_missing_folder_is_refused_before_the_work(tmp_path):
    link = tmp_path / "out.csv"
    link.symlink_to(tmp_path / "missing" / "out.csv")  # (passed the check, and failed after the work)
    res = runner.invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "2", "--csv", str(link)])
    _refused(res, "--csv", "is a link to", "whose folder does not exist")


def test_cli_a_loop_of_links_is_refused(tmp_path):
    (tmp_path / "a").symlink_to(tmp_path / "b")
    (tmp_path / "b").symlink_to(tmp_path / "a")
    res = runner.invoke(app, ["tune", "--plant", "1/(s+1)", "--delay", "0.3", "--save", str(tmp_path / "a")])
    _refused(res, "--save", "loop of links")


def test_cli_a_link_to_a_new_file_in_a_folder_that_exists_is_written(tmp_path):
    link = tmp_path / "out.csv"
    link.symlink_to(tmp_path / "target.csv")
    res = runner.invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "1", "--csv", str(link)])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "target.csv").read_text().startswith("t,z,z_ref,u")


def test_cli_a_dangling_link_for_an_output_folder_is_refused(tmp_path):
    (tmp_path / "out").symlink_to(tmp_path / "nowhere")
    _refused(runner.invoke(app, ["report", "--out", str(tmp_path / "out")]), "--out", "which does not exist")


def test_cli_tune_a_tau_c_whose_gains_underflow_is_one_line():
    res = runner.invoke(app, ["tune", "--plant", "1/s", "--delay", "0.3", "--rule", "simc", "--tau-c", "1e300"])
    _refused(res, "tau_c")


# ------------------------------------------------------------- found by trying: integers beyond the floats
_BIG = 10**400


@pytest.mark.parametrize("call", [
    lambda: delaykit.saturation(-1.0, _BIG),
    lambda: delaykit.TransferFunction([_BIG], [1.0, 1.0]),
    lambda: tune(_BIG, delay=0.3, rule="simc"),
    lambda: delaykit.DelaySchedule((0.0, 0.3), (1.0, _BIG)),
    lambda: delaykit.Samples([0.0, _BIG], [0.0, 1.0]),
    lambda: delaykit.sampled_frequency_response(delaykit.AltitudeLoop(kp=1.31, delay=0.368, period=0.065), [_BIG]),
    lambda: delaykit.frequency_grid(delaykit.AltitudeLoop(kp=1.31, delay=0.368), _BIG),
    lambda: delaykit.step_metrics([0.0, 1.0, _BIG], [0.0, 1.0, 1.0], step=1.0),
    lambda: delaykit.simulate_many(delaykit.AltitudeLoop(kp=1.31, delay=0.368), t_end=2.0, kp=[1.0, _BIG]),
], ids=["saturation", "TransferFunction", "tune", "DelaySchedule", "Samples", "sampled_frequency_response",
        "frequency_grid", "step_metrics", "simulate_many"])
def test_integers_beyond_the_floats_are_refused_by_name(call):
    with pytest.raises(InvalidValueError):  # (a raw OverflowError: int too large to convert to float)
        call()


@pytest.mark.parametrize("call", [
    lambda: delaykit.QuasiPolynomial(None, [0.0]),
    lambda: delaykit.QuasiPolynomial([[1.0]], 0.5),
    lambda: delaykit.interconnect([tf("1/(s+1)", inputs="u", outputs="y")], None, ["y"]),
    lambda: delaykit.interconnect([tf("1/(s+1)", inputs="u", outputs="y")], ["u"], 3),
    lambda: delaykit.measure_cycle([0.0, 1.0j], [0.0, 1.0], [1.0, -1.0]),
    lambda: delaykit.measure_cycle(["a", "b"], [0.0, 1.0], [1.0, -1.0]),
], ids=["qp-polys", "qp-delays", "interconnect-inputs", "interconnect-outputs", "cycle-complex", "cycle-text"])
def test_arguments_that_are_not_lists_of_numbers_are_type_errors(call):
    with pytest.raises(InvalidTypeError):  # (a raw TypeError or ValueError)
        call()


@pytest.mark.parametrize("sign", [np.array([1.0, -1.0]), "1", None])
def test_feedback_sign_that_is_not_a_number(sign):
    with pytest.raises(InvalidValueError, match="sign must be -1"):
        delaykit.feedback(tf("1/(s+1)"), 1, sign=sign)
    with pytest.raises(InvalidValueError, match="sign must be -1"):
        delaykit.TransferFunction([1.0], [1.0, 1.0]).feedback(1.0, sign=sign)


@pytest.mark.parametrize("kw", [{"ratio_max": None}, {"ratio_max": math.inf}, {"ratio_max": 1e308},
                                {"ratio_max": 0.5}, {"tol": 1e-320}, {"tol": 0.0}, {"tol": "x"}])
def test_delay_ratio_range_bounds_its_scan(kw):
    comp = delaykit.Compensator.smith("1/s", 0.37, closed_loop_time=0.5)
    with pytest.raises((InvalidValueError, InvalidTypeError)):  # (TypeError, or a scan or bisection without end)
        delaykit.delay_ratio_range(comp, "1/s", **kw)


# ------------------------------------------------------------- found by trying: huge and tiny delays, steps
def _quiet(call):
    """``call()`` with warnings as errors (numpy's overflow warnings were printed on the way to the answer)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return call()


def test_margins_and_roots_of_a_delay_near_the_largest_float_refuse_without_a_traceback():
    loop = delaykit.AltitudeLoop(kp=1.31, delay=1e308)
    with pytest.raises(InvalidValueError, match="phase crossovers"):
        _quiet(lambda: delaykit.margins(loop))  # (OverflowError: cannot convert float infinity to integer)
    from delaykit.spectrum.roots import find_roots

    with pytest.raises(InvalidValueError, match="grid points"):
        _quiet(lambda: find_roots(loop.characteristic(), (-5.0, 1.0, 0.0, 30.0)))  # (ZeroDivisionError)


def test_frequency_response_far_beyond_the_crossovers_is_quiet():
    fr = _quiet(lambda: delaykit.frequency_response(delaykit.AltitudeLoop(kp=1.31, delay=0.368), [1e308]))
    assert fr.phase_deg[0] == -math.inf  # -w T in degrees: -2.1e309, beyond the floats
    assert fr.magnitude_db[0] == pytest.approx(20 * math.log10(1.31 / 1e308), rel=1e-12)  # |1.31 / (j w)|


def test_a_delay_below_the_floats_range_is_refused_by_margins():
    with pytest.raises(InvalidValueError, match="too small"):
        _quiet(lambda: delaykit.stable_for(delaykit.AltitudeLoop(kp=1.31, delay=0.368), 1e-320, 0.2))


def test_tune_names_a_delay_whose_gains_overflow():
    with pytest.raises(InvalidValueError, match="beyond the floats"):
        _quiet(lambda: tune("1/(s+1)", delay=1e-320, rule="simc"))


def test_pade_error_tells_a_pole_from_an_overflow():
    pytest.importorskip("control")
    loop = delaykit.AltitudeLoop(kp=1.31, delay=0.368)  # L = 1.31 exp(-0.368 s) / s: a pole at 0
    with pytest.raises(InvalidValueError, match="a pole on the imaginary axis"):
        _quiet(lambda: delaykit.pade_error(loop, 3, [0.0]))
    with pytest.raises(InvalidValueError, match="overflow the floats"):
        _quiet(lambda: delaykit.pade_error(loop, 3, [1e308]))


def test_a_horizon_of_1e308_seconds_is_refused_quietly():
    G = delaykit.feedback(tf("exp(-0.3*s)/(s+1)"), 1)
    with pytest.raises(InvalidValueError, match="pieces"):
        _quiet(lambda: delaykit.step_response_many([G, G], 1e308))


def test_a_step_too_small_to_measure_against_is_refused():
    t = np.linspace(0.0, 5.0, 51)
    with pytest.raises(InvalidValueError, match="too small"):
        _quiet(lambda: delaykit.step_metrics(t, 1 - np.exp(-t), step=1e-320))


def test_relay_cycle_of_a_delay_near_the_largest_float_is_refused():
    with pytest.raises(InvalidValueError, match="shorter delay"):
        _quiet(lambda: delaykit.relay_cycle("1/(s+1)", 1e308))


@pytest.mark.parametrize("args", [["roots", "--kp", "1.31", "--delay", "0.368", "--region", "-5", "1", "0", "30",
                                   "--output-delay", "1e308"],
                                  ["margins", "--kp", "1.31", "--delay", "0.368", "--output-delay", "1e308"]])
def test_cli_a_delay_near_the_largest_float_is_one_line(args):
    _refused(runner.invoke(app, args))


# ------------------------------------------------------------- found by trying: entries near the largest float
_HUGE_SYSTEM = ('inputs = "u"\noutputs = "y"\n[[blocks]]\nss = {A = [[-1e308, 1e308], [1e308, -1e308]], '
                'B = [[1e308], [1e308]], C = [[1e308, 1e308]]}\ninputs = "u"\noutputs = "y"\n[[blocks]]\n'
                'delay = 1e308\ninputs = "y"\noutputs = "z"\n')


@pytest.mark.parametrize("args", [["simulate", "--t-end", "2"], ["roots", "--region", "-5", "1", "0", "30"],
                                  ["margins"]])
def test_cli_a_system_file_with_entries_near_the_largest_float_is_one_line_without_warnings(tmp_path, args):
    path = tmp_path / "huge.toml"
    path.write_text(_HUGE_SYSTEM)
    res = runner.invoke(app, [args[0], "--system", str(path), *args[1:]])
    _refused(res)  # (numpy's overflow warnings were printed before the error, or after)
    assert "Warning" not in res.stderr


def test_the_characteristic_function_names_an_overflow():
    G = ss([[-1e308, 1e308], [1e308, -1e308]], [[1.0], [1.0]], [[1.0, 1.0]], [[0.0]])
    with pytest.raises(InvalidValueError, match="characteristic function overflows"):
        _quiet(lambda: G.characteristic())


@pytest.mark.parametrize("seed", [True, 2.5, "3"])
def test_the_emulator_refuses_a_seed_that_is_not_an_integer(seed):
    from delaykit.hardware.emulator import EmulatorConfig

    with pytest.raises(InvalidTypeError, match="seed must be an integer"):
        EmulatorConfig(seed=seed)  # (True was used as the seed 1)
    assert EmulatorConfig(seed=np.int64(3)).seed == 3


# ------------------------------------------------------------- found by trying: inputs that overflow a response
def test_a_ramp_beyond_the_floats_by_t_end_is_refused():
    loop = delaykit.AltitudeLoop(kp=1.31, delay=0.368)
    with pytest.raises(InvalidValueError, match="reference reaches inf"):
        _quiet(lambda: delaykit.simulate(loop, t_end=2.0, reference=delaykit.Ramp(slope=1e308, size=0.0)))
    r = _quiet(lambda: delaykit.simulate(loop, t_end=2.0, reference=delaykit.Ramp(slope=1e300, size=0.0)))
    assert r.metrics is None or r is not None  # 2e300 at t_end: within the floats, answered


def test_a_load_that_overflows_the_response_is_answered_quietly():
    # as a diverging loop is (tests/test_cli_output.py): the response overflows, and the metrics say so
    loop = delaykit.AltitudeLoop(kp=1.31, delay=0.368)
    r = _quiet(lambda: delaykit.simulate(loop, t_end=2.0, disturbance=delaykit.LoadStep(1e308, 0.0)))
    assert r.t_end == 2.0  # (numpy's overflow warnings were printed on the way)


def test_a_huge_step_is_answered_through_the_speed_limit():
    # the altitude loop climbs at vmax = 1 m/s at most: after a step of 1e308 m the output is t - 0 at t = 2 s,
    # no overflow (the closed form of a saturated climb from rest)
    r = _quiet(lambda: delaykit.simulate(delaykit.AltitudeLoop(kp=1.31, delay=0.368), step=1e308, t_end=2.0))
    z = r.sample(dt=0.5)["z"]
    assert np.all(np.isfinite(z)) and z[-1] <= 2.0 + 1e-9


def test_cli_a_ramp_beyond_the_floats_is_one_line_without_warnings():
    res = runner.invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "2", "--ramp", "1e308"])
    _refused(res, "floats")
    assert "Warning" not in res.stderr


def test_cli_a_load_that_overflows_is_answered_without_warnings():
    res = runner.invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "2", "--disturbance", "1e308",
                              "--json"])
    assert res.exit_code == 0, res.output
    assert "Warning" not in res.stderr
    json.loads(res.stdout, parse_constant=lambda name: pytest.fail(f"{name} is not strict JSON"))


def test_margins_with_a_gain_at_infinity_below_the_floats_is_quiet():
    m = _quiet(lambda: delaykit.margins(delaykit.AltitudeLoop(kp=1.31, delay=0.368, kv=1e-320)))
    assert m is not None


# ------------------------------------------------------------- found by trying: library writers' paths
def test_library_writers_refuse_paths_that_are_not_text(scratch, tmp_path):
    from matplotlib.figure import Figure

    from delaykit.hardware.flight import FlightPlan, fly
    from delaykit.identify import write_log
    from delaykit.paper.report import write_report
    from delaykit.plotting.figures import save_figure

    model = load_model(scratch / "model.json")
    for call in (lambda: model.save(None), lambda: save_figure(Figure(), 3),
                 lambda: write_log(b"x.csv", {"t": [0.0], "z": [1.0]}), lambda: write_report(None),
                 lambda: fly(FlightPlan(kp=1.31), None, host="127.0.0.1")):
        with pytest.raises(InvalidTypeError, match="must be a path"):
            call()  # (TypeError: expected str, bytes or os.PathLike object)


def test_save_figure_refuses_a_suffix_that_is_no_figure_format(tmp_path):
    from matplotlib.figure import Figure

    from delaykit.plotting.figures import save_figure

    with pytest.raises(InvalidValueError, match="'.json' is not a figure format"):
        save_figure(Figure(), tmp_path / "x.json")  # (matplotlib's ValueError)
    assert not (tmp_path / "x.json").exists()


def test_writes_into_a_folder_or_a_missing_one_are_output_errors(scratch, tmp_path):
    model = load_model(scratch / "model.json")
    with pytest.raises(OutputError, match="Is a directory"):
        model.save(tmp_path)
    with pytest.raises(OutputError, match="No such file or directory"):
        model.save(tmp_path / "missing" / "m.json")


@pytest.mark.parametrize("args", [
    ["identify", "LOG", "--model", "ipdt", "--input", "u", "--resample", "1e-320"],
    ["estimate", "--kp", "1.31", "--method", "overshoot", "--overshoot", "20", "--peak-time", "1.2", "--kp", "1e308"],
])
def test_cli_counts_beyond_the_floats_are_refused_without_warnings(scratch, args):
    res = runner.invoke(app, [str(scratch / "log.csv") if a == "LOG" else a for a in args])
    _refused(res)  # (numpy's 'overflow encountered in scalar divide' printed before the refusal)
    assert "Warning" not in res.stderr


# ------------------------------------------------------------- found by trying: identification's arguments
@pytest.mark.parametrize("outputs", [None, True, 3, [], [1], object()])
def test_read_experiment_and_identify_name_outputs_that_are_not_names(scratch, outputs):
    with pytest.raises(InvalidTypeError, match="outputs must be"):
        read_experiment(scratch / "log.csv", input="u", outputs=outputs)  # (TypeError: Value after * ...)
    if outputs is not None:
        e = read_experiment(scratch / "log.csv", input="u")
        with pytest.raises(InvalidTypeError, match="outputs must be"):
            delaykit.identify(e, model="ipdt", outputs=outputs)


@pytest.mark.parametrize("experiment", [None, "log.csv", 1.0, []])
def test_predict_names_an_experiment_that_is_not_one(scratch, experiment):
    with pytest.raises(InvalidTypeError, match="experiment must be an Experiment"):
        delaykit.predict(load_model(scratch / "model.json"), experiment)  # (AttributeError: no attribute 'outputs')


@pytest.mark.parametrize("call, error", [
    (lambda: delaykit.design_compensator("smith", "1/s", 0.37, closed_loop_time=0.5, steps=None), InvalidTypeError),
    (lambda: delaykit.design_compensator("smith", "1/s", 0.37, closed_loop_time=0.5, steps=0.2), InvalidTypeError),
    (lambda: delaykit.design_compensator("smith", "1/s", 0.37, closed_loop_time=0.5, steps="x"), InvalidTypeError),
    (lambda: delaykit.Experiment.from_arrays([0.0, 1.0, _BIG], {"z": [0.0, 1.0, 2.0]}), InvalidValueError),
    (lambda: delaykit.DelayLTI([[_BIG]]), InvalidValueError),
    (lambda: delaykit.DelayLTI([[-1.0]], [[_BIG]], None, [[1.0]]), InvalidValueError),
    (lambda: delaykit.Jitter(0.3, np.array([1.0, 2.0])), InvalidValueError),
    (lambda: delaykit.monte_carlo(delaykit.AltitudeLoop(kp=1.31, delay=0.368),
                                  delaykit.Jitter(0.368, "uniform", spread=0.05), n=_BIG), InvalidValueError),
], ids=["steps-None", "steps-number", "steps-text", "experiment-big", "DelayLTI-A-big", "DelayLTI-B-big",
        "jitter-array", "monte-carlo-n-big"])
def test_design_and_simulation_arguments_are_refused_by_name(call, error):
    with pytest.raises(error):  # (raw TypeError, OverflowError, or numpy's 'truth value is ambiguous')
        call()


@pytest.mark.parametrize("host", ["a" * 300, "", "256.1.1.1", "bad name"])
def test_the_emulator_checks_its_host_before_binding(monkeypatch, host):
    from delaykit.hardware.emulator import EmulatorConfig

    def lookup(*args, **kwargs):
        raise AssertionError(f"looked up {args!r}")

    monkeypatch.setattr(socket, "getaddrinfo", lookup)
    with pytest.raises(InvalidValueError, match="is not an IPv4 address"):
        EmulatorConfig(host=host)  # (a PortError from bind, after the resolver; '' bound every interface)


def test_cli_a_link_to_a_folder_names_both(tmp_path):
    (tmp_path / "out.csv").symlink_to(tmp_path)
    res = runner.invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.368", "--t-end", "1", "--csv",
                              str(tmp_path / "out.csv")])
    line = _refused(res, "is a folder")
    assert f"{str(tmp_path / 'out.csv')!r} (a link to {str(tmp_path)!r})" in line
