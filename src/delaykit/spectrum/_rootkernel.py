"""Compiled inner loops of the root finder (:mod:`delaykit.spectrum.roots` is the interface).

A quasi-polynomial is held as arrays: ``C[j, :]`` the coefficients of term j (highest degree first, padded),
``A = |C|``, and ``tau[j]`` its delay.  ``qeval`` returns Q, Q' and a bound on the rounding error of Q.
"""

from __future__ import annotations

import cmath
import math

import numpy as np
from numba import njit

__all__ = ["qeval", "contour", "newton", "grid_minima"]

_EPS = 2.220446049250313e-16


@njit(cache=True)
def qeval(C, A, tau, s):
    nt, n1 = C.shape
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
        e = cmath.exp(-s * tau[j])
        Q += p * e
        dQ += (dp - tau[j] * p) * e
        nz += pa * abs(e)
    return Q, dQ, (n1 + 1) * _EPS * nz


@njit(cache=True)
def contour(C, A, tau, corners, n_init, max_phase, reliable, cap, out_s, out_dl):
    """Adaptive phase tracking around the closed polygon ``corners``.

    Returns ``(status, winding, m, where)``: status 0 = fine, 1 = a root on/next to the boundary at ``where``,
    2 = more than ``cap`` samples needed.  ``out_s[:m]`` and ``out_dl[:m]`` receive segment midpoints and log
    increments of Q (for contour-integral moments).
    """
    nc = corners.shape[0]
    total = 0.0
    m = 0
    # explicit stack of segments: endpoints, Q values and |Q'/Q| (the initial segments of one edge, plus up
    # to 63 entries for each level of refinement below them)
    size = 0
    for e in range(nc):
        size = max(size, n_init[e])
    size += 64 * 64
    sa = np.empty(size, np.complex128)
    sb = np.empty(size, np.complex128)
    wa = np.empty(size, np.complex128)
    wb = np.empty(size, np.complex128)
    ra = np.empty(size)
    rb = np.empty(size)
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
            dl = cmath.log(qb / qa)
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
            k = int(math.ceil(1.5 * need))
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
    return 0, total / (2.0 * math.pi), m, 0j


@njit(cache=True)
def newton(C, A, tau, s0, maxit, box):
    """Newton from each start.  Returns points, converged flags, and clean flags (a vanishing step)."""
    n = s0.shape[0]
    out = np.empty(n, np.complex128)
    conv = np.zeros(n, np.bool_)
    clean = np.zeros(n, np.bool_)
    x0, x1, y0, y1 = box[0], box[1], box[2], box[3]
    for i in range(n):
        s = s0[i]
        for _ in range(maxit):
            Q, dQ, nz = qeval(C, A, tau, s)
            if abs(Q) <= nz:
                conv[i] = True
                # at the noise floor a simple root still has a tiny Newton step; a multiple root does not
                if dQ != 0 and abs(Q / dQ) <= 1e-10 * (1.0 + abs(s)):
                    clean[i] = True
                break
            if dQ == 0:
                break
            step = Q / dQ
            s = s - step
            if not (abs(s) < 1e8):
                break
            if abs(step) <= 64 * _EPS * (1.0 + abs(s)):
                conv[i] = True
                clean[i] = True
                break
            if s.real < x0 or s.real > x1 or s.imag < y0 or s.imag > y1:
                break
        out[i] = s
    return out, conv, clean


@njit(cache=True)
def grid_minima(C, tau, xs, ys):
    """Grid nodes (interior) where |Q| is not larger than at any of the 8 neighbours."""
    nx = xs.shape[0]
    ny = ys.shape[0]
    nt, n1 = C.shape
    # exp(-(x + i y) tau) = exp(-x tau) exp(-i y tau): one factor per column and one per row
    EX = np.empty((nt, nx))
    EY = np.empty((nt, ny), np.complex128)
    for j in range(nt):
        for ix in range(nx):
            EX[j, ix] = math.exp(-xs[ix] * tau[j]) if -xs[ix] * tau[j] < 700.0 else np.inf
        for iy in range(ny):
            EY[j, iy] = cmath.exp(-1j * ys[iy] * tau[j])
    V = np.empty((ny, nx))
    for iy in range(ny):
        for ix in range(nx):
            s = complex(xs[ix], ys[iy])
            Q = 0j
            for j in range(nt):
                p = 0j
                for k in range(n1):
                    p = p * s + C[j, k]
                Q += p * (EX[j, ix] * EY[j, iy])
            a = abs(Q)
            V[iy, ix] = a if a == a and a < np.inf else np.inf
    out = np.empty(nx * ny, np.complex128)
    k = 0
    for iy in range(1, ny - 1):
        for ix in range(1, nx - 1):
            v = V[iy, ix]
            if v == np.inf:
                continue
            ok = True
            for di in range(-1, 2):
                for dj in range(-1, 2):
                    if (di != 0 or dj != 0) and V[iy + di, ix + dj] < v:
                        ok = False
            if ok:
                out[k] = complex(xs[ix], ys[iy])
                k += 1
    return out[:k]
