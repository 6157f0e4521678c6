"""Regenerate the paper from one command: every table and figure, the paper's values beside delaykit's,
and a verdict for each item.  ``delaykit reproduce --out DIR`` writes ``DIR/report.md`` and a self-contained
``DIR/index.html`` (figures embedded as PNG).

Every verdict is decided by a tolerance check (a small function taking the numbers, with the paper's printed
values as defaults, so that a test can move them), and the tolerance is written beside the result.  Each item
has a ``status``, one of ``"reproduced"``, ``"not reproduced"`` or ``"not checked"``, and its verdict text starts
with that word; code tests the status, never the text.  Nothing here is tuned to the printed numbers: where a
configuration had to be chosen (Table 4), the candidates are all shown and the one that fits is named.

Examples
--------
>>> import tempfile
>>> rep = reproduce(tempfile.mkdtemp())
>>> [item.key for item in rep.items][:3]
['table1', 'section511', 'section512']
"""

from __future__ import annotations

import base64
import html
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable


from ..design.tuning import filter_analysis
from ..errors import check_path, writing
from ..identify.estimation import estimate_lambert, estimate_overshoot, lambert_paper_iterations
from ..models.altitude import PAPER_PERIOD, AltitudeLoop
from ..simulate.metrics import SecondOrder
from ..simulate.simulation import simulate
from ..spectrum.roots import find_roots
from .data import PAPER_PV_KV, TABLE1_KP, TABLE2, TABLE3_DELAY, TABLE3_KP, TABLE3_TOLERANCE, table1, table3
from .report import SOLVER_TOLERANCE_S, Status, Verdict, plot_table1_responses, table1_check

__all__ = ["Item", "Reproduction", "reproduce", "TABLE4", "section511_check", "section512_check", "table3_check",
           "table3_conclusion_check", "table4_check", "design_text_check", "fig5_check"]

PAPER_511_DELAY = 5.6646 * PAPER_PERIOD  # section 5.1.1: "5.6646 Ts"
PAPER_512 = {"zeta": 0.7684, "omega_n": 1.6069, "root": complex(-1.2347, 1.0284), "delay": 0.374}  # section 5.1.2
PAPER_BEST_KV = PAPER_PV_KV  # Table 3 / Fig. 8: the paper's most stable Kv (also the most negative printed real part)
#: Section 5.1's measurement: the first flight of Table 2 (Mo = 2.300 %, tp = 3.055 s)
PAPER_MO, PAPER_TP = TABLE2["overshoot"][0], TABLE2["peak_time"][0]
PAPER_DESIGN_TEXT = {"overshoot": 0.44, "settling_time": 1.52, "peak_time": 1.76}  # Kp = 2.0, Kv = 0.3, no filter
TABLE4_TOLERANCE = (0.5, 0.05, 0.1)  # pp, s, s: the paper does not give its step, solver or filter discretisation
FIG5_NO_OVERSHOOT_KP = 1.0  # "Kp = 1.0 ... the response has no overshoot, however, the response is very slow"

TABLE4 = {  # Kp = 2.0 with the derivative filter, simulated rows (Td = 0.37 s)
    "kv": (0.0, 0.1, 0.3, 0.5, 0.7),
    "overshoot": (15.10, 10.10, 0.32, 0.15, 0.70),
    "peak_time": (1.82, 1.76, 1.69, 3.64, 4.36),
    "settling_time": (3.28, 2.87, 1.52, 2.33, 3.04),
}


@dataclass
class Item:
    """One reproduced item: a title, tables (header + rows), figures (PNG files), a verdict and notes."""

    key: str
    title: str
    verdict: str
    status: Status
    tables: list[tuple[list[str], list[list[str]]]] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    checks: dict[str, Verdict] = field(default_factory=dict)

    @classmethod
    def from_verdict(cls, key: str, title: str, verdict: Verdict, *args: Any, **kwargs: Any) -> "Item":
        """An item whose verdict and status come from one :class:`~delaykit.paper.report.Verdict`."""
        return cls(key, title, verdict.text, verdict.status, *args, **kwargs)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"key": self.key, "title": self.title, "status": self.status, "verdict": self.verdict,
                "tables": [{"header": h, "rows": r} for h, r in self.tables],
                "figures": [str(f) for f in self.figures], "notes": self.notes,
                "checks": {k: v.to_dict() for k, v in self.checks.items()}}


