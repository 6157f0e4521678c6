"""The simulator kernel's shortcuts, each against the general computation it stands in for.

* A single-state loop's Taylor recursion (``_taylor._known_one``, the paper's integrator) runs apart from the
  general N-state loop of ``recursion_known``: here the same state is embedded in a two-state system whose
  second state is inert, which takes the general loop, and every coefficient must come out identical.
* The batch kernel (``run_batch``) reuses its work arrays from row to row, where ``run_one`` allocates fresh
  ones: rows of different loops (1 to 4 states, saturated, sliding on a limit, sampled) in one batch must give
  exactly what each gives alone.
* The peak search skips the derivative's root search where the derivative's bounds keep one sign: the peak
  found on a piece must still be the piece's maximum, as a dense evaluation of the polynomial finds it.
* One metric update (``_kernel._metrics_update``) serves the kernel (roots on a grid) and the sampled batch
  (certified roots, ``_sampled_batch._poly_metrics``): on one piece both must find what a dense evaluation finds.
* The two Taylor recursions share their output block: on a piece both can run (the plant's input delayed, the
  measurement delayed too), the known-input one and the general one must give the same coefficients.
"""

from __future__ import annotations

import numpy as np
import pytest

from delaykit import AltitudeLoop
from delaykit.models import Controller, Loop
from delaykit import _native
from delaykit.simulate import _jit, _layout
from delaykit.simulate._layout import NC, NOUT, HEAD, loop_matrices, param_row
from delaykit.simulate.simulation import as_loop

_T = _native.load("delaykit.simulate", "_taylor")  # compiled (by Cython, or numba without the extension)
_K = _jit.kernel(compiled=True)
_KI = _jit.kernel(compiled=False)  # the same source run as plain Python


def _recur(N, A, G, VE, H, frozen, integ, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, x0, zero_a):
    X = np.zeros((_layout.MAXN, NC + 1))
    X[0, 0] = x0
    Y, Yd, V, E = np.zeros(NC), np.zeros(NC), np.zeros(NC), np.zeros(NC)
    nt = _T.recursion_known(A, G, VE, N, H, frozen, integ, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, X, Y,
                            Yd, V, E, zero_a, False, 0.0, np.zeros(NC), NC)
    return nt, X, Y, Yd, V, E


@pytest.mark.parametrize("seed", range(12))
def test_single_state_recursion_equals_the_general_loop(seed):
    rng = np.random.default_rng(seed)
    zero_a = seed % 2 == 0
    a00 = 0.0 if zero_a else rng.uniform(-2.0, 1.0)
    g = rng.normal(size=4)
    ve = rng.normal(size=10)
    use_meas = seed % 3 == 0
    if not use_meas:  # the measurement is then the output, folded into A and g[0]: g's ym and vm terms are zero
        g[2:] = 0.0
    need_yd = seed % 4 < 2
    frozen = seed in (5, 7)  # the single state is the frozen integrator
    nW = int(rng.integers(1, NC + 1))
    Wd = np.zeros(NC)
    Wd[:nW] = rng.normal(size=nW) / np.cumprod(np.arange(1, nW + 1))
    R = np.array([rng.normal(), rng.normal()] + [0.0] * (NC - 2))
    nR = 2
    Ym, Vm = np.zeros(NC), np.zeros(NC)
    if use_meas:
        k = int(rng.integers(1, 8))
        Ym[:k], Vm[:k] = rng.normal(size=k), rng.normal(size=k)
    d5 = rng.normal(size=5)
    H, w0, x0 = rng.uniform(0.05, 0.8), rng.normal(), rng.normal()
    # the one-state system, and the same with a second, inert state (no input, no coupling, zero start)
    A1, G1, VE1 = np.array([[a00]]), g.reshape(4, 1).copy(), ve.reshape(10, 1).copy()
    A2, G2, VE2 = np.zeros((2, 2)), np.zeros((4, 2)), np.zeros((10, 2))
    A2[0, 0], G2[:, 0], VE2[:, 0] = a00, g, ve
    one = _recur(1, A1, G1, VE1, H, frozen, 0, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, x0, zero_a)
    two = _recur(2, A2, G2, VE2, H, frozen, 0, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, x0, zero_a)
    assert one[0] == two[0]  # the same number of coefficients (a forcing of low degree ends the series early)
    np.testing.assert_array_equal(one[1][0], two[1][0])
    for a, b in zip(one[2:], two[2:]):
        np.testing.assert_array_equal(a, b)
    if frozen:
        assert np.all(one[1][0, 1:] == 0.0)
    else:
        assert np.any(one[1][0, 1:] != 0.0)


