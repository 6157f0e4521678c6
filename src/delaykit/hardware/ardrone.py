"""The AR.Drone 2.0 wire protocol: AT commands (host to drone) and navdata (drone to host).

AT commands are text, ``AT*NAME=<seq>[,arg...]`` ended by a carriage return, several to a datagram (at most
1024 bytes).  Floats travel as the signed 32-bit integer with the same bits as the IEEE-754 single.  Navdata
is little-endian: a 16-byte header (0x55667788, state bits, sequence, vision flag), then options (u16 tag,
u16 size counting the 4 tag/size bytes, payload); the demo option (tag 0, 148 bytes) carries the altitude
in millimetres and the velocities in mm/s; the checksum option (tag 0xFFFF, 8 bytes) is last and holds the
byte sum of everything before it.

Every decoder rejects a malformed datagram with a specific :class:`ProtocolError` subclass (never an
``IndexError`` or ``struct.error`` from deep inside).

Examples
--------
>>> at = ATEncoder()
>>> at.pcmd(gaz=0.5)
b'AT*PCMD=1,1,0,0,1056964608,0\\r'
>>> parse_at(b'AT*PCMD=1,1,0,0,1056964608,0\\r')[0].floats(1, 5)
[0.0, 0.0, 0.5, 0.0]
>>> pkt = encode_navdata(NavState.FLYING | NavState.NAVDATA_DEMO, 7, demo=Demo(altitude_mm=812))
>>> decode_navdata(pkt).demo.altitude_mm
812
"""

from __future__ import annotations

import enum
import math
import operator
import struct
from dataclasses import dataclass, field
from typing import Iterable

from ..errors import InvalidValueError

__all__ = [
    "ProtocolError", "ATError", "NavdataError", "ATCommand", "ATEncoder", "parse_at", "float_to_int", "int_to_float",
    "NavState", "CtrlState", "Demo", "Navdata", "encode_navdata", "decode_navdata", "bootstrap_packet", "HEADER",
    "REF_BASE", "REF_TAKEOFF", "REF_EMERGENCY", "DEMO_SIZE", "ARITY",
]

HEADER = 0x55667788
REF_BASE = 0x11540000  # bits 18, 20, 22, 24, 28: always on
REF_TAKEOFF = 1 << 9
REF_EMERGENCY = 1 << 8
DEMO_TAG = 0
CKS_TAG = 0xFFFF
DEMO_SIZE = 148
MAX_AT = 1024
INT32_MIN, UINT32_END = -(2**31), 2**32  # an AT integer argument is in [INT32_MIN, UINT32_END)
ARITY = {"REF": 1, "PCMD": 5, "PCMD_MAG": 7, "FTRIM": 0, "CONFIG": 2, "CONFIG_IDS": 3, "CTRL": 2, "COMWDG": 0,
         "CALIB": 1}
_FLOAT_ARGS = {"PCMD": (1, 2, 3, 4), "PCMD_MAG": (1, 2, 3, 4, 5, 6)}  # each in [-1, 1]
_FLOAT_NAMES = ("roll", "pitch", "gaz", "yaw", "psi", "psi_accuracy")
_INT_ARGS = {"REF": (0,), "PCMD": (0,), "PCMD_MAG": (0,), "CTRL": (0, 1), "CALIB": (0,)}  # flags, modes, bits
_STR_ARGS = {"CONFIG": (0, 1), "CONFIG_IDS": (0, 1, 2)}  # quoted keys, values, ids


class ProtocolError(InvalidValueError):
    """A malformed datagram."""


class ATError(ProtocolError):
    """A malformed AT command."""


class NavdataError(ProtocolError):
    """A malformed navdata packet."""


def float_to_int(x: float) -> int:
    """The signed 32-bit integer with the bits of the IEEE-754 single ``x`` (how AT commands carry floats).

    Raises :class:`ATError` (an :class:`~delaykit.errors.InvalidValueError`) for a value that is not a real number
    or is too large for a single (beyond about ±3.4e38).

    Examples
    --------
    >>> float_to_int(1.0), float_to_int(-0.8)
    (1065353216, -1085485875)
    """
    try:
        return struct.unpack("<i", struct.pack("<f", x))[0]
    except OverflowError:
        raise ATError(f"an AT float must fit an IEEE-754 single (at most about 3.4e38 in size), got {x!r}") from None
    except struct.error:
        raise ATError(f"an AT float must be a real number, got {x!r} ({type(x).__name__})") from None