@dataclass(frozen=True, repr=False)
class Reproduction:
    """What :func:`reproduce` wrote."""

    out: Path
    items: tuple[Item, ...]
    files: tuple[Path, ...]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"out": str(self.out), "items": [i.to_dict() for i in self.items], "files": [str(f) for f in self.files]}

    def __repr__(self) -> str:
        n = sum(i.status == "reproduced" for i in self.items)
        return f"Reproduction({self.out}: {n} of {len(self.items)} items reproduced)"


# ----- the verdicts: small functions of the numbers, the paper's printed values as defaults ------------------------

def _cmp(name: str, ours: float, paper: float, tol: float, unit: str = "", d: int = 4) -> tuple[bool, str]:
    diff = abs(ours - paper)
    ok = diff <= tol
    return ok, f"{name} |{ours:.{d}f} - ({paper:g})| = {diff:.{d}f}{unit} {'<=' if ok else '>'} {tol:.{d}f}{unit}"


def section511_check(delay: float, paper_delay: float = PAPER_511_DELAY,
                     tolerance: float = SOLVER_TOLERANCE_S) -> Verdict:
    """Section 5.1.1: the delay matching Mo = 2.300 % against the paper's 5.6646 Ts, within the solver error
    (half the 1 ms step of a first-order fixed-step solver, which acts as extra delay).

    Examples
    --------
    >>> section511_check(0.368643).status, section511_check(0.368643, paper_delay=0.3670).status
    ('reproduced', 'not reproduced')
    """
    ok, txt = _cmp("delay", delay, paper_delay, tolerance, " s", 5)
    rule = (f"({1e3 * tolerance:g} ms is the solver error: a first-order fixed-step solver with a 1 ms step acts as "
            "half a step of extra delay)")
    if ok:
        return Verdict("reproduced", f"reproduced to within solver error: the exact simulation gives {delay:.4f} s, "
                                     f"the paper {paper_delay:.4f} s ({1e3 * (delay - paper_delay):+.2f} ms): "
                                     f"{txt} {rule}")
    return Verdict("not reproduced", f"not reproduced: the exact simulation gives {delay:.4f} s, the paper "
                                     f"{paper_delay:.4f} s ({1e3 * (delay - paper_delay):+.2f} ms): {txt} {rule}")


def section512_check(zeta: float, omega_n: float, root: complex, delay: complex, damping_delay: float | None = None,
                     paper_zeta: float = PAPER_512["zeta"], paper_omega_n: float = PAPER_512["omega_n"],
                     paper_root: complex = PAPER_512["root"], paper_delay: float = PAPER_512["delay"]) -> Verdict:
    """Section 5.1.2: ζ and ωn from (Mo, tp), the root from the printed ζ and ωn, and the delay the paper's
    iteration converges to (its real part against the printed 0.374 s), each within half a unit of the
    paper's last printed digit (0.00005 for the four-decimal values, 0.0005 s for the delay).

    Examples
    --------
    >>> args = (0.76842, 1.60692, complex(-1.23474, 1.02837), complex(0.37426, -0.25072))
    >>> section512_check(*args).status, section512_check(*args, paper_delay=0.380).status
    ('reproduced', 'not reproduced')
    """
    t4, t3 = 0.5e-4, 0.5e-3
    parts = [_cmp("zeta", zeta, paper_zeta, t4, "", 5), _cmp("omega_n", omega_n, paper_omega_n, t4, " rad/s", 5),
             _cmp("Re root", root.real, paper_root.real, t4, "", 5),
             _cmp("|Im root|", abs(root.imag), abs(paper_root.imag), t4, "", 5),
             _cmp("Td (real part)", delay.real, paper_delay, t3, " s", 4)]
    ok = all(p[0] for p in parts)
    rule = "; ".join(p[1] for p in parts) + " (half a unit of each printed last digit)"
    caveat = ""
    if abs(delay.imag) > t3:
        caveat = (f"; but the printed {paper_delay:g} s is the real part of the complex delay "
                  f"{delay.real:.4f}{delay.imag:+.4f}j: no real delay puts the P loop's root at "
                  f"{paper_root.real:.4f} + {abs(paper_root.imag):.4f}j")
        if damping_delay is not None:
            caveat += f"; matching the damping ratio alone gives a real {damping_delay:.4f} s"
    return Verdict("reproduced" if ok else "not reproduced",
                   ("reproduced: " if ok else "not reproduced: ") + rule + caveat)


