"""The frequency band and the peaks of the steady-state response over it: the default
band, a sweep over it, and the peaks of the host (true maxima over frequency) and of
the inerter terminal (`peaks`, `peak_response`)."""

import functools as ft
from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ._model._building import BuildingTID, Quantity, checked_quantity
from ._model._checks import (
    check_grid,
)
from ._model._system import TIDSystem, compiler_options
from ._orbit._sampled_peaks import (
    PEAK_NEWTON_STEPS,
    REFINED_PEAKS,
    STENCIL_POINTS,
    bracket,
    grid_peak,
    interpolated,
    lane_grid_peaks,
    located_peak,
    newton_peak,
    stencil,
    top_peaks,
    true_peaks,
)
from ._orbit._settings import SolverSettings
from ._orbit._steady_state import one_by_one
from ._response import (
    FrequencyResponse,
    batched,
    lane_response,
    point_response,
    scaled_states,
    static_units,
)
from ._runtime._cache import compiled

# Default band, as multiples of the host frequency sqrt(K/M): holds both resonance peaks
# for TID frequencies from well below to 25% above Den Hartog's.
BAND = (0.65, 1.4)
DEFAULT_FREQUENCIES = 61
# The default band of a building: these multiples of the bare structure's first natural
# frequency.
BUILDING_BAND = (0.5, 1.6)


def first_mode_band(system: BuildingTID, points: int = DEFAULT_FREQUENCIES) -> np.ndarray:
    """`points` frequencies (rad/s) over `BUILDING_BAND` of the first mode."""
    return np.linspace(*BUILDING_BAND, points) * system.structure.modes()[0][0]


# The peaks' programs (`_selection`, `_stencils`, `_newton_steps`, `_peaks_found`) run on
# chunks of this many lanes (`_in_chunks`), so that one compiled program serves any
# number of lanes: a run meets many (a retune's checks, a design's stencils, their
# shares among the processes), each of which compiled a program of its own.
LANE_CHUNK = 16


def default_omegas(system: TIDSystem | BuildingTID,
                   n: int | None = None) -> Float[Array, " freqs"]:
    """The default frequency band: `n` (default `DEFAULT_FREQUENCIES`) frequencies over
    0.65-1.4 times the host frequency of a `TIDSystem`, or over 0.5-1.6 times a
    `BuildingTID`'s first natural frequency.

    **Arguments:**

    - `system`: a `TIDSystem` or a `BuildingTID`.
    - `n`: the number of frequencies, an integer >= 5.

    **Returns:** `n` evenly spaced circular frequencies, rad/s.
    """
    if n is not None and not (isinstance(n, int) and n >= 5):
        raise ValueError(f"n must be an integer >= 5, got {n!r}")
    n = DEFAULT_FREQUENCIES if n is None else n
    if isinstance(system, BuildingTID):
        return jnp.asarray(first_mode_band(system, n))
    return jnp.asarray(np.linspace(*BAND, n) * float(system.host_frequency))


def sweep(system: TIDSystem | BuildingTID, amplitude, omegas, settings: SolverSettings,
          z_init=None, quantity: Quantity = Quantity()):
    """Peak |x| (a building's `quantity`), |y| (m), convergence and the orbits' scaled
    states at every frequency for one amplitude, shooting from `z_init` (one state per
    frequency) if given."""

    def one(omega, z0):
        orbit, x_max, y_max = point_response(system, omega, amplitude, settings, z0,
                                             quantity=quantity)
        return x_max, y_max, orbit.converged, orbit.state

    # (a building's LAPACK calls one frequency after another: `one_by_one`)
    each = ft.partial(one_by_one, floors=system.floors)
    if z_init is None:
        return each(lambda omega: one(omega, None))(omegas)
    return each(one)(omegas, z_init)


class Peaks(eqx.Module):
    """Peak steady-state responses over a frequency band, per amplitude (SI): of the host
    (a building's measured quantity, in its unit), the maximum in continuous frequency;
    of the inerter terminal (the stroke), the grid's refined by a parabola (see
    `response_peaks`)."""

    amplitudes: Float[Array, " amps"]
    x_peak: Float[Array, " amps"]  # m, NaN where a steady state in the band did not converge
    y_peak: Float[Array, " amps"]  # m
    omega_x: Float[Array, " amps"]  # rad/s where the host peak occurs
    omega_y: Float[Array, " amps"]
    at_edge: Bool[Array, " amps"]  # host peak at an end of the band
    converged: Bool[Array, " amps"]  # every steady state in the band converged


