"""Exact stability of sampled delay loops: zero-order hold, any delay (not only multiples of the period).

With ``period`` set, delaykit's loop samples the controller's output ``v`` at ``t_k = offset + k h`` and holds
the command ``u_k`` until the next sample; the controller's own states (an integrator, the derivative filter of
the PV law, a PD/PID derivative filter, any transfer function's states) run in *continuous* time on the
continuous measurement, exactly as the simulator (:mod:`delaykit.simulate`) runs them, and a sample reads the
left limits of the measured output and velocity.  Saturation ignored, this loop is, from sample to sample, a
linear discrete-time system, and this module builds it exactly.

The lifted state.  Fold the output delay into the input delay (the controller sees only
``ym(t) = y(t - To)``, which is the output of the plant state ``x(t - To)`` driven by ``u(t - Ti - To)``), and
write the total delay ``T = Ti + To = m h + f`` with ``0 <= f < h``.  Over ``[t_k, t_k + f)`` the plant's input
is the command ``u_{k-m-1}``, over ``[t_k + f, t_{k+1})`` it is ``u_{k-m}``; a sample at ``t_k`` sees the
left limit, input ``u_{k-m-1}``.  The state at ``t_k``,

    ``z_k = [x(t_k - To), xc(t_k), u_{k-1}, ..., u_{k-p}]``

(plant, controller, then ``p`` held commands: ``p = m + 1``, or ``m`` when ``f = 0`` and the sample does not
read the plant's input, i.e. no direct feedthrough and no true velocity of a plant of relative degree one),
obeys ``z_{k+1} = Phi z_k``.  With ``xi = [x; xc]``, ``xi' = F xi + G w`` on each piece,

    ``xi_{k+1} = E xi_k + G1 u_{k-m-1} + G2 u_{k-m}``,  ``E = e^{F h}``,
    ``G1 = e^{F (h - f)} int_0^f e^{F s} ds G``,  ``G2 = int_0^{h - f} e^{F s} ds G``,

with the integrals from the exponential of an augmented matrix (Van Loan, 1978), and the command
``u_k = K z_k`` (``v = Cc xc + dvy ym + dvv vm`` at the left limits).  ``Phi``'s eigenvalues are the loop's
poles in the z-plane; ``|z| < 1`` for all of them is asymptotic stability.  ``det(zI - Phi)`` is, up to
factors ``z``, the characteristic polynomial of the modified z-transform (Åström & Wittenmark, ch. 2).

**A compensator** (a Smith predictor, predictor feedback) also reads the held command ``u_k`` and the command
one model delay ``Tm = mm h + fm`` ago: its states run on ``u_k`` over the whole period and on ``u_{k-mm-1}``
then ``u_{k-mm}`` (switching at ``fm``), so the period is cut at both ``f`` and ``fm`` and enough commands are
held for the longer delay.  Its history states (``p = int_{t-Tm}^t u`` and, for predictor feedback, its weighted
form) make invariants that no history of commands excites: one eigenvalue 1 each, which no plant gain and no
plant delay moves, removed exactly from the poles (:meth:`SampledModel.poles`) as the continuous loop's
structural roots at ``s = 0`` are.  The loop is broken at the plant's input, after the branch where the
compensator reads its command: ``L(e^{j w h})`` runs from the plant's held input back to it, and the plant's
column of the model (``a_plant``...) is what a plant gain scales, so the margins
(:mod:`.discrete_margins`) mean what the continuous compensated margins (:mod:`.compensated`) mean.

The **sampling offset does not change stability**: moving the first sample only shifts the sampling grid in
time, and what happens before the first sample is an initial condition, so ``Phi`` is the same for every offset.

A delay within ``1e-9 h`` of a multiple of the period is taken as that multiple (the simulator, too, merges a
command change and a sample that coincide to rounding, the sample reading the command before the change).

Examples
--------
>>> from delaykit import AltitudeLoop
>>> sampled_spectrum(AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", period=0.065))
SampledSpectrum(h=0.065 s, 9 poles, radius 0.888439 (rate -1.8198/s), dominant 0.8451+0.2741j, stable)

References
----------
K. J. Åström, B. Wittenmark, *Computer-Controlled Systems*, 3rd ed., Prentice Hall, 1997, sec. 2.3 (sampling
a system with a time delay; the modified z-transform).
C. F. Van Loan, "Computing integrals involving the matrix exponential", IEEE Trans. Automatic Control 23(3),
1978, pp. 395-404.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError
from ..models.altitude import AltitudeLoop, as_loop
from ..models.closed_loop import loop_realisation
from ..models.hold import hold_matrices, split_delay
from ..models.loop import Loop
from .frequency import FrequencyResponse

__all__ = ["SampledModel", "SampledSpectrum", "SampledCrossover", "SampledMargins", "SamplingComparison",
           "sampled_model", "sampled_spectrum", "sampled_frequency_response", "sampled_response", "sampled_margins",
           "compare_sampling", "MAX_ORDER"]

MAX_ORDER = 2000
"""The largest lifted state (plant + controller + held commands) built; a longer delay-to-period ratio is refused."""

_MARGINS = ("SampledCrossover", "SampledMargins", "SamplingComparison", "sampled_margins", "compare_sampling")


def __getattr__(name: str) -> Any:
    """The margins, kept importable from here: they live in :mod:`.discrete_margins`, which builds on this module."""
    if name in _MARGINS:
        from . import discrete_margins

        return getattr(discrete_margins, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _sampled_loop(loop: Any, what: str) -> Loop:
    lp = as_loop(loop)
    if not lp.sampled:
        raise InvalidValueError(
            f"{what} needs a sampled loop (period set, in s); this loop is continuous (period=None): use "
            "delaykit.spectrum.stability.rightmost for its roots, or give it a period")
    return lp


def _period_transition(F: np.ndarray, G: np.ndarray, Gr: np.ndarray, h: float, m: int, f: float, N: int,
                       model: tuple[np.ndarray, np.ndarray, int, float] | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``xi_{k+1} = X [z_k; u_k] + xr r`` over one period, piece by piece with the inputs held on each piece, and
    ``Xp``, the part of ``X`` that comes in through the plant's input column ``G`` (linear in it).

    The plant's input is ``u_{k-m-1}`` before ``f`` and ``u_{k-m}`` after it.  With ``model = (Gu, Gm, mm, fm)``
    (a compensator) the controller's states also read ``u_k`` throughout and the model's delayed command,
    ``u_{k-mm-1}`` before ``fm`` and ``u_{k-mm}`` after it, so the period is cut at ``fm`` too."""
    nx = F.shape[0]
    X = np.zeros((nx, N + 1))
    X[:, :nx] = np.eye(nx)
    Xp = np.zeros((nx, N + 1))
    xr = np.zeros(nx)

    def sel(j: int) -> np.ndarray:  # the command u_{k-j} as a row over [z_k; u_k]
        e = np.zeros(N + 1)
        e[N if j == 0 else nx + j - 1] = 1.0
        return e

    cols = [G, Gr] if model is None else [G, Gr, model[0], model[1]]
    GG = np.column_stack(cols) if nx else np.zeros((0, len(cols)))
    edges = sorted({0.0, f, h} | (set() if model is None else {model[3]}))
    for a, b in zip(edges[:-1], edges[1:]):
        E, J = hold_matrices(F, GG, b - a)
        plant = np.outer(J[:, 0], sel(m + 1 if a < f else m))
        X = E @ X + plant
        Xp = E @ Xp + plant
        xr = E @ xr + J[:, 1]
        if model is not None:
            mm, fm = model[2], model[3]
            X += np.outer(J[:, 2], sel(0)) + np.outer(J[:, 3], sel(mm + 1 if a < fm else mm))
    return X, xr, Xp