def table3_check(rows: list) -> Verdict:
    """Table 3: each printed "rightmost" root against the computed rightmost root, within
    :data:`~delaykit.paper.data.TABLE3_TOLERANCE` in each part (half a unit of the printed second decimal).

    Examples
    --------
    >>> from .data import Table3Row
    >>> row = Table3Row(kv=0.1, paper=complex(-1.98, 3.25), rightmost=complex(-1.9764, 3.2518), neutral_line=-6.2,
    ...                 printed_is_root=True, rank=1)
    >>> table3_check([row]).status
    'reproduced'
    """
    bad = [r for r in rows if not r.agrees]
    rule = f"(each part within {TABLE3_TOLERANCE:g}, half a unit of the printed second decimal)"
    if not bad:
        return Verdict("reproduced", f"reproduced: all {len(rows)} printed roots are the rightmost {rule}")
    return Verdict("not reproduced", f"not reproduced: {len(rows) - len(bad)} of {len(rows)} rows reproduced {rule}; "
                   + "; ".join(f"Kv = {r.kv:g}: {r.verdict}" for r in bad))


def table3_conclusion_check(kvs: list[float], abscissae: list[float], paper_best_kv: float = PAPER_BEST_KV,
                            tolerance: float = TABLE3_TOLERANCE) -> Verdict:
    """The paper's conclusion from Table 3 (Kv = 0.3 is the most stable): is the computed spectral abscissa of
    ``paper_best_kv`` the most negative, below every other by more than ``tolerance`` (half a unit of Table 3's
    second decimal)?

    Examples
    --------
    >>> kvs, ab = [0.0, 0.1, 0.3, 0.5, 0.7], [-1.4235, -1.9764, -3.1951, -1.8408, -0.8929]
    >>> table3_conclusion_check(kvs, ab).status, table3_conclusion_check(kvs, ab, paper_best_kv=0.1).status
    ('reproduced', 'not reproduced')
    """
    pairs = sorted(zip(abscissae, kvs))
    best_a, best_kv = pairs[0]
    if not any(math.isclose(k, paper_best_kv) for k in kvs):
        return Verdict("not checked", f"not checked: Kv = {paper_best_kv:g} is not among the computed gains")
    mine = next(a for a, k in pairs if math.isclose(k, paper_best_kv))
    others = [(a, k) for a, k in pairs if not math.isclose(k, paper_best_kv)]
    if not others:
        return Verdict("not checked", "not checked: only one gain was computed, there is nothing to compare")
    runner_a, runner_kv = others[0]
    gap = runner_a - mine
    ok = gap > tolerance
    head = (f"Kv = {paper_best_kv:g} is the most stable: its spectral abscissa, {mine:.4f}, is "
            f"{'below' if gap > 0 else 'not below'} the next most negative (Kv = {runner_kv:g}, {runner_a:.4f}) by "
            f"{gap:.4f} {'>' if ok else '<='} {tolerance:g} (half a unit of Table 3's second decimal)")
    if ok:
        return Verdict("reproduced", "reproduced: the paper's conclusion survives: " + head)
    return Verdict("not reproduced", f"not reproduced: the paper's conclusion, {head}; the most negative is "
                                     f"Kv = {best_kv:g} ({best_a:.4f})")


def table4_check(best: str, deviation: tuple[float, float, float],
                 tolerance: tuple[float, float, float] = TABLE4_TOLERANCE) -> Verdict:
    """Table 4: the closest configuration's largest deviations (overshoot pp, peak time s, settling time s) from
    the printed rows, against ``tolerance``: the solver error of a configuration the paper does not fully give
    (its step, solver and filter discretisation).

    Examples
    --------
    >>> table4_check("x", (0.2, 0.01, 0.05)).status, table4_check("x", (0.2, 0.01, 0.3)).status
    ('reproduced', 'not reproduced')
    """
    names = (("overshoot", " pp", 2), ("peak time", " s", 3), ("settling", " s", 3))
    ok = all(d <= t for d, t in zip(deviation, tolerance))
    detail = ", ".join(f"{n} within {d:.{k}f}{u} {'<=' if d <= t else '>'} {t:g}{u}"
                       for (n, u, k), d, t in zip(names, deviation, tolerance))
    rule = "(tolerances: the solver error of details the paper does not give: step, solver, filter discretisation)"
    if ok:
        return Verdict("reproduced", f"reproduced to within solver error by the configuration '{best}': {detail} "
                                     f"of every printed row {rule}")
    return Verdict("not reproduced", f"not reproduced: the closest configuration, '{best}': {detail} {rule}")


