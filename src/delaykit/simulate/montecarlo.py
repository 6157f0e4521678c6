"""Monte Carlo of the step metrics over random delays: a constant delay per run, or a delay per packet.

:func:`monte_carlo` runs a loop ``n`` times and gives the distribution of its step metrics (overshoot, peak, rise
and settling times, with percentiles and the count of runs that did not settle).  It takes one of two kinds of
randomness, and each runs on its own path (the result's ``method`` says which one ran):

* a :class:`DelayDistribution`: every run's delay is a **constant** drawn from the distribution (uniform, normal
  truncated at 0, lognormal, or an explicit array of delays).  The ``n`` runs are **one** call of
  :func:`delaykit.simulate.simulation.simulate_many`, the exact method-of-steps kernel run in parallel on all cores
  (``method="batched"``).  The loop may be continuous or sampled.  The drawn delay replaces the loop's input delay
  (its output delay is kept).  A loop whose controller is a :class:`~delaykit.models.compensators.Compensator` has
  two delays: the drawn one is the **true** delay and the compensator's model delay stays as designed (the
  kernel's sweep of ``delay`` writes the true delay only), so the result measures the compensator's robustness to
  a mismatched delay;
* a per-packet delay model of :mod:`delaykit.simulate.varying` (:class:`~delaykit.simulate.varying.Jitter`,
  :class:`~delaykit.simulate.varying.Burst`, :class:`~delaykit.simulate.varying.DelaySchedule`,
  :class:`~delaykit.simulate.varying.DelayTrace` or their sum): every run is an event simulation of the sampled
  loop (:func:`~delaykit.simulate.varying.simulate_varying`) whose packets draw their delays from an independent
  random stream (``method="events"``).

Examples
--------
>>> from delaykit.models import Controller, Loop
>>> loop = Loop("1/s", Controller.p(1.31), umin=-1, umax=1)
>>> mc = monte_carlo(loop, DelayDistribution.uniform(0.3, 0.45), n=500, seed=1)
>>> mc.method, mc.runs, mc.unsettled
('batched', 500, 0)
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass, field
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real
from ..models.altitude import as_loop
from ..models.budget import MAX_GRID_POINTS, check_count
from ..models.compensators import Compensator
from .simulation import simulate_many
from .varying import DelayModel, _check_seed, _checked_delays, as_delay_model, simulate_varying

__all__ = ["DelayDistribution", "DISTRIBUTION_KINDS", "MonteCarlo", "monte_carlo", "MONTE_CARLO_METHODS"]

DISTRIBUTION_KINDS = ("uniform", "normal", "lognormal", "array")
"""The kinds of :class:`DelayDistribution`."""

MONTE_CARLO_METHODS = {
    "batched": "one simulate_many call: the exact kernel, in parallel",
    "events": "one event simulation (simulate_varying) per run",
}
"""The values of :attr:`MonteCarlo.method`, with what each means."""

_PARAMS = {"uniform": ("lo", "hi"), "normal": ("mean", "sd"), "lognormal": ("median", "sigma"),
           "array": ("values",)}
_ALL_PARAMS = ("lo", "hi", "mean", "sd", "median", "sigma", "values")
_METRICS = ("overshoot", "peak_time", "rise_time", "settling_time")
_DEFAULT_RUNS = 200


# ------------------------------------------------------------------------------------ the delay distribution
@dataclass(frozen=True, repr=False)
class DelayDistribution:
    """The distribution of a delay that is constant within a run and random between runs.

    ``DelayDistribution(kind, **params)`` with

    * ``"uniform"``, ``lo`` and ``hi`` (s): uniform on ``[lo, hi]``, ``0 <= lo <= hi``;
    * ``"normal"``, ``mean`` and ``sd`` (s): a normal truncated at 0 (conditioned on being at least 0, not clipped:
      no mass piles up at 0), ``sd >= 0``; the mean may be below 0 down to 30 standard deviations;
    * ``"lognormal"``, ``median`` (s) and ``sigma``: ``ln(delay)`` is normal with mean ``ln(median)`` and standard
      deviation ``sigma``, ``median > 0``, ``sigma >= 0``;
    * ``"array"``, ``values`` (s): these delays exactly, one run each, in order (no randomness).

    The parameters are keyword-only; the class methods :meth:`uniform`, :meth:`normal`, :meth:`lognormal` and
    :meth:`from_array` build the same objects.  A bad parameter raises
    :class:`~delaykit.errors.InvalidValueError` naming it.

    Examples
    --------
    >>> DelayDistribution("uniform", lo=0.3, hi=0.45)
    DelayDistribution(uniform 0.3 to 0.45 s)
    >>> DelayDistribution("normal", mean=0.35, sd=0.05).to_dict()
    {'kind': 'normal', 'mean': 0.35, 'sd': 0.05}
    """

    kind: str
    _: KW_ONLY
    lo: float | None = None
    hi: float | None = None
    mean: float | None = None
    sd: float | None = None
    median: float | None = None
    sigma: float | None = None
    values: Any = None

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        if not isinstance(self.kind, str) or self.kind not in DISTRIBUTION_KINDS:
            raise InvalidValueError(f"kind must be one of {', '.join(DISTRIBUTION_KINDS)}; got {self.kind!r}")
        need = _PARAMS[self.kind]
        given = [p for p in _ALL_PARAMS if getattr(self, p) is not None]
        extra = [p for p in given if p not in need]
        if extra:
            raise InvalidValueError(f"a {self.kind} delay distribution takes {' and '.join(need)}, not "
                                    f"{', '.join(f'{p}={getattr(self, p)!r}' for p in extra)}")
        missing = [p for p in need if p not in given]
        if missing:
            raise InvalidValueError(f"a {self.kind} delay distribution needs {' and '.join(need)}; "
                                    f"{' and '.join(missing)} missing")
        if self.kind == "uniform":
            lo = check_real("lo (s)", self.lo, minimum=0.0)
            hi = check_real("hi (s)", self.hi, minimum=0.0)
            if hi < lo:
                raise InvalidValueError(f"hi (s) must be at least lo = {lo:g} s, got {hi:g}")
            set_("lo", lo)
            set_("hi", hi)
        elif self.kind == "normal":
            sd = check_real("sd (s)", self.sd, minimum=0.0)
            mean = check_real("mean (s)", self.mean, minimum=0.0 if sd == 0.0 else None)
            if sd > 0.0 and mean < -30.0 * sd:
                raise InvalidValueError(f"mean (s) must be above -30 sd = {-30.0 * sd:g} s (the normal truncated "
                                        f"at 0 would have no mass left), got {mean:g}")
            set_("mean", mean)
            set_("sd", sd)
        elif self.kind == "lognormal":
            set_("median", check_real("median (s)", self.median, minimum=0.0, strict=True))
            set_("sigma", check_real("sigma (of ln delay)", self.sigma, minimum=0.0))
        else:
            if isinstance(self.values, (str, bytes)):
                raise InvalidTypeError(f"values must be delays (numbers), got {self.values!r}")
            try:
                v = np.asarray(self.values, dtype=float)
            except (TypeError, ValueError):
                raise InvalidTypeError(f"values must be delays (numbers), got {self.values!r}") from None
            if v.ndim != 1 or v.size == 0:
                raise InvalidValueError(f"values must be a non-empty 1-D list of delays, got shape {v.shape}")
            set_("values", tuple(_checked_delays(v, "values").tolist()))

    @classmethod
    def uniform(cls, lo: float, hi: float) -> "DelayDistribution":
        """Uniform on ``[lo, hi]`` (s).

        Examples
        --------
        >>> DelayDistribution.uniform(0.3, 0.45).bounds()
        (0.3, 0.45)
        """
        return cls("uniform", lo=lo, hi=hi)

    @classmethod
    def normal(cls, mean: float, sd: float) -> "DelayDistribution":
        """Normal with ``mean`` and ``sd`` (s), truncated at 0.

        Examples
        --------
        >>> DelayDistribution.normal(0.35, 0.05)
        DelayDistribution(normal mean 0.35 s, sd 0.05 s, truncated at 0)
        """
        return cls("normal", mean=mean, sd=sd)

    @classmethod
    def lognormal(cls, median: float, sigma: float) -> "DelayDistribution":
        """Lognormal: ``ln(delay)`` normal with mean ``ln(median)`` and standard deviation ``sigma``.

        Examples
        --------
        >>> DelayDistribution.lognormal(0.35, 0.2)
        DelayDistribution(lognormal median 0.35 s, sigma 0.2)
        """
        return cls("lognormal", median=median, sigma=sigma)

    @classmethod
    def from_array(cls, values: Any) -> "DelayDistribution":
        """These delays (s), one run each, in order.

        Examples
        --------
        >>> DelayDistribution.from_array([0.3, 0.35, 0.4])
        DelayDistribution(array of 3 delays, 0.3 to 0.4 s)
        """
        return cls("array", values=values)

    @property
    def size(self) -> int | None:
        """The number of delays of an ``"array"`` distribution (None for the random kinds)."""
        return len(self.values) if self.kind == "array" else None

    def draw(self, n: int | None = None, rng: np.random.Generator | int | None = None) -> np.ndarray:
        """``n`` delays (s) drawn with ``rng`` (a generator, a seed or None); an array distribution returns its
        values (``n`` must then be None or their number).

        Examples
        --------
        >>> d = DelayDistribution.uniform(0.3, 0.45).draw(1000, rng=1)
        >>> d.shape, bool(d.min() >= 0.3 and d.max() <= 0.45)
        ((1000,), True)
        """
        n = _check_runs(n, self)
        if self.kind == "array":
            return np.asarray(self.values, dtype=float)
        g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        if self.kind == "uniform":
            return g.uniform(self.lo, self.hi, n)
        if self.kind == "lognormal":
            return g.lognormal(math.log(self.median), self.sigma, n)
        if self.sd == 0.0:
            return np.full(n, self.mean)
        # the normal conditioned on delay >= 0, by its inverse distribution function on the upper tail (accurate
        # however little of the normal lies above 0): z > a = -mean/sd has P = ndtr(mean/sd) = q, and
        # z = -ndtri(v) with v uniform on (0, q] has P(z > x) = ndtr(-x) / q, the tail conditioned on z > a
        from scipy.special import ndtr, ndtri

        q = float(ndtr(self.mean / self.sd))
        z = -ndtri((1.0 - g.random(n)) * q)
        return np.maximum(self.mean + self.sd * z, 0.0)

    def bounds(self) -> tuple[float, float]:
        """The smallest and largest delay the distribution can give (``inf`` when unbounded).

        Examples
        --------
        >>> DelayDistribution.normal(0.35, 0.05).bounds()
        (0.0, inf)
        """
        if self.kind == "uniform":
            return float(self.lo), float(self.hi)
        if self.kind == "array":
            return float(min(self.values)), float(max(self.values))
        if self.kind == "normal":
            return (float(self.mean), float(self.mean)) if self.sd == 0.0 else (0.0, math.inf)
        return (float(self.median), float(self.median)) if self.sigma == 0.0 else (0.0, math.inf)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description: the kind and its parameters.

        Examples
        --------
        >>> DelayDistribution.lognormal(0.35, 0.2).to_dict()
        {'kind': 'lognormal', 'median': 0.35, 'sigma': 0.2}
        """
        return {"kind": self.kind, **{p: (list(self.values) if p == "values" else getattr(self, p))
                                      for p in _PARAMS[self.kind]}}

    def __repr__(self) -> str:
        if self.kind == "uniform":
            law = f"uniform {self.lo:g} to {self.hi:g} s"
        elif self.kind == "normal":
            law = f"normal mean {self.mean:g} s, sd {self.sd:g} s, truncated at 0"
        elif self.kind == "lognormal":
            law = f"lognormal median {self.median:g} s, sigma {self.sigma:g}"
        else:
            lo, hi = self.bounds()
            law = f"array of {len(self.values)} delays, {lo:g} to {hi:g} s"
        return f"DelayDistribution({law})"


