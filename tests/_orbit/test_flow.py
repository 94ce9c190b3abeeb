"""The paper's system is the one-storey case of the stick-slip flow that every structure
runs on: the same `Plant`, the same period map, the same steady states."""

import jax
import numpy as np
import pytest

import tid_jax as tj
from tid_jax._model._building import building_of
from tid_jax._orbit._flow import plant
from tid_jax._orbit._period import point_model

AMPLITUDE = 300.0  # N
OMEGAS = 2 * np.pi * np.array([3.4, 3.8, 3.95, 4.3])  # rad/s, through stick-slip


def _equation_12(system, omega):
    """Eq. (12)'s matrices written out, rigid device with parasitic damping and terminal
    mass: coordinates (x, y), the inerter's friction on y, the load on x."""
    M, K, C, b, k, c, cp, mt = (float(getattr(system, name)) for name in (
        "host_mass", "host_stiffness", "host_damping", "inertance", "tid_stiffness",
        "tid_damping", "parasitic_damping", "terminal_mass"))
    mass = np.array([[M, 0.0], [0.0, b + mt]])
    damping = np.array([[C + c, -c], [-c, c + cp]])
    stiffness = np.array([[K + k, -k], [-k, k]])
    return mass, damping, stiffness


def test_the_paper_system_is_eq_12_as_a_one_storey_building():
    system = tj.paper_system().replace(parasitic_damping=15.0, terminal_mass=2.0)
    building = building_of(system, "force")
    for ours, theirs in zip(building.generalised_matrices(), _equation_12(system, 25.0),
                            strict=True):
        np.testing.assert_allclose(np.asarray(ours), theirs, rtol=1e-15)
    np.testing.assert_array_equal(np.asarray(building.load_vector()), [1.0, 0.0])
    assert float(building.static_scale()) == pytest.approx(1 / float(system.host_stiffness))


@pytest.mark.parametrize("omega", OMEGAS)
def test_the_paper_system_s_plant_is_its_one_storey_building_s(omega):
    # one code path: the same plant, to the bit
    system = tj.paper_system()
    ours = point_model(system, tj.Quantity(), AMPLITUDE, omega)[0]
    building = plant(building_of(system, "force"), tj.Quantity(), AMPLITUDE, omega)
    assert ours.stroke == building.stroke == 1
    for a, b in zip(jax.tree.leaves(ours), jax.tree.leaves(building), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_steady_states_of_the_paper_system_and_its_one_storey_building_are_equal():
    system = tj.paper_system()
    host = tj.frequency_response(system, OMEGAS, AMPLITUDE)
    building = tj.frequency_response(building_of(system, "force"), OMEGAS, AMPLITUDE)
    assert np.all(host.converged) and np.all(building.converged)
    for name in ("x_max", "y_max", "transitions", "state", "monodromy", "newton_steps"):
        np.testing.assert_array_equal(getattr(host, name), getattr(building, name), name)


def _peak_derivatives(system, omega, amplitude, names):
    """Forward-mode derivatives of the steady-state peak at one point with respect to the
    system's fields `names` (implicit, through `solve_orbit`), and the peak."""
    import jax
    import jax.numpy as jnp

    from tid_jax._orbit._settings import SolverSettings
    from tid_jax._response import point_response

    values = jnp.asarray([float(getattr(system, name)) for name in names])

    def peak(v):
        changed = system.replace(**dict(zip(names, v, strict=True)))
        return point_response(changed, omega, amplitude, SolverSettings())[1]

    return np.asarray(jax.jacfwd(peak)(values)), float(peak(values))


NAMES = ("tid_stiffness", "tid_damping", "inertance", "friction_force")


def test_a_buildings_orbit_is_differentiable_by_field_name():
    # a 3-storey building under ground motion, exact friction through stick-slip: the
    # implicit derivatives against central differences of independent batch solves
    structure = tj.Structure.shear_building([2000.0, 2000.0, 1500.0],
                                            [1.5e6, 1.25e6, 1.0e6], damping_ratio=0.02)
    system = tj.BuildingTID(structure, 275.0, 300.0, 4e4, 500.0, load="ground")
    omega, amplitude = 0.7 * structure.modes()[0][0], 1.3
    derivatives, value = _peak_derivatives(system, omega, amplitude, NAMES)
    batch = tj.frequency_response(system, [omega], [amplitude])
    assert int(batch.transitions[0, 0]) > 2  # it sticks
    assert value == pytest.approx(float(batch.x_max[0, 0]), rel=1e-7)
    step = 1e-4
    for name, derivative in zip(NAMES, derivatives, strict=True):
        base = float(getattr(system, name))
        peaks = [float(tj.frequency_response(system.replace(**{name: base * np.exp(h)}),
                                             [omega], [amplitude]).x_max[0, 0])
                 for h in (-step, step)]
        difference = (peaks[1] - peaks[0]) / (2 * step)
        assert derivative * base == pytest.approx(difference, rel=1e-5, abs=1e-7 * value), name


def test_derivatives_of_the_paper_system_and_its_one_storey_building_agree():
    system = tj.paper_system()
    building = building_of(system, "force")
    for omega in OMEGAS[1:3]:
        ours, peak = _peak_derivatives(system, omega, AMPLITUDE, NAMES)
        theirs, building_peak = _peak_derivatives(building, omega, AMPLITUDE, NAMES)
        assert building_peak == peak
        np.testing.assert_array_equal(theirs, ours)


@pytest.mark.parametrize("index", [28, 31])  # of the default band: sticks twice a period
def test_a_building_s_stroke_derivative_through_stick_slip_matches_differences(index):
    # The stroke's peak reads the stroke at the stick-slip transitions, where a stuck
    # interval begins and ends at the same position: its forward derivative by the TID's
    # stiffness against central differences of orbits solved afresh.
    import jax
    import jax.numpy as jnp

    from tid_jax._response import point_response

    structure = tj.Structure.shear_building([2000.0, 2000.0, 1500.0],
                                            [1.5e6, 1.25e6, 1.0e6], damping_ratio=0.02)
    # (a robust design's tuning, the stroke limit active)
    system = tj.BuildingTID(structure, 275.0, 135.0, 28603.673621271577, 747.3393444255601,
                            load="ground")
    quantity, settings = tj.Quantity("drift", 1), tj.SolverSettings()
    omega = float(tj.default_omegas(system)[index])

    @jax.jit
    def peaks(k):
        _, x_max, y_max = point_response(system.replace(tid_stiffness=k), omega, 2.0,
                                         settings, quantity=quantity)
        return jnp.stack([x_max, y_max])

    k = jnp.asarray(28603.673621271577)
    derivative = np.asarray(jax.jit(jax.jacfwd(peaks))(k))
    step = 1e-5 * float(k)
    difference = np.asarray(peaks(k + step) - peaks(k - step)) / (2 * step)
    np.testing.assert_allclose(derivative, difference, rtol=1e-4)
