"""Identify: from measured data back to a model.

:mod:`.flightlog` reads, checks and writes flight logs (and makes synthetic ones), and :mod:`.estimation` estimates
the paper's loop delay from them: from the overshoot, with the paper's Lambert-W iteration, or by fitting the whole
trajectory.  :mod:`.iodata` reads any log (input or reference, outputs), :mod:`.structures` names the plant families,
:mod:`.identify.identification` fits them open or closed loop with honest errors and chooses among them, :mod:`.noise` models
coloured residuals, :mod:`.experiment` predicts the errors of a planned test, and :mod:`.online` re-estimates the
delay on a window of a flight from the commands sent (whatever the controller); :mod:`.vehiclelogs` reads PX4,
ArduPilot and MAVLink flight logs, :mod:`.logalign` puts their signals on one clock, and :mod:`.steps` cuts a log of
several reference steps into one log per step.  It uses the models, simulations
and spectra of the layers below.

Note that ``delaykit.identify`` as an attribute of the package root is the :func:`identify` function; import this
layer's modules by their full names, ``from delaykit.identify.iodata import ...`` or
``from delaykit.identify import iodata``.

The names are imported on first use: ``from delaykit.identify.identification import identify`` (what the command
line does) loads the fits only, not the flight-log estimators of :mod:`.estimation` and :mod:`.online` nor the
SciPy they need.

Examples
--------
>>> from delaykit.identify import Experiment, estimate_window
>>> Experiment.__module__, estimate_window.__module__
('delaykit.identify.iodata', 'delaykit.identify.online')
"""

from .._lazy import by_module, lazy_exports

_SOURCES = {
    "estimation": ["DelayEstimate", "EstimationError", "estimate_flights", "estimate_lambert", "estimate_overshoot",
                   "estimate_trajectory", "fitted_altitude", "lambert_paper_iterations"],
    "experiment": ["SIGNALS", "ExpectedErrors", "expected_errors", "planned_signal"],
    "flightlog": ["REQUIRED", "FlightLog", "LogError", "synthetic_log", "write_log"],
    "identification": ["Candidate", "IdentificationError", "IdentifiedModel", "LogFit", "Prediction", "identify",
                       "load_model", "predict", "simulate_experiment"],
    "iodata": ["Experiment", "read_experiment"],
    "noise": ["ARNoise", "VARNoise", "fit_ar", "fit_var", "ljung_box"],
    "online": ["WindowEstimate", "estimate_window"],
    "structures": ["STRUCTURES", "Structure", "structure"],
    "system_fit": ["SystemFit", "SystemLogFit", "fit_system", "simulate_log"],
    "logalign": ["read_log_experiment", "read_log_flight"],
    "steps": ["find_steps", "split_steps"],
    "vehiclelogs": ["LogListing", "list_log", "read_signals"],
}

__all__ = [
    "FlightLog", "LogError", "REQUIRED", "write_log", "synthetic_log",
    "DelayEstimate", "EstimationError", "estimate_overshoot", "estimate_lambert", "estimate_trajectory",
    "estimate_flights", "fitted_altitude", "lambert_paper_iterations",
    "Experiment", "read_experiment", "Structure", "STRUCTURES", "structure",
    "IdentifiedModel", "Candidate", "LogFit", "Prediction", "IdentificationError", "identify", "predict",
    "simulate_experiment", "load_model", "ARNoise", "VARNoise", "fit_ar", "fit_var", "ljung_box",
    "ExpectedErrors", "expected_errors", "planned_signal", "SIGNALS", "WindowEstimate", "estimate_window",
    "SystemFit", "SystemLogFit", "fit_system", "simulate_log",
    "LogListing", "list_log", "read_log_experiment", "read_log_flight", "read_signals", "find_steps", "split_steps",
]


__getattr__, __dir__ = lazy_exports(__name__, by_module(_SOURCES), globals())
