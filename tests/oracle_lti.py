"""An independent reference solver for delay systems in LFT form (:class:`delaykit.DelayLTI`), used only by the
tests and the benchmarks' accuracy checks.

It reads a system's matrices and nothing else of delaykit (no kernel, no layout, no algebra): the equations

    x'(t)  = A  x + B1  u + B2  w
    y(t)   = C1 x + D11 u + D12 w
    z(t)   = C2 x + D21 u + D22 w
    w_j(t) = sat_j(z_j(t - tau_j))          (sat_j the identity when channel j has no limits)

are integrated with SciPy's DOP853 (rtol 1e-12, atol 1e-14 by default) by the method of steps.  All signals are
at rest before the start ``t0``: ``u``, ``z`` and ``w`` are 0 for ``t < t0`` and ``x(t0) = X0``.

Channels.  A channel with ``tau_j = 0`` is algebraic: at each time the zero-delay channels are solved from
``w_Z = sat(C2_Z x + D21_Z u + D22_ZP w_P + D22_ZZ w_Z)`` given the state, the input and the delayed channels
``w_P``.  Its saturations are handled as a mode per channel (linear, at the lower limit, at the upper limit): in a
mode the solution is one linear solve; a mode change is an event of the integrator (the unsaturated value reaching
a limit, or the value it would have, with the channel held at the limit, coming back inside), located by SciPy's
root finder on the dense output, and the integration restarts there in the new mode.  Delayed channels are read
from the dense outputs of the segments already solved: every segment is at most the smallest positive delay long,
so ``t - tau_j`` always lies in the past.  ``z_j`` in the past is recomputed from that segment's state, the input,
and (only when ``z_j`` depends directly on delayed channels: a neutral system) the delayed channels at that
earlier time, which each solved segment of a neutral system keeps as a Chebyshev interpolant of degree 23 (the
segment is shorter than every delay and has no breakpoint inside, so the interpolant is exact to rounding level;
the tests check it against a closed form and the Loop simulator).

Breakpoints.  The integrator restarts at every breakpoint: the start (a jump of the input or of ``z``), the input's
sample times (kinks), the saturation switches, and their images ``s + tau_j`` through every delay channel.  Each
breakpoint carries the order of the lowest derivative of the signals that jumps there; an image through channel
``j`` keeps that order when ``z_j`` has a direct path (no state in between) from what jumped (the input, the
delayed channel that brought the jump, a zero-delay saturation), and gains one otherwise; images past
``max_order`` (default 6) are dropped (DOP853's step control absorbs the rest).  A switch of a saturated delayed channel (``z_j`` crossing a limit, found by a non-terminal event) has its
breakpoint at the switch time plus ``tau_j``.

Delayed look-ups at a segment's ends: on the segment ``[a, b]`` a value at ``s = t - tau`` comes from the piece
of history that covers the shifted interior ``(a - tau, b - tau)``: the piece is selected at ``s`` nudged towards
the shifted midpoint, then evaluated at ``s``.  Outputs are right-continuous (the value just after a jump), the
last time excepted.

The impulse response is the regular part: the Dirac at 0 moves the state by ``B1`` (plus ``B2`` times the
Dirac parts of the zero-delay channels), and the Dirac parts of ``z`` arrive through each delay channel as further
jumps of the state; the outputs' Dirac parts (``D11``, ``D12`` paths) are kept apart
(``impulse(T, diracs=True)``), as python-control's ``impulse_response`` drops them.

A saturation whose free value grazes its limit, or rests on it (an equilibrium exactly at the limit), would
switch back and forth at one time: it is then kept linear with its limits widened by 1e-10 (relative) until it
next switches.

Not supported (NotImplementedError): saturations with an impulse; Filippov sliding on a saturation (more than 100
switches in a row without progress).
"""

from __future__ import annotations

import bisect
import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["LTIOracle", "Trajectory"]

_GRAZE = 1e-10  # a saturation that grazes its limit (or rests on it) has it widened by this much (relative)
_CHEB = 24  # points of the Chebyshev interpolant of a neutral system's delayed channels on each segment
_REL = 1e-11  # breakpoints closer than this (relative to max(1, |t|)) are one; the nudge of delayed look-ups


