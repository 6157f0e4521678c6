"""Issue 25's leftovers: the last API cases of the fuzz suite, option values read as ASCII decimal, table numbers
short at any magnitude.

Each case asserts delaykit's exception type and that the message names the value, or, where a result was wrong
before, the now-correct result against a closed form.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from delaykit import AltitudeLoop, InvalidTypeError, InvalidValueError, margins, noise_level
from delaykit.models.ranges import parse_range
from delaykit.spectrum.lambert import lambert_roots


@pytest.mark.parametrize("kp", [1e3, 1e8, 1e30, 1e100])
def test_margins_of_a_huge_gain_find_its_crossover(kp):
    # delay 0: L(s) = kp/s (the altitude loop's P law on the integrator), closed form: |L(jw)| = 1 at w = kp, phase
    # -90 degrees there, so a phase margin of 90 degrees and a delay margin of (pi/2)/kp.  Before, above about
    # kp = 1e7 the crossover was dropped (|L|^2's polynomial coefficients span kp^2) and the margins read infinite;
    # at 1e30 an invalid cast also warned.
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = margins(AltitudeLoop(kp=kp, delay=0.0))
    assert m.stable
    assert m.crossover == pytest.approx(kp, rel=1e-12)
    assert m.phase_margin == pytest.approx(90.0, abs=1e-9)
    assert m.delay_margin == pytest.approx(math.pi / 2 / kp, rel=1e-12)


@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan])
def test_noise_level_refuses_a_sample_that_is_not_finite(bad):
    z = np.zeros(8)
    z[5] = bad
    with pytest.raises(InvalidValueError, match=r"z\[5\] is (-?inf|nan)"):
        noise_level(z)


def test_noise_level_refuses_text():
    with pytest.raises(InvalidTypeError, match="z must be real numbers"):
        noise_level(np.array(["a", "b", "c", "d", "e"]))


@pytest.mark.parametrize("spec", [None, 3, 2.5, b"1:2:3", object()])
def test_parse_range_refuses_what_is_neither_text_nor_a_sequence(spec):
    with pytest.raises(InvalidTypeError, match="kp must be text"):
        parse_range(spec, "kp")


def test_parse_range_still_takes_a_sequence():
    assert parse_range((1, 2.5), "kp") == [1.0, 2.5]


@pytest.mark.parametrize("branches", [0.0, 2.5, "01", None, [0, 1.0], [0, "1"]])
def test_lambert_branches_that_are_not_integers_are_refused(branches):
    with pytest.raises(InvalidTypeError, match="integer"):
        lambert_roots(0.0, -1.31, 0.368, branches=branches)


@pytest.mark.parametrize("branches", [10**30, [0, -(10**19)]])
def test_lambert_branches_beyond_c_long_are_refused(branches):
    with pytest.raises(InvalidValueError, match="out of range"):
        lambert_roots(0.0, -1.31, 0.368, branches=branches)


# ---- numbers in tables: short at any magnitude ------------------------------------------------------------------

@pytest.mark.parametrize("x, digits", [(1e300, 5), (-1e300, 4), (2e-9, 4), (-3.5e-12, 5), (123456789.0, 4),
                                       (5e-5, 4), (1e6, 3)])
def test_fmt_stays_short_and_keeps_the_value(x, digits):
    from delaykit.cli.common import fmt

    text = fmt(x, digits)
    assert len(text) <= digits + 8, text  # sign, one digit, point, the digits, e+300
    assert float(text) == pytest.approx(x, rel=10.0 ** -digits)  # the value is still there (not 0.0000)


def test_fmt_keeps_fixed_point_in_the_usual_range():
    from delaykit.cli.common import fmt

    assert [fmt(0.368, 5), fmt(12.5), fmt(0.0), fmt(-0.25, 3), fmt(999999.0, 1)] == \
        ["0.36800", "12.5000", "0.0000", "-0.250", "999999.0"]


def test_simulate_prints_a_huge_delay_in_a_short_cell():
    from typer.testing import CliRunner

    from delaykit.cli import app

    res = CliRunner().invoke(app, ["simulate", "--kp", "1.31", "--delay", "0.3,1e300", "--t-end", "3"])
    assert res.exit_code == 0, res.output
    assert "1.00000e+300" in res.output and "0.30000" in res.output
    assert max(len(line) for line in res.output.splitlines()) < 100  # a 300-digit cell would be 300 wide


# ---- option values: ASCII decimal only, for every numeric option of every command -----------------------------

def _numeric_options():
    """(command, option, int or float, nargs) for every option of the Typer app that takes numbers."""
    import typer.main

    from delaykit.cli import app
    from delaykit.cli.common import _number_kind

    group = typer.main.get_command(app)
    found = []
    for name, cmd in sorted(group.commands.items()):
        for p in cmd.params:
            kind = _number_kind(p.type_descriptor.annotation)
            if kind is not None and p.param_type_name == "option":
                found.append(pytest.param(name, p.opts[0], kind, max(p.nargs, 1), id=f"{name} {p.opts[0]}"))
    return found


NUMERIC_OPTIONS = _numeric_options()
# what Python's float() and int() (and pydantic) read as numbers but a person does not write: underscores,
# full-width, Arabic-Indic and superscript digits
NOT_ASCII_DECIMAL = ["1_0", "1e5_0", "\uff11\uff12", "\u0661\u0662", "\u00b9"]


def test_every_command_has_numeric_options_enumerated():
    commands = {p.values[0] for p in NUMERIC_OPTIONS}
    assert {"simulate", "roots", "margins", "lambert", "design", "estimate", "fly", "emulate", "demo"} <= commands
    assert any(p.values[3] > 1 for p in NUMERIC_OPTIONS)  # roots --region: four numbers


@functools.lru_cache(maxsize=1)
def _group():
    import typer.main

    from delaykit.cli import app

    return typer.main.get_command(app)  # (its options convert values as the delaykit script's do)


def _parse(command: str, args: list[str]):
    """Parse ``delaykit COMMAND ARGS`` (nothing runs); the click error raised, or None."""
    group = _group()
    usage = next(c for c in __import__("typer").BadParameter.__mro__ if c.__name__ == "UsageError")
    try:
        group.commands[command].make_context(command, args)
    except usage as exc:
        return exc
    return None


@pytest.mark.parametrize("command, flag, kind, nargs", NUMERIC_OPTIONS)
def test_numeric_options_take_ascii_decimal_only(command, flag, kind, nargs):
    import typer

    good = "2" if kind is int else "2.5"
    for text in NOT_ASCII_DECIMAL:
        exc = _parse(command, [flag, *([good] * (nargs - 1)), text])  # the option first: click checks it first
        assert isinstance(exc, typer.BadParameter) and exc.param is not None and exc.param.opts[0] == flag, \
            (text, exc)
        assert "ASCII decimal" in exc.format_message() and repr(text) in exc.format_message()
    exc = _parse(command, [flag, *([good] * nargs)])  # a plain number passes this option (others may be missing)
    assert not (isinstance(exc, typer.BadParameter) and exc.param is not None and exc.param.opts[0] == flag), exc


def test_a_bad_option_number_is_one_line_exit_2():
    from typer.testing import CliRunner

    from delaykit.cli import app

    res = CliRunner().invoke(app, ["simulate", "--kp", "1_0", "--delay", "0.3"])
    assert res.exit_code == 2 and "Traceback" not in res.output
    lines = res.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "'--kp'" in lines[0] and "'1_0'" in lines[0]


def test_lambert_prints_a_huge_root_in_short_text():
    from typer.testing import CliRunner

    from delaykit.cli import app

    # a1 = 0: the one root is s = a0 (closed form), here -1e250, printed as 251 digits before
    res = CliRunner().invoke(app, ["lambert", "--a0", "-1e250", "--a1", "0", "--delay", "1"])
    assert res.exit_code == 0, res.output
    assert "Rightmost root -1.00000000e+250 +0.00000000j" in " ".join(res.output.split())
    assert max(len(line) for line in res.output.splitlines()) < 130


def test_estimate_warns_about_a_huge_peak_time_in_short_text():
    from typer.testing import CliRunner

    from delaykit.cli import app

    res = CliRunner().invoke(app, ["estimate", "--kp", "1.31", "--method", "overshoot", "--overshoot", "20",
                                   "--peak-time", "1e200"])
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert "the flight peaked at 1e+200 s" in text and max(len(w) for w in text.split()) < 40
