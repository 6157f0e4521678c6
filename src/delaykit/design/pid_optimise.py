"""Optimisation-based tuning of P, PI, PD, PID and PV control for plants with a dead time.

Three objectives, each subject to a robustness limit on the exact frequency response (the delay as
``exp(-jwθ)``, no Padé approximation), over one plant or over a set of plants (every combination of a list of
delays and a list of gain factors: the constraint holds at every point, the objective is the worst case):

``"ki"`` (MIGO, the default)
    The largest integral gain ``ki`` (for PI and PID: the integrated error after a unit load step is ``1 / ki``
    for a stable loop) subject to ``Ms <= ms`` and optionally ``Mt <= mt`` (Astrom, Panagopoulos and Hagglund,
    1998; Astrom and Hagglund, 2006, section 7.4).  Without integral action (P, PD, PV) the largest ``kp``.
``"iae-load"``
    The least integrated absolute error after a load step at the plant input, from delaykit's exact simulation
    (with the actuator's limits), subject to the same constraint.
``"abscissa"``
    The rightmost characteristic root pushed left (certified roots, :func:`~delaykit.spectrum.stability.rightmost`),
    subject to the same constraint.

How MIGO is solved: the loop transfer function is affine in the gain ``x`` being maximised, ``L = L0 + x Lx``
(``x = ki`` with ``L0 = P (kp + derivative)``, ``Lx = P / s``; or ``x = kp``).  At each frequency the constraint
``|1 + L| >= 1/ms`` excludes an interval of ``x`` (the roots of a quadratic), and so does ``|L| <= mt |1 + L|``;
the largest admissible ``x`` reached from ``x = 0`` without crossing an excluded interval is the least lower end of
those intervals above 0 — over a dense frequency grid, then polished at the binding frequency by a bounded
one-dimensional minimisation.  On that path ``L`` never touches -1, so no closed-loop root crosses the imaginary
axis: the loop is as stable as at ``x = 0``.  The outer parameters (``kp``, and ``Td = kd / kp`` for PID) are
searched on a grid and refined (Nelder-Mead), ``kp`` only below :meth:`_Problem.kp_limit` (the P or PD loop's own
largest gain from 0), so that the loop at ``x = 0`` is itself reached from zero gain without touching -1: for a
stable or integrating plant the whole design is then stable (:func:`~delaykit.design.pid.tune` checks it by the
certified roots and enforces the exact Ms).

Examples
--------
>>> from delaykit.models.plants import integrator
>>> s = optimise("pi", [(integrator(), 0.37)], ms=1.4)
>>> round(s.kp, 3), round(s.ki, 4)
(0.762, 0.3056)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import InvalidValueError
from ..models.budget import BLOCK_ELEMENTS, MAX_GRID_POINTS, blocks, check_count
from ..models.controllers import Controller, feedback_response
from ..models.loop import Loop
from ..models.transfer import TransferFunction

__all__ = ["OBJECTIVES", "Solution", "ms_map", "load_iae", "optimise", "plant_points", "controller_of", "peak_gains",
           "controller_response"]

OBJECTIVES = ("ki", "iae-load", "abscissa")
KINDS = ("p", "pi", "pd", "pid", "pv")
MAX_PEAK = 100.0
"""The largest Ms or Mt limit the optimisation takes: a limit above it keeps ``L`` within 1 % of -1, closer than the
design's frequency grid (about 1 % apart) resolves."""

PlantPoint = tuple[TransferFunction, float]
"""One plant of a robust design: the transfer function (its gain factor applied) and its delay (s)."""


@dataclass(frozen=True, repr=False)
class Solution:
    """Optimised gains (parallel form): ``kd`` the derivative gain (pd, pid) or the velocity gain ``kv`` (pv),
    ``tf`` the derivative filter's time constant (pd, pid; 0 otherwise), ``value`` the objective reached
    (``ki`` or ``kp`` for MIGO, the worst IAE, or the worst abscissa), ``binding`` the frequency (rad/s) where the
    robustness limit binds (None when it does not bind), and ``evaluations`` how many candidates were tried."""

    kind: str
    kp: float
    ki: float
    kd: float
    tf: float
    objective: str
    value: float
    binding: float | None
    evaluations: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"kind": self.kind, "kp": self.kp, "ki": self.ki, "kd": self.kd, "tf": self.tf,
                "objective": self.objective, "value": self.value, "binding": self.binding,
                "evaluations": self.evaluations}

    def __repr__(self) -> str:
        at = "" if self.binding is None else f", binds at {self.binding:.4g} rad/s"
        return (f"Solution({self.kind} by {self.objective}: kp={self.kp:.6g}, ki={self.ki:.6g}, kd={self.kd:.6g}; "
                f"value {self.value:.6g}{at})")


