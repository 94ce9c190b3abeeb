"""Exact Coulomb friction: the period map of the hybrid stick-slip flow.

With `ff sgn(y')` exact, eq. (12) is linear in each of three modes: slipping forwards
(`y' > 0`), slipping backwards (`y' < 0`), and stuck (`y' = 0`, `y` held, while the force
`F = k (x - y) + c (x' - y')` that the spring and damper put on the terminal stays within
`ff`). In each mode the motion under the forcing `A sin(theta)` is known in closed form
(constant and harmonic particular solutions plus the modal homogeneous part), so a
period is a short sequence of segments; each segment ends at the first of its mode's
events, located on the sample grid (an event function that dips below 0 and back
between two samples is not seen) and refined by safeguarded Newton steps:

- slipping with sign `s`: `s y'` reaches 0; the terminal sticks there if `|F| <= ff`, else
  it slips back (sign `-s`);
- stuck: `|F|` reaches `ff`; the terminal slips with the sign of `F`.

Every event time carries the derivative of one Newton step from its (constant) root,
which is the implicit derivative of the event time, so that forward derivatives of the
period map (the monodromy matrix, the parameter Jacobians) include the jumps at the
transitions (saltation) without any special case.

Units are those of `_dynamics`: phase `theta = omega t`, displacements in A / K,
velocities in omega A / K.
"""

import functools as ft
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Complex, Float, Int

from .._model._dynamics import linear_part
from ._eigen import eigensystem

MAX_SEGMENTS = 24  # segments per period; an orbit that needs more is reported as failed
_ROOT_ITERATIONS = 60  # safeguarded Newton iterations allowed per event
_STICK = 0


class _Mode(eqx.Module):
    """The closed-form motion in one mode: `z(theta) = Re(harmonic e^{i theta}) + constant
    + Re(vectors (coefficients * e^{eigenvalues (theta - start)}))`."""

    vectors: Complex[Array, "4 4"]
    inverse: Complex[Array, "4 4"]
    eigenvalues: Complex[Array, " 4"]
    harmonic: Complex[Array, " 4"]
    powers: Complex[Array, "grid 4"]  # e^{eigenvalues * m * (2 pi / samples)}, m = 0..samples


class _Segment(eqx.Module):
    sign: Int[Array, ""]  # +1 or -1 slipping, 0 stuck
    start: Float[Array, ""]  # phase at which the segment starts
    constant: Float[Array, " 4"]  # constant particular solution
    coefficients: Complex[Array, " 4"]  # modal coefficients of the homogeneous part


class _Period(eqx.Module):
    segment: _Segment  # the segment in progress
    samples: Float[Array, "samples 4"]  # none without keep_samples
    z_end: Float[Array, " 4"]  # the state after the period, once reached
    transitions: Int[Array, ""]
    y_events: Float[Array, ""]  # max |y| at the transitions so far
    done: Bool[Array, ""]


class _Quantities(NamedTuple):
    """The parameters of `p` that the modes and events use (the friction per unit A / K),
    taken out of `p` once for a period."""

    mass: Float[Array, ""]
    stiffness: Float[Array, ""]
    k: Float[Array, ""]
    c: Float[Array, ""]
    omega: Float[Array, ""]
    friction: Float[Array, ""]


def _quantities(p) -> _Quantities:
    mass, stiffness, _, _, friction, k, c, *_, amplitude, omega = p
    scale = amplitude / stiffness
    return _Quantities(mass, stiffness, k, c, omega, friction / scale)


def _slip_matrix(p):
    """The matrix of the scaled field's linear part (`_dynamics.linear_part`), column j
    the field of the unit state j."""
    return jnp.stack(linear_part(jnp.eye(4, dtype=p.dtype), p))


def _forcing(q: _Quantities):
    zero = jnp.zeros_like(q.mass)
    return jnp.stack([zero, q.stiffness / (q.mass * q.omega**2), zero, zero])


