"""The AR.Drone 2.0 wire protocol: test vectors, round trips, rejections, and fuzzing (hypothesis)."""

from __future__ import annotations

import ast
import struct
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from delaykit.errors import InvalidValueError
from delaykit.hardware.ardrone import (ARITY, ATCommand, ATEncoder, ATError, CtrlState, Demo, NavdataError, NavState,
                                       ProtocolError, bootstrap_packet, decode_navdata, encode_navdata, float_to_int,
                                       int_to_float, parse_at)

# the bootstrap packet of the protocol notes, captured from a real drone
VECTOR = bytes.fromhex("88 77 66 55 10 0c 80 4f 01 00 00 00 00 00 00 00 ff ff 08 00 a6 02 00 00")


def test_bootstrap_vector_decodes_and_re_encodes():
    nd = decode_navdata(VECTOR)
    assert nd.state == 0x4F800C10 and nd.sequence == 1 and nd.demo is None
    assert nd.has(NavState.NAVDATA_BOOTSTRAP) and nd.has(NavState.COM_WATCHDOG)
    assert encode_navdata(0x4F800C10, 1) == VECTOR
    assert len(bootstrap_packet()) == 24


def test_float_encoding_vectors():
    # the protocol notes' examples (struct pack '<f', unpack '<i')
    assert [float_to_int(x) for x in (1.0, 0.5, -0.25, -0.8)] == [1065353216, 1056964608, -1098907648, -1085485875]
    assert int_to_float(-1085485875) == struct.unpack("<f", struct.pack("<f", -0.8))[0]


def _bits(x: float, fmt: str) -> int:
    """The reference: the IEEE-754 single's bits of x read as a signed ('<i') or unsigned ('<I') integer."""
    return struct.unpack(fmt, struct.pack("<f", x))[0]


def test_floats_accepts_the_signed_and_unsigned_forms_of_the_same_bits():
    # the values named in the bug report; by struct (see _bits) they are the bits of -0.25, not -0.5
    assert (_bits(-0.25, "<I"), _bits(-0.25, "<i")) == (3196059648, -1098907648)
    assert ATCommand("PCMD", 1, (1, 0, 0, 3196059648, 0)).floats(3, 4) == [-0.25]
    assert ATCommand("PCMD", 1, (1, 0, 0, -1098907648, 0)).floats(3, 4) == [-0.25]
    # -0.5 itself, both forms (3204448256 and -1090519040)
    half = ATCommand("PCMD", 1, (1, _bits(-0.5, "<I"), _bits(-0.5, "<i"), 0, 0))
    assert half.floats(1, 3) == [-0.5, -0.5] and int_to_float(_bits(-0.5, "<I")) == -0.5
    # the parser accepts the unsigned form, and floats() reads what it accepted
    cmd, = parse_at(b"AT*PCMD=1,1,0,0,3196059648,0\r")
    assert cmd.floats(1, 5) == [0.0, 0.0, -0.25, 0.0]


@pytest.mark.parametrize("arg, fragment", [
    (2**32, "from -2\\*\\*31 to 2\\*\\*32 - 1, got 4294967296"),
    (-(2**31) - 1, "from -2\\*\\*31 to 2\\*\\*32 - 1, got -2147483649"),
    ("k", "argument 1 must be a 32-bit integer, got 'k' \\(str\\)"),
    (True, "got the bool True"),
])
def test_floats_rejects_what_does_not_fit_32_bits_with_the_modules_error(arg, fragment):
    with pytest.raises(ATError, match=fragment) as info:
        ATCommand("CONFIG", 1, (arg, "v")).floats(0, 1)
    assert isinstance(info.value, InvalidValueError)
    with pytest.raises(ATError, match="32-bit integer"):
        int_to_float(arg)


def test_at_commands_encode_as_the_sdk_and_parse_back():
    e = ATEncoder()
    assert e.ref(takeoff=True) == b"AT*REF=1,290718208\r"
    assert e.ref() == b"AT*REF=2,290717696\r"
    assert e.pcmd(gaz=-0.25) == b"AT*PCMD=3,1,0,0,-1098907648,0\r"
    assert e.config("general:navdata_demo", "TRUE") == b'AT*CONFIG=4,"general:navdata_demo","TRUE"\r'
    datagram = e.ftrim() + e.ctrl(5, 0) + e.comwdg() + e.config_ids("a", "b", "c") + e.pcmd_mag(0, 0, 0.5, 0, 0.1, 0.2)
    cmds = parse_at(datagram)
    assert [c.name for c in cmds] == ["FTRIM", "CTRL", "COMWDG", "CONFIG_IDS", "PCMD_MAG"]
    assert [c.seq for c in cmds] == [5, 6, 7, 8, 9]
    assert cmds[3].args == ("a", "b", "c") and cmds[4].floats(1, 5)[2] == 0.5


