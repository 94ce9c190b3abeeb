import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tid_jax as tj
from tests.lanes import peaks_of

NAMES = ("tid_stiffness", "tid_damping", "friction_force", "inertance", "host_damping",
         "amplitude")


@pytest.fixture(scope="module")
def model():
    """The paper's system with the friction smoothed at the relative width (exact friction:
    `test_coulomb`), a band, and the values of the parameters `NAMES` at a point away from
    the optimum (Den Hartog tuning, A = 300 N)."""
    system = tj.paper_system(friction_width=None)
    band = tj.default_omegas(system, 31)
    base = np.array([float(getattr(system, n)) for n in NAMES[:-1]] + [300.0])
    return system, band, base


def _tuned(system, values):
    """`system` with the parameters `NAMES` but the amplitude set to `values`, and the
    amplitude `values[-1]`."""
    return system.replace(**dict(zip(NAMES[:-1], values[:-1], strict=True))), values[-1]


def test_gradients_match_finite_differences(model):
    system, band, base = model

    # Peak host and inerter displacement (m) from one sweep of the band: their Jacobian
    # (forward mode), the host peak's gradient (reverse mode: the transpose of the same
    # linearisation, as `jax.grad` takes it) and the peaks, from one compiled program.
    def derivatives(values):
        value, tangent = jax.linearize(
            lambda v: tj.peak_response(_tuned(system, v)[0], band, _tuned(system, v)[1],
                                      response=("host", "inerter")),
            values)
        jacobian = jax.vmap(tangent, out_axes=-1)(jnp.eye(values.shape[0]))
        (gradient,) = jax.linear_transpose(tangent, values)(jnp.array([1.0, 0.0]))
        return jacobian, gradient, value

    forward, grad_host, value = (np.asarray(out) for out in jax.jit(derivatives)(base))
    np.testing.assert_allclose(grad_host, forward[0], rtol=1e-9)
    # The differences take their peaks from the batched solver (`tj.peaks`), at the base
    # and a step either side in each parameter, in one batch. A step of 1e-3: the
    # truncation error (~1e-6) stays below the tolerance, and so does the integration
    # noise of the peaks (~1e-9 relative) divided by the step.
    steps = 1e-3 * base
    points = [base] + [base + sign * step * np.eye(base.size)[i]
                       for i, step in enumerate(steps) for sign in (1, -1)]
    found = peaks_of([_tuned(system, point) for point in points], band)
    # The peaks of one sweep are the batched solver's, to its integration tolerance.
    np.testing.assert_allclose(value, found[0], rtol=1e-8)
    for i, name in enumerate(NAMES):
        fd = (found[1 + 2 * i] - found[2 + 2 * i]) / (2 * steps[i])
        # Relative 1e-4, or 1e-6 of an elasticity-one derivative where the derivative is tiny.
        floor = 1e-6 * value / base[i]
        np.testing.assert_array_less(np.abs(forward[:, i] - fd), 1e-4 * np.abs(fd) + floor,
                                     err_msg=name)
