"""A command delay that varies from packet to packet, and the exact response of a sampled loop to it.

**The physical model.**  A sampled controller with period ``h`` sends command packet ``k`` at
``t_k = sample_offset + k h`` (``k = 0, 1, ...``): it reads the measurement (and, for the PV law, the true
velocity) at ``t_k``, computes its law, clips the command to ``[umin, umax]`` and sends it.  The packet arrives
``d_k`` seconds later, ``d_k`` given by a delay model at the send time (a schedule, a random jitter, a burst, a
replayed trace or their sum).  The plant applies the newest packet that has arrived (the highest sequence number
so far) and holds it until a newer one arrives: its input is piecewise constant, switching at arrival times.

* ``keep_order=False`` (the default): packets may overtake.  The receiver keeps the newest sequence number and
  drops a packet that arrives after a newer one (stale), as the AR.Drone does with its AT commands' sequence
  numbers: when the delay falls by more than a period, packets are dropped.
* ``keep_order=True``: first in, first out; a packet that would overtake waits for its predecessor
  (``a_k = max(t_k + d_k, a_{k-1})``), like a TCP stream's head-of-line blocking; none is dropped.

Between two events (a sample or an arrival) the plant's input and the reference are constant, so the loop's
state (the plant's, then the controller's) moves by the exact matrix exponential of the linear loop.  The
controller's states (integrator, filters) run in continuous time on the continuous measurement, as in
:func:`delaykit.simulate.simulate`, so with a constant delay both give the same response to rounding.  An output
delay ``To`` is exact too: the controller sees ``y(t - To)``, the same plant's response to the input ``To``
later.  Deviation variables from rest before t = 0.  Limits: the reference is a step at t = 0; anti-windup and
compensators with an internal model are refused.

Examples
--------
>>> from delaykit.models import Controller, Loop
>>> loop = Loop("1/s", Controller.p(1.31), delay=0.25, umin=-1, umax=1, period=0.065)
>>> sched = DelaySchedule([0.0, 2.0], [0.25, 0.40])          # the delay moves from 0.25 s to 0.40 s at 2 s
>>> r = simulate_varying(loop, sched, t_end=8.0)
>>> r.delays[[0, -1]].tolist(), r.dropped
([0.25, 0.4], 0)
>>> round(float(r.output[-1]), 4)
1.0
"""

from __future__ import annotations

import csv
import io
import math
import reprlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .. import _native
from ..errors import InvalidTypeError, InvalidValueError, check_path, check_real
from ..models.budget import read_regular
from ..models.ranges import parse_number
from ..models.altitude import as_loop
from ..models.closed_loop import loop_realisation
from ..models.controllers import Controller
from ..models.loop import Loop
from .metrics import StepMetrics, step_metrics

__all__ = ["DelayModel", "DelaySchedule", "Jitter", "Burst", "DelayTrace", "CombinedDelay", "as_delay_model",
           "arrival_plan", "VaryingResponse", "simulate_varying", "JITTER_DISTRIBUTIONS"]

JITTER_DISTRIBUTIONS = ("uniform", "exponential", "gamma")


# ------------------------------------------------------------------------------------------ delay models
def _checked_delays(values: Any, what: str, times: np.ndarray | None = None) -> np.ndarray:
    """``values`` as floats, each finite and >= 0, or an error naming the first bad one."""
    d = _floats(values, what)
    bad = ~np.isfinite(d) | (d < 0)
    if np.any(bad):
        i = int(np.flatnonzero(bad.ravel())[0])
        at = f" at t = {times.ravel()[i]:g} s" if times is not None else f"[{i}]"
        raise InvalidValueError(f"{what}{at} must be a finite delay of at least 0 s, got {d.ravel()[i]:g}")
    return d


def _floats(values: Any, what: str) -> np.ndarray:
    """``values`` as an array of floats, or an :class:`InvalidTypeError` naming ``what`` (text, complex numbers...)."""
    try:
        return np.asarray(values, dtype=float)
    except OverflowError:  # an integer of hundreds of digits
        raise InvalidValueError(f"{what} must be finite, got an integer beyond the floats in "
                                f"{reprlib.repr(values)}") from None
    except (TypeError, ValueError):
        raise InvalidTypeError(f"{what} must be real numbers (seconds), got {values!r}") from None


def _increasing(times: Any, what: str) -> np.ndarray:
    t = _floats(times, what)
    if t.ndim != 1 or t.size == 0 or not np.all(np.isfinite(t)):
        raise InvalidValueError(f"{what} must be a non-empty list of finite times, got {times!r}")
    if np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise InvalidValueError(f"{what} must increase: {what}[{i}] = {t[i]:g} s is not after "
                                f"{what}[{i - 1}] = {t[i - 1]:g} s")
    return t


