"""Transient response to a general load history with exact Coulomb friction (SI units).

Model: generalised coordinates ``u`` (length ``m``) with::

    Mg u'' + Cg u' + Kg u = g a(t) + F e_f

``Mg`` (symmetric positive definite, possibly non-diagonal), ``Cg``, ``Kg`` symmetric
``m x m``; ``g`` a load vector, ``a(t)`` a scalar load history and ``e_f`` the unit vector
of the last coordinate ``f = m - 1``, which carries the friction force ``F``.
Friction law: exact Coulomb friction with stick, static = kinetic = ``ff >= 0``.  While
sliding ``F = -ff sign(u_f')``.  While stuck (``u_f' = 0``, ``u_f = r`` held) the reduced
``(m-1)``-DOF system is integrated and ``F = -phi`` holds the coordinate, with
``phi = g_f a - Mg[f, x] x'' - Cg[f, x] x' - Kg[f, :] u`` the net force on the ``f`` row
without friction and ``f`` inertia (``x''`` from the stuck dynamics); sticking lasts while
``|phi| <= ff``, then the coordinate slips with ``sign(phi)``.  When ``u_f'`` returns to
zero it sticks if ``|phi| <= ff`` there, else it slides the other way (ties within a
relative ``1e-10`` are broken by ``dphi/dt``).  ``ff = 0``: the linear system.
The system starts at rest at ``t = 0`` (stuck if ``ff > 0`` and ``|phi(0)| <= ff``).

Method: each phase (slip ``+1``, slip ``-1``, stick) is integrated with
``scipy.integrate.solve_ivp`` (DOP853 by default, RK45 on request) with terminal events
(``u_f' = 0`` while slipping, only in the stopping direction; ``phi = +ff`` upwards or
``phi = -ff`` downwards while stuck); the mode is switched here and the integration
restarted at each event with ``u_f'`` set to exactly zero, so that an event does not
refire at its restart point.  With ``max_step = dt`` no step straddles a point ``j dt``
(the solver's steps are cut there), so the kinks of a load that is linear between
samples at ``t = j dt`` are stepped on exactly.  The states at the requested times come
from the solvers' dense output (``t_eval``).

Loads: :func:`white_noise` is band-limited white noise by spectral representation,
tabulated exactly by FFT on a grid of step ``pi / (8 cutoff)`` and interpolated linearly.
:func:`statistics`: Monte Carlo RMS and mean peak of a combination of displacements.

Pure numpy / scipy; nothing here imports ``tid_jax``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import DOP853, RK45, solve_ivp

__all__ = ["simulate", "simulate_detailed", "statistics", "white_noise"]

STICK = 0


def _aligned(base):
    """``base`` (an RK solver class) whose steps never straddle a point ``j * grid``."""

    class Aligned(base):
        def __init__(self, fun, t0, y0, t_bound, grid=math.inf, **kw):
            super().__init__(fun, t0, y0, t_bound, **kw)
            self._final, self._grid = t_bound, grid

        def _step_impl(self):
            if math.isfinite(self._grid):  # stop this step at the next grid point
                nxt = (math.floor(self.t / self._grid + 1e-9) + 1) * self._grid
                self.t_bound = min(self._final, nxt)
            try:
                return super()._step_impl()
            finally:
                self.t_bound = self._final

    return Aligned


_METHODS = {"DOP853": _aligned(DOP853), "RK45": _aligned(RK45)}


class _System:
    """First-order slip and stuck dynamics and the holding force ``phi``."""

    def __init__(self, mass, damping, stiffness, load_vector, friction_force, load):
        M, C, K = (np.atleast_2d(np.asarray(a, float)) for a in (mass, damping, stiffness))
        g = np.asarray(load_vector, float).reshape(-1)
        m = M.shape[0]
        if M.shape != (m, m) or C.shape != (m, m) or K.shape != (m, m) or g.shape != (m,):
            raise ValueError("mass, damping, stiffness must be m x m and load_vector length m")
        if friction_force < 0:
            raise ValueError("friction_force must be >= 0")
        n = m - 1
        self.m, self.n, self.ff, self.load = m, n, float(friction_force), load
        Z, Id = np.zeros((m, m)), np.eye(m)
        Mi = np.linalg.inv(M)
        self.S = np.block([[Z, Id], [-Mi @ K, -Mi @ C]])
        self.e = np.concatenate((np.zeros(m), Mi @ g))
        self.fr = np.concatenate((np.zeros(m), Mi @ Id[n]))  # per unit friction force F
        x = slice(0, n)
        if n:
            Mxi = np.linalg.inv(M[x, x])
            Zn, In = np.zeros((n, n)), np.eye(n)
            self.Ss = np.block([[Zn, In], [-Mxi @ K[x, x], -Mxi @ C[x, x]]])
            self.es = np.concatenate((np.zeros(n), Mxi @ g[:n]))
            self.hs = np.concatenate((np.zeros(n), -Mxi @ K[:n, n]))  # per unit r
            w = M[n, :n] @ Mxi
        else:  # nothing moves while stuck: a dummy state with zero derivative
            self.Ss, self.es, self.hs, w = np.zeros((1, 1)), np.zeros(1), np.zeros(1), []
        w = np.asarray(w, float)
        self.phi_a = g[n] - w @ g[:n]
        self.phi_x = -K[n, :n] + w @ K[x, x]
        self.phi_v = -C[n, :n] + w @ C[x, x]
        self.phi_r = -K[n, n] + w @ K[:n, n]

    def a(self, t):
        return float(self.load(t))

    # --- state conversions ---------------------------------------------------------------
    def reduce(self, z):
        n, m = self.n, self.m
        return np.concatenate((z[:n], z[m:m + n])) if n else np.zeros(1)

    def expand(self, y, r):
        """Full states (rows) from reduced states y (columns) with u_f = r, u_f' = 0."""
        y = np.atleast_2d(np.asarray(y, float).T)
        n, k = self.n, y.shape[0]
        full = np.zeros((k, 2 * self.m))
        full[:, :n], full[:, n] = y[:, :n], r
        full[:, self.m:self.m + n] = y[:, n:2 * n]
        return full

    # --- right-hand sides ------------------------------------------------------------------
    def slip_rhs(self, s):
        S, e, f, a = self.S, self.e, -s * self.ff * self.fr, self.a
        return lambda t, z: S @ z + e * a(t) + f

    def stuck_rhs(self, r):
        S, e, h, a = self.Ss, self.es, r * self.hs, self.a
        return lambda t, y: S @ y + e * a(t) + h

    # --- holding force and the stick / slip decision ---------------------------------------
    def phi(self, t, y, r):
        n = self.n
        return (self.phi_a * self.a(t) + self.phi_x @ y[:n] + self.phi_v @ y[n:2 * n]
                + self.phi_r * r)

    def dphi(self, t, y, r):
        n = self.n
        h = 1e-8 * (1.0 + abs(t))
        da = (self.a(t + h) - self.a(t)) / h
        acc = self.stuck_rhs(r)(t, y)[n:2 * n]
        return self.phi_a * da + self.phi_x @ y[n:2 * n] + self.phi_v @ acc

    def decide(self, t, z):
        """Mode (+1, -1 slip; 0 stick) of a full state z with u_f' = 0 at time t."""
        y, r, ff = self.reduce(z), z[self.n], self.ff
        p = self.phi(t, y, r)
        tol = 1e-10 * max(ff, abs(p))
        if p > ff + tol:
            return +1
        if p < -ff - tol:
            return -1
        if abs(p) >= ff - tol:
            dp = self.dphi(t, y, r)
            if p > 0 and dp > 0:
                return +1
            if p < 0 and dp < 0:
                return -1
        return STICK


