import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Complex, Float, Int

from .._model._building import building_of
from ._eigen import eigenvalues
from ._flow import Plant, PlantInputs
from ._implicit import (
    Periodic,
    Samples,
    field_columns,
    fixed_point_matrix,
    sample_jacobians,
    with_field_derivatives,
)
from ._period import (
    building_start,
    flow,
    period_samples,
    period_tangents,
    transient,
)
from ._sampled_peaks import refined_peak
from ._settings import SolverSettings


def one_by_one(function, floors: int):
    """`jax.vmap(function)` for the plants of a structure of `floors` storeys: batched for
    one storey, and for more computed one entry after the other (`jax.lax.map`), for the
    LAPACK calls (inverses, eigenvalues) of a large batch of plants with a building's
    matrices: batched, XLA's CPU thread pool can be left waiting on itself (seen with
    blocks of 512 three-storey buildings on two cores)."""
    if floors == 1:
        return jax.vmap(function)
    return lambda *args: jax.lax.map(lambda xs: function(*xs), args)


class Orbit(eqx.Module):
    """The periodic steady state at one (frequency, amplitude), scaled state units
    (displacements in A d, velocities in omega A d; d the static scale, 1 / K for the
    paper's host) unless stated."""

    state: Float[Array, " states"]  # scaled coordinates, then their velocities, at phase 0
    x_samples: Float[Array, " samples"]  # the scaled quantity over one period
    y_samples: Float[Array, " samples"]  # the scaled stroke
    y_velocity_samples: Float[Array, " samples"]  # the friction's coordinate's velocity
    y_events: Float[Array, ""]  # max |y| at the stick-slip transitions (exact friction; else 0)
    monodromy: Float[Array, "states states"]  # dPhi_T/dz at `state`
    floquet_multipliers: Complex[Array, " states"]
    residual: Float[Array, ""]  # max |Phi_T(z0) - z0|, scaled
    newton_steps: Int[Array, ""]
    converged: Bool[Array, ""]
    # d state / d field, one column per field that `solve_orbit` was asked for (else None)
    field_derivatives: Float[Array, "states fields"] | None = None


_MAX_NEWTON_STEP = 2.0  # largest Newton update, relative to max(1, max |z|)


def _limited(z, update):
    size = jnp.max(jnp.abs(update))
    limit = _MAX_NEWTON_STEP * jnp.maximum(1.0, jnp.max(jnp.abs(z)))
    return z + update * jnp.minimum(1.0, limit / jnp.maximum(size, jnp.finfo(z.dtype).tiny))


class _ChordLane(eqx.Module):
    """The state of chord iterations at one point (`_chord_step`)."""

    z: Float[Array, " states"]  # the next iterate
    lu: tuple  # LU factors of the fixed Jacobian `I - monodromy`
    best: Float[Array, " states"]  # the best iterate evaluated, its residual and samples
    best_residual: Float[Array, ""]
    best_samples: "Samples"
    last_residual: Float[Array, ""]  # of the last iterate evaluated
    improved: Bool[Array, ""]  # whether that residual was the best yet


def _chord_lane(z0, monodromy, settings: SolverSettings) -> _ChordLane:
    """Chord iterations about to start from `z0` with the monodromy matrix `monodromy` (of
    a nearby orbit) held."""
    nan = jnp.full(settings.samples, jnp.nan, z0.dtype)
    zero = jnp.zeros((), z0.dtype)
    inf = jnp.asarray(jnp.inf, z0.dtype)
    no_samples = Samples(nan, nan, nan, jnp.full(z0.shape, jnp.nan, z0.dtype), zero, zero)
    lu = jax.scipy.linalg.lu_factor(fixed_point_matrix(monodromy))
    return _ChordLane(z0, lu, z0, inf, no_samples, inf, jnp.asarray(False))


def _chord_step(lane: _ChordLane, p, settings: SolverSettings, modes) -> _ChordLane:
    """One chord iteration for z* = Phi_T(z*) with the fixed Jacobian of `lane`: one
    integration without tangents (of the flow `modes` at `p`: `_period.flow`), which
    also samples the orbit over the period. The next iterate stays where the residual is
    within `settings.periodicity_tol` or not finite."""
    samples = Samples(*period_samples(lane.z, p, settings, modes))
    residual = _residual(samples, lane.z)
    improved = residual < lane.best_residual

    def keep(new, old):
        return jnp.where(improved, new, old)

    ok = jnp.isfinite(residual)
    update = jax.scipy.linalg.lu_solve(lane.lu, jnp.where(ok, samples.z_end - lane.z, 0.0))
    stay = (residual <= settings.periodicity_tol) | ~ok
    return _ChordLane(
        z=jnp.where(stay, lane.z, _limited(lane.z, update)),
        lu=lane.lu,
        best=keep(lane.z, lane.best),
        best_residual=jnp.minimum(residual, lane.best_residual),
        best_samples=jax.tree.map(keep, samples, lane.best_samples),
        last_residual=residual,
        improved=improved,
    )


