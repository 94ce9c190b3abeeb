"""Whether an optimistix minimiser's search has come down to the noise of its objective."""

import jax.numpy as jnp


def cut_within_tolerance(solver, y, state):
    """Whether the move that `solver` tries next from `y` (to `state.y_eval`) is within
    its tolerance, measured as it measures an accepted step's (`|y_eval - y| < atol +
    rtol |y|` in `solver.norm`). After a rejected step, the search is then down to moves
    that would count as converged, and finds no decrease above the noise of the
    objective (the error of the integrations it is computed from)."""
    move = jnp.abs(state.y_eval - y) / (solver.atol + solver.rtol * jnp.abs(y))
    return solver.norm(move) < 1
