"""The compiled matrix exponential of a small matrix (:func:`delaykit.models.hold.hold_matrices` is the interface).

``expm_into`` computes ``exp(A)`` by scaling and squaring around a Taylor series: with ``s`` the least integer
for which ``B = A / 2^s`` has ``b = ||B||_1 <= 1/2``, the series of ``exp(B)`` is summed until the bound of its
tail, ``||T_k||_1 (b/(k+1)) / (1 - b/(k+2))`` (``T_k = B^k / k!``), is below 2^-56 (1.4e-17; at most 40 terms),
then squared ``s`` times.  It returns that bound relative to ``||exp(B)||_1 >= e^-b >= 0.6``: the certified
expansions of the sampled loops' fast path (:mod:`delaykit.simulate._sampled_batch`) report it.  The terms skip
the zero entries of ``T_k`` and the zero rows of ``A`` (the matrices exponentiated in delaykit are augmented with
held inputs and references, whose rows are zero).  Every exact step of a linear system under a held input in
delaykit (the sampled loops' batch, the sample-to-sample simulator, the varying-delay simulator, the relay cycle,
the emulated flight laws) takes its exponential from here, directly (the kernels of :mod:`delaykit.simulate`,
through ``cimport`` or :func:`delaykit._native.sibling`) or through ``hold_matrices``.

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

if cython.compiled:
    from cython.cimports.libc.math import INFINITY as _INF, NAN as _NAN, ceil, isinf, ldexp, log2
else:
    from math import ceil, inf as _INF, isinf, ldexp, log2, nan as _NAN

__all__ = ["expm_into", "expm", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""


def _norm1(X):
    """The 1-norm of a square matrix (its largest column sum of absolute values)."""
    m = X.shape[0]
    nrm = 0.0
    for j in range(m):
        s = 0.0
        for i in range(m):
            s += abs(X[i, j])
        nrm = max(nrm, s)
    return nrm


def expm_into(A, E, T, W):
    """``E = exp(A)`` for a square ``A`` (not changed); ``T``, ``W``: work space of its shape.  Returns the bound
    of the series' remainder, relative to ``||exp(A / 2^s)||_1`` (infinity, and ``E`` all NaN, if ``A`` has an
    infinite entry)."""
    m = A.shape[0]
    nrm = _norm1(A)
    if isinf(nrm):
        for i in range(m):
            for j in range(m):
                E[i, j] = _NAN
        return _INF
    sq = 0  # the least s with ||A|| / 2^s <= 1/2 (log2 gives it or one off; log2(nrm / 0.5) could overflow)
    if nrm > 0.5:
        sq = int(ceil(log2(nrm)))  # (a C cast where compiled, then the sum)
        sq += 1
        while ldexp(nrm, -sq) > 0.5:
            sq += 1
        while sq > 1 and ldexp(nrm, 1 - sq) <= 0.5:
            sq -= 1
    f = ldexp(1.0, -sq)
    b = nrm * f
    for i in range(m):
        for j in range(m):
            T[i, j] = A[i, j] * f
            E[i, j] = T[i, j] + (1.0 if i == j else 0.0)
    # W[1]: which rows of A are not zero (1.0), for the terms; W[0]: one row of the next term
    if m > 1:
        for i in range(m):
            W[1, i] = 0.0
            for j in range(m):
                if A[i, j] != 0.0:
                    W[1, i] = 1.0
    rem = 0.0
    k = 1
    while True:
        rem = _norm1(T) * (b / (k + 1)) / (1.0 - b / (k + 2))
        if rem <= 1.4e-17 or k >= 40:
            break
        k += 1
        g = f / k
        for i in range(m):  # T_k = T_(k-1) A f / k, row by row in place (row i reads its own row of T only)
            for j in range(m):
                W[0, j] = 0.0
            for l in range(m):
                t = T[i, l]
                if t != 0.0 and (m == 1 or W[1, l] != 0.0):
                    t *= g
                    for j in range(m):
                        W[0, j] += t * A[l, j]
            for j in range(m):
                T[i, j] = W[0, j]
                E[i, j] += W[0, j]
    for _ in range(sq):
        for i in range(m):
            for j in range(m):
                W[i, j] = 0.0
            for l in range(m):
                t = E[i, l]
                if t != 0.0:
                    for j in range(m):
                        W[i, j] += t * E[l, j]
        for i in range(m):
            for j in range(m):
                E[i, j] = W[i, j]
    return rem / 0.6


def expm(M):
    """``exp(M)`` of a small square matrix, as a new array (``M`` is not changed)."""
    q = M.shape[0]
    E = np.empty((q, q))
    work = np.empty((3, q, q))  # A, T and W in one allocation (each costs a call into Python when compiled)
    A = work[0]
    for i in range(q):
        for j in range(q):
            A[i, j] = M[i, j]
    expm_into(A, E, work[1], work[2])
    return np.asarray(E)