def _eps(t: float) -> float:
    return _REL * max(1.0, abs(t))


def _chebval(x: float, coef: np.ndarray) -> np.ndarray:
    """The Chebyshev series ``sum_k coef[k] T_k(x)`` at one scalar ``x`` (numpy's ``chebval`` to rounding): the
    ``T_k(x)`` by their three-term recurrence in scalars, then one dot product."""
    T = [1.0, x]
    for _ in range(len(coef) - 2):
        T.append(2.0 * x * T[-1] - T[-2])
    return np.dot(T[:len(coef)], coef)


class _Dense:
    """DOP853's dense output of one segment (its 7th-degree interpolants, step by step), evaluated with little
    overhead per scalar time: ``y = y_old + F0 x + F1 x (1-x) + F2 x^2 (1-x) + ...`` with ``x = (t - t_old)/h``."""

    def __init__(self, sol: Any) -> None:
        steps = sol.interpolants
        self.t_old = [float(d.t_old) for d in steps]  # (Python floats: bisect on them is the cheapest look-up)
        self.h = [float(d.h) for d in steps]
        self.F = np.array([np.asarray(d.F) for d in steps])        # (steps, 7, n)
        self.y_old = np.array([np.asarray(d.y_old) for d in steps])  # (steps, n)

    def __call__(self, t: float) -> np.ndarray:
        i = bisect.bisect_right(self.t_old, t) - 1
        i = min(max(i, 0), len(self.h) - 1)
        x = (t - self.t_old[i]) / self.h[i]
        # the same polynomial summed as  sum_k F[k] prod_{j <= k} f_j  with f_j = x (j even), 1 - x (j odd): the
        # products in scalars, then one dot product (equal to the nested form to rounding)
        w, p = [], 1.0
        for k in range(self.F.shape[1]):
            p *= x if k % 2 == 0 else 1.0 - x
            w.append(p)
        return np.dot(w, self.F[i]) + self.y_old[i]


@dataclass
class _Segment:
    a: float
    b: float
    dense: Any            # state as a function of time on [a, b] (None for a segment without states)
    x0: np.ndarray        # the state at a (used when there are no states to integrate)
    mode: tuple[int, ...]  # the zero-delay saturation channels' modes: 0 linear, -1 lower, +1 upper
    wp: Any = None        # neutral systems: the delayed channels' values on [a, b] as a Chebyshev interpolant


@dataclass
class _Break:
    t: float
    u: float = math.inf     # order of the input's lowest jumping derivative (0: the input jumps)
    w: dict = field(default_factory=dict)  # same for the delayed channels' values arriving here, per channel
    x: float = math.inf     # 0: the state jumps (an impulse)
    sat: float = math.inf   # 1: a zero-delay saturation switches (its value has a kink)
    dirac: np.ndarray | None = None  # Dirac weights arriving in the delayed channels (impulse responses)


