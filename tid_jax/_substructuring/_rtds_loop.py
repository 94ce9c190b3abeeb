"""One virtual real-time substructuring test, sample by sample: the numerical substructure
(host, spring and damper) advanced by RK4 with the fed-back force held, the controller's
command (forward prediction of the interface kinematics), the actuator (delay line and
first-order lag), the physical device's force, and the peaks and first harmonics of the
response measured at the end."""

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .._model._dynamics import dead_zone, smooth_sign
from .._orbit._sampled_peaks import parabola_top
from .._runtime._cache import compiled

MAX_PREDICTION_ORDER = 4


class Plan(NamedTuple):
    """Static options: they select code paths and array sizes (each new plan compiles)."""

    scheme: str
    compliant: bool
    substeps: int
    buffer_length: int  # slots of the actuator's delay line


class Controller(eqx.Module):
    """Options shared by all points of a batch, traced so that they do not recompile."""

    dt: Array  # sample period, s
    n_steps: Array  # samples simulated
    prediction: Array  # 0 none, 1 polynomial, 2 harmonic
    prediction_order: Array
    harmonic_guess: Array  # bool: b_g y*'' ~ -b_g omega^2 y*


class Point(eqx.Module):
    """Per-point options (scalars, SI; batched by vmap)."""

    omega: Array
    amplitude: Array
    delay_samples: Array  # delay / sample period
    guessed_inertance: Array
    horizon: Array  # prediction horizon, s (0 without prediction)
    lag: Array  # actuator time constant, s
    bound: Array  # divergence bound on |x|, |y|, m
    window: Array  # measurement window, s


# Numerical substructure ------------------------------------------------------------------


def _interface_kinematics(plan, model, point, t, z, force):
    """(y, y', y'') of the numerical substructure at time `t`, the force held."""

    def field(s, state):
        return model.field(plan, point, s, state, force)

    def rate(s, state):  # y'
        return model.interface_rate(plan, point, s, state, force)

    _, acceleration = jax.jvp(rate, (t, z), (jnp.ones_like(t), field(t, z)))
    return jnp.stack([model.interface(z), rate(t, z), acceleration])


def _rk4(field, t, state, dt, substeps: int):
    """`substeps` classical Runge-Kutta steps over [t, t + dt] for a pytree `state`."""
    h = dt / substeps

    def axpy(a, x, y):
        return jax.tree.map(lambda xi, yi: xi + a * yi, x, y)

    def body(i, state):
        s = t + i * h
        k1 = field(s, state)
        k2 = field(s + h / 2, axpy(h / 2, state, k1))
        k3 = field(s + h / 2, axpy(h / 2, state, k2))
        k4 = field(s + h, axpy(h, state, k3))
        return jax.tree.map(
            lambda x, a, b, c, d: x + h / 6 * (a + 2 * b + 2 * c + d), state, k1, k2, k3, k4
        )

    return jax.lax.fori_loop(0, substeps, body, state)


# Controller, actuator and physical substructure --------------------------------------------


def _lagrange_weights(order, steps_ahead):
    """Weights on samples at 0, -1, ..., -MAX_PREDICTION_ORDER (in sample periods) of the
    polynomial through the first `order + 1` of them, evaluated `steps_ahead` sample
    periods ahead (zero beyond `order`)."""
    weights = []
    for j in range(MAX_PREDICTION_ORDER + 1):
        w = jnp.ones_like(steps_ahead)
        for i in range(MAX_PREDICTION_ORDER + 1):
            if i != j:
                w = w * jnp.where(i <= order, (steps_ahead + i) / (i - j), 1.0)
        weights.append(jnp.where(j <= order, w, 0.0))
    return jnp.stack(weights)


def _harmonic_prediction(kinematics, omega, horizon):
    """(y, y', y'') `horizon` ahead, exact for harmonic motion at `omega`: the phase is
    advanced with y and y' (y'' and y' for the acceleration, whose rate is -omega^2 y')."""
    y, v, a = kinematics
    cos, sin = jnp.cos(omega * horizon), jnp.sin(omega * horizon)
    return jnp.stack(
        [cos * y + sin / omega * v, cos * v - omega * sin * y, cos * a - omega * sin * v]
    )


