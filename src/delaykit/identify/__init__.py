"""Identify: from measured data back to a model.

:mod:`.flightlog` reads, checks and writes flight logs (and makes synthetic ones), and :mod:`.estimation` estimates
the paper's loop delay from them: from the overshoot, with the paper's Lambert-W iteration, or by fitting the whole
trajectory.  :mod:`.iodata` reads any log (input or reference, outputs), :mod:`.structures` names the plant families,
:mod:`.identify.identification` fits them open or closed loop with honest errors and chooses among them, :mod:`.noise` models
coloured residuals, :mod:`.experiment` predicts the errors of a planned test, and :mod:`.online` re-estimates the
delay on a window of a flight from the commands sent (whatever the controller).  It uses the models, simulations
and spectra of the layers below.

Note that ``delaykit.identify`` as an attribute of the package root is the :func:`identify` function; import this
layer's modules by their full names, ``from delaykit.identify.iodata import ...`` or
``from delaykit.identify import iodata``.
"""

from .estimation import (DelayEstimate, EstimationError, estimate_flights, estimate_lambert, estimate_overshoot,
                         estimate_trajectory, fitted_altitude, lambert_paper_iterations)
from .experiment import SIGNALS, ExpectedErrors, expected_errors, planned_signal
from .flightlog import REQUIRED, FlightLog, LogError, synthetic_log, write_log
from .identification import (Candidate, IdentificationError, IdentifiedModel, LogFit, Prediction, identify, load_model,
                             predict, simulate_experiment)
from .iodata import Experiment, read_experiment
from .noise import ARNoise, VARNoise, fit_ar, fit_var, ljung_box
from .online import WindowEstimate, estimate_window
from .structures import STRUCTURES, Structure, structure
from .system_fit import SystemFit, SystemLogFit, fit_system, simulate_log

__all__ = [
    "FlightLog", "LogError", "REQUIRED", "write_log", "synthetic_log",
    "DelayEstimate", "EstimationError", "estimate_overshoot", "estimate_lambert", "estimate_trajectory",
    "estimate_flights", "fitted_altitude", "lambert_paper_iterations",
    "Experiment", "read_experiment", "Structure", "STRUCTURES", "structure",
    "IdentifiedModel", "Candidate", "LogFit", "Prediction", "IdentificationError", "identify", "predict",
    "simulate_experiment", "load_model", "ARNoise", "VARNoise", "fit_ar", "fit_var", "ljung_box",
    "ExpectedErrors", "expected_errors", "planned_signal", "SIGNALS", "WindowEstimate", "estimate_window",
    "SystemFit", "SystemLogFit", "fit_system", "simulate_log",
]
