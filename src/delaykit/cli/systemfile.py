"""``--system FILE`` of ``roots`` and ``margins``: a delay system read from a TOML file of blocks.

The file's format is :mod:`delaykit.systems.files`'.  ``roots`` gives the interconnection's certified poles in a
region and its stability; ``margins`` gives the loop-at-a-time margins at the file's ``break`` signals and the
stability of the closed system.  JSON is strict: a non-finite number is printed as null.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..errors import InvalidValueError
from .common import out, print_json

__all__ = ["system_margins", "system_roots"]


def _stability(system: Any) -> tuple[bool | None, str]:
    from ..spectrum.systems import is_stable

    try:
        return is_stable(system), ""
    except InvalidValueError as exc:
        return None, str(exc)


def system_roots(path: Path, region: tuple[float, float, float, float], as_json: bool) -> None:
    """Print the certified poles of a system file's interconnection in ``region`` and its stability."""
    from ..spectrum.systems import poles
    from ..systems.files import read_system_file

    sf = read_system_file(path)
    sp = poles(sf.system, region)
    stable, why = _stability(sf.system)
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


def system_margins(path: Path, as_json: bool) -> None:
    """Print the loop-at-a-time margins at a system file's break signals and the closed system's stability."""
    from ..spectrum.systems import loop_margins
    from ..systems.files import read_system_file

    sf = read_system_file(path)
    if not sf.loops:
        raise InvalidValueError(f"{sf.source}: margins need the signals where the loop is opened: add "
                                "break = [\"signal\", ...] to the file")
    stable, why = _stability(sf.system)
    rows = [(x, loop_margins(L)) for x, L in zip(sf.breaks, sf.loops)]
    if as_json:
        data = {"system": repr(sf.system), "source": sf.source, "stable": stable, "stability_reason": why or None,
                "loops": [{"at": x, **m.to_dict()} for x, m in rows]}
        print_json(data)
        return
    from rich.table import Table
    from rich.text import Text

    table = Table(title=Text(f"Loop-at-a-time margins of {sf.system!r}"))
    for col in ("opened at", "gain margin", "phase crossover", "phase margin (deg)", "gain crossover",
                "delay margin"):
        table.add_column(col, justify="right")
    f = lambda v, d=4: "none" if v is None else ("inf" if v == math.inf else f"{v:.{d}g}")  # noqa: E731
    for x, m in rows:
        table.add_row(Text(x), f(m.gain_margin), f(m.phase_crossover), f(m.phase_margin), f(m.gain_crossover),
                      f(m.delay_margin))
    out.print(table)
    out.print("Crossovers in rad per time unit of the file, delay margins in that unit (s unless the file's "
              "blocks use another).", highlight=False, markup=False)
    verdict = {True: "stable", False: "UNSTABLE"}.get(stable, f"stability not decided: {why}")
    out.print(f"The closed system is {verdict}.", highlight=False, markup=False)
