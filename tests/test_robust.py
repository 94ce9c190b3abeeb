"""The best tuning per scenario and the robust design over amplitudes."""

import numpy as np
import pytest

import tid_jax as tj

ROBUST_AMPLITUDES = (100.0, 200.0, 3000.0)  # N: the ends of the paper's range and 200 N
PAPER_RULE = (1.05, 0.9)  # k and c over Den Hartog's: the paper's "+5% k, -10% c"


# --- robust design ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def best(system, band):
    return tj.best_tunings(system, ROBUST_AMPLITUDES, omegas=band)


@pytest.fixture(scope="module")
def robust(system, best):
    return tj.robust_tune(system, ROBUST_AMPLITUDES, best=best)


@pytest.fixture(scope="module")
def robust_free(system, best):
    return tj.robust_tune(system, ROBUST_AMPLITUDES, best=best, stroke_limit=None)


@pytest.fixture(scope="module")
def other_designs(system, best):
    """Den Hartog, retuned at 200 N, and the paper's rule, each against the same best."""
    k, c = float(system.tid_stiffness), float(system.tid_damping)
    at_200 = ROBUST_AMPLITUDES.index(200.0)
    tunings = {
        "Den Hartog": (k, c),
        "retuned at 200 N": (
            float(best.tid_stiffness[0, at_200]),
            float(best.tid_damping[0, at_200]),
        ),
        "paper rule": (PAPER_RULE[0] * k, PAPER_RULE[1] * c),
    }
    return {
        name: tj.tuning_performance(system.replace(tid_stiffness=kk, tid_damping=cc), best)
        for name, (kk, cc) in tunings.items()
    }


def _fine_stroke(system, k, c, band):
    """Largest inerter displacement (m) on a grid eight times finer and 2% wider than the
    design band, over the converged steady states (at most one may fail)."""
    fine = np.linspace(band[0] * 0.98, band[-1] * 1.02, 161)
    response = tj.frequency_response(
        system.replace(tid_stiffness=k, tid_damping=c), fine, ROBUST_AMPLITUDES
    )
    converged = np.asarray(response.converged)
    assert np.sum(~converged) <= 1
    return float(np.max(np.asarray(response.y_max)[converged]))


def test_best_tunings(system, best):
    assert bool(np.all(best.converged))
    # Low amplitudes want a stiffer TID with less damping (paper, section 4.2); at 3000 N
    # the device is nearly linear and Den Hartog's tuning nearly optimal.
    k = np.asarray(best.tid_stiffness)[0] / float(system.tid_stiffness)
    c = np.asarray(best.tid_damping)[0] / float(system.tid_damping)
    assert k[0] > k[1] > k[2] and c[0] < c[1] < c[2]
    assert abs(k[2] - 1) < 0.02 and abs(c[2] - 1) < 0.05
    # The paper's retuning at 200 N: k 1.09 and c 0.45 of Den Hartog's.
    assert k[1] == pytest.approx(1.09, abs=0.02) and c[1] == pytest.approx(0.45, abs=0.05)


def test_best_tunings_are_the_retunes_optima(system, band, best):
    # One optimum: `best_tunings` is `retune`'s optimiser on the same lanes, so its
    # tunings are those `retune` reports, to the last bit.
    retuned = tj.retune(system, ROBUST_AMPLITUDES, omegas=band)
    np.testing.assert_array_equal(np.asarray(best.tid_stiffness)[0],
                                  np.asarray(retuned.tid_stiffness))
    np.testing.assert_array_equal(np.asarray(best.tid_damping)[0],
                                  np.asarray(retuned.tid_damping))
    np.testing.assert_array_equal(np.asarray(best.converged)[0], np.asarray(retuned.converged))


def test_robust_beats_other_designs_without_stroke_limit(robust_free, other_designs):
    assert int(robust_free.status) == 0, robust_free.status_messages()[0]
    for name, performance in other_designs.items():
        assert float(robust_free.worst_ratio) <= float(performance.worst_ratio), name
    # The best tuning at each amplitude has ratio 1, so no tuning does better than 1.
    assert float(np.min(robust_free.performance.ratio)) >= 1 - 1e-3


def test_robust_design_respects_stroke_limit(system, band, robust, other_designs):
    assert int(robust.status) == 0, robust.status_messages()[0]
    k, c = float(robust.tid_stiffness), float(robust.tid_damping)
    # Checked independently on a finer and wider grid than the design's.
    assert _fine_stroke(system, k, c, band) <= tj.PAPER_STROKE
    assert float(robust.max_stroke) <= tj.PAPER_STROKE
    assert float(robust.stroke_margin) >= 0
    feasible = 0
    for name, performance in other_designs.items():
        kk, cc = float(performance.tid_stiffness), float(performance.tid_damping)
        if _fine_stroke(system, kk, cc, band) <= tj.PAPER_STROKE:
            feasible += 1
            assert float(robust.worst_ratio) <= float(performance.worst_ratio), name
    assert feasible >= 1  # Den Hartog's tuning keeps the stroke within 7 cm


def test_robust_reports_where_the_worst_case_is(robust, robust_free):
    for design in (robust, robust_free):
        ratio = np.asarray(design.performance.ratio)
        i, j = np.unravel_index(np.argmax(ratio), ratio.shape)
        assert float(design.worst_ratio) == pytest.approx(ratio[i, j], rel=1e-12)
        assert float(design.worst_amplitude) == ROBUST_AMPLITUDES[j]
        assert float(design.worst_host_frequency_scale) == 1.0
        assert ratio.shape == (1, len(ROBUST_AMPLITUDES))
    # Without the limit the worst cases balance between the ends of the range.
    free = np.asarray(robust_free.performance.ratio)[0]
    assert free[0] == pytest.approx(free[-1], rel=0.01)


