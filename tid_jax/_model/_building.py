"""`BuildingTID`: a TID anywhere in a `Structure`, under a force pattern or a ground
acceleration; `Quantity`, the response that is measured; their generalised matrices and
linear (frictionless and stuck) steady states in closed form.

Coordinates `u = (x_1..x_n, r)`: the floors' displacements relative to the ground and
the inerter's stroke `r = y - x_i`, its terminal `y` relative to floor i (the ground for
i = 0). The spring k and damper c join floor j to the terminal; with `d = e_j - e_i`
(`e_0 = 0`) the spring's stretch is `d.x - r` and

    Mg u'' + Cg u' + Kg u = G a(t) - phi e_f,
    Mg = [[M + mt e_i e_i^T, mt e_i], [mt e_i^T, b + mt]],
    Kg = [[K + k d d^T, -k d], [-k d^T, k]],  Cg = [[C + c d d^T, -c d], [-c d^T, c + cp]],

with `phi = ff sgn(u_f')` the inerter's friction on the last coordinate f (here r),
`a(t) = A sin(w t)` and `G` the load per unit amplitude: `(pattern, 0)` for a force,
`-(M 1 + mt e_i, mt)` for a ground acceleration (responses relative to the ground).

A compliant device (a finite `series_stiffness` ks) adds its mechanism's stroke q
(relative to floor i), joined to the terminal (mass mt > 0) by the series spring with
its free play `gap` (a dead zone `D`), and carrying the inertance, the parasitic
damping and the friction: `u = (x_1..x_n, r, q)`, f = q, and

    Mg = [[M + mt e_i e_i^T, mt e_i, 0], [mt e_i^T, mt, 0], [0, 0, b]],
    Kg = [[K + k d d^T, -k d, 0], [-k d^T, k + ks, -ks], [0, -ks, ks]],
    Cg = [[C + c d d^T, -c d, 0], [-c d^T, c, 0], [0, 0, cp]],

`G` with a last 0, and the backlash's force `ks (s - D(s)) (e_r - e_q)` on the right
(s = r - q; zero without backlash).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Complex, Float

from ._checks import (
    check_grid,
    check_precision,
    check_single_storey_quantity,
    check_steady_state_device,
    check_system,
)
from ._linear import den_hartog_tuning
from ._structure import Structure
from ._system import FRICTION_WIDTH_RATIO, TIDSystem, check_values, is_compliant

LOADS = ("force", "ground")
QUANTITIES = ("displacement", "drift", "acceleration")
# what each quantity is measured in
QUANTITY_UNITS = {"displacement": "m", "drift": "m", "acceleration": "m/s2"}
LOAD_UNITS = {"force": "N", "ground": "m/s2"}  # of each load's amplitude
G = 9.80665  # m/s2, the standard acceleration of gravity


class Quantity(eqx.Module):
    """The response a design is judged by: `kind` "displacement" (a floor's, relative to
    the ground), "drift" (floor minus the floor below) or "acceleration" (a floor's
    absolute acceleration) of `floor` (1..n; None: the top floor)."""

    kind: str = eqx.field(static=True, default="displacement")
    floor: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        if self.kind not in QUANTITIES:
            raise ValueError(f"response kind must be one of {list(QUANTITIES)}, "
                             f"got {self.kind!r}")

    def floor_of(self, floors: int) -> int:
        floor = floors if self.floor is None else self.floor
        if not (isinstance(floor, (int, np.integer)) and 1 <= floor <= floors):
            raise ValueError(f"response floor must be a floor 1..{floors}, got {floor!r}")
        return int(floor)

    def describe(self, floors: int) -> str:
        floor = self.floor_of(floors)
        return {"displacement": f"floor {floor} displacement",
                "drift": f"storey {floor} drift",
                "acceleration": f"floor {floor} absolute acceleration"}[self.kind]

    @property
    def unit(self) -> str:
        return QUANTITY_UNITS[self.kind]


def _floor(name: str, value, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not (
            low <= value <= high):
        raise ValueError(f"{name} must be a floor {low}..{high}, got {value!r}")
    return int(value)


def _pattern(value, floors: int) -> Array:
    pattern = np.zeros(floors) if value is None else np.asarray(value, dtype=float)
    if value is None:
        pattern[-1] = 1.0
    if pattern.shape != (floors,):
        raise ValueError(f"force_pattern must have one weight per floor ({floors}), "
                         f"got shape {pattern.shape}")
    if not np.all(np.isfinite(pattern)) or not np.any(pattern != 0):
        raise ValueError("force_pattern must be finite and not all zero")
    return jnp.asarray(pattern)


class BuildingTID(eqx.Module):
    """A tuned inerter damper in a `Structure` (see the module's equations).

    **Fields** (SI units): `structure`; `inertance` b (kg); `friction_force` ff (N);
    `tid_stiffness` k (N/m); `tid_damping` c (N s/m); `friction_width`: 0 (default) for
    exact Coulomb friction, a velocity scale (m/s) of `tanh` smoothing, or None for
    `FRICTION_WIDTH_RATIO` times omega times the static displacement scale;
    `parasitic_damping` cp (N s/m, on the inerter's velocity); `terminal_mass` mt (kg);
    `series_stiffness` ks (N/m; inf, the default: a rigid device) and `backlash` (m, the
    total free play of the series connection) of a compliant device, which needs mt > 0
    (the node between the TID's spring and the series stiffness), and smoothed friction
    where it has backlash.

    **Placement and load** (static): `spring_floor` j (1..n) where the spring and damper
    attach; `inerter_floor` i (0..n, not j; 0: the ground) where the inerter attaches;
    `load` "force" (amplitude A in N on `force_pattern`, one weight per floor, default
    the top floor) or "ground" (ground acceleration amplitude A in m/s2).
    """

    structure: Structure
    inertance: Float[Array, ""]
    friction_force: Float[Array, ""]
    tid_stiffness: Float[Array, ""]
    tid_damping: Float[Array, ""]
    friction_width: Float[Array, ""] | None
    parasitic_damping: Float[Array, ""]
    terminal_mass: Float[Array, ""]
    series_stiffness: Float[Array, ""]
    backlash: Float[Array, ""]
    force_pattern: Float[Array, " n"]
    spring_floor: int = eqx.field(static=True)
    inerter_floor: int = eqx.field(static=True)
    load: str = eqx.field(static=True)
    exact_friction: bool = eqx.field(static=True)
    compliant: bool = eqx.field(static=True)

    def __init__(self, structure: Structure, inertance: ArrayLike, friction_force: ArrayLike,
                 tid_stiffness: ArrayLike, tid_damping: ArrayLike,
                 friction_width: ArrayLike | None = 0.0, *, spring_floor: int = 1,
                 inerter_floor: int = 0, load: str = "force",
                 force_pattern: ArrayLike | None = None, parasitic_damping: ArrayLike = 0.0,
                 terminal_mass: ArrayLike = 0.0, series_stiffness: ArrayLike = math.inf,
                 backlash: ArrayLike = 0.0):
        if not isinstance(structure, Structure):
            raise ValueError("structure must be a tid_jax.Structure")
        floors = structure.floors
        self.structure = structure
        self.spring_floor = _floor("spring_floor", spring_floor, 1, floors)
        self.inerter_floor = _floor("inerter_floor", inerter_floor, 0, floors)
        if self.inerter_floor == self.spring_floor:
            raise ValueError("inerter_floor must differ from spring_floor")
        if load not in LOADS:
            raise ValueError(f"load must be one of {list(LOADS)}, got {load!r}")
        self.load = load
        self.force_pattern = _pattern(force_pattern, floors)
        for name, value, allowed in (
                ("inertance", inertance, "positive"),
                ("friction_force", friction_force, "non-negative"),
                ("tid_stiffness", tid_stiffness, "positive"),
                ("tid_damping", tid_damping, "non-negative"),
                ("parasitic_damping", parasitic_damping, "non-negative"),
                ("terminal_mass", terminal_mass, "non-negative"),
                ("series_stiffness", series_stiffness, "positive or inf"),
                ("backlash", backlash, "non-negative")):
            check_values(name, value, allowed)
            setattr(self, name, jnp.asarray(value, dtype=float))
        if friction_width is not None:
            check_values("friction_width", friction_width, "non-negative")
            friction_width = jnp.asarray(friction_width, dtype=float)
        self.friction_width = friction_width
        self.exact_friction = friction_width is not None and bool(
            np.all(np.asarray(friction_width) == 0))
        self.compliant = is_compliant(series_stiffness)
        self._check_device()

    def _check_device(self):
        concrete = lambda value: not isinstance(value, jax.core.Tracer)
        if self.compliant and concrete(self.terminal_mass) and not np.all(
                np.asarray(self.terminal_mass) > 0):
            raise ValueError("a compliant device (series_stiffness finite) needs "
                             "terminal_mass > 0: the mass of the node between the TID's "
                             "spring and the series stiffness")
        if concrete(self.backlash) and np.any(np.asarray(self.backlash) > 0):
            if not self.compliant:
                raise ValueError("backlash needs a finite series_stiffness (a rigid device "
                                 "has no free play)")
            if self.exact_friction:
                raise ValueError("backlash takes smoothed friction: give friction_width > 0 "
                                 "or None, not 0")

    @property
    def floors(self) -> int:
        return self.structure.floors

    @property
    def coordinates(self) -> int:
        """The generalised coordinates: the floors, the stroke and a compliant device's
        mechanism. The friction acts on the last; the stroke is number `floors`."""
        return self.floors + (2 if self.compliant else 1)

    def replace(self, **changes) -> "BuildingTID":
        """A copy with some fields changed (validated like the constructor)."""
        names = ("structure", "inertance", "friction_force", "tid_stiffness", "tid_damping",
                 "friction_width", "spring_floor", "inerter_floor", "load", "force_pattern",
                 "parasitic_damping", "terminal_mass", "series_stiffness", "backlash")
        unknown = sorted(set(changes) - set(names))
        if unknown:
            raise ValueError(f"unknown BuildingTID field(s) {unknown}; fields are {list(names)}")
        values = {name: getattr(self, name) for name in names}
        values.update(changes)
        structure = values.pop("structure")
        args = [values.pop(name) for name in names[1:6]]
        return BuildingTID(structure, *args, **values)

    def generalised_matrices(self) -> tuple[Array, Array, Array]:
        """`(Mg, Cg, Kg)`, square over the coordinates: floors, the stroke and a compliant
        device's mechanism."""
        s = self.structure
        d = self._direction()
        e_i = self._unit(self.inerter_floor)
        mt, b, k, c = self.terminal_mass, self.inertance, self.tid_stiffness, self.tid_damping
        # the floors and the terminal; the inertance and cp on the friction's coordinate
        inertance = jnp.zeros(self.coordinates - self.floors).at[-1].set(b)
        parasitic = jnp.zeros_like(inertance).at[-1].set(self.parasitic_damping)
        zero = jnp.zeros_like(inertance).at[0].set(1.0)  # the terminal's row
        mass = _coupled(s.mass_matrix + mt * jnp.outer(e_i, e_i), mt * zero, mt * e_i,
                        inertance)
        stiffness = _coupled(s.stiffness_matrix + k * jnp.outer(d, d), k * zero, -k * d,
                             jnp.zeros_like(inertance))
        damping = _coupled(s.damping_matrix + c * jnp.outer(d, d), c * zero, -c * d,
                           parasitic)
        if self.compliant:
            series = self.series_stiffness * jnp.array([[1.0, -1.0], [-1.0, 1.0]])
            stiffness = stiffness.at[self.floors:, self.floors:].add(series)
        return mass, damping, stiffness

    def play_direction(self) -> Float[Array, " m"]:
        """`ks (e_r - e_q)`, zero for a rigid device: the generalised force of a compliant
        device's backlash is this times `s - D(s)`, s = r - q its series spring's stretch
        and D the dead zone (the spring's force is `ks D(s)`, not the `ks s` of `Kg`)."""
        if not self.compliant:
            return jnp.zeros(self.coordinates)
        return jnp.zeros(self.coordinates).at[self.floors].set(self.series_stiffness).at[
            -1].set(-self.series_stiffness)

    def _unit(self, floor: int) -> Array:
        return jnp.zeros(self.floors).at[floor - 1].set(1.0 if floor > 0 else 0.0)

    def _direction(self) -> Array:
        return self._unit(self.spring_floor) - self._unit(self.inerter_floor)

    def load_vector(self) -> Float[Array, " m"]:
        """G, the generalised load per unit amplitude (N per N, or N per m/s2)."""
        device = jnp.zeros(self.coordinates - self.floors)
        if self.load == "force":
            return jnp.concatenate([self.force_pattern, device])
        s = self.structure
        e_i = self._unit(self.inerter_floor)
        floors = s.mass_matrix @ jnp.ones(self.floors) + self.terminal_mass * e_i
        return -jnp.concatenate([floors, device.at[0].set(self.terminal_mass)])

    def static_scale(self) -> Float[Array, ""]:
        """d, the largest floor displacement of the bare structure under the static load
        per unit amplitude (m per N, or m per m/s2): the unit of the scaled states."""
        s = self.structure
        g = self.load_vector()[:self.floors]
        return jnp.max(jnp.abs(jnp.linalg.solve(s.stiffness_matrix, g)))

    def width_at(self, amplitude, omega) -> Float[Array, "..."]:
        """The friction width (m/s) at amplitude A and frequency omega."""
        if self.friction_width is not None:
            return self.friction_width
        return FRICTION_WIDTH_RATIO * omega * amplitude * self.static_scale()

    def first_mode(self) -> tuple[float, float, float]:
        """The bare structure's first mode seen by the TID: its natural frequency (rad/s)
        and its modal mass and stiffness with the mode scaled to a unit relative motion
        of the TID's floors (`d.phi = 1`)."""
        omegas, shapes = self.structure.modes()
        shape = shapes[:, 0] / float(np.asarray(self._direction()) @ shapes[:, 0])
        mass = float(shape @ np.asarray(self.structure.mass_matrix) @ shape)
        return float(omegas[0]), mass, mass * float(omegas[0]) ** 2


def _coupled(block, corner, coupling, device):
    """The square matrix of a floors' `block`, the terminal's `corner` entry and
    `coupling` column, and the device's diagonal (its first entry added to the
    terminal's)."""
    n, extra = block.shape[0], device.shape[0]
    matrix = jnp.zeros((n + extra, n + extra)).at[:n, :n].set(block)
    matrix = matrix.at[:n, n].set(coupling).at[n, :n].set(coupling)
    return matrix.at[n:, n:].add(jnp.diag(device)).at[n, n].add(corner[0])


def as_building(system: TIDSystem, load: str = "force") -> BuildingTID:
    """The single-storey host of `system` (a `TIDSystem`) as a one-storey `BuildingTID`
    (its device, friction model and tuning), under a force or a ground acceleration.
    Traceable, and for batched fields too: the fields (checked by `TIDSystem`) are
    placed into a building of the same device and friction model."""
    width = system.friction_width
    with jax.ensure_compile_time_eval():
        template = BuildingTID(
            Structure([[1.0]], [[1.0]], [[0.0]]), 1.0, 0.0, 1.0, 0.0,
            None if width is None else (0.0 if system.exact_friction else 1.0), load=load,
            terminal_mass=1.0, series_stiffness=1.0 if system.compliant else math.inf)
    matrix = lambda value: jnp.reshape(value, jnp.shape(value) + (1, 1))
    fields = [(lambda b: b.structure.mass_matrix, matrix(system.host_mass)),
              (lambda b: b.structure.stiffness_matrix, matrix(system.host_stiffness)),
              (lambda b: b.structure.damping_matrix, matrix(system.host_damping))]
    fields += [(lambda b, name=name: getattr(b, name), getattr(system, name)) for name in (
        "inertance", "friction_force", "tid_stiffness", "tid_damping", "parasitic_damping",
        "terminal_mass", "series_stiffness", "backlash")]
    if width is not None:
        fields.append((lambda b: b.friction_width, width))
    if jnp.ndim(system.host_mass):  # batched: one force pattern per lane
        fields.append((lambda b: b.force_pattern, jnp.ones(jnp.shape(system.host_mass) + (1,))))
    where = lambda b: [get(b) for get, _ in fields]
    values = [jnp.asarray(value, dtype=float) for _, value in fields]
    return eqx.tree_at(where, template, values)


def checked_quantity(system, quantity: "Quantity | None", purpose: str | None = None
                     ) -> "Quantity":
    """The `quantity` a verb measures on `system` (a `BuildingTID`: default the top floor's
    displacement; a `TIDSystem`: its host's, the only one), after the checks of both
    (double precision, the quantity's floor; with `purpose`, that the steady-state
    solvers take a `TIDSystem`'s device)."""
    if isinstance(system, BuildingTID):
        check_precision()
        quantity = Quantity() if quantity is None else quantity
        quantity.floor_of(system.floors)
        return quantity
    check_single_storey_quantity(quantity)
    check_system(system)
    if purpose is not None:
        check_steady_state_device(system, purpose)
    return Quantity()


def building_of(system: "BuildingTID | TIDSystem", load: str) -> BuildingTID:
    """`system` as a `BuildingTID`: itself, or a `TIDSystem`'s host as a one-storey
    building under `load` ("force" or "ground", `as_building`)."""
    if isinstance(system, TIDSystem):
        return as_building(system, load)
    if not isinstance(system, BuildingTID):
        raise ValueError("system must be a TIDSystem or a BuildingTID, got "
                         f"{type(system).__name__}")
    return system


def log_tuned(system: BuildingTID, log_tuning) -> BuildingTID:
    """The system with the TID's `(k, c) = exp(log_tuning)`: the designs' variables."""
    k, c = jnp.exp(log_tuning)
    return eqx.tree_at(lambda s: (s.tid_stiffness, s.tid_damping), system, (k, c))


def log_tuning_of(system: BuildingTID) -> Float[Array, " 2"]:
    """`(ln k, ln c)` of the system's TID (the inverse of `log_tuned`)."""
    return jnp.log(jnp.stack([system.tid_stiffness, system.tid_damping]))


def first_mode_tunings(system: BuildingTID) -> dict[str, tuple[float, float]]:
    """Single-mode tunings `(k, c)` on the first mode (`BuildingTID.first_mode`):
    "den_hartog" (eq. (11)) and "h_infinity", the exact H-infinity optimum of an undamped
    host (Nishihara and Asami 2002)."""
    _, mass, stiffness = system.first_mode()
    b = float(system.inertance)
    k, c = den_hartog_tuning(mass, stiffness, b)
    mu = b / mass
    root = math.sqrt(4 + 3 * mu)
    ratio = 2 / (1 + mu) * math.sqrt(2 * (16 + 23 * mu + 9 * mu**2 + 2 * (2 + mu) * root)
                                     / (3 * (64 + 80 * mu + 27 * mu**2)))
    xi = 0.25 * math.sqrt((8 + 9 * mu - 4 * root) / (1 + mu))
    k_exact = b * ratio**2 * stiffness / mass
    return {"den_hartog": (float(k), float(c)),
            "h_infinity": (k_exact, 2 * xi * math.sqrt(k_exact * b))}


def selection(system: BuildingTID, quantity: Quantity):
    """The chosen quantity as `w . u + wd . u'' + kappa a(t)` per unit of displacement
    (for an acceleration, per unit of acceleration): `(w, wd, kappa, acceleration)` with
    `w`, `wd` over the coordinates."""
    n, m = system.floors, system.coordinates
    floor = quantity.floor_of(n)
    unit = lambda f: np.eye(m)[f - 1] if f > 0 else np.zeros(m)
    zero = np.zeros(m)
    if quantity.kind == "displacement":
        return unit(floor), zero, 0.0, False
    if quantity.kind == "drift":
        return unit(floor) - unit(floor - 1), zero, 0.0, False
    return zero, unit(floor), 1.0 if system.load == "ground" else 0.0, True


def _solve(matrices, vector):
    """`matrices^-1 vector` for a batch of matrices and one vector."""
    rhs = jnp.broadcast_to(vector, matrices.shape[:-1]).astype(complex)
    return jnp.linalg.solve(matrices, rhs[..., None])[..., 0]


def linear_amplitudes(system: BuildingTID, omegas, friction_damping=0.0, stuck=False):
    """Complex amplitudes U per unit load amplitude (`a(t) = Im(e^{i w t})`) of the
    frictionless TID, or with an extra viscous damping on the friction's coordinate (the
    last), or with that coordinate stuck (`stuck`: held, returning the friction force it
    needs as the last entry): `[..., m]` over the coordinates. Backlash is left out."""
    mass, damping, stiffness = system.generalised_matrices()
    g = system.load_vector()
    w = jnp.asarray(omegas)[..., None, None]
    f = system.coordinates - 1
    damping = damping + jnp.zeros_like(damping).at[f, f].set(1.0) * jnp.asarray(
        friction_damping)[..., None, None]
    dynamic = stiffness - w**2 * mass + 1j * w * damping
    if stuck:
        # the friction coordinate's column replaced by the friction force's (-e_f)
        dynamic = dynamic.at[..., :, f].set(0.0).at[..., f, f].set(1.0)
    return _solve(dynamic, g)


def friction_influence(system: BuildingTID, omega) -> tuple[Array, Array]:
    """`(U, V)` at one frequency `omega`: the frictionless amplitudes per unit load (as
    `linear_amplitudes`) and those per unit harmonic force on the friction's coordinate
    (the last). An extra damping c there gives `U - V (i w c U_f) / (1 + i w c V_f)`
    (Sherman and Morrison), the coordinate held `U - V U_f / V_f` with the friction force
    `U_f / V_f` holding it."""
    mass, damping, stiffness = system.generalised_matrices()
    dynamic = stiffness - omega**2 * mass + 1j * omega * damping
    unit = jnp.zeros(system.coordinates).at[-1].set(1.0)
    both = jnp.linalg.solve(dynamic, jnp.stack([system.load_vector(), unit], axis=1) + 0j)
    return both[:, 0], both[:, 1]


def state_space(system: BuildingTID) -> tuple[Array, Array]:
    """`(A, g)` of the frictionless system in first-order form, `z' = A z + g a(t)` with
    `z = (u, u')` (SI; friction and backlash left out)."""
    mass, damping, stiffness = system.generalised_matrices()
    m = mass.shape[0]
    inverse = jnp.linalg.inv(mass)
    A = jnp.zeros((2 * m, 2 * m)).at[:m, m:].set(jnp.eye(m))
    A = A.at[m:, :m].set(-inverse @ stiffness).at[m:, m:].set(-inverse @ damping)
    return A, jnp.concatenate([jnp.zeros(m), inverse @ system.load_vector()])


def quantity_amplitude(system: BuildingTID, quantity: Quantity, omegas,
                       amplitudes: Complex[Array, "... m"]) -> Complex[Array, "..."]:
    """The quantity's complex amplitude from the floors' `amplitudes` (the first n
    entries are used) at `omegas`."""
    w, wd, kappa, _ = selection(system, quantity)
    n = system.floors
    omegas = jnp.asarray(omegas)
    coordinates = amplitudes[..., :n] @ jnp.asarray(w[:n] + 0j)
    accelerations = -omegas**2 * (amplitudes[..., :n] @ jnp.asarray(wd[:n] + 0j))
    return coordinates + accelerations + kappa


def uncontrolled_amplitude(system: BuildingTID, quantity: Quantity, omegas):
    """|quantity| per unit load amplitude of the bare structure (no TID) at `omegas`."""
    s = system.structure
    g = system.load_vector()[:system.floors]
    if system.load == "ground":
        g = -(s.mass_matrix @ jnp.ones(system.floors))
    w = jnp.asarray(omegas)[..., None, None]
    dynamic = s.stiffness_matrix - w**2 * s.mass_matrix + 1j * w * s.damping_matrix
    return jnp.abs(quantity_amplitude(system, quantity, omegas, _solve(dynamic, g)))


def linear_building_response(system: BuildingTID, omegas,
                             quantity: Quantity = Quantity()) -> np.ndarray:
    """|quantity| per unit load amplitude of the frictionless TID (friction_force
    ignored) at `omegas` (rad/s), in closed form: the quantity's unit per N (force) or
    per m/s2 (ground acceleration)."""
    omegas = np.asarray(check_grid("omegas", omegas), float)
    quantity.floor_of(system.floors)
    u = linear_amplitudes(system, jnp.asarray(omegas))
    return np.asarray(jnp.abs(quantity_amplitude(system, quantity, omegas, u)))


def building_breakaway(system: BuildingTID, omegas) -> np.ndarray:
    """The load amplitudes (N, or m/s2) up to which the steady state with the inerter
    stuck exists at `omegas` (rad/s): ff / |phi| with phi the friction force the stuck
    inerter needs per unit amplitude. Below them the structure moves as if the spring
    and damper joined its floors directly and the inertance does nothing."""
    omegas = np.asarray(check_grid("omegas", omegas), float)
    phi = linear_amplitudes(system, jnp.asarray(omegas), stuck=True)[..., -1]
    return np.asarray(system.friction_force / jnp.abs(phi))
