"""Making delay systems: ``tf``, ``ss``, ``delay``, from and to python-control, and a ``Loop`` as a system.

Names and conventions follow python-control (``tf``, ``ss``, signal names ``u[i]`` and ``y[i]``).  A delay is
kept exact: ``tf("12.8*exp(-s)/(16.7*s+1)")`` is the rational part realised in controllable canonical form with one
delay channel on its input.  A transfer matrix is realised entry by entry (each entry its own states and delay),
which keeps every dead time of, say, the Wood-Berry column as it is; the realisation is not minimal in the states
(a MIMO minimal realisation with delays does not exist in general).

Examples
--------
>>> G = tf([["12.8*exp(-s)/(16.7*s+1)", "-18.9*exp(-3*s)/(21*s+1)"],
...         ["6.6*exp(-7*s)/(10.9*s+1)", "-19.4*exp(-3*s)/(14.4*s+1)"]])
>>> G
DelayLTI(2 inputs ['u[0]', 'u[1]'] -> 2 outputs ['y[0]', 'y[1]'], 4 states, delays [1, 3, 7, 3] s)
>>> G.dcgain().round(12).tolist()
[[12.8, -18.9], [6.6, -19.4]]
"""

from __future__ import annotations

import functools
import numbers
import reprlib
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real, plain
from ..models.budget import MAX_TEXT_CHARS, shorten
from ..models.interop import check_pade_order, require_control
from ..models.transfer import TransferFunction, check_control_system
from .algebra import _closed, _partitions, _stack, feedback, gain, interconnect, summing_junction
from .laplace import LaplaceExpression, exp, laplace_variable, parse_expression
from .lti import DelayLTI
from .pade import pade

__all__ = ["tf", "ss", "delay", "saturation", "to_control", "from_loop", "system_of", "plant_of", "to_loop"]


def _rename(sys: DelayLTI, inputs: Any, outputs: Any, name: str | None) -> DelayLTI:
    if inputs is None and outputs is None and name is None:
        return sys
    out = DelayLTI._from_parts(_partitions(sys), sys.delays, sys.limits, sys.inputs if inputs is None else inputs,
                               sys.outputs if outputs is None else outputs, sys.name if name is None else name)
    if "_expr" in sys.__dict__:  # built from s: still combined exactly with expressions of s
        out.__dict__["_expr"] = sys.__dict__["_expr"]
    return out


def _rational(g: TransferFunction, T: float = 0.0) -> DelayLTI:
    """``g(s) exp(-s T)``: ``g`` in controllable canonical form, the delay on its input."""
    A, B, C, D = g.state_space()
    n = A.shape[0]
    B, C = B.reshape(n, 1), C.reshape(1, n)
    z = np.zeros
    if T == 0.0:
        return DelayLTI._from_parts((A, B, z((n, 0)), C, z((0, n)), np.array([[D]]), z((1, 0)), z((0, 1)), z((0, 0))),
                                    (), None, names_checked=True)
    return DelayLTI._from_parts((A, z((n, 1)), B, C, z((1, n)), z((1, 1)), np.array([[D]]), np.ones((1, 1)),
                                 z((1, 1))), (float(T),), None, names_checked=True)


def _invert(h: DelayLTI, text: str) -> DelayLTI:
    """``1 / h`` of a SISO system with a feedthrough ``d != 0`` that no delay carries: ``(1/d) / (1 + X/d)`` with
    ``X = h - d``, the feedback loop of 1 and ``X/d`` (well posed: ``X`` has no undelayed feedthrough)."""
    d = float(h.D11[0, 0])
    if d == 0.0:
        raise InvalidValueError(f"cannot divide by '{text}': it has no direct feedthrough without delay, so its "
                                "inverse would predict")
    return (1.0 / d) * feedback(1.0, (h - d) * (1.0 / d))


@functools.lru_cache(maxsize=512)
def _text(text: str) -> DelayLTI:
    """A transfer function as text: read whole as a rational function times delays when it is one, otherwise
    split at its top operator (sums and quotients of delayed terms: internal delays) and combined by the algebra.

    Remembered for the last texts read (a system is immutable, so the same text gives the same object): building
    many loops around one plant written as text reads it once; errors are not remembered."""
    import ast

    try:
        g, T = TransferFunction.parse_with_delay(text, proper=False)
        if g.num.any() and g.num.size > g.den.size:
            raise InvalidValueError(
                f"the transfer function {text!r} is improper: the numerator degree {g.num.size - 1} exceeds the "
                f"denominator degree {g.den.size - 1}, and a system must be proper (numerator degree <= denominator "
                "degree); an improper controller such as a PD law is built from s = tf('s') (kp + kd*s), which "
                "stays an expression until it is combined with its plant")
        return _rational(g, T)
    except (InvalidValueError, InvalidTypeError) as exc:
        first = exc
    if len(text) > MAX_TEXT_CHARS:  # refused for its length: not split into parts either (each would be read)
        raise first
    src = text.replace("^", "**").strip()
    try:
        node = ast.parse(src, mode="eval").body
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        raise first from None

    def part(n: ast.AST) -> str:
        return ast.get_source_segment(src, n) or ast.unparse(n)

    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        return -_part(text, part(node.operand), "term")
    if not isinstance(node, ast.BinOp) or not isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
        raise first
    if not any(isinstance(n, ast.Call) for n in ast.walk(node)):  # no delay: the reader's own error is the reason
        raise first
    role = ("numerator", "denominator") if isinstance(node.op, ast.Div) else ("factor", "factor") \
        if isinstance(node.op, ast.Mult) else ("term", "term")
    left = _part(text, part(node.left), role[0])
    if isinstance(node.op, ast.Div):
        try:  # a rational denominator: multiply by its reciprocal
            g, T = TransferFunction.parse_with_delay(part(node.right), proper=False)
        except (InvalidValueError, InvalidTypeError):
            g, T = None, 0.0
        if g is not None and T == 0.0 and g.num.any() and g.num.size >= g.den.size:
            return left * _rational(TransferFunction(g.den, g.num))
        den = _part(text, part(node.right), role[1])
        try:
            inverse = _invert(den, part(node.right))
        except (InvalidValueError, InvalidTypeError) as exc:
            raise _PartError.of(text, part(node.right), role[1], exc) from None
        return left * inverse
    right = _part(text, part(node.right), role[1])
    return left + right if isinstance(node.op, ast.Add) else left - right if isinstance(node.op, ast.Sub) \
        else left * right


