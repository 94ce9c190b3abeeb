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

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Complex, Float, Int

from ._dynamics import linear_part
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


def _quantities(p):
    mass, stiffness, damping, inertance, friction, k, c, *_, amplitude, omega = p
    scale = amplitude / stiffness
    return mass, stiffness, damping, inertance, k, c, omega, friction / scale


def _slip_matrix(p):
    """The matrix of the scaled field's linear part (`_dynamics.linear_part`), column j
    the field of the unit state j."""
    return jnp.stack(linear_part(jnp.eye(4, dtype=p.dtype), p))


def _forcing(p):
    mass, stiffness, _, _, _, _, omega, _ = _quantities(p)
    zero = jnp.zeros_like(mass)
    return jnp.stack([zero, stiffness / (mass * omega**2), zero, zero])


def _modes(p, grid) -> tuple[_Mode, _Mode]:
    """The slipping mode (both signs share it) and the stuck mode, whose homogeneous part
    moves only the host (the terminal's rows are zero), with their powers over the
    uniform phase `grid` (from 0)."""
    powers = lambda eigenvalues: jnp.exp(eigenvalues[None, :] * grid[:, None])
    matrix = _slip_matrix(p)
    forcing = _forcing(p).astype(complex)
    eye = jnp.eye(4, dtype=complex)
    # The motion depends on the eigenvectors only through `vectors diag(.) vectors^-1`,
    # whatever their normalisation, and the modes' eigenvalues are distinct (a damped
    # oscillator's complex pair, or two real ones off critical damping).
    eigenvalues, vectors = eigensystem(matrix)
    slip = _Mode(vectors, jnp.linalg.inv(vectors), eigenvalues,
                 jnp.linalg.solve(1j * eye - matrix, -1j * forcing), powers(eigenvalues))
    host = matrix[:2, :2]
    host_values, host_vectors = eigensystem(host)

    def embed(block, rest):
        return jnp.zeros((4, 4), complex).at[:2, :2].set(block).at[2:, 2:].set(rest)

    host_harmonic = jnp.linalg.solve(1j * eye[:2, :2] - host, -1j * forcing[:2])
    stuck_values = jnp.concatenate([host_values, jnp.zeros(2, complex)])
    stuck = _Mode(
        embed(host_vectors, jnp.eye(2)),
        embed(jnp.linalg.inv(host_vectors), jnp.eye(2)),
        stuck_values,
        jnp.concatenate([host_harmonic, jnp.zeros(2, complex)]),
        powers(stuck_values),
    )
    return slip, stuck


def _spring_force(z, p):
    """The scaled force of the spring and damper on the terminal (per unit A / K)."""
    _, _, _, _, k, c, omega, _ = _quantities(p)
    return k * (z[0] - z[2]) + c * omega * (z[1] - z[3])


def _start(sign, theta, z, p, modes) -> _Segment:
    """The segment in mode `sign` that starts at phase `theta` in state `z`."""
    slip, stuck = modes
    _, stiffness, _, _, k, _, _, friction = _quantities(p)
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


def _state(segment: _Segment, mode: _Mode, theta):
    """The state at phase `theta` (>= the segment's start) and its phase derivative."""
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


def _event_value(segment: _Segment, z, p):
    """The event function at the state `z`: positive while the mode holds."""
    friction = _quantities(p)[-1]
    stuck = segment.sign == _STICK
    return jnp.where(stuck, friction - jnp.abs(_spring_force(z, p)), segment.sign * z[3])


def _event(segment: _Segment, z, dz, p):
    """The event function and its phase derivative (`dz` that of the state)."""
    force, dforce = _spring_force(z, p), _spring_force(dz, p)
    stuck = segment.sign == _STICK
    dg = jnp.where(stuck, -jnp.sign(force) * dforce, segment.sign * dz[3])
    return _event_value(segment, z, p), dg


def _root(segment, mode, p, low, high, active):
    """The phase in `[low, high]` where the event function changes sign (positive at
    `low`, negative at `high`), by Newton steps kept inside the shrinking bracket; no
    iterations where not `active`."""
    g_of = lambda theta: _event(segment, *_state(segment, mode, theta), p)
    g_low, g_high = g_of(low)[0], g_of(high)[0]
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


def _differentiable_root(segment, mode, p, theta0):
    """`theta0`, a root of the event function, with the forward derivative of one Newton
    step from it: the implicit derivative -dg / (dg/dtheta) of the event time (the value
    stays `theta0`)."""
    theta0 = jax.lax.stop_gradient(theta0)
    g, dg = _event(segment, *_state(segment, mode, theta0), p)
    dg = jax.lax.stop_gradient(jnp.where(dg == 0, 1.0, dg))
    return theta0 - (g - jax.lax.stop_gradient(g)) / dg


