"""The inerter device identified from synthetic test records with known parameters (the
independent event-driven reference `tests/reference/inerter.py`, 1% force noise), and
`tid-jax identify` on a records file."""

import csv
import dataclasses
import json
import tomllib

import jax
import numpy as np
import pytest

import tid_jax as tj
from tests.cli.test_main import run
from tests.reference.inerter import synthetic_records
from tid_jax._identify import _fit as _identify
from tid_jax._identify._device import ForceSettings, Motion, friction_width
from tid_jax.cli._common import INPUT_KEYS, _inputs, _system

jax.config.update("jax_enable_x64", True)

NOISE = 0.01  # force noise, relative to each record's peak force
PAPER_DEVICE = dict(inertance=75.0, friction_force=20.0)
# a compliant device: the mechanism resonates on its mounts at 10 Hz, 3% damped
COMPLIANT_DEVICE = dict(inertance=75.0, friction_force=20.0, parasitic_damping=300.0,
                        series_stiffness=3e5)


def _records(device, seed=0):
    return [tj.InerterRecord(r["time"], r["displacement"], r["force"], name=f"test {i}")
            for i, r in enumerate(synthetic_records(noise=NOISE, seed=seed, loaded=True,
                                                    **device))]


def _noise_levels(device, seed=0):
    """The standard deviation of each record's force noise."""
    clean = synthetic_records(noise=0.0, loaded=True, **device)
    return np.array([NOISE * np.max(np.abs(r["force"])) for r in clean])


def _assert_recovered(fit, device, sigmas=3.0):
    for name, value, error in zip(fit.parameters, np.asarray(fit.estimates),
                                  np.asarray(fit.standard_errors), strict=True):
        assert 0 < error < 0.05 * device[name], (name, error)
        assert abs(value - device[name]) < sigmas * error, (name, value, error)


def test_least_squares_end_where_the_residual_noise_rejects_every_move():
    """A residual with an integration's error (1e-8, not seen by its Jacobian) about a
    linear least-squares problem: the fit ends at the first rejected step cut to a move
    within the tolerance, at the exact least squares (`numpy.linalg.lstsq`) to within
    that error, in fewer steps than cutting the trust region on until a move is
    accepted."""
    import lineax as lx
    import optimistix as optx

    t = np.linspace(0.0, 1.0, 200)
    basis = np.stack([np.ones_like(t), t, t**2], axis=1)
    data = 1.0 + 2.0 * t - 0.5 * t**2 + 0.01 * np.sin(37 * t)
    exact, *_ = np.linalg.lstsq(basis, data, rcond=None)

    def residual(x, _):
        noise = jax.lax.stop_gradient(1e-8 * jax.numpy.sin(1e9 * (x[0] + 3 * x[1] + 7 * x[2])
                                                            + 50 * t))
        return basis @ x - data + noise

    steps = []
    for solver in (_identify._LevenbergMarquardt, optx.LevenbergMarquardt):
        sol = optx.least_squares(residual, solver(rtol=1e-9, atol=1e-9,
                                                  linear_solver=lx.Normal(lx.Cholesky())),
                                 np.zeros(3), max_steps=200, throw=False)
        assert sol.result == optx.RESULTS.successful
        np.testing.assert_allclose(np.asarray(sol.value), exact, rtol=0, atol=1e-6)
        steps.append(int(sol.stats["num_steps"]))
    assert steps[0] < steps[1]


def test_paper_device_is_recovered():
    fit = tj.identify_inerter(_records(PAPER_DEVICE), model="ideal")
    assert bool(fit.converged)
    assert fit.parameters == ("inertance", "friction_force")
    _assert_recovered(fit, PAPER_DEVICE)
    b, ff = np.asarray(fit.estimates)
    assert abs(b / 75.0 - 1) < 0.01 and abs(ff / 20.0 - 1) < 0.03
    # what is left is the noise
    np.testing.assert_allclose(np.asarray(fit.rms), _noise_levels(PAPER_DEVICE), rtol=0.1)
    assert fit.device.inertance == pytest.approx(b) and fit.device.rigid
    assert abs(float(fit.correlations[0, 1])) < 1 and float(fit.correlations[0, 0]) == \
        pytest.approx(1.0)


def test_a_known_terminal_mass_is_held_and_separated_from_the_inertance():
    # A rigid device's terminal mass moves with the inertance: the records see b + mt.
    device = dict(PAPER_DEVICE, terminal_mass=2.0)
    records = _records(device)
    lumped = tj.identify_inerter(records, model="ideal")
    held = tj.identify_inerter(records, model="ideal", terminal_mass=2.0)
    assert bool(lumped.converged) and bool(held.converged)
    assert float(lumped.estimates[0]) == pytest.approx(77.0, rel=0.01)
    _assert_recovered(held, PAPER_DEVICE)
    assert held.device.terminal_mass == 2.0 and lumped.device.terminal_mass == 0.0
    with pytest.raises(ValueError, match="terminal_mass must be finite and non-negative"):
        tj.identify_inerter(records, terminal_mass=-1.0)


