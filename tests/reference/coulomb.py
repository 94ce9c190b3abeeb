"""Independent event-driven reference solver for a TID with exact Coulomb friction.

Model (Gonzalez-Buelga et al. 2017, eq. 12), SI units throughout::

    M x'' + C x' + K x + c (x' - y') + k (x - y) = A sin(omega t)
    b y'' + c (y' - x') + k (y - x) + ff sign(y') = 0

``x`` host displacement [m], ``y`` inerter-terminal displacement [m].  The friction is
exact Coulomb friction with stick: while ``y' = 0`` the terminal stays stuck as long as
the spring + damper force on it, ``F = c x' + k (x - y)`` [N], satisfies ``|F| <= ff``
(static = kinetic friction).

Method: the motion is piecewise linear time invariant.  In every phase (slip with
``sign(y') = +1``, slip with ``-1``, stick with ``y = y_stuck``) the response is written
exactly as constant + sinusoidal particular solution plus a modal (eigen-decomposed
matrix exponential) homogeneous part.  Phase-ending events (``y' = 0`` while slipping,
``|F| = ff`` while stuck) are located on a fixed grid of ``n_grid`` points per forcing
period, with a derivative test for double crossings inside one grid interval, and then
refined with ``brentq``.  The periodic steady state is found by integrating periods and
accelerating with Newton shooting on the period map (finite-difference Jacobian); a
fully stuck period is closed analytically (SDOF with ``K + k``, ``C + c``).

Pure numpy / scipy; nothing here imports ``tid_jax``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

__all__ = ["coulomb_steady_state", "paper_parameters"]

_STICK = 0


def paper_parameters() -> dict:
    """Paper system values (SI units): masses kg, stiffnesses N/m, dampings N s/m, ff N.

    Keys match the argument names of :func:`coulomb_steady_state` (without omega and
    amplitude).
    """
    M = 1500.0
    K = M * (2.0 * math.pi * 4.0) ** 2
    C = 2.0 * 0.02 * math.sqrt(K * M)
    b = 75.0
    mu = b / M
    alpha = 1.0 / (1.0 + mu) ** 2
    xi = math.sqrt(3.0 * mu / (8.0 * (1.0 + mu)))
    k = mu * alpha * K
    c = 2.0 * xi * math.sqrt(k * b)
    return dict(
        host_mass=M,
        host_stiffness=K,
        host_damping=C,
        inertance=b,
        friction_force=20.0,
        tid_stiffness=k,
        tid_damping=c,
    )


class _Modal:
    """Exact solution of z' = S z + f0 + e sin(omega t) (S fixed, f0 may vary)."""

    def __init__(self, S, e, omega):
        self.S = np.asarray(S, float)
        self.n = self.S.shape[0]
        self.e = np.asarray(e, float)
        self.omega = omega
        lam, V = np.linalg.eig(self.S)
        self.lam = lam
        self.V = V
        self.Vinv = np.linalg.inv(V)
        self.cond = np.linalg.cond(V)
        # sinusoidal particular solution: Re(Zs exp(j w t)), since sin = Re(-j exp(j w t))
        self.Zs = np.linalg.solve(1j * omega * np.eye(self.n) - self.S, -1j * self.e)
        self.Sinv = np.linalg.inv(self.S)


class _Phase:
    """One linear phase started at (t0, z0) with constant forcing vector f0."""

    __slots__ = ("m", "f0", "zc", "t0", "d")

    def __init__(self, modal: _Modal, f0, t0, z0):
        self.m = modal
        self.f0 = f0
        self.zc = -modal.Sinv @ f0
        self.t0 = t0
        self.d = modal.Vinv @ (z0 - self._zp_scalar(t0))

    def _zp_scalar(self, t):
        m = self.m
        return self.zc + (m.Zs * complex(math.cos(m.omega * t), math.sin(m.omega * t))).real

    def eval(self, t):
        """State at the times ``t`` (1-d array), shape (len(t), n)."""
        m = self.m
        t = np.asarray(t, float)
        ph = np.exp(1j * m.omega * t)
        zp = self.zc[None, :] + (ph[:, None] * m.Zs[None, :]).real
        zh = (np.exp(np.outer(t - self.t0, m.lam)) * self.d[None, :]) @ m.V.T
        return zp + zh.real

    def eval1(self, t):
        m = self.m
        zh = m.V @ (np.exp(m.lam * (t - self.t0)) * self.d)
        return self._zp_scalar(t) + zh.real

    def deriv(self, t, z):
        """Time derivative from the ODE for states ``z`` at times ``t``."""
        m = self.m
        return z @ m.S.T + self.f0[None, :] + np.sin(m.omega * np.asarray(t))[:, None] * m.e[None, :]

    def deriv1(self, t, z):
        m = self.m
        return m.S @ z + self.f0 + math.sin(m.omega * t) * m.e


