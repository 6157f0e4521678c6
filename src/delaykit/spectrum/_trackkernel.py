"""Compiled loop of the stability map (:func:`delaykit.spectrum.stability.stability_map` is the interface).

``track`` follows the points of a grid, one quasi-polynomial a row of ``W``: Newton's method from the previous
point's rightmost roots gives a candidate, and one argument-principle count on the region that holds every root
right of it confirms it (the root kernel's ``newton_into``, ``bound_into`` and ``contour_into``).  It allocates its
work space, then runs :func:`track_points` without the GIL, so the map's threads run side by side.

One source, three modes (:mod:`delaykit._native`), as ``_rootkernel.py``: compiled ahead of time by Cython
(``_trackkernel.pxd``; the root kernel cimported from its extension), compiled by numba where no extension was built
(the root kernel numba's copy too; :func:`track` is left to Python, which calls the compiled, GIL-free
``track_points``: see ``PYTHON_ONLY``), or run as plain Python.
"""

from __future__ import annotations

import numpy as np

try:
    import cython
except ImportError:  # plain Python without Cython installed: ``cython.compiled`` and ``cython.nogil`` are read
    from contextlib import nullcontext
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False, nogil=nullcontext())

if cython.compiled:  # the root kernel's extension, called in C; C's floor
    from cython.cimports.delaykit.spectrum._rootkernel import bound_into, contour_into, newton_into, stack_size, stacks
    from cython.cimports.libc.math import floor
else:  # the root kernel of this module's own mode (numba's copy calls numba's)
    from math import floor

    from delaykit import _native

    _rk = _native.sibling(__name__, "_rootkernel")
    bound_into, contour_into, newton_into = _rk.bound_into, _rk.contour_into, _rk.newton_into
    stack_size, stacks = _rk.stack_size, _rk.stacks

