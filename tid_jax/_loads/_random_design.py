"""RMS design of the TID with its friction under stationary random loads: k and c retuned
per intensity (S0) on the Monte Carlo estimate with common random numbers, and on the
statistical linearisation, both designs judged by an independent Monte Carlo run; the
sensitivities of the Monte Carlo optimum.

With common random numbers (the same noise at every design) the estimate of the mean
square is a deterministic, continuous and piecewise smooth function of (k, c), and its
gradient along the paths (`jax.grad` through every step) is exact: BFGS minimises it.
Without friction the RMS is exact (Lyapunov) and so is the optimum (`h2_tuning`).

The design is kept within bounds on k and c (by default a factor `BOUND_FACTOR` either
way of the first mode's Den Hartog tuning) and, if given, the stroke's RMS within a
limit: where the free optimum breaks either, SLSQP (scipy) solves the constrained problem
on the same estimate, with its exact gradients, from the free optimum held in the bounds.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import scipy.optimize
from jaxtyping import Array, Bool, Float, Int

from .._model._building import (
    BuildingTID,
    Quantity,
    building_of,
    first_mode_tunings,
    log_tuned,
    log_tuning_of,
)
from .._model._system import TIDSystem, check_values
from .._optimise._bfgs import CappedBFGS, CappedNewtonDescent, InterpolatingArmijo
from .._runtime._outcomes import Outcome, outcome_code, outcome_message
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
# The default bounds: k and c within this factor either way of the first mode's Den
# Hartog tuning.
BOUND_FACTOR = 10.0
# The stroke limit is aimed this fraction below the given one (SLSQP meets its
# constraints to its tolerance); a design whose stroke RMS is within `STROKE_ACTIVE` of
# the limit has it active.
STROKE_MARGIN = 1e-3
STROKE_ACTIVE = 2e-3
_AT_BOUND = 1e-6  # |ln k - ln bound| (or c's) within which a bound is active


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


def log_mean_squares(log_tuning, system, load, quantity, run_plan, key, samples):
    """ln of the Monte Carlo mean squares of `quantity` and of the stroke at
    (ln k, ln c), as `log_mean_square`."""
    tuned = log_tuned(system, log_tuning)
    stepper = stationary_stepper(tuned, load, quantity, run_plan.time_step)
    z0 = stationary_start(tuned, load, key, samples)
    squares, _, _ = run(stepper, z0, stationary_inputs(run_plan, key, samples),
                        run_plan.chunks)
    return jnp.log(jnp.mean(squares, axis=0) / (run_plan.steps - run_plan.first))


def exact_log_mean_squares(log_tuning, system, load, quantity):
    """ln of the exact (Lyapunov) mean squares of `quantity` and of the stroke of the
    frictionless system at (ln k, ln c)."""
    tuned = log_tuned(system, log_tuning)
    stroke = stationary_covariance(tuned, load)[tuned.floors, tuned.floors]
    return jnp.stack([2 * jnp.log(rms_response(tuned, load, quantity)), jnp.log(stroke)])


def _with_jacobian(function):
    """`x -> (function(x), its Jacobian)`, compiled (forward mode: two inputs), with
    `.values`, the values alone."""
    both = jax.jit(lambda x: (function(x), jax.jacfwd(function)(x)))

    def pair(x):
        return both(x)

    pair.values = jax.jit(function)
    return pair


def _constrained(pair, start, box, log_limit, rtol, max_steps):
    """SLSQP (scipy) on `pair(x) -> ((objective, ln mean square stroke), Jacobian)` over
    x = (ln k, ln c) in `box` (2 x 2, ln), the stroke's RMS within exp(`log_limit`)
    (None: free), from `start` held in the box. Returns the design and whether SLSQP
    succeeded."""
    cache = {}

    def evaluate(x):
        key = tuple(np.asarray(x, float))
        if key not in cache:
            value, jacobian = pair(jnp.asarray(key))
            cache[key] = (np.asarray(value, float), np.asarray(jacobian, float))
        return cache[key]

    constraints = [] if log_limit is None else [{
        "type": "ineq", "fun": lambda x: np.atleast_1d(log_limit - 0.5 * evaluate(x)[0][1]),
        "jac": lambda x: -0.5 * evaluate(x)[1][1:2]}]
    solution = scipy.optimize.minimize(
        lambda x: evaluate(x)[0][0], np.clip(np.asarray(start, float), box[:, 0], box[:, 1]),
        jac=lambda x: evaluate(x)[1][0], method="SLSQP", bounds=[tuple(b) for b in box],
        constraints=constraints, options={"ftol": max(rtol**2, 1e-14), "maxiter": max_steps})
    ok = bool(solution.success) and bool(np.all(np.isfinite(evaluate(solution.x)[0])))
    return jnp.asarray(solution.x), ok


def _bounded(pair, design, converged, box, log_limit, rtol, max_steps):
    """The free optimum `design` where it keeps within `box` and the stroke limit
    (exp(`log_limit`), None: none), else `_constrained`'s from it. Returns the design
    and whether its search converged."""
    x = np.asarray(design, float)
    inside = bool(np.all((x >= box[:, 0]) & (x <= box[:, 1])))
    within = log_limit is None or bool(
        0.5 * float(pair.values(jnp.asarray(x))[1]) <= log_limit + STROKE_MARGIN)
    if inside and within:
        return design, converged
    return _constrained(pair, x, box, log_limit, rtol, max_steps)


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
    that same run, `rms_linearised` and `rms_linearised_se`, and `linearised_status`
    (codes of `Outcome`, read by `linearised_messages()`). Without friction
    everything is exact (Lyapunov, `h2_tuning`) and the standard errors are 0.

    The bounds, `stiffness_bounds` (N/m) and `damping_bounds` (N s/m), each (low, high),
    and the `stroke_limit` on the stroke's RMS (m; None: none). Per level: `at_bound`, the
    design is on a bound; `stroke_limited`, its stroke RMS is at the limit (within
    `STROKE_ACTIVE`); `within_stroke_limit`, by the design's own estimate; and the
    stroke's RMS (m) with the given tuning and the design, `stroke_rms_before` and
    `stroke_rms_after`, by the independent run."""

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
    linearised_status: Int[Array, " levels"]
    at_bound: Bool[Array, " levels"]
    stroke_limited: Bool[Array, " levels"]
    within_stroke_limit: Bool[Array, " levels"]
    stroke_rms_before: Float[Array, " levels"]
    stroke_rms_after: Float[Array, " levels"]
    stiffness_bounds: Float[Array, " 2"]
    damping_bounds: Float[Array, " 2"]
    stroke_limit: float | None = eqx.field(static=True, default=None)

    def linearised_messages(self) -> list[str]:
        """The message of each level's `linearised_status`."""
        return [outcome_message(Outcome, code)
                for code in np.asarray(self.linearised_status)]


