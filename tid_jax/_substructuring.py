"""Virtual real-time dynamic substructuring (RTDS) test of the inerter, paper section 5.

The host structure and the TID's spring and damper are numerical; the inerter is
"physical", emulated by the friction model of eq. (12), optionally behind a parasitic
compliance. A digital controller advances the numerical substructure sample by sample,
commands the interface kinematics to an actuator (a delay line with an optional
first-order lag, compensated by default by forward prediction, as in the paper) and
feeds the force measured at the interface back into the numerical model, held over each
sample.
"""

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ._cache import compiled
from ._checks import check_concrete_system, choice, integer, real_array, real_scalar
from ._dynamics import smooth_sign
from ._linear import linear_receptance
from ._response import point_response
from ._steady_state import SolverSettings
from ._system import TIDSystem

SCHEMES = ("conventional", "error_feedback")
GUESSED_FORCES = ("acceleration", "harmonic")
PREDICTIONS = ("polynomial", "harmonic")
MAX_PREDICTION_ORDER = 4
DEFAULT_DELAY = 0.01  # s
DEFAULT_SAMPLE_RATE = 1000.0  # Hz


class Substructuring(eqx.Module):
    """Steady state of a virtual RTDS test of the inerter. Arrays have the broadcast shape
    of the `omega`, `amplitude`, `delay` and `guessed_inertance` inputs. SI units.

    - `omega` (rad/s), `amplitude` (N), `delay` (s), `guessed_inertance` (kg): the inputs.
    - `x_max`, `y_max`: peak |x| and |y| of the numerical substructure over the last
      `measure_periods` forcing periods, m. Meaningless where `stable` is False (a
      diverged test is frozen at its last state inside the bound, so they stay finite).
    - `x_phase`, `y_phase`: phase of the first harmonic against the forcing
      `A sin(omega t)`, i.e. `x ~ X sin(omega t + x_phase)`, rad.
    - `stable`: the test neither diverged nor was still growing at the end.
    - `diverged`: |x| or |y| left the divergence bound (or became non-finite).
    - `growth`: peak of the last window over the peak from mid-run up to that window
      (at most about 1 once settled, even if the motion is irregular, as in friction
      chatter; above 1 while an instability grows).

    With `reference=True` (else None):

    - `reference_x_max`, `reference_y_max` (m), `reference_x_phase`, `reference_y_phase`
      (rad): the whole system's steady state (the model of `frequency_response`).
    - `x_amplitude_error`, `y_amplitude_error`: `x_max / reference_x_max - 1` (and y).
    - `x_phase_error`, `y_phase_error`: substructured minus whole-system phase, rad, in
      (-pi, pi].
    - `reference_converged`: the whole-system periodic orbit was found.
    """

    omega: Float[Array, "*batch"]
    amplitude: Float[Array, "*batch"]
    delay: Float[Array, "*batch"]
    guessed_inertance: Float[Array, "*batch"]
    x_max: Float[Array, "*batch"]
    y_max: Float[Array, "*batch"]
    x_phase: Float[Array, "*batch"]
    y_phase: Float[Array, "*batch"]
    stable: Bool[Array, "*batch"]
    diverged: Bool[Array, "*batch"]
    growth: Float[Array, "*batch"]
    reference_x_max: Float[Array, "*batch"] | None = None
    reference_y_max: Float[Array, "*batch"] | None = None
    reference_x_phase: Float[Array, "*batch"] | None = None
    reference_y_phase: Float[Array, "*batch"] | None = None
    x_amplitude_error: Float[Array, "*batch"] | None = None
    y_amplitude_error: Float[Array, "*batch"] | None = None
    x_phase_error: Float[Array, "*batch"] | None = None
    y_phase_error: Float[Array, "*batch"] | None = None
    reference_converged: Bool[Array, "*batch"] | None = None


