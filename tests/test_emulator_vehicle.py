"""The emulator's vehicles (EmulatorConfig.vehicle): the default speed loop identified from the PX4 flights with
its hover wander, and the first-order lag vehicle kept as it was.  The physics are driven with chosen times
through the emulator's own stepping (no sockets, no real time): commands go through ``_handle`` with an arrival
time, the state through ``_advance``.  References: the closed form of the transfer function (partial fractions),
scipy.signal's step and zero-order-hold simulation, and the Ornstein-Uhlenbeck process's moments."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal
from test_emulator_varying import take_off_by_hand

from delaykit import InvalidTypeError, InvalidValueError
from delaykit.hardware.ardrone import ATEncoder, CtrlState
from delaykit.hardware.emulator import DroneEmulator, EmulatorConfig

FREE = dict(at_port=0, navdata_port=0, video_port=0, control_port=0)
VZ_MAX = 0.7  # the factory control_vz_max (m/s): gaz 1 commands 0.7 m/s


def hovering(**cfg) -> tuple[DroneEmulator, ATEncoder]:
    """An emulator that is not started (no threads), its clock set by hand: taken off and hovering at 0.8 m."""
    return take_off_by_hand(**{"delay": 0.25, "noise": 0.0, **cfg})


def state(emu: DroneEmulator, t: float) -> tuple[float, float]:
    """The true altitude (wander included) and vertical speed at emulator time t (s since its start)."""
    with emu._lock:
        emu._advance(emu._t0 + t)
        return emu._true_z(), emu._phys.v


def closed_form(t: np.ndarray, wn: float, zeta: float, tz: float) -> tuple[np.ndarray, np.ndarray]:
    """Altitude and speed after a unit speed command at t = 0, from rest, for distinct real poles: the partial
    fractions of wn^2 (Tz s + 1) / (s^2 (s - p1)(s - p2)): t + Tz - 2 zeta / wn + sum a_i exp(p_i t),
    a_i = wn^2 (Tz p_i + 1) / (p_i^2 (p_i - p_j)); the speed is its derivative."""
    q = wn * math.sqrt(zeta * zeta - 1.0)
    p1, p2 = -zeta * wn + q, -zeta * wn - q
    a1 = wn * wn * (tz * p1 + 1.0) / (p1 * p1 * (p1 - p2))
    a2 = wn * wn * (tz * p2 + 1.0) / (p2 * p2 * (p2 - p1))
    z = t + tz - 2.0 * zeta / wn + a1 * np.exp(p1 * t) + a2 * np.exp(p2 * t)
    v = 1.0 + a1 * p1 * np.exp(p1 * t) + a2 * p2 * np.exp(p2 * t)
    return z, v


def test_default_vehicle_is_the_px4_speed_loop():
    c = EmulatorConfig()
    assert (c.vehicle, c.speed_wn, c.speed_zeta, c.speed_zero) == ("speed_loop", 1.53, 2.4, 3.9)
    assert c.wander_rms == 0.007 and c.wander_time == 2.0
    assert EmulatorConfig(vehicle="lag").wander_rms == 0.0 and EmulatorConfig(vehicle="lag", wander=0.01).wander_rms \
        == 0.01
    s = DroneEmulator(EmulatorConfig(**FREE)).summary()["vehicle"]
    assert s == {"kind": "speed_loop", "wander": 0.007, "wander_time": 2.0, "wn": 1.53, "zeta": 2.4, "zero": 3.9}
    assert DroneEmulator(EmulatorConfig(**FREE, vehicle="lag", lag=0.1)).summary()["vehicle"] == {
        "kind": "lag", "wander": 0.0, "wander_time": 2.0, "lag": 0.1}


@pytest.mark.parametrize("kw, error, message", [
    ({"vehicle": "px4"}, InvalidValueError, "vehicle must be one of lag, speed_loop, got 'px4'"),
    ({"vehicle": 3}, InvalidTypeError, "vehicle must be one of lag, speed_loop (text), got 3"),
    ({"speed_wn": 0.0}, InvalidValueError, r"speed_wn (rad/s) must be greater than 0, got 0"),
    ({"speed_wn": "fast"}, InvalidTypeError, r"speed_wn (rad/s) must be a real number"),
    ({"speed_zeta": -1.0}, InvalidValueError, "speed_zeta must be greater than 0, got -1"),
    ({"speed_zero": -0.5}, InvalidValueError, r"speed_zero (s) must be at least 0, got -0.5"),
    ({"speed_zero": float("nan")}, InvalidValueError, r"speed_zero (s) must be finite"),
    ({"wander": -0.01}, InvalidValueError, r"wander (m) must be at least 0, got -0.01"),
    ({"wander_time": 0.0}, InvalidValueError, r"wander_time (s) must be greater than 0, got 0"),
])
def test_bad_vehicle_settings_are_refused_naming_the_value(kw, error, message):
    with pytest.raises(error) as info:
        EmulatorConfig(**kw)
    assert message in str(info.value)


@pytest.mark.parametrize("wn, zeta, tz", [(1.53, 2.4, 3.9), (4.0, 0.35, 0.2), (2.0, 1.0, 0.0)])
def test_speed_loop_step_is_the_transfer_functions(wn, zeta, tz):
    # a speed command of gaz 0.25 (0.175 m/s) from a hover, taking effect 0.25 s after it arrives, then gaz -0.25
    # 2.5 s later: the altitude is wn^2 (Tz s + 1) / (s (s^2 + 2 zeta wn s + wn^2)) driven by that piecewise
    # constant speed command, from the command's effect on.  References: scipy.signal.lsim with a zero-order hold
    # on a grid holding both switches (all cases), and the partial fractions of the step (distinct real poles);
    # the emulator steps exactly (its closed-form step per interval, 2 ms or what is left), so to 1e-9.
    emu, enc = hovering(speed_wn=wn, speed_zeta=zeta, speed_zero=tz, wander=0.0)
    z_hover = state(emu, 1.5)[0]
    assert z_hover == 0.8
    u1 = 0.25 * VZ_MAX  # (gaz travels as a float32: 0.25 is exact)
    emu._handle(enc.pcmd(gaz=0.25), emu._t0 + 1.5)
    t = np.round(np.arange(0.0, 5.0 + 1e-9, 0.01), 10)  # since the first command took effect (1.75 s)
    got = []
    for x in t:
        if x == 2.25:  # (the physics only go forward: the second command is sent when its time, 4 s, comes)
            emu._handle(enc.pcmd(gaz=-0.25), emu._t0 + 4.0)
        got.append(state(emu, 1.75 + x))
    got = np.array(got)
    u = np.where(t < 2.5, u1, -u1)
    num = [wn * wn * tz, wn * wn] if tz else [wn * wn]
    plant = signal.lti(num, [1.0, 2.0 * zeta * wn, wn * wn, 0.0])
    _, z_ref, _ = signal.lsim(plant, u, t, interp=False)
    assert np.max(np.abs(got[:, 0] - z_hover - z_ref)) < 1e-9
    speed = signal.lti(num, [1.0, 2.0 * zeta * wn, wn * wn])
    _, v_ref, _ = signal.lsim(speed, u, t, interp=False)
    assert np.max(np.abs(got[:, 1] - v_ref)) < 1e-9  # the navdata speed is the speed loop's output
    assert abs(got[-1, 1]) > 1e-3  # (the speed really moved: not a trivially passing comparison)
    if zeta > 1.0:
        first = t < 2.5
        z_cf, v_cf = closed_form(t[first], wn, zeta, tz)
        assert np.max(np.abs(got[first, 0] - z_hover - u1 * z_cf)) < 1e-9
        assert np.max(np.abs(got[first, 1] - u1 * v_cf)) < 1e-9
    # and nothing moved before the command took effect
    emu2, enc2 = hovering(speed_wn=wn, speed_zeta=zeta, speed_zero=tz, wander=0.0)
    emu2._handle(enc2.pcmd(gaz=0.25), emu2._t0 + 1.5)
    assert state(emu2, 1.75) == (0.8, 0.0)


def test_speed_loop_has_unit_dc_gain_and_the_px4_overshoot():
    # the default loop (PX4: poles -0.33 and -7.1 rad/s, zero -0.26): the speed settles on the command (unit DC
    # gain: control_vz_max keeps its meaning) after overshooting it by about 24 % (the closed form's peak)
    emu, enc = hovering(wander=0.0)
    emu._handle(enc.pcmd(gaz=0.25), emu._t0 + 1.5)
    t = np.arange(0.0, 1.5, 0.005)
    v = np.array([state(emu, 1.75 + x)[1] for x in t])
    _, v_cf = closed_form(t, 1.53, 2.4, 3.9)
    assert abs(v.max() / (0.25 * VZ_MAX) - v_cf.max()) < 1e-9 and 1.2 < v_cf.max() < 1.3
    # 15 s on (a smaller command, to stay below the 3 m ceiling; the watchdog only runs with the threads)
    emu, enc = hovering(wander=0.0)
    emu._handle(enc.pcmd(gaz=0.125), emu._t0 + 1.5)
    v15 = state(emu, 16.75)[1] / (0.125 * VZ_MAX)
    assert abs(v15 - closed_form(np.array([15.0]), 1.53, 2.4, 3.9)[1][0]) < 1e-9
    assert abs(v15 - 1.0) < 0.003  # 15 s on, the slow mode (0.30 exp(-0.33 t)) is down to 0.2 %


def test_lag_vehicle_is_the_first_order_lag_without_wander():
    # vehicle="lag": the speed follows the command through exp(-t / T); the altitude is its integral,
    # u (t - T (1 - exp(-t / T))), exactly (the closed form), and the hover does not wander
    T = 0.15
    emu, enc = hovering(vehicle="lag", lag=T, seed=4)
    assert [state(emu, x)[0] for x in (1.5, 3.0, 9.0)] == [0.8, 0.8, 0.8]
    emu._handle(enc.pcmd(gaz=0.5), emu._t0 + 9.0)
    t = np.arange(0.0, 2.0, 0.01)
    got = np.array([state(emu, 9.25 + x) for x in t])
    u = 0.5 * VZ_MAX
    assert np.max(np.abs(got[:, 0] - 0.8 - u * (t - T * (1.0 - np.exp(-t / T))))) < 1e-9
    assert np.max(np.abs(got[:, 1] - u * (1.0 - np.exp(-t / T)))) < 1e-9


def test_hover_wander_has_the_ornstein_uhlenbeck_moments():
    # the hovering altitude minus 0.8 m is the wander alone (no command, the speed loop at rest).  Sampled every
    # h = 0.1 s, an OU process of RMS s and correlation time T is AR(1) with phi = exp(-h / T) and variance s^2.
    # (The emulator draws it on a 2 ms grid, exactly discretised, and advances its physics 2 ms at a time.)
    # Over n samples the sample variance has a standard error
    # s^2 sqrt(2 (1 + phi^2) / (n (1 - phi^2))), the lag-1 autocorrelation sqrt((1 - phi^2) / n) and the mean
    # s sqrt((1 + phi) / (n (1 - phi))) (large-sample formulas for AR(1)); each must be within 4 of them.
    s, T, h, n = 0.01, 0.5, 0.1, 6000
    emu, _ = hovering(wander=s, wander_time=T, seed=7)
    w = np.array([state(emu, 2.0 + h * k)[0] for k in range(n)]) - 0.8
    assert emu._phys.z == 0.8 and emu._phys.v == 0.0  # the vehicle itself stood still: it is all wander
    phi = math.exp(-h / T)
    var = np.mean((w - w.mean()) ** 2)
    r1 = np.sum((w[1:] - w.mean()) * (w[:-1] - w.mean())) / np.sum((w - w.mean()) ** 2)
    assert abs(var - s * s) < 4 * s * s * math.sqrt(2 * (1 + phi * phi) / (n * (1 - phi * phi))), var
    assert abs(r1 - phi) < 4 * math.sqrt((1 - phi * phi) / n), r1
    assert abs(w.mean()) < 4 * s * math.sqrt((1 + phi) / (n * (1 - phi))), w.mean()
    # the same seed gives the same wander, however the physics are stepped (it lives on its own 2 ms grid);
    # another seed another one
    again, _ = hovering(wander=s, wander_time=T, seed=7)
    for x in np.arange(1.4, 7.0, 0.0137):  # (steps that fall between the grid points)
        state(again, x)
    assert [state(again, 7.0 + h * k)[0] - 0.8 for k in range(50)] == list(w[50:100])
    other, _ = hovering(wander=s, wander_time=T, seed=8)
    assert state(other, 7.0)[0] - 0.8 != w[50]


def test_wander_is_on_the_altitude_only_while_flying():
    # landed: the altitude is 0; taking off: the climb is exact (0.7 m/s); hovering: 0.8 m plus the wander
    emu = DroneEmulator(EmulatorConfig(**FREE, seed=2, wander=0.05, noise=0.0))
    emu._phys.t = emu._t0
    assert state(emu, 1.0)[0] == 0.0
    emu._handle(ATEncoder().ref(takeoff=True), emu._t0 + 1.0)
    assert state(emu, 1.5)[0] == pytest.approx(0.35, abs=1e-9)
    z = state(emu, 3.0)[0]
    assert emu.mode == CtrlState.HOVERING and z != 0.8 and z == 0.8 + emu._phys.w


def test_emulate_command_sets_the_vehicle_and_refuses_a_bad_one():
    import json as _json

    from typer.testing import CliRunner

    from delaykit.cli import app

    ports = ["--at-port", "0", "--navdata-port", "0", "--video-port", "0", "--control-port", "0", "--duration", "0.2"]
    res = CliRunner().invoke(app, ["emulate", *ports, "--speed-zeta", "1.5", "--wander", "0.002"])
    assert res.exit_code == 0, res.output
    veh = _json.loads(res.stdout)["vehicle"]
    assert veh == {"kind": "speed_loop", "wander": 0.002, "wander_time": 2.0, "wn": 1.53, "zeta": 1.5, "zero": 3.9}
    res = CliRunner().invoke(app, ["emulate", *ports, "--vehicle", "lag", "--lag", "0.08"])
    assert res.exit_code == 0 and _json.loads(res.stdout)["vehicle"]["kind"] == "lag"
    res = CliRunner().invoke(app, ["emulate", *ports, "--vehicle", "bogus"])
    assert res.exit_code == 2 and "bogus" in res.output and "Traceback" not in res.output
