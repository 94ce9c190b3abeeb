"""`tid-jax frf`, `retune`, `sensitivity` and `robust` on a multi-storey structure: a
config with a [structure] table (and [tid], [load], [response]) to a `BuildingTID` and a `Quantity`,
and their tables, CSV, JSON and PNG files."""

import math

import numpy as np

from .. import plot
from .._building import BuildingTID, Quantity, first_mode_tunings
from .._building_design import BUILDING_BAND, building_peaks, retune_building
from .._building_orbit import building_response
from .._building_robust import robust_building, scaled_structure
from .._building_sensitivity import building_sensitivities, storey_stiffnesses
from .._io import write_json, write_toml
from .._settings import SolverSettings
from .._structure import Structure
from ._building_config import BUILDING_TABLES, amplitude_value
from ._common import (
    PROG,
    SOLVER_TABLE,
    CLIError,
    _config_comment,
    _config_data,
    _Output,
)
from ._tables import save_records, shown, table


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
        "amplitude_unit": "m/s2" if system.load == "ground" else "N",
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


def _begin(args, inputs: dict, doing: str):
    """A command's system, quantity, amplitudes, band (Hz, rad/s) and output folder, and
    its first message: `doing` (with {amplitudes} and {frequencies}) and the system."""
    system, quantity, amplitudes = building_inputs(inputs)
    frequencies_hz, omegas = band(inputs, system)
    output = _Output(args)
    output.say(doing.format(amplitudes=amplitudes.size, frequencies=omegas.size)
               + f"; {describe(system, quantity)}")
    return system, quantity, amplitudes, frequencies_hz, omegas, output


def run_frf(args, inputs: dict) -> int:
    system, quantity, amplitudes, frequencies_hz, omegas, output = _begin(
        args, inputs, "frequency response at {amplitudes} amplitude(s) x {frequencies} "
        "frequencies")
    response = building_response(system, omegas, amplitudes, quantity,
                                 SolverSettings(**inputs[SOLVER_TABLE]))
    bare_peak = np.max(response.uncontrolled, axis=1)
    records = [{"amplitude": float(a), "frequency_hz": float(f),
                "response_max": float(response.response_max[i, j]),
                "response_over_uncontrolled_peak": float(response.response_max[i, j]
                                                         / bare_peak[i]),
                "stroke_m": float(response.stroke_max[i, j]),
                "converged": bool(response.converged[i, j]),
                "stable": bool(response.stable[i, j]),
                "transitions": int(response.transitions[i, j])}
               for i, a in enumerate(amplitudes) for j, f in enumerate(frequencies_hz)]
    save_records(output, "frf.csv", list(records[0]), records)
    save_config(inputs, output, "frf")
    plot.save_figure(plot.plot_building_response(
        frequencies_hz, amplitudes, response.response_max, response.uncontrolled,
        ylabel=f"{quantity.describe(system.floors)} ({quantity.unit})"), output.path("frf.png"))
    peaks = np.nanmax(np.where(response.converged, response.response_max, np.nan), axis=1)
    summary = [{"amplitude": float(a), "peak": float(peaks[i]),
                "ratio": float(peaks[i] / bare_peak[i]),
                "stroke_cm": 100 * float(np.nanmax(response.stroke_max[i])),
                "converged": f"{int(response.converged[i].sum())}/{omegas.size}"}
               for i, a in enumerate(amplitudes)]
    data = document("frf", inputs, system, quantity, frequencies_hz, output,
                     amplitudes=amplitudes.tolist(),
                     response_max=np.asarray(response.response_max).tolist(),
                     uncontrolled=np.asarray(response.uncontrolled).tolist(),
                     y_max_m=np.asarray(response.stroke_max).tolist(),
                     converged=np.asarray(response.converged).tolist(),
                     stable=np.asarray(response.stable).tolist(),
                     transitions=np.asarray(response.transitions).tolist(), summary=summary)
    write_json(output.path("frf.json"), data)
    unit = data["amplitude_unit"]
    columns = [shown(f"A ({unit})", "amplitude", "g"),
               shown(f"peak ({quantity.unit})", "peak", ".4g"),
               shown("/ uncontrolled", "ratio", ".3f"), shown("stroke (cm)", "stroke_cm", ".2f"),
               shown("converged", "converged", "s")]
    title = f"Frequency response: {describe(system, quantity)}"
    return output.finish(data, title + "\n" + table(columns, summary))


