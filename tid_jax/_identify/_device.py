"""The inerter as a device on a test rig: the force it takes to impose a motion across its
terminals.

The paper models its ball-screw inerter as `b y'' + ff sgn(y')` (section 3) and names
what that leaves out. `InerterDevice` adds, in SI units:

- `parasitic_damping` `cp`: viscous damping in parallel with the inertance;
- `series_stiffness` `ks`: the compliance of screw, nut and mounts, a spring between the
  driven terminal and the mechanism (infinite: rigid);
- `backlash` `g`: total free play in that connection (needs a finite `ks`);
- `terminal_mass` `mt`: the device's own moving mass at the driven terminal.

Rigid, the device is algebraic in the imposed motion u(t):
`F = (b + mt) u'' + cp u' + ff sgn(u')`. Compliant, the mechanism's displacement q is a
state: `b q'' + cp q' + ff sgn(q') = S`, `S = ks D(u - q)` with the dead zone
`D(d) = sgn(d) max(|d| - g/2, 0)`, and `F = mt u'' + S`; it starts at the record's first
sample moving with the terminal (`q' = u'`), the spring carrying the force the rigid
mechanism would (`S = b u'' + cp u' + ff sgn(u')`). Friction is smoothed,
`ff tanh(v / width)`, with `width` a small fraction of the record's peak velocity
(`ForceSettings.relative_width`).
"""

import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._model._checks import real_scalar
from .._model._dynamics import dead_zone

DEVICE_FIELDS = ("inertance", "friction_force", "parasitic_damping", "series_stiffness",
                 "backlash", "terminal_mass")


class InerterDevice(eqx.Module):
    """An inerter on a test rig (SI units): inertance `b` (kg), dry friction force `ff`
    (N), parasitic viscous damping (N s/m, default 0), series stiffness (N/m, default
    infinite: rigid), backlash (total free play, m, default 0; needs a finite series
    stiffness) and the moving mass at the driven terminal (kg, default 0)."""

    inertance: float
    friction_force: float
    parasitic_damping: float = 0.0
    series_stiffness: float = math.inf
    backlash: float = 0.0
    terminal_mass: float = 0.0

    def __check_init__(self):
        if any(isinstance(getattr(self, name), jax.core.Tracer) for name in DEVICE_FIELDS):
            return
        real_scalar("inertance", self.inertance, "positive")
        for name in ("friction_force", "parasitic_damping", "backlash", "terminal_mass"):
            real_scalar(name, getattr(self, name), "non-negative")
        stiffness = float(self.series_stiffness)
        if not stiffness > 0:
            raise ValueError(f"series_stiffness must be positive (inf: rigid), got {stiffness!r}")
        if float(self.backlash) > 0 and math.isinf(stiffness):
            raise ValueError("backlash needs a finite series_stiffness (a rigid device with "
                             "free play would impact)")

    @property
    def rigid(self) -> bool:
        """Whether the series stiffness is infinite (a traced one counts as finite)."""
        stiffness = self.series_stiffness
        return not isinstance(stiffness, jax.core.Tracer) and math.isinf(float(stiffness))


# Samples count as evenly spaced where every time is within this fraction of the mean
# spacing from its place on the even grid: the interpolant's interval is then read off the
# grid, at worst its neighbour's cubic carried that far past their shared sample (the two
# agree there in value and slope).
_EVEN_SPACING = 1e-6


