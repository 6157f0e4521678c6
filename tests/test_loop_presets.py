"""Loops as presets of systems (issue 32): ``Loop.system`` and the system-level functions taking a loop.

References: the same functions called on ``from_loop(loop)`` built by hand, and the loop's own Taylor simulation
(``simulate``, a different kernel: delaykit.simulate.simulation) for the step responses.
"""

from __future__ import annotations

import numpy as np
import pytest

import delaykit as dk
from delaykit import AltitudeLoop, Controller, Loop, from_loop

LOOPS = [
    Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2),
    Loop("0.62/(150*s+1)", Controller.pi(6.0, 0.05), delay=12.0, output_delay=3.0),
    AltitudeLoop(kp=1.31, delay=0.368, vmax=None),
]


def test_the_system_is_from_loop_and_cached():
    for loop in LOOPS:
        T = loop.system
        assert T is loop.system
        ref = from_loop(loop)
        w = np.geomspace(1e-3, 30, 25)
        assert np.array_equal(T.frequency_response(w).response, ref.frequency_response(w).response)
    with pytest.raises(dk.InvalidValueError, match="samples its controller"):
        Loop("1/s", Controller.p(1.0), delay=0.1, period=0.05).system


@pytest.mark.parametrize("loop", LOOPS, ids=["pid", "pi", "altitude"])
def test_system_functions_take_a_loop(loop):
    ref = from_loop(loop)
    region = (-3.0, 1.0, 0.0, 6.0)
    a, b = dk.poles(loop, region), dk.poles(ref, region)
    assert a.certified and np.array_equal(a.roots, b.roots)
    assert dk.is_stable(loop) == dk.is_stable(ref) == dk.margins(loop).stable
    assert dk.hinfnorm(loop).value == dk.hinfnorm(ref).value


@pytest.mark.parametrize("loop", LOOPS, ids=["pid", "pi", "altitude"])
def test_step_response_of_a_loop_is_its_simulation(loop):
    # two kernels: the system's LFT Taylor kernel and the loop's own (simulate); no limits, so both are linear
    t_end = 40.0 if loop is LOOPS[1] else 8.0
    sim = dk.simulate(loop, step=1.0, t_end=t_end)
    t = np.linspace(0.0, t_end, 161)
    r = dk.step_response(loop, t)
    assert r.status == "exact" and r.outputs.shape == (2, 2, t.size)
    assert np.max(np.abs(r.outputs[0, 0] - sim.output(t))) < 1e-9
    assert np.max(np.abs(r.outputs[1, 0] - sim.command(t))) < 1e-9 * max(1.0, float(np.abs(sim.command(t)).max()))
    # forced: the reference as an input signal (a step held from 0), the disturbance 0
    f = dk.forced_response(loop, t, np.vstack([np.ones(t.size), np.zeros(t.size)]))
    assert np.max(np.abs(f.outputs[0] - sim.output(t))) < 1e-9


def test_something_else_is_refused_naming_loops_and_systems():
    with pytest.raises(dk.InvalidTypeError, match="DelayLTI .*or a Loop"):
        dk.step_response("1/(s+1)")
    with pytest.raises(dk.InvalidTypeError, match="DelayLTI .*or a Loop"):
        dk.is_stable(3.0)
