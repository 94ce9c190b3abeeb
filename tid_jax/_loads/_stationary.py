"""Stationary random loads and the exact stationary covariance of the frictionless
response: white noise, Kanai-Tajimi and Clough-Penzien ground acceleration (the filters
as extra linear states), and the Lyapunov equation of the structure with the TID.

Spectral densities are two-sided over angular frequency: a white noise w of density S0
has `E[w(t) w(t + tau)] = 2 pi S0 delta(tau)`, so that `m x'' + c x' + k x = w` has
`E[x^2] = pi S0 / (k c)`. The load is `a(t)` in the building's units (N on the force
pattern, or m/s2 of ground acceleration): white noise, or the output of a filter driven
by white noise of density S0 (for the ground filters, the bedrock's acceleration):

- Kanai-Tajimi: `x'' + 2 zg wg x' + wg^2 x = -w`, `a = -(2 zg wg x' + wg^2 x)`;
- Clough-Penzien: that `a` through `h'' + 2 zf wf h' + wf^2 h = a`, the ground
  acceleration `h''` (a high-pass filter that removes the Kanai-Tajimi spectrum's finite
  density at zero frequency).

With the building's state `z = (u, u')`, `Mg u'' + Cg u' + Kg u = G a(t)` and the filter
`s' = F s + f w`, `a = h . s + d w`, the joint state `q = (z, s)` obeys `q' = A q + B w`
and its stationary covariance P solves `A P + P A^T + 2 pi S0 B B^T = 0`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._model._building import (
    BuildingTID,
    Quantity,
    building_of,
    log_tuned,
    log_tuning_of,
    selection,
    state_space,
)
from .._model._system import TIDSystem

KINDS = ("white_noise", "kanai_tajimi", "clough_penzien")


class StationaryLoad(eqx.Module):
    """A stationary random load: `kind` "white_noise", "kanai_tajimi" or
    "clough_penzien"; `psd` S0, the two-sided density over angular frequency of the white
    noise (N^2 s/rad, or (m/s2)^2 s/rad); the ground filter's `ground_frequency` wg
    (rad/s) and `ground_damping` zg, and Clough-Penzien's `filter_frequency` wf (rad/s)
    and `filter_damping` zf."""

    kind: str = eqx.field(static=True)
    psd: Float[Array, ""]
    ground_frequency: Float[Array, ""]
    ground_damping: Float[Array, ""]
    filter_frequency: Float[Array, ""]
    filter_damping: Float[Array, ""]

    def __init__(self, kind: str, psd, ground_frequency=None, ground_damping=None,
                 filter_frequency=None, filter_damping=None):
        if kind not in KINDS:
            raise ValueError(f"load kind must be one of {list(KINDS)}, got {kind!r}")
        needs = {"white_noise": (), "kanai_tajimi": ("ground_frequency", "ground_damping"),
                 "clough_penzien": ("ground_frequency", "ground_damping", "filter_frequency",
                                    "filter_damping")}[kind]
        given = dict(psd=psd, ground_frequency=ground_frequency,
                     ground_damping=ground_damping, filter_frequency=filter_frequency,
                     filter_damping=filter_damping)
        for name, value in given.items():
            if name in needs or name == "psd":
                if value is None:
                    raise ValueError(f"a {kind} load needs {name}")
                if not (np.ndim(value) == 0 and np.isfinite(value) and value > 0):
                    raise ValueError(f"{name} must be a positive number, got {value!r}")
            elif value is not None:
                raise ValueError(f"{name} does not apply to a {kind} load")
        self.kind = kind
        for name, value in given.items():
            setattr(self, name, jnp.asarray(np.nan if value is None else value, float))

    def filter(self) -> tuple[Array, Array, Array, Array]:
        """`(F, f, h, d)`: the filter `s' = F s + f w`, `a = h . s + d w` (no states for
        white noise: `a = w`)."""
        if self.kind == "white_noise":
            return jnp.zeros((0, 0)), jnp.zeros(0), jnp.zeros(0), jnp.ones(())
        wg, zg = self.ground_frequency, self.ground_damping
        # s = (x, x'): x'' = -wg^2 x - 2 zg wg x' - w; a = -(wg^2 x + 2 zg wg x')
        F = jnp.zeros((2, 2)).at[0, 1].set(1.0).at[1].set(jnp.stack([-wg**2, -2 * zg * wg]))
        f = jnp.array([0.0, -1.0])
        h = -jnp.stack([wg**2, 2 * zg * wg])
        if self.kind == "kanai_tajimi":
            return F, f, h, jnp.zeros(())
        wf, zf = self.filter_frequency, self.filter_damping
        # (x, x', y, y'): y'' = a - wf^2 y - 2 zf wf y'; the ground acceleration is y''
        G = jnp.zeros((4, 4)).at[:2, :2].set(F).at[2, 3].set(1.0)
        G = G.at[3, :2].set(h).at[3, 2].set(-wf**2).at[3, 3].set(-2 * zf * wf)
        out = jnp.concatenate([h, jnp.stack([-wf**2, -2 * zf * wf])])
        return G, jnp.append(f, jnp.zeros(2)), out, jnp.zeros(())

    def spectrum(self, omegas) -> Array:
        """The load's two-sided density at `omegas` (rad/s)."""
        w = jnp.asarray(omegas)
        if self.kind == "white_noise":
            return self.psd * jnp.ones_like(w)
        wg, zg = self.ground_frequency, self.ground_damping
        ground = (wg**4 + (2 * zg * wg * w) ** 2) / ((wg**2 - w**2) ** 2 + (2 * zg * wg * w) ** 2)
        if self.kind == "kanai_tajimi":
            return self.psd * ground
        wf, zf = self.filter_frequency, self.filter_damping
        high = w**4 / ((wf**2 - w**2) ** 2 + (2 * zf * wf * w) ** 2)
        return self.psd * ground * high