class _PartError(InvalidValueError):
    """A part of a transfer function read part by part (:func:`_text`) that is no system of its own: the message
    quotes the whole text the user gave and names the part of it that fails (its top-level numerator, term...)."""

    def __init__(self, whole: str, part: str, role: str, reason: str) -> None:
        super().__init__(f"cannot build {shorten(whole, 80)!r}: with a delay exp(-T*s) in a sum or in a denominator, "
                         f"it is built from its parts as systems of their own (internal delays), and its {role} "
                         f"{shorten(part, 80)!r} is not one: {shorten(reason, 400)}")
        self.part, self.role, self.reason = part, role, reason

    @classmethod
    def of(cls, whole: str, part: str, role: str, exc: Exception) -> _PartError:
        if isinstance(exc, _PartError):  # the reason found deeper, this level's part named
            reason = exc.reason
        else:
            reason = str(exc)
        try:
            g, _ = TransferFunction.parse_with_delay(part, proper=False)
        except (InvalidValueError, InvalidTypeError):
            g = None
        if g is not None and g.relative_degree < 0:
            reason = f"it is improper (degree {g.num.size - 1} in s over {g.den.size - 1}), and every part must be proper"
        return cls(whole, part, role, reason)


def _part(whole: str, text: str, role: str) -> DelayLTI:
    """:func:`_text` of a part of ``whole``; its error names ``whole`` and the part (a :class:`_PartError`)."""
    try:
        return _text(text)
    except (InvalidValueError, InvalidTypeError) as exc:
        raise _PartError.of(whole, text, role, exc) from None


def _is_number_list(x: Any) -> bool:
    if isinstance(x, (numbers.Real, np.ndarray)) and not isinstance(x, (bool, np.bool_)):
        return True
    return isinstance(x, (list, tuple)) and all(isinstance(c, numbers.Real) and not isinstance(c, bool) for c in x)


def _siso(spec: Any, where: str) -> DelayLTI:
    """One entry: text, ``(num, den)``, ``(num, den, delay)``, a number, a TransferFunction or a SISO system."""
    if isinstance(spec, DelayLTI):
        if (spec.ninputs, spec.noutputs) != (1, 1):
            raise InvalidValueError(f"{where}: a transfer-matrix entry must have one input and one output, got "
                                    f"{spec!r}")
        return spec
    if isinstance(spec, str):
        try:
            return _text(spec)
        except (InvalidValueError, InvalidTypeError) as exc:
            kind = InvalidTypeError if isinstance(exc, InvalidTypeError) else InvalidValueError
            raise kind(f"{where}: {exc}") from exc
    if isinstance(spec, TransferFunction):
        return _rational(TransferFunction.coerce(spec, name=where))
    if isinstance(spec, tuple) and len(spec) in (2, 3) and _is_number_list(spec[0]) and _is_number_list(spec[1]):
        T = 0.0 if len(spec) == 2 else check_real(f"{where}: delay", spec[2], minimum=0.0)
        try:
            return _rational(TransferFunction(spec[0], spec[1]), T)
        except (InvalidValueError, InvalidTypeError) as exc:
            raise type(exc)(f"{where}: {exc}") from exc
    if isinstance(spec, numbers.Real) and not isinstance(spec, bool):
        x = check_real(f"{where}: a gain", spec)  # a finite number (10**400 and nan named)
        return _number(x, repr(x))
    raise InvalidTypeError(f"{where}: expected text such as '2*exp(-s)/(s+1)', a pair (num, den), a number or a "
                           f"TransferFunction, got {reprlib.repr(spec)} ({type(spec).__name__})")


@functools.lru_cache(maxsize=64)
def _number(x: float, spelling: str) -> DelayLTI:
    """A number as a static gain, remembered (the zeros of a diagonal controller's transfer matrix); ``spelling``
    tells apart ``-0.0`` and ``0.0``."""
    return gain(x)


