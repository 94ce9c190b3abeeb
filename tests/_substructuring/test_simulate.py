"""Virtual real-time dynamic substructuring (RTDS) test of the inerter (paper section 5).

Expected values come from the whole-system model (`frequency_response`), from closed-form
linear theory of the delayed loop, or from the neutral-equation stability condition."""

import contextlib
import csv
import io
import json
import math

import numpy as np
import pytest

import tid_jax as tj
from tid_jax.cli import main
from tid_jax.cli.rtds import RTDS_COLUMNS

SYSTEM = tj.paper_system(friction_width=None)  # the test needs smoothed friction
FRICTIONLESS = SYSTEM.replace(friction_force=0.0)
B = float(SYSTEM.inertance)
A = 200.0  # N
OMEGAS = 2 * math.pi * np.array([3.8, 4.0, 4.2])  # rad/s, around the tuned 4 Hz host
GUESS_RATIOS = np.array([0.6, 0.8, 1.0, 1.2])
SAMPLE_PERIOD = 1e-3  # s, the default 1 kHz controller


def closed_form(system, omega, inerter_stiffness):
    """Linear steady state X, Y (complex, m) of host + spring/damper + a terminal element
    of dynamic stiffness `inerter_stiffness` (N/m; -b w^2 for an ideal inerter)."""
    spring = float(system.tid_stiffness) + 1j * omega * float(system.tid_damping)
    terminal = spring / (spring + inerter_stiffness)  # Y / X
    host = (
        float(system.host_stiffness)
        - float(system.host_mass) * omega**2
        + 1j * omega * float(system.host_damping)
        + spring * (1 - terminal)
    )
    x = A / host
    return x, x * terminal


def delayed_inertance(guess, omega, delay):
    """Effective complex inertance b_g + (b - b_g) exp(-i w delay) of error feedback when
    the measured acceleration lags the numerical one by `delay`."""
    return guess + (B - guess) * np.exp(-1j * omega * delay)


def relative(a, b):
    return np.abs(np.asarray(a) / np.asarray(b) - 1)


def phase_gap(a, b):
    return np.abs(np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b)))))


@pytest.fixture(scope="module")
def whole():
    return tj.frequency_response(SYSTEM, OMEGAS, A)


@pytest.fixture(scope="module")
def predicted():
    """tau = 10 ms, b_g / b in 0.6-1.2 (rows) x frequencies, with the default delay
    compensation (harmonic forward prediction, as in the paper's tests)."""
    return tj.simulate_substructuring(
        SYSTEM,
        OMEGAS[None, :],
        A,
        scheme="error_feedback",
        delay=0.01,
        guessed_inertance=B * GUESS_RATIOS[:, None],
    )


@pytest.fixture(scope="module")
def ideal():
    """tau = 0, no lag, no prediction, b_g = 0.8 b, at 2 kHz and 8 kHz."""
    return {
        rate: tj.simulate_substructuring(
            SYSTEM,
            OMEGAS,
            A,
            delay=0.0,
            guessed_inertance=0.8 * B,
            prediction=None,
            sample_rate=rate,
            periods=30,
        )
        for rate in (2000.0, 8000.0)
    }


def test_shapes_and_reference(predicted, whole):
    assert predicted.x_max.shape == (4, 3)
    assert predicted.stable.dtype == bool
    np.testing.assert_allclose(predicted.guessed_inertance[:, 0], B * GUESS_RATIOS)
    # The built-in reference is the whole-system model of frequency_response.
    assert bool(np.all(predicted.reference_converged))
    np.testing.assert_allclose(
        predicted.reference_x_max, np.broadcast_to(whole.x_max, (4, 3)), rtol=1e-6
    )
    np.testing.assert_allclose(
        predicted.reference_y_max, np.broadcast_to(whole.y_max, (4, 3)), rtol=1e-6
    )
    # (the errors are against the built-in reference, which agrees with the separate
    # solve above to within the solver's tolerance)
    np.testing.assert_allclose(
        predicted.x_amplitude_error,
        np.asarray(predicted.x_max) / np.asarray(predicted.reference_x_max) - 1,
        atol=1e-12,
    )


