import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from ._checks import check_grid, check_system
from ._system import (
    DEFAULT_FRICTION_WIDTH,
    PAPER_FRICTION_FORCE,
    PAPER_HOST_DAMPING_RATIO,
    PAPER_HOST_FREQUENCY_HZ,
    PAPER_HOST_MASS,
    PAPER_INERTANCE,
    TIDSystem,
    check_values,
)


def den_hartog(mass_ratio: ArrayLike) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """Den Hartog tuning, eq. (10).

    **Arguments:**

    - `mass_ratio`: mu = b / M, positive (any shape).

    **Returns:** `(alpha, xi)`: the squared TID-to-host frequency ratio
    `alpha = 1 / (1 + mu)^2` and the damping ratio `xi = sqrt(3 mu / (8 (1 + mu)))`.
    """
    check_values("mass_ratio", mass_ratio, "positive")
    mu = jnp.asarray(mass_ratio)
    alpha = 1 / (1 + mu) ** 2
    xi = jnp.sqrt(3 * mu / (8 * (1 + mu)))
    return alpha, xi


def den_hartog_tuning(
    host_mass: ArrayLike, host_stiffness: ArrayLike, inertance: ArrayLike
) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """Den Hartog TID stiffness and damping, eq. (11): `k = mu alpha K`,
    `c = 2 xi sqrt(k b)` with `mu = b / M`.

    **Arguments:**

    - `host_mass`: M, kg.
    - `host_stiffness`: K, N/m.
    - `inertance`: b, kg.

    **Returns:** `(k, c)`, N/m and N s/m (the arguments' broadcast shape).
    """
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
    friction_width: float | None = DEFAULT_FRICTION_WIDTH,
) -> TIDSystem:
    """The paper's system (section 4.1): M = 1500 kg, 4 Hz host, 2% host damping,
    b = 75 kg (mu = 0.05), ff = 20 N, with Den Hartog `tid_stiffness`/`tid_damping`
    (42.97 kN/m and 0.479 kN s/m), eqs. (10)-(11), and the ideal inerter.

    **Arguments:**

    - `friction_force`: ff, N (default the paper's 20 N).
    - `friction_width`: 0 (default) for exact Coulomb friction, or the velocity scale of
      the smoothed friction sign, m/s, or None for the relative width (`TIDSystem`).

    **Returns:** a `TIDSystem`.
    """
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


def host_receptance(system: TIDSystem, omega: ArrayLike) -> LinearReceptance:
    """Receptances X/Fe (host, eq. (3) with host damping) and Y/Fe (inerter terminal) of the
    linear TID, with the real device's parasitic damping, terminal mass and series
    stiffness; friction and backlash (nonlinear) are left out.

    The mechanism (inertance b, parasitic damping cp) has the dynamic stiffness
    `Dm = -b w^2 + i w cp`; in series with the stiffness ks it becomes
    `Dm / (1 + Dm / ks)` (exactly `Dm` when ks is infinite), and the terminal mass adds
    `-mt w^2`.

    **Arguments:**

    - `system`: a `TIDSystem` (rigid or compliant).
    - `omega`: circular frequency, rad/s (any shape).

    **Returns:** a `LinearReceptance` (`host`, `inerter`: complex, m/N, the shape of
    `omega`).
    """
    return _linear_receptance(system, jnp.asarray(omega))


@eqx.filter_jit
def _linear_receptance(system: TIDSystem, w) -> LinearReceptance:
    """`host_receptance`, one compiled program (not an array operation each)."""
    mechanism = 1j * w * system.parasitic_damping - system.inertance * w**2
    return _receptance(system, w, mechanism / (1 + mechanism / system.series_stiffness))


def _receptance(system: TIDSystem, w, device) -> LinearReceptance:
    """Host and terminal receptances when the terminal (with its mass) is held to ground
    by the dynamic stiffness `device`."""
    jw = 1j * w
    spring = system.tid_stiffness + jw * system.tid_damping
    inerter_terminal = spring / (spring + device - system.terminal_mass * w**2)  # Y/X
    dynamic_stiffness = (
        system.host_stiffness
        - system.host_mass * w**2
        + jw * system.host_damping
        + spring * (1 - inerter_terminal)
    )
    host = 1 / dynamic_stiffness
    return LinearReceptance(host=host, inerter=host * inerter_terminal)


def stuck_receptance(system: TIDSystem, omega: ArrayLike) -> Complex[Array, "..."]:
    """Host receptance X/Fe with the inerter terminal held still (friction never
    overcome): a single-degree-of-freedom host with stiffness K + k and damping C + c.

    **Arguments:**

    - `system`: a `TIDSystem`.
    - `omega`: circular frequency, rad/s (any shape).

    **Returns:** the complex receptance, m/N, the shape of `omega`.
    """
    return _stuck_receptance(system, jnp.asarray(omega))


