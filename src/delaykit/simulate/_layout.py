"""The simulator kernel's data: a loop's parameter row (built here from a loop) and a run's metrics row.

:mod:`delaykit.simulate.simulation` builds parameter rows (:func:`param_row`) and reads metrics rows; the
kernel (:mod:`._kernel`, compiled or interpreted, see :mod:`._jit`) reads and fills them.  Kept apart so that
neither importing nor building a row imports numba.  This module is private.

Examples
--------
>>> from delaykit import AltitudeLoop
>>> from delaykit.simulate.simulation import as_loop
>>> loop = as_loop(AltitudeLoop(kp=1.31, delay=0.368))
>>> row = param_row(loop, loop_matrices(loop), step=1.0, slope=0.0, norm=1.0, t_end=15.0, band=0.02, dist=None)
>>> row.size == NPAR, float(row[HEAD["ti"]]), round(float(1.0 / row[HEAD["hmax"]]), 2)  # the fastest rate: Kp
(True, 0.368, 1.31)
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..errors import InvalidValueError
from ..models.closed_loop import LoopRealisation, loop_realisation
from ..models.loop import Loop
from ..models.signals import LoadStep

__all__ = ["LoopMatrices", "loop_matrices", "fastest_rate", "param_row", "DEG", "NC", "MAXN", "HEAD", "NHEAD",
           "NPAR", "OUT", "NOUT", "AW", "SELF", "GROW", "STATUS_OK", "STATUS_CAPACITY", "STATUS_STALLED", "OFF_M", "OFF_BW",
           "OFF_BR", "OFF_BYM", "OFF_BVM", "OFF_BAW", "OFF_CY", "OFF_CYD", "OFF_CV", "OFF_BU", "OFF_BUM"]

DEG = 24  # the Taylor polynomials' degree
NC = DEG + 1
MAXN = 16  # states of plant and controller together
GROW = 4.0
"""The kernel's longest piece, in units of ``hmax`` (where the Taylor tail allows; see :mod:`._kernel`)."""
SELF = 0.125
"""A delay at most this many times the kernel's piece length ``hmax`` is short: past its breakpoints' images, a
piece reads the delayed signal from itself (see :mod:`._kernel`), and ``hmax`` then also bounds the rates of
the loop without its delay."""

# Scalars at the start of a parameter row.
_NAMES = ("n", "ti", "to", "umin", "umax", "period", "offset", "t_end", "band", "norm", "dist", "t_dist", "dy",
          "dyd", "dvr", "dvy", "dvv", "integ", "aw", "hmax", "scale", "step", "slope", "tm")
HEAD = {name: i for i, name in enumerate(_NAMES)}
NHEAD = len(_NAMES)
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


LoopMatrices = LoopRealisation
"""A loop as the kernel's matrices (everything of a parameter row but the run's settings): the loop's closed-loop
realisation, :class:`~delaykit.models.closed_loop.LoopRealisation`."""


def loop_matrices(loop: Loop) -> LoopMatrices:
    """The kernel's matrices of a loop (at most ``MAXN`` states in all): its closed-loop realisation
    (:func:`~delaykit.models.closed_loop.loop_realisation`), with one inert state for a static plant under a
    static law (the kernel needs a state).

    Examples
    --------
    >>> from delaykit.models import Controller, Loop
    >>> m = loop_matrices(Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2))
    >>> m.npl, m.M.shape, m.integ
    (2, (4, 4), 2)
    """
    lay = loop_realisation(loop)
    n = lay.order
    if n > MAXN:
        raise InvalidValueError(
            f"the loop has {n} states (plant {lay.npl}, controller {n - lay.npl}); the simulator takes at most {MAXN}")
    if n == 0:  # a static plant and a static law: give the kernel one inert state
        z = np.zeros(1)
        lay = replace(lay, npl=1, M=np.zeros((1, 1)), bw=z, br=z, bym=z, bvm=z, baw=z, cy=z, cyd=z, cv=z, bu=z, bum=z,
                      dyd=0.0)
    return lay


def _put(row: np.ndarray, off: int, vec: np.ndarray) -> None:
    row[off:off + vec.size] = vec


