"""The exact time response of a system with internal delays: the method of steps with Taylor pieces.

The system (:class:`delaykit.systems.DelayLTI`, reduced by :mod:`delaykit.simulate.systems` so that every channel
either has a delay or is a saturation without one) is, on each piece ``[a, a + H]`` in the local variable
``x = (t - a) / H``::

    X' = A X + B1 U + B2 W        (X, U, W polynomials in x; ' is d/dx divided by H)
    Y  = C1 X + D11 U + D12 W
    Z  = C2 X + D21 U + D22 W     V_c = sat_c(Z_c)   (the channel's signal, stored)
    W_c(t) = V_c(t - tau_c)       (tau_c > 0: read from the stored pieces; tau_c = 0: V_c itself)

The inputs are piecewise linear between knots (a step, or the samples of a forced response); before 0 every signal
is 0 and the states are at rest (at ``x0`` at 0+).  The states are truncated Taylor series,
``X[k+1] = H (A X[k] + B1 U[k] + B2 W[k]) / (k + 1)``, with the delayed channels' coefficients known before the
piece and those of a saturation without delay formed in the same recursion (its limit's constant while it is
saturated; two such saturations never feed each other directly, checked before).

Each piece's degree ``K`` (at most ``DEG``) is the least whose remainder is provably below rounding.  With
``e_k = max_i |X_i[k]| 2^k`` (the coefficients' size on ``[0, 2]``: a stored piece is read up to twice its length
past its start), ``a = 2 H ||A||`` and ``||B2||`` the (weighted, below) infinity norms bounding the states' matrix
and the delayed channels' map to the derivative in every regime of the saturations (``|A| + |B2_S| |C2_S|``), the
recursion gives ``e_{k+1} <= (a e_k + 2^(k+1) H ||B2|| max_c |W_c[k]|) / (k + 1)`` once the inputs' (linear)
coefficients are past, and summing over ``k >= K``::

    sum_{k > K} e_k  <=  (a e_K + 2 H ||B2|| sum_{k >= K} 2^k max_c |W_c[k]|) / (K + 1 - a)     (K + 1 > a)

``K`` is the least degree (at least 2, and past the delayed channels' coefficients that sum, weighted by ``2^k``,
to more than ``u`` of their largest) where this bound is at most ``u`` (the unit roundoff, ``2^-53``) times the
states' largest coefficient of degree 1 or more (the values at the start count for ``1e-6`` of theirs): a
truncation error, unlike rounding, has the same sign from piece to piece and adds up, so it is held below the
rounding of what changes on the piece.  The norms are weighted (``diag(v)^-1 A diag(v)``, ``v`` close to the
Perron vector of ``|A|``, largest entry 1; ``e_k`` with ``|X_i[k]| / v_i``): any positive weights keep the bound
rigorous, these keep ``a`` near the spectral radius of ``|A|`` where the plain norm of a companion matrix is far
above it.  A piece where even ``DEG`` does not meet it is redone at half its length.  (Wood-Berry's pieces, a
minute long, take degree 11 to 17 this way, against 24 for every piece before, and its responses did not move.)
A piece ends at:

* a *breakpoint image*: each channel keeps the times where its signal ``V_c`` is not analytic, with the order of
  the lowest derivative that jumps there (0: the value); ``tau_c`` later, ``W_c`` is not analytic, and every
  channel ``i`` gets a breakpoint there of that order plus the relative degree of the path from ``W_c`` to ``V_i``
  (0 through ``D22``, ``r`` through ``r`` integrations: ``C2 A^(r-1) B2``).  A breakpoint whose order exceeds
  ``DEG`` is analytic to the truncation accepted everywhere and is dropped, so a retarded system images each
  source at most ``DEG + 1`` times.  The jump of the signal and its derivatives at a breakpoint is also measured
  once the piece after it is known (left and right polynomials, derivatives scaled to the shortest of the
  channel's delay and ``hmax``); below ``_JUMP`` times the channel's scale the breakpoint is dropped: a neutral
  system's jumps (a path of relative degree 0, ``D22``) fade this way when its difference operator is strongly
  stable;
* a knot of the inputs (its order: 0 where the value jumps, 1 where the slope changes), and the start (the
  inputs and the initial state, with the orders given by the caller);
* a saturation switch: the first root in the piece of ``Z_c - limit`` leaving the channel's present regime,
  refined by bisection; the piece is cut there by rescaling its polynomials (the same analytic solution).  A switch
  is a breakpoint of order 1 (a kink) of the channel (delayed) or of every channel it reaches (without delay);
* ``hmax`` (the reciprocal of the fastest rate of the recursion), and twice the length of the stored piece a
  delayed channel is read from, past that piece's start (a stored piece extrapolated far would amplify the
  rounding of its high coefficients).  Points where a piece ended for length or for another channel are not
  breakpoints of a channel: the stored polynomial of an analytic signal is its Taylor series past its end.

Outputs are evaluated on the pieces at the requested times (right limits at a jump), or their derivative (the
impulse response of a linear system is the step response's derivative; the jumps of the step response, recorded
here, are its Dirac terms).

One source, three modes (:mod:`delaykit._native`): compiled by Cython from this file and ``_ltikernel.pxd``, by
numba, or run as plain Python.  This module is private: :mod:`delaykit.simulate.systems` is its interface.
"""

