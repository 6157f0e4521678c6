"""Core of the simulator: the method of steps with truncated Taylor polynomials, for any loop.

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
  over the next piece too.  Each breakpoint carries its smoothness order (the lowest derivative that is
  discontinuous there; 0 for the sources: the start, a switch, a sample, a knot, the load), stored as order + 1
  in the histories' ``gen`` (0: analytic).  An image through the loop is smoother by the relative degree of
  the path (plant input to output, measurement and its velocity to command, a predictor's delayed command to
  command: read from the realisation once per run); an image whose order exceeds ``DEG`` is analytic to the
  truncation accepted everywhere and is not imaged, so a retarded loop images each source at most ``DEG + 1``
  times.  A neutral loop's images keep their order (a path of relative degree 0 or less): there, the jump of
  the signal and its scaled derivatives, measured at the breakpoint from the polynomials left and right of it
  over the window one delay long that its image would cover (:func:`_jump`), is compared with ``_JUMP``
  (8 rounding units) times the signal's size there or its scale; below it, the point is not imaged;
* past the images, a delay at most ``SELF`` times ``hmax`` (:data:`._layout.SELF`) is read from the piece
  being built, where the piece starts where the signal is analytic and no breakpoint is stored within one
  delay before it: the history just before the piece is then the analytic continuation of the piece's own
  polynomial, and the delayed signal on the piece is ``U(x - delta)``, ``delta`` the delay over the piece's
  length.  The recursion is then implicit; it is solved by fixed-point passes (:func:`_picard`: each shifts
  the last pass's signal back by ``delta``), to rounding.  Such a piece is at least twice the delay long,
  reads a held or saturated command as its constant, and is redone at half its length when ``_PICARD`` passes
  do not converge or its tail shows rates faster than ``hmax`` assumed.  Delays below 64 ulp of ``t_end``
  (whose images could not be placed) are dropped, unless the loop is ill-posed without them;
* a saturation switch of the command (a root of ``v(x) = umax`` or ``umin``, refined to machine precision),
  and, with clamping anti-windup, a sign change of the error while saturated, or the end of a slide: where
  the free integrator would drive the command past its limit and the frozen one back, the command slides on
  the limit (the Filippov solution), the integrator running at the rate that holds it there, until that
  rate reaches 0 or the free rate;
* a sample instant of a sampled controller, a knot of the reference, the load disturbance's start;
* a length cap: ``hmax`` (the reciprocal of the loop's fastest rate, which keeps the Taylor coefficients
  decaying like ``1 / j!``), or longer, up to ``4 hmax``, where the last Taylor coefficient of every state and
  of the command, relative to that signal's largest, stays below ``1 / 24!`` (that of a pure mode of the
  fastest rate over ``hmax``): a fast mode the loop barely excites (a derivative filter's) does not hold every
  piece to its own time scale.  Each piece's tail sets the next one's length; a piece longer than ``hmax``
  whose tail misses the bound by far is redone shorter;
* twice the length of the stored piece a delayed signal is read from, past that piece's start: a short
  stored piece (between two near breakpoints), rescaled far past its end, would amplify the rounding of its
  high coefficients.

Where the plant's input is known before the piece (delayed, or held by a sampled controller) and the command
does not act back on the states, the recursion runs on ``X' = A X + G (w, r, ym, vm)``, with the measurement's
coupling folded into ``A`` once per run (:mod:`._taylor`); otherwise on the general form.

Step metrics are computed on the polynomials themselves while the pieces stream past: one pass over a piece's
output gives its bounds and its value at the piece's end (:func:`._poly.bounds`), which the advance reuses.

The piece loop (``_run``) and the non-inlined helpers it calls are compiled without numba's reference counting
(``_nrt=False``): they allocate nothing, and with it every array view bound in the loop (each inlined helper's
array arguments) cost an atomic increment and decrement, a third of the paper's P loops' time.  Their work
arrays come from the caller: :func:`run_one` allocates them for one run, :func:`run_batch` once per work set
(one per thread).

The parameter row layout (``HEAD`` and the ``OFF_*`` offsets) is defined in :mod:`._layout` and filled by
:mod:`delaykit.simulate.simulation`; the polynomial helpers are :mod:`._poly`.  One source, three modes (see
:mod:`delaykit._native` and :mod:`._jit`): compiled ahead of time by Cython (the C types are in ``_kernel.pxd``;
the piece loop runs without the GIL, and :func:`run_batch`'s loop in parallel with OpenMP), compiled by numba
(``NUMBA_OPTIONS``) where no extension was built, or run as plain Python.  Cython builds this module as one C
module with :mod:`._poly` and :mod:`._taylor` (``FUSED`` in ``setup.py``): the cimports below become calls within
the module, which the C compiler inlines into the piece loop as numba inlines them (a call across modules would
copy each array view it passes, a 208-byte struct, and could not be inlined).  This module is private.
"""

from __future__ import annotations

import numpy as np

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

from ._layout import (DEG, HEAD, MAXN, NC, NOUT, OFF_BAW, OFF_BR, OFF_BU, OFF_BUM, OFF_BVM, OFF_BW, OFF_BYM, OFF_CV,
                      OFF_CY, OFF_CYD, OFF_M, SELF, GROW as _GROW, STATUS_CAPACITY, STATUS_OK, STATUS_STALLED)
from ._poly import BINOMIAL as _BIN, GRID as _GRID
from ._taylor import HIGH as _HIGH, LIN as _LIN, LOW as _LOW

if cython.compiled:  # the polynomial helpers and the Taylor recursion (compiled into this module: setup.py's FUSED),
    # called as C; C's numbers and OpenMP's loop
    from cython.cimports.delaykit.simulate._poly import all_cross as _all_cross, bounds as _bounds
    from cython.cimports.delaykit.simulate._poly import crossings as _crossings, degree as _degree
    from cython.cimports.delaykit.simulate._poly import first_cross as _first_cross, horner as _horner
    from cython.cimports.delaykit.simulate._poly import poly_sum as _sum, scale as _scale
    from cython.cimports.delaykit.simulate._poly import shift_scale as _shift_scale
    from cython.cimports.delaykit.simulate._taylor import recursion as _recursion
    from cython.cimports.delaykit.simulate._taylor import recursion_known as _recursion_known
    from cython.cimports.delaykit.models._foldkernel import fold_into as _fold_into
    from cython.cimports.libc.math import INFINITY as _INF, NAN as _NAN, isnan
    from cython.parallel import prange
else:  # the same modules run as this one is (numba's copies, or Python)
    from math import inf as _INF, isnan, nan as _NAN

    from .._native import sibling

    _p = sibling(__name__, "_poly")
    _horner, _sum, _bounds, _first_cross, _all_cross, _crossings, _shift_scale, _scale, _degree = (
        _p.horner, _p.poly_sum, _p.bounds, _p.first_cross, _p.all_cross, _p.crossings, _p.shift_scale, _p.scale,
        _p.degree)
    _t = sibling(__name__, "_taylor")
    _recursion, _recursion_known = _t.recursion, _t.recursion_known
    _fold_into = sibling(__name__, "_foldkernel", "delaykit.models").fold_into
    if __name__.endswith("_numba"):
        from numba import prange
    else:
        from builtins import range as prange