def test_figure14_case_within_two_percent(predicted, whole):
    # tau = 10 ms, b_g = 0.8 b, A = 200 N near 4 Hz, forward prediction.
    row = list(GUESS_RATIOS).index(0.8)
    assert bool(np.all(predicted.stable[row]))
    assert np.max(relative(predicted.x_max[row], whole.x_max)) < 0.02
    assert np.max(relative(predicted.y_max[row], whole.y_max)) < 0.02
    assert np.max(np.abs(predicted.x_phase_error[row])) < 0.03
    assert np.max(np.abs(predicted.y_phase_error[row])) < 0.03


def test_error_feedback_insensitive_to_guessed_inertance(predicted, whole):
    assert bool(np.all(predicted.stable))
    for field, reference in (("x_max", whole.x_max), ("y_max", whole.y_max)):
        values = np.asarray(getattr(predicted, field))
        assert np.max(relative(values, reference)) < 0.02
        spread = (values.max(axis=0) - values.min(axis=0)) / np.asarray(reference)
        assert np.max(spread) < 0.02


def test_ideal_actuator_reproduces_whole_system(ideal, whole):
    fine = ideal[8000.0]
    assert bool(np.all(fine.stable))
    assert np.max(relative(fine.x_max, whole.x_max)) < 1e-3
    assert np.max(relative(fine.y_max, whole.y_max)) < 1e-3
    assert np.max(np.abs(fine.x_phase_error)) < 1e-3
    assert np.max(np.abs(fine.y_phase_error)) < 1e-3


def test_ideal_actuator_error_is_first_order_in_sample_period(ideal, whole):
    # What is left at tau = 0 is the zero-order hold: 4x the sample rate, ~4x smaller.
    def worst(result):
        return max(
            np.max(relative(result.x_max, whole.x_max)), np.max(relative(result.y_max, whole.y_max))
        )

    assert worst(ideal[2000.0]) > 2.5 * worst(ideal[8000.0])


def test_conventional_scheme_unstable_for_every_delay():
    delays = np.array([0.5e-3, 1e-3, 2e-3, 5e-3, 10e-3, 20e-3])
    for prediction in (None, "harmonic"):
        result = tj.simulate_substructuring(
            SYSTEM,
            OMEGAS[1],
            A,
            scheme="conventional",
            delay=delays,
            prediction=prediction,
            reference=False,
        )
        assert not np.any(result.stable)
        assert bool(np.all(result.diverged))
        for field in ("x_max", "y_max", "x_phase", "y_phase", "growth"):
            assert np.all(np.isfinite(getattr(result, field)))


def test_exact_guess_without_friction_is_exact_for_any_delay():
    # b_g = b and ff = 0: the fed-back error e = (b - b_g) y*'' vanishes identically.
    result = tj.simulate_substructuring(
        FRICTIONLESS, OMEGAS, A, delay=np.array([0.0, 0.005, 0.02]), prediction=None,
        reference=False,
    )
    x, y = closed_form(FRICTIONLESS, OMEGAS, -B * OMEGAS**2)
    assert bool(np.all(result.stable))
    assert np.max(relative(result.x_max, np.abs(x))) < 1e-6
    assert np.max(relative(result.y_max, np.abs(y))) < 1e-6
    assert np.max(phase_gap(result.x_phase, np.angle(x))) < 1e-6
    assert np.max(phase_gap(result.y_phase, np.angle(y))) < 1e-6