def _linearised(system, load, quantity, start, box, rtol, max_steps):
    """The linearisation's design (ln k, ln c) within `box` and its outcome's code."""
    args = (system, load, quantity)
    if not bool(jnp.isfinite(_linearised_log_rms(start, args))):
        return start, outcome_code(Outcome.locked)
    try:
        design, ok = _minimise(_linearised_log_rms, start, args, rtol, max_steps)
    except eqx.EquinoxRuntimeError:  # the search stepped where the inerter locks
        return start, outcome_code(Outcome.not_stationary)
    finite = bool(jnp.isfinite(_linearised_log_rms(design, args)))
    if finite:
        pair = _with_jacobian(lambda x: jnp.stack([_linearised_log_rms(x, args), 0.0]))
        design, ok = _bounded(pair, design, bool(ok), box, None, rtol, max_steps)
        finite = bool(jnp.isfinite(_linearised_log_rms(design, args)))
    outcome = (Outcome.ok if finite and ok else Outcome.locked
               if not finite else Outcome.not_stationary)
    return design, outcome_code(outcome)


def _level(system, load, quantity, settings, rtol, max_steps, box, stroke_limit):
    """One level's row of `RandomDesign` (see there), as floats."""
    log_limit = None if stroke_limit is None else math.log(stroke_limit * (1 - STROKE_MARGIN))
    free = system.replace(friction_force=0.0)
    start = jnp.log(jnp.array(h2_tuning(free, load, quantity)))
    if float(system.friction_force) == 0:
        pair = _with_jacobian(lambda x: exact_log_mean_squares(x, system, load, quantity))
        design, converged = _bounded(pair, start, True, box, log_limit, rtol, max_steps)
        stroke = [float(jnp.sqrt(jnp.exp(pair.values(x)[1]))) for x in (log_tuning_of(system),
                                                                   design)]
        row = dict(rms_before=float(rms_response(system, load, quantity)), rms_before_se=0.0,
                   rms_after=float(rms_response(log_tuned(system, design), load, quantity)),
                   rms_after_se=0.0, linearised_status=outcome_code(Outcome.ok),
                   stroke_rms_before=stroke[0], stroke_rms_after=stroke[1])
        row.update(linearised_stiffness=float(jnp.exp(design[0])),
                   linearised_damping=float(jnp.exp(design[1])),
                   rms_linearised=row["rms_after"], rms_linearised_se=0.0)
    else:
        run_plan = plan(system, settings)
        args = (system, load, quantity, run_plan, jax.random.key(settings.seed),
                settings.samples)
        design, converged = _minimise(_monte_carlo_objective, start, args, rtol, max_steps)
        pair = _with_jacobian(lambda x: log_mean_squares(x, *args))
        design, converged = _bounded(pair, design, bool(converged), box, log_limit, rtol,
                                     max_steps)
        linear, status = _linearised(system, load, quantity, start, box, rtol, max_steps)
        row = _judged(system, load, quantity, settings, run_plan, design, linear, status)
    x = np.asarray(design, float)
    stroke = float(jnp.sqrt(jnp.exp(pair.values(design)[1])))
    row.update(tid_stiffness=float(np.exp(x[0])), tid_damping=float(np.exp(x[1])),
               converged=bool(converged),
               at_bound=bool(np.any(np.abs(x[:, None] - box) < _AT_BOUND)),
               stroke_limited=stroke_limit is not None and stroke >= stroke_limit * (
                   1 - STROKE_ACTIVE),
               within_stroke_limit=stroke_limit is None or stroke <= stroke_limit)
    return row


