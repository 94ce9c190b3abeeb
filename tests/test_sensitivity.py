"""Sensitivities of the peak response and of the optimal tuning: `tj.sensitivities`
against finite differences, re-optimised differences and exact scaling laws."""

import functools as ft

import equinox as eqx
import jax
import numpy as np
import pytest

import tid_jax as tj
from tests.lanes import peaks_of
from tid_jax._model._system import FIELD_NAMES, compiler_options
from tid_jax._optimise._design_variables import DESIGN_SCALE, design_of_tuning

SENSITIVITY_AMPLITUDE = 400.0  # N: both resonance peaks split, the optimum is smooth there


@pytest.fixture(scope="module")
def sensitivity(system, band):
    return tj.sensitivities(system, SENSITIVITY_AMPLITUDE, omegas=band)


def _perturbed(system, amplitude, name, value):
    if name == "amplitude":
        return system, value
    return system.replace(**{name: value}), amplitude


def _peaks(system, amplitude, band):
    result = tj.peaks(system, band, [amplitude])
    return np.array([float(result.x_peak[0]), float(result.y_peak[0])])


# --- sensitivities ---------------------------------------------------------------------


def test_sensitivities_match_finite_differences(system, band, sensitivity):
    # Five-point central differences of the peaks found by `tj.peaks` (relative step 5e-4).
    assert sensitivity.parameters == tuple(FIELD_NAMES[:7]) + (
        "parasitic_damping", "terminal_mass", "amplitude")
    assert bool(sensitivity.converged)
    x0, y0 = _peaks(system, SENSITIVITY_AMPLITUDE, band)
    assert float(sensitivity.host_peak) == pytest.approx(x0, rel=1e-7)
    assert float(sensitivity.stroke_peak) == pytest.approx(y0, rel=1e-7)
    # The device's terms are 0 (non-negative): one-sided differences, on the scale of the
    # TID's own damping and inertance.
    one_sided = {"parasitic_damping": float(system.tid_damping),
                 "terminal_mass": float(system.inertance)}
    values = dict(zip(sensitivity.parameters, np.asarray(sensitivity.values).tolist(),
                      strict=True))
    steps = {name: 5e-4 * one_sided.get(name, value) for name, value in values.items()}
    multiples = {name: (0, 1, 2) if name in one_sided else (-2, -1, 1, 2) for name in values}
    # the peaks at every step of every parameter, in one batch
    cases = [(name, m) for name in values for m in multiples[name]]
    at = dict(zip(cases, peaks_of([_perturbed(system, SENSITIVITY_AMPLITUDE, name,
                                               values[name] + m * steps[name])
                                    for name, m in cases], band), strict=True))
    for i, name in enumerate(sensitivity.parameters):
        value, h = values[name], steps[name]
        f = {m: at[name, m] for m in multiples[name]}
        if name in one_sided:
            assert value == 0.0
            fd = (-3 * f[0] + 4 * f[1] - f[2]) / (2 * h)
            tol = 1e-3  # second order in h, against fourth
        else:
            fd = (8 * (f[1] - f[-1]) - (f[2] - f[-2])) / (12 * h)
            tol = 1e-4
        assert float(sensitivity.host_derivative[i]) == pytest.approx(fd[0], rel=tol), name
        assert float(sensitivity.stroke_derivative[i]) == pytest.approx(fd[1], rel=tol), name
        assert float(sensitivity.host_elasticity[i]) == pytest.approx(value * fd[0] / x0, rel=1e-4)
        assert float(sensitivity.stroke_elasticity[i]) == pytest.approx(
            value * fd[1] / y0, rel=1e-4
        )