def design_text_check(overshoot: float, settling_time: float | None, peak_time: float | None,
                      paper: dict[str, float] = PAPER_DESIGN_TEXT) -> Verdict:
    """The design text's Mo, ts and tp for Kp = 2.0, Kv = 0.3 without the filter, each within half a unit of the
    printed second decimal (0.005).

    Examples
    --------
    >>> design_text_check(1.5e-7, 1.6258, None).status, design_text_check(0.441, 1.521, 1.762).status
    ('not reproduced', 'reproduced')
    """
    tol = 0.005
    parts = [_cmp("Mo", overshoot, paper["overshoot"], tol, " %", 3)]
    for key, name, ours in (("settling_time", "ts", settling_time), ("peak_time", "tp", peak_time)):
        parts.append((False, f"{name}: no value here against the printed {paper[key]:g} s") if ours is None
                     else _cmp(name, ours, paper[key], tol, " s", 3))
    ok = all(p[0] for p in parts)
    return Verdict("reproduced" if ok else "not reproduced",
                   ("reproduced: " if ok else "not reproduced: ") + "; ".join(p[1] for p in parts)
                   + f" (tolerance {tol:g}, half a unit of the printed second decimal)")


def fig5_check(kps: list[float], overshoots: list[float], rise_times: list[float | None],
               no_overshoot_kp: float | None = FIG5_NO_OVERSHOOT_KP, overshoot_trend: int = +1,
               rise_trend: int = -1, tol_pp: float = 0.0005, tol_s: float = 0.0005) -> Verdict:
    """Fig. 5 (measured; its curves are not printed as numbers, so they are not compared): the claims the paper's
    text reads off it, checked on the model's responses at the estimated delay.

    * ``no_overshoot_kp`` (1.0) has no overshoot: Mo <= ``tol_pp`` (half a unit of Table 1's third decimal);
    * the overshoot rises with Kp (``overshoot_trend = +1``) and the rise time falls (``rise_trend = -1``), each
      step by more than ``tol_pp`` percentage points or ``tol_s`` seconds (half a unit of the paper's
      three-decimal times).

    Examples
    --------
    >>> args = ([1.0, 1.31, 2.0], [0.0, 2.3, 12.06], [1.218, 0.904, 0.801])
    >>> fig5_check(*args).status, fig5_check(*args, no_overshoot_kp=1.31).status
    ('reproduced', 'not reproduced')
    """
    order = sorted(range(len(kps)), key=lambda i: kps[i])
    k = [kps[i] for i in order]
    mo = [overshoots[i] for i in order]
    tr = [rise_times[i] for i in order]
    parts: list[tuple[bool, str]] = []
    if no_overshoot_kp is not None:
        hit = [i for i, kk in enumerate(k) if math.isclose(kk, no_overshoot_kp)]
        if not hit:
            return Verdict("not checked", f"not checked: Kp = {no_overshoot_kp:g} was not simulated")
        m0 = mo[hit[0]]
        parts.append((m0 <= tol_pp, f"Kp = {no_overshoot_kp:g} has Mo = {m0:.4f} % "
                                    f"{'<=' if m0 <= tol_pp else '>'} {tol_pp:g} % (no overshoot)"))

    def trend(name: str, xs: list[float | None], sign: int, tol: float, unit: str) -> tuple[bool, str]:
        if any(x is None for x in xs):
            return False, f"{name}: undefined for some Kp"
        steps = [sign * (b - a) for a, b in zip(xs, xs[1:])]
        ok = all(st > tol for st in steps)
        sym = " < " if sign > 0 else " > "
        word = "rises" if sign > 0 else "falls"
        return ok, (f"{name} {word} with Kp ({sym.join(f'{x:.3f}' for x in xs)}{unit}; smallest step "
                    f"{min(steps):.4f}{unit} {'>' if ok else '<='} {tol:g}{unit})")

    parts.append(trend("Mo", mo, overshoot_trend, tol_pp, " %"))
    parts.append(trend("rise time", tr, rise_trend, tol_s, " s"))
    ok = all(p[0] for p in parts)
    scope = ("the paper's text on Fig. 5, checked on the model at the estimated delay "
             "(the measured curves are not printed as numbers and are not compared)")
    return Verdict("reproduced" if ok else "not reproduced",
                   ("reproduced" if ok else "not reproduced") + f", {scope}: " + "; ".join(p[1] for p in parts))


