"""Stationary random loads without friction, against independent answers: the variance
of a single oscillator under white noise (pi S0 / (k c)), the H2 integral of the
reference receptance (`reference/building_linear.py`) over the loads' spectra
(numerical quadrature), and Warburton's closed-form H2 optimum of the tuned mass damper,
which holds for the TID with mu = b / M."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

import tid_jax as tj
from tests._model.test_building import MASSES, STIFFNESSES, B, _matrices
from tests.reference import building_linear
from tid_jax._loads._stationary import lyapunov

STRUCTURE = tj.Structure.shear_building(MASSES, STIFFNESSES, damping_ratio=0.02)
FIRST = float(STRUCTURE.modes()[0][0])
LOADS = {
    "white_noise": tj.StationaryLoad("white_noise", 2.0),
    "kanai_tajimi": tj.StationaryLoad("kanai_tajimi", 0.01, ground_frequency=2 * FIRST,
                                      ground_damping=0.4),
    "clough_penzien": tj.StationaryLoad("clough_penzien", 0.01, ground_frequency=2 * FIRST,
                                        ground_damping=0.4, filter_frequency=0.3 * FIRST,
                                        filter_damping=0.6),
}


def test_a_single_oscillator_has_variance_pi_s0_over_k_c():
    m, c, k, s0 = 3.0, 0.7, 50.0, 0.2
    A = np.array([[0.0, 1.0], [-k / m, -c / m]])
    B = np.array([0.0, 1.0 / m])
    P = np.asarray(lyapunov(A, 2 * math.pi * s0 * np.outer(B, B)))
    assert P[0, 0] == pytest.approx(math.pi * s0 / (k * c), rel=1e-12)
    assert P[1, 1] == pytest.approx(math.pi * s0 / (m * c), rel=1e-12)


@pytest.mark.parametrize("kind", sorted(LOADS))
def test_filters_have_the_closed_form_spectra(kind):
    load = LOADS[kind]
    F, f, h, d = (np.asarray(a) for a in load.filter())
    omegas = FIRST * np.array([0.01, 0.3, 1.0, 2.0, 7.0])
    gain = np.array([h @ np.linalg.solve(1j * w * np.eye(F.shape[0]) - F, f) + d
                     if F.size else d for w in omegas])
    np.testing.assert_allclose(float(load.psd) * np.abs(gain) ** 2, load.spectrum(omegas),
                               rtol=1e-12)


CASES = [  # load, on, quantity kind, floor, spring floor, inerter floor
    ("white_noise", "force", "drift", 2, 3, 1),
    ("white_noise", "ground", "displacement", 3, 1, 0),
    ("kanai_tajimi", "ground", "displacement", 3, 1, 0),
    ("kanai_tajimi", "ground", "acceleration", 2, 2, 3),
    ("clough_penzien", "ground", "drift", 1, 1, 0),
]


@pytest.mark.parametrize("case", CASES)
def test_lyapunov_variance_is_the_h2_integral_of_the_receptance(case):
    kind, on, quantity, floor, j, i = case
    load = LOADS[kind]
    system = tj.BuildingTID(STRUCTURE, B, 0.0, 4e4, 500.0, spring_floor=j, inerter_floor=i,
                            load=on, terminal_mass=10.0, parasitic_damping=30.0)
    rms = float(tj.rms_response(system, load, tj.Quantity(quantity, floor)))
    M, K, C = _matrices(STRUCTURE)

    def density(w):
        gain = building_linear.response_amplitude(
            w, M, K, C, b=B, k=4e4, c=500.0, spring_floor=j, inerter_floor=i, load=on,
            kind=quantity, floor=floor, cp=30.0, mt=10.0)
        return float(gain) ** 2 * float(load.spectrum(w))

    modes = list(np.asarray(STRUCTURE.modes()[0]))
    top = 4 * max(modes)
    near = quad(density, 0.0, top, points=modes + [FIRST * 0.9, FIRST * 1.1], limit=800,
                epsabs=0.0, epsrel=1e-10)[0]
    far = quad(density, top, np.inf, limit=200, epsabs=0.0, epsrel=1e-10)[0]
    assert rms**2 == pytest.approx(2 * (near + far), rel=1e-7)


@pytest.mark.parametrize("on", ["force", "ground"])
def test_h2_tuning_is_warburton_s_optimum(system, on):
    # The TID under a force (or a ground acceleration, the relative displacement) with an
    # undamped host is the tuned mass damper with absorber mass b (Warburton 1982).
    host = tj.as_building(system.replace(host_damping=0.0, friction_force=0.0), on)
    mu = float(system.inertance / system.host_mass)
    k, c = tj.h2_tuning(host, tj.StationaryLoad("white_noise", 1.0))
    b = float(system.inertance)
    natural = math.sqrt(float(system.host_stiffness / system.host_mass))
    ratio = math.sqrt(k / b) / natural
    damping = c / (2 * math.sqrt(k * b))
    assert ratio == pytest.approx(math.sqrt(1 + mu / 2) / (1 + mu), rel=1e-5)
    assert damping == pytest.approx(math.sqrt(mu * (1 + 3 * mu / 4)
                                              / (4 * (1 + mu) * (1 + mu / 2))), rel=1e-5)


@pytest.mark.parametrize("args, message", [
    (("wind", 1.0), "load kind"),
    (("white_noise", -1.0), "psd"),
    (("kanai_tajimi", 1.0), "ground_frequency"),
    (("white_noise", 1.0, 10.0), "does not apply"),
])
def test_bad_loads_name_the_input(args, message):
    with pytest.raises(ValueError, match=message):
        tj.StationaryLoad(*args)


def test_white_noise_acceleration_is_refused():
    system = tj.BuildingTID(STRUCTURE, B, 0.0, 4e4, 500.0, load="ground")
    with pytest.raises(ValueError, match="infinite variance"):
        tj.rms_response(system, LOADS["white_noise"], tj.Quantity("acceleration", 3))


def _stroke_velocity_rms(system, load, damping):
    """The stroke's RMS velocity of the paper's host with `damping` added on the stroke:
    quadrature of the reference receptance (`building_linear`) over the load's spectrum."""
    M, K, C = ([[float(v)]] for v in (system.host_mass, system.host_stiffness,
                                      system.host_damping))
    natural = math.sqrt(float(system.host_stiffness / system.host_mass))

    def density(w):
        gain = building_linear.response_amplitude(
            w, M, K, C, b=float(system.inertance), k=float(system.tid_stiffness),
            c=float(system.tid_damping), spring_floor=1, inerter_floor=0, kind="stroke",
            cp=float(system.parasitic_damping) + damping)
        return (w * float(gain)) ** 2 * float(load.spectrum(w))

    near = quad(density, 0.0, 6 * natural, points=[0.9 * natural, natural, 1.1 * natural],
                limit=800, epsabs=0.0, epsrel=1e-11)[0]
    far = quad(density, 6 * natural, np.inf, limit=200, epsabs=0.0, epsrel=1e-11)[0]
    return math.sqrt(2 * (near + far))