@pytest.mark.parametrize(
    ("delay", "prediction", "lag"),
    [(0.01, None, 0.0), (0.01, "harmonic", 0.0), (0.0, None, 0.003)],
)
def test_linear_delayed_loop_matches_theory(delay, prediction, lag):
    # Without friction the test is a linear delay equation; its steady state has the
    # effective inertance b_g + (b - b_g) G exp(-i w tau), G the actuator lag's response,
    # plus half a sample of zero-order hold. Harmonic prediction over tau + dt/2 (its
    # default horizon) cancels both.
    guess = 0.8 * B
    result = tj.simulate_substructuring(
        FRICTIONLESS,
        OMEGAS,
        A,
        delay=delay,
        guessed_inertance=guess,
        prediction=prediction,
        actuator_lag=lag,
        reference=False,
    )
    lag_left = 0.0 if prediction == "harmonic" else delay + SAMPLE_PERIOD / 2
    effective = delayed_inertance(guess, OMEGAS, lag_left)
    if lag > 0:
        decay = math.exp(-SAMPLE_PERIOD / lag)
        response = (1 - decay) / (1 - decay * np.exp(-1j * OMEGAS * SAMPLE_PERIOD))
        effective = guess + (effective - guess) * response
    x, y = closed_form(FRICTIONLESS, OMEGAS, -effective * OMEGAS**2)
    assert bool(np.all(result.stable))
    assert np.max(relative(result.x_max, np.abs(x))) < 3e-3
    assert np.max(relative(result.y_max, np.abs(y))) < 3e-3
    assert np.max(phase_gap(result.x_phase, np.angle(x))) < 3e-3
    if delay > 0 and prediction is None:
        # ... and the delay matters: the undelayed system is far off.
        x_ideal, _ = closed_form(FRICTIONLESS, OMEGAS, -B * OMEGAS**2)
        assert np.max(relative(result.x_max, np.abs(x_ideal))) > 0.05


def test_compliant_device_matches_theory():
    # The physical substructure is the whole device: a mechanism (b, cp) behind a spring
    # ks, with a terminal mass mt; terminal dynamic stiffness Dm / (1 + Dm / ks) - mt w^2,
    # Dm = -b w^2 + i w cp. With the paper's harmonic guess -b_g w^2 y* (b_g = b + mt by
    # default), e cancels b_g y'' in steady state.
    stiffness, damping, mass = 1e6, 300.0, 2.0
    device = FRICTIONLESS.replace(series_stiffness=stiffness, parasitic_damping=damping,
                                  terminal_mass=mass)
    result = tj.simulate_substructuring(
        device,
        OMEGAS,
        A,
        delay=0.0,
        guessed_force="harmonic",
        prediction=None,
        sample_rate=8000.0,
        periods=30,
        reference=False,
    )
    mechanism = -B * OMEGAS**2 + 1j * OMEGAS * damping
    x, y = closed_form(FRICTIONLESS, OMEGAS, mechanism / (1 + mechanism / stiffness)
                       - mass * OMEGAS**2)
    assert bool(np.all(result.stable))
    assert np.max(relative(result.x_max, np.abs(x))) < 2e-3
    assert np.max(relative(result.y_max, np.abs(y))) < 2e-3
    host, inerter = tj.linear_receptance(device, OMEGAS)
    assert np.max(relative(np.abs(A * np.asarray(host)), np.abs(x))) < 1e-12
    assert np.max(relative(np.abs(A * np.asarray(inerter)), np.abs(y))) < 1e-12
    rigid, _ = closed_form(FRICTIONLESS, OMEGAS, -B * OMEGAS**2)
    assert np.max(relative(np.abs(x), np.abs(rigid))) > 0.01  # the device shows


def test_backlash_is_compared_with_the_rigid_device():
    # The whole-system reference of a test with a compliant device is its rigid
    # counterpart, the design under test; free play worsens the agreement.
    compliant = SYSTEM.replace(series_stiffness=1e6)
    options = dict(delay=0.0, guessed_force="harmonic", prediction=None, sample_rate=8000.0,
                   periods=30)
    tight = tj.simulate_substructuring(compliant, OMEGAS[1], A, **options)
    loose = tj.simulate_substructuring(compliant.replace(backlash=5e-4), OMEGAS[1], A,
                                       **options)
    whole = tj.frequency_response(SYSTEM, OMEGAS[1], A)
    for result in (tight, loose):
        assert bool(result.stable)
        assert float(result.reference_x_max) == pytest.approx(float(whole.x_max),
                                                             rel=1e-9)
    assert abs(float(loose.x_amplitude_error)) > abs(float(tight.x_amplitude_error))