__all__ = ["track", "track_points", "COMPILED", "PYTHON_ONLY"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

PYTHON_ONLY = ("track",)
"""Functions numba leaves alone in mode numba (:func:`delaykit._native.load`): ``track`` releases the GIL in a
``with`` block numba cannot compile; it calls ``track_points``, which numba compiles without the GIL."""

_STACK = 1 << 14  # the contour's first stacks; grown (and the point done again) when a point needs more


def track(Wc, Wt, nt, n1, k0, starts, nstart, sym, absc, max_phase, reliable, cap):
    """Points ``k0, k0 + 1, ...`` of ``Wc``, ``Wt`` (one quasi-polynomial a row: its coefficients, ``nt`` terms of
    ``n1``, term after term, and its ``nt`` delays), each from Newton's method started at the previous point's
    roots right of its abscissa (``starts[:nstart]``, updated), confirmed by one argument-principle count.  Writes
    each confirmed point's abscissa into ``absc``; stops at the first point not confirmed.  Returns its index
    (``Wc.shape[0]`` when all are) and the number of starts."""
    C = np.empty((nt, n1), np.complex128)
    A = np.empty((nt, n1))
    tau = np.empty(nt)
    found = np.empty(2 * starts.shape[0], np.complex128)
    sout = np.empty(starts.shape[0], np.complex128)
    conv = np.empty(starts.shape[0], np.uint8)
    clean = np.empty(starts.shape[0], np.uint8)
    p0 = np.empty(n1, np.complex128)
    oth = np.empty(n1)
    box = np.empty(4)
    box[0] = -1e300
    box[1] = 1e300
    box[2] = -1e300
    box[3] = 1e300
    n_init = np.empty(4, np.int64)
    corners = np.empty(4, np.complex128)
    cs = corners
    csr = corners.view(np.float64)  # the corners' parts, written one by one (exactly: no complex arithmetic)
    buf = np.empty(1, np.complex128)
    buf2 = np.empty(1, np.complex128)
    state = np.empty(2, np.int64)  # the number of starts; the stack a point needs (0: enough)
    size = _STACK
    k = k0
    while True:
        sa, sb, wa, wb, ra, rb = stacks(size)
        state[0] = nstart
        state[1] = 0
        with cython.nogil:
            k = track_points(Wc, Wt, nt, n1, k, starts, absc, sym, max_phase, reliable, cap, C, A, tau, found,
                             sout, conv, clean, p0, oth, box, n_init, cs, csr, buf, buf2, sa, sb, wa, wb, ra, rb,
                             state)
        nstart = state[0]
        if state[1] == 0:
            return k, nstart
        size = 2 * state[1]


def track_points(Wc, Wt, nt, n1, k0, starts, absc, sym, max_phase, reliable, cap, C, A, tau, found, sout, conv,
                 clean, p0, oth, box, n_init, cs, csr, buf, buf2, sa, sb, wa, wb, ra, rb, state):
    """:func:`track` with its work space given (``csr``: the real view of ``cs``; the contour's stacks ``sa`` to
    ``rb``, of one length; the number of starts in ``state[0]``, updated; ``state[1]`` set to the stack a point
    needs where it is longer, the point then not done): allocates nothing, runs without the GIL.  Returns the
    index of the first point not done."""
    nstart = state[0]
    for k in range(k0, Wc.shape[0]):
        taumax = 0.0
        for i in range(nt):
            for j in range(n1):
                C[i, j] = Wc[k, i * n1 + j]
                A[i, j] = abs(C[i, j])
            tau[i] = Wt[k, i]
            if i == 0 or tau[i] > taumax:
                taumax = tau[i]
        newton_into(C, A, tau, starts[:nstart], 60, box, sout[:nstart], conv[:nstart], clean[:nstart])
        nf = 0
        for i in range(nstart):
            if conv[i] == 0 or clean[i] == 0:
                continue
            z = sout[i]
            if sym and abs(z.imag) <= 1e-10 * (1.0 + abs(z)):
                z = z.real + 0j
            for c in range(2 if sym and z.imag != 0.0 else 1):
                zz = z if c == 0 else z.conjugate()
                new = True
                for m in range(nf):
                    if abs(found[m] - zz) <= 1e-9 * (1.0 + abs(zz)):
                        new = False
                if new and nf < found.shape[0]:
                    found[nf] = zz
                    nf += 1
        if nf == 0:
            state[0] = nstart
            return k
        top = found[0]
        for m in range(1, nf):
            if found[m].real > top.real or (found[m].real == top.real and found[m].imag > top.imag):
                top = found[m]
        x = top.real - 1e-6 * (1.0 + abs(top))
        R = bound_into(C, tau, x, p0, oth)
        if R < 0.0:
            state[0] = nstart
            return k
        R = max(R, abs(top)) * (1.0 + 1e-9) + 1e-12
        y0 = -1e-3 * (1.0 + abs(top)) if sym else -R  # a real q: the upper half, its real roots inside
        csr[0] = x  # the corners x + i y0, R + i y0, R + i R, x + i R
        csr[1] = y0
        csr[2] = R
        csr[3] = y0
        csr[4] = R
        csr[5] = R
        csr[6] = x
        csr[7] = R
        total_init = 0
        for e in range(4):
            ni = int(abs(cs[(e + 1) % 4] - cs[e]) * (taumax + 0.25) / max_phase)
            n_init[e] = 8 + ni
            total_init += n_init[e]
        if total_init > cap:
            state[0] = nstart
            return k
        if stack_size(n_init) > sa.shape[0]:  # (nothing of this point kept: it is done again on longer stacks)
            state[0] = nstart
            state[1] = stack_size(n_init)
            return k
        status, total, used, where = contour_into(C, A, tau, cs, n_init, max_phase, reliable, cap, buf, buf2, sa,
                                                  sb, wa, wb, ra, rb)
        want = 0
        for m in range(nf):
            if found[m].real > x and found[m].imag > y0:
                want += 1
        nearest = floor(total + 0.5)  # the nearest whole number (where it is within 0.05, as round gives it)
        if status != 0 or abs(total - nearest) > 0.05 or nearest != want:
            state[0] = nstart
            return k
        absc[k] = top.real  # (a neutral loop's chains lie left of x, where the bound holds)
        nstart = 0
        for m in range(nf):
            if found[m].real > x and found[m].imag >= 0.0 and nstart < starts.shape[0]:
                starts[nstart] = found[m]
                nstart += 1
    state[0] = nstart
    return Wc.shape[0]
