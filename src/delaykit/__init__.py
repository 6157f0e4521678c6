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

import os
import sys
import types
from typing import Any

from ._lazy import lazy_exports
from .errors import (DelaykitError, DelaykitWarning, FlightError, FlightInterruptedError, InvalidTypeError, InvalidValueError, MissingDependencyError,
                     OutputError, PortError, PortNumberError, RangeSpecError)

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
    "OutputError",
    "FlightError", "FlightInterruptedError", "MissingDependencyError", "ProtocolError", "ATError", "NavdataError", "LinkError", "VehicleRefusedError", "EstimationError", "LogError",
    "IdentificationError",
    # identification
    "Experiment", "read_experiment", "identify", "predict", "load_model", "IdentifiedModel", "fit_system", "SystemFit",
    # delay compensation and delays that vary
    "Compensator", "design_compensator", "delay_ratio_range", "simulate_varying", "monte_carlo", "DelayDistribution",
    "DelaySchedule",
    "Jitter", "Burst", "DelayTrace", "jitter_margin", "stable_for",
    # delay systems as objects
    "DelayLTI", "tf", "ss", "exp", "LaplaceExpression", "delay", "feedback", "append", "interconnect", "summing_junction", "from_loop", "plant_of", "to_loop", "c2d", "saturation", "load_system",
    "pade", "thiran", "absorb_delay", "zeros", "is_minimum_phase",
    "series", "parallel",
    "poles", "is_stable", "hinfnorm", "nyquist_count", "loop_margins",
    "root_locus", "RootLocus", "LocusCrossing",
    "step_response", "impulse_response", "initial_response", "forced_response", "SystemTimeResponse", "step_info",
    "step_response_many", "BatchTimeResponse",
    # PID tuning
    "tune", "assess", "Tuning", "TuningWarning", "DelaykitWarning", "relay_cycle", "StaleExtensionWarning", "SlowKernelWarning",
    # decentralised PI for square delay systems: pairing and BLT tuning
    "blt", "BLTResult", "rga", "niederlinski",
    "relay_ultimate", "measure_cycle",
]
__version__ = "0.1.0"

