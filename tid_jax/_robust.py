"""One tuning for many scenarios: any tuning against the best of each
(`tuning_performance`), and the robust design (`robust_tune`)."""

from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._model._building import BuildingTID, Quantity, checked_quantity
from ._model._checks import (
    check_distinct,
    is_positive,
)
from ._model._system import PAPER_AMPLITUDES, PAPER_STROKE, TIDSystem
from ._optimise._best_tunings import BestTunings, check_best, checked_best
from ._optimise._design import scaled_hosts
from ._optimise._design_evaluation import (
    Context,
    Evaluation,
    Scenario,
    cold_start,
    evaluate_design,
    evaluation_of,
)
from ._optimise._smooth_max import Terms, smooth_max, term_weights
from ._optimise._sqp import Model, finite, minimise_stage, stationary
from ._orbit._sampled_peaks import (
    lane_grid_peaks,
)
from ._orbit._settings import SolverSettings
from ._response import batched, lane_response
from ._retune import RetuneSettings, check_retune_options
from ._runtime._outcomes import Outcome, outcome_code, outcome_message, outcome_messages
from ._runtime._parallel import map_shares, serial


class RobustSettings(eqx.Module):
    """Settings of the robust design's optimiser (`robust_tune`). Defaults live here only.

    **Fields:**

    - `sharpness`: sharpness of the smooth worst case of the scenarios' log peak ratios
      at each stage; its ratios need not balance as finely as the peaks of one optimum
      (`RetuneSettings.sharpness`).
    - `stroke_margin`: the stroke limit is aimed this fraction below the stated one on
      the design grid.
    - `check_refinement`: the stroke is then checked on a grid this many times finer
      than the design band; where it is over the limit there, the design-grid target is
      lowered by the excess and the design polished again,
    - `stroke_rounds`: at most this many times.
    - `max_step`: longest trust-region step in the design variables (0.25 is about 28%
      in k).
    - `min_step`: trust radius at which a stage gives up.
    - `noise_factor`: the optimiser aims at a Newton decrement below `tol`; the noise of
      the orbit solver in the gradients, and jumps of ~1e-8 in the log peak where a
      sample's concavity flips, can hold it above that: within `noise_factor * tol` the
      design counts as converged.
    - `feasibility`: |ln(stroke / target)| within which the stroke constraint is met.
    - `stencil_step`: step in the design variables of the forward differences of exact
      gradients that give the curvature of each refined peak (that of the smooth maximum
      across peaks is exact). Smaller steps amplify the noise of the orbit solver in the
      gradients, larger ones the truncation error.
    - `negligible_weight`: a scenario whose weight in the smooth worst case (and in the
      stroke's smooth maximum) is below this is evaluated at the design alone, without
      the neighbours that give the curvatures of its peaks: its share of the curvature,
      below this fraction of theirs, is left out; the value and gradient stay exact (the
      optimum is the same). 0 keeps every scenario's curvature.
    - `min_damping_start`: the search starts with the damping at least this fraction of
      Den Hartog's (as `retune` does): c = 0 is stationary in the design variables.
    """

    sharpness: tuple[float, ...] = (50.0, 1000.0)
    stroke_margin: float = 0.005
    check_refinement: int = 4
    stroke_rounds: int = 3
    max_step: float = 0.25
    min_step: float = 1e-8
    noise_factor: float = 1000.0
    feasibility: float = 1e-6
    stencil_step: float = 1e-3
    negligible_weight: float = 1e-3
    min_damping_start: float = 0.05

    def __check_init__(self):
        if not (isinstance(self.sharpness, tuple) and self.sharpness
                and all(is_positive(v) for v in self.sharpness)):
            raise ValueError("RobustSettings.sharpness must be a non-empty tuple of positive "
                             f"numbers, got {self.sharpness!r}")
        for name in ("max_step", "min_step", "noise_factor", "feasibility", "stencil_step"):
            if not is_positive(getattr(self, name)):
                raise ValueError(f"RobustSettings.{name} must be a positive number, "
                                 f"got {getattr(self, name)!r}")
        for name in ("negligible_weight", "min_damping_start"):
            value = getattr(self, name)
            if not (is_positive(value) or value == 0):
                raise ValueError(f"RobustSettings.{name} must be a number >= 0, got {value!r}")
        if not (is_positive(self.stroke_margin) and self.stroke_margin < 1):
            raise ValueError("RobustSettings.stroke_margin must be in (0, 1), "
                             f"got {self.stroke_margin!r}")
        for name, low in (("check_refinement", 1), ("stroke_rounds", 0)):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= low):
                raise ValueError(f"RobustSettings.{name} must be an integer >= {low}, "
                                 f"got {value!r}")


