"""The Laplace variable ``s`` and exact algebra on it: ``s = tf("s")``, then ``2*exp(-0.5*s)/(s + 1)``.

python-control's users build transfer functions from ``s = tf("s")``; its delay work spells a dead time
``exp(-T*s)``.  Here ``s`` is a :class:`LaplaceExpression`, a quotient of two *quasi-polynomials*
``N(s)/D(s)`` with ``N(s) = sum_k n_k(s) exp(-t_k s)`` (polynomials ``n_k``, delays ``t_k >= 0``), on which
``+ - * /``, integer powers and ``exp(-T*s)`` are exact.  An expression that a causal system realises (proper,
no prediction) becomes a :class:`~delaykit.systems.lti.DelayLTI` at once, so ``1/(s + 1)`` is a system like any
other; one that is not (``s``, ``kp + kd*s``) stays an expression, kept for further algebra, until it is
combined into a proper one (``(kp + kd*s) * G``).  A system made this way remembers its expression, so that it
can still be combined exactly with an improper one; a system made otherwise (by ``feedback``, from text) cannot
be multiplied by an improper expression: make the controller proper (a derivative filter) or write the plant
with ``s`` too.

The realisation of ``N/D``: with ``d_0`` the undelayed polynomial of ``D`` (which must have ``D``'s highest degree,
else ``D`` asks for a prediction), ``N/D = [sum_k (n_k/d_0) exp(-t_k s)] / [1 + sum_{t_k > 0} (d_k/d_0) exp(-t_k
s)]``: proper rational blocks, delays, and one feedback loop (internal delays; neutral where a delayed term of
``D`` has ``d_0``'s degree).  Common powers of ``s`` and a common delay are cancelled; other common factors are
kept, as python-control keeps them (``feedback`` gives the minimal closed loop).

Examples
--------
>>> from delaykit import tf
>>> s = tf("s")
>>> s
LaplaceExpression(s)
>>> G = 2 * exp(-0.5 * s) / (s + 1)
>>> G
DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 1 state, delays [0.5] s)
>>> C = 1.5 + 0.2 * s          # a PD law: improper, still an expression
>>> C
LaplaceExpression(0.2*s + 1.5)
>>> L = C * G / (0.05 * s + 1)  # proper again: a system
>>> float(abs(L.evaluate([0.0])[0, 0, 0]))       # the DC gain 1.5 * 2
3.0
"""

from __future__ import annotations

import ast
import math
import numbers
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real, plain

__all__ = ["LaplaceExpression", "exp", "laplace_variable", "parse_expression", "MAX_DEGREE"]

MAX_DEGREE = 40
"""The highest degree of ``s`` an expression may reach (algebra multiplies degrees: refused past this)."""

_MAX_TERMS = 64  # distinct delays in one quasi-polynomial

_Quasi = tuple[tuple[float, np.ndarray], ...]  # ((delay, polynomial coefficients, highest power first), ...)


def _poly(p: np.ndarray) -> np.ndarray:
    """``p`` without leading zeros (the zero polynomial is ``[0.0]``)."""
    nz = np.flatnonzero(p)
    return p[nz[0]:] if nz.size else np.zeros(1)


def _normal(terms: dict[float, np.ndarray]) -> _Quasi:
    """The terms as a sorted tuple, zero polynomials left out, delays closer than rounding merged."""
    out: list[tuple[float, np.ndarray]] = []
    for t in sorted(terms):
        p = _poly(terms[t])
        if out and abs(t - out[-1][0]) <= 1e-12 * max(1.0, t):
            out[-1] = (out[-1][0], _poly(np.polyadd(out[-1][1], p)))
        elif p.any():
            out.append((t, p))
    out = [(t, p) for t, p in out if p.any()]
    if len(out) > _MAX_TERMS:
        raise InvalidValueError(f"an expression of s with {len(out)} distinct delays, more than {_MAX_TERMS}")
    for _, p in out:
        if p.size - 1 > MAX_DEGREE:
            raise InvalidValueError(f"an expression of s of degree {p.size - 1}, more than MAX_DEGREE = "
                                    f"{MAX_DEGREE}")
        if not np.isfinite(p).all():
            raise InvalidValueError("an expression of s whose coefficients overflowed (not finite)")
    return tuple(out)


