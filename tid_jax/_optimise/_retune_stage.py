"""One continuation stage of retune's optimiser on one lane, as one compiled program:
BFGS on the smooth log peak, each design swept over the band from the orbits of the last
(steady states settled, the highest peaks located in continuous frequency and solved
with their derivatives)."""

import functools as ft

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._model._building import BuildingTID, Quantity
from .._model._system import compiler_options
from .._orbit._period import point_model
from .._orbit._sampled_peaks import (
    REFINED_PEAKS,
    bracket,
    interpolated,
    located_peak,
    newton_iterates,
    refined_peak,
    smooth_log_peak,
    stencil,
    top_peaks,
)
from .._orbit._settings import SolverSettings
from .._orbit._steady_state import one_by_one, settled_state
from .._response import point_response, with_tuning
from .._runtime._cache import compiled
from ._bfgs import CappedBFGS, CappedNewtonDescent, InterpolatingArmijo
from ._design_variables import tuning_of_design
from ._stall import cut_within_tolerance

# the fields the design moves: the shooting carries tangents along them
TUNING_FIELDS = ("tid_stiffness", "tid_damping")


@compiled(options=compiler_options)
def optimise_stage(systems, amplitudes, references, u0, z0, h0, omegas, sharpness, first_step,
                   settings, max_steps, tol, design_newton_steps, max_rejected_steps,
                   max_design_step, small_cuts_end, quantity):
    """BFGS on one lane (every array with a leading axis of one lane: the system
    `systems[0]`, its fields batched, measuring `quantity`, at `amplitudes[0]` over the
    frequencies `omegas[0]`, its design variables relative to the tuning `references[0]`)
    from the design `u0[0]` and inverse Hessian `h0[0]` on the smooth log peak, shooting
    from the orbits `z0` of a nearby design (its tuning (k, c) and, per frequency, the
    scaled state, monodromy matrix and state derivatives with respect to (k, c)); returns
    the design, iterations, success, the orbits of the last accepted design and BFGS's
    inverse Hessian there, each with the lane axis."""
    settings = eqx.tree_at(
        lambda s: s.max_newton_steps, settings, min(settings.max_newton_steps, design_newton_steps)
    )
    solver = CappedBFGS(rtol=tol, atol=tol, descent=CappedNewtonDescent(max_step=max_design_step),
                        search=InterpolatingArmijo(max_step=max_design_step,
                                                   first_step=first_step))
    lane = ft.partial(_optimise_lane, solver=solver, sharpness=sharpness, settings=settings,
                      max_steps=max_steps, max_rejected_steps=max_rejected_steps,
                      small_cuts_end=small_cuts_end, quantity=quantity)

    # One lane per call: its optimiser stops when it converges, and its integrations wait
    # only for its own stiffest steady state. Batching the loops of the optimiser, with
    # the batched loops of the steady states inside, would cost most of the program's
    # tracing; spread over several devices as one batch (one lane each), every device
    # would also wait for the others at each iteration of those loops (a retune with
    # smoothed friction took five times as long on 4 simulated CPU devices as on one),
    # and optimistix's BFGS cannot yet run on each device on its own (in a `shard_map`:
    # lineax issue 185).
    args = (systems, amplitudes, references, omegas, u0, z0, h0)
    return jax.tree.map(lambda a: a[None], lane(*jax.tree.map(lambda a: a[0], args)))


def stage_lanes(lanes, options: dict):
    """One stage (`optimise_stage`) of the lane `(systems, amplitudes, references, bands,
    designs, orbits, inverse Hessians)` (NumPy arrays, with a leading axis of one lane), its
    results as NumPy arrays: a task of `map_lanes`."""
    return jax.tree.map(np.asarray, optimise_stage(*_stage_arguments(lanes, options)))


def compile_stage(lanes, options: dict) -> None:
    """`optimise_stage` for `stage_lanes(lanes, options)` compiled, not run (only the
    shapes of `lanes` matter): a task of `map_lanes` that a worker process runs while
    the initial tuning is solved, so that the stages find the program in the cache."""
    optimise_stage.compile_only(*_stage_arguments(lanes, options))