class _Minimum(NamedTuple):
    evaluation: Evaluation
    objective: "Model"  # the smooth worst case at the last stage's sharpness
    constraint: "Model | None"  # the stroke constraint, if any
    steps: int
    converged: bool


def _models(evaluation: Evaluation, sharpness, stroke_log_limit):
    """The worst case f (smooth maximum of the host terms) and, if a stroke limit is given,
    the constraint c = (smooth maximum of the log inerter peaks) - ln(limit) <= 0."""
    f = Model(*smooth_max(evaluation.host_terms, sharpness))
    if stroke_log_limit is None:
        return f, None
    value, grad, hess = smooth_max(evaluation.stroke_terms, sharpness)
    return f, Model(value - stroke_log_limit, grad, hess)


def _weights(evaluation: Evaluation, sharpness, stroke_log_limit) -> np.ndarray:
    """Each scenario's weight (the sum of its terms', `term_weights`) in the smooth worst
    case at `sharpness` and, with a stroke limit, in the smooth maximum of the inerter
    peaks: the larger of the two. All 1 where a smooth maximum is not finite."""
    count = len(evaluation.stencils)

    def per_scenario(terms: Terms, response: str) -> np.ndarray:
        _, weights = term_weights(terms, sharpness)
        if weights is None:
            return np.ones(count)
        sizes = [getattr(stencil[0], f"log_{response}").size for stencil in evaluation.stencils]
        return np.add.reduceat(weights, np.cumsum([0] + sizes[:-1]))

    weights = per_scenario(evaluation.host_terms, "x")
    if stroke_log_limit is not None:
        weights = np.maximum(weights, per_scenario(evaluation.stroke_terms, "y"))
    return weights


def _completed(ctx, evaluation: Evaluation, scenarios, sharpness, stroke_log_limit,
               negligible: float) -> Evaluation:
    """`evaluation` with the forward stencil of every scenario solved at the design alone
    whose weight (`_weights`) is not below `negligible`, solved now; the others' curvature
    (NaN, unknown) left out (0)."""
    weights = _weights(evaluation, sharpness, stroke_log_limit)
    missing = [i for i, (weight, stencil) in enumerate(zip(weights, evaluation.stencils,
                                                           strict=True))
               if weight >= negligible and len(stencil) == 1]
    if missing:
        states = evaluation.states()
        again = evaluate_design(ctx, evaluation.u, [scenarios[i] for i in missing],
                                [states[i] for i in missing])
        stencils = list(evaluation.stencils)
        for i, stencil in zip(missing, again.stencils, strict=True):
            stencils[i] = stencil
        evaluation = evaluation_of(ctx, evaluation.u, scenarios, stencils)
    return evaluation._replace(**{
        name: terms._replace(dgrad=np.nan_to_num(terms.dgrad, nan=0.0))
        for name, terms in (("host_terms", evaluation.host_terms),
                            ("stroke_terms", evaluation.stroke_terms))})


