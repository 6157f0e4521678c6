"""Compiled core of the simulator: the method of steps with truncated Taylor polynomials, for any loop.

The loop (see :mod:`delaykit.models.loop` for the user-facing description) is one linear system with a
state vector ``X`` (the plant's states, then the controller's), driven by polynomial signals:

* the plant input ``w(t) = u(t - Ti) + d``, the command one input delay ago plus a load disturbance;
* the measured output ``ym(t) = y(t - To)`` and velocity ``vm(t) = y'(t - To)``, one output delay ago;
* the reference ``r(t)``, piecewise linear;
* the back-calculation term ``sat(v) - v`` of an integrator's anti-windup;
* for a controller with a model of the plant inside (a Smith predictor, predictor feedback), the command
  ``u(t)`` itself and the command one *model* delay ago, ``u(t - Tm)``: a second delay, whose images are
  breakpoints like the input delay's.

Every signal is a polynomial in a local variable ``x`` in ``[0, 1]`` on each piece, and the states follow
from the Taylor recursion ``X[j+1] = H (M X[j] + inputs[j]) / (j + 1)``.  A piece ends at the next
*breakpoint*:

* the image one input delay later of a point where the command ``u`` is not analytic, and one output delay
  later of a point where the output ``y`` is not analytic (these are where a neutral loop's jumps sit, and
  where the kinks of a saturation switch reappear).  Points where a piece was only cut for length are not
  imaged: the signal is analytic there, and the earlier piece's polynomial is its Taylor series, accurate
  over the next piece too;
* a saturation switch of the command (a root of ``v(x) = umax`` or ``umin``, refined to machine precision),
  and, with clamping anti-windup, a sign change of the error while saturated;
* a sample instant of a sampled controller, a knot of the reference, the load disturbance's start;
* a length cap ``hmax`` (the reciprocal of the loop's fastest rate) that keeps the Taylor coefficients
  decaying like ``1 / j!``.

Step metrics are computed on the polynomials themselves while the pieces stream past.

The parameter row layout (``HEAD`` and the ``OFF_*`` offsets) is defined once here and filled by
:mod:`delaykit.simulate.simulation`.  This module is private.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["DEG", "NC", "MAXN", "HEAD", "NPAR", "OUT", "NOUT", "AW", "run_one", "run_batch"]

DEG = 24
NC = DEG + 1
MAXN = 16
_GRID = 16

# Scalars at the start of a parameter row.
(_N, _TI, _TO, _UMIN, _UMAX, _PERIOD, _OFFSET, _T_END, _BAND, _NORM, _DIST, _T_DIST, _DY, _DYD, _DVR, _DVY, _DVV, _INTEG, _AW, _HMAX, _SCALE, _STEP, _SLOPE, _TM) = range(24)
HEAD = {
    "n": _N,
    "ti": _TI,
    "to": _TO,
    "umin": _UMIN,
    "umax": _UMAX,
    "period": _PERIOD,
    "offset": _OFFSET,
    "t_end": _T_END,
    "band": _BAND,
    "norm": _NORM,
    "dist": _DIST,
    "t_dist": _T_DIST,
    "dy": _DY,
    "dyd": _DYD,
    "dvr": _DVR,
    "dvy": _DVY,
    "dvv": _DVV,
    "integ": _INTEG,
    "aw": _AW,
    "hmax": _HMAX,
    "scale": _SCALE,
    "step": _STEP,
    "slope": _SLOPE,
    "tm": _TM,
}
NHEAD = 24
# Matrices and vectors after it: M (MAXN x MAXN, row-major), then ten vectors of length MAXN.
OFF_M = NHEAD
OFF_BW = OFF_M + MAXN * MAXN      # plant input w
OFF_BR = OFF_BW + MAXN            # reference r
OFF_BYM = OFF_BR + MAXN           # measured output ym
OFF_BVM = OFF_BYM + MAXN          # measured velocity vm
OFF_BAW = OFF_BVM + MAXN          # back-calculation term sat(v) - v
OFF_CY = OFF_BAW + MAXN           # y = CY X + dy w
OFF_CYD = OFF_CY + MAXN           # y' = CYD X + dyd w
OFF_CV = OFF_CYD + MAXN           # v = CV X + dvr r + dvy ym + dvv vm
OFF_BU = OFF_CV + MAXN            # the command u itself (a predictor's model input)
OFF_BUM = OFF_BU + MAXN           # the command one model delay ago, u(t - Tm)
NPAR = OFF_BUM + MAXN
AW = {"none": 0, "clamp": 1, "backcalc": 2}

# Column layout of a metrics row.
OUT = {
    "overshoot": 0, "peak_time": 1, "peak": 2, "t10": 3, "t90": 4, "rise_time": 5,
    "settling_time": 6, "final_error": 7, "truncation": 8, "pieces": 9, "status": 10,
    "u_pieces": 11, "y_pieces": 12, "t_stop": 13,
}
NOUT = len(OUT)
STATUS_OK, STATUS_CAPACITY, STATUS_STALLED = 0.0, 1.0, 2.0
_STALL = 256  # consecutive pieces shorter than 1e-9 of the run: no progress (the command chatters)

_LIN, _HIGH, _LOW = 0, 1, 2


# -- polynomials on [0, 1] ---------------------------------------------------------------------------------
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
    """Root of c(x) - target in [lo, hi], where the sign just right of lo is ``slo`` (safeguarded Newton)."""
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
    """dst(y) = src(alpha + beta*y): Taylor shift by alpha, then scale by beta (zeros above degree n-1)."""
    for j in range(n):
        dst[j] = src[j]
    for j in range(n, NC):
        dst[j] = 0.0
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
def _degree(c, n):
    """Number of coefficients up to the last non-zero one (at least 1)."""
    while n > 1 and c[n - 1] == 0.0:
        n -= 1
    return n


@njit(cache=True)
def _classify(V, n, umin, umax, tol):
    """Regime of the command at the start of a piece: linear, or saturated high or low."""
    v0 = V[0]
    if v0 > umax + tol:
        return _HIGH
    if v0 < umin - tol:
        return _LOW
    slope = 0.0
    for j in range(1, n):  # the first non-zero derivative decides at the boundary
        if V[j] != 0.0:
            slope = V[j]
            break
    if v0 >= umax - tol and slope > 0.0:
        return _HIGH
    if v0 <= umin + tol and slope < 0.0:
        return _LOW
    return _LIN


@njit(cache=True)
def _delayed(t0, th, tc, tdeg, q, s, H, dst):
    """The stored piece ``q`` of a history, as a polynomial over [s, s + H] (extrapolated past its end
    where the signal is analytic there); returns the number of coefficients."""
    alpha = (s - t0[q]) / th[q]
    if alpha < 1e-13:
        alpha = 0.0
    beta = H / th[q]
    if alpha == 0.0 and abs(beta - 1.0) < 1e-13:
        beta = 1.0
    n = tdeg[q]
    _shift_scale(tc[q], n, alpha, beta, dst)
    return n


@njit(cache=True)
def _ref_poly(rt, r0, rs, k, a, H, R):
    """The reference on [a, a + H] within its segment ``k`` (value r0[k] + rs[k] (t - rt[k]))."""
    R[0] = r0[k] + rs[k] * (a - rt[k])
    R[1] = rs[k] * H
    return 2 if rs[k] != 0.0 else 1


# The step metrics' running state (a row of ``ms``): highest w so far and when, the first times w reaches
# 0.1 and 0.9, the last time w was outside the settling band, and w at the end of the latest piece.
_WMAX, _TPEAK, _T10, _T90, _TLAST, _WEND = range(6)
_NMS = 6


@njit(cache=True)
def _step_metrics(Y, nY, norm, a, H, band, ms, Wn, dW, xs):
    """Update the step metrics with the piece ``Y`` on ``[a, a + H]`` (exact: extrema and crossings are roots)."""
    end = a + H
    for j in range(nY):
        Wn[j] = Y[j] / norm
    lo, hi = _bounds(Wn, nY)
    if hi > ms[_WMAX]:
        for j in range(nY - 1):
            dW[j] = (j + 1) * Wn[j + 1]
        k = _all_cross(dW, nY - 1, 0.0, xs)
        for i in range(k + 1):
            x = xs[i] if i < k else 1.0
            wv = _horner(Wn, nY, x)
            if wv > ms[_WMAX]:
                ms[_WMAX] = wv
                ms[_TPEAK] = a + x * H
        if Wn[0] > ms[_WMAX]:
            ms[_WMAX] = Wn[0]
            ms[_TPEAK] = a
    for idx, level in ((_T10, 0.1), (_T90, 0.9)):
        if np.isnan(ms[idx]) and hi >= level:
            t = a if Wn[0] >= level else a + _first_cross(Wn, nY, level, -1.0) * H
            ms[idx] = t if t <= end else np.nan
    wend = _sum(Wn, nY)
    ms[_WEND] = wend
    if hi - 1.0 >= band or lo - 1.0 <= -band:
        if abs(wend - 1.0) >= band:
            ms[_TLAST] = end
        else:
            xl = -1.0
            k = _all_cross(Wn, nY, 1.0 + band, xs)
            if k > 0:
                xl = max(xl, xs[k - 1])
            k = _all_cross(Wn, nY, 1.0 - band, xs)
            if k > 0:
                xl = max(xl, xs[k - 1])
            if xl >= 0.0:
                ms[_TLAST] = a + xl * H
            elif abs(Wn[0] - 1.0) >= band:
                ms[_TLAST] = a


@njit(cache=True)
def _first_switch(V, nv, E, ne, regime, frozen, umin, umax, aw):
    """Where on the piece (x in (0, 1]) the command ``V`` first leaves its regime or, with clamping
    anti-windup while saturated, the error ``E`` changes sign; 2.0 if nowhere."""
    xc = 2.0
    lo, hi = _bounds(V, nv)
    if regime == _LIN:
        if hi >= umax:
            xc = min(xc, _first_cross(V, nv, umax, -1.0))
        if lo <= umin:
            xc = min(xc, _first_cross(V, nv, umin, 1.0))
    elif regime == _HIGH:
        if lo <= umax:
            xc = _first_cross(V, nv, umax, 1.0)
    elif hi >= umin:
        xc = _first_cross(V, nv, umin, -1.0)
    if aw == 1 and regime != _LIN:
        s0 = 1.0 if frozen == (regime == _HIGH) else -1.0
        xc = min(xc, _first_cross(E, ne, 0.0, s0))
    return xc


@njit(cache=True)
def _image(t0, gen, n, q, qg, s, a, delay, eps):
    """In a history of ``n`` pieces (starts ``t0``, ``gen`` = not analytic at the start): the piece ``q``
    that contains ``s``, the first piece ``qg`` after it that starts where the signal is not analytic, and
    the time that start's image reaches (one ``delay`` later; ``a + delay`` if there is none yet)."""
    while q < n - 1 and t0[q + 1] <= s + eps:
        q += 1
    if qg <= q:
        qg = q + 1
    while qg < n and gen[qg] == 0:
        qg += 1
    return q, qg, (t0[qg] if qg < n else a) + delay