def _int32(value: object, what: str = "AT argument") -> int:
    """``value`` as a signed 32-bit integer: the signed form (from -2**31) and the unsigned form (up to
    2**32 - 1) of the same bits are both accepted, as senders write either; anything else is an :class:`ATError`."""
    if isinstance(value, bool):
        raise ATError(f"{what} must be a 32-bit integer, got the bool {value!r}")
    try:
        i = operator.index(value)
    except TypeError:
        raise ATError(f"{what} must be a 32-bit integer, got {value!r} ({type(value).__name__})") from None
    if not INT32_MIN <= i < UINT32_END:
        raise ATError(f"{what} must be a 32-bit integer, from -2**31 to 2**32 - 1, got {i}")
    return i - UINT32_END if i >= 2**31 else i


def int_to_float(i: int) -> float:
    """The inverse of :func:`float_to_int`; ``i`` may be the signed or the unsigned 32-bit form of the bits.

    Raises :class:`ATError` if ``i`` is not an integer in ``[-2**31, 2**32)``.

    Examples
    --------
    >>> int_to_float(-1098907648), int_to_float(3196059648)
    (-0.25, -0.25)
    """
    return struct.unpack("<f", struct.pack("<i", _int32(i)))[0]


@dataclass(frozen=True)
class ATCommand:
    """One parsed AT command: name, sequence number, and raw arguments (ints, or strings without quotes)."""

    name: str
    seq: int
    args: tuple

    def floats(self, start: int = 0, stop: int | None = None) -> list[float]:
        """Integer arguments ``args[start:stop]`` read as floats (signed or unsigned 32-bit forms alike).

        Raises :class:`ATError` if one of them is a string or does not fit 32 bits."""
        first = range(len(self.args))[start:stop]
        return [struct.unpack("<f", struct.pack("<i", _int32(a, f"AT*{self.name} argument {k + 1}")))[0]
                for k, a in zip(first, self.args[start:stop])]