def _transition(segment: _Segment, z, p):
    """The mode after an event of `segment` in state `z`: a stuck terminal slips with the
    sign of the force on it; a slipping one sticks where the force is within ff, else
    slips back."""
    slip_sign, held = _held_by_friction(z, p)
    return jnp.where(segment.sign == _STICK, slip_sign, jnp.where(held, _STICK, slip_sign))


def _held_by_friction(z, p):
    """For a terminal at rest in state `z`: the sign it slips with (that of the force on
    it) and whether the friction holds it (the force within ff)."""
    force = _spring_force(z, p)
    return jnp.where(force >= 0, 1, -1), jnp.abs(force) <= _quantities(p)[-1]


def _initial_sign(z, p):
    slip_sign, held = _held_by_friction(z, p)
    at_rest = jnp.where(held, _STICK, slip_sign)
    return jnp.where(z[3] > 0, 1, jnp.where(z[3] < 0, -1, at_rest))


# Traced once for each program that integrates periods (samples, monodromy, derivatives:
# up to five times in one), its forward derivatives and batches taken of that trace.
@ft.partial(jax.jit, static_argnums=(2, 3))
def period(z0: Float[Array, " 4"], p: Float[Array, " 10"], samples: int,
           keep_samples: bool = True):
    """One forcing period of the hybrid flow from the scaled state `z0` at phase 0: the
    states at the `samples` phases `2 pi j / samples` (rows `(x, x', y, y')`), the state
    after the period, the number of stick-slip transitions (mode changes) in it, and the
    largest |y| at a transition. Every extremum of y is at a transition (where y' turns
    0) or on a stuck segment, so that the peak |y| is the largest of that and the samples.
    The state after the period is NaN where the orbit needed more than `MAX_SEGMENTS`
    segments. Without `keep_samples`, the samples (zeros) are not formed and only find
    the transitions, and derivatives reach the state after the period alone."""
    dtype = z0.dtype
    grid = jnp.arange(samples + 1, dtype=dtype) * (2 * np.pi / samples)
    modes = _modes(p, grid)
    phasors = jnp.exp(1j * grid)
    guard = 1e-9 * (2 * np.pi / samples)

    def body(state: _Period):
        segment = state.segment
        mode = _mode_of(segment, modes)
        on_grid = segment if keep_samples else jax.lax.stop_gradient(segment)
        zs = _on_grid(on_grid, mode, grid, phasors)
        # The event is located on the values alone (its derivative is that of one Newton
        # step from it, `_differentiable_root`): no tangents enter the search.
        fixed = jax.lax.stop_gradient((segment, mode, p, zs))
        g = jax.vmap(lambda z: _event_value(fixed[0], z, fixed[2]))(fixed[3])
        crossing = (grid > fixed[0].start + guard) & (g < 0)
        ends = jnp.any(crossing)
        j = jnp.argmax(crossing)
        low = jnp.maximum(grid[jnp.maximum(j - 1, 0)], fixed[0].start)
        high = jnp.where(ends, grid[j], low + 1.0)
        theta = _root(*fixed[:3], low, high, ends)
        theta = _differentiable_root(segment, mode, p, theta)
        theta = jnp.where(ends, theta, 2 * np.pi)
        own = (grid[:-1] >= segment.start) & (grid[:-1] < theta)
        samples = jnp.where(own[:, None], zs[:-1], state.samples) if keep_samples else state.samples
        z, _ = _state(segment, mode, theta)
        z = jnp.where(segment.sign == _STICK, z, z.at[3].set(0.0))
        following = _start(_transition(segment, z, p), theta, z, p, modes)
        transitions = state.transitions + ends
        too_many = transitions >= MAX_SEGMENTS
        return _Period(
            segment=jax.tree.map(lambda a, b: jnp.where(ends, a, b), following, segment),
            samples=samples,
            z_end=jnp.where(ends, jnp.where(too_many, jnp.nan, state.z_end),
                            _state(segment, mode, grid[-1])[0]),
            transitions=transitions,
            y_events=jnp.where(ends, jnp.maximum(state.y_events, jnp.abs(z[2])), state.y_events),
            done=~ends | too_many,
        )

    first = _start(_initial_sign(z0, p), jnp.zeros((), dtype), z0, p, modes)
    no_samples = jnp.zeros((samples if keep_samples else 0, 4), dtype)
    start = _Period(first, no_samples, jnp.zeros(4, dtype),
                    jnp.zeros((), int), jnp.zeros((), dtype), jnp.asarray(False))
    end = jax.lax.while_loop(lambda state: ~state.done, body, start)
    return end.samples, end.z_end, end.transitions, end.y_events