# -- the exact discrete-time model -----------------------------------------------------------------------
@dataclass(frozen=True, repr=False, eq=False)
class SampledModel:
    """The linearised sampled loop as a discrete-time system over one period (see the module docstring).

    The state is ``z_k = [x(t_k - To), xc(t_k), u_{k-1}, ..., u_{k-p}]`` (``n_plant``, ``n_controller`` and
    ``n_held = p`` entries).  Open at the command: ``z_{k+1} = a_open z_k + b_open u_k`` and ``v_k = k_row z_k``;
    closed (``u_k = v_k``): ``z_{k+1} = phi z_k + b_ref r`` for a reference ``r`` constant over the period
    (``phi = a_open + b_open k_row``).  ``total_delay = whole_periods * period + fraction``.

    ``a_plant``, ``b_plant`` and ``k_plant`` are the parts of ``a_open``, ``b_open`` and ``k_row`` that come
    through the plant's input (the held commands as the plant reads them, and the sample's direct dependence on
    the plant's input); the rest is the controller's own reading of its command (a compensator's model).
    ``structural`` is the number of a compensator's eigenvalues at 1 (see :meth:`poles`); ``compensated`` is
    True for a controller that reads its own command.
    """

    period: float
    total_delay: float
    whole_periods: int
    fraction: float
    n_plant: int
    n_controller: int
    n_held: int
    phi: np.ndarray
    a_open: np.ndarray
    b_open: np.ndarray
    k_row: np.ndarray
    b_ref: np.ndarray
    structural: int = 0
    a_plant: np.ndarray | None = None
    b_plant: np.ndarray | None = None
    k_plant: np.ndarray | None = None
    compensated: bool = False

    @property
    def order(self) -> int:
        """Size of the lifted state."""
        return int(self.phi.shape[0])

    def closed(self, gain: float = 1.0) -> np.ndarray:
        """The one-period transition matrix with the loop, broken at the plant's input, scaled by ``gain``.

        Without a compensator that is the command scaled, ``u_k = gain v_k`` (the same poles as the plant's
        input scaled).  With one, only the plant's input is scaled: the plant reads ``gain u`` while the
        compensator's model reads the command ``u`` itself, which is a plant gain ``gain`` times the model's.

        Examples
        --------
        >>> mdl = sampled_model(Loop("1/s", delay=0.0, period=0.1))         # P control, Kp = 1: z = 1 - g h
        >>> mdl.closed(3.0).round(12).tolist()
        [[0.7]]
        """
        if not self.compensated or self.a_plant is None:
            return self.a_open + gain * np.outer(self.b_open, self.k_row)
        d = float(gain) - 1.0
        return (self.a_open + d * self.a_plant) + np.outer(self.b_open + d * self.b_plant,
                                                           self.k_row + d * self.k_plant)

    def poles(self, gain: float = 1.0) -> np.ndarray:
        """The loop's poles (z-plane) at the loop gain ``gain`` (see :meth:`closed`), unsorted.

        For a compensated loop the ``structural`` eigenvalues at 1 of the transition matrix are not poles: they
        belong to invariants of the compensator's history states that the loop never excites (a model's window
        integral ``int_{t-Tm}^t u`` is fixed by the commands held, whatever the plant does), the sampled image
        of the continuous loop's structural roots at ``s = 0``.  They are removed exactly, not by distance from
        1: the part of the lifted state that the plant's input reaches, and that reaches it back, is
        separated once from the modes that no plant gain or plant delay moves (orthonormal Krylov bases of the
        model's plant-input matrices, :func:`_fixed_modes`); the poles are that part's eigenvalues at ``gain``
        and the fixed modes other than the structural ones.

        Examples
        --------
        >>> from delaykit.models.compensators import Compensator
        >>> smith = Compensator.smith("1/s", 0.37, closed_loop_time=0.2)
        >>> mdl = sampled_model(Loop("1/s", smith, delay=0.37, period=0.065))
        >>> mdl.order, mdl.structural, mdl.poles().size          # the eigenvalue 1 of the model's window removed
        (8, 1, 7)
        >>> round(mdl.radius(), 12), round(mdl.radius(2.0), 6)   # 1 - Kc h; the plant's gain doubled
        (0.675, 0.957366)
        """
        M = self.closed(gain)
        if not self.compensated or self.a_plant is None:
            return np.linalg.eigvals(M) if M.size else np.zeros(0, complex)
        basis, fixed = self._deflation
        red = basis.T @ M @ basis
        z = np.linalg.eigvals(red) if red.size else np.zeros(0, complex)
        return np.concatenate([z.astype(complex), fixed.astype(complex)])

    def radius(self, gain: float = 1.0) -> float:
        """The spectral radius of the loop's poles at the loop gain ``gain`` (0 for none).

        Examples
        --------
        >>> round(sampled_model(Loop("1/s", delay=0.0, period=0.1)).radius(10.0), 12)   # z = 1 - g Kp h
        0.0
        """
        z = self.poles(gain)
        return float(np.max(np.abs(z))) if z.size else 0.0

    @cached_property
    def _deflation(self) -> tuple[np.ndarray, np.ndarray]:
        return _fixed_modes(self)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (matrices as nested lists)."""
        return {"period": self.period, "total_delay": self.total_delay, "whole_periods": self.whole_periods,
                "fraction": self.fraction, "n_plant": self.n_plant, "n_controller": self.n_controller,
                "n_held": self.n_held, "phi": self.phi.tolist(), "a_open": self.a_open.tolist(),
                "b_open": self.b_open.tolist(), "k_row": self.k_row.tolist(), "b_ref": self.b_ref.tolist()}

    def __repr__(self) -> str:
        return (f"SampledModel(order {self.order}: plant {self.n_plant}, controller {self.n_controller}, "
                f"{self.n_held} held commands; T = {self.whole_periods} h + {self.fraction:.6g} s, "
                f"h = {self.period:g} s)")


def _orth(M: np.ndarray, tol: float) -> np.ndarray:
    """An orthonormal basis of the columns of ``M``, singular values below ``tol`` (absolute) dropped."""
    if not M.size:
        return np.zeros((M.shape[0], 0))
    U, sv, _ = np.linalg.svd(M, full_matrices=False)
    return U[:, sv > tol]


_RANK_MAX = 4  # the plant's input acts on the lifted state through at most 4 directions (see _fixed_modes)


def _range(M: np.ndarray, tol: float) -> np.ndarray:
    """An orthonormal basis of the column space of ``M``, known to be of low rank (the plant's input acts through
    a few vectors): ``M`` times a fixed pseudo-random block a few columns wider than the rank can be, then
    :func:`_orth` (exact for a matrix of that rank; deterministic)."""
    n, k = M.shape
    nz = np.flatnonzero(np.any(M != 0.0, axis=0))
    if nz.size <= 8:
        return _orth(M[:, nz], tol)
    Y = M[:, nz] @ np.random.default_rng(1).standard_normal((nz.size, min(nz.size, n, 8 + _RANK_MAX)))
    return _orth(Y, tol * math.sqrt(nz.size))


def _complement(Q: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the orthogonal complement of ``Q``'s (orthonormal) columns: a fixed pseudo-random
    block projected off ``Q`` twice (deterministic; cheaper than a full decomposition when the complement is small)."""
    n, r = Q.shape
    k = n - r
    if k == 0:
        return np.zeros((n, 0))
    Y = np.random.default_rng(0).standard_normal((n, k))
    for _ in range(2):
        Y -= Q @ (Q.T @ Y)
    return np.linalg.svd(Y, full_matrices=False)[0]


