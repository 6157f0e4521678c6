"""The simulator's kernel in a process: compiled, or run as plain Python for short single runs.

The kernel modules (:mod:`._kernel`, with :mod:`._taylor` and :mod:`._poly`, which it calls) are one source in three
modes (:mod:`delaykit._native`): the extension modules Cython compiled when the package was built, numba's
compilation of the same files where none was built, or the files run by the interpreter.  Loading an extension
costs milliseconds; importing numba and loading its cached machine code about a second, more than one short
simulation run as plain Python.  So:

* :func:`kernel` gives the compiled kernel (the extension, or numba's copy without one) or the interpreted one
  (``delaykit.simulate._kernel_python``, whose helpers are interpreted too).
* :func:`use_interpreter` makes the interpreted kernel the default for this process (the command line calls it
  before a single simulation, for an install without the extension).  Interpreted runs draw on a budget of pieces
  (:func:`budget`): a run that would exceed it is redone compiled, and so is every run after it, so a long run
  never stays slow.

The modes run the same arithmetic and agree to rounding (the tests check 1e-12).  numba's cache of a compiled
function does not notice edits of the *other* kernel modules it calls: after changing :mod:`._poly`,
:mod:`._taylor` or :mod:`delaykit.models._foldkernel`, remove the cached kernels
(``src/delaykit/simulate/__pycache__/*.nb*``); an edited kernel's extension is rebuilt by ``make``.  This module is
private.

Examples
--------
>>> from delaykit.simulate import _jit
>>> _jit.kernel(compiled=False).__name__
'delaykit.simulate._kernel_python'
"""

from __future__ import annotations

from contextlib import contextmanager
from types import ModuleType
from typing import Iterator

from .. import _native

__all__ = ["use_interpreter", "interpreter", "interpreting", "budget", "spend", "kernel", "PIECE_BUDGET"]

PIECE_BUDGET = 1000
"""Pieces of a one-state loop the interpreter may run in a process before the compiled kernel takes over (a loop
of ``n`` states counts ``(1 + n) / 2`` a piece).  An interpreted piece takes 0.1 to 0.35 ms on this project's
machine, so the budget is 0.1 to 0.35 s: a third of what numba's import and cache load cost (about 0.9 s)."""

_PACKAGE = __name__.rpartition(".")[0]
_interpreting = False  # the process's default mode
_budget = float(PIECE_BUDGET)


def use_interpreter(on: bool = True) -> None:
    """Run this process's single simulations as plain Python (``on=False``: compiled, the default).

    Examples
    --------
    >>> use_interpreter(); budget(1) <= PIECE_BUDGET  # the pieces it may still run interpreted (0 once spent)
    True
    >>> use_interpreter(False); interpreting(), budget(1)
    (False, 0)
    """
    global _interpreting
    _interpreting = bool(on)


@contextmanager
def interpreter() -> Iterator[None]:
    """Within the block, run single simulations as plain Python (as :func:`use_interpreter`), then restore the
    process's mode: what the command line's ``simulate`` does, so that a command run in-process (a test, a
    notebook) leaves the library as it found it.  The budget spent stays spent.

    Examples
    --------
    >>> with interpreter():
    ...     allowed = budget(1)  # pieces it may run interpreted inside (0 once the budget is spent)
    >>> allowed <= PIECE_BUDGET, budget(1)  # and outside, none
    (True, 0)
    """
    global _interpreting
    before = _interpreting
    _interpreting = True
    try:
        yield
    finally:
        _interpreting = before


def interpreting() -> bool:
    """Whether single simulations run interpreted now (switched on, and the piece budget not spent).

    Examples
    --------
    >>> interpreting()
    False
    """
    return _interpreting and _budget > 0


def _weight(nstates: int) -> float:
    return (1 + nstates) / 2  # an interpreted piece's cost grows with the states (measured: 0.2 + 0.15 n ms)


def budget(nstates: int) -> int:
    """Pieces of an ``nstates``-state loop the interpreter may still run (0: run compiled).

    Examples
    --------
    >>> budget(1)  # the interpreter is off
    0
    """
    if not _interpreting:
        return 0
    return max(0, int(_budget / _weight(nstates)))


def spend(nstates: int, pieces: int) -> None:
    """Charge ``pieces`` interpreted pieces of an ``nstates``-state loop to the budget.

    Examples
    --------
    >>> spend(1, 0)
    """
    global _budget
    _budget -= pieces * _weight(nstates)


def kernel(compiled: bool | None = None) -> ModuleType:
    """The simulator's kernel module: compiled (the extension, or numba's copy where none was built; see
    :func:`delaykit._native.load`), interpreted, or (``None``) as this process runs now.

    Examples
    --------
    >>> kernel(compiled=False).NC
    25
    """
    if compiled is None:
        compiled = not interpreting()
    return _native.load(_PACKAGE, "_kernel", None if compiled else "python")
