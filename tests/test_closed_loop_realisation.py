"""The loop's closed-loop realisation (:func:`delaykit.models.closed_loop.loop_realisation`, the one every simulator
and the sampled spectrum build from) is the loop :func:`delaykit.systems.from_loop` builds independently, block by
block, with :func:`~delaykit.systems.interconnect`: the same transfer functions at random complex ``s`` and the
same poles, for every controller kind; and the sampled model built from it has the poles of the loop discretised
independently (:func:`delaykit.systems.c2d` of the open loop, exact with fractional delays, closed by hand).
"""

from __future__ import annotations

import numpy as np
import pytest

from delaykit import Compensator, Controller, Loop
from delaykit.models.closed_loop import loop_realisation
from delaykit.simulate._layout import loop_matrices
from delaykit.spectrum.roots import find_roots
from delaykit.spectrum.sampled import sampled_model
from delaykit.systems import c2d, delay, from_loop, interconnect, ss, tf

RNG = np.random.default_rng(2021)
S = RNG.normal(size=6) * 2 + 1j * RNG.normal(size=6) * 4

LAWS = [
    Controller.p(1.31),
    Controller.pv(2.0, 0.3),
    Controller.pv(1.2, 0.4, velocity="filtered"),
    Controller.pi(0.95, 0.3),
    Controller.pi(0.95, 0.3, antiwindup="backcalc", setpoint_weight=0.4),
    Controller.pd(2.0, 0.1, 0.02),
    Controller.pid(2.0, 0.5, 0.1, 0.02, setpoint_weight=0.5, derivative_weight=0.3),
    Controller.transfer("2*(s+1)/(0.1*s+1)"),
]
PLANT = "1.5/((s+1)*(0.5*s+1))"
COMPENSATED = [
    Loop("1/s", Compensator.smith("1/s", 0.37, closed_loop_time=0.2), delay=0.37),
    Loop("2/(5*s+1)", Compensator.smith("2/(5*s+1)", 0.8), delay=0.6, output_delay=0.2),
    Loop("1/s", Compensator.filtered_smith("1/s", 0.4), delay=0.4),
    Loop("1/s", Compensator.predictor("1/s", 0.37, closed_loop_time=0.3), delay=0.37),
]
LOOPS = [Loop(PLANT, c, delay=0.3, output_delay=0.1) for c in LAWS] + COMPENSATED


def realised(lr, lp: Loop, s: complex) -> np.ndarray:
    """``[[y/r, y/d], [u/r, u/d]]`` at ``s`` from the realisation's equations (the module docstring of
    :mod:`delaykit.models.closed_loop`), solved for ``(X, u)`` with the delays as exponentials (no limits)."""
    n = lr.order
    ei, eo, em = (np.exp(-s * t) for t in (lp.delay, lp.output_delay, lr.model_delay))
    ky = eo * (lr.dvy * lr.dy + lr.dvv * lr.dyd)  # the law's dependence on w through the measurement
    K = np.zeros((n + 1, n + 1), complex)
    K[:n, :n] = s * np.eye(n) - lr.M - eo * (np.outer(lr.bym, lr.cy) + np.outer(lr.bvm, lr.cyd))
    bw = lr.bw + eo * (lr.bym * lr.dy + lr.bvm * lr.dyd)  # everything the plant's input w reaches in X'
    K[:n, n] = -(bw * ei + lr.bu + lr.bum * em)
    K[n, :n] = -(lr.cv + eo * (lr.dvy * lr.cy + lr.dvv * lr.cyd))
    K[n, n] = 1.0 - ky * ei
    rhs = np.zeros((n + 1, 2), complex)
    rhs[:n, 0], rhs[n, 0] = lr.br, lr.dvr
    rhs[:n, 1], rhs[n, 1] = bw, ky
    sol = np.linalg.solve(K, rhs)
    X, u = sol[:n], sol[n]
    y = lr.cy @ X + lr.dy * (ei * u + np.array([0.0, 1.0]))
    return np.array([y, u])


@pytest.mark.parametrize("lp", LOOPS, ids=repr)
def test_the_realisation_is_from_loops_closed_loop(lp):
    lr = loop_realisation(lp)
    T = from_loop(lp, ignore_limits=True)
    assert T.inputs == ("r", "d") and T.outputs == ("y", "u")
    H = T.evaluate(S)
    for i, s in enumerate(S):
        mine = realised(lr, lp, s)
        ref = H[..., i]
        assert np.allclose(mine, ref, rtol=1e-10, atol=1e-12 * np.max(np.abs(ref))), (s, mine, ref)


