"""Exact zero-order-hold discretisation of a delay system whose delays act on its inputs.

With the inputs held over each period ``h`` (a zero-order hold), a delay channel that reads only the inputs
(``z_j = D21_j u``: no state, no other channel) delivers a piecewise-constant signal shifted by
``tau_j = m_j h + f_j``: over each period it is the input of ``m_j + 1`` periods ago for the first ``f_j`` seconds,
then that of ``m_j`` periods ago.  Integrating the states over the two pieces (:func:`delaykit.models.hold.
hold_matrices`) and keeping the last inputs in a shift register gives a finite discrete-time system that is exact
at the sampling instants, fractional delays included (as MATLAB's ``c2d`` of input delays).  Every transfer matrix
made by :func:`delaykit.tf` has this form (each entry's delay sits on its input).

A delay inside a loop (a channel that reads the states) makes the sampled system infinite-dimensional: such
systems are refused, unless ``thiran_order`` asks for the approximation MATLAB makes (the delayed signals taken as
held, each delay as whole periods times a Thiran all-pass filter for the fraction).

Examples
--------
>>> from delaykit import tf
>>> Gd = c2d(tf("exp(-0.25*s)/(s+1)"), 0.1)
>>> Gd
DiscreteLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 4 states, period 0.1 s)
>>> round(float(Gd.frequency_response([0.0]).response[0, 0, 0].real), 12)
1.0
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real, plain
from ..models import budget
from ..models.budget import MAX_MATRIX_ELEMENTS, check_count
from ..models.hold import hold_matrices, split_delay
from ..models.interop import require_control
from .algebra import blockdiag, close_parts
from .lti import DelayLTI, SystemResponse, as_frequencies

__all__ = ["DiscreteLTI", "c2d", "thiran", "thiran_coefficients", "absorb_delay"]


@dataclass(frozen=True, repr=False, eq=False)
class DiscreteLTI:
    """``x[k+1] = A x[k] + B u[k - d_in]``, ``y[k] = C x[k] + D u[k - d_in]`` delayed by ``d_out`` at the outputs,
    with period ``period`` (s), from :func:`c2d` or :func:`thiran`.

    ``input_delay`` and ``output_delay`` are whole numbers of periods, one per input and per output (empty: none;
    MATLAB's ``InputDelay`` and ``OutputDelay`` of a discrete model); :func:`absorb_delay` turns them into states.
    The systems delaykit makes carry none (their delays are states already).

    Examples
    --------
    >>> g = DiscreteLTI(np.array([[0.5]]), np.array([[1.0]]), np.array([[1.0]]), np.array([[0.0]]), 0.1,
    ...                 ("u",), ("y",), input_delay=(2,))
    >>> g
    DiscreteLTI(1 input ['u'] -> 1 output ['y'], 1 state, period 0.1 s, input delays [2])
    >>> absorb_delay(g)
    DiscreteLTI(1 input ['u'] -> 1 output ['y'], 3 states, period 0.1 s)
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    period: float
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    input_delay: tuple[int, ...] = ()
    output_delay: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        for name, k in (("input_delay", self.B.shape[1]), ("output_delay", self.C.shape[0])):
            d = getattr(self, name)
            if isinstance(d, numbers.Integral) and not isinstance(d, (bool, np.bool_)):
                d = (d,) * k
            d = tuple(d)
            if d and (len(d) != k or any(isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Integral)
                                         or x < 0 for x in d)):
                raise InvalidValueError(f"{name} must be {k} whole numbers of periods (at least 0), one per "
                                        f"{name.split('_')[0]}, got {plain(getattr(self, name))!r}")
            object.__setattr__(self, name, tuple(int(x) for x in d) if any(d) else ())

    def frequency_response(self, w: Any) -> SystemResponse:
        """``C (zI - A)^-1 B + D`` at ``z = exp(j w h)``, shaped ``(outputs, inputs, len(w))``, times
        ``z^-d`` for the input and output delays."""
        w = as_frequencies(w)
        z = np.exp(1j * w * self.period)
        n, (ny, nu) = self.A.shape[0], self.D.shape
        budget.check_response(w.size, ny, nu)
        H = np.empty((w.size, ny, nu), complex)
        for b in budget.blocks(w.size, n * (n + nu) + ny * nu):  # bounded work memory
            with np.errstate(all="ignore"):
                X = np.linalg.solve(z[b][:, None, None] * np.eye(n) - self.A,
                                    np.broadcast_to(self.B, (z[b].size,) + self.B.shape))
                H[b] = self.C @ X + self.D
        H = np.moveaxis(H, 0, -1)
        if self.input_delay:
            H = H * z ** -np.array(self.input_delay, float)[None, :, None]
        if self.output_delay:
            H = H * z ** -np.array(self.output_delay, float)[:, None, None]
        return SystemResponse(w, H, self.inputs, self.outputs)

    def to_control(self) -> Any:
        """A discrete-time python-control ``StateSpace`` (``dt = period``), the delays as states
        (:func:`absorb_delay`)."""
        control = require_control("to_control()")
        d = absorb_delay(self)
        return control.ss(d.A, d.B, d.C, d.D, d.period, inputs=list(d.inputs), outputs=list(d.outputs))

    def __repr__(self) -> str:
        nu, ny, n = self.B.shape[1], self.C.shape[0], self.A.shape[0]
        delays = "".join(f", {k.split('_')[0]} delays {list(getattr(self, k))}" for k in ("input_delay", "output_delay")
                         if getattr(self, k))
        return (f"DiscreteLTI({nu} input{'s' * (nu != 1)} {list(self.inputs)} -> {ny} output{'s' * (ny != 1)} "
                f"{list(self.outputs)}, {n} state{'s' * (n != 1)}, period {self.period:g} s{delays})")