def _matrix_of(rows: list, where: str) -> DelayLTI:
    """A transfer matrix from rows of SISO entries: every entry realised on its own, then summed along rows."""
    if not rows or not all(isinstance(r, (list, tuple)) and r for r in rows):
        raise InvalidValueError(f"{where}: a transfer matrix is a non-empty list of non-empty rows")
    nu = len(rows[0])
    if any(len(r) != nu for r in rows):
        raise InvalidValueError(f"{where}: the rows have different lengths {[len(r) for r in rows]}")
    ny = len(rows)
    entries = [_siso(rows[i][j], f"{where}, entry [{i}][{j}]") for i in range(ny) for j in range(nu)]
    P = _stack(entries)
    k = ny * nu
    F = np.zeros((k, k))
    G = np.zeros((k, nu))
    H = np.zeros((ny, k))
    for i in range(ny):
        for j in range(nu):
            G[i * nu + j, j] = 1.0
            H[i, i * nu + j] = 1.0
    return _closed(P, F, G, H, np.zeros((ny, nu)), None, None, "", "the interconnection", names_checked=True)


def _text_rows(rows: list) -> tuple[tuple[tuple[str | float | int, ...], ...], tuple[str, ...]] | None:
    """``rows`` as the arguments of :func:`_matrix_of_text` when every entry is text or a plain number, else None:
    the rows as tuples, and each number's spelling (``-0.0`` is not ``0.0``, whose systems differ in a zero's sign)."""
    key = tuple(tuple(r) for r in rows if isinstance(r, (list, tuple)))
    if len(key) != len(rows) or not all(type(x) in (str, float, int) for r in key for x in r):
        return None
    return key, tuple(repr(x) for r in key for x in r if type(x) is not str)


@functools.lru_cache(maxsize=128)
def _matrix_of_text(rows: tuple[tuple[str | float | int, ...], ...], spelling: tuple[str, ...]) -> DelayLTI:
    """:func:`_matrix_of` of rows of text and numbers, remembered as :func:`_text` remembers its texts (one plant
    written once and connected to many controllers is realised once); ``spelling`` tells apart numbers that
    compare equal."""
    return _matrix_of(rows, "tf")


def _from_control(obj: Any) -> DelayLTI:
    import control

    check_control_system(obj)
    ins, outs = list(getattr(obj, "input_labels", [])) or None, list(getattr(obj, "output_labels", [])) or None
    if isinstance(obj, control.StateSpace):
        return ss(obj.A, obj.B, obj.C, obj.D, inputs=ins, outputs=outs)
    num, den = getattr(obj, "num_array", obj.num), getattr(obj, "den_array", obj.den)
    rows = [[(np.asarray(num[i][j], float).tolist(), np.asarray(den[i][j], float).tolist())
             for j in range(obj.ninputs)] for i in range(obj.noutputs)]
    sys = _matrix_of(rows, "the python-control TransferFunction")
    return _rename(sys, ins, outs, None)


def tf(spec: Any, den: Any = None, *, inputs: Any = None, outputs: Any = None, name: str | None = None) -> Any:
    """A system from a transfer function or matrix with dead times, kept exact.

    Parameters
    ----------
    spec
        One of: text with ``exp(-T*s)`` factors (``"12.8*exp(-s)/(16.7*s+1)"``, the grammar of
        :meth:`~delaykit.models.TransferFunction.parse_with_delay`), where delayed terms may also be added and
        divided (``"1/(1 + exp(-s)/(s+1))"``: internal delays, combined by the algebra); a pair ``(num, den)``
        or a triple ``(num, den, delay)``; a number; a :class:`~delaykit.models.TransferFunction`; a list of rows
        of these (a transfer matrix); a python-control ``TransferFunction`` or ``StateSpace`` (MIMO too); a
        :class:`DelayLTI` (renamed); an expression of ``s``
        (:class:`~delaykit.systems.laplace.LaplaceExpression`).  ``tf("s")`` is the Laplace variable itself,
        for python-control's ``s = tf("s")`` and its algebra (``2*exp(-0.5*s)/(s + 1)``; an improper
        expression such as a PD law ``kp + kd*s`` is kept as an expression until it is combined into a proper
        one); other improper text (``"s + 1"``) is refused, as a plant must be proper.
    den : array_like, optional
        With ``spec`` the numerator's coefficients: ``tf(num, den)``, as python-control's.
    inputs, outputs : list of str or str, optional
        Signal names (python-control's ``u[i]`` and ``y[i]`` by default).
    name : str, optional
        A label.

    Returns
    -------
    DelayLTI

    Raises
    ------
    InvalidValueError, InvalidTypeError
        For text that is not a transfer function, an improper one, a negative delay, ragged rows, a
        discrete-time python-control system, ...

    See Also
    --------
    ss, delay, feedback

    Examples
    --------
    >>> tf("12.8*exp(-s)/(16.7*s+1)", inputs="u", outputs="y", name="G11")
    DelayLTI(G11: 1 input ['u'] -> 1 output ['y'], 1 state, delays [1] s)
    >>> tf(([2.0], [1.0, 1.0], 0.5)).delays
    (0.5,)
    >>> tf("(1 - exp(-2*s))/(s+1)")          # a difference of delayed paths
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 1 state, delays [2] s)
    >>> tf([2.0], [1.0, 1.0])                 # python-control's tf(num, den)
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 1 state, no delays)
    >>> s = tf("s")                           # the Laplace variable
    >>> 2 * exp(-0.5 * s) / (s + 1)
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 1 state, delays [0.5] s)
    """
    if den is not None:
        if isinstance(spec, (str, DelayLTI)) or not _is_number_list(spec) or not _is_number_list(den):
            raise InvalidTypeError(f"tf(num, den) takes two lists of coefficients (highest power first), got "
                                   f"{reprlib.repr(spec)} and {reprlib.repr(den)}")
        spec = (spec, den)
    if isinstance(spec, LaplaceExpression):
        return _rename(spec.to_system(), inputs, outputs, name)
    if isinstance(spec, str) and spec.strip() == "s":
        if inputs is not None or outputs is not None or name:
            raise InvalidValueError("tf('s') is the Laplace variable, an expression of s, not a system: it takes "
                                    "no names (name the system made from it)")
        return laplace_variable()
    if isinstance(spec, DelayLTI):
        sys = spec
    elif isinstance(spec, list):
        key = _text_rows(spec)
        sys = _matrix_of(spec, "tf") if key is None else _matrix_of_text(*key)
    elif (type(spec).__module__ or "").split(".")[0] == "control":
        sys = _from_control(spec)
    else:
        try:
            sys = _siso(spec, "tf")
        except InvalidValueError:
            if not isinstance(spec, str):
                raise
            try:  # read by the algebra of s: forms the reader refuses ("(s+1)/(s+0.5*exp(-s))"), improper text
                sys = parse_expression(spec)
            except (InvalidValueError, InvalidTypeError):
                sys = None
            if sys is None or isinstance(sys, LaplaceExpression):  # improper: the reader's reason stands
                raise
    return _rename(sys, inputs, outputs, name)


