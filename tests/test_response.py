import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st

import tid_jax as tj
from tests.reference.coulomb import coulomb_steady_state

RATIOS = np.linspace(0.7, 1.3, 25)  # omega / host frequency; contains 0.85, 0.9, ..., 1.1
AMPLITUDES = [100.0, 200.0, 1000.0, 3000.0]
REFERENCE_RATIOS = [0.85, 0.9, 0.95, 1.0, 1.05, 1.1]


@pytest.fixture(scope="module")
def system():
    """The paper's system with the smoothed friction at the relative width (the
    integrated model these tests are about; exact friction is `test_coulomb`'s)."""
    return tj.paper_system(friction_width=None)


@pytest.fixture(scope="module")
def omegas(system):
    return RATIOS * float(system.host_frequency)


@pytest.fixture(scope="module")
def nonlinear(system, omegas):
    return tj.frequency_response(system, omegas, AMPLITUDES)


@pytest.fixture(scope="module")
def frictionless(system, omegas):
    return tj.frequency_response(system.replace(friction_force=0.0), omegas, AMPLITUDES)


def _normalised(result, system):
    return np.asarray(result.x_max) / (np.asarray(result.amplitudes)[:, None] / float(
        system.host_stiffness))


def test_frictionless_matches_receptance(system, omegas, frictionless):
    host, inerter = tj.linear_receptance(system, omegas)
    amps = np.asarray(AMPLITUDES)[:, None]
    assert frictionless.x_max.shape == (4, 25)
    assert bool(jnp.all(frictionless.converged))
    np.testing.assert_allclose(frictionless.x_max, np.abs(host) * amps, rtol=1e-5)
    np.testing.assert_allclose(frictionless.y_max, np.abs(inerter) * amps, rtol=1e-5)
    # A linear, damped system's periodic orbit is stable.
    assert bool(jnp.all(frictionless.stable))
    assert float(jnp.max(jnp.abs(frictionless.floquet_multipliers))) < 1


def test_all_nonlinear_points_converge(nonlinear):
    assert bool(jnp.all(nonlinear.converged))
    assert float(jnp.max(nonlinear.residual)) <= tj.SolverSettings().periodicity_tol
    assert np.all(np.isfinite(nonlinear.x_max)) and np.all(np.isfinite(nonlinear.y_max))


@pytest.mark.parametrize("amplitude", [100.0, 200.0, 1000.0])
def test_matches_exact_coulomb_reference(system, nonlinear, amplitude):
    row = AMPLITUDES.index(amplitude)
    parameters = {name: float(getattr(system, name)) for name in
                  ("host_mass", "host_stiffness", "host_damping", "inertance", "friction_force",
                   "tid_stiffness", "tid_damping")}
    for ratio in REFERENCE_RATIOS:
        column = int(np.argmin(np.abs(RATIOS - ratio)))
        omega = RATIOS[column] * float(system.host_frequency)
        reference = coulomb_steady_state(**parameters, omega=omega, amplitude=amplitude)
        assert reference["converged"]
        x_max = float(nonlinear.x_max[row, column])
        assert x_max == pytest.approx(reference["x_max"], rel=5e-3), (amplitude, ratio)


def test_converges_to_coulomb_as_width_shrinks(system):
    # Stick-slip point: A = 100 N just below the host frequency.
    omega = 0.95 * float(system.host_frequency)
    parameters = {name: float(getattr(system, name)) for name in
                  ("host_mass", "host_stiffness", "host_damping", "inertance", "friction_force",
                   "tid_stiffness", "tid_damping")}
    exact = coulomb_steady_state(**parameters, omega=omega, amplitude=100.0)["x_max"]
    errors = []
    for width in (1e-3, 1e-4, 1e-5):
        result = tj.frequency_response(system.replace(friction_width=width), omega, 100.0)
        assert bool(result.converged)
        errors.append(abs(float(result.x_max) / exact - 1))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-3


