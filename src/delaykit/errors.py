"""The exceptions delaykit raises.

Every check in the library raises one of these, with a message that names the bad value and what was
expected; the command line prints the message (no traceback) and exits with status 2.  Code tells errors apart
by their type, never by their message (the message is for people).

Every exception class of the package derives from :class:`DelaykitError` and is exported from ``delaykit``.
The ones of general use are defined here; those that belong to one layer are defined next to the code that raises
them (this module is the lowest layer and imports nothing of the package) and are loaded on first use by
``delaykit``: ``ProtocolError``, ``ATError`` and ``NavdataError`` (:mod:`delaykit.hardware.ardrone`),
``LinkError`` and ``VehicleRefusedError`` (:mod:`delaykit.hardware.link`), ``EstimationError`` (:mod:`delaykit.identify.estimation`),
``LogError`` (:mod:`delaykit.identify.flightlog`) and ``IdentificationError``
(:mod:`delaykit.identify.identification`).

Hierarchy::

    DelaykitError
    ├── InvalidValueError (also ValueError): a bad value
    │   ├── RangeSpecError: text that is not a range (START:STOP:N, a comma list or a number)
    │   ├── ProtocolError: a malformed datagram (ATError, NavdataError)
    │   ├── EstimationError: the data cannot give a delay by this method
    │   ├── LogError: an unreadable flight log
    │   ├── IdentificationError: data or settings that do not allow an identification
    │   ├── PortNumberError (also PortError): a port number out of range
    │   └── OutputError (also OSError): a file that cannot be written (its folder gone, no space left...)
    ├── InvalidTypeError (also TypeError): a value of the wrong type
    ├── PortError (also OSError): a port that cannot be bound (already in use, ...)
    ├── LinkError (also RuntimeError): the vehicle does not answer
    │   └── VehicleRefusedError: the vehicle refuses a mode, arming or take-off (its reason in the message)
    ├── FlightError (also RuntimeError): a flight produced nothing to work with
    │   └── FlightInterruptedError: the user stopped a pipeline of flights (Ctrl-C, SIGTERM, SIGHUP)
    └── MissingDependencyError (also ImportError): an optional package (python-control) is not installed
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Any, Iterator

__all__ = ["DelaykitError", "DelaykitWarning", "InvalidValueError", "InvalidTypeError", "RangeSpecError", "PortError",
           "PortNumberError", "OutputError", "FlightError", "FlightInterruptedError", "MissingDependencyError",
           "check_real",
           "check_finite_array", "check_path", "plain", "writing"]


class DelaykitError(Exception):
    """Base class of delaykit's own errors."""


class DelaykitWarning(UserWarning):
    """Base class of delaykit's warnings (a result is returned, but outside the range its method is meant for)."""


class InvalidValueError(DelaykitError, ValueError):
    """A value is out of range, not finite, or not one of the allowed choices."""


class InvalidTypeError(DelaykitError, TypeError):
    """A value has the wrong type (for example text where a number was expected)."""


class RangeSpecError(InvalidValueError):
    """Text that is not a range of values at all: not ``START:STOP:N``, a comma list or a number.

    (A well-formed range with bad values, such as ``N = 0`` or a reversed range, is a plain
    :class:`InvalidValueError`.)
    """


class PortError(DelaykitError, OSError):
    """A network port that cannot be used: already in use, or the system refused to bind it.

    An environment problem rather than a bad value, so an :class:`OSError` (not a :class:`ValueError`).
    """


class PortNumberError(PortError, InvalidValueError):
    """A port number out of range (0 to 65535): a bad value, and a :class:`PortError`."""


class OutputError(InvalidValueError, OSError):
    """A file that cannot be written: its folder is gone, the disk is full (``/dev/full``), a link points nowhere,
    a device refuses.  A bad output path (an :class:`InvalidValueError`, as the checks before the work say) and an
    :class:`OSError` (what the system said)."""


class FlightError(DelaykitError, RuntimeError):
    """A flight produced nothing to work with (no logs), so the pipeline cannot go on."""


class FlightInterruptedError(FlightError):
    """A flight of a pipeline (``run_demo``) was interrupted (Ctrl-C, SIGTERM, SIGHUP): the vehicle landed, and the
    pipeline stops instead of flying its next flight.  ``signal_name`` says which (``"Ctrl-C"``, ``"SIGTERM"``)."""

    def __init__(self, message: str, signal_name: str) -> None:
        super().__init__(message)
        self.signal_name = signal_name


class MissingDependencyError(DelaykitError, ImportError):
    """An optional package that a function needs is not installed (the message says which and how to install it).

    An :class:`ImportError`, so ``except ImportError`` around optional features keeps working.
    """


