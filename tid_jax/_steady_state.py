import functools as ft
import math
from collections.abc import Sequence

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Bool, Complex, Float, Int

from ._dynamics import vector_field


class SolverSettings(eqx.Module):
    """Numerical settings of the steady-state (shooting) solver. Defaults live here only.

    - `rtol`, `atol`: tolerances of the adaptive Tsit5 integration, on the state scaled by
      the static displacement A / K.
    - `max_steps`: integration steps allowed per forcing period.
    - `transient_periods`: periods integrated from the initial guess before shooting.
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
    max_newton_steps: int = 10
    periodicity_tol: float = 1e-6
    samples: int = 128

    def __check_init__(self):
        for name in ("rtol", "atol", "periodicity_tol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"SolverSettings.{name} must be a positive number, got {value!r}")
        for name, low in (("max_steps", 16), ("transient_periods", 0), ("max_newton_steps", 1),
                          ("samples", 8)):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= low):
                raise ValueError(f"SolverSettings.{name} must be an integer >= {low}, got {value!r}")

    def persistent(self) -> "SolverSettings":
        """Settings for a second attempt at points that did not converge: a long transient
        towards the attracting orbit, then more Newton iterations, on integrations 100 times
        more accurate (Newton stalls where the integration error of the period map exceeds
        `periodicity_tol`)."""
        return eqx.tree_at(
            lambda s: (s.rtol, s.atol, s.transient_periods, s.max_newton_steps),
            self,
            (self.rtol / 100, self.atol / 100, max(40, 4 * self.transient_periods),
             max(25, 2 * self.max_newton_steps)),
        )

    def to_dict(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


class Orbit(eqx.Module):
    """The periodic steady state at one (frequency, amplitude), scaled state units
    (displacements in A / K, velocities in omega A / K) unless stated."""

    state: Float[Array, " 4"]  # scaled (x, x', y, y') at phase 0 of the forcing
    x_samples: Float[Array, " samples"]  # scaled x over one period
    y_samples: Float[Array, " samples"]
    y_velocity_samples: Float[Array, " samples"]
    monodromy: Float[Array, "4 4"]  # dPhi_T/dz at `state`
    # d state / d p[i] for i in the `directions` of `solve_orbit` (implicit derivatives)
    state_derivatives: Float[Array, "4 directions"]
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


def _transient(z, p, settings: SolverSettings):
    """Integrate `settings.transient_periods` periods from `z` (keeps `z` if that fails)."""
    if settings.transient_periods == 0:
        return z
    sol = _integrate(
        z,
        p,
        2 * jnp.pi * settings.transient_periods,
        settings,
        dfx.SaveAt(t1=True),
        settings.max_steps * settings.transient_periods,
    )
    return jnp.where(jnp.all(jnp.isfinite(sol.ys[-1])), sol.ys[-1], z)


def _samples_and_jacobian(z, p, settings, directions=()):
    """One integration of a period from `z` with tangents along the four state directions
    and the parameters `p[i]`, `i` in `directions`: `(xs, ys, ws, z_end)`, their Jacobians
    with respect to `z` (that of `z_end` is the monodromy matrix) and with respect to those
    parameters (last axis of size `len(directions)`)."""
    index = jnp.asarray(directions, dtype=int)
    fn = lambda z0, q: _period_samples(z0, p.at[index].set(q), settings)
    size = 4 + len(directions)
    basis = jnp.eye(size, dtype=z.dtype)
    q = p[index]
    primal, tangents = jax.vmap(
        lambda t: jax.jvp(fn, (z, q), (t[:4], t[4:])), out_axes=(None, 0)
    )(basis)
    tangents = tuple(jnp.moveaxis(t, 0, -1) for t in tangents)
    return primal, tuple(t[..., :4] for t in tangents), tuple(t[..., 4:] for t in tangents)


_MAX_NEWTON_STEP = 2.0  # largest Newton update, relative to max(1, max |z|)


def _limited(z, update):
    size = jnp.max(jnp.abs(update))
    limit = _MAX_NEWTON_STEP * jnp.maximum(1.0, jnp.max(jnp.abs(z)))
    return z + update * jnp.minimum(1.0, limit / jnp.maximum(size, 1e-300))


def _chord(z0, p, settings: SolverSettings, monodromy):
    """Chord iterations for z* = Phi_T(z*) with the fixed Jacobian `I - monodromy` (from a
    nearby orbit): each costs one integration without tangents, which also samples x over
    the period. Stops once the residual is within `settings.periodicity_tol` or after
    `settings.max_newton_steps` iterations. Returns the last iterate while the residuals
    fall, else the best one evaluated (`z0` if none is finite), and the x samples of the
    best iterate evaluated."""
    lu = jax.scipy.linalg.lu_factor(jnp.eye(4, dtype=z0.dtype) - monodromy)
    inf = jnp.asarray(jnp.inf, z0.dtype)
    no_samples = jnp.full(settings.samples, jnp.nan, z0.dtype)

    def cond(carry):
        _, _, best_residual, _, _, steps = carry
        return (best_residual > settings.periodicity_tol) & (steps < settings.max_newton_steps)

    def body(carry):
        z, best, best_residual, best_xs, _, steps = carry
        xs, _, _, z_end = _period_samples(z, p, settings)
        r = z_end - z
        ok = jnp.all(jnp.isfinite(r)) & jnp.all(jnp.isfinite(z))
        residual = jnp.where(ok, jnp.max(jnp.abs(r)), inf)
        improved = residual < best_residual
        best, best_residual = jnp.where(improved, z, best), jnp.minimum(residual, best_residual)
        best_xs = jnp.where(improved, xs, best_xs)
        converged = residual <= settings.periodicity_tol
        step = jax.scipy.linalg.lu_solve(lu, jnp.where(ok, r, 0.0))
        z_next = jnp.where(converged | ~ok, z, _limited(z, step))
        return z_next, best, best_residual, best_xs, improved, steps + 1

    z, best, _, best_xs, improved, _ = jax.lax.while_loop(
        cond, body, (z0, z0, inf, no_samples, jnp.asarray(False), 0)
    )
    return jnp.where(improved & jnp.all(jnp.isfinite(z)), z, best), best_xs


def settled_state(z0, p, settings: SolverSettings, monodromy):
    """The periodic orbit at `p` by chord iterations from `z0` with the monodromy matrix of
    a nearby orbit (`_chord`; no tangents): the scaled state (the last iterate, or the best
    one evaluated where the residuals stopped falling) and the x samples over a period of
    the best iterate evaluated (NaN if none was)."""
    return _chord(jax.lax.stop_gradient(z0), jax.lax.stop_gradient(p), settings,
                  jax.lax.stop_gradient(monodromy))


def _shoot(z0, p, settings: SolverSettings, directions=()):
    """Newton shooting for z* = Phi_T(z*). Each iteration is one integration of a period
    with four state tangents (and one per parameter in `directions`), giving the residual
    Phi_T(z) - z, the monodromy matrix and the samples at once. Once the residual is
    within `settings.periodicity_tol`, the last Newton update is applied to the state and,
    to first order, to the samples (their error is then second order in the residual)."""
    eye = jnp.eye(4, dtype=z0.dtype)

    def evaluate(z):
        (xs, ys, ws, z_end), (jx, jy, jw, monodromy), (jx_p, jy_p, jw_p, jz_p) = (
            _samples_and_jacobian(z, p, settings, directions)
        )
        residual = z_end - z
        update = jnp.linalg.solve(eye - monodromy, residual)
        finite = jnp.all(jnp.isfinite(update)) & jnp.all(jnp.isfinite(xs))
        finite = finite & jnp.all(jnp.isfinite(ys))
        return dict(
            z=z, xs=xs, ys=ys, ws=ws, jx=jx, jy=jy, jw=jw, monodromy=monodromy,
            jx_p=jx_p, jy_p=jy_p, jw_p=jw_p, jz_p=jz_p,
            update=jnp.where(finite, update, 0.0),
            residual=jnp.where(finite, jnp.max(jnp.abs(residual)), jnp.inf),
        )

    def cond(carry):
        state, steps = carry
        return (state["residual"] > settings.periodicity_tol) & (steps < settings.max_newton_steps)

    def body(carry):
        state, steps = carry
        return evaluate(_limited(state["z"], state["update"])), steps + 1

    state, steps = jax.lax.while_loop(cond, body, (evaluate(z0), jnp.array(1)))
    dz = state["update"]
    orbit = dict(
        z=state["z"] + dz,
        xs=state["xs"] + state["jx"] @ dz,
        ys=state["ys"] + state["jy"] @ dz,
        ws=state["ws"] + state["jw"] @ dz,
        **{key: state[key] for key in ("jx", "jy", "jw", "monodromy", "jx_p", "jy_p", "jw_p",
                                       "jz_p")},
    )
    return orbit, state["residual"], steps


@ft.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _with_orbit_derivatives(settings, directions, orbit, *p):
    """Identity on a converged `orbit`; its JVP is the implicit derivative of the orbit
    with respect to the parameters `p`, using the Jacobians that `_shoot` formed with
    respect to `p[i]`, `i` in `directions`, where it can."""
    del p
    return orbit


def _orbit_jvp(settings, directions, primals, tangents):
    # z* = Phi_T(z*, p) gives dz*/dp = (I - dPhi/dz)^{-1} dPhi/dp, and the samples follow by
    # the chain rule. Only parameters with non-zero tangents are differentiated, and every
    # Jacobian is formed from primals alone: the tangent map is an explicit matrix product,
    # which reverse mode can transpose.
    orbit, *p = primals
    _, *p_dot = tangents
    active = [i for i, t in enumerate(p_dot) if not isinstance(t, SymbolicZero)]
    tangent_out = jax.tree.map(jnp.zeros_like, orbit)
    if not active:
        return orbit, tangent_out

    if set(active) <= set(directions):
        columns = jnp.asarray([directions.index(i) for i in active], dtype=int)
        jx_p, jy_p, jw_p, jz_p = (orbit[key][..., columns] for key in
                                  ("jx_p", "jy_p", "jw_p", "jz_p"))
    else:
        def period(*values):
            q = list(p)
            for i, value in zip(active, values, strict=True):
                q[i] = value
            return _period_samples(orbit["z"], jnp.stack(q), settings)

        jac = jax.jacfwd(period, argnums=tuple(range(len(active))))(*(p[i] for i in active))
        jx_p, jy_p, jw_p, jz_p = (jnp.stack(j, axis=-1) for j in jac)
    p_active_dot = jnp.stack([p_dot[i] for i in active])
    eye = jnp.eye(4, dtype=orbit["z"].dtype)
    z_dot = jnp.linalg.solve(eye - orbit["monodromy"], jz_p) @ p_active_dot
    tangent_out["z"] = z_dot
    tangent_out["xs"] = orbit["jx"] @ z_dot + jx_p @ p_active_dot
    tangent_out["ys"] = orbit["jy"] @ z_dot + jy_p @ p_active_dot
    tangent_out["ws"] = orbit["jw"] @ z_dot + jw_p @ p_active_dot
    return orbit, tangent_out


_with_orbit_derivatives.defjvp(_orbit_jvp, symbolic_zeros=True)


def solve_orbit(
    p: Float[Array, " 10"] | Sequence[Float[Array, ""]],
    settings: SolverSettings,
    z_init: Float[Array, " 4"] | None = None,
    monodromy_init: Float[Array, "4 4"] | None = None,
    directions: tuple[int, ...] = (),
) -> Orbit:
    """The periodic orbit at the parameter vector `p` (order `_dynamics.PARAMETERS`; or
    the sequence of its scalars, which lets derivatives skip the parameters that do not
    depend on the differentiated inputs), by
    shooting from `z_init` (scaled state; default the linear steady state followed by
    `settings.transient_periods` periods). Differentiable with respect to `p` (implicit
    differentiation), not with respect to `z_init`.

    With `monodromy_init`, the monodromy matrix of a nearby orbit (e.g. that of `z_init`
    at slightly different parameters), chord iterations without tangents bring `z_init`
    to the orbit before the Newton iteration that forms the Jacobians. Derivatives with
    respect to `p[i]`, `i` in `directions`, reuse the tangents of that iteration; the
    state's are returned too (`Orbit.state_derivatives`), e.g. to predict the orbit at
    nearby parameters."""
    scalars = list(p) if isinstance(p, (list, tuple)) else [p[i] for i in range(p.shape[0])]
    p_const = jax.lax.stop_gradient(jnp.stack(scalars))
    if z_init is None:
        z_init = _transient(linear_initial_state(p_const), p_const, settings)
    z_init = jax.lax.stop_gradient(z_init)
    if monodromy_init is not None:
        z_init, _ = _chord(z_init, p_const, settings, jax.lax.stop_gradient(monodromy_init))
    orbit, residual, steps = _shoot(z_init, p_const, settings, tuple(directions))
    orbit = _with_orbit_derivatives(settings, tuple(directions), orbit, *scalars)
    converged = (residual <= settings.periodicity_tol) & jnp.all(jnp.isfinite(orbit["xs"]))
    monodromy = jax.lax.stop_gradient(orbit["monodromy"])
    eye = jnp.eye(4, dtype=monodromy.dtype)
    state_derivatives = jnp.linalg.solve(eye - monodromy, jax.lax.stop_gradient(orbit["jz_p"]))
    return Orbit(
        state=orbit["z"],
        x_samples=orbit["xs"],
        y_samples=orbit["ys"],
        y_velocity_samples=orbit["ws"],
        monodromy=monodromy,
        state_derivatives=state_derivatives,
        floquet_multipliers=jnp.linalg.eigvals(monodromy),
        residual=residual,
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