def test_stuck_limit_is_sdof_with_combined_stiffness_and_damping(system):
    # Forcing well below the slip threshold (about 23 N): the inerter terminal stays stuck
    # and the host responds as a single-degree-of-freedom system with K + k and C + c. The
    # smoothed friction lets the terminal creep; that error shrinks with the width.
    for ratio, amplitude in ((0.9, 5.0), (1.1, 5.0)):
        omega = ratio * float(system.host_frequency)
        expected = amplitude * abs(complex(tj.stuck_receptance(system, omega)))
        errors = []
        for width in (1e-4, 1e-5):
            result = tj.frequency_response(system.replace(friction_width=width), omega, amplitude)
            assert bool(result.converged)
            assert float(result.stick_fraction) == 1.0
            errors.append(abs(float(result.x_max) / expected - 1))
        assert errors[1] < 1e-3
        assert errors[1] < errors[0] / 5


def _count_peaks(curve):
    inner = curve[1:-1]
    return int(np.sum((inner > curve[:-2]) & (inner > curve[2:])))


def test_figure_5_behaviour(system, omegas, nonlinear):
    normalised = _normalised(nonlinear, system)
    linear = np.abs(np.asarray(tj.linear_receptance(system, omegas).host)) * float(
        system.host_stiffness)
    linear_peak = 5.433  # Den Hartog-tuned linear TID with 2% host damping (theory)
    # A = 100 N: friction locks the inerter; one resonance peak, far above the linear one.
    assert _count_peaks(normalised[0]) == 1
    assert normalised[0].max() > 1.4 * linear_peak
    # Large amplitudes: two peaks, approaching the linear TID's curve.
    assert _count_peaks(normalised[3]) == 2
    deviation = np.max(np.abs(normalised - linear[None, :]), axis=1) / linear_peak
    assert deviation[0] > deviation[1] > deviation[2] > deviation[3]
    assert deviation[3] < 0.03


@hypothesis_settings(max_examples=8, deadline=None, derandomize=True)
@given(
    ratio=st.floats(0.6, 1.5),
    amplitude=st.floats(1.0, 5000.0),
    scale=st.floats(0.01, 100.0),
)
def test_frictionless_response_is_linear_in_amplitude(ratio, amplitude, scale):
    system = tj.paper_system(friction_force=0.0)
    omega = ratio * float(system.host_frequency)
    base = tj.frequency_response(system, omega, amplitude)
    scaled = tj.frequency_response(system, omega, amplitude * scale)
    assert float(scaled.x_max) == pytest.approx(scale * float(base.x_max), rel=1e-7)
    assert float(scaled.y_max) == pytest.approx(scale * float(base.y_max), rel=1e-7)


def test_shapes(system):
    w = float(system.host_frequency)
    point = tj.frequency_response(system, w, 300.0)
    assert point.x_max.shape == () and point.state.shape == (4,)
    assert point.floquet_multipliers.shape == (4,)
    row = tj.frequency_response(system, [w], [300.0])
    assert row.x_max.shape == (1, 1)
    assert float(row.x_max[0, 0]) == pytest.approx(float(point.x_max), rel=1e-12)


def test_grid_shapes(nonlinear):
    for name in ("x_max", "y_max", "converged", "stable", "residual", "newton_steps",
                 "stick_fraction"):
        assert getattr(nonlinear, name).shape == (4, 25), name
    assert nonlinear.state.shape == (4, 25, 4)
    assert nonlinear.floquet_multipliers.shape == (4, 25, 4)


@pytest.mark.parametrize(
    "omegas, amplitudes, message",
    [
        ([], [100.0], "omegas must not be empty"),
        ([25.0], [], "amplitudes must not be empty"),
        ([25.0, -1.0], [100.0], "omegas must be finite and positive, got -1.0"),
        ([0.0], [100.0], "omegas must be finite and positive, got 0.0"),
        ([25.0], [float("nan")], "amplitudes must be finite and positive, got nan"),
        ([25.0], [float("inf")], "amplitudes must be finite and positive, got inf"),
        ([[25.0]], [100.0], "omegas must be a scalar or 1-d"),
        (["fast"], [100.0], "omegas must be numbers"),
    ],
)
def test_bad_grids_raise(system, omegas, amplitudes, message):
    with pytest.raises(ValueError, match=message):
        tj.frequency_response(system, omegas, amplitudes)


