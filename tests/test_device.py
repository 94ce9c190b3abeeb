"""The real inerter in the TID: parasitic damping, terminal mass, compliance and backlash
through the steady-state solvers and the design, against the independent references."""

import math

import numpy as np
import pytest

import tid_jax as tj
from tests.lanes import peaks_of
from tests.reference import hinf
from tests.reference.compliant import compliant_peaks
from tests.reference.coulomb import coulomb_steady_state
from tests.reference.transient import transient_peaks

DEVICE = dict(parasitic_damping=300.0, terminal_mass=2.0)  # N s/m, kg: the Penske unit's mass
MODEL_FIELDS = ("host_mass", "host_stiffness", "host_damping", "inertance", "friction_force",
                "tid_stiffness", "tid_damping", "parasitic_damping", "terminal_mass")
OMEGA_RATIOS = np.array([0.85, 0.95, 1.02, 1.12])


@pytest.fixture(scope="module")
def system():
    """The paper's system with the friction smoothed at the relative width: the model of
    the compliant device (which has no exact friction) and of the transient references;
    the rigid device's exact friction is compared alongside where it applies."""
    return tj.paper_system(friction_width=None)


def _fields(system):
    return {name: float(getattr(system, name)) for name in MODEL_FIELDS}


def test_default_device_is_the_ideal_inerter(system):
    omegas = OMEGA_RATIOS * float(system.host_frequency)
    explicit = system.replace(parasitic_damping=0.0, terminal_mass=0.0,
                              series_stiffness=math.inf, backlash=0.0)
    for width in (None, 0.0):
        a = tj.frequency_response(system.replace(friction_width=width), omegas, [300.0])
        b = tj.frequency_response(explicit.replace(friction_width=width), omegas, [300.0])
        np.testing.assert_array_equal(np.asarray(a.x_max), np.asarray(b.x_max))
        np.testing.assert_array_equal(np.asarray(a.state), np.asarray(b.state))


@pytest.mark.parametrize("amplitude", [100.0, 300.0])
def test_device_terms_match_the_references(system, amplitude):
    device = system.replace(**DEVICE)
    omegas = OMEGA_RATIOS * float(system.host_frequency)
    exact = tj.frequency_response(device.replace(friction_width=0.0), omegas, [amplitude])
    smooth = tj.frequency_response(device, omegas, [amplitude])
    ideal = tj.frequency_response(system, omegas, [amplitude])
    assert bool(np.all(exact.converged)) and bool(np.all(smooth.converged))
    for i, omega in enumerate(omegas):
        reference = coulomb_steady_state(**_fields(device), omega=omega, amplitude=amplitude)
        assert float(exact.x_max[0, i]) == pytest.approx(reference["x_max"], rel=1e-6)
        assert float(exact.y_max[0, i]) == pytest.approx(reference["y_max"], rel=1e-6, abs=1e-9)
        reference = transient_peaks(dict(_fields(device), omega=omega, amplitude=amplitude),
                                    float(device.width_at(amplitude, omega)))
        assert float(smooth.x_max[0, i]) == pytest.approx(reference["x_max"], rel=1e-6)
        assert float(smooth.y_max[0, i]) == pytest.approx(reference["y_max"], rel=2e-4)
    # the device's terms matter at this size
    assert np.max(np.abs(np.asarray(smooth.x_max / ideal.x_max) - 1)) > 0.05


def test_retune_with_terminal_mass_is_the_h_infinity_optimum_of_the_total_mass(system):
    # Without friction, a terminal mass mt adds to the inertance: the optimum is the exact
    # H-infinity tuning of the TID with inertance b + mt.
    # (the default model, exact friction: without friction, the same linear model as the
    # smoothed one, in programs that compile in half the time)
    mass = 5.0
    device = system.replace(friction_force=0.0, terminal_mass=mass, friction_width=0.0)
    band = np.linspace(0.8, 1.2, 21) * float(system.host_frequency)
    result = tj.retune(device, [1000.0], omegas=band, tol=1e-5)
    assert bool(result.converged[0])
    k, c, peak = hinf.h_infinity_optimum(*(float(getattr(system, name)) for name in (
        "host_mass", "host_stiffness", "host_damping")), float(system.inertance) + mass)
    static = 1000.0 / float(system.host_stiffness)
    assert float(result.x_peak[0]) / static == pytest.approx(peak, abs=1e-5)
    assert float(result.tid_stiffness[0]) == pytest.approx(k, rel=2e-3)
    ideal_k = hinf.h_infinity_optimum(*(float(getattr(system, name)) for name in (
        "host_mass", "host_stiffness", "host_damping", "inertance")))[0]
    assert abs(k / ideal_k - 1) > 0.02  # the mass moves the optimum


