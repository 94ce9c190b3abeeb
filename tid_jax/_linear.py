import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Complex, Float

from ._system import (
    PAPER_FRICTION_FORCE,
    PAPER_HOST_DAMPING_RATIO,
    PAPER_HOST_FREQUENCY_HZ,
    PAPER_HOST_MASS,
    PAPER_INERTANCE,
    TIDSystem,
    check_values,
)


def den_hartog(mass_ratio: ArrayLike) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """Den Hartog tuning, eq. (10): returns `(alpha, xi)`, the squared TID-to-host frequency
    ratio `alpha = 1 / (1 + mu)^2` and damping ratio `xi = sqrt(3 mu / (8 (1 + mu)))`."""
    check_values("mass_ratio", mass_ratio, "positive")
    mu = jnp.asarray(mass_ratio)
    alpha = 1 / (1 + mu) ** 2
    xi = jnp.sqrt(3 * mu / (8 * (1 + mu)))
    return alpha, xi


def den_hartog_tuning(
    host_mass: ArrayLike, host_stiffness: ArrayLike, inertance: ArrayLike
) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """Den Hartog TID stiffness (N/m) and damping (N s/m), eq. (11):
    `k = mu alpha K`, `c = 2 xi sqrt(k b)` with `mu = b / M`."""
    check_values("host_mass", host_mass, "positive")
    check_values("host_stiffness", host_stiffness, "positive")
    check_values("inertance", inertance, "positive")
    mu = jnp.asarray(inertance) / jnp.asarray(host_mass)
    alpha, xi = den_hartog(mu)
    k = mu * alpha * jnp.asarray(host_stiffness)
    c = 2 * xi * jnp.sqrt(k * jnp.asarray(inertance))
    return k, c


def paper_system(
    *,
    friction_force: float = PAPER_FRICTION_FORCE,
    friction_width: float | None = None,
) -> TIDSystem:
    """The paper's system (section 4.1): M = 1500 kg, 4 Hz host, 2% host damping,
    b = 75 kg (mu = 0.05), ff = 20 N, with Den Hartog `tid_stiffness`/`tid_damping`
    (42.97 kN/m and 0.479 kN s/m), eqs. (10)-(11); `friction_width` None takes the
    relative width (`TIDSystem`)."""
    host_mass = PAPER_HOST_MASS
    host_stiffness = host_mass * (2 * math.pi * PAPER_HOST_FREQUENCY_HZ) ** 2
    host_damping = 2 * PAPER_HOST_DAMPING_RATIO * math.sqrt(host_stiffness * host_mass)
    k, c = den_hartog_tuning(host_mass, host_stiffness, PAPER_INERTANCE)
    return TIDSystem(
        host_mass=host_mass,
        host_stiffness=host_stiffness,
        host_damping=host_damping,
        inertance=PAPER_INERTANCE,
        friction_force=friction_force,
        tid_stiffness=k,
        tid_damping=c,
        friction_width=friction_width,
    )


class LinearReceptance(eqx.Module):
    """Complex receptances of the frictionless system, m/N. Unpacks as `(host, inerter)`."""

    host: Complex[Array, "..."]
    inerter: Complex[Array, "..."]

    def __iter__(self):
        return iter((self.host, self.inerter))


def linear_receptance(system: TIDSystem, omega: ArrayLike) -> LinearReceptance:
    """Receptances X/Fe (host, eq. (3) with host damping) and Y/Fe (inerter terminal) of the
    linear TID at circular frequency `omega` (rad/s); friction is ignored."""
    w = jnp.asarray(omega)
    jw = 1j * w
    spring = system.tid_stiffness + jw * system.tid_damping
    inerter_terminal = spring / (spring - system.inertance * w**2)  # Y/X
    dynamic_stiffness = (
        system.host_stiffness
        - system.host_mass * w**2
        + jw * system.host_damping
        + spring * (1 - inerter_terminal)
    )
    host = 1 / dynamic_stiffness
    return LinearReceptance(host=host, inerter=host * inerter_terminal)


def stuck_receptance(system: TIDSystem, omega: ArrayLike) -> Complex[Array, "..."]:
    """Host receptance X/Fe (m/N) with the inerter terminal held still (friction never
    overcome): a single-degree-of-freedom host with stiffness K + k and damping C + c."""
    w = jnp.asarray(omega)
    return 1 / (
        system.host_stiffness
        + system.tid_stiffness
        - system.host_mass * w**2
        + 1j * w * (system.host_damping + system.tid_damping)
    )
