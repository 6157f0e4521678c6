"""Models: what a loop with a delay is, before anything is computed from it.

The lowest layer above :mod:`delaykit.errors`. :class:`Loop` is any delayed loop (a plant as a
:class:`TransferFunction`, a :class:`Controller`, input and output delays, limits, sampling), with the plant
families of :mod:`.plants` and the inputs of :mod:`.signals`; :class:`AltitudeLoop` is the quadrotor's P or PV altitude loop with a
delay on the command (gains, delay, velocity filter, sample period), and :class:`QuasiPolynomial` is the
characteristic function ``sum_k p_k(s) exp(-tau_k s)`` that such a loop (or any linear loop with delays) has. Every
later layer (simulate, spectrum, identify, design, ...) takes these as its input; nothing here imports them.

The names are imported on first use (``from delaykit.models import Loop`` works as ever), so that a command that
needs only :mod:`.ranges` does not load NumPy, and none of this package loads SciPy until :mod:`.hold` computes.

Examples
--------
>>> from delaykit.models import Loop, parse_range
>>> Loop.__module__, parse_range("1:2:3")
('delaykit.models.loop', [1.0, 1.5, 2.0])
"""

from .._lazy import by_module, lazy_exports

_SOURCES = {
    "altitude": ["AltitudeLoop", "VELOCITY_CHOICES", "PAPER_PERIOD"],
    "quasipolynomial": ["QuasiPolynomial"],
    "controllers": ["Controller", "Realisation", "CONTROLLER_KINDS", "ANTIWINDUP_CHOICES"],
    "closed_loop": ["LoopRealisation", "loop_realisation"],
    "compensators": ["Compensator", "COMPENSATOR_KINDS"],
    "loop": ["Loop", "LOOP_KEYS", "load_loop", "loop_from_dict"],
    "plants": ["PLANT_FAMILIES", "integrator", "integrator_lag", "integrator_speed_loop", "first_order", "second_order",
               "second_order_wn"],
    "signals": ["Step", "Ramp", "Samples", "LoadStep", "as_reference"],
    "transfer": ["TransferFunction", "MAX_ORDER"],
    "ranges": ["parse_range"],
}

__all__ = [
    "AltitudeLoop", "VELOCITY_CHOICES", "PAPER_PERIOD", "QuasiPolynomial",
    "Controller", "Realisation", "CONTROLLER_KINDS", "ANTIWINDUP_CHOICES", "Compensator", "COMPENSATOR_KINDS",
    "LoopRealisation", "loop_realisation",
    "Loop", "LOOP_KEYS", "load_loop", "loop_from_dict",
    "PLANT_FAMILIES", "integrator", "integrator_lag", "integrator_speed_loop", "first_order", "second_order",
    "second_order_wn",
    "Step", "Ramp", "Samples", "LoadStep", "as_reference",
    "TransferFunction", "MAX_ORDER", "parse_range",
]


__getattr__, __dir__ = lazy_exports(__name__, by_module(_SOURCES), globals())