@pytest.mark.parametrize("lp", LOOPS, ids=repr)
def test_the_realisation_has_the_loops_poles(lp):
    # the rightmost roots of the loop's characteristic function (certified root search on the quasi-polynomial of
    # feedback_polynomials / compensated_polynomials) make the realisation's equations singular
    lr = loop_realisation(lp)
    res = find_roots(lp.characteristic(), (-8.0, 2.0, 0.0, 30.0))
    roots = [z for z in res.roots if abs(z) > 1e-6]  # a compensator's structural root at 0 is divided out
    assert roots
    n = lr.order
    for z in roots:
        ei, eo, em = (np.exp(-z * t) for t in (lp.delay, lp.output_delay, lr.model_delay))
        K = np.zeros((n + 1, n + 1), complex)
        K[:n, :n] = z * np.eye(n) - lr.M - eo * (np.outer(lr.bym, lr.cy) + np.outer(lr.bvm, lr.cyd))
        K[:n, n] = -((lr.bw + eo * (lr.bym * lr.dy + lr.bvm * lr.dyd)) * ei + lr.bu + lr.bum * em)
        K[n, :n] = -(lr.cv + eo * (lr.dvy * lr.cy + lr.dvv * lr.cyd))
        K[n, n] = 1.0 - eo * (lr.dvy * lr.dy + lr.dvv * lr.dyd) * ei
        sv = np.linalg.svd(K, compute_uv=False)
        assert sv[-1] <= 1e-8 * sv[0], (z, sv)


@pytest.mark.parametrize("c", LAWS + [Compensator.smith(PLANT, 0.3, primary=Controller.pi(0.5, 0.4))],
                         ids=repr)
def test_without_delays_the_poles_are_from_loops(c):
    # no delay at all: the realisation closed (u = v = k X / (1 - kw) with w = u) is a matrix whose eigenvalues are
    # the poles of from_loop's system (all its delays 0, closed by interconnect's algebra)
    tm = 0.0 if isinstance(c, Compensator) else None
    if tm is not None:
        c = c.replace(model_delay=0.0)
    lp = Loop(PLANT, c)
    lr = loop_realisation(lp)
    f = lr.folded()
    acl = f.A + np.outer(f.b + f.bu + f.bum, f.k) / (1.0 - f.kw)
    mine = np.sort_complex(np.linalg.eigvals(acl))
    T = from_loop(lp, ignore_limits=True)
    ref = np.sort_complex(np.linalg.eigvals(T.A + T.B2 @ np.linalg.solve(np.eye(T.ndelays) - T.D22, T.C2))
                          if T.ndelays else np.linalg.eigvals(T.A))
    assert mine.size == ref.size
    assert np.allclose(mine, ref, rtol=1e-9, atol=1e-9)


def test_the_simulators_rows_are_the_realisation():
    lp = LOOPS[6]
    lay, lr = loop_matrices(lp), loop_realisation(lp)
    for name in lr.__dataclass_fields__:
        assert np.array_equal(getattr(lay, name), getattr(lr, name)), name


def _open_sampled(lp: Loop):
    """The loop opened at the held command, built independently with the systems' blocks: inputs ``u`` (held)
    and ``r``, output the law's ``v``; the plant reads ``u`` after the total delay (the output delay moved to the
    input), the controller (its realisation, on ``r``, the output and its velocity, and for a compensator the held
    command and the command one model delay earlier) reads the output without delay."""
    r = lp.controller.realisation()
    k = r.order
    cols, ins, dv = [r.Bcr, r.Bcy, r.Bcv], ["r", "y", "ydot"], [r.dvr, r.dvy, r.dvv]
    blocks = [delay(lp.delay + lp.output_delay, inputs="u", outputs="ud")]
    if r.reads_command:
        cols, ins, dv = cols + [r.Bcu, r.Bcm], ins + ["u", "um"], dv + [0.0, 0.0]
        blocks.append(delay(r.model_delay, inputs="u", outputs="um"))
    B = np.column_stack(cols) if k else np.zeros((0, len(ins)))
    blocks.append(ss(r.Ac, B, np.asarray(r.Cc, float).reshape(1, k), [dv], inputs=ins, outputs="v"))
    A, Bp, Cp, Dp = lp.plant.state_space()
    n = A.shape[0]
    Bp, Cp = Bp.reshape(n, 1), Cp.reshape(1, n)
    blocks.append(ss(A, Bp, np.vstack([Cp, Cp @ A]), [[Dp], [float((Cp @ Bp)[0, 0])]], inputs="ud",
                     outputs=["y", "ydot"]))
    return interconnect(blocks, inputs=["u", "r"], outputs=["v"])


