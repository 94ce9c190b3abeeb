"""Event-driven steady state of a multi-storey structure with a friction TID (SI units).

Model (see ``building_linear`` for the matrices): generalised coordinates
``u = (x_1..x_n, r)``, ``r`` the inerter stroke, with::

    Mg u'' + Cg u' + Kg u = G A sin(w t) - ff sign(r') e_r

``G = [pattern; 0]`` for a force load, ``G = -[M 1_n + mt e_i; mt]`` for a ground
acceleration ``a_g = A sin(w t)`` [m/s2]; ``e_r`` the unit vector of the ``r`` row.
With a compliant device (``ks``) the coordinates are ``(x_1..x_n, r, q)`` and the
friction acts on the mechanism's ``q`` instead of ``r``: below, ``r`` stands for the
last coordinate, and "stroke" is still the terminal's ``r``.
The friction is exact Coulomb friction with stick (static = kinetic = ``ff``): while
``r' = 0`` the inerter is stuck (``r`` held) as long as the force needed to hold it,
``|phi| <= ff``, where ``phi`` is the net generalised force on the ``r`` row without
friction and ``r`` inertia, ``phi = G_r a - Mg[r, x] x'' - Cg[r, x] x' - Kg[r, :] u``,
with ``x''`` from the stuck dynamics (``phi = F - mt (x_i'' + a_g)`` for a ground load,
``F`` the spring-damper force).  When ``|phi|`` reaches ``ff`` the inerter slips with
``sign(phi)``; when ``r'`` returns to zero it sticks if ``|phi| <= ff`` there, else it
slips the other way (ties are broken by ``dphi/dt``).

Method: each phase (slip ``+1``, slip ``-1``, stick with ``r`` held, integrating the
reduced n-DOF system) is integrated with ``scipy.integrate.solve_ivp`` (DOP853, ``rtol``
1e-11, ``atol`` 1e-13 times the motion scale) with terminal events (``r' = 0`` while
slipping, ``phi = +-ff`` while stuck); the mode is switched here and the integration
restarted at each event. The periodic steady state is found by integrating periods from
the frictionless (or, when consistent, the fully stuck) steady state (or from rest / a
given start) and by Newton shooting on the period map (finite-difference Jacobian), with
the Poincare section placed in the middle of a slip phase so that the map is smooth
there. A period that is stuck throughout is closed analytically with the current ``r``
(``r`` is then a free family parameter; the value reached is kept). Peaks come from the
dense output: samples over the period plus all event times, each sampled local maximum
polished with a bounded scalar maximisation of the interpolant.

Pure numpy / scipy; nothing here imports ``tid_jax``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import minimize_scalar

try:
    from .building_linear import generalised_load, generalised_matrices
except ImportError:  # run as a script from this folder
    from building_linear import generalised_load, generalised_matrices

__all__ = ["steady_state"]

STICK = 0


def _first_order(Mass, Damp, Stiff, *rhs):
    """State matrix [[0, I], [-Mass^-1 Stiff, -Mass^-1 Damp]] and [0; Mass^-1 v] vectors."""
    m = Mass.shape[0]
    Mi = np.linalg.inv(Mass)
    S = np.block([[np.zeros((m, m)), np.eye(m)], [-Mi @ Stiff, -Mi @ Damp]])
    return (S,) + tuple(np.concatenate((np.zeros(m), Mi @ v)) for v in rhs)


class _Model:
    """Slip and stick dynamics, phi, events and the period map for one (omega, A)."""

    def __init__(self, omega, M, K, C, b, ff, k, c, spring_floor, inerter_floor, A, load,
                 pattern, cp, mt, ks, ode_rtol, scale):
        M = np.atleast_2d(np.asarray(M, float))
        Mg, Cg, Kg = generalised_matrices(M, K, C, b=b, k=k, c=c, spring_floor=spring_floor,
                                          inerter_floor=inerter_floor, cp=cp, mt=mt, ks=ks)
        G = A * generalised_load(M, load=load, pattern=pattern, inerter_floor=inerter_floor,
                                 mt=mt, compliant=ks is not None)
        # n: the coordinates that move while the friction's (the last) is stuck
        n = Mg.shape[0] - 1
        self.floors = M.shape[0]
        self.n, self.N, self.w, self.T, self.ff = n, n + 1, omega, 2 * math.pi / omega, ff
        self.A, self.ground = A, load == "ground"
        self.Mg, self.Cg, self.Kg, self.G = Mg, Cg, Kg, G
        e_r = np.eye(n + 1)[n]
        self.S, self.e, self.fr = _first_order(Mg, Cg, Kg, G, -ff * e_r)
        xs = slice(0, n)
        self.Ss, self.es, self.hs = _first_order(Mg[xs, xs], Cg[xs, xs], Kg[xs, xs], G[:n],
                                                 -Kg[:n, n])
        m = Mg[n, :n] @ np.linalg.inv(Mg[xs, xs])
        self.phi_a = G[n] - m @ G[:n]
        self.phi_x = -Kg[n, :n] + m @ Kg[xs, xs]
        self.phi_v = -Cg[n, :n] + m @ Cg[xs, xs]
        self.phi_r = -Kg[n, n] + m @ Kg[:n, n]
        self.rtol = ode_rtol
        L, V = scale
        self.atol = 1e-2 * ode_rtol * np.concatenate((np.full(n + 1, L), np.full(n + 1, V)))
        self.atol_s = np.concatenate((self.atol[:n], self.atol[n + 1:2 * n + 1]))

    # --- phi and the stick / slip decision ---------------------------------------------
    def phi(self, t, y, r):
        """Holding force on the r row for stuck states y = (x, x') (arrays: columns)."""
        n = self.n
        return (self.phi_a * np.sin(self.w * t) + self.phi_x @ y[:n] + self.phi_v @ y[n:]
                + self.phi_r * r)

    def dphi(self, t, y, r):
        acc = self.stuck_rhs(r)(t, y)[self.n:]
        return (self.phi_a * self.w * math.cos(self.w * t) + self.phi_x @ y[self.n:]
                + self.phi_v @ acc)

    def decide(self, t, z):
        """Mode (+1, -1 slip; 0 stick) for a full state z with r' = 0 at time t."""
        y, r = self.reduce(z), z[self.n]
        p = self.phi(t, y, r)
        tol = 1e-12 * max(self.ff, abs(p))
        dp = self.dphi(t, y, r)
        if p > self.ff + tol or (p >= self.ff - tol and dp > 0.0):
            return +1
        if p < -self.ff - tol or (p <= -self.ff + tol and dp < 0.0):
            return -1
        return STICK

    def mode_of(self, t, z):
        v = z[2 * self.N - 1]
        return (1 if v > 0 else -1) if v != 0.0 else self.decide(t, z)

    # --- state conversions and right-hand sides ----------------------------------------
    def reduce(self, z):
        n, N = self.n, self.N
        return np.concatenate((z[:n], z[N:N + n]))

    def expand(self, y, r):
        n = self.n
        return np.concatenate((y[:n], [r], y[n:], [0.0]))

    def slip_rhs(self, s):
        return self._rhs(self.S, self.e, s * self.fr)

    def stuck_rhs(self, r):
        return self._rhs(self.Ss, self.es, r * self.hs)

    def _rhs(self, S, e, f):
        """z' = S z + e sin(w t) + f, for one state or for states in columns."""
        w = self.w

        def rhs(t, z):
            if np.ndim(z) == 1:
                return S @ z + e * math.sin(w * t) + f
            return S @ z + np.outer(e, np.sin(w * t)) + f[:, None]
        return rhs

    # --- integration over [t0, t1] with mode switching ---------------------------------
    def _phase(self, mode, t, t1, z, record):
        """Integrate one phase; returns (t_end, z_end, next mode or None, segment)."""
        n, N = self.n, self.N
        if mode == STICK:
            r = z[n]

            def up(tt, y):
                return self.phi(tt, y, r) - self.ff

            def down(tt, y):
                return self.phi(tt, y, r) + self.ff

            up.terminal, up.direction = True, 1.0
            down.terminal, down.direction = True, -1.0
            sol = solve_ivp(self.stuck_rhs(r), (t, t1), self.reduce(z), method="DOP853",
                            rtol=self.rtol, atol=self.atol_s, events=[up, down],
                            dense_output=record)
            z_end = self.expand(sol.y[:, -1], r)
            nxt = None
            if sol.status == 1:
                nxt = +1 if len(sol.t_events[0]) else -1
        else:
            def stop(tt, zz):
                return zz[2 * N - 1]

            stop.terminal, stop.direction = True, -float(mode)
            sol = solve_ivp(self.slip_rhs(mode), (t, t1), z, method="DOP853", rtol=self.rtol,
                            atol=self.atol, events=[stop], dense_output=record)
            z_end = sol.y[:, -1].copy()
            nxt = None
            if sol.status == 1:
                z_end[2 * N - 1] = 0.0
                nxt = self.decide(sol.t[-1], z_end)
        if sol.status == -1:
            raise RuntimeError(sol.message)
        seg = (mode, t, sol.t[-1], sol.sol if record else None, z[n])
        return sol.t[-1], z_end, nxt, seg

    def advance(self, z, t0, t1, record=False, max_events=400):
        """State at t1 from z at t0; info: segments, stick time, mode changes."""
        z = np.array(z, float)
        t, mode = t0, self.mode_of(t0, z)
        segs, stick_time, changes = [], 0.0, 0
        while t < t1 - 1e-14 * self.T:
            t_end, z, nxt, seg = self._phase(mode, t, t1, z, record)
            segs.append(seg)
            if mode == STICK:
                stick_time += t_end - t
            t = t_end
            if nxt is not None:
                changes += nxt != mode
                mode = nxt
                if changes > max_events:
                    raise RuntimeError("too many mode changes in one period (chattering?)")
        return z, dict(segs=segs, stick_time=stick_time, changes=changes)

    def period(self, z, ts, record=False):
        return self.advance(z, ts, ts + self.T, record)

    # --- closed-form linear states -----------------------------------------------------
    def linear_state(self, t):
        """Frictionless steady state at time t (full state)."""
        U = np.linalg.solve(self.Kg - self.w**2 * self.Mg + 1j * self.w * self.Cg, self.G)
        ph = np.exp(1j * self.w * t)
        return np.concatenate(((U * ph).imag, (1j * self.w * U * ph).imag))

    def stuck_amplitudes(self):
        n, xs = self.n, slice(0, self.n)
        D = self.Kg[xs, xs] - self.w**2 * self.Mg[xs, xs] + 1j * self.w * self.Cg[xs, xs]
        X = np.linalg.solve(D, self.G[:n])
        x_r = np.linalg.solve(self.Kg[xs, xs], -self.Kg[:n, n])  # static offset per unit r
        return X, x_r

    def stuck_state(self, r, t):
        """Periodic stuck motion with r held, at time t (full state), and max |phi|."""
        X, x_r = self.stuck_amplitudes()
        ph = np.exp(1j * self.w * t)
        y = np.concatenate((r * x_r + (X * ph).imag, (1j * self.w * X * ph).imag))
        P = self.phi_a + self.phi_x @ X + 1j * self.w * (self.phi_v @ X)
        p0 = self.phi_x @ (r * x_r) + self.phi_r * r
        return self.expand(y, r), abs(p0) + abs(P)


def _section_time(model, info):
    """Middle of the longest slip phase of the last period (None if fully stuck)."""
    slips = [(t1 - t0, 0.5 * (t0 + t1)) for mode, t0, t1, _, _ in info["segs"] if mode != STICK]
    return max(slips)[1] if slips else None


def _newton(model, z, ts, norm, rtol, max_iter=8):
    """Shooting P(z) = z at section time ts; returns (z, period maps used, ok, multiplier)."""
    pz, _ = model.period(z, ts)
    used, res = 1, pz - z
    rn = norm(res) / norm(pz)
    mult = None
    sc = np.array([1.0 / norm(e) for e in np.eye(len(z))])
    for _ in range(max_iter):
        if rn <= 0.5 * rtol:
            return z, used, True, mult
        J = np.empty((len(z), len(z)))
        for i in range(len(z)):
            h = 1e-6 * sc[i]
            zp = z.copy()
            zp[i] += h
            J[:, i] = (model.period(zp, ts)[0] - pz) / h
        used += len(z)
        mult = float(np.max(np.abs(np.linalg.eigvals(J))))
        dz = np.linalg.solve(J - np.eye(len(z)), -res)
        lam = 1.0
        for _ls in range(6):
            zn = z + lam * dz
            pn, _ = model.period(zn, ts)
            used += 1
            rnn = norm(pn - zn) / norm(pn)
            if rnn < rn:
                break
            lam *= 0.5
        else:
            return z, used, False, mult
        z, pz, res, rn = zn, pn, pn - zn, rnn
    return z, used, rn <= rtol, mult


def _quantity(model, seg, t, kind, floor):
    """Chosen response (or stroke) on a segment at times t (array)."""
    mode, _, _, sol, r = seg
    n, N, s = model.n, model.N, model.floors  # s: the terminal's stroke
    if mode == STICK:
        y = sol(t)
        x, stroke = y[:n], (y[s] if s < n else np.full(len(t), r))
        acc = model.stuck_rhs(r)(t, y)[n:]
    else:
        z = sol(t)
        x, stroke = z[:n], z[s]
        acc = model.slip_rhs(mode)(t, z)[N:N + n]
    f = floor - 1
    if kind == "stroke":
        return stroke
    if kind == "displacement":
        return x[f]
    if kind == "drift":
        return x[f] - x[f - 1] if f >= 1 else x[f]
    if kind == "acceleration":
        return acc[f] + (model.A * np.sin(model.w * t) if model.ground else 0.0)
    raise ValueError(f"unknown kind {kind!r}")


def _peak_abs(model, segs, kind, floor, samples):
    """max |q| over the period: samples + segment ends, local maxima polished."""
    T = model.T
    best = 0.0
    for seg in segs:
        t0, t1 = seg[1], seg[2]
        m = max(int(math.ceil(samples * (t1 - t0) / T)), 2)
        t = np.linspace(t0, t1, m + 1)
        q = np.abs(_quantity(model, seg, t, kind, floor))
        best = max(best, float(np.max(q)))
        idx = np.nonzero((q[1:-1] >= q[:-2]) & (q[1:-1] >= q[2:]))[0] + 1

        def neg(tt, seg=seg):
            return -float(np.abs(_quantity(model, seg, np.array([tt]), kind, floor)[0]))

        for i in idx[np.argsort(-q[idx])][:4]:
            res = minimize_scalar(
                neg, bounds=(t[i - 1], t[i + 1]), method="bounded", options={"xatol": 1e-14 * T})
            best = max(best, -float(res.fun))
    return best


def steady_state(omega, M, K, C, *, b, ff, k, c, spring_floor, inerter_floor, amplitude,
                 load="force", pattern=None, kind="displacement", floor=None, cp=0.0, mt=0.0,
                 ks=None, samples=2000, start=None, rtol=1e-10, ode_rtol=1e-11,
                 max_periods=300):
    """Periodic steady state with exact Coulomb friction (SI units).

    ``omega`` [rad/s], ``amplitude`` A [N per unit pattern, or m/s2 for a ground load],
    ``ff`` [N] >= 0; ``ks`` [N/m]: a compliant device's series stiffness (None: rigid).
    ``kind`` in displacement / drift / acceleration (absolute) / stroke
    of ``floor`` (default top).  ``start``: optional full state (x, r, x', r') at t = 0,
    or ``"rest"`` (default: the fully stuck steady state with r = 0 when consistent, else the
    frictionless one).
    Returns a dict: ``response_max`` (max |quantity| over a period), ``stroke_max``
    (max |r|), ``transitions`` (mode changes per period, slip reversals included),
    ``stick_fraction``, ``periods`` (period maps evaluated), ``converged`` (period start
    state repeats to ``rtol``, scaled), ``residual``, ``multiplier`` (largest Floquet
    multiplier from the last Newton Jacobian, None if not used), ``fully_stuck``,
    ``section_time`` and ``state`` (the periodic state there).
    """
    M = np.atleast_2d(np.asarray(M, float))
    n = M.shape[0]
    floor = n if floor is None else int(floor)
    if ff < 0 or amplitude == 0 or omega <= 0:
        raise ValueError("need ff >= 0, amplitude != 0, omega > 0")
    args = (omega, M, K, C, b, ff, k, c, spring_floor, inerter_floor, amplitude, load,
            pattern, cp, mt, ks)
    probe = _Model(*args, ode_rtol, (1.0, 1.0))
    n = probe.n
    z_lin = probe.linear_state(0.0)
    z_st, phi_st = probe.stuck_state(0.0, 0.0)
    L = max(np.max(np.abs(z_lin[:n + 1])), np.max(np.abs(z_st[:n + 1])),
            np.max(np.abs(np.linalg.solve(probe.Kg[:n, :n], probe.G[:n]))))
    model = _Model(*args, ode_rtol, (L, omega * L))
    scale = np.concatenate((np.full(n + 1, L), np.full(n + 1, omega * L)))

    def norm(dz):
        return max(float(np.max(np.abs(dz / scale))), 1e-300)

    if isinstance(start, str) and start == "rest":
        z = np.zeros(2 * (n + 1))
    elif start is not None:
        z = np.array(start, float)
    else:
        z = z_st if phi_st <= ff else z_lin
    ts, periods, residual, converged = 0.0, 0, np.inf, False
    mult, last_newton = None, -10**9
    while periods < max_periods:
        z1, info = model.period(z, ts)
        periods += 1
        residual = norm(z1 - z) / norm(z1)
        if residual <= rtol:
            converged = True
            break
        if info["stick_time"] >= model.T * (1 - 1e-12):
            # stuck all period: close the orbit exactly with this r; accept it if the
            # holding force stays within ff over the whole closed orbit
            z, phi_max = model.stuck_state(z1[n], ts)
            if phi_max <= ff * (1.0 + 1e-9):
                residual, converged = norm(z1 - z) / norm(z), True
                break
            continue
        z = z1
        if periods >= 3 and periods - last_newton >= 10:
            last_newton = periods
            t_new = _section_time(model, info)
            z = model.advance(z, ts, t_new)[0]
            ts = t_new - model.T * math.floor(t_new / model.T)
            zn, used, ok, m = _newton(model, z, ts, norm, rtol)
            periods += used
            mult = m if m is not None else mult
            if ok:
                z = zn
    z_end, info = model.period(z, ts, record=True)
    segs = info["segs"]
    return dict(
        response_max=_peak_abs(model, segs, kind, floor, samples),
        stroke_max=_peak_abs(model, segs, "stroke", floor, samples),
        transitions=int(info["changes"]),
        stick_fraction=float(info["stick_time"] / model.T),
        fully_stuck=bool(info["stick_time"] >= model.T * (1 - 1e-12)),
        periods=int(periods),
        converged=bool(converged),
        residual=float(residual),
        multiplier=mult,
        section_time=float(ts),
        state=z,
    )


# ---------------------------------------------------------------------------
# Self-check (python -m tests.reference.building_stick_slip)
# ---------------------------------------------------------------------------


def _timed(**kw):
    import time

    t0 = time.perf_counter()
    out = steady_state(**kw)
    return out, time.perf_counter() - t0


def _check_frictionless(M, K, C, w1):
    try:
        from .building_linear import response_amplitude
    except ImportError:
        from building_linear import response_amplitude
    worst, times = 0.0, []
    cases = [(1, 0, 0.0, 0.0), (3, 1, 20.0, 50.0), (2, 3, 10.0, 0.0)]
    for j, i, mt, cp in cases:
        for load in ("force", "ground"):
            for kind, fl in (("displacement", 3), ("drift", 2), ("acceleration", 1),
                             ("stroke", None)):
                for r, start in ((0.9, None), (1.4, np.zeros(8))):
                    kw = dict(b=275.0, k=0.9 * 275.0 * w1**2, c=0.2 * 275.0 * w1,
                              spring_floor=j, inerter_floor=i, load=load,
                              pattern=[0.3, 0.3, 0.4], kind=kind, floor=fl, cp=cp, mt=mt)
                    out, dt = _timed(omega=r * w1, M=M, K=K, C=C, ff=0.0, amplitude=2.0,
                                     start=start, **kw)
                    lin = 2.0 * response_amplitude(r * w1, M, K, C, **kw)
                    worst = max(worst, abs(out["response_max"] / lin - 1))
                    times.append(dt)
    print(f"(i) ff = 0 vs building_linear, {len(times)} cases (3 layouts incl. mt, cp; force,"
          f" ground; 4 kinds; linear start and from rest): max rel diff {worst:.2e}; "
          f"{np.mean(times):.2f} s mean, {np.max(times):.2f} s max per call")


def _check_coulomb():
    try:
        from .coulomb import coulomb_steady_state, paper_parameters
    except ImportError:
        from coulomb import coulomb_steady_state, paper_parameters
    p = paper_parameters()
    Mh, Kh, Ch, b = p["host_mass"], p["host_stiffness"], p["host_damping"], p["inertance"]
    k, c, ff = p["tid_stiffness"], p["tid_damping"], p["friction_force"]
    wn = math.sqrt(Kh / Mh)
    for mt, cp in ((0.0, 0.0), (10.0, 30.0)):
        dx, dy, times, kinds = 0.0, 0.0, [], set()
        for A in (100.0, 200.0, 500.0, 1000.0):
            for r in (0.85, 0.95, 1.0, 1.05, 1.15):
                out, dt = _timed(omega=r * wn, M=[[Mh]], K=[[Kh]], C=[[Ch]], b=b, ff=ff, k=k,
                                 c=c, spring_floor=1, inerter_floor=0, amplitude=A, mt=mt,
                                 cp=cp)
                ref = coulomb_steady_state(Mh, Kh, Ch, b, ff, k, c, r * wn, A,
                                           parasitic_damping=cp, terminal_mass=mt)
                dx = max(dx, abs(out["response_max"] / ref["x_max"] - 1))
                dy = max(dy, abs(out["stroke_max"] - ref["y_max"]) / max(ref["y_max"], 1e-300)
                         if ref["y_max"] > 0 else abs(out["stroke_max"]))
                times.append(dt)
                kinds.add("stuck" if out["fully_stuck"] else
                          "stick-slip" if out["stick_fraction"] > 0 else "slip")
        print(f"(ii) 1-storey vs coulomb.py (mt = {mt}, cp = {cp}), A = 100..1000 N, 5 "
              f"frequencies ({', '.join(sorted(kinds))}): max rel diff x peak {dx:.2e}, "
              f"stroke peak {dy:.2e}; {np.mean(times):.2f} s mean per call")


def _check_ground_vs_force():
    try:
        from .coulomb import paper_parameters
    except ImportError:
        from coulomb import paper_parameters
    p = paper_parameters()
    Mh, Kh, Ch, b = p["host_mass"], p["host_stiffness"], p["host_damping"], p["inertance"]
    wn = math.sqrt(Kh / Mh)
    common = dict(M=[[Mh]], K=[[Kh]], C=[[Ch]], b=b, ff=20.0, k=p["tid_stiffness"],
                  c=p["tid_damping"], spring_floor=1, inerter_floor=0)
    worst = 0.0
    for ag in (0.1, 0.3):
        for r in (0.9, 1.0, 1.1):
            g = steady_state(omega=r * wn, amplitude=ag, load="ground", **common)
            f = steady_state(omega=r * wn, amplitude=-Mh * ag, load="force", **common)
            worst = max(worst, abs(g["response_max"] / f["response_max"] - 1))
    print(f"(iii) ground A m/s2 vs force -M A N (1-storey): max rel diff {worst:.2e}")


def _check_three_storey(M, K, C, w1):
    try:
        from .building_hinf import h_infinity_search
    except ImportError:
        from building_hinf import h_infinity_search
    b = 0.05 * np.trace(M)
    h = h_infinity_search(M, K, C, b=b, spring_floor=1, inerter_floor=0, load="ground",
                          kind="displacement", floor=3, start=(b * w1**2, 0.3 * b * w1))
    ff = 0.05 * np.trace(M) * 1.0
    print(f"(iv) 3-storey, f1 = {w1 / 2 / math.pi:.4f} Hz, b = {b:.0f} kg, H-inf k = "
          f"{h['k']:.6g} N/m, c = {h['c']:.6g} N s/m; ground 1 m/s2, ff = {ff:.0f} N")
    print("     w/w1   top disp max [m]  stroke max [m]  trans  stick  periods  conv  "
          "multiplier  time")
    for r in np.linspace(0.7, 1.3, 20):
        out, dt = _timed(omega=r * w1, M=M, K=K, C=C, b=b, ff=ff, k=h["k"], c=h["c"],
                         spring_floor=1, inerter_floor=0, amplitude=1.0, load="ground",
                         kind="displacement", floor=3)
        mult = "-" if out["multiplier"] is None else f"{out['multiplier']:.3f}"
        print(f"     {r:.3f}  {out['response_max']:.10e}  {out['stroke_max']:.6e}  "
              f"{out['transitions']:5d}  {out['stick_fraction']:.3f}  {out['periods']:7d}  "
              f"{out['converged']!s:5}  {mult:>10}  {dt:.2f} s")


if __name__ == "__main__":
    try:
        from .building_linear import modal_damping, natural_frequencies, shear_building
    except ImportError:
        from building_linear import modal_damping, natural_frequencies, shear_building
    M3, K3 = shear_building([2000.0, 2000.0, 1500.0], np.array([1.5, 1.25, 1.0]) * 1e6)
    C3 = modal_damping(M3, K3, 0.02)
    w13 = natural_frequencies(M3, K3)[0][0]
    _check_frictionless(M3, K3, C3, w13)
    _check_coulomb()
    _check_ground_vs_force()
    _check_three_storey(M3, K3, C3, w13)
