import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

import tid_jax as tj
from tests.reference import hinf

N_FREQUENCIES = 21
PAPER_RETUNED = {200.0: (1.09, 0.45), 400.0: (1.034, 0.85), 600.0: (1.018, 0.9)}  # k, c ratios


@pytest.fixture(scope="module")
def band(system):
    # Narrower than the default band (both peaks stay inside for every design visited here),
    # so that 21 frequencies, the other design tests' number (the same compiled programs),
    # sample the peaks almost as finely as the default 61 do (every 0.02 of the host
    # frequency, against 0.0125).
    return np.linspace(0.8, 1.2, N_FREQUENCIES) * float(system.host_frequency)


@pytest.fixture(scope="module")
def undamped_linear(system, band):
    linear = system.replace(friction_force=0.0, host_damping=0.0)
    return linear, tj.retune(linear, [1000.0], omegas=band, tol=1e-5)


def _static(system, amplitude):
    return amplitude / float(system.host_stiffness)


def _h_infinity(system):
    """The exact H-infinity optimum (k, c, peak / static) of the linear `system`, from the
    independent reference (true peaks of the closed-form receptance)."""
    return hinf.h_infinity_optimum(*(float(getattr(system, name)) for name in (
        "host_mass", "host_stiffness", "host_damping", "inertance")))


def test_exact_h_infinity_tuning_of_undamped_host(system, undamped_linear):
    # Nishihara & Asami (2002), mu = 0.05: frequency ratio 0.952372, damping ratio 0.133938,
    # peak 6.40792 x static; no tuning beats the fixed points' sqrt(1 + 2/mu) = 6.4031.
    linear, result = undamped_linear
    k_exact, c_exact, peak_exact = _h_infinity(linear)
    assert peak_exact == pytest.approx(6.40792, abs=1e-5)
    assert k_exact == pytest.approx(
        0.952372**2 * float(system.host_frequency) ** 2 * float(system.inertance), rel=1e-6)
    assert bool(result.converged[0])
    peak = float(result.x_peak[0]) / _static(system, 1000.0)
    # The true maximum over frequency is optimised, not a grid's: the optimum is exact.
    assert peak == pytest.approx(peak_exact, abs=1e-5)
    assert peak >= peak_exact * (1 - 1e-7)
    assert float(result.tid_stiffness[0]) == pytest.approx(k_exact, rel=1e-4)
    assert float(result.tid_damping[0]) == pytest.approx(c_exact, rel=2e-3)
    # The reported peak is the true maximum of this tuning's response: the reference's
    # exact peaks of the closed-form receptance.
    _, exact_peaks = hinf.true_peaks(
        *(float(getattr(linear, name)) for name in (
            "host_mass", "host_stiffness", "host_damping", "inertance")),
        float(result.tid_stiffness[0]), float(result.tid_damping[0]))
    assert peak == pytest.approx(max(exact_peaks), rel=1e-7)


def test_exact_h_infinity_tuning_of_damped_host(system, band):
    linear = system.replace(friction_force=0.0)
    result = tj.retune(linear, [1000.0], omegas=band, tol=1e-5)
    _, _, peak_exact = _h_infinity(linear)
    peak = float(result.x_peak[0]) / _static(system, 1000.0)
    assert peak == pytest.approx(peak_exact, abs=1e-5)
    assert float(result.x_peak_initial[0]) / _static(system, 1000.0) == pytest.approx(5.433,
                                                                                    rel=2e-3)
    # The optimum does not depend on where the grid falls: the same on a shifted grid.
    shifted = band + 0.37 * (band[1] - band[0])
    again = tj.retune(linear, [1000.0], omegas=shifted, tol=1e-5)
    assert float(again.x_peak[0]) / _static(system, 1000.0) == pytest.approx(peak, abs=1e-5)


@pytest.fixture(scope="module")
def nonlinear(system, band):
    # The twelve paper amplitudes, 100 to 3000 N, in one batched call.
    return tj.retune(system, tj.PAPER_AMPLITUDES, omegas=band, tol=1e-5)


def _at(amplitude):
    return tj.PAPER_AMPLITUDES.index(amplitude)