@pytest.mark.parametrize("lp", [Loop(PLANT, c, delay=0.23, output_delay=0.04, period=0.05) for c in LAWS]
                         + [lp.replace(period=0.1) for lp in COMPENSATED], ids=repr)
def test_the_sampled_model_has_the_poles_of_the_discretised_loop(lp):
    # c2d holds u over each period (exact, fractional delays included); the command is the law's output sampled,
    # u_k = v(t_k) (no direct feedthrough from u_k: every delay here is positive and the plants strictly proper)
    G = c2d(_open_sampled(lp), lp.period)
    assert np.all(G.D[:, 0] == 0)
    ref = np.linalg.eigvals(G.A + np.outer(G.B[:, 0], G.C[0]))
    mdl = sampled_model(lp)
    mine = mdl.poles()
    # the shift registers' poles at 0 differ in number, and a multiple pole at 0 is computed only to about
    # eps^(1/multiplicity) (0.01 for 8 held commands): the poles away from 0 are compared
    left = list(ref[np.abs(ref) > 0.05])
    for z in mine[np.abs(mine) > 0.05]:
        i = int(np.argmin(np.abs(np.array(left) - z)))
        assert abs(left[i] - z) <= 1e-7 * max(1.0, abs(z)), (z, left)
        left.pop(i)
    # what remains are a compensator's structural eigenvalues at 1 (fixed window integrals), which poles() omits
    assert len(left) == mdl.structural
    assert np.allclose(left, 1.0, atol=1e-6)


# -- the measurement folded in, written once (models/_foldkernel.py) -------------------------------------------------
# Before, LoopRealisation.folded() (numpy) and the two simulator kernels' set-up blocks (loops over a parameter row)
# each wrote this algebra; now all three call fold_into.  The kernels' work arrays are read after a short run: the
# Taylor kernel's known-input A and G's w column (mats[2], mats[3, 0]; the law's row in mats[3, 6]) and the sampled
# batch's event map (Z0: A in its first N columns, b in column N; k and kw in vec[1]).
# a plant with a direct feedthrough (dy != 0) but under the PV law with the true velocity, which needs dy = 0
FOLD_LOOPS = [Loop(PLANT if c.uses_velocity and not c.filtered else "(s+3)/(s+1)", c, delay=0.2) for c in LAWS] + [
    Loop("2/(s+1)", Controller.pv(1.0, 0.3), delay=0.3),
    Loop(PLANT, Compensator.smith(PLANT, 0.3, primary=Controller.pi(0.5, 0.4)), delay=0.3),
]


def _numpy_fold(lr):
    """The fold as folded() wrote it before (numpy's outer products): an independent spelling of the algebra."""
    return (lr.M + np.outer(lr.bym, lr.cy) + np.outer(lr.bvm, lr.cyd), lr.bw + lr.bym * lr.dy + lr.bvm * lr.dyd,
            lr.cv + lr.dvy * lr.cy + lr.dvv * lr.cyd, lr.dvy * lr.dy + lr.dvv * lr.dyd)


@pytest.mark.parametrize("lp", FOLD_LOOPS, ids=repr)
def test_folded_is_the_substitution_of_the_measurement(lp):
    lr = loop_realisation(lp)
    f = lr.folded()
    A, b, k, kw = _numpy_fold(lr)
    # numpy sums each entry in the same order: equal to the last bit
    np.testing.assert_array_equal(f.A, A)
    np.testing.assert_array_equal(f.b, b)
    np.testing.assert_array_equal(f.k, k)
    assert f.kw == kw


