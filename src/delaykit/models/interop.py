"""python-control interoperability: a loop's open-loop transfer function as a ``control.TransferFunction``.

python-control has no exact delay, so :func:`to_control` replaces ``exp(-s T)`` by a Padé approximation of the
order asked for (:func:`pade_coefficients`, from its closed form; a delayed loop without an order is refused), and :func:`pade_error` reports how far the
approximation's ``L(jw)`` is from the exact one at chosen frequencies.  python-control stays optional: it is
imported inside the functions, and a missing installation raises
:class:`~delaykit.errors.MissingDependencyError` (an ``ImportError``).

The other direction needs nothing here: a :class:`~delaykit.models.loop.Loop` takes python-control
``TransferFunction`` and ``StateSpace`` plants, and :meth:`~delaykit.models.controllers.Controller.transfer`
takes a python-control ``TransferFunction`` controller (through :meth:`TransferFunction.coerce`).

Examples
--------
>>> from delaykit import AltitudeLoop
>>> L = to_control(AltitudeLoop(kp=1.31, delay=0.368), pade_order=3)
>>> L.num_array[0][0].size, L.den_array[0][0].size    # 1.31/s times a third-order Pade factor
(4, 5)
>>> pade_error(AltitudeLoop(kp=1.31, delay=0.368), 3, [0.1, 1.0, 2.0]).max_error < 1e-3
True
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, MissingDependencyError, check_real, plain
from .altitude import AltitudeLoop, as_loop
from .loop import Loop

__all__ = ["to_control", "pade_error", "PadeError", "pade_coefficients", "require_control", "check_pade_order",
           "MAX_PADE_ORDER"]


def require_control(what: str) -> Any:
    """The python-control module, or a MissingDependencyError that says what needed it."""
    try:
        import control
    except ImportError as exc:
        raise MissingDependencyError(f"{what} needs python-control, which is not installed (pip install control)"
                                     ) from exc
    return control


def _loop(loop: Any) -> Loop:
    loop = as_loop(loop)
    if loop.sampled:
        raise InvalidValueError(
            f"the loop is sampled (period {loop.period:g} s): its open loop is not a rational function of s times a "
            "delay; use the continuous loop (loop.replace(period=None)), or delaykit.spectrum.sampled")
    return loop


MAX_PADE_ORDER = 40
"""The highest Padé order accepted: the coefficients of order ``n`` span ``n! / (2n)!`` (1e-30 at ``n = 20``), so
that higher orders hold nothing more in floating point (and ``control.pade`` divides by zero from about 200)."""


def check_pade_order(pade_order: Any, name: str = "pade_order") -> int:
    """``pade_order`` as an int from 1 to :data:`MAX_PADE_ORDER` (an integral float accepted), or an
    :class:`InvalidValueError` naming it as ``name``.

    Examples
    --------
    >>> check_pade_order(6), check_pade_order(3.0)
    (6, 3)
    >>> check_pade_order(10**6)
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: pade_order must be an integer from 1 to 40, got 1000000
    """
    if isinstance(pade_order, (bool, np.bool_)) or not isinstance(pade_order, numbers.Integral):
        if isinstance(pade_order, numbers.Real) and not isinstance(pade_order, bool) and math.isfinite(pade_order) \
                and float(pade_order).is_integer():
            pade_order = int(pade_order)
        else:
            raise InvalidValueError(f"{name} must be an integer from 1 to {MAX_PADE_ORDER}, got "
                                    f"{plain(pade_order)!r:.40}")
    if not 1 <= pade_order <= MAX_PADE_ORDER:
        raise InvalidValueError(f"{name} must be an integer from 1 to {MAX_PADE_ORDER}, got {int(pade_order)}")
    return int(pade_order)


def pade_coefficients(T: float, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``(order, order)`` Padé approximant of ``exp(-s T)`` as ``(num, den)``, highest power of ``s`` first.

    ``den = sum_k c_k T^k s^k`` and ``num`` the same with ``(-1)^k``, ``c_k = (2n - k)! n! / ((2n)! k! (n - k)!)``,
    scaled so that ``den`` is monic (python-control's ``pade`` normalisation, whose coefficients these equal).

    Parameters
    ----------
    T : float
        The delay (s), at least 0 (``T = 0`` gives ``([1], [1])``).
    order : int
        ``n``, at least 1.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)

    Examples
    --------
    >>> num, den = pade_coefficients(1.0, 2)      # (12 - 6 s + s^2) / (12 + 6 s + s^2)
    >>> num.tolist(), den.tolist()
    ([1.0, -6.0, 12.0], [1.0, 6.0, 12.0])
    """
    T = check_real("delay T (s)", T, minimum=0.0)
    n = check_pade_order(plain(order), "order")
    if T == 0.0:
        return np.ones(1), np.ones(1)
    k = np.arange(n + 1)
    c = np.array([math.factorial(2 * n - j) * math.factorial(n) / (math.factorial(2 * n) * math.factorial(j)
                                                                    * math.factorial(n - j)) for j in k])
    # monic in s: divide by c_n T^n, each power scaled by T^(k - n) (no overflow of T^n for long delays)
    asc = c / c[-1] * T ** (k - n).astype(float)
    den = asc[::-1].copy()
    num = (asc * (-1.0) ** k)[::-1].copy()
    return num, den


