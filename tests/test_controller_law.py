"""A controller's law is defined once (:func:`delaykit.models.controllers.controller_branches`); its derived forms
agree: the realisation's transfer functions, the feedback polynomials, the law as the module docstring writes it,
and the gains evaluated at arrays (what ``simulate_many`` writes into its rows).

References are independent of the code under test: the closed forms of the laws (``kp + ki/s + kd s/(Tf s + 1)``
and so on, from the module docstring of :mod:`delaykit.models.controllers`) evaluated at complex ``s``, and
``(sI - A)^-1`` by a dense linear solve.
"""

from __future__ import annotations

import numpy as np
import pytest

from delaykit import Controller, Loop, simulate, simulate_many
from delaykit.models.controllers import controller_branches, feedback_response, feedback_transfer, parallel

RNG = np.random.default_rng(21)
S = np.concatenate([1j * np.logspace(-2, 2, 7), RNG.normal(size=5) + 1j * RNG.normal(size=5) * 3])

CONTROLLERS = [
    Controller.p(1.31),
    Controller.pv(2.0, 0.3),
    Controller.pv(1.2, 0.4, velocity="filtered"),
    Controller.pv(1.2, 0.4, velocity="filtered", filter_wn=12.3, filter_zeta=0.7),
    Controller.pi(0.95, 0.1),
    Controller.pi(0.95, 0.1, antiwindup="clamp"),
    Controller.pi(0.95, 0.1, antiwindup="backcalc", setpoint_weight=0.4),
    Controller.pd(2.0, 0.1, 0.02),
    Controller.pd(1.0, 1.0, 1e-4),
    Controller.pid(2.0, 0.5, 0.1, 0.02),
    Controller.pid(2.0, 0.5, 0.1, 0.02, antiwindup="backcalc", setpoint_weight=0.5, derivative_weight=0.3),
    Controller.pid(-2.0, -0.5, -0.1, 0.02, antiwindup="clamp"),
    Controller.transfer("2*(s+1)/(0.1*s+1)"),
    Controller.transfer("(3*s^2+s+2)/(s^2+0.5*s)"),
]


def closed_form(c: Controller, s: complex) -> tuple[complex, complex]:
    """``(Cr(s), Cy(s))`` of the law ``v = Cr r - Cy ym`` (the velocity read as ``s ym``), written from the module
    docstring of :mod:`delaykit.models.controllers`, not from the code."""
    if c.kind == "tf":
        g = np.polyval(c.transfer_function.num, s) / np.polyval(c.transfer_function.den, s)
        return g, g
    b, cw = c.setpoint_weight, c.derivative_weight
    if c.kind == "p":
        return c.kp, c.kp
    if c.kind == "pv":
        w, z = c.filter_wn, c.filter_zeta
        f = w * w * s / (s * s + 2 * z * w * s + w * w) if c.velocity == "filtered" else s
        return c.kp, c.kp + c.kv * f
    d = s / (c.derivative_filter * s + 1)
    i = c.ki / s if c.has_integrator else 0.0
    kd = c.kd if c.kind in ("pd", "pid") else 0.0
    return b * c.kp + i + cw * kd * d, c.kp + i + kd * d


def realised(r, s: complex) -> tuple[complex, complex]:
    """``(Cr, Cy)`` of a realisation by a dense solve of ``(sI - Ac) x = B``."""
    n = r.order
    R = np.linalg.solve(s * np.eye(n) - r.Ac, np.column_stack([r.Bcr, r.Bcy, r.Bcv])) if n else np.zeros((0, 3))
    cr = r.dvr + r.Cc @ R[:, 0]
    cy = -(r.dvy + r.Cc @ R[:, 1]) - s * (r.dvv + r.Cc @ R[:, 2])
    return complex(cr), complex(cy)


@pytest.mark.parametrize("c", CONTROLLERS, ids=repr)
def test_realisation_and_polynomials_are_the_law(c):
    num, den = c.feedback_polynomials()
    for s in S:
        cr, cy = closed_form(c, s)
        r = c.realisation()
        rr, ry = realised(r, s)
        poly = np.polyval(num, s) / np.polyval(den, s)
        # the realisation's feedthrough -kp - kd/Tf cancels against the filter's state at low frequencies: its
        # rounding is relative to that term's size
        tol = 1e-13 * (1.0 + abs(cy) + abs(r.dvy) + abs(r.dvr))
        assert abs(rr - cr) <= tol * max(1.0, abs(cr))
        assert abs(ry - cy) <= tol
        assert abs(poly - cy) <= 1e-13 * max(1.0, abs(cy))


@pytest.mark.parametrize("c", CONTROLLERS, ids=repr)
def test_the_realisation_is_the_parallel_sum_of_the_branches(c):
    branches = controller_branches(c)
    assert sum(b.order for b in branches) == c.realisation().order
    for s in S[:4]:
        total = np.sum([realised(b, s) for b in branches], axis=0)
        assert np.allclose(total, realised(c.realisation(), s), rtol=1e-13, atol=1e-13)
    if c.kind != "tf":  # the polynomials are the sum of the branches' feedback parts
        parts = [feedback_transfer(b) for b in branches]
        num, den = c.feedback_polynomials()
        for s in S[:4]:
            want = sum(np.polyval(n, s) / np.polyval(d, s) for n, d in parts)
            assert abs(np.polyval(num, s) / np.polyval(den, s) - want) <= 1e-13 * abs(want)


