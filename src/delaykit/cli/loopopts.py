"""One option group that builds a loop, shared by every command that takes one.

``with_loop`` adds the options below to a command's signature and hands the command ``loop`` (built with
the first delay) and ``delays`` (the delays of ``--delay``, which may be a sweep).  Without ``--plant``
and ``--loop`` the loop is the paper's: the integrator ``1/s``, P control (PV with ``--kv``), the command
limited to +-1 m/s.  With ``--loop FILE.toml`` the file gives the loop and any option given beside it
overrides the file's value.
"""

from __future__ import annotations

import functools
import inspect
import math
from pathlib import Path
from typing import Any, Callable, Optional

import typer

from ..errors import InvalidValueError

__all__ = ["LOOP_OPTION_NAMES", "build_loop", "parse_limit", "with_loop"]


def _opt(default: Any, flag: str, help: str) -> Any:
    return typer.Option(default, flag, help=help)


_SPECS: list[tuple[str, Any, Any]] = [
    ("loop_file", Optional[Path], _opt(None, "--loop", "Read the whole loop from a TOML file (other loop options override it).")),
    ("plant", Optional[str], _opt(None, "--plant", "Plant transfer function in s, e.g. '1/(s*(0.05*s+1))' or '0.62*exp(-12*s)/(150*s+1)' (default: the paper's 1/s).")),
    ("controller", Optional[str], _opt(None, "--controller", "p | pv | pi | pd | pid | smith | filtered-smith | predictor, or a transfer function on the error (default: p, or pv with --kv).")),
    ("model_delay", Optional[float], _opt(None, "--model-delay", "Compensators: the delay the design assumes, s (default: --delay); the loop runs with --delay.")),
    ("closed_loop_time", Optional[float], _opt(None, "--closed-loop-time", "Compensators: the closed-loop time constant Tc, s (default: the fastest that survives a 20 % delay error).")),
    ("kp", Optional[float], _opt(None, "--kp", "Proportional gain Kp. The gains Kp, Ki, Kd and Kv share one sign: all at least 0, or all at most 0 for a plant of negative gain (the paper's loop: at least 0); 0 drops a term.")),
    ("ki", Optional[float], _opt(None, "--ki", "Integral gain Ki (1/s), for pi and pid; of the sign of the other gains (see --kp).")),
    ("kd", Optional[float], _opt(None, "--kd", "Derivative gain Kd (s), for pd and pid; of the sign of the other gains (see --kp).")),
    ("kv", Optional[float], _opt(None, "--kv", "Velocity gain Kv of the paper's PV law, at least 0 (see --kp).")),
    ("derivative_filter", Optional[float], _opt(None, "--derivative-filter", "Time constant Tf (s) of the derivative's filter s/(Tf s + 1), for pd and pid.")),
    ("velocity", Optional[str], _opt(None, "--velocity", "Velocity of the PV law: true | filtered.")),
    ("filter_wn", Optional[float], _opt(None, "--filter-wn", "PV derivative filter natural frequency, rad/s (default 38).")),
    ("filter_zeta", Optional[float], _opt(None, "--filter-zeta", "PV derivative filter damping ratio (default 1).")),
    ("antiwindup", Optional[str], _opt(None, "--antiwindup", "Integrator anti-windup: none | clamp | backcalc.")),
    ("tracking_time", Optional[float], _opt(None, "--tracking-time", "Back-calculation tracking time Tt, s.")),
    ("delay", Optional[str], _opt(None, "--delay", "Input delay in s; or START:STOP:N, a comma list, or 'table1'.")),
    ("output_delay", Optional[float], _opt(None, "--output-delay", "Delay on the measurement, s (default 0).")),
    ("umin", Optional[str], _opt(None, "--umin", "Lower command limit, or 'none'.")),
    ("umax", Optional[str], _opt(None, "--umax", "Upper command limit, or 'none'.")),
    ("vmax", Optional[str], _opt(None, "--vmax", "Shorthand for --umin -V --umax V; 'none' for no limit (paper loop default: 1).")),
    ("period", Optional[str], _opt(None, "--period", "Controller period, s (default: continuous).")),
    ("sample_offset", Optional[float], _opt(None, "--sample-offset", "First sample time after the step, s.")),
]
LOOP_OPTION_NAMES = tuple(name for name, _, _ in _SPECS)
_CONTROLLER_KEYS = ("kp", "ki", "kd", "kv", "derivative_filter", "velocity", "filter_wn", "filter_zeta", "antiwindup",
                    "tracking_time", "setpoint_weight", "derivative_weight")
