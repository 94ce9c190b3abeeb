"""Checks of the independent Coulomb-friction reference solver against theory (SI units)."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

try:
    from reference.coulomb import coulomb_steady_state, paper_parameters
except ImportError:  # tests/ imported as a package
    from tests.reference.coulomb import coulomb_steady_state, paper_parameters

P = paper_parameters()
M, K, C = P["host_mass"], P["host_stiffness"], P["host_damping"]
B, FF = P["inertance"], P["friction_force"]
KT, CT = P["tid_stiffness"], P["tid_damping"]
W0 = 2.0 * math.pi * 4.0


def test_paper_parameters():
    assert K == pytest.approx(1500.0 * (8.0 * math.pi) ** 2)
    assert KT == pytest.approx(42.97e3, rel=1e-3)
    assert CT == pytest.approx(479.0, rel=2e-3)
    assert B == 75.0 and FF == 20.0


@pytest.mark.parametrize("ratio", [0.7, 0.9, 1.0, 1.05, 1.3])
def test_frictionless_matches_linear_frf(ratio):
    w = ratio * W0
    A = 150.0
    res = coulomb_steady_state(**dict(P, friction_force=0.0), omega=w, amplitude=A)
    zt = KT + 1j * w * CT
    x_over_f = 1.0 / (K - M * w**2 + 1j * w * C + zt * (-B * w**2) / (KT - B * w**2 + 1j * w * CT))
    y_over_x = zt / (KT - B * w**2 + 1j * w * CT)
    assert res["converged"]
    assert res["stick_fraction"] == 0.0
    assert res["x_max"] == pytest.approx(A * abs(x_over_f), rel=1e-6)
    assert res["y_max"] == pytest.approx(A * abs(x_over_f * y_over_x), rel=1e-6)


@pytest.mark.parametrize("ratio", [0.7, 1.0, 1.3])
def test_large_friction_sticks_whole_period(ratio):
    w = ratio * W0
    A = 100.0
    res = coulomb_steady_state(**dict(P, friction_force=1e4), omega=w, amplitude=A)
    assert res["converged"]
    assert res["stick_fraction"] == 1.0
    expected = A / abs(K + KT - M * w**2 + 1j * w * (C + CT))
    assert res["x_max"] == pytest.approx(expected, rel=1e-6)


def test_stick_slip_energy_balance():
    # paper system: with A = 200 N the terminal slips throughout for 0.88..1.14 x 4 Hz and
    # stick-slips on either side; A = 100 N at 1.1 x 4 Hz sticks ~26 % of the period.
    for ratio, A in ((0.85, 200.0), (1.2, 200.0), (1.1, 100.0)):
        w = ratio * W0
        res = coulomb_steady_state(**P, omega=w, amplitude=A)
        assert res["converged"]
        assert 0.0 < res["stick_fraction"] < 1.0
        t, v, w_ = res["t"], res["v"], res["w"]
        assert t[0] == 0.0 and t[-1] == pytest.approx(2.0 * math.pi / w, rel=1e-14)
        power_in = A * np.sin(w * t) * v
        power_out = C * v**2 + CT * (v - w_) ** 2 + FF * np.abs(w_)
        work = np.trapezoid(power_in, t)
        dissipated = np.trapezoid(power_out, t)
        assert work > 0.0
        assert dissipated == pytest.approx(work, rel=1e-4)
        friction = np.trapezoid(FF * np.abs(w_), t)
        assert friction > 0.0


def test_stick_slip_paper_200N_near_4Hz():
    # paper system, A = 200 N just below 4 Hz (0.85 x 4 Hz): stick-slip orbit
    res = coulomb_steady_state(**P, omega=0.85 * W0, amplitude=200.0)
    assert res["converged"]
    assert 0.0 < res["stick_fraction"] < 1.0
    assert res["residual"] < 1e-9
    # x_max consistent with the dense trajectory, and y is constant while stuck
    assert res["x_max"] >= np.max(np.abs(res["x"])) * (1.0 - 1e-12)
    assert res["x_max"] == pytest.approx(np.max(np.abs(res["x"])), rel=1e-4)
    assert res["y_max"] == pytest.approx(np.max(np.abs(res["y"])), rel=1e-12)


def _rhs_period_ivp(z0, w, A):
    """Independent solve_ivp event integration of one forcing period from z0."""
    T = 2.0 * math.pi / w
    t, z = 0.0, np.array(z0, float)

    def force(z):
        return CT * (z[1] - z[3]) + KT * (z[0] - z[2])

    def mode_at(t, z):
        if z[3] != 0.0:
            return int(np.sign(z[3]))
        F = force(z)
        acc = (A * math.sin(w * t) - (C + CT) * z[1] - (K + KT) * z[0] + KT * z[2]) / M
        dF = CT * acc + KT * z[1]
        if abs(F) > FF * (1 - 1e-9) and np.sign(dF) == np.sign(F):
            return int(np.sign(F))
        return 0

    mode = mode_at(t, z)
    xs = []
    while t < T * (1 - 1e-13):
        if mode == 0:
            ys = z[2]

            def f(t, u, ys=ys):
                return [u[1], (A * math.sin(w * t) - (C + CT) * u[1] - (K + KT) * u[0] + KT * ys) / M]

            def e1(t, u, ys=ys):
                return CT * u[1] + KT * (u[0] - ys) - FF

            def e2(t, u, ys=ys):
                return -(CT * u[1] + KT * (u[0] - ys)) - FF

            for e in (e1, e2):
                e.terminal, e.direction = True, 1
            sol = solve_ivp(f, (t, T), z[:2], method="DOP853", rtol=1e-12, atol=1e-15,
                            events=(e1, e2), dense_output=True)
            xs.append(sol.sol(np.linspace(t, sol.t[-1], 2000))[0])
            t, z = sol.t[-1], np.array([sol.y[0, -1], sol.y[1, -1], ys, 0.0])
            if sol.status == 1:
                mode = 1 if len(sol.t_events[0]) else -1
        else:
            s = mode

            def f(t, u, s=s):
                x, v, y, wy = u
                fs = CT * (v - wy) + KT * (x - y)
                return [v, (A * math.sin(w * t) - C * v - K * x - fs) / M, wy, (fs - FF * s) / B]

            def ev(t, u):
                return u[3]

            ev.terminal, ev.direction = True, -s
            sol = solve_ivp(f, (t, T), z, method="DOP853", rtol=1e-12, atol=1e-15,
                            events=(ev,), dense_output=True, first_step=1e-6)
            xs.append(sol.sol(np.linspace(t, sol.t[-1], 2000))[0])
            t, z = sol.t[-1], sol.y[:, -1].copy()
            if sol.status == 1:
                z[3] = 0.0
                mode = mode_at(t, z)
    return z, np.concatenate(xs)


def test_fixed_point_against_solve_ivp():
    w, A = 1.1 * W0, 100.0
    res = coulomb_steady_state(**P, omega=w, amplitude=A)
    assert 0.0 < res["stick_fraction"] < 1.0
    z0 = res["state0"]
    z1, xs = _rhs_period_ivp(z0, w, A)
    scale = np.array([1.0, w, 1.0, w]) * res["x_max"]
    assert np.max(np.abs(z1 - z0) / scale) < 1e-8
    assert np.max(np.abs(xs)) == pytest.approx(res["x_max"], rel=1e-6)


@pytest.mark.parametrize("omega,amplitude", [(0.0, 1.0), (-1.0, 1.0), (10.0, 0.0), (10.0, -5.0)])
def test_invalid_inputs(omega, amplitude):
    with pytest.raises(ValueError):
        coulomb_steady_state(**P, omega=omega, amplitude=amplitude)
