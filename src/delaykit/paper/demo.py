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
   after every step, raising the alarm when it leaves the design range and re-designing the law.

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
from ..errors import FlightError
from ..models.altitude import AltitudeLoop
from ..hardware.emulator import DroneEmulator, EmulatorConfig
from ..hardware.flight import FlightPlan, FlightResult, fly
from ..identify.estimation import DelayEstimate, estimate_flights
from ..identify.flightlog import FlightLog
from ..models.compensators import COMPENSATOR_KINDS
from ..simulate.metrics import step_metrics
from .data import PAPER_PV_KV, TABLE1_KP, TABLE3_KP

__all__ = ["DemoReport", "run_demo", "P_KP", "PV_KP", "PV_KV_CANDIDATES", "FALLBACK_KV"]

P_STEPS = (1.0, -1.0, 1.0, -1.0, 1.0)
#: The P gain of the step tests the delay is estimated from: the paper's flights (Table 1, Table 2).
P_KP = TABLE1_KP
#: The PV loop's proportional gain, and the velocity gains its design compares: the paper's Tables 3 and 4.
PV_KP = TABLE3_KP
PV_KV_CANDIDATES = "0:0.7:8"
#: Flown only when the design finds no candidate that settles: the paper's own choice (Table 3, Fig. 8).
FALLBACK_KV = PAPER_PV_KV


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
                "files": [str(f) for f in self.files]}

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
) -> DemoReport:
    """Run the pipeline and write ``demo.md``, ``demo.json`` and the figures into ``out``.

    The P step tests fly at :data:`P_KP` (the paper's 1.31); the PV loop at :data:`PV_KP` (2.0) with the Kv that
    settles fastest among :data:`PV_KV_CANDIDATES` for the estimated delay.  If none of them settles, the paper's
    Kv = :data:`FALLBACK_KV` is flown instead, and the report, its ``kv_source`` and the status line say so.

    With ``compensate``, the best of the three compensators for the estimated delay flies the PV flight's steps;
    on the emulator, ``varying_steps`` steps of ``varying_duration`` seconds then fly it again while the
    emulator's delay grows by ``delay_jump`` after about half of them (0: no such flight).

    Raises :class:`~delaykit.errors.FlightError` when the P flight produced no logs (nothing to estimate from).
    """
    say = status or (lambda _m: None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    emu = None
    truth = None
    if host is None:
        rng = random.Random(seed)
        cfg = EmulatorConfig(at_port=0, navdata_port=0, video_port=0, control_port=0,
                             delay=round(rng.uniform(0.22, 0.42), 4), lag=0.05, noise=0.004, seed=seed)
        emu = DroneEmulator(cfg).start()
        truth = emu.true_delay
        host, at_port, navdata_port = "127.0.0.1", emu.ports["at"], emu.ports["navdata"]
        say("emulator started on 127.0.0.1 with a delay the pipeline is not told")
    try:
        say(f"P flight: {p_steps} step tests at Kp = {P_KP:g}")
        steps = tuple((P_STEPS * 3)[:p_steps])
        p = fly(FlightPlan(kp=P_KP, steps=steps, step_duration=step_duration, hover_time=1.5), out / "p_flight.csv",
                host=host, at_port=at_port, navdata_port=navdata_port, confirm=confirm, status=say)
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
                            hover_time=1.5), out / "pv_flight.csv", host=host, at_port=at_port,
                 navdata_port=navdata_port, confirm=confirm, status=say)
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
                                step_duration=step_duration, hover_time=1.5), out / "comp_flight.csv", host=host,
                     at_port=at_port, navdata_port=navdata_port, confirm=confirm, status=say)
    finally:
        if emu is not None:
            emu.stop()
    vf = vtruth = None
    if comp is not None and emu is not None and varying_steps > 0 and delay_jump != 0:
        vf, vtruth = _varying_flight(out, emu.config, designs[comp["chosen"]].compensator, varying_steps,
                                     varying_duration, delay_jump, say)
    pm, vm = _metrics(p.logs), _metrics(pv.logs)
    cm = _metrics(cf.logs) if cf is not None else None
    files = _write(out, truth, est, lag, kv, d, p, pv, pm, vm, kv_source=kv_source, comp=comp, cf=cf, cm=cm, vf=vf,
                   vtruth=vtruth)
    return DemoReport(out=out, true_delay=truth, estimate=est, lag=lag, kv=kv, kv_source=kv_source, p_flight=p,
                      pv_flight=pv, p_metrics=pm, pv_metrics=vm, files=files, compensator=comp, comp_flight=cf,
                      comp_metrics=cm, varying_flight=vf, varying_truth=vtruth)


def _settling(design: Any) -> float:
    m = design.steps.get(1.0)
    return math.inf if m is None or m.settling_time is None else float(m.settling_time)


def _varying_flight(out: Path, cfg: EmulatorConfig, law: Any, n: int, duration: float, jump: float,
                    say: Callable[[str], None]) -> tuple[FlightResult, dict]:
    """The compensator on the same emulated vehicle, its delay growing by ``jump`` after about half the steps."""
    from ..hardware.monitor import DelayMonitor

    # take-off (~1.2 s) and the hover (1.5 s), then the steps (each followed by a fraction of a second of
    # estimation): the change falls in the middle of the step after half of them
    change = 2.7 + (n // 2) * (duration + 0.2) + duration / 2
    vcfg = replace(cfg, delay_schedule=((change, cfg.delay + jump),))
    emu = DroneEmulator(vcfg).start()
    truth = {"before": emu.true_delay, "after": emu.true_delay + jump, "change_time": change}
    say(f"a delay that moves: {emu.true_delay:.3f} s, then {emu.true_delay + jump:.3f} s from {change:.1f} s")
    try:
        mon = DelayMonitor(law, schedule=True)
        steps = tuple((1.0, -1.0) * n)[:n]
        vf = fly(FlightPlan(kp=0.0, controller=law, steps=steps, step_duration=duration, hover_time=1.5),
                 out / "varying_flight.csv", host="127.0.0.1", at_port=emu.ports["at"],
                 navdata_port=emu.ports["navdata"], status=say, monitor=mon)
        truth["t0"] = emu.start_time
    finally:
        emu.stop()
    return vf, truth


def _write(out, truth, est, lag, kv, d, p, pv, pm, vm, kv_source="design", comp=None, cf=None, cm=None, vf=None,
           vtruth=None) -> tuple[Path, ...]:
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
    text = ("# delaykit demo: fly, estimate, design, fly again\n\n"
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
    md = out / "demo.md"
    md.write_text(text)
    js = out / "demo.json"
    js.write_text(json.dumps({"true_delay": truth, "estimate": est.to_dict(), "lag": lag, "p_kp": P_KP,
                              "pv_kp": PV_KP, "kv": kv, "kv_source": kv_source,
                              "p_metrics": pm, "pv_metrics": vm, "p_flight": p.to_dict(), "pv_flight": pv.to_dict(),
                              "compensator": comp, "comp_metrics": cm,
                              "comp_flight": None if cf is None else cf.to_dict(),
                              "varying_flight": None if vf is None else vf.to_dict(), "varying_truth": vtruth},
                             indent=2, default=str))
    extra = [*(cf.logs if cf is not None else ()), *(vf.logs if vf is not None else ())]
    return (md, js, *figs, *p.logs, *pv.logs, *extra)