def test_derivatives_are_those_of_every_sample_at_the_candidates(system, band):
    # The kernel takes derivatives at the samples of each response's highest candidates
    # only; against the derivatives of every sample (jacfwd through the whole sweep), at
    # 200 N (the stroke sticks over part of the band) and 700 N.
    from tid_jax._optimise._design import _TANGENT_CANDIDATES, _log_candidates, changed_system
    from tid_jax._optimise._design_evaluation import Context
    from tid_jax._peaks import sweep

    # (the default settings, as `sensitivities` passes them)
    settings = tj.SolverSettings()
    ctx = Context(system, band, settings, locate=False,
                  stencil_step=tj.SensitivitySettings().stencil_step)
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    amplitudes = [200.0, 700.0]
    z_init = ctx.cold_states(k, c, amplitudes, 1.0)
    omegas = jax.numpy.asarray(band)
    none = (jax.numpy.zeros(0, int), jax.numpy.zeros(0), jax.numpy.zeros(0, bool))

    @ft.partial(jax.jit, compiler_options=compiler_options(system))
    def every_sample(theta, z):
        """The logs of every sample (and their masks), with their Jacobian in `theta`:
        one compiled program (with the XLA options of the package's own)."""

        def logs(theta):
            xs, ys, _, _ = sweep(changed_system(system, theta, 1.0), theta[-1], omegas,
                                 settings, z)
            (log_x, mask_x), (log_y, mask_y) = (_log_candidates(xs, omegas, none),
                                                _log_candidates(ys, omegas, none))
            return (log_x, log_y), (log_x, mask_x, log_y, mask_y)

        return jax.jacfwd(logs, has_aux=True)(theta)

    for amplitude, z in zip(amplitudes, z_init, strict=True):
        theta = ctx.theta(k, c, amplitude)
        curves = ctx.evaluate([(theta, 1.0, z)])[0]
        assert curves.converged
        (jac_x, jac_y), (log_x, mask_x, log_y, mask_y) = every_sample(theta, z)
        for response, values, mask, jac in (("x", log_x, mask_x, jac_x),
                                            ("y", log_y, mask_y, jac_y)):
            kept = getattr(curves, f"peak_{response}")
            # The highest candidates are kept, at most the kernel's number (the entries
            # after the grid's, of located peaks, are none here: no candidates).
            highest = np.argsort(np.where(mask, values, -np.inf))[::-1]
            highest = highest[:min(_TANGENT_CANDIDATES, int(np.sum(mask)))]
            assert np.array_equal(np.flatnonzero(kept), np.sort(highest)), response
            grid = slice(0, values.size)
            np.testing.assert_allclose(getattr(curves, f"log_{response}")[grid][kept[grid]],
                                       np.asarray(values)[kept[grid]], rtol=0, atol=1e-7)
            np.testing.assert_allclose(getattr(curves, f"jac_{response}")[grid][kept[grid]],
                                       np.asarray(jac)[kept[grid]], rtol=1e-5, atol=1e-9)


def test_elasticities_obey_scaling_laws(sensitivity):
    # Exact laws of eq. (12), whatever the solver. Multiplying every mass, stiffness,
    # damping and force by s leaves x and y unchanged: the elasticities sum to 0. The
    # forcing and friction forces set the response only through A/K and ff/A up to a scale:
    # x(s A, s ff) = s x(A, ff), so e_A + e_ff = 1 (exact Coulomb friction has no width to
    # change with them). At the optimum the same laws hold with k, c free: the host and stroke
    # elasticities over the other parameters sum to 0 and e_A + e_ff = 1, k* scales with
    # stiffness (its elasticities sum to 1) and c* likewise, and neither depends on A, ff
    # apart from ff / A.
    index = {name: i for i, name in enumerate(sensitivity.parameters)}
    a, f = index["amplitude"], index["friction_force"]
    optimum = sensitivity.optimum
    # The envelope theorem needs first derivatives only; the moving optimum also needs the
    # curvature of the objective, from differences of first derivatives: looser.
    for e, tol in (
        (sensitivity.host_elasticity, 1e-4),
        (sensitivity.stroke_elasticity, 1e-4),
        (optimum.host_elasticity, 1e-4),
        (optimum.stroke_elasticity, 3e-3),
    ):
        e = np.asarray(e)
        assert np.sum(e) == pytest.approx(0.0, abs=tol)
        assert e[a] + e[f] == pytest.approx(1.0, abs=tol)
    for e in (optimum.stiffness_elasticity, optimum.damping_elasticity):
        e = np.asarray(e)
        assert np.sum(e) == pytest.approx(1.0, abs=3e-3)
        assert e[a] + e[f] == pytest.approx(0.0, abs=3e-3)
    # Time scaled by s (stiffnesses by s^2, dampings by s, forces by s^2 with the masses
    # held) leaves x and y unchanged, the band moving with the host frequency: sum_p (time
    # units of p) e_p = time units of the quantity. (Not the stroke's: its peak is refined
    # on the grid, which the derivatives hold fixed.)
    units = {"host_stiffness": 2, "tid_stiffness": 2, "host_damping": 1, "tid_damping": 1,
             "parasitic_damping": 1, "friction_force": 2, "amplitude": 2}
    weights = np.array([units.get(name, 0) for name in sensitivity.parameters])
    for e, units_of_quantity, tol in (
        (sensitivity.host_elasticity, 0, 1e-4),
        (optimum.host_elasticity, 0, 1e-4),
        (optimum.stiffness_elasticity, 2, 3e-3),
        (optimum.damping_elasticity, 1, 3e-3),
    ):
        assert weights @ np.asarray(e) == pytest.approx(units_of_quantity, abs=tol)