def _check_runs(n: Any, model: Any) -> int:
    """The number of runs: ``n``, or by default the array's length (an array distribution) or 200."""
    size = model.size if isinstance(model, DelayDistribution) else None
    if n is None:
        return size if size is not None else _DEFAULT_RUNS
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InvalidValueError(f"n (number of runs) must be a positive integer, got {n!r}")
    check_count("n (number of runs)", int(n), MAX_GRID_POINTS, "runs")
    if size is not None and int(n) != size:
        raise InvalidValueError(f"n (number of runs) must be None or {size} for an array of {size} delays "
                                f"(one run each), got {n}")
    return int(n)


# ---------------------------------------------------------------------------------------------- the result
@dataclass(frozen=True, repr=False, eq=False)
class MonteCarlo:
    """Step metrics over random delay realisations: one value per run (NaN where absent, e.g. not settled).

    Attributes
    ----------
    runs, seed : int
        The number of runs and the seed they were drawn with.
    overshoot, peak_time, rise_time, settling_time : ndarray
        One value per run, in percent and seconds (NaN: no peak, not risen, not settled by ``t_end``).
    levels : tuple of float
        The percentiles reported.
    method : str
        The path that ran: ``"batched"`` (a :class:`DelayDistribution`: one call of the exact kernel over all
        runs) or ``"events"`` (a per-packet delay model: one event simulation per run); see
        :data:`MONTE_CARLO_METHODS`.
    delay : DelayDistribution or DelayModel
        What the delays were drawn from.
    delays : ndarray or None
        The constant delay of each run (batched path; None for the per-packet path).
    model_delay : float or None
        A compensator's model delay, which stayed fixed while the true delay was drawn (None: no compensator).
    """

    runs: int
    seed: int | None
    overshoot: np.ndarray = field(repr=False)
    peak_time: np.ndarray = field(repr=False)
    rise_time: np.ndarray = field(repr=False)
    settling_time: np.ndarray = field(repr=False)
    levels: tuple[float, ...] = (5.0, 50.0, 95.0)
    method: str = "events"
    delay: Any = None
    delays: np.ndarray | None = field(default=None, repr=False)
    model_delay: float | None = None

    @property
    def unsettled(self) -> int:
        """Runs that did not settle by the end."""
        return int(np.count_nonzero(np.isnan(self.settling_time)))

    def percentiles(self, name: str) -> dict[float, float | None]:
        """The percentiles (at ``levels``) of one metric over the runs that have it.

        Examples
        --------
        >>> from delaykit.models import Controller, Loop
        >>> loop = Loop("1/s", Controller.p(1.31), umin=-1, umax=1)
        >>> mc = monte_carlo(loop, DelayDistribution.from_array([0.3, 0.368, 0.4]), levels=(0.0, 50.0))
        >>> {p: round(v, 4) for p, v in mc.percentiles("overshoot").items()}
        {0.0: 0.0197, 50.0: 2.263}
        """
        if name not in _METRICS:
            raise InvalidValueError(f"metric must be one of {', '.join(_METRICS)}; got {name!r}")
        a = getattr(self, name)[np.isfinite(getattr(self, name))]
        return {p: (float(np.percentile(a, p)) if a.size else None) for p in self.levels}

    def to_dict(self, arrays: bool = False) -> dict[str, Any]:
        """JSON-ready form: the method, the delay's description, the percentiles of each metric (keys like
        ``"p50"``) and the counts; with ``arrays``, the per-run values too (NaN as None).

        Examples
        --------
        >>> from delaykit.models import Controller, Loop
        >>> mc = monte_carlo(Loop("1/s", Controller.p(1.31), umin=-1, umax=1), DelayDistribution.from_array([0.3]))
        >>> d = mc.to_dict()
        >>> d["method"], d["delay"]["kind"], d["unsettled"]
        ('batched', 'array', 0)
        """
        d: dict[str, Any] = {
            "runs": self.runs, "seed": self.seed, "method": self.method,
            "delay": self.delay.to_dict() if self.delay is not None else None, "model_delay": self.model_delay,
            "unsettled": self.unsettled,
            "percentiles": {m: {f"p{p:g}": v for p, v in self.percentiles(m).items()} for m in _METRICS}}
        if arrays:
            nn = lambda a: [None if math.isnan(x) else float(x) for x in a]  # noqa: E731
            d.update({m: nn(getattr(self, m)) for m in _METRICS})
            d["delays"] = None if self.delays is None else self.delays.tolist()
        return d

    def __repr__(self) -> str:
        f = lambda m: "/".join("-" if v is None else f"{v:.4g}" for v in self.percentiles(m).values())  # noqa: E731
        comp = f", compensator's model delay fixed at {self.model_delay:g} s" if self.model_delay is not None else ""
        return (f"MonteCarlo({self.runs} runs, percentiles {'/'.join(f'{p:g}' for p in self.levels)}: overshoot "
                f"{f('overshoot')} %, settling {f('settling_time')} s, {self.unsettled} unsettled; method "
                f"{self.method}{comp})")


