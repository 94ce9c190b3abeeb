"""The tables of a building's config ([structure], [tid], [load], [response]) and its
amplitudes, checked before anything is computed. [load] also says which load: harmonic
(`frf`, `retune`, ...), or a stationary random load (`random`) with its intensities and
filter."""

import math

from .._model._building import G

BUILDING_TABLES = ("structure", "tid", "load", "response")
HARMONIC = "harmonic"
RANDOM_KINDS = ("white_noise", "kanai_tajimi", "clough_penzien")
LOAD_KINDS = (HARMONIC, *RANDOM_KINDS)
# [load]'s keys of a stationary random load: the intensities S0 and the filter's parameters
# (rad/s and damping ratios), as `StationaryLoad` names them.
RANDOM_KEYS = ("psd_levels", "ground_frequency", "ground_damping", "filter_frequency",
               "filter_damping")
# The commands whose load is not harmonic: `random` (kind one of RANDOM_KINDS) and
# `records` (the recorded ground motions; kind and RANDOM_KEYS do not apply).
NOT_HARMONIC = ("random", "records")
_KEYS = {
    "structure": ("storey_masses", "storey_stiffnesses", "damping_ratio", "rayleigh",
                  "mass_matrix", "stiffness_matrix", "damping_matrix"),
    "tid": ("spring_floor", "inerter_floor"),
    "load": ("on", "force_pattern", "kind", *RANDOM_KEYS),
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
    kind = config.get("load", {}).get("kind", HARMONIC)
    if kind not in LOAD_KINDS:
        raise ValueError(f"config {path}: [load] kind must be one of {', '.join(LOAD_KINDS)}, "
                         f"got {kind!r}")


def check_harmonic(load: dict, command: str) -> None:
    """A harmonic command (all but `NOT_HARMONIC`) takes no random load: `ValueError`
    naming [load]'s kind or key otherwise."""
    if command in NOT_HARMONIC:
        return
    kind = load.get("kind", HARMONIC)
    if kind != HARMONIC:
        raise ValueError(f"[load] kind = {kind!r} is a stationary random load, for "
                         f"'tid-jax random'; 'tid-jax {command}' takes kind = {HARMONIC!r}")
    given = [key for key in RANDOM_KEYS if key in load]
    if given:
        raise ValueError(f"[load] {given[0]} applies to a random load ('tid-jax random'), not "
                         f"to 'tid-jax {command}' (kind = {HARMONIC!r})")


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