# -- one piece -------------------------------------------------------------------------------------------
@njit(cache=True)
def _recursion(par, Mloc, VE, N, H, regime, frozen, algebraic, ti_pos, sampled, uhold, dist, X, R, nR,
               Wd, nW, Ym, Vm, use_meas, Y, Yd, V, E, need_yd, Um, nUm, has_u):
    """Taylor coefficients of every signal on one piece of length ``H`` with the regime fixed.

    ``X[:, 0]`` holds the states at the start; fills ``X[:, 1:]``, the output ``Y``, its derivative ``Yd``,
    the controller output ``V`` and the error ``E`` (``Yd`` only where ``need_yd``: something reads y').
    With ``has_u`` (a predictor's model inside the controller), the states also read the command ``u``
    itself and ``Um`` (``nUm`` coefficients), the command one model delay ago.
    """
    umin = par[_UMIN]
    umax = par[_UMAX]
    dy = par[_DY]
    dyd = par[_DYD]
    dvr = par[_DVR]
    dvy = par[_DVY]
    dvv = par[_DVV]
    integ = int(par[_INTEG])
    aw = int(par[_AW])
    kd = dvy * dy + dvv * dyd  # direct feedthrough around a loop with no delay at all
    lim = umax if regime == _HIGH else umin
    # the forcing is a polynomial of degree < nf: once the states' coefficients vanish past it, all do
    nf = max(nR, nW if ti_pos else 1, 1)
    if has_u:
        nf = max(nf, nUm)
    if use_meas:
        nf = max(nf, _degree(Ym, NC), _degree(Vm, NC))
    nt = NC
    for j in range(NC):
        if j >= nf and j > 0:
            zero = True
            for i in range(N):
                if X[i, j] != 0.0:
                    zero = False
                    break
            if zero:
                nt = j
                break
        rj = R[j] if j < nR else 0.0
        dj = dist if j == 0 else 0.0
        # the parts of y, y' and v that do not depend on this piece's plant input
        cy = 0.0
        cyd = 0.0
        cv = 0.0
        for i in range(N):
            xi = X[i, j]
            cy += VE[5, i] * xi
            cv += VE[7, i] * xi
        if need_yd:
            for i in range(N):
                cyd += VE[6, i] * X[i, j]
        if sampled:
            wj = (Wd[j] if (ti_pos and j < nW) else (uhold if j == 0 else 0.0)) + dj
            vj = 0.0  # filled below
        elif ti_pos:
            wj = (Wd[j] if j < nW else 0.0) + dj
            vj = 0.0
        elif algebraic:
            base = cv + dvr * rj + dvy * cy + dvv * cyd
            if regime == _LIN:
                vj = (base + kd * dj) / (1.0 - kd)
                wj = vj + dj
            else:
                wj = (lim if j == 0 else 0.0) + dj
                vj = base + kd * wj
        else:
            # no input delay, a delayed measurement: v is known before w
            vj = cv + dvr * rj + dvy * Ym[j] + dvv * Vm[j]
            wj = (vj if regime == _LIN else (lim if j == 0 else 0.0)) + dj
        yj = cy + dy * wj
        ydj = cyd + dyd * wj
        if use_meas:
            ymj = Ym[j]
            vmj = Vm[j]
        else:
            ymj = yj
            vmj = ydj
        if sampled or ti_pos:
            vj = cv + dvr * rj + dvy * ymj + dvv * vmj
        Y[j] = yj
        Yd[j] = ydj
        V[j] = vj
        E[j] = rj - ymj
        if j == DEG:
            break
        awj = 0.0
        if aw == 2 and regime != _LIN:
            awj = (lim if j == 0 else 0.0) - vj
        f = H / (j + 1)
        if has_u:
            # the command as applied: held, the law's output, or the limit it is clipped to
            if sampled:
                uj = uhold if j == 0 else 0.0
            elif regime == _LIN:
                uj = vj
            else:
                uj = lim if j == 0 else 0.0
            umj = Um[j] if j < nUm else 0.0
            for i in range(N):
                acc = (VE[0, i] * wj + VE[1, i] * rj + VE[2, i] * ymj + VE[3, i] * vmj + VE[4, i] * awj
                       + VE[8, i] * uj + VE[9, i] * umj)
                for k in range(N):
                    acc += Mloc[i, k] * X[k, j]
                X[i, j + 1] = f * acc
        else:
            for i in range(N):
                acc = VE[0, i] * wj + VE[1, i] * rj + VE[2, i] * ymj + VE[3, i] * vmj + VE[4, i] * awj
                for k in range(N):
                    acc += Mloc[i, k] * X[k, j]
                X[i, j + 1] = f * acc
        if frozen and integ >= 0:
            X[integ, j + 1] = 0.0
    for j in range(nt, NC):
        Y[j] = 0.0
        Yd[j] = 0.0
        V[j] = 0.0
        E[j] = 0.0
        for i in range(N):
            X[i, j] = 0.0
    for i in range(N):
        X[i, NC] = 0.0
    return nt


