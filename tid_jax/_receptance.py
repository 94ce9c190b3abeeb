"""The frictionless and the stuck steady states of any structure with its TID: complex
receptances and the breakaway amplitude, in closed form."""

import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ._model._building import (
    BuildingTID,
    Quantity,
    building_breakaway,
    linear_amplitudes,
    quantity_amplitude,
)
from ._model._checks import check_grid, check_single_storey_quantity
from ._model._linear import Breakaway, LinearReceptance, host_breakaway, host_receptance
from ._model._system import TIDSystem

# Frequencies over the band on which a building's smallest breakaway amplitude is found.
BREAKAWAY_GRID = 4001


def linear_receptance(system: TIDSystem | BuildingTID, omegas: ArrayLike, *,
                      quantity: Quantity | None = None) -> LinearReceptance:
    """Complex amplitudes per unit load amplitude of the frictionless TID (friction and
    backlash left out), at `omegas` (rad/s, scalar or 1-d).

    - A `TIDSystem`: the receptances X/Fe of the host (eq. (3) with host damping) and
      Y/Fe of the inerter terminal, with the real device's parasitic damping, terminal
      mass and series stiffness, m/N.
    - A `BuildingTID`: `host` is its `quantity`'s (default the top floor's displacement)
      and `inerter` the inerter's stroke, per N of a force or per m/s2 of a ground
      acceleration; a one-storey building's are the `TIDSystem`'s.

    **Returns:** a `LinearReceptance` (unpacks as `(host, inerter)`).
    """
    if not isinstance(system, BuildingTID):
        check_single_storey_quantity(quantity)
        return host_receptance(system, omegas)
    quantity = Quantity() if quantity is None else quantity
    quantity.floor_of(system.floors)
    w = jnp.asarray(check_grid("omegas", omegas), float)
    u = linear_amplitudes(system, jnp.atleast_1d(w))
    shape = np.shape(w)
    return LinearReceptance(
        host=quantity_amplitude(system, quantity, jnp.atleast_1d(w), u).reshape(shape),
        inerter=u[..., system.floors].reshape(shape))


def breakaway_amplitude(system: TIDSystem | BuildingTID, omegas: ArrayLike) -> Breakaway:
    """The load amplitudes up to which the steady state with the inerter stuck exists, at
    each of `omegas` (rad/s, scalar or 1-d, finite and positive), and their smallest over
    `[min(omegas), max(omegas)]` (see `Breakaway`). Below it the inerter never slips at
    any frequency of the band: the spring and damper join the floors as if the inerter
    were not there.

    - A `TIDSystem`: forcing amplitudes, N; the minimum exact (for a compliant device, on
      a grid).
    - A `BuildingTID`: N for a force, m/s2 for a ground acceleration; the minimum on a
      grid of `BREAKAWAY_GRID` frequencies over the band.
    """
    if not isinstance(system, BuildingTID):
        return host_breakaway(system, omegas)
    w = np.atleast_1d(np.asarray(check_grid("omegas", omegas), float))
    fine = np.linspace(w.min(), w.max(), BREAKAWAY_GRID)
    values = building_breakaway(system, fine)
    best = int(np.argmin(values))
    return Breakaway(omegas=jnp.asarray(w), amplitude=jnp.asarray(building_breakaway(system, w)),
                     minimum=jnp.asarray(values[best]), omega_minimum=jnp.asarray(fine[best]))
