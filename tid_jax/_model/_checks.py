"""Checks of user input: each raises `ValueError` with a message that names the input."""

import math

import jax
import numpy as np
from jaxtyping import ArrayLike

from ._system import FIELD_NAMES, TIDSystem


def is_positive(value) -> bool:
    """Whether `value` is a finite positive Python number (not a bool)."""
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value) and value > 0)


def check_precision() -> None:
    """`ValueError` unless JAX computes in double precision: the steady states' tolerances
    (1e-8 and below) are out of reach in single precision, where orbits fail to converge
    after many fallbacks."""
    if not jax.config.jax_enable_x64:
        raise ValueError('tid_jax needs double precision: run jax.config.update('
                         '"jax_enable_x64", True) before importing tid_jax')


def check_system(system) -> None:
    check_precision()
    if not isinstance(system, TIDSystem):
        raise ValueError("system must be a TIDSystem or a BuildingTID, got "
                         f"{type(system).__name__}")


def check_single_storey_quantity(quantity) -> None:
    """`ValueError` unless `quantity` (a `Quantity` or None) is what a `TIDSystem`
    measures: its host's displacement (the one floor's)."""
    if quantity is None or (getattr(quantity, "kind", None) == "displacement"
                            and getattr(quantity, "floor", None) in (None, 1)):
        return
    raise ValueError("a TIDSystem's response is its host's displacement: for another "
                     "quantity pass tid_jax.as_building(system)")


def check_steady_state_device(system: TIDSystem, purpose: str) -> None:
    """`ValueError` unless the steady-state solvers take the system's device: a rigid one,
    or a compliant one with a terminal mass (the node between the TID's spring and the
    series stiffness) and smoothed friction."""
    if system.rigid:
        return
    mass = system.terminal_mass
    if not isinstance(mass, jax.core.Tracer) and not np.all(np.asarray(mass) > 0):
        raise ValueError(
            f"{purpose} needs terminal_mass > 0 with a compliant device (series_stiffness "
            "finite): the mass of the node between the TID's spring and the series stiffness")
    if system.exact_friction:
        raise ValueError(f"{purpose} takes a compliant device with smoothed friction only: give "
                         "friction_width > 0 or None, not 0")


def check_concrete_system(system) -> None:
    """`check_system`, and every field a concrete scalar (not traced, not batched)."""
    check_system(system)
    for name in FIELD_NAMES:
        value = getattr(system, name)
        if value is None and name == "friction_width":
            continue
        if isinstance(value, jax.core.Tracer) or np.ndim(value) != 0:
            raise ValueError(f"system.{name} must be a concrete scalar, got {value!r}")


def check_grid(name: str, values: ArrayLike) -> np.ndarray:
    """A 0- or 1-d grid of finite, positive values, else `ValueError` naming `name`."""
    array = real_array(name, values, "positive")
    if array.ndim > 1:
        raise ValueError(f"{name} must be a scalar or 1-d, got shape {array.shape}")
    return array


def check_optimiser_options(max_steps, tol) -> None:
    """`max_steps` a positive integer and `tol` a positive finite float."""
    integer("max_steps", max_steps, 1)
    if not (isinstance(tol, float) and np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a positive float, got {tol!r}")


def real_array(name: str, value, allowed: str) -> np.ndarray:
    """A concrete array of finite values, `allowed` "positive" (> 0) or "non-negative"
    (>= 0)."""
    if isinstance(value, jax.core.Tracer):
        raise ValueError(f"{name} must be concrete (not traced)")
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None
    if array.size == 0:
        raise ValueError(f"{name} must not be empty")
    bad = ~np.isfinite(array) | ~((array > 0) if allowed == "positive" else (array >= 0))
    if np.any(bad):
        first = array.reshape(-1)[np.argmax(bad.reshape(-1))]
        raise ValueError(f"{name} must be finite and {allowed}, got {float(first)!r}")
    return array


def real_scalar(name: str, value, allowed: str) -> float:
    array = real_array(name, value, allowed)
    if array.ndim != 0:
        raise ValueError(f"{name} must be a scalar, got shape {array.shape}")
    return float(array)


def integer(name: str, value, low: int, high: int | None = None) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | np.integer)
        or value < low
        or (high is not None and value > high)
    ):
        allowed = f">= {low}" if high is None else f"from {low} to {high}"
        raise ValueError(f"{name} must be an integer {allowed}, got {value!r}")
    return int(value)


def choice(name: str, value, allowed: tuple) -> None:
    if not isinstance(value, str) or value not in allowed:
        raise ValueError(f"{name} must be one of {list(allowed)}, got {value!r}")


def check_amplitude(amplitude) -> float:
    if isinstance(amplitude, jax.core.Tracer):
        raise ValueError("amplitude must be concrete (not traced)")
    array = check_grid("amplitude", amplitude)
    if array.ndim != 0:
        raise ValueError(f"amplitude must be a scalar, got shape {array.shape}")
    return float(array)


def check_distinct(name: str, values) -> np.ndarray:
    """A 1-d grid of distinct, finite, positive values, else `ValueError` naming `name`."""
    array = np.atleast_1d(check_grid(name, values))
    if np.unique(array).size != array.size:
        raise ValueError(f"{name} must be distinct, got {array.tolist()}")
    return array