def test_robust_tune_rejects_bad_input(system, best):
    with pytest.raises(ValueError, match="stroke_limit"):
        tj.robust_tune(system, ROBUST_AMPLITUDES, best=best, stroke_limit=-0.07)
    with pytest.raises(ValueError, match="amplitudes"):
        tj.robust_tune(system, [100.0, 3000.0], best=best)
    with pytest.raises(ValueError, match="amplitudes"):
        tj.robust_tune(system, [], best=best)
    with pytest.raises(ValueError, match="host_frequency_scales"):
        tj.robust_tune(system, ROBUST_AMPLITUDES, host_frequency_scales=[0.0], best=best)
    with pytest.raises(ValueError, match="another system"):
        tj.robust_tune(system.replace(inertance=80.0), ROBUST_AMPLITUDES, best=best)
    with pytest.raises(ValueError, match="best"):
        tj.robust_tune(system, ROBUST_AMPLITUDES, best="none")
    with pytest.raises(ValueError, match="another system"):
        tj.tuning_performance(system.replace(host_mass=1000.0), best)


def test_robust_settings_set_the_stages(system, best, robust_free):
    settings = tj.RobustSettings(sharpness=(1000.0,))
    messages = []
    design = tj.robust_tune(system, ROBUST_AMPLITUDES, best=best, stroke_limit=None,
                            robust_settings=settings, progress=messages.append)
    assert any("stage 1/1 (smooth-max sharpness 1000)" in m for m in messages)
    assert not any("stage 2/" in m for m in messages)
    assert bool(design.converged)
    # the last stage's sharpness is the default's: the same optimum
    assert float(design.worst_ratio) == pytest.approx(float(robust_free.worst_ratio), rel=1e-4)


def test_negligible_curvatures_leave_the_optimum_alone(system, best):
    # The robust design evaluates a trial design with the curvatures of the scenarios
    # that weigh in the smooth maxima only, so it solves fewer steady states; with every
    # scenario's curvature (no weight negligible) it reaches the same optimum, the values
    # and gradients being the same. The tasks it maps (`map_lanes`) count the work.
    tasks = []

    def counting(function, lanes):
        # each task's lanes: the leading axis of its first argument where it is an array
        tasks.extend(np.shape(lane[0])[0] if np.ndim(lane[0]) else 1 for lane in lanes)
        return [function(*lane) for lane in lanes]

    again = tj.robust_tune(system, ROBUST_AMPLITUDES, best=best, map_lanes=counting)
    skipping = sum(tasks)
    tasks.clear()
    full = tj.robust_tune(system, ROBUST_AMPLITUDES, best=best, map_lanes=counting,
                          robust_settings=tj.RobustSettings(negligible_weight=0.0))
    assert sum(tasks) > skipping > 0
    assert bool(again.converged) and bool(full.converged)
    assert float(full.tid_stiffness) == pytest.approx(float(again.tid_stiffness), rel=1e-6)
    assert float(full.tid_damping) == pytest.approx(float(again.tid_damping), rel=1e-5)


@pytest.mark.parametrize(
    ("changes", "name"),
    [(dict(sharpness=()), "sharpness"), (dict(stroke_margin=1.0), "stroke_margin"),
     (dict(check_refinement=0), "check_refinement"), (dict(stroke_rounds=-1), "stroke_rounds"),
     (dict(max_step=float("nan")), "max_step")],
)
def test_bad_robust_settings(system, best, changes, name):
    with pytest.raises(ValueError, match=f"RobustSettings.{name}"):
        tj.RobustSettings(**changes)
    with pytest.raises(ValueError, match="robust_settings must be a RobustSettings"):
        tj.robust_tune(system, ROBUST_AMPLITUDES, best=best, robust_settings=tj.RetuneSettings())


# --- command line ----------------------------------------------------------------------


def test_cli_robust_rejects_bad_tolerance(tmp_path, capsys):
    from tid_jax import cli

    status = cli.main(["robust", "--host-frequency-tolerance", "1.5", "--out", str(tmp_path)])
    assert status == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and "host_frequency_tolerance" in error[0]


def test_cli_robust_writes_the_design(tmp_path, capsys, band, robust_free):
    import csv
    import json

    from tid_jax import cli

    argv = ["robust", "--amplitudes", *map(str, ROBUST_AMPLITUDES), "--n-frequencies",
            str(len(band)), "--no-stroke-limit",
            "--quiet", "--out", str(tmp_path)]
    assert cli.main(argv) == 0
    lines = capsys.readouterr().out.splitlines()
    data = json.loads((tmp_path / "robust.json").read_text())
    assert data["robust"]["k_N_per_m"] == pytest.approx(float(robust_free.tid_stiffness),
                                                        rel=1e-6)
    assert data["robust"]["worst_ratio"] == pytest.approx(float(robust_free.worst_ratio),
                                                          rel=1e-6)
    with open(tmp_path / "robust.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert [float(row["amplitude"]) for row in rows] == list(ROBUST_AMPLITUDES)
    assert {row["amplitude_unit"] for row in rows} == {"N"}
    ratios = np.asarray(robust_free.performance.ratio)[0]
    # the table: a row per scenario, the robust ratio in its sixth column
    assert [float(line.split()[5]) for line in lines[3:]] == pytest.approx(ratios, abs=5e-4)

