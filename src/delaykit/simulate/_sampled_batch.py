"""Sampled loops stepped exactly from event to event with matrix exponentials: the batch simulator's fast path.

A loop whose controller samples (zero-order hold), with no output delay, no anti-windup and no predictor in the
controller, driven by a step or ramp reference (and at most a step load), is between two consecutive *events*
(a sample ``t_k = offset + k h``, its image ``t_k + Ti`` one input delay later where the held command reaches
the plant, the load's start) one linear time-invariant system with a constant input: with ``z = (X, w, r, r')``
(the loop's states of :mod:`._layout`, the plant's input ``w = u(t - Ti) + d``, the reference and its slope),

    z' = Z z,        Z = [[A, b, br, 0], [0, 0, 0, 0], [0, 0, 0, 1], [0, 0, 0, 0]],

where ``A = M + bym cy' + bvm cyd'`` and ``b = bw + bym dy + bvm dyd`` fold the measurement (the output itself,
no output delay) into the states.  So ``z(a + tau) = exp(Z tau) z(a)`` exactly.  Since ``Ti = m h + f``, the
intervals have two lengths (``f`` and ``h - f``) but at the start and the end of the run and around the
load's start: each run computes ``exp(Z tau)`` once per distinct length (delaykit's one matrix exponential,
:func:`delaykit.models._expmkernel.expm_into`: scaling and squaring around a Taylor series whose remainder bound,
below 2.4e-17 relative, it reports; lengths that differ only by the rounding of the event times,
16 units in the last place of ``t_end``, share one), and steps each interval with one matrix-vector product
(a small loop in the regular pattern, a sample then one image inside the period, goes a whole period at a time:
one product for the states at the next sample, and the output's quantities at the image from the same start).
At a sample the controller reads the output's and its derivative's left limits and the reference there (as
the Taylor kernel, :mod:`._kernel`, does) and clips its output to the limits; the command waits in a ring
buffer for its image.  Events closer than the kernel's ``eps`` are one event, handled in the kernel's order
(the sample reads its left limits first, then the plant's input changes).

The step metrics (those of :mod:`._kernel`: overshoot and peak time, the 10 % and 90 % crossings, the last time
outside the settling band, the final value) are taken on the continuous output, exactly.  Within an interval the
output depends only on the part ``S`` of ``z`` it can see (the plant's states and ``w``: the controller does not
act on the plant between events), so with ``x = (t - a) / tau`` on ``[0, 1]``, ``v0 = Z z(a)`` and
``Y(x) = y(a + x tau)``:

    Y'(x) - Y'(0) = tau sum_{k>=1} x^k c' (Z tau)^k v0 / k!,   so  |Y'(x) - Y'(0)| <= x G,   G = sum_i |v0_i| G_i,

with ``G_i = tau sum_{k>=1} |c' (Z_S tau)^k e_i| / k!`` computed once per interval length (the series summed to
order ``K`` <= 48 where its tail, bounded by ``||c||_1 beta^(K+1) / (K+1)! / (1 - beta/(K+2))`` with
``beta = ||Z_S tau||_inf <= 8``, is below 1e-9 of the largest weight, and that bound added; beyond ``beta = 8``,
``G = inf``).  Hence, rigorously (up to rounding, covered by a margin of 1e-14 relative):

* ``Y(x)`` lies within ``x^2 G / 2`` of the line ``Y(0) + x Y'(0)``: the interval's range is bounded from the
  state at its start, in a few operations;
* if ``|Y'(0)| > G``, ``Y`` is strictly monotone on the interval: its extrema are its end values, it crosses a
  level at most once and only if the level lies between its ends, and it stays inside the band if both ends do.

An interval is examined further only when this bound says it *may* matter: its range may exceed the running
maximum, or reach 0.1 or 0.9 before they are found, or leave the settling band while its end lies inside it
(an end outside makes the end the latest time outside, with no need to look in), and monotonicity with the
end values does not settle the question.  It is then expanded as the output's Taylor polynomial in ``x`` (the
coefficients ``c' Z_S^(j-1) v0 tau^j / j!``, degree raised until the remainder bound
``||c||_1 ||q_K||_inf (beta/(K+1)) / (1 - beta/(K+2))`` is below 1e-17 of the step (cut into 2^p sub-pieces
with ``beta <= 1`` when needed), and the kernel's metric rules (:func:`._kernel._metrics_update`) are applied to
it with certified root isolation (:func:`._poly.crossings`): the polynomial is evaluated on a grid of 16 cells;
a cell whose ends have the same sign is dropped only if ``min(|f_l|, |f_r|) > w^2 B2 / 8`` or
``|f_l| + |f_r| > w B1`` (``B1``, ``B2`` bounds of ``|f'|``, ``|f''|`` on [0, 1]: then ``f`` cannot vanish
inside), a cell with a sign change is refined
(:func:`._poly.refine`) only if ``|f'(l)| > w B2`` (then it holds exactly one root); any other cell is
bisected, until ``f`` at both its ends is within the rounding of its evaluation (a tangency, whose sign is not
resolved: it is then counted as the kernel's grid would see its ends) or its width is 2^-40 of the interval.
So no extremum above the running maximum, no first crossing of 0.1 or 0.9 and no exit from the band is missed:
an interval is skipped only when the bound proves it irrelevant, and an examined one has its roots certified.

One source, three modes, as the Taylor kernel (see :mod:`delaykit._native`): the extension module Cython built
(C types in ``_sampled_batch.pxd``), numba's compilation of this file where none was built, or plain Python (for
checking).  This module is private.

Examples
--------
>>> from delaykit import _native
>>> _native.load("delaykit.simulate", "_sampled_batch", "python").NSLOT  # exponentials a run keeps at once
6
"""

