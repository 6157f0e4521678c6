"""simulate_many over a loop whose controller is a Compensator: each variant equals a single simulate run.

The reference is :func:`delaykit.simulate` of the loop built with the gain changed by hand (the compensator's
primary controller, or a predictor's own gains), one run per value.
"""

from __future__ import annotations

import numpy as np
import pytest

from delaykit import Compensator, InvalidValueError, Loop, simulate, simulate_many


def _single(loop: Loop, **gains: float):
    c = loop.controller
    c = c.replace(primary=c.primary.replace(**gains)) if c.primary is not None else c.replace(**gains)
    return simulate(loop.replace(controller=c), t_end=15.0).metrics


@pytest.mark.parametrize("loop, sweep", [
    (Loop("1/s", Compensator.smith("1/s", 0.5, closed_loop_time=0.2), delay=0.5, umin=-1.0, umax=1.0),
     {"kp": np.array([2.0, 3.5, 5.0])}),
    (Loop("2/(5*s+1)", Compensator.smith("2/(5*s+1)", 1.0, closed_loop_time=0.5), delay=1.0),
     {"kp": np.array([3.0, 5.0]), "ki": np.array([0.5, 1.0])}),
    (Loop("1/s", Compensator.predictor("1/s", 0.37, closed_loop_time=0.3), delay=0.37),
     {"kp": np.array([4.0, 6.0]), "ki": np.array([8.0, 11.0])}),
    (Loop("1/s", Compensator.filtered_smith("1/s", 0.4), delay=0.4, umin=-2.0, umax=2.0),
     {"kp": np.array([1.5, 2.5, 4.0])}),
    (Loop("2/(5*s+1)", Compensator.smith("2/(5*s+1)", 1.0, closed_loop_time=0.5), delay=1.0, period=0.1),
     {"kp": np.array([3.0, 5.0])}),
])
def test_simulate_many_of_a_compensator_equals_single_runs(loop, sweep):
    m = simulate_many(loop, **sweep)
    for i in range(len(next(iter(sweep.values())))):
        one = _single(loop, **{k: float(v[i]) for k, v in sweep.items()})
        assert abs(m.overshoot[i] - one.overshoot) < 1e-9
        assert abs(m.settling_time[i] - one.settling_time) < 1e-9
        assert abs(m.rise_time[i] - one.rise_time) < 1e-9
    assert np.all(np.diff(m.rise_time) != 0)  # the gains really changed the response


def test_simulate_many_of_a_compensator_refuses_a_gain_its_primary_lacks():
    loop = Loop("1/s", Compensator.smith("1/s", 0.5, closed_loop_time=0.2), delay=0.5)
    with pytest.raises(InvalidValueError, match="primary controller has no ki"):
        simulate_many(loop, ki=[1.0, 2.0])
    pred = Loop("1/s", Compensator.predictor("1/s", 0.37, closed_loop_time=0.3), delay=0.37)
    with pytest.raises(InvalidValueError, match="no kd"):
        simulate_many(pred, kd=[1.0])
