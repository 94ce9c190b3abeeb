import functools as ft
import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Complex, Float, Int

from ._dynamics import vector_field


class SolverSettings(eqx.Module):
    """Numerical settings of the steady-state (shooting) solver. Defaults live here only.

    - `rtol`, `atol`: tolerances of the adaptive Tsit5 integration, on the state scaled by
      the static displacement A / K.
    - `max_steps`: integration steps allowed per forcing period.
    - `transient_periods`: periods integrated from the initial guess before shooting.
    - `newton_tol`: Newton stops when the periodicity update is below this (scaled).
    - `max_newton_steps`: Newton iterations allowed.
    - `periodicity_tol`: a point counts as converged only if |Phi_T(z0) - z0| is below this
      (scaled), checked by a separate integration of the final orbit.
    - `samples`: points per period at which x and y are sampled; each peak is refined by a
      parabola through the three samples around it.
    """

    rtol: float = 1e-8
    atol: float = 1e-8
    max_steps: int = 4096
    transient_periods: int = 2
    newton_tol: float = 1e-6
    max_newton_steps: int = 25
    periodicity_tol: float = 1e-6
    samples: int = 128

    def __check_init__(self):
        for name in ("rtol", "atol", "newton_tol", "periodicity_tol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"SolverSettings.{name} must be a positive number, got {value!r}")
        for name, low in (("max_steps", 16), ("transient_periods", 0), ("max_newton_steps", 1),
                          ("samples", 8)):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= low):
                raise ValueError(f"SolverSettings.{name} must be an integer >= {low}, got {value!r}")

    def to_dict(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


class Orbit(eqx.Module):
    """The periodic steady state at one (frequency, amplitude), scaled state units
    (displacements in A / K, velocities in omega A / K) unless stated."""

    state: Float[Array, " 4"]  # scaled (x, x', y, y') at phase 0 of the forcing
    x_samples: Float[Array, " samples"]  # scaled x over one period
    y_samples: Float[Array, " samples"]
    y_velocity_samples: Float[Array, " samples"]
    floquet_multipliers: Complex[Array, " 4"]
    residual: Float[Array, ""]  # max |Phi_T(z0) - z0|, scaled
    newton_steps: Int[Array, ""]
    converged: Bool[Array, ""]


def _integrate(z0, p, t1, settings: SolverSettings, saveat, max_steps):
    return dfx.diffeqsolve(
        dfx.ODETerm(vector_field),
        dfx.Tsit5(),
        t0=0.0,
        t1=t1,
        dt0=None,
        y0=z0,
        args=p,
        saveat=saveat,
        stepsize_controller=dfx.PIDController(rtol=settings.rtol, atol=settings.atol),
        adjoint=dfx.ForwardMode(),
        max_steps=max_steps,
        throw=False,
    )


def _phases(settings: SolverSettings, dtype):
    # Sample phases in [0, 2 pi), clipped below t1 so none rounds past the end.
    return jnp.arange(settings.samples, dtype=dtype) * (2 * jnp.pi / settings.samples)


def _period_map(z0, p, settings: SolverSettings):
    """Phi_T: state after one forcing period from `z0`."""
    sol = _integrate(z0, p, 2 * jnp.pi, settings, dfx.SaveAt(t1=True), settings.max_steps)
    return sol.ys[-1]


def _period_samples(z0, p, settings: SolverSettings):
    """x, y and y' sampled over one period from `z0`, and the state after the period."""
    phases = _phases(settings, z0.dtype)
    sol = _integrate(
        z0, p, 2 * jnp.pi, settings, dfx.SaveAt(ts=phases, t1=True), settings.max_steps
    )
    ys = sol.ys
    return ys[:-1, 0], ys[:-1, 2], ys[:-1, 3], ys[-1]


def linear_initial_state(p) -> Float[Array, " 4"]:
    """Scaled state at phase 0 of the steady linear response: of the free (frictionless)
    TID, or of the stuck one when the friction force exceeds the force needed to hold the
    inerter terminal still."""
    mass, stiffness, damping, inertance, friction, k, c, _, amplitude, omega = p
    jw = 1j * omega
    spring = k + jw * c
    terminal = spring / (spring - inertance * omega**2)
    free_x = stiffness / (stiffness - mass * omega**2 + jw * damping + spring * (1 - terminal))
    stuck_x = stiffness / (stiffness + k - mass * omega**2 + jw * (damping + c))
    holding_force = jnp.abs(spring * stuck_x) * amplitude / stiffness
    stuck = holding_force < friction
    x_hat = jnp.where(stuck, stuck_x, free_x)
    y_hat = jnp.where(stuck, 0.0, free_x * terminal)
    # Forcing Im(A e^{i theta}); response Im(X e^{i theta}); velocity in units of omega A/K.
    return jnp.stack([x_hat.imag, x_hat.real, y_hat.imag, y_hat.real])


def _find_orbit(p, settings: SolverSettings):
    z = linear_initial_state(p)
    if settings.transient_periods > 0:
        sol = _integrate(
            z,
            p,
            2 * jnp.pi * settings.transient_periods,
            settings,
            dfx.SaveAt(t1=True),
            settings.max_steps * settings.transient_periods,
        )
        z = jnp.where(jnp.all(jnp.isfinite(sol.ys[-1])), sol.ys[-1], z)

    def residual(z0, p):
        return _period_map(z0, p, settings) - z0

    solver = optx.Newton(rtol=settings.newton_tol, atol=settings.newton_tol)
    sol = optx.root_find(residual, solver, z, args=p, max_steps=settings.max_newton_steps,
                         throw=False)
    z_star = jnp.where(jnp.all(jnp.isfinite(sol.value)), sol.value, z)
    return z_star, sol.stats["num_steps"]


def _samples_and_monodromy(z_star, p, settings):
    """One integration of the orbit, with the four state tangents (the monodromy matrix)."""
    fn = lambda z: _period_samples(z, p, settings)
    basis = jnp.eye(4, dtype=z_star.dtype)
    primal, tangents = jax.vmap(lambda t: jax.jvp(fn, (z_star,), (t,)), out_axes=(None, 0))(basis)
    monodromy = tangents[3].T  # column j: d z_T / d z0_j
    return primal, monodromy


@ft.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _orbit_samples(z_star, p, settings):
    (xs, ys, ws, z_end), monodromy = _samples_and_monodromy(z_star, p, settings)
    return z_star, xs, ys, ws, z_end, monodromy


@_orbit_samples.defjvp
def _orbit_samples_jvp(settings, primals, tangents):
    # Implicit differentiation through the periodic orbit: z* = Phi_T(z*, p) gives
    # dz*/dp = (I - dPhi/dz)^{-1} dPhi/dp. The Jacobians are formed from primals only, so
    # the tangent map is an explicit matrix product and reverse mode can transpose it.
    z_star, p = primals
    _, p_dot = tangents
    out = _orbit_samples(z_star, p, settings)
    jac_z, jac_p = jax.jacfwd(lambda z, q: _period_samples(z, q, settings), argnums=(0, 1))(
        z_star, p
    )
    monodromy = out[-1]
    sensitivity = jnp.linalg.solve(jnp.eye(4, dtype=monodromy.dtype) - monodromy, jac_p[3])
    z_dot = sensitivity @ p_dot
    xs_dot, ys_dot, ws_dot = (jz @ z_dot + jp @ p_dot for jz, jp in zip(jac_z[:3], jac_p[:3]))
    return out, (z_dot, xs_dot, ys_dot, ws_dot, z_dot, jnp.zeros_like(monodromy))


def solve_orbit(p: Float[Array, " 10"], settings: SolverSettings) -> Orbit:
    """The periodic orbit at one parameter vector `p` (see `_dynamics.PARAMETERS`).
    Differentiable with respect to `p` by implicit differentiation."""
    z_guess, steps = _find_orbit(jax.lax.stop_gradient(p), settings)
    z_star, xs, ys, ws, z_end, monodromy = _orbit_samples(
        jax.lax.stop_gradient(z_guess), p, settings
    )
    monodromy = jax.lax.stop_gradient(monodromy)
    residual = jax.lax.stop_gradient(jnp.max(jnp.abs(z_end - z_star)))
    multipliers = jnp.linalg.eigvals(monodromy)
    finite = jnp.all(jnp.isfinite(xs)) & jnp.all(jnp.isfinite(ys)) & jnp.isfinite(residual)
    converged = finite & (residual <= settings.periodicity_tol)
    return Orbit(
        state=z_star,
        x_samples=xs,
        y_samples=ys,
        y_velocity_samples=ws,
        floquet_multipliers=multipliers,
        residual=jnp.where(jnp.isfinite(residual), residual, jnp.inf),
        newton_steps=steps,
        converged=converged,
    )


def refined_peak(samples: Float[Array, " n"]) -> Float[Array, ""]:
    """max |s(phase)| over a period from periodic samples, refined by the vertex of the
    parabola through the largest sample and its two neighbours."""

    def top(s):
        i = jnp.argmax(s)
        left, mid, right = s[i - 1], s[i], s[(i + 1) % s.shape[0]]
        curvature = left - 2 * mid + right
        safe = jnp.where(curvature < 0, curvature, -1.0)
        vertex = mid - (right - left) ** 2 / (8 * safe)
        return jnp.where(curvature < 0, jnp.maximum(vertex, mid), mid)

    return jnp.maximum(top(samples), top(-samples))

