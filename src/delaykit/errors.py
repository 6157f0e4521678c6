"""The exceptions delaykit raises for bad input.

Every check in the library raises one of these, with a message that names the bad value and what was
expected; the command line prints the message (no traceback) and exits with status 2.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["DelaykitError", "InvalidValueError", "InvalidTypeError", "check_real"]


class DelaykitError(Exception):
    """Base class of delaykit's own errors."""


class InvalidValueError(DelaykitError, ValueError):
    """A value is out of range, not finite, or not one of the allowed choices."""


class InvalidTypeError(DelaykitError, TypeError):
    """A value has the wrong type (for example text where a number was expected)."""


def check_real(
    name: str,
    value: Any,
    *,
    minimum: float | None = None,
    maximum: float | None = None,
    strict: bool = False,
    allow_inf: bool = False,
    allow_neg_inf: bool = False,
) -> float:
    """Return ``value`` as a float, or raise a delaykit error that names it.

    Parameters
    ----------
    name : str
        The name shown in the message (for example ``"delay"``).
    value : Any
        The value to check.
    minimum, maximum : float, optional
        Bounds, inclusive unless ``strict``.
    strict : bool
        Make the lower bound exclusive (``value > minimum``).
    allow_inf : bool
        Accept ``+inf``.
    allow_neg_inf : bool
        Accept ``-inf``.

    Returns
    -------
    float

    Examples
    --------
    >>> check_real("delay", 0.37, minimum=0.0)
    0.37
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) and not hasattr(value, "__float__"):
        raise InvalidTypeError(f"{name} must be a real number, got {value!r} ({type(value).__name__})")
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be a real number, got {value!r}") from exc
    if math.isnan(x) or (math.isinf(x) and not ((allow_inf and x > 0) or (allow_neg_inf and x < 0))):
        raise InvalidValueError(f"{name} must be finite, got {value!r}")
    if minimum is not None:
        if strict and not x > minimum:
            raise InvalidValueError(f"{name} must be greater than {minimum:g}, got {x:g}")
        if not strict and not x >= minimum:
            raise InvalidValueError(f"{name} must be at least {minimum:g}, got {x:g}")
    if maximum is not None and not x <= maximum:
        raise InvalidValueError(f"{name} must be at most {maximum:g}, got {x:g}")
    return x