class SubstructuringStability(eqx.Module):
    """Stability of an RTDS test over guessed inertances x actuator delays.

    - `guessed_inertance`: b_g, kg, shape `(n_guesses,)`.
    - `delay`: actuator delays tried, s, shape `(n_delays,)`, increasing.
    - `stable`: shape `(n_guesses, n_delays)`.
    - `largest_stable_delay`: for each b_g, the largest grid delay such that it and every
      smaller grid delay are stable, s; -1 where the smallest delay is already unstable.
    """

    guessed_inertance: Float[Array, " guesses"]
    delay: Float[Array, " delays"]
    stable: Bool[Array, "guesses delays"]
    largest_stable_delay: Float[Array, " guesses"]


class _Plan(NamedTuple):
    """Static options: they select code paths and array sizes (each new plan compiles)."""

    scheme: str
    compliant: bool
    substeps: int
    buffer_length: int  # slots of the actuator's delay line


class _Controller(eqx.Module):
    """Options shared by all points of a batch, traced so that they do not recompile."""

    dt: Array  # sample period, s
    n_steps: Array  # samples simulated
    prediction: Array  # 0 none, 1 polynomial, 2 harmonic
    prediction_order: Array
    harmonic_guess: Array  # bool: b_g y*'' ~ -b_g omega^2 y*


class _Point(eqx.Module):
    """Per-point options (scalars, SI; batched by vmap)."""

    omega: Array
    amplitude: Array
    delay_samples: Array  # delay / sample period
    guessed_inertance: Array
    horizon: Array  # prediction horizon, s (0 without prediction)
    lag: Array  # actuator time constant, s
    parasitic_stiffness: Array
    bound: Array  # divergence bound on |x|, |y|, m
    window: Array  # measurement window, s


# Numerical substructure ------------------------------------------------------------------


def _numerical_field(plan: _Plan, system: TIDSystem, point: _Point, t, z, force):
    """Time derivative of the numerical substructure with the fed-back `force` held.
    Error feedback, eq. (16): z = (x, x', y, y'). Conventional, eqs. (13)-(14):
    z = (x, x', y), y' solved from c (y' - x') + k (y - x) = -f_s."""
    forcing = point.amplitude * jnp.sin(point.omega * t)
    mass, stiffness, damping = system.host_mass, system.host_stiffness, system.host_damping
    k, c = system.tid_stiffness, system.tid_damping
    x, v, y = z[0], z[1], z[2]
    if plan.scheme == "error_feedback":
        w = z[3]
        spring = c * (v - w) + k * (x - y)
        dv = (forcing - damping * v - stiffness * x - spring) / mass
        dw = (spring - force) / point.guessed_inertance  # b_g y'' + c(y'-x') + k(y-x) = -e
        return jnp.stack([v, dv, w, dw])
    w = v - (k * (y - x) + force) / c
    dv = (forcing - damping * v - stiffness * x - force) / mass  # the host feels f_s
    return jnp.stack([v, dv, w])


def _interface_kinematics(plan, system, point, t, z, force):
    """(y, y', y'') of the numerical substructure at time `t`, the force held."""

    def field(s, state):
        return _numerical_field(plan, system, point, s, state, force)

    def rate(s, state):  # y'
        return field(s, state)[2]

    _, acceleration = jax.jvp(rate, (t, z), (jnp.ones_like(t), field(t, z)))
    return jnp.stack([z[2], rate(t, z), acceleration])


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
    """f_s = b y*'' + ff sgn(y*') of the rigidly driven inerter, N."""
    return system.inertance * kinematics[2] + system.friction_force * smooth_sign(
        kinematics[1], system.width_at(point.amplitude, point.omega)
    )


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
    """Inerter behind a parasitic spring: b u'' + ff sgn(u') = k_p (y*(s) - u), the
    actuator moving over the sample on the parabola of its kinematics at the sample."""
    u, du = state
    position = actuator[0] + actuator[1] * s + 0.5 * actuator[2] * s**2
    spring = point.parasitic_stiffness * (position - u)
    friction = system.friction_force * smooth_sign(
        du, system.width_at(point.amplitude, point.omega)
    )
    return jnp.stack([du, (spring - friction) / system.inertance])


