"""The AR.Drone 2.0 wire protocol: test vectors, round trips, rejections, and fuzzing (hypothesis)."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from delaykit.hardware.ardrone import (ATEncoder, ATError, CtrlState, Demo, NavdataError, NavState, ProtocolError,
                                       bootstrap_packet, decode_navdata, encode_navdata, float_to_int, int_to_float,
                                       parse_at)

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
])
def test_malformed_at_is_rejected_specifically(datagram, fragment):
    with pytest.raises(ATError, match=fragment):
        parse_at(datagram)
    with pytest.raises(ATError):
        ATEncoder().pcmd(gaz=1.5)


def test_navdata_round_trip_and_rejections():
    demo = Demo(ctrl_state=CtrlState.HOVERING << 16, battery=77, altitude_mm=1234, vz=-56.5, theta=1.5)
    pkt = encode_navdata(NavState.FLYING | NavState.NAVDATA_DEMO, 42, demo=demo, options=[(0x1234, b"abcd")])
    nd = decode_navdata(pkt)
    assert nd.demo == demo and nd.sequence == 42 and nd.options == {0x1234: b"abcd"}
    assert nd.demo.major == CtrlState.HOVERING
    bad = {
        "too short": pkt[:20],
        "header": b"\x00" + pkt[1:],
        "checksum": pkt[:-1] + bytes([pkt[-1] ^ 1]),
        "no checksum": pkt[:-8],
        "past the end": pkt[:16] + struct.pack("<HH", 0, 200) + pkt[20:],
        "demo option has size": pkt[:16] + struct.pack("<HH", 0, 100) + pkt[20:],
    }
    for what, data in bad.items():
        with pytest.raises(NavdataError):
            decode_navdata(data)


def test_pyardrone_parses_delaykit_navdata():
    pn = pytest.importorskip("pyardrone.navdata")
    pkt = encode_navdata(NavState.FLYING | NavState.NAVDATA_DEMO, 5, demo=Demo(altitude_mm=987, vz=12.0))
    nd = pn.NavData(bytearray(pkt))
    assert nd.demo.altitude == 987 and nd.demo.vz == 12.0 and nd.metadata.sequence_number == 5


@settings(max_examples=400)
@given(st.binary(max_size=600))
def test_fuzz_decoders_never_crash(data):
    for decode in (decode_navdata, parse_at):
        try:
            decode(data)
        except ProtocolError:
            pass


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
