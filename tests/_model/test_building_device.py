"""A compliant inerter (series stiffness, backlash) in a multi-storey structure, against
independent answers: the dynamic stiffness of the structure with the device's mechanism
(`reference/building_linear.py`), the event-driven stick-slip solver with the friction
on the mechanism (`reference/building_stick_slip.py`), the single-storey compliant
reference in physical coordinates (`reference/compliant.py`) and central differences."""

import numpy as np
import pytest

import tid_jax as tj
from tests._model.test_building import MASSES, STIFFNESSES, B, _matrices
from tests.reference import building_linear
from tests.reference.building_stick_slip import steady_state
from tests.reference.compliant import compliant_peaks

DEVICE = dict(series_stiffness=2e6, terminal_mass=20.0, parasitic_damping=30.0)
K_TID, C_TID = 41668.57, 524.636


@pytest.fixture(scope="module")
def building():
    return tj.Structure.shear_building(MASSES, STIFFNESSES, damping_ratio=0.02)


@pytest.mark.parametrize("layout", [(1, 0, "ground", None), (3, 1, "force", [0.2, 0.3, 1.0]),
                                    (2, 3, "ground", None)])
def test_linear_steady_state_matches_the_dynamic_stiffness(building, layout):
    j, i, load, pattern = layout
    system = tj.BuildingTID(building, B, 0.0, K_TID, C_TID, spring_floor=j, inerter_floor=i,
                            load=load, force_pattern=pattern, **DEVICE)
    assert system.coordinates == 5
    omegas = np.linspace(0.5, 2.5, 9) * 2 * np.pi * 2.0
    M, K, C = _matrices(building)
    reference = dict(b=B, k=K_TID, c=C_TID, spring_floor=j, inerter_floor=i, load=load,
                     pattern=pattern, cp=DEVICE["parasitic_damping"],
                     mt=DEVICE["terminal_mass"], ks=DEVICE["series_stiffness"])
    for kind in ("displacement", "drift", "acceleration"):
        mine = np.abs(tj.linear_receptance(system, omegas, quantity=tj.Quantity(kind, 2)).host)
        theirs = building_linear.response_amplitude(omegas, M, K, C, kind=kind, floor=2,
                                                    **reference)
        np.testing.assert_allclose(mine, theirs, rtol=1e-10)
    # the shooting solver without friction finds the same steady states, stroke too
    orbits = tj.frequency_response(system, omegas[::4], [3.0])
    stroke = building_linear.response_amplitude(omegas[::4], M, K, C, kind="stroke",
                                                **reference)
    top = building_linear.response_amplitude(omegas[::4], M, K, C, kind="displacement",
                                             **reference)
    np.testing.assert_allclose(orbits.x_max[0], 3.0 * top, rtol=1e-6)
    np.testing.assert_allclose(orbits.y_max[0], 3.0 * stroke, rtol=1e-6)


def test_exact_coulomb_matches_the_event_driven_reference(building):
    M, K, C = _matrices(building)
    first = building.modes()[0][0]
    ff = 50.0
    system = tj.BuildingTID(building, B, ff, K_TID, C_TID, load="ground", **DEVICE)
    quantity = tj.Quantity("drift", 2)
    ratios = np.linspace(0.8, 1.2, 5)
    amplitudes = [0.04, 0.1, 0.5]
    mine = tj.frequency_response(system, first * ratios, amplitudes, quantity=quantity)
    assert np.all(mine.converged)
    for a, amplitude in enumerate(amplitudes):
        for r, ratio in enumerate(ratios):
            reference = steady_state(
                ratio * first, M, K, C, b=B, ff=ff, k=K_TID, c=C_TID, spring_floor=1,
                inerter_floor=0, amplitude=amplitude, load="ground", kind="drift", floor=2,
                cp=DEVICE["parasitic_damping"], mt=DEVICE["terminal_mass"],
                ks=DEVICE["series_stiffness"])
            assert reference["converged"]
            assert mine.x_max[a, r] == pytest.approx(reference["response_max"],
                                                            rel=1e-4)
            assert mine.y_max[a, r] == pytest.approx(reference["stroke_max"], rel=1e-4,
                                                          abs=1e-6 * reference["response_max"])
    transitions = np.asarray(mine.transitions)
    assert 0 in transitions and transitions.max() >= 4  # stuck, slipping and stick-slip


