"""Independent steady-state reference for the host + TID with a compliant inerter device
(SI units, SciPy; nothing here imports ``tid_jax``).

Model: the host x, the device's terminal y (mass mt), and its mechanism q (inertance b,
parasitic damping cp, dry friction ff smoothed as tanh(q' / eps)), joined to the terminal
by a series spring ks with a total free play g (a dead zone of half-width g / 2)::

    M x'' + C x' + K x + c (x' - y') + k (x - y) = A sin(omega t)
    mt y'' + c (y' - x') + k (y - x) + ks D(y - q) = 0
    b q'' + cp q' + ff tanh(q' / eps) = ks D(y - q)

Integrated in time (not in phase) with SciPy's explicit DOP853 at tight tolerances (the
friction's stiffness ff / (b eps), a few thousand per second here, does not limit its
steps: it matches Radau's peaks to 1e-10 at a tenth of the time), period after period from
the frictionless linear steady state (a 3 x 3 complex solve), until two successive
periods' states agree; the peaks are the largest |x| and |y| over 4096 samples of the
dense output of the last period.
"""

import math

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["compliant_peaks"]


def _dead_zone(d, gap):
    return np.sign(d) * np.maximum(np.abs(d) - 0.5 * gap, 0.0)


def compliant_peaks(case: dict, *, rtol: float = 1e-10, max_periods: int = 600,
                    tol: float = 1e-9) -> dict:
    """Steady-state peaks of one case: ``case`` holds host_mass, host_stiffness,
    host_damping, inertance, friction_force, tid_stiffness, tid_damping,
    parasitic_damping, terminal_mass, series_stiffness, backlash, friction_width (eps,
    m/s), omega (rad/s) and amplitude (N). Returns ``x_max``, ``y_max`` (m),
    ``converged`` and ``periods``."""
    M, K, C = case["host_mass"], case["host_stiffness"], case["host_damping"]
    b, ff, k, c = case["inertance"], case["friction_force"], case["tid_stiffness"], \
        case["tid_damping"]
    cp, mt, ks, g = case["parasitic_damping"], case["terminal_mass"], \
        case["series_stiffness"], case["backlash"]
    eps, omega, A = case["friction_width"], case["omega"], case["amplitude"]

    def rhs(t, s):
        x, v, y, w, q, u = s
        tid = c * (v - w) + k * (x - y)
        series = ks * _dead_zone(y - q, g)
        return [v, (A * math.sin(omega * t) - C * v - K * x - tid) / M,
                w, (tid - series) / mt,
                u, (series - cp * u - ff * math.tanh(u / eps)) / b]

    period = 2 * math.pi / omega
    scale = A / K
    jw = 1j * omega
    tid = k + jw * c
    stiffness = np.array([[K - M * omega**2 + jw * C + tid, -tid, 0.0],
                          [-tid, tid + ks - mt * omega**2, -ks],
                          [0.0, -ks, ks - b * omega**2 + jw * cp]])
    amplitudes = np.linalg.solve(stiffness, np.array([A, 0.0, 0.0]))  # x = Im(X e^{iwt})
    state = np.ravel([[z.imag, (jw * z).imag] for z in amplitudes])
    t0 = 0.0
    atol = rtol * scale * np.array([1, omega] * 3)
    for periods in range(1, max_periods + 1):
        sol = solve_ivp(rhs, (t0, t0 + period), state, method="DOP853", rtol=rtol,
                        atol=atol)
        new = sol.y[:, -1]
        change = np.max(np.abs(new - state) / (scale * np.array([1, omega] * 3)))
        start, state, t0 = state, new, t0 + period
        if change < tol:
            break
    # the last period again, the same steps, with its dense output
    sol = solve_ivp(rhs, (t0 - period, t0), start, method="DOP853", rtol=rtol, atol=atol,
                    dense_output=True)
    ts = np.linspace(t0 - period, t0, 4096, endpoint=False)
    xs, _, ys, *_ = sol.sol(ts)
    return dict(x_max=float(np.max(np.abs(xs))), y_max=float(np.max(np.abs(ys))),
                converged=bool(change < tol), periods=periods)
