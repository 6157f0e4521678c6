"""An independent reference solver for the general delayed SISO loop, used only by the tests.

It shares no code with delaykit (and does not import it).  The loop is integrated with SciPy's DOP853
(rtol 1e-12 by default) by the method of steps: the integrator is restarted at every breakpoint, and
every delayed quantity is read from the dense outputs of the segments already solved.

The loop (all signals are deviations, 0 for t < 0):

    plant        x' = A x + B w,  y = C x + D w,  w(t) = u(t - Ti) + d 1(t >= t_d)
    measurement  ym(t) = y(t - To),  vm(t) = y'(t - To) = C A x(t - To) + C B w(t - To)
    controller   v = f(r - ym, ym, vm, controller states)   (p, pv, pi, pd, pid, or a state-space "tf")
    actuator     u = clip(v, umin, umax), or sampled and held: u(t) = clip(v(t_k)) on [t_k, t_k+1)

Breakpoints.  Let L = Ti + To.  The command u is non-smooth (or jumps) at the "command sources": t = 0,
the reference's breakpoints, the saturation switches (located as events), t_d + To, and, because u
feeds back to itself through the loop delay L, at every source plus k L.  The plant input w is
non-smooth at the command's breakpoints plus Ti, and at t_d.  So the breakpoints are
{c + k L, c + Ti + k L : c a command source, k >= 0} together with t_d.  Segments are also cut to at
most min(Ti, To) (the positive ones) so that every delayed value comes from an already solved segment.
For sampled control the command only jumps at the sample instants t_k, and the breakpoints are
t_k, t_k + Ti, t_k + L, t_d, t_d + To, the reference's breakpoints, and the continuous-v saturation
switches that drive the anti-windup of the (continuous-time) integrator.

Delayed look-ups at a segment's ends: on the segment [a, b] a delayed value at s = t - delay is taken
from the piece that covers the shifted interior (a - delay, b - delay): the piece is selected at
s nudged by a tiny amount towards the shifted midpoint ("sel" below) and then evaluated at s.

Neutral loops (PV with true velocity and C B != 0, or D != 0): u(t) depends on u(t - L) directly;
u is then evaluated by running the recursion u(s - j L), j = J .. 0, forwards from the oldest term.

Saturation switches are located as events (on v - umax, v - umin; and, for the clamp, on e while
saturated); a segment is stopped at its first event and re-integrated up to it, so no step straddles a
switch.  The clamp is a hybrid system: its mode ("free": xi' = e, "clamped": xi' = 0) is frozen on a
segment and re-decided at each segment start.  Where both modes push v towards the limit (free: v' > 0
below it, clamped: v' < 0 above it) the literal rule has no classical solution, and the oracle follows the
Filippov sliding mode v = umax (xi' = -g / Ki, with g the part of v' not due to the integrator); it is
the limit of any fixed-step simulation of the literal rule, which chatters around it with O(h) error.

Not supported (NotImplementedError): continuous control with Ti + To = 0 in a neutral loop (an
algebraic loop), PV with true velocity when D != 0, and the clamp anti-windup when D != 0.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.integrate import DOP853
from scipy.optimize import brentq, minimize_scalar

_TOL = 1e-12  # breakpoints closer than this are merged


class _Dense:
    """The dense output of one segment: DOP853's 7th-degree interpolants of its steps, evaluated with
    the same formula as SciPy's Dop853DenseOutput but with far less overhead per scalar call."""

    def __init__(self, interps):
        self.t0 = [d.t_old for d in interps]
        self.steps = [(d.t_old, d.h, np.asarray(d.F), np.asarray(d.y_old)) for d in interps]

    def __call__(self, t):
        i = bisect.bisect_right(self.t0, t) - 1
        t_old, h, F, y_old = self.steps[min(max(i, 0), len(self.steps) - 1)]
        x = (t - t_old) / h
        c = [0.0] * 7
        cum = 1.0
        for k in range(7):  # coefficient of F[k]: x (1-x) x (1-x) ... (k + 1 factors)
            cum *= x if k % 2 == 0 else 1.0 - x
            c[k] = cum
        return y_old + np.dot(c, F)


