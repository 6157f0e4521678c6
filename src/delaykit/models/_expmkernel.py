"""The compiled matrix exponential of a small matrix (:func:`delaykit.models.hold.hold_matrices` is the interface).

``expm_into`` computes ``exp(X)`` by scaling and squaring around a Taylor series: ``X`` is halved ``s`` times until
``||X / 2^s||_1 <= 1/2``, the series is summed until a term is below 1e-18 of one (at most degree 18; its remainder,
below ``0.5^19 / 19!`` ~ 2e-23 relative, is far under rounding), then squared ``s`` times.  Every exact step of a
linear system under a held input in delaykit (the sample-to-sample simulator, the varying-delay simulator, the
relay cycle, the emulated flight laws) takes its exponential from here, directly (the kernels of
:mod:`delaykit.simulate`, through :func:`delaykit._native.sibling`) or through ``hold_matrices``.

One source, three modes (:mod:`delaykit._native`), as ``spectrum/_rootkernel.py``: compiled ahead of time by Cython
(the C types are in ``_expmkernel.pxd``), compiled by numba where no extension was built, or run as plain Python.
"""

from __future__ import annotations

import numpy as np

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

__all__ = ["mul_into", "expm_into", "expm", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""


def mul_into(X, Y, Z):
    """``Z = X @ Y`` for small square matrices (explicit loops: no BLAS call overhead)."""
    n = X.shape[0]
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += X[i, k] * Y[k, j]
            Z[i, j] = s


def expm_into(X, E, T, W):
    """``E = exp(X)`` for a square ``X`` (overwritten: scaled by ``2^-s``); ``T``, ``W``: work space of its shape."""
    q = X.shape[0]
    norm = 0.0
    for j in range(q):
        c = 0.0
        for i in range(q):
            c += abs(X[i, j])
        norm = max(norm, c)
    s = 0
    while norm > 0.5:
        norm *= 0.5
        s += 1
    sc = 0.5 ** s
    for i in range(q):
        for j in range(q):
            X[i, j] *= sc
    for i in range(q):
        for j in range(q):
            T[i, j] = 1.0 if i == j else 0.0
            E[i, j] = T[i, j]
    for k in range(1, 19):
        mul_into(T, X, W)
        big = 0.0
        for i in range(q):
            for j in range(q):
                T[i, j] = W[i, j] / k
                E[i, j] += T[i, j]
                big = max(big, abs(T[i, j]))
        if big < 1e-18:
            break
    for _ in range(s):
        mul_into(E, E, W)
        for i in range(q):
            for j in range(q):
                E[i, j] = W[i, j]


def expm(M):
    """``exp(M)`` of a small square matrix, as a new array (``M`` is not changed)."""
    q = M.shape[0]
    E = np.empty((q, q))
    work = np.empty((3, q, q))  # X, T and W in one allocation (each costs a call into Python when compiled)
    X = work[0]
    for i in range(q):
        for j in range(q):
            X[i, j] = M[i, j]
    expm_into(X, E, work[1], work[2])
    return np.asarray(E)
