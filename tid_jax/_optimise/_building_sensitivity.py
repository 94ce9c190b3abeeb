"""The sensitivities of a `BuildingTID`'s peak response: the elasticities of the highest
peak of a quantity over the band in every physical parameter, the TID's, the load's and
every floor's mass and storey's stiffness, exact (implicit derivatives of the periodic
orbit at the peak, `_building_design.peak_derivatives`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._model._building import BuildingTID, Quantity, log_tuned
from .._model._checks import check_grid
from .._orbit._building_orbit import building_settings
from .._orbit._settings import SolverSettings
from .._runtime._outcomes import Outcome, outcome_code, outcome_messages
from ._building_design import (
    at_band_edge,
    frictionless,
    no_start,
    peak_derivatives,
    peak_over_frequency,
    retune_building,
    search_grid,
)

# The TID's and the load's parameters, in the order of the elasticities (a compliant
# device's series stiffness and backlash come before the amplitude; the floors' masses
# and the storeys' stiffnesses follow, floor 1 first).
DEVICE_PARAMETERS = ("tid_stiffness", "tid_damping", "inertance", "friction_force",
                     "parasitic_damping", "terminal_mass", "amplitude")
COMPLIANT_PARAMETERS = ("series_stiffness", "backlash")
# the optimum's second derivatives: central differences of the exact first derivatives
# over this step in log k and log c
_STEP = 2e-3
_ACTIVE = 1e-4  # two candidate log peaks this close at the optimum are both active


def device_parameters(system: BuildingTID) -> tuple[str, ...]:
    """The TID's and the load's parameters of `system`, in the elasticities' order."""
    extra = COMPLIANT_PARAMETERS if system.compliant else ()
    return DEVICE_PARAMETERS[:-1] + extra + DEVICE_PARAMETERS[-1:]


def parameter_names(system: BuildingTID) -> tuple[str, ...]:
    """The names of the elasticities: `device_parameters`, then `floor_mass_1..n` and
    `storey_stiffness_1..n`."""
    floors = system.floors
    return (device_parameters(system) + tuple(f"floor_mass_{i}" for i in range(1, floors + 1))
            + tuple(f"storey_stiffness_{i}" for i in range(1, floors + 1)))


def storey_stiffnesses(stiffness_matrix) -> Array:
    """The storeys' stiffnesses of a structure (N/m): `-K[s, s - 1]` for the storey below
    floor s > 1, and the row sum `K[0, 0] + K[0, 1]` for the first; a shear building's
    own."""
    n = stiffness_matrix.shape[0]
    above = jnp.diagonal(stiffness_matrix, 1)
    first = stiffness_matrix[0].sum() if n > 1 else stiffness_matrix[0, 0]
    return jnp.concatenate([jnp.atleast_1d(first), -above])


def storey_springs(floors: int) -> np.ndarray:
    """`(d_s d_s^T)` for each storey s: the stiffness matrix of a unit spring from floor
    s - 1 to floor s (floor 0, the ground, fixed)."""
    springs = np.zeros((floors, floors, floors))
    for s in range(floors):
        springs[s, s, s] = 1.0
        if s:
            springs[s, s - 1, s - 1] = 1.0
            springs[s, s, s - 1] = springs[s, s - 1, s] = -1.0
    return springs


def _changed(system: BuildingTID, amplitude, theta):
    """The system and amplitude with every parameter p scaled by exp(theta_p); the
    floors' masses and storeys' stiffnesses changed by adding masses and storey springs
    (the damping matrix held)."""
    n = system.floors
    names = device_parameters(system)[:-1]
    scale = jnp.exp(theta)
    load = len(names)  # the amplitude's index; the floors' follow
    s = system.structure
    masses = jnp.diagonal(s.mass_matrix) * (scale[load + 1:load + 1 + n] - 1)
    springs = storey_stiffnesses(s.stiffness_matrix) * (scale[load + 1 + n:] - 1)
    structure = eqx.tree_at(
        lambda x: (x.mass_matrix, x.stiffness_matrix), s,
        (s.mass_matrix + jnp.diag(masses),
         s.stiffness_matrix + jnp.tensordot(springs, jnp.asarray(storey_springs(n)), 1)))
    changed = eqx.tree_at(
        lambda x: tuple(getattr(x, name) for name in names) + (x.structure,), system,
        tuple(getattr(system, name) * scale[i] for i, name in enumerate(names))
        + (structure,))
    return changed, amplitude * scale[load]