def _judged(system, load, quantity, settings, run_plan, design, linear, status):
    """The RMS of the given tuning, the design and the linearisation's (`linear`, its
    outcome's code `status`), by one Monte Carlo run independent of the design's: the
    same steps and noise for every tuning."""
    judge = MonteCarloSettings(samples=settings.samples, duration=settings.duration,
                               transient=run_plan.first * run_plan.time_step,
                               time_step=run_plan.time_step, seed=settings.seed + 1)
    linear_ok = status == outcome_code(Outcome.ok)
    row = dict(linearised_status=status)
    for name, tuning in (("before", None), ("after", design), ("linearised", linear)):
        if name == "linearised" and not linear_ok:
            row.update(rms_linearised=np.nan, rms_linearised_se=np.nan)
            continue
        tuned = system if tuning is None else log_tuned(system, tuning)
        result = monte_carlo(tuned, load, quantity, settings=judge)
        row[f"rms_{name}"], row[f"rms_{name}_se"] = float(result.rms), float(result.rms_se)
        row[f"stroke_rms_{name}"] = float(result.stroke_rms)
    row.pop("stroke_rms_linearised", None)
    k_lin, c_lin = np.exp(np.asarray(linear)) if linear_ok else (np.nan, np.nan)
    row.update(linearised_stiffness=float(k_lin), linearised_damping=float(c_lin))
    return row


