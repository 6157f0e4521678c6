"""The import contract: the package's layers import one way only, lowest first.

Read from the source with :mod:`ast` (nothing is imported), so imports inside function bodies count as much as those
at the top of a module. A module may import its own layer's package-mates and any lower layer; the two peers of
layer 3 (simulate and spectrum) must not import each other. The package root ``delaykit/__init__.py`` is exempt as
an importer (it re-exports); a module that imports the root is taken to import what the root imports.
"""

from __future__ import annotations

import ast
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src" / "delaykit"

LAYERS = {
    "errors": 0, "_lazy": 0,
    "_native": 0.5,  # the kernels compiled ahead of time (loads them; uses errors; models' exponential uses it)
    "models": 1,
    "systems": 2,  # delay systems as objects: their algebra and exact frequency response read models only
    "simulate": 3, "spectrum": 3,  # peers: neither imports the other
    "identify": 4,
    "design": 5,
    "hardware": 6,
    "plotting": 7,
    "paper": 8,
    "cli": 9,
}

# (importing module, imported module) pairs that break the contract but are kept on purpose, each with its reason.
ALLOWED: set[tuple[str, str]] = {
    # DelayLTI.poles() and .is_stable() (python-control's method names) call the root finder of the layer above,
    # inside the methods; the object and its algebra need nothing from it
    ("delaykit.systems.lti", "delaykit.spectrum.systems"),
    # DelayLTI.step(), .impulse(), .initial() and .lsim() (python-control's method names) call the time responses
    # of the layer above, inside the methods, as poles() does
    ("delaykit.systems.lti", "delaykit.simulate.systems"),
    # Loop.system (a cached property) builds the closed loop as a DelayLTI with from_loop, inside the property: a
    # Loop is a preset (named constructor) of that system (issue 32); the model itself needs nothing from layer 2
    ("delaykit.models.loop", "delaykit.systems.build"),
    # SystemTimeResponse.plot() (python-control's response.plot()) draws with the plotting layer, imported inside
    # the method only, so that computing a response never loads matplotlib
    ("delaykit.simulate.systems", "delaykit.plotting.systems"),
    # SystemResponse.plot() (python-control's response.plot()) draws its Bode plot with the plotting layer, imported
    # inside the method only, as SystemTimeResponse.plot() does
    ("delaykit.systems.lti", "delaykit.plotting.lti"),
    # FrequencyResponse.plot() (a loop's response, python-control's response.plot()), the same way
    ("delaykit.spectrum.frequency", "delaykit.plotting.lti"),
}


def _module_name(root: Path, path: Path) -> str:
    parts = [root.name, *path.relative_to(root).with_suffix("").parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(root: Path, path: Path) -> set[str]:
    """Every module of the package that ``path`` imports, anywhere in it, as dotted names."""
    name = _module_name(root, path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            if module == root.name:  # `from delaykit import x`: x may be a subpackage or a re-exported name
                found.update(f"{module}.{a.name}" if f"{a.name}" in LAYERS else module for a in node.names)
            else:
                found.add(module)
    return {m for m in found if m == root.name or m.startswith(root.name + ".")}


def _unit(root: Path, module: str) -> str | None:
    """The layer's name (the first component under the package), or None for the package root."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def contract_violations(root: Path) -> list[tuple[str, str]]:
    """(module, imported module) pairs under the package directory ``root`` that break the layering, sorted.

    A module outside every layer (a new top-level module, say) is reported as (module, "<no layer>").
    """
    root = Path(root)
    root_init = root / "__init__.py"
    root_imports = _imports(root, root_init) - {root.name} if root_init.exists() else set()
    bad: set[tuple[str, str]] = set()
    for path in sorted(root.rglob("*.py")):
        if path == root_init:
            continue
        module = _module_name(root, path)
        unit = _unit(root, module)
        if unit not in LAYERS:
            bad.add((module, "<no layer>"))
            continue
        for target in sorted(_imports(root, path)):
            for effective in (root_imports if target == root.name else {target}):
                other = _unit(root, effective)
                if other == unit:
                    continue
                if other not in LAYERS or LAYERS[other] >= LAYERS[unit]:
                    bad.add((module, target))
    return sorted(bad - ALLOWED)


def modules_without_all(root: Path) -> list[str]:
    """Modules under ``root`` with no top-level assignment to ``__all__``."""
    missing = []
    for path in sorted(Path(root).rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        targets = [t for n in tree.body if isinstance(n, ast.Assign) for t in n.targets]
        targets += [n.target for n in tree.body if isinstance(n, (ast.AnnAssign, ast.AugAssign))]
        if not any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
            missing.append(_module_name(Path(root), path))
    return missing


def test_lower_layers_never_import_higher_ones():
    bad = contract_violations(SRC)
    assert not bad, "imports against the layering (lowest first: " + ", ".join(LAYERS) + "):\n" + "\n".join(
        f"  {m} imports {t}" for m, t in bad)


def test_allowlist_has_no_stale_entries():
    allowed = set(ALLOWED)
    ALLOWED.clear()
    try:
        current = set(contract_violations(SRC))
    finally:
        ALLOWED.update(allowed)
    assert allowed <= current, f"allowlisted pairs that no longer occur, remove them: {sorted(allowed - current)}"


def test_every_module_sets_all():
    missing = modules_without_all(SRC)
    assert not missing, "modules without a top-level __all__: " + ", ".join(missing)


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "delaykit"
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    return root


def test_the_checker_reports_violations(tmp_path):
    root = _tree(tmp_path, {
        "__init__.py": "from .simulate.run import go\n__all__ = ['go']\n",
        "errors.py": "__all__ = []\n",
        "models/__init__.py": "__all__ = []\n",
        "models/x.py": "from ..cli import app\nfrom ..errors import E\nfrom .y import z\n__all__ = []\n",
        "models/y.py": "__all__ = []\n\ndef f():\n    import delaykit.paper.data\n",
        "simulate/__init__.py": "__all__ = []\n",
        "simulate/run.py": "from ..models.x import A\n__all__ = []\n\ndef g():\n    from ..spectrum import roots\n",
        "spectrum/__init__.py": "__all__ = []\n",
        "spectrum/roots.py": "from delaykit import go\n__all__ = []\n",
        "cli/__init__.py": "from .. import models, spectrum\nfrom ..paper import data\n",
        "paper/__init__.py": "__all__ = []\n",
        "paper/data.py": "from .. import cli\n__all__ = []\n",
        "stray.py": "__all__ = []\n",
    })
    assert contract_violations(root) == [
        ("delaykit.models.x", "delaykit.cli"),  # top-level import of a higher layer
        ("delaykit.models.y", "delaykit.paper.data"),  # absolute, inside a function
        ("delaykit.paper.data", "delaykit.cli"),  # `from .. import cli`
        ("delaykit.simulate.run", "delaykit.spectrum"),  # peers, inside a function
        ("delaykit.spectrum.roots", "delaykit"),  # the root re-exports simulate, a peer
        ("delaykit.stray", "<no layer>"),
    ]
    assert modules_without_all(root) == ["delaykit.cli"]


def test_the_real_tree_is_checked():
    # guards against a checker that passes because it found nothing
    mods = {_module_name(SRC, p) for p in SRC.rglob("*.py")}
    assert {"delaykit.errors", "delaykit.models.altitude", "delaykit.cli.app",
            "delaykit.spectrum.discrete_margins"} <= mods
    assert "delaykit.models.altitude" in _imports(SRC, SRC / "spectrum" / "stability.py")
    assert "delaykit.plotting.figures" in _imports(SRC, SRC / "cli" / "cmd_simulate.py")  # imported inside functions