@pytest.mark.parametrize("datagram, fragment", [
    (b"AT*JUMP=1\r", "unknown command"),
    (b"AT*REF=1\r", "REF takes 1 arguments, got 0"),
    (b"AT*REF=x,1\r", "sequence number"),
    (b"AT*PCMD=1,1,0,0,1075838976,0\r", "gaz = 2.5 is outside"),  # 2.5 as a float
    (b"AT*REF=1,12a\r", "not an integer"),
    (b"AT*REF=1,290718208", "does not end with a carriage return"),
    (b'AT*CONFIG=1,"a,"b"\r', "expected ','"),
    (b"\xff\xfe", "not ASCII"),
    (b"A" * 1100 + b"\r", "exceeds 1024"),
    (b"GET / HTTP/1.0\r", "not of the form"),
    (b"AT*PCMD=1,1,0,0,4294967296,0\r", "does not fit 32 bits"),  # 2**32
    (b'AT*REF=1,"x"\r', "argument 1 of REF must be an integer"),
    (b'AT*PCMD=1,"1",0,0,0,0\r', "argument 1 of PCMD must be an integer"),
    (b"AT*CONFIG=1,5,6\r", "argument 1 of CONFIG must be a quoted string"),
])
def test_malformed_at_is_rejected_specifically(datagram, fragment):
    with pytest.raises(ATError, match=fragment):
        parse_at(datagram)


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(gaz=1.5), r"PCMD gaz must be in \[-1, 1\], got 1.5"),
    (dict(roll=-1.01), r"PCMD roll must be in \[-1, 1\], got -1.01"),
    (dict(yaw=float("nan")), r"PCMD yaw must be in \[-1, 1\], got nan"),
])
def test_pcmd_out_of_range_names_the_value(kwargs, fragment):
    with pytest.raises(ATError, match=fragment) as info:
        ATEncoder().pcmd(**kwargs)
    assert type(info.value) is ATError


@pytest.mark.parametrize("args, fragment", [
    ((0, 0, 0, 0, 1e40, 0), r"PCMD_MAG psi must be a number in \[-1, 1\], got 1e\+40"),  # was an OverflowError
    ((0, 0, 2.0, 0, 0, 0), r"PCMD_MAG gaz must be a number in \[-1, 1\], got 2.0"),
    ((0, 0, 0, 0, 0, float("inf")), r"PCMD_MAG psi_accuracy must be a number in \[-1, 1\], got inf"),
    ((0, "0", 0, 0, 0, 0), r"PCMD_MAG pitch must be a number in \[-1, 1\], got '0'"),
])
def test_pcmd_mag_out_of_range_is_a_value_error_naming_the_value(args, fragment):
    with pytest.raises(InvalidValueError, match=fragment) as info:
        ATEncoder().pcmd_mag(*args)
    assert type(info.value) is ATError and isinstance(info.value, ValueError)


def test_encoder_rejects_what_the_wire_cannot_carry():
    # a float beyond the single's range (about 3.4e38) and an integer beyond 32 bits: the module's error, naming it
    with pytest.raises(ATError, match=r"fit an IEEE-754 single .* got 1e\+40"):
        float_to_int(1e40)
    with pytest.raises(ATError, match="must be a real number, got 'x'"):
        float_to_int("x")  # type: ignore[arg-type]
    with pytest.raises(ATError, match=r"AT\*CTRL argument 1 must be a 32-bit integer, .* got 4294967296"):
        ATEncoder().ctrl(2**32)
    with pytest.raises(ATError, match=r"AT\*FLOAT argument 1 must be a 32-bit integer, .* got -2147483649"):
        ATEncoder().encode("FLOAT", -(2**31) - 1)
    # the largest single still encodes, and reads back
    big = struct.unpack("<f", struct.pack("<f", 3.4e38))[0]
    assert int_to_float(float_to_int(3.4e38)) == big
    # the receiver applies the same [-1, 1] rule to PCMD_MAG as to PCMD (2.5 as a float: 1075838976)
    with pytest.raises(ATError, match="psi = 2.5 is outside"):
        parse_at(b"AT*PCMD_MAG=1,1,0,0,0,0,1075838976,0\r")


