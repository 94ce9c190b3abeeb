"""The paper's system as the flat parameter vector `p` (order `PARAMETERS`) that the
shooting solver and its derivatives work with; the dry friction's smoothed sign and the
backlash's dead zone. Its scaled model is `_orbit._flow.parameter_plant`."""

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
    "series_stiffness",
    "backlash",
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


def parameter_vector(system, amplitude, omega) -> Float[Array, " 14"]:
    """Stack a `TIDSystem`'s fields, the forcing amplitude (N) and frequency (rad/s) into
    the flat vector `p` (order `PARAMETERS`)."""
    return jnp.stack(parameters(system, amplitude, omega))


def dead_zone(d, gap):
    """The stretch of a spring with total free play `gap` at relative displacement `d`:
    `sgn(d) max(|d| - gap / 2, 0)`."""
    return jnp.sign(d) * jnp.maximum(jnp.abs(d) - 0.5 * gap, 0.0)
