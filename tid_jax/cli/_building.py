"""A multi-storey structure on the command line: a config with a [structure] table (and
[tid], [load], [response]) to a `BuildingTID` and a `Quantity`, its band, description and
JSON record; and where `frf`, `retune`, `sensitivity` and `robust` start, on the paper's
host or a structure (`design_start`, `design_document`)."""

import math
from typing import NamedTuple

import numpy as np

from .._model._building import BuildingTID, Quantity, first_mode_tunings, uncontrolled_amplitude
from .._model._structure import Structure
from .._model._system import TIDSystem
from .._orbit._settings import SolverSettings
from .._peaks import BUILDING_BAND, DEFAULT_FREQUENCIES
from .._runtime._io import write_toml
from ._building_config import BUILDING_TABLES, amplitude_value
from ._common import (
    PROG,
    SOLVER_TABLE,
    CLIError,
    _config_comment,
    _config_data,
    _den_hartog,
    _describe,
    _Output,
    _start,
)
from ._schema import (
    amplitude_unit,
)


def _structure(table: dict) -> Structure:
    matrices = [key for key in ("mass_matrix", "stiffness_matrix", "damping_matrix")
                if key in table]
    try:
        if matrices:
            if len(matrices) != 3:
                raise ValueError("give mass_matrix, stiffness_matrix and damping_matrix")
            return Structure(table["mass_matrix"], table["stiffness_matrix"],
                             table["damping_matrix"])
        for key in ("storey_masses", "storey_stiffnesses"):
            if key not in table:
                raise ValueError(f"[structure] needs {key} (or the three matrices)")
        rayleigh = table.get("rayleigh")
        if rayleigh is not None:
            if not isinstance(rayleigh, dict) or set(rayleigh) != {"ratios", "frequencies_hz"}:
                raise ValueError("rayleigh must be {ratios = [..], frequencies_hz = [..]}")
            rayleigh = (rayleigh["ratios"], rayleigh["frequencies_hz"])
        return Structure.shear_building(table["storey_masses"], table["storey_stiffnesses"],
                                        damping_ratio=table.get("damping_ratio"),
                                        rayleigh=rayleigh)
    except (ValueError, TypeError) as error:
        raise CLIError(f"[structure]: {error}") from None


def building_inputs(inputs: dict) -> tuple[BuildingTID, Quantity, np.ndarray]:
    """The system, the quantity and the amplitudes of a config with a [structure]."""
    structure = _structure(inputs["structure"])
    tid, load, response = (inputs.get(name, {}) for name in BUILDING_TABLES[1:])
    for key in ("host_stiffness", "host_damping"):
        if key in inputs:
            raise CLIError(f"{key} does not apply to a [structure]")
    # exact friction, unless backlash needs it smoothed
    width = inputs.get("friction_width", "relative" if inputs.get("backlash", 0) > 0 else 0.0)
    try:
        system = BuildingTID(
            structure, inputs["inertance"], inputs["friction_force"], 1.0, 0.0,
            None if width == "relative" else width,
            spring_floor=tid.get("spring_floor", 1), inerter_floor=tid.get("inerter_floor", 0),
            load=load.get("on", "force"), force_pattern=load.get("force_pattern"),
            parasitic_damping=inputs.get("parasitic_damping", 0.0),
            terminal_mass=inputs.get("terminal_mass", 0.0),
            series_stiffness=inputs.get("series_stiffness", math.inf),
            backlash=inputs.get("backlash", 0.0))
        quantity = Quantity(response.get("kind", "displacement"), response.get("floor"))
        quantity.floor_of(structure.floors)
    except ValueError as error:
        raise CLIError(str(error)) from None
    k, c = first_mode_tunings(system)["den_hartog"]
    system = system.replace(tid_stiffness=inputs.get("tid_stiffness", k),
                            tid_damping=inputs.get("tid_damping", c))
    if system.load == "ground" and "amplitudes_given" not in inputs:
        raise CLIError("a ground acceleration needs amplitudes (m/s2, or texts such as '0.2g')")
    try:
        amplitudes = np.asarray([amplitude_value(a) for a in inputs["amplitudes"]])
    except ValueError as error:
        raise CLIError(str(error)) from None
    return system, quantity, amplitudes


def band(inputs: dict, system: BuildingTID) -> tuple[np.ndarray, np.ndarray]:
    first = system.structure.modes()[0][0] / (2 * math.pi)
    low, high = inputs.get("band_hz", [BUILDING_BAND[0] * first, BUILDING_BAND[1] * first])
    hz = np.linspace(low, high, inputs["n_frequencies"])
    return hz, 2 * math.pi * hz


def design_band(omegas) -> tuple[np.ndarray, np.ndarray]:
    """A design's band (Hz, rad/s): `omegas`, or `DEFAULT_FREQUENCIES` frequencies over
    their range where they are fewer (a coarser design grid can miss or merge a
    building's peaks)."""
    if omegas.size < DEFAULT_FREQUENCIES:
        omegas = np.linspace(omegas[0], omegas[-1], DEFAULT_FREQUENCIES)
    return omegas / (2 * math.pi), omegas


def describe(system: BuildingTID, quantity: Quantity) -> str:
    floors = system.floors
    first = system.structure.natural_frequencies_hz()[0]
    where = "the ground" if system.inerter_floor == 0 else f"floor {system.inerter_floor}"
    load = "ground acceleration" if system.load == "ground" else "force"
    return (f"{floors}-storey structure (first mode {first:.3g} Hz), TID from floor "
            f"{system.spring_floor} to {where}, b = {float(system.inertance):g} kg, "
            f"ff = {float(system.friction_force):g} N{_compliance(system)}; {load}; "
            f"{quantity.describe(floors)}")