def _add(a: _Quasi, b: _Quasi) -> _Quasi:
    d: dict[float, np.ndarray] = {}
    for t, p in (*a, *b):
        d[t] = np.polyadd(d[t], p) if t in d else p
    return _normal(d)


def _mul(a: _Quasi, b: _Quasi) -> _Quasi:
    d: dict[float, np.ndarray] = {}
    for ta, pa in a:
        for tb, pb in b:
            t, p = ta + tb, np.polymul(pa, pb)
            d[t] = np.polyadd(d[t], p) if t in d else p
    return _normal(d)


def _degree(q: _Quasi) -> int:
    return max((p.size - 1 for _, p in q), default=-1)


def _fmt(c: float) -> str:
    return format(c, ".15g")


def _poly_text(p: np.ndarray) -> str:
    n = p.size - 1
    parts = []
    for k, c in enumerate(p):
        if c == 0.0:
            continue
        power = n - k
        mag = abs(c)
        coef = "" if mag == 1.0 and power else _fmt(mag) + ("*" if power else "")
        var = "" if power == 0 else "s" if power == 1 else f"s^{power}"
        parts.append(("-" if c < 0 else "+", coef + var))
    if not parts:
        return "0"
    text = ("-" if parts[0][0] == "-" else "") + parts[0][1]
    return text + "".join(f" {sign} {body}" for sign, body in parts[1:])


def _quasi_text(q: _Quasi) -> str:
    if not q:
        return "0"
    terms = []
    for t, p in q:
        body = _poly_text(p)
        if t == 0.0:
            terms.append(body)
        else:
            factor = "exp(-s)" if t == 1.0 else f"exp(-{_fmt(t)}*s)"
            terms.append(factor if body == "1" else f"({body})*{factor}" if len(p) > 1 or body.startswith("-")
                         else f"{body}*{factor}")
    return " + ".join(terms)


