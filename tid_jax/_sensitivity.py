"""Sensitivities of the peak response, at a given tuning and at the retuned optimum."""


from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._model._building import BuildingTID, Quantity, checked_quantity
from ._model._checks import (
    check_amplitude,
    check_distinct,
    is_positive,
)
from ._model._system import TIDSystem
from ._optimise._best_tunings import BestTunings, best_tunings, check_best
from ._optimise._design_evaluation import (
    Context,
    Scenario,
    coordinates,
    evaluate_designs,
    without_jumped_peaks,
)
from ._optimise._smooth_max import smooth_max
from ._optimise._sqp import Model, decrement, finite, trust_step
from ._orbit._settings import SolverSettings
from ._peaks import _band
from ._retune import RetuneSettings, check_retune_options
from ._runtime._parallel import serial


class SensitivitySettings(eqx.Module):
    """Settings of the derivatives at the retuned optimum (`sensitivities`). Defaults live
    here only.

    - `polish_steps`: Newton steps at most, on central differences, that polish the
      optimiser's optimum before it is differentiated.
    - `polish_tol`: the Newton decrement of the smooth log peak that the polishing aims
      at.
    - `noise_factor`: the noise of the orbit solver in the gradients, and jumps of ~1e-8
      in the log peak where a sample's concavity flips, can hold the decrement above
      `polish_tol` (most where peaks of different amplitudes balance): within
      `noise_factor * polish_tol` (1e-6 of the log peak by default) the optimum counts as
      converged.
    - `polish_accuracy`: the polishing's orbits are this many times tighter (integration
      and periodicity) than the solver settings': the curvatures, differences of
      gradients over the stencil's step, multiply the orbits' errors by
      1 / `stencil_step`. At the default settings, c*'s elasticities would break its
      exact scaling law 2 e_K + e_C = 1 by up to 0.05.
    - `stencil_step`: step in the design variables of the differences of exact gradients
      that give the curvature of each refined peak (central; the curvature of the smooth
      maximum across peaks is exact). Smaller steps amplify the noise of the orbit solver
      in the gradients, larger ones the truncation error.
    - `same_curvatures`: the polishing's steps keep the curvatures of the central stencil
      at their start while they move less than this fraction of `stencil_step`.
    - `max_step`: longest polishing step in the design variables (0.25 is about 28% in
      k).
    """

    polish_steps: int = 3
    polish_tol: float = 1e-9
    noise_factor: float = 1000.0
    polish_accuracy: float = 10.0
    stencil_step: float = 1e-3
    same_curvatures: float = 0.1
    max_step: float = 0.25

    def __check_init__(self):
        for name in ("polish_tol", "noise_factor", "polish_accuracy", "stencil_step",
                     "max_step"):
            value = getattr(self, name)
            if not is_positive(value):
                raise ValueError(f"SensitivitySettings.{name} must be a positive number, "
                                 f"got {value!r}")
        if not (is_positive(self.same_curvatures) or self.same_curvatures == 0):
            raise ValueError("SensitivitySettings.same_curvatures must be a number >= 0, "
                             f"got {self.same_curvatures!r}")
        value = self.polish_steps
        if not (isinstance(value, int) and not isinstance(value, bool) and value >= 0):
            raise ValueError("SensitivitySettings.polish_steps must be an integer >= 0, "
                             f"got {value!r}")


# --- sensitivities -------------------------------------------------------------------------