def _minimise(
    ctx,
    scenarios,
    u,
    *,
    stroke_log_limit=None,
    z_inits=None,
    stages,
    robust_settings: RobustSettings,
    max_steps,
    tol,
    say=None,
) -> _Minimum:
    """Minimise the smooth worst case f over `scenarios` in the design variables u, at each
    smooth-max sharpness of `stages` in turn, by a trust-region Newton method; with a
    stroke limit, by sequential quadratic programming on the constraint c <= 0 with the
    exact penalty f + weight max(c, 0) as merit function. A design is evaluated with the
    curvatures of only the scenarios that weigh in the smooth maxima
    (`robust_settings.negligible_weight`): a
    trial with those that weighed in the last accepted design, then those of any other
    that weighs at the trial (`_completed`); the first, solved at the design alone, with
    those that weigh there."""
    if z_inits is None:
        z_inits = cold_start(ctx, u, scenarios)
    current = evaluate_design(ctx, np.asarray(u, dtype=float), scenarios, z_inits,
                              stencil="centre")
    steps, converged = 0, False
    negligible, feasibility = robust_settings.negligible_weight, robust_settings.feasibility
    for stage, sharpness in enumerate(stages, start=1):
        current = _completed(ctx, current, scenarios, sharpness, stroke_log_limit, negligible)
        f, c = _models(current, sharpness, stroke_log_limit)
        if not (finite(f) and (c is None or finite(c))):
            return _Minimum(current, f, c, steps, False)

        def evaluate(u, accepted, sharpness=sharpness):
            curved = _weights(accepted, sharpness, stroke_log_limit) >= negligible
            trial = evaluate_design(ctx, u, scenarios, accepted.states(),
                                    stencil=["forward" if c else "centre" for c in curved])
            trial = _completed(ctx, trial, scenarios, sharpness, stroke_log_limit, negligible)
            t_f, t_c = _models(trial, sharpness, stroke_log_limit)
            return trial, t_f, t_c, trial.converged()

        current, f, c, stage_steps = minimise_stage(
            evaluate, current, f, c, max_step=robust_settings.max_step,
            min_step=robust_settings.min_step,
            feasibility=feasibility, max_steps=max_steps, tol=tol)
        steps += stage_steps
        converged = stationary(f, c, robust_settings.noise_factor * tol, feasibility)
        if say is not None:
            k, c_tuned = ctx.tuning(current.u)
            say(
                f"stage {stage}/{len(stages)} (smooth-max sharpness {sharpness:g}): "
                f"{steps} steps, k = {k:.6g} N/m, c = {c_tuned:.5g} N s/m"
                + ("" if converged else ", not converged")
            )
    return _Minimum(current, f, c, steps, converged)



class TuningPerformance(eqx.Module):
    """One tuning against the best achievable, over the scenarios of a `BestTunings`.
    Arrays are `[scales, amps]`; SI.

    - `host_peak`, `stroke_peak`: peak |x| and |y| over the band, m.
    - `ratio`: `host_peak` over the best achievable host peak.
    - `worst_ratio`, and the `worst_amplitude` (N) and `worst_host_frequency_scale` where
      it occurs; `max_stroke`: the largest `stroke_peak`, m.
    - `converged`: every steady state in the band converged.
    """

    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    amplitudes: Float[Array, " amps"]
    host_frequency_scales: Float[Array, " scales"]
    host_peak: Float[Array, "scales amps"]
    stroke_peak: Float[Array, "scales amps"]
    ratio: Float[Array, "scales amps"]
    worst_ratio: Float[Array, ""]
    worst_amplitude: Float[Array, ""]
    worst_host_frequency_scale: Float[Array, ""]
    max_stroke: Float[Array, ""]
    converged: Bool[Array, "scales amps"]


