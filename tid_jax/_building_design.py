"""The peak of a `BuildingTID`'s response over frequency and the TID's retune per
amplitude: steady states on a frequency grid (`_building_orbit`), the highest local
maxima refined by parabolas through ever closer frequencies, and the tuning (k, c) that
minimises that peak by optimistix's Nelder-Mead search (the minimax optimum, with two
equal peaks, is not smooth)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float

from ._building import (
    BuildingTID,
    Quantity,
    first_mode_tunings,
    linear_amplitudes,
    quantity_amplitude,
    uncontrolled_amplitude,
)
from ._building_orbit import building_settings, solve_orbit
from ._checks import check_grid
from ._peaks import local_peaks
from ._settings import SolverSettings

# The default band of a building's design: these multiples of the bare structure's
# first natural frequency.
BUILDING_BAND = (0.5, 1.6)
BAND_POINTS = 31
_CANDIDATES = 2  # local maxima refined
_ROUNDS = 4  # parabolas through ever closer frequencies
_SHRINK = 4.0


def default_omegas(system: BuildingTID, points: int = BAND_POINTS) -> np.ndarray:
    """`points` frequencies (rad/s) over `BUILDING_BAND` of the first mode."""
    return np.linspace(*BUILDING_BAND, points) * system.structure.modes()[0][0]


class Peak(eqx.Module):
    value: Float[Array, ""]  # SI
    omega: Float[Array, ""]  # rad/s
    converged: Bool[Array, ""]  # every steady state it rests on was found


def _solve(system, quantity, amplitude, omegas, settings, linear):
    if linear:  # no friction: the steady state in closed form
        u = linear_amplitudes(system, omegas)
        value = amplitude * jnp.abs(quantity_amplitude(system, quantity, omegas, u))
        return value, jnp.isfinite(value)
    orbits = jax.vmap(lambda w: solve_orbit(system, quantity, amplitude, w, settings))(omegas)
    return orbits.response_max, orbits.converged


def peak_over_frequency(system: BuildingTID, quantity: Quantity, amplitude, omegas,
                        settings: SolverSettings, linear: bool = False) -> Peak:
    """The largest steady-state peak of `quantity` over the band of `omegas`: the grid's
    highest local maxima (or band ends), each refined `_ROUNDS` times by the vertex of the
    parabola through three frequencies about it, their spacing shrinking each round.
    `linear`: the system has no friction, and its steady states are found in closed
    form."""
    values, ok = _solve(system, quantity, amplitude, omegas, settings, linear)
    values = jnp.where(ok, values, jnp.inf)
    peaks, at, _ = local_peaks(values, omegas)
    order = jnp.argsort(-peaks)[:_CANDIDATES]
    centres, step = at[order], (omegas[1] - omegas[0]) / _SHRINK
    all_ok = jnp.all(ok)
    best = peaks[order]
    for _ in range(_ROUNDS):
        points = centres[:, None] + step * jnp.asarray([-1.0, 0.0, 1.0])
        points = jnp.clip(points, omegas[0], omegas[-1])
        v, ok = _solve(system, quantity, amplitude, points.reshape(-1), settings, linear)
        v = v.reshape(points.shape)
        all_ok &= jnp.all(ok)
        left, mid, right = v[:, 0], v[:, 1], v[:, 2]
        curvature = left - 2 * mid + right
        concave = (curvature < 0) & (mid >= left) & (mid >= right)
        shift = jnp.where(concave, 0.5 * (left - right) / jnp.where(concave, curvature, -1.0),
                          jnp.where(left > right, -1.0, 1.0))
        best = jnp.where(concave, mid - 0.125 * (right - left) ** 2 / jnp.where(
            concave, curvature, -1.0), jnp.max(v, axis=1))
        centres = jnp.clip(centres + shift * step, omegas[0], omegas[-1])
        step = step / _SHRINK
    top = jnp.argmax(best)
    return Peak(best[top], centres[top], all_ok & jnp.all(jnp.isfinite(best)))


class BuildingRetune(eqx.Module):
    """The retuned TID per amplitude (SI): `tid_stiffness` k (N/m), `tid_damping` c
    (N s/m), `peak` (of the quantity over the band), `peak_omega` (rad/s), `uncontrolled`
    (the bare structure's peak over the band at that amplitude), `converged` (the search
    ended by its tolerance and every steady state was found), and the first-mode
    tunings' peaks `den_hartog_peak`, `h_infinity_peak`."""

    amplitudes: Float[Array, " amps"]
    tid_stiffness: Float[Array, " amps"]
    tid_damping: Float[Array, " amps"]
    peak: Float[Array, " amps"]
    peak_omega: Float[Array, " amps"]
    uncontrolled: Float[Array, " amps"]
    converged: Bool[Array, " amps"]
    den_hartog_peak: Float[Array, " amps"]
    h_infinity_peak: Float[Array, " amps"]


