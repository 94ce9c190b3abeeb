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
    "friction_width",
    "amplitude",
    "omega",
)
N_PARAMETERS = len(PARAMETERS)
OMEGA = PARAMETERS.index("omega")
AMPLITUDE = PARAMETERS.index("amplitude")


def smooth_sign(velocity: Float[Array, "..."], width: Float[Array, "..."]) -> Float[Array, "..."]:
    """`tanh(velocity / width)`: the smoothed `sign` of the inerter's dry friction."""
    return jnp.tanh(velocity / width)


def parameters(system, amplitude, omega) -> list[Float[Array, ""]]:
    """A `TIDSystem`'s fields, the forcing amplitude (N) and frequency (rad/s) as the
    scalars of `p` (order `PARAMETERS`), in one floating dtype. Kept apart (not stacked),
    so that derivatives can see which of them depend on a differentiated input."""
    values = [jnp.asarray(getattr(system, name)) for name in PARAMETERS[:-2]]
    values += [jnp.asarray(amplitude), jnp.asarray(omega)]
    dtype = jnp.result_type(*values, float)
    return [value.astype(dtype) for value in values]


def parameter_vector(system, amplitude, omega) -> Float[Array, " 10"]:
    """Stack a `TIDSystem`'s fields, the forcing amplitude (N) and frequency (rad/s) into
    the flat vector `p` (order `PARAMETERS`)."""
    return jnp.stack(parameters(system, amplitude, omega))


def displacement_scale(p: Float[Array, " 10"]) -> Float[Array, ""]:
    """Static displacement A / K (m): the unit of the scaled state."""
    return p[AMPLITUDE] / p[1]


def vector_field(theta: Float[Array, ""], z: Float[Array, " 4"], p: Float[Array, " 10"]):
    """Eq. (12) in scaled form. Time is the forcing phase `theta = omega t` (one period is
    2 pi), displacements are in units of A / K and velocities in units of omega A / K, so
    `z = (x, x', y, y')` is O(1) for every frequency and amplitude."""
    mass, stiffness, damping, inertance, friction, k, c, width, amplitude, omega = p
    scale = amplitude / stiffness
    x, v, y, w = z
    spring = k * (x - y) + c * omega * (v - w)  # N per (A/K), acting on the inerter terminal
    friction_term = friction * smooth_sign(omega * scale * w, width) / scale
    host_force = amplitude / scale * jnp.sin(theta) - damping * omega * v - stiffness * x - spring
    dv = host_force / (mass * omega**2)
    dw = (spring - friction_term) / (inertance * omega**2)
    return jnp.stack([v, dv, w, dw])