class OptimumSensitivities(eqx.Module):
    """How the retuned optimum moves with each parameter. The optimum is the tuning
    (k*, c*) minimising the smooth maximum over the band of the host displacement (see
    `best_tunings`), solved to stationarity. Arrays are ordered as
    `Sensitivities.parameters`; their `tid_stiffness` and `tid_damping` entries are 0, as
    the optimum does not depend on the tuning it starts from. SI units.

    - `tid_stiffness` (N/m), `tid_damping` (N s/m): k*, c*.
    - `host_peak`, `stroke_peak`: peak |x| and |y| over the band at the optimum, m.
    - `smooth_peak`: the smooth maximum over the band of |x| that the optimum minimises
      (a few tenths of a percent above `host_peak`), m.
    - `host_elasticity`: d ln peak* / d ln p of the optimal host peak: of `smooth_peak`
      exactly, by the envelope theorem (the partial derivative at fixed k*, c*);
      `host_derivative = host_peak * host_elasticity / p`, m per unit of p.
    - `stroke_derivative`, `stroke_elasticity`: of the inerter peak at the optimum, as the
      optimum moves (partial derivative plus the change through k* and c*).
    - `stiffness_derivative`, `stiffness_elasticity`, `damping_derivative`,
      `damping_elasticity`: dk*/dp, dc*/dp (units of k or c per unit of p) and their
      elasticities, by implicit differentiation of the stationarity condition (elasticities
      of c* are NaN when c* is at its bound 0, where dc*/dp = 0).
    - `gradient_norm`: |dG/du| at the optimum, G the smooth log peak and u the design
      variables (ln k, sqrt c); `iterations`: Newton steps; `converged`: a stationary point
      was found and every steady state converged; `damping_at_bound`: c* = 0.
    """

    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    host_peak: Float[Array, ""]
    stroke_peak: Float[Array, ""]
    smooth_peak: Float[Array, ""]
    host_derivative: Float[Array, " params"]
    host_elasticity: Float[Array, " params"]
    stroke_derivative: Float[Array, " params"]
    stroke_elasticity: Float[Array, " params"]
    stiffness_derivative: Float[Array, " params"]
    stiffness_elasticity: Float[Array, " params"]
    damping_derivative: Float[Array, " params"]
    damping_elasticity: Float[Array, " params"]
    gradient_norm: Float[Array, ""]
    iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    damping_at_bound: Bool[Array, ""]


class Sensitivities(eqx.Module):
    """Derivatives of the peak host displacement (a building's quantity) and of the inerter
    stroke over the band with respect to each parameter in `parameters` (`parameters_of`:
    the physical fields of `TIDSystem`, or a building's device, floors and storeys, and
    the `amplitude`; their units by `parameter_unit`), at the given tuning and, in
    `optimum` (None if not asked for), at the retuned optimum. SI units.

    - `values`: the parameters' values.
    - `host_peak`, `stroke_peak`: peak |x| and |y| over the band, m.
    - `host_derivative`, `stroke_derivative`: d peak / dp, m per unit of p.
    - `host_elasticity`, `stroke_elasticity`: d ln peak / d ln p = (p / peak) d peak / dp.
    - `converged`: every steady state in the band converged.

    `as_dict()` gives the same numbers keyed by parameter name.
    """

    parameters: tuple[str, ...] = eqx.field(static=True)
    values: Float[Array, " params"]
    host_peak: Float[Array, ""]
    stroke_peak: Float[Array, ""]
    host_derivative: Float[Array, " params"]
    host_elasticity: Float[Array, " params"]
    stroke_derivative: Float[Array, " params"]
    stroke_elasticity: Float[Array, " params"]
    converged: Bool[Array, ""]
    optimum: OptimumSensitivities | None

    def as_dict(self) -> dict[str, dict[str, float]]:
        """`{parameter: {quantity: value}}` with the per-parameter arrays of this result
        and, prefixed `optimum_`, of `optimum`."""
        arrays = {
            name: getattr(self, name)
            for name in (
                "values",
                "host_derivative",
                "host_elasticity",
                "stroke_derivative",
                "stroke_elasticity",
            )
        }
        if self.optimum is not None:
            for name in (
                "host_derivative",
                "host_elasticity",
                "stroke_derivative",
                "stroke_elasticity",
                "stiffness_derivative",
                "stiffness_elasticity",
                "damping_derivative",
                "damping_elasticity",
            ):
                arrays[f"optimum_{name}"] = getattr(self.optimum, name)
        return {
            parameter: {key: float(array[i]) for key, array in arrays.items()}
            for i, parameter in enumerate(self.parameters)
        }


