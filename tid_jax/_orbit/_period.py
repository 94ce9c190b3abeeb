"""The period map Phi_T: the state one forcing period on from a state at phase 0, with the
samples of the response over that period, its Jacobians (the monodromy matrix, by the
variational equations or forward derivatives) and the transient before shooting; diffrax
for smoothed friction, the closed-form stick-slip flow of `_flow` for exact friction. Each
function takes the paper's parameter vector (its one-storey `Plant`,
`_flow.parameter_plant`, with states in the paper's order) or any structure's `Plant`
(`model`); `point_model` gives either, with its linear equivalent start, at a point."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._model._building import BuildingTID, Quantity, friction_influence
from .._model._dynamics import dead_zone, parameters
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


def model(p, z) -> tuple[_flow.Plant, bool]:
    """The `_flow.Plant` of the period map at `p` and whether states like `z` are in the
    paper's order: `p` is a `Plant` (states in its own order, coordinates then their
    velocities) or the paper's parameter vector (`_dynamics.PARAMETERS`; states (x, x', y,
    y'[, q, q']), its one-storey plant `_flow.parameter_plant`)."""
    if isinstance(p, _flow.Plant):
        return p, False
    return _flow.parameter_plant(p, compliant=z.shape[-1] == 6), True


def flow(p, settings: SolverSettings) -> _flow.Flow | None:
    """What every period at `p` (see `model`) shares, for the functions below (`modes=`),
    computed once where many periods are integrated at the same `p`: with exact friction
    the modes of the stick-slip flow (`_flow.flow`); None for smoothed friction (its
    integrations share nothing)."""
    if not settings.exact_friction:
        return None
    return _flow.flow(model(p, np.zeros(settings.states))[0], settings.samples)


# The paper's state (x, x', y, y'), and (x, x', y, y', q, q') with a compliant device, in
# the order of the one-storey plant's coordinates and their velocities: (x, y, x', y') (the
# stroke r is y: the inerter joins the terminal to the ground), (x, y, q, x', y', q').
_PLANT_ORDER = {4: np.array([0, 2, 1, 3]), 6: np.array([0, 2, 4, 1, 3, 5])}


def to_plant(z, paper: bool = True):
    return z[..., _PLANT_ORDER[z.shape[-1]]] if paper else z


def from_plant(z, paper: bool = True):
    return z[..., np.argsort(_PLANT_ORDER[z.shape[-1]])] if paper else z


def _exact_period(z0, modes: _flow.Flow, paper: bool, keep_samples: bool = True):
    """`_flow.period` in the order of the states `z0` (`paper`: the paper's): samples of
    the quantity, the stroke and the friction's velocity, the state after the period, the
    transitions and the largest |stroke| at a transition."""
    values, z_end, transitions, events = _flow.period(to_plant(z0, paper), modes,
                                                      keep_samples)
    return values, from_plant(z_end, paper), transitions, events


def _given_flow(p, settings: SolverSettings, given):
    return flow(p, settings) if given is None else given


def period_samples(z0, p, settings: SolverSettings, modes=None):
    """The quantity (the paper's x), the stroke (y) and the velocity of the friction's body
    (y' of a rigid device, q' of a compliant one) sampled over one period from `z0` at `p`
    (see `model`), the state after the period (not finite where the integration failed),
    the largest |stroke| at a stick-slip transition and the number of transitions (exact
    friction; else 0). `modes`: the flow at `p` (`flow(p, settings)`), if computed
    already."""
    plant, paper = model(p, z0)
    if settings.exact_friction:
        values, z_end, transitions, events = _exact_period(
            z0, _given_flow(p, settings, modes), paper)
    else:
        values, z_end, transitions, events = smoothed_period(to_plant(z0, paper), plant,
                                                             settings)
        z_end = from_plant(z_end, paper)
    return (values[:, 0], values[:, 1], values[:, 2], z_end, events,
            transitions.astype(z0.dtype))


def period_tangents(z, p, settings: SolverSettings, modes=None):
    """The state after one period from `z` at `p` (see `model`) and its Jacobian with
    respect to `z` (the monodromy matrix), by the variational equations (their step sizes
    follow the error of the state alone: accurate enough for Newton's iterations, whose
    answer does not depend on them). With exact friction, the forward derivatives of the
    hybrid period map. `modes`: the flow at `p` (`flow(p, settings)`), if computed
    already."""
    plant, paper = model(p, z)
    if settings.exact_friction:
        modes = _given_flow(p, settings, modes)
        end = lambda z0: _exact_period(z0, modes, paper, keep_samples=False)[1]
        return jax.vmap(lambda t: jax.jvp(end, (z,), (t,)), out_axes=(None, 1))(
            jnp.eye(z.shape[0], dtype=z.dtype))
    _, z_end, _, _, monodromy = smoothed_period(to_plant(z, paper), plant, settings,
                                                keep_samples=False, tangents=True)
    if paper:  # d z_end / d z in the paper's order: the rows and the columns permuted
        back = np.argsort(_PLANT_ORDER[z.shape[-1]])
        monodromy = monodromy[np.ix_(back, back)]
    return from_plant(z_end, paper), monodromy


def samples_and_jacobian(z, p, settings, directions=()):
    """One integration of a period from `z` with tangents along the state directions
    and the parameters `p[i]`, `i` in `directions` (the paper's parameter vector; a
    `Plant` takes none), differentiating the integration itself (so that the derivatives
    are those of the computed samples, to rounding): `(xs, ys, ws, z_end)`, their
    Jacobians with respect to `z` (that of `z_end` is the monodromy matrix) and with
    respect to those parameters (last axis of size `len(directions)`)."""
    index = jnp.asarray(directions, dtype=int)
    fn = lambda z0, q: period_samples(z0, p.at[index].set(q) if directions else p, settings)
    n = z.shape[0]
    basis = jnp.eye(n + len(directions), dtype=z.dtype)
    given = p[index] if directions else jnp.zeros(0, z.dtype)
    primal, tangents = jax.vmap(
        lambda t: jax.jvp(fn, (z, given), (t[:n], t[n:])), out_axes=(None, 0)
    )(basis)
    tangents = tuple(jnp.moveaxis(t, 0, -1) for t in tangents)
    return primal, tuple(t[..., :n] for t in tangents), tuple(t[..., n:] for t in tangents)


def initial_state(p, compliant: bool = False) -> Float[Array, " n"]:
    """Scaled state at phase 0 of the equivalent linear steady state: the friction
    ff sgn(v) replaced by the viscous damping that dissipates as much over a period at the
    amplitude it lets the friction's body (the rigid device's terminal, a compliant
    device's mechanism) reach, 4 ff / (pi omega |V|) for a velocity amplitude |V| (the
    describing function of dry friction), that amplitude found by bisection; the stuck
    linear steady state where the friction force exceeds the force needed to hold the
    body still. Four states, or six for a `compliant` device (backlash left out)."""
    (mass, stiffness, damping, inertance, friction, k, c, parasitic, terminal_mass, ks, _,
     _, amplitude, omega) = p
    jw = 1j * omega
    spring = k + jw * c
    scale = amplitude / stiffness  # displacements in units of A / K

    def host(terminal):
        """x of the host with the TID's terminal moving `terminal` times as far."""
        return stiffness / (stiffness - mass * omega**2 + jw * damping + spring * (1 - terminal))

    def response(friction_damping):
        """Complex amplitudes (scaled) of x, y and the friction's body, with the friction
        an extra viscous damping `friction_damping` on that body."""
        body = jw * (parasitic + friction_damping)
        if compliant:
            mechanism = body - inertance * omega**2
            device = ks * mechanism / (ks + mechanism)
            terminal = spring / (spring + device - terminal_mass * omega**2)
        else:
            terminal = spring / (spring + body - (inertance + terminal_mass) * omega**2)
        x = host(terminal)
        y = x * terminal
        q = y * ks / (ks + mechanism) if compliant else y
        return x, y, q

    def equivalent_damping(log_amplitude):
        return 4 * friction / (jnp.pi * omega * scale * jnp.exp(log_amplitude))

    def slips_further(log_amplitude):
        # whether the body moves more than assumed: the amplitude lies above
        _, _, q = response(equivalent_damping(log_amplitude))
        return jnp.log(jnp.abs(q)) > log_amplitude

    def bisect(_, bounds):
        low, high = bounds
        middle = 0.5 * (low + high)
        further = slips_further(middle)
        return jnp.where(further, middle, low), jnp.where(further, high, middle)

    # Between the frictionless amplitude and e^-40 of it (where more damping would let
    # the body move more, as near an antiresonance, the bisection ends at the top).
    high = jnp.log(jnp.abs(response(0.0)[2]))
    low, high = jax.lax.fori_loop(0, 64, bisect, (high - 40.0, high))
    x, y, q = response(equivalent_damping(0.5 * (low + high)))
    # Held still, the body feels the force of what joins it to the host.
    if compliant:
        stuck_terminal = spring / (spring + ks - terminal_mass * omega**2)
        stuck_x = host(stuck_terminal)
        stuck_y = stuck_x * stuck_terminal
        holding_force = jnp.abs(ks * stuck_y) * scale
    else:
        stuck_x = host(0.0)
        stuck_y = 0.0
        holding_force = jnp.abs(spring * stuck_x) * scale
    stuck = holding_force < friction
    x, y = jnp.where(stuck, stuck_x, x), jnp.where(stuck, stuck_y, y)
    # Forcing Im(A e^{i theta}); response Im(X e^{i theta}); velocity in units of omega A/K.
    parts = [x, y] + ([jnp.where(stuck, 0.0, q)] if compliant else [])
    return jnp.stack([part for z in parts for part in (z.imag, z.real)])


# bisections of the equivalent stroke's logarithm over a range of 40: 2e-6 apart at the
# end, closer than Newton's first step needs
_BISECTIONS = 24


def building_start(system: BuildingTID, amplitude, omega) -> Float[Array, " s"]:
    """`initial_state` of a `BuildingTID` at one point, in its plant's order (coordinates,
    then their velocities), in units of its static scale: the friction
    replaced by the viscous damping 4 ff / (pi omega |R|) that dissipates as much at the
    stroke amplitude |R| it lets through (found by bisection), or the steady state with
    the inerter stuck where the friction holds it."""
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
    """The period map's model of `system` (a `TIDSystem` or a `BuildingTID`, measuring
    `quantity`) at one point: `p` for the functions above (the paper's parameter vector,
    or the building's `Plant`), the linear equivalent start in the order of its states
    (`initial_state`, `building_start`), and the SI units of the scaled quantity and of
    the stroke, the unit D of the scaled displacements (velocities in omega D)."""
    if isinstance(system, BuildingTID):
        unit_q, unit = _flow.projection_units(system, quantity, amplitude, omega)
        return (_flow.plant(system, quantity, amplitude, omega),
                building_start(system, amplitude, omega), unit_q, unit)
    p = jnp.stack(parameters(system, amplitude, omega))
    unit = amplitude / system.host_stiffness
    return p, initial_state(p, system.compliant), unit, unit


def state_units(unit, omega, states: int, paper: bool, xp=jnp):
    """The SI units of scaled states at points of displacement unit `unit` and frequency
    `omega` (broadcast together), `[..., states]`: in the paper's order (x, x', y, y'[,
    q, q']) or a plant's (coordinates, then their velocities)."""
    m = states // 2
    columns = [unit + 0 * omega, unit * omega]
    return xp.stack(columns * m if paper else [columns[0]] * m + [columns[1]] * m, axis=-1)


def transient(z, p, settings: SolverSettings, periods=None):
    """Integrate `periods` (default `settings.transient_periods`, at most that; may be
    traced) periods from `z` at `p` (see `model`); keeps `z` if that fails."""
    if settings.transient_periods == 0:
        return z
    count = settings.transient_periods if periods is None else periods
    plant, paper = model(p, z)
    if settings.exact_friction:
        modes = flow(p, settings)
        end = jax.lax.fori_loop(
            0, count, lambda _, z: _exact_period(z, modes, paper, keep_samples=False)[1], z)
    else:
        sol = integrate(smoothed_field, to_plant(z, paper), plant, 2 * jnp.pi * count,
                        settings, dfx.SaveAt(t1=True),
                        settings.max_steps * settings.transient_periods)
        end = from_plant(sol.ys[-1], paper)
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
