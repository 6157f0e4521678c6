"""``delaykit report``, ``reproduce`` and ``demo``: the paper's tables checked, and the emulated flight demo."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer
from rich.table import Table

from ..errors import InvalidValueError, check_real
from .common import confirm_real, err, fmt_ci, friendly, out

__all__ = ["demo", "report", "reproduce"]


@friendly
def report(
    out_dir: Path = typer.Option(Path("out"), "--out", help="Folder to write the report into."),
    as_json: bool = typer.Option(False, "--json", help="Print the results as JSON."),
) -> None:
    """Regenerate only the paper's Table 1, with a figure, into --out (see `reproduce` for everything)."""
    from ..paper.report import table1_markdown, write_report

    with err.status("writing the report…") as status:
        rep = write_report(out_dir, progress=lambda m: status.update(m))
    if as_json:
        print(json.dumps(rep.to_dict(), indent=2))
        return
    from rich.markdown import Markdown

    out.print(Markdown("## Table 1 (Kp = 1.31, P control, ±1 m/s)\n\n" + table1_markdown(rep.rows)))
    out.print(f"\nVerdict: {rep.verdict}.\n", highlight=False)
    out.print("Wrote " + ", ".join(str(f) for f in rep.files), highlight=False)


@friendly
def reproduce(
    out_dir: Path = typer.Option(Path("out"), "--out", help="Folder for report.md, index.html and the figures."),
    as_json: bool = typer.Option(False, "--json", help="Print the verdicts as JSON."),
) -> None:
    """Regenerate the paper's tables and figures, with the paper's values beside delaykit's and a verdict each."""
    from rich.progress import Progress

    from ..paper.reproduce import reproduce as run

    with Progress(console=err, transient=True) as bar:
        task = bar.add_task("reproducing the paper", total=None)  # the total comes with the first report
        rep = run(out_dir, progress=lambda name, done, total: bar.update(task, completed=done, total=total,
                                                                           description=name))
    if as_json:
        print(json.dumps(rep.to_dict(), indent=2))
        return
    table = Table(title="The paper, regenerated")
    table.add_column("item", justify="left")
    table.add_column("verdict", justify="left")
    for it in rep.items:
        table.add_row(it.title, it.verdict)
    out.print(table)
    out.print(f"Wrote {out_dir / 'report.md'} and {out_dir / 'index.html'} (open it in a browser).", highlight=False)


@friendly
def demo(
    out_dir: Path = typer.Option(Path("out/demo"), "--out", help="Folder for the report, logs and figures."),
    host: Optional[str] = typer.Option(None, "--host", help="A real drone (default: the built-in emulator)."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Seed of the emulator (its hidden delay and noise)."),
    p_steps: int = typer.Option(5, "--p-steps", help="P-control step tests."),
    step_duration: float = typer.Option(8.0, "--step-duration", help="Seconds after each step."),
    compensate: bool = typer.Option(True, "--compensate/--no-compensate", help="Also design the delay compensators and fly the best."),
    varying_steps: int = typer.Option(6, "--varying-steps", help="Emulator only: steps of the flight whose delay grows mid-flight (0: none)."),
    delay_jump: float = typer.Option(0.15, "--delay-jump", help="Emulator only: how much that flight's delay grows, s."),
    yes: bool = typer.Option(False, "--yes", help="Do not ask before taking off a real drone."),
    as_json: bool = typer.Option(False, "--json", help="Print the result as JSON."),
) -> None:
    """The whole pipeline: fly P step tests, estimate the delay, design PV gains and the delay compensators, fly
    them, fly once more while the emulator's delay grows (the delay monitor's alarm), and report."""
    from ..paper.demo import run_demo

    if p_steps < 1:
        raise InvalidValueError(f"--p-steps must be at least 1, got {p_steps}")
    if varying_steps < 0:
        raise InvalidValueError(f"--varying-steps must be at least 0, got {varying_steps}")
    check_real("--delay-jump (s)", delay_jump, minimum=0.0, maximum=2.0)
    with err.status("starting") as st:
        rep = run_demo(out_dir, host=host, seed=seed, p_steps=p_steps, step_duration=step_duration,
                       compensate=compensate, varying_steps=varying_steps, delay_jump=delay_jump,
                       confirm=confirm_real(host, yes) if host else None, status=lambda m: st.update(m))
    if as_json:
        print(json.dumps(rep.to_dict(), indent=2, default=str))
        return
    e = rep.estimate
    interval = "no interval" if e.ci is None else f"95 % {fmt_ci(e.ci)}"
    out.print(f"Estimated delay {e.delay:.4f} s ± {e.stderr or 0:.4f} ({interval}) from "
              f"{e.flights} step tests" + (f"; the emulator's truth is {rep.true_delay:.4f} s (error "
                                          f"{1e3 * rep.error:+.1f} ms)" if rep.true_delay is not None else "") + ".",
              highlight=False)
    import numpy as np

    pm = np.mean([m["settling_time"] or np.nan for m in rep.p_metrics])
    vm = np.mean([m["settling_time"] or np.nan for m in rep.pv_metrics])
    out.print(f"PV design: Kp = {rep.pv_kp:g}, Kv = {rep.kv:g} ({rep.kv_source}). Mean settling time: P {pm:.2f} s, "
              f"PV {vm:.2f} s.", highlight=False)
    if rep.comp_metrics:
        cm = np.mean([m["settling_time"] or np.nan for m in rep.comp_metrics])
        out.print(f"Compensator flown: {rep.compensator['chosen']} (model delay {rep.compensator['model_delay']:.4f} s); "
                  f"mean settling time {cm:.2f} s.", highlight=False)
    if rep.varying_flight is not None:
        v = rep.varying_flight
        out.print(f"Delay moving from {rep.varying_truth['before']:.3f} to {rep.varying_truth['after']:.3f} s: "
                  f"{len(v.online)} online estimates, {v.alarms} alarm(s), "
                  f"{sum(o.action == 'redesigned' for o in v.online)} re-design(s).", highlight=False)
    out.print(f"Report: {out_dir / 'demo.md'}", highlight=False)
