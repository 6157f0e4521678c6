"""Padé approximation of a system's delays: a delay-free system that python-control can hold, and its error.

The ``(n, n)`` Padé approximant of ``exp(-s T)`` is ``p(-s T) / p(s T)`` with
``p(x) = sum_k c_k x^k``, ``c_k = (2n - k)! n! / ((2n)! k! (n - k)!)`` (closed form, [1]_): all-pass (``|.| = 1``
on the imaginary axis), exact at ``s = 0`` up to ``s^(2n)``.  :func:`pade` replaces every delay channel of a
:class:`~delaykit.systems.DelayLTI` by it (the linear-fractional form closed over the approximations), so the
result is a delay-free system, which :func:`delaykit.systems.to_control` hands to python-control.
:func:`pade_error` states how far the approximation's frequency response is from the exact one.

Limits: the approximation is good for ``w T`` well below ``n`` (its phase falls behind the delay's beyond); its
relative error at low frequency is about ``(w T)^(2n+1) (n!)^2 / ((2n)! (2n+1)!)``.  High orders of long delays are
ill-conditioned polynomials (the coefficients span ``(2n)!``): orders above 10 or so gain nothing in double
precision.

References
----------
.. [1] G. A. Baker and P. Graves-Morris, *Padé Approximants*, 2nd ed., Cambridge University Press, 1996.

Examples
--------
>>> from delaykit import tf
>>> G = pade(tf("exp(-s)/(s+1)"), 3)
>>> G
DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 4 states, no delays)
>>> pade_error(tf("exp(-s)/(s+1)"), 3, [0.1, 1.0]).max_error < 1e-3
True
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real, plain
from ..models.interop import PadeError, check_pade_order, pade_coefficients
from ..models.transfer import TransferFunction
from .algebra import append, close, gain
from .lti import DelayLTI, as_frequencies

__all__ = ["pade", "pade_error"]


def _check_order(order: Any) -> int:
    """An order from 1 to :data:`~delaykit.models.interop.MAX_PADE_ORDER`, or an error naming ``order``."""
    return check_pade_order(plain(order), "order")


def _block(T: float, order: int) -> DelayLTI:
    """The Padé approximant of ``exp(-s T)`` as a delay-free SISO system (controllable canonical form)."""
    if T == 0.0:
        return gain(1.0)
    A, B, C, D = TransferFunction(*pade_coefficients(T, order)).state_space()
    n = A.shape[0]
    return DelayLTI(A=A, B1=B.reshape(n, 1), C1=C.reshape(1, n), D11=[[D]])


def pade(sys: DelayLTI | float, order: int, *, channels: Any = None) -> DelayLTI:
    """A delay-free system: every delay ``exp(-s tau_j)`` of ``sys`` replaced by its ``(order, order)`` Padé
    approximant (:func:`~delaykit.models.interop.pade_coefficients`), or the approximant of one delay ``T`` given as a number; with
    ``channels``, only those delay channels approximated, the others kept exact.

    The delay channels of the linear-fractional form are closed over the approximations (as MATLAB's ``pade`` of
    a ``delayss``), so internal delays (a delay inside a loop) are approximated where they sit; a channel of zero
    delay is closed as it is.  The result converts to python-control (:meth:`DelayLTI.to_control`).

    Parameters
    ----------
    sys : DelayLTI or float
        The system (without saturation channels), or a delay ``T`` in seconds (at least 0).
    order : int
        The order ``n`` of every approximant, at least 1: ``n`` states per delay.
    channels : int or sequence of int, optional
        The delay channels to approximate (indices into ``sys.delays``); by default all of them.

    Returns
    -------
    DelayLTI
        No delays (or only those of the channels left out); the states of ``sys`` first, then ``order`` states
        per approximated delay channel.

    Raises
    ------
    InvalidValueError
        For an order that is not an integer of at least 1, a negative delay, a saturation channel, a channel
        index out of range, or a closed loop that is not well posed.

    See Also
    --------
    pade_error : how far the approximation's frequency response is from the exact one.
    delaykit.systems.to_control : the same approximation as a python-control ``StateSpace``.

    Examples
    --------
    >>> from delaykit import tf, feedback
    >>> P = pade(feedback(tf("exp(-0.5*s)/s"), 1), 2)     # a delay inside a loop
    >>> P.ndelays, P.nstates
    (0, 3)
    >>> pade(0.5, 1)                  # exp(-0.5 s) ~ (4 - s)/(4 + s)
    DelayLTI(1 input ['u[0]'] -> 1 output ['y[0]'], 1 state, no delays)
    >>> pade(tf([["exp(-s)/(s+1)", "exp(-2*s)/(s+1)"]]), 2, channels=[1])     # the second delay only
    DelayLTI(2 inputs ['u[0]', 'u[1]'] -> 1 output ['y[0]'], 4 states, delays [1] s)
    """
    n = _check_order(order)
    if not isinstance(sys, DelayLTI):
        if isinstance(sys, numbers.Real) and not isinstance(sys, (bool, np.bool_)):
            return _block(check_real("delay T (s)", sys, minimum=0.0), n)
        raise InvalidTypeError(f"pade takes a DelayLTI or a delay in seconds (a number), got {type(sys).__name__}")
    if sys.saturations:
        raise InvalidValueError(f"the channels {list(sys.saturations)} saturate, which a delay-free linear system "
                                "cannot hold: approximate sys.without_limits() for the small-signal system")
    m, nu, ny = sys.ndelays, sys.ninputs, sys.noutputs
    chosen = set(range(m)) if channels is None else _channels(channels, m)
    if not m:
        return sys
    P = DelayLTI(sys.A, np.hstack([sys.B1, sys.B2]), None, np.vstack([sys.C1, sys.C2]), None,
                 np.block([[sys.D11, sys.D12], [sys.D21, sys.D22]]))
    # blocks: P (inputs u, w; outputs y, z) and the approximations (inputs z; outputs w)
    F = np.zeros((nu + 2 * m, ny + 2 * m))
    F[nu:nu + m, ny + m:] = np.eye(m)  # w = the approximations' outputs
    F[nu + m:, ny:ny + m] = np.eye(m)  # the approximations' inputs = z
    G = np.zeros((nu + 2 * m, nu))
    G[:nu] = np.eye(nu)
    H = np.zeros((ny, ny + 2 * m))
    H[:, :ny] = np.eye(ny)
    blocks = [_block(t, n) if j in chosen else _exact(t) for j, t in enumerate(sys.delays)]
    return close(append(P, *blocks), F, G, H, np.zeros((ny, nu)), inputs=sys.inputs, outputs=sys.outputs,
                 name=sys.name, what="the Padé approximation")


def _exact(T: float) -> DelayLTI:
    """``exp(-s T)`` kept exact: one delay channel (a gain of 1 for ``T = 0``)."""
    if T == 0.0:
        return gain(1.0)
    return DelayLTI(D11=[[0.0]], D12=[[1.0]], D21=[[1.0]], D22=[[0.0]], delays=[T])


def _channels(channels: Any, m: int) -> set[int]:
    """Delay-channel indices, each an integer in ``[0, m)``, or an error naming the bad one."""
    items = [channels] if isinstance(channels, numbers.Integral) else channels
    try:
        items = list(items)
    except TypeError:
        raise InvalidTypeError(f"channels must be delay-channel indices (integers), got {plain(channels)!r}"
                               ) from None
    for j in items:
        if isinstance(j, (bool, np.bool_)) or not isinstance(j, numbers.Integral):
            raise InvalidTypeError(f"channels must be delay-channel indices (integers), got {plain(j)!r}")
        if not 0 <= j < m:
            raise InvalidValueError(f"channel {int(j)} is out of range: the system has {m} delay channels "
                                    f"(0 to {m - 1})")
    return {int(j) for j in items}


def pade_error(sys: Any, order: int, w: Any) -> PadeError:
    """How far the Padé approximation's frequency response is from the exact one, over frequencies ``w``.

    For a :class:`DelayLTI`: ``max |H_pade(jw) - H(jw)|`` over ``w`` and over the entries of the transfer matrix,
    ``H_pade`` the response of :func:`pade` ``(sys, order)`` and ``H`` the exact one
    (:meth:`DelayLTI.frequency_response`), and the largest relative error ``|H_pade - H| / |H|`` where
    ``H != 0``.  A :class:`~delaykit.models.Loop` or ``AltitudeLoop`` is the error of its open loop ``L`` (broken
    at the plant input), as :func:`delaykit.models.interop.pade_error`.

    Parameters
    ----------
    sys : DelayLTI, Loop or AltitudeLoop
    order : int
        The Padé order, at least 1.
    w : array_like
        Frequencies in rad/s (finite, at least 0, not empty), away from poles on the imaginary axis.

    Returns
    -------
    PadeError

    Examples
    --------
    The error of ``exp(-s)`` grows with ``w`` and falls with the order:

    >>> from delaykit import delay
    >>> [f"{pade_error(delay(1.0), n, [0.5]).max_error:.1e}" for n in (1, 2, 3)]
    ['1.0e-02', '4.3e-05', '7.7e-08']
    """
    from ..models.altitude import AltitudeLoop
    from ..models.interop import pade_error as loop_pade_error
    from ..models.loop import Loop

    if isinstance(sys, (Loop, AltitudeLoop)):
        return loop_pade_error(sys, order, w)
    if not isinstance(sys, DelayLTI):
        raise InvalidTypeError(f"pade_error takes a DelayLTI, a Loop or an AltitudeLoop, got {type(sys).__name__}")
    n = _check_order(order)
    wa = as_frequencies(w)
    sys = sys.without_limits()
    exact = sys.frequency_response(wa).response
    approx = pade(sys, n).frequency_response(wa).response
    with np.errstate(all="ignore"):
        err = np.abs(approx - exact)
        rel = np.where(np.abs(exact) > 0, err / np.abs(exact), 0.0)
    if not np.all(np.isfinite(err)):
        bad = wa[np.nonzero(~np.isfinite(err))[-1][0]]
        raise InvalidValueError(f"H(jw) is infinite at w = {bad:g} rad/s (a pole on the imaginary axis); leave that "
                                "frequency out")
    worst = err.max(axis=(0, 1)) if err.size else np.zeros(wa.size)
    i = int(np.argmax(worst))
    return PadeError(order=n, max_error=float(worst[i]), frequency=float(wa[i]),
                     max_relative_error=float(np.max(rel)) if rel.size else math.nan)