def test_single_precision_is_refused():
    # Without float64 the steady states cannot reach their tolerances: a clear error, not
    # minutes of failed solves. (A fresh process: this one computes in float64.)
    import subprocess
    import sys

    code = ("import tid_jax as tj\n"
            "try:\n"
            "    tj.frequency_response(tj.paper_system(), [25.0], [100.0])\n"
            "except ValueError as error:\n"
            "    print(error)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, env={"JAX_ENABLE_X64": "0", "JAX_PLATFORMS": "cpu",
                                           "PATH": ""})
    assert "tid_jax needs double precision" in done.stdout


def test_unconverged_point_is_flagged_and_retried(system):
    # One Newton iteration from the linear guess cannot reach the stick-slip orbit: the
    # batched solve flags the point; frequency_response then solves it again, persistently.
    from tid_jax._response import _solve_blocks, batched

    settings = tj.SolverSettings(transient_periods=0, max_newton_steps=1)
    omega = jnp.array([0.95 * float(system.host_frequency)])
    first = _solve_blocks(settings, (omega, jnp.array([100.0]), batched(system, 1)))
    assert not bool(first.converged[0])
    assert float(first.residual[0]) > settings.periodicity_tol
    # The peaks of an orbit that was not found are not reported as numbers.
    assert np.isnan(float(first.x_max[0])) and np.isnan(float(first.y_max[0]))
    result = tj.frequency_response(system, omega[0], 100.0, settings=settings)
    assert bool(result.converged)


# Below the slip threshold (about 23 N) the terminal sticks, where the smoothed friction
# is stiff: at a width of 1e-6 m/s, no period of the stuck orbit is integrated within the
# explicit steps allowed (the default limit: the compiled programs of the other tests of
# a width in m/s, `test_reach`'s among them).
STUCK, STIFF_WIDTH = 5.0, 1e-6


def test_a_point_that_no_attempt_integrates_is_flagged_and_its_peaks_are_nan(system):
    # At the stiff stuck point, 16 steps per period are too few for the explicit and the
    # implicit integrations alike: every attempt runs out of steps. The point is reported
    # as not converged, no period integrated (residual inf), its peaks NaN, never a
    # plausible number; so is the peak over a band holding it.
    settings = tj.SolverSettings(max_steps=16, max_newton_steps=1)
    host = float(system.host_frequency)
    stiff = system.replace(friction_width=STIFF_WIDTH)
    result = tj.frequency_response(stiff, 0.95 * host, STUCK, settings=settings)
    assert not bool(result.converged) and np.isinf(float(result.residual))
    assert np.isnan(float(result.x_max)) and np.isnan(float(result.y_max))
    band = np.linspace(0.9, 1.1, 5) * host
    peaks = tj.peaks(stiff, band, [STUCK], settings=settings)
    assert not bool(peaks.converged[0])
    assert np.isnan(float(peaks.x_peak[0])) and np.isnan(float(peaks.y_peak[0]))


def test_a_point_whose_explicit_steps_run_out_is_solved_implicitly(system):
    # The explicit steps allowed integrate no period of the stiff stuck orbit
    # (`test_an_orbit_whose_integration_ran_out_of_steps_is_not_converged`); solved again
    # with the implicit Kvaerno5, the point converges to the stuck orbit: the host as a
    # single-degree-of-freedom system with K + k and C + c (the smoothed friction lets
    # the terminal creep, by 1e-5 here).
    omega = 0.95 * float(system.host_frequency)
    result = tj.frequency_response(system.replace(friction_width=STIFF_WIDTH), omega, STUCK)
    assert bool(result.converged) and float(result.stick_fraction) == 1.0
    expected = STUCK * abs(complex(tj.stuck_receptance(system, omega)))
    assert float(result.x_max) == pytest.approx(expected, rel=1e-4)


def test_a_near_miss_is_solved_as_accurately_as_with_newton_iterations_enough(system):
    # One Newton iteration from the linear steady state falls short of the stick-slip
    # orbit (`test_unconverged_point_is_flagged_and_retried`). Shot on from where it
    # stopped, integrated more accurately, the point converges to the steady state of
    # Newton's iterations enough to converge at once, as accurately integrated, to 1e-9
    # (a solve from the linear steady state again, which stops within the periodicity
    # tolerance, is 1.5e-8 away).
    omega = 0.95 * float(system.host_frequency)
    settings = tj.SolverSettings(transient_periods=0, max_newton_steps=1)
    result = tj.frequency_response(system, omega, 100.0, settings=settings)
    assert bool(result.converged)
    reference = tj.frequency_response(system, omega, 100.0,
                                      settings=tj.SolverSettings().more_accurate())
    np.testing.assert_allclose(result.x_max, reference.x_max, rtol=1e-9)
    np.testing.assert_allclose(result.y_max, reference.y_max, rtol=1e-8)


