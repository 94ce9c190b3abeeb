"""Designs judged over scenarios: the peaks of each scenario (forcing amplitude, host
frequency scale) at a few designs (k, c) and their derivatives, the smooth worst case
over scenarios, and the best tuning of each scenario (`best_tunings`) that the
sensitivities and the robust design are measured against."""

from collections.abc import Callable, Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from ._band import _band, locate_peaks, sweep
from ._cache import compiled
from ._checks import check_grid, check_steady_state_device, check_system
from ._design_variables import design_of_tuning, tuning_of_design
from ._linear import den_hartog_tuning
from ._parallel import map_shares, serial
from ._peaks import (
    REFINED_PEAKS,
    interpolated,
    lane_grid_peaks,
    located_peak,
    parabola_vertices,
    smooth_log_peak,
)
from ._response import batched, lane_response, scaled_states
from ._retune import RETUNE_OUTCOMES, RetuneSettings, check_retune_options, optimal_tunings
from ._settings import SolverSettings
from ._system import FIELD_NAMES, TIDSystem, compiler_options

# The parameters that sensitivities are taken with respect to: the physical fields of a
# `TIDSystem` in the steady-state model (not the numerical `friction_width`) and the
# forcing amplitude, last. A compliant device adds its series stiffness and backlash; a
# rigid one has neither to vary (see `parameters_of`).
RIGID_PARAMETERS = FIELD_NAMES[:7] + ("parasitic_damping", "terminal_mass", "amplitude")
COMPLIANT_PARAMETERS = RIGID_PARAMETERS[:-1] + ("series_stiffness", "backlash", "amplitude")
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
_K, _C = RIGID_PARAMETERS.index("tid_stiffness"), RIGID_PARAMETERS.index("tid_damping")


def parameters_of(system: TIDSystem) -> tuple[str, ...]:
    """The parameters of `system`'s sensitivities: `COMPLIANT_PARAMETERS` for a compliant
    device, else `RIGID_PARAMETERS`."""
    return COMPLIANT_PARAMETERS if system.compliant else RIGID_PARAMETERS


# Design-variable step of the differences of exact gradients that give the curvature of
# each refined peak (forward while optimising, central for the final derivatives; the
# curvature of the smooth maximum across peaks is exact). Smaller steps amplify the noise
# of the orbit solver in the gradients, larger ones the truncation error.
STENCIL_STEP = 1e-3
UNSCALED = (1.0, 1.0)  # the design variables' scales here: unscaled
_CHUNK = 3  # points per kernel call (one compiled shape for every use)
# The grid index of a located peak that is none (where the host's peaks are the grid's):
# beyond every candidate array, so that no grid candidate is left out for it.
_NO_PEAK = np.iinfo(np.int32).max
# Grid candidates of each response per point whose derivatives are taken (`_point_curves`).
_TANGENT_CANDIDATES = 4
MAX_STEP = 0.25  # largest optimiser step in u (about 28% in k)

# The optimiser aims at a Newton decrement below `tol`; the noise of the orbit solver in the
# gradients, and jumps of ~1e-8 in the log peak where a sample's concavity flips, can hold
# it above that (most where peaks of different amplitudes balance). Within
# NOISE_FACTOR * tol (1e-6 of the log peak by default) the optimum counts as converged.
NOISE_FACTOR = 1000.0

# Sharpness of the smooth log peak over a scenario's band (`BestTunings.objective`), the
# reference of the robust design's ratios: that of its last stage by default
# (`RobustSettings.sharpness`).
OBJECTIVE_SHARPNESS = 1000.0

# --- the kernel: refined peaks and their derivatives at a few designs ---------------------


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


def _changed_system(system, theta, scale):
    """`system` with the parameters `theta` (order `parameters_of(system)`, amplitude last
    and unused) and its host stiffness multiplied by `scale**2`; of a `batched` system,
    `theta` holds a row per parameter and `scale` an entry per point."""
    values = dict(zip(parameters_of(system)[:-1], theta, strict=False))
    values["host_stiffness"] = values["host_stiffness"] * scale**2
    return eqx.tree_at(lambda s: [getattr(s, name) for name in values], system,
                       list(values.values()))


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


