"""Design: choose gains for a loop whose delay is known (or has been identified).

:mod:`.tuning` sweeps candidate gains and ranks them by spectral abscissa, settling time or overshoot, searches
gain maps, and analyses the derivative filter of the PV loop. It builds on the simulate and spectrum layers.
"""

from .tuning import (CRITERIA, Design, DesignRow, FilterReport, GainMap, design_sweep, filter_analysis, gain_search,
                     parse_range)

__all__ = ["DesignRow", "Design", "GainMap", "FilterReport", "design_sweep", "gain_search", "filter_analysis",
           "CRITERIA", "parse_range"]