from __future__ import annotations

import math

import numpy as np

from ._layout import DEG, HEAD, MAXN, NC, NOUT, OFF_BR, OFF_CY, OFF_M, STATUS_OK
from ._poly import MAXX as _MAXX, STACK as _STACK  # the certified root search's most roots, and its stack

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

if cython.compiled:  # the certified roots and the step metrics' update (shared with the Taylor kernel), as C
    from cython.cimports.delaykit.simulate._kernel import _chunk, _metrics_row, _metrics_update
    from cython.cimports.delaykit.simulate._poly import crossings as _crossings
    from cython.cimports.delaykit.models._expmkernel import expm_into
    from cython.cimports.delaykit.models._foldkernel import fold_into as _fold_into
    from cython.cimports.libc.math import INFINITY as _INF, NAN as _NAN, isinf
    from cython.parallel import prange
else:  # the same modules run as this one is (numba's copies, or Python)
    from math import inf as _INF, isinf, nan as _NAN

    from .._native import sibling

    _crossings = sibling(__name__, "_poly").crossings  # certified roots (see the module's notes)
    expm_into = sibling(__name__, "_expmkernel", "delaykit.models").expm_into  # the one matrix exponential
    _fold_into = sibling(__name__, "_foldkernel", "delaykit.models").fold_into
    _k = sibling(__name__, "_kernel")
    _metrics_update, _metrics_row, _chunk = _k._metrics_update, _k._metrics_row, _k._chunk
    if __name__.endswith("_numba"):
        from numba import prange
    else:
        from builtins import range as prange