def _f(x: float | None, d: int = 4) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{d}f}"


def _c(z: complex | None, d: int = 4) -> str:
    return "–" if z is None else f"{z.real:.{d}f} ± {abs(z.imag):.{d}f}j"


def _table1(out: Path) -> Item:
    rows = table1()
    fig = out / "fig_table1_responses.png"
    plot_table1_responses(fig)
    body = [[f"{r.K:.4f}", f"{r.delay:.5f}", f"{r.paper_overshoot:.3f}", f"{r.overshoot:.4f}", f"{r.difference:+.4f}",
             _f(r.equivalent_delay, 5)] for r in rows]
    return Item.from_verdict("table1", "Table 1: overshoot against delay (P control, Kp = 1.31)", table1_check(rows),
                [(["K", "Td = K Ts (s)", "paper Mo (%)", "delaykit Mo (%)", "paper − delaykit",
                   "delay giving the paper's Mo (s)"], body)], [fig],
                ["The loop: continuous P controller, ±1 m/s saturation, the delay on the command, a 1 m step from rest."])


def _section511() -> Item:
    est = estimate_overshoot(PAPER_MO, TABLE1_KP, peak_time=PAPER_TP)
    paper = PAPER_511_DELAY
    verdict = section511_check(est.delay, paper)
    notes = [w for w in est.warnings]
    notes.append("Sensitivity: Kp = 1.20 gives " + _f(estimate_overshoot(PAPER_MO, 1.20).delay) + " s, Kp = 1.40 gives "
                 + _f(estimate_overshoot(PAPER_MO, 1.40).delay) + " s, no saturation "
                 + _f(estimate_overshoot(PAPER_MO, TABLE1_KP, vmax=None).delay) + " s.")
    # every flight of Table 2 by the same method: how much the one estimate the paper made depends on the flight
    flights = [[str(i + 1), f"{mo:.3f}", f"{tp:.3f}", _f(estimate_overshoot(mo, TABLE1_KP).delay)]
               for i, (mo, tp) in enumerate(zip(TABLE2["overshoot"], TABLE2["peak_time"]))]
    notes.append("Table 2's five flights give delays from " + min(r[3] for r in flights) + " to "
                 + max(r[3] for r in flights) + " s by the same method; the paper used the first.")
    return Item.from_verdict("section511", f"Section 5.1.1: the numerical estimate (Mo = {PAPER_MO:.3f} %)", verdict,
                [(["", "paper", "delaykit"], [["delay (s)", f"{paper:.4f} (5.6646 Ts)", f"{est.delay:.4f}"],
                                              ["model peak time at that delay (s)", "–",
                                               _f(est.diagnostics.model_peak_time, 3)],
                                              ["measured peak time (s)", f"{PAPER_TP:.3f}", f"{PAPER_TP:.3f}"]]),
                 (["Table 2 flight", "Mo (%)", "tp (s)", "delay matching its Mo (s)"], flights)], [], notes)


def _section512(out: Path) -> Item:
    from ..plotting.figures import plot_iterations

    so = SecondOrder.from_step(PAPER_MO, PAPER_TP)
    paper_root = SecondOrder(PAPER_512["zeta"], PAPER_512["omega_n"]).root
    it = lambert_paper_iterations(paper_root, TABLE1_KP)
    T = it[-1]
    dmp = estimate_lambert(PAPER_MO, PAPER_TP, TABLE1_KP, variant="damping")
    fig = out / "fig7_iterations.png"
    plot_iterations(it, fig, reference=PAPER_512["delay"],
                    title="Fig. 7 redone: the paper's Newton iteration converges to a complex delay")
    verdict = section512_check(so.zeta, so.omega_n, paper_root, T, dmp.delay)
    rows = [["damping ratio", "0.7684", _f(so.zeta)], ["natural frequency (rad/s)", "1.6069", _f(so.omega_n)],
            ["dominant root", "−1.2347 ± 1.0284j", _c(so.root) + " (unrounded)"],
            ["Td (s)", "0.374", f"{T.real:.4f} {T.imag:+.4f}j (complex)"],
            ["Td matching the damping only (s)", "–", _f(dmp.delay)]]
    return Item.from_verdict("section512", "Section 5.1.2: the analytical estimate (Lambert W)", verdict,
                             [(["", "paper", "delaykit"], rows)], [fig],
                             ["The printed roots follow from the rounded ζ and ωn (the root is computed from the "
                              "printed ζ = 0.7684 and ωn = 1.6069, as the paper did).", *dmp.warnings])


