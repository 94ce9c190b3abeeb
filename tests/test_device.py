"""The real inerter in the TID: parasitic damping and terminal mass through the
steady-state solvers and the design, against the independent references; compliance
and backlash where the solvers do not take them."""

import math

import numpy as np
import pytest

import tid_jax as tj
from tests.reference import hinf
from tests.reference.coulomb import coulomb_steady_state
from tests.reference.transient import transient_peaks

DEVICE = dict(parasitic_damping=300.0, terminal_mass=2.0)  # N s/m, kg: the Penske unit's mass
MODEL_FIELDS = ("host_mass", "host_stiffness", "host_damping", "inertance", "friction_force",
                "tid_stiffness", "tid_damping", "parasitic_damping", "terminal_mass")
OMEGA_RATIOS = np.array([0.85, 0.95, 1.02, 1.12])


def _fields(system):
    return {name: float(getattr(system, name)) for name in MODEL_FIELDS}


def test_default_device_is_the_ideal_inerter(system):
    omegas = OMEGA_RATIOS * float(system.host_frequency)
    explicit = system.replace(parasitic_damping=0.0, terminal_mass=0.0,
                              series_stiffness=math.inf, backlash=0.0)
    for width in (None, 0.0):
        a = tj.frequency_response(system.replace(friction_width=width), omegas, [300.0])
        b = tj.frequency_response(explicit.replace(friction_width=width), omegas, [300.0])
        np.testing.assert_array_equal(np.asarray(a.x_max), np.asarray(b.x_max))
        np.testing.assert_array_equal(np.asarray(a.state), np.asarray(b.state))


@pytest.mark.parametrize("amplitude", [100.0, 300.0])
def test_device_terms_match_the_references(system, amplitude):
    device = system.replace(**DEVICE)
    omegas = OMEGA_RATIOS * float(system.host_frequency)
    exact = tj.frequency_response(device.replace(friction_width=0.0), omegas, [amplitude])
    smooth = tj.frequency_response(device, omegas, [amplitude])
    ideal = tj.frequency_response(system, omegas, [amplitude])
    assert bool(np.all(exact.converged)) and bool(np.all(smooth.converged))
    for i, omega in enumerate(omegas):
        reference = coulomb_steady_state(**_fields(device), omega=omega, amplitude=amplitude)
        assert float(exact.x_max[0, i]) == pytest.approx(reference["x_max"], rel=1e-6)
        assert float(exact.y_max[0, i]) == pytest.approx(reference["y_max"], rel=1e-6, abs=1e-9)
        reference = transient_peaks(dict(_fields(device), omega=omega, amplitude=amplitude),
                                    float(device.width_at(amplitude, omega)))
        assert float(smooth.x_max[0, i]) == pytest.approx(reference["x_max"], rel=1e-6)
        assert float(smooth.y_max[0, i]) == pytest.approx(reference["y_max"], rel=2e-4)
    # the device's terms matter at this size
    assert np.max(np.abs(np.asarray(smooth.x_max / ideal.x_max) - 1)) > 0.05


def test_retune_with_terminal_mass_is_the_h_infinity_optimum_of_the_total_mass(system):
    # Without friction, a terminal mass mt adds to the inertance: the optimum is the exact
    # H-infinity tuning of the TID with inertance b + mt.
    mass = 5.0
    device = system.replace(friction_force=0.0, terminal_mass=mass)
    band = np.linspace(0.8, 1.2, 31) * float(system.host_frequency)
    result = tj.retune(device, [1000.0], omegas=band, tol=1e-5)
    assert bool(result.converged[0])
    k, c, peak = hinf.h_infinity_optimum(*(float(getattr(system, name)) for name in (
        "host_mass", "host_stiffness", "host_damping")), float(system.inertance) + mass)
    static = 1000.0 / float(system.host_stiffness)
    assert float(result.x_peak[0]) / static == pytest.approx(peak, abs=1e-5)
    assert float(result.tid_stiffness[0]) == pytest.approx(k, rel=2e-3)
    ideal_k = hinf.h_infinity_optimum(*(float(getattr(system, name)) for name in (
        "host_mass", "host_stiffness", "host_damping", "inertance")))[0]
    assert abs(k / ideal_k - 1) > 0.02  # the mass moves the optimum


def test_sensitivities_to_the_device_terms(system, band):
    device = system.replace(**DEVICE)
    amplitude = 400.0
    sens = tj.sensitivities(device, amplitude, omegas=band, optimum=False)
    assert bool(sens.converged)
    assert sens.parameters[-3:] == ("parasitic_damping", "terminal_mass", "amplitude")

    def peaks(changed):
        result = tj.peaks(changed, [amplitude], band)
        return np.array([float(result.x_peak[0]), float(result.y_peak[0])])

    for name in ("parasitic_damping", "terminal_mass"):
        i = sens.parameters.index(name)
        value = float(sens.values[i])
        h = 1e-3 * value
        fd = (peaks(device.replace(**{name: value + h}))
              - peaks(device.replace(**{name: value - h}))) / (2 * h)
        assert float(sens.host_derivative[i]) == pytest.approx(fd[0], rel=1e-3), name
        assert float(sens.stroke_derivative[i]) == pytest.approx(fd[1], rel=1e-3), name
    # Scaling every mass, stiffness, damping and force by s leaves x and y unchanged:
    # the elasticities, the device's among them, sum to 0.
    assert float(np.sum(sens.host_elasticity)) == pytest.approx(0.0, abs=1e-4)
    assert float(np.sum(sens.stroke_elasticity)) == pytest.approx(0.0, abs=1e-4)


@pytest.mark.parametrize("device", [dict(series_stiffness=3e5),
                                    dict(series_stiffness=3e5, backlash=2e-4)])
def test_compliant_device_is_rejected_by_the_steady_state_solvers(system, band, device):
    compliant = system.replace(**device)
    calls = {
        "frequency_response": lambda: tj.frequency_response(compliant, band, [400.0]),
        "retune": lambda: tj.retune(compliant, [400.0], omegas=band),
        "sensitivities": lambda: tj.sensitivities(compliant, 400.0, omegas=band),
        "best_tunings": lambda: tj.best_tunings(compliant, [400.0], omegas=band),
        "robust_tune": lambda: tj.robust_tune(compliant, [400.0], omegas=band),
        "breakaway_amplitude": lambda: tj.breakaway_amplitude(compliant, band),
    }
    for name, call in calls.items():
        with pytest.raises(ValueError, match=f"{name} needs a rigid inerter"):
            call()
    # the linear receptance takes it
    assert np.all(np.isfinite(np.asarray(tj.linear_receptance(compliant, band).host)))