def run_retune(args, inputs: dict) -> int:
    system, quantity, amplitudes, frequencies_hz, omegas, output = _begin(
        args, inputs, "retuning {amplitudes} amplitude(s) over {frequencies} frequencies")
    with output.steps(amplitudes.size) as step:
        result = retune_building(
            system, amplitudes, quantity, omegas=omegas,
            settings=SolverSettings(**inputs[SOLVER_TABLE]),
            progress=lambda done, total: step(f"amplitude {done}/{total} retuned"))
    records = [{"amplitude": float(a), "k_N_per_m": float(result.tid_stiffness[i]),
                "c_N_s_per_m": float(result.tid_damping[i]),
                "peak": float(result.peak[i]),
                "peak_over_uncontrolled": float(result.peak[i] / result.uncontrolled[i]),
                "peak_frequency_hz": float(result.peak_omega[i]) / (2 * math.pi),
                "den_hartog_peak": float(result.den_hartog_peak[i]),
                "h_infinity_peak": float(result.h_infinity_peak[i]),
                "converged": bool(result.converged[i])}
               for i, a in enumerate(amplitudes)]
    save_records(output, "retune.csv", list(records[0]), records)
    save_config(inputs, output, "retune")
    plot.save_figure(plot.plot_building_retune(
        amplitudes, {"retuned": result.peak, "first-mode Den Hartog": result.den_hartog_peak,
                     "first-mode H-infinity": result.h_infinity_peak},
        ylabel=f"peak {quantity.describe(system.floors)} ({quantity.unit})"),
        output.path("retune.png"))
    tunings = first_mode_tunings(system)
    data = document("retune", inputs, system, quantity, frequencies_hz, output,
                     first_mode_tunings={name: {"k_N_per_m": k, "c_N_s_per_m": c}
                                         for name, (k, c) in tunings.items()},
                     results=records)
    write_json(output.path("retune.json"), data)
    unit = data["amplitude_unit"]
    columns = [shown(f"A ({unit})", "amplitude", "g"), shown("k (N/m)", "k_N_per_m", ".5g"),
               shown("c (N s/m)", "c_N_s_per_m", ".5g"),
               shown(f"peak ({quantity.unit})", "peak", ".4g"),
               shown("/ uncontrolled", "peak_over_uncontrolled", ".3f"),
               shown("Den Hartog", "den_hartog_peak", ".4g"),
               shown("H-infinity", "h_infinity_peak", ".4g"),
               shown("converged", "converged", "")]
    title = f"Retuned per amplitude: {describe(system, quantity)}"
    return output.finish(data, title + "\n" + table(columns, records))


def _parameters(system: BuildingTID, amplitude_unit: str) -> dict:
    """Each parameter of `building_sensitivities`: its value and unit."""
    s = system.structure
    values = {"tid_stiffness": (float(system.tid_stiffness), "N/m"),
              "tid_damping": (float(system.tid_damping), "N s/m"),
              "inertance": (float(system.inertance), "kg"),
              "friction_force": (float(system.friction_force), "N"),
              "parasitic_damping": (float(system.parasitic_damping), "N s/m"),
              "terminal_mass": (float(system.terminal_mass), "kg"),
              "amplitude": (None, amplitude_unit)}
    if system.compliant:
        values["series_stiffness"] = (float(system.series_stiffness), "N/m")
        values["backlash"] = (float(system.backlash), "m")
    for i, mass in enumerate(np.diagonal(np.asarray(s.mass_matrix))):
        values[f"floor_mass_{i + 1}"] = (float(mass), "kg")
    for i, spring in enumerate(np.asarray(storey_stiffnesses(s.stiffness_matrix))):
        values[f"storey_stiffness_{i + 1}"] = (float(spring), "N/m")
    return values


