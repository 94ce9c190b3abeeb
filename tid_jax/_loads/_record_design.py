"""Design of the TID with its friction over a suite of recorded ground motions: the
(k, c) that minimise the mean over the records of the response's peak.

Each candidate steps every record as `friction_history` does, all records padded to the
longest and stepped together in one compiled program (vmap), the peaks and RMS read at
the records' own samples: a rigid device with exact friction (the default) by the exact
stick-slip flow of `_record_flow` (events located), and only where that flow does not
apply (smoothed friction, a compliant device) or where a `time_step` is given, with the
friction held over substeps (Monte Carlo's scheme). The mean peak is continuous but not
smooth in (k, c) (a peak moves from one instant to another), so optimistix's
Nelder-Mead minimises it over (ln k, ln c), restarted from where it stops until a
restart no longer improves. Bounds on (k, c) hold the objective at the
nearest point within them plus `BOUND_PENALTY` times the distance outside. A stroke
limit enters as an exact penalty, `STROKE_PENALTY` times the excess of ln(largest
stroke peak / limit): once the weight exceeds the constraint's multiplier (the decrease
of ln(mean peak) per unit of ln(stroke) along the limit, below 1 on the paper's TID)
the penalised minimum is the constrained one.
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from .._model._building import BuildingTID, Quantity, building_of, log_tuned, log_tuning_of
from .._model._system import TIDSystem, check_values
from ._monte_carlo import (
    CHUNK,
    check_system,
    first_period,
    record_stepper,
    run,
    substeps,
    uses_exact_flow,
)
from ._random_design import check_bounds, default_bounds
from ._record_flow import MAX_EVENTS, grid_points, march, outputs, record_flow, summary
from ._records import GroundMotion

STROKE_PENALTY = 10.0
# the weight of the distance (in ln k, ln c) outside the bounds, where the objective is
# that at the nearest point within them: any positive weight keeps the minimum within
BOUND_PENALTY = 1.0
# The limit is aimed this fraction below the given one: the simplex stops within its
# tolerance of the kink.
STROKE_MARGIN = 1e-3
MAX_RESTARTS = 8


class RecordDesign(eqx.Module):
    """The design over a suite of records: `names`; the (k, c) that minimise the mean
    peak, `tid_stiffness` and `tid_damping` (N/m, N s/m), and whether Nelder-Mead
    `converged`; per record the quantity's `peak_before` and `rms_before` (SI) with the
    given tuning, and `peak_after`, `rms_after` with the design; the stroke's peak per
    record, `stroke_peak_before` and `stroke_peak_after` (m); the `stroke_limit` (m, None
    for none) and whether the design's every stroke peak is `within_stroke_limit`; the
    bounds, `stiffness_bounds` (N/m) and `damping_bounds` (N s/m), each (low, high), and
    whether the design is `at_bound` (its ln k or ln c within Nelder-Mead's tolerance of
    a bound's)."""

    names: tuple[str, ...] = eqx.field(static=True)
    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    converged: Bool[Array, ""]
    peak_before: Float[Array, " records"]
    rms_before: Float[Array, " records"]
    peak_after: Float[Array, " records"]
    rms_after: Float[Array, " records"]
    stroke_peak_before: Float[Array, " records"]
    stroke_peak_after: Float[Array, " records"]
    stroke_limit: float | None = eqx.field(static=True)
    within_stroke_limit: Bool[Array, ""]
    stiffness_bounds: Float[Array, " 2"]
    damping_bounds: Float[Array, " 2"]
    at_bound: Bool[Array, ""]


class _Suite(eqx.Module):
    """The records of a design, stepped together: `statistics` gives each record's peak
    and RMS of the quantity and its stroke peak (m) over its samples, from rest."""

    @abc.abstractmethod
    def statistics(self, system: BuildingTID, quantity: Quantity):
        raise NotImplementedError


class _ExactSuite(_Suite):
    """The records padded to the longest, `(records, samples)` (m/s2), their time steps
    (s) and last samples, stepped by the exact stick-slip flow at `grid` points a step."""

    accelerations: Float[Array, "records samples"]
    time_steps: Float[Array, " records"]
    lasts: Int[Array, " records"]
    grid: int = eqx.field(static=True)
    max_events: int = eqx.field(static=True)

    def statistics(self, system, quantity):
        def one(record):
            acceleration, time_step, last = record
            flow = record_flow(system, time_step, self.grid, self.max_events)
            states, _, forces, capped = march(flow, acceleration, last)
            values, stroke = outputs(system, quantity, acceleration, states, forces)
            counted = jnp.arange(acceleration.shape[0]) <= last
            return summary(values, stroke, counted, capped)

        # (one record after another: vmap's records in step wait for each other's events)
        return jax.lax.map(one, (self.accelerations, self.time_steps, self.lasts))


class _HeldSuite(_Suite):
    """The records as padded substep inputs `(records, steps, 2)`, the weights of the
    substeps that end on a record's sample, the substep of each record (s) and the
    number of samples each weighs."""

    inputs: Float[Array, "records steps 2"]
    weights: Float[Array, "records steps"]
    time_steps: Float[Array, " records"]
    counts: Float[Array, " records"]
    chunks: int = eqx.field(static=True)

    def statistics(self, system, quantity):
        def one(inputs, weights, time_step):
            stepper = record_stepper(system, quantity, time_step)

            def chunk_inputs(c):
                start = c * CHUNK
                return (jax.lax.dynamic_slice_in_dim(inputs, start, CHUNK)[:, None],
                        jax.lax.dynamic_slice_in_dim(weights, start, CHUNK))

            squares, peaks, _ = run(stepper, jnp.zeros((1, stepper.phi.shape[0])),
                                    chunk_inputs, self.chunks)
            start = stepper.out_inputs[0, 0] * inputs[0, 0]  # at rest: the ground's own part
            return (jnp.maximum(peaks[0, 0], jnp.abs(start)), squares[0, 0] + start**2,
                    peaks[0, 1])

        peaks, squares, strokes = jax.vmap(one)(self.inputs, self.weights, self.time_steps)
        return peaks, jnp.sqrt(squares / (self.counts + 1)), strokes


def _exact_suite(system: BuildingTID, motions, box, max_events: int) -> _ExactSuite:
    """The exact flow's suite, its grid enough for every record's step at the system's
    tuning and at the corners of the bounds `box` (ln k, ln c)."""
    longest = max(motion.acceleration.shape[0] for motion in motions)
    accelerations = np.zeros((len(motions), longest))
    for r, motion in enumerate(motions):
        accelerations[r, :motion.acceleration.shape[0]] = np.asarray(motion.acceleration)
    corners = [system] + [log_tuned(system, jnp.asarray([k, c]))
                          for k in box[0] for c in box[1]]
    grid = max(grid_points(s, m.time_step) for s in corners for m in motions)
    return _ExactSuite(jnp.asarray(accelerations),
                       jnp.asarray([m.time_step for m in motions]),
                       jnp.asarray([m.acceleration.shape[0] - 1 for m in motions]),
                       grid, max_events)


def _held_suite(motions, time_step: float) -> _HeldSuite:
    parts = [substeps(motion, time_step) for motion in motions]
    longest = max(inputs.shape[0] for _, inputs in parts)
    chunks = -(-longest // CHUNK)
    inputs = np.zeros((len(parts), chunks * CHUNK, 2))
    weights = np.zeros((len(parts), chunks * CHUNK))
    for r, (count, values) in enumerate(parts):
        inputs[r, :values.shape[0]] = values
        weights[r, count - 1:values.shape[0]:count] = 1.0
    steps = [motion.time_step / count for motion, (count, _) in zip(motions, parts, strict=True)]
    return _HeldSuite(inputs=jnp.asarray(inputs), weights=jnp.asarray(weights),
                      time_steps=jnp.asarray(steps),
                      counts=jnp.asarray(weights.sum(axis=1)), chunks=chunks)


def _objective(log_tuning, args):
    # (Nelder-Mead's shrink evaluates a batch of vertices: one after another, as vmap's
    # vertices in step would wait for each other's events)
    return jax.custom_batching.sequential_vmap(_penalised)(log_tuning, args)


def _penalised(log_tuning, args):
    system, quantity, suite, box, log_limit = args
    inside = jnp.clip(log_tuning, box[:, 0], box[:, 1])
    peaks, _, strokes = suite.statistics(log_tuned(system, inside), quantity)
    excess = jnp.maximum(jnp.log(jnp.max(strokes)) - log_limit, 0.0)
    value = jnp.log(jnp.mean(peaks)) + STROKE_PENALTY * excess
    # a failed solve (NaN) is no candidate
    return jnp.nan_to_num(value, nan=jnp.inf) + BOUND_PENALTY * jnp.sum(
        jnp.abs(log_tuning - inside))


@eqx.filter_jit
def _design(system, quantity, suite, box, log_limit, rtol, max_steps):
    """Nelder-Mead from the system's tuning, restarted from its end (a fresh simplex) while
    a restart lowers the objective by more than `rtol` of it, at most `MAX_RESTARTS`
    times: a simplex may collapse short of a minimum on a kink (a bound, the stroke
    limit, a peak moving from one instant to another)."""
    args = (system, quantity, suite, box, log_limit)
    solver = optx.NelderMead(rtol=rtol, atol=rtol)

    def minimise(log_tuning):
        solution = optx.minimise(_objective, solver, log_tuning, args=args, throw=False,
                                 max_steps=max_steps)
        return (solution.value, _penalised(solution.value, args),
                solution.result == optx.RESULTS.successful, solution.stats["num_steps"])

    def improving(carry):
        _, value, previous, _, _, restarts = carry
        return (restarts < MAX_RESTARTS) & (value < previous - rtol * jnp.abs(previous))

    def restart(carry):
        log_tuning, value, _, _, steps, restarts = carry
        found, found_value, converged, more = minimise(log_tuning)
        better = found_value < value
        return (jnp.where(better, found, log_tuning), jnp.minimum(found_value, value), value,
                converged, steps + more, restarts + 1)

    found, value, converged, steps = minimise(
        jnp.clip(log_tuning_of(system), box[:, 0], box[:, 1]))
    found, _, _, converged, steps, _ = jax.lax.while_loop(
        improving, restart, restart((found, value, value, converged, steps, 0)))
    return jnp.clip(found, box[:, 0], box[:, 1]), converged, steps


@eqx.filter_jit
def suite_statistics(system: BuildingTID, quantity: Quantity, suite: _Suite):
    """Each record's peak and RMS of `quantity` and its stroke peak (one program for the
    tuning before and after the design)."""
    return suite.statistics(system, quantity)


def _checked(system, motions, quantity, stroke_limit, max_events):
    """The system as a building, the motions as a list and the stroke limit as a float,
    or ValueError."""
    system = building_of(system, "ground")
    check_system(system)
    quantity.floor_of(system.floors)
    if system.load != "ground":
        raise ValueError("recorded ground motions need a system with load='ground'")
    motions = list(motions)
    if not motions or not all(isinstance(m, GroundMotion) for m in motions):
        raise ValueError("motions must be a non-empty list of tid_jax.GroundMotion")
    if system.friction_width is None:
        raise ValueError("under records give friction_width: 0 (exact) or a velocity (m/s)")
    if isinstance(max_events, bool) or not isinstance(max_events, int) or max_events < 0:
        raise ValueError(f"max_events must be a non-negative integer, got {max_events!r}")
    if stroke_limit is not None:
        check_values("stroke_limit", stroke_limit, "positive")
        stroke_limit = float(stroke_limit)
    return system, motions, stroke_limit


def design_for_records(system: BuildingTID | TIDSystem, motions,
                       quantity: Quantity = Quantity(), *, bounds=None,
                       stroke_limit: float | None = None, time_step: float | None = None,
                       max_events: int = MAX_EVENTS, tol: float = 1e-4,
                       max_steps: int = 400) -> RecordDesign:
    """The TID's (k, c) minimising the mean peak of `quantity` over the ground motions
    `motions` (a list of `GroundMotion`, each as given: scale them first), with the
    system's friction (exact, or smoothed with a given `friction_width`), from the
    system's own tuning (held in the bounds), within `bounds`, `((k_low, k_high),
    (c_low, c_high))` (N/m, N s/m; None: `default_bounds`), with every record's stroke
    peak within `stroke_limit` (m; None: no limit); `tol`: Nelder-Mead's tolerance. A
    `TIDSystem` is its host under the records.

    Each record is stepped as `friction_history` steps it: a rigid device with exact
    friction by the exact stick-slip flow (at most `max_events` events a record step;
    a candidate whose solve fails counts as infinite), and with a `time_step` (s), or
    for smoothed friction or a compliant device, with the friction held over substeps
    of at most `time_step` (default the first mode's period / 200)."""
    system, motions, stroke_limit = _checked(system, motions, quantity, stroke_limit,
                                             max_events)
    box = check_bounds(default_bounds(system) if bounds is None else bounds)
    log_box = np.log(box)
    if uses_exact_flow(system, time_step):
        suite = _exact_suite(system, motions, log_box, max_events)
    else:
        suite = _held_suite(motions, first_period(system) / 200 if time_step is None
                            else time_step)
    log_limit = (jnp.asarray(jnp.inf) if stroke_limit is None
                 else jnp.log(stroke_limit * (1 - STROKE_MARGIN)))
    design, converged, _ = _design(system, quantity, suite, jnp.asarray(log_box), log_limit,
                                   tol, max_steps)
    before = suite_statistics(system, quantity, suite)
    after = suite_statistics(log_tuned(system, design), quantity, suite)
    # (within the bounds also after rounding: exp(ln 150) may be 149.99999999999997)
    k, c = jnp.clip(jnp.exp(design), box[:, 0], box[:, 1])
    within = (jnp.asarray(True) if stroke_limit is None
              else jnp.max(after[2]) <= stroke_limit)
    return RecordDesign(names=tuple(m.name for m in motions), tid_stiffness=k, tid_damping=c,
                        converged=converged, peak_before=before[0], rms_before=before[1],
                        peak_after=after[0], rms_after=after[1],
                        stroke_peak_before=before[2], stroke_peak_after=after[2],
                        stroke_limit=stroke_limit, within_stroke_limit=within,
                        stiffness_bounds=jnp.asarray(box[0]),
                        damping_bounds=jnp.asarray(box[1]),
                        at_bound=jnp.any(jnp.abs(design[:, None] - log_box)
                                         <= tol * (1 + jnp.abs(design[:, None]))))