@eqx.filter_jit
def _retune_lanes(system, quantity, amplitudes, omegas, start, settings, rtol, max_steps,
                  linear):
    def one(amplitude):
        def objective(log_tuning, _):
            k, c = jnp.exp(log_tuning)
            tuned = eqx.tree_at(lambda s: (s.tid_stiffness, s.tid_damping), system, (k, c))
            found = peak_over_frequency(tuned, quantity, amplitude, omegas, settings, linear)
            return jnp.where(found.converged, jnp.log(found.value), jnp.inf)

        solver = optx.NelderMead(rtol=rtol, atol=rtol)
        solution = optx.minimise(objective, solver, jnp.log(start), max_steps=max_steps,
                                 throw=False)
        k, c = jnp.exp(solution.value)
        tuned = eqx.tree_at(lambda s: (s.tid_stiffness, s.tid_damping), system, (k, c))
        found = peak_over_frequency(tuned, quantity, amplitude, omegas, settings, linear)
        ok = (solution.result == optx.RESULTS.successful) & found.converged
        return k, c, found.value, found.omega, ok

    return jax.vmap(one)(amplitudes)


@eqx.filter_jit
def _peaks_at(system, quantity, amplitudes, omegas, settings, linear):
    return jax.vmap(lambda a: peak_over_frequency(system, quantity, a, omegas, settings,
                                                  linear))(amplitudes)


def _frictionless(system: BuildingTID) -> bool:
    return bool(np.all(np.asarray(system.friction_force) == 0))


def building_peaks(system: BuildingTID, amplitudes, quantity: Quantity = Quantity(),
                   omegas=None, settings: SolverSettings | None = None) -> Peak:
    """The peak of `quantity` over the band `omegas` (default `default_omegas`) at each
    amplitude, with the system's own tuning."""
    amplitudes = np.atleast_1d(check_grid("amplitudes", amplitudes)).astype(float)
    omegas = default_omegas(system) if omegas is None else np.asarray(
        check_grid("omegas", omegas), float)
    quantity.floor_of(system.floors)
    return _peaks_at(system, quantity, jnp.asarray(amplitudes), jnp.asarray(omegas),
                     building_settings(system, settings), _frictionless(system))


def retune_building(system: BuildingTID, amplitudes, quantity: Quantity = Quantity(), *,
                    omegas=None, settings: SolverSettings | None = None,
                    rtol: float = 1e-5, max_steps: int = 400) -> BuildingRetune:
    """The TID's (k, c) that minimise the peak of `quantity` over the band `omegas`
    (default `default_omegas`) at each of `amplitudes`, by a Nelder-Mead search in
    (log k, log c) from the first mode's exact H-infinity tuning (`first_mode_tunings`),
    the whole structure and the friction seen by each steady state; with the peaks of the
    first-mode Den Hartog and H-infinity tunings for comparison."""
    amplitudes = np.atleast_1d(check_grid("amplitudes", amplitudes)).astype(float)
    omegas = default_omegas(system) if omegas is None else np.asarray(
        check_grid("omegas", omegas), float)
    quantity.floor_of(system.floors)
    settings = building_settings(system, settings)
    tunings = first_mode_tunings(system)
    linear = _frictionless(system)
    a, w = jnp.asarray(amplitudes), jnp.asarray(omegas)
    reference = {name: _peaks_at(system.replace(tid_stiffness=k, tid_damping=c), quantity,
                                 a, w, settings, linear) for name, (k, c) in tunings.items()}
    k, c, value, at, ok = _retune_lanes(system, quantity, a, w,
                                        jnp.asarray(tunings["h_infinity"]), settings, rtol,
                                        max_steps, linear)
    bare = np.max(np.asarray(uncontrolled_amplitude(system, quantity, w)))
    return BuildingRetune(
        amplitudes=amplitudes, tid_stiffness=np.asarray(k), tid_damping=np.asarray(c),
        peak=np.where(ok, np.asarray(value), np.nan), peak_omega=np.asarray(at),
        uncontrolled=amplitudes * bare, converged=np.asarray(ok),
        den_hartog_peak=np.asarray(reference["den_hartog"].value),
        h_infinity_peak=np.asarray(reference["h_infinity"].value))
