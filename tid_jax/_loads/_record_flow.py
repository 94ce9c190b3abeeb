"""Exact stick-slip time histories of a rigid device with Coulomb friction under a
recorded ground motion.

Between two samples the ground acceleration is a straight line, `a = a0 + slope t`.
In each mode the state z = (u, u') obeys a linear equation with that input and one
constant, so its motion is known in closed form, `z(t) = p0 + p1 t + V e^{L t} V^-1
(z(0) - p0)` (the particular solution p0 + p1 t of the linear input and the constant,
the mode's eigen-decomposition, computed once per system):

- slipping with sign s (`s u_f' > 0`): `z' = A z + g a - s ff e`, the friction force
  `F = -s ff` on the friction's coordinate f (e its rate per unit force);
- stuck (`u_f = r` held, `u_f' = 0`): the reduced system of the other coordinates, with
  r as its constant, and the force F that holds f: the friction force the inerter
  carries while `|F| <= ff`.

Events end a mode: slipping, `s u_f'` reaches 0 (the inerter sticks if the holding
force there is within ff, else it slips back); stuck, `|F|` reaches ff (it slips against
F). Each record step checks its event signal at `grid` points (at least `GRID`, and
enough that the fastest mode turns by at most half a radian between two) with its
slope: a point below zero, or a turn between two points that may dip below it. A step
without one is advanced by matrices computed once; otherwise the step is cut at each
event, located by safeguarded Newton steps on the closed form, at most `max_events`
(default `MAX_EVENTS`) events a step (more are flagged, and the history is NaN from there on).

Smoothed friction and a compliant device are not written here (`friction_history`
holds their friction over substeps).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Complex, Float, Int

from .._model._building import BuildingTID, Quantity, selection, state_space
from .._orbit._eigen import eigensystem, eigenvalues
from ._records import GroundMotion, History

MAX_EVENTS = 32  # mode changes within one record step; more is flagged as a failure
GRID = 4  # the fewest points per record step at which the event signal is checked
_MAX_GRID = 64
# a turn of the event signal between two points whose cubic stays above this fraction of
# the signal's scale is taken as no event
DIP_MARGIN = 1e-2
_ROOT_ITERATIONS = 60
_ROOT_TOLERANCE = 1e-13  # of the record's step, in time
_STICK = 0
# quiet record steps tried in one iteration of the march's loop (fewer iterations: each
# has a fixed cost)
QUIET_STEPS = 4


class _Mode(eqx.Module):
    """`z' = matrix z + load a(t) + constant c`: the matrix's eigen-decomposition and
    inverse. The stuck mode keeps the full state: its rows of u_f and u_f' are
    `u_f' = r - u_f`, `u_f'' = -2 u_f'`, which hold them at (r, 0)."""

    eigenvalues: Complex[Array, " N"]
    vectors: Complex[Array, "N N"]
    inverse: Complex[Array, "N N"]
    solve: Float[Array, "N N"]
    load: Float[Array, " N"]
    constant: Float[Array, " N"]


class RecordFlow(eqx.Module):
    """A system's modes, the holding force `F = holding . z + holding_load a`, and over a
    whole record step per unit (z, a0, slope, c): the event signals' parts at the grid
    (u_f', its rate, F, its rate) and the state at the step's end."""

    slip: _Mode
    stuck: _Mode
    holding: Float[Array, " N"]
    holding_load: Float[Array, ""]
    friction_force: Float[Array, ""]
    signals: Float[Array, "2 points 4 P"]  # [slip, stuck], P = N + 3
    ends: Float[Array, "2 N P"]
    time_step: Float[Array, ""]
    grid: int = eqx.field(static=True)
    max_events: int = eqx.field(static=True)


def coefficients(mode: _Mode, inputs):
    """A segment's particular solution `p0 + p1 t` and modal coefficients, from `inputs`
    = (z(0), a(0), slope, c)."""
    n = mode.load.shape[0]
    z0, start, slope, constant = inputs[:n], inputs[n], inputs[n + 1], inputs[n + 2]
    p1 = -mode.solve @ (mode.load * slope)
    p0 = mode.solve @ (p1 - mode.load * start - mode.constant * constant)
    return p0, p1, mode.inverse @ (z0 - p0)


def state_at(mode: _Mode, segment, time):
    """The state and its rate at `time` (s) after the start of a segment (its
    `coefficients`)."""
    p0, p1, modal = segment
    growth = modal * jnp.exp(mode.eigenvalues * time)
    return (p0 + p1 * time + jnp.real(mode.vectors @ growth),
            p1 + jnp.real(mode.vectors @ (mode.eigenvalues * growth)))


def evolve(mode: _Mode, inputs, time):
    """The state and its rate at `time` (s) after the start of a segment in `mode`, from
    `inputs` = (z(0), a(0), slope, c)."""
    return state_at(mode, coefficients(mode, inputs), time)


def _modes(system: BuildingTID):
    mass, damping, stiffness = system.generalised_matrices()
    load = system.load_vector()
    m = system.coordinates
    f, size = m - 1, 2 * m
    A, g = state_space(system)
    friction = jnp.zeros(size).at[m:].set(jnp.linalg.solve(mass, jnp.eye(m)[f]))
    slip_values, slip_vectors = eigensystem(A)
    # stuck: the other coordinates x, with u_f = r held
    inverse = jnp.linalg.inv(mass[:f, :f])
    kept = jnp.concatenate([jnp.arange(f), m + jnp.arange(f)])
    reduced = jnp.zeros((2 * f, 2 * f)).at[:f, f:].set(jnp.eye(f))
    reduced = reduced.at[f:, :f].set(-inverse @ stiffness[:f, :f])
    reduced = reduced.at[f:, f:].set(-inverse @ damping[:f, :f])
    matrix = jnp.zeros((size, size)).at[jnp.ix_(kept, kept)].set(reduced)
    matrix = matrix.at[f, f].set(-1.0).at[size - 1, size - 1].set(-2.0)
    small_values, small_vectors = eigensystem(reduced)
    vectors = jnp.eye(size, dtype=small_vectors.dtype).at[jnp.ix_(kept, kept)].set(
        small_vectors)
    values = jnp.zeros(size, small_values.dtype).at[kept].set(small_values)
    values = values.at[f].set(-1.0).at[size - 1].set(-2.0)
    stuck_load = jnp.zeros(size).at[m:m + f].set(inverse @ load[:f])
    stuck_constant = jnp.zeros(size).at[m:m + f].set(-inverse @ stiffness[:f, f]).at[f].set(1.0)
    # (both modes' inverses in one batch each: fewer programs to compile)
    inverses = jnp.linalg.inv(jnp.stack([slip_vectors, vectors]))
    solves = jnp.linalg.inv(jnp.stack([A, matrix]))
    slip = _Mode(slip_values, slip_vectors, inverses[0], solves[0], g, friction)
    stuck = _Mode(values, vectors, inverses[1], solves[1], stuck_load, stuck_constant)
    # F = M[f,x] x'' + C[f,:] u' + K[f,:] u - g_f a, x'' from the stuck x rows
    row = mass[f, :f] @ inverse
    holding = jnp.concatenate([stiffness[f] - row @ stiffness[:f], damping[f] - row @ damping[:f]])
    return slip, stuck, holding, row @ load[:f] - load[f]


def grid_points(system: BuildingTID, time_step: float) -> int:
    """The points per record step of `time_step` (s) at which events are looked for:
    the fastest mode (slipping) turns by at most half a radian between two."""
    fastest = float(_fastest(system))
    return int(min(_MAX_GRID, max(GRID, math.ceil(2 * fastest * time_step))))


@eqx.filter_jit
def _fastest(system: BuildingTID):
    """The largest |eigenvalue| (rad/s) of the slipping system."""
    return jnp.max(jnp.abs(eigenvalues(state_space(system)[0])))


def record_flow(system: BuildingTID, time_step: float, grid: int = GRID,
                max_events: int = MAX_EVENTS) -> RecordFlow:
    """The flow of a rigid device with exact friction over record steps of `time_step`
    (s), events looked for at `grid` points a step, at most `max_events` a step."""
    slip, stuck, holding, holding_load = _modes(system)
    size = 2 * system.coordinates
    basis = jnp.eye(size + 3)
    times = jnp.linspace(0.0, time_step, grid + 1)

    def tabulated(mode):
        at = lambda t: jax.vmap(lambda x: evolve(mode, x, t), out_axes=-1)(basis)
        return jax.vmap(at)(times)

    def signals(mode):
        states, rates = tabulated(mode)
        start, slope = basis[size], basis[size + 1]
        force = holding @ states + holding_load * (start + times[:, None] * slope)
        rate = holding @ rates + holding_load * slope
        return jnp.stack([states[:, -1], rates[:, -1], force, rate], axis=1), states[-1]

    (slip_signals, slip_end), (stuck_signals, stuck_end) = signals(slip), signals(stuck)
    return RecordFlow(slip, stuck, holding, holding_load, system.friction_force,
                      jnp.stack([slip_signals, stuck_signals]),
                      jnp.stack([slip_end, stuck_end]), jnp.asarray(time_step), grid,
                      max_events)


def holding_force(flow: RecordFlow, z, a):
    """The force (N) on the friction's coordinate that keeps it stuck at state z."""
    return z @ flow.holding + flow.holding_load * a


def _decide(flow: RecordFlow, z, a):
    """The mode at a state with u_f' = 0: stuck (0) while the holding force is within
    ff, else slipping (+-1) against it."""
    force = holding_force(flow, z, a)
    held = (jnp.abs(force) <= flow.friction_force) & (flow.friction_force > 0)
    return jnp.where(held, _STICK, _against(force))


def _against(force):
    """The sign of a slip against `force` (forwards where it is zero)."""
    return jnp.where(force > 0, -1, 1)


def _signal(flow: RecordFlow, sign, states, rates, a, slope):
    """The event signal (positive while the mode holds) and its rate at states."""
    force = holding_force(flow, states, a)
    rate = rates @ flow.holding + flow.holding_load * slope
    return _event(flow, sign, states[..., -1], rates[..., -1], force, rate)


def _event(flow: RecordFlow, sign, velocity, acceleration, force, rate):
    """The event signal and its rate from u_f', u_f'', the holding force and its rate."""
    stuck = sign == _STICK
    g = jnp.where(stuck, flow.friction_force - jnp.abs(force), sign * velocity)
    return g, jnp.where(stuck, -jnp.sign(force) * rate, sign * acceleration)


def _constant(flow: RecordFlow, sign, z):
    m = z.shape[0] // 2
    return jnp.where(sign == _STICK, z[m - 1], -sign * flow.friction_force)


def _mode(flow: RecordFlow, sign) -> _Mode:
    return jax.tree.map(lambda a, b: jnp.where(sign == _STICK, b, a), flow.slip, flow.stuck)


def _crossing(times, g, rate, signal_at):
    """Whether the signal, sampled at `times` with its `rate`, falls below zero, and a
    bracket of its first fall: a sample below zero, or the minimum (by the secant of
    the rate) between two samples."""
    tolerance = 1e-12 * jnp.max(jnp.abs(g))
    dip = (rate[:-1] < 0) & (rate[1:] > 0)
    fraction = rate[:-1] / jnp.where(dip, rate[:-1] - rate[1:], 1.0)
    lowest = times[:-1] + jnp.clip(fraction, 0.0, 1.0) * (times[1:] - times[:-1])
    g_lowest = jax.vmap(signal_at)(lowest)
    below = g[1:] < -tolerance
    dipped = dip & (g_lowest < -tolerance)
    hit = below | dipped
    k = jnp.argmax(hit)
    high = jnp.where(dipped[k], lowest[k], times[k + 1])
    g_high = jnp.where(dipped[k], g_lowest[k], g[k + 1])
    return jnp.any(hit), times[k], high, jnp.maximum(g[k], 0.0), g_high


def _root(signal_with_rate, low, high, g_low, g_high, time_step, active):
    """The time in [low, high] where the signal falls through zero (`g_low` >= 0 at low,
    `g_high` < 0 at high): Newton steps from the secant, kept in the shrinking bracket;
    none where not `active`."""

    def cond(carry):
        _, _, _, i, done = carry
        return ~done & (i < _ROOT_ITERATIONS)

    def body(carry):
        low, high, x, i, _ = carry
        g, rate = signal_with_rate(x)
        below = g < 0
        low, high = jnp.where(below, low, x), jnp.where(below, x, high)
        newton = x - g / rate
        inside = (newton > low) & (newton < high)
        step = jnp.where(inside, newton, 0.5 * (low + high))
        done = (jnp.abs(step - x) <= _ROOT_TOLERANCE * time_step) | (
            high - low <= _ROOT_TOLERANCE * time_step) | (g == 0)
        return low, high, jnp.where(g == 0, x, step), i + 1, done

    fraction = g_low / jnp.where(active, g_low - g_high, 1.0)
    start = low + jnp.clip(fraction, 0.0, 1.0) * (high - low)
    return jax.lax.while_loop(cond, body, (low, high, start, 0, ~active))[2]


class _Cut(eqx.Module):
    time: Float[Array, ""]  # into the record step (s)
    z: Float[Array, " N"]
    sign: Int[Array, ""]
    events: Int[Array, ""]
    done: Bool[Array, ""]


def _segment(flow: RecordFlow, cut: _Cut, start, slope) -> _Cut:
    """From `cut` to the next event in the record step, or to the step's end."""
    mode = _mode(flow, cut.sign)
    a0 = start + slope * cut.time
    inputs = jnp.concatenate([cut.z, jnp.stack([a0, slope, _constant(flow, cut.sign, cut.z)])])
    segment = coefficients(mode, inputs)
    at = lambda t: state_at(mode, segment, t)

    def signal_with_rate(t):
        z, rate = at(t)
        return _signal(flow, cut.sign, z, rate, a0 + slope * t, slope)

    times = jnp.linspace(0.0, flow.time_step - cut.time, flow.grid + 1)
    states, rates = jax.vmap(at)(times)
    g, rate = _signal(flow, cut.sign, states, rates, a0 + slope * times, slope)
    event, *bracket = _crossing(times, g, rate, lambda t: signal_with_rate(t)[0])
    when = jnp.where(event, _root(signal_with_rate, *bracket, flow.time_step, event),
                     times[-1])
    z, _ = at(when)
    z = jnp.where(event, z.at[-1].set(0.0), z)
    # slipping: stuck or back; stuck: slipping against the holding force
    force = holding_force(flow, z, a0 + slope * when)
    after = jnp.where(cut.sign == _STICK, _against(force),
                      _decide(flow, z, a0 + slope * when))
    return _Cut(jnp.where(event, cut.time + when, flow.time_step), z,
                jnp.where(event, after, cut.sign), cut.events + event, ~event)


def _cut_step(flow: RecordFlow, z, sign, start, slope):
    """A record step cut at its events: the state, the mode and whether it took more
    than the flow's `max_events` events."""
    first = _Cut(jnp.asarray(0.0), z, sign, jnp.asarray(0), jnp.asarray(False))
    last = jax.lax.while_loop(lambda cut: ~cut.done & (cut.events <= flow.max_events),
                              lambda cut: _segment(flow, cut, start, slope), first)
    return last.z, last.sign, ~last.done


class _March(eqx.Module):
    """The history so far: the states and modes at the samples up to `index`."""

    index: Int[Array, ""]
    z: Float[Array, " N"]
    sign: Int[Array, ""]
    capped: Bool[Array, ""]
    blocked: Bool[Array, ""]  # the next step has an event to cut
    states: Float[Array, "samples N"]
    signs: Int[Array, " samples"]


def _advance(march: _March, go, z, sign, capped=False) -> _March:
    """`march` with the next sample's state and mode where `go`."""
    j = march.index + go
    z, sign = jnp.where(go, z, march.z), jnp.where(go, sign, march.sign)
    # (without a step, the sample reached is written again)
    return _March(j, z, sign, march.capped | (go & capped), ~go,
                  jax.lax.dynamic_update_index_in_dim(march.states, z, j, 0),
                  jax.lax.dynamic_update_index_in_dim(march.signs, sign, j, 0))


def _quiet_step(flow: RecordFlow, acceleration, last, march: _March) -> _March:
    """The next record step from matrices computed once, where its event signal shows no
    event and the march is neither blocked nor at the sample `last`; else `march`
    blocked."""
    start, end = acceleration[march.index], acceleration[march.index + 1]
    slope = (end - start) / flow.time_step
    stuck = (march.sign == _STICK).astype(int)
    inputs = jnp.concatenate([march.z, jnp.stack([start, slope,
                                                  _constant(flow, march.sign, march.z)])])
    g, rate = _event(flow, march.sign, *(flow.signals[stuck] @ inputs).T)
    go = _quiet(g, rate, flow.time_step / flow.grid) & ~march.blocked & (march.index < last)
    return _advance(march, go, flow.ends[stuck] @ inputs, march.sign)


def _quiet(g, rate, spacing):
    """Whether the event signal, at points `spacing` (s) apart with its rate, certainly
    stays positive: positive at the points and, between two where it turns up, above
    `DIP_MARGIN` of its scale at the cubic's control points (a lower bound of the cubic
    through the values and slopes)."""
    scale = jnp.max(jnp.abs(g))
    upturn = (rate[:-1] < 0) & (rate[1:] > 0)
    lower = jnp.minimum(g[:-1] + rate[:-1] * spacing / 3, g[1:] - rate[1:] * spacing / 3)
    return jnp.all(g[1:] >= -1e-12 * scale) & ~jnp.any(upturn & (lower < DIP_MARGIN * scale))


def _march(flow: RecordFlow, acceleration, last, march: _March) -> _March:
    """Quiet steps as far as they go (to the sample `last`), then one step cut at its
    events."""
    def quiet_steps(march):
        for _ in range(QUIET_STEPS):
            march = _quiet_step(flow, acceleration, last, march)
        return march

    march = jax.lax.while_loop(lambda m: ~m.blocked & (m.index < last), quiet_steps,
                               eqx.tree_at(lambda m: m.blocked, march, jnp.asarray(False)))
    j = jnp.minimum(march.index, last - 1)
    start, end = acceleration[j], acceleration[j + 1]
    z, sign, capped = _cut_step(flow, march.z, march.sign, start,
                                (end - start) / flow.time_step)
    # a step left unfinished is no state
    return _advance(march, march.index < last, jnp.where(capped, jnp.nan, z), sign, capped)


def exact_history(system: BuildingTID, motion: GroundMotion, quantity: Quantity,
                  max_events: int = MAX_EVENTS) -> History:
    """The exact stick-slip history of `quantity` and the stroke of `system` (a rigid
    device with exact friction, a ground load) under `motion`, from rest."""
    a = motion.acceleration
    grid = grid_points(system, motion.time_step)
    return _history(system, quantity, a, motion.time_step, grid, max_events)


@eqx.filter_jit
def _history(system, quantity, a, time_step, grid, max_events) -> History:
    flow = record_flow(system, time_step, grid, max_events)
    states, signs, forces, capped = march(flow, a, a.shape[0] - 1)
    values, stroke = outputs(system, quantity, a, states, forces)
    peak, rms, _ = summary(values, stroke, jnp.ones(a.shape[0], bool), capped)
    return History(time=jnp.arange(a.shape[0]) * time_step, quantity=values, stroke=stroke,
                   peak=peak, rms=rms, stuck=signs == _STICK, friction_force=forces,
                   events_capped=capped)


def outputs(system: BuildingTID, quantity: Quantity, acceleration, states, forces):
    """`quantity` (SI) and the stroke (m) at the samples from the states, the ground's
    `acceleration` (m/s2) and the friction forces (N) there."""
    m = system.coordinates
    A, g = state_space(system)
    friction = jnp.zeros(2 * m).at[m:].set(
        jnp.linalg.solve(system.generalised_matrices()[0], jnp.eye(m)[-1]))
    rates = states @ A.T + acceleration[:, None] * g + forces[:, None] * friction
    w, wd, kappa, _ = selection(system, quantity)
    values = (states[:, :m] @ jnp.asarray(w) + rates[:, m:] @ jnp.asarray(wd)
              + kappa * acceleration)
    return values, states[:, system.floors]


def summary(values, stroke, counted, capped):
    """The peak and the RMS of `values` and the stroke's peak over the `counted` samples;
    NaN where the solve was `capped`."""
    values, stroke = jnp.where(counted, values, 0.0), jnp.where(counted, stroke, 0.0)
    found = (jnp.max(jnp.abs(values)), jnp.sqrt(jnp.sum(values**2) / jnp.sum(counted)),
             jnp.max(jnp.abs(stroke)))
    return tuple(jnp.where(capped, jnp.nan, value) for value in found)


def march(flow: RecordFlow, acceleration: Float[Array, " samples"], last):
    """The states (u, u') at the samples from rest, the modes there (+-1 slipping, 0
    stuck), the friction forces (N) and whether some step needed more than the flow's
    `max_events` events; the record ends at the sample `last` (later samples, and those
    after a failure, are NaN)."""
    size, count = flow.slip.load.shape[0], acceleration.shape[0]
    z0 = jnp.zeros(size)
    sign0 = _decide(flow, z0, acceleration[0])
    first = _March(jnp.asarray(0), z0, sign0, jnp.asarray(False), jnp.asarray(False),
                   jnp.full((count, size), jnp.nan).at[0].set(z0),
                   jnp.zeros(count, sign0.dtype).at[0].set(sign0))
    last_march = jax.lax.while_loop(lambda m: (m.index < last) & ~m.capped,
                                    lambda m: _march(flow, acceleration, last, m), first)
    states, signs, capped = last_march.states, last_march.signs, last_march.capped
    forces = jnp.where(signs == _STICK, holding_force(flow, states, acceleration),
                       -signs * flow.friction_force + 0 * states[:, 0])
    return states, signs, forces, capped