def _sensitivities_against_differences(device, band, names):
    """`tj.sensitivities` of `device` at 400 N (no optimum), its derivatives with respect
    to `names` checked against central differences of `tj.peaks`."""
    amplitude = 400.0
    sens = tj.sensitivities(device, amplitude, omegas=band, optimum=False)
    assert bool(sens.converged)
    assert sens.parameters[-3:] == (*names, "amplitude")

    values = {name: float(sens.values[sens.parameters.index(name)]) for name in names}
    # every name's two steps in one batch
    at = peaks_of([(device.replace(**{name: values[name] * (1 + s * 1e-3)}), amplitude)
                   for name in names for s in (1, -1)], band).reshape(len(names), 2, 2)
    for name, (plus, minus) in zip(names, at, strict=True):
        i = sens.parameters.index(name)
        fd = (plus - minus) / (2e-3 * values[name])
        assert float(sens.host_derivative[i]) == pytest.approx(fd[0], rel=1e-3), name
        assert float(sens.stroke_derivative[i]) == pytest.approx(fd[1], rel=1e-3), name
    return sens


def test_sensitivities_to_the_device_terms(system, band):
    # The rigid device with the default model, exact friction.
    sens = _sensitivities_against_differences(system.replace(friction_width=0.0, **DEVICE),
                                              band, ("parasitic_damping", "terminal_mass"))
    # Scaling every mass, stiffness, damping and force by s leaves x and y unchanged:
    # the elasticities, the device's among them, sum to 0.
    assert float(np.sum(sens.host_elasticity)) == pytest.approx(0.0, abs=1e-4)
    assert float(np.sum(sens.stroke_elasticity)) == pytest.approx(0.0, abs=1e-4)


COMPLIANT = dict(series_stiffness=3e5, terminal_mass=2.0)  # mounts at about 10 Hz


def test_sensitivities_to_compliance_and_backlash(system, band):
    device = system.replace(backlash=2e-4, parasitic_damping=300.0, **COMPLIANT)
    sens = _sensitivities_against_differences(device, band, ("series_stiffness", "backlash"))
    # Exact laws of the six-state model. Scaling every mass, stiffness (ks too), damping
    # and force by s leaves x and y unchanged: those elasticities sum to 0. Scaling the
    # forces and the free play by s scales x and y by s (the default friction width
    # follows A): e_A + e_ff + e_backlash = 1.
    index = {name: i for i, name in enumerate(sens.parameters)}
    for e in (np.asarray(sens.host_elasticity), np.asarray(sens.stroke_elasticity)):
        assert float(np.sum(e) - e[index["backlash"]]) == pytest.approx(0.0, abs=1e-4)
        assert float(e[index["amplitude"]] + e[index["friction_force"]]
                     + e[index["backlash"]]) == pytest.approx(1.0, abs=1e-4)
    assert abs(float(sens.host_elasticity[index["series_stiffness"]])) > 0.05  # it matters


@pytest.mark.parametrize("device", [COMPLIANT,
                                    dict(COMPLIANT, backlash=2e-4, parasitic_damping=300.0)])
