"""Time history with exact Coulomb friction under a sampled ground acceleration (SI units),
event-driven, for checking record histories.

Model: generalised coordinates ``u`` (length ``m``)::

    Mg u'' + Cg u' + Kg u = g a(t) + F e_f

``e_f`` the unit vector of the last coordinate ``f``, which carries the friction force
``F``; ``a(t)`` the straight line between samples ``a_j`` at ``t_j = j dt``.  Exact
Coulomb friction, static = kinetic = ``ff > 0``: slipping, ``F = -ff sign(u_f')``; stuck
(``u_f' = 0``, ``u_f = r`` held), the other coordinates obey their own rows with ``u_f'' =
0`` and ``F`` is the force that holds ``f``, from its row.  Stuck lasts while ``|F| <=
ff``; then ``f`` slips against ``F``.  When ``u_f'`` returns to zero, ``f`` sticks if the
holding force there is within ``ff`` (ties within a relative ``1e-10`` go by its rate),
else slips the other way.

Method: every record interval ``[t_j, t_{j+1}]`` (on which ``a`` is exactly linear) is
integrated on its own by ``scipy.integrate.solve_ivp`` (DOP853, ``rtol`` 1e-12 by
default) with terminal events (``u_f' = 0`` slipping, in the stopping direction;
``F = +-ff`` stuck); at each event the mode is switched and the integration restarted
with ``u_f'`` set to exactly zero.  Pure numpy / scipy; nothing here imports ``tid_jax``.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["simulate"]

STICK = 0


class _Model:
    def __init__(self, mass, damping, stiffness, load_vector, friction_force):
        M, C, K = (np.atleast_2d(np.asarray(a, float)) for a in (mass, damping, stiffness))
        self.M, self.C, self.K = M, C, K
        self.g = np.asarray(load_vector, float)
        self.m = M.shape[0]
        self.f = self.m - 1
        self.ff = float(friction_force)
        self.Mi = np.linalg.inv(M)
        self.Mxi = np.linalg.inv(M[:self.f, :self.f])

    def slip_rhs(self, a, sign):
        m, Mi, C, K, g = self.m, self.Mi, self.C, self.K, self.g
        force = np.zeros(m)
        force[-1] = -sign * self.ff

        def rhs(t, z):
            u, v = z[:m], z[m:]
            return np.concatenate([v, Mi @ (g * a(t) + force - C @ v - K @ u)])

        return rhs

    def stuck_acceleration(self, t, u, v, a):
        """The other coordinates' accelerations with ``u_f`` held (``v[f] = 0``)."""
        x = slice(0, self.f)
        return self.Mxi @ (self.g[x] * a(t) - self.C[x] @ v - self.K[x] @ u)

    def stuck_rhs(self, a, r):
        f = self.f

        def rhs(t, y):
            u = np.concatenate([y[:f], [r]])
            v = np.concatenate([y[f:], [0.0]])
            return np.concatenate([y[f:], self.stuck_acceleration(t, u, v, a)])

        return rhs

    def holding(self, t, u, v, a):
        """The friction force that keeps ``f`` stuck at (u, v) (``v[f] = 0``)."""
        f = self.f
        xdd = self.stuck_acceleration(t, u, v, a)
        return (self.M[f, :f] @ xdd + self.C[f] @ v + self.K[f] @ u - self.g[f] * a(t))

    def full(self, y, r):
        f, m = self.f, self.m
        z = np.zeros(2 * m)
        z[:f], z[f], z[m:m + f] = y[:f], r, y[f:]
        return z

    def decide(self, t, z, a):
        m = self.m
        u, v = z[:m], z[m:].copy()
        v[-1] = 0.0
        force = self.holding(t, u, v, a)
        tolerance = 1e-10 * max(self.ff, abs(force))
        if abs(force) < self.ff - tolerance:
            return STICK
        if abs(force) > self.ff + tolerance:
            return -int(np.sign(force))
        h = 1e-7
        rate = (self.holding(t + h, u + h * v, v, a) - force) / h
        return -int(np.sign(force)) if rate * force > 0 else STICK


def _interval(model, mode, t0, t1, z, a, rtol, atol):
    """From (t0, z) in `mode` to t1 or the first event: (t_end, z_end, next mode)."""
    m, f = model.m, model.f
    if mode == STICK:
        r = z[f]
        y0 = np.concatenate([z[:f], z[m:m + f]])

        def force(t, y):
            zz = model.full(y, r)
            return model.holding(t, zz[:m], zz[m:], a)

        up = lambda t, y: force(t, y) - model.ff
        down = lambda t, y: force(t, y) + model.ff
        up.terminal, up.direction = True, 1.0
        down.terminal, down.direction = True, -1.0
        sol = solve_ivp(model.stuck_rhs(a, r), (t0, t1), y0, method="DOP853", rtol=rtol,
                        atol=atol, events=[up, down])
        if sol.status == 1:
            hit = 0 if len(sol.t_events[0]) else 1
            return sol.t_events[hit][0], model.full(sol.y_events[hit][0], r), (-1, +1)[hit]
        return t1, model.full(sol.y[:, -1], r), mode
    stop = lambda t, zz: zz[-1]
    stop.terminal, stop.direction = True, -float(mode)
    sol = solve_ivp(model.slip_rhs(a, mode), (t0, t1), z, method="DOP853", rtol=rtol,
                    atol=atol, events=[stop])
    if sol.status == 1:
        t_end, z_end = sol.t_events[0][0], sol.y_events[0][0].copy()
        z_end[-1] = 0.0
        return t_end, z_end, model.decide(t_end, z_end, a)
    return t1, sol.y[:, -1], mode


def simulate(mass, damping, stiffness, load_vector, friction_force, acceleration,
             time_step, *, rtol=1e-12, atol=1e-15, max_events=1000):
    """From rest at t = 0 under the samples ``acceleration`` every ``time_step`` (s):
    a dict of ``states`` ``(samples, 2m)`` (u, u'), ``stuck`` (bool, the mode that
    follows each sample), ``friction_force`` (N, on ``f``: the holding force while
    stuck) and ``events`` (list of (time, new mode), +-1 slipping, 0 stuck)."""
    model = _Model(mass, damping, stiffness, load_vector, friction_force)
    samples = np.asarray(acceleration, float)
    count, m = len(samples), model.m
    states, modes = np.zeros((count, 2 * m)), np.zeros(count, int)
    z = np.zeros(2 * m)
    a0 = lambda t: samples[0]
    mode = model.decide(0.0, z, a0)
    modes[0] = mode
    events = []
    for j in range(count - 1):
        t0, t1 = j * time_step, (j + 1) * time_step
        slope = (samples[j + 1] - samples[j]) / time_step
        a = lambda t, j=j, slope=slope, t0=t0: samples[j] + slope * (t - t0)
        t = t0
        while True:
            t, z, after = _interval(model, mode, t, t1, z, a, rtol, atol)
            if after != mode:
                events.append((t, after))
                if len(events) > max_events:
                    raise RuntimeError("too many events")
            mode = after
            if t >= t1:
                break
        states[j + 1], modes[j + 1] = z, mode
    forces = np.empty(count)
    for j in range(count):
        if modes[j] == STICK:
            a = lambda t, j=j: samples[j]
            forces[j] = model.holding(j * time_step, states[j, :m], states[j, m:], a)
        else:
            forces[j] = -modes[j] * model.ff
    return dict(states=states, stuck=modes == STICK, friction_force=forces, events=events)