def _row(loop, step=1.0, t_end=15.0):
    gen = as_loop(loop)
    return param_row(gen, loop_matrices(gen), step=step, slope=0.0, norm=step, t_end=t_end, band=0.02, dist=None)


def test_batch_rows_equal_runs_alone():
    rng = np.random.default_rng(3)
    pid = Loop("1/((s+1)*(0.5*s+1))", Controller.pid(2.0, 0.8, 0.2, 0.05), delay=0.25, umin=-0.5, umax=2.0)
    clamp = Loop("0.62/(150*s+1)", Controller.pi(8.0, 0.1, antiwindup="clamp"), delay=12.0, umin=0.0, umax=1.0)
    rows = []
    for i in range(24):
        kind = i % 6
        if kind == 0:
            rows.append(_row(AltitudeLoop(kp=1.31, delay=rng.uniform(0.2, 0.5))))
        elif kind == 1:
            rows.append(_row(AltitudeLoop(kp=rng.uniform(0.8, 2.0), delay=rng.uniform(0.2, 0.5),
                                          kv=rng.uniform(0.05, 0.5)), step=rng.uniform(-2.0, 2.0)))
        elif kind == 2:
            rows.append(_row(pid.replace(delay=rng.uniform(0.1, 0.3))))
        elif kind == 3:
            rows.append(_row(clamp.replace(delay=rng.uniform(8.0, 14.0)), t_end=600.0))
        elif kind == 4:
            rows.append(_row(AltitudeLoop(kp=1.31, delay=rng.uniform(0.2, 0.5), period=0.065), t_end=10.0))
        else:
            rows.append(_row(pid.replace(delay=rng.uniform(0.1, 0.3), output_delay=0.1)))
    pars = np.array(rows)
    batch = _K.run_batch(pars, 4096, 1)  # one chunk: every row after the first reuses the work arrays
    cap = 4096
    for i, row in enumerate(pars):
        u = (np.empty(cap), np.empty(cap), np.zeros((cap, NC)), np.empty(cap, dtype=np.int64),
             np.empty(cap, dtype=np.int8))
        y = (np.empty(cap), np.empty(cap), np.zeros((cap, NC)), np.zeros((cap, NC)), np.empty(cap, dtype=np.int8))
        out = np.empty(NOUT)
        _K.run_one(row, np.zeros(1), np.array([row[HEAD["step"]]]), np.zeros(1), cap, *u, *y, out, False,
                   np.empty(0), np.empty(0))
        assert out[_layout.OUT["status"]] == _layout.STATUS_OK
        np.testing.assert_array_equal(batch[i], out)
    # the rows did differ (different loops, not one result repeated)
    assert np.unique(batch[:, _layout.OUT["pieces"]]).size > 6


def _metrics_state():
    ms = np.zeros(_KI._NMS)
    ms[_KI._WMAX] = -np.inf
    ms[_KI._TPEAK] = np.nan
    ms[_KI._T10] = np.nan
    ms[_KI._T90] = np.nan
    return ms


