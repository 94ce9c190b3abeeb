"""The best tuning of each scenario (forcing amplitude, host frequency scale): the
optimum that `retune` finds there, which the sensitivities and the robust design are
measured against."""

import functools as ft
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._model._building import BuildingTID, Quantity, checked_quantity
from .._model._checks import check_distinct, is_positive
from .._model._system import TIDSystem
from .._orbit._sampled_peaks import lane_grid_peaks, smooth_log_peak
from .._orbit._settings import SolverSettings
from .._peaks import _band
from .._response import batched
from .._retune import RetuneSettings, check_retune_options, optimal_tunings
from .._runtime._outcomes import Outcome, outcome_code
from .._runtime._parallel import serial
from ._design import parameter_values, parameters_of, scaled_hosts


class BestTunings(eqx.Module):
    """For each host-frequency scale and forcing amplitude, the retuned optimum: the tuning
    that `retune` finds (the minimiser of the smooth maximum over the band of the host
    displacement), and the peaks it achieves. Arrays are `[scales, amps]`; SI.

    - `system`: the nominal system; a scale s multiplies its host stiffness (a
      building's stiffness matrix) by s**2 (host frequency by s) and its band `omegas`
      (rad/s) by s; `quantity`: a building's measured response.
    - `tid_stiffness` (N/m), `tid_damping` (N s/m): the best tuning.
    - `host_peak`: peak |x| over the band's grid with it (refined by a parabola, as the
      robust design judges peaks), m; `stroke_peak`: peak |y|, m, on the check grid of
      `retune` (`RetuneSettings.check_refinement` times finer than the band).
    - `objective`: the smooth log peak over the band's grid (`smooth_log_peak`, of the
      sharpness `best_tunings` was given, ln m), the reference of the worst-case ratio of
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
    quantity: Quantity = Quantity()


def _scaled_lanes(system: TIDSystem | BuildingTID, scales) -> TIDSystem | BuildingTID:
    """One system per scale s (batched fields): host stiffness (a building's stiffness
    matrix) times s**2 and, keeping the TID's frequency ratio and damping ratio (Den
    Hartog's k scales with K and c with sqrt(k b)), TID stiffness times s**2 and damping
    times s."""
    scales = np.asarray(scales, float)
    lanes = scaled_hosts(batched(system, scales.size), scales)
    return eqx.tree_at(lambda s: (s.tid_stiffness, s.tid_damping), lanes,
                       (lanes.tid_stiffness * scales**2, lanes.tid_damping * scales))


@ft.partial(jax.jit, static_argnames="sharpness")
def _smooth_objective(values, omegas, sharpness: float):
    """`BestTunings.objective` from the host peaks `values` (m, lanes x frequencies), of
    the given `sharpness`."""
    return jax.vmap(lambda v, w: smooth_log_peak(v, w, sharpness))(values, omegas)


def best_tunings(
    system: TIDSystem | BuildingTID,
    amplitudes: ArrayLike,
    *,
    host_frequency_scales: ArrayLike = (1.0,),
    omegas: ArrayLike | None = None,
    settings: SolverSettings = SolverSettings(),
    max_steps: int = 60,
    tol: float = 1e-4,
    retune_settings: RetuneSettings = RetuneSettings(),
    objective_sharpness: float = 1000.0,
    progress: Callable[[str], None] | None = None,
    map_lanes: Callable = serial,
    quantity: Quantity | None = None,
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
    - `objective_sharpness`: sharpness of the smooth log peak `BestTunings.objective`, the
      reference of the robust design's ratios (by default that of the robust design's
      last stage, `RobustSettings.sharpness`).
    - `progress`: if given, called with a line as each step of the retune ends.
    - `map_lanes`: how the independent scenarios are mapped (see `retune`).
    - `quantity`: a building's measured response (`Quantity`, default the top floor's
      displacement); a scale s multiplies its stiffness matrix by s**2.

    **Returns:** a `BestTunings` (arrays `[scales, amps]`).
    """
    quantity = checked_quantity(system, quantity, "best_tunings")
    amps = check_distinct("amplitudes", amplitudes)
    scales = check_distinct("host_frequency_scales", host_frequency_scales)
    band = _band(system, omegas)
    check_retune_options(max_steps, tol, retune_settings)
    if not is_positive(objective_sharpness):
        raise ValueError("objective_sharpness must be a positive number, got "
                         f"{objective_sharpness!r}")
    lane_scales, lane_amps = (g.reshape(-1) for g in np.meshgrid(scales, amps, indexing="ij"))
    bands = jnp.asarray(lane_scales[:, None] * np.asarray(band)[None])
    result = optimal_tunings(
        _scaled_lanes(system, lane_scales), jnp.asarray(lane_amps), bands, settings=settings,
        max_steps=max_steps, tol=tol, retune_settings=retune_settings, progress=progress,
        map_lanes=map_lanes, quantity=quantity,
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
        objective=grid(_smooth_objective(on_band, bands, objective_sharpness)),
        iterations=grid(result.iterations),
        stationary=grid(np.asarray(result.status)
                        != outcome_code(Outcome.not_stationary)),
        converged=grid(result.converged),
        damping_at_bound=grid(result.damping_at_bound),
        quantity=quantity,
    )


