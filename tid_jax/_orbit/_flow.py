"""The stick-slip flow of exact Coulomb friction in closed form: one forcing period of a
structure with its TID in scaled form, for any number of storeys (the paper's system is
the one-storey building, `_building.as_building`).

Scaled units: phase `theta = omega t`, coordinates in units of `D = A d` (d: the static
scale, `BuildingTID.static_scale`; 1 / K for the paper's host), velocities in `omega D`.
The state is `z = (u, u')` over the coordinates u (`_building`: the floors, the stroke r
and a compliant device's mechanism q; the friction on the last), and

    z' = S z + f sin(theta) - phi_s F,      phi_s = phi / (omega^2 D),

with `S = [[0, I], [-Mg^-1 Kg / w^2, -Mg^-1 Cg / w]]`, `f = (0, Mg^-1 G / (w^2 d))`,
`F = (0, Mg^-1 e_f)` (f: the friction's coordinate, written r below; a compliant
device's backlash adds its play, smoothed friction only). Exact friction is linear in
each of three modes: slipping with sign s (`phi = s ff`), and stuck (`r' = 0`, r held:
the other coordinates move as the structure with the device held at that point, and the
friction force phi that holds it is linear in the state and the forcing). A slipping
inerter sticks where `r'` reaches 0 with `|phi| <= ff`, else slips back; a stuck one
slips with the sign of phi once `|phi|` reaches ff. Each mode's motion is a harmonic and
a constant particular solution plus its modal homogeneous part, so a period is a short
sequence of segments; each segment ends at the first of its mode's events, located on
the sample grid (an event function that dips below 0 and back between two samples is
not seen) and refined by safeguarded Newton steps. Every event time carries the
derivative of one Newton step from its (constant) root, the implicit derivative of the
event time, so that forward derivatives of the period map (the monodromy matrix, the
parameter Jacobians) include the jumps at the transitions (saltation) without any
special case.

Only projections of the state are sampled (the quantity, the stroke, r' and phi), so
that a period costs O(samples n) beyond its events.
"""

import functools as ft

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Complex, Float, Int

from .._model._building import BuildingTID, Quantity, building_of, selection
from .._model._system import TIDSystem
from ._eigen import eigensystem

MAX_SEGMENTS = 24  # segments per period; an orbit that needs more is reported as failed
_ROOT_ITERATIONS = 60  # safeguarded Newton iterations allowed per event
_STICK = 0
# rows of the sampled projections: the quantity, the stroke, its velocity, the friction
# force a stuck inerter needs
_QUANTITY, _STROKE, _STROKE_VELOCITY, _DEMAND = range(4)


class Plant(eqx.Module):
    """The scaled model at one (amplitude, frequency): matrices of the slipping field,
    the stuck field's friction demand `phi_s = demand . z + demand_sin sin(theta)`, the
    scaled friction, and the sampled projections `rows . z + rows_rate . z' +
    rows_sin sin(theta)`."""

    slip: Float[Array, "s s"]
    forcing: Float[Array, " s"]
    friction_vector: Float[Array, " s"]
    friction: Float[Array, ""]
    stuck: Float[Array, "s s"]  # the stuck field (rows of r and r' zero)
    stuck_forcing: Float[Array, " s"]
    demand: Float[Array, " s"]
    demand_sin: Float[Array, ""]
    rows: Float[Array, "4 s"]
    rows_rate: Float[Array, "4 s"]
    rows_sin: Float[Array, " 4"]
    width: Float[Array, ""]  # scaled friction width (smoothed friction), velocity units
    gap: Float[Array, ""]  # a compliant device's scaled backlash
    play_vector: Float[Array, " s"]  # the backlash's field per unit of s - D(s)
    stroke: int = eqx.field(static=True)  # the stroke's coordinate


def plant(system: BuildingTID, quantity: Quantity, amplitude, omega) -> Plant:
    """The scaled model of `system` at load amplitude `amplitude` and frequency `omega`
    (rad/s); differentiable with respect to the system's arrays."""
    w, wd, kappa, _ = selection(system, quantity)
    return scaled_plant(system.generalised_matrices(), system.load_vector(),
                        system.static_scale(), (w, wd, kappa), system.floors,
                        system.friction_force, system.width_at(amplitude, omega),
                        system.backlash, system.play_direction(), amplitude, omega)


