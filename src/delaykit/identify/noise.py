"""Coloured residuals: an autoregressive noise model, the covariance it implies, and whiteness checks.

A hovering drone wanders slowly and a heater's thermocouple drifts: residuals of a fit are correlated in time,
and a standard error that assumes them white is too small.  Identification here estimates the plant by output
error (least squares on the free-run simulation) and then describes each residual series by an autoregressive
model ``e[k] = r[k] + a1 r[k-1] + ... + ap r[k-p]`` with ``e`` white (order ``p`` chosen by BIC, Yule-Walker
coefficients, so the model is stable).  The covariance of the output-error estimate under that noise is the
sandwich ``H^-1 (J' S J) H^-1`` with ``H = J'J`` and ``S = sigma_e^2 A^-1 A^-T`` the AR model's covariance:
``J' S J`` is computed by filtering the Jacobian backwards through ``1/A``, without forming ``S``.

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

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.linalg import solve_toeplitz
from scipy.signal import lfilter

__all__ = ["ARNoise", "fit_ar", "ar_covariance", "ljung_box", "cross_correlation"]


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
        return lfilter(self.coeffs, [1.0], x, axis=0)

    def loglik(self) -> float:
        """Gaussian log-likelihood of the series under the model (innovations form)."""
        return -0.5 * self.n * (math.log(2.0 * math.pi * max(self.sigma2, 1e-300)) + 1.0)

    def __repr__(self) -> str:
        return f"ARNoise(order={self.order}, sigma={math.sqrt(self.sigma2):.4g})"


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
    full = np.correlate(x, x, mode="full")[n - 1:n + pmax] / n
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


def ar_covariance(blocks: list[tuple[np.ndarray, ARNoise]]) -> np.ndarray:
    """Covariance of a least-squares estimate whose residual blocks follow AR models.

    Parameters
    ----------
    blocks : list of (J_b, ARNoise)
        Each block's Jacobian rows (residuals by parameters) and its noise model.

    Returns
    -------
    ndarray
        ``H^-1 M H^-1`` with ``H = sum J_b' J_b`` and ``M = sum sigma_b^2 X_b' X_b``, ``X_b = A_b^-T J_b``.
    """
    p = blocks[0][0].shape[1]
    H = np.zeros((p, p))
    M = np.zeros((p, p))
    for J, ar in blocks:
        H += J.T @ J
        X = lfilter([1.0], ar.coeffs, J[::-1], axis=0)[::-1]
        M += ar.sigma2 * (X.T @ X)
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
    return q, float(stats.chi2.sf(q, lags))


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