def _optimum_fields(result, j: int) -> dict:
    """A parameter's elasticities at the retuned optimum (NaN where not found)."""
    o = result.optimum
    if o is None:
        return {}
    return {"optimum_peak": float(o.peak[0]),
            "optimum_elasticity": float(o.peak_elasticities[0, j]),
            "optimum_stiffness_elasticity": float(o.stiffness_elasticities[0, j]),
            "optimum_damping_elasticity": float(o.damping_elasticities[0, j]),
            "optimum_converged": bool(o.converged[0])}


def run_sensitivity(args, inputs: dict) -> int:
    optimum = not args.no_optimum
    system, quantity, amplitudes, frequencies_hz, omegas, output = _begin(
        args, inputs, "sensitivities at {amplitudes} amplitude(s) over {frequencies} "
        "frequencies, at the given tuning" + (" and at the optimum" if optimum else ""))
    unit = "m/s2" if system.load == "ground" else "N"
    parameters = _parameters(system, unit)
    with output.steps(amplitudes.size) as step:
        results = []
        for i, amplitude in enumerate(amplitudes):
            results.append(building_sensitivities(
                system, [amplitude], quantity, omegas=omegas,
                settings=SolverSettings(**inputs[SOLVER_TABLE]), optimum=optimum))
            step(f"amplitude {i + 1}/{amplitudes.size}")
    records = []
    for amplitude, result in zip(amplitudes, results, strict=True):
        peak = float(result.peak[0])
        for j, name in enumerate(result.names):
            value, parameter_unit = parameters[name]
            value = float(amplitude) if value is None else value
            elasticity = float(result.elasticities[0, j])
            records.append({
                "amplitude": float(amplitude), "parameter": name, "value": value,
                "unit": parameter_unit, "peak": peak,
                "peak_frequency_hz": float(result.peak_omega[0]) / (2 * math.pi),
                "elasticity": elasticity,
                "derivative_per_unit": elasticity * peak / value if value else 0.0,
                "converged": bool(result.converged[0]), **_optimum_fields(result, j)})
    save_records(output, "sensitivity.csv", list(records[0]), records)
    save_config(inputs, output, "sensitivity")
    elasticities = np.asarray([result.elasticities[0] for result in results])
    plot.save_figure(plot.plot_building_elasticities(
        amplitudes, results[0].names, elasticities, xlabel=f"amplitude ({unit})",
        title=f"elasticities of the peak {quantity.describe(system.floors)}"),
        output.path("sensitivity.png"))
    optima = [{"amplitude": float(a), "k_N_per_m": float(r.optimum.tid_stiffness[0]),
               "c_N_s_per_m": float(r.optimum.tid_damping[0]),
               "peak": float(r.optimum.peak[0]), "active_peaks": int(r.optimum.active[0]),
               "converged": bool(r.optimum.converged[0])}
              for a, r in zip(amplitudes, results, strict=True) if r.optimum is not None]
    data = document("sensitivity", inputs, system, quantity, frequencies_hz, output,
                    tid_stiffness_N_per_m=float(system.tid_stiffness),
                    tid_damping_N_s_per_m=float(system.tid_damping), results=records,
                    optimum=optima or None)
    write_json(output.path("sensitivity.json"), data)
    columns = [shown(f"A ({unit})", "amplitude", "g"), shown("parameter", "parameter", "s"),
               shown("value", "value", ".5g"), shown("unit", "unit", "s"),
               shown(f"peak ({quantity.unit})", "peak", ".4g"),
               shown("elasticity", "elasticity", ".4f")]
    if optimum:
        columns += [shown("at optimum", "optimum_elasticity", ".4f"),
                    shown("of k*", "optimum_stiffness_elasticity", ".4f"),
                    shown("of c*", "optimum_damping_elasticity", ".4f")]
    columns.append(shown("converged", "converged", ""))
    ranked = sorted(records, key=lambda r: (r["amplitude"], -abs(r["elasticity"])))
    title = (f"Elasticities of the peak (d ln peak / d ln p; damping matrix held), at "
             f"k = {float(system.tid_stiffness):.5g} N/m, c = "
             f"{float(system.tid_damping):.5g} N s/m: {describe(system, quantity)}")
    return output.finish(data, title + "\n" + table(columns, ranked))


