"""A system as a Loop's plant: plant_of (exp(-s T) G(s) recovered from any realisation) and to_loop.

References: the transfer functions the systems were built from (closed forms), the systems' own exact
frequency responses, and delaykit's Loop kernel (`simulate`) against the general delay-system kernel
(`DelayLTI.step`): two independent implementations of the method of steps.
"""

import numpy as np
import pytest

from delaykit import (Controller, InvalidTypeError, InvalidValueError, Loop, delay, feedback,
                      from_loop, plant_of, saturation, simulate, tf, to_loop)
from delaykit.models import TransferFunction


def _same_tf(g, num, den):
    ref = TransferFunction(num, den)
    np.testing.assert_allclose(g.num, ref.num, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(g.den, ref.den, rtol=1e-12, atol=1e-14)


def test_text_with_dead_time_factors():
    # reference: the text itself, 2/(s + 1) with 0.5 s of dead time
    g, T = plant_of(tf("2*exp(-0.5*s)/(s+1)"))
    _same_tf(g, [2.0], [1.0, 1.0])
    assert T == pytest.approx(0.5, abs=1e-15)


def test_delays_spread_through_a_cascade_factor():
    # internal delays in series (states between them): exp(-s) 1/(s+1) then exp(-2 s) (s+3)/(s+2), and delays
    # at both ends; reference: the product written by hand, (s+3) / ((s+1)(s+2)) with 3.35 s in all
    sys = delay(0.1) * tf("exp(-2*s)*(s+3)/(s+2)") * tf("exp(-s)/(s+1)") * delay(0.25)
    g, T = plant_of(sys)
    _same_tf(g, [1.0, 3.0], np.polymul([1.0, 1.0], [1.0, 2.0]))
    assert T == pytest.approx(3.35, abs=1e-12)


def test_parallel_paths_with_equal_delays_factor():
    # two paths with the same dead time: exp(-s) (1/(s+1) + 2/(s+2)) = exp(-s) (3 s + 4) / ((s+1)(s+2))
    g, T = plant_of(tf("exp(-s)/(s+1)") + tf("2*exp(-s)/(s+2)"))
    _same_tf(g, [3.0, 4.0], [1.0, 3.0, 2.0])
    assert T == pytest.approx(1.0, abs=1e-14)


def test_frequency_response_of_the_factors_equals_the_system():
    # a 3-state interconnection with an internal delay between two blocks and one at the output;
    # reference: the system's own exact frequency response
    sys = delay(0.3) * tf("(0.5*s+1)/(s^2+0.4*s+1)") * delay(0.7) * tf("4/(2*s+1)")
    g, T = plant_of(sys)
    w = np.linspace(0.0, 20.0, 81)
    np.testing.assert_allclose(g(1j * w) * np.exp(-1j * w * T), sys.frequency_response(w).response[0, 0],
                               rtol=1e-11, atol=1e-13)


def test_pure_delay_and_static_gain():
    g, T = plant_of(delay(0.4) * 3.0)
    _same_tf(g, [3.0], [1.0])
    assert T == pytest.approx(0.4)
    g, T = plant_of(tf("0"))
    assert not g.num.any() and T == 0.0


@pytest.mark.parametrize("loop", [
    Loop("1/s", Controller.p(1.31), delay=0.368, umin=-1, umax=1),
    Loop("0.62/(150*s+1)", Controller.pi(2.0, 0.02), delay=12.0, output_delay=3.0, umin=-50, umax=50),
    Loop("1/(s*(0.05*s+1))", Controller.pid(2.0, 0.5, 0.1, 0.02), delay=0.3, output_delay=0.1),
])
def test_round_trip_through_a_system(loop):
    # Loop -> its plant as a system (the dead time around the loop) -> to_loop -> the same Loop; and the closed
    # loops of both, made by from_loop, agree in frequency (reference: the original loop's from_loop)
    sys = tf((loop.plant.num, loop.plant.den, loop.total_delay))
    back = to_loop(sys, loop.controller, output_delay=loop.output_delay, umin=loop.umin, umax=loop.umax)
    _same_tf(back.plant, loop.plant.num, loop.plant.den)
    assert back.delay == pytest.approx(loop.delay, abs=1e-12)
    assert back.output_delay == pytest.approx(loop.output_delay, abs=1e-12)
    assert (back.umin, back.umax, back.controller) == (loop.umin, loop.umax, loop.controller)
    w = np.linspace(0.0, 5.0, 41)
    np.testing.assert_allclose(from_loop(back, ignore_limits=True).frequency_response(w).response,
                               from_loop(loop, ignore_limits=True).frequency_response(w).response,
                               rtol=1e-10, atol=1e-12)
    # with the limits as a saturation at the plant system's input, in time (both loops' from_loop systems, limits
    # acting): the same responses to r and d
    sat = tf("1") if not loop.saturated else saturation(loop.umin, loop.umax)
    back2 = to_loop(sys * sat, loop.controller, output_delay=loop.output_delay)
    assert (back2.umin, back2.umax) == (loop.umin, loop.umax)
    t = np.linspace(0.0, 5 * (1 + loop.total_delay), 101)
    np.testing.assert_allclose(from_loop(back2).step(t).outputs, from_loop(loop).step(t).outputs, rtol=0,
                               atol=1e-10)
    # and the other way: the plant system made again from the loop has the original's frequency response
    again = tf((back.plant.num, back.plant.den, back.total_delay))
    np.testing.assert_allclose(again.frequency_response(w).response, sys.frequency_response(w).response,
                               rtol=1e-12, atol=1e-14)


def test_plant_of_a_loops_own_plant_block():
    # from_loop's system, opened: the path from the load disturbance d to y with the controller removed is
    # the plant; built here as the same blocks by algebra, the plant_of it returns the Loop's plant
    loop = Loop("2/(s^2+3*s+2)", Controller.p(1.0), delay=0.2, output_delay=0.05)
    sys = delay(loop.output_delay) * tf((loop.plant.num, loop.plant.den)) * delay(loop.delay)
    g, T = plant_of(sys)
    _same_tf(g, loop.plant.num, loop.plant.den)
    assert T == pytest.approx(loop.total_delay)


@pytest.mark.parametrize("sat", [False, True])
def test_loop_simulated_equals_the_systems_closed_loop_step(sat):
    # the paper's P loop: the Loop made by to_loop simulated by the Loop kernel equals the closed loop built by
    # algebra and stepped by the delay-system kernel, to 1e-9 (independent implementations)
    plant = tf("exp(-0.368*s)/s")
    lim = dict(umin=-1.0, umax=1.0) if sat else {}
    loop = to_loop(plant, Controller.p(1.31), **lim)
    ref = simulate(loop, t_end=12.0)
    K = (saturation(-1.0, 1.0) if sat else tf("1")) * 1.31
    t = np.linspace(0.0, 12.0, 241)
    r = feedback(plant * K, 1).step(t)
    assert r.status == "exact"
    np.testing.assert_allclose(r.outputs[0, 0], ref.output(t), rtol=0, atol=1e-9)


def test_pi_loop_with_internal_delays_simulated_equals_system_step():
    # a plant with its dead time split inside the realisation; PI control; references as above
    plant = delay(0.2) * tf("1/(2*s+1)") * delay(0.3) * tf("1/(0.5*s+1)")
    loop = to_loop(plant, Controller.pi(1.2, 0.6))
    assert loop.delay == pytest.approx(0.5)
    ref = simulate(loop, t_end=15.0)
    t = np.linspace(0.0, 15.0, 151)
    r = feedback(plant * tf("1.2 + 0.6/s"), 1).step(t)
    np.testing.assert_allclose(r.outputs[0, 0], ref.output(t), rtol=0, atol=1e-9)


@pytest.mark.parametrize("sys, words", [
    (feedback(tf("exp(-s)/(s+1)"), 1), "delay inside a loop"),
    (tf("1/(s+1)") + tf("exp(-s)/(s+1)"), "different delays [0, 1]"),
    (tf("2/(1 + 2/(s+1)*(1 - exp(-0.37*s)))"), "delay inside a loop"),
    (tf([["1/(s+1)", "exp(-s)"]]), "2 inputs"),
    (saturation(-1, 1) * tf("1/s"), "saturates"),           # at the output: not a loop's actuator
])
def test_refusals_say_why(sys, words):
    with pytest.raises(InvalidValueError) as err:
        plant_of(sys)
    assert words in str(err.value)
    with pytest.raises(InvalidValueError):
        to_loop(sys, Controller.p(1.0))


def test_bad_arguments():
    with pytest.raises(InvalidTypeError, match="DelayLTI"):
        plant_of("1/(s+1)")
    with pytest.raises(InvalidValueError, match="output_delay 2 s is more than the plant's dead time 1 s"):
        to_loop(tf("exp(-s)/(s+1)"), output_delay=2.0)
    with pytest.raises(InvalidValueError, match="output_delay"):
        to_loop(tf("exp(-s)/(s+1)"), output_delay=float("nan"))


def test_a_saturation_at_the_input_becomes_the_loops_limits():
    # G exp(-sT) sat(u): the Loop's actuator limits; the Loop kernel (simulate) equals the delay-system kernel's
    # closed loop of the same system (independent implementations) to 1e-9
    plant = tf("exp(-0.368*s)/s") * saturation(-1.0, 1.0)
    loop = to_loop(plant, Controller.p(1.31))
    assert (loop.umin, loop.umax, loop.delay) == (-1.0, 1.0, pytest.approx(0.368))
    t = np.linspace(0.0, 12.0, 121)
    r = feedback(plant * 1.31, 1).step(t)
    np.testing.assert_allclose(r.outputs[0, 0], simulate(loop, t_end=12.0).output(t), rtol=0, atol=1e-9)
    one_sided = to_loop(tf("2/(s+1)") * delay(0.1) * saturation(None, 0.5))
    assert (one_sided.umin, one_sided.umax) == (-np.inf, 0.5)
    with pytest.raises(InvalidValueError, match="not both"):
        to_loop(plant, umin=-2.0, umax=2.0)
    with pytest.raises(InvalidValueError, match="saturates"):           # a second saturation, inside
        to_loop(saturation(-1, 1) * tf("1/s") * saturation(-1, 1))
