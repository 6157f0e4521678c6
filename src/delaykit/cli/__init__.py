"""The command line: ``delaykit simulate|report|reproduce|design|roots|lambert|estimate|emulate|fly|demo``.

The top layer, a thin one over the library: :mod:`.app` holds the Typer application; each command imports what it
needs when it runs, so ``delaykit --help`` stays quick. Only :data:`app`, :func:`main` (the ``delaykit`` console
script) and :func:`parse_delays` are exported.
"""

from .app import app, main, parse_delays

__all__ = ["app", "main", "parse_delays"]