def _krylov(A: np.ndarray, M: np.ndarray, tol: float) -> np.ndarray:
    """An orthonormal basis of ``span{M, A M, A^2 M, ...}``, the smallest ``A``-invariant subspace holding ``M``'s
    columns (Arnoldi with Gram-Schmidt done twice, vector by vector; a new direction shorter than ``tol`` is
    dropped)."""
    n = A.shape[0]
    Q = np.zeros((n, n))
    r = 0
    for v in _range(M, tol).T:
        Q[:, r] = v
        r += 1
    start = 0
    while start < r < n:
        block = A @ Q[:, start:r]
        start = r
        for v in block.T:
            for _ in range(2):
                v = v - Q[:, :r] @ (Q[:, :r].T @ v)
            nv = float(np.linalg.norm(v))
            if nv > tol and r < n:
                Q[:, r] = v / nv
                r += 1
    return Q[:, :r]


def _fixed_modes(mdl: SampledModel) -> tuple[np.ndarray, np.ndarray]:
    """``(basis, fixed)``: an orthonormal basis of the part of a compensated loop's lifted state that the plant's
    input reaches and that reaches it back, and the eigenvalues of the rest without the ``structural`` ones at 1.

    ``closed(g) = P0 + g P1 + g^2 P2``.  The plant's input acts through the columns of ``P1, P2``: the smallest
    ``phi``-invariant subspace holding them (reachable from the plant's input) carries every mode that the gain
    moves; a left invariant subspace outside it (a compensator's window integral, which depends on the commands
    only) keeps its eigenvalues for every ``g``.  Within the reachable part the same is done on the rows (modes
    that never reach the plant's input, such as predictor feedback's integral when its gain is 0).  The
    eigenvalues of those quotient blocks that lie at 1 must be exactly the compensator's ``structural`` ones.
    """
    a_m, b_m, k_m = mdl.a_open - mdl.a_plant, mdl.b_open - mdl.b_plant, mdl.k_row - mdl.k_plant
    P1 = mdl.a_plant + np.outer(mdl.b_plant, k_m) + np.outer(b_m, mdl.k_plant)
    P2 = np.outer(mdl.b_plant, mdl.k_plant)
    phi = mdl.phi
    scale = max(1.0, float(np.linalg.norm(phi, np.inf)), float(np.linalg.norm(P1, np.inf)))
    tol = 1e-10 * scale
    Q = _krylov(phi, np.column_stack([P1, P2]), tol)
    Qc = _complement(Q)
    fixed = [np.linalg.eigvals(Qc.T @ phi @ Qc)] if Qc.shape[1] else []
    pr, p1, p2 = Q.T @ phi @ Q, Q.T @ P1 @ Q, Q.T @ P2 @ Q
    W = _krylov(pr.T, np.column_stack([p1.T, p2.T]), tol)
    Wc = _complement(W)
    if Wc.shape[1]:
        fixed.append(np.linalg.eigvals(Wc.T @ pr @ Wc))
    z = np.concatenate(fixed) if fixed else np.zeros(0, complex)
    at_one = np.abs(z - 1.0) <= 1e-6  # a Jordan block at 1 splits by about eps^(1/size) in floating point
    if int(np.sum(at_one)) != mdl.structural:
        raise InvalidValueError(
            f"the compensated loop's transition matrix should have {mdl.structural} eigenvalue(s) at 1 that the "
            f"plant's input neither reaches nor sees (the compensator's history states), but it has "
            f"{int(np.sum(at_one))}: the loop's poles cannot be separated from them")
    return Q @ W, z[~at_one]


