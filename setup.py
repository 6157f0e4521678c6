"""Build of delaykit's compiled kernels (everything else is in pyproject.toml).

Each kernel in ``KERNELS`` is a plain Python module with a ``.pxd`` beside it that gives its C types (Cython's
"pure Python mode"): Cython compiles it to a C extension module here, at build time, which Python then imports in
place of the ``.py``.  So an installed delaykit runs these kernels at full speed from its first call, with nothing
compiled at run time (see docs/guide/first-calls.md).  Where no C compiler is found, the build goes on without the
extension and the same ``.py`` runs compiled by numba instead (``delaykit._native``), as before.

The simulator's batch loops run in parallel (``cython.parallel.prange``) where the compiler has OpenMP; without it
(Apple's clang without libomp, say) they are built serially, with the same results.
"""

import os
import shutil
import sys
import sysconfig
import tempfile

from Cython.Build import cythonize
from setuptools import Extension, setup

KERNELS = [
    "delaykit.spectrum._rootkernel",
    "delaykit.spectrum._trackkernel",
    "delaykit.models._expmkernel",
    "delaykit.models._foldkernel",
    "delaykit.simulate._poly",
    "delaykit.simulate._taylor",
    "delaykit.simulate._kernel",
    "delaykit.simulate._sampled_batch",
    "delaykit.simulate._discretekernel",
    "delaykit.simulate._varyingkernel",
    "delaykit.simulate._ltikernel",
    "delaykit.identify._fitkernel",
    "delaykit.identify._noisekernel",
]
# the kernels with a parallel loop (OpenMP where the compiler has it)
PARALLEL = {"delaykit.simulate._kernel", "delaykit.simulate._sampled_batch", "delaykit.simulate._ltikernel"}
# the Loop simulator's kernels, built with the SIMULATOR directives below
SIMULATOR_KERNELS = {"delaykit.simulate._poly", "delaykit.simulate._taylor", "delaykit.simulate._kernel",
                     "delaykit.simulate._sampled_batch"}

# numba's arithmetic: no bounds or negative-index checks, C's pow, Python's division (a zero divisor raises)
DIRECTIVES = {"language_level": 3, "boundscheck": False, "wraparound": False, "initializedcheck": False,
              "cpow": True, "cdivision": False, "embedsignature": True}
# the simulator's kernels: C types for every local assigned from C values (numba's typing), C division (their
# divisors are never zero: none is checked in the piece loop, which runs without the GIL)
SIMULATOR = {"infer_types": True, "cdivision": True}
# -O3 as numba's LLVM; no -march (a wheel runs on every CPU of its platform) and no fast-math (results to rounding)
ARGS = [] if sys.platform == "win32" else ["-O3", "-g0"]


def openmp_flags():
    """The compile and link flags of OpenMP, if this compiler builds and links a program with them (else none)."""
    if sys.platform == "win32":
        return ["/openmp"], []
    from setuptools._distutils.ccompiler import new_compiler
    from setuptools._distutils.sysconfig import customize_compiler

    cc = new_compiler()
    customize_compiler(cc)
    tmp = tempfile.mkdtemp()
    try:
        src = os.path.join(tmp, "omp.c")
        with open(src, "w") as f:
            f.write("#include <omp.h>\nint main(void) { return omp_get_max_threads() > 0 ? 0 : 1; }\n")
        objs = cc.compile([src], output_dir=tmp, extra_postargs=["-fopenmp"])
        cc.link_executable(objs, os.path.join(tmp, "omp"), extra_postargs=["-fopenmp"])
    except Exception:  # no OpenMP (any compile or link error): the parallel loops run serially
        return [], []
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return ["-fopenmp"], ["-fopenmp"]


OMP_COMPILE, OMP_LINK = openmp_flags() if PARALLEL else ([], [])


# gcc's limits for inlining a function declared inline, raised for the sampled loops' batch: its helpers of every
# interval (`cdef inline` in its .pxd) are then inline as in numba's copy (gcc kept _interval_metrics apart, passing
# its tuple of running metrics in and out through memory: 0.43 s of CPU against 0.38 s for bench_general's 10,000
# sampled loops, results equal bit for bit); gcc only (clang has other parameters)
INLINE = {"delaykit.simulate._sampled_batch"}
GCC = "gcc" in (os.environ.get("CC") or sysconfig.get_config_var("CC") or "") and sys.platform != "darwin"
INLINE_ARGS = ["--param", "max-inline-insns-single=2000", "--param", "inline-unit-growth=400"] if GCC else []


def extension(name):
    par = name in PARALLEL
    return Extension(name, [f"src/{name.replace('.', '/')}.py"],
                     extra_compile_args=ARGS + (OMP_COMPILE if par else []) + (INLINE_ARGS if name in INLINE else []),
                     extra_link_args=OMP_LINK if par else [])


extensions = (cythonize([extension(n) for n in KERNELS if n not in SIMULATOR_KERNELS], compiler_directives=DIRECTIVES,
                        quiet=True)
              + cythonize([extension(n) for n in KERNELS if n in SIMULATOR_KERNELS],
                          compiler_directives={**DIRECTIVES, **SIMULATOR}, quiet=True))
for ext in extensions:
    ext.optional = True  # a failed C build warns and goes on (set after cythonize, which does not copy it)

# the extension modules are compiled side by side, one per core (a fresh install's longest step)
setup(ext_modules=extensions, options={"build_ext": {"parallel": os.cpu_count() or 1}})