@eqx.filter_jit
def _stuck_receptance(system: TIDSystem, w) -> Complex[Array, "..."]:
    """`stuck_receptance`, one compiled program."""
    return 1 / (
        system.host_stiffness
        + system.tid_stiffness
        - system.host_mass * w**2
        + 1j * w * (system.host_damping + system.tid_damping)
    )


class Breakaway(eqx.Module):
    """Forcing amplitudes at which the inerter breaks away (SI units). With the terminal
    stuck, the host is a single-degree-of-freedom oscillator (`stuck_receptance`) and the
    spring and damper put the harmonic force (k + i omega c) X on the terminal; that
    steady state exists while the force stays within the friction force ff.

    - `omegas`: the frequencies, rad/s.
    - `amplitude`: at each frequency, the forcing amplitude (N) up to which the steady
      state with the inerter stuck exists: ff |K + k - M omega^2 + i omega (C + c)| /
      |k + i omega c|.
    - `minimum`, `omega_minimum`: its smallest value over the band from the lowest to
      the highest of `omegas` (exact, not the grid's; for a compliant device, on a grid
      of `COMPLIANT_BREAKAWAY_GRID` frequencies), N, and where, rad/s. Below it the
      inerter never slips at any frequency of the band: the TID acts as a spring and
      damper to ground and its inertance does nothing.

    A compliant device's mechanism is what sticks: the terminal is then held by the
    series spring ks alone (its free play left out), and the force on the mechanism is
    ks Y.
    """

    omegas: Float[Array, " freqs"]
    amplitude: Float[Array, " freqs"]
    minimum: Float[Array, ""]
    omega_minimum: Float[Array, ""]


# Frequencies over the band on which a compliant device's smallest breakaway amplitude is
# found (its amplitude is no longer a ratio of quadratics in omega^2).
COMPLIANT_BREAKAWAY_GRID = 4001


@eqx.filter_jit
def _compliant_breakaway(system: TIDSystem, w) -> Breakaway:
    """`host_breakaway` of a compliant device: the mechanism stuck, the terminal
    (mass mt) held by the series spring ks alone (its free play left out), and the force
    ks Y on the mechanism within ff; the minimum on a fine grid over the band."""
    def amplitude(w):
        held = _receptance(system, w, system.series_stiffness)  # the mechanism stuck
        return system.friction_force / jnp.abs(system.series_stiffness * held.inerter)

    fine = jnp.linspace(jnp.min(w), jnp.max(w), COMPLIANT_BREAKAWAY_GRID)
    values = amplitude(fine)
    best = jnp.argmin(values)
    return Breakaway(omegas=w, amplitude=amplitude(w), minimum=values[best],
                     omega_minimum=fine[best])


def host_breakaway(system: TIDSystem, omegas: ArrayLike) -> Breakaway:
    """The forcing amplitudes up to which the steady state with the inerter stuck exists,
    at each frequency, and their smallest over the band (see `Breakaway`).

    **Arguments:**

    - `system`: the `TIDSystem`.
    - `omegas`: circular frequencies, rad/s (scalar or 1-d, finite and positive); the
      minimum is taken over `[min(omegas), max(omegas)]`.

    **Returns:** a `Breakaway`.
    """
    check_system(system)
    w = np.atleast_1d(np.asarray(check_grid("omegas", omegas), dtype=float))
    if system.compliant:
        return _compliant_breakaway(system, w)
    return _rigid_breakaway(system, w)


@eqx.filter_jit
def _rigid_breakaway(system: TIDSystem, w) -> Breakaway:
    """`host_breakaway` of a rigid device: the minimum over the band in closed
    form."""
    mass, k, c = system.host_mass, system.tid_stiffness, system.tid_damping
    stiffness = system.host_stiffness + k
    damping = system.host_damping + c

    def amplitude(w):
        return system.friction_force * jnp.abs(1 / stuck_receptance(system, w)) / jnp.abs(
            k + 1j * w * c)

    # The squared amplitude is a ratio of polynomials in u = omega^2, stationary where
    # M^2 c^2 u^2 + 2 M^2 k^2 u + (d^2 - 2 a M) k^2 - a^2 c^2 = 0 (a = K + k, d = C + c):
    # the minimum over the band is there or at an end.
    qa = mass**2 * c**2
    qb = 2 * mass**2 * k**2
    qc = (damping**2 - 2 * stiffness * mass) * k**2 - stiffness**2 * c**2
    root = jnp.where(qa > 0, (-qb + jnp.sqrt(jnp.maximum(qb**2 - 4 * qa * qc, 0.0)))
                     / (2 * jnp.where(qa > 0, qa, 1.0)), -qc / qb)
    low, high = jnp.min(w), jnp.max(w)
    candidates = jnp.stack([low, high, jnp.clip(jnp.sqrt(jnp.maximum(root, 0.0)), low, high)])
    values = amplitude(candidates)
    best = jnp.argmin(values)
    return Breakaway(omegas=w, amplitude=amplitude(w), minimum=values[best],
                     omega_minimum=candidates[best])
