"""Design: choose gains for a loop whose delay is known (or has been identified).

:mod:`.compensators` designs delay compensators (Smith, filtered Smith, predictor feedback) and maps how much
model error they survive; :mod:`.tuning` sweeps candidate gains and ranks them by spectral abscissa, settling time or overshoot, searches
gain maps, and analyses the derivative filter of the PV loop. It builds on the simulate and spectrum layers.
"""

from .compensators import (CompensatorDesign, DisturbanceRecovery, RobustnessMap, compare_designs, delay_ratio_range,
                           design_compensator, disturbance_recovery, minimum_settling_time, robustness_map,
                           tune_compensator)
from .tuning import (CRITERIA, Design, DesignRow, FilterReport, GainMap, design_sweep, filter_analysis, gain_search,
                     parse_range)

__all__ = ["CompensatorDesign", "DisturbanceRecovery", "RobustnessMap", "compare_designs", "delay_ratio_range",
           "design_compensator", "disturbance_recovery", "minimum_settling_time", "robustness_map", "tune_compensator",
           "DesignRow", "Design", "GainMap", "FilterReport", "design_sweep", "gain_search", "filter_analysis",
           "CRITERIA", "parse_range"]
