"""Exact Coulomb friction (`friction_width=0`) against the independent event-driven
reference `tests/reference/coulomb.py`, and its derivatives against finite differences."""

import math

import jax
import numpy as np
import pytest

import tid_jax as tj
from tid_jax._model._system import compiler_options

try:
    from lanes import peaks_of
    from reference.coulomb import coulomb_steady_state
except ImportError:  # tests/ imported as a package
    from tests.lanes import peaks_of
    from tests.reference.coulomb import coulomb_steady_state

jax.config.update("jax_enable_x64", True)

PAPER = tj.paper_system().replace(friction_width=0.0)
AMPLITUDES = np.array([100.0, 200.0, 400.0, 1000.0, 3000.0])
FREQUENCIES_HZ = np.array([3.0, 3.5, 3.8, 4.0, 4.2, 4.5, 5.0])


def _reference(system: tj.TIDSystem, omega: float, amplitude: float) -> dict:
    fields = {name: float(value) for name, value in system.to_dict().items()
              if name not in ("friction_width", "series_stiffness", "backlash")}
    return coulomb_steady_state(**fields, omega=omega, amplitude=amplitude)


def _compare(system, omegas, amplitudes):
    response = tj.frequency_response(system, omegas, amplitudes)
    assert np.all(np.asarray(response.converged))
    for i, amplitude in enumerate(amplitudes):
        for j, omega in enumerate(omegas):
            ref = _reference(system, omega, amplitude)
            assert ref["converged"]
            where = f"A = {amplitude} N, {omega / (2 * math.pi):.2f} Hz"
            assert float(response.x_max[i, j]) == pytest.approx(ref["x_max"], rel=1e-5), where
            if ref["stick_fraction"] < 1:  # a terminal stuck throughout has no unique y
                assert float(response.y_max[i, j]) == pytest.approx(ref["y_max"], rel=1e-5), where
            else:
                assert float(response.stick_fraction[i, j]) == 1.0, where
            # the share of the period stuck, at the samples' resolution
            assert abs(float(response.stick_fraction[i, j]) - ref["stick_fraction"]) < 0.02, where
            transitions = int(response.transitions[i, j])
            if ref["stick_fraction"] == 0:
                assert transitions == 2, where  # two reversals
            elif ref["stick_fraction"] == 1:
                assert transitions == 0, where
            else:
                assert transitions >= 4 and transitions % 2 == 0, where
    return response


def test_exact_friction_is_the_default_of_a_rigid_device_only():
    values = {name: float(getattr(PAPER, name)) for name in
              ("host_mass", "host_stiffness", "host_damping", "inertance", "friction_force",
               "tid_stiffness", "tid_damping")}
    rigid = tj.TIDSystem(**values)
    assert rigid.exact_friction and float(rigid.friction_width) == 0.0
    assert tj.paper_system().exact_friction
    # a compliant device's solver needs smoothed friction: its default is the relative width
    compliant = tj.TIDSystem(**values, series_stiffness=1e6, terminal_mass=1.0)
    assert compliant.friction_width is None and not compliant.exact_friction
    made_compliant = PAPER.replace(series_stiffness=1e6, terminal_mass=1.0)
    assert made_compliant.friction_width is None and not made_compliant.exact_friction
    assert PAPER.replace(series_stiffness=1e6, friction_width=1e-4).friction_width == 1e-4


def test_real_time_substructuring_asks_for_smoothed_friction():
    with pytest.raises(ValueError, match="needs smoothed friction"):
        tj.simulate_substructuring(PAPER, 8 * math.pi, 300.0)


def test_exact_friction_is_selected_by_zero_width():
    assert PAPER.exact_friction
    assert not tj.paper_system(friction_width=None).exact_friction
    assert PAPER.replace(tid_stiffness=4e4).exact_friction
    assert not PAPER.replace(friction_width=1e-4).exact_friction
    with pytest.raises(ValueError, match="friction_width must be 0"):
        PAPER.replace(friction_width=np.array([0.0, 1e-4]))
    with pytest.raises(ValueError, match="friction_width must be finite and non-negative"):
        PAPER.replace(friction_width=-1e-4)


@pytest.mark.parametrize("stiffness_factor, damping_factor", [(1.0, 1.0), (0.9, 1.6), (1.1, 0.4)])
def test_agrees_with_reference(stiffness_factor, damping_factor):
    system = PAPER.replace(tid_stiffness=stiffness_factor * PAPER.tid_stiffness,
                           tid_damping=damping_factor * PAPER.tid_damping)
    response = _compare(system, 2 * math.pi * FREQUENCIES_HZ, AMPLITUDES)
    stick = np.asarray(response.stick_fraction)
    # the spread covers stuck, stick-slip and sliding orbits
    assert np.any(stick == 1) and np.any((stick > 0) & (stick < 1)) and np.any(stick == 0)