class _System:
    def __init__(self, M, K, C, b, ff, k, c, omega, A, n_grid, cp=0.0):
        self.M, self.K, self.C, self.b, self.ff = M, K, C, b, ff
        self.k, self.c, self.omega, self.A = k, c, omega, A
        self.T = 2.0 * math.pi / omega
        self.grid = np.linspace(0.0, self.T, n_grid + 1)
        S4 = np.array(
            [
                [0.0, 1.0, 0.0, 0.0],
                [-(K + k) / M, -(C + c) / M, k / M, c / M],
                [0.0, 0.0, 0.0, 1.0],
                [k / b, c / b, -k / b, -(c + cp) / b],
            ]
        )
        self.slip = _Modal(S4, [0.0, A / M, 0.0, 0.0], omega)
        S2 = np.array([[0.0, 1.0], [-(K + k) / M, -(C + c) / M]])
        self.stick = _Modal(S2, [0.0, A / M], omega)
        self.f_slip = {
            +1: np.array([0.0, 0.0, 0.0, -ff / b]),
            -1: np.array([0.0, 0.0, 0.0, ff / b]),
        }

    # --- force on the inerter terminal and mode decision at y' = 0 ---------------------
    def force(self, z):
        return self.c * (z[1] - z[3]) + self.k * (z[0] - z[2])

    def decide(self, t, z):
        """Mode (+1, -1 slip; 0 stick) for a state with y' = 0 at time t."""
        M, K, C, k, c, ff = self.M, self.K, self.C, self.k, self.c, self.ff
        x, v, y = z[0], z[1], z[2]
        F = c * v + k * (x - y)
        acc = (self.A * math.sin(self.omega * t) - (C + c) * v - (K + k) * x + k * y) / M
        dF = c * acc + k * v
        tol = 1e-12 * max(ff, abs(F), 1e-300)
        if F > ff + tol or (F >= ff - tol and dF > 0.0):
            return +1
        if F < -ff - tol or (F <= -ff + tol and dF < 0.0):
            return -1
        return _STICK

    def make_phase(self, mode, t0, z):
        if mode == _STICK:
            ys = z[2]
            f0 = np.array([0.0, self.k * ys / self.M])
            return _Phase(self.stick, f0, t0, np.array([z[0], z[1]]))
        return _Phase(self.slip, self.f_slip[mode], t0, np.asarray(z, float))

    # --- one forcing period ------------------------------------------------------------
    def period(self, z0, record=False, max_events=2000):
        T = self.T
        z = np.array(z0, float)
        t = 0.0
        mode = (1 if z[3] > 0 else -1) if z[3] != 0.0 else self.decide(0.0, z)
        stick_time = 0.0
        n_events = 0
        segs = []
        ok = True
        while t < T * (1.0 - 1e-14):
            ph = self.make_phase(mode, t, z)
            times = np.concatenate(([t], self.grid[self.grid > t * (1.0 + 1e-15) + 1e-14 * T]))
            if times[-1] < T:
                times = np.append(times, T)
            Z = ph.eval(times)
            Zd = ph.deriv(times, Z)
            if mode == _STICK:
                ys = z[2]
                F = self.c * Z[:, 1] + self.k * (Z[:, 0] - ys)
                dF = self.c * Zd[:, 1] + self.k * Z[:, 1]
                scale = max(self.ff, np.max(np.abs(F)), 1e-300)

                def g_plus(tt, ph=ph, ys=ys):
                    zz = ph.eval1(tt)
                    return self.c * zz[1] + self.k * (zz[0] - ys) - self.ff

                def g_minus(tt, ph=ph, ys=ys):
                    zz = ph.eval1(tt)
                    return -(self.c * zz[1] + self.k * (zz[0] - ys)) - self.ff

                def dg_plus(tt, ph=ph):
                    zz = ph.eval1(tt)
                    zd = ph.deriv1(tt, zz)
                    return self.c * zd[1] + self.k * zz[1]

                def dg_minus(tt, ph=ph):
                    return -dg_plus(tt)

                e1 = _first_crossing(times, F - self.ff, dF, g_plus, dg_plus, 1e-12 * scale)
                e2 = _first_crossing(times, -F - self.ff, -dF, g_minus, dg_minus, 1e-12 * scale)
                te, new_mode = None, None
                if e1 is not None:
                    te, new_mode = e1, +1
                if e2 is not None and (te is None or e2 < te):
                    te, new_mode = e2, -1
            else:
                s = mode
                W = Z[:, 3]
                scale = max(np.max(np.abs(W)), np.max(np.abs(Z[:, 1])), 1e-300)

                def g(tt, ph=ph, s=s):
                    return -s * ph.eval1(tt)[3]

                def dg(tt, ph=ph, s=s):
                    zz = ph.eval1(tt)
                    return -s * ph.deriv1(tt, zz)[3]

                te = _first_crossing(times, -s * W, -s * Zd[:, 3], g, dg, 1e-13 * scale)
                new_mode = None
            if te is None:
                te = T
                zend = Z[-1].copy()
                seg_t, seg_z = times, Z
            else:
                zend = ph.eval1(te)
                keep = times < te
                seg_t = np.append(times[keep], te)
                seg_z = np.vstack((Z[keep], zend[None, :]))
            if mode == _STICK:
                stick_time += te - t
                ys = z[2]
                zend = np.array([zend[0], zend[1], ys, 0.0])
                if record:
                    seg_z = np.column_stack(
                        (seg_z[:, 0], seg_z[:, 1], np.full(len(seg_t), ys), np.zeros(len(seg_t)))
                    )
            if record:
                segs.append((mode, ph, seg_t, seg_z))
            t = te
            z = zend
            if te < T * (1.0 - 1e-14):
                n_events += 1
                if n_events > max_events:
                    ok = False
                    break
                if mode == _STICK:
                    mode = new_mode
                else:
                    z[3] = 0.0
                    mode = self.decide(t, z)
        info = dict(stick_time=stick_time, n_events=n_events, ok=ok, segs=segs)
        return z, info

    def stuck_periodic(self, ys):
        """Exact periodic state at t = 0 of a fully stuck motion with y = ys."""
        m = self.stick
        zc = -m.Sinv @ np.array([0.0, self.k * ys / self.M])
        z2 = zc + m.Zs.real
        return np.array([z2[0], z2[1], ys, 0.0])

    def linear_guess(self):
        """Steady state at t = 0 of the frictionless (ff = 0) linear system."""
        m = self.slip
        return m.Zs.real.copy()