def joint_state_space(system: BuildingTID, load: StationaryLoad):
    """`(A, B)` of the joint state `q = (u, u', s)` driven by the unit white noise w."""
    structure, g = state_space(system)
    F, f, h, d = load.filter()
    n, k = structure.shape[0], F.shape[0]
    A = jnp.zeros((n + k, n + k)).at[:n, :n].set(structure)
    A = A.at[:n, n:].set(jnp.outer(g, h)).at[n:, n:].set(F)
    return A, jnp.concatenate([g * d, f])


def lyapunov(A: Float[Array, "n n"], Q: Float[Array, "n n"]) -> Float[Array, "n n"]:
    """P with `A P + P A^T + Q = 0` (A stable), by the Kronecker form's linear solve:
    `(I (x) A + A (x) I) vec P = -vec Q`; differentiable."""
    n = A.shape[0]
    eye = jnp.eye(n, dtype=A.dtype)
    operator = jnp.kron(eye, A) + jnp.kron(A, eye)
    P = jnp.linalg.solve(operator, -Q.reshape(-1)).reshape(n, n)
    return 0.5 * (P + P.T)


def stationary_covariance(system: BuildingTID | TIDSystem,
                          load: StationaryLoad) -> Float[Array, "n n"]:
    """The stationary covariance of the joint state `(u, u', s)` of the frictionless
    system (its friction and backlash left out) under `load`."""
    system = building_of(system, "force")
    A, B = joint_state_space(system, load)
    return lyapunov(A, 2 * jnp.pi * load.psd * jnp.outer(B, B))


def rms_response(system: BuildingTID | TIDSystem, load: StationaryLoad,
                 quantity: Quantity = Quantity()) -> Float[Array, ""]:
    """The RMS of `quantity` (SI) of the frictionless system under the stationary
    `load`: the square root of `c P c^T` for the quantity's row c of the joint state (an
    absolute acceleration from the state's derivative; the white-noise load's own part of
    it, infinite in variance, needs a filtered ground motion). One compiled program."""
    system = building_of(system, "force")
    quantity.floor_of(system.floors)
    return _rms(system, load, quantity)


@eqx.filter_jit
def _rms(system: BuildingTID, load: StationaryLoad, quantity: Quantity) -> Float[Array, ""]:
    A, B = joint_state_space(system, load)
    P = lyapunov(A, 2 * jnp.pi * load.psd * jnp.outer(B, B))
    row = quantity_row(system, load, quantity, A)
    return jnp.sqrt(row @ P @ row)


def quantity_row(system: BuildingTID, load: StationaryLoad, quantity: Quantity,
                 A: Float[Array, "n n"]) -> Float[Array, " n"]:
    """The row c with `quantity = c q` over the joint state q of `joint_state_space` (its
    matrix `A`), the friction left out."""
    w, wd, kappa, _ = selection(system, quantity)
    m = system.coordinates
    if quantity.kind != "acceleration":
        return jnp.concatenate([jnp.asarray(w), jnp.zeros(A.shape[0] - m)])
    if load.kind == "white_noise" and (kappa != 0 or np.any(wd)):
        raise ValueError("an acceleration under white noise has infinite variance: "
                         "give a filtered load (kanai_tajimi or clough_penzien)")
    # u'' = (A q)[m:2m]; the ground's a = h . s (no d w for the filters)
    _, _, h, _ = load.filter()
    return jnp.asarray(wd) @ A[m:2 * m] + kappa * jnp.concatenate([jnp.zeros(2 * m), h])


