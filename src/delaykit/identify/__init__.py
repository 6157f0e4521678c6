"""Identify: from flight data back to a model, i.e. estimate the loop's delay.

:mod:`.flightlog` reads, checks and writes flight logs (and makes synthetic ones), and :mod:`.estimation` estimates
the delay from them: from the overshoot, with the paper's Lambert-W iteration, or by fitting the whole trajectory,
with uncertainty and a model-adequacy check. It uses the models, simulations and spectra of the layers below.
"""

from .estimation import (DelayEstimate, EstimationError, estimate_flights, estimate_lambert, estimate_overshoot,
                         estimate_trajectory, fitted_altitude, lambert_paper_iterations)
from .flightlog import REQUIRED, FlightLog, LogError, synthetic_log, write_log

__all__ = [
    "FlightLog", "LogError", "REQUIRED", "write_log", "synthetic_log",
    "DelayEstimate", "EstimationError", "estimate_overshoot", "estimate_lambert", "estimate_trajectory",
    "estimate_flights", "fitted_altitude", "lambert_paper_iterations",
]