def _parabola_top(left, mid, right):
    """Vertex of the parabola through three equally spaced samples where `mid` is a local
    maximum, else `mid` (elementwise)."""
    curvature = left - 2 * mid + right
    is_top = (mid >= left) & (mid >= right) & (curvature < 0)
    safe = jnp.where(is_top, curvature, -1.0)
    return jnp.where(is_top, mid - (right - left) ** 2 / (8 * safe), mid)


def _linear_kinematics(system, point, times):
    """Frictionless whole-system steady state at `times`: rows x, x', y, y', y''."""
    receptance = linear_receptance(system, point.omega)
    jw = 1j * point.omega
    phase = point.amplitude * jnp.exp(jw * times)
    host, inerter = receptance.host * phase, receptance.inerter * phase
    return jnp.stack(
        [host.imag, (jw * host).imag, inerter.imag, (jw * inerter).imag, (jw**2 * inerter).imag]
    )


# One test --------------------------------------------------------------------------------


def _simulate_point(plan: _Plan, controller: _Controller, system: TIDSystem, point: _Point):
    length, dt = plan.buffer_length, controller.dt
    n_steps, order = controller.n_steps, controller.prediction_order
    dtype = point.omega.dtype
    end = n_steps * dt
    window_start, previous_start = end - point.window, end / 2
    whole_samples = jnp.floor(point.delay_samples).astype(jnp.int32)
    fraction = point.delay_samples - whole_samples
    horizon = point.horizon
    lag_factor = jnp.exp(-dt / jnp.where(point.lag > 0, point.lag, 1.0))
    lag_factor = jnp.where(point.lag > 0, lag_factor, 0.0)
    weights = _lagrange_weights(order, horizon / dt)

    # Start on the frictionless steady state, with the matching history for t < 0.
    start = _linear_kinematics(system, point, jnp.zeros((), dtype))
    z0 = start[:4] if plan.scheme == "error_feedback" else start[:3]
    sample_times = (jnp.arange(length) - length) * dt  # slot n mod L holds sample n < 0
    commands0 = _linear_kinematics(system, point, sample_times + horizon)[2:].T
    past_times = -jnp.arange(1, MAX_PREDICTION_ORDER + 1) * dt
    past0 = _linear_kinematics(system, point, past_times)[2:].T  # samples n-1, n-2, ...
    delay = point.delay_samples * dt
    actuator0 = _linear_kinematics(system, point, -dt - delay + horizon)[2:]
    held0 = _fed_back_force(plan, controller, point, start[2:], _inerter_force(system, point, start[2:]))
    physical0 = start[2:4]

    def step(n, carry):
        z, held, commands, past, actuator, physical, diverged, stats = carry
        t = n * dt
        # The controller commands the interface kinematics, predicted if asked.
        current = _interface_kinematics(plan, system, point, t, z, held)
        samples = jnp.concatenate([current[None], past], axis=0)
        command = jnp.select(
            [controller.prediction == 1, controller.prediction == 2],
            [weights @ samples, _harmonic_prediction(current, point.omega, horizon)],
            current,
        )
        past = samples[:-1]
        commands = commands.at[n % length].set(command)
        # The actuator: the delay (interpolated between samples), then the lag.
        newer = commands[(n - whole_samples) % length]
        older = commands[(n - whole_samples - 1) % length]
        delayed = (1 - fraction) * newer + fraction * older
        actuator = lag_factor * actuator + (1 - lag_factor) * delayed
        # The physical inerter's force and the signal fed back, held over the sample.
        if plan.compliant:
            measured = point.parasitic_stiffness * (actuator[0] - physical[0])
        else:
            measured = _inerter_force(system, point, actuator)
        force = _fed_back_force(plan, controller, point, actuator, measured)

        def field(s, state):
            numerical, phys = state
            d_numerical = _numerical_field(plan, system, point, s, numerical, force)
            if plan.compliant:
                return d_numerical, _physical_field(system, point, s - t, phys, actuator)
            return d_numerical, jnp.zeros_like(phys)

        z_new, physical_new = _rk4(field, t, (z, physical), dt, plan.substeps)
        inside = (
            jnp.all(jnp.isfinite(z_new))
            & jnp.all(jnp.isfinite(physical_new))
            & (jnp.abs(z_new[0]) < point.bound)
            & (jnp.abs(z_new[2]) < point.bound)
            & (jnp.abs(physical_new[0]) < point.bound)
        )
        diverged = diverged | ~inside
        z = jnp.where(diverged, z, z_new)
        physical = jnp.where(diverged, physical, physical_new)
        held = jnp.where(diverged, held, force)
        # Peaks (a maximum at t_n refined by a parabola) and first-harmonic sums at t_n+1.
        t_next = (n + 1) * dt
        in_window = t_next > window_start
        in_previous = (t_next > previous_start) & ~in_window
        peaks, previous_peaks, recent, sums = stats
        values = jnp.abs(jnp.stack([z[0], z[2]]))
        candidates = jnp.maximum(values, _parabola_top(recent[1], recent[0], values))
        peaks = jnp.where(in_window, jnp.maximum(peaks, candidates), peaks)
        previous_peaks = jnp.where(
            in_previous, jnp.maximum(previous_peaks, candidates), previous_peaks
        )
        sine, cosine = jnp.sin(point.omega * t_next), jnp.cos(point.omega * t_next)
        x, y = z[0], z[2]
        sums = sums + in_window * jnp.stack(
            [
                sine * sine,
                cosine * cosine,
                sine * cosine,
                x * sine,
                x * cosine,
                y * sine,
                y * cosine,
            ]
        )
        stats = (peaks, previous_peaks, jnp.stack([values, recent[0]]), sums)
        return z, held, commands, past, actuator, physical, diverged, stats

    first = jnp.abs(jnp.stack([z0[0], z0[2]]))
    stats0 = (
        jnp.zeros(2, dtype),
        jnp.zeros(2, dtype),
        jnp.stack([first, first]),
        jnp.zeros(7, dtype),
    )
    carry0 = (z0, held0, commands0, past0, actuator0, physical0, jnp.zeros((), bool), stats0)
    carry = jax.lax.fori_loop(0, n_steps, step, carry0)
    *_, diverged, (peaks, previous_peaks, _, sums) = carry

    # Least-squares fit of a sin + b cos over the window: phase atan2(b, a).
    ss, cc, sc, xs, xc, ys, yc = sums
    tiny = jnp.finfo(dtype).tiny
    return dict(
        x_max=peaks[0],
        y_max=peaks[1],
        x_phase=jnp.arctan2(ss * xc - sc * xs, cc * xs - sc * xc),
        y_phase=jnp.arctan2(ss * yc - sc * ys, cc * ys - sc * yc),
        diverged=diverged,
        growth=jnp.max(peaks / jnp.maximum(previous_peaks, tiny)),
    )