def absorb_delay(dsys: DiscreteLTI) -> DiscreteLTI:
    """The same discrete system with its input and output delays turned into states (as MATLAB's ``absorbDelay``).

    An input delayed by ``d`` periods passes a shift register of ``d`` states before the system, an output one
    after it; the transfer matrix is unchanged (exact: a discrete delay is a finite shift).

    Parameters
    ----------
    dsys : DiscreteLTI

    Returns
    -------
    DiscreteLTI
        Without delays: the inputs' registers first, then the system's states, then the outputs' registers.

    Examples
    --------
    >>> g = DiscreteLTI(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[2.0]]), 1.0, ("u",),
    ...                 ("y",), input_delay=(3,))
    >>> d = absorb_delay(g)
    >>> d.A.shape, bool(abs(d.frequency_response([0.5]).response[0, 0, 0] - 2 * np.exp(-1.5j)) < 1e-12)
    ((3, 3), True)
    """
    if not isinstance(dsys, DiscreteLTI):
        raise InvalidTypeError(f"absorb_delay takes a DiscreteLTI, got {type(dsys).__name__}")
    if not dsys.input_delay and not dsys.output_delay:
        return dsys
    nu, ny = dsys.B.shape[1], dsys.C.shape[0]
    ind = dsys.input_delay or (0,) * nu
    outd = dsys.output_delay or (0,) * ny
    ins = [_shift(k) for k in ind]  # each input's register, then the system, then each output's
    sysp = (dsys.A, dsys.B, dsys.C, dsys.D)
    pre = tuple(blockdiag(*(f[i] for f in ins)) for i in range(4))
    post = tuple(blockdiag(*(f[i] for f in (_shift(k) for k in outd))) for i in range(4))
    A, B, C, D = _series(_series(pre, sysp), post)
    for mat in (A, B, C, D):
        mat.setflags(write=False)
    return DiscreteLTI(A, B, C, D, dsys.period, dsys.inputs, dsys.outputs)