def _stage_arguments(lanes, options: dict):
    """The arguments of `optimise_stage` for `stage_lanes`."""
    systems, amplitudes, references, bands, u, z, h = lanes
    return (systems, amplitudes, references, u, z, h, bands, jnp.asarray(options["sharpness"]),
            jnp.asarray(options["first_step"]), options["settings"], options["max_steps"],
            jnp.asarray(options["tol"]), options["design_newton_steps"],
            jnp.asarray(options["max_rejected_steps"]), options["max_design_step"],
            jnp.asarray(options["small_cuts_end"]), options["quantity"])


def static_unit(system):
    """The unit of the scaled displacements per unit load amplitude: 1 / K of a
    `TIDSystem`, a building's `static_scale` (traceable)."""
    if isinstance(system, BuildingTID):
        return system.static_scale()
    return 1 / system.host_stiffness


def _design_sweep(system, quantity: Quantity, omegas, u, amplitude, reference, warm,
                  settings: SolverSettings):
    """Peaks (SI; the host's displacement, a building's `quantity`) at every frequency, the true maxima over frequency of the highest
    of them, and the orbits of the design `u`, from the orbits `warm` of a nearby
    design (its tuning, then per frequency the scaled state, monodromy matrix and state
    derivatives with respect to the tuning): every steady state is predicted to first
    order at `u` and settled by chord iterations without tangents; each of the
    `REFINED_PEAKS` highest local maxima is then located in continuous frequency by
    Newton steps on the slope of the response (`_peaks.true_peaks`), the stencils
    shot from the grid's orbits (interpolated) with the monodromy matrix of the
    peak's grid point and settled by chord iterations; the peak, the response at the
    last iterate, is solved with tangents from the last stencil's orbits
    (interpolated), which give its derivatives and renew the monodromy matrices at
    those grid points.
    Returns `(xs, (index, peaks))`, as `smooth_log_peak` takes them, and the orbits."""
    k, c = tuning_of_design(u, reference[0], reference[1])
    tuned = with_tuning(system, k, c)
    warm_tuning, states, monodromies, derivatives = warm
    change = jax.lax.stop_gradient(jnp.stack([k, c]) - warm_tuning)

    def settle(omega, z0, monodromy):
        p, _, unit, _ = jax.lax.stop_gradient(point_model(tuned, quantity, amplitude, omega))
        z, x_samples = settled_state(z0, p, settings.for_system(tuned), monodromy)
        return z, jnp.nan_to_num(refined_peak(x_samples) * unit, nan=jnp.inf)

    # (a building's matrices: one at a time, see `one_by_one`)
    each = ft.partial(one_by_one, floors=system.floors)
    states, xs = each(settle)(omegas, states + derivatives @ change, monodromies)
    index, centre, _ = top_peaks(xs, omegas, REFINED_PEAKS)
    lower, upper, interior = bracket(index, omegas)

    def on_stencil(at):
        nearby = jnp.broadcast_to(monodromies[index][:, None], at.shape + monodromies.shape[-2:])
        # One vmap over every stencil point (a nested one would batch the solves' loops
        # twice over when traced).
        args = (at, interpolated(states, omegas, at), nearby)
        z, x = each(settle)(*jax.tree.map(lambda a: a.reshape((-1,) + a.shape[2:]), args))
        return x.reshape(at.shape), z.reshape(at.shape + z.shape[1:])

    no_states = jnp.zeros(stencil(centre, interior).shape + states.shape[1:], states.dtype)
    estimate, centre, at, stencil_states = newton_iterates(on_stencil, centre, interior,
                                                           lower, upper, no_states)
    # Each peak is shot with tangents from its last stencil's orbits, interpolated to its
    # frequency (the last Newton step's move from that stencil's centre): closer than
    # the grid's, so that no chord iterations (another copy of the solver in the
    # compiled program) precede the Newton iterations with tangents.
    start = jax.vmap(interpolated)(stencil_states, at, centre[:, None])[:, 0]

    def full(omega, z0):
        orbit, x_max, _ = point_response(tuned, omega, amplitude, settings, z0,
                                          quantity=quantity, fields=TUNING_FIELDS)
        return x_max, (orbit.monodromy, orbit.field_derivatives)

    values, (m_new, d_new) = jax.vmap(full)(centre, start)
    peak = located_peak(estimate, values)
    orbits = (states, monodromies.at[index].set(m_new), derivatives.at[index].set(d_new))
    return (jax.lax.stop_gradient(xs), (index, peak)), (
        jax.lax.stop_gradient(jnp.stack([k, c])), *orbits)