def _check_seed(seed: Any) -> None:
    """A seed NumPy's generators take: None or an integer >= 0."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))):
        raise InvalidTypeError(f"seed must be an integer or None, got {seed!r}")
    if seed is not None and seed < 0:
        raise InvalidValueError(f"seed must be at least 0 (NumPy's generators take non-negative seeds), got {seed}")


class DelayModel:
    """Base of the delay models: :meth:`packet_delays` gives each packet's delay from its send time; ``a + b``
    adds two models packet by packet (:class:`CombinedDelay`); ``keep_order``: see the module docstring."""

    keep_order: bool = False

    def packet_delays(self, send_times: Any, rng: np.random.Generator | None = None) -> np.ndarray:
        """The delay (s) of the packets sent at ``send_times`` (random models draw from ``rng``)."""
        raise NotImplementedError

    def bounds(self) -> tuple[float, float]:
        """The smallest and largest delay the model can give (``inf`` when unbounded)."""
        raise NotImplementedError

    def __add__(self, other: Any) -> "CombinedDelay":
        return CombinedDelay((self, as_delay_model(other)))

    __radd__ = __add__

    def to_dict(self) -> dict[str, Any]:  # pragma: no cover (abstract)
        """JSON-ready description."""
        raise NotImplementedError


@dataclass(frozen=True, repr=False, eq=False)
class DelaySchedule(DelayModel):
    """A delay that is piecewise constant in time, or a function of time evaluated at each send time.

    ``delay(t) = delays[i]`` for ``times[i] <= t < times[i+1]`` (before ``times[0]``, ``delays[0]``); times
    increase strictly, delays are at least 0.  With ``function`` set, ``delay(t) = function(t)``, checked at every
    packet.

    Examples
    --------
    >>> DelaySchedule([0.0, 5.0], [0.25, 0.40]).packet_delays([0.0, 4.9, 5.0, 9.0]).tolist()
    [0.25, 0.25, 0.4, 0.4]
    >>> DelaySchedule.from_function(lambda t: 0.25 + t / 8).packet_delays([0.0, 1.0]).tolist()
    [0.25, 0.375]
    """

    times: Any = (0.0,)
    delays: Any = (0.0,)
    function: Callable[[float], float] | None = None
    keep_order: bool = False

    def __post_init__(self) -> None:
        if self.function is not None and not callable(self.function):
            raise InvalidTypeError(f"function must be callable, got {type(self.function).__name__}")
        t, d = _increasing(self.times, "times"), _checked_delays(self.delays, "delays")
        if d.ndim != 1 or d.size != t.size:
            raise InvalidValueError(f"a schedule needs one delay per time: {t.size} times, {d.size} delays")
        object.__setattr__(self, "times", tuple(t.tolist()))
        object.__setattr__(self, "delays", tuple(d.tolist()))
        object.__setattr__(self, "keep_order", bool(self.keep_order))

    @classmethod
    def constant(cls, delay: float) -> "DelaySchedule":
        """The same delay for every packet.

        Examples
        --------
        >>> DelaySchedule.constant(0.3).bounds()
        (0.3, 0.3)
        """
        return cls((0.0,), (check_real("delay (s)", delay, minimum=0.0),))

    @classmethod
    def from_pairs(cls, pairs: Sequence[Sequence[float]], *, keep_order: bool = False) -> "DelaySchedule":
        """A schedule from ``(time, delay)`` pairs, e.g. ``[(0, 0.25), (20, 0.40)]``.

        Examples
        --------
        >>> DelaySchedule.from_pairs([(0, 0.25), (20, 0.4)]).value(25.0)
        0.4
        """
        rows = list(pairs) if isinstance(pairs, (list, tuple)) else []
        if not rows or any(not isinstance(p, (list, tuple)) or len(p) != 2 for p in rows):
            raise InvalidValueError(f"a delay schedule is a non-empty list of (time, delay) pairs, got {pairs!r}")
        return cls([p[0] for p in rows], [p[1] for p in rows], keep_order=keep_order)

    @classmethod
    def from_function(cls, function: Callable[[float], float], *, keep_order: bool = False) -> "DelaySchedule":
        """A delay computed by ``function(t)`` at each send time (its range is not known in advance)."""
        return cls(function=function, keep_order=keep_order)

    def value(self, t: Any) -> Any:
        """The delay at time(s) ``t`` (a float for a scalar)."""
        tt = np.asarray(t, dtype=float)
        if self.function is not None:
            d = _checked_delays([self.function(float(x)) for x in tt.ravel()], "the delay function's value", tt)
            d = d.reshape(tt.shape)
        else:
            i = np.clip(np.searchsorted(np.asarray(self.times), tt, side="right") - 1, 0, len(self.times) - 1)
            d = np.asarray(self.delays)[i]
        return float(d) if d.ndim == 0 else d

    def packet_delays(self, send_times: Any, rng: np.random.Generator | None = None) -> np.ndarray:
        return np.atleast_1d(np.asarray(self.value(np.asarray(send_times, dtype=float)), dtype=float))

    def bounds(self) -> tuple[float, float]:
        return (0.0, math.inf) if self.function is not None else (float(min(self.delays)), float(max(self.delays)))

    def to_dict(self) -> dict[str, Any]:
        if self.function is not None:
            return {"kind": "schedule", "function": getattr(self.function, "__name__", "?"),
                    "keep_order": self.keep_order}
        return {"kind": "schedule", "times": list(self.times), "delays": list(self.delays),
                "keep_order": self.keep_order}

    def __repr__(self) -> str:
        if self.function is not None:
            return f"DelaySchedule(function {getattr(self.function, '__name__', '?')})"
        if len(self.times) == 1:
            return f"DelaySchedule(constant {self.delays[0]:g} s)"
        return f"DelaySchedule({', '.join(f'{d:g} s from {t:g} s' for t, d in zip(self.times, self.delays))})"


@dataclass(frozen=True, repr=False, eq=False)
class Jitter(DelayModel):
    """A base delay plus a random extra per packet.

    ``distribution``: ``"uniform"`` (extra uniform in ``[0, spread]``), ``"exponential"`` (mean ``scale``) or
    ``"gamma"`` (shape ``shape``, scale ``scale``: the extra is a gamma variable, so the delay a shifted gamma).
    ``cap`` clips the extra (a bounded channel).  ``seed`` makes the draws reproducible (Monte Carlo passes its own
    generator instead).  ``keep_order``: see the module docstring (default False: overtaking packets are dropped).

    Examples
    --------
    >>> j = Jitter(0.25, "uniform", spread=0.1, seed=1)
    >>> d = j.packet_delays(np.arange(1000) * 0.065)
    >>> bool(d.min() >= 0.25 and d.max() <= 0.35), j.bounds()
    (True, (0.25, 0.35))
    """

    base: float = 0.0
    distribution: str = "uniform"
    spread: float = 0.0
    scale: float = 0.0
    shape: float = 1.0
    cap: float | None = None
    seed: int | None = None
    keep_order: bool = False

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        for name in ("base", "spread", "scale"):
            set_(name, check_real(f"{name} (s)", getattr(self, name), minimum=0.0))
        if not isinstance(self.distribution, str) or self.distribution not in JITTER_DISTRIBUTIONS:
            raise InvalidValueError(f"distribution must be one of {', '.join(JITTER_DISTRIBUTIONS)}; "
                                    f"got {self.distribution!r}")
        set_("shape", check_real("shape", self.shape, minimum=0.0, strict=True))
        if self.cap is not None:
            set_("cap", check_real("cap (largest extra delay, s)", self.cap, minimum=0.0))
        _check_seed(self.seed)
        set_("keep_order", bool(self.keep_order))

    def packet_delays(self, send_times: Any, rng: np.random.Generator | None = None) -> np.ndarray:
        n = np.asarray(send_times, dtype=float).size
        g = rng if rng is not None else np.random.default_rng(self.seed)
        if self.distribution == "uniform":
            extra = g.uniform(0.0, self.spread, n)
        else:
            extra = g.exponential(self.scale, n) if self.distribution == "exponential" else g.gamma(self.shape,
                                                                                                   self.scale, n)
        return self.base + (extra if self.cap is None else np.minimum(extra, self.cap))

    def bounds(self) -> tuple[float, float]:
        top = self.spread if self.distribution == "uniform" else (math.inf if self.scale > 0 else 0.0)
        return self.base, self.base + (top if self.cap is None else min(top, self.cap))

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "jitter", "base": self.base, "distribution": self.distribution, "spread": self.spread,
                "scale": self.scale, "shape": self.shape, "cap": self.cap, "seed": self.seed,
                "keep_order": self.keep_order}

    def __repr__(self) -> str:
        law = {"uniform": f"uniform [0, {self.spread:g}] s", "exponential": f"exponential, mean {self.scale:g} s",
               "gamma": f"gamma, shape {self.shape:g}, scale {self.scale:g} s"}[self.distribution]
        cap = f", capped at {self.cap:g} s" if self.cap is not None else ""
        order = "in order" if self.keep_order else "may overtake"
        return f"Jitter({self.base:g} s + {law}{cap}, {order})"


@dataclass(frozen=True, repr=False, eq=False)
class Burst(DelayModel):
    """During ``[start, end]`` the delay rises by ``extra`` (a Wi-Fi scan), repeated every ``every`` s if given.

    Alone it is 0 outside the burst; add it to a base: ``DelaySchedule.constant(0.25) + Burst(5, 6, 0.3)``.

    Examples
    --------
    >>> (DelaySchedule.constant(0.25) + Burst(5.0, 6.0, 0.3)).packet_delays([4.0, 5.5, 7.0]).tolist()
    [0.25, 0.55, 0.25]
    """

    start: float = 0.0
    end: float = 1.0
    extra: float = 0.0
    every: float | None = None
    keep_order: bool = False

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        set_("start", check_real("start (s)", self.start))
        set_("end", check_real("end (s)", self.end))
        if not self.end > self.start:
            raise InvalidValueError(f"a burst must end after it starts: start {self.start:g} s, end {self.end:g} s")
        set_("extra", check_real("extra (delay added during the burst, s)", self.extra, minimum=0.0))
        if self.every is not None:
            set_("every", check_real("every (s)", self.every, minimum=self.end - self.start, strict=True))
        set_("keep_order", bool(self.keep_order))

    def packet_delays(self, send_times: Any, rng: np.random.Generator | None = None) -> np.ndarray:
        t = np.atleast_1d(np.asarray(send_times, dtype=float))
        into = t - self.start if self.every is None else np.mod(t - self.start, self.every)
        return np.where((t >= self.start) & (into <= self.end - self.start), self.extra, 0.0)

    def bounds(self) -> tuple[float, float]:
        return 0.0, self.extra

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "burst", "start": self.start, "end": self.end, "extra": self.extra, "every": self.every}

    def __repr__(self) -> str:
        rep = f", every {self.every:g} s" if self.every is not None else ""
        return f"Burst(+{self.extra:g} s from {self.start:g} to {self.end:g} s{rep})"


@dataclass(frozen=True, repr=False, eq=False)
class DelayTrace(DelayModel):
    """A recorded delay trace replayed: a packet sent at ``t`` gets the delay recorded at ``start + t``.

    ``interpolation="previous"`` holds each record until the next (``"linear"`` joins them); the first and last
    records hold before and after the trace.  ``start`` defaults to the first record's time.  Build one from
    arrays, from a CSV of ``(t, delay)`` (:meth:`from_csv`) or from a flight log (:meth:`from_flight_log`).

    Examples
    --------
    >>> DelayTrace([10.0, 10.5, 11.0], [0.30, 0.32, 0.29]).packet_delays([0.0, 0.6, 2.0]).tolist()
    [0.3, 0.32, 0.29]
    """

    times: Any = (0.0,)
    delays: Any = (0.0,)
    start: float | None = None
    interpolation: str = "previous"
    keep_order: bool = False
    source: str = "<arrays>"

    def __post_init__(self) -> None:
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        t, d = _increasing(self.times, "times"), _checked_delays(self.delays, "delays")
        if d.ndim != 1 or d.size != t.size:
            raise InvalidValueError(f"a trace needs one delay per time: {t.size} times, {d.size} delays")
        set_("times", tuple(t.tolist()))
        set_("delays", tuple(d.tolist()))
        set_("start", float(t[0]) if self.start is None else check_real("start (trace time of t = 0, s)", self.start))
        if self.interpolation not in ("previous", "linear"):
            raise InvalidValueError(f"interpolation must be 'previous' or 'linear', got {self.interpolation!r}")
        set_("keep_order", bool(self.keep_order))

    @classmethod
    def from_csv(cls, path: str | Path, *, time_column: str = "t", delay_column: str = "delay",
                 unit: str = "s", **kwargs: Any) -> "DelayTrace":
        """A trace from a UTF-8, comma-separated file whose header names ``time_column`` (s) and
        ``delay_column`` (in ``unit``, ``"s"`` or ``"ms"``).  A bad row is an error naming the file, the row (the
        header is row 1) and the value: text, a non-finite number, a time that does not increase, a negative delay.

        Examples
        --------
        >>> import tempfile, os
        >>> with tempfile.NamedTemporaryFile("w", suffix=".csv", delete=False) as f:
        ...     _ = f.write("t,delay\\n0,0.25\\n1,0.3\\n")
        >>> DelayTrace.from_csv(f.name).delays
        (0.25, 0.3)
        >>> os.unlink(f.name)
        """
        if unit not in ("s", "ms"):
            raise InvalidValueError(f"unit must be 's' or 'ms', got {unit!r}")
        name = str(check_path("delay trace", path))
        try:  # (read as identify.flightlog reads a log; this layer may not import it)
            data = read_regular(path, "delay trace")  # (a regular file of bounded size only)
            rows = list(csv.reader(io.StringIO(data.decode("utf-8-sig"), newline="")))
        except OSError as exc:
            raise InvalidValueError(f"{name}: cannot be read ({exc.strerror or exc})") from None
        except (UnicodeDecodeError, csv.Error) as exc:
            raise InvalidValueError(f"{name} is not a readable UTF-8 CSV ({exc})") from None
        header = [h.strip() for h in rows[0]] if rows else []
        missing = [c for c in (time_column, delay_column) if c not in header]
        if missing:
            raise InvalidValueError(f"{name}: no column {missing[0]!r} (the header has {', '.join(header)})")
        cols = {c: header.index(c) for c in (time_column, delay_column)}
        times: list[float] = []
        delays: list[float] = []
        for line, row in enumerate(rows[1:], start=2):
            if not any(c.strip() for c in row):
                continue
            vals = {}
            for col, i in cols.items():
                cell = row[i].strip() if i < len(row) else ""
                try:
                    vals[col] = parse_number(cell)
                except ValueError:
                    vals[col] = math.nan
                if not math.isfinite(vals[col]):
                    raise InvalidValueError(f"{name}: row {line}: {col} is {cell!r}, not a finite number")
            t, d = vals[time_column], vals[delay_column]
            if times and not t > times[-1]:
                raise InvalidValueError(f"{name}: row {line}: {time_column} = {t:g} does not increase (after "
                                        f"{times[-1]:g})")
            if d < 0:
                raise InvalidValueError(f"{name}: row {line}: {delay_column} must be at least 0, got {d:g}")
            times.append(t)
            delays.append(d / 1000.0 if unit == "ms" else d)
        if not times:
            raise InvalidValueError(f"{name}: no rows after the header")
        return cls(times, delays, source=name, **kwargs)

    @classmethod
    def from_flight_log(cls, path: str | Path, **kwargs: Any) -> "DelayTrace":
        """The ``latency_ms`` column of a log written by ``delaykit fly`` (times from ``t``).

        That column is the loop's own latency (navdata received to command sent); add a base delay for the
        network and the actuator: ``DelayTrace.from_flight_log(f) + DelaySchedule.constant(0.25)``.
        """
        return cls.from_csv(path, time_column="t", delay_column="latency_ms", unit="ms", **kwargs)

    def packet_delays(self, send_times: Any, rng: np.random.Generator | None = None) -> np.ndarray:
        tau = np.atleast_1d(np.asarray(send_times, dtype=float)) + self.start
        times, delays = np.asarray(self.times), np.asarray(self.delays)
        if self.interpolation == "linear":
            return np.interp(tau, times, delays)
        return delays[np.clip(np.searchsorted(times, tau, side="right") - 1, 0, times.size - 1)]

    def bounds(self) -> tuple[float, float]:
        return float(min(self.delays)), float(max(self.delays))

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "trace", "source": self.source, "records": len(self.times), "start": self.start,
                "interpolation": self.interpolation, "bounds": list(self.bounds())}

    def __repr__(self) -> str:
        lo, hi = self.bounds()
        return f"DelayTrace({self.source}: {len(self.times)} records, {lo:g} to {hi:g} s)"


@dataclass(frozen=True, repr=False, eq=False)
class CombinedDelay(DelayModel):
    """The sum of delay models, packet by packet (a schedule plus a jitter plus a burst); the channel keeps the
    order if any part asks for it."""

    parts: tuple[DelayModel, ...] = ()

    def __post_init__(self) -> None:
        bad = [type(p).__name__ for p in self.parts if not isinstance(p, DelayModel)]
        if bad:
            raise InvalidTypeError(f"a combined delay adds delay models, got {bad[0]}")
        flat = (q for p in self.parts for q in (p.parts if isinstance(p, CombinedDelay) else (p,)))
        object.__setattr__(self, "parts", tuple(flat))

    @property
    def keep_order(self) -> bool:  # type: ignore[override]
        return any(p.keep_order for p in self.parts)

    def packet_delays(self, send_times: Any, rng: np.random.Generator | None = None) -> np.ndarray:
        t = np.atleast_1d(np.asarray(send_times, dtype=float))
        return sum((p.packet_delays(t, rng) for p in self.parts), np.zeros(t.size))

    def bounds(self) -> tuple[float, float]:
        lo, hi = zip(*(p.bounds() for p in self.parts))
        return float(sum(lo)), float(sum(hi))

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "sum", "parts": [p.to_dict() for p in self.parts]}

    def __repr__(self) -> str:
        return " + ".join(map(repr, self.parts))


def as_delay_model(delay: Any) -> DelayModel:
    """A delay model from a model, a number (a constant delay) or ``(time, delay)`` pairs.

    Examples
    --------
    >>> as_delay_model(0.3)
    DelaySchedule(constant 0.3 s)
    """
    if isinstance(delay, DelayModel):
        return delay
    if isinstance(delay, (int, float, np.floating, np.integer)) and not isinstance(delay, bool):
        return DelaySchedule.constant(delay)
    if isinstance(delay, (list, tuple)):
        return DelaySchedule.from_pairs(delay)
    raise InvalidTypeError(f"delay must be a delay model (DelaySchedule, Jitter, Burst, DelayTrace), a number "
                           f"or (time, delay) pairs; got {type(delay).__name__}")


def arrival_plan(send_times: np.ndarray, delays: np.ndarray, keep_order: bool) -> tuple[np.ndarray, np.ndarray]:
    """Arrival times and whether each packet is applied: ``(arrival, used)``.

    ``arrival[k]`` is when packet ``k`` reaches the plant (with ``keep_order``, no earlier than its predecessor);
    ``used[k]`` is False for a packet that arrives after (or with) a newer one: it is dropped.

    Examples
    --------
    >>> a, used = arrival_plan(np.array([0.0, 0.1, 0.2]), np.array([0.5, 0.2, 0.2]), keep_order=False)
    >>> a.round(3).tolist(), used.tolist()
    ([0.5, 0.3, 0.4], [False, True, True])
    """
    return _plan(np.asarray(send_times, float) + np.asarray(delays, float), keep_order)


def _plan(a: np.ndarray, keep_order: bool) -> tuple[np.ndarray, np.ndarray]:
    if keep_order:
        return np.maximum.accumulate(a), np.ones(a.size, bool)
    later = np.r_[np.minimum.accumulate(a[::-1])[::-1][1:], np.inf]  # the earliest arrival of any newer packet
    return a, a < later


# ---------------------------------------------------------------------------------------------- the kernel
VK = _native.load("delaykit.simulate", "_varyingkernel")
"""The compiled event loop (``simulate/_varyingkernel.py``): the extension built at install, else numba's copy."""


