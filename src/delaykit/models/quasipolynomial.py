"""Quasi-polynomials: sums of polynomials times exponentials, the characteristic functions of delay loops.

``Q(s) = sum_j p_j(s) exp(-s tau_j)``.  Polynomial coefficients are given highest degree first (the NumPy
``polyval`` and MATLAB convention).  The altitude loop builds its own with
:meth:`delaykit.models.altitude.AltitudeLoop.characteristic`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real

__all__ = ["QuasiPolynomial"]


def _clean_poly(name: str, coeffs: Iterable[complex]) -> tuple[complex, ...]:
    try:
        arr = np.asarray(list(coeffs), dtype=complex)
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"{name}: coefficients must be numbers, got {coeffs!r}") from exc
    if arr.ndim != 1:
        raise InvalidValueError(f"{name}: coefficients must be a flat sequence, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InvalidValueError(f"{name}: coefficients must be finite, got {arr.tolist()}")
    nz = np.flatnonzero(arr)
    arr = arr[nz[0]:] if nz.size else np.zeros(1, dtype=complex)
    return tuple(complex(c) for c in arr)


@dataclass(frozen=True)
class QuasiPolynomial:
    """``Q(s) = sum_j polys[j](s) * exp(-s * delays[j])``.

    Parameters
    ----------
    polys : sequence of sequences of complex
        Polynomial coefficients of each term, highest degree first.
    delays : sequence of float
        The delay of each term (non-negative; terms with equal delays are merged).

    Examples
    --------
    The P loop of the paper, ``s + Kp exp(-s Td)``:

    >>> q = QuasiPolynomial([[1, 0], [1.31]], [0.0, 0.368])
    >>> q
    QuasiPolynomial(s + 1.31·exp(-0.368 s))
    >>> bool(abs(q(0.0) - 1.31) < 1e-12)
    True
    """

    polys: tuple[tuple[complex, ...], ...]
    delays: tuple[float, ...]

    def __init__(self, polys: Sequence[Sequence[complex]], delays: Sequence[float]) -> None:
        try:
            polys = list(polys)
            delays = list(delays)
        except TypeError:
            raise InvalidTypeError(f"QuasiPolynomial takes a list of polynomials and a list of delays, got "
                                   f"{type(polys).__name__} and {type(delays).__name__}") from None
        if len(polys) != len(delays):
            raise InvalidValueError(
                f"QuasiPolynomial needs one delay per polynomial, got {len(polys)} polynomials and {len(delays)} delays"
            )
        merged: dict[float, np.ndarray] = {}
        for k, (p, tau) in enumerate(zip(polys, delays)):
            tau = check_real(f"delay of term {k}", tau, minimum=0.0)
            c = np.asarray(_clean_poly(f"polynomial of term {k}", p), dtype=complex)
            if tau in merged:
                a, b = merged[tau], c
                n = max(a.size, b.size)
                c = np.pad(a, (n - a.size, 0)) + np.pad(b, (n - b.size, 0))
            merged[tau] = c
        keep = sorted((t, c) for t, c in merged.items() if np.any(c != 0))
        if not keep:
            raise InvalidValueError("QuasiPolynomial: all polynomials are zero; there is nothing to solve")
        object.__setattr__(self, "polys", tuple(_clean_poly("p", c) for _, c in keep))
        object.__setattr__(self, "delays", tuple(float(t) for t, _ in keep))

    @property
    def degree(self) -> int:
        """The highest polynomial degree over all terms."""
        return max(len(p) - 1 for p in self.polys)

    @property
    def kind(self) -> str:
        """``"retarded"``, ``"neutral"`` or ``"advanced"``: how the delay-free term's degree compares.

        Retarded: the delay-free term has the highest degree strictly.  Neutral: a delayed term has the same
        degree (root chains approach vertical lines).  Advanced: a delayed term has a higher degree.
        """
        n0 = max((len(p) - 1 for p, t in zip(self.polys, self.delays) if t == 0.0), default=-1)
        nd = max((len(p) - 1 for p, t in zip(self.polys, self.delays) if t > 0.0), default=-1)
        if n0 > nd:
            return "retarded"
        return "neutral" if n0 == nd else "advanced"

    @property
    def is_neutral(self) -> bool:
        """True for a neutral quasi-polynomial (see :attr:`kind`)."""
        return self.kind == "neutral"

    def __call__(self, s: complex | np.ndarray) -> complex | np.ndarray:
        """Evaluate Q at ``s`` (a number or an array)."""
        s = np.asarray(s, dtype=complex)
        total = np.zeros_like(s)
        for p, tau in zip(self.polys, self.delays):
            total = total + np.polyval(p, s) * np.exp(-s * tau)
        return total[()] if total.ndim == 0 else total

    def derivative(self) -> "QuasiPolynomial":
        """dQ/ds, again a quasi-polynomial."""
        polys, delays = [], []
        for p, tau in zip(self.polys, self.delays):
            dp = np.polyder(np.asarray(p)) if len(p) > 1 else np.zeros(1, dtype=complex)
            term = np.polysub(dp, tau * np.asarray(p))
            polys.append(term)
            delays.append(tau)
        return QuasiPolynomial(polys, delays)

    def to_dict(self) -> dict:
        """JSON-ready form: real and imaginary parts of each coefficient."""
        return {
            "polys": [[[c.real, c.imag] for c in p] for p in self.polys],
            "delays": list(self.delays),
        }

    def __repr__(self) -> str:
        parts = []
        for p, tau in zip(self.polys, self.delays):
            n = len(p) - 1
            mono = []
            for k, c in enumerate(p):
                if c == 0:
                    continue
                deg = n - k
                cs = f"{c.real:g}" if c.imag == 0 else f"({c.real:g}{c.imag:+g}j)"
                sp = "" if deg == 0 else ("s" if deg == 1 else f"s^{deg}")
                if sp and cs == "1":
                    cs = ""
                mono.append(f"{cs}{'·' if cs and sp else ''}{sp}" or "1")
            poly = " + ".join(mono)
            if tau == 0:
                parts.append(poly)
            else:
                poly = f"({poly})" if len(mono) > 1 else poly
                parts.append(f"{poly}·exp(-{tau:g} s)")
        return f"QuasiPolynomial({' + '.join(parts)})"

    def __hash__(self) -> int:  # frozen with a custom __init__
        return hash((self.polys, self.delays))
