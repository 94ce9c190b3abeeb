"""Design of the TID with its friction over a suite of recorded ground motions: the
(k, c) that minimise the mean over the records of the response's peak.

Each record is stepped with the friction held over substeps of at most h (Monte Carlo's
scheme, `friction_history` with `time_step=h`; the record a straight line between its
samples); the records are padded to the longest and stepped together, and the peaks and
RMS are read at the records' own samples. The mean peak is continuous but not smooth in
(k, c) (a peak moves from one instant to another), so optimistix's Nelder-Mead minimises
it over (ln k, ln c). A stroke limit enters as an exact penalty, `STROKE_PENALTY` times
the excess of ln(largest stroke peak / limit): once the weight exceeds the constraint's
multiplier (the decrease of ln(mean peak) per unit of ln(stroke) along the limit, below
1 on the paper's TID) the penalised minimum is the constrained one.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float

from .._model._building import BuildingTID, Quantity, building_of, log_tuned, log_tuning_of
from .._model._system import TIDSystem, check_values
from ._monte_carlo import CHUNK, check_system, first_period, record_stepper, run, substeps
from ._records import GroundMotion

STROKE_PENALTY = 10.0
# The limit is aimed this fraction below the given one: the simplex stops within its
# tolerance of the kink.
STROKE_MARGIN = 1e-3


class RecordDesign(eqx.Module):
    """The design over a suite of records: `names`; the (k, c) that minimise the mean
    peak, `tid_stiffness` and `tid_damping` (N/m, N s/m), and whether Nelder-Mead
    `converged`; per record the quantity's `peak_before` and `rms_before` (SI) with the
    given tuning, and `peak_after`, `rms_after` with the design; the stroke's peak per
    record, `stroke_peak_before` and `stroke_peak_after` (m); the `stroke_limit` (m, None
    for none) and whether the design's every stroke peak is `within_stroke_limit`."""

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


class _Suite(eqx.Module):
    """The records as padded substep inputs `(records, steps, 2)`, the weights of the
    substeps that end on a record's sample, the substep of each record (s) and the
    number of samples each weighs."""

    inputs: Float[Array, "records steps 2"]
    weights: Float[Array, "records steps"]
    time_steps: Float[Array, " records"]
    counts: Float[Array, " records"]
    chunks: int = eqx.field(static=True)


def _suite(motions, time_step: float) -> _Suite:
    parts = [substeps(motion, time_step) for motion in motions]
    longest = max(inputs.shape[0] for _, inputs in parts)
    chunks = -(-longest // CHUNK)
    inputs = np.zeros((len(parts), chunks * CHUNK, 2))
    weights = np.zeros((len(parts), chunks * CHUNK))
    for r, (count, values) in enumerate(parts):
        inputs[r, :values.shape[0]] = values
        weights[r, count - 1:values.shape[0]:count] = 1.0
    steps = [motion.time_step / count for motion, (count, _) in zip(motions, parts)]
    return _Suite(inputs=jnp.asarray(inputs), weights=jnp.asarray(weights),
                  time_steps=jnp.asarray(steps), counts=jnp.asarray(weights.sum(axis=1)),
                  chunks=chunks)


def suite_statistics(system: BuildingTID, quantity: Quantity, suite: _Suite):
    """The peak and the RMS of `quantity` and the stroke's peak over each record's
    samples, from rest (as `friction_history` with `time_step`)."""

    def one(inputs, weights, time_step):
        stepper = record_stepper(system, quantity, time_step)

        def chunk_inputs(c):
            start = c * CHUNK
            return (jax.lax.dynamic_slice_in_dim(inputs, start, CHUNK)[:, None],
                    jax.lax.dynamic_slice_in_dim(weights, start, CHUNK))

        squares, peaks, _ = run(stepper, jnp.zeros((1, stepper.phi.shape[0])), chunk_inputs,
                                suite.chunks)
        start = stepper.out_inputs[0, 0] * inputs[0, 0]  # at rest: the ground's own part
        return (jnp.maximum(peaks[0, 0], jnp.abs(start)), squares[0, 0] + start**2,
                peaks[0, 1])

    peaks, squares, strokes = jax.vmap(one)(suite.inputs, suite.weights, suite.time_steps)
    return peaks, jnp.sqrt(squares / (suite.counts + 1)), strokes


def _objective(log_tuning, args):
    system, quantity, suite, log_limit = args
    peaks, _, strokes = suite_statistics(log_tuned(system, log_tuning), quantity, suite)
    excess = jnp.maximum(jnp.log(jnp.max(strokes)) - log_limit, 0.0)
    return jnp.log(jnp.mean(peaks)) + STROKE_PENALTY * excess


@eqx.filter_jit
def _design(system, quantity, suite, log_limit, rtol, max_steps):
    start = log_tuning_of(system)
    solution = optx.minimise(_objective, optx.NelderMead(rtol=rtol, atol=rtol), start,
                             args=(system, quantity, suite, log_limit), throw=False,
                             max_steps=max_steps)
    before = suite_statistics(system, quantity, suite)
    after = suite_statistics(log_tuned(system, solution.value), quantity, suite)
    return solution.value, solution.result == optx.RESULTS.successful, before, after


def design_for_records(system: BuildingTID | TIDSystem, motions,
                       quantity: Quantity = Quantity(), *,
                       stroke_limit: float | None = None, time_step: float | None = None,
                       tol: float = 1e-4, max_steps: int = 400) -> RecordDesign:
    """The TID's (k, c) minimising the mean peak of `quantity` over the ground motions
    `motions` (a list of `GroundMotion`, each as given: scale them first), with the
    system's friction (exact, or smoothed with a given `friction_width`), from the
    system's own tuning, with every record's stroke peak within `stroke_limit` (m; None:
    no limit); substeps of at most `time_step` (s; default the first mode's period /
    200); `tol`: Nelder-Mead's tolerance. A `TIDSystem` is its host under the records."""
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
    if stroke_limit is not None:
        check_values("stroke_limit", stroke_limit, "positive")
        stroke_limit = float(stroke_limit)
    h = first_period(system) / 200 if time_step is None else time_step
    log_limit = (jnp.asarray(jnp.inf) if stroke_limit is None
                 else jnp.log(stroke_limit * (1 - STROKE_MARGIN)))
    design, converged, before, after = _design(system, quantity, _suite(motions, h),
                                               log_limit, tol, max_steps)
    k, c = jnp.exp(design)
    within = (jnp.asarray(True) if stroke_limit is None
              else jnp.max(after[2]) <= stroke_limit)
    return RecordDesign(names=tuple(m.name for m in motions), tid_stiffness=k, tid_damping=c,
                        converged=converged, peak_before=before[0], rms_before=before[1],
                        peak_after=after[0], rms_after=after[1],
                        stroke_peak_before=before[2], stroke_peak_after=after[2],
                        stroke_limit=stroke_limit, within_stroke_limit=within)
