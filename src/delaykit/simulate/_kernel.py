"""Compiled core of the simulator: the method of steps with truncated Taylor polynomials.

The loop is simulated piece by piece.  On each piece every signal is a polynomial in a local variable
``x`` in ``[0, 1]``; the piece ends at the next *breakpoint*:

* the image ``b + Td`` of an earlier breakpoint ``b`` (so that the delayed command ``u(t - Td)`` is a single
  polynomial on the piece: this is where the neutral loop's jumps sit, and where the kinks of a saturation
  switch reappear);
* a saturation switch of the command (a root of ``p(x) = +-vmax``, refined to machine precision);
* a sample instant of a sampled controller;
* a length cap ``1 / rate`` that keeps the Taylor coefficients decaying like ``rate**j / j!``.

Between breakpoints the solution is analytic, so the polynomials are exact up to the truncation at degree
``DEG`` (24); the largest discarded coefficient is reported, and in practice it is below 1e-16.  Step
metrics are computed on the polynomials themselves (crossings and extrema are polynomial roots), while the
pieces stream past, so a batch run stores nothing but the metrics.

This module is private: :mod:`delaykit.simulate.simulation` is its interface.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["DEG", "NC", "PARAM", "OUT", "run_one", "run_batch"]

DEG = 24
NC = DEG + 1
_GRID = 16

# Column layout of a parameter row.
PARAM = {
    "kp": 0, "kv": 1, "td": 2, "vmax": 3, "filtered": 4, "wf": 5, "zf": 6,
    "period": 7, "offset": 8, "step": 9, "t_end": 10, "band": 11, "gain": 12, "lag": 13,
}
NPAR = len(PARAM)
# Column layout of a metrics row.
OUT = {
    "overshoot": 0, "peak_time": 1, "peak": 2, "t10": 3, "t90": 4, "rise_time": 5,
    "settling_time": 6, "final_error": 7, "truncation": 8, "pieces": 9, "status": 10,
    "u_pieces": 11,
}
NOUT = len(OUT)

_LINEAR, _HIGH, _LOW = 0, 1, 2


@njit(cache=True, inline="always")
def _horner(c, n, x):
    s = 0.0
    for j in range(n - 1, -1, -1):
        s = s * x + c[j]
    return s


@njit(cache=True, inline="always")
def _horner_d(c, n, x):
    p = 0.0
    dp = 0.0
    for j in range(n - 1, -1, -1):
        dp = dp * x + p
        p = p * x + c[j]
    return p, dp


@njit(cache=True, inline="always")
def _sum(c, n):
    s = 0.0
    for j in range(n):
        s += c[j]
    return s


@njit(cache=True)
def _bounds(c, n):
    """Lower and upper bounds of the polynomial on [0, 1] (x**j lies in [0, 1])."""
    lo = c[0]
    hi = c[0]
    for j in range(1, n):
        if c[j] > 0.0:
            hi += c[j]
        else:
            lo += c[j]
    return lo, hi


@njit(cache=True)
def _refine(c, n, target, lo, hi, slo):
    """Root of c(x) - target in [lo, hi], where the sign just right of lo is ``slo``."""
    x = 0.5 * (lo + hi)
    for _ in range(200):
        f, df = _horner_d(c, n, x)
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


@njit(cache=True)
def _first_cross(c, n, target, s0):
    """First x in (0, 1] where c(x) - target leaves the sign ``s0`` it has just right of 0; 2.0 if none."""
    if n <= 1:
        return 2.0
    prev = 0.0
    for i in range(1, _GRID + 1):
        x = i / _GRID
        f = _horner(c, n, x) - target
        if f * s0 <= 0.0:
            if f == 0.0 and i == _GRID:
                return 1.0
            return _refine(c, n, target, prev, x, s0)
        prev = x
    return 2.0


@njit(cache=True)
def _crossing_time(W, n, level, a, H):
    """Time of the first upward crossing of ``level`` on the piece, NaN if it stays below."""
    if W[0] >= level:
        return a
    x = _first_cross(W, n, level, -1.0)
    return a + x * H if x <= 1.0 else np.nan


@njit(cache=True)
def _all_cross(c, n, target, xs):
    """All sign changes of c(x) - target in (0, 1), refined; returns their count (stored in xs)."""
    if n <= 1:
        return 0
    k = 0
    fp = c[0] - target
    xp = 0.0
    for i in range(1, _GRID + 1):
        x = i / _GRID
        f = _horner(c, n, x) - target
        if (fp < 0.0 and f >= 0.0) or (fp > 0.0 and f <= 0.0):
            if not (i == _GRID and f == 0.0):
                xs[k] = _refine(c, n, target, xp, x, 1.0 if fp > 0.0 else -1.0)
                k += 1
        if f != 0.0:
            fp = f
        xp = x
    return k


@njit(cache=True)
def _shift_scale(src, n, alpha, beta, dst):
    """dst(y) = src(alpha + beta*y): Taylor shift by alpha, then scale by beta."""
    for j in range(n):
        dst[j] = src[j]
    if alpha != 0.0:
        for i in range(n - 1):
            for j in range(n - 2, i - 1, -1):
                dst[j] += alpha * dst[j + 1]
    if beta != 1.0:
        b = 1.0
        for j in range(n):
            dst[j] *= b
            b *= beta


@njit(cache=True)
def _scale(c, n, s):
    b = 1.0
    for j in range(n):
        c[j] *= b
        b *= s


@njit(cache=True)
def _classify(P, n, vmax, tol):
    p0 = P[0]
    if p0 > vmax + tol:
        return _HIGH
    if p0 < -vmax - tol:
        return _LOW
    slope = P[1] if n > 1 else 0.0
    if p0 >= vmax - tol and slope > 0.0:
        return _HIGH
    if p0 <= -vmax + tol and slope < 0.0:
        return _LOW
    return _LINEAR


@njit(cache=True)
def run_one(par, cap, tu0, thu, tuc, tdeg, tz0, th, tzc, out, store, et, ez):
    """Simulate one loop; fill ``out`` with its metrics and, if ``store``, ``tz0, th, tzc`` with z's pieces.

    ``et`` (sorted times) and ``ez`` (same size): z is evaluated at those times as the pieces stream past
    (held at its final value after ``t_end``, 0 before the step).

    The command's pieces (``tu0, thu, tuc, tdeg``) are kept apart from z's: contiguous pieces on which the
    command is the same constant (saturated, or held by a sampled controller) are merged, so that only the
    real breakpoints of the command have images one delay later.  Returns the number of z pieces;
    ``out[status]`` is 1 when ``cap`` pieces were not enough.
    """
    kp = par[0]
    kv = par[1]
    td = par[2]
    vmax = par[3]
    filt = par[4] > 0.5
    wf = par[5]
    zf = par[6]
    per = par[7]
    off = par[8]
    r = par[9]
    tend = par[10]
    band = par[11]
    g = par[12]
    lag = par[13]
    lagged = lag > 0.0
    sampled = per > 0.0
    true_vel = not filt
    w2 = wf * wf
    twozw = 2.0 * zf * wf
    eps = 1e-12 * max(1.0, tend)
    ar = abs(r)
    ptol = 1e-13 * max(1.0, kp * ar)

    rate = kp * max(g, 1e-300)
    if td == 0.0 and true_vel and not lagged:
        rate = kp * g / (1.0 + kv * g)
    if lagged:
        rate = max(rate, 1.0 / lag)
    if filt:
        rate = max(rate, wf)
        rate = max(rate, np.sqrt(abs(kv) * w2))
    hmax = 1.0 / max(rate, 1e-9)

    V = np.zeros(NC + 1)
    Z = np.zeros(NC + 1)
    F1 = np.zeros(NC + 1)
    F2 = np.zeros(NC + 1)
    L = np.zeros(NC + 1)
    P = np.zeros(NC + 1)
    U = np.zeros(NC + 1)
    W = np.zeros(NC + 1)
    dW = np.zeros(NC + 1)
    xs = np.zeros(_GRID + 2)

    z = 0.0
    f1 = 0.0
    f2 = 0.0
    lv = 0.0
    vleft = 0.0
    ke = 0
    ne = et.shape[0]
    while ke < ne and et[ke] < 0.0:
        ez[ke] = 0.0
        ke += 1
    uhold = 0.0
    ksamp = 0
    nexts = off if sampled else np.inf
    a = 0.0
    n = 0
    nu = 0
    q = 0
    trunc = 0.0
    wmax = -np.inf
    tpeak = np.nan
    t10 = np.nan
    t90 = np.nan
    tlast = 0.0
    status = 0.0
    wend = 0.0

    while a < tend - eps:
        if n >= cap:
            status = 1.0
            break
        # a sample instant: the controller reads z and the velocity signal, and holds its command
        while sampled and nexts <= a + eps:
            vel = vleft if true_vel else w2 * f2
            p0 = kp * (r - z) - kv * vel
            uhold = min(max(p0, -vmax), vmax)
            ksamp += 1
            nexts = off + ksamp * per
        end = min(tend, a + hmax)
        if sampled:
            end = min(end, nexts)
        # the delayed command on this piece
        nV = 1
        V[0] = 0.0
        past = False
        s = a - td
        if td > 0.0:
            if s < -eps:
                end = min(end, td)
            else:
                past = True
                while q < nu - 1 and tu0[q] + thu[q] <= s + eps:
                    q += 1
                end = min(end, tu0[q] + thu[q] + td)
        H = end - a
        if past:
            alpha = (s - tu0[q]) / thu[q]
            if alpha < 1e-13:
                alpha = 0.0
            beta = H / thu[q]
            if alpha == 0.0 and abs(beta - 1.0) < 1e-13:
                beta = 1.0
            nV = tdeg[q]
            _shift_scale(tuc[q], nV, alpha, beta, V)
        regime = _LINEAR
        nU = 1
        if td == 0.0 and not sampled:
            # an ordinary differential equation: z' = u(t), solved by a Taylor recursion
            if lagged:
                p0 = kp * (r - z) - kv * (lv if true_vel else w2 * f2)
            elif true_vel:
                p0 = kp * (r - z) / (1.0 + kv * g)
            else:
                p0 = kp * (r - z) - kv * w2 * f2
            if p0 > vmax + ptol:
                regime = _HIGH
            elif p0 < -vmax - ptol:
                regime = _LOW
            for j in range(NC + 1):
                F1[j] = 0.0
                F2[j] = 0.0
                Z[j] = 0.0
                L[j] = 0.0
            Z[0] = z
            F1[0] = f1
            F2[0] = f2
            L[0] = lv
            for attempt in range(2):
                for j in range(DEG):
                    rj = r if j == 0 else 0.0
                    if lagged:
                        pj = kp * (rj - Z[j]) - kv * (L[j] if true_vel else w2 * F2[j])
                    elif true_vel:
                        pj = kp * (rj - Z[j]) / (1.0 + kv * g)
                    else:
                        pj = kp * (rj - Z[j]) - kv * w2 * F2[j]
                    P[j] = pj
                    if regime == _LINEAR:
                        uj = pj
                    elif j == 0:
                        uj = vmax if regime == _HIGH else -vmax
                    else:
                        uj = 0.0
                    V[j] = uj
                    if lagged:
                        L[j + 1] = H * (g * uj - L[j]) / (lag * (j + 1))
                        Z[j + 1] = H * L[j] / (j + 1)
                    else:
                        Z[j + 1] = H * g * uj / (j + 1)
                    if filt:
                        F1[j + 1] = H * F2[j] / (j + 1)
                        F2[j + 1] = H * (-w2 * F1[j] - twozw * F2[j] + Z[j]) / (j + 1)
                rj = 0.0
                if lagged:
                    P[DEG] = kp * (-Z[DEG]) - kv * (L[DEG] if true_vel else w2 * F2[DEG])
                elif true_vel:
                    P[DEG] = kp * (-Z[DEG]) / (1.0 + kv * g)
                else:
                    P[DEG] = kp * (-Z[DEG]) - kv * w2 * F2[DEG]
                V[DEG] = P[DEG] if regime == _LINEAR else 0.0
                if attempt == 0 and regime == _LINEAR and abs(abs(p0) - vmax) <= ptol:
                    if p0 > 0.0 and P[1] > 0.0:
                        regime = _HIGH
                        continue
                    if p0 < 0.0 and P[1] < 0.0:
                        regime = _LOW
                        continue
                break
            nV = NC
            nZ = NC
            nP = NC
            trunc = max(trunc, abs(Z[DEG]) / ar)
        else:
            if td == 0.0:
                V[0] = uhold
                nV = 1
            # z is the integral of the plant velocity: the delayed command times the gain, through the lag
            Z[0] = z
            if lagged:
                L[0] = lv
                for j in range(DEG):
                    vj = g * V[j] if j < nV else 0.0
                    L[j + 1] = H * (vj - L[j]) / (lag * (j + 1))
                    Z[j + 1] = H * L[j] / (j + 1)
                nZ = NC
                trunc = max(trunc, abs(Z[DEG]) / ar)
            else:
                for j in range(nV):
                    Z[j + 1] = H * g * V[j] / (j + 1)
                nZ = nV + 1
                if nZ > NC:
                    trunc = max(trunc, abs(Z[NC]) / ar)
                    nZ = NC
            for j in range(nZ, NC + 1):
                Z[j] = 0.0
            nP = nZ
            if filt:
                F1[0] = f1
                F2[0] = f2
                for j in range(DEG):
                    F1[j + 1] = H * F2[j] / (j + 1)
                    F2[j + 1] = H * (-w2 * F1[j] - twozw * F2[j] + Z[j]) / (j + 1)
                trunc = max(trunc, abs(kv * w2 * F2[DEG]) / max(kp * ar, 1e-300))
                nP = NC
            if not sampled:
                if lagged:
                    nP = NC
                for j in range(nP):
                    if not true_vel:
                        vel = w2 * F2[j]
                    elif lagged:
                        vel = L[j]
                    else:
                        vel = g * V[j] if j < nV else 0.0
                    P[j] = -kp * Z[j] - kv * vel
                P[0] += kp * r
                regime = _classify(P, nP, vmax, ptol)
        # the command on this piece, and a cut at the first saturation switch
        if sampled:
            U[0] = uhold
            nU = 1
        else:
            xc = 2.0
            for attempt in range(3):
                xc = 2.0
                if regime == _LINEAR:
                    lo, hi = _bounds(P, nP)
                    if hi >= vmax:
                        xc = min(xc, _first_cross(P, nP, vmax, -1.0))
                    if lo <= -vmax:
                        xc = min(xc, _first_cross(P, nP, -vmax, 1.0))
                elif regime == _HIGH:
                    lo, hi = _bounds(P, nP)
                    if lo <= vmax:
                        xc = _first_cross(P, nP, vmax, 1.0)
                else:
                    lo, hi = _bounds(P, nP)
                    if hi >= -vmax:
                        xc = _first_cross(P, nP, -vmax, -1.0)
                # a switch at the very start means the piece began on the boundary in the wrong regime:
                # classify again just past the start (a cut there would make no progress in time)
                if td > 0.0 and xc < 1.0 and xc * H <= 1e-12 * max(1.0, abs(a) + H):
                    probe = _horner(P, nP, min(1.0, max(16.0 * xc, 1e-9)))
                    regime = _HIGH if probe > vmax else (_LOW if probe < -vmax else _LINEAR)
                    continue
                break
            if xc < 1.0 - 1e-13:
                _scale(Z, nZ, xc)
                _scale(V, nV, xc)
                _scale(P, nP, xc)
                if filt:
                    _scale(F1, NC, xc)
                    _scale(F2, NC, xc)
                if lagged:
                    _scale(L, NC, xc)
                H *= xc
                end = a + H
            if regime == _LINEAR:
                nU = nP
                for j in range(nU):
                    U[j] = P[j]
                # drop coefficients that are below rounding
                while nU > 1 and abs(U[nU - 1]) < 1e-19 * (vmax if vmax < np.inf else kp * ar + 1.0):
                    nU -= 1
            else:
                U[0] = vmax if regime == _HIGH else -vmax
                nU = 1
        # store the piece
        if nu > 0 and nU == 1 and tdeg[nu - 1] == 1 and tuc[nu - 1, 0] == U[0]:
            thu[nu - 1] = end - tu0[nu - 1]
        else:
            tu0[nu] = a
            thu[nu] = H
            tdeg[nu] = nU
            for j in range(nU):
                tuc[nu, j] = U[j]
            nu += 1
        if store:
            tz0[n] = a
            th[n] = H
            for j in range(NC):
                tzc[n, j] = Z[j] if j < nZ else 0.0
        # metrics on the normalised response w = z / r
        for j in range(nZ):
            W[j] = Z[j] / r
        lo, hi = _bounds(W, nZ)
        if hi > wmax:
            for j in range(nZ - 1):
                dW[j] = (j + 1) * W[j + 1]
            k = _all_cross(dW, nZ - 1, 0.0, xs)
            for i in range(k + 1):
                x = xs[i] if i < k else 1.0
                wv = _horner(W, nZ, x)
                if wv > wmax:
                    wmax = wv
                    tpeak = a + x * H
            w0 = W[0]
            if w0 > wmax:
                wmax = w0
                tpeak = a
        if np.isnan(t10) and hi >= 0.1:
            t10 = _crossing_time(W, nZ, 0.1, a, H)
        if np.isnan(t90) and hi >= 0.9:
            t90 = _crossing_time(W, nZ, 0.9, a, H)
        wend = _sum(W, nZ)
        if hi - 1.0 >= band or lo - 1.0 <= -band:
            if abs(wend - 1.0) >= band:
                tlast = end
            else:
                xl = -1.0
                k = _all_cross(W, nZ, 1.0 + band, xs)
                if k > 0:
                    xl = max(xl, xs[k - 1])
                k = _all_cross(W, nZ, 1.0 - band, xs)
                if k > 0:
                    xl = max(xl, xs[k - 1])
                if xl >= 0.0:
                    tlast = a + xl * H
                elif abs(W[0] - 1.0) >= band:
                    tlast = a
        # the requested samples of z on this piece
        while ke < ne and et[ke] <= end + eps:
            x = (et[ke] - a) / H
            ez[ke] = _horner(Z, nZ, min(max(x, 0.0), 1.0))
            ke += 1
        # advance the state to the end of the piece
        z = _sum(Z, nZ)
        if filt:
            f1 = _sum(F1, NC)
            f2 = _sum(F2, NC)
        if lagged:
            lv = _sum(L, NC)
            vleft = lv
        else:
            vleft = g * _sum(V, nV)
        a = end
        n += 1

    while ke < ne:
        ez[ke] = z
        ke += 1
    overshoot = max(0.0, wmax - 1.0) * 100.0
    out[0] = overshoot
    out[1] = tpeak if wmax > 1.0 else np.nan
    out[2] = wmax
    out[3] = t10
    out[4] = t90
    out[5] = t90 - t10
    out[6] = tlast if abs(wend - 1.0) < band else np.nan
    out[7] = r * (1.0 - wend)
    out[8] = trunc
    out[9] = n
    out[10] = status
    out[11] = nu
    return n


@njit(cache=True, parallel=True)
def run_batch(pars, cap, nchunks):
    """Metrics of many loops (one parameter row each), split over ``nchunks`` threads."""
    m = pars.shape[0]
    out = np.empty((m, NOUT))
    for c in prange(nchunks):
        lo = c * m // nchunks
        hi = (c + 1) * m // nchunks
        tu0 = np.empty(cap)
        thu = np.empty(cap)
        tuc = np.empty((cap, NC))
        tdeg = np.empty(cap, dtype=np.int64)
        tz0 = np.empty(1)
        th = np.empty(1)
        tzc = np.empty((1, NC))
        et = np.empty(0)
        ez = np.empty(0)
        for i in range(lo, hi):
            run_one(pars[i], cap, tu0, thu, tuc, tdeg, tz0, th, tzc, out[i], False, et, ez)
    return out
