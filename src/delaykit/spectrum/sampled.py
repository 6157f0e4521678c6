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
form) make invariants that no history of commands excites: one eigenvalue 1 each, removed from the poles as the
continuous loop's structural roots at ``s = 0`` are.  The poles and stability of a sampled compensated loop come
from this model; its margins are not computed (the compensator reads the held command itself, so breaking the
loop at the command is not breaking it at the plant).

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
from typing import Any

import numpy as np
from scipy.optimize import brentq, minimize_scalar

from ..errors import InvalidTypeError, InvalidValueError
from ..models.altitude import AltitudeLoop, as_loop
from ..models.hold import hold_matrices, split_delay
from ..models.loop import Loop
from .frequency import FrequencyResponse, _jsonable
from .stability import delay_margin as _continuous_delay_margin
from .stability import rightmost

__all__ = ["SampledModel", "SampledSpectrum", "SampledCrossover", "SampledMargins", "SamplingComparison",
           "sampled_model", "sampled_spectrum", "sampled_frequency_response", "sampled_response", "sampled_margins",
           "compare_sampling", "MAX_ORDER"]

MAX_ORDER = 2000
"""The largest lifted state (plant + controller + held commands) built; a longer delay-to-period ratio is refused."""

_GAIN_SCAN_MAX = 1e6


def _sampled_loop(loop: Any, what: str, compensators: bool = False) -> Loop:
    lp = as_loop(loop)
    if not lp.sampled:
        raise InvalidValueError(
            f"{what} needs a sampled loop (period set, in s); this loop is continuous (period=None): use "
            "delaykit.spectrum.stability.rightmost for its roots, or give it a period")
    if not compensators and lp.controller.realisation().reads_command:
        raise InvalidValueError(
            f"{what} of a loop with a {lp.controller.kind} compensator is not implemented: the compensator reads "
            "the held command itself, so the loop broken at the command is not the loop broken at the plant; "
            "its poles and stability are exact from sampled_spectrum (`delaykit roots --period ...`), and the "
            "continuous loop's margins from `delaykit margins` without --period")
    return lp


