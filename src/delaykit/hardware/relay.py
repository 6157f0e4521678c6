"""A delay injector for real links: :class:`DelayRelay` forwards UDP datagrams or a TCP stream with a set delay.

Put it between a ground station and a vehicle (or a simulator) to study a known delay on your own link: the
ground station talks to ``listen`` instead of the vehicle, and the relay forwards to ``to``.

* **up** is ground station -> vehicle: what arrives on ``listen`` goes to ``to``;
* **down** is vehicle -> ground station: the replies go back to the last ground-station address seen on
  ``listen`` (as any UDP proxy must: UDP has no connection), or along the accepted TCP connection.

``direction`` (``"up"``, ``"down"`` or ``"both"``, the default) names the directions that get the delay and
the loss; the other one is forwarded as soon as it arrives.

**The delay of a packet** (a UDP datagram, or a TCP chunk as one ``recv`` returned it) is drawn when it
arrives, from the kernel's arrival stamp (:mod:`.stamps`, so that a late wake-up of the relay is not counted
as arrival), as ``delay + jitter * U + trace(t)``: ``U`` uniform in ``[0, 1)`` (the extra is uniform in
``[0, jitter]``, mean ``jitter / 2``: :class:`~delaykit.simulate.varying.Jitter`'s uniform law), and
``trace(t)`` a recorded delay (:class:`~delaykit.simulate.varying.DelayTrace`) replayed from :meth:`DelayRelay.start`
(``t`` seconds since then; each record held until the next, or joined linearly if the trace says so).
``delay`` may itself be any :class:`~delaykit.simulate.varying.DelayModel` (a schedule, a gamma jitter, a burst,
their sum), evaluated at ``t``.  A packet is lost with probability ``loss`` (UDP only: a TCP stream cannot lose
bytes).  Randomness comes from one generator per direction seeded by ``seed``: each direction draws, for its
``k``-th packet, first whether it is lost, then its delay (none is drawn for a constant delay), whatever happens
in the other direction, so a seed gives the same losses and jitter for the same traffic.

**Order.**  First in, first out in each direction: a packet leaves no earlier than the one ahead of it
(``due_k = max(arrival_k + delay_k, due_{k-1})``), so a jitter larger than the spacing of the packets delays
the later ones instead of reordering them.  With ``reorder=True`` each packet leaves at ``arrival_k + delay_k``
and may overtake (UDP only).

**Scheduling.**  One thread reads the sockets (``selectors``) and keeps the packets waiting in a heap of due
times; it sleeps in ``select`` until the next due time or the next arrival, never busy-waiting.  On a machine
whose CPUs are busy with other work, an ordinary thread woken by its timer can wait for the scheduler's next
tick (4 ms on a 250 Hz kernel) before it runs, while one woken by an arriving packet runs at once; ``priority``
asks for a real-time priority (``SCHED_FIFO``), which runs it as soon as it wakes (``benchmarks/bench_relay.py``
measures both).  The thread sleeps between packets, so the priority costs the machine nothing, but a flood of
packets at that priority takes a CPU from everything else.  The
:func:`select.select` call is used because its timeout has microsecond resolution (``epoll`` and ``poll`` round
up to milliseconds, which would make every packet up to 1 ms late).  After each send the relay records its
own **excess**: the time of the send minus the due time; :meth:`DelayRelay.summary` gives its 50th and 99th
percentiles and maximum for each direction (the benchmark ``benchmarks/bench_relay.py`` measures it from
outside, end to end).

**TCP**: the relay accepts one connection on ``listen`` at a time, connects to ``to`` (waiting up to 5 s, during
which nothing else is forwarded; a refusal closes the ground station's connection and counts an error) and
forwards both byte streams chunk by chunk with the delay; when one side closes, the other is shut down for
writing once the data ahead of the close has been delivered, and the relay waits for the next connection.

Limits: packets waiting are held in memory (a 1 s delay at 1,000 packets/s holds 1,000 of them); at
:meth:`DelayRelay.stop` the packets still waiting are discarded and counted (``unsent``).  The relay is a user
process: a busy machine makes it late, and its excess says by how much.

Examples
--------
>>> import socket
>>> vehicle = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); vehicle.bind(("127.0.0.1", 0))
>>> with DelayRelay("udp:127.0.0.1:0", f"udp:127.0.0.1:{vehicle.getsockname()[1]}", delay=0.05) as relay:
...     gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
...     _ = gcs.sendto(b"hello", relay.address)
...     vehicle.settimeout(2.0)
...     data, _ = vehicle.recvfrom(64)
>>> data, relay.summary().up.forwarded
(b'hello', 1)
>>> gcs.close(); vehicle.close()
"""