class PlantInputs(eqx.Module):
    """What a structure's `Plant` is made from: the system (its fields by name), the
    measured quantity, the load amplitude and the frequency. A periodic orbit is
    differentiated with respect to these fields (`_implicit.with_field_derivatives`),
    not the plant's many derived entries."""

    system: BuildingTID | TIDSystem  # a `TIDSystem` as its one-storey building
    amplitude: Float[Array, ""]
    omega: Float[Array, ""]
    quantity: Quantity = eqx.field(static=True)

    def plant(self) -> "Plant":
        return plant(building_of(self.system, "force"), self.quantity, self.amplitude,
                     self.omega)


def scaled_plant(matrices, load, scale, quantity, stroke: int, friction_force, width,
                 backlash, play_direction, amplitude, omega) -> Plant:
    """The `Plant` of the generalised `matrices` `(Mg, Cg, Kg)` (the friction on the last
    coordinate) under the load `load` per unit amplitude, in units of the static `scale`
    d, measuring `quantity = (w, wd, kappa)` (`_building.selection`), the stroke on
    coordinate `stroke`, at amplitude A and frequency omega."""
    mass, damping, stiffness = matrices
    m = mass.shape[0]
    f = m - 1  # the friction's coordinate; the others move while it is stuck
    g = load / (omega**2 * scale)
    ks, cs = stiffness / omega**2, damping / omega
    eye, zeros = jnp.eye(m), jnp.zeros((m, m))
    inverse = jnp.linalg.inv(mass)
    slip = jnp.block([[zeros, eye], [-inverse @ ks, -inverse @ cs]])
    # stuck: the other coordinates' accelerations with u_f'' = u_f' = 0 (unknowns: those
    # and phi)
    held = mass.at[:, f].set(0.0).at[f, f].set(1.0)
    solve = jnp.linalg.inv(held)
    free = -solve @ jnp.concatenate([ks, cs.at[:, f].set(0.0)], axis=1)
    stuck = jnp.zeros((2 * m, 2 * m)).at[:f, m:m + f].set(jnp.eye(f)).at[m:m + f].set(free[:f])
    stuck_forcing = jnp.zeros(2 * m).at[m:m + f].set((solve @ g)[:f])
    w, wd, kappa = quantity
    units = np.zeros((2, 2 * m))
    units[0, stroke] = units[1, m + f] = 1.0  # the stroke; the friction's velocity
    rows = jnp.concatenate([jnp.append(jnp.asarray(w), jnp.zeros(m))[None],
                            jnp.asarray(units), free[f][None]])
    rows_rate = jnp.zeros((4, 2 * m)).at[_QUANTITY].set(jnp.append(jnp.zeros(m), wd))
    rows_sin = jnp.stack([kappa / (omega**2 * scale), 0.0 * scale, 0.0 * scale,
                          (solve @ g)[f]])
    unit = amplitude * scale
    return Plant(slip=slip, forcing=jnp.concatenate([jnp.zeros(m), inverse @ g]),
                 friction_vector=jnp.concatenate([jnp.zeros(m), inverse[:, f]]),
                 friction=friction_force / (omega**2 * unit),
                 stuck=stuck, stuck_forcing=stuck_forcing, demand=free[f],
                 demand_sin=(solve @ g)[f], rows=rows, rows_rate=rows_rate,
                 rows_sin=rows_sin, width=width / (omega * unit), gap=backlash / unit,
                 play_vector=jnp.concatenate([jnp.zeros(m),
                                              inverse @ play_direction / omega**2]),
                 stroke=stroke)


def projection_units(system: BuildingTID, quantity: Quantity, amplitude, omega):
    """SI units of the scaled quantity and stroke: `D` (or `omega^2 D` for an
    acceleration) and `D`."""
    unit = amplitude * system.static_scale()
    return (omega**2 * unit if quantity.kind == "acceleration" else unit), unit


class _Mode(eqx.Module):
    vectors: Complex[Array, "s s"]
    inverse: Complex[Array, "s s"]
    eigenvalues: Complex[Array, " s"]
    harmonic: Complex[Array, " s"]
    powers: Complex[Array, "grid s"]
    projected: Complex[Array, "4 s"]  # the projections of the modal vectors
    projected_harmonic: Complex[Array, " 4"]


