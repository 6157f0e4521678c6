"""The ``delaykit`` command line: a thin layer over the library.

Every command has ``--help``; those that print results have ``--json``; figures are written only where
``--plot FILE`` asks.  Bad input prints one line, ``error: ...``, and exits with status 2.

The Typer application is :data:`.common.app`; each ``cmd_*`` module holds one group of commands (simulate;
roots, margins and lambert; design; estimate, identify and predict; emulate and fly; autotune; relay; report,
reproduce and demo) and imports the library only when a command runs, so ``delaykit --help`` stays quick.  This
module registers them, in the order and under the headings ``delaykit --help`` shows, by module and name: a command's module
is imported when the command is needed (``delaykit simulate ...`` imports :mod:`.cmd_simulate` alone).
"""

from __future__ import annotations

import sys
from typing import Any

from .common import app, parse_delays, parse_schedule

__all__ = ["app", "main", "parse_delays", "parse_schedule"]

COMMANDS = (
    ("Simulate and analyse a loop", (("cmd_simulate", "simulate"), ("cmd_spectrum", "roots"),
                                     ("cmd_spectrum", "margins"), ("cmd_spectrum", "lambert"))),
    ("Identify from logs", (("cmd_identify", "estimate"), ("cmd_identify", "identify"), ("cmd_identify", "predict"),
                            ("cmd_identify", "log"))),
    ("Design", (("cmd_design", "design"), ("cmd_tune", "tune"))),
    ("Fly", (("cmd_hardware", "emulate"), ("cmd_hardware", "fly"), ("cmd_autotune", "autotune"),
             ("cmd_relay", "relay"))),
    ("The paper", (("cmd_paper", "reproduce"), ("cmd_paper", "report"), ("cmd_paper", "demo"))),
)
"""The commands under their help headings, each as (module in this package, function)."""
_WHERE = {function: module for _, commands in COMMANDS for module, function in commands}
for _panel, _commands in COMMANDS:
    for _module, _function in _commands:
        app.add_lazy_command(f"{__package__}.{_module}", _function, _panel)


def __getattr__(name: str) -> Any:
    """A command's function by its name (``delaykit.cli.app.simulate``), its module imported now."""
    if name in _WHERE:
        from importlib import import_module

        return getattr(import_module(f".{_WHERE[name]}", __package__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""The BLAS libraries' thread settings that :func:`main` sets to 1 where the user has not set them."""


def one_blas_thread(environ: Any) -> None:
    """Ask NumPy's BLAS for one thread, unless ``environ`` already says how many.

    delaykit's matrices are small (a loop's or a fitted model's few states): a BLAS thread pool only adds
    hand-offs, which measured 0.5 s of the 1.2 s of CPU of ``delaykit identify`` of the heater log (SciPy's ``expm``
    of stiff trial plants).  delaykit's own parallel loops use OpenMP's threads, which this leaves alone.  It must
    run before NumPy is imported.

    Examples
    --------
    >>> env = {"MKL_NUM_THREADS": "4"}
    >>> one_blas_thread(env); env
    {'MKL_NUM_THREADS': '4', 'OPENBLAS_NUM_THREADS': '1'}
    """
    for name in BLAS_THREADS:
        environ.setdefault(name, "1")


def main() -> None:
    """Entry point of the ``delaykit`` script."""
    import os

    one_blas_thread(os.environ)
    app(prog_name="delaykit")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
