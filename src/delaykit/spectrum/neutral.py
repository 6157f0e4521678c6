"""The spectrum of a neutral quasi-polynomial's difference operator: where its root chains can accumulate.

A neutral quasi-polynomial ``Q(s) = sum_j p_j(s) exp(-s tau_j)`` has infinitely many roots whose real parts
approach those of the roots of its *difference operator* ``D(s) = a_0 + sum_k b_k exp(-s tau_k)`` (the
top-degree coefficients; ``a_0`` the delay-free one).  With one delay they lie on the line
``Re s = ln|b / a_0| / tau``.  With several they need not lie on lines at all: when the delays are rationally
independent, the phases ``tau_k Im s`` (mod ``2 pi``) are dense on the torus (Kronecker's theorem), and the closure
of the real parts of the roots of ``D`` is the set of ``x`` at which the moduli ``|a_0|`` and
``r_k(x) = |b_k| exp(-tau_k x)``, with their phases chosen freely, can add up to zero: the *polygon condition*
``2 max(|a_0|, r_1, ..., r_m) <= |a_0| + r_1 + ... + r_m`` (Henry 1974; Avellar & Hale 1980).

Its supremum is the root ``x*`` of ``r_1(x) + ... + r_m(x) = |a_0|``: for larger ``x`` the delayed moduli cannot
reach ``|a_0|`` (no root of ``D`` can lie there, for any delays: ``|a_0| = |sum b_k exp(-s tau_k)| <= sum r_k``),
and at ``x*`` itself ``|a_0|`` is the largest side and equals the sum of the others, so the polygon closes.
Hence :func:`neutral_abscissa` is an upper bound on the real parts of the roots of ``D`` for every set of
delays, and their exact supremum when the delays are rationally independent.  ``x* < 0`` (equivalently
``sum |b_k| < |a_0|``) is *strong stability*: the difference operator stays stable under every small change of
its delays (Hale & Verduyn Lunel 2002), which is what a neutral system must have for its stability to mean
anything in practice.

For a system in LFT form the difference operator is ``det(I - D22 Delta(s))``; expanded, its terms' delays are
sums of the channels' and not independent, so the polygon bound on them is conservative.
:func:`~delaykit.systems.difference.channel_abscissa` (in the systems layer, so that the time kernel can use it
too; exported here as well) keeps the channels: the supremum over their independent phases, by the structured
singular value of complex scalar channels (exact, bracketed from above and below), and the exact lines for
commensurate delays.

Examples
--------
>>> from delaykit.models import QuasiPolynomial
>>> import math
>>> q = QuasiPolynomial([[1, 2], [0.5, 0], [0.45, 0.1]], [0.0, 1.0, math.sqrt(2)])
>>> neutral_abscissa(q)
NeutralAbscissa(-0.04285 (strongly stable), delays [1, 1.414], exact for independent delays)

References
----------
D. Henry, "Linear autonomous neutral functional differential equations", J. Differential Equations 15 (1974).
C. E. Avellar and J. K. Hale, "On the zeros of exponential polynomials", J. Math. Anal. Appl. 73 (1980).
J. K. Hale and S. M. Verduyn Lunel, "Strong stabilization of neutral functional differential equations",
IMA J. Math. Control Inform. 19 (2002).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidValueError
from ..models.quasipolynomial import QuasiPolynomial
from ..systems.difference import ChannelAbscissa, channel_abscissa, rationally_independent

__all__ = ["NeutralAbscissa", "neutral_abscissa", "polygon_abscissa", "difference_operator", "ChannelAbscissa",
           "channel_abscissa"]


@dataclass(frozen=True, repr=False)
class NeutralAbscissa:
    """The supremum of the real parts of a difference operator's roots (the polygon bound).

    Attributes
    ----------
    abscissa : float
        ``x*``: no root of the difference operator lies right of it, for any delays; ``inf`` when the delay-free
        top-degree coefficient is zero.
    delays : tuple of float
        The delays of the difference operator's terms.
    independent : bool
        True when one delay, or when no integer relation with coefficients up to 6 holds between the delays
        (to a relative 1e-9): then ``abscissa`` is the exact supremum (the roots' real parts come arbitrarily
        close to it); otherwise it is an upper bound that may not be reached.
    """

    abscissa: float
    delays: tuple[float, ...]
    independent: bool

    @property
    def strongly_stable(self) -> bool:
        """``abscissa < 0``: the difference operator is stable for every small change of its delays."""
        return self.abscissa < 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (an infinite abscissa as null)."""
        return {"abscissa": self.abscissa if math.isfinite(self.abscissa) else None, "delays": list(self.delays),
                "independent": self.independent, "strongly_stable": self.strongly_stable}

    def __repr__(self) -> str:
        verdict = "strongly stable" if self.strongly_stable else "NOT strongly stable"
        how = "exact for independent delays" if self.independent else "upper bound"
        return (f"NeutralAbscissa({self.abscissa:.4g} ({verdict}), delays [{', '.join(f'{t:.4g}' for t in self.delays)}]"
                f", {how})")