def test_a_near_miss_stalled_at_the_integration_error_converges():
    # Integrated at rtol 1e-5 (after coarse iterations at 1e-4: the program of the default
    # settings, whose tolerances are its arguments), the period map errs by more than a
    # periodicity tolerance of 1e-6 (at 1000 N, by 3e-5 to 4e-4): Newton's iterations
    # stall at a finite residual. Solved again, integrated more accurately, every point
    # converges, to the steady states of the default settings (within 1e-6).
    smoothed = tj.paper_system(friction_width=None)
    settings = tj.SolverSettings(rtol=1e-5, atol=1e-5, coarse_rtol=1e-4, periodicity_tol=1e-6)
    omegas = np.array([1.0, 1.1, 1.2]) * float(smoothed.host_frequency)
    result = tj.frequency_response(smoothed, omegas, [1000.0], settings=settings)
    assert bool(np.all(result.converged))
    assert float(np.max(result.residual)) <= settings.periodicity_tol
    reference = tj.frequency_response(smoothed, omegas, [1000.0])
    np.testing.assert_allclose(result.x_max, reference.x_max, rtol=1e-6)
    np.testing.assert_allclose(result.y_max, reference.y_max, rtol=1e-6)


def _orbit_at(system, amplitude, omega):
    """Jitted (k, c) -> the orbit of `system` tuned to (k, c), at one forcing point."""
    import jax

    from tid_jax._orbit._flow import PlantInputs
    from tid_jax._orbit._steady_state import SolverSettings, solve_orbit

    def orbit(k, c):
        tuned = system.replace(tid_stiffness=k, tid_damping=c)
        return solve_orbit(PlantInputs(tuned, amplitude, omega, tj.Quantity()),
                           SolverSettings().for_system(system))

    return jax.jit(orbit)


def test_state_derivatives_match_finite_differences(system):
    # The implicit derivatives of the orbit's state with respect to the tuning (k, c) that
    # retune's continuation predicts from, against central differences of orbits solved
    # afresh, at 200 N where the inerter sticks for part of the period.
    import jax

    from tid_jax._orbit._flow import PlantInputs
    from tid_jax._orbit._steady_state import solve_orbit

    omega, k, c = 0.95 * float(system.host_frequency), float(system.tid_stiffness), float(
        system.tid_damping)
    solve = _orbit_at(system, 200.0, omega)
    settings = tj.SolverSettings().for_system(system)
    derivatives = jax.jit(lambda z: solve_orbit(
        PlantInputs(system, 200.0, omega, tj.Quantity()), settings, z,
        fields=("tid_stiffness", "tid_damping")).field_derivatives)(solve(k, c).state)
    assert derivatives.shape == (4, 2)
    for column, (dk, dc) in enumerate([(1e-4 * k, 0.0), (0.0, 1e-4 * c)]):
        plus, minus = solve(k + dk, c + dc).state, solve(k - dk, c - dc).state
        fd = np.asarray(plus - minus) / (2 * (dk + dc))
        np.testing.assert_allclose(np.asarray(derivatives[:, column]), fd,
                                   rtol=1e-3, atol=1e-3 * np.max(np.abs(fd)))


def _plant(system, amplitude, omega):
    from tid_jax._orbit._period import point_model

    return point_model(system, tj.Quantity(), amplitude, omega)[0]


def test_chord_iterations_settle_on_the_orbit_from_a_nearby_one(system):
    # From the orbit (state and monodromy) of a 2% stiffer TID, chord iterations without
    # tangents reach the orbit that Newton's method finds from the linear guess.
    import jax

    from tid_jax._orbit._sampled_peaks import refined_peak
    from tid_jax._orbit._steady_state import SolverSettings, settled_state

    omega, k, c = float(system.host_frequency), float(system.tid_stiffness), float(
        system.tid_damping)
    solve = _orbit_at(system, 300.0, omega)
    near, exact = solve(1.02 * k, c), solve(k, c)
    p = _plant(system, 300.0, omega)
    settings = SolverSettings().for_system(system)
    state, samples = jax.jit(lambda z, m: settled_state(z, p, settings, m))(
        near.state, near.monodromy)
    np.testing.assert_allclose(np.asarray(state), np.asarray(exact.state), atol=1e-5)
    assert float(refined_peak(samples)) == pytest.approx(float(refined_peak(exact.x_samples)),
                                                         rel=1e-5)


