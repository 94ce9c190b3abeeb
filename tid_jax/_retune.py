"""Retuning the TID per forcing amplitude: `retune`, its settings and result, and the
optimiser on lanes that every per-scenario optimum shares (`optimal_tunings`): the initial
orbits, the continuation stages (`_retune_stage`) and the check on a finer grid."""

import concurrent.futures
import dataclasses
import functools as ft
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._model._building import (
    BuildingTID,
    Quantity,
    building_breakaway,
    checked_quantity,
    first_mode_tunings,
)
from ._model._checks import (
    check_grid,
    check_optimiser_options,
    is_positive,
)
from ._model._linear import den_hartog_tuning, host_breakaway
from ._model._system import TIDSystem
from ._optimise._design_variables import design_of_tuning, tuning_of_design
from ._optimise._retune_stage import compile_stage, stage_lanes
from ._orbit._settings import SolverSettings
from ._peaks import Peaks, _band, response_peaks
from ._response import (
    FrequencyResponse,
    _on_host,
    batched,
    lane_response,
    scaled_states,
    state_count,
    static_units,
    with_tuning,
)
from ._runtime._outcomes import Outcome, outcome_code, outcome_messages
from ._runtime._parallel import process_count, serial


class RetuneSettings(eqx.Module):
    """Settings of the retuning optimiser: of `retune`, and of the per-scenario optimum
    that `best_tunings`, `sensitivities` and `robust_tune` share with it. Defaults live
    here only.

    - `sharpness`: sharpness of the smooth maximum of the local peaks (in log-peak units)
      at each continuation stage; the last one defines the optimum.
    - `continuation_tol`: optimiser tolerance of every stage but the last.
    - `check_refinement`: the check grid is the design grid with `check_refinement - 1`
      frequencies inserted evenly between neighbours.
    - `design_newton_steps`: Newton iterations allowed per steady state inside the
      optimiser, where every solve is warm-started; points that need more are still
      evaluated (at their last iterate), and the final design is checked with fully
      converged steady states.
    - `max_rejected_steps`: consecutive rejected line-search steps (each at most half the
      last) after which a stage is taken as converged, as a stage before the last is
      sooner where a rejected step is cut to a move within its tolerance: no decrease is
      found above the noise of the objective.
    - `max_design_step`: longest optimiser step in the scaled design variables (1.0 is
      about 10% in k; see `DESIGN_SCALE`).
    - `damping_bound_ratio`: the damping's ratio to Den Hartog's below which the bound
      c >= 0 is reported as active (`RetuneResult.damping_at_bound`).
    """

    sharpness: tuple[float, ...] = (50.0, 1000.0, 30000.0)
    continuation_tol: float = 1e-3
    check_refinement: int = 2
    design_newton_steps: int = 4
    max_rejected_steps: int = 12
    max_design_step: float = 1.0
    damping_bound_ratio: float = 1e-3

    def __check_init__(self):
        sharpness = self.sharpness
        if not (isinstance(sharpness, tuple) and sharpness
                and all(is_positive(v) for v in sharpness)):
            raise ValueError("RetuneSettings.sharpness must be a non-empty tuple of positive "
                             f"numbers, got {sharpness!r}")
        for name in ("continuation_tol", "max_design_step", "damping_bound_ratio"):
            value = getattr(self, name)
            if not is_positive(value):
                raise ValueError(f"RetuneSettings.{name} must be a positive number, "
                                 f"got {value!r}")
        for name in ("check_refinement", "design_newton_steps", "max_rejected_steps"):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and value >= 1):
                raise ValueError(f"RetuneSettings.{name} must be an integer >= 1, "
                                 f"got {value!r}")

    def progress_steps(self) -> int:
        """The messages that `retune` gives its `progress`, one as each step ends: the
        initial tuning's steady states, each stage, the check."""
        return len(self.sharpness) + 2