def test_compliant_device_matches_the_reference(system, device):
    compliant = system.replace(**device)
    omegas = np.array([0.9, 1.0, 1.05]) * float(system.host_frequency)
    amplitude = 300.0
    # The terminal's motion has corners where the free play closes: its peak is sampled
    # finely (at the default 128 samples per period the stroke is within about 1e-4).
    response = tj.frequency_response(compliant, omegas, [amplitude],
                                     settings=tj.SolverSettings(samples=1024))
    assert bool(np.all(response.converged)) and response.state.shape == (1, 3, 6)
    fields = {name: float(value) for name, value in compliant.to_dict().items()
              if name != "friction_width"}
    for i, omega in enumerate(omegas):
        reference = compliant_peaks(dict(fields, omega=float(omega), amplitude=amplitude,
                                         friction_width=float(compliant.width_at(amplitude,
                                                                                 omega))))
        assert reference["converged"]
        assert float(response.x_max[0, i]) == pytest.approx(reference["x_max"], rel=1e-6)
        assert float(response.y_max[0, i]) == pytest.approx(reference["y_max"], rel=1e-5)
    # the compliance shows: the host moves more near resonance than with a rigid device
    rigid = tj.frequency_response(system.replace(terminal_mass=2.0), omegas, [amplitude])
    assert float(response.x_max[0, 2]) > 1.1 * float(rigid.x_max[0, 2])


def test_frictionless_compliant_response_is_the_linear_receptance(system):
    compliant = system.replace(friction_force=0.0, parasitic_damping=300.0, **COMPLIANT)
    omegas = np.linspace(0.7, 1.3, 7) * float(system.host_frequency)
    response = tj.frequency_response(compliant, omegas, [500.0])
    receptance = tj.linear_receptance(compliant, omegas)  # tested against a matrix solve
    np.testing.assert_allclose(np.asarray(response.x_max[0]),
                               500.0 * np.abs(np.asarray(receptance.host)), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(response.y_max[0]),
                               500.0 * np.abs(np.asarray(receptance.inerter)), rtol=1e-6)


def test_stiff_series_spring_tends_to_the_rigid_device(system):
    # The series spring's compliance moves the orbit by O(1 / ks): ten times stiffer, a
    # tenth of the change, and Richardson's extrapolation of ks = 1e7 and 1e8 N/m (the
    # terminal's mode 90 and 280 times the forcing frequency) is the rigid device.
    omegas = np.array([0.95, 1.05]) * float(system.host_frequency)
    rigid = tj.frequency_response(system.replace(terminal_mass=2.0), omegas, [400.0])
    soft, stiff = (tj.frequency_response(system.replace(terminal_mass=2.0, series_stiffness=ks),
                                         omegas, [400.0]) for ks in (1e7, 1e8))
    for field in ("x_max", "y_max"):
        exact, a, b = (np.asarray(getattr(r, field)) for r in (rigid, soft, stiff))
        change = b / exact - 1
        assert np.all(np.abs(change) > 1e-4) and np.all(np.abs(change) < 1e-2), field
        np.testing.assert_allclose((a / exact - 1) / change, 10.0, rtol=0.05, err_msg=field)
        np.testing.assert_allclose((10 * b - a) / 9, exact, rtol=2e-5, err_msg=field)


def _minimax_of_receptance(system, band):
    """Independent: the (k, c) minimising the peak host receptance of the frictionless
    compliant TID over the band, by Nelder-Mead on a fine grid (3 x 3 dynamic stiffness
    of host, terminal and mechanism, numpy), and that peak over A / K."""
    from scipy.optimize import minimize

    M, K, C, b, cp, mt, ks = (float(getattr(system, n)) for n in (
        "host_mass", "host_stiffness", "host_damping", "inertance", "parasitic_damping",
        "terminal_mass", "series_stiffness"))
    w = np.linspace(band[0], band[-1], 20001)
    jw = 1j * w

    def peak(log_kc):
        k, c = np.exp(log_kc)
        s = k + jw * c
        zero = np.zeros_like(w)
        matrix = np.moveaxis(np.array([
            [K - M * w**2 + jw * C + s, -s, zero],
            [-s, s + ks - mt * w**2, -ks + zero],
            [zero, -ks + zero, ks - b * w**2 + jw * cp]]), -1, 0)
        x = np.linalg.solve(matrix, np.broadcast_to([1.0, 0.0, 0.0], (w.size, 3))[..., None])
        h = np.abs(x[:, 0, 0]) * K
        i = int(np.argmax(h))
        left, mid, right = h[i - 1], h[i], h[i + 1]
        return mid - (right - left) ** 2 / (8 * (left - 2 * mid + right))

    start = np.log([float(system.tid_stiffness), float(system.tid_damping)])
    found = minimize(peak, start, method="Nelder-Mead",
                     options=dict(xatol=1e-7, fatol=1e-11, maxiter=4000))
    return np.exp(found.x), found.fun


