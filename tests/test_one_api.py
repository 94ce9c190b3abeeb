"""One API for every structure: each verb is one public function that takes the paper's
single-storey `TIDSystem` and a `BuildingTID` alike, with one argument order; a
one-storey building gives the paper system's numbers."""

import inspect
import re

import numpy as np
import pytest

import tid_jax as tj

# The verbs, each once, in the order (system, frequencies, amplitudes) where they take
# both positionally.
VERBS = ("frequency_response", "peaks", "peak_response", "retune", "robust_tune", "sensitivities",
         "amplitude_sensitivities", "breakaway_amplitude", "linear_receptance",
         "default_omegas")
# Words that name one kind of structure in a public function's name.
STRUCTURE_WORDS = re.compile(r"(^|_)(building|host|storey|single|multi)(_|$)")


def _functions():
    return [name for name in tj.__all__
            if callable(getattr(tj, name)) and not inspect.isclass(getattr(tj, name))]


def test_no_public_function_is_written_for_one_kind_of_structure():
    twinned = [name for name in _functions()
               if STRUCTURE_WORDS.search(name) and name != "as_building"]
    assert not twinned, f"public functions for one kind of structure: {twinned}"
    names = set(tj.__all__)
    pairs = [(name, other) for name in names for other in names if name != other and (
        other in (f"building_{name}", f"{name}_building", f"building{name}"))]
    assert not pairs
    # and no result or settings type of one kind: the structure's own type names it
    results = [name for name in names if inspect.isclass(getattr(tj, name))
               and re.search("Building|Host|Storey", name) and name != "BuildingTID"]
    assert not results, f"public types for one kind of structure: {results}"


def test_the_arguments_run_system_frequencies_amplitudes():
    for verb in VERBS:
        parameters = list(inspect.signature(getattr(tj, verb)).parameters)
        assert parameters[0] == "system", verb
        positional = [name for name, p in inspect.signature(getattr(tj, verb)).parameters.items()
                      if p.kind is p.POSITIONAL_OR_KEYWORD]
        if "omegas" in positional and any(name.startswith("amplitude") for name in positional):
            amplitude = next(name for name in positional if name.startswith("amplitude"))
            assert positional.index("omegas") < positional.index(amplitude), verb
        # a building's measured response, by the same keyword everywhere it applies
        if verb not in ("breakaway_amplitude", "default_omegas"):
            assert "quantity" in inspect.signature(getattr(tj, verb)).parameters, verb


def test_a_band_in_the_old_argument_order_is_refused_in_one_line(system):
    with pytest.raises(ValueError, match="system, omegas, amplitudes"):
        tj.peaks(system, [200.0], tj.default_omegas(system, 9))
    with pytest.raises(ValueError, match="system, omegas, amplitudes"):
        tj.peak_response(system, 200.0, tj.default_omegas(system, 9))


def test_a_single_storey_system_refuses_another_quantity(system):
    with pytest.raises(ValueError, match="as_building"):
        tj.frequency_response(system, [25.0], [200.0], quantity=tj.Quantity("acceleration"))


def test_the_verbs_give_a_one_storey_building_the_paper_system_s_numbers(system):
    building = tj.as_building(system)
    omegas = np.asarray(tj.default_omegas(system, 41))
    # linear theory: the receptances of the host and the inerter terminal (the stroke
    # from the ground) are the paper's eq. (3) with host damping
    mine, paper = tj.linear_receptance(building, omegas), tj.linear_receptance(system, omegas)
    np.testing.assert_allclose(mine.host, paper.host, rtol=1e-10)
    np.testing.assert_allclose(mine.inerter, paper.inerter, rtol=1e-10)
    # the breakaway amplitude: the building's minimum on a grid, the paper's exact
    mine, paper = (tj.breakaway_amplitude(s, omegas) for s in (building, system))
    np.testing.assert_allclose(mine.amplitude, paper.amplitude, rtol=1e-10)
    assert float(mine.minimum) == pytest.approx(float(paper.minimum), rel=1e-6)
    # the peak over the band with exact friction: the same finder (the maximum in
    # continuous frequency, the stroke's grid peak), within the shooting's tolerance
    amplitudes = [100.0, 1000.0]
    mine, paper = tj.peaks(building, omegas, amplitudes), tj.peaks(system, omegas, amplitudes)
    assert type(mine) is type(paper) is tj.Peaks  # one result type, one set of names
    assert np.all(mine.converged) and np.all(paper.converged)
    for name in ("x_peak", "y_peak", "omega_x", "omega_y"):
        np.testing.assert_allclose(getattr(mine, name), getattr(paper, name), rtol=1e-6,
                                   err_msg=name)
    assert type(tj.frequency_response(building, omegas, 100.0)) is tj.FrequencyResponse
    # sensitivities: the host's mass, stiffness and damping are the building's floor
    # mass, storey stiffness and damping matrix (its factor)
    mine, paper = (tj.sensitivities(s, 300.0, omegas=omegas, optimum=False)
                   for s in (building, system))
    names = {"floor_mass_1": "host_mass", "storey_stiffness_1": "host_stiffness",
             "damping_scale": "host_damping"}
    for name in mine.parameters:
        j, i = mine.parameters.index(name), paper.parameters.index(names.get(name, name))
        for field in ("host_elasticity", "stroke_elasticity"):
            assert float(getattr(mine, field)[j]) == pytest.approx(
                float(getattr(paper, field)[i]), rel=1e-6, abs=1e-9), (name, field)
    # the retune: the same optimiser, from the same reference tuning (Den Hartog's on the
    # one mode), to the same design and peaks
    mine, paper = (tj.retune(s, [600.0], omegas=omegas) for s in (building, system))
    assert type(mine) is type(paper) is tj.RetuneResult
    for name in ("status", "iterations"):
        assert np.array_equal(np.asarray(getattr(mine, name)), np.asarray(getattr(paper, name)))
    for name in ("tid_stiffness", "tid_damping", "x_peak", "y_peak", "x_peak_initial"):
        np.testing.assert_allclose(getattr(mine, name), getattr(paper, name), rtol=1e-10,
                                   err_msg=name)


def test_random_and_recorded_loads_take_the_paper_system_as_its_one_storey_building(system):
    # a stationary load is a force on the host, a record a ground acceleration
    load = tj.StationaryLoad("white_noise", 500.0)
    assert float(tj.rms_response(system, load)) == float(
        tj.rms_response(tj.as_building(system, "force"), load))
    ground = tj.StationaryLoad("kanai_tajimi", 0.01, ground_frequency=15.0, ground_damping=0.6)
    motion = tj.synthetic_motion(ground, 4.0, 0.01, seed=3)
    mine = tj.friction_history(system, motion)
    building = tj.friction_history(tj.as_building(system, "ground"), motion)
    np.testing.assert_array_equal(np.asarray(mine.quantity), np.asarray(building.quantity))
    with pytest.raises(ValueError, match="TIDSystem or a BuildingTID"):
        tj.monte_carlo("paper", load)
