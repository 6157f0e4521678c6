"""The full pipeline in one command: fly step tests, estimate the delay, design the PV gains and a delay
compensator, fly them, watch a delay that moves, report.

By default the "drone" is the built-in emulator on loopback, started with a delay the pipeline is not told;
the report compares the estimate with the emulator's truth.  With a real drone (``host``) the same steps run,
after a confirmation.

The stages:

1. P step tests at the paper's Kp; the loop delay (and the drone's speed lag) estimated from them;
2. the PV gains designed for that delay, and flown;
3. the three delay compensators (:mod:`delaykit.models.compensators`) designed for the integrator model with the
   estimated delay plus the lag (the model the compensators know: the lag counted as delay), and the one whose
   simulated 1 m step settles soonest flown on the same steps: the report compares P, PV and it;
4. on the emulator only: one more flight of that compensator in which the emulator's delay grows by
   ``delay_jump`` seconds mid-flight, with the delay monitor (:mod:`delaykit.hardware.monitor`) re-estimating it
   after every step, raising the alarm when it leaves the design range and re-designing the law;
5. which plant is it?  The P flight identified (:func:`identify_flights`:
   :func:`~delaykit.identify.identification.identify` with ``model="auto"``), closed loop from the reference
   through the known P law, its limits and the packet period, the altitude and the navdata's vertical speed
   fitted jointly.  Not open loop from the logged command:
   the controller answers the altitude's wander and noise, so the command is correlated with the very
   disturbance an output-error fit leaves in its residuals, which biases an open-loop fit; the reference is
   independent of it.  The report gives the structure chosen, its parameters with their 95 % intervals, its dead
   time against the emulator's true loop delay, and the free-run prediction RMS
   (:func:`~delaykit.identify.identification.predict`) of the PV flight by the identified model beside the paper
   model's (the integrator with the estimated delay and lag: the estimator's).

By default the emulator flies its richer vehicle (``vehicle="speed_loop"``: the PX4's identified speed loop and a
hover wander, :mod:`delaykit.hardware.emulator`), not the estimator's own model; ``vehicle="lag"`` flies the
simple one.  On the speed loop the paper estimator's delay is biased (its model lacks the loop's slow mode), and
the report says by how much.

Examples
--------
>>> import tempfile
>>> rep = run_demo(tempfile.mkdtemp(), p_steps=1, pv_steps=1, step_duration=4.0, seed=3)  # doctest: +SKIP
"""

from __future__ import annotations

import json
import math
import random
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..design.compensators import design_compensator
from ..design.tuning import design_sweep
from ..errors import FlightError, FlightInterruptedError, InvalidValueError, check_path, writing
from ..models.altitude import AltitudeLoop
from ..hardware.emulator import DroneEmulator, EmulatorConfig
from ..hardware.flight import FlightPlan, FlightResult, fly
from ..identify.estimation import DelayEstimate, estimate_flights
from ..identify.flightlog import FlightLog
from ..identify.identification import IdentifiedModel, identify, predict
from ..identify.iodata import Experiment
from ..models.compensators import COMPENSATOR_KINDS
from ..simulate.metrics import step_metrics
from .data import PAPER_PV_KV, TABLE1_KP, TABLE3_KP

__all__ = ["DemoReport", "run_demo", "identify_flights", "flight_experiment", "P_KP", "PV_KP", "PV_KV_CANDIDATES",
           "FALLBACK_KV", "PROTOCOL_RATES"]

P_STEPS = (1.0, -1.0, 1.0, -1.0, 1.0)
#: The P gain of the step tests the delay is estimated from: the paper's flights (Table 1, Table 2).
P_KP = TABLE1_KP
#: The PV loop's proportional gain, and the velocity gains its design compares: the paper's Tables 3 and 4.
PV_KP = TABLE3_KP
PV_KV_CANDIDATES = "0:0.7:8"
#: Flown only when the design finds no candidate that settles: the paper's own choice (Table 3, Fig. 8).
FALLBACK_KV = PAPER_PV_KV
#: How the emulator is flown, and its sample rate (Hz): the AR.Drone's navdata, MAVLink's LOCAL_POSITION_NED, the
#: Tello's state.
PROTOCOL_RATES = {"ardrone": 15.0, "mavlink": 50.0, "tello": 10.0}


@dataclass(frozen=True, repr=False)
class DemoReport:
    """What the demo did and found."""

    out: Path
    true_delay: float | None
    estimate: DelayEstimate
    lag: float | None
    kv: float
    kv_source: str
    p_flight: FlightResult
    pv_flight: FlightResult
    p_metrics: list[dict]
    pv_metrics: list[dict]
    files: tuple[Path, ...]
    p_kp: float = P_KP
    compensator: dict | None = None
    comp_flight: FlightResult | None = None
    comp_metrics: list[dict] | None = None
    varying_flight: FlightResult | None = None
    varying_truth: dict | None = None
    pv_kp: float = PV_KP
    vehicle: str | None = None
    identification: dict | None = None

    @property
    def error(self) -> float | None:
        """Estimate minus truth (s), when the truth is known (emulator)."""
        return None if self.true_delay is None else self.estimate.delay - self.true_delay

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"true_delay": self.true_delay, "estimate": self.estimate.to_dict(), "error": self.error,
                "lag": self.lag, "p_kp": self.p_kp, "pv_kp": self.pv_kp, "pv_kv": self.kv,
                "pv_kv_source": self.kv_source, "p_flight": self.p_flight.to_dict(),
                "pv_flight": self.pv_flight.to_dict(), "p_metrics": self.p_metrics, "pv_metrics": self.pv_metrics,
                "files": [str(f) for f in self.files], "vehicle": self.vehicle, "identification": self.identification}

    def __repr__(self) -> str:
        t = "" if self.true_delay is None else f" (truth {self.true_delay:.4f} s, error {1e3 * self.error:+.1f} ms)"
        return (f"DemoReport(delay {self.estimate.delay:.4f} s ± {self.estimate.stderr or 0:.4f}{t}, "
                f"PV Kp = {self.pv_kp:g}, Kv = {self.kv:g} ({self.kv_source}))")


