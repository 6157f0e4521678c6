"""Exact sample-to-sample simulation of a plant driven by a held, delayed command.

When the command is held between samples (a zero-order hold: a logged actuator signal, or a sampled controller)
the plant's state at the next sample is an exact linear function of the state now and of the held commands that
reach the plant during the period.  With the period ``h`` and the delay ``T = m h + f`` (``0 <= f < h``), the plant
input during ``[t_k, t_k + f)`` is the command issued at ``t_{k-m-1}`` and during ``[t_k + f, t_{k+1})`` the one
issued at ``t_{k-m}``, so

    x[k+1] = Phi(h) x[k] + Phi(h - f) Gamma(f) u[k-m-1] + Gamma(h - f) u[k-m],

with ``Phi(t) = exp(A t)`` and ``Gamma(t) = int_0^t exp(A s) ds B``, both read off one matrix exponential of an
augmented matrix.  Nothing is approximated: this is the same trajectory the method of steps computes
(:func:`delaykit.simulate.simulation.simulate`), evaluated only at the samples, in microseconds.  Identification
uses it to fit plants and delays to logs.

Two drives are supported: an **open** loop, where the command sequence is given (a logged input), and a **closed**
loop with a static sampled law ``u = sat(kp (r - y) - kv y')`` (the paper's P and PV laws with the true velocity,
and the PX4 vehicle's outer loop), where the controller samples at the same instants as the log.  Both work in
deviation variables from rest: the state starts at zero and commands issued before the first sample are zero.

A log on a real clock (a logger that writes at 1.01 s instead of 1 s, or with jitter) has no one-period map:
:func:`held_response_at` steps the plant from event to event, the samples and the instants at which each held
command reaches the plant, with one exponential per stretch: exact on any increasing clock.

Examples
--------
>>> import numpy as np
>>> from delaykit.models.transfer import TransferFunction
>>> m = held_delay_model(TransferFunction.parse("1/(2*s+1)"), period=0.5, delay=0.75)
>>> y = held_response(m, np.ones(8)).y                 # a unit step held from t = 0, seen 0.75 s later
>>> bool(np.allclose(y[3:], 1 - np.exp(-(np.arange(3, 8) * 0.5 - 0.75) / 2)))
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import InvalidValueError, check_real
from ..models.hold import hold_matrices, split_delay
from ..models.transfer import TransferFunction

__all__ = ["HeldDelayModel", "HeldResponse", "held_delay_model", "held_response", "closed_loop_response",
           "held_matrices_of", "held_response_at"]


STIFF = 1e6
"""Above this ``sum |A| h`` (a mode a million times faster than the period), :func:`held_matrices_of` leaves the
compiled series (whose rounding grows with the squarings: 1e-13 to 1e-11 below it, as SciPy's) for SciPy's."""


@dataclass(frozen=True, repr=False, eq=False)
class HeldDelayModel:
    """The exact one-period map of a plant whose held command arrives ``delay`` seconds late.

    ``x[k+1] = phi x[k] + g_early u[k-m-1] + g_late u[k-m]``; the output at a sample is ``c x + d u_now`` and its
    derivative ``ca x + cb u_now`` where ``u_now`` is the command acting at the sample instant.
    """

    phi: np.ndarray
    g_early: np.ndarray
    g_late: np.ndarray
    c: np.ndarray
    d: float
    ca: np.ndarray
    cb: float
    m: int
    fractional: bool
    period: float
    delay: float

    def __repr__(self) -> str:
        return (f"HeldDelayModel(order={self.phi.shape[0]}, period={self.period:g} s, delay={self.delay:g} s "
                f"= {self.m} periods + {self.delay - self.m * self.period:.4g} s)")


@dataclass(frozen=True, repr=False, eq=False)
class HeldResponse:
    """Output ``y``, its derivative ``dy`` and the commands ``u`` at the samples (deviation variables)."""

    y: np.ndarray
    dy: np.ndarray
    u: np.ndarray

    def __repr__(self) -> str:
        return f"HeldResponse({self.y.size} samples, y in [{self.y.min():.4g}, {self.y.max():.4g}])"


@njit(cache=True)
def _expm(M):  # pragma: no cover (compiled)
    """exp(M) of a small matrix: scaling and squaring with a Taylor series of degree 18 on ||M / 2^s||_1 <= 1/2,
    whose remainder (below 0.5^19 / 19! ~ 2e-23 relative) is far under rounding."""
    n = M.shape[0]
    norm = 0.0
    for j in range(n):
        c = 0.0
        for i in range(n):
            c += abs(M[i, j])
        norm = max(norm, c)
    s = 0
    while norm > 0.5:
        norm *= 0.5
        s += 1
    X = M / (2.0 ** s)
    E = np.eye(n)
    T = np.eye(n)
    for k in range(1, 19):
        T = T @ X / k
        E = E + T
    for _ in range(s):
        E = E @ E
    return E


@njit(cache=True)
def _phi_gamma_fast(A, B, t):  # pragma: no cover (compiled)
    n = A.shape[0]
    E = np.empty((n + 1, n + 1))
    _aug_expm(A, B, t, E)
    return E[:n, :n].copy(), E[:n, n].copy()


def _phi_gamma(A: np.ndarray, B: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    if A.shape[0] == 0:
        return np.zeros((0, 0)), np.zeros(0)
    if np.abs(A).sum() * t > 1e3:  # far from what the compiled series is meant for: SciPy's Pade method
        E, J = hold_matrices(A, B[:, None], t)
        return E, J[:, 0]
    return _phi_gamma_fast(np.ascontiguousarray(A, dtype=float), np.ascontiguousarray(B, dtype=float), float(t))


def held_delay_model(plant: TransferFunction, period: float, delay: float = 0.0) -> HeldDelayModel:
    """The exact sample-to-sample map of ``plant`` driven by a command held for ``period`` and delayed by ``delay``.

    Parameters
    ----------
    plant : TransferFunction
        A proper plant.
    period : float
        The hold period ``h`` (s), > 0.
    delay : float
        The delay ``T`` (s), >= 0; need not be a multiple of the period.

    Returns
    -------
    HeldDelayModel

    Examples
    --------
    >>> held_delay_model(TransferFunction.parse("1/s"), period=0.02, delay=0.205)
    HeldDelayModel(order=1, period=0.02 s, delay=0.205 s = 10 periods + 0.005 s)
    """
    h = check_real("period (s)", period, minimum=0.0, strict=True)
    T = check_real("delay (s)", delay, minimum=0.0)
    if not isinstance(plant, TransferFunction):
        raise InvalidValueError(f"plant must be a TransferFunction, got {type(plant).__name__}")
    A, B, C, D = plant.state_space()
    m, f = split_delay(T, h)
    phi_h, gam_h = _phi_gamma(A, B, h)
    if f > 0.0:
        phi_r, gam_r = _phi_gamma(A, B, h - f)
        _, gam_f = _phi_gamma(A, B, f)
        g_early, g_late = phi_r @ gam_f, gam_r
    else:
        g_early, g_late = np.zeros_like(gam_h), gam_h
    return HeldDelayModel(phi=np.ascontiguousarray(phi_h), g_early=np.ascontiguousarray(g_early),
                          g_late=np.ascontiguousarray(g_late), c=np.ascontiguousarray(C, dtype=float), d=float(D),
                          ca=np.ascontiguousarray(C @ A if A.size else np.zeros(0)), cb=float(C @ B) if A.size else 0.0,
                          m=m, fractional=f > 0.0, period=h, delay=T)


@njit(cache=True)
def _run_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, closed, kp, kv, lo, hi, y, dy, u,
              x, xn):  # pragma: no cover (compiled)
    """One log from rest into ``y``, ``dy`` and ``u`` (``x``, ``xn``: work vectors of the plant's order)."""
    n = phi.shape[0]
    N = drive.shape[0]
    for i in range(n):
        x[i] = 0.0
    lag_now = m + 1 if fractional else m  # the command acting at a sample instant was issued lag_now samples ago
    for k in range(N):
        j = k - lag_now
        u_now = u[j] if j >= 0 and j < k else 0.0
        yk = d * u_now
        dk = cb * u_now
        for i in range(n):
            yk += c[i] * x[i]
            dk += ca[i] * x[i]
        if closed:
            uk = kp * (drive[k] - yk) - kv * dk
            if uk < lo:
                uk = lo
            elif uk > hi:
                uk = hi
        else:
            uk = drive[k]
        u[k] = uk
        if j == k:  # no delay: the command issued now acts now
            yk += d * uk
            dk += cb * uk
        y[k] = yk
        dy[k] = dk
        je = k - m - 1
        jl = k - m
        ue = u[je] if je >= 0 else 0.0
        ul = u[jl] if jl >= 0 else 0.0
        for i in range(n):
            s = g_early[i] * ue + g_late[i] * ul
            for q in range(n):
                s += phi[i, q] * x[q]
            xn[i] = s
        for i in range(n):
            x[i] = xn[i]


@njit(cache=True)
def _run(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, closed, kp, kv, lo, hi):  # pragma: no cover
    N = drive.shape[0]
    n = phi.shape[0]
    u = np.zeros(N)
    y = np.empty(N)
    dy = np.empty(N)
    _run_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, closed, kp, kv, lo, hi, y, dy, u,
              np.zeros(n), np.zeros(n))
    return y, dy, u


@njit(cache=True)
def _run_logs(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive, starts, closed, kp, kv, lo, hi, unit,
              y, dy, uy, udy):  # pragma: no cover (compiled)
    """Several logs laid end to end (log ``i`` is ``drive[starts[i]:starts[i + 1]]``, each from rest, each with its
    own limits ``lo[i]``, ``hi[i]``) into ``y`` and ``dy``; with ``unit``, also each log's response to a held unit
    command (open loop) into ``uy`` and ``udy``."""
    n = phi.shape[0]
    x = np.zeros(n)
    xn = np.zeros(n)
    u = np.zeros(drive.shape[0])
    for i in range(starts.shape[0] - 1):
        a = starts[i]
        b = starts[i + 1]
        _run_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, drive[a:b], closed, kp, kv, lo[i], hi[i],
                  y[a:b], dy[a:b], u[a:b], x, xn)
        if unit:
            for k in range(a, b):
                u[k] = 1.0
            _run_into(phi, g_early, g_late, c, d, ca, cb, m, fractional, u[a:b], False, 0.0, 0.0, lo[i], hi[i],
                      uy[a:b], udy[a:b], u[a:b], x, xn)


