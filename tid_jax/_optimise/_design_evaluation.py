"""Designs evaluated over scenarios, on the host: what every evaluation shares
(`Context`: the system, the band, the solver settings), the responses over the band and
the kernel's derivatives (`_design`) at a design and its stencil, and the terms of the
smooth maxima in the design coordinates."""

from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from .._model._building import BuildingTID, Quantity
from .._model._system import TIDSystem
from .._orbit._sampled_peaks import REFINED_PEAKS
from .._orbit._settings import SolverSettings
from .._peaks import locate_peaks
from .._response import batched, lane_response, scaled_states, static_units
from .._retune import reference_tunings
from .._runtime._parallel import map_shares, serial
from ._design import (
    CHUNK,
    NO_PEAK,
    changed_system,
    evaluate_chunk,
    parameter_values,
    parameters_of,
)
from ._design_variables import design_of_tuning, tuning_of_design
from ._smooth_max import Terms

UNSCALED = (1.0, 1.0)  # the design variables' scales here: unscaled


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
    """What every evaluation shares: the system, the band (rad/s, scaled by each
    scenario's host frequency scale), the solver settings, whether the host's peaks are located in continuous
    frequency (`locate`: as `retune` does, for the sensitivities of its optimum; else
    the grid's, refined by parabolas) and the reference tuning of the design variables
    u = (ln(k / k_ref), sqrt(c / c_ref)) (`design_of_tuning`, unscaled), the step in u of
    the stencils (`stencil_step`: the curvature of each refined peak from differences of
    its exact gradients over that step), and how independent lanes are mapped
    (`map_lanes`, see `_parallel`). A building's response is its `quantity`'s; the
    reference tuning is the retune's (`reference_tunings`: a building's first mode's Den
    Hartog tuning)."""

    def __init__(self, system: TIDSystem | BuildingTID, omegas, settings: SolverSettings, *,
                 locate: bool, stencil_step: float, map_lanes: Callable = serial,
                 quantity: Quantity = Quantity()):
        self.system = system
        self.quantity = quantity
        self.stencil_step = stencil_step
        self.map_lanes = map_lanes
        self.locate = locate
        self.settings = settings
        self.omegas = np.asarray(omegas, dtype=float)
        self.parameters = parameters_of(system)
        self.values = parameter_values(system)
        # The entries of the tuning (k, c) in a vector of parameters `theta`.
        self.k_index = self.parameters.index("tid_stiffness")
        self.c_index = self.parameters.index("tid_damping")
        # Parameters other than the design (k, c), in the order of the optimiser's
        # coordinates (u0, u1, *other): u0 = ln(k / k_ref), u1 = sqrt(c / c_ref).
        self.other = [i for i in range(len(self.parameters))
                      if i not in (self.k_index, self.c_index)]
        k_ref, c_ref = reference_tunings(batched(system, 1))
        self.k_ref, self.c_ref = float(k_ref[0]), float(c_ref[0])

    def tuning(self, u) -> tuple[float, float]:
        k, c = tuning_of_design(np.asarray(u, dtype=float), self.k_ref, self.c_ref, UNSCALED,
                                np)
        return float(k), float(c)

    def design(self, k, c, *, floor=0.0) -> np.ndarray:
        c = max(c, floor * self.c_ref)
        return design_of_tuning(k, c, self.k_ref, self.c_ref, UNSCALED, np)

    def theta(self, k, c, amplitude) -> np.ndarray:
        theta = np.append(self.values, float(amplitude))
        theta[self.k_index], theta[self.c_index] = k, c
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
                            lanes, self.system, self.omegas, settings, self.locate,
                            self.quantity)
        return [_Grid(*(field[i] for field in fields)) for i in range(len(points))]

    def _tasks(self, points: Sequence[tuple], grids: Sequence["_Grid"],
               settings: SolverSettings):
        """The tasks of `evaluate_chunk` for `points` (`(theta, scale, ...)`) and their
        `grids`, `CHUNK` points each (the last padded with copies of its last point), and
        how many points each holds."""
        tasks, sizes = [], []
        for start in range(0, len(points), CHUNK):
            chunk = [(point[0], point[1], grid)
                     for point, grid in zip(points[start : start + CHUNK],
                                            grids[start : start + CHUNK], strict=True)]
            sizes.append(len(chunk))
            chunk += [chunk[-1]] * (CHUNK - len(chunk))
            thetas, scales = (np.stack([point[i] for point in chunk]) for i in range(2))
            fields = [np.stack(field) for field in zip(*(point[2] for point in chunk),
                                                       strict=True)]
            tasks.append((self.system, self.quantity, thetas, np.asarray(scales, dtype=float),
                          self.omegas,
                          settings, tuple(fields[:4]), tuple(fields[4:])))
        return tasks, sizes

    def _evaluate(self, points: Sequence[tuple], settings: SolverSettings) -> list[_Curves]:
        """`_Curves` at each point with `settings`: the responses over the band of every
        point in one batch (`_grids`), then the derivatives `CHUNK` points per compiled
        call, the calls mapped by `map_lanes`."""
        tasks, sizes = self._tasks(points, self._grids(points, settings), settings)
        results = []
        for used, ((jac_x, jac_y), out) in zip(
                sizes, self.map_lanes(evaluate_chunk, tasks), strict=True):
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
                          self.system, self.omegas, self.settings, False,
                          self.quantity).states


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