def polygon_abscissa(a0: complex, b: Sequence[complex], tau: Sequence[float]) -> float:
    """The root ``x`` of ``sum_k |b_k| exp(-tau_k x) = |a0|``: the supremum of the polygon condition.

    Parameters
    ----------
    a0 : complex
        The delay-free coefficient.
    b, tau : sequences
        The delayed coefficients and their delays (``tau_k > 0``).

    Returns
    -------
    float
        ``inf`` when ``a0 = 0``, ``-inf`` when every ``b_k`` is zero; otherwise the root, to the last bit (Brent's
        method on ``log(sum r_k) - log|a0|``, which is strictly decreasing).

    Examples
    --------
    >>> round(polygon_abscissa(1.0, [0.3], [0.37]), 12) == round(math.log(0.3) / 0.37, 12)
    True
    """
    from scipy.optimize import brentq

    r = np.abs(np.asarray(b, complex))
    t = np.asarray(tau, float)
    if r.shape != t.shape or r.ndim != 1:
        raise InvalidValueError(f"one delay per delayed coefficient expected, got {r.size} coefficients and "
                                f"{t.size} delays")
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(t)) and np.all(t > 0) and math.isfinite(abs(a0))):
        raise InvalidValueError(f"finite coefficients and positive delays expected, got b={list(b)}, tau={list(tau)}")
    keep = r > 0
    r, t = r[keep], t[keep]
    a = abs(a0)
    if a == 0.0:
        return math.inf
    if r.size == 0:
        return -math.inf
    own = np.log(r / a) / t  # where each term alone reaches |a0|
    lo = float(own.max())  # there that term is |a0|: the sum is at least |a0|
    hi = float((np.log(r.size * r / a) / t).max())  # there every term is at most |a0| / m
    if hi <= lo:
        return lo

    def h(x: float) -> float:
        e = np.log(r) - t * x
        m = e.max()
        return float(m + math.log(np.exp(e - m).sum()) - math.log(a))

    return float(brentq(h, lo, hi, xtol=1e-15 * max(1.0, abs(lo)), rtol=4 * np.finfo(float).eps))


def neutral_abscissa(q: QuasiPolynomial) -> NeutralAbscissa:
    """The polygon bound on the real parts of the roots of ``q``'s difference operator.

    The difference operator is ``q``'s top-degree coefficients, ``a_0 + sum_k b_k exp(-s tau_k)``; see the
    module's text for the method.  For a retarded ``q`` there is none: the abscissa is ``-inf``.

    Raises
    ------
    InvalidValueError
        For an advanced quasi-polynomial (its roots are unbounded to the right).

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> na = neutral_abscissa(AltitudeLoop(kp=2, delay=0.37, kv=0.3).characteristic())
    >>> round(na.abscissa, 4), na.strongly_stable                # ln(0.3) / 0.37
    (-3.254, True)
    """
    if not isinstance(q, QuasiPolynomial):
        raise InvalidValueError(f"expected a QuasiPolynomial, got {type(q).__name__}")
    if q.kind == "advanced":
        raise InvalidValueError("an advanced quasi-polynomial (a delayed term of higher degree) has no bounded "
                                "difference operator spectrum")
    if q.kind != "neutral":
        return NeutralAbscissa(-math.inf, (), True)
    a0, b, delays = difference_operator(q)
    return NeutralAbscissa(polygon_abscissa(a0, b, delays), delays, rationally_independent(delays))


def difference_operator(q: QuasiPolynomial) -> tuple[complex, tuple[complex, ...], tuple[float, ...]]:
    """The difference operator ``a0 + sum_k b_k exp(-s tau_k)`` of a neutral ``q`` (its top-degree coefficients):
    ``(a0, b, tau)``.

    Examples
    --------
    >>> from delaykit import AltitudeLoop
    >>> a0, b, tau = difference_operator(AltitudeLoop(kp=2, delay=0.37, kv=0.3).characteristic())
    >>> float(abs(b[0] / a0)), tau
    (0.3, (0.37,))
    """
    n = q.degree
    lead = [(p[0], t) for p, t in zip(q.polys, q.delays) if len(p) - 1 == n]
    a0 = next(c for c, t in lead if t == 0.0)
    b = [(c, t) for c, t in lead if t > 0.0]
    return a0, tuple(c for c, _ in b), tuple(t for _, t in b)
