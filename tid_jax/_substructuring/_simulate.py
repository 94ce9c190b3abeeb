"""Virtual real-time dynamic substructuring (RTDS) test of the inerter, paper section 5.

The host structure and the TID's spring and damper are numerical; the inerter is
"physical": the whole device of the `TIDSystem` (inertance, friction, parasitic damping,
terminal mass, and a series stiffness with backlash where it has them). A digital
controller advances the numerical substructure sample by sample, commands the interface
kinematics to an actuator (a delay line with an optional first-order lag, compensated by
default by forward prediction, as in the paper) and feeds the force measured at the
interface back into the numerical model, held over each sample.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._model._building import BuildingTID, Quantity, building_of
from .._model._checks import check_concrete_system, choice, integer, real_array, real_scalar
from .._model._system import TIDSystem
from .._orbit._settings import SolverSettings
from ._building_rtds import BuildingModel, building_reference, building_scale, check_building_test
from ._rtds_loop import (
    MAX_PREDICTION_ORDER,
    Controller,
    Plan,
    Point,
    simulate_batch,
)

SCHEMES = ("conventional", "error_feedback")
GUESSED_FORCES = ("acceleration", "harmonic")
PREDICTIONS = ("polynomial", "harmonic")
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


# Public functions ------------------------------------------------------------------------


def _planned_tests(system, omega, amplitude, *, scale, scheme, delay, guessed_inertance,
                   guessed_force, prediction, prediction_order, prediction_horizon,
                   actuator_lag, sample_rate, substeps, periods,
                   measure_periods, divergence_factor, growth_tolerance):
    """The checked options of `simulate_substructuring` as the static `Plan`, the
    `Controller` and the flat batch of `Point`s, with the broadcast grid's shape and
    arrays `(omega, amplitude, delay, guessed_inertance)`; `scale(omegas)`: the size of
    the motion per unit amplitude that a diverged test leaves (m)."""
    choice("scheme", scheme, SCHEMES)
    choice("guessed_force", guessed_force, GUESSED_FORCES)
    if prediction is not None:
        choice("prediction", prediction, PREDICTIONS)
    if guessed_inertance is None:
        guessed_inertance = float(system.inertance) + float(system.terminal_mass)
    arrays, shape = _grid(omega, amplitude, delay, guessed_inertance)
    rate = real_scalar("sample_rate", sample_rate, "positive")
    order = integer("prediction_order", prediction_order, 0, MAX_PREDICTION_ORDER)
    substeps = integer("substeps", substeps, 1)
    measure_periods = integer("measure_periods", measure_periods, 1)
    periods = integer("periods", periods, 3 * measure_periods)
    lag = real_scalar("actuator_lag", actuator_lag, "non-negative")
    factor = real_scalar("divergence_factor", divergence_factor, "positive")
    if factor <= 1:
        raise ValueError(f"divergence_factor must be > 1, got {divergence_factor!r}")
    growth_tolerance = real_scalar("growth_tolerance", growth_tolerance, "positive")
    n_steps, horizon = _duration(arrays, rate, periods, prediction, prediction_horizon)
    points = _points(scale, shape, arrays, horizon, rate=rate, lag=lag, factor=factor,
                     measure_periods=measure_periods)
    # One spare slot beyond the two read (against rounding of the delay), rounded up to a
    # power of two (at least 32) so that nearby delays share the compiled code.
    needed = int(math.floor(float(np.max(points.delay_samples)))) + 3
    plan = Plan(
        scheme=scheme,
        compliant=bool(system.compliant),
        substeps=substeps,
        buffer_length=max(32, 1 << (needed - 1).bit_length()),
    )
    controller = Controller(
        dt=jnp.asarray(1 / rate, points.omega.dtype),
        n_steps=jnp.asarray(n_steps),
        prediction=jnp.asarray(0 if prediction is None else 1 + PREDICTIONS.index(prediction)),
        prediction_order=jnp.asarray(order),
        harmonic_guess=jnp.asarray(guessed_force == "harmonic"),
    )
    return plan, controller, points, shape, arrays, growth_tolerance


def _grid(omega, amplitude, delay, guessed_inertance):
    """The checked arrays `(omega, amplitude, delay, guessed_inertance)` and the shape
    they broadcast to."""
    arrays = (
        real_array("omega", omega, "positive"),
        real_array("amplitude", amplitude, "positive"),
        real_array("delay", delay, "non-negative"),
        real_array("guessed_inertance", guessed_inertance, "positive"),
    )
    try:
        return arrays, np.broadcast_shapes(*(array.shape for array in arrays))
    except ValueError:
        shapes = [array.shape for array in arrays]
        raise ValueError(
            "omega, amplitude, delay and guessed_inertance must broadcast together, got "
            f"shapes {shapes[0]}, {shapes[1]}, {shapes[2]} and {shapes[3]}"
        ) from None


def _duration(arrays, rate, periods, prediction, prediction_horizon):
    """The samples simulated and the prediction horizon (s, broadcasting with the
    delays), checked against the sample rate and the simulated duration."""
    omega_array, _, delay_array, _ = arrays
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
    if prediction is None:
        return n_steps, np.zeros(())
    if prediction_horizon is None:
        return n_steps, delay_array + 0.5 / rate  # the hold lags half a sample on average
    horizon = real_scalar("prediction_horizon", prediction_horizon, "non-negative")
    if horizon >= duration / 2:
        raise ValueError(
            f"prediction_horizon must be shorter than half the simulated duration "
            f"({duration:g} s), got {prediction_horizon!r}"
        )
    return n_steps, np.asarray(horizon)


def _points(scale, shape, arrays, horizon, *, rate, lag, factor, measure_periods) -> Point:
    """The flat batch of tests over the broadcast grid."""
    omegas, amplitudes, delays, guesses, horizons = (
        np.broadcast_to(a, shape).reshape(-1)
        for a in (*arrays, np.broadcast_to(horizon, arrays[2].shape))
    )
    scale = scale(omegas) * amplitudes
    dtype = jnp.result_type(float)
    return Point(
        omega=jnp.asarray(omegas, dtype),
        amplitude=jnp.asarray(amplitudes, dtype),
        delay_samples=jnp.asarray(delays * rate, dtype),
        guessed_inertance=jnp.asarray(guesses, dtype),
        horizon=jnp.asarray(horizons, dtype),
        lag=jnp.full(omegas.shape, lag, dtype),
        bound=jnp.asarray(factor * scale, dtype),
        window=jnp.asarray(measure_periods * 2 * np.pi / omegas, dtype),
    )


def simulate_substructuring(
    system: TIDSystem | BuildingTID,
    omega: ArrayLike,
    amplitude: ArrayLike,
    *,
    quantity: Quantity | None = None,
    scheme: str = "error_feedback",
    delay: ArrayLike = DEFAULT_DELAY,
    guessed_inertance: ArrayLike | None = None,
    guessed_force: str = "acceleration",
    prediction: str | None = "harmonic",
    prediction_order: int = 2,
    prediction_horizon: float | None = None,
    actuator_lag: float = 0.0,
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
    `actuator_lag` (discretised per sample). The physical device answers with
    f_s = (b + mt) y*'' + cp y*' + ff sgn(y*') (the smoothed sign of
    `frequency_response`), or, where it has a series stiffness ks (and backlash g), with
    mt y*'' + ks D(y* - u), its mechanism u moving as b u'' + cp u' + ff sgn(u') =
    ks D(y* - u), D the dead zone of half-width g / 2. The fed-back force is held over the
    sample while RK4 advances the numerical substructure (zero-order hold, so even with no
    delay the loop lags by the sampling: errors are first order in 1 / `sample_rate`). The
    test starts on the frictionless steady state with the matching history. A test whose
    |x| or |y| leaves the divergence bound is frozen and reported as diverged, never as
    NaN.

    **Arguments:**

    - `system`: the emulated `TIDSystem`; its inertance, friction and device terms
      (`parasitic_damping`, `terminal_mass`, `series_stiffness`, `backlash`) are the
      physical device's. Or a `BuildingTID` (smoothed friction): the numerical
      substructure is the structure with the spring and damper (`_building_rtds`), the
      interface the stroke r (y below), and x is `quantity` (default: the top floor's
      displacement); a terminal mass on a floor couples its motion to the floor's, and
      that part stays numerical.
    - `omega`: forcing circular frequency, rad/s.
    - `amplitude`: forcing amplitude A of `A sin(omega t)`, N (a building's load: N or
      m/s2).
    - `quantity`: a building's measured `Quantity` (None for a `TIDSystem`).
    - `scheme`: "conventional" (feed back f_s, eqs. (13)-(14): an advanced equation,
      unstable for any delay) or "error_feedback" (feed back e = f_s - b_g y*'',
      eq. (16)).
    - `delay`: actuator delay tau, s.
    - `guessed_inertance`: b_g, kg (default the device's inertance plus its terminal
      mass; unused by the conventional scheme).
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
      amplitude and phase errors; a compliant device is compared with the whole system
      of its rigid counterpart (no series stiffness or backlash), the design the test
      checks. A building is compared with its own whole system (`frequency_response`'s
      model, the compliant device included).
    - `settings`: `SolverSettings` of that whole-system solve.

    `omega`, `amplitude`, `delay` and `guessed_inertance` broadcast against each other;
    all points run in one compiled, vmapped call.

    **Returns:** a `Substructuring`.
    """
    system, whole, quantity = _tested(system, quantity, scheme)
    model = BuildingModel(system, quantity)
    scale = lambda omegas: building_scale(system, quantity, omegas)
    if not isinstance(settings, SolverSettings):
        raise ValueError(f"settings must be a SolverSettings, got {type(settings).__name__}")
    plan, controller, points, shape, arrays, growth_tolerance = _planned_tests(
        system, omega, amplitude, scale=scale, scheme=scheme, delay=delay,
        guessed_inertance=guessed_inertance, guessed_force=guessed_force,
        prediction=prediction, prediction_order=prediction_order,
        prediction_horizon=prediction_horizon, actuator_lag=actuator_lag,
        sample_rate=sample_rate,
        substeps=substeps, periods=periods, measure_periods=measure_periods,
        divergence_factor=divergence_factor, growth_tolerance=growth_tolerance,
    )
    measured = simulate_batch(plan, controller, model, points)
    fields = {name: jnp.reshape(getattr(measured, name), shape)
              for name in ("x_max", "y_max", "x_phase", "y_phase", "diverged", "growth")}
    fields["stable"] = ~fields["diverged"] & (fields["growth"] <= 1 + growth_tolerance)
    if reference:
        fields.update(_against_whole(whole, quantity, points, shape, fields, settings))
    dtype = jnp.result_type(float)
    return Substructuring(
        **{name: jnp.asarray(np.broadcast_to(array, shape), dtype) for name, array in zip(
            ("omega", "amplitude", "delay", "guessed_inertance"), arrays, strict=True)},
        **fields,
    )


