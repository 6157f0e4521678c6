"""A continuous-time MIMO linear system with internal delays, in linear-fractional (LFT) form.

::

    x'(t) = A  x(t) + B1  u(t) + B2  w(t)
    y(t)  = C1 x(t) + D11 u(t) + D12 w(t)
    z(t)  = C2 x(t) + D21 u(t) + D22 w(t)
    w_j(t) = z_j(t - tau_j),   tau_j >= 0

``u`` are the inputs, ``y`` the outputs, and the pairs ``(z_j, w_j)`` the delay channels: the system is the
delay-free part ``P`` closed through the diagonal delay block ``Delta(s) = diag(exp(-s tau_j))``, so that its
transfer matrix is the lower linear-fractional transformation

    ``H(s) = P11(s) + P12(s) Delta(s) (I - P22(s) Delta(s))^-1 P21(s)``,  ``Pij(s) = Cij (sI - A)^-1 Bj + Dij``.

This is the form of MATLAB's ``delayss`` and of ControlSystems.jl's ``DelayLtiSystem``: every interconnection of
delays and rational blocks (series, parallel, feedback) stays in it (:mod:`delaykit.systems.algebra`).  With
``D22 = 0`` the system is retarded; otherwise the delay channels feed each other directly (a difference equation
inside), the neutral case.

A channel may also carry limits: ``w_j(t) = sat(z_j(t - tau_j), lower_j, upper_j)`` (a saturation channel; with
``tau_j = 0``, a plain saturation such as an actuator's).  The limits are recorded and kept by the algebra; every
linear analysis here (frequency response, poles, norms) is of the small-signal system, each saturation taken as
the identity (:meth:`DelayLTI.without_limits`), which is what the system does while no limit is reached.

Build systems with :func:`delaykit.tf`, :func:`delaykit.ss` and :func:`delaykit.delay` rather than by hand.

Examples
--------
>>> import numpy as np
>>> g = DelayLTI(A=[[-1.0]], B1=[[0.0]], B2=[[1.0]], C1=[[2.0]], D11=[[0.0]], D12=[[0.0]],
...              C2=[[0.0]], D21=[[1.0]], D22=[[0.0]], delays=[0.5])
>>> g
DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 1 state, delays [0.5] s)
>>> h = g.frequency_response([1.0]).response[0, 0, 0]
>>> bool(abs(h - 2 * np.exp(-0.5j) / (1j + 1)) < 1e-15)
True
"""

from __future__ import annotations

import math
import numbers
import reprlib
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models import budget

__all__ = ["DelayLTI", "SystemResponse", "as_frequencies"]


def _real(name: str, value: Any) -> np.ndarray:
    """``value`` as a float array (complex and non-numeric values refused)."""
    try:
        if np.asarray(value).dtype.kind == "c":
            raise TypeError("complex")
        return np.array(value, dtype=float)
    except OverflowError:  # an integer of hundreds of digits
        raise InvalidValueError(f"{name} must be finite, got an integer beyond the floats in "
                                f"{reprlib.repr(value)}") from None
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be a real matrix, got {reprlib.repr(value)}") from exc


def _matrix(name: str, value: Any, shape: tuple[int, int]) -> np.ndarray:
    """``value`` as a read-only real finite float matrix of ``shape`` (None or an empty value: zeros)."""
    out = np.zeros(shape) if value is None else _real(name, value)
    if out.size == 0:
        out = np.zeros(shape)
    elif out.ndim < 2 and out.size == shape[0] * shape[1] and (1 in shape or out.ndim == 0):
        out = out.reshape(shape)
    if out.shape != shape:
        raise InvalidValueError(f"{name} must have shape {shape}, got {out.shape}")
    if not np.all(np.isfinite(out)):
        raise InvalidValueError(f"{name} must be finite, got {out.tolist()}")
    out.setflags(write=False)
    return out


def _names(what: str, names: Any, n: int, default: str) -> tuple[str, ...]:
    """``n`` distinct signal names (``default[i]`` when ``names`` is None; a single text for ``n = 1``)."""
    if names is None:
        return tuple(f"{default}[{i}]" for i in range(n))
    if isinstance(names, str):
        names = [names]
    try:
        names = list(names)
    except TypeError:
        raise InvalidTypeError(f"{what} must be a list of names, got {reprlib.repr(names)}") from None
    if len(names) != n:
        raise InvalidValueError(f"{what}: {n} names expected, got {len(names)} ({names})")
    for x in names:
        if not isinstance(x, str) or not x:
            raise InvalidTypeError(f"{what}: every name must be non-empty text, got {x!r}")
    dup = sorted({x for x in names if names.count(x) > 1})
    if dup:
        raise InvalidValueError(f"{what}: names must be distinct, {dup} repeat")
    return tuple(names)


def _check_name(name: Any) -> str:
    """A system's label: text."""
    if not isinstance(name, str):
        raise InvalidTypeError(f"name must be text, got {type(name).__name__}")
    return name


def _check_delays(delays: Any) -> tuple[float, ...]:
    """Delays as a tuple of finite non-negative floats (an error names the bad one)."""
    try:
        arr = [d for d in np.atleast_1d(np.asarray(delays, dtype=object)).ravel()]
    except TypeError:
        raise InvalidTypeError(f"delays must be a list of numbers, got {reprlib.repr(delays)}") from None
    out = []
    for j, d in enumerate(arr):
        if isinstance(d, (bool, np.bool_)) or not isinstance(d, numbers.Real):
            raise InvalidTypeError(f"delay {j} must be a real number of seconds, got {d!r}")
        d = float(d)
        if not math.isfinite(d) or d < 0:
            raise InvalidValueError(f"delay {j} must be finite and >= 0 s, got {d:g}")
        out.append(d)
    return tuple(out)