def default_bounds(system: BuildingTID) -> tuple[tuple[float, float], tuple[float, float]]:
    """The default bounds of `retune_random`: `((k_low, k_high), (c_low, c_high))` (N/m,
    N s/m), `BOUND_FACTOR` either way of the first mode's Den Hartog tuning."""
    k, c = first_mode_tunings(system)["den_hartog"]
    return ((k / BOUND_FACTOR, k * BOUND_FACTOR), (c / BOUND_FACTOR, c * BOUND_FACTOR))


def check_bounds(bounds) -> np.ndarray:
    """The bounds as a 2 x 2 array (rows k and c), or ValueError."""
    try:
        box = np.asarray(bounds, float)
    except (TypeError, ValueError):
        box = np.zeros(0)
    if box.shape != (2, 2) or not np.all(np.isfinite(box) & (box > 0)) or np.any(
            box[:, 0] >= box[:, 1]):
        raise ValueError("bounds must be ((k_low, k_high), (c_low, c_high)), positive and "
                         f"finite with low < high, got {bounds!r}")
    return box


def retune_random(system: BuildingTID | TIDSystem, load: StationaryLoad, psd_levels,
                  quantity: Quantity = Quantity(), *,
                  settings: MonteCarloSettings = MonteCarloSettings(), tol: float = 1e-5,
                  max_steps: int = 64, bounds=None, stroke_limit: float | None = None,
                  progress=None) -> RandomDesign:
    """The TID's (k, c) minimising the RMS of `quantity` under `load` at each S0 of
    `psd_levels` (see `RandomDesign`), from the frictionless H2 optimum: BFGS on
    (ln k, ln c) of the Monte Carlo mean square (`settings`, common random numbers), and
    of the linearisation's. `bounds`: `((k_low, k_high), (c_low, c_high))` (N/m, N s/m;
    None: `default_bounds`), which both designs keep within; `stroke_limit` (m; None:
    none): the Monte Carlo design's stroke RMS at most this. Where the free optimum breaks
    either, SLSQP (scipy) finds the constrained one. `tol`: the optimisers' tolerance.
    `progress(done, total)` is called after each level. A `TIDSystem` is its host under
    a random force."""
    system = building_of(system, "force")
    check_load(system, load, quantity)
    levels = np.asarray(psd_levels, float).reshape(-1)
    if levels.size == 0 or not np.all(np.isfinite(levels) & (levels > 0)):
        raise ValueError(f"psd_levels must be positive numbers, got {psd_levels!r}")
    box = check_bounds(default_bounds(system) if bounds is None else bounds)
    if stroke_limit is not None:
        check_values("stroke_limit", stroke_limit, "positive")
        stroke_limit = float(stroke_limit)
    rows = []
    for number, level in enumerate(levels):
        at_level = eqx.tree_at(lambda ld: ld.psd, load, jnp.asarray(level))
        rows.append(_level(system, at_level, quantity, settings, tol, max_steps,
                           np.log(box), stroke_limit))
        if progress is not None:
            progress(number + 1, levels.size)
    columns = {name: jnp.asarray([row[name] for row in rows]) for name in rows[0]}
    return RandomDesign(psd_levels=jnp.asarray(levels), stiffness_bounds=jnp.asarray(box[0]),
                        damping_bounds=jnp.asarray(box[1]), stroke_limit=stroke_limit,
                        **columns)


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


def random_sensitivities(system: BuildingTID | TIDSystem, load: StationaryLoad,
                         quantity: Quantity = Quantity(), *,
                         settings: MonteCarloSettings = MonteCarloSettings(),
                         exact: bool = False) -> RandomSensitivities:
    """The sensitivities of the RMS optimum, `system` carrying the optimal (k, c) (from
    `retune_random` with the same `settings`); `exact`: the frictionless Lyapunov RMS
    instead of Monte Carlo."""
    system = building_of(system, "force")
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
