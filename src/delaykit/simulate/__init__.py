"""Simulate: a model's step response in the time domain, exactly, and the metrics read off it.

:mod:`.simulation` integrates any :class:`~delaykit.models.Loop` (or the paper's :class:`~delaykit.models.AltitudeLoop`) by the method of steps (the compiled
kernel is the private :mod:`._kernel`), one loop or a batch of them; :mod:`.varying` simulates a sampled loop whose
delay varies packet by packet (schedules, jitter, bursts, recorded traces); :mod:`.metrics` measures a step response
(overshoot, peak, rise and settling times, a fitted second-order model, noise level); :mod:`.systems` gives the exact
step, impulse, initial and forced responses of a :class:`~delaykit.systems.DelayLTI` (kernel :mod:`._ltikernel`) and
:mod:`.step_info` python-control's ``step_info`` of any SISO system. This layer reads models only;
it is a peer of :mod:`delaykit.spectrum` and neither imports the other.

The names are imported on first use: ``from delaykit.simulate.simulation import simulate`` (what the command line
does) loads the continuous kernel only, not the sampled and varying-delay kernels of :mod:`.varying` and
:mod:`.discrete` nor SciPy, which they need.

Note that ``delaykit.simulate`` as an attribute of the package root is the :func:`simulate` function (kept for
compatibility); import this layer's modules by their full names, ``from delaykit.simulate.simulation import ...``.

Examples
--------
>>> from delaykit.simulate import StepMetrics, simulate_varying
>>> StepMetrics.__module__, simulate_varying.__module__
('delaykit.simulate.metrics', 'delaykit.simulate.varying')
"""

from .._lazy import by_module, lazy_exports

_SOURCES = {
    "metrics": ["StepMetrics", "SecondOrder", "step_metrics", "noise_level", "OVERSHOOT_TOLERANCE", "peak_time_of",
                "load_recovery"],
    "simulation": ["Response", "BatchMetrics", "Sampler", "simulate", "simulate_many", "as_loop", "SWEEPABLE"],
    "varying": ["DelayModel", "DelaySchedule", "Jitter", "Burst", "DelayTrace", "CombinedDelay", "as_delay_model",
                "arrival_plan", "VaryingResponse", "simulate_varying"],
    "montecarlo": ["MonteCarlo", "monte_carlo", "DelayDistribution"],
    "systems": ["SystemTimeResponse", "step_response", "impulse_response", "initial_response", "forced_response",
                "step_response_many", "BatchTimeResponse"],
    "step_info": ["step_info"],
}

__all__ = [
    "StepMetrics", "SecondOrder", "step_metrics", "noise_level", "OVERSHOOT_TOLERANCE", "peak_time_of", "load_recovery",
    "Response", "BatchMetrics", "Sampler", "simulate", "simulate_many", "as_loop", "SWEEPABLE",
    "DelayModel", "DelaySchedule", "Jitter", "Burst", "DelayTrace", "CombinedDelay", "as_delay_model", "arrival_plan",
    "VaryingResponse", "simulate_varying", "MonteCarlo", "monte_carlo", "DelayDistribution",
    "SystemTimeResponse", "step_response", "impulse_response", "initial_response", "forced_response",
    "step_response_many", "BatchTimeResponse", "step_info",
]


__getattr__, __dir__ = lazy_exports(__name__, by_module(_SOURCES), globals())
