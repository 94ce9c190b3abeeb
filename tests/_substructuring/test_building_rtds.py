"""The virtual substructuring test of the inerter in a building: the structure, spring and
damper numerical, the device physical along the stroke. Expected values come from the
whole building (`frequency_response`, itself checked against the references), from the
dynamic stiffness of the reference matrices (`reference/building_linear.py`) and from
the paper's result that the conventional scheme is unstable for any delay."""

import numpy as np
import pytest

import tid_jax as tj
from tests._model.test_building import MASSES, STIFFNESSES, B, _matrices
from tests.reference import building_linear

STRUCTURE = tj.Structure.shear_building(MASSES, STIFFNESSES, damping_ratio=0.02)
FIRST = float(STRUCTURE.modes()[0][0])
OMEGAS = FIRST * np.array([0.9, 1.0, 1.1])
K_TID, C_TID = 41668.57, 524.636
LAYOUTS = {  # the paper's reference [8] (ground to floor 1), and between floors 2 and 3
    "ground": dict(spring_floor=1, inerter_floor=0, load="ground"),
    "floors": dict(spring_floor=3, inerter_floor=2, load="force", terminal_mass=10.0,
                   parasitic_damping=40.0),
}
AMPLITUDES = {"ground": 1.0, "floors": 4000.0}  # m/s2, N
DRIFT = tj.Quantity("drift", 2)


def _system(layout, friction=135.0, width=None, **changes):
    return tj.BuildingTID(STRUCTURE, B, friction, K_TID, C_TID, width,
                          **dict(LAYOUTS[layout], **changes))


def _relative(a, b):
    return np.abs(np.asarray(a) / np.asarray(b) - 1)


@pytest.mark.parametrize("layout", ["ground", "floors"])
def test_ideal_actuator_reproduces_the_whole_building(layout):
    system = _system(layout)
    amplitude = AMPLITUDES[layout]
    whole = tj.frequency_response(system, OMEGAS, [amplitude], quantity=DRIFT)
    guess = 0.8 * (B + float(system.terminal_mass))
    worst = {}
    for rate in (2000.0, 8000.0):
        test = tj.simulate_substructuring(system, OMEGAS, amplitude, quantity=DRIFT, delay=0.0,
                                          prediction=None, guessed_inertance=guess,
                                          sample_rate=rate, periods=30)
        assert bool(np.all(test.stable)) and bool(np.all(test.reference_converged))
        # the test's reference orbits are the whole building's, solved one at a time:
        # equal within the shooting tolerance (periodicity 1e-6 of the static scale)
        np.testing.assert_allclose(test.reference_x_max, whole.x_max[0], rtol=1e-6)
        np.testing.assert_allclose(test.reference_y_max, whole.y_max[0], rtol=1e-6)
        worst[rate] = max(np.max(_relative(test.x_max, whole.x_max[0])),
                          np.max(_relative(test.y_max, whole.y_max[0])))
        if rate == 8000.0:
            assert np.max(np.abs(test.x_phase_error)) < 2e-3
            assert np.max(np.abs(test.y_phase_error)) < 2e-3
    # what is left is the zero-order hold: first order in the sample period
    assert worst[8000.0] < 1e-3 and worst[2000.0] > 2.5 * worst[8000.0]


@pytest.mark.parametrize("layout", ["ground", "floors"])
def test_exact_guess_without_friction_is_the_dynamic_stiffness(layout):
    # b_g = b + mt, ff = 0, cp = 0: the error fed back, (b + mt - b_g) r*'', vanishes,
    # whatever the delay, and the test is the linear building
    system = _system(layout, friction=0.0, parasitic_damping=0.0)
    amplitude = AMPLITUDES[layout]
    test = tj.simulate_substructuring(
        system, OMEGAS, amplitude, quantity=DRIFT, delay=np.array([[0.0], [0.01]]),
        prediction=None, guessed_inertance=B + float(system.terminal_mass), reference=False)
    M, K, C = _matrices(STRUCTURE)
    layout_ = LAYOUTS[layout]
    U = amplitude * building_linear.complex_amplitudes(
        OMEGAS, M, K, C, b=B, k=K_TID, c=C_TID, spring_floor=layout_["spring_floor"],
        inerter_floor=layout_["inerter_floor"], load=layout_["load"],
        mt=layout_.get("terminal_mass", 0.0))
    drift, stroke = U[:, 1] - U[:, 0], U[:, 3]
    assert bool(np.all(test.stable))
    np.testing.assert_allclose(test.x_max, np.broadcast_to(np.abs(drift), (2, 3)), rtol=1e-6)
    np.testing.assert_allclose(test.y_max, np.broadcast_to(np.abs(stroke), (2, 3)), rtol=1e-6)
    gap = lambda a, b: np.abs(np.angle(np.exp(1j * (a - b))))
    assert np.max(gap(np.asarray(test.x_phase), np.angle(drift))) < 1e-6
    assert np.max(gap(np.asarray(test.y_phase), np.angle(stroke))) < 1e-6


def test_conventional_scheme_is_unstable_for_every_delay():
    system = _system("ground")
    test = tj.simulate_substructuring(system, OMEGAS[1], 1.0, scheme="conventional",
                                      delay=np.array([1e-3, 5e-3, 2e-2]), reference=False)
    assert not np.any(test.stable) and bool(np.all(test.diverged))
    assert np.all(np.isfinite(test.x_max)) and np.all(np.isfinite(test.y_max))
    # and error feedback with the same delays is stable
    feedback = tj.simulate_substructuring(system, OMEGAS[1], 1.0,
                                          delay=np.array([1e-3, 5e-3, 2e-2]), reference=False)
    assert bool(np.all(feedback.stable))


def test_compliant_device_is_compared_with_the_whole_compliant_building():
    system = _system("ground", terminal_mass=20.0, series_stiffness=2e6)
    whole = tj.frequency_response(system, OMEGAS, [1.0])
    # (the paper's harmonic guess -b_g w^2 r*: an acceleration guess b_g r*'' of the
    # terminal, which moves on the series spring, would destabilise the loop)
    test = tj.simulate_substructuring(system, OMEGAS, 1.0, delay=0.0, prediction=None,
                                      guessed_force="harmonic", sample_rate=8000.0,
                                      periods=30)
    assert bool(np.all(test.stable)) and bool(np.all(test.reference_converged))
    # (the whole building's orbits solved one at a time: within the shooting tolerance)
    np.testing.assert_allclose(test.reference_x_max, whole.x_max[0], rtol=1e-6)
    # (the zero-order hold's first-order error at 8 kHz, as on the single-storey host)
    assert np.max(_relative(test.x_max, whole.x_max[0])) < 3e-3
    assert np.max(_relative(test.y_max, whole.y_max[0])) < 3e-3
    rigid = tj.frequency_response(_system("ground", terminal_mass=20.0), OMEGAS, [1.0])
    assert np.max(_relative(whole.x_max, rigid.x_max)) > 0.01  # it shows


@pytest.mark.parametrize("system, options, message", [
    (_system("ground", width=0.0), {}, "smoothed friction"),
    (_system("floors"), dict(scheme="conventional"), "terminal mass"),
    (tj.paper_system(friction_width=None), dict(quantity=DRIFT), "quantity"),
    (_system("ground"), dict(quantity=tj.Quantity("drift", 5)), "response floor"),
])
def test_bad_building_tests_name_the_input(system, options, message):
    with pytest.raises(ValueError, match=message):
        tj.simulate_substructuring(system, OMEGAS[1], 1.0, reference=False, **options)
