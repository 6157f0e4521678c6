"""``--system FILE`` of ``roots``, ``margins`` and ``simulate``: a delay system read from a TOML file of blocks.

The file's format is :mod:`delaykit.systems.files`'.  ``roots`` gives the interconnection's certified poles in a
region and its stability; ``margins`` gives the loop-at-a-time margins at the file's ``break`` signals and the
stability of the closed system; ``simulate`` its exact step response, input by input.  JSON is strict: a
non-finite number is printed as null.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..errors import InvalidValueError
from .common import check_output, err, out, print_json, warn

__all__ = ["system_margins", "system_roots", "system_simulate"]


def _stability(system: Any) -> tuple[bool | None, str]:
    from ..spectrum.systems import is_stable

    try:
        return is_stable(system), ""
    except InvalidValueError as exc:
        return None, str(exc)


def system_roots(path: Path, region: tuple[float, float, float, float], as_json: bool,
                 plot: Path | None = None) -> None:
    """Print the certified poles of a system file's interconnection in ``region`` and its stability; draw them,
    the region and any neutral lines to ``plot``."""
    from ..spectrum.systems import poles
    from ..systems.files import read_system_file

    check_output("--plot", plot, "figure")
    sf = read_system_file(path)
    sp = poles(sf.system, region)
    stable, why = _stability(sf.system)
    if plot is not None:
        from ..plotting.lti import pole_map

        pole_map(sp, path=plot, title=f"Poles of {sf.system.name or sf.source}")
    if as_json:
        data = {**sp.to_dict(), "system": repr(sf.system), "source": sf.source, "stable": stable,
                "stability_reason": why or None}
        print_json(data)
        return
    from .cmd_spectrum import print_roots_table

    print_roots_table(f"Poles of {sf.system!r} in {tuple(sp.region)}", sp)
    cert = "certified" if sp.certified else f"NOT certified: {sp.reason}"
    n = int(sp.multiplicities.sum())
    out.print(f"{n} pole{'' if n == 1 else 's'}, {cert} (argument principle: {sp.count}).", highlight=False,
              markup=False)
    verdict = {True: "stable", False: "UNSTABLE"}.get(stable, f"stability not decided: {why}")
    out.print(f"The system is {verdict}.", highlight=False, markup=False)


def system_margins(path: Path, as_json: bool, plot: Path | None = None) -> None:
    """Print the loop-at-a-time margins at a system file's break signals and the closed system's stability; draw
    each loop's Bode plot (its margins marked in its colour) and Nyquist plot to ``plot``."""
    from ..spectrum.frequency import margins
    from ..systems.files import read_system_file

    check_output("--plot", plot, "figure")
    sf = read_system_file(path)
    if not sf.loops:
        raise InvalidValueError(f"{sf.source}: margins need the signals where the loop is opened: add "
                                "break = [\"signal\", ...] to the file")
    stable, why = _stability(sf.system)
    rows = [(x, margins(L)) for x, L in zip(sf.breaks, sf.loops)]
    if plot is not None:
        _plot_loops(sf, plot)
    if as_json:
        data = {"system": repr(sf.system), "source": sf.source, "stable": stable, "stability_reason": why or None,
                "loops": [{"at": x, **m.to_dict()} for x, m in rows]}
        print_json(data)
        return
    from rich.table import Table
    from rich.text import Text

    table = Table(title=Text(f"Loop-at-a-time margins of {sf.system!r}"))
    for col in ("opened at", "gain margin", "phase crossover", "phase margin (deg)", "gain crossover",
                "delay margin", "method"):
        table.add_column(col, justify="right")
    f = lambda v, d=4: "none" if v is None else ("inf" if v == math.inf else f"{v:.{d}g}")  # noqa: E731
    for x, m in rows:
        table.add_row(Text(x), f(m.gain_margin), f(m.phase_crossover), f(m.phase_margin), f(m.crossover),
                      f(m.delay_margin), m.method)
    out.print(table)
    out.print("Crossovers in rad per time unit of the file, delay margins in that unit (s unless the file's "
              "blocks use another).", highlight=False, markup=False)
    verdict = {True: "stable", False: "UNSTABLE"}.get(stable, f"stability not decided: {why}")
    out.print(f"The closed system is {verdict}.", highlight=False, markup=False)


def _plot_loops(sf: Any, plot: Path) -> None:
    """Bode plots of the loops opened at the break signals (margins marked) and their Nyquist plots beside."""
    from matplotlib.figure import Figure

    from ..plotting.lti import bode_plot, nyquist_plot

    fig = Figure(figsize=(12.0, 6.0), layout="constrained")
    grid = fig.add_gridspec(2, 2)
    ax_mag = fig.add_subplot(grid[0, 0])
    ax_ph = fig.add_subplot(grid[1, 0], sharex=ax_mag)
    names = [f"opened at {x}" for x in sf.breaks]
    loops = list(sf.loops)
    bode_plot(loops, ax=(ax_mag, ax_ph), margins=True, labels=names)
    nyquist_plot(loops, ax=fig.add_subplot(grid[:, 1]), labels=names)
    fig.suptitle(f"Loop-at-a-time margins of {sf.system.name or sf.source}", fontsize=10)
    from ..plotting.figures import save_figure

    save_figure(fig, plot)


def system_simulate(path: Path, t_end: float | None, as_json: bool, plot: Path | None) -> int:
    """Print the exact step response of each input of a system file's interconnection (a table of each output's
    final value, extremes and time of its largest value, or JSON with every sample); draw it to ``plot``.

    Returns the exit status: 0 when the response is exact at every time, 1 when it stopped early (its
    ``status``; the outputs past the point reached are null).
    """
    import numpy as np

    from ..errors import check_real
    from ..simulate.systems import step_response
    from ..systems.files import read_system_file

    check_output("--plot", plot, "figure")
    horizon = None if t_end is None else check_real("--t-end", t_end, minimum=0.0, strict=True)
    sf = read_system_file(path)
    with err.status("simulating…"):
        r = step_response(sf.system, horizon)
    if plot is not None:
        from ..plotting.systems import plot_system_response

        plot_system_response(r, path=plot, title=f"Step responses of {sf.system.name or sf.source}")
    if as_json:
        print_json({"system": repr(sf.system), "source": sf.source, **r.to_dict()})
    else:
        from rich.table import Table
        from rich.text import Text

        table = Table(title=Text(f"Step responses of {sf.system!r}, 0 to {r.time[-1]:g}"))
        for col in ("step of", "output", "final value", "largest", "at t", "smallest"):
            table.add_column(col, justify="right")
        f = lambda v: "none" if not math.isfinite(v) else f"{v:.6g}"  # noqa: E731
        for j, u in enumerate(r.input_labels):
            for i, y in enumerate(r.output_labels):
                v = r.outputs[i, j]
                ok = np.isfinite(v)
                k = int(np.argmax(np.where(ok, v, -np.inf))) if ok.any() else 0
                table.add_row(Text(u), Text(y), f(float(v[ok][-1]) if ok.any() else math.nan),
                              f(float(v[k]) if ok.any() else math.nan), f(float(r.time[k]) if ok.any() else math.nan),
                              f(float(v[ok].min()) if ok.any() else math.nan))
        out.print(table)
        out.print(f"{r.time.size} times, {r.pieces} Taylor pieces, {r.status}. Times in the file's unit (s unless "
                  "its blocks use another).", highlight=False, markup=False)
    if r.status == "exact":
        return 0
    if not as_json:  # (the JSON's status and t_reached say it)
        warn(f"the response stopped at t = {r.t_reached:g} ({r.status}); later outputs are not given")
    return 1
