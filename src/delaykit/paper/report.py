"""The main job until the later parts land: Table 1 regenerated, with a figure, into a folder.

Examples
--------
>>> import tempfile
>>> rep = write_report(tempfile.mkdtemp())
>>> rep.verdict.startswith("reproduced to within solver error")
True
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from ..models.altitude import PAPER_PERIOD
from ..plotting.figures import plot_responses
from ..simulate.simulation import simulate
from .data import TABLE1_KP, Table1Row, paper_loop, table1

__all__ = ["Report", "write_report", "table1_verdict", "table1_markdown", "plot_table1_responses"]


@dataclass(frozen=True, repr=False)
class Report:
    """What :func:`write_report` wrote, and Table 1's verdict."""

    out: Path
    files: tuple[Path, ...]
    rows: tuple[Table1Row, ...]
    variants: dict[str, float]
    verdict: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"out": str(self.out), "files": [str(f) for f in self.files],
                "table1": [r.to_dict() for r in self.rows], "variants": self.variants, "verdict": self.verdict}

    def __repr__(self) -> str:
        return f"Report({self.out}, {len(self.files)} files: {self.verdict})"


def table1_verdict(rows: list[Table1Row] | tuple[Table1Row, ...]) -> str:
    """One sentence: does the converged computation reproduce Table 1, and how closely."""
    diffs = [r.difference for r in rows if r.paper_overshoot > 0]
    extras = [r.extra_delay for r in rows if r.extra_delay is not None]
    zero_ok = all(r.overshoot < 1e-9 for r in rows if r.paper_overshoot == 0.0)
    if zero_ok and diffs and max(abs(d) for d in diffs) < 0.05 and all(e > 0 for e in extras):
        return (
            f"reproduced to within solver error: the printed overshoots are {min(diffs):.3f} to {max(diffs):.3f} "
            f"percentage points above the exact ones, which is what {1e3 * min(extras):.2f} to "
            f"{1e3 * max(extras):.2f} ms of extra delay gives (about half the step of a first-order solver "
            "with a 1 ms step)"
        )
    return "not reproduced: " + "; ".join(repr(r) for r in rows)


def table1_markdown(rows: list[Table1Row] | tuple[Table1Row, ...]) -> str:
    """Table 1 with the paper's and delaykit's overshoot side by side, as Markdown."""
    lines = [
        f"| K | Td = K·Ts (s) | paper Mo (%) | delaykit Mo (%) | paper − delaykit | delay giving the paper's Mo (s) | extra (ms) |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        eq = "–" if r.equivalent_delay is None else f"{r.equivalent_delay:.5f}"
        ex = "–" if r.extra_delay is None else f"{1e3 * r.extra_delay:+.3f}"
        lines.append(f"| {r.K:.4f} | {r.delay:.5f} | {r.paper_overshoot:.3f} | {r.overshoot:.4f} | "
                     f"{r.difference:+.4f} | {eq} | {ex} |")
    return "\n".join(lines)


def plot_table1_responses(path: str | Path) -> None:
    """The responses of Table 1's loop for four of its delays (K = 4, 5, 5.6, 5.6646), to ``path``."""
    ks = (4.0, 5.0, 5.6, 5.6646)
    plot_responses([simulate(paper_loop(k * PAPER_PERIOD)) for k in ks], path,
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
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    say("Table 1: exact overshoot at each K·Ts")
    rows = tuple(table1())
    verdict = table1_verdict(rows)
    say("model variants at the paper's estimate")
    td = 5.6646 * PAPER_PERIOD
    variants = {
        "continuous, saturated (the model of Table 1)": simulate(paper_loop(td)).metrics.overshoot,
        "continuous, no saturation": simulate(paper_loop(td).replace(vmax=None)).metrics.overshoot,
        "sampled every 0.065 s, saturated": simulate(paper_loop(td).replace(period=PAPER_PERIOD)).metrics.overshoot,
    }
    say("figure of the responses")
    fig = out / "responses.png"
    plot_table1_responses(fig)
    md = out / "table1.md"
    md.write_text(
        "# Table 1: overshoot against delay (P control, Kp = 1.31, ±1 m/s, 1 m step)\n\n"
        + table1_markdown(rows)
        + f"\n\nVerdict: {verdict}.\n\n"
        + f"## The same loop at Td = 5.6646·Ts = {td:.5f} s, other model variants\n\n"
        + "| model | Mo (%) |\n|---|---|\n"
        + "\n".join(f"| {k} | {v:.4f} |" for k, v in variants.items())
        + "\n\nOnly the continuous saturated loop is within solver error of the printed 2.300 %.\n"
        + "\n![responses](responses.png)\n"
    )
    js = out / "table1.json"
    rep = Report(out=out, files=(md, js, fig), rows=rows, variants=variants, verdict=verdict)
    js.write_text(json.dumps(rep.to_dict(), indent=2))
    return rep