def _metrics(logs: tuple[Path, ...]) -> list[dict]:
    out = []
    for p in logs:
        log = FlightLog.from_csv(p)
        m = step_metrics(log.t, log.z, step=log.step, z0=log.z0, step_time=log.step_time, smooth=5, peak_window=5)
        out.append({"file": str(p), "step": log.step, **m.to_dict()})
    return out


def run_demo(
    out: str | Path = "out/demo",
    *,
    host: str | None = None,
    at_port: int = 5556,
    navdata_port: int = 5554,
    seed: int | None = None,
    p_steps: int = 5,
    pv_steps: int = 2,
    step_duration: float = 8.0,
    compensate: bool = True,
    varying_steps: int = 6,
    varying_duration: float = 4.0,
    delay_jump: float = 0.15,
    confirm: Callable[[], bool] | None = None,
    status: Callable[[str], None] | None = None,
    vehicle: str = "speed_loop",
    identify_plant: bool = True,
    protocol: str = "ardrone",
    autopilot: str = "ardupilot",
    link: Callable[[], Any] | None = None,
) -> DemoReport:
    """Run the pipeline and write ``demo.md``, ``demo.json`` and the figures into ``out``.

    The P step tests fly at :data:`P_KP` (the paper's 1.31); the PV loop at :data:`PV_KP` (2.0) with the Kv that
    settles fastest among :data:`PV_KV_CANDIDATES` for the estimated delay.  If none of them settles, the paper's
    Kv = :data:`FALLBACK_KV` is flown instead, and the report, its ``kv_source`` and the status line say so.

    With ``compensate``, the best of the three compensators for the estimated delay flies the PV flight's steps;
    on the emulator, ``varying_steps`` steps of ``varying_duration`` seconds then fly it again while the
    emulator's delay grows by ``delay_jump`` after about half of them (0: no such flight).

    ``protocol`` is how the emulator is flown: ``"ardrone"`` (AT commands and navdata at 15 Hz), ``"mavlink"``
    (its MAVLink front end behaving as ``autopilot``, ``"ardupilot"`` or ``"px4"``, flown by
    :class:`~delaykit.hardware.mavlink.MavlinkLink` at 50 Hz) or ``"tello"`` (its Tello front end, flown by
    :class:`~delaykit.hardware.tello.TelloLink` at 10 Hz).  A real vehicle is ``host`` (an AR.Drone) or
    ``link``, a function making a :class:`~delaykit.hardware.link.VehicleLink` for each flight.

    ``vehicle`` is the emulator's (:data:`~delaykit.hardware.emulator.VEHICLES`; not used with ``host``).  With
    ``identify_plant`` the P flights are identified and the identified model and the paper model predict the PV
    flights (:attr:`DemoReport.identification`; see the module docstring).

    Raises :class:`~delaykit.errors.FlightError` when the P flight produced no logs (nothing to estimate from), and
    :class:`~delaykit.errors.FlightInterruptedError` when a flight was interrupted (Ctrl-C, or SIGTERM and SIGHUP
    within :func:`~delaykit.hardware.flight.land_on_signals`): it landed, and no further flight takes off.

    Examples
    --------
    >>> rep = run_demo("out/demo", seed=2026, p_steps=2, pv_steps=2, compensate=False)  # doctest: +SKIP
    >>> rep.identification["structure"], rep.identification["delay_covers_truth"]  # doctest: +SKIP
    ('ipdt_speed', True)
    """
    say = status or (lambda _m: None)
    out = check_path("output folder", out)
    out.mkdir(parents=True, exist_ok=True)
    emu = None
    truth = None
    if protocol not in PROTOCOL_RATES:
        raise InvalidValueError(f"protocol must be one of {', '.join(PROTOCOL_RATES)}, got {protocol!r}")
    if host is not None and link is not None:
        raise InvalidValueError("give host (an AR.Drone) or link (another vehicle), not both")
    fly_kw: dict[str, Any] = ({"link": link} if link is not None else
                              {"host": host, "at_port": at_port, "navdata_port": navdata_port})
    if host is None and link is None:
        rng = random.Random(seed)
        cfg = EmulatorConfig(at_port=0, navdata_port=0, video_port=0, control_port=0,
                             delay=round(rng.uniform(0.22, 0.42), 4), lag=0.05, noise=0.004, seed=seed,
                             vehicle=vehicle, rate=PROTOCOL_RATES[protocol])
        emu, fly_kw = _start_emulator(cfg, protocol, autopilot)
        truth = emu.true_delay
        say("emulator started on 127.0.0.1 with a delay the pipeline is not told")
    try:
        say(f"P flight: {p_steps} step tests at Kp = {P_KP:g}")
        steps = tuple((P_STEPS * 3)[:p_steps])
        p = fly(FlightPlan(kp=P_KP, steps=steps, step_duration=step_duration, hover_time=1.5), out / "p_flight.csv",
                confirm=confirm, status=say, **fly_kw)
        _stop_if_interrupted(p, "the P flight")
        if not p.logs:
            raise FlightError(f"the P flight did not fly: {p.reason}")
        say("estimating the delay")
        logs = [FlightLog.from_csv(f) for f in p.logs]
        period = p.packet_interval
        est, _ = estimate_flights(logs, kp=P_KP, period=period, free=("lag",))
        lag = float(np.mean(est.params.lag)) if est.params.lag is not None else None
        say(f"designing PV gains for Td = {est.delay:.4f} s")
        d = design_sweep(AltitudeLoop(kp=PV_KP, delay=est.delay, period=period, lag=lag or 0.0), PV_KP,
                         PV_KV_CANDIDATES, criterion="settling")
        if d.best is not None:
            kv, kv_source = d.best.kv, "design"
        else:
            kv, kv_source = FALLBACK_KV, f"fallback: the paper's Kv, as the design found no candidate ({d.reason})"
            say(f"no PV design: {d.reason}; flying the paper's Kv = {kv:g} instead")
        say(f"PV flight: Kp = {PV_KP:g}, Kv = {kv:g}")
        pv = fly(FlightPlan(kp=PV_KP, kv=kv, steps=tuple((P_STEPS * 2)[:pv_steps]), step_duration=step_duration,
                            hover_time=1.5), out / "pv_flight.csv", confirm=confirm, status=say, **fly_kw)
        _stop_if_interrupted(pv, "the PV flight")
        comp = cf = None
        if compensate:
            model_delay = est.delay + (lag or 0.0)
            say(f"designing the compensators for 1/s with the delay {model_delay:.4f} s")
            designs = {k: design_compensator(k, "1/s", model_delay, umin=-1.0, umax=1.0) for k in COMPENSATOR_KINDS}
            best = min(designs, key=lambda k: _settling(designs[k]))
            comp = {"chosen": best, "model_delay": model_delay,
                    "designs": {k: {"params": v.compensator.params(), "settling_1m": _settling(v),
                                    "delay_ratio_range": list(v.delay_ratio_range)} for k, v in designs.items()}}
            say(f"{best} flight (the soonest-settling design)")
            cf = fly(FlightPlan(kp=0.0, controller=designs[best].compensator, steps=tuple((P_STEPS * 2)[:pv_steps]),
                                step_duration=step_duration, hover_time=1.5), out / "comp_flight.csv",
                     confirm=confirm, status=say, **fly_kw)
            _stop_if_interrupted(cf, f"the {best} flight")
    finally:
        if emu is not None:
            emu.stop()
    vf = vtruth = None
    if comp is not None and emu is not None and varying_steps > 0 and delay_jump != 0:
        vf, vtruth = _varying_flight(out, emu.config, designs[comp["chosen"]].compensator, varying_steps,
                                     varying_duration, delay_jump, say, protocol, autopilot)
    ident = None
    if identify_plant:
        say("identifying the plant from the P flights")
        ident = identify_flights(p.logs, pv.logs, est, lag, kv, truth=truth, save=out / "identified_model.json",
                                 status=say)
    pm, vm = _metrics(p.logs), _metrics(pv.logs)
    cm = _metrics(cf.logs) if cf is not None else None
    files = _write(out, truth, est, lag, kv, d, p, pv, pm, vm, kv_source=kv_source, comp=comp, cf=cf, cm=cm, vf=vf,
                   vtruth=vtruth, ident=ident, vehicle=None if emu is None else emu.config.vehicle)
    return DemoReport(out=out, true_delay=truth, estimate=est, lag=lag, kv=kv, kv_source=kv_source, p_flight=p,
                      pv_flight=pv, p_metrics=pm, pv_metrics=vm, files=files, compensator=comp, comp_flight=cf,
                      comp_metrics=cm, varying_flight=vf, varying_truth=vtruth,
                      vehicle=None if emu is None else emu.config.vehicle, identification=ident)


