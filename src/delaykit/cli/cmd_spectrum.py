"""``delaykit roots``, ``margins`` and ``lambert``: characteristic roots, frequency response and margins."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Optional

import typer

from ..errors import DelaykitError, InvalidValueError, check_real
from .common import check_output, fmt, friendly, out, print_json
from .loopopts import with_loop

__all__ = ["lambert", "margins", "roots"]


@friendly
@with_loop
def roots(
    region: tuple[float, float, float, float] = typer.Option(
        (-10.0, 2.0, 0.0, 100.0), "--region", help="RE_MIN RE_MAX IM_MIN IM_MAX."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(
        None, "--plot", help="Draw the spectrum (as the paper's Fig. 8) here; a sampled loop's poles in the z-plane; "
        "with --system its pole map (the poles, the region searched, a neutral system's lines)."),
    system: Optional[Path] = typer.Option(
        None, "--system", help="A delay system from a TOML file of blocks connected by name (instead of a loop): "
        "its poles in --region and its stability."),
    loop: Any = None,
    delays: Any = None,
) -> None:
    """Every characteristic root of the linearised loop in a region, certified by the argument principle.

    Any continuous loop (the loop options or --loop); saturation is ignored (the linearised loop).  A sampled loop
    (--period) gets its exact discrete-time poles instead (z-plane, every one: --region does not apply), with the
    spectral radius and stability; "abscissa" and "rightmost" are then the equivalent continuous rate log(z)/h.
    --plot then draws them in the z-plane, with the unit circle.
    """
    if system is not None:
        from .systemfile import system_roots

        system_roots(system, region, as_json, plot)
        return
    from ..spectrum.roots import find_roots
    from ..spectrum.stability import rightmost as rightmost_root

    check_output("--plot", plot, "figure")
    if len(delays) > 1:
        raise InvalidValueError("roots takes one --delay, not a sweep")
    if loop.sampled:
        if plot is not None:
            from ..plotting.figures import plot_z_spectrum
            from ..spectrum.sampled import sampled_spectrum

            plot_z_spectrum(sampled_spectrum(loop), plot, title=repr(loop))
        _sampled_roots(loop, as_json)
        return
    q = loop.characteristic()
    sp = find_roots(q, region)
    rm = rightmost_root(q)
    data = sp.to_dict()
    data["rightmost"] = None if rm.root is None else [rm.root.real, rm.root.imag]
    data["stable"] = rm.stable
    data["abscissa"] = rm.abscissa
    data["rightmost_certified"] = rm.certified
    data["rightmost_in_region"] = None if sp.rightmost is None else [sp.rightmost.real, sp.rightmost.imag]
    if plot is not None:
        from ..plotting.figures import plot_spectrum

        plot_spectrum([sp], plot, labels=[repr(loop)], title=str(q))
    if as_json:
        print_json(data)
        return
    print_roots_table(f"{q!r} in {tuple(sp.region)}", sp)
    cert = "certified" if sp.certified else f"NOT certified: {sp.reason}"
    nl = f"; neutral line Re s = {sp.neutral_lines[0]:.6f}" if len(sp.neutral_lines) == 1 else ""
    r = rm.root
    out.print(f"{int(sp.multiplicities.sum())} roots, {cert} (argument principle: {sp.count}){nl}.", highlight=False)
    verdict = "stable" if rm.stable else "UNSTABLE"
    if not rm.certified:  # the search stopped short: the abscissa is only a bound, the verdict not proven
        verdict += f" (NOT certified: {rm.spectrum.reason or 'the search for the rightmost root did not finish'})"
    out.print(f"Rightmost root {r.real:.6f} ± {abs(r.imag):.6f}j; spectral abscissa {rm.abscissa:.6f}: {verdict}."
              if r is not None else f"Spectral abscissa {rm.abscissa:.6f}: {verdict}.", highlight=False)
    if q.kind == "neutral" and not rm.stable and sp.neutral_lines and max(sp.neutral_lines) >= 0:
        out.print("Warning: this neutral loop's root chains reach the right half-plane (for the paper's loop, "
                  "Kv >= 1): it cannot be stable whatever its other gains.")


def print_roots_table(title: str, sp: Any) -> None:
    """The roots of a :class:`~delaykit.spectrum.roots.Spectrum` as a table (the title is plain text)."""
    from rich.table import Table
    from rich.text import Text

    table = Table(title=Text(title))
    for col in ("#", "Re s", "Im s", "multiplicity"):
        table.add_column(col, justify="right")
    for i, (z, m) in enumerate(zip(sp.roots, sp.multiplicities), 1):
        table.add_row(str(i), f"{z.real:.6f}", f"{z.imag:.6f}", str(m))
    out.print(table)


def _sampled_roots(loop: Any, as_json: bool) -> None:
    """The roots command for a sampled loop: its poles (z-plane), spectral radius and stability."""
    from ..spectrum.sampled import sampled_spectrum

    sp = sampled_spectrum(loop)
    rate = sp.rate if math.isfinite(sp.rate.real) else None
    data = {**sp.to_dict(), "sampled": True, "abscissa": None if rate is None else rate.real,
            "rightmost": None if rate is None else [rate.real, abs(rate.imag)]}
    if as_json:
        print_json(data)
        return
    from rich.table import Table

    table = Table(title=f"Poles of the sampled loop {loop!r} (z-plane, h = {sp.period:g} s)")
    for col in ("#", "Re z", "Im z", "|z|", "rate log|z|/h (1/s)"):
        table.add_column(col, justify="right")
    shown = 30
    for i, z in enumerate(sp.poles.astype(complex)[:shown], 1):
        table.add_row(str(i), f"{z.real:.6f}", f"{z.imag:.6f}", f"{abs(z):.6f}",
                      f"{math.log(abs(z)) / sp.period:.6f}" if z != 0 else "-inf")
    out.print(table)
    more = f" (the {shown} largest shown; --json lists all)" if sp.poles.size > shown else ""
    d = sp.dominant
    out.print(f"{sp.poles.size} poles{more}; spectral radius {sp.radius:.6f} at {d.real:.6f} ± {abs(d.imag):.6f}j "
              f"(decay rate {math.log(sp.radius) / sp.period if sp.radius > 0 else -math.inf:.6f}/s): "
              f"{'stable' if sp.stable else 'UNSTABLE'}.", highlight=False)


@friendly
@with_loop
def margins(
    wmin: Optional[float] = typer.Option(None, "--wmin", help="Lowest frequency of the plot, rad/s (default: from the loop)."),
    wmax: Optional[float] = typer.Option(None, "--wmax", help="Highest frequency of the plot, rad/s (default: from the loop)."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
    plot: Optional[Path] = typer.Option(None, "--plot", help="Write a Bode plot, with the Nyquist plot beside it, here "
                                        "(with --system: each break signal's loop, its margins in its colour)."),
    system: Optional[Path] = typer.Option(
        None, "--system", help="A delay system from a TOML file of blocks connected by name (instead of a loop): "
        "loop-at-a-time margins at its break signals and its stability."),
    loop: Any = None,
    delays: Any = None,
) -> None:
    """Gain, phase and delay margins, peak sensitivity and every crossover of a loop, exact with the delay.

    Any loop (the loop options or --loop); saturation is ignored (the linearised loop).  A continuous loop's
    stability comes from its exact characteristic roots; a sampled loop's (--period) margins and stability are
    those of its exact discrete-time model (its poles, and L(e^{jwh}) broken at the plant's input, on (0, pi/h];
    without a compensator that is the held command), with the same JSON keys where they exist.  With a delay
    compensator the gain margin is the factor on the plant's input (the compensator's model unchanged) and the
    delay margin extra true delay.  An unstable closed loop gets no margins.

    The jitter margin (Kao & Lincoln 2004; JSON key jitter_margin, s) is the largest extra delay, varying
    arbitrarily fast anywhere between 0 and it on top of the loop's own delay, that is still guaranteed stable.
    It is sufficient only, and never above the delay margin.  Continuous loops only: it is null for a sampled
    loop, whose held command turns a packet delay into a continuous delay up to one period longer (the criterion
    covers the continuous law; for P, or PV with the true velocity, check the loop without --period with the
    range widened by the period).  Also null for an unstable loop, a loop the library's criterion does not take
    (the text output says why), or a margin without bound (no feedback at all).
    """
    if system is not None:
        from .systemfile import system_margins

        for flag, v in (("--wmin", wmin), ("--wmax", wmax)):
            if v is not None:
                raise InvalidValueError(f"margins --system has no {flag} yet")
        system_margins(system, as_json, plot)
        return
    from ..spectrum.frequency import frequency_grid, frequency_response
    from ..spectrum.frequency import margins as loop_margins

    check_output("--plot", plot, "figure")
    if len(delays) > 1:
        raise InvalidValueError("margins takes one --delay, not a sweep")
    lo = None if wmin is None else check_real("--wmin", wmin, minimum=0.0, strict=True)
    hi = None if wmax is None else check_real("--wmax", wmax, minimum=0.0, strict=True)
    if lo is not None and hi is not None and not lo < hi:
        raise InvalidValueError(f"--wmin {lo:g} must be below --wmax {hi:g} (rad/s): the frequency range is "
                                f"{'empty' if lo == hi else 'reversed'}")
    sampled = loop.sampled
    if sampled:  # (the discrete-time model's modules only where needed)
        from ..spectrum.discrete_margins import sampled_margins
        from ..spectrum.sampled import sampled_response, sampled_spectrum

        wn = math.pi / loop.period
        for flag, v in (("--wmin", lo), ("--wmax", hi)):
            if v is not None and v > wn:
                raise InvalidValueError(f"{flag} {v:g} rad/s is above pi/h = {wn:.6g} rad/s, the highest frequency "
                                        f"of the loop sampled every {loop.period:g} s")
    m = sampled_margins(loop) if sampled else loop_margins(loop)
    jm: Any = None
    jm_why = "a sampled loop (see --help)" if sampled else "the closed loop is unstable"
    if not sampled and m.stable:
        from ..spectrum.jitter import jitter_margin

        try:
            jm = jitter_margin(loop)
        except DelaykitError as exc:  # a loop the criterion does not take (e.g. a compensator): no margin
            jm_why = str(exc)
    if not sampled and (plot is not None or lo is not None or hi is not None):
        w = frequency_grid(loop, 1000, wmin=lo, wmax=hi)  # checks a range given at one end against the other
    if plot is not None:
        from matplotlib.figure import Figure

        from ..plotting.frequency import plot_bode, plot_nyquist

        if sampled:
            import numpy as np

            a, b = lo or 1e-3 * wn, hi or wn
            if not a < b:
                raise InvalidValueError(f"the frequency range is empty or reversed: {a:g} to {b:g} rad/s")
            resp = sampled_response(loop, np.geomspace(a, b, 1000))
        else:
            resp = frequency_response(loop, w)
        fig = Figure(figsize=(12.0, 6.0), layout="constrained")
        grid = fig.add_gridspec(2, 2)
        ax_mag = fig.add_subplot(grid[0, 0])
        ax_ph = fig.add_subplot(grid[1, 0], sharex=ax_mag)
        fig.suptitle(repr(loop), fontsize=9)
        plot_bode(resp, axes=(ax_mag, ax_ph), margins=None if sampled else m)
        plot_nyquist(resp, plot, ax=fig.add_subplot(grid[:, 1]))  # writes the whole figure
    if as_json:
        data = m.to_dict()
        if sampled:
            data.update(sampled=True, period=loop.period, radius=sampled_spectrum(loop).radius,
                        stability_from="sampled poles")
        data["jitter_margin"] = None if jm is None or not math.isfinite(jm.margin) else jm.margin
        print_json(data)
        return

    def at(w: Optional[float]) -> str:
        return "" if w is None else " at ∞" if math.isinf(w) else f" at {w:.6g} rad/s"

    from rich.table import Table

    table = Table(title=f"Margins of {loop!r}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    why = {"roots": "its characteristic roots", "nyquist": "the Nyquist count",
           "neutral chains": "neutral root chains at Re s = ln|L(j∞)|/T ≥ 0"}
    why = (f"its poles, spectral radius {sampled_spectrum(loop).radius:.6f}" if sampled
           else why.get(m.stability_from, m.stability_from))
    table.add_row("closed loop", f"{'stable' if m.stable else 'UNSTABLE'} (from {why})")
    if m.stable:
        table.add_row("gain margin", "∞" if math.isinf(m.gain_margin) else
                      f"{m.gain_margin:.6g} ({m.gain_margin_db:.4f} dB){at(m.phase_crossover)}")
        if m.lower_gain_margin > 0:
            low_db = 20 * math.log10(m.lower_gain_margin)
            table.add_row("lower gain margin", f"{m.lower_gain_margin:.6g} ({low_db:.4f} dB)")
        table.add_row("phase margin", "∞" if math.isinf(m.phase_margin) else f"{m.phase_margin:.4f}°")
        table.add_row("delay margin (extra)", "∞" if math.isinf(m.delay_margin) else
                      f"{m.delay_margin:.6g} s{at(m.crossover)}")
        table.add_row("critical delay (total)", "∞" if math.isinf(m.critical_delay) else f"{m.critical_delay:.6g} s")
        table.add_row("jitter margin (any variation)", "–" if jm is None else "∞" if math.isinf(jm.margin) else
                      f"{jm.margin:.6g} s{at(jm.frequency)}")
        table.add_row("peak sensitivity Ms", f"{m.ms:.6g}{at(getattr(m, 'ms_frequency', None))}")
    if not sampled:
        table.add_row("open-loop RHP poles P", str(m.open_loop_rhp_poles))
        table.add_row("encirclements of -1 (ccw)", "–" if m.encirclements is None else str(m.encirclements))
    out.print(table)
    if m.stable and jm is None:
        out.print(f"No jitter margin: {jm_why.rstrip('.')}.", highlight=False)
    cross = Table(title=f"crossovers up to {math.pi / loop.period if sampled else m.cutoff:.6g} rad/s")
    for col in ("kind", "ω (rad/s)", "|L|", "phase (deg)", "gives"):
        cross.add_column(col, justify="right")
    shown = 12
    for c in m.crossovers[:shown]:
        gives = (f"PM {c.phase_margin:.4f}°" + ("" if sampled else f", DM {c.delay_margin:.6g} s")
                 if c.kind == "gain" else f"gain factor {c.gain_margin:.6g}")
        phase = "–" if math.isnan(c.phase_deg) else f"{c.phase_deg:.4f}"
        cross.add_row(c.kind, "∞" if math.isinf(c.frequency) else f"{c.frequency:.6g}", f"{c.magnitude:.6g}", phase,
                      gives)
    out.print(cross)
    if len(m.crossovers) > shown:
        out.print(f"… and {len(m.crossovers) - shown} more phase crossovers (--json lists them all).",
                  highlight=False)


def _parse_branches(spec: str) -> list[int]:
    from ..models.budget import MAX_RANGE_POINTS, check_count
    from ..models.ranges import parse_integer

    try:
        if ":" in spec:
            a, b = (parse_integer(x) for x in spec.split(":"))
        else:
            items = spec.split(",")
            check_count(f"--branches {spec!r}", len(items), MAX_RANGE_POINTS, "branches")
            return [parse_integer(x) for x in items]
    except ValueError:
        raise InvalidValueError(f"--branches {spec!r} must be K1:K2 or a comma list of integers") from None
    if b < a:
        raise InvalidValueError(f"--branches {spec!r}: the range is reversed (K1 must not exceed K2)")
    check_count(f"--branches {spec!r}", b - a + 1, MAX_RANGE_POINTS, "branches", "ask for fewer branches")
    return list(range(a, b + 1))


@friendly
def lambert(
    a0: float = typer.Option(0.0, "--a0", help="a0 in x' = a0 x + a1 x(t - Td)."),
    a1: float = typer.Option(..., "--a1", help="a1 (for the P loop, -Kp)."),
    delay: float = typer.Option(..., "--delay", help="Td, s."),
    branches: str = typer.Option("-3:3", "--branches", help="Lambert W branches: K1:K2 or a list."),
    as_json: bool = typer.Option(False, "--json", help="Print JSON."),
) -> None:
    """Roots s_k = W_k(Td a1 exp(-a0 Td)) / Td + a0 of a first-order delay equation, by branch."""
    from ..spectrum.lambert import lambert_roots

    r = lambert_roots(a0, a1, check_real("--delay", delay, minimum=0.0), branches=_parse_branches(branches))
    data = r.to_dict()
    if as_json:
        print_json(data)
        return
    from rich.table import Table

    table = Table(title=f"s - {a0:g} - ({a1:g}) exp(-{delay:g} s) = 0")
    for col in ("branch k", "Re s", "Im s"):
        table.add_column(col, justify="right")
    none = 0
    for row in data["roots"]:
        if math.isfinite(row["re"]) and math.isfinite(row["im"]):
            table.add_row(str(row["branch"]), fmt(row["re"], 8), fmt(row["im"], 8))
        else:  # W_k(0) = -inf for k != 0 (the argument Td a1 exp(-a0 Td) is 0, or underflows to 0)
            none += 1
            table.add_row(str(row["branch"]), "no root", "")
    out.print(table)
    if none:
        out.print(f"{none} branch(es) without a root: W_k of 0 is -inf for k != 0 (with a1 = 0 the equation is "
                  "s = a0, one root, on branch 0).")
    rm = data["rightmost"]
    if math.isfinite(rm[0]) and math.isfinite(rm[1]):
        out.print(f"Rightmost root {fmt(rm[0], 8)} {'-' if rm[1] < 0 else '+'}{fmt(abs(rm[1]), 8)}j (branch 0; for "
                  "real coefficients branch -1 is its conjugate).")
    else:
        out.print("No root on the branches asked for (the root of a1 = 0, s = a0, is on branch 0).")
