"""The integrator of smoothed friction (`SolverSettings.implicit`): the automatic choice
between the explicit Tsit5 and the implicit Kvaerno5 from the estimated explicit steps per
period (`_orbit._stiffness`), the explicit and implicit settings, and the answers of both."""

import numpy as np
import pytest

import tid_jax as tj
from tid_jax._orbit._stiffness import for_points
from tid_jax._response import batched

MASSES = [2000.0, 2000.0, 1500.0]
STIFFNESSES = [1.5e6, 1.25e6, 1.0e6]  # first mode near 2 Hz
B = 275.0
# A narrow width against a ground acceleration the friction holds the inerter stuck at
# (about 60 steps per period with the relative width at 1 m/s2, where it slips).
NARROW, HELD, SLIPPING = 2e-5, 0.05, 1.0


@pytest.fixture(scope="module")
def building():
    structure = tj.Structure.shear_building(MASSES, STIFFNESSES, damping_ratio=0.02)
    return tj.BuildingTID(structure, B, 275.0, 41668.57, 524.636, load="ground",
                          friction_width=None)


def _omegas(system, count=5):
    return system.first_mode()[0] * np.linspace(0.8, 1.2, count)


def _chosen(system, amplitude, settings=None):
    omegas = _omegas(system)
    settings = tj.SolverSettings() if settings is None else settings
    return for_points(settings, batched(system, omegas.size), omegas,
                      np.full(omegas.shape, amplitude)).implicit


def test_automatic_choice_is_implicit_where_a_narrow_width_holds_the_inerter(building):
    assert _chosen(building.replace(friction_width=NARROW), HELD) is True
    assert _chosen(building, SLIPPING) is False
    # a setting given is kept
    assert _chosen(building.replace(friction_width=NARROW), HELD,
                   tj.SolverSettings(implicit=False)) is False


def test_automatic_choice_is_explicit_for_the_paper_system():
    paper = tj.paper_system()
    omegas = np.asarray(tj.default_omegas(paper, 21))
    amplitudes = np.geomspace(50.0, 3000.0, 6)
    a, w = (g.reshape(-1) for g in np.meshgrid(amplitudes, omegas, indexing="ij"))

    def chosen(system):
        return for_points(tj.SolverSettings(), batched(system, a.size), w, a).implicit

    # exact friction (the paper's default model) takes no integrator: left automatic
    assert chosen(paper) is None
    assert chosen(paper.replace(friction_width=1e-4)) is False


def test_a_bad_integrator_setting_is_refused_in_one_line():
    with pytest.raises(ValueError, match=r"^SolverSettings.implicit must be None") as error:
        tj.SolverSettings(implicit="yes")
    assert "\n" not in str(error.value)
    with pytest.raises(ValueError):
        tj.SolverSettings(implicit=1)


def test_the_implicit_choice_finds_the_stuck_orbit_of_exact_friction(building):
    # at the narrow width the explicit steps allowed run out; the automatic (implicit)
    # choice finds the stuck orbit, that of exact friction but for the smoothed
    # friction's creep
    system = building.replace(friction_width=NARROW)
    omegas = _omegas(system, 3)
    automatic = tj.frequency_response(system, omegas, [HELD])
    exact = tj.frequency_response(system.replace(friction_width=0.0), omegas, [HELD])
    assert np.all(automatic.converged) and np.all(exact.converged)
    assert np.all(exact.transitions == 0)
    np.testing.assert_allclose(automatic.x_max, exact.x_max, rtol=1e-3)


def test_implicit_and_explicit_steady_states_agree(building):
    omegas = _omegas(building, 3)
    explicit, implicit = (
        tj.frequency_response(building, omegas, [SLIPPING],
                              settings=tj.SolverSettings(implicit=choice))
        for choice in (False, True))
    assert np.all(explicit.converged) and np.all(implicit.converged)
    np.testing.assert_allclose(implicit.x_max, explicit.x_max, rtol=1e-5)
    np.testing.assert_allclose(implicit.y_max, explicit.y_max, rtol=1e-5)
