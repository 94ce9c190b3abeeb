"""Steady states of random structures (tall buildings to machines), against independent
references: the transient integration of the same smoothed model (`reference/transient.py`,
implicit Kvaerno5) and exact Coulomb friction (`reference/coulomb.py`); and the design
with the smoothed model against exact friction's."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st

import tid_jax as tj
from tests.reference.coulomb import coulomb_steady_state
from tests.reference.family import random_system
from tests.reference.transient import transient_peaks

SYSTEM_KEYS = ("host_mass", "host_stiffness", "host_damping", "inertance", "friction_force",
               "tid_stiffness", "tid_damping")


def _system(case, friction_width):
    return tj.TIDSystem(**{key: case[key] for key in SYSTEM_KEYS}, friction_width=friction_width)


@hypothesis_settings(max_examples=6, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1))
def test_random_structure_converges_to_the_transient_steady_state(seed):
    # Hosts of 0.1-10 Hz and 1e2-1e7 kg, mass ratios 0.005-0.2, any tuning, friction up to
    # 0.6 A, forcing 0.5-1.6 times the host frequency, friction width 1e-4 m/s.
    case = random_system(np.random.default_rng(seed))
    response = tj.frequency_response(_system(case, 1e-4), case["omega"], case["amplitude"])
    assert bool(response.converged)
    reference = transient_peaks(case, 1e-4)
    assert reference["converged"]
    assert float(response.x_max) == pytest.approx(reference["x_max"], rel=1e-3)


@hypothesis_settings(max_examples=4, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1))
def test_relative_width_is_within_half_a_percent_of_coulomb_friction(seed):
    # Friction drawn against the frictionless inerter force, so that the inerter sticks
    # and slips (against the forcing amplitude it mostly stays stuck).
    case = random_system(np.random.default_rng(seed), friction_scale="inerter")
    response = tj.frequency_response(_system(case, None), case["omega"], case["amplitude"])
    assert bool(response.converged)
    exact = coulomb_steady_state(**case)
    assert exact["converged"]
    assert float(response.x_max) == pytest.approx(exact["x_max"], rel=5e-3)


def test_relative_width_follows_the_static_velocity():
    system = tj.paper_system(friction_width=None)
    omega = float(system.host_frequency)
    expected = 0.02 * omega * 300.0 / float(system.host_stiffness)
    assert float(system.width_at(300.0, omega)) == pytest.approx(expected, rel=1e-12)
    # A number fixes the width.
    assert float(tj.paper_system(friction_width=1e-4).width_at(300.0, omega)) == 1e-4


def test_slow_tall_structure_with_high_friction_converges():
    # A 0.2 Hz, 5000 t host whose inerter friction is 40% of the forcing: at a width of
    # 1e-4 m/s the friction's time scale is a thousand times shorter than the forcing's.
    mass = 5e6
    stiffness = mass * (2 * np.pi * 0.2) ** 2
    inertance = 0.005 * mass
    k, c = tj.den_hartog_tuning(mass, stiffness, inertance)
    amplitude = 1e-3 * stiffness
    case = dict(host_mass=mass, host_stiffness=stiffness,
                host_damping=2 * 0.01 * np.sqrt(stiffness * mass), inertance=inertance,
                friction_force=0.4 * amplitude, tid_stiffness=float(k), tid_damping=float(c),
                omega=0.97 * 2 * np.pi * 0.2, amplitude=amplitude)
    system = _system(case, 1e-4)
    assert float(case["friction_force"] / (inertance * 1e-4 * case["omega"])) > 1e3
    response = tj.frequency_response(system, case["omega"], amplitude)
    assert bool(response.converged)
    reference = transient_peaks(case, 1e-4)
    assert float(response.x_max) == pytest.approx(reference["x_max"], rel=1e-3)


def test_design_at_the_relative_width_agrees_with_exact_friction(system, band):
    # The design entry points with the smoothed model: its peaks are within half a percent
    # of exact Coulomb friction's (above), so the best achievable peak is too (the minimum
    # of a function moved by at most 0.5% everywhere moves by at most that). The
    # sensitivities of its optimum obey the exact scaling laws of the model (the relative
    # width scales with A / K).
    smoothed = system.replace(friction_width=None)
    assert system.exact_friction and not smoothed.exact_friction
    amplitudes = [200.0, 1000.0]
    best, exact = (tj.best_tunings(model, amplitudes, omegas=band) for model in (smoothed,
                                                                                 system))
    assert bool(np.all(best.converged)) and bool(np.all(exact.converged))
    np.testing.assert_allclose(np.asarray(best.host_peak), np.asarray(exact.host_peak),
                               rtol=5e-3)
    sens = tj.sensitivities(smoothed, 1000.0, omegas=band, best=best)
    optimum = sens.optimum
    assert bool(sens.converged) and bool(optimum.converged)
    index = {name: i for i, name in enumerate(sens.parameters)}
    a, f = index["amplitude"], index["friction_force"]
    for e in (sens.host_elasticity, optimum.host_elasticity):
        assert float(np.sum(e)) == pytest.approx(0.0, abs=1e-4)
        assert float(e[a] + e[f]) == pytest.approx(1.0, abs=1e-4)
    e = np.asarray(optimum.stiffness_elasticity)
    assert float(np.sum(e)) == pytest.approx(1.0, abs=3e-3)
