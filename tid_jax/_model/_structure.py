"""`Structure`: a linear host of n degrees of freedom in floor coordinates (floors 1..n
from the ground, displacements relative to the ground), given as a shear building or as
its mass, stiffness and damping matrices, checked on entry."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._system import check_values

# Relative tolerance of the symmetry and definiteness checks of user matrices.
_MATRIX_RTOL = 1e-9


def _matrix(name: str, value, n: int | None = None) -> np.ndarray:
    """A square, finite, symmetric matrix, or a `ValueError` naming `name`."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a square matrix of numbers") from None
    if array.ndim != 2 or array.shape[0] != array.shape[1] or array.shape[0] == 0:
        raise ValueError(f"{name} must be a square matrix, got shape {array.shape}")
    if n is not None and array.shape[0] != n:
        raise ValueError(f"{name} must be {n} x {n} (as mass_matrix), got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    scale = np.max(np.abs(array))
    if np.max(np.abs(array - array.T)) > _MATRIX_RTOL * scale:
        raise ValueError(f"{name} must be symmetric")
    return array


def _definite(name: str, matrix: np.ndarray, strict: bool) -> None:
    lowest = np.linalg.eigvalsh(matrix)[0]
    scale = np.max(np.abs(matrix))
    if strict and not lowest > _MATRIX_RTOL * scale:
        raise ValueError(f"{name} must be positive definite (lowest eigenvalue {lowest:.6g})")
    if not strict and lowest < -_MATRIX_RTOL * scale:
        raise ValueError(
            f"{name} must be positive semi-definite (lowest eigenvalue {lowest:.6g})")


def _vector(name: str, value, allowed: str) -> np.ndarray:
    array = np.atleast_1d(np.asarray(value, dtype=float)) if np.ndim(value) <= 1 else None
    if array is None:
        raise ValueError(f"{name} must be a list of numbers")
    check_values(name, array, allowed)
    return array


def _modes(mass: np.ndarray, stiffness: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies (rad/s, ascending) and mass-normalised mode shapes (columns)."""
    lower = np.linalg.cholesky(mass)
    inverse = np.linalg.inv(lower)
    values, vectors = np.linalg.eigh(inverse @ stiffness @ inverse.T)
    return np.sqrt(values), inverse.T @ vectors


def modal_damping(mass, stiffness, ratio: float) -> np.ndarray:
    """The damping matrix that gives every mode the damping ratio `ratio`:
    `M Phi diag(2 ratio w) Phi^T M` with mass-normalised modes `Phi`."""
    check_values("damping_ratio", ratio, "non-negative")
    omegas, shapes = _modes(np.asarray(mass, float), np.asarray(stiffness, float))
    weighted = mass @ shapes
    return weighted @ np.diag(2 * float(ratio) * omegas) @ weighted.T


def rayleigh_damping(mass, stiffness, ratios, frequencies_hz) -> np.ndarray:
    """Rayleigh damping `a0 M + a1 K` with the damping ratios `ratios` at the two
    frequencies `frequencies_hz`."""
    ratios = _vector("rayleigh.ratios", ratios, "non-negative")
    frequencies = _vector("rayleigh.frequencies_hz", frequencies_hz, "positive")
    if ratios.shape != (2,) or frequencies.shape != (2,):
        raise ValueError("rayleigh needs two ratios and two frequencies_hz")
    if frequencies[0] == frequencies[1]:
        raise ValueError("rayleigh.frequencies_hz must be two different frequencies")
    w1, w2 = 2 * np.pi * frequencies
    z1, z2 = ratios
    a0 = 2 * w1 * w2 * (z1 * w2 - z2 * w1) / (w2**2 - w1**2)
    a1 = 2 * (z2 * w2 - z1 * w1) / (w2**2 - w1**2)
    damping = a0 * np.asarray(mass) + a1 * np.asarray(stiffness)
    _definite("rayleigh damping (a0 M + a1 K)", damping, strict=False)
    return damping


def shear_matrices(storey_masses, storey_stiffnesses) -> tuple[np.ndarray, np.ndarray]:
    """The mass and stiffness matrices of a shear building: storey s (1..n) joins floor
    s - 1 to floor s (floor 0: the ground) with stiffness `storey_stiffnesses[s - 1]`."""
    masses = _vector("storey_masses", storey_masses, "positive")
    springs = _vector("storey_stiffnesses", storey_stiffnesses, "positive")
    if masses.shape != springs.shape:
        raise ValueError(f"storey_stiffnesses must have one entry per storey ({masses.size}), "
                         f"got {springs.size}")
    below = springs
    above = np.append(springs[1:], 0.0)
    stiffness = np.diag(below + above) - np.diag(springs[1:], 1) - np.diag(springs[1:], -1)
    return np.diag(masses), stiffness


class Structure(eqx.Module):
    """A linear structure of n degrees of freedom: `M x'' + C x' + K x = f`, with `x` the
    floors' displacements (m) relative to the ground, floor 1 the lowest.

    **Fields**: `mass_matrix` (kg), `stiffness_matrix` (N/m), `damping_matrix` (N s/m),
    each n x n, symmetric; M and K positive definite, C positive semi-definite.

    Build a shear building with `Structure.shear_building`.
    """

    mass_matrix: Float[Array, "n n"]
    stiffness_matrix: Float[Array, "n n"]
    damping_matrix: Float[Array, "n n"]

    def __init__(self, mass_matrix: ArrayLike, stiffness_matrix: ArrayLike,
                 damping_matrix: ArrayLike):
        mass = _matrix("mass_matrix", mass_matrix)
        n = mass.shape[0]
        stiffness = _matrix("stiffness_matrix", stiffness_matrix, n)
        damping = _matrix("damping_matrix", damping_matrix, n)
        _definite("mass_matrix", mass, strict=True)
        _definite("stiffness_matrix", stiffness, strict=True)
        _definite("damping_matrix", damping, strict=False)
        self.mass_matrix = jnp.asarray(mass)
        self.stiffness_matrix = jnp.asarray(stiffness)
        self.damping_matrix = jnp.asarray(damping)

    @classmethod
    def shear_building(cls, storey_masses: ArrayLike, storey_stiffnesses: ArrayLike, *,
                       damping_ratio: float | None = None,
                       rayleigh: tuple | None = None) -> "Structure":
        """A shear building from its storey masses (kg) and storey stiffnesses (N/m),
        floor 1 first, damped by one `damping_ratio` for every mode (default 0.02) or by
        Rayleigh damping `rayleigh=(ratios, frequencies_hz)` (two of each)."""
        mass, stiffness = shear_matrices(storey_masses, storey_stiffnesses)
        if damping_ratio is not None and rayleigh is not None:
            raise ValueError("give damping_ratio or rayleigh, not both")
        if rayleigh is not None:
            if len(rayleigh) != 2:
                raise ValueError("rayleigh must be (ratios, frequencies_hz)")
            damping = rayleigh_damping(mass, stiffness, *rayleigh)
        else:
            damping = modal_damping(mass, stiffness, 0.02 if damping_ratio is None
                                    else damping_ratio)
        return cls(mass, stiffness, damping)

    @property
    def floors(self) -> int:
        """n, the number of floors (degrees of freedom)."""
        return self.mass_matrix.shape[-1]  # (a batch of structures: the last axis)

    def modes(self) -> tuple[np.ndarray, np.ndarray]:
        """Undamped natural frequencies (rad/s, ascending) and mass-normalised mode shapes
        (columns)."""
        return _modes(np.asarray(self.mass_matrix), np.asarray(self.stiffness_matrix))

    def natural_frequencies_hz(self) -> np.ndarray:
        return self.modes()[0] / (2 * np.pi)


def storey_stiffnesses(stiffness_matrix) -> Array:
    """The storeys' stiffnesses of a structure (N/m; of a batch of stiffness matrices, one
    row each): `-K[s, s - 1]` for the storey below floor s > 1, and the row sum
    `K[0, 0] + K[0, 1]` for the first; a shear building's own."""
    K = jnp.asarray(stiffness_matrix)
    if K.shape[-1] == 1:
        return K[..., 0, :]
    above = jnp.diagonal(K, 1, axis1=-2, axis2=-1)
    return jnp.concatenate([(K[..., 0, 0] + K[..., 0, 1])[..., None], -above], axis=-1)


def storey_springs(floors: int) -> np.ndarray:
    """`(d_s d_s^T)` for each storey s: the stiffness matrix of a unit spring from floor
    s - 1 to floor s (floor 0, the ground, fixed)."""
    springs = np.zeros((floors, floors, floors))
    for s in range(floors):
        springs[s, s, s] = 1.0
        if s:
            springs[s, s - 1, s - 1] = 1.0
            springs[s, s, s - 1] = springs[s, s - 1, s] = -1.0
    return springs