def _table3(out: Path) -> Item:
    from ..plotting.figures import plot_spectrum

    rows = table3()
    spectra = [find_roots(AltitudeLoop(kp=TABLE3_KP, delay=TABLE3_DELAY, kv=r.kv).characteristic(), (-10, 2, 0, 100))
               for r in rows]
    fig = out / "fig8_spectra.png"
    plot_spectrum(spectra, fig, labels=[f"Kv = {r.kv:g}" for r in rows],
                  title="Fig. 8 redone: s + (2 + Kv s) exp(-0.37 s), roots in [-10, 2] x [0, 100]")
    verdict = table3_check(rows)
    conclusion = table3_conclusion_check([r.kv for r in rows], [r.rightmost.real for r in rows])
    body = [[f"{r.kv:g}", _c(r.paper, 2), _c(r.rightmost), _f(r.neutral_line), "yes" if r.agrees else "no"]
            for r in rows]
    header = ["Kv", "paper", "delaykit rightmost", "neutral line ln(Kv)/Td", "agrees"]
    notes = ["All spectra certified by the argument principle.",
             f"The paper's conclusion (Kv = {PAPER_BEST_KV:g} is the most stable): {conclusion.text}."]
    return Item.from_verdict("table3", "Table 3 and Fig. 8: rightmost roots of the PV loop (Kp = 2.0, Td = 0.37 s)",
                             verdict, [(header, body)], [fig], notes, checks={"conclusion": conclusion})


def _table4(out: Path) -> Item:
    from ..plotting.figures import plot_responses

    variants = {
        "filter, saturation, sampled 0.065 s": dict(velocity="filtered", period=PAPER_PERIOD),
        "filter, saturation, continuous": dict(velocity="filtered"),
        "true velocity, saturation, sampled": dict(velocity="true", period=PAPER_PERIOD),
        "filter, no saturation, continuous": dict(velocity="filtered", vmax=None),
    }
    res = {}
    for name, kw in variants.items():
        res[name] = [simulate(AltitudeLoop(kp=TABLE3_KP, delay=TABLE3_DELAY, kv=kv, **kw), 1.0).metrics
                     for kv in TABLE4["kv"]]
    dev = {}
    for name, ms in res.items():
        d_mo = max(abs(m.overshoot - p) for m, p in zip(ms, TABLE4["overshoot"]))
        d_tp = max(abs((m.peak_time or math.inf) - p) for m, p in zip(ms, TABLE4["peak_time"]))
        d_ts = max(abs((m.settling_time or math.inf) - p) for m, p in zip(ms, TABLE4["settling_time"]))
        dev[name] = (d_mo, d_tp, d_ts)
    best = min(dev, key=lambda k: dev[k][0] + 10 * dev[k][1] + 10 * dev[k][2])
    d = dev[best]
    fig = out / "fig9_pv_responses.png"
    loops = [AltitudeLoop(kp=TABLE3_KP, delay=TABLE3_DELAY, kv=kv, **variants[best]) for kv in TABLE4["kv"]]
    plot_responses([simulate(lp, 1.0, t_end=6.0) for lp in loops], fig, labels=[f"Kv = {kv:g}" for kv in TABLE4["kv"]],
                   title=f"Fig. 9 redone: PV control, Kp = 2.0, Td = 0.37 s ({best})")
    verdict = table4_check(best, d)
    header = ["configuration", "quantity"] + [f"Kv = {kv:g}" for kv in TABLE4["kv"]] + ["largest deviation"]
    body = [["paper", "Mo (%)"] + [f"{x:.2f}" for x in TABLE4["overshoot"]] + [""],
            ["paper", "tp (s)"] + [f"{x:.2f}" for x in TABLE4["peak_time"]] + [""],
            ["paper", "ts (s)"] + [f"{x:.2f}" for x in TABLE4["settling_time"]] + [""]]
    for name, ms in res.items():
        body.append([name, "Mo (%)"] + [f"{m.overshoot:.2f}" for m in ms] + [f"{dev[name][0]:.2f} pp"])
        body.append([name, "tp (s)"] + [_f(m.peak_time, 2) for m in ms] + [f"{dev[name][1]:.3f} s"])
        body.append([name, "ts (s)"] + [_f(m.settling_time, 2) for m in ms] + [f"{dev[name][2]:.3f} s"])
    design_text = simulate(AltitudeLoop(kp=TABLE3_KP, delay=TABLE3_DELAY, kv=PAPER_PV_KV), 1.0).metrics
    design_verdict = design_text_check(design_text.overshoot, design_text.settling_time, design_text.peak_time)
    notes = ["The filter: poles at -38 rad/s (repeated), W(s) = wf^2 s / (s^2 + 2 zf wf s + wf^2); the controller "
             "samples at Ts = 0.065 s with the step on a sample.",
             f"The paper's design text quotes Mo = 0.44 %, ts = 1.52 s, tp = 1.76 s for Kp = 2.0, Kv = 0.3 without the "
             f"filter; the continuous true-velocity loop gives Mo = {design_text.overshoot:.2f} %, ts = "
             f"{_f(design_text.settling_time, 2)} s, tp = {_f(design_text.peak_time, 2)} s: {design_verdict.text}."]
    return Item.from_verdict("table4", "Table 4 and Fig. 9: PV control with the derivative filter (simulated rows)",
                             verdict, [(header, body)], [fig], notes, checks={"design_text": design_verdict})


