"""Hypothesis strategies for random delay systems built the way users build them: delaykit's ``tf``, ``ss``,
``delay``, ``saturation``, ``feedback``, ``interconnect`` (1 to 3 inputs and outputs, 1 to 4 delays, stable and
integrating blocks, with and without saturations, a few neutral loops).  Used by tests/test_lti_oracle.py."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import strategies as st

from delaykit import delay, feedback, interconnect, saturation, ss, summing_junction, tf

__all__ = ["delay_free_systems", "edge_times", "linear_systems", "smooth_systems", "systems"]

# delays on a 0.005 grid: distinct draws are often commensurate (coinciding breakpoints), sometimes not
_delays = st.integers(20, 300).map(lambda k: round(k * 0.005, 3))
_gain = st.floats(0.3, 2.0).map(lambda g: round(g, 3))
_sign = st.sampled_from([1.0, -1.0])
_lag_time = st.floats(0.2, 3.0).map(lambda x: round(x, 3))


@st.composite
def _rational(draw, integrating=True, proper=True) -> str:
    """A SISO rational block as text: a lag, a second-order lag, a lead-lag (if ``proper``: a direct feedthrough),
    or (if ``integrating``) an integrator."""
    kinds = ["lag", "second"] + (["leadlag"] if proper else []) + (["integrator"] if integrating else [])
    kind = draw(st.sampled_from(kinds))
    K = draw(_sign) * draw(_gain)
    if kind == "lag":
        return f"{K}/({draw(_lag_time)}*s+1)"
    if kind == "second":
        wn, z = draw(st.floats(0.5, 3.0)), draw(st.floats(0.2, 1.2))
        return f"{K * wn * wn:.6g}/(s^2+{2 * z * wn:.6g}*s+{wn * wn:.6g})"
    if kind == "leadlag":
        return f"{K}*({draw(_lag_time)}*s+1)/({draw(_lag_time)}*s+1)"
    return f"{round(K / 2, 3)}/s"


def _with_delay(text: str, tau: float | None) -> str:
    return text if tau is None else f"({text})*exp(-{tau}*s)"


@st.composite
def _transfer_matrix(draw, nd: int, integrating: bool = True, proper: bool = True):
    """A p x m transfer matrix (1 to 3 each) with ``nd`` of its entries delayed (distinct draws)."""
    p, m = draw(st.integers(1, 3)), draw(st.integers(1, 3))
    nd = min(nd, p * m)
    cells = draw(st.permutations(list(itertools.product(range(p), range(m)))))[:nd]
    rows = [[draw(_rational(integrating, proper)) for _ in range(m)] for _ in range(p)]
    for (i, j) in cells:
        rows[i][j] = _with_delay(rows[i][j], draw(_delays))
    return tf(rows if (p, m) != (1, 1) else rows[0][0])


@st.composite
def _siso_loop(draw, nd: int, limited: bool, integrating: bool = True, proper: bool = True):
    """``feedback(C * [sat] * G, H)``: a P or PI controller, a plant with a delay, a delayed return path, an
    optional saturation between the controller and the plant; loop gains small enough to stay stable mostly."""
    plant = draw(_rational(integrating, proper))
    taus = [draw(_delays) for _ in range(nd)]
    G = tf(_with_delay(plant, taus[0]))
    kp = round(draw(st.floats(0.1, 0.6)), 3) * (1 if "-" not in plant.split("/")[0] else -1)
    ti = draw(st.one_of(st.none(), st.floats(1.0, 5.0)))
    C = tf(f"{kp}" if ti is None else f"{kp}*(1 + 1/({ti:.4g}*s))")
    H = tf("1")
    for tau in taus[1:]:
        H = H * delay(tau) if draw(st.booleans()) else H * tf(_with_delay(draw(_rational(False)), tau))
    if limited:
        L = round(draw(st.floats(0.2, 1.5)), 3)
        C = saturation(-L, draw(st.sampled_from([L, 2 * L]))) * C
    return feedback(C * G, H)


@st.composite
def _mimo_loop(draw, nd: int, limited: bool):
    """``feedback(G K, 1)`` for a square 2x2 (or 3x3) delayed plant under decentralised P gains."""
    n = draw(st.integers(2, 3))
    cells = draw(st.permutations(list(itertools.product(range(n), range(n)))))[:nd]
    # with saturations, strictly proper entries: no algebraic loop through the limits (the issue allows refusing
    # saturations in one algebraic loop with each other)
    rows = [[draw(_rational(False, proper=not limited)) for _ in range(n)] for _ in range(n)]
    for (i, j) in cells:
        rows[i][j] = _with_delay(rows[i][j], draw(_delays))
    G = tf(rows)
    K = tf([[round(draw(st.floats(0.05, 0.4)), 3) if i == j else 0 for j in range(n)] for i in range(n)])
    if limited:
        L = round(draw(st.floats(0.3, 1.5)), 3)
        sat = None
        for i in range(n):
            s = saturation(-L, L)
            sat = s if sat is None else _append(sat, s)
        K = sat * K
    return feedback(G * K, np.eye(n))


def _append(a, b):
    from delaykit import append

    return append(a, b)


@st.composite
def _cascade(draw, nd: int, limited: bool):
    """An inner PI speed loop inside an outer P loop, by signal names (as the guide's example), each delay drawn."""
    taus = [draw(_delays) for _ in range(max(nd, 1))] + [None] * 3
    lag = draw(_lag_time)
    blocks = [tf(f"1/({lag}*s+1)", inputs="a_tot", outputs="v", name="vehicle"),
              summing_junction(["a", "d"], "a_tot"),
              tf(f"{round(draw(st.floats(0.5, 2.0)), 3)}*(1 + 1/({round(draw(st.floats(0.5, 2.0)), 3)}*s))",
                 inputs="ev", outputs="a_req", name="speed PI"),
              tf("1/s", inputs="v", outputs="z", name="altitude"),
              summing_junction(["v_ref", "-v"], "ev"),
              delay(taus[0], inputs="a_sat" if limited else "a_req", outputs="a", name="actuation delay"),
              (delay(taus[1], inputs="z", outputs="zm", name="measurement delay") if taus[1] is not None
               else ss([], [], [], [[1.0]], inputs="z", outputs="zm")),
              tf(f"{round(draw(st.floats(0.2, 1.0)), 3)}", inputs="ez", outputs="v_cmd"),
              summing_junction(["z_ref", "-zm"], "ez"),
              (delay(taus[2], inputs="v_cmd", outputs="v_ref", name="command delay") if taus[2] is not None
               else ss([], [], [], [[1.0]], inputs="v_cmd", outputs="v_ref"))]
    if limited:
        L = round(draw(st.floats(0.3, 2.0)), 3)
        blocks.append(saturation(-L, L, inputs="a_req", outputs="a_sat", name="limits"))
    outputs = draw(st.sampled_from([["z"], ["z", "v"], ["zm", "v", "a"]]))
    inputs = draw(st.sampled_from([["z_ref", "d"], ["d", "z_ref"]]))
    return interconnect(blocks, inputs=inputs, outputs=outputs)


@st.composite
def _neutral_loop(draw):
    """``feedback(G + a exp(-tau s), 1)``: a delayed direct path inside a loop (neutral), with a delayed lag
    ``G = K exp(-theta s)/(T s + 1)`` and ``|K| + |a| < 1``: a loop gain below 1 at every frequency, so stable
    (small gain) with a strongly stable difference operator.  Delays of at least 0.3 keep the oracle quick."""
    a = round(draw(st.floats(-0.6, 0.6)), 3)
    K = round(draw(st.floats(0.05, 0.95 - abs(a))) * draw(_sign), 3)
    slow = st.integers(60, 300).map(lambda k: round(k * 0.005, 3))
    G = tf(f"{K}*exp(-{draw(slow)}*s)/({draw(_lag_time)}*s+1)")
    return feedback(G + tf(f"{a}*exp(-{draw(slow)}*s)"), 1)


@st.composite
def systems(draw, limited: bool | None = None, neutral: bool = True):
    """A random DelayLTI with 1 to 4 delays (saturated or not, as ``limited``; either when None)."""
    if limited is None:
        limited = draw(st.booleans())
    nd = draw(st.integers(1, 4))
    kinds = ["loop", "mimo", "cascade"] + ([] if limited else ["matrix"]) + (["neutral"] if neutral and not limited
                                                                            else [])
    kind = draw(st.sampled_from(kinds))
    if kind == "matrix":
        return draw(_transfer_matrix(nd))
    if kind == "loop":
        return draw(_siso_loop(nd, limited))
    if kind == "mimo":
        return draw(_mimo_loop(nd, limited))
    if kind == "cascade":
        return draw(_cascade(nd, limited))
    return draw(_neutral_loop())


@st.composite
def smooth_systems(draw):
    """Linear retarded systems whose step responses are continuous (strictly proper plants and return paths, a
    P or PI controller, no saturation): where a Padé approximation's error dies out away from the delays' edges."""
    nd = draw(st.integers(1, 3))
    if draw(st.booleans()):
        return draw(_transfer_matrix(nd, proper=False))
    plant = draw(_rational(True, False))
    taus = [draw(_delays) for _ in range(nd)]
    kp = round(draw(st.floats(0.1, 0.6)), 3) * (1 if "-" not in plant.split("/")[0] else -1)
    C = tf(f"{kp}*(1 + 1/(2*s))") if draw(st.booleans()) else tf(f"{kp}")
    H = tf("1")
    for tau in taus[1:]:
        H = H * tf(_with_delay(draw(_rational(False, False)), tau))
    return feedback(C * tf(_with_delay(plant, taus[0])), H)


def linear_systems(neutral: bool = False):
    """Random systems without saturations."""
    return systems(limited=False, neutral=neutral)


@st.composite
def delay_free_systems(draw):
    """Random interconnections without any delay (python-control's ground), 1 to 3 inputs and outputs."""
    kind = draw(st.sampled_from(["matrix", "loop", "mimo"]))
    if kind == "matrix":
        p, m = draw(st.integers(1, 3)), draw(st.integers(1, 3))
        rows = [[draw(_rational()) for _ in range(m)] for _ in range(p)]
        return tf(rows if (p, m) != (1, 1) else rows[0][0])
    if kind == "loop":
        G, C = tf(draw(_rational())), tf(f"{round(draw(st.floats(0.1, 0.8)), 3)}*(1 + 1/(2*s))")
        return feedback(C * G, tf(draw(_rational(False))))
    n = draw(st.integers(2, 3))
    G = tf([[draw(_rational(False)) for _ in range(n)] for _ in range(n)])
    return feedback(G, 0.3 * np.eye(n))


def edge_times(sys, t_end: float, depth: int = 3) -> np.ndarray:
    """Every sum of at most ``depth`` of the system's positive delays (with repetition) up to ``t_end``: where a
    step's discontinuities reach by then (the low-order ones)."""
    taus = sorted({t for t in sys.delays if t > 0})
    out = {0.0}
    for k in range(1, depth + 1):
        for combo in itertools.combinations_with_replacement(taus, k):
            s = sum(combo)
            if s <= t_end:
                out.add(s)
    return np.array(sorted(out))
