"""The plant families users ask for, as transfer functions (the dead time is the loop's ``delay``).

=================================  ==============================================================  ============
family                             transfer function                                               parameters
=================================  ==============================================================  ============
:func:`integrator`                 ``K / s`` (the paper's drone)                                   K
:func:`integrator_lag`             ``K / (s (T s + 1))`` (a first-order speed loop)                K, T
:func:`integrator_speed_loop`      ``K (kp s + ki) b / (s (s^2 + kp b s + ki b))``: an             K, kp, ki, b
                                   integrator behind a closed PI speed loop on ``b / s``
                                   (the PX4 vehicle)
:func:`first_order`                ``K / (T s + 1)`` (with the loop's delay: FOPDT)                K, T
:func:`second_order`               ``K / ((T1 s + 1)(T2 s + 1))`` (SOPDT)                          K, T1, T2
:func:`second_order_wn`            ``K wn^2 / (s^2 + 2 zeta wn s + wn^2)`` (SOPDT, underdamped)    K, wn, zeta
=================================  ==============================================================  ============

An integrating plant plus dead time is :func:`integrator` with the loop's delay.

Examples
--------
>>> integrator_lag(gain=0.8, lag=0.15)
TransferFunction(5.33333/(s^2 + 6.66667 s))
>>> first_order(gain=0.62, time_constant=150.0).dc_gain()
0.62
"""

from __future__ import annotations

from ..errors import check_real
from .transfer import TransferFunction

__all__ = ["integrator", "integrator_lag", "integrator_speed_loop", "first_order", "second_order", "second_order_wn",
           "PLANT_FAMILIES"]


def integrator(gain: float = 1.0) -> TransferFunction:
    """An integrator ``K / s``: the paper's drone, whose altitude integrates the commanded speed.

    Examples
    --------
    >>> integrator().to_string()
    '1/s'
    """
    k = check_real("gain", gain)
    return TransferFunction([k], [1.0, 0.0])


def integrator_lag(gain: float = 1.0, lag: float = 0.1) -> TransferFunction:
    """An integrator behind a first-order lag, ``K / (s (T s + 1))``.

    Examples
    --------
    >>> integrator_lag(1.0, 0.05).poles().real.tolist()
    [-20.0, 0.0]
    """
    k = check_real("gain", gain)
    t = check_real("lag (time constant, s)", lag, minimum=0.0, strict=True)
    return TransferFunction([k], [t, 1.0, 0.0])


def integrator_speed_loop(gain: float = 1.0, kp: float = 4.0, ki: float = 2.0, accel_gain: float = 1.0) -> TransferFunction:
    """An integrator behind a closed PI speed loop: the PX4 vehicle's altitude from its speed command.

    The vehicle's vertical speed follows ``b / s`` of the thrust; a PI controller ``kp + ki / s`` closes
    the speed loop; the altitude integrates the speed.  From the speed command to the altitude::

        K (kp s + ki) b / (s (s^2 + kp b s + ki b))

    a second-order speed loop with a zero, then an integrator.  ``K`` is the gain of the whole chain
    (1 when the vehicle tracks the commanded speed exactly in steady state).

    Examples
    --------
    >>> integrator_speed_loop(kp=4.0, ki=2.0, accel_gain=1.0).to_string()
    '(4*s + 2)/(s^3 + 4*s^2 + 2*s)'
    """
    k = check_real("gain", gain)
    p = check_real("kp (speed loop)", kp, minimum=0.0)
    i = check_real("ki (speed loop)", ki, minimum=0.0)
    b = check_real("accel_gain (thrust to acceleration)", accel_gain, minimum=0.0, strict=True)
    if p == 0.0 and i == 0.0:
        from ..errors import InvalidValueError

        raise InvalidValueError("the speed loop needs kp or ki above zero")
    return TransferFunction([k * p * b, k * i * b], [1.0, p * b, i * b, 0.0])


def first_order(gain: float = 1.0, time_constant: float = 1.0) -> TransferFunction:
    """A first-order process ``K / (T s + 1)``; with the loop's delay, first order plus dead time.

    Examples
    --------
    >>> first_order(2.0, 10.0).poles().tolist()
    [(-0.1+0j)]
    """
    k = check_real("gain", gain)
    t = check_real("time_constant (s)", time_constant, minimum=0.0, strict=True)
    return TransferFunction([k], [t, 1.0])


def second_order(gain: float = 1.0, t1: float = 1.0, t2: float = 0.5) -> TransferFunction:
    """An overdamped second-order process ``K / ((T1 s + 1)(T2 s + 1))``.

    Examples
    --------
    >>> sorted(second_order(1.0, 1.0, 0.5).poles().real.tolist())
    [-2.0, -1.0]
    """
    k = check_real("gain", gain)
    a = check_real("t1 (time constant, s)", t1, minimum=0.0, strict=True)
    b = check_real("t2 (time constant, s)", t2, minimum=0.0, strict=True)
    return TransferFunction([k], [a * b, a + b, 1.0])


def second_order_wn(gain: float = 1.0, wn: float = 1.0, zeta: float = 0.7) -> TransferFunction:
    """A second-order process ``K wn^2 / (s^2 + 2 zeta wn s + wn^2)``.

    Examples
    --------
    >>> second_order_wn(1.0, 2.0, 0.5).dc_gain()
    1.0
    """
    k = check_real("gain", gain)
    w = check_real("wn (rad/s)", wn, minimum=0.0, strict=True)
    z = check_real("zeta", zeta, minimum=0.0)
    return TransferFunction([k * w * w], [1.0, 2 * z * w, w * w])


PLANT_FAMILIES = {
    "integrator": integrator,
    "integrator_lag": integrator_lag,
    "integrator_speed_loop": integrator_speed_loop,
    "first_order": first_order,
    "second_order": second_order,
    "second_order_wn": second_order_wn,
}
"""The families by name (for loop files: ``[plant] family = "first_order"``, ``gain = 0.62``, ...)."""
