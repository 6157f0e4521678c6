"""Models: what a loop with a delay is, before anything is computed from it.

The lowest layer above :mod:`delaykit.errors`. :class:`Loop` is any delayed loop (a plant as a
:class:`TransferFunction`, a :class:`Controller`, input and output delays, limits, sampling), with the plant
families of :mod:`.plants` and the inputs of :mod:`.signals`; :class:`AltitudeLoop` is the quadrotor's P or PV altitude loop with a
delay on the command (gains, delay, velocity filter, sample period), and :class:`QuasiPolynomial` is the
characteristic function ``sum_k p_k(s) exp(-tau_k s)`` that such a loop (or any linear loop with delays) has. Every
later layer (simulate, spectrum, identify, design, ...) takes these as its input; nothing here imports them.
"""

from .altitude import PAPER_PERIOD, VELOCITY_CHOICES, AltitudeLoop
from .compensators import COMPENSATOR_KINDS, Compensator
from .controllers import ANTIWINDUP_CHOICES, CONTROLLER_KINDS, Controller, Realisation
from .loop import LOOP_KEYS, Loop, load_loop, loop_from_dict
from .plants import (PLANT_FAMILIES, first_order, integrator, integrator_lag, integrator_speed_loop, second_order,
                     second_order_wn)
from .quasipolynomial import QuasiPolynomial
from .ranges import parse_range
from .signals import LoadStep, Ramp, Samples, Step, as_reference
from .transfer import MAX_ORDER, TransferFunction

__all__ = [
    "AltitudeLoop", "VELOCITY_CHOICES", "PAPER_PERIOD", "QuasiPolynomial",
    "Controller", "Realisation", "CONTROLLER_KINDS", "ANTIWINDUP_CHOICES", "Compensator", "COMPENSATOR_KINDS",
    "Loop", "LOOP_KEYS", "load_loop", "loop_from_dict",
    "PLANT_FAMILIES", "integrator", "integrator_lag", "integrator_speed_loop", "first_order", "second_order",
    "second_order_wn",
    "Step", "Ramp", "Samples", "LoadStep", "as_reference",
    "TransferFunction", "MAX_ORDER", "parse_range",
]