@compiled
def _simulate_batch(plan: _Plan, controller: _Controller, system: TIDSystem, points: _Point):
    return jax.vmap(lambda point: _simulate_point(plan, controller, system, point))(points)


def _first_harmonic_phase(samples):
    """Phase of the first harmonic of samples over one period from phase 0, rad."""
    theta = 2 * jnp.pi * jnp.arange(samples.shape[-1]) / samples.shape[-1]
    return jnp.arctan2(jnp.sum(samples * jnp.cos(theta)), jnp.sum(samples * jnp.sin(theta)))


@compiled
def _reference_batch(system: TIDSystem, omegas, amplitudes, settings: SolverSettings):
    def one(omega, amplitude):
        orbit, x_max, y_max = point_response(system, omega, amplitude, settings)
        return dict(
            x_max=x_max,
            y_max=y_max,
            x_phase=_first_harmonic_phase(orbit.x_samples),
            y_phase=_first_harmonic_phase(orbit.y_samples),
            converged=orbit.converged,
        )

    return jax.vmap(one)(omegas, amplitudes)


# Public functions ------------------------------------------------------------------------


def _planned_tests(system, omega, amplitude, *, scheme, delay, guessed_inertance,
                   guessed_force, prediction, prediction_order, prediction_horizon,
                   actuator_lag, parasitic_stiffness, sample_rate, substeps, periods,
                   measure_periods, divergence_factor, growth_tolerance):
    """The checked options of `simulate_substructuring` as the static `_Plan`, the
    `_Controller` and the flat batch of `_Point`s, with the broadcast grid's shape and
    arrays `(omega, amplitude, delay, guessed_inertance)`."""
    choice("scheme", scheme, SCHEMES)
    choice("guessed_force", guessed_force, GUESSED_FORCES)
    if prediction is not None:
        choice("prediction", prediction, PREDICTIONS)
    omega_array = real_array("omega", omega, "positive")
    amplitude_array = real_array("amplitude", amplitude, "positive")
    delay_array = real_array("delay", delay, "non-negative")
    if guessed_inertance is None:
        guessed_inertance = float(system.inertance)
    guess_array = real_array("guessed_inertance", guessed_inertance, "positive")
    rate = real_scalar("sample_rate", sample_rate, "positive")
    order = integer("prediction_order", prediction_order, 0, MAX_PREDICTION_ORDER)
    substeps = integer("substeps", substeps, 1)
    measure_periods = integer("measure_periods", measure_periods, 1)
    periods = integer("periods", periods, 3 * measure_periods)
    lag = real_scalar("actuator_lag", actuator_lag, "non-negative")
    if parasitic_stiffness is not None:
        parasitic_stiffness = real_scalar("parasitic_stiffness", parasitic_stiffness, "positive")
    factor = real_scalar("divergence_factor", divergence_factor, "positive")
    if factor <= 1:
        raise ValueError(f"divergence_factor must be > 1, got {divergence_factor!r}")
    growth_tolerance = real_scalar("growth_tolerance", growth_tolerance, "positive")
    if scheme == "conventional" and not float(system.tid_damping) > 0:
        raise ValueError(
            "system.tid_damping must be positive for the conventional scheme (it solves y' "
            f"from the damper), got {float(system.tid_damping)!r}"
        )
    try:
        shape = np.broadcast_shapes(
            omega_array.shape, amplitude_array.shape, delay_array.shape, guess_array.shape
        )
    except ValueError:
        raise ValueError(
            "omega, amplitude, delay and guessed_inertance must broadcast together, got "
            f"shapes {omega_array.shape}, {amplitude_array.shape}, {delay_array.shape} and "
            f"{guess_array.shape}"
        ) from None
    highest = float(np.max(omega_array))
    if highest >= math.pi * rate / 4:
        raise ValueError(
            f"omega must be below a quarter of the Nyquist frequency, pi * sample_rate / 4 = "
            f"{math.pi * rate / 4:g} rad/s ({rate / 8:g} Hz), got {highest:g} rad/s "
            f"({highest / (2 * math.pi):g} Hz); raise sample_rate"
        )
    n_steps = int(math.ceil(periods * 2 * math.pi / float(np.min(omega_array)) * rate))
    duration = n_steps / rate
    longest = float(np.max(delay_array))
    if longest >= duration / 2:
        raise ValueError(
            f"delay must be shorter than half the simulated duration ({duration:g} s), got "
            f"{longest!r}; raise periods"
        )
    if prediction_horizon is None:
        horizon_array = delay_array + 0.5 / rate  # the hold lags half a sample on average
    else:
        horizon = real_scalar("prediction_horizon", prediction_horizon, "non-negative")
        if horizon >= duration / 2:
            raise ValueError(
                f"prediction_horizon must be shorter than half the simulated duration "
                f"({duration:g} s), got {prediction_horizon!r}"
            )
        horizon_array = np.asarray(horizon)
    if prediction is None:
        horizon_array = np.zeros(())

    flat = [
        np.broadcast_to(a, shape).reshape(-1)
        for a in (
            omega_array,
            amplitude_array,
            delay_array,
            guess_array,
            np.broadcast_to(horizon_array, delay_array.shape),
        )
    ]
    omegas, amplitudes, delays, guesses, horizons = flat
    delay_samples = delays * rate
    # One spare slot beyond the two read (against rounding of the delay), rounded up to a
    # power of two (at least 32) so that nearby delays share the compiled code.
    needed = int(math.floor(float(np.max(delay_samples)))) + 3
    plan = _Plan(
        scheme=scheme,
        compliant=parasitic_stiffness is not None,
        substeps=substeps,
        buffer_length=max(32, 1 << (needed - 1).bit_length()),
    )
    dtype = jnp.result_type(float)
    controller = _Controller(
        dt=jnp.asarray(1 / rate, dtype),
        n_steps=jnp.asarray(n_steps),
        prediction=jnp.asarray(0 if prediction is None else 1 + PREDICTIONS.index(prediction)),
        prediction_order=jnp.asarray(order),
        harmonic_guess=jnp.asarray(guessed_force == "harmonic"),
    )
    receptance = linear_receptance(system, omegas)
    linear = np.maximum(np.abs(np.asarray(receptance.host)), np.abs(np.asarray(receptance.inerter)))
    scale = np.maximum(linear, 1 / float(system.host_stiffness)) * amplitudes
    points = _Point(
        omega=jnp.asarray(omegas, dtype),
        amplitude=jnp.asarray(amplitudes, dtype),
        delay_samples=jnp.asarray(delay_samples, dtype),
        guessed_inertance=jnp.asarray(guesses, dtype),
        horizon=jnp.asarray(horizons, dtype),
        lag=jnp.full(omegas.shape, lag, dtype),
        parasitic_stiffness=jnp.full(omegas.shape, parasitic_stiffness or 0.0, dtype),
        bound=jnp.asarray(factor * scale, dtype),
        window=jnp.asarray(measure_periods * 2 * np.pi / omegas, dtype),
    )
    arrays = (omega_array, amplitude_array, delay_array, guess_array)
    return plan, controller, points, shape, arrays, growth_tolerance


