"""Monte Carlo with exact Coulomb friction against the independent event-driven
simulator (`reference/random_friction.py`: scipy, one realisation at a time, its own
integrator and its own band-limited noise): path by path under a recorded-like ground
motion, where the time-stepped friction converges at first order in the step, and in
distribution under white noise, within three combined standard errors."""

import math

import numpy as np

import tid_jax as tj
from tests.reference import building_linear, random_friction

PAPER = tj.paper_system()
HOST = [[float(PAPER.host_mass)]]


def _reference_matrices(load):
    p = PAPER
    Mg, Cg, Kg = building_linear.generalised_matrices(
        HOST, [[float(p.host_stiffness)]], [[float(p.host_damping)]], b=float(p.inertance),
        k=float(p.tid_stiffness), c=float(p.tid_damping), spring_floor=1, inerter_floor=0)
    return Mg, Cg, Kg, building_linear.generalised_load(HOST, load=load)


def test_paths_under_a_ground_motion_converge_to_the_event_driven_reference():
    filtered = tj.StationaryLoad("kanai_tajimi", 0.05, ground_frequency=15.0,
                                 ground_damping=0.6)
    motion = tj.synthetic_motion(filtered, 6.0, 0.01, seed=7).scaled_to(0.03)
    Mg, Cg, Kg, g = _reference_matrices("ground")
    samples = np.asarray(motion.acceleration)
    load = lambda t: float(np.interp(t, np.arange(samples.size) * 0.01, samples))
    times = np.arange(samples.size) * 0.01
    states, info = random_friction.simulate_detailed(
        Mg, Cg, Kg, g, float(PAPER.friction_force), load, times, rtol=1e-10, atol=1e-13,
        max_step=0.01)
    assert info["transitions"] > 30 and 0.1 < info["stick_time"] / times[-1] < 0.9
    system = tj.as_building(PAPER, "ground")
    errors = []
    for h in (4e-4, 1e-4):
        history = tj.friction_history(system, motion, time_step=h)
        scale = np.max(np.abs(states[:, 0]))
        errors.append(np.max(np.abs(np.asarray(history.quantity) - states[:, 0])) / scale)
        stroke = np.max(np.abs(np.asarray(history.stroke) - states[:, 1]))
        assert stroke < 5 * errors[-1] * np.max(np.abs(states[:, 1])) + 1e-12
    assert errors[1] < 2e-3
    assert 2.0 < errors[0] / errors[1] < 8.0  # first order: about 4 for a step 4 times shorter


def test_white_noise_statistics_agree_with_the_event_driven_reference():
    psd = 500.0
    Mg, Cg, Kg, g = _reference_matrices("force")
    natural = 2 * math.pi * 4.0
    reference = random_friction.statistics(
        Mg, Cg, Kg, g, float(PAPER.friction_force), [1.0, 0.0], psd=psd, cutoff=10 * natural,
        samples=20, duration=20.0, transient=5.0, seed=11, output_step=0.002)
    settings = tj.MonteCarloSettings(samples=400, duration=20.0, transient=5.0, seed=11)
    ours = tj.monte_carlo(tj.as_building(PAPER, "force"), tj.StationaryLoad("white_noise", psd),
                          settings=settings)
    for name in ("rms", "peak"):
        combined = math.hypot(float(getattr(ours, f"{name}_se")), reference[f"{name}_se"])
        assert abs(float(getattr(ours, name)) - reference[name]) <= 3 * combined, (
            name, float(getattr(ours, name)), reference[name], combined)
    # friction matters here: the frictionless RMS is well apart
    free = float(tj.rms_response(tj.as_building(PAPER.replace(friction_force=0.0)),
                                 tj.StationaryLoad("white_noise", psd)))
    assert abs(free - reference["rms"]) > 6 * reference["rms_se"]
