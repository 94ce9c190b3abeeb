"""Monte Carlo simulation of the TID with its friction under stationary random loads and
recorded ground motions: many realisations stepped together, with standard errors.

Each time step h advances the linear part exactly (matrix exponentials) with the friction
force F held over the step and fixed by the friction's coordinate velocity at the step's
end, `v = v* + gain F` (v* without friction; `gain` > 0, the step's velocity per unit
force):

- exact Coulomb friction (`friction_width` 0): the set-valued law `F in -ff Sgn(v)`,
  solved in closed form, `F = clip(-v* / gain, -ff, ff)`: the coordinate is held
  (v = 0) while the force that holds it is within ff, and slips against ff otherwise.
  The step is first order in h for the friction and exact for the rest;
- smoothed friction (`friction_width` > 0, or None: `FRICTION_WIDTH_RATIO` times the
  frictionless RMS velocity of the friction's coordinate): `F = -ff tanh(v / width)`,
  solved by bisection and two Newton steps (its first and second derivatives are those
  of the implicit root).

Both maps are continuous and piecewise smooth in the design, so that derivatives along
the paths (common random numbers) are those of the estimate.

A stationary load's white noise is held over each step, `w_n ~ N(0, 2 pi S0 / h)`
(two-sided S0 over angular frequency), and drives the joint state of the structure, the
TID and the load's filter; each realisation starts from the frictionless stationary
state and a transient is discarded. An `envelope` (e.g. `jennings_envelope`) multiplies
the white noise for a non-stationary motion, from rest. A recorded motion is a straight
line between its samples, as in `linear_history`, on substeps of at most h.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._model._building import BuildingTID, Quantity, building_of, selection, state_space
from .._model._system import FRICTION_WIDTH_RATIO, TIDSystem
from ._record_flow import MAX_EVENTS, exact_history
from ._records import GroundMotion, History, propagators
from ._stationary import StationaryLoad, joint_state_space, quantity_row, stationary_covariance

CHUNK = 256  # steps between checkpoints of the reverse-mode derivative
_BISECTIONS = 48


class MonteCarloSettings(eqx.Module):
    """Monte Carlo's knobs: `samples` realisations of `duration` (s) each, of which the
    first `transient` (s; None: 20 periods of the first mode with the TID) are discarded;
    the `time_step` (s; None: that period / 200); the random `seed`."""

    samples: int = 200
    duration: float = 60.0
    transient: float | None = None
    time_step: float | None = None
    seed: int = 0

    def __check_init__(self):
        if isinstance(self.samples, bool) or not isinstance(self.samples, int) or (
                self.samples < 2):
            raise ValueError(f"samples must be an integer of at least 2, got {self.samples!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")
        for name in ("duration", "transient", "time_step"):
            value = getattr(self, name)
            if value is None and name != "duration":
                continue
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number of seconds, got {value!r}")
        if self.transient is not None and self.transient >= self.duration:
            raise ValueError(f"transient ({self.transient} s) must be shorter than duration "
                             f"({self.duration} s)")


class MonteCarlo(eqx.Module):
    """Monte Carlo statistics of a response (SI): `rms` (the square root of the mean of
    the realisations' mean squares) and `peak` (the mean of their peaks |value|), with
    standard errors `rms_se` (by the delta method) and `peak_se`; the stroke's
    `stroke_rms` and `stroke_peak` (m, mean peak); the realisations' `mean_squares` and
    `peaks`; the `time_step` (s) and the counted `duration` (s) of each realisation."""

    rms: Float[Array, ""]
    rms_se: Float[Array, ""]
    peak: Float[Array, ""]
    peak_se: Float[Array, ""]
    stroke_rms: Float[Array, ""]
    stroke_peak: Float[Array, ""]
    mean_squares: Float[Array, " samples"]
    peaks: Float[Array, " samples"]
    time_step: float = eqx.field(static=True)
    duration: float = eqx.field(static=True)


class Stepper(eqx.Module):
    """One step of the joint state z: `z' = phi z + inputs u + friction F`, and the
    outputs (the quantity, the stroke) at its end, `out z + out_friction F +
    out_inputs u`."""

    phi: Float[Array, "n n"]
    inputs: Float[Array, "n p"]
    friction: Float[Array, " n"]
    out: Float[Array, "2 n"]
    out_friction: Float[Array, " 2"]
    out_inputs: Float[Array, "2 p"]
    friction_force: Float[Array, ""]
    width: Float[Array, ""]
    velocity: int = eqx.field(static=True)
    exact: bool = eqx.field(static=True)

    def __call__(self, z, u):
        z, y, _ = self.advance(z, u)
        return z, y

    def advance(self, z, u):
        """The state and the outputs at the step's end, and the friction force held."""
        free = z @ self.phi.T + u @ self.inputs.T
        trial = free[..., self.velocity]
        gain = self.friction[self.velocity]
        force = _friction(trial, gain, self.friction_force, self.width, self.exact)
        z = free + force[..., None] * self.friction
        y = z @ self.out.T + force[..., None] * self.out_friction + u @ self.out_inputs.T
        return z, y, force


def _friction(trial, gain, ff, width, exact):
    """F with `v = trial + gain F` and F = -ff Sgn(v) (exact) or -ff tanh(v / width)."""
    if exact:
        return jnp.clip(-trial / gain, -ff, ff)
    residual = lambda v: v - trial + gain * ff * jnp.tanh(v / width)

    def bisect(_, bounds):
        low, high = bounds
        middle = 0.5 * (low + high)
        up = residual(middle) > 0
        return jnp.where(up, low, middle), jnp.where(up, middle, high)

    low = jax.lax.stop_gradient(jnp.minimum(trial, 0.0))
    high = jax.lax.stop_gradient(jnp.maximum(trial, 0.0))
    low, high = jax.lax.fori_loop(0, _BISECTIONS, bisect, (low, high))
    v = jax.lax.stop_gradient(0.5 * (low + high))
    # two Newton steps from the bracketed root: the first gives the implicit first
    # derivatives, the second the second derivatives too
    for _ in range(2):
        slope = 1 + gain * ff / width * (1 - jnp.tanh(v / width) ** 2)
        v = v - residual(v) / slope
    return -ff * jnp.tanh(v / width)


def check_system(system: BuildingTID):
    if not isinstance(system, BuildingTID):
        raise ValueError("system must be a tid_jax.BuildingTID (tid_jax.as_building turns "
                         "a TIDSystem into one)")
    if np.any(np.asarray(system.backlash) > 0):
        raise ValueError("Monte Carlo does not model backlash: give backlash=0")


def check_load(system: BuildingTID, load: StationaryLoad, quantity: Quantity) -> None:
    """A `ValueError` naming what Monte Carlo cannot take of these."""
    check_system(system)
    quantity.floor_of(system.floors)
    if not isinstance(load, StationaryLoad):
        raise ValueError("load must be a tid_jax.StationaryLoad")
    if not isinstance(quantity, Quantity):
        raise ValueError("quantity must be a tid_jax.Quantity")


def _friction_direction(system: BuildingTID, size: int):
    """The joint state's rate per unit friction force on the last coordinate."""
    mass, _, _ = system.generalised_matrices()
    m = system.coordinates
    unit = jnp.zeros(m).at[-1].set(1.0)
    return jnp.zeros(size).at[m:2 * m].set(jnp.linalg.solve(mass, unit))


def first_period(system: BuildingTID) -> float:
    """The period (s) of the lowest undamped mode of the structure with the TID."""
    mass, _, stiffness = (np.asarray(a) for a in system.generalised_matrices())
    values = np.linalg.eigvals(np.linalg.solve(mass, stiffness)).real
    return 2 * math.pi / math.sqrt(np.min(values[values > 0]))


def _width(system: BuildingTID, load: StationaryLoad | None):
    if system.exact_friction:
        return jnp.asarray(0.0)
    if system.friction_width is not None:
        return system.friction_width
    if load is None:
        raise ValueError("under a record give friction_width: 0 (exact) or a velocity (m/s)")
    P = stationary_covariance(system, load)  # (the friction left out)
    index = 2 * system.coordinates - 1
    return FRICTION_WIDTH_RATIO * jnp.sqrt(P[index, index])


def _rows(system: BuildingTID, quantity: Quantity, A, friction, size: int):
    """The quantity's and the stroke's rows over the joint state, their friction and
    their acceleration's part of the structure's own input rate (for an acceleration)."""
    m = system.coordinates
    w, wd, kappa, acceleration = selection(system, quantity)
    stroke = jnp.zeros(size).at[system.floors].set(1.0)
    if not acceleration:
        row = jnp.zeros(size).at[:m].set(jnp.asarray(w))
        return jnp.stack([row, stroke]), jnp.zeros(2), jnp.asarray(wd), kappa
    row = jnp.asarray(wd) @ A[m:2 * m]
    return (jnp.stack([row, stroke]), jnp.stack([jnp.asarray(wd) @ friction[m:2 * m], 0.0]),
            jnp.asarray(wd), kappa)


def stationary_stepper(system: BuildingTID, load: StationaryLoad, quantity: Quantity,
                       time_step) -> Stepper:
    """The step under a stationary load, its input one unit normal number a step."""
    A, B = joint_state_space(system, load)
    size = A.shape[0]
    friction = _friction_direction(system, size)
    phi, noise, _ = propagators(A, B, time_step)
    _, held, _ = propagators(A, friction, time_step)
    scale = jnp.sqrt(2 * jnp.pi * load.psd / time_step)
    out, out_friction, _, _ = _rows(system, quantity, A, friction, size)
    out = out.at[0].set(quantity_row(system, load, quantity, A))
    return Stepper(phi=phi, inputs=(noise * scale)[:, None], friction=held, out=out,
                   out_friction=out_friction, out_inputs=jnp.zeros((2, 1)),
                   friction_force=system.friction_force, width=_width(system, load),
                   velocity=2 * system.coordinates - 1, exact=system.exact_friction)


def record_stepper(system: BuildingTID, quantity: Quantity, time_step) -> Stepper:
    """The step under a ground motion, its inputs the acceleration at the step's start
    and its slope over the step."""
    A, g = state_space(system)
    size = A.shape[0]
    friction = _friction_direction(system, size)
    phi, start, slope = propagators(A, g, time_step)
    _, held, _ = propagators(A, friction, time_step)
    out, out_friction, wd, kappa = _rows(system, quantity, A, friction, size)
    m = system.coordinates
    direct = jnp.where(quantity.kind == "acceleration", wd @ g[m:] + kappa, 0.0)
    out_inputs = jnp.zeros((2, 2)).at[0].set(direct * jnp.stack([1.0, time_step]))
    return Stepper(phi=phi, inputs=jnp.stack([start, slope], axis=1), friction=held, out=out,
                   out_friction=out_friction, out_inputs=out_inputs,
                   friction_force=system.friction_force, width=_width(system, None),
                   velocity=2 * system.coordinates - 1, exact=system.exact_friction)


def run(stepper: Stepper, z0, chunk_inputs, chunks: int, keep: bool = False):
    """Step `z0` (..., n) over `chunks` chunks of `CHUNK` steps, the chunk c's inputs
    and weights `chunk_inputs(c)` ((steps, ..., p), (steps,)); returns the weighted sums
    of the squared outputs (..., 2), the largest weighted |output| (..., 2) and, with
    `keep`, the outputs (steps, ..., 2). Each chunk is recomputed in the reverse pass."""

    def chunk(carry, c):
        inputs, weights = chunk_inputs(c)

        def step(carry, pair):
            z, squares, peaks = carry
            u, weight = pair
            z, y = stepper(z, u)
            squares = squares + weight * y**2
            peaks = jnp.maximum(peaks, weight * jnp.abs(y))
            return (z, squares, peaks), (y if keep else None)

        return jax.lax.scan(step, carry, (inputs, weights))

    zeros = jnp.zeros(z0.shape[:-1] + (2,))
    carry, outputs = jax.lax.scan(jax.checkpoint(chunk), (z0, zeros, zeros),
                                  jnp.arange(chunks))
    _, squares, peaks = carry
    if keep:
        outputs = outputs.reshape((-1,) + outputs.shape[2:])
    return squares, peaks, outputs


class _Plan(eqx.Module):
    time_step: float = eqx.field(static=True)
    steps: int = eqx.field(static=True)
    first: int = eqx.field(static=True)
    chunks: int = eqx.field(static=True)


def plan(system: BuildingTID, settings: MonteCarloSettings, stationary: bool = True) -> _Plan:
    """The time step, the steps, the first counted step and the chunks of a run: after the
    transient where `stationary`, from the start (a run from rest under an envelope)."""
    period = first_period(system)
    h = settings.time_step if settings.time_step is not None else period / 200
    transient = settings.transient if settings.transient is not None else 20 * period
    if stationary and settings.transient is None and transient >= 0.5 * settings.duration:
        raise ValueError(f"duration ({settings.duration} s) must be at least twice the "
                         f"default transient, 20 periods of the first mode ({transient:.3g} "
                         "s): give a longer duration or a transient")
    steps = int(round(settings.duration / h))
    first = int(round(transient / h)) if stationary else 0
    return _Plan(time_step=h, steps=steps, first=first, chunks=-(-steps // CHUNK))


def stationary_inputs(plan: _Plan, key, samples: int, scale=None):
    """The chunk function of `run` for `samples` realisations: unit normal numbers from
    `key` (one fold per chunk: the same numbers whatever the design), times `scale` at
    each step (an envelope: `(chunks, CHUNK)`, or None), and the counted steps' weights."""
    noise = jax.random.split(key)[1]
    index = jnp.arange(plan.chunks * CHUNK).reshape(plan.chunks, CHUNK)
    weights = ((index >= plan.first) & (index < plan.steps)).astype(float)
    scale = jnp.ones_like(weights) if scale is None else scale

    def inputs(c):
        normal = jax.random.normal(jax.random.fold_in(noise, c), (CHUNK, samples, 1))
        return normal * scale[c][:, None, None], weights[c]

    return inputs


def envelope_scale(plan: _Plan, envelope):
    """`envelope` at each step's start, `(chunks, CHUNK)`, or None."""
    if envelope is None:
        return None
    times = np.arange(plan.chunks * CHUNK) * plan.time_step
    values = np.asarray(envelope(times), float).reshape(plan.chunks, CHUNK)
    if not np.all(np.isfinite(values)):
        raise ValueError("the envelope must be finite at every time")
    return jnp.asarray(values)


def stationary_start(system: BuildingTID, load: StationaryLoad, key, samples: int):
    """Draws from the frictionless stationary state (Cholesky of its covariance)."""
    P = stationary_covariance(system, load)
    scale = jnp.sqrt(jnp.diag(P))
    correlation = P / jnp.outer(scale, scale) + 1e-12 * jnp.eye(P.shape[0])
    lower = jnp.linalg.cholesky(correlation) * scale[:, None]
    return jax.random.normal(jax.random.split(key)[0], (samples, P.shape[0])) @ lower.T


def statistics(squares, peaks, counted: int, time_step: float) -> MonteCarlo:
    """The estimates and their standard errors from `run`'s sums over realisations."""
    n = squares.shape[0]
    mean_squares = squares / counted
    ms = jnp.mean(mean_squares[:, 0])
    rms = jnp.sqrt(ms)
    se = lambda values: jnp.std(values, ddof=1) / math.sqrt(n)
    return MonteCarlo(rms=rms, rms_se=se(mean_squares[:, 0]) / (2 * rms),
                      peak=jnp.mean(peaks[:, 0]), peak_se=se(peaks[:, 0]),
                      stroke_rms=jnp.sqrt(jnp.mean(mean_squares[:, 1])),
                      stroke_peak=jnp.mean(peaks[:, 1]), mean_squares=mean_squares[:, 0],
                      peaks=peaks[:, 0], time_step=time_step, duration=counted * time_step)


def monte_carlo(system: BuildingTID | TIDSystem, load: StationaryLoad,
                quantity: Quantity = Quantity(), *,
                settings: MonteCarloSettings = MonteCarloSettings(),
                envelope=None) -> MonteCarlo:
    """Monte Carlo statistics of `quantity` and the stroke of `system` (exact or smoothed
    friction, see the module) under the stationary random `load`: `settings.samples`
    realisations stepped together. With an `envelope` (a function of time in s, e.g.
    `jennings_envelope`) the white noise is modulated from rest and every step counts."""
    system = building_of(system, "force")
    check_load(system, load, quantity)
    run_plan = plan(system, settings, stationary=envelope is None)
    key = jax.random.key(settings.seed)
    squares, peaks = _stationary_sums(system, load, quantity, run_plan, key,
                                      settings.samples, envelope_scale(run_plan, envelope))
    return statistics(squares, peaks, run_plan.steps - run_plan.first, run_plan.time_step)


@eqx.filter_jit
def _stationary_sums(system, load, quantity, run_plan, key, samples, scale):
    stepper = stationary_stepper(system, load, quantity, run_plan.time_step)
    if scale is None:
        z0 = stationary_start(system, load, key, samples)
    else:
        z0 = jnp.zeros((samples, stepper.phi.shape[0]))
    inputs = stationary_inputs(run_plan, key, samples, scale)
    squares, peaks, _ = run(stepper, z0, inputs, run_plan.chunks)
    return squares, peaks


def substeps(motion: GroundMotion, time_step: float) -> tuple[int, np.ndarray]:
    """The substeps per sample (each at most `time_step`) and the inputs of `run`: the
    acceleration at each substep's start and the record's slope there, `(steps, 2)`."""
    count = max(1, math.ceil(motion.time_step / time_step - 1e-9))
    a = np.asarray(motion.acceleration)
    slope = np.diff(a) / motion.time_step
    within = np.arange(count) * (motion.time_step / count)
    starts = (a[:-1, None] + slope[:, None] * within[None, :]).reshape(-1)
    return count, np.stack([starts, np.repeat(slope, count)], axis=1)


def uses_exact_flow(system: BuildingTID, time_step: float | None) -> bool:
    """Whether a history under a record is the exact stick-slip flow: a rigid device with
    exact friction and no `time_step` asked for."""
    return time_step is None and system.exact_friction and not system.compliant


def friction_history(system: BuildingTID | TIDSystem, motion: GroundMotion,
                     quantity: Quantity = Quantity(), *,
                     time_step: float | None = None,
                     max_events: int = MAX_EVENTS) -> History:
    """The time history of `quantity` and the stroke of `system` (a ground load, with
    its friction) under `motion` from rest, sampled at the record's samples, with the
    stuck flags and the friction force (see `History`).

    A rigid device with exact friction (`friction_width` 0) is stepped exactly by
    default (`_record_flow`: closed-form modes, events located in time, at most
    `max_events` in one record step: more set `events_capped`). With a
    `time_step` (s), or for smoothed friction or a compliant device, the friction force
    is held over substeps of at most `time_step` (default the first mode's period / 200;
    first order in the step, Monte Carlo's scheme); smoothed friction never sticks."""
    system = building_of(system, "ground")
    check_system(system)
    quantity.floor_of(system.floors)
    if system.load != "ground":
        raise ValueError("a recorded ground motion needs a system with load='ground'")
    if isinstance(max_events, bool) or not isinstance(max_events, int) or max_events < 0:
        raise ValueError(f"max_events must be a non-negative integer, got {max_events!r}")
    if uses_exact_flow(system, time_step):
        return exact_history(system, motion, quantity, max_events)
    h = first_period(system) / 200 if time_step is None else time_step
    count, inputs = substeps(motion, h)
    start, outputs, forces = _record_outputs(system, quantity, jnp.asarray(inputs),
                                             motion.time_step / count)
    values = np.concatenate([np.asarray(start)[None], np.asarray(outputs)[count - 1::count]])
    forces = np.concatenate([[0.0], np.asarray(forces)[count - 1::count]])
    ff = float(np.max(np.asarray(system.friction_force)))
    stuck = np.abs(forces) < ff if system.exact_friction else np.zeros(forces.shape, bool)
    times = np.arange(values.shape[0]) * motion.time_step
    quantity_values = jnp.asarray(values[:, 0])
    return History(time=jnp.asarray(times), quantity=quantity_values,
                   stroke=jnp.asarray(values[:, 1]), peak=jnp.max(jnp.abs(quantity_values)),
                   rms=jnp.sqrt(jnp.mean(quantity_values**2)), stuck=jnp.asarray(stuck),
                   friction_force=jnp.asarray(forces), events_capped=jnp.asarray(False))


@eqx.filter_jit
def _record_outputs(system, quantity, inputs, time_step):
    stepper = record_stepper(system, quantity, time_step)

    def step(z, u):
        z, y, force = stepper.advance(z, u)
        return z, (y, force)

    _, (outputs, forces) = jax.lax.scan(step, jnp.zeros(stepper.phi.shape[0]), inputs)
    # at rest at the start: only the ground's own acceleration shows
    start = stepper.out_inputs[:, 0] * inputs[0, 0]
    return start, outputs, forces


def random_history(system: BuildingTID | TIDSystem, load: StationaryLoad,
                   quantity: Quantity = Quantity(), *,
                   settings: MonteCarloSettings = MonteCarloSettings()) -> History:
    """The time history of `quantity` and the stroke in the first realisation of
    `monte_carlo` with these `settings`, every step of `settings.duration` (from the
    frictionless stationary state); its `peak` and `rms` over the counted steps."""
    system = building_of(system, "force")
    check_load(system, load, quantity)
    run_plan = plan(system, settings)
    outputs = np.asarray(_first_realisation(system, load, quantity, run_plan,
                                            jax.random.key(settings.seed), settings.samples))
    outputs = outputs[:run_plan.steps]
    counted = outputs[run_plan.first:, 0]
    return History(time=jnp.arange(1, run_plan.steps + 1) * run_plan.time_step,
                   quantity=jnp.asarray(outputs[:, 0]), stroke=jnp.asarray(outputs[:, 1]),
                   peak=jnp.max(jnp.abs(counted)), rms=jnp.sqrt(jnp.mean(counted**2)))


@eqx.filter_jit
def _first_realisation(system, load, quantity, run_plan, key, samples):
    stepper = stationary_stepper(system, load, quantity, run_plan.time_step)
    z0 = stationary_start(system, load, key, samples)[:1]
    inputs = stationary_inputs(run_plan, key, samples)

    def first(c):
        normal, weights = inputs(c)
        return normal[:, :1], weights

    _, _, outputs = run(stepper, z0, first, run_plan.chunks, keep=True)
    return outputs[:, 0]