def test_twelve_paper_amplitudes_in_one_call(system, nonlinear):
    assert nonlinear.tid_stiffness.shape == (12,)
    np.testing.assert_array_equal(np.asarray(nonlinear.amplitudes), tj.PAPER_AMPLITUDES)
    # Every design is checked on the finer grid and beats Den Hartog's tuning there, with
    # converged steady states and the peak inside the band (status 0 or 1 only).
    assert np.all(np.asarray(nonlinear.x_peak) < np.asarray(nonlinear.x_peak_initial))
    assert set(np.asarray(nonlinear.status).tolist()) <= {0, 1}, nonlinear.status_messages()
    # At 100 N dry friction does the damping: the optimum puts c at its bound 0 with a
    # stiffer TID (the paper's lowest-amplitude values are k x1.20, c x0.18), and the peak
    # falls from 8.84 A/K with Den Hartog's tuning to near the linear TID's 5.43.
    i = _at(100.0)
    assert bool(nonlinear.damping_at_bound[i])
    assert float(nonlinear.tid_stiffness[i]) / float(system.tid_stiffness) == pytest.approx(
        1.20, abs=0.02)
    assert float(nonlinear.x_peak[i]) / _static(system, 100.0) < 5.2


def test_nonlinear_retune_no_worse_than_paper(system, band, nonlinear):
    k_dh, c_dh = float(system.tid_stiffness), float(system.tid_damping)
    fine = np.linspace(float(band[0]), float(band[-1]), 2 * (N_FREQUENCIES - 1) + 1)
    for amplitude in [200.0, 400.0, 600.0]:
        i = _at(amplitude)
        k_ratio, c_ratio = PAPER_RETUNED[amplitude]
        paper = system.replace(tid_stiffness=k_ratio * k_dh, tid_damping=c_ratio * c_dh)
        paper_peak = tj.peaks(paper, fine, [amplitude]).x_peak[0]
        assert float(nonlinear.x_peak[i]) <= float(paper_peak) * (1 + 1e-6), amplitude
        assert float(nonlinear.x_peak[i]) < float(nonlinear.x_peak_initial[i])
        assert bool(nonlinear.converged[i]), amplitude


def test_nonlinear_retune_trend_matches_figure_7(system, nonlinear):
    k = np.asarray(nonlinear.tid_stiffness) / float(system.tid_stiffness)
    c = np.asarray(nonlinear.tid_damping) / float(system.tid_damping)
    # From 100 to 3000 N the stiffness falls towards Den Hartog's and the damping rises
    # towards it.
    assert np.all(np.diff(k) < 0), k
    assert np.all(np.diff(c) > 0), c
    i = _at(200.0)
    assert k[i] == pytest.approx(1.09, abs=0.02) and c[i] == pytest.approx(0.45, abs=0.1)
    assert abs(k[-1] - 1) < 0.02 and abs(c[-1] - 1) < 0.1


def _peak_of_design(system, omegas):
    """The objective of the derivative-free search: `peak(u, amplitude)`, the true peak
    host response over `omegas` (in A/K) of `system` tuned to k = k_DH exp(u0),
    c = c_DH u1^2: `peak_response`, whose compiled program takes the tuning and the
    amplitude as arguments."""
    k_dh, c_dh = float(system.tid_stiffness), float(system.tid_damping)

    def peak(u, amplitude):
        tuned = system.replace(tid_stiffness=k_dh * np.exp(u[0]), tid_damping=c_dh * u[1] ** 2)
        return float(tj.peak_response(tuned, omegas, amplitude)) / _static(system, amplitude)

    return peak


