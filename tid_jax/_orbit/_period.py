"""The period map Phi_T: the state one forcing period on from a state at phase 0, with the
samples of the response over that period, its Jacobians (the monodromy matrix, by the
variational equations or forward derivatives) and the transient before shooting; diffrax
for smoothed friction, the closed-form stick-slip flow of `_flow` for exact friction. Each
function takes a structure's `Plant` (states: its coordinates, then their velocities);
`point_model` gives it, with its linear equivalent start, at a point."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._model._building import BuildingTID, Quantity, building_of, friction_influence
from .._model._dynamics import dead_zone
from . import _flow
from ._settings import SolverSettings


def _solver(settings: SolverSettings):
    return dfx.Kvaerno5() if settings.implicit is True else dfx.Tsit5()


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


def flow(plant: _flow.Plant, settings: SolverSettings) -> _flow.Flow | None:
    """What every period of `plant` shares, for the functions below (`modes=`),
    computed once where many periods are integrated with it: with exact friction
    the modes of the stick-slip flow (`_flow.flow`); None for smoothed friction (its
    integrations share nothing)."""
    if not settings.exact_friction:
        return None
    return _flow.flow(plant, settings.samples)


def _given_flow(plant, settings: SolverSettings, given):
    return flow(plant, settings) if given is None else given


def period_samples(z0, plant: _flow.Plant, settings: SolverSettings, modes=None):
    """The quantity, the stroke and the velocity of the friction's coordinate (the stroke's
    of a rigid device, the mechanism's of a compliant one) sampled over one period from
    `z0` of `plant`, the state after the period (not finite where the integration failed),
    the largest |stroke| at a stick-slip transition and the number of transitions (exact
    friction; else 0). `modes`: the flow of `plant` (`flow(plant, settings)`), if computed
    already."""
    if settings.exact_friction:
        values, z_end, transitions, events = _flow.period(
            z0, _given_flow(plant, settings, modes), True)
    else:
        values, z_end, transitions, events = smoothed_period(z0, plant, settings)
    return (values[:, 0], values[:, 1], values[:, 2], z_end, events,
            transitions.astype(z0.dtype))


def period_tangents(z, plant: _flow.Plant, settings: SolverSettings, modes=None):
    """The state after one period from `z` of `plant` and its Jacobian with respect to `z`
    (the monodromy matrix), by the variational equations (their step sizes follow the
    error of the state alone: accurate enough for Newton's iterations, whose answer does
    not depend on them). With exact friction, the forward derivatives of the hybrid
    period map. `modes`: the flow of `plant` (`flow(plant, settings)`), if computed
    already."""
    if settings.exact_friction:
        modes = _given_flow(plant, settings, modes)
        end = lambda z0: _flow.period(z0, modes, False)[1]
        return jax.vmap(lambda t: jax.jvp(end, (z,), (t,)), out_axes=(None, 1))(
            jnp.eye(z.shape[0], dtype=z.dtype))
    _, z_end, _, _, monodromy = smoothed_period(z, plant, settings, keep_samples=False,
                                                tangents=True)
    return z_end, monodromy


def samples_and_jacobian(z, plant: _flow.Plant, settings: SolverSettings, columns=None):
    """One integration of a period from `z` with tangents along the state directions
    and, where given, along the plant's tangents `columns` (a `Plant` of tangents with a
    trailing axis), differentiating the integration itself (so that the derivatives are
    those of the computed samples, to rounding): `period_samples`, their Jacobians with
    respect to `z` (that of the state after the period is the monodromy matrix) and along
    `columns` (None where not given)."""
    n = z.shape[0]
    if columns is None:
        fn = lambda z0: period_samples(z0, plant, settings)
        primal, tangents = jax.vmap(lambda t: jax.jvp(fn, (z,), (t,)), out_axes=(None, 0))(
            jnp.eye(n, dtype=z.dtype))
        return primal, tuple(jnp.moveaxis(t, 0, -1) for t in tangents), None
    m = jax.tree.leaves(columns)[0].shape[-1]
    fn = lambda z0, q: period_samples(z0, q, settings)
    of_z = jnp.eye(n + m, n, dtype=z.dtype)
    of_plant = jax.tree.map(lambda a, column: jnp.concatenate(
        [jnp.zeros((n,) + a.shape, a.dtype), jnp.moveaxis(column, -1, 0)]), plant, columns)
    primal, tangents = jax.vmap(lambda dz, dq: jax.jvp(fn, (z, plant), (dz, dq)),
                                out_axes=(None, 0))(of_z, of_plant)
    tangents = tuple(jnp.moveaxis(t, 0, -1) for t in tangents)
    return (primal, tuple(t[..., :n] for t in tangents),
            tuple(t[..., n:] for t in tangents))


# bisections of the equivalent stroke's logarithm over a range of 40: 2e-6 apart at the
# end, closer than Newton's first step needs
_BISECTIONS = 24


def building_start(system: BuildingTID, amplitude, omega) -> Float[Array, " s"]:
    """The equivalent linear steady state of a `BuildingTID` at phase 0 at one point, in
    its plant's order (coordinates, then their velocities), in units of its static scale:
    the friction replaced by the viscous damping 4 ff / (pi omega |V|) that dissipates as
    much at the velocity amplitude omega |V| it lets the friction's coordinate reach (the
    describing function of dry friction; |V| found by bisection), or the steady state
    with the inerter stuck where the friction holds it (a compliant device's backlash
    left out)."""
    scale = system.static_scale()
    free, influence = friction_influence(system, omega)
    f = system.coordinates - 1  # the friction's coordinate

    def added(log_amplitude):
        """i omega times the equivalent damping at a stroke amplitude of e^log_amplitude."""
        return 4j * system.friction_force / (jnp.pi * amplitude * jnp.exp(log_amplitude))

    def bisect(_, bounds):
        low, high = bounds
        middle = 0.5 * (low + high)
        stroke = free[f] / (1 + added(middle) * influence[f])
        further = jnp.log(jnp.abs(stroke)) > middle
        return jnp.where(further, middle, low), jnp.where(further, high, middle)

    high = jnp.log(jnp.abs(free[f]))
    low, high = jax.lax.fori_loop(0, _BISECTIONS, bisect, (high - 40.0, high))
    damped = added(0.5 * (low + high))
    slipping = free - influence * (damped * free[f] / (1 + damped * influence[f]))
    holding = free[f] / influence[f]  # the friction force that holds it, per unit load
    stuck = jnp.abs(holding) * amplitude < system.friction_force
    u = jnp.where(stuck, (free - influence * holding).at[f].set(0.0), slipping) / scale
    # load Im(e^{i theta}); response Im(U e^{i theta}); velocity in units of omega D
    return jnp.concatenate([u.imag, u.real])


def point_model(system, quantity: Quantity, amplitude, omega):
    """The period map's model of `system` (a `BuildingTID`, measuring `quantity`, or a
    `TIDSystem` as its one-storey building) at one point: its `Plant`, the linear
    equivalent start (`building_start`), and the SI units of the scaled quantity and of
    the stroke, the unit D of the scaled displacements (velocities in omega D)."""
    system = building_of(system, "force")
    unit_q, unit = _flow.projection_units(system, quantity, amplitude, omega)
    return (_flow.plant(system, quantity, amplitude, omega),
            building_start(system, amplitude, omega), unit_q, unit)


def state_units(unit, omega, states: int, xp=jnp):
    """The SI units of scaled states (coordinates, then their velocities) at points of
    displacement unit `unit` and frequency `omega` (broadcast together), `[..., states]`."""
    m = states // 2
    return xp.stack([unit + 0 * omega] * m + [unit * omega] * m, axis=-1)


def transient(z, plant: _flow.Plant, settings: SolverSettings, periods=None):
    """Integrate `periods` (default `settings.transient_periods`, at most that; may be
    traced) periods from `z` of `plant`; keeps `z` if that fails."""
    if settings.transient_periods == 0:
        return z
    count = settings.transient_periods if periods is None else periods
    if settings.exact_friction:
        modes = flow(plant, settings)
        end = jax.lax.fori_loop(
            0, count, lambda _, z: _flow.period(z, modes, False)[1], z)
    else:
        sol = integrate(smoothed_field, z, plant, 2 * jnp.pi * count, settings,
                        dfx.SaveAt(t1=True), settings.max_steps * settings.transient_periods)
        end = sol.ys[-1]
    return jnp.where(jnp.all(jnp.isfinite(end)), end, z)


def _product(matrix, z):
    """`matrix @ z` (z a state or columns of tangents) as a sum over the columns of
    `matrix`: in a batch of small plants this fuses with the field, where a batched
    product calls the matrix kernel lane by lane."""
    columns = [matrix[:, j] if z.ndim == 1 else matrix[:, j, None] for j in range(z.shape[0])]
    return sum(column * z[j] for j, column in enumerate(columns))


def _play(z, plant: _flow.Plant):
    """A compliant device's series spring's stretch `r - q` (rows of z: the states, or
    their tangents)."""
    return z[plant.stroke] - z[plant.stroke + 1]


def _compliant(z, plant: _flow.Plant) -> bool:
    """Whether the plant's device is compliant: its stroke is not the friction's
    coordinate (the last)."""
    return plant.stroke != z.shape[0] // 2 - 1


def smoothed_field(theta, z, plant: _flow.Plant):
    """The scaled field with the friction smoothed as `tanh(r' / width)`."""
    m = z.shape[0] // 2
    friction = plant.friction * jnp.tanh(z[2 * m - 1] / plant.width)
    field = (_product(plant.slip, z) + plant.forcing * jnp.sin(theta)
             - friction * plant.friction_vector)
    if not _compliant(z, plant):
        return field
    stretch = _play(z, plant)
    return field + (stretch - dead_zone(stretch, plant.gap)) * plant.play_vector


def _field_and_tangents(theta, y, plant: _flow.Plant):
    """The smoothed field with its variational equations: `y = (z, tangents)`, where the
    tangents (n x n) are d z / d z0."""
    z, tangents = y
    m = z.shape[0] // 2
    slope = plant.friction * (1 - jnp.tanh(z[2 * m - 1] / plant.width) ** 2) / plant.width
    along = _product(plant.slip, tangents) - jnp.outer(plant.friction_vector,
                                                       slope * tangents[2 * m - 1])
    if _compliant(z, plant):
        # within the free play the series spring's force is constant: d(s - D(s)) = ds
        slack = jnp.abs(_play(z, plant)) <= 0.5 * plant.gap
        along += jnp.outer(plant.play_vector, jnp.where(slack, 1.0, 0.0) * _play(tangents, plant))
    return smoothed_field(theta, z, plant), along


def smoothed_period(z0, plant: _flow.Plant, settings: SolverSettings, keep_samples: bool = True,
                    tangents: bool = False):
    """One period of the smoothed flow of a `_flow.Plant` (diffrax): the same outputs as
    `_flow.period`, and with `tangents` the monodromy matrix last, by the variational
    equations (their step sizes follow the error of the state alone: accurate enough for
    Newton's iterations, whose answer does not depend on it, and cheaper than forward
    derivatives of the steps)."""
    phases = np.arange(settings.samples) * (2 * np.pi / settings.samples)
    saveat = dfx.SaveAt(ts=phases, t1=True) if keep_samples else dfx.SaveAt(t1=True)
    field, y0 = smoothed_field, z0
    if tangents:
        field, y0 = _field_and_tangents, (z0, jnp.eye(z0.shape[0], dtype=z0.dtype))
    sol = integrate(field, y0, plant, 2 * np.pi, settings, saveat, settings.max_steps)
    ys, monodromy = (sol.ys[0], (sol.ys[1][-1],)) if tangents else (sol.ys, ())
    z_end = jnp.where(sol.result == dfx.RESULTS.successful, ys[-1], jnp.nan)
    if not keep_samples:
        return (jnp.zeros((0, 3), z0.dtype), z_end, jnp.zeros((), int),
                jnp.zeros((), z0.dtype)) + monodromy
    states = ys[:-1]
    rates = jax.vmap(smoothed_field, in_axes=(0, 0, None))(jnp.asarray(phases), states, plant)
    values = (states @ plant.rows.T + rates @ plant.rows_rate.T
              + jnp.sin(jnp.asarray(phases))[:, None] * plant.rows_sin)
    return (values[:, :3], z_end, jnp.zeros((), int), jnp.zeros((), z0.dtype)) + monodromy
