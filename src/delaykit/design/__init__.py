"""Design: choose gains for a loop whose delay is known (or has been identified).

:mod:`.compensators` designs delay compensators (Smith, filtered Smith, predictor feedback) and maps how much
model error they survive; :mod:`.tuning` sweeps candidate gains and ranks them by spectral abscissa, settling time or overshoot, searches
gain maps, and analyses the derivative filter of the PV loop; :mod:`.pid` tunes P, PI, PD, PID and PV controllers by rules
(:mod:`.pid_rules`) or optimisation (:mod:`.pid_optimise`); :mod:`.relay` solves relay feedback's limit cycle exactly, and :mod:`.autotune` finds the ultimate point from a measured one. It builds on the simulate and spectrum layers.
"""

from .compensators import (CompensatorDesign, DisturbanceRecovery, RobustnessMap, compare_designs, delay_ratio_range,
                           design_compensator, disturbance_recovery, minimum_settling_time, robustness_map,
                           tune_compensator)
from .pid import LoadReport, RobustPoint, SetpointReport, Tuning, tune
from .pid_rules import ReducedModel, RuleGains, TuningWarning, UltimatePoint, reduce_model, rule_gains, ultimate_point
from .autotune import MeasuredCycle, RelayUltimate, measure_cycle, relay_ultimate
from .relay import RelayCycle, relay_cycle
from .tuning import (CRITERIA, Design, DesignRow, FilterReport, GainMap, design_sweep, filter_analysis, gain_search,
                     parse_range)

__all__ = ["CompensatorDesign", "DisturbanceRecovery", "RobustnessMap", "compare_designs", "delay_ratio_range",
           "design_compensator", "disturbance_recovery", "minimum_settling_time", "robustness_map", "tune_compensator",
           "DesignRow", "Design", "GainMap", "FilterReport", "design_sweep", "gain_search", "filter_analysis",
           "CRITERIA", "parse_range", "tune", "Tuning", "SetpointReport", "LoadReport", "RobustPoint", "TuningWarning",
           "ReducedModel", "RuleGains", "UltimatePoint", "reduce_model", "rule_gains", "ultimate_point", "RelayCycle", "relay_cycle",
           "MeasuredCycle", "RelayUltimate", "measure_cycle", "relay_ultimate"]
