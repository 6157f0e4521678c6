"""The ``delaykit`` command line: a thin layer over the library.

Every command has ``--help``; those that print results have ``--json``; figures are written only where
``--plot FILE`` asks.  Bad input prints one line, ``error: ...``, and exits with status 2.

The Typer application is :data:`.common.app`; each ``cmd_*`` module holds one group of commands (simulate;
roots, margins and lambert; design; estimate, identify and predict; emulate and fly; report, reproduce and demo)
and imports the library only when a command runs, so ``delaykit --help`` stays quick.  This module registers
them, in the order and under the headings ``delaykit --help`` shows.
"""

from __future__ import annotations

import sys

from .cmd_design import design
from .cmd_hardware import emulate, fly
from .cmd_identify import estimate, identify, predict
from .cmd_paper import demo, report, reproduce
from .cmd_simulate import simulate
from .cmd_spectrum import lambert, margins, roots
from .common import app, parse_delays, parse_schedule

__all__ = ["app", "main", "parse_delays", "parse_schedule"]

COMMANDS = (
    ("Simulate and analyse a loop", (simulate, roots, margins, lambert)),
    ("Identify from logs", (estimate, identify, predict)),
    ("Design", (design,)),
    ("Fly", (emulate, fly)),
    ("The paper", (reproduce, report, demo)),
)
for _panel, _commands in COMMANDS:
    for _command in _commands:
        app.command(rich_help_panel=_panel)(_command)


def main() -> None:
    """Entry point of the ``delaykit`` script."""
    app(prog_name="delaykit")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
