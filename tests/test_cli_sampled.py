"""`delaykit roots` and `delaykit margins` on sampled loops (--period), run as a user would (typer's runner).

References, none of which calls delaykit's sampled-loop module:

* the one-period transition matrix built here by hand: the plant (and a PI controller's integrator) propagated
  over the two parts of a period with SciPy's matrix exponential, the held commands shifted in the state;
  its eigenvalues are the loop's poles, and the gain or extra delay that brings its spectral radius to 1 gives
  the gain and delay margins (Brent's method);
* the closed form of the open loop for P control of an integrator, ``L(z) = Kp ((h - f) z + f) / (z^(m+1) (z - 1))``
  with ``T = m h + f`` (the command held for ``f`` seconds from m + 1 samples back, then from m samples back).
"""

from __future__ import annotations

import cmath
import json
import math

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq, linear_sum_assignment
from typer.testing import CliRunner

from delaykit.cli import app

runner = CliRunner()


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def hand_phi(A, B, C, kp, ki, h, delay, gain=1.0):
    """The one-period transition matrix of a sampled loop, built by hand.

    Plant ``x' = A x + B w``, ``y = C x`` (no feedthrough); controller ``v = -kp y + ki xi`` with ``xi' = -y`` running
    in continuous time (``ki = 0``: P control, no integrator state); ``u_k = gain v(t_k)`` held; the plant's input
    ``w`` is ``u_{k-m-1}`` for ``f`` seconds, then ``u_{k-m}``, with ``delay = m h + f``, ``0 < f < h``.
    State ``[x, xi, u_{k-1}, ..., u_{k-m-1}]``.
    """
    A, B, C = np.atleast_2d(A).astype(float), np.ravel(B).astype(float), np.ravel(C).astype(float)
    n = A.shape[0]
    ni = 1 if ki else 0
    m = int(math.floor(delay / h))
    f = delay - m * h
    assert 1e-9 < f < h - 1e-9
    nx = n + ni
    F = np.zeros((nx, nx))
    F[:n, :n] = A
    if ni:
        F[n, :n] = -C
    G = np.r_[B, np.zeros(ni)]

    def step(t):  # x(t) = E x(0) + J w for a constant input w over t
        M = np.zeros((nx + 1, nx + 1))
        M[:nx, :nx], M[:nx, nx] = F, G
        eM = expm(M * t)
        return eM[:nx, :nx], eM[:nx, nx]

    E1, J1 = step(f)
    E2, J2 = step(h - f)
    N = nx + m + 1
    phi = np.zeros((N, N))
    phi[:nx, :nx] = E2 @ E1
    phi[:nx, nx + m] = E2 @ J1           # u_{k-m-1}, the oldest held command, over [0, f)
    if m >= 1:
        phi[:nx, nx + m - 1] = J2        # u_{k-m} over [f, h)
    row = gain * np.r_[-kp * C, [ki] * ni]  # u_k from the state at t_k
    if m == 0:
        phi[:nx, :] += np.outer(J2, np.r_[row, np.zeros(m + 1)])
    phi[nx, :nx] = row                   # the new command enters the first held slot
    for i in range(1, m + 1):
        phi[nx + i, nx + i - 1] = 1.0
    return phi


def radius(phi):
    return float(np.max(np.abs(np.linalg.eigvals(phi))))


def same_nonzero(a, b, tol):
    """The nonzero eigenvalues of two sets agree one to one (the lifted states may differ by poles at 0)."""
    a, b = a[np.abs(a) > 1e-10], b[np.abs(b) > 1e-10]
    assert a.size == b.size
    cost = np.abs(a[:, None] - b[None, :])
    i, j = linear_sum_assignment(cost)
    assert cost[i, j].max() < tol


def poles(data):
    return np.array([complex(re, im) for re, im in data["poles"]])


