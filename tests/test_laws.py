"""The flight law (delaykit.hardware.laws.FlightLaw): any controller run on packets at uneven times.

The reference is an independent integration of the same definition (the realisation's differential equation, the
newest packet's values held over the interval it ends, the commands from the history, back-calculation after a
saturated command) with scipy's DOP853 at tight tolerances, cut at every command change, instead of the law's
matrix exponentials.  It is used by test_flight.py too, on logs of loopback flights."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from delaykit import InvalidTypeError, InvalidValueError
from delaykit.hardware.laws import FlightLaw
from delaykit.models import Compensator, Controller


def replay(controller, t, r, y, vm, umin=-1.0, umax=1.0):
    """The commands the law must send at packets (t, r, y, vm): DOP853 on the realisation (see the module)."""
    R = controller.realisation()
    n = R.order
    d = np.array([R.dvr, R.dvy, R.dvv])
    Bs = [np.zeros(n) if b is None else np.asarray(b, float) for b in (R.Bcr, R.Bcy, R.Bcv, R.Bcu, R.Bcm)]
    tm = R.model_delay
    aw = controller.antiwindup if controller.has_integrator else "none"
    hist_t, hist_u = [], []

    def u_at(s):
        k = np.searchsorted(hist_t, s, side="right") - 1
        return hist_u[k] if k >= 0 else 0.0

    out = []
    x = None
    for k in range(len(t)):
        w = np.array([r[k], y[k], vm[k]])
        if k == 0:
            if n:
                rhs = -(np.column_stack(Bs[:3]) @ w)
                x, *_ = np.linalg.lstsq(R.Ac, rhs, rcond=None)
                if R.integ >= 0:
                    x[R.integ] = 0.0
            else:
                x = np.zeros(0)
        elif n:
            sat = out[-1][0] != out[-1][1]
            cuts = sorted({t[k - 1], t[k], *[h + tm for h in hist_t if tm > 0 and t[k - 1] < h + tm < t[k]]})
            for a, b in zip(cuts[:-1], cuts[1:]):
                m = 0.5 * (a + b)
                uu, um = u_at(m), (u_at(m - tm) if tm > 0 else 0.0)

                def f(_s, xx, uu=uu, um=um, w=w, sat=sat):
                    dx = R.Ac @ xx + sum(B * v for B, v in zip(Bs, (*w, uu, um)))
                    if sat and aw == "backcalc":
                        dx = dx + np.asarray(R.Baw) * (uu - (R.Cc @ xx + d @ w))
                    return dx

                x = solve_ivp(f, (a, b), x, method="DOP853", rtol=1e-12, atol=1e-13).y[:, -1]
        v = (float(np.asarray(R.Cc) @ x) if n else 0.0) + float(d @ w)
        u = min(max(v, umin), umax)
        out.append((u, v))
        hist_t.append(t[k])
        hist_u.append(u)
    return np.array([o[0] for o in out])


def _packets(seed, n=120, step=1.0):
    """Packets of a plausible flight: 15 Hz with up to 12 ms jitter, an altitude that moves towards the step."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(1 / 15 + rng.uniform(0.0, 0.012, n))
    y = 0.8 + step * (1 - np.exp(-np.maximum(t - t[0] - 0.4, 0) / 0.8)) + rng.normal(0, 0.004, n)
    vm = np.gradient(y, t) + rng.normal(0, 0.02, n)
    r = np.full(n, 0.8 + step)
    return t, r, y, vm


LAWS = {
    "p": Controller.p(1.31),
    "pv-true": Controller.pv(2.0, 0.3),
    "pv-filtered": Controller.pv(2.0, 0.3, velocity="filtered"),
    "pi-backcalc": Controller.pi(1.2, 0.6, antiwindup="backcalc"),
    "pid": Controller.pid(1.0, 0.3, 0.1, derivative_filter=0.05),
    "smith": Compensator.smith("1/s", 0.3, closed_loop_time=0.075),
    "filtered-smith": Compensator.filtered_smith("1/s", 0.3, closed_loop_time=0.06, filter_time=0.3),
    "predictor": Compensator.predictor("1/s", 0.3, closed_loop_time=0.1),
    "smith-lag": Compensator.smith("1/(0.5*s+1)", 0.3, closed_loop_time=0.2),
}