def run_robust(args, inputs: dict, tolerance: float) -> int:
    """One tuning for every amplitude and, with `tolerance` f, the structure's natural
    frequencies (1 +- f) times the nominal (its stiffness (1 +- f)^2 times)."""
    scales = [1.0] if tolerance == 0 else [(1 - tolerance) ** 2, 1.0, (1 + tolerance) ** 2]
    stroke_limit = None if args.no_stroke_limit else inputs["stroke_limit"]
    limited = "not limited" if stroke_limit is None else f"within {stroke_limit:g} m"
    system, quantity, amplitudes, frequencies_hz, omegas, output = _begin(
        args, inputs, "robust tuning over {amplitudes} amplitude(s) x "
        f"{len(scales)} structure frequencies, the stroke {limited}")
    band = omegas if "band_hz" in inputs else None
    settings = SolverSettings(**inputs[SOLVER_TABLE])
    with output.steps(len(scales) + 2) as step:
        result = robust_building(system, amplitudes, quantity, stiffness_scales=scales,
                                 omegas=band, stroke_limit=stroke_limit, settings=settings,
                                 progress=step)
    given = np.stack([np.asarray(building_peaks(
        system.replace(structure=scaled_structure(system.structure, scale)), amplitudes,
        quantity, omegas=band, settings=settings).value) for scale in scales], axis=1)
    given_ratio = given / np.asarray(result.best)
    records = [{"structure_frequency_scale": math.sqrt(scale), "amplitude": float(a),
                "best_peak": float(result.best[i, j]), "robust_peak": float(result.peak[i, j]),
                "robust_ratio": float(result.ratio[i, j]), "given_peak": float(given[i, j]),
                "given_ratio": float(given_ratio[i, j]),
                "robust_stroke_m": float(result.stroke_peak[i, j])}
               for j, scale in enumerate(scales) for i, a in enumerate(amplitudes)]
    save_records(output, "robust.csv", list(records[0]), records)
    save_config(inputs, output, "robust")
    nominal = scales.index(1.0)
    plot.save_figure(plot.plot_building_retune(
        amplitudes, {"robust": np.asarray(result.ratio)[:, nominal],
                     "given": given_ratio[:, nominal]},
        ylabel="peak / best of a tuning of its own"), output.path("robust.png"))
    summary = {"k_N_per_m": float(result.tid_stiffness),
               "c_N_s_per_m": float(result.tid_damping),
               "worst_ratio": float(result.worst_ratio), "converged": bool(result.converged),
               "given_k_N_per_m": float(system.tid_stiffness),
               "given_c_N_s_per_m": float(system.tid_damping),
               "given_worst_ratio": float(np.max(given_ratio)),
               "stroke_limited": bool(result.stroke_limited),
               "stroke_limit_m": stroke_limit,
               "within_stroke_limit": bool(result.within_stroke_limit)}
    data = document("robust", inputs, system, quantity, frequencies_hz, output,
                     structure_frequency_scales=[math.sqrt(s) for s in scales],
                     robust=summary, results=records)
    write_json(output.path("robust.json"), data)
    unit = data["amplitude_unit"]
    columns = [shown("f scale", "structure_frequency_scale", ".3g"),
               shown(f"A ({unit})", "amplitude", "g"),
               shown(f"best ({quantity.unit})", "best_peak", ".4g"),
               shown("robust / best", "robust_ratio", ".4f"),
               shown("given / best", "given_ratio", ".4f")]
    title = (f"Robust tuning k = {summary['k_N_per_m']:.5g} N/m, c = "
             f"{summary['c_N_s_per_m']:.5g} N s/m: worst {summary['worst_ratio']:.4f} of "
             f"the best (given tuning: {summary['given_worst_ratio']:.4f})"
             f"{'' if summary['converged'] else ' (search not converged)'}; "
             f"{describe(system, quantity)}")
    return output.finish(data, title + "\n" + table(columns, records))
