"""Independent event-driven reference for an inerter device under an imposed displacement.

A test rig imposes the relative displacement ``u(t)`` [m] across the device's terminals
and measures the force ``F(t)`` [N] it needs.  Parameters (SI units): inertance ``b``
[kg], dry friction force ``ff`` [N], parasitic damping ``cp`` [N s/m], series stiffness
``ks`` [N/m], total backlash ``g`` [m], terminal mass ``mt`` [kg].

Rigid device (``ks = inf``)::

    F = (b + mt) u'' + cp u' + ff sign(u')

Compliant device: the mechanism coordinate ``q`` is tied to the driven terminal by the
spring ``ks`` with a dead zone of total width ``g``; ``e = u - q`` is its deflection::

    S = ks D(e),   D(e) = sign(e) max(|e| - g/2, 0)
    F = mt u'' + S
    b q'' + cp q' + ff sign(q') = S

with exact Coulomb friction (static = kinetic): while ``q' = 0`` the mechanism sticks as
long as ``|S| <= ff`` and slips in the direction of ``S`` once ``|S|`` exceeds ``ff``.  At
the first sample ``q' = u'`` and the spring is unstretched (``q = u``) or, with
``loaded``, carries the force the rigid mechanism would.

Method: the state ``(e, q')`` is integrated with ``solve_ivp`` (DOP853) through slip
phases, which end at terminal events: ``q' = 0`` (then stick or reversal) and
``|e| = g/2`` (the kinks of the dead zone, where the integration restarts).  Integrating
the deflection rather than ``q`` keeps the spring force accurate for a stiff spring.  A
stick phase needs no integration (``e`` follows ``u``); the breakaway ``|S| = ff`` is
bracketed between the sample times (the motion's reversals inside a sample interval
included) and refined with ``brentq``, so the sample times must resolve the motion: at
most one reversal of ``u`` per sample interval.  A slip starts only where
``sign(S) S - ff >= 0`` holds in floating point, so it never stops at once.

Pure numpy / scipy; nothing here imports ``tid_jax``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

__all__ = ["PAPER_TESTS", "device_force", "synthetic_records"]

PAPER_TESTS = (  # (frequency Hz, displacement amplitude m, periods), as the paper's Figs. 2-3
    (0.5, 0.02, 3),  # slow friction test
    (3.0, 0.003, 6),
    (4.0, 0.004, 8),
)

_STICK = 0.0
_RTOL = 1e-12
_ATOL = 1e-14  # relative to the deflection and velocity scales
_EDGE = 1e-9  # relative distance to a dead-zone edge within which the motion picks the side
_EPS = np.finfo(float).eps


def _terminal(fun):
    """Mark an event function as terminal, triggered when it goes from + to -."""
    fun.terminal = True
    fun.direction = -1.0
    return fun


def _upper_root(f, a, c):
    """Root of ``f`` in ``[a, c]`` (``f(c) > 0``), returned where ``f >= 0``."""
    if f(a) >= 0.0:
        return a
    r = brentq(f, a, c, xtol=4.0 * _EPS * max(abs(a), abs(c), c - a), rtol=4.0 * _EPS)
    while f(r) < 0.0:
        r = float(np.nextafter(r, c))
    return r


class _Compliant:
    """Event-driven motion of the compliant device; ``deflection()`` at the sample times."""

    def __init__(self, u, v, b, ff, cp, ks, half_gap, atol, max_events):
        self.u, self.v = u, v
        self.b, self.ff, self.cp, self.ks, self.h = b, ff, cp, ks, half_gap
        self.atol = atol
        self.max_events = max_events

    def spring(self, e):
        return self.ks * math.copysign(max(abs(e) - self.h, 0.0), e)

    def decide(self, e):
        """Slip sign (+1, -1) or stick for the mechanism at rest with deflection ``e``."""
        S = self.spring(e)
        for s in (1.0, -1.0):
            if s * S - self.ff >= 0.0:
                return s
        return _STICK

    def edges(self, t, e, w):
        """Events for leaving the current side of the dead zone (inside, e > 0, e < 0)."""
        h = self.h
        if abs(abs(e) - h) <= _EDGE * h:
            side = math.copysign(1.0, e) if e * (self.v(t) - w) > 0.0 else 0.0
        else:
            side = math.copysign(1.0, e) if abs(e) > h else 0.0
        if side == 0.0:
            return [_terminal(lambda t, y: h - y[0]), _terminal(lambda t, y: y[0] + h)]
        return [_terminal(lambda t, y: side * y[0] - h)]

    def slip(self, t0, t1, e0, w0, s):
        """Slip phase with sign ``s`` (free motion without friction) from ``t0`` towards ``t1``.

        Returns the solution, whether an event ended it, and whether that was ``q' = 0``.
        """
        b, cp, ks, h, v = self.b, self.cp, self.ks, self.h, self.v
        fs = s * self.ff

        def rhs(t, y):
            e, w = y
            return (v(t) - w, (ks * math.copysign(max(abs(e) - h, 0.0), e) - cp * w - fs) / b)

        events = []
        if self.ff > 0.0:
            events.append(_terminal(lambda t, y: s * y[1]))
        if h > 0.0:
            events += self.edges(t0, e0, w0)
        sol = solve_ivp(rhs, (t0, t1), (e0, w0), method="DOP853", rtol=_RTOL, atol=self.atol,
                        events=events or None, dense_output=True)
        if sol.status < 0:
            raise RuntimeError(f"integration failed at t = {sol.t[-1]} s: {sol.message}")
        stopped = self.ff > 0.0 and sol.t_events[0].size > 0
        return sol, sol.status == 1, stopped

    def breakaway(self, t0, e0, ts, us, vs):
        """First (time, slip sign) after ``t0`` at which a mechanism stuck with deflection
        ``e0`` at ``t0`` breaks away, given the later sample times ``ts`` and the motion
        ``us``, ``vs`` there; None if it stays stuck up to ``ts[-1]``."""
        u0 = self.u(t0)
        ff = self.ff
        ts = np.concatenate(([t0], ts))
        vs = np.concatenate(([self.v(t0)], vs))
        e = e0 + (np.concatenate(([u0], us)) - u0)
        S = self.ks * np.sign(e) * np.maximum(np.abs(e) - self.h, 0.0)

        def excess(t, s):
            return s * self.spring(e0 + (self.u(t) - u0)) - ff

        for i in np.flatnonzero((np.abs(S[1:]) > ff) | (vs[:-1] * vs[1:] < 0.0)):
            a, c = ts[i], ts[i + 1]
            hits = []
            for s in (1.0, -1.0):
                end = c
                if s * S[i + 1] - ff <= 0.0:
                    if not s * vs[i] > 0.0 > s * vs[i + 1]:
                        continue
                    end = brentq(self.v, a, c, xtol=4.0 * _EPS * max(abs(a), abs(c), c - a),
                                 rtol=4.0 * _EPS)  # extremum of s S: a reversal of u
                    if excess(end, s) <= 0.0:
                        continue
                hits.append((_upper_root(lambda t, s=s: excess(t, s), a, end), s))
            if hits:
                return min(hits)
        return None

    def deflection(self, time, us, vs, e0=0.0):
        """Spring deflection ``e = u - q`` at the sample times, from ``e0``."""
        n = len(time)
        t_end = time[-1]
        out = np.empty(n)
        t, e, w = float(time[0]), float(e0), float(vs[0])
        if self.ff == 0.0:
            mode = 1.0
        elif w != 0.0:
            mode = math.copysign(1.0, w)
        else:
            mode = self.decide(e)
        done = 0
        events = 0
        while True:
            if mode == _STICK:
                hit = self.breakaway(t, e, time[done:], us[done:], vs[done:])
                t1 = t_end if hit is None else hit[0]
                j = int(np.searchsorted(time, t1, "right"))
                u0 = self.u(t)
                out[done:j] = e + (us[done:j] - u0)
                done = j
                if hit is None:
                    break
                e, w, mode = e + (self.u(t1) - u0), 0.0, hit[1]
            else:
                sol, ended, stopped = self.slip(t, t_end, e, w, mode)
                t1 = float(sol.t[-1])
                j = int(np.searchsorted(time, t1, "right"))
                out[done:j] = sol.sol(time[done:j])[0]
                done = j
                if not ended:
                    break
                e, w = float(sol.y[0, -1]), float(sol.y[1, -1])
                if stopped or (self.ff > 0.0 and mode * w <= 0.0):
                    w, mode = 0.0, self.decide(e)
            t = t1
            if t >= t_end:
                break
            events += 1
            if events > self.max_events:
                raise RuntimeError(
                    f"more than {self.max_events} stick/slip/backlash events before "
                    f"t = {t} s of {t_end} s (chattering?)")
        return out


def _samples(fun, time):
    return np.array([float(fun(t)) for t in time])


def device_force(time, displacement, velocity, acceleration, *, inertance, friction_force,
                 parasitic_damping=0.0, series_stiffness=math.inf, backlash=0.0,
                 terminal_mass=0.0, loaded=False, max_events=100_000) -> np.ndarray:
    """Force [N] at the sample times ``time`` [s] (1-D, increasing) for the imposed motion.

    ``displacement``, ``velocity``, ``acceleration`` are callables of a float time giving
    ``u`` [m], ``u'`` [m/s], ``u''`` [m/s^2].  The motion starts at ``time[0]``; the force
    of a rigid device uses ``sign(0) = 0``.  A compliant device starts with ``q' = u'``
    and the spring unstretched or, if ``loaded``, carrying the rigid mechanism's force
    ``b u'' + cp u' + ff sign(u')``.  Raises RuntimeError beyond ``max_events`` phase
    changes.
    """
    time = np.asarray(time, float)
    b, ff, cp = float(inertance), float(friction_force), float(parasitic_damping)
    ks, g, mt = float(series_stiffness), float(backlash), float(terminal_mass)
    if time.ndim != 1 or time.size == 0 or not np.all(np.isfinite(time)):
        raise ValueError("time must be a non-empty 1-D array of finite values")
    if np.any(np.diff(time) <= 0.0):
        raise ValueError("time must be strictly increasing")
    if not b > 0.0:
        raise ValueError(f"inertance must be positive, got {b!r}")
    for name, val in (("friction_force", ff), ("parasitic_damping", cp), ("backlash", g),
                      ("terminal_mass", mt)):
        if not (val >= 0.0 and math.isfinite(val)):
            raise ValueError(f"{name} must be finite and >= 0, got {val!r}")
    if not ks > 0.0:
        raise ValueError(f"series_stiffness must be positive, got {ks!r}")
    if g > 0.0 and math.isinf(ks):
        raise ValueError("backlash needs a finite series_stiffness")

    us = _samples(displacement, time)
    vs = _samples(velocity, time)
    acc = _samples(acceleration, time)
    if math.isinf(ks):
        return (b + mt) * acc + cp * vs + ff * np.sign(vs)

    v_scale = float(np.max(np.abs(vs)))
    force_scale = b * float(np.max(np.abs(acc))) + cp * v_scale + ff
    e_scale = 0.5 * g + force_scale / ks
    atol = np.maximum(_ATOL * np.array([e_scale, v_scale]), np.finfo(float).tiny)
    device = _Compliant(displacement, velocity, b, ff, cp, ks, 0.5 * g, atol, max_events)
    held = b * acc[0] + cp * vs[0] + ff * np.sign(vs[0]) if loaded else 0.0
    e0 = held / ks + math.copysign(0.5 * g, held) if held != 0.0 else 0.0
    e = device.deflection(time, us, vs, e0)
    return mt * acc + ks * np.sign(e) * np.maximum(np.abs(e) - 0.5 * g, 0.0)


def synthetic_records(*, noise=0.01, seed=0, rate=1000.0, tests=PAPER_TESTS, phase=0.3,
                      **device) -> list[dict]:
    """One record per test ``(f [Hz], X [m], periods)``: ``dict(time, displacement, force)``.

    ``u = X sin(2 pi f t + phase)`` sampled at ``rate`` [Hz] from ``t = 0`` over the whole
    periods (end point excluded; the phase keeps samples off the reversals, where the
    friction force is undetermined); force from :func:`device_force` with the ``device`` keywords,
    plus Gaussian noise of standard deviation ``noise * max|force|`` of the record (one
    ``numpy.random.default_rng(seed)`` for all records, in order).
    """
    rng = np.random.default_rng(seed)
    records = []
    for f, X, periods in tests:
        w = 2.0 * math.pi * f
        t = np.arange(round(rate * periods / f)) / rate
        force = device_force(
            t,
            lambda t, X=X, w=w: X * math.sin(w * t + phase),
            lambda t, X=X, w=w: X * w * math.cos(w * t + phase),
            lambda t, X=X, w=w: -X * w * w * math.sin(w * t + phase),
            **device,
        )
        sd = noise * float(np.max(np.abs(force)))
        records.append(dict(time=t, displacement=X * np.sin(w * t + phase),
                            force=force + rng.normal(0.0, sd, t.size)))
    return records