def _fig5(out: Path) -> Item:
    from ..plotting.figures import plot_responses

    kps = (1.0, 1.31, 1.6, 2.0)
    td = estimate_overshoot(PAPER_MO, TABLE1_KP).delay
    rs = [simulate(AltitudeLoop(kp=k, delay=td), 1.0, t_end=8.0) for k in kps]
    fig = out / "fig5_p_responses.png"
    plot_responses(rs, fig, labels=[f"Kp = {k:g}" for k in kps], title=f"Fig. 5's simulated counterpart: P control, Td = {td:.4f} s")
    body = [[f"{k:g}", f"{r.metrics.overshoot:.3f}", _f(r.metrics.peak_time, 3), _f(r.metrics.rise_time, 3),
             _f(r.metrics.settling_time, 3)] for k, r in zip(kps, rs)]
    verdict = fig5_check(list(kps), [r.metrics.overshoot for r in rs], [r.metrics.rise_time for r in rs])
    return Item.from_verdict("fig5", "Fig. 5's counterpart: P-loop responses for several Kp (simulated)", verdict,
                [(["Kp", "Mo (%)", "tp (s)", "rise (s)", "ts (s)"], body)], [fig],
                ["The paper's Fig. 5 is measured; this is the model at the estimated delay. The measured responses "
                 "are slower (peak near 3 s, not 2 s): see section 5.1.1."])


def _filter(out: Path) -> Item:
    from ..plotting.figures import plot_filter_bode

    f = filter_analysis()
    fig = out / "fig_filter_bode.png"
    plot_filter_bode(f, fig)
    body = [[k, f"{v:.2f}"] for k, v in f.candidates.items()]
    return Item("filter", "The derivative filter: which form the quoted numbers fit", f.verdict, f.status,
                [(["reading of 'cutoff' (wf = 38 rad/s, zf = 1)", "rad/s"], body)], [fig],
                [f"The poles {f.poles[0].real:g} (repeated) fit W(s) = wf^2 s / (s + wf)^2 exactly. At the PV loop's "
                 f"crossover ({_f(f.crossover, 2)} rad/s) the filter lags the true velocity by "
                 f"{_f(f.phase_lag_at_crossover, 1)} degrees."])