def _tuning_peaks(system, tunings, amplitudes, scales, omegas, settings, map_lanes,
                  quantity: Quantity = Quantity()):
    """Host (a building's `quantity`) and inerter peaks (on the grid, refined by
    parabolas, as the robust design judges them) and convergence `[tunings, scales, amps]`
    of each tuning (k, c) of `tunings`, over `omegas` (rad/s) times each scale: every
    steady state in one batch, one share per process of `map_lanes`."""
    tunings, scales, amplitudes = (np.asarray(a, dtype=float) for a in (tunings, scales,
                                                                        amplitudes))
    shape = (len(tunings), len(scales), len(amplitudes))
    lane_tuning, lane_scale, lane_amplitude = (
        g.reshape(-1) for g in np.meshgrid(np.arange(len(tunings)), scales, amplitudes,
                                           indexing="ij"))
    lanes = eqx.tree_at(
        lambda lane: (lane.tid_stiffness, lane.tid_damping),
        scaled_hosts(batched(system, lane_tuning.size), lane_scale),
        (tunings[lane_tuning, 0], tunings[lane_tuning, 1]))
    grids = lane_scale[:, None] * np.asarray(omegas)[None]
    x, y, ok = map_shares(map_lanes, _lane_peaks, (lanes, lane_amplitude, grids), settings,
                          quantity)
    return x.reshape(shape), y.reshape(shape), ok.reshape(shape)


def _lane_peaks(lanes, amplitudes, grids, settings, quantity):
    """The host and inerter peaks on the grid (refined by parabolas) of each lane's
    `lane_response`, and whether every steady state of it converged, as NumPy arrays: a
    task of `map_shares`."""
    response = lane_response(lanes, amplitudes, grids, settings, quantity=quantity)
    return (np.asarray(lane_grid_peaks(response.x_max, grids)[0]),
            np.asarray(lane_grid_peaks(response.y_max, grids)[0]),
            np.all(np.asarray(response.converged), axis=-1))


def _peaks_per_scale(system, k, c, amplitudes, scales, omegas, settings, map_lanes,
                     quantity: Quantity = Quantity()):
    """`_tuning_peaks` of the one tuning (k, c): `[scales, amps]`."""
    return tuple(a[0] for a in _tuning_peaks(system, [(k, c)], amplitudes, scales, omegas,
                                             settings, map_lanes, quantity))



def tuning_performance(
    system: TIDSystem | BuildingTID, best: BestTunings, *,
    settings: SolverSettings = SolverSettings(),
    map_lanes: Callable = serial,
) -> TuningPerformance:
    """The system's tuning over the scenarios of `best` (same band, amplitudes and host
    frequency scales): its host (a building's `best.quantity`) and inerter peaks (by
    `peaks`) and the ratio of its host peak to the best achievable, with the worst case
    and where it occurs.

    **Arguments:**

    - `system`: the `TIDSystem` (rigid device) or `BuildingTID` of `best`, at the tuning
      to judge.
    - `best`: a `BestTunings` (the scenarios, the band and the best peaks).
    - `settings`: `SolverSettings` of every steady state.
    - `map_lanes`: how shares of the steady states are mapped (see `retune`).

    **Returns:** a `TuningPerformance`.
    """
    if not isinstance(best, BestTunings):
        raise ValueError(f"best must be a BestTunings, got {type(best).__name__}")
    quantity = checked_quantity(system, best.quantity, "tuning_performance")
    check_best(best, system)
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    amps = np.asarray(best.amplitudes)
    scales = np.asarray(best.host_frequency_scales)
    x, y, ok = _peaks_per_scale(system, k, c, amps, scales, best.omegas, settings, map_lanes,
                                quantity)
    ratio = x / np.asarray(best.host_peak)
    i, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    return TuningPerformance(
        tid_stiffness=jnp.asarray(k),
        tid_damping=jnp.asarray(c),
        amplitudes=jnp.asarray(amps),
        host_frequency_scales=jnp.asarray(scales),
        host_peak=jnp.asarray(x),
        stroke_peak=jnp.asarray(y),
        ratio=jnp.asarray(ratio),
        worst_ratio=jnp.asarray(ratio[i, j]),
        worst_amplitude=jnp.asarray(amps[j]),
        worst_host_frequency_scale=jnp.asarray(scales[i]),
        max_stroke=jnp.asarray(float(np.max(y))),
        converged=jnp.asarray(ok),
    )


