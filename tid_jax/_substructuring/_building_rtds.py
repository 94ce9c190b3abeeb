"""The numerical substructure of a virtual substructuring test of the inerter in a
building: the structure, the TID's spring and damper (and b_g for error feedback), with
the physical device between the TID's terminal and floor i driven by the actuator along
the stroke r (its motion relative to floor i, the reaction frame).

The building's generalised matrices (`_building`) over `u = (x_1..x_n, r)` without the
device: the stroke's diagonal keeps the spring and damper only (k, c); the terminal
mass, the inertance and the parasitic damping (and a compliant device's series spring)
are physical. A terminal mass on floor i > 0 still couples r to x_i through the
off-diagonal `mt e_i` (its motion relative to the ground is x_i + r): that part is
numerical. With the device's force f_s on r,

    error feedback:  (Mn + b_g e_r e_r^T) u'' + Cn u' + Kn u = G a(t) - (f_s - b_g r*'') e_r,
    conventional:    the r row solved for r' (no r'' in it: it needs mt = 0 or i = 0),

so `z = (u, u')` or `z = (x, x', r)`.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._model._building import (
    BuildingTID,
    Quantity,
    linear_amplitudes,
    quantity_amplitude,
    selection,
)
from .._orbit._settings import SolverSettings
from .._orbit._steady_state import one_by_one
from .._response import point_response
from .._runtime._cache import compiled
from ._rtds_loop import Plan, Point, first_harmonic_phase


class BuildingModel(eqx.Module):
    """The numerical substructure of `system` (its device is the physical one), measuring
    `quantity` and the stroke. The matrices are over `(x_1..x_n, r)`."""

    system: BuildingTID
    mass: Float[Array, "m m"]
    damping: Float[Array, "m m"]
    stiffness: Float[Array, "m m"]
    load: Float[Array, " m"]
    weights: Float[Array, " m"]  # the quantity: weights . u + rate_weights . u'' + kappa a
    rate_weights: Float[Array, " m"]
    kappa: float = eqx.field(static=True)

    def __init__(self, system: BuildingTID, quantity: Quantity):
        n = system.floors
        m = n + 1
        mass, damping, stiffness = (a[:m, :m] for a in system.generalised_matrices())
        self.system = system
        self.mass = mass.at[n, n].set(0.0)
        self.damping = damping.at[n, n].set(system.tid_damping)
        self.stiffness = stiffness.at[n, n].set(system.tid_stiffness)
        self.load = system.load_vector()[:m]
        w, wd, kappa, _ = selection(system, quantity)
        self.weights, self.rate_weights, self.kappa = jnp.asarray(w[:m]), jnp.asarray(wd[:m]), kappa

    @property
    def floors(self) -> int:
        return self.system.floors

    def field(self, plan: Plan, point: Point, t, z, force):
        n = self.floors
        m = n + 1
        a = point.amplitude * jnp.sin(point.omega * t)
        if plan.scheme == "error_feedback":
            u, v = z[:m], z[m:]
            rhs = self.load * a - self.damping @ v - self.stiffness @ u
            mass = self.mass.at[n, n].add(point.guessed_inertance)
            return jnp.concatenate([v, jnp.linalg.solve(mass, rhs.at[n].add(-force))])
        x, v, r = z[:n], z[n:2 * n], z[2 * n]
        # the r row: c (r' - d.x') + k (r - d.x) = G_r a - f_s (Cn[r, x] = -c d)
        c = self.damping[n, n]
        rate = (self.load[n] * a - force - self.stiffness[n, :n] @ x - self.stiffness[n, n] * r
                - self.damping[n, :n] @ v) / c
        rhs = (self.load[:n] * a - self.damping[:n, :n] @ v - self.damping[:n, n] * rate
               - self.stiffness[:n, :n] @ x - self.stiffness[:n, n] * r)
        return jnp.concatenate([v, jnp.linalg.solve(self.mass[:n, :n], rhs), rate[None]])

    def interface(self, z):
        """The stroke r."""
        return z[self.floors] if z.shape[0] == 2 * (self.floors + 1) else z[2 * self.floors]

    def interface_rate(self, plan: Plan, point: Point, t, z, force):
        if plan.scheme == "error_feedback":
            return z[2 * self.floors + 1]
        return self.field(plan, point, t, z, force)[2 * self.floors]

    def _coordinates(self, plan: Plan, z, rates):
        """`u` and `u''` from a state and its derivative."""
        n = self.floors
        if plan.scheme == "error_feedback":
            return z[:n + 1], rates[n + 1:]
        return (jnp.append(z[:n], z[2 * n]),
                jnp.append(rates[n:2 * n], jnp.zeros((), z.dtype)))

    def outputs(self, plan: Plan, point: Point, t, z, force):
        """The measured pair: the quantity and the stroke r."""
        u, accelerations = self._coordinates(plan, z, self.field(plan, point, t, z, force))
        a = point.amplitude * jnp.sin(point.omega * t)
        quantity = self.weights @ u + self.rate_weights @ accelerations + self.kappa * a
        return jnp.stack([quantity, self.interface(z)])

    def linear(self, plan: Plan, point: Point, times):
        """The frictionless whole system's steady state at `times` (backlash left out):
        the substructure's states (rows) and the stroke's r, r', r'' (rows)."""
        n = self.floors
        jw = 1j * point.omega
        amplitudes = linear_amplitudes(self.system, point.omega)[:n + 1]
        phase = point.amplitude * jnp.exp(jw * jnp.asarray(times)[..., None])
        u = amplitudes * phase  # [..., n + 1]
        moved = lambda values: jnp.moveaxis(values, -1, 0)
        position, velocity = moved(u.imag), moved((jw * u).imag)
        if plan.scheme == "error_feedback":
            states = jnp.concatenate([position, velocity])
        else:
            states = jnp.concatenate([position[:n], velocity[:n], position[n:]])
        stroke = jnp.stack([position[n], velocity[n], moved((jw**2 * u).imag)[n]])
        return states, stroke