def test_folded_by_hand():
    # (s + 3)/(s + 1) = 1 + 2/(s + 1): x' = -x + w and y = 2x + w (dy = 1; the PI law reads no velocity).
    # PI (kp, ki) with xi' = r - ym, v = kp r - kp ym + ki xi.  Substituting ym = y = 2x + w:
    #   x'  = -x + w,   xi' = -2x - w + r,   v = -2 kp x + ki xi - kp w + kp r
    kp, ki = 1.5, 0.4
    f = loop_realisation(Loop("(s+3)/(s+1)", Controller.pi(kp, ki))).folded()
    np.testing.assert_allclose(f.A, [[-1.0, 0.0], [-2.0, 0.0]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(f.b, [1.0, -1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(f.k, [-2.0 * kp, ki], rtol=0, atol=1e-15)
    assert f.kw == pytest.approx(-kp, abs=1e-15) and f.dvr == kp
    # 2/(s + 1) under a PV law with the true velocity: y = 2x, y' = -2x + 2w, v = r - y - 0.3 y' = r - 1.4 x - 0.6 w
    g = loop_realisation(Loop("2/(s+1)", Controller.pv(1.0, 0.3))).folded()
    np.testing.assert_allclose(g.k, [-1.4], rtol=0, atol=1e-15)
    assert g.kw == pytest.approx(-0.6, abs=1e-15) and g.A.tolist() == [[-1.0]] and g.b.tolist() == [1.0]


def _captured(mod, name, call):
    """The arguments (by name) of the last call of ``mod.name`` while ``call()`` runs (``mod`` run by Python)."""
    import inspect

    real = getattr(mod, name)
    seen = {}

    def spy(*args):
        seen.update(inspect.signature(real).bind(*args).arguments)
        return real(*args)

    setattr(mod, name, spy)
    try:
        call()
    finally:
        setattr(mod, name, real)
    return seen


@pytest.mark.parametrize("lp", FOLD_LOOPS, ids=repr)
def test_the_taylor_kernels_fold_is_folded(lp):
    from delaykit import _native
    from test_kernel_modes import run

    py = _native.load("delaykit.simulate", "_kernel", "python")
    args = _captured(py, "_run", lambda: run(py, lp, None, 0.5))
    lr = loop_matrices(lp)
    f, n = lr.folded(), lr.order
    modes = {"python": args["mats"]}
    if _native.built("delaykit.simulate", "_kernel"):  # the extension, on the same arguments
        cy = _native.load("delaykit.simulate", "_kernel", "cython")
        again = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in args.items()}
        again["mats"] = np.full_like(args["mats"], np.nan)
        cy._run(*again.values())
        modes["cython"] = again["mats"]
    for mode, mats in modes.items():
        np.testing.assert_array_equal(mats[2, :n, :n], f.A, err_msg=mode)
        np.testing.assert_array_equal(mats[3, 0, :n], f.b, err_msg=mode)
        np.testing.assert_array_equal(mats[3, 6, :n], f.k, err_msg=mode)


@pytest.mark.parametrize("lp", FOLD_LOOPS[:4] + FOLD_LOOPS[5:9], ids=repr)
def test_the_sampled_batchs_fold_is_folded(lp):
    from delaykit import _native
    from delaykit.simulate.simulation import _event_stepped, param_row

    lp = lp.replace(period=0.05)
    lr = loop_matrices(lp)
    row = param_row(lp, lr, step=1.0, slope=0.0, norm=1.0, t_end=0.5, band=0.02, dist=None)[None, :]
    assert _event_stepped(row).all()
    f, n = lr.folded(), lr.order
    found = []
    for mode in ("python", "cython") if _native.built("delaykit.simulate", "_sampled_batch") else ("python",):
        sb = _native.load("delaykit.simulate", "_sampled_batch", mode)
        if mode == "python":
            args = _captured(sb, "run_one", lambda: sb.run_batch(row, 1, 1))
        else:
            args = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in args.items()}
            args["Z0"], args["vec"] = np.full_like(args["Z0"], np.nan), np.full_like(args["vec"], np.nan)
            sb.run_one(*args.values())
        Z0, k0 = args["Z0"], args["vec"][1]
        found.append(mode)
        np.testing.assert_array_equal(Z0[:n, :n], f.A, err_msg=mode)
        np.testing.assert_array_equal(Z0[:n, n], f.b, err_msg=mode)
        np.testing.assert_array_equal(k0[:n], f.k, err_msg=mode)
        assert k0[n] == f.kw, mode
    assert found


def test_the_rows_matrices_are_packed_as_the_fold_reads_them():
    # the kernels hand fold_into their parameter row from OFF_M: M (MAXN x MAXN), then MAXN numbers per vector
    from delaykit.models._foldkernel import PACKED
    from delaykit.simulate import _layout as K

    assert PACKED == tuple(name for name in loop_realisation(LOOPS[0]).__dataclass_fields__ if name in PACKED)
    for j, name in enumerate(PACKED):
        assert getattr(K, "OFF_" + name.upper()) == K.OFF_M + K.MAXN * K.MAXN + j * K.MAXN, name