def _period_transition(F: np.ndarray, G: np.ndarray, Gr: np.ndarray, h: float, m: int, f: float, N: int,
                       model: tuple[np.ndarray, np.ndarray, int, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``xi_{k+1} = X [z_k; u_k] + xr r`` over one period, piece by piece with the inputs held on each piece.

    The plant's input is ``u_{k-m-1}`` before ``f`` and ``u_{k-m}`` after it.  With ``model = (Gu, Gm, mm, fm)``
    (a compensator) the controller's states also read ``u_k`` throughout and the model's delayed command,
    ``u_{k-mm-1}`` before ``fm`` and ``u_{k-mm}`` after it, so the period is cut at ``fm`` too."""
    nx = F.shape[0]
    X = np.zeros((nx, N + 1))
    X[:, :nx] = np.eye(nx)
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
        X = E @ X + np.outer(J[:, 0], sel(m + 1 if a < f else m))
        xr = E @ xr + J[:, 1]
        if model is not None:
            mm, fm = model[2], model[3]
            X += np.outer(J[:, 2], sel(0)) + np.outer(J[:, 3], sel(mm + 1 if a < fm else mm))
    return X, xr


# -- the exact discrete-time model -----------------------------------------------------------------------
@dataclass(frozen=True, repr=False, eq=False)
class SampledModel:
    """The linearised sampled loop as a discrete-time system over one period (see the module docstring).

    The state is ``z_k = [x(t_k - To), xc(t_k), u_{k-1}, ..., u_{k-p}]`` (``n_plant``, ``n_controller`` and
    ``n_held = p`` entries).  Open at the command: ``z_{k+1} = a_open z_k + b_open u_k`` and ``v_k = k_row z_k``;
    closed (``u_k = v_k``): ``z_{k+1} = phi z_k + b_ref r`` for a reference ``r`` constant over the period
    (``phi = a_open + b_open k_row``).  ``total_delay = whole_periods * period + fraction``.
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

    @property
    def order(self) -> int:
        """Size of the lifted state."""
        return int(self.phi.shape[0])

    def closed(self, gain: float = 1.0) -> np.ndarray:
        """The one-period transition matrix with the loop gain multiplied by ``gain`` (``u_k = gain v_k``)."""
        return self.a_open + gain * np.outer(self.b_open, self.k_row)

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
    lp = _sampled_loop(loop, "sampled_model", compensators=True)
    h = float(lp.period)
    A, B, C, D = lp.plant.state_space()
    n = A.shape[0]
    A = np.asarray(A, float).reshape(n, n)
    B = np.asarray(B, float).reshape(n)
    C = np.asarray(C, float).reshape(n)
    D = float(D)
    rz = lp.controller.realisation()
    nc = rz.order
    CA, CB = C @ A, float(C @ B) if n else 0.0
    nx = n + nc
    # xi' = F xi + G w + Gr r, the controller driven by the continuous measurement (and velocity, if any)
    F = np.zeros((nx, nx))
    F[:n, :n] = A
    F[n:, :n] = np.outer(rz.Bcy, C) + np.outer(rz.Bcv, CA)
    F[n:, n:] = rz.Ac
    G = np.r_[B, rz.Bcy * D + rz.Bcv * CB]
    Gr = np.r_[np.zeros(n), rz.Bcr]
    kx = np.r_[rz.dvy * C + rz.dvv * CA, rz.Cc]
    kl = rz.dvy * D + rz.dvv * CB  # the sample's dependence on the plant input at the left limit
    m, f = split_delay(lp.total_delay, h)
    p = m + 1 if (f > 0.0 or kl != 0.0) else m
    comp = rz.reads_command
    if comp:  # a compensator also reads u_k and u(t - Tm): hold enough commands for its model's delay too
        mm, fm = split_delay(rz.model_delay, h)
        p = max(p, mm + 1 if fm > 0.0 else mm)
    N = nx + p
    if N > MAX_ORDER:
        raise InvalidValueError(
            f"the total delay {lp.total_delay:g} s is {m} periods of {h:g} s: the lifted state would have {N} "
            f"entries, more than {MAX_ORDER}; use a longer period or the continuous loop")
    zc = np.zeros(n)
    X, xr = _period_transition(F, G, Gr, h, m, f, N,
                               model=(np.r_[zc, rz.Bcu], np.r_[zc, rz.Bcm], mm, fm) if comp else None)
    Ao = np.zeros((N, N))
    Bo = np.zeros(N)
    K = np.zeros(N)
    Ao[:nx, :] = X[:, :N]   # the plant's and model's held inputs sit in the command slots: slot j holds u_{k-j}
    Bo[:nx] = X[:, N]       # u_k itself (before any fraction has passed, or read by a compensator)
    if p >= 1:
        Bo[nx] += 1.0
        for i in range(1, p):
            Ao[nx + i, nx + i - 1] = 1.0
    K[:nx] = kx
    if kl != 0.0:
        K[nx + m] += kl
    b_ref = Bo * rz.dvr + np.r_[xr, np.zeros(p)]
    return SampledModel(period=h, total_delay=lp.total_delay, whole_periods=m, fraction=f, n_plant=n,
                        n_controller=nc, n_held=p, phi=Ao + np.outer(Bo, K), a_open=Ao, b_open=Bo, k_row=K,
                        b_ref=b_ref, structural=lp.controller.structural_zeros() if comp else 0)


def _drop_structural(z: np.ndarray, k: int) -> np.ndarray:
    """The poles without the ``k`` at ``z = 1`` that a compensator's history states carry: ``p - int u`` over the
    model's window (and, for predictor feedback, its weighted form) is the same at every sample, so each such
    invariant is an eigenvalue 1 of the transition matrix that no history of commands excites (the sampled
    image of the continuous loop's structural roots at ``s = 0``,
    :meth:`~delaykit.models.compensators.Compensator.structural_zeros`)."""
    d = np.abs(z - 1.0)
    idx = np.argsort(d)[:k]
    # a Jordan block at 1 splits by about eps^(1/size) in floating point
    if idx.size < k or np.max(d[idx]) > 1e-5:
        raise InvalidValueError(
            f"the compensated loop's transition matrix should have {k} eigenvalue(s) at 1 from the compensator's "
            f"history states, but the nearest are {np.round(z[idx], 9).tolist()}: not separable from the loop's poles")
    return np.delete(z, idx)


def _radius(M: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(M)))) if M.size else 0.0


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
    z = np.linalg.eigvals(mdl.phi) if mdl.order else np.zeros(0, complex)
    if mdl.structural:
        z = _drop_structural(z, mdl.structural)
    z = z[np.lexsort((-z.imag, -np.abs(z)))] if z.size else z
    radius = float(np.abs(z[0])) if z.size else 0.0
    if z.size:
        top = z[np.abs(z) >= radius * (1 - 1e-9)]
        dom = complex(top[np.argmax(top.imag)])
    else:
        dom = 0j
    rate = complex(-math.inf, 0.0) if dom == 0 else cmath.log(dom) / h
    coef = np.real_if_close(np.poly(z if mdl.structural else mdl.phi)) if mdl.order else np.ones(1)
    if np.iscomplexobj(coef):
        coef = coef.real
    if np.all(np.abs(z.imag) < 1e-300):
        z = z.real
    return SampledSpectrum(period=h, poles=z, characteristic=np.asarray(coef, float), radius=radius,
                           dominant=dom, rate=rate)


