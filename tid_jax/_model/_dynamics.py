"""The dry friction's smoothed sign and the backlash's dead zone."""

import jax.numpy as jnp
from jaxtyping import Array, Float


def smooth_sign(velocity: Float[Array, "..."], width: Float[Array, "..."]) -> Float[Array, "..."]:
    """`tanh(velocity / width)`: the smoothed `sign` of the inerter's dry friction."""
    return jnp.tanh(velocity / width)


def dead_zone(d, gap):
    """The stretch of a spring with total free play `gap` at relative displacement `d`:
    `sgn(d) max(|d| - gap / 2, 0)`."""
    return jnp.sign(d) * jnp.maximum(jnp.abs(d) - 0.5 * gap, 0.0)
