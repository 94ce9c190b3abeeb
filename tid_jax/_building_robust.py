"""One TID tuning for a building under many scenarios (`robust_building`): the ground or
force amplitudes and a tolerance on the structure's stiffness, each scenario's peak
against the best that a tuning of its own achieves."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from ._building import BuildingTID, Quantity, first_mode_tunings
from ._building_design import (
    BandSearch,
    frictionless,
    minimax,
    retune_building,
    search_grid,
)
from ._building_orbit import building_settings
from ._checks import check_grid
from ._settings import SolverSettings
from ._structure import Structure


class BuildingRobust(eqx.Module):
    """The robust tuning (SI): `tid_stiffness` k (N/m) and `tid_damping` c (N s/m), and
    per scenario (amplitude x stiffness scale, arrays of that shape) its `peak`, the
    `best` peak of a tuning of the scenario's own (`retune_building`) and their `ratio`;
    `worst_ratio`, the highest ratio; `converged`: the search ended by its tolerance, or
    at a first-order minimax point, and every steady state was found."""

    amplitudes: Float[Array, " amps"]
    stiffness_scales: Float[Array, " scales"]
    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    peak: Float[Array, "amps scales"]
    best: Float[Array, "amps scales"]
    ratio: Float[Array, "amps scales"]
    worst_ratio: Float[Array, ""]
    converged: Bool[Array, ""]


def scaled_structure(structure: Structure, scale: float) -> Structure:
    """The structure with its stiffness matrix times `scale` (mass and damping held)."""
    return eqx.tree_at(lambda s: s.stiffness_matrix, structure,
                       structure.stiffness_matrix * scale)


def robust_building(system: BuildingTID, amplitudes, quantity: Quantity | None = None, *,
                    stiffness_scales=(1.0,), omegas=None,
                    settings: SolverSettings | None = None, rtol: float = 1e-6,
                    max_steps: int = 100, progress=None) -> BuildingRobust:
    """One (k, c) for every scenario, amplitude x stiffness scale (the structure's
    stiffness matrix times the scale: `(0.95, 1.0, 1.05)` for +-5%): the minimiser of the
    worst, over the scenarios, of the peak of `quantity` over the band divided by the
    best peak a tuning of the scenario's own achieves (`retune_building`). The band is
    `omegas`, or per scenario its default (`first_mode_band`, with its own first mode).
    The same search as the retune's (`minimax`) over every scenario's two highest
    peaks, from the best scenario-own tuning that does best in the worst case.
    `progress(message)` is told of each step."""
    quantity = Quantity() if quantity is None else quantity
    amplitudes = np.atleast_1d(check_grid("amplitudes", amplitudes)).astype(float)
    scales = np.atleast_1d(check_grid("stiffness_scales", stiffness_scales)).astype(float)
    quantity.floor_of(system.floors)
    settings = building_settings(system, settings)
    linear = frictionless(system)
    say = progress if progress is not None else (lambda message: None)
    searches, best, tunings = [], [], []
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
    best = np.asarray(best).T  # amplitudes x scales
    order = [(i, j) for j in range(scales.size) for i in range(amplitudes.size)]
    offsets = np.asarray([np.log(best[i, j]) for i, j in order])
    if not np.all(np.isfinite(offsets)):
        raise ValueError("the best tuning of a scenario was not found; robust_building "
                         "needs every scenario's")
    worst = {}
    for tuning in tunings:  # the scenario-own tunings, each in every scenario
        x = np.log(np.asarray(tuning, float))
        found = [search(x) for search in searches]
        if all(f[2] for f in found):
            worst[tuple(x)] = max(f[0].max() - o for f, o in zip(found, offsets,
                                                                  strict=True))
    say("the scenario-own tunings in every scenario")
    centre = np.log(np.asarray(first_mode_tunings(system)["h_infinity"], float))
    result = None
    if worst:
        start = np.asarray(min(worst, key=worst.get))
        result = minimax(searches, offsets, start, centre, rtol, max_steps)
    say("robust tuning")
    if result is None:
        x, ok = centre, False
        peaks = np.full(best.shape, np.nan)
    else:
        x, _, ok = result
        found = [search(x) for search in searches]
        ok = ok and all(f[2] for f in found)
        peaks = np.empty(best.shape)
        for (i, j), f in zip(order, found, strict=True):
            peaks[i, j] = float(f[3].value) if f[2] else np.nan
    ratio = peaks / best
    k, c = np.exp(x)
    return BuildingRobust(
        amplitudes=amplitudes, stiffness_scales=scales, tid_stiffness=jnp.asarray(k),
        tid_damping=jnp.asarray(c), peak=peaks, best=best, ratio=ratio,
        worst_ratio=jnp.asarray(np.max(ratio)), converged=jnp.asarray(bool(ok)))