# A band for `peak_response` (as multiples of the host frequency): that of `test_retune`'s
# derivative-free search, whose compiled program of exact friction these tests share.
PEAK_BAND = np.linspace(0.8, 1.2, 41)


def test_peak_over_a_band_with_an_unconverged_orbit_is_nan_not_a_number():
    # An orbit that was not found leaves the differentiable peak over frequency NaN, never
    # a finite number: with exact friction, one Newton iteration from the linear steady
    # state does not reach the stick-slip orbits at 100 N.
    paper = tj.paper_system()
    band = PEAK_BAND * float(paper.host_frequency)
    once = tj.SolverSettings(max_newton_steps=1)
    assert np.isnan(float(tj.peak_response(paper, band, 100.0, settings=once)))
    assert np.isfinite(float(tj.peak_response(paper, band, 100.0)))


def test_an_orbit_whose_integration_ran_out_of_steps_is_not_converged(system):
    # The single orbits of `peak_response`'s sweep (`point_response`), at the stiff stuck
    # point: the explicit steps ran out; not converged, the peaks inf (and the band's
    # peak NaN, above).
    from tid_jax._response import point_response

    stiff = system.replace(friction_width=STIFF_WIDTH)
    orbit, x_max, y_max = jax.jit(
        lambda omega: point_response(stiff, omega, STUCK, tj.SolverSettings()))(
        0.95 * float(system.host_frequency))
    assert not bool(orbit.converged) and np.isinf(float(orbit.residual))
    assert np.isposinf(float(x_max)) and np.isposinf(float(y_max))


def _compiling(call):
    """`call()` and the compilation events of JAX (`jax.monitoring`: tracing for jit,
    lowering, compiling) that it caused."""
    events = []

    def listener(event, duration, **kwargs):
        if event.startswith("/jax/core/compile/"):
            events.append((event, kwargs.get("fun_name")))

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        return call(), events
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)


def test_the_peaks_programs_serve_any_number_of_lanes():
    # The peaks of eighteen amplitudes in one call (two chunks of lanes, the second
    # padded) are those of each amplitude alone, and the programs of that call serve one
    # lane: the calls for one amplitude trace and compile nothing.
    paper = tj.paper_system()
    band = np.linspace(0.8, 1.25, 13) * float(paper.host_frequency)
    amplitudes = np.linspace(150.0, 3000.0, 18)
    together = tj.peaks(paper, band, amplitudes)
    assert bool(np.all(together.converged))
    lanes = (0, 9, 17)
    alone, events = _compiling(
        lambda: [tj.peaks(paper, band, amplitudes[i : i + 1]) for i in lanes])
    assert events == []
    for i, one in zip(lanes, alone, strict=True):
        for field in ("x_peak", "y_peak", "omega_x", "omega_y", "at_edge"):
            np.testing.assert_allclose(np.asarray(getattr(together, field))[i],
                                       np.asarray(getattr(one, field))[0], rtol=1e-12)


def test_peak_response_is_compiled_once_for_every_amplitude_and_tolerance():
    # The amplitude, given as a Python number, the system's fields, whether made from
    # Python or NumPy numbers, and the solver's tolerances and Newton iterations are
    # arguments of the compiled program, not constants of it: once one call has run,
    # later ones trace and compile nothing; nor do settings fitted to the system
    # beforehand.
    paper = tj.paper_system()
    band = PEAK_BAND * float(paper.host_frequency)
    peaks = [float(tj.peak_response(paper, band, 100.0))]
    tight = tj.SolverSettings(exact_periodicity_tol=1e-13, max_newton_steps=20)
    stiffer = paper.replace(tid_stiffness=np.float64(1.01) * float(paper.tid_stiffness),
                            inertance=np.int64(75))
    fitted = tj.SolverSettings().for_system(paper)

    def later():
        return ([float(tj.peak_response(paper, band, amplitude)) for amplitude in (150.0, 200.0)],
                float(tj.peak_response(paper, band, 200.0, settings=tight)),
                float(tj.peak_response(stiffer, band, 200.0)),
                float(tj.peak_response(paper, band, 200.0, settings=fitted)))

    (more, tightly, stiffer_peak, fitted_peak), events = _compiling(later)
    assert events == []
    peaks += more
    assert np.all(np.diff(peaks) > 0)
    assert tightly == pytest.approx(peaks[-1], rel=1e-8)
    assert np.isfinite(stiffer_peak) and stiffer_peak != peaks[-1]
    assert fitted_peak == peaks[-1]


