"""The command line's output: user text printed as written, errors on one line, strict JSON, output paths checked
before the work, and a flight that lands on SIGTERM and SIGHUP."""

from __future__ import annotations

import io
import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from scipy.special import lambertw
from typer.testing import CliRunner

import delaykit
from delaykit.cli import app
from delaykit.cli.common import check_output, out, strict_json, warn
from delaykit.errors import InvalidValueError
from delaykit.hardware.ardrone import ATEncoder, CtrlState
from delaykit.hardware.emulator import DroneEmulator, EmulatorConfig

runner = CliRunner()
SRC = str(Path(delaykit.__file__).resolve().parents[1])


def run(*args: str):
    return runner.invoke(app, list(args))


def strict(text: str):
    """JSON as a strict parser reads it: NaN, Infinity and -Infinity refused."""
    def refuse(name):
        raise AssertionError(f"not JSON: {name}")
    return json.loads(text, parse_constant=refuse)


def one_error_line(res) -> str:
    """The error a command printed: exit status 2, no traceback, exactly one line, starting 'error: '."""
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert "Traceback" not in res.output
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    return lines[0]


# ---- 1. user text is never markup or emoji -----------------------------------------------------------------------

@pytest.mark.parametrize("args, shown", [
    (["simulate", "--kp", "1", "--delay", "[/]"], "'[/]'"),
    (["simulate", "--plant", "[/]", "--kp", "1", "--delay", "0.3"], "[/]"),
    (["simulate", "--kp", "1", "--kv", "0.3", "--velocity", "[/]", "--delay", "0.3"], "[/]"),
    (["simulate", "--kp", "1", "--delay", "0.3", "--period", "0.1", "--delay-schedule", "[/]"], "'[/]'"),
    (["design", "--kv", "[/]", "--delay", "0.3"], "[/]"),
    (["lambert", "--a1", "-1", "--delay", "1", "--branches", "[/]"], "'[/]'"),
    (["estimate", "[/].csv", "--kp", "1"], "[/].csv"),
    (["fly", "--kp", "1", "--monitor", "--design-range", "[/]", "--host", "127.0.0.1"], "[/]"),
    (["roots", "--kp", "1", "--delay", "0.3", "--region", "nan", "2", "0", "100"], "[nan, 2.0, 0.0, 100.0]"),
    (["simulate", "--kp", "1", "--delay", "a:b:c"], "'a:b:c'"),  # rich reads ':b:' as an emoji code
    (["simulate", "--kp", "1", "--delay", "[bold]x[/bold]:smile:"], "'[bold]x[/bold]:smile:'"),
])
def test_user_text_in_an_error_is_printed_as_written(args, shown):
    line = one_error_line(run(*args))
    assert shown in line


def test_control_characters_in_an_error_are_escaped_onto_one_line():
    line = one_error_line(run("simulate", "--kp", "1", "--delay", "1\n2\x1b[31m"))
    assert "\x1b" not in line and r"\n" in line


def test_tables_titles_and_warnings_print_user_text_as_written(monkeypatch):
    from rich.table import Table

    buf = io.StringIO()
    monkeypatch.setattr(sys, "stdout", buf)
    table = Table(title="[/] title :b:")
    table.add_column("[b]log[/b]")
    table.add_row("[red]flight[/].csv :smile:")
    out.print(table)
    warn("a log named [/]x.csv :b:")
    text = buf.getvalue()
    for piece in ("[/] title :b:", "[b]log[/b]", "[red]flight[/].csv :smile:", "warning: a log named [/]x.csv :b:"):
        assert piece in text, text


# ---- 2. one line, whatever the width and the path ------------------------------------------------------------------

def test_an_error_is_one_line_from_a_deep_folder_and_a_narrow_terminal(tmp_path):
    deep = tmp_path.joinpath(*[f"level-{k:02d}-of-a-deeply-nested-folder" for k in range(20)])
    deep.mkdir(parents=True)
    target = deep / "missing" / "r.csv"
    env = {**os.environ, "PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", ""), "COLUMNS": "20"}
    for args, shown in ((["simulate", "--kp", "1", "--delay", "0.3", "--csv", str(target)], repr(str(target))),
                        (["simulate", "--kp", "1", "--delay", str(deep)], repr(str(deep))),  # a library error
                        (["simulate", "--kp", "abc", "--delay", "0.3"], "'--kp'")):  # a usage error
        proc = subprocess.run([sys.executable, "-m", "delaykit.cli", *args], cwd=deep, env=env, capture_output=True,
                              text=True, timeout=300)
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.splitlines()
        assert len(lines) == 1, proc.stderr  # (rich would cut it at 80 columns, or at 20)
        assert lines[0].startswith("error: ") and shown in lines[0]
    assert len(str(target)) > 600  # the path is far longer than any terminal line