def test_navdata_round_trip_and_rejections():
    demo = Demo(ctrl_state=CtrlState.HOVERING << 16, battery=77, altitude_mm=1234, vz=-56.5, theta=1.5)
    pkt = encode_navdata(NavState.FLYING | NavState.NAVDATA_DEMO, 42, demo=demo, options=[(0x1234, b"abcd")])
    nd = decode_navdata(pkt)
    assert nd.demo == demo and nd.sequence == 42 and nd.options == {0x1234: b"abcd"}
    assert nd.demo.major == CtrlState.HOVERING
    # each malformed packet, and the message that names what is wrong with it (the sizes, the values)
    bad = {
        "navdata packet of 20 bytes is too short": pkt[:20],
        "navdata header is 0x55667700, expected 0x55667788": b"\x00" + pkt[1:],
        r"navdata checksum \d+ does not match the data \(\d+\)": pkt[:-1] + bytes([pkt[-1] ^ 1]),
        "navdata packet has no checksum option": pkt[:-8],
        r"navdata option 0x0000 at byte 16 \(size 200\) runs past the end \(\d+ bytes\)":
            pkt[:16] + struct.pack("<HH", 0, 200) + pkt[20:],
        "demo option has size 100, expected 148": pkt[:16] + struct.pack("<HH", 0, 100) + pkt[20:],
    }
    for fragment, data in bad.items():
        with pytest.raises(NavdataError, match=fragment) as info:
            decode_navdata(data)
        assert type(info.value) is NavdataError


def test_pyardrone_parses_delaykit_navdata():
    pn = pytest.importorskip("pyardrone.navdata")
    pkt = encode_navdata(NavState.FLYING | NavState.NAVDATA_DEMO, 5, demo=Demo(altitude_mm=987, vz=12.0))
    nd = pn.NavData(bytearray(pkt))
    assert nd.demo.altitude == 987 and nd.demo.vz == 12.0 and nd.metadata.sequence_number == 5


def _read_everything(cmds):
    """Use every parsed command as a receiver would: all its arguments read as floats."""
    for c in cmds:
        for k in range(len(c.args)):
            try:
                c.floats(k, k + 1)
            except ATError:
                assert not isinstance(c.args[k], int) or not -(2**31) <= c.args[k] < 2**32


@settings(max_examples=400)
@given(st.binary(max_size=600))
def test_fuzz_decoders_never_crash(data):
    for decode in (decode_navdata, parse_at):
        try:
            result = decode(data)
        except ProtocolError:
            continue
        if decode is parse_at:
            _read_everything(result)


# integers around every edge of the 32-bit forms: signed, unsigned (above 2**31), and just outside both
INT_ARG = st.one_of(st.integers(-(2**31), 2**31 - 1), st.integers(2**31, 2**32 - 1),
                    st.integers(-(2**33), 2**33), st.sampled_from([-(2**31) - 1, -(2**31), 2**31 - 1, 2**31,
                                                                   2**32 - 1, 2**32]))
AT_ARG = st.one_of(INT_ARG, INT_ARG.map(str), st.text(alphabet="abc:_,", max_size=6).map(lambda t: f'"{t}"'))


@settings(max_examples=400)
@given(st.lists(st.tuples(st.sampled_from(sorted(ARITY) + ["JUMP"]), st.integers(-2, 2**31),
                          st.lists(AT_ARG, max_size=8)), min_size=1, max_size=6))
def test_fuzz_at_with_random_signed_and_unsigned_arguments(commands):
    # AT-shaped datagrams whose arguments are random integers in and out of the 32-bit forms (and strings);
    # nothing but the module's own error escapes, from parsing or from reading the arguments as floats
    datagram = b"".join(f"AT*{name}={','.join([str(seq), *map(str, args)])}\r".encode()
                        for name, seq, args in commands)
    try:
        cmds = parse_at(datagram)
    except ProtocolError:
        return
    _read_everything(cmds)
    for c in cmds:
        if c.name == "PCMD":  # the reference: the low 32 bits read as an IEEE-754 single by struct
            assert c.floats(1, 5) == [struct.unpack("<f", struct.pack("<I", a & 0xFFFFFFFF))[0] for a in c.args[1:5]]


