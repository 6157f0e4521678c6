"""Issue 31's criteria on data the fit did not shape: flights of the emulator's ``speed_loop`` vehicle with its
acceleration limit, generated offline.

The emulator's own physics (:class:`~delaykit.hardware.emulator.DroneEmulator`: the command's delay, the 1 m/s^2
rate limit held over 2 ms steps, the second-order speed loop with a zero, the hover wander, the ultrasonic noise)
is stepped directly on a 20 Hz clock, no sockets and no real time: a held random vertical-speed command (a new
value every 0.5 s, uniform in +-1 m/s) for 60 s, the altitude and the vertical speed logged at 20 Hz.  The vehicle
is not the fitted structure (a speed loop with a slow pole-zero pair, not a first-order lag), so the fit's errors
are real.  The truth is the emulator's loop delay (:attr:`~delaykit.hardware.emulator.DroneEmulator.true_delay`).
"""

from __future__ import annotations

import numpy as np
import pytest

from delaykit.hardware.ardrone import CtrlState
from delaykit.hardware.emulator import DroneEmulator, EmulatorConfig
from delaykit.identify.identification import identify
from delaykit.identify.iodata import Experiment

H = 0.05  # 20 Hz
DELAY = 0.30  # the emulator's default actuator delay (no link delay: the loop delay)


def _flight(command_seed: int, added: float = 0.0, link: float = 0.0) -> tuple[Experiment, float]:
    """One emulated flight and the emulator's true loop delay: ``added`` to the actuator's delay, ``link`` each
    way on the link (the command's way in and the measurement's way back)."""
    emu = DroneEmulator(EmulatorConfig(vehicle="speed_loop", accel_limit=1.0, delay=DELAY + added, link_delay=link,
                                       seed=10 + command_seed))
    emu._alt_max = 1e6  # (a random walk of the altitude: no ceiling or floor within the log)
    p = emu._phys
    p.t, emu._t0, p.mode, p.z = 0.0, 0.0, CtrlState.HOVERING, 100.0
    n = int(round(60.0 / H))
    t = np.arange(n) * H
    u = np.repeat(np.random.default_rng(command_seed).uniform(-1.0, 1.0, n // 10 + 1), 10)[:n]
    u[:40] = 0.0  # 2 s of hover first
    z, vz = np.empty(n), np.empty(n)
    for k in range(n):
        emu._advance(t[k])
        z_true, vz[k] = emu._state_at(t[k] - link)  # (what the emulator sends: the state a link delay ago)
        z[k] = emu._measure(z_true, p.mode)
        emu._cmd_speed(float(u[k]), t[k])
    return Experiment.from_arrays(t, {"z": z, "vz": vz}, u=u, name=f"cmd{command_seed}+{added:g}"), emu.true_delay


def _delay(e: Experiment, model: str = "ipdt_accel"):
    return identify(e, model=model, outputs="z", rate="vz", baseline="fit", per_log=False)


@pytest.fixture(scope="module")
def fits():
    out = {}
    for seed, added in ((1, 0.0), (2, 0.0), (3, 0.0), (1, 0.15), (1, 0.30)):
        e, truth = _flight(seed, added)
        out[seed, added] = (_delay(e), truth)
    for added in (0.15, 0.30):  # the same added on the link, half each way
        e, truth = _flight(1, link=added / 2)
        out["link", added] = (_delay(e), truth)
    return out


def test_the_same_vehicle_gives_the_same_delay_whatever_the_excitation(fits):
    delays = [fits[s, 0.0][0].delay for s in (1, 2, 3)]
    assert max(delays) - min(delays) < 0.040, delays  # issue 31: within 40 ms (measured: 13.6 ms)
    for m, truth in fits.values():  # and each interval holds the emulator's loop delay
        lo, hi = m.ci["delay"]
        assert lo <= truth <= hi, (m.delay, m.ci["delay"], truth)


@pytest.mark.parametrize("where", [1, "link"])
def test_an_added_delay_is_recovered(fits, where):
    # added to the actuator's delay, or on the link (half on the command's way in, half on the measurement's way
    # back); measured: 0.153 and 0.302 s, 0.162 and 0.300 s
    base = fits[1, 0.0][0].delay
    for added in (0.15, 0.30):
        m, truth = fits[where, added]
        assert truth == pytest.approx(DELAY + added)
        assert abs((m.delay - base) - added) < 0.030, (added, m.delay - base)  # issue 31: within 30 ms


def test_auto_chooses_the_acceleration_limit_on_these_flights_and_a_linear_structure_is_biased(fits):
    e, truth = _flight(2)
    m = identify(e, model="auto", outputs="z", rate="vz", baseline="fit", per_log=False)
    assert m.model == "ipdt_accel"
    assert m.delay == pytest.approx(fits[2, 0.0][0].delay, abs=1e-6)
    # without the limit the ramps go into the delay: ipdt_lag's interval misses the truth (it puts 0.41 to 0.43 s)
    lag = _delay(e, "ipdt_lag")
    assert lag.ci["delay"][0] > truth + 0.05