def _loop_matrices(loop: Loop) -> tuple[np.ndarray, np.ndarray]:
    """``M`` with ``z' = M z`` for ``z`` = (the plant's states, the controller's, the plant's input ``w``, the
    reference ``r``), and the rows that read ``y``, ``y'`` and the controller's output ``v`` from ``z``."""
    c = loop.controller
    if not isinstance(c, Controller) or getattr(c.realisation(), "reads_command", False):
        raise InvalidValueError(f"simulate_varying runs the controllers p, pv, pi, pd, pid and tf; got "
                                f"{type(c).__name__} (a compensator with an internal model is not supported)")
    if c.antiwindup != "none":
        raise InvalidValueError(f"simulate_varying does not model anti-windup (antiwindup={c.antiwindup!r}); "
                                "use antiwindup='none'")
    lr = loop_realisation(loop)
    f = lr.folded()  # the measurement is the output itself (no output delay)
    n = lr.order
    rows = np.zeros((3, n + 2))  # y, y' and v
    rows[0, :n], rows[0, n] = lr.cy, lr.dy
    rows[1, :n], rows[1, n] = lr.cyd, lr.dyd
    rows[2, :n], rows[2, n], rows[2, n + 1] = f.k, f.kw, f.dvr
    M = np.zeros((n + 2, n + 2))
    M[:n, :n] = f.A
    M[:n, n] = f.b
    M[:n, n + 1] = f.br
    return M, rows