def plant_points(plant: TransferFunction, delay: float, delays: Sequence[float] | None = None,
                 gains: Sequence[float] | None = None) -> list[PlantPoint]:
    """Every combination of ``delays`` (default: the nominal delay) and gain factors ``gains`` (default 1).

    Examples
    --------
    >>> [(p.to_string(), d) for p, d in plant_points(TransferFunction([1.0], [1.0, 0.0]), 0.3, [0.3, 0.4], [1, 2])]
    [('1/s', 0.3), ('2/s', 0.3), ('1/s', 0.4), ('2/s', 0.4)]
    """
    ds = [float(delay)] if delays is None else [float(d) for d in delays]
    gs = [1.0] if gains is None else [float(g) for g in gains]
    for d in ds:
        if not (math.isfinite(d) and d >= 0):
            raise InvalidValueError(f"every delay must be finite and at least 0 s, got {d:g}")
    for g in gs:
        if not (math.isfinite(g) and g > 0):
            raise InvalidValueError(f"every gain factor must be finite and above 0, got {g:g}")
    check_count(f"{len(ds)} delays x {len(gs)} gain factors", float(len(ds)) * len(gs), MAX_GRID_POINTS, "plants",
                "give fewer delays or gains")
    return [(plant if g == 1.0 else TransferFunction(plant.num * g, plant.den), d) for d in ds for g in gs]


def _values(points: Sequence[PlantPoint], w: np.ndarray) -> np.ndarray:
    """``P(jw) exp(-jw θ)`` of each point (rows) at ``w`` (columns)."""
    s = 1j * np.asarray(w, float)
    with np.errstate(all="ignore"):
        return np.array([p(s) * np.exp(-s * d) for p, d in points])


def controller_response(kind: str, kp: Any, ki: Any, kd: Any, tf: Any, s: np.ndarray) -> np.ndarray:
    """``C(s)`` of the feedback part: ``kp + ki/s + kd s/(tf s + 1)``, or ``kp + kd s`` for the PV law (``kd`` the
    velocity gain), the controller's own law (:func:`~delaykit.models.controllers.feedback_response`) for gains
    that may be arrays of one shape (leading the result's; ``tf`` one value).

    Examples
    --------
    >>> round(complex(controller_response("pid", 1.0, 0.5, 0.2, 0.02, np.array(1j))).real, 6)
    1.003998
    """
    uses = {"ki": kind in ("pi", "pid"), "kd": kind in ("pd", "pid"), "kv": kind == "pv"}
    c = Controller.make(kind, kp=1.0, **{g: 1.0 if used else 0.0 for g, used in uses.items()},
                        derivative_filter=float(tf) if uses["kd"] else None)
    return feedback_response(c, s, kp=kp, ki=ki if uses["ki"] else None, kd=kd if uses["kd"] else None,
                             kv=kd if uses["kv"] else None)


def peak_gains(L: np.ndarray) -> tuple[float, float]:
    """``(Ms, Mt)``: the peaks of ``|1/(1+L)|`` and ``|L/(1+L)|`` over every value of ``L`` given.

    Examples
    --------
    >>> peak_gains(np.array([-0.5 + 0j, 1.0 + 0j]))
    (2.0, 1.0)
    """
    with np.errstate(all="ignore"):
        d = np.abs(1.0 + L)
        ms = float(np.max(1.0 / d))
        mt = float(np.max(np.where(np.isfinite(L), np.abs(L) / d, 1.0)))
    return ms, mt


def controller_of(kind: str, kp: float, ki: float, kd: float, tf: float, **extra: Any) -> Controller:
    """The :class:`~delaykit.models.controllers.Controller` of optimised gains (``kd`` is ``kv`` for pv).

    Examples
    --------
    >>> controller_of("pid", 1.0, 0.5, 0.2, 0.02)
    Controller(pid: kp=1, ki=0.5, kd=0.2, Tf=0.02 s)
    """
    if kind == "p":
        return Controller.p(kp)
    if kind == "pv":
        return Controller.pv(kp, kd)
    if kind == "pi":
        return Controller.pi(kp, ki, **extra)
    if kind == "pd":
        return Controller.pd(kp, kd, tf)
    return Controller.pid(kp, ki, kd, tf, **extra)