@njit(cache=True)
def _mul_into(X, Y, Z):  # pragma: no cover (compiled)
    """Z = X @ Y for small square matrices (explicit loops: no BLAS call overhead)."""
    n = X.shape[0]
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += X[i, k] * Y[k, j]
            Z[i, j] = s


@njit(cache=True)
def _aug_expm(A, B, t, E):  # pragma: no cover (compiled)
    """``E = exp([[A t, B t], [0, 0]])`` ((n+1) x (n+1)): ``E[:n, :n] = Phi(t)``, ``E[:n, n] = Gamma(t)``.

    Scaling and squaring with a Taylor series on ``||M / 2^s||_1 <= 1/2``, summed until a term is below 1e-18 of
    the sum (at most degree 18, as :func:`_expm`)."""
    n = A.shape[0]
    q = n + 1
    X = np.zeros((q, q))
    for i in range(n):
        for j in range(n):
            X[i, j] = A[i, j] * t
        X[i, n] = B[i] * t
    norm = 0.0
    for j in range(q):
        c = 0.0
        for i in range(q):
            c += abs(X[i, j])
        norm = max(norm, c)
    s = 0
    while norm > 0.5:
        norm *= 0.5
        s += 1
    sc = 0.5 ** s
    for i in range(q):
        for j in range(q):
            X[i, j] *= sc
    T = np.eye(q)
    W = np.empty((q, q))
    for i in range(q):
        for j in range(q):
            E[i, j] = 1.0 if i == j else 0.0
    for k in range(1, 19):
        _mul_into(T, X, W)
        big = 0.0
        for i in range(q):
            for j in range(q):
                T[i, j] = W[i, j] / k
                E[i, j] += T[i, j]
                big = max(big, abs(T[i, j]))
        if big < 1e-18:
            break
    for _ in range(s):
        _mul_into(E, E, W)
        for i in range(q):
            for j in range(q):
                E[i, j] = W[i, j]


