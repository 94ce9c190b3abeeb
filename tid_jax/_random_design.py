"""RMS design of the TID with its friction under stationary random loads: k and c retuned
per intensity (S0) on the Monte Carlo estimate with common random numbers, and on the
statistical linearisation, both designs judged by an independent Monte Carlo run; the
sensitivities of the Monte Carlo optimum.

With common random numbers (the same noise at every design) the estimate of the mean
square is a deterministic, continuous and piecewise smooth function of (k, c), and its
gradient along the paths (`jax.grad` through every step) is exact: BFGS minimises it.
Without friction the RMS is exact (Lyapunov) and so is the optimum (`h2_tuning`).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float

from ._bfgs import CappedBFGS, CappedNewtonDescent, InterpolatingArmijo
from ._building import BuildingTID, Quantity, log_tuned, log_tuning_of
from ._monte_carlo import (
    MonteCarloSettings,
    check_load,
    monte_carlo,
    plan,
    run,
    stationary_inputs,
    stationary_start,
    stationary_stepper,
)
from ._stationary import StationaryLoad, h2_tuning, rms_response, stationary_covariance

_MAX_LOG_STEP = 0.5  # the longest BFGS step in (ln k, ln c)
SENSITIVITY_PARAMETERS = ("inertance", "friction_force", "psd")


def _scaled(system: BuildingTID, load: StationaryLoad, log_scales):
    """The system and load with b, ff and S0 times `exp(log_scales)`."""
    b, ff, s0 = jnp.exp(log_scales)
    system = eqx.tree_at(lambda s: (s.inertance, s.friction_force), system,
                         (system.inertance * b, system.friction_force * ff))
    return system, eqx.tree_at(lambda ld: ld.psd, load, load.psd * s0)


def log_mean_square(log_tuning, system, load, quantity, run_plan, key, samples):
    """ln of the Monte Carlo mean square of `quantity` at (ln k, ln c), the noise from
    `key` (common random numbers)."""
    tuned = log_tuned(system, log_tuning)
    stepper = stationary_stepper(tuned, load, quantity, run_plan.time_step)
    z0 = stationary_start(tuned, load, key, samples)
    squares, _, _ = run(stepper, z0, stationary_inputs(run_plan, key, samples),
                        run_plan.chunks)
    return jnp.log(jnp.mean(squares[:, 0]) / (run_plan.steps - run_plan.first))


def _solver(rtol: float):
    return CappedBFGS(rtol=rtol, atol=rtol, descent=CappedNewtonDescent(max_step=_MAX_LOG_STEP),
                      search=InterpolatingArmijo(max_step=_MAX_LOG_STEP))


@eqx.filter_jit
def _minimise(objective, start, args, rtol, max_steps):
    solution = optx.minimise(objective, _solver(rtol), start, args=args, throw=False,
                             max_steps=max_steps)
    return solution.value, solution.result == optx.RESULTS.successful


def _monte_carlo_objective(log_tuning, args):
    return log_mean_square(log_tuning, *args)


def _linearised_log_rms(log_tuning, args):
    """ln RMS of `quantity` under the self-consistent statistical linearisation at
    (ln k, ln c): Newton on ln sigma_v from the frictionless sigma_v, its derivatives
    implicit; infinite where Newton fails (no self-consistent solution found)."""
    system, load, quantity = args
    tuned = log_tuned(system, log_tuning)
    index = 2 * tuned.coordinates - 1
    kappa = tuned.friction_force * jnp.sqrt(2 / jnp.pi)

    def with_damping(log_sigma):
        return eqx.tree_at(lambda s: s.parasitic_damping, tuned,
                           tuned.parasitic_damping + kappa / jnp.exp(log_sigma))

    def gap(log_sigma, _):
        P = stationary_covariance(with_damping(log_sigma), load)
        return 0.5 * jnp.log(P[index, index]) - log_sigma

    free = stationary_covariance(tuned, load)[index, index]
    solution = optx.root_find(gap, optx.Newton(rtol=1e-10, atol=1e-10), 0.5 * jnp.log(free),
                              throw=False, max_steps=64)
    value = jnp.log(rms_response(with_damping(solution.value), load, quantity))
    return jnp.where(solution.result == optx.RESULTS.successful, value, jnp.inf)


class RandomDesign(eqx.Module):
    """k and c retuned per intensity. Per level of `psd_levels` (S0): the Monte Carlo
    design `tid_stiffness`, `tid_damping` (N/m, N s/m) and `converged`; the RMS of the
    quantity (SI) with the given tuning, `rms_before`, and the design's, `rms_after`, with
    their standard errors (`_se`), from Monte Carlo runs independent of the design's
    (seed + 1) on the same steps and noise for every tuning; the linearisation's design
    `linearised_stiffness`, `linearised_damping` (NaN where it found none) and its RMS by
    that same run, `rms_linearised` and `rms_linearised_se`. Without friction everything
    is exact (Lyapunov, `h2_tuning`) and the standard errors are 0."""

    psd_levels: Float[Array, " levels"]
    tid_stiffness: Float[Array, " levels"]
    tid_damping: Float[Array, " levels"]
    converged: Bool[Array, " levels"]
    rms_before: Float[Array, " levels"]
    rms_before_se: Float[Array, " levels"]
    rms_after: Float[Array, " levels"]
    rms_after_se: Float[Array, " levels"]
    linearised_stiffness: Float[Array, " levels"]
    linearised_damping: Float[Array, " levels"]
    rms_linearised: Float[Array, " levels"]
    rms_linearised_se: Float[Array, " levels"]


def _level(system, load, quantity, settings, rtol, max_steps):
    """One level's row of `RandomDesign` (see there), as floats."""
    if float(system.friction_force) == 0:
        k, c = h2_tuning(system, load, quantity)
        before = float(rms_response(system, load, quantity))
        after = float(rms_response(log_tuned(system, jnp.log(jnp.array([k, c]))), load,
                                   quantity))
        return dict(tid_stiffness=k, tid_damping=c, converged=True, rms_before=before,
                    rms_before_se=0.0, rms_after=after, rms_after_se=0.0,
                    linearised_stiffness=k, linearised_damping=c, rms_linearised=after,
                    rms_linearised_se=0.0)
    free = system.replace(friction_force=0.0)
    start = jnp.log(jnp.array(h2_tuning(free, load, quantity)))
    run_plan = plan(system, settings)
    key = jax.random.key(settings.seed)
    args = (system, load, quantity, run_plan, key, settings.samples)
    design, converged = _minimise(_monte_carlo_objective, start, args, rtol, max_steps)
    linear, linear_ok = _minimise(_linearised_log_rms, start, (system, load, quantity), rtol,
                                  max_steps)
    linear_ok = bool(linear_ok) and bool(jnp.isfinite(_linearised_log_rms(linear, (
        system, load, quantity))))
    # every tuning judged on the same steps and noise, independent of the design's
    judge = MonteCarloSettings(samples=settings.samples, duration=settings.duration,
                               transient=run_plan.first * run_plan.time_step,
                               time_step=run_plan.time_step, seed=settings.seed + 1)
    row = dict(tid_stiffness=float(jnp.exp(design[0])), tid_damping=float(jnp.exp(design[1])),
               converged=bool(converged))
    for name, tuning in (("before", None), ("after", design), ("linearised", linear)):
        if name == "linearised" and not linear_ok:
            row.update(rms_linearised=np.nan, rms_linearised_se=np.nan)
            continue
        tuned = system if tuning is None else log_tuned(system, tuning)
        result = monte_carlo(tuned, load, quantity, settings=judge)
        row[f"rms_{name}"], row[f"rms_{name}_se"] = float(result.rms), float(result.rms_se)
    k_lin, c_lin = np.exp(np.asarray(linear)) if linear_ok else (np.nan, np.nan)
    row.update(linearised_stiffness=float(k_lin), linearised_damping=float(c_lin))
    return row