# ------------------------------------------------------------------------------------------------ the runs
def monte_carlo(loop: Any, model: Any, *, n: int | None = None, seed: int | None = None, step: float = 1.0,
                t_end: float = 15.0, period: float | None = None, dt: float | None = None, band: float = 0.02,
                levels: Sequence[float] = (5.0, 50.0, 95.0)) -> MonteCarlo:
    """The distribution of the step metrics over ``n`` random delay realisations.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        The loop.  Its input delay is replaced by the drawn delays; its output delay is kept.
    model : DelayDistribution, DelayModel, float or list of (time, delay)
        A :class:`DelayDistribution`: each run's delay is a constant drawn from it, and all runs are one call of
        the exact batch kernel :func:`~delaykit.simulate.simulation.simulate_many` (``method="batched"``; a
        compensator's model delay stays fixed, the drawn delay is the true one).  Anything else is a per-packet
        delay model (:func:`~delaykit.simulate.varying.as_delay_model`): each run is an event simulation of the
        sampled loop, :func:`~delaykit.simulate.varying.simulate_varying` (``method="events"``).
    n : int, optional
        The number of runs (default 200; for an ``"array"`` distribution, its length, which ``n`` must equal).
    seed : int, optional
        Makes the draws reproducible.  Batched path: the ``n`` delays are drawn from
        ``numpy.random.default_rng(seed)``.  Event path: run ``i`` draws from the ``i``-th stream spawned by
        ``numpy.random.SeedSequence(seed)`` (the model's own seed is not used).
    step, t_end, band : float
        The reference step at t = 0, the end of each run (s) and the settling band (fraction of the step).
    period : float, optional
        The controller's sampling period (default: the loop's).  The event path needs one; the batched path
        runs a continuous loop as it is.
    dt : float, optional
        Event path only: the record's spacing (see ``simulate_varying``).  The kernel of the batched path is exact
        and has no grid, so it ignores ``dt``.
    levels : sequence of float
        The percentiles to report (0 to 100).

    Returns
    -------
    MonteCarlo

    Examples
    --------
    >>> from delaykit.models import Controller, Loop
    >>> from delaykit.simulate.varying import Jitter
    >>> loop = Loop("1/s", Controller.p(1.31), umin=-1, umax=1, period=0.065)
    >>> mc = monte_carlo(loop, Jitter(0.3, "exponential", scale=0.05), n=20, seed=4, t_end=8.0, dt=0.02)
    >>> mc.runs, mc.unsettled, mc.method
    (20, 0, 'events')
    >>> mc = monte_carlo(loop, DelayDistribution.uniform(0.3, 1.4), n=100, seed=4, t_end=8.0)
    >>> mc.method, mc.unsettled > 0
    ('batched', True)
    """
    _check_seed(seed)
    lv = tuple(check_real("percentile level", p, minimum=0.0, maximum=100.0) for p in levels)
    if isinstance(model, np.ndarray):
        raise InvalidTypeError("an array of delays is ambiguous: wrap it as DelayDistribution.from_array(values) "
                               "(one constant delay per run) or DelayTrace(times, delays) (a delay per packet)")
    runs = _check_runs(n, model)
    if isinstance(model, DelayDistribution):
        return _batched(loop, model, runs, seed, step=step, t_end=t_end, period=period, band=band, levels=lv)
    dm = as_delay_model(model)
    return _events(loop, dm, runs, seed, step=step, t_end=t_end, period=period, dt=dt, band=band, levels=lv)