def c2d(sys: DelayLTI, period: float, *, thiran_order: int | None = None) -> DiscreteLTI:
    """The exact zero-order-hold discretisation of a system whose delays act on its inputs (or, with
    ``thiran_order``, an approximate one of any retarded or neutral system).

    Parameters
    ----------
    sys : DelayLTI
        Without ``thiran_order``, every delay channel must read the inputs only (``C2 = 0``, ``D22 = 0``), as in
        every transfer matrix made by :func:`delaykit.tf`.
    period : float
        The sampling period ``h`` (s), positive.
    thiran_order : int, optional
        Approximate instead, as MATLAB's ``c2d`` does for internal delays: the delay-free part is sampled behind
        a zero-order hold with the delayed signals taken as held too, and each delay of ``D = tau / h`` periods
        becomes ``z^-k`` times a Thiran all-pass filter of this order or lower (maximally flat group delay,
        exactly ``D`` at ``w = 0``; :func:`thiran`, with the order lowered to at most ``D + 1/2`` for a short
        delay).  The error shrinks with the period (first order in ``h``: the delayed signals are not piecewise
        constant).

    Returns
    -------
    DiscreteLTI
        States: the system's own, then the inputs of the last ``M`` periods (``M`` the longest delay in periods,
        rounded up); exact at ``t = k h``.

    Raises
    ------
    InvalidValueError
        For a delay inside a loop (no finite exact discretisation) or a period that is not positive.

    References
    ----------
    .. [1] K. J. Åström and B. Wittenmark, *Computer-Controlled Systems*, 3rd ed., Prentice Hall, 1997, sec. 2.3
       (sampling a system with a time delay).

    Examples
    --------
    A step into ``exp(-0.25 s)/(s + 1)`` sampled every 0.1 s reads ``1 - exp(-(k h - 0.25))`` once ``k h > 0.25``:

    >>> import math
    >>> from delaykit import tf
    >>> d = c2d(tf("exp(-0.25*s)/(s+1)"), 0.1)
    >>> x = np.zeros(d.A.shape[0]); ys = []
    >>> for k in range(6):
    ...     ys.append(float((d.C @ x + d.D[:, 0])[0])); x = d.A @ x + d.B[:, 0]
    >>> round(ys[5], 12) == round(1 - math.exp(-(0.5 - 0.25)), 12), ys[:3]
    (True, [0.0, 0.0, 0.0])
    """
    if not isinstance(sys, DelayLTI):
        raise InvalidTypeError(f"c2d takes a DelayLTI, got {type(sys).__name__}")
    h = check_real("period (s)", period, minimum=0.0, strict=True)
    if sys.saturations:
        raise InvalidValueError(f"the channels {list(sys.saturations)} saturate: c2d samples linear systems only; "
                                "discretise sys.without_limits() for the small-signal system")
    if thiran_order is not None:
        return _thiran_c2d(sys, h, thiran_order)
    internal = [j for j in range(sys.ndelays) if sys.C2[j].any() or sys.D22[j].any()]
    if internal:
        taus = [sys.delays[j] for j in internal]
        raise InvalidValueError(f"the delay channels {internal} (delays {taus} s) read the states: a delay inside a "
                                "loop has no finite exact zero-order-hold discretisation; give thiran_order=N for an "
                                "approximation, or discretise the open-loop blocks and close the loop in discrete time")
    n, nu, ny = sys.nstates, sys.ninputs, sys.noutputs
    tau = max(sys.delays, default=0.0)
    _check_states(n + nu * max(tau / h - 1.0, 0.0), h, tau)  # (a lower bound, before the counts are made)
    splits = [split_delay(t, h) for t in sys.delays]
    M = max([m + (1 if f > 0 else 0) for m, f in splits], default=0)
    # state: [x; u[k-1]; ...; u[k-M]]
    N = n + M * nu
    _check_states(N, h, tau)
    Ad, Bd = np.zeros((N, N)), np.zeros((N, nu))
    Cd, Dd = np.zeros((ny, N)), sys.D11.copy()
    Phi, Gam = hold_matrices(sys.A, np.hstack([sys.B1, sys.B2]), h) if n else (np.zeros((0, 0)), np.zeros((0, nu)))
    Ad[:n, :n] = Phi
    Cd[:, :n] = sys.C1
    if n:
        Bd[:n] += Gam[:, :nu]

    def add_input(rows: slice, M_rows: np.ndarray, lag: int, target: str) -> None:
        """Add ``M_rows @ u[k - lag]`` to the states (target "x") or the outputs ("y")."""
        if lag == 0:
            (Bd if target == "x" else Dd)[rows] += M_rows
        else:
            cols = slice(n + (lag - 1) * nu, n + lag * nu)
            (Ad if target == "x" else Cd)[rows, cols] += M_rows

    for j, (m, f) in enumerate(splits):
        d21 = sys.D21[j:j + 1]  # w_j = d21 u(t - tau_j)
        b2 = sys.B2[:, j:j + 1]
        if n and b2.any():
            if f > 0:
                E1, J1 = hold_matrices(sys.A, b2, h - f)  # the later piece, u[k - m]
                _, Jf = hold_matrices(sys.A, b2, f)  # the first piece, u[k - m - 1], then carried over h - f
                add_input(slice(0, n), J1 @ d21, m, "x")
                add_input(slice(0, n), E1 @ Jf @ d21, m + 1, "x")
            else:
                add_input(slice(0, n), Gam[:, nu + j:nu + j + 1] @ d21, m, "x")
        d12 = sys.D12[:, j:j + 1]
        if d12.any():  # the output reads w_j(k h) = d21 u((k - m) h - f)
            add_input(slice(0, ny), d12 @ d21, m + (1 if f > 0 else 0), "y")
    if M:  # the shift register
        Bd[n:n + nu] = np.eye(nu)
        for i in range(1, M):
            Ad[n + i * nu:n + (i + 1) * nu, n + (i - 1) * nu:n + i * nu] = np.eye(nu)
    for name, mat in (("A", Ad), ("B", Bd), ("C", Cd), ("D", Dd)):
        if not np.all(np.isfinite(mat)):
            raise InvalidValueError(f"the discretised {name} overflows: the period {h:g} s is too long for this "
                                    "system")
        mat.setflags(write=False)
    return DiscreteLTI(Ad, Bd, Cd, Dd, h, sys.inputs, sys.outputs)