def check_building_test(system: BuildingTID, scheme: str) -> None:
    """`ValueError` unless the building's test can run: smoothed friction; for the
    conventional scheme, a damper and no terminal mass that couples r to a floor."""
    if system.exact_friction:
        raise ValueError(
            "the substructuring test integrates in real time with fixed steps and needs "
            "smoothed friction: give friction_width > 0 or None, not 0 (exact Coulomb "
            "friction)")
    if scheme == "conventional":
        if not float(system.tid_damping) > 0:
            raise ValueError("tid_damping must be positive for the conventional scheme (it "
                             "solves r' from the damper)")
        if system.inerter_floor > 0 and float(system.terminal_mass) > 0:
            raise ValueError("the conventional scheme takes a terminal mass only with the "
                             "inerter on the ground (inerter_floor = 0): on a floor it "
                             "couples the stroke's acceleration to the floor's")


def building_scale(system: BuildingTID, quantity: Quantity, omegas) -> np.ndarray:
    """Per unit load amplitude, the larger of the frictionless |quantity| and |stroke|
    at `omegas` and the static scale: the size a diverged test is measured against."""
    u = linear_amplitudes(system, jnp.asarray(omegas))
    values = jnp.maximum(jnp.abs(quantity_amplitude(system, quantity, omegas, u)),
                         jnp.abs(u[..., system.floors]))
    return np.maximum(np.asarray(values), float(system.static_scale()))


@compiled
def building_reference(system: BuildingTID, quantity: Quantity, omegas, amplitudes,
                       settings: SolverSettings):
    """The whole building's steady states at the pairs `(omegas, amplitudes)` (the
    device's model of `frequency_response`): peaks of the quantity and the stroke, their
    first harmonics' phases and whether each was found."""
    def one(omega, amplitude):
        orbit, x_max, y_max = point_response(system, omega, amplitude, settings,
                                             quantity=quantity)
        return (x_max, y_max, first_harmonic_phase(orbit.x_samples),
                first_harmonic_phase(orbit.y_samples), orbit.converged)

    return one_by_one(one, system.floors)(omegas, amplitudes)
