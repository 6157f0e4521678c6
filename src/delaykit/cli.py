"""The ``delaykit`` command line: a thin layer over the library.

Every command has ``--help``; those that print results have ``--json``; figures are written only where
``--plot FILE`` asks.  Bad input prints one line, ``error: ...``, and exits with status 2.
"""

from __future__ import annotations

import csv
import functools
import json
import math
import sys
from pathlib import Path
from typing import Any, Callable, Optional

import typer
from rich.console import Console
from rich.table import Table

from .errors import DelaykitError, InvalidValueError, check_real
from .model import PAPER_PERIOD, AltitudeLoop
from .paper import TABLE1, table1_overshoot

__all__ = ["app", "main", "parse_delays"]

app = typer.Typer(
    help="delaykit: feedback loops with a time delay (the quadrotor altitude loop of Armah & Yi).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
out = Console(soft_wrap=True)
err = Console(stderr=True)


def _friendly(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Turn delaykit's errors into one line on stderr and exit status 2."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except DelaykitError as exc:
            err.print(f"[bold red]error:[/] {exc}", highlight=False)
            raise typer.Exit(2) from None

    return wrapper


def parse_delays(spec: str) -> list[float]:
    """Delays from ``0.368``, ``START:STOP:N``, ``a,b,c`` or ``table1`` (the K·Ts of the paper's Table 1).

    Examples
    --------
    >>> parse_delays("0.2:0.5:4")
    [0.2, 0.3, 0.4, 0.5]
    >>> len(parse_delays("table1"))
    7
    """
    spec = spec.strip()
    if spec.lower() == "table1":
        return [k * PAPER_PERIOD for k, _, _ in TABLE1]
    try:
        if ":" in spec:
            parts = spec.split(":")
            if len(parts) != 3:
                raise ValueError
            a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
            if n < 1:
                raise InvalidValueError(f"delay sweep {spec!r}: N must be at least 1, got {n}")
            if n > 1 and not b > a:
                raise InvalidValueError(f"delay sweep {spec!r}: STOP must be greater than START")
            return [a] if n == 1 else [a + (b - a) * i / (n - 1) for i in range(n)]
        return [float(x) for x in spec.split(",")]
    except ValueError:
        raise InvalidValueError(
            f"--delay {spec!r} is not a delay: give seconds (0.368), START:STOP:N, a comma list, or 'table1'"
        ) from None


def _optional_float(name: str, text: Optional[str]) -> Optional[float]:
    if text is None or text.strip().lower() in ("none", "off", "inf"):
        return None
    try:
        return float(text)
    except ValueError:
        raise InvalidValueError(f"{name} must be a number or 'none', got {text!r}") from None


def _fmt(x: Optional[float], digits: int = 4) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


@app.command()
@_friendly
def simulate(
    kp: float = typer.Option(..., "--kp", help="Proportional gain Kp (1/s)."),
    delay: str = typer.Option(..., "--delay", help="Delay Td in s; or START:STOP:N, a comma list, or 'table1'."),
    kv: float = typer.Option(0.0, "--kv", help="Velocity gain Kv (0 = P control)."),
    step: float = typer.Option(1.0, "--step", help="Reference step, m (either sign)."),
    z0: float = typer.Option(0.0, "--z0", help="Altitude before the step, m."),
    vmax: str = typer.Option("1.0", "--vmax", help="Command saturation, m/s, or 'none'."),
    velocity: str = typer.Option("true", "--velocity", help="Velocity for the Kv term: true | filtered."),
    filter_wn: float = typer.Option(38.0, "--filter-wn", help="Derivative filter natural frequency, rad/s."),
    filter_zeta: float = typer.Option(1.0, "--filter-zeta", help="Derivative filter damping ratio."),
    period: Optional[str] = typer.Option(None, "--period", help="Controller period, s (default: continuous)."),
    sample_offset: float = typer.Option(0.0, "--sample-offset", help="First sample time after the step, s."),
    t_end: float = typer.Option(15.0, "--t-end", help="Simulated time after the step, s."),
    band: float = typer.Option(0.02, "--band", help="Settling band, fraction of the step."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON instead of a table."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Write a figure of the response(s) here."),
    csv_path: Optional[Path] = typer.Option(None, "--csv", help="Write t, z, z_ref, u samples here."),
    dt: float = typer.Option(0.01, "--dt", help="Sample interval of --csv, s."),
) -> None:
    """Simulate the altitude loop's step response exactly and print its metrics.

    With a sweep of delays it prints one row per delay; for the delays of the paper's Table 1
    (--delay table1, with --kp 1.31) the paper's overshoot is shown beside delaykit's.
    """
    from .simulation import simulate as sim

    delays = parse_delays(delay)
    base = AltitudeLoop(kp=kp, delay=delays[0], kv=kv, vmax=_optional_float("--vmax", vmax), velocity=velocity,
                        filter_wn=filter_wn, filter_zeta=filter_zeta, period=_optional_float("--period", period),
                        sample_offset=sample_offset)
    check_real("--dt", dt, minimum=0.0, strict=True)
    with err.status("simulating (the first run compiles the solver, a few seconds)…"):
        responses = [sim(base.replace(delay=d), step, z0=z0, t_end=t_end, band=band) for d in delays]
    paper_cfg = kp == 1.31 and kv == 0 and base.vmax == 1.0 and not base.sampled and step == 1.0
    rows = []
    for r in responses:
        row = {"delay": r.loop.delay, **r.to_dict()}
        if paper_cfg and table1_overshoot(r.loop.delay) is not None:
            row["paper_overshoot"] = table1_overshoot(r.loop.delay)
        rows.append(row)
    if csv_path is not None:
        with open(csv_path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow((["delay"] if len(responses) > 1 else []) + ["t", "z", "z_ref", "u"])
            for r in responses:
                s = r.sample(dt=dt)
                for i in range(s["t"].size):
                    vals = [f"{s[k][i]:.9g}" for k in ("t", "z", "z_ref", "u")]
                    w.writerow(([f"{r.loop.delay:.9g}"] if len(responses) > 1 else []) + vals)
    if plot is not None:
        from .plots import plot_responses

        plot_responses(responses, plot, title=repr(base.replace(delay=delays[0])) if len(delays) == 1 else None)
    if as_json:
        print(json.dumps(rows[0] if len(rows) == 1 else rows, indent=2))
        return
    title = repr(base) if len(delays) == 1 else repr(base).replace(f"delay={base.delay:.4g} s, ", "")
    table = Table(title=title)
    table.add_column("Td s", justify="right")
    table.add_column("Mo %", justify="right")
    if any("paper_overshoot" in r for r in rows):
        table.add_column("paper Mo %", justify="right")
        table.add_column("paper−ours", justify="right")
    for col in ("peak s", "rise s", "settle s"):
        table.add_column(col, justify="right")
    for r in rows:
        cells = [f"{r['delay']:.5f}", _fmt(r["overshoot"])]
        if any("paper_overshoot" in x for x in rows):
            p = r.get("paper_overshoot")
            cells += [_fmt(p, 3), "–" if p is None else f"{p - r['overshoot']:+.4f}"]
        cells += [_fmt(r["peak_time"]), _fmt(r["rise_time"]),
                  _fmt(r["settling_time"]) if r["settled"] else "never"]
        table.add_row(*cells)
    out.print(table)


@app.command()
@_friendly
def report(
    out_dir: Path = typer.Option(Path("out"), "--out", help="Folder to write the report into."),
    as_json: bool = typer.Option(False, "--json", help="Print the results as JSON."),
) -> None:
    """Regenerate the paper's Table 1 with a figure into --out (the main job of `make run`)."""
    from .report import table1_markdown, write_report

    with err.status("writing the report…") as status:
        rep = write_report(out_dir, progress=lambda m: status.update(m))
    if as_json:
        print(json.dumps(rep.to_dict(), indent=2))
        return
    from rich.markdown import Markdown

    out.print(Markdown("## Table 1 (Kp = 1.31, P control, ±1 m/s)\n\n" + table1_markdown(rep.rows)))
    out.print(f"\nVerdict: {rep.verdict}.\n", highlight=False)
    out.print("Wrote " + ", ".join(str(f) for f in rep.files), highlight=False)


def main() -> None:
    """Entry point of the ``delaykit`` script."""
    app(prog_name="delaykit")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