def _point_curves(system, theta, scale, omegas, settings, grid, located):
    """Log refined peaks of |x| and |y| (m) over `omegas`, with the true peaks of |x| where
    `located` holds them (see `_log_candidates`), for the parameters `theta` (order
    `parameters_of(system)`), with the host stiffness multiplied by `scale**2`, and which
    entries carry derivatives in `theta`. `grid = (xs, ys, converged, states)` is the
    response over `omegas` at `theta` (without derivatives) and `located = (index,
    estimate, centre, valid)` its host peaks (`_band.locate_peaks`; where they are the
    grid's, `REFINED_PEAKS` entries that are no peaks: index `_NO_PEAK`, not valid). The
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
        _changed_system(system, theta, scale), theta[-1],
        jnp.concatenate([omegas[slots], centre]), settings,
        jnp.concatenate([states[slots], interpolated(states, omegas, centre)]))
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


def _kernel_arguments(system, thetas, scales, ratio_grid, settings, grids, located):
    """The arguments of `_evaluate_points` for one chunk (a task of `_evaluate_chunk`), as
    NumPy arrays: placed on the device by the call (`_cache.compiled`), with no program
    of their own."""
    return (system, np.asarray(thetas), np.asarray(scales), np.asarray(ratio_grid),
            settings.with_array_tolerances(system), tuple(np.asarray(a) for a in grids),
            tuple(np.asarray(a) for a in located))


def _evaluate_chunk(*task):
    """`_evaluate_points` on one chunk of points, NumPy arrays in and out: a task of
    `map_lanes`."""
    return jax.tree.map(np.asarray, _evaluate_points(*_kernel_arguments(*task)))


@compiled(options=compiler_options)
def _evaluate_points(system, thetas, scales, ratio_grid, settings, grids, located):
    """`_CHUNK` points, one after another, from their responses over the band `grids`
    and their located host peaks `located` (see `_point_curves`): for each, the log
    refined peaks, candidate masks and their Jacobians with respect to `theta` (forward
    mode, implicit differentiation through the orbits). Each point's band is
    `ratio_grid` times its host frequency.

    The points are mapped over (`jax.lax.map`), not batched: each point's solves stop
    when its own orbits converge rather than waiting for the other points', and tracing
    batches the solves' loops over a point's frequencies and derivative directions, not
    over the points too: the program traces and compiles in less time and runs faster on
    a CPU."""
    host_frequency = jax.lax.stop_gradient(system.host_frequency)

    def one(point):
        theta, scale, grid, peaks = point
        omegas = ratio_grid * host_frequency * scale

        def curves(t):
            return _point_curves(system, t, scale, omegas, settings, grid, peaks)

        return jax.jacfwd(curves, has_aux=True)(theta)

    return jax.lax.map(one, (thetas, scales, grids, located))


# --- host side: points, stencils, the smooth worst case and its derivatives ----------------


class _Curves(NamedTuple):
    """One design point (numpy): log refined values (ln m) of |x| and |y| per frequency
    (then the true peaks of |x|, if located), their candidate masks (`_log_candidates`,
    the highest with derivatives: `_point_curves`), Jacobians `[entries, parameters]`
    (NaN rows where none were taken), convergence of every orbit, the orbits' states and
    the grid indices of the true peaks."""

    log_x: np.ndarray
    log_y: np.ndarray
    peak_x: np.ndarray
    peak_y: np.ndarray
    jac_x: np.ndarray
    jac_y: np.ndarray
    converged: bool
    states: np.ndarray
    located: np.ndarray

    def top(self, response: str) -> tuple[float, np.ndarray]:
        """Log of the grid peak of `response` ("x" or "y"), as `_peaks.grid_peak` finds it,
        and its gradient (over `Context.parameters`)."""
        values = np.where(
            getattr(self, f"peak_{response}"), getattr(self, f"log_{response}"), -np.inf
        )
        i = int(np.argmax(values))
        return float(values[i]), getattr(self, f"jac_{response}")[i]

    def host_peak(self) -> float:
        return float(np.exp(self.top("x")[0]))

    def stroke_peak(self) -> float:
        return float(np.exp(self.top("y")[0]))


class Context:
    """What every evaluation shares: the system, the band as multiples of the host
    frequency, the solver settings, whether the host's peaks are located in continuous
    frequency (`locate`: as `retune` does, for the sensitivities of its optimum; else
    the grid's, refined by parabolas) and the reference tuning of the design variables
    u = (ln(k / k_ref), sqrt(c / c_ref)) (`_retune.design_of_tuning`, unscaled), and how
    independent lanes are mapped (`map_lanes`, see `_parallel`)."""

    def __init__(self, system: TIDSystem, omegas, settings: SolverSettings, *, locate: bool,
                 map_lanes: Callable = serial):
        self.system = system
        self.map_lanes = map_lanes
        self.locate = locate
        self.settings = settings
        self.omegas = np.asarray(omegas, dtype=float)
        self.ratio_grid = jnp.asarray(self.omegas / float(system.host_frequency))
        self.parameters = parameters_of(system)
        self.values = np.array([float(getattr(system, name)) for name in self.parameters[:-1]])
        # Parameters other than the design (k, c), in the order of the optimiser's
        # coordinates (u0, u1, *other): u0 = ln(k / k_ref), u1 = sqrt(c / c_ref).
        self.other = [i for i in range(len(self.parameters)) if i not in (_K, _C)]
        k_ref, c_ref = den_hartog_tuning(system.host_mass, system.host_stiffness, system.inertance)
        self.k_ref, self.c_ref = float(k_ref), float(c_ref)

    def tuning(self, u) -> tuple[float, float]:
        k, c = tuning_of_design(np.asarray(u, dtype=float), self.k_ref, self.c_ref, UNSCALED,
                                np)
        return float(k), float(c)

    def design(self, k, c, *, floor=0.0) -> np.ndarray:
        c = max(c, floor * self.c_ref)
        return design_of_tuning(k, c, self.k_ref, self.c_ref, UNSCALED, np)

    def theta(self, k, c, amplitude) -> np.ndarray:
        theta = np.append(self.values, float(amplitude))
        theta[_K], theta[_C] = k, c
        return theta

    def evaluate(self, points: Sequence[tuple]) -> list[_Curves]:
        """`_Curves` at each `(theta, scale, z_init)` (z_init None at every point: the
        orbits solved from the linear steady state); points where a steady state did not
        converge are tried again with each of the fallbacks of the settings fitted to the
        system (`SolverSettings.fallbacks`) in turn."""
        results = self._evaluate(points, self.settings)
        for settings in self.settings.for_system(self.system).fallbacks():
            failed = [i for i, curves in enumerate(results) if not curves.converged]
            if not failed:
                break
            retried = self._evaluate([points[i] for i in failed], settings)
            for i, curves in zip(failed, retried, strict=True):
                if curves.converged:
                    results[i] = curves
        return results

    def _grids(self, points: Sequence[tuple], settings: SolverSettings) -> list["_Grid"]:
        """The `_Grid` of each `(theta, scale, z_init)` (`_solve_grids`; z_init None at
        every point: from the linear steady state), the points shared out over the
        processes of `map_lanes` (`_parallel.map_shares`)."""
        thetas, scales, z_inits = ([point[i] for point in points] for i in range(3))
        cold = all(z is None for z in z_inits)
        lanes = (np.stack(thetas), np.stack(scales)) + (() if cold else (np.stack(z_inits),))
        fields = map_shares(self.map_lanes, _solve_cold_grids if cold else _solve_grids,
                            lanes, self.system, self.omegas, settings, self.locate)
        return [_Grid(*(field[i] for field in fields)) for i in range(len(points))]

    def _tasks(self, points: Sequence[tuple], grids: Sequence["_Grid"],
               settings: SolverSettings):
        """The tasks of `_evaluate_chunk` for `points` (`(theta, scale, ...)`) and their
        `grids`, `_CHUNK` points each (the last padded with copies of its last point), and
        how many points each holds."""
        tasks, sizes, ratio_grid = [], [], np.asarray(self.ratio_grid)
        for start in range(0, len(points), _CHUNK):
            chunk = [(point[0], point[1], grid)
                     for point, grid in zip(points[start : start + _CHUNK],
                                            grids[start : start + _CHUNK], strict=True)]
            sizes.append(len(chunk))
            chunk += [chunk[-1]] * (_CHUNK - len(chunk))
            thetas, scales = (np.stack([point[i] for point in chunk]) for i in range(2))
            fields = [np.stack(field) for field in zip(*(point[2] for point in chunk),
                                                       strict=True)]
            tasks.append((self.system, thetas, np.asarray(scales, dtype=float), ratio_grid,
                          settings, tuple(fields[:4]), tuple(fields[4:])))
        return tasks, sizes

    def _evaluate(self, points: Sequence[tuple], settings: SolverSettings) -> list[_Curves]:
        """`_Curves` at each point with `settings`: the responses over the band of every
        point in one batch (`_grids`), then the derivatives `_CHUNK` points per compiled
        call, the calls mapped by `map_lanes`."""
        tasks, sizes = self._tasks(points, self._grids(points, settings), settings)
        results = []
        for used, ((jac_x, jac_y), out) in zip(
                sizes, self.map_lanes(_evaluate_chunk, tasks), strict=True):
            jac_x, jac_y = np.array(jac_x), np.array(jac_y)
            # Entries without derivatives (`_point_curves`) are no candidates: NaN rows.
            jac_x[~out.tangent_x], jac_y[~out.tangent_y] = np.nan, np.nan
            results += [
                _Curves(out.log_x[i], out.log_y[i], out.peak_x[i], out.peak_y[i], jac_x[i],
                        jac_y[i], bool(np.all(out.converged[i])), out.states[i], out.located[i])
                for i in range(used)
            ]
        return results

    def cold_states(self, k, c, amplitudes, scale) -> np.ndarray:
        """Scaled orbit states `[lanes, freqs, 4]`, one lane per amplitude: the tuning k
        (N/m), c (N s/m) at that amplitude (N) with the host frequency times `scale` (over
        the band times `scale`), each given once or once per lane; the lanes shared out
        over the processes of `map_lanes` (`_solve_cold_grids`, whose `lane_response`
        retries points that fail to converge)."""
        amplitudes = np.atleast_1d(np.asarray(amplitudes, dtype=float))
        k, c, scale = (np.broadcast_to(np.asarray(value, dtype=float), amplitudes.shape)
                       for value in (k, c, scale))
        thetas = np.stack([self.theta(k_i, c_i, amplitude)
                           for k_i, c_i, amplitude in zip(k, c, amplitudes, strict=True)])
        return map_shares(self.map_lanes, _solve_cold_grids, (thetas, np.asarray(scale)),
                          self.system, self.omegas, self.settings, False).states


class _Grid(NamedTuple):
    """One point's response over its band, without derivatives (NumPy; or several points',
    each field with a leading axis of points): peak |x| and |y| (m) and convergence per
    frequency, the orbits' scaled states, and its located host
    peaks (grid index, last Newton estimate, frequency, local maximum; where the peaks are
    the grid's, `REFINED_PEAKS` entries that are no peaks, see `_point_curves`)."""

    xs: np.ndarray
    ys: np.ndarray
    converged: np.ndarray
    states: np.ndarray
    index: np.ndarray
    estimate: np.ndarray
    centre: np.ndarray
    valid: np.ndarray


def _solve_grids(thetas, scales, z_init, system, omegas, settings, locate):
    """The `_Grid` of points (a leading axis of points) at the parameters `thetas` (a row
    per point, order `parameters_of(system)`) with the host stiffness multiplied by
    `scales**2`, over the band `omegas` times `scales`, each point shot from its scaled
    states `z_init` (None: from the equivalent linear steady state after a transient):
    every point in one batch (`lane_response`) and, where `locate`, the
    host's peaks located in continuous frequency (`locate_peaks`)."""
    lanes = _changed_system(batched(system, len(thetas)), thetas.T, scales)
    response = lane_response(lanes, thetas[:, -1], omegas * scales[:, None], settings, z_init)
    states = scaled_states(response, lanes.host_stiffness, np)
    xs, ys, converged = (np.asarray(a) for a in (response.x_max, response.y_max,
                                                 response.converged))
    if locate:
        found = locate_peaks(lanes, response, settings)
        located = (found.index.astype(int), found.estimate, found.centre, found.valid)
        converged = converged & found.converged[:, None]
    else:
        # No peaks: entries the kernel leaves out (one program for both kinds of points).
        shape = (len(thetas), REFINED_PEAKS)
        located = (np.full(shape, _NO_PEAK), np.full(shape, np.nan),
                   np.broadcast_to(omegas[0] * scales[:, None], shape), np.zeros(shape, bool))
    return _Grid(xs, ys, converged, states, *located)


def _solve_cold_grids(thetas, scales, system, omegas, settings, locate):
    """`_solve_grids` from the linear steady state (a task of `map_shares`)."""
    return _solve_grids(thetas, scales, None, system, omegas, settings, locate)


class Scenario(NamedTuple):
    amplitude: float  # N
    scale: float  # host frequency / nominal host frequency
    offset: float  # subtracted from the log host peak: ln of the best achievable peak, or 0


# The designs at which a design u is evaluated (`_stencil`): u and its forward or central
# neighbours in u0 and u1 (the curvatures of the refined peaks from differences of their
# gradients), or u alone (values and gradients only).
STENCILS = {
    "forward": [[1.0, 0.0], [0.0, 1.0]],
    "central": [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]],
    "centre": [],
}


