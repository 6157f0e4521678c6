"""Plotting: figures of what the lower layers compute (responses, spectra, stability maps, fits, filter Bode plots).

:mod:`.figures` draws with matplotlib (Agg backend) and writes PNG, PDF or SVG files. Importing this package
imports matplotlib, which is why nothing below it (models to hardware) imports it: only the paper layer and the
command line do, and the command line only when a figure is asked for.
"""

from .figures import plot_filter_bode, plot_fit, plot_responses, plot_spectrum, plot_stability_map

__all__ = ["plot_responses", "plot_spectrum", "plot_stability_map", "plot_fit", "plot_filter_bode"]