class _Segment(eqx.Module):
    sign: Int[Array, ""]
    start: Float[Array, ""]
    constant: Float[Array, " s"]
    coefficients: Complex[Array, " s"]


def _mode(matrix, forcing, plant: Plant, grid, stuck: bool) -> _Mode:
    s = matrix.shape[0]
    m = s // 2
    if stuck:  # the floors' block alone; the stroke and its velocity held (eigenvalue 0)
        keep = np.r_[0:m - 1, m:s - 1]
        values, vectors = eigensystem(matrix[np.ix_(keep, keep)])
        inverse = jnp.linalg.inv(vectors)
        embed = lambda block: jnp.eye(s, dtype=complex).at[np.ix_(keep, keep)].set(block)
        values = jnp.zeros(s, complex).at[keep].set(values)
        vectors, inverse = embed(vectors), embed(inverse)
    else:
        values, vectors = eigensystem(matrix)
        inverse = jnp.linalg.inv(vectors)
    harmonic = vectors @ ((inverse @ (-1j * forcing)) / (1j - values))
    rows = plant.rows + 0j
    projected = rows @ vectors + (plant.rows_rate @ vectors) * values[None, :]
    projected_harmonic = rows @ harmonic + 1j * (plant.rows_rate @ harmonic)
    return _Mode(vectors, inverse, values, harmonic,
                 jnp.exp(values[None, :] * grid[:, None]), projected, projected_harmonic)


def segment_state(segment, mode, theta):
    """The state at phase `theta` (>= the segment's start) of a closed-form segment (a
    `_Segment` and its `_Mode`, or any with their fields) and its phase derivative."""
    tau = jnp.maximum(theta - segment.start, 0.0)
    growth = segment.coefficients * jnp.exp(mode.eigenvalues * tau)
    harmonic = mode.harmonic * jnp.exp(1j * theta)
    z = jnp.real(harmonic + mode.vectors @ growth) + segment.constant
    dz = jnp.real(1j * harmonic + mode.vectors @ (mode.eigenvalues * growth))
    return z, dz


def bracketed_root(g_of, low, high, g_low, g_high, active):
    """The phase in `[low, high]` where the event function `g_of(theta) -> (g, dg/dtheta)`
    changes sign (positive at `low`, negative at `high`), by Newton steps kept inside the
    shrinking bracket from the secant of the values `g_low`, `g_high` there; no
    iterations where not `active`."""
    secant = g_low / jnp.where(g_low == g_high, 1.0, g_low - g_high)
    first = low + (high - low) * jnp.clip(secant, 0.1, 0.9)
    tol = 1e-14 * 2 * np.pi

    def cond(carry):
        low, high, theta, step, i = carry
        return (jnp.abs(step) > tol) & (high - low > tol) & (i < _ROOT_ITERATIONS)

    def body(carry):
        low, high, theta, _, i = carry
        g, dg = g_of(theta)
        low, high = jnp.where(g >= 0, theta, low), jnp.where(g >= 0, high, theta)
        newton = theta - g / jnp.where(dg == 0, 1.0, dg)
        # (a step below theta's rounding leaves newton == theta, on the bracket's end)
        inside = (newton >= low) & (newton <= high) & (dg != 0)
        new = jnp.where(inside, newton, 0.5 * (low + high))
        return low, high, new, new - theta, i + 1

    _, _, theta, _, _ = jax.lax.while_loop(
        cond, body, (low, high, first, jnp.where(active, jnp.inf, 0.0).astype(low.dtype), 0)
    )
    return theta


def differentiable_root(g_of, theta0):
    """`theta0`, a root of the event function `g_of(theta) -> (g, dg/dtheta)`, with the
    forward derivative of one Newton step from it: the implicit derivative
    -dg / (dg/dtheta) of the event time (the value stays `theta0`)."""
    theta0 = jax.lax.stop_gradient(theta0)
    g, dg = g_of(theta0)
    dg = jax.lax.stop_gradient(jnp.where(dg == 0, 1.0, dg))
    return theta0 - (g - jax.lax.stop_gradient(g)) / dg


class Flow(eqx.Module):
    plant: Plant
    modes: tuple[_Mode, _Mode]


