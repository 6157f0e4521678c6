"""Exact time responses of a system with internal delays: step, impulse, initial condition, any input.

A :class:`~delaykit.systems.DelayLTI` is simulated by the method of steps with Taylor pieces (the private kernel
:mod:`._ltikernel`): every delay exact, several incommensurate delays, saturation channels switching at the roots
of their polynomials, neutral systems (``D22 != 0``) whose difference operator is strongly stable.  The answer is
exact to rounding; a run that could not reach the end (its piece budget spent, a value overflowing) says so in
its ``status`` and its outputs past that point are NaN (``None`` in JSON), never silently wrong.

Before the kernel runs, the system is reduced:

* channels without delay and without limits are eliminated algebraically (``w0 = (I - D22_00)^-1 (...)``); an
  algebraic loop that is not well posed is refused;
* saturations without delay stay as channels, solved in the same Taylor recursion as the states, each in its
  regime (linear, or at a limit) between switches; two of them feeding each other directly (an algebraic loop
  through saturations) are refused;
* a neutral system is simulated when its difference operator ``z(t) = D22 diag(z_j(t - tau_j))`` (among the
  delayed channels, those without delay eliminated) is strongly stable, ``sup_theta rho(D22 diag(e^{i theta})) < 1``
  (its jumps then fade, for any delays), shown by ``rho(|D22|) < 1`` or by a diagonal scaling with
  ``||S D22 S^-1|| < 1``; otherwise refused, with the phases at which the spectral radius reaches 1 when a search
  finds them.

Before time 0 every signal is 0 (the delay lines are empty); the states start at ``X0``.

Examples
--------
>>> from delaykit import tf, feedback
>>> r = feedback(tf("exp(-s)/(s+1)"), 1).step([0.0, 1.0, 2.0, 3.0])
>>> r
SystemTimeResponse(step: 1 output x 1 input at 4 times, 0 to 3 s, exact, 4 pieces)
>>> r.outputs[0, 0].round(6).tolist()     # 1 - exp(1 - t) on [1, 2]; exp(2 - t) (y(2) + t - 2) on [2, 3]
[0.0, 0.0, 0.632121, 0.600424]
"""

from __future__ import annotations

import functools
import math
import reprlib
import weakref
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import _native
from ..errors import InvalidTypeError, InvalidValueError, check_finite_array
from ..models.budget import MAX_PIECES  # the most pieces one run may use (the kernel's history grows to it)
from ..models.budget import MAX_PIECE_CHANNELS, MAX_SAMPLES, check_count  # (its history: a polynomial per channel)

__all__ = ["SystemTimeResponse", "BatchTimeResponse", "step_response", "impulse_response", "initial_response",
           "forced_response", "step_response_many", "default_horizon", "STATUSES"]

STATUSES = ("exact", "truncated", "overflow", "stalled")
"""The statuses of a response: exact to rounding at every time; stopped early for lack of room (more pieces than
:data:`MAX_PIECES`); stopped where a value left the floating-point range; stopped where a saturation's regime could
not be settled.  Past the point reached, outputs are NaN."""

_NPOINTS = 1001  # times of a response when none are given

_K = None


def _kernel():
    global _K
    if _K is None:
        _K = _native.load("delaykit.simulate", "_ltikernel")
    return _K


@dataclass(frozen=True, repr=False, eq=False)
class SystemTimeResponse:
    """A time response of a :class:`~delaykit.systems.DelayLTI`.

    Attributes
    ----------
    time : ndarray
        The times (s), shape ``(nt,)``.
    outputs : ndarray
        ``(outputs, inputs, nt)`` for a step or impulse response (entry ``[i, j]``: output ``i`` for input ``j``,
        as python-control's ``step_response``), ``(outputs, nt)`` for an initial or forced response.
    output_labels, input_labels : tuple of str
        The system's signal names.
    kind : str
        ``"step"``, ``"impulse"``, ``"initial"`` or ``"forced"``.
    status : str
        One of :data:`STATUSES`: ``"exact"``, or why the run stopped at :attr:`t_reached` (outputs NaN after).
    pieces : int
        Taylor pieces used (all input columns together).
    t_reached : float
        The time up to which the outputs are computed (the last time when ``status`` is ``"exact"``).
    impulses : tuple of (float, int, int, float)
        An impulse response's Dirac terms ``(time, output, input, weight)``: direct feedthrough at 0 and its
        delayed images (a path from the input to the output without any state).  They are not in
        :attr:`outputs`, which hold the regular part (python-control drops ``D`` with a warning; here it is kept,
        apart).

    Examples
    --------
    >>> from delaykit import tf
    >>> r = tf("exp(-s)/(s+1)", inputs="u", outputs="y").step([0.0, 2.0])
    >>> r
    SystemTimeResponse(step: 1 output x 1 input at 2 times, 0 to 2 s, exact, 2 pieces)
    >>> t, y = r                       # unpacks as python-control's response (squeezed: one input, one output)
    >>> y.round(6).tolist(), r.output_labels
    ([0.0, 0.632121], ('y',))
    >>> r.y.shape, r.t is r.time       # python-control's aliases: y unsqueezed, t the times
    ((1, 1, 2), True)
    """

    time: np.ndarray
    outputs: np.ndarray
    output_labels: tuple[str, ...]
    input_labels: tuple[str, ...]
    kind: str
    status: str
    pieces: int
    t_reached: float
    impulses: tuple[tuple[float, int, int, float], ...] = field(default=())

    def __iter__(self):
        """``t, y = response``, as python-control 0.10's ``TimeResponseData``: ``y`` squeezed for a system with one
        input and one output (shape ``(times,)``), else :attr:`outputs` as they are."""
        return iter((self.time, self._squeezed()))

    def _squeezed(self) -> np.ndarray:
        siso = len(self.output_labels) == 1 and len(self.input_labels) == 1
        return self.outputs.reshape(-1) if siso else self.outputs

    @property
    def t(self) -> np.ndarray:
        """The times (python-control's alias of :attr:`time`)."""
        return self.time

    @property
    def y(self) -> np.ndarray:
        """The outputs, not squeezed (python-control's alias of :attr:`outputs`)."""
        return self.outputs

    def plot(self, *, ax: Any = None, title: str | None = None) -> Any:
        """Draw the response (:func:`~delaykit.plotting.systems.plot_system_response`, imported here: matplotlib
        is loaded only when a figure is asked for); returns the figure.

        Examples
        --------
        >>> from delaykit import tf
        >>> fig = tf("exp(-s)/(s+1)").step([0.0, 1.0, 2.0]).plot(title="a lag")
        >>> fig.get_suptitle()
        'a lag'
        """
        from ..plotting.systems import plot_system_response  # the plotting layer, on demand (tests/test_layout.py)

        return plot_system_response(self, ax=ax, title=title)

    def to_dict(self) -> dict[str, Any]:
        """Strict JSON: NaN outputs (past a stop) as ``None``.

        Examples
        --------
        >>> from delaykit import tf
        >>> d = tf("exp(-s)").step([0.5, 1.5]).to_dict()
        >>> d["outputs"], d["status"]
        ([[[0.0, 1.0]]], 'exact')
        """
        def clean(a: Any) -> Any:
            if isinstance(a, np.ndarray) and a.ndim > 1:
                return [clean(x) for x in a]
            return [float(x) if math.isfinite(x) else None for x in a]

        return {"kind": self.kind, "status": self.status, "time": self.time.tolist(),
                "outputs": clean(self.outputs), "output_labels": list(self.output_labels),
                "input_labels": list(self.input_labels), "pieces": int(self.pieces),
                "t_reached": float(self.t_reached),
                "impulses": [{"time": t, "output": self.output_labels[i], "input": self.input_labels[j], "weight": w}
                             for t, i, j, w in self.impulses]}

    def __repr__(self) -> str:
        ny, nu = len(self.output_labels), len(self.input_labels)
        t = self.time
        span = f", {t[0]:g} to {t[-1]:g} s" if t.size else ""
        io = (f"{ny} output{'s' * (ny != 1)} x {nu} input{'s' * (nu != 1)}" if self.outputs.ndim == 3
              else f"{ny} output{'s' * (ny != 1)}")
        extra = f", {len(self.impulses)} Dirac term{'s' * (len(self.impulses) != 1)}" if self.impulses else ""
        return (f"SystemTimeResponse({self.kind}: {io} at {t.size} time{'s' * (t.size != 1)}{span}, {self.status}"
                + ("" if self.status == "exact" else f" up to {self.t_reached:g} s")
                + f", {self.pieces} piece{'s' * (self.pieces != 1)}{extra})")


