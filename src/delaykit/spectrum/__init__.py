"""Spectrum: a model in the frequency domain, its characteristic roots and what they say about stability.

:mod:`.lambert` gives the roots of first-order loops in closed form with Lambert W, :mod:`.roots` finds every root
of a retarded or neutral quasi-polynomial in a rectangle (the compiled inner loops are the private
:mod:`._rootkernel`), :mod:`.locus` follows them as a loop's gain or delay moves (the root locus), :mod:`.stability` turns roots into the rightmost root, delay margins and stability maps,
:mod:`.frequency` gives the exact frequency response and the gain, phase and delay margins of continuous loops
(and, through :mod:`.system_margins`, of open loops given as delay systems), and
:mod:`.sampled` gives the exact discrete-time model and poles of loops with a sampled (zero-order hold) controller
and :mod:`.discrete_margins` their frequency response and margins, and
:mod:`.jitter` the jitter margin: stability for a delay that varies arbitrarily fast within bounds.
:mod:`.neutral` bounds the spectrum of a neutral quasi-polynomial's difference operator, and
:mod:`.systems` gives the poles, stability, H-infinity norm, Nyquist count and loop-at-a-time margins of the
delay systems of :mod:`delaykit.systems`.
This layer reads models and systems only; it is a peer of :mod:`delaykit.simulate` and neither imports the other.

The names are imported on first use (as in :mod:`delaykit.simulate`): ``from delaykit.spectrum import margins``
loads the frequency-domain modules, not the sampled-loop ones nor the root finder's compiled kernels until a
margin needs them.
"""

from .._lazy import by_module, lazy_exports

_SOURCES = {
    "lambert": ["LambertRoots", "lambert_w", "lambert_roots", "dominant_root", "kp_delay_for_damping",
                "delay_for_damping", "complex_delays_for_root"],
    "roots": ["RootStatus", "Spectrum", "find_roots", "neutral_lines", "root_bound"],
    "locus": ["RootLocus", "LocusCrossing", "root_locus"],
    "stability": ["Rightmost", "DelayMargin", "StabilityMap", "rightmost", "delay_margin", "stability_map"],
    "sampled": ["SampledModel", "SampledSpectrum", "sampled_model", "sampled_spectrum", "sampled_frequency_response"],
    "discrete_margins": ["SampledCrossover", "SampledMargins", "SamplingComparison", "sampled_margins",
                         "compare_sampling"],
    "frequency": ["FrequencyResponse", "Margins", "Crossover", "frequency_response", "frequency_grid", "margins"],
    "jitter": ["JitterMargin", "jitter_margin", "stable_for", "jitter_bound"],
    "neutral": ["NeutralAbscissa", "neutral_abscissa", "polygon_abscissa", "ChannelAbscissa", "channel_abscissa"],
    "systems": ["poles", "neutral_spectrum", "is_stable", "hinfnorm", "HinfNorm", "nyquist_count", "NyquistCount", "loop_margins",
                "LoopMargins"],
}

__all__ = [
    "LambertRoots", "lambert_w", "lambert_roots", "dominant_root", "kp_delay_for_damping", "delay_for_damping",
    "complex_delays_for_root",
    "RootStatus", "Spectrum", "find_roots", "neutral_lines", "root_bound",
    "RootLocus", "LocusCrossing", "root_locus",
    "Rightmost", "DelayMargin", "StabilityMap", "rightmost", "delay_margin", "stability_map",
    "SampledModel", "SampledSpectrum", "SampledCrossover", "SampledMargins", "SamplingComparison", "sampled_model",
    "sampled_spectrum", "sampled_frequency_response", "sampled_margins", "compare_sampling",
    "FrequencyResponse", "Margins", "Crossover", "frequency_response", "frequency_grid", "margins",
    "JitterMargin", "jitter_margin", "stable_for", "jitter_bound",
    "poles", "is_stable", "hinfnorm", "HinfNorm", "nyquist_count", "NyquistCount", "loop_margins", "LoopMargins",
    "NeutralAbscissa", "neutral_abscissa", "polygon_abscissa", "ChannelAbscissa", "channel_abscissa",
    "neutral_spectrum",
]


__getattr__, __dir__ = lazy_exports(__name__, by_module(_SOURCES), globals())