def _reoptimised_log_differences(system, amplitude, band, name, value, rel, amplitudes=None):
    """Central differences, in ln p, of the optimum found afresh (`best_tunings` at
    `amplitudes`, default `amplitude` alone, polished by `sensitivities`) at p (1 +- rel):
    of its smooth peak, k* and c*."""
    ends = []
    for sign in (1, -1):
        changed = system.replace(**{name: value * (1 + sign * rel)})
        best = tj.best_tunings(changed, amplitudes or [amplitude], omegas=band, tol=1e-6)
        optimum = tj.sensitivities(changed, amplitude, omegas=band, best=best).optimum
        assert bool(optimum.converged)
        ends.append(optimum)

    def d_log(field):
        return float(np.log(getattr(ends[0], field) / getattr(ends[1], field)) / (2 * rel))

    return d_log


def test_optimum_sensitivity_matches_reoptimised_differences(system, band, sensitivity):
    optimum = sensitivity.optimum
    assert bool(optimum.converged)
    assert not bool(optimum.damping_at_bound)
    index = {name: i for i, name in enumerate(sensitivity.parameters)}
    assert float(optimum.host_elasticity[index["tid_stiffness"]]) == 0.0
    assert float(optimum.smooth_peak) >= float(optimum.host_peak)
    assert float(optimum.smooth_peak) <= float(optimum.host_peak) * 1.003
    for name in ("friction_force", "host_damping"):
        i = index[name]
        d_log = _reoptimised_log_differences(
            system, SENSITIVITY_AMPLITUDE, band, name, float(sensitivity.values[i]), 1e-3
        )
        assert float(optimum.host_elasticity[i]) == pytest.approx(d_log("smooth_peak"), rel=1e-3)
        if name == "friction_force":
            # Implicit derivatives of the optimal tuning, looser: the optimum's damping lies
            # along a flat valley, so re-optimised differences of it carry the optimiser's
            # tolerance (host damping hardly moves k* and c*: there it is all noise).
            assert float(optimum.stiffness_elasticity[i]) == pytest.approx(
                d_log("tid_stiffness"), rel=0.02
            )
            assert float(optimum.damping_elasticity[i]) == pytest.approx(
                d_log("tid_damping"), rel=0.02
            )