def _phase(sys, mode, t, t1, z, t_eval, kw):
    """One phase from (t, z); returns (t_end, z_end, next mode or None, states at t_eval)."""
    n, m = sys.n, sys.m
    opts = dict(method=_METHODS[kw["method"]], t_eval=t_eval, rtol=kw["rtol"],
                max_step=kw["max_step"], grid=kw["max_step"])
    atol = kw["atol"]
    if mode == STICK:
        r = z[n]

        def up(tt, y):
            return sys.phi(tt, y, r) - sys.ff

        def down(tt, y):
            return sys.phi(tt, y, r) + sys.ff

        up.terminal, up.direction = True, 1.0
        down.terminal, down.direction = True, -1.0
        if np.ndim(atol):
            atol = sys.reduce(np.asarray(atol, float)) if n else 1.0
        y0 = sys.reduce(z)
        sol = solve_ivp(sys.stuck_rhs(r), (t, t1), y0, events=[up, down], atol=atol, **opts)
        states = sys.expand(np.reshape(sol.y, (len(y0), -1)), r)
        if sol.status == 1:
            hit = 0 if len(sol.t_events[0]) else 1
            t_end = sol.t_events[hit][0]
            return t_end, sys.expand(sol.y_events[hit][0], r)[0], (+1, -1)[hit], states
    else:
        s = 0.0 if mode is None else float(mode)

        def stop(tt, zz):
            return zz[2 * m - 1]

        stop.terminal, stop.direction = True, -s
        sol = solve_ivp(sys.slip_rhs(s), (t, t1), z, events=None if mode is None else [stop],
                        atol=atol, **opts)
        states = np.reshape(sol.y, (2 * m, -1)).T
        if sol.status == 1:
            t_end, z_end = sol.t_events[0][0], sol.y_events[0][0].copy()
            z_end[2 * m - 1] = 0.0
            return t_end, z_end, sys.decide(t_end, z_end), states
    if sol.status != 0:
        raise RuntimeError(sol.message)
    return t1, None, None, states