def _modes(p, q: _Quantities, grid) -> tuple[_Mode, _Mode]:
    """The slipping mode (both signs share it) and the stuck mode, whose homogeneous part
    moves only the host (the terminal's rows are zero), with their powers over the
    uniform phase `grid` (from 0)."""
    powers = lambda eigenvalues: jnp.exp(eigenvalues[None, :] * grid[:, None])
    matrix = _slip_matrix(p)
    forcing = _forcing(q).astype(complex)
    # The motion depends on the eigenvectors only through `vectors diag(.) vectors^-1`,
    # whatever their normalisation, and the modes' eigenvalues are distinct (a damped
    # oscillator's complex pair, or two real ones off critical damping). The harmonic
    # particular solution Re(H e^{i theta}) under the forcing F sin(theta) =
    # Re(-i F e^{i theta}): (i - A) H = -i F, solved in the modal basis.
    eigenvalues, vectors = eigensystem(matrix)
    inverse = jnp.linalg.inv(vectors)
    harmonic = vectors @ ((inverse @ (-1j * forcing)) / (1j - eigenvalues))
    slip = _Mode(vectors, inverse, eigenvalues, harmonic, powers(eigenvalues))
    # The host alone, x'' = a x + b x' (its rows of `matrix`: x' = v, v' = a x + b v,
    # forcing apart), in closed form: eigenvalues l = b/2 +- sqrt(b^2/4 + a), eigenvectors
    # (1, l).
    a, b = matrix[1, 0].astype(complex), matrix[1, 1].astype(complex)
    root = jnp.sqrt(b**2 / 4 + a)
    low, high = b / 2 - root, b / 2 + root
    one, zero = jnp.ones_like(low), jnp.zeros_like(low)
    host_vectors = jnp.stack([jnp.stack([one, one]), jnp.stack([low, high])])
    host_inverse = jnp.stack([jnp.stack([high, -one]), jnp.stack([-low, one])]) / (high - low)
    # (i - [[0, 1], [a, b]]) h = -i (0, f): h = (1, i) (-i f) / (-1 - a - i b)
    host_harmonic = jnp.stack([one, 1j * one]) * (-1j * forcing[1]) / (-1 - a - 1j * b)

    def embed(block, rest):
        return jnp.zeros((4, 4), complex).at[:2, :2].set(block).at[2:, 2:].set(rest)

    stuck_values = jnp.stack([low, high, zero, zero])
    stuck = _Mode(
        embed(host_vectors, jnp.eye(2)),
        embed(host_inverse, jnp.eye(2)),
        stuck_values,
        jnp.concatenate([host_harmonic, jnp.zeros(2, complex)]),
        powers(stuck_values),
    )
    return slip, stuck


def _spring_force(z, q: _Quantities):
    """The scaled force of the spring and damper on the terminal (per unit A / K)."""
    return q.k * (z[0] - z[2]) + q.c * q.omega * (z[1] - z[3])


def _start(sign, theta, z, q: _Quantities, modes) -> _Segment:
    """The segment in mode `sign` that starts at phase `theta` in state `z`."""
    slip, stuck = modes
    stiffness, k, friction = q.stiffness, q.k, q.friction
    is_stuck = sign == _STICK
    z = jnp.where(is_stuck, z.at[3].set(0.0), z)
    # constant particular solutions: static equilibrium under the friction (slipping) or
    # with the terminal held at y (stuck)
    held = k * z[2] / (stiffness + k)
    static_y = -sign * friction * (stiffness + k) / (k * stiffness)
    static_x = -sign * friction / stiffness
    constant = jnp.where(
        is_stuck,
        jnp.stack([held, 0.0 * held, z[2], 0.0 * held]),
        jnp.stack([static_x, 0.0 * static_x, static_y, 0.0 * static_x]),
    )
    mode = jax.tree.map(lambda a, b: jnp.where(is_stuck, b, a), slip, stuck)
    particular = jnp.real(mode.harmonic * jnp.exp(1j * theta)) + constant
    return _Segment(sign, theta, constant, mode.inverse @ (z - particular).astype(complex))


def _mode_of(segment: _Segment, modes) -> _Mode:
    slip, stuck = modes
    return jax.tree.map(lambda a, b: jnp.where(segment.sign == _STICK, b, a), slip, stuck)


def segment_state(segment, mode, theta):
    """The state at phase `theta` (>= the segment's start) of a closed-form segment (a
    `_Segment` and its `_Mode`, or any with their fields) and its phase derivative."""
    tau = jnp.maximum(theta - segment.start, 0.0)
    growth = segment.coefficients * jnp.exp(mode.eigenvalues * tau)
    harmonic = mode.harmonic * jnp.exp(1j * theta)
    z = jnp.real(harmonic + mode.vectors @ growth) + segment.constant
    dz = jnp.real(1j * harmonic + mode.vectors @ (mode.eigenvalues * growth))
    return z, dz


