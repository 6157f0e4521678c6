"""Values from text: a number (plain ASCII decimal), and the ranges to sweep of the command line
(``START:STOP:N``, a comma list, or a number).

Python's ``float`` and ``int`` read more than a number as a file or a person writes it: ``1_0`` (ten),
full-width and other Unicode digits (``'１２'`` is twelve).  A value in a CSV file or a range is read by
:func:`parse_number`, which takes ASCII decimal only (digits, a sign, a point and an exponent; ``nan`` and
``inf`` are read, and left to the caller's finiteness check).

A range holds at most :data:`~delaykit.models.budget.MAX_RANGE_POINTS` values.

Examples
--------
>>> parse_range("1:3:3", "kp")
[1.0, 2.0, 3.0]
>>> parse_number("2.5e-3")
0.0025
"""

from __future__ import annotations

from typing import Sequence

from ..errors import InvalidTypeError, InvalidValueError, RangeSpecError, check_real
from .budget import MAX_RANGE_POINTS, check_count, shorten

__all__ = ["parse_range", "parse_number", "parse_integer"]


def parse_number(text: str, name: str = "value") -> float:
    """A number written in ASCII decimal (``-1.5``, ``2e-3``, ``nan``, ``inf``; surrounding spaces allowed).

    Raises :class:`~delaykit.errors.InvalidValueError` (a :class:`ValueError`) naming ``name`` and the text for
    anything else, including what ``float`` would accept but a file does not mean: ``1_0`` and non-ASCII
    digits such as ``'１２'``.

    Examples
    --------
    >>> parse_number(" -0.5 ")
    -0.5
    >>> parse_number("1_0", "z")
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: z is '1_0', not a number (ASCII decimal, e.g. -1.5 or 2e-3)
    """
    # float() reads exactly the ASCII decimal numbers (and nan/inf) once underscores and non-ASCII characters
    # (Unicode digits and spaces) are ruled out
    if isinstance(text, str) and text.isascii() and "_" not in text:
        try:
            return float(text)
        except ValueError:
            pass
    raise InvalidValueError(f"{name} is {str(text)[:40]!r}, not a number (ASCII decimal, e.g. -1.5 or 2e-3)")


def parse_integer(text: str, name: str = "value") -> int:
    """An integer written in ASCII decimal (``-3``, ``+12``; surrounding spaces allowed).

    Examples
    --------
    >>> parse_integer(" 12 ")
    12
    """
    t = text.strip() if isinstance(text, str) else text
    if isinstance(t, str) and t.isascii() and t.lstrip("+-").isdigit() and len(t) - len(t.lstrip("+-")) <= 1:
        return int(t)
    raise InvalidValueError(f"{name} is {str(text)[:40]!r}, not an integer (ASCII decimal, e.g. 12)")


def parse_range(spec: str | Sequence[float], name: str = "range") -> list[float]:
    """Values from ``START:STOP:N`` (N values, ends included), a comma list, a number, or a sequence.

    Text that is none of these raises :class:`~delaykit.errors.RangeSpecError`; a well-formed range with bad
    values (``N < 1``, a reversed range, a value that is not finite) or with more than
    :data:`~delaykit.models.budget.MAX_RANGE_POINTS` values a plain :class:`~delaykit.errors.InvalidValueError`.

    Examples
    --------
    >>> parse_range("0:0.7:8")
    [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]
    """
    hint = "sweep fewer values, or split the sweep into several runs"
    shown = repr(shorten(spec, 80)) if isinstance(spec, str) else ""  # (a refusal quotes a long text shortened)
    if not isinstance(spec, str):
        try:
            if isinstance(spec, (bytes, bytearray)):
                raise TypeError
            spec = list(spec)
        except TypeError:
            raise InvalidTypeError(f"{name} must be text (START:STOP:N, a comma list or a number) or a sequence "
                                   f"of numbers, got {spec!r:.40} ({type(spec).__name__})") from None
        check_count(name, len(spec), MAX_RANGE_POINTS, "values", hint)
        vals = [check_real(name, v) for v in spec]
    elif ":" in spec:
        try:
            a_s, b_s, n_s = spec.split(":")
            a, b, n = parse_number(a_s), parse_number(b_s), parse_integer(n_s)
        except ValueError:
            raise RangeSpecError(f"{name} {shown} must be START:STOP:N, a comma list or a number") from None
        if n < 1:
            raise InvalidValueError(f"{name} {shown}: N must be at least 1")
        check_count(f"{name} {shown}", n, MAX_RANGE_POINTS, "values", hint)
        if n > 1 and not b > a:
            raise InvalidValueError(f"{name} {shown}: the range is empty or reversed (STOP must exceed START)")
        vals = [a] if n == 1 else [round(a + (b - a) * i / (n - 1), 12) for i in range(n)]
    else:
        items = spec.split(",")
        check_count(name, len(items), MAX_RANGE_POINTS, "values", hint)
        try:
            vals = [parse_number(x) for x in items]
        except ValueError:
            raise RangeSpecError(f"{name} {shown} must be START:STOP:N, a comma list or a number") from None
    if not vals:
        raise InvalidValueError(f"{name} is empty")
    for v in vals:
        check_real(name, v)
    return vals
