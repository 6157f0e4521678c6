"""Sphinx configuration of delaykit's documentation site (``make docs`` builds it into docs/_build/html).

The API reference is generated from the package itself at every build (``_apiref.py``): one page per public
module, listing every name of its ``__all__``. Tutorials in ``tutorials/`` are MyST Markdown notebooks, executed
by myst-nb at build time (cached in ``_build/.jupyter_cache``). Nothing is fetched from the network.

Real measured data is not part of the project: a page that reads it says so (``<!-- reads shared data: ... -->``,
see ``tests/shared_data.py``) and finds it where the tests do, in ``../shared/data`` beside the project or in
``$DELAYKIT_DATA``. Where it is absent, such a tutorial is built without running, with a note saying so.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))

import delaykit  # noqa: E402

from _apiref import write_api_pages  # noqa: E402

sys.path.insert(0, str(HERE.parent / "tests"))
from shared_data import DATA, data_needed, missing_data  # noqa: E402  (where real data is read, for tests and docs)

os.environ["DELAYKIT_DATA"] = str(DATA)  # the tutorials' kernels read the data where this build found it

project = "delaykit"
author = "the delaykit developers"
copyright = "2026, the delaykit developers"
release = version = delaykit.__version__

extensions = [
    "myst_nb",
    "numpydoc",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
]

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb"}
exclude_patterns = ["_build", "**.ipynb_checkpoints", "Thumbs.db", ".DS_Store"]
root_doc = "index"

html_theme = "furo"
html_title = f"delaykit {release}"
html_static_path: list[str] = []

# MyST: Markdown pages and the tutorials' notebooks
myst_enable_extensions = ["colon_fence", "deflist"]
myst_heading_anchors = 3
# a guide page whose headings skip a level still reads well; every other warning stays an error under -W
suppress_warnings = ["myst.header"]
nb_execution_mode = "cache"          # a notebook runs again only when its code, or delaykit (below), changed
nb_execution_cache_path = str(HERE / "_build" / ".jupyter_cache")
nb_execution_timeout = 300
nb_execution_raise_on_error = True   # a tutorial that fails to run fails the build
nb_execution_show_tb = True
nb_merge_streams = True


def _encrypted_kernels() -> None:
    """The tutorials' kernels talk to the build over CurveZMQ-encrypted TCP, not plain text.

    jupyter_client provisions Curve keys for kernels whose kernelspec declares it (ipykernel's does) when its
    ``KernelManager.transport_encryption`` is ``"auto"``; its default is ``"disabled"``, and each kernel then printed
    ``[IPKernelApp] WARNING | Kernel is running over TCP without encryption`` into the build's output.  myst-nb runs
    the notebooks through nbclient, which makes its kernel managers without any configuration, so the trait's
    default is set here, for this build's process only.  (IPC transport would also silence it, but its socket
    files live under the working folder, and Unix socket paths are limited to about 100 characters: a deep clone
    would fail.)
    """
    try:
        import zmq
        from jupyter_client.manager import KernelManager
    except ImportError:  # the docs extra is not installed: nothing runs a notebook anyway
        return
    if zmq.has("curve"):
        KernelManager.class_traits()["transport_encryption"].default_value = "auto"


_encrypted_kernels()

# the API reference: autodoc + numpydoc
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# no network access at build time: sphinx.ext.intersphinx is not loaded, so no inventory is fetched

write_api_pages(HERE / "api")


def _pages_reading_data() -> dict[str, tuple[Path, list[Path]]]:
    """The pages that say they read shared data: docname -> (source, the files of it that are absent)."""
    pages = {}
    for page in sorted(HERE.rglob("*.md")):
        if "_build" in page.relative_to(HERE).parts:
            continue
        text = page.read_text(encoding="utf-8")
        if data_needed(text):
            pages[page.relative_to(HERE).with_suffix("").as_posix()] = (page, missing_data(text))
    return pages


_DATA_PAGES = _pages_reading_data()
# a tutorial whose data is absent is built without running (its code shows, its outputs do not)
nb_execution_excludepatterns = [page.as_posix() for page, missing in _DATA_PAGES.values() if missing]


def _forget_stale_executions() -> None:
    """myst-nb's cache knows a notebook's code, not the library it calls: when delaykit's source or the data the
    pages read (present or absent, and its content) change, the cached outputs are dropped and every tutorial runs
    again."""
    root = HERE.parent
    digest = hashlib.sha256()
    for path in sorted((root / "src" / "delaykit").rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    named = sorted({name for page, _ in _DATA_PAGES.values() for name in data_needed(page.read_text("utf-8"))})
    for name in named:
        top = DATA / name
        files = sorted(top.rglob("*")) if top.is_dir() else [top]
        digest.update(f"data {name} {'present' if top.exists() else 'absent'}".encode())
        for path in files:
            if path.is_file():
                digest.update(str(path.relative_to(DATA)).encode() + b"\0" + path.read_bytes())
    cache, stamp = Path(nb_execution_cache_path), Path(nb_execution_cache_path + ".source")
    if cache.exists() and (not stamp.exists() or stamp.read_text() != digest.hexdigest()):
        shutil.rmtree(cache)
    stamp.parent.mkdir(parents=True, exist_ok=True)
    stamp.write_text(digest.hexdigest())


_forget_stale_executions()


def _guide_pages(app, docname: str, source: list[str]) -> None:
    """The index's guide toctree lists some pages first, for their order, and ends with ``guide/*`` for every
    other page of docs/guide/; the glob is spelled out here, because Sphinx warns (an error under -W) about a
    glob that matches nothing new."""
    if docname != "index":
        return
    text = source[0]
    listed = {line.strip() for line in text.splitlines() if line.strip().startswith("guide/")}
    rest = sorted(f"guide/{p.stem}" for p in (HERE / "guide").glob("*.md") if f"guide/{p.stem}" not in listed)
    source[0] = text.replace("\nguide/*\n", "\n" + "".join(f"{d}\n" for d in rest))


def _note_unrun(app, docname: str, source: list[str]) -> None:
    """A page built without running, its data absent, says so under its title, and where the data is read."""
    entry = _DATA_PAGES.get(docname)
    if entry is None or not entry[1]:
        return
    absent = ", ".join(f"`{p}`" for p in entry[1])
    note = (f"\n:::{{note}}\nThis page was built **without running its code**: the real data it reads ({absent}) was "
            "absent when the documentation was built. The project holds no copy of it: it is read from "
            "`../shared/data` beside the project's folder, or from the folder `$DELAYKIT_DATA` names. With the data "
            "there, the build runs the page and shows its results.\n:::\n")
    text = source[0]
    head = text.find("\n# ")
    end = text.find("\n", head + 1) if head >= 0 else -1
    source[0] = text[:end + 1] + note + text[end + 1:] if end >= 0 else note + text


def setup(app):
    app.connect("source-read", _guide_pages)
    app.connect("source-read", _note_unrun)
