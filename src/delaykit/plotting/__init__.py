"""Plotting: figures of what the lower layers compute (responses, spectra, stability maps, fits, filter Bode plots,
frequency responses, identified models' predictions).

Every function draws on given axes (or a new figure), returns the figure and writes a PNG, PDF or SVG file only
when given a path; nothing switches matplotlib's backend. :mod:`.figures` holds the paper's figures,
:mod:`.frequency` Bode and Nyquist plots, :mod:`.locus` root loci, :mod:`.identification` measured logs beside a
model's predictions, :mod:`.systems` a delay system's step responses, :mod:`.lti` plots of any system (Bode,
Nyquist, singular values, Nichols, a step-response grid, a pole map).
Importing this package imports matplotlib, which is why nothing below it (models to hardware) imports it: only the
paper layer and the command line do, and the command line only when a figure is asked for.
"""

from .compensation import plot_online, plot_robustness_map
from .figures import plot_filter_bode, plot_fit, plot_responses, plot_spectrum, plot_stability_map, plot_z_spectrum
from .frequency import plot_bode, plot_nyquist
from .identification import plot_predictions
from .locus import plot_root_locus
from .lti import bode_plot, nichols_plot, nyquist_plot, pole_map, sigma_plot, step_grid
from .systems import plot_system_response

__all__ = ["plot_responses", "plot_spectrum", "plot_z_spectrum", "plot_stability_map", "plot_fit", "plot_filter_bode",
           "plot_bode", "plot_nyquist", "plot_predictions", "plot_robustness_map", "plot_online",
           "plot_system_response", "plot_root_locus", "bode_plot", "nyquist_plot", "sigma_plot", "nichols_plot",
           "step_grid", "pole_map"]