def _chord(z0, p, settings: SolverSettings, monodromy):
    """Chord iterations (`_chord_step`) for z* = Phi_T(z*) with the fixed Jacobian
    `I - monodromy` (from a nearby orbit). Stops once the residual is within
    `settings.periodicity_tol` or after `settings.max_newton_steps` iterations. Returns
    the last iterate while the residuals fall, else the best one evaluated (`z0` if none
    is finite), and the x samples of the best iterate evaluated."""
    modes = flow(p, settings)

    def cond(carry):
        lane, steps = carry
        return ((lane.best_residual > settings.periodicity_tol)
                & (steps < settings.max_newton_steps))

    def body(carry):
        lane, steps = carry
        return _chord_step(lane, p, settings, modes), steps + 1

    lane, _ = jax.lax.while_loop(cond, body, (_chord_lane(z0, monodromy, settings), 0))
    z = jnp.where(lane.improved & jnp.all(jnp.isfinite(lane.z)), lane.z, lane.best)
    return z, lane.best_samples.xs


def settled_state(z0, p, settings: SolverSettings, monodromy):
    """The periodic orbit at `p` by chord iterations from `z0` with the monodromy matrix of
    a nearby orbit (`_chord`; no tangents): the scaled state (the last iterate, or the best
    one evaluated where the residuals stopped falling) and the x samples over a period of
    the best iterate evaluated (NaN if none was)."""
    return _chord(jax.lax.stop_gradient(z0), jax.lax.stop_gradient(p), settings,
                  jax.lax.stop_gradient(monodromy))


class _Newton(eqx.Module):
    z: Float[Array, " states"]  # the iterate
    update: Float[Array, " states"]  # its Newton update (zero where it is not finite)
    monodromy: Float[Array, "states states"]
    residual: Float[Array, ""]  # max |Phi_T(z) - z|, inf where not finite


def _newton(z, p, settings: SolverSettings, modes) -> _Newton:
    z_end, monodromy = period_tangents(z, p, settings, modes)
    residual = z_end - z
    update = jnp.linalg.solve(fixed_point_matrix(monodromy), residual)
    finite = jnp.all(jnp.isfinite(update))
    return _Newton(
        z=z,
        update=jnp.where(finite, update, 0.0),
        monodromy=monodromy,
        residual=jnp.where(finite, jnp.max(jnp.abs(residual)), jnp.inf),
    )


class Shots(eqx.Module):
    """Shooting results for a batch of points (scaled units): the best iterate evaluated,
    its samples over the period and residual |Phi_T(z) - z|, the monodromy matrix of the
    last Newton iterate (within `SolverSettings.chord_residual` of the orbit) and the
    period integrations used."""

    state: Float[Array, "points states"]
    samples: "Samples"
    monodromy: Float[Array, "points states states"]
    residual: Float[Array, " points"]
    newton_steps: Int[Array, " points"]


class _Lanes(eqx.Module):
    point: Int[Array, " slots"]  # the point each lane works on
    carry: object  # each lane's own state (a pytree with a leading axis of lanes)
    steps: Int[Array, " slots"]
    active: Bool[Array, " slots"]
    next_point: Int[Array, ""]  # position in `order` of the next point to take
    out: object  # each point's record (a pytree with a leading axis of points)
    out_steps: Int[Array, " points"]


