"""Rational transfer functions in ``s``: the plant (and controller) of a loop, read from text or python-control.

A :class:`TransferFunction` is a single-input single-output rational function

    ``G(s) = (b_m s^m + ... + b_1 s + b_0) / (s^n + a_(n-1) s^(n-1) + ... + a_0)``

kept as two NumPy float arrays, highest power first (the :func:`numpy.polyval` convention).  The denominator
is made monic (leading coefficient 1) and leading zeros are stripped (a function read from text is still printed
with the coefficients the text gave it: ``0.6976/(146.6 s + 1)``, ``1/(0.05 s^2 + s)``), but common factors are
*kept*, so ``(s+2)/(s^2+3*s+2)`` stays of order 2; :meth:`TransferFunction.minimal` cancels them.  Degrees are at most
:data:`MAX_ORDER`, and by default only proper functions (``m <= n``) are accepted, since a loop with a delay
needs a proper plant; ``proper=False`` admits improper controllers such as the PD law ``4*s + 2``.

Grammar of :meth:`TransferFunction.parse`
-----------------------------------------
The text is read with Python's :mod:`ast` and interpreted as rational arithmetic on (numerator,
denominator) polynomial pairs; it is never evaluated::

    expr     := expr + expr | expr - expr | expr * expr | expr / expr | +expr | -expr
              | expr ** exponent | expr ^ exponent | ( expr ) | number | s | exp(delay)
    number   := an int or float literal: 2, 0.05, 1e-3
    exponent := a constant with an integer value 0 ... 12: 2, (1+1), 4/2
    delay    := -T*s, -s*T, -s/T ... : linear in s with no constant term and T >= 0

Products are always written out (``2*s``; ``2s`` and ``2 s`` are refused) and ``^`` means a power.
``exp(-T*s)`` is a delay: it may only *multiply* the rest, as in ``0.62*exp(-12*s)/(150*s+1)``.
:meth:`TransferFunction.parse_with_delay` returns the rational part and the total delay;
:meth:`TransferFunction.parse` refuses delays (give them through the loop's delay option instead).
Bad input raises :class:`~delaykit.errors.InvalidValueError` or :class:`~delaykit.errors.InvalidTypeError`
with a message that names the text.

Examples
--------
>>> g = TransferFunction.parse("1/(s*(0.05*s+1))")
>>> g                                                   # printed as written; kept normalised
TransferFunction(1/(0.05 s^2 + s))
>>> g.num.tolist(), g.den.tolist()
([20.0], [1.0, 20.0, 0.0])
>>> TransferFunction.parse_with_delay("0.62*exp(-12*s)/(150*s+1)")[1]
12.0
"""

from __future__ import annotations

import ast
import math
import numbers
import reprlib
from dataclasses import dataclass
from typing import Any, NamedTuple, NoReturn

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, MissingDependencyError, check_real
from .budget import MAX_TEXT_CHARS

__all__ = ["TransferFunction", "MAX_ORDER", "check_control_system"]

MAX_ORDER = 12
"""The highest order (denominator degree) a :class:`TransferFunction` may have."""
_MAX_COEFF = 1e100  # larger numbers, or normalised coefficients, are refused as badly scaled
_MAX_TEXT = MAX_TEXT_CHARS  # characters
_MAX_WORK_DEGREE = 4 * MAX_ORDER  # degree allowed in intermediate results while parsing
_ONE = np.ones(1)
_S = np.array([1.0, 0.0])


def _real_array(name: str, value: Any) -> np.ndarray:
    """``value`` as a finite float array; text, bools, complex numbers and None are refused."""
    if value is None or isinstance(value, (str, bytes, dict, set)):
        raise InvalidTypeError(f"{name} must be real numbers, got {reprlib.repr(value)} ({type(value).__name__})")
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise InvalidValueError(f"{name} must be a regular array of numbers, got {reprlib.repr(value)}") from exc
    if arr.dtype.kind != "b" and not isinstance(value, np.ndarray) and any(
            isinstance(x, (bool, np.bool_)) for x in np.asarray(value, dtype=object).flat):
        arr = np.asarray(value, dtype=object)  # a bool among numbers: refused below
    if arr.dtype == object and all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in arr.flat):
        try:
            arr = arr.astype(float)
        except OverflowError:  # an integer of hundreds of digits
            raise InvalidValueError(f"{name} must be finite, got an integer beyond the floats in "
                                    f"{reprlib.repr(value)}") from None
    if arr.dtype.kind not in "iuf":
        raise InvalidTypeError(f"{name} must be real numbers, got {reprlib.repr(value)} (dtype {arr.dtype})")
    arr = arr.astype(float)
    if not np.all(np.isfinite(arr)):
        raise InvalidValueError(f"{name} must be finite, got {arr.tolist()}")
    return arr