class RobustDesign(eqx.Module):
    """One TID tuning for a range of forcing amplitudes (and host frequencies): the one
    minimising the worst case over them of the peak host displacement relative to the best
    achievable at that amplitude, with the inerter stroke within a limit. SI units.

    - `tid_stiffness` (N/m), `tid_damping` (N s/m): the robust tuning.
    - `worst_ratio`: its largest peak ratio over the scenarios, at `worst_amplitude` (N) and
      `worst_host_frequency_scale`.
    - `stroke_limit`, `max_stroke` (m): the limit and the largest inerter peak, the latter
      on a grid `RobustSettings.check_refinement` times finer than the design band;
      `stroke_margin = 1 - max_stroke / stroke_limit`.
    - `performance`: the robust tuning's `TuningPerformance` on the design band (its
      `ratio` per scenario); `check_stroke_peak`: inerter peaks `[scales, amps]` on the
      fine grid, `check_converged`: whether every steady state there converged; `best`:
      the `BestTunings` it was measured against.
    - `iterations`: Newton steps; `converged`; `status`: a code of `Outcome`,
      see `status_messages()`.
    """

    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    worst_ratio: Float[Array, ""]
    worst_amplitude: Float[Array, ""]
    worst_host_frequency_scale: Float[Array, ""]
    stroke_limit: Float[Array, ""]
    max_stroke: Float[Array, ""]
    stroke_margin: Float[Array, ""]
    performance: TuningPerformance
    check_stroke_peak: Float[Array, "scales amps"]
    check_converged: Bool[Array, "scales amps"]
    best: BestTunings
    iterations: Int[Array, ""]
    converged: Bool[Array, ""]
    status: Int[Array, ""]

    def status_messages(self) -> list[str]:
        """The meaning of `status`, one message per entry (one here), as
        `RetuneResult.status_messages`."""
        return outcome_messages(self.status)


def _check_stroke_limit(stroke_limit) -> float:
    if isinstance(stroke_limit, bool) or not isinstance(stroke_limit, int | float):
        raise ValueError(f"stroke_limit must be a number, got {stroke_limit!r}")
    if not (np.isfinite(stroke_limit) and stroke_limit > 0):
        raise ValueError(f"stroke_limit must be finite and positive, got {stroke_limit!r}")
    return float(stroke_limit)


def _robust_start(system, best: BestTunings, target, settings,
                  map_lanes) -> tuple[float, float]:
    """The start of the robust search: of the system's tuning and the best tunings of the
    nominal host frequency, the one with the smallest worst-case ratio among those within
    the stroke target, or with the smallest stroke if none is: judged on every other
    frequency of the band (a start needs only the ranking, and 13 tunings at every
    scenario are a large batch)."""
    scales = np.asarray(best.host_frequency_scales)
    nominal = int(np.argmin(np.abs(np.log(scales))))
    candidates = [(float(system.tid_stiffness), float(system.tid_damping))] + list(
        zip(
            np.asarray(best.tid_stiffness)[nominal].tolist(),
            np.asarray(best.tid_damping)[nominal].tolist(),
            strict=True,
        )
    )
    scores = []
    xs, ys, _ = _tuning_peaks(system, candidates, np.asarray(best.amplitudes), scales,
                              np.asarray(best.omegas)[::2], settings, map_lanes, best.quantity)
    for x, y in zip(xs, ys, strict=True):
        worst = float(np.max(np.log(x / np.asarray(best.host_peak))))
        excess = float(np.log(np.max(y))) - target if target is not None else 0.0
        scores.append((max(excess, 0.0), worst))
    return candidates[min(range(len(candidates)), key=scores.__getitem__)]


def _defaults(settings, max_steps, tol):
    return (SolverSettings() if settings is None else settings,
            40 if max_steps is None else max_steps, 1e-9 if tol is None else tol)