# -- the frequency response -----------------------------------------------------------------------------------
def _blocks(mdl: SampledModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """``E, G1, G2, kx, kl`` back from the model's matrices."""
    nx, m = mdl.n_plant + mdl.n_controller, mdl.whole_periods
    E = mdl.a_open[:nx, :nx]
    G1 = mdl.a_open[:nx, nx + m] if mdl.n_held > m else np.zeros(nx)
    G2 = mdl.a_open[:nx, nx + m - 1] if m >= 1 else mdl.b_open[:nx]
    kl = float(mdl.k_row[nx + m]) if mdl.n_held > m else 0.0
    return E, G1, G2, mdl.k_row[:nx], kl


def _response(mdl: SampledModel, w: np.ndarray) -> np.ndarray:
    E, G1, G2, kx, kl = _blocks(mdl)
    z = np.exp(1j * w * mdl.period)
    nx = E.shape[0]
    if nx:
        lhs = z[:, None, None] * np.eye(nx) - E
        rhs = (G1[None, :] / z[:, None] + G2[None, :])[..., None]
        try:
            s = np.linalg.solve(lhs, rhs)[..., 0] @ kx
        except np.linalg.LinAlgError:  # a frequency exactly on an open-loop pole: infinite there
            s = np.empty(z.shape, complex)
            for i in range(z.size):
                try:
                    s[i] = np.linalg.solve(lhs[i], rhs[i])[:, 0] @ kx
                except np.linalg.LinAlgError:
                    s[i] = complex(math.inf, 0.0)
    else:
        s = np.zeros(z.shape, complex)
    return -(z ** (-mdl.whole_periods)) * (s + kl / z)


def _check_frequencies(w: Any, h: float) -> np.ndarray:
    try:
        arr = np.asarray(w, dtype=float)
    except (TypeError, ValueError):
        raise InvalidTypeError(f"w must be real frequencies in rad/s, got {w!r}") from None
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
    """The exact open-loop frequency response ``L(e^{j w h})`` of a sampled loop, broken at the held command.

    ``L(z) = -K (zI - A_open)^{-1} B_open``: the command sequence goes through the hold, the delays, the
    plant and the continuous controller and comes back sampled, with the sign of negative feedback, so that
    the closed loop's poles are the roots of ``1 + L(z)`` (besides the open loop's own).  For P control of
    ``1/s`` with ``T = m h + f`` this is ``Kp ((h - f) z + f) / (z^{m+1} (z - 1))``.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A loop with ``period`` set.
    w : float or array_like
        Frequencies in rad/s, in ``(0, pi/h]``.

    Returns
    -------
    complex or ndarray of complex
        The same shape as ``w``.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> L = sampled_frequency_response(AltitudeLoop(kp=1.0, delay=0.0, period=0.1), np.pi / 0.1)
    >>> round(L.real, 12), abs(L.imag) < 1e-15     # Kp h / (z - 1) at z = -1
    (-0.05, True)
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


# -- margins ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, repr=False)
class SampledCrossover:
    """A crossover of the discrete open loop ``L(e^{j w h})``: ``kind`` ``"gain"`` (``|L| = 1``) or ``"phase"``
    (``L`` real and negative: the Nyquist curve crosses the negative real axis), with the value ``L`` there.
    """

    kind: str
    frequency: float
    value: complex

    @property
    def magnitude(self) -> float:
        """``|L|`` at the crossover."""
        return abs(self.value)

    @property
    def phase_deg(self) -> float:
        """``arg L`` in degrees, in (-180, 180]."""
        return math.degrees(cmath.phase(self.value))

    @property
    def phase_margin(self) -> float | None:
        """``180 + arg L`` in (-180, 180] degrees, at a gain crossover (else ``None``)."""
        return math.degrees(cmath.phase(-self.value)) if self.kind == "gain" else None

    @property
    def gain_margin(self) -> float | None:
        """``1 / |L|``, the factor that puts a pole on the unit circle there, at a phase crossover."""
        return 1.0 / abs(self.value) if self.kind == "phase" and self.value != 0 else None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (the keys of the continuous crossovers, without their delay margin and direction)."""
        return _jsonable({"kind": self.kind, "frequency": self.frequency, "magnitude": self.magnitude,
                          "phase_deg": self.phase_deg, "gain_margin": self.gain_margin,
                          "phase_margin": self.phase_margin})

    def __repr__(self) -> str:
        if self.kind == "gain":
            return f"SampledCrossover(gain at {self.frequency:.6g} rad/s, PM {self.phase_margin:.4f} deg)"
        return f"SampledCrossover(phase at {self.frequency:.6g} rad/s, |L| {self.magnitude:.6g})"


@dataclass(frozen=True, repr=False)
class SampledMargins:
    """Stability margins of a sampled loop (see :func:`sampled_margins` for how each is found).

    ``gain_margin``: the factor above 1 on the loop gain that puts a pole on the unit circle (``inf`` if none
    up to 1e6); ``lower_gain_margin``: the factor below 1 that does (``0`` if lowering the gain never
    destabilises the loop; positive when the open loop is unstable, or the loop only conditionally stable);
    ``phase_margin`` (degrees) at the gain crossover ``crossover`` (rad/s) where it is smallest;
    ``delay_margin``: the extra continuous delay that reaches instability, ``critical_delay`` the total delay
    there; ``ms``: the largest sensitivity ``max |1 / (1 + L)|``; ``crossovers``: the gain and phase
    crossovers in ``(0, pi/h]``.  As for continuous loops, margins are ``inf`` when nothing crosses and
    ``nan`` when the closed loop is already unstable (the crossovers are still listed); both are ``null``
    in :meth:`to_dict`.
    """

    gain_margin: float
    phase_margin: float
    delay_margin: float
    critical_delay: float
    crossover: float | None
    ms: float
    crossovers: tuple[SampledCrossover, ...]
    stable: bool
    lower_gain_margin: float = 0.0

    @property
    def gain_crossovers(self) -> tuple[float, ...]:
        """Frequencies (rad/s) where ``|L| = 1``."""
        return tuple(c.frequency for c in self.crossovers if c.kind == "gain")

    @property
    def gain_margin_db(self) -> float:
        """The gain margin in dB, ``20 log10(gain_margin)``."""
        g = self.gain_margin
        return g if not (math.isfinite(g) and g > 0) else 20.0 * math.log10(g)

    @property
    def phase_crossover(self) -> float | None:
        """The phase crossover (rad/s) whose factor ``1 / |L|`` is the gain margin (``None`` if none is)."""
        return next((c.frequency for c in self.crossovers if c.kind == "phase" and c.gain_margin is not None
                     and abs(c.gain_margin - self.gain_margin) <= 1e-6 * self.gain_margin), None)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: keys ``gain_margin``, ``phase_margin``, ``delay_margin``, ``critical_delay``,
        ``crossover``, ``ms``, ``crossovers`` (a list of :meth:`SampledCrossover.to_dict`), ``stable``,
        ``lower_gain_margin``, ``gain_margin_db`` and ``phase_crossover`` (the keys of the continuous
        :meth:`~delaykit.spectrum.frequency.Margins.to_dict` that a sampled loop has); infinite and NaN values are
        ``None``."""
        return _jsonable({"gain_margin": self.gain_margin, "phase_margin": self.phase_margin,
                          "delay_margin": self.delay_margin, "critical_delay": self.critical_delay,
                          "crossover": self.crossover, "ms": self.ms,
                          "crossovers": [c.to_dict() for c in self.crossovers], "stable": self.stable,
                          "lower_gain_margin": self.lower_gain_margin, "gain_margin_db": self.gain_margin_db,
                          "phase_crossover": self.phase_crossover})

    def __repr__(self) -> str:
        if not self.stable:
            return (f"SampledMargins(closed loop UNSTABLE, {len(self.gain_crossovers)} gain and "
                    f"{len(self.crossovers) - len(self.gain_crossovers)} phase crossovers)")
        w = "" if self.crossover is None else f" at {self.crossover:.4f} rad/s"
        low = f" (lower {self.lower_gain_margin:.4f})" if self.lower_gain_margin > 0 else ""
        return (f"SampledMargins(gain {self.gain_margin:.4f}{low}, phase {self.phase_margin:.2f} deg{w}, delay "
                f"{self.delay_margin:.4f} s (critical {self.critical_delay:.4f} s), Ms {self.ms:.4f}, stable)")


def _grid(h: float, m: int) -> np.ndarray:
    wn = math.pi / h
    n = min(2000 + 64 * (m + 1), 200_000)
    w = np.unique(np.r_[np.geomspace(1e-6 * wn, wn, n // 2), np.linspace(wn / n, wn, n)])
    return w[w <= wn]


def _sign_changes(w: np.ndarray, y: np.ndarray, fun: Any) -> list[float]:
    out = []
    idx = np.nonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)[0]
    for i in idx:
        out.append(float(brentq(fun, w[i], w[i + 1], xtol=1e-14 * w[i + 1], rtol=1e-15)))
    out.extend(float(w[i]) for i in np.nonzero(y == 0.0)[0])
    return sorted(out)


def _first_crossing(fun: Any, xs: np.ndarray, x0: float) -> float:
    """The first ``x`` in the scan ``xs`` (after ``x0``, where ``fun < 0``) with ``fun(x) >= 0``, refined."""
    prev = x0
    for x in xs:
        if fun(x) >= 0.0:
            return float(brentq(fun, prev, x, xtol=1e-13 * max(1.0, abs(x)), rtol=1e-14))
        prev = x
    return math.inf


def sampled_margins(loop: Loop | AltitudeLoop) -> SampledMargins:
    """Gain, phase and delay margins of a sampled loop, from its exact discrete-time model.

    * gain margin (upward): the loop gain is scaled (``u_k = g v_k``) and the spectral radius of
      ``A + g B K`` is scanned upwards from ``g = 1`` (a geometric grid up to 1e6, plus the factors ``-1/L``
      at every crossing of the negative real axis by the discrete Nyquist curve, where a pole can reach the
      unit circle), the first crossing of 1 refined by Brent's method;
    * lower gain margin: the same scan downwards from ``g = 1`` to ``1e-6`` (then to 0, when the open loop is
      unstable and the radius has not yet crossed 1), ``0`` when the radius stays below 1;
    * phase margin: ``180 + arg L`` in degrees at each gain crossover ``|L(e^{j w h})| = 1``, the smallest;
    * delay margin: extra continuous delay on the loop, scanned from 0 in steps of ``0.1 / w_max`` up to
      ``2 (2 pi / w_min) + 4 h`` (``w_min``, ``w_max`` the lowest and highest gain crossovers), the first
      radius crossing of 1 refined by Brent's method.  Without any gain crossover, at the nominal delay and
      at extra delays of h/4, h/2 and 3h/4, and with a stable open loop, the loop is taken as stable for
      every delay (``|L| < 1``: the small-gain argument); else the scan goes up to ``20 (T + h)``.
      ``inf`` when no crossing is found;
    * ``ms``: the maximum of ``|1 / (1 + L)|`` on a dense grid, refined.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A loop with ``period`` set.

    Returns
    -------
    SampledMargins

    See Also
    --------
    sampled_frequency_response, sampled_spectrum, compare_sampling

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> sampled_margins(AltitudeLoop(kp=1.0, delay=0.1, period=0.1))   # z^2 - z + g Kp h: g = 1 / (Kp h)
    SampledMargins(gain 10.0000, phase 81.40 deg at 1.0004 rad/s, delay 1.4215 s (critical 1.5215 s), Ms 1.1446, stable)
    """
    lp = _sampled_loop(loop, "sampled_margins")
    mdl = sampled_model(lp)
    h, m = mdl.period, mdl.whole_periods
    stable = _radius(mdl.phi) < 1.0
    w = _grid(h, m)
    L = _response(mdl, w)
    resp = lambda x: complex(_response(mdl, np.array([x]))[0])  # noqa: E731
    # gain crossovers and the phase margin
    with np.errstate(divide="ignore"):
        logmag = np.log(np.abs(L))
    gains = _sign_changes(w, logmag, lambda x: math.log(abs(resp(x))))
    pms = [(math.degrees(cmath.phase(-resp(x))), x) for x in gains]
    pm, wc = min(pms) if pms else (math.inf, None)
    # phase crossovers: L real and negative (sign changes of Im L where Re L < 0, and w = pi / h)
    imL = L.imag
    phases = []
    for x in _sign_changes(w, np.where(np.isfinite(imL), imL, 0.0), lambda x: resp(x).imag) + [float(w[-1])]:
        v = resp(x)
        if math.isfinite(abs(v)) and v.real < 0 and abs(v.imag) <= 1e-9 * abs(v):
            phases.append(x)
    crossings = sorted([SampledCrossover("gain", x, resp(x)) for x in gains]
                       + [SampledCrossover("phase", x, resp(x)) for x in phases], key=lambda c: c.frequency)
    # the largest sensitivity
    S = np.abs(1.0 + L)
    i = int(np.argmin(S))
    lo, hi = w[max(i - 1, 0)], w[min(i + 1, w.size - 1)]
    smin = S[i]
    if hi > lo:
        r = minimize_scalar(lambda x: abs(1.0 + resp(x)), bounds=(lo, hi), method="bounded",
                            options={"xatol": 1e-12 * hi})
        smin = min(smin, float(r.fun))
    ms = math.inf if smin == 0.0 else 1.0 / float(smin)
    if not stable:
        nan = math.nan
        return SampledMargins(nan, nan, nan, nan, wc, ms, tuple(crossings), False)
    # gain margin: the radius of A + g B K as g grows; a pole can reach the unit circle only where g L = -1
    cands = [g for g in (-1.0 / resp(x).real for x in phases) if 1.0 < g < _GAIN_SCAN_MAX]
    gs = np.unique(np.r_[np.geomspace(1.0, _GAIN_SCAN_MAX, 121)[1:], [g * (1 + 1e-9) for g in cands],
                         [g * (1 - 1e-9) for g in cands]])
    gm = _first_crossing(lambda g: _radius(mdl.closed(g)) - 1.0, gs, 1.0)
    with np.errstate(all="ignore"):  # (infinite at an integrator)
        at_one = complex(_response(mdl, np.zeros(1))[0])  # L at z = 1, where a real pole can cross
    low = _lower_gain_margin(mdl, [-1.0 / v.real for v in [resp(x) for x in phases] + [at_one]
                                   if math.isfinite(v.real) and v.real < 0.0])
    # delay margin: the radius as extra delay is added
    dm = _delay_margin(lp, h, tuple(gains), mdl)
    return SampledMargins(gm, pm, dm, mdl.total_delay + dm, wc, ms, tuple(crossings), True, low)


def _lower_gain_margin(mdl: SampledModel, factors: list[float]) -> float:
    """The largest gain factor below 1 at which a pole reaches the unit circle (0 if none), scanning ``1 / g``
    upwards from 1 (a geometric grid to 1e6 and the factors ``-1/L`` of the phase crossings and ``z = 1``), then
    down to ``g = 0`` when the open loop itself is unstable."""
    def fun(t: float) -> float:
        return _radius(mdl.closed(1.0 / t)) - 1.0

    cands = [1.0 / g for g in factors if math.isfinite(g) and 0.0 < g < 1.0]
    ts = np.unique(np.r_[np.geomspace(1.0, _GAIN_SCAN_MAX, 121)[1:], [t * (1 + 1e-9) for t in cands],
                         [t * (1 - 1e-9) for t in cands]])
    t = _first_crossing(fun, ts[ts > 1.0], 1.0)
    if math.isfinite(t):
        return 1.0 / t
    g_min = 1.0 / _GAIN_SCAN_MAX
    if _radius(mdl.a_open) > 1.0 + 1e-12 and _radius(mdl.closed(g_min)) < 1.0:
        return float(brentq(lambda g: _radius(mdl.closed(g)) - 1.0, 0.0, g_min, xtol=1e-300, rtol=1e-14))
    return 0.0


def _delay_margin(lp: Loop, h: float, crossovers: tuple[float, ...], mdl: SampledModel) -> float:
    def rad(extra: float) -> float:
        return _radius(sampled_model(lp.replace(delay=lp.delay + extra)).phi) - 1.0

    if crossovers:
        step = 0.1 / max(crossovers)  # a tenth of a radian of phase at the highest crossover (>= h / (10 pi))
        cap = 2.0 * (2.0 * math.pi / min(crossovers)) + 4.0 * h
    else:
        # no gain crossover: if none appears at other fractions of extra delay either and the open loop is
        # stable, |L| < 1 on the unit circle for every extra delay and the loop is stable for all of them
        fracs = [h * k / 4.0 for k in (1, 2, 3)]
        w = _grid(h, mdl.whole_periods)
        crossing = any(np.any(np.abs(_response(sampled_model(lp.replace(delay=lp.delay + d)), w)) >= 1.0)
                       for d in fracs)
        if not crossing and _radius(mdl.a_open) < 1.0:
            return math.inf
        step = h / 8.0
        cap = 20.0 * (mdl.total_delay + h)
    room = (MAX_ORDER - mdl.order - 1) * h  # the lifted state grows by one held command per period of delay
    xs = np.arange(1, int(math.ceil(min(cap, room) / step)) + 1) * step
    dm = _first_crossing(rad, xs, 0.0)
    if math.isinf(dm) and room < cap:
        raise InvalidValueError(
            f"the delay margin search reached {MAX_ORDER} lifted states (extra delay {room:g} s at the period "
            f"{h:g} s) without finding instability; use a longer period")
    return dm


# -- sampled against continuous --------------------------------------------------------------------------------
@dataclass(frozen=True, repr=False)
class SamplingComparison:
    """A sampled loop beside the same loop with a continuous controller (``period=None``).

    ``radius`` and ``rate = log(radius) / h`` (1/s) of the sampled loop against the continuous spectral
    abscissa ``abscissa``; the sampled margins (``sampled``) against the continuous loop's extra-delay margin
    ``continuous_delay_margin`` and critical total delay ``continuous_critical_delay`` (exact, from the
    crossing frequencies; ``nan`` when the continuous loop is unstable, as the sampled margins are then).
    """

    period: float
    total_delay: float
    radius: float
    rate: float
    abscissa: float
    sampled: SampledMargins
    continuous_delay_margin: float
    continuous_critical_delay: float
    continuous_stable: bool

    @property
    def delay_margin_lost(self) -> float:
        """Continuous minus sampled delay margin, s (about ``h / 2`` for a slow loop: the hold's lag)."""
        return self.continuous_delay_margin - self.sampled.delay_margin

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (infinite and NaN values are ``None``)."""
        return _jsonable({"period": self.period, "total_delay": self.total_delay, "radius": self.radius,
                          "rate": self.rate, "abscissa": self.abscissa, "sampled": self.sampled.to_dict(),
                          "continuous_delay_margin": self.continuous_delay_margin,
                          "continuous_critical_delay": self.continuous_critical_delay,
                          "continuous_stable": self.continuous_stable, "sampled_stable": self.sampled.stable,
                          "delay_margin_lost": self.delay_margin_lost})

    def __repr__(self) -> str:
        return (f"SamplingComparison(h={self.period:g} s: rate {self.rate:.4f}/s vs abscissa {self.abscissa:.4f}/s; "
                f"delay margin {self.sampled.delay_margin:.4f} s vs {self.continuous_delay_margin:.4f} s; "
                f"{'stable' if self.sampled.stable else 'UNSTABLE'} sampled, "
                f"{'stable' if self.continuous_stable else 'UNSTABLE'} continuous)")


def _continuous_extra_margin(cont: Loop, stable: bool) -> float:
    """Extra delay before the continuous loop's first crossing past its own delay (it is stable there)."""
    if not stable:
        return math.nan
    T = cont.total_delay
    dm = _continuous_delay_margin(cont.characteristic())
    if math.isinf(dm.delay):
        return math.inf
    nxt = []
    for w, tau in dm.crossings:
        per = 2.0 * math.pi / w
        k = max(0, math.ceil((T - tau) / per - 1e-12))
        nxt.append(tau + k * per)
    return (min(nxt) - T) if nxt else dm.delay - T


def compare_sampling(loop: Loop | AltitudeLoop) -> SamplingComparison:
    """The sampled loop's spectral radius and margins beside those of the same loop sampled continuously.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A loop with ``period`` set; its continuous counterpart is ``loop.replace(period=None)``.

    Returns
    -------
    SamplingComparison

    See Also
    --------
    sampled_margins, delaykit.spectrum.stability.rightmost, delaykit.spectrum.stability.delay_margin

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> c = compare_sampling(AltitudeLoop(kp=1.31, delay=0.368, period=0.065))
    >>> round(c.sampled.delay_margin, 4), round(c.continuous_delay_margin, 4)
    (0.7984, 0.8311)
    """
    lp = _sampled_loop(loop, "compare_sampling")
    spec = sampled_spectrum(lp)
    margins = sampled_margins(lp)
    cont = lp.replace(period=None, sample_offset=0.0)
    rm = rightmost(cont)
    extra = _continuous_extra_margin(cont, rm.stable)
    rate = math.log(spec.radius) / spec.period if spec.radius > 0 else -math.inf
    return SamplingComparison(period=spec.period, total_delay=lp.total_delay, radius=spec.radius, rate=rate,
                              abscissa=rm.abscissa, sampled=margins, continuous_delay_margin=extra,
                              continuous_critical_delay=lp.total_delay + extra, continuous_stable=rm.stable)
