"""The emulated flights of docs/guide/tuning.md: ``python docs/guide/tuning_flights.py`` flies them and prints the table.

Each controller of the paper's altitude loop (SIMC, AMIGO and MIGO PI tuned by :func:`delaykit.tune`, and the
paper's PV law with its filtered velocity) flies one 1 m step on the built-in emulator on loopback, its vehicle
configured as the paper's loop: a pure integrator (the ``lag`` vehicle with no lag, no hover wander), an actuator
delay of 0.37 s, navdata at 15 Hz, 2 mm of altitude noise, the command limited to +-1 m/s.  The flown step metrics
are set beside the exact simulation of the same loop: sampled at the flight's packet interval, with the delay the
controller saw (the emulator's delay plus the flight loop's mean latency, packet in to command out).  This runs in
real time (about 20 s a flight).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from delaykit import AltitudeLoop, Controller, Loop, simulate, tune
from delaykit.hardware.emulator import DroneEmulator, EmulatorConfig
from delaykit.hardware.flight import FlightPlan, fly
from delaykit.identify.flightlog import FlightLog
from delaykit.simulate.metrics import StepMetrics, step_metrics

DELAY = 0.37
STEP = 1.0
VMAX = 1.0


@dataclass(frozen=True)
class FlownStep:
    """One tuned controller flown on the emulator beside its exact simulation."""

    name: str
    flown: StepMetrics
    simulated: StepMetrics
    delay_seen: float
    packet_interval: float


def controllers() -> list[tuple[str, Controller | None, dict]]:
    """(name, controller, FlightPlan's P/PV keys) of the paper's loop, tuned as in the guide's drone table."""
    base = dict(delay=DELAY, umin=-VMAX, umax=VMAX, step=STEP, load=0.5, t_end=40.0)
    out: list[tuple[str, Controller | None, dict]] = []
    for name, kw in (("SIMC PI", dict(rule="simc")), ("AMIGO PI", dict(rule="amigo")),
                     ("MIGO PI, Ms 1.4", dict(ms=1.4))):
        t = tune("1/s", "pi", **kw, **base)
        out.append((name, Controller.pi(t.kp, t.ki), {}))
    out.append(("paper PV, Kp 2, Kv 0.3 (filtered)", None, dict(kp=2.0, kv=0.3, velocity="filtered")))
    return out


def _simulated(controller: Controller | None, pv: dict, delay: float, period: float, t_end: float) -> StepMetrics:
    if controller is None:
        loop = AltitudeLoop(kp=pv["kp"], kv=pv["kv"], velocity=pv["velocity"], delay=delay, period=period)
    else:
        loop = Loop("1/s", controller, delay=delay, umin=-VMAX, umax=VMAX, period=period)
    return simulate(loop, STEP, t_end=t_end).metrics


def fly_one(name: str, controller: Controller | None, pv: dict, *, duration: float = 14.0, seed: int = 1,
            log_dir: Path | None = None) -> FlownStep:
    """Fly one step of ``controller`` (or the P/PV law of ``pv``) on the paper's emulated loop and simulate it."""
    free = dict(at_port=0, navdata_port=0, video_port=0, control_port=0)
    config = EmulatorConfig(**free, vehicle="lag", lag=0.0, delay=DELAY, noise=0.002, seed=seed)
    plan = FlightPlan(kp=pv.get("kp", 0.0), kv=pv.get("kv", 0.0), velocity=pv.get("velocity", "true"),
                      controller=controller, vmax=VMAX, steps=(STEP,), step_duration=duration, hover_time=0.8,
                      gap_timeout=2.0)
    with tempfile.TemporaryDirectory() as tmp:
        where = Path(log_dir or tmp)
        with DroneEmulator(config) as emu:
            res = fly(plan, where / f"{name.split(',')[0].replace(' ', '_')}.csv", host="127.0.0.1",
                      at_port=emu.ports["at"], navdata_port=emu.ports["navdata"])
            truth = emu.true_delay
        if not res.completed:
            raise RuntimeError(f"the {name} flight ended early: {res.reason}")
        log = FlightLog.from_csv(res.logs[0])
    latency = float(np.mean(np.asarray(log.extra["latency_ms"], dtype=float))) / 1e3
    seen = truth + latency
    period = float(res.packet_interval)
    flown = step_metrics(log.t, log.z, step=log.step, step_time=log.step_time)
    simulated = _simulated(controller, pv, seen, period, duration)
    return FlownStep(name, flown, simulated, seen, period)


def _f(x: float | None, digits: int = 3) -> str:
    return "–" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


HEAD = ("| controller | delay seen s | overshoot % flown / simulated | rise s flown / simulated | "
        "settling s flown / simulated |\n|---|---|---|---|---|")


def table(rows: list[FlownStep]) -> str:
    """The Markdown table of the flights."""
    lines = [f"| {r.name} | {r.delay_seen:.3f} | {_f(r.flown.overshoot)} / {_f(r.simulated.overshoot)} | "
             f"{_f(r.flown.rise_time)} / {_f(r.simulated.rise_time)} | "
             f"{_f(r.flown.settling_time)} / {_f(r.simulated.settling_time)} |" for r in rows]
    return HEAD + "\n" + "\n".join(lines)


if __name__ == "__main__":
    print(table([fly_one(n, c, pv) for n, c, pv in controllers()]))
