"""The tables of a building's config ([structure], [tid], [load], [response]) and its
amplitudes, checked before anything is computed."""

import math

from .._building import G

BUILDING_TABLES = ("structure", "tid", "load", "response")
_KEYS = {
    "structure": ("storey_masses", "storey_stiffnesses", "damping_ratio", "rayleigh",
                  "mass_matrix", "stiffness_matrix", "damping_matrix"),
    "tid": ("spring_floor", "inerter_floor"),
    "load": ("on", "force_pattern"),
    "response": ("kind", "floor"),
}


def check_tables(config: dict, path: str) -> None:
    """Each building table is a table of known keys, else `ValueError` naming the key."""
    for name in BUILDING_TABLES:
        entries = config.get(name, {})
        if not isinstance(entries, dict):
            raise ValueError(f"config {path}: {name} must be a table [{name}]")
        unknown = [key for key in entries if key not in _KEYS[name]]
        if unknown:
            raise ValueError(f"config {path}: unknown key {unknown[0]!r} in [{name}]; allowed "
                           f"keys are {', '.join(_KEYS[name])}")



def amplitude_value(value) -> float:
    """A ground acceleration amplitude: m/s2, or a text such as "0.2g"."""
    if isinstance(value, str) and value.strip().endswith("g"):
        try:
            return float(value.strip()[:-1]) * G
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, int | float) or not (
            math.isfinite(value) and value > 0):
        raise ValueError(f"amplitudes must be positive numbers (or '0.2g' for a ground "
                       f"acceleration), got {value!r}")
    return float(value)