def _polished(ctx, starts, sharpness, sensitivity_settings: SensitivitySettings):
    """For each `(scenario, u, z_init, at_bound)` of `starts`, the evaluation at the
    optimum of the smooth log peak of `retune` (of its last stage's `sharpness`) near u,
    with its smooth maximum, gradient and derivatives (a `Model`): at most
    `sensitivity_settings.polish_steps` Newton steps from u, aiming at a decrement below
    its `polish_tol` (along u0 alone, with u1 = 0, where the damping is at its bound),
    each round's evaluations of every start in one batch. Only the start is evaluated
    with its central stencil: the steps are far shorter than the stencil's
    (`ctx.stencil_step`), so that the curvatures of the refined peaks from its
    differences hold at every step, which is then evaluated alone (values and exact
    gradients); an optimum found further away than `same_curvatures` times the stencil's
    step is evaluated with its own."""
    tol = sensitivity_settings.polish_tol
    finals = evaluate_designs(ctx, [(u, [scenario], [z]) for scenario, u, z, _ in starts],
                              stencil="central")
    first = list(finals)
    models = [Model(*smooth_max(final.host_terms, sharpness)) for final in finals]
    # A start whose smooth maximum is not finite (a steady state failed) is not polished.
    moving = [i for i, model in enumerate(models) if finite(model)]
    for _ in range(sensitivity_settings.polish_steps):
        steps = {}
        for i in moving:
            free = slice(0, 1) if starts[i][3] else slice(0, 2)
            g, h = models[i].grad[free], models[i].curvature()[free, free]
            if decrement(g, h) >= tol:
                steps[i] = np.zeros(2)
                steps[i][free] = trust_step(g, h, sensitivity_settings.max_step)
        if not steps:
            break
        trials = evaluate_designs(ctx, [
            (finals[i].u + step, [starts[i][0]], finals[i].states())
            for i, step in steps.items()], stencil="centre")
        moving = []
        for i, trial in zip(steps, trials, strict=True):
            dgrad = without_jumped_peaks(first[i].host_terms.dgrad, trial.centres()[0].located,
                                         first[i].centres()[0].located)
            trial = trial._replace(host_terms=trial.host_terms._replace(dgrad=dgrad))
            trial_model = Model(*smooth_max(trial.host_terms, sharpness))
            if trial_model.value < models[i].value:
                finals[i], models[i] = trial, trial_model
                moving.append(i)
    # Where the steps went further, the curvatures are evaluated again there.
    far = [i for i, ((_, u, _, _), final) in enumerate(zip(starts, finals, strict=True))
           if np.max(np.abs(final.u - u))
           > sensitivity_settings.same_curvatures * ctx.stencil_step]
    if far:
        again = evaluate_designs(ctx, [(finals[i].u, [starts[i][0]], finals[i].states())
                                       for i in far], stencil="central")
        for i, final in zip(far, again, strict=True):
            finals[i], models[i] = final, Model(*smooth_max(final.host_terms, sharpness))
    return finals, models


def _optimum_starts(ctx, amplitudes, best: "BestTunings", indices):
    """Where `_polished` starts from at the best tunings `best[index]` of the nominal
    scenarios at `amplitudes` (`indices`, one each): `(scenario, u, z_init, at_bound)`
    each, the orbits of every amplitude solved in one batch."""
    at_bound = [bool(best.damping_at_bound[index]) for index in indices]
    k, c = (np.array([float(tuning[index]) for index in indices])
            for tuning in (best.tid_stiffness, best.tid_damping))
    z_inits = ctx.cold_states(k, c, amplitudes, 1.0)
    return [(Scenario(float(amplitude), 1.0, 0.0), ctx.design(k_i, 0.0 if bound else c_i), z,
             bound)
            for amplitude, k_i, c_i, z, bound in zip(amplitudes, k, c, z_inits, at_bound,
                                                      strict=True)]