@pytest.mark.parametrize(
    "host_hz, mass, friction_ratio",
    [(0.15, 1e6, 0.3), (0.3, 2e5, 0.45), (0.8, 5e4, 0.6), (9.0, 1e2, 0.55)],
)
def test_slow_and_high_friction_structures(host_hz, mass, friction_ratio):
    # where the smoothed friction is stiff: hosts below 1 Hz, friction a large part of
    # the forcing
    stiffness = mass * (2 * math.pi * host_hz) ** 2
    k, c = tj.den_hartog_tuning(mass, stiffness, 0.05 * mass)
    amplitude = 1000.0
    system = tj.TIDSystem(mass, stiffness, 2 * 0.02 * math.sqrt(stiffness * mass), 0.05 * mass,
                          friction_ratio * amplitude, k, c, friction_width=0.0)
    omegas = 2 * math.pi * host_hz * np.array([0.6, 0.9, 1.0, 1.1, 1.5])
    _compare(system, omegas, np.array([amplitude]))


def test_stuck_inerter_is_the_stuck_linear_system():
    # friction far above the spring-damper force: the terminal never moves, and the host
    # is a single degree of freedom with K + k and C + c
    system = PAPER.replace(friction_force=1e5)
    omegas = 2 * math.pi * np.array([3.0, 4.0, 5.0])
    response = tj.frequency_response(system, omegas, 300.0)
    M, K, C = (float(getattr(system, name)) for name in ("host_mass", "host_stiffness",
                                                          "host_damping"))
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    expected = 300.0 / np.abs(K + k - M * omegas**2 + 1j * omegas * (C + c))
    np.testing.assert_allclose(np.asarray(response.x_max), expected, rtol=1e-6)
    assert np.all(np.asarray(response.y_max) == 0)
    assert np.all(np.asarray(response.stick_fraction) == 1)
    # the terminal's position is a neutral direction (multiplier 1); the host's decay
    multipliers = np.sort(np.abs(np.asarray(response.floquet_multipliers)), axis=-1)
    assert np.all(multipliers[:, -1] == pytest.approx(1.0))
    assert np.all(multipliers[:, :2] < 1)
    assert np.all(np.asarray(response.stable))  # neutral along the position only


def test_a_point_that_did_not_converge_is_tried_again_once():
    # Exact friction's period map has neither an integration error nor stiff steps: a
    # point that did not converge is tried again once, with the long transient and more
    # Newton iterations (a more accurate or an implicit attempt would repeat that
    # computation).
    [fallback] = tj.SolverSettings().for_system(PAPER).fallbacks()
    assert fallback.exact_friction and not fallback.implicit
    assert fallback.transient_periods == 40 and fallback.max_newton_steps == 25
    # One Newton iteration per stage from the linear steady state, shot on twice from
    # where it stopped, leaves stick-slip points short of their orbits (at 25 N near
    # 1.02, 100 N near 0.94 and 150 N near 0.88 times the host frequency, by 2e-8 to
    # 1e-7): tried again, every point converges, to the orbits of the default settings.
    omegas = np.linspace(0.8, 1.2, 21) * float(PAPER.host_frequency)
    amplitudes = [25.0, 100.0, 150.0]
    once = tj.frequency_response(PAPER, omegas, amplitudes,
                                 settings=tj.SolverSettings(max_newton_steps=1))
    assert np.all(np.asarray(once.converged))
    default = tj.frequency_response(PAPER, omegas, amplitudes)
    np.testing.assert_allclose(once.x_max, default.x_max, rtol=1e-9)
    slips = np.asarray(default.stick_fraction) < 1  # (a terminal stuck throughout: no unique y)
    np.testing.assert_allclose(np.asarray(once.y_max)[slips], np.asarray(default.y_max)[slips],
                               rtol=1e-9)


def test_gradients_match_finite_differences():
    # the peak host displacement over a band, with respect to k, c, ff and A, at a
    # stick-slip and a sliding peak, against central differences (steps too small to
    # change the stick-slip pattern)
    omegas = 2 * math.pi * np.linspace(3.4, 4.6, 13)
    names = ("tid_stiffness", "tid_damping", "friction_force")

    def peak(values):
        system = PAPER.replace(**dict(zip(names, values[:3], strict=True)))
        return tj.peak_response(system, omegas, values[3])

    # The differences take their peaks from the same compiled program as the gradient,
    # compiled with the XLA options of the package's own programs of exact friction.
    value_and_gradient = jax.jit(jax.value_and_grad(peak),
                                 compiler_options=compiler_options(PAPER))
    for amplitude in (150.0, 600.0):
        values = np.array([float(getattr(PAPER, name)) for name in names] + [amplitude])
        exact = np.asarray(value_and_gradient(values)[1])
        assert np.all(np.isfinite(exact))
        for i, value in enumerate(values):
            step = np.zeros(4)
            step[i] = 1e-5 * value
            central = (float(value_and_gradient(values + step)[0])
                       - float(value_and_gradient(values - step)[0])) / (2 * step[i])
            assert exact[i] == pytest.approx(central, rel=2e-4), (amplitude, i)


