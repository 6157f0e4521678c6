"""The simulator's kernels, compiled by numba or run as plain Python: one source, two modes.

Importing numba and loading its cached machine code costs about a second, far more than one short simulation
run as plain Python.  So the kernel modules (:mod:`._poly`, :mod:`._kernel`) take their decorators from here:

* ``njit`` is numba's while a module is built *compiled*, and returns the function unchanged while it is built
  *interpreted*; ``prange`` is numba's or the built-in ``range``.
* The package's own names (``delaykit.simulate._kernel``, ...) are always the compiled modules.  The interpreted
  copies are loaded from the same files under other names (``..._kernel_interpreted``) by :func:`kernel`, and a
  kernel module finds its helpers with :func:`sibling`, in its own mode.  numba is imported only when a compiled
  module is.
* :func:`use_interpreter` makes the interpreted kernel the default for this process (the command line calls it
  before a single simulation).  Interpreted runs draw on a budget of pieces (:func:`budget`): a run that
  would exceed it is redone compiled, and so is every run after it, so a long run never stays slow.

The two modes run the same arithmetic and agree to rounding (the tests check 1e-12).  numba's cache of a
compiled function does not notice edits of the *other* kernel modules it calls: after changing :mod:`._poly` or
:mod:`._taylor`, remove the cached kernels (``src/delaykit/simulate/__pycache__/*.nb*``).  This module is private.

Examples
--------
>>> from delaykit.simulate import _jit
>>> _jit.kernel(compiled=False).__name__
'delaykit.simulate._kernel_interpreted'
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from types import ModuleType
from contextlib import contextmanager
from typing import Any, Callable, Iterator

__all__ = ["njit", "use_interpreter", "interpreter", "interpreting", "budget", "spend", "kernel", "sibling",
           "PIECE_BUDGET"]

PIECE_BUDGET = 1000
"""Pieces of a one-state loop the interpreter may run in a process before the compiled kernel takes over (a loop
of ``n`` states counts ``(1 + n) / 2`` a piece).  An interpreted piece takes 0.1 to 0.35 ms on this project's
machine, so the budget is 0.1 to 0.35 s: a third of what numba's import and cache load cost (about 0.9 s)."""

_PACKAGE = __name__.rpartition(".")[0]
_building_compiled = True  # the mode of the kernel module being imported now (what njit and prange give)
_interpreting = False  # the process's default mode
_budget = float(PIECE_BUDGET)
_interpreted: dict[str, ModuleType] = {}


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


def njit(*args: Any, **kwargs: Any) -> Any:
    """numba's ``njit`` in a compiled build; in an interpreted one, the function itself (the options are numba's).

    Examples
    --------
    >>> double = njit(lambda x: 2.0 * x)  # compiled here: this module's default build is compiled
    >>> double(1.5)
    3.0
    """
    if _building_compiled:
        import numba

        if "_nrt" in kwargs and not _numba_knows("_nrt"):
            del kwargs["_nrt"]  # a private option: compile with reference counting rather than not at all
        return numba.njit(*args, **kwargs)
    if len(args) == 1 and callable(args[0]) and not kwargs:
        return args[0]
    return _identity


def _numba_knows(option: str) -> bool:
    """Whether this numba's CPU target accepts ``option``.

    The piece loop is compiled with ``_nrt=False`` (no reference counting: a third of its time), a private option
    numba's own tests use.  A numba release that drops it would refuse to compile the kernel with a ``KeyError``;
    asking first keeps the kernel compiling, only slower, on such a release.
    """
    try:
        from numba.core.cpu import CPUTargetOptions
    except ImportError:
        return False
    return hasattr(CPUTargetOptions, option)


def _identity(fn: Callable[..., Any]) -> Callable[..., Any]:
    return fn


def __getattr__(name: str) -> Any:
    if name == "prange":  # read by a kernel module as it is built: numba's prange, or range
        if _building_compiled:
            import numba

            return numba.prange
        return range
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _load(name: str, compiled: bool) -> ModuleType:
    global _building_compiled
    if not compiled and name in _interpreted:
        return _interpreted[name]
    before = _building_compiled
    _building_compiled = compiled
    try:
        if compiled:
            return importlib.import_module(f"{_PACKAGE}.{name}")
        full = f"{_PACKAGE}.{name}_interpreted"
        spec = importlib.util.spec_from_file_location(full, Path(__file__).with_name(f"{name}.py"))
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[full] = mod
        try:
            spec.loader.exec_module(mod)
        except BaseException:
            del sys.modules[full]
            raise
        _interpreted[name] = mod
        return mod
    finally:
        _building_compiled = before


def sibling(name: str) -> ModuleType:
    """The kernel module ``name`` (``"_poly"``), built in the mode of the module being imported now."""
    return _load(name, _building_compiled)


def kernel(compiled: bool | None = None) -> ModuleType:
    """The simulator's kernel module: compiled, interpreted, or (``None``) as this process runs now.

    Examples
    --------
    >>> kernel(compiled=False).NC
    25
    """
    if compiled is None:
        compiled = not interpreting()
    return _load("_kernel", compiled)