class RetuneResult(eqx.Module):
    """Per-amplitude retuned TID (SI units). `x_peak`/`x_peak_initial` and `y_peak`/
    `y_peak_initial` are the peak host and inerter displacements over the band after and
    before retuning, confirmed on a frequency grid `RetuneSettings.check_refinement` times
    finer than the design grid, `check_omegas`, on which `x_response`/`x_response_initial`
    hold the peak host displacement over a period at every frequency. `status` holds codes
    of `Outcome`, explained by `status_messages()`."""

    amplitudes: Float[Array, " amps"]
    tid_stiffness: Float[Array, " amps"]
    tid_damping: Float[Array, " amps"]
    initial_stiffness: Float[Array, " amps"]
    initial_damping: Float[Array, " amps"]
    x_peak: Float[Array, " amps"]
    x_peak_initial: Float[Array, " amps"]
    y_peak: Float[Array, " amps"]
    y_peak_initial: Float[Array, " amps"]
    omega_peak: Float[Array, " amps"]
    iterations: Int[Array, " amps"]
    converged: Bool[Array, " amps"]
    damping_at_bound: Bool[Array, " amps"]
    status: Int[Array, " amps"]
    check_omegas: Float[Array, "*lanes check"]  # rad/s, the check grid (one per lane)
    x_response: Float[Array, "amps check"]  # m, peak |x| over a period on the check grid
    x_response_initial: Float[Array, "amps check"]  # m, the same for the initial tuning

    def status_messages(self) -> list[str]:
        """The meaning of `status`, one message per amplitude (`Outcome`'s), with a note
        where the damping is at its lower bound."""
        return [text + ("; damping at its lower bound 0" if at_bound else "")
                for text, at_bound in zip(outcome_messages(self.status),
                                          np.ravel(self.damping_at_bound), strict=True)]


def _check_lanes(systems, amplitudes, omegas, warm, settings, quantity: Quantity):
    """The check's `lane_response` of the lanes (each steady state shot from `warm`) and
    its `response_peaks`, as NumPy arrays."""
    response = lane_response(systems, amplitudes, omegas, settings, warm, quantity)
    return jax.tree.map(np.asarray, (response, response_peaks(systems, response, settings,
                                                              quantity)))



def _on_check_grid(values, refinement: int):
    """`values` (amplitudes x design frequencies x ...) on the check grid, `refinement`
    times finer: interpolated linearly between neighbouring design frequencies."""
    f = jnp.arange(refinement).reshape((-1,) + (1,) * (values.ndim - 2)) / refinement
    lower, upper = values[:, :-1, None], values[:, 1:, None]
    inner = lower + f * (upper - lower)
    inner = inner.reshape(inner.shape[:1] + (-1,) + inner.shape[3:])
    return jnp.concatenate([inner, values[:, -1:]], axis=1)


def _rows(response: FrequencyResponse, rows) -> FrequencyResponse:
    """The amplitudes `rows` of a `FrequencyResponse` over amplitudes x frequencies."""
    fields = {field.name: getattr(response, field.name) for field in dataclasses.fields(response)}
    return FrequencyResponse(**{
        name: value if name == "omegas" and value.ndim == 1 else value[rows]
        for name, value in fields.items()
    })