def ss(A: Any, B: Any, C: Any, D: Any = None, *, inputs: Any = None, outputs: Any = None, name: str = "") -> DelayLTI:
    """A delay-free state-space system ``x' = A x + B u``, ``y = C x + D u`` (as python-control's ``ss``).

    Delays are added by algebra (``ss(...) * delay(0.3)``) or :func:`interconnect`.

    Examples
    --------
    >>> ss([[-1.0]], [[1.0]], [[1.0]], [[0.0]]) * delay(0.2)
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 1 state, delays [0.2] s)
    """
    if (type(A).__module__ or "").split(".")[0] == "control":
        return tf(A, inputs=inputs, outputs=outputs, name=name or None)
    args = (A, B, C, D)
    for k, v in zip("ABCD", args):
        if _holds_bool(v):  # numpy would read True as 1.0; a bool is no number (as the algebra's gains say)
            raise InvalidTypeError(f"ss: {k} holds a bool ({reprlib.repr(v)}); write the numbers 1 or 0")
    for k, v in zip("ABC", args):
        if v is None:
            raise InvalidTypeError(f"ss: {k} must be a real matrix, got None")
    try:
        A, B, C = (_ss_array(k, v) for k, v in zip("ABC", args))
        D = None if D is None else _ss_array("D", D)
    except OverflowError:  # an integer beyond the floats (10**400)
        bad = next(k for k, v in zip("ABCD", args) if _overflows(v))
        raise InvalidValueError(f"ss: the entries of {bad} must be finite, got an integer beyond the floats in "
                                f"{bad} = {reprlib.repr(args['ABCD'.index(bad)])}") from None
    A = np.atleast_2d(A) if A.size else np.zeros((0, 0))  # (a 1-D A is a row, as python-control reads it)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise InvalidValueError(f"ss: A must be a square matrix, got shape {A.shape}")
    n = A.shape[0]
    # python-control's shapes: B has n rows (a 1-D B is one column), C has n columns (a 1-D C is one row); a scalar
    # only for one state.  Nothing is reshaped to fit: a B of 2 rows for 1 state is an error, not 2 inputs.
    B = _ss_shape("B", B, n, "rows", lambda a: a.reshape(-1, 1) if a.ndim == 1 else a.reshape(1, 1))
    C = _ss_shape("C", C, n, "columns", lambda a: a.reshape(1, -1) if a.ndim == 1 else a.reshape(1, 1))
    ny, nu = C.shape[0], B.shape[1]
    if n == 0 and (D is None or not D.size):
        raise InvalidValueError("ss: a system without states needs D, its matrix of gains (not empty)")
    if D is None or D.ndim == 0 and not D.any() and D.size:
        D = np.zeros((ny, nu))  # D = 0: zeros of the size B and C give (as python-control)
    if n == 0:
        D = np.atleast_2d(D)
        if D.ndim != 2:
            raise InvalidValueError(f"ss: D must be a matrix, got shape {D.shape}")
        return DelayLTI(D11=D, inputs=inputs, outputs=outputs, name=name)
    if D.ndim < 2 and D.size == ny * nu and (ny == 1 or nu == 1):
        D = D.reshape(ny, nu)  # a scalar or 1-D D for one input or one output
    if D.shape != (ny, nu):
        raise InvalidValueError(f"ss: D must have shape ({ny}, {nu}) (outputs of C, inputs of B), got {D.shape}")
    return DelayLTI(A=A, B1=B, C1=C, D11=D, inputs=inputs, outputs=outputs, name=name)