@pytest.mark.parametrize("seed", range(40))
def test_peak_of_a_piece_is_its_maximum(seed):
    """The peak the metrics record on one piece against the maximum of 200,001 evaluations of its polynomial
    (a grid that finds a smooth maximum to about 1e-10): pieces rising throughout (the derivative's bounds
    positive, the root search skipped), falling throughout, and with interior extrema."""
    rng = np.random.default_rng(100 + seed)
    kind = seed % 3
    nY = NC
    rate = rng.uniform(0.3, 3.0)
    Y = rng.normal(size=nY) * rate ** np.arange(nY) / np.cumprod(np.r_[1.0, np.arange(1, nY)])
    Y[0] = rng.uniform(0.5, 1.2)
    if kind == 0:
        Y[1] = abs(Y[1]) + 2.0 * np.sum(np.abs(np.arange(2, nY) * Y[2:]))  # rising throughout
    elif kind == 1:
        Y[1] = -abs(Y[1]) - 2.0 * np.sum(np.abs(np.arange(2, nY) * Y[2:]))  # falling throughout
    else:
        Y[1], Y[2] = 0.8, -1.0  # a maximum near x = 0.4
    a, H = rng.uniform(0.0, 10.0), rng.uniform(0.1, 0.5)
    ms = _metrics_state()
    Wn, dW, xs, fs = np.zeros(NC), np.zeros(NC), np.zeros(_KI._GRID + 2), np.zeros(_KI._GRID + 1)
    _K._step_metrics(Y, nY, 1.0, a, H, 0.02, ms, Wn, dW, xs, fs, np.zeros(1, dtype=np.int64))
    x = np.linspace(0.0, 1.0, 200_001)
    w = np.polynomial.polynomial.polyval(x, Y)
    k = int(np.argmax(w))
    assert ms[_KI._WMAX] >= w[k] - 1e-12
    assert abs(ms[_KI._WMAX] - w[k]) <= 1e-9
    assert abs(ms[_KI._TPEAK] - (a + x[k] * H)) <= 1e-4 * H
    if kind == 0:
        assert ms[_KI._TPEAK] == a + H
    elif kind == 1:
        assert ms[_KI._TPEAK] == a


def _step_response_piece(rng):
    """A damped second-order step response w(t) = 1 - e^(-al t) (cos(be t) + al/be sin(be t)) over [0, T], as
    the Taylor polynomial in x = t / T that the kernel would hold: it rises through 0.1 and 0.9, overshoots and
    leaves the 2 % band more than once."""
    al, be, T = rng.uniform(0.3, 0.8), rng.uniform(1.2, 1.8), rng.uniform(2.2, 3.0)
    j = np.arange(NC)
    fact = np.cumprod(np.r_[1.0, np.arange(1, NC)])
    s = complex(-al, be) * T
    W = -np.real((1.0 - 1j * al / be) * s ** j / fact)
    W[0] += 1.0
    return W


def _dense_metrics(W, a, H, band):
    """The metrics of one piece from 400,001 evaluations: (peak, its time, t10, t90, last time outside the
    band), the times to within H / 400,000."""
    x = np.linspace(0.0, 1.0, 400_001)
    w = np.polynomial.polynomial.polyval(x, W)
    k = int(np.argmax(w))
    t10 = a + x[np.argmax(w >= 0.1)] * H
    t90 = a + x[np.argmax(w >= 0.9)] * H
    out = np.flatnonzero(np.abs(w - 1.0) >= band)
    return w[k], a + x[k] * H, t10, t90, a + x[out[-1]] * H