def retune(
    system: TIDSystem | BuildingTID,
    amplitudes: ArrayLike,
    *,
    omegas: ArrayLike | None = None,
    quantity: Quantity | None = None,
    settings: SolverSettings | None = None,
    max_steps: int | None = None,
    tol: float | None = None,
    retune_settings: RetuneSettings = RetuneSettings(),
    progress: Callable[[str], None] | None = None,
    map_lanes: Callable = serial,
) -> RetuneResult:
    """Retune the TID for each forcing amplitude: the `tid_stiffness` k > 0 and
    `tid_damping` c >= 0 minimising the peak steady-state host displacement (a building's
    `quantity`) over a band.

    The amplitudes are optimised one after another (each with its frequencies batched, or
    spread over processes by `map_lanes`) by one compiled
    program, whatever their number, so that each optimiser stops as soon as it converges;
    the checks are batched over every amplitude and frequency (and sharded over several
    JAX devices). The non-smooth maximum over frequency is replaced by
    a smooth maximum of the local peaks (the highest located in continuous frequency, so
    that the optimum does not depend on where the grid falls) whose sharpness grows over
    `retune_settings.sharpness` (continuation), each stage a BFGS run (optimistix's, with
    its steps capped at `retune_settings.max_design_step` and a line search that
    interpolates and extrapolates) warm-started from the last (its design, orbits and BFGS's
    inverse Hessian; its first step shortened by the ratio of the sharpnesses), with
    gradients by implicit differentiation through the periodic orbits. The first stage
    starts from the initial tuning's orbits on the design grid and the identity (in the
    scaled design variables). At every design, each steady state is predicted to first order
    from the orbit of the last accepted design and settled by chord iterations with the
    latest monodromy matrix at its frequency; the `REFINED_PEAKS` highest local maxima are
    then located in continuous frequency by Newton steps on the slope of the response
    (`_peaks`), and the response at the last iterate is solved with tangents, which give the
    derivatives of the true peaks and renew the monodromy matrices at their grid points. The
    initial and retuned designs are then solved afresh (each steady state starting from the
    design's orbits) on a grid `retune_settings.check_refinement` times finer; a design
    whose peak there is above the initial tuning's is replaced by the initial tuning (status
    `initial_kept`), as is the design at an amplitude below the initial tuning's breakaway
    amplitude (`host_breakaway`; status `stuck`, not optimised at all, 0 iterations):
    there the inerter never slips, and the smoothed model's optimum would be an ever stiffer
    spring and damper to ground.

    A `BuildingTID` is retuned in the same way for its `quantity` (default the top floor's
    displacement), its design variables relative to the first mode's Den Hartog tuning.

    **Arguments:**

    - `system`: the `TIDSystem` (or `BuildingTID`); its `tid_stiffness` and
      `tid_damping` are the initial tuning.
    - `amplitudes`: forcing amplitudes A of `A sin(omega t)`, N (a building's ground
      acceleration: m/s2), scalar or 1-d.
    - `omegas`: the design grid of the band, rad/s, increasing (default
      `default_omegas(system)`: 61 frequencies over 0.65-1.4 times the host frequency).
    - `settings`: `SolverSettings` of the steady states.
    - `quantity`: a building's measured response (`Quantity`).
    - `max_steps`: BFGS iterations allowed per stage (default 60).
    - `tol`: tolerance of the last stage, on the scaled design variables and the log peak
      (the default 1e-4 settles k to about 1e-5 and the peak to about 1e-4, relative);
      the stages before use `retune_settings.continuation_tol`. A stage also ends,
      converged, when its line search finds no decrease in
      `retune_settings.max_rejected_steps` cuts of its step, or (stages before the last)
      none before a cut step is within the tolerance (as an accepted step's length is
      judged).
    - `retune_settings`: `RetuneSettings` of the optimiser.
    - `progress`: if given, called with a one-line message as each of the
      `retune_settings.progress_steps()` steps ends (the initial tuning's steady states,
      each stage, the check).
    - `map_lanes`: how the independent amplitudes are mapped (default: one after another
      in this process; a `ProcessMap` spreads them over processes).

    **Returns:** a `RetuneResult`.
    """
    quantity = checked_quantity(system, quantity, "retune")
    settings = SolverSettings() if settings is None else settings
    max_steps = 60 if max_steps is None else max_steps
    tol = 1e-4 if tol is None else tol
    band = _band(system, omegas)
    amps = np.atleast_1d(check_grid("amplitudes", amplitudes)).astype(band.dtype)
    check_retune_options(max_steps, tol, retune_settings)
    bands = np.broadcast_to(np.asarray(band), amps.shape + band.shape)
    result = optimal_tunings(batched(system, amps.size), amps, bands, settings=settings,
                             max_steps=max_steps, tol=tol, retune_settings=retune_settings,
                             progress=progress, map_lanes=map_lanes, quantity=quantity)
    return eqx.tree_at(lambda r: r.check_omegas, result, result.check_omegas[0])


def check_retune_options(max_steps, tol, retune_settings) -> None:
    check_optimiser_options(max_steps, tol)
    if not isinstance(retune_settings, RetuneSettings):
        raise ValueError("retune_settings must be a RetuneSettings, got "
                         f"{type(retune_settings).__name__}")