def _ss_array(key: str, value: Any) -> np.ndarray:
    """One of ss's matrices as a float array: complex values and anything that is not numbers refused."""
    try:
        arr = np.asarray(value)
        if arr.dtype.kind == "c" or arr.dtype == object and any(isinstance(x, complex) for x in arr.ravel()):
            raise InvalidTypeError(f"ss: {key} must be a real matrix, got complex entries in {reprlib.repr(value)}")
        return np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InvalidTypeError):
            raise
        raise InvalidTypeError(f"ss: {key} must be a real matrix (rows of numbers), got {reprlib.repr(value)}"
                               ) from None


def _ss_shape(key: str, arr: np.ndarray, n: int, side: str, reshape: Any) -> np.ndarray:
    """``arr`` (B or C) with ``n`` rows (``side = "rows"``) or columns, as python-control reads it."""
    if n == 0:
        if arr.size:
            raise InvalidValueError(f"ss: A has no states, so {key} must be empty, got shape {arr.shape}")
        return np.zeros((0, 0))
    if arr.ndim == 1 and arr.size == n or arr.ndim == 0 and n == 1:
        arr = reshape(arr)
    k = 0 if side == "rows" else 1
    if arr.ndim != 2 or arr.shape[k] != n:
        raise InvalidValueError(f"ss: {key} must have {n} {side[:-1] if n == 1 else side} (A has {n} "
                                f"state{'s' * (n != 1)}), got shape {arr.shape}")
    return arr


def _holds_bool(value: Any) -> bool:
    """True when ``value`` is a bool, a bool array, or a (nested) list with a bool in it."""
    if isinstance(value, (bool, np.bool_)):
        return True
    if isinstance(value, np.ndarray):
        return value.dtype == bool or (value.dtype == object and any(_holds_bool(x) for x in value.ravel()))
    if isinstance(value, (list, tuple)):
        return any(_holds_bool(x) for x in value)
    return False


def _overflows(value: Any) -> bool:
    """True when ``value`` holds an integer too large for a float."""
    try:
        np.array(value, dtype=float)
    except OverflowError:
        return True
    except (TypeError, ValueError):
        return False
    return False


def delay(T: float, *, inputs: Any = None, outputs: Any = None, name: str = "") -> DelayLTI:
    """The pure delay ``exp(-s T)``: ``y(t) = u(t - T)`` (a gain of 1 for ``T = 0``).

    Examples
    --------
    >>> delay(0.3)
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 0 states, delays [0.3] s)
    >>> delay(-1)
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: delay (s) must be at least 0, got -1
    """
    T = check_real("delay (s)", T, minimum=0.0)
    if T == 0.0:
        return gain(1.0, inputs=inputs, outputs=outputs, name=name)
    return DelayLTI(D12=[[1.0]], D21=[[1.0]], D11=[[0.0]], D22=[[0.0]], delays=[T], inputs=inputs,
                    outputs=outputs, name=name)


def saturation(lower: float, upper: float, *, inputs: Any = None, outputs: Any = None, name: str = "") -> DelayLTI:
    """The static saturation ``y = min(max(u, lower), upper)``, recorded as a channel with no delay.

    ``lower <= 0 <= upper`` (None or an infinite value for no limit on that side).  The linear analyses take it
    as the identity (see :class:`~delaykit.systems.lti.DelayLTI`).

    Examples
    --------
    >>> saturation(-1, 1)
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 0 states, delays [0] s, 1 saturation)
    """
    return DelayLTI(D12=[[1.0]], D21=[[1.0]], D11=[[0.0]], D22=[[0.0]], delays=[0.0], inputs=inputs,
                    outputs=outputs, name=name, limits=[(lower, upper)])


def to_control(sys: DelayLTI, pade_order: int | None = None) -> Any:
    """The system as a python-control ``StateSpace``, each delay channel replaced by a Padé approximation.

    Parameters
    ----------
    sys : DelayLTI
    pade_order : int, optional
        The order (at least 1) of the Padé approximant of every delay (:func:`~delaykit.systems.pade.pade`, the
        coefficients of ``control.pade``); required when the system has a delay.

    Raises
    ------
    InvalidValueError
        For a delayed system without ``pade_order``.
    MissingDependencyError
        When python-control is not installed.

    Examples
    --------
    >>> from delaykit import tf
    >>> G = to_control(tf("exp(-s)/(s+1)"), pade_order=3)
    >>> G.nstates, float(G.dcgain())
    (4, 1.0)
    """
    if not isinstance(sys, DelayLTI):
        raise InvalidTypeError(f"to_control takes a DelayLTI, got {type(sys).__name__}")
    if sys.saturations:
        raise InvalidValueError(f"the channels {list(sys.saturations)} saturate, which a python-control LTI system "
                                "cannot hold: convert sys.without_limits() for the small-signal system")
    control = require_control("to_control()")
    live = [t for t in sys.delays if t > 0]
    if live and pade_order is None:
        raise InvalidValueError(f"the system has delays {list(sys.delays)} s, which python-control cannot represent "
                                "exactly: give pade_order=n for an n-th order Padé approximation of each")
    if live:
        pade_order = check_pade_order(pade_order)
    if sys.ndelays:  # every channel closed over its Padé approximant (a zero delay closed as it is)
        sys = pade(sys, int(pade_order) if live else 1)
    return control.ss(sys.A, sys.B1, sys.C1, sys.D11, inputs=list(sys.inputs), outputs=list(sys.outputs))