def _tested(system, quantity: Quantity | None, scheme: str):
    """The building whose test is simulated, the whole system it is compared with and
    the measured quantity, checked: a `TIDSystem` as its one-storey building, compared
    with its rigid counterpart (the design the test checks)."""
    whole = system
    if isinstance(system, TIDSystem):
        check_concrete_system(system)
        if quantity is not None:
            raise ValueError("quantity is for a BuildingTID; a TIDSystem measures x and y")
        whole = system.replace(series_stiffness=None, backlash=0.0)
    system = building_of(system, "force")
    quantity = Quantity() if quantity is None else quantity
    quantity.floor_of(system.floors)
    check_building_test(system, scheme)
    return system, whole, quantity


def _against_whole(system, quantity: Quantity, points: Point, shape, fields,
                   settings) -> dict:
    """The whole system's steady state at each test's (omega, amplitude) (each distinct
    pair solved once) and the test's amplitude and phase errors against it."""
    omegas, amplitudes = np.asarray(points.omega), np.asarray(points.amplitude)
    pairs, inverse = np.unique(np.stack([omegas, amplitudes], axis=1), axis=0,
                               return_inverse=True)
    dtype = jnp.result_type(float)
    whole = building_reference(system, quantity, jnp.asarray(pairs[:, 0], dtype),
                               jnp.asarray(pairs[:, 1], dtype), settings)
    whole = [jnp.reshape(value[inverse.reshape(-1)], shape) for value in whole]
    return _errors(fields, whole)