from __future__ import annotations

import errno
import heapq
import ipaddress
import math
import selectors
import socket
import threading
import time
from array import array
from dataclasses import asdict, dataclass
from typing import Any

from ..errors import InvalidTypeError, InvalidValueError, PortError, PortNumberError, check_real
from .stamps import enable_stamps, recv_stamped

__all__ = ["Endpoint", "parse_endpoint", "DirectionStats", "RelaySummary", "DelayRelay", "DIRECTIONS",
           "TRANSPORTS"]

DIRECTIONS = ("up", "down", "both")
"""The values of ``direction``: which directions get the delay and the loss."""
TRANSPORTS = ("udp", "tcp")
_MAX_DATAGRAM = 65535
_CHUNK = 65536  # the largest TCP chunk read at once
_BATCH = 64  # the most datagrams read from one socket before the due packets are sent again


@dataclass(frozen=True)
class Endpoint:
    """A transport, an IP address and a port: ``udp:127.0.0.1:14550``.

    Examples
    --------
    >>> Endpoint("udp", "127.0.0.1", 14550)
    Endpoint(udp:127.0.0.1:14550)
    """

    transport: str
    host: str
    port: int

    @property
    def family(self) -> int:
        """``AF_INET`` or ``AF_INET6``."""
        return socket.AF_INET6 if ":" in self.host else socket.AF_INET

    @property
    def address(self) -> tuple[str, int]:
        """``(host, port)`` as the socket functions take it."""
        return self.host, self.port

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{self.transport}:{host}:{self.port}"

    def __repr__(self) -> str:
        return f"Endpoint({self})"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"transport", "host", "port"}``."""
        return asdict(self)


def parse_endpoint(text: Any, name: str = "endpoint") -> Endpoint:
    """An :class:`Endpoint` from ``TRANSPORT:HOST:PORT`` (``udp:127.0.0.1:14550``, ``tcp:[::1]:5760``).

    ``HOST`` is an IP address or ``localhost`` (127.0.0.1); ``PORT`` 0 to 65535 (0: any free one, for a listening
    side).  An :class:`Endpoint` is returned as it is.

    Parameters
    ----------
    text : str or Endpoint
        The endpoint.
    name : str
        What the messages call it (``"--listen"``).

    Returns
    -------
    Endpoint

    Raises
    ------
    InvalidValueError
        Not of that form, naming ``name`` and the text; a port out of range is a
        :class:`~delaykit.errors.PortNumberError`.

    Examples
    --------
    >>> parse_endpoint("udp:127.0.0.1:14551"), parse_endpoint("tcp:[::1]:5760"), parse_endpoint("udp:localhost:0")
    (Endpoint(udp:127.0.0.1:14551), Endpoint(tcp:[::1]:5760), Endpoint(udp:127.0.0.1:0))
    """
    if isinstance(text, Endpoint):
        return text
    if not isinstance(text, str):
        raise InvalidTypeError(f"{name} must be text such as 'udp:127.0.0.1:14550', got {text!r}")
    form = f"{name} {text!r} is not TRANSPORT:HOST:PORT (e.g. udp:127.0.0.1:14550 or tcp:127.0.0.1:5760)"
    transport, sep, rest = text.strip().partition(":")
    host, sep2, port_text = rest.rpartition(":")
    transport = transport.lower()
    if sep and transport not in TRANSPORTS:
        raise InvalidValueError(f"{name} {text!r}: the transport must be udp or tcp, got {transport!r}")
    if not sep or not sep2 or not host:
        raise InvalidValueError(form)
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if host.lower() == "localhost":
        host = "127.0.0.1"
    try:
        host = str(ipaddress.ip_address(host))
    except ValueError:
        raise InvalidValueError(f"{name} {text!r}: the host must be an IP address (or localhost), got "
                                f"{host!r}") from None
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise PortNumberError(f"{name} {text!r}: the port must be a number from 0 to 65535, got {port_text!r}")
    return Endpoint(transport, host, int(port_text))


@dataclass(frozen=True)
class DirectionStats:
    """One direction's counts and the relay's own lateness on it.

    ``received``: packets (datagrams, TCP chunks) that arrived; ``forwarded``: sent on; ``dropped``: lost on
    purpose (``loss``); ``unroutable``: down-going datagrams that came before any ground station had sent one,
    or that the system refused to send (with ``errors``); ``unsent``: still waiting when the relay stopped;
    ``bytes``: payload bytes forwarded; ``excess_p50_ms``, ``excess_p99_ms``, ``excess_max_ms``: how late the relay
    sent them after their due time (None before the first).

    Examples
    --------
    >>> DirectionStats(received=10, forwarded=9, dropped=1, excess_p50_ms=0.2, excess_p99_ms=0.4)
    DirectionStats(9/10 forwarded, 1 dropped, 0 unroutable, late p50 0.200 ms, p99 0.400 ms)
    """

    received: int = 0
    forwarded: int = 0
    dropped: int = 0
    unroutable: int = 0
    unsent: int = 0
    errors: int = 0
    bytes: int = 0
    excess_p50_ms: float | None = None
    excess_p99_ms: float | None = None
    excess_max_ms: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (None for a percentile with no packet)."""
        return asdict(self)

    def __repr__(self) -> str:
        late = ("" if self.excess_p99_ms is None else
                f", late p50 {self.excess_p50_ms:.3f} ms, p99 {self.excess_p99_ms:.3f} ms")
        return (f"DirectionStats({self.forwarded}/{self.received} forwarded, {self.dropped} dropped, "
                f"{self.unroutable} unroutable{late})")