def test_parasitic_damping_is_recovered_and_supported():
    device = dict(PAPER_DEVICE, parasitic_damping=300.0)
    fit = tj.identify_inerter(_records(device), model="damped")
    assert bool(fit.converged)
    _assert_recovered(fit, device)
    assert fit.comparison.models == ("ideal", "damped")
    assert bool(fit.comparison.supported[1]) and float(fit.comparison.delta_bic[1]) < -10


def test_compliance_leaves_a_residual_that_the_compliant_model_removes():
    fit = tj.identify_inerter(_records(COMPLIANT_DEVICE), model="compliant")
    assert bool(fit.converged)
    _assert_recovered(fit, COMPLIANT_DEVICE)
    noise = float(np.sqrt(np.mean(_noise_levels(COMPLIANT_DEVICE) ** 2)))
    rms = np.asarray(fit.comparison.rms)
    # the rigid models leave a systematic residual many times the noise ...
    assert rms[0] > 5 * noise and rms[1] > 5 * noise
    # ... which the compliant model removes, down to the noise
    assert rms[2] < 1.1 * noise
    assert np.all(np.asarray(fit.comparison.supported))


class _Captured(Exception):
    pass


def test_the_start_scan_over_processes_is_the_scan_here():
    """The compliant model's scan of starting values, mapped over two worker processes
    (`ProcessMap`): every candidate's sum of squares is the one this process computes
    alone (the same compiled program, its arguments sent to the workers)."""
    scans = []

    def capture(function, tasks):
        scans.append((function, tasks))
        raise _Captured

    with pytest.raises(_Captured):
        tj.identify_inerter(_records(COMPLIANT_DEVICE), model="compliant", map_lanes=capture)
    [(function, tasks)] = scans
    assert len(tasks) >= 3  # the series stiffness's candidates, a few to a task
    tasks = tasks[:3]
    here = [function(*task) for task in tasks]
    with tj.ProcessMap(2) as pool:
        shared = pool(function, tasks)
    for mine, theirs in zip(here, shared, strict=True):
        assert np.all(np.isfinite(mine))
        np.testing.assert_array_equal(theirs, mine)


def test_the_scan_starts_from_the_first_of_the_lowest_finite_costs():
    """A candidate whose sum of squares is NaN or infinite (a failed integration) is never
    the start; of equal costs, the first in the scan's order is."""
    costs = [np.array([np.nan, 3.0, np.inf, 2.0]), np.array([2.0, np.nan])]
    settings = tj.IdentifySettings(stiffness_starts=(1.0, 2.0, 3.0, 4.0, 5.0))
    parameters = _identify.MODEL_PARAMETERS["compliant"]
    typical = dict.fromkeys(parameters, 1.0)
    values = np.array([75.0, 20.0, 300.0, 10.0])  # the fitted value, a sixth candidate
    motion = Motion.from_samples(np.arange(4.0), np.arange(4.0) ** 2)
    start = _identify._scanned_start(parameters, values, [motion], [np.zeros(4)], 1.0,
                                     settings, typical, 1e9, 0.0,
                                     lambda function, tasks: costs)
    np.testing.assert_array_equal(start, [75.0, 20.0, 300.0, 4.0])


def test_the_scan_keeps_the_start_where_no_series_stiffness_is_resolved():
    """Records sampled too coarsely for any scanned series stiffness (all above the
    limit): nothing is tried and the start stays."""
    parameters = _identify.MODEL_PARAMETERS["backlash"]
    values = np.array([75.0, 20.0, 300.0, 10.0, 1e-3])
    motion = Motion.from_samples(np.arange(4.0), np.arange(4.0) ** 2)
    start = _identify._scanned_start(parameters, values, [motion], [np.zeros(4)], 1.0,
                                     _identify.IdentifySettings(),
                                     dict.fromkeys(parameters, 1.0), 1e-3, 0.0,
                                     lambda function, tasks: [])
    np.testing.assert_array_equal(start, values)