# ------------------------------------------------------------------------------------------ the frequency grid
def _scales(points: Sequence[PlantPoint]) -> tuple[float, float]:
    """A time scale ``T`` (s) of the plants (their delay, else their fastest significant pole) and a gain scale
    ``K0``: ``1/|P(j/T)|``, the gain that makes ``|L| = 1`` at ``1/T``."""
    p, d = points[0]
    t = max(dd for _, dd in points)
    if t <= 0:
        mags = [abs(r) for pp, _ in points for r in np.concatenate([pp.poles(), pp.zeros()]) if abs(r) > 0]
        t = 1.0 / max(mags) if mags else 1.0
    with np.errstate(all="ignore"):
        k0 = float(np.min(1.0 / np.abs(_values(points, np.array([1.0 / t])))))
    if not (math.isfinite(k0) and k0 > 0):
        k0 = 1.0
    return t, k0


_GRID_N = 700  # frequencies of each of the grid's two base ranges


def _check_design(plants: int, frequencies: int, least: str = "") -> None:
    """Refuse a design whose plants' responses on the grid exceed :data:`~delaykit.models.budget.MAX_GRID_POINTS`
    (its work and memory grow with their number)."""
    check_count(f"a design for {plants} plants at {least}{frequencies} frequencies each", float(plants) * frequencies,
                MAX_GRID_POINTS, "plant responses", "give fewer delays or gains (a robust design's work grows with "
                "their product)")


def _grid(points: Sequence[PlantPoint], t: float, n: int = _GRID_N) -> np.ndarray:
    """Frequencies (rad/s) from 1e-4/T to 300/T, denser around 1/T, plus every pole and zero's magnitude."""
    plants = {id(pp): pp for pp, _ in points}.values()  # (the points of a robust design share their plants)
    feats = [abs(r) for pp in plants for r in np.concatenate([pp.poles(), pp.zeros()]) if abs(r) > 0]
    w = np.geomspace(1e-4 / t, 300.0 / t, n)
    extra = [np.geomspace(f / 3, f * 3, 60) for f in feats if 1e-4 / t < f < 300 / t]
    return np.unique(np.concatenate([w, np.geomspace(0.05 / t, 20.0 / t, n), *extra]))


# ----------------------------------------------------------------------------------------------- MIGO core
def _largest(a2: np.ndarray, re_a: np.ndarray, ab: np.ndarray, re_b: np.ndarray, b2: np.ndarray, ms: float,
             mt: float | None) -> tuple[np.ndarray, np.ndarray]:
    """The largest ``x >= 0`` reached from 0 with ``|1 + L| >= 1/ms`` (and ``|L| <= mt |1 + L|``) for
    ``1 + L = a + x b`` at every frequency of the last axis; ``-inf`` where ``x = 0`` already violates it.

    The arguments are real: ``|a|^2``, ``Re a``, ``Re(a conj b)``, ``Re b`` and ``|b|^2``.  Returns
    ``(x, index of the binding frequency)`` over the leading axes."""
    with np.errstate(all="ignore"):
        quads = [(b2, 2 * ab, a2 - 1.0 / ms ** 2)]
        if mt is not None:  # mt^2 |a + x b|^2 - |a - 1 + x b|^2 >= 0
            m2 = mt * mt
            quads.append(((m2 - 1) * b2, 2 * m2 * ab - 2 * (ab - re_b), m2 * a2 - (a2 - 2 * re_a + 1.0)))
        low, bad = None, None
        for qa, qb, qc in quads:  # excluded: qa x^2 + qb x + qc < 0 (qa > 0), between the roots
            disc = qb * qb - 4 * qa * qc
            sq = np.sqrt(np.maximum(disc, 0.0))
            hi = (-qb + sq) / (2 * qa)
            lo = np.where((disc > 0) & (hi > 0) & np.isfinite(hi), (-qb - sq) / (2 * qa), np.inf)
            b_ = np.any(lo <= 0, axis=-1)
            low, bad = (lo, b_) if low is None else (np.minimum(low, lo), bad | b_)
    idx = np.argmin(low, axis=-1)
    x = np.take_along_axis(low, idx[..., None], axis=-1)[..., 0]
    return np.where(bad, -np.inf, x), idx


