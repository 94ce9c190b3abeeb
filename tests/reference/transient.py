"""Independent steady-state reference for the host + TID with smoothed friction (SI units).

Model::

    M x'' + C x' + K x + c (x' - y') + k (x - y) = A sin(omega t)
    b y'' + c (y' - x') + k (y - x) + ff tanh(y' / eps) = 0

The equations are integrated in scaled form (time tau = omega t, displacements over
L = A / K, velocities over omega L) with diffrax ``Kvaerno5`` and a PID controller
(atol = rtol on the scaled state), one forcing period per call of a single jitted
function of (state, parameters), so different systems share one compilation.  The
periodic state is found from the frictionless steady state by plain periods and Newton
shooting on the period map (Jacobian by forward-mode differentiation of the solve).
Peaks come from 1024 samples of the final period refined by a parabola.

Enables float64 in JAX at import.  Nothing here imports ``tid_jax``.
"""

from __future__ import annotations

import functools
import math

import jax

jax.config.update("jax_enable_x64", True)

import diffrax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

__all__ = ["transient_peaks", "linear_steady_state"]

_N_SAMPLES = 1024
_TWO_PI = 2.0 * math.pi


def linear_steady_state(case: dict) -> tuple[complex, complex]:
    """Complex amplitudes (X, Y) [m] of the frictionless steady state, x = Im(X e^{i w t})."""
    M, K, C = case["host_mass"], case["host_stiffness"], case["host_damping"]
    b, k, c = case["inertance"], case["tid_stiffness"], case["tid_damping"]
    b = b + case.get("terminal_mass", 0.0)
    w, A = case["omega"], case["amplitude"]
    Z = k + 1j * w * c
    D = k - b * w**2 + 1j * w * (c + case.get("parasitic_damping", 0.0))
    device = -b * w**2 + 1j * w * case.get("parasitic_damping", 0.0)
    X = A / (K - M * w**2 + 1j * w * C + Z * device / D)
    return complex(X), complex(Z * X / D)


def _rhs(tau, u, p):
    m, ch, ct, kt, bb, f, s, cp = p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]
    u0, u1, u2, u3 = u[0], u[1], u[2], u[3]
    fl = ct * (u1 - u3) + kt * (u0 - u2)
    a1 = (jnp.sin(tau) - ch * u1 - u0 - fl) / m
    a3 = (fl - cp * u3 - f * jnp.tanh(s * u3)) / bb
    return jnp.stack([u1, a1, u3, a3])


@functools.cache
def _solvers(rtol: float, max_steps: int):
    term = diffrax.ODETerm(_rhs)
    solver = diffrax.Kvaerno5()
    ctrl = diffrax.PIDController(rtol=rtol, atol=rtol)
    ts = jnp.linspace(0.0, _TWO_PI, _N_SAMPLES + 1)

    def solve(u, p, saveat):
        return diffrax.diffeqsolve(
            term, solver, 0.0, _TWO_PI, None, u, args=p, saveat=saveat,
            stepsize_controller=ctrl, max_steps=max_steps,
            adjoint=diffrax.ForwardMode(), throw=False,
        )

    @jax.jit
    def period_dense(u, p):
        sol = solve(u, p, diffrax.SaveAt(ts=ts))
        ok = sol.result == diffrax.RESULTS.successful
        return sol.ys, ok, sol.stats["num_steps"]

    def end(u, p):
        sol = solve(u, p, diffrax.SaveAt(t1=True))
        ok = sol.result == diffrax.RESULTS.successful
        return sol.ys[-1], ok

    @jax.jit
    def period_jac(u, p):
        J, _ = jax.jacfwd(end, has_aux=True)(u, p)
        ue, ok = end(u, p)
        return ue, J, ok

    return period_dense, period_jac


def _peak(v: np.ndarray) -> float:
    """Peak |v| of periodic samples (last sample = first) refined by a parabola."""
    w = v[:-1]
    n = len(w)
    i = int(np.argmax(np.abs(w)))
    sg = 1.0 if w[i] >= 0.0 else -1.0
    ym, y0, yp = sg * w[(i - 1) % n], sg * w[i], sg * w[(i + 1) % n]
    den = ym - 2.0 * y0 + yp
    if den < 0.0:
        return float(y0 - (yp - ym) ** 2 / (8.0 * den))
    return float(y0)


