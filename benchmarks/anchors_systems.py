"""Anchors for the delay-system benchmark rows (issue 21): the Wood-Berry column under decentralised PI, its
closed-loop step responses over 100 min at 201 times, computed the ways a user could without delaykit's kernel.

The plant (Wood & Berry 1973, minutes)::

    xD = 12.8 e^{-s}/(16.7 s + 1) R  - 18.9 e^{-3s}/(21 s + 1) S
    xB =  6.6 e^{-7s}/(10.9 s + 1) R - 19.4 e^{-3s}/(14.4 s + 1) S

under Luyben's (1986) BLT tuning of two PI loops, ``R = 0.375 (1 + 1/(8.29 s)) (r1 - xD)``,
``S = -0.075 (1 + 1/(23.6 s)) (r2 - xB)`` (the settings the repo uses: ``delaykit.design.mimo.blt``'s docstring,
docs/guide/systems.md and docs/tutorials/wood-berry.md).  Each anchor returns ``(t, y)`` with ``y`` shaped
``(2, 2, 201)`` as python-control's ``step_response``: ``y[i, j]`` is output ``i`` (xD, xB) for a unit step of
setpoint ``j`` (r1, r2) at 0, everything at rest before.

* :func:`scipy_method_of_steps`: SciPy's ``solve_ivp`` written by hand the way a user would: the six states
  (four first-order lags, two PI integrators), each minute integrated apart (every delay is a whole number of
  minutes, so every breakpoint is one) and the delayed commands read from the dense outputs of the minutes
  already solved.
* :class:`JitcddeAnchor`: jitcdde (Ansmann 2018, an adaptive Bogacki-Shampine DDE solver compiled to C) on the
  same six states; the setpoint step seen through a delay, ``r(t - theta)``, is jitcdde's smoothed
  ``conditional`` of width 1e-9 min (symmetric about the jump, so its error is of second order in the width except
  at the jump's own instant), since jitcdde's past is a smooth spline and cannot hold the jump itself.  Compiled once (reported apart).

Run ``python benchmarks/anchors_systems.py`` to print their agreement with each other and with the test suite's
independent oracle (tests/oracle_lti.py, DOP853 at rtol 1e-12 on the system built by delaykit's algebra), and with
delaykit's kernel when it is there, with each one's CPU time.

References
----------
R. K. Wood and M. W. Berry, "Terminal composition control of a binary distillation column", Chem. Eng. Sci. 28
(1973) 1707-1717.  W. L. Luyben, "Simple method for tuning SISO controllers in multivariable systems", Ind. Eng.
Chem. Process Des. Dev. 25 (1986) 654-660.  G. Ansmann, "Efficiently and easily integrating differential equations
with JiTCODE, JiTCDDE, and JiTCSDE", Chaos 28 (2018) 043116.
"""

from __future__ import annotations

import argparse
import bisect
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["GAIN", "LAG", "DELAY", "KC", "TAU_I", "T_END", "TIMES", "scipy_method_of_steps", "JitcddeAnchor",
           "wood_berry_plant", "wood_berry_loop"]

# plant element (i, j): output i (xD, xB) from input j (R, S)
GAIN = np.array([[12.8, -18.9], [6.6, -19.4]])
LAG = np.array([[16.7, 21.0], [10.9, 14.4]])
DELAY = np.array([[1.0, 3.0], [7.0, 3.0]])
KC = np.array([0.375, -0.075])      # Luyben's BLT PI (1986)
TAU_I = np.array([8.29, 23.6])      # min
T_END = 100.0
TIMES = np.linspace(0.0, T_END, 201)


def wood_berry_plant():
    """The Wood-Berry column as a delaykit system, written as text (inputs R, S; outputs xD, xB)."""
    from delaykit import tf

    return tf([[f"{GAIN[i, j]}*exp(-{DELAY[i, j]}*s)/({LAG[i, j]}*s+1)" for j in range(2)] for i in range(2)],
              inputs=["R", "S"], outputs=["xD", "xB"], name="Wood-Berry")


def wood_berry_loop(kc: tuple[float, float] | np.ndarray = KC):
    """The same closed loop built by delaykit's algebra (for the oracle and the kernel); ``kc`` the PI gains."""
    from delaykit import feedback, tf

    G = wood_berry_plant()
    K = tf([[f"{kc[0]}*(1 + 1/({TAU_I[0]}*s))", 0], [0, f"{kc[1]}*(1 + 1/({TAU_I[1]}*s))"]],
           inputs=["e1", "e2"], outputs=["R", "S"], name="BLT PI")
    return feedback(G * K, 1)