def _grid(samples: int, dtype):
    return jnp.arange(samples + 1, dtype=dtype) * (2 * np.pi / samples)


@ft.partial(jax.jit, static_argnums=1)
def flow(plant: Plant, samples: int) -> Flow:
    """The slipping and stuck modes of `plant` over a grid of `samples` phases."""
    grid = _grid(samples, plant.slip.dtype)
    return Flow(plant, (_mode(plant.slip, plant.forcing, plant, grid, False),
                        _mode(plant.stuck, plant.stuck_forcing, plant, grid, True)))


def _select(flag, a, b):
    return jax.tree.map(lambda x, y: jnp.where(flag, x, y), a, b)


def _constant(sign, z, plant: Plant):
    """The constant particular solution: static under the friction (slipping) or with
    the stroke held at z's (stuck)."""
    m = z.shape[0] // 2
    n = m - 1
    # slipping: S zc = s phi_s F -> zc = (-s phi_s Ks^-1 e_r, 0); from S's lower rows
    lower = plant.slip[m:, :m]  # -Mg^-1 Ks
    slipping = jnp.linalg.solve(lower, sign * plant.friction * plant.friction_vector[m:])
    # stuck: x'' = A_x x + (stroke column) r = 0 with r held
    block = plant.stuck[m:m + n, :n]
    held = jnp.linalg.solve(block, -plant.stuck[m:m + n, n] * z[n])
    stuck = jnp.zeros(2 * m).at[:n].set(held).at[n].set(z[n])
    return jnp.where(sign == _STICK, stuck, jnp.zeros(2 * m).at[:m].set(slipping))


def _start(sign, theta, z, plant: Plant, modes) -> _Segment:
    m = z.shape[0] // 2
    z = jnp.where(sign == _STICK, z.at[2 * m - 1].set(0.0), z)
    mode = _select(sign == _STICK, modes[1], modes[0])
    constant = _constant(sign, z, plant)
    particular = jnp.real(mode.harmonic * jnp.exp(1j * theta)) + constant
    return _Segment(sign, theta, constant, mode.inverse @ (z - particular).astype(complex))


def _projections(segment: _Segment, mode: _Mode, plant: Plant, grid, phasors):
    """The sampled projections (rows `_QUANTITY`..`_DEMAND`) over the grid from the
    segment's start on."""
    step = grid[1]
    first = jnp.clip(jnp.ceil(segment.start / step), 0, grid.shape[0] - 1)
    offset = jnp.exp(mode.eigenvalues * (first * step - segment.start))
    index = jnp.clip(jnp.arange(grid.shape[0]) - first.astype(int), 0, grid.shape[0] - 1)
    growth = segment.coefficients * offset * mode.powers[index]
    values = jnp.real(phasors[:, None] * mode.projected_harmonic + growth @ mode.projected.T)
    return values + plant.rows @ segment.constant + jnp.imag(phasors)[:, None] * plant.rows_sin


def _demand(z, theta, plant: Plant):
    return plant.demand @ z + plant.demand_sin * jnp.sin(theta)


def _event(segment: _Segment, z, dz, theta, plant: Plant):
    m = z.shape[0] // 2
    stuck = segment.sign == _STICK
    phi = _demand(z, theta, plant)
    dphi = plant.demand @ dz + plant.demand_sin * jnp.cos(theta)
    g = jnp.where(stuck, plant.friction - jnp.abs(phi), segment.sign * z[2 * m - 1])
    dg = jnp.where(stuck, -jnp.sign(phi) * dphi, segment.sign * dz[2 * m - 1])
    return g, dg


def _root(segment, mode, plant, low, high, g_low, g_high, active):
    return bracketed_root(lambda theta: _event(segment, *segment_state(segment, mode, theta), theta,
                                               plant), low, high, g_low, g_high, active)


def _next_sign(sign, z, theta, plant: Plant):
    """After an event at state `z`: a stuck inerter slips with the sign of phi; a
    slipping one sticks where |phi| <= ff, else slips with the sign of phi."""
    phi = _demand(z, theta, plant)
    slip = jnp.where(phi >= 0, 1, -1)
    return jnp.where((sign != _STICK) & (jnp.abs(phi) <= plant.friction), _STICK, slip)