class ATEncoder:
    """Builds AT commands with an increasing sequence number (thread-unsafe; one per sender).

    Examples
    --------
    >>> e = ATEncoder()
    >>> e.ref(takeoff=True), e.comwdg()
    (b'AT*REF=1,290718208\\r', b'AT*COMWDG=2\\r')
    """

    def __init__(self, start: int = 1) -> None:
        self.seq = start - 1

    def _next(self) -> int:
        self.seq += 1
        return self.seq

    def encode(self, name: str, *args: int | float | str) -> bytes:
        """``AT*NAME=<seq>,args...\\r`` (floats as integers, strings quoted)."""
        parts = [str(self._next())]
        for k, a in enumerate(args):
            if isinstance(a, bool):
                parts.append(str(int(a)))
            elif isinstance(a, int):
                _int32(a, f"AT*{name} argument {k + 1}")  # a value the receiver can read back, or an ATError
                parts.append(str(a))
            elif isinstance(a, float):
                parts.append(str(float_to_int(a)))
            elif isinstance(a, str):
                if '"' in a or "\r" in a:
                    raise ATError(f"AT string arguments cannot hold quotes or carriage returns: {a!r}")
                parts.append(f'"{a}"')
            else:
                raise ATError(f"AT argument must be int, float or str, got {type(a).__name__}")
        return f"AT*{name}={','.join(parts)}\r".encode()

    def ref(self, takeoff: bool = False, emergency: bool = False) -> bytes:
        """Take off (``takeoff=True``), land (False), or toggle emergency."""
        return self.encode("REF", REF_BASE | (REF_TAKEOFF if takeoff else 0) | (REF_EMERGENCY if emergency else 0))

    def pcmd(self, roll: float = 0.0, pitch: float = 0.0, gaz: float = 0.0, yaw: float = 0.0, *,
             progressive: bool = True) -> bytes:
        """Move: ``gaz`` is the vertical speed as a fraction of control_vz_max (``|gaz| <= 1``); flag 0 = hover."""
        for name, v in (("roll", roll), ("pitch", pitch), ("gaz", gaz), ("yaw", yaw)):
            if not (math.isfinite(v) and -1.0 <= v <= 1.0):
                raise ATError(f"PCMD {name} must be in [-1, 1], got {v}")
        return self.encode("PCMD", 1 if progressive else 0, float(roll), float(pitch), float(gaz), float(yaw))

    def pcmd_mag(self, roll: float, pitch: float, gaz: float, yaw: float, psi: float, psi_accuracy: float,
                 progressive: bool = True) -> bytes:
        """PCMD with the magnetometer heading: the four moves as in :meth:`pcmd`, and the normalised heading and
        its accuracy, all six in [-1, 1] (an :class:`ATError` names the value otherwise).

        Examples
        --------
        >>> ATEncoder().pcmd_mag(0, 0, 0.5, 0, 0.25, 0.1)
        b'AT*PCMD_MAG=1,1,0,0,1056964608,0,1048576000,1036831949\\r'
        """
        values = (roll, pitch, gaz, yaw, psi, psi_accuracy)
        for name, v in zip(("roll", "pitch", "gaz", "yaw", "psi", "psi_accuracy"), values):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and -1.0 <= v <= 1.0):
                raise ATError(f"PCMD_MAG {name} must be a number in [-1, 1], got {v!r}")
        return self.encode("PCMD_MAG", 1 if progressive else 0, *(float(x) for x in values))

    def ftrim(self) -> bytes:
        """Flat trim (on the ground, before take-off)."""
        return self.encode("FTRIM")

    def config(self, key: str, value: str) -> bytes:
        """``AT*CONFIG=<seq>,"key","value"``."""
        return self.encode("CONFIG", key, value)

    def config_ids(self, session: str, user: str, app: str) -> bytes:
        """``AT*CONFIG_IDS``, sent before CONFIG when custom configuration ids are in use."""
        return self.encode("CONFIG_IDS", session, user, app)

    def ctrl(self, mode: int, arg: int = 0) -> bytes:
        """``AT*CTRL``: 4 = send the configuration on TCP 5559, 5 = acknowledge (clear the ack bit)."""
        return self.encode("CTRL", int(mode), int(arg))

    def comwdg(self) -> bytes:
        """Reset the communication watchdog."""
        return self.encode("COMWDG")


def _parse_args(raw: str, where: str) -> tuple:
    args = []
    i = 0
    while i < len(raw):
        if raw[i] == '"':
            j = raw.find('"', i + 1)
            if j < 0:
                raise ATError(f"{where}: unterminated string argument")
            args.append(raw[i + 1:j])
            i = j + 1
        else:
            j = raw.find(",", i)
            tok = raw[i:] if j < 0 else raw[i:j]
            try:
                val = int(tok)
            except ValueError:
                raise ATError(f"{where}: argument {tok!r} is not an integer") from None
            if not INT32_MIN <= val < UINT32_END:
                raise ATError(f"{where}: argument {val} does not fit 32 bits (expected -2**31 to 2**32 - 1)")
            args.append(val)
            i = len(raw) if j < 0 else j
        if i < len(raw):
            if raw[i] != ",":
                raise ATError(f"{where}: expected ',' after an argument")
            i += 1
            if i == len(raw):
                raise ATError(f"{where}: trailing comma")
    return tuple(args)