def optimal_tunings(
    systems: TIDSystem,
    amplitudes,
    bands,
    *,
    settings: SolverSettings,
    max_steps: int,
    tol: float,
    retune_settings: RetuneSettings,
    progress: Callable[[str], None] | None = None,
    map_lanes: Callable = serial,
    quantity: Quantity = Quantity(),
) -> RetuneResult:
    """The optimiser of `retune` on lanes: lane i retunes the system `systems[i]` (its
    fields batched, see `_response.batched`; `TIDSystem`s, or `BuildingTID`s measuring
    `quantity`) at the amplitude `amplitudes[i]` over the frequencies `bands[i]`: the lanes are optimised one per task of `map_lanes`, their
    initial orbits and their check solved in one batch each, in this process.
    `check_omegas` of the result is one check grid per lane."""
    say = progress if progress is not None else (lambda message: None)
    amps = jax.device_put(np.asarray(amplitudes))
    refinement = retune_settings.check_refinement
    k_ref, c_ref = reference_tunings(systems)
    k0, c0, u, hessian_inv = _initial_design(systems, amps, k_ref, c_ref)
    references = np.stack([k_ref, c_ref], axis=-1)
    # Below the breakaway amplitude the inerter never slips: those lanes keep the initial
    # tuning (status `stuck`), and only the others are optimised.
    stuck = _below_breakaway(systems, amps, bands)
    moving = np.flatnonzero(~stuck)
    stages = [_stage_options(stage, retune_settings.sharpness, tol, settings, max_steps,
                             retune_settings, quantity)
              for stage in range(1, len(retune_settings.sharpness) + 1)]
    # With worker processes, this process's threads only wait for them: a worker compiles
    # the stages' program while this process solves the initial tuning, and the stages
    # run on the workers while this process checks the initial tuning. (In one process
    # everything runs in turn: two threads running XLA's programs at once can deadlock.)
    workers, compiling = process_count(map_lanes) > 1, None
    with concurrent.futures.ThreadPoolExecutor(2) as waiting:
        if workers and moving.size:
            placeholder = _lanes_of(moving[:1], (systems, amps, references, bands, u,
                                                  _placeholder_orbits(systems, k0, c0, bands),
                                                  hessian_inv))
            compiling = waiting.submit(map_lanes, compile_stage, [(placeholder, stages[0])])
        start = lane_response(systems, amps, bands, settings, quantity=quantity)
        say(f"initial tuning solved on {bands.shape[-1]} frequencies x {amps.size} lanes")
        orbits = _initial_orbits(start, systems, k0, c0)
        initial = _check_inputs(systems, amps, bands, orbits[1], refinement)
        # On the host here: the stages' thread then only slices NumPy arrays and waits.
        lanes = jax.tree.map(np.asarray, (systems, amps, references, bands, u, orbits,
                                          hessian_inv))
        run = ft.partial(_stages, lanes, moving, stages, retune_settings.sharpness, say,
                         map_lanes)
        if workers:
            # (the stages wait for the program: the other workers then load it)
            staged = waiting.submit(_after, compiling, run)
            initial_check = _check_lanes(*initial, settings, quantity)
            u, orbits, ok, iterations = staged.result()
        else:
            u, orbits, ok, iterations = run()
            initial_check = _check_lanes(*initial, settings, quantity)
    k, c, retuned = _retuned(systems, u, k_ref, c_ref)
    checked = _check_lanes(*_check_inputs(retuned, amps, bands, orbits[1], refinement),
                           settings, quantity)
    both, found = jax.tree.map(lambda *a: np.concatenate(a), initial_check, checked)
    result = _checked_result(both, found, k0, c0, k, c, ok, iterations, c_ref, stuck,
                             retune_settings.damping_bound_ratio)
    say(f"checked the initial and retuned designs on {initial[2].shape[-1]} frequencies x "
        f"{amps.size} lanes: {int(np.sum(result.converged))}/{amps.size} ok")
    return result


def _after(future: concurrent.futures.Future | None, function: Callable):
    """`function()` once `future` (if any) is done, whatever its outcome."""
    if future is not None:
        future.exception()
    return function()


def _stages(lanes, moving, stages, sharpnesses, say, map_lanes):
    """The continuation stages of the lanes `moving` of `lanes` (systems, amplitudes,
    reference tunings, bands, designs, orbits, inverse Hessians), one lane per task of
    `map_lanes`: the designs, orbits, convergence and iterations of every lane (the
    others' unchanged)."""
    systems, amps, references, bands, u, orbits, hessian_inv = lanes
    ok = np.zeros(amps.shape, bool)
    iterations = np.zeros(amps.shape, dtype=int)
    for stage, (sharpness, options) in enumerate(zip(sharpnesses, stages, strict=True), start=1):
        steps = np.zeros(moving.size, int)
        if moving.size:
            these = _lanes_of(moving, (systems, amps, references, bands, u, orbits,
                                       hessian_inv))
            # One lane per call: one compiled program serves any number of lanes.
            parts = map_lanes(stage_lanes, [
                (jax.tree.map(lambda a, i=i: a[i : i + 1], these), options)
                for i in range(moving.size)
            ])
            new_u, steps, new_ok, new_orbits, new_hessian_inv = jax.tree.map(
                lambda *values: np.concatenate(values), *parts)
            u, orbits, hessian_inv, ok = _set_lanes(
                (u, orbits, hessian_inv, ok), moving, (new_u, new_orbits, new_hessian_inv, new_ok))
        iterations[moving] += steps
        say(f"retune stage {stage}/{len(sharpnesses)} (smooth-max sharpness {sharpness:g}): "
            f"{int(np.sum(ok))}/{amps.size} lanes converged, "
            f"{int(np.max(steps, initial=0))} iterations at most")
    return u, orbits, ok, iterations