@eqx.filter_jit
def _candidates(system, quantity, amplitude, omegas, start, settings, linear):
    """The band of `system` (`peak_over_frequency` from `start`) and its two candidate
    peaks' log derivatives (candidates x parameters), whether all were found."""
    band = peak_over_frequency(system, quantity, amplitude, omegas, settings, linear, start)
    count = len(parameter_names(system))
    derivatives = jax.vmap(lambda w, z: peak_derivatives(
        system, quantity, amplitude, w, z, settings, linear,
        lambda theta: _changed(system, amplitude, theta), count))(band.omegas, band.states)
    ok = band.peak.converged & jnp.all(jnp.isfinite(derivatives))
    return band, derivatives / band.values[:, None], ok


def _elasticities(system, quantity, amplitude, omegas, settings, linear):
    band, derivatives, ok = _candidates(system, quantity, amplitude, omegas,
                                        no_start(system, omegas.shape[0]), settings, linear)
    return band.peak, derivatives[jnp.argmax(band.values)], ok


def _optimum_row(system, quantity, amplitude, omegas, settings, linear, tuning):
    """At the retuned `tuning` (k*, c*): the optimal log peak's and log k*'s and log
    c*'s derivatives in every log parameter (3 x parameters), the peaks active there
    and whether every steady state was found. The optimum minimises the highest of the
    two candidate log peaks L_i: with one active, grad_u L = 0 (u = log k, log c); with
    two, L_1 = L_2 = t and l grad_u L_1 + (1 - l) grad_u L_2 = 0. Implicit
    differentiation of these conditions needs the second derivatives in u and the mixed
    ones: central differences (`_STEP`) of the exact first derivatives."""
    log_tuning = jnp.log(jnp.asarray(tuning, float))
    evaluate = lambda design, start: _candidates(log_tuned(system, design), quantity, amplitude,
                                                 omegas, start, settings, linear)
    band, gradients, ok = evaluate(log_tuning, no_start(system, omegas.shape[0]))
    start = (band.grid_states, band.grid_monodromies)
    differences = []
    for j in range(2):
        shifted = [evaluate(log_tuning + sign * _STEP * jnp.eye(2)[j], start)
                   for sign in (1.0, -1.0)]
        ok = ok & shifted[0][2] & shifted[1][2]
        differences.append((shifted[0][1] - shifted[1][1]) / (2 * _STEP))
    second = np.stack([np.asarray(d) for d in differences], axis=1)  # candidate, j, param
    g = np.asarray(gradients)  # candidate x parameters; the first two: u
    logs = np.log(np.asarray(band.values))
    hessians = 0.5 * (second[:, :, :2] + np.swapaxes(second[:, :, :2], 1, 2))
    mixed = second[:, :, 2:]  # candidate, j, other parameters
    top = int(np.argmax(logs))
    slope = g[0, :2] - g[1, :2]
    share = -g[1, :2] @ slope / max(float(slope @ slope), 1e-300)  # l of the first peak
    both = (abs(logs[0] - logs[1]) < _ACTIVE and 0 < share < 1
            and float(np.asarray(band.omegas[0] - band.omegas[1])) != 0)
    rows = np.zeros((3, g.shape[1]))
    if both:
        weights = np.array([share, 1 - share])
        # unknowns (u0, u1, t, l); rows: stationarity (2), L_1 = t, L_2 = t
        matrix = np.zeros((4, 4))
        matrix[:2, :2] = np.tensordot(weights, hessians, 1)
        matrix[:2, 3] = slope
        matrix[2:, :2] = g[:, :2]
        matrix[2:, 2] = -1.0
        right = np.concatenate([np.tensordot(weights, mixed, 1), g[:, 2:]])
        solution = -np.linalg.solve(matrix, right)
        rows[0, 2:], rows[1:, 2:] = solution[2], solution[:2]
    else:
        rows[0, 2:] = g[top, 2:]
        rows[1:, 2:] = -np.linalg.solve(hessians[top], mixed[top])
    return rows, 2 if both else 1, bool(ok) and bool(np.all(np.isfinite(rows)))


class BuildingOptimum(eqx.Module):
    """How the retuned optimum (`retune_building`) moves with each parameter, per
    amplitude (SI): the optimum `tid_stiffness` k*, `tid_damping` c* and `peak`, and
    the elasticities (amplitudes x parameters, as `BuildingSensitivities.names`) of the
    optimal peak (`peak_elasticities`: by the envelope theorem, the active peaks'
    partial derivatives weighted by their multipliers) and of k* and c*
    (`stiffness_elasticities`, `damping_elasticities`: by implicit differentiation of
    the optimum's conditions); the entries of k and c are 0, as the optimum does not
    depend on the tuning it starts from. `active`: the peaks active at the optimum (1 or
    2); `converged`: the retune converged (its `status` ok) and every steady state was
    found."""

    tid_stiffness: Float[Array, " amps"]
    tid_damping: Float[Array, " amps"]
    peak: Float[Array, " amps"]
    peak_elasticities: Float[Array, "amps parameters"]
    stiffness_elasticities: Float[Array, "amps parameters"]
    damping_elasticities: Float[Array, "amps parameters"]
    active: Int[Array, " amps"]
    converged: Bool[Array, " amps"]