def parse_at(datagram: bytes) -> list[ATCommand]:
    """Parse a datagram of AT commands; raise :class:`ATError` on anything malformed.

    Checks: at most 1024 bytes, ASCII, each command ``AT*NAME=<seq>[,args]`` ended by ``\\r`` (a lone ``\\n``
    is accepted too, as the SDK guide writes it), a known name with its number of arguments, integer
    arguments that fit 32 bits (signed or unsigned), integers where the command needs them (flags, modes,
    floats' bits), quoted strings where it needs them (CONFIG), and PCMD and PCMD_MAG floats within [-1, 1].
    """
    if len(datagram) > MAX_AT:
        raise ATError(f"AT datagram of {len(datagram)} bytes exceeds {MAX_AT}")
    try:
        text = datagram.decode("ascii")
    except UnicodeDecodeError:
        raise ATError("AT datagram is not ASCII text") from None
    text = text.replace("\n", "\r")
    if not text.endswith("\r"):
        raise ATError("AT datagram does not end with a carriage return")
    out = []
    for k, chunk in enumerate(c for c in text.split("\r") if c):
        where = f"command {k + 1} ({chunk[:40]!r})"
        if not chunk.startswith("AT*") or "=" not in chunk:
            raise ATError(f"{where}: not of the form AT*NAME=<seq>[,args]")
        name, rest = chunk[3:].split("=", 1)
        if name not in ARITY:
            raise ATError(f"{where}: unknown command {name!r}")
        seq_s, _, argstr = rest.partition(",")
        try:
            seq = int(seq_s)
        except ValueError:
            raise ATError(f"{where}: sequence number {seq_s!r} is not an integer") from None
        if seq < 1:
            raise ATError(f"{where}: sequence number {seq} is not positive")
        args = _parse_args(argstr, where) if argstr or rest.endswith(",") else ()
        if rest.endswith(",") and not argstr:
            raise ATError(f"{where}: trailing comma")
        if len(args) != ARITY[name]:
            raise ATError(f"{where}: {name} takes {ARITY[name]} arguments, got {len(args)}")
        for i in _INT_ARGS.get(name, ()):
            if not isinstance(args[i], int):
                raise ATError(f"{where}: argument {i + 1} of {name} must be an integer, got the string {args[i]!r}")
        for i in _STR_ARGS.get(name, ()):
            if not isinstance(args[i], str):
                raise ATError(f"{where}: argument {i + 1} of {name} must be a quoted string, got {args[i]!r}")
        for i in _FLOAT_ARGS.get(name, ()):
            if not isinstance(args[i], int):
                raise ATError(f"{where}: argument {i + 1} must be a float sent as an integer")
            v = int_to_float(args[i])
            if not (math.isfinite(v) and -1.0 <= v <= 1.0):
                raise ATError(f"{where}: {_FLOAT_NAMES[i - 1]} = {v} is outside [-1, 1]")
        out.append(ATCommand(name, seq, args))
    if not out:
        raise ATError("AT datagram holds no command")
    return out


class NavState(enum.IntFlag):
    """Drone state bits (navdata word 2)."""

    FLYING = 1 << 0
    VIDEO = 1 << 1
    VISION = 1 << 2
    CONTROL = 1 << 3
    ALTITUDE_CONTROL = 1 << 4
    START_BUTTON = 1 << 5
    COMMAND_ACK = 1 << 6
    CAMERA_READY = 1 << 7
    NAVDATA_DEMO = 1 << 10
    NAVDATA_BOOTSTRAP = 1 << 11
    MOTORS_PROBLEM = 1 << 12
    COMMUNICATION_LOST = 1 << 13
    SOFTWARE_FAULT = 1 << 14
    LOW_BATTERY = 1 << 15
    USER_EMERGENCY_LANDING = 1 << 16
    TIMER_ELAPSED = 1 << 17
    MAGNETO_NEEDS_CALIBRATION = 1 << 18
    ANGLES_OUT_OF_RANGE = 1 << 19
    TOO_MUCH_WIND = 1 << 20
    ULTRASOUND_DEAF = 1 << 21
    CUTOUT = 1 << 22
    PIC_VERSION_OK = 1 << 23
    CONTROL_WATCHDOG = 1 << 28
    ADC_WATCHDOG = 1 << 29
    COM_WATCHDOG = 1 << 30
    EMERGENCY = 1 << 31


class CtrlState(enum.IntEnum):
    """Major control state (``ctrl_state >> 16``) in the demo option."""

    DEFAULT = 0
    INIT = 1
    LANDED = 2
    FLYING = 3
    HOVERING = 4
    TEST = 5
    TAKING_OFF = 6
    GOING_TO_FIX = 7
    LANDING = 8
    LOOPING = 9


_DEMO_FMT = "<HHII3fi3fI9f3fII9f3f"
assert struct.calcsize(_DEMO_FMT) == DEMO_SIZE