def _metrics(t: np.ndarray, y: np.ndarray, dl: np.ndarray, dr: np.ndarray, step: float, z0: float,
             band: float) -> StepMetrics:
    """:func:`step_metrics` of the record with the peak refined: between two records the output is smooth (every
    switch is a record), so the cubic Hermite through the values and the one-sided slopes has its maximum to
    O(dt^4)."""
    m = step_metrics(t, z0 + y, step=step, z0=z0, band=band)
    w = y / step
    i = int(np.argmax(w))
    best, tb = float(w[i]), float(t[i])
    for a in (i - 1, i) if 0 < i < t.size - 1 else ():
        hh = t[a + 1] - t[a]
        p0, p1, m0, m1 = w[a], w[a + 1], dr[a] / step * hh, dl[a + 1] / step * hh
        c = np.array([2 * p0 + m0 - 2 * p1 + m1, -3 * p0 - 2 * m0 + 3 * p1 - m1, m0, p0])  # the cubic in s
        for s in np.roots(np.polyder(c)):
            if abs(s.imag) < 1e-12 and 0.0 < s.real < 1.0 and np.polyval(c, s.real) > best:
                best, tb = float(np.polyval(c, s.real)), float(t[a] + s.real * hh)
    over = best > 1.0
    return replace(m, overshoot=(best - 1.0) * 100.0 if over else 0.0, peak_time=tb if over else None,
                   peak=float(z0 + best * step), noise=None)