def _markdown(items: list[Item]) -> str:
    lines = ["# The paper, regenerated by delaykit", "",
             "Armah & Yi, *Altitude Regulation of Quadrotor Types of UAVs Considering Communication Delays*.", ""]
    lines.append("| item | verdict |")
    lines.append("|---|---|")
    for it in items:
        lines.append(f"| {it.title} | {it.verdict} |")
    for it in items:
        lines += ["", f"## {it.title}", "", f"**Verdict:** {it.verdict}", ""]
        for header, rows in it.tables:
            lines.append("| " + " | ".join(header) + " |")
            lines.append("|" + "---|" * len(header))
            lines += ["| " + " | ".join(r) + " |" for r in rows]
            lines.append("")
        for fig in it.figures:
            lines.append(f"![{fig.stem}]({fig.name})")
            lines.append("")
        lines += [f"- {n}" for n in it.notes]
        lines += [f"- Check '{k}' ({v.status}): {v.text}" for k, v in it.checks.items()
                  if v.text not in " ".join(it.notes)]
    return "\n".join(lines) + "\n"


def _html(items: list[Item]) -> str:
    esc = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>delaykit: the paper regenerated</title>",
             "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;line-height:1.4}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:3px 7px;text-align:right}"
             "th{background:#eee}.verdict{background:#f4f8ff;padding:.5em;border-left:4px solid #36c}"
             "img{max-width:100%}</style></head><body>",
             "<h1>The paper, regenerated by delaykit</h1>",
             "<p>Armah &amp; Yi, <i>Altitude Regulation of Quadrotor Types of UAVs Considering Communication Delays</i>.</p>",
             "<table class='summary'><tr><th>item</th><th>verdict</th></tr>"]
    parts += [f"<tr><td>{esc(i.title)}</td><td style='text-align:left'>{esc(i.verdict)}</td></tr>" for i in items]
    parts.append("</table>")
    for it in items:
        parts.append(f"<section id='{it.key}'><h2>{esc(it.title)}</h2><p class='verdict'>{esc(it.verdict)}</p>")
        for header, rows in it.tables:
            parts.append("<table class='data'><tr>" + "".join(f"<th>{esc(h)}</th>" for h in header) + "</tr>")
            parts += ["<tr>" + "".join(f"<td>{esc(c)}</td>" for c in r) + "</tr>" for r in rows]
            parts.append("</table>")
        for fig in it.figures:
            data = base64.b64encode(fig.read_bytes()).decode()
            parts.append(f"<img alt='{esc(fig.stem)}' src='data:image/png;base64,{data}'>")
        parts += [f"<p>{esc(n)}</p>" for n in it.notes]
        parts += [f"<p>Check '{esc(k)}' ({esc(v.status)}): {esc(v.text)}</p>" for k, v in it.checks.items()
                  if v.text not in " ".join(it.notes)]
        parts.append("</section>")
    parts.append("<script>window.addEventListener('load',function(){var im=document.images,ok=0;"
                 "for(var i=0;i<im.length;i++){if(im[i].complete&&im[i].naturalWidth>0)ok++;}"
                 "document.body.setAttribute('data-images',im.length);document.body.setAttribute('data-images-ok',ok);"
                 "document.body.setAttribute('data-tables',document.querySelectorAll('table.data').length);});</script>")
    parts.append("</body></html>")
    return "\n".join(parts)


def reproduce(out: str | Path = "out", progress: Callable[[str, int, int], None] | None = None) -> Reproduction:
    """Regenerate the paper's tables and figures into ``out`` (``report.md``, ``index.html``, PNGs, ``report.json``).

    ``progress(stage, done, total)`` is called before each item.
    """
    out = check_path("output folder", out)
    out.mkdir(parents=True, exist_ok=True)
    stages = [("Table 1", lambda: _table1(out)), ("section 5.1.1", _section511), ("section 5.1.2", lambda: _section512(out)),
              ("Table 3 and Fig. 8", lambda: _table3(out)), ("Table 4 and Fig. 9", lambda: _table4(out)),
              ("Fig. 5 counterpart", lambda: _fig5(out)), ("the derivative filter", lambda: _filter(out))]
    items = []
    for i, (name, fn) in enumerate(stages):
        if progress:
            progress(name, i, len(stages))
        items.append(fn())
    if progress:
        progress("writing", len(stages), len(stages))
    md = out / "report.md"
    page = out / "index.html"
    js = out / "report.json"
    rep = Reproduction(out=out, items=tuple(items), files=(md, page, js, *[f for it in items for f in it.figures]))
    for path, text in ((md, _markdown(items)), (page, _html(items)), (js, json.dumps(rep.to_dict(), indent=2))):
        with writing("the report file", path):
            path.write_text(text)
    return rep