_KIND_KEYS = {  # the settings each law reads (a transfer-function law reads none)
    "p": ("kp",), "pv": ("kp", "kv", "velocity", "filter_wn", "filter_zeta"),
    "pi": ("kp", "ki", "antiwindup", "tracking_time", "setpoint_weight"), "pd": ("kp", "kd", "derivative_filter"),
    "pid": ("kp", "ki", "kd", "derivative_filter", "antiwindup", "tracking_time", "setpoint_weight",
            "derivative_weight"),
}


def parse_limit(flag: str, text: Optional[str]) -> Optional[float]:
    """A limit or period from text: a number, or ``none``/``off``/``inf`` for none.

    Examples
    --------
    >>> parse_limit("--vmax", "none") is None, parse_limit("--vmax", "2")
    (True, 2.0)
    """
    from ..models.ranges import parse_number

    if text is None or text.strip().lower() in ("none", "off", "inf"):
        return None
    try:
        return parse_number(text)
    except ValueError:
        raise InvalidValueError(f"{flag} must be a number or 'none', got {text!r}") from None


def build_loop(opts: dict[str, Any], parse_delays: Callable[[str], list[float]]) -> tuple[Any, list[float]]:
    """The loop of the options (with the first delay) and the list of delays.

    Examples
    --------
    >>> from delaykit.cli.app import parse_delays
    >>> loop, delays = build_loop({"kp": 1.31, "delay": "0.368"}, parse_delays)
    >>> loop, delays
    (AltitudeLoop(kp=1.31, delay=0.368 s, vmax=±1 m/s, continuous), [0.368])
    """
    from ..models.compensators import COMPENSATOR_KINDS

    o = {k: v for k, v in opts.items() if v is not None}
    comp = {k: o.pop(k) for k in ("model_delay", "closed_loop_time") if k in o}
    kind = str(o.get("controller", "")).lower().replace("_", "-")
    if kind in COMPENSATOR_KINDS:
        o["controller"] = "p"  # a placeholder while the loop is built; the compensator replaces it
        o.setdefault("kp", 1.0)
        if "plant" not in o and "loop_file" not in o:  # the paper's plant and limits
            o["plant"] = "1/s"
            if not {"umin", "umax", "vmax"} & set(o):
                o["umin"], o["umax"] = "-1", "1"
    elif comp:
        raise InvalidValueError(f"--{next(iter(comp)).replace('_', '-')} is for a compensator "
                                f"(--controller {' | '.join(COMPENSATOR_KINDS)})")
    loop, delays = _build(o, parse_delays)
    if kind in COMPENSATOR_KINDS:
        from ..design.compensators import tune_compensator

        model_delay = comp.get("model_delay", loop.delay)
        law = tune_compensator(kind, loop.plant, model_delay, closed_loop_time=comp.get("closed_loop_time"))
        loop = loop.replace(controller=law)
    return loop, delays