def _optimum_sensitivities(ctx, theta, best: "BestTunings", index, at_bound, final, model,
                           sensitivity_settings: SensitivitySettings):
    """`OptimumSensitivities` at the best tuning `best[index]`, polished (`final` and its
    `model`, from `_polished`) and differentiated through its stationarity condition: in
    (u0, u1), or where the damping is at its bound, in u0 alone with dc*/dp = 0 (the bound
    stays active). Where a steady state failed there (the smooth maximum is not finite),
    every peak and derivative is NaN, not converged."""
    if not finite(model):
        return _unsolved_optimum(ctx, best, index, at_bound, final)
    u = final.u
    k, c = ctx.tuning(u)
    g, h_uu = model.grad, model.curvature()
    free = [0] if at_bound else [0, 1]
    du_dp = np.zeros((2, len(ctx.other)))
    du_dp[free] = -np.linalg.solve(h_uu[np.ix_(free, free)], model.hess[free, 2:])
    centre = final.centres()[0]
    values, _, stroke_grads, _ = coordinates(ctx, u, final.stencils[0], "y")
    stroke_grad = stroke_grads[int(np.argmax(np.where(centre.peak_y, values, -np.inf)))]
    n = len(ctx.parameters)
    d_log_host, d_log_stroke, dk, dc = (np.zeros(n) for _ in range(4))
    # Envelope theorem, with the first-order effect of the gradient left at the optimum
    # (the smooth maximum is stiff across a balance of peaks: a small step there leaves a
    # gradient that is not negligible against the partial derivative).
    d_log_host[ctx.other] = g[2:] + g[:2] @ du_dp
    d_log_stroke[ctx.other] = stroke_grad[2:] + stroke_grad[:2] @ du_dp
    dk[ctx.other] = k * du_dp[0]
    dc[ctx.other] = 2 * ctx.c_ref * u[1] * du_dp[1]
    host_peak, stroke_peak = centre.host_peak(), centre.stroke_peak()
    within = sensitivity_settings.noise_factor * sensitivity_settings.polish_tol
    at_optimum = decrement(g[free], h_uu[np.ix_(free, free)]) < within
    # At the bound the peak must rise with the damping (a positive curvature in u1).
    at_optimum &= not at_bound or h_uu[1, 1] > 0
    return OptimumSensitivities(
        tid_stiffness=jnp.asarray(k),
        tid_damping=jnp.asarray(c),
        host_peak=jnp.asarray(host_peak),
        stroke_peak=jnp.asarray(stroke_peak),
        smooth_peak=jnp.asarray(float(np.exp(model.value))),
        host_derivative=jnp.asarray(host_peak * d_log_host),
        host_elasticity=jnp.asarray(theta * d_log_host),
        stroke_derivative=jnp.asarray(stroke_peak * d_log_stroke),
        stroke_elasticity=jnp.asarray(theta * d_log_stroke),
        stiffness_derivative=jnp.asarray(dk),
        stiffness_elasticity=jnp.asarray(theta * dk / k),
        damping_derivative=jnp.asarray(dc),
        # The elasticity of a quantity held at zero is undefined.
        damping_elasticity=jnp.asarray(np.full(n, np.nan) if at_bound else theta * dc / c),
        gradient_norm=jnp.asarray(float(np.linalg.norm(g[free]))),
        iterations=jnp.asarray(int(best.iterations[index])),
        converged=jnp.asarray(bool(at_optimum and final.converged()
                                   and best.converged[index])),
        damping_at_bound=jnp.asarray(at_bound),
    )


def _unsolved_optimum(ctx, best: "BestTunings", index, at_bound, final) -> OptimumSensitivities:
    """`OptimumSensitivities` at the best tuning `best[index]` (as polished, `final`) where
    its steady states failed: the tuning, NaN for every peak and derivative, not
    converged."""
    k, c = ctx.tuning(final.u)
    nan, nans = jnp.asarray(np.nan), jnp.full(len(ctx.parameters), np.nan)
    return OptimumSensitivities(
        tid_stiffness=jnp.asarray(k), tid_damping=jnp.asarray(c), host_peak=nan,
        stroke_peak=nan, smooth_peak=nan, host_derivative=nans, host_elasticity=nans,
        stroke_derivative=nans, stroke_elasticity=nans, stiffness_derivative=nans,
        stiffness_elasticity=nans, damping_derivative=nans, damping_elasticity=nans,
        gradient_norm=nan, iterations=jnp.asarray(int(best.iterations[index])),
        converged=jnp.asarray(False), damping_at_bound=jnp.asarray(at_bound))


def _best_index(best: "BestTunings", system, band, amplitude) -> tuple[int, int]:
    """Where `best` holds the nominal scenario at `amplitude`, else `ValueError`."""
    check_best(best, system)
    if best.omegas.shape != band.shape or not np.allclose(best.omegas, band, rtol=1e-12):
        raise ValueError("omegas differ from the band best was computed on")
    scales, amps = np.asarray(best.host_frequency_scales), np.asarray(best.amplitudes)
    i, j = np.flatnonzero(np.isclose(scales, 1.0, rtol=1e-12)), np.flatnonzero(
        np.isclose(amps, amplitude, rtol=1e-12))
    if not (i.size and j.size):
        raise ValueError(f"best holds no tuning for {amplitude:g} N at the nominal host "
                         f"frequency (amplitudes {amps.tolist()}, scales {scales.tolist()})")
    return int(i[0]), int(j[0])