@pytest.mark.parametrize("psd", [100.0, 1000.0])
def test_statistical_linearisation_is_the_fixed_point_of_the_receptance(system, psd):
    # Caughey's c_eq = ff sqrt(2/pi) / sigma_v, sigma_v the stroke's RMS velocity with
    # c_eq on the stroke: the fixed point found on the reference receptance by brentq
    from scipy.optimize import brentq

    load = tj.StationaryLoad("white_noise", psd)
    result = tj.statistical_linearisation(tj.as_building(system), load)
    assert not result.locked
    kappa = float(system.friction_force) * math.sqrt(2 / math.pi)
    sigma = float(result.velocity_rms)
    gap = lambda s: math.log(_stroke_velocity_rms(system, load, kappa / math.exp(s))) - s
    root = brentq(gap, math.log(sigma) - 0.5, math.log(sigma) + 0.5, xtol=1e-13)
    assert sigma == pytest.approx(math.exp(root), rel=1e-7)
    assert float(result.friction_damping) == pytest.approx(kappa / sigma, rel=1e-12)


def test_statistical_linearisation_locks_under_weak_loads(system):
    # under a weak load the spring and damper's force stays below what the linearised
    # friction holds: no self-consistent slipping solution
    weak = tj.statistical_linearisation(tj.as_building(system),
                                        tj.StationaryLoad("white_noise", 1.0))
    assert weak.locked and math.isnan(float(weak.rms))
