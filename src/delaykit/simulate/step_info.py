"""python-control's ``step_info`` for any SISO delay system: the step metrics of its exact step response.

The response is :func:`~delaykit.simulate.systems.step_response` (exact at every sample: the Taylor method of
steps) and the metrics are :func:`~delaykit.simulate.metrics.step_metrics`' (the same as a loop's
``simulate(...).metrics``): overshoot in percent of the final value, the peak refined by a parabola through the
samples around it, rise (10 to 90 %) and settling (``band``, 2 % by default) times interpolated between samples.
python-control reads its rise and settling times at samples, so the two agree to about a sample interval.

Examples
--------
>>> from delaykit import tf
>>> m = step_info(tf("exp(-0.5*s)/(s^2+s+1)"))
>>> round(m.overshoot, 2), round(m.peak_time, 2)     # 16.3 % at 0.5 + pi/sqrt(3/4): the delayed second order
(16.3, 4.13)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from .metrics import StepMetrics, step_metrics

__all__ = ["step_info"]

_POINTS = 4001


def step_info(sys: Any, T: Any = None, *, yfinal: float | None = None, band: float = 0.02) -> StepMetrics:
    """Step metrics of a SISO system's unit step (python-control's ``step_info``), or of a step response.

    Parameters
    ----------
    sys : DelayLTI, Loop or SystemTimeResponse
        A system with one input and one output; a :class:`~delaykit.models.Loop` or ``AltitudeLoop`` gives its
        reference-to-output step (``loop.system[0, 0]``); a step response of such a system (its own times).
    T : array_like or float, optional
        Times or a horizon for the response, as :func:`~delaykit.simulate.systems.step_response`; by default
        4001 times up to :func:`~delaykit.simulate.systems.default_horizon`.
    yfinal : float, optional
        The value the step settles to; by default the DC gain of a system, the mean of the last 10 % of the
        samples of a given response.
    band : float
        The settling band, a fraction of ``yfinal``.

    Returns
    -------
    StepMetrics
        ``overshoot`` (percent of ``yfinal``), ``peak`` and ``peak_time`` (``None`` without overshoot),
        ``rise_time``, ``settling_time`` (``None`` if not settled by the last time), and ``steady_state_error``
        (1 minus the mean of the last 10 % of the samples: the unit step's error).

    Raises
    ------
    InvalidValueError
        Several inputs or outputs, a DC gain that is 0 or infinite (give ``yfinal``), a response that is not a
        step or stopped early.

    Examples
    --------
    >>> from delaykit import tf
    >>> m = step_info(tf("2/(s+1)"), 10.0)
    >>> round(m.rise_time, 4), round(m.settling_time, 3)   # ln 9 and ln 50 time constants
    (2.1972, 3.912)
    """
    from ..models.altitude import AltitudeLoop
    from ..models.loop import Loop
    from ..systems.lti import DelayLTI
    from .systems import SystemTimeResponse, default_horizon, step_response

    if isinstance(sys, (Loop, AltitudeLoop)):
        sys = sys.system[0, 0]
    if isinstance(sys, SystemTimeResponse):
        r = sys
        if r.kind != "step":
            raise InvalidValueError(f"step_info needs a step response, got a {r.kind} response")
        final: Any = "tail" if yfinal is None else check_real("yfinal", yfinal)
    elif isinstance(sys, DelayLTI):
        if (sys.ninputs, sys.noutputs) != (1, 1):
            raise InvalidValueError(f"step_info takes a system with one input and one output, got {sys!r}; select "
                                    "one with sys[i, j]")
        if yfinal is None:
            dc = float(np.real(sys.without_limits().dcgain()[0, 0]))
            if not math.isfinite(dc) or dc == 0.0:
                raise InvalidValueError(f"the DC gain of {sys!r} is {dc:g}: its step does not settle to a nonzero "
                                        "value; give yfinal")
            final = dc
        else:
            final = check_real("yfinal", yfinal)
        if T is None:
            T = np.linspace(0.0, default_horizon(sys), _POINTS)
        elif np.ndim(T) == 0:
            T = np.linspace(0.0, check_real("T (horizon, s)", T, minimum=0.0, strict=True), _POINTS)
        r = step_response(sys, T)
    else:
        raise InvalidTypeError(f"step_info takes a DelayLTI, a Loop or a step response, got {type(sys).__name__}")
    if r.outputs.shape[:2] != (1, 1):
        raise InvalidValueError(f"step_info needs one input and one output, got a response of shape "
                                f"{r.outputs.shape[:2]}")
    if r.status != "exact":
        raise InvalidValueError(f"the step response stopped early ({r.status} at t = {r.t_reached:g} s); give a "
                                "shorter horizon T")
    return step_metrics(r.time, r.outputs[0, 0], step=1.0, z0=0.0, final=final, band=band)
