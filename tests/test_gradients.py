import jax
import jax.numpy as jnp
import numpy as np
import pytest

import tid_jax as tj

NAMES = ("tid_stiffness", "tid_damping", "friction_force", "inertance", "host_damping",
         "amplitude")


@pytest.fixture(scope="module")
def peaks():
    """Peak host and inerter displacement (m) as a function of the parameters `NAMES`, at a
    point away from the optimum (Den Hartog tuning, A = 300 N)."""
    system = tj.paper_system(friction_width=None)  # the relative width (exact: test_coulomb)
    band = tj.default_omegas(system, 31)
    base = jnp.array([float(getattr(system, n)) for n in NAMES[:-1]] + [300.0])

    def fn(values, responses=("host", "inerter")):
        tuned = system.replace(**dict(zip(NAMES[:-1], values[:-1])))
        return jnp.stack([tj.peak_response(tuned, values[-1], band, response=response)
                          for response in responses])

    return base, fn


def test_gradients_match_finite_differences(peaks):
    base, fn = peaks

    # The Jacobian (forward mode), the host peak's gradient (reverse mode: the transpose
    # of the same linearisation, as `jax.grad` takes it) and the peaks, from one compiled
    # program: the differences below take their peaks from it too.
    def derivatives(values):
        value, tangent = jax.linearize(fn, values)
        jacobian = jax.vmap(tangent, out_axes=-1)(jnp.eye(values.shape[0]))
        (gradient,) = jax.linear_transpose(tangent, values)(jnp.array([1.0, 0.0]))
        return jacobian, gradient, value

    derivatives = jax.jit(derivatives)
    forward, grad_host, value = (np.asarray(out) for out in derivatives(base))
    np.testing.assert_allclose(grad_host, forward[0], rtol=1e-9)
    for i, name in enumerate(NAMES):
        # A step of 1e-3: the truncation error (~1e-6) stays below the tolerance, and so
        # does the integration noise of the peaks (~1e-9 relative) divided by the step.
        h = 1e-3 * float(base[i])
        fd = (np.asarray(derivatives(base.at[i].add(h))[2])
              - np.asarray(derivatives(base.at[i].add(-h))[2])) / (2 * h)
        # Relative 1e-4, or 1e-6 of an elasticity-one derivative where the derivative is tiny.
        floor = 1e-6 * value / float(base[i])
        np.testing.assert_array_less(np.abs(forward[:, i] - fd), 1e-4 * np.abs(fd) + floor,
                                     err_msg=name)
