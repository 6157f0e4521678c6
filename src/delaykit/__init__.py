"""delaykit: feedback loops with a time delay, after Armah & Yi's quadrotor altitude loop.

The package's names are imported on first use, so that ``import delaykit`` (and the command line) start
fast: numba, scipy and matplotlib load only when something needs them.

Examples
--------
>>> import delaykit
>>> delaykit.simulate(delaykit.AltitudeLoop(kp=1.31, delay=0.368)).metrics.overshoot > 2.26
True
"""

from __future__ import annotations

import sys
import types
from typing import Any

from ._lazy import lazy_exports
from .errors import (DelaykitError, DelaykitWarning, FlightError, InvalidTypeError, InvalidValueError, MissingDependencyError,
                     PortError, PortNumberError, RangeSpecError)

__all__ = [
    "AltitudeLoop", "Loop", "Controller", "TransferFunction", "Step", "Ramp", "Samples", "LoadStep", "load_loop",
    "BatchMetrics", "PAPER_PERIOD",
    "QuasiPolynomial", "Response", "SecondOrder", "StepMetrics", "noise_level", "simulate", "simulate_many",
    "step_metrics", "RootStatus",
    "frequency_response", "frequency_grid", "margins", "FrequencyResponse", "Margins", "Crossover", "to_control",
    "pade_error", "PadeError",
    "sampled_spectrum", "sampled_margins", "compare_sampling", "sampled_frequency_response",
    # every exception class of the package (all derive from DelaykitError)
    "DelaykitError", "InvalidTypeError", "InvalidValueError", "RangeSpecError", "PortError", "PortNumberError",
    "FlightError", "MissingDependencyError", "ProtocolError", "ATError", "NavdataError", "LinkError", "EstimationError", "LogError",
    "IdentificationError",
    # identification
    "Experiment", "read_experiment", "identify", "predict", "load_model", "IdentifiedModel",
    # delay compensation and delays that vary
    "Compensator", "design_compensator", "delay_ratio_range", "simulate_varying", "monte_carlo", "DelayDistribution",
    "DelaySchedule",
    "Jitter", "Burst", "DelayTrace", "jitter_margin", "stable_for",
    # PID tuning
    "tune", "assess", "Tuning", "TuningWarning", "DelaykitWarning", "relay_cycle",
    "relay_ultimate", "measure_cycle",
]
__version__ = "0.1.0"

_LAZY = {
    "PAPER_PERIOD": ".models.altitude", "AltitudeLoop": ".models.altitude", "Controller": ".models.controllers",
    "Loop": ".models.loop", "load_loop": ".models.loop", "QuasiPolynomial": ".models.quasipolynomial",
    "Step": ".models.signals", "Ramp": ".models.signals", "Samples": ".models.signals", "LoadStep": ".models.signals",
    "TransferFunction": ".models.transfer", "SecondOrder": ".simulate.metrics", "StepMetrics": ".simulate.metrics",
    "noise_level": ".simulate.metrics", "step_metrics": ".simulate.metrics", "BatchMetrics": ".simulate.simulation",
    "Response": ".simulate.simulation", "simulate_many": ".simulate.simulation", "RootStatus": ".spectrum.roots",
    "frequency_response": ".spectrum.frequency", "frequency_grid": ".spectrum.frequency",
    "margins": ".spectrum.frequency", "FrequencyResponse": ".spectrum.frequency", "Margins": ".spectrum.frequency",
    "Crossover": ".spectrum.frequency", "to_control": ".models.interop", "pade_error": ".models.interop",
    "PadeError": ".models.interop",
    "sampled_spectrum": ".spectrum.sampled", "sampled_margins": ".spectrum.sampled",
    "compare_sampling": ".spectrum.sampled", "sampled_frequency_response": ".spectrum.sampled",
    # exception classes defined beside the code that raises them (also re-exported by delaykit.errors)
    "ProtocolError": ".hardware.ardrone", "ATError": ".hardware.ardrone", "NavdataError": ".hardware.ardrone",
    "LinkError": ".hardware.flight", "EstimationError": ".identify.estimation", "LogError": ".identify.flightlog",
    "IdentificationError": ".identify.identification",
    "Experiment": ".identify.iodata", "read_experiment": ".identify.iodata", "identify": ".identify.identification",
    "predict": ".identify.identification", "load_model": ".identify.identification",
    "IdentifiedModel": ".identify.identification",
    "Compensator": ".models.compensators", "design_compensator": ".design.compensators",
    "delay_ratio_range": ".design.compensators", "simulate_varying": ".simulate.varying",
    "monte_carlo": ".simulate.montecarlo", "DelayDistribution": ".simulate.montecarlo",
    "DelaySchedule": ".simulate.varying", "Jitter": ".simulate.varying",
    "Burst": ".simulate.varying", "DelayTrace": ".simulate.varying", "jitter_margin": ".spectrum.jitter",
    "stable_for": ".spectrum.jitter",
    "tune": ".design.pid", "assess": ".design.pid", "relay_cycle": ".design.relay", "Tuning": ".design.pid", "TuningWarning": ".design.pid_rules",
    "relay_ultimate": ".design.autotune", "measure_cycle": ".design.autotune",
}


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals())


class _Package(types.ModuleType):
    """The package's module type: ``delaykit.simulate`` is the function, though a subpackage shares its name.

    Importing the subpackage :mod:`delaykit.simulate` makes Python bind it as the package's attribute
    ``simulate``; this property keeps that name the function (the subpackage stays importable by its
    full name, ``from delaykit.simulate.simulation import ...``).
    """

    @property
    def simulate(self) -> Any:
        from .simulate.simulation import simulate

        return simulate

    @simulate.setter
    def simulate(self, value: Any) -> None:
        pass  # the import system binding the subpackage: the name stays the function


sys.modules[__name__].__class__ = _Package