def _compliance(system: BuildingTID) -> str:
    if not system.compliant:
        return ""
    return (f", series stiffness {float(system.series_stiffness):g} N/m, backlash "
            f"{float(system.backlash):g} m")


def reference_tuning(system: TIDSystem | BuildingTID) -> tuple[float, float]:
    """Den Hartog's tuning (k, c) of the paper's host, or of a building's first mode."""
    if isinstance(system, BuildingTID):
        return first_mode_tunings(system)["den_hartog"]
    return _den_hartog(system)


def uncontrolled_peak(system: BuildingTID, quantity: Quantity, omegas) -> float:
    """The bare structure's peak of `quantity` per unit load amplitude over the band of
    `omegas` (rad/s): the largest on a fine grid and at its natural frequencies there."""
    low, high = float(np.min(omegas)), float(np.max(omegas))
    natural = np.asarray(system.structure.modes()[0])
    fine = np.concatenate([np.linspace(low, high, 2001),
                           natural[(natural >= low) & (natural <= high)]])
    return float(np.max(np.asarray(uncontrolled_amplitude(system, quantity, fine))))


def amplitude_label(system: BuildingTID) -> str:
    """A figure's amplitude axis, with its unit."""
    return (f"ground acceleration amplitude [{amplitude_unit(system.load)}]"
            if system.load == "ground" else "forcing amplitude A [N]")


def document(command, inputs, system, quantity, frequencies_hz, output, **results) -> dict:
    s = system.structure
    return {
        "command": f"{PROG} {command}",
        "inputs": {key: value for key, value in inputs.items() if key != "amplitudes_given"},
        "structure": {"mass_matrix_kg": np.asarray(s.mass_matrix).tolist(),
                      "stiffness_matrix_N_per_m": np.asarray(s.stiffness_matrix).tolist(),
                      "damping_matrix_N_s_per_m": np.asarray(s.damping_matrix).tolist(),
                      "natural_frequencies_hz": s.natural_frequencies_hz().tolist()},
        "tid": {"spring_floor": system.spring_floor, "inerter_floor": system.inerter_floor,
                "inertance_kg": float(system.inertance),
                "friction_force_N": float(system.friction_force),
                "parasitic_damping_N_s_per_m": float(system.parasitic_damping),
                "terminal_mass_kg": float(system.terminal_mass),
                # null: a rigid device
                "series_stiffness_N_per_m": (float(system.series_stiffness)
                                             if system.compliant else None),
                "backlash_m": float(system.backlash)},
        "load": system.load,
        "amplitude_unit": amplitude_unit(system.load),
        "response": {"kind": quantity.kind, "floor": quantity.floor_of(system.floors),
                     "unit": quantity.unit, "describes": quantity.describe(system.floors)},
        "frequencies_hz": [float(f) for f in frequencies_hz],
        **results,
        "files": [str(path) for path in output.files],
    }


def save_config(inputs, output, command):
    data = _config_data({key: value for key, value in inputs.items()
                         if key != "amplitudes_given"})
    write_toml(output.path(f"{command}_config.toml"), data, comment=_config_comment(command))


def begin(args, inputs: dict, doing: str):
    """A command's system, quantity, amplitudes, band (Hz, rad/s) and output folder, and
    its first message: `doing` (with {amplitudes} and {frequencies}) and the system."""
    system, quantity, amplitudes = building_inputs(inputs)
    frequencies_hz, omegas = band(inputs, system)
    output = _Output(args)
    output.say(doing.format(amplitudes=amplitudes.size, frequencies=omegas.size)
               + f"; {describe(system, quantity)}")
    return system, quantity, amplitudes, frequencies_hz, omegas, output


class DesignStart(NamedTuple):
    """What a command (`frf`, `retune`, `robust`, `sensitivity`) starts from, on the
    paper's host or a [structure]: its `quantity` None on the host."""

    inputs: dict
    system: TIDSystem | BuildingTID
    quantity: Quantity | None
    settings: SolverSettings
    frequencies_hz: np.ndarray
    omegas: np.ndarray
    amplitudes: np.ndarray
    output: _Output
    described: str


def design_start(args, inputs: dict, doing: str, design: bool = True) -> DesignStart:
    """A command's start (`doing` as in `begin`): with `design`, a building's band at least
    `DEFAULT_FREQUENCIES` frequencies (`design_band`)."""
    if "structure" in inputs:
        system, quantity, amplitudes, frequencies_hz, omegas, output = begin(args, inputs,
                                                                             doing)
        if design:
            frequencies_hz, omegas = design_band(omegas)
        return DesignStart(inputs, system, quantity, SolverSettings(**inputs[SOLVER_TABLE]),
                           frequencies_hz, omegas, amplitudes, output,
                           describe(system, quantity))
    inputs, system, settings, frequencies_hz, omegas, amplitudes, output = _start(args)
    described = _describe(system)
    output.say(doing.format(amplitudes=amplitudes.size, frequencies=omegas.size)
               + f"; {described}")
    return DesignStart(inputs, system, None, settings, frequencies_hz, omegas, amplitudes,
                       output, described)


def design_document(start: DesignStart, command: str, **results) -> dict:
    """The JSON record of a command's run, the host's or a building's."""
    if start.quantity is None:
        return start.output.document(command, start.inputs, start.system, start.settings,
                                     start.frequencies_hz, **results)
    return document(command, start.inputs, start.system, start.quantity,
                    start.frequencies_hz, start.output, **results)