def _on_grid(segment: _Segment, mode: _Mode, grid, phasors):
    """The states at every phase of the grid (`phasors` = e^{i grid}) from the segment's
    start on (rows before it are not meaningful), with the exponentials of the grid's
    steps computed once (`_Mode.powers`)."""
    step = grid[1]
    first = jnp.clip(jnp.ceil(segment.start / step), 0, grid.shape[0] - 1)
    offset = jnp.exp(mode.eigenvalues * (first * step - segment.start))
    index = jnp.clip(jnp.arange(grid.shape[0]) - first.astype(int), 0, grid.shape[0] - 1)
    growth = segment.coefficients * offset * mode.powers[index]
    harmonic = phasors[:, None] * mode.harmonic
    return jnp.real(harmonic + growth @ mode.vectors.T) + segment.constant


def _event_value(segment: _Segment, z, q: _Quantities, force):
    """The event function at the state `z`, where the force on the terminal is `force`:
    positive while the mode holds."""
    stuck = segment.sign == _STICK
    return jnp.where(stuck, q.friction - jnp.abs(force), segment.sign * z[3])


def _event(segment: _Segment, z, dz, q: _Quantities):
    """The event function and its phase derivative (`dz` that of the state)."""
    force, dforce = _spring_force(z, q), _spring_force(dz, q)
    stuck = segment.sign == _STICK
    dg = jnp.where(stuck, -jnp.sign(force) * dforce, segment.sign * dz[3])
    return _event_value(segment, z, q, force), dg


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


def _root(segment, mode, q: _Quantities, low, high, g_low, g_high, active):
    """`bracketed_root` of the event function of `segment`."""
    return bracketed_root(lambda theta: _event(segment, *segment_state(segment, mode, theta), q),
                          low, high, g_low, g_high, active)


def differentiable_root(g_of, theta0):
    """`theta0`, a root of the event function `g_of(theta) -> (g, dg/dtheta)`, with the
    forward derivative of one Newton step from it: the implicit derivative
    -dg / (dg/dtheta) of the event time (the value stays `theta0`)."""
    theta0 = jax.lax.stop_gradient(theta0)
    g, dg = g_of(theta0)
    dg = jax.lax.stop_gradient(jnp.where(dg == 0, 1.0, dg))
    return theta0 - (g - jax.lax.stop_gradient(g)) / dg


def _transition(segment: _Segment, z, q: _Quantities):
    """The mode after an event of `segment` in state `z`: a stuck terminal slips with the
    sign of the force on it; a slipping one sticks where the force is within ff, else
    slips back."""
    slip_sign, held = _held_by_friction(z, q)
    return jnp.where(segment.sign == _STICK, slip_sign, jnp.where(held, _STICK, slip_sign))


def _held_by_friction(z, q: _Quantities):
    """For a terminal at rest in state `z`: the sign it slips with (that of the force on
    it) and whether the friction holds it (the force within ff)."""
    force = _spring_force(z, q)
    return jnp.where(force >= 0, 1, -1), jnp.abs(force) <= q.friction


def _initial_sign(z, q: _Quantities):
    slip_sign, held = _held_by_friction(z, q)
    at_rest = jnp.where(held, _STICK, slip_sign)
    return jnp.where(z[3] > 0, 1, jnp.where(z[3] < 0, -1, at_rest))


class Flow(eqx.Module):
    """What every period at one parameter vector shares: its quantities and its modes
    (their eigen-decompositions and powers over the sample grid), computed once for the
    many periods that shooting integrates at the same parameters (`flow`)."""

    quantities: _Quantities
    modes: tuple[_Mode, _Mode]


@ft.partial(jax.jit, static_argnums=1)
def flow(p: Float[Array, " 10"], samples: int) -> Flow:
    """The `Flow` at the parameter vector `p` (order `_dynamics.PARAMETERS`) for periods
    sampled at `samples` phases; differentiable with respect to `p`."""
    q = _quantities(p)
    return Flow(q, _modes(p, q, _grid(samples, p.dtype)))


def _grid(samples: int, dtype):
    return jnp.arange(samples + 1, dtype=dtype) * (2 * np.pi / samples)