def test_the_paper_laws_polynomials_are_exactly_the_coefficients():
    # P and PV (true and filtered): the paper's laws, kp + kv s and kp + kv wf^2 s / (s^2 + 2 zf wf s + wf^2),
    # multiplied out by hand
    assert [p.tolist() for p in Controller.p(1.31).feedback_polynomials()] == [[1.31], [1.0]]
    assert [p.tolist() for p in Controller.pv(2.0, 0.3).feedback_polynomials()] == [[0.3, 2.0], [1.0]]
    w, z, kp, kv = 38.0, 1.0, 1.2, 0.4
    num, den = Controller.pv(kp, kv, velocity="filtered").feedback_polynomials()
    assert den.tolist() == [1.0, 2 * z * w, w * w]
    assert num.tolist() == [kp, kp * 2 * z * w + kv * w * w, kp * w * w]
    assert [p.tolist() for p in Controller.pi(0.95, 0.1).feedback_polynomials()] == [[0.95, 0.1], [1.0, 0.0]]


@pytest.mark.parametrize("c", [c for c in CONTROLLERS if c.kind != "tf"], ids=repr)
def test_gains_at_arrays_equal_each_controller_built_alone(c):
    # what simulate_many writes into its rows: the branches at arrays of gains, entry by entry the realisation of
    # the controller built with those gains
    m = 4
    scale = np.array([0.5, 1.0, 1.7, 3.0])
    gains = {g: getattr(c, g) * scale for g in ("kp", "ki", "kd", "kv")}
    many = parallel(controller_branches(c, **gains))
    for i in range(m):
        one = c.replace(**{g: float(v[i]) for g, v in gains.items() if v[i] != 0 or g == "kp"}).realisation()
        assert np.array_equal(np.broadcast_to(many.Cc, (m, one.order))[i], one.Cc)
        assert np.array_equal(np.broadcast_to(many.Baw, (m, one.order))[i], one.Baw)
        for name in ("dvr", "dvy", "dvv"):
            assert np.broadcast_to(getattr(many, name), (m,))[i] == getattr(one, name)
        for name in ("Ac", "Bcr", "Bcy", "Bcv"):  # the structure does not depend on the gains
            assert np.array_equal(getattr(many, name), getattr(one, name))


@pytest.mark.parametrize("c", [Controller.pi(1.0, 0.5, setpoint_weight=0.4),
                               Controller.pid(1.0, 0.5, 0.2, 0.05, setpoint_weight=0.5, derivative_weight=0.5)],
                         ids=repr)
def test_simulate_many_keeps_the_setpoint_weights(c):
    # simulate_many wrote dvr = kp whatever the weights b and c (the 2-DOF law's reference gain is b kp + c kd/Tf):
    # each swept loop must equal simulate() of that loop built alone
    lp = Loop("1/(s+1)", c, delay=0.3)
    kps = np.array([0.8, 1.2])
    kds = np.array([0.1, 0.3]) if c.kind == "pid" else None
    m = simulate_many(lp, kp=kps, **({"kd": kds} if kds is not None else {}))
    for i, k in enumerate(kps):
        one = c.replace(kp=float(k), **({"kd": float(kds[i])} if kds is not None else {}))
        ref = simulate(lp.replace(controller=one), t_end=15.0).metrics
        assert abs(m.rise_time[i] - ref.rise_time) < 1e-9
        assert abs(m.overshoot[i] - ref.overshoot) < 1e-9
        assert abs(m.settling_time[i] - ref.settling_time) < 1e-9


def test_the_law_is_built_once_per_controller_and_cannot_be_changed_through_it():
    c = Controller.pid(2.0, 0.5, 0.1, 0.02)
    r = c.realisation()
    assert c.realisation() is r
    with pytest.raises(ValueError):
        r.Cc[0] = 1.0  # read-only: a caller cannot change the controller's law behind its back
    num, _ = c.feedback_polynomials()
    num[0] = 99.0  # the polynomials are copies
    assert c.feedback_polynomials()[0][0] != 99.0
    assert c.replace(kp=3.0).realisation().dvy == -3.0 - 0.1 / 0.02  # a changed controller has its own law


@pytest.mark.parametrize("c", CONTROLLERS, ids=repr)
def test_the_feedback_response_is_the_law(c):
    # Cy(s) from the branches against the closed form written from the module docstring
    ref = np.array([closed_form(c, s)[1] for s in S])
    np.testing.assert_allclose(feedback_response(c, S), ref, rtol=1e-12, atol=1e-12)
    if c.kind != "tf":  # at arrays of gains: row i is the controller built with gains i
        scale = np.array([0.5, 1.0, 1.7])
        gains = {g: getattr(c, g) * scale for g in ("kp", "ki", "kd", "kv")}
        many = feedback_response(c, S, **gains)
        assert many.shape == (3, S.size)
        for i in range(3):
            one = c.replace(**{g: float(v[i]) for g, v in gains.items() if v[i] != 0 or g == "kp"})
            np.testing.assert_allclose(many[i], [closed_form(one, s)[1] for s in S], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("kind", ["p", "pv", "pi", "pd", "pid"])
def test_the_tuners_controller_response_is_the_law(kind):
    # design.pid_optimise.controller_response evaluates the one law; the reference is its docstring's closed form
    from delaykit.design.pid_optimise import controller_response

    kp, ki, kd, tf = np.array([1.0, 2.5]), np.array([0.5, 0.2]), np.array([0.2, 0.05]), 0.02
    got = controller_response(kind, kp, ki, kd, tf, S)
    kp, ki, kd = kp[:, None], ki[:, None], kd[:, None]
    ref = kp + kd * S if kind == "pv" else (kp + 0.0 * S + (ki / S if "i" in kind else 0.0)
                                             + (kd * S / (tf * S + 1.0) if "d" in kind else 0.0))
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=0)
