import dataclasses
import functools as ft

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Complex, Float, Int

from ._model._building import BuildingTID, Quantity, checked_quantity
from ._model._checks import (
    check_grid,
)
from ._model._system import TIDSystem, compiler_options
from ._orbit._eigen import eigenvalues
from ._orbit._flow import PlantInputs
from ._orbit._implicit import moving_part
from ._orbit._period import point_model, state_units, transient
from ._orbit._sampled_peaks import refined_peak
from ._orbit._settings import SolverSettings
from ._orbit._steady_state import (
    one_by_one,
    shoot_queue,
    solve_orbit,
    y_peak,
)
from ._orbit._stiffness import for_points
from ._runtime._cache import compiled
from ._runtime._sharding import map_batch, per_device, sharded_batch


class FrequencyResponse(eqx.Module):
    """Steady-state response of eq. (12), or of a TID in a building, with smoothed or
    exact friction, on a grid of load amplitudes x frequencies. Arrays have shape
    `(n_amplitudes, n_frequencies)` (axes of scalar inputs dropped). SI units.

    - `omegas` (rad/s), `amplitudes` (N; a building's ground acceleration m/s2): the grid.
    - `x_max`: peak |x| over one steady period, m (a building's: of its `Quantity`, in its
      unit); `y_max`: the terminal's (the device's stroke) peak |y|, m; NaN where the
      orbit did not converge.
    - `converged`: the periodic orbit was found and verified (|Phi_T(z0) - z0| small).
    - `stable`: all Floquet multipliers inside the unit circle (only meaningful if
      converged), but for the multiplier 1 of a terminal stuck for the whole period (exact
      friction), along whose position the orbits form a neutral family.
    - `state`: the coordinates at phase 0 of the forcing on the periodic orbit, then their
      velocities, m and m/s: the floors, the stroke and a compliant device's mechanism
      (the paper's system: (x, y, x', y'), or (x, y, q, x', y', q')).
    - `residual`: periodicity residual, in units of the static displacement A / K.
    - `newton_steps`: shooting iterations used.
    - `floquet_multipliers`: eigenvalues of the monodromy matrix.
    - `monodromy`: the monodromy matrix dPhi_T/dz, in the scaled state units of
      `solve_orbit` (displacements in A / K, velocities in omega A / K).
    - `stick_fraction`: share of the period with |y'| below two friction widths (stuck,
      with exact friction).
    - `transitions`: changes per period of the terminal's state (stuck, slipping forwards,
      slipping backwards): 2 for a terminal that slips throughout, more with sticking, 0
      stuck throughout. Exact with exact friction (every transition is located); with
      smoothed friction, counted at the samples of the period as `stick_fraction` is.
    """

    omegas: Float[Array, "*freqs"]
    amplitudes: Float[Array, "*amps"]
    x_max: Float[Array, "*grid"]
    y_max: Float[Array, "*grid"]
    converged: Bool[Array, "*grid"]
    stable: Bool[Array, "*grid"]
    state: Float[Array, "*grid states"]
    residual: Float[Array, "*grid"]
    newton_steps: Int[Array, "*grid"]
    floquet_multipliers: Complex[Array, "*grid states"]
    monodromy: Float[Array, "*grid states states"]
    stick_fraction: Float[Array, "*grid"]
    transitions: Int[Array, "*grid"]


_GRID_FIELDS = tuple(f.name for f in dataclasses.fields(FrequencyResponse))[2:]


class _Solutions(eqx.Module):
    """The steady states at a flat list of points: `FrequencyResponse`'s per-point
    fields, each with a leading axis of points."""

    x_max: Float[Array, " points"]
    y_max: Float[Array, " points"]
    converged: Bool[Array, " points"]
    stable: Bool[Array, " points"]
    state: Float[Array, "points states"]
    residual: Float[Array, " points"]
    newton_steps: Int[Array, " points"]
    floquet_multipliers: Complex[Array, "points states"]
    monodromy: Float[Array, "points states states"]
    stick_fraction: Float[Array, " points"]
    transitions: Int[Array, " points"]
    unit: Float[Array, " points"]  # the unit of the scaled displacements, m

    def fields(self) -> dict:
        return {name: getattr(self, name) for name in _GRID_FIELDS}


