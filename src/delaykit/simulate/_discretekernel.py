"""Compiled loops of the sample-to-sample simulator (:mod:`delaykit.simulate.discrete` is the interface).

A plant ``x' = A x + B w`` whose input ``w`` is a held command, delayed: ``held_arrays`` gives the exact
one-period map (``phi``, ``g_early``, ``g_late``) from two exponentials of the augmented matrix
``[[A t, B t], [0, 0]]`` (:mod:`delaykit.models._expmkernel`); ``run_into`` and ``run_logs`` step it over logs, open
or closed by a static sampled law; ``run_at_into`` and ``run_at_logs`` step a plant on a clock that is not uniform,
one exponential per stretch between events.

One source, three modes (:mod:`delaykit._native`), as ``spectrum/_rootkernel.py``: compiled ahead of time by
Cython (the C types are in ``_discretekernel.pxd``; the exponential is cimported from the models' extension),
compiled by numba where no extension was built (the exponential is then numba's copy too), or run as plain Python.
"""

from __future__ import annotations

import numpy as np

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

if cython.compiled:  # the models' extension, called in C
    from cython.cimports.delaykit.models._expmkernel import expm_into
else:  # the exponential of this module's own mode (numba's copy calls numba's)
    from delaykit import _native

    expm_into = _native.sibling(__name__, "_expmkernel", "delaykit.models").expm_into

__all__ = ["aug_expm", "held_arrays", "held_arrays_into", "run_into", "run", "run_logs", "run_logs_into", "advance",
           "run_at_into", "run_at_logs", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""


def aug_expm(A, B, t, E, X, T, W):
    """``E = exp([[A t, B t], [0, 0]])`` ((n+1) x (n+1)): ``E[:n, :n] = Phi(t)``, ``E[:n, n] = Gamma(t)``
    (``X``, ``T``, ``W``: work matrices of E's shape)."""
    n = A.shape[0]
    for i in range(n + 1):
        for j in range(n + 1):
            X[i, j] = 0.0
    for i in range(n):
        for j in range(n):
            X[i, j] = A[i, j] * t
        X[i, n] = B[i] * t
    expm_into(X, E, T, W)


def held_arrays(A, B, h, f):
    """``phi``, ``g_early`` and ``g_late`` of a realisation ``(A, B)`` for the delay's fraction ``f`` of a period
    (two exponentials: over ``f`` and over ``h - f``; ``phi = Phi(h - f) Phi(f)``), as new arrays."""
    n = A.shape[0]
    phi = np.zeros((n, n))
    g = np.zeros((2, n))  # g_early, g_late
    work = np.empty((5, n + 1, n + 1))  # the two exponentials and their work space, in one allocation
    held_arrays_into(A, B, h, f, phi, g[0], g[1], work)
    return np.asarray(phi), np.asarray(g)[0], np.asarray(g)[1]


def held_arrays_into(A, B, h, f, phi, ge, gl, work):
    """:func:`held_arrays` into ``phi`` (n x n), ``ge`` and ``gl`` (``work``: five matrices of order n + 1), so that
    a caller evaluating many trial plants (identification) allocates nothing per plant."""
    n = A.shape[0]
    Er = work[0]
    Ef = work[1]
    aug_expm(A, B, h - f, Er, work[2], work[3], work[4])
    for i in range(n):
        gl[i] = Er[i, n]
    if f > 0.0:
        aug_expm(A, B, f, Ef, work[2], work[3], work[4])
        for i in range(n):
            for j in range(n):
                acc = 0.0
                for k in range(n):
                    acc += Er[i, k] * Ef[k, j]
                phi[i, j] = acc
            acc = 0.0
            for k in range(n):
                acc += Er[i, k] * Ef[k, n]
            ge[i] = acc
    else:
        for i in range(n):
            ge[i] = 0.0
            for j in range(n):
                phi[i, j] = Er[i, j]


def run_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, closed, kp, kv, lo, hi, y, dy, u, x, xn):
    """One log from rest into ``y``, ``dy`` and ``u`` (``x``, ``xn``: work vectors of the plant's order)."""
    n = phi.shape[0]
    N = drive.shape[0]
    for i in range(n):
        x[i] = 0.0
    lag_now = m + 1 if fractional else m  # the command acting at a sample instant was issued lag_now samples ago
    for k in range(N):
        j = k - lag_now
        u_now = u[j] if j >= 0 and j < k else 0.0
        yk = d * u_now
        dk = cb * u_now
        for i in range(n):
            yk += c[i] * x[i]
            dk += ca[i] * x[i]
        if closed:
            uk = kp * (drive[k] - yk) - kv * dk
            if uk < lo:
                uk = lo
            elif uk > hi:
                uk = hi
        else:
            uk = drive[k]
        u[k] = uk
        if j == k:  # no delay: the command issued now acts now
            yk += d * uk
            dk += cb * uk
        y[k] = yk
        dy[k] = dk
        je = k - m - 1
        jl = k - m
        ue = u[je] if je >= 0 else 0.0
        ul = u[jl] if jl >= 0 else 0.0
        for i in range(n):
            s = g_early[i] * ue + g_late[i] * ul
            for q in range(n):
                s += phi[i, q] * x[q]
            xn[i] = s
        for i in range(n):
            x[i] = xn[i]