def transient_peaks(
    case: dict,
    friction_width: float,
    *,
    rtol: float = 1e-10,
    max_periods: int = 3000,
    tol: float = 1e-9,
    from_rest: bool = False,
    max_steps: int = 200_000,
) -> dict:
    """Periodic steady state of the smoothed-friction model for one case (SI units).

    ``case`` holds the seven system keys plus ``omega`` [rad/s] and ``amplitude`` [N],
    and optionally the inerter's ``parasitic_damping`` cp [N s/m] and ``terminal_mass``
    mt [kg] (default 0), which make its equation
    ``(b + mt) y'' + cp y' + c (y' - x') + k (y - x) + ff tanh(y' / eps) = 0``;
    ``friction_width`` eps [m/s] is the velocity scale of ``tanh(y'/eps)``.  Starts from
    the frictionless steady state (or from rest with ``from_rest``).

    Returns a dict with ``x_max``, ``y_max`` (peak |x|, |y| over the final period, m),
    ``converged`` (the period-boundary state repeats to ``tol`` relative and the peaks
    of two successive periods agree to ``tol``, |x| relative to itself, |y| relative to
    max(peak |x|, peak |y|) since a stuck terminal has |y| near 0), ``periods`` (period maps
    evaluated, Jacobian evaluations included), ``residual`` (relative period-map
    residual of the scaled state) and ``steps`` (solver steps in the final period).
    """
    M, K, C = float(case["host_mass"]), float(case["host_stiffness"]), float(case["host_damping"])
    b, ff = float(case["inertance"]), float(case["friction_force"])
    k, c = float(case["tid_stiffness"]), float(case["tid_damping"])
    w, A = float(case["omega"]), float(case["amplitude"])
    cp, mt = float(case.get("parasitic_damping", 0.0)), float(case.get("terminal_mass", 0.0))
    eps = float(friction_width)
    if not (eps > 0.0 and w > 0.0 and A > 0.0):
        raise ValueError("friction_width, omega and amplitude must be positive")
    L = A / K
    p = jnp.asarray([M * w * w / K, C * w / K, c * w / K, k / K, (b + mt) * w * w / K, ff / A,
                     w * L / eps, cp * w / K], dtype=jnp.float64)
    period_dense, period_jac = _solvers(float(rtol), int(max_steps))

    if from_rest:
        u = np.zeros(4)
    else:
        X, Y = linear_steady_state(case)
        u = np.array([X.imag, X.real, Y.imag, Y.real]) / L

    def rel(a, bref):
        return float(np.max(np.abs(a))) / max(float(np.max(np.abs(bref))), 1e-300)

    target = 0.1 * tol

    def newton(u, max_iter=10):
        """Newton shooting on P(u) = u; returns (best u, maps used, residual reached)."""
        used = 0
        r_now = math.inf
        for _ in range(max_iter):
            ue, J, ok = period_jac(jnp.asarray(u), p)
            used += 5
            ue, J = np.asarray(ue), np.asarray(J)
            if not bool(ok) or not np.all(np.isfinite(J)):
                break
            r = ue - u
            r_now = rel(r, ue)
            if r_now <= target:
                break
            try:
                du = np.linalg.solve(J - np.eye(4), -r)
            except np.linalg.LinAlgError:
                break
            lam, improved = 1.0, False
            for _ls in range(8):
                un = u + lam * du
                ys, ok, _ = period_dense(jnp.asarray(un), p)
                used += 1
                ys = np.asarray(ys)
                if bool(ok) and np.all(np.isfinite(ys)):
                    rn = rel(ys[-1] - un, ys[-1])
                    if rn < r_now:
                        improved = True
                        break
                lam *= 0.5
            if not improved:
                break
            u, r_now = un, rn
            if r_now <= target:
                break
        return u, used, r_now

    periods = 0
    converged = False
    prev = None
    residual = math.inf
    steps = 0
    since_newton = 0
    newton_first, newton_every = 3, 20
    peaks = (math.nan, math.nan)
    while periods < max_periods:
        ys, ok, nst = period_dense(jnp.asarray(u), p)
        periods += 1
        since_newton += 1
        ys = np.asarray(ys)
        if not bool(ok) or not np.all(np.isfinite(ys)):
            break
        steps = int(nst)
        peaks = (_peak(ys[:, 0]), _peak(ys[:, 2]))
        residual = rel(ys[-1] - u, ys[-1])
        if prev is not None:
            scale = max(abs(peaks[0]), abs(peaks[1]), 1e-300)
            dpk = max(abs(peaks[0] - prev[0]) / max(abs(peaks[0]), 1e-300),
                      abs(peaks[1] - prev[1]) / scale)
            if dpk <= tol and residual <= tol:
                converged = True
                break
        prev = peaks
        u = ys[-1]
        due = (periods == newton_first) or (since_newton >= newton_every)
        if due and residual > target:
            u, used, _ = newton(u)
            periods += used
            since_newton = 0
            prev = None
    return dict(
        x_max=peaks[0] * L,
        y_max=peaks[1] * L,
        converged=bool(converged),
        periods=int(periods),
        residual=float(residual),
        steps=steps,
    )