class LaplaceExpression:
    """An exact quotient of quasi-polynomials of ``s`` that no causal system realises yet (see the module).

    Made by ``tf("s")`` (or :func:`laplace_variable`) and the algebra on it; an operation whose result is proper
    returns a :class:`~delaykit.systems.lti.DelayLTI` instead.  ``str()`` is text that :func:`delaykit.tf` reads.

    Examples
    --------
    >>> s = laplace_variable()
    >>> s * s + 2 * s
    LaplaceExpression(s^2 + 2*s)
    >>> (s + 1).is_proper()
    False
    """

    _is_laplace = True  # recognised by DelayLTI's operators without importing this module
    __slots__ = ("num", "den")

    def __init__(self, num: _Quasi, den: _Quasi) -> None:
        if not den:
            raise InvalidValueError("division by zero in an expression of s")
        # cancel a common delay (the least delay of the denominator) and a common power of s
        t0 = den[0][0]
        if t0:
            num = tuple((t - t0, p) for t, p in num)
            den = tuple((t - t0, p) for t, p in den)
        zeros = min(_trailing_zeros(p) for _, p in (*num, *den)) if num else 0
        if zeros:
            num = tuple((t, p[:-zeros]) for t, p in num)
            den = tuple((t, p[:-zeros]) for t, p in den)
        scale = den[0][1][0]  # the undelayed denominator's leading coefficient becomes 1
        if scale != 1.0:
            num = tuple((t, p / scale) for t, p in num)
            den = tuple((t, p / scale) for t, p in den)
        object.__setattr__(self, "num", num)
        object.__setattr__(self, "den", den)

    def __setattr__(self, key: str, value: Any) -> None:
        raise AttributeError("a LaplaceExpression is immutable")

    # -- what it is ------------------------------------------------------------------------------------------
    def is_proper(self) -> bool:
        """Whether a causal system realises it: no delay ahead (``exp(+T s)``), the undelayed part of the
        denominator of the highest degree, and the numerator of no higher degree."""
        if not self.num:
            return True
        if self.num[0][0] < 0:
            return False
        n0 = self.den[0][1].size - 1
        return _degree(self.den) <= n0 and _degree(self.num) <= n0

    def to_system(self) -> Any:
        """The :class:`~delaykit.systems.lti.DelayLTI` that realises it (see the module for how).

        Raises
        ------
        InvalidValueError
            Where it is improper: more zeros than poles, or a prediction ``exp(+T*s)``.
        """
        if not self.is_proper():
            raise InvalidValueError(f"{self} is improper (more zeros than poles, or a prediction exp(+T*s)): no "
                                    "causal system realises it; combine it with a proper factor first, e.g. a "
                                    "derivative filter 1/(T*s + 1)")
        from ..models.transfer import TransferFunction
        from .algebra import feedback, gain
        from .build import _rational

        d0 = self.den[0][1]
        if not self.num:
            sys = gain(0.0)
        else:
            sys = None
            for t, p in self.num:
                term = _rational(TransferFunction(p, d0), t)
                sys = term if sys is None else sys + term
        if len(self.den) > 1:
            rest = None
            for t, p in self.den[1:]:
                term = _rational(TransferFunction(p, d0), t)
                rest = term if rest is None else rest + term
            sys = sys * feedback(gain(1.0), rest)
        object.__setattr__(sys, "_expr", self)
        return sys

    # -- algebra -------------------------------------------------------------------------------------------
    @staticmethod
    def _lift(x: Any) -> LaplaceExpression | None:
        if isinstance(x, LaplaceExpression):
            return x
        if isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_)):
            c = check_real("a number in an expression of s", x)
            return LaplaceExpression(_normal({0.0: np.array([c])}), ((0.0, np.ones(1)),))
        if getattr(x, "ninputs", None) is None:
            return None
        expr = x.__dict__.get("_expr")
        return expr if expr is not None else _of_system(x)

    def _result(self) -> Any:
        return self.to_system() if self.is_proper() else self

    def _combine(self, other: Any, op: str, reflected: bool = False) -> Any:
        o = self._lift(other)
        if o is None:
            if getattr(other, "ninputs", None) is not None:  # a system without an expression
                if self.is_proper():
                    sys = self.to_system()
                    return getattr(sys, f"__{'r' if reflected else ''}{op}__")(other)
                word = {"add": "sum", "sub": "difference", "mul": "product", "truediv": "quotient"}[op]
                raise InvalidValueError(
                    f"{self} is improper, and {plain(other)!r} is not a rational function times one delay: their "
                    f"{word} cannot be realised piece by piece; write the system with s too (G = 2*exp(-s)/(s + 1)), "
                    "or make the expression proper (a derivative filter 1/(T*s + 1))")
            return NotImplemented
        a, b = (o, self) if reflected else (self, o)
        if op == "add":
            r = LaplaceExpression(_add(_mul(a.num, b.den), _mul(b.num, a.den)), _mul(a.den, b.den))
        elif op == "sub":
            neg = tuple((t, -p) for t, p in b.num)
            r = LaplaceExpression(_add(_mul(a.num, b.den), _mul(neg, a.den)), _mul(a.den, b.den))
        elif op == "mul":
            r = LaplaceExpression(_mul(a.num, b.num), _mul(a.den, b.den))
        else:  # truediv
            r = LaplaceExpression(_mul(a.num, b.den), _mul(a.den, b.num))
        return r._result()

    def __add__(self, other: Any) -> Any:
        return self._combine(other, "add")

    def __radd__(self, other: Any) -> Any:
        return self._combine(other, "add", True)

    def __sub__(self, other: Any) -> Any:
        return self._combine(other, "sub")

    def __rsub__(self, other: Any) -> Any:
        return self._combine(other, "sub", True)

    def __mul__(self, other: Any) -> Any:
        return self._combine(other, "mul")

    def __rmul__(self, other: Any) -> Any:
        return self._combine(other, "mul", True)

    def __truediv__(self, other: Any) -> Any:
        return self._combine(other, "truediv")

    def __rtruediv__(self, other: Any) -> Any:
        return self._combine(other, "truediv", True)

    def __neg__(self) -> Any:
        return LaplaceExpression(tuple((t, -p) for t, p in self.num), self.den)._result()

    def __pos__(self) -> Any:
        return self

    def __pow__(self, n: Any) -> Any:
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or abs(n) > MAX_DEGREE:
            raise InvalidValueError(f"a power of an expression of s must be an integer from {-MAX_DEGREE} to "
                                    f"{MAX_DEGREE}, got {plain(n)!r}")
        r = LaplaceExpression(((0.0, np.ones(1)),), ((0.0, np.ones(1)),))
        base = self if n >= 0 else LaplaceExpression(self.den, self.num) if self.num else None
        if base is None:
            raise InvalidValueError("division by zero in an expression of s")
        for _ in range(abs(int(n))):
            r = LaplaceExpression(_mul(r.num, base.num), _mul(r.den, base.den))
        return r._result()

    def exp(self) -> Any:
        """``exp(-T*s)`` of the expression ``-T*s`` (``T >= 0``): a delay of ``T`` (``np.exp`` calls it)."""
        tau = self._delay_argument()
        return LaplaceExpression(((tau, np.ones(1)),), ((0.0, np.ones(1)),))._result()

    def _delay_argument(self) -> float:
        """``T`` where the expression is ``-T*s``, else an error."""
        ok = (len(self.den) == 1 and self.den[0][1].size == 1 and len(self.num) == 1 and self.num[0][0] == 0.0
              and self.num[0][1].size == 2 and self.num[0][1][1] == 0.0)
        if not ok:
            raise InvalidValueError(f"exp() of an expression of s must be exp(-T*s) with T >= 0 (a delay), got "
                                    f"exp({self})")
        tau = -float(self.num[0][1][0]) / float(self.den[0][1][0])
        if tau < 0:
            raise InvalidValueError(f"exp(-T*s) needs T >= 0 (a delay; exp(+T*s) would predict), got T = {tau:g}")
        return tau

    def __array_ufunc__(self, ufunc: Any, method: str, *inputs: Any, **kwargs: Any) -> Any:
        """``np.exp(-T*s)`` is a delay; numpy's arithmetic (``np.float64(2) * s``) is the expression's."""
        if method != "__call__" or kwargs:
            return NotImplemented
        if ufunc is np.exp and len(inputs) == 1:
            return self.exp()
        if ufunc is np.negative and len(inputs) == 1:
            return -self
        ops = {np.add: "add", np.subtract: "sub", np.multiply: "mul", np.true_divide: "truediv"}
        if ufunc in ops and len(inputs) == 2:
            if inputs[0] is self:
                return self._combine(inputs[1], ops[ufunc])
            return self._combine(inputs[0], ops[ufunc], True)
        if ufunc is np.power and len(inputs) == 2 and inputs[0] is self:
            return self ** inputs[1]
        return NotImplemented

    # -- output --------------------------------------------------------------------------------------------
    def __str__(self) -> str:
        num = _quasi_text(self.num)
        if len(self.den) == 1 and self.den[0][1].size == 1 and self.den[0][1][0] == 1.0:
            return num
        den = _quasi_text(self.den)
        wrap = (lambda x: f"({x})" if any(c in x for c in " */") else x)  # noqa: E731
        return f"{wrap(num)}/{wrap(den)}"

    def __repr__(self) -> str:
        return f"LaplaceExpression({self})"

    def to_dict(self) -> dict[str, Any]:
        """The numerator and denominator as lists of ``{"delay", "coefficients"}`` (highest power first)."""
        return {part: [{"delay": t, "coefficients": p.tolist()} for t, p in q]
                for part, q in (("num", self.num), ("den", self.den))}

    def __eq__(self, other: Any) -> bool:
        if not isinstance(other, LaplaceExpression):
            return NotImplemented
        same = lambda a, b: len(a) == len(b) and all(  # noqa: E731
            ta == tb and pa.shape == pb.shape and (pa == pb).all() for (ta, pa), (tb, pb) in zip(a, b))
        return same(self.num, other.num) and same(self.den, other.den)

    __hash__ = None  # type: ignore[assignment]