def run(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, closed, kp, kv, lo, hi):
    """One log from rest: ``(y, dy, u)`` as new arrays (:func:`run_into`)."""
    N = drive.shape[0]
    n = phi.shape[0]
    u = np.zeros(N)
    y = np.empty(N)
    dy = np.empty(N)
    x = np.zeros(n)
    xn = np.zeros(n)
    run_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, closed, kp, kv, lo, hi, y, dy, u, x, xn)
    return np.asarray(y), np.asarray(dy), np.asarray(u)


def run_logs(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, starts, closed, kp, kv, lo, hi, unit,
             y, dy, uy, udy):
    """Several logs laid end to end (log ``i`` is ``drive[starts[i]:starts[i + 1]]``, each from rest, each with its
    own limits ``lo[i]``, ``hi[i]``) into ``y`` and ``dy``; with ``unit``, also each log's response to a held unit
    command (open loop) into ``uy`` and ``udy``."""
    n = phi.shape[0]
    x = np.zeros(n)
    xn = np.zeros(n)
    u = np.zeros(drive.shape[0])
    run_logs_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, starts, closed, kp, kv, lo, hi, unit,
                  y, dy, uy, udy, u, x, xn)


def run_logs_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, starts, closed, kp, kv, lo, hi, unit,
                  y, dy, uy, udy, u, x, xn):
    """:func:`run_logs` with its work arrays given: the commands ``u`` (of ``drive``'s length) and the state ``x``,
    ``xn`` (of the plant's order); nothing is read from them before it is written."""
    for i in range(starts.shape[0] - 1):
        a = starts[i]
        b = starts[i + 1]
        run_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive[a:b], closed, kp, kv, lo[i], hi[i],
                 y[a:b], dy[a:b], u[a:b], x, xn)
        if unit:
            for k in range(a, b):
                u[k] = 1.0
            run_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, u[a:b], False, 0.0, 0.0, lo[i], hi[i],
                     uy[a:b], udy[a:b], u[a:b], x, xn)


def advance(A, B, dt, v, x, xn, E, X, T, W):
    """``x <- Phi(dt) x + Gamma(dt) v`` (``E``, ``X``, ``T``, ``W``: work matrices of order n + 1)."""
    n = A.shape[0]
    if dt <= 0.0:
        return
    aug_expm(A, B, dt, E, X, T, W)
    for i in range(n):
        s = E[i, n] * v
        for q in range(n):
            s += E[i, q] * x[q]
        xn[i] = s
    for i in range(n):
        x[i] = xn[i]


def run_at_into(A, B, c, d, ca, cb, delay, tol, t, drive, y, dy):
    """One log from rest on its own clock ``t``: ``drive[k]`` held from ``t[k]`` reaches the plant at
    ``t[k] + delay``; an arrival within ``tol`` of a sample acts at that sample."""
    n = A.shape[0]
    N = t.shape[0]
    x = np.zeros(n)
    xn = np.zeros(n)
    E = np.empty((n + 1, n + 1))
    X = np.empty((n + 1, n + 1))
    T = np.empty((n + 1, n + 1))
    W = np.empty((n + 1, n + 1))
    tau = t[0]
    j = -1  # the last command that has reached the plant (-1: none yet, the input is 0)
    v = 0.0
    for i in range(N):
        while j + 1 < N and t[j + 1] + delay <= t[i] + tol:
            s = min(t[j + 1] + delay, t[i])
            advance(A, B, s - tau, v, x, xn, E, X, T, W)
            tau = max(tau, s)
            j += 1
            v = drive[j]
        advance(A, B, t[i] - tau, v, x, xn, E, X, T, W)
        tau = t[i]
        yk = d * v
        dk = cb * v
        for q in range(n):
            yk += c[q] * x[q]
            dk += ca[q] * x[q]
        y[i] = yk
        dy[i] = dk


def run_at_logs(A, B, c, d, ca, cb, delay, tol, t, drive, starts, unit, y, dy, uy, udy):
    """Several logs laid end to end (as :func:`run_logs`, each on its own clock ``t[starts[i]:starts[i + 1]]``);
    with ``unit``, also each log's response to a held unit command into ``uy`` and ``udy``."""
    ones = np.ones(drive.shape[0])
    for i in range(starts.shape[0] - 1):
        a = starts[i]
        b = starts[i + 1]
        run_at_into(A, B, c, d, ca, cb, delay, tol, t[a:b], drive[a:b], y[a:b], dy[a:b])
        if unit:
            run_at_into(A, B, c, d, ca, cb, delay, tol, t[a:b], ones[a:b], uy[a:b], udy[a:b])
