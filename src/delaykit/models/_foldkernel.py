"""The measurement folded into a loop's matrices, written once for Python and for the compiled simulators.

A loop's closed-loop realisation (:mod:`delaykit.models.closed_loop`) reads the measurement ``ym = y(t - To)`` and
its velocity ``vm = y'(t - To)``.  Without an output delay they are the output itself, ``y = cy X + dy w`` and
``y' = cyd X + dyd w``; substituting them gives the loop's matrices with the measurement folded in::

    A  = M + bym cy' + bvm cyd'          b  = bw + bym dy + bvm dyd
    k  = cv + dvy cy + dvv cyd           kw = dvy dy + dvv dyd

(``X' = A X + b w + ...`` and the law's output ``v = k X + kw w + dvr r``).  :func:`fold_into` is that algebra, on
arrays: :meth:`LoopRealisation.folded <delaykit.models.closed_loop.LoopRealisation.folded>` calls it, and so do
the simulator kernels of :mod:`delaykit.simulate` on a parameter row, once per run, in C.  Each entry is summed in
that order, left to right.

The realisation is read *packed*, as the simulator's parameter row holds it (:mod:`delaykit.simulate._layout`)
from its matrix on: ``M`` row-major with ``ldm`` numbers a row, then the vectors of :data:`PACKED` (the fields of
:class:`~delaykit.models.closed_loop.LoopRealisation`, in that order), ``ldm`` numbers each.  One array and an
offset, not a view per vector: a view costs the batch kernels an atomic reference count each, per run.

One source, three modes (:mod:`delaykit._native`), as ``models/_expmkernel.py``: compiled ahead of time by Cython
(the C types are in ``_foldkernel.pxd``; the simulator kernels cimport it), compiled by numba where no extension was
built, or run as plain Python.  This module is private.
"""

from __future__ import annotations

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

__all__ = ["fold_into", "PACKED", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

PACKED = ("bw", "br", "bym", "bvm", "baw", "cy", "cyd", "cv")
"""The vectors after ``M`` in a packed realisation, in order (see the module's notes)."""

# numba's options where it compiles this file (see delaykit._native): it allocates nothing, and the Taylor kernel's
# piece loop, which calls it, is compiled without reference counting too
NUMBA_OPTIONS = {"fold_into": {"_nrt": False}}


def fold_into(R, o, ldm, dy, dyd, dvy, dvv, n, A, b, k):
    """The first ``n`` states' ``A``, ``b`` and ``k`` (written into the arrays given) of the realisation packed in
    ``R`` from offset ``o`` (``ldm`` numbers a row of ``M`` and a vector), with the scalars named as in
    :class:`~delaykit.models.closed_loop.LoopRealisation`; returns ``kw`` (see the module's notes)."""
    v = o + ldm * ldm  # bw, then br, bym, bvm, baw, cy, cyd, cv
    for i in range(n):
        ym = R[v + 2 * ldm + i]
        vm = R[v + 3 * ldm + i]
        for j in range(n):
            A[i, j] = R[o + i * ldm + j] + ym * R[v + 5 * ldm + j] + vm * R[v + 6 * ldm + j]
        b[i] = R[v + i] + ym * dy + vm * dyd
        k[i] = R[v + 7 * ldm + i] + dvy * R[v + 5 * ldm + i] + dvv * R[v + 6 * ldm + i]
    return dvy * dy + dvv * dyd
