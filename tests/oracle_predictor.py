"""An independent reference solver for loops with a delay compensator, used only by the tests.

It does not import delaykit.  Each law is written from its textbook definition with *two copies* of the model
(one driven by the command, one by the command one model delay ago), not with the window states the library
uses:

* Smith:           yp = y + Gn u - Gn u(t - Tm),          v = C(s) (r - yp)    (C given as P gain or (kp, ki))
* filtered Smith:  yp = Fr y + Gn u - Gn Fr u(t - Tm),    v = Kc (r - yp)
* predictor:       yhat = y + K int_{t-Tm}^t u,  xihat = xi - Tm y - K int_{t-Tm}^t (t - s) u(s) ds
                   (the integral of r(t - Tm) - y predicted Tm ahead), xi' = r - y + (u - v) / (ki Tt)
                   (back-calculation anti-windup),
                   v = b kp r - kp yhat + ki xihat;  the integrals are differences of running integrals
                   int_0^t u, int_0^t s u(s) ds and their copies one delay later.

The plant is x' = A x + B u(t - Td), y = C x; all signals are 0 for t < 0; the reference is a step.  The
method of steps with SciPy's DOP853 (rtol 1e-12): segments end at every point where the command may be
non-smooth (t = 0, saturation switches, and their images Td and Tm later, recursively) and are at
most min(Td, Tm) long, so every delayed value is read from the dense output of a segment already solved.
"""

from __future__ import annotations

import bisect
import heapq
import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.signal import tf2ss


def _ss(num, den):
    A, B, C, D = tf2ss(num, den)
    return np.atleast_2d(A), B.ravel(), C.ravel(), float(np.ravel(D)[0])