def _fields(system) -> dict:
    """The physical parameters of `system` (`parameters_of`) and its friction width, by
    name: the tuning left out."""
    values = dict(zip(parameters_of(system), parameter_values(system), strict=False))
    values["friction_width"] = system.friction_width
    return {name: value for name, value in values.items()
            if name not in ("tid_stiffness", "tid_damping")}


def _same(a, b) -> bool:
    """Two field values agree (`None`, the default friction width, only with itself)."""
    if a is None or b is None:
        return a is b
    return bool(np.isclose(float(a), float(b), rtol=1e-12, atol=0.0))


def check_best(best, system: TIDSystem | BuildingTID) -> None:
    if not isinstance(best, BestTunings):
        raise ValueError(f"best must be a BestTunings, got {type(best).__name__}")
    nominal, given = best.system, system
    layout = lambda s: (type(s), s.compliant) + ((
        s.floors, s.spring_floor, s.inerter_floor, s.load) if isinstance(s, BuildingTID) else ())
    if layout(nominal) != layout(given):
        raise ValueError("best was computed for another system: another kind of system, "
                         "device or placement")
    nominal, given = _fields(nominal), _fields(given)
    different = [name for name in nominal if not _same(nominal[name], given[name])]
    if different:
        raise ValueError(
            f"best was computed for another system: {different[0]} is "
            f"{nominal[different[0]]!r} there and {given[different[0]]!r} here"
        )


def checked_best(system, amps, scales, best, omegas, settings, retune_settings, progress,
                 map_lanes, quantity: Quantity = Quantity()):
    """`best` after checking that it was computed for this system, quantity, these
    scenarios and this band, or, if None, the best tunings found afresh."""
    if best is None:
        return best_tunings(system, amps, host_frequency_scales=scales, omegas=omegas,
                            settings=settings, retune_settings=retune_settings,
                            progress=progress, map_lanes=map_lanes, quantity=quantity)
    check_best(best, system)
    if best.quantity != quantity:
        raise ValueError(f"best was computed for another quantity: {best.quantity} there, "
                         f"{quantity} here")
    for name, given in (("amplitudes", amps), ("host_frequency_scales", scales)):
        stored = np.asarray(getattr(best, name))
        if stored.shape != given.shape or not np.allclose(stored, given, rtol=1e-12):
            raise ValueError(f"{name} {given.tolist()} differ from best's {stored.tolist()}")
    if omegas is not None:
        band = _band(system, omegas)
        if band.shape != best.omegas.shape or not np.allclose(band, best.omegas):
            raise ValueError("omegas differ from the band best was computed on")
    return best