def test_the_interpolant_of_evenly_spaced_samples_is_that_of_bisection():
    """The interval of evenly spaced samples (a rig's fixed rate, to within a millionth of
    the spacing) is read off their grid: the interpolant is the one that bisection
    finds, at the samples, between them and beyond the ends; uneven samples take
    bisection."""
    rng = np.random.default_rng(0)
    time = 0.25 + np.arange(200) / 1000.0
    displacement = 0.003 * np.sin(2 * np.pi * 4.0 * time + 0.3)
    jittered = time + 1e-10 * rng.standard_normal(time.size)
    t = np.concatenate([time, jittered, rng.uniform(0.2, 0.5, 400), [0.2, time[-1] + 0.01]])
    for samples in (time, jittered):
        motion = Motion.from_samples(samples, displacement)
        assert motion.evenly_spaced
        bisected = dataclasses.replace(motion, evenly_spaced=False)
        for got, want in zip(*(jax.jit(jax.vmap(m.at))(t) for m in (motion, bisected)),
                             strict=True):
            np.testing.assert_allclose(np.asarray(got), np.asarray(want), rtol=1e-9, atol=1e-15)
    uneven = time + 2e-4 * rng.uniform(size=time.size)
    assert not Motion.from_samples(uneven, displacement).evenly_spaced


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda t, u, f: (t[:10], u[:10], f[:10]), "too short"),
        (lambda t, u, f: (t[::-1], u, f), "time must increase"),
        (lambda t, u, f: (t, u, np.where(np.arange(t.size) == 7, np.nan, f)),
         "force is not finite at sample 7"),
        (lambda t, u, f: (t, u[:-1], f), "columns of different lengths"),
        (lambda t, u, f: (t, 0 * u, f), "does not move"),
    ],
)
def test_bad_records_are_rejected(change, message):
    t = np.linspace(0, 1, 200)
    u, f = 1e-3 * np.sin(2 * np.pi * 3 * t), np.cos(2 * np.pi * 3 * t)
    with pytest.raises(ValueError, match=message):
        tj.InerterRecord(*change(t, u, f))


def test_bad_model_is_rejected():
    with pytest.raises(ValueError, match="model must be one of"):
        tj.identify_inerter(_records(PAPER_DEVICE), model="stiff")


def _write_records(path, records, names=True):
    with open(path, "w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["record", "time", "displacement", "force"] if names
                        else ["time", "displacement", "force"])
        for i, record in enumerate(records):
            for row in zip(record["time"], record["displacement"], record["force"],
                           strict=True):
                writer.writerow([f"test {i}", *row] if names else row)


def test_cli_identifies_and_writes_files_retune_accepts(tmp_path):
    records = synthetic_records(noise=NOISE, seed=0, **PAPER_DEVICE)
    path = tmp_path / "records.csv"
    _write_records(path, records)
    status, stdout, stderr = run(["identify", path, "--out", tmp_path / "out", "--quiet"])
    assert status == 0, stderr
    assert "inertance" in stdout and "friction_force" in stdout
    data = json.loads((tmp_path / "out" / "identify.json").read_text())
    assert set(data["parameters"]) == {"inertance", "friction_force"}
    assert set(data["standard_errors"]) == set(data["parameters"])
    assert data["parameters"]["inertance"] == pytest.approx(75.0, rel=0.01)
    assert data["parameters"]["friction_force"] == pytest.approx(20.0, rel=0.03)
    assert [r["name"] for r in data["records"]] == ["test 0", "test 1", "test 2"]
    with open(tmp_path / "out" / "identify.csv", newline="") as file:
        rows = list(csv.reader(file))
    assert len(rows) == 1 + sum(r["time"].size for r in records)
    assert (tmp_path / "out" / "identify.png").read_bytes().startswith(b"\x89PNG")
    # the saved device is what retune's --config reads
    config = tmp_path / "out" / "identify_config.toml"
    with open(config, "rb") as file:
        saved = tomllib.load(file)
    saved = saved["inerter"]
    assert set(saved) == {"inertance", "friction_force"}  # the ideal model's terms
    args = type("Args", (), {key: None for key in INPUT_KEYS})()
    args.config = str(config)
    system = _system(_inputs(args))
    assert float(system.inertance) == pytest.approx(saved["inertance"])
    assert float(system.friction_force) == pytest.approx(saved["friction_force"])


@pytest.mark.parametrize(
    "text, message",
    [
        ("time,displacement\n0,0\n", "no 'force' column"),
        ("time,displacment,force\n0,0,0\n", "unknown column 'displacment'"),
        ("time,displacement,force\n0,0,0\n0.1,abc,0\n", "row 3, column 'displacement'"),
        ("time,displacement,force\n0,0,0\n0.1,0,nan\n", "row 3, column 'force'"),
        ("time,displacement,force\n0,0,0\n0,1,0\n", "row 3, column 'time'"),
        ("time,displacement,force\n0,0,0\n0.1,0\n", "row 3 has 2 values"),
        ("time,displacement,force\n0,0,0\n0.1,0.001,0\n", "too short"),
        ("", "empty"),
    ],
)
def test_cli_bad_records_file_is_one_line(tmp_path, text, message):
    path = tmp_path / "records.csv"
    path.write_text(text)
    status, _, stderr = run(["identify", path, "--out", tmp_path / "out"])
    assert status == 2
    assert message in stderr and len(stderr.strip().splitlines()) == 1, stderr
    assert not (tmp_path / "out" / "identify.json").exists()


