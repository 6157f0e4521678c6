"""An independent reference solver for the altitude loop, used only by the tests.

It shares no code with delaykit's kernel: it integrates the loop with SciPy's DOP853 (rtol 1e-12) between
breakpoints, restarting at every breakpoint (t = 0, the sample instants, the saturation switches found
by event location, and all their images k*Td later), and evaluates the delayed command from the dense
output of earlier segments.  It is slow (pure Python, recursion through the history for the neutral
loop) and meant for a few dozen loops.
"""

from __future__ import annotations

import bisect
import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, minimize_scalar


class Oracle:
    def __init__(self, kp, td, kv=0.0, vmax=1.0, filtered=False, wf=38.0, zf=1.0, period=None, offset=0.0,
                 step=1.0, t_end=15.0, gain=1.0, lag=0.0):
        self.gain, self.lag = gain, lag
        assert td > 0
        self.kp, self.td, self.kv = kp, td, kv
        self.vmax = math.inf if vmax is None else vmax
        self.filtered = filtered and kv > 0
        self.wf, self.zf = wf, zf
        self.period, self.offset = period, offset
        self.r, self.t_end = step, t_end
        self.seg_t0: list[float] = []
        self.segs: list = []
        self.samples_t: list[float] = []
        self.samples_u: list[float] = []
        self._solve()

    # -- history -----------------------------------------------------------------------------------
    def state(self, t):
        if t < 0 or not self.segs:
            return np.zeros(4)
        i = max(0, bisect.bisect_right(self.seg_t0, t) - 1)
        return self.segs[i](t)

    def v(self, t):
        """Plant input at t: gain * u(t - Td)."""
        return self.gain * self.u(t - self.td)

    def speed(self, t, y):
        """The plant's vertical speed: the plant input, or the lag state."""
        return y[3] if self.lag > 0 else self.v(t)

    def p(self, t, y=None):
        if y is None:
            y = self.state(t)
        vel = self.wf**2 * y[2] if self.filtered else self.speed(t, y)
        return self.kp * (self.r - y[0]) - self.kv * vel

    def u(self, t):
        if t < 0:
            return 0.0
        if self.period:
            i = bisect.bisect_right(self.samples_t, t) - 1
            return self.samples_u[i] if i >= 0 else 0.0
        return min(max(self.p(t), -self.vmax), self.vmax)

    # -- integration -------------------------------------------------------------------------------
    def _rhs(self, t, y):
        vin = self.v(t)
        dz = y[3] if self.lag > 0 else vin
        dl = (vin - y[3]) / self.lag if self.lag > 0 else 0.0
        if self.filtered:
            return [dz, y[2], -self.wf**2 * y[1] - 2 * self.zf * self.wf * y[2] + y[0], dl]
        return [dz, 0.0, 0.0, dl]

    def _solve(self):
        T = self.t_end
        bps = {0.0}
        k = 0
        if self.period:
            t = self.offset
            while t < T:
                bps.add(t)
                k += 1
                t = self.offset + k * self.period
        todo = sorted(bps)
        order = list(todo)  # the breakpoints, kept sorted (bisect) so that each step finds the next in log time

        def add(b):
            if b not in bps:
                bps.add(b)
                bisect.insort(order, b)

        # add the images of every breakpoint
        def add_images(b):
            t = b + self.td
            while t < T:
                add(round(t, 13))
                t += self.td
        for b in todo:
            add_images(b)
        t = 0.0
        y = np.zeros(4)
        samples = self._sample_times() if self.period else []
        while t < T - 1e-12:
            i = bisect.bisect_right(order, t + 1e-12)  # the first breakpoint > t + 1e-12
            nxt = min(order[i], T) if i < len(order) else T
            j = bisect.bisect_right(samples, t - 1e-12)  # a sample within 1e-12 of t?
            if self.period and j < len(samples) and samples[j] < t + 1e-12:
                self._take_sample(t, y)
            events = []
            if not self.period and math.isfinite(self.vmax):
                for sgn in (1.0, -1.0):
                    ev = (lambda tt, yy, s=sgn: self.kp * (self.r - yy[0]) - self.kv * (
                        self.wf**2 * yy[2] if self.filtered else self.speed(tt, yy)) - s * self.vmax)
                    events.append(ev)
            sol = solve_ivp(self._rhs, (t, nxt), y, method="DOP853", rtol=1e-12, atol=1e-14,
                            dense_output=True, events=events or None)
            self.seg_t0.append(t)
            self.segs.append(sol.sol)
            if events:
                for te in sol.t_events:
                    for ts in te:
                        if t + 1e-12 < ts < nxt - 1e-12:
                            add_images(ts)
            y = sol.y[:, -1]
            t = nxt

    def _sample_times(self):
        if not hasattr(self, "_st"):
            n = int(math.ceil((self.t_end - self.offset) / self.period)) + 1
            self._st = [self.offset + i * self.period for i in range(n)]
        return self._st

    def _take_sample(self, t, y):
        if self.filtered:
            vel = self.wf**2 * y[2]
        elif self.lag > 0:
            vel = y[3]
        else:
            vel = self.gain * self.u(t - self.td - 1e-12)
        p = self.kp * (self.r - y[0]) - self.kv * vel
        self.samples_t.append(t)
        self.samples_u.append(min(max(p, -self.vmax), self.vmax))

    # -- metrics -----------------------------------------------------------------------------------
    def z(self, t):
        return np.array([self.state(tt)[0] for tt in np.atleast_1d(t)])

    def metrics(self, band=0.02, dt=2e-3):
        w = lambda tt: self.state(tt)[0] / self.r  # noqa: E731
        grid = np.arange(0.0, self.t_end + 1e-12, dt)
        wg = np.array([w(tt) for tt in grid])
        i = int(np.argmax(wg))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        res = minimize_scalar(lambda tt: -w(tt), bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-12})
        wpk, tpk = (-res.fun, res.x) if -res.fun > wg[i] else (wg[i], grid[i])
        out = {"overshoot": max(0.0, wpk - 1.0) * 100.0, "peak_time": tpk if wpk > 1 else math.nan}
        for lev, key in ((0.1, "t10"), (0.9, "t90")):
            j = np.flatnonzero(wg >= lev)
            out[key] = brentq(lambda tt: w(tt) - lev, grid[j[0] - 1], grid[j[0]], xtol=1e-14) if j.size else math.nan
        out["rise_time"] = out["t90"] - out["t10"]
        dev = np.abs(wg - 1.0)
        j = np.flatnonzero(dev >= band)
        if j[-1] == grid.size - 1:
            out["settling_time"] = math.nan
        else:
            a, b = grid[j[-1]], grid[j[-1] + 1]
            lev = 1 + band if wg[j[-1]] > 1 else 1 - band
            out["settling_time"] = brentq(lambda tt: w(tt) - lev, a, b, xtol=1e-14)
        out["final"] = w(self.t_end)
        return out