def _columns(path: str | Path, *names: str) -> FlightLog:
    """A flight log that has the columns ``names`` (beside ``t, z, z_ref, u``), or a delaykit error saying which
    it lacks."""
    log = FlightLog.from_csv(path)
    missing = [n for n in names if n not in log.extra]
    if missing:
        raise InvalidValueError(f"{path}: no {', '.join(missing)} column (a log written by delaykit fly has them)")
    return log


def _packet_period(paths: Any) -> float:
    """The navdata period of flight logs: the least-squares slope of the packets' arrival times (``recv_time``)
    on their sequence numbers, over all the logs (one drone: one grid, one clock).  Not the median arrival
    interval: a packet sent late makes one interval longer and the next shorter, and on a loaded machine that
    median was off by 0.2 %, 25 ms over a flight."""
    seqs, times = [], []
    for path in paths:
        log = _columns(path, "seq", "recv_time")
        seqs.append(np.asarray(log.extra["seq"], dtype=float))
        times.append(np.asarray(log.extra["recv_time"], dtype=float))
    seq = np.concatenate(seqs) if seqs else np.array([])
    if np.unique(seq).size < 3:
        raise InvalidValueError("the flight logs have too few packets to measure their period")
    return float(np.polyfit(seq, np.concatenate(times), 1)[0])