def point_response(
    system: TIDSystem | BuildingTID,
    omega,
    amplitude,
    settings: SolverSettings,
    z_init=None,
    monodromy_init=None,
    quantity: Quantity = Quantity(),
    fields: tuple[str, ...] = (),
):
    """Single (omega, amplitude) point: the orbit (shooting from the scaled state `z_init`
    if given, with chord iterations first if `monodromy_init` is given; default the
    linear steady state after `settings.transient_periods` periods; see `solve_orbit`)
    and its peaks in SI: of `quantity` (a `TIDSystem`'s: its host's displacement) and
    of the stroke. Differentiable with respect to the system's fields (implicit
    differentiation through the orbit)."""
    settings = settings.for_system(system)
    _, _, unit_q, unit = point_model(system, quantity, amplitude, omega)
    orbit = solve_orbit(PlantInputs(system, amplitude, omega, quantity), settings, z_init,
                        monodromy_init, fields)
    # A failed integration gives non-finite samples: report +inf (and `converged` False).
    peaks = (refined_peak(orbit.x_samples) * unit_q,
             y_peak(orbit.y_samples, orbit.y_events, settings) * unit)
    x_max, y_max = (_finite_or_inf(peak) for peak in peaks)
    return orbit, x_max, y_max


def _finite_or_inf(value):
    return jnp.where(jnp.isfinite(value), value, jnp.inf)


def with_tuning(system: TIDSystem, stiffness, damping) -> TIDSystem:
    """`system` with the TID's stiffness k and damping c replaced (traceable, unchecked)."""
    return eqx.tree_at(lambda s: (s.tid_stiffness, s.tid_damping), system, (stiffness, damping))


@compiled(options=compiler_options)
def _points(systems, quantity, omegas, amplitudes, settings, warm, valid, use_warm):
    """Steady states at the points (`omegas[i]`, `amplitudes[i]`) of the systems `systems`
    (one per point, its fields batched: `TIDSystem`s, or `BuildingTID`s measuring
    `quantity`): shooting on work queues (`shoot_queue`, `settings.chunk` lanes per
    device), from the equivalent linear steady state after `settings.transient_periods`
    periods (integrated at `settings.coarse_rtol`) or, where `use_warm`, from the scaled
    states `warm`; the last Newton iteration samples each orbit and verifies its
    periodicity. Points where `valid` is False (padding) are skipped."""
    settings = settings.for_system(systems)
    # (a building's matrices: one point after the other, see `one_by_one`)
    each = ft.partial(one_by_one, floors=systems.floors)
    p, linear, unit_q, unit = each(lambda s, w, a: point_model(s, quantity, a, w))(
        systems, omegas, amplitudes)

    def start(q, z, warm_start, z_linear):
        z = jnp.where(warm_start, z, z_linear)
        return transient(z, q, settings.coarse(),
                         jnp.where(warm_start, 0, settings.transient_periods))

    chunk = settings.chunk

    def solve(q, w, use, z_linear, v):
        z0 = map_batch(lambda batch: start(*batch), (q, w, use, z_linear), chunk, v)
        return shoot_queue(z0, q, settings, chunk, v)

    shots = per_device(solve, p, warm, use_warm, linear, valid)
    samples, residual = shots.samples, shots.residual
    y_peaks = jax.vmap(lambda ys, events: y_peak(ys, events, settings))(samples.ys,
                                                                       samples.y_events)
    converged = (residual <= settings.periodicity_tol) & jnp.all(jnp.isfinite(samples.xs), -1)
    width = jax.vmap(lambda s, amplitude, omega: s.width_at(amplitude, omega))(
        systems, amplitudes, omegas)
    # (exact friction: width 0, and the samples of a stuck body's velocity are 0)
    stuck = jnp.abs(samples.ws * (omegas * unit)[:, None]) <= 2 * width[:, None]
    if settings.exact_friction:  # counted by the period map, each one located
        transitions = jnp.round(samples.transitions).astype(int)
    else:
        phase = jnp.where(stuck, 0, jnp.sign(samples.ws).astype(int))
        transitions = jnp.sum(phase != jnp.roll(phase, 1, axis=-1), axis=-1)
    # The peaks of an orbit that was not found are unknown: NaN, never a plausible number.
    return _Solutions(
        x_max=jnp.where(converged, jax.vmap(refined_peak)(samples.xs) * unit_q, jnp.nan),
        y_max=jnp.where(converged, y_peaks * unit, jnp.nan),
        converged=converged,
        stable=jnp.max(jnp.abs(each(lambda m: eigenvalues(moving_part(m)))(shots.monodromy)),
                       axis=-1) < 1,
        state=shots.state * state_units(unit, omegas, warm.shape[-1]),
        residual=residual,
        newton_steps=shots.newton_steps,
        floquet_multipliers=each(eigenvalues)(shots.monodromy),
        monodromy=shots.monodromy,
        stick_fraction=jnp.mean(stuck.astype(unit.dtype), axis=-1),
        transitions=transitions,
        unit=unit,
    )