class Located(NamedTuple):
    """The host's highest peaks of each lane of a `lane_response`, located in continuous
    frequency (`locate_peaks`), as NumPy arrays: the lanes' frequencies and scaled states,
    and per peak (lanes x `REFINED_PEAKS`) its grid index, the last Newton step's estimate,
    its frequency, whether it is a local maximum and whether its bracket is interior;
    `converged`: every steady state of the lane, grid and stencils, converged."""

    omegas: np.ndarray
    states: np.ndarray
    index: np.ndarray
    estimate: np.ndarray
    centre: np.ndarray
    valid: np.ndarray
    interior: np.ndarray
    converged: np.ndarray


def locate_peaks(systems: TIDSystem | BuildingTID, response: FrequencyResponse,
                 settings: SolverSettings, quantity: Quantity = Quantity()) -> Located:
    """The `REFINED_PEAKS` highest local maxima of |x| of each lane of a `lane_response` of
    the systems `systems` (lanes x frequencies), each located in continuous frequency by
    `PEAK_NEWTON_STEPS` Newton steps on its slope (`_peaks.newton_peak`): every step's
    stencils of every lane solved in one batch, each steady state shot from the grid's
    orbits, interpolated. A building's response is that of `quantity`."""
    response = _lane_grids(response)
    omegas, states, converged, index, centre, valid, lower, upper, interior = _in_chunks(
        _selection, response, static_units(systems))
    estimate = np.full(centre.shape, np.nan)
    for _ in range(PEAK_NEWTON_STEPS):
        at, warm = _in_chunks(_stencils, centre, interior, states, omegas, STENCIL_POINTS)
        values, ok = _solve_at(systems, response.amplitudes, at, settings, warm, quantity)
        converged &= ok
        estimate, centre = _in_chunks(_newton_steps, values, at, lower, upper, interior)
    return Located(omegas, states, index, estimate, centre, valid, interior, converged)


def _lane_grids(response: FrequencyResponse) -> FrequencyResponse:
    """`response` (lanes x frequencies) with its frequencies as one row per lane, on the
    host: every array of it then has a leading axis of lanes (`_in_chunks`)."""
    omegas = np.broadcast_to(np.asarray(response.omegas), np.shape(response.x_max))
    return eqx.tree_at(lambda r: r.omegas, response, omegas)


def _in_chunks(program, *args):
    """`program(*args)` (each array of `args` and of its results has a leading axis of
    lanes) run on `LANE_CHUNK` lanes at a time, the last chunk padded with copies of the
    last lane (as `_response` pads its blocks); the results put back together as NumPy
    arrays."""
    args = jax.tree.map(lambda a: np.asarray(a) if eqx.is_array(a) else a, args)
    lanes = len(next(leaf for leaf in jax.tree.leaves(args) if eqx.is_array(leaf)))
    if lanes == 0:
        return jax.tree.map(np.asarray, program(*args))

    def chunk(start):
        index = np.minimum(np.arange(start, start + LANE_CHUNK), lanes - 1)
        return jax.tree.map(lambda a: a[index] if eqx.is_array(a) else a, args)

    parts = [program(*chunk(start)) for start in range(0, lanes, LANE_CHUNK)]
    return jax.tree.map(lambda *chunks: np.concatenate(chunks)[:lanes], *parts)


def _solve_at(systems, amplitudes, at, settings, warm, quantity: Quantity):
    """|x| (m; a building's `quantity`) at the frequencies `at` (lanes x ...) of each
    lane, shot from `warm`, and whether every one of a lane converged."""
    at = np.asarray(at)
    solved = lane_response(systems, amplitudes, at.reshape(at.shape[0], -1), settings, warm,
                           quantity)
    return (np.asarray(solved.x_max).reshape(at.shape),
            np.all(np.asarray(solved.converged), axis=-1))


def response_peaks(systems: TIDSystem | BuildingTID, response: FrequencyResponse,
                   settings: SolverSettings, quantity: Quantity = Quantity()) -> Peaks:
    """`Peaks` of a `lane_response` of the systems `systems` (lanes x frequencies): the
    true maxima over frequency of |x| (`locate_peaks`, then the response at each located
    frequency), and of |y| the grid's (`_peaks.grid_peak`: the stroke over frequency
    can have corners, where the highest of the terminal's excursions within a period
    changes, which Newton steps on its slope would miss). NaN where a steady state in the
    band, or of a stencil, did not converge. A building's response is that of
    `quantity`."""
    found = locate_peaks(systems, response, settings, quantity)
    at, warm = _in_chunks(_stencils, found.centre, found.interior, found.states,
                          found.omegas, 1)
    values, ok = _solve_at(systems, response.amplitudes, at, settings, warm, quantity)
    peaks_found = _in_chunks(_peaks_found, _lane_grids(response), found.omegas, found.index,
                             found.valid, found.centre, found.estimate, values[..., 0],
                             found.converged & ok)
    # (placed on the device as they are: `jnp.asarray` would compile a program per shape)
    return jax.tree.map(jax.device_put, peaks_found)