@njit(cache=True)
def run_one(par, rt, r0, rs, cap, tu0, thu, tuc, tdeg, ugen, ty0, tyh, tyc, tyd, ygen, out, keep_y, et, ez):
    """Simulate one loop; fill ``out`` with its metrics.

    The command's history (``tu0, thu, tuc, tdeg, ugen``: start, length, coefficients, number of
    coefficients, "not analytic at the start") always, and the output's (``ty0, tyh, tyc, tyd, ygen``: y
    and y') when ``keep_y``.  Contiguous pieces on which the command is the same constant are merged.
    ``rt, r0, rs``: the reference's knots, values there and slopes.  ``et`` (sorted times) and ``ez``
    (same size): y is evaluated at those times as the pieces stream past (held at its final value after
    ``t_end``, 0 before the step).  Returns the number of pieces; ``out[status]`` is 1 when ``cap``
    pieces were not enough.
    """
    N = int(par[_N])
    ti = par[_TI]
    to = par[_TO]
    umin = par[_UMIN]
    umax = par[_UMAX]
    per = par[_PERIOD]
    off = par[_OFFSET]
    tend = par[_T_END]
    tm = par[_TM]
    band = par[_BAND]
    norm = par[_NORM]
    dist = par[_DIST]
    tdist = par[_T_DIST]
    dvr = par[_DVR]
    dvy = par[_DVY]
    dvv = par[_DVV]
    aw = int(par[_AW])
    hmax = par[_HMAX]
    scale = par[_SCALE]
    sampled = per > 0.0
    cont = not sampled
    ti_pos = ti > 0.0
    to_pos = to > 0.0
    algebraic = cont and not ti_pos and not to_pos
    need_yd = keep_y or to_pos or dvv != 0.0
    tm_pos = tm > 0.0
    switches = cont or aw != 0
    keep_y = keep_y or to_pos
    has_dist = dist != 0.0
    eps = 1e-12 * max(1.0, tend)
    ptol = 1e-13 * max(1.0, scale)
    metrics = norm != 0.0
    nref = rt.shape[0]

    X = np.zeros((MAXN, NC + 1))
    R = np.zeros(NC)
    Wd = np.zeros(NC)
    Um = np.zeros(NC)
    Ym = np.zeros(NC)
    Vm = np.zeros(NC)
    Y = np.zeros(NC)
    Yd = np.zeros(NC)
    V = np.zeros(NC)
    E = np.zeros(NC)
    Wn = np.zeros(NC)
    dW = np.zeros(NC)
    xs = np.zeros(_GRID + 2)
    x0 = np.zeros(MAXN)
    has_u = False
    for i in range(N):
        if par[OFF_BVM + i] != 0.0:
            need_yd = True
        if par[OFF_BU + i] != 0.0 or par[OFF_BUM + i] != 0.0:
            has_u = True
    tm_pos = tm_pos and has_u
    regime_matters = (cont and not ti_pos) or aw != 0 or (cont and has_u)
    # the loop's matrices, read once: M, then the input and output vectors (w, r, ym, vm, aw; y, y', v)
    Mloc = np.empty((N, N))
    VE = np.empty((10, N))
    for i in range(N):
        for k in range(N):
            Mloc[i, k] = par[OFF_M + i * MAXN + k]
        VE[0, i] = par[OFF_BW + i]
        VE[1, i] = par[OFF_BR + i]
        VE[2, i] = par[OFF_BYM + i]
        VE[3, i] = par[OFF_BVM + i]
        VE[4, i] = par[OFF_BAW + i]
        VE[5, i] = par[OFF_CY + i]
        VE[6, i] = par[OFF_CYD + i]
        VE[7, i] = par[OFF_CV + i]
        VE[8, i] = par[OFF_BU + i]
        VE[9, i] = par[OFF_BUM + i]

    ne = et.shape[0]
    ke = 0
    while ke < ne and et[ke] < 0.0:
        ez[ke] = 0.0
        ke += 1
    uhold = 0.0
    ksamp = 0
    nexts = off if sampled else np.inf
    ym_left = 0.0
    vm_left = 0.0
    a = 0.0
    n = 0
    nu = 0
    ny = 0
    qu = 0
    qgu = 1
    qy = 0
    qgy = 1
    qm = 0
    qgm = 1
    kr = 0
    trunc = 0.0
    ms = np.empty(_NMS)  # the step metrics as the pieces stream past
    ms[_WMAX] = -np.inf
    ms[_TPEAK] = np.nan
    ms[_T10] = np.nan
    ms[_T90] = np.nan
    ms[_TLAST] = 0.0
    ms[_WEND] = 0.0
    status = STATUS_OK
    regime = _LIN
    tiny = 0
    genu = True  # the command and the output are not analytic at t = 0
    geny = True
    y_end = 0.0

    while a < tend - eps:
        if n >= cap:
            status = STATUS_CAPACITY
            break
        while kr + 1 < nref and rt[kr + 1] <= a + eps:
            kr += 1
        # a sample instant: the controller reads its inputs (left limits) and holds its command
        while sampled and nexts <= a + eps:
            v = dvr * (r0[kr] + rs[kr] * (a - rt[kr])) + dvy * ym_left + dvv * vm_left
            for i in range(N):
                v += VE[7, i] * x0[i]
            uhold = min(max(v, umin), umax)
            ksamp += 1
            nexts = off + ksamp * per
        # where the piece must end, and why
        end = min(tend, a + hmax)
        t_img_u = np.inf
        t_img_y = np.inf
        t_img_m = np.inf
        if sampled:
            end = min(end, nexts)
        t_knot = rt[kr + 1] if kr + 1 < nref else np.inf
        end = min(end, t_knot)
        dist_on = has_dist and a >= tdist - eps
        if has_dist and not dist_on:
            end = min(end, tdist)
        su = a - ti
        if ti_pos:
            if su < -eps:
                t_img_u = ti
            else:
                qu, qgu, t_img_u = _image(tu0, ugen, nu, qu, qgu, su, a, ti, eps)
            end = min(end, t_img_u)
        sy = a - to
        if to_pos:
            if sy < -eps:
                t_img_y = to
            else:
                qy, qgy, t_img_y = _image(ty0, ygen, ny, qy, qgy, sy, a, to, eps)
            end = min(end, t_img_y)
        sm = a - tm
        if tm_pos:
            if sm < -eps:
                t_img_m = tm
            else:
                qm, qgm, t_img_m = _image(tu0, ugen, nu, qm, qgm, sm, a, tm, eps)
            end = min(end, t_img_m)
        H = end - a
        # the delayed signals and the reference on this piece
        nW = 1
        Wd[0] = 0.0
        if ti_pos and su >= -eps:
            nW = _delayed(tu0, thu, tuc, tdeg, qu, max(su, tu0[qu]), H, Wd)
        if to_pos:
            if sy >= -eps:
                alpha = (max(sy, ty0[qy]) - ty0[qy]) / tyh[qy]
                if alpha < 1e-13:
                    alpha = 0.0
                beta = H / tyh[qy]
                if alpha == 0.0 and abs(beta - 1.0) < 1e-13:
                    beta = 1.0
                _shift_scale(tyc[qy], NC, alpha, beta, Ym)
                _shift_scale(tyd[qy], NC, alpha, beta, Vm)
            else:
                for j in range(NC):
                    Ym[j] = 0.0
                    Vm[j] = 0.0
        nUm = 1
        Um[0] = 0.0
        if tm_pos and sm >= -eps:
            nUm = _delayed(tu0, thu, tuc, tdeg, qm, max(sm, tu0[qm]), H, Um)
        nR = _ref_poly(rt, r0, rs, kr, a, H, R)
        dcur = dist if dist_on else 0.0
        for i in range(N):
            X[i, 0] = x0[i]
        # the regime (linear or saturated) and, with clamping, whether the integrator is frozen
        frozen = False
        xc = 2.0
        prev_regime = regime
        for attempt in range(4):
            nt = _recursion(par, Mloc, VE, N, H, regime, frozen, algebraic, ti_pos, sampled, uhold, dcur, X, R, nR,
                            Wd, nW, Ym, Vm, to_pos, Y, Yd, V, E, need_yd, Um, nUm, has_u)
            nv = _degree(V, nt)
            new = _classify(V, nv, umin, umax, ptol)
            newf = False
            if aw == 1 and new != _LIN:
                sgn = 0.0
                for j in range(NC):
                    if abs(E[j]) > (ptol if j == 0 else 0.0):
                        sgn = E[j]
                        break
                newf = (new == _HIGH and sgn > 0.0) or (new == _LOW and sgn < 0.0)
            if attempt < 2 and (new != regime or newf != frozen):
                changed = regime_matters or newf != frozen
                regime = new
                frozen = newf
                if changed:
                    continue
            # the first switch on the piece: the command leaves its regime, or the error changes sign
            xc = _first_switch(V, nv, E, _degree(E, nt), regime, frozen, umin, umax, aw) if switches else 2.0
            # a switch at the very start: the piece began on the boundary in the wrong regime
            if attempt < 3 and xc < 1.0 and xc * H <= 1e-12 * max(1.0, abs(a) + H):
                probe = _horner(V, nv, min(1.0, max(16.0 * xc, 1e-9)))
                regime = _HIGH if probe > umax else (_LOW if probe < umin else _LIN)
                if aw == 1 and regime != _LIN:
                    ep = _horner(E, nt, min(1.0, max(16.0 * xc, 1e-9)))
                    frozen = (regime == _HIGH and ep > 0.0) or (regime == _LOW and ep < 0.0)
                else:
                    frozen = False
                continue
            break
        cut = xc < 1.0 - 1e-13
        if cut:
            for i in range(N):
                b = 1.0
                for j in range(nt):
                    X[i, j] *= b
                    b *= xc
            _scale(Y, nt, xc)
            _scale(Yd, nt, xc)
            _scale(V, nt, xc)
            if to_pos:
                _scale(Ym, NC, xc)
                _scale(Vm, NC, xc)
            H *= xc
            end = a + H
        if cont and regime != prev_regime:
            genu = True
        tiny = tiny + 1 if H < 1e-9 * max(1.0, tend) else 0
        if tiny > _STALL:
            status = STATUS_STALLED
            break
        # store the command's piece (constant pieces of equal value merged)
        nU = 1
        if sampled:
            uval = uhold
        elif regime == _LIN:
            nU = nv
            uval = V[0]
            # drop coefficients below rounding
            ref = max(abs(umax) if umax < np.inf else 0.0, abs(umin) if umin > -np.inf else 0.0, scale, 1.0)
            while nU > 1 and abs(V[nU - 1]) < 1e-19 * ref:
                nU -= 1
        else:
            uval = umax if regime == _HIGH else umin
        if nu > 0 and nU == 1 and tdeg[nu - 1] == 1 and tuc[nu - 1, 0] == uval:
            thu[nu - 1] = end - tu0[nu - 1]
        else:
            tu0[nu] = a
            thu[nu] = H
            tdeg[nu] = nU
            ugen[nu] = 1 if genu else 0
            if nU == 1:
                tuc[nu, 0] = uval
            else:
                for j in range(nU):
                    tuc[nu, j] = V[j]
            nu += 1
        nY = _degree(Y, nt)
        if keep_y:
            ty0[ny] = a
            tyh[ny] = H
            ygen[ny] = 1 if geny else 0
            for j in range(NC):
                tyc[ny, j] = Y[j]
                tyd[ny, j] = Yd[j]
            ny += 1
        trunc = max(trunc, abs(Y[DEG]) / max(abs(norm), scale, 1e-300))
        if metrics:
            _step_metrics(Y, nY, norm, a, H, band, ms, Wn, dW, xs)
        # the requested samples of y on this piece
        while ke < ne and et[ke] <= end + eps:
            x = (et[ke] - a) / H
            ez[ke] = _horner(Y, nY, min(max(x, 0.0), 1.0))
            ke += 1
        # advance: the states, the left limits the next sample reads, and why the next piece starts
        for i in range(N):
            x0[i] = _sum(X[i], nt)
        y_end = _sum(Y, nY)
        if to_pos:
            ym_left = _sum(Ym, NC)
            vm_left = _sum(Vm, NC)
        else:
            ym_left = y_end
            vm_left = _sum(Yd, nt)
        genu = False
        geny = False
        if cut:
            genu = cont
            geny = cont and not ti_pos
        else:
            if end >= t_img_u - eps:
                geny = True
            if end >= t_img_y - eps or end >= t_img_m - eps:
                genu = cont
            if sampled and end >= nexts - eps:
                genu = True
            if cont and end >= t_knot - eps:
                genu = True
            if has_dist and not dist_on and end >= tdist - eps:
                geny = True
            if not ti_pos and genu:
                geny = True
            if not to_pos and geny and cont:
                genu = True
        a = end
        n += 1

    while ke < ne:
        ez[ke] = y_end
        ke += 1
    if metrics:
        wmax, wend = ms[_WMAX], ms[_WEND]
        out[0] = max(0.0, wmax - 1.0) * 100.0
        out[1] = ms[_TPEAK] if wmax > 1.0 else np.nan
        out[2] = wmax
        out[3] = ms[_T10]
        out[4] = ms[_T90]
        out[5] = ms[_T90] - ms[_T10]
        out[6] = ms[_TLAST] if abs(wend - 1.0) < band else np.nan
        out[7] = norm * (1.0 - wend)
    else:
        for i in range(8):
            out[i] = np.nan
    out[8] = trunc
    out[9] = n
    out[10] = status
    out[11] = nu
    out[12] = ny
    out[13] = a
    return n