def _batched(loop: Any, dist: DelayDistribution, n: int, seed: int | None, *, step: float, t_end: float,
             period: float | None, band: float, levels: tuple[float, ...]) -> MonteCarlo:
    """All runs in one call of the exact kernel: the loop's input delay swept over the drawn delays."""
    gen = as_loop(loop)
    if period is not None:
        gen = gen.replace(period=check_real("period (s)", period, minimum=0.0, strict=True))
    delays = dist.draw(n, np.random.default_rng(seed))
    # simulate_many's sweep of `delay` writes the kernel's true input delay only: a compensator keeps the model
    # delay of its realisation (tests/test_montecarlo.py checks this against per-run simulate() calls)
    b = simulate_many(gen, delay=delays, step=step, t_end=t_end, band=band)
    comp = gen.controller if isinstance(gen.controller, Compensator) else None
    return MonteCarlo(runs=n, seed=seed, levels=levels, method="batched", delay=dist, delays=delays,
                      model_delay=float(comp.model_delay) if comp is not None else None,
                      **{m: np.asarray(getattr(b, m), dtype=float).copy() for m in _METRICS})


def _events(loop: Any, model: DelayModel, n: int, seed: int | None, *, step: float, t_end: float,
            period: float | None, dt: float | None, band: float, levels: tuple[float, ...]) -> MonteCarlo:
    """One event simulation per run, run ``i`` drawing from the ``i``-th stream spawned from ``seed``."""
    streams = np.random.SeedSequence(seed).spawn(n)
    out = {m: np.full(n, np.nan) for m in _METRICS}
    for i, ss in enumerate(streams):
        r = simulate_varying(loop, model, step=step, t_end=t_end, period=period, dt=dt, band=band,
                             rng=np.random.default_rng(ss))
        for m in _METRICS if r.metrics is not None else ():
            out[m][i] = np.nan if getattr(r.metrics, m) is None else getattr(r.metrics, m)
    return MonteCarlo(runs=n, seed=seed, levels=levels, method="events", delay=model, **out)
