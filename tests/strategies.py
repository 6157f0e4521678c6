"""Hypothesis strategies shared by the random-loop tests (the general simulator against the reference solver,
and the sampled batch against the Taylor kernel)."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st


@st.composite
def plant_denominators(draw):
    """A random plant of order 1 to 4: its order, its denominator (real poles in [-5, -0.3], the first at 0 half
    the time: integrating), and a gain that makes the DC gain 0.3 to 3 (or, integrating, the numerator 0.3 to 3)."""
    order = draw(st.integers(1, 4))
    poles = [-draw(st.floats(0.3, 5.0)) for _ in range(order)]
    if draw(st.booleans()):
        poles[0] = 0.0  # integrating
    den = np.real(np.poly(poles))
    gain = draw(st.floats(0.3, 3.0)) * den[-1] if den[-1] != 0 else draw(st.floats(0.3, 3.0))
    return order, den, gain