def sensitivities(
    system: TIDSystem | BuildingTID,
    amplitude: ArrayLike,
    *,
    omegas: ArrayLike | None = None,
    quantity: Quantity | None = None,
    optimum: bool = True,
    best: "BestTunings | None" = None,
    settings: SolverSettings | None = None,
    max_steps: int = 60,
    tol: float = 1e-4,
    retune_settings: RetuneSettings = RetuneSettings(),
    sensitivity_settings: SensitivitySettings = SensitivitySettings(),
) -> Sensitivities:
    """Sensitivities of the peak steady-state host displacement and inerter stroke over the
    band `omegas` (rad/s; default `default_omegas(system)`) at forcing amplitude `amplitude`
    (N) to every physical parameter and the amplitude: derivatives and elasticities, by
    forward-mode implicit differentiation through the periodic orbits.

    With `optimum=True` also at the retuned optimum (see `OptimumSensitivities`): the
    tuning that `retune` finds (from `best`, a `BestTunings` of this system and band
    holding `amplitude`, or else from `best_tunings` with `max_steps`, `tol` and
    `retune_settings`), polished by at most `sensitivity_settings.polish_steps` Newton
    steps on the same objective (the smooth maximum of `retune_settings.sharpness[-1]`,
    aiming at a Newton decrement below `sensitivity_settings.polish_tol`, converged within
    `noise_factor` times that; its orbits solved `polish_accuracy` times tighter than
    `settings`), then differentiated through its stationarity condition rather than
    re-optimised. Where the optimal damping
    is at its bound 0, only k* moves: dc*/dp = 0 and the elasticities of c* are NaN.
    The parameters are `parameters_of(system)`: the physical fields of the steady-state
    model and the amplitude, with a compliant device's series stiffness and backlash (a
    rigid device has neither to vary). At zero backlash its derivative is the one-sided
    one (the free play opening) and its elasticity 0.

    A `BuildingTID`'s peak is its `quantity`'s (default the top floor's displacement),
    its parameters its device's, every floor's mass, every storey's stiffness, a factor
    on its damping matrix and the amplitude (`building_parameters`); its optimum is the
    retune's, from the first mode's Den Hartog tuning.

    **Arguments:**

    - `system`: the `TIDSystem` (or `BuildingTID`) at its given tuning.
    - `amplitude`: forcing amplitude A, N (a building's ground acceleration: m/s2).
    - `omegas`: the band, rad/s (default `default_omegas(system)`).
    - `quantity`: a building's measured response (`Quantity`).
    - `optimum`: also the sensitivities at the retuned optimum.
    - `best`: a `BestTunings` of this system and band holding `amplitude` (default: found
      afresh when `optimum` is True).
    - `settings`: `SolverSettings` of every steady state.
    - `max_steps`, `tol`, `retune_settings`: of the optimiser that finds the optimum (as
      in `retune`).
    - `sensitivity_settings`: `SensitivitySettings` of the polishing and the derivatives
      at the optimum.

    **Returns:** a `Sensitivities` (parameters in the order `parameters_of(system)`).
    """
    amplitude = check_amplitude(amplitude)
    return amplitude_sensitivities(
        system, [amplitude], omegas=omegas, quantity=quantity, optimum=optimum, best=best,
        settings=settings,
        max_steps=max_steps, tol=tol, retune_settings=retune_settings,
        sensitivity_settings=sensitivity_settings)[0]


