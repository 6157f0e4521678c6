"""Systems: MIMO linear systems with internal delays, their algebra and their exact frequency response.

:class:`DelayLTI` (:mod:`.lti`) is a continuous-time system in linear-fractional form (a delay-free part closed
through a diagonal block of delays), :mod:`.algebra` combines systems (series, parallel, feedback, named
interconnection) without approximating a delay, and :mod:`.build` makes them (``tf``, ``ss``, ``delay``,
python-control objects, a :class:`~delaykit.models.Loop`) and turns them back into python-control objects with
Padé approximations (:mod:`.pade`: a delay-free system and its error), and :mod:`.discrete` samples them exactly
behind a zero-order hold (and approximates a fractional delay by a Thiran filter); :mod:`.files` reads a system from a TOML
file of blocks connected by name; :mod:`.difference` locates a neutral system's root chains, channel by channel; :mod:`.laplace` is the Laplace variable ``s = tf("s")`` and its exact algebra.  This layer reads
:mod:`delaykit.models` only; the poles, stability, H-infinity norm and margins of a system are in
:mod:`delaykit.spectrum.systems`.

Examples
--------
>>> from delaykit.systems import tf, feedback
>>> feedback(tf("exp(-0.2*s)/s"), 1).ndelays
1
"""

from .._lazy import by_module, lazy_exports

_SOURCES = {
    "lti": ["DelayLTI", "SystemResponse"],
    "algebra": ["append", "series", "parallel", "feedback", "interconnect", "summing_junction", "gain"],
    "build": ["tf", "ss", "delay", "saturation", "to_control", "from_loop", "plant_of", "to_loop"],
    "discrete": ["DiscreteLTI", "c2d", "thiran", "absorb_delay"],
    "pade": ["pade", "pade_error"],
    "files": ["SystemFile", "read_system_file", "load_system", "system_from_dict"],
    "difference": ["ChannelAbscissa", "channel_abscissa", "rationally_independent",
           "LaplaceExpression", "exp", "laplace_variable", "parse_expression"],
    "laplace": ["LaplaceExpression", "exp", "laplace_variable", "parse_expression"],
}

__all__ = ["DelayLTI", "SystemResponse", "append", "series", "parallel", "feedback", "interconnect",
           "summing_junction", "gain", "tf", "ss", "delay", "saturation", "to_control", "from_loop", "plant_of",
           "to_loop", "DiscreteLTI", "c2d", "thiran", "absorb_delay", "pade", "pade_error", "SystemFile", "read_system_file", "load_system", "system_from_dict",
           "ChannelAbscissa", "channel_abscissa", "rationally_independent",
           "LaplaceExpression", "exp", "laplace_variable", "parse_expression"]


__getattr__, __dir__ = lazy_exports(__name__, by_module(_SOURCES), globals())