def _inerter_force(system, point, kinematics):
    """f_s = (b + mt) y*'' + cp y*' + ff sgn(y*') of the rigid device driven at its
    terminal, N."""
    return ((system.inertance + system.terminal_mass) * kinematics[2]
            + system.parasitic_damping * kinematics[1]
            + system.friction_force * smooth_sign(
                kinematics[1], system.width_at(point.amplitude, point.omega)))


def _spring_force(system, terminal, mechanism):
    """The force of the compliant device's series spring (with its backlash), N."""
    return system.series_stiffness * dead_zone(terminal - mechanism, system.backlash)


def _fed_back_force(plan, controller, point, actuator, measured):
    """The force the controller feeds back: f_s (conventional) or e = f_s - b_g y*''."""
    if plan.scheme == "conventional":
        return measured
    acceleration = jnp.where(
        controller.harmonic_guess,
        -(point.omega**2) * actuator[0],  # the paper's approximation of y*''
        actuator[2],
    )
    return measured - point.guessed_inertance * acceleration


def _physical_field(system, point, s, state, actuator):
    """The compliant device's mechanism: b u'' + cp u' + ff sgn(u') = ks D(y*(s) - u) with
    the backlash's dead zone D, the actuator moving over the sample on the parabola of
    its kinematics at the sample."""
    u, du = state
    position = actuator[0] + actuator[1] * s + 0.5 * actuator[2] * s**2
    friction = system.friction_force * smooth_sign(
        du, system.width_at(point.amplitude, point.omega)
    )
    rest = system.parasitic_damping * du + friction
    return jnp.stack([du, (_spring_force(system, position, u) - rest) / system.inertance])


def first_harmonic_phase(samples):
    """Phase of the first harmonic of samples over one period from phase 0 (the last
    axis), rad: `X sin(theta + phase)`."""
    theta = 2 * jnp.pi * jnp.arange(samples.shape[-1]) / samples.shape[-1]
    return jnp.arctan2(jnp.sum(samples * jnp.cos(theta), axis=-1),
                       jnp.sum(samples * jnp.sin(theta), axis=-1))


# One test --------------------------------------------------------------------------------


class _Timing(eqx.Module):
    """What one point's loop derives from its options once, before its first sample."""

    whole_samples: Array  # the delay's whole samples
    fraction: Array  # and its fraction of a sample
    lag_factor: Array  # the lag's decay over a sample (0: no lag)
    weights: Array  # the polynomial prediction's weights on the last samples
    window_start: Array  # start of the measuring window, s
    previous_start: Array  # start of the window before it (from mid-run), s


class _Harmonics(eqx.Module):
    """Running sums of the least-squares fit of a sin + b cos to x and y."""

    ss: Array
    cc: Array
    sc: Array
    xs: Array
    xc: Array
    ys: Array
    yc: Array

    def phases(self):
        """The phases atan2(b, a) of x and y, rad."""
        det_x = (self.ss * self.xc - self.sc * self.xs, self.cc * self.xs - self.sc * self.xc)
        det_y = (self.ss * self.yc - self.sc * self.ys, self.cc * self.ys - self.sc * self.yc)
        return jnp.arctan2(*det_x), jnp.arctan2(*det_y)


class _Stats(eqx.Module):
    """What the loop measures as it goes: |x| and |y| peaks, each a maximum at a sample
    refined by a parabola."""

    peaks: Float[Array, " 2"]  # in the measuring window
    previous_peaks: Float[Array, " 2"]  # from mid-run up to the window
    recent: Float[Array, "2 2"]  # |x|, |y| at the last two samples
    harmonics: _Harmonics


