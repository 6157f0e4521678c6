"""The Taylor recursion of one piece of the simulator's response: every signal's coefficients, the regime fixed.

On a piece of length ``H`` the loop's states follow ``X[j+1] = H (M X[j] + inputs[j]) / (j + 1)``, where the
inputs (the delayed command, the reference, the delayed measurement, anti-windup, a predictor's command) are
polynomials known before the piece or, without any delay in the loop, algebraic in the states.
:func:`recursion_known` is the common case, the plant's input known before the piece and the command not
acting back on the states, with the measurement folded into the matrix once per run; :func:`recursion` is
the general one.  One source, three modes, as the kernel (see :mod:`delaykit._native`): compiled by Cython (C
types in ``_taylor.pxd``; the kernel :mod:`._kernel` is built with this file in its own C module, ``FUSED`` in
``setup.py``), by numba (``NUMBA_OPTIONS``: inlined but
:func:`recursion`, compiled without reference counting as the kernel's piece loop), or run as plain Python.  This
module is private.

Examples
--------
>>> import numpy as np
>>> from delaykit import _native
>>> from delaykit.simulate._layout import NC
>>> t = _native.load("delaykit.simulate", "_taylor", "python")
>>> X, Y, Yd, V, E = np.zeros((1, NC + 1)), np.zeros(NC), np.zeros(NC), np.zeros(NC), np.zeros(NC)
>>> X[0, 0] = 1.0  # x' = -x over a piece of length 1: the coefficients of exp(-x)
>>> A, G, VE = np.array([[-1.0]]), np.zeros((4, 1)), np.zeros((10, 1))
>>> VE[5, 0] = 1.0  # y = x
>>> nt = t.recursion_known(A, G, VE, 1, 1.0, False, -1, 0.0, np.zeros(NC), 1, np.zeros(NC), 1, np.zeros(NC),
...                        np.zeros(NC), False, False, np.zeros(5), X, Y, Yd, V, E, False, False, 0.0, np.zeros(NC), NC)
>>> nt, [round(float(c), 6) for c in Y[:4]]
(25, [1.0, -1.0, 0.5, -0.166667])
"""

from __future__ import annotations

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

from ._layout import DEG, HEAD, NC

if cython.compiled:  # the polynomial helpers, called as C
    from cython.cimports.delaykit.simulate._poly import degree as _degree
else:  # the same module run as this one is (numba's copy, or Python)
    from .._native import sibling

    _degree = sibling(__name__, "_poly").degree