_LAZY = {
    "PAPER_PERIOD": ".models.altitude", "AltitudeLoop": ".models.altitude", "Controller": ".models.controllers",
    "Loop": ".models.loop", "load_loop": ".models.loop", "QuasiPolynomial": ".models.quasipolynomial",
    "Step": ".models.signals", "Ramp": ".models.signals", "Samples": ".models.signals", "LoadStep": ".models.signals",
    "TransferFunction": ".models.transfer", "SecondOrder": ".simulate.metrics", "StepMetrics": ".simulate.metrics",
    "noise_level": ".simulate.metrics", "step_metrics": ".simulate.metrics", "BatchMetrics": ".simulate.simulation",
    "Response": ".simulate.simulation", "simulate": ".simulate.simulation", "simulate_many": ".simulate.simulation", "RootStatus": ".spectrum.roots",
    "frequency_response": ".spectrum.frequency", "frequency_grid": ".spectrum.frequency",
    "margins": ".spectrum.frequency", "FrequencyResponse": ".spectrum.frequency", "Margins": ".spectrum.frequency",
    "Crossover": ".spectrum.frequency", "to_control": ".models.interop", "pade_error": ".systems.pade",
    "PadeError": ".models.interop",
    "sampled_spectrum": ".spectrum.sampled", "sampled_margins": ".spectrum.sampled",
    "compare_sampling": ".spectrum.sampled", "sampled_frequency_response": ".spectrum.sampled",
    # exception classes defined beside the code that raises them (also re-exported by delaykit.errors)
    "ProtocolError": ".hardware.ardrone", "ATError": ".hardware.ardrone", "NavdataError": ".hardware.ardrone",
    "LinkError": ".hardware.link", "VehicleRefusedError": ".hardware.link", "EstimationError": ".identify.estimation", "LogError": ".identify.flightlog",
    "IdentificationError": ".identify.identification",
    "Experiment": ".identify.iodata", "read_experiment": ".identify.iodata", "identify": ".identify.identification",
    "predict": ".identify.identification", "load_model": ".identify.identification",
    "IdentifiedModel": ".identify.identification",
    "fit_system": ".identify.system_fit", "SystemFit": ".identify.system_fit",
    "Compensator": ".models.compensators", "design_compensator": ".design.compensators",
    "delay_ratio_range": ".design.compensators", "simulate_varying": ".simulate.varying",
    "monte_carlo": ".simulate.montecarlo", "DelayDistribution": ".simulate.montecarlo",
    "DelaySchedule": ".simulate.varying", "Jitter": ".simulate.varying",
    "Burst": ".simulate.varying", "DelayTrace": ".simulate.varying", "jitter_margin": ".spectrum.jitter",
    "stable_for": ".spectrum.jitter",
    "DelayLTI": ".systems.lti", "tf": ".systems.build", "exp": ".systems.laplace",
    "LaplaceExpression": ".systems.laplace", "ss": ".systems.build", "delay": ".systems.build",
    "feedback": ".systems.algebra", "append": ".systems.algebra", "interconnect": ".systems.algebra",
    "summing_junction": ".systems.algebra", "series": ".systems.algebra", "parallel": ".systems.algebra",
    "from_loop": ".systems.build", "plant_of": ".systems.build", "to_loop": ".systems.build", "c2d": ".systems.discrete",
    "pade": ".systems.pade", "thiran": ".systems.discrete", "absorb_delay": ".systems.discrete",
    "zeros": ".spectrum.systems", "is_minimum_phase": ".spectrum.systems",
    "saturation": ".systems.build", "load_system": ".systems.files",
    "poles": ".spectrum.systems",
    "root_locus": ".spectrum.locus", "RootLocus": ".spectrum.locus", "LocusCrossing": ".spectrum.locus",
    "is_stable": ".spectrum.systems", "hinfnorm": ".spectrum.systems", "nyquist_count": ".spectrum.systems",
    "loop_margins": ".spectrum.systems",
    "step_response": ".simulate.systems", "impulse_response": ".simulate.systems",
    "initial_response": ".simulate.systems", "forced_response": ".simulate.systems",
    "SystemTimeResponse": ".simulate.systems", "step_response_many": ".simulate.systems",
    "BatchTimeResponse": ".simulate.systems", "step_info": ".simulate.step_info",
    "StaleExtensionWarning": "._native", "SlowKernelWarning": "._native", "tune": ".design.pid", "assess": ".design.pid", "relay_cycle": ".design.relay", "Tuning": ".design.pid", "TuningWarning": ".design.pid_rules",
    "blt": ".design.mimo", "BLTResult": ".design.mimo", "rga": ".design.mimo", "niederlinski": ".design.mimo",
    "relay_ultimate": ".design.autotune", "measure_cycle": ".design.autotune",
}


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals())


class _Export:
    """A package attribute that stays the exported function though a subpackage shares its name.

    Importing a subpackage (``delaykit.identify``, say, to reach ``read_experiment``) makes Python bind it as the
    package's attribute of the same name; this data descriptor on the package's type outranks that binding, so
    ``delaykit.identify`` and ``from delaykit import identify`` give the function whatever was imported before
    (the subpackage stays importable by its full name, ``from delaykit.identify.iodata import ...``).  A value
    that is not a module (a test's monkeypatch) is kept.
    """

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, objtype: Any = None) -> Any:
        if obj is None:
            return self
        value = obj.__dict__.get(self.name)
        return __getattr__(self.name) if value is None or isinstance(value, types.ModuleType) else value

    def __set__(self, obj: Any, value: Any) -> None:
        if not isinstance(value, types.ModuleType):  # the import system binding the subpackage: ignored
            obj.__dict__[self.name] = value

    def __delete__(self, obj: Any) -> None:
        obj.__dict__.pop(self.name, None)


_SHARED = tuple(name for name in _LAZY if os.path.isdir(os.path.join(os.path.dirname(__file__), name)))
"""Exported names that are also subpackages' names (``simulate``, ``identify``)."""

_Package = type("_Package", (types.ModuleType,), {
    "__doc__": "The package's module type: each name of :data:`_SHARED` is the exported function (:class:`_Export`).",
    **{name: _Export() for name in _SHARED}})

sys.modules[__name__].__class__ = _Package