@dataclass
class LoopSpec:
    A: Any
    B: Any
    C: Any
    D: float = 0.0
    Ti: float = 0.0
    To: float = 0.0
    controller: str = "p"  # "p", "pv", "pi", "pd", "pid", "tf"
    kp: float = 0.0
    ki: float = 0.0
    kd: float = 0.0
    kv: float = 0.0
    tf: float = 0.0  # derivative filter time constant (pd, pid)
    velocity: str = "true"  # "true" | "filtered" (pv)
    wf: float = 38.0
    zf: float = 1.0
    ctrl_ss: Any = None  # (Ac, Bc, Cc, Dc) for "tf", acting on the error
    antiwindup: str = "none"  # "none" | "clamp" | "backcalc" (pi and pid only)
    tt: float = 1.0  # back-calculation tracking time
    umin: float = -math.inf
    umax: float = math.inf
    period: float | None = None
    offset: float = 0.0
    reference: tuple = ("step", 1.0)
    disturbance: tuple | None = None  # (d, t_d)
    t_end: float = 10.0


class LoopOracle:
    def __init__(self, spec: LoopSpec, rtol: float = 1e-12, atol: float = 1e-14):
        self.spec = spec
        self.rtol, self.atol = rtol, atol
        self._setup()
        self._solve()

    # ------------------------------------------------------------------------------------------------
    # set-up and validation
    # ------------------------------------------------------------------------------------------------
    def _setup(self):
        s = self.spec
        A = np.atleast_2d(np.asarray(s.A, dtype=float))
        n = A.shape[0]
        if A.shape != (n, n) or n < 1:
            raise ValueError("A must be square, order >= 1")
        self.A = A
        self.B = np.asarray(s.B, dtype=float).reshape(n)
        self.C = np.asarray(s.C, dtype=float).reshape(n)
        self.D = float(np.asarray(s.D, dtype=float).reshape(()))
        self.n = n
        self.CA = self.C @ self.A
        self.CB = float(self.C @ self.B)
        self.Ti, self.To = float(s.Ti), float(s.To)
        if self.Ti < 0 or self.To < 0:
            raise ValueError("delays must be >= 0")
        self.L = self.Ti + self.To
        self.T = float(s.t_end)
        if not self.T > 0:
            raise ValueError("t_end must be > 0")
        self.umin, self.umax = float(s.umin), float(s.umax)
        if self.umin > 0 or self.umax < 0:
            raise ValueError("need umin <= 0 <= umax")
        self.sat = math.isfinite(self.umin) or math.isfinite(self.umax)

        ctrl = s.controller
        self.ctrl = ctrl
        self.kp, self.ki, self.kd, self.kv = float(s.kp), float(s.ki), float(s.kd), float(s.kv)
        self.pv_true = False
        if ctrl == "p":
            self.nc = 0
        elif ctrl == "pv":
            if s.velocity == "true":
                self.pv_true = True
                self.nc = 0
                if self.D != 0:
                    raise NotImplementedError("pv with true velocity needs D = 0")
            elif s.velocity == "filtered":
                self.nc = 2
                self.wf, self.zf = float(s.wf), float(s.zf)
            else:
                raise ValueError(f"unknown velocity {s.velocity!r}")
        elif ctrl == "pi":
            self.nc = 1
        elif ctrl in ("pd", "pid"):
            self.tf = float(s.tf)
            if not self.tf > 0:
                raise ValueError("pd/pid need a derivative filter time tf > 0")
            self.nc = 2 if ctrl == "pid" else 1
        elif ctrl == "tf":
            Ac, Bc, Cc, Dc = s.ctrl_ss
            Ac = np.asarray(Ac, dtype=float)
            nc = 0 if Ac.size == 0 else np.atleast_2d(Ac).shape[0]
            self.nc = nc
            self.Ac = np.atleast_2d(Ac).reshape(nc, nc) if nc else np.zeros((0, 0))
            self.Bc = np.asarray(Bc, dtype=float).reshape(nc)
            self.Cc = np.asarray(Cc, dtype=float).reshape(nc)
            self.Dc = float(np.asarray(Dc, dtype=float).reshape(()))
        else:
            raise ValueError(f"unknown controller {ctrl!r}")

        self.aw = s.antiwindup if ctrl in ("pi", "pid") else "none"
        if self.aw not in ("none", "clamp", "backcalc"):
            raise ValueError(f"unknown anti-windup {s.antiwindup!r}")
        if self.aw == "backcalc":
            self.tt = float(s.tt)
            if not (self.tt > 0 and self.ki != 0):
                raise ValueError("backcalc needs tt > 0 and ki != 0")
        if not self.sat:
            self.aw = "none"  # clamp / backcalc are inactive without limits
        if self.aw == "clamp" and self.D != 0:
            raise NotImplementedError("clamp anti-windup with D != 0 (the sliding mode needs ym')")

        self.period = None if s.period is None else float(s.period)
        self.offset = float(s.offset)
        if self.period is not None and not (self.period > 0 and 0 <= self.offset < self.period):
            raise ValueError("need period > 0 and 0 <= offset < period")
        self.sampled = self.period is not None

        # u(t) depends on u(t - L) directly (through D in ym, or C B in vm)
        self.neutral = self.D != 0 or (self.pv_true and self.CB != 0)
        if not self.sampled and self.L == 0 and self.neutral:
            raise NotImplementedError("continuous control with zero total delay in a neutral loop "
                                      "(algebraic loop)")

        ref = s.reference
        self.rkind = ref[0]
        if self.rkind == "step":
            self.S = float(ref[1])
        elif self.rkind == "ramp":
            self.S, self.m = float(ref[1]), float(ref[2])
        elif self.rkind == "samples":
            self.rt = np.asarray(ref[1], dtype=float)
            self.rv = np.asarray(ref[2], dtype=float)
            self.rmode = ref[3] if len(ref) > 3 else "linear"
            if self.rmode not in ("linear", "hold"):
                raise ValueError(f"unknown interpolation {self.rmode!r}")
            if self.rt.ndim != 1 or self.rt.shape != self.rv.shape or self.rt.size < 1:
                raise ValueError("bad reference samples")
            if np.any(np.diff(self.rt) <= 0):
                raise ValueError("reference sample times must increase")
            self.rt_list = self.rt.tolist()
        else:
            raise ValueError(f"unknown reference {ref!r}")

        if s.disturbance is None:
            self.dist_d, self.dist_t = 0.0, math.inf
        else:
            self.dist_d, self.dist_t = float(s.disturbance[0]), float(s.disturbance[1])
            if self.dist_t < 0:
                raise ValueError("t_d must be >= 0")
        if self.dist_d == 0:
            self.dist_t = math.inf

        # maximum segment length: delayed look-ups must fall in finished segments
        if self.sampled:
            pos = [self.To] if self.To > 0 else []
        else:
            pos = [d for d in (self.Ti, self.To) if d > 0]
        self.hmax = min(pos) if pos else math.inf

    # ------------------------------------------------------------------------------------------------
    # signals.  Every look-up takes the evaluation time s and a selection time sel (s nudged towards the
    # interior of the current segment) used for piece selection and for the side of jumps.
    # ------------------------------------------------------------------------------------------------
    def _r(self, s, sel):
        if sel < 0:
            return 0.0
        k = self.rkind
        if k == "step":
            return self.S
        if k == "ramp":
            return self.S + self.m * s
        if self.rmode == "linear":
            return float(np.interp(s, self.rt, self.rv))
        i = bisect.bisect_right(self.rt_list, sel) - 1
        return float(self.rv[max(i, 0)])

    def _rdot(self, sel):
        if sel < 0 or self.rkind == "step":
            return 0.0
        if self.rkind == "ramp":
            return self.m
        if self.rmode == "hold":
            return 0.0
        i = bisect.bisect_right(self.rt_list, sel) - 1
        if i < 0 or i >= len(self.rt_list) - 1:
            return 0.0
        return float((self.rv[i + 1] - self.rv[i]) / (self.rt[i + 1] - self.rt[i]))

    def _dist(self, sel):
        return self.dist_d if sel >= self.dist_t else 0.0

    def _hist(self, s, sel):
        """Full state [x; controller] at s from the finished segments (0 for s < 0)."""
        if sel < 0:
            return self._zero
        i = bisect.bisect_right(self._t0, sel) - 1
        return self._sols[i](s)

    def _ctrl_v(self, r, Z, xo, wo):
        """Controller output, error and measurement from the reference value r, the full state Z, the
        plant state xo = x(s - To) and the plant input wo = w(s - To)."""
        ym = float(self.C @ xo) + self.D * wo
        e = r - ym
        c = self.ctrl
        n = self.n
        if c == "p":
            v = self.kp * e
        elif c == "pv":
            if self.pv_true:
                v = self.kp * e - self.kv * (float(self.CA @ xo) + self.CB * wo)
            else:
                v = self.kp * e - self.kv * self.wf**2 * Z[n + 1]
        elif c == "pi":
            v = self.kp * e + self.ki * Z[n]
        elif c == "pid":
            v = self.kp * e + self.ki * Z[n] - self.kd * (ym - Z[n + 1]) / self.tf
        elif c == "pd":
            v = self.kp * e - self.kd * (ym - Z[n]) / self.tf
        else:
            v = (float(self.Cc @ Z[n:]) if self.nc else 0.0) + self.Dc * e
        return v, e, ym

    def _clip(self, v):
        return min(max(v, self.umin), self.umax)

    def _u(self, s, sel, Zs=None):
        """Command u(s).  Zs: the full state at s when s is the current integration time."""
        if sel < 0:
            return 0.0
        if self.sampled:
            i = bisect.bisect_right(self._samp_t, sel) - 1
            return self._samp_u[i] if i >= 0 else 0.0
        pts = [(s, sel)]
        if self.neutral:  # L > 0 here
            while pts[-1][1] - self.L >= 0:
                pts.append((pts[-1][0] - self.L, pts[-1][1] - self.L))
        n, To = self.n, self.To
        u_prev = 0.0  # u at the oldest point minus L, which is < 0
        for j in range(len(pts) - 1, -1, -1):
            sj, selj = pts[j]
            if j == 0 and Zs is not None:
                Z = Zs
            elif self.nc or To == 0:
                Z = self._hist(sj, selj)
            else:
                Z = None
            xo = Z[:n] if To == 0 else self._hist(sj - To, selj - To)[:n]
            wo = u_prev + self._dist(selj - To) if self.neutral else 0.0
            v, _, _ = self._ctrl_v(self._r(sj, selj), Z, xo, wo)
            u_prev = self._clip(v)
        return u_prev

    def _sel(self, t):
        a, b = self._seg
        mid = 0.5 * (a + b)
        if t < mid:
            return t + self._delta
        if t > mid:
            return t - self._delta
        return t

    def _signals(self, t, Z, full=False):
        """(w, v, e, ym, xo, wo) at the current integration time t with state Z: xo = x(t - To) and
        wo = w(t - To) (wo only when the loop is neutral or full is set, else 0)."""
        sel = self._sel(t)
        x = Z[: self.n]
        if self.Ti > 0 or self.sampled:
            w = self._u(t - self.Ti, sel - self.Ti) + self._dist(sel)
        else:
            w = None
        if self.To == 0:
            xo, wo = x, w
        else:
            xo = self._hist(t - self.To, sel - self.To)[: self.n]
            need = self.neutral or full
            wo = (self._u(t - self.L, sel - self.L) + self._dist(sel - self.To)) if need else 0.0
        v, e, ym = self._ctrl_v(self._r(t, sel), Z, xo, wo if (wo is not None and self.neutral) else 0.0)
        if w is None:  # continuous control, Ti = 0
            w = self._clip(v) + self._dist(sel)
            if self.To == 0:
                wo = w
        return w, v, e, ym, xo, wo

    def _vdot(self, t, Z, sig=None):
        """(v, e, g, e') with v' = g + Ki xi' (pi / pid, D = 0): g is the part of v' that does not come
        from the integrator; used for the clamp's modes."""
        w, v, e, ym, xo, wo = sig if sig is not None else self._signals(t, Z, full=True)
        ymd = float(self.CA @ xo) + self.CB * wo
        ed = self._rdot(self._sel(t)) - ymd
        g = self.kp * ed
        if self.ctrl == "pid":
            g -= self.kd * (ymd - (ym - Z[self.n + 1]) / self.tf) / self.tf
        return v, e, g, ed

    def _clamp_mode(self, t, Z):
        """The clamp's discrete mode on the segment starting at t, and whether the zero crossings of e
        matter on it.  The mode is frozen on a segment (so the right-hand side is smooth there) and
        events on v - umax, v - umin (and e) end the segment.  Modes: "free" (xi' = e), "clamped"
        (xi' = 0), and "slide+" / "slide-": the state is on v = umax / umin and both fields point into
        that surface (Filippov sliding: xi' = -g / Ki keeps v at the limit)."""
        v, e, g, ed = self._vdot(t, Z)
        eps = 1e-9
        es = e if abs(e) > eps else ed  # the sign of e just after t
        ki = self.ki
        for lim, sgn in ((self.umax, 1.0), (self.umin, -1.0)):
            if not math.isfinite(lim):
                continue
            dv = sgn * (v - lim)  # > 0: beyond the limit
            if sgn * es <= 0:
                continue  # the error does not drive further into this limit
            if dv > eps:
                return "clamped", True
            if dv < -eps:
                continue
            # on the surface v = lim: free field sgn v' = sgn (g + ki e), clamped field sgn v' = sgn g
            gf, gc = sgn * (g + ki * e), sgn * g
            if gf < -eps:
                return "free", True
            if abs(gc) <= eps:
                # the clamped field is tangent to the surface (v' = 0, as when the measurement has not moved
                # yet): which side it turns to decides (a slide if it turns back below the limit)
                gc = sgn * self._g_after(t, Z)
                if gc < -1e-15 and gf > eps:
                    return ("slide+" if sgn > 0 else "slide-"), False
                return "clamped", True
            if gc > eps or abs(gc) <= eps:
                return "clamped", True
            if gc < -eps and gf > eps:
                return ("slide+" if sgn > 0 else "slide-"), False
            return "free", True
        sat = (math.isfinite(self.umax) and v > self.umax - eps) or (math.isfinite(self.umin) and v < self.umin + eps)
        return "free", sat

    def _g_after(self, t, Z):
        """g a moment after ``t`` (the tangent case, g(t) = 0).  While the command sits at the limit the plant
        and the filters do not depend on the integrator, so g follows the same path in the clamped mode and
        in a slide: integrate the clamped field over a short stretch and read g at its end."""
        a, b = self._seg
        d = min(1e-4, (b - a) / 8)
        keep = self._cmode
        self._cmode = "clamped"
        try:
            _, Z1 = self._integrate(t, t + d, Z, [])
            self._set_seg(a, b)
            return self._vdot(t + d, Z1)[2]
        finally:
            self._cmode = keep

    def _rhs(self, t, Z):
        slide = self.aw == "clamp" and self._cmode.startswith("slide")
        sig = self._signals(t, Z, full=slide)
        w, v, e, ym = sig[:4]
        n = self.n
        dx = self.A @ Z[:n] + self.B * w
        c = self.ctrl
        if self.nc == 0:
            return dx
        if c == "pv":
            dc = [Z[n + 1], -self.wf**2 * Z[n] - 2 * self.zf * self.wf * Z[n + 1] + ym]
        elif c in ("pi", "pid"):
            if self.aw == "clamp":
                m = self._cmode
                di = e if m == "free" else (0.0 if m == "clamped" else -self._vdot(t, Z, sig)[2] / self.ki)
            elif self.aw == "backcalc":
                di = e + (self._clip(v) - v) / (self.ki * self.tt)
            else:
                di = e
            dc = [di] if c == "pi" else [di, (ym - Z[n + 1]) / self.tf]
        elif c == "pd":
            dc = [(ym - Z[n]) / self.tf]
        else:
            dc = self.Ac @ Z[n:] + self.Bc * e
        return np.concatenate([dx, dc])

    # ------------------------------------------------------------------------------------------------
    # breakpoints and integration
    # ------------------------------------------------------------------------------------------------
    def _add_bp(self, p):
        if p < -_TOL or p >= self.T - _TOL:
            return
        p = max(p, 0.0)
        bp = self._bp
        i = bisect.bisect_left(bp, p)
        if (i < len(bp) and bp[i] - p < _TOL) or (i > 0 and p - bp[i - 1] < _TOL):
            return
        bp.insert(i, p)

    def _add_source(self, c):
        """A command breakpoint c (continuous control): c + k L and c + Ti + k L for k >= 0."""
        if self.L == 0:
            self._add_bp(c)
            return
        for base in (c, c + self.Ti):
            k = 0
            while True:
                p = base + k * self.L
                if p >= self.T:
                    break
                self._add_bp(p)
                k += 1

    def _ref_breaks(self):
        if self.rkind == "samples":
            return [t for t in self.rt_list if 0 <= t < self.T]
        return []

    def _event_funcs(self):
        if self._cmode.startswith("slide"):  # it ends when a field stops pointing into the surface
            return [lambda t, Z: self._vdot(t, Z)[2],
                    lambda t, Z: (lambda v, e, g, ed: g + self.ki * e)(*self._vdot(t, Z))]
        if not self.sat:
            return []
        if self.sampled and self.aw == "none":
            return []
        evs = []
        for lim in (self.umax, self.umin):
            if math.isfinite(lim):
                evs.append(lambda t, Z, lim=lim: self._signals(t, Z)[1] - lim)
        if self.aw == "clamp" and self._e_event:
            evs.append(lambda t, Z: self._signals(t, Z)[2])
        return evs

    def _take_sample(self, t, Z):
        """v(t_k) with the reference at t_k and the left limits of ym, vm and the states."""
        d = self._delta_s
        xo = Z[: self.n] if self.To == 0 else self._hist(t - self.To, t - self.To - d)[: self.n]
        wo = self._u(t - self.L, t - self.L - d) + self._dist(t - self.To - d)
        v, _, _ = self._ctrl_v(self._r(t, t + d), Z, xo, wo)
        self._samp_t.append(t)
        self._samp_u.append(self._clip(v))

    def _solve(self):
        T = self.T
        nz = self.n + self.nc
        self._zero = np.zeros(nz)
        self._t0: list[float] = []
        self._t1: list[float] = []
        self._sols: list = []
        self._samp_t: list[float] = []
        self._samp_u: list[float] = []
        self._bp: list[float] = []
        self._delta_s = 1e-10
        sample_times = []
        if self.sampled:
            k = 0
            while True:
                tk = self.offset + k * self.period
                if tk >= T - _TOL:
                    break
                sample_times.append(tk)
                k += 1
            self._add_bp(0.0)
            for tk in sample_times:
                for p in (tk, tk + self.Ti, tk + self.L):
                    self._add_bp(p)
            for p in self._ref_breaks():
                self._add_bp(p)
            if math.isfinite(self.dist_t):
                self._add_bp(self.dist_t)
                self._add_bp(self.dist_t + self.To)
        else:
            self._add_source(0.0)
            for p in self._ref_breaks():
                self._add_source(p)
            if math.isfinite(self.dist_t):
                self._add_bp(self.dist_t)
                self._add_source(self.dist_t + self.To)
        si = 0  # next sample index
        self._cmode, self._e_event = "free", False
        self.slide_time = 0.0
        t = 0.0
        Z = np.zeros(nz)
        self.n_segments = 0
        while t < T - _TOL:
            i = bisect.bisect_right(self._bp, t + _TOL)
            nxt = self._bp[i] if i < len(self._bp) else T
            nxt = min(nxt, t + self.hmax, T)
            if self.sampled and si < len(sample_times) and abs(sample_times[si] - t) < 2 * _TOL:
                self._take_sample(sample_times[si], Z)
                si += 1
            if self.aw == "clamp":
                self._set_seg(t, nxt)
                self._cmode, self._e_event = self._clamp_mode(t, Z)
            evs = self._event_funcs()
            res = self._integrate(t, nxt, Z, evs)
            if isinstance(res, float):  # the first event in the open segment: stop there and redo
                nxt = res
                res = self._integrate(t, nxt, Z, [])
                if self.sampled:
                    self._add_bp(nxt)
                else:
                    self._add_source(nxt)
            sol, Zn = res
            if self._cmode.startswith("slide"):
                self.slide_time += nxt - t
            self._t0.append(t)
            self._t1.append(nxt)
            self._sols.append(sol)
            self.n_segments += 1
            Z = Zn
            t = nxt
        self._zend = Z

    def _set_seg(self, a, b):
        self._seg = (a, b)
        self._delta = min(1e-10, (b - a) / 4)

    def _integrate(self, a, b, Z, evs):
        """DOP853 on [a, b].  Returns (dense solution, end state), or, if one of the event functions
        changes sign in (a + 1e-10, b - 1e-10), the first such time (the caller re-integrates up to
        it: the steps that straddle the event saw a non-smooth right-hand side)."""
        self._set_seg(a, b)
        solver = DOP853(self._rhs, a, np.asarray(Z, dtype=float), b, rtol=self.rtol, atol=self.atol)
        ts, interps = [a], []
        gprev = [g(a, Z) for g in evs]
        while solver.status == "running":
            msg = solver.step()
            if solver.status == "failed":
                raise RuntimeError(msg)
            dense = solver.dense_output()
            ts.append(solver.t)
            interps.append(dense)
            if evs:
                gnew = [g(solver.t, solver.y) for g in evs]
                roots = []
                for g, g0, g1 in zip(evs, gprev, gnew):
                    if g0 != 0 and g0 * g1 <= 0:
                        te = brentq(lambda tt, g=g: g(tt, dense(tt)), solver.t_old, solver.t, xtol=1e-15)
                        if a + 1e-10 < te < b - 1e-10:
                            roots.append(te)
                if roots:
                    return float(min(roots))
                gprev = gnew
        return _Dense(interps), solver.y.copy()

    # ------------------------------------------------------------------------------------------------
    # public output
    # ------------------------------------------------------------------------------------------------
    def _state_scalar(self, t):
        if t < 0:
            return self._zero
        i = bisect.bisect_right(self._t0, t) - 1
        return self._sols[i](t)

    def _w(self, t):
        return self._u(t - self.Ti, t - self.Ti) + self._dist(t)

    def _y_scalar(self, t):
        if t < 0:
            return 0.0
        y = float(self.C @ self._state_scalar(t)[: self.n])
        if self.D != 0:
            y += self.D * self._w(t)
        return y

    def _dy_scalar(self, t):
        """y'(t) (D = 0 only)."""
        if t < 0:
            return 0.0
        return float(self.CA @ self._state_scalar(t)[: self.n]) + self.CB * self._w(t)

    def _check_t(self, t):
        t = np.asarray(t, dtype=float)
        if np.any(t > self.T + 1e-9):
            raise ValueError("t beyond t_end")
        return t

    def states(self, t):
        """Full state [x; controller states] at times t, shape t.shape + (nz,)."""
        t = self._check_t(t)
        tf = np.atleast_1d(t).ravel()
        out = np.zeros((tf.size, self.n + self.nc))
        idx = np.searchsorted(np.asarray(self._t0), tf, side="right") - 1
        for k in np.flatnonzero(tf >= 0):
            out[k] = self._sols[idx[k]](tf[k])
        return out.reshape(t.shape + (self.n + self.nc,))

    def y(self, t):
        """Plant output y(t) = C x + D w (0 for t < 0)."""
        t = self._check_t(t)
        x = self.states(t)[..., : self.n]
        y = x @ self.C
        if self.D != 0:
            tf = np.atleast_1d(t).ravel()
            wv = np.array([self._w(tt) if tt >= 0 else 0.0 for tt in tf]).reshape(t.shape)
            y = y + self.D * wv
        return np.asarray(y)

    def u(self, t):
        """Command u(t) (right-continuous; 0 for t < 0)."""
        t = self._check_t(t)
        tf = np.atleast_1d(t).ravel()
        return np.array([self._u(tt, tt) for tt in tf]).reshape(t.shape)

    def r(self, t):
        t = np.asarray(t, dtype=float)
        tf = np.atleast_1d(t).ravel()
        return np.array([self._r(tt, tt) for tt in tf]).reshape(t.shape)

    # ------------------------------------------------------------------------------------------------
    # step metrics
    # ------------------------------------------------------------------------------------------------
    def metrics(self, band=0.02, dt=1e-3):
        T = self.T
        Sf = self._r(T, T)
        if Sf == 0:
            raise ValueError("metrics need a nonzero final reference")
        npts = int(round(T / dt)) + 1
        grid = np.linspace(0.0, T, npts)
        wg = self.y(grid) / Sf

        def w(tt):
            return self._y_scalar(tt) / Sf

        # peak
        i = int(np.argmax(wg))
        tpk, wpk = float(grid[i]), float(wg[i])
        lo, hi = float(grid[max(i - 1, 0)]), float(grid[min(i + 1, npts - 1)])
        if 0 < i < npts - 1:
            done = False
            if self.D == 0:
                dw = lambda tt: self._dy_scalar(tt) / Sf  # noqa: E731
                dlo, dhi = dw(lo), dw(hi)
                if dlo > 0 > dhi:
                    # the maximum of w on [lo, hi] is at the sign change of w' (or a jump of w')
                    tc = brentq(dw, lo, hi, xtol=1e-14, rtol=4 * np.finfo(float).eps)
                    wc = w(tc)
                    if wc >= wpk:
                        tpk, wpk = tc, wc
                    done = True
            if not done:
                res = minimize_scalar(lambda tt: -w(tt), bounds=(lo, hi), method="bounded",
                                      options={"xatol": 1e-12})
                if -res.fun > wpk:
                    tpk, wpk = float(res.x), float(-res.fun)
        out = {"overshoot": max(0.0, wpk - 1.0) * 100.0, "peak_time": tpk if wpk > 1 else math.nan}

        for lev, key in ((0.1, "t10"), (0.9, "t90")):
            j = np.flatnonzero(wg >= lev)
            if not j.size:
                out[key] = math.nan
            elif j[0] == 0:
                out[key] = 0.0
            else:
                out[key] = brentq(lambda tt: w(tt) - lev, grid[j[0] - 1], grid[j[0]], xtol=1e-14,
                                  rtol=4 * np.finfo(float).eps)
        out["rise_time"] = out["t90"] - out["t10"]

        wend = w(T)
        j = np.flatnonzero(np.abs(wg - 1.0) >= band)
        if abs(wend - 1.0) >= band:
            out["settling_time"] = math.nan
        elif not j.size:
            out["settling_time"] = 0.0
        else:
            a, b = grid[j[-1]], grid[j[-1] + 1]
            lev = 1 + band if wg[j[-1]] > 1 else 1 - band
            out["settling_time"] = brentq(lambda tt: w(tt) - lev, a, b, xtol=1e-14,
                                          rtol=4 * np.finfo(float).eps)
        out["final"] = wend
        return out
