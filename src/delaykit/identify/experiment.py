"""Experiment design: the standard errors a planned test will give, before it is run.

For a model (an identified one, or a structure with guessed values) and a planned drive (steps, a chirp, a PRBS or
a sine, with its duration, sample rate and the expected noise level), the Fisher information of the output-error
fit, ``J'J / sigma^2`` with ``J`` the sensitivity of the simulated output to each parameter, gives the covariance
the fit will have (the same covariance :func:`~.identification.identify` reports, for white noise or for an
autoregressive noise model).  A user can see which test separates the delay from a lag before flying it.

Examples
--------
>>> from delaykit.identify.structures import STRUCTURES
>>> t, u = planned_signal("steps", duration=20.0, period=0.02, amplitude=0.5, steps=(2.0, 10.0))
>>> e = expected_errors("ipdt_lag", {"gain": 1.0, "lag": 0.2, "delay": 0.1}, t, u, noise=0.005)
>>> e
ExpectedErrors(ipdt_lag: gain ± ..., lag ± 0.00... s, delay ± 0.00... s; noise 0.005, 1000 samples)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..errors import InvalidValueError, check_real
from ..models.loop import Loop
from .identification import IdentificationError, IdentifiedModel, _jacobian, _law, _prepare, _Problem
from .iodata import Experiment
from .noise import ARNoise, ar_covariance
from .structures import structure

__all__ = ["ExpectedErrors", "planned_signal", "expected_errors", "SIGNALS"]

SIGNALS = ("steps", "chirp", "prbs", "sine")
"""The planned drives :func:`planned_signal` makes."""


@dataclass(frozen=True, repr=False, eq=False)
class ExpectedErrors:
    """Standard errors and correlations a planned experiment is expected to give."""

    model: str
    params: dict[str, float]
    stderr: dict[str, float]
    correlation: np.ndarray
    noise: float
    samples: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        names = list(self.params)
        return {"model": self.model, "params": dict(self.params), "stderr": dict(self.stderr),
                "correlation": {f"{a},{b}": float(self.correlation[i, j]) for i, a in enumerate(names)
                                for j, b in enumerate(names) if j > i},
                "noise": self.noise, "samples": self.samples}

    def __repr__(self) -> str:
        st = structure(self.model)
        parts = [f"{p} ± {self.stderr[p]:.2g}{' s' if u == 's' else ''}" for p, u in zip(st.params, st.units)]
        return f"ExpectedErrors({self.model}: {', '.join(parts)}; noise {self.noise:g}, {self.samples} samples)"


def planned_signal(kind: str, *, duration: float, period: float, amplitude: float = 1.0,
                   steps: tuple[float, ...] | None = None, band: tuple[float, float] = (0.05, 2.0),
                   seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A planned drive sampled every ``period`` for ``duration`` seconds: ``(t, drive)``.

    Parameters
    ----------
    kind : {"steps", "chirp", "prbs", "sine"}
        Steps of ``amplitude`` at the times ``steps`` (alternating sign: up, back...; default one step at
        a tenth of the duration); a linear chirp over ``band`` (Hz); a PRBS switching between +-amplitude with
        a mean hold of ``1 / (2 band[1])``; a sine at ``band[0]`` Hz.
    duration, period : float
        Length and sample period (s).
    amplitude : float
        Size of the drive.
    steps : tuple of float, optional
        Step times (s) for ``"steps"``.
    band : (float, float)
        Frequencies (Hz).
    seed : int
        PRBS seed.

    Examples
    --------
    >>> t, u = planned_signal("steps", duration=12.0, period=1.0, steps=(2.0, 8.0))
    >>> u.tolist()
    [0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0]
    """
    T = check_real("duration (s)", duration, minimum=0.0, strict=True)
    h = check_real("period (s)", period, minimum=0.0, strict=True)
    a = check_real("amplitude", amplitude)
    if T / h < 10:
        raise InvalidValueError(f"duration {T:g} s holds fewer than 10 samples of {h:g} s")
    f0 = check_real("band[0] (Hz)", band[0], minimum=0.0, strict=True)
    f1 = check_real("band[1] (Hz)", band[1], minimum=0.0, strict=True)
    if f1 < f0:
        raise InvalidValueError(f"band must be increasing, got ({f0:g}, {f1:g}) Hz")
    t = np.arange(int(round(T / h))) * h
    if kind == "steps":
        times = steps if steps is not None else (0.1 * T,)
        u = np.zeros_like(t)
        for i, ts in enumerate(sorted(check_real("step time (s)", s, minimum=0.0) for s in times)):
            u[t >= ts] = a if i % 2 == 0 else 0.0
    elif kind == "chirp":
        u = a * np.sin(2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / T * t * t))
    elif kind == "prbs":
        rng = np.random.default_rng(seed)
        hold = max(1, int(round(1.0 / (2.0 * f1) / h)))
        levels = rng.choice([-a, a], size=t.size // hold + 1)
        u = np.repeat(levels, hold)[: t.size]
    elif kind == "sine":
        u = a * np.sin(2 * np.pi * f0 * t)
    else:
        raise InvalidValueError(f"unknown signal kind {kind!r}; expected one of {', '.join(SIGNALS)}")
    return t, u


def expected_errors(model: IdentifiedModel | str, params: Mapping[str, float] | None, t: np.ndarray,
                    drive: np.ndarray, *, noise: float, loop: Loop | None = None,
                    ar: tuple[float, ...] = (), u0: float | None = None) -> ExpectedErrors:
    """The standard errors an output-error fit of ``model`` will have on the planned experiment.

    Parameters
    ----------
    model : IdentifiedModel or str
        An identified model (its values are used) or a structure name with ``params``.
    params : mapping, optional
        The parameter values (for a structure name).
    t, drive : ndarray
        The planned sample times and drive: the plant's input (open loop), or the reference when ``loop`` gives
        the controller (closed loop).
    noise : float
        Standard deviation of the output noise (for AR noise: of its innovations).
    loop : Loop, optional
        The controller of a closed-loop experiment (as for :func:`~.identification.identify`).
    ar : tuple of float
        Autoregressive noise coefficients ``a1, ..., ap`` (``e[k] = r[k] + a1 r[k-1] + ...``); none: white.
    u0 : float, optional
        The absolute command at rest, for a closed loop whose limits act on it and whose controller's integrator
        holds it (a PI or PID loop around a self-regulating plant), as for :func:`~.identification.identify`.

    Returns
    -------
    ExpectedErrors

    See Also
    --------
    delaykit.identify.identification.identify

    References
    ----------
    .. [1] G. C. Goodwin and R. L. Payne, *Dynamic System Identification: Experiment Design and Data Analysis*,
       Academic Press, 1977.
    """
    if isinstance(model, IdentifiedModel):
        st = model.structure
        values = dict(model.params)
        law_loop = loop
    else:
        st = structure(model)
        if params is None:
            raise InvalidValueError(f"give the values of {', '.join(st.params)} for a structure name")
        missing = [p for p in st.params if p not in params]
        if missing:
            raise InvalidValueError(f"missing values for {', '.join(missing)} (the {st.name} parameters are "
                                    f"{', '.join(st.params)})")
        values = {p: check_real(p, params[p]) for p in st.params}
        law_loop = loop
    sigma = check_real("noise (output standard deviation)", noise, minimum=0.0, strict=True)
    if u0 is not None:
        if law_loop is None:
            raise InvalidValueError("u0 is the command at rest of a closed-loop experiment: give the loop too")
        u0 = check_real("u0 (the command at rest)", u0)
    law = _law(law_loop, general=u0 is not None)
    zeros = {"y": np.zeros(len(t))}
    exp = (Experiment.from_arrays(t, zeros, r=drive, name="plan") if law is not None
           else Experiment.from_arrays(t, zeros, u=drive, name="plan", u_before=0.0))
    prep = _prepare(exp, ("y",), None, law, fresh_only=False, u0=u0)
    prob = _Problem(st, [prep], law, {"y": 1.0}, fit_offset=False)
    prob.fit_bias = False  # a planned experiment knows its input's level
    p = np.array([values[k] for k in st.params], dtype=float)
    with np.errstate(all="ignore"):
        J = _jacobian(prob, p)
    if not np.all(np.isfinite(J)):
        raise IdentificationError("the planned experiment's sensitivities are not finite for these values")
    coeffs = np.concatenate([[1.0], np.asarray(ar, dtype=float)])
    cov = ar_covariance([(J, ARNoise(coeffs, sigma * sigma, J.shape[0]))])
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    d = np.where(se > 0, se, 1.0)
    corr = cov / np.outer(d, d)
    if np.linalg.matrix_rank(J) < J.shape[1]:
        se = np.where(se >= 0, np.inf, se)
    return ExpectedErrors(st.name, values, {k: float(s) for k, s in zip(st.params, se)}, corr, sigma,
                          int(J.shape[0]))