@compiled
def _selection(response: FrequencyResponse, units):
    """The grid's part of `response_peaks`, one program: the lanes' frequencies and scaled
    states (units `static_units`), whether every
    steady state converged, and the `REFINED_PEAKS` highest local maxima of each lane
    with their brackets."""
    omegas = jnp.broadcast_to(response.omegas, response.x_max.shape)
    states = scaled_states(response, units)
    converged = jnp.all(response.converged, axis=-1)
    # Selection only: an orbit that was not found makes the lane's peaks NaN below.
    grid = jnp.where(response.converged, response.x_max, 0.0)
    index, centre, valid = jax.vmap(lambda v, w: top_peaks(v, w, REFINED_PEAKS))(grid, omegas)
    lower, upper, interior = jax.vmap(bracket)(index, omegas)
    return omegas, states, converged, index, centre, valid, lower, upper, interior


@compiled
def _stencils(centre, interior, states, omegas, points: int):
    """The stencils of `points` frequencies around each lane's peaks (lanes x peaks x
    points; one point: the centres) and the grid's states interpolated to them (lanes x
    frequencies of the stencils, flat)."""
    at = jax.vmap(ft.partial(stencil, points=points))(centre, interior)
    return at, jax.vmap(interpolated)(states, omegas, at.reshape(at.shape[0], -1))


@compiled
def _newton_steps(values, at, lower, upper, interior):
    """`_peaks.newton_peak` on every lane."""
    return jax.vmap(newton_peak)(values, at, lower, upper, interior)


@compiled
def _peaks_found(response: FrequencyResponse, omegas, index, valid, centre, estimate, values,
                 converged) -> Peaks:
    """`Peaks` from the located maxima of `response_peaks` (the last Newton step's
    `estimate`, the response `values` at their frequencies `centre`) and the grid's
    stroke."""
    peak = located_peak(estimate, values)
    best = jnp.argmax(jnp.where(valid, peak, -jnp.inf), axis=1)

    def take(a):
        return jnp.take_along_axis(a, best[:, None], axis=1)[:, 0]

    y, omega_y, _ = lane_grid_peaks(response.y_max, omegas)
    return Peaks(
        amplitudes=response.amplitudes,
        x_peak=jnp.where(converged, take(peak), jnp.nan),
        y_peak=jnp.where(converged, y, jnp.nan),
        omega_x=take(centre),
        omega_y=omega_y,
        at_edge=(take(index) == 0) | (take(index) == omegas.shape[-1] - 1),
        converged=converged,
    )


def _band(system, omegas):
    if omegas is None:
        return default_omegas(system)
    array = check_grid("omegas", omegas)
    if array.ndim != 1 or array.size < 5:
        raise ValueError("omegas must be a band: a 1-d grid of at least 5 frequencies, rad/s "
                         f"(the order is system, omegas, amplitudes), got {array!r}")
    if np.any(np.diff(array) <= 0):
        raise ValueError("omegas must be strictly increasing")
    return jnp.asarray(array, dtype=jnp.result_type(float))


def peaks(
    system: TIDSystem | BuildingTID,
    omegas: ArrayLike | None,
    amplitudes: ArrayLike,
    *,
    quantity: Quantity | None = None,
    settings: SolverSettings | None = None,
) -> Peaks:
    """Peak responses over a frequency band for each amplitude: of the host's displacement
    (a building's `quantity`) and of the inerter's (the stroke); the first the maximum in
    continuous frequency (each of the highest local maxima on the grid located by Newton
    steps on the slope of the response, see `_peaks`), the stroke the grid's refined by a
    parabola. All amplitudes in one batch.

    **Arguments:**

    - `system`: a `TIDSystem` or a `BuildingTID`.
    - `omegas`: the band's grid, rad/s, increasing; None: `default_omegas(system)`.
    - `amplitudes`: load amplitudes A of `A sin(omega t)`, N (a building's ground
      acceleration: m/s2), scalar or 1-d.
    - `quantity`: a building's measured response (`Quantity`; default the top floor's
      displacement).
    - `settings`: `SolverSettings` of the steady states.

    **Returns:** `Peaks`, one entry per amplitude (a building's `x_peak` that of its
    `quantity`, in its unit; `y_peak` the device's stroke, m).
    """
    settings = SolverSettings() if settings is None else settings
    quantity = checked_quantity(system, quantity)
    band = _band(system, omegas)
    amps = np.atleast_1d(np.asarray(check_grid("amplitudes", amplitudes), band.dtype))
    systems = batched(system, amps.size)
    return response_peaks(systems, lane_response(systems, amps, band, settings,
                                                 quantity=quantity), settings, quantity)