class PredictorOracle:
    def __init__(self, kind, plant, model, Td, Tm, *, kc=0.0, ki_primary=0.0, fr=None, kp=0.0, ki=0.0, b=1.0,
                 umin=-math.inf, umax=math.inf, step=1.0, t_end=5.0, tt=1.0, rtol=1e-12, atol=1e-14):
        self.kind, self.Td, self.Tm, self.step = kind, float(Td), float(Tm), float(step)
        self.umin, self.umax, self.t_end = umin, umax, t_end
        self.kc, self.kip, self.kp, self.ki, self.b, self.tt = kc, ki_primary, kp, ki, b, tt
        self.Ap, self.Bp, self.Cp, _ = _ss(*plant)
        self.Am, self.Bm, self.Cm, _ = _ss(*model)
        self.K = float(model[0][-1])  # predictor: model K/s
        np_, nm = self.Ap.shape[0], self.Am.shape[0]
        sl = {"x": slice(0, np_)}
        k = np_
        if kind in ("smith", "filtered-smith"):
            sl["z"] = slice(k, k + nm)
            k += nm
            if kind == "smith":
                self.Ad, self.Bd, self.Cd = self.Am, self.Bm, self.Cm
            else:
                gf = (np.polymul(model[0], fr[0]), np.polymul(model[1], fr[1]))
                self.Ad, self.Bd, self.Cd, _ = _ss(*gf)
                self.Af, self.Bf, self.Cf, self.Df = _ss(*fr)
                sl["f"] = slice(k + self.Ad.shape[0], k + self.Ad.shape[0] + self.Af.shape[0])
            sl["zd"] = slice(k, k + self.Ad.shape[0])
            k = max(s.stop for s in sl.values())
            sl["int"] = slice(k, k + 1)  # the primary's integral of r - yp
            k += 1
        else:
            sl["I"] = slice(k, k + 4)  # int u, int u(s-Tm), int s u(s), int (s - Tm) u(s - Tm)
            sl["xi"] = slice(k + 4, k + 5)
            k += 5
        self.sl, self.n = sl, k
        self.segs = []  # (a, b, dense)
        self.starts = []
        self._solve(rtol, atol)

    # -- signals ----------------------------------------------------------------------------------------
    def _state(self, t):
        if t < 0 or not self.segs:
            return np.zeros(self.n)
        i = min(max(bisect.bisect_right(self.starts, t) - 1, 0), len(self.segs) - 1)
        return self.segs[i][2](t)

    def _v(self, t, X):
        s = self.sl
        r = self.step if t >= 0 else 0.0
        y = self.Cp @ X[s["x"]]
        if self.kind == "smith":
            yp = y + self.Cm @ X[s["z"]] - self.Cd @ X[s["zd"]]
            return self.kc * (r - yp) + self.kip * X[s["int"]][0]
        if self.kind == "filtered-smith":
            yp = self.Cf @ X[s["f"]] + self.Df * y + self.Cm @ X[s["z"]] - self.Cd @ X[s["zd"]]
            return self.kc * (r - yp) + self.kip * X[s["int"]][0]
        iu, iud, isu, isud = X[s["I"]]
        p = iu - iud
        q = t * p - (isu - isud)
        yhat = y + self.K * p
        xihat = X[s["xi"]][0] - self.Tm * y - self.K * q  # the integral against r(t - Tm), Tm ahead
        return self.b * self.kp * r - self.kp * yhat + self.ki * xihat

    def _u(self, t, X=None):
        if t < 0:
            return 0.0
        X = self._state(t) if X is None else X
        return min(max(self._v(t, X), self.umin), self.umax)

    def _rhs(self, t, X):
        s = self.sl
        u = min(max(self._v(t, X), self.umin), self.umax)
        ud = self._u(t - self.Td) if t - self.Td >= 0 else 0.0
        um = self._u(t - self.Tm) if t - self.Tm >= 0 else 0.0
        dX = np.zeros(self.n)
        dX[s["x"]] = self.Ap @ X[s["x"]] + self.Bp * ud
        y = self.Cp @ X[s["x"]]
        r = self.step
        if self.kind in ("smith", "filtered-smith"):
            dX[s["z"]] = self.Am @ X[s["z"]] + self.Bm * u
            dX[s["zd"]] = self.Ad @ X[s["zd"]] + self.Bd * um
            if self.kind == "smith":
                yp = y + self.Cm @ X[s["z"]] - self.Cd @ X[s["zd"]]
            else:
                dX[s["f"]] = self.Af @ X[s["f"]] + self.Bf * y
                yp = self.Cf @ X[s["f"]] + self.Df * y + self.Cm @ X[s["z"]] - self.Cd @ X[s["zd"]]
            dX[s["int"]] = r - yp
        else:
            dX[s["I"]] = [u, um, t * u, (t - self.Tm) * um]
            v = self._v(t, X)
            dX[s["xi"]] = r - y + ((u - v) / (self.ki * self.tt) if self.ki else 0.0)
        return dX

    # -- the method of steps ------------------------------------------------------------------------------
    def _solve(self, rtol, atol):
        delays = [d for d in (self.Td, self.Tm) if d > 0]
        hmax = min(delays)
        pend = [0.0]
        seen = set()

        def source(c):
            for d in delays:
                for m in (c + d,):
                    key = round(m, 11)
                    if m < self.t_end and key not in seen:
                        seen.add(key)
                        heapq.heappush(pend, m)

        source(0.0)
        a, X = 0.0, np.zeros(self.n)
        while a < self.t_end - 1e-12:
            while pend and pend[0] <= a + 1e-12:
                heapq.heappop(pend)
            b = min(self.t_end, a + hmax, pend[0] if pend else math.inf)
            sgn = {}
            evs = []
            for name, lim in (("hi", self.umax), ("lo", self.umin)):
                if math.isfinite(lim):
                    g0 = self._v(a, X) - lim
                    if abs(g0) < 1e-10:  # on the limit: the side it leaves towards decides the direction
                        g0 = self._v(a + 1e-7, X + 1e-7 * self._rhs(a, X)) - lim
                    f = (lambda t, Z, *_, lim=lim: self._v(t, Z) - lim)
                    f.terminal, f.direction = True, (-1.0 if g0 > 0 else 1.0)
                    evs.append(f)
                    sgn[name] = g0
            for _ in range(4):
                sol = solve_ivp(self._rhs, (a, b), X, method="DOP853", rtol=rtol, atol=atol, dense_output=True,
                                events=evs or None)
                end = sol.t[-1]
                if not (sol.status == 1 and end <= a + 1e-12):
                    break
                # an event at the very start: the signal leaves zero that way, so its next crossing is the other
                for f, te in zip(evs, sol.t_events):
                    if te.size and te[0] <= a + 1e-12:
                        f.direction = -f.direction
            self.segs.append((a, end, sol.sol))
            self.starts.append(a)
            X = sol.y[:, -1]
            hit = sol.status == 1 and end < b - 1e-13
            if hit or (pend and abs(end - pend[0]) <= 1e-12):
                source(end)
            a = end

    # -- output ---------------------------------------------------------------------------------------
    def y(self, t):
        t = np.atleast_1d(np.asarray(t, float))
        return np.array([0.0 if tt < 0 else float(self.Cp @ self._state(tt)[self.sl["x"]]) for tt in t])

    def u(self, t):
        t = np.atleast_1d(np.asarray(t, float))
        return np.array([self._u(tt) for tt in t])