def test_coarse_newton_iterations_reach_the_orbits_of_a_tight_solve(system, omegas, nonlinear):
    # The batch's first Newton iterations integrate coarsely (`coarse_rtol`) until the
    # residual is within `coarse_residual`: the orbits are those of a solve at rtol 1e-10
    # to a periodicity residual of 1e-10 (x within 1e-5; y, which a stuck inerter makes
    # small and weakly determined, within 1e-4 of the static displacement).
    tight = tj.SolverSettings(rtol=1e-10, atol=1e-10, periodicity_tol=1e-10,
                              max_newton_steps=30)
    reference, events = _compiling(
        lambda: tj.frequency_response(system, omegas, AMPLITUDES, settings=tight))
    assert bool(jnp.all(reference.converged))
    # Tolerances and Newton iterations are arguments of the compiled program, not part of
    # it: the tight solve ran the program of the default settings (`nonlinear`), to its
    # own tolerances, and compiled nothing.
    assert events == []
    assert np.max(np.asarray(reference.residual)) <= 1e-10
    assert np.sum(np.asarray(reference.newton_steps)) > np.sum(np.asarray(nonlinear.newton_steps))
    scale = np.asarray(AMPLITUDES)[:, None] / float(system.host_stiffness)
    np.testing.assert_allclose(nonlinear.x_max, reference.x_max, rtol=1e-5)
    np.testing.assert_allclose(nonlinear.y_max / scale, reference.y_max / scale, atol=1e-4)


def _scaled_orbit(response, system, amplitude, omega):
    """The converged orbit's state at phase 0 of a one-point `response`, scaled."""
    assert bool(response.converged)
    static = amplitude / float(system.host_stiffness)
    return np.asarray(response.state) / np.array([static] * 2 + [omega * static] * 2)


@pytest.mark.parametrize(("amplitude", "ratio"), [(100.0, 0.95), (200.0, 1.0), (1000.0, 1.1)])
def test_monodromy_is_that_of_the_orbit_returned(system, amplitude, ratio):
    # The monodromy matrix (and so the Floquet multipliers) belongs to the orbit returned,
    # not to a coarse iterate near it: against central differences of the period map at
    # the returned state, integrated at rtol 1e-12 (stick-slip at 100 and 200 N).
    import jax

    from tid_jax._orbit._period import period_samples

    omega = ratio * float(system.host_frequency)
    response = tj.frequency_response(system, omega, amplitude)
    z = _scaled_orbit(response, system, amplitude, omega)
    tight = tj.SolverSettings(rtol=1e-12, atol=1e-12, max_steps=65536)
    p = _plant(system, amplitude, omega)
    end = jax.jit(jax.vmap(lambda z0: period_samples(z0, p, tight)[3]))
    h = 1e-6 * max(1.0, np.max(np.abs(z)))
    steps = h * np.eye(4)
    fd = np.asarray(end(z + steps) - end(z - steps)).T / (2 * h)
    np.testing.assert_allclose(np.asarray(response.monodromy), fd, rtol=1e-3,
                               atol=1e-3 * np.max(np.abs(fd)))


def _period_end(system, amplitude, omega, z, settings):
    from tid_jax._orbit._period import period_samples

    settings = settings.for_system(system)
    p = _plant(system, amplitude, omega)
    return np.asarray(period_samples(jnp.asarray(z), p, settings)[3])


def _initial_state(system, amplitude, omega):
    from tid_jax._orbit._period import point_model

    return np.asarray(point_model(system, tj.Quantity(), amplitude, omega)[1])


