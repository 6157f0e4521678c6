"""Table 1 regenerated, with a figure, into a folder (`delaykit report`; `delaykit reproduce` does every table).

Examples
--------
>>> import tempfile
>>> rep = write_report(tempfile.mkdtemp())
>>> rep.verdict.startswith("reproduced to within solver error"), rep.status
(True, 'reproduced')

Every verdict here is decided by a tolerance check whose tolerance is written into the verdict, and carries a
``status`` ("reproduced", "not reproduced" or "not checked") that code can test without reading the text.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Literal, Mapping

from ..errors import InvalidTypeError, InvalidValueError, check_path, writing
from ..models.altitude import PAPER_PERIOD
from ..plotting.figures import plot_responses
from ..simulate.simulation import simulate
from .data import TABLE1_KP, Table1Row, paper_loop, table1

__all__ = ["Report", "Verdict", "Status", "write_report", "table1_check", "table1_verdict", "variants_check",
           "table1_markdown", "plot_table1_responses", "SOLVER_TOLERANCE_PP", "SOLVER_TOLERANCE_S", "TABLE1_MODEL"]

Status = Literal["reproduced", "not reproduced", "not checked"]
STATUSES: tuple[str, ...] = ("reproduced", "not reproduced", "not checked")

#: Solver error in overshoot, percentage points: a first-order fixed-step solver with a step near 1 ms adds
#: about half a step of delay, about 0.03 pp at the 58 pp/s slope near Td = 0.37 s; 0.05 pp allows for it.
SOLVER_TOLERANCE_PP = 0.05
#: Solver error in delay, seconds: half of the 1 ms step a first-order fixed-step solver acts as extra delay.
SOLVER_TOLERANCE_S = 0.5e-3
#: The loop behind Table 1 in :func:`write_report`'s comparison of model variants.
TABLE1_MODEL = "continuous, saturated (the model of Table 1)"


@dataclass(frozen=True)
class Verdict:
    """A verdict: its ``status`` (for programs) and its ``text`` (for people), which starts with the status
    and states the tolerance the decision used.

    Examples
    --------
    >>> v = Verdict("reproduced", "reproduced: |0.3743 - 0.374| = 0.0003 s <= 0.0005 s")
    >>> v.status, str(v)[:10]
    ('reproduced', 'reproduced')
    """

    status: Status
    text: str

    def __post_init__(self) -> None:
        for name in ("status", "text"):
            if not isinstance(getattr(self, name), str):
                raise InvalidTypeError(f"a verdict's {name} must be a str, got {type(getattr(self, name)).__name__} "
                                       f"{getattr(self, name)!r}")
        if self.status not in STATUSES:
            raise InvalidValueError(f"status {self.status!r} is not one of {', '.join(map(repr, STATUSES))}")
        if not self.text.startswith(self.status):
            raise InvalidValueError(f"the verdict text must start with its status {self.status!r}: {self.text!r}")

    def __str__(self) -> str:
        return self.text

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"status": self.status, "verdict": self.text}


@dataclass(frozen=True, repr=False)
class Report:
    """What :func:`write_report` wrote, and Table 1's verdict."""

    out: Path
    files: tuple[Path, ...]
    rows: tuple[Table1Row, ...]
    variants: dict[str, float]
    verdict: str
    status: Status
    variants_verdict: Verdict | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"out": str(self.out), "files": [str(f) for f in self.files],
                "table1": [r.to_dict() for r in self.rows], "variants": self.variants, "verdict": self.verdict,
                "status": self.status,
                "variants_verdict": None if self.variants_verdict is None else self.variants_verdict.to_dict()}

    def __repr__(self) -> str:
        return f"Report({self.out}, {len(self.files)} files: {self.verdict})"