def from_loop(loop: Any, *, ignore_limits: bool = False) -> DelayLTI:
    """The closed loop of a continuous :class:`~delaykit.models.Loop` (or ``AltitudeLoop``) as a system.

    Inputs ``["r", "d"]`` (the reference and the load disturbance at the plant input, after the input delay) and
    outputs ``["y", "u"]`` (the plant output and the command, after the limits); the blocks are the controller's
    realisation, the plant, the limits, and the input, output and (for a predictor) model delays, connected by
    :func:`interconnect`.

    A compensator's internal model is part of the realisation: its modes are poles of the system even where they
    cancel in every transfer function (an integrating model's pole at 0: the classical Smith predictor of an
    integrating plant is not internally asymptotically stable).

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A continuous loop (no sampling period).
    ignore_limits : bool
        By default the actuator's limits become a saturation channel (with back-calculation anti-windup, if the
        controller has it, wired to the saturated command; clamping anti-windup is refused); True drops them.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> T = from_loop(AltitudeLoop(kp=1.31, delay=0.368, vmax=None))
    >>> T
    DelayLTI(loop: 2 inputs ['r', 'd'] -> 2 outputs ['y', 'u'], 1 state, delays [0.368] s)
    >>> float(T.dcgain()[0, 0])
    1.0
    """
    from ..models.altitude import as_loop

    try:
        lp = as_loop(loop)
    except (InvalidTypeError, InvalidValueError, AttributeError):
        raise InvalidTypeError(f"from_loop takes a Loop or an AltitudeLoop, got {type(loop).__name__}") from None
    if lp.sampled:
        raise InvalidValueError(f"the loop samples its controller (period {lp.period:g} s), which is not a "
                                "continuous LTI system; give a continuous loop")
    limited = lp.saturated and not ignore_limits
    r = lp.controller.realisation()
    velocity = bool(np.any(r.Bcv) or r.dvv)
    cols, ins, dv = [r.Bcr, r.Bcy], ["r", "ym"], [r.dvr, r.dvy]
    if velocity:
        cols, ins, dv = cols + [r.Bcv], ins + ["vm"], dv + [r.dvv]
    if r.Bcu is not None and np.any(r.Bcu):
        cols, ins, dv = cols + [r.Bcu], ins + ["u"], dv + [0.0]
    blocks = []
    if r.Bcm is not None and np.any(r.Bcm):
        cols, ins, dv = cols + [r.Bcm], ins + ["u_model"], dv + [0.0]
        blocks.append(delay(r.model_delay, inputs="u", outputs="u_model", name="model delay"))
    k = r.order
    B = np.column_stack(cols) if k else np.zeros((0, len(ins)))
    Ac, Cc = r.Ac, np.asarray(r.Cc, float).reshape(1, k)
    if limited:
        if getattr(lp.controller, "antiwindup", "none") == "clamp" and k:
            raise InvalidValueError("clamping anti-windup (integration stopped at a limit) is not a saturation "
                                    "channel of a linear system; use antiwindup='backcalc' or ignore_limits=True")
        # back-calculation Baw (u - v): v = Cc xc + dv [inputs], u the saturated command
        Baw = np.asarray(r.Baw, float).reshape(k, 1)
        if Baw.any():
            Ac, B = Ac - Baw @ Cc, B - Baw @ np.array([dv])
            if "u" in ins:  # a predictor reads the command already
                B[:, ins.index("u")] += Baw[:, 0]
            else:
                B, ins, dv = np.hstack([B, Baw]), ins + ["u"], dv + [0.0]
        blocks.append(saturation(lp.umin, lp.umax, inputs="v", outputs="u", name="actuator limits"))
    blocks.append(ss(Ac, B, Cc, [dv], inputs=ins, outputs=["v" if limited else "u"], name="controller"))
    A, Bp, Cp, Dp = lp.plant.state_space()
    n = A.shape[0]
    Bp, Cp = Bp.reshape(n, 1), Cp.reshape(1, n)
    if velocity:  # the output and its derivative (the plant is strictly proper: Loop checks it)
        plant = ss(A, Bp, np.vstack([Cp, Cp @ A]), [[Dp], [float((Cp @ Bp)[0, 0])]], inputs="up",
                   outputs=["y", "ydot"], name="plant")
        blocks.append(delay(lp.output_delay, inputs="ydot", outputs="vm", name="velocity delay"))
    else:
        plant = ss(A, Bp, Cp, [[Dp]], inputs="up", outputs="y", name="plant")
    blocks += [plant, delay(lp.delay, inputs="u", outputs="ud", name="input delay"),
               summing_junction(["ud", "d"], "up"), delay(lp.output_delay, inputs="y", outputs="ym",
                                                           name="output delay")]
    return interconnect(blocks, inputs=["r", "d"], outputs=["y", "u"], name="loop")



def system_of(x: Any) -> Any:
    """The closed loop ``x.system`` (:func:`from_loop`, cached) of a :class:`~delaykit.models.Loop` or an
    ``AltitudeLoop``; anything else unchanged (the caller checks it): how the system-level functions (``poles``,
    ``is_stable``, ``hinfnorm``, ``step_response``, ...) take a loop.

    Examples
    --------
    >>> from delaykit import AltitudeLoop, tf
    >>> loop = AltitudeLoop(kp=1.31, delay=0.368)
    >>> system_of(loop) is loop.system, system_of(tf("1/s")) == tf("1/s")
    (True, True)
    """
    from ..models.altitude import AltitudeLoop
    from ..models.loop import Loop

    return x.system if isinstance(x, (Loop, AltitudeLoop)) else x


