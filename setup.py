"""Build of delaykit's compiled kernels (everything else is in pyproject.toml).

Each kernel in ``KERNELS`` is a plain Python module with a ``.pxd`` beside it that gives its C types (Cython's
"pure Python mode"): Cython compiles it to a C extension module here, at build time, which Python then imports in
place of the ``.py``.  So an installed delaykit runs these kernels at full speed from its first call, with nothing
compiled at run time (see docs/guide/first-calls.md).  Where no C compiler is found, the build goes on without the
extension and the same ``.py`` runs compiled by numba instead (``delaykit._native``), as before.
"""

import sys

from Cython.Build import cythonize
from setuptools import Extension, setup

KERNELS = ["delaykit.spectrum._rootkernel", "delaykit.simulate._ltikernel"]

# numba's arithmetic: no bounds or negative-index checks, C's pow, Python's division (a zero divisor raises)
DIRECTIVES = {"language_level": 3, "boundscheck": False, "wraparound": False, "initializedcheck": False,
              "cpow": True, "cdivision": False, "embedsignature": True}
# -O3 as numba's LLVM; no -march (a wheel runs on every CPU of its platform) and no fast-math (results to rounding)
ARGS = [] if sys.platform == "win32" else ["-O3", "-g0"]

# kernels with OpenMP threads (cython.parallel.prange): built with it where the compiler has it (gcc, clang with
# libomp: Linux; MSVC's /openmp), otherwise their loops run serially
THREADED = {"delaykit.simulate._ltikernel"}
OMP = [] if sys.platform == "darwin" else ["/openmp"] if sys.platform == "win32" else ["-fopenmp"]
OMP_LINK = [] if sys.platform in ("darwin", "win32") else ["-fopenmp"]

extensions = cythonize([Extension(name, [f"src/{name.replace('.', '/')}.py"],
                                  extra_compile_args=ARGS + (OMP if name in THREADED else []),
                                  extra_link_args=OMP_LINK if name in THREADED else [])
                        for name in KERNELS], compiler_directives=DIRECTIVES, quiet=True)
for ext in extensions:
    ext.optional = True  # a failed C build warns and goes on (set after cythonize, which does not copy it)

setup(ext_modules=extensions)
