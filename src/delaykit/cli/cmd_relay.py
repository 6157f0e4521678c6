"""``delaykit relay``: a delay injector between a ground station and a vehicle (:mod:`delaykit.hardware.relay`)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..errors import check_real
from .common import err, fmt, friendly, out, print_json, read_delay_trace, run_until_stopped

__all__ = ["relay"]


@friendly
def relay(
    listen: str = typer.Option("udp:127.0.0.1:14551", "--listen", help="Where the ground station sends: udp:HOST:PORT or tcp:HOST:PORT (port 0: any free one)."),
    to: str = typer.Option("udp:127.0.0.1:14550", "--to", help="The vehicle or simulator, same transport."),
    delay: float = typer.Option(..., "--delay", help="The delay added to each packet, s."),
    jitter: float = typer.Option(0.0, "--jitter", help="A random extra per packet, uniform in [0, JITTER] s (mean JITTER/2); packets stay in order unless --reorder."),
    loss: float = typer.Option(0.0, "--loss", help="The probability that a packet is dropped (UDP only)."),
    trace: Optional[Path] = typer.Option(None, "--trace", help="Replay a recorded delay, added to --delay (as `emulate --delay-trace`): a CSV with a header t,delay (s), or a flight log of `delaykit fly` (its latency_ms column), replayed from the relay's start."),
    direction: str = typer.Option("both", "--direction", help="up (ground station -> vehicle) | down (vehicle -> ground station) | both: the directions that get the delay and the loss; the other is forwarded at once."),
    reorder: bool = typer.Option(False, "--reorder", help="Let a packet with a shorter delay overtake the ones ahead of it (UDP only)."),
    seed: Optional[int] = typer.Option(None, "--seed", help="Random seed (loss and jitter)."),
    priority: Optional[int] = typer.Option(None, "--priority", help="Run the relay at this real-time priority (SCHED_FIFO, 1-99; Linux, root or CAP_SYS_NICE), so that it wakes on time on a busy machine; refused, it runs as an ordinary process and says so."),
    duration: float = typer.Option(0.0, "--duration", help="Run this long, s (0 = until Ctrl-C or SIGTERM)."),
    as_json: bool = typer.Option(False, "--json", help="Print the end-of-run summary as JSON."),
) -> None:
    """Forward a link (UDP datagrams, or one TCP connection at a time) with a set delay, jitter and loss, until
    Ctrl-C, SIGTERM, SIGHUP or --duration; then print what it forwarded and dropped, and how late it was itself.

    "up" is ground station -> vehicle (what arrives on --listen goes to --to); "down" is the replies, sent back to
    the last ground-station address seen. Each direction is first in, first out."""
    from ..hardware.relay import DelayRelay, parse_endpoint

    check_real("--duration", duration, minimum=0.0)
    for flag, value, top in (("--delay (s)", delay, None), ("--jitter (s)", jitter, None), ("--loss", loss, 1.0)):
        check_real(flag, value, minimum=0.0, maximum=top)
    rel = DelayRelay(parse_endpoint(listen, "--listen"), parse_endpoint(to, "--to"), delay, jitter=jitter, loss=loss,
                     trace=None if trace is None else read_delay_trace(trace), direction=direction,
                     reorder=reorder, seed=seed, priority=priority)
    with run_until_stopped(duration) as wait:  # Ctrl-C, SIGTERM and SIGHUP end the run alike, with the summary
        with rel:
            err.print(f"relay running: {rel!r}. Ctrl-C stops.", highlight=False)
            if rel.scheduling.startswith("refused"):
                err.print(f"warning: --priority {priority} {rel.scheduling}: the relay runs as an ordinary thread, "
                          "whose timer wake-ups a busy machine can delay", highlight=False, markup=False)
            wait()
        summary = rel.summary()  # after stop(): the thread is done, so the counts are final
    if as_json:
        print_json({"status": "ok", **summary.to_dict()})
        return
    from rich.table import Table

    tab = Table("direction", "delayed", "received", "forwarded", "dropped", "unroutable", "unsent",
                "late p50 (ms)", "late p99 (ms)", "late max (ms)",
                title=f"{summary.listen} -> {summary.to}, {summary.duration:.1f} s")
    for name, st in (("up", summary.up), ("down", summary.down)):
        tab.add_row(name, "yes" if summary.direction in (name, "both") else "no", str(st.received),
                    str(st.forwarded), str(st.dropped), str(st.unroutable), str(st.unsent), fmt(st.excess_p50_ms, 3),
                    fmt(st.excess_p99_ms, 3), fmt(st.excess_max_ms, 3))
    out.print(tab)
