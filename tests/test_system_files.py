"""System files (TOML blocks joined by name): loading, the examples against systems built otherwise, the CLI.

References: the examples' frequency responses and characteristic functions are written here by hand with numpy
from the physics stated in the files (no delaykit algebra); their margins are compared with the same loop built
with delaykit's ``tf``/``feedback`` algebra instead of ``interconnect``; the PX4 file's numbers are recomputed
by delaykit's identification of three PX4 flights read from ../shared/data (tests/shared_data.py; skipped, saying
why, where absent), cut at 30 s as the file's numbers were (slow).
"""

from __future__ import annotations

import doctest
import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from delaykit import (InvalidValueError, delay, feedback, is_stable, load_system, loop_margins, poles, tf)
from delaykit.cli.app import app
from delaykit.systems.files import read_system_file, system_from_dict

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
runner = CliRunner()

# the PX4 file's numbers (checked against the identification in test_px4_file_numbers_are_the_identification)
K, WN, ZETA, TZ, TD, KP = 0.7906, 1.554, 1.694, 2.744, 0.06325, 0.95
# the quadrotor file's numbers
G, TAU, T_LINK, KPQ, KDQ, PSI = 9.81, 0.15, 0.1, 0.2, 0.25, math.radians(10.0)
ROT = np.array([[math.cos(PSI), math.sin(PSI)], [-math.sin(PSI), math.cos(PSI)]])
W = np.array([0.01, 0.3, 1.0, 2.5, 7.0, 30.0])


def _px4_loop(s: np.ndarray) -> np.ndarray:
    """L(s) at the speed command, by hand: Kp e^{-s Td} K wn^2 (Tz s + 1) / ((s^2 + 2 zeta wn s + wn^2) s)."""
    return KP * np.exp(-s * TD) * K * WN**2 * (TZ * s + 1) / ((s**2 + 2 * ZETA * WN * s + WN**2) * s)


def _quad_plant(s: complex) -> np.ndarray:
    """x = P(s) c: tilt commands c over the link, rotated, attitude lag, g, two integrators (by hand)."""
    return G * np.exp(-s * T_LINK) / (s * s * (TAU * s + 1)) * ROT


def test_px4_file_equals_its_loop_built_by_hand():
    sf = read_system_file(EXAMPLES / "px4-altitude.toml")
    s = 1j * W
    L = _px4_loop(s)
    got = sf.system.frequency_response(W).response[0, 0]
    assert np.allclose(got, L / (1 + L), rtol=1e-11, atol=0)
    loop = sf.loops[0].frequency_response(W).response[0, 0]
    assert np.allclose(loop, L, rtol=1e-11, atol=0)
    # margins of the file's loop = those of the same loop built with the algebra (series of tf blocks)
    L_alg = tf(KP) * delay(TD) * tf(f"{K}*{WN}^2*({TZ}*s+1)/(s^2+2*{ZETA}*{WN}*s+{WN}^2)") * tf("1/s")
    a, b = loop_margins(sf.loops[0]), loop_margins(L_alg)
    for f in ("gain_margin", "phase_margin", "delay_margin", "gain_crossover", "phase_crossover"):
        assert math.isclose(getattr(a, f), getattr(b, f), rel_tol=1e-9), f
    # the poles are the roots of s (s^2 + 2 zeta wn s + wn^2) + Kp K wn^2 (Tz s + 1) e^{-s Td}
    sp = sf.system.poles((-8, 1, -20, 20))
    assert sp.certified
    for z in sp.roots:
        q = z * (z * z + 2 * ZETA * WN * z + WN**2) + KP * K * WN**2 * (TZ * z + 1) * np.exp(-z * TD)
        assert abs(q) < 1e-9 * (1 + abs(z) ** 3)
    assert is_stable(sf.system) and sp.roots.real.max() < 0


def test_quadrotor_file_equals_its_loop_built_by_hand():
    sf = read_system_file(EXAMPLES / "quadrotor-xy.toml")
    assert sf.system.inputs == ("x_ref", "y_ref") and sf.system.outputs == ("x", "y")
    got = sf.system.frequency_response(W).response
    for k, w in enumerate(W):
        s = 1j * w
        P = _quad_plant(s)
        L = (KPQ + KDQ * s) * P  # c = Kp (r - x) - Kd s x
        T = np.linalg.solve(np.eye(2) + L, P) * KPQ
        assert np.allclose(got[:, :, k], T, rtol=1e-10, atol=1e-14 * np.abs(T).max())
    # the loop opened at cx (cy closed) = channel 0 of the 2x2 loop built with the algebra
    c = math.cos(PSI)
    sn = math.sin(PSI)
    entry = "({k}*(0.2+0.25*s)*9.81*exp(-0.1*s)/(s^2*(0.15*s+1)))"
    L_alg = tf([[entry.format(k=c), entry.format(k=sn)], [entry.format(k=-sn), entry.format(k=c)]])
    for ch in (0, 1):
        a, b = loop_margins(sf.loops[ch]), loop_margins(L_alg, ch)
        for f in ("gain_margin", "phase_margin", "delay_margin"):
            assert math.isclose(getattr(a, f), getattr(b, f), rel_tol=1e-8), (ch, f)
    # each pole is a zero of det(s^2 (tau s + 1) I + g (Kp + Kd s) e^{-s T} R)
    sp = sf.system.poles((-4, 1, -12, 12))
    assert sp.certified and sp.roots.size >= 4
    for z in sp.roots:
        D = z * z * (TAU * z + 1) * np.eye(2) + G * (KPQ + KDQ * z) * np.exp(-z * T_LINK) * ROT
        assert abs(np.linalg.det(D)) < 1e-8 * (1 + abs(z) ** 3) ** 2
    assert is_stable(sf.system)


