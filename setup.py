"""Build of delaykit's compiled kernels (everything else is in pyproject.toml).

Each kernel in ``KERNELS`` is a plain Python module with a ``.pxd`` beside it that gives its C types (Cython's
"pure Python mode"): Cython compiles it to a C extension module here, at build time, which Python then imports in
place of the ``.py``.  So an installed delaykit runs these kernels at full speed from its first call, with nothing
compiled at run time (see docs/guide/first-calls.md).  Where no C compiler is found, the build goes on without the
extension and the same ``.py`` runs compiled by numba instead (``delaykit._native``), as before.

The simulator's batch loops run in parallel (``cython.parallel.prange``) where the compiler has OpenMP; without it
(Apple's clang without libomp, say) they are built serially, with the same results.  The Loop simulator's kernel is
built as one C module with the kernels it calls (``FUSED``), so that the C compiler inlines them.
"""

import ast
import os
import re
import shutil
import sys
import tempfile
from pathlib import Path

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
# kernels compiled as one C module with the kernels they cimport (listed here, in order): the calls between them are
# then C calls within one file, which the C compiler inlines (numba inlines them too: see their NUMBA_OPTIONS), not
# calls through the pointers Cython's cimport gives, which pass each array view (a 208-byte struct) by value.  Each
# function's source stays in its own module; the parts keep their own extension modules for the other kernels.
FUSED = {"delaykit.simulate._kernel": ("delaykit.simulate._poly", "delaykit.simulate._taylor")}
# -O3 as numba's LLVM; no -march (a wheel runs on every CPU of its platform) and no fast-math (results to rounding)
ARGS = [] if sys.platform == "win32" else ["-O3", "-g0"]


def _links(code, flags):
    """Whether this compiler builds and links the C program ``code`` with ``flags``."""
    from setuptools._distutils.ccompiler import new_compiler
    from setuptools._distutils.sysconfig import customize_compiler

    cc = new_compiler()
    customize_compiler(cc)
    tmp = tempfile.mkdtemp()
    try:
        src = os.path.join(tmp, "probe.c")
        with open(src, "w") as f:
            f.write(code)
        objs = cc.compile([src], output_dir=tmp, extra_postargs=flags)
        cc.link_executable(objs, os.path.join(tmp, "probe"), extra_postargs=flags)
    except Exception:  # any compile or link error: not with these flags
        return False
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return True


def openmp_flags():
    """The compile and link flags of OpenMP, if this compiler builds and links a program with them (else none)."""
    if sys.platform == "win32":
        return ["/openmp"], []
    if _links("#include <omp.h>\nint main(void) { return omp_get_max_threads() > 0 ? 0 : 1; }\n", ["-fopenmp"]):
        return ["-fopenmp"], ["-fopenmp"]
    return [], []  # no OpenMP: the parallel loops run serially


def inline_flags():
    """GCC's limits on inlining raised, for the INLINED kernels (where this compiler takes them; else none): a FUSED
    kernel's piece loop is one large function, into which GCC's default limits would not inline the helpers it calls
    (numba inlines them all), and each call not inlined copies every array view it passes (a 208-byte struct each)."""
    flags = ["--param", "max-inline-insns-auto=4000", "--param", "max-inline-insns-single=4000",
             "--param", "large-function-growth=2000",
             "--param", "large-stack-frame-growth=2000", "--param", "inline-unit-growth=2000"]
    if sys.platform == "win32" or not _links("int main(void) { return 0; }\n", flags + ["-Werror"]):
        return []
    return flags


OMP_COMPILE, OMP_LINK = openmp_flags() if PARALLEL else ([], [])
INLINE = inline_flags()
# the kernels INLINE is given to: the FUSED ones and the sampled loops' batch, whose helpers of every interval (`cdef
# inline` in its .pxd) are then inline as in numba's copy (gcc kept _interval_metrics apart, passing its tuple of
# running metrics in and out through memory: 0.43 s of CPU against 0.38 s for bench_general's 10,000 sampled loops,
# results equal bit for bit)
INLINED = set(FUSED) | {"delaykit.simulate._sampled_batch"}