def _solve_grids(thetas, scales, z_init, system, omegas, settings, locate,
                 quantity=Quantity()):
    """The `_Grid` of points (a leading axis of points) at the parameters `thetas` (a row
    per point, order `parameters_of(system)`) with the host stiffness multiplied by
    `scales**2`, over the band `omegas` times `scales`, each point shot from its scaled
    states `z_init` (None: from the equivalent linear steady state after a transient):
    every point in one batch (`lane_response`) and, where `locate`, the
    host's peaks located in continuous frequency (`locate_peaks`). A building's
    response is its `quantity`'s."""
    lanes = changed_system(batched(system, len(thetas)), thetas.T, scales)
    response = lane_response(lanes, thetas[:, -1], omegas * scales[:, None], settings, z_init,
                             quantity)
    states = scaled_states(response, static_units(lanes), xp=np)
    xs, ys, converged = (np.asarray(a) for a in (response.x_max, response.y_max,
                                                 response.converged))
    if locate:
        found = locate_peaks(lanes, response, settings, quantity)
        located = (found.index.astype(int), found.estimate, found.centre, found.valid)
        converged = converged & found.converged[:, None]
    else:
        # No peaks: entries the kernel leaves out (one program for both kinds of points).
        shape = (len(thetas), REFINED_PEAKS)
        located = (np.full(shape, NO_PEAK), np.full(shape, np.nan),
                   np.broadcast_to(omegas[0] * scales[:, None], shape), np.zeros(shape, bool))
    return _Grid(xs, ys, converged, states, *located)


def _solve_cold_grids(thetas, scales, system, omegas, settings, locate, quantity=Quantity()):
    """`_solve_grids` from the linear steady state (a task of `map_shares`)."""
    return _solve_grids(thetas, scales, None, system, omegas, settings, locate, quantity)


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


def _stencil(u, kind: str, step: float) -> list[np.ndarray]:
    """The designs of the stencil `kind` (of `STENCILS`) at u, `step` apart."""
    u = np.asarray(u, dtype=float)
    return [u] + [u + step * np.asarray(offset) for offset in STENCILS[kind]]


def coordinates(ctx: Context, u, stencil: list[_Curves], response: str) -> Terms:
    """Log peaks, their gradients in the coordinates (u0, u1, parameters `Context.other`) and
    the derivatives of those gradients along u0 and u1, for every frequency of one
    scenario, from the curves at the designs of a stencil at u (`_stencil`; central when
    there are five). Only the second derivatives of each refined peak come from differences;
    from u alone (one design) they are unknown: NaN."""
    k, _ = ctx.tuning(u)
    jac = [getattr(curves, f"jac_{response}") for curves in stencil]
    centre = jac[0]
    ki, ci = ctx.k_index, ctx.c_index
    grad = np.concatenate([k * centre[:, [ki]], 2 * ctx.c_ref * u[1] * centre[:, [ci]],
                           centre[:, ctx.other]], axis=1)
    dgrad = np.full(grad.shape[:1] + (2,) + grad.shape[1:], np.nan)
    for i in range(2 if len(stencil) > 1 else 0):
        if len(stencil) == 5:
            d_jac = (jac[1 + 2 * i] - jac[2 + 2 * i]) / (2 * ctx.stencil_step)
        else:
            d_jac = (jac[1 + i] - centre) / ctx.stencil_step
        dgrad[:, i, 0] = k * d_jac[:, ki] + (k * centre[:, ki] if i == 0 else 0.0)
        dgrad[:, i, 1] = 2 * ctx.c_ref * (u[1] * d_jac[:, ci] + (centre[:, ci] if i == 1 else 0.0))
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
        us = [_stencil(u, kind, ctx.stencil_step) for kind in kinds]
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