# ---------------------------------------------------------------------------------------------- the result
@dataclass(frozen=True, repr=False, eq=False)
class VaryingResponse:
    """The response of a sampled loop to a step, with a time-varying command delay.

    Attributes
    ----------
    t, output, applied_input : ndarray
        Record times (s), the output ``z0 + y`` and the input the plant applies (the held command).
    send_times, commands, delays, arrival_times, used : ndarray
        Per packet: when it was sent, its (saturated) command, its delay, when it reached the plant and whether
        the plant applied it (False: dropped as stale).
    metrics : StepMetrics
        Step metrics read off the record (:func:`delaykit.simulate.metrics.step_metrics`).
    """

    loop: Loop
    delay: DelayModel
    step: float
    z0: float
    t_end: float
    t: np.ndarray = field(repr=False)
    output: np.ndarray = field(repr=False)
    applied_input: np.ndarray = field(repr=False)
    send_times: np.ndarray = field(repr=False)
    commands: np.ndarray = field(repr=False)
    delays: np.ndarray = field(repr=False)
    arrival_times: np.ndarray = field(repr=False)
    used: np.ndarray = field(repr=False)
    metrics: StepMetrics | None = None

    @property
    def dropped(self) -> int:
        """Packets dropped because a newer one had arrived first."""
        return int(np.count_nonzero(~self.used))

    def to_dict(self, arrays: bool = False) -> dict[str, Any]:
        """JSON-ready summary (with the arrays when ``arrays``)."""
        d: dict[str, Any] = {
            "loop": self.loop.to_dict(), "delay": self.delay.to_dict(), "step": self.step, "z0": self.z0,
            "t_end": self.t_end, "packets": int(self.send_times.size), "dropped": self.dropped,
            "delay_min": float(self.delays.min()), "delay_max": float(self.delays.max()),
            **(self.metrics.to_dict() if self.metrics is not None else {})}
        keys = ("t", "output", "applied_input", "send_times", "commands", "delays", "arrival_times") if arrays else ()
        return {**d, **{k: getattr(self, k).tolist() for k in keys}}

    def __repr__(self) -> str:
        return (f"VaryingResponse(step={self.step:g}, {self.send_times.size} packets ({self.dropped} dropped), "
                f"delay {self.delays.min():.4g} to {self.delays.max():.4g} s: {self.metrics!r})")