@pytest.mark.parametrize("args", [["simulate", "--kp", "abc", "--delay", "0.3"],
                                  ["simulate", "--kp", "1", "--delay", "0.3", "--bogus"],
                                  ["simulat"], ["lambert", "--delay", "1"]])
def test_usage_errors_are_one_line_too(args):
    line = one_error_line(run(*args))
    assert "--help" in line  # where to look


# ---- 3. strict JSON ------------------------------------------------------------------------------------------------

def test_strict_json_writes_null_and_says_why():
    data = strict_json({"a": float("inf"), "b": [1.0, float("nan")], "c": {"d": -math.inf, "status": "ok"},
                        "e": [{"f": math.nan}], "g": 2})
    assert data["a"] is None and data["b"] == [1.0, None] and data["g"] == 2
    assert "a = inf" in data["status"] and "b[1] = nan" in data["status"]
    assert data["c"]["status"] == "ok" and "d = -inf" in data["c"]["null_status"]
    assert data["e"][0]["f"] is None and "f = nan" in data["e"][0]["status"]
    json.dumps(data, allow_nan=False)


def test_a_diverging_loop_gives_strict_json_with_a_status():
    # the loop s + 50 exp(-0.5 s) = 0 is unstable: its rightmost root W_0(-25)/0.5 (SciPy) has Re > 0, so with no
    # limit the output grows until it overflows
    assert (lambertw(-50 * 0.5, 0) / 0.5).real > 0
    res = run("simulate", "--kp", "50", "--delay", "0.5", "--vmax", "none", "--t-end", "300", "--json")
    assert res.exit_code == 0, res.output
    got = strict(res.stdout)
    assert got["overshoot"] is None and "overshoot = inf" in got["status"]
    assert got["settled"] is False


def test_lambert_with_a1_zero_has_one_root_and_strict_json():
    # a1 = 0: the equation s - a0 = 0 has the single root s = a0 (branch 0); the other branches have none
    res = run("lambert", "--a0", "-0.7", "--a1", "0", "--delay", "0.5", "--json")
    assert res.exit_code == 0, res.output
    got = strict(res.stdout)
    assert got["rightmost"] == [-0.7, 0.0]
    roots = {r["branch"]: r for r in got["roots"]}
    assert roots[0]["re"] == -0.7 and roots[0]["im"] == 0.0
    assert all(r["re"] is None and "re = -inf" in r["status"] for k, r in roots.items() if k != 0)
    text = run("lambert", "--a0", "-0.7", "--a1", "0", "--delay", "0.5")
    assert text.exit_code == 0, text.output
    assert "Rightmost root -0.70000000 +0.00000000j" in text.stdout
    assert "nanj" not in text.stdout and text.stdout.count("no root") == 6  # branches -3..3 but 0


# ---- 4. outputs checked before the work ----------------------------------------------------------------------------

@pytest.fixture
def no_work(monkeypatch):
    """Make every long piece of work fail the test if it starts: the output check must come first."""
    def forbidden(*args, **kwargs):
        raise AssertionError("the work started before the output was checked")
    from importlib import import_module

    for module, name in (("hardware.flight", "fly"), ("identify.identification", "identify"),
                         ("paper.demo", "run_demo"), ("paper.report", "write_report"),
                         ("paper.reproduce", "reproduce"), ("simulate.simulation", "simulate")):
        monkeypatch.setattr(import_module(f"delaykit.{module}"), name, forbidden)


@pytest.mark.parametrize("case", ["csv-missing-folder", "plot-bogus", "save-folder", "save-missing-folder",
                                  "report-file", "reproduce-file", "demo-file", "log-folder", "log-empty"])
def test_outputs_are_checked_before_the_work(case, tmp_path, no_work):
    log = tmp_path / "log.csv"
    log.write_text("t,u,z\n0,0,0\n1,1,0\n2,1,1\n")
    a_file = tmp_path / "a-file"
    a_file.write_text("x")
    loop = ["--kp", "1", "--delay", "0.3"]
    path, args = {
        "csv-missing-folder": (tmp_path / "no" / "r.csv", ["simulate", *loop, "--csv"]),
        "plot-bogus": (tmp_path / "x.bogus", ["simulate", *loop, "--plot"]),
        "save-folder": (tmp_path, ["identify", str(log), "--save"]),
        "save-missing-folder": (tmp_path / "no" / "m.json", ["identify", str(log), "--save"]),
        "report-file": (a_file, ["report", "--out"]),
        "reproduce-file": (a_file, ["reproduce", "--out"]),
        "demo-file": (a_file, ["demo", "--out"]),
        "log-folder": (tmp_path, ["fly", "--kp", "1", "--host", "127.0.0.1", "--log"]),
        "log-empty": ("", ["fly", "--kp", "1", "--host", "127.0.0.1", "--log"]),
    }[case]
    line = one_error_line(run(*args, str(path)))
    assert (repr(str(path)) in line) if path else "--log is empty" in line


