import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

# Index of each physical parameter in the flat parameter vector `p` that the dynamics,
# the shooting solver and its derivatives work with.
PARAMETERS = (
    "host_mass",
    "host_stiffness",
    "host_damping",
    "inertance",
    "friction_force",
    "tid_stiffness",
    "tid_damping",
    "parasitic_damping",
    "terminal_mass",
    "friction_width",
    "amplitude",
    "omega",
)


def smooth_sign(velocity: Float[Array, "..."], width: Float[Array, "..."]) -> Float[Array, "..."]:
    """`tanh(velocity / width)`: the smoothed `sign` of the inerter's dry friction."""
    return jnp.tanh(velocity / width)


def parameters(system, amplitude, omega) -> list[Float[Array, ""]]:
    """A `TIDSystem`'s fields, the forcing amplitude (N) and frequency (rad/s) as the
    scalars of `p` (order `PARAMETERS`), in one floating dtype; the friction width is the
    system's explicit one or, by default, its rule at this amplitude and frequency
    (`TIDSystem.width_at`). Kept apart (not stacked), so that derivatives can see which of
    them depend on a differentiated input."""
    values = [jnp.asarray(getattr(system, name)) for name in PARAMETERS[:-3]]
    values += [jnp.asarray(system.width_at(amplitude, omega)), jnp.asarray(amplitude),
               jnp.asarray(omega)]
    dtype = jnp.result_type(*values, float)
    return [value.astype(dtype) for value in values]


def parameter_vector(system, amplitude, omega) -> Float[Array, " 12"]:
    """Stack a `TIDSystem`'s fields, the forcing amplitude (N) and frequency (rad/s) into
    the flat vector `p` (order `PARAMETERS`)."""
    return jnp.stack(parameters(system, amplitude, omega))


# Eq. (12) in scaled form. Time is the forcing phase `theta = omega t` (one period is
# 2 pi), displacements are in units of A / K and velocities in units of omega A / K, so
# `z = (x, x', y, y')` is O(1) for every frequency and amplitude. The field is split into
# its linear part, the forcing and the friction, so that the variational equations reuse
# the linear part.


def linear_part(z: Float[Array, "4 ..."], p: Float[Array, " 12"]) -> tuple[Array, ...]:
    """The rows of the linear part `L z` of the scaled vector field, for a state `z` or
    for columns of states (`z[i]` arrays of one shape), written out elementwise."""
    mass, stiffness, damping, inertance, _, k, c, parasitic, terminal, _, _, omega = p
    x, v, y, w = z
    spring = k * (x - y) + c * omega * (v - w)  # on the inerter terminal, per unit A/K
    host = -(stiffness * x + damping * omega * v + spring) / (mass * omega**2)
    return v, host, w, (spring - parasitic * omega * w) / ((inertance + terminal) * omega**2)


def friction_acceleration(w: Float[Array, ""], p: Float[Array, " 12"]) -> Float[Array, ""]:
    """The friction's contribution to the scaled acceleration of the inerter terminal
    at the scaled terminal velocity `w`."""
    _, stiffness, _, inertance, friction, _, _, _, terminal, width, amplitude, omega = p
    scale = amplitude / stiffness
    return -friction * smooth_sign(omega * scale * w, width) / (
        scale * (inertance + terminal) * omega**2)


def vector_field(theta: Float[Array, ""], z: Float[Array, " 4"], p: Float[Array, " 12"]):
    """Eq. (12) in scaled form (see above)."""
    mass, stiffness, omega = p[0], p[1], p[-1]
    force = stiffness * jnp.sin(theta) / (mass * omega**2)  # A sin(theta) in units of A/K
    dx, dv, dy, dw = linear_part(z, p)
    return jnp.stack([dx, dv + force, dy, dw + friction_acceleration(z[3], p)])


def tangent_field(theta: Float[Array, ""], z: Float[Array, " 4"], tangents, p):
    """d/dtheta of `tangents` (4 x n, columns d z / d something) along the orbit through
    `z`: the linear part plus the friction's slope in `z[3]`."""
    del theta
    slope = jax.grad(friction_acceleration)(z[3], p)
    dx, dv, dy, dw = linear_part(tangents, p)
    return jnp.stack([dx, dv, dy, dw + slope * tangents[3]])
