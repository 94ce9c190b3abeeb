"""The automatic choice between the explicit and the implicit integrator of smoothed
friction (`SolverSettings.implicit=None`), from a cheap estimate of the explicit steps a
period needs for stability.

The estimate at a point: the largest eigenvalue magnitude `rho` of the scaled field's
Jacobian (phase units: one period is 2 pi) at the linear equivalent steady state's
start (`_period.point_model`), with the friction's
body at rest where that state holds it stuck (where tanh(v / width) is steepest: the
friction's slope ff / (width * inertance) in scaled units joins the linear part's
eigenvalues), and slipping fast (the slope nil) elsewhere. A slipping body crosses the
narrow band |v| < width in a time proportional to the width, so its explicit steps per
period do not grow as the width shrinks (measured, 10-storey building at 0.5 m/s2:
Tsit5 203 steps per period at a width of 2e-3 m/s, 224 at 5e-6 m/s); a stuck one stays
in it, and Tsit5's steps follow its stability boundary, about `2 pi rho / 2.8` per
period (fitted: 132 .. 19303 steps for widths 2e-3 .. 5e-6 m/s at 0.01 m/s2, where the
estimate gives 137 .. 19000).
"""


import jax
import jax.numpy as jnp
import numpy as np

from .._model._building import Quantity
from ._period import point_model, smoothed_field
from ._settings import SolverSettings

# Tsit5's stability boundary along the negative real axis, in steps: fitted, see above.
_STABILITY = 2.8
# Explicit steps per period above which the implicit Kvaerno5 is cheaper: a Kvaerno5 step
# costs 10-15 Tsit5 steps (Newton iterations and linear solves), and it takes 80-570 steps
# per period on these orbits at rtol 1e-8, accuracy bound; measured on the stuck
# 10-storey building, Tsit5 is 3x cheaper at 494 steps per period and 4x dearer at 1939.
STIFF_STEPS = 1000.0
_FAST = 1e6  # a slipping body's velocity, in friction widths (tanh's slope nil)


def explicit_steps(field, z, args, width, stuck):
    """Estimated explicit steps per period of `field(theta, z, args)` at the state `z`
    (the friction's body's velocity last, `width` its friction width), that body at rest
    where `stuck`, else slipping fast."""
    velocity = jnp.where(stuck, 0.0, _FAST * width)
    jacobian = jax.jacfwd(lambda s: field(jnp.zeros((), z.dtype), s, args))(z.at[-1].set(velocity))
    return 2 * jnp.pi * jnp.max(jnp.abs(jnp.linalg.eigvals(jacobian))) / _STABILITY


@jax.jit
def _steps(systems, omegas, amplitudes):
    def one(system, omega, amplitude):
        plant, z, _, _ = point_model(system, Quantity(), amplitude, omega)
        return explicit_steps(smoothed_field, z, plant, plant.width, z[-1] == 0.0)

    return jax.vmap(one)(systems, omegas, amplitudes)


def choose(settings: SolverSettings, steps) -> SolverSettings:
    """`settings` with `implicit` decided from the explicit steps per period `steps` of
    the points of one call (where it is None)."""
    # one program integrates the batch: implicit where most of its points are stiff (the
    # others reach the implicit fallback, `SolverSettings.fallbacks`, if they fail)
    return settings.with_implicit(bool(np.median(np.asarray(steps)) > STIFF_STEPS))


def for_points(settings: SolverSettings, systems, omegas, amplitudes) -> SolverSettings:
    """`settings` with `implicit` decided where it is None (automatic): for the `systems`
    (one `TIDSystem` or `BuildingTID` per point, fields batched) at the points
    (`omegas[i]`, `amplitudes[i]`), the implicit integrator where the explicit one needs more than
    `STIFF_STEPS` steps per period at most of them. Exact friction: unchanged."""
    fitted = settings.for_system(systems)
    if settings.implicit is not None or fitted.exact_friction:
        return settings
    return choose(settings, _steps(systems, jnp.asarray(omegas), jnp.asarray(amplitudes)))