@pytest.mark.parametrize("amplitude", [200.0, 400.0, 600.0])
def test_retune_agrees_with_derivative_free_search(system, band, nonlinear, amplitude):
    # A second opinion: Nelder-Mead on the peak over a grid twice as fine (each peak the
    # true maximum over frequency), from the paper's manual retune.
    k_dh, c_dh = float(system.tid_stiffness), float(system.tid_damping)
    fine = np.linspace(float(band[0]), float(band[-1]), 2 * (N_FREQUENCIES - 1) + 1)
    peak = _peak_of_design(system, fine)
    k_ratio, c_ratio = PAPER_RETUNED[amplitude]
    u0 = np.array([np.log(k_ratio), np.sqrt(c_ratio)])
    # scipy's Nelder-Mead, each value one run of the compiled objective; stopped where the
    # simplex's values agree to 1e-7 (relative), a thousandth of the agreement asked of the
    # two designs below.
    start = peak(u0, amplitude)
    search = scipy.optimize.minimize(
        lambda u: peak(u, amplitude), u0, method="Nelder-Mead",
        options=dict(xatol=1e-7, fatol=1e-7 * start, maxfev=1000),
    )
    assert search.success, search.message
    ours = float(nonlinear.x_peak[_at(amplitude)]) / _static(system, amplitude)
    theirs = peak(search.x, amplitude)
    assert ours <= theirs * (1 + 1e-4)
    # Our design judged on the search's grid.
    k, c = float(nonlinear.tid_stiffness[_at(amplitude)]), float(nonlinear.tid_damping[_at(
        amplitude)])
    assert peak(np.array([np.log(k / k_dh), np.sqrt(c / c_dh)]), amplitude) == \
        pytest.approx(ours, rel=1e-6)


def test_stage_ends_once_its_line_search_cuts_within_the_tolerance(system, band):
    # With the count of rejected steps out of the way, a stage must still end (converged)
    # where the line search finds no decrease until its steps are within the tolerance:
    # at 250 N on this band the objective's noise rejects the steps near an early stage's
    # optimum; cutting on towards zero, the three stages took 66 iterations in all (16
    # with the rule).
    settings = tj.RetuneSettings(max_rejected_steps=10**6)
    result = tj.retune(system, [250.0], omegas=band, retune_settings=settings)
    assert bool(result.converged[0])
    assert int(result.iterations[0]) < 60
    usual = tj.retune(system, [250.0], omegas=band)
    assert float(result.x_peak[0]) == pytest.approx(float(usual.x_peak[0]), rel=1e-6)


def test_amplitude_below_breakaway_keeps_the_initial_tuning_and_says_so(band):
    # 15 N is below the paper system's breakaway amplitude over the band (22.8 N): the
    # inerter never slips, and a stiffer damper to ground only lowers the stuck peak
    # further, so there is no TID optimum there. With exact friction (the default), whose
    # retune takes a fraction of the smoothed model's time. Such a lane is not optimised
    # at all (no iteration, the initial tuning returned as it was given); the lanes beside
    # it are retuned as on their own.
    system = tj.paper_system()
    assert 15.0 < float(tj.breakaway_amplitude(system, band).minimum)
    result = tj.retune(system, [15.0, 1000.0, 800.0], omegas=band)
    assert int(result.status[0]) == 5 and not bool(result.converged[0])
    assert "below the breakaway amplitude" in result.status_messages()[0]
    assert float(result.tid_stiffness[0]) == float(system.tid_stiffness)
    assert float(result.tid_damping[0]) == float(system.tid_damping)
    assert int(result.iterations[0]) == 0
    assert int(result.iterations[1]) > 0 and int(result.iterations[2]) > 0
    damper = system.replace(tid_damping=1.5 * float(system.tid_damping))
    assert float(tj.peaks(damper, band, [15.0]).x_peak[0]) < 0.95 * float(result.x_peak[0])
    alone = tj.retune(system, [800.0], omegas=band)
    assert int(result.status[2]) == int(alone.status[0]) == 0
    assert int(result.iterations[2]) == int(alone.iterations[0])
    for field in ("tid_stiffness", "tid_damping"):
        np.testing.assert_allclose(getattr(result, field)[2], getattr(alone, field)[0],
                                   rtol=1e-9)
    # The check's steady states, solved in batches of other make-up, agree within their
    # periodicity tolerance.
    np.testing.assert_allclose(result.x_peak[2], alone.x_peak[0], rtol=1e-7)


