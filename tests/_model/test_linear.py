import math

import numpy as np
import pytest

import tid_jax as tj
from tid_jax._model._system import FIELD_NAMES


def test_den_hartog_paper_numbers():
    alpha, xi = tj.den_hartog(0.05)
    assert float(alpha) == pytest.approx(1 / 1.05**2, rel=1e-14)
    assert float(alpha) == pytest.approx(0.907, abs=5e-4)
    assert float(xi) == pytest.approx(0.134, abs=5e-4)
    system = tj.paper_system()
    k, c = tj.den_hartog_tuning(system.host_mass, system.host_stiffness, system.inertance)
    assert float(k) == pytest.approx(42.97e3, abs=5.0)
    assert float(c) == pytest.approx(0.479e3, abs=1.0)
    assert float(system.tid_stiffness) == float(k)
    assert float(system.host_stiffness) == pytest.approx(947.5e3, rel=1e-4)
    assert float(system.host_damping) == pytest.approx(2 * 0.02 * math.sqrt(947482.0 * 1500), rel=1e-5)


def _direct_receptance(system, omega):
    # Independent check: solve the 2x2 complex dynamic-stiffness system of eq. (12), ff = 0.
    M, K, C, b, k, c = (float(getattr(system, n)) for n in
                        ("host_mass", "host_stiffness", "host_damping", "inertance",
                         "tid_stiffness", "tid_damping"))
    jw = 1j * omega
    D = np.array([[K + k - M * omega**2 + jw * (C + c), -(k + jw * c)],
                  [-(k + jw * c), k - b * omega**2 + jw * c]])
    return np.linalg.solve(D, np.array([1.0, 0.0]))


@pytest.mark.parametrize("ratio", [0.5, 0.9, 1.0, 1.07, 2.0])
def test_receptance_matches_direct_solution(ratio):
    system = tj.paper_system()
    omega = ratio * float(system.host_frequency)
    host, inerter = tj.linear_receptance(system, omega)
    expected = _direct_receptance(system, omega)
    assert complex(host) == pytest.approx(expected[0], rel=1e-12)
    assert complex(inerter) == pytest.approx(expected[1], rel=1e-12)


def _linear_peak(system):
    omegas = np.linspace(0.6, 1.4, 400001) * float(system.host_frequency)
    return float(np.max(np.abs(tj.linear_receptance(system, omegas).host))) * float(
        system.host_stiffness
    )


def test_linear_peaks_with_den_hartog_tuning():
    system = tj.paper_system()
    assert _linear_peak(system) == pytest.approx(5.433, abs=1e-3)
    assert _linear_peak(system.replace(host_damping=0.0)) == pytest.approx(6.408, abs=1e-3)


def test_stuck_receptance_is_sdof():
    system = tj.paper_system()
    omega = 25.0
    expected = 1 / (947482.0225045783 + float(system.tid_stiffness) - 1500 * omega**2
                    + 1j * omega * (float(system.host_damping) + float(system.tid_damping)))
    assert complex(tj.stuck_receptance(system, omega)) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("field", FIELD_NAMES)
@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf")])
def test_system_rejects_bad_values(field, bad):
    if field == "series_stiffness" and bad == float("inf"):
        assert tj.paper_system().replace(series_stiffness=bad).rigid  # inf: rigid
        return
    with pytest.raises(ValueError, match=field):
        tj.paper_system().replace(**{field: bad})


def test_device_terms_default_to_the_ideal_inerter():
    system = tj.paper_system()
    assert float(system.parasitic_damping) == 0.0
    assert float(system.terminal_mass) == 0.0
    assert float(system.backlash) == 0.0
    assert system.rigid and float(system.series_stiffness) == math.inf
    assert system.to_dict()["series_stiffness"] is None  # rigid: JSON/TOML leave it out
    assert tj.TIDSystem(**system.to_dict()).rigid
    assert not system.replace(series_stiffness=3e5).rigid
    with pytest.raises(ValueError, match="backlash needs a finite series_stiffness"):
        system.replace(backlash=1e-4)
    with pytest.raises(ValueError, match="series_stiffness must be positive"):
        system.replace(series_stiffness=0.0)


def _direct_device_receptance(system, omega):
    """Independent: the 3 x 3 dynamic stiffness of host x, terminal y (mass mt) and
    mechanism q (inertance b, damping cp to ground) joined by the spring ks, solved for a
    unit force on the host; the rigid device as the 2 x 2 of y = q."""
    M, K, C, b, k, c, cp, mt, ks = (float(getattr(system, n)) for n in (
        "host_mass", "host_stiffness", "host_damping", "inertance", "tid_stiffness",
        "tid_damping", "parasitic_damping", "terminal_mass", "series_stiffness"))
    jw = 1j * omega
    s = k + jw * c
    if math.isinf(ks):
        D = np.array([[K - M * omega**2 + jw * C + s, -s],
                      [-s, s - (b + mt) * omega**2 + jw * cp]])
        return np.linalg.solve(D, np.array([1.0, 0.0]))
    D = np.array([[K - M * omega**2 + jw * C + s, -s, 0.0],
                  [-s, s + ks - mt * omega**2, -ks],
                  [0.0, -ks, ks - b * omega**2 + jw * cp]])
    return np.linalg.solve(D, np.array([1.0, 0.0, 0.0]))[:2]