def _work_queue(start, step, data, order, count, slots: int, max_steps: int, out):
    """Works through the points `order[:count]` on `slots` lanes: each lane starts a point
    with `start(d)` (d: the point's entries of `data`, a pytree of per-point arrays) and
    iterates `carry, done, record = step(carry, d)` until `done` or `max_steps` steps; the
    point's last `record` is then written into `out` (and its steps into the returned
    counts) and the lane takes the next point at once, so that no lane waits for the
    slowest point (each iteration still runs all lanes together)."""
    size = order.shape[0]
    slots = min(slots, size)

    def take(points):
        return jax.tree.map(lambda a: a[points], data)

    first = order[:slots]
    lanes = _Lanes(
        point=first,
        carry=jax.vmap(start)(take(first)),
        steps=jnp.zeros(slots, int),
        active=jnp.arange(slots) < count,
        next_point=jnp.minimum(slots, count),
        out=out,
        out_steps=jnp.zeros(size, int),
    )

    def body(lanes):
        carry, done, record = jax.vmap(step)(lanes.carry, take(lanes.point))
        steps = lanes.steps + 1
        done = lanes.active & (done | (steps >= max_steps))
        where = jnp.where(done, lanes.point, size)  # out of range: dropped
        out = jax.tree.map(lambda o, r: o.at[where].set(r, mode="drop"), lanes.out, record)
        position = lanes.next_point + jnp.cumsum(done) - 1
        takes = done & (position < count)
        point = jnp.where(takes, order[jnp.minimum(position, size - 1)], lanes.point)
        fresh = jax.vmap(start)(take(point))

        def pick(new, old):
            return jnp.where(takes.reshape((-1,) + (1,) * (new.ndim - 1)), new, old)

        return _Lanes(
            point=point,
            carry=jax.tree.map(pick, fresh, carry),
            steps=jnp.where(takes, 0, steps),
            active=jnp.where(done, takes, lanes.active),
            next_point=lanes.next_point + jnp.sum(done),
            out=out,
            out_steps=lanes.out_steps.at[where].set(steps, mode="drop"),
        )

    lanes = jax.lax.while_loop(lambda lanes: jnp.any(lanes.active), body, lanes)
    return lanes.out, lanes.out_steps


def _newton_phase(z0, p, modes, settings: SolverSettings, order, count, slots, switch):
    """Newton's iterations integrated with `settings` for the points `order[:count]`,
    from `z0`, until the residual is within `switch`: each point's last evaluation
    (`_Newton`, its update not applied) and the evaluations used. `modes`: the points'
    flows (`_period.flow`)."""

    def step(z, d):
        newton = _newton(z, d[1], settings, d[2])
        return _limited(newton.z, newton.update), newton.residual <= switch, newton

    return _work_queue(lambda d: d[0], step, (z0, p, modes), order, count, slots,
                       settings.max_newton_steps, _not_evaluated(z0))


def _not_evaluated(z: Float[Array, "points states"]) -> _Newton:
    """The states `z` as Newton evaluations not made: no update, no monodromy matrix, the
    residual inf."""
    size, n = z.shape
    return _Newton(z, jnp.zeros_like(z), jnp.zeros((size, n, n), z.dtype),
                   jnp.full(size, jnp.inf, z.dtype))


def _next_iterate(newton: _Newton, settings: SolverSettings):
    """Where to go on from a Newton evaluation: its state if it has converged, else its
    update applied."""
    return jnp.where(newton.residual <= settings.periodicity_tol, newton.z,
                     _limited(newton.z, newton.update))


def _chord_phase(newton: _Newton, p, modes, settings: SolverSettings, order, count, slots):
    """Chord iterations (`_chord_step`) with each point's last Newton matrix held, from
    where its Newton iterations leave it (`_next_iterate`), each one integration without
    tangents that also samples the orbit and verifies it. They stop at the periodicity
    tolerance, or once the residual falls by less than half. Each point's chord state
    (`_ChordLane`, its best iterate) and the integrations used."""

    def start(d):
        last = d[0]
        return _chord_lane(_next_iterate(last, settings), last.monodromy, settings)

    def step(lane, d):
        lane_next = _chord_step(lane, d[1], settings, d[2])
        residual = lane_next.last_residual
        # (the first evaluation follows `last_residual` inf: it stops only if not finite)
        done = (residual <= settings.periodicity_tol) | ~(residual < 0.5 * lane.last_residual)
        return lane_next, done, lane_next

    out = jax.vmap(start)((newton, p, modes))
    return _work_queue(start, step, (newton, p, modes), order, count, slots,
                       settings.max_newton_steps, out)