def simulate_substructuring(
    system: TIDSystem,
    omega: ArrayLike,
    amplitude: ArrayLike,
    *,
    scheme: str = "error_feedback",
    delay: ArrayLike = DEFAULT_DELAY,
    guessed_inertance: ArrayLike | None = None,
    guessed_force: str = "acceleration",
    prediction: str | None = "harmonic",
    prediction_order: int = 2,
    prediction_horizon: float | None = None,
    actuator_lag: float = 0.0,
    parasitic_stiffness: float | None = None,
    sample_rate: float = DEFAULT_SAMPLE_RATE,
    substeps: int = 4,
    periods: int = 60,
    measure_periods: int = 5,
    divergence_factor: float = 100.0,
    growth_tolerance: float = 0.02,
    reference: bool = True,
    settings: SolverSettings = SolverSettings(),  # noqa: B008 (immutable)
) -> Substructuring:
    """Simulate a real-time dynamic substructuring test of the inerter (paper section 5)
    as a digital controller runs it, and compare it with the whole system.

    Every sample period the controller commands the interface kinematics (y, y', y'') of
    the numerical substructure (host M, K, C and the TID's k, c, plus b_g for error
    feedback), optionally predicted `prediction_horizon` ahead. The actuator imposes them
    after the pure `delay` (interpolated linearly between samples) and a first-order lag
    `actuator_lag` (discretised per sample). The physical inerter answers with
    f_s = b y*'' + ff sgn(y*') (the smoothed sign of `frequency_response`), or through a
    parasitic spring. The fed-back force is held over the sample while RK4 advances the
    numerical substructure (zero-order hold, so even with no delay the loop lags by the
    sampling: errors are first order in 1 / `sample_rate`). The test starts on the
    frictionless steady state with the matching history. A test whose |x| or |y| leaves
    the divergence bound is frozen and reported as diverged, never as NaN.

    **Arguments:**

    - `system`: the emulated `TIDSystem`; its inertance and friction are the physical
      inerter's.
    - `omega`: forcing circular frequency, rad/s.
    - `amplitude`: forcing amplitude A of `A sin(omega t)`, N.
    - `scheme`: "conventional" (feed back f_s, eqs. (13)-(14): an advanced equation,
      unstable for any delay) or "error_feedback" (feed back e = f_s - b_g y*'',
      eq. (16)).
    - `delay`: actuator delay tau, s.
    - `guessed_inertance`: b_g, kg (default the system's inertance; unused by the
      conventional scheme).
    - `guessed_force`: "acceleration" (b_g y*'' from the actuator's acceleration) or
      "harmonic" (the paper's -b_g omega^2 y*, exact only for harmonic motion).
    - `prediction`: the compensation of the delay: "harmonic" (the default, as in the
      paper's tests: advance the phase of the current y, y', y'' by omega * horizon,
      exact for harmonic motion at the forcing frequency); "polynomial" (extrapolate the
      polynomial through the last `prediction_order + 1` commanded samples, the usual
      model-free compensation); or None (no compensation: with a 10 ms delay the host
      amplitude is then about 10% off on the paper's system).
    - `prediction_order`: degree of the "polynomial" prediction, 0 to 4.
    - `prediction_horizon`: how far ahead to predict, s (default: the delay plus half a
      sample period, the mean lag of the zero-order hold).
    - `actuator_lag`: time constant of the actuator's first-order lag, s (0: none).
    - `parasitic_stiffness`: stiffness in series with the physical inerter, N/m (None:
      rigid).
    - `sample_rate`: controller sample rate, Hz.
    - `substeps`: RK4 steps per sample.
    - `periods`: simulated duration, in periods of the lowest forcing frequency.
    - `measure_periods`: peaks and phases come from the last `measure_periods` periods;
      the peak between mid-run and them is used to detect growth.
    - `divergence_factor`: the test diverged once |x| or |y| exceeds this multiple of the
      largest of A / K and the frictionless |X|, |Y|.
    - `growth_tolerance`: a test whose last-window peak exceeds the peak from mid-run up
      to that window by more than this fraction counts as unstable.
    - `reference`: also solve the whole system (`frequency_response`'s model) and report
      amplitude and phase errors.
    - `settings`: `SolverSettings` of that whole-system solve.

    `omega`, `amplitude`, `delay` and `guessed_inertance` broadcast against each other;
    all points run in one compiled, vmapped call.

    **Returns:** a `Substructuring`.
    """
    check_concrete_system(system)
    if system.exact_friction:
        raise ValueError(
            "simulate_substructuring integrates the test in real time with fixed steps and "
            "needs smoothed friction: give system.friction_width > 0 or None, not 0 (exact "
            "Coulomb friction)"
        )
    if not isinstance(settings, SolverSettings):
        raise ValueError(f"settings must be a SolverSettings, got {type(settings).__name__}")
    plan, controller, points, shape, arrays, growth_tolerance = _planned_tests(
        system, omega, amplitude, scheme=scheme, delay=delay,
        guessed_inertance=guessed_inertance, guessed_force=guessed_force,
        prediction=prediction, prediction_order=prediction_order,
        prediction_horizon=prediction_horizon, actuator_lag=actuator_lag,
        parasitic_stiffness=parasitic_stiffness, sample_rate=sample_rate,
        substeps=substeps, periods=periods, measure_periods=measure_periods,
        divergence_factor=divergence_factor, growth_tolerance=growth_tolerance,
    )
    out = _simulate_batch(plan, controller, system, points)
    out["stable"] = ~out["diverged"] & (out["growth"] <= 1 + growth_tolerance)
    fields = {key: jnp.reshape(value, shape) for key, value in out.items()}
    if reference:
        fields.update(_against_whole(system, points, shape, fields, settings))
    dtype = jnp.result_type(float)
    return Substructuring(
        **{name: jnp.asarray(np.broadcast_to(array, shape), dtype) for name, array in zip(
            ("omega", "amplitude", "delay", "guessed_inertance"), arrays, strict=True)},
        **fields,
    )