def peak_response(
    system: TIDSystem | BuildingTID,
    omegas: ArrayLike | None,
    amplitude: ArrayLike,
    *,
    response: str | Sequence[str] = "host",
    quantity: Quantity | None = None,
    settings: SolverSettings = SolverSettings(),
) -> Float[Array, ""] | Float[Array, " responses"]:
    """Peak steady-state response over a frequency band at one load amplitude: of the
    host's displacement (a building's `quantity`; max |x|), of the inerter (its stroke,
    max |y|) or both. Differentiable, in forward and reverse mode, with respect to every
    field of `system` and `amplitude` (implicit differentiation through the periodic
    orbits; envelope theorem at the peak). The host's peak is the maximum in continuous
    frequency, the inerter's the grid's refined by a parabola (see `response_peaks`).

    **Arguments:**

    - `system`: a `TIDSystem` or a `BuildingTID`.
    - `omegas`: the band's grid, rad/s, increasing; None: `default_omegas(system)`.
    - `amplitude`: load amplitude A of `A sin(omega t)`, N (a building's ground
      acceleration: m/s2; scalar; may be traced).
    - `response`: `"host"` (the host's displacement, a building's `quantity`) or
      `"inerter"` (the stroke), or a tuple (or list) of them: their peaks from one sweep
      of the band (the steady states and their derivatives shared).
    - `quantity`: a building's measured response (`Quantity`; default the top floor's
      displacement).
    - `settings`: `SolverSettings` of the steady states.

    **Returns:** the peak, in the quantity's unit (m for the stroke; for a tuple of
    responses, an array of their peaks in its order); NaN where a steady state in the
    band did not converge.
    """
    quantity = checked_quantity(system, quantity, "peak_response")
    responses = (response,) if isinstance(response, str) else (
        tuple(response) if isinstance(response, tuple | list) else ())
    if not (responses and all(name in ("host", "inerter") for name in responses)):
        raise ValueError(
            f"response must be 'host' or 'inerter', or a tuple of them, got {response!r}")
    band = _band(system, omegas)
    if not isinstance(amplitude, jax.core.Tracer):
        check_grid("amplitude", amplitude)
        if np.ndim(amplitude) != 0:
            raise ValueError(f"amplitude must be a scalar, got shape {np.shape(amplitude)}")
    # An array, traced by the compiled program: a Python number would be one of its
    # static arguments, compiled anew for every amplitude.
    amplitude = jnp.asarray(amplitude, band.dtype)
    # (its tolerances too: one program for any of their values)
    return _peak_response(system, amplitude, band,
                          response if isinstance(response, str) else responses,
                          settings.with_array_tolerances(system), quantity)


@compiled(options=compiler_options)
def _peak_response(system, amplitude, omegas, response: str | tuple[str, ...], settings,
                   quantity: Quantity):
    """The peak of `response` (a scalar), or of each of a tuple of them (an array)."""
    responses = (response,) if isinstance(response, str) else response
    xs, ys, converged, states = sweep(system, amplitude, omegas, settings, quantity=quantity)
    peaks = {}
    if "host" in responses:
        def solve(at, last):
            del last
            z0 = interpolated(states, omegas, at)
            # One sweep over every point of every peak (a sweep per peak would batch the
            # solves' loops twice over when traced).
            x, _, ok, _ = sweep(system, amplitude, at.reshape(-1), settings,
                                z0.reshape((-1,) + z0.shape[2:]), quantity)
            return jnp.where(ok, x, jnp.nan).reshape(at.shape)

        selection = jnp.where(converged, jax.lax.stop_gradient(xs), 0.0)
        _, located, _, valid = true_peaks(selection, omegas, solve, REFINED_PEAKS)
        peaks["host"] = jnp.max(jnp.where(valid, located, -jnp.inf))
    if "inerter" in responses:
        peaks["inerter"] = grid_peak(ys, omegas)[0]  # see `response_peaks`
    # The maximum over a band with an orbit that was not found is unknown.
    found = jnp.stack([peaks[name] for name in responses])
    found = found[0] if isinstance(response, str) else found
    return jnp.where(jnp.all(converged), found, jnp.nan)