def _optimise_lane(system, amplitude, reference, omegas, u_start, z_start, h_start, *,
                   solver, sharpness, settings: SolverSettings, max_steps,
                   max_rejected_steps, small_cuts_end, quantity: Quantity):
    """BFGS on one lane of `optimise_stage`: `(u, steps, converged, orbits, inverse
    Hessian)`."""
    options = dict(autodiff_mode="fwd")
    tags = frozenset()

    def traced_objective(u, warm):
        (xs, (index, peak)), orbits = _design_sweep(system, quantity, omegas, u, amplitude,
                                                    reference, warm, settings)
        static = amplitude * static_unit(system)
        objective = smooth_log_peak(xs / static, omegas, sharpness, (index, peak / static))
        return objective, jax.lax.stop_gradient(orbits)

    # Traced once: the optimiser's steps replay this trace rather than tracing the
    # steady-state solves again.
    objective = eqx.filter_closure_convert(traced_objective, u_start, z_start)
    # Every shooting solve starts from the orbits of the last accepted design, so that
    # the Newton iterations of the steady states follow the optimiser.
    f_struct, aux_struct = objective.out_struct
    state = solver.init(objective, u_start, z_start, options, f_struct, aux_struct, tags)
    # A stage starts from the curvature that the last one learnt, not from the identity:
    # from a gradient step (about 0.1 long on the paper's system), the line search
    # would cut its way down to the small moves that a sharper maximum asks for
    # (1e-3 to 1e-4), one evaluation of the objective per cut.
    state = eqx.tree_at(lambda s: s.f_info.hessian_inv.pytree, state, h_start)

    def cond(carry):
        u, state, z, steps, rejected, settled = carry
        done, _ = solver.terminate(objective, u, z, options, state, tags)
        return ~done & (steps < max_steps) & (rejected < max_rejected_steps) & ~settled

    def body(carry):
        u, state, z, steps, rejected, _ = carry
        accepted = state.num_accepted_steps
        u, state, _ = solver.step(objective, u, z, options, state, tags)
        # A first step shortened on purpose (`InterpolatingArmijo.first_step`) says
        # nothing of the distance to the optimum: the stage does not end on it.
        shortened = (accepted == 1) & (solver.search.first_step < 1)
        state = eqx.tree_at(lambda s: s.terminate, state, state.terminate & ~shortened)
        z = jax.tree.map(lambda new, old: jnp.where(state.num_accepted_steps > 0, new, old),
                         state.aux, z)
        rejected = jnp.where(state.num_accepted_steps > accepted, 0, rejected + 1)
        # A rejected step cut to a move within the tolerance (as BFGS measures an
        # accepted step's): the line search is down to moves that would count as
        # converged, and no decrease is found above the noise of the objective. (Where
        # `small_cuts_end` is off, in the last stage, the design goes on creeping by
        # such moves where they are accepted: the optimum that `sensitivities` polishes.)
        settled = small_cuts_end & (rejected > 0) & cut_within_tolerance(solver, u, state)
        return u, state, z, steps + 1, rejected, settled

    u, state, z, steps, rejected, settled = jax.lax.while_loop(
        cond, body, (u_start, state, z_start, 0, 0, False)
    )
    done, result = solver.terminate(objective, u, z, options, state, tags)
    # A line search that finds no decrease in `max_rejected_steps` cuts, or none before
    # its cuts are within the tolerance, has reached the noise of the objective (steady
    # states converged to the periodicity tolerance).
    stalled = (rejected >= max_rejected_steps) | settled
    return (u, steps, (done & (result == optx.RESULTS.successful)) | stalled, z,
            state.f_info.hessian_inv.pytree)