def simulate_detailed(mass, damping, stiffness, load_vector, friction_force, load, times, *,
                      rtol=1e-9, atol=1e-12, max_step=None, method="DOP853", max_stalls=50):
    """:func:`simulate` plus a dict: ``transitions`` (mode changes, slip reversals
    included), ``stick_time`` [s], ``phases`` (integrated phases), ``events`` (list of
    (time, new mode), mode +1 / -1 slip, 0 stick)."""
    if method not in _METHODS:
        raise ValueError(f"method must be one of {sorted(_METHODS)}")
    sys = _System(mass, damping, stiffness, load_vector, friction_force, load)
    times = np.asarray(times, float)
    if times.ndim != 1 or len(times) == 0 or times[0] != 0.0 or np.any(np.diff(times) <= 0):
        raise ValueError("times must be an increasing 1-D array starting at 0")
    kw = dict(rtol=rtol, atol=atol, max_step=np.inf if max_step is None else max_step,
              method=method)
    out = np.empty((len(times), 2 * sys.m))
    t, t1, z, i = 0.0, times[-1], np.zeros(2 * sys.m), 0
    mode = sys.decide(0.0, z) if sys.ff > 0 else None
    events, stick_time, phases, stalls = [], 0.0, 0, 0
    while t1 > 0.0:
        t_end, z_end, nxt, states = _phase(sys, mode, t, t1, z, times[i:], kw)
        phases += 1
        out[i:i + len(states)] = states
        i += len(states)
        if mode == STICK:
            stick_time += t_end - t
        if nxt is None:
            break
        stalls = stalls + 1 if t_end <= t else 0
        if stalls > max_stalls:
            raise RuntimeError(f"no progress at t = {t}: chattering between modes")
        if nxt != mode:
            events.append((float(t_end), int(nxt)))
        t, z, mode = t_end, z_end, nxt
    if t1 == 0.0:
        out[:], i = 0.0, 1
    if i != len(times):
        raise RuntimeError("not all output times were reached")
    info = dict(transitions=len(events), stick_time=stick_time, phases=phases, events=events)
    return out, info


def simulate(mass, damping, stiffness, load_vector, friction_force, load, times, *,
             rtol=1e-9, atol=1e-12, max_step=None, method="DOP853") -> np.ndarray:
    """States ``(len(times), 2m)``, columns ``(u, u')``, from rest at ``t = 0``.

    ``load``: callable ``t -> a(t)``; ``times``: increasing, starting at 0 [s];
    ``friction_force`` ff [N] on the last coordinate (0: frictionless).  ``rtol``,
    ``atol`` (scalar or length ``2m``), ``max_step`` and ``method`` (``"DOP853"`` or
    ``"RK45"``) go to ``solve_ivp``; ``max_step`` also cuts the steps at its multiples
    (pass the sample spacing of a piecewise linear load).
    """
    return simulate_detailed(mass, damping, stiffness, load_vector, friction_force, load,
                             times, rtol=rtol, atol=atol, max_step=max_step, method=method)[0]


