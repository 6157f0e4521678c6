"""Spectrum: a model in the frequency domain, its characteristic roots and what they say about stability.

:mod:`.lambert` gives the roots of first-order loops in closed form with Lambert W, :mod:`.roots` finds every root
of a retarded or neutral quasi-polynomial in a rectangle (the compiled inner loops are the private
:mod:`._rootkernel`), :mod:`.stability` turns roots into the rightmost root, delay margins and stability maps,
:mod:`.frequency` gives the exact frequency response and the gain, phase and delay margins of continuous loops, and
:mod:`.sampled` gives the exact discrete-time model and poles of loops with a sampled (zero-order hold) controller
and :mod:`.discrete_margins` their frequency response and margins, and
:mod:`.jitter` the jitter margin: stability for a delay that varies arbitrarily fast within bounds.
This layer reads models only; it is a peer of :mod:`delaykit.simulate` and neither imports the other.
"""

from .frequency import Crossover, FrequencyResponse, Margins, frequency_grid, frequency_response, margins
from .jitter import JitterMargin, jitter_bound, jitter_margin, stable_for
from .lambert import (LambertRoots, complex_delays_for_root, delay_for_damping, dominant_root, kp_delay_for_damping,
                      lambert_roots, lambert_w)
from .roots import RootStatus, Spectrum, find_roots, neutral_lines, root_bound
from .sampled import (SampledCrossover, SampledMargins, SampledModel, SampledSpectrum, SamplingComparison,
                      compare_sampling, sampled_frequency_response, sampled_margins, sampled_model, sampled_spectrum)
from .stability import DelayMargin, Rightmost, StabilityMap, delay_margin, rightmost, stability_map

__all__ = [
    "LambertRoots", "lambert_w", "lambert_roots", "dominant_root", "kp_delay_for_damping", "delay_for_damping",
    "complex_delays_for_root",
    "RootStatus", "Spectrum", "find_roots", "neutral_lines", "root_bound",
    "Rightmost", "DelayMargin", "StabilityMap", "rightmost", "delay_margin", "stability_map",
    "SampledModel", "SampledSpectrum", "SampledCrossover", "SampledMargins", "SamplingComparison", "sampled_model",
    "sampled_spectrum", "sampled_frequency_response", "sampled_margins", "compare_sampling",
    "FrequencyResponse", "Margins", "Crossover", "frequency_response", "frequency_grid", "margins",
    "JitterMargin", "jitter_margin", "stable_for", "jitter_bound",
]
