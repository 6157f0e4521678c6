"""Compiled inner loops of the root finder (:mod:`delaykit.spectrum.roots` is the interface).

A quasi-polynomial is held as arrays: ``C[j, :]`` the coefficients of term j (highest degree first, padded),
``A = |C|``, and ``tau[j]`` its delay.  ``qeval`` returns Q, Q' and a bound on the rounding error of Q.

One source, three modes (:mod:`delaykit._native` loads them): compiled ahead of time by Cython when the package is
built (the C types are in ``_rootkernel.pxd``; the extension module it makes is imported in place of this file),
compiled by numba on first use where no extension was built, or run as plain Python.  So the code here keeps to
what all three read alike: loops over arrays, ``math`` functions under the names C gives them, and arrays
made with ``np.empty``/``np.zeros`` (their memory written through a typed view when compiled by Cython).
"""

from __future__ import annotations

import numpy as np

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

if cython.compiled:  # C's own functions (Cython turns these imports into cimports)
    from cython.cimports.libc.math import HUGE_VAL, atan2, ceil, cos, exp, log, pi, sin
else:
    from math import atan2, ceil, cos, exp, log, pi, sin
    from math import inf as HUGE_VAL

__all__ = ["qeval", "stack_size", "stacks", "contour", "contour_into", "newton", "newton_into", "grid_minima", "bound",
           "bound_into", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

_EPS = 2.220446049250313e-16


def cexp(z):
    """exp(z) of a complex z from real functions, as C's cexp for finite z (and portable to C compilers without
    C99's complex functions, such as MSVC)."""
    r = exp(z.real)
    return r * cos(z.imag) + 1j * (r * sin(z.imag))


def _ipow(a, n):
    """``a ** n`` for a whole ``n >= 0`` by repeated squaring: the product numba forms for a float to an integer
    power, written out so that every mode rounds alike (C's ``pow`` rounds otherwise)."""
    r = 1.0
    while n != 0:
        if n & 1:
            r *= a
        n >>= 1
        a *= a
    return r


def clog(z):
    """The principal log(z) of a complex z, from real functions (as :func:`cexp`)."""
    return log(abs(z)) + 1j * atan2(z.imag, z.real)


def qeval(C, A, tau, s):
    nt = C.shape[0]
    n1 = C.shape[1]
    Q = 0j
    dQ = 0j
    nz = 0.0
    abs_s = abs(s)
    for j in range(nt):
        p = 0j
        dp = 0j
        pa = 0.0
        for k in range(n1):
            dp = dp * s + p
            p = p * s + C[j, k]
            pa = pa * abs_s + A[j, k]
        e = cexp(-s * tau[j])
        Q += p * e
        dQ += (dp - tau[j] * p) * e
        nz += pa * abs(e)
    return Q, dQ, (n1 + 1) * _EPS * nz


def stack_size(n_init):
    """The length of :func:`contour_into`'s stacks for edges of ``n_init`` initial segments: the initial segments of
    one edge, plus up to 63 entries for each of 64 levels of refinement below them."""
    size = 0
    for e in range(n_init.shape[0]):
        size = max(size, n_init[e])
    return size + 64 * 64


def stacks(size):
    """:func:`contour_into`'s six stacks, ``size`` long: endpoints ``sa``, ``sb``, Q values ``wa``, ``wb`` (complex),
    and ``|Q'/Q|`` ``ra``, ``rb``."""
    return (np.empty(size, np.complex128), np.empty(size, np.complex128), np.empty(size, np.complex128),
            np.empty(size, np.complex128), np.empty(size), np.empty(size))


def contour(C, A, tau, corners, n_init, max_phase, reliable, cap, out_s, out_dl):
    """Adaptive phase tracking around the closed polygon ``corners``.

    Returns ``(status, winding, m, where)``: status 0 = fine, 1 = a root on/next to the boundary at ``where``,
    2 = more than ``cap`` samples needed.  ``out_s[:m]`` and ``out_dl[:m]`` receive segment midpoints and log
    increments of Q (for contour-integral moments).
    """
    sa, sb, wa, wb, ra, rb = stacks(stack_size(n_init))
    return contour_into(C, A, tau, corners, n_init, max_phase, reliable, cap, out_s, out_dl, sa, sb, wa, wb, ra, rb)


def contour_into(C, A, tau, corners, n_init, max_phase, reliable, cap, out_s, out_dl, sa, sb, wa, wb, ra, rb):
    """:func:`contour` with its stack of segments given (endpoints ``sa``, ``sb``, Q values ``wa``, ``wb`` and
    ``|Q'/Q|`` ``ra``, ``rb``; each at least :func:`stack_size` long): allocates nothing, runs without the GIL."""
    nc = corners.shape[0]
    total = 0.0
    m = 0
    size = stack_size(n_init)
    for e in range(nc):
        a0 = corners[e]
        b0 = corners[(e + 1) % nc]
        n = n_init[e]
        # push the segments of this edge in reverse so they are processed from a0 to b0
        top = 0
        prev_s = b0
        Qp, dQp, nzp = qeval(C, A, tau, prev_s)
        if abs(Qp) <= reliable * nzp:
            return 1, total, m, prev_s
        prev_w = Qp
        prev_r = abs(dQp / Qp)
        for i in range(n - 1, -1, -1):
            s0 = a0 + (b0 - a0) * (i / n)
            Q0, dQ0, nz0 = qeval(C, A, tau, s0)
            if abs(Q0) <= reliable * nz0:
                return 1, total, m, s0
            if top >= size:  # cannot happen: size covers n
                return 2, total, m, s0
            sa[top] = s0
            wa[top] = Q0
            ra[top] = abs(dQ0 / Q0)
            sb[top] = prev_s
            wb[top] = prev_w
            rb[top] = prev_r
            top += 1
            prev_s = s0
            prev_w = Q0
            prev_r = ra[top - 1]
        while top > 0:
            top -= 1
            a = sa[top]
            b = sb[top]
            qa = wa[top]
            qb = wb[top]
            r_a = ra[top]
            r_b = rb[top]
            dl = clog(qb / qa)
            h = abs(b - a)
            need = max(max(abs(dl.imag), h * max(r_a, r_b)) / max_phase, abs(dl.real) / 2.0)
            if need <= 1.0:
                total += dl.imag
                if m < out_s.shape[0]:
                    out_s[m] = 0.5 * (a + b)
                    out_dl[m] = dl
                m += 1
                if m > cap:
                    return 2, total, m, a
                continue
            k = int(ceil(1.5 * need))
            k = max(2, min(64, k))
            if top + k >= size:  # refinement deeper than 64 levels
                return 2, total, m, a
            # sub-segments, pushed in reverse
            nxt_s = b
            nxt_w = qb
            nxt_r = r_b
            for i in range(k - 1, 0, -1):
                si = a + (b - a) * (i / k)
                Qi, dQi, nzi = qeval(C, A, tau, si)
                if abs(Qi) <= reliable * nzi:
                    return 1, total, m, si
                ri = abs(dQi / Qi)
                sa[top] = si
                wa[top] = Qi
                ra[top] = ri
                sb[top] = nxt_s
                wb[top] = nxt_w
                rb[top] = nxt_r
                top += 1
                nxt_s = si
                nxt_w = Qi
                nxt_r = ri
            sa[top] = a
            wa[top] = qa
            ra[top] = r_a
            sb[top] = nxt_s
            wb[top] = nxt_w
            rb[top] = nxt_r
            top += 1
    return 0, total / (2.0 * pi), m, 0j


def newton(C, A, tau, s0, maxit, box):
    """Newton from each start.  Returns points, converged flags, and clean flags (a vanishing step)."""
    n = s0.shape[0]
    out = np.empty(n, np.complex128)
    conv = np.zeros(n, np.uint8)  # flags as bytes (Cython writes them through a typed view), bool on return
    clean = np.zeros(n, np.uint8)
    newton_into(C, A, tau, s0, maxit, box, out, conv, clean)
    return np.asarray(out), np.asarray(conv) != 0, np.asarray(clean) != 0


def newton_into(C, A, tau, s0, maxit, box, out, conv, clean):
    """:func:`newton` into ``out``, ``conv`` and ``clean`` (flags as bytes, 1 for true): allocates nothing, runs
    without the GIL."""
    n = s0.shape[0]
    x0, x1, y0, y1 = box[0], box[1], box[2], box[3]
    for i in range(n):
        conv[i] = 0
        clean[i] = 0
        s = s0[i]
        for _ in range(maxit):
            Q, dQ, nz = qeval(C, A, tau, s)
            if abs(Q) <= nz:
                conv[i] = 1
                # at the noise floor a simple root still has a tiny Newton step; a multiple root does not
                if dQ != 0 and abs(Q / dQ) <= 1e-10 * (1.0 + abs(s)):
                    clean[i] = 1
                break
            if dQ == 0:
                break
            step = Q / dQ
            s = s - step
            if not (abs(s) < 1e8):
                break
            if abs(step) <= 64 * _EPS * (1.0 + abs(s)):
                conv[i] = 1
                clean[i] = 1
                break
            if s.real < x0 or s.real > x1 or s.imag < y0 or s.imag > y1:
                break
        out[i] = s


def grid_minima(C, tau, xs, ys):
    """Grid nodes (interior) where |Q| is not larger than at any of the 8 neighbours."""
    nx = xs.shape[0]
    ny = ys.shape[0]
    nt = C.shape[0]
    n1 = C.shape[1]
    # exp(-(x + i y) tau) = exp(-x tau) exp(-i y tau): one factor per column and one per row
    EX = np.empty((nt, nx))
    EY = np.empty((nt, ny), np.complex128)
    for j in range(nt):
        for ix in range(nx):
            EX[j, ix] = exp(-xs[ix] * tau[j]) if -xs[ix] * tau[j] < 700.0 else HUGE_VAL
        for iy in range(ny):
            EY[j, iy] = cexp(-1j * ys[iy] * tau[j])
    V = np.empty((ny, nx))
    for iy in range(ny):
        for ix in range(nx):
            s = xs[ix] + 1j * ys[iy]
            Q = 0j
            for j in range(nt):
                p = 0j
                for k in range(n1):
                    p = p * s + C[j, k]
                Q += p * (EX[j, ix] * EY[j, iy])
            a = abs(Q)
            V[iy, ix] = a if a == a and a < HUGE_VAL else HUGE_VAL
    out = np.empty(nx * ny, np.complex128)
    k = 0
    for iy in range(1, ny - 1):
        for ix in range(1, nx - 1):
            v = V[iy, ix]
            if v == HUGE_VAL:
                continue
            ok = True
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    if (di != 0 or dj != 0) and V[iy + di, ix + dj] < v:
                        ok = False
            if ok:
                out[k] = xs[ix] + 1j * ys[iy]
                k += 1
    return np.asarray(out)[:k]


def bound(C, tau, x):
    """The smallest ``R`` with ``|Q(s)| > 0`` for ``|s| >= R``, ``Re s >= x`` (Cauchy's form of
    :func:`~delaykit.spectrum.roots.root_bound`: the positive root of ``lead - sum rest_k r^-k``, which increases
    in ``r``), or -1 where no such bound exists (no delay-free term of positive degree, neutral chains at or
    right of ``x``, or an advanced term)."""
    n1 = C.shape[1]
    return bound_into(C, tau, x, np.zeros(n1, np.complex128), np.zeros(n1))


def bound_into(C, tau, x, p0, oth):
    """:func:`bound` with its work vectors given (``p0``, ``oth``: as long as a row of ``C``): allocates nothing,
    runs without the GIL."""
    nt = C.shape[0]
    n1 = C.shape[1]
    for k in range(n1):
        p0[k] = 0j
        oth[k] = 0.0
    for j in range(nt):
        if tau[j] == 0.0:
            for k in range(n1):
                p0[k] += C[j, k]
        else:
            g = -x * tau[j]
            if g > 700.0:
                return -1.0
            for k in range(n1):
                oth[k] += abs(C[j, k]) * exp(g)
    k0 = -1
    for k in range(n1):
        if p0[k] != 0:
            k0 = k
            break
    if k0 < 0 or k0 == n1 - 1:
        return -1.0
    for k in range(k0):
        if oth[k] != 0.0:
            return -1.0
    lead = abs(p0[k0]) - oth[k0]
    if not lead > 0.0:
        return -1.0
    hi = 0.0
    for k in range(1, n1 - k0):  # Fujiwara's bound: g(hi) > 0
        hi = max(hi, 2.0 * (((abs(p0[k0 + k]) + oth[k0 + k]) / lead) ** (1.0 / k)))
    if hi == 0.0:
        return 1e-12
    lo = 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        g = lead
        for k in range(1, n1 - k0):
            g -= (abs(p0[k0 + k]) + oth[k0 + k]) * (1.0 / _ipow(mid, k))  # mid ** -k, as numba forms it
        if g > 0.0:
            hi = mid
        else:
            lo = mid
        if hi - lo <= 1e-12 * hi:
            break
    return hi