def sampled_model(loop: Loop | AltitudeLoop) -> SampledModel:
    """The exact discrete-time model of a sampled loop, linearised (saturation ignored).

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A loop with ``period`` set.

    Returns
    -------
    SampledModel

    Raises
    ------
    InvalidValueError
        For a continuous loop, or when the lifted state would exceed :data:`MAX_ORDER`.

    See Also
    --------
    sampled_spectrum : its poles.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> m = sampled_model(AltitudeLoop(kp=1.0, delay=0.2, period=0.1))   # T = 2 h exactly
    >>> m
    SampledModel(order 3: plant 1, controller 0, 2 held commands; T = 2 h + 0 s, h = 0.1 s)
    >>> np.round(np.poly(m.phi), 12).tolist()   # z^3 - z^2 + Kp h
    [1.0, -1.0, 0.0, 0.1]
    """
    lp = _sampled_loop(loop, "sampled_model")
    h = float(lp.period)
    lr = loop_realisation(lp)
    n, nx = lr.npl, lr.order
    nc = nx - n
    # xi' = F xi + G w + Gr r, the controller driven by the continuous measurement (and velocity, if any): the
    # loop's realisation with the measurement folded in (the output delay is moved to the input, the total delay)
    fo = lr.folded()
    F, G, Gr, kx = fo.A, fo.b, fo.br, fo.k
    kl = fo.kw  # the sample's dependence on the plant input at the left limit
    m, f = split_delay(lp.total_delay, h)
    p = m + 1 if (f > 0.0 or kl != 0.0) else m
    comp = bool(np.any(lr.bu) or np.any(lr.bum))
    if comp:  # a compensator also reads u_k and u(t - Tm): hold enough commands for its model's delay too
        mm, fm = split_delay(lr.model_delay, h)
        p = max(p, mm + 1 if fm > 0.0 else mm)
    N = nx + p
    if N > MAX_ORDER:
        raise InvalidValueError(
            f"the total delay {lp.total_delay:g} s is {m} periods of {h:g} s: the lifted state would have {N} "
            f"entries, more than {MAX_ORDER}; use a longer period or the continuous loop")
    X, xr, Xp = _period_transition(F, G, Gr, h, m, f, N, model=(fo.bu, fo.bum, mm, fm) if comp else None)
    Ao = np.zeros((N, N))
    Bo = np.zeros(N)
    K = np.zeros(N)
    Ao[:nx, :] = X[:, :N]   # the plant's and model's held inputs sit in the command slots: slot j holds u_{k-j}
    Bo[:nx] = X[:, N]       # u_k itself (before any fraction has passed, or read by a compensator)
    Ap = np.zeros((N, N))   # the parts that come through the plant's input
    Bp = np.zeros(N)
    Kp = np.zeros(N)
    Ap[:nx, :] = Xp[:, :N]
    Bp[:nx] = Xp[:, N]
    if p >= 1:
        Bo[nx] += 1.0
        for i in range(1, p):
            Ao[nx + i, nx + i - 1] = 1.0
    K[:nx] = kx
    if kl != 0.0:
        K[nx + m] += kl
        Kp[nx + m] = kl
    b_ref = Bo * fo.dvr + np.r_[xr, np.zeros(p)]
    return SampledModel(period=h, total_delay=lp.total_delay, whole_periods=m, fraction=f, n_plant=n,
                        n_controller=nc, n_held=p, phi=Ao + np.outer(Bo, K), a_open=Ao, b_open=Bo, k_row=K,
                        b_ref=b_ref, structural=lp.controller.structural_zeros() if comp else 0,
                        a_plant=Ap, b_plant=Bp, k_plant=Kp, compensated=comp)


