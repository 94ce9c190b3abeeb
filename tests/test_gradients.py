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


BUILDING_NAMES = ("tid_stiffness", "tid_damping", "friction_force", "inertance", "amplitude")


def test_a_building_s_peak_gradients_match_finite_differences():
    # A TID on the first floor of a 3-storey building under ground acceleration, exact
    # Coulomb friction: the peak drift of storey 2 and the stroke, their Jacobian in
    # forward mode and the drift's gradient in reverse mode (`jax.grad`'s transpose),
    # against central differences of the batched peaks (`tj.peaks`).
    structure = tj.Structure.shear_building([2000.0, 2000.0, 1500.0], [1.5e6, 1.25e6, 1.0e6],
                                            damping_ratio=0.02)
    system = tj.BuildingTID(structure, 275.0, 15.0, 1.0, 1.0, load="ground")
    k, c = tj.first_mode_tunings(system)["den_hartog"]
    system = system.replace(tid_stiffness=k, tid_damping=c)
    quantity = tj.Quantity("drift", 2)
    band = tj.default_omegas(system, 25)
    base = np.array([float(getattr(system, n)) for n in BUILDING_NAMES[:-1]] + [1.0])

    def at(values):
        return system.replace(**dict(zip(BUILDING_NAMES[:-1], values[:-1], strict=True)))

    def derivatives(values):
        value, tangent = jax.linearize(
            lambda v: tj.peak_response(at(v), band, v[-1], response=("host", "inerter"),
                                      quantity=quantity), values)
        jacobian = jax.vmap(tangent, out_axes=-1)(jnp.eye(values.shape[0]))
        (gradient,) = jax.linear_transpose(tangent, values)(jnp.array([1.0, 0.0]))
        return jacobian, gradient, value

    forward, grad_drift, value = (np.asarray(out) for out in derivatives(jnp.asarray(base)))
    np.testing.assert_allclose(grad_drift, forward[0], rtol=1e-9)
    steps = 1e-4 * base
    for i, name in enumerate(BUILDING_NAMES):
        found = [tj.peaks(at(point), band, point[-1], quantity=quantity)
                 for point in (base + steps[i] * np.eye(base.size)[i],
                               base - steps[i] * np.eye(base.size)[i])]
        for row, field in enumerate(("x_peak", "y_peak")):  # the drift, the stroke
            fd = (float(getattr(found[0], field)[0])
                  - float(getattr(found[1], field)[0])) / (2 * steps[i])
            floor = 1e-6 * value[row] / base[i]
            assert abs(forward[row, i] - fd) < 1e-4 * abs(fd) + floor, (name, field,
                                                                        forward[row, i], fd)


def test_a_one_storey_building_s_gradient_is_the_paper_system_s():
    system = tj.paper_system()
    band = tj.default_omegas(system, 31)

    def gradient(make):
        return jax.grad(lambda k, c: make(k, c), argnums=(0, 1))(
            jnp.asarray(float(system.tid_stiffness)), jnp.asarray(float(system.tid_damping)))

    host = gradient(lambda k, c: tj.peak_response(system.replace(tid_stiffness=k,
                                                                 tid_damping=c), band, 300.0))
    building = tj.as_building(system)
    one_storey = gradient(lambda k, c: tj.peak_response(
        building.replace(tid_stiffness=k, tid_damping=c), band, 300.0))
    np.testing.assert_allclose(one_storey, host, rtol=1e-8)