def _first_crossing(times, G, GD, g, dg, eps):
    """First time after times[0] at which g crosses from < 0 to >= 0.

    ``G``, ``GD`` are g and g' on ``times``; ``g``, ``dg`` scalar callables.
    Returns None if there is no crossing up to times[-1].
    """
    n = len(times)
    if n < 2:
        return None
    cand1 = G[1:] >= 0.0
    cand2 = (GD[:-1] > 0.0) & (GD[1:] < 0.0)
    idx = np.nonzero(cand1 | cand2)[0]
    for i in idx:
        a, bnd = times[i], times[i + 1]
        if cand2[i]:
            # interior maximum of g within (a, b)
            try:
                tm = brentq(dg, a, bnd, xtol=1e-16 * max(bnd, 1.0), rtol=1e-15, maxiter=200)
            except ValueError:
                tm = None
            if tm is not None:
                gm = g(tm)
                if gm > eps and (i > 0 or tm - a > 1e-10 * (bnd - a)):
                    return _bracket_root(g, a, tm, i == 0)
        if cand1[i]:
            return _bracket_root(g, a, bnd, i == 0)
    return None


def _bracket_root(g, a, b, at_start):
    """Root of g in [a, b] with g(b) >= 0 and g < 0 just after a."""
    ga = g(a)
    if ga < 0.0:
        gb = g(b)
        if gb == 0.0:
            return b
        return brentq(g, a, b, xtol=1e-16 * max(b, 1.0), rtol=1e-15, maxiter=200)
    # g(a) >= 0 only through round-off at a phase start: find a point inside
    h = b - a
    for p in range(1, 50):
        tt = a + h * 2.0 ** (-50 + p)
        if g(tt) < 0.0:
            return brentq(g, tt, b, xtol=1e-16 * max(b, 1.0), rtol=1e-15, maxiter=200)
    return a


