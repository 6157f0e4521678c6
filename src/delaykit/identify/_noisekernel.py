"""Compiled inner loops of the noise models (:mod:`.noise` is the interface): a series filtered by a polynomial
ratio (an autoregressive model's whitening and its inverse), and a Jacobian filtered backwards through the inverse
of a vector-autoregressive model.

One source, three modes (:mod:`delaykit._native` loads them): compiled ahead of time by Cython when the package is
built (the C types are in ``_noisekernel.pxd``), compiled by numba on first use where no extension was built, or
run as plain Python (see ``docs/guide/first-calls.md``).
"""

from __future__ import annotations

import numpy as np

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

__all__ = ["linear_filter", "var_backward", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""


def linear_filter(b, a, x, y):
    """``y = B(q) / A(q) x`` along the first axis of ``x`` (each column from rest), into ``y``: SciPy's
    ``lfilter(b, a, x, axis=0)`` for ``b`` and ``a`` of one length with ``a[0] = 1``, in the direct form II
    transposed and the order of operations of its recursive path (taken where ``a`` is longer than 1), so the
    same numbers, without importing ``scipy.signal`` (which imports most of SciPy)."""
    n = x.shape[0]
    K = b.shape[0]
    z = np.zeros(K)
    for c in range(x.shape[1]):
        for k in range(K):
            z[k] = 0.0
        for i in range(n):
            xn = x[i, c]
            if K > 1:
                yn = z[0] + b[0] * xn
                for k in range(K - 2):
                    z[k] = z[k + 1] + xn * b[k + 1] - yn * a[k + 1]
                z[K - 2] = xn * b[K - 1] - yn * a[K - 1]
            else:
                yn = xn * b[0]
            y[i, c] = yn


def var_backward(J, phi):
    """``X[m] = J[m] + sum_i phi_i' X[m+i]`` from the end: ``J`` filtered backwards through the model's inverse
    (shapes: ``J`` and ``X`` (n, d, q), ``phi`` (p, d, d))."""
    n = J.shape[0]
    d = J.shape[1]
    q = J.shape[2]
    p = phi.shape[0]
    X = np.zeros((n, d, q))
    for m in range(n - 1, -1, -1):
        for a in range(d):
            for c in range(q):
                s = J[m, a, c]
                for i in range(p):
                    if m + 1 + i < n:
                        for b in range(d):
                            s += phi[i, b, a] * X[m + 1 + i, b, c]
                X[m, a, c] = s
    return np.asarray(X)