def test_backlash_is_recovered_where_the_compliant_model_fails():
    """A compliant device with free play rattles: the compliant model without the gap
    leaves a residual many times the noise; the backlash model recovers every parameter
    and leaves the noise."""
    device = dict(COMPLIANT_DEVICE, backlash=2e-4)
    fit = tj.identify_inerter(_records(device), model="backlash")
    assert bool(fit.converged)
    _assert_recovered(fit, device)
    noise = float(np.sqrt(np.mean(_noise_levels(device) ** 2)))
    rms = np.asarray(fit.comparison.rms)
    assert rms[2] > 5 * noise and rms[3] < 1.1 * noise
    assert bool(fit.comparison.supported[3]) and float(fit.comparison.delta_bic[3]) < -10


def test_cli_carries_a_compliant_device_with_its_terminal_mass_to_retune(tmp_path):
    device = dict(COMPLIANT_DEVICE, terminal_mass=2.0)
    path = tmp_path / "records.csv"
    _write_records(path, synthetic_records(noise=NOISE, seed=0, loaded=True, **device))
    status, stdout, stderr = run(["identify", path, "--model", "compliant", "--terminal-mass",
                                  "2", "--out", tmp_path / "out", "--quiet"])
    assert status == 0, stderr
    assert "terminal_mass held at 2 kg" in stdout
    data = json.loads((tmp_path / "out" / "identify.json").read_text())
    for name, value in data["parameters"].items():
        assert abs(value - device[name]) < 3 * data["standard_errors"][name], name
    config = tmp_path / "out" / "identify_config.toml"
    with open(config, "rb") as file:
        saved = tomllib.load(file)["inerter"]
    assert set(saved) == {"inertance", "friction_force", "parasitic_damping",
                          "series_stiffness", "terminal_mass"}
    args = type("Args", (), {key: None for key in INPUT_KEYS})()
    args.config = str(config)
    system = _system(_inputs(args))
    assert system.compliant and float(system.terminal_mass) == 2.0
    assert float(system.series_stiffness) == pytest.approx(saved["series_stiffness"])
    # a terminal mass that is no mass is refused before anything is read or fitted
    status, _, stderr = run(["identify", path, "--terminal-mass", "-1", "--out",
                             tmp_path / "bad"])
    assert status == 2 and "terminal_mass must be finite and non-negative" in stderr


def test_a_term_the_records_would_take_negative_fits_at_zero():
    """The 4 Hz test of a compliant device alone: the rigid damped model's least squares
    would take a negative friction force (the ringing on the mounts read as a force
    against the motion). The friction fits at zero, and the other two terms at their
    least squares with it zero (linear in them: `numpy.linalg.lstsq`). The standard
    errors are those of that linear model, the friction's included (not zero): the
    noise variance from the residual of the fit, times the diagonal of (X^T X)^-1."""
    [record] = _records(COMPLIANT_DEVICE)[-1:]
    motion = Motion.from_samples(record.time, record.displacement)
    velocity, force = np.asarray(motion.velocity), np.asarray(record.force)
    width = float(friction_width(motion, ForceSettings()))
    columns = np.stack([np.asarray(motion.acceleration), np.tanh(velocity / width), velocity],
                       axis=1)
    assert np.linalg.lstsq(columns, force, rcond=None)[0][1] < 0
    b, cp = np.linalg.lstsq(columns[:, [0, 2]], force, rcond=None)[0]
    damped = tj.identify_inerter([record], model="damped")
    assert bool(damped.converged) and damped.comparison.models == ("ideal", "damped")
    estimates = np.asarray(damped.estimates)
    assert 0 <= estimates[1] < 1e-6 * np.max(np.abs(force))
    np.testing.assert_allclose(estimates[[0, 2]], [b, cp], rtol=1e-6)
    residual = force - columns[:, [0, 2]] @ [b, cp]
    variance = residual @ residual / (force.size - 3)
    errors = np.sqrt(variance * np.diag(np.linalg.inv(columns.T @ columns)))
    np.testing.assert_allclose(np.asarray(damped.standard_errors), errors, rtol=1e-5)
