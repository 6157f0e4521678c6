"""Kernels compiled ahead of time: one Python source, run as a Cython extension, by numba, or as plain Python.

A kernel module written for this (``spectrum/_rootkernel.py``: loops over arrays, C's math functions, no
decorators) sits beside a ``.pxd`` file that gives its C types.  When the package is built (``pip install``,
``make``), ``setup.py`` has Cython compile it to an extension module, which Python imports in place of the
``.py``: no compilation at run time, so the first call is as fast as the thousandth.  The same file still runs
without the extension:

* ``"cython"``: the extension module (:data:`COMPILED` true in it);
* ``"numba"``: the source loaded under the name ``<module>_numba`` with every function it defines compiled by
  numba on first use (and cached), as before the extension existed; numba code that calls a kernel (a compiled
  loop elsewhere) needs this copy;
* ``"python"``: the source loaded under ``<module>_python`` and run by the interpreter (slow; for checking).

:func:`load` gives the extension where it was built and numba's copy where it was not (an install without a C
compiler).  The environment variable ``DELAYKIT_KERNELS`` (``cython``, ``numba`` or ``python``) chooses for the
whole process, for comparisons.  This module is private.

Examples
--------
>>> from delaykit import _native
>>> _native.load("delaykit.spectrum", "_rootkernel", "python").__name__
'delaykit.spectrum._rootkernel_python'
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import sys
import warnings
from pathlib import Path
from types import ModuleType

from .errors import DelaykitWarning, InvalidValueError, MissingDependencyError

__all__ = ["MODES", "load", "built", "sibling", "StaleExtensionWarning", "SlowKernelWarning"]

MODES = ("cython", "numba", "python")
_loaded: dict[tuple[str, str], ModuleType] = {}


class SlowKernelWarning(DelaykitWarning):
    """A kernel runs as plain Python: neither its extension module was built nor numba is installed."""


class StaleExtensionWarning(DelaykitWarning):
    """A kernel's extension module was built from an older source than the one beside it (see :func:`built`)."""


def built(package: str, name: str) -> bool:
    """Whether the kernel module ``package.name`` was compiled to an extension module when the package was built,
    from its present source.

    An extension older than its ``.py`` or ``.pxd`` (a kernel edited in a working copy since ``make`` built it)
    does not count: it warns, saying how to rebuild, and numba compiles the source meanwhile.

    Examples
    --------
    >>> isinstance(built("delaykit.spectrum", "_rootkernel"), bool)
    True
    """
    try:
        mod = importlib.import_module(f"{package}.{name}")
    except ImportError:  # an extension that cimports another whose build failed (setup.py's builds are optional)
        return False
    if not getattr(mod, "COMPILED", False):
        return False
    stale = _newer_sources(Path(mod.__file__ or ""), name)
    if stale:
        warnings.warn(f"the compiled {package}.{name} is older than {stale[0]}: rebuild it (`make`, or "
                      "`pip install -e .`); numba compiles the source until then", StaleExtensionWarning, stacklevel=2)
        return False
    return True


def _newer_sources(ext: Path, name: str) -> list[str]:
    """The source files of kernel ``name`` (``.py``, ``.pxd``) written after its extension module ``ext``."""
    # a wheel's files are all written at its install, within moments of each other: a margin of 2 s
    return [f.name for f in (ext.with_name(f"{name}.py"), ext.with_name(f"{name}.pxd"))
            if f.exists() and f.stat().st_mtime > ext.stat().st_mtime + 2.0]


def load(package: str, name: str, mode: str | None = None) -> ModuleType:
    """The kernel module ``package.name`` in ``mode`` (one of :data:`MODES`).

    ``None`` takes ``DELAYKIT_KERNELS`` from the environment where it is set, and otherwise the extension module
    where it was built, numba's copy where not (numba is optional: ``pip install delaykit[numba]``), and the plain
    source, with a :class:`SlowKernelWarning`, where neither is there.

    Examples
    --------
    >>> rk = load("delaykit.spectrum", "_rootkernel", "python")
    >>> rk.COMPILED, rk.qeval.__module__
    (False, 'delaykit.spectrum._rootkernel_python')
    """
    if mode is None:
        mode = os.environ.get("DELAYKIT_KERNELS") or _default_mode(package, name)
    if mode not in MODES:
        raise InvalidValueError(f"kernel mode must be one of {', '.join(MODES)} (DELAYKIT_KERNELS), got {mode!r}")
    if mode == "cython":
        mod = importlib.import_module(f"{package}.{name}")
        if not getattr(mod, "COMPILED", False):
            raise InvalidValueError(f"{package}.{name} was not compiled when delaykit was installed (no C compiler?): "
                                    "reinstall with one, or set DELAYKIT_KERNELS to numba or python")
        return mod
    key = (f"{package}.{name}", mode)
    if key not in _loaded:
        _loaded[key] = _from_source(package, name, mode)
    return _loaded[key]