def _errors(fields, whole) -> dict:
    """The whole system's values (peaks, phases, convergence) and the test's errors
    against them."""
    x_max, y_max, x_phase, y_phase, converged = whole

    def wrap(angle):
        return jnp.angle(jnp.exp(1j * angle))

    return dict(
        reference_x_max=x_max,
        reference_y_max=y_max,
        reference_x_phase=x_phase,
        reference_y_phase=y_phase,
        x_amplitude_error=fields["x_max"] / x_max - 1,
        y_amplitude_error=fields["y_max"] / y_max - 1,
        x_phase_error=wrap(fields["x_phase"] - x_phase),
        y_phase_error=wrap(fields["y_phase"] - y_phase),
        reference_converged=converged,
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
    """Stability of the RTDS test at one forcing on a grid of guessed inertances and
    delays, with the largest stable delay for each guess; all points run in one batched
    call.

    **Arguments:**

    - `system`: the emulated `TIDSystem`, as in `simulate_substructuring`.
    - `omega`: forcing circular frequency, rad/s.
    - `amplitude`: forcing amplitude, N.
    - `guessed_inertance`: b_g, kg, 1-d.
    - `delay`: actuator delays, s, 1-d and increasing.
    - `options`: any other keyword of `simulate_substructuring` but `reference` (default
      scheme "error_feedback").

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
