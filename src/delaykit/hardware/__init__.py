"""Hardware: fly a designed loop on an AR.Drone 2.0, or on an emulator that speaks its protocol.

:mod:`.ardrone` encodes and decodes the drone's AT commands and navdata, :mod:`.emulator` is a drone on UDP
(simulated altitude dynamics with a delay) for testing without one, :mod:`.stamps` gives datagrams the kernel's
arrival time, :mod:`.laws` runs any controller or compensator on packets, :mod:`.autotune` flies a relay experiment and tunes from its cycle, :mod:`.monitor` re-estimates the delay
during a flight (alarm, gain scheduling), :mod:`.link` is the vehicle-link interface (:mod:`.ardrone_link` the
AR.Drone's, :mod:`.mavlink` PX4's and ArduPilot's, :mod:`.tello` a Tello's over its SDK; :mod:`.emulator_mavlink` and
:mod:`.emulator_tello` the emulator's front ends), :mod:`.flight` is the real-time loop that flies a plan and logs
what it saw, and :mod:`.relay` forwards a real link (UDP or TCP) with a set delay, jitter and loss. It sits above
design and identification: its logs feed :mod:`delaykit.identify`.
"""

from .._lazy import lazy_exports
from .ardrone import (ARITY, DEMO_SIZE, HEADER, REF_BASE, REF_EMERGENCY, REF_TAKEOFF, ATCommand, ATEncoder, ATError,
                      CtrlState, Demo, Navdata, NavdataError, NavState, ProtocolError, bootstrap_packet,
                      decode_navdata, encode_navdata, float_to_int, int_to_float, parse_at)
from .emulator import DroneEmulator, EmulatorConfig, PortError
from .ardrone_link import DroneLink
from .flight import FlightPlan, FlightResult, fly, land_on_signals
from .link import AltitudeSample, LinkError, VehicleLink, VehicleRefusedError
from .laws import FlightLaw, Relay, RelayLaw
from .relay import DelayRelay, DirectionStats, Endpoint, RelaySummary, parse_endpoint
from .stamps import enable_stamps, recv_stamped

# the monitor pulls in the estimator, the design and the simulator (numba): loaded on first use, so that the
# emulator and the flight loop start without them
_LAZY = {"MavlinkLink": ".mavlink", "MavlinkEmulator": ".emulator_mavlink", "TelloLink": ".tello", "TelloEmulator": ".emulator_tello", "AutotuneResult": ".autotune", "DelayMonitor": ".monitor", "OnlineEstimate": ".monitor", "stable_range": ".monitor"}


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals())

__all__ = [
    "ProtocolError", "ATError", "NavdataError", "ATCommand", "ATEncoder", "parse_at", "float_to_int", "int_to_float",
    "NavState", "CtrlState", "Demo", "Navdata", "encode_navdata", "decode_navdata", "bootstrap_packet", "HEADER",
    "REF_BASE", "REF_TAKEOFF", "REF_EMERGENCY", "DEMO_SIZE", "ARITY",
    "EmulatorConfig", "DroneEmulator", "PortError",
    "LinkError", "VehicleRefusedError", "VehicleLink", "AltitudeSample", "DroneLink", "FlightPlan", "FlightResult", "fly", "land_on_signals", "FlightLaw",
    "DelayMonitor", "OnlineEstimate", "stable_range", "enable_stamps", "recv_stamped", "Relay", "RelayLaw", "AutotuneResult",
    "DelayRelay", "RelaySummary", "DirectionStats", "Endpoint", "parse_endpoint", "MavlinkLink", "MavlinkEmulator",
    "TelloLink", "TelloEmulator",
]
