"""The kernel of the design evaluations, compiled: in one scenario (forcing amplitude,
host frequency scale), a design's refined peaks over the band, and their exact
derivatives with respect to every physical parameter (forward mode, implicit
differentiation through the orbits); and the parameters they are taken with respect to,
with their units."""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._model._building import LOAD_UNITS, BuildingTID
from .._model._structure import storey_springs, storey_stiffnesses
from .._model._system import FIELD_NAMES, TIDSystem, compiler_options
from .._orbit._sampled_peaks import interpolated, located_peak, parabola_vertices
from .._peaks import sweep
from .._runtime._cache import compiled

# The parameters that sensitivities are taken with respect to: the physical fields of a
# `TIDSystem` in the steady-state model (not the numerical `friction_width`) and the
# forcing amplitude, last. A compliant device adds its series stiffness and backlash; a
# rigid one has neither to vary (see `parameters_of`). A `BuildingTID`'s host is its
# floors' masses, its storeys' stiffnesses and the scale of its damping matrix
# (`building_parameters`).
RIGID_PARAMETERS = FIELD_NAMES[:7] + ("parasitic_damping", "terminal_mass", "amplitude")
COMPLIANT_PARAMETERS = RIGID_PARAMETERS[:-1] + ("series_stiffness", "backlash", "amplitude")
DEVICE_PARAMETERS = ("inertance", "friction_force", "tid_stiffness", "tid_damping",
                     "parasitic_damping", "terminal_mass")
PARAMETER_UNITS = {
    "host_mass": "kg",
    "host_stiffness": "N/m",
    "host_damping": "N s/m",
    "inertance": "kg",
    "friction_force": "N",
    "tid_stiffness": "N/m",
    "tid_damping": "N s/m",
    "parasitic_damping": "N s/m",
    "terminal_mass": "kg",
    "series_stiffness": "N/m",
    "backlash": "m",
    "amplitude": "N",
}


def parameter_unit(name: str, system=None) -> str:
    """The SI unit of the parameter `name` (of `parameters_of`): a floor's mass in kg, a
    storey's stiffness in N/m, a building's ground acceleration amplitude in m/s2."""
    if name.startswith("floor_mass_"):
        return "kg"
    if name.startswith("storey_stiffness_"):
        return "N/m"
    if name == "damping_scale":
        return "1"
    if name == "amplitude" and isinstance(system, BuildingTID):
        return LOAD_UNITS[system.load]
    return PARAMETER_UNITS[name]


def building_parameters(system: BuildingTID) -> tuple[str, ...]:
    """The parameters of a building's sensitivities: the device's (a compliant one's series
    stiffness and backlash too), every floor's mass `floor_mass_1..n`, every storey's
    stiffness `storey_stiffness_1..n`, the factor `damping_scale` on the structure's
    damping matrix (1 as given: its elasticity is that of the structure's damping) and
    the amplitude, last."""
    floors = range(1, system.floors + 1)
    return (DEVICE_PARAMETERS + (("series_stiffness", "backlash") if system.compliant else ())
            + tuple(f"floor_mass_{i}" for i in floors)
            + tuple(f"storey_stiffness_{i}" for i in floors) + ("damping_scale", "amplitude"))


def parameters_of(system: TIDSystem | BuildingTID) -> tuple[str, ...]:
    """The parameters of `system`'s sensitivities, the amplitude last:
    `building_parameters` of a `BuildingTID`, `COMPLIANT_PARAMETERS` for a compliant
    device, else `RIGID_PARAMETERS`."""
    if isinstance(system, BuildingTID):
        return building_parameters(system)
    return COMPLIANT_PARAMETERS if system.compliant else RIGID_PARAMETERS


def parameter_values(system: TIDSystem | BuildingTID) -> np.ndarray:
    """The values of `parameters_of(system)` but the amplitude (SI)."""
    if isinstance(system, BuildingTID):
        s = system.structure
        return np.concatenate([
            [float(getattr(system, name)) for name in parameters_of(system)[:-2]
             if not name.startswith(("floor_mass_", "storey_stiffness_"))],
            np.diagonal(np.asarray(s.mass_matrix)),
            np.asarray(storey_stiffnesses(s.stiffness_matrix)), [1.0]])
    return np.array([float(getattr(system, name)) for name in parameters_of(system)[:-1]])


CHUNK = 3  # points per kernel call (one compiled shape for every use)
# The grid index of a located peak that is none (where the host's peaks are the grid's):
# beyond every candidate array, so that no grid candidate is left out for it.
NO_PEAK = np.iinfo(np.int32).max
# Grid candidates of each response per point whose derivatives are taken (`_point_curves`).
_TANGENT_CANDIDATES = 4