# -- the spectrum --------------------------------------------------------------------------------------------
@dataclass(frozen=True, repr=False, eq=False)
class SampledSpectrum:
    """The poles (z-plane) of a sampled loop: the eigenvalues of its one-period transition matrix.

    ``poles`` are sorted by decreasing modulus; ``characteristic`` holds the coefficients of
    ``det(zI - Phi)`` (highest power first); ``radius`` is the spectral radius, ``stable`` means
    ``radius < 1``; ``dominant`` is the pole of largest modulus (``Im >= 0``) and ``rate = log(dominant) / h``
    its equivalent continuous-time root (``Re rate = log(radius) / h``, the decay rate per second).
    """

    period: float
    poles: np.ndarray
    characteristic: np.ndarray
    radius: float
    dominant: complex
    rate: complex

    @property
    def stable(self) -> bool:
        """Asymptotically stable: every pole strictly inside the unit circle."""
        return self.radius < 1.0

    def rates(self) -> np.ndarray:
        """``log(z) / h`` of every pole (principal logarithm; ``-inf`` for a pole at 0), same order as ``poles``."""
        with np.errstate(divide="ignore"):
            return np.log(self.poles.astype(complex)) / self.period

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (complex numbers as ``[re, im]``)."""
        return {"period": self.period, "poles": [[z.real, z.imag] for z in self.poles.astype(complex)],
                "characteristic": self.characteristic.tolist(), "radius": self.radius,
                "dominant": [self.dominant.real, self.dominant.imag],
                "rate": None if math.isinf(self.rate.real) else [self.rate.real, self.rate.imag],
                "stable": self.stable}

    def __repr__(self) -> str:
        d = self.dominant
        return (f"SampledSpectrum(h={self.period:g} s, {self.poles.size} poles, radius {self.radius:.6f} "
                f"(rate {self.rate.real:.4f}/s), dominant {d.real:.4f}{d.imag:+.4f}j, "
                f"{'stable' if self.stable else 'UNSTABLE'})")


def sampled_spectrum(loop: Loop | AltitudeLoop) -> SampledSpectrum:
    """Poles, characteristic polynomial and spectral radius of a sampled loop (saturation ignored).

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A loop with ``period`` set (the sampling offset does not matter).

    Returns
    -------
    SampledSpectrum

    See Also
    --------
    sampled_model : the transition matrix.
    delaykit.spectrum.stability.rightmost : the continuous loop's rightmost root.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> s = sampled_spectrum(AltitudeLoop(kp=1.31, delay=0.368, period=0.065))
    >>> s.stable, round(s.rate.real, 4)
    (True, -1.8951)
    """
    mdl = sampled_model(loop)
    h = mdl.period
    z = mdl.poles()
    z = z[np.lexsort((-z.imag, -np.abs(z)))] if z.size else z
    radius = float(np.abs(z[0])) if z.size else 0.0
    if z.size:
        top = z[np.abs(z) >= radius * (1 - 1e-9)]
        dom = complex(top[np.argmax(top.imag)])
    else:
        dom = 0j
    rate = complex(-math.inf, 0.0) if dom == 0 else cmath.log(dom) / h
    coef = np.real_if_close(np.poly(z if mdl.compensated else mdl.phi)) if mdl.order else np.ones(1)
    if np.iscomplexobj(coef):
        coef = coef.real
    if np.all(np.abs(z.imag) < 1e-300):
        z = z.real
    return SampledSpectrum(period=h, poles=z, characteristic=np.asarray(coef, float), radius=radius,
                           dominant=dom, rate=rate)


# -- the frequency response -----------------------------------------------------------------------------------
def _response(mdl: SampledModel, w: np.ndarray) -> np.ndarray:
    """``L(e^{j w h})`` broken at the plant's input (see :func:`sampled_frequency_response`).

    With the plant's held input ``w_k = W z^k`` and the command ``u_k = U z^k``, a held value ``j`` periods old
    is ``z^{-j}`` times the current one.  The state ``xi = [x; xc]`` obeys ``(z I - E) Xi = Am(z) U + Ap(z) W``
    (``Ap``: through the plant's input, ``Am``: a compensator's model reading the command) and the sample
    ``U = kx Xi + Kh(z) U + Kp(z) W``, so ``L = -U / W = -(kx R Ap + Kp) / (1 - Kh - kx R Am)``,
    ``R = (z I - E)^{-1}``.  Without a compensator ``Am = Kh = 0`` and this is ``-K (zI - A_open)^{-1} B_open``.
    """
    nx, p = mdl.n_plant + mdl.n_controller, mdl.n_held
    w = np.asarray(w, float)
    zinv = np.exp(-1j * np.outer(w * mdl.period, np.arange(p + 1)))  # z^{-j}, j = 0..p, exact for long delays
    z = np.exp(1j * w * mdl.period)
    cols = nx + np.arange(p)  # slot j >= 1 holds u_{k-j}

    def series(now: np.ndarray, held: np.ndarray) -> np.ndarray:  # sum_j c_j z^{-j}: u_k, then the held slots
        return zinv[:, :1] * now[None, :] + zinv[:, 1:] @ held

    a_p, b_p = mdl.a_plant[:nx], mdl.b_plant[:nx]
    a_m, b_m = mdl.a_open[:nx] - a_p, mdl.b_open[:nx] - b_p
    Ap = series(b_p, a_p[:, cols].T)  # (frequencies, nx)
    Am = series(b_m, a_m[:, cols].T)
    Kp = zinv[:, 1:] @ mdl.k_plant[cols]
    Kh = zinv[:, 1:] @ (mdl.k_row - mdl.k_plant)[cols]
    kx = mdl.k_row[:nx]
    E = mdl.a_open[:nx, :nx]
    if nx:
        lhs = z[:, None, None] * np.eye(nx) - E
        rhs = np.stack([Ap, Am], axis=-1)
        with np.errstate(all="ignore"):
            try:
                sol = np.linalg.solve(lhs, rhs)
            except np.linalg.LinAlgError:  # a frequency exactly on an open-loop pole: infinite there
                sol = np.empty(rhs.shape, complex)
                for i in range(z.size):
                    try:
                        sol[i] = np.linalg.solve(lhs[i], rhs[i])
                    except np.linalg.LinAlgError:
                        sol[i] = complex(math.inf, 0.0)
        sp, sm = sol[..., 0] @ kx, sol[..., 1] @ kx
    else:
        sp = sm = np.zeros(w.size, complex)
    with np.errstate(all="ignore"):
        return -(sp + Kp) / (1.0 - Kh - sm)


def _check_frequencies(w: Any, h: float) -> np.ndarray:
    try:
        arr = np.asarray(w, dtype=float)
    except OverflowError:  # an integer of hundreds of digits
        raise InvalidValueError("w must be finite frequencies in rad/s, got an integer beyond the floats") from None
    except (TypeError, ValueError):
        raise InvalidTypeError(f"w must be real frequencies in rad/s, got {w!r:.60}") from None
    if not np.all(np.isfinite(arr)):
        bad = arr[~np.isfinite(arr)].ravel()[0]
        raise InvalidValueError(f"w must be finite frequencies in rad/s, got {bad!r}")
    wn = math.pi / h
    if arr.size and (np.min(arr) <= 0.0 or np.max(arr) > wn * (1 + 1e-12)):
        bad = arr.ravel()[np.argmax((arr.ravel() <= 0) | (arr.ravel() > wn * (1 + 1e-12)))]
        raise InvalidValueError(
            f"w must lie in (0, pi/h] = (0, {wn:.6g}] rad/s for the period h = {h:g} s, got {bad:g}")
    return arr


def sampled_frequency_response(loop: Loop | AltitudeLoop, w: Any) -> Any:
    """The exact open-loop frequency response ``L(e^{j w h})`` of a sampled loop, broken at the plant's input.

    The plant's held input sequence goes through the delays, the plant and the continuous controller and comes
    back as the command, sampled, with the sign of negative feedback, so that the closed loop's poles are the
    roots of ``1 + L(z)`` (besides the open loop's own).  Without a compensator this is the loop broken at the
    held command, ``L(z) = -K (zI - A_open)^{-1} B_open``; for P control of ``1/s`` with ``T = m h + f`` it is
    ``Kp ((h - f) z + f) / (z^{m+1} (z - 1))``.  A compensator's model reads the command itself, inside ``L``
    (the sampled counterpart of ``A2 e^{-sT} / (A0 + A1 e^{-s Tm})`` in :mod:`.compensated`): for the Smith
    predictor with P control of ``1/s`` and a perfect model, ``L = Kc Hd_T / (1 + Kc Hd - Kc Hd_T)`` with
    ``Hd = h / (z - 1)`` and ``Hd_T`` the P loop's ``L / Kp`` above.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A loop with ``period`` set; any controller, a delay compensator included.
    w : float or array_like
        Frequencies in rad/s, in ``(0, pi/h]``.

    Returns
    -------
    complex or ndarray of complex
        The same shape as ``w``.

    Raises
    ------
    InvalidValueError
        For a continuous loop, or a frequency outside ``(0, pi/h]``.
    InvalidTypeError
        For frequencies that are not numbers.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> L = sampled_frequency_response(AltitudeLoop(kp=1.0, delay=0.0, period=0.1), np.pi / 0.1)
    >>> round(L.real, 12), abs(L.imag) < 1e-15     # Kp h / (z - 1) at z = -1
    (-0.05, True)
    >>> from delaykit.models.compensators import Compensator
    >>> smith = Compensator.smith("1/s", 0.2, closed_loop_time=0.2)      # Kc = 5, T = Tm = 2 h
    >>> L = sampled_frequency_response(Loop("1/s", smith, delay=0.2, period=0.1), np.pi / 0.1)
    >>> round(L.real, 12), abs(L.imag) < 1e-15     # z = -1: Hd = -h/2 = Hd_T, L = Kc Hd_T / 1
    (-0.25, True)
    """
    mdl = sampled_model(_sampled_loop(loop, "sampled_frequency_response"))
    arr = _check_frequencies(w, mdl.period)
    out = _response(mdl, arr.ravel()).reshape(arr.shape)
    return complex(out) if out.ndim == 0 else out


def sampled_response(loop: Loop | AltitudeLoop, w: Any = None) -> FrequencyResponse:
    """:func:`sampled_frequency_response` as a :class:`~delaykit.spectrum.frequency.FrequencyResponse`, for
    :func:`~delaykit.plotting.frequency.plot_bode` and ``plot_nyquist``.

    ``w`` in ``(0, pi/h]`` (default: 1000 frequencies, logarithmic from ``1e-3 pi/h`` to ``pi/h``); the phase is
    unwrapped along increasing ``w`` (so the grid must be fine enough that it turns by less than pi between
    neighbours, as the default is for delays under about a hundred periods).

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> r = sampled_response(AltitudeLoop(kp=1.31, delay=0.368, period=0.065))
    >>> r.w.size, round(float(r.phase_deg[-1]), 6)   # at pi/h: z = -1, L real and negative, 3.5 turns down
    (1000, -1260.0)
    """
    h = sampled_model(_sampled_loop(loop, "sampled_response")).period
    w = np.geomspace(1e-3 * math.pi / h, math.pi / h, 1000) if w is None else np.sort(np.ravel(w))
    L = np.atleast_1d(sampled_frequency_response(loop, w))
    with np.errstate(divide="ignore"):
        db = 20.0 * np.log10(np.abs(L))
    return FrequencyResponse(w=w, L=L, magnitude_db=db, phase_deg=np.degrees(np.unwrap(np.angle(L))))
