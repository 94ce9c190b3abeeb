"""Design under random and recorded loads against independent answers: Warburton's
closed-form H2 optimum without friction; the pathwise gradient of the Monte Carlo
estimate against its difference quotients; the Monte Carlo design against scipy's
Nelder-Mead on the same estimate; the linearised design on the linearisation that is
checked against the receptance (test_stationary.py); the optimum's sensitivities
against re-optimised designs and the exact laws of Coulomb friction; the record-suite
design without friction against scipy minimising over the linear history (itself checked
against Newmark)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize

import tid_jax as tj
from tid_jax._loads._monte_carlo import first_period, plan
from tid_jax._loads._random_design import _linearised_log_rms, log_mean_square, log_mean_squares
from tid_jax._runtime._outcomes import outcome_code

LOAD = tj.StationaryLoad("white_noise", 700.0)
# a fixed time step: the same steps whatever the inertance (its first period)
SMALL = tj.MonteCarloSettings(samples=16, duration=10.0, transient=3.0, time_step=1.4e-3,
                              seed=4)


def _paper(ff=20.0, on="force", **changes):
    return tj.as_building(tj.paper_system().replace(friction_force=ff, **changes), on)


def _estimate(system, settings=SMALL, load=LOAD):
    """The Monte Carlo ln mean square at (ln k, ln c), compiled, and its gradient."""
    run_plan, key = plan(system, settings), jax.random.key(settings.seed)
    f = lambda x: log_mean_square(x, system, load, tj.Quantity(), run_plan, key,
                                  settings.samples)
    return jax.jit(f), jax.jit(jax.grad(f))


def _log_tuning(system):
    return jnp.log(jnp.stack([system.tid_stiffness, system.tid_damping]))


def _smooth():
    """The paper's TID with friction smoothed over 0.02 of the frictionless RMS stroke
    velocity (a width proportional to the load, so Coulomb's homogeneity holds): with
    exact friction the estimate has kinks wherever a step turns from stick to slip, and
    local minima within about 1e-5 of its least ln mean square."""
    return _paper(friction_width=None)


@pytest.fixture(scope="module")
def design():
    """The Monte Carlo design of `_smooth` under white noise (700 N^2 s/rad)."""
    return tj.retune_random(_smooth(), LOAD, [700.0], settings=SMALL, tol=1e-8)


def test_frictionless_retune_is_warburton_s_optimum():
    system = _paper(0.0, host_damping=0.0)
    result = tj.retune_random(system, LOAD, [100.0, 1000.0])
    mu = float(system.inertance) / 1500.0
    natural = math.sqrt(float(system.structure.stiffness_matrix[0, 0]) / 1500.0)
    k, c = np.asarray(result.tid_stiffness), np.asarray(result.tid_damping)
    b = float(system.inertance)
    np.testing.assert_allclose(np.sqrt(k / b) / natural, math.sqrt(1 + mu / 2) / (1 + mu),
                               rtol=1e-5)
    np.testing.assert_allclose(c / (2 * np.sqrt(k * b)), math.sqrt(
        mu * (1 + 3 * mu / 4) / (4 * (1 + mu) * (1 + mu / 2))), rtol=1e-5)
    assert np.all(np.asarray(result.rms_after_se) == 0)
    assert np.all(np.asarray(result.rms_before_se) == 0)
    at = tj.StationaryLoad("white_noise", 1000.0)
    assert float(result.rms_before[1]) == pytest.approx(
        float(tj.rms_response(system, at)), rel=1e-12)


@pytest.mark.parametrize("width", [0.0, 1e-3])
def test_pathwise_gradient_is_the_difference_quotient(width):
    system = _paper(friction_width=width)
    f, grad = _estimate(system)
    x = _log_tuning(system)
    step = 1e-6
    quotient = [(f(x.at[i].add(step)) - f(x.at[i].add(-step))) / (2 * step) for i in range(2)]
    np.testing.assert_allclose(grad(x), quotient, rtol=1e-6, atol=1e-7)


def test_monte_carlo_design_is_the_minimum_of_its_estimate(design):
    system, result = _smooth(), design
    assert bool(result.converged[0])
    f, _ = _estimate(system)
    tuning = jnp.log(jnp.stack([result.tid_stiffness[0], result.tid_damping[0]]))
    # scipy's Nelder-Mead on the same estimate (common random numbers), from the given
    # tuning: it finds nothing lower
    found = minimize(lambda x: float(f(jnp.asarray(x))), np.asarray(_log_tuning(system)),
                     method="Nelder-Mead", options=dict(xatol=1e-6, fatol=1e-10))
    assert float(f(tuning)) <= found.fun + 1e-9
    np.testing.assert_allclose(np.asarray(tuning), found.x, atol=1e-3)
    # judged by an independent run, the design beats the given (Den Hartog) tuning
    assert float(result.rms_after[0]) < float(result.rms_before[0]) - 3 * float(
        result.rms_before_se[0])


def test_linearised_design_minimises_the_linearisation(design):
    system, result, load = _smooth(), design, LOAD
    tuning = jnp.log(jnp.stack([result.linearised_stiffness[0],
                                result.linearised_damping[0]]))
    # the objective is the linearisation checked against the receptance (test_stationary)
    for scale in (0.9, 1.0, 1.1):
        tuned = system.replace(tid_stiffness=result.linearised_stiffness[0] * scale,
                               tid_damping=result.linearised_damping[0] / scale)
        linear = tj.statistical_linearisation(tuned, load)
        value = _linearised_log_rms(_log_tuning(tuned), (system, load, tj.Quantity()))
        assert float(jnp.exp(value)) == pytest.approx(float(linear.rms), rel=1e-8)
    gradient = jax.grad(_linearised_log_rms)(tuning, (system, load, tj.Quantity()))
    assert float(jnp.max(jnp.abs(gradient))) < 1e-4
    # a design the linearisation prefers is judged by Monte Carlo too
    assert np.isfinite(float(result.rms_linearised[0]))
    assert float(result.rms_linearised_se[0]) > 0


def test_exact_sensitivities_are_differences_of_h2_optima():
    system = _paper(0.0)
    k, c = tj.h2_tuning(system, LOAD)
    optimum = system.replace(tid_stiffness=k, tid_damping=c)
    result = tj.random_sensitivities(optimum, LOAD, exact=True)
    step = 1e-4
    rows = []
    for sign in (1, -1):
        changed = system.replace(inertance=system.inertance * math.exp(sign * step))
        kk, cc = tj.h2_tuning(changed, LOAD)
        rms = float(tj.rms_response(changed.replace(tid_stiffness=kk, tid_damping=cc), LOAD))
        rows.append(np.log([rms, kk, cc]))
    differences = (rows[0] - rows[1]) / (2 * step)
    np.testing.assert_allclose([result.rms[0], result.tid_stiffness[0],
                                result.tid_damping[0]], differences, rtol=1e-4)
    # without friction the RMS goes as sqrt(S0) and the optimum does not move with S0
    assert float(result.rms[2]) == pytest.approx(0.5, rel=1e-9)
    np.testing.assert_allclose([result.tid_stiffness[2], result.tid_damping[2]], 0.0,
                               atol=1e-8)


def test_monte_carlo_sensitivities_obey_coulomb_homogeneity(design):
    system, result = _smooth(), design
    optimum = system.replace(tid_stiffness=result.tid_stiffness[0],
                             tid_damping=result.tid_damping[0])
    sens = tj.random_sensitivities(optimum, LOAD, settings=SMALL)
    # ff and the load scaled together (S0 by the square) scale every path: at the optimum
    # the RMS elasticities obey e_ff + 2 e_S0 = 1 and the tuning's e_ff + 2 e_S0 = 0
    assert float(sens.rms[1] + 2 * sens.rms[2]) == pytest.approx(1.0, abs=1e-6)
    for values in (sens.tid_stiffness, sens.tid_damping):
        assert abs(float(values[1] + 2 * values[2])) < 1e-4


def test_monte_carlo_sensitivity_is_the_difference_of_designs(design):
    system = _smooth()
    designs = []
    step = 0.05
    for scale in (math.exp(step), math.exp(-step)):
        changed = system.replace(inertance=system.inertance * scale)
        result = tj.retune_random(changed, LOAD, [700.0], settings=SMALL, tol=1e-8)
        designs.append(np.log([float(result.tid_stiffness[0]), float(result.tid_damping[0])]))
    optimum = system.replace(tid_stiffness=design.tid_stiffness[0],
                             tid_damping=design.tid_damping[0])
    sens = tj.random_sensitivities(optimum, LOAD, settings=SMALL)
    differences = (designs[0] - designs[1]) / (2 * step)
    np.testing.assert_allclose([sens.tid_stiffness[0], sens.tid_damping[0]], differences,
                               rtol=2e-2)


def test_frictionless_record_design_is_scipy_s_on_the_linear_history():
    kt = tj.StationaryLoad("kanai_tajimi", 0.05, ground_frequency=15.0, ground_damping=0.6)
    motions = [tj.synthetic_motion(kt, 6.0, 0.01, seed=s).scaled_to(0.2) for s in (1, 2)]
    system = _paper(0.0, on="ground")
    result = tj.design_for_records(system, motions)
    assert bool(result.converged)

    def mean_peak(x):
        k, c = np.exp(x)
        tuned = system.replace(tid_stiffness=k, tid_damping=c)
        return float(np.mean([tj.linear_history(tuned, m).peak for m in motions]))

    found = minimize(mean_peak, np.asarray(_log_tuning(system)), method="Nelder-Mead",
                     options=dict(xatol=1e-5, fatol=1e-12))
    ours = mean_peak(np.log([float(result.tid_stiffness), float(result.tid_damping)]))
    assert ours <= found.fun * (1 + 1e-4)
    assert float(np.mean(result.peak_after)) == pytest.approx(ours, rel=1e-9)
    before = [tj.linear_history(system, m) for m in motions]
    np.testing.assert_allclose(result.peak_before, [h.peak for h in before], rtol=1e-9)
    np.testing.assert_allclose(result.rms_before, [h.rms for h in before], rtol=1e-9)


def test_stroke_limited_record_design_is_scipy_s_constrained_minimum():
    # The frictionless design above moves the stroke peak from 24 to 29 mm; at 24.3 mm
    # the limit is active. scipy's SLSQP on the linear history (an independent model and
    # optimiser) finds the constrained minimum; ours aims 0.1% inside the limit.
    kt = tj.StationaryLoad("kanai_tajimi", 0.05, ground_frequency=15.0, ground_damping=0.6)
    motions = [tj.synthetic_motion(kt, 6.0, 0.01, seed=s).scaled_to(0.2) for s in (1, 2)]
    system = _paper(0.0, on="ground")
    limit = 0.0243
    result = tj.design_for_records(system, motions, stroke_limit=limit)
    assert bool(result.converged) and bool(result.within_stroke_limit)
    seen = {}

    def evaluate(x):
        if tuple(x) not in seen:
            k, c = np.exp(x)
            histories = [tj.linear_history(system.replace(tid_stiffness=k, tid_damping=c), m)
                         for m in motions]
            seen[tuple(x)] = (float(np.mean([h.peak for h in histories])),
                              max(float(np.max(np.abs(h.stroke))) for h in histories))
        return seen[tuple(x)]

    found = minimize(lambda x: evaluate(x)[0], np.asarray(_log_tuning(system)), method="SLSQP",
                     constraints=[{"type": "ineq", "fun": lambda x: 1 - evaluate(x)[1] / limit}],
                     options=dict(ftol=1e-12))
    assert found.success and evaluate(found.x)[1] <= limit * (1 + 1e-9)
    ours = np.log([float(result.tid_stiffness), float(result.tid_damping)])
    peak, stroke = evaluate(ours)
    assert stroke <= limit and peak <= found.fun * (1 + 1e-3)
    np.testing.assert_allclose(ours, found.x, atol=2e-2)
    np.testing.assert_allclose(result.stroke_peak_after, [
        float(np.max(np.abs(tj.linear_history(system.replace(
            tid_stiffness=float(result.tid_stiffness), tid_damping=float(result.tid_damping)),
            m).stroke))) for m in motions], rtol=1e-6)
    free = tj.design_for_records(system, motions)
    assert float(np.max(free.stroke_peak_after)) > limit  # the limit is active
    assert float(np.mean(free.peak_after)) < peak
    with pytest.raises(ValueError, match="stroke_limit"):
        tj.design_for_records(system, motions, stroke_limit=-0.01)


def _friction_records():
    kt = tj.StationaryLoad("kanai_tajimi", 0.05, ground_frequency=15.0, ground_damping=0.6)
    return [tj.synthetic_motion(kt, duration, 0.01, seed=s).scaled_to(0.05)
            for s, duration in ((1, 6.0), (2, 4.5))]


def _history_statistics(system, motions, **options):
    """Each record's peak, RMS and stroke peak by `friction_history`."""
    histories = [tj.friction_history(system, m, **options) for m in motions]
    return np.array([[float(h.peak), float(h.rms), float(np.max(np.abs(h.stroke)))]
                     for h in histories])


def test_record_design_with_friction_steps_the_records_as_friction_history():
    # Records of two lengths (padded in the design): with exact friction the design's
    # peaks, RMS and stroke peaks before and after are those of the exact stick-slip
    # history; with a time step, those of the held-friction history.
    motions = _friction_records()
    system = _paper(on="ground")
    result = tj.design_for_records(system, motions)
    assert bool(result.converged)
    assert float(np.mean(result.peak_after)) < float(np.mean(result.peak_before))
    designed = system.replace(tid_stiffness=float(result.tid_stiffness),
                              tid_damping=float(result.tid_damping))
    for tuned, ours in ((system, (result.peak_before, result.rms_before,
                                  result.stroke_peak_before)),
                        (designed, (result.peak_after, result.rms_after,
                                    result.stroke_peak_after))):
        exact = _history_statistics(tuned, motions)
        np.testing.assert_allclose(np.stack(ours, axis=1), exact, rtol=1e-9, atol=0)
    step = first_period(system) / 200
    held = tj.design_for_records(system, motions, time_step=step, max_steps=1)
    np.testing.assert_allclose(
        np.stack([held.peak_before, held.rms_before, held.stroke_peak_before], axis=1),
        _history_statistics(system, motions, time_step=step), rtol=1e-9, atol=0)
    # the held scheme is within its first-order error of the exact history
    np.testing.assert_allclose(held.peak_before, result.peak_before, rtol=1e-2)
    with pytest.raises(ValueError, match="load='ground'"):
        tj.design_for_records(_paper(), motions)
    with pytest.raises(ValueError, match="GroundMotion"):
        tj.design_for_records(system, [])
    with pytest.raises(ValueError, match="max_events"):
        tj.design_for_records(system, motions, max_events=-1)


def test_record_design_keeps_within_its_bounds():
    # The free design lowers c to 48 N s/m, at the default lower bound (Den Hartog's
    # c / 10); with c at least 150 N s/m the design lies on that bound, and the bounded
    # minimum is no worse than the free design held at the bound.
    motions = _friction_records()
    system = _paper(on="ground")
    free = tj.design_for_records(system, motions)
    np.testing.assert_allclose([free.stiffness_bounds, free.damping_bounds],
                               tj.default_bounds(system))
    bounds = ((1e4, 2e5), (150.0, 2e3))
    result = tj.design_for_records(system, motions, bounds=bounds)
    assert bool(result.converged) and bool(result.at_bound)
    # (within Nelder-Mead's tolerance of the bound)
    assert 150.0 <= float(result.tid_damping) <= 150.0 * (1 + 1e-3)
    assert 1e4 < float(result.tid_stiffness) < 2e5
    np.testing.assert_allclose(result.damping_bounds, bounds[1])
    held = system.replace(tid_stiffness=float(free.tid_stiffness), tid_damping=150.0)
    assert float(np.mean(result.peak_after)) <= float(
        np.mean(_history_statistics(held, motions)[:, 0])) * (1 + 1e-6)
    assert float(np.mean(result.peak_after)) > float(np.mean(free.peak_after))
    for bad in (((1e4, 2e5),), ((2e5, 1e4), (150.0, 2e3)), ((1e4, 2e5), (-1.0, 2e3))):
        with pytest.raises(ValueError, match="bounds must be"):
            tj.design_for_records(system, motions, bounds=bad)


def _exact_log_squares(system, load, x):
    """ln of the exact mean squares of the top floor and the stroke at (ln k, ln c), by
    the Lyapunov covariance read directly."""
    tuned = system.replace(tid_stiffness=float(np.exp(x[0])), tid_damping=float(np.exp(x[1])))
    P = np.asarray(tj.stationary_covariance(tuned, load))
    return np.log([P[0, 0], P[tuned.floors, tuned.floors]])


def test_bounded_stroke_limited_frictionless_design_is_scipy_s():
    # Without friction: the H2 optimum (k 43.9 kN/m, stroke RMS 2.11 mm at S0 = 700)
    # against an upper bound on k of 40 kN/m (stroke 1.90 mm there) and a stroke limit
    # of 1.79 mm, both active.
    # scipy's trust-constr on the exact covariance (difference quotients) is the reference.
    system = _paper(0.0)
    free = tj.retune_random(system, LOAD, [700.0])
    limit = 0.85 * float(free.stroke_rms_after[0])
    bounds = ((1e3, 4e4), (10.0, 5e3))
    result = tj.retune_random(system, LOAD, [700.0], bounds=bounds, stroke_limit=limit)
    assert float(free.tid_stiffness[0]) > 4e4 and not bool(free.at_bound[0])
    assert bool(result.converged[0]) and bool(result.at_bound[0])
    assert bool(result.stroke_limited[0]) and bool(result.within_stroke_limit[0])
    x = np.log([float(result.tid_stiffness[0]), float(result.tid_damping[0])])
    ours = _exact_log_squares(system, LOAD, x)
    assert 0.5 * ours[1] <= math.log(limit) + 1e-9
    assert float(np.exp(0.5 * ours[1])) == pytest.approx(float(result.stroke_rms_after[0]),
                                                         rel=1e-9)
    found = minimize(lambda v: _exact_log_squares(system, LOAD, v)[0], np.log([3e4, 400.0]),
                     method="trust-constr", bounds=np.log(bounds),
                     constraints=[{"type": "ineq", "fun": lambda v: math.log(limit) - 0.5 *
                                   _exact_log_squares(system, LOAD, v)[1]}],
                     options=dict(xtol=1e-10, gtol=1e-10, maxiter=2000))
    assert 0.5 * _exact_log_squares(system, LOAD, found.x)[1] <= math.log(limit) + 1e-6
    # the same mean square within 0.2% (ours aims 0.1% inside the limit)
    assert ours[0] <= found.fun + 2e-3
    assert float(result.rms_after[0]) > float(free.rms_after[0])
    np.testing.assert_allclose(result.stiffness_bounds, bounds[0])
    np.testing.assert_allclose(result.damping_bounds, bounds[1])


# Shorter runs for the designs at a low intensity: the design against an optimiser on the
# same estimate, not a converged one.
SHORT = tj.MonteCarloSettings(samples=8, duration=6.0, transient=2.0, time_step=1.4e-3,
                              seed=4)


def test_low_intensity_design_is_bounded_and_stroke_limited_as_scipy_s():
    # At S0 = 30 the free optimum braces the host through the stuck inerter; the default
    # bounds (10x Den Hartog) hold c, and a stroke limit of 0.1 mm RMS (below the
    # bounded design's, about 0.12 mm) is active too. scipy's trust-constr on the same
    # estimate (common random numbers, its exact gradient) is the reference: it ends on
    # the limit as well.
    system, low, limit = _smooth(), tj.StationaryLoad("white_noise", 30.0), 1e-4
    result = tj.retune_random(system, low, [30.0], settings=SHORT, stroke_limit=limit)
    assert bool(result.converged[0]) and bool(result.at_bound[0])
    assert bool(result.stroke_limited[0]) and bool(result.within_stroke_limit[0])
    box = np.log(np.asarray(tj.default_bounds(system)))
    run_plan, key = plan(system, SHORT), jax.random.key(SHORT.seed)
    f = jax.jit(lambda x: log_mean_squares(x, system, low, tj.Quantity(), run_plan, key,
                                           SHORT.samples))
    jac = jax.jit(jax.jacfwd(f))
    x = np.log([float(result.tid_stiffness[0]), float(result.tid_damping[0])])
    ours = np.asarray(f(jnp.asarray(x)))
    assert np.all((x >= box[:, 0] - 1e-12) & (x <= box[:, 1] + 1e-12))
    assert 0.5 * ours[1] <= math.log(limit)
    found = minimize(lambda v: float(f(jnp.asarray(v))[0]), np.asarray(_log_tuning(system)),
                     jac=lambda v: np.asarray(jac(jnp.asarray(v)))[0], method="trust-constr",
                     bounds=box, constraints=[{
                         "type": "ineq",
                         "fun": lambda v: math.log(limit) - 0.5 * float(f(jnp.asarray(v))[1]),
                         "jac": lambda v: -0.5 * np.asarray(jac(jnp.asarray(v)))[1]}],
                     options=dict(xtol=1e-10, gtol=1e-9, maxiter=500))
    theirs = 0.5 * float(f(jnp.asarray(found.x))[1])
    assert math.log(limit) - 2e-3 <= theirs <= math.log(limit) + 1e-6  # on the limit
    assert ours[0] <= found.fun + 3e-3  # ln mean square; ours aims 0.1% inside the limit


def test_locked_linearisation_is_flagged():
    # At S0 = 30 the spring and damper's RMS force is below what the friction holds: the
    # linearisation has no self-consistent solution (the scan of statistical_linearisation
    # finds none) and the design says so.
    system, low = _paper(), tj.StationaryLoad("white_noise", 30.0)
    assert tj.statistical_linearisation(system, low).locked
    result = tj.retune_random(system, low, [30.0], settings=SHORT)
    assert int(result.linearised_status[0]) == outcome_code(tj.Outcome.locked)
    assert "no statistical linearisation" in result.linearised_messages()[0]
    assert np.isnan(float(result.linearised_stiffness[0]))
    assert np.isnan(float(result.rms_linearised[0]))
    assert np.isfinite(float(result.rms_after[0]))


def test_bad_bounds_and_stroke_limit_are_refused():
    system = _paper(0.0)
    for bounds in (((2e4, 1e4), (10.0, 100.0)), ((1e4, 2e4),), ((-1.0, 2e4), (1.0, 2.0))):
        with pytest.raises(ValueError, match="bounds"):
            tj.retune_random(system, LOAD, [700.0], bounds=bounds)
    with pytest.raises(ValueError, match="stroke_limit"):
        tj.retune_random(system, LOAD, [700.0], stroke_limit=-0.01)