__all__ = ["LIN", "HIGH", "LOW", "recursion", "recursion_known", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

LIN, HIGH, LOW = 0, 1, 2  # the command's regime on a piece: linear, saturated high or low
_LIN, _HIGH, _LOW, _DEG, _NC = LIN, HIGH, LOW, DEG, NC  # (C values where compiled; the public names stay Python's)
# numba's options where it compiles this file (see delaykit._native): all inlined but the general recursion
NUMBA_OPTIONS = {"_vanished": {"inline": "always"}, "_clear_tail": {"inline": "always"},
                 "_hold_at_limit": {"inline": "always"}, "_state_parts": {"inline": "always"},
                 "_signals": {"inline": "always"}, "_known_one": {"inline": "always"},
                 "recursion_known": {"inline": "always"}, "recursion": {"_nrt": False}}
_UMIN, _UMAX, _DY, _DYD, _DVR, _DVY, _DVV, _INTEG, _AW = (HEAD[k] for k in ("umin", "umax", "dy", "dyd", "dvr", "dvy",
                                                                          "dvv", "integ", "aw"))


def _vanished(X, N, j):
    """Whether every state's coefficient ``j`` is zero (past the forcing's degree, all later ones are then too)."""
    for i in range(N):
        if X[i, j] != 0.0:
            return False
    return True


def _clear_tail(X, Y, Yd, V, E, N, nt, nz):
    """Zero every signal's coefficients from ``nt`` up to ``nz``: the buffers are reused from piece to piece, and
    the caller says from where on they are zero already (the last call's ``nt``; ``_NC`` for all).  (The states'
    last column, ``X[:, _NC]``, is never written: it stays as the caller cleared it.)"""
    for j in range(nt, nz):
        Y[j] = 0.0
        Yd[j] = 0.0
        V[j] = 0.0
        E[j] = 0.0
        for i in range(N):
            X[i, j] = 0.0


def _hold_at_limit(X, V, VE, integ, j, lim, Fz):
    """Sliding on the limit (Filippov): replace the integrator's coefficient ``j`` by the one that keeps the
    command at ``lim`` (``V[0] = lim``, ``V[j] = 0`` after), and keep the free integrator's in ``Fz[j]``.

    The integrator feeds the command only (``v = ... + Ki xi``, nothing else reads ``xi``), so its
    coefficient ``j`` follows from the others' at ``j``; the next order's then read the corrected one."""
    target = lim if j == 0 else 0.0
    Fz[j] = X[integ, j]
    X[integ, j] -= (V[j] - target) / VE[7, integ]
    V[j] = target


def _state_parts(X, VE, N, j, need_yd):
    """The parts of the output, its derivative (only where ``need_yd``, else 0) and the command that the
    states' coefficients ``j`` carry: ``sum_i VE[5, i] X[i, j]``, with rows 6 and 7."""
    cy = 0.0
    cv = 0.0
    for i in range(N):
        xi = X[i, j]
        cy += VE[5, i] * xi
        cv += VE[7, i] * xi
    cyd = 0.0
    if need_yd:
        for i in range(N):
            cyd += VE[6, i] * X[i, j]
    return cy, cyd, cv


def _signals(j, cy, cyd, cv, wj, rj, yd_on, law_on, vj, use_meas, Ym, Vm, dy, dyd, dvr, dvy, dvv, Y, Yd, V, E):
    """Store the coefficients ``j`` of the output, its derivative, the command and the error, from the states'
    parts (:func:`_state_parts`), the plant input's ``wj`` and the reference's ``rj``; returns the measurement's
    (``ymj, vmj``: the delayed one's where ``use_meas``, else the output's own) and the command's.

    ``yd_on``: compute y' (else 0); ``law_on``: the command follows from the control law on the measurement
    (else ``vj``, already known, is stored)."""
    yj = cy + dy * wj
    ydj = cyd + dyd * wj if yd_on else 0.0
    if use_meas:
        ymj = Ym[j]
        vmj = Vm[j]
    else:
        ymj = yj
        vmj = ydj
    if law_on:
        vj = cv + dvr * rj + dvy * ymj + dvv * vmj
    Y[j] = yj
    Yd[j] = ydj
    V[j] = vj
    E[j] = rj - ymj
    return ymj, vmj, vj


def _known_one(A, G, VE, H, frozen, integ, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, X, Y, Yd, V, E,
               zero_a, nf, nz):
    """:func:`recursion_known` for a single state, not sliding: the same arithmetic in the same order, with
    the state's coefficient carried from one order to the next rather than read back."""
    dy, dyd, dvr, dvy, dvv = d5[0], d5[1], d5[2], d5[3], d5[4]
    c5 = VE[5, 0]
    c6 = VE[6, 0]
    c7 = VE[7, 0]
    g0 = G[0, 0]
    g1 = G[1, 0]
    g2 = G[2, 0]
    g3 = G[3, 0]
    a00 = A[0, 0]
    hold = frozen and integ == 0
    x = X[0, 0]
    nt = _NC
    for j in range(_NC):
        if j >= nf and j > 0 and x == 0.0:
            nt = j
            break
        wj = (Wd[j] if j < nW else 0.0) + (w0 if j == 0 else 0.0)
        rj = R[j] if j < nR else 0.0
        # the sums of _state_parts, from 0.0 as there
        cy = 0.0 + c5 * x
        cv = 0.0 + c7 * x
        cyd = 0.0 + c6 * x if need_yd else 0.0
        ymj, vmj, _ = _signals(j, cy, cyd, cv, wj, rj, need_yd, True, 0.0, use_meas, Ym, Vm, dy, dyd, dvr, dvy, dvv,
                               Y, Yd, V, E)
        if j == _DEG:
            break
        f = H / (j + 1)
        if j < nf:
            acc = g0 * wj + g1 * rj
            if use_meas:  # (the same sum, left to right; else G's rows 2 and 3 are zero, see recursion_known)
                acc += g2 * ymj
                acc += g3 * vmj
            if not zero_a:
                acc += a00 * x
            x = f * acc
        elif zero_a:
            x = 0.0
        else:
            acc = 0.0
            acc += a00 * x
            x = f * acc
        if hold:
            x = 0.0
        X[0, j + 1] = x
    _clear_tail(X, Y, Yd, V, E, 1, nt, nz)
    return nt


def recursion_known(A, G, VE, N, H, frozen, integ, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, X, Y, Yd, V,
                    E, zero_a, slide, lim, Fz, nz):
    """:func:`recursion` where the plant's input is known before the piece (delayed or held) and the command
    does not act back on the states (no back-calculation while saturated, no predictor): ``X' = A X + G (w, r,
    ym, vm)``, with the measurement's coupling folded into ``A`` and ``G`` once per run (by the kernel's
    ``run_one``).

    ``w0`` is added to the plant input's constant term (a held command, a load disturbance); ``d5`` holds the
    direct terms ``dy, dyd, dvr, dvy, dvv``; ``zero_a`` says that ``A`` is zero (integrators driven by the input
    alone, as the paper's loop: each coefficient then follows from the input's, with no chain through the
    states).  ``slide``: the command slides on the limit ``lim`` (clamping anti-windup, see :func:`recursion`).
    ``G``'s rows 2 and 3 (the measurement's) are read only with ``use_meas`` (a delayed measurement, known before
    the piece); without it the measurement is the output itself, folded into ``A`` and ``G[0]``, and those rows
    are zero: adding their terms would only chain each order's coefficients to the last order's through the
    output.  ``nz`` and the number of coefficients returned: as :func:`recursion`.
    """
    dy, dyd, dvr, dvy, dvv = d5[0], d5[1], d5[2], d5[3], d5[4]
    nf = max(nR, nW, 1)
    if use_meas:
        nf = max(nf, _degree(Ym, _NC), _degree(Vm, _NC))
    if N == 1 and not slide:
        return _known_one(A, G, VE, H, frozen, integ, w0, Wd, nW, R, nR, Ym, Vm, use_meas, need_yd, d5, X, Y, Yd, V,
                          E, zero_a, nf, nz)
    nt = _NC
    for j in range(_NC):
        if j >= nf and j > 0 and _vanished(X, N, j):
            nt = j
            break
        wj = (Wd[j] if j < nW else 0.0) + (w0 if j == 0 else 0.0)
        rj = R[j] if j < nR else 0.0
        cy, cyd, cv = _state_parts(X, VE, N, j, need_yd)
        ymj, vmj, _ = _signals(j, cy, cyd, cv, wj, rj, need_yd, True, 0.0, use_meas, Ym, Vm, dy, dyd, dvr, dvy, dvv,
                               Y, Yd, V, E)
        if slide:
            _hold_at_limit(X, V, VE, integ, j, lim, Fz)
        if j == _DEG:
            break
        f = H / (j + 1)
        if j < nf:
            for i in range(N):
                acc = G[0, i] * wj + G[1, i] * rj
                if use_meas:
                    acc += G[2, i] * ymj
                    acc += G[3, i] * vmj
                if not zero_a:
                    for k in range(N):
                        acc += A[i, k] * X[k, j]
                X[i, j + 1] = f * acc
        elif zero_a:
            for i in range(N):
                X[i, j + 1] = 0.0
        else:
            for i in range(N):
                acc = 0.0
                for k in range(N):
                    acc += A[i, k] * X[k, j]
                X[i, j + 1] = f * acc
        if frozen and integ >= 0:
            X[integ, j + 1] = 0.0
    _clear_tail(X, Y, Yd, V, E, N, nt, nz)
    return nt


def recursion(par, Mloc, VE, N, H, regime, frozen, algebraic, ti_pos, sampled, uhold, dist, X, R, nR,
              Wd, nW, Ym, Vm, use_meas, Y, Yd, V, E, need_yd, Um, nUm, has_u, slide, Fz, nz):
    """Taylor coefficients of every signal on one piece of length ``H`` with the regime fixed.

    ``X[:, 0]`` holds the states at the start; fills ``X[:, 1:]``, the output ``Y``, its derivative ``Yd``,
    the controller output ``V`` and the error ``E`` (``Yd`` only where ``need_yd``: something reads y').
    With ``has_u`` (a predictor's model inside the controller), the states also read the command ``u``
    itself and ``Um`` (``nUm`` coefficients), the command one model delay ago.

    With ``slide`` (clamping anti-windup, the regime saturated), the command slides on its limit: the
    Filippov solution where the free integrator would drive the command past the limit and the frozen one
    back below it.  The integrator then runs at the rate that holds the command at the limit, between 0 and
    the free rate; ``Fz`` receives the free integrator's coefficients (the kernel ends the slide where the
    rate reaches either end).

    ``nz``: the signals' coefficients (``X[:, 1:]``, ``Y``, ``Yd``, ``V``, ``E``) are zero on entry from ``nz`` on (the
    last call's number of coefficients, where the caller reuses the buffers; ``NC`` where it knows nothing): only
    those between the returned number and ``nz`` are cleared.
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
        nf = max(nf, _degree(Ym, _NC), _degree(Vm, _NC))
    nt = _NC
    for j in range(_NC):
        if j >= nf and j > 0 and _vanished(X, N, j):
            nt = j
            break
        rj = R[j] if j < nR else 0.0
        dj = dist if j == 0 else 0.0
        # the parts of y, y' and v that do not depend on this piece's plant input
        cy, cyd, cv = _state_parts(X, VE, N, j, need_yd)
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
        # y' always (0 + dyd wj where nothing reads it); the law gives v where the input is delayed or held
        ymj, vmj, vj = _signals(j, cy, cyd, cv, wj, rj, True, sampled or ti_pos, vj, use_meas, Ym, Vm, dy, dyd, dvr,
                                dvy, dvv, Y, Yd, V, E)
        if slide:
            _hold_at_limit(X, V, VE, integ, j, lim, Fz)
            vj = V[j]
        if j == _DEG:
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
    _clear_tail(X, Y, Yd, V, E, N, nt, nz)
    return nt