# ----------------------------------------------------------------------------------------------------------------
# (a) SciPy's solve_ivp by the method of steps, written by hand
# ----------------------------------------------------------------------------------------------------------------
def scipy_method_of_steps(t: np.ndarray = TIMES, *, rtol: float = 1e-10, atol: float = 1e-12,
                          method: str = "DOP853") -> tuple[np.ndarray, np.ndarray]:
    """The closed-loop step responses by ``solve_ivp`` one minute at a time (see the module docstring).

    States ``q = [x11, x12, x21, x22, xi1, xi2]``: ``x_ij`` the lag of element ``(i, j)``, ``xi_i`` the integral
    of loop ``i``'s error.  ``u_j(t) = Kc_j (e_j + xi_j / tau_I_j)``, ``e_j = r_j - y_j``, ``y_i = x_i1 + x_i2``,
    and ``x_ij' = (K_ij u_j(t - theta_ij) - x_ij) / T_ij``.
    """
    t = np.asarray(t, float)
    y = np.empty((2, 2, t.size))
    for col in range(2):
        r = np.zeros(2)
        r[col] = 1.0
        starts: list[float] = []
        pieces: list = []

        def command(s: float, late: bool) -> np.ndarray:
            """u(s): 0 before the step, else read from the minute that holds s; at the step itself (s = 0, where u
            jumps), the value before it when ``late`` (at the end of a minute), after it otherwise."""
            if s < 0.0 or (s == 0.0 and late):
                return np.zeros(2)
            k = min(bisect.bisect_right(starts, s) - 1, len(pieces) - 1)
            q = pieces[k](s)
            e = r - np.array([q[0] + q[1], q[2] + q[3]])
            return KC * (e + q[4:6] / TAU_I)

        def rhs(tt: float, q: np.ndarray) -> np.ndarray:
            dq = np.empty(6)
            late = tt - minute[0] > 0.5  # in the second half of the minute being solved
            for i in range(2):
                for j in range(2):
                    uj = command(tt - DELAY[i, j], late)[j]
                    dq[2 * i + j] = (GAIN[i, j] * uj - q[2 * i + j]) / LAG[i, j]
            dq[4] = r[0] - (q[0] + q[1])
            dq[5] = r[1] - (q[2] + q[3])
            return dq

        q0 = np.zeros(6)
        minute = [0.0]
        for k in range(int(T_END)):
            minute[0] = float(k)
            # one minute: t - theta always falls in a minute already solved (theta >= 1)
            sol = solve_ivp(rhs, (float(k), float(k + 1)), q0, method=method, rtol=rtol, atol=atol,
                            dense_output=True)
            starts.append(float(k))
            pieces.append(sol.sol)
            q0 = sol.y[:, -1]
        for n, tt in enumerate(t):
            k = min(bisect.bisect_right(starts, tt) - 1, len(pieces) - 1)
            q = pieces[k](tt)
            y[:, col, n] = [q[0] + q[1], q[2] + q[3]]
    return t, y