def retune_random(system: BuildingTID, load: StationaryLoad, psd_levels,
                  quantity: Quantity = Quantity(), *,
                  settings: MonteCarloSettings = MonteCarloSettings(), rtol: float = 1e-5,
                  max_steps: int = 64, progress=None) -> RandomDesign:
    """The TID's (k, c) minimising the RMS of `quantity` under `load` at each S0 of
    `psd_levels` (see `RandomDesign`), from the frictionless H2 optimum: BFGS on
    (ln k, ln c) of the Monte Carlo mean square (`settings`, common random numbers), and
    of the linearisation's. `progress(done, total)` is called after each level."""
    check_load(system, load, quantity)
    levels = np.asarray(psd_levels, float).reshape(-1)
    if levels.size == 0 or not np.all(np.isfinite(levels) & (levels > 0)):
        raise ValueError(f"psd_levels must be positive numbers, got {psd_levels!r}")
    rows = []
    for number, level in enumerate(levels):
        at_level = eqx.tree_at(lambda ld: ld.psd, load, jnp.asarray(level))
        rows.append(_level(system, at_level, quantity, settings, rtol, max_steps))
        if progress is not None:
            progress(number + 1, levels.size)
    columns = {name: jnp.asarray([row[name] for row in rows]) for name in rows[0]}
    return RandomDesign(psd_levels=jnp.asarray(levels), **columns)