def shoot_queue(z0: Float[Array, "points states"], p: Plant,
                settings: SolverSettings, slots: int,
                valid: Bool[Array, " points"] | None = None) -> Shots:
    """Periodic orbits at every point (`z0[i]`, `p[i]`), on `slots` lanes that work through
    the points as queues (`_work_queue`), in three stages: Newton's iterations integrated
    at the coarse `settings.coarse_rtol` until the residual is within
    `settings.coarse_residual`; Newton's iterations at `settings.rtol` until it is within
    `settings.chord_residual`; chord iterations with the last Newton matrix held, each
    one integration without tangents that also samples the orbit and verifies it. The
    best iterate evaluated is returned with its samples and residual, and the monodromy
    matrix of the last Newton iterate. Points where `valid` is False are skipped. Where
    the coarse settings are these settings (`SolverSettings.coarse`), the first stage
    would repeat the second: Newton's iterations at `settings.rtol` start at once."""
    size = z0.shape[0]
    valid = jnp.ones(size, bool) if valid is None else valid
    order = jnp.argsort(~valid, stable=True)
    count = jnp.sum(valid)
    # (the coarse settings integrate the same flows: they differ in tolerances alone)
    modes = one_by_one(lambda q: flow(q, settings), p.stroke)(p)
    # Newton's stages, one after the other, as the iterations of a loop over their
    # tolerances: a compiled program holds one copy of the variational integration.
    stages = [(settings.rtol, settings.atol, settings.chord_residual)]
    coarse = settings.coarse()
    if coarse is not settings:
        stages.insert(0, (coarse.rtol, coarse.atol, settings.coarse_residual))

    def stage(carry, tolerances):
        newton, steps = carry
        rtol, atol, switch = tolerances
        staged = eqx.tree_at(lambda s: (s.rtol, s.atol), settings, (rtol, atol))
        z = jax.vmap(lambda last: _next_iterate(last, settings))(newton)
        newton, used = _newton_phase(z, p, modes, staged, order, count, slots, switch)
        return (newton, steps + used), None

    stages = jax.tree.map(lambda *values: jnp.stack(jnp.broadcast_arrays(*values)), *stages)
    (newton, newton_steps), _ = jax.lax.scan(
        stage, (_not_evaluated(z0), jnp.zeros(size, int)), stages)
    chord, chord_steps = _chord_phase(newton, p, modes, settings, order, count, slots)
    return Shots(chord.best, chord.best_samples, newton.monodromy, chord.best_residual,
                 newton_steps + chord_steps)


def verified_samples(z: Float[Array, " states"], p: Plant,
                     settings: SolverSettings, modes=None):
    """x, y, y' sampled over the period from `z`, and the residual |Phi_T(z) - z| of that
    integration (inf where it is not finite). `modes`: the flow at `p` (`_period.flow`),
    if computed already."""
    samples = Samples(*period_samples(z, p, settings, modes))
    return samples, _residual(samples, z)


def _residual(samples, z):
    finite = jnp.all(jnp.isfinite(samples.z_end)) & jnp.all(jnp.isfinite(samples.xs))
    finite = finite & jnp.all(jnp.isfinite(samples.ys))
    return jnp.where(finite, jnp.max(jnp.abs(samples.z_end - z)), jnp.inf)


def _iterate(evaluate, z0, settings: SolverSettings):
    """Newton's iterations `evaluate(z)` (with fields `z`, `update`, `residual`) from `z0`
    until the residual is within `settings.periodicity_tol` or after
    `settings.max_newton_steps` evaluations: the last evaluation and their count.
    `evaluate` is traced once, and evaluated only in the loop, which makes the first
    evaluation too (at `z0`): a compiled program holds one copy of its integration."""
    evaluate = eqx.filter_closure_convert(evaluate, z0)

    def cond(carry):
        newton, steps = carry
        return (newton.residual > settings.periodicity_tol) & (steps < settings.max_newton_steps)

    def body(carry):
        newton, steps = carry
        z = jnp.where(steps == 0, z0, _limited(newton.z, newton.update))
        return evaluate(z), steps + 1

    # Before the first evaluation: its shapes, the residual inf (not converged).
    unevaluated = jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), evaluate.out_struct)
    unevaluated = eqx.tree_at(lambda n: n.residual, unevaluated,
                              jnp.full_like(unevaluated.residual, jnp.inf))
    return jax.lax.while_loop(cond, body, (unevaluated, jnp.array(0)))


class _TangentNewton(eqx.Module):
    z: Float[Array, " states"]
    update: Float[Array, " states"]
    residual: Float[Array, ""]
    samples: Samples
    of_state: Samples
    of_fields: Samples


def _tangent_newton(z, plant: Plant, settings: SolverSettings, columns) -> _TangentNewton:
    samples, of_state, of_fields = sample_jacobians(z, plant, settings, columns)
    residual = samples.z_end - z
    update = jnp.linalg.solve(fixed_point_matrix(of_state.z_end), residual)
    finite = jnp.all(jnp.isfinite(update)) & jnp.all(jnp.isfinite(samples.xs))
    finite = finite & jnp.all(jnp.isfinite(samples.ys))
    return _TangentNewton(z=z, update=jnp.where(finite, update, 0.0),
                          residual=jnp.where(finite, jnp.max(jnp.abs(residual)), jnp.inf),
                          samples=samples, of_state=of_state, of_fields=of_fields)