def test_wood_berry_file_equals_the_loop_built_by_the_algebra():
    # the Python construction of docs/guide/systems.md (tf matrices, series, feedback): no interconnect
    G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
            ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]])
    Kc = tf([["0.375*(1 + 1/(8.29*s))", 0], [0, "-0.075*(1 + 1/(23.6*s))"]])
    sf = read_system_file(EXAMPLES / "wood-berry.toml")
    w = np.array([0.003, 0.03, 0.1, 0.3, 1.0])
    ref = feedback(G * Kc, 1).frequency_response(w).response
    assert np.allclose(sf.system.frequency_response(w).response, ref, rtol=1e-10, atol=1e-13)
    for ch, at in enumerate(("R", "S")):
        # opened at the manipulated variable: K G, whose loop-at-a-time margins are those of G K
        a, b = loop_margins(sf.loops[ch]), loop_margins(Kc * G, ch)
        assert sf.breaks[ch] == at
        for f in ("gain_margin", "phase_margin", "delay_margin"):
            assert math.isclose(getattr(a, f), getattr(b, f), rel_tol=1e-8), (at, f)
    assert is_stable(sf.system)


def test_margins_need_a_break(tmp_path):
    p = tmp_path / "nobreak.toml"
    p.write_text('inputs = "r"\noutputs = "y"\n[[blocks]]\ntf = "1/(s+1)"\ninputs = "r"\noutputs = "y"\n')
    res = runner.invoke(app, ["margins", "--system", str(p)])
    assert res.exit_code == 2 and "break" in res.output


@pytest.mark.slow
def test_px4_file_numbers_are_the_identification():
    from delaykit import Controller, Loop
    from delaykit.identify import identify
    from shared_data import px4_flights

    outer = Loop("1/s", Controller.p(0.95), umin=-1.0, umax=3.0, period=0.02)  # the flights' loop (data README)
    # the file's numbers were identified on t = 10 to 30 s of each log (the step at 15 s and the 15 s after it)
    runs = px4_flights([f"HAYDEN_0{i}" for i in (1, 2, 3)], reference="z_ref")
    m = identify(runs, model="ipdt_speed", loop=outer, fresh_only=True)
    for name, v in (("gain", K), ("wn", WN), ("zeta", ZETA), ("zero", TZ), ("delay", TD)):
        assert float(f"{m.params[name]:.4g}") == v, (name, m.params[name])


def test_the_guide_examples_run():
    path = ROOT / "docs" / "guide" / "system-files.md"
    parser = doctest.DocTestParser()
    test = parser.get_doctest(path.read_text(encoding="utf-8"), {}, path.name, str(path), 0)
    runner_ = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    import os
    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        runner_.run(test)
    finally:
        os.chdir(cwd)
    assert test.examples and runner_.failures == 0