from __future__ import annotations

import numpy as np

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

if cython.compiled:  # C's own functions (Cython turns these imports into cimports), OpenMP's threads
    from cython.cimports.libc.math import fabs, isfinite
    from cython.parallel import prange, threadid
else:  # (prange and threadid: run_batch, their one user, is called in compiled mode only)
    from math import fabs, isfinite

__all__ = ["run", "run_batch", "work_sizes", "DEG", "NC", "NINFO", "STATUS_OK", "STATUS_CAPACITY", "STATUS_STALLED",
           "STATUS_OVERFLOW", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

DEG = 24  # the Taylor polynomials' degree (as the Loop kernel's)
NC = DEG + 1
NINFO = 4  # info: status, pieces, jumps recorded, the time reached
STATUS_OK = 0
STATUS_CAPACITY = 1  # the history or the breakpoint lists are full: the caller retries with more room
STATUS_STALLED = 2  # a saturation's regime could not be settled at a point (chattering)
STATUS_OVERFLOW = 3  # a value left the floating-point range (an unstable system over a long horizon)
# the same, typed for the compiled loops (the names above are for Python)
_DEG = 24
_NC = 25
_OK = 0
_CAPACITY = 1
_STALLED = 2
_OVERFLOW = 3

_EPS = 2.220446049250313e-16
_NAN = float("nan")
_JUMP = 16.0 * _EPS  # a breakpoint's jump, relative to its channel's scale, below which it is not imaged
_LIN = 0
_HIGH = 1
_LOW = 2
# a piece is redone at half its length when degree _DEG does not bring the remainder's bound (see the module
# docstring) below _TRUNC of the states' largest coefficient (the rates of the loop through its delays can exceed
# those of its states' matrix), and the next may grow to twice its length, up to _GROW hmax, when this one needed
# at most _NGROW coefficients
_TRUNC = 0.5 * _EPS
_FLOOR = 1e-6  # (the values at the start count for this much in the scale the remainder is measured against)
_NGROW = 17
_GROW = 4.0
_SELF = 0.125  # a delay at most this times hmax is read from the piece being built (as the Loop kernel)
_PICARD = 200  # fixed-point passes of a self-read piece before it is redone shorter
_PICARD_TOL = 4.0 * _EPS
_GRIDN = 32  # grid of the switch search on a piece
_MODE_TRIES = 8


def _shift_scale(src, n, alpha, beta, dst, work):
    """``dst(y) = src(alpha + beta y)`` for a polynomial of ``n`` coefficients (lowest first)."""
    for k in range(n):
        dst[k] = 0.0
    if alpha == 0.0:
        for j in range(n):
            dst[j] = src[j]
    else:
        for j in range(n):  # synthetic division: Taylor shift by alpha
            work[j] = src[j]
        for i in range(n - 1):
            for j in range(n - 2, i - 1, -1):
                work[j] += alpha * work[j + 1]
        for j in range(n):
            dst[j] = work[j]
    if beta != 1.0:
        b = 1.0
        for j in range(n):
            dst[j] *= b
            b *= beta


def _horner(c, n, x):
    s = 0.0
    for j in range(n - 1, -1, -1):
        s = s * x + c[j]
    return s


def _horner_d(c, n, x):
    s = 0.0
    for j in range(n - 1, 0, -1):
        s = s * x + j * c[j]
    return s


def _first_exit(c, n, level, up, x0):
    """The first ``x`` in ``(x0, 1]`` where ``c(x) - level`` turns positive (``up``) or negative (not ``up``),
    refined by bisection; 2.0 if it does not."""
    sgn = 1.0 if up else -1.0
    prev = x0
    for g in range(1, _GRIDN + 1):
        x = x0 + (1.0 - x0) * g / _GRIDN
        f = sgn * (_horner(c, n, x) - level)
        if f > 0.0:
            lo = prev
            hi = x
            for it in range(80):
                mid = 0.5 * (lo + hi)
                if mid <= lo or mid >= hi:
                    break
                if sgn * (_horner(c, n, mid) - level) > 0.0:
                    hi = mid
                else:
                    lo = mid
            return hi
        prev = x
    return 2.0


def _add_bp(bp_t, bp_o, bp_n, c, t, order, tol):
    """Record a breakpoint of channel ``c`` at ``t`` (the latest time so far) of ``order``; merged with one at
    the same time (lowest order kept).  Returns False when the list is full."""
    k = bp_n[c]
    if k > 0 and fabs(bp_t[c, k - 1] - t) <= tol:
        if order < bp_o[c, k - 1]:
            bp_o[c, k - 1] = order
        return True
    if k >= bp_t.shape[1]:
        return False
    bp_t[c, k] = t
    bp_o[c, k] = order
    bp_n[c] = k + 1
    return True


def run(A, B1, B2, C1, C2, D11, D12, D21, D22, gp, gi, gv, hp, hi_, hv, jp, ji, jv, tau, lo, hi, ut, uvs, x0, Rw,
        Ru, R0, tq, deriv, t_end, hmax, anorm, bw, iw, tol, out, hist_t, hist_h, hist_n, hist_c, bp_t, bp_o, bp_n,
        jump_t, jump_v, info):
    """Integrate the reduced system from 0 to ``t_end``, once for each input column ``uvs[col]`` (one call: the
    work space is shared); write ``out[col, :, k]`` (the outputs, or their derivative when ``deriv``) at the
    sorted times ``tq`` and the jumps of the outputs into ``jump_t[col]``/``jump_v[col]``.

    ``tau``, ``lo``, ``hi``: each channel's delay and limits (+-inf: none); ``ut``, ``uv``: the inputs' knots and
    values there (piecewise linear, held after the last, 0 before 0); ``Rw[i, c]``: relative degree from ``W_c``
    to ``V_i`` (``> DEG``: no path), ``Ru[i, l]`` from input ``l``, ``R0[i]`` from the initial state;
    ``gp, gi, gv`` (and ``hp...``, ``jp...``): ``[A B1 B2]`` (``[C2 D21 D22]``, ``[C1 D11 D12]``) as compressed rows
    (see :func:`_recursion`); ``hist_*``, ``bp_*``: work space whose size bounds the pieces and breakpoints (status
    CAPACITY when full).  ``info[col]``: status, pieces, jumps recorded, the time reached.  ``anorm`` and ``bw``:
    the bounds of the remainder's recursion (see :func:`_recursion`)."""
    n = A.shape[0]
    nu = B1.shape[1]
    m = B2.shape[1]
    ny = C1.shape[0]
    rows, nf, ni = work_sizes(n, nu, m, ny)
    FW = np.zeros((rows, _NC))
    F1 = np.zeros(nf)
    I1 = np.zeros(ni, dtype=np.int64)
    for col in range(uvs.shape[0]):
        _core(A, B1, B2, C1, C2, D11, D12, D21, D22, gp, gi, gv, hp, hi_, hv, jp, ji, jv, tau, lo, hi, ut, uvs[col],
              x0, Rw, Ru, R0, tq, deriv, t_end, hmax, anorm, bw, iw, tol, out[col], hist_t, hist_h, hist_n, hist_c,
              bp_t, bp_o, bp_n, jump_t[col], jump_v[col], info[col], FW, F1, I1)


def work_sizes(n, nu, m, ny):
    """The sizes of :func:`_core`'s work space for ``n`` states, ``nu`` inputs, ``m`` channels, ``ny`` outputs:
    the rows of ``FW`` (of ``NC`` numbers each), the numbers of ``F1``, the integers of ``I1``."""
    return n + nu + 3 * m + ny, ny + n + 4 * _NC + m + 1, 5 * m


def run_batch(A, B1, B2, C1, C2, D11, D12, D21, D22, gp, gi, gv, hp, hi_, hv, jp, ji, jv, tau, lo, hi, ut, uvs, x0,
              Rw, Ru, R0, tq, deriv, t_end, hmax, anorm, bw, iw, tol, out, hist_t, hist_h, hist_n, hist_c, bp_t, bp_o,
              bp_n, jump_t, jump_v, info, FW, F1, I1):
    """Step responses of many systems of one shape in parallel threads (compiled mode only; the other modes call
    :func:`run` per job): job ``k`` is system ``k // nu``'s response to the inputs ``uvs[k % nu]``, written to
    ``out[k]`` and ``info[k]``.  The system arrays have a leading system axis; the work arrays (``hist_*``,
    ``bp_*``, ``jump_*``, ``FW``, ``F1``, ``I1``) a leading thread axis."""
    njobs = out.shape[0]
    nu = B1.shape[2]
    for k in prange(njobs, nogil=True, schedule="dynamic"):  # noqa: F821 (compiled mode only)
        tid = threadid()  # noqa: F821
        sy = k // nu
        _core(A[sy], B1[sy], B2[sy], C1[sy], C2[sy], D11[sy], D12[sy], D21[sy], D22[sy], gp[sy], gi[sy], gv[sy],
              hp[sy], hi_[sy], hv[sy], jp[sy], ji[sy], jv[sy], tau[sy], lo[sy], hi[sy], ut, uvs[k % nu], x0,
              Rw[sy], Ru[sy], R0, tq, deriv, t_end, hmax[sy], anorm[sy], bw[sy], iw[sy], tol, out[k], hist_t[tid],
              hist_h[tid], hist_n[tid], hist_c[tid], bp_t[tid], bp_o[tid], bp_n[tid], jump_t[tid], jump_v[tid],
              info[k], FW[tid], F1[tid], I1[tid])


def _core(A, B1, B2, C1, C2, D11, D12, D21, D22, gp, gi, gv, hp, hi_, hv, jp, ji, jv, tau, lo, hi, ut, uv, x0, Rw,
          Ru, R0, tq, deriv, t_end, hmax, anorm, bw, iw, tol, out, hist_t, hist_h, hist_n, hist_c, bp_t, bp_o, bp_n,
          jump_t, jump_v, info, FW, F1, I1):
    """:func:`run`'s work, with its work space given: ``FW``, ``F1``, ``I1`` of :func:`work_sizes`'s sizes;
    allocates nothing (so that threads can run it without the GIL)."""
    n = A.shape[0]
    nu = B1.shape[1]
    m = B2.shape[1]
    ny = C1.shape[0]
    nt = tq.shape[0]
    nk = ut.shape[0]
    cap = hist_t.shape[0]
    jcap = jump_t.shape[0]
    SW = FW[0:n + nu + m, :]  # the states', inputs' and channels' coefficients, one block (see _recursion)
    X = FW[0:n, :]
    U = FW[n:n + nu, :]
    W = FW[n + nu:n + nu + m, :]
    Z = FW[n + nu + m:n + nu + 2 * m, :]
    V = FW[n + nu + 2 * m:n + nu + 3 * m, :]
    Y = FW[n + nu + 3 * m:n + nu + 3 * m + ny, :]
    Yprev = F1[0:ny]
    xa = F1[ny:ny + n]
    work = F1[ny + n:ny + n + _NC]
    tmp = F1[ny + n + _NC:ny + n + 2 * _NC]
    work2 = F1[ny + n + 2 * _NC:ny + n + 3 * _NC]
    scale = F1[ny + n + 3 * _NC:ny + n + 3 * _NC + m]
    wsum = F1[ny + n + 3 * _NC + m:ny + n + 4 * _NC + m + 1]
    mode = I1[0:m]
    rd = I1[m:2 * m]  # read pointer into the history, per channel
    ip = I1[2 * m:3 * m]  # next breakpoint to image, per channel
    border = I1[3 * m:4 * m]  # orders of the breakpoints at the piece's start
    selfr = I1[4 * m:5 * m]
    for o in range(ny):
        Yprev[o] = 0.0
    for c in range(m):
        mode[c] = _LIN
        rd[c] = 0
        ip[c] = 0
        border[c] = _DEG + 1
        selfr[c] = 0
        scale[c] = 0.0
    for i in range(n):
        xa[i] = x0[i]
    for c in range(m):
        bp_n[c] = 0
    anyself = False
    status = _OK
    hcap = hmax
    nc = _NC
    pieces = 0
    njump = 0
    yscale = 0.0
    kq = 0
    a = 0.0
    kn = 0  # the next knot of the inputs: ut[kn] > a
    # the start: every channel a breakpoint of the orders the input and the initial state give
    for i in range(m):
        o = R0[i]
        for l in range(nu):
            if uv[0, l] != 0.0 and Ru[i, l] < o:
                o = Ru[i, l]
            elif nk > 1 and uv[1, l] != uv[0, l] and Ru[i, l] + 1 < o:
                o = Ru[i, l] + 1
        border[i] = o
    while kn < nk and ut[kn] <= tol:
        kn += 1
    for c in range(m):  # regimes at the start from the channels' values (refined below)
        mode[c] = _LIN
    while a < t_end - tol:
        if pieces >= cap:
            status = _CAPACITY
            break
        # -- the piece's end: the next event, hmax, the reads' extrapolation limits ---------------------------
        e = t_end
        if kn < nk and ut[kn] < e:
            e = ut[kn]
        for c in range(m):
            if tau[c] > 0.0:
                while ip[c] < bp_n[c] and bp_t[c, ip[c]] + tau[c] <= a + tol:
                    ip[c] += 1
                if ip[c] < bp_n[c] and bp_t[c, ip[c]] + tau[c] < e:
                    e = bp_t[c, ip[c]] + tau[c]
        H = e - a
        if H > hcap:
            H = hcap
        # a delay short against the piece, with no breakpoint of its channel within one delay before the start
        # nor at it, is read from the piece being built (self-read: implicit, solved by fixed-point passes)
        for c in range(m):
            selfr[c] = 0
            if tau[c] > 0.0 and tau[c] <= _SELF * hmax and ip[c] == bp_n[c] and border[c] > _DEG:
                selfr[c] = 1
        for c in range(m):
            if tau[c] > 0.0:
                s = a - tau[c]
                if s >= -tol:
                    q = rd[c]
                    while q + 1 < pieces and hist_t[q + 1] <= s + tol:
                        q += 1
                    rd[c] = q
        for sweep in range(2):
            for c in range(m):
                if tau[c] > 0.0 and selfr[c] == 0:
                    if tau[c] < H:
                        H = tau[c]  # read the stored pieces, never past the piece's start (an explicit scheme)
                    s = a - tau[c]
                    if s >= -tol:
                        q = rd[c]
                        lim = hist_t[q] + 2.0 * hist_h[q] - s
                        if lim < H:
                            H = lim
            anyself = False
            for c in range(m):
                if selfr[c] == 1:
                    if H < 2.0 * tau[c]:
                        selfr[c] = 0  # a self-read piece is at least twice the delay long
                    else:
                        anyself = True
        if H <= 0.0:
            H = tol
        # -- the inputs on the piece ------------------------------------------------------------------------
        k0 = kn - 1  # the segment holding a
        for l in range(nu):
            for j in range(_NC):
                U[l, j] = 0.0
            if k0 < 0:
                continue
            if k0 + 1 < nk:
                slope = (uv[k0 + 1, l] - uv[k0, l]) / (ut[k0 + 1] - ut[k0])
            else:
                slope = 0.0
            U[l, 0] = uv[k0, l] + slope * (a - ut[k0])
            U[l, 1] = slope * H
        # -- the delayed channels on the piece, from the history -------------------------------------------------
        for c in range(m):
            for j in range(_NC):
                W[c, j] = 0.0
            if tau[c] > 0.0:
                s = a - tau[c]
                if s >= -tol and pieces > 0:
                    q = rd[c]
                    alpha = (s - hist_t[q]) / hist_h[q]
                    if alpha < 1e-13:  # (a read from a stored piece's start, to rounding: no Taylor shift)
                        alpha = 0.0
                    beta = H / hist_h[q]
                    nq = hist_n[q]
                    for j in range(nq):
                        tmp[j] = hist_c[q, c, j]
                    if selfr[c] == 1:  # the first pass reads the history's value, held
                        W[c, 0] = _horner(tmp, nq, alpha)
                    else:
                        _shift_scale(tmp, nq, alpha, beta, work, work2)
                        for j in range(nq):
                            W[c, j] = work[j]
        # -- the Taylor recursion, with the saturations' regimes settled at the start -------------------------------
        for c in range(m):
            if lo[c] > -1e308 or hi[c] < 1e308:
                z0 = 0.0
                for i in range(n):
                    z0 += C2[c, i] * xa[i]
                for l in range(nu):
                    z0 += D21[c, l] * U[l, 0]
                for d in range(m):
                    if tau[d] > 0.0:
                        z0 += D22[c, d] * W[d, 0]
                if z0 > hi[c]:
                    mode[c] = _HIGH
                elif z0 < lo[c]:
                    mode[c] = _LOW
                elif mode[c] == _HIGH and z0 < hi[c] - tol * (1.0 + fabs(hi[c])):
                    mode[c] = _LIN
                elif mode[c] == _LOW and z0 > lo[c] + tol * (1.0 + fabs(lo[c])):
                    mode[c] = _LIN
        xcut = 1.0
        settled = False
        tries = 0
        picard_failed = False
        while tries < _MODE_TRIES:
            tries += 1
            nc = _recursion(gp, gi, gv, hp, hi_, hv, jp, ji, jv, n, nu, m, ny, tau, lo, hi, mode, xa, SW, Z, V, Y, H,
                            anorm, bw, iw, wsum)
            if anyself:
                converged = False
                for it in range(_PICARD):
                    diff = 0.0
                    for c in range(m):
                        if selfr[c] == 1:
                            for j in range(_NC):
                                tmp[j] = V[c, j]
                            _shift_scale(tmp, _NC, -tau[c] / H, 1.0, work, work2)  # (V is 0 past nc)
                            big = 0.0
                            dj = 0.0
                            for j in range(_NC):
                                big += fabs(work[j])
                                if fabs(work[j] - W[c, j]) > dj:
                                    dj = fabs(work[j] - W[c, j])
                                W[c, j] = work[j]
                            if dj > _PICARD_TOL * (big + scale[c]):
                                diff = 1.0
                    nc = _recursion(gp, gi, gv, hp, hi_, hv, jp, ji, jv, n, nu, m, ny, tau, lo, hi, mode, xa, SW, Z,
                                    V, Y, H, anorm, bw, iw, wsum)
                    if diff == 0.0:
                        converged = True
                        break
                if not converged:
                    picard_failed = True
                    break
            over = nc > _NC  # (degree _DEG did not meet the bound: all _NC coefficients are there)
            if over:
                nc = _NC
            # the first switch in the piece
            xcut = 2.0
            cfirst = -1
            nxt = _LIN
            for c in range(m):
                if lo[c] > -1e308 or hi[c] < 1e308:
                    to = _LIN
                    if mode[c] == _LIN:
                        xs = 2.0
                        if hi[c] < 1e308:
                            xs = _first_exit(Z[c, :], nc, hi[c], True, 0.0)
                            to = _HIGH
                        if lo[c] > -1e308:
                            x2 = _first_exit(Z[c, :], nc, lo[c], False, 0.0)
                            if x2 < xs:
                                xs = x2
                                to = _LOW
                    elif mode[c] == _HIGH:
                        xs = _first_exit(Z[c, :], nc, hi[c], False, 0.0)
                    else:
                        xs = _first_exit(Z[c, :], nc, lo[c], True, 0.0)
                    if xs < xcut:
                        xcut = xs
                        cfirst = c
                        nxt = to
            if cfirst >= 0 and xcut * H <= tol:
                mode[cfirst] = nxt  # the channel leaves its regime at once: the next regime holds here
                continue
            if over and H > 1e-6 * hmax:
                # the Taylor coefficients do not decay enough: the piece is too long for the signals' rates
                H *= 0.5
                hcap = H
                if anyself:
                    picard_failed = True  # (redone from the start: the self-read channels' shift changes)
                    break
                _cut(U, nu, 0.5, _NC)
                _cut(W, m, 0.5, _NC)
                tries = 0
                continue
            if nc <= _NGROW and hcap < _GROW * hmax:
                hcap *= 2.0
            settled = True
            break
        if picard_failed:
            # redone shorter (the fixed point did not converge, or the tail was long): a delay over _SELF times
            # the shorter cap is read from the stored pieces again
            if hcap > 0.5 * H:
                hcap = 0.5 * H
            continue
        if not settled:
            status = _STALLED
            break
        switched = -1
        if xcut < 1.0:
            switched = cfirst
            _cut(X, n, xcut, nc)
            _cut(Z, m, xcut, nc)
            _cut(V, m, xcut, nc)
            _cut(W, m, xcut, nc)
            _cut(U, nu, xcut, nc)
            _cut(Y, ny, xcut, nc)
            H = H * xcut
            mode[switched] = nxt
        # -- the jumps at the piece's start: drop a breakpoint whose jump is negligible ------------------------
        for c in range(m):
            big = 0.0
            for j in range(_NC):
                big += fabs(V[c, j])
            if big > scale[c]:
                scale[c] = big
        for c in range(m):
            if tau[c] > 0.0 and border[c] <= _DEG:
                L = tau[c] if tau[c] < hmax else hmax
                jmax = 0.0
                keep = False
                if L > 1e6 * H or (pieces > 0 and L > 1e6 * hist_h[pieces - 1]):
                    keep = True  # pieces far shorter than the window: not measured (the breakpoint is kept)
                elif pieces > 0 and hist_t[pieces - 1] + hist_h[pieces - 1] >= a - tol:
                    hl = hist_h[pieces - 1]
                    # the jump of the breakpoint's own order first (one derivative): usually it is the answer
                    k0 = border[c]
                    b = 1.0  # C(j, k0)
                    dj = 0.0
                    for j in range(k0, hist_n[pieces - 1]):
                        dj += b * hist_c[pieces - 1, c, j]
                        b = b * (j + 1) / (j + 1 - k0)
                    r = L / hl
                    x = L / H
                    beta = 1.0
                    alpha = 1.0
                    for j in range(k0):
                        beta *= r
                        alpha *= x
                    if fabs(V[c, k0] * alpha - dj * beta) > _JUMP * scale[c]:
                        keep = True
                if not keep and pieces > 0 and hist_t[pieces - 1] + hist_h[pieces - 1] >= a - tol:
                    # derivatives of the left piece at its end, scaled to L
                    hl = hist_h[pieces - 1]
                    nq = hist_n[pieces - 1]
                    for j in range(nq):
                        tmp[j] = hist_c[pieces - 1, c, j]
                    for j in range(nq, _NC):
                        tmp[j] = 0.0
                    _shift_scale(tmp, nq, 1.0, L / hl, work, work2)
                    for j in range(nq, _NC):
                        work[j] = 0.0
                    r = 1.0
                    for j in range(_NC):
                        dj = fabs(V[c, j] * r - work[j])
                        r *= L / H
                        if dj > jmax:
                            jmax = dj
                elif not keep:
                    r = 1.0
                    for j in range(_NC):
                        dj = fabs(V[c, j] * r)
                        r *= L / H
                        if dj > jmax:
                            jmax = dj
                if keep or jmax > _JUMP * scale[c]:
                    if not _add_bp(bp_t, bp_o, bp_n, c, a, border[c], tol):
                        status = _CAPACITY
                        break
            border[c] = _DEG + 1
        if status != _OK:
            break
        # -- the outputs' jumps at the start, the requested times on the piece ---------------------------------
        if jcap > 0:
            jm = 0.0
            for o in range(ny):
                dj = fabs(Y[o, 0] - Yprev[o])
                if dj > jm:
                    jm = dj
                if fabs(Y[o, 0]) > yscale:
                    yscale = fabs(Y[o, 0])
            if jm > 1e-12 * yscale:
                if njump >= jcap:
                    status = _CAPACITY
                    break
                jump_t[njump] = a
                for o in range(ny):
                    jump_v[njump, o] = Y[o, 0] - Yprev[o]
                njump += 1
        b = a + H
        last = b >= t_end - tol
        while kq < nt and (tq[kq] < b - tol or (last and tq[kq] <= t_end + tol)):
            x = (tq[kq] - a) / H
            if x < 0.0:
                x = 0.0
            for o in range(ny):
                if deriv:
                    out[o, kq] = _horner_d(Y[o, :], nc, x) / H
                else:
                    out[o, kq] = _horner(Y[o, :], nc, x)
            kq += 1
        # -- store the piece, advance -------------------------------------------------------------------------
        hist_t[pieces] = a
        hist_h[pieces] = H
        hist_n[pieces] = nc
        for c in range(m):
            for j in range(nc):
                hist_c[pieces, c, j] = V[c, j]
        pieces += 1
        finite = True
        for i in range(n):
            s = 0.0
            for j in range(nc - 1, -1, -1):
                s += X[i, j]
            xa[i] = s
            if not isfinite(s):
                finite = False
        for o in range(ny):
            Yprev[o] = _horner(Y[o, :], nc, 1.0)
        if not finite:
            status = _OVERFLOW
            a = b
            break
        a = b
        if last:
            a = t_end
            break
        # -- the breakpoints at the new start ----------------------------------------------------------------------
        for i in range(m):
            border[i] = _DEG + 1
        while kn < nk and ut[kn] <= a + tol:  # a knot of the inputs: a jump of slope (order 1)
            for l in range(nu):
                s1 = (uv[kn + 1, l] - uv[kn, l]) / (ut[kn + 1] - ut[kn]) if kn + 1 < nk else 0.0
                s0 = (uv[kn, l] - uv[kn - 1, l]) / (ut[kn] - ut[kn - 1]) if kn > 0 else 0.0
                if s1 != s0:
                    for i in range(m):
                        if Ru[i, l] + 1 < border[i]:
                            border[i] = Ru[i, l] + 1
            kn += 1
        for c in range(m):  # images of the channels' breakpoints
            if tau[c] > 0.0:
                while ip[c] < bp_n[c] and bp_t[c, ip[c]] + tau[c] <= a + tol:
                    oc = bp_o[c, ip[c]]
                    for i in range(m):
                        if oc + Rw[i, c] < border[i]:
                            border[i] = oc + Rw[i, c]
                    ip[c] += 1
        if switched >= 0:  # a switch: a kink of the channel, or of every channel a switch without delay reaches
            if tau[switched] > 0.0:
                if border[switched] > 1:
                    border[switched] = 1
            else:
                for i in range(m):
                    if 1 + Rw[i, switched] < border[i]:
                        border[i] = 1 + Rw[i, switched]
    info[0] = status
    info[1] = pieces
    info[2] = njump
    info[3] = a
    while kq < nt and status != _OK:
        for o in range(ny):
            out[o, kq] = _NAN
        kq += 1


def _cut(P, rows, xc, nc):
    """Rescale the polynomials ``P[:rows]`` (``nc`` coefficients) from ``[0, 1]`` to ``[0, xc]``."""
    for i in range(rows):
        b = 1.0
        for j in range(nc):
            P[i, j] *= b
            b *= xc


def _recursion(gp, gi, gv, hp, hi_, hv, jp, ji, jv, n, nu, m, ny, tau, lo, hi, mode, xa, S, Z, V, Y, H, anorm, bw, iw,
               ws):
    """The Taylor coefficients of the states, channels and outputs on a piece of length ``H`` from the states
    ``xa`` at its start, to the least degree whose remainder is below rounding (see :func:`_core`'s bound);
    returns the number of coefficients kept, ``nc`` (the rest of each row set to 0), or ``_NC + 1`` when even
    degree ``_DEG`` does not meet the bound (the piece is too long: all ``_NC`` coefficients are there).

    ``S`` holds the states' coefficients (rows ``0..n``, written here), the inputs' (``n..n + nu``) and the
    channels' (``n + nu..``: the delayed ones given, those without delay formed here, in the regimes ``mode``).
    ``[A B1 B2]``, ``[C2 D21 D22]`` and ``[C1 D11 D12]`` come as compressed rows (``gp, gi, gv`` and so on: their
    non-zero entries in increasing column order over the rows of ``S``, so that each sum is the dense one's without
    its zero terms).  ``anorm`` bounds the weighted infinity norm ``||diag(iw) A diag(iw)^-1||`` of the states'
    matrix in every regime of the channels without delay, ``bw`` that of the map from the delayed channels to the
    states' derivative (``iw >= 1``, the inverse weights of the states); ``ws``: work space of ``_NC + 1``."""
    w0 = n + nu
    # the delayed channels' coefficients on [0, 2]: ws[k] = sum_{j >= k} 2^j max_c |W_c[j]|
    wbig = 0.0
    ws[_NC] = 0.0
    p2 = 16777216.0  # 2^_DEG
    for j in range(_DEG, -1, -1):
        wn = 0.0
        for c in range(m):
            if tau[c] > 0.0 and fabs(S[w0 + c, j]) > wn:
                wn = fabs(S[w0 + c, j])
        if j == 0:
            wn *= _FLOOR
        if wn > wbig:
            wbig = wn
        ws[j] = ws[j + 1] + wn * p2
        p2 *= 0.5
    a2 = 2.0 * H * anorm
    g2 = 2.0 * H * bw
    xs = 0.0
    p2 = 1.0
    nc = _NC + 1
    for i in range(n):
        S[i, 0] = xa[i]
    for k in range(_NC):
        # the channels without delay (their D22 among each other is 0)
        for c in range(m):
            if tau[c] == 0.0:
                if mode[c] == _LIN:
                    s = 0.0
                    for q in range(hp[c], hp[c + 1]):
                        s += hv[q] * S[hi_[q], k]
                    S[w0 + c, k] = s
                elif k == 0:
                    S[w0 + c, k] = hi[c] if mode[c] == _HIGH else lo[c]
                else:
                    S[w0 + c, k] = 0.0
        ek = 0.0
        for i in range(n):
            if fabs(S[i, k]) * (_FLOOR if k == 0 else 1.0) > xs:
                xs = fabs(S[i, k]) * (_FLOOR if k == 0 else 1.0)
            if fabs(S[i, k]) * iw[i] > ek:
                ek = fabs(S[i, k]) * iw[i]
        ek *= p2
        p2 *= 2.0
        if (k >= 2 and k + 1.0 > a2 and ws[k + 1] <= _TRUNC * wbig
                and a2 * ek + g2 * ws[k] <= _TRUNC * xs * (k + 1.0 - a2)):
            nc = k + 1
            break
        if k < _DEG:
            f = H / (k + 1)
            for i in range(n):
                s = 0.0
                for q in range(gp[i], gp[i + 1]):
                    s += gv[q] * S[gi[q], k]
                S[i, k + 1] = f * s
    kc = nc if nc <= _NC else _NC
    for i in range(n):
        for k in range(kc, _NC):
            S[i, k] = 0.0
    for c in range(m):
        if tau[c] == 0.0:
            for k in range(kc, _NC):
                S[w0 + c, k] = 0.0
    for c in range(m):
        for k in range(kc):
            s = 0.0
            for q in range(hp[c], hp[c + 1]):
                s += hv[q] * S[hi_[q], k]
            Z[c, k] = s
            if mode[c] == _LIN:
                V[c, k] = s
            elif k == 0:
                V[c, k] = hi[c] if mode[c] == _HIGH else lo[c]
            else:
                V[c, k] = 0.0
        for k in range(kc, _NC):
            Z[c, k] = 0.0
            V[c, k] = 0.0
    for o in range(ny):
        for k in range(kc):
            s = 0.0
            for q in range(jp[o], jp[o + 1]):
                s += jv[q] * S[ji[q], k]
            Y[o, k] = s
        for k in range(kc, _NC):
            Y[o, k] = 0.0
    return nc