def _flight(paths: Any, period: float) -> tuple[Experiment, int, list[tuple[str, int, int]]]:
    """One flight's step logs merged by sequence number (see :func:`flight_experiment`), the places filled, and
    each log's ``(name, first, last)`` sample of the merged clock."""
    seqs, zs, vs, rs, spans = [], [], [], [], []
    for path in paths:
        log = _columns(path, "seq", "vz")
        seq = np.asarray(log.extra["seq"], dtype=float).astype(np.int64)
        seqs.append(seq)
        zs.append(log.z)
        vs.append(np.asarray(log.extra["vz"], dtype=float))
        rs.append(log.z_ref)
        spans.append((Path(path).name, int(seq.min()), int(seq.max())))
    seq = np.concatenate(seqs)
    order = np.argsort(seq, kind="stable")
    seq, z, v, r = seq[order], np.concatenate(zs)[order], np.concatenate(vs)[order], np.concatenate(rs)[order]
    keep = np.r_[True, np.diff(seq) > 0]  # (a packet in two logs, a log's overlap with the next: once)
    seq, z, v, r = seq[keep], z[keep], v[keep], r[keep]
    k = seq - seq[0]
    n = int(k[-1]) + 1
    idx = np.searchsorted(k, np.arange(n), side="right") - 1  # each place: its packet, or the one before it
    filled = n - int(k.size)
    if filled > 0.1 * n:
        raise InvalidValueError(f"{spans[0][0]}: {filled} of {n} packets are missing from the flight's logs; "
                                "too many to fill")
    name = spans[0][0] if len(spans) == 1 else f"{spans[0][0]} to {spans[-1][0]}"
    exp = Experiment.from_arrays(period * np.arange(n), {"z": z[idx], "vz": v[idx]}, r=r[idx], name=name)
    return exp, filled, [(nm, a - int(seq[0]), b - int(seq[0])) for nm, a, b in spans]


def flight_experiment(paths: Any, period: float) -> tuple[Experiment, int]:
    """A flight's step logs (:func:`~delaykit.hardware.flight.fly`'s CSVs) as one closed-loop experiment.

    The navdata packets go out on a uniform grid and carry a sequence number that counts every packet, sent or
    lost: sample ``k`` is at ``k * period`` from the first packet (the arrival stamps add only the loopback's
    scheduling noise).  A flight's step logs overlap (each starts a second before its step), so merged by
    sequence number they make the whole flight, from the hover before its first step: the one start at rest,
    which an identification (deviation variables from a steady state) needs; a later step's log alone starts in
    the middle of the previous step's response.  A lost packet's place is filled with the packet before it (an
    identification then needs ``fresh_only``); more than a tenth missing is refused.  The outputs: the altitude
    ``z`` and the navdata's vertical speed ``vz``.

    Parameters
    ----------
    paths : path or sequence of path
        One flight's logs.
    period : float
        The packet period (s).

    Returns
    -------
    Experiment, int
        The experiment (outputs ``z`` and ``vz``, reference ``z_ref``), and how many places were filled.

    Examples
    --------
    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "f.csv")
    >>> _ = open(path, "w").write("t,z,z_ref,u,vz,seq,recv_time,latency_ms\\n"
    ...     + "".join(f"{0.05 * k},0.8,{0.8 if k < 6 else 1.8},0,0,{100 + k + (k > 12)},0,0\\n" for k in range(20)))
    >>> exp, filled = flight_experiment(path, 0.05)
    >>> exp, filled
    (Experiment('f.csv': 21 samples every 0.05 s, reference z_ref, outputs z, vz, moves at 0.3 s), 1)
    """
    exp, filled, _ = _flight([paths] if isinstance(paths, (str, Path)) else list(paths), period)
    return exp, filled


def _model_like(model: IdentifiedModel, closed_loop: dict[str, Any]) -> IdentifiedModel:
    """The same plant and dead time under another controller (for predicting flights flown with it)."""
    return IdentifiedModel.from_dict({**model.to_dict(), "closed_loop": closed_loop})