def _check_limits(limits: Any, m: int) -> tuple[tuple[float, float], ...]:
    """One ``(lower, upper)`` per channel with ``lower <= 0 <= upper``, ``lower < upper`` (None: no limit)."""
    if limits is None:
        return ((-math.inf, math.inf),) * m
    try:
        pairs = [tuple(p) for p in limits]
    except TypeError:
        raise InvalidTypeError(f"limits must be one (lower, upper) pair per channel, got {reprlib.repr(limits)}"
                               ) from None
    if len(pairs) != m or any(len(p) != 2 for p in pairs):
        raise InvalidValueError(f"limits must be {m} (lower, upper) pairs, one per channel, got {reprlib.repr(limits)}")
    out = []
    for j, (lo, hi) in enumerate(pairs):
        lo = -math.inf if lo is None else lo
        hi = math.inf if hi is None else hi
        if any(isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real) for x in (lo, hi)):
            raise InvalidTypeError(f"the limits of channel {j} must be numbers, got ({lo!r}, {hi!r})")
        try:
            lo, hi = float(lo), float(hi)
        except OverflowError:  # an integer of hundreds of digits (inf, or None, is no limit)
            raise InvalidValueError(f"the limits of channel {j} must be floats (inf or None for no limit), got an "
                                    "integer beyond them") from None
        if math.isnan(lo) or math.isnan(hi) or not (lo <= 0.0 <= hi and lo < hi):
            raise InvalidValueError(f"the limits of channel {j} must satisfy lower <= 0 <= upper and lower < upper "
                                    f"(the origin at rest inside them), got ({lo:g}, {hi:g})")
        out.append((lo, hi))
    return tuple(out)


def as_frequencies(w: Any, name: str = "w") -> np.ndarray:
    """Frequencies (rad/s) as a 1-D float array of finite values >= 0, or a delaykit error naming the problem
    (text and complex or non-numeric arrays are refused, not converted).

    Examples
    --------
    >>> as_frequencies(2.0).tolist()
    [2.0]
    >>> as_frequencies([1.0, -2.0])
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: frequencies must be at least 0 rad/s (w >= 0), got -2 in w
    """
    if isinstance(w, (str, bytes)):
        raise InvalidTypeError(f"{name} must be frequencies in rad/s (numbers), got {reprlib.repr(w)}")
    try:
        arr = np.asarray(w)
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be an array of frequencies in rad/s, got {reprlib.repr(w)}") from exc
    budget.check_response(arr.size)  # (before the copies below)
    if arr.dtype.kind not in "iuf":
        raise InvalidTypeError(f"{name} must be real frequencies in rad/s, got an array of dtype {arr.dtype}")
    arr = np.atleast_1d(arr.astype(float))
    if arr.ndim != 1:
        raise InvalidValueError(f"{name} must be a one-dimensional array of frequencies, got shape {arr.shape}")
    if arr.size == 0:
        raise InvalidValueError(f"{name} is empty: give at least one frequency (rad/s)")
    bad = ~np.isfinite(arr)
    if bad.any():
        raise InvalidValueError(f"frequencies must be finite, got {float(arr[bad][0])!r} in {name}")
    if (arr < 0).any():
        raise InvalidValueError(f"frequencies must be at least 0 rad/s ({name} >= 0), got {arr[arr < 0][0]:g} in "
                                f"{name}")
    return arr