_CIMPORT = re.compile(r"^(\s*)from cython\.cimports\.([\w.]+) import (.+)$", re.M)
_DECL = re.compile(r"^cdef\s+(.+?)\s+(\w+(?:\s*,\s*\w+)*)\s*$")


def _own_calls(text, fused):
    """``text`` with its cimports of the ``fused`` modules removed (a ``pass`` in their place) and each name
    they bound (``f as _f``) replaced by the function's own name, now defined in the same module."""
    names = {}

    def drop(m):
        if m.group(2) not in fused:
            return m.group(0)
        for item in m.group(3).split(","):
            real, _, alias = item.strip().partition(" as ")
            names[(alias or real).strip()] = real.strip()
        return m.group(1) + "pass"

    text = _CIMPORT.sub(drop, text)
    for alias, real in names.items():
        if alias != real:
            text = re.sub(rf"(?<![\w.]){re.escape(alias)}\b", real, text)
    return text


def fused_source(name, parts, out="build/fused"):
    """Write the source of the extension ``name`` compiled with its ``parts`` (see FUSED) under ``out``: its docstring,
    then the parts' modules and its own, one after the other (their module-level names agree where they repeat: the
    same constants; its own ``__all__`` comes last), and their ``.pxd`` declarations merged; returns the path of the
    ``.py``."""
    mods = list(parts) + [name]
    src = [Path("src", *m.split(".")) for m in mods]
    doc = ast.get_docstring(ast.parse(src[-1].with_suffix(".py").read_text()), clean=False)  # the module's own
    py = f"{doc!r}\nfrom __future__ import annotations\n" + "".join(
        _own_calls(s.with_suffix(".py").read_text().replace("from __future__ import annotations\n", ""), mods)
        for s in src)
    seen, pxd = {}, []
    for s in src:
        for line in s.with_suffix(".pxd").read_text().splitlines():
            m = _DECL.match(line)
            if m and not line.startswith(("cdef inline", "cdef class")):  # a C global: declared once
                ctype, new = m.group(1), []
                for v in (v.strip() for v in m.group(2).split(",")):
                    if v in seen and seen[v] != ctype:
                        raise ValueError(f"{v} is declared {seen[v]} and {ctype} in the parts of {name}")
                    if v not in seen:
                        seen[v] = ctype
                        new.append(v)
                line = f"cdef {ctype} {', '.join(new)}" if new else ""
            pxd.append(line)
    target = Path(out, *name.split("."))
    target.parent.mkdir(parents=True, exist_ok=True)
    for d in list(target.parents)[:len(name.split(".")) - 1]:  # packages, so that Cython names the module
        (d / "__init__.py").touch()
    for path, text in ((target.with_suffix(".py"), py), (target.with_suffix(".pxd"), "\n".join(pxd) + "\n")):
        if not path.exists() or path.read_text() != text:  # (rewritten only when changed: no rebuild otherwise)
            path.write_text(text)
    return str(target.with_suffix(".py"))


def extension(name):
    par = name in PARALLEL
    source = fused_source(name, FUSED[name]) if name in FUSED else f"src/{name.replace('.', '/')}.py"
    flags = ARGS + (OMP_COMPILE if par else []) + (INLINE if name in INLINED else [])
    return Extension(name, [source], extra_compile_args=flags, extra_link_args=OMP_LINK if par else [])


# (include_path: a FUSED kernel's source, written under build/, still finds the .pxd of the other kernels it cimports)
extensions = (cythonize([extension(n) for n in KERNELS if n not in SIMULATOR_KERNELS], compiler_directives=DIRECTIVES,
                        include_path=["src"], quiet=True)
              + cythonize([extension(n) for n in KERNELS if n in SIMULATOR_KERNELS],
                          compiler_directives={**DIRECTIVES, **SIMULATOR}, include_path=["src"], quiet=True))
for ext in extensions:
    ext.optional = True  # a failed C build warns and goes on (set after cythonize, which does not copy it)

# the extension modules are compiled side by side, one per core (a fresh install's longest step)
setup(ext_modules=extensions, options={"build_ext": {"parallel": os.cpu_count() or 1}})