def plain(value: Any) -> Any:
    """``value`` as a message shows it: a NumPy scalar as the Python number it holds (``1.5``, not
    ``np.float64(1.5)``), anything else unchanged.

    Examples
    --------
    >>> import numpy as np
    >>> f"got {plain(np.float64(0.5))!r}"
    'got 0.5'
    """
    if type(value).__module__ == "numpy" and getattr(value, "shape", None) == () and hasattr(value, "item"):
        return value.item()
    return value


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
    except OverflowError:  # an int beyond the floats (10**400)
        size = f"an integer of about {int(value.bit_length() * 0.30103) + 1} digits" if isinstance(value, int) \
            else f"a {type(value).__name__} beyond the floats"
        raise InvalidValueError(f"{name} must be finite, got {size}") from None
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name} must be a real number, got {value!r}") from exc
    if math.isnan(x) or (math.isinf(x) and not ((allow_inf and x > 0) or (allow_neg_inf and x < 0))):
        raise InvalidValueError(f"{name} must be finite, got {x!r}")  # a plain float: nan, not np.float64(nan)
    if minimum is not None:
        if strict and not x > minimum:
            raise InvalidValueError(f"{name} must be greater than {minimum:g}, got {x:g}")
        if not strict and not x >= minimum:
            raise InvalidValueError(f"{name} must be at least {minimum:g}, got {x:g}")
    if maximum is not None and not x <= maximum:
        raise InvalidValueError(f"{name} must be at most {maximum:g}, got {x:g}")
    return x


def check_finite_array(name: str, values: Any) -> Any:
    """Return ``values`` as a float NumPy array, or raise a delaykit error that names the first bad sample.

    Anything that is not numbers (text, None, objects) raises :class:`InvalidTypeError`; a sample that is nan or
    infinite raises :class:`InvalidValueError` giving its index.  Complex values are refused (a signal is real).

    Parameters
    ----------
    name : str
        The name shown in the message (for example ``"z"``).
    values : array_like
        The samples.

    Returns
    -------
    numpy.ndarray

    Examples
    --------
    >>> check_finite_array("z", [0.0, 1.5]).tolist()
    [0.0, 1.5]
    >>> check_finite_array("z", [0.0, float("inf")])
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: z[1] is inf; every sample must be finite
    """
    import numpy as np  # here, so that importing this module stays cheap

    try:
        arr = np.asarray(values)
        if arr.dtype.kind not in "biuf":
            raise TypeError(arr.dtype)
        arr = arr.astype(float, copy=False)
    except (TypeError, ValueError, OverflowError):
        shown = repr(values)
        raise InvalidTypeError(f"{name} must be real numbers, got {shown[:60]}{'...' if len(shown) > 60 else ''}") \
            from None
    bad = np.flatnonzero(~np.isfinite(arr.ravel()))
    if bad.size:
        i = int(bad[0])
        where = f"{name}[{i}]" if arr.ndim == 1 else f"{name}[{', '.join(map(str, np.unravel_index(i, arr.shape)))}]"
        raise InvalidValueError(f"{where} is {arr.ravel()[i]}; every sample must be finite")
    return arr


def check_path(name: str, value: Any) -> Any:
    """Return ``value`` as a :class:`pathlib.Path`, or raise :class:`InvalidTypeError` naming it when it is not a
    file name (text or an ``os.PathLike`` giving text): None, a number, bytes.

    Parameters
    ----------
    name : str
        What the path is, for the message (for example ``"loop file"``).
    value : Any
        The path to check.

    Returns
    -------
    pathlib.Path

    Examples
    --------
    >>> check_path("loop file", "loop.toml").name
    'loop.toml'
    >>> check_path("loop file", None)
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidTypeError: the loop file must be a path (text or a pathlib.Path), got None (NoneType)
    """
    import os
    from pathlib import Path

    text = os.fspath(value) if isinstance(value, os.PathLike) else value
    if not isinstance(text, str):
        raise InvalidTypeError(f"the {name} must be a path (text or a pathlib.Path), got {value!r:.60} "
                               f"({type(value).__name__})")
    if not text or "\0" in text:
        raise InvalidValueError(f"the {name} {text!r:.60} is not a file name" + (" (it holds a NUL character)"
                                                                              if text else " (it is empty)"))
    return Path(text)


@contextmanager
def writing(name: str, path: Any) -> Iterator[None]:
    """Turn an :class:`OSError` raised while writing ``path`` into an :class:`OutputError` naming ``name`` (an
    option such as ``--save``, or what the file is) and the path: a failure after the work, one line.

    Examples
    --------
    >>> with writing("--csv", "/no/such/folder/r.csv"):
    ...     open("/no/such/folder/r.csv", "w")
    Traceback (most recent call last):
    ...
    delaykit.errors.OutputError: --csv '/no/such/folder/r.csv' could not be written: No such file or directory
    """
    try:
        yield
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"{name} {str(path)!r} could not be written: {exc.strerror or exc}") from None