@pytest.fixture(scope="module")
def frictionless_compliant(system):
    """The frictionless compliant TID, a band about its peaks and the minimax of its
    linear receptance over the band (`_minimax_of_receptance`)."""
    compliant = system.replace(friction_force=0.0, **COMPLIANT)
    band = np.linspace(0.8, 1.25, 21) * float(system.host_frequency)
    return compliant, band, *_minimax_of_receptance(compliant, band)


def test_retune_of_a_frictionless_compliant_device_is_the_minimax(system,
                                                                  frictionless_compliant):
    # Without friction the retuned design is the minimax of the linear receptance.
    compliant, band, (k, c), peak = frictionless_compliant
    result = tj.retune(compliant, [1000.0], omegas=band, tol=1e-6)
    assert bool(result.converged[0])
    static = 1000.0 / float(system.host_stiffness)
    assert float(result.x_peak[0]) / static == pytest.approx(peak, rel=2e-5)
    assert float(result.tid_stiffness[0]) == pytest.approx(k, rel=1e-3)
    ideal_k = hinf.h_infinity_optimum(*(float(getattr(system, name)) for name in (
        "host_mass", "host_stiffness", "host_damping", "inertance")))[0]
    assert k / ideal_k - 1 > 0.05  # the compliance stiffens the optimal spring


def test_robust_design_of_a_frictionless_compliant_device_is_the_minimax(
        system, frictionless_compliant):
    # Without friction the response scales with the amplitude: one tuning is best at every
    # amplitude, the minimax of the linear receptance, and the robust design is it.
    compliant, band, (k, c), peak = frictionless_compliant
    design = tj.robust_tune(compliant, [500.0, 1000.0], omegas=band, stroke_limit=None)
    assert bool(design.converged)
    np.testing.assert_allclose(np.asarray(design.best.tid_stiffness), k, rtol=1e-4)
    np.testing.assert_allclose(np.asarray(design.best.tid_damping), c, rtol=1e-4)
    # The robust design judges peaks on the band's grid (parabola-refined): its true peak,
    # on a fine grid of the receptance, is within 5e-4 of the minimax.
    tuned = compliant.replace(tid_stiffness=float(design.tid_stiffness),
                              tid_damping=float(design.tid_damping))
    fine = np.linspace(band[0], band[-1], 20001)
    host = np.abs(np.asarray(tj.linear_receptance(tuned, fine).host))
    assert float(np.max(host)) * float(system.host_stiffness) / peak - 1 < 5e-4
    assert float(design.tid_stiffness) == pytest.approx(k, rel=2e-3)


@pytest.mark.parametrize(("device", "message"), [
    (dict(series_stiffness=3e5), "needs terminal_mass > 0 with a compliant device"),
    (dict(COMPLIANT, friction_width=0.0), "compliant device with smoothed friction only"),
])
def test_compliant_device_needs_a_terminal_mass_and_smoothed_friction(system, band, device,
                                                                       message):
    compliant = system.replace(**device)
    calls = {
        "frequency_response": lambda: tj.frequency_response(compliant, band, [400.0]),
        "retune": lambda: tj.retune(compliant, [400.0], omegas=band),
        "sensitivities": lambda: tj.sensitivities(compliant, 400.0, omegas=band),
        "best_tunings": lambda: tj.best_tunings(compliant, [400.0], omegas=band),
        "robust_tune": lambda: tj.robust_tune(compliant, [400.0], omegas=band),
    }
    for name, call in calls.items():
        with pytest.raises(ValueError, match=f"{name} .*{message}"):
            call()
