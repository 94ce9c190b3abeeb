"""The implicit derivatives of a periodic orbit z* = Phi_T(z*, p): the periodicity
residual's Jacobian (`fixed_point_matrix`), the samples over a period with their
Jacobians, and the identity on a converged orbit whose JVP is dz*/dp = (I - dPhi/dz)^{-1}
dPhi/dp, with respect to the fields of a structure (`PlantInputs`)."""

import functools as ft

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Bool, Float

from ._flow import Plant, PlantInputs
from ._period import samples_and_jacobian
from ._settings import SolverSettings


def _held(monodromy: Float[Array, "states states"]) -> Bool[Array, "states 1"]:
    """The coordinates that the period returns unchanged whatever the start (rows of
    `monodromy` that are unit rows): the position of an inerter terminal stuck for the
    whole period (exact friction), along which the periodic orbits form a family."""
    eye = jnp.eye(monodromy.shape[-1], dtype=monodromy.dtype)
    return jnp.all(eye - monodromy == 0, axis=-1, keepdims=True)


def fixed_point_matrix(monodromy: Float[Array, "states states"]) -> Float[Array, "states states"]:
    """`I - monodromy`, the Jacobian of the periodicity residual, with the rows of held
    coordinates (`_held`) replaced by unit rows: of the family of periodic orbits, the
    one through the current value is kept."""
    eye = jnp.eye(monodromy.shape[-1], dtype=monodromy.dtype)
    return jnp.where(_held(monodromy), eye, eye - monodromy)


def moving_part(monodromy: Float[Array, "states states"]) -> Float[Array, "states states"]:
    """`monodromy` with the rows of held coordinates (`_held`) zeroed: their multiplier 1
    becomes 0 and the others are unchanged, so that its multipliers judge the stability
    of the motion about the family of orbits."""
    return jnp.where(_held(monodromy), 0.0, monodromy)


class Samples(eqx.Module):
    """x, y, y' sampled over the period from the orbit's state, and the state after it."""

    xs: Float[Array, " samples"]
    ys: Float[Array, " samples"]
    ws: Float[Array, " samples"]
    z_end: Float[Array, " states"]
    y_events: Float[Array, ""]  # max |y| at the stick-slip transitions (exact friction)
    transitions: Float[Array, ""]  # their number (exact friction; else 0, not counted)


class Periodic(eqx.Module):
    """A periodic orbit as it passes through `with_field_derivatives`: the state, its
    samples, the monodromy matrix and, where the shooting formed them, the samples'
    Jacobians with respect to the state (`state_jacobians`) and to named fields of the
    system (`field_jacobians`, last axis one field each), each a `Samples` of
    Jacobians."""

    z: Float[Array, " states"]
    samples: Samples
    monodromy: Float[Array, "states states"]
    state_jacobians: Samples | None = None
    field_jacobians: Samples | None = None


def sample_jacobians(z, plant: Plant, settings: SolverSettings, columns=None):
    """`period_samples` from `z` of `plant` and their Jacobians with respect to `z` and,
    where given, along the plant's tangents `columns` (a `Plant` with a trailing axis;
    else None), each a `Samples`."""
    primal, of_state, of_columns = samples_and_jacobian(z, plant, settings, columns)
    return (Samples(*primal), Samples(*of_state),
            None if of_columns is None else Samples(*of_columns))


def field_columns(inputs: PlantInputs, fields: tuple[str, ...]):
    """The tangents of the plant of `inputs` along each of the system's scalar `fields`
    (a `Plant` with a trailing axis, one field each)."""
    where = lambda i: [getattr(i.system, name) for name in fields]

    def plant_of(values):
        return eqx.tree_at(where, inputs, list(values)).plant()

    return jax.jacfwd(plant_of)(jnp.stack(where(inputs)))


def _active(dots) -> list[int]:
    """The inputs whose tangents are not symbolic zeros."""
    return [i for i, t in enumerate(dots) if not isinstance(t, SymbolicZero)]


def _orbit_tangent(orbit: Periodic, z_dot=None, samples_dot=None) -> Periodic:
    """The tangent of a `Periodic`: `z_dot` and `samples_dot` (zero where not given), the
    rest zero."""
    zero = jax.tree.map(jnp.zeros_like, orbit)
    if z_dot is None:
        return zero
    return eqx.tree_at(lambda o: (o.z, o.samples), zero, (z_dot, samples_dot))


def with_field_derivatives(settings: SolverSettings, inputs: PlantInputs, orbit: Periodic,
                           plant: Plant, fields: tuple[str, ...] = ()):
    """Identity on a converged `orbit` of `plant`, the plant of `inputs` (as the shooting
    used it, to the bit); its JVP is the implicit derivative of the orbit with respect to
    the arrays of `inputs` (the system's fields, the amplitude, the frequency), each an
    explicit Jacobian over the entries of the arrays with non-zero tangents (so that
    reverse mode can transpose it). The period map is linearised at `plant` itself: a
    plant computed again may differ in its last bits, and where a stuck interval's two
    ends tie, that decides which transition the stroke's peak takes its derivative from.
    Where only the system's scalar `fields` vary, the Jacobians the shooting formed along
    them (`orbit.field_jacobians`) are used."""
    arrays, static = eqx.partition(settings, eqx.is_array)
    leaves, treedef = jax.tree.flatten(inputs)
    numbered = jax.tree.unflatten(treedef, list(range(len(leaves))))
    indices = tuple(getattr(numbered.system, name) for name in fields)
    return _field_identity((static, treedef, indices), (arrays, plant), orbit, *leaves)


@ft.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _field_identity(statics, arrays, orbit, *leaves):
    del statics, arrays, leaves
    return orbit


def _field_jvp(statics, primals, tangents):
    static, treedef, indices = statics
    (arrays, plant), orbit, *leaves = primals
    _, _, *dots = tangents
    settings = eqx.combine(arrays, static)
    active = _active(dots)
    if not active:
        return orbit, _orbit_tangent(orbit)
    sizes = [jnp.size(leaves[i]) for i in active]

    def plant_at(flat):
        changed = list(leaves)
        for i, part in zip(active, jnp.split(flat, np.cumsum(sizes)[:-1]), strict=True):
            changed[i] = part.reshape(jnp.shape(leaves[i]))
        return jax.tree.unflatten(treedef, changed).plant()

    flat = jnp.concatenate([jnp.ravel(leaves[i]) for i in active])
    flat_dot = jnp.concatenate([jnp.ravel(dots[i]) for i in active])
    if orbit.field_jacobians is not None and set(active) <= set(indices):
        of_state = orbit.state_jacobians
        of_fields = jax.tree.map(lambda j: j[..., [indices.index(i) for i in active]],
                                 orbit.field_jacobians)
    else:
        # the plant's tangent along each active entry, then the period's along each
        _, of_state, of_fields = sample_jacobians(orbit.z, plant, settings,
                                                  jax.jacfwd(plant_at)(flat))
    z_dot = jnp.linalg.solve(fixed_point_matrix(of_state.z_end), of_fields.z_end @ flat_dot)
    samples_dot = jax.tree.map(lambda j_state, j_fields: j_state @ z_dot + j_fields @ flat_dot,
                               of_state, of_fields)
    return orbit, _orbit_tangent(orbit, z_dot, samples_dot)


_field_identity.defjvp(_field_jvp, symbolic_zeros=True)
