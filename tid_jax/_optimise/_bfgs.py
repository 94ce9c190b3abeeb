"""The BFGS method of retune's optimiser: optimistix's, with its Newton step capped and a
line search that interpolates and extrapolates."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float


class CappedNewtonDescent(optx.NewtonDescent):
    """Newton direction with its two-norm capped at `max_step` before the line search
    scales it, and the scaled step capped again: where the objective is nearly linear
    along some direction, BFGS's curvature estimate there is near zero and the plain
    Newton step would throw the design far off, where the steady states are expensive
    and the objective meaningless."""

    max_step: float = 1.0

    def query(self, y, f_info, state):
        state = super().query(y, f_info, state)
        return eqx.tree_at(lambda s: s.newton, state, _capped(state.newton, self.max_step))

    def step(self, step_size, state):
        step, result = super().step(step_size, state)
        return _capped(step, self.max_step), result


def _capped(step, max_step):
    """`step` scaled down to two-norm `max_step` if longer."""
    length = optx.two_norm(step)
    factor = jnp.minimum(1.0, max_step / jnp.maximum(length, jnp.finfo(length.dtype).tiny))
    return jax.tree.map(lambda leaf: factor * leaf, step)


class _SearchState(eqx.Module):
    step_size: Float[Array, ""]


class InterpolatingArmijo(optx.AbstractSearch):
    """Backtracking Armijo line search (as `optx.BacktrackingArmijo`) that shortens a
    rejected step to the minimum of the parabola through the objective's values and slope
    along it, and lengthens steps where the objective shows no curvature.

    A step is accepted when the objective falls by at least `slope` times the decrease its
    gradient predicts. A rejected step t is cut to the parabola's minimum, kept within
    [`shortest`, 1/2] times t (halved where the objective is not finite). The first step
    from the starting point is `first_step` times the (quasi-)Newton step: a continuation
    stage that sharpens the smooth maximum starts from the last stage's curvature, too
    weak across the ridge of equal peaks by about the ratio of the sharpnesses. After an
    accepted step the next one starts at the full step; where the accepted step fell at
    least as far as its gradient predicted (the objective is linear or concave along it,
    and BFGS learnt no curvature from it), at twice its size, its length at most
    `max_step`: where the objective curves down towards a distant optimum, the design
    reaches it in a few steps instead of many equal ones."""

    max_step: float
    first_step: Float[ArrayLike, ""] = 1.0
    slope: float = 0.1
    shortest: float = 0.05

    def init(self, y, f_info_struct):
        return _SearchState(step_size=jnp.asarray(1.0, f_info_struct.f.dtype))

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        t = state.step_size
        y_diff = jax.tree.map(lambda new, old: new - old, y_eval, y)
        predicted = f_info.compute_grad_dot(y_diff)
        actual = f_eval_info.as_min() - f_info.as_min()
        accept = first_step | ((actual <= self.slope * predicted) & (predicted <= 0))
        # Rejected: the minimum of the parabola through f(0), its slope and f(t), in units
        # of the step tried.
        excess = actual - predicted  # the parabola's curvature term, > 0 where rejected
        fraction = -predicted / (2 * jnp.where(excess > 0, excess, 1.0))
        fraction = jnp.where(jnp.isfinite(actual) & (excess > 0),
                             jnp.clip(fraction, self.shortest, 0.5), 0.5)
        # Accepted with no curvature seen: twice the step, no longer than `max_step`.
        length = optx.two_norm(y_diff)
        room = self.max_step / jnp.maximum(length, jnp.finfo(length.dtype).tiny)
        linear = ~first_step & (predicted < 0) & (actual <= predicted)
        longer = jnp.maximum(1.0, t * jnp.minimum(2.0, room))
        step_size = jnp.where(first_step, self.first_step,
                              jnp.where(accept, jnp.where(linear, longer, 1.0), fraction * t))
        return step_size.astype(t.dtype), accept, optx.RESULTS.successful, _SearchState(step_size)


class CappedBFGS(optx.AbstractBFGS):
    """`optx.BFGS` (inverse-Hessian updates) with the Newton step capped
    (`CappedNewtonDescent`) and a line search that interpolates and extrapolates
    (`InterpolatingArmijo`)."""

    rtol: float
    atol: float
    descent: optx.AbstractDescent
    search: optx.AbstractSearch
    norm: Callable = optx.max_norm
    use_inverse: bool = True
    verbose: Callable[..., None] = optx.BFGS(rtol=1.0, atol=1.0).verbose