def _placeholder_orbits(systems, k0, c0, bands):
    """Orbits of the shapes and types `_initial_orbits` gives, all states zero: the stages'
    program compiled for them is the program of the stages on the real orbits."""
    size = state_count(systems)
    states = np.zeros(bands.shape + (size,), bands.dtype)
    return (np.stack([np.asarray(k0), np.asarray(c0)], axis=-1), states,
            np.zeros(states.shape + (size,), bands.dtype),
            np.zeros(states.shape + (2,), bands.dtype))


def _stage_options(stage: int, sharpnesses, tol, settings, max_steps,
                   retune_settings: RetuneSettings, quantity: Quantity) -> dict:
    """The options of `stage_lanes` at the continuation stage `stage` (from 1)."""
    sharpness = sharpnesses[stage - 1]
    # Stages before the last only bring the design near the optimum.
    stage_tol = (tol if stage == len(sharpnesses)
                 else max(tol, retune_settings.continuation_tol))
    return dict(
        sharpness=float(sharpness), settings=settings, max_steps=max_steps,
        # Across the ridge where two peaks are equal, the curvature grows with the
        # sharpness: the last stage's, inherited, is that much too weak there.
        first_step=min(1.0, sharpnesses[stage - 2] / sharpness) if stage > 1 else 1.0,
        tol=float(stage_tol), design_newton_steps=retune_settings.design_newton_steps,
        max_rejected_steps=retune_settings.max_rejected_steps,
        small_cuts_end=stage < len(sharpnesses),
        max_design_step=float(retune_settings.max_design_step), quantity=quantity,
    )


def _lanes_of(lanes, values):
    """The entries `lanes` of every array of `values`, as NumPy arrays."""
    return jax.tree.map(lambda a: np.asarray(a)[lanes], values)


def reference_tunings(systems) -> tuple[np.ndarray, np.ndarray]:
    """The design variables' reference tuning (k, c) of each lane (`systems` batched):
    Den Hartog's of a `TIDSystem`, the first mode's of a `BuildingTID`
    (`first_mode_tunings`)."""
    if isinstance(systems, BuildingTID):
        systems = _on_host(systems)
        count = np.shape(systems.inertance)[0]
        return tuple(np.asarray(t) for t in zip(*(
            first_mode_tunings(jax.tree.map(lambda a, i=i: a[i], systems))["den_hartog"]
            for i in range(count))))
    return tuple(np.asarray(t) for t in den_hartog_tuning(
        np.asarray(systems.host_mass), np.asarray(systems.host_stiffness),
        np.asarray(systems.inertance)))


@eqx.filter_jit
def _initial_design(systems, amplitudes, k_ref, c_ref):
    """The initial tuning of each lane, its design variables (relative to the reference
    tuning `k_ref`, `c_ref`) and BFGS's first inverse Hessian (the identity)."""
    # Strongly typed, as every later design is: one program serves every stage.
    k0 = jnp.asarray(systems.tid_stiffness, amplitudes.dtype)
    c0 = jnp.asarray(systems.tid_damping, amplitudes.dtype)
    # Start no lower than 5% of Den Hartog's damping: c = 0 is stationary in the design
    # variables and would never be left.
    u = design_of_tuning(k0, jnp.maximum(c0, 0.05 * c_ref), k_ref, c_ref)
    eye = jnp.eye(2, dtype=amplitudes.dtype)
    return k0, c0, u, jnp.broadcast_to(eye, amplitudes.shape + (2, 2))


def _initial_orbits(start: FrequencyResponse, systems, k0, c0):
    """The first stage's warm start: the initial tuning, and per frequency its orbit's
    scaled state, monodromy matrix and (zero) state derivatives."""
    return _orbits_of(start, static_units(systems), k0, c0)


@eqx.filter_jit
def _orbits_of(start: FrequencyResponse, units, k0, c0):
    states = scaled_states(start, units)
    return (jnp.stack([k0, c0], axis=-1), states, start.monodromy,
            jnp.zeros(states.shape + (2,), states.dtype))