class _Problem:
    """The plants' frequency responses on the grid and the parametrisation of one controller structure."""

    def __init__(self, kind: str, points: Sequence[PlantPoint], ms: float, mt: float | None, filter_ratio: float):
        self.kind, self.points, self.ms, self.mt, self.n = kind, list(points), ms, mt, filter_ratio
        _check_design(len(self.points), 2 * _GRID_N, "at least ")  # (the grid has at least 2 * _GRID_N)
        self.t, self.k0 = _scales(self.points)
        self.w = _grid(self.points, self.t)
        _check_design(len(self.points), self.w.size)
        self.s = 1j * self.w
        self.P = _values(self.points, self.w)  # (points, w)
        self.evaluations = 0


    def tf_of(self, td: float) -> float:
        """The derivative filter's time constant ``Td / N`` (a small one, ``T / 1000``, when ``Td = 0``)."""
        return td / self.n if td > 0 else self.t / 1000.0

    def shape(self, td: np.ndarray | float) -> np.ndarray:
        """``D(s)``, the controller's shape without ``kp`` and ``ki``: ``1 + Td s/(Td s/N + 1)`` (pd, pid),
        ``1 + Td s`` (pv: ``Td = kv/kp``), 1 otherwise; broadcast ``(..., w)``."""
        td = np.asarray(td, float)[..., None]
        if self.kind in ("pd", "pid"):
            tf = np.where(td > 0, td / self.n, 1.0)
            return 1.0 + td * self.s / (tf * self.s + 1.0)
        if self.kind == "pv":
            return 1.0 + td * self.s
        return np.ones_like(td) * np.ones_like(self.s)

    def best_x(self, kp: np.ndarray, td: np.ndarray, P: np.ndarray | None = None, s: np.ndarray | None = None,
               integral: bool | None = None) -> tuple[np.ndarray, np.ndarray]:
        """MIGO's objective at outer parameters ``(kp, td)`` (arrays of one shape): the largest ki (pi, pid) or
        kp (p, pd, pv; ``kp`` ignored), and the flat index of the binding (point, frequency).  With
        ``integral=False`` the largest kp of the structure without its integral (:meth:`kp_limit`)."""
        if integral is None:
            integral = self.kind in ("pi", "pid")
        P = self.P if P is None else P
        s = self.s if s is None else s
        kp, td = np.broadcast_arrays(np.asarray(kp, float), np.asarray(td, float))
        self.evaluations += kp.size
        per = 16 * P.size  # the work arrays of one outer point (a dozen of the plants' responses' size)
        if kp.ndim and kp.size > 1 and kp.size * per > BLOCK_ELEMENTS:  # in blocks: the memory stays bounded
            x, idx = np.empty(kp.shape), np.empty(kp.shape, dtype=np.intp)
            fk, ft, fx, fi = kp.ravel(), td.ravel(), x.reshape(-1), idx.reshape(-1)
            for b in blocks(kp.size, per):
                fx[b], fi[b] = self._best_x(fk[b], ft[b], P, s, integral)
            return x, idx
        return self._best_x(kp, td, P, s, integral)

    def _best_x(self, kp: np.ndarray, td: np.ndarray, P: np.ndarray, s: np.ndarray,
                integral: bool) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`best_x` at outer parameters of one shape, all at once."""
        tdx = td[..., None]
        if self.kind in ("pd", "pid"):
            d = 1.0 + tdx * s / (np.where(tdx > 0, tdx / self.n, 1.0) * s + 1.0)
        elif self.kind == "pv":
            d = 1.0 + tdx * s
        else:
            d = np.ones(td.shape + s.shape)
        q = P * d[..., None, :]  # (..., points, w): P D
        if integral:  # 1 + L = (1 + kp P D) + ki P / s
            bc = (P / s).conj()
            k = kp[..., None, None]
            rq = q.real
            a2 = 1.0 + 2 * k * rq + k * k * (q.real ** 2 + q.imag ** 2)
            re_a = 1.0 + k * rq
            ab = bc.real + k * (q * bc).real
            re_b, b2 = bc.real, bc.real ** 2 + bc.imag ** 2
        else:  # 1 + L = 1 + kp P D
            a2 = re_a = 1.0
            ab = re_b = q.real
            b2 = q.real ** 2 + q.imag ** 2
        shape = q.shape[:-2] + (-1,)  # points and frequencies: one axis
        flat = lambda z: np.broadcast_to(z, q.shape).reshape(shape)  # noqa: E731
        return _largest(flat(a2), flat(re_a), flat(ab), flat(re_b), flat(b2), self.ms, self.mt)

    def kp_limit(self, td: np.ndarray | float) -> np.ndarray:
        """The largest ``kp`` reached from 0 at ``ki = 0`` within the limits, for each ``td``: the outer gains of a
        PI or PID are admissible only below it.  On the path from ``kp = 0`` (a stable or integrating plant, stable
        at small gains) ``L`` never touches -1, and then on the path in ``ki`` neither: the loop stays stable.  Above
        it the P or PD loop may encircle -1 while keeping its distance, unstable with an acceptable Ms on the grid."""
        return self.best_x(np.zeros(np.shape(td)), np.asarray(td, float), integral=False)[0]

    def polish(self, kp: float, td: float) -> tuple[float, float | None]:
        """:meth:`best_x` at one point, the binding frequency refined by a bounded scalar minimisation of the
        excluded interval's lower end between the neighbouring grid frequencies (of every point whose grid
        minimum is within 10 % of the least)."""
        from scipy.optimize import minimize_scalar

        x, idx = self.best_x(np.array(kp), np.array(td))
        x = float(x)
        if not math.isfinite(x) or x <= 0:
            return x, None
        nw = self.w.size
        i_pt, i_w = divmod(int(idx), nw)
        best, where = x, float(self.w[i_w])
        for j in range(max(0, i_w - 1), min(nw - 1, i_w + 1)):
            lo, hi = self.w[j], self.w[j + 1]

            def f(w: float) -> float:
                ww = np.array([w])
                v = _values([self.points[i_pt]], ww)
                xx, _ = self.best_x(np.array(kp), np.array(td), v, 1j * ww)
                return float(xx) if np.isfinite(xx) else 1e300

            r = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-12 * hi})
            if r.fun < best:
                best, where = float(r.fun), float(r.x)
        return best, where


def _outer_grid(pb: _Problem) -> tuple[np.ndarray, np.ndarray]:
    """The outer parameters' grid: ``kp`` (pi, pid; rows below :meth:`_Problem.kp_limit` of each ``Td``, shape
    ``(Td, kp)``) and ``Td`` (pd, pid, pv)."""
    tds = (np.concatenate([[0.0], np.geomspace(1e-2, 8.0, 27 if pb.kind != "pid" else 16)]) * pb.t
           if pb.kind in ("pd", "pid", "pv") else np.zeros(1))
    if pb.kind not in ("pi", "pid"):
        return np.zeros((tds.size, 1)), tds
    lim = pb.kp_limit(tds)
    n = 121 if pb.kind == "pi" else 36
    lo = 1e-3 * pb.k0
    kps = np.array([np.geomspace(min(lo, 0.5 * k), k * (1 - 1e-9), n) if np.isfinite(k) and k > 0
                    else np.full(n, np.nan) for k in lim])
    return kps, tds


def _migo(pb: _Problem) -> tuple[float, float, float, float | None]:
    """``(kp, ki, td, binding frequency)`` of the MIGO design (``ki`` 0 without integral action)."""
    from scipy.optimize import minimize, minimize_scalar

    kps, tds = _outer_grid(pb)
    K, D = kps, np.broadcast_to(tds[:, None], kps.shape)
    with np.errstate(invalid="ignore"):
        x, _ = pb.best_x(np.nan_to_num(K, nan=0.0), D)
    unbounded = (pb.kind in ("pi", "pid") and not np.isfinite(K).any()) or np.isposinf(x).all()
    if unbounded:
        raise InvalidValueError(
            f"the {pb.kind} gains have no largest value: the loop keeps Ms <= {pb.ms:g}"
            + (f" and Mt <= {pb.mt:g}" if pb.mt else "") + " however large its proportional gain (these plants' "
            "phase never reaches -180 degrees: no delay); give the plant's delay, even a small one")
    x = np.where(np.isfinite(K), x, -np.inf)
    if not np.isfinite(x).any() or np.nanmax(x) <= 0:
        raise InvalidValueError(
            f"no {pb.kind} gains meet Ms <= {pb.ms:g}" + (f" and Mt <= {pb.mt:g}" if pb.mt else "")
            + " for these plants (try a larger --ms or another controller)")
    i, j = np.unravel_index(int(np.argmax(x)), x.shape)
    integral = pb.kind in ("pi", "pid")
    if pb.kind == "pi":  # one outer parameter: a bounded search between the grid neighbours
        lo, hi = K[0, max(j - 1, 0)], K[0, min(j + 1, K.shape[1] - 1)]
        r = minimize_scalar(lambda k: -float(pb.best_x(np.array(k), np.array(0.0))[0]), bounds=(lo, hi),
                            method="bounded", options={"xatol": 1e-10 * hi})
        kp, td = float(r.x), 0.0
    elif pb.kind in ("pid", "pd", "pv"):
        def f(v: np.ndarray) -> float:
            t = math.exp(v[-1])
            k = math.exp(v[0]) if integral else 0.0
            if integral and not k < float(pb.kp_limit(t)):
                return 1e300  # beyond the P/PD loop's own limit: not reached from zero gain
            val = float(pb.best_x(np.array(k), np.array(t))[0])
            return -val if math.isfinite(val) else 1e300

        td0 = D[i, j] if D[i, j] > 0 else tds[1]
        v0 = np.log([K[i, j], td0] if integral else [td0])
        r = minimize(f, v0, method="Nelder-Mead", options={"xatol": 1e-7, "fatol": 1e-12, "maxiter": 400})
        kp = math.exp(r.x[0]) if integral else 0.0
        td = math.exp(r.x[-1])
        if -r.fun < x[i, j]:  # the grid point itself (Td = 0 may be best)
            kp, td = float(K[i, j]), float(D[i, j])
    else:
        kp, td = 0.0, 0.0
    if td < 1e-4 * pb.t:
        td = 0.0  # a vanishing derivative is none (its filter would be vanishingly fast)
    best, where = pb.polish(kp, td)
    if integral:
        return kp, best, td, where
    return best, 0.0, td, where


# ------------------------------------------------------------------------------------------ other objectives
def _iae(response: Any, t_end: float, ref: float = 0.0) -> float:
    """``∫ |ref - y| dt`` up to ``t_end`` (the error after a step of the reference to ``ref``, or after a load step
    with ``ref = 0``), exactly: each polynomial piece of the exact solution integrated by its antiderivative,
    split at the roots of the error inside it."""
    coeffs = response.coeffs[response.starts < t_end].copy()  # coeffs[:, j] multiplies x^j, x in [0, 1]
    lengths = response.lengths[response.starts < t_end]
    coeffs[:, 0] = ref - coeffs[:, 0]
    coeffs[:, 1:] = -coeffs[:, 1:]
    j = np.arange(coeffs.shape[1])
    anti = coeffs / (j + 1)  # the antiderivative's coefficients of x^(j+1)

    def prim(rows: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.sum(anti[rows] * x[..., None] ** (j + 1), axis=-1)

    x = np.linspace(0.0, 1.0, 33)
    vals = coeffs @ x[None, :] ** j[:, None]
    whole = np.sum(anti, axis=1)  # the integral over [0, 1]
    change = np.any(np.sign(vals[:, :-1]) * np.sign(vals[:, 1:]) < 0, axis=1)
    total = np.abs(whole)
    for i in np.flatnonzero(change):
        r = np.roots(coeffs[i, ::-1][np.argmax(coeffs[i, ::-1] != 0):]) if np.any(coeffs[i, 1:]) else np.zeros(0)
        r = np.sort(r.real[(np.abs(r.imag) <= 1e-12) & (r.real > 0) & (r.real < 1)])
        edges = np.concatenate([[0.0], r, [1.0]])
        p = prim(np.full(edges.size, i), edges)
        total[i] = np.sum(np.abs(np.diff(p)))
    return float(np.sum(total * lengths))


def load_iae(loop: Loop, size: float, t_end: float) -> float:
    """The integrated absolute error after a load step of ``size`` at the plant input at t = 0 (exact simulation).

    Examples
    --------
    >>> loop = Loop("1/s", Controller.pi(1.0, 0.25), delay=0.37)
    >>> round(load_iae(loop, 1.0, 80.0), 3)        # 1/ki for a stable loop with integral action
    4.0
    """
    from ..models.signals import LoadStep
    from ..simulate.simulation import simulate

    r = simulate(loop, 0.0, disturbance=LoadStep(size), t_end=t_end)
    return _iae(r, t_end)


def _search(pb: _Problem, start: tuple[float, float, float], cost: Callable[[float, float, float], float]
            ) -> tuple[float, float, float, float]:
    """Nelder-Mead from ``start`` = (kp, ki, td) over the admissible set itself: the outer parameters (``log kp``
    for pi and pid, ``log Td`` for pd, pid and pv) and the fraction ``f = min(1, e^v)`` of the largest admissible
    gain (:meth:`_Problem.best_x`), so that every candidate meets the robustness limit on the grid; a candidate at
    ``f = 1`` is polished like MIGO's.  Returns (kp, ki, td, cost)."""
    from scipy.optimize import minimize

    integral = pb.kind in ("pi", "pid")
    deriv = pb.kind in ("pd", "pid", "pv")
    kp0, ki0, td0 = start
    if deriv and td0 <= 0:
        td0 = 0.05 * pb.t

    def unpack(v: np.ndarray) -> tuple[float, float, float, bool]:
        k = math.exp(v[0]) if integral else 0.0
        td = math.exp(v[int(integral)]) if deriv else 0.0
        f = min(1.0, math.exp(v[-1]))
        if integral and not k < float(pb.kp_limit(td)):
            return k, 0.0, td, False  # beyond the P/PD loop's own limit: not reached from zero gain
        x = float(pb.best_x(np.array(k), np.array(td))[0])
        if not (math.isfinite(x) and x > 0):
            return k, 0.0, td, False
        return (k, f * x, td, True) if integral else (f * x, 0.0, td, True)

    def f(v: np.ndarray) -> float:
        kp, ki, td, ok = unpack(v)
        if not ok:
            return 1e12
        pb.evaluations += 1
        return cost(kp, ki, td)

    v0 = ([math.log(kp0)] if integral else []) + ([math.log(td0)] if deriv else []) + [0.0]
    r = minimize(f, np.array(v0), method="Nelder-Mead",
                 options={"xatol": 1e-4, "fatol": 1e-9, "maxiter": 80 * len(v0)})
    kp, ki, td, _ = unpack(r.x)
    if deriv and td < 1e-4 * pb.t:
        td = 0.0
        kp, ki, td, _ = unpack(np.concatenate([r.x[:int(integral)], [-np.inf], r.x[-1:]]))
    if r.x[-1] >= -1e-3:  # on the limit: the binding frequency polished, as MIGO's
        x, _ = pb.polish(kp, td)
        kp, ki = (kp, x) if integral else (x, ki)
    return kp, ki, td, float(r.fun)


