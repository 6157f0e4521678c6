"""Building delay systems fast (issue 21: 10,000 closed loops with varied gains) without changing what is built.

The algebra makes its results through ``DelayLTI._from_parts`` (no re-validation of matrices it made itself) and
``tf`` remembers the systems of texts it has read.  References, independent of that path:

* python-control's ``series``/``feedback``/``parallel`` of the same rational blocks when there is no delay;
* the algebra's definitions evaluated with numpy at complex points when there are delays: ``(G K)(s) = G(s) K(s)``,
  ``(G + K)(s) = G(s) + K(s)``, ``feedback(L, 1)(s) = (I + L(s))^-1 L(s)``, each delayed entry as
  ``exp(-s T) n(s)/d(s)`` written by hand;
* the public constructor: every built system is rebuilt by ``DelayLTI(**sys.to_dict())``, which checks shapes,
  names and finiteness, and must give the same matrices.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from delaykit import DelayLTI, InvalidTypeError, InvalidValueError, feedback, interconnect, summing_junction, tf
from delaykit.systems import gain

control = pytest.importorskip("control")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from anchors_systems import DELAY, GAIN, KC, LAG, TAU_I, wood_berry_loop, wood_berry_plant  # noqa: E402

PARTS = ("A", "B1", "B2", "C1", "C2", "D11", "D12", "D21", "D22")
S = np.array([0.05j, 0.3 + 0.7j, 1.1j, -0.02 + 2.5j, 0.4])  # points away from every pole used below


def _plant(s):
    """The Wood-Berry transfer matrix at ``s`` written by hand (Wood & Berry 1973)."""
    return GAIN * np.exp(-s * DELAY) / (LAG * s + 1)


def _pi(s, kc):
    return np.diag([kc[0] * (1 + 1 / (TAU_I[0] * s)), kc[1] * (1 + 1 / (TAU_I[1] * s))])


def _at(sys_, s):
    return sys_.evaluate([s])[:, :, 0]


def _same_as_constructor(sys_):
    """The public constructor accepts the system's parts and gives the same matrices, read-only."""
    again = DelayLTI(**sys_.to_dict(), limits=sys_.limits)
    for k in PARTS:
        a, b = getattr(sys_, k), getattr(again, k)
        assert a.shape == b.shape and a.dtype == np.float64 and np.array_equal(a, b), k
        assert not a.flags.writeable, k
    assert (again.delays, again.inputs, again.outputs, again.name) == (sys_.delays, sys_.inputs, sys_.outputs,
                                                                        sys_.name)


@pytest.mark.parametrize("scale", [(1.0, 1.0), (0.7, 1.3), (1.29, 0.71)])
def test_wood_berry_loops_with_varied_gains_are_the_closed_loop_of_the_definition(scale):
    # reference: T(s) = (I + G(s) K(s))^-1 G(s) K(s) with G and K written by hand
    kc = (KC[0] * scale[0], KC[1] * scale[1])
    T = wood_berry_loop(kc=kc)
    _same_as_constructor(T)
    for s in S:
        L = _plant(s) @ _pi(s, kc)
        ref = np.linalg.solve(np.eye(2) + L, L)
        assert np.allclose(_at(T, s), ref, rtol=1e-12, atol=1e-13)


def test_a_prebuilt_plant_with_many_controllers_gives_the_same_loops():
    # reference: the loop built from scratch each time (wood_berry_loop) and the definition at one point
    G = wood_berry_plant()
    rng = np.random.default_rng(5)
    for _ in range(4):
        kc = (KC[0] * rng.uniform(0.7, 1.3), KC[1] * rng.uniform(0.7, 1.3))
        K = tf([[([kc[0] * TAU_I[0], kc[0]], [TAU_I[0], 0.0]), 0], [0, ([kc[1] * TAU_I[1], kc[1]], [TAU_I[1], 0.0])]],
               inputs=["e1", "e2"], outputs=["R", "S"])
        T = feedback(G * K, 1)
        _same_as_constructor(T)
        L = _plant(S[1]) @ _pi(S[1], kc)
        assert np.allclose(_at(T, S[1]), np.linalg.solve(np.eye(2) + L, L), rtol=1e-12, atol=1e-13)
        assert np.allclose(T.evaluate(S), wood_berry_loop(kc=kc).evaluate(S), rtol=1e-12, atol=1e-13)
    assert G.inputs == ("R", "S") and tf(G).inputs == ("R", "S")


@pytest.mark.parametrize("seed", range(3))
def test_delay_free_algebra_matches_python_control(seed):
    # reference: python-control's series, parallel and feedback of the same transfer functions
    rng = np.random.default_rng(seed)

    def block():
        den = np.real(np.poly(-rng.uniform(0.3, 4.0, 2)))
        num = rng.normal(size=2)
        return (num.tolist(), den.tolist()), control.tf(num, den)

    (g, cg), (k, ck), (h, ch) = block(), block(), block()
    G, K, H = tf(g), tf(k), tf(h)
    w = np.geomspace(1e-2, 1e2, 9)
    pairs = [(G * K, cg * ck), (G + K, cg + ck), (G - K, cg - ck), (feedback(G * K, H), control.feedback(cg * ck, ch)),
             (feedback(G, 0.5, sign=1), control.feedback(cg, 0.5, sign=1)), (3.0 * G, 3.0 * cg)]
    for mine, theirs in pairs:
        _same_as_constructor(mine)
        ref = np.asarray(theirs(1j * w, squeeze=False))
        assert np.allclose(mine.frequency_response(w).response, ref, rtol=1e-11, atol=1e-14)


