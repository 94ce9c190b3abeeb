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


# Eq. (12) in scaled form. Time is the forcing phase `theta = omega t` (one period is
# 2 pi), displacements are in units of A / K and velocities in units of omega A / K, so
# `z = (x, x', y, y')` is O(1) for every frequency and amplitude. The field is split into
# its linear part, the forcing and the friction, so that the variational equations reuse
# the linear part.
#
# A compliant device (a finite `series_stiffness` ks) adds its mechanism's displacement q
# and velocity: `z = (x, x', y, y', q, q')`. The terminal y (mass mt > 0) is joined to the
# mechanism by the series spring with its free play (a dead zone of half the backlash);
# the mechanism (inertance b, parasitic damping cp) carries the friction:
#     mt y'' = c (x' - y') + k (x - y) - ks D(y - q)
#     b q''  = ks D(y - q) - cp q' - ff sgn(q')


def linear_part(z: Float[Array, "n ..."], p: Float[Array, " 14"]) -> tuple[Array, ...]:
    """The rows of the linear part `L z` of the scaled vector field of the rigid device,
    for a state `z` or for columns of states (`z[i]` arrays of one shape), written out
    elementwise."""
    _, _, _, inertance, _, _, _, parasitic, terminal, *_, omega = p
    x, v, y, w = z[:4]
    spring, host = _host_rows(x, v, y, w, p)
    return v, host, w, (spring - parasitic * omega * w) / ((inertance + terminal) * omega**2)


def _host_rows(x, v, y, w, p):
    """The force of the TID's spring and damper on the inerter terminal (per unit A/K)
    and the host's scaled acceleration, forcing apart."""
    mass, stiffness, damping, _, _, k, c, *_, omega = p
    spring = k * (x - y) + c * omega * (v - w)
    return spring, -(stiffness * x + damping * omega * v + spring) / (mass * omega**2)


def friction_acceleration(w: Float[Array, ""], p: Float[Array, " 14"],
                          compliant: bool = False) -> Float[Array, ""]:
    """The friction's contribution to the scaled acceleration of the body it acts on (the
    rigid device's terminal, with its terminal mass, or a `compliant` device's
    mechanism) at its scaled velocity `w`."""
    _, stiffness, _, inertance, friction, _, _, _, terminal, _, _, width, amplitude, omega = p
    scale = amplitude / stiffness
    mass = inertance if compliant else inertance + terminal
    return -friction * smooth_sign(omega * scale * w, width) / (scale * mass * omega**2)


def _compliant_field(z, p):
    """The scaled field of the compliant device's six states, forcing and friction
    apart."""
    _, stiffness, _, inertance, _, _, _, parasitic, terminal, ks, gap, *_ = p
    omega, scale = p[-1], p[-2] / stiffness
    x, v, y, w, q, u = z
    spring, host = _host_rows(x, v, y, w, p)
    series = ks * dead_zone(y - q, gap / scale)
    return jnp.stack([v, host, w, (spring - series) / (terminal * omega**2), u,
                      (series - parasitic * omega * u) / (inertance * omega**2)])


def dead_zone(d, gap):
    """The stretch of a spring with total free play `gap` at relative displacement `d`:
    `sgn(d) max(|d| - gap / 2, 0)`."""
    return jnp.sign(d) * jnp.maximum(jnp.abs(d) - 0.5 * gap, 0.0)


def vector_field(theta: Float[Array, ""], z: Float[Array, " n"], p: Float[Array, " 14"]):
    """Eq. (12) in scaled form (see above), of four states (rigid device) or six
    (compliant device)."""
    mass, stiffness, omega = p[0], p[1], p[-1]
    force = stiffness * jnp.sin(theta) / (mass * omega**2)  # A sin(theta) in units of A/K
    if z.shape[0] == 6:
        field = _compliant_field(z, p)
        return field.at[1].add(force).at[5].add(friction_acceleration(z[5], p, compliant=True))
    dx, dv, dy, dw = linear_part(z, p)
    return jnp.stack([dx, dv + force, dy, dw + friction_acceleration(z[3], p)])


def tangent_field(theta: Float[Array, ""], z: Float[Array, " n"], tangents, p):
    """d/dtheta of `tangents` (n x m, columns d z / d something) along the orbit through
    `z`: the linear part plus the friction's slope in `z[3]` (rigid device), or the
    field's forward derivatives (compliant device)."""
    if z.shape[0] == 6:
        return jax.vmap(lambda t: jax.jvp(lambda s: vector_field(theta, s, p), (z,), (t,))[1],
                        in_axes=1, out_axes=1)(tangents)
    slope = jax.grad(friction_acceleration)(z[3], p)
    dx, dv, dy, dw = linear_part(tangents, p)
    return jnp.stack([dx, dv, dy, dw + slope * tangents[3]])
