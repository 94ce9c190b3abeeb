"""Recorded ground motions: PEER NGA `.AT2` files and two-column CSV records read and
checked, scaled to a peak ground acceleration, and the frictionless structure's exact
time history under them.

Between two samples the ground acceleration is taken as the straight line through them
(first-order hold); the linear state `z' = A z + g a(t)` then advances exactly over a
step by matrix exponentials (Van Loan's block form), so the time step is the record's
own and the only error is that of the record's interpolation.
"""

import math
import re
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._model._building import BuildingTID, G, Quantity, building_of, selection, state_space
from .._model._system import TIDSystem

_AT2_STEP = re.compile(r"NPTS\s*=\s*(\d+)\s*,?\s*DT\s*=\s*([0-9.eE+-]+)", re.IGNORECASE)


class GroundMotion(eqx.Module):
    """A recorded ground acceleration: `acceleration` (m/s2) at times `i * time_step`
    (s) and its `name`."""

    acceleration: Float[Array, " samples"]
    time_step: float = eqx.field(static=True)
    name: str = eqx.field(static=True)

    @property
    def duration(self) -> float:
        return self.time_step * (self.acceleration.shape[0] - 1)

    @property
    def peak(self) -> float:
        """The peak ground acceleration, m/s2."""
        return float(np.max(np.abs(np.asarray(self.acceleration))))

    def scaled_to(self, pga_g: float) -> "GroundMotion":
        """The record scaled to a peak ground acceleration of `pga_g` g."""
        if not (isinstance(pga_g, int | float) and math.isfinite(pga_g) and pga_g > 0):
            raise ValueError(f"pga must be a positive number of g, got {pga_g!r}")
        return GroundMotion(self.acceleration * (pga_g * G / self.peak), self.time_step,
                            self.name)


def _bad(path, line: int, problem: str) -> ValueError:
    return ValueError(f"{path}:{line}: {problem}")


def _checked(path, values, lines) -> np.ndarray:
    values = np.asarray(values, float)
    bad = ~np.isfinite(values)
    if np.any(bad):
        raise _bad(path, lines[int(np.argmax(bad))], "acceleration is not a finite number")
    if values.size < 2:
        raise _bad(path, lines[-1] if lines else 1, "a record needs at least two samples")
    return values


def read_at2(path) -> GroundMotion:
    """A PEER NGA `.AT2` record: three lines of text (the third naming the units, g), a
    fourth with `NPTS=` and `DT=` (s), then the accelerations in g."""
    path = Path(path)
    try:
        text = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: cannot read the record ({error})") from None
    if len(text) < 5:
        raise _bad(path, len(text), "not a PEER .AT2 record (a header of four lines, then "
                   "the accelerations)")
    if "G" not in text[2].upper().split():
        raise _bad(path, 3, f"the accelerations must be in units of g, got {text[2].strip()!r}")
    found = _AT2_STEP.search(text[3])
    if found is None:
        raise _bad(path, 4, f"expected 'NPTS= n, DT= s', got {text[3].strip()!r}")
    count, step = int(found.group(1)), float(found.group(2))
    if not (math.isfinite(step) and step > 0):
        raise _bad(path, 4, f"DT must be a positive time step, got {step!r}")
    values, lines = [], []
    for number, line in enumerate(text[4:], start=5):
        for word in line.split():
            try:
                values.append(float(word))
            except ValueError:
                raise _bad(path, number, f"not a number: {word!r}") from None
            lines.append(number)
    if len(values) != count:
        raise _bad(path, len(text), f"NPTS is {count} but the record holds {len(values)} "
                   "values")
    return GroundMotion(jnp.asarray(_checked(path, values, lines) * G), step, path.stem)


def read_csv_record(path, units: str = "g") -> GroundMotion:
    """A two-column CSV record: time (s, evenly spaced) and ground acceleration in
    `units` ("g" or "m/s2"); a first line that is not numbers is a header."""
    if units not in ("g", "m/s2"):
        raise ValueError(f"units must be 'g' or 'm/s2', got {units!r}")
    path = Path(path)
    try:
        text = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: cannot read the record ({error})") from None
    rows, lines = [], []
    for number, line in enumerate(text, start=1):
        if not line.strip():
            continue
        cells = [cell.strip() for cell in line.split(",")]
        if len(cells) != 2:
            raise _bad(path, number, f"expected two columns (time, acceleration), got "
                       f"{len(cells)}")
        try:
            rows.append((float(cells[0]), float(cells[1])))
        except ValueError:
            if rows or number > 1:
                raise _bad(path, number, f"not numbers: {line.strip()!r}") from None
            continue  # the header
        lines.append(number)
    times = np.asarray([row[0] for row in rows])
    values = _checked(path, [row[1] for row in rows], lines)
    steps = np.diff(times)
    uneven = ~(np.abs(steps - steps[0]) <= 1e-6 * steps[0]) | ~(steps > 0)
    if np.any(uneven):
        raise _bad(path, lines[int(np.argmax(uneven)) + 1],
                   "times must increase by one constant step")
    return GroundMotion(jnp.asarray(values * (G if units == "g" else 1.0)),
                        float(np.mean(steps)), path.stem)