# Traced once for each program that integrates periods (samples, monodromy, derivatives:
# up to five times in one), its forward derivatives and batches taken of that trace.
@ft.partial(jax.jit, static_argnums=2)
def period(z0: Float[Array, " 4"], flow: Flow, keep_samples: bool = True):
    """One forcing period of the hybrid flow (`flow`, at the parameters that made it, for
    the number of samples it was made for) from the scaled state `z0` at phase 0: the
    states at the `samples` phases `2 pi j / samples` (rows `(x, x', y, y')`), the state
    after the period, the number of stick-slip transitions (mode changes) in it, and the
    largest |y| at a transition. Every extremum of y is at a transition (where y' turns
    0) or on a stuck segment, so that the peak |y| is the largest of that and the samples.
    The state after the period is NaN where the orbit needed more than `MAX_SEGMENTS`
    segments. Without `keep_samples`, the samples (zeros) are not formed and only find
    the transitions, and derivatives reach the state after the period alone."""
    dtype = z0.dtype
    q, modes = flow.quantities, flow.modes
    samples = modes[0].powers.shape[0] - 1  # the grid's phases, 2 pi included
    grid = _grid(samples, dtype)
    phasors = jnp.exp(1j * grid)
    guard = 1e-9 * (2 * np.pi / samples)

    def body(state: _Period):
        segment = state.segment
        mode = _mode_of(segment, modes)
        on_grid = segment if keep_samples else jax.lax.stop_gradient(segment)
        zs = _on_grid(on_grid, mode, grid, phasors)
        # The event is located on the values alone (its derivative is that of one Newton
        # step from it, `differentiable_root`): no tangents enter the search.
        fixed = jax.lax.stop_gradient((segment, mode, q, zs))
        states = fixed[3].T  # rows x, x', y, y' over the grid
        g = _event_value(fixed[0], states, fixed[2], _spring_force(states, fixed[2]))
        crossing = (grid > fixed[0].start + guard) & (g < 0)
        ends = jnp.any(crossing)
        j = jnp.argmax(crossing)
        before = jnp.maximum(j - 1, 0)
        low = jnp.maximum(grid[before], fixed[0].start)
        high = jnp.where(ends, grid[j], low + 1.0)
        # The event values on the grid bracket the root; where the bracket starts at the
        # segment's start (between two samples), the event function is 0 there (the
        # terminal came to rest, or the force reached ff) or above it.
        g_low = jnp.where(grid[before] >= fixed[0].start, g[before], 0.0)
        theta = _root(*fixed[:3], low, high, jnp.maximum(g_low, 0.0), jnp.minimum(g[j], 0.0),
                      ends)
        theta = differentiable_root(
            lambda t: _event(segment, *segment_state(segment, mode, t), q), theta)
        theta = jnp.where(ends, theta, 2 * np.pi)
        own = (grid[:-1] >= segment.start) & (grid[:-1] < theta)
        samples = jnp.where(own[:, None], zs[:-1], state.samples) if keep_samples else state.samples
        z, _ = segment_state(segment, mode, theta)
        z = jnp.where(segment.sign == _STICK, z, z.at[3].set(0.0))
        following = _start(_transition(segment, z, q), theta, z, q, modes)
        transitions = state.transitions + ends
        too_many = transitions >= MAX_SEGMENTS
        return _Period(
            segment=jax.tree.map(lambda a, b: jnp.where(ends, a, b), following, segment),
            samples=samples,
            z_end=jnp.where(ends, jnp.where(too_many, jnp.nan, state.z_end),
                            segment_state(segment, mode, grid[-1])[0]),
            transitions=transitions,
            y_events=jnp.where(ends, jnp.maximum(state.y_events, jnp.abs(z[2])), state.y_events),
            done=~ends | too_many,
        )

    first = _start(_initial_sign(z0, q), jnp.zeros((), dtype), z0, q, modes)
    no_samples = jnp.zeros((samples if keep_samples else 0, 4), dtype)
    start = _Period(first, no_samples, jnp.zeros(4, dtype),
                    jnp.zeros((), int), jnp.zeros((), dtype), jnp.asarray(False))
    end = jax.lax.while_loop(lambda state: ~state.done, body, start)
    return end.samples, end.z_end, end.transitions, end.y_events