def test_design_worse_on_the_check_grid_keeps_the_initial_tuning(system):
    # On a design grid as coarse as 0.1 of the host frequency at 1000 N (21 points from 0.2
    # to 2.2 times it), the optimiser moves the peaks between grid points; the check grid,
    # twice as fine, shows a higher peak than Den Hartog's, so that tuning is kept.
    coarse = np.linspace(0.2, 2.2, 21) * float(system.host_frequency)
    result = tj.retune(system, [1000.0], omegas=coarse)
    assert int(result.status[0]) == 4
    assert "initial tuning kept" in result.status_messages()[0]
    assert not bool(result.converged[0])
    assert float(result.tid_stiffness[0]) == float(system.tid_stiffness)
    assert float(result.tid_damping[0]) == float(system.tid_damping)
    assert float(result.x_peak[0]) == float(result.x_peak_initial[0])
    # The reported peak is the initial tuning's, checked independently on the same grid
    # (shooting from other starting states: agreement far inside the periodicity tolerance).
    fine = np.linspace(0.2, 2.2, 41) * float(system.host_frequency)
    assert float(result.x_peak[0]) == pytest.approx(
        float(tj.peaks(system, fine, [1000.0]).x_peak[0]), rel=1e-7)


def test_bad_arguments(system):
    with pytest.raises(ValueError, match="amplitudes must be finite and positive"):
        tj.retune(system, [-100.0])
    with pytest.raises(ValueError, match="omegas must be"):
        tj.retune(system, [100.0], omegas=[25.0, 26.0])
    with pytest.raises(ValueError, match="response must be"):
        tj.peak_response(system, None, 100.0, response="stroke")


def test_retune_settings_set_the_stages_and_the_check_grid(system, band):
    settings = tj.RetuneSettings(sharpness=(1000.0, 30000.0), check_refinement=3)
    messages = []
    result = tj.retune(system, [1000.0], omegas=band, retune_settings=settings,
                       progress=messages.append)
    assert result.check_omegas.shape == (3 * 20 + 1,)
    np.testing.assert_allclose(result.check_omegas[::3], band, rtol=1e-12)
    assert len(messages) == settings.progress_steps() == 4
    assert "stage 2/2 (smooth-max sharpness 30000)" in messages[2]


@pytest.mark.parametrize(
    ("changes", "name"),
    [(dict(sharpness=()), "sharpness"), (dict(sharpness=(50.0, -1.0)), "sharpness"),
     (dict(check_refinement=0), "check_refinement"), (dict(max_design_step=np.inf),
                                                      "max_design_step"),
     (dict(design_newton_steps=2.5), "design_newton_steps")],
)
def test_bad_retune_settings(changes, name):
    with pytest.raises(ValueError, match=f"RetuneSettings.{name}"):
        tj.RetuneSettings(**changes)


def test_retune_settings_must_be_retune_settings(system):
    with pytest.raises(ValueError, match="retune_settings must be a RetuneSettings"):
        tj.retune(system, [100.0], retune_settings=tj.SolverSettings())


def test_check_grid_orbits_interpolate_between_design_points():
    from tid_jax import _retune

    # States linear in the design-grid index are reproduced exactly at every check point.
    n = 5
    index = np.arange(n, dtype=float)
    states = jnp.asarray(np.stack([index, 2 * index, -index, index + 1], axis=-1))[None]
    for r in (tj.RetuneSettings().check_refinement, 3):
        z = _retune._on_check_grid(states, r)
        fine = np.arange((n - 1) * r + 1) / r
        np.testing.assert_allclose(np.asarray(z[0]),
                                   np.stack([fine, 2 * fine, -fine, fine + 1], -1))

def test_worker_processes_retune_as_this_process_alone(system, band):
    # The amplitudes mapped over two worker processes (which load the same compiled
    # programs from the cache): the same designs as this process optimising them one
    # after another.
    amplitudes = [300.0, 1500.0, 3000.0]
    alone = tj.retune(system, amplitudes, omegas=band, tol=1e-5)
    with tj.ProcessMap(2) as pool:
        shared = tj.retune(system, amplitudes, omegas=band, tol=1e-5, map_lanes=pool)
    for name in ("tid_stiffness", "tid_damping", "x_peak", "iterations", "status"):
        np.testing.assert_allclose(getattr(shared, name), getattr(alone, name), rtol=1e-12,
                                   err_msg=name)