def _quoted(text: str, limit: int = 80) -> str:
    """``repr(text)``, shortened with ``...`` past ``limit`` characters."""
    return repr(text if len(text) <= limit else text[:limit - 3] + "...")


def _trim(p: np.ndarray) -> np.ndarray:
    """Strip leading zeros; the zero polynomial is ``[0.]``."""
    if p.ndim == 1 and p.size and p[0] != 0:  # the common case, without a search
        return p[0:]
    nz = np.flatnonzero(p)
    return p[nz[0]:] if nz.size else np.zeros(1)


def _padd(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    if p.size < q.size:
        p, q = q, p
    k = p.size - q.size  # q padded with k leading zeros, as the sum p + pad(q) adds them
    out = np.empty(p.size)
    out[:k] = p[:k] + 0.0
    out[k:] = p[k:] + q
    return _trim(out)


def _pmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The product of two polynomials: :func:`numpy.polymul`'s (leading zeros stripped, then convolved) without its
    ``poly1d`` objects, which cost most of the time of reading a transfer function."""
    return np.convolve(_trim(p), _trim(q))


def _normalise(num: np.ndarray, den: np.ndarray, what: str, proper: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Trimmed, monic-denominator copies of ``num``/``den``, or an error naming ``what``."""
    num, den = _trim(np.ravel(num).astype(float)), _trim(np.ravel(den).astype(float))
    if not den.any():
        raise InvalidValueError(f"{what}: the denominator is zero")
    if proper and num.any() and num.size > den.size:
        raise InvalidValueError(
            f"{what} is improper: the numerator degree {num.size - 1} exceeds the denominator degree "
            f"{den.size - 1}; a delayed loop needs a proper plant (numerator degree <= denominator degree); "
            "pass proper=False for a controller such as a PD law")
    if max(num.size, den.size) - 1 > MAX_ORDER:
        raise InvalidValueError(f"{what} has degree {max(num.size, den.size) - 1}, more than MAX_ORDER = {MAX_ORDER}")
    lead = den[0]
    with np.errstate(all="ignore"):
        num, den = _trim(num / lead + 0.0), den / lead + 0.0  # + 0.0 turns -0.0 into 0.0; tiny b_m may underflow
    worst = max(np.max(np.abs(num)), np.max(np.abs(den)))
    if not worst <= _MAX_COEFF:
        raise InvalidValueError(
            f"{what} is badly scaled: divided by the leading denominator coefficient {lead:g} a coefficient "
            f"becomes {worst:g} (at most {_MAX_COEFF:g} allowed)")
    return num, den


def _poly_text(p: np.ndarray, fmt: str, times: str) -> tuple[str, int]:
    """The polynomial ``p`` in ``s`` as text, and its number of terms."""
    terms = []
    for k, c in enumerate(p):
        if c == 0:
            continue
        power, mag = p.size - 1 - k, fmt % abs(c)
        var = "" if power == 0 else "s" if power == 1 else f"s^{power}"
        body = mag if not var else var if mag == "1" else f"{mag}{times}{var}"
        terms.append(("-" if c < 0 else "+", body))
    if not terms:
        return "0", 1
    text = ("-" if terms[0][0] == "-" else "") + terms[0][1]
    return text + "".join(f" {sign} {body}" for sign, body in terms[1:]), len(terms)


class _Val(NamedTuple):
    num: np.ndarray
    den: np.ndarray
    delay: float = 0.0
    has_exp: bool = False


class _Reader:
    """Rational arithmetic over the ``ast`` of a transfer function's text (nothing is evaluated)."""

    def __init__(self, text: str, src: str) -> None:
        self.text, self.src = _quoted(text), src

    def fail(self, why: str) -> NoReturn:
        raise InvalidValueError(f"could not read the transfer function {self.text}: {why}")

    def seg(self, node: ast.AST) -> str:
        text = (ast.get_source_segment(self.src, node) or ast.unparse(node)).replace("**", "^")
        return text if len(text) <= 60 else text[:57] + "..."

    def checked(self, num: np.ndarray, den: np.ndarray, node: ast.AST, delay: float = 0.0,
                has_exp: bool = False) -> _Val:
        num, den = _trim(num), _trim(den)
        if not (np.isfinite(num).all() and np.isfinite(den).all()):
            self.fail(f"the coefficients of '{self.seg(node)}' overflow")
        if max(num.size, den.size) - 1 > _MAX_WORK_DEGREE:
            self.fail(f"'{self.seg(node)}' has degree over {_MAX_WORK_DEGREE}")
        return _Val(num, den, delay, has_exp)

    def value(self, node: ast.AST) -> _Val:
        if isinstance(node, ast.Constant):
            return _Val(np.array([self.number(node)]), _ONE)
        if isinstance(node, ast.Name):
            if node.id == "s":
                return _Val(_S, _ONE)
            self.unknown(f"the unknown name {node.id!r}")
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            v = self.value(node.operand)
            return v if isinstance(node.op, ast.UAdd) else v._replace(num=-v.num)
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            return self.power(node)
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
            a, b = self.value(node.left), self.value(node.right)
            with np.errstate(all="ignore"):
                if isinstance(node.op, (ast.Add, ast.Sub)):
                    if a.has_exp or b.has_exp:
                        self.fail(f"in '{self.seg(node)}' a delay factor exp(-T*s) is added to something; it may "
                                  "only multiply the rest of the transfer function")
                    bn = b.num if isinstance(node.op, ast.Add) else -b.num
                    if np.array_equal(a.den, b.den):
                        return self.checked(_padd(a.num, bn), a.den, node)
                    num = _padd(_pmul(a.num, b.den), _pmul(bn, a.den))
                    return self.checked(num, _pmul(a.den, b.den), node)
                if isinstance(node.op, ast.Mult):
                    return self.checked(_pmul(a.num, b.num), _pmul(a.den, b.den), node,
                                        a.delay + b.delay, a.has_exp or b.has_exp)
                if b.has_exp:
                    self.fail(f"'{self.seg(node.right)}' puts a delay factor exp(-T*s) in a denominator (a "
                              "prediction); delays may only multiply the numerator")
                if not b.num.any():
                    self.fail(f"division by zero: '{self.seg(node.right)}' is zero")
                return self.checked(_pmul(a.num, b.den), _pmul(a.den, b.num), node, a.delay, a.has_exp)
        if isinstance(node, ast.Call):
            return self.call(node)
        if isinstance(node, ast.BinOp):
            self.fail(f"the operator in '{self.seg(node)}' is not allowed; use + - * / and ** or ^")
        self.fail(f"'{self.seg(node)}' is not allowed; write numbers, s, + - * / ** ^, parentheses and exp(-T*s)")

    def unknown(self, what: str) -> NoReturn:
        raise InvalidValueError(f"the transfer function {self.text} uses {what}; only the variable s and the "
                                "delay factor exp(-T*s) are allowed")

    def number(self, node: ast.Constant) -> float:
        v = node.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(f"{self.seg(node)} is not a real number")
        try:
            x = float(v)
        except OverflowError:
            self.fail(f"the number {self.seg(node)} is too large (at most {_MAX_COEFF:g})")
        if not math.isfinite(x):
            self.fail(f"the number {self.seg(node)} is not finite")
        if abs(x) > _MAX_COEFF:
            self.fail(f"the number {self.seg(node)} is too large (at most {_MAX_COEFF:g})")
        return x

    def power(self, node: ast.BinOp) -> _Val:
        e = self.value(node.right)
        k = e.num[0] / e.den[0] if e.num.size == e.den.size == 1 and not e.has_exp else math.nan
        if not (math.isfinite(k) and k == round(k) and 0 <= k <= MAX_ORDER):
            got = f"{k:g}" if math.isfinite(k) else f"'{self.seg(node.right)}'"
            self.fail(f"the exponent in '{self.seg(node)}' must be a constant integer from 0 to {MAX_ORDER}, got {got}")
        k, base = int(k), self.value(node.left)
        if (max(base.num.size, base.den.size) - 1) * k > _MAX_WORK_DEGREE:
            self.fail(f"'{self.seg(node)}' has degree over {_MAX_WORK_DEGREE}")
        num, den = _ONE, _ONE
        with np.errstate(all="ignore"):
            for _ in range(k):
                num, den = _pmul(num, base.num), _pmul(den, base.den)
        return self.checked(num, den, node, base.delay * k, base.has_exp and k > 0)

    def call(self, node: ast.Call) -> _Val:
        if not isinstance(node.func, ast.Name):
            self.fail(f"'{self.seg(node)}' is not allowed")
        if node.func.id != "exp":
            self.unknown(f"the unknown function {node.func.id!r}")
        if len(node.args) != 1 or node.keywords:
            self.fail(f"'{self.seg(node)}': exp takes one argument, as in exp(-0.3*s)")
        arg = self.value(node.args[0])
        p = _trim(arg.num / arg.den[0]) if arg.den.size == 1 and not arg.has_exp else np.zeros(3)
        if p.size > 2 or (p.size == 2 and p[1] != 0) or (p.size == 1 and p[0] != 0):
            self.fail(f"'{self.seg(node)}' is not a delay factor: its argument must be -T*s with T >= 0 (linear "
                      "in s, no constant term)")
        delay = -p[0] + 0.0 if p.size == 2 else 0.0
        if delay < 0:
            self.fail(f"'{self.seg(node)}' is a prediction (delay {delay:g} < 0); only delays exp(-T*s) with "
                      "T >= 0 are allowed")
        return _Val(_ONE, _ONE, float(delay), True)


def _read(text: Any) -> tuple[_Val, str]:
    """Parse ``text`` into a rational value with delay, and a label for messages."""
    if not isinstance(text, str):
        raise InvalidTypeError(f"a transfer function must be text, got {reprlib.repr(text)} ({type(text).__name__})")
    if len(text) > _MAX_TEXT:
        raise InvalidValueError(f"could not read the transfer function {_quoted(text)}: longer than {_MAX_TEXT} "
                                "characters (delaykit.models.budget.MAX_TEXT_CHARS)")
    src = text.replace("^", "**").strip()
    reader = _Reader(text, src)
    if not src:
        reader.fail("it is empty")
    try:
        tree = ast.parse(src, mode="eval")
    except SyntaxError as exc:
        reader.fail(f"{exc.msg.split('. Perhaps')[0]} at column {exc.offset}; write products with * (2*s, not 2s)")
    except (ValueError, RecursionError, MemoryError) as exc:
        reader.fail(str(exc) or type(exc).__name__)
    try:
        return reader.value(tree.body), f"the transfer function {_quoted(text)}"
    except RecursionError:
        reader.fail("it is nested too deeply")


def check_control_system(obj: Any) -> str:
    """The class name of a continuous-time python-control ``TransferFunction`` or ``StateSpace``; an error for
    any other python-control object or a discrete-time one."""
    import control

    kind = type(obj).__name__
    if not isinstance(obj, (control.TransferFunction, control.StateSpace)):
        raise InvalidTypeError(f"python-control {kind} objects are not supported; give a TransferFunction "
                               "or a StateSpace")
    dt = obj.dt
    if not (dt is None or (not isinstance(dt, bool) and dt == 0)):
        raise InvalidValueError(f"the python-control {kind} is discrete-time (dt = {dt}); only "
                                "continuous-time systems (dt = 0) are supported")
    return kind


def _scalar(x: Any) -> float | None:
    """``x`` as a float if it is a real scalar (not a bool), else None."""
    if isinstance(x, (bool, np.bool_)):
        return None
    if isinstance(x, numbers.Real) or (isinstance(x, np.ndarray) and x.ndim == 0 and x.dtype.kind in "iuf"):
        try:
            return float(x)
        except OverflowError:  # 10**400
            raise InvalidValueError(f"a gain must be finite, got an integer of about {len(str(abs(int(x))))} "
                                    "digits") from None
    return None


@dataclass(frozen=True, init=False, repr=False, eq=False)
class TransferFunction:
    """A SISO rational transfer function ``num(s)/den(s)`` of degree at most ``MAX_ORDER``.

    Parameters
    ----------
    num, den : sequence of float
        Coefficients, highest power first.  They are copied, leading zeros stripped and both divided by the
        leading denominator coefficient; common factors are kept.  Scalars count as constant polynomials.
    proper : bool, keyword-only
        Refuse a numerator of higher degree than the denominator (the default: a plant must be proper).
        ``proper=False`` admits improper controllers such as the PD law ``4*s + 2``.

    Attributes
    ----------
    num, den : numpy.ndarray
        Read-only normalised coefficients (``den[0] == 1``; the zero numerator is ``[0.]``).

    Notes
    -----
    ``==`` compares the normalised coefficients exactly (compare ``num`` and ``den`` with
    :func:`numpy.allclose` for a tolerance), and instances are hashable.  Operators: ``G * H``, ``2 * G``
    (series), ``G + H``, ``G - H`` (parallel), ``-G``.

    Examples
    --------
    >>> TransferFunction([2, 4], [2, 6, 4])
    TransferFunction((s + 2)/(s^2 + 3 s + 2))
    >>> TransferFunction([1], [1, 1]) == TransferFunction.parse("1/(s+1)")
    True
    >>> 2 * TransferFunction.parse("1/s") + 1
    TransferFunction((s + 2)/s)
    """

    num: np.ndarray
    den: np.ndarray
    __array_ufunc__ = None  # numpy scalars then defer to __rmul__ / __radd__

    def __init__(self, num: Any, den: Any, *, proper: bool = True) -> None:
        n, d = _real_array("numerator coefficients", num), _real_array("denominator coefficients", den)
        if n.ndim > 1 or d.ndim > 1:
            raise InvalidValueError(f"coefficients must be flat sequences, got shapes {n.shape} and {d.shape}")
        what = f"the transfer function with numerator {n.tolist()} and denominator {d.tolist()}"
        if n.size == 0 or d.size == 0:
            raise InvalidValueError(f"{what}: a polynomial needs at least one coefficient")
        self._set(*_normalise(n, d, what, proper))

    def _set(self, num: np.ndarray, den: np.ndarray) -> None:
        num.flags.writeable = den.flags.writeable = False
        object.__setattr__(self, "num", num)
        object.__setattr__(self, "den", den)

    def _written(self, v: _Val) -> TransferFunction:
        """Keep the coefficients as the text gave them (before the denominator was made monic), for display: the
        gain-and-time-constant form ``K/(T s + 1)`` of a self-regulating plant, and an integrator's scale
        (``1/(s*(0.05*s+1))`` prints ``1/(0.05 s^2 + s)``, its products expanded)."""
        num, den = _trim(np.ravel(v.num).astype(float)), _trim(np.ravel(v.den).astype(float))
        if np.isfinite(num).all() and np.isfinite(den).all() and den.any():
            num.flags.writeable = den.flags.writeable = False
            object.__setattr__(self, "_as_written", (num, den))
        return self

    @classmethod
    def _make(cls, num: np.ndarray, den: np.ndarray, what: str, proper: bool = True) -> TransferFunction:
        tf = object.__new__(cls)
        tf._set(*_normalise(num, den, what, proper))
        return tf

    # ----------------------------------------------------------------------------------------- constructors
    @classmethod
    def parse(cls, text: str, *, proper: bool = True) -> TransferFunction:
        """Read a rational transfer function from text (grammar in the module docstring); no delays.

        Examples
        --------
        >>> TransferFunction.parse("1/(s^2 + 2*0.7*3*s + 9)")
        TransferFunction(1/(s^2 + 4.2 s + 9))
        >>> TransferFunction.parse("4*s+2", proper=False)
        TransferFunction(4 s + 2)
        """
        v, what = _read(text)
        if v.has_exp:
            raise InvalidValueError(
                f"the transfer function {_quoted(text)} contains a delay factor exp(-T*s); read it with "
                "TransferFunction.parse_with_delay, or give the delay through the loop's delay option")
        return cls._make(v.num, v.den, what, proper)._written(v)

    @classmethod
    def parse_with_delay(cls, text: str, *, proper: bool = True) -> tuple[TransferFunction, float]:
        """Read ``rational * exp(-T1*s) * exp(-T2*s) ...``; return the rational part and ``T1 + T2 + ...``.

        Examples
        --------
        >>> TransferFunction.parse_with_delay("exp(-0.25*s)*2/(s+1)*exp(-s/4)")
        (TransferFunction(2/(s + 1)), 0.5)
        """
        v, what = _read(text)
        return cls._make(v.num, v.den, what, proper)._written(v), v.delay

    @classmethod
    def from_state_space(cls, A: Any, B: Any, C: Any, D: Any = 0.0) -> TransferFunction:
        """``C (sI - A)^-1 B + D`` of a single-input single-output realisation.

        ``A`` is ``(n, n)``, ``B`` is ``(n,)`` or ``(n, 1)``, ``C`` is ``(n,)`` or ``(1, n)`` and ``D`` a
        scalar.  The denominator is ``det(sI - A)`` (from the eigenvalues, :func:`numpy.poly`); the numerator
        comes from the Markov parameters ``C A^k B``, so structural zeros stay exact.

        Examples
        --------
        >>> TransferFunction.from_state_space([[0, 1], [0, 0]], [0, 1], [1, 0], 0)
        TransferFunction(1/s^2)
        """
        A, B, C, D = (_real_array(k, x) for k, x in zip("ABCD", (A, B, C, D)))
        if A.ndim != 2 or A.shape[0] != A.shape[1]:
            raise InvalidValueError(f"A must be a square matrix, got shape {A.shape}")
        n = A.shape[0]
        if n > MAX_ORDER:
            raise InvalidValueError(f"the state-space system has {n} states, more than MAX_ORDER = {MAX_ORDER}")
        if B.shape not in ((n,), (n, 1)):
            raise InvalidValueError(f"B must have shape ({n},) or ({n}, 1) (one input), got {B.shape}")
        if C.shape not in ((n,), (1, n)):
            raise InvalidValueError(f"C must have shape ({n},) or (1, {n}) (one output), got {C.shape}")
        if D.size != 1 or D.ndim > 2:
            raise InvalidValueError(f"D must be a scalar (one input, one output), got shape {D.shape}")
        b, c, d = B.reshape(n), C.reshape(n), float(D.reshape(()))
        if n == 0:
            return cls([d], [1.0])
        with np.errstate(all="ignore"):  # overflow ends as a "badly scaled" error
            den = np.real(np.poly(A))
            h, x = np.empty(n), b
            for k in range(n):  # Markov parameters h_k = C A^k B
                h[k], x = c @ x, A @ x
            strict = np.array([np.dot(den[:j + 1], h[j::-1]) for j in range(n)])
        return cls._make(np.concatenate(([0.0], strict)) + d * den, den, "the state-space system")

    @classmethod
    def coerce(cls, obj: Any, name: str = "plant", *, proper: bool = True) -> TransferFunction:
        """Make a transfer function of ``obj``, or raise an error naming ``name``.

        Accepted: a :class:`TransferFunction` (returned as is), text (:meth:`parse`), a real number (a
        static gain), a pair ``(num, den)``, a 4-tuple ``(A, B, C, D)``, and python-control
        ``TransferFunction`` / ``StateSpace`` systems that are continuous-time and SISO.

        Examples
        --------
        >>> TransferFunction.coerce(([1], [1, 1])) == TransferFunction.coerce("1/(s+1)")
        True
        >>> TransferFunction.coerce(2.5)
        TransferFunction(2.5)
        """
        if isinstance(obj, TransferFunction):
            if proper and obj.relative_degree < 0:
                _normalise(obj.num, obj.den, f"{name} {obj!r}")  # raises the improper message
            return obj
        try:
            if isinstance(obj, str):
                return cls.parse(obj, proper=proper)
            gain = _scalar(obj)
            if gain is not None:
                return cls([gain], [1.0])
            if (type(obj).__module__ or "").split(".")[0] == "control":
                return cls._from_control(obj, name, proper)
            if isinstance(obj, (tuple, list)) and len(obj) in (2, 4):
                return cls(*obj, proper=proper) if len(obj) == 2 else cls.from_state_space(*obj)
        except (InvalidValueError, InvalidTypeError) as exc:
            raise type(exc)(f"{name}: {exc}") from exc
        raise InvalidTypeError(
            f"{name} must be a TransferFunction, text such as '1/(s+1)', a number, a pair (num, den), a tuple "
            f"(A, B, C, D) or a python-control system, got {reprlib.repr(obj)} ({type(obj).__name__})")

    @classmethod
    def _from_control(cls, obj: Any, name: str, proper: bool) -> TransferFunction:
        import control

        kind = check_control_system(obj)
        if (obj.ninputs, obj.noutputs) != (1, 1):
            raise InvalidValueError(f"the python-control {kind} has {obj.ninputs} inputs and {obj.noutputs} "
                                    "outputs; only single-input single-output systems are supported")
        if isinstance(obj, control.StateSpace):
            return cls.from_state_space(obj.A, obj.B, obj.C, obj.D)
        num, den = getattr(obj, "num_array", obj.num), getattr(obj, "den_array", obj.den)
        return cls(num[0][0], den[0][0], proper=proper)

    # --------------------------------------------------------------------------------------------- queries
    @property
    def order(self) -> int:
        """Degree of the denominator (the number of poles, common factors included).

        Examples
        --------
        >>> TransferFunction.parse("1/(s*(0.05*s+1))").order
        2
        """
        return self.den.size - 1

    @property
    def relative_degree(self) -> int:
        """``order`` minus the numerator degree (the zero numerator counts as degree 0); < 0 if improper.

        Examples
        --------
        >>> TransferFunction.parse("(s+2)/(s^3+1)").relative_degree
        2
        """
        return self.order - (self.num.size - 1)

    @property
    def is_strictly_proper(self) -> bool:
        """True when ``G(s) -> 0`` as ``s -> infinity``.

        Examples
        --------
        >>> TransferFunction.parse("s/(0.02*s+1)").is_strictly_proper
        False
        """
        return self.relative_degree > 0 or not self.num.any()

    @property
    def integrators(self) -> int:
        """Poles at exactly 0: trailing zeros of the denominator as written (see :meth:`minimal`).

        Examples
        --------
        >>> TransferFunction.parse("1/(s^2*(s+1))").integrators
        2
        """
        return int(self.den.size - 1 - np.flatnonzero(self.den)[-1])

    def poles(self) -> np.ndarray:
        """Roots of the denominator, as a sorted complex array.

        Examples
        --------
        >>> TransferFunction.parse("1/((s+1)*(0.5*s+1))").poles().real.round(9).tolist()
        [-2.0, -1.0]
        """
        return np.sort(np.roots(self.den).astype(complex))

    def zeros(self) -> np.ndarray:
        """Roots of the numerator, as a sorted complex array (empty for a constant or zero numerator).

        Examples
        --------
        >>> TransferFunction.parse("(s+2)/(s^2+3*s+2)").zeros().tolist()
        [(-2+0j)]
        """
        return np.sort(np.roots(self.num).astype(complex))

    def dc_gain(self) -> float:
        """``lim G(s)`` as ``s -> 0+``: ``inf`` (signed) with more integrators than zeros at the origin.

        Examples
        --------
        >>> TransferFunction.parse("3/(2*s+1)").dc_gain()
        3.0
        >>> TransferFunction.parse("-2/(s*(s+1))").dc_gain()
        -inf
        """
        if not self.num.any():
            return 0.0
        kz, kp = int(self.num.size - 1 - np.flatnonzero(self.num)[-1]), self.integrators
        ratio = float(self.num[self.num.size - 1 - kz]) / float(self.den[self.den.size - 1 - kp])
        return math.copysign(math.inf, ratio) if kp > kz else 0.0 if kp < kz else ratio

    def __call__(self, s: Any) -> complex | np.ndarray:
        """``G(s)`` at complex points (a complex for a scalar, else an array); not finite at a pole.

        Examples
        --------
        >>> g = TransferFunction.parse("1/(s+1)")
        >>> g(1j)
        (0.5-0.5j)
        >>> g([0, 1]).real.tolist()
        [1.0, 0.5]
        """
        try:
            if isinstance(s, (str, bytes)):
                raise TypeError("text")
            x = np.asarray(s, dtype=complex)
        except (TypeError, ValueError) as exc:
            raise InvalidTypeError(f"a transfer function is evaluated at numbers, got {reprlib.repr(s)}") from exc
        with np.errstate(all="ignore"):
            out = np.asarray(np.polyval(self.num, x) / np.polyval(self.den, x))
        return complex(out) if out.ndim == 0 else out

    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """A realisation ``(A, B, C, D)`` in controllable canonical form (as :func:`scipy.signal.tf2ss`).

        ``A`` has ``-den[1:]`` in its first row and ones on its subdiagonal, ``B = e_1``,
        ``C = num[1:] - D den[1:]`` (numerator padded to ``order + 1``) and ``D = num[0]`` (0 when strictly
        proper); shapes ``(n, n)``, ``(n,)``, ``(n,)`` and a float.  Improper functions have none.

        Examples
        --------
        >>> A, B, C, D = TransferFunction.parse("(s+3)/(s^2+3*s+2)").state_space()
        >>> A.tolist(), B.tolist(), C.tolist(), D
        ([[-3.0, -2.0], [1.0, 0.0]], [1.0, 0.0], [1.0, 3.0], 0.0)
        """
        n = self.order
        if self.relative_degree < 0:
            raise InvalidValueError(f"{self!r} is improper and has no state-space realisation")
        b = np.concatenate([np.zeros(n + 1 - self.num.size), self.num])  # padded with leading zeros
        A = np.zeros((n, n))
        if n:
            A[0] = -self.den[1:]
            A[1:, :-1] = np.eye(n - 1)
        return A, np.eye(n)[0] if n else np.zeros(0), b[1:] - b[0] * self.den[1:], float(b[0])

    def minimal(self, tol: float = 1e-6) -> TransferFunction:
        """Cancel zeros and poles closer than ``tol * max(1, |zero|)``; ``self`` if none cancel.

        Repeated roots are computed less accurately and may need a larger ``tol``.

        Examples
        --------
        >>> TransferFunction.parse("(s+2)/(s^2+3*s+2)").minimal()
        TransferFunction(1/(s + 1))
        """
        tol = check_real("tol", tol, minimum=0.0)
        if not self.num.any():
            return TransferFunction([0.0], [1.0])
        poles, kept = list(self.poles()), []
        for z in self.zeros():
            j = min(range(len(poles)), key=lambda i: abs(poles[i] - z), default=None)
            if j is not None and abs(poles[j] - z) <= tol * max(1.0, abs(z)):
                poles.pop(j)
            else:
                kept.append(z)
        if len(poles) == self.order:
            return self
        num = self.num[0] * np.real(np.atleast_1d(np.poly(kept)))
        return TransferFunction(num, np.real(np.atleast_1d(np.poly(poles))), proper=False)

    # ------------------------------------------------------------------------------------------- arithmetic
    def _operand(self, x: Any) -> tuple[TransferFunction | None, bool]:
        """``x`` as a TransferFunction (None if it is not one or a real number), and whether both are proper."""
        g = _scalar(x)
        o = x if isinstance(x, TransferFunction) else None if g is None else TransferFunction([g], [1.0])
        return o, o is not None and self.relative_degree >= 0 and o.relative_degree >= 0

    def __mul__(self, other: Any) -> TransferFunction:
        o, proper = self._operand(other)
        if o is None:
            return NotImplemented
        return TransferFunction(_pmul(self.num, o.num), _pmul(self.den, o.den), proper=proper)

    __rmul__ = __mul__

    def __add__(self, other: Any) -> TransferFunction:
        o, proper = self._operand(other)
        if o is None:
            return NotImplemented
        if np.array_equal(self.den, o.den):
            return TransferFunction(_padd(self.num, o.num), self.den, proper=proper)
        num = _padd(_pmul(self.num, o.den), _pmul(o.num, self.den))
        return TransferFunction(num, _pmul(self.den, o.den), proper=proper)

    __radd__ = __add__

    def __neg__(self) -> TransferFunction:
        return TransferFunction._make(-self.num, self.den, "-G", proper=False)

    def __sub__(self, other: Any) -> TransferFunction:
        o, _ = self._operand(other)
        return NotImplemented if o is None else self + (-o)

    def __rsub__(self, other: Any) -> TransferFunction:
        o, _ = self._operand(other)
        return NotImplemented if o is None else o + (-self)

    def feedback(self, other: Any = 1, sign: int = -1) -> TransferFunction:
        """The closed loop ``G / (1 - sign G H)`` with ``H = other`` (anything :meth:`coerce` takes).

        Examples
        --------
        >>> TransferFunction.parse("1/s").feedback()
        TransferFunction(1/(s + 1))
        """
        h = TransferFunction.coerce(other, name="feedback path", proper=False)
        if isinstance(sign, bool) or not isinstance(sign, numbers.Real) or sign not in (1, -1):
            raise InvalidValueError(f"sign must be -1 (negative feedback) or +1, got {sign!r:.60}")
        den = _padd(_pmul(self.den, h.den), -sign * _pmul(self.num, h.num))
        if not den.any():
            raise InvalidValueError(f"the closed loop of {self.to_string()} with {h.to_string()} is undefined: "
                                    "1 - sign*G*H is identically zero")
        proper = self.relative_degree >= 0 and h.relative_degree >= 0
        return TransferFunction._make(_pmul(self.num, h.den), den, "the closed loop", proper)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, TransferFunction):
            return NotImplemented
        return np.array_equal(self.num, other.num) and np.array_equal(self.den, other.den)

    def __hash__(self) -> int:
        return hash((tuple(self.num.tolist()), tuple(self.den.tolist())))

    # ---------------------------------------------------------------------------------------------- output
    def to_string(self, digits: int | None = None, times: str = "*") -> str:
        """``num/den`` as text that :meth:`parse` reads back (with the default ``times``).

        A function read from text is written with the coefficients the text gave it (``0.6976/(146.6 s + 1)``,
        not its monic ``0.00475853/(s + 0.00682128)``; ``1/(s*(0.05*s+1))`` as ``1/(0.05 s^2 + s)``, not
        ``20/(s^2 + 20 s)``; products expanded); one built from coefficients or by arithmetic, normalised.
        Coefficients use ``%g``, or ``%.{digits}g`` (17 round-trips floats exactly); coefficients 1 are
        omitted; ``times`` joins a coefficient and its power of ``s`` (``" "`` for display, as in ``repr``).

        Examples
        --------
        >>> TransferFunction.parse("s/(0.02*s+1)").to_string(), TransferFunction([1, 0], [0.02, 1]).to_string()
        ('s/(0.02*s + 1)', '50*s/(s + 50)')
        """
        fmt = "%g" if digits is None else f"%.{int(check_real('digits', digits, minimum=1, maximum=17))}g"
        a, b = getattr(self, "_as_written", None) or (self.num, self.den)
        if b.size == 1:  # a constant denominator (4/2): the constant
            a, b = self.num, self.den
        num, n_terms = _poly_text(a, fmt, times)
        if b.size == 1 and b[0] == 1.0:
            return num
        den, d_terms = _poly_text(b, fmt, times)
        bare = d_terms == 1 and (den == "s" or den.startswith("s^"))  # 2/s^2; but 2.5/(4 s^2), not 2.5/4 s^2
        return f"{f'({num})' if n_terms > 1 else num}/{den if bare else f'({den})'}"

    def __repr__(self) -> str:
        return f"TransferFunction({self.to_string(times=' ')})"

    def to_dict(self) -> dict[str, list[float]]:
        """``{"num": [...], "den": [...]}`` of plain floats, ready for JSON; ``TransferFunction(**d)`` reads it.

        Examples
        --------
        >>> TransferFunction.parse("0.5/(s+2)").to_dict()
        {'num': [0.5], 'den': [1.0, 2.0]}
        """
        return {"num": self.num.tolist(), "den": self.den.tolist()}

    def to_control(self) -> Any:
        """The same system as a python-control ``TransferFunction`` (python-control must be installed).

        Raises
        ------
        MissingDependencyError
            When python-control is not installed (an ``ImportError`` too).

        Examples
        --------
        >>> float(TransferFunction.parse("2/(s+1)").to_control().dcgain())
        2.0
        """
        try:
            import control
        except ImportError as exc:
            raise MissingDependencyError("to_control() needs python-control, which is not installed "
                                         "(pip install control)") from exc
        return control.tf(self.num.copy(), self.den.copy())
