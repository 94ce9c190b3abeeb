import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tid_jax._orbit._sampled_peaks import newton_peak, stencil, top_peaks, true_peaks


def _oscillator(ratio, damping_ratio, scale=1.0):
    """|H| of a single-degree-of-freedom oscillator at the frequency ratios `ratio`; its
    maximum, 1 / (2 zeta sqrt(1 - zeta^2)) at sqrt(1 - 2 zeta^2), is exact theory."""
    r = ratio / scale
    return 1 / jnp.sqrt((1 - r**2) ** 2 + (2 * damping_ratio * r) ** 2)


def _located(response, grid, count):
    """`true_peaks` of `response` (a function of the frequencies) sampled on `grid`, its
    stencils' values from `response` too, in one compiled program (as the package's
    programs call it)."""
    return jax.jit(lambda g: true_peaks(response(g), g, lambda at, _: response(at),
                                        count))(grid)


@pytest.mark.parametrize("points, offset", [(11, 0.5), (21, 0.0), (21, 0.3), (61, 0.1)])
def test_true_peak_of_an_oscillator_wherever_the_grid_falls(points, offset):
    zeta = 0.1
    step = 0.75 / (points - 1)
    grid = jnp.linspace(0.65, 1.4, points) + offset * step
    index, peak, omega, valid = _located(lambda at: _oscillator(at, zeta), grid, 3)
    exact = 1 / (2 * zeta * np.sqrt(1 - zeta**2))
    assert bool(valid[0]) and 0 < int(index[0]) < points - 1
    assert float(peak[0]) == pytest.approx(exact, rel=1e-9)
    assert float(omega[0]) == pytest.approx(np.sqrt(1 - 2 * zeta**2), abs=1e-6)
    if points <= 21:  # the largest sample is far off on the coarse grids
        assert abs(float(jnp.max(_oscillator(grid, zeta))) / exact - 1) > 1e-4


def test_two_peaks_each_located():
    # Two resonances, the second higher: both are found, the higher first.
    def response(w):
        return _oscillator(w, 0.08, 0.9) + 1.2 * _oscillator(w, 0.06, 1.15)

    grid = jnp.linspace(0.6, 1.5, 31)
    index, peak, omega, valid = _located(response, grid, 2)
    fine = np.linspace(0.6, 1.5, 2_000_001)
    values = np.asarray(response(jnp.asarray(fine)))
    for i, (low, high) in enumerate([(1.0, 1.5), (0.6, 1.0)]):
        inside = (fine > low) & (fine < high)
        assert bool(valid[i])
        assert float(peak[i]) == pytest.approx(values[inside].max(), rel=1e-8)
        assert float(omega[i]) == pytest.approx(fine[inside][np.argmax(values[inside])],
                                                abs=1e-5)


def test_top_peaks_follow_the_highest_local_maxima():
    # Peaks at grid points 12 and 30 of 41, the second the higher, a lower one at 20 and
    # flat band ends (candidates too, but lower).
    omegas = jnp.linspace(20.0, 30.0, 41)
    i = np.arange(41)

    def tent(centre, height, width):
        return height * np.maximum(0, 1 - np.abs(i - centre) / width)

    values = jnp.asarray(1 + tent(12, 10, 4) + tent(30, 12, 4) + tent(20, 3, 2))
    located = jax.jit(top_peaks, static_argnums=2)
    index, _, valid = located(values, omegas, 3)
    assert np.asarray(index).tolist() == [30, 12, 20]
    assert np.all(np.asarray(valid))
    # Fewer local maxima than asked for: the band ends, then repeats marked invalid.
    index, _, valid = located(jnp.asarray(1 + tent(12, 10, 4)), omegas, 4)
    assert np.asarray(index)[:3].tolist() == [12, 0, 40]
    assert np.asarray(valid).tolist() == [True, True, True, False]


def test_band_end_and_failed_steady_states():
    # At a band end the peak is the end's value; a value that is not finite is passed on.
    centre = jnp.array([2.0, 3.0, 3.0])
    interior = jnp.array([False, True, True])
    at = jax.jit(stencil, static_argnames="points")(centre, interior, points=3)
    assert np.asarray(at[0]).tolist() == [2.0, 2.0, 2.0]
    values = jnp.array([[5.0, 5.0, 5.0], [1.0, jnp.inf, 1.0], [1.0, jnp.nan, 1.0]])
    peak, omega = jax.jit(newton_peak)(values, at, centre - 1, centre + 1, interior)
    assert float(peak[0]) == 5.0 and float(omega[0]) == 2.0
    assert np.isposinf(float(peak[1])) and np.isnan(float(peak[2]))
    assert np.asarray(omega[1:]).tolist() == [3.0, 3.0]