@pytest.mark.parametrize("backlash", [0.0, 2e-4])
def test_one_storey_compliant_building_matches_the_physical_reference(system, backlash):
    device = dict(series_stiffness=3e5, terminal_mass=2.0, parasitic_damping=300.0,
                  backlash=backlash)
    host = tj.Structure([[float(system.host_mass)]], [[float(system.host_stiffness)]],
                        [[float(system.host_damping)]])
    width = 0.002  # m/s
    building = tj.BuildingTID(host, system.inertance, system.friction_force,
                              system.tid_stiffness, system.tid_damping, width, **device)
    omegas = np.array([0.9, 1.0, 1.05]) * float(system.host_frequency)
    amplitude = 300.0
    response = tj.frequency_response(building, omegas, [amplitude],
                                     settings=tj.SolverSettings(samples=1024))
    assert np.all(response.converged)
    fields = {name: value for name, value in system.to_dict().items()}
    fields.update(device, friction_width=width, amplitude=amplitude)
    for i, omega in enumerate(omegas):
        reference = compliant_peaks(dict(fields, omega=float(omega)))
        assert reference["converged"]
        assert float(response.x_max[0, i]) == pytest.approx(reference["x_max"],
                                                                    rel=1e-6)
        assert float(response.y_max[0, i]) == pytest.approx(reference["y_max"], rel=1e-5)


@pytest.mark.parametrize("changes, message", [
    (dict(series_stiffness=2e6), "terminal_mass > 0"),
    (dict(series_stiffness=-1.0, terminal_mass=20.0), "series_stiffness"),
    (dict(backlash=1e-3), "backlash needs a finite series_stiffness"),
    (dict(backlash=1e-3, series_stiffness=2e6, terminal_mass=20.0), "smoothed friction"),
    (dict(backlash=-1e-3, series_stiffness=2e6, terminal_mass=20.0), "backlash"),
])
def test_bad_devices_name_the_input(building, changes, message):
    system = tj.BuildingTID(building, B, 50.0, K_TID, C_TID)
    with pytest.raises(ValueError, match=message):
        system.replace(**changes)


def test_breakaway_amplitude_is_where_the_stuck_mechanism_slips(building):
    system = tj.BuildingTID(building, B, 50.0, K_TID, C_TID, load="ground", **DEVICE)
    omega = 0.7 * building.modes()[0][0]
    breakaway = float(tj.breakaway_amplitude(system, [omega]).amplitude[0])
    below = tj.frequency_response(system, [omega], [0.95 * breakaway])
    above = tj.frequency_response(system, [omega], [1.05 * breakaway])
    assert int(below.transitions[0, 0]) == 0 and int(above.transitions[0, 0]) > 0
    # held, the mechanism leaves the terminal on the series spring: it still moves
    assert float(below.y_max[0, 0]) > 0


@pytest.mark.parametrize("friction_width, backlash", [(0.0, 0.0), (None, 5e-4)])
def test_elasticities_in_the_device_terms_are_differences(building, friction_width,
                                                         backlash):
    system = tj.BuildingTID(building, B, 50.0, K_TID, C_TID, friction_width, load="ground",
                            backlash=backlash, **DEVICE)
    # (about the first mode: with backlash, at 1.2 times its frequency, Newton's
    # iterations find no steady state of the forcing's period, even after 200 periods)
    omegas = building.modes()[0][0] * np.linspace(0.85, 1.15, 31)
    amplitude = 0.3
    (sens,) = tj.amplitude_sensitivities(system, [amplitude], omegas=omegas, optimum=False)
    assert bool(sens.converged)
    names = list(sens.parameters)
    assert names[6:8] == ["series_stiffness", "backlash"] and names[-1] == "amplitude"
    step = 1e-4
    for name in ("series_stiffness", "terminal_mass") + (("backlash",) if backlash else ()):
        value = float(getattr(system, name))
        peaks = [float(tj.peaks(system.replace(**{name: value * np.exp(h)}), omegas,
                                [amplitude]).x_peak[0])
                 for h in (step, -step)]
        difference = (peaks[0] - peaks[1]) / (2 * step) / float(sens.host_peak)
        assert float(sens.host_elasticity[names.index(name)]) == pytest.approx(
            difference, abs=2e-4)
    if not backlash:
        assert float(sens.host_elasticity[names.index("backlash")]) == 0.0
