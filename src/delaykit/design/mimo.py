"""Decentralised PI control of a square delay system: pairing (RGA, Niederlinski index) and BLT tuning.

For a square :class:`~delaykit.systems.DelayLTI` ``G`` (``n`` outputs, ``n`` inputs, any delays):

* :func:`rga`: the relative gain array ``Lambda(jw) = G(jw) .* (G(jw)^-1)^T`` (elementwise) over frequency, from the
  exact frequency response (each delay as ``exp(-j w tau)``).
* :func:`niederlinski`: the Niederlinski index ``det G(0) / prod_i G_{i,p(i)}(0)`` of a pairing ``p``.
* :func:`blt`: Luyben's (1986) biggest-log-modulus tuning of ``n`` PI loops.  Each paired element's ultimate gain
  ``Ku`` and period ``Pu`` come from its exact frequency response (its gain margin, the least ``1/|g|`` over the
  phase crossovers, and the crossover's frequency, no Padé approximation); the Ziegler-Nichols settings
  ``Kzn = Ku / 2.2``, ``tau_zn = Pu / 1.2`` (Luyben's) are detuned by one factor ``F`` for every loop,
  ``Kc = Kzn / F``, ``tau_I = F tau_zn``; ``F`` is the root of ``L_cm(F) = 2n`` dB, where the biggest
  closed-loop log modulus is ``L_cm = max_w 20 log10 |W / (1 + W)|`` with ``W(jw) = -1 + det(I + G(jw) K(jw))``.

How ``Ku`` and ``L_cm`` are computed: ``G(jw)`` once on the grid of :func:`~delaykit.spectrum.systems.hinfnorm`
(200 points a decade across the system's features, 16 points per period of its longest delay path), up to 100
times the fastest feature (eigenvalue of ``A`` or 1/delay) rather than hinfnorm's 1000: beyond it every element
has reached its high-frequency asymptote (a strictly proper one has fallen a hundredfold past its fastest pole; one
with delays inside a loop repeats the ripple already on the grid), so no later phase crossover gives a smaller
ultimate gain and no later point a larger log modulus, and the grid is several times shorter (4,800 points for the
Wood-Berry column instead of 37,000; the same results to 1e-14).  Each
element's phase crossovers are located on it, and those whose gain estimate is within 20 % of the least are
refined by Brent's method to a relative 1e-14 in frequency (as :func:`~delaykit.spectrum.systems.loop_margins`
does for every crossover).  For ``L_cm``, the controller's
``K(jw)`` in closed form for each ``F``; the largest local maxima of ``|W / (1 + W)|`` on the grid (those within
1 dB of the largest) are refined by a bounded scalar search with ``G`` evaluated exactly, to a relative 1e-10 in
frequency.  ``F`` is the largest root the scan finds: from ``F = 1`` upwards in steps of ``2^(1/4)`` until
``L_cm`` has stayed below the target over a factor of 4 (downwards from 1 when no point reaches the target), the
bracket refined by Brent's method to a relative 1e-10.  The largest root, approached from the detuned side, is the
one on the stable side: a closed-loop pole crossing the imaginary axis makes ``L_cm`` infinite on the way (the
Ziegler-Nichols settings themselves, ``F = 1``, leave the Wood-Berry column unstable).

Examples
--------
>>> from delaykit import tf
>>> G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
...         ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]])
>>> round(niederlinski(G), 4)
0.4977
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.budget import blocks
from ..spectrum.systems import _features, _grid, is_stable
from ..systems.algebra import feedback
from ..systems.build import tf
from ..systems.lti import DelayLTI, as_frequencies

__all__ = ["rga", "niederlinski", "blt", "BLTResult"]

_STEP = 2.0 ** 0.25  # the scan's ratio between two detuning factors
_F_RANGE = (1e-4, 1e4)  # the scan gives up outside
_CONFIRM = 8  # steps of the scan below the target that end it (a factor of 4 in F)
_REFINE_DB = 1.0
_CAP_DB = 1e3  # dB: the log modulus where W / (1 + W) is infinite  # grid maxima within this of the largest are refined


def _square(G: Any, what: str) -> DelayLTI:
    if not isinstance(G, DelayLTI):
        raise InvalidTypeError(f"{what} needs a DelayLTI (made by delaykit.tf, ss, ...), got {type(G).__name__}")
    if G.ninputs != G.noutputs or G.ninputs == 0:
        raise InvalidValueError(f"{what} needs a square system with as many inputs as outputs, got {G!r}")
    return G.without_limits()


def _pairing(pairing: Any, n: int) -> tuple[int, ...]:
    """``p[i]``: the input that controls output ``i`` (the identity by default), checked to be a permutation."""
    if pairing is None:
        return tuple(range(n))
    try:
        p = tuple(pairing)
    except TypeError:
        raise InvalidTypeError(f"pairing must be a sequence of {n} input indices, got {pairing!r}") from None
    if (len(p) != n or any(isinstance(x, bool) or not isinstance(x, (int, np.integer)) for x in p)
            or sorted(int(x) for x in p) != list(range(n))):
        raise InvalidValueError(f"pairing must list the input paired with each output, a permutation of 0..{n - 1}, "
                                f"got {pairing!r}")
    return tuple(int(x) for x in p)


def rga(G: DelayLTI, w: Any) -> np.ndarray:
    """The relative gain array of a square system over frequency.

    ``Lambda(jw) = G(jw) .* (G(jw)^-1)^T`` (elementwise product), from the exact frequency response.  Each row and
    each column sums to 1.  Bristol's rule pairs output ``i`` with an input whose ``lambda_ij`` is positive and close
    to 1 at the frequencies that matter (steady state, ``w = 0``, and around the intended bandwidth); a negative
    steady-state ``lambda_ij`` means the loop ``i``-``j`` changes sign when the other loops are closed, and large
    values mean strong interaction and sensitivity to model error.

    Parameters
    ----------
    G : DelayLTI
        A square system (``n`` outputs, ``n`` inputs).
    w : array_like
        Frequencies (rad/s), finite and ``>= 0``.

    Returns
    -------
    numpy.ndarray
        Complex, shaped ``(n, n, len(w))`` as python-control's frequency responses (``lambda_ij(jw)`` at
        ``[i, j, k]``); its magnitude is what is usually plotted.

    Raises
    ------
    InvalidValueError
        For a system that is not square, or where ``G(jw)`` is singular or infinite (the frequency is named).

    See Also
    --------
    niederlinski, blt

    References
    ----------
    E. H. Bristol, "On a new measure of interaction for multivariable process control", IEEE Trans. Automatic
    Control 11(1):133-134, 1966.

    Examples
    --------
    >>> from delaykit import tf
    >>> G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
    ...         ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]])
    >>> rga(G, [0.0])[:, :, 0].real.round(4)       # Wood-Berry at steady state
    array([[ 2.0094, -1.0094],
           [-1.0094,  2.0094]])
    """
    G = _square(G, "the relative gain array")
    w = as_frequencies(w)
    h = np.moveaxis(G.evaluate(1j * w), -1, 0)  # (len(w), n, n)
    out = np.empty_like(h)
    n = h.shape[1]
    for b in blocks(w.size, 8 * n * n):  # a block of frequencies at a time: the work memory stays bounded
        m = h[b]
        bad = ~np.isfinite(m).all(axis=(1, 2))
        if bad.any():
            k = b.start + int(np.argmax(bad))
            raise InvalidValueError(f"G(jw) is infinite at w={w[k]:g} rad/s (a pole on the imaginary axis): no "
                                    "relative gain array there")
        with np.errstate(all="ignore"):
            cond = np.linalg.cond(m)
        bad = ~(cond <= 1e14)
        if bad.any():
            k = int(np.argmax(bad))
            raise InvalidValueError(f"G(jw) is singular at w={w[b.start + k]:g} rad/s (condition number "
                                    f"{cond[k]:.3g}): no relative gain array there")
        out[b] = m * np.swapaxes(np.linalg.inv(m), 1, 2)
    return np.moveaxis(out, 0, -1)


def niederlinski(G: DelayLTI, pairing: Sequence[int] | None = None) -> float:
    """The Niederlinski index ``NI = det G_p(0) / prod_i G_{i,p(i)}(0)`` of a pairing, from the steady-state gains.

    ``G_p`` is ``G`` with its columns reordered so that the paired elements lie on the diagonal (``G_p[:, i] =
    G[:, p(i)]``); for the diagonal pairing ``NI = det G(0) / prod_i G_ii(0)``.

    Interpretation (for a stable ``G`` under decentralised control with integral action in every loop, each
    controller's sign chosen so its own loop has positive gain, ``k_i G_{i,p(i)}(0) > 0``): **NI < 0** means the
    closed loop is unstable for every choice of the controllers' settings (or becomes unstable when one loop is
    opened): the pairing must not be used.  NI > 0 is necessary for stability, not sufficient; for two loops it is
    equivalent to a positive steady-state relative gain ``lambda_11 = 1 / NI``.  NI = 0 (a singular ``G(0)``) means
    the outputs cannot all be held at independent set points.

    Parameters
    ----------
    G : DelayLTI
        A square system with finite steady-state gains.
    pairing : sequence of int, optional
        ``pairing[i]`` is the input that controls output ``i`` (default: input ``i``, the diagonal).

    Returns
    -------
    float

    Raises
    ------
    InvalidValueError
        For a non-square system, an infinite steady-state gain (an integrator), a paired gain of zero, or a
        pairing that is not a permutation.

    See Also
    --------
    rga, blt

    References
    ----------
    A. Niederlinski, "A heuristic approach to the design of linear multivariable interacting control systems",
    Automatica 7:691-701, 1971; P. Grosdidier, M. Morari and B. R. Holt, "Closed-loop properties from
    steady-state gain information", Ind. Eng. Chem. Fundam. 24:221-235, 1985.

    Examples
    --------
    >>> from delaykit import tf
    >>> G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
    ...         ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]])
    >>> round(niederlinski(G), 4), round(niederlinski(G, pairing=[1, 0]), 4)   # the off-diagonal pairing fails
    (0.4977, -0.9907)
    """
    G = _square(G, "the Niederlinski index")
    p = _pairing(pairing, G.ninputs)
    g0 = G.dcgain()
    if not np.all(np.isfinite(g0)):
        raise InvalidValueError(f"the steady-state gains of {G!r} are not all finite (an integrator): the "
                                "Niederlinski index needs finite gains")
    paired = [float(g0[i, j]) for i, j in enumerate(p)]
    if any(v == 0.0 for v in paired):
        bad = [(i, j) for i, j in enumerate(p) if g0[i, j] == 0.0]
        raise InvalidValueError(f"the paired steady-state gains at (output, input) {bad} are zero: those loops have "
                                "no effect on their outputs at steady state")
    return float(np.linalg.det(g0[:, list(p)]) / np.prod(paired))  # the paired gains on the diagonal


@dataclass(frozen=True, repr=False)
class BLTResult:
    """Luyben's BLT tuning of ``n`` decentralised PI loops: loop ``i`` drives input ``pairing[i]`` from the error of
    output ``i``, ``u = kp_i (e + 1/ti_i int e dt)`` (``ki_i = kp_i / ti_i``).

    ``ku``, ``pu`` are each paired element's exact ultimate gain (signed as its steady-state gain) and period,
    ``detuning`` the factor ``F``, ``lcm`` the biggest closed-loop log modulus (dB) reached at ``frequency``
    (rad per time unit of the model), ``target_db`` what it was set to (``2n`` by default), ``zn`` the
    Ziegler-Nichols divisors of ``Ku`` and ``Pu``.  ``stable`` is the certified stability of the closed loop
    (``None`` when not checked).
    """

    detuning: float
    kp: tuple[float, ...]
    ki: tuple[float, ...]
    ti: tuple[float, ...]
    ku: tuple[float, ...]
    pu: tuple[float, ...]
    lcm: float
    frequency: float
    target_db: float
    pairing: tuple[int, ...]
    zn: tuple[float, float] = (2.2, 1.2)
    stable: bool | None = None
    inputs: tuple[str, ...] = field(default=(), compare=False)

    def controller(self) -> DelayLTI:
        """The decentralised PI controller as a :class:`~delaykit.systems.DelayLTI` from the errors
        ``e[0..n-1]`` (output ``i``'s set point minus output ``i``) to the plant's inputs, so that
        ``feedback(G * result.controller(), 1)`` is the closed loop.

        Examples
        --------
        >>> from delaykit import tf
        >>> r = blt(tf("exp(-s)/(s+1)"), check_stability=False)
        >>> r.controller()
        DelayLTI(BLT PI: 1 input ['e[0]'] -> 1 output ['u[0]'], 1 state, no delays)
        """
        return _controller(self.kp, self.ki, self.pairing, self.inputs)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"detuning": self.detuning, "kp": list(self.kp), "ki": list(self.ki), "ti": list(self.ti),
                "ku": list(self.ku), "pu": list(self.pu), "lcm_db": self.lcm, "frequency": self.frequency,
                "target_db": self.target_db, "pairing": list(self.pairing), "zn": list(self.zn),
                "stable": self.stable, "inputs": list(self.inputs)}

    def __repr__(self) -> str:
        f = lambda xs: "[" + ", ".join(f"{x:.4g}" for x in xs) + "]"  # noqa: E731
        verdict = {None: "stability not checked", True: "stable", False: "UNSTABLE"}[self.stable]
        return (f"BLTResult(F={self.detuning:.4g}, kp={f(self.kp)}, ti={f(self.ti)}, Lcm {self.lcm:.4g} dB at "
                f"w={self.frequency:.4g}, {verdict})")


def _controller(kp: Sequence[float], ki: Sequence[float], pairing: Sequence[int], inputs: Sequence[str]) -> DelayLTI:
    """The PI loops ``kp_i + ki_i / s`` from error ``i`` to input ``pairing[i]``, as one system."""
    n = len(kp)
    rows: list[list[Any]] = [[0] * n for _ in range(n)]
    for i, j in enumerate(pairing):
        rows[j][i] = ((float(kp[i]), float(ki[i])), (1.0, 0.0))
    return tf(rows, inputs=[f"e[{i}]" for i in range(n)], outputs=list(inputs) if inputs else None, name="BLT PI")


class _Loops:
    """The paired plant ``G_p`` (loop ``i``'s input ``p[i]`` as column ``i``, so the controller is diagonal) on a fixed
    frequency grid, evaluated once: each element's ultimate point and ``L_cm(F)`` for detuned PI loops."""

    def __init__(self, G: DelayLTI, pairing: tuple[int, ...]) -> None:
        self.G, self.p = G, list(pairing)
        lo, hi, _ = _features(G)
        w = _grid(G, lo, hi / 10)  # 100 times the fastest feature: see the module docstring
        self.w = w[w > 0]
        self.g = self._paired(self.w)

    def _paired(self, w: np.ndarray) -> np.ndarray:
        return np.moveaxis(self.G.evaluate(1j * np.asarray(w, float)), -1, 0)[:, :, self.p]

    def ultimate(self, i: int) -> tuple[float, float]:
        """``(Ku, Pu)`` of loop ``i``'s element under proportional control alone, ``Ku`` signed as its steady-state
        gain: the least ``1 / |g|`` over the phase crossovers (``sign * g`` real and negative), each crossover's
        frequency refined by Brent's method (those whose grid estimate is within 20 % of the least)."""
        from scipy.optimize import brentq

        j = self.p[i]
        g0 = complex(self._paired([0.0])[0, i, i]).real
        if not math.isfinite(g0):  # an integrator: the sign of g(eps) for a small real eps, which goes as k / eps
            eps = float(self.w[0])
            g0 = complex(self.G.evaluate([eps])[i, j, 0]).real
        if g0 == 0.0 or math.isnan(g0):
            raise InvalidValueError(f"the element G[{i}, {j}] has no steady-state gain ({g0:g}): it cannot be tuned by "
                                    "its ultimate point")
        sign = 1.0 if g0 > 0 else -1.0
        h = sign * self.g[:, i, i]
        ok = np.isfinite(h)
        cross = np.flatnonzero(ok[:-1] & ok[1:] & (np.sign(h.imag[:-1]) * np.sign(h.imag[1:]) < 0)
                               & (h.real[:-1] + h.real[1:] < 0))
        if not cross.size:
            raise InvalidValueError(f"the element G[{i}, {j}] has no ultimate point (its phase never reaches -180 deg, "
                                    "so proportional control never makes it oscillate): Ziegler-Nichols settings do "
                                    "not exist for it")
        est = 2.0 / (np.abs(h[cross]) + np.abs(h[cross + 1]))
        best, wu = math.inf, math.nan
        val = lambda x: sign * complex(self._paired([x])[0, i, i])  # noqa: E731
        for k in cross[est <= 1.2 * est.min()]:
            x = brentq(lambda t: val(t).imag, self.w[k], self.w[k + 1], xtol=1e-14 * self.w[k])
            v = val(x)
            if v.real < 0 and 1.0 / abs(v) < best:
                best, wu = 1.0 / abs(v), float(x)
        return sign * best, 2.0 * math.pi / wu

    def _ratio_db(self, g: np.ndarray, w: np.ndarray, kc: np.ndarray, ti: np.ndarray) -> np.ndarray:
        k = kc[None, :] * (1.0 + 1.0 / (1j * w[:, None] * ti[None, :]))  # (len(w), n)
        n = k.shape[1]
        with np.errstate(all="ignore"):
            d = np.linalg.det(np.eye(n)[None] + g * k[:, None, :])
            r = 20.0 * np.log10(np.abs((d - 1.0) / d))
        return np.where(np.isfinite(r), r, _CAP_DB)  # a closed-loop pole on the axis: an infinite peak, capped

    def lcm(self, kc: np.ndarray, ti: np.ndarray) -> tuple[float, float]:
        """``(L_cm in dB, frequency of the peak)`` of the PI loops ``kc_i (1 + 1 / (ti_i s))``."""
        from scipy.optimize import minimize_scalar

        r = self._ratio_db(self.g, self.w, kc, ti)
        i = int(np.argmax(r))
        best, where = float(r[i]), float(self.w[i])
        k = 1 + np.flatnonzero((r[1:-1] >= r[:-2]) & (r[1:-1] >= r[2:]))
        k = k[r[k] >= best - _REFINE_DB]
        for j in k[np.argsort(r[k])][::-1][:8]:
            res = minimize_scalar(lambda x: -float(self._ratio_db(self._paired([x]), np.array([x]), kc, ti)[0]),
                                  bounds=(self.w[j - 1], self.w[j + 1]), method="bounded",
                                  options={"xatol": 1e-10 * self.w[j]})
            if -res.fun > best:
                best, where = float(-res.fun), float(res.x)
        return best, where


def _bracket(excess: Any) -> tuple[float, float]:
    """``(lo, hi)`` with ``excess(lo) >= 0 > excess(hi)``, around the largest root the scan finds.

    Upwards from ``F = 1`` until ``excess`` has stayed negative for :data:`_CONFIRM` steps; the last point at or
    above the target and the next one bracket the root.  When no point from 1 upwards reaches the target, downwards
    from 1 to the first point that does.  Coming from the detuned side matters: a stable plant under ever weaker
    control stays stable until a closed-loop pole reaches the imaginary axis, where ``L_cm`` is infinite, so the
    largest root is on the stable side; a smaller one need not be.
    """
    F, e = 1.0, excess(1.0)
    above = (F, e) if e >= 0 else None
    below_run = 0 if e >= 0 else 1
    while below_run < _CONFIRM:
        F *= _STEP
        if F > _F_RANGE[1]:
            if above is None:
                break
            raise InvalidValueError(f"the biggest log modulus stays above the target up to a detuning factor of "
                                    f"{_F_RANGE[1]:g}")
        e = excess(F)
        if e >= 0:
            above, below_run = (F, e), 0
        else:
            below_run += 1
    if above is not None:
        return above[0], above[0] * _STEP
    F = 1.0
    while True:
        lower = F / _STEP
        if lower < _F_RANGE[0]:
            raise InvalidValueError(f"no detuning factor from {_F_RANGE[0]:g} to {_F_RANGE[1]:g} on the scan brings "
                                    "the biggest log modulus up to the target (ask for a smaller detune_target_db)")
        if excess(lower) >= 0:
            return lower, F
        F = lower


def _element(G: DelayLTI, i: int, j: int) -> DelayLTI:
    """``G[i, j]`` with only the states and delay channels that input ``j`` reaches and output ``i`` sees (by the
    matrices' nonzero pattern): a matrix of transfer functions realised element by element keeps every element's
    states in ``G[i, j]``, whose poles would then be the other elements' too."""
    n, m = G.nstates, G.ndelays
    # a graph on the states (0..n-1) and the delay channels (n..n+m-1): an edge k -> l when k drives l
    drive = np.zeros((n + m, n + m), bool)
    drive[:n, :n] = G.A.T != 0
    drive[n:, :n] = G.B2.T != 0
    drive[:n, n:] = G.C2.T != 0
    drive[n:, n:] = G.D22.T != 0
    src = np.concatenate([G.B1[:, j] != 0, G.D21[:, j] != 0])
    dst = np.concatenate([G.C1[i, :] != 0, G.D12[i, :] != 0])

    def closure(start: np.ndarray, M: np.ndarray) -> np.ndarray:
        seen = start.copy()
        while True:
            more = seen | M[seen].any(axis=0)
            if (more == seen).all():
                return seen
            seen = more

    keep = closure(src, drive) & closure(dst, drive.T)
    x, c = np.flatnonzero(keep[:n]), np.flatnonzero(keep[n:])
    ix = np.ix_
    return DelayLTI(G.A[ix(x, x)], G.B1[ix(x, [j])], G.B2[ix(x, c)], G.C1[ix([i], x)], G.C2[ix(c, x)],
                    G.D11[ix([i], [j])], G.D12[ix([i], c)], G.D21[ix(c, [j])], G.D22[ix(c, c)],
                    delays=[G.delays[k] for k in c])


def _check_elements(G: DelayLTI, pairing: Sequence[int]) -> None:
    """Refuse a paired element with a pole right of the imaginary axis: its ultimate point is not a gain margin
    (the element is unstable at small gains), so the Ziegler-Nichols settings and the detuning mean nothing."""
    from ..spectrum.stability import rightmost

    for i, j in enumerate(pairing):
        e = _element(G, i, j)
        if not e.nstates:
            continue
        rm = rightmost(e.characteristic())
        if rm.certified and rm.root is not None and rm.root.real > 1e-9 * max(1.0, abs(rm.root)):
            r = rm.root
            where = f"{r.real:.4g}" if r.imag == 0 else f"{r.real:.4g}{abs(r.imag):+.4g}j"
            raise InvalidValueError(f"the paired element G[{i}, {j}] is unstable (a pole at {where}): BLT tuning "
                                    "needs each paired "
                                    "element stable or integrating (its ultimate point a gain margin)")


def blt(G: DelayLTI, *, pairing: Sequence[int] | None = None, detune_target_db: float | None = None,
        zn: tuple[float, float] = (2.2, 1.2), check_stability: bool = True) -> BLTResult:
    """Luyben's biggest-log-modulus (BLT) tuning of decentralised PI control for a square delay system.

    Each loop's Ziegler-Nichols PI settings from its paired element's exact ultimate gain and period (the
    element alone, the other loops open), ``Kzn = Ku / zn[0]``, ``tau_zn = Pu / zn[1]``, then one detuning factor
    ``F`` for all loops, ``Kc = Kzn / F``, ``tau_I = F tau_zn``, chosen so that the biggest closed-loop log modulus
    ``L_cm = max_w 20 log10 |W / (1 + W)|``, ``W = -1 + det(I + G K)``, equals ``detune_target_db`` (Luyben's
    ``2n`` dB for ``n`` loops by default).  The method is in the module docstring.

    Parameters
    ----------
    G : DelayLTI
        The plant, square (``n`` outputs, ``n`` inputs), each paired element stable (or integrating) with a phase
        that reaches -180 degrees (a delay is enough).
    pairing : sequence of int, optional
        ``pairing[i]`` is the input that controls output ``i`` (default: the diagonal).  Choose it with
        :func:`rga` and :func:`niederlinski`.
    detune_target_db : float, optional
        The biggest log modulus to reach (dB, > 0); default ``2 n``.
    zn : (float, float)
        The divisors of ``Ku`` and ``Pu`` in the Ziegler-Nichols PI settings; Luyben's (2.2, 1.2) by default
        (Ziegler and Nichols' own are 0.45 Ku, that is 1/2.22, and Pu/1.2).
    check_stability : bool
        Certify the closed loop's stability (:func:`~delaykit.spectrum.systems.is_stable` of
        ``feedback(G K, I)``; about a second for a 2x2 column).  ``L_cm`` alone does not show instability.

    Returns
    -------
    BLTResult
        ``detuning``, ``kp``, ``ki``, ``ti`` (one per loop), ``ku``, ``pu``, ``lcm``, ``frequency``, ``stable``;
        ``.controller()`` is the PI controller as a system.

    Raises
    ------
    InvalidValueError
        For a non-square system, a bad pairing or target, an unstable paired element, an element without an
        ultimate point, or no detuning factor between 1e-4 and 1e4 that reaches the target.

    See Also
    --------
    rga, niederlinski, delaykit.spectrum.systems.loop_margins

    References
    ----------
    W. L. Luyben, "Simple method for tuning SISO controllers in multivariable systems", Ind. Eng. Chem. Process
    Des. Dev. 25:654-660, 1986.

    Examples
    --------
    >>> from delaykit import tf
    >>> G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
    ...         ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]])
    >>> blt(G)                              # Luyben (1986): F 2.55, Kc 0.375 and -0.075, tau_I 8.29 and 23.6 min
    BLTResult(F=2.545, kp=[0.375, -0.0754], ti=[8.286, 23.61], Lcm 4 dB at w=0.3232, stable)
    """
    G = _square(G, "BLT tuning")
    n = G.ninputs
    p = _pairing(pairing, n)
    target = 2.0 * n if detune_target_db is None else check_real("detune_target_db", detune_target_db,
                                                                  minimum=1e-6, maximum=1e3)
    if not (isinstance(zn, (tuple, list)) and len(zn) == 2):
        raise InvalidValueError(f"zn must be two divisors (of Ku and of Pu), got {zn!r}")
    a = check_real("zn[0]", zn[0], minimum=1e-6)
    b = check_real("zn[1]", zn[1], minimum=1e-6)
    _check_elements(G, p)
    loops = _Loops(G, p)
    ult = [loops.ultimate(i) for i in range(n)]
    ku = np.array([u[0] for u in ult])
    pu = np.array([u[1] for u in ult])
    kzn, tzn = ku / a, pu / b

    from scipy.optimize import brentq

    def excess(F: float) -> float:
        return loops.lcm(kzn / F, tzn * F)[0] - target

    lo, hi = _bracket(excess)
    F = float(brentq(excess, lo, hi, xtol=1e-12 * hi, rtol=1e-10))
    value, where = loops.lcm(kzn / F, tzn * F)
    kp = kzn / F
    ti = tzn * F
    ki = kp / ti
    stable = None
    if check_stability:
        try:
            stable = bool(is_stable(feedback(G * _controller(kp, ki, p, G.inputs), 1)))
        except InvalidValueError as exc:  # a neutral loop, or a rightmost root that could not be certified
            raise InvalidValueError(f"{exc}; blt(..., check_stability=False) tunes without the check") from exc
    return BLTResult(F, tuple(map(float, kp)), tuple(map(float, ki)), tuple(map(float, ti)), tuple(map(float, ku)),
                     tuple(map(float, pu)), float(value), float(where), float(target), p, (float(a), float(b)),
                     stable, G.inputs)