@settings(max_examples=300)
@given(st.lists(st.sampled_from(["REF", "PCMD", "COMWDG", "CONFIG", "CTRL", "FTRIM"]), min_size=1, max_size=8),
       st.floats(-1, 1), st.text(alphabet="abcdefghij:_", max_size=20))
def test_fuzz_at_round_trip(names, x, text):
    e = ATEncoder()
    parts = []
    for n in names:
        parts.append({"REF": lambda: e.ref(takeoff=x > 0), "PCMD": lambda: e.pcmd(gaz=x), "COMWDG": e.comwdg,
                      "CONFIG": lambda: e.config(text or "k", text), "CTRL": lambda: e.ctrl(5),
                      "FTRIM": e.ftrim}[n]())
    datagram = b"".join(parts)
    if len(datagram) > 1024:
        return
    cmds = parse_at(datagram)
    assert [c.name for c in cmds] == names
    for c in cmds:
        if c.name == "PCMD":
            assert c.floats(3, 4)[0] == struct.unpack("<f", struct.pack("<f", x))[0]


@settings(max_examples=300)
@given(st.binary(min_size=24, max_size=400), st.integers(0, 2**32 - 1))
def test_fuzz_navdata_with_valid_header_and_checksum(body, state):
    # structurally plausible packets (right header, right checksum) with random options in between
    raw = struct.pack("<IIII", 0x55667788, state, 1, 0) + body
    pkt = raw + struct.pack("<HHI", 0xFFFF, 8, sum(raw) & 0xFFFFFFFF)
    try:
        nd = decode_navdata(pkt)
    except NavdataError:
        return
    assert nd.state == state


def _unused_names(path: Path) -> list[str]:
    """Parameters never used, and local names assigned but never read, in each function of a module (read with
    :mod:`ast`; names starting with ``_`` are deliberate throwaways, an abstract method's parameters are its
    interface's, and ``del name`` says that an implementation has no use for a parameter of its interface)."""
    found = []
    for fn in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        if any(isinstance(d, ast.Name) and d.id == "abstractmethod" for d in fn.decorator_list):
            continue
        loads = {n.id for n in ast.walk(fn) if isinstance(n, ast.Name) and isinstance(n.ctx, (ast.Load, ast.Del))}
        params = [a.arg for a in fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs]
        found += [f"{path.name}:{fn.lineno} {fn.name}: parameter {a!r} is never used" for a in params
                  if a not in ("self", "cls") and not a.startswith("_") and a not in loads]
        stores = {n.id: n.lineno for n in ast.walk(fn)
                  if isinstance(n, ast.Name) and isinstance(n.ctx, ast.Store) and not n.id.startswith("_")}
        found += [f"{path.name}:{line} {fn.name}: {name!r} is assigned but never read" for name, line in stores.items()
                  if name not in loads]
    return found


def test_hardware_code_has_no_unused_parameters_or_dead_assignments(tmp_path):
    import importlib

    import delaykit.hardware

    folder = Path(delaykit.hardware.__file__).parent
    assert [f for p in sorted(folder.glob("*.py")) for f in _unused_names(p)] == []
    # the compiled kernels too (numba functions are read from their source, as any other function), and the
    # modules around them that were cleaned of the same
    modules = ("delaykit.simulate._kernel", "delaykit.spectrum._rootkernel", "delaykit.simulate.simulation",
               "delaykit.spectrum.roots", "delaykit.identify.identification", "delaykit.identify.estimation",
               "delaykit.paper.report", "delaykit.plotting.compensation", "delaykit.plotting.identification")
    # (a module's source, also where Cython built an extension module from it: ``__file__`` is then the extension)
    sources = [Path(importlib.import_module(m).__file__).with_name(m.rpartition('.')[2] + '.py') for m in modules]
    assert [f for p in sources for f in _unused_names(p)] == []
    # the check finds what it is for: a parameter and an assignment nobody reads (and not the throwaways)
    sample = tmp_path / "sample.py"
    sample.write_text("def f(a, b, _c):\n    x = 1\n    y, _z = a, 2\n    return y\n")
    assert _unused_names(sample) == ["sample.py:1 f: parameter 'b' is never used",
                                     "sample.py:2 f: 'x' is assigned but never read"]
    # and in a compiled function, whose decorator does not hide it
    jitted = tmp_path / "jitted.py"
    jitted.write_text("from numba import njit\n\n\n@njit(cache=True)\ndef g(C, A, tau):\n    return C * tau\n")
    assert _unused_names(jitted) == ["jitted.py:5 g: parameter 'A' is never used"]
