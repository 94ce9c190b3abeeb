"""The period map Phi_T: the state one forcing period on from a state at phase 0, with the
samples of the response over that period, its Jacobians (the monodromy matrix, by the
variational equations or forward derivatives) and the transient before shooting; diffrax
for smoothed friction, the closed-form stick-slip flow of `_coulomb` for exact friction."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from . import _coulomb
from ._dynamics import tangent_field, vector_field
from ._settings import SolverSettings


def _solver(settings: SolverSettings):
    return dfx.Kvaerno5() if settings.implicit else dfx.Tsit5()


def integrate(field, y0, p, t1, settings: SolverSettings, saveat, max_steps):
    """Integrate `field(theta, y, p)` from phase 0 to `t1` from `y0`, a state `z` or a
    pair `(z, tangents)`; the step size follows the error of `z` alone."""
    state_norm = lambda error: optx.rms_norm(error[0] if isinstance(error, tuple) else error)
    return dfx.diffeqsolve(
        dfx.ODETerm(field),
        _solver(settings),
        t0=0.0,
        t1=t1,
        dt0=None,
        y0=y0,
        args=p,
        saveat=saveat,
        stepsize_controller=dfx.PIDController(
            rtol=settings.rtol, atol=settings.atol, norm=state_norm
        ),
        adjoint=dfx.ForwardMode(),
        max_steps=max_steps,
        throw=False,
    )


def _phases(settings: SolverSettings, dtype):
    return np.arange(settings.samples, dtype=dtype) * (2 * np.pi / settings.samples)


def period_samples(z0, p, settings: SolverSettings):
    """x, y and the velocity of the friction's body (y' of a rigid device, q' of a
    compliant one) sampled over one period from `z0`, the state after the period, the
    largest |y| at a stick-slip transition and the number of transitions (exact friction;
    else 0)."""
    if settings.exact_friction:
        states, z_end, transitions, y_events = _coulomb.period(z0, p, settings.samples)
        return (states[:, 0], states[:, 2], states[:, 3], z_end, y_events,
                transitions.astype(z0.dtype))
    phases = _phases(settings, z0.dtype)
    sol = integrate(
        vector_field, z0, p, 2 * jnp.pi, settings, dfx.SaveAt(ts=phases, t1=True),
        settings.max_steps,
    )
    ys = sol.ys
    zero = jnp.zeros((), z0.dtype)
    return ys[:-1, 0], ys[:-1, 2], ys[:-1, -1], ys[-1], zero, zero


def _field_and_tangents(theta, y, p):
    """The vector field with its variational equations: `y = (z, tangents)`, where the
    tangents (n x n) are d z / d z0."""
    z, tangents = y
    return vector_field(theta, z, p), tangent_field(theta, z, tangents, p)


def period_tangents(z, p, settings: SolverSettings):
    """The state after one period from `z` and its Jacobian with respect to `z` (the
    monodromy matrix), by the variational equations (their step sizes follow the error of
    the state alone: accurate enough for Newton's iterations, whose answer does not depend
    on them). With exact friction, the forward derivatives of the hybrid period map."""
    if settings.exact_friction:
        end = lambda z0: _coulomb.period(z0, p, settings.samples, keep_samples=False)[1]
        return jax.vmap(lambda t: jax.jvp(end, (z,), (t,)), out_axes=(None, 1))(
            jnp.eye(4, dtype=z.dtype))
    sol = integrate(
        _field_and_tangents, (z, jnp.eye(z.shape[0], dtype=z.dtype)), p, 2 * jnp.pi, settings,
        dfx.SaveAt(t1=True), settings.max_steps,
    )
    z_end, monodromy = (y[-1] for y in sol.ys)
    return z_end, monodromy


def samples_and_jacobian(z, p, settings, directions=()):
    """One integration of a period from `z` with tangents along the state directions
    and the parameters `p[i]`, `i` in `directions`, differentiating the integration itself
    (so that the derivatives are those of the computed samples, to rounding): `(xs, ys,
    ws, z_end)`, their Jacobians with respect to `z` (that of `z_end` is the monodromy
    matrix) and with respect to those parameters (last axis of size `len(directions)`)."""
    index = jnp.asarray(directions, dtype=int)
    fn = lambda z0, q: period_samples(z0, p.at[index].set(q), settings)
    n = z.shape[0]
    basis = jnp.eye(n + len(directions), dtype=z.dtype)
    primal, tangents = jax.vmap(
        lambda t: jax.jvp(fn, (z, p[index]), (t[:n], t[n:])), out_axes=(None, 0)
    )(basis)
    tangents = tuple(jnp.moveaxis(t, 0, -1) for t in tangents)
    return primal, tuple(t[..., :n] for t in tangents), tuple(t[..., n:] for t in tangents)


def linear_initial_state(p, compliant: bool = False) -> Float[Array, " n"]:
    """Scaled state at phase 0 of the steady linear response: of the free (frictionless)
    TID, or of the stuck one when the friction force exceeds the force needed to hold the
    friction's body (the rigid device's terminal, a compliant device's mechanism) still.
    Four states, or six for a `compliant` device."""
    if compliant:
        return _compliant_initial_state(p)
    (mass, stiffness, damping, inertance, friction, k, c, parasitic, terminal_mass, *_,
     amplitude, omega) = p
    jw = 1j * omega
    spring = k + jw * c
    terminal = spring / (spring + jw * parasitic - (inertance + terminal_mass) * omega**2)
    free_x = stiffness / (stiffness - mass * omega**2 + jw * damping + spring * (1 - terminal))
    stuck_x = stiffness / (stiffness + k - mass * omega**2 + jw * (damping + c))
    holding_force = jnp.abs(spring * stuck_x) * amplitude / stiffness
    stuck = holding_force < friction
    x_hat = jnp.where(stuck, stuck_x, free_x)
    y_hat = jnp.where(stuck, 0.0, free_x * terminal)
    # Forcing Im(A e^{i theta}); response Im(X e^{i theta}); velocity in units of omega A/K.
    return jnp.stack([x_hat.imag, x_hat.real, y_hat.imag, y_hat.real])


def _compliant_initial_state(p):
    """`linear_initial_state` of a compliant device (backlash left out): the terminal's
    dynamic stiffness to ground is that of the series spring and the mechanism in series,
    or of the spring alone with the mechanism stuck."""
    (mass, stiffness, damping, inertance, friction, k, c, parasitic, terminal_mass, ks, _,
     _, amplitude, omega) = p
    jw = 1j * omega
    spring = k + jw * c
    mechanism = jw * parasitic - inertance * omega**2

    def host_and_terminal(device):
        terminal = spring / (spring + device - terminal_mass * omega**2)  # Y / X
        x = stiffness / (stiffness - mass * omega**2 + jw * damping + spring * (1 - terminal))
        return x, x * terminal

    free_x, free_y = host_and_terminal(ks * mechanism / (ks + mechanism))
    stuck_x, stuck_y = host_and_terminal(ks)
    stuck = jnp.abs(ks * stuck_y) * amplitude / stiffness < friction
    x_hat = jnp.where(stuck, stuck_x, free_x)
    y_hat = jnp.where(stuck, stuck_y, free_y)
    q_hat = jnp.where(stuck, 0.0, free_y * ks / (ks + mechanism))
    return jnp.stack([x_hat.imag, x_hat.real, y_hat.imag, y_hat.real, q_hat.imag, q_hat.real])


def transient(z, p, settings: SolverSettings, periods=None):
    """Integrate `periods` (default `settings.transient_periods`, at most that; may be
    traced) periods from `z` (keeps `z` if that fails)."""
    if settings.transient_periods == 0:
        return z
    if settings.exact_friction:
        count = settings.transient_periods if periods is None else periods
        end = jax.lax.fori_loop(
            0, count, lambda _, z: _coulomb.period(z, p, settings.samples, False)[1], z
        )
        return jnp.where(jnp.all(jnp.isfinite(end)), end, z)
    sol = integrate(
        vector_field,
        z,
        p,
        2 * jnp.pi * (settings.transient_periods if periods is None else periods),
        settings,
        dfx.SaveAt(t1=True),
        settings.max_steps * settings.transient_periods,
    )
    return jnp.where(jnp.all(jnp.isfinite(sol.ys[-1])), sol.ys[-1], z)