@pytest.mark.parametrize("name", sorted(LAWS))
def test_the_law_sends_what_an_independent_integration_of_its_equations_gives(name):
    c = LAWS[name]
    t, r, y, vm = _packets(3)
    law = FlightLaw(c, umin=-1.0, umax=1.0)
    got = np.array([law.update(tk, r=rk, y=yk, vm=vk) for tk, rk, yk, vk in zip(t, r, y, vm)])
    ref = replay(c, t, r, y, vm)
    assert np.max(np.abs(got - ref)) < 1e-8
    # the cases exercise the limits (else the comparison would be too easy) and, but for the PI primary of the
    # lag model (its integral winds up: these packets do not answer its commands), the linear range
    assert np.any(np.abs(got) == 1.0) and (name == "smith-lag" or np.any(np.abs(got) < 1.0))


def test_the_papers_laws_are_their_formulas():
    law = FlightLaw(Controller.pv(2.0, 0.3), umin=-1.0, umax=1.0)
    assert law.update(0.0, r=1.2, y=1.0, vm=0.1) == pytest.approx(2.0 * 0.2 - 0.3 * 0.1, abs=1e-15)
    assert law.update(0.07, r=2.0, y=1.0, vm=0.0) == 1.0  # saturated
    law = FlightLaw(Controller.p(1.31), umin=-0.5, umax=3.0)
    assert law.update(0.0, r=0.0, y=1.0) == -0.5 and law.update(0.1, r=2.0, y=1.0) == pytest.approx(1.31)


def test_a_smith_predictor_with_a_perfect_model_predicts_the_delay_away():
    # the plant z' = u(t - Tm) simulated exactly at packets every dt (Tm = n dt), the command held between them: the
    # Smith predictor's feedback is z(t) + int_{t-Tm}^t u = z(t + Tm) exactly, so its P law sends
    # u_k = kp (r - z_{k+n}) and the output is the delay-free sampled P loop w_{j+1} = w_j + dt kp (r - w_j) delayed
    # by n packets: z_{j+n} = w_j (a closed form of the discrete recursion, independent of the law's exponentials)
    tm, kp, dt, n = 0.3, 1.0, 0.01, 30
    law = FlightLaw(Compensator.smith("1/s", tm, closed_loop_time=1.0 / kp), umin=-1.0, umax=1.0)
    z, us, zs = 0.0, [], []
    for k in range(600):
        zs.append(z)
        us.append(law.update(k * dt, r=0.5, y=z))
        z += dt * (us[k - n] if k >= n else 0.0)
    w = 0.5 * (1.0 - (1.0 - dt * kp) ** np.arange(600 - n))  # w_j in closed form, w_0 = 0
    assert np.max(np.abs(np.array(zs[n:]) - w)) < 1e-9
    assert max(abs(u) for u in us) < 1.0  # (kp 1 on a 0.5 m step: never saturated, so the law is linear)


def test_commands_recorded_between_packets_and_replayed_commands_enter_the_model():
    c = LAWS["smith"]
    a, b, plain = (FlightLaw(c, umin=-1, umax=1) for _ in range(3))
    t, r, y, vm = _packets(5, n=40)
    for k in range(20):
        u = a.update(t[k], r=r[k], y=y[k], vm=vm[k])
        b.update(t[k], r=r[k], y=y[k], vm=vm[k], sent=u)  # a replay of what was sent: the same states
        plain.update(t[k], r=r[k], y=y[k], vm=vm[k])
    a.record(t[19] + 0.01, 0.0)  # a hover sent between two packets
    b.record(t[19] + 0.01, 0.0)
    ua, ub, up = (law.update(t[20], r=r[20], y=y[20], vm=vm[20]) for law in (a, b, plain))
    assert ua == pytest.approx(ub, abs=1e-12)
    assert abs(ua - up) > 1e-4  # the hover is in the model: without it the command differs


def test_bad_input_is_named():
    with pytest.raises(InvalidTypeError, match="Controller or a Compensator, got str"):
        FlightLaw("1/s", umin=-1, umax=1)
    with pytest.raises(InvalidValueError, match="umin must be below umax, got 1 and -1"):
        FlightLaw(Controller.p(1.0), umin=1, umax=-1)
    law = FlightLaw(Controller.p(1.0), umin=-1, umax=1)
    law.update(1.0, r=0.0, y=0.0)
    with pytest.raises(InvalidValueError, match="must not go back: 0.5 after 1.0"):
        law.update(0.5, r=0.0, y=0.0)
    with pytest.raises(InvalidValueError, match="y must be finite, got nan"):
        law.update(2.0, r=0.0, y=float("nan"))
