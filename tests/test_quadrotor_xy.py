"""The quadrotor's x-y position through a delayed attitude command (docs/tutorials/quadrotor-xy.md).

Each axis: tilt command -> attitude loop 1/(tau s + 1) -> acceleration g * tilt -> velocity -> position (the
hover linearisation of the quadrotor model the paper cites, Corke 2011, section 4.2), a position PD law
``c = Kp (r - x) - Kd v`` on the ground, the commands over a link with delay T, applied in a frame rotated by the
heading error psi.  Built with delaykit's ``interconnect`` by names; the references are independent of it:

* every delay 0: python-control's ``interconnect`` of the same blocks (its poles, its margins);
* with the delay: the rotation is normal, so the loop splits into two scalar ones with ``exp(+-i psi)``: the
  closed loop's frequency response and singular values in closed form with numpy, its poles as roots of
  ``s^2 (tau s + 1) + exp(+-i psi) g (Kp + Kd s) exp(-s T)``, and python-control on a Pade approximation of
  order 12 for the poles and the margins.
"""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

from delaykit import delay, feedback, hinfnorm, interconnect, is_stable, loop_margins, poles, ss, summing_junction, tf

G_ACC, TAU, PSI = 9.81, 0.15, math.radians(10.0)
ROT = np.array([[math.cos(PSI), math.sin(PSI)], [-math.sin(PSI), math.cos(PSI)]])


def _vehicle(T: float) -> list:
    return [delay(T, inputs="cx", outputs="cx_d", name="link x"), delay(T, inputs="cy", outputs="cy_d", name="link y"),
            ss([], [], [], ROT, inputs=["cx_d", "cy_d"], outputs=["ax", "ay"], name="heading error"),
            tf(f"1/({TAU}*s+1)", inputs="ax", outputs="tx"), tf(f"1/({TAU}*s+1)", inputs="ay", outputs="ty"),
            tf(f"{G_ACC}/s", inputs="tx", outputs="vx"), tf(f"{G_ACC}/s", inputs="ty", outputs="vy"),
            tf("1/s", inputs="vx", outputs="x"), tf("1/s", inputs="vy", outputs="y")]


def _pd(kp: float, kd: float, inputs: list[str]):
    return ss([], [], [], [[kp, 0, -kd, 0], [0, kp, 0, -kd]], inputs=inputs, outputs=["cx", "cy"], name="PD")


def closed_loop(T: float, kp: float, kd: float):
    blocks = _vehicle(T) + [_pd(kp, kd, ["ex", "ey", "vx", "vy"]), summing_junction(["x_ref", "-x"], "ex"),
                            summing_junction(["y_ref", "-y"], "ey")]
    return interconnect(blocks, inputs=["x_ref", "y_ref"], outputs=["x", "y"], name="quadrotor x-y")


def loop(T: float, kp: float, kd: float):
    """The loop broken at the tilt commands: L = [Kp, Kd] (x, v), so that the closed loop is feedback(L, 1)."""
    P = interconnect(_vehicle(T), inputs=["cx", "cy"], outputs=["x", "y", "vx", "vy"])
    return ss([], [], [], [[kp, 0, kd, 0], [0, kp, 0, kd]], inputs=["x", "y", "vx", "vy"],
              outputs=["cx", "cy"]) * P


def _control_closed_loop(kp: float, kd: float, pade: int | None = None, T: float = 0.0):
    """The same loop with python-control's interconnect (the delay as a Pade approximation when given)."""
    blocks = []
    for ax in "xy":
        if pade:
            num, den = control.pade(T, pade)
            blocks.append(control.tf(num, den, inputs=f"c{ax}", outputs=f"c{ax}_d"))
        else:
            blocks.append(control.tf([1], [1], inputs=f"c{ax}", outputs=f"c{ax}_d"))
        blocks += [control.tf([1], [TAU, 1], inputs=f"a{ax}", outputs=f"t{ax}"),
                   control.tf([G_ACC], [1, 0], inputs=f"t{ax}", outputs=f"v{ax}"),
                   control.tf([1], [1, 0], inputs=f"v{ax}", outputs=ax),
                   control.summing_junction([f"{ax}_ref", f"-{ax}"], f"e{ax}")]
    blocks.append(control.ss([], [], [], ROT, inputs=["cx_d", "cy_d"], outputs=["ax", "ay"]))
    blocks.append(control.ss([], [], [], [[kp, 0, -kd, 0], [0, kp, 0, -kd]], inputs=["ex", "ey", "vx", "vy"],
                             outputs=["cx", "cy"]))
    return control.interconnect(blocks, inputs=["x_ref", "y_ref"], outputs=["x", "y"])


