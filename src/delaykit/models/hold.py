"""A zero-order hold across a delay: the exact matrices that carry a plant's state from one sample to the next.

A command held for a period ``h`` and delayed by ``T = m h + f`` (``0 <= f < h``) reaches the plant as the
command issued ``m + 1`` samples earlier for the first ``f`` seconds of a period, then the one issued ``m``
samples earlier.  Over a stretch of length ``tau`` with a constant input the state moves by
``x -> exp(F tau) x + int_0^tau exp(F s) ds G u``; both matrices come from one exponential of an augmented
matrix.  The sample-to-sample simulator (:mod:`delaykit.simulate.discrete`) and the exact analysis of sampled
loops (:mod:`delaykit.spectrum.sampled`) both build on these two functions.

Examples
--------
>>> import numpy as np
>>> m, f = split_delay(0.37, 0.065)
>>> m, round(f, 9)
(5, 0.045)
>>> E, J = hold_matrices(np.array([[0.0]]), np.array([[1.0]]), 0.5)   # an integrator over 0.5 s
>>> float(E[0, 0]), float(J[0, 0])
(1.0, 0.5)
"""

from __future__ import annotations

import math
from types import ModuleType

import numpy as np

__all__ = ["SNAP", "STIFF_NORM", "split_delay", "hold_matrices"]

SNAP = 1e-9
"""A delay within this fraction of a period from a multiple of the period is that multiple."""


def split_delay(total: float, period: float) -> tuple[int, float]:
    """``(m, f)`` with ``total = m period + f`` and ``0 <= f < period``, snapped to ``f = 0`` within :data:`SNAP`.

    Examples
    --------
    >>> split_delay(0.2, 0.02)
    (10, 0.0)
    """
    m = math.floor(total / period)
    f = total - m * period
    if f < SNAP * period:
        f = 0.0
    elif period - f < SNAP * period:
        m, f = m + 1, 0.0
    return m, f


STIFF_NORM = 1e3
"""Above this ``sum |F| tau``, :func:`hold_matrices` leaves the compiled series for SciPy's Pade method (the series'
rounding grows with the squarings it needs: one per halving of the norm)."""


def hold_matrices(F: np.ndarray, G: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """``exp(F tau)`` and ``int_0^tau exp(F s) ds G`` (one column per column of ``G``; a vector for a vector).

    Both are blocks of one exponential, of the augmented matrix ``[[F, G], [0, 0]] tau``: delaykit's compiled one
    (:mod:`delaykit.models._expmkernel`: scaling and squaring around a Taylor series, summed to below rounding),
    or SciPy's (:func:`scipy.linalg.expm`) for a matrix far from what the series is meant for
    (``sum |F| tau`` above :data:`STIFF_NORM`).  This is delaykit's one matrix exponential on the Python side: the
    sampled simulators, the sampled and discrete analyses, the relay cycle and the emulated flight laws call it.

    Parameters
    ----------
    F : ndarray
        The state matrix, n x n.
    G : ndarray
        The input matrix, n x k, or one input's column as a vector of n.
    tau : float
        The length of the stretch (s).

    Returns
    -------
    (ndarray, ndarray)
        ``exp(F tau)`` (n x n) and ``int_0^tau exp(F s) ds G`` (n x k, or n for a vector ``G``).

    Examples
    --------
    >>> E, J = hold_matrices(np.array([[-1.0]]), np.array([[1.0]]), 1.0)
    >>> round(float(J[0, 0]), 12) == round(1 - math.exp(-1), 12)
    True
    """
    n = F.shape[0]
    if G.ndim == 1:
        E, J = hold_matrices(F, G.reshape(n, 1), tau)
        return E, J[:, 0]
    k = G.shape[1]
    if tau == 0.0:
        return np.eye(n), np.zeros((n, k))
    M = np.zeros((n + k, n + k))
    M[:n, :n] = F
    M[:n, n:] = G
    if np.abs(F).sum() * abs(tau) > STIFF_NORM:
        from scipy.linalg import expm  # here, not at the top: importing scipy.linalg costs ~0.2 s at start-up

        X = expm(M * tau)
    else:
        X = _kernel().expm(M * tau)
    return X[:n, :n], X[:n, n:]


def _kernel() -> ModuleType:
    """The compiled exponential (:func:`delaykit._native.load`: the extension built at install, else numba's)."""
    if not _loaded:
        from .. import _native

        _loaded.append(_native.load("delaykit.models", "_expmkernel"))
    return _loaded[0]


_loaded: list[ModuleType] = []