# -- the command line -------------------------------------------------------------------------------------------
def test_cli_margins_and_roots_of_a_system_file():
    f = str(EXAMPLES / "quadrotor-xy.toml")
    res = runner.invoke(app, ["margins", "--system", f, "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["stable"] is True and [x["at"] for x in d["loops"]] == ["cx", "cy"]
    sf = read_system_file(f)
    assert math.isclose(d["loops"][0]["gain_margin"], loop_margins(sf.loops[0]).gain_margin, rel_tol=1e-12)
    res = runner.invoke(app, ["roots", "--system", f, "--region", "-4", "1", "0", "12", "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    ref = poles(sf.system, (-4, 1, 0, 12))
    assert d["certified"] and d["stable"] is True
    got = np.array([complex(*r) for r in d["roots"]])
    assert got.size == ref.roots.size and np.allclose(got, ref.roots, rtol=1e-10)
    res = runner.invoke(app, ["margins", "--system", f])
    assert res.exit_code == 0 and "cx" in res.stdout and "stable" in res.stdout


def test_cli_json_is_strict_when_a_margin_is_infinite(tmp_path):
    # a first-order loop has no phase crossover: gain margin infinite -> null
    p = tmp_path / "lag.toml"
    p.write_text('inputs = "r"\noutputs = "y"\nbreak = "u"\n[[blocks]]\ntf = "1/(s+1)"\ninputs = "u"\n'
                 'outputs = "y"\n[[blocks]]\nsum = ["r", "-y"]\noutputs = "u"\n')
    res = runner.invoke(app, ["margins", "--system", str(p), "--json"])
    assert res.exit_code == 0, res.output
    assert "Infinity" not in res.stdout and "NaN" not in res.stdout
    assert json.loads(res.stdout)["loops"][0]["gain_margin"] is None


def test_cli_loop_options_beside_a_system_are_refused():
    f = str(EXAMPLES / "px4-altitude.toml")
    res = runner.invoke(app, ["simulate", "--system", f, "--kp", "2"])  # (simulate --system: test_cli_system_simulate)
    assert res.exit_code == 2 and "--kp" in res.output and "Traceback" not in res.output
    res = runner.invoke(app, ["margins", "--system", f, "--kp", "2"])
    assert res.exit_code == 2 and "--kp" in res.output


_GOOD = {"inputs": ["r"], "outputs": ["y"], "break": ["u"],
         "blocks": [{"tf": "1/s", "inputs": "u", "outputs": "y"}, {"sum": ["r", "-y"], "outputs": "u"}]}


@pytest.mark.parametrize("text, words", [
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\ntf = "1/s"\ninputs = "w"\noutputs = "y"\n', ["unknown signal", "'w'"]),
    ('inputs = "r"\noutputs = "z"\n[[blocks]]\ntf = "1/s"\ninputs = "r"\noutputs = "y"\n', ["unknown signal", "'z'"]),
    ('inputs = "r"\noutputs = "y"\nbreak = "q"\n[[blocks]]\ntf = "1/s"\ninputs = "r"\noutputs = "y"\n',
     ["unknown signal", "'q'", "break"]),
    ('outputs = "y"\n[[blocks]]\ntf = "1/s"\ninputs = "r"\noutputs = "y"\n', ["inputs is missing"]),
    ('inputs = "r"\noutputs = "y"\n', ["blocks is missing"]),
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\ntf = "1/s"\noutputs = "y"\n', ["inputs is missing"]),
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\ninputs = "r"\noutputs = "y"\n', ["exactly one of"]),
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\ndelay = nan\ninputs = "r"\noutputs = "y"\n', ["finite", "nan"]),
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\ndelay = -inf\ninputs = "r"\noutputs = "y"\n', ["finite", "-inf"]),
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\nss = {A = [[inf]], B = [[1.0]], C = [[1.0]]}\ninputs = "r"\n'
     'outputs = "y"\n', ["ss.A[0][0]", "finite", "inf"]),
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\ntf = "1/s"\ngain = 2\ninputs = "r"\noutputs = "y"\n',
     ["unknown key", "'gain'"]),
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\ndelay = -1.0\ninputs = "r"\noutputs = "y"\n', ["delay", "-1"]),
    ('inputs = "r"\noutputs = "y"\n[[blocks]]\ntf = "1/(s+"\ninputs = "r"\noutputs = "y"\n', ["block"]),
    ('inputs = "r"\noutputs = "y"\nx = ' + "[" * 40 + "1" + "]" * 40 + '\n[[blocks]]\ntf = "1"\ninputs = "r"\n'
     'outputs = "y"\n', ["nested", "deep"]),
    ('inputs = "r"\noutputs = "y"\nx = ' + "[" * 5000 + "]" * 5000 + '\n', ["deep"]),
    ("not toml = = 1\n", ["not valid TOML"]),
])
def test_bad_files_get_one_line_errors(tmp_path, text, words):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(InvalidValueError) as exc:
        read_system_file(p)
    msg = str(exc.value)
    assert "\n" not in msg and str(p) in msg
    for w in words:
        assert w in msg, (w, msg)
    res = runner.invoke(app, ["margins", "--system", str(p)])
    assert res.exit_code == 2 and "Traceback" not in res.output
    # the message is one line; the error console may wrap it at its width (cli/common.py's printer)
    flat = res.output.replace("\n", "")
    assert res.output.startswith("error: ") and all(w in flat for w in words[:1]), res.output


def test_library_forms():
    sf = system_from_dict(_GOOD)
    assert "loop opened at u" in repr(sf) and sf.to_dict()["breaks"] == ["u"]
    # opening the loop gives L with feedback(L, 1) = the file's system
    T = feedback(sf.loops[0], 1)
    assert np.allclose(T.frequency_response(W).response, sf.system.frequency_response(W).response, rtol=1e-12)
    with pytest.raises(InvalidValueError, match="cannot read the system file"):
        load_system(Path("/nonexistent/system.toml"))
    with pytest.raises(InvalidValueError, match="a system file is a table"):
        system_from_dict([1, 2])
