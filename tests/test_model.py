"""The loop object: validation, its characteristic quasi-polynomial, and its printed form."""

from __future__ import annotations

import cmath
import math

import numpy as np
import pytest

from delaykit import AltitudeLoop, InvalidValueError, QuasiPolynomial


def test_characteristic_of_p_and_neutral_pv():
    q = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3).characteristic()
    assert q.kind == "neutral"
    s = 0.3 + 2.1j
    assert abs(q(s) - (s + (2.0 + 0.3 * s) * cmath.exp(-0.37 * s))) < 1e-12
    assert AltitudeLoop(kp=1.31, delay=0.368).characteristic().kind == "retarded"


def test_characteristic_of_filtered_pv_matches_the_block_diagram():
    # 1 + e^{-s Td} (Kp + Kv F(s)) / s = 0 with F = wf^2 s / (s^2 + 2 zf wf s + wf^2), times s D(s).
    kp, kv, td, wf, zf = 2.0, 0.3, 0.37, 38.0, 1.0
    q = AltitudeLoop(kp=kp, delay=td, kv=kv, velocity="filtered", filter_wn=wf, filter_zeta=zf).characteristic()
    assert q.kind == "retarded"
    for s in (1 + 1j, -0.5 + 7j, 3.0):
        d = s * s + 2 * zf * wf * s + wf * wf
        loop_gain = cmath.exp(-s * td) * (kp + kv * wf * wf * s / d) / s
        assert abs(q(s) / (s * d) - (1 + loop_gain)) < 1e-12


def test_no_delay_merges_terms():
    q = AltitudeLoop(kp=1.5, delay=0.0, kv=0.5).characteristic()
    assert q.delays == (0.0,) and np.allclose(q.polys[0], [1.5, 1.5])


def test_sampled_loop_has_no_quasi_polynomial():
    with pytest.raises(InvalidValueError, match="sampled"):
        AltitudeLoop(kp=1.0, delay=0.3, period=0.065).characteristic()


def test_quasi_polynomial_derivative_is_exact():
    q = QuasiPolynomial([[1, 0, 2], [0.5, 3]], [0.0, 0.4])
    dq = q.derivative()
    s, h = 0.7 + 1.3j, 1e-6
    assert abs(dq(s) - (q(s + h) - q(s - h)) / (2 * h)) < 1e-7


def test_quasi_polynomial_rejects_nonsense():
    with pytest.raises(InvalidValueError, match="zero"):
        QuasiPolynomial([[0, 0]], [0.0])
    with pytest.raises(InvalidValueError, match="finite"):
        QuasiPolynomial([[1, math.inf]], [0.0])
    with pytest.raises(InvalidValueError, match="delay of term 1"):
        QuasiPolynomial([[1, 0], [1]], [0.0, -1.0])
    with pytest.raises(InvalidValueError, match="one delay per polynomial"):
        QuasiPolynomial([[1, 0], [1]], [0.0])


def test_reprs_are_one_line_and_readable():
    loop = AltitudeLoop(kp=2.0, delay=0.37, kv=0.3, velocity="filtered", period=0.065)
    text = repr(loop)
    assert "\n" not in text and "kv=0.3" in text and "filtered velocity" in text and "0.065" in text
    assert loop.replace(kv=0.0).kv == 0.0
    assert loop.to_dict()["velocity"] == "filtered"


def test_characteristic_with_lag_and_gain():
    # s (T s + 1) + g (Kv s + Kp) e^{-s Td}, and with the filter s (T s + 1) D + g (Kp D + Kv wf^2 s) e^{-s Td}
    loop = AltitudeLoop(kp=1.5, delay=0.3, kv=0.2, lag=0.1, gain=0.8)
    q = loop.characteristic()
    assert q.kind == "retarded"
    s = 0.4 + 3j
    assert abs(q(s) - (s * (0.1 * s + 1) + 0.8 * (0.2 * s + 1.5) * cmath.exp(-0.3 * s))) < 1e-12
    qf = loop.replace(velocity="filtered").characteristic()
    d = s * s + 76 * s + 1444
    assert abs(qf(s) - (s * (0.1 * s + 1) * d + 0.8 * (1.5 * d + 0.2 * 1444 * s) * cmath.exp(-0.3 * s))) < 1e-9