@dataclass(frozen=True, repr=False)
class SystemResponse:
    """The frequency response of a :class:`DelayLTI`: ``response[i, j, k]`` is ``H_ij(j omega_k)``.

    Shaped ``(outputs, inputs, len(omega))`` as python-control's ``frequency_response``.

    Examples
    --------
    >>> from delaykit import tf
    >>> r = tf("exp(-s)/(s+1)").frequency_response([0.0, 1.0])
    >>> r
    SystemResponse(1 output x 1 input at 2 frequencies, 0 to 1 rad/s)
    >>> r.magnitude[0, 0].round(4).tolist()
    [1.0, 0.7071]
    >>> mag, phase, omega = r          # unpacks as python-control's
    >>> round(float(phase[0, 0, 1]), 6)        # -pi/4 - 1 rad at w = 1
    -1.785398
    """

    omega: np.ndarray
    response: np.ndarray
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]

    @property
    def magnitude(self) -> np.ndarray:
        """``|H(j omega)|``, same shape as :attr:`response`."""
        return np.abs(self.response)

    @property
    def phase(self) -> np.ndarray:
        """Phase (rad), unwrapped along the frequencies, same shape as :attr:`response`."""
        return np.unwrap(np.angle(self.response), axis=-1)

    def __iter__(self):  # mag, phase, omega = sys.frequency_response(w), as python-control's
        return iter((self.magnitude, self.phase, self.omega))

    def singular_values(self) -> np.ndarray:
        """Singular values of ``H(j omega)``, largest first, shaped ``(min(outputs, inputs), len(omega))``."""
        h = np.moveaxis(self.response, -1, 0)
        with np.errstate(all="ignore"):
            finite = np.all(np.isfinite(h), axis=(1, 2))
            sv = np.full((h.shape[0], min(h.shape[1:])), np.inf)
            if finite.any():
                sv[finite] = np.linalg.svd(h[finite], compute_uv=False)
        return sv.T

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the frequencies and the real and imaginary parts (``None`` where infinite)."""
        def clean(a: np.ndarray) -> Any:
            return [[[float(x) if math.isfinite(x) else None for x in row] for row in m] for m in a]

        return {"omega": self.omega.tolist(), "inputs": list(self.inputs), "outputs": list(self.outputs),
                "real": clean(self.response.real), "imag": clean(self.response.imag)}

    def plot(self, *, ax: Any = None, kind: str = "bode") -> Any:
        """Draw the response, as python-control's ``response.plot()``: ``kind="bode"``
        (:func:`~delaykit.plotting.lti.bode_plot`, every element) or ``"sigma"`` (its singular values); the plotting
        layer is imported here, so computing a response never loads matplotlib.  Returns the figure.

        The phase drawn is unwrapped between these frequencies (right when they are dense enough); ``bode_plot(sys)``
        of the system itself draws the exact phase at any spacing.

        Examples
        --------
        >>> from delaykit import tf
        >>> fig = tf("exp(-s)/(s+1)").frequency_response([0.1, 1.0, 10.0]).plot()
        >>> len(fig.axes)
        2
        """
        from ..plotting.lti import bode_plot, sigma_plot  # the plotting layer, on demand (tests/test_layout.py)

        if kind not in ("bode", "sigma"):
            raise InvalidValueError(f"kind must be 'bode' or 'sigma', got {kind!r}")
        return bode_plot(self, ax=ax) if kind == "bode" else sigma_plot(self, ax=ax)

    def __repr__(self) -> str:
        ny, nu, nw = self.response.shape
        span = f"{self.omega.min():g} to {self.omega.max():g} rad/s"
        return (f"SystemResponse({ny} output{'s' * (ny != 1)} x {nu} input{'s' * (nu != 1)} at {nw} "
                f"frequenc{'ies' if nw != 1 else 'y'}, {span})")


@dataclass(frozen=True, repr=False, eq=False)
class DelayLTI:
    """A linear time-invariant system with internal delays (see the module docstring for the equations).

    Parameters
    ----------
    A, B1, B2, C1, C2, D11, D12, D21, D22 : array_like
        The delay-free part, partitioned by (states, inputs, delay channels) and (states, outputs, delay
        channels).  ``None`` (or an empty value) is a zero block.  The shapes are taken from ``A`` (states),
        ``B1`` and ``C1`` (inputs, outputs) and ``delays`` (channels).
    delays : sequence of float
        ``tau_j >= 0`` (s), one per delay channel.
    inputs, outputs : sequence of str, optional
        Signal names (default ``u[0], u[1], ...`` and ``y[0], ...`` as python-control).
    name : str
        A label, shown by ``repr`` and used by :func:`~delaykit.systems.algebra.interconnect` messages.
    limits : sequence of (float, float), optional
        ``(lower, upper)`` per channel (None or infinite: no limit), with ``lower <= 0 <= upper``.

    Examples
    --------
    >>> from delaykit import tf, feedback
    >>> g = tf("12.8*exp(-s)/(16.7*s+1)", inputs="u", outputs="y")
    >>> g
    DelayLTI(1 input ['u'] -> 1 output ['y'], 1 state, delays [1] s)
    >>> feedback(g, 1).dcgain().round(6).tolist()
    [[0.927536]]
    """

    A: np.ndarray
    B1: np.ndarray
    B2: np.ndarray
    C1: np.ndarray
    C2: np.ndarray
    D11: np.ndarray
    D12: np.ndarray
    D21: np.ndarray
    D22: np.ndarray
    delays: tuple[float, ...] = ()
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    name: str = ""
    limits: tuple[tuple[float, float], ...] = ()

    def __init__(self, A: Any = None, B1: Any = None, B2: Any = None, C1: Any = None, C2: Any = None,
                 D11: Any = None, D12: Any = None, D21: Any = None, D22: Any = None, delays: Sequence[float] = (),
                 inputs: Any = None, outputs: Any = None, name: str = "", limits: Any = None) -> None:
        tau = _check_delays(delays)
        A0 = np.zeros((0, 0)) if A is None else _real("A", A)
        A0 = A0.reshape(1, 1) if A0.ndim == 0 else A0 if A0.size else np.zeros((0, 0))
        if A0.ndim != 2 or A0.shape[0] != A0.shape[1]:
            raise InvalidValueError(f"A must be a square matrix, got shape {A0.shape}")
        n, m = A0.shape[0], len(tau)
        nu = _cols("B1", B1, "D11", D11, n)
        ny = _rows("C1", C1, "D11", D11, n)
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        for key, val, shape in (("A", A0, (n, n)), ("B1", B1, (n, nu)), ("B2", B2, (n, m)), ("C1", C1, (ny, n)),
                                ("C2", C2, (m, n)), ("D11", D11, (ny, nu)), ("D12", D12, (ny, m)),
                                ("D21", D21, (m, nu)), ("D22", D22, (m, m))):
            set_(key, _matrix(key, val, shape))
        set_("delays", tau)
        set_("limits", _check_limits(limits, m))
        set_("inputs", _names("inputs", inputs, nu, "u"))
        set_("outputs", _names("outputs", outputs, ny, "y"))
        set_("name", _check_name(name))

    @classmethod
    def _from_parts(cls, parts: Sequence[np.ndarray], delays: tuple[float, ...],
                    limits: tuple[tuple[float, float], ...] | None = None, inputs: Any = None, outputs: Any = None,
                    name: Any = "", *, names_checked: bool = False, finite: bool = False) -> DelayLTI:
        """A system from parts the algebra made, without the public constructor's conversions (internal).

        ``parts`` are the nine float matrices ``(A, B1, B2, C1, C2, D11, D12, D21, D22)`` of consistent shapes,
        ``delays`` and ``limits`` tuples already checked (``limits`` None: no limit).  Finiteness is checked (an
        overflow in the algebra is the constructor's error) unless ``finite`` says that the parts are copies of
        checked ones; then the names as the constructor checks them, unless ``names_checked`` says that ``inputs``
        and ``outputs`` are a system's own tuples (or None: the default names) and ``name`` is text.  A matrix
        that is read-only already (another system's) is shared, one the caller made is frozen in place, anything
        else is copied as the constructor copies it: the values, and so every result, are the constructor's.
        """
        self = object.__new__(cls)
        d = self.__dict__
        made = []
        for key, val in zip(_PARTS, parts):
            if val.flags.writeable:  # made by the caller (another system's matrices are read-only, checked already)
                if val.base is not None or val.dtype != _FLOAT:  # a view, or not float: copied
                    val = np.array(val, dtype=float)
                val.flags.writeable = False
                if val.size:
                    made.append(val)
            d[key] = val
        if made and not finite and not np.isfinite(np.concatenate([v.ravel() for v in made])).all():
            for key in _PARTS:
                _matrix(key, d[key], d[key].shape)  # raises the constructor's error for the first bad matrix
        m, nu, ny = len(delays), d["B1"].shape[1], d["C1"].shape[0]
        d["delays"] = delays
        d["limits"] = ((-math.inf, math.inf),) * m if limits is None else limits
        if not names_checked or inputs is None or outputs is None:
            inputs, outputs = _names("inputs", inputs, nu, "u"), _names("outputs", outputs, ny, "y")
        if not names_checked:
            _check_name(name)
        d["inputs"], d["outputs"], d["name"] = inputs, outputs, name
        return self

    # -- sizes -------------------------------------------------------------------------------------------
    @property
    def nstates(self) -> int:
        """Number of states."""
        return self.A.shape[0]

    @property
    def ninputs(self) -> int:
        """Number of inputs."""
        return self.B1.shape[1]

    @property
    def noutputs(self) -> int:
        """Number of outputs."""
        return self.C1.shape[0]

    @property
    def ndelays(self) -> int:
        """Number of delay channels."""
        return len(self.delays)

    @property
    def saturations(self) -> tuple[int, ...]:
        """The channels with a finite limit (saturation channels)."""
        return tuple(j for j, (lo, hi) in enumerate(self.limits) if math.isfinite(lo) or math.isfinite(hi))

    def without_limits(self) -> DelayLTI:
        """The same system with every saturation removed: the small-signal system the linear analyses use."""
        return DelayLTI(self.A, self.B1, self.B2, self.C1, self.C2, self.D11, self.D12, self.D21, self.D22,
                        delays=self.delays, inputs=self.inputs, outputs=self.outputs, name=self.name)

    @property
    def is_retarded(self) -> bool:
        """True when no delayed signal feeds itself back without passing a state: every principal minor of the
        direct coupling between the delayed channels (through the channels without delay) is zero, so
        ``det(I - D22 Delta(s))`` is 1.  Otherwise the system is neutral (a difference equation inside)."""
        pos = [j for j, t in enumerate(self.delays) if t > 0]
        zero = [j for j, t in enumerate(self.delays) if t == 0]
        D = self.D22
        try:
            Deff = D[np.ix_(pos, pos)] + (D[np.ix_(pos, zero)] @ np.linalg.solve(
                np.eye(len(zero)) - D[np.ix_(zero, zero)], D[np.ix_(zero, pos)]) if zero else 0.0)
        except np.linalg.LinAlgError:
            return False  # the channels without delay form an algebraic loop that is not well posed
        if not Deff.any():
            return True
        tol = 1e-12 * max(1.0, float(np.abs(Deff).max()))
        k = len(pos)
        if k > _MAX_CHANNELS:
            return not np.any(np.abs(np.linalg.eigvals(Deff)) > tol)
        return all(abs(np.linalg.det(Deff[np.ix_(S, S)])) <= tol
                   for mask in range(1, 1 << k) for S in [[j for j in range(k) if mask >> j & 1]])

    # -- values ------------------------------------------------------------------------------------------
    def evaluate(self, s: Any) -> np.ndarray:
        """``H(s)`` at complex points: shape ``(outputs, inputs, len(s))``; ``inf`` at a pole.

        Examples
        --------
        >>> from delaykit import tf
        >>> complex(tf("exp(-2*s)/(s+1)").evaluate([1.0])[0, 0, 0]).real.__round__(6)
        0.067668
        """
        s = _points(s)
        n, nu, ny, m = self.nstates, self.ninputs, self.noutputs, self.ndelays
        budget.check_response(s.size, ny, nu)
        budget.check_count(f"the {n + m} x {n + m} matrix solved at each point ({n} states, {m} delay channels)",
                           float(n + m) ** 2, budget.MAX_MATRIX_ELEMENTS, "elements")
        budget.check_count(f"a response at {s.size} points of a system of {n} states and {m} delay channels",
                           float(s.size) * float(n + m) ** 3, budget.MAX_SOLVE_WORK, "operations",
                           "ask for fewer frequencies or a smaller system")
        out = np.empty((s.size, ny, nu), complex)
        CD = np.hstack([self.C1, self.D12])
        for b in budget.blocks(s.size, (n + m) * (n + m + 2 * nu + 2) + ny * nu):  # bounded work memory
            sb = s[b]
            N = sb.size
            # the states and the delayed signals at once: [[sI - A, -B2], [-E C2, I - E D22]] [x; w] = [B1; E D21]
            # u, singular exactly at the poles of the system (not at those of its delay-free part)
            E = np.exp(-np.outer(sb, self.delays)) if m else np.zeros((N, 0))
            M = np.zeros((N, n + m, n + m), complex)
            M[:, :n, :n] = sb[:, None, None] * np.eye(n) - self.A
            M[:, :n, n:] = -self.B2
            M[:, n:, :n] = -E[:, :, None] * self.C2
            M[:, n:, n:] = np.eye(m) - E[:, :, None] * self.D22
            rhs = np.zeros((N, n + m, nu), complex)
            rhs[:, :n] = self.B1
            rhs[:, n:] = E[:, :, None] * self.D21
            with np.errstate(all="ignore"):
                X = _solve(M, rhs) if n + m else rhs
                out[b] = self.D11 + CD @ X
        out[~np.isfinite(out)] = complex(math.inf, 0.0)
        return np.moveaxis(out, 0, -1)

    def __call__(self, s: Any) -> np.ndarray:
        """``H(s)`` at one complex point (an ``(outputs, inputs)`` matrix) or at several (see :meth:`evaluate`)."""
        h = self.evaluate(s)
        return h[:, :, 0] if np.ndim(s) == 0 else h

    def frequency_response(self, w: Any) -> SystemResponse:
        """The exact ``H(j w)``: each delay as ``exp(-j w tau)``, the LFT closed at each frequency.

        Parameters
        ----------
        w : array_like
            Frequencies (rad/s), finite and >= 0.

        Returns
        -------
        SystemResponse
            ``response`` shaped ``(outputs, inputs, len(w))``.

        Examples
        --------
        >>> from delaykit import tf
        >>> r = tf("exp(-s)/(s+1)").frequency_response([1.0])
        >>> round(float(r.phase[0, 0, 0]), 6)   # -pi/4 - 1 rad
        -1.785398
        """
        w = as_frequencies(w)
        return SystemResponse(w, self.evaluate(1j * w), self.inputs, self.outputs)

    def singular_values(self, w: Any) -> np.ndarray:
        """Singular values of ``H(j w)``, largest first, shaped ``(min(outputs, inputs), len(w))``.

        Examples
        --------
        >>> from delaykit import tf
        >>> tf([["1", "0"], ["0", "2*exp(-s)"]]).singular_values([0.0]).ravel().tolist()
        [2.0, 1.0]
        """
        return self.frequency_response(w).singular_values()

    def dcgain(self) -> np.ndarray:
        """``H(0)``, an ``(outputs, inputs)`` matrix (``inf`` entries for an integrator)."""
        return self.evaluate([0.0])[:, :, 0].real

    # -- the characteristic function -------------------------------------------------------------------
    def characteristic(self) -> Any:
        """``det(sI - A) det(I - P22(s) Delta(s))`` as a :class:`~delaykit.models.QuasiPolynomial`.

        The determinant is multilinear in the channels' ``exp(-s tau_j)``, so it is the sum over the subsets
        ``S`` of channels of ``exp(-s sum_S tau_j)`` times ``det([[sI - A, -B2_S], [-C2_S, -D22_SS]])``; each such
        polynomial is found by interpolation on a circle whose radius is the geometric mean of ``A``'s nonzero
        eigenvalues, or, when these spread over more than four decades, on circles spanning them, each coefficient
        from the circle where it stands highest above its rounding floor.  A coefficient is dropped only at the
        rounding level of its own term (the elimination's error bound, :func:`_det_scale`), never because another
        term is larger: a loop gain of 1e300, or time constants of 1e-13 and 1e13 s, keep every term.  Its roots
        are the system's internal
        poles, hidden modes included (as MATLAB's ``pole`` of a state-space model, but with the delays kept).

        Examples
        --------
        >>> from delaykit import tf, feedback
        >>> feedback(tf("exp(-0.5*s)/s"), 1).characteristic()
        QuasiPolynomial(s + 1·exp(-0.5 s))
        """
        from ..models.quasipolynomial import QuasiPolynomial

        n, m = self.nstates, self.ndelays
        if m > _MAX_CHANNELS:
            raise InvalidValueError(f"the characteristic function of {m} delay channels has 2^{m} terms; at most "
                                    f"{_MAX_CHANNELS} channels are supported")
        overflow = InvalidValueError("the characteristic function overflows the floats (the system's matrices, A up "
                                     f"to {float(np.max(np.abs(self.A), initial=0.0)):g}, are too large for its "
                                     "determinant): rescale the system's units")
        with np.errstate(all="ignore"):  # (checked just below)
            eig = np.linalg.eigvals(self.A) if n else np.zeros(0)
            mags = np.abs(eig[eig != 0])
            radius = float(np.exp(np.mean(np.log(mags)))) if mags.size else 1.0  # balances the coefficients' sizes
        if not (math.isfinite(radius) and radius > 0):
            raise overflow
        radii = [radius]
        if mags.size and mags.max() > _SPREAD * mags.min():
            # time scales far apart: no one circle gives every coefficient to full precision (s^2 + 1e13 s + 1 on
            # the unit circle loses its 1 and its s^2), so circles from the smallest to the largest eigenvalue
            # magnitude, each coefficient taken from the one where it stands highest above the rounding floor
            spread = math.log10(float(mags.max() / mags.min()))
            radii += list(np.geomspace(float(mags.min()), float(mags.max()), int(math.ceil(spread / 2)) + 1))
        k = np.arange(n + 1)
        unity = np.exp(2j * np.pi * k / (n + 1))
        terms = []
        for mask in range(1 << m):
            S = [j for j in range(m) if mask >> j & 1]
            if S and not (self.B2[:, S].any() or self.D22[np.ix_(S, S)].any()):
                continue
            top = np.hstack([-self.A, -self.B2[:, S]])
            bottom = np.hstack([-self.C2[S, :], -self.D22[np.ix_(S, S)]])
            G = np.vstack([top, bottom])
            F = np.zeros_like(G)
            F[:n, :n] = np.eye(n)
            per = []
            for r in radii:
                mats = [p * F + G for p in r * unity]
                with np.errstate(all="ignore"):  # (checked just below)
                    vals = np.array([np.linalg.det(M) for M in mats])
                if not np.all(np.isfinite(vals)):
                    raise overflow
                noise = max(_det_scale(M) for M in mats)  # this term's own floor, whatever the others' scale
                per.append((np.fft.fft(vals).real / (n + 1), noise))
            terms.append((per, sum(self.delays[j] for j in S)))
        # coefficients at rounding level of a term's (scaled) size are noise of the interpolation; each term is
        # judged against its own floor (never above the largest coefficient's), so a term far smaller than
        # another (a loop gain of 1e20 against the plant's own s + 1) is kept, not dropped
        bigs = [max(float(np.max(np.abs(per[i][0]))) for per, _ in terms) for i in range(len(radii))]
        polys, delays = [], []
        for per, tau in terms:
            best, snr = np.zeros(n + 1), np.zeros(n + 1)
            for r, big, (c, noise) in zip(radii, bigs, per):
                with np.errstate(divide="ignore", invalid="ignore"):
                    here = np.abs(c) / (1e-12 * min(big, noise))
                take = here > snr
                best[take], snr[take] = c[take] / r ** k[take], here[take]  # ascending powers
            c = np.where(snr > 1.0, best, 0.0)
            if c.any():
                polys.append(c[::-1])
                delays.append(tau)
        return QuasiPolynomial(polys, delays)

    def poles(self, region: Sequence[float]) -> Any:
        """Every pole in ``region = (re_min, re_max, im_min, im_max)``, certified: a
        :class:`~delaykit.spectrum.roots.Spectrum` (see :func:`delaykit.spectrum.systems.poles`).

        Examples
        --------
        >>> from delaykit import tf, feedback
        >>> feedback(tf("exp(-s)/(s+1)"), 1).poles((-1, 1, 0, 3)).roots.round(4).tolist()
        [(-0.605+1.7882j)]
        """
        from ..spectrum.systems import poles

        return poles(self, region)

    def is_stable(self) -> bool:
        """True when every pole lies left of the imaginary axis (retarded systems; see
        :func:`delaykit.spectrum.systems.is_stable`).

        Examples
        --------
        >>> from delaykit import tf, feedback
        >>> feedback(tf("exp(-s)/(s+1)"), 1).is_stable()
        True
        """
        from ..spectrum.systems import is_stable

        return is_stable(self)

    def zeros(self, region: Sequence[float] | None = None) -> Any:
        """Every zero in ``region`` (by default one that holds the rightmost zeros), certified, of a SISO or square
        system: a :class:`~delaykit.spectrum.roots.Spectrum` (see :func:`delaykit.spectrum.systems.zeros`).

        Examples
        --------
        >>> from delaykit import tf
        >>> tf("(s-1)*exp(-s)/(s+2)^2").zeros().roots.round(12).tolist()
        [(1+0j)]
        """
        from ..spectrum.systems import zeros

        return zeros(self, region)

    def is_minimum_phase(self) -> bool:
        """True when no zero lies in the closed right half-plane, a delay not counted as one (see
        :func:`delaykit.spectrum.systems.is_minimum_phase`).

        Examples
        --------
        >>> from delaykit import tf
        >>> tf("(s-1)*exp(-s)/(s+2)^2").is_minimum_phase()
        False
        """
        from ..spectrum.systems import is_minimum_phase

        return is_minimum_phase(self)

    # -- time responses (see delaykit.simulate.systems) ---------------------------------------------------------
    def step(self, T: Any = None) -> Any:
        """The exact step response, ``outputs`` shaped ``(outputs, inputs, times)`` (see
        :func:`delaykit.simulate.systems.step_response`).

        Examples
        --------
        >>> from delaykit import tf
        >>> tf("exp(-s)/(s+1)").step([1.0, 2.0]).outputs.round(6).tolist()
        [[[0.0, 0.632121]]]
        """
        from ..simulate.systems import step_response

        return step_response(self, T)

    def impulse(self, T: Any = None) -> Any:
        """The exact impulse response, its Dirac terms apart (see
        :func:`delaykit.simulate.systems.impulse_response`).

        Examples
        --------
        >>> from delaykit import tf
        >>> r = tf("exp(-s)/(s+1)").impulse([1.0, 2.0])
        >>> r.outputs.round(6).tolist(), r.impulses
        ([[[1.0, 0.367879]]], ())
        """
        from ..simulate.systems import impulse_response

        return impulse_response(self, T)

    def initial(self, T: Any = None, X0: Any = 0.0) -> Any:
        """The exact free response from the states ``X0`` (see :func:`delaykit.simulate.systems.initial_response`).

        Examples
        --------
        >>> from delaykit import tf, feedback
        >>> feedback(tf("exp(-s)/(s+1)"), 1).initial([0.5, 1.5], X0=1.0).outputs.round(6).tolist()
        [[0.606531, -0.080135]]
        """
        from ..simulate.systems import initial_response

        return initial_response(self, T, X0)

    def lsim(self, T: Any, U: Any, X0: Any = 0.0) -> Any:
        """The exact response to ``U`` linear between the times ``T`` (see
        :func:`delaykit.simulate.systems.forced_response`).

        Examples
        --------
        >>> from delaykit import tf
        >>> tf("exp(-s)/s").lsim([0.0, 1.0, 2.0, 3.0], [0.0, 1.0, 1.0, 1.0]).outputs.tolist()
        [[0.0, 0.0, 0.5, 1.5]]
        """
        from ..simulate.systems import forced_response

        return forced_response(self, T, U, X0)

    def to_control(self, pade_order: int | None = None) -> Any:
        """A python-control ``StateSpace`` with each delay as a Padé approximation of ``pade_order``
        (see :func:`delaykit.systems.build.to_control`)."""
        from .build import to_control

        return to_control(self, pade_order)

    # -- algebra (see delaykit.systems.algebra) ------------------------------------------------------------
    __array_ufunc__ = None  # ``matrix * sys`` is the gain times the system (numpy defers to __rmul__), not per entry

    def _laplace(self, other: Any, op: str, reflected: bool = False) -> Any:
        """The exact algebra of ``s`` (:mod:`~delaykit.systems.laplace`) where it applies: ``other`` an
        expression of ``s``, or this system built from ``s`` (it remembers its expression) and ``other`` a
        number or another such system.  None elsewhere: the algebra of systems."""
        if getattr(other, "_is_laplace", False):
            return other._combine(self, op, not reflected)
        mine = self.__dict__.get("_expr")
        if mine is None:
            return None
        if isinstance(other, DelayLTI) and other.__dict__.get("_expr") is not None or (
                isinstance(other, numbers.Real) and not isinstance(other, (bool, np.bool_))):
            return mine._combine(other, op, reflected)
        return None

    def __mul__(self, other: Any) -> DelayLTI:
        r = self._laplace(other, "mul")
        if r is not None:
            return r
        from .algebra import product

        return product(self, other)

    def __rmul__(self, other: Any) -> DelayLTI:
        r = self._laplace(other, "mul", True)
        if r is not None:
            return r
        from .algebra import product

        return product(other, self)

    def __add__(self, other: Any) -> DelayLTI:
        r = self._laplace(other, "add")
        if r is not None:
            return r
        from .algebra import sum_of

        return sum_of(self, other)

    def __radd__(self, other: Any) -> DelayLTI:
        r = self._laplace(other, "add", True)
        if r is not None:
            return r
        from .algebra import sum_of

        return sum_of(other, self)

    def __neg__(self) -> DelayLTI:
        mine = self.__dict__.get("_expr")
        if mine is not None:
            return -mine
        from .algebra import negate

        return negate(self)

    def __sub__(self, other: Any) -> DelayLTI:
        r = self._laplace(other, "sub")
        if r is not None:
            return r
        from .algebra import as_system, sum_of

        return sum_of(self, -as_system(other, "right term"))

    def __rsub__(self, other: Any) -> DelayLTI:
        r = self._laplace(other, "sub", True)
        if r is not None:
            return r
        from .algebra import sum_of

        return sum_of(other, -self)

    def __truediv__(self, other: Any) -> DelayLTI:
        r = self._laplace(other, "truediv")
        if r is not None:
            return r
        if isinstance(other, numbers.Real) and not isinstance(other, (bool, np.bool_)):
            x = check_real("a divisor", other)
            if x == 0.0:
                raise InvalidValueError("division of a system by zero")
            return self * (1.0 / x)
        raise InvalidTypeError(f"a system is divided only by a number, or where both sides are built from s = "
                               f"tf('s'); for a closed loop use feedback(), got a {type(other).__name__}")

    def __rtruediv__(self, other: Any) -> DelayLTI:
        r = self._laplace(other, "truediv", True)
        if r is not None:
            return r
        raise InvalidTypeError("only a system built from s = tf('s') can be inverted by '/'; for a closed loop use "
                               f"feedback(), got {type(other).__name__} / system")

    def __getitem__(self, key: Any) -> DelayLTI:
        from .algebra import select

        return select(self, key)

    def feedback(self, other: Any = 1, sign: int = -1) -> DelayLTI:
        """The closed loop with ``other`` in the return path (see :func:`~delaykit.systems.algebra.feedback`)."""
        from .algebra import feedback

        return feedback(self, other, sign)

    # -- output ------------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form; ``DelayLTI(**d)`` reads it back.

        Examples
        --------
        >>> from delaykit import delay
        >>> delay(0.5).to_dict()["delays"]
        [0.5]
        """
        d: dict[str, Any] = {k: getattr(self, k).tolist() for k in
                             ("A", "B1", "B2", "C1", "C2", "D11", "D12", "D21", "D22")}
        d.update(delays=list(self.delays), inputs=list(self.inputs), outputs=list(self.outputs), name=self.name)
        if self.saturations:  # JSON has no infinity: unlimited sides as None
            d["limits"] = [[lo if math.isfinite(lo) else None, hi if math.isfinite(hi) else None]
                           for lo, hi in self.limits]
        return d

    def __repr__(self) -> str:
        def names(x: tuple[str, ...]) -> str:
            return repr(list(x)) if len(x) <= 6 else f"[{', '.join(map(repr, x[:5]))}, ...]"

        nu, ny, n = self.ninputs, self.noutputs, self.nstates
        tau = ", ".join(f"{t:g}" for t in self.delays[:8]) + (", ..." if self.ndelays > 8 else "")
        head = f"{self.name}: " if self.name else ""
        return (f"DelayLTI({head}{nu} input{'s' * (nu != 1)} {names(self.inputs)} -> {ny} output{'s' * (ny != 1)} "
                f"{names(self.outputs)}, {n} state{'s' * (n != 1)}, "
                + (f"delays [{tau}] s" if self.delays else "no delays")
                + (f", {len(self.saturations)} saturation{'s' * (len(self.saturations) != 1)}" if self.saturations
                   else "") + ("" if self.is_retarded else ", neutral") + ")")


def _det_scale(M: np.ndarray) -> float:
    """A size whose eps-multiple bounds the rounding error of ``det(M)`` by Gaussian elimination (partial
    pivoting): ``|det M|`` times the sum over the pivots of ``(|L||U|)_ii / |U_ii|`` (each pivot's error relative
    to it), at least ``|det M|``; Hadamard's bound (the product of the rows' 1-norms) when a pivot is zero."""
    import warnings

    from scipy.linalg import LinAlgWarning, lu_factor

    if not M.size:
        return 1.0
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", LinAlgWarning)  # a singular M: handled below
        lu, _ = lu_factor(M, check_finite=False)
        d = np.abs(np.diag(lu))
        if not np.all(d > 0) or not np.all(np.isfinite(lu)):
            return float(np.prod(np.abs(M).sum(axis=1)))
        L = np.tril(lu, -1) + np.eye(M.shape[0])
        growth = np.einsum("ij,ji->i", np.abs(L), np.abs(np.triu(lu))) / d
        logdet = float(np.sum(np.log(d)))
        return float(np.exp(logdet + math.log(max(1.0, float(growth.sum())))))


_MAX_CHANNELS = 14
_SPREAD = 1e4
"""The ratio of ``A``'s largest to smallest nonzero eigenvalue magnitude above which :meth:`DelayLTI.characteristic`
interpolates on several circles (below it one circle gives every coefficient to about 12 digits)."""
_PARTS = ("A", "B1", "B2", "C1", "C2", "D11", "D12", "D21", "D22")
_FLOAT = np.dtype(float)


def _is_numeric(x: Any) -> bool:
    try:
        np.asarray(x, dtype=float)
    except (TypeError, ValueError, OverflowError):  # (an integer beyond the floats: refused by _real)
        return False
    return True


def _cols(bname: str, b: Any, dname: str, d: Any, n: int) -> int:
    """The number of inputs: the columns of ``B1`` (when there are states) or of ``D11`` (2-D values only)."""
    for v in ((b, d) if n else (d,)):
        if v is not None and _is_numeric(v) and np.ndim(v) == 2:
            return int(np.shape(v)[1])
    return 0


def _rows(cname: str, c: Any, dname: str, d: Any, n: int) -> int:
    """The number of outputs: the rows of ``C1`` (when there are states) or of ``D11`` (2-D values only)."""
    for v in ((c, d) if n else (d,)):
        if v is not None and _is_numeric(v) and np.ndim(v) == 2:
            return int(np.shape(v)[0])
    return 0


def _points(s: Any) -> np.ndarray:
    """``s`` as a flat complex array of finite points; text, None, bools, nan and infinity refused by name."""
    try:
        arr = np.asarray(s)
        if arr.dtype.kind not in "iufc" or arr.dtype == object:
            raise TypeError(arr.dtype)
        arr = np.atleast_1d(arr.astype(complex)).ravel()
    except (TypeError, ValueError, OverflowError):
        raise InvalidTypeError(f"a system is evaluated at complex numbers, got {reprlib.repr(s)}") from None
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise InvalidValueError(f"a system is evaluated at finite points s, got s[{int(bad[0])}] = "
                                f"{complex(arr[bad[0]])!r}")
    return arr


def _solve(M: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``M^-1 B`` for a stack of matrices; ``inf`` where a matrix is singular (a pole, an ill-posed loop)."""
    try:
        return np.linalg.solve(M, B)
    except np.linalg.LinAlgError:
        out = np.empty(B.shape, complex)
        for i in range(M.shape[0]):
            try:
                out[i] = np.linalg.solve(M[i], B[i])
            except np.linalg.LinAlgError:
                out[i] = complex(math.inf, 0.0)
        return out
