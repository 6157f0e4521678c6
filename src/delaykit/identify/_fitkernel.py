"""Compiled inner loops of identification's least squares (:mod:`._fit` is the interface): a structure's
realisation, one trial point end to end (the held-input matrices, every log simulated, each log's nuisance
columns projected out), its forward-difference Jacobian, and the plain-loop products of the solver.

One source, three modes (:mod:`delaykit._native` loads them): compiled ahead of time by Cython when the package is
built (the C types are in ``_fitkernel.pxd``), compiled by numba on first use where no extension was built, or run
as plain Python.  So the code here keeps to what all three read alike (see ``docs/guide/first-calls.md``).

The held-input matrices and the simulation of the logs are the discrete simulator's kernel
(:mod:`delaykit.simulate._discretekernel`: ``held_arrays_into``, ``run_logs_into``), cimported by the extension and
taken in this module's own mode otherwise.

A trial point allocates nothing: its matrices and vectors are rows of the two work arrays of :func:`workspace`,
made once per fit (allocating a dozen small NumPy arrays per trial point cost the extension more than the
simulation of a 600-sample log).
"""

from __future__ import annotations

import numpy as np

from delaykit.simulate.discrete import STIFF

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

if cython.compiled:  # C's own functions and the discrete simulator's extension (Cython turns these into cimports)
    from cython.cimports.delaykit.simulate._discretekernel import held_arrays_into as _held_arrays_into
    from cython.cimports.delaykit.simulate._discretekernel import run_logs_into as _run_logs_into
    from cython.cimports.libc.math import exp, floor, isfinite
else:  # the discrete simulator's kernel in this module's own mode (numba's copy calls numba's)
    from math import exp, floor, isfinite

    from delaykit import _native

    _held_arrays_into = _native.sibling(__name__, "_discretekernel", "delaykit.simulate").held_arrays_into
    _run_logs_into = _native.sibling(__name__, "_discretekernel", "delaykit.simulate").run_logs_into

