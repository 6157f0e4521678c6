"""The z-plane figure of a sampled loop (delaykit.plotting.figures.plot_z_spectrum) and `roots --period --plot`.

Reference: a closed form derived here, not delaykit's code.  P control of the integrator plant z' = u(t - d h),
sampled every h with a zero-order hold, the delay a whole number d of periods.  The command u_k = Kp (r - x_k)
is held on [k h, (k+1) h), so the plant integrates u_{k-d} over that period, with x_k = z(k h):

    x_{k+1} = x_k + h u_{k-d} = x_k - Kp h x_{k-d}    (r = 0)

and the trial solution x_k = z^k gives z^{d+1} = z^d - Kp h, i.e. the characteristic polynomial

    z^{d+1} - z^d + Kp h = 0,

whose roots numpy.roots computes.  Stability limits from it: d = 0, z = 1 - Kp h, stable for Kp h < 2;
d = 1, z^2 - z + Kp h, complex roots of modulus sqrt(Kp h) once Kp h > 1/4, stable for Kp h < 1.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")  # inside the tests only: the library itself never chooses a backend

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from scipy.optimize import linear_sum_assignment  # noqa: E402
from typer.testing import CliRunner  # noqa: E402

from delaykit import AltitudeLoop, InvalidTypeError  # noqa: E402
from delaykit.cli import app  # noqa: E402
from delaykit.plotting.figures import plot_z_spectrum  # noqa: E402
from delaykit.spectrum.sampled import sampled_spectrum  # noqa: E402

runner = CliRunner()


def _closed_form_roots(d: int, kp: float, h: float) -> np.ndarray:
    """The roots of z^{d+1} - z^d + Kp h (see the module docstring)."""
    coeffs = np.zeros(d + 2)
    coeffs[0] = 1.0
    coeffs[1] -= 1.0
    coeffs[-1] += kp * h
    return np.roots(coeffs)


def _loop(d: int, kp: float, h: float) -> AltitudeLoop:
    return AltitudeLoop(kp=kp, delay=d * h, period=h)


def _points(fig: Figure, label: str) -> np.ndarray:
    (line,) = [ln for ln in fig.axes[0].lines if ln.get_label() == label]
    return np.asarray(line.get_xdata(), float) + 1j * np.asarray(line.get_ydata(), float)


def _assert_same_set(got: np.ndarray, want: np.ndarray, tol: float) -> None:
    assert got.size == want.size
    cost = np.abs(got[:, None] - want[None, :])
    i, j = linear_sum_assignment(cost)
    assert cost[i, j].max() <= tol, (got, want)


@pytest.mark.parametrize("d, kp, h", [(0, 1.31, 0.065), (1, 5.0, 0.1), (3, 1.31, 0.065), (5, 2.0, 0.065),
                                      (2, 9.0, 0.1)])
def test_plotted_points_are_the_closed_form_roots(d, kp, h):
    want = _closed_form_roots(d, kp, h)
    fig = plot_z_spectrum(sampled_spectrum(_loop(d, kp, h)), label="poles")
    assert isinstance(fig, Figure)
    _assert_same_set(_points(fig, "poles"), want, 1e-9)
    # the circled poles are those of largest modulus, and the legend says that modulus
    radius = float(np.max(np.abs(want)))
    (ring,) = [ln for ln in fig.axes[0].lines if ln.get_label().startswith("|z| = ")]
    circled = np.asarray(ring.get_xdata(), float) + 1j * np.asarray(ring.get_ydata(), float)
    assert circled.size >= 1 and np.allclose(np.abs(circled), radius, rtol=1e-9, atol=0)
    assert ring.get_label() == f"|z| = {radius:.6g}"


def test_the_unit_circle_and_the_axes():
    fig = plot_z_spectrum(sampled_spectrum(_loop(1, 5.0, 0.1)))
    ax = fig.axes[0]
    circle = _points(fig, "unit circle")
    assert circle.size > 100 and np.allclose(np.abs(circle), 1.0, atol=1e-12)
    angles = np.angle(circle)
    assert np.isclose(angles.min(), -np.pi, atol=0.02) and np.isclose(angles.max(), np.pi, atol=0.02)
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("Re z", "Im z")
    assert ax.get_xlim()[0] < -1 < 1 < ax.get_xlim()[1] and ax.get_ylim()[0] < -1 < 1 < ax.get_ylim()[1]
    # the default legend entry counts the poles: z^2 - z + 0.5 has two
    assert len(_points(fig, "2 poles")) == 2


@pytest.mark.parametrize("d, kp_h, stable", [(1, 0.99, True), (1, 1.01, False), (0, 1.9, True), (0, 2.1, False)])
def test_the_title_gives_the_radius_and_says_unstable_beyond_the_limit(d, kp_h, stable):
    h = 0.1
    radius = float(np.max(np.abs(_closed_form_roots(d, kp_h / h, h))))
    # the closed forms of the limits: sqrt(Kp h) for d = 1 (complex pair), |1 - Kp h| for d = 0
    assert np.isclose(radius, np.sqrt(kp_h) if d == 1 else abs(1 - kp_h), rtol=1e-12)
    title = plot_z_spectrum(sampled_spectrum(_loop(d, kp_h / h, h))).axes[0].get_title()
    assert f"spectral radius {radius:.6f}" in title
    if stable:
        assert "< 1: stable" in title and "UNSTABLE" not in title
    else:
        assert ">= 1: UNSTABLE" in title


def test_a_given_title_comes_first():
    title = plot_z_spectrum(sampled_spectrum(_loop(1, 5.0, 0.1)), title="my loop").axes[0].get_title()
    assert title.splitlines() == ["my loop", "spectral radius 0.707107 < 1: stable (h = 0.1 s)"]


def test_draws_into_given_axes_and_writes_only_when_asked(tmp_path):
    sp = sampled_spectrum(_loop(3, 1.31, 0.065))
    own = Figure()
    ax = own.subplots()
    assert plot_z_spectrum(sp, ax=ax, label="p") is own
    assert len(own.axes) == 1 and len(_points(own, "p")) == sp.poles.size
    assert list(tmp_path.iterdir()) == []
    png = tmp_path / "sub" / "z.png"
    fig = plot_z_spectrum(sp, png)
    assert isinstance(fig, Figure) and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_refuses_what_is_not_a_sampled_spectrum():
    with pytest.raises(InvalidTypeError, match="SampledSpectrum"):
        plot_z_spectrum(_loop(1, 1.0, 0.1))


def test_exported_from_the_plotting_package():
    import delaykit.plotting as plotting

    assert plotting.plot_z_spectrum is plot_z_spectrum and "plot_z_spectrum" in plotting.__all__


# ---- the command line -----------------------------------------------------------------------------------------

def test_cli_roots_sampled_plot_writes_a_png(tmp_path):
    png = tmp_path / "z.png"
    res = runner.invoke(app, ["roots", "--kp", "1.31", "--delay", "0.195", "--period", "0.065", "--plot", str(png)])
    assert res.exit_code == 0, res.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000
    assert "stable" in res.stdout and "UNSTABLE" not in res.stdout


def test_cli_roots_sampled_plot_with_json_lists_the_closed_form_poles(tmp_path):
    import json

    png = tmp_path / "z.png"
    res = runner.invoke(app, ["roots", "--kp", "1.31", "--delay", "0.195", "--period", "0.065", "--plot", str(png),
                              "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    got = np.array([complex(re, im) for re, im in data["poles"]])
    _assert_same_set(got, _closed_form_roots(3, 1.31, 0.065), 1e-9)
    assert png.exists()


def test_cli_roots_sampled_plot_of_an_unstable_loop(tmp_path):
    png = tmp_path / "unstable.png"
    # d = 1, Kp h = 1.3 > 1: beyond the limit
    res = runner.invoke(app, ["roots", "--kp", "13", "--delay", "0.1", "--period", "0.1", "--plot", str(png)])
    assert res.exit_code == 0, res.output
    assert "UNSTABLE" in res.stdout and png.read_bytes()[:4] == b"\x89PNG"