def _subset_terms(sys: DelayLTI, transfer: bool) -> dict[float, np.ndarray]:
    """The characteristic function ``det(sI - A) det(I - P22 Delta)`` (``transfer`` False) or the numerator of the
    SISO transfer function over it (True) as ``{delay: ascending polynomial coefficients}``, equal delays summed.

    Both are multilinear in the channels' ``exp(-s tau_j)``: a sum over the subsets ``S`` of channels of
    ``exp(-s sum_S tau_j)`` times the determinant of ``[[sI - A, -B2_S], [-C2_S, -D22_SS]]`` (bordered by
    ``[-B1; -D21_S]`` and ``[C1, D12_S, D11]`` for the numerator, by the Schur complement), each polynomial
    interpolated on a circle as :meth:`DelayLTI.characteristic`.
    """
    n, m = sys.nstates, sys.ndelays
    eig = np.linalg.eigvals(sys.A) if n else np.zeros(0)
    mags = np.abs(eig)
    # an eigenvalue at 0 computed as 1e-18 is 0: counted, it would shrink the circle to the rounding level
    mags = mags[mags > 1e-12 * mags.max()] if mags.size else mags
    radius = float(np.exp(np.mean(np.log(mags)))) if mags.size else 1.0
    pts = radius * np.exp(2j * np.pi * np.arange(n + 1) / (n + 1))
    terms: dict[float, np.ndarray] = {}
    for mask in range(1 << m):
        S = [j for j in range(m) if mask >> j & 1]
        rows = [np.hstack([-sys.A, -sys.B2[:, S]]), np.hstack([-sys.C2[S, :], -sys.D22[np.ix_(S, S)]])]
        if transfer:
            rows = [np.hstack([rows[0], -sys.B1]), np.hstack([rows[1], -sys.D21[S, :]]),
                    np.hstack([sys.C1, sys.D12[:, S], sys.D11])]
        G = np.vstack(rows)
        F = np.zeros_like(G)
        F[:n, :n] = np.eye(n)
        vals = np.array([np.linalg.det(p * F + G) for p in pts])
        c = np.fft.fft(vals).real / (n + 1) / radius ** np.arange(n + 1)
        tau = sum(sys.delays[j] for j in S)
        key = next((k for k in terms if abs(k - tau) <= 1e-12 * max(1.0, tau)), tau)
        terms[key] = terms.get(key, 0.0) + c
    scale = radius ** np.arange(n + 1)
    big = max(float(np.max(np.abs(c * scale))) for c in terms.values())
    # coefficients at rounding level of the largest (scaled) one are noise of the interpolation or cancellations
    terms = {k: np.where(np.abs(c * scale) <= 1e-11 * big, 0.0, c) for k, c in terms.items()}
    return {k: c for k, c in terms.items() if c.any()}


def plant_of(sys: DelayLTI) -> tuple[TransferFunction, float]:
    """A SISO system that is a rational transfer function times a dead time, as ``(G, T)``: ``exp(-s T) G(s)``.

    The inverse of ``tf((num, den, T))`` and the shape of :meth:`TransferFunction.parse_with_delay`'s answer,
    ready to be a :class:`~delaykit.models.Loop`'s plant and delay (see :func:`to_loop`).  Any realisation is
    accepted, internal delays included, as long as no delay lies inside a loop of the system and every path from
    the input to the output carries the same total delay; ``G``'s denominator is ``det(sI - A)`` (hidden modes
    kept, as :func:`from_loop` keeps them; :meth:`TransferFunction.minimal` cancels them).

    Parameters
    ----------
    sys : DelayLTI
        One input, one output, no saturation channel.

    Returns
    -------
    (TransferFunction, float)
        The rational part and the dead time (s).

    Raises
    ------
    InvalidValueError
        For several inputs or outputs, a saturation, a delay inside a loop (the characteristic function has
        delayed terms: not rational times a dead time), paths with different delays (``1 + exp(-s)``), or a
        rational part of order over :data:`~delaykit.models.transfer.MAX_ORDER`.

    See Also
    --------
    to_loop, from_loop, tf

    Examples
    --------
    >>> from delaykit import tf, delay
    >>> plant_of(delay(0.1) * tf("2*exp(-0.25*s)/(s+1)"))
    (TransferFunction(2/(s + 1)), 0.35)
    >>> plant_of(tf("1/(s+1)") + tf("exp(-s)/(s+1)"))
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: the system's paths from input to output carry different delays [0, 1] s, so it is not a rational transfer function times one dead time
    """
    if not isinstance(sys, DelayLTI):
        raise InvalidTypeError(f"plant_of takes a DelayLTI, got {type(sys).__name__}")
    label = f"the system {sys.name!r}" if sys.name else "the system"
    if (sys.ninputs, sys.noutputs) != (1, 1):
        raise InvalidValueError(f"{label} has {sys.ninputs} inputs and {sys.noutputs} outputs; a loop's plant has "
                                "one of each (select one with sys[i, j])")
    if sys.saturations:
        raise InvalidValueError(f"{label} saturates (channels {list(sys.saturations)}), which a loop's plant "
                                "cannot; give the actuator's limits as the loop's umin and umax")
    from .lti import _MAX_CHANNELS

    if sys.ndelays > _MAX_CHANNELS:
        raise InvalidValueError(f"{label} has {sys.ndelays} delay channels; at most {_MAX_CHANNELS} are supported")
    char = _subset_terms(sys, transfer=False)
    looped = sorted(k for k in char if k > 0)
    if looped:
        raise InvalidValueError(f"{label} has a delay inside a loop (its characteristic function has terms delayed "
                                f"by [{', '.join(f'{k:.6g}' for k in looped)}] s), so it is not a rational transfer "
                                "function times a dead time")
    if 0.0 not in char:
        raise InvalidValueError(f"{label} is not well posed: its characteristic function is zero")
    num = _subset_terms(sys, transfer=True)
    if len(num) > 1:
        raise InvalidValueError(f"{label}'s paths from input to output carry different delays "
                                f"[{', '.join(f'{k:.6g}' for k in sorted(num))}] s, so it is not a rational transfer "
                                "function times one dead time")
    T, b = next(iter(num.items()), (0.0, np.zeros(1)))
    try:
        g = TransferFunction(b[::-1], char[0.0][::-1])
    except InvalidValueError as exc:
        raise InvalidValueError(f"{label}: the rational part {exc}") from None
    return g, float(T)