def _initial_sign(z, plant: Plant):
    m = z.shape[0] // 2
    velocity = z[2 * m - 1]
    at_rest = _next_sign(jnp.ones((), int), z, jnp.zeros((), z.dtype), plant)
    return jnp.where(velocity > 0, 1, jnp.where(velocity < 0, -1, at_rest))


class _Period(eqx.Module):
    segment: _Segment
    samples: Float[Array, "samples 3"]
    z_end: Float[Array, " s"]
    transitions: Int[Array, ""]
    stroke_events: Float[Array, ""]
    done: Array


@ft.partial(jax.jit, static_argnums=(2, 3))
def period(z0, flow: Flow, keep_samples: bool = True, sample_tangents: bool = True):
    """One period of the stick-slip flow from `z0` at phase 0: the quantity, the stroke
    and the friction's velocity sampled at the grid's phases (`samples x 3`; without
    their derivatives unless `sample_tangents`), the state after the period (NaN past
    `MAX_SEGMENTS` segments), the number of transitions and the largest |stroke| at a
    transition."""
    dtype = z0.dtype
    plant, modes = flow.plant, flow.modes
    samples = modes[0].powers.shape[0] - 1
    grid = _grid(samples, dtype)
    phasors = jnp.exp(1j * grid)
    guard = 1e-9 * (2 * np.pi / samples)
    m = z0.shape[0] // 2

    def body(state: _Period):
        segment = state.segment
        mode = _select(segment.sign == _STICK, modes[1], modes[0])
        tangents = keep_samples and sample_tangents
        sampled = segment if tangents else jax.lax.stop_gradient(segment)
        values = _projections(sampled, mode, plant, grid, phasors)
        fixed = jax.lax.stop_gradient((segment, mode, plant, values))
        seg, fixed_values = fixed[0], fixed[3]
        g = jnp.where(seg.sign == _STICK, fixed[2].friction - jnp.abs(fixed_values[:, _DEMAND]),
                      seg.sign * fixed_values[:, _STROKE_VELOCITY])
        crossing = (grid > seg.start + guard) & (g < 0)
        ends = jnp.any(crossing)
        j = jnp.argmax(crossing)
        before = jnp.maximum(j - 1, 0)
        low = jnp.maximum(grid[before], seg.start)
        high = jnp.where(ends, grid[j], low + 1.0)
        g_low = jnp.where(grid[before] >= seg.start, g[before], 0.0)
        theta = _root(*fixed[:3], low, high, jnp.maximum(g_low, 0.0), jnp.minimum(g[j], 0.0),
                      ends)
        theta = differentiable_root(
            lambda t: _event(segment, *segment_state(segment, mode, t), t, plant), theta)
        theta = jnp.where(ends, theta, 2 * np.pi)
        own = (grid[:-1] >= segment.start) & (grid[:-1] < theta)
        kept = values[:-1, _QUANTITY:_STROKE_VELOCITY + 1]
        samples = jnp.where(own[:, None], kept, state.samples) if keep_samples else state.samples
        z, _ = segment_state(segment, mode, theta)
        z = jnp.where(segment.sign == _STICK, z, z.at[2 * m - 1].set(0.0))
        following = _start(_next_sign(segment.sign, z, theta, plant), theta, z, plant, modes)
        transitions = state.transitions + ends
        too_many = transitions >= MAX_SEGMENTS
        return _Period(
            segment=_select(ends, following, segment),
            samples=samples,
            z_end=jnp.where(ends, jnp.where(too_many, jnp.nan, state.z_end),
                            segment_state(segment, mode, grid[-1])[0]),
            transitions=transitions,
            stroke_events=jnp.where(
                ends, jnp.maximum(state.stroke_events, jnp.abs(z[plant.stroke])),
                state.stroke_events),
            done=~ends | too_many,
        )

    first = _start(_initial_sign(z0, plant), jnp.zeros((), dtype), z0, plant, modes)
    start = _Period(first, jnp.zeros((samples if keep_samples else 0, 3), dtype),
                    jnp.zeros_like(z0), jnp.zeros((), int), jnp.zeros((), dtype),
                    jnp.asarray(False))
    end = jax.lax.while_loop(lambda state: ~state.done, body, start)
    return end.samples, end.z_end, end.transitions, end.stroke_events