class History(eqx.Module):
    """A time history under a record, at the record's samples: `time` (s), `quantity`
    (SI) and `stroke` (m); `stuck` (whether the inerter is stuck at each sample, None
    where not computed) and `friction_force` (N, the force the friction puts on the
    inerter's coordinate, along the stroke: -ff sgn(stroke rate) while slipping, the
    force that holds it while stuck; None where not computed); the quantity's `peak`
    (the largest |quantity| over the samples) and `rms` over the record; and
    `events_capped`, true where the solve failed (a record step needed more mode changes
    than allowed): the history is then NaN from that step on."""

    time: Float[Array, " samples"]
    quantity: Float[Array, " samples"]
    stroke: Float[Array, " samples"]
    peak: Float[Array, ""]
    rms: Float[Array, ""]
    stuck: Bool[Array, " samples"] | None = None
    friction_force: Float[Array, " samples"] | None = None
    events_capped: Bool[Array, ""] = False


def propagators(A, g, dt):
    """`(Phi, Gamma0, Gamma1)`: over a step dt, `z(dt) = Phi z(0) + Gamma0 a(0) +
    Gamma1 (a(dt) - a(0)) / dt` for `z' = A z + g a(t)` with a(t) linear in the step."""
    n = A.shape[0]
    block = jnp.zeros((n + 2, n + 2), A.dtype)
    block = block.at[:n, :n].set(A).at[:n, n].set(g).at[n, n + 1].set(1.0)
    exponential = jax.scipy.linalg.expm(block * dt)
    return exponential[:n, :n], exponential[:n, n], exponential[:n, n + 1]


def linear_history(system: BuildingTID | TIDSystem, motion: GroundMotion,
                   quantity: Quantity = Quantity()) -> History:
    """The frictionless (backlash left out) time history of `quantity` and the stroke of
    `system` (a ground load, friction_force 0) under `motion`, from rest."""
    system = building_of(system, "ground")
    if system.load != "ground":
        raise ValueError("a recorded ground motion needs a system with load='ground'")
    if np.any(np.asarray(system.friction_force) > 0):
        raise ValueError(f"linear_history has no friction, but friction_force is "
                         f"{float(np.max(np.asarray(system.friction_force)))!r} N: use "
                         "friction_history, or give friction_force=0")
    return _linear_history(system, motion, quantity)


@eqx.filter_jit
def _linear_history(system: BuildingTID, motion: GroundMotion, quantity: Quantity) -> History:
    m = system.coordinates
    A, g = state_space(system)
    phi, gamma0, gamma1 = propagators(A, g, motion.time_step)
    a = motion.acceleration

    def step(z, pair):
        now, later = pair
        z = phi @ z + gamma0 * now + gamma1 * ((later - now) / motion.time_step)
        return z, z

    _, states = jax.lax.scan(step, jnp.zeros(2 * m), (a[:-1], a[1:]))
    states = jnp.concatenate([jnp.zeros((1, 2 * m)), states])
    w, wd, kappa, _ = selection(system, quantity)
    rates = states @ A.T + a[:, None] * g[None, :]
    values = states[:, :m] @ jnp.asarray(w) + rates[:, m:] @ jnp.asarray(wd) + kappa * a
    return History(time=jnp.arange(a.shape[0]) * motion.time_step, quantity=values,
                   stroke=states[:, system.floors], peak=jnp.max(jnp.abs(values)),
                   rms=jnp.sqrt(jnp.mean(values**2)), stuck=jnp.zeros(a.shape[0], bool),
                   friction_force=jnp.zeros(a.shape[0]), events_capped=jnp.asarray(False))


def jennings_envelope(times, rise: float, end: float, decay: float):
    """Jennings, Housner and Tsai's envelope of strong motion: `(t / rise)^2` up to
    `rise` (s), 1 up to `end` (s), then `exp(-decay (t - end))` (decay in 1/s)."""
    t = np.asarray(times, float)
    if not (0 < rise <= end and decay > 0):
        raise ValueError(f"the envelope needs 0 < rise <= end and decay > 0, got rise={rise!r}, "
                         f"end={end!r}, decay={decay!r}")
    return np.where(t < rise, (t / rise) ** 2,
                    np.where(t <= end, 1.0, np.exp(-decay * (t - end))))


def synthetic_motion(load, duration: float, time_step: float, seed: int = 0, *,
                     envelope=None, frequencies: int = 2048,
                     cutoff: float | None = None) -> GroundMotion:
    """An artificial ground acceleration (m/s2) with the two-sided spectrum of `load` (a
    `StationaryLoad`) by spectral representation (Shinozuka):
    `sum_k 2 sqrt(S(w_k) dw) cos(w_k t + phi_k)` over `frequencies` evenly spaced w_k up
    to `cutoff` (rad/s; default the Nyquist frequency pi / time_step), the phases
    uniform from `seed`; times `envelope(t)` (e.g. `jennings_envelope`) if given."""
    for name, value in (("duration", duration), ("time_step", time_step)):
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number of seconds, got {value!r}")
    top = math.pi / time_step if cutoff is None else float(cutoff)
    step = top / frequencies
    omegas = (np.arange(frequencies) + 0.5) * step
    phases = np.random.default_rng(seed).uniform(0.0, 2 * np.pi, frequencies)
    times = np.arange(int(round(duration / time_step)) + 1) * time_step
    amplitudes = 2 * np.sqrt(np.asarray(load.spectrum(omegas)) * step)
    values = np.zeros_like(times)
    for block in range(0, frequencies, 256):  # (memory: times x 256 at a time)
        part = slice(block, block + 256)
        values += np.cos(np.outer(times, omegas[part]) + phases[part]) @ amplitudes[part]
    if envelope is not None:
        values = values * np.asarray(envelope(times))
    return GroundMotion(jnp.asarray(values), float(time_step), f"{load.kind} seed {seed}")