class Motion(eqx.Module):
    """An imposed motion sampled at `time` (s): displacement (m), velocity (m/s) and
    acceleration (m/s^2), the derivatives by second-order differences of the samples
    (the acceleration at the ends extrapolated linearly); `evenly_spaced`: whether the
    samples are (as a test rig's, at a fixed rate)."""

    time: Float[Array, " samples"]
    displacement: Float[Array, " samples"]
    velocity: Float[Array, " samples"]
    acceleration: Float[Array, " samples"]
    evenly_spaced: bool = eqx.field(static=True, default=False)

    @classmethod
    def from_samples(cls, time: ArrayLike, displacement: ArrayLike) -> "Motion":
        time, displacement = np.asarray(time, float), np.asarray(displacement, float)
        velocity = np.gradient(displacement, time, edge_order=2)
        h, slope = np.diff(time), np.diff(displacement) / np.diff(time)
        acceleration = np.empty_like(displacement)
        acceleration[1:-1] = 2 * np.diff(slope) / (h[1:] + h[:-1])
        acceleration[0] = acceleration[1] + (acceleration[1] - acceleration[2]) * h[0] / h[1]
        acceleration[-1] = (acceleration[-2]
                            + (acceleration[-2] - acceleration[-3]) * h[-1] / h[-2])
        even = np.linspace(time[0], time[-1], time.size)
        evenly_spaced = bool(np.max(np.abs(time - even))
                             <= _EVEN_SPACING * (time[-1] - time[0]) / (time.size - 1))
        return cls(*(jnp.asarray(a) for a in (time, displacement, velocity, acceleration)),
                   evenly_spaced=evenly_spaced)

    def at(self, t):
        """Displacement and velocity at time `t`: the cubic Hermite interpolant of the
        samples and their velocities."""
        i = self.interval(t)
        h = self.time[i + 1] - self.time[i]
        s = (t - self.time[i]) / h
        u0, u1 = self.displacement[i], self.displacement[i + 1]
        v0, v1 = self.velocity[i] * h, self.velocity[i + 1] * h
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        u = h00 * u0 + h10 * v0 + h01 * u1 + h11 * v1
        du = ((6 * s**2 - 6 * s) * u0 + (3 * s**2 - 4 * s + 1) * v0
              + (-6 * s**2 + 6 * s) * u1 + (3 * s**2 - 2 * s) * v1) / h
        return u, du

    def interval(self, t):
        """The index i of the samples' interval time[i] <= t <= time[i + 1] (the first or
        the last where t lies beyond the samples): read off the grid of evenly spaced
        samples, else found by bisection (a loop at every evaluation of the interpolant,
        which takes most of the time of an integration through the record on a CPU)."""
        time, last = self.time, self.time.shape[0] - 2
        if self.evenly_spaced:
            spacing = (time[-1] - time[0]) / (last + 1)
            i = jnp.floor((t - time[0]) / spacing).astype(int)
        else:
            i = jnp.searchsorted(time, t) - 1
        return jnp.clip(i, 0, last)


class ForceSettings(eqx.Module):
    """Numerical settings of the device's force: the friction width as a fraction of the
    record's peak velocity, and the compliant mechanism's integration (relative and
    absolute tolerances on the state scaled by the peak displacement and velocity, most
    steps per record)."""

    relative_width: float = 1e-4
    rtol: float = 1e-8
    atol: float = 1e-8
    max_steps: int = 200_000


def friction_width(motion: Motion, settings: ForceSettings):
    """The velocity scale (m/s) of the smoothed friction sign along `motion`."""
    return settings.relative_width * jnp.max(jnp.abs(motion.velocity))


def _mechanism_force(device: InerterDevice, acceleration, velocity, width):
    """The force (N) that moves the mechanism (inertance, damping, friction)."""
    return (device.inertance * acceleration + device.parasitic_damping * velocity
            + device.friction_force * jnp.tanh(velocity / width))


def device_force(device: InerterDevice, motion: Motion,
                 settings: ForceSettings = ForceSettings()):
    """The force (N) at the samples of `motion` that imposes it across `device`, and
    whether the mechanism's integration succeeded (always, for a rigid device).
    Traceable in the device's fields; rigid or compliant is decided by whether
    `series_stiffness` is infinite, which must be concrete."""
    width = friction_width(motion, settings)
    terminal = device.terminal_mass * motion.acceleration
    if device.rigid:
        force = terminal + _mechanism_force(device, motion.acceleration, motion.velocity,
                                            width)
        return force, jnp.asarray(True)
    ks, gap = device.series_stiffness, device.backlash
    scale = jnp.stack([jnp.max(jnp.abs(motion.displacement)),
                       jnp.max(jnp.abs(motion.velocity))])

    def field(t, z, args):
        q, w = z * scale
        u, _ = motion.at(t)
        spring = ks * dead_zone(u - q, gap)
        # the mechanism's acceleration, where its force (linear in it) equals the spring's
        rest = _mechanism_force(device, 0.0, w, width)
        return jnp.stack([w, (spring - rest) / device.inertance]) / scale

    # start on the quasi-static path: the spring already carries the rigid mechanism's
    # force, which keeps a lightly damped device from ringing at the record's start
    held = _mechanism_force(device, motion.acceleration[0], motion.velocity[0], width)
    stretch = held / ks + jnp.sign(held) * 0.5 * gap
    z0 = jnp.stack([motion.displacement[0] - stretch, motion.velocity[0]]) / scale
    sol = dfx.diffeqsolve(
        dfx.ODETerm(field), dfx.Tsit5(), motion.time[0], motion.time[-1], None, z0,
        saveat=dfx.SaveAt(ts=motion.time),
        stepsize_controller=dfx.PIDController(rtol=settings.rtol, atol=settings.atol),
        max_steps=settings.max_steps, adjoint=dfx.ForwardMode(), throw=False,
    )
    q = sol.ys[:, 0] * scale[0]
    force = terminal + ks * dead_zone(motion.displacement - q, gap)
    return force, sol.result == dfx.RESULTS.successful
