"""The sensitivities of a `BuildingTID`'s peak response: the elasticities of the highest
peak of a quantity over the band in every physical parameter, the TID's, the load's and
every floor's mass and storey's stiffness, exact (implicit derivatives of the periodic
orbit at the peak, `_building_design.peak_derivatives`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ._building import BuildingTID, Quantity
from ._building_design import (
    frictionless,
    no_start,
    peak_derivatives,
    peak_over_frequency,
    search_grid,
)
from ._building_orbit import building_settings
from ._checks import check_grid
from ._settings import SolverSettings

# The TID's and the load's parameters, in the order of the elasticities (a compliant
# device's series stiffness and backlash come before the amplitude; the floors' masses
# and the storeys' stiffnesses follow, floor 1 first).
DEVICE_PARAMETERS = ("tid_stiffness", "tid_damping", "inertance", "friction_force",
                     "parasitic_damping", "terminal_mass", "amplitude")
COMPLIANT_PARAMETERS = ("series_stiffness", "backlash")


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
def _elasticities(system, quantity, amplitude, omegas, settings, linear):
    band = peak_over_frequency(system, quantity, amplitude, omegas, settings, linear,
                               no_start(system, omegas.shape[0]))
    top = jnp.argmax(band.values)
    count = len(parameter_names(system))
    derivatives = peak_derivatives(system, quantity, amplitude, band.omegas[top],
                                   band.states[top], settings, linear,
                                   lambda theta: _changed(system, amplitude, theta), count)
    ok = band.peak.converged & jnp.all(jnp.isfinite(derivatives))
    return band.peak, derivatives / band.values[top], ok


class BuildingSensitivities(eqx.Module):
    """Per amplitude (SI): the highest `peak` of the quantity over the band, its
    frequency `peak_omega` (rad/s), and `elasticities` (amplitudes x parameters): the
    relative change of the peak per relative change of each parameter of `names`
    (`parameter_names`: the TID's k, c, b, ff, cp, mt, a compliant device's series
    stiffness and backlash, the amplitude, every floor's mass and every storey's
    stiffness, the damping matrix held); `converged` False where a
    steady state was not found (its values NaN)."""

    amplitudes: Float[Array, " amps"]
    names: tuple[str, ...] = eqx.field(static=True)
    peak: Float[Array, " amps"]
    peak_omega: Float[Array, " amps"]
    elasticities: Float[Array, "amps parameters"]
    converged: Bool[Array, " amps"]


def building_sensitivities(system: BuildingTID, amplitudes, quantity: Quantity | None = None,
                           *, omegas=None, settings: SolverSettings | None = None
                           ) -> BuildingSensitivities:
    """The elasticities of the peak of `quantity` (default: the top floor's displacement)
    over the band of `omegas` (default `default_omegas`; at least `BAND_POINTS`
    frequencies) at each of `amplitudes`, with the system's own tuning, in every
    parameter of `parameter_names`. A parameter that is zero has elasticity zero."""
    quantity = Quantity() if quantity is None else quantity
    amplitudes = np.atleast_1d(check_grid("amplitudes", amplitudes)).astype(float)
    omegas = jnp.asarray(search_grid(system, omegas))
    quantity.floor_of(system.floors)
    settings = building_settings(system, settings)
    linear = frictionless(system)
    rows = [_elasticities(system, quantity, jnp.asarray(a), omegas, settings, linear)
            for a in amplitudes]
    ok = np.asarray([bool(row[2]) for row in rows])
    keep = lambda values: np.where(ok.reshape((-1,) + (1,) * (values.ndim - 1)), values,
                                   np.nan)
    return BuildingSensitivities(
        amplitudes=amplitudes, names=parameter_names(system),
        peak=keep(np.asarray([float(row[0].value) for row in rows])),
        peak_omega=keep(np.asarray([float(row[0].omega) for row in rows])),
        elasticities=keep(np.asarray(jax.device_get([row[1] for row in rows]))),
        converged=ok)
