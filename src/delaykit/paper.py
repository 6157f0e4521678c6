"""The numbers printed in Armah & Yi's paper, and delaykit's converged counterparts of Table 1.

The printed values are kept here verbatim, as claims to check; nothing in delaykit is tuned to them.

Examples
--------
>>> rows = table1()
>>> rows[0]
Table1Row(K=4.0, delay=0.2600 s, paper=0.000 %, delaykit=0.0000 %, diff=+0.0000)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import brentq

from .model import PAPER_PERIOD, AltitudeLoop
from .simulation import simulate, simulate_many

__all__ = ["TABLE1", "TABLE2", "TABLE1_KP", "Table1Row", "table1", "paper_loop"]

TABLE1_KP = 1.31
TABLE1 = (  # (K, printed Td = K Ts, printed Mo %); the starred row is the paper's estimate
    (4.0000, 0.260, 0.000),
    (5.0000, 0.325, 0.419),
    (5.6000, 0.364, 2.067),
    (5.6640, 0.368, 2.298),
    (5.6645, 0.368, 2.301),
    (5.6646, 0.368, 2.300),
    (5.6660, 0.369, 2.305),
)
TABLE2 = {  # five flights at Kp = 1.31: overshoot (%) and peak time (s)
    "overshoot": (2.300, 2.290, 2.300, 2.270, 2.140),
    "peak_time": (3.055, 3.084, 3.575, 3.194, 3.096),
}


def paper_loop(delay: float, kp: float = TABLE1_KP) -> AltitudeLoop:
    """The loop behind Table 1: P control, ±1 m/s saturation, continuous controller.

    Examples
    --------
    >>> paper_loop(0.368)
    AltitudeLoop(kp=1.31, delay=0.368 s, vmax=±1 m/s, continuous)
    """
    return AltitudeLoop(kp=kp, delay=delay)


@dataclass(frozen=True, repr=False)
class Table1Row:
    """One row of Table 1: the paper's overshoot beside delaykit's exact one.

    ``equivalent_delay`` is the delay at which the exact loop gives the paper's printed overshoot; its
    excess over ``delay`` is what the paper's solver added (about half of its step for a first-order
    fixed-step method).
    """

    K: float
    delay: float
    paper_overshoot: float
    overshoot: float
    equivalent_delay: float | None

    @property
    def difference(self) -> float:
        """Paper minus delaykit, percentage points."""
        return self.paper_overshoot - self.overshoot

    @property
    def extra_delay(self) -> float | None:
        """Equivalent delay minus the true one, seconds."""
        return None if self.equivalent_delay is None else self.equivalent_delay - self.delay

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"K": self.K, "delay": self.delay, "paper_overshoot": self.paper_overshoot,
                "overshoot": self.overshoot, "difference": self.difference,
                "equivalent_delay": self.equivalent_delay, "extra_delay": self.extra_delay}

    def __repr__(self) -> str:
        return (f"Table1Row(K={self.K}, delay={self.delay:.4f} s, paper={self.paper_overshoot:.3f} %, "
                f"delaykit={self.overshoot:.4f} %, diff={self.difference:+.4f})")


def _equivalent_delay(target: float, delay: float, kp: float) -> float | None:
    if target <= 0.0:
        return None
    f = lambda d: simulate(paper_loop(d, kp)).metrics.overshoot - target  # noqa: E731
    lo, hi = delay - 0.02, delay + 0.02
    if f(lo) * f(hi) > 0:
        return None
    return brentq(f, lo, hi, xtol=1e-10)


def table1(period: float = PAPER_PERIOD) -> list[Table1Row]:
    """Table 1 recomputed: the exact overshoot at each ``Td = K * Ts``, beside the printed value.

    Examples
    --------
    >>> [round(r.overshoot, 3) for r in table1()][:3]
    [0.0, 0.398, 2.038]
    """
    k = np.array([row[0] for row in TABLE1])
    m = simulate_many(kp=TABLE1_KP, delay=k * period)
    rows = []
    for (kk, _, mo_paper), td, mo in zip(TABLE1, k * period, m.overshoot):
        rows.append(Table1Row(K=kk, delay=float(td), paper_overshoot=mo_paper, overshoot=float(mo),
                              equivalent_delay=_equivalent_delay(mo_paper, float(td), TABLE1_KP)))
    return rows


def table1_overshoot(delay: float) -> float | None:
    """The paper's printed overshoot for a delay equal (to 1e-9 s) to one of Table 1's ``K * Ts``."""
    for kk, _, mo in TABLE1:
        if math.isclose(delay, kk * PAPER_PERIOD, abs_tol=1e-9):
            return mo
    return None