def test_stuck_stroke_is_no_candidate_of_the_worst_case():
    # with exact friction a terminal stuck at a band end has stroke 0: its log is no
    # candidate of the smooth worst case (nor a NaN in its gradient)
    from tid_jax._optimise._design import _log_candidates

    omegas = np.linspace(20.0, 30.0, 6)
    stroke = np.array([0.0, 1e-3, 2e-3, 3e-3, 2e-3, 1e-3])
    none = (np.zeros(0, int), np.zeros(0), np.zeros(0, bool))
    logs, mask = jax.jit(_log_candidates)(stroke, omegas, none)
    assert not mask[0] and np.all(np.isfinite(np.asarray(logs)))
    assert np.asarray(mask)[1:].any()
    gradient = jax.jit(jax.jacfwd(lambda s: _log_candidates(s, omegas, none)[0]))(stroke)
    assert np.all(np.isfinite(np.asarray(gradient)))


def test_retuned_design_is_optimal_on_the_reference():
    """`retune` with exact friction at 400 N (stick-slip), on 21 frequencies (`test_retune`'s
    band, whose compiled optimiser it shares): the event-driven reference confirms its
    peak, and detuning k by 2% or c by 20% either way raises the reference's largest peak
    over the band."""
    amplitude = 400.0
    band = np.linspace(0.8, 1.2, 21) * float(PAPER.host_frequency)
    result = tj.retune(PAPER, [amplitude], omegas=band)
    assert bool(result.converged[0])
    k, c = float(result.tid_stiffness[0]), float(result.tid_damping[0])
    omegas = 2 * math.pi * np.linspace(3.0, 5.0, 201)

    def band_peaks(k, c, at):
        system = PAPER.replace(tid_stiffness=k, tid_damping=c)
        return np.array([_reference(system, omega, amplitude)["x_max"] for omega in at])

    peaks = band_peaks(k, c, omegas)
    optimum = float(np.max(peaks))
    # the reported peak is located in continuous frequency, the reference's on the grid
    assert optimum <= float(result.x_peak[0]) * (1 + 1e-5)
    assert optimum == pytest.approx(float(result.x_peak[0]), rel=1e-4)
    # A detuned design's largest peak on the grid points within 0.15 Hz of the optimum's
    # two peaks is at most its largest over the band: above the optimum's, so is that.
    interior = np.flatnonzero((peaks[1:-1] > peaks[:-2]) & (peaks[1:-1] > peaks[2:])) + 1
    assert interior.size == 2
    near = np.unique(np.clip(interior[:, None] + np.arange(-15, 16), 0, omegas.size - 1))
    for detuned in ((1.02 * k, c), (0.98 * k, c), (k, 1.2 * c), (k, 0.8 * c)):
        assert np.max(band_peaks(*detuned, omegas[near])) > optimum, detuned


def test_sensitivities_and_robust_design_take_exact_friction():
    """`sensitivities` and `robust_tune` with exact friction: the peaks they report at
    their tunings are the event-driven reference's largest over the band, and the
    sensitivity to k matches central differences of the peak."""
    omegas = 2 * math.pi * np.linspace(3.0, 5.0, 101)

    def band_peak(system, amplitude):
        # on the grid, then by a bounded search within a grid step of its largest value
        from scipy.optimize import minimize_scalar

        def peak(omega):
            return _reference(system, omega, amplitude)["x_max"]

        peaks = [peak(omega) for omega in omegas]
        j, step = int(np.argmax(peaks)), omegas[1] - omegas[0]
        found = minimize_scalar(lambda omega: -peak(omega), method="bounded",
                                bounds=(omegas[j] - step, omegas[j] + step),
                                options=dict(xatol=1e-5 * step))
        return max(peaks[j], -found.fun)

    sens = tj.sensitivities(PAPER, 400.0, optimum=False)
    assert bool(sens.converged)
    assert float(sens.host_peak) == pytest.approx(band_peak(PAPER, 400.0), rel=1e-4)
    k, h = float(PAPER.tid_stiffness), 1e-3
    i = sens.parameters.index("tid_stiffness")
    shifted = peaks_of([(PAPER.replace(tid_stiffness=k * (1 + s * h)), 400.0) for s in (1, -1)],
                       tj.default_omegas(PAPER))[:, 0]
    assert float(sens.host_derivative[i]) == pytest.approx(
        (shifted[0] - shifted[1]) / (2 * h * k), rel=2e-3)

    robust = tj.robust_tune(PAPER, [200.0, 600.0], stroke_limit=None)
    assert bool(robust.converged)
    tuned = PAPER.replace(tid_stiffness=float(robust.tid_stiffness),
                          tid_damping=float(robust.tid_damping))
    # the robust design judges peaks on its 61-frequency grid refined by parabolas
    # (`tuning_performance`): as accurate as that refinement, about 1e-4
    for j, amplitude in enumerate((200.0, 600.0)):
        assert float(robust.performance.host_peak[0, j]) == pytest.approx(
            band_peak(tuned, amplitude), rel=1e-3)
    assert float(robust.worst_ratio) >= 1.0
