"""The documentation site: every public name in the API reference, and the built pages as a browser renders them.

The tests marked ``docs`` read ``docs/_build/html``: ``make test`` builds it with ``make docs`` (warnings are
errors) and then runs them; run alone, the first test to need the site builds it the same way.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
import shutil
import struct
import subprocess
import sys
from html import unescape
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
HTML = DOCS / "_build" / "html"
SRC = ROOT / "src" / "delaykit"


@pytest.fixture(scope="module")
def site() -> Path:
    if not (HTML / "index.html").exists():
        cmd = [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q", str(DOCS), str(HTML)]
        res = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, timeout=1200)
        assert res.returncode == 0, res.stderr[-3000:]
    return HTML


def _apiref():
    spec = importlib.util.spec_from_file_location("_apiref", DOCS / "_apiref.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _public_modules_from_files() -> set[str]:
    # independent of docs/_apiref.py: every .py file of the source tree with no private part, the CLI left out
    # (it is documented by its --help)
    out = set()
    for path in SRC.rglob("*.py"):
        parts = path.relative_to(SRC.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if any(p.startswith("_") for p in parts) or parts[:2] == ("delaykit", "cli"):
            continue
        out.add(".".join(parts))
    return out


@pytest.mark.docs
def test_every_public_module_has_a_reference_page(site):
    mods = _public_modules_from_files()
    assert "delaykit.models.loop" in mods and "delaykit" in mods
    assert set(_apiref().public_modules()) == mods
    missing = [m for m in sorted(mods) if not (site / "api" / f"{m}.html").exists()]
    assert not missing, missing


@pytest.mark.docs
def test_every_name_of_every_all_is_in_the_reference(site):
    ref = _apiref()
    mods = sorted(_public_modules_from_files())
    home = ref.homes(mods)
    pages = {m: (site / "api" / f"{m}.html").read_text(encoding="utf-8") for m in mods}
    missing = []
    n = 0
    for m in mods:
        for name in importlib.import_module(m).__all__:
            n += 1
            where = home[(m, name)]
            target = f"{where}.{name}"
            # documented at its home (an anchor with its full name), and named on the module's own page: there,
            # or as a link to the home
            documented = f'id="{target}"' in pages[where]
            listed = m == where or f'href="{where}.html#{target}"' in pages[m]
            if not (documented and listed):
                missing.append(f"{m}.{name} (home {where}: documented {documented}, listed {listed})")
    assert n > 300, n  # the package has several hundred public names; a broken walk would find few
    assert not missing, "\n".join(missing)


@pytest.mark.docs
def test_a_documented_name_shows_its_docstring(site):
    # the reference is generated from the docstrings: a phrase of Loop's docstring is on its page
    from delaykit.models.loop import Loop

    first = Loop.__doc__.strip().splitlines()[0].split(":")[0].split("(")[0].strip()
    page = unescape(re.sub(r"<[^>]+>", "", (site / "api" / "delaykit.models.loop.html").read_text(encoding="utf-8")))
    assert first and first in re.sub(r"\s+", " ", page)


def _chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.skip("Debian's chromium is not installed (make test installs it where apt can reach its registry)")
    return exe


def _dom(page: Path, profile: Path) -> str:
    cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           f"--user-data-dir={profile}", "--virtual-time-budget=5000", "--dump-dom", page.as_uri()]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120).stdout


def _png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()[:24]
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    return struct.unpack(">II", data[16:24])


@pytest.mark.docs
def test_index_renders_in_headless_chromium(site, tmp_path):
    dom = _dom(site / "index.html", tmp_path / "profile")
    assert re.search(r"<title>[^<]*delaykit", dom), dom[:500]
    assert "<h1>delaykit" in dom
    # the navigation links to the API reference, the tutorials and the guide, and the targets exist
    for href in ("api/index.html", "tutorials/paper.html", "howto/identify.html", "guide/roots.html",
                 "benchmarks.html"):
        assert f'href="{href}' in dom, href
        assert (site / href).exists()


@pytest.mark.docs
def test_tutorial_figures_render_in_headless_chromium(site, tmp_path):
    # each executed tutorial shows the figures it computed: an <img> per figure, the PNG on disk and not empty
    for name, n_figures in (("paper", 1), ("heater", 2), ("px4", 1), ("smith", 1), ("flight", 1),
                             ("pid-tuning", 2), ("wood-berry", 2), ("quadrotor-xy", 2)):
        page = site / "tutorials" / f"{name}.html"
        dom = _dom(page, tmp_path / f"profile-{name}")
        assert "<h1>" in dom, (name, dom[:300])
        srcs = re.findall(r'<img[^>]+src="([^"]+\.png)"', dom)
        assert len(srcs) >= n_figures, (name, srcs)
        for src in srcs:
            w, h = _png_size((page.parent / src).resolve())
            assert w > 200 and h > 100, (name, src, w, h)
        # no cell raised: myst-nb would show the traceback in an error output
        assert "Traceback" not in dom, name


def test_readme_is_a_front_page_whose_links_resolve():
    # the README was 92 KB; its topics live in docs/ now, and every relative link from it must reach a file
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.encode()) < 25_000
    links = re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", readme)
    assert len(links) >= 20, links
    missing = [link for link in links if not (ROOT / link).exists()]
    assert not missing, missing
    assert "make run" in readme and "make test" in readme


def test_every_guide_page_is_in_the_site_navigation():
    # the guide's toctree globs docs/guide/*, so a page another change adds is never left out; a page listed
    # explicitly (for its order) must exist
    index = (DOCS / "index.md").read_text(encoding="utf-8")
    listed = re.findall(r"^guide/([\w-]+)$", index, flags=re.M)
    assert "guide/*" in index
    assert all((DOCS / "guide" / f"{name}.md").exists() for name in listed), listed
