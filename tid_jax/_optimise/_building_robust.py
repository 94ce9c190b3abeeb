"""One TID tuning for a building under many scenarios (`robust_building`): the ground or
force amplitudes and a tolerance on the structure's stiffness, each scenario's peak
against the best that a tuning of its own achieves, every scenario's stroke peak within a
limit."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._model._building import (
    BuildingTID,
    Quantity,
    first_mode_tunings,
    linear_amplitudes,
    log_tuned,
)
from .._model._checks import check_grid
from .._model._structure import Structure
from .._model._system import PAPER_STROKE, check_values
from .._orbit._building_orbit import building_settings, solve_orbits
from .._orbit._settings import SolverSettings
from .._runtime._outcomes import Outcome, outcome_code, outcome_messages
from ._building_design import (
    BandSearch,
    frictionless,
    minimax,
    retune_building,
    search_grid,
)

# The stroke limit is aimed this fraction below the given one (SLSQP meets its
# constraints to its tolerance); a design whose largest stroke peak is within
# `STROKE_ACTIVE` of the limit has it active.
STROKE_MARGIN = 1e-3
STROKE_ACTIVE = 2e-3
_STROKE_STEP = 1e-4  # the step in ln k and ln c of the stroke peak's difference quotients


@eqx.filter_jit
def _stroke_peaks(system, amplitude, omegas, settings, linear, log_tunings):
    """The stroke's peak (m) over the grid `omegas` at each design of `log_tunings`
    (designs x 2, ln k and ln c); NaN where a steady state was not found."""

    def one(x):
        tuned = log_tuned(system, x)
        if linear:  # the steady state in closed form
            u = linear_amplitudes(tuned, omegas)
            return amplitude * jnp.max(jnp.abs(u[:, tuned.floors]))
        orbits = solve_orbits(tuned, Quantity(), jnp.full_like(omegas, amplitude), omegas,
                              settings)
        return jnp.max(jnp.where(orbits.converged, orbits.stroke_max, jnp.nan))

    return jax.vmap(one)(log_tunings)


class StrokeSearch:
    """One scenario's stroke peak over the band's grid at designs (ln k, ln c): its log,
    `value(x)`, and with the central difference quotients of that, `(x)`; each design
    evaluated once."""

    def __init__(self, system, amplitude, omegas, settings, linear):
        self.args = (system, jnp.asarray(amplitude), jnp.asarray(omegas), settings, linear)
        self.values, self.gradients = {}, {}

    def value(self, x):
        key = tuple(np.asarray(x[:2], float))
        if key not in self.values:
            self.values[key] = float(np.log(_stroke_peaks(*self.args, jnp.asarray([key]))[0]))
        return self.values[key]

    def __call__(self, x):
        key = tuple(np.asarray(x[:2], float))
        if key not in self.gradients:
            steps = _STROKE_STEP * np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])
            logs = np.log(np.asarray(_stroke_peaks(*self.args, jnp.asarray(key) + steps)))
            self.gradients[key] = np.array([logs[0] - logs[1], logs[2] - logs[3]]) / (
                2 * _STROKE_STEP)
        return self.value(key), self.gradients[key]


class _StrokeLimits:
    """Each scenario's log stroke peak less `log_aim`: `values(x)`, and with their
    gradients, `(x)`."""

    def __init__(self, strokes, log_aim):
        self.strokes, self.log_aim = strokes, log_aim

    def values(self, x):
        return np.array([search.value(x) for search in self.strokes]) - self.log_aim

    def __call__(self, x):
        found = [search(x) for search in self.strokes]
        return (np.array([f[0] for f in found]) - self.log_aim,
                np.array([f[1] for f in found]))


class BuildingRobust(eqx.Module):
    """The robust tuning (SI): `tid_stiffness` k (N/m) and `tid_damping` c (N s/m), and
    per scenario (amplitude x stiffness scale, arrays of that shape) its `peak`, the
    `best` peak of a tuning of the scenario's own (`retune_building`) and their `ratio`;
    `worst_ratio`, the highest ratio. Per scenario too, `stroke_peak` (m), the stroke's
    peak over the band's grid; the `stroke_limit` (m; None: none), whether every stroke
    peak is `within_stroke_limit` and whether the limit is active, `stroke_limited` (the
    largest peak within `STROKE_ACTIVE` of it). `status`, a code of `Outcome` read by
    `status_messages()`: `not_stationary` where the search ended neither by its tolerance
    nor at a first-order minimax point, `steady_states_failed` where a steady state was
    not found (a scenario-own tuning's or the design's), `stroke_over_limit` where a
    stroke peak is over the limit (the values NaN where no design within it was found),
    else `ok`; `converged` is `status == ok`."""

    amplitudes: Float[Array, " amps"]
    stiffness_scales: Float[Array, " scales"]
    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    peak: Float[Array, "amps scales"]
    best: Float[Array, "amps scales"]
    ratio: Float[Array, "amps scales"]
    worst_ratio: Float[Array, ""]
    converged: Bool[Array, ""]
    stroke_peak: Float[Array, "amps scales"]
    within_stroke_limit: Bool[Array, ""]
    stroke_limited: Bool[Array, ""]
    status: Int[Array, ""]
    stroke_limit: float | None = eqx.field(static=True, default=None)

    def status_messages(self) -> list[str]:
        """The meaning of `status`, one message (`Outcome`'s)."""
        return outcome_messages(self.status)


def scaled_structure(structure: Structure, scale: float) -> Structure:
    """The structure with its stiffness matrix times `scale` (mass and damping held)."""
    return eqx.tree_at(lambda s: s.stiffness_matrix, structure,
                       structure.stiffness_matrix * scale)


def robust_building(system: BuildingTID, amplitudes, quantity: Quantity | None = None, *,
                    stiffness_scales=(1.0,), omegas=None,
                    stroke_limit: float | None = PAPER_STROKE,
                    settings: SolverSettings | None = None, rtol: float = 1e-6,
                    max_steps: int = 100, progress=None) -> BuildingRobust:
    """One (k, c) for every scenario, amplitude x stiffness scale (the structure's
    stiffness matrix times the scale: `(0.95, 1.0, 1.05)` for +-5%): the minimiser of the
    worst, over the scenarios, of the peak of `quantity` over the band divided by the
    best peak a tuning of the scenario's own achieves (`retune_building`), with every
    scenario's stroke peak over the band's grid within `stroke_limit` (m; None: no
    limit). The band is `omegas`, or per scenario its default (`first_mode_band`, with its
    own first mode). The same search as the retune's (`minimax`) over every scenario's
    two highest peaks, the stroke peaks as further constraints (their difference
    quotients), from the best scenario-own tuning that does best in the worst case
    (within the limit, where one is). `progress(message)` is told of each step."""
    quantity = Quantity() if quantity is None else quantity
    amplitudes = np.atleast_1d(check_grid("amplitudes", amplitudes)).astype(float)
    scales = np.atleast_1d(check_grid("stiffness_scales", stiffness_scales)).astype(float)
    if stroke_limit is not None:
        check_values("stroke_limit", stroke_limit, "positive")
        stroke_limit = float(stroke_limit)
    quantity.floor_of(system.floors)
    settings = building_settings(system, settings)
    linear = frictionless(system)
    say = progress if progress is not None else (lambda message: None)
    searches, strokes, best, tunings = [], [], [], []
    for scale in scales:
        scaled = system.replace(structure=scaled_structure(system.structure, float(scale)))
        grid = search_grid(scaled, omegas)
        own = retune_building(scaled, amplitudes, quantity, omegas=grid, settings=settings,
                              rtol=rtol, max_steps=max_steps)
        say(f"best tunings of the {amplitudes.size} amplitude(s) at stiffness x {scale:g}")
        best.append(own.peak)
        tunings += list(zip(own.tid_stiffness, own.tid_damping, strict=True))
        searches += [BandSearch(scaled, quantity, a, grid, settings, linear)
                     for a in amplitudes]
        strokes += [StrokeSearch(scaled, a, grid, settings, linear) for a in amplitudes]
    best = np.asarray(best).T  # amplitudes x scales
    order = [(i, j) for j in range(scales.size) for i in range(amplitudes.size)]
    offsets = np.asarray([np.log(best[i, j]) for i, j in order])
    if not np.all(np.isfinite(offsets)):
        raise ValueError("the best tuning of a scenario was not found; robust_building "
                         "needs every scenario's")
    limits = None if stroke_limit is None else _StrokeLimits(
        strokes, np.log(stroke_limit * (1 - STROKE_MARGIN)))
    start = _start(searches, offsets, tunings, limits)
    say("the scenario-own tunings in every scenario")
    centre = np.log(np.asarray(first_mode_tunings(system)["h_infinity"], float))
    result = None
    if start is not None:
        result = minimax(searches, offsets, start, centre, rtol, max_steps, limits,
                         -np.log1p(-STROKE_MARGIN))
    say("robust tuning")
    return _robust_result(searches, strokes, order, (start, result), centre, best,
                          amplitudes, scales, stroke_limit)


def _start(searches, offsets, tunings, limits):
    """The scenario-own tuning (ln k, ln c) with the lowest worst value, among those
    within the stroke limits where any is (else the one least over them); None where
    none was found in every scenario."""
    worst = {}
    for tuning in tunings:  # the scenario-own tunings, each in every scenario
        x = np.log(np.asarray(tuning, float))
        found = [search(x) for search in searches]
        if all(f[2] for f in found):
            over = 0.0 if limits is None else max(float(np.max(limits.values(x))), 0.0)
            worst[tuple(x)] = (over, max(f[0].max() - o for f, o in zip(found, offsets,
                                                                         strict=True)))
    return np.asarray(min(worst, key=worst.get)) if worst else None


def _outcome(searches, start, result, values, stroke_limit) -> Outcome:
    """The `Outcome` of the robust search from `start` (None: no scenario-own tuning was
    found in every scenario) that ended in `minimax`'s `result` (None: the start's steady
    states were not all found, or no design within the stroke limits was); `values`, the
    design's peaks and stroke peaks (NaN where a steady state was not found)."""
    if result is None:
        started = start is not None and all(search(start)[2] for search in searches)
        return Outcome.stroke_over_limit if started else Outcome.steady_states_failed
    peaks, stroke = values
    if not result[2]:
        return Outcome.not_stationary
    if not (np.all(np.isfinite(peaks)) and np.all(np.isfinite(stroke))):
        return Outcome.steady_states_failed
    if stroke_limit is not None and np.max(stroke) > stroke_limit:
        return Outcome.stroke_over_limit
    return Outcome.ok


def _robust_result(searches, strokes, order, ended, centre, best, amplitudes, scales,
                   stroke_limit) -> BuildingRobust:
    """The `BuildingRobust` of the search `ended` = (its start, `minimax`'s result; the
    result None: not found, its values NaN)."""
    start, result = ended
    peaks, stroke = np.full(best.shape, np.nan), np.full(best.shape, np.nan)
    x = centre if result is None else result[0]
    if result is not None:
        found = [search(x) for search in searches]
        for (i, j), f, s in zip(order, found, strokes, strict=True):
            peaks[i, j] = float(f[3].value) if f[2] else np.nan
            stroke[i, j] = float(np.exp(s.value(x)))
    ratio = peaks / best
    top = np.max(stroke)  # NaN where one was not found
    within = stroke_limit is None or bool(top <= stroke_limit)
    active = stroke_limit is not None and bool(top >= stroke_limit * (1 - STROKE_ACTIVE))
    status = outcome_code(_outcome(searches, start, result, (peaks, stroke), stroke_limit))
    k, c = np.exp(x)
    return BuildingRobust(
        amplitudes=amplitudes, stiffness_scales=scales, tid_stiffness=jnp.asarray(k),
        tid_damping=jnp.asarray(c), peak=peaks, best=best, ratio=ratio,
        worst_ratio=jnp.asarray(np.max(ratio)),
        converged=jnp.asarray(status == outcome_code(Outcome.ok)), stroke_peak=stroke,
        within_stroke_limit=jnp.asarray(within), stroke_limited=jnp.asarray(active),
        status=jnp.asarray(status), stroke_limit=stroke_limit)