# -- the system, reduced for the kernel ----------------------------------------------------------------------

@dataclass(frozen=True)
class _Reduced:
    """The system with its linear channels without delay eliminated (the channels left are the delayed ones and
    the saturations without delay, in the original order), and what the kernel needs besides."""

    A: np.ndarray
    B1: np.ndarray
    B2: np.ndarray
    C1: np.ndarray
    C2: np.ndarray
    D11: np.ndarray
    D12: np.ndarray
    D21: np.ndarray
    D22: np.ndarray
    tau: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    Rw: np.ndarray  # relative degree from W_c to V_i
    Ru: np.ndarray  # from input l to V_i
    AL: np.ndarray  # the states' matrix with every saturation linear (for R0 and the horizon)
    C2L: np.ndarray
    hmax: float
    anorm: float  # the kernel's remainder bound (see _weights): the states' matrix's weighted infinity norm in
    bw: float     # any regime of the saturations without delay, that of the delayed channels' map to the states'
    iw: np.ndarray  # derivative, and the states' inverse weights

    @functools.cached_property
    def R0(self) -> np.ndarray:
        """The orders of the start's breakpoints from a state at rest: none (``DEG + 1``)."""
        return np.full(len(self.tau), _kernel().DEG + 1, dtype=np.int64)

    @functools.cached_property
    def csr(self) -> tuple[np.ndarray, ...]:
        """``[A B1 B2]``, ``[C2 D21 D22]``, ``[C1 D11 D12]`` as compressed rows (pointers, columns, values each),
        the kernel's form of them (its sums skip the zero terms)."""
        out: list[np.ndarray] = []
        for M in (np.hstack([self.A, self.B1, self.B2]), np.hstack([self.C2, self.D21, self.D22]),
                  np.hstack([self.C1, self.D11, self.D12])):
            rows, cols = np.nonzero(M)
            ptr = np.zeros(M.shape[0] + 1, dtype=np.int64)
            np.cumsum(np.bincount(rows, minlength=M.shape[0]), out=ptr[1:])
            out += [ptr, cols.astype(np.int64), np.ascontiguousarray(M[rows, cols], dtype=float)]
        return tuple(out)


