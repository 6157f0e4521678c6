"""Simulate: a model's step response in the time domain, exactly, and the metrics read off it.

:mod:`.simulation` integrates any :class:`~delaykit.models.Loop` (or the paper's :class:`~delaykit.models.AltitudeLoop`) by the method of steps (the compiled
kernel is the private :mod:`._kernel`), one loop or a batch of them; :mod:`.varying` simulates a sampled loop whose
delay varies packet by packet (schedules, jitter, bursts, recorded traces); :mod:`.metrics` measures a step response
(overshoot, peak, rise and settling times, a fitted second-order model, noise level). This layer reads models only;
it is a peer of :mod:`delaykit.spectrum` and neither imports the other.

Note that ``delaykit.simulate`` as an attribute of the package root is the :func:`simulate` function (kept for
compatibility); import this layer's modules by their full names, ``from delaykit.simulate.simulation import ...``.
"""

from .metrics import SecondOrder, StepMetrics, noise_level, step_metrics
from .simulation import SWEEPABLE, BatchMetrics, Response, Sampler, as_loop, simulate, simulate_many
from .montecarlo import DelayDistribution, MonteCarlo, monte_carlo
from .varying import (Burst, CombinedDelay, DelayModel, DelaySchedule, DelayTrace, Jitter, VaryingResponse,
                      arrival_plan, as_delay_model, simulate_varying)

__all__ = [
    "StepMetrics", "SecondOrder", "step_metrics", "noise_level",
    "Response", "BatchMetrics", "Sampler", "simulate", "simulate_many", "as_loop", "SWEEPABLE",
    "DelayModel", "DelaySchedule", "Jitter", "Burst", "DelayTrace", "CombinedDelay", "as_delay_model", "arrival_plan",
    "VaryingResponse", "simulate_varying", "MonteCarlo", "monte_carlo", "DelayDistribution",
]