@pytest.mark.parametrize("series_stiffness", [math.inf, 2e5])
@pytest.mark.parametrize("ratio", [0.8, 1.0, 1.2])
def test_initial_state_without_friction_is_the_periodic_orbit(system, series_stiffness, ratio):
    # Without friction the equivalent linear system is the system itself: one period of
    # the equations of motion, integrated tightly, returns the initial state.
    free = tj.TIDSystem(1500.0, float(system.host_stiffness), float(system.host_damping),
                        75.0, 0.0, float(system.tid_stiffness), float(system.tid_damping),
                        1e-4, parasitic_damping=30.0, terminal_mass=2.0,
                        series_stiffness=series_stiffness)
    omega = ratio * float(system.host_frequency)
    z = _initial_state(free, 200.0, omega)
    assert z.shape == ((6,) if free.compliant else (4,))
    tight = tj.SolverSettings(rtol=1e-12, atol=1e-12, max_steps=65536)
    np.testing.assert_allclose(_period_end(free, 200.0, omega, z, tight), z, atol=1e-9)


def test_initial_state_of_a_stuck_inerter_is_the_stuck_orbit(system):
    # Friction above the holding force: the inerter stays still for the whole period of
    # the exact Coulomb flow started from the initial state, which is periodic.
    exact = tj.TIDSystem(1500.0, float(system.host_stiffness), float(system.host_damping),
                         75.0, 20.0, float(system.tid_stiffness), float(system.tid_damping), 0.0)
    omega = float(system.host_frequency)
    z = _initial_state(exact, 10.0, omega)
    assert z[1] == 0.0 and z[3] == 0.0  # (x, y, x', y'): the terminal still
    end = _period_end(exact, 10.0, omega, z, tj.SolverSettings())
    np.testing.assert_allclose(end, z, atol=1e-10)


@pytest.mark.parametrize(("amplitude", "ratio"), [(100.0, 1.0), (200.0, 0.95), (400.0, 1.05),
                                                  (1000.0, 1.0)])
def test_initial_state_of_a_slipping_inerter_is_near_its_orbit(system, amplitude, ratio):
    # Where the inerter slips, the equivalent linear state (friction as the viscous
    # damping that dissipates as much per period) starts nearer the steady state than the
    # frictionless one does.
    omega = ratio * float(system.host_frequency)
    orbit = _scaled_orbit(tj.frequency_response(system, omega, amplitude), system, amplitude,
                          omega)
    free = eqx.tree_at(lambda s: s.friction_force, system, 0.0)
    equivalent = np.max(np.abs(_initial_state(system, amplitude, omega) - orbit))
    frictionless = np.max(np.abs(_initial_state(free, amplitude, omega) - orbit))
    assert equivalent < 0.2 * frictionless


def test_coarse_settings():
    settings = tj.SolverSettings(rtol=1e-8, atol=1e-9, coarse_rtol=1e-6)
    coarse = settings.coarse()
    assert (coarse.rtol, coarse.atol) == pytest.approx((1e-6, 1e-7))
    # Never finer than the settings themselves, and off for the fallbacks.
    assert tj.SolverSettings(rtol=1e-5).coarse().rtol == 1e-5
    assert settings.without_coarse().coarse() == settings.without_coarse()
    assert all(fallback.coarse() == fallback for fallback in settings.fallbacks())
    # Exact friction's period map has no integration error: no coarse Newton iterations.
    exact = settings.for_system(tj.paper_system())
    assert exact.coarse() is exact
    for name in ("coarse_rtol", "coarse_residual"):
        with pytest.raises(ValueError, match=name):
            tj.SolverSettings(**{name: -1.0})


def test_tighter_settings():
    settings = tj.SolverSettings(rtol=1e-8, atol=1e-9, periodicity_tol=1e-6)
    tight = settings.tighter(10.0)
    assert (tight.rtol, tight.atol, tight.periodicity_tol) == pytest.approx((1e-9, 1e-10, 1e-7))
    assert tight.coarse_rtol == settings.coarse_rtol
    # Exact friction has no integration error, and its own periodicity tolerance.
    exact = settings.for_system(tj.paper_system().replace(friction_width=0.0))
    assert exact.tighter(10.0) == exact
