"""Hostile inputs to the delay-system algebra: each gets a delaykit error (a ValueError or TypeError too) whose
message names the bad value and what was expected, never a raw numpy/Python error or a misleading reason.

The reference for each case is the arithmetic of the call itself (1e200 * 1e200 is beyond the largest float,
1.8e308; 10**400 has 401 digits; a bool is not a number), written in the comments.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit import InvalidTypeError, InvalidValueError, delay, feedback, ss, tf
from delaykit.cli.app import app
from delaykit.systems.algebra import append, gain, interconnect

G = tf("1/(s+1)")
HUGE = 10**400  # 401 digits: no float holds it


def _raises(kind, call, *words):
    with pytest.raises(kind) as exc:
        call()
    assert issubclass(kind, (ValueError, TypeError))
    msg = str(exc.value)
    for w in words:
        assert w in msg, (w, msg)
    return msg


@pytest.mark.parametrize("call, what", [
    (lambda: gain(1e200) * gain(1e200), "G * H"),        # 1e400 > 1.8e308
    (lambda: gain(1e308) + gain(1e308), "G + H"),        # 2e308 > 1.8e308
    (lambda: gain(1e308) - gain(-1e308), "G + H"),
    (lambda: (G * 1e200) * 1e200, "G * H"),              # the input matrix B1 = 1e400
    (lambda: interconnect([gain(1e200, inputs="u", outputs="e"), gain(1e200, inputs="e", outputs="y")],
                          ["u"], ["y"]), "the interconnection"),
])
def test_overflow_is_named_not_called_ill_posed(call, what):
    msg = _raises(InvalidValueError, call, f"{what} overflows", "beyond the largest float")
    assert "well posed" not in msg
    assert "D11" in msg or "B1" in msg  # the matrix that overflows


def test_large_gains_in_a_chain_are_not_ill_posed():
    # gain(1e7) * gain(1): I - D F is unit triangular (no loop), its condition number 1e14 is no singularity;
    # the product is 1e7 exactly
    assert (gain(1e7) * gain(1.0)).D11.tolist() == [[1e7]]
    assert (gain(1e150) * gain(1e150)).D11.tolist() == [[1e150 * 1e150]]  # the float product
    # a true algebraic loop is still refused: 1 / (1 - 1)
    _raises(InvalidValueError, lambda: feedback(1, 1, sign=1), "not well posed")


@pytest.mark.parametrize("call, where", [
    (lambda: feedback(G, HUGE), "return path"),
    (lambda: G * HUGE, "right factor"),
    (lambda: G + HUGE, "right term"),
    (lambda: append(G, HUGE), "system 1"),
    (lambda: gain(HUGE), "a gain"),
    (lambda: tf(HUGE), "tf"),
])
def test_an_integer_beyond_the_floats(call, where):
    _raises(InvalidValueError, call, where, "must be finite", "401 digits")


@pytest.mark.parametrize("call, where, shown", [
    (lambda: feedback(G, math.nan), "return path", "nan"),
    (lambda: feedback(G, math.inf), "return path", "inf"),
    (lambda: G * math.nan, "right factor", "nan"),
    (lambda: tf(math.nan), "tf", "nan"),
    (lambda: delay(math.nan), "delay", "nan"),
    (lambda: gain([[1.0, math.inf]]), "a gain", "inf"),
])
def test_nan_and_inf_are_named(call, where, shown):
    _raises(InvalidValueError, call, where, "finite", shown)


@pytest.mark.parametrize("call, where", [
    (lambda: feedback(G, True), "return path"),
    (lambda: G * True, "right factor"),
    (lambda: G + False, "right term"),
    (lambda: G - True, "right term"),
    (lambda: append(G, np.bool_(True)), "system 1"),
    (lambda: interconnect([True], ["u"], ["y"]), "block 0"),
    (lambda: gain(True), "a gain"),
])
def test_a_bool_is_not_a_gain(call, where):
    # python-control 0.10.2 takes True as the gain 1 (feedback(1/(s+1), True) = 1/(s+2)); delaykit says that a bool is no number (as check_real does)
    msg = _raises(InvalidTypeError, call, where, "bool")
    assert "expected text" not in msg  # not the tf() message for a call that gave no text


@pytest.mark.parametrize("args, bad", [
    (([[True]], [[1.0]], [[1.0]]), "A"),
    (([[-1.0]], np.array([[True]]), [[1.0]]), "B"),
    (([[-1.0, 0.0], [0.0, -2.0]], [[1.0], [1.0]], [[1.0, np.bool_(False)]]), "C"),
    (([[-1.0]], [[1.0]], [[1.0]], True), "D"),
])
def test_ss_refuses_a_bool_entry(args, bad):
    # numpy reads True as 1.0 (np.array([[True]], dtype=float) is [[1.0]]): the bool is named instead, as for gains
    _raises(InvalidTypeError, lambda: ss(*args), "ss", bad, "bool")


def test_ss_takes_numbers_and_integer_arrays_as_before():
    # the check refuses bools only: integers and float arrays build the same system as floats
    a = ss([[-1]], [[1]], [[2]], [[0]])
    b = ss(np.array([[-1.0]]), np.array([[1.0]]), np.array([[2.0]]), 0.0)
    assert np.array_equal(a.A, b.A) and np.array_equal(a.C1, b.C1) and np.array_equal(a.D11, b.D11)


def test_ss_with_an_integer_beyond_the_floats():
    _raises(InvalidValueError, lambda: ss([[HUGE]], [[1]], [[1]]), "ss", "A", "finite")
    _raises(InvalidValueError, lambda: ss([[-1]], [[1]], [[1]], [[HUGE]]), "ss", "D", "finite")


@pytest.mark.parametrize("text, part, role", [
    ("(s+1)/(1 + 0.5*exp(-s))", "s+1", "numerator"),     # degree 1 over 0: improper on its own
    ("s/(1 + 0.5*exp(-s))", "s", "numerator"),
])
def test_a_delay_in_a_denominator_names_the_text_given(text, part, role):
    msg = _raises(InvalidValueError, lambda: tf(text), repr(text), f"its {role} {part!r}", "improper",
                  "degree 1 in s over 0")


def test_text_without_delay_keeps_the_readers_reason():
    # s^2/(s+1) is improper as a whole (2 over 1); no part of it is blamed
    msg = _raises(InvalidValueError, lambda: tf("s^2/(s+1)"), "'s^2/(s+1)' is improper", "degree 2", "degree 1")
    assert "s**2" not in msg


def test_a_delay_in_a_denominators_lower_term_builds():
    # 1/(s + e^{-s}) was refused part by part (s + exp(-s) is improper on its own); the algebra of s reads it whole:
    # at s = j w it is 1/(j w + e^{-j w}) (the closed form)
    H = tf("1/(s + exp(-s))")
    for w in (0.1, 1.0, 7.0):
        assert abs(complex(H.evaluate([1j * w])[0, 0, 0]) - 1 / (1j * w + np.exp(-1j * w))) < 1e-13


def test_valid_delayed_denominators_still_build():
    # 1/(1 + 0.5 e^{-s}) at s = 0 is 1/1.5 (the closed form)
    T = tf("1/(1 + 0.5*exp(-s))")
    assert abs(float(T.dcgain()[0, 0]) - 1 / 1.5) < 1e-14


_BLOCKS = '''inputs = ["r"]
outputs = ["y"]
[[blocks]]
ss = {{A = [[-1.0]], B = [[1.0]], C = [[1.0]], D = [[{d}]]}}
inputs = "r"
outputs = "e"
[[blocks]]
ss = {{A = [[-1.0]], B = [[1.0]], C = [[1.0]], D = [[{d}]]}}
inputs = "e"
outputs = "y"
'''


def test_cli_overflow_in_a_system_file(tmp_path):
    p = tmp_path / "huge.toml"
    p.write_text(_BLOCKS.format(d="1e200"))  # the two feedthroughs in series: 1e400
    res = CliRunner().invoke(app, ["margins", "--system", str(p)])
    assert res.exit_code == 2 and "Traceback" not in res.output
    flat = res.output.replace("\n", "")
    assert res.output.startswith("error: ") and "overflows" in flat and "well posed" not in flat, res.output


def test_cli_delay_in_a_denominator(tmp_path):
    p = tmp_path / "neutral.toml"
    p.write_text('inputs = ["r"]\noutputs = ["y"]\n[[blocks]]\ntf = "(s+1)/(1 + 0.5*exp(-s))"\ninputs = "r"\n'
                 'outputs = "y"\n')
    res = CliRunner().invoke(app, ["margins", "--system", str(p)])
    assert res.exit_code == 2 and "Traceback" not in res.output
    flat = res.output.replace("\n", "")
    assert res.output.startswith("error: ") and "(s+1)/(1 + 0.5*exp(-s))" in flat and "improper" in flat, res.output