@pytest.mark.parametrize("seed", range(16))
def test_metric_update_serves_the_kernel_and_the_sampled_batch(seed):
    SB = _native.load("delaykit.simulate", "_sampled_batch")
    SBI = _native.load("delaykit.simulate", "_sampled_batch", "python")  # its constants (C ones when compiled)

    rng = np.random.default_rng(500 + seed)
    W = _step_response_piece(rng)
    a, band = rng.uniform(0.0, 5.0), 0.02
    H = rng.uniform(0.5, 2.0)  # the piece's length in time (W is already in x on [0, 1])
    peak, tpeak, t10, t90, tlast = _dense_metrics(W, a, H, band)
    assert 1.0 + band < peak < 2.0 and 0.0 < t10 - a < t90 - a < tpeak - a < H  # the piece is as intended
    sentinel = 123.0
    found = {}
    for way in ("kernel", "interpreted kernel", "sampled batch", "interpreted sampled way"):
        ms = _metrics_state()
        ms[_KI._TLAST] = 0.0
        ms[_KI._WEND] = sentinel
        Wn, dW, fs = np.zeros(NC), np.zeros(NC), np.zeros(_KI._GRID + 1)
        xs = np.zeros(SBI._MAXX)
        sr, sd = np.zeros(SBI._STACK), np.zeros(SBI._STACK, dtype=np.int64)
        if way == "kernel":
            _K._step_metrics(W, NC, 1.0, a, H, band, ms, Wn, dW, xs, fs, sd)
        elif way == "interpreted kernel":
            _KI._step_metrics(W, NC, 1.0, a, H, band, ms, Wn, dW, xs, fs, sd)
        elif way == "sampled batch":
            SB._poly_metrics(W.copy(), NC, a, H, band, ms, dW, xs, sr, sd)
        else:
            _KI._metrics_update(W.copy(), NC, a, H, band, ms, dW, xs, fs, sr, sd, True)
        tol = 2e-5 * H
        assert abs(ms[_KI._WMAX] - peak) <= 1e-9, way
        assert ms[_KI._WMAX] >= peak - 1e-12, way
        assert abs(ms[_KI._TPEAK] - tpeak) <= 1e-3 * H, way  # a flat maximum: its time is found less sharply
        assert abs(ms[_KI._T10] - t10) <= tol and abs(ms[_KI._T90] - t90) <= tol, way
        assert abs(ms[_KI._TLAST] - tlast) <= tol, way
        if way.endswith("kernel"):  # the kernel keeps w at the piece's end; the batch's ms has no such slot
            assert abs(ms[_KI._WEND] - np.polynomial.polynomial.polyval(1.0, W)) <= 1e-12, way
        else:
            assert ms[_KI._WEND] == sentinel, way
        found[way] = ms.copy()
    # each way's two modes run the same arithmetic
    np.testing.assert_allclose(found["kernel"], found["interpreted kernel"], rtol=1e-12)
    np.testing.assert_allclose(found["sampled batch"], found["interpreted sampled way"], rtol=1e-12)


