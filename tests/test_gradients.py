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
    system = tj.paper_system(friction_width=None)  # exact friction: test_coulomb's
    band = tj.default_omegas(system, 31)
    base = jnp.array([float(getattr(system, n)) for n in NAMES[:-1]] + [300.0])

    def fn(values, responses=("host", "inerter")):
        tuned = system.replace(**dict(zip(NAMES[:-1], values[:-1])))
        return jnp.stack([tj.peak_response(tuned, values[-1], band, response=response)
                          for response in responses])

    return base, fn


def test_gradients_match_finite_differences(peaks):
    base, fn = peaks
    grad_host = np.asarray(jax.jit(jax.grad(lambda v: fn(v, ("host",))[0]))(base))
    # The Jacobian and the peaks from one compiled program: the differences below take
    # their peaks from it too.
    def twice(values):
        out = fn(values)
        return out, out

    jacobian_and_value = jax.jit(jax.jacfwd(twice, has_aux=True))
    forward, value = (np.asarray(out) for out in jacobian_and_value(base))
    np.testing.assert_allclose(grad_host, forward[0], rtol=1e-9)
    for i, name in enumerate(NAMES):
        # A step of 1e-3: the truncation error (~1e-6) stays below the tolerance, and so
        # does the integration noise of the peaks (~1e-9 relative) divided by the step.
        h = 1e-3 * float(base[i])
        fd = (np.asarray(jacobian_and_value(base.at[i].add(h))[1])
              - np.asarray(jacobian_and_value(base.at[i].add(-h))[1])) / (2 * h)
        # Relative 1e-4, or 1e-6 of an elasticity-one derivative where the derivative is tiny.
        floor = 1e-6 * value / float(base[i])
        np.testing.assert_array_less(np.abs(forward[:, i] - fd), 1e-4 * np.abs(fd) + floor,
                                     err_msg=name)
