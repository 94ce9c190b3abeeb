"""Monte Carlo with friction against independent answers: without friction the exact
stationary variance (Lyapunov, itself checked against the receptance's H2 integral) and
the exact non-stationary covariance under an envelope (its differential equation
integrated by scipy); with friction an independent event-driven simulator
(`reference/random_friction.py`: scipy, one realisation at a time, its own noise), path
by path under a record and in distribution under white noise; and the exact laws of
Coulomb friction (homogeneity)."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import tid_jax as tj
from tests._model.test_building import MASSES, STIFFNESSES, B
from tests.reference import building_linear

STRUCTURE = tj.Structure.shear_building(MASSES, STIFFNESSES, damping_ratio=0.02)
FIRST = float(STRUCTURE.modes()[0][0])
KANAI_TAJIMI = tj.StationaryLoad("kanai_tajimi", 0.01, ground_frequency=2 * FIRST,
                                 ground_damping=0.4)
SHORT = tj.MonteCarloSettings(samples=96, duration=40.0, seed=3)


def _paper(ff=20.0, on="force", **changes):
    return tj.as_building(tj.paper_system().replace(friction_force=ff, **changes), on)


def _within(estimate, se, exact, sigmas=3.0):
    assert abs(float(estimate) - exact) <= sigmas * float(se), (float(estimate), exact,
                                                                 float(se))


@pytest.mark.parametrize("on, kind, floor", [("force", "displacement", 1),
                                             ("ground", "drift", 2),
                                             ("ground", "acceleration", 3)])
def test_frictionless_monte_carlo_is_the_lyapunov_variance(on, kind, floor):
    system = tj.BuildingTID(STRUCTURE, B, 0.0, 4e4, 500.0, spring_floor=3, inerter_floor=2,
                            load=on, terminal_mass=10.0, parasitic_damping=30.0)
    load = KANAI_TAJIMI if on == "ground" else tj.StationaryLoad("white_noise", 2.0)
    quantity = tj.Quantity(kind, floor)
    result = tj.monte_carlo(system, load, quantity, settings=SHORT)
    exact = float(tj.rms_response(system, load, quantity))
    _within(result.rms, result.rms_se, exact)
    assert float(result.rms_se) < 0.02 * exact
    # the peak of a stationary Gaussian process over 30 s: a few RMS
    assert 2.5 < float(result.peak) / exact < 5.0


def test_enveloped_noise_has_the_non_stationary_covariance():
    # dP/dt = A P + P A^T + e(t)^2 2 pi S0 B B^T from rest, on the reference matrices
    system = _paper(0.0)
    load = tj.StationaryLoad("white_noise", 1000.0)
    envelope = lambda t: tj.jennings_envelope(t, 2.0, 6.0, 0.4)
    settings = tj.MonteCarloSettings(samples=400, duration=12.0, seed=5)
    result = tj.monte_carlo(system, load, settings=settings, envelope=envelope)
    p = tj.paper_system()
    Mg, Cg, Kg = building_linear.generalised_matrices(
        [[float(p.host_mass)]], [[float(p.host_stiffness)]], [[float(p.host_damping)]],
        b=float(p.inertance), k=float(p.tid_stiffness), c=float(p.tid_damping),
        spring_floor=1, inerter_floor=0)
    g = building_linear.generalised_load([[float(p.host_mass)]], load="force")
    m = Mg.shape[0]
    inverse = np.linalg.inv(Mg)
    A = np.block([[np.zeros((m, m)), np.eye(m)], [-inverse @ Kg, -inverse @ Cg]])
    Bv = np.concatenate([np.zeros(m), inverse @ g])

    def rate(t, p):
        P = p.reshape(2 * m, 2 * m)
        e = float(envelope(t))
        return (A @ P + P @ A.T + e**2 * 2 * math.pi * 1000.0 * np.outer(Bv, Bv)).ravel()

    h = result.time_step
    times = np.arange(1, int(round(12.0 / h)) + 1) * h
    solution = solve_ivp(rate, (0.0, times[-1]), np.zeros(4 * m * m), t_eval=times,
                         rtol=1e-9, atol=1e-20, max_step=0.05)
    mean_square = float(np.mean(solution.y[0]))
    _within(result.rms, result.rms_se, math.sqrt(mean_square))


def test_coulomb_friction_is_homogeneous():
    # the friction force and the load scaled by lam (S0 by lam^2): every path scales by lam
    load = tj.StationaryLoad("white_noise", 700.0)
    settings = tj.MonteCarloSettings(samples=16, duration=10.0, transient=3.0, time_step=1e-3)
    base = tj.monte_carlo(_paper(20.0), load, settings=settings)
    scaled = tj.monte_carlo(_paper(60.0), tj.StationaryLoad("white_noise", 6300.0),
                            settings=settings)
    np.testing.assert_allclose(scaled.mean_squares, 9 * base.mean_squares, rtol=1e-9)
    np.testing.assert_allclose(scaled.peaks, 3 * base.peaks, rtol=1e-9)


def test_narrow_smoothing_approaches_exact_friction():
    load = tj.StationaryLoad("white_noise", 700.0)
    settings = tj.MonteCarloSettings(samples=16, duration=10.0, transient=3.0, time_step=1e-3)
    exact = tj.monte_carlo(_paper(), load, settings=settings)
    errors = []
    for width in (1e-3, 1e-4, 1e-5):
        smooth = tj.monte_carlo(_paper(friction_width=width), load, settings=settings)
        errors.append(abs(float(smooth.rms) / float(exact.rms) - 1))
    assert errors[2] < 1e-3 and errors[0] > errors[1] > errors[2]


def test_friction_history_without_friction_is_the_linear_history():
    load = tj.StationaryLoad("kanai_tajimi", 0.05, ground_frequency=15.0, ground_damping=0.6)
    motion = tj.synthetic_motion(load, 8.0, 0.01, seed=2).scaled_to(0.2)
    system = tj.BuildingTID(STRUCTURE, B, 0.0, 4e4, 500.0, spring_floor=2, inerter_floor=1,
                            load="ground", terminal_mass=10.0)
    for kind in ("displacement", "acceleration"):
        quantity = tj.Quantity(kind, 2)
        linear = tj.linear_history(system, motion, quantity)
        history = tj.friction_history(system, motion, quantity)
        scale = float(linear.peak)
        np.testing.assert_allclose(history.quantity, linear.quantity, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(history.stroke, linear.stroke, rtol=0,
                                   atol=1e-10 * float(np.max(np.abs(linear.stroke))))


@pytest.mark.parametrize("change, message", [
    (dict(samples=1), "samples"), (dict(duration=-1.0), "duration"),
    (dict(transient=70.0), "transient"), (dict(seed=-2), "seed"),
    (dict(time_step=0.0), "time_step"),
])
def test_bad_settings_name_the_input(change, message):
    with pytest.raises(ValueError, match=message):
        tj.MonteCarloSettings(**change)


def test_what_monte_carlo_cannot_take_is_named():
    load = tj.StationaryLoad("white_noise", 1.0)
    compliant = _paper(friction_width=1e-3, terminal_mass=2.0, series_stiffness=1e6,
                       backlash=1e-3)
    with pytest.raises(ValueError, match="backlash"):
        tj.monte_carlo(compliant, load)
    with pytest.raises(ValueError, match="infinite variance"):
        tj.monte_carlo(_paper(on="ground"), load, tj.Quantity("acceleration"))
    with pytest.raises(ValueError, match="at least twice"):
        tj.monte_carlo(_paper(), load, settings=tj.MonteCarloSettings(duration=4.0))
    with pytest.raises(ValueError, match="load='ground'"):
        tj.friction_history(_paper(), tj.synthetic_motion(load, 1.0, 0.01))