class _Tabulated:
    """Linear interpolation of samples ``values`` at ``times = step * j`` (callable);
    constant beyond the ends, as ``np.interp``."""

    def __init__(self, step, values):
        self.step, self.values = float(step), np.asarray(values, float)
        self.times = self.step * np.arange(len(values))
        self._v = self.values.tolist()
        self._d = np.diff(self.values).tolist()

    def __call__(self, t):
        if isinstance(t, (float, int)):  # fast scalar path (inside the integrator)
            x = t / self.step
            j = int(x) if x >= 0.0 else -1
            if 0 <= j < len(self._d):
                return self._v[j] + self._d[j] * (x - j)
        return np.interp(t, self.times, self.values)


def white_noise(psd, cutoff, duration, rng, *, terms=4096):
    """Band-limited white noise ``a(t) = sum_k 2 sqrt(S0 dw) cos(w_k t + phi_k)``.

    ``psd`` S0: two-sided spectral density over angular frequency (variance
    ``2 S0 cutoff``); ``cutoff`` [rad/s]; ``w_k = (k + 1/2) dw``, ``dw = cutoff / terms``,
    ``phi_k`` uniform on [0, 2 pi) from ``rng``.  The sum is evaluated exactly on the grid
    ``t_j = j h``, ``h = pi / (8 cutoff)``, up to ``duration`` (one FFT of length
    ``16 terms``, with ``a(t + 2 pi / dw) = -a(t)``); the returned callable interpolates it
    linearly (floats or arrays of times; attributes ``step``, ``times``, ``values``).
    """
    phases = rng.uniform(0.0, 2.0 * math.pi, terms)
    dw = cutoff / terms
    h = math.pi / (8.0 * cutoff)
    N = 16 * terms  # dw h = 2 pi / N
    c = np.zeros(N, complex)
    c[:terms] = 2.0 * math.sqrt(psd * dw) * np.exp(1j * phases)
    j = np.arange(N)
    base = (np.exp(1j * math.pi * j / N) * np.fft.ifft(c) * N).real  # t_j, j < N
    count = int(math.ceil(duration / h)) + 2
    jj = np.arange(count)
    values = base[jj % N] * np.where((jj // N) % 2 == 0, 1.0, -1.0)
    return _Tabulated(h, values)


def statistics(mass, damping, stiffness, load_vector, friction_force, output_row, *, psd,
               cutoff, samples, duration, transient, seed, output_step, rtol=1e-8,
               atol=1e-12) -> dict:
    """Monte Carlo RMS and mean peak of ``y = output_row . u`` under :func:`white_noise`.

    ``samples`` realisations from ``np.random.default_rng(seed)``, each from rest over
    ``[0, duration]``, ``y`` sampled every ``output_step`` over ``[transient, duration]``.
    Returns ``rms`` (sqrt of the mean of the per-realisation mean squares), ``rms_se``
    (its standard error by the delta method), ``peak`` (mean of max |y|), ``peak_se``,
    ``mean_squares`` and ``peaks``.  Integration: RK45 with steps cut at the noise's
    grid points (there the steps, not the tolerances, limit the accuracy).
    """
    rng = np.random.default_rng(seed)
    row = np.asarray(output_row, float).reshape(-1)
    m = len(row)
    times = output_step * np.arange(int(math.floor(duration / output_step + 1e-9)) + 1)
    keep = times >= transient - 1e-9 * output_step
    ms, pk = np.empty(samples), np.empty(samples)
    for s in range(samples):
        load = white_noise(psd, cutoff, duration, rng)
        states = simulate(mass, damping, stiffness, load_vector, friction_force, load, times,
                          rtol=rtol, atol=atol, max_step=load.step, method="RK45")
        y = states[keep, :m] @ row
        ms[s], pk[s] = np.mean(y**2), np.max(np.abs(y))
    rms = math.sqrt(np.mean(ms))
    se_ms, se_pk = (float(np.std(v, ddof=1) / math.sqrt(samples)) if samples > 1 else math.nan
                    for v in (ms, pk))
    return dict(rms=rms, rms_se=se_ms / (2.0 * rms), peak=float(np.mean(pk)), peak_se=se_pk,
                mean_squares=ms, peaks=pk)
