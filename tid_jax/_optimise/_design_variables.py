"""The design variables of a tuning (k, c): the coordinates that retune's optimiser, the
sensitivities and the robust design move in."""

import jax.numpy as jnp

# Scales of retune's design variables: they make the curvature of the log peak about one
# in each, so that BFGS's first steps (from an identity Hessian) are about the right
# length. (The robust design's trust-region steps are measured in unscaled ones.)
DESIGN_SCALE = (10.0, 3.0)


def tuning_of_design(u, k_ref, c_ref, scale=DESIGN_SCALE, xp=jnp):
    """The tuning (k, c) of the design variables u = (scale[0] ln(k / k_ref), scale[1]
    sqrt(c / c_ref)): k > 0 through an exponential, c >= 0 through a square, so that the
    bound c = 0 is a stationary point of the unconstrained problem and can be reached
    exactly. `xp`: the array module (`jax.numpy`, or `numpy` on the host)."""
    return k_ref * xp.exp(u[0] / scale[0]), c_ref * (u[1] / scale[1]) ** 2


def design_of_tuning(k, c, k_ref, c_ref, scale=DESIGN_SCALE, xp=jnp):
    """The design variables of the tuning (k, c), the inverse of `tuning_of_design`."""
    return xp.stack([scale[0] * xp.log(k / k_ref), scale[1] * xp.sqrt(c / c_ref)], axis=-1)