__all__ = ["order", "workspace", "realise", "realise_into", "core", "evaluate", "evaluate_fit", "jacobian_fit", "residual_blocks", "dot",
           "normal_equations", "OK", "STIFF_PLANT", "NEGATIVE", "ALGEBRAIC", "NONFINITE", "STEP", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

# the status values the kernels return (code reads these, never a message)
OK, STIFF_PLANT, NEGATIVE, ALGEBRAIC, NONFINITE = 0, 1, 2, 3, 4

STEP = 1e-6
"""Relative step of the forward differences in fitting coordinates."""


def order(code):
    """The number of states of structure number ``code``'s realisation."""
    return 1 if code == 0 or code == 3 else (3 if code == 2 else 2)


def workspace(code, size):
    """The work arrays of a fit of structure number ``code`` with ``size`` parameters: ``mats`` (7 matrices of
    order n + 1: the realisation's ``A`` and the one-period ``phi`` in their top-left corners, and the five of the
    held-input exponentials) and ``vecs`` (9 rows: ``B``, ``C``, ``C A``, ``g_early``, ``g_late``, the state and the
    next state, the physical point and the Jacobian's shifted one)."""
    n = order(code)
    mats = np.zeros((7, n + 1, n + 1))
    vecs = np.zeros((9, max(n, size)))
    return np.asarray(mats), np.asarray(vecs)


def realise(code, v):
    """``(A, B, C)`` of structure number ``code`` (:attr:`~.structures.Structure.code`) at the values ``v``: the
    physical cascade (a lag's output, then the next lag or the integrator), every entry of the size of a rate."""
    n = order(code)
    A = np.zeros((n, n))
    B = np.zeros(n)
    C = np.zeros(n)
    realise_into(code, v, A, B, C)
    return np.asarray(A), np.asarray(B), np.asarray(C)


def realise_into(code, v, A, B, C):
    """:func:`realise` into ``A`` (of the order's shape), ``B`` and ``C``."""
    n = A.shape[0]
    for i in range(n):
        for j in range(n):
            A[i, j] = 0.0
        B[i] = 0.0
        C[i] = 0.0
    C[n - 1] = 1.0
    if code == 0:  # ipdt: y' = K u
        B[0] = v[0]
    elif code == 1:  # ipdt_lag: w' = (K u - w) / T, y' = w
        a = 1.0 / v[1]
        A[0, 0] = -a
        A[1, 0] = 1.0
        B[0] = v[0] * a
    elif code == 2:  # ipdt_speed: (s^2 + 2 zeta wn s + wn^2) z = u in q1 = wn^2 z, q2 = wn z'; speed K (q1 + wn Tz q2)
        k = v[0]
        wn = v[1]
        zeta = v[2]
        tz = v[3]
        A[0, 1] = wn
        A[1, 0] = -wn
        A[1, 1] = -2.0 * zeta * wn
        A[2, 0] = k
        A[2, 1] = k * wn * tz
        B[1] = wn
    elif code == 3:  # fopdt
        a = 1.0 / v[1]
        A[0, 0] = -a
        B[0] = v[0] * a
    else:  # sopdt: two lags in cascade
        a = 1.0 / v[1]
        b = 1.0 / v[2]
        A[0, 0] = -a
        A[1, 0] = b
        A[1, 1] = -b
        B[0] = v[0] * a


def residual_blocks(y, dy, uy, udy, starts, k0, p0, m0, k1, p1, m1, w0, w1, bias, offset, out):
    """Measured minus simulated at the kept samples (log by log: the first output, then its rate), with each
    log's nuisance columns projected out by weighted least squares: the response to a held unit input (``bias``,
    the hover level of an integrating plant) and a constant on the first output (``offset``)."""
    pos = 0
    for i in range(starts.shape[0] - 1):
        s = starts[i]
        a0 = p0[i]
        n0 = p0[i + 1] - p0[i]
        a1 = p1[i]
        n1 = p1[i + 1] - p1[i]
        for j in range(n0):
            out[pos + j] = m0[a0 + j] - y[s + k0[a0 + j]]
        for j in range(n1):
            out[pos + n0 + j] = m1[a1 + j] - dy[s + k1[a1 + j]]
        if bias or offset:
            # normal equations of the weighted columns (at most two: well conditioned, a ramp and a constant)
            g00 = 0.0
            g01 = 0.0
            g11 = 0.0
            b0 = 0.0
            b1 = 0.0
            for j in range(n0 + n1):
                if j < n0:
                    w = w0
                    ca = uy[s + k0[a0 + j]] if bias else 0.0
                    cc = 1.0 if offset else 0.0
                else:
                    w = w1
                    ca = udy[s + k1[a1 + j - n0]] if bias else 0.0
                    cc = 0.0
                ca /= w
                cc /= w
                rj = out[pos + j] / w
                g00 += ca * ca
                g01 += ca * cc
                g11 += cc * cc
                b0 += ca * rj
                b1 += cc * rj
            beta0 = 0.0
            beta1 = 0.0
            det = g00 * g11 - g01 * g01
            if g00 > 0.0 and g11 > 0.0 and det > 1e-13 * g00 * g11:
                beta0 = (g11 * b0 - g01 * b1) / det
                beta1 = (g00 * b1 - g01 * b0) / det
            elif g00 >= g11 and g00 > 0.0:
                beta0 = b0 / g00
            elif g11 > 0.0:
                beta1 = b1 / g11
            for j in range(n0 + n1):
                if j < n0:
                    ca = uy[s + k0[a0 + j]] if bias else 0.0
                    cc = 1.0 if offset else 0.0
                else:
                    ca = udy[s + k1[a1 + j - n0]] if bias else 0.0
                    cc = 0.0
                out[pos + j] -= ca * beta0 + cc * beta1
        pos += n0 + n1


def core(phi, ge, gl, m, frac, C, ca, cb, drive, starts, closed, kp, kv, lo, hi, bias, offset, k0, p0, m0, k1, p1,
         m1, w0, w1, y, dy, uy, udy, u, x, xn, out):
    """Simulate every log with the one-period matrices and fill ``out`` with the projected raw residuals (``u``:
    work array of ``drive``'s length; ``x``, ``xn``: of the plant's order)."""
    if closed and m == 0 and not frac and kv != 0.0 and cb != 0.0:
        return ALGEBRAIC
    _run_logs_into(phi, ge, gl, C, 0.0, ca, cb, m, frac, drive, starts, closed, kp, kv, lo, hi, bias, y, dy, uy, udy,
                   u, x, xn)
    residual_blocks(y, dy, uy, udy, starts, k0, p0, m0, k1, p1, m1, w0, w1, bias, offset, out)
    return OK


def evaluate(code, p, h, snap, drive, starts, closed, kp, kv, lo, hi, bias, offset, k0, p0, m0, k1, p1, m1, w0, w1,
             y, dy, uy, udy, u, mats, vecs, out):
    """One trial point, compiled end to end: the realisation, the delay split as
    :func:`~delaykit.models.hold.split_delay` splits it, the exact one-period matrices, the logs, the residuals
    (``u``: work array of ``drive``'s length; ``mats``, ``vecs``: :func:`workspace`'s).
    Returns ``STIFF_PLANT`` (nothing computed) when the plant is far too fast for the compiled exponential."""
    T = p[p.shape[0] - 1]
    if not T >= 0.0:
        return NEGATIVE
    n = order(code)
    A = mats[0, :n, :n]
    B = vecs[0, :n]
    C = vecs[1, :n]
    realise_into(code, p, A, B, C)
    norm = 0.0
    for i in range(n):
        for j in range(n):
            norm += abs(A[i, j])
    if not norm * h <= STIFF:
        return STIFF_PLANT
    m = int(floor(T / h))
    f = T - m * h
    if f < snap * h:
        f = 0.0
    elif h - f < snap * h:
        m += 1
        f = 0.0
    phi = mats[1, :n, :n]
    ge = vecs[3, :n]
    gl = vecs[4, :n]
    _held_arrays_into(A, B, h, f, phi, ge, gl, mats[2:, :n + 1, :n + 1])
    ca = vecs[2, :n]
    cb = 0.0
    for j in range(n):
        cb += C[j] * B[j]
        ca[j] = 0.0
        for i in range(n):
            ca[j] += C[i] * A[i, j]
    return core(phi, ge, gl, m, f > 0.0, C, ca, cb, drive, starts, closed, kp, kv, lo, hi, bias, offset, k0, p0, m0,
                k1, p1, m1, w0, w1, y, dy, uy, udy, u, vecs[5, :n], vecs[6, :n], out)


def evaluate_fit(code, z, pos, rw, h, snap, drive, starts, closed, kp, kv, lo, hi, bias, offset, k0, p0, m0, k1, p1,
                 m1, w0, w1, y, dy, uy, udy, u, mats, vecs, out):
    """:func:`evaluate` at fitting coordinates (``exp`` of the positive ones, clipped at +-60), the residuals
    weighted; ``NONFINITE`` when they overflow."""
    p = vecs[7, :z.shape[0]]
    for i in range(z.shape[0]):
        p[i] = exp(min(max(z[i], -60.0), 60.0)) if pos[i] != 0 else z[i]
        if not isfinite(p[i]):
            return NONFINITE
    status = evaluate(code, p, h, snap, drive, starts, closed, kp, kv, lo, hi, bias, offset, k0, p0, m0, k1, p1, m1,
                      w0, w1, y, dy, uy, udy, u, mats, vecs, out)
    if status != OK:
        return status
    for i in range(out.shape[0]):
        out[i] /= rw[i]
        if not isfinite(out[i]):
            return NONFINITE
    return OK


def jacobian_fit(code, z, pos, lb, ub, r0, rw, h, snap, drive, starts, closed, kp, kv, lo, hi, bias, offset, k0, p0,
                 m0, k1, p1, m1, w0, w1, y, dy, uy, udy, u, mats, vecs, col, J):
    """Forward differences of :func:`evaluate_fit` around ``z`` (residuals ``r0`` there) into ``J``."""
    zz = vecs[8, :z.shape[0]]
    for i in range(z.shape[0]):
        zz[i] = z[i]
    for i in range(z.shape[0]):
        step = STEP * max(1.0, abs(z[i])) * (1.0 if z[i] >= 0.0 else -1.0)
        if z[i] + step > ub[i] or z[i] + step < lb[i]:
            step = -step
        zz[i] = z[i] + step
        dz = zz[i] - z[i]
        status = evaluate_fit(code, zz, pos, rw, h, snap, drive, starts, closed, kp, kv, lo, hi, bias, offset, k0, p0,
                              m0, k1, p1, m1, w0, w1, y, dy, uy, udy, u, mats, vecs, col)
        zz[i] = z[i]
        if status == STIFF_PLANT:
            return STIFF_PLANT
        ok = status == OK
        for k in range(r0.shape[0]):
            J[k, i] = ((col[k] if ok else 1e6) - r0[k]) / dz
    return OK


def dot(a, b):
    """``a . b`` in a plain loop (OpenBLAS threads long dot products, which stalls on a busy machine)."""
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


def normal_equations(J, r):
    """``J^T J`` and ``J^T r`` in plain loops (a tall, thin ``J``: no threaded BLAS call for a 4-column product)."""
    m = J.shape[0]
    n = J.shape[1]
    A = np.zeros((n, n))
    g = np.zeros(n)
    for k in range(m):
        rk = r[k]
        for i in range(n):
            a = J[k, i]
            g[i] += a * rk
            for j in range(i, n):
                A[i, j] += a * J[k, j]
    for i in range(n):
        for j in range(i):
            A[i, j] = A[j, i]
    return np.asarray(A), np.asarray(g)
