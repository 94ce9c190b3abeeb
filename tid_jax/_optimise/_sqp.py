"""A trust-region sequential quadratic programming method in two design variables.

It minimises a smooth function f of u = (u0, u1) subject to at most one constraint
c(u) <= 0, from models that carry, at each design, the value, the gradient and the
derivatives of the gradient along u0 and u1 (`Model`): Newton steps within a trust
region on the Lagrangian's quadratic model, the linearised constraint enforced when the
step would break it, and the exact penalty f + weight max(c, 0) as merit function.

It is written here, in NumPy on the host, rather than with optimistix: the problem has
two variables and an inequality constraint (optimistix offers unconstrained minimisers
and least squares, not constrained ones); every model comes with its curvature (exact
across the smooth maximum, by differences of exact gradients within each peak), which a
trust region uses directly; and an evaluation is a host-side loop over batched, compiled
steady-state solves with retries of failed points, not one traceable function.
"""

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

_TINY = np.finfo(float).tiny


class Model(NamedTuple):
    """A smooth maximum at a design: value, gradient in all coordinates, and derivatives
    of the gradient along u0, u1 (rows)."""

    value: float
    grad: np.ndarray
    hess: np.ndarray

    def curvature(self) -> np.ndarray:
        return 0.5 * (self.hess[:, :2] + self.hess[:, :2].T)


def decrement(g, h) -> float:
    """Newton decrement g h^-1 g / 2 (inf where h is not positive definite)."""
    if np.linalg.eigvalsh(h)[0] <= 0:
        return np.inf
    return float(g @ np.linalg.solve(h, g) / 2)


def multiplier(f: Model, c: Model) -> float:
    """First-order estimate of the constraint's multiplier, from grad f + mu grad c = 0."""
    a = c.grad[:2]
    return float(-(f.grad[:2] @ a) / max(a @ a, _TINY))


def lagrangian_curvature(f: Model, c: Model | None) -> np.ndarray:
    if c is None:
        return f.curvature()
    return f.curvature() + max(multiplier(f, c), 0.0) * c.curvature()


def stationary(f: Model, c: Model | None, tol, feasibility) -> bool:
    """Unconstrained: Newton decrement below `tol`. With the constraint active
    (|c| <= `feasibility`), a non-negative multiplier and the decrement along the
    constraint below `tol`."""
    h = lagrangian_curvature(f, c)
    if (c is None or c.value <= 0) and decrement(f.grad[:2], f.curvature()) < tol:
        return True
    if c is None or abs(c.value) > feasibility or multiplier(f, c) < -np.sqrt(tol):
        return False
    a = c.grad[:2]
    n = np.array([-a[1], a[0]]) / max(np.linalg.norm(a), _TINY)
    along = n @ h @ n
    return bool(along > 0 and (n @ f.grad[:2]) ** 2 / (2 * along) < tol)


def trust_step(g, h, radius) -> np.ndarray:
    """Minimiser of g.d + d.h.d / 2 over |d| <= radius (2-norm), h symmetric 2 x 2.
    `ValueError` where g or h is not finite (a step from a failed evaluation)."""
    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(h))):
        raise ValueError(f"trust_step: the gradient {g} and curvature {h.tolist()} must be "
                         "finite (a failed evaluation has no step)")
    values, vectors = np.linalg.eigh(h)
    g_eig = vectors.T @ g
    if values[0] > 0:
        newton = -g_eig / values
        if np.linalg.norm(newton) <= radius:
            return vectors @ newton
    low = max(0.0, -values[0]) + 1e-12 * max(1.0, np.abs(values).max())

    def length(shift):
        return np.linalg.norm(g_eig / (values + shift))

    if length(low) <= radius:  # the hard case: go along the lowest curvature to the boundary
        d = -g_eig / (values + low)
        d[0] = np.sqrt(max(radius**2 - np.sum(d[1:] ** 2), 0.0))
        return vectors @ d
    high = low + np.linalg.norm(g) / radius + np.abs(values).max()
    for _ in range(100):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if length(mid) > radius else (low, mid)
    return vectors @ (-g_eig / (values + high))