@eqx.filter_jit
def _retuned(systems: TIDSystem, u, k_ref, c_ref):
    """The tunings (k, c) of the lanes' design variables `u`, and the systems so tuned."""
    k, c = tuning_of_design(u.T, k_ref, c_ref)
    return k, c, with_tuning(systems, k, c)


@eqx.filter_jit
def _check_inputs(systems: TIDSystem, amplitudes, bands, states, refinement: int):
    """The check's lanes of one design each (the tuning of `systems`), as `_check_lanes`
    takes them: the systems, amplitudes and check grids, every steady state shot from the
    design's orbits `states` on the design grid (interpolated in between)."""
    return (systems, amplitudes, _on_check_grid(bands, refinement),
            _on_check_grid(states, refinement))


def _set_lanes(values, lanes, new):
    """`values` (arrays with a leading axis of lanes, or a pytree of them) as NumPy arrays,
    with the entries at `lanes` replaced by `new`."""

    def put(value, part):
        value = np.array(value)
        value[lanes] = np.asarray(part)
        return value

    return jax.tree.map(put, values, new)


def _below_breakaway(systems, amplitudes, bands):
    """Whether each lane's amplitude is below its system's smallest breakaway amplitude
    over its band (`host_breakaway`, `building_breakaway`): the inerter then never
    slips."""
    systems, bands = _on_host((systems, bands))

    def smallest(system, band):
        if isinstance(system, BuildingTID):
            return float(np.min(building_breakaway(system, band)))
        return float(host_breakaway(system, band).minimum)

    minimum = [smallest(jax.tree.map(lambda a, i=i: a[i], systems), bands[i])
               for i in range(amplitudes.shape[0])]
    return np.asarray(amplitudes) < np.asarray(minimum)


@eqx.filter_jit
def _checked_result(both: FrequencyResponse, found: Peaks, k0, c0, k, c, ok, iterations,
                    c_ref, stuck, damping_bound_ratio: float):
    """The `RetuneResult` from the check `both` of the initial designs (`k0`, `c0`, its first
    half of amplitudes) and the retuned ones (`k`, `c`, the second half), and their true
    peaks `found`; `stuck` marks the amplitudes below the initial tuning's breakaway
    amplitude, `damping_bound_ratio` (`RetuneSettings`) where the damping is at its
    bound."""
    n = k0.shape[0]
    initial, retuned = _rows(both, slice(None, n)), _rows(both, slice(n, None))
    before = jax.tree.map(lambda a: a[:n], found)
    after = jax.tree.map(lambda a: a[n:], found)
    code = {name: outcome_code(getattr(Outcome, name)) for name in (
        "ok", "not_stationary", "steady_states_failed", "peak_at_band_edge", "initial_kept",
        "stuck")}
    status = jnp.where(after.at_edge, code["peak_at_band_edge"], code["ok"])
    status = jnp.where(after.converged & before.converged, status, code["steady_states_failed"])
    status = jnp.where(ok, status, code["not_stationary"])
    # A design that the check finds worse than the tuning it started from (the design grid
    # misled the optimiser) is not returned: the initial tuning is kept and flagged.
    worse = after.x_peak > before.x_peak
    status = jnp.where(worse, code["initial_kept"], status)
    # Below the breakaway amplitude the smoothed model's optimum is a stiffer and stiffer
    # spring-damper to ground (the inerter stays stuck): not a TID design, so not returned.
    status = jnp.where(stuck, code["stuck"], status)
    kept = worse | stuck
    k, c = jnp.where(kept, k0, k), jnp.where(kept, c0, c)
    after = jax.tree.map(lambda b, a: jnp.where(kept, b, a), before, after)
    x_response = jnp.where(kept[:, None], initial.x_max, retuned.x_max)
    return RetuneResult(
        amplitudes=initial.amplitudes,
        tid_stiffness=k,
        tid_damping=c,
        initial_stiffness=k0,
        initial_damping=c0,
        x_peak=after.x_peak,
        x_peak_initial=before.x_peak,
        y_peak=after.y_peak,
        y_peak_initial=before.y_peak,
        omega_peak=after.omega_x,
        check_omegas=retuned.omegas,
        x_response=x_response,
        x_response_initial=initial.x_max,
        iterations=iterations,
        converged=status == code["ok"],
        damping_at_bound=c < damping_bound_ratio * c_ref,
        status=status,
    )