def _against_whole(system, points: _Point, shape, fields, settings) -> dict:
    """The whole system's steady state at each test's (omega, amplitude) (each distinct
    pair solved once) and the test's amplitude and phase errors against it."""
    omegas, amplitudes = np.asarray(points.omega), np.asarray(points.amplitude)
    pairs, inverse = np.unique(np.stack([omegas, amplitudes], axis=1), axis=0,
                               return_inverse=True)
    dtype = jnp.result_type(float)
    whole = _reference_batch(
        system, jnp.asarray(pairs[:, 0], dtype), jnp.asarray(pairs[:, 1], dtype), settings
    )
    whole = {key: jnp.reshape(value[inverse.reshape(-1)], shape) for key, value in whole.items()}

    def wrap(angle):
        return jnp.angle(jnp.exp(1j * angle))

    return dict(
        reference_x_max=whole["x_max"],
        reference_y_max=whole["y_max"],
        reference_x_phase=whole["x_phase"],
        reference_y_phase=whole["y_phase"],
        x_amplitude_error=fields["x_max"] / whole["x_max"] - 1,
        y_amplitude_error=fields["y_max"] / whole["y_max"] - 1,
        x_phase_error=wrap(fields["x_phase"] - whole["x_phase"]),
        y_phase_error=wrap(fields["y_phase"] - whole["y_phase"]),
        reference_converged=whole["converged"],
    )