__all__ = ["run_one", "run_batch", "NSLOT", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

(_N, _TI, _TO, _UMIN, _UMAX, _PERIOD, _OFFSET, _T_END, _BAND, _NORM, _DIST, _T_DIST, _DY, _DYD, _DVR, _DVY, _DVV,
 _INTEG, _AW, _HMAX, _SCALE, _STEP, _SLOPE, _TM) = HEAD.values()

NSLOT = 6
"""Interval lengths whose exponentials a run keeps at once (two recur; the others are the run's few odd ones)."""
_NSLOT = NSLOT  # (a C value where compiled; the public name stays Python's)
_NA = MAXN + 3  # the augmented state: the loop's states, then w, r, r'
_NQ = MAXN + 3 + _NA  # the rows of an interval's map: the states, Y(0), Y(1), Y'(0), Z_S z
# a small loop (at most 8 components in z, 4 seen by the output, 2 of those moving) runs at these fixed lengths
_SA, _SS = 8, 4
_GKEEP = 48  # terms of the series of G_i (see the module's docstring)
_GMAX_BETA = 8.0  # beyond this ||Z_S tau||, no cheap bound (every interval is expanded)
_SUB_BETA = 1.0  # the expansion's sub-pieces have ||Z_S tau|| at most this
_REM = 1e-17  # the expansion's remainder, relative to the step
_MARGIN = 1e-14  # rounding margin of the cheap bound, relative
# the running metrics (the kernel's but its last, w at the end), as an expansion reads and updates them: highest w
# and when, first times w >= 0.1 and 0.9, last time outside the band
_WMAX, _TPEAK, _T10, _T90, _TLAST = range(5)  # (the kernel's order: see _kernel._WMAX ...)
# numba's options where it compiles this file (see delaykit._native): the batch in parallel, small helpers inlined
NUMBA_OPTIONS = {"_row4": {"inline": "always"}, "_slope_bound": {"inline": "always"},
                 "_interval_metrics": {"inline": "always"}, "_batch_sets": {"parallel": True}}


def _poly_metrics(Wn, nW, a, H, band, ms, dW, xs, sr, sd):
    """The kernel's metric update (:func:`._kernel._metrics_update`) on the piece ``Wn`` (the normalised output
    over ``[a, a + H]``), with certified roots (:func:`._poly.crossings`)."""
    _metrics_update(Wn, nW, a, H, band, ms, dW, xs, xs, sr, sd, True)


def _expand(zs, Zs, cs, ns, tau, a, inv, ref, band, ms, q, qn, zsum, Y, Wn, dW, xs, sr, sd):
    """Apply the metrics to one interval through the output's Taylor polynomial (sub-pieces where
    ``||Z_S tau||`` exceeds ``_SUB_BETA``); ``zs`` (the state seen by the output at the start) is overwritten.
    Returns the largest remainder bound, relative to ``ref``."""
    beta = 0.0
    c1 = 0.0
    for i in range(ns):
        s = 0.0
        for k in range(ns):
            s += abs(Zs[i, k])
        beta = max(beta, s * tau)
        c1 += abs(cs[i])
    nsub = 1
    while beta / nsub > _SUB_BETA:
        nsub *= 2
    h = tau / nsub
    bh = beta / nsub
    trunc = 0.0
    for sub in range(nsub):
        y = 0.0
        for i in range(ns):
            y += cs[i] * zs[i]
            zsum[i] = 0.0
        Y[0] = y
        for i in range(ns):  # q_1 = h Z_S z
            s = 0.0
            for k in range(ns):
                s += Zs[i, k] * zs[k]
            q[i] = h * s
        nt = 1
        rem = 0.0
        for j in range(1, NC):
            y = 0.0
            mx = 0.0
            for i in range(ns):
                y += cs[i] * q[i]
                zsum[i] += q[i]
                mx = max(mx, abs(q[i]))
            Y[j] = y
            nt = j + 1
            rem = c1 * mx * (bh / (j + 1)) / (1.0 - bh / (j + 2))
            if rem <= _REM * ref or j == DEG:
                break
            for i in range(ns):  # q_{j+1} = h / (j + 1) Z_S q_j
                s = 0.0
                for k in range(ns):
                    s += Zs[i, k] * q[k]
                qn[i] = s * h / (j + 1)
            for i in range(ns):
                q[i] = qn[i]
        trunc = max(trunc, rem / ref)
        for j in range(nt):
            Wn[j] = Y[j] * inv
        _poly_metrics(Wn, nt, a + sub * h, h, band, ms, dW, xs, sr, sd)
        for i in range(ns):
            zs[i] += zsum[i]
    return trunc


def _row4(M, s, r, z0, z1, z2, z3):
    """Row ``r`` of the map ``M[s]`` applied to the first four states, summed as a tree (the small systems'
    fixed order, which the results depend on to the last bit)."""
    return (M[s, r, 0] * z0 + M[s, r, 1] * z1) + (M[s, r, 2] * z2 + M[s, r, 3] * z3)


def _slope_bound(G, cheap, s, v0, v1):
    """The cheap bound on the interval's higher terms from the command's coefficients ``v0``, ``v1`` (slot
    ``s``), or, where that length has none, 0 if they vanish and infinity (expand the interval) if not."""
    if cheap[s]:
        return abs(v0) * G[s, 0] + abs(v1) * G[s, 1]
    return 0.0 if v0 == 0.0 and v1 == 0.0 else _INF


def _interval_metrics(y0, y1, d1, gs, a, end, st, inv, ainv, band):
    """The metrics of one interval ``[a, end]`` from the output at its ends (``y0``, ``y1``), ``tau Y'(0)``
    (``d1``) and the cheap bound's ``G`` (``gs``); ``st`` holds the running metrics (``wmax, tpeak, t10, t90,
    tlast``; NaN: not found yet).  Returns them updated, the end's normalised output, and whether the interval
    must be expanded instead (:func:`_expanded`; ``st`` is then returned as it was)."""
    wmax, tpeak, t10, t90, tlast = st
    # the cheap bound: Y(x) within x^2 G / 2 of Y(0) + x Y'(0); monotone if |Y'(0)| > G
    w0 = y0 * inv
    w1 = y1 * inv
    d1 *= inv
    gs *= ainv
    mg = _MARGIN * (abs(w0) + abs(d1) + gs) + 1e-300
    hi = w0 + max(0.0, d1) + 0.5 * gs + mg
    lo = w0 + min(0.0, d1) - 0.5 * gs - mg
    w1out = abs(w1 - 1.0) >= band  # then the interval's last moment is outside: no need to look inside
    peak = hi > wmax
    bchk = not w1out and (hi - 1.0 >= band or lo - 1.0 <= -band)
    open10 = t10 != t10  # (NaN: not found yet)
    open90 = t90 != t90
    if peak or bchk or open10 or open90:
        mono = abs(d1) > gs + mg or (d1 == 0.0 and gs == 0.0)
        need = peak and not mono
        if open10 and hi >= 0.1 and w0 < 0.1 and not (mono and w1 < 0.1):
            need = True
        if open90 and hi >= 0.9 and w0 < 0.9 and not (mono and w1 < 0.9):
            need = True
        if bchk and not (mono and abs(w0 - 1.0) < band):
            need = True
        if need:
            return st, w1, True
        if peak:  # monotone: the ends (the kernel's order: the end, then the start)
            if w1 > wmax:
                wmax = w1
                tpeak = end
            if w0 > wmax:
                wmax = w0
                tpeak = a
        if open10 and w0 >= 0.1:
            t10 = a
        if open90 and w0 >= 0.9:
            t90 = a
    if w1out:
        tlast = end
    return (wmax, tpeak, t10, t90, tlast), w1, False


def _expanded(st, src, row, ns, tau, a, inv, ref, band, ms, Zs, cs, zs, q, qn, zsum, Y, Wn, dW, xs, sr, sd):
    """The running metrics ``st`` (as :func:`_interval_metrics`) after one interval expanded (:func:`_expand`)
    from the state the output sees at its start, ``src[row, :ns]``; and the expansion's remainder bound."""
    for i in range(ns):
        zs[i] = src[row, i]
    ms[_WMAX], ms[_TPEAK], ms[_T10], ms[_T90], ms[_TLAST] = st
    trunc = _expand(zs, Zs, cs, ns, tau, a, inv, ref, band, ms, q, qn, zsum, Y, Wn, dW, xs, sr, sd)
    return (ms[_WMAX], ms[_TPEAK], ms[_T10], ms[_T90], ms[_TLAST]), trunc


def _pair(Q, sa, sb, tau_a, N, dpos, pw, pr, prs, ns, EA, Pab, gb, Es, Rb, Rbw):
    """A small loop's map over a whole period, the interval ``sa`` then ``sb`` (whose plant input differs by one
    image): the states at the end are ``Pab z + (w_b - w_a) gb`` (``z`` at the start, holding ``w_a``), the part
    the output sees at the image is ``Es z[:4]`` (then holding ``w_b``), and the second interval's output at its
    end and ``Z_S z`` at its start are ``Rb z[:4] + Rbw w_b``."""
    for i in range(_SA):
        for k in range(_SA):
            EA[i, k] = 0.0
    for d in range(N):  # exp(Z tau_a), its rows rebuilt: the states', then w's, r's and r''s (known)
        for k in range(_SA):
            EA[dpos[d], k] = Q[sa, d, k]
    EA[pw, pw] = 1.0
    EA[pr, pr] = 1.0
    EA[pr, prs] = tau_a
    EA[prs, prs] = 1.0
    for d in range(N):
        for k in range(_SA):
            s = 0.0
            for j in range(_SA):
                s += Q[sb, d, j] * EA[j, k]
            Pab[d, k] = s
        gb[d] = Q[sb, d, pw]
    for i in range(_SS):
        for k in range(_SS):
            Es[i, k] = EA[i, k] if (i < ns and k < ns) else 0.0
    # the second interval's output at its end and Z_S z at its start, straight from the first's start:
    # Rb z[:4] + Rbw w_b
    for m in range(3):
        r = N + 1 if m == 0 else N + 2 + m
        for j in range(_SS):
            s = 0.0
            for k in range(_SS):
                if k != pw:
                    s += Q[sb, r, k] * Es[k, j]
            Rb[m, j] = s
        Rbw[m] = Q[sb, r, pw] if pw < _SS else 0.0


def _fill_slot(Z, na, N, tau, dpos, ns, cs, rows, nrow, metrics, slot, Q, G, A, E, T, W, gw):
    """For the interval length ``tau``: ``Q[slot]``, the map from the state at an interval's start (``z``,
    ``Z[:ns, :ns]`` being ``Z_S``) to, in its rows, the loop's states at the end (``N``, in the order of
    ``dpos``) and, with ``metrics``, the output at the start and at the end, ``Y'(0)`` and ``Z_S z`` (its
    rows ``rows``; these read ``z[:ns]`` only); and ``G[slot]``, the cheap bound's weights of those rows.
    Returns the exponential's remainder bound.  ``gw``: work space (3 rows of ``na``)."""
    for i in range(na):
        for j in range(na):
            A[i, j] = Z[i, j] * tau
    rem = expm_into(A[:na, :na], E[:na, :na], T[:na, :na], W[:na, :na])
    for r in range(N + 3 + _SS):  # (zeros around a small loop's map, applied at fixed lengths)
        for k in range(_SA):
            Q[slot, r, k] = 0.0
    for r in range(_SS):
        G[slot, r] = 0.0
    for d in range(N):
        for k in range(na):
            Q[slot, d, k] = E[dpos[d], k]
    if not metrics:
        return rem
    for k in range(ns):  # these read z[:ns] only (S is closed)
        y1 = 0.0
        d1 = 0.0
        for i in range(ns):
            y1 += cs[i] * E[i, k]
            d1 += cs[i] * Z[i, k]
        Q[slot, N, k] = cs[k]
        Q[slot, N + 1, k] = y1
        Q[slot, N + 2, k] = d1 * tau
        for r in range(nrow):
            Q[slot, N + 3 + r, k] = Z[rows[r], k]
    # the weights G_i = tau sum_k |c' (Z_S tau)^k e_i| / k!, with the tail bound
    beta = 0.0
    c1 = 0.0
    for i in range(ns):
        s = 0.0
        for k in range(ns):
            s += abs(Z[i, k])
        beta = max(beta, s * tau)
        c1 += abs(cs[i])
    if beta > _GMAX_BETA:
        for r in range(nrow):
            G[slot, r] = _INF
        return rem
    rho = gw[0]
    rn = gw[1]
    g = gw[2]
    for i in range(ns):
        g[i] = 0.0
    for i in range(ns):
        rho[i] = cs[i]
    pw = c1  # ||c||_1 beta^k / k!, which bounds every term of order k
    tail = 0.0
    for k in range(1, _GKEEP + 1):
        big = 0.0
        for i in range(ns):
            s = 0.0
            for l in range(ns):
                s += rho[l] * Z[l, i]
            rn[i] = s * tau / k
        for i in range(ns):
            rho[i] = rn[i]
            g[i] += abs(rn[i])
            big = max(big, g[i])
        pw *= beta / k
        # the terms after order k (their ratio beta / (j + 1) below 1 from here on, or no bound yet)
        tail = pw * (beta / (k + 1)) / (1.0 - beta / (k + 2)) if beta < k + 2 else _INF
        if tail <= 1e-9 * big or (big == 0.0 and tail <= 1e-300):
            break
    for r in range(nrow):
        G[slot, r] = tau * (g[rows[r]] + tail)
    return rem


def run_one(par, out, Z, Q, G, taus, A, E, T, W, zb, acc, zs, Zs, q, qn, zsum, Y, Wn, dW, xs, sr, sd, ms, EA,
            Pab, gb, Es, Rb, Rbw, zi, Z0, vec, ring, flags, idx, used, gw):
    """Simulate one eligible sampled loop (its parameter row ``par``, a step or ramp reference) and fill ``out``
    with the kernel's columns (:data:`._layout.OUT`); the other arguments are work space (see :func:`run_batch`:
    ``ring`` holds at least ``ti / period + 4`` numbers).  Returns the number of intervals."""
    N = int(par[_N])
    na = N + 3
    ti = par[_TI]
    umin = par[_UMIN]
    umax = par[_UMAX]
    per = par[_PERIOD]
    off = par[_OFFSET]
    tend = par[_T_END]
    band = par[_BAND]
    norm = par[_NORM]
    dist = par[_DIST]
    tdist = par[_T_DIST]
    dy = par[_DY]
    dyd = par[_DYD]
    dvr = par[_DVR]
    dvy = par[_DVY]
    dvv = par[_DVV]
    step = par[_STEP]
    slope = par[_SLOPE]
    scale = par[_SCALE]
    eps = 1e-12 * max(1.0, tend)
    ttol = 16.0 * 2.220446049250313e-16 * max(1.0, tend)  # interval lengths equal up to the events' rounding
    metrics = norm != 0.0
    has_dist = dist != 0.0
    ref = max(abs(norm), scale, 1e-300)
    inv = 1.0 / norm if metrics else 0.0
    ainv = abs(inv)

    # z' = Z z, z = (X, w, r, r'); y = c.z, the law's output v = kv.z (with the left limits of y and y')
    iw, ir, irs = N, N + 1, N + 2
    c0, k0, c, kv, cs = vec[0], vec[1], vec[2], vec[3], vec[4]
    seen, cheap = flags[0], flags[1]
    perm, pos, dpos, rows = idx[0], idx[1], idx[2], idx[3]
    for i in range(na):
        c0[i] = 0.0
        k0[i] = 0.0
        for k in range(na):
            Z0[i, k] = 0.0
    # the measurement folded in (models/_foldkernel.py): A in Z0's first N columns, b in its column iw, k and kw in k0
    k0[iw] = _fold_into(par, OFF_M, MAXN, dy, dyd, dvy, dvv, N, Z0, Z0[:, iw], k0)
    for i in range(N):
        Z0[i, ir] = par[OFF_BR + i]
        c0[i] = par[OFF_CY + i]
    Z0[ir, irs] = 1.0
    c0[iw] = dy
    k0[ir] = dvr
    # the part S of z the output sees (closed under "the derivative of a seen component reads it") goes first:
    # z is kept in that order, z[:ns] = S
    for i in range(na):
        seen[i] = c0[i] != 0.0
    grew = True
    while grew:
        grew = False
        for i in range(na):
            if seen[i]:
                for j in range(na):
                    if Z0[i, j] != 0.0 and not seen[j]:
                        seen[j] = True
                        grew = True
    ns = 0
    for i in range(na):
        if seen[i]:
            perm[ns] = i
            ns += 1
    k = ns
    for i in range(na):
        if not seen[i]:
            perm[k] = i
            k += 1
    for i in range(na):
        pos[perm[i]] = i
    for i in range(_NA):
        kv[i] = 0.0  # (zeros past na: a small loop's law is applied at a fixed length)
    for i in range(na):
        c[i] = c0[perm[i]]
        kv[i] = k0[perm[i]]
        for j in range(na):
            Z[i, j] = Z0[perm[i], perm[j]]
    pw, pr, prs = pos[iw], pos[ir], pos[irs]
    for i in range(N):  # where each of the loop's states sits in z
        dpos[i] = pos[i]
    nrow = 0  # the rows of Z_S that are not zero: rows[:nrow]
    for i in range(ns):
        cs[i] = c[i]
        nz = False
        for j in range(ns):
            Zs[i, j] = Z[i, j]
            nz = nz or Z[i, j] != 0.0
        if nz:
            rows[nrow] = i
            nrow += 1
    nq = N + 3 + nrow if metrics else N  # the rows of an interval's map

    # the held commands waiting for their image (a ring)
    nring = int(ti / per)  # (a C cast where compiled, then the sum)
    nring += 4
    nslot = 0
    for s in range(_NSLOT):
        taus[s] = -1.0
        used[s] = 0  # the interval that last used each length
        cheap[s] = False  # whether a length has the cheap bound (||Z_S tau|| <= 8)
    ms[_WMAX] = -_INF
    ms[_TPEAK] = _NAN
    ms[_T10] = _NAN
    ms[_T90] = _NAN
    ms[_TLAST] = 0.0
    # the running metrics (as the kernel's): wmax, tpeak, t10, t90, tlast
    st = (-_INF, _NAN, _NAN, _NAN, 0.0)
    wend = 0.0
    cw = c[pw]  # the plant's direct feedthrough: the output jumps by cw times the input's
    pair_a = -1  # the period's map (small loops): of which two lengths
    pair_b = -1
    pair_ta = 0.0
    pair_tb = 0.0
    for i in range(zb.shape[1]):
        zb[0, i] = 0.0
        zb[1, i] = 0.0
    zb[0, prs] = slope
    zb[1, prs] = slope
    small = na <= _SA and ns <= _SS and nrow <= 2
    cr0 = cs[rows[0]] if nrow > 0 else 0.0  # Y'(0) = tau (c_S . Z_S z) from the rows that are not zero
    cr1 = cs[rows[1]] if nrow > 1 else 0.0
    trunc = 0.0
    ks = 0  # samples taken
    kput = 0  # where the next one goes in the ring
    ki = 0  # images reached
    kget = 0
    ts = off
    timg = off + ti
    wu = 0.0
    dcur = 0.0
    dist_on = False
    a = 0.0
    n = 0
    slot = 0
    slot_prev = 0
    cur = 0  # z is double-buffered (zb[cur], then zb[1 - cur]): no store waits for the next interval's loads
    while a < tend - eps:
        # events at a: the sample reads the left limits, then the plant's input changes
        sampled = ts <= a + eps
        if sampled:
            zb[cur, pw] = wu + dcur
            zb[cur, pr] = step + slope * a
            if small:
                v = (((kv[0] * zb[cur, 0] + kv[1] * zb[cur, 1]) + (kv[2] * zb[cur, 2] + kv[3] * zb[cur, 3]))
                     + ((kv[4] * zb[cur, 4] + kv[5] * zb[cur, 5]) + (kv[6] * zb[cur, 6] + kv[7] * zb[cur, 7])))
            else:
                v = 0.0
                for i in range(na):
                    v += kv[i] * zb[cur, i]
            while ts <= a + eps:
                ring[kput] = min(max(v, umin), umax)
                kput = kput + 1 if kput + 1 < nring else 0
                ks += 1
                ts = off + ks * per
        while timg <= a + eps and ki < ks:
            wu = ring[kget]
            kget = kget + 1 if kget + 1 < nring else 0
            ki += 1
            timg = off + ki * per + ti
        if has_dist and not dist_on and a >= tdist - eps:
            dcur = dist
            dist_on = True
        zb[cur, pw] = wu + dcur
        zb[cur, pr] = step + slope * a
        # a small loop in the regular pattern (a sample now, one image inside the period, nothing else before the
        # next sample) goes a whole period at a time while it stays so, the lengths' maps already at hand
        if (small and sampled and a + eps < timg < ts - eps and ts < tend - eps
                and (not has_dist or dist_on or tdist > ts + eps)):
            fa = timg - a
            fb = ts - timg
            sa = -1
            sb = -1
            for s in range(nslot):
                if abs(taus[s] - fa) <= ttol:
                    sa = s
                if abs(taus[s] - fb) <= ttol:
                    sb = s
            if sa >= 0 and sb >= 0:
                if not (pair_a == sa and pair_b == sb and pair_ta == taus[sa] and pair_tb == taus[sb]):
                    _pair(Q, sa, sb, taus[sa], N, dpos, pw, pr, prs, ns, EA, Pab, gb, Es, Rb, Rbw)
                    pair_a, pair_b, pair_ta, pair_tb = sa, sb, taus[sa], taus[sb]
                used[sa] = n
                used[sb] = n
                while True:
                    nxt = 1 - cur
                    wa = zb[cur, pw]
                    wb = ring[kget] + dcur
                    dw = wb - wa
                    z0, z1, z2, z3 = zb[cur, 0], zb[cur, 1], zb[cur, 2], zb[cur, 3]
                    z4, z5, z6, z7 = zb[cur, 4], zb[cur, 5], zb[cur, 6], zb[cur, 7]
                    for d in range(N):
                        zb[nxt, dpos[d]] = ((((Pab[d, 0] * z0 + Pab[d, 1] * z1) + (Pab[d, 2] * z2 + Pab[d, 3] * z3))
                                             + ((Pab[d, 4] * z4 + Pab[d, 5] * z5) + (Pab[d, 6] * z6
                                                                                    + Pab[d, 7] * z7)))
                                            + dw * gb[d])
                    if metrics:
                        y0 = _row4(Q, sa, N, z0, z1, z2, z3)
                        y1 = _row4(Q, sa, N + 1, z0, z1, z2, z3)
                        v0 = _row4(Q, sa, N + 3, z0, z1, z2, z3)
                        v1 = _row4(Q, sa, N + 4, z0, z1, z2, z3)
                        gs = _slope_bound(G, cheap, sa, v0, v1)
                        st, wend, need = _interval_metrics(y0, y1, fa * (cr0 * v0 + cr1 * v1), gs, a, timg, st, inv,
                                                           ainv, band)
                        if need:
                            st, tr = _expanded(st, zb, cur, ns, fa, a, inv, ref, band, ms, Zs, cs, zs, q, qn, zsum,
                                               Y, Wn, dW, xs, sr, sd)
                            trunc = max(trunc, tr)
                        # the second interval, from the first's start: its output at the start jumps with the
                        # plant's input (by dy (w_b - w_a))
                        y0 = y1 + cw * dw
                        y1 = ((Rb[0, 0] * z0 + Rb[0, 1] * z1) + (Rb[0, 2] * z2 + Rb[0, 3] * z3)) + Rbw[0] * wb
                        v0 = ((Rb[1, 0] * z0 + Rb[1, 1] * z1) + (Rb[1, 2] * z2 + Rb[1, 3] * z3)) + Rbw[1] * wb
                        v1 = ((Rb[2, 0] * z0 + Rb[2, 1] * z1) + (Rb[2, 2] * z2 + Rb[2, 3] * z3)) + Rbw[2] * wb
                        gs = _slope_bound(G, cheap, sb, v0, v1)
                        st, wend, need = _interval_metrics(y0, y1, fb * (cr0 * v0 + cr1 * v1), gs, timg, ts, st,
                                                           inv, ainv, band)
                        if need:  # the part the output sees at the image, the plant's input changed
                            for i in range(_SS):
                                zi[0, i] = (Es[i, 0] * z0 + Es[i, 1] * z1) + (Es[i, 2] * z2 + Es[i, 3] * z3)
                            if pw < _SS:
                                zi[0, pw] = wb
                            st, tr = _expanded(st, zi, 0, ns, fb, timg, inv, ref, band, ms, Zs, cs, zs, q, qn,
                                               zsum, Y, Wn, dW, xs, sr, sd)
                            trunc = max(trunc, tr)
                    # the image: the held command reaches the plant
                    wu = ring[kget]
                    kget = kget + 1 if kget + 1 < nring else 0
                    ki += 1
                    timg = off + ki * per + ti
                    # the next sample, which reads the left limits
                    cur = nxt
                    a = ts
                    n += 2
                    zb[cur, pw] = wu + dcur
                    zb[cur, pr] = step + slope * a
                    v = (((kv[0] * zb[cur, 0] + kv[1] * zb[cur, 1]) + (kv[2] * zb[cur, 2] + kv[3] * zb[cur, 3]))
                         + ((kv[4] * zb[cur, 4] + kv[5] * zb[cur, 5]) + (kv[6] * zb[cur, 6] + kv[7] * zb[cur, 7])))
                    ring[kput] = min(max(v, umin), umax)
                    kput = kput + 1 if kput + 1 < nring else 0
                    ks += 1
                    ts = off + ks * per
                    if not (a + eps < timg < ts - eps and ts < tend - eps
                            and (not has_dist or dist_on or tdist > ts + eps)
                            and abs(timg - a - pair_ta) <= ttol and abs(ts - timg - pair_tb) <= ttol):
                        break
                continue
        end = min(tend, ts, timg)
        if has_dist and not dist_on:
            end = min(end, tdist)
        tau = end - a
        # the exponential of this length (lengths alternate: try the one before last first)
        if abs(taus[slot_prev] - tau) <= ttol:
            s_new = slot_prev
        else:
            s_new = -1
            for s in range(nslot):
                if abs(taus[s] - tau) <= ttol:
                    s_new = s
                    break
            if s_new < 0:
                if nslot < _NSLOT:
                    s_new = nslot
                    nslot += 1
                else:  # the least recently used length makes room
                    s_new = 0
                    for s in range(1, _NSLOT):
                        if used[s] < used[s_new]:
                            s_new = s
                taus[s_new] = tau
                trunc = max(trunc, _fill_slot(Z, na, N, tau, dpos, ns, cs, rows, nrow, metrics, s_new, Q, G, A, E, T,
                                              W, gw))
                cheap[s_new] = not isinf(G[s_new, 0])
        slot_prev = slot
        slot = s_new
        used[slot] = n
        # one interval: the states at its end into zb[nxt]; with metrics, acc = the output at both ends, Y'(0)
        # and Z_S z (these read z[:ns] only)
        nxt = 1 - cur
        if small:  # fixed lengths (zeros around), summed as trees: short chains from one interval to the next
            z0, z1, z2, z3 = zb[cur, 0], zb[cur, 1], zb[cur, 2], zb[cur, 3]
            z4, z5, z6, z7 = zb[cur, 4], zb[cur, 5], zb[cur, 6], zb[cur, 7]
            for d in range(N):
                zb[nxt, dpos[d]] = (((Q[slot, d, 0] * z0 + Q[slot, d, 1] * z1) + (Q[slot, d, 2] * z2
                                     + Q[slot, d, 3] * z3)) + ((Q[slot, d, 4] * z4 + Q[slot, d, 5] * z5)
                                                               + (Q[slot, d, 6] * z6 + Q[slot, d, 7] * z7)))
            if metrics:
                y0 = _row4(Q, slot, N, z0, z1, z2, z3)
                y1 = _row4(Q, slot, N + 1, z0, z1, z2, z3)
                v0 = _row4(Q, slot, N + 3, z0, z1, z2, z3)
                v1 = _row4(Q, slot, N + 4, z0, z1, z2, z3)
                d1 = tau * (cr0 * v0 + cr1 * v1)
                gs = _slope_bound(G, cheap, slot, v0, v1)
        else:
            for d in range(N):
                sm = 0.0
                for k in range(na):
                    sm += Q[slot, d, k] * zb[cur, k]
                zb[nxt, dpos[d]] = sm
            if metrics:
                for r in range(N, nq):
                    sm = 0.0
                    for k in range(ns):
                        sm += Q[slot, r, k] * zb[cur, k]
                    acc[r] = sm
                y0, y1, d1 = acc[N], acc[N + 1], acc[N + 2]
                gs = 0.0
                for r in range(nrow):
                    sm = acc[N + 3 + r]
                    if sm != 0.0:
                        gs += abs(sm) * G[slot, r]
        if metrics:
            st, wend, need = _interval_metrics(y0, y1, d1, gs, a, end, st, inv, ainv, band)
            if need:
                st, tr = _expanded(st, zb, cur, ns, tau, a, inv, ref, band, ms, Zs, cs, zs, q, qn, zsum, Y, Wn, dW,
                                   xs, sr, sd)
                trunc = max(trunc, tr)
        cur = nxt
        a = end
        n += 1

    wmax, tpeak, t10, t90, tlast = st
    _metrics_row(out, metrics, wmax, wend, tpeak, t10, t90, tlast, norm, band)
    out[8] = trunc
    out[9] = n
    out[10] = STATUS_OK
    out[11] = ks
    out[12] = 0.0
    out[13] = a
    return n


def run_batch(pars, nchunks, nsets=1):
    """The kernel's metrics rows (:data:`._layout.OUT`) of many eligible sampled loops, one parameter row each
    (a step or ramp reference, as :func:`._kernel.run_batch` reads it): ``nchunks`` chunks of rows, taken in turn
    by ``nsets`` work sets run in parallel (one per thread)."""
    m = pars.shape[0]
    out = np.empty((m, NOUT))
    nsets = max(1, min(nsets, nchunks))
    nring = 4
    for i in range(m):  # the ring of held commands: the longest any row needs
        nring = max(nring, int(pars[i, _TI] / pars[i, _PERIOD]) + 4)  # (as run_one's own)
    Z = np.zeros((nsets, _NA, _NA))
    Q = np.zeros((nsets, _NSLOT, _NQ, _NA))
    G = np.zeros((nsets, _NSLOT, _NA))
    taus = np.empty((nsets, _NSLOT))
    A = np.empty((nsets, _NA, _NA))
    E = np.empty((nsets, _NA, _NA))
    T = np.empty((nsets, _NA, _NA))
    W = np.empty((nsets, _NA, _NA))
    zb = np.zeros((nsets, 2, _NA))
    acc = np.zeros((nsets, _NQ))
    zs = np.zeros((nsets, _NA))
    Zs = np.zeros((nsets, _NA, _NA))
    q = np.zeros((nsets, _NA))
    qn = np.zeros((nsets, _NA))
    zsum = np.zeros((nsets, _NA))
    Y = np.zeros((nsets, NC))
    Wn = np.zeros((nsets, NC))
    dW = np.zeros((nsets, NC))
    xs = np.zeros((nsets, _MAXX))
    sr = np.zeros((nsets, _STACK))
    sd = np.zeros((nsets, _STACK), dtype=np.int64)
    ms = np.zeros((nsets, 5))
    EA = np.zeros((nsets, _SA, _SA))
    Pab = np.zeros((nsets, MAXN, _SA))
    gb = np.zeros((nsets, MAXN))
    Es = np.zeros((nsets, _SS, _SS))
    Rb = np.zeros((nsets, 3, _SS))
    Rbw = np.zeros((nsets, 3))
    zi = np.zeros((nsets, 1, _NA))
    Z0 = np.zeros((nsets, _NA, _NA))
    vec = np.zeros((nsets, 5, _NA))  # c0, k0, c, kv, cs
    ring = np.empty((nsets, nring))
    flags = np.zeros((nsets, 2, _NA), dtype=np.uint8)  # seen, cheap
    idx = np.zeros((nsets, 4, _NA), dtype=np.int64)  # perm, pos, dpos, rows
    used = np.zeros((nsets, _NSLOT), dtype=np.int64)
    gw = np.zeros((nsets, 3, _NA))
    if nsets == 1:  # on the calling thread, with no parallel region (whose idle threads would spin beside it)
        _set_chunks(pars, nchunks, 1, 0, out, Z[0], Q[0], G[0], taus[0], A[0], E[0], T[0], W[0], zb[0], acc[0], zs[0],
                    Zs[0], q[0], qn[0], zsum[0], Y[0], Wn[0], dW[0], xs[0], sr[0], sd[0], ms[0], EA[0], Pab[0], gb[0],
                    Es[0], Rb[0], Rbw[0], zi[0], Z0[0], vec[0], ring[0], flags[0], idx[0], used[0], gw[0])
    else:
        _batch_sets(pars, nchunks, nsets, out, Z, Q, G, taus, A, E, T, W, zb, acc, zs, Zs, q, qn, zsum, Y, Wn, dW, xs,
                    sr, sd, ms, EA, Pab, gb, Es, Rb, Rbw, zi, Z0, vec, ring, flags, idx, used, gw)
    return out


def _batch_sets(pars, nchunks, nsets, out, Z, Q, G, taus, A, E, T, W, zb, acc, zs, Zs, q, qn, zsum, Y, Wn, dW, xs, sr,
                sd, ms, EA, Pab, gb, Es, Rb, Rbw, zi, Z0, vec, ring, flags, idx, used, gw):
    """:func:`run_batch`'s parallel loop: work set ``s`` runs its chunks (:func:`_set_chunks`) on its own arrays."""
    for s in prange(nsets):
        _set_chunks(pars, nchunks, nsets, s, out, Z[s], Q[s], G[s], taus[s], A[s], E[s], T[s], W[s], zb[s], acc[s],
                    zs[s], Zs[s], q[s], qn[s], zsum[s], Y[s], Wn[s], dW[s], xs[s], sr[s], sd[s], ms[s], EA[s], Pab[s],
                    gb[s], Es[s], Rb[s], Rbw[s], zi[s], Z0[s], vec[s], ring[s], flags[s], idx[s], used[s], gw[s])


def _set_chunks(pars, nchunks, nsets, s, out, Z, Q, G, taus, A, E, T, W, zb, acc, zs, Zs, q, qn, zsum, Y, Wn, dW, xs, sr,
                sd, ms, EA, Pab, gb, Es, Rb, Rbw, zi, Z0, vec, ring, flags, idx, used, gw):
    """Work set ``s``'s rows: the chunks ``s, s + nsets, ...`` (:func:`._kernel._chunk`), on that set's arrays."""
    m = pars.shape[0]
    for k in range(nchunks):
        lo, hi = _chunk(m, nchunks, nsets, s, k)
        for i in range(lo, hi):
            run_one(pars[i], out[i], Z, Q, G, taus, A, E, T, W, zb, acc, zs, Zs, q, qn, zsum, Y, Wn, dW, xs, sr, sd, ms,
                    EA, Pab, gb, Es, Rb, Rbw, zi, Z0, vec, ring, flags, idx, used, gw)