class _Loop(eqx.Module):
    """The state of the test between two samples."""

    z: Array  # the numerical substructure's state
    held: Array  # the fed-back force held over the sample, N
    commands: Array  # the actuator's delay line (slot n mod length holds sample n)
    past: Array  # the controller's last interface kinematics, newest first
    actuator: Array  # (y*, y*', y*'') imposed by the actuator
    physical: Array  # the compliant device's mechanism (u, u')
    diverged: Bool[Array, ""]
    stats: _Stats


class _Measured(eqx.Module):
    """One test's result: peaks (m) and phases (rad) of x and y over the measuring window,
    whether it diverged, and the growth of its peaks over the window before."""

    x_max: Array
    y_max: Array
    x_phase: Array
    y_phase: Array
    diverged: Array
    growth: Array


def _timing(plan: Plan, controller: Controller, point: Point) -> _Timing:
    dt = controller.dt
    end = controller.n_steps * dt
    whole_samples = jnp.floor(point.delay_samples).astype(jnp.int32)
    lag_factor = jnp.exp(-dt / jnp.where(point.lag > 0, point.lag, 1.0))
    return _Timing(
        whole_samples=whole_samples,
        fraction=point.delay_samples - whole_samples,
        lag_factor=jnp.where(point.lag > 0, lag_factor, 0.0),
        weights=_lagrange_weights(controller.prediction_order, point.horizon / dt),
        window_start=end - point.window,
        previous_start=end / 2,
    )


def _initial_loop(plan: Plan, controller: Controller, model, point: Point) -> _Loop:
    """The frictionless steady state, with the matching history for t < 0."""
    dt, length, dtype = controller.dt, plan.buffer_length, point.omega.dtype
    z0, start = model.linear(plan, point, jnp.zeros((), dtype))
    interface = lambda times: model.linear(plan, point, times)[1]
    sample_times = (jnp.arange(length) - length) * dt  # slot n mod L holds sample n < 0
    past_times = -jnp.arange(1, MAX_PREDICTION_ORDER + 1) * dt
    delay = point.delay_samples * dt
    held = _fed_back_force(plan, controller, point, start,
                           _inerter_force(model.system, point, start))
    first = jnp.abs(model.outputs(plan, point, jnp.zeros((), dtype), z0, held))
    zero = jnp.zeros((), dtype)
    return _Loop(
        z=z0,
        held=held,
        commands=interface(sample_times + point.horizon).T,
        past=interface(past_times).T,  # samples n-1, n-2, ...
        actuator=interface(-dt - delay + point.horizon),
        physical=start[:2],
        diverged=jnp.zeros((), bool),
        stats=_Stats(jnp.zeros(2, dtype), jnp.zeros(2, dtype), jnp.stack([first, first]),
                     _Harmonics(*[zero] * 7)),
    )


def _actuate(plan, controller, model, point, timing: _Timing, n, loop: _Loop):
    """The controller's command at sample `n` (predicted if asked) into the delay line,
    and the actuator's motion after the delay and the lag: `(commands, past,
    actuator)`."""
    t = n * controller.dt
    current = _interface_kinematics(plan, model, point, t, loop.z, loop.held)
    samples = jnp.concatenate([current[None], loop.past], axis=0)
    command = jnp.select(
        [controller.prediction == 1, controller.prediction == 2],
        [timing.weights @ samples, _harmonic_prediction(current, point.omega, point.horizon)],
        current,
    )
    length = plan.buffer_length
    commands = loop.commands.at[n % length].set(command)
    newer = commands[(n - timing.whole_samples) % length]
    older = commands[(n - timing.whole_samples - 1) % length]
    delayed = (1 - timing.fraction) * newer + timing.fraction * older
    actuator = timing.lag_factor * loop.actuator + (1 - timing.lag_factor) * delayed
    return commands, samples[:-1], actuator