@dataclass(frozen=True)
class Demo:
    """The navdata_demo option (the fields a controller uses; the camera matrices are carried as zeros)."""

    ctrl_state: int = CtrlState.LANDED << 16
    battery: int = 100
    theta: float = 0.0
    phi: float = 0.0
    psi: float = 0.0
    altitude_mm: int = 0
    vx: float = 0.0
    vy: float = 0.0
    vz: float = 0.0
    frames: int = 0

    @property
    def major(self) -> int:
        """The major control state (see :class:`CtrlState`)."""
        return self.ctrl_state >> 16

    def pack(self) -> bytes:
        return struct.pack(_DEMO_FMT, DEMO_TAG, DEMO_SIZE, self.ctrl_state, self.battery, self.theta, self.phi,
                           self.psi, self.altitude_mm, self.vx, self.vy, self.vz, self.frames, *([0.0] * 12), 0, 0,
                           *([0.0] * 12))

    @classmethod
    def unpack(cls, buf: bytes) -> "Demo":
        v = struct.unpack(_DEMO_FMT, buf)
        return cls(ctrl_state=v[2], battery=v[3], theta=v[4], phi=v[5], psi=v[6], altitude_mm=v[7], vx=v[8],
                   vy=v[9], vz=v[10], frames=v[11])


@dataclass(frozen=True)
class Navdata:
    """A decoded navdata packet."""

    state: int
    sequence: int
    vision: int
    demo: Demo | None
    options: dict = field(default_factory=dict)

    def has(self, bit: NavState) -> bool:
        """True if the state bit is set."""
        return bool(self.state & bit)


def _checksum(b: bytes) -> int:
    return sum(b) & 0xFFFFFFFF


def encode_navdata(state: int, sequence: int, *, vision: int = 0, demo: Demo | None = None,
                   options: Iterable[tuple[int, bytes]] = ()) -> bytes:
    """A navdata packet: header, the demo option (if given), other ``(tag, payload)`` options, the checksum."""
    body = struct.pack("<IIII", HEADER, int(state) & 0xFFFFFFFF, sequence & 0xFFFFFFFF, vision)
    if demo is not None:
        body += demo.pack()
    for tag, payload in options:
        body += struct.pack("<HH", tag, 4 + len(payload)) + payload
    return body + struct.pack("<HHI", CKS_TAG, 8, _checksum(body))


def bootstrap_packet(sequence: int = 1, state: int = 0x0F800C10 | NavState.NAVDATA_BOOTSTRAP) -> bytes:
    """The short packet a drone sends before navdata_demo is set (24 bytes)."""
    return encode_navdata(state | NavState.NAVDATA_BOOTSTRAP, sequence)


def decode_navdata(datagram: bytes) -> Navdata:
    """Decode a navdata packet; raise :class:`NavdataError` on a short packet, a wrong header, an option whose
    size is wrong or runs past the end, a missing or wrong checksum.  Unknown option tags are kept raw."""
    n = len(datagram)
    if n < 24:
        raise NavdataError(f"navdata packet of {n} bytes is too short (at least 24: header and checksum)")
    header, state, seq, vision = struct.unpack_from("<IIII", datagram, 0)
    if header != HEADER:
        raise NavdataError(f"navdata header is {header:#010x}, expected {HEADER:#010x}")
    off = 16
    demo = None
    options: dict[int, bytes] = {}
    cks = None
    while off < n:
        if off + 4 > n:
            raise NavdataError(f"navdata option header at byte {off} is cut off")
        tag, size = struct.unpack_from("<HH", datagram, off)
        if size < 4:
            raise NavdataError(f"navdata option {tag:#06x} at byte {off} has size {size} (at least 4)")
        if off + size > n:
            raise NavdataError(f"navdata option {tag:#06x} at byte {off} (size {size}) runs past the end ({n} bytes)")
        payload = datagram[off:off + size]
        if tag == CKS_TAG:
            if size != 8:
                raise NavdataError(f"checksum option has size {size}, expected 8")
            cks = struct.unpack_from("<I", payload, 4)[0]
            if off + size != n:
                raise NavdataError("the checksum option is not the last")
            if cks != _checksum(datagram[:off]):
                raise NavdataError(f"navdata checksum {cks} does not match the data ({_checksum(datagram[:off])})")
        elif tag == DEMO_TAG:
            if size != DEMO_SIZE:
                raise NavdataError(f"demo option has size {size}, expected {DEMO_SIZE}")
            demo = Demo.unpack(payload)
        else:
            options[tag] = payload[4:]
        off += size
    if cks is None:
        raise NavdataError("navdata packet has no checksum option")
    return Navdata(state=state, sequence=seq, vision=vision, demo=demo, options=options)