def thiran_coefficients(D: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The Thiran all-pass filter of ``order`` for a delay of ``D`` periods, ``(num, den)`` in powers of ``z``.

    ``a_k = (-1)^k C(N, k) prod_{i=0}^{N} (D - N + i) / (D - N + k + i)``; the filter is
    ``z^-N a(1/z) / a(z)`` normalised, stable for ``D > N - 1``, with a group delay of exactly ``D`` at ``w = 0``.

    References
    ----------
    .. [1] J.-P. Thiran, "Recursive digital filters with maximally flat group delay", *IEEE Transactions on
       Circuit Theory* 18(6), 659-664, 1971.

    Examples
    --------
    >>> num, den = thiran_coefficients(1.5, 1)      # a_1 = -(D - 1)/(D + 1) = -0.2
    >>> num.round(12).tolist(), den.round(12).tolist()
    ([-0.2, 1.0], [1.0, -0.2])
    """
    N = int(order)
    if N < 0 or not D > N - 1:
        raise InvalidValueError(f"a Thiran filter of order {N} needs a delay of more than {N - 1} periods, got {D:g}")
    a = np.array([1.0] + [(-1) ** k * math.comb(N, k) * math.prod((D - N + i) / (D - N + k + i)
                                                                  for i in range(N + 1)) for k in range(1, N + 1)])
    return a[::-1].copy(), a.copy()


def _thiran_parts(D: float, N: int) -> tuple[np.ndarray, ...]:
    """``D`` periods as ``z^-k`` times a Thiran filter of order ``N`` for the remaining ``D - k`` periods, with
    ``k`` whole periods such that ``D - k`` is within half a period of ``N`` (where the filter is best damped), or
    as close as ``D`` allows (``D - k = D > N - 1``, for a short delay); ``N = 0`` rounds to whole periods."""
    if N == 0:
        return _shift(int(round(D)))
    k = max(int(math.floor(D - N + 0.5)), 0)
    return _series(_shift(k), _filter(*thiran_coefficients(D - k, N)))


def thiran(delay: float, period: float, order: int) -> DiscreteLTI:
    """The discrete delay-free approximation of a delay ``exp(-s delay)`` sampled every ``period``: whole periods
    as a shift register, the rest by a Thiran all-pass filter of ``order`` (maximally flat group delay, exactly
    ``delay / period`` periods at ``w = 0``; as MATLAB's ``thiran``).

    With ``D = delay / period`` periods: ``z^-k`` times the Thiran filter of order ``N`` for ``D - k`` periods, ``k``
    chosen so that ``D - k`` lies within half a period of ``N`` when ``D`` is long enough (the filter's poles then
    stay well inside the unit circle); a whole number of periods is the exact ``z^-D``.  The filter is an all-pass
    (``|H| = 1``), so the error is in the phase only, and it grows with ``w`` towards the Nyquist frequency.

    Parameters
    ----------
    delay : float
        The delay (s), at least 0.
    period : float
        The sampling period (s), positive.
    order : int
        ``N``, from 0 (the delay rounded to whole periods) to 10; the filter is stable for ``D > N - 1``.

    Returns
    -------
    DiscreteLTI
        One input and one output, ``k + N`` states, no delays.

    Raises
    ------
    InvalidValueError
        For a negative delay, a period that is not positive, an order out of range, or a delay of ``N - 1``
        periods or less (the filter would be unstable: take a lower order).

    See Also
    --------
    thiran_coefficients : the filter's coefficients and their reference.
    c2d

    Examples
    --------
    >>> F = thiran(0.25, 0.1, 2)          # 2.5 periods: one whole period, a second-order filter for 1.5
    >>> F
    DiscreteLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 3 states, period 0.1 s)
    >>> H = F.frequency_response([1e-3]).response[0, 0, 0]
    >>> round(float(-np.angle(H) / 1e-3), 6)        # the delay at w -> 0
    0.25
    """
    tau = check_real("delay (s)", delay, minimum=0.0)
    h = check_real("period (s)", period, minimum=0.0, strict=True)
    if isinstance(order, (bool, np.bool_)) or not isinstance(order, numbers.Integral) or not 0 <= order <= 10:
        raise InvalidValueError(f"the Thiran order must be an integer from 0 to 10, got {plain(order)!r}")
    D = tau / h
    if order and not D > order - 1:
        raise InvalidValueError(f"a Thiran filter of order {int(order)} needs a delay of more than {int(order) - 1} "
                                f"periods, got {D:g} ({tau:g} s / {h:g} s); take an order below {D + 1:g}")
    A, B, C, Dm = (np.asarray(x, float) for x in _thiran_parts(D, int(order)))
    for mat in (A, B, C, Dm):
        mat.setflags(write=False)
    return DiscreteLTI(A, B, C, Dm, h, ("u[0]",), ("y[0]",))


def _check_states(N: float, h: float, tau: float) -> None:
    """Refuse a discretisation of ``N`` states whose state matrix (``N x N``) is beyond the matrix budget, before
    it is built: a delay of ``tau`` s sampled every ``h`` s adds some ``tau / h`` states per input."""
    check_count(f"the discretised system of {N:.6g} states (a delay of {tau:g} s over a period of {h:g} s)",
                float(N) ** 2 if float(N) < 1e150 else math.inf,  # (a float's square past 1e154 overflows)
                MAX_MATRIX_ELEMENTS, "state-matrix elements", "sample with a longer period")


def _filter(num: np.ndarray, den: np.ndarray) -> tuple[np.ndarray, ...]:
    """A proper rational ``num/den`` in ``z`` realised in controllable canonical form: ``(A, B, C, D)``."""
    from ..models.transfer import TransferFunction

    A, B, C, D = TransferFunction(num, den).state_space()
    n = A.shape[0]
    return A, B.reshape(n, 1), C.reshape(1, n), np.array([[D]])


def _shift(k: int) -> tuple[np.ndarray, ...]:
    """``z^-k`` as a shift register of ``k`` states."""
    A = np.eye(k, k, -1)
    B = np.zeros((k, 1))
    C = np.zeros((1, k))
    if k:
        B[0, 0], C[0, k - 1] = 1.0, 1.0
    return A, B, C, np.array([[0.0 if k else 1.0]])


def _series(p: tuple[np.ndarray, ...], q: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """SISO ``q`` after ``p`` (state-space, discrete or continuous alike)."""
    A1, B1, C1, D1 = p
    A2, B2, C2, D2 = q
    A = np.block([[A1, np.zeros((A1.shape[0], A2.shape[0]))], [B2 @ C1, A2]])
    return A, np.vstack([B1, B2 @ D1]), np.hstack([D2 @ C1, C2]), D2 @ D1


def _thiran_c2d(sys: DelayLTI, h: float, order: Any) -> DiscreteLTI:
    if isinstance(order, bool) or not isinstance(order, numbers.Integral) or not 0 <= order <= 10:
        raise InvalidValueError(f"thiran_order must be an integer from 0 to 10, got {plain(order)!r}")
    n, nu, ny, m = sys.nstates, sys.ninputs, sys.noutputs, sys.ndelays
    # the delay-free part sampled with u and w held: inputs [u; w], outputs [y; z]
    Phi, Gam = hold_matrices(sys.A, np.hstack([sys.B1, sys.B2]), h) if n else (np.zeros((0, 0)),
                                                                                  np.zeros((0, nu + m)))
    P = (Phi, Gam, np.zeros((n, 0)), np.vstack([sys.C1, sys.C2]), np.zeros((0, n)),
         np.block([[sys.D11, sys.D12], [sys.D21, sys.D22]]), np.zeros((ny + m, 0)), np.zeros((0, nu + m)),
         np.zeros((0, 0)))
    longest = max(sys.delays, default=0.0)
    _check_states(n + sum(max(t / h - 1.0, 0.0) for t in sys.delays), h, longest)  # (a lower bound, first)
    parts = []
    for tau in sys.delays:
        D = tau / h
        N = min(int(order), max(int(math.floor(D + 0.5)), 0))  # an order the delay supports (D > N - 1)
        parts.append((D, N))
    # the filters' states counted before any is built: whole periods k plus the filter's order N each
    _check_states(n + sum(N + (max(int(math.floor(D - N + 0.5)), 0) if N else int(round(D))) for D, N in parts),
                  h, longest)
    filters = [_thiran_parts(D, N) for D, N in parts]
    Fa = blockdiag(*(f[0] for f in filters)) if filters else np.zeros((0, 0))
    Fb = blockdiag(*(f[1] for f in filters)) if filters else np.zeros((0, 0))
    Fc = blockdiag(*(f[2] for f in filters)) if filters else np.zeros((0, 0))
    Fd = blockdiag(*(f[3] for f in filters)) if filters else np.zeros((0, 0))
    nf = Fa.shape[0]
    # both side by side: inputs [u; w; z_in], outputs [y; z; w_out]; w = w_out, z_in = z
    parts = (blockdiag(P[0], Fa), blockdiag(P[1], Fb), np.zeros((n + nf, 0)), blockdiag(P[3], Fc),
             np.zeros((0, n + nf)), blockdiag(P[5], Fd), np.zeros((ny + 2 * m, 0)), np.zeros((0, nu + 2 * m)),
             np.zeros((0, 0)))
    F = np.zeros((nu + 2 * m, ny + 2 * m))
    F[nu:nu + m, ny + m:] = np.eye(m)
    F[nu + m:, ny:ny + m] = np.eye(m)
    G = np.zeros((nu + 2 * m, nu))
    G[:nu] = np.eye(nu)
    H = np.zeros((ny, ny + 2 * m))
    H[:, :ny] = np.eye(ny)
    A, B, _, C, _, Dm, *_ = close_parts(parts, F, G, H, np.zeros((ny, nu)), "the sampled delays")
    for mat in (A, B, C, Dm):
        mat.setflags(write=False)
    return DiscreteLTI(A, B, C, Dm, h, sys.inputs, sys.outputs)