def fastest_rate(lay: LoopMatrices, dvy: float, dvv: float, cv: np.ndarray, delay_free: bool) -> float:
    """The loop's fastest rate, whose reciprocal caps a piece's length (Taylor terms decay like 1/j!).

    Examples
    --------
    >>> from delaykit.models import Controller, Loop
    >>> m = loop_matrices(Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2))
    >>> fastest_rate(m, -5.5, 0.0, m.cv, False)  # the derivative filter's pole, 1 / 0.05 s
    20.0
    """
    rate = float(np.max(np.abs(np.linalg.eigvals(lay.M)))) if lay.M.size else 0.0
    rate = max(rate, abs(dvy * lay.dyd))
    if np.any(lay.bu):  # a predictor's model reads the command, u = v while it is not saturated
        rate = max(rate, float(np.max(np.abs(np.linalg.eigvals(lay.M + np.outer(lay.bu, cv))))))
    if delay_free:  # the loop's realisation with the measurement folded in (at these gains), closed by u = v = w
        f = replace(lay, dvy=dvy, dvv=dvv, cv=cv).folded()
        if abs(1.0 - f.kw) < 1e-12:
            raise InvalidValueError("the loop without delay is ill-posed: the controller's direct feedthrough "
                                    "cancels the plant's (1 + C(inf) P(inf) = 0)")
        acl = f.A + np.outer(f.b, f.k) / (1.0 - f.kw)
        rate = max(rate, float(np.max(np.abs(np.linalg.eigvals(acl)))))
    return rate


def step_rate(lay: LoopMatrices, dvy: float, dvv: float, cv: np.ndarray, delay: float, sampled: bool) -> float:
    """The rate whose reciprocal is the kernel's ``hmax``: :func:`fastest_rate`, and for a continuous loop
    whose delays are short (at most :data:`SELF` over that rate, 0 included) also the rates of the loop
    without its delays, which pieces longer than the delay see (where that loop is well posed).

    Examples
    --------
    >>> from delaykit.models import Controller, Loop
    >>> m = loop_matrices(Loop("1/(s+1)", Controller.pi(20.0, 1.0), delay=1e-6))
    >>> round(step_rate(m, -20.0, 0.0, m.cv, 1e-6, False), 2), fastest_rate(m, -20.0, 0.0, m.cv, False)
    (20.95, 20.0)
    """
    rate = fastest_rate(lay, dvy, dvv, cv, False)
    if not sampled and delay * rate <= SELF:
        if delay == 0.0:
            return fastest_rate(lay, dvy, dvv, cv, True)
        try:
            rate = max(rate, fastest_rate(lay, dvy, dvv, cv, True))
        except InvalidValueError:  # ill-posed without its delay: the delayed loop's own rate
            pass
    return rate


def param_row(loop: Loop, lay: LoopMatrices, *, step: float, slope: float, norm: float, t_end: float, band: float,
              dist: LoadStep | None) -> np.ndarray:
    """The kernel's parameter row of one run of a loop (its matrices ``lay``, the reference's first value
    ``step`` and slope, the metrics' normalisation ``norm``, the run's end and settling band, a load).

    Examples
    --------
    See the module's.
    """
    c = loop.controller
    p = np.zeros(NPAR)
    n = lay.M.shape[0]
    p[HEAD["n"]] = n
    p[HEAD["ti"]] = loop.delay
    p[HEAD["to"]] = loop.output_delay
    p[HEAD["umin"]] = loop.umin
    p[HEAD["umax"]] = loop.umax
    p[HEAD["period"]] = loop.period or 0.0
    p[HEAD["offset"]] = loop.sample_offset
    p[HEAD["t_end"]] = t_end
    p[HEAD["band"]] = band
    p[HEAD["norm"]] = norm
    p[HEAD["dist"]] = dist.size if dist is not None else 0.0
    p[HEAD["t_dist"]] = dist.arrival(loop.delay) if dist is not None else math.inf
    p[HEAD["dy"]] = lay.dy
    p[HEAD["dyd"]] = lay.dyd
    p[HEAD["dvr"]] = lay.dvr
    p[HEAD["dvy"]] = lay.dvy
    p[HEAD["dvv"]] = lay.dvv
    p[HEAD["integ"]] = lay.integ
    p[HEAD["aw"]] = AW[c.antiwindup]
    p[HEAD["hmax"]] = 1.0 / max(step_rate(lay, lay.dvy, lay.dvv, lay.cv, max(loop.delay, loop.output_delay),
                                          loop.sampled), 1e-9)
    p[HEAD["scale"]] = max(1.0, abs(lay.dvr * step), abs(norm))
    p[HEAD["step"]] = step
    p[HEAD["slope"]] = slope
    p[HEAD["tm"]] = lay.model_delay
    M = np.zeros((MAXN, MAXN))
    M[:n, :n] = lay.M
    _put(p, OFF_M, M.ravel())
    for off, vec in ((OFF_BW, lay.bw), (OFF_BR, lay.br), (OFF_BYM, lay.bym), (OFF_BVM, lay.bvm),
                     (OFF_BAW, lay.baw), (OFF_CY, lay.cy), (OFF_CYD, lay.cyd), (OFF_CV, lay.cv),
                     (OFF_BU, lay.bu), (OFF_BUM, lay.bum)):
        _put(p, off, vec)
    return p
