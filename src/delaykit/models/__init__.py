"""Models: what a loop with a delay is, before anything is computed from it.

The lowest layer above :mod:`delaykit.errors`. :class:`AltitudeLoop` is the quadrotor's P or PV altitude loop with a
delay on the command (gains, delay, velocity filter, sample period), and :class:`QuasiPolynomial` is the
characteristic function ``sum_k p_k(s) exp(-tau_k s)`` that such a loop (or any linear loop with delays) has. Every
later layer (simulate, spectrum, identify, design, ...) takes these as its input; nothing here imports them.
"""

from .altitude import PAPER_PERIOD, VELOCITY_CHOICES, AltitudeLoop
from .quasipolynomial import QuasiPolynomial

__all__ = ["AltitudeLoop", "VELOCITY_CHOICES", "PAPER_PERIOD", "QuasiPolynomial"]