def _stencil(u, kind: str) -> list[np.ndarray]:
    u = np.asarray(u, dtype=float)
    return [u] + [u + STENCIL_STEP * np.asarray(step) for step in STENCILS[kind]]


class Terms(NamedTuple):
    """A smooth maximum's terms (log peaks), whether each is a candidate, their gradients
    (u0, u1, parameters `Context.other`) and those gradients' derivatives along u0 and u1."""

    values: np.ndarray
    mask: np.ndarray
    grad: np.ndarray
    dgrad: np.ndarray


def coordinates(ctx: Context, u, stencil: list[_Curves], response: str) -> Terms:
    """Log peaks, their gradients in the coordinates (u0, u1, parameters `Context.other`) and
    the derivatives of those gradients along u0 and u1, for every frequency of one
    scenario, from the curves at the designs `_stencil(u, kind)` (central when there
    are five). Only the second derivatives of each refined peak come from differences;
    from u alone (one design) they are unknown: NaN."""
    k, _ = ctx.tuning(u)
    jac = [getattr(curves, f"jac_{response}") for curves in stencil]
    centre = jac[0]
    grad = np.concatenate(
        [k * centre[:, [_K]], 2 * ctx.c_ref * u[1] * centre[:, [_C]], centre[:, ctx.other]], axis=1
    )
    dgrad = np.full(grad.shape[:1] + (2,) + grad.shape[1:], np.nan)
    for i in range(2 if len(stencil) > 1 else 0):
        if len(stencil) == 5:
            d_jac = (jac[1 + 2 * i] - jac[2 + 2 * i]) / (2 * STENCIL_STEP)
        else:
            d_jac = (jac[1 + i] - centre) / STENCIL_STEP
        dgrad[:, i, 0] = k * d_jac[:, _K] + (k * centre[:, _K] if i == 0 else 0.0)
        dgrad[:, i, 1] = 2 * ctx.c_ref * (u[1] * d_jac[:, _C] + (centre[:, _C] if i == 1 else 0.0))
        dgrad[:, i, 2:] = d_jac[:, ctx.other]
    if len(stencil) > 1:
        # An entry whose derivatives a neighbour did not take (`_point_curves`): its
        # curvature is unknown.
        dgrad[np.isnan(dgrad) & np.isfinite(grad)[:, None, :]] = 0.0
        if response == "x" and ctx.locate:
            dgrad = without_jumped_peaks(dgrad, [curves.located for curves in stencil],
                                         stencil[0].located)
    curves = stencil[0]
    return Terms(getattr(curves, f"log_{response}"), getattr(curves, f"peak_{response}"), grad,
                 dgrad)