def optimise(kind: str, points: Sequence[PlantPoint], *, ms: float = 1.4, mt: float | None = None,
             objective: str = "ki", filter_ratio: float = 10.0, umin: float = -math.inf, umax: float = math.inf,
             load: float = 1.0, t_end: float | None = None) -> Solution:
    """Optimal gains of a structure for one plant or a set of plants (see the module docstring).

    Parameters
    ----------
    kind : {"p", "pi", "pd", "pid", "pv"}
    points : list of (TransferFunction, delay)
        The plants (:func:`plant_points`); the robustness limit holds at each, the objective is the worst case.
    ms, mt : float
        Limits on the peak sensitivity and (optionally) complementary sensitivity, both above 1.
    objective : {"ki", "iae-load", "abscissa"}
    filter_ratio : float
        ``N`` of the derivative filter ``Tf = Td / N`` (pd, pid).
    umin, umax, load, t_end
        The actuator's limits, the load step and the simulation's length for ``"iae-load"``.

    Returns
    -------
    Solution

    References
    ----------
    .. [1] K. J. Astrom, H. Panagopoulos and T. Hagglund, "Design of PI controllers based on non-convex
       optimization", *Automatica* 34 (1998) 585-601.
    .. [2] K. J. Astrom and T. Hagglund, *Advanced PID Control*, ISA, 2006, sections 7.4 (MIGO).

    Examples
    --------
    >>> from delaykit.models.plants import first_order
    >>> s = optimise("pi", plant_points(first_order(1.0, 1.0), 1.0), ms=1.4)
    >>> round(s.ki, 3) > 0, s.objective
    (True, 'ki')
    """
    if kind not in KINDS:
        raise InvalidValueError(f"the optimiser tunes {', '.join(KINDS)} controllers; got {kind!r}")
    if objective not in OBJECTIVES:
        raise InvalidValueError(f"objective must be one of {', '.join(OBJECTIVES)}; got {objective!r}")
    if objective == "iae-load" and kind not in ("pi", "pid"):
        raise InvalidValueError(f"the iae-load objective needs integral action (pi or pid): a {kind} controller "
                                "leaves a steady error after a load step, so its IAE grows without bound")
    if kind in ("pv",) and any(not p.is_strictly_proper for p, _ in points):
        raise InvalidValueError("the PV law needs a strictly proper plant")
    for name, peak in (("ms", ms), ("mt", mt)):
        if peak is not None and not peak <= MAX_PEAK:
            raise InvalidValueError(f"{name} must be at most {MAX_PEAK:g}, got {peak:g}: a larger limit lets the loop "
                                    "pass within 1 % of instability, closer than the design's frequency grid resolves")
    for p, d in points:
        unstable = [complex(r) for r in p.poles() if r.real > 1e-9 * max(1.0, abs(r))]
        if unstable:
            r = max(unstable, key=lambda z: z.real)
            where = f"{r.real:.4g}" if r.imag == 0 else f"{r.real:.4g}{abs(r.imag):+.4g}j"
            raise InvalidValueError(
                f"the plant {p.to_string(times=' ')} is unstable (a pole at {where}): "
                "the optimisation grows the gains from zero, where the loop must be stable, so it tunes stable and "
                "integrating plants only")
    pb = _Problem(kind, points, ms, mt, filter_ratio)
    kp, ki, td, where = _migo(pb)
    if objective == "ki":
        value = ki if kind in ("pi", "pid") else kp
        return Solution(kind, kp, ki, kp * td, pb.tf_of(td) if kind in ("pd", "pid") else 0.0, objective, value,
                        where, pb.evaluations)
    if objective == "iae-load":
        horizon = t_end if t_end is not None else 12.0 * (kp / ki + pb.t)

        def cost(kp_: float, ki_: float, td_: float) -> float:
            c = controller_of(kind, kp_, ki_, kp_ * td_, pb.tf_of(td_))
            worst = 0.0
            for p, d in pb.points:
                v = load_iae(Loop(p, c, delay=d, umin=umin, umax=umax), load, horizon)
                worst = max(worst, v if math.isfinite(v) else 1e5)
            return worst
    else:
        from ..spectrum.stability import rightmost

        def cost(kp_: float, ki_: float, td_: float) -> float:
            c = controller_of(kind, kp_, ki_, kp_ * td_, pb.tf_of(td_))
            return max(rightmost(Loop(p, c, delay=d)).abscissa for p, d in pb.points)

    start_cost = cost(kp, ki, td)
    kp2, ki2, td2, val = _search(pb, (kp, ki, td), cost)
    if val > start_cost:
        kp2, ki2, td2, val = kp, ki, td, start_cost
    return Solution(kind, kp2, ki2, kp2 * td2, pb.tf_of(td2) if kind in ("pd", "pid") else 0.0, objective, val,
                    None, pb.evaluations)