def to_control(loop: Loop | AltitudeLoop, pade_order: int | None = None) -> Any:
    """The open-loop transfer function ``L`` (broken at the plant input) as a python-control ``TransferFunction``.

    ``L(s) = Np(s) Nc(s) / (Dp(s) Dc(s)) exp(-s T)`` with ``T`` the total delay, so that
    ``control.feedback(L, 1)`` is the closed loop of the loop's characteristic equation.  The delay is replaced
    by its Padé approximant of order ``pade_order`` (:func:`pade_coefficients`, the coefficients of
    ``control.pade(T, pade_order)``).

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A continuous loop.
    pade_order : int, optional
        Order (at least 1) of the Padé approximation of the delay; required when the loop has a delay (ignored
        without one).

    Returns
    -------
    control.TransferFunction

    Raises
    ------
    InvalidValueError
        For a delayed loop without ``pade_order``, a ``pade_order`` that is not an integer of at least 1, or a
        sampled loop.
    MissingDependencyError
        When python-control is not installed.

    See Also
    --------
    pade_error : the approximation's error against the exact ``L(jw)``.

    References
    ----------
    .. [1] G. A. Baker and P. Graves-Morris, *Padé Approximants*, 2nd ed., Cambridge University Press, 1996.

    Examples
    --------
    >>> from delaykit import Controller, Loop
    >>> L = to_control(Loop("1/((s+1)*(s+2))", Controller.p(3.0)))
    >>> float(L.dcgain())
    1.5
    """
    loop = _loop(loop)
    order = None if pade_order is None else check_pade_order(pade_order)
    if loop.total_delay > 0 and order is None:
        raise InvalidValueError(
            f"the loop has a delay of {loop.total_delay:g} s, which python-control cannot represent exactly: give "
            "pade_order=n for an n-th order Padé approximation of exp(-s T)")
    control = require_control("to_control()")
    num, den = loop.open_loop()
    L = control.tf(num, den)
    if loop.total_delay > 0:
        pn, pd = pade_coefficients(loop.total_delay, order)
        L = L * control.tf(pn, pd)
    return L


@dataclass(frozen=True, repr=False)
class PadeError:
    """How far a Padé-approximated ``L(jw)`` is from the exact one over a set of frequencies.

    ``max_error`` is ``max |L_pade(jw) - L(jw)|`` and ``frequency`` (rad/s) is where it is largest;
    ``max_relative_error`` is ``max |L_pade - L| / |L|`` over the frequencies where ``L`` is not 0.
    """

    order: int
    max_error: float
    frequency: float
    max_relative_error: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"order": self.order, "max_error": self.max_error, "frequency": self.frequency,
                "max_relative_error": self.max_relative_error}

    def __repr__(self) -> str:
        return (f"PadeError(order {self.order}: max |error| {self.max_error:.3g} at {self.frequency:.4g} rad/s, "
                f"relative {self.max_relative_error:.3g})")


def pade_error(loop: Loop | AltitudeLoop, order: int, w: Any) -> PadeError:
    """The error of :func:`to_control`'s Padé approximation against the exact ``L(jw)``, over frequencies ``w``.

    The exact ``L(jw) = Np Nc / (Dp Dc) (jw) exp(-jw T)`` is evaluated here with NumPy; the approximation by
    python-control (``L_pade(jw)`` of the returned transfer function).

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        A continuous loop.
    order : int
        The Padé order (at least 1).
    w : array_like
        Frequencies in rad/s (finite, at least 0, not empty), away from poles on the imaginary axis.

    Returns
    -------
    PadeError

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> loop = AltitudeLoop(kp=1.31, delay=0.368)
    >>> [pade_error(loop, n, [0.5, 1.31, 3.0]).max_error < 10.0 ** -k for n, k in ((1, 1), (4, 7))]
    [True, True]
    """
    loop = _loop(loop)
    n = check_pade_order(order, "order")
    if isinstance(w, (str, bytes)):
        raise InvalidTypeError(f"w must be frequencies in rad/s (numbers), got {w!r}")
    wa = np.atleast_1d(np.asarray(w))
    if wa.dtype.kind not in "iuf":
        raise InvalidTypeError(f"w must be real frequencies in rad/s, got an array of dtype {wa.dtype}")
    wa = wa.astype(float).ravel()
    if wa.size == 0:
        raise InvalidValueError("w is empty: give at least one frequency (rad/s)")
    if not np.all(np.isfinite(wa)):
        raise InvalidValueError(f"frequencies must be finite, got {float(wa[~np.isfinite(wa)][0])!r} in w")
    if np.any(wa < 0):
        raise InvalidValueError(f"frequencies must be at least 0 rad/s, got {float(wa[wa < 0][0]):g} in w")
    approx_tf = to_control(loop, pade_order=n)
    num, den = loop.open_loop()
    s = 1j * wa
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # python-control's own division at a pole (w = 0 on 1/s)
        exact = np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * loop.total_delay)
        approx = np.asarray(approx_tf(s), dtype=complex).reshape(wa.shape)
        err = np.abs(approx - exact)
        rel = np.where(np.abs(exact) > 0, err / np.abs(exact), 0.0)
    if not np.all(np.isfinite(err)):
        k = int(np.flatnonzero(~np.isfinite(err))[0])
        with np.errstate(all="ignore"):
            pole = np.polyval(den, s[k]) == 0
        if not pole:  # L or its approximation beyond the floats (the Pade polynomials at w = 1e308)
            raise InvalidValueError(f"L(jw) or its approximation cannot be evaluated at w = {wa[k]:g} rad/s: the "
                                    "polynomials overflow the floats there; leave frequencies this high out")
        raise InvalidValueError(f"L(jw) is infinite at w = {wa[k]:g} rad/s (a pole on the imaginary axis); leave "
                                "that frequency out")
    i = int(np.argmax(err))
    return PadeError(order=n, max_error=float(err[i]), frequency=float(wa[i]),
                     max_relative_error=float(np.max(rel)) if rel.size else math.nan)