def _default_mode(package: str, name: str) -> str:
    """The extension where it was built, else numba's copy where numba is installed, else the plain source."""
    if built(package, name):
        return "cython"
    if importlib.util.find_spec("numba") is not None:
        return "numba"
    warnings.warn(f"{package}.{name} was not compiled when delaykit was installed and numba is not installed: it "
                  "runs as plain Python, far slower; reinstall delaykit where a C compiler is found, or install numba "
                  "(pip install 'delaykit[numba]')", SlowKernelWarning, stacklevel=3)
    return "python"


def sibling(importer: str, name: str, package: str | None = None) -> ModuleType:
    """The kernel module ``name`` (of ``package``, by default the package of ``importer``) for the kernel module
    ``importer`` (its ``__name__``) to call, in that module's mode: numba's copy for numba's copy (numba code calls
    numba code), Python's for Python's and for the plain ``.py`` imported under its own name.  (Compiled by Cython,
    a kernel cimports the other extension instead; see ``simulate/_discretekernel.py``.)

    Examples
    --------
    >>> sibling("delaykit.spectrum._rootkernel_python", "_rootkernel").__name__
    'delaykit.spectrum._rootkernel_python'
    >>> sibling("delaykit.simulate._discretekernel_python", "_expmkernel", "delaykit.models").__name__
    'delaykit.models._expmkernel_python'
    """
    own_package, _, own = importer.rpartition(".")
    return load(package or own_package, name, "numba" if own.endswith("_numba") else "python")


def _numba_knows(option: str) -> bool:
    """Whether this numba's CPU target accepts ``option`` (``_nrt``, a private one numba's own tests use: a release
    that dropped it would refuse to compile with a ``KeyError``; asking first keeps the kernel compiling)."""
    try:
        from numba.core.cpu import CPUTargetOptions
    except ImportError:
        return False
    return hasattr(CPUTargetOptions, option)


def _from_source(package: str, name: str, mode: str) -> ModuleType:
    """The kernel's ``.py`` file as a module of its own name, its functions compiled by numba in mode numba."""
    folder = Path(importlib.import_module(package).__file__ or "").parent
    full = f"{package}.{name}_{mode}"
    spec = importlib.util.spec_from_file_location(full, folder / f"{name}.py")
    if spec is None or spec.loader is None:
        raise FileNotFoundError(f"the source of {package}.{name} is not installed ({folder / (name + '.py')})")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[full] = mod
    try:
        spec.loader.exec_module(mod)
        if mode == "numba":
            try:
                import numba
            except ImportError:
                raise MissingDependencyError(f"{package}.{name} in mode numba needs numba, which is not installed: "
                                             "pip install 'delaykit[numba]', or set DELAYKIT_KERNELS to cython or "
                                             "python") from None

            # every function the module defines, so that kernels calling one another call compiled code (numba
            # reads a called function from the module's globals when it compiles the caller, on first use); a
            # module's NUMBA_OPTIONS gives some functions numba options of their own (inlining, parallel loops), or
            # None: left as Python (a wrapper that converts its arguments for a compiled function); so are those it
            # lists in PYTHON_ONLY (an entry that releases the GIL around a kernel, in a `with` block numba cannot
            # compile: numba's copy releases it itself)
            options = getattr(mod, "NUMBA_OPTIONS", {})
            keep = set(getattr(mod, "PYTHON_ONLY", ()))
            for attr, fn in list(vars(mod).items()):
                if (inspect.isfunction(fn) and fn.__module__ == full and attr not in keep
                        and options.get(attr, {}) is not None):
                    opts = dict(options.get(attr, {}))
                    if "_nrt" in opts and not _numba_knows("_nrt"):
                        del opts["_nrt"]  # compile with reference counting (slower) rather than not at all
                    setattr(mod, attr, numba.njit(cache=True, nogil=True, **opts)(fn))
    except BaseException:
        del sys.modules[full]
        raise
    return mod
