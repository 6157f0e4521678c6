"""Counting the zeros of an analytic function in a rectangle by the argument principle, written for the tests
(plain NumPy sampling of arg f along the boundary, refined until no step turns by more than 0.3 rad): a check
independent of delaykit's root finder."""

from __future__ import annotations

import math

import numpy as np


def zeros_in_box(f, x0: float, x1: float, y0: float, y1: float) -> int:
    """Zeros of an analytic f in the rectangle [x0, x1] x [y0, y1] (see the module docstring)."""
    corners = [complex(x0, y0), complex(x1, y0), complex(x1, y1), complex(x0, y1), complex(x0, y0)]
    total = 0.0
    for a, b in zip(corners[:-1], corners[1:]):
        t = np.linspace(0.0, 1.0, 4001)
        for _ in range(80):
            v = f(a + (b - a) * t)
            d = np.angle(v[1:] / v[:-1])
            coarse = np.abs(d) > 0.3
            if not coarse.any():
                break
            t = np.sort(np.concatenate([t, 0.5 * (t[:-1] + t[1:])[coarse]]))
        else:
            raise AssertionError("the contour passes through a zero")
        total += float(d.sum())
    n = total / (2 * math.pi)
    assert abs(n - round(n)) < 1e-6
    return round(n)