def amplitude_sensitivities(
    system: TIDSystem | BuildingTID,
    amplitudes: ArrayLike,
    *,
    omegas: ArrayLike | None = None,
    quantity: Quantity | None = None,
    optimum: bool = True,
    best: "BestTunings | None" = None,
    settings: SolverSettings | None = None,
    max_steps: int = 60,
    tol: float = 1e-4,
    retune_settings: RetuneSettings = RetuneSettings(),
    sensitivity_settings: SensitivitySettings = SensitivitySettings(),
    progress: Callable[[str], None] | None = None,
    map_lanes: Callable = serial,
) -> list[Sensitivities]:
    """`sensitivities` at each of the forcing `amplitudes` (N, distinct), the steady
    states of every amplitude solved in the same batches (and, with `optimum=True` and no
    `best`, the optimum of every amplitude found by one `best_tunings`). `progress`, if
    given, is called with a line as each step ends (those of `best_tunings` where it
    runs, the given tuning's derivatives, the optima's); `map_lanes` maps the independent
    lanes (see `retune`). The other arguments are those of `sensitivities`.

    **Returns:** a list of `Sensitivities`, one per amplitude, in their order.
    """
    quantity = checked_quantity(system, quantity, "sensitivities")
    settings = SolverSettings() if settings is None else settings
    amplitudes = check_distinct("amplitudes", amplitudes)
    band = _band(system, omegas)
    if not isinstance(optimum, bool):
        raise ValueError(f"optimum must be True or False, got {optimum!r}")
    check_retune_options(max_steps, tol, retune_settings)
    if not isinstance(sensitivity_settings, SensitivitySettings):
        raise ValueError("sensitivity_settings must be a SensitivitySettings, got "
                         f"{type(sensitivity_settings).__name__}")
    step = sensitivity_settings.stencil_step
    ctx = Context(system, band, settings, locate=True, stencil_step=step, map_lanes=map_lanes,
                  quantity=quantity)
    if optimum and best is None:
        best = best_tunings(system, amplitudes, omegas=band, settings=settings,
                            max_steps=max_steps, tol=tol, retune_settings=retune_settings,
                            progress=progress, map_lanes=map_lanes, quantity=quantity)
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    thetas = [ctx.theta(k, c, amplitude) for amplitude in amplitudes]
    given = ctx.evaluate([(theta, 1.0, None) for theta in thetas])
    say = progress if progress is not None else (lambda message: None)
    say(f"derivatives at the given tuning: {sum(curves.converged for curves in given)}/"
        f"{len(given)} amplitude(s) converged")
    optimal = [None] * amplitudes.size
    if optimum:
        indices = [_best_index(best, system, band, amplitude) for amplitude in amplitudes]
        starts = _optimum_starts(ctx, amplitudes, best, indices)
        given_settings = settings.for_system(system)
        tight = given_settings.tighter(sensitivity_settings.polish_accuracy)
        # Exact friction has no integration error to tighten: the context of the given
        # tuning serves (one compiled program, not two that compute the same).
        accurate = ctx if tight == given_settings else Context(
            system, band, tight, locate=True, stencil_step=step, map_lanes=map_lanes,
            quantity=quantity)
        finals, models = _polished(accurate, starts, retune_settings.sharpness[-1],
                                   sensitivity_settings)
        optimal = [
            _optimum_sensitivities(ctx, theta, best, index, start[3], final, model,
                                   sensitivity_settings)
            for theta, index, start, final, model in zip(thetas, indices, starts, finals, models,
                                                         strict=True)
        ]
        say(f"derivatives at the retuned optima: {sum(bool(o.converged) for o in optimal)}/"
            f"{len(optimal)} amplitude(s) converged")
    return [_sensitivities(ctx, theta, curves, optimal_i)
            for theta, curves, optimal_i in zip(thetas, given, optimal, strict=True)]


def _sensitivities(ctx, theta, given, optimal) -> Sensitivities:
    """`Sensitivities` from the curves `given` at the parameters `theta` and the
    `OptimumSensitivities` `optimal` (or None)."""
    log_host, d_log_host = given.top("x")
    log_stroke, d_log_stroke = given.top("y")
    host_peak, stroke_peak = np.exp(log_host), np.exp(log_stroke)
    return Sensitivities(
        parameters=ctx.parameters,
        values=jnp.asarray(theta),
        host_peak=jnp.asarray(host_peak),
        stroke_peak=jnp.asarray(stroke_peak),
        host_derivative=jnp.asarray(host_peak * d_log_host),
        host_elasticity=jnp.asarray(theta * d_log_host),
        stroke_derivative=jnp.asarray(stroke_peak * d_log_stroke),
        stroke_elasticity=jnp.asarray(theta * d_log_stroke),
        converged=jnp.asarray(given.converged),
        optimum=optimal,
    )


def elasticity_series(results) -> tuple[dict, dict, dict | None, dict | None]:
    """The elasticities of `Sensitivities` at several amplitudes (`results`, one each) as
    one series per parameter: of the host peak and the stroke at the given tuning, and,
    where the optimum was found, at the optimum for every parameter but the tuning itself
    (on which the optimum does not depend; None otherwise)."""
    parameters = results[0].parameters

    def series(get, names):
        return {name: np.array([np.asarray(get(r))[parameters.index(name)] for r in results])
                for name in names}

    host = series(lambda r: r.host_elasticity, parameters)
    stroke = series(lambda r: r.stroke_elasticity, parameters)
    if results[0].optimum is None:
        return host, stroke, None, None
    physical = [name for name in parameters if name not in ("tid_stiffness", "tid_damping")]
    return (host, stroke, series(lambda r: r.optimum.host_elasticity, physical),
            series(lambda r: r.optimum.stroke_elasticity, physical))