def _input_saturation(sys: DelayLTI) -> tuple[DelayLTI, tuple[float, float]] | None:
    """``(rest, (lower, upper))`` when the SISO ``sys`` is ``rest * saturation(lower, upper)``: a saturation channel
    without delay that reads the input alone (``z_j = u``) and is the input's only path; else None."""
    for j in sys.saturations:
        others = [i for i in range(sys.ndelays) if i != j]
        if (sys.delays[j] == 0.0 and sys.D21[j, 0] == 1.0 and not sys.C2[j].any() and not sys.D22[j].any()
                and not sys.B1.any() and not sys.D11.any() and not sys.D21[others].any()):
            rest = DelayLTI(sys.A, sys.B2[:, [j]], sys.B2[:, others], sys.C1, sys.C2[others], sys.D12[:, [j]],
                            sys.D12[:, others], sys.D22[others][:, [j]], sys.D22[np.ix_(others, others)],
                            delays=[sys.delays[i] for i in others], limits=[sys.limits[i] for i in others],
                            inputs=sys.inputs, outputs=sys.outputs, name=sys.name)
            return rest, sys.limits[j]
    return None


def to_loop(plant: DelayLTI, controller: Any = None, *, output_delay: float = 0.0, umin: float | None = None,
            umax: float | None = None, period: float | None = None, sample_offset: float = 0.0,
            name: str = "") -> Any:
    """A :class:`~delaykit.models.Loop` around a plant given as a system ``exp(-s T) G(s)`` (see :func:`plant_of`).

    The inverse of :func:`from_loop`'s plant side: ``G`` becomes the loop's plant and the dead time ``T`` its
    delay, all of it on the command unless ``output_delay`` (at most ``T``) puts part of it on the measurement
    (the same loop transfer; the load disturbance and the measured output see the split).  A saturation at the
    plant's input (``G * delay(T) * saturation(lower, upper)``) becomes the loop's actuator limits.

    Parameters
    ----------
    plant : DelayLTI
        A SISO system without a delay inside a loop.
    controller : Controller or Compensator, optional
        The control law (default ``Controller.p(1.0)``, as ``Loop``'s).
    output_delay : float
        The part of ``T`` on the measurement (s).
    umin, umax : float, optional
        The actuator's limits (none by default; not with a saturation at the plant's input, which gives them).
    period, sample_offset, name
        As :class:`~delaykit.models.Loop`.

    Returns
    -------
    Loop

    See Also
    --------
    plant_of, from_loop

    Examples
    --------
    >>> from delaykit import Controller, tf
    >>> to_loop(tf("exp(-0.368*s)/s"), Controller.p(1.31), umin=-1, umax=1)
    Loop(plant 1/s, p: kp=1.31, delay=0.368 s, u in [-1, 1], continuous)
    >>> from delaykit import saturation
    >>> to_loop(tf("exp(-0.368*s)/s") * saturation(-1, 1), Controller.p(1.31))     # the limits from the system
    Loop(plant 1/s, p: kp=1.31, delay=0.368 s, u in [-1, 1], continuous)
    """
    from ..models.controllers import Controller
    from ..models.loop import Loop

    if isinstance(plant, DelayLTI) and plant.saturations and (plant.ninputs, plant.noutputs) == (1, 1):
        found = _input_saturation(plant)
        if found is not None:
            if umin is not None or umax is not None:
                raise InvalidValueError("the plant system saturates its input already, which gives the loop's "
                                        "limits; give umin and umax, or the saturation, not both")
            plant, (umin, umax) = found
    g, T = plant_of(plant)
    umin = -np.inf if umin is None else umin
    umax = np.inf if umax is None else umax
    To = check_real("output_delay (s)", output_delay, minimum=0.0)
    if To > T * (1 + 1e-12):
        raise InvalidValueError(f"output_delay {To:g} s is more than the plant's dead time {T:g} s")
    To = min(To, T)
    return Loop(g, Controller.p(1.0) if controller is None else controller, delay=max(T - To, 0.0),
                output_delay=To, umin=umin, umax=umax, period=period, sample_offset=sample_offset, name=name)