def without_jumped_peaks(dgrad, located, reference) -> np.ndarray:
    """`dgrad` (of host `Terms`) with the curvatures of the true peaks (its last rows, in
    the order of their grid indices `reference`) left out (0) where the grid indices of
    any design of `located` jumped from `reference` by more than one: a true peak's entry
    holds the same peak at nearby designs unless the set of highest local maxima changed
    between them, and then its curvature is unknown."""
    changed = np.any(np.abs(np.atleast_2d(located) - reference) > 1, axis=0)
    dgrad = dgrad.copy()
    dgrad[dgrad.shape[0] - changed.size:][changed] = 0.0
    return dgrad


def term_weights(candidates: Terms, sharpness):
    """The smooth maximum G = ln(sum exp(s T)) / s of the candidate terms T and each
    term's weight in it, exp(s (T - G)) (0 for a term that is no candidate; they sum to
    1): `(inf, None)` where no candidate is finite."""
    terms = np.where(candidates.mask, candidates.values, -np.inf)
    top = np.max(terms)
    if not np.isfinite(top):
        return np.inf, None
    weights = np.exp(sharpness * (terms - top))
    total = weights.sum()
    return top + np.log(total) / sharpness, weights / total


def smooth_max(candidates: Terms, sharpness):
    """Smooth maximum G = ln(sum exp(s T)) / s of the candidate terms T, its gradient in
    all coordinates and its derivatives along u0, u1 (rows) in all coordinates: the exact
    curvature of the log-sum-exp plus the weighted curvatures of the terms."""
    _, mask, grad, dgrad = candidates
    value, weights = term_weights(candidates, sharpness)
    if weights is None:
        return value, None, None
    grad = np.where(mask[:, None], grad, 0.0)
    dgrad = np.where(mask[:, None, None], dgrad, 0.0)
    g = weights @ grad
    hess = sharpness * (np.einsum("n,ni,nj->ij", weights, grad[:, :2], grad) - np.outer(g[:2], g))
    hess += np.einsum("n,nij->ij", weights, dgrad)
    return value, g, hess