def ms_map(loop: Loop, kps: Any, kis: Any) -> np.ndarray:
    """The peak sensitivity of ``loop`` with its PI gains replaced by each ``(kp, ki)`` (rows ``ki``, columns ``kp``),
    on the dense grid of :func:`optimise` (``inf`` where ``1 + L`` vanishes on it); stability is not judged here
    (:func:`~delaykit.spectrum.stability.stability_map` does).

    Examples
    --------
    >>> loop = Loop("1/s", Controller.pi(0.76, 0.31), delay=0.37)
    >>> ms_map(loop, [0.7624137], [0.3055775]).round(4).tolist()
    [[1.4]]
    """
    kps, kis = np.asarray(kps, float).ravel(), np.asarray(kis, float).ravel()
    check_count(f"a map of {kps.size} x {kis.size} values", float(kps.size) * kis.size, MAX_GRID_POINTS, "loops",
                "map fewer values")
    pts = [(loop.plant, loop.total_delay)]
    t, _ = _scales(pts)
    w = _grid(pts, t)
    P = _values(pts, w)[0]
    s = 1j * w
    out = np.empty((kis.size, kps.size))
    with np.errstate(all="ignore"):
        for i, ki in enumerate(kis):
            L = P * (kps[:, None] + ki / s)
            out[i] = np.max(1.0 / np.abs(1.0 + L), axis=1)
    return out