def _check_options(max_steps, tol, retune_settings, robust_settings) -> None:
    check_retune_options(max_steps, tol, retune_settings)
    if not isinstance(robust_settings, RobustSettings):
        raise ValueError("robust_settings must be a RobustSettings, got "
                         f"{type(robust_settings).__name__}")


def robust_tune(
    system: TIDSystem | BuildingTID,
    amplitudes: ArrayLike = PAPER_AMPLITUDES,
    *,
    host_frequency_scales: ArrayLike = (1.0,),
    stroke_limit: float | None = PAPER_STROKE,
    best: BestTunings | None = None,
    omegas: ArrayLike | None = None,
    quantity: Quantity | None = None,
    settings: SolverSettings | None = None,
    max_steps: int | None = None,
    tol: float | None = None,
    retune_settings: RetuneSettings = RetuneSettings(),
    robust_settings: RobustSettings = RobustSettings(),
    progress: Callable[[str], None] | None = None,
    map_lanes: Callable = serial,
) -> RobustDesign:
    """One TID stiffness k and damping c for every scenario (forcing amplitude and host
    frequency scale): the minimiser of the worst case, over the scenarios, of the peak
    host displacement over the band divided by the best achievable in that scenario,
    subject to the inerter stroke |y| <= `stroke_limit`.

    The best achievable peaks come from `best` if given, else from `best_tunings`. The
    worst case is a smooth maximum, with sharpness rising over `robust_settings.sharpness`,
    of the scenarios' log peak ratios. It is minimised by sequential quadratic programming
    with the smooth maximum of the log inerter peaks held below the limit (aimed
    `robust_settings.stroke_margin` below it): trust-region Newton steps (the curvature
    from the scenarios that weigh at least `robust_settings.negligible_weight` in either
    smooth maximum; the value and gradient from all), aiming at a decrement along the
    constraint below `tol` (converged within `robust_settings.noise_factor * tol`),
    from the system's tuning or the best tuning of a nominal scenario, whichever has the
    smaller worst case within the limit. The stroke is then checked on a grid
    `robust_settings.check_refinement` times finer; if it is over the limit there, the
    target is lowered by the excess and the design polished again.

    A `BuildingTID` is designed for the whole structure in the same way: its peaks are its
    `quantity`'s (default the top floor's displacement), a scale s multiplies its
    stiffness matrix by s**2.

    **Arguments:**

    - `system`: the `TIDSystem` (rigid device) or `BuildingTID`; its tuning is one
      starting point.
    - `amplitudes`: forcing amplitudes, N (default the paper's, 100-3000 N).
    - `host_frequency_scales`: host frequency scales s (the host stiffness times s**2),
      e.g. (0.95, 1, 1.05) for +-5% host frequency.
    - `stroke_limit`: the inerter stroke limit, m; None leaves the stroke free (reported
      with an infinite limit).
    - `best`: a `BestTunings` of the same system, amplitudes and scales (default: found
      by `best_tunings` with `retune_settings`).
    - `omegas`: the band, rad/s, for the nominal system (default
      `default_omegas(system)`), scaled with the host frequency.
    - `quantity`: a building's measured response (`Quantity`).
    - `settings`: `SolverSettings` of every steady state.
    - `max_steps`: optimiser steps per stage (default 40).
    - `tol`: the Newton decrement aimed at (default 1e-9).
    - `retune_settings`: `RetuneSettings` of the best tunings.
    - `robust_settings`: `RobustSettings` of this optimiser.
    - `progress`: if given, called with one-line messages.
    - `map_lanes`: how independent lanes are mapped (see `retune`).

    **Returns:** a `RobustDesign`.
    """
    quantity = checked_quantity(system, quantity, "robust_tune")
    settings, max_steps, tol = _defaults(settings, max_steps, tol)
    amps = check_distinct("amplitudes", amplitudes)
    scales = check_distinct("host_frequency_scales", host_frequency_scales)
    limit = np.inf if stroke_limit is None else _check_stroke_limit(stroke_limit)
    _check_options(max_steps, tol, retune_settings, robust_settings)
    say = progress if progress is not None else (lambda message: None)
    best = checked_best(system, amps, scales, best, omegas, settings, retune_settings,
                         progress, map_lanes, quantity)
    band = np.asarray(best.omegas)
    # The worst case over scenarios is of the peaks on the band's grid (refined by
    # parabolas), as its reference `best.objective` is; the stroke limit is then checked
    # on a finer grid.
    ctx = Context(system, band, settings, locate=False,
                  stencil_step=robust_settings.stencil_step, map_lanes=map_lanes,
                  quantity=quantity)
    scenarios = [
        Scenario(float(amplitude), float(scale), float(best.objective[i, j]))
        for i, scale in enumerate(scales)
        for j, amplitude in enumerate(amps)
    ]
    margin = robust_settings.stroke_margin
    target = np.log(limit * (1 - margin)) if np.isfinite(limit) else None
    say(f"robust tuning over {len(scenarios)} scenarios, stroke limit {limit:g} m")
    k, c = _robust_start(system, best, target, settings, map_lanes)
    say(f"starting from k = {k:.6g} N/m, c = {c:.5g} N s/m")
    options = dict(max_steps=max_steps, tol=tol, say=say, robust_settings=robust_settings)
    minimum = _minimise(ctx, scenarios, ctx.design(k, c, floor=robust_settings.min_damping_start),
                        stroke_log_limit=target, stages=robust_settings.sharpness, **options)
    steps = minimum.steps
    fine = np.linspace(band[0], band[-1], robust_settings.check_refinement * (band.size - 1) + 1)
    for round_ in range(robust_settings.stroke_rounds + 1):
        k, c = ctx.tuning(minimum.evaluation.u)
        _, check_y, check_ok = _peaks_per_scale(system, k, c, amps, scales, fine, settings,
                                                map_lanes, quantity)
        max_stroke = float(np.max(check_y))
        if max_stroke <= limit or round_ == robust_settings.stroke_rounds:
            break
        target -= np.log(max_stroke / limit) + margin
        say(f"stroke {max_stroke:.5g} m over the limit on the check grid: aiming lower")
        states = minimum.evaluation.states()
        minimum = _minimise(ctx, scenarios, minimum.evaluation.u, stroke_log_limit=target,
                            z_inits=states, stages=robust_settings.sharpness[-1:], **options)
        steps += minimum.steps
    performance = tuning_performance(
        system.replace(tid_stiffness=k, tid_damping=c), best, settings=settings,
        map_lanes=map_lanes)
    steady = bool(np.all(performance.converged) and np.all(check_ok))
    outcome = (Outcome.not_stationary if not minimum.converged
               else Outcome.steady_states_failed if not steady
               else Outcome.stroke_over_limit if max_stroke > limit else Outcome.ok)
    status = outcome_code(outcome)
    say(
        f"robust tuning: k = {k:.6g} N/m, c = {c:.5g} N s/m, worst ratio "
        f"{float(performance.worst_ratio):.4f} at {float(performance.worst_amplitude):g} N; "
        f"{outcome_message(Outcome, status)}"
    )
    return RobustDesign(
        tid_stiffness=jnp.asarray(k),
        tid_damping=jnp.asarray(c),
        worst_ratio=performance.worst_ratio,
        worst_amplitude=performance.worst_amplitude,
        worst_host_frequency_scale=performance.worst_host_frequency_scale,
        stroke_limit=jnp.asarray(limit),
        max_stroke=jnp.asarray(max_stroke),
        stroke_margin=jnp.asarray(1 - max_stroke / limit),
        performance=performance,
        check_stroke_peak=jnp.asarray(check_y),
        check_converged=jnp.asarray(check_ok),
        best=best,
        iterations=jnp.asarray(steps),
        converged=jnp.asarray(status == outcome_code(Outcome.ok)),
        status=jnp.asarray(status),
    )