@njit(cache=True)
def _held_arrays(A, B, h, f):  # pragma: no cover (compiled)
    """``phi``, ``g_early`` and ``g_late`` of a realisation ``(A, B)`` for the delay's fraction ``f`` of a period
    (two exponentials: over ``f`` and over ``h - f``; ``phi = Phi(h - f) Phi(f)``)."""
    n = A.shape[0]
    phi = np.zeros((n, n))
    ge = np.zeros(n)
    gl = np.zeros(n)
    Er = np.empty((n + 1, n + 1))
    _aug_expm(A, B, h - f, Er)
    for i in range(n):
        gl[i] = Er[i, n]
    if f > 0.0:
        Ef = np.empty((n + 1, n + 1))
        _aug_expm(A, B, f, Ef)
        for i in range(n):
            for j in range(n):
                acc = 0.0
                for k in range(n):
                    acc += Er[i, k] * Ef[k, j]
                phi[i, j] = acc
            acc = 0.0
            for k in range(n):
                acc += Er[i, k] * Ef[k, n]
            ge[i] = acc
    else:
        for i in range(n):
            for j in range(n):
                phi[i, j] = Er[i, j]
    return phi, ge, gl


def held_matrices_of(A: np.ndarray, B: np.ndarray, period: float, delay: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, bool]:
    """``(phi, g_early, g_late, m, fractional)`` of :class:`HeldDelayModel` for a realisation ``(A, B)`` given as
    arrays (no checks: the caller's realisation is proper and its period positive).  Identification calls this
    for every trial plant; matrices far from what the compiled exponential is meant for go to SciPy's.

    Examples
    --------
    >>> phi, ge, gl, m, frac = held_matrices_of(np.array([[0.0]]), np.array([2.0]), 0.1, 0.25)
    >>> phi.tolist(), ge.round(12).tolist(), gl.round(12).tolist(), m, frac
    ([[1.0]], [0.1], [0.1], 2, True)
    """
    m, f = split_delay(delay, period)
    if not np.abs(A).sum() * period <= STIFF:
        phi_h, gam_h = _phi_gamma(A, B, period)
        if f > 0.0:
            phi_r, gam_r = _phi_gamma(A, B, period - f)
            _, gam_f = _phi_gamma(A, B, f)
            return phi_h, phi_r @ gam_f, gam_r, m, True
        return phi_h, np.zeros_like(gam_h), gam_h, m, False
    phi, ge, gl = _held_arrays(A, B, float(period), float(f))
    return phi, ge, gl, m, f > 0.0