# -- roots ----------------------------------------------------------------------------------------------------------
def test_roots_of_the_sampled_paper_loop_are_the_eigenvalues_of_the_hand_built_matrix():
    kp, td, h = 1.31, 0.368, 0.065  # T = 5 h + 0.043 s
    res = run("roots", "--kp", kp, "--delay", td, "--period", h, "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    phi = hand_phi([[0.0]], [1.0], [1.0], kp, 0.0, h, td)  # the integrator 1/s
    z = np.linalg.eigvals(phi)
    same_nonzero(poles(d), z, 1e-10)
    assert d["radius"] == pytest.approx(radius(phi), rel=1e-12) and d["stable"] is True and d["sampled"] is True
    # the equivalent continuous rate of the dominant pole
    assert d["abscissa"] == pytest.approx(math.log(radius(phi)) / h, rel=1e-10)
    # and the text form says the same
    res = run("roots", "--kp", kp, "--delay", td, "--period", h)
    assert res.exit_code == 0 and f"spectral radius {radius(phi):.6f}" in res.stdout and "stable" in res.stdout


@pytest.mark.parametrize("kp, ki, stable", [(1.5, 0.8, True), (15.0, 5.0, False)])
def test_roots_of_a_sampled_pi_loop_on_a_lag(kp, ki, stable):
    """PI on 1/(2 s + 1) with a 0.37 s delay, sampled every 0.1 s: the controller's integrator runs in continuous
    time on the continuous measurement; poles and verdict from the hand-built matrix."""
    h, td = 0.1, 0.37
    res = run("roots", "--plant", "1/(2*s+1)", "--controller", "pi", "--kp", kp, "--ki", ki, "--delay", td,
              "--period", h, "--vmax", "none", "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    phi = hand_phi([[-0.5]], [0.5], [1.0], kp, ki, h, td)
    same_nonzero(poles(d), np.linalg.eigvals(phi), 1e-9)
    assert d["stable"] is stable and (radius(phi) < 1) is stable
    assert d["radius"] == pytest.approx(radius(phi), rel=1e-10)


# -- margins --------------------------------------------------------------------------------------------------------
def test_margins_of_the_sampled_paper_loop_against_the_hand_built_matrix_and_the_closed_form():
    kp, td, h = 1.31, 0.368, 0.065
    res = run("margins", "--kp", kp, "--delay", td, "--period", h, "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    # the continuous JSON keys that a sampled loop has, and what says it is sampled
    assert {"gain_margin", "phase_margin", "delay_margin", "critical_delay", "crossover", "ms", "crossovers",
            "stable", "lower_gain_margin", "gain_margin_db", "phase_crossover", "stability_from"} <= set(d)
    assert d["sampled"] is True and d["period"] == h and d["stable"] is True
    integ = ([[0.0]], [1.0], [1.0])
    # gain margin: the factor at which the hand-built matrix's spectral radius reaches 1
    g = brentq(lambda g: radius(hand_phi(*integ, kp, 0.0, h, td, gain=g)) - 1.0, 1.0, 10.0, xtol=1e-12)
    assert d["gain_margin"] == pytest.approx(g, rel=1e-8)
    assert d["gain_margin_db"] == pytest.approx(20 * math.log10(g), rel=1e-8)
    assert d["lower_gain_margin"] == 0.0  # an integrator: lowering the gain never destabilises the loop
    # phase margin at the crossover, from the closed form of L
    m, f = 5, td - 5 * h

    def L(w):
        z = cmath.exp(1j * w * h)
        return kp * ((h - f) * z + f) / (z ** (m + 1) * (z - 1))

    wc = d["crossover"]
    assert abs(L(wc)) == pytest.approx(1.0, abs=1e-10)
    assert d["phase_margin"] == pytest.approx(math.degrees(cmath.phase(-L(wc))), abs=1e-8)
    assert 1 / abs(L(d["phase_crossover"])) == pytest.approx(d["gain_margin"], rel=1e-6)
    # delay margin: with that much extra delay the hand-built matrix reaches the unit circle
    dm = d["delay_margin"]
    assert radius(hand_phi(*integ, kp, 0.0, h, td + dm * (1 - 1e-6))) < 1 < radius(
        hand_phi(*integ, kp, 0.0, h, td + dm * (1 + 1e-6)))
    assert d["critical_delay"] == pytest.approx(td + dm, rel=1e-12)
    # the text form
    res = run("margins", "--kp", kp, "--delay", td, "--period", h)
    assert res.exit_code == 0 and "spectral radius" in res.stdout and f"{g:.6g}" in res.stdout


def test_margins_of_a_sampled_open_loop_unstable_plant_give_the_lower_gain_margin():
    """P control (Kp = 2) of 1/(s - 1), T = 0.12 s, h = 0.05 s: the pole at z = 1 appears when the loop gain is
    halved (g Kp P(0) = -1), and the hand-built matrix's radius crosses 1 there."""
    h, td = 0.05, 0.12
    res = run("margins", "--plant", "1/(s-1)", "--kp", 2, "--delay", td, "--period", h, "--vmax", "none", "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["stable"] is True and d["lower_gain_margin"] == pytest.approx(0.5, abs=1e-9)
    unstable = ([[1.0]], [1.0], [1.0])
    assert radius(hand_phi(*unstable, 2.0, 0.0, h, td, gain=0.499)) > 1 > radius(
        hand_phi(*unstable, 2.0, 0.0, h, td, gain=0.501))
    res = run("margins", "--plant", "1/(s-1)", "--kp", 2, "--delay", td, "--period", h, "--vmax", "none")
    assert res.exit_code == 0 and "lower gain margin" in res.stdout and "0.5 (" in res.stdout


def test_unstable_sampled_loop_has_no_margins():
    res = run("margins", "--kp", 5, "--delay", 0.37, "--period", 0.065, "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["stable"] is False and d["gain_margin"] is None and d["delay_margin"] is None
    assert radius(hand_phi([[0.0]], [1.0], [1.0], 5.0, 0.0, 0.065, 0.37)) > 1  # the hand-built matrix agrees
    res = run("margins", "--kp", 5, "--delay", 0.37, "--period", 0.065)
    assert res.exit_code == 0 and "UNSTABLE" in res.stdout


def test_sampled_plot_and_bad_input(tmp_path):
    png = tmp_path / "sampled.png"
    res = run("margins", "--kp", 1.31, "--delay", 0.368, "--period", 0.065, "--plot", png, "--wmin", 0.1)
    assert res.exit_code == 0, res.output
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000
    res = run("margins", "--kp", 1.31, "--delay", 0.368, "--period", 0.065, "--wmax", 100)
    assert res.exit_code == 2 and "--wmax 100" in res.output and "pi/h" in res.output
    res = run("roots", "--kp", 1.31, "--delay", 0.368, "--period", 0.065, "--plot", tmp_path / "r.png")
    assert res.exit_code == 0 and (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"  # the z-plane (test_zplot)
    res = run("roots", "--kp", 1.31, "--delay", "0.3,0.4", "--period", 0.065)
    assert res.exit_code == 2 and "one --delay" in res.output
