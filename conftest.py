"""pytest's collection settings for the whole tree (the tests' fixtures are in tests/conftest.py).

A compiled kernel's ``.py`` (one with a ``.pxd`` beside it: ``setup.py``'s KERNELS) is the source of an extension
module.  Collected for doctests, it would be imported from the ``.py`` under the extension's own name, and a kernel
not imported yet (one loaded on first use) would then be that plain copy for the rest of the run, which
``delaykit._native.load`` refuses as not compiled.  Kernel sources hold no doctests; they are left out.
"""

from pathlib import Path

collect_ignore = [str(pxd.with_suffix(".py")) for pxd in Path(__file__).parent.glob("src/delaykit/*/*.pxd")]