def _closed_form(w: np.ndarray, T: float, kp: float, kd: float) -> np.ndarray:
    """T(jw) = (I + L0 Rot)^-1 L0 Rot Kp / (Kp + Kd s), L0 = g (Kp + Kd s) exp(-sT) / (s^2 (tau s + 1))."""
    s = 1j * np.asarray(w, float)
    L0 = G_ACC * (kp + kd * s) * np.exp(-s * T) / (s ** 2 * (TAU * s + 1))
    out = np.empty((2, 2, s.size), complex)
    for i in range(s.size):
        A = L0[i] * ROT
        out[:, :, i] = np.linalg.solve(np.eye(2) + A, A) * kp / (kp + kd * s[i])
    return out


def _in_box(p: np.ndarray, box) -> np.ndarray:
    x0, x1, y0, y1 = box
    return np.sort_complex(p[(p.real >= x0) & (p.real <= x1) & (p.imag >= y0) & (p.imag <= y1)])


BOX = (-4.0, 1.0, 0.0, 12.0)


def test_without_delay_it_is_python_controls_loop():
    Q = closed_loop(0.0, 0.2, 0.25)
    ref = _control_closed_loop(0.2, 0.25)
    sp = poles(Q, BOX)
    theirs = _in_box(np.asarray(control.poles(ref), complex), BOX)
    assert sp.certified and sp.roots.size == theirs.size
    assert np.abs(np.sort_complex(sp.roots) - theirs).max() < 1e-9
    w = np.logspace(-2, 2, 50)
    mine = Q.frequency_response(w).response
    assert np.abs(mine - ref.frequency_response(w).complex.reshape(2, 2, -1)).max() < 1e-10


def test_the_delayed_loop_matches_the_closed_form_and_its_poles_solve_the_scalar_loops():
    for T, kp, kd in ((0.1, 0.2, 0.25), (0.37, 0.03, 0.1)):
        Q = closed_loop(T, kp, kd)
        w = np.concatenate([np.logspace(-2, 2, 120), [0.7, 2.5]])
        assert np.abs(Q.frequency_response(w).response - _closed_form(w, T, kp, kd)).max() < 1e-10
        sp = poles(Q, BOX)
        assert sp.certified and sp.roots.size >= 3
        for r in sp.roots:  # each pole a root of one of the two scalar loops (the rotation's eigenvalues)
            res = [abs(r ** 2 * (TAU * r + 1) + np.exp(sgn * 1j * PSI) * G_ACC * (kp + kd * r) * np.exp(-r * T))
                   for sgn in (1, -1)]
            assert min(res) < 1e-9 * (1 + abs(r) ** 3)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")  # python-control evaluates the Pade-12 polynomials far out
def test_pade_poles_and_margins_agree_with_the_exact_ones():
    T, kp, kd = 0.37, 0.03, 0.1
    Q = closed_loop(T, kp, kd)
    sp = poles(Q, (-3.0, 1.0, 0.0, 5.0))
    theirs = _in_box(np.asarray(control.poles(_control_closed_loop(kp, kd, pade=12, T=T)), complex),
                     (-3.0, 1.0, 0.0, 5.0))
    assert sp.certified and sp.roots.size == theirs.size
    assert np.abs(np.sort_complex(sp.roots) - theirs).max() < 1e-8
    # loop-at-a-time: break channel 0 with channel 1 closed; python-control's margins of the Pade loop
    L = loop(T, kp, kd)
    m = loop_margins(L, 0)
    Lp = L.to_control(pade_order=12)
    L0 = control.feedback(Lp, control.ss([], [], [], [[0, 0], [0, 1]]))[0, 0]
    gm, pm, wcg, wcp = control.margin(L0)
    assert abs(m.gain_margin - gm) < 1e-6 * gm and abs(m.phase_margin - pm) < 1e-6
    assert abs(m.gain_crossover - wcp) < 1e-6 and abs(m.phase_crossover - wcg) < 1e-6