def _of_system(sys: Any) -> LaplaceExpression | None:
    """A SISO system that is a rational function times one dead time (:func:`~delaykit.systems.build.plant_of`)
    as an expression of ``s``; None for any other system."""
    from .build import plant_of

    try:
        g, T = plant_of(sys)
    except (InvalidValueError, InvalidTypeError):
        return None
    return LaplaceExpression(_normal({T: np.asarray(g.num, float)}), _normal({0.0: np.asarray(g.den, float)}))


def _trailing_zeros(p: np.ndarray) -> int:
    nz = np.flatnonzero(p)
    return int(p.size - 1 - nz[-1]) if nz.size else 0


def laplace_variable() -> LaplaceExpression:
    """The Laplace variable ``s`` (what ``tf("s")`` returns).

    Examples
    --------
    >>> s = laplace_variable()
    >>> 1 / (s + 2)
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 1 state, no delays)
    """
    return LaplaceExpression(((0.0, np.array([1.0, 0.0])),), ((0.0, np.ones(1)),))


def exp(x: Any) -> Any:
    """A dead time ``exp(-T*s)`` from the expression ``-T*s`` (python-control's delay spelling).

    ``numpy.exp(-T*s)`` gives the same; on a number, the number's exponential.

    Examples
    --------
    >>> s = laplace_variable()
    >>> exp(-0.3 * s)
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 0 states, delays [0.3] s)
    """
    if isinstance(x, numbers.Real) and not isinstance(x, bool):
        return math.exp(x)
    e = LaplaceExpression._lift(x)
    if e is None:
        raise InvalidTypeError(f"exp() takes -T*s, an expression of the Laplace variable s = tf('s'), got "
                               f"{plain(x)!r} ({type(x).__name__})")
    return e.exp()