class BuildingSensitivities(eqx.Module):
    """Per amplitude (SI): the highest `peak` of the quantity over the band, its
    frequency `omega_peak` (rad/s), and `elasticities` (amplitudes x parameters): the
    relative change of the peak per relative change of each parameter of `names`
    (`parameter_names`: the TID's k, c, b, ff, cp, mt, a compliant device's series
    stiffness and backlash, the amplitude, every floor's mass and every storey's
    stiffness, the damping matrix held); `optimum`, at the retuned optimum (None unless
    asked for). `status`, codes of `Outcome` read by `status_messages()`:
    `steady_states_failed` where a steady state was not found (the values NaN),
    `peak_at_band_edge` where the peak is at an end of the band, else `ok`; `converged`
    is `status == ok`."""

    amplitudes: Float[Array, " amps"]
    names: tuple[str, ...] = eqx.field(static=True)
    peak: Float[Array, " amps"]
    omega_peak: Float[Array, " amps"]
    elasticities: Float[Array, "amps parameters"]
    converged: Bool[Array, " amps"]
    status: Int[Array, " amps"]
    optimum: BuildingOptimum | None = None

    def status_messages(self) -> list[str]:
        """The meaning of `status`, one message per amplitude (`Outcome`'s)."""
        return outcome_messages(self.status)


def _keep(ok, values):
    values = np.asarray(values, float)
    return np.where(ok.reshape((-1,) + (1,) * (values.ndim - 1)), values, np.nan)


def building_sensitivities(system: BuildingTID, amplitudes, quantity: Quantity | None = None,
                           *, omegas=None, settings: SolverSettings | None = None,
                           optimum: bool = False) -> BuildingSensitivities:
    """The elasticities of the peak of `quantity` (default: the top floor's displacement)
    over the band of `omegas` (default `first_mode_band`; at least `BAND_POINTS`
    frequencies) at each of `amplitudes`, with the system's own tuning, in every
    parameter of `parameter_names`. A parameter that is zero has elasticity zero. With
    `optimum`, also those of the retuned optimum (`BuildingOptimum`)."""
    quantity = Quantity() if quantity is None else quantity
    amplitudes = np.atleast_1d(check_grid("amplitudes", amplitudes)).astype(float)
    omegas = jnp.asarray(search_grid(system, omegas))
    quantity.floor_of(system.floors)
    settings = building_settings(system, settings)
    linear = frictionless(system)
    rows = [_elasticities(system, quantity, jnp.asarray(a), omegas, settings, linear)
            for a in amplitudes]
    ok = np.asarray([bool(row[2]) for row in rows])
    omega_peak = _keep(ok, [float(row[0].omega) for row in rows])
    status = np.where(ok, np.where(at_band_edge(omega_peak, omegas),
                                   outcome_code(Outcome.peak_at_band_edge),
                                   outcome_code(Outcome.ok)),
                      outcome_code(Outcome.steady_states_failed))
    return BuildingSensitivities(
        amplitudes=amplitudes, names=parameter_names(system),
        peak=_keep(ok, [float(row[0].value) for row in rows]), omega_peak=omega_peak,
        elasticities=_keep(ok, jax.device_get([row[1] for row in rows])),
        converged=status == outcome_code(Outcome.ok), status=status,
        optimum=(_optimum(system, quantity, amplitudes, omegas, settings, linear)
                 if optimum else None))


def _optimum(system, quantity, amplitudes, omegas, settings, linear) -> BuildingOptimum:
    retuned = retune_building(system, amplitudes, quantity, omegas=np.asarray(omegas),
                              settings=settings)
    rows = [_optimum_row(system, quantity, jnp.asarray(a), omegas, settings, linear,
                         (k, c))
            for a, k, c in zip(amplitudes, retuned.tid_stiffness, retuned.tid_damping,
                               strict=True)]
    ok = np.asarray([row[2] for row in rows]) & np.asarray(retuned.converged)
    derivatives = np.stack([row[0] for row in rows])  # amplitudes x 3 x parameters
    return BuildingOptimum(
        tid_stiffness=np.asarray(retuned.tid_stiffness),
        tid_damping=np.asarray(retuned.tid_damping), peak=_keep(ok, retuned.peak),
        peak_elasticities=_keep(ok, derivatives[:, 0]),
        stiffness_elasticities=_keep(ok, derivatives[:, 1]),
        damping_elasticities=_keep(ok, derivatives[:, 2]),
        active=np.asarray([row[1] for row in rows]), converged=ok)
