"""delaykit: feedback loops with a time delay, after Armah & Yi's quadrotor altitude loop.

Examples
--------
>>> import delaykit
>>> delaykit.simulate(delaykit.AltitudeLoop(kp=1.31, delay=0.368)).metrics.overshoot > 2.26
True
"""

from .errors import DelaykitError, InvalidTypeError, InvalidValueError
from .models.altitude import PAPER_PERIOD, AltitudeLoop
from .models.quasipolynomial import QuasiPolynomial
from .simulate.metrics import SecondOrder, StepMetrics, noise_level, step_metrics
from .simulate.simulation import BatchMetrics, Response, simulate, simulate_many

__all__ = [
    "AltitudeLoop", "BatchMetrics", "DelaykitError", "InvalidTypeError", "InvalidValueError", "PAPER_PERIOD",
    "QuasiPolynomial", "Response", "SecondOrder", "StepMetrics", "noise_level", "simulate", "simulate_many",
    "step_metrics",
]
__version__ = "0.1.0"