def test_stability_follows_neutral_condition():
    # Without prediction the measured inertia closes a neutral loop
    # b_g y''(t) + (b - b_g) y''(t - tau) + ... = 0: stable only if |b - b_g| < b_g.
    stability = tj.substructuring_stability(
        SYSTEM,
        OMEGAS[1],
        A,
        guessed_inertance=B * np.array([0.4, 0.7, 1.0]),
        delay=[0.0, 0.005, 0.01, 0.02],
    )
    assert stability.stable.shape == (3, 4)
    np.testing.assert_array_equal(stability.stable, [[False] * 4, [True] * 4, [True] * 4])
    np.testing.assert_allclose(stability.largest_stable_delay, [-1.0, 0.02, 0.02])


def test_harmonic_guess_needs_guess_above_inertance():
    # With e = f_s + b_g w^2 y* the loop is b_g y''(t) + b cos(w tau) y''(t) ... : the
    # physical inertia b enters undiminished, so b cos(w tau) / b_g < 1 is needed.
    ratios = np.array([0.9, 1.1, 1.3])
    assert (1 / ratios[0]) * math.cos(OMEGAS[1] * 0.01) > 1 > (1 / ratios[1])
    result = tj.simulate_substructuring(
        SYSTEM,
        OMEGAS[1],
        A,
        delay=0.01,
        guessed_inertance=B * ratios,
        guessed_force="harmonic",
        prediction="harmonic",
        reference=False,
    )
    np.testing.assert_array_equal(result.stable, [False, True, True])


def test_polynomial_prediction_amplifies_the_inertia_loop():
    # Quadratic extrapolation 10 samples ahead has gain 241 at the Nyquist frequency, so
    # any (b - b_g) / b_g above 1/241 destabilises; with b_g = b the loop is open.
    result = tj.simulate_substructuring(
        SYSTEM,
        OMEGAS[1],
        A,
        delay=0.01,
        guessed_inertance=B * np.array([0.9, 0.97, 1.0]),
        prediction="polynomial",
        prediction_order=2,
        reference=False,
    )
    np.testing.assert_array_equal(result.stable, [False, False, True])


@pytest.mark.parametrize(
    ("changes", "name"),
    [
        (dict(scheme="hybrid"), "scheme"),
        (dict(delay=-0.001), "delay"),
        (dict(delay=float("nan")), "delay"),
        (dict(delay=100.0), "delay"),
        (dict(sample_rate=0.0), "sample_rate"),
        (dict(guessed_inertance=0.0), "guessed_inertance"),
        (dict(guessed_force="measured"), "guessed_force"),
        (dict(prediction="linear"), "prediction"),
        (dict(prediction_order=7), "prediction_order"),
        (dict(prediction_horizon=-1.0), "prediction_horizon"),
        (dict(actuator_lag=-1.0), "actuator_lag"),
        (dict(substeps=0), "substeps"),
        (dict(periods=3), "periods"),
        (dict(divergence_factor=1.0), "divergence_factor"),
        (dict(omega=-1.0), "omega"),
        (dict(omega=2000.0), "omega"),
        (dict(amplitude=0.0), "amplitude"),
        (dict(delay=[0.0, 0.01], guessed_inertance=[60.0, 70.0, 80.0]), "broadcast"),
    ],
)
def test_bad_input_names_argument(changes, name):
    arguments = dict(omega=OMEGAS[1], amplitude=A)
    arguments.update(changes)
    omega, amplitude = arguments.pop("omega"), arguments.pop("amplitude")
    with pytest.raises(ValueError, match=name):
        tj.simulate_substructuring(SYSTEM, omega, amplitude, **arguments)