class Evaluation(NamedTuple):
    u: np.ndarray
    stencils: list  # per scenario, the curves at `_stencil(u, kind)`
    host_terms: Terms  # all scenarios' terms concatenated
    stroke_terms: Terms

    def centres(self) -> list[_Curves]:
        return [stencil[0] for stencil in self.stencils]

    def states(self) -> list:
        """Per scenario, the orbits' states at the design itself: where the next
        design's shooting starts."""
        return [curves.states for curves in self.centres()]

    def converged(self) -> bool:
        return all(curves.converged for curves in self.centres())


def evaluate_designs(ctx, designs, *, stencil="forward") -> list[Evaluation]:
    """An `Evaluation` at each of `designs`, `(u, scenarios, z_inits)`: the curves at the
    design u and its `stencil` (a kind of `STENCILS`, or one kind per scenario) for every
    scenario (shooting from `z_inits`, one state array per scenario) and the terms of the
    smooth maxima (`evaluation_of`). Every point of every design is solved in one
    batch."""
    points, stencils = [], []
    for u, scenarios, z_inits in designs:
        kinds = [stencil] * len(scenarios) if isinstance(stencil, str) else stencil
        us = [_stencil(u, kind) for kind in kinds]
        stencils.append(us)
        for scenario, z, vs in zip(scenarios, z_inits, us, strict=True):
            points += [(ctx.theta(*ctx.tuning(v), scenario.amplitude), scenario.scale, z)
                       for v in vs]
    curves = iter(ctx.evaluate(points))
    return [evaluation_of(ctx, u, scenarios, [[next(curves) for _ in vs] for vs in us])
            for (u, scenarios, _), us in zip(designs, stencils, strict=True)]