def sqp_step(f: Model, c: Model | None, radius) -> np.ndarray:
    """Trust-region step of sequential quadratic programming: the quadratic model of the
    Lagrangian minimised within `radius`, subject to the linearised constraint when the
    unconstrained step would break it (or, if the constraint cannot be reached within
    `radius`, the step towards it)."""
    g, h = f.grad[:2], lagrangian_curvature(f, c)
    step = trust_step(g, h, radius)
    if c is None or c.value + c.grad[:2] @ step <= 0:
        return step
    a = c.grad[:2]
    norm = max(np.linalg.norm(a), _TINY)
    to_line = -c.value * a / norm**2
    if np.linalg.norm(to_line) >= radius:
        return to_line * radius / np.linalg.norm(to_line)
    n = np.array([-a[1], a[0]]) / norm
    along, slope = n @ h @ n, n @ (g + h @ to_line)
    reach = np.sqrt(radius**2 - to_line @ to_line)
    t = -slope / along if along > 0 else -np.sign(slope) * reach
    return to_line + np.clip(t, -reach, reach) * n


def finite(model: Model) -> bool:
    # `_smooth_max` gives no derivatives (None) only with a non-finite value.
    return bool(np.isfinite(model.value) and np.all(np.isfinite(model.grad))
                and np.all(np.isfinite(model.hess)))


def merit(f: Model, c: Model | None, weight) -> float:
    return f.value + (weight * max(c.value, 0.0) if c is not None else 0.0)


def minimise_stage(
    evaluate: Callable,
    current,
    f: Model,
    c: Model | None,
    *,
    max_step: float,
    min_step: float,
    feasibility: float,
    max_steps: int,
    tol: float,
):
    """Trust-region SQP from the design `current` (any object with the design variables
    in `current.u`) whose models are `f` and `c` (None: unconstrained), for at most
    `max_steps` trial steps of length at most `max_step`. `evaluate(u, current)` gives
    `(design, f, c, usable)` at u (from the last accepted design `current`); a trial
    that is not `usable` (a steady state failed) or whose models are not finite is
    rejected. Stops when `stationary` within `tol` (the
    constraint active within `feasibility`), when the predicted decrease falls below
    `tol / 10`, or when the trust radius shrinks below `min_step`. Returns the last
    accepted `(design, f, c, trial steps)`."""
    radius, weight, steps = max_step, 1.0, 0
    for _ in range(max_steps):
        if stationary(f, c, tol, feasibility):
            break
        if c is not None:
            weight = max(weight, 2 * multiplier(f, c))
        step = sqp_step(f, c, radius)
        h = lagrangian_curvature(f, c)
        predicted = -(f.grad[:2] @ step + step @ h @ step / 2)
        if c is not None:
            predicted += weight * (max(c.value, 0.0) - max(c.value + c.grad[:2] @ step, 0.0))
        if predicted < tol / 10:
            break  # nothing left to gain at the noise level of the objective
        trial, t_f, t_c, usable = evaluate(current.u + step, current)
        steps += 1
        # A design where a steady state failed, or whose model is not finite, is a
        # rejected step: its peaks are unknown.
        usable = usable and all(finite(m) for m in (t_f, t_c) if m is not None)
        actual = merit(f, c, weight) - merit(t_f, t_c, weight) if usable else -np.inf
        ratio = actual / predicted if np.isfinite(actual) else -np.inf
        length = np.linalg.norm(step)
        if ratio < 0.25:
            radius = length / 4
        elif ratio > 0.75 and length > 0.9 * radius:
            radius = min(2 * radius, max_step)
        if ratio >= 1e-4:
            current, f, c = trial, t_f, t_c
        elif radius < min_step:
            break  # a jump or kink of the objective: no model fits it
    return current, f, c, steps