_MAX_TEXT = 10_000


def parse_expression(text: str) -> Any:
    """Read text such as ``"(s + 1)/(s + 0.5*exp(-s))"`` by the algebra of ``s``: a system where it is proper,
    else a :class:`LaplaceExpression`.  Only numbers, ``s``, ``+ - * / ** ^``, parentheses and ``exp(...)``.

    Examples
    --------
    >>> parse_expression("(s + 1)/(s + 0.5*exp(-s))")
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 2 states, delays [1] s)
    >>> parse_expression("s^2")
    LaplaceExpression(s^2)
    """
    if not isinstance(text, str):
        raise InvalidTypeError(f"expected text, got {type(text).__name__}")
    if len(text) > _MAX_TEXT:
        raise InvalidValueError(f"an expression of s of {len(text)} characters, more than {_MAX_TEXT}")
    try:
        node = ast.parse(text.replace("^", "**").strip(), mode="eval").body
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        raise InvalidValueError(f"{text!r} is not an expression of s") from None
    s = laplace_variable()

    def ev(n: ast.AST) -> Any:
        if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)) and not isinstance(n.value, bool):
            return check_real("a number", n.value) if isinstance(n.value, float) else _int(n.value)
        if isinstance(n, ast.Name) and n.id == "s":
            return s
        if isinstance(n, ast.UnaryOp) and isinstance(n.op, (ast.USub, ast.UAdd)):
            v = ev(n.operand)
            return -v if isinstance(n.op, ast.USub) else v
        if isinstance(n, ast.BinOp) and isinstance(n.op, (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow)):
            a, b = ev(n.left), ev(n.right)
            if isinstance(n.op, ast.Pow):
                if isinstance(b, float) and b.is_integer():
                    b = int(b)
                if isinstance(a, numbers.Real):
                    return check_real("a power", float(a) ** b) if isinstance(b, (int, float)) else _bad(n)
                return a ** b
            if isinstance(n.op, ast.Div) and isinstance(b, numbers.Real) and b == 0:
                raise InvalidValueError(f"division by zero in {text!r}")
            return {ast.Add: lambda: a + b, ast.Sub: lambda: a - b, ast.Mult: lambda: a * b,
                    ast.Div: lambda: a / b}[type(n.op)]()
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "exp" and len(n.args) == 1 \
                and not n.keywords:
            return exp(ev(n.args[0]))
        return _bad(n)

    def _bad(n: ast.AST) -> Any:
        raise InvalidValueError(f"{text!r}: {ast.unparse(n)!r} is not part of an expression of s (numbers, s, "
                                "+ - * / ^, parentheses and exp(-T*s))")

    def _int(v: int) -> float:
        return check_real("a number", float(v)) if abs(v) < 10**309 else check_real("a number", math.inf)

    try:
        return ev(node)
    except RecursionError:
        raise InvalidValueError(f"{text[:60]!r}...: nested too deeply") from None