# ----------------------------------------------------------------------------------------------------------------
# (b) jitcdde
# ----------------------------------------------------------------------------------------------------------------
class JitcddeAnchor:
    """jitcdde's model of the loop, compiled once (``compile_time`` seconds); :meth:`run` gives ``(t, y)``.

    The twelve states are the six of :func:`scipy_method_of_steps` twice, one copy per setpoint, so one run gives
    both columns.  The past is 0; the setpoint steps at 0, seen through a delay as the smoothed step
    ``conditional(t - theta, 0, 0, 1, width)``.
    """

    def __init__(self, width: float = 1e-9) -> None:
        from jitcdde import jitcdde, t, y
        from jitcxde_common.symbolic import conditional

        def model(base: int, r: tuple[float, float]) -> list:
            def command(j: int, theta: float):
                s = t - theta
                step = conditional(s, 0, 0, 1, width=width)
                e = r[j] * step - (y(base + 2 * j, s) + y(base + 2 * j + 1, s))
                return float(KC[j]) * (e + y(base + 4 + j, s) / float(TAU_I[j]))

            f = [(float(GAIN[i, j]) * command(j, float(DELAY[i, j])) - y(base + 2 * i + j)) / float(LAG[i, j])
                 for i in range(2) for j in range(2)]
            f += [r[0] - (y(base) + y(base + 1)), r[1] - (y(base + 2) + y(base + 3))]
            return f

        f = model(0, (1.0, 0.0)) + model(6, (0.0, 1.0))
        cwd = os.getcwd()
        with tempfile.TemporaryDirectory() as tmp:
            os.chdir(tmp)  # jitcdde builds with setuptools in the working directory
            try:
                t0 = time.perf_counter()
                self.dde = jitcdde(f, max_delay=float(DELAY.max()), verbose=False)
                self.dde.compile_C(simplify=False, do_cse=False, verbose=False)
                self.compile_time = time.perf_counter() - t0
            finally:
                os.chdir(cwd)

    def run(self, t: np.ndarray = TIMES, *, rtol: float = 1e-8, atol: float = 1e-10,
            max_step: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """Both columns at the times ``t`` (>= 0, increasing)."""
        t = np.asarray(t, float)
        dde = self.dde
        dde.purge_past()
        dde.constant_past(np.zeros(12), time=0.0)
        dde.set_integration_parameters(rtol=rtol, atol=atol, first_step=1e-6, min_step=1e-14, max_step=max_step)
        dde.adjust_diff()
        y = np.empty((2, 2, t.size))
        with warnings.catch_warnings():
            # a time inside the last step taken is read from jitcdde's own Hermite interpolant; it says so
            warnings.filterwarnings("ignore", message="The target time is smaller than the current time")
            states = [dde.integrate(tt) if tt > 0 else np.zeros(12) for tt in t]
        for n, q in enumerate(states):
            for col in range(2):
                b = 6 * col
                y[:, col, n] = [q[b] + q[b + 1], q[b + 2] + q[b + 3]]
        return t, y


# ----------------------------------------------------------------------------------------------------------------
# script: agreement and CPU time
# ----------------------------------------------------------------------------------------------------------------
def _cpu(fn, *args, **kw):
    c = time.process_time()
    out = fn(*args, **kw)
    return out, time.process_time() - c


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--no-jitcdde", action="store_true", help="skip jitcdde (it compiles C code first)")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from oracle_lti import LTIOracle

    T = wood_berry_loop()
    runs: dict[str, tuple[np.ndarray, float]] = {}
    (ref, cpu) = _cpu(LTIOracle(T).step, TIMES)
    runs["oracle (tests/oracle_lti.py, DOP853 rtol 1e-12)"] = (ref, cpu)
    for rtol in (1e-6, 1e-8, 1e-10):
        (out, cpu) = _cpu(scipy_method_of_steps, TIMES, rtol=rtol, atol=rtol * 1e-2)
        runs[f"SciPy method of steps by hand, DOP853 rtol {rtol:g}"] = (out[1], cpu)
    (out, cpu) = _cpu(scipy_method_of_steps, TIMES, rtol=1e-6, atol=1e-8, method="RK45")
    runs["SciPy method of steps by hand, RK45 rtol 1e-06"] = (out[1], cpu)
    if not args.no_jitcdde:
        c = time.perf_counter()
        jit = JitcddeAnchor()
        print(f"jitcdde compiled in {time.perf_counter() - c:.1f} s (wall, not counted below)")
        for rtol in (1e-6, 1e-8, 1e-10):
            (out, cpu) = _cpu(jit.run, TIMES, rtol=rtol, atol=rtol * 1e-2)
            runs[f"jitcdde rtol {rtol:g}"] = (out[1], cpu)
    try:
        from delaykit.simulate.systems import step_response
    except ImportError:
        print("delaykit.simulate.systems is not there yet: the kernel's row is missing")
    else:
        step_response(T, TIMES)  # load (and compile) first
        (r, cpu) = _cpu(step_response, T, TIMES)
        runs[f"delaykit step_response ({r.status})"] = (r.outputs, cpu)
    print(f"Wood-Berry under BLT PI, both setpoint steps, {TIMES.size} times over {T_END:g} min; "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"{'computation':55s} {'max |y - oracle|':>17s} {'CPU s':>8s}")
    for name, (y, cpu) in runs.items():
        print(f"{name:55s} {float(np.max(np.abs(y - ref))):17.3e} {cpu:8.3f}")


if __name__ == "__main__":
    main()
