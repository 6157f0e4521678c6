"""Command-line habits found by trying it as a new user: ``tune --plant`` with the dead time in the text, and
``--help`` paragraphs that the terminal wraps (not the source's line breaks)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from delaykit import tune
from delaykit.cli import app
from delaykit.cli.app import COMMANDS
from delaykit.cli.common import help_text

runner = CliRunner()
PLANT = "2*exp(-3*s)/((10*s+1)*(2*s+1))"


def test_tune_reads_the_plants_dead_time_from_its_text():
    res = runner.invoke(app, ["tune", "--plant", PLANT, "--controller", "pi", "--json"])
    assert res.exit_code == 0, res.output
    got = json.loads(res.stdout)
    ref = tune(PLANT, "pi")  # the Python function reads the delay from the same text
    assert got["kp"] == pytest.approx(ref.kp, rel=1e-12) and got["ki"] == pytest.approx(ref.ki, rel=1e-12)
    # the same as the delay given apart, on the rational part
    apart = runner.invoke(app, ["tune", "--plant", "2/((10*s+1)*(2*s+1))", "--delay", "3", "--controller", "pi",
                                "--json"])
    assert apart.exit_code == 0, apart.output
    assert json.loads(apart.stdout)["kp"] == pytest.approx(got["kp"], rel=1e-12)


def test_tune_without_a_plant_or_a_delay_says_what_to_give():
    res = runner.invoke(app, ["tune", "--controller", "pi"])
    assert res.exit_code == 2 and "--plant" in res.output and "Traceback" not in res.output


def test_every_commands_help_has_its_paragraphs_on_one_line_each():
    from importlib import import_module

    for _, commands in COMMANDS:
        for module, name in commands:
            text = help_text(getattr(import_module(f"delaykit.cli.{module}"), name))
            for para in text.split("\n\n"):
                lines = para.split("\n")
                if len(lines) > 1:  # only lists keep their breaks
                    assert all(ln.lstrip().startswith(("- ", "* ")) or ln.startswith(" ") or
                               ln.split(" ", 1)[0].rstrip(".").isdigit() for ln in lines[1:]), (name, para)


def test_fly_help_is_wrapped_by_the_terminal_not_by_the_source():
    env = {**os.environ, "COLUMNS": "200", "TERM": "dumb"}
    out = subprocess.run([sys.executable, "-m", "delaykit.cli", "fly", "--help"], capture_output=True, text=True,
                         env=env, timeout=120).stdout
    # in the source this sentence breaks after "on the"; at 200 columns it must stay on one line
    assert any("designed for --model-delay on the integrator model 1/s" in ln for ln in out.splitlines()), out
