"""Polynomials on [0, 1] for the simulator kernel: evaluation, bounds, roots, Taylor shifts.

A polynomial is its coefficients ``c[0] + c[1] x + ... + c[n-1] x**(n-1)`` in a local variable ``x`` in
``[0, 1]`` (one piece of a response).  One source, three modes, as the kernels that call it (see
:mod:`delaykit._native`): compiled ahead of time by Cython (the C types are in ``_poly.pxd``; the kernels cimport
these functions, and the Loop kernel :mod:`._kernel` is built with this file in its own C module: ``FUSED`` in
``setup.py``), compiled by numba (``NUMBA_OPTIONS``: the small ones inlined), or run as plain Python.

Note that numba's cache of a compiled kernel does not notice edits of this file (see :mod:`._jit`).  Under
numba, the functions that are not inlined (:func:`refine`, :func:`all_cross`) allocate nothing and are compiled
without reference counting, as the kernel's piece loop (see :mod:`._kernel`).  This module is private.

Examples
--------
>>> import numpy as np
>>> from delaykit import _native
>>> p = _native.load("delaykit.simulate", "_poly")  # compiled (Cython, or numba where not built)
>>> c = np.array([-0.25, 0.0, 1.0])  # x**2 - 1/4
>>> p.horner(c, 3, 0.5), p.bounds(c, 3)
(0.0, (-0.25, 0.75, 0.75))
>>> round(p.first_cross(c, 3, 0.0, -1.0, np.empty(p.GRID + 1)), 15)  # its root, refined
0.5
"""

from __future__ import annotations

import math

import numpy as np

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

from ._layout import NC

