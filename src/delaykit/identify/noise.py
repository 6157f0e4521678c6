"""Coloured residuals: an autoregressive noise model, the covariance it implies, and whiteness checks.

A hovering drone wanders slowly and a heater's thermocouple drifts: residuals of a fit are correlated in time,
and a standard error that assumes them white is too small.  Identification here estimates the plant by output
error (least squares on the free-run simulation) and then describes each residual series by an autoregressive
model ``e[k] = r[k] + a1 r[k-1] + ... + ap r[k-p]`` with ``e`` white (order ``p`` chosen by BIC, Yule-Walker
coefficients, so the model is stable).  The covariance of the output-error estimate under that noise is the
sandwich ``H^-1 (J' S J) H^-1`` with ``H = J'J`` and ``S = sigma_e^2 A^-1 A^-T`` the AR model's covariance:
``J' S J`` is computed by filtering the Jacobian backwards through ``1/A``, without forming ``S``.

Two outputs of one log (an altitude and its rate) share their disturbance: in closed loop the controller turns
the altitude's wander into the commanded speed, so the rate's residual is largely the altitude's residual of a
few samples earlier, filtered.  Described as independent series, the two outputs' contributions to the score
lose their cross-covariance, and on the emulated demo flights the delay's standard error came out at 0.76 of the
estimates' actual spread (95 % intervals covering the truth in 88.5 % of 200 flights; now 95.5 %:
benchmarks/bench_identify_coverage.py).  Such series are described jointly by a vector autoregressive model
(:func:`fit_var`, the multivariate Yule-Walker equations, order by BIC), and :func:`ar_covariance` filters the
stacked Jacobian backwards through the matrix polynomial.

Examples
--------
>>> rng = np.random.default_rng(1)
>>> e = rng.standard_normal(5000)
>>> r = np.empty_like(e); r[0] = e[0]
>>> for k in range(1, e.size): r[k] = 0.8 * r[k - 1] + e[k]
>>> ar = fit_ar(r)
>>> ar.order, round(float(ar.coeffs[1]), 2)
(1, -0.8)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import special  # (its functions only: scipy.stats would import ten times more at start-up)
from scipy.linalg import solve, solve_toeplitz

from .. import _native
from ..errors import InvalidValueError

__all__ = ["ARNoise", "VARNoise", "fit_ar", "fit_var", "ar_covariance", "ljung_box", "cross_correlation"]


@functools.cache
def _kernel() -> Any:
    """The compiled loops of this module (:mod:`._noisekernel`: Cython, else numba), found once per process as
    :mod:`._fit` finds its own (finding it checks the extension's files: 20 µs, twice per log of a fit)."""
    return _native.load("delaykit.identify", "_noisekernel")


def _filter(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``B(q) / A(q) x`` along the first axis from rest (``b`` and ``a`` of one length, ``a[0] = 1``): what
    ``scipy.signal.lfilter(b, a, x, axis=0)`` computes for ``a`` longer than 1, to the same numbers
    (:func:`._noisekernel.linear_filter`; importing ``scipy.signal`` would import most of SciPy)."""
    x = np.asarray(x, dtype=float)
    x2 = np.ascontiguousarray(x[:, None] if x.ndim == 1 else x.reshape(x.shape[0], -1))
    y = np.empty_like(x2)
    _kernel().linear_filter(np.ascontiguousarray(b, dtype=float), np.ascontiguousarray(a, dtype=float), x2, y)
    return y.reshape(x.shape)


@dataclass(frozen=True, repr=False, eq=False)
class ARNoise:
    """An autoregressive noise model: ``coeffs = [1, a1, ..., ap]`` and the innovations' variance ``sigma2``."""

    coeffs: np.ndarray
    sigma2: float
    n: int

    @property
    def order(self) -> int:
        """The order ``p``."""
        return self.coeffs.size - 1

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """The innovations ``A(q) x`` (along the first axis)."""
        # (scipy.signal.lfilter(coeffs, [1.0], x, axis=0)'s own computation, without importing scipy.signal)
        x = np.asarray(x, dtype=float)
        return np.apply_along_axis(lambda v: np.convolve(self.coeffs, v), 0, x)[:x.shape[0]]

    def loglik(self) -> float:
        """Gaussian log-likelihood of the series under the model (innovations form)."""
        return -0.5 * self.n * (math.log(2.0 * math.pi * max(self.sigma2, 1e-300)) + 1.0)

    def __repr__(self) -> str:
        return f"ARNoise(order={self.order}, sigma={math.sqrt(self.sigma2):.4g})"


@dataclass(frozen=True, repr=False, eq=False)
class VARNoise:
    """A vector autoregressive model of ``d`` series seen at the same samples:
    ``x[k] = phi_1 x[k-1] + ... + phi_p x[k-p] + e[k]``, the innovations ``e`` white with covariance ``sigma``.

    ``phi`` has shape ``(p, d, d)``; ``sigma`` ``(d, d)``; ``n`` is the series' length.

    Examples
    --------
    >>> m = VARNoise(np.array([[[0.5, 0.0], [1.0, 0.0]]]), np.eye(2), 3)
    >>> m.order, m.dim
    (1, 2)
    >>> m.whiten(np.array([[1.0, 0.0], [0.5, 1.0], [0.25, 0.5]])).tolist()  # only the first sample is new
    [[1.0, 0.0], [0.0, 0.0], [0.0, 0.0]]
    """

    phi: np.ndarray
    sigma: np.ndarray
    n: int

    @property
    def order(self) -> int:
        """The order ``p``."""
        return int(self.phi.shape[0])

    @property
    def dim(self) -> int:
        """The number of series ``d``."""
        return int(self.sigma.shape[0])

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """The innovations ``x[k] - sum phi_i x[k-i]`` of an ``(n, d)`` series (the first samples use zeros
        before the start)."""
        x = np.asarray(x, dtype=float)
        e = x.copy()
        for i in range(self.order):
            e[i + 1:] -= x[:x.shape[0] - i - 1] @ self.phi[i].T
        return e

    def loglik(self) -> float:
        """Gaussian log-likelihood of the series under the model (innovations form; infinite when ``sigma`` is
        singular: a series that the others predict exactly)."""
        sign, logdet = np.linalg.slogdet(self.sigma)
        if sign <= 0:
            return math.inf
        return -0.5 * self.n * (self.dim * math.log(2.0 * math.pi) + logdet + self.dim)

    def __repr__(self) -> str:
        sd = ", ".join(f"{math.sqrt(max(v, 0.0)):.4g}" for v in np.diag(self.sigma))
        return f"VARNoise(order={self.order}, dim={self.dim}, sigma=({sd}))"


def fit_ar(r: np.ndarray, max_order: int = 20) -> ARNoise:
    """Fit an autoregressive model to ``r`` by Yule-Walker, the order chosen by BIC.

    Parameters
    ----------
    r : ndarray
        A residual series (its mean is removed first).
    max_order : int
        Largest order tried (also at most a tenth of the series' length).

    Returns
    -------
    ARNoise

    References
    ----------
    .. [1] L. Ljung, *System Identification: Theory for the User*, 2nd ed., Prentice Hall, 1999, ch. 4 and 9.
    """
    x = np.asarray(r, dtype=float)
    x = x - x.mean()
    n = x.size
    pmax = int(max(0, min(max_order, n // 10)))
    # the biased autocovariances at lags 0..pmax, each a dot product: O(n pmax) (np.correlate's full mode is
    # O(n^2), hours for a log of millions of samples)
    full = np.array([np.dot(x[: n - k], x[k:]) for k in range(pmax + 1)]) / n
    if full[0] <= 0.0:
        return ARNoise(np.array([1.0]), 0.0, n)
    best = (n * math.log(full[0]), np.array([1.0]), float(full[0]))
    for p in range(1, pmax + 1):
        try:
            phi = solve_toeplitz(full[:p], full[1:p + 1])
        except np.linalg.LinAlgError:
            break
        s2 = float(full[0] - np.dot(phi, full[1:p + 1]))
        if s2 <= 0.0:
            break
        bic = n * math.log(s2) + p * math.log(n)
        if bic < best[0]:
            best = (bic, np.concatenate([[1.0], -phi]), s2)
    return ARNoise(best[1], best[2], n)


def fit_var(x: np.ndarray, max_order: int = 20) -> VARNoise:
    """Fit a vector autoregressive model to the columns of ``x`` by Yule-Walker, the order chosen by BIC.

    The multivariate Yule-Walker equations on the biased sample autocovariances (the block-Toeplitz matrix they
    make is positive definite), so the fitted model is stable (Whittle, 1963); BIC counts ``d^2`` coefficients
    per lag.

    Parameters
    ----------
    x : ndarray, shape (n, d)
        ``d`` series at the same ``n`` samples (each one's mean is removed first).
    max_order : int
        Largest order tried (also at most a tenth of the series' length).

    Returns
    -------
    VARNoise
        Order 0 (``sigma`` the lag-0 covariance) when the series are constant or exactly collinear.

    Raises
    ------
    InvalidValueError
        ``x`` is not a two-dimensional array of finite numbers with at least two rows.

    Examples
    --------
    >>> rng = np.random.default_rng(3)
    >>> e = rng.standard_normal((4000, 2))
    >>> x = np.zeros_like(e)
    >>> for k in range(1, 4000): x[k] = [0.7 * x[k - 1, 0] + e[k, 0], 0.5 * x[k - 1, 0] + e[k, 1]]
    >>> m = fit_var(x)
    >>> m.order, (np.round(m.phi[0], 1) + 0.0).tolist()  # (+ 0.0: no "-0.0")
    (1, [[0.7, 0.0], [0.5, 0.0]])

    References
    ----------
    .. [1] P. Whittle, "On the fitting of multivariate autoregressions, and the approximate canonical
       factorization of a spectral density matrix", *Biometrika* 50, 1963, 129-134.
    .. [2] H. Luetkepohl, *New Introduction to Multiple Time Series Analysis*, Springer, 2005, ch. 3 and 4.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or x.shape[0] < 2 or not np.all(np.isfinite(x)):
        raise InvalidValueError(f"fit_var needs an (n, d) array of finite numbers, n at least 2, got shape {x.shape}")
    n, d = x.shape
    x = x - x.mean(axis=0)
    pmax = int(max(0, min(max_order, n // 10)))
    lags = np.array([x[k:].T @ x[:n - k] / n for k in range(pmax + 1)])  # R_k = E[x[t+k] x[t]']
    none = VARNoise(np.zeros((0, d, d)), lags[0], n)
    sign, logdet = np.linalg.slogdet(lags[0])
    if sign <= 0:
        return none
    best = (n * logdet, none)
    # [phi_1 ... phi_p] T = [R_1 ... R_p], T's block (i, j) = R_(j-i) (R_-k = R_k'): the leading p blocks of one
    # block-Toeplitz matrix built for the largest order
    both = np.concatenate([np.transpose(lags[:0:-1], (0, 2, 1)), lags])  # R_-pmax ... R_pmax
    ij = np.arange(pmax)
    Tall = both[pmax + ij[None, :] - ij[:, None]].transpose(0, 2, 1, 3).reshape(pmax * d, pmax * d)
    rall = np.concatenate(lags[1:], axis=1) if pmax else np.zeros((d, 0))
    for p in range(1, pmax + 1):
        T = Tall[:p * d, :p * d]
        rhs = rall[:, :p * d]
        try:
            coef = solve(T, rhs.T, assume_a="sym").T
        except (np.linalg.LinAlgError, ValueError):
            break
        phi = coef.reshape(d, p, d).transpose(1, 0, 2)
        sigma = lags[0] - sum(phi[i] @ lags[i + 1].T for i in range(p))
        sigma = 0.5 * (sigma + sigma.T)
        sign, logdet = np.linalg.slogdet(sigma)
        if sign <= 0:
            break
        bic = n * logdet + p * d * d * math.log(n)
        if bic < best[0]:
            best = (bic, VARNoise(phi, sigma, n))
    return best[1]


def ar_covariance(blocks: list[tuple[np.ndarray, ARNoise | VARNoise]]) -> np.ndarray:
    """Covariance of a least-squares estimate whose residual blocks follow autoregressive models.

    Parameters
    ----------
    blocks : list of (J_b, ARNoise or VARNoise)
        Each block's Jacobian rows and its noise model: an ``(n, q)`` array (residuals by parameters) with an
        :class:`ARNoise`, or an ``(n, d, q)`` array (samples by series by parameters) with a :class:`VARNoise`
        of ``d`` series, for residual series seen at the same samples and described jointly.  Blocks are
        independent of each other.

    Returns
    -------
    ndarray
        ``H^-1 M H^-1`` with ``H = sum J_b' J_b`` and ``M = sum_b Var(J_b' r_b)``: ``sigma_b^2 X_b' X_b``,
        ``X_b = A_b^-T J_b``, for an autoregressive block; ``sum_m X_m' sigma X_m`` with ``X_m = J_m +
        sum_i phi_i' X_(m+i)`` (the Jacobian filtered backwards through the inverse of the vector model) for a
        vector one.

    Raises
    ------
    InvalidValueError
        A vector block whose Jacobian's shape does not match its model's dimension, or blocks with different
        numbers of parameters.

    Examples
    --------
    >>> J = np.ones((100, 1))
    >>> white = ar_covariance([(J, ARNoise(np.array([1.0]), 4.0, 100))])
    >>> round(float(white[0, 0]), 6)  # the variance of a mean of 100 samples of variance 4
    0.04
    >>> both = ar_covariance([(np.ones((100, 2, 1)), VARNoise(np.zeros((0, 2, 2)), np.eye(2), 100))])
    >>> round(float(both[0, 0]), 6)  # two independent unit series: the mean of 200 samples
    0.005
    """
    if not blocks:
        raise InvalidValueError("ar_covariance needs at least one block")
    q = blocks[0][0].shape[-1]
    H = np.zeros((q, q))
    M = np.zeros((q, q))
    for J, model in blocks:
        J = np.asarray(J, dtype=float)
        if J.shape[-1] != q:
            raise InvalidValueError(f"every block needs {q} parameter columns, got a block of shape {J.shape}")
        if isinstance(model, VARNoise):
            if J.ndim != 3 or J.shape[1] != model.dim:
                raise InvalidValueError(f"a vector block of {model.dim} series needs an (n, {model.dim}, q) "
                                        f"Jacobian, got shape {J.shape}")
            H += np.einsum("mdi,mdj->ij", J, J)
            X = _kernel().var_backward(np.ascontiguousarray(J), np.ascontiguousarray(model.phi, dtype=float))
            M += np.einsum("mdi,de,mej->ij", X, model.sigma, X)
        else:
            H += J.T @ J
            X = _filter(np.eye(1, model.coeffs.size)[0], model.coeffs, J[::-1])[::-1]
            M += model.sigma2 * (X.T @ X)
    Hi = np.linalg.pinv(H)
    return Hi @ M @ Hi


def ljung_box(e: np.ndarray, lags: int = 20) -> tuple[float, float]:
    """The Ljung-Box statistic ``Q`` of a series and its p-value (chi-square with ``lags`` degrees of freedom).

    Examples
    --------
    >>> q, p = ljung_box(np.random.default_rng(0).standard_normal(2000))
    >>> p > 0.01
    True
    """
    x = np.asarray(e, dtype=float)
    x = x - x.mean()
    n = x.size
    den = float(np.dot(x, x))
    lags = int(min(lags, n - 2))
    if den == 0.0 or lags < 1:
        return 0.0, 1.0
    q = 0.0
    for k in range(1, lags + 1):
        rho = float(np.dot(x[:-k], x[k:])) / den
        q += rho * rho / (n - k)
    q *= n * (n + 2)
    return q, float(special.chdtrc(lags, q))  # chi-square's tail (scipy.stats.chi2.sf's own code)


def cross_correlation(e: np.ndarray, u: np.ndarray, lags: int = 25) -> tuple[float, int, float]:
    """Largest normalised cross-correlation of residuals ``e`` with past inputs ``u`` (lags 0..``lags``).

    Returns ``(rho, lag, bound)`` with ``bound = 2.58 / sqrt(n)``, the 99 % band of a white series uncorrelated
    with the input.
    """
    x = np.asarray(e, dtype=float) - np.mean(e)
    v = np.asarray(u, dtype=float) - np.mean(u)
    n = x.size
    den = math.sqrt(float(np.dot(x, x)) * float(np.dot(v, v)))
    if den == 0.0:
        return 0.0, 0, 2.58 / math.sqrt(max(n, 1))
    best, at = 0.0, 0
    for k in range(0, int(min(lags, n - 2)) + 1):
        rho = float(np.dot(x[k:], v[:n - k])) / den
        if abs(rho) > abs(best):
            best, at = rho, k
    return best, at, 2.58 / math.sqrt(n)