def test_bad_system_rejected():
    with pytest.raises(ValueError, match="system"):
        tj.simulate_substructuring("paper", OMEGAS[1], A)
    with pytest.raises(ValueError, match="tid_damping"):
        tj.simulate_substructuring(
            SYSTEM.replace(tid_damping=0.0), OMEGAS[1], A, scheme="conventional"
        )
    with pytest.raises(ValueError, match="delay"):
        tj.substructuring_stability(SYSTEM, OMEGAS[1], A, guessed_inertance=[B], delay=[0.01, 0.0])


def run_cli(argv):
    """`tid-jax` in-process: `(exit status, stdout, stderr)`."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main([str(arg) for arg in argv])
    return status, out.getvalue(), err.getvalue()


def test_cli_rtds_table_and_files(tmp_path, whole):
    frequencies = [f"{w / (2 * math.pi):.1f}" for w in OMEGAS]
    status, stdout, _ = run_cli(
        [
            "rtds",
            "--frequency-hz",
            *frequencies,
            "--amplitude",
            A,
            "--delay-ms",
            10,
            "--guessed-inertance-ratio",
            0.8,
            "--out",
            tmp_path,
            "--quiet",
        ]
    )
    assert status == 0
    assert stdout.count("stable") == 3
    with open(tmp_path / "rtds.csv", newline="") as file:
        rows = list(csv.reader(file))
    assert tuple(rows[0]) == RTDS_COLUMNS
    table = np.array(
        [
            [float(v == "True") if v in ("True", "False") else float(v) for v in row]
            for row in rows[1:]
        ]
    )
    column = {name: table[:, i] for i, name in enumerate(RTDS_COLUMNS)}
    np.testing.assert_allclose(column["x_whole_m"], whole.x_max, rtol=1e-6)
    assert np.max(relative(column["x_test_m"], whole.x_max)) < 0.02
    assert np.max(relative(column["y_test_m"], whole.y_max)) < 0.02
    data = json.loads((tmp_path / "rtds.json").read_text())
    assert data["test"]["guessed_inertance_kg"] == pytest.approx(0.8 * B)
    assert data["system"]["friction_width"] is None  # the relative width, not exact friction
    assert (tmp_path / "rtds.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_rtds_takes_the_whole_device(tmp_path):
    device = dict(series_stiffness=1e6, backlash=1e-4, parasitic_damping=300.0,
                  terminal_mass=2.0)
    flags = [item for name, value in device.items()
             for item in (f"--{name.replace('_', '-')}", value)]
    options = dict(delay=0.0, guessed_force="harmonic", prediction=None, sample_rate=8000.0)
    status, stdout, stderr = run_cli(["rtds", "--frequency-hz", "4.0", "--amplitude", A,
                                      "--delay-ms", 0, "--guessed-force", "harmonic",
                                      "--prediction", "none", "--sample-rate", 8000, *flags,
                                      "--out", tmp_path, "--quiet"])
    assert status == 0, stderr
    data = json.loads((tmp_path / "rtds.json").read_text())
    assert {name: data["system"][name] for name in device} == device
    assert data["test"]["guessed_inertance_kg"] == pytest.approx(B + 2.0)
    expected = tj.simulate_substructuring(SYSTEM.replace(**device), 2 * math.pi * 4.0, A,
                                          **options)
    assert bool(expected.stable)
    assert data["x_test_m"][0] == pytest.approx(float(expected.x_max), rel=1e-9)


@pytest.mark.parametrize(
    ("argv", "word"),
    [
        (["--delay-ms", "-1"], "delay_ms"),
        (["--scheme", "hybrid"], "scheme"),
        (["--frequency-hz", "4", "--band-hz", "3", "5"], "--frequency-hz"),
        (["--frequency-hz", "400"], "omega"),
        (["--amplitude", "0"], "amplitudes"),
        (["--friction-width", "0"], "needs smoothed friction"),
    ],
)
def test_cli_rtds_bad_input_is_one_line(tmp_path, argv, word):
    status, stdout, stderr = run_cli(["rtds", *argv, "--out", tmp_path, "--quiet"])
    assert status == 2
    assert stdout == ""
    assert len(stderr.strip().splitlines()) == 1
    assert word in stderr
    assert not any(tmp_path.iterdir())