def substructuring_stability(
    system: TIDSystem,
    omega: float,
    amplitude: float,
    *,
    guessed_inertance: ArrayLike,
    delay: ArrayLike,
    **options,
) -> SubstructuringStability:
    """Stability of the RTDS test at one forcing (`omega` rad/s, `amplitude` N) on the
    grid `guessed_inertance` (b_g, kg, 1-d) x `delay` (s, 1-d, increasing), with the
    largest stable delay for each b_g. `options` are those of `simulate_substructuring`
    (default scheme "error_feedback"); all points run in one batched call.

    **Returns:** a `SubstructuringStability`.
    """
    if "reference" in options:
        raise ValueError("options must not contain reference (stability needs none)")
    guesses = real_array("guessed_inertance", guessed_inertance, "positive")
    delays = real_array("delay", delay, "non-negative")
    for name, array in (("guessed_inertance", guesses), ("delay", delays)):
        if array.ndim != 1:
            raise ValueError(f"{name} must be 1-d, got shape {array.shape}")
    if np.any(np.diff(delays) <= 0):
        raise ValueError(f"delay must be strictly increasing, got {delays.tolist()!r}")
    real_scalar("omega", omega, "positive")
    real_scalar("amplitude", amplitude, "positive")
    result = simulate_substructuring(
        system,
        omega,
        amplitude,
        guessed_inertance=guesses[:, None],
        delay=delays[None, :],
        reference=False,
        **options,
    )
    stable = np.asarray(result.stable)
    run = np.cumprod(stable, axis=1).astype(bool)  # stable at this and every smaller delay
    count = run.sum(axis=1)
    largest = np.where(count > 0, delays[np.maximum(count - 1, 0)], -1.0)
    dtype = jnp.result_type(float)
    return SubstructuringStability(
        guessed_inertance=jnp.asarray(guesses, dtype),
        delay=jnp.asarray(delays, dtype),
        stable=jnp.asarray(stable),
        largest_stable_delay=jnp.asarray(largest, dtype),
    )