@pytest.mark.parametrize("seed", range(8))
def test_known_input_recursion_equals_the_general_one(seed):
    """A piece where the plant's input is delayed (known before it) and the measurement is delayed too (no
    folding into the matrix): ``recursion_known`` on ``X' = A X + G (w, r, ym, vm)`` with ``A = M``, ``G`` the
    input vectors, against ``recursion`` on the general form, and both outputs against numpy's sums."""
    rng = np.random.default_rng(900 + seed)
    N = int(rng.integers(2, 4))  # two or three states: the general loop of recursion_known
    MAXN = _layout.MAXN
    M = np.zeros((MAXN, MAXN))
    M[:N, :N] = rng.uniform(-1.0, 1.0, (N, N)) - 1.5 * np.eye(N)
    VE = np.zeros((10, MAXN))
    VE[:4, :N] = rng.normal(size=(4, N))  # w, r, ym, vm
    VE[5:8, :N] = rng.normal(size=(3, N))  # y, y', v
    G = VE[:4].copy()
    d5 = rng.normal(size=5)
    par = np.zeros(len(HEAD))
    par[HEAD["umin"]], par[HEAD["umax"]] = -np.inf, np.inf
    for k, name in enumerate(("dy", "dyd", "dvr", "dvy", "dvv")):
        par[HEAD[name]] = d5[k]
    par[HEAD["integ"]] = -1.0
    nW = int(rng.integers(1, NC + 1))
    Wd = np.zeros(NC)
    Wd[:nW] = rng.normal(size=nW) / np.cumprod(np.arange(1, nW + 1))
    R = np.zeros(NC)
    R[:2] = rng.normal(size=2)
    k = int(rng.integers(1, 10))
    Ym, Vm = np.zeros(NC), np.zeros(NC)
    Ym[:k], Vm[:k] = rng.normal(size=k), rng.normal(size=k)
    H, dist = rng.uniform(0.05, 0.6), rng.normal()
    x0 = rng.normal(size=N)
    got = []
    for general in (False, True):
        X = np.zeros((MAXN, NC + 1))
        X[:N, 0] = x0
        Y, Yd, V, E, Fz = np.zeros(NC), np.zeros(NC), np.zeros(NC), np.zeros(NC), np.zeros(NC)
        if general:
            nt = _T.recursion(par, M, VE, N, H, _T.LIN, False, False, True, False, 0.0, dist, X, R, 2, Wd, nW, Ym,
                              Vm, True, Y, Yd, V, E, True, np.zeros(NC), 1, False, False, Fz, NC)
        else:
            nt = _T.recursion_known(M, G, VE, N, H, False, -1, dist, Wd, nW, R, 2, Ym, Vm, True, True, d5, X, Y,
                                    Yd, V, E, False, False, 0.0, Fz, NC)
        got.append((nt, X, Y, Yd, V, E))
    (n1, *one), (n2, *two) = got
    assert n1 == n2 and n1 > 2
    for u, v in zip(one, two):
        np.testing.assert_array_equal(u, v)
    # the outputs from the states, by numpy: y = c'X + dy w, y' likewise, v = cv'X + dvr r + dvy ym + dvv vm
    X, Y, Yd, V, E = one
    w = np.where(np.arange(NC) < nW, Wd, 0.0)
    w[0] += dist
    dy, dyd, dvr, dvy, dvv = d5
    scale = 1.0 + np.abs(X[:N, :NC]).sum(axis=0) + np.abs(w)
    np.testing.assert_allclose(Y[:n1], (VE[5, :N] @ X[:N, :NC] + dy * w)[:n1], rtol=0, atol=1e-14 * scale.max())
    np.testing.assert_allclose(Yd[:n1], (VE[6, :N] @ X[:N, :NC] + dyd * w)[:n1], rtol=0, atol=1e-14 * scale.max())
    v = VE[7, :N] @ X[:N, :NC] + dvr * R + dvy * Ym + dvv * Vm
    np.testing.assert_allclose(V[:n1], v[:n1], rtol=0, atol=1e-14 * (scale.max() + np.abs(Ym).max()))
    np.testing.assert_array_equal(E[:n1], (R - Ym)[:n1])
    # and the states follow X[j+1] = H (M X[j] + G (w, r, ym, vm)[j]) / (j + 1)
    for j in range(n1 - 1):
        rhs = M[:N, :N] @ X[:N, j] + G[0, :N] * w[j] + G[1, :N] * R[j] + G[2, :N] * Ym[j] + G[3, :N] * Vm[j]
        np.testing.assert_allclose(X[:N, j + 1], H * rhs / (j + 1), rtol=1e-12, atol=1e-300)


def test_this_numba_accepts_the_no_refcount_option():
    # the piece loop relies on it for a third of its speed under numba; if this fails, numba dropped the private
    # option and the kernel compiles with reference counting (slower, still exact): see _native._numba_knows
    assert _native._numba_knows("_nrt")
    assert not _native._numba_knows("an_option_numba_never_had")


def test_a_numba_without_the_option_still_compiles(monkeypatch):
    # a numba release that drops `_nrt` would raise KeyError("Unrecognized options") at the first call: numba's
    # copy of a kernel is made without the option instead, and its functions compile and run (with reference
    # counting).  (_poly's refine asks for it in its NUMBA_OPTIONS.)
    import sys

    monkeypatch.setattr(_native, "_numba_knows", lambda option: False)
    name = "delaykit.simulate._poly_numba"
    before = sys.modules.get(name)
    try:
        p = _native._from_source("delaykit.simulate", "_poly", "numba")
        assert "_nrt" not in p.refine.targetoptions  # dropped, not passed on (numba keeps the options it was given)
        c = np.array([-0.25, 0.0, 1.0])  # x**2 - 1/4: its root 1/2 (refined from the bracket [0, 1])
        assert abs(p.refine(c, 3, 0.0, 0.0, 1.0, -1.0) - 0.5) <= 1e-15
    finally:
        if before is not None:
            sys.modules[name] = before