def identify_flights(
    p_logs: Any,
    pv_logs: Any,
    estimate: DelayEstimate,
    lag: float | None,
    kv: float,
    *,
    truth: float | None = None,
    save: str | Path | None = None,
    status: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Identify the plant from the P flight, and predict the PV flight with it and with the paper model.

    The P flight's logs, merged into the whole flight (:func:`flight_experiment`), are identified closed loop
    (:func:`~delaykit.identify.identification.identify`, ``model="auto"``) from the reference through the P law
    at :data:`P_KP`, limits ±1 m/s, at the packet period measured from the logs (see the module docstring for
    why not open loop), the altitude ``z`` with its rate, the navdata's vertical speed ``vz`` (``rate="vz"``: it
    shows the speed loop directly, where the altitude shows it through an integrator and the hover wander), and
    an output offset fitted (``baseline="fit"``: the second of hover before the first step is too short to
    average out a wander of seconds).  The PV flight (flown at :data:`PV_KP` and ``kv`` with the navdata speed),
    merged the same way, is then predicted free-run from its reference by the identified plant and by the paper
    model, the integrator with ``estimate``'s delay behind the ``lag`` (gain 1: the model the demo designs with),
    both under the PV law; the RMS errors are given per step log (over its samples of the whole flight's
    prediction) and over the whole flight.

    Parameters
    ----------
    p_logs, pv_logs : sequence of path
        The P and PV flights' logs.
    estimate : DelayEstimate
        The paper estimator's result on the P flights.
    lag : float or None
        Its fitted speed-loop lag (s).
    kv : float
        The PV flight's velocity gain.
    truth : float, optional
        The true loop delay (s), on the emulator.
    save : path, optional
        Where to write the identified model (JSON, for ``delaykit predict``).
    status : callable, optional
        Called with progress messages.

    Returns
    -------
    dict
        JSON-ready: ``structure``, ``title``, ``criterion``, ``params``, ``stderr``, ``ci``, ``delay``,
        ``delay_ci``, ``true_delay``, ``delay_error``, ``delay_covers_truth``, ``candidates``, ``warnings``,
        ``period``, ``filled_packets``, ``paper_model``, ``estimator`` (its delay, interval, error and whether
        the interval holds the truth), ``pv_predictions`` (per PV step log: ``identified_rms``, ``paper_rms``,
        in metres; ``identified_rms_vz``, ``paper_rms_vz`` for the vertical speed, m/s) and ``pv_flight`` (the
        same over the whole PV flight, and its ``wander`` before the first step); or ``{"error": reason}`` when
        the logs cannot be identified.

    Examples
    --------
    >>> ident = identify_flights(p.logs, pv.logs, est, lag, 0.3, truth=0.30)  # doctest: +SKIP
    >>> ident["structure"], ident["delay_covers_truth"]  # doctest: +SKIP
    ('ipdt_speed', True)
    """
    say = status or (lambda _m: None)
    try:
        period = _packet_period(list(p_logs) + list(pv_logs))
        p_exp, p_filled, _ = _flight(list(p_logs), period)
        pv_exp, pv_filled, pv_spans = _flight(list(pv_logs), period)
        loop = AltitudeLoop(kp=P_KP, delay=0.0, period=period)
        model = identify(p_exp, model="auto", loop=loop, outputs=["z"], rate="vz", baseline="fit",
                         fresh_only=p_filled > 0,
                         progress=say)
    except InvalidValueError as exc:  # (logs an identification cannot use: the report says why)
        return {"error": str(exc)}
    if save is not None:
        model.save(save)
    lo, hi = model.ci["delay"] or (None, None)  # (None: the data did not determine the delay)
    pv_law = {"kp": PV_KP, "kv": float(kv), "umin": -1.0, "umax": 1.0, "period": period}
    names = ("gain", "lag", "delay") if lag else ("gain", "delay")
    values = (1.0, float(lag), estimate.delay) if lag else (1.0, estimate.delay)
    paper_params = dict(zip(names, values))
    paper = IdentifiedModel.from_dict({
        "model": "ipdt_lag" if lag else "ipdt", "params": paper_params, "stderr": dict.fromkeys(names, 0.0),
        "ci": {}, "cov": [[0.0] * len(names)] * len(names), "rms": math.nan, "aic": math.nan, "bic": math.nan,
        "n": 0, "outputs": ["z"], "rate": "vz", "closed_loop": pv_law}, source="the paper model")
    a, b = predict(_model_like(model, pv_law), pv_exp), predict(paper, pv_exp)
    err = {(who, o): pr.measured[o] - pr.predicted[o] for who, pr in (("identified", a), ("paper", b))
           for o in ("z", "vz")}
    rms = lambda e: float(np.sqrt(np.mean(e * e)))  # noqa: E731
    preds = [{"file": nm, **{f"{who}_rms{'' if o == 'z' else '_vz'}": rms(e[i:j + 1]) for (who, o), e in err.items()}}
             for nm, i, j in pv_spans]
    w = a.wander["z"]
    est_ci = estimate.ci
    return {
        "approach": "closed loop from the reference through the P law, the flight's logs merged, z and vz fitted "
                    "jointly, an output offset fitted (see identify_flights)",
        "period": period, "logs": [str(f) for f in p_logs], "filled_packets": p_filled + pv_filled,
        "structure": model.model, "title": model.structure.title, "criterion": model.criterion,
        "params": dict(model.params), "stderr": dict(model.stderr), "ci": {k: None if v is None else list(v)
                                                                   for k, v in model.ci.items()},
        "delay": model.delay, "delay_ci": None if lo is None else [lo, hi], "true_delay": truth,
        "delay_error": None if truth is None else model.delay - truth,
        "delay_covers_truth": None if truth is None or lo is None else bool(lo <= truth <= hi),
        "candidates": [c.to_dict() for c in model.candidates], "warnings": list(model.warnings),
        "paper_model": {"structure": paper.model, "params": paper_params},
        "estimator": {"delay": estimate.delay, "ci": None if est_ci is None else list(est_ci),
                      "error": None if truth is None else estimate.delay - truth,
                      "covers_truth": None if truth is None or est_ci is None
                      else bool(est_ci[0] <= truth <= est_ci[1])},
        "pv_predictions": preds,
        "pv_flight": {"file": pv_exp.name, "identified_rms": a.rms["z"], "paper_rms": b.rms["z"],
                      "identified_rms_vz": a.rms["vz"], "paper_rms_vz": b.rms["vz"],
                      "wander": None if math.isnan(w) else w},
    }


def _settling(design: Any) -> float:
    m = design.steps.get(1.0)
    return math.inf if m is None or m.settling_time is None else float(m.settling_time)


def _start_emulator(cfg: EmulatorConfig, protocol: str, autopilot: str) -> tuple[Any, dict[str, Any]]:
    """Start the emulator behind the ``protocol``'s front end; return it and :func:`fly`'s keywords to reach it."""
    if protocol == "ardrone":
        emu = DroneEmulator(cfg).start()
        return emu, {"host": "127.0.0.1", "at_port": emu.ports["at"], "navdata_port": emu.ports["navdata"]}
    if protocol == "tello":
        import socket

        from ..hardware.emulator_tello import TelloEmulator
        from ..hardware.tello import TelloLink

        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:  # a free port for the state
            probe.bind(("127.0.0.1", 0))
            state_port = probe.getsockname()[1]
        emu = TelloEmulator(cfg, command_port=0, state_port=state_port).start()
        port = emu.ports["command"]
        return emu, {"link": lambda: TelloLink("127.0.0.1", command_port=port, state_port=state_port)}
    from ..hardware.emulator_mavlink import MavlinkEmulator
    from ..hardware.mavlink import MavlinkLink

    emu = MavlinkEmulator(cfg, autopilot=autopilot, listen="tcp:127.0.0.1:0").start()
    conn = f"tcp:127.0.0.1:{emu.ports['mavlink']}"
    return emu, {"link": lambda: MavlinkLink(conn, rate=cfg.rate, takeoff_height=0.8)}


def _varying_flight(out: Path, cfg: EmulatorConfig, law: Any, n: int, duration: float, jump: float,
                    say: Callable[[str], None], protocol: str = "ardrone",
                    autopilot: str = "ardupilot") -> tuple[FlightResult, dict]:
    """The compensator on the same emulated vehicle, its delay growing by ``jump`` after about half the steps."""
    from ..hardware.monitor import DelayMonitor

    # take-off (~1.2 s; about a second more to reach a MAVLink vehicle) and the hover (1.5 s), then the steps (each
    # followed by a fraction of a second of estimation): the change falls in the middle of the step after half
    change = 2.7 + (1.0 if protocol == "mavlink" else 0.0) + (n // 2) * (duration + 0.2) + duration / 2
    vcfg = replace(cfg, delay_schedule=((change, cfg.delay + jump),))
    emu, fly_kw = _start_emulator(vcfg, protocol, autopilot)
    truth = {"before": emu.true_delay, "after": emu.true_delay + jump, "change_time": change}
    say(f"a delay that moves: {emu.true_delay:.3f} s, then {emu.true_delay + jump:.3f} s from {change:.1f} s")
    try:
        mon = DelayMonitor(law, schedule=True)
        steps = tuple((1.0, -1.0) * n)[:n]
        vf = fly(FlightPlan(kp=0.0, controller=law, steps=steps, step_duration=duration, hover_time=1.5),
                 out / "varying_flight.csv", status=say, monitor=mon, **fly_kw)
        truth["t0"] = emu.start_time
    finally:
        emu.stop()
    _stop_if_interrupted(vf, "the flight with a moving delay")
    return vf, truth


def _stop_if_interrupted(flight: FlightResult, which: str) -> None:
    """Raise :class:`~delaykit.errors.FlightInterruptedError` if the user interrupted ``flight`` (it landed): the
    pipeline stops there rather than take off again."""
    if flight.interrupted is not None:
        raise FlightInterruptedError(f"{which} was interrupted ({flight.interrupted}) and landed; the demo stops "
                                     "there (the logs flown so far are kept)", flight.interrupted)


def _identification_text(ident: dict, truth: float | None, vehicle: str | None = None) -> str:
    """The report's section on the identified plant (see :func:`identify_flights`)."""
    head = "\n## Which plant? Identified from the P flights\n\n"
    if "error" in ident:
        return head + f"The P flights could not be identified: {ident['error']}\n"
    ms = lambda x: f"{1e3 * x:.1f}"  # noqa: E731
    rows = ["| parameter | value | 95 % interval |", "|---|---|---|"]
    rows += [f"| {k} | {v:.4g} | " + ("not determined" if ident["ci"][k] is None else
                                     f"{ident['ci'][k][0]:.4g} to {ident['ci'][k][1]:.4g}") + " |"
             for k, v in ident["params"].items()]
    cands = ["| structure | values fitted (BIC's count) | leave-one-log-out RMS (mm) | BIC |", "|---|---|---|---|"]
    for c in ident["candidates"]:
        lolo = "–" if c["lolo_rms"] is None else ms(c["lolo_rms"])
        mark = " (chosen)" if c["model"] == ident["structure"] else ""
        cands.append(f"| {c['model']}{mark} | {c['k']} | {lolo} | {c['bic']:.1f} |")
    lo, hi = ident["delay_ci"] or (None, None)
    text = (head + f"The P flight's step logs merged into the whole flight (from the hover before its first step, "
            f"at rest), identified closed loop from the reference through the P law (Kp = {P_KP:g}, ±1 m/s, a "
            f"command every {1e3 * ident['period']:.1f} ms), the altitude and the navdata's vertical speed fitted "
            "jointly, with an output offset.  Not open loop from the "
            "logged command: the controller answers the altitude's wander and noise, so the command is correlated "
            "with what an output-error fit leaves in its residuals, which biases an open-loop fit; the reference is "
            "independent of it.  Chosen by "
            f"{'BIC' if ident['criterion'] == 'bic' else ident['criterion']}: **{ident['structure']}**, "
            f"{ident['title']}.\n\n" + "\n".join(rows) + "\n\n"
            + ("\n".join(cands) + "\n\n" if ident["candidates"] else ""))
    text += (f"Identified dead time: **{ident['delay']:.4f} s** "
             + ("(its interval not determined by these data)" if lo is None else f"(95 % {lo:.4f} to {hi:.4f} s)"))
    e = ident["estimator"]
    if truth is not None:
        if lo is None:
            text += (f"; the emulator's true loop delay is {truth:.4f} s (error {1e3 * ident['delay_error']:+.1f} "
                     "ms).")
        else:
            text += (f"; the emulator's true loop delay is {truth:.4f} s, "
                     + ("inside" if ident["delay_covers_truth"] else "**outside**")
                     + f" the interval (error {1e3 * ident['delay_error']:+.1f} ms"
                     + ("" if ident["delay_covers_truth"] else "; the interval counts the hover wander and the "
                        "sensor noise, not the timing of the real-time loop, whose latency is given above") + ").")
        text += (f"  The paper estimator's delay, {e['delay']:.4f} s, is off by {1e3 * e['error']:+.1f} ms"
                 + ("" if e["ci"] is None else f" (its 95 % interval {e['ci'][0]:.4f} to {e['ci'][1]:.4f} s "
                    + ("holds the truth)" if e["covers_truth"] else "does not hold the truth)")))
        if vehicle == "speed_loop":
            text += (": **the paper estimator is biased on this vehicle**.  Its model, an integrator behind a "
                     "first-order lag, has no room for the speed loop's slow mode (its zero and slow pole), so its "
                     "delay absorbs it" + (", and the misfit widens its interval" if e["covers_truth"] else "")
                     + ".  The designs above used that delay.")
        elif e["covers_truth"] is False:
            text += ": its model does not describe this vehicle well enough, and its delay is biased."
        else:
            text += "."
        text += "\n\n"
    else:
        text += ".\n\n"
    preds = ["| PV flight | z: identified model (mm) | z: paper model (mm) | vz: identified model (mm/s) | "
             "vz: paper model (mm/s) |", "|---|---|---|---|---|"]
    f = ident["pv_flight"]
    for q in (*ident["pv_predictions"], {**f, "file": "the whole flight"}):
        preds.append(f"| {q['file']} | {ms(q['identified_rms'])} | {ms(q['paper_rms'])} | "
                     f"{ms(q['identified_rms_vz'])} | {ms(q['paper_rms_vz'])} |")
    pm = ident["paper_model"]
    wander = "" if f["wander"] is None else (f"\nFor scale: the altitude's spread in the hover before the first step "
                                             f"was {ms(f['wander'])} mm.\n")
    text += ("### Predicting the PV flights\n\nThe whole PV flight (its step logs merged, from the hover before the "
             "first step) run free from its reference through the PV law, by the identified model and by the paper "
             f"model ({pm['structure']}: " + ", ".join(f"{k} {v:.4g}" for k, v in pm["params"].items())
             + "); the RMS errors over each step log's samples and over the whole flight:\n\n" + "\n".join(preds)
             + f"\n{wander}\n")
    if ident["warnings"]:
        text += "\nThe identification's warnings:\n\n" + "".join(f"* {w}\n" for w in ident["warnings"])
    return text