def _log_rms(log_tuning, args):
    system, load, quantity = args
    return jnp.log(rms_response(log_tuned(system, log_tuning), load, quantity))


@eqx.filter_jit
def _h2_minimise(system, load, quantity, rtol):
    start = log_tuning_of(system)
    solution = optx.minimise(_log_rms, optx.BFGS(rtol=rtol, atol=rtol), start,
                             args=(system, load, quantity), throw=False, max_steps=256)
    return solution.value, solution.result == optx.RESULTS.successful


def h2_tuning(system: BuildingTID | TIDSystem, load: StationaryLoad,
              quantity: Quantity = Quantity(), *, tol: float = 1e-10) -> tuple[float, float]:
    """The TID's (k, c) that minimise the frictionless RMS of `quantity` under the
    stationary `load` (`rms_response`): BFGS (optimistix) on (log k, log c) from the
    system's own tuning, the gradients by differentiating the Lyapunov solve."""
    system = building_of(system, "force")
    quantity.floor_of(system.floors)
    value, successful = _h2_minimise(system, load, quantity, tol)
    if not bool(successful):
        raise RuntimeError("the H2 tuning did not converge")
    k, c = np.exp(np.asarray(value))
    return float(k), float(c)


class Linearisation(eqx.Module):
    """The statistical linearisation of the inerter's dry friction under a stationary
    load (SI): the friction replaced by the viscous damping `friction_damping`
    c_eq = ff sqrt(2/pi) / sigma_v on its coordinate, sigma_v (`velocity_rms`) that
    coordinate's RMS velocity with c_eq in place; `rms`, the quantity's RMS then.
    `locked`: there is no self-consistent c_eq (the iteration locks the inerter: the
    forces on it stay below what the friction holds in this model); its values NaN."""

    rms: Float[Array, ""]
    friction_damping: Float[Array, ""]
    velocity_rms: Float[Array, ""]
    locked: bool = eqx.field(static=True)


def _velocity_rms(system: BuildingTID, load: StationaryLoad, damping):
    """The RMS velocity of the friction's coordinate with `damping` added on it."""
    changed = eqx.tree_at(lambda s: s.parasitic_damping, system,
                          system.parasitic_damping + damping)
    P = stationary_covariance(changed, load)
    index = 2 * changed.coordinates - 1
    return jnp.sqrt(P[index, index]), changed


def statistical_linearisation(system: BuildingTID | TIDSystem, load: StationaryLoad,
                              quantity: Quantity = Quantity(), *,
                              span: float = 30.0, points: int = 121) -> Linearisation:
    """The self-consistent statistical linearisation of the friction (Caughey): the
    fixed points of sigma_v = RMS velocity with c_eq = ff sqrt(2/pi) / sigma_v, over
    `span` (natural log units) on each side of the frictionless sigma_v, scanned at
    `points` and refined by bisection; the largest attracting one (where
    ln RMS(sigma) - ln sigma falls through zero) is kept."""
    system = building_of(system, "force")
    kappa = system.friction_force * jnp.sqrt(2 / jnp.pi)
    free, _ = _velocity_rms(system, load, 0.0)

    def gap(log_sigma):  # ln RMS(sigma) - ln sigma: positive where sigma_v would grow
        sigma = jnp.exp(log_sigma)
        return jnp.log(_velocity_rms(system, load, kappa / sigma)[0]) - log_sigma

    grid = jnp.log(free) + jnp.linspace(-span, span, points)
    gaps = np.asarray(jax.vmap(gap)(grid))
    falls = np.nonzero((gaps[:-1] > 0) & (gaps[1:] <= 0))[0]
    if falls.size == 0:
        nan = jnp.asarray(np.nan)
        return Linearisation(rms=nan, friction_damping=nan, velocity_rms=nan, locked=True)
    low, high = grid[falls[-1]], grid[falls[-1] + 1]

    def bisect(_, bounds):
        low, high = bounds
        middle = 0.5 * (low + high)
        up = gap(middle) > 0
        return jnp.where(up, middle, low), jnp.where(up, high, middle)

    low, high = jax.lax.fori_loop(0, 60, bisect, (low, high))
    sigma = jnp.exp(0.5 * (low + high))
    damping = kappa / sigma
    _, changed = _velocity_rms(system, load, damping)
    return Linearisation(rms=rms_response(changed, load, quantity), friction_damping=damping,
                         velocity_rms=sigma, locked=False)