def evaluation_of(ctx, u, scenarios, stencils) -> Evaluation:
    """The `Evaluation` at the design u from the curves of each scenario at `_stencil(u,
    kind)` (`stencils`, one list per scenario): each scenario's log host peaks less its
    offset, and its log inerter peaks, with their derivatives (`coordinates`)."""

    def join(parts):
        return Terms(*(np.concatenate(field) for field in zip(*parts, strict=True)))

    host, stroke = [], []
    for scenario, stencil in zip(scenarios, stencils, strict=True):
        terms = coordinates(ctx, u, stencil, "x")
        host.append(terms._replace(values=terms.values - scenario.offset))
        stroke.append(coordinates(ctx, u, stencil, "y"))
    return Evaluation(u, stencils, join(host), join(stroke))


def evaluate_design(ctx, u, scenarios, z_inits, *, stencil="forward") -> Evaluation:
    """The `Evaluation` at the one design u (see `evaluate_designs`)."""
    return evaluate_designs(ctx, [(u, scenarios, z_inits)], stencil=stencil)[0]


def cold_start(ctx: Context, u, scenarios) -> list[np.ndarray]:
    """Orbit states at the design u for every scenario, all in one batch."""
    amplitudes, scales = ([getattr(scenario, name) for scenario in scenarios]
                          for name in ("amplitude", "scale"))
    return list(ctx.cold_states(*ctx.tuning(u), amplitudes, scales))