@dataclass
class Trajectory:
    """One solved run: evaluate the state, the outputs and the channels at any time in ``[t0, t_end]``."""

    oracle: "LTIOracle"
    segments: list[_Segment]
    u: Callable[[float, float], np.ndarray]
    t0: float
    t_end: float
    switches: list[tuple[float, int]] = field(default_factory=list)  # (time, channel) of saturation switches
    starts: list[float] = field(default_factory=list)
    diracs: list[tuple[float, np.ndarray]] = field(default_factory=list)  # (time, Dirac weights of the outputs)

    def add(self, seg: _Segment) -> None:
        self.segments.append(seg)
        self.starts.append(seg.a)

    def _seg(self, s: float, sel: float) -> _Segment:
        i = bisect.bisect_right(self.starts, sel) - 1
        return self.segments[min(max(i, 0), len(self.segments) - 1)]

    def state(self, t: float, sel: float | None = None) -> np.ndarray:
        g = self._seg(t, t if sel is None else sel)
        return g.dense(t) if g.dense is not None else g.x0

    def signals(self, t: float, side: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(x, w, z, y)`` at ``t`` (right limit for ``side = 1``, left for ``-1``)."""
        sel = t + side * _eps(t)
        g = self._seg(t, sel)
        x = g.dense(t) if g.dense is not None else g.x0
        u = self.u(t, sel)
        wp = self.oracle._delayed(self, t, sel)
        w, z = self.oracle._algebra(x, u, wp, g.mode)
        y = self.oracle.C1 @ x + self.oracle.D11 @ u + self.oracle.D12 @ w
        return x, w, z, y

    def outputs(self, T: Any) -> np.ndarray:
        """``y`` at the times ``T`` (right-continuous; the last time of the run is a left limit), ``(ny, nt)``."""
        T = np.asarray(T, float)
        out = np.empty((self.oracle.ny, T.size))
        for k, t in enumerate(T):
            side = -1 if t >= self.t_end - _eps(self.t_end) else 1
            out[:, k] = self.signals(float(t), side)[3]
        return out


class LTIOracle:
    """The reference solver for one system (see the module docstring).

    Parameters
    ----------
    sys : DelayLTI (or anything with its attributes A, B1, ..., D22, delays, limits)
    rtol, atol : float
        DOP853's tolerances.
    max_order : int
        Breakpoint images whose jumping derivative is of higher order are not restarted at.
    """

    def __init__(self, sys: Any, *, rtol: float = 1e-12, atol: float = 1e-14, max_order: int = 6) -> None:
        f = lambda name: np.array(getattr(sys, name), dtype=float)  # noqa: E731
        self.A, self.B1, self.B2 = f("A"), f("B1"), f("B2")
        self.C1, self.C2 = f("C1"), f("C2")
        self.D11, self.D12, self.D21, self.D22 = f("D11"), f("D12"), f("D21"), f("D22")
        self.tau = np.array(sys.delays, dtype=float)
        m = self.tau.size
        lim = getattr(sys, "limits", None) or ((-math.inf, math.inf),) * m
        self.lo = np.array([p[0] for p in lim], float)
        self.hi = np.array([p[1] for p in lim], float)
        self.n, self.nu, self.ny, self.m = self.A.shape[0], self.B1.shape[1], self.C1.shape[0], m
        self.rtol, self.atol, self.max_order = rtol, atol, max_order
        self.P = [j for j in range(m) if self.tau[j] > 0]            # delayed channels
        self.Z = [j for j in range(m) if self.tau[j] == 0]           # algebraic channels
        self.limited = [bool(np.isfinite(self.lo[j]) or np.isfinite(self.hi[j])) for j in range(m)]
        self.satZ = [j for j in self.Z if self.limited[j]]           # zero-delay saturations (modes)
        self.tau_min = float(min(self.tau[self.P])) if self.P else math.inf
        self._maps: dict[tuple[int, ...], tuple[np.ndarray, ...]] = {}
        # structural direct dependence of each z on the inputs, the delayed channels and the zero-delay
        # saturations, through chains of zero-delay channels (a graph reachability, not a numerical test)
        direct = (self.D22 != 0)
        reach = direct.copy()  # reach[i, k]: z_i depends on w_k through zero-delay channels
        for _ in range(m):
            via = reach[:, self.Z] @ direct[self.Z, :] if self.Z else np.zeros((m, m), bool)
            new = reach | via
            if (new == reach).all():
                break
            reach = new
        self.reach = reach
        uz = (self.D21 != 0)
        self.z_on_u = uz.any(axis=1) | (reach[:, self.Z] @ uz[self.Z, :]).any(axis=1) if self.Z else uz.any(axis=1)
        self.z_on_wp = reach[:, self.P] if self.P else np.zeros((m, 0), bool)  # (m, len(P))
        self.z_on_sat = reach[:, self.satZ].any(axis=1) if self.satZ else np.zeros(m, bool)
        self.neutral = bool(self.z_on_wp[self.P].any()) if self.P else False

    # -- the algebra at one time ---------------------------------------------------------------------------
    def _map(self, mode: tuple[int, ...]) -> tuple[np.ndarray, ...]:
        """``w = Wx x + Wu u + Wp wP + wc`` for a mode of the zero-delay saturations (cached)."""
        if mode in self._maps:
            return self._maps[mode]
        m, Z, P = self.m, self.Z, self.P
        held = {j: (self.lo[j] if s < 0 else self.hi[j]) for j, s in zip(self.satZ, mode) if s != 0}
        L = [j for j in Z if j not in held]
        Wx, Wu = np.zeros((m, self.n)), np.zeros((m, self.nu))
        Wp, wc = np.zeros((m, len(P))), np.zeros(m)
        for k, j in enumerate(P):
            Wp[j, k] = 1.0
        for j, v in held.items():
            wc[j] = v
        if L:
            M = np.eye(len(L)) - self.D22[np.ix_(L, L)]
            if abs(np.linalg.det(M)) < 1e-12:
                raise NotImplementedError(f"the zero-delay channels {L} form an algebraic loop that is not well posed")
            S = list(held)
            rhs_x = self.C2[L]
            rhs_u = self.D21[L]
            rhs_p = self.D22[np.ix_(L, P)] if P else np.zeros((len(L), 0))
            rhs_c = self.D22[np.ix_(L, S)] @ wc[S] if S else np.zeros(len(L))
            Wx[L] = np.linalg.solve(M, rhs_x)
            Wu[L] = np.linalg.solve(M, rhs_u)
            Wp[L] = np.linalg.solve(M, rhs_p) if P else np.zeros((len(L), 0))
            wc[L] = np.linalg.solve(M, rhs_c)
        # z and x' in the same terms
        Zx, Zu = self.C2 + self.D22 @ Wx, self.D21 + self.D22 @ Wu
        Zp, zc = self.D22 @ Wp, self.D22 @ wc
        Ax, Au = self.A + self.B2 @ Wx, self.B1 + self.B2 @ Wu
        Ap, ac = self.B2 @ Wp, self.B2 @ wc
        out = (Wx, Wu, Wp, wc, Zx, Zu, Zp, zc, Ax, Au, Ap, ac)
        self._maps[mode] = out
        return out

    def _algebra(self, x: np.ndarray, u: np.ndarray, wp: np.ndarray, mode: tuple[int, ...]
                 ) -> tuple[np.ndarray, np.ndarray]:
        Wx, Wu, Wp, wc, Zx, Zu, Zp, zc = self._map(mode)[:8]
        return Wx @ x + Wu @ u + Wp @ wp + wc, Zx @ x + Zu @ u + Zp @ wp + zc

    def _delayed(self, tr: Trajectory, t: float, sel: float) -> np.ndarray:
        """The delayed channels' values ``w_P(t)`` (saturated where limited), read from the history."""
        out = np.empty(len(self.P))
        for k, j in enumerate(self.P):
            v = self._z_past(tr, j, t - self.tau[j], sel - self.tau[j])
            out[k] = min(max(v, self.lo[j]), self.hi[j])
        return out

    def _z_past(self, tr: Trajectory, j: int, s: float, sel: float) -> float:
        """``z_j(s)`` from the solved history (0 before the start)."""
        if sel < tr.t0:
            return 0.0
        g = tr._seg(s, sel)
        x = g.dense(s) if g.dense is not None else g.x0
        u = tr.u(s, sel)
        mp = self._map(g.mode)
        Zx, Zu, Zp, zc = mp[4], mp[5], mp[6], mp[7]
        val = float(Zx[j] @ x + Zu[j] @ u + zc[j])
        if self.z_on_wp[j].any():  # neutral: the delayed channels at s, from that segment's interpolant
            val += float(Zp[j] @ g.wp(s))
        return val

    def _fit_wp(self, tr: Trajectory, g: _Segment) -> Callable[[float], np.ndarray]:
        """The delayed channels on a solved segment of a neutral system, interpolated at Chebyshev points of
        the first kind (interior points: no jump at an end is sampled).  Between breakpoints they are smooth up to
        derivatives of order max_order or more, and the segments are short, so the interpolant of degree
        _CHEB - 1 is exact to rounding level; it saves the recursion through every earlier segment."""
        if g.b - g.a <= _eps(g.b):
            v = self._delayed(tr, g.a, g.a + _eps(g.a))
            return lambda s, v=v: v
        nodes = np.cos(np.pi * (np.arange(_CHEB) + 0.5) / _CHEB)
        ts = 0.5 * (g.a + g.b) + 0.5 * (g.b - g.a) * nodes
        vals = np.array([self._delayed(tr, float(t), float(t)) for t in ts])  # (N, len(P))
        coef = np.polynomial.chebyshev.chebfit(nodes, vals, _CHEB - 1)
        c, h = 0.5 * (g.a + g.b), 0.5 * (g.b - g.a)
        return lambda s, coef=coef: _chebval((s - c) / h, coef)

    # -- the run ---------------------------------------------------------------------------------------------
    def run(self, t_end: float, *, u: Callable[[float, float], np.ndarray] | None = None, X0: Any = 0.0,
            t0: float = 0.0, kinks: Any = (), impulse: Any = None) -> Trajectory:
        """Solve on ``[t0, t_end]``.

        ``u(t, sel)`` is the input at ``t`` (``sel``, a time nudged into the piece being solved, decides which side
        of a jump); ``kinks`` the times where it is not smooth (besides ``t0``, where it may jump); ``impulse`` a
        vector of Dirac weights on the inputs at ``t0``.
        """
        n, m = self.n, self.m
        if u is None:
            zero = np.zeros(self.nu)
            u = lambda t, sel: zero  # noqa: E731
        if impulse is not None and (self.satZ or any(self.limited)):
            raise NotImplementedError("an impulse into a system with saturations has no meaning here")
        x = np.zeros(n) + np.asarray(X0, float).ravel() if n else np.zeros(0)
        tr = Trajectory(self, [], u, t0, t_end)
        pending: list[_Break] = [_Break(t0, u=0.0, x=0.0)]  # at the start anything may jump
        for tk in np.asarray(kinks, float).ravel():
            if t0 < tk < t_end:
                self._add(pending, _Break(float(tk), u=1.0))
        mode = tuple(0 for _ in self.satZ)
        t = t0
        stalls = 0
        widen: set[int] = set()
        dirac_now = None
        if impulse is not None:
            dirac_now = ("input", np.asarray(impulse, float).ravel())
        while t < t_end - _eps(t_end):
            here = self._pop(pending, t)
            # Dirac parts: the state jumps; the Dirac parts of z go on through the delays
            if dirac_now is not None or (here is not None and here.dirac is not None):
                Wlin = self._map(tuple(0 for _ in self.satZ))
                du = dirac_now[1] if dirac_now is not None else np.zeros(self.nu)
                dp = here.dirac if here is not None and here.dirac is not None else np.zeros(len(self.P))
                dw = Wlin[1] @ du + Wlin[2] @ dp
                tr.diracs.append((t, self.D11 @ du + self.D12 @ dw))
                x = x + self.B1 @ du + self.B2 @ dw
                dz = self.D21 @ du + self.D22 @ dw
                for k, j in enumerate(self.P):
                    if dz[j] != 0.0 and t + self.tau[j] <= t_end:
                        arr = np.zeros(len(self.P))
                        arr[k] = dz[j]
                        self._add(pending, _Break(t + self.tau[j], x=0.0, dirac=arr))
                dirac_now = None
                here = here or _Break(t)
                here.x = 0.0
            if here is not None:
                self._images(pending, here, t_end)
            nxt = min(t + self.tau_min, t_end)
            if pending:
                nxt = min(nxt, pending[0].t)
            sel_a = t + _eps(t)
            mode = self._consistent_mode(tr, t, sel_a, x, mode)
            if tr.segments:
                self._jump_crossings(tr, pending, t, x, mode, t_end)
            seg, te, jch, crossings = self._segment(tr, t, nxt, x, mode, widen)
            tr.add(seg)
            if self.neutral:
                seg.wp = self._fit_wp(tr, seg)
            for ts, j in crossings:  # a delayed saturation switched at ts: a kink of w_j at ts + tau_j
                tr.switches.append((ts, j))
                if ts + self.tau[j] < t_end:
                    self._add(pending, _Break(ts + self.tau[j], w={self.P.index(j): 1.0}))
            end = seg.b
            x = seg.dense(end) if seg.dense is not None else seg.x0
            if te is not None:  # a zero-delay saturation switches: new mode from here
                k = self.satZ.index(jch[0])
                stalls = stalls + 1 if te - t < _eps(te) else 0
                if stalls > 100:
                    raise NotImplementedError(f"the saturations switch without end at t = {te:g} (sliding)")
                if stalls and tr.switches and tr.switches[-1][1] == jch[0]:
                    # switched at te and straight back: the free value grazes the limit or stays on it (an
                    # equilibrium on the limit); go on in the linear mode, with this channel's limits widened by
                    # _GRAZE (relative) until it next switches, so w_j errs by at most that much meanwhile
                    mode = mode[:k] + (0,) + mode[k + 1:]
                    widen = {jch[0]}
                else:
                    mode = mode[:k] + (jch[1],) + mode[k + 1:]
                    widen.discard(jch[0])
                tr.switches.append((te, jch[0]))
                self._add(pending, _Break(te, sat=1.0))
            t = end
        return tr

    def _jump_crossings(self, tr: Trajectory, pending: list[_Break], t: float, x: np.ndarray,
                        mode: tuple[int, ...], t_end: float) -> None:
        """A delayed saturation's input ``z_j`` jumping across a limit at ``t`` (no event sees it): ``w_j`` jumps
        at ``t + tau_j``."""
        lim_p = [j for j in self.P if self.limited[j]]
        if not lim_p:
            return
        zl = tr.signals(t, -1)[2]
        sel = t + _eps(t)
        zr = self._algebra(x, tr.u(t, sel), self._delayed(tr, t, sel), mode)[1]
        for j in lim_p:
            for lim in (self.lo[j], self.hi[j]):
                if math.isfinite(lim) and (zl[j] - lim) * (zr[j] - lim) < 0 and t + self.tau[j] < t_end:
                    tr.switches.append((t, j))
                    self._add(pending, _Break(t + self.tau[j], w={self.P.index(j): 0.0}))

    def _consistent_mode(self, tr: Trajectory, t: float, sel: float, x: np.ndarray, mode: tuple[int, ...]
                         ) -> tuple[int, ...]:
        """Keep ``mode`` if the zero-delay saturations are consistent with it at ``t`` (right limit); otherwise
        find the one mode that is."""
        if not self.satZ:
            return mode
        u = tr.u(t, sel)
        wp = self._delayed(tr, t, sel)
        tol = 2 * _GRAZE * (1.0 + (float(np.max(np.abs(x))) if x.size else 0.0))

        def ok(md: tuple[int, ...]) -> bool:
            _, z = self._algebra(x, u, wp, md)
            for j, s in zip(self.satZ, md):
                if s == 0 and not (self.lo[j] - tol <= z[j] <= self.hi[j] + tol):
                    return False
                if s > 0 and z[j] < self.hi[j] - tol:
                    return False
                if s < 0 and z[j] > self.lo[j] + tol:
                    return False
            return True

        if ok(mode):
            return mode
        good = [md for md in itertools.product((0, -1, 1), repeat=len(self.satZ)) if ok(md)]
        if not good:
            raise NotImplementedError(f"no consistent saturation mode at t = {t:g}")
        return good[0]

    def _segment(self, tr: Trajectory, a: float, b: float, x: np.ndarray, mode: tuple[int, ...],
                 widen: set[int] = frozenset()):
        """Integrate ``[a, b]`` in ``mode``; stop at the first zero-delay saturation switch."""
        Wx, Wu, Wp, wc, Zx, Zu, Zp, zc, Ax, Au, Ap, ac = self._map(mode)
        mid = 0.5 * (a + b)

        def inputs(t: float) -> tuple[np.ndarray, np.ndarray]:
            sel = t + _eps(t) if t <= mid else t - _eps(t)
            return tr.u(t, sel), (self._delayed(tr, t, sel) if self.P else np.zeros(0))

        def rhs(t: float, xx: np.ndarray) -> np.ndarray:
            uu, wp = inputs(t)
            return Ax @ xx + Au @ uu + Ap @ wp + ac

        def zfun(t: float, xx: np.ndarray) -> np.ndarray:
            uu, wp = inputs(t)
            return Zx @ xx + Zu @ uu + Zp @ wp + zc

        events, meta = [], []
        for k, j in enumerate(self.satZ):
            s = mode[k]
            for lim, newmode, direction in ((self.hi[j], 1, 1.0), (self.lo[j], -1, -1.0)):
                if not math.isfinite(lim):
                    continue
                if s == 0:      # linear: reaching the limit from inside
                    if j in widen:
                        lim = lim + direction * _GRAZE * max(1.0, abs(lim))
                    ev = (lambda t, xx, j=j, lim=lim: zfun(t, xx)[j] - lim)
                    ev.direction, ev.terminal = direction, True
                    events.append(ev)
                    meta.append(("zero", j, newmode))
                elif s == newmode:  # held at this limit: the free value coming back inside
                    ev = (lambda t, xx, j=j, lim=lim: zfun(t, xx)[j] - lim)
                    ev.direction, ev.terminal = -direction, True
                    events.append(ev)
                    meta.append(("zero", j, 0))
        for j in self.P:
            if not self.limited[j]:
                continue
            for lim in (self.hi[j], self.lo[j]):
                if math.isfinite(lim):
                    ev = (lambda t, xx, j=j, lim=lim: zfun(t, xx)[j] - lim)
                    ev.direction, ev.terminal = 0.0, False
                    events.append(ev)
                    meta.append(("delayed", j, 0))
        crossings: list[tuple[float, int]] = []
        if self.n == 0:
            # no states: nothing to integrate; find delayed-saturation crossings and zero-delay switches on a
            # fine scan refined by bisection (the signals are piecewise smooth functions of the input only)
            seg = _Segment(a, b, None, x.copy(), mode)
            te, jch = None, None
            if events:
                grid = np.linspace(a, b, 401)
                xx = np.zeros(0)
                for ev, (kind, j, newmode) in zip(events, meta):
                    g = np.array([ev(tt, xx) for tt in grid])
                    idx = np.flatnonzero(np.sign(g[:-1]) * np.sign(g[1:]) < 0)
                    if not idx.size:
                        continue
                    lo_t, hi_t = grid[idx[0]], grid[idx[0] + 1]
                    for _ in range(60):
                        mt = 0.5 * (lo_t + hi_t)
                        if np.sign(ev(mt, xx)) == np.sign(ev(lo_t, xx)):
                            lo_t = mt
                        else:
                            hi_t = mt
                    tc = 0.5 * (lo_t + hi_t)
                    if kind == "delayed":
                        crossings.append((tc, j))
                    elif te is None or tc < te:
                        te, jch = tc, (j, newmode)
                if te is not None:
                    seg.b = te
                    crossings = [(tc, j) for tc, j in crossings if tc <= te]
            return seg, te, jch, crossings
        sol = solve_ivp(rhs, (a, b), x, method="DOP853", rtol=self.rtol, atol=self.atol, dense_output=True,
                        events=events or None)
        if sol.status < 0:
            raise RuntimeError(f"DOP853 failed on [{a:g}, {b:g}]: {sol.message}")
        te, jch = None, None
        if events:
            for (kind, j, newmode), times in zip(meta, sol.t_events):
                for tc in times:
                    if kind == "delayed":
                        crossings.append((float(tc), j))
                    elif te is None or tc < te:
                        te, jch = float(tc), (j, newmode)
        seg = _Segment(a, float(sol.t[-1]) if te is None else te, _Dense(sol.sol), x.copy(), mode)
        return seg, te, jch, crossings

    # -- breakpoints -----------------------------------------------------------------------------------------
    @staticmethod
    def _add(pending: list[_Break], br: _Break) -> None:
        for p in pending:
            if abs(p.t - br.t) <= _eps(br.t):
                LTIOracle._merge(p, br)
                if br.dirac is not None:
                    p.dirac = br.dirac if p.dirac is None else p.dirac + br.dirac
                return
        bisect.insort(pending, br, key=lambda q: q.t)

    @staticmethod
    def _merge(p: _Break, br: _Break) -> None:
        p.u, p.x, p.sat = min(p.u, br.u), min(p.x, br.x), min(p.sat, br.sat)
        for k, o in br.w.items():
            p.w[k] = min(p.w.get(k, math.inf), o)

    @staticmethod
    def _pop(pending: list[_Break], t: float) -> _Break | None:
        out = None
        while pending and pending[0].t <= t + _eps(t):
            br = pending.pop(0)
            if out is None:
                out = br
            else:
                LTIOracle._merge(out, br)
                if br.dirac is not None:
                    out.dirac = br.dirac if out.dirac is None else out.dirac + br.dirac
        return out

    def _images(self, pending: list[_Break], br: _Break, t_end: float) -> None:
        """The breakpoint's images through each delay channel, with the order of the jump they carry."""
        for k, j in enumerate(self.P):
            order = min(br.x,  # the state jumps: z jumps through C2
                        br.u + (0 if self.z_on_u[j] else 1),
                        min((o + (0 if self.z_on_wp[j, c] else 1) for c, o in br.w.items()), default=math.inf),
                        br.sat + (0 if self.z_on_sat[j] else 1))
            tj = br.t + self.tau[j]
            if order <= self.max_order and tj < t_end - _eps(t_end):
                self._add(pending, _Break(tj, w={k: order}))

    # -- responses shaped as python-control's ----------------------------------------------------------------
    def step(self, T: Any, *, amplitude: float = 1.0, inputs: Any = None) -> np.ndarray:
        """Step responses ``(ny, nu, nt)`` at the times ``T`` (>= 0): input ``i`` steps by ``amplitude`` at 0, the
        others stay 0
        (only the inputs listed in ``inputs``, if given; the other columns are NaN)."""
        T = np.asarray(T, float)
        out = np.full((self.ny, self.nu, T.size), np.nan)
        for i in (range(self.nu) if inputs is None else inputs):
            e = np.zeros(self.nu)
            e[i] = amplitude
            zero = np.zeros(self.nu)
            tr = self.run(float(T[-1]), u=lambda t, sel, e=e: e if sel >= 0.0 else zero)
            out[:, i, :] = tr.outputs(T)
        return out

    def impulse(self, T: Any, *, diracs: bool = False) -> Any:
        """Impulse responses ``(ny, nu, nt)`` (the regular part; see the module docstring), the impulse at 0;
        with ``diracs``, also the outputs' Dirac terms as ``(time, output, input, weight)``, weights not 0."""
        T = np.asarray(T, float)
        out = np.empty((self.ny, self.nu, T.size))
        terms = []
        for i in range(self.nu):
            e = np.zeros(self.nu)
            e[i] = 1.0
            tr = self.run(float(T[-1]), impulse=e)
            out[:, i, :] = tr.outputs(T)
            terms += [(tt, k, i, float(wk)) for tt, w in tr.diracs for k, wk in enumerate(w) if wk != 0.0]
        return (out, sorted(terms)) if diracs else out

    def initial(self, T: Any, X0: Any) -> np.ndarray:
        """The response ``(ny, nt)`` at the times ``T`` (>= 0) from the state ``X0`` at 0, with zero input and
        history."""
        T = np.asarray(T, float)
        return self.run(float(T[-1]), X0=X0).outputs(T)

    def forced(self, T: Any, U: Any, X0: Any = 0.0) -> np.ndarray:
        """The response ``(ny, nt)`` to ``U`` (``(nu, nt)``, linear between the samples ``T``, 0 before
        ``T[0]``)."""
        T = np.asarray(T, float)
        U = np.asarray(U, float).reshape(self.nu, T.size)
        t0 = float(T[0])
        zero = np.zeros(self.nu)

        Tl = T.tolist()

        def u(t: float, sel: float) -> np.ndarray:  # np.interp of every input, with one look-up of the interval
            if sel < t0:
                return zero
            if t <= Tl[0]:
                return U[:, 0].copy()
            if t >= Tl[-1]:
                return U[:, -1].copy()
            k = bisect.bisect_right(Tl, t) - 1
            f = (t - Tl[k]) / (Tl[k + 1] - Tl[k])
            return U[:, k] + f * (U[:, k + 1] - U[:, k])

        return self.run(float(T[-1]), u=u, t0=t0, X0=X0, kinks=T[1:-1]).outputs(T)