def _write(out, truth, est, lag, kv, d, p, pv, pm, vm, kv_source="design", comp=None, cf=None, cm=None, vf=None,
           vtruth=None, ident=None, vehicle=None) -> tuple[Path, ...]:
    from ..plotting.figures import plot_fit

    from ..identify.estimation import fitted_altitude

    fig_p, fig_v = out / "p_flights.png", out / "pv_flights.png"
    ls = [FlightLog.from_csv(f) for f in p.logs]
    fits = [(lg.t, fitted_altitude(lg, est, P_KP, i, period=p.packet_interval)) for i, lg in enumerate(ls)]
    plot_fit(ls, fits, fig_p,
             title=f"P control, Kp = {P_KP:g}: data (dots) and the fitted model, Td = {est.delay:.4f} s")
    ls = [FlightLog.from_csv(f) for f in pv.logs]
    plot_fit(ls, [(lg.t, lg.z_ref) for lg in ls], fig_v, lower_label="tracking error z - z_ref (mm)",
             title=f"PV control, Kp = {PV_KP:g}, Kv = {kv:g}: altitude (dots) and reference (lines)")
    figs = [fig_p, fig_v]
    err = "" if truth is None else f" The emulator's true delay is {truth:.4f} s: the error is {1e3 * (est.delay - truth):+.1f} ms."
    if truth is not None and vehicle == "speed_loop":
        err += (" The emulated vehicle is not the estimator's model, so this error is the estimator's bias on it (see "
                "\"Which plant?\" below).")

    def table(ms):
        rows = ["| flight | step (m) | Mo (%) | tp (s) | rise (s) | ts (s) |", "|---|---|---|---|---|---|"]
        f = lambda x: "–" if x is None else f"{x:.3f}"  # noqa: E731
        rows += [f"| {Path(m['file']).name} | {m['step']:+g} | {m['overshoot']:.2f} | {f(m['peak_time'])} | "
                 f"{f(m['rise_time'])} | {f(m['settling_time'])} |" for m in ms]
        return "\n".join(rows)

    interval = "no interval" if est.ci is None else f"95 % interval {est.ci[0]:.4f} to {est.ci[1]:.4f} s"
    design = f"PV design for that delay (Kp = {PV_KP:g}, criterion: settling time): "
    design += (f"Kv = {kv:g} ({d.reason})." if kv_source == "design"
               else f"no candidate; **Kv = {kv:g} flown instead** ({kv_source}).")
    veh = {"speed_loop": "the emulator flies its `speed_loop` vehicle (the PX4's identified speed loop and a hover "
                         "wander), not the estimator's model.\n\n",
           "lag": "the emulator flies its `lag` vehicle: the estimator's own model.\n\n"}.get(vehicle, "")
    text = ("# delaykit demo: fly, estimate, design, fly again\n\n" + (veh[:1].upper() + veh[1:]) +
            f"Estimated loop delay: **{est.delay:.4f} s ± {est.stderr or 0:.4f}** ({interval}) from {est.flights} step "
            f"tests, with the drone's speed-loop lag fitted ({lag if lag is not None else 0:.3f} s).{err}\n\n"
            f"{design}\n\n"
            f"Loop latency (navdata received to command sent): median {p.latency_median_ms:.3f} ms, 99th percentile "
            f"{p.latency_p99_ms:.3f} ms.\n\n## P flights (Kp = {P_KP:g})\n\n{table(pm)}\n\n![P flights](p_flights.png)\n\n"
            f"## PV flights (Kp = {PV_KP:g}, Kv = {kv:g})\n\n{table(vm)}\n\n![PV flights](pv_flights.png)\n")
    if comp is not None and cf is not None:
        fig_c = out / "comp_flights.png"
        ls = [FlightLog.from_csv(f) for f in cf.logs]
        name = comp["chosen"]
        plot_fit(ls, [(lg.t, lg.z_ref) for lg in ls], fig_c, lower_label="tracking error z - z_ref (mm)",
                 title=f"{name} (model 1/s, delay {comp['model_delay']:.3f} s): altitude (dots) and reference")
        figs.append(fig_c)
        rows = ["| compensator | simulated 1 m settling (s) | stable delay ratios |", "|---|---|---|"]
        for k, v in comp["designs"].items():
            lo, hi = v["delay_ratio_range"]
            mark = " (flown)" if k == name else ""
            rows.append(f"| {k}{mark} | {v['settling_1m']:.3f} | {lo:.2f} to {hi:.2f} |")

        def mean_ts(ms):
            x = [m["settling_time"] for m in ms if m["settling_time"] is not None]
            return f"{np.mean(x):.3f} s ({len(x)} of {len(ms)} settled)" if x else f"none of {len(ms)} settled"

        text += (f"\n## Delay compensation\n\nThe three compensators designed for the integrator model with the "
                 f"estimated delay plus the lag, {comp['model_delay']:.4f} s (the lag counted as delay):\n\n"
                 + "\n".join(rows) + f"\n\n### {name} flights\n\n{table(cm)}\n\n![{name} flights](comp_flights.png)\n\n"
                 f"Mean settling time (2 %): P {mean_ts(pm)}, PV {mean_ts(vm)}, {name} {mean_ts(cm)}.\n")
    if vf is not None:
        from ..plotting.compensation import plot_online

        fig_o = out / "online_delay.png"
        plot_online(vf.online, fig_o, t0=vtruth["t0"],
                    truth=((0.0, vtruth["before"]), (vtruth["change_time"], vtruth["after"])))
        figs.append(fig_o)
        rows = ["| step | window (s) | true delay (s) | estimate (s) | 95 % interval | design range | alarm | action |",
                "|---|---|---|---|---|---|---|---|"]
        for o in vf.online:
            a, b = o.estimate.t_from - vtruth["t0"], o.estimate.t_to - vtruth["t0"]
            tr = (f"{vtruth['before']:.3f}" if b <= vtruth["change_time"] else f"{vtruth['after']:.3f}"
                  if a >= vtruth["change_time"] else f"{vtruth['before']:.3f} → {vtruth['after']:.3f}")
            rows.append(f"| {o.step} | {a:.1f} to {b:.1f} | {tr} | {o.delay:.4f} | {o.estimate.ci[0]:.4f} to "
                        f"{o.estimate.ci[1]:.4f} | {o.design_range[0]:.3f} to {o.design_range[1]:.3f} | "
                        f"{'**ALARM**' if o.alarm else ''} | {o.action} |")
        text += (f"\n## A delay that moves\n\nThe emulator's loop delay goes from {vtruth['before']:.3f} s to "
                 f"{vtruth['after']:.3f} s {vtruth['change_time']:.1f} s into the flight.  After every step the delay "
                 "is re-estimated from the step's packets and commands (the drone hovers meanwhile), compared with "
                 "the range the law was designed for, and the law is re-designed when the whole 95 % interval has "
                 "left it.\n\n" + "\n".join(rows) + "\n\n![online estimates](online_delay.png)\n")
        early = [o.delay - vtruth["before"] for o in vf.online
                 if o.estimate.t_to - vtruth["t0"] <= vtruth["change_time"]]
        if vehicle == "speed_loop" and early:
            text += (f"\nOn this vehicle these estimates carry the paper model's bias (\"Which plant?\" below): before "
                     f"the change they exceed the true delay by {1e3 * float(np.mean(early)):+.0f} ms on average.  The "
                     "law was designed for the same biased estimate, so the alarm answers the change, not the "
                     "level.\n")
    if ident is not None:
        text += _identification_text(ident, truth, vehicle)
    md = out / "demo.md"
    with writing("the demo's report", md):
        md.write_text(text)
    js = out / "demo.json"
    with writing("the demo's report", js):
        js.write_text(json.dumps({"true_delay": truth, "estimate": est.to_dict(), "lag": lag, "p_kp": P_KP,
                                  "pv_kp": PV_KP, "kv": kv, "kv_source": kv_source,
                                  "p_metrics": pm, "pv_metrics": vm, "p_flight": p.to_dict(), "pv_flight": pv.to_dict(),
                                  "compensator": comp, "comp_metrics": cm,
                                  "comp_flight": None if cf is None else cf.to_dict(),
                                  "varying_flight": None if vf is None else vf.to_dict(), "varying_truth": vtruth,
                                  "vehicle": vehicle, "identification": ident},
                                 indent=2, default=str))
    extra = [*(cf.logs if cf is not None else ()), *(vf.logs if vf is not None else ())]
    model = out / "identified_model.json"
    if ident is not None and "error" not in ident and model.exists():
        extra.append(model)
    return (md, js, *figs, *p.logs, *pv.logs, *extra)
