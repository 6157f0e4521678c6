"""The model structures identification fits: plant families with physical parameters, and a dead time.

==============  ===============================================================  =====================================
name            plant (times ``exp(-delay s)``)                                  parameters
==============  ===============================================================  =====================================
``ipdt``        ``K / s``: integrating plus dead time (the paper's drone)        gain, delay
``ipdt_lag``    ``K / (s (T s + 1))``: a first-order speed loop                  gain, lag, delay
``ipdt_speed``  ``K wn^2 (Tz s + 1) / (s (s^2 + 2 zeta wn s + wn^2))``: a        gain, wn, zeta, zero, delay
                closed second-order speed loop with a zero (what a PI speed
                controller makes: the PX4 vehicle)
``fopdt``       ``K / (T s + 1)``: first order plus dead time                    gain, time_constant, delay
``sopdt``       ``K / ((T1 s + 1)(T2 s + 1))``: second order plus dead time      gain, time_constant, time_constant2,
                (``T1 >= T2``)                                                   delay
``ipdt_accel``  the command's rate limited to ``accel`` (an autopilot's          gain, accel, lag, delay
                acceleration limit), then ``K / (s (T s + 1))``: not linear,
                simulated by its own exact closed form (open loop only)
==============  ===============================================================  =====================================

A PI speed controller ``(P s + I)/s`` around an acceleration ``b/s`` closes to ``wn^2 = b I``, ``2 zeta wn = b P``
and ``Tz = P / I``; ``ipdt_speed`` leaves the three free, so a speed loop with other dynamics (a rate limit, a
filter) still fits.  The dead time is always the last parameter, ``delay``.

Examples
--------
>>> s = STRUCTURES["fopdt"]
>>> s
Structure('fopdt': gain, time_constant, delay)
>>> s.plant([0.62, 150.0, 12.0]).dc_gain()
0.62
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from .. import _native
from ..errors import InvalidValueError
from ..models.transfer import TransferFunction

__all__ = ["Structure", "STRUCTURES", "structure"]

_FK = _native.load("delaykit.identify", "_fitkernel")  # (its realise: the well-scaled cascades)


@dataclass(frozen=True, repr=False)
class Structure:
    """A named plant family with a dead time.

    Attributes
    ----------
    name : str
        Its name (``ipdt``, ``ipdt_lag``, ``ipdt_speed``, ``fopdt``, ``sopdt``).
    title : str
        A short description.
    params : tuple of str
        Parameter names, ``delay`` last.
    units : tuple of str
        Their units (``"u"`` stands for the input's unit, ``"y"`` for the output's).
    positive : tuple of bool
        Which parameters must be positive (fitted on a log scale).
    integrating : bool
        Whether the plant has an integrator.
    code : int
        Which compiled realisation :meth:`realise` uses (-1: the companion form of :meth:`plant`).
    limited : bool
        Whether the command is rate limited before the plant (``ipdt_accel``): the structure is not linear,
        :meth:`plant` is its linear part only (the limit left out), and fits simulate it with its own closed
        form (``delaykit.identify._accel``), open loop only.
    fixed : tuple of (str, float)
        Parameters held at a given value instead of fitted (``ipdt_accel``'s ``accel`` when the vehicle's limit
        is known: :func:`~delaykit.identify.identification.identify`'s ``accel_limit``); empty for a registered
        structure.
    """

    name: str
    title: str
    params: tuple[str, ...]
    units: tuple[str, ...]
    positive: tuple[bool, ...]
    integrating: bool
    _coeffs: Callable[[np.ndarray], tuple[list[float], list[float]]]
    code: int = -1
    limited: bool = False
    fixed: tuple[tuple[str, float], ...] = ()

    @property
    def size(self) -> int:
        """Number of parameters (the delay included)."""
        return len(self.params)

    def plant(self, values: Sequence[float]) -> TransferFunction:
        """The plant (without its dead time) for parameter values in :attr:`params` order.

        Examples
        --------
        >>> STRUCTURES["ipdt_lag"].plant([0.9, 0.25, 0.2]).to_string()
        '3.6/(s^2 + 4*s)'
        """
        v = np.asarray(values, dtype=float)
        if v.shape != (self.size,):
            raise InvalidValueError(f"{self.name} takes {self.size} values ({', '.join(self.params)}), got {v.size}")
        num, den = self._coeffs(v)
        return TransferFunction(num, den)

    def realise(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A state-space realisation ``(A, B, C)`` of the plant (strictly proper: no ``D``), built directly from
        the parameters in a well-scaled form (a cascade of the physical lags, not the companion form of
        :meth:`plant`), for the fits that simulate thousands of trial plants.  Same transfer function as
        :meth:`plant`; no checks.

        Examples
        --------
        >>> A, B, C = STRUCTURES["sopdt"].realise(np.array([2.0, 0.5, 0.1, 0.0]))
        >>> A.tolist(), B.tolist(), C.tolist()
        ([[-2.0, 0.0], [10.0, -10.0]], [4.0, 0.0], [0.0, 1.0])
        """
        if self.code >= 0:
            return _FK.realise(self.code, np.ascontiguousarray(values, dtype=float))
        A, B, C, D = self.plant(values).state_space()
        if D:
            raise InvalidValueError(f"{self.name}: realise() is for strictly proper plants")
        return np.atleast_2d(A), np.asarray(B, float), np.asarray(C, float)

    def canonical(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The values in a unique order (``sopdt``: ``T1 >= T2``), and the permutation applied."""
        perm = np.arange(self.size)
        if self.name == "sopdt" and values[1] < values[2]:
            perm[[1, 2]] = [2, 1]
        return values[perm], perm

    def __repr__(self) -> str:
        return f"Structure({self.name!r}: {', '.join(self.params)})"


def _ipdt(v: np.ndarray) -> tuple[list[float], list[float]]:
    return [v[0]], [1.0, 0.0]


def _ipdt_lag(v: np.ndarray) -> tuple[list[float], list[float]]:
    return [v[0]], [v[1], 1.0, 0.0]


def _ipdt_speed(v: np.ndarray) -> tuple[list[float], list[float]]:
    k, wn, zeta, tz = v[0], v[1], v[2], v[3]
    return [k * wn * wn * tz, k * wn * wn], [1.0, 2.0 * zeta * wn, wn * wn, 0.0]


def _ipdt_accel(v: np.ndarray) -> tuple[list[float], list[float]]:
    return [v[0]], [v[2], 1.0, 0.0]


def _fopdt(v: np.ndarray) -> tuple[list[float], list[float]]:
    return [v[0]], [v[1], 1.0]


def _sopdt(v: np.ndarray) -> tuple[list[float], list[float]]:
    return [v[0]], [v[1] * v[2], v[1] + v[2], 1.0]


STRUCTURES: dict[str, Structure] = {
    s.name: s for s in (
        Structure("ipdt", "integrating plus dead time", ("gain", "delay"), ("y/(u s)", "s"), (False, False), True,
                  _ipdt, 0),
        Structure("ipdt_lag", "integrating with a first-order lag plus dead time", ("gain", "lag", "delay"),
                  ("y/(u s)", "s", "s"), (False, True, False), True, _ipdt_lag, 1),
        Structure("ipdt_speed", "integrating behind a second-order speed loop with a zero, plus dead time",
                  ("gain", "wn", "zeta", "zero", "delay"), ("y/(u s)", "rad/s", "", "s", "s"),
                  (False, True, True, True, False), True, _ipdt_speed, 2),
        Structure("fopdt", "first order plus dead time", ("gain", "time_constant", "delay"), ("y/u", "s", "s"),
                  (False, True, False), False, _fopdt, 3),
        Structure("sopdt", "second order plus dead time", ("gain", "time_constant", "time_constant2", "delay"),
                  ("y/u", "s", "s", "s"), (False, True, True, False), False, _sopdt, 4),
        Structure("ipdt_accel", "integrating with a first-order lag behind an acceleration (rate) limit, plus "
                  "dead time", ("gain", "accel", "lag", "delay"), ("y/(u s)", "u/s", "s", "s"),
                  (False, True, True, False), True, _ipdt_accel, -1, True),
    )
}
"""Every structure by name."""


def structure(name: str) -> Structure:
    """The structure called ``name``, or an error listing the names that exist.

    Examples
    --------
    >>> structure("sopdt").params
    ('gain', 'time_constant', 'time_constant2', 'delay')
    """
    if not isinstance(name, str) or name not in STRUCTURES:
        raise InvalidValueError(f"unknown model structure {name!r}; expected one of {', '.join(STRUCTURES)} "
                                "(or 'auto')")
    return STRUCTURES[name]
