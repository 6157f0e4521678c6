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

from ..models.altitude import PAPER_PERIOD, AltitudeLoop
from ..simulate.simulation import simulate, simulate_many

__all__ = ["TABLE1", "TABLE2", "TABLE3", "TABLE3_TOLERANCE", "TABLE1_KP", "TABLE3_KP", "TABLE3_DELAY", "PAPER_PV_KV",
           "Table1Row", "Table3Row", "table1", "table3", "paper_loop"]

TABLE1_KP = 1.31  # the P gain of Table 1 and of the flights of Table 2
TABLE1 = (  # (K, printed Td = K Ts, printed Mo %); the starred row is the paper's estimate
    (4.0000, 0.260, 0.000),
    (5.0000, 0.325, 0.419),
    (5.6000, 0.364, 2.067),
    (5.6640, 0.368, 2.298),
    (5.6645, 0.368, 2.301),
    (5.6646, 0.368, 2.300),
    (5.6660, 0.369, 2.305),
)
TABLE3 = (  # (Kv, printed "rightmost" root) of s + (2 + Kv s) exp(-0.37 s), Kp = 2.0, Td = 0.37 s
    (0.0, complex(-1.42, 3.07)),
    (0.1, complex(-1.98, 3.25)),
    (0.3, complex(-3.25, 24.75)),
    (0.5, complex(-1.84, 6.98)),
    (0.7, complex(-0.89, 7.47)),
)
TABLE3_KP, TABLE3_DELAY = 2.0, 0.37  # the PV loop of Tables 3 and 4
#: The velocity gain the paper chooses for the PV loop at Kp = 2.0 (Table 3 and Fig. 8: the most stable of its five).
PAPER_PV_KV = 0.3
#: Table 3 prints two decimals: a printed root agrees with a computed one within half a unit of the last digit.
TABLE3_TOLERANCE = 0.005
TABLE2 = {  # five flights at Kp = 1.31: overshoot (%) and peak time (s); section 5.1 estimates from the first
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
    from scipy.optimize import brentq

    return brentq(f, lo, hi, xtol=1e-10)


def table1(period: float = PAPER_PERIOD) -> list[Table1Row]:
    """Table 1 recomputed: the exact overshoot at each ``Td = K * Ts``, beside the printed value.

    Examples
    --------
    >>> [round(r.overshoot, 3) for r in table1()][:3]
    [0.0, 0.398, 2.038]
    """
    k = np.array([row[0] for row in TABLE1])
    m = simulate_many(paper_loop(float(k[0] * period)), delay=k * period)
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


@dataclass(frozen=True, repr=False)
class Table3Row:
    """One row of Table 3: the printed "rightmost" root beside the computed rightmost root.

    ``printed_is_root`` says whether the printed value is a root at all (within its rounding: a root lies
    within 0.01 of it), ``rank`` is its place in the spectrum by decreasing real part (1 = rightmost).
    """

    kv: float
    paper: complex
    rightmost: complex
    neutral_line: float | None
    printed_is_root: bool
    rank: int | None

    @property
    def agrees(self) -> bool:
        """The printed root is the rightmost one, to the printed two decimals (within :data:`TABLE3_TOLERANCE`)."""
        return (abs(self.paper.real - self.rightmost.real) <= TABLE3_TOLERANCE
                and abs(self.paper.imag - self.rightmost.imag) <= TABLE3_TOLERANCE)

    @property
    def status(self) -> str:
        """``"reproduced"`` or ``"not reproduced"`` (from :attr:`agrees`, not from the text)."""
        return "reproduced" if self.agrees else "not reproduced"

    @property
    def verdict(self) -> str:
        """Reproduced (with the tolerance), or what the printed value is instead."""
        d_re, d_im = abs(self.paper.real - self.rightmost.real), abs(self.paper.imag - self.rightmost.imag)
        tol = (f"|Re| difference {d_re:.4f}, |Im| difference {d_im:.4f} {'<=' if self.agrees else 'not both <='} "
               f"{TABLE3_TOLERANCE:g} (half a unit of the printed second decimal)")
        if self.agrees:
            return f"reproduced: the printed root is the rightmost, {tol}"
        if self.printed_is_root:
            return (f"not reproduced: the printed {self.paper.real:.2f} ± {self.paper.imag:.2f}j is a root, but "
                    f"number {self.rank} from the right"
                    + ("" if self.neutral_line is None else
                       f" (on the neutral chain that approaches Re s = {self.neutral_line:.4f})")
                    + f"; the rightmost is {self.rightmost.real:.4f} ± {self.rightmost.imag:.4f}j; {tol}")
        return f"not reproduced: the printed value is not a root; the rightmost is {self.rightmost:.4f}; {tol}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"kv": self.kv, "paper": [self.paper.real, self.paper.imag],
                "rightmost": [self.rightmost.real, self.rightmost.imag], "neutral_line": self.neutral_line,
                "printed_is_root": self.printed_is_root, "rank": self.rank, "status": self.status,
                "verdict": self.verdict}

    def __repr__(self) -> str:
        return f"Table3Row(Kv={self.kv}, paper={self.paper}, rightmost={self.rightmost:.4f}: {self.verdict})"


def table3() -> list[Table3Row]:
    """Table 3 checked: the rightmost root of the neutral PV loop for each Kv, and where the printed one sits.

    Examples
    --------
    >>> [r.agrees for r in table3()]
    [True, True, False, True, True]
    """
    from ..spectrum.roots import find_roots
    from ..spectrum.stability import rightmost

    rows = []
    for kv, printed in TABLE3:
        loop = AltitudeLoop(kp=TABLE3_KP, delay=TABLE3_DELAY, kv=kv)
        rm = rightmost(loop)
        sp = find_roots(loop.characteristic(), (-10.0, 2.0, 0.0, abs(printed.imag) + 10.0))
        d = np.abs(sp.roots - printed)
        is_root = bool(d.size and d.min() <= 0.01)
        rank = int(np.argmin(d)) + 1 if is_root else None
        rows.append(Table3Row(kv=kv, paper=printed, rightmost=rm.root, neutral_line=(rm.neutral_lines or (None,))[0],
                              printed_is_root=is_root, rank=rank))
    return rows