def _scaled(z, L, omega):
    return np.array([z[0] / L, z[1] / (omega * L), z[2] / L, z[3] / (omega * L)])


def coulomb_steady_state(
    host_mass,
    host_stiffness,
    host_damping,
    inertance,
    friction_force,
    tid_stiffness,
    tid_damping,
    omega,
    amplitude,
    *,
    rtol=1e-10,
    n_grid=256,
    max_periods=4000,
    n_dense=2048,
    parasitic_damping=0.0,
    terminal_mass=0.0,
) -> dict:
    """Periodic steady state of the host + TID with exact Coulomb friction (SI units).

    Arguments: host mass M [kg], host stiffness K [N/m], host damping C [N s/m],
    inertance b [kg], friction force ff [N] (>= 0), TID stiffness k [N/m], TID damping
    c [N s/m], forcing frequency omega [rad/s], forcing amplitude A [N]; forcing is
    ``A sin(omega t)`` on the host. The inerter's own parasitic damping cp [N s/m] and
    terminal mass mt [kg] (default 0) make its equation
    ``(b + mt) y'' + cp y' + c (y' - x') + k (y - x) + ff sign(y') = 0``; at rest
    (y' = 0) neither changes the stick and slip decisions.

    Returns a dict with ``x_max``, ``y_max`` (peak |x|, |y| over one steady period, m),
    ``converged`` (period-boundary state repeats to ``rtol``), ``periods`` (period maps
    evaluated, transient + shooting), ``stick_fraction`` (fraction of the final period
    spent stuck), and, for checks, ``state0`` (x, x', y, y' at t = 0 mod T), ``residual``
    and a dense trajectory over the final period: ``t`` [s] (0..T, forcing phase
    A sin(omega t)), ``x``, ``v`` (= x'), ``y``, ``w`` (= y'), including all event times.
    If the inerter sticks for the whole period, y's constant offset is not unique; the
    value reached from the initial guess is reported.
    """
    M, K, C = float(host_mass), float(host_stiffness), float(host_damping)
    b, ff = float(inertance), float(friction_force)
    k, c = float(tid_stiffness), float(tid_damping)
    omega, A = float(omega), float(amplitude)
    if not (omega > 0.0 and math.isfinite(omega)):
        raise ValueError(f"omega must be positive and finite, got {omega!r}")
    if not (A > 0.0 and math.isfinite(A)):
        raise ValueError(f"amplitude must be positive and finite, got {A!r}")
    if ff < 0.0:
        raise ValueError(f"friction_force must be >= 0, got {ff!r}")
    for name, val in (("host_mass", M), ("host_stiffness", K), ("inertance", b),
                      ("tid_stiffness", k)):
        if not val > 0.0:
            raise ValueError(f"{name} must be positive, got {val!r}")
    if not (C >= 0.0 and c >= 0.0 and C + c > 0.0):
        raise ValueError("dampings must be >= 0 with host_damping + tid_damping > 0")

    sysm = _System(M, K, C, b + float(terminal_mass), ff, k, c, omega, A, n_grid,
                   float(parasitic_damping))
    T = sysm.T

    # Initial guess: fully stuck periodic motion if it is consistent, else frictionless.
    zs = sysm.stuck_periodic(0.0)
    Fs_amp = abs(c * sysm.stick.Zs[1] + k * sysm.stick.Zs[0])
    if Fs_amp <= ff:
        z = zs
    else:
        z = sysm.linear_guess()
    L = max(abs(sysm.linear_guess()[0]), abs(sysm.linear_guess()[2]), abs(zs[0]), A / K)

    def norm(dz):
        return float(np.max(np.abs(_scaled(dz, L, omega))))

    periods = 0
    converged = False
    residual = np.inf
    newton_start = 8
    newton_every = 40
    last_newton = -10**9
    while periods < max_periods:
        z1, info = sysm.period(z)
        periods += 1
        if not info["ok"]:
            break
        residual = norm(z1 - z) / max(norm(z1), 1e-300)
        if residual <= rtol:
            z = z1
            converged = True
            break
        if info["stick_time"] >= T * (1.0 - 1e-12) and z1[3] == 0.0:
            # fully stuck: close the orbit analytically with the current y
            z = sysm.stuck_periodic(z1[2])
            continue
        z = z1
        if periods >= newton_start and periods - last_newton >= newton_every:
            last_newton = periods
            zn, used, ok = _newton(sysm, z, norm, rtol)
            periods += used
            if ok:
                z = zn

    zf, info = sysm.period(z, record=True)
    if converged:
        residual = norm(zf - z) / max(norm(zf), 1e-300)

    # peaks: x at zeros of x' (located exactly), y at phase boundaries (monotone slips)
    xmax = 0.0
    ymax = 0.0
    for _mode, ph, seg_t, seg_z in info["segs"]:
        xmax = max(xmax, float(np.max(np.abs(seg_z[:, 0]))))
        ymax = max(ymax, float(np.max(np.abs(seg_z[:, 2]))))
        V = seg_z[:, 1]
        sc = np.nonzero(np.sign(V[:-1]) * np.sign(V[1:]) < 0)[0]
        for i in sc:
            def fv(tt, ph=ph):
                return ph.eval1(tt)[1]
            tr = brentq(fv, seg_t[i], seg_t[i + 1], xtol=1e-16 * T, rtol=1e-15, maxiter=200)
            xmax = max(xmax, abs(float(ph.eval1(tr)[0])))
    # dense trajectory over the final period
    tdense = np.linspace(0.0, T, n_dense + 1)
    t_all, x_all = [], []
    for mode, ph, seg_t, seg_z in info["segs"]:
        ta, tb = seg_t[0], seg_t[-1]
        inner = tdense[(tdense > ta) & (tdense < tb)]
        tt = np.concatenate(([ta], inner, [tb]))
        Z = ph.eval(tt)
        if mode == _STICK:
            ys = seg_z[0, 2]
            Z = np.column_stack((Z[:, 0], Z[:, 1], np.full(len(tt), ys), np.zeros(len(tt))))
        t_all.append(tt)
        x_all.append(Z)
    t_all = np.concatenate(t_all)
    Zall = np.vstack(x_all)
    return dict(
        x_max=xmax,
        y_max=ymax,
        converged=bool(converged),
        periods=int(periods),
        stick_fraction=float(info["stick_time"] / T),
        residual=float(residual),
        state0=np.array(z, float),
        n_events=int(info["n_events"]),
        t=t_all,
        x=Zall[:, 0],
        v=Zall[:, 1],
        y=Zall[:, 2],
        w=Zall[:, 3],
    )


