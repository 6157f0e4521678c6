"""The simulator kernel's shortcuts, each against the general computation it stands in for.

* A single-state loop's Taylor recursion (``_taylor._known_one``, the paper's integrator) runs apart from the
  general N-state loop of ``recursion_known``: here the same state is embedded in a two-state system whose
  second state is inert, which takes the general loop, and every coefficient must come out identical.
* The batch kernel (``run_batch``) reuses its work arrays from row to row, where ``run_one`` allocates fresh
  ones: rows of different loops (1 to 4 states, saturated, sliding on a limit, sampled) in one batch must give
  exactly what each gives alone.
* The peak search skips the derivative's root search where the derivative's bounds keep one sign: the peak
  found on a piece must still be the piece's maximum, as a dense evaluation of the polynomial finds it.
"""

from __future__ import annotations

import numpy as np
import pytest

from delaykit import AltitudeLoop
from delaykit.models import Controller, Loop
from delaykit.simulate import _jit, _layout
from delaykit.simulate._layout import NC, NOUT, HEAD, loop_matrices, param_row
from delaykit.simulate.simulation import as_loop

_T = _jit.sibling("_taylor")  # compiled (this process builds compiled modules by default)
_K = _jit.kernel(compiled=True)


def _recur(N, A, G, VE, H, frozen, integ, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, x0, zero_a):
    X = np.zeros((_layout.MAXN, NC + 1))
    X[0, 0] = x0
    Y, Yd, V, E = np.zeros(NC), np.zeros(NC), np.zeros(NC), np.zeros(NC)
    nt = _T.recursion_known(A, G, VE, N, H, frozen, integ, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, X, Y,
                            Yd, V, E, zero_a, False, 0.0, np.zeros(NC))
    return nt, X, Y, Yd, V, E


@pytest.mark.parametrize("seed", range(12))
def test_single_state_recursion_equals_the_general_loop(seed):
    rng = np.random.default_rng(seed)
    zero_a = seed % 2 == 0
    a00 = 0.0 if zero_a else rng.uniform(-2.0, 1.0)
    g = rng.normal(size=4)
    ve = rng.normal(size=10)
    use_meas = seed % 3 == 0
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
    ms = np.zeros(_K._NMS)
    ms[_K._WMAX] = -np.inf
    ms[_K._TPEAK] = np.nan
    ms[_K._T10] = np.nan
    ms[_K._T90] = np.nan
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
    Wn, dW, xs, fs = np.zeros(NC), np.zeros(NC), np.zeros(_K._GRID + 2), np.zeros(_K._GRID + 1)
    _K._step_metrics(Y, nY, 1.0, a, H, 0.02, ms, Wn, dW, xs, fs)
    x = np.linspace(0.0, 1.0, 200_001)
    w = np.polynomial.polynomial.polyval(x, Y)
    k = int(np.argmax(w))
    assert ms[_K._WMAX] >= w[k] - 1e-12
    assert abs(ms[_K._WMAX] - w[k]) <= 1e-9
    assert abs(ms[_K._TPEAK] - (a + x[k] * H)) <= 1e-4 * H
    if kind == 0:
        assert ms[_K._TPEAK] == a + H
    elif kind == 1:
        assert ms[_K._TPEAK] == a


def test_this_numba_accepts_the_no_refcount_option():
    # the piece loop relies on it for a third of its speed; if this fails, numba dropped the private option and
    # the kernel compiles with reference counting (slower, still exact): see _jit._numba_knows
    assert _jit._numba_knows("_nrt")
    assert not _jit._numba_knows("an_option_numba_never_had")


def test_a_numba_without_the_option_still_compiles(monkeypatch):
    # a numba release that drops `_nrt` would raise KeyError("Unrecognized options") at the first call: the
    # decorator drops the option instead, and the function compiles and runs (with reference counting)
    monkeypatch.setattr(_jit, "_numba_knows", lambda option: False)

    @_jit.njit(cache=False, _nrt=False)
    def total(x):
        s = 0.0
        for i in range(x.size):
            s += x[i]
        return s

    assert total(np.arange(5.0)) == 10.0
    assert "_nrt" not in total.targetoptions  # dropped, not passed on (numba keeps the options it was given)