class RandomSensitivities(eqx.Module):
    """Elasticities (d ln y / d ln p) of the Monte Carlo RMS optimum, for p in
    `parameters` (inertance b, friction force ff, the load's S0): of its `rms`, and of
    the optimal `tid_stiffness` and `tid_damping`. The RMS's follow from the envelope
    theorem, the tuning's from implicit differentiation of the optimum's conditions
    (exact second derivatives along the paths, common random numbers)."""

    parameters: tuple[str, ...] = eqx.field(static=True)
    rms: Float[Array, " p"]
    tid_stiffness: Float[Array, " p"]
    tid_damping: Float[Array, " p"]


def random_sensitivities(system: BuildingTID, load: StationaryLoad,
                         quantity: Quantity = Quantity(), *,
                         settings: MonteCarloSettings = MonteCarloSettings(),
                         exact: bool = False) -> RandomSensitivities:
    """The sensitivities of the RMS optimum, `system` carrying the optimal (k, c) (from
    `retune_random` with the same `settings`); `exact`: the frictionless Lyapunov RMS
    instead of Monte Carlo."""
    check_load(system, load, quantity)
    run_plan = plan(system, settings)
    key = jax.random.key(settings.seed)
    start = jnp.concatenate([log_tuning_of(system), jnp.zeros(3)])
    gradient, hessian = _derivatives(start, system, load, quantity, run_plan, key,
                                     settings.samples, exact)
    tuning = -jnp.linalg.solve(hessian[:2, :2], hessian[:2, 2:])
    return RandomSensitivities(parameters=SENSITIVITY_PARAMETERS, rms=0.5 * gradient[2:],
                               tid_stiffness=tuning[0], tid_damping=tuning[1])


def _sensitivity_objective(variables, system, load, quantity, run_plan, key, samples, exact):
    """ln mean square at (ln k, ln c, ln of the scales of b, ff and S0)."""
    scaled, scaled_load = _scaled(system, load, variables[2:])
    if exact:
        return 2 * jnp.log(rms_response(log_tuned(scaled, variables[:2]), scaled_load, quantity))
    return log_mean_square(variables[:2], scaled, scaled_load, quantity, run_plan, key,
                           samples)


@eqx.filter_jit
def _derivatives(start, *args):
    gradient = jax.grad(_sensitivity_objective)
    return gradient(start, *args), jax.jacfwd(gradient)(start, *args)
