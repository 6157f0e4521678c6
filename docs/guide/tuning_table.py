"""The tables of docs/guide/tuning.md, computed: ``python docs/guide/tuning_table.py`` prints them as Markdown.

tests/test_tune.py checks that the tables in the guide are this script's output, so no number there is typed by hand.

* The drone: the paper's altitude loop (``1/s``, delay 0.37 s, command limited to +-1 m/s) tuned by SIMC, AMIGO
  and MIGO (Ms 1.4; also robust over delays 0.30 to 0.45 s), beside the paper's P (Kp 1.31) and PV (Kp 2, Kv 0.3,
  filtered velocity) laws, each simulated exactly for a 1 m setpoint step and a 0.5 m/s load step at the plant
  input.
* The heater: the TCLab step test's FOPDT model (``identify tclab/step_test.csv --model fopdt`` on the shared data:
  K 0.698 degC/%, tau 146.6 s, theta 16.6 s; heater command limited to +-50 % around its operating point) tuned by
  every rule and by MIGO, for a 5 degC setpoint step and a 10 % load step.
* The PX4 vehicle: its identified model (the closed-loop ``ipdt_speed`` fit of t = 10 to 30 s of the HAYDEN
  flights, read from ../shared/data beside the project or $DELAYKIT_DATA: the model of examples/px4-altitude.toml,
  computed here as tests/test_system_files.py computes it; the speed command limited to
  -1/+3 m/s as in the flights) tuned by SIMC, AMIGO and Ziegler-Nichols and by MIGO, beside the PX4's own altitude P
  loop (Kp 0.95), for a 1 m setpoint step and a 0.5 m/s load step; a rule outside its plant family is listed as
  refused with delaykit's reason, and a dagger marks one outside its range of validity (a TuningWarning).
"""

from __future__ import annotations

import math
import warnings

from delaykit import AltitudeLoop, InvalidValueError, TuningWarning, assess, tune


def _f(x: float | None, digits: int = 3) -> str:
    if x is None or not math.isfinite(x):
        return "–"
    return f"{x:.{digits}g}"


def _row(name: str, t) -> str:
    gains = f"{_f(t.kp)}" + (f" / {_f(t.ki)}" if t.kind in ("pi", "pid") else " / –")
    gains += f" / {_f(t.kd)}" if t.kind in ("pd", "pid", "pv") else " / –"
    sp, ld = t.setpoint, t.load
    integral = t.kind in ("pi", "pid")
    load_iae = _f(ld.iae) if integral else f"steady error {_f(ld.size / t.kp)}"
    return (f"| {name} | {gains} | {_f(t.ms)} | {_f(t.gain_margin)} | {_f(t.phase_margin)} | {_f(t.delay_margin)} | "
            f"{_f(sp.overshoot)} | {_f(sp.settling_time)} | {_f(sp.iae)} | {_f(ld.peak_error)} | {load_iae} | "
            f"{_f(ld.recovery_time)} |")


HEAD = ("| tuning | kp / ki / kd (kv) | Ms | GM | PM deg | DM s | overshoot % | settling s | setpoint IAE | "
        "load peak | load IAE | recovery s |\n|---|---|---|---|---|---|---|---|---|---|---|---|")


def drone_table() -> str:
    """The drone's table (Markdown)."""
    base = dict(delay=0.37, umin=-1.0, umax=1.0, step=1.0, load=0.5)
    rows = [
        ("paper P, Kp 1.31", assess(AltitudeLoop(kp=1.31, delay=0.37), step=1.0, load=0.5, t_end=40.0)),
        ("paper PV, Kp 2, Kv 0.3 (filtered)", assess(AltitudeLoop(kp=2.0, kv=0.3, velocity="filtered", delay=0.37),
                                                     step=1.0, load=0.5, t_end=40.0)),
        ("SIMC PI (tau_c = 0.37 s)", tune("1/s", "pi", rule="simc", t_end=40.0, **base)),
        ("AMIGO PI", tune("1/s", "pi", rule="amigo", t_end=40.0, **base)),
        ("AMIGO PID", tune("1/s", "pid", rule="amigo", t_end=40.0, **base)),
        ("MIGO PI, Ms 1.4", tune("1/s", "pi", ms=1.4, t_end=40.0, **base)),
        ("MIGO PI, Ms 1.4, delays 0.30-0.45 s", tune("1/s", "pi", ms=1.4, delays="0.3:0.45:4", t_end=40.0, **base)),
        ("MIGO PI, least load IAE", tune("1/s", "pi", ms=1.4, objective="iae-load", t_end=40.0, **base)),
        ("MIGO PV, Ms 1.4", tune("1/s", "pv", ms=1.4, t_end=40.0, **base)),
    ]
    return HEAD + "\n" + "\n".join(_row(n, t) for n, t in rows)


