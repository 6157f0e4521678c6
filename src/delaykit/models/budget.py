"""The work limits: how much one call may ask for, checked before the work starts.

A request beyond a limit is refused at once with an :class:`~delaykit.errors.InvalidValueError` that names the
value, the limit and what to change, instead of running for hours or filling the memory.  The limits are
generous (each is far beyond what the paper or a flight needs) and come from memory and time:

* :data:`MAX_RANGE_POINTS` values in one range (``START:STOP:N``, a comma list, Lambert branches ``K1:K2``): each
  value is a simulation, a root search or a design candidate, some milliseconds to a second each;
* :data:`MAX_GRID_POINTS` candidates in one gain search (the product of its ranges);
* :data:`MAX_ROOT_GRID_POINTS` points of a root search's grid, which is finer the longer the delay;
* :data:`MAX_FREQUENCY_DECADES` decades of a frequency range (a plot);
* :data:`MAX_SAMPLES` samples in one record (a response sampled every ``dt``, a log put on a uniform clock):
  each sample is some 32 bytes per column in memory and some 60 bytes of CSV, so the limit keeps a record below a
  gigabyte;
* :data:`MAX_PIECES` Taylor pieces of one exact time response of a delay system.

The user documentation lists them (``docs/guide/limits.md``).

Examples
--------
>>> check_count("--delay", 100_000_000, MAX_RANGE_POINTS, "values")
Traceback (most recent call last):
...
delaykit.errors.InvalidValueError: --delay: 100000000 values, above the limit of 10000 (delaykit.models.budget.MAX_RANGE_POINTS)
"""

from __future__ import annotations

import math

from ..errors import InvalidValueError

__all__ = ["MAX_RANGE_POINTS", "MAX_GRID_POINTS", "MAX_ROOT_GRID_POINTS", "MAX_FREQUENCY_DECADES", "MAX_SAMPLES",
           "MAX_PIECES", "check_count", "sample_count"]

MAX_RANGE_POINTS = 10_000
"""Values in one range (a sweep of delays or gains, Lambert branches)."""

MAX_GRID_POINTS = 1_000_000
"""Candidates in one gain search (Kp values x Kv values x delays)."""

MAX_ROOT_GRID_POINTS = 20_000_000
"""Points of one root search's candidate grid (some six per ``2 pi / delay`` along Im, 24 or more across the
region): a region that needs more holds more roots than can be listed (a chain puts one every ``2 pi / delay``)."""

MAX_FREQUENCY_DECADES = 24
"""Decades of one frequency range (a Bode or Nyquist plot, a frequency grid): 1e-12 to 1e12 rad/s."""

MAX_SAMPLES = 10_000_000
"""Samples in one record: a response sampled every ``dt``, a log resampled on a uniform clock."""

MAX_PIECES = 1 << 21
"""Taylor pieces of one exact time response of a delay system (``delaykit.step_response`` and its kin): the kernel
keeps every piece's polynomials (some 200 bytes per delay channel each) for the delays to read."""

_NAMES = {MAX_RANGE_POINTS: "MAX_RANGE_POINTS", MAX_GRID_POINTS: "MAX_GRID_POINTS",
          MAX_ROOT_GRID_POINTS: "MAX_ROOT_GRID_POINTS", MAX_FREQUENCY_DECADES: "MAX_FREQUENCY_DECADES",
          MAX_SAMPLES: "MAX_SAMPLES", MAX_PIECES: "MAX_PIECES"}


def check_count(what: str, count: float, limit: int, unit: str, hint: str = "") -> int:
    """Return ``count`` as an int, or raise :class:`~delaykit.errors.InvalidValueError` when it exceeds ``limit``.

    Parameters
    ----------
    what : str
        What asks for the work, as the user wrote it (``"--delay"``, ``"dt = 1e-09 s over 15 s"``).
    count : float
        How many items it asks for (a float, so that an astronomically large count is no problem).
    limit : int
        The limit (one of this module's constants).
    unit : str
        What is counted (``"values"``, ``"samples"``).
    hint : str
        What to change, appended to the message.

    Examples
    --------
    >>> check_count("--kp", 5, MAX_RANGE_POINTS, "values")
    5
    """
    if not count <= limit:  # (also refuses NaN)
        try:
            shown = f"{count:.0f}" if count < 1e18 else f"{count:.3g}"
        except OverflowError:  # an integer beyond the floats
            shown = f"about 1e{len(str(int(count))) - 1}"
        name = _NAMES.get(limit)
        where = f" (delaykit.models.budget.{name})" if name else ""
        raise InvalidValueError(f"{what}: {shown} {unit}, above the limit of {limit}{where}"
                                + (f"; {hint}" if hint else ""))
    return int(count)


def sample_count(what: str, span: float, step: float, hint: str = "") -> int:
    """The number of samples every ``step`` over ``span`` (both ends included), checked against
    :data:`MAX_SAMPLES`.

    Examples
    --------
    >>> sample_count("dt", 15.0, 0.01)
    1501
    >>> sample_count("--dt 1e-09 s", 15.0, 1e-9)
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: --dt 1e-09 s: 15000000001 samples, above the limit of 10000000 (delaykit.models.budget.MAX_SAMPLES)
    """
    try:
        n = float(span) / float(step) * (1 + 1e-12) + 1 if span > 0 else 1.0  # (Python floats: no numpy warning)
    except (OverflowError, ZeroDivisionError):  # a step of 1e-320: beyond any count
        n = math.inf
    check_count(what, n, MAX_SAMPLES, "samples", hint)
    return math.floor(n)