def test_polishing_steps_keep_the_curvatures_of_their_start(system, band):
    # The polishing evaluates the optimiser's optimum with its central stencil, then each
    # Newton step alone, with the curvatures of that stencil: the steps are far shorter
    # than its step. The derivatives of the optimum match those with the stencil evaluated
    # again at the polished optimum: the peak's and k*'s closely, c*'s (along its flat
    # valley, from differences of gradients) within the 2% of the re-optimised differences
    # above. (Measured against re-optimised differences of host mass, inertance and
    # friction: c*'s elasticities within 0.5% either way.)
    # The polishing starts 6e-5 off the optimiser's optimum in the scaled stiffness
    # (`DESIGN_SCALE`: k 6 ppm higher), so that it has a step to take, within a tenth of
    # the stencil's step of its start.
    best = tj.best_tunings(system, [SENSITIVITY_AMPLITUDE], omegas=band)
    k_start = best.tid_stiffness * np.exp(6e-5 / DESIGN_SCALE[0])
    best = eqx.tree_at(lambda b: b.tid_stiffness, best, k_start)
    kept = tj.sensitivities(system, SENSITIVITY_AMPLITUDE, omegas=band, best=best).optimum
    # Curvatures evaluated again wherever the polishing moved at all.
    anew = tj.SensitivitySettings(same_curvatures=0.0)
    again = tj.sensitivities(system, SENSITIVITY_AMPLITUDE, omegas=band, best=best,
                             sensitivity_settings=anew).optimum
    assert bool(kept.converged) and bool(again.converged)
    # The polishing moved the optimum (else both would be one evaluation), by less than a
    # tenth of the stencil's step in the design variables.
    references = tj.den_hartog_tuning(system.host_mass, system.host_stiffness, system.inertance)
    start = design_of_tuning(float(k_start[0, 0]), float(best.tid_damping[0, 0]), *references,
                             xp=np)
    end = design_of_tuning(float(kept.tid_stiffness), float(kept.tid_damping), *references,
                           xp=np)
    assert 0 < np.max(np.abs(end - start)) < 0.1 * tj.SensitivitySettings().stencil_step
    assert float(again.tid_stiffness) == float(kept.tid_stiffness)
    assert float(again.tid_damping) == float(kept.tid_damping)
    for name, rtol in (("host_elasticity", 1e-6), ("stiffness_elasticity", 1e-3),
                       ("damping_elasticity", 2e-2)):
        np.testing.assert_allclose(np.asarray(getattr(kept, name)),
                                   np.asarray(getattr(again, name)), rtol=rtol, atol=1e-6,
                                   err_msg=name)


def test_a_failed_steady_state_is_flagged(system, band, sensitivity):
    # Steady states that cannot converge: a periodicity tolerance (exact friction's) below
    # the rounding error of double precision, which neither the settings nor their
    # fallbacks reach. The sensitivities at the given tuning and at the optimum come back
    # flagged, not as an exception nor as converged numbers.
    best = tj.best_tunings(system, [SENSITIVITY_AMPLITUDE], omegas=band)
    unreachable = tj.SolverSettings(max_newton_steps=1, exact_periodicity_tol=1e-30)
    result = tj.sensitivities(system, SENSITIVITY_AMPLITUDE, omegas=band, best=best,
                              settings=unreachable)
    assert not bool(result.converged)
    assert bool(best.converged[0, 0]) and not bool(result.optimum.converged)
    # The same tuning, amplitude and band with the default settings converge.
    assert bool(sensitivity.converged) and bool(sensitivity.optimum.converged)


def test_optimum_at_the_damping_bound_and_at_3000_n():
    # On the default band, with exact friction (the default). At 100 N the optimal damping
    # is 0 (the friction damps enough): c* stays at its bound for small changes of any
    # parameter, so dc*/dp = 0 and the elasticities of c* are undefined; k* moves as
    # re-optimised differences and the scaling laws say. At 3000 N, nearly linear, the
    # optimum converges too. Both amplitudes in one batch (`amplitude_sensitivities`), the
    # optimum at the bound polished beside the free one.
    system = tj.paper_system()
    band = np.asarray(tj.default_omegas(system))
    amplitudes = [100.0, 3000.0]
    best = tj.best_tunings(system, amplitudes, omegas=band)
    assert bool(best.damping_at_bound[0, 0]) and not bool(best.damping_at_bound[0, 1])
    messages = []
    low, high = tj.amplitude_sensitivities(system, amplitudes, omegas=band, best=best,
                                           progress=messages.append)
    assert messages == ["derivatives at the given tuning: 2/2 amplitude(s) converged",
                        "derivatives at the retuned optima: 2/2 amplitude(s) converged"]
    assert bool(high.optimum.converged) and not bool(high.optimum.damping_at_bound)
    assert np.all(np.isfinite(np.asarray(high.optimum.damping_elasticity)))
    optimum = low.optimum
    assert bool(optimum.converged) and bool(optimum.damping_at_bound)
    assert float(optimum.tid_damping) == 0.0
    assert np.all(np.asarray(optimum.damping_derivative) == 0.0)
    assert np.all(np.isnan(np.asarray(optimum.damping_elasticity)))
    index = {name: i for i, name in enumerate(low.parameters)}
    i = index["friction_force"]
    d_log = _reoptimised_log_differences(
        system, 100.0, band, "friction_force", float(low.values[i]), 1e-3, amplitudes
    )
    assert float(optimum.stiffness_elasticity[i]) == pytest.approx(
        d_log("tid_stiffness"), rel=0.02, abs=1e-3
    )
    assert float(optimum.host_elasticity[i]) == pytest.approx(d_log("smooth_peak"), rel=1e-3)
    # Every other parameter through the exact scaling laws (test_elasticities_obey_scaling_laws),
    # which hold with c* held at 0 too: k*'s elasticities sum to 1, the peak's to 0.
    a = index["amplitude"]
    k_star, peak = np.asarray(optimum.stiffness_elasticity), np.asarray(optimum.host_elasticity)
    assert np.sum(k_star) == pytest.approx(1.0, abs=3e-3)
    assert k_star[a] + k_star[i] == pytest.approx(0.0, abs=3e-3)
    assert np.sum(peak) == pytest.approx(0.0, abs=1e-4)
    assert peak[a] + peak[i] == pytest.approx(1.0, abs=1e-4)