def simulate_varying(loop: Any, delay: Any = None, *, step: float = 1.0, z0: float = 0.0, t_end: float = 15.0,
                     period: float | None = None, dt: float | None = None, band: float = 0.02,
                     keep_order: bool | None = None, rng: np.random.Generator | None = None) -> VaryingResponse:
    """Exact step response of a sampled loop whose command delay varies from packet to packet.

    Parameters
    ----------
    loop : Loop or AltitudeLoop
        The loop; its input delay is replaced by ``delay`` (its output delay is kept).  A continuous loop needs
        ``period``.
    delay : DelayModel, float or list of (time, delay), optional
        The command delay of each packet (see the module docstring); by default the loop's own, constant.
    step, z0 : float
        The reference steps by ``step`` at t = 0 from the rest level ``z0``.
    t_end, period : float
        End of the record (s); the controller's period (default: the loop's).
    dt, band : float
        Spacing of the record (default ``min(period / 4, 0.01)``; the switches are recorded too); the
        settling band of the metrics, as a fraction of the step.
    keep_order : bool, optional
        Override the delay model's ``keep_order``.
    rng : numpy.random.Generator, optional
        The generator random models draw from (default: the model's own seed).

    Returns
    -------
    VaryingResponse

    Examples
    --------
    >>> from delaykit.models import Controller, Loop
    >>> loop = Loop("1/s", Controller.p(1.31), umin=-1, umax=1, period=0.065)
    >>> r = simulate_varying(loop, Jitter(0.3, "uniform", spread=0.1, seed=3), t_end=10.0)
    >>> r.send_times.size, bool(abs(r.output[-1] - 1.0) < 1e-3)
    (154, True)
    """
    gen = as_loop(loop)
    t_end = check_real("t_end (s)", t_end, minimum=0.0, strict=True)
    step = check_real("step", step)
    if step == 0.0:
        raise InvalidValueError("step must not be zero (metrics are relative to the step size)")
    z0 = check_real("z0", z0)
    band = check_real("band", band, minimum=0.0, strict=True, maximum=1.0)
    h = gen.period if period is None else check_real("period (s)", period, minimum=0.0, strict=True)
    if h is None:
        raise InvalidValueError("simulate_varying needs a sampled controller: give the loop a period or pass "
                                "period=...")
    off = gen.sample_offset if gen.period is not None else 0.0
    if off >= h:
        raise InvalidValueError(f"sample_offset {off:g} s must be less than the period {h:g} s")
    model = as_delay_model(gen.delay if delay is None else delay)
    order = model.keep_order if keep_order is None else bool(keep_order)
    dt = min(h / 4, 0.01) if dt is None else check_real("dt (s)", dt, minimum=0.0, strict=True)
    if t_end / dt > 5e6:
        raise InvalidValueError(f"dt = {dt:g} s gives more than 5e6 records over t_end = {t_end:g} s")
    To = gen.output_delay
    M, rows = _loop_matrices(gen)
    horizon = t_end + To  # the controller's time runs To ahead of the plant's output
    n_pk = int(math.floor((horizon - off) / h + 1e-9)) + 1
    send = off + h * np.arange(n_pk)
    d = _checked_delays(np.broadcast_to(model.packet_delays(send, rng), send.shape), "the delay of the packet sent",
                        send)
    arr_c = send + d + To  # in the controller's time; within rounding of a sample instant is at it (the sample
    at = off + np.rint((arr_c - off) / h) * h  # reads the input before the switch)
    arr_c, used = _plan(np.where(np.abs(arr_c - at) <= 1e-9 * h, at, arr_c), order)
    arrival = arr_c - To
    sw = np.flatnonzero(used & (arr_c <= horizon))
    grid = np.arange(0.0, t_end, dt) + To
    sw_t = np.unique(arr_c[sw])
    if sw_t.size:  # a grid point within rounding of a switch is the switch
        j = np.searchsorted(sw_t, grid)
        gap = np.minimum(np.abs(grid - sw_t[np.minimum(j, sw_t.size - 1)]), np.abs(grid - sw_t[np.maximum(j - 1, 0)]))
        grid = grid[gap > 1e-6 * dt]
    rec_c = np.unique(np.concatenate([grid, [horizon], sw_t]))  # records, in the controller's time
    ev_t = np.concatenate([send, arr_c[sw], rec_c])
    ev_kind = np.repeat(np.array([0, 1, 2], np.int64), [send.size, sw.size, rec_c.size])
    ev_idx = np.concatenate([np.arange(send.size), sw, np.arange(rec_c.size)]).astype(np.int64)
    o = np.lexsort((ev_idx, ev_kind, ev_t))
    u_cmd, rec = np.zeros(send.size), np.zeros((rec_c.size, 4))
    VK.events(M, rows, gen.umin, gen.umax, step, np.ascontiguousarray(ev_t[o]), np.ascontiguousarray(ev_kind[o]),
              np.ascontiguousarray(ev_idx[o]), u_cmd, rec)
    z = z0 + rec[:, 0]
    ok = np.all(np.isfinite(z)) and z.size >= 3
    metrics = _metrics(rec_c - To, rec[:, 0], rec[:, 3], rec[:, 2], step, z0, band) if ok else None
    return VaryingResponse(loop=gen, delay=model, step=step, z0=z0, t_end=t_end, t=rec_c - To, output=z,
                           applied_input=rec[:, 1], send_times=send, commands=u_cmd, delays=d, arrival_times=arrival,
                           used=used, metrics=metrics)