@pytest.mark.parametrize("device", [
    dict(parasitic_damping=300.0),
    dict(terminal_mass=2.0),
    dict(series_stiffness=3e5),
    dict(parasitic_damping=300.0, terminal_mass=2.0, series_stiffness=3e5, backlash=1e-4),
])
@pytest.mark.parametrize("ratio", [0.5, 0.9, 1.0, 1.07, 2.0, 6.0])
def test_device_receptance_matches_matrix_solution(device, ratio):
    system = tj.paper_system().replace(**device)
    omega = ratio * float(system.host_frequency)
    host, inerter = tj.linear_receptance(system, omega)
    expected = _direct_device_receptance(system, omega)
    assert complex(host) == pytest.approx(expected[0], rel=1e-11)
    assert complex(inerter) == pytest.approx(expected[1], rel=1e-11)
    ideal = tj.linear_receptance(tj.paper_system(), omega).inerter
    assert abs(complex(inerter) / complex(ideal) - 1) > 1e-3  # the device term shows


@pytest.mark.parametrize("field", ["host_mass", "host_stiffness", "inertance", "tid_stiffness"])
def test_system_rejects_zero_where_positive_required(field):
    with pytest.raises(ValueError, match=f"{field} must be finite and positive, got 0.0"):
        tj.paper_system().replace(**{field: 0.0})


@pytest.mark.parametrize("field", ["host_damping", "friction_force", "tid_damping",
                                   "friction_width"])
def test_system_accepts_zero_where_allowed(field):
    system = tj.paper_system(friction_width=1e-4).replace(**{field: 0.0})
    assert float(getattr(system, field)) == 0.0
    assert system.exact_friction == (field == "friction_width")  # 0: exact Coulomb friction


def test_system_rejects_non_numbers():
    with pytest.raises(ValueError, match="inertance"):
        tj.paper_system().replace(inertance="heavy")
    with pytest.raises(ValueError, match="unknown TIDSystem field"):
        tj.paper_system().replace(mass=1.0)


def _breakaway_numpy(system, omega):
    """Independent: the amplitude A at which the force of the spring and damper on the
    stuck terminal, (k + i w c) X with X = A / (K + k - M w^2 + i w (C + c)), reaches ff."""
    M, K, C, ff, k, c = (float(getattr(system, n)) for n in
                         ("host_mass", "host_stiffness", "host_damping", "friction_force",
                          "tid_stiffness", "tid_damping"))
    x_per_newton = 1 / (K + k - M * omega**2 + 1j * omega * (C + c))
    return ff / np.abs((k + 1j * omega * c) * x_per_newton)


@pytest.mark.parametrize(
    ("band_hz", "damping"), [((2.0, 6.0), None), ((2.0, 6.0), 0.0), ((4.5, 6.0), None)]
)
def test_breakaway_amplitude_and_its_exact_minimum(band_hz, damping):
    from scipy.optimize import minimize_scalar

    system = tj.paper_system()
    if damping is not None:
        system = system.replace(tid_damping=damping)
    omegas = 2 * np.pi * np.linspace(*band_hz, 41)
    result = tj.breakaway_amplitude(system, omegas)
    np.testing.assert_allclose(result.amplitude, _breakaway_numpy(system, omegas), rtol=1e-12)
    found = minimize_scalar(lambda w: _breakaway_numpy(system, w), bounds=tuple(omegas[[0, -1]]),
                            method="bounded", options={"xatol": 1e-10})
    assert float(result.minimum) <= float(np.min(result.amplitude))
    if band_hz[0] > 4.2:  # above the stuck host's resonance: the band's lower end
        assert float(result.omega_minimum) == pytest.approx(omegas[0], rel=1e-12)
        assert float(result.minimum) == pytest.approx(_breakaway_numpy(system, omegas[0]),
                                                      rel=1e-12)
    else:
        assert float(result.minimum) == pytest.approx(found.fun, rel=1e-10)
        assert float(result.omega_minimum) == pytest.approx(found.x, rel=1e-6)


def test_breakaway_separates_stuck_from_slipping_steady_states():
    # The smoothed model's steady states, from the linear steady state after a transient:
    # just below the breakaway amplitude the inerter stays stuck (creeping within two
    # friction widths) all period; just above it slips for part of it.
    system = tj.paper_system()
    omegas = 2 * np.pi * np.array([3.5, 4.09, 4.6])
    breakaway = np.asarray(tj.breakaway_amplitude(system, omegas).amplitude)
    for factor, stuck in ((0.9, True), (1.05, False)):
        for omega, amplitude in zip(omegas, breakaway, strict=True):
            response = tj.frequency_response(system, omega, factor * amplitude)
            assert bool(response.converged)
            assert (float(response.stick_fraction) == 1.0) == stuck, (factor, omega)
    # The paper's smallest amplitude, 100 N, is above the band's minimum (about 23 N).
    assert 20.0 < float(tj.breakaway_amplitude(system, omegas).minimum) < 25.0


def test_breakaway_bad_input():
    with pytest.raises(ValueError, match="omegas"):
        tj.breakaway_amplitude(tj.paper_system(), [10.0, -1.0])
    with pytest.raises(ValueError, match="system"):
        tj.breakaway_amplitude("paper", [10.0])