__all__ = ["GRID", "MAXX", "STACK", "BINOMIAL", "grid_values", "horner", "horner_d", "poly_sum", "bounds", "refine",
           "first_cross", "all_cross", "crossings", "shift_scale", "scale", "degree", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

GRID = 16  # root searches evaluate the polynomial on this many subintervals of [0, 1]
DEPTH = 40  # bisections of a grid cell before a same-sign cell counts as a tangency (crossings)
MAXX = 64  # crossings kept per certified search
STACK = GRID + DEPTH + 4  # the certified search's stack of cells
BINOMIAL = np.array([[float(math.comb(j, k)) for k in range(NC)] for j in range(NC)])  # binomial coefficients
# the same as C values where compiled (the public names above stay Python's, for the modules that import them)
_GRID, _DEPTH, _MAXX, _NC = GRID, DEPTH, MAXX, NC
_XG = np.arange(GRID + 1) / GRID  # the grid's points, 0 ... 1
_BIN = BINOMIAL

# numba's options where it compiles this file (see delaykit._native): the small helpers inlined into their callers
NUMBA_OPTIONS = {"horner": {"inline": "always"}, "horner_d": {"inline": "always"}, "poly_sum": {"inline": "always"},
                 "bounds": {"inline": "always"}, "refine": {"_nrt": False}, "grid_values": {"inline": "always"},
                 "first_cross": {"inline": "always"}, "all_cross": {"_nrt": False},
                 "shift_scale": {"inline": "always"}, "scale": {"inline": "always"}, "degree": {"inline": "always"}}


def horner(c, n, x):
    s = 0.0
    for j in range(n - 1, -1, -1):
        s = s * x + c[j]
    return s


def horner_d(c, n, x):
    p = 0.0
    dp = 0.0
    for j in range(n - 1, -1, -1):
        dp = dp * x + p
        p = p * x + c[j]
    return p, dp


def poly_sum(c, n):
    s = 0.0
    for j in range(n):
        s += c[j]
    return s


def bounds(c, n):
    """Lower and upper bounds of the polynomial on [0, 1] (x**j lies in [0, 1]), and its value at 1 (the sum of its
    coefficients, as :func:`poly_sum`): one pass, three independent chains of additions."""
    lo = c[0]
    hi = c[0]
    s = 0.0 + c[0]  # (poly_sum's first addition: -0.0 becomes 0.0)
    for j in range(1, n):
        cj = c[j]
        s += cj
        # branch-free (the signs of Taylor coefficients follow no pattern a branch predictor learns): p is
        # max(cj, 0) and cj - p is min(cj, 0), exactly (signed zeros included), for |cj| below 2**1023
        p = 0.5 * (cj + abs(cj))
        hi += p
        lo += cj - p
    return lo, hi, s


def refine(c, n, target, lo, hi, slo):
    """Root of c(x) - target in [lo, hi], where the sign just right of lo is ``slo`` (safeguarded Newton)."""
    x = 0.5 * (lo + hi)
    for _ in range(200):
        f, df = horner_d(c, n, x)
        f -= target
        if f == 0.0:
            return x
        if f * slo > 0.0:
            lo = x
        else:
            hi = x
        if hi - lo <= 4e-16 * max(1.0, abs(x)):
            break
        xn = x - f / df if df != 0.0 else 0.5 * (lo + hi)
        if not (lo < xn < hi):
            xn = 0.5 * (lo + hi)
        if abs(xn - x) <= 1e-17:
            x = xn
            break
        x = xn
    return x


def grid_values(c, n, target, fs, i0):
    """``fs[i] = c(i / GRID) - target`` for the four grid points i = i0 ... i0 + 3, by Horner's rule on four
    independent chains at once (which the processor overlaps)."""
    x0 = _XG[i0]
    x1 = _XG[i0 + 1]
    x2 = _XG[i0 + 2]
    x3 = _XG[i0 + 3]
    s0 = 0.0
    s1 = 0.0
    s2 = 0.0
    s3 = 0.0
    for j in range(n - 1, -1, -1):
        cj = c[j]
        s0 = s0 * x0 + cj
        s1 = s1 * x1 + cj
        s2 = s2 * x2 + cj
        s3 = s3 * x3 + cj
    fs[i0] = s0 - target
    fs[i0 + 1] = s1 - target
    fs[i0 + 2] = s2 - target
    fs[i0 + 3] = s3 - target


def first_cross(c, n, target, s0, fs):
    """First x in (0, 1] where c(x) - target leaves the sign ``s0`` it has just right of 0; 2.0 if none.

    ``fs`` is work space of GRID + 1 numbers."""
    if n <= 1:
        return 2.0
    for i in range(1, _GRID + 1):
        if i % 4 == 1:
            grid_values(c, n, target, fs, i)
        f = fs[i]
        if f * s0 <= 0.0:
            if f == 0.0 and i == _GRID:
                return 1.0
            return refine(c, n, target, _XG[i - 1], _XG[i], s0)
    return 2.0


def all_cross(c, n, target, xs, fs):
    """All sign changes of c(x) - target in (0, 1), refined; returns their count (stored in xs).

    ``fs`` is work space of GRID + 1 numbers."""
    if n <= 1:
        return 0
    k = 0
    fp = c[0] - target
    for i in range(1, _GRID + 1):
        if i % 4 == 1:
            grid_values(c, n, target, fs, i)
        f = fs[i]
        if (fp < 0.0 and f >= 0.0) or (fp > 0.0 and f <= 0.0):
            if not (i == _GRID and f == 0.0):
                xs[k] = refine(c, n, target, _XG[i - 1], _XG[i], 1.0 if fp > 0.0 else -1.0)
                k += 1
        if f != 0.0:
            fp = f
    return k


def crossings(c, n, target, xs, sr, sd):
    """All points of (0, 1) where ``c(x) - target`` changes sign, in increasing order (at most ``MAXX``), with
    none missed (the certified isolation described in :mod:`._sampled_batch`); ``sr``, ``sd``: a stack of
    ``STACK`` right ends and depths.  A zero exactly at x = 1 is not a crossing (as :func:`all_cross`)."""
    if n <= 1:
        return 0
    b1 = 0.0
    b2 = 0.0
    size = abs(c[0]) + abs(target)
    for j in range(1, n):
        b1 += j * abs(c[j])
        b2 += j * (j - 1) * abs(c[j])
        size += abs(c[j])
    noise = 4.0 * n * 1.1102230246251565e-16 * size  # Horner's rounding on [0, 1], twice over
    top = 0
    for i in range(_GRID, 0, -1):
        sr[top] = _XG[i]  # i / GRID
        sd[top] = 0
        top += 1
    k = 0
    xl = 0.0
    fl = c[0] - target
    sl = fl  # the sign just right of xl: f's there, or the last non-zero value's (as all_cross carries it) ...
    if fl == 0.0:  # ... or, at 0 itself, the first non-zero coefficient's
        for j in range(1, n):
            if c[j] != 0.0:
                sl = c[j]
                break
    while top > 0:
        top -= 1
        r = sr[top]
        d = sd[top]
        fr = horner(c, n, r) - target
        w = r - xl
        change = (sl < 0.0 and fr >= 0.0) or (sl > 0.0 and fr <= 0.0)
        if change and r == 1.0 and fr == 0.0:
            change = False
        if sl == 0.0:  # f is the target itself
            ok = True
        elif change:  # f' keeps its sign on the cell: one root
            ok = abs(horner_d(c, n, xl)[1]) > w * b2
        else:  # f cannot reach 0 inside the cell
            ok = min(abs(fl), abs(fr)) > 0.125 * w * w * b2 or abs(fl) + abs(fr) > w * b1
        if not ok and abs(fl) <= noise and abs(fr) <= noise:
            ok = True  # f is at rounding level across the cell (a tangency): its sign there is not resolved
        if not ok and d < _DEPTH:
            sr[top] = r
            sd[top] = d + 1
            top += 1
            sr[top] = 0.5 * (xl + r)
            sd[top] = d + 1
            top += 1
            continue
        if change and k < _MAXX:
            xs[k] = refine(c, n, target, xl, r, 1.0 if sl > 0.0 else -1.0)
            k += 1
        xl = r
        fl = fr
        if fr != 0.0:
            sl = fr
    return k


def shift_scale(src, n, alpha, beta, dst, work):
    """dst(y) = src(alpha + beta*y): Taylor shift by alpha, then scale by beta (zeros above degree n-1).

    The shift sums the binomial expansion, ``dst[k] = sum_j C(j, k) alpha**(j-k) src[j]``: independent
    products rather than Horner's chain of dependent ones.  ``work`` is work space of NC numbers."""
    for k in range(_NC):
        dst[k] = 0.0
    if alpha == 0.0:
        for j in range(n):
            dst[j] = src[j]
    else:
        work[0] = 1.0
        for j in range(1, n):
            work[j] = work[j - 1] * alpha
        for j in range(n):
            t = src[j]
            for k in range(j + 1):
                dst[k] += _BIN[j, k] * work[j - k] * t
    if beta != 1.0:
        b = 1.0
        for j in range(n):
            dst[j] *= b
            b *= beta


def scale(c, n, s):
    b = 1.0
    for j in range(n):
        c[j] *= b
        b *= s


def degree(c, n):
    """Number of coefficients up to the last non-zero one (at least 1)."""
    while n > 1 and c[n - 1] == 0.0:
        n -= 1
    return n
