"""``delaykit simulate --system FILE``: the exact step response of a system file, on the command line.

The reference for the numbers is a closed form: the file below is ``y = exp(-s) / (s + 1)`` in unity feedback,
whose step response is 0 before 1 s, ``1 - e^{-(t-1)}`` on [1, 2] and ``e^{-(t-2)} (1 - e^{-1} + t - 2)`` on
[2, 3] (the method of steps by hand: ``v' = -v + 1 - v(t - 1)``, ``y(t) = v(t - 1)``).  The examples' responses
are compared with ``delaykit.simulate.systems.step_response`` of the same file (the command is a thin layer).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from delaykit.cli.app import app
from delaykit.simulate.systems import step_response
from delaykit.systems.files import read_system_file

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
runner = CliRunner()

LOOP = ('name = "delayed lag"\ninputs = "r"\noutputs = "y"\n'
        '[[blocks]]\nsum = ["r", "-y"]\noutputs = "e"\n'
        '[[blocks]]\ntf = "1/(s+1)"\ninputs = "e"\noutputs = "v"\n'
        '[[blocks]]\ndelay = 1.0\ninputs = "v"\noutputs = "y"\n')


def _strict(text: str):
    def bad(c: str):
        raise AssertionError(f"non-strict JSON constant {c}")
    return json.loads(text, parse_constant=bad)


def _closed_form(t: np.ndarray) -> np.ndarray:
    return np.where(t < 1, 0.0, np.where(t <= 2, 1 - np.exp(-(t - 1)), np.exp(-(t - 2)) * (1 - math.exp(-1) + t - 2)))


def test_json_is_the_closed_form(tmp_path):
    p = tmp_path / "loop.toml"
    p.write_text(LOOP)
    res = runner.invoke(app, ["simulate", "--system", str(p), "--t-end", "3", "--json"])
    assert res.exit_code == 0, res.output
    d = _strict(res.stdout)
    assert d["status"] == "exact" and d["kind"] == "step" and "delayed lag" in d["system"]
    t, y = np.array(d["time"]), np.array(d["outputs"])
    assert y.shape == (1, 1, t.size) and t[0] == 0 and t[-1] == 3.0 and t.size == 1001
    assert np.abs(y[0, 0] - _closed_form(t)).max() < 1e-10
    assert d["input_labels"] == ["r"] and d["output_labels"] == ["y"]


def test_table_and_figure_of_the_quadrotor_example(tmp_path):
    f = EXAMPLES / "quadrotor-xy.toml"
    fig = tmp_path / "a" / "deep" / "folder" / "for" / "the" / "figure" / "xy.png"
    fig.parent.mkdir(parents=True)
    res = runner.invoke(app, ["simulate", "--system", str(f), "--t-end", "12", "--plot", str(fig)])
    assert res.exit_code == 0, res.output
    assert fig.stat().st_size > 10_000
    ref = step_response(read_system_file(f).system, 12.0)
    # the table's final values are the library's (x after the x step: 1, the integral of the position loop)
    assert "x_ref" in res.stdout and "exact" in res.stdout
    final = ref.outputs[:, :, -1]
    assert abs(final[0, 0] - 1) < 1e-3 and abs(final[1, 1] - 1) < 1e-3
    assert f"{final[0, 0]:.6g}" in res.stdout and f"{final[1, 0]:.6g}" in res.stdout
    res = runner.invoke(app, ["simulate", "--system", str(f), "--t-end", "12", "--json"])
    d = _strict(res.stdout)
    assert np.abs(np.array(d["outputs"]) - ref.outputs).max() == 0.0


def test_errors_are_one_line_with_status_2(tmp_path):
    f = str(EXAMPLES / "px4-altitude.toml")
    for args, words in (([f, "--step", "2"], ["--step", "does not apply"]),
                        ([f, "--kp", "2"], ["--kp"]),
                        ([f, "--t-end", "-1"], ["--t-end"]),
                        ([str(tmp_path / "missing.toml")], ["missing.toml"]),
                        ([f, "--plot", str(tmp_path / "no" / "such" / "deep" / "folder" / "f.png")], ["does not exist"]),
                        ([f, "--plot", str(tmp_path / "f.xyz")], ["not a figure format"])):
        res = runner.invoke(app, ["simulate", "--system", *args])
        assert res.exit_code == 2, (args, res.output)
        assert res.output.startswith("error: ") and "Traceback" not in res.output, res.output
        flat = res.output.replace("\n", "")
        assert all(w in flat for w in words), (words, res.output)
    assert not (tmp_path / "no").exists()  # the output path is checked before the work, nothing is made
    # a neutral system whose difference operator is not strongly stable: refused by the kernel, one line
    p = tmp_path / "neutral.toml"
    p.write_text('inputs = "r"\noutputs = "y"\n[[blocks]]\nsum = ["r", "-w"]\noutputs = "y"\n'
                 '[[blocks]]\ntf = 1.5\ninputs = "y_d"\noutputs = "w"\n'
                 '[[blocks]]\ndelay = 1.0\ninputs = "y"\noutputs = "y_d"\n')
    res = runner.invoke(app, ["simulate", "--system", str(p), "--json"])
    assert res.exit_code == 2 and res.output.startswith("error: ") and "Traceback" not in res.output


def test_a_response_that_stops_early_exits_with_status_1(tmp_path):
    # 1/(s - 50) behind a delay grows like e^{50 t}: past about t = 14 it leaves the floating-point range, so the
    # kernel stops there (status overflow) and the later outputs are null, never Infinity or NaN
    p = tmp_path / "unstable.toml"
    p.write_text('inputs = "r"\noutputs = "y"\n[[blocks]]\ntf = "1/(s-50)"\ninputs = "r"\noutputs = "v"\n'
                 '[[blocks]]\ndelay = 0.1\ninputs = "v"\noutputs = "y"\n')
    res = runner.invoke(app, ["simulate", "--system", str(p), "--t-end", "100", "--json"])
    assert res.exit_code == 1, res.output
    d = _strict(res.stdout)
    assert d["status"] == "overflow" and 10 < d["t_reached"] < 100
    y = d["outputs"][0][0]
    assert y[-1] is None and y[0] == 0.0
    t = np.array(d["time"])
    k = int(np.searchsorted(t, 2.0))  # before the overflow the values are the closed form (e^{50 (t - 0.1)} - 1) / 50
    assert math.isclose(y[k], (math.exp(50 * (t[k] - 0.1)) - 1) / 50, rel_tol=1e-10)
    res = runner.invoke(app, ["simulate", "--system", str(p), "--t-end", "100"])
    assert res.exit_code == 1 and "warning: the response stopped" in res.stdout