@njit(cache=True, parallel=True)
def run_batch(pars, cap, nchunks):
    """Metrics of many loops (one parameter row each, a step or ramp reference), over ``nchunks`` threads."""
    m = pars.shape[0]
    out = np.empty((m, NOUT))
    for c in prange(nchunks):
        lo = c * m // nchunks
        hi = (c + 1) * m // nchunks
        tu0 = np.empty(cap)
        thu = np.empty(cap)
        tuc = np.zeros((cap, NC))
        tdeg = np.empty(cap, dtype=np.int64)
        ugen = np.empty(cap, dtype=np.int8)
        ty0 = np.empty(cap)
        tyh = np.empty(cap)
        tyc = np.empty((cap, NC))
        tyd = np.empty((cap, NC))
        ygen = np.empty(cap, dtype=np.int8)
        rt = np.zeros(1)
        r0 = np.zeros(1)
        rs = np.zeros(1)
        et = np.empty(0)
        ez = np.empty(0)
        for i in range(lo, hi):
            r0[0] = pars[i, _STEP]
            rs[0] = pars[i, _SLOPE]
            run_one(pars[i], rt, r0, rs, cap, tu0, thu, tuc, tdeg, ugen, ty0, tyh, tyc, tyd, ygen,
                    out[i], False, et, ez)
    return out