def _build(o: dict[str, Any], parse_delays: Callable[[str], list[float]]) -> tuple[Any, list[float]]:
    from ..models.altitude import AltitudeLoop
    from ..models.loop import load_loop, loop_from_dict

    delays = parse_delays(o.pop("delay")) if "delay" in o else None
    path = o.pop("loop_file", None)
    limits = {k: o.pop(k) for k in ("umin", "umax", "vmax") if k in o}
    if "vmax" in limits and len(limits) > 1:
        raise InvalidValueError("give --vmax or --umin/--umax, not both")
    if "period" in o:
        o["period"] = parse_limit("--period", o["period"])
    general = {"plant", "ki", "kd", "derivative_filter", "output_delay", "antiwindup", "tracking_time"} & set(o)
    if path is None and not general and set(limits) <= {"vmax"} and o.get("controller", "p") in ("p", "pv"):
        # the paper's loop (the integrator 1/s): an AltitudeLoop, printed as before
        if "kp" not in o:
            raise InvalidValueError("give --kp (or --loop FILE.toml)")
        if delays is None:
            raise InvalidValueError("give --delay (or --loop FILE.toml)")
        if o.pop("controller", None) == "p" and o.get("kv"):
            raise InvalidValueError("--controller p has no --kv; use --controller pv")
        vmax = parse_limit("--vmax", limits["vmax"]) if "vmax" in limits else 1.0
        return AltitudeLoop(delay=delays[0], vmax=vmax, **o), delays
    if path is not None:
        d = _flatten(load_loop(path))
        if "controller" in o:  # another law than the file's: keep only the file's settings the new law uses
            keep = _KIND_KEYS.get(str(o["controller"]).lower(), ())
            for k in _CONTROLLER_KEYS:
                if k not in o and k not in keep:
                    d.pop(k, None)
    else:
        d = {"plant": "1/s"}
        if "plant" not in o and "vmax" not in limits:  # the paper's limits, +-1, where not given
            limits.setdefault("umin", "-1")
            limits.setdefault("umax", "1")
    d.update(o)
    d.setdefault("controller", "pv" if d.get("kv") else "p")
    if str(d["controller"]).lower() in _KIND_KEYS and "kp" not in d:  # (Kp = 0 would silently open the loop)
        raise InvalidValueError(f"give --kp, the {str(d['controller']).lower()} controller's proportional gain "
                                "(--kp 0 for none)")
    if "vmax" in limits:
        v = parse_limit("--vmax", limits["vmax"])
        d["umin"], d["umax"] = (-math.inf, math.inf) if v is None else (-v, v)
    for k, inf in (("umin", -math.inf), ("umax", math.inf)):
        if k in limits:
            v = parse_limit(f"--{k}", limits[k])
            d[k] = inf if v is None else v
    if delays is not None:
        d["delay"] = delays[0]
    loop = loop_from_dict(d, source=str(path) if path else "options")
    if delays is None:
        return loop, [loop.delay]
    # a dead time written into the plant (exp(-T*s)) adds to every delay of the sweep
    extra = loop.delay - delays[0]
    return loop, [x + extra for x in delays]


def _flatten(loop: Any) -> dict[str, Any]:
    """A loop file's loop as the flat keys of :func:`~delaykit.models.loop.loop_from_dict`."""
    c = loop.controller
    d: dict[str, Any] = {"plant": loop.plant, "delay": loop.delay, "output_delay": loop.output_delay,
                         "umin": loop.umin, "umax": loop.umax, "sample_offset": loop.sample_offset}
    if loop.period is not None:
        d["period"] = loop.period
    if c.kind == "tf":
        d["controller"] = c.transfer_function
    else:
        d.update({k: v for k, v in c.to_dict().items() if k != "kind"})
        d["controller"] = c.kind
        if c.tracking_time is None:
            d.pop("tracking_time", None)
    return d


def with_loop(fn: Callable[..., Any] | None = None, *, omit: tuple[str, ...] = ()) -> Any:
    """Add the loop options to a command; it receives ``loop`` and ``delays`` instead.

    With ``omit`` (for example ``("kp", "kv")`` for a command that sweeps them with options of its own), those
    options are left out and the command receives ``loop_options`` (a dict) to build loops itself with
    :func:`build_loop`.
    """
    if fn is None:
        return lambda f: with_loop(f, omit=omit)
    sig = inspect.signature(fn)
    kept = [p for p in sig.parameters.values() if p.name not in ("loop", "delays", "loop_options")]
    added = [inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=ann)
             for name, ann, default in _SPECS if name not in omit]

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        from .app import parse_delays

        opts = {name: kwargs.pop(name, None) for name in LOOP_OPTION_NAMES if name not in omit}
        if omit:
            return fn(*args, loop_options=opts, **kwargs)
        if kwargs.get("system") is not None:  # --system FILE: the model is the file's, no loop is built
            given = sorted(n for n, v in opts.items() if v is not None)
            if given:
                raise InvalidValueError(f"--system reads the whole model from its file; --{given[0].replace('_', '-')} "
                                        "does not apply to it")
            return fn(*args, loop=None, delays=None, **kwargs)
        loop, delays = build_loop(opts, parse_delays)
        return fn(*args, loop=loop, delays=delays, **kwargs)

    wrapper.__signature__ = sig.replace(parameters=[*kept, *added])  # type: ignore[attr-defined]
    return wrapper