def _log_candidates(values, omegas, true):
    """Log of the parabola-refined value at every grid point of `values` over `omegas`,
    then of the true peaks `true = (index, peaks, valid)` (`_peaks.true_peaks`, in the
    order of their grid indices), and the candidates of the smooth worst case: the
    true peaks, and the other interior local maxima and band ends. The value at every
    sample where the samples are concave is the vertex of the parabola through it and its
    neighbours, clipped to between them (`_peaks.parabola_vertices`). A value of 0 (the
    stroke of a terminal stuck throughout) is no candidate. Between nearby
    designs, the same entry holds the same peak (the true peaks in the order of
    frequency, wherever the grid falls), so that differences of its gradient give its
    curvature."""
    index, peaks, valid = true
    vertex, _, is_peak = parabola_vertices(values, omegas)
    true_mask = jnp.ones(1, dtype=bool)
    grid_mask = jnp.concatenate([true_mask, is_peak, true_mask]).at[index].set(False)
    candidates = jnp.concatenate([values[:1], vertex, values[-1:], peaks])
    # A terminal stuck throughout (exact friction) has no stroke: 0, no candidate.
    moves = candidates != 0
    logs = jnp.log(jnp.where(moves, candidates, 1.0))
    return logs, jnp.concatenate([grid_mask, valid]) & moves


def changed_system(system, theta, scale):
    """`system` with the parameters `theta` (order `parameters_of(system)`, amplitude last
    and unused) and its host stiffness (a building's stiffness matrix) multiplied by
    `scale**2`; of a `batched` system, `theta` holds a row per parameter and `scale` an
    entry per point. A building's floors' masses and storeys' stiffnesses change by
    adding masses and storey springs (`storey_springs`), its damping matrix by its
    factor `damping_scale`."""
    names = parameters_of(system)[:-1]
    values = dict(zip(names, theta, strict=False))
    if not isinstance(system, BuildingTID):
        values["host_stiffness"] = values["host_stiffness"] * scale**2
        return eqx.tree_at(lambda s: [getattr(s, name) for name in values], system,
                           list(values.values()))
    n = system.floors
    device = [name for name in names
              if not name.startswith(("floor_mass_", "storey_", "damping_scale"))]
    floors = jnp.moveaxis(jnp.asarray(theta[len(device):len(device) + 2 * n]), 0, -1)
    s = system.structure
    damping = jnp.asarray(values["damping_scale"])[..., None, None] * s.damping_matrix
    masses = floors[..., :n] - jnp.diagonal(s.mass_matrix, axis1=-2, axis2=-1)
    springs = floors[..., n:] - storey_stiffnesses(s.stiffness_matrix)
    stiffness = s.stiffness_matrix + jnp.einsum("...s,sij->...ij", springs,
                                                storey_springs(n))
    structure = eqx.tree_at(
        lambda x: (x.mass_matrix, x.stiffness_matrix, x.damping_matrix), s,
        (s.mass_matrix + masses[..., None] * jnp.eye(n),
         stiffness * jnp.asarray(scale)[..., None, None] ** 2, damping))
    return eqx.tree_at(lambda x: [getattr(x, name) for name in device] + [x.structure],
                       system, [values[name] for name in device] + [structure])


def scaled_hosts(lanes, scales):
    """Batched systems `lanes` with each lane's host stiffness (a building's stiffness
    matrix) times its entry of `scales` squared: its host frequencies times the scale."""
    scales = np.asarray(scales, float)
    if isinstance(lanes, BuildingTID):
        return eqx.tree_at(lambda s: s.structure.stiffness_matrix, lanes,
                           lanes.structure.stiffness_matrix * scales[:, None, None] ** 2)
    return eqx.tree_at(lambda s: s.host_stiffness, lanes, lanes.host_stiffness * scales**2)


def _tangent_slots(values, omegas, located):
    """The grid indices of the samples behind the `_TANGENT_CANDIDATES` highest grid
    candidates of `values` over `omegas` (`_log_candidates`; no grid candidates at the
    grid indices `located` of the true peaks):
    the three samples around each (entry i is sample i: its parabola's; at a band end,
    the end's sample, once more, and its neighbour)."""
    true = (located, jnp.ones(located.shape, values.dtype), jnp.zeros(located.shape, bool))
    logs, mask = _log_candidates(values, omegas, true)
    grid = slice(0, values.size)
    _, entries = jax.lax.top_k(jnp.where(mask[grid], logs[grid], -jnp.inf), _TANGENT_CANDIDATES)
    return jnp.clip(entries[:, None] + jnp.arange(-1, 2), 0, values.size - 1).reshape(-1)


def _with_tangents(has_tangent, true):
    """Which candidate entries of `_log_candidates` have derivatives, from which samples
    do (`has_tangent`): an interior entry's three samples, a band end's one; every true
    peak (`true`, solved with its own derivatives)."""
    interior = has_tangent[:-2] & has_tangent[1:-1] & has_tangent[2:]
    return jnp.concatenate([has_tangent[:1], interior, has_tangent[-1:],
                            jnp.ones(true[0].shape, dtype=bool)])


class _PointOutputs(NamedTuple):
    """One point's outputs of `_point_curves` beside the log values it differentiates: log
    values of |x| and |y| (`_log_candidates`), their candidate masks, which entries carry
    derivatives, convergence of every entry, the grid's orbit states and the grid indices
    of the host's true peaks."""

    log_x: Array
    log_y: Array
    peak_x: Array
    peak_y: Array
    tangent_x: Array
    tangent_y: Array
    converged: Array
    states: Array
    located: Array