def _record(stats: _Stats, outputs, t, point: Point, timing: _Timing) -> _Stats:
    """`stats` after the sample at time `t` of the measured `outputs` (x, y)."""
    in_window = t > timing.window_start
    in_previous = (t > timing.previous_start) & ~in_window
    values = jnp.abs(outputs)
    candidates = jnp.maximum(values, parabola_top(stats.recent[1], stats.recent[0], values))
    sine, cosine = jnp.sin(point.omega * t), jnp.cos(point.omega * t)
    x, y = outputs
    terms = _Harmonics(sine * sine, cosine * cosine, sine * cosine, x * sine, x * cosine,
                       y * sine, y * cosine)
    return _Stats(
        peaks=jnp.where(in_window, jnp.maximum(stats.peaks, candidates), stats.peaks),
        previous_peaks=jnp.where(in_previous, jnp.maximum(stats.previous_peaks, candidates),
                                 stats.previous_peaks),
        recent=jnp.stack([values, stats.recent[0]]),
        harmonics=jax.tree.map(lambda sum_, term: sum_ + in_window * term,
                               stats.harmonics, terms),
    )


def _step(plan, controller, model, point, timing: _Timing, n, loop: _Loop) -> _Loop:
    """The test from sample `n` to sample `n + 1`."""
    dt = controller.dt
    t = n * dt
    device = model.system
    commands, past, actuator = _actuate(plan, controller, model, point, timing, n, loop)
    # The physical device's force and the signal fed back, held over the sample.
    if plan.compliant:
        measured = (device.terminal_mass * actuator[2]
                    + _spring_force(device, actuator[0], loop.physical[0]))
    else:
        measured = _inerter_force(device, point, actuator)
    force = _fed_back_force(plan, controller, point, actuator, measured)

    def field(s, state):
        numerical, physical = state
        d_numerical = model.field(plan, point, s, numerical, force)
        if plan.compliant:
            return d_numerical, _physical_field(device, point, s - t, physical, actuator)
        return d_numerical, jnp.zeros_like(physical)

    z_new, physical_new = _rk4(field, t, (loop.z, loop.physical), dt, plan.substeps)
    outputs = model.outputs(plan, point, t + dt, z_new, force)
    inside = (
        jnp.all(jnp.isfinite(z_new))
        & jnp.all(jnp.isfinite(physical_new))
        & jnp.all(jnp.abs(outputs) < point.bound)
        & (jnp.abs(physical_new[0]) < point.bound)
    )
    diverged = loop.diverged | ~inside
    z = jnp.where(diverged, loop.z, z_new)
    outputs = jnp.where(diverged, model.outputs(plan, point, t + dt, z, force), outputs)
    return _Loop(
        z=z,
        held=jnp.where(diverged, loop.held, force),
        commands=commands,
        past=past,
        actuator=actuator,
        physical=jnp.where(diverged, loop.physical, physical_new),
        diverged=diverged,
        stats=_record(loop.stats, outputs, (n + 1) * dt, point, timing),
    )


def _simulate_point(plan: Plan, controller: Controller, model, point: Point) -> _Measured:
    timing = _timing(plan, controller, point)
    loop = jax.lax.fori_loop(
        0, controller.n_steps,
        lambda n, loop: _step(plan, controller, model, point, timing, n, loop),
        _initial_loop(plan, controller, model, point),
    )
    stats = loop.stats
    x_phase, y_phase = stats.harmonics.phases()
    tiny = jnp.finfo(point.omega.dtype).tiny
    return _Measured(
        x_max=stats.peaks[0],
        y_max=stats.peaks[1],
        x_phase=x_phase,
        y_phase=y_phase,
        diverged=loop.diverged,
        growth=jnp.max(stats.peaks / jnp.maximum(stats.previous_peaks, tiny)),
    )


@compiled
def simulate_batch(plan: Plan, controller: Controller, model, points: Point) -> _Measured:
    """The tests at every point of the batch `points`, as one vmapped loop, of the
    numerical substructure `model` (`_building_rtds.BuildingModel`: the paper's host as its
    one-storey building) whose `system`'s device is the physical one."""
    return jax.vmap(lambda point: _simulate_point(plan, controller, model, point))(points)