def _newton(sysm, z, norm, rtol, max_iter=12):
    """Shooting: solve P(z) = z with a finite-difference Jacobian. Returns (z, maps, ok)."""
    pz, _ = sysm.period(z)
    used = 1
    r = pz - z
    rn = norm(r) / max(norm(pz), 1e-300)
    # component scales (L, wL, L, wL) used by norm(), recovered from unit vectors
    Lvec = np.array([1.0 / norm(np.eye(4)[i]) for i in range(4)])
    for _ in range(max_iter):
        if rn <= 0.1 * rtol:
            return z, used, True
        zscale = max(norm(z), 1e-300)
        J = np.empty((4, 4))
        for i in range(4):
            h = 1e-7 * zscale * Lvec[i]
            zp = z.copy()
            zp[i] += h
            pp, _ = sysm.period(zp)
            used += 1
            J[:, i] = ((pp - zp) - r) / h
        try:
            dz = np.linalg.solve(J, -r)
        except np.linalg.LinAlgError:
            return z, used, False
        if not np.all(np.isfinite(dz)):
            return z, used, False
        lam = 1.0
        improved = False
        for _ls in range(6):
            zn = z + lam * dz
            pn, _ = sysm.period(zn)
            used += 1
            rnn = norm(pn - zn) / max(norm(pn), 1e-300)
            if rnn < rn:
                improved = True
                break
            lam *= 0.5
        if not improved:
            return z, used, False
        z, pz, r, rn = zn, pn, pn - zn, rnn
    return z, used, rn <= rtol