def batched(system, count: int):
    """`system` (a `TIDSystem` or a `BuildingTID`) repeated `count` times: every field a
    NumPy array of `count` equal entries (the batched form, one system per point, that
    `solve_points` takes; on the host, so that no program is compiled, or loaded, for
    each count)."""
    return jax.tree.map(
        lambda leaf: np.broadcast_to(np.asarray(leaf, float), (count,) + np.shape(leaf)), system)


def state_count(systems) -> int:
    """The scaled states of `systems`' model."""
    if isinstance(systems, BuildingTID):
        return 2 * systems.coordinates
    return 6 if systems.compliant else 4


# Batches are solved in blocks of BLOCK points, the last one padded: padding costs little
# (the work queue and the chunks of `map_batch` skip it; a batch of a few points takes
# about 40 ms longer than in a block of its own size on the paper's system), and batches
# of every size share one compiled program, whichever sizes a run happens to meet first.
BLOCK = 512
# Rounds of shooting on at the points that came closest to their orbit (`solve_points`).
CONTINUATIONS = 2


def _block_sizes(count: int):
    """(start, stop, padded size) of the blocks of a batch of `count` points: as few as
    hold `BLOCK` points each, of equal sizes."""
    blocks = -(-count // BLOCK)
    for i in range(blocks):
        yield i * count // blocks, (i + 1) * count // blocks, BLOCK


def _on_host(tree):
    """Every array of `tree` as a NumPy array: the batches are cut, padded and put together
    on the host, so that no small program is compiled (or loaded) for each of those steps."""
    return jax.tree.map(np.asarray, tree)


def _solve_blocks(settings, batch, warm=None,
                  quantity: Quantity = Quantity()) -> _Solutions:
    """`_points` on the flat `batch = (omegas, amplitudes, systems)` (NumPy arrays), block
    by block: every block is shot from the states `warm` if given (else from the linear
    state after a transient), so that one compiled program serves every kind of call.
    The solutions are NumPy arrays."""
    omegas = batch[0]
    count = omegas.shape[0]
    use_warm = np.full(count, warm is not None)
    if warm is None:
        warm = np.zeros((count, state_count(batch[2])), omegas.dtype)
    outs = []
    arrays = settings.with_array_tolerances(batch[2])  # one program for any of their values
    for start, stop, size in _block_sizes(count):
        index = np.minimum(np.arange(start, start + size), stop - 1)  # repeat the last point
        valid = np.arange(start, start + size) < stop
        part = jax.tree.map(lambda a: a[index], (batch, warm, use_warm))
        out = sharded_batch(
            lambda b, w, u, v: _points(b[2], quantity, b[0], b[1], arrays, w, v, u), *part,
            valid)
        outs.append(jax.tree.map(lambda value, n=stop - start: np.asarray(value)[:n], out))
    return jax.tree.map(lambda *values: np.concatenate(values), *outs)


def solve_points(systems, omegas, amplitudes, settings: SolverSettings, warm=None,
                 quantity: Quantity = Quantity()) -> _Solutions:
    """Steady states at the flat lists of points (`omegas[i]`, `amplitudes[i]`) of the
    systems `systems` (one per point: `TIDSystem`s or `BuildingTID`s measuring
    `quantity`, their fields arrays, entry i for point i; see `batched`), in batches; with
    `warm` (scaled states), point i is shot from `warm[i]` (e.g. the orbit of a nearby
    design). A near miss (a finite periodicity residual above the tolerance) is first
    shot on from its own last state, integrated 100 times more accurately
    (`SolverSettings.more_accurate`), up to `CONTINUATIONS` times. Points that do not
    converge are solved again, from the equivalent linear steady state
    (`_period.building_start`), with each of the fallbacks of `settings` fitted to the
    systems (`SolverSettings.fallbacks`) in turn until they do (a point where no period
    could be integrated skips the explicit integrations); the best attempt is kept. Each
    block of the batch is sharded over all JAX devices (`sharded_batch`). The solutions are
    NumPy arrays."""
    batch = _on_host((omegas, amplitudes, systems))
    settings = for_points(settings, batch[2], batch[0], batch[1])
    out = _solve_blocks(settings, batch, None if warm is None else np.asarray(warm), quantity)
    # A near miss (a finite residual above the tolerance: its Newton iterations ran out
    # on an orbit that converges slowly, or stalled at the integration error of its
    # period map) is shot on from its own last state, integrated 100 times more
    # accurately, in the same compiled program (whose tolerances are its arguments), up
    # to `CONTINUATIONS` times before any fallback.
    for _ in range(CONTINUATIONS):
        near = np.flatnonzero(~out.converged & np.isfinite(out.residual))
        if not near.size:
            break
        part = jax.tree.map(lambda b, near=near: b[near], batch)
        own = out.state[near] / state_units(out.unit[near], part[0], out.state.shape[-1], np)
        out = _keep_better(out, _solve_blocks(settings.more_accurate(), part, own, quantity),
                           near)
    for fallback in settings.for_system(batch[2]).fallbacks():
        failed = ~out.converged
        if not (fallback.implicit or fallback.exact_friction):
            # A point where no period was integrated (residual inf: the explicit steps ran
            # out, or the state blew up) goes straight to the implicit attempt: more
            # accurate explicit steps would only run out sooner.
            failed &= np.isfinite(out.residual)
        failed = np.flatnonzero(failed)
        if not failed.size:
            continue
        retry = _solve_blocks(fallback, jax.tree.map(lambda b: b[failed], batch),
                              quantity=quantity)
        out = _keep_better(out, retry, failed)
    return out


def _keep_better(out: _Solutions, retry: _Solutions, points) -> _Solutions:
    """`out` with the results `retry` at its `points` where they converged and `out`'s did
    not, or where their residual is smaller (NumPy arrays)."""
    better = retry.converged & ~out.converged[points]
    better |= retry.residual < out.residual[points]
    chosen = points[better]

    def kept(value, new):
        value = value.copy()
        value[chosen] = new[better]
        return value

    return jax.tree.map(kept, out, retry)


def lane_response(systems: TIDSystem | BuildingTID, amplitudes, omegas, settings,
                  warm=None, quantity: Quantity = Quantity()) -> FrequencyResponse:
    """`FrequencyResponse` over lanes x frequencies: lane i is the system `systems[i]` (its
    fields batched, see `batched`) at the amplitude `amplitudes[i]` over the frequencies
    `omegas` (one grid for every lane, or one row per lane), every lane in one batch;
    with `warm` (scaled states, lanes x frequencies), each steady state is shot from its
    state there. A building's response is that of `quantity`."""
    amplitudes, omegas = np.asarray(amplitudes), np.asarray(omegas)
    shape = amplitudes.shape + omegas.shape[-1:]
    flat = lambda a: np.broadcast_to(a, shape).reshape(-1)
    lanes = jax.tree.map(
        lambda leaf: np.broadcast_to(np.asarray(leaf)[:, None], shape + np.shape(leaf)[1:])
        .reshape((-1,) + np.shape(leaf)[1:]), systems)
    if warm is not None:
        warm = np.asarray(warm).reshape((-1,) + warm.shape[2:])
    out = solve_points(lanes, flat(omegas), flat(amplitudes[:, None]), settings, warm,
                       quantity)
    # (placed on the device as they are: `jnp.asarray` would compile a program per shape)
    out = jax.tree.map(lambda value: jax.device_put(value.reshape(shape + value.shape[1:])), out)
    return FrequencyResponse(omegas=jax.device_put(omegas),
                             amplitudes=jax.device_put(amplitudes), **out.fields())


def static_units(systems) -> np.ndarray:
    """The unit of each lane's scaled displacements per unit load amplitude (`systems`
    batched, see `batched`): 1 / K of a `TIDSystem`, a building's `static_scale`."""
    if isinstance(systems, BuildingTID):
        return np.asarray(jax.vmap(lambda system: system.static_scale())(systems))
    return 1 / np.asarray(systems.host_stiffness)


def scaled_states(response: FrequencyResponse, units, xp=jnp) -> Float[Array, "amps freqs s"]:
    """The orbits' states of a `response` over lanes (amplitudes) x frequencies in the
    scaled units of `solve_orbit` (displacements in A d, velocities in omega A d, d
    `static_units`: one value or one per lane). With `xp=np`, computed on the host."""
    amplitudes, omegas, state = (xp.asarray(a) for a in (response.amplitudes,
                                                         response.omegas, response.state))
    unit = amplitudes[:, None] * xp.reshape(xp.asarray(units), (-1, 1))
    return state / state_units(unit, omegas, state.shape[-1], xp)
def frequency_response(
    system: TIDSystem | BuildingTID,
    omegas: ArrayLike,
    amplitudes: ArrayLike,
    *,
    quantity: Quantity | None = None,
    settings: SolverSettings | None = None,
) -> FrequencyResponse:
    """Steady-state response at every (amplitude, frequency) pair, found by shooting on the
    forcing period (all points solved in one batched call); with smoothed friction, or
    exact Coulomb friction where `system.friction_width` is 0.

    **Arguments:**

    - `system`: the `TIDSystem` (the paper's single-storey host) or a `BuildingTID` (a TID
      in a `Structure` of any number of floors).
    - `omegas`: forcing circular frequencies, rad/s (scalar or 1-d).
    - `amplitudes`: load amplitudes A of `A sin(omega t)`: N for a force, m/s2 for a
      building's ground acceleration (scalar or 1-d).
    - `quantity`: a building's measured response (`Quantity`; default the top floor's
      displacement). A `TIDSystem`'s response is its host's and its terminal's
      displacement (`as_building` measures any other quantity).
    - `settings`: `SolverSettings` of the shooting solver.

    **Returns:** a `FrequencyResponse`, arrays `(n_amplitudes, n_frequencies)` with the
    axis of a scalar input dropped. Points that fail to converge are flagged in
    `converged`.
    """
    settings = SolverSettings() if settings is None else settings
    quantity = checked_quantity(system, quantity, "frequency_response")
    omega_array = check_grid("omegas", omegas)
    amplitude_array = check_grid("amplitudes", amplitudes)
    dtype = jnp.result_type(float)
    amps = np.atleast_1d(np.asarray(amplitude_array, dtype))
    response = lane_response(batched(system, amps.size), amps,
                             np.atleast_1d(np.asarray(omega_array, dtype)), settings,
                             quantity=quantity)
    index = (0 if amplitude_array.ndim == 0 else slice(None),
             0 if omega_array.ndim == 0 else slice(None))
    return FrequencyResponse(
        omegas=jnp.asarray(omega_array, dtype=dtype),
        amplitudes=jnp.asarray(amplitude_array, dtype=dtype),
        **{name: getattr(response, name)[index] for name in _GRID_FIELDS},
    )