# --- checks of user input ------------------------------------------------------------------


def check_amplitude(amplitude) -> float:
    if isinstance(amplitude, jax.core.Tracer):
        raise ValueError("amplitude must be concrete (not traced)")
    array = check_grid("amplitude", amplitude)
    if array.ndim != 0:
        raise ValueError(f"amplitude must be a scalar, got shape {array.shape}")
    return float(array)


def check_distinct(name: str, values) -> np.ndarray:
    """A 1-d grid of distinct, finite, positive values, else `ValueError` naming `name`."""
    array = np.atleast_1d(check_grid(name, values))
    if np.unique(array).size != array.size:
        raise ValueError(f"{name} must be distinct, got {array.tolist()}")
    return array


# --- the best tuning per scenario, any tuning against it, the robust tuning ---------------


class BestTunings(eqx.Module):
    """For each host-frequency scale and forcing amplitude, the retuned optimum: the tuning
    that `retune` finds (the minimiser of the smooth maximum over the band of the host
    displacement), and the peaks it achieves. Arrays are `[scales, amps]`; SI.

    - `system`: the nominal system; a scale s multiplies its host stiffness by s**2 (host
      frequency by s) and its band `omegas` (rad/s) by s.
    - `tid_stiffness` (N/m), `tid_damping` (N s/m): the best tuning.
    - `host_peak`: peak |x| over the band's grid with it (refined by a parabola, as the
      robust design judges peaks), m; `stroke_peak`: peak |y|, m, on the check grid of
      `retune` (`RetuneSettings.check_refinement` times finer than the band).
    - `objective`: the smooth log peak over the band's grid (`smooth_log_peak`, sharpness
      `OBJECTIVE_SHARPNESS`, ln m), the reference of the worst-case ratio of
      `robust_tune`.
    - `iterations`: optimiser iterations; `stationary`: the optimiser converged;
      `converged`: `retune`'s status is ok (stationary, every steady state converged, the
      peak inside the band and no higher than the starting tuning's on the check grid);
      `damping_at_bound`: c = 0 is optimal.
    """

    system: TIDSystem
    omegas: Float[Array, " freqs"]
    amplitudes: Float[Array, " amps"]
    host_frequency_scales: Float[Array, " scales"]
    tid_stiffness: Float[Array, "scales amps"]
    tid_damping: Float[Array, "scales amps"]
    host_peak: Float[Array, "scales amps"]
    stroke_peak: Float[Array, "scales amps"]
    objective: Float[Array, "scales amps"]
    iterations: Int[Array, "scales amps"]
    stationary: Bool[Array, "scales amps"]
    converged: Bool[Array, "scales amps"]
    damping_at_bound: Bool[Array, "scales amps"]


def _scaled_lanes(system: TIDSystem, scales) -> TIDSystem:
    """One system per scale s (batched fields): host stiffness times s**2 and, keeping the
    TID's frequency ratio and damping ratio (Den Hartog's k scales with K and c with
    sqrt(k b)), TID stiffness times s**2 and damping times s."""
    scales = np.asarray(scales, float)
    lanes = batched(system, scales.size)
    return eqx.tree_at(
        lambda s: (s.host_stiffness, s.tid_stiffness, s.tid_damping),
        lanes,
        (lanes.host_stiffness * scales**2, lanes.tid_stiffness * scales**2,
         lanes.tid_damping * scales),
    )


@jax.jit
def _smooth_objective(values, omegas):
    """`BestTunings.objective` from the host peaks `values` (m, lanes x frequencies)."""
    return jax.vmap(lambda v, w: smooth_log_peak(v, w, OBJECTIVE_SHARPNESS))(values, omegas)


