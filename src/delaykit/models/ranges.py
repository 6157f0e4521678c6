"""Values to sweep, from text: ``START:STOP:N``, a comma list, or a number (the command line's ranges).

Examples
--------
>>> parse_range("1:3:3", "kp")
[1.0, 2.0, 3.0]
"""

from __future__ import annotations

from typing import Sequence

from ..errors import InvalidValueError, RangeSpecError, check_real

__all__ = ["parse_range"]


def parse_range(spec: str | Sequence[float], name: str = "range") -> list[float]:
    """Values from ``START:STOP:N`` (N values, ends included), a comma list, a number, or a sequence.

    Text that is none of these raises :class:`~delaykit.errors.RangeSpecError`; a well-formed range with bad
    values (``N < 1``, a reversed range, a value that is not finite) a plain
    :class:`~delaykit.errors.InvalidValueError`.

    Examples
    --------
    >>> parse_range("0:0.7:8")
    [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]
    """
    if not isinstance(spec, str):
        vals = [check_real(name, v) for v in spec]
    elif ":" in spec:
        try:
            a_s, b_s, n_s = spec.split(":")
            a, b, n = float(a_s), float(b_s), int(n_s)
        except ValueError:
            raise RangeSpecError(f"{name} {spec!r} must be START:STOP:N, a comma list or a number") from None
        if n < 1:
            raise InvalidValueError(f"{name} {spec!r}: N must be at least 1")
        if n > 1 and not b > a:
            raise InvalidValueError(f"{name} {spec!r}: the range is empty or reversed (STOP must exceed START)")
        vals = [a] if n == 1 else [round(a + (b - a) * i / (n - 1), 12) for i in range(n)]
    else:
        try:
            vals = [float(x) for x in spec.split(",")]
        except ValueError:
            raise RangeSpecError(f"{name} {spec!r} must be START:STOP:N, a comma list or a number") from None
    if not vals:
        raise InvalidValueError(f"{name} is empty")
    for v in vals:
        check_real(name, v)
    return vals