@dataclass(frozen=True)
class RelaySummary:
    """What a :class:`DelayRelay` did: its endpoints, its delay, how long it ran, and each direction's counts.

    Examples
    --------
    >>> s = RelaySummary("udp:127.0.0.1:1", "udp:127.0.0.1:2", "both", {"kind": "schedule"}, 0.0, 0.0, False,
    ...                  True, 1.5, DirectionStats(), DirectionStats())
    >>> s.to_dict()["up"]["forwarded"], s.duration
    (0, 1.5)
    """

    listen: str
    to: str
    direction: str
    delay: dict[str, Any]
    jitter: float
    loss: float
    reorder: bool
    kernel_stamps: bool
    duration: float
    up: DirectionStats
    down: DirectionStats
    seed: int | None = None
    connections: int = 0
    scheduling: str = "ordinary"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the fields, the two directions as dicts."""
        d = asdict(self)
        d["up"], d["down"] = self.up.to_dict(), self.down.to_dict()
        return d

    def __repr__(self) -> str:
        return (f"RelaySummary({self.listen} -> {self.to}, {self.direction}, {self.duration:.1f} s: up "
                f"{self.up.forwarded}/{self.up.received}, down {self.down.forwarded}/{self.down.received})")


class _Direction:
    """One direction's state: its generator, whether it is delayed, its counts and its excess samples."""

    def __init__(self, delayed: bool, seed: Any) -> None:
        import numpy as np

        self.delayed = delayed
        self.rng = np.random.default_rng(seed)
        self.last_due = -math.inf
        self.counts = {k: 0 for k in ("received", "forwarded", "dropped", "unroutable", "unsent", "errors",
                                      "bytes")}
        self.excess = array("d")

    def stats(self) -> DirectionStats:
        import numpy as np

        c = dict(self.counts)
        if len(self.excess):
            e = np.frombuffer(self.excess, dtype=float) * 1e3
            p50, p99 = np.percentile(e, [50, 99])
            return DirectionStats(**c, excess_p50_ms=float(p50), excess_p99_ms=float(p99),
                                  excess_max_ms=float(e.max()))
        return DirectionStats(**c)