def test_check_output_passes_what_can_be_written(tmp_path):
    check_output("--csv", tmp_path / "r.csv")
    check_output("--plot", tmp_path / "r.svg", "figure")
    check_output("--out", tmp_path / "new" / "deeper", "folder")  # made when written
    check_output("--plot", None, "figure")
    with pytest.raises(InvalidValueError, match="is a file, not a folder"):
        (tmp_path / "f").write_text("")
        check_output("--out", tmp_path / "f" / "sub", "folder")


# ---- 5. flying ------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("args, shown", [
    (["fly", "--kp", "1", "--host", "127.0.0.1", "--steps", "1,,2"], "item 2 ''"),
    (["fly", "--kp", "1", "--host", "127.0.0.1", "--steps", "a"], "item 1 'a'"),
    (["fly", "--kp", "1", "--host", "::1"], "'::1' is an IPv6 address"),
    (["emulate", "--video-port", "6011", "--control-port", "6011", "--duration", "0.1"], "both 6011"),
    (["emulate", "--at-port", "6012", "--navdata-port", "6012", "--duration", "0.1"], "both 6012"),
])
def test_fly_and_emulate_arguments_give_one_line_errors(args, shown, tmp_path):  # (nothing is sent)
    line = one_error_line(run(*args, *(["--log", str(tmp_path / "f.csv")] if args[0] == "fly" else [])))
    assert shown in line


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGHUP"])
def test_fly_lands_and_says_why_on_sigterm_and_sighup(tmp_path, sig):
    log = tmp_path / "f.csv"
    env = {**os.environ, "PYTHONPATH": SRC + os.pathsep + os.environ.get("PYTHONPATH", "")}
    with DroneEmulator(EmulatorConfig(at_port=0, navdata_port=0, video_port=0, control_port=0, seed=3)) as emu:
        proc = subprocess.Popen([sys.executable, "-m", "delaykit.cli", "fly", "--host", "127.0.0.1", "--at-port",
                                 str(emu.ports["at"]), "--navdata-port", str(emu.ports["navdata"]), "--kp", "1.31",
                                 "--hover", "0.5", "--duration", "30", "--log", str(log)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        try:
            deadline = time.monotonic() + 120
            while not (log.exists() and emu.mode in (CtrlState.FLYING, CtrlState.HOVERING)):  # in the air, stepping
                assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
                time.sleep(0.05)
            proc.send_signal(getattr(signal, sig))
            stdout, stderr = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        deadline = time.monotonic() + 10
        while emu.mode != CtrlState.LANDED and time.monotonic() < deadline:
            time.sleep(0.1)
        assert emu.mode == CtrlState.LANDED  # it landed before the process ended
    assert proc.returncode == 1, stderr
    assert f"Flight ended early: interrupted ({sig})" in stdout
    assert "Traceback" not in stderr


def test_the_emulator_ignores_configuration_keys_it_does_not_have():
    enc = ATEncoder()
    with DroneEmulator(EmulatorConfig(at_port=0, navdata_port=0, video_port=0, control_port=0)) as emu:
        ctl = socket.create_connection(("127.0.0.1", emu.ports["control"]), timeout=5)
        at = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            deadline = time.monotonic() + 5
            while emu.summary()["stats"]["datagrams"] == 0 or emu._control_conn is None:  # connected and heard
                at.sendto(enc.comwdg(), ("127.0.0.1", emu.ports["at"]))
                assert time.monotonic() < deadline
                time.sleep(0.05)
            at.sendto(enc.config("custom:evil", "x") + enc.config("control:control_vz_max", "1000")
                      + enc.ctrl(4), ("127.0.0.1", emu.ports["at"]))
            text = b""
            while b"general:navdata_demo" not in text:
                text += ctl.recv(4096)
        finally:
            ctl.close()
            at.close()
        stats = emu.stats
    lines = text.decode().splitlines()
    # the configuration text: the drone's own keys, with the value it uses; the unknown key neither kept nor echoed
    assert sorted(lines) == ["control:altitude_max = 3000", "control:control_vz_max = 1000",
                             "general:navdata_demo = FALSE"]
    assert stats["config_ignored"] == 1