def test_optimum_is_a_minimum_of_the_peak(system, band, sensitivity):
    # Independent of the optimiser: no neighbouring tuning (+-3% in k, +-6% in c) has a
    # lower peak host displacement by `tj.peaks`.
    optimum = sensitivity.optimum
    k, c = float(optimum.tid_stiffness), float(optimum.tid_damping)
    at_optimum = _peaks(
        system.replace(tid_stiffness=k, tid_damping=c), SENSITIVITY_AMPLITUDE, band
    )[0]
    assert at_optimum == pytest.approx(float(optimum.host_peak), rel=1e-7)
    assert at_optimum < float(sensitivity.host_peak)  # better than Den Hartog's
    moves = [(a, b) for a in (-1, 0, 1) for b in (-1, 0, 1) if (a, b) != (0, 0)]
    neighbours = peaks_of([(system.replace(tid_stiffness=k * (1 + 0.03 * dk),
                                            tid_damping=c * (1 + 0.06 * dc)),
                             SENSITIVITY_AMPLITUDE) for dk, dc in moves], band)
    for (dk, dc), (peak, _) in zip(moves, neighbours, strict=True):
        assert peak > at_optimum, (dk, dc)


def test_sensitivities_reject_bad_input(system):
    with pytest.raises(ValueError, match="amplitude"):
        tj.sensitivities(system, -1.0)
    with pytest.raises(ValueError, match="amplitude"):
        tj.sensitivities(system, [100.0, 200.0])
    with pytest.raises(ValueError, match="system"):
        tj.sensitivities("paper", 100.0)
    with pytest.raises(ValueError, match="max_steps"):
        tj.sensitivities(system, 100.0, max_steps=0)
    with pytest.raises(ValueError, match="tol"):
        tj.sensitivities(system, 100.0, tol=-1.0)
    with pytest.raises(ValueError, match="omegas"):
        tj.sensitivities(system, 100.0, omegas=[1.0, 2.0])
    with pytest.raises(ValueError, match="amplitudes must be distinct"):
        tj.amplitude_sensitivities(system, [100.0, 100.0])
    with pytest.raises(ValueError, match="amplitudes"):
        tj.amplitude_sensitivities(system, [100.0, -1.0])


# --- command line ----------------------------------------------------------------------


def test_cli_sensitivity_ranks_parameters(tmp_path, capsys, band, sensitivity):
    from tid_jax import cli

    status = cli.main(
        [
            "sensitivity",
            "--amplitudes",
            str(SENSITIVITY_AMPLITUDE),
            "--n-frequencies",
            str(len(band)),
            "--no-optimum",
            "--quiet",
            "--out",
            str(tmp_path),
        ]
    )
    assert status == 0
    lines = capsys.readouterr().out.splitlines()
    first = lines[3].split()  # after the title, the header and the rule
    order = np.argsort(-np.abs(np.asarray(sensitivity.host_elasticity)))
    # the amplitude and its unit, then the parameter ranked first and its elasticity
    assert first[2] == sensitivity.parameters[order[0]]
    assert f"{float(sensitivity.host_elasticity[order[0]]):.4f}" in first
    with open(tmp_path / "sensitivity.csv") as file:
        assert len(file.readlines()) == 1 + len(sensitivity.parameters)