def _shoot(z0, plant: Plant, settings: SolverSettings, columns=None):
    """Newton shooting for z* = Phi_T(z*), returning the orbit once the residual is within
    `settings.periodicity_tol`.

    Without `columns`, each iteration integrates one period with the variational
    equations (the residual Phi_T(z) - z and the monodromy matrix); the last iterate
    evaluated is then integrated once more to sample it over a period, and the residual
    of that integration is the one returned, which decides convergence. With `columns`
    (the plant's tangents along some of the system's fields, `field_columns`), each
    iteration differentiates the integration along the state and those tangents, which
    gives the samples' Jacobians at once; the last update is applied to the samples to
    first order (their error is then second order in the residual returned, the last
    one evaluated)."""
    if columns is not None:
        last, steps = _iterate(lambda z: _tangent_newton(z, plant, settings, columns), z0,
                               settings)
        samples = jax.tree.map(lambda value, jacobian: value + jacobian @ last.update,
                               last.samples, last.of_state)
        orbit = Periodic(last.z + last.update, samples, last.of_state.z_end, last.of_state,
                         last.of_fields)
        return orbit, last.residual, steps
    modes = flow(plant, settings)
    last, steps = _iterate(lambda z: _newton(z, plant, settings, modes), z0, settings)
    z = last.z  # as in `shoot_queue`: the last iterate evaluated, without its update
    samples, residual = verified_samples(z, plant, settings, modes)
    return Periodic(z, samples, last.monodromy), residual, steps


def solve_orbit(
    inputs: PlantInputs,
    settings: SolverSettings,
    z_init: Float[Array, " states"] | None = None,
    monodromy_init: Float[Array, "states states"] | None = None,
    fields: tuple[str, ...] = (),
) -> Orbit:
    """The periodic orbit of the plant of `inputs` (a structure, its load amplitude and
    frequency) by shooting from `z_init` (scaled state; default the equivalent linear
    steady state, `_period.building_start`, followed by `settings.transient_periods`
    periods). Differentiable with respect to the fields of `inputs` (implicit
    differentiation, in forward and reverse mode), not with respect to `z_init`.

    With `monodromy_init`, the monodromy matrix of a nearby orbit (e.g. that of `z_init`
    at slightly different parameters), chord iterations without tangents bring `z_init`
    to the orbit before Newton's.

    With `fields` (names of the system's scalar fields), the shooting's Newton iterations
    carry tangents along them: the orbit's derivatives with respect to them come at once
    (`Orbit.field_derivatives`, and the implicit derivatives use them)."""
    plant = jax.lax.stop_gradient(inputs.plant())
    if z_init is None:
        system = jax.lax.stop_gradient(inputs.system)
        z_init = transient(building_start(building_of(system, "force"), inputs.amplitude,
                                          inputs.omega), plant, settings)
    z_init = jax.lax.stop_gradient(z_init)
    if monodromy_init is not None:
        z_init, _ = _chord(z_init, plant, settings, jax.lax.stop_gradient(monodromy_init))
    columns = (jax.lax.stop_gradient(field_columns(inputs, fields)) if fields else None)
    orbit, residual, steps = _shoot(z_init, plant, settings, columns)
    derivatives = None
    if fields:
        derivatives = jax.lax.stop_gradient(jnp.linalg.solve(
            fixed_point_matrix(orbit.monodromy), orbit.field_jacobians.z_end))
    orbit = with_field_derivatives(settings, inputs, orbit, plant, fields)
    converged = (residual <= settings.periodicity_tol) & jnp.all(jnp.isfinite(orbit.samples.xs))
    monodromy = jax.lax.stop_gradient(orbit.monodromy)
    return Orbit(
        state=orbit.z,
        x_samples=orbit.samples.xs,
        y_samples=orbit.samples.ys,
        y_velocity_samples=orbit.samples.ws,
        y_events=orbit.samples.y_events,
        monodromy=monodromy,
        floquet_multipliers=eigenvalues(monodromy),
        residual=residual,
        newton_steps=steps,
        converged=converged,
        field_derivatives=derivatives,
    )


def y_peak(y_samples: Float[Array, " n"], y_events: Float[Array, ""],
           settings: SolverSettings) -> Float[Array, ""]:
    """max |y| over a period: with exact friction on a rigid device (y the friction's
    coordinate), the largest of the samples and of y at the transitions (where every
    extremum lies: y is not twice differentiable there, so no parabola is fitted); else
    the refined peak of the samples."""
    if settings.exact_friction and not settings.compliant:
        return jnp.maximum(jnp.max(jnp.abs(y_samples)), y_events)
    return refined_peak(y_samples)
