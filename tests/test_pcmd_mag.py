"""PCMD_MAG's psi and psi_accuracy: [-1, 1], the range of the AR.Drone SDK 2.0.

Source: the SDK's ARDroneLib, ``ardrone_at_set_progress_cmd_with_magneto`` (ARDroneLib/Soft/Common/ardrone_api.h and
ARDroneLib/Soft/Lib/ardrone_tool/AT/ardrone_at_mutex.c, as vendored in AutonomyLab/ardrone_autonomy) documents
``magneto_psi`` and ``magneto_psi_accuracy`` as floating values between -1 and +1, sent, like roll, pitch, gaz and
yaw, as the 32-bit integer with the IEEE-754 single's bits.  Both ends are accepted; the nearest floats outside are
refused, by the encoder (in Python floats) and by the receiver's parser (in the float32 on the wire), with a message
that names the argument and the value.
"""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from delaykit.hardware.ardrone import ATEncoder, ATError, float_to_int, int_to_float, parse_at

ABOVE_ONE = math.nextafter(1.0, 2.0)  # the nearest Python float outside [-1, 1]
ABOVE_ONE_F32 = float(np.nextafter(np.float32(1.0), np.float32(2.0)))  # the nearest float32 outside: 1 + 2^-23


def _bits(x: float) -> int:
    """The AT integer of a float32, computed here with struct (independently of delaykit)."""
    return struct.unpack("<i", struct.pack("<f", x))[0]


def _args(psi: float, acc: float) -> list[float]:
    return [0.0, 0.0, 0.0, 0.0, psi, acc]


@pytest.mark.parametrize("psi, acc", [(-1.0, -1.0), (1.0, 1.0), (-1.0, 1.0), (1, -1), (0.0, 0.0), (0.5, -0.25)])
def test_the_ends_are_accepted_and_read_back(psi, acc):
    datagram = ATEncoder().pcmd_mag(*_args(psi, acc))
    assert datagram == f"AT*PCMD_MAG=1,1,0,0,0,0,{_bits(psi)},{_bits(acc)}\r".encode()
    (cmd,) = parse_at(datagram)
    assert cmd.name == "PCMD_MAG"
    assert [int_to_float(v) for v in cmd.args[5:]] == [float(psi), float(acc)]


@pytest.mark.parametrize("name, index", [("psi", 4), ("psi_accuracy", 5)])
@pytest.mark.parametrize("value", [ABOVE_ONE, -ABOVE_ONE, ABOVE_ONE_F32, -ABOVE_ONE_F32, 2.0, -1.5])
def test_the_encoder_refuses_just_outside_naming_the_value(name, index, value):
    args = [0.0] * 6
    args[index] = value
    with pytest.raises(ATError, match=rf"^PCMD_MAG {name} must be a number in \[-1, 1\], got ") as info:
        ATEncoder().pcmd_mag(*args)
    assert str(info.value).endswith(f"got {value!r}")
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize("name, index", [("psi", 6), ("psi_accuracy", 7)])
@pytest.mark.parametrize("value", [1.0, -1.0])
def test_the_parser_accepts_the_ends(name, index, value):
    fields = ["1", "1", "0", "0", "0", "0", "0", "0"]
    fields[index] = str(_bits(value))
    (cmd,) = parse_at(f"AT*PCMD_MAG={','.join(fields)}\r".encode())
    assert int_to_float(cmd.args[index - 1]) == value


@pytest.mark.parametrize("name, index", [("psi", 6), ("psi_accuracy", 7)])
@pytest.mark.parametrize("value", [ABOVE_ONE_F32, -ABOVE_ONE_F32])
def test_the_parser_refuses_just_outside_naming_the_value(name, index, value):
    fields = ["1", "1", "0", "0", "0", "0", "0", "0"]
    fields[index] = str(_bits(value))
    assert _bits(value) in (1065353217, -1082130431)  # one step past 1.0 (1065353216) and -1.0 (-1082130432)
    with pytest.raises(ATError, match=rf"{name} = {value!r} is outside \[-1, 1\]"):
        parse_at(f"AT*PCMD_MAG={','.join(fields)}\r".encode())


def test_the_wire_bits_of_the_ends():
    # the encoder's conversion agrees with struct at the boundary values
    assert [float_to_int(x) for x in (1.0, -1.0, ABOVE_ONE_F32)] == [1065353216, -1082130432, 1065353217]