def best_tunings(
    system: TIDSystem,
    amplitudes: ArrayLike,
    *,
    host_frequency_scales: ArrayLike = (1.0,),
    omegas: ArrayLike | None = None,
    settings: SolverSettings = SolverSettings(),
    max_steps: int = 60,
    tol: float = 1e-4,
    retune_settings: RetuneSettings = RetuneSettings(),
    progress: Callable[[str], None] | None = None,
    map_lanes: Callable = serial,
) -> BestTunings:
    """The best achievable peak host displacement for each scenario (forcing amplitude and
    host frequency scale) over the band scaled with the host frequency. Every scenario
    is retuned by `retune`'s optimiser, all of them in one batch, from the system's tuning
    (k times scale**2, c times scale).

    **Arguments:**

    - `system`: the nominal `TIDSystem` (rigid device).
    - `amplitudes`: forcing amplitudes, N.
    - `host_frequency_scales`: host frequency scales s (the host stiffness times s**2).
    - `omegas`: the band for the nominal system, rad/s (default `default_omegas(system)`).
    - `settings`: `SolverSettings` of every steady state.
    - `max_steps`, `tol`, `retune_settings`: the optimiser's, as in `retune`.
    - `progress`: if given, called with a line as each step of the retune ends.
    - `map_lanes`: how the independent scenarios are mapped (see `retune`).

    **Returns:** a `BestTunings` (arrays `[scales, amps]`).
    """
    check_system(system)
    check_steady_state_device(system, "best_tunings")
    amps = check_distinct("amplitudes", amplitudes)
    scales = check_distinct("host_frequency_scales", host_frequency_scales)
    band = _band(system, omegas)
    check_retune_options(max_steps, tol, retune_settings)
    lane_scales, lane_amps = (g.reshape(-1) for g in np.meshgrid(scales, amps, indexing="ij"))
    bands = jnp.asarray(lane_scales[:, None] * np.asarray(band)[None])
    result = optimal_tunings(
        _scaled_lanes(system, lane_scales), jnp.asarray(lane_amps), bands, settings=settings,
        max_steps=max_steps, tol=tol, retune_settings=retune_settings, progress=progress,
        map_lanes=map_lanes,
    )
    # The robust design's reference: the peaks on the band's grid (see `robust_tune`),
    # which the check grid holds at every `check_refinement`-th point.
    on_band = np.asarray(result.x_response)[:, ::retune_settings.check_refinement]
    band_peaks = lane_grid_peaks(on_band, bands)[0]
    shape = (scales.size, amps.size)
    grid = lambda a: jnp.asarray(np.asarray(a).reshape(shape))
    return BestTunings(
        system=system,
        omegas=band,
        amplitudes=jnp.asarray(amps),
        host_frequency_scales=jnp.asarray(scales),
        tid_stiffness=grid(result.tid_stiffness),
        tid_damping=grid(result.tid_damping),
        host_peak=grid(band_peaks),
        stroke_peak=grid(result.y_peak),
        objective=grid(_smooth_objective(on_band, bands)),
        iterations=grid(result.iterations),
        stationary=grid(np.asarray(result.status) != RETUNE_OUTCOMES.not_stationary),
        converged=grid(result.converged),
        damping_at_bound=grid(result.damping_at_bound),
    )


def _same(a: float | None, b: float | None) -> bool:
    """Two field values agree (`None`, the default friction width, only with itself)."""
    if a is None or b is None:
        return a is b
    return bool(np.isclose(a, b, rtol=1e-12, atol=0.0))


def check_best(best, system: TIDSystem) -> None:
    if not isinstance(best, BestTunings):
        raise ValueError(f"best must be a BestTunings, got {type(best).__name__}")
    nominal = best.system.to_dict()
    given = system.to_dict()
    different = [name for name in FIELD_NAMES if name not in ("tid_stiffness", "tid_damping")
                 and not _same(nominal[name], given[name])]
    if different:
        raise ValueError(
            f"best was computed for another system: {different[0]} is "
            f"{nominal[different[0]]!r} there and {given[different[0]]!r} here"
        )