def table1_check(rows: list[Table1Row] | tuple[Table1Row, ...], tolerance: float = SOLVER_TOLERANCE_PP) -> Verdict:
    """Does the converged computation reproduce Table 1: every printed overshoot within ``tolerance`` percentage
    points (the solver error, :data:`SOLVER_TOLERANCE_PP`) of the exact one, above it (the solver's error
    acts as extra delay), and the printed zeros exactly zero.

    Examples
    --------
    >>> from .data import Table1Row
    >>> row = Table1Row(K=5.0, delay=0.325, paper_overshoot=0.419, overshoot=0.398, equivalent_delay=0.3254)
    >>> table1_check([row]).status, table1_check([row], tolerance=0.01).status
    ('reproduced', 'not reproduced')
    """
    diffs = [r.difference for r in rows if r.paper_overshoot > 0]
    extras = [r.extra_delay for r in rows if r.extra_delay is not None]
    zero_ok = all(r.overshoot < 1e-9 for r in rows if r.paper_overshoot == 0.0)
    worst = max((abs(d) for d in diffs), default=math.nan)
    if zero_ok and diffs and worst <= tolerance and all(e > 0 for e in extras):
        ex = (f", which is what {1e3 * min(extras):.2f} to {1e3 * max(extras):.2f} ms of extra delay gives (about half "
              "the step of a first-order solver with a 1 ms step)") if extras else ""
        return Verdict("reproduced", (
            f"reproduced to within solver error: the printed overshoots are {min(diffs):.3f} to {max(diffs):.3f} "
            f"percentage points above the exact ones (largest |paper - delaykit| = {worst:.4f} pp <= {tolerance:g} pp, "
            f"the solver error){ex}"))
    why = []
    if not zero_ok:
        why.append("a printed 0.000 % is not zero here")
    if not diffs or not worst <= tolerance:
        why.append(f"largest |paper - delaykit| = {worst:.4f} pp > {tolerance:g} pp (the solver error)")
    if not all(e > 0 for e in extras):
        why.append("some printed overshoots are below the exact ones (a first-order solver's error adds delay)")
    return Verdict("not reproduced", "not reproduced: " + "; ".join(why) + ": " + "; ".join(repr(r) for r in rows))


def table1_verdict(rows: list[Table1Row] | tuple[Table1Row, ...]) -> str:
    """One sentence: does the converged computation reproduce Table 1, and how closely (see :func:`table1_check`)."""
    return table1_check(rows).text


def variants_check(variants: Mapping[str, float], paper_overshoot: float = 2.300, model: str = TABLE1_MODEL,
                   tolerance: float = SOLVER_TOLERANCE_PP) -> Verdict:
    """Is ``model`` the only variant whose overshoot is within ``tolerance`` pp (the solver error) of the
    paper's ``paper_overshoot`` (2.300 % at Td = 5.6646 Ts)?

    Examples
    --------
    >>> v = {TABLE1_MODEL: 2.2745, "continuous, no saturation": 2.9795}
    >>> variants_check(v).status, variants_check(v, paper_overshoot=2.98).status
    ('reproduced', 'not reproduced')
    """
    dist = {k: abs(v - paper_overshoot) for k, v in variants.items()}
    fits = [k for k, d in dist.items() if d <= tolerance]
    detail = "; ".join(f"{k}: |{variants[k]:.4f} - {paper_overshoot:.3f}| = {d:.4f} pp "
                       f"{'<=' if d <= tolerance else '>'} {tolerance:g} pp" for k, d in dist.items())
    rule = f"(tolerance {tolerance:g} pp, the solver error)"
    if fits == [model]:
        return Verdict("reproduced", f"reproduced: only the {model.split(' (')[0]} loop is within solver error of the "
                                     f"printed {paper_overshoot:.3f} % {rule}: {detail}")
    which = ", ".join(fits) if fits else "none"
    return Verdict("not reproduced", f"not reproduced: the variants within solver error of the printed "
                                     f"{paper_overshoot:.3f} % {rule} are: {which}; {detail}")