def _drive(name: str, values: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(values, dtype=float)
    if a.ndim != 1 or a.size == 0:
        raise InvalidValueError(f"{name} must be a non-empty 1-d array, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InvalidValueError(f"{name} holds a non-finite value at sample {int(np.flatnonzero(~np.isfinite(a))[0])}")
    return a


def held_response(model: HeldDelayModel, u: np.ndarray) -> HeldResponse:
    """The plant's output at the samples when the command ``u[k]`` is held from sample ``k`` to ``k + 1``.

    Deviation variables from rest: the state is zero at the first sample and earlier commands are zero.

    Examples
    --------
    >>> m = held_delay_model(TransferFunction.parse("1/s"), period=0.1, delay=0.25)
    >>> held_response(m, np.ones(6)).y.round(6).tolist()         # a ramp that starts 0.25 s late
    [0.0, 0.0, 0.0, 0.05, 0.15, 0.25]
    """
    a = _drive("u (the held command)", u)
    y, dy, uu = _run(model.phi, model.g_early, model.g_late, model.c, model.d, model.ca, model.cb, model.m,
                     model.fractional, a, False, 0.0, 0.0, -math.inf, math.inf)
    return HeldResponse(y=y, dy=dy, u=uu)


def closed_loop_response(model: HeldDelayModel, r: np.ndarray, *, kp: float, kv: float = 0.0,
                         umin: float = -math.inf, umax: float = math.inf) -> HeldResponse:
    """The loop ``u[k] = sat(kp (r[k] - y[k]) - kv y'[k])`` sampled at every sample, the command held and delayed.

    ``r`` is the reference at the samples (deviation from the initial steady state, as are the limits).

    Examples
    --------
    >>> m = held_delay_model(TransferFunction.parse("1/s"), period=0.01, delay=0.0)
    >>> res = closed_loop_response(m, np.ones(400), kp=1.0)       # ~ 1 - exp(-t), sampled every 10 ms
    >>> round(float(res.y[100]), 3), round(1 - 0.99 ** 100, 3)
    (0.634, 0.634)
    """
    a = _drive("r (the reference)", r)
    kp = check_real("kp", kp)
    kv = check_real("kv", kv)
    lo = check_real("umin", umin, allow_neg_inf=True)
    hi = check_real("umax", umax, allow_inf=True)
    if not lo < hi:
        raise InvalidValueError(f"umin must be below umax; got {lo:g} and {hi:g}")
    if model.m == 0 and not model.fractional and (model.d != 0.0 or (kv != 0.0 and model.cb != 0.0)):
        raise InvalidValueError("a sampled loop without delay around a plant with a direct feedthrough (or a "
                                "velocity term on a plant whose velocity jumps) is an algebraic loop")
    y, dy, uu = _run(model.phi, model.g_early, model.g_late, model.c, model.d, model.ca, model.cb, model.m,
                     model.fractional, a, True, kp, kv, lo, hi)
    return HeldResponse(y=y, dy=dy, u=uu)


@njit(cache=True)
def _advance(A, B, dt, v, x, xn, E):  # pragma: no cover (compiled)
    """``x <- Phi(dt) x + Gamma(dt) v`` (``E``: work matrix of order n + 1)."""
    n = A.shape[0]
    if dt <= 0.0:
        return
    _aug_expm(A, B, dt, E)
    for i in range(n):
        s = E[i, n] * v
        for q in range(n):
            s += E[i, q] * x[q]
        xn[i] = s
    for i in range(n):
        x[i] = xn[i]


@njit(cache=True)
def _run_at_into(A, B, c, d, ca, cb, delay, tol, t, drive, y, dy):  # pragma: no cover (compiled)
    """One log from rest on its own clock ``t``: ``drive[k]`` held from ``t[k]`` reaches the plant at
    ``t[k] + delay``; an arrival within ``tol`` of a sample acts at that sample."""
    n = A.shape[0]
    N = t.shape[0]
    x = np.zeros(n)
    xn = np.zeros(n)
    E = np.empty((n + 1, n + 1))
    tau = t[0]
    j = -1  # the last command that has reached the plant (-1: none yet, the input is 0)
    v = 0.0
    for i in range(N):
        while j + 1 < N and t[j + 1] + delay <= t[i] + tol:
            s = min(t[j + 1] + delay, t[i])
            _advance(A, B, s - tau, v, x, xn, E)
            tau = max(tau, s)
            j += 1
            v = drive[j]
        _advance(A, B, t[i] - tau, v, x, xn, E)
        tau = t[i]
        yk = d * v
        dk = cb * v
        for q in range(n):
            yk += c[q] * x[q]
            dk += ca[q] * x[q]
        y[i] = yk
        dy[i] = dk


@njit(cache=True)
def _run_at_logs(A, B, c, d, ca, cb, delay, tol, t, drive, starts, unit, y, dy, uy, udy):  # pragma: no cover
    """Several logs laid end to end (as :func:`_run_logs`, each on its own clock ``t[starts[i]:starts[i + 1]]``);
    with ``unit``, also each log's response to a held unit command into ``uy`` and ``udy``."""
    ones = np.ones(drive.shape[0])
    for i in range(starts.shape[0] - 1):
        a = starts[i]
        b = starts[i + 1]
        _run_at_into(A, B, c, d, ca, cb, delay, tol, t[a:b], drive[a:b], y[a:b], dy[a:b])
        if unit:
            _run_at_into(A, B, c, d, ca, cb, delay, tol, t[a:b], ones[a:b], uy[a:b], udy[a:b])


def held_response_at(plant: TransferFunction, t: np.ndarray, u: np.ndarray, delay: float = 0.0) -> HeldResponse:
    """The plant's output at the sample times ``t`` (any increasing clock) when ``u[k]`` is held from ``t[k]``
    to ``t[k + 1]`` and reaches the plant ``delay`` seconds later.

    Exact (one matrix exponential per stretch between a sample and a command's arrival); on a uniform clock it
    is :func:`held_response`.  Deviation variables from rest, as there: the state is zero at ``t[0]`` and
    earlier commands are zero.

    Parameters
    ----------
    plant : TransferFunction
        A proper plant.
    t : array_like
        Sample times (s), increasing.
    u : array_like
        The command issued at each sample, as long as ``t``.
    delay : float
        The delay (s), >= 0.

    Returns
    -------
    HeldResponse

    Examples
    --------
    >>> t = np.array([0.0, 0.4, 1.1, 1.5, 2.3])                   # a clock that is not uniform
    >>> r = held_response_at(TransferFunction.parse("1/s"), t, np.ones(5), delay=0.5)
    >>> r.y.round(12).tolist()                                     # a ramp from t = 0.5 s
    [0.0, 0.0, 0.6, 1.0, 1.8]
    """
    if not isinstance(plant, TransferFunction):
        raise InvalidValueError(f"plant must be a TransferFunction, got {type(plant).__name__}")
    tt = _drive("t (the sample times)", t)
    if tt.size > 1 and not np.all(np.diff(tt) > 0.0):
        i = int(np.flatnonzero(np.diff(tt) <= 0.0)[0])
        raise InvalidValueError(f"t (the sample times) must increase; t[{i + 1}] = {tt[i + 1]:g} s follows "
                                f"t[{i}] = {tt[i]:g} s")
    a = _drive("u (the held command)", u)
    if a.size != tt.size:
        raise InvalidValueError(f"u has {a.size} values for {tt.size} sample times")
    T = check_real("delay (s)", delay, minimum=0.0)
    A, B, C, D = plant.state_space()
    A = np.ascontiguousarray(np.atleast_2d(A), dtype=float).reshape(len(B), len(B))
    B = np.ascontiguousarray(B, dtype=float).ravel()
    C = np.ascontiguousarray(C, dtype=float).ravel()
    y, dy = np.empty(tt.size), np.empty(tt.size)
    tol = 1e-12 * max(abs(float(tt[-1])), T, 1.0)
    _run_at_into(A, B, C, float(D), np.ascontiguousarray(C @ A if A.size else np.zeros(0)),
                 float(C @ B) if A.size else 0.0, T, tol, tt, a, y, dy)
    return HeldResponse(y=y, dy=dy, u=a.copy())