class DelayRelay:
    """Forward a link with a set delay, jitter and loss; ``start()``/``stop()`` or a context manager.

    Parameters
    ----------
    listen : str or Endpoint
        Where the ground station sends: ``udp:HOST:PORT`` or ``tcp:HOST:PORT`` (port 0: any free one; see
        :attr:`address`).
    to : str or Endpoint
        The vehicle or simulator, of the same transport.
    delay : float or DelayModel
        The delay added to each packet, s (default 0), or any delay model of
        :mod:`delaykit.simulate.varying`, evaluated at the packet's arrival (s since :meth:`start`).
    jitter : float
        A uniform random extra in ``[0, jitter]`` s per packet (default 0).
    loss : float
        The probability that a packet is dropped (UDP only), from 0 to 1.
    trace : DelayTrace or sequence of (t, delay), optional
        A recorded delay replayed from :meth:`start`, added to ``delay``.
    direction : {"both", "up", "down"}
        The directions that get the delay and the loss; the other is forwarded at once.
    reorder : bool
        Let a packet overtake the ones ahead of it (UDP only); default False: first in, first out.
    seed : int, optional
        Makes the loss and the jitter reproducible.
    priority : int, optional
        Run the relay's thread at this real-time priority (``SCHED_FIFO``, 1 to 99; Linux, with root or
        ``CAP_SYS_NICE``), so that it wakes on time on a busy machine (see the module docstring); refused, the
        relay runs as an ordinary thread and :attr:`scheduling` says why.  Default None: an ordinary thread.

    Attributes
    ----------
    address : tuple
        The bound ``listen`` address ``(host, port)`` once started.
    kernel_stamps : bool
        Whether arrivals carry the kernel's stamp (UDP on Linux) rather than the time of reading.

    Examples
    --------
    >>> DelayRelay("udp:127.0.0.1:0", "udp:127.0.0.1:14550", delay=0.2, jitter=0.02, loss=0.01, seed=1)
    DelayRelay(udp:127.0.0.1:0 -> udp:127.0.0.1:14550, both, 0.2 s + uniform [0, 0.02] s, loss 0.01)
    """

    def __init__(self, listen: Any, to: Any, delay: Any = 0.0, *, jitter: float = 0.0, loss: float = 0.0,
                 trace: Any = None, direction: str = "both", reorder: bool = False, seed: int | None = None,
                 priority: int | None = None) -> None:
        from ..simulate.varying import DelayModel, DelayTrace, Jitter, _check_seed, as_delay_model

        self.listen = parse_endpoint(listen, "listen")
        self.to = parse_endpoint(to, "to")
        if self.listen.transport != self.to.transport:
            raise InvalidValueError(f"listen ({self.listen}) and to ({self.to}) must use the same transport")
        if self.to.port == 0:
            raise PortNumberError(f"to ({self.to}) needs a port: 0 means any free one, which only a listening side "
                                  "can use")
        self.tcp = self.listen.transport == "tcp"
        if direction not in DIRECTIONS:
            raise InvalidValueError(f"direction must be one of {', '.join(DIRECTIONS)}; got {direction!r}")
        self.direction = direction
        if isinstance(delay, DelayModel):
            model = delay
        else:
            model = as_delay_model(check_real("delay (s)", delay, minimum=0.0))
        self.jitter = check_real("jitter (s)", jitter, minimum=0.0)
        self.loss = check_real("loss (probability)", loss, minimum=0.0, maximum=1.0)
        if self.jitter > 0:
            model = model + Jitter(0.0, "uniform", spread=self.jitter)
        if trace is not None:
            if not isinstance(trace, DelayTrace):
                if isinstance(trace, (str, bytes)) or not hasattr(trace, "__iter__"):
                    raise InvalidTypeError(f"trace must be a DelayTrace or (t, delay) records, got {trace!r}")
                pairs = list(trace)
                if not pairs or any(not isinstance(p, (list, tuple)) or len(p) != 2 for p in pairs):
                    raise InvalidValueError(f"trace must be a non-empty list of (t, delay) records, got {trace!r}")
                trace = DelayTrace([p[0] for p in pairs], [p[1] for p in pairs])
            model = model + trace
        self.model = model
        lo, hi = model.bounds()
        self._constant = lo if lo == hi else None  # no draw per packet (NumPy's call costs tens of microseconds)
        self.reorder = bool(reorder)
        if self.tcp and self.loss > 0:
            raise InvalidValueError(f"loss {self.loss:g} on TCP: a byte stream cannot lose data (use udp)")
        if self.tcp and self.reorder:
            raise InvalidValueError("reorder on TCP: a byte stream is delivered in order (use udp)")
        _check_seed(seed)
        self.seed = seed
        if priority is not None and (isinstance(priority, bool) or not isinstance(priority, int)):
            raise InvalidTypeError(f"priority must be an integer from 1 to 99 or None, got {priority!r}")
        if priority is not None and not 1 <= priority <= 99:
            raise InvalidValueError(f"priority must be from 1 to 99 (SCHED_FIFO's range), got {priority}")
        self.priority = priority
        self.scheduling = "ordinary"  # what the thread got: "ordinary", "SCHED_FIFO N" or "refused (...)"
        self._ready = threading.Event()
        self._dirs = {d: _Direction(direction in (d, "both"), None if seed is None else [seed, i])
                      for i, d in enumerate(("up", "down"))}
        self.address: tuple[str, int] | None = None
        self.kernel_stamps = False
        self._heap: list[tuple[float, int, str, Any]] = []
        self._seq = 0
        self._client: Any = None  # the last ground-station address (UDP)
        self._conns: dict[str, socket.socket] = {}  # TCP: "gcs" and "vehicle" while a connection is open
        self._out: dict[str, bytearray] = {}
        self._closing: set[str] = set()  # TCP: the sides to shut down once their data has gone
        self._connections = 0
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._running = False
        self._t0 = 0.0
        self._t_end: float | None = None
        self._sel: selectors.BaseSelector | None = None
        self._socks: list[socket.socket] = []
        self._wake_r: socket.socket | None = None
        self._wake_w: socket.socket | None = None

    # -------------------------------------------------------------------------------------------- public
    def __repr__(self) -> str:
        from ..simulate.varying import DelaySchedule, Jitter

        parts = []
        for p in getattr(self.model, "parts", (self.model,)):
            if isinstance(p, DelaySchedule) and len(p.times) == 1 and p.function is None:
                parts.append(f"{p.delays[0]:g} s")
            elif isinstance(p, Jitter) and p.distribution == "uniform" and p.base == 0:
                parts.append(f"uniform [0, {p.spread:g}] s")
            else:
                parts.append(repr(p))
        loss = f", loss {self.loss:g}" if self.loss else ""
        order = ", may reorder" if self.reorder else ""
        listen = self.listen if self.address is None else Endpoint(self.listen.transport, *self.address[:2])
        return f"DelayRelay({listen} -> {self.to}, {self.direction}, {' + '.join(parts)}{loss}{order})"

    def start(self) -> "DelayRelay":
        """Bind ``listen`` (and, for UDP, the socket towards ``to``) and start the relay's thread.

        Raises
        ------
        PortError
            ``listen`` cannot be bound (in use, or refused), naming it.
        """
        if self._running:
            raise InvalidValueError("this relay is already running")
        self._sel = selectors.SelectSelector()  # microsecond timeouts (see the module docstring)
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        try:
            self._listen_sock = self._bind(self.listen)
            if not self.tcp:
                up = socket.socket(self.to.family, socket.SOCK_DGRAM)
                self._socks.append(up)
                up.connect(self.to.address)  # replies from anyone else are not the vehicle's
                up.setblocking(False)
                self.kernel_stamps = enable_stamps(self._listen_sock) and enable_stamps(up)
                self._up_sock = up
                self._sel.register(up, selectors.EVENT_READ, "vehicle")
        except OSError as exc:
            self._close_all()
            if isinstance(exc, PortError):
                raise
            raise PortError(f"cannot open the relay towards {self.to}: {exc.strerror or exc}") from None
        self._sel.register(self._listen_sock, selectors.EVENT_READ, "listen")
        self.address = self._listen_sock.getsockname()[:2]
        self._t0 = time.monotonic()
        self._t_end = None
        self._running = True
        self._ready.clear()
        self._thread = threading.Thread(target=self._run, name="delaykit-relay", daemon=True)
        self._thread.start()
        self._ready.wait(5.0)  # (its priority is set, or refused, before start returns)
        return self

    def stop(self) -> None:
        """Stop the thread, count the packets still waiting as ``unsent``, and close the sockets."""
        if not self._running:
            return
        self._running = False
        try:
            self._wake_w.send(b"x")  # type: ignore[union-attr]
        except OSError:
            pass
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        with self._lock:
            for _, _, d, payload in self._heap:
                if payload is not None:  # (None: a TCP end of stream)
                    self._dirs[d].counts["unsent"] += 1
            self._heap.clear()
            self._t_end = time.monotonic()
        self._close_all()

    def __enter__(self) -> "DelayRelay":
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        """Whether the relay is forwarding."""
        return self._running

    @property
    def counts(self) -> dict[str, dict[str, int]]:
        """A snapshot of each direction's counts, ``{"up": {...}, "down": {...}}`` (safe while it runs)."""
        with self._lock:
            return {d: dict(s.counts) for d, s in self._dirs.items()}

    def summary(self) -> RelaySummary:
        """Counts and excess of each direction so far (final after :meth:`stop`).

        Returns
        -------
        RelaySummary
        """
        with self._lock:
            end = self._t_end if self._t_end is not None else time.monotonic()
            up, down = self._dirs["up"].stats(), self._dirs["down"].stats()
            return RelaySummary(listen=str(self.listen if self.address is None else
                                           Endpoint(self.listen.transport, *self.address[:2])),
                                to=str(self.to), direction=self.direction, delay=self.model.to_dict(),
                                jitter=self.jitter, loss=self.loss, reorder=self.reorder,
                                kernel_stamps=self.kernel_stamps,
                                duration=max(end - self._t0, 0.0) if self._t0 else 0.0,
                                up=up, down=down, seed=self.seed, connections=self._connections,
                                scheduling=self.scheduling)

    # ------------------------------------------------------------------------------------------ sockets
    def _bind(self, ep: Endpoint) -> socket.socket:
        s = socket.socket(ep.family, socket.SOCK_STREAM if self.tcp else socket.SOCK_DGRAM)
        self._socks.append(s)
        if self.tcp:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(ep.address)
            if self.tcp:
                s.listen(1)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise PortError(f"listen {ep}: the port is already in use") from None
            raise PortError(f"listen {ep}: cannot bind it ({exc.strerror or exc})") from None
        s.setblocking(False)
        return s

    def _close_all(self) -> None:
        for s in [*self._socks, *self._conns.values(), self._wake_r, self._wake_w]:
            if s is not None:
                try:
                    s.close()
                except OSError:
                    pass
        self._socks.clear()
        self._conns.clear()
        if self._sel is not None:
            self._sel.close()
            self._sel = None

    # -------------------------------------------------------------------------------------- the thread
    def _set_priority(self) -> None:
        """Ask for ``SCHED_FIFO`` at :attr:`priority` for this thread (Linux applies it to the calling thread)."""
        if self.priority is None:
            self.scheduling = "ordinary"
            return
        try:
            import os

            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.priority))
        except AttributeError:
            self.scheduling = "refused (no SCHED_FIFO on this system)"
        except OSError as exc:
            self.scheduling = f"refused ({exc.strerror or exc})"
        else:
            self.scheduling = f"SCHED_FIFO {self.priority}"

    def _run(self) -> None:
        self._set_priority()
        self._ready.set()
        sel = self._sel
        assert sel is not None
        while self._running:
            self._send_due()
            timeout = None if not self._heap else max(self._heap[0][0] - time.monotonic(), 0.0)
            try:
                events = sel.select(timeout)
            except (OSError, ValueError):  # closed under us: stopping
                break
            for key, mask in events:
                what = key.data
                if what == "wake":
                    try:
                        self._wake_r.recv(64)  # type: ignore[union-attr]
                    except OSError:
                        pass
                elif what == "listen" and self.tcp:
                    self._accept()
                elif self.tcp:
                    if mask & selectors.EVENT_WRITE:
                        self._flush(what)
                    if mask & selectors.EVENT_READ:
                        self._read_stream(what)
                else:
                    self._read_datagrams(key.fileobj, "up" if what == "listen" else "down")

    def _schedule(self, d: str, t_arrival: float, payload: Any) -> bool:
        """Draw the packet's fate and queue it; False if it is lost."""
        st = self._dirs[d]
        with self._lock:
            st.counts["received"] += 1
        due = t_arrival
        if st.delayed:
            lost = st.rng.random() < self.loss
            delay = (self._constant if self._constant is not None else
                     float(self.model.packet_delays([t_arrival - self._t0], st.rng)[0]))
            if lost:
                with self._lock:
                    st.counts["dropped"] += 1
                return False
            due = t_arrival + delay
        if not self.reorder:
            due = max(due, st.last_due)
        st.last_due = due
        self._seq += 1
        heapq.heappush(self._heap, (due, self._seq, d, payload))
        return True

    def _read_datagrams(self, sock: Any, d: str) -> None:
        for _ in range(_BATCH):
            try:
                data, addr, t = recv_stamped(sock, _MAX_DATAGRAM)
            except BlockingIOError:
                return
            except OSError:  # ICMP port unreachable from an earlier send (the vehicle is not listening yet)
                with self._lock:
                    self._dirs["up"].counts["errors"] += 1
                continue
            if d == "up":
                self._client = addr
            self._schedule(d, t, data)

    def _send_due(self) -> None:
        heap = self._heap
        while heap and heap[0][0] <= time.monotonic():
            due, _, d, payload = heapq.heappop(heap)
            if self.tcp:
                self._deliver_stream(d, due, payload)
                continue
            st = self._dirs[d]
            try:
                if d == "up":
                    self._up_sock.send(payload)
                elif self._client is None:
                    with self._lock:
                        st.counts["unroutable"] += 1
                    continue
                else:
                    self._listen_sock.sendto(payload, self._client)
            except OSError:  # refused (nobody listens there yet) or the buffer is full
                with self._lock:
                    st.counts["errors"] += 1
                    st.counts["unroutable"] += 1
                continue
            late = time.monotonic() - due
            with self._lock:
                st.counts["forwarded"] += 1
                st.counts["bytes"] += len(payload)
                st.excess.append(late)

    # --------------------------------------------------------------------------------------------- TCP
    def _accept(self) -> None:
        try:
            gcs, _ = self._listen_sock.accept()
        except OSError:
            return
        if self._conns:  # one connection at a time (the listening socket is unregistered meanwhile)
            gcs.close()
            return
        try:
            veh = socket.create_connection(self.to.address, timeout=5.0)
        except OSError:
            gcs.close()
            with self._lock:
                self._dirs["up"].counts["errors"] += 1
            return
        for s in (gcs, veh):
            s.setblocking(False)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._conns = {"gcs": gcs, "vehicle": veh}
        self._out = {"gcs": bytearray(), "vehicle": bytearray()}
        self._closing = set()
        self._connections += 1
        self._dirs["up"].last_due = self._dirs["down"].last_due = -math.inf
        self._sel.unregister(self._listen_sock)  # type: ignore[union-attr]
        self._sel.register(gcs, selectors.EVENT_READ, "gcs")  # type: ignore[union-attr]
        self._sel.register(veh, selectors.EVENT_READ, "vehicle")  # type: ignore[union-attr]

    def _read_stream(self, side: str) -> None:
        sock = self._conns.get(side)
        if sock is None:
            return
        d = "up" if side == "gcs" else "down"
        try:
            data = sock.recv(_CHUNK)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        t = time.monotonic()
        if data:
            self._schedule(d, t, data)
            return
        # end of this side's stream: stop reading it; the other side is shut down once the data ahead has gone
        self._sel.unregister(sock)  # type: ignore[union-attr]
        st = self._dirs[d]
        due = max(t, st.last_due)
        st.last_due = due
        self._seq += 1
        heapq.heappush(self._heap, (due, self._seq, d, None))

    def _deliver_stream(self, d: str, due: float, payload: bytes | None) -> None:
        side = "vehicle" if d == "up" else "gcs"
        if side not in self._conns:
            return
        if payload is None:
            self._closing.add(side)
        else:
            self._out[side] += payload
            st = self._dirs[d]
            with self._lock:
                st.counts["forwarded"] += 1
                st.counts["bytes"] += len(payload)
                st.excess.append(time.monotonic() - due)
        self._flush(side)

    def _flush(self, side: str) -> None:
        sock = self._conns.get(side)
        if sock is None:
            return
        buf = self._out[side]
        try:
            while buf:
                n = sock.send(buf)
                del buf[:n]
        except BlockingIOError:
            pass
        except OSError:  # the peer went away: end the connection
            self._end_connection()
            return
        want = selectors.EVENT_WRITE if buf else 0
        key = self._sel.get_map().get(sock)  # type: ignore[union-attr]
        reading = key is not None and key.events & selectors.EVENT_READ
        events = want | (selectors.EVENT_READ if reading else 0)
        if key is not None and events != key.events:
            if events:
                self._sel.modify(sock, events, side)  # type: ignore[union-attr]
            else:
                self._sel.unregister(sock)  # type: ignore[union-attr]
        elif key is None and events:
            self._sel.register(sock, events, side)  # type: ignore[union-attr]
        if not buf and side in self._closing:
            try:
                sock.shutdown(socket.SHUT_WR)
            except OSError:
                pass
            self._closing.discard(side)
            self._closing.add(side + ":done")
            if {"gcs:done", "vehicle:done"} <= self._closing:
                self._end_connection()

    def _end_connection(self) -> None:
        for s in self._conns.values():
            try:
                self._sel.unregister(s)  # type: ignore[union-attr]
            except (KeyError, ValueError):
                pass
            s.close()
        self._conns = {}
        self._out = {}
        self._closing = set()
        with self._lock:  # what was still waiting has nowhere to go now
            for _, _, d, payload in self._heap:
                if payload is not None:
                    self._dirs[d].counts["unsent"] += 1
        self._heap.clear()
        self._sel.register(self._listen_sock, selectors.EVENT_READ, "listen")  # type: ignore[union-attr]