def test_the_link_delay_of_the_paper_destabilises_the_fast_design():
    from scipy.optimize import brentq

    # the PD tuned for a 0.1 s link: its loop-at-a-time delay margin is 0.254 s, so the paper's 0.37 s is past it
    m = loop_margins(loop(0.1, 0.2, 0.25), 0)
    assert 0.1 + m.delay_margin < 0.37
    assert is_stable(closed_loop(0.1, 0.2, 0.25)) and not is_stable(closed_loop(0.37, 0.2, 0.25))
    # the link delays both axes at once: L = l0 Rot, whose eigen-loops l0 e^{+-i psi} cross |.| = 1 at one w_c with
    # phase margins pi + arg l0 +- psi; the common delay margin is the smaller over w_c (closed form, brentq)
    kp, kd = 0.2, 0.25
    l0 = lambda w: G_ACC * (kp + kd * 1j * w) * np.exp(-0.1j * w) / ((1j * w) ** 2 * (TAU * 1j * w + 1))  # noqa: E731
    wc = brentq(lambda w: abs(l0(w)) - 1.0, 0.1, 20.0, xtol=1e-14)
    pm = min((math.pi + np.angle(l0(wc)) + sgn * PSI) % (2 * math.pi) for sgn in (1, -1))
    common = pm / wc
    assert common < m.delay_margin - 0.05       # smaller than the loop-at-a-time margin
    assert is_stable(closed_loop(0.1 + common - 1e-4, kp, kd))
    assert not is_stable(closed_loop(0.1 + common + 1e-4, kp, kd))


def test_hinfnorm_of_the_sensitivity_is_the_closed_form_peak():
    from scipy.optimize import minimize_scalar

    T, kp, kd = 0.37, 0.03, 0.1
    S = feedback(np.eye(2), loop(T, kp, kd))  # (I + L)^-1: from an output disturbance on the commands
    val, where = hinfnorm(S)
    # (I + L)^-1 with L = [Kp, Kd] P: L = l0(s) Rot with l0 = g (Kp + Kd s) e^{-sT} / (s^2 (tau s + 1)), a normal
    # matrix: its singular values are 1 / |1 + l0 e^{+-i psi}|; the peak by a dense grid and a bounded search
    def smax(w: float) -> float:
        s = 1j * w
        l0 = G_ACC * (kp + kd * s) * np.exp(-s * T) / (s ** 2 * (TAU * s + 1))
        return max(1 / abs(1 + l0 * np.exp(1j * PSI)), 1 / abs(1 + l0 * np.exp(-1j * PSI)))

    grid = np.linspace(0.01, 20, 200_001)
    i = int(np.argmax([smax(w) for w in grid]))
    res = minimize_scalar(lambda w: -smax(w), bounds=(grid[i - 1], grid[i + 1]), method="bounded",
                          options={"xatol": 1e-12})
    assert abs(val - (-res.fun)) < 1e-8 * val and abs(where - res.x) < 1e-5


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_step_responses_match_python_control():
    t = np.linspace(0.0, 15.0, 301)
    # every delay 0: python-control's step response of the same interconnection (its exact discretisation of an
    # LTI system: expm), to 1e-8
    mine = closed_loop(0.0, 0.2, 0.25).step(t)
    ref = control.step_response(_control_closed_loop(0.2, 0.25), T=t)
    assert mine.status == "exact" and np.abs(mine.outputs - ref.outputs).max() < 1e-8
    # the paper's delay: python-control with each link delay as its Pade approximation (control.pade; past order 8
    # its polynomial coefficients lose the digits): the difference falls with the order, to under 1e-5 at 8
    mine = closed_loop(0.37, 0.03, 0.1).step(t)
    assert mine.status == "exact"
    err = [float(np.abs(mine.outputs - control.step_response(_control_closed_loop(0.03, 0.1, pade=n, T=0.37),
                                                              T=t).outputs).max()) for n in (3, 6, 8)]
    assert err[0] > err[1] > err[2] and err[2] < 1e-5
    assert mine.outputs[0, 0, :int(0.37 / 0.05)].max() == 0.0          # nothing moves before the delay
    assert abs(mine.outputs[0, 0, -1] - 1) < 5e-3 and abs(mine.outputs[1, 0, -1]) < 5e-3