def _point_curves(system, quantity, theta, scale, omegas, settings, grid, located):
    """Log refined peaks of |x| (a building's `quantity`) and |y| (m) over `omegas`, with the true peaks of |x| where
    `located` holds them (see `_log_candidates`), for the parameters `theta` (order
    `parameters_of(system)`), with the host stiffness multiplied by `scale**2`, and which
    entries carry derivatives in `theta`. `grid = (xs, ys, converged, states)` is the
    response over `omegas` at `theta` (without derivatives) and `located = (index,
    estimate, centre, valid)` its host peaks (`_band.locate_peaks`; where they are the
    grid's, `REFINED_PEAKS` entries that are no peaks: index `NO_PEAK`, not valid). The
    orbits are solved again with derivatives (shot from the grid's orbits) at the samples
    of each response's `_TANGENT_CANDIDATES` highest grid candidates only
    (`_tangent_slots`), and at the true peaks' frequencies, all in one sweep: the
    forward-mode derivatives are most of the cost of a solve, and each traced sweep of its
    compilation. Lower grid candidates are no candidates here; in a smooth maximum, each
    weighs less than any of those kept."""
    xs, ys, converged, states = grid
    # The peaks in the order of their grid indices: between nearby designs, the same entry
    # holds the same peak.
    index, estimate, centre, valid = (a[jnp.argsort(located[0])] for a in located)
    none = (jnp.zeros(0, int), jnp.zeros(0, ys.dtype), jnp.zeros(0, bool))
    slots = jnp.concatenate([_tangent_slots(xs, omegas, index),
                             _tangent_slots(ys, omegas, none[0])])
    # With derivatives, in one sweep: the samples of those candidates, and the true peaks
    # (the response at each located frequency, shot from the grid's orbits).
    xs_at, ys_at, ok_at, _ = sweep(
        changed_system(system, theta, scale), theta[-1],
        jnp.concatenate([omegas[slots], centre]), settings,
        jnp.concatenate([states[slots], interpolated(states, omegas, centre)]), quantity)
    n = slots.size
    true_x = (index, located_peak(estimate, jnp.where(ok_at[n:], xs_at[n:], jnp.nan)), valid)
    xs_at, ys_at, ok_at = xs_at[:n], ys_at[:n], ok_at[:n]
    xs, ys = xs.at[slots].set(xs_at), ys.at[slots].set(ys_at)
    converged = converged.at[slots].set(converged[slots] & ok_at)
    has_tangent = jnp.zeros(omegas.shape, dtype=bool).at[slots].set(True)
    tangent_x, tangent_y = _with_tangents(has_tangent, true_x), _with_tangents(has_tangent, none)
    converged = jnp.concatenate([converged, jnp.isfinite(true_x[1]) | ~true_x[2]])
    log_x, peak_x = _log_candidates(xs, omegas, true_x)
    log_y, peak_y = _log_candidates(ys, omegas, none)
    return (log_x, log_y), _PointOutputs(log_x, log_y, peak_x & tangent_x, peak_y & tangent_y,
                                         tangent_x, tangent_y, converged, states, true_x[0])


def _kernel_arguments(system, quantity, thetas, scales, band, settings, grids, located):
    """The arguments of `_evaluate_points` for one chunk (a task of `evaluate_chunk`), as
    NumPy arrays: placed on the device by the call (`_cache.compiled`), with no program
    of their own."""
    return (system, quantity, np.asarray(thetas), np.asarray(scales), np.asarray(band),
            settings.with_array_tolerances(system), tuple(np.asarray(a) for a in grids),
            tuple(np.asarray(a) for a in located))


def evaluate_chunk(*task):
    """`_evaluate_points` on one chunk of points, NumPy arrays in and out: a task of
    `map_lanes`."""
    return jax.tree.map(np.asarray, _evaluate_points(*_kernel_arguments(*task)))


@compiled(options=compiler_options)
def _evaluate_points(system, quantity, thetas, scales, band, settings, grids, located):
    """`CHUNK` points, one after another, from their responses over the band `grids`
    and their located host peaks `located` (see `_point_curves`): for each, the log
    refined peaks, candidate masks and their Jacobians with respect to `theta` (forward
    mode, implicit differentiation through the orbits). Each point's band is `band`
    times its host frequency scale.

    The points are mapped over (`jax.lax.map`), not batched: each point's solves stop
    when its own orbits converge rather than waiting for the other points', and tracing
    batches the solves' loops over a point's frequencies and derivative directions, not
    over the points too: the program traces and compiles in less time and runs faster on
    a CPU."""
    def one(point):
        theta, scale, grid, peaks = point
        omegas = band * scale

        def curves(t):
            return _point_curves(system, quantity, t, scale, omegas, settings, grid, peaks)

        return jax.jacfwd(curves, has_aux=True)(theta)

    return jax.lax.map(one, (thetas, scales, grids, located))