def test_delayed_algebra_and_text_follow_their_definitions():
    # reference: each delayed transfer function written by hand with numpy
    a = tf("2*exp(-0.5*s)/(s+1)")
    b = tf("exp(-0.2*s)/(s^2+s+3)")
    fa = lambda s: 2 * np.exp(-0.5 * s) / (s + 1)  # noqa: E731
    fb = lambda s: np.exp(-0.2 * s) / (s * s + s + 3)  # noqa: E731
    cases = [(a * b, lambda s: fa(s) * fb(s)), (a + b, lambda s: fa(s) + fb(s)), (a - b, lambda s: fa(s) - fb(s)),
             (-a, lambda s: -fa(s)), (feedback(a, b), lambda s: fa(s) / (1 + fa(s) * fb(s))),
             (tf("1/(1 + exp(-s)/(s+1))"), lambda s: 1 / (1 + np.exp(-s) / (s + 1))),
             (tf("(1 - exp(-2*s))/(s+1)"), lambda s: (1 - np.exp(-2 * s)) / (s + 1)),
             (tf([["2*exp(-0.5*s)/(s+1)", 0.5]])[0, 1], lambda s: 0.5 + 0 * s)]
    for sys_, f in cases:
        _same_as_constructor(sys_)
        assert np.allclose(sys_.evaluate(S)[0, 0], f(S), rtol=1e-12, atol=1e-14)
    P = tf("12.8*exp(-s)/(16.7*s+1)", inputs="u", outputs="y")
    C = tf("0.375*(1 + 1/(8.29*s))", inputs="e", outputs="u")
    T = interconnect([P, C, summing_junction(["r", "-y"], "e")], inputs=["r"], outputs=["y", "u"], name="pi")
    _same_as_constructor(T)
    L = 12.8 * np.exp(-S) / (16.7 * S + 1) * 0.375 * (1 + 1 / (8.29 * S))
    assert np.allclose(T.evaluate(S)[0, 0], L / (1 + L), rtol=1e-12, atol=1e-14)


def test_the_remembered_texts_are_immutable_and_errors_are_not_remembered():
    g1 = tf("12.8*exp(-s)/(16.7*s+1)")
    with pytest.raises(ValueError):
        g1.A[0, 0] = 0.0  # read-only: the next tf() of this text gives the same system
    named = tf("12.8*exp(-s)/(16.7*s+1)", inputs="u", outputs="y", name="G")
    assert (named.inputs, named.outputs, named.name) == (("u",), ("y",), "G")
    g2 = tf("12.8*exp(-s)/(16.7*s+1)")
    assert (g2.inputs, g2.outputs, g2.name) == (("u[0]",), ("y[0]",), "")  # the renaming did not leak
    assert np.array_equal(g2.A, [[-1 / 16.7]]) and g2.delays == (1.0,)
    # a remembered transfer matrix of text and numbers against the same one with an entry as (num, den), which is
    # not remembered: the same bytes in every matrix (signed zeros included)
    for zero in (0.0, -0.0, 0):
        cached = tf([["12.8*exp(-s)/(16.7*s+1)", zero], [1, "1/(s+2)"]])
        fresh = tf([["12.8*exp(-s)/(16.7*s+1)", zero], [1, ([1.0], [1.0, 2.0])]])
        assert all(getattr(cached, k).tobytes() == getattr(fresh, k).tobytes() for k in PARTS)
    for _ in range(2):  # the same bad text fails each time, with its message
        with pytest.raises(InvalidValueError, match="prediction"):
            tf("exp(2*s)/(s+1)")
        with pytest.raises(InvalidValueError, match="entry"):
            tf([["1/(s+1)", "exp(2*s)"]])


def test_the_algebra_still_refuses_what_the_constructor_refuses():
    with pytest.raises(InvalidValueError, match="not well posed"):
        feedback(tf("1"), 1, sign=1)  # I - D11 F singular
    with pytest.raises(InvalidValueError, match="not well posed"):
        feedback(tf([["1", "0"], ["0", "2"]]), np.diag([1.0, 0.5]), sign=1)
    with pytest.raises(InvalidValueError, match=r"G \+ H overflows: the result's D11"):
        gain(1e308) + gain(1e308)  # the sum overflows (2e308 > 1.8e308), named (test_systems_errors)
    with pytest.raises(InvalidValueError, match="a gain must be finite, got nan"):
        gain(np.nan)
    with pytest.raises(InvalidValueError, match="distinct"):
        tf([["1/(s+1)", "2/(s+1)"]], inputs=["a", "b"])[0, ["a", "a"]]
    with pytest.raises(InvalidValueError, match="2 names expected"):
        gain([[1.0, 2.0]], inputs=["a"])
    with pytest.raises(InvalidTypeError, match="name must be text"):
        gain(1.0, name=3)
    with pytest.raises(InvalidTypeError, match="name must be text"):
        tf("1/(s+1)", name=3)
    with pytest.raises(InvalidValueError, match="outputs: 1 names expected"):
        tf(tf("1/(s+1)"), outputs=["a", "b"])