def _weights(M: np.ndarray, Bm: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's remainder bound's norms for the entrywise bounds ``M >= |A|`` and ``Bm >= |B2|`` (one system,
    or stacks): with the states weighted by ``v`` (the Perron vector of ``M`` plus 1 % of its scale in every
    entry, so that no weight is tiny; largest 1), ``anorm = max_i (M v)_i / v_i`` and ``bw = max_i sum_c Bm_ic /
    v_i`` bound the infinity norms of ``diag(v)^-1 A diag(v)`` and ``diag(v)^-1 B2``; any positive ``v`` makes the
    bound rigorous, this one makes ``anorm`` close to the spectral radius of ``M`` (a companion matrix's infinity
    norm can be its spectral radius's square).  Returns ``anorm``, ``bw`` and ``1 / v``."""
    n = M.shape[-1]
    if n == 0:
        return np.zeros(M.shape[:-2]), np.zeros(M.shape[:-2]), np.ones(M.shape[:-1])
    big = M.max(axis=(-2, -1), keepdims=True)
    P = M + 0.01 * np.where(big > 0.0, big, 1.0) / n
    lam, vec = np.linalg.eig(P)
    k = np.argmax(lam.real, axis=-1)
    v = np.abs(np.take_along_axis(vec, k[..., None, None], axis=-1)[..., 0].real)
    v = v / v.max(axis=-1, keepdims=True)
    v = np.maximum(v, 1e-8)  # (rounding of a vector with positive entries)
    with np.errstate(over="ignore"):  # entries near 1e308: the bound is inf, and the horizon is refused (no pieces)
        anorm = ((M @ v[..., None])[..., 0] / v).max(axis=-1)
    bw = (Bm.sum(axis=-1) / v).max(axis=-1) if Bm.shape[-1] else np.zeros(M.shape[:-2])
    return anorm, bw, np.ascontiguousarray(1.0 / v)


def _solve_channels(M: np.ndarray, what: str) -> np.ndarray:
    """``M^-1`` for ``M = I - D22`` of channels without delay, or an error saying the loop is not well posed."""
    if M.size == 0:
        return M
    if np.linalg.cond(M) > 1e12:
        raise InvalidValueError(f"the channels without delay ({what}) form an algebraic loop that is not well "
                                f"posed: I - D22 among them, {M.round(12).tolist()}, is singular")
    return np.linalg.inv(M)


def _eliminate(P: dict[str, np.ndarray], Z: list[int], R: list[int]) -> dict[str, np.ndarray]:
    """The LFT's matrices with the channels ``Z`` closed as the identity (w_Z = z_Z), keeping channels ``R``."""
    A, B1, B2, C1, C2 = P["A"], P["B1"], P["B2"], P["C1"], P["C2"]
    D11, D12, D21, D22 = P["D11"], P["D12"], P["D21"], P["D22"]
    Minv = _solve_channels(np.eye(len(Z)) - D22[Z][:, Z], f"channels {Z}")
    Kx = Minv @ C2[Z]
    Ku = Minv @ D21[Z]
    Kw = Minv @ D22[Z][:, R]
    B2Z, D12Z, D22RZ = B2[:, Z], D12[:, Z], D22[R][:, Z]
    return {"A": A + B2Z @ Kx, "B1": B1 + B2Z @ Ku, "B2": B2[:, R] + B2Z @ Kw,
            "C1": C1 + D12Z @ Kx, "D11": D11 + D12Z @ Ku, "D12": D12[:, R] + D12Z @ Kw,
            "C2": C2[R] + D22RZ @ Kx, "D21": D21[R] + D22RZ @ Ku, "D22": D22[R][:, R] + D22RZ @ Kw}


def _rel_degree(direct: np.ndarray, C: np.ndarray, A: np.ndarray, B: np.ndarray, deg: int) -> np.ndarray:
    """``R[i, j]``: 0 where ``direct[i, j] != 0``, else the least ``r >= 1`` with ``(C A^(r-1) B)[i, j] != 0``
    (``deg + 1`` when none up to ``deg``): the lowest derivative of output ``i`` that a jump of input ``j``
    moves.  One system's matrices, or stacks of them (leading axes)."""
    R = np.full(direct.shape, deg + 1, dtype=np.int64)
    if R.size == 0:
        return R

    def big(x: np.ndarray) -> np.ndarray:  # the largest entry of each matrix of a stack
        return np.abs(x).max(axis=(-2, -1), keepdims=True) if x.size else np.zeros(x.shape[:-2] + (1, 1))

    R[np.abs(direct) > 1e-14 * (big(direct) + 1.0)] = 0
    n = A.shape[-1]
    nA, nC, norm = np.maximum(big(A), 1e-300), big(C), big(B)
    P = B.copy()
    with np.errstate(over="ignore", invalid="ignore"):  # entries near 1e308: the powers overflow (the horizon
        for r in range(1, min(deg, n + 1) + 1):  # check refuses such a system); C A^k B, k >= n, adds nothing
            if not P.size or not C.size:
                break
            G = C @ P
            hit = (np.abs(G) > 1e-13 * np.maximum(nC * norm * n, 1e-300)) & (R > r)
            R[hit] = r
            P = A @ P
            norm = norm * nA
    return R


def _reduce_many(systems: list[Any], deg: int) -> list[_Reduced]:
    """:func:`_reduce` of each system, the work done on stacks of their matrices where every channel of every
    system has a delay and no limits (a parameter sweep of a linear loop); one by one otherwise."""
    if any(0.0 in sysk.delays or sysk.saturations for sysk in systems):
        return [_reduce(sysk, deg) for sysk in systems]
    P = {k: np.stack([np.asarray(getattr(sysk, k), float) for sysk in systems])
         for k in ("A", "B1", "B2", "C1", "C2", "D11", "D12", "D21", "D22")}
    tau = np.array([sysk.delays for sysk in systems], float)
    ns, m, n = len(systems), tau.shape[1], P["A"].shape[1]
    for k in np.flatnonzero(np.abs(P["D22"]).reshape(ns, -1).max(axis=1, initial=0.0) > 0.0):
        _check_neutral(P["D22"][k], list(range(m)), tau[k])
    Rw = _rel_degree(P["D22"], P["C2"], P["A"], P["B2"], deg)
    Ru = _rel_degree(P["D21"], P["C2"], P["A"], P["B1"], deg)
    rate = np.max(np.abs(np.linalg.eigvals(P["A"])), axis=-1) if n else np.zeros(ns)
    if m and n:  # the loop with its delays at 0, where it is well posed (as _reduce)
        M = np.eye(m) - P["D22"]
        ok = np.linalg.cond(M) <= 1e12
        if ok.any():
            A0 = P["A"][ok] + P["B2"][ok] @ (np.linalg.inv(M[ok]) @ P["C2"][ok])
            rate[ok] = np.maximum(rate[ok], np.max(np.abs(np.linalg.eigvals(A0)), axis=-1))
    lim = np.full(m, math.inf)
    anorm, bw, iw = _weights(np.abs(P["A"]), np.abs(P["B2"]))
    out = []
    for k in range(ns):
        mats = {key: np.ascontiguousarray(v[k]) for key, v in P.items()}
        out.append(_Reduced(**mats, tau=np.ascontiguousarray(tau[k]), lo=-lim, hi=lim.copy(), Rw=Rw[k],
                            Ru=Ru[k], AL=mats["A"], C2L=mats["C2"],
                            hmax=1.0 / rate[k] if rate[k] > 0.0 else math.inf, anorm=float(anorm[k]),
                            bw=float(bw[k]), iw=iw[k]))
    return out


def _reduce(sys: Any, deg: int) -> _Reduced:
    """The kernel's form of ``sys`` (see the module docstring), with the checks that refuse what it cannot do."""
    P = {k: np.asarray(getattr(sys, k), float) for k in ("A", "B1", "B2", "C1", "C2", "D11", "D12", "D21", "D22")}
    tau = np.asarray(sys.delays, float)
    lim = np.asarray(sys.limits, float).reshape(-1, 2)
    sat = np.isfinite(lim).any(axis=1)
    Z = [j for j in range(len(tau)) if tau[j] == 0.0 and not sat[j]]
    R = [j for j in range(len(tau)) if j not in Z]
    Q = _eliminate(P, Z, R) if Z else P
    tauR, limR = tau[R], lim[R]
    S = [k for k in range(len(R)) if tauR[k] == 0.0]  # saturations without delay
    D = [k for k in range(len(R)) if tauR[k] > 0.0]
    if S:
        DSS = Q["D22"][np.ix_(S, S)]
        if np.abs(DSS).max() > 0.0:
            i, j = np.argwhere(DSS != 0)[0]
            raise InvalidValueError(
                f"saturation channels {R[S[i]]} and {R[S[j]]} (no delay) feed each other directly (an algebraic loop "
                f"through saturations, D22 = {DSS[i, j]:g}): not supported; put a state or a delay between them")
    # every saturation linear: the small-signal system, for the relative degrees, the neutral check, the horizon
    L = _eliminate(Q, S, D) if S else Q
    _check_neutral(L["D22"], [R[k] for k in D], tauR[D])
    m = len(R)
    Rw = np.full((m, m), deg + 1, dtype=np.int64)
    if D:
        Rw[np.ix_(D, D)] = _rel_degree(L["D22"], L["C2"], L["A"], L["B2"], deg)
        if S:
            Rw[np.ix_(D, S)] = _rel_degree(Q["D22"][np.ix_(D, S)], L["C2"], L["A"], Q["B2"][:, S], deg)
    Ru = np.full((m, sys.ninputs), deg + 1, dtype=np.int64)
    if D:
        Ru[D] = _rel_degree(L["D21"], L["C2"], L["A"], L["B1"], deg)
    mats = [Q["A"], L["A"]] if S else [Q["A"]]
    if D:  # the loop's rates with its delays set to 0, where that loop is well posed
        try:
            mats.append(_eliminate(L, list(range(len(D))), [])["A"])
        except InvalidValueError:
            pass
    rate = max((float(np.max(np.abs(np.linalg.eigvals(M)))) for M in mats if M.size), default=0.0)
    hmax = 1.0 / rate if rate > 0.0 else math.inf
    C2L = np.zeros((m, sys.nstates))
    if D:
        C2L[D] = L["C2"]
    # the kernel's remainder bound: |A| + |B2_S| |C2_S| bounds the states' matrix entrywise in every regime of the
    # saturations without delay (linear: A + B2_S C2_S, D22 among them being 0; at a limit: A), and so on for B2
    absA, absB = np.abs(Q["A"]), np.abs(Q["B2"][:, D])
    if S:
        absA = absA + np.abs(Q["B2"][:, S]) @ np.abs(Q["C2"][S])
        absB = absB + np.abs(Q["B2"][:, S]) @ np.abs(Q["D22"][np.ix_(S, D)])
    anorm, bw, iw = _weights(absA, absB)
    return _Reduced(**{k: np.ascontiguousarray(v) for k, v in Q.items()}, tau=np.ascontiguousarray(tauR),
                    lo=np.ascontiguousarray(limR[:, 0] if m else np.zeros(0)),
                    hi=np.ascontiguousarray(limR[:, 1] if m else np.zeros(0)), Rw=Rw, Ru=Ru, AL=L["A"], C2L=C2L,
                    hmax=hmax, anorm=float(anorm), bw=float(bw), iw=iw)


def _check_neutral(D: np.ndarray, channels: list[int], tau: np.ndarray) -> None:
    """Refuse a difference operator ``z = D diag(z_j(t - tau_j))`` that is not strongly stable (see the module
    docstring): its jumps fade only when the channels' abscissa (:func:`delaykit.systems.channel_abscissa`, an
    upper bound of the supremum over independent phases) is below zero.  A retarded system passes at once."""
    if not D.size or not np.abs(D).max() > 0.0:
        return
    if float(np.max(np.abs(np.linalg.eigvals(np.abs(D))))) < 1.0:
        return  # rho(D Theta) <= rho(|D|) < 1 for every diagonal unitary Theta: strongly stable, no search needed
    from ..systems.difference import channel_abscissa

    ca = channel_abscissa(D, [float(t) for t in tau])
    if ca.strongly_stable:
        return
    delays = ", ".join(f"{t:g}" for t in tau)
    if ca.exact:
        raise InvalidValueError(
            f"the system is neutral and its difference operator (delay channels {channels}, delays [{delays}] s) is "
            f"not strongly stable: its root chains reach Re s = {ca.abscissa:.6g} >= 0 for some delays near these "
            f"(channel abscissa), so its jumps do not fade: its time response is not computed")
    raise InvalidValueError(
        f"the system is neutral and strong stability of its difference operator (delay channels {channels}, delays "
        f"[{delays}] s) could not be shown: its channel abscissa is at most {ca.abscissa:.6g}, not below 0 (the "
        f"bounds did not meet): its time response is not computed")


# -- inputs --------------------------------------------------------------------------------------------------

def _check_system(sys: Any) -> Any:
    """``sys`` as a :class:`~delaykit.systems.DelayLTI` (a loop's closed-loop system, :attr:`Loop.system
    <delaykit.models.loop.Loop.system>`), or an error."""
    from ..systems.build import system_of
    from ..systems.lti import DelayLTI

    sys = system_of(sys)
    if not isinstance(sys, DelayLTI):
        raise InvalidTypeError(f"a DelayLTI is expected (build one with delaykit.tf or ss) or a Loop, got "
                               f"{type(sys).__name__}")
    return sys


def _times(T: Any, name: str = "T") -> np.ndarray:
    if isinstance(T, (str, bytes)):
        raise InvalidTypeError(f"{name} must be times in seconds (numbers), got {reprlib.repr(T)}")
    try:
        arr = np.asarray(T)
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be an array of times in seconds, got {reprlib.repr(T)}") from exc
    if arr.dtype.kind not in "iuf":
        raise InvalidTypeError(f"{name} must be real times in seconds, got an array of dtype {arr.dtype}")
    check_count(f"{name}: a response", arr.size, MAX_SAMPLES, "times", "ask for fewer times")  # (before the copy)
    arr = np.atleast_1d(arr.astype(float))
    if arr.ndim != 1 or arr.size == 0:
        raise InvalidValueError(f"{name} must be a non-empty one-dimensional array of times, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidValueError(f"{name} must be finite, got {float(arr[~np.isfinite(arr)][0])!r}")
    if np.any(np.diff(arr) <= 0):
        k = int(np.argmax(np.diff(arr) <= 0))
        raise InvalidValueError(f"{name} must be strictly increasing, got {arr[k]:g} then {arr[k + 1]:g}")
    return arr


def default_horizon(sys: Any) -> float:
    """The end of a response's times when none are given: 7 time constants of the slowest decaying mode of the
    system with its delays set to 0 and its saturations linear (the rate ``|Re lambda|`` of its states' matrix's
    slowest stable eigenvalue), plus 3 times the longest delay; 10 s plus 3 times the longest delay when no
    eigenvalue decays (integrators, unstable or static systems).

    Examples
    --------
    >>> from delaykit import tf
    >>> default_horizon(tf("exp(-2*s)/(s+1)"))     # 7 x 1 s + 3 x 2 s
    13.0
    """
    sys = _check_system(sys)
    P = {k: np.asarray(getattr(sys, k), float) for k in ("A", "B1", "B2", "C1", "C2", "D11", "D12", "D21", "D22")}
    m = len(sys.delays)
    try:
        L = _eliminate(P, list(range(m)), []) if m else P
        eig = np.linalg.eigvals(L["A"]) if L["A"].size else np.zeros(0)
    except InvalidValueError:
        eig = np.linalg.eigvals(P["A"]) if P["A"].size else np.zeros(0)
    tmax = max(sys.delays, default=0.0)
    decay = -eig.real[eig.real < -1e-9 * max(1.0, float(np.abs(eig).max(initial=0.0)))]
    base = 7.0 / float(decay.min()) if decay.size else 10.0
    return float(base + 3.0 * tmax)


def _default_times(sys: Any, T: Any) -> np.ndarray:
    if T is None:
        return np.linspace(0.0, default_horizon(sys), _NPOINTS)
    if np.ndim(T) == 0 and not isinstance(T, (str, bytes)):
        tf = _times(T)[0]
        if tf <= 0:
            raise InvalidValueError(f"T must be a positive horizon or an array of times, got {tf:g}")
        return np.linspace(0.0, tf, _NPOINTS)
    t = _times(T)
    if t[0] < 0:
        raise InvalidValueError(f"T must be times >= 0 s (the response starts at 0), got {t[0]:g}")
    return t


def _initial_state(sys: Any, X0: Any) -> np.ndarray:
    n = sys.nstates
    x = check_finite_array("X0", X0)
    if x.ndim == 0:
        x = np.full(n, float(x))
    x = x.ravel()
    if x.size != n:
        raise InvalidValueError(f"X0 must have {n} entries (the system's states), got {x.size}")
    return x


def _check_horizon(red: _Reduced, t_end: float) -> None:
    """Refuse before the run a horizon that needs more pieces than the budget allows: a piece is at most
    ``red.hmax`` long, so ``t_end / hmax`` is a lower bound of the count."""
    from ..models import budget  # the module's limit (a test may shrink this module's MAX_PIECES to truncate)

    if t_end > 0.0 and math.isfinite(red.hmax):
        with np.errstate(over="ignore", divide="ignore"):  # (an infinite count is refused as any too large)
            pieces = float(np.float64(t_end) / red.hmax)
        budget.check_count(f"T: a horizon of {t_end:g} s", pieces, budget.MAX_PIECES, "pieces at least",
                           f"each piece is at most {red.hmax:.3g} s (the system's fastest time scale); ask for a "
                           "shorter horizon")
        m = len(red.tau)
        if m:  # each piece keeps a polynomial per delay channel
            budget.check_count(f"T: a horizon of {t_end:g} s with {m} delay channels", t_end / red.hmax * m,
                               budget.MAX_PIECE_CHANNELS, "pieces x channels at least",
                               f"each piece is at most {red.hmax:.3g} s (the system's fastest time scale); ask for "
                               "a shorter horizon or use fewer delays")


# -- one run ---------------------------------------------------------------------------------------------------

_STATUS = {0: "exact", 2: "stalled", 3: "overflow"}
_SHORTEST = 1e-12
"""s: the shortest horizon a run is made to (the kernel resolves times to 1.4e-14 s); the outputs at earlier times
are read from it."""


def _horizon(t_end: float) -> tuple[float, float]:
    """The horizon the kernel runs to for outputs up to ``t_end``, and its time tolerance.

    The kernel takes times within the tolerance (1.4e-14 s up to 1 s) as equal: a horizon that short was "reached"
    before the first piece (no outputs, all NaN, yet "exact"); such a run goes on to :data:`_SHORTEST` and the
    outputs are read at the times asked (a horizon of 0, times at 0 only, runs a first piece for the right limits).
    """
    t_end = t_end if t_end > 0.0 else 1.0
    t_end = max(t_end, _SHORTEST)
    return t_end, 64.0 * np.finfo(float).eps * max(1.0, t_end)


def _honest(status: str, reached: float, out: np.ndarray, tq: np.ndarray) -> tuple[str, float]:
    """Never NaN labelled exact: an "exact" run with an output missing at a time asked stalled there."""
    lost = np.isnan(out).reshape(-1, tq.size).any(axis=0)
    if status == "exact" and lost.any():
        return "stalled", float(tq[np.argmax(lost)])
    return status, reached


def _run(red: _Reduced, ut: np.ndarray, uvs: np.ndarray, x0: np.ndarray, tq: np.ndarray, t_end: float,
         deriv: bool = False, jumps: bool = False) -> list[tuple[np.ndarray, str, int, float, np.ndarray, np.ndarray]]:
    """Kernel runs, one per input column ``uvs[k]`` (the inputs' values at the knots ``ut``), in one call: for each,
    the outputs at ``tq`` (relative to the start), status, pieces, time reached, output jumps."""
    _check_horizon(red, t_end)
    K = _kernel()
    c_ = np.ascontiguousarray
    deg = K.DEG
    m, ny = len(red.tau), red.C1.shape[0]
    ncol = uvs.shape[0]
    check_count(f"a response at {tq.size} times x {ny} outputs x {ncol} runs", float(tq.size) * ny * ncol,
                MAX_SAMPLES, "values", "ask for fewer times")
    most = max(1024, MAX_PIECE_CHANNELS // max(m, 1))  # the history's pieces x channels stay within the budget
    R0 = red.R0 if not x0.any() else np.full(m, deg + 1, dtype=np.int64)
    if x0.any() and m:
        v = x0.copy()
        for r in range(deg + 1):
            hit = (np.abs(red.C2L @ v) > 0.0) & (R0 > r)
            R0[hit] = r
            v = red.AL @ v
    t_end, tol = _horizon(t_end)
    hmax = min(red.hmax, t_end)
    most = min(most, MAX_PIECES)
    cap = min(1024, most)
    while True:
        out = np.full((ncol, ny, tq.size), np.nan)
        hist_t, hist_h, hist_n = np.zeros(cap), np.zeros(cap), np.zeros(cap, dtype=np.int64)
        hist_c = np.zeros((cap, m, K.NC))
        bp_t, bp_o = np.zeros((m, cap)), np.zeros((m, cap), dtype=np.int64)
        bp_n = np.zeros(m, dtype=np.int64)
        jcap = cap if jumps else 0
        jump_t, jump_v = np.zeros((ncol, jcap)), np.zeros((ncol, jcap, ny))
        info = np.zeros((ncol, K.NINFO))
        K.run(red.A, red.B1, red.B2, red.C1, red.C2, red.D11, red.D12, red.D21, red.D22, *red.csr, red.tau,
              red.lo, red.hi, c_(ut), c_(uvs), c_(x0), red.Rw, red.Ru, R0, c_(tq), bool(deriv), float(t_end),
              float(hmax), red.anorm, red.bw, red.iw, float(tol), out, hist_t, hist_h, hist_n, hist_c, bp_t, bp_o, bp_n,
              jump_t, jump_v, info)
        if (info[:, 0] == K.STATUS_CAPACITY).any() and cap < most:
            cap = min(cap * 4, most)
            continue
        res = []
        for k in range(ncol):
            status, nj = int(info[k, 0]), int(info[k, 2])
            st, reached = "truncated" if status == K.STATUS_CAPACITY else _STATUS[status], float(info[k, 3])
            st, reached = _honest(st, reached, out[k], tq)
            res.append((out[k], st, int(info[k, 1]), reached, jump_t[k, :nj], jump_v[k, :nj]))
        return res


def _plan(sys: Any) -> _Reduced:
    """The kernel's form of ``sys`` (:func:`_reduce`), computed once per system: a :class:`DelayLTI` is frozen and
    its arrays are read-only, so a second response of the same object (other times, another kind) starts at the
    kernel.  Held only as long as the system is."""
    red = _PLANS.get(sys)
    if red is None:
        red = _reduce(sys, _kernel().DEG)
        _PLANS[sys] = red
    return red


_PLANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _columns(sys: Any, T: Any, deriv: bool, kind: str) -> SystemTimeResponse:
    sys = _check_system(sys)
    t = _default_times(sys, T)
    red = _plan(sys)
    ny, nu = sys.noutputs, sys.ninputs
    out = np.full((ny, nu, t.size), np.nan)
    pieces, reached, statuses, impulses = 0, math.inf, [], []
    runs = _run(red, np.zeros(1), np.eye(nu).reshape(nu, 1, nu), np.zeros(sys.nstates), t, float(t[-1]), deriv,
                deriv)
    for j, (y, st, p, tr, jt, jv) in enumerate(runs):
        out[:, j] = y
        pieces += p
        statuses.append(st)
        reached = min(reached, tr)
        for tk, vk in zip(jt, jv):
            impulses += [(float(tk), i, j, float(vk[i])) for i in range(ny) if vk[i] != 0.0]
    status = next((s for s in statuses if s != "exact"), "exact")
    return SystemTimeResponse(t, out, sys.outputs, sys.inputs, kind, status, pieces,
                              float(t[-1]) if status == "exact" else reached, tuple(sorted(impulses)))


# -- the public calls -------------------------------------------------------------------------------------------

def step_response(sys: Any, T: Any = None) -> SystemTimeResponse:
    """The exact unit-step response of each input, shaped ``(outputs, inputs, times)`` as python-control's.

    Parameters
    ----------
    sys : DelayLTI or Loop
        The system (delays, saturation channels, neutral with a strongly stable difference operator); a
        :class:`~delaykit.models.Loop` or ``AltitudeLoop`` stands for its closed loop :attr:`Loop.system
        <delaykit.models.loop.Loop.system>` (inputs ``r``, ``d``; outputs ``y``, ``u``).
    T : array_like or float, optional
        Times (s, increasing, >= 0), or a horizon (1001 times from 0 to it); default :func:`default_horizon`.

    Returns
    -------
    SystemTimeResponse
        ``outputs[i, j, k]``: output ``i`` at ``T[k]`` for a unit step of input ``j`` at 0 (the others 0), right
        limits at a jump.

    Raises
    ------
    InvalidValueError
        An algebraic loop that is not well posed, saturations in an algebraic loop with each other, a neutral
        system whose difference operator is not strongly stable, bad times.

    See Also
    --------
    impulse_response, initial_response, forced_response, delaykit.simulate.simulate

    Examples
    --------
    >>> from delaykit import tf
    >>> r = tf("exp(-0.5*s)/(s+1)").step([0.0, 0.5, 1.5])
    >>> r.outputs.shape
    (1, 1, 3)
    >>> round(float(r.outputs[0, 0, 2]), 12) == round(1 - 2.718281828459045 ** -1, 12)
    True
    """
    return _columns(sys, T, False, "step")


def impulse_response(sys: Any, T: Any = None) -> SystemTimeResponse:
    """The exact unit-impulse response of each input, shaped ``(outputs, inputs, times)``.

    The response of a linear system to a Dirac impulse is the derivative of its step response: here, the
    derivative of the step response's Taylor pieces (exact, right limits at a breakpoint).  Its Dirac terms (the
    jumps of the step response: the direct feedthrough ``D11`` at 0 and every delayed image of a path without a
    state, such as a pure delay's) are returned apart in :attr:`SystemTimeResponse.impulses` as ``(time, output,
    input, weight)``; :attr:`~SystemTimeResponse.outputs` hold the regular part.  (python-control drops ``D`` with
    a warning.)

    Parameters
    ----------
    sys : DelayLTI
        A linear system: an impulse through a saturation has no meaning, so saturation channels are refused
        (simulate ``initial_response`` from ``X0 = B1[:, j]`` or ``forced_response`` with a short pulse instead).
    T : array_like or float, optional
        As :func:`step_response`.

    Examples
    --------
    >>> from delaykit import tf
    >>> r = tf("2*exp(-s)").impulse([0.0, 2.0])
    >>> r.outputs.tolist(), r.impulses            # all of it is a Dirac of weight 2 at 1 s
    ([[[0.0, 0.0]]], ((1.0, 0, 0, 2.0),))
    >>> r = tf("exp(-s)/(s+1)").impulse([0.5, 1.0, 2.0])
    >>> r.outputs[0, 0].round(6).tolist()       # exp(-(t - 1)) after 1 s
    [0.0, 1.0, 0.367879]
    """
    sys = _check_system(sys)
    if sys.saturations:
        raise InvalidValueError(f"{sys!r} has saturation channels {list(sys.saturations)}: an impulse through a "
                                "saturation has no meaning; use initial_response from X0 = B1[:, j] or "
                                "forced_response with a pulse, or impulse_response(sys.without_limits())")
    return _columns(sys, T, True, "impulse")


def initial_response(sys: Any, T: Any = None, X0: Any = 0.0) -> SystemTimeResponse:
    """The exact free response from the states ``X0`` at 0 (inputs 0, the delay lines empty before 0), shaped
    ``(outputs, times)``.

    Examples
    --------
    >>> from delaykit import ss
    >>> r = ss([[-1.0]], [[0.0]], [[1.0]], [[0.0]]).initial([0.0, 1.0], X0=2.0)
    >>> r.outputs.round(6).tolist()
    [[2.0, 0.735759]]
    """
    sys = _check_system(sys)
    t = _default_times(sys, T)
    x0 = _initial_state(sys, X0)
    y, st, p, tr, _, _ = _run(_plan(sys), np.zeros(1), np.zeros((1, 1, sys.ninputs)), x0, t, float(t[-1]))[0]
    return SystemTimeResponse(t, y, sys.outputs, sys.inputs, "initial", st, p, float(t[-1]) if st == "exact" else tr)


def forced_response(sys: Any, T: Any, U: Any, X0: Any = 0.0) -> SystemTimeResponse:
    """The exact response to the input ``U``, linear between the times ``T`` (as python-control's
    ``forced_response``, for which this is exact), from the states ``X0`` at ``T[0]``; shaped ``(outputs,
    times)``.

    Parameters
    ----------
    sys : DelayLTI or Loop
        A loop stands for its closed loop, as in :func:`step_response`.
    T : array_like
        Times (s), strictly increasing; the system starts at ``T[0]`` (every signal 0 before it).
    U : array_like
        ``(inputs, len(T))`` (or ``(len(T),)`` for one input, or a number held constant); held at its last value
        past ``T[-1]`` (not needed: the response ends there).
    X0 : float or array_like
        The states at ``T[0]``.

    Examples
    --------
    >>> import numpy as np
    >>> from delaykit import tf
    >>> r = tf("exp(-s)/s").lsim([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 1.0, 1.0])   # a ramp to 1, then held
    >>> r.outputs.tolist()            # the integral of the input one second late
    [[0.0, 0.0, 0.5, 1.5]]
    """
    sys = _check_system(sys)
    t = _times(T)
    nu = sys.ninputs
    u = check_finite_array("U", U)
    if u.ndim == 0:
        u = np.full((nu, t.size), float(u))
    elif u.ndim == 1 and nu == 1 and u.size == t.size:
        u = u[None, :]
    if u.shape != (nu, t.size):
        raise InvalidValueError(f"U must have shape ({nu}, {t.size}) (inputs, times), got {u.shape}")
    x0 = _initial_state(sys, X0)
    rel = t - t[0]
    y, st, p, tr, _, _ = _run(_plan(sys), np.ascontiguousarray(rel), u.T[None], x0, rel, float(rel[-1]))[0]
    return SystemTimeResponse(t, y, sys.outputs, sys.inputs, "forced", st, p,
                              float(t[-1]) if st == "exact" else tr + float(t[0]))


# -- many systems of one shape ---------------------------------------------------------------------------------

_BATCH_CAP = 4096  # pieces per job in the parallel run; a job needing more is rerun alone with room to grow


@dataclass(frozen=True, repr=False, eq=False)
class BatchTimeResponse:
    """The step responses of many systems of one shape (:func:`step_response_many`).

    Attributes
    ----------
    time : ndarray
        ``(nt,)``.
    outputs : ndarray
        ``(systems, outputs, inputs, nt)``: ``outputs[k]`` is system ``k``'s :attr:`SystemTimeResponse.outputs`.
    status : tuple of str
        Each system's status (:data:`STATUSES`).
    pieces : ndarray
        Taylor pieces per system (its input columns together).
    output_labels, input_labels : tuple of str
        The first system's signal names.
    """

    time: np.ndarray
    outputs: np.ndarray
    status: tuple[str, ...]
    pieces: np.ndarray
    output_labels: tuple[str, ...]
    input_labels: tuple[str, ...]

    def __len__(self) -> int:
        return self.outputs.shape[0]

    def __getitem__(self, k: int) -> SystemTimeResponse:
        """System ``k``'s response as a :class:`SystemTimeResponse`."""
        st = self.status[k]
        y = self.outputs[k]
        reached = float(self.time[-1]) if st == "exact" else float(
            self.time[np.argmax(~np.isfinite(y).all(axis=(0, 1)))])
        return SystemTimeResponse(self.time, y, self.output_labels, self.input_labels, "step", st,
                                  int(self.pieces[k]), reached)

    def to_dict(self) -> dict[str, Any]:
        """Strict JSON (NaN as ``None``)."""
        out = self.outputs
        return {"time": self.time.tolist(), "status": list(self.status), "pieces": self.pieces.tolist(),
                "output_labels": list(self.output_labels), "input_labels": list(self.input_labels),
                "outputs": [[[[float(v) if math.isfinite(v) else None for v in row] for row in mat] for mat in sysk]
                            for sysk in out]}

    def __repr__(self) -> str:
        ns, ny, nu, nt = self.outputs.shape
        bad = sum(s != "exact" for s in self.status)
        return (f"BatchTimeResponse({ns} step response{'s' * (ns != 1)}: {ny} output{'s' * (ny != 1)} x {nu} "
                f"input{'s' * (nu != 1)} at {nt} times, {self.time[0]:g} to {self.time[-1]:g} s, "
                + ("all exact" if not bad else f"{bad} not exact") + f", {int(self.pieces.sum())} pieces)")


def _thread_rows(nth: int, width: int, dtype: Any) -> np.ndarray:
    """Zeros with a row of at least ``width`` numbers per thread (the kernel uses the first ``width``), each row on
    cache lines of its own: in a plain ``(nth, width)`` array the small rows (``bp_n``, ``I1``, ``F1``), written on
    every piece, shared a 64-byte line between two threads, which then took turns owning it."""
    line = 128 // np.dtype(dtype).itemsize  # two lines of 64 bytes: also past the adjacent-line prefetcher
    return np.zeros((nth, -(-width // line) * line + line), dtype=dtype)


def step_response_many(systems: Any, T: Any = None) -> BatchTimeResponse:
    """The exact step responses of many systems of one shape (the same numbers of states, inputs, outputs and
    delay channels, and the same channels without delay: a parameter sweep), in parallel threads where the kernel
    was compiled with OpenMP.

    Each answer equals :func:`step_response`'s for that system (the same kernel on each); a system that needs more
    than 4096 pieces per input is rerun alone, with room to grow.

    Parameters
    ----------
    systems : sequence of DelayLTI
    T : array_like or float, optional
        As :func:`step_response`; by default the first system's horizon.

    Examples
    --------
    >>> from delaykit import tf, feedback
    >>> loops = [feedback(tf(f"{k}*exp(-s)/(s+1)"), 1) for k in (0.5, 1.0)]
    >>> r = step_response_many(loops, [0.0, 5.0, 20.0])
    >>> r
    BatchTimeResponse(2 step responses: 1 output x 1 input at 3 times, 0 to 20 s, all exact, 94 pieces)
    >>> r.outputs[:, 0, 0, -1].round(4).tolist()     # k / (1 + k) in the end
    [0.3333, 0.5]
    """
    try:
        systems = list(systems)
    except TypeError:
        raise InvalidTypeError(f"systems must be a sequence of DelayLTI, got {type(systems).__name__}") from None
    if not systems:
        raise InvalidValueError("systems is empty: give at least one DelayLTI")
    for sysk in systems:
        _check_system(sysk)
    first = systems[0]
    t = _default_times(first, T)
    K = _kernel()
    for k, sysk in enumerate(systems):
        shape = (sysk.nstates, sysk.ninputs, sysk.noutputs, sysk.ndelays)
        if shape != (first.nstates, first.ninputs, first.noutputs, first.ndelays) or \
                [d == 0 for d in sysk.delays] != [d == 0 for d in first.delays]:
            raise InvalidValueError(f"system {k} ({sysk!r}) is not of the first one's shape ({first!r}): the same "
                                    "numbers of states, inputs, outputs and delay channels, and the same channels "
                                    "without delay, are needed")
    reds = _reduce_many(systems, K.DEG)
    if len({len(r.tau) for r in reds}) > 1 or len({tuple(np.isfinite(r.lo) | np.isfinite(r.hi)) for r in reds}) > 1:
        raise InvalidValueError("the systems' saturation channels differ: give systems of one structure")
    ns, nu, ny = len(systems), first.ninputs, first.noutputs
    check_count(f"{ns} responses at {t.size} times x {ny} outputs x {nu} inputs", float(ns) * nu * ny * t.size,
                MAX_SAMPLES, "values", "ask for fewer times or systems")
    out = np.full((ns * nu, ny, t.size), np.nan)
    info = np.zeros((ns * nu, K.NINFO))
    t_end, tol = _horizon(float(t[-1]))
    stack = {k: np.ascontiguousarray(np.stack([getattr(r, k) for r in reds]))
             for k in ("A", "B1", "B2", "C1", "C2", "D11", "D12", "D21", "D22", "tau", "lo", "hi", "Rw", "Ru")}
    hmax = np.array([min(r.hmax, t_end) for r in reds])
    uvs = np.eye(nu).reshape(nu, 1, nu).copy()
    m, n = len(reds[0].tau), first.nstates
    R0 = np.full(m, K.DEG + 1, dtype=np.int64)
    if K.COMPILED:
        import os

        nth = max(1, os.cpu_count() or 1)
        rows, nf, ni = K.work_sizes(n, nu, m, ny)
        cap = max(16, min(_BATCH_CAP, MAX_PIECE_CHANNELS // (nth * max(m, 1))))  # (a run needing more is redone)
        csrs = [r.csr for r in reds]
        packed = []  # each system's compressed rows, the columns and values padded to the longest
        for q in range(9):
            parts = [c[q] for c in csrs]
            width = max(1, max(p.size for p in parts))
            arr = np.zeros((ns, width), dtype=parts[0].dtype)
            for k, p in enumerate(parts):
                arr[k, :p.size] = p
            packed.append(arr)
        K.run_batch(stack["A"], stack["B1"], stack["B2"], stack["C1"], stack["C2"], stack["D11"], stack["D12"],
                    stack["D21"], stack["D22"], *packed, stack["tau"], stack["lo"], stack["hi"], np.zeros(1), uvs,
                    np.zeros(n), stack["Rw"], stack["Ru"], R0, t, False, t_end, hmax,
                    np.array([r.anorm for r in reds]), np.array([r.bw for r in reds]),
                    np.stack([r.iw for r in reds]), tol, out,
                    np.zeros((nth, cap)), np.zeros((nth, cap)), np.zeros((nth, cap), dtype=np.int64),
                    np.zeros((nth, cap, m, K.NC)),
                    np.zeros((nth, m, cap)), np.zeros((nth, m, cap), dtype=np.int64),
                    _thread_rows(nth, m, np.int64), np.zeros((nth, 0)), np.zeros((nth, 0, ny)), info,
                    np.zeros((nth, rows, K.NC)), _thread_rows(nth, nf, float), _thread_rows(nth, ni, np.int64))
        redo = [k for k in range(ns * nu) if int(info[k, 0]) == K.STATUS_CAPACITY]
    else:
        redo = list(range(ns * nu))
    status = ["exact"] * ns
    pieces = np.zeros(ns, dtype=np.int64)
    for k in range(ns * nu):
        s_, j = divmod(k, nu)
        if k in redo:
            y, st, p, _, _, _ = _run(reds[s_], np.zeros(1), uvs[j:j + 1], np.zeros(n), t, t_end)[0]
            out[k] = y
        else:
            st, p = _STATUS[int(info[k, 0])], int(info[k, 1])
            st, _ = _honest(st, t_end, out[k], t)
        pieces[s_] += p
        if st != "exact" and status[s_] == "exact":
            status[s_] = st
    outputs = out.reshape(ns, nu, ny, t.size).transpose(0, 2, 1, 3).copy()
    return BatchTimeResponse(t, outputs, tuple(status), pieces, first.outputs, first.inputs)
