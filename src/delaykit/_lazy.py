"""Names a package exports but imports on first use (module ``__getattr__``, PEP 562).

A package that re-exports its modules' names would import all of them, and with them numba, SciPy or the
estimator, when any one name is asked for; these packages instead give :func:`lazy_exports` a table of where each
name lives, and the module holding it is imported the first time the name is read.

Examples
--------
>>> ns = {"__all__": ["sqrt"]}
>>> getattr_, dir_ = lazy_exports("math", {"sqrt": "math"}, ns)
>>> getattr_("sqrt")(4.0), "sqrt" in ns, dir_()
(2.0, True, ['__all__', 'sqrt'])
"""

from __future__ import annotations

from importlib import import_module
from typing import Any, Callable

__all__ = ["lazy_exports", "by_module"]


def by_module(sources: dict[str, list[str]]) -> dict[str, str]:
    """``{module: [names]}`` (modules relative to the package, without the dot) as ``{name: ".module"}``.

    Examples
    --------
    >>> by_module({"metrics": ["StepMetrics", "step_metrics"]})
    {'StepMetrics': '.metrics', 'step_metrics': '.metrics'}
    """
    return {name: f".{mod}" for mod, names in sources.items() for name in names}


def lazy_exports(package: str, where: dict[str, str], namespace: dict[str, Any]
                 ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """A package's ``__getattr__`` and ``__dir__``: ``where`` maps each name to its module (relative to
    ``package`` when it starts with a dot); a name read once is kept in ``namespace`` (the package's globals)."""

    def __getattr__(name: str) -> Any:
        mod = where.get(name)
        if mod is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(import_module(mod, package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(namespace.get("__all__", ())))

    return __getattr__, __dir__
