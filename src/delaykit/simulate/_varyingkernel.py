"""Compiled event loop of the varying-delay simulator (:mod:`delaykit.simulate.varying` is the interface).

``events`` walks the sorted events of a sampled loop whose packets arrive late by varying delays: ``z`` (the
plant's and the controller's states, the plant's input and the reference) moves exactly between events by
``exp(M tau)`` (:mod:`delaykit.models._expmkernel`), a sample computes a command, an arrival switches the input,
a record writes a row.

One source, three modes (:mod:`delaykit._native`), as ``spectrum/_rootkernel.py``: compiled ahead of time by
Cython (``_varyingkernel.pxd``; the exponential cimported from the models' extension), compiled by numba where no
extension was built (the exponential numba's copy too), or run as plain Python.
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

__all__ = ["events", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""


def events(M, rows, lo, hi, r, ev_t, ev_kind, ev_idx, u_cmd, rec):
    """Walk the sorted events: 0 = a sample (packet ev_idx), 1 = an arrival (packet ev_idx takes over), 2 = a
    record (row ev_idx: y, the input, y' just after and just before).  ``z`` is the state, then the plant's input
    and the reference, constant between events, where ``z' = M z`` moves it exactly by ``exp(M tau)``."""
    q = M.shape[0]
    n = q - 2
    z = np.zeros(q)
    zn = np.zeros(q)
    z[n + 1] = r
    E = np.zeros((q, q))
    X = np.empty((q, q))
    T = np.empty((q, q))
    W = np.empty((q, q))
    for i in range(q):
        E[i, i] = 1.0
    t = 0.0
    last = -1.0
    t_switch = -1.0
    w_left = 0.0
    for e in range(ev_t.shape[0]):
        tau = ev_t[e] - t
        if tau > 0.0:
            if tau != last:
                for i in range(q):
                    for j in range(q):
                        X[i, j] = M[i, j] * tau
                expm_into(X, E, T, W)
                last = tau
            for i in range(q):
                acc = 0.0
                for j in range(q):
                    acc += E[i, j] * z[j]
                zn[i] = acc
            for i in range(q):
                z[i] = zn[i]
            t = ev_t[e]
        k = ev_kind[e]
        i = ev_idx[e]
        if k == 0:
            v = 0.0
            for j in range(q):
                v += rows[2, j] * z[j]
            u_cmd[i] = min(max(v, lo), hi)
        elif k == 1:
            if t_switch != t:
                w_left = z[n]
                t_switch = t
            z[n] = u_cmd[i]
        else:
            y = 0.0
            dy = 0.0
            for j in range(q):
                y += rows[0, j] * z[j]
                dy += rows[1, j] * z[j]
            rec[i, 0] = y
            rec[i, 1] = z[n]
            rec[i, 2] = dy
            rec[i, 3] = dy - rows[1, n] * (z[n] - w_left) if t_switch == t else dy
