"""One periodic steady state of a `BuildingTID` at a time, traceable and warm-started
from a nearby orbit's state and monodromy matrix, for the building's designs: Newton's
and chord iterations on the period map (`_flow`, `_period`) with its monodromy matrix by
forward derivatives (exact friction) or the variational equations (smoothed friction),
and Floquet multipliers. Batches of steady states go through `_response.solve_points`."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._model._building import BuildingTID, Quantity
from ._eigen import eigenvalues
from ._flow import flow, period, plant, projection_units
from ._implicit import fixed_point_matrix, moving_part
from ._period import building_start, smoothed_period
from ._sampled_peaks import refined_peak
from ._settings import SolverSettings

_MAX_NEWTON_STEP = 2.0  # largest Newton update, relative to max(1, max |z|)
CHUNK = 2  # orbits solved together (vectorised) in a batch
_WARM_CHORDS = 6  # chord steps from a warm start before Newton's from the start again
_ROUNDS = 2  # rounds of Newton steps, each followed by chord steps
# Newton steps of a round before the chord steps (`solve_orbit`'s default): a Newton step
# of smoothed friction integrates s tangents, as dear as 10-20 periods without them, and
# chord steps from the first Newton matrix converge in as many steps as Newton's (8
# frequencies of the 10- and 30-storey buildings of `benchmarks/bench_building.py`: the
# same steps, 41 -> 16 and 327 -> 121 ms per orbit); exact friction's are cheap.
_NEWTON_STEPS = {True: 3, False: 1}  # by `settings.exact_friction`


def period_end(z, pl, fl, settings: SolverSettings):
    if settings.exact_friction:
        return period(z, fl, keep_samples=False)[1]
    return smoothed_period(z, pl, settings, keep_samples=False)[1]


def period_samples(z, pl, fl, settings: SolverSettings):
    if settings.exact_friction:
        return period(z, fl)
    return smoothed_period(z, pl, settings)


def _record(z, pl, fl, settings: SolverSettings, tangents: bool = False):
    """The period from `z`: its end, (without derivatives) its samples, transitions and
    largest stroke at a transition, and with `tangents` (smoothed friction) its
    monodromy matrix."""
    if settings.exact_friction:
        values, z_end, transitions, events = period(z, fl, sample_tangents=False)
        more = ()
    else:
        values, z_end, transitions, events, *more = smoothed_period(z, pl, settings,
                                                                    tangents=tangents)
    return (z_end, jax.lax.stop_gradient((values, transitions, events, z)), *more)


class _Newton(eqx.Module):
    z: Float[Array, " s"]
    monodromy: Float[Array, "s s"]
    lu: tuple  # LU factors of the fixed-point matrix held by the chord iterations
    residual: Float[Array, ""]  # inf until the iterations are done
    steps: Int[Array, ""]
    # the last period computed: its samples, transitions and largest stroke at one, its
    # start and |end - start|
    record: tuple
    checked: Float[Array, ""]


def _limited(z, update):
    size = jnp.max(jnp.abs(update))
    limit = _MAX_NEWTON_STEP * jnp.maximum(1.0, jnp.max(jnp.abs(z)))
    ok = jnp.all(jnp.isfinite(update))
    return jnp.where(ok, z + update * jnp.minimum(1.0, limit / jnp.maximum(size, 1e-300)), z)


def _newton(z0, pl, fl, settings: SolverSettings, tol, newton_steps: int,
            monodromy=None) -> _Newton:
    """Iterations for z = Phi_T(z) from `z0`: `newton_steps` Newton steps, each with the
    monodromy matrix (forward derivatives of the period map, or the variational equations
    of smoothed friction; the stuck stroke's family of orbits kept apart by
    `fixed_point_matrix`), then chord steps with the last matrix
    held, each one period without tangents, until the residual is within `tol` or
    after `settings.max_newton_steps` of them; then, where not done, all that again
    (`_ROUNDS` in all), each round integrating 100 times more accurately than the one
    before (`SolverSettings.more_accurate`: Newton's iterations stall where the
    integration error of the period map exceeds `tol`, as about backlash's steep force).
    Given a `monodromy` (of a nearby orbit: a warm start), up to `_WARM_CHORDS` chord
    steps with it come first, and the Newton steps start again from `z0` only where they
    did not converge."""
    basis = jnp.eye(z0.shape[0], dtype=z0.dtype)

    def iterations(accuracy: SolverSettings):
        """The Newton and the chord step with the period map integrated at `accuracy`."""
        record = lambda z: _record(z, pl, fl, accuracy)

        def newton(state):
            if fl is None:  # smoothed friction: by the variational equations
                z_end, kept, monodromy = _record(state.z, pl, fl, accuracy, tangents=True)
            else:
                z_end, monodromy, kept = jax.vmap(
                    lambda t: jax.jvp(record, (state.z,), (t,), has_aux=True),
                    out_axes=(None, 1, None))(basis)
            lu = jax.scipy.linalg.lu_factor(fixed_point_matrix(monodromy))
            return _step(state, z_end, kept, monodromy, lu)

        def chord(state):
            return _step(state, *record(state.z), state.monodromy, state.lu)

        return newton, chord

    def _step(state, z_end, kept, monodromy, lu):
        residual = z_end - state.z
        value = jnp.where(jnp.all(jnp.isfinite(residual)), jnp.max(jnp.abs(residual)), jnp.inf)
        done = value <= tol
        update = jax.scipy.linalg.lu_solve(lu, jnp.where(jnp.isfinite(residual), residual, 0.0))
        return _Newton(jnp.where(done, state.z, _limited(state.z, update)), monodromy, lu,
                       jnp.where(done, value, jnp.inf), state.steps + 1, kept, value)

    def until(limit):
        return lambda state: (state.residual > tol) & (state.steps < limit)

    s = z0.shape[0]
    eye = jnp.eye(s, dtype=z0.dtype)
    samples = settings.samples
    empty = (jnp.full((samples, 3), jnp.nan, z0.dtype), jnp.zeros((), int),
             jnp.zeros((), z0.dtype), z0)
    start = _Newton(z0, jnp.full((s, s), jnp.nan, z0.dtype),
                    jax.scipy.linalg.lu_factor(eye), jnp.asarray(jnp.inf, z0.dtype),
                    jnp.zeros((), int), empty, jnp.asarray(jnp.inf, z0.dtype))
    if monodromy is not None:
        warm = _Newton(z0, monodromy, jax.scipy.linalg.lu_factor(fixed_point_matrix(monodromy)),
                       start.residual, start.steps, empty, start.checked)
        usable = jnp.all(jnp.isfinite(monodromy))
        warm = jax.lax.while_loop(until(jnp.where(usable, _WARM_CHORDS, 0)),
                                  iterations(settings)[1], warm)
        cold = eqx.tree_at(lambda n: n.steps, start, warm.steps)
        start = jax.tree.map(lambda a, b: jnp.where(warm.residual <= tol, a, b), warm, cold)
    # (loops, not a switch in one: in a batch a switch would run both branches) Where the
    # chord steps stall (a period map with corners, as of backlash), Newton's again.
    state = start
    for round_ in range(_ROUNDS):
        newton, chord = iterations(settings.more_accurate(100.0**round_))
        state = jax.lax.while_loop(until(state.steps + newton_steps), newton, state)
        state = jax.lax.while_loop(until(state.steps + settings.max_newton_steps), chord,
                                   state)
    return state


class BuildingOrbit(eqx.Module):
    """The steady state at one (amplitude, frequency), SI units unless stated."""

    state: Float[Array, " s"]  # scaled (u, u') at phase 0
    response_max: Float[Array, ""]  # peak |quantity| over the period
    stroke_max: Float[Array, ""]  # peak |r|, m
    quantity_samples: Float[Array, " samples"]  # the quantity over the period, SI
    stroke_samples: Float[Array, " samples"]  # the stroke, m
    transitions: Int[Array, ""]  # stick-slip transitions per period (exact friction)
    floquet_max: Float[Array, ""]  # largest Floquet multiplier modulus (about the family)
    residual: Float[Array, ""]  # max |Phi_T(z) - z|, scaled
    newton_steps: Int[Array, ""]
    converged: Bool[Array, ""]
    monodromy: Float[Array, "s s"]  # of the period map, at the last Newton step


def solve_orbit(system: BuildingTID, quantity: Quantity, amplitude, omega,
                settings: SolverSettings, newton_steps: int | None = None, start=None,
                cold=None) -> BuildingOrbit:
    """The periodic steady state at one point (traceable; see `frequency_response`):
    `newton_steps` Newton steps (default: 3 with exact friction, 1 smoothed), then chord
    steps (`_newton`), from the linear equivalent
    state or from `start`, the state and monodromy matrix of a nearby orbit (with a
    scalar `cold`, where it is False; a monodromy matrix that is not finite is not
    used)."""
    pl = plant(system, quantity, amplitude, omega)
    fl = flow(pl, settings.samples) if settings.exact_friction else None
    tol = settings.exact_periodicity_tol if settings.exact_friction else settings.periodicity_tol

    def linear_start():
        z = building_start(system, amplitude, omega)
        if settings.transient_periods:
            z = jax.lax.fori_loop(0, settings.transient_periods,
                                  lambda _, z: period_end(z, pl, fl, settings), z)
        return z

    if start is None:
        z, monodromy = linear_start(), None
    else:
        z, monodromy = start
        if cold is not None:
            z = jax.lax.cond(cold, linear_start, lambda: z)
    if newton_steps is None:
        newton_steps = _NEWTON_STEPS[settings.exact_friction]
    newton = _newton(z, pl, fl, settings, tol, newton_steps, monodromy)
    # the last period the iterations computed: from the orbit's state where they are done
    values, transitions, stroke_events, state = newton.record
    residual = newton.checked
    unit_q, unit_r = projection_units(system, quantity, amplitude, omega)
    floquet = jnp.max(jnp.abs(eigenvalues(moving_part(newton.monodromy))))
    converged = (residual <= 10 * tol) & jnp.all(jnp.isfinite(values))
    return BuildingOrbit(
        state=state,
        response_max=refined_peak(values[:, 0]) * unit_q,
        # every extremum of a rigid device's stroke that has events is at one (r' = 0)
        # or on a stuck segment, where the samples hold it
        stroke_max=jnp.where((transitions > 0) & (not system.compliant),
                             jnp.maximum(jnp.max(jnp.abs(values[:, 1])), stroke_events),
                             refined_peak(values[:, 1])) * unit_r,
        quantity_samples=values[:, 0] * unit_q,
        stroke_samples=values[:, 1] * unit_r,
        transitions=transitions,
        floquet_max=floquet,
        residual=residual,
        newton_steps=newton.steps,
        converged=converged,
        monodromy=newton.monodromy,
    )


@eqx.filter_jit
def solve_orbits(system: BuildingTID, quantity: Quantity, amplitudes, omegas,
                 settings: SolverSettings) -> BuildingOrbit:
    """`solve_orbit` at each pair of `amplitudes` and `omegas` (1-d, one length), in
    batches of `CHUNK` (padded with the last pair): an orbit waits only for the slowest
    of its batch."""
    count = amplitudes.shape[0]
    pad = lambda x: jnp.concatenate([x, jnp.repeat(x[-1:], -count % CHUNK)])
    orbits = jax.lax.map(lambda aw: solve_orbit(system, quantity, *aw, settings),
                         (pad(amplitudes), pad(omegas)), batch_size=CHUNK)
    return jax.tree.map(lambda x: x[:count], orbits)


def building_settings(system: BuildingTID, settings: SolverSettings | None) -> SolverSettings:
    settings = SolverSettings() if settings is None else settings
    return eqx.tree_at(lambda s: s.exact_friction, settings, system.exact_friction)