def heater_table() -> str:
    """The heater's table (Markdown)."""
    plant = "0.698/(146.6*s+1)"
    base = dict(delay=16.6, umin=-50.0, umax=50.0, step=5.0, load=10.0, t_end=1500.0)
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("error", TuningWarning)  # every rule here is inside its range: a warning is a failure
        for name, kw in [("SIMC PI (tau_c = theta)", dict(rule="simc")), ("AMIGO PI", dict(rule="amigo")),
                         ("lambda PI (lambda = theta)", dict(rule="lambda")), ("ZN PI", dict(rule="zn")),
                         ("Tyreus-Luyben PI", dict(rule="tyreus-luyben")), ("MIGO PI, Ms 1.4", dict(ms=1.4)),
                         ("MIGO PI, Ms 1.4, gains 0.8-1.2, delays 14-20 s",
                          dict(ms=1.4, gains="0.8:1.2:3", delays="14:20:4"))]:
            rows.append((name, tune(plant, "pi", **kw, **base)))
        for name, kw in [("SIMC PID", dict(rule="simc")), ("AMIGO PID", dict(rule="amigo")),
                         ("MIGO PID, Ms 1.4", dict(ms=1.4))]:
            rows.append((name, tune(plant, "pid", **kw, **base)))
    return HEAD + "\n" + "\n".join(_row(n, t) for n, t in rows)


def px4_model():
    """The PX4 vehicle's identified model: the closed-loop ``ipdt_speed`` fit of the three HAYDEN flights, cut at
    30 s as for examples/px4-altitude.toml (the shared data's logs run to about 44 s)."""
    from delaykit import Controller, Loop
    from delaykit.identify import identify

    _shared_data()
    from shared_data import px4_flights

    outer = Loop("1/s", Controller.p(0.95), umin=-1.0, umax=3.0, period=0.02)  # the flights' loop (data README)
    runs = px4_flights([f"HAYDEN_0{i}" for i in (1, 2, 3)], reference="z_ref", t_end=30.0)
    return identify(runs, model="ipdt_speed", loop=outer, fresh_only=True)


def _shared_data():
    """Make tests/shared_data.py importable: it says where the real data is read (../shared/data)."""
    import sys
    from pathlib import Path

    tests = str(Path(__file__).resolve().parents[2] / "tests")
    if tests not in sys.path:
        sys.path.insert(0, tests)


def px4_table(model=None) -> str:
    """The PX4 vehicle's table (Markdown); ``model`` defaults to :func:`px4_model`."""
    from delaykit import Controller, Loop

    m = px4_model() if model is None else model
    base = dict(umin=-1.0, umax=3.0, step=1.0, load=0.5, t_end=40.0)
    rows = [("PX4 P, Kp 0.95", assess(Loop(m.plant, Controller.p(0.95), delay=float(m.delay), umin=-1.0, umax=3.0),
                                      step=1.0, load=0.5, t_end=40.0))]
    refused = []
    for name, kw in [("SIMC PI", dict(rule="simc")), ("AMIGO PI", dict(rule="amigo")), ("ZN PI", dict(rule="zn")),
                     ("Tyreus-Luyben PI", dict(rule="tyreus-luyben")), ("MIGO PI, Ms 1.4", dict(ms=1.4))]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", TuningWarning)
            try:
                t = tune(m, "pi", **kw, **base)
            except InvalidValueError as e:  # outside the rule's family: the table says so, with delaykit's reason
                refused.append(f"{name}: refused ({e})")
                continue
        if t.model is not None:
            name += " (half rule)"
        if any(issubclass(w.category, TuningWarning) for w in caught):
            name += " †"
        rows.append((name, t))
    notes = "".join(f"\n- {r}" for r in refused)
    return HEAD + "\n" + "\n".join(_row(n, t) for n, t in rows) + ("\n" + notes if notes else "")


if __name__ == "__main__":
    print("### The drone\n")
    print(drone_table())
    print("\n### The heater\n")
    print(heater_table())
    print("\n### The PX4 vehicle\n")
    _shared_data()
    from shared_data import DATA, absent_reason, have_data

    print(px4_table() if have_data("px4-altitude") else f"(not computed: {absent_reason(DATA / 'px4-altitude')})")