__all__ = ["run_one", "run_batch", "run_sweep", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

# Indices of the scalars at the start of a parameter row.
(_N, _TI, _TO, _UMIN, _UMAX, _PERIOD, _OFFSET, _T_END, _BAND, _NORM, _DIST, _T_DIST, _DY, _DYD, _DVR, _DVY, _DVV,
 _INTEG, _AW, _HMAX, _SCALE, _STEP, _SLOPE, _TM) = HEAD.values()
_STALL = 256  # consecutive pieces shorter than 1e-9 of the run: no progress (the command chatters)

# A piece's length: hmax (the reciprocal of the fastest rate), or up to _GROW times that where the Taylor tail
# relative to the signal (see _tail) stays below _TAIL = 1 / 24!, the tail of a pure mode of that rate over hmax.
_TAIL = 1.0 / 620448401733239439360000.0
_NONE = DEG + 1  # a breakpoint's smoothness order above the Taylor degree: analytic to truncation, not imaged
# A neutral loop's jump over a delay's window, relative to the signal there, below which it is not imaged
_JUMP = 8.0 * 2.220446049250313e-16
_PICARD = 400  # fixed-point passes before a piece that reads its own delayed signal is redone shorter
# numba's options where it compiles this file (see delaykit._native): the helpers inlined into the piece loop, which
# (with the rarely run helpers, kept out of its code) is compiled without reference counting; the batch in parallel
NUMBA_OPTIONS = {name: {"inline": "always"} for name in (
    "_classify", "_delayed", "_ref_poly", "_tail", "_last_ratio", "_step_metrics", "_metrics_row", "_metrics_update",
    "_first_switch", "_continues", "_on_limit", "_lead_sign", "_slide_rates", "_image", "_pending", "_read_end", "_held",
    "_chunk")}
NUMBA_OPTIONS.update({"_rel_degree": {"_nrt": False}, "_jump": {"_nrt": False}, "_picard": {"_nrt": False},
                      "_run": {"_nrt": False}, "_batch_sets": {"parallel": True}})


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


def _delayed(t0, th, tc, tdeg, q, s, H, dst, work):
    """The stored piece ``q`` of a history, as a polynomial over [s, s + H] (extrapolated past its end
    where the signal is analytic there); returns the number of coefficients."""
    alpha = (s - t0[q]) / th[q]
    if alpha < 1e-13:
        alpha = 0.0
    beta = H / th[q]
    if alpha == 0.0 and abs(beta - 1.0) < 1e-13:
        beta = 1.0
    n = min(max(tdeg[q], 1), NC)  # (never past the coefficients, whatever the history holds)
    _shift_scale(tc[q], n, alpha, beta, dst, work)
    return n


def _ref_poly(rt, r0, rs, k, a, H, R):
    """The reference on [a, a + H] within its segment ``k`` (value r0[k] + rs[k] (t - rt[k]))."""
    R[0] = r0[k] + rs[k] * (a - rt[k])
    R[1] = rs[k] * H
    return 2 if rs[k] != 0.0 else 1


def _tail(X, N, V, nt):
    """The largest last Taylor coefficient of a state or of the command, relative to that signal's largest
    coefficient on the piece (0 when the coefficients ended before degree DEG)."""
    if nt < NC:
        return 0.0
    t = _last_ratio(V)
    for i in range(N):
        t = max(t, _last_ratio(X[i]))
    return t


def _last_ratio(c):
    """``|c[DEG]|`` relative to the largest ``|c[j]|`` (0 where all are 0): four running maxima side by side, not
    one chain of dependent comparisons (a maximum is exact in any order)."""
    b0 = 0.0
    b1 = 0.0
    b2 = 0.0
    b3 = 0.0
    j = 0
    while j + 3 < NC:
        a0 = abs(c[j])
        a1 = abs(c[j + 1])
        a2 = abs(c[j + 2])
        a3 = abs(c[j + 3])
        b0 = a0 if a0 > b0 else b0
        b1 = a1 if a1 > b1 else b1
        b2 = a2 if a2 > b2 else b2
        b3 = a3 if a3 > b3 else b3
        j += 4
    while j < NC:
        a0 = abs(c[j])
        b0 = a0 if a0 > b0 else b0
        j += 1
    b0 = b1 if b1 > b0 else b0
    b2 = b3 if b3 > b2 else b2
    big = b2 if b2 > b0 else b0
    return abs(c[DEG]) / big if big > 0.0 else 0.0


# The step metrics' running state (a row of ``ms``): highest w so far and when, the first times w reaches
# 0.1 and 0.9, the last time w was outside the settling band, and w at the end of the latest piece.
_WMAX, _TPEAK, _T10, _T90, _TLAST, _WEND = range(6)
_NMS = 6


def _step_metrics(Y, nY, norm, a, H, band, ms, Wn, dW, xs, fs, sd):
    """Update the step metrics with the piece ``Y`` on ``[a, a + H]`` (exact: extrema and crossings are roots).
    ``sd``: any int64 array (the certified search's stack, which the kernel's way does not use)."""
    if norm == 1.0:
        for j in range(nY):
            Wn[j] = Y[j]
    else:
        for j in range(nY):
            Wn[j] = Y[j] / norm
    _metrics_update(Wn, nY, a, H, band, ms, dW, xs, fs, fs, sd, False)


def _metrics_row(out, metrics, wmax, wend, tpeak, t10, t90, tlast, norm, band):
    """The step metrics' part of an output row (:data:`._layout.OUT`: overshoot %, peak time, peak, 10/90 %
    times, rise time, settling time, steady error) from the run's extremes and crossings (``wmax``, ``wend``,
    ``tpeak``... of the output divided by the step ``norm``); NaN without metrics.  The Taylor kernel and the
    sampled batch (:mod:`._sampled_batch`) both end with it."""
    if metrics:
        out[0] = max(0.0, wmax - 1.0) * 100.0
        out[1] = tpeak if wmax > 1.0 else _NAN
        out[2] = wmax
        out[3] = t10
        out[4] = t90
        out[5] = t90 - t10
        out[6] = tlast if abs(wend - 1.0) < band else _NAN
        out[7] = norm * (1.0 - wend)
    else:
        for i in range(8):
            out[i] = _NAN


def _metrics_update(Wn, nW, a, H, band, ms, dW, xs, fs, sr, sd, certified):
    """Update the step metrics ``ms`` with the piece ``Wn`` (the output over ``[a, a + H]``, divided by the
    step), the kernel's way or (``certified``) the sampled batch's (:mod:`._sampled_batch`).

    The kernel finds the roots on a grid (:func:`._poly.all_cross`, :func:`._poly.first_cross`; ``fs`` their
    work space), skips the derivative's root search where the derivative's bounds keep one sign, and keeps w at
    the piece's end in ``ms[_WEND]`` (the sum of its coefficients, from the pass that gives its bounds: the piece
    loop reads it back as y at the piece's end where the step is 1).  The sampled batch isolates them with certainty (:func:`._poly.crossings`;
    ``sr``, ``sd`` its stack) and has no ``_WEND`` in its ``ms``.  ``certified`` is a constant at each call:
    numba drops the other way's branches before typing them, so each caller compiles only its own."""
    end = a + H
    lo, hi, wend = _bounds(Wn, nW)  # (wend: w at the piece's end, the sum of its coefficients)
    if hi > ms[_WMAX]:
        big = 0.0
        for j in range(nW - 1):
            dW[j] = (j + 1) * Wn[j + 1]
            big += abs(dW[j])
        if certified:
            k = _crossings(dW, nW - 1, 0.0, xs, sr, sd)
        else:
            # no root of the derivative where its bounds keep one sign, beyond rounding: the grid search would
            # find none
            dlo, dhi, _ = _bounds(dW, nW - 1)
            if dlo > 1e-13 * big or dhi < -1e-13 * big:
                k = 0
            else:
                k = _all_cross(dW, nW - 1, 0.0, xs, fs)
        for i in range(k + 1):
            x = xs[i] if i < k else 1.0
            wv = _horner(Wn, nW, x)
            if wv > ms[_WMAX]:
                ms[_WMAX] = wv
                ms[_TPEAK] = a + x * H
        if Wn[0] > ms[_WMAX]:
            ms[_WMAX] = Wn[0]
            ms[_TPEAK] = a
    for m in range(2):  # the first times w reaches 0.1 and 0.9
        idx = _T10 if m == 0 else _T90
        level = 0.1 if m == 0 else 0.9
        if isnan(ms[idx]) and hi >= level:
            if Wn[0] >= level:
                t = a
            elif certified:
                t = a + xs[0] * H if _crossings(Wn, nW, level, xs, sr, sd) > 0 else _NAN
            else:
                t = a + _first_cross(Wn, nW, level, -1.0, fs) * H  # (2.0 where there is none: past the end)
            ms[idx] = t if t <= end else _NAN
    if not certified:
        ms[_WEND] = wend
    if hi - 1.0 >= band or lo - 1.0 <= -band:
        if abs(wend - 1.0) >= band:
            ms[_TLAST] = end
        else:
            xl = -1.0  # the last exit from the band on the piece
            for level in (1.0 + band, 1.0 - band):
                k = _crossings(Wn, nW, level, xs, sr, sd) if certified else _all_cross(Wn, nW, level, xs, fs)
                if k > 0:
                    xl = max(xl, xs[k - 1])
            if xl >= 0.0:
                ms[_TLAST] = a + xl * H
            elif abs(Wn[0] - 1.0) >= band:
                ms[_TLAST] = a


def _first_switch(V, nv, E, ne, regime, frozen, umin, umax, aw, fs):
    """Where on the piece (x in (0, 1]) the command ``V`` first leaves its regime or, with clamping
    anti-windup while saturated, the error ``E`` (at most ``ne`` coefficients) changes sign; 2.0 if nowhere."""
    xc = 2.0
    lo, hi, _ = _bounds(V, nv)
    if regime == _LIN:
        if hi >= umax:
            xc = min(xc, _first_cross(V, nv, umax, -1.0, fs))
        if lo <= umin:
            xc = min(xc, _first_cross(V, nv, umin, 1.0, fs))
    elif regime == _HIGH:
        if lo <= umax:
            xc = _first_cross(V, nv, umax, 1.0, fs)
    elif hi >= umin:
        xc = _first_cross(V, nv, umin, -1.0, fs)
    if aw == 1 and regime != _LIN:
        s0 = 1.0 if frozen == (regime == _HIGH) else -1.0
        xc = min(xc, _first_cross(E, _degree(E, ne), 0.0, s0, fs))
    return xc


def _continues(t0, th, tc, deg, full, n, q, s, tol):
    """Whether the stored piece ``q`` of a history, continued past its end to ``s``, still agrees (to ``tol``)
    with the stored piece that covers ``s`` (or, past the history's end, with the last one at its end).
    ``deg``: the pieces' numbers of coefficients, or all ``NC`` where ``full``."""
    end_q = t0[q] + th[q]
    if q + 1 >= n or s <= end_q:
        return True
    k = q + 1
    while k + 1 < n and t0[k + 1] <= s:
        k += 1
    s = min(s, t0[k] + th[k])
    ext = _horner(tc[q], NC if full else deg[q], (s - t0[q]) / th[q])
    return abs(ext - _horner(tc[k], NC if full else deg[k], (s - t0[k]) / th[k])) <= tol


def _on_limit(v0, E, ne, umin, umax, tol):
    """The limit the command starts on (``_HIGH``, ``_LOW``) with the error ``E`` driving it further (the
    clamp would freeze the integrator beyond it); ``_LIN`` if none."""
    if abs(v0 - umax) <= tol:
        side = _HIGH
    elif abs(v0 - umin) <= tol:
        side = _LOW
    else:
        return _LIN
    s = _lead_sign(E, ne, tol)
    if (side == _HIGH and s > 0.0) or (side == _LOW and s < 0.0):
        return side
    return _LIN


def _lead_sign(c, n, tol):
    """The sign of the polynomial ``c`` just right of 0: that of its first coefficient above ``tol`` (0 if none)."""
    for j in range(n):
        if c[j] > tol:
            return 1.0
        if c[j] < -tol:
            return -1.0
    return 0.0


def _slide_rates(X, integ, Fz, nt, S, D):
    """On a sliding piece: ``S`` the integrator's rate and ``D`` the free rate minus it, times the piece's
    length, as polynomials in ``x``; returns their number of coefficients."""
    ns = max(nt - 1, 1)
    for k in range(ns):
        if k + 1 < nt:
            S[k] = (k + 1) * X[integ, k + 1]
            D[k] = (k + 1) * Fz[k + 1] - S[k]
        else:
            S[k] = 0.0
            D[k] = 0.0
    return ns


def _image(t0, gen, n, q, qg, s, a, delay, eps):
    """In a history of ``n`` pieces (starts ``t0``, ``gen``: 0 where the signal is analytic at the start, else
    one more than the breakpoint's smoothness order): the piece ``q`` that contains ``s``, the first piece
    ``qg`` after it that starts at a breakpoint, the time that start's image reaches (one ``delay`` later), and
    the breakpoint's order; with none stored yet, ``a + delay`` (the piece being built starts there: the
    method of steps reads no further) and order -1 (the caller's: the current piece's start)."""
    if n == 0:
        return 0, 1, a + delay, -1
    while q < n - 1 and t0[q + 1] <= s + eps:
        q += 1
    if qg <= q:
        qg = q + 1
    while qg < n and gen[qg] == 0:
        qg += 1
    if qg < n:
        return q, qg, t0[qg] + delay, gen[qg] - 1
    return q, qg, a + delay, -1


def _pending(t0, gen, n, q, qg, s, a, delay, eps, can_self):
    """:func:`_image` at ``s = a - delay`` (before the history's start: the image of t = 0, order 0), and whether
    the piece reads the delayed signal from itself (``can_self`` and nothing pending: the image is then at
    infinity); the order is -1 where the image is the current piece's start's (known once it is stored)."""
    if s < -eps:
        return q, qg, delay, 0, False
    q, qg, t_img, order = _image(t0, gen, n, q, qg, s, a, delay, eps)
    if order < 0 and can_self and n > 0:
        return q, qg, _INF, order, True
    return q, qg, t_img, order, False


def _read_end(t0, th, tc, tdeg, full, n, q, delay, end, ctol):
    """Where a piece reading a delayed signal from its stored piece ``q`` must end, at most ``end``: no farther
    than twice that piece's length from its start (rescaled far past its end, a short piece's polynomial
    would amplify the rounding of its high coefficients), nor past its end where its continuation has drifted
    from the pieces stored after it (the piece then ends at that junction's image, as at a breakpoint)."""
    if n == 0 or (not full and tdeg[q] <= 1):
        return end
    end = min(end, t0[q] + delay + 2.0 * th[q])
    if not _continues(t0, th, tc, tdeg, full, n, q, end - delay, ctol):
        end = min(end, t0[q] + th[q] + delay)
    return end


def _rel_degree(Mloc, VE, N, row_out, row_in, k0, v, w):
    """The smallest ``k0 + k`` (k >= 0) with ``VE[row_out] . M**k . VE[row_in]`` non-zero: the relative degree
    of the path through the states from the input ``row_in`` to the output ``row_out``, ``k0`` for the
    integration (1) or not (0, the input being a derivative); ``_NONE`` if none up to the Taylor degree.
    ``v``, ``w``: work space of ``N`` numbers."""
    for i in range(N):
        v[i] = VE[row_in, i]
    for k in range(NC + 1):
        c = 0.0
        for i in range(N):
            c += VE[row_out, i] * v[i]
        if c != 0.0:
            return k0 + k
        for i in range(N):
            acc = 0.0
            for m in range(N):
                acc += Mloc[i, m] * v[m]
            w[i] = acc
        for i in range(N):
            v[i] = w[i]
    return _NONE


def _jump(cl, nl, hl, cr, nr, hr, L, tmp, work):
    """The jump at a breakpoint of a signal whose left piece (``cl``, ``nl`` coefficients, length ``hl``) ends
    where the right one (``cr``, ``nr``, ``hr``) starts, over a window of length ``L`` after it: the sum of the
    absolute differences of the two Taylor expansions' coefficients in the window's variable, and the right
    expansion's size (the sum of its absolute coefficients); (inf, 0) where the window is more than 4 times
    longer than either piece (rescaling would amplify the rounding of the high coefficients)."""
    if L > 4.0 * hl or L > 4.0 * hr:
        return _INF, 0.0
    _shift_scale(cl, nl, 1.0, L / hl, tmp, work)
    d = 0.0
    size = 0.0
    b = 1.0
    r = L / hr
    for j in range(NC):
        c = (cr[j] * b) if j < nr else 0.0
        d += abs(tmp[j] - c)
        size += abs(c)
        b *= r
    return d, size


def _picard(src, n, delta, dst):
    """One fixed-point pass of a delayed signal read from the piece being built: ``dst`` (all ``NC``
    coefficients) becomes ``src`` (``n`` coefficients) shifted back by ``delta`` (the delay over the piece's
    length), ``src(x - delta)``; returns the largest change of a coefficient and the new number of coefficients
    (``src`` must not alias ``dst``).
    """
    big = 0.0
    out = 0
    for k in range(NC):
        acc = 0.0
        if k < n:
            p = 1.0  # sum_j C(j, k) (-delta)**(j - k) src[j]
            for j in range(k, n):
                acc += _BIN[j, k] * p * src[j]
                p *= -delta
        d = abs(acc - dst[k])
        if d > big:
            big = d
        dst[k] = acc
        if acc != 0.0:
            out = k + 1
    return big, max(out, 1)


def _held(c, n, x, dst):
    """``dst``: the constant value of the polynomial ``c`` at ``x`` (clipped to [0, 1]); returns 1 (its number
    of coefficients)."""
    v = _horner(c, min(n, NC), min(max(x, 0.0), 1.0))
    for k in range(NC):
        dst[k] = 0.0
    dst[0] = v
    return 1


_NBUF = 15 * NC + 2 * _GRID + 3 + MAXN + 5 + _NMS  # the signals' coefficients and the small work arrays
_PAD = 16  # doubles (two cache lines) after each work set's small arrays in a batch: no line shared by two sets


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
    X = np.empty((MAXN, NC + 1))
    buf = np.empty(_NBUF)
    mats = np.empty((4, MAXN, MAXN))
    return _run(par, rt, r0, rs, cap, tu0, thu, tuc, tdeg, ugen, ty0, tyh, tyc, tyd, ygen, out, keep_y, et, ez,
                X, buf, mats)


def _run(par, rt, r0, rs, cap, tu0, thu, tuc, tdeg, ugen, ty0, tyh, tyc, tyd, ygen, out, keep_y, et, ez, X, buf,
         mats):
    """:func:`run_one` on work arrays from the caller (cleared here): ``X`` the states' coefficients
    (``MAXN x (NC + 1)``), ``buf`` the signals' coefficients and small work arrays (``_NBUF``), ``mats`` the
    loop's matrices (``4 x MAXN x MAXN``).  Compiled without reference counting (see the module's notes)."""
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
    yscale = par[_SCALE]  # (not `scale`: compiled by Cython, that is _poly's scale, in this module)
    sampled = per > 0.0
    cont = not sampled
    # a delay below the resolution of the run's times (64 ulp of t_end) cannot place its images: the loop runs
    # without it (the responses differ by O(delay), below that resolution), unless that loop is ill-posed
    tres = 64.0 * 2.220446049250313e-16 * max(1.0, tend)
    kd0 = dvy * par[_DY] + dvv * par[_DYD]
    if ti < tres and to < tres and (not cont or abs(1.0 - kd0) > 1e-12):
        ti = 0.0
        to = 0.0
    ti_pos = ti > 0.0
    to_pos = to > 0.0
    algebraic = cont and not ti_pos and not to_pos
    need_yd = keep_y or to_pos or dvv != 0.0
    tm_pos = tm > 0.0
    switches = cont or aw != 0
    keep_y = keep_y or to_pos
    has_dist = dist != 0.0
    eps = 1e-12 * max(1.0, tend)
    # the tolerance on the delays' images: eps, or less where a delay is shorter
    epsd = eps
    for dl in (ti, to, tm):
        if dl > 0.0:
            epsd = min(epsd, 1e-3 * dl)
    epsd = max(epsd, 4.0 * 2.220446049250313e-16 * max(1.0, tend))
    ptol = 1e-13 * max(1.0, yscale)
    tdiv = max(abs(norm), yscale, 1e-300)  # the truncation's scale
    # a command coefficient below rounding, relative to this, is dropped when the piece is stored
    uref = max(abs(umax) if umax < _INF else 0.0, abs(umin) if umin > -_INF else 0.0, yscale, 1.0)
    ctol = 1e-12 * max(1.0, yscale)
    jscale = max(1.0, yscale)  # the smallest scale a neutral loop's jumps are measured against  # a delayed signal's continuation past its stored piece: how far it may drift
    metrics = norm != 0.0
    nref = rt.shape[0]

    for i in range(N):  # (only the first N rows are read)
        for j in range(NC + 1):
            X[i, j] = 0.0
    # the signals' coefficients and the small work arrays: views of one block
    buf[:] = 0.0
    R, Wd, Um, Ym, Vm, Y = buf[0:NC], buf[NC:2 * NC], buf[2 * NC:3 * NC], buf[3 * NC:4 * NC], buf[4 * NC:5 * NC], \
        buf[5 * NC:6 * NC]
    Yd, V, E, Wn, dW, work = buf[6 * NC:7 * NC], buf[7 * NC:8 * NC], buf[8 * NC:9 * NC], buf[9 * NC:10 * NC], \
        buf[10 * NC:11 * NC], buf[11 * NC:12 * NC]
    Fz, S, D = buf[12 * NC:13 * NC], buf[13 * NC:14 * NC], buf[14 * NC:15 * NC]  # a slide's integrator rates
    o = 15 * NC
    xs, fs = buf[o:o + _GRID + 2], buf[o + _GRID + 2:o + 2 * _GRID + 3]
    o += 2 * _GRID + 3
    x0 = buf[o:o + MAXN]
    o += MAXN
    d5, ms = buf[o:o + 5], buf[o + 5:o + 5 + _NMS]  # the direct terms; the step metrics as the pieces stream past
    has_u = False
    for i in range(N):
        if par[OFF_BVM + i] != 0.0:
            need_yd = True
        if par[OFF_BU + i] != 0.0 or par[OFF_BUM + i] != 0.0:
            has_u = True
    tm_pos = tm_pos and has_u
    integ = int(par[_INTEG])
    regime_matters = (cont and not ti_pos) or aw != 0 or (cont and has_u)
    # the loop's matrices, read once: M, then the input and output vectors (w, r, ym, vm, aw; y, y', v), and
    # the known-input form's A and G (below); only their first N rows and columns are used
    Mloc = mats[0]
    VE = mats[1, :10]
    A = mats[2]
    G = mats[3, :4]
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
        if not tm_pos:  # no model delay: the command one model delay ago is the command itself
            VE[8, i] += VE[9, i]
            VE[9, i] = 0.0
    # with the plant's input known (delayed, or held by a sampled controller): X' = A X + G (w, r, ym, vm), the
    # measurement folded into A when it is the output itself (no output delay)
    known = (ti_pos or sampled) and not algebraic and not has_u
    for i in range(N):
        for k in range(N):
            A[i, k] = Mloc[i, k]
        for k in range(4):
            G[k, i] = 0.0
    d5[0], d5[1], d5[2], d5[3], d5[4] = par[_DY], par[_DYD], dvr, dvy, dvv
    slide_on = aw == 1 and integ >= 0 and VE[7, integ] != 0.0  # clamping: the command may slide on a limit
    # the relative degrees of the loop's paths (structural, from the realisation): the plant input to the output,
    # the measurement (and its velocity, one order lower) to the command, the command one model delay ago to the
    # command.  An image of a breakpoint through a path is smoother by the path's relative degree (see the
    # module's notes).
    rv, rw = mats[3, 4], mats[3, 5]
    r_wy = 0 if par[_DY] != 0.0 else _rel_degree(Mloc, VE, N, 5, 0, 1, rv, rw)
    r_yu = _NONE
    if dvy != 0.0:
        r_yu = 0
    if dvv != 0.0:
        r_yu = -1
    if r_yu > 0:  # (a direct term already gives the smallest: a path through the states has at least 0)
        r_yu = min(r_yu, _rel_degree(Mloc, VE, N, 7, 2, 1, rv, rw), _rel_degree(Mloc, VE, N, 7, 3, 0, rv, rw))
    r_mu = _rel_degree(Mloc, VE, N, 7, 9, 1, rv, rw) if tm_pos else _NONE
    # a neutral loop: a jump of the command comes back, one loop delay later, as a jump again; these stop being
    # imaged once they are below rounding (measured at each breakpoint, see the module's notes)
    neutral = (ti_pos or to_pos) and r_wy + r_yu <= 0
    if not to_pos:  # A and G's w column with the measurement folded in (models/_foldkernel.py; the law's row, unused)
        _fold_into(par, OFF_M, MAXN, d5[0], d5[1], dvy, dvv, N, A, G[0], mats[3, 6])
    zero_a = True
    for i in range(N):
        G[1, i] = VE[1, i]
        if to_pos:
            G[0, i] = VE[0, i]
            G[2, i] = VE[2, i]
            G[3, i] = VE[3, i]
        for k in range(N):
            if A[i, k] != 0.0:
                zero_a = False

    ne = et.shape[0]
    ke = 0
    while ke < ne and et[ke] < 0.0:
        ez[ke] = 0.0
        ke += 1
    uhold = 0.0
    ksamp = 0
    nexts = off if sampled else _INF
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
    ytr = 0.0  # the largest last coefficient of y (the truncation, over tdiv)
    nz = 0  # the states' and the signals' coefficients are zero from there on (cleared here; see _taylor.recursion)
    ms[_WMAX] = -_INF
    ms[_TPEAK] = _NAN
    ms[_T10] = _NAN
    ms[_T90] = _NAN
    ms[_TLAST] = 0.0
    ms[_WEND] = 0.0
    status = STATUS_OK
    regime = _LIN
    tiny = 0
    # pieces shorter than this do not advance (the command chatters): 1e-9 of the run, or less with short delays
    tiny_h = 1e-9 * max(1.0, tend)
    for dl in (ti, to, tm):
        if dl > 0.0:
            tiny_h = min(tiny_h, 1e-3 * dl)
    hlen = hmax  # the next piece's length, unless something cuts it shorter
    # the smoothness orders of the command and the output at the next piece's start (_NONE: analytic there), and
    # whether they come from images only (a neutral loop's are measured before they are stored)
    ou = 0  # the command and the output are not analytic at t = 0
    oy = 0
    u_img = False
    y_img = False
    self_ok = True  # whether this piece may read its own delayed signals (not after a failed fixed point)
    hcap = _INF  # this piece's length at most (a piece reading itself redone shorter)
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
        end = min(tend, a + min(hlen, hcap))
        t_img_u = _INF
        t_img_y = _INF
        t_img_m = _INF
        if sampled:
            end = min(end, nexts)
        t_knot = rt[kr + 1] if kr + 1 < nref else _INF
        end = min(end, t_knot)
        dist_on = has_dist and a >= tdist - eps
        if has_dist and not dist_on:
            end = min(end, tdist)
        # the images of the delayed signals' breakpoints, and their smoothness orders (gi_*); where none is stored
        # after the piece a delayed signal is read from and the piece starts where the signal is analytic, a delay
        # short against the piece (at most SELF hmax) is read from the piece being built (self_*)
        self_u = False
        self_y = False
        self_m = False
        gi_u = _NONE
        gi_y = _NONE
        gi_m = _NONE
        su = a - ti
        if ti_pos:
            qu, qgu, t_img_u, gi_u, self_u = _pending(tu0, ugen, nu, qu, qgu, su, a, ti, epsd,
                                                      self_ok and ou >= _NONE and ti <= SELF * hmax)
            end = min(end, t_img_u)
        sy = a - to
        if to_pos:
            qy, qgy, t_img_y, gi_y, self_y = _pending(ty0, ygen, ny, qy, qgy, sy, a, to, epsd,
                                                      cont and self_ok and oy >= _NONE and to <= SELF * hmax)
            end = min(end, t_img_y)
        sm = a - tm
        if tm_pos:
            qm, qgm, t_img_m, gi_m, self_m = _pending(tu0, ugen, nu, qm, qgm, sm, a, tm, epsd,
                                                      cont and self_ok and ou >= _NONE and tm <= SELF * hmax)
            end = min(end, t_img_m)
        # a piece reading its own delayed signal is at least twice that delay long (else it reads the stored
        # pieces, at most one delay ahead)
        if self_u and end - a < 2.0 * ti:
            self_u = False
            t_img_u = a + ti
            end = min(end, t_img_u)
        if self_y and end - a < 2.0 * to:
            self_y = False
            t_img_y = a + to
            end = min(end, t_img_y)
        if self_m and end - a < 2.0 * tm:
            self_m = False
            t_img_m = a + tm
            end = min(end, t_img_m)
        if ti_pos and su >= -epsd and not self_u:
            end = _read_end(tu0, thu, tuc, tdeg, False, nu, qu, ti, end, ctol)
        if to_pos and sy >= -epsd and not self_y:
            end = _read_end(ty0, tyh, tyc, tdeg, True, ny, qy, to, end, ctol)
        if tm_pos and sm >= -epsd and not self_m:
            end = _read_end(tu0, thu, tuc, tdeg, False, nu, qm, tm, end, ctol)
        self_any = self_u or self_y or self_m
        H = end - a
        # the delayed signals and the reference on this piece (a signal read from the piece being built starts
        # from the stored piece's continuation, or its value where that piece is much shorter)
        nW = 1
        Wd[0] = 0.0
        if ti_pos and su >= -epsd and nu > 0:
            if self_u and H > 2.0 * thu[qu]:
                nW = _held(tuc[qu], tdeg[qu], (max(su, tu0[qu]) - tu0[qu]) / thu[qu], Wd)
            else:
                nW = _delayed(tu0, thu, tuc, tdeg, qu, max(su, tu0[qu]), H, Wd, work)
        if to_pos:
            if sy >= -epsd and ny > 0:
                alpha = (max(sy, ty0[qy]) - ty0[qy]) / tyh[qy]
                if self_y and H > 2.0 * tyh[qy]:
                    _held(tyc[qy], NC, alpha, Ym)
                    _held(tyd[qy], NC, alpha, Vm)
                else:
                    if alpha < 1e-13:
                        alpha = 0.0
                    beta = H / tyh[qy]
                    if alpha == 0.0 and abs(beta - 1.0) < 1e-13:
                        beta = 1.0
                    _shift_scale(tyc[qy], _degree(tyc[qy], NC), alpha, beta, Ym, work)
                    _shift_scale(tyd[qy], _degree(tyd[qy], NC), alpha, beta, Vm, work)
            else:
                for j in range(NC):
                    Ym[j] = 0.0
                    Vm[j] = 0.0
        nUm = 1
        Um[0] = 0.0
        if tm_pos and sm >= -epsd and nu > 0:
            if self_m and H > 2.0 * thu[qm]:
                nUm = _held(tuc[qm], tdeg[qm], (max(sm, tu0[qm]) - tu0[qm]) / thu[qm], Um)
            else:
                nUm = _delayed(tu0, thu, tuc, tdeg, qm, max(sm, tu0[qm]), H, Um, work)
        nR = _ref_poly(rt, r0, rs, kr, a, H, R)
        dcur = dist if dist_on else 0.0
        for i in range(N):
            X[i, 0] = x0[i]
        # the regime (linear or saturated) and, with clamping, whether the integrator is frozen or the command
        # slides on its limit
        frozen = False
        sliding = False
        tried = not slide_on  # whether the piece was tested for a slide
        keep_regime = regime
        xc = 2.0
        prev_regime = regime
        attempt = 0
        failed = False
        while True:
            lim = umax if regime == _HIGH else umin
            # a delayed signal read from the piece being built: the fixed point of the recursion and the shift
            # (each pass reads the signal the last one gave, shifted back by the delay; see the module's notes)
            passes = 0
            while True:
                if known and (aw != 2 or regime == _LIN):
                    nt = _recursion_known(A, G, VE, N, H, frozen, integ, dcur + (0.0 if ti_pos else uhold), Wd, nW,
                                          R, nR, Ym, Vm, to_pos, need_yd, d5, X, Y, Yd, V, E, zero_a, sliding, lim,
                                          Fz, nz)
                else:
                    nt = _recursion(par, Mloc, VE, N, H, regime, frozen, algebraic, ti_pos, sampled, uhold, dcur, X,
                                    R, nR, Wd, nW, Ym, Vm, to_pos, Y, Yd, V, E, need_yd, Um, nUm, has_u, sliding, Fz,
                                    nz)
                nz = nt  # (the coefficients are zero from there on, for the next call)
                if not self_any:
                    break
                change = 0.0
                size = 1e-300
                if self_u or self_m:  # the command as applied on the piece: the law's output, or its limit
                    if cont and (regime == _LIN or sliding):
                        src, nsrc = V, _degree(V, nt)
                    else:  # held by a sampled controller, or on a limit
                        for k in range(NC):
                            work[k] = 0.0
                        work[0] = lim if cont else uhold
                        src, nsrc = work, 1
                    for k in range(nsrc):
                        size = max(size, abs(src[k]))
                    if self_u:
                        c, nW = _picard(src, nsrc, ti / H, Wd)
                        change = max(change, c)
                    if self_m:
                        c, nUm = _picard(src, nsrc, tm / H, Um)
                        change = max(change, c)
                if self_y:
                    for k in range(NC):
                        size = max(size, abs(Y[k]), abs(Yd[k]))
                    c, _ = _picard(Y, NC, to / H, Ym)
                    change = max(change, c)
                    c, _ = _picard(Yd, NC, to / H, Vm)
                    change = max(change, c)
                passes += 1
                if change <= 4.0 * 2.220446049250313e-16 * size:
                    break
                if passes >= _PICARD:
                    failed = True
                    break
                for i in range(N):
                    X[i, 0] = x0[i]
            if failed:
                break
            if not tried:
                # the command starts on a limit with the error driving it further: try a slide
                tried = True
                side = _on_limit(V[0], E, nt, umin, umax, ptol)
                if side != _LIN:
                    keep_regime = regime
                    regime = side
                    sliding = True
                    continue
            if sliding:
                # a Filippov slide holds while the integrator's rate stays between 0 and the free rate, both
                # fields pointing into the limit; it ends where the rate reaches either end
                ns = _slide_rates(X, integ, Fz, nt, S, D)
                want = (1.0 if regime == _HIGH else -1.0) * (1.0 if VE[7, integ] > 0.0 else -1.0)
                big = 0.0
                for k in range(ns):
                    big = max(big, abs(S[k] + D[k]))
                tol = 1e-12 * big
                if big > 0.0 and _lead_sign(S, ns, tol) == want and _lead_sign(D, ns, tol) == want:
                    xc = min(_first_cross(S, ns, 0.0, want, fs), _first_cross(D, ns, 0.0, want, fs))
                    break
                sliding = False  # no slide: the regime is decided as usual
                regime = keep_regime
                X[integ, 0] = x0[integ]
                continue
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
                    attempt += 1
                    continue
            # the first switch on the piece: the command leaves its regime, or the error changes sign
            xc = _first_switch(V, nv, E, nt, regime, frozen, umin, umax, aw, fs) if switches else 2.0
            # a switch at the very start: the piece began on the boundary in the wrong regime
            if attempt < 3 and xc < 1.0 and xc * H <= 1e-12 * max(1.0, abs(a) + H):
                probe = _horner(V, nv, min(1.0, max(16.0 * xc, 1e-9)))
                regime = _HIGH if probe > umax else (_LOW if probe < umin else _LIN)
                if aw == 1 and regime != _LIN:
                    ep = _horner(E, nt, min(1.0, max(16.0 * xc, 1e-9)))
                    frozen = (regime == _HIGH and ep > 0.0) or (regime == _LOW and ep < 0.0)
                else:
                    frozen = False
                attempt += 1
                continue
            break
        if failed or (self_any and cont and regime != prev_regime):
            # no fixed point (or the command turned out not analytic at the start): redo the piece shorter
            # (at most half as long; once shorter than twice the delay, it reads the stored pieces)
            if failed:
                hcap = 0.5 * H
            else:
                self_ok = False
            regime = prev_regime
            continue
        # the Taylor tail of the states and the command decides how long the next piece may be: as long as
        # their last coefficient stays below that of the loop's fastest mode over hmax (a piece that was longer
        # than hmax and missed that by far is redone shorter; one shorter than hmax, cut by a breakpoint, leaves
        # the length as it was)
        if H >= hmax * (1.0 - 1e-9) or self_any:
            tail = _tail(X, N, V, nt)
            grow = (_TAIL / tail) ** (1.0 / DEG) if tail > 0.0 else _INF
            if H > hmax * (1.0 + 1e-9) and tail > 64.0 * _TAIL:
                hlen = max(hmax, H * grow)
                regime = prev_regime
                continue
            if self_any and tail > 64.0 * _TAIL and grow < 0.9:
                # a piece reading itself sees the loop's closed-loop rates, which hmax may not bound
                hcap = H * grow
                regime = prev_regime
                continue
            if H >= hmax * (1.0 - 1e-9):
                hlen = min(_GROW * hmax, max(hmax, H * grow))
        hcap = _INF
        self_ok = True
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
        if cont and regime != prev_regime:  # the start is a breakpoint after all
            ou = 0
            u_img = False
        tiny = tiny + 1 if H < tiny_h else 0
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
            while nU > 1 and abs(V[nU - 1]) < 1e-19 * uref:
                nU -= 1
        else:
            uval = umax if regime == _HIGH else umin
        if nu > 0 and nU == 1 and tdeg[nu - 1] == 1 and tuc[nu - 1, 0] == uval:
            thu[nu - 1] = end - tu0[nu - 1]
            ou = _NONE  # the same constant on both sides: not a breakpoint of the command
        else:
            tu0[nu] = a
            thu[nu] = H
            tdeg[nu] = nU
            if nU == 1:
                tuc[nu, 0] = uval
            else:
                for j in range(nU):
                    tuc[nu, j] = V[j]
            if neutral and u_img and ou < _NONE and nu > 0:
                # a neutral loop's image: not a breakpoint any more where the jump of the command and of its
                # derivatives, over the window one delay long that its image would cover, is below rounding
                jd, js = _jump(tuc[nu - 1], tdeg[nu - 1], thu[nu - 1], tuc[nu], nU, H, ti if ti_pos else to, Wn,
                               work)
                if jd <= _JUMP * max(js, jscale):
                    ou = _NONE
            ugen[nu] = 0 if ou >= _NONE else ou + 1
            nu += 1
        nY = _degree(Y, nt)
        if keep_y:
            ty0[ny] = a
            tyh[ny] = H
            if neutral and y_img and oy < _NONE and ny > 0 and to_pos:
                jd, js = _jump(tyc[ny - 1], NC, tyh[ny - 1], Y, NC, H, to, Wn, work)
                jd2, js2 = _jump(tyd[ny - 1], NC, tyh[ny - 1], Yd, NC, H, to, Wn, work)
                if jd + jd2 <= _JUMP * max(js + js2, jscale):
                    oy = _NONE
            ygen[ny] = 0 if oy >= _NONE else oy + 1
            for j in range(NC):
                tyc[ny, j] = Y[j]
                tyd[ny, j] = Yd[j]
            ny += 1
        ytr = max(ytr, abs(Y[DEG]))
        if metrics:
            _step_metrics(Y, nY, norm, a, H, band, ms, Wn, dW, xs, fs, tdeg)
        # the requested samples of y on this piece
        while ke < ne and et[ke] <= end + eps:
            x = (et[ke] - a) / H
            ez[ke] = _horner(Y, nY, min(max(x, 0.0), 1.0))
            ke += 1
        # advance: the states, the left limits the next sample reads, and why the next piece starts
        if N == 1:  # the same sum, without the inner loop
            s1 = 0.0
            for j in range(nt):
                s1 += X[0, j]
            x0[0] = s1
        else:
            for i in range(N):
                x0[i] = 0.0
            for j in range(nt):  # the sums of the states' coefficients, side by side
                for i in range(N):
                    x0[i] += X[i, j]
        y_end = ms[_WEND] if metrics and norm == 1.0 else _sum(Y, nY)  # (the metrics' sum of the same Y)
        if sampled:  # what the next sample reads
            if to_pos:
                ym_left = _sum(Ym, NC)
                vm_left = _sum(Vm, NC)
            else:
                ym_left = y_end
                vm_left = _sum(Yd, nt)
        # the breakpoints at the next piece's start and their smoothness orders: an image through a path is
        # smoother by the path's relative degree; sources (a switch, a sample, a knot, the load) are order 0
        # (an image of this piece's own start has the order stored for it)
        gi_u = ou if gi_u < 0 else gi_u
        gi_m = ou if gi_m < 0 else gi_m
        gi_y = oy if gi_y < 0 else gi_y
        ou = _NONE
        oy = _NONE
        u_src = False
        y_src = False
        if cut:
            if cont:
                ou = 0
                u_src = True
                if not ti_pos:
                    oy = 0
                    y_src = True
        else:
            if end >= t_img_u - epsd and gi_u < _NONE:
                oy = gi_u + r_wy
            if cont and end >= t_img_y - epsd and gi_y < _NONE:
                ou = min(ou, gi_y + r_yu)
            if cont and end >= t_img_m - epsd and gi_m < _NONE:
                ou = min(ou, gi_m + r_mu)
            if sampled and end >= nexts - eps:
                ou = 0
                u_src = True
            if cont and end >= t_knot - eps:
                ou = 0
                u_src = True
            if has_dist and not dist_on and end >= tdist - eps:
                oy = 0
                y_src = True
            if not ti_pos and ou < _NONE:
                oy = min(oy, ou + r_wy)
                y_src = y_src or u_src
            if not to_pos and oy < _NONE and cont:
                ou = min(ou, oy + r_yu)
                u_src = u_src or y_src
        ou = _NONE if ou > DEG else max(ou, 0)
        oy = _NONE if oy > DEG else max(oy, 0)
        u_img = not u_src
        y_img = not y_src
        a = end
        n += 1

    while ke < ne:
        ez[ke] = y_end
        ke += 1
    _metrics_row(out, metrics, ms[_WMAX], ms[_WEND], ms[_TPEAK], ms[_T10], ms[_T90], ms[_TLAST], norm, band)
    out[8] = ytr / tdiv  # (max(a, b) / t is max(a / t, b / t): division by t > 0 keeps the order)
    out[9] = n
    out[10] = status
    out[11] = nu
    out[12] = ny
    out[13] = a
    return n


def run_batch(pars, cap, nchunks, nsets=1):
    """Metrics of many loops (one parameter row each, a step or ramp reference): ``nchunks`` chunks of rows, taken
    in turn by ``nsets`` work sets run in parallel (one per thread)."""
    return _runs(pars, np.empty(0, dtype=np.int64), np.empty((pars.shape[0], 0)), cap, nchunks, nsets)


def run_sweep(row, cols, vals, cap, nchunks, nsets=1):
    """:func:`run_batch` of ``vals.shape[0]`` loops given compactly: loop ``i``'s parameter row is ``row`` with the
    columns ``cols`` set to ``vals[i]`` (a sweep reads the few columns its loops differ in, not its rows repeated:
    35 MB for 10,000 loops).  Each work set writes the loop's values into its own copy of ``row`` before the run."""
    rows = np.empty((1, row.shape[0]))
    rows[0, :] = row
    return _runs(rows, cols, vals, cap, nchunks, nsets)


def _runs(pars, cols, vals, cap, nchunks, nsets):
    """:func:`run_batch` (``cols`` empty: ``pars`` holds every loop's row) and :func:`run_sweep` (``pars`` holds
    the one shared row): the work sets' arrays, padded so that no two sets' arrays share a cache line (each set
    writes its ``buf`` and ``ref`` at every piece)."""
    m = vals.shape[0]
    out = np.empty((m, NOUT))
    nsets = max(1, min(nsets, nchunks))
    tu0 = np.empty((nsets, cap))
    thu = np.empty((nsets, cap))
    tuc = np.zeros((nsets, cap, NC))
    tdeg = np.empty((nsets, cap), dtype=np.int64)
    ugen = np.empty((nsets, cap), dtype=np.int8)
    ty0 = np.empty((nsets, cap))
    tyh = np.empty((nsets, cap))
    tyc = np.empty((nsets, cap, NC))
    tyd = np.empty((nsets, cap, NC))
    ygen = np.empty((nsets, cap), dtype=np.int8)
    X = np.empty((nsets, MAXN, NC + 1))
    buf = np.empty((nsets, _NBUF + _PAD))
    mats = np.empty((nsets, 4, MAXN, MAXN))
    ref = np.zeros((nsets, _PAD))  # the reference's knot, value and slope (rt, r0, rs)
    row = np.empty((nsets, pars.shape[1] + _PAD))  # each set's copy of the shared row (run_sweep's)
    if cols.shape[0] > 0:
        for s in range(nsets):
            row[s, :pars.shape[1]] = pars[0]
    none = np.empty(0)
    if nsets == 1:  # on this thread: a parallel loop of one set would keep OpenMP's other threads spinning idle
        _set_chunks(pars, cols, vals, cap, nchunks, 1, 0, out, tu0[0], thu[0], tuc[0], tdeg[0], ugen[0], ty0[0],
                    tyh[0], tyc[0], tyd[0], ygen[0], X[0], buf[0], mats[0], ref[0], row[0], none)
    else:
        _batch_sets(pars, cols, vals, cap, nchunks, nsets, out, tu0, thu, tuc, tdeg, ugen, ty0, tyh, tyc, tyd, ygen, X,
                    buf, mats, ref, row, none)
    return out


def _batch_sets(pars, cols, vals, cap, nchunks, nsets, out, tu0, thu, tuc, tdeg, ugen, ty0, tyh, tyc, tyd, ygen, X, buf,
                mats, ref, row, none):
    """:func:`_runs`' parallel loop: work set ``s`` runs the chunks ``s, s + nsets, ...`` on its own arrays."""
    for s in prange(nsets):
        _set_chunks(pars, cols, vals, cap, nchunks, nsets, s, out, tu0[s], thu[s], tuc[s], tdeg[s], ugen[s], ty0[s],
                    tyh[s], tyc[s], tyd[s], ygen[s], X[s], buf[s], mats[s], ref[s], row[s], none)


def _chunk(m, nchunks, nsets, s, k):
    """Rows ``lo:hi`` of work set ``s``'s ``k``-th chunk: the chunk ``s + k nsets`` of ``nchunks`` near-equal chunks of
    ``m`` rows (sets take the chunks in turn: a sweep whose cost grows along its rows is shared evenly), empty for
    ``k`` past the set's last.  The batch loops of this module and :mod:`._sampled_batch` run ``k`` over
    ``range(nchunks)``."""
    c = min(s + k * nsets, nchunks)
    return c * m // nchunks, min(c + 1, nchunks) * m // nchunks


def _set_chunks(pars, cols, vals, cap, nchunks, nsets, s, out, tu0, thu, tuc, tdeg, ugen, ty0, tyh, tyc, tyd, ygen, X,
                buf, mats, ref, row, none):
    """Work set ``s`` of :func:`_runs`: its chunks (:func:`_chunk`) on that set's arrays (``ref``: the reference's knot,
    value and slope; ``row``: its copy of the shared row; ``none``: no samples of y).  The set's arrays are sliced
    once, here, not per row (compiled by Cython, each slice kept in a variable counts a reference on the batch's
    shared array: ``par``, once per row, is the one such slice left in the loop)."""
    m = vals.shape[0]
    nv = cols.shape[0]
    for k in range(nchunks):
        lo, hi = _chunk(m, nchunks, nsets, s, k)
        for i in range(lo, hi):
            if nv == 0:
                par = pars[i]
            else:
                for j in range(nv):
                    row[cols[j]] = vals[i, j]
                par = row
            ref[1] = par[_STEP]
            ref[2] = par[_SLOPE]
            _run(par, ref[0:1], ref[1:2], ref[2:3], cap, tu0, thu, tuc, tdeg, ugen, ty0, tyh, tyc, tyd, ygen, out[i],
                 False, none, none, X, buf, mats)