def table1_markdown(rows: list[Table1Row] | tuple[Table1Row, ...]) -> str:
    """Table 1 with the paper's and delaykit's overshoot side by side, as Markdown."""
    lines = [
        "| K | Td = K·Ts (s) | paper Mo (%) | delaykit Mo (%) | paper − delaykit | delay giving the paper's Mo (s) | extra (ms) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        eq = "–" if r.equivalent_delay is None else f"{r.equivalent_delay:.5f}"
        ex = "–" if r.extra_delay is None else f"{1e3 * r.extra_delay:+.3f}"
        lines.append(f"| {r.K:.4f} | {r.delay:.5f} | {r.paper_overshoot:.3f} | {r.overshoot:.4f} | "
                     f"{r.difference:+.4f} | {eq} | {ex} |")
    return "\n".join(lines)


def plot_table1_responses(path: str | Path | None = None, *, ax: Any = None) -> Any:
    """The responses of Table 1's loop for four of its delays (K = 4, 5, 5.6, 5.6646): the figure, written to
    ``path`` when one is given (``ax``: draw into these axes, as :func:`~delaykit.plotting.figures.plot_responses`).

    Examples
    --------
    >>> fig = plot_table1_responses()
    >>> [line.get_label() for line in fig.axes[0].lines][:2]
    ['K=4, Td=0.2600 s', 'K=5, Td=0.3250 s']
    """
    ks = (4.0, 5.0, 5.6, 5.6646)
    return plot_responses([simulate(paper_loop(k * PAPER_PERIOD)) for k in ks], path, ax=ax,
                          labels=[f"K={k:g}, Td={k * PAPER_PERIOD:.4f} s" for k in ks],
                          title=f"P control, Kp = {TABLE1_KP}, ±1 m/s, 1 m step (the loop behind Table 1)", t_max=6.0)


def write_report(out: str | Path = "out", progress: Callable[[str], None] | None = None) -> Report:
    """Regenerate Table 1 (P control, Kp = 1.31) with a figure of the responses, into ``out``.

    Writes ``table1.md``, ``table1.json`` and ``responses.png``.

    Parameters
    ----------
    out : str or Path
        Output folder (created).
    progress : callable, optional
        Called with a short description before each stage.

    Returns
    -------
    Report
    """
    say = progress or (lambda _msg: None)
    out = check_path("output folder", out)
    out.mkdir(parents=True, exist_ok=True)
    say("Table 1: exact overshoot at each K·Ts")
    rows = tuple(table1())
    check = table1_check(rows)
    say("model variants at the paper's estimate")
    td = 5.6646 * PAPER_PERIOD
    variants = {
        TABLE1_MODEL: simulate(paper_loop(td)).metrics.overshoot,
        "continuous, no saturation": simulate(paper_loop(td).replace(vmax=None)).metrics.overshoot,
        "sampled every 0.065 s, saturated": simulate(paper_loop(td).replace(period=PAPER_PERIOD)).metrics.overshoot,
    }
    vcheck = variants_check(variants)
    say("figure of the responses")
    fig = out / "responses.png"
    plot_table1_responses(fig)
    md = out / "table1.md"
    _write(
        md,
        "# Table 1: overshoot against delay (P control, Kp = 1.31, ±1 m/s, 1 m step)\n\n"
        + table1_markdown(rows)
        + f"\n\nVerdict: {check.text}.\n\n"
        + f"## The same loop at Td = 5.6646·Ts = {td:.5f} s, other model variants\n\n"
        + "| model | Mo (%) |\n|---|---|\n"
        + "\n".join(f"| {k} | {v:.4f} |" for k, v in variants.items())
        + f"\n\nVerdict on the variants: {vcheck.text}.\n"
        + "\n![responses](responses.png)\n"
    )
    js = out / "table1.json"
    rep = Report(out=out, files=(md, js, fig), rows=rows, variants=variants, verdict=check.text,
                 status=check.status, variants_verdict=vcheck)
    _write(js, json.dumps(rep.to_dict(), indent=2))
    return rep


def _write(path: Path, text: str) -> None:
    """Write one file of the report; a failure (the disk full) an OutputError naming it."""
    with writing("the report file", path):
        path.write_text(text)
