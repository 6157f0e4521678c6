"""The measurement folded into a loop's matrices, written once for Python and for the compiled simulators.

A loop's closed-loop realisation (:mod:`delaykit.models.closed_loop`) reads the measurement ``ym = y(t - To)`` and
its velocity ``vm = y'(t - To)``.  Without an output delay they are the output itself, ``y = cy X + dy w`` and
``y' = cyd X + dyd w``; substituting them gives the loop's matrices with the measurement folded in::

    A  = M + bym cy' + bvm cyd'          b  = bw + bym dy + bvm dyd
    k  = cv + dvy cy + dvv cyd           kw = dvy dy + dvv dyd

(``X' = A X + b w + ...`` and the law's output ``v = k X + kw w + dvr r``).  :func:`fold_into` is that algebra, on
arrays: :meth:`LoopRealisation.folded <delaykit.models.closed_loop.LoopRealisation.folded>` calls it, and so do
the simulator kernels of :mod:`delaykit.simulate` on a parameter row's matrices (``_kernel``'s known-input form,
``_sampled_batch``'s event map), once per run, in C.  Each entry is summed in that order, left to right.

One source, three modes (:mod:`delaykit._native`), as ``models/_expmkernel.py``: compiled ahead of time by Cython
(the C types are in ``_foldkernel.pxd``; the simulator kernels cimport it), compiled by numba where no extension was
built, or run as plain Python.  This module is private.

Examples
--------
>>> import numpy as np
>>> A, b, k = np.empty((2, 2)), np.empty(2), np.empty(2)
>>> M, z = np.array([0.0, 0.0, 0.0, -1.0]), np.zeros(2)  # 1/s under a PV law with a filter state, row-major
>>> kw = fold_into(M, 2, np.array([1.0, 0.0]), np.array([0.0, 1.0]), z, np.array([1.0, 0.0]), z,
...                np.array([0.0, 3.0]), 0.0, 0.0, -2.0, 0.0, 2, A, b, k)
>>> A.tolist(), b.tolist(), k.tolist(), kw
([[0.0, 0.0], [1.0, -1.0]], [1.0, 0.0], [-2.0, 3.0], 0.0)
"""

from __future__ import annotations

try:
    import cython
except ImportError:  # plain Python without Cython installed: only ``cython.compiled`` is read
    from types import SimpleNamespace

    cython = SimpleNamespace(compiled=False)

__all__ = ["fold_into", "COMPILED"]

COMPILED: bool = cython.compiled
"""Whether this module is the extension module Cython built (False: this file, run by Python or numba)."""

# numba's options where it compiles this file (see delaykit._native): it allocates nothing, and the Taylor kernel's
# piece loop, which calls it, is compiled without reference counting too
NUMBA_OPTIONS = {"fold_into": {"_nrt": False}}


def fold_into(M, ldm, bw, bym, bvm, cy, cyd, cv, dy, dyd, dvy, dvv, n, A, b, k):
    """The first ``n`` states' ``A``, ``b`` and ``k`` (written into the arrays given) of the loop whose ``M`` is
    the flat row-major ``M`` with ``ldm`` numbers a row, and the vectors and scalars named as in
    :class:`~delaykit.models.closed_loop.LoopRealisation`; returns ``kw`` (see the module's notes)."""
    for i in range(n):
        ym = bym[i]
        vm = bvm[i]
        for j in range(n):
            A[i, j] = M[i * ldm + j] + ym * cy[j] + vm * cyd[j]
        b[i] = bw[i] + ym * dy + vm * dyd
        k[i] = cv[i] + dvy * cy[i] + dvv * cyd[i]
    return dvy * dy + dvv * dyd
