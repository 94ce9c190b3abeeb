"""`tid-jax records`: the response with the inerter's friction under recorded ground
motions (PEER `.AT2` or CSV files), with the given tuning and with the (k, c) designed
over the suite (the least mean peak)."""

from pathlib import Path

import numpy as np

from .. import plot
from .._loads._monte_carlo import friction_history
from .._loads._random_design import check_bounds
from .._loads._record_design import design_for_records
from .._loads._records import GroundMotion, read_at2, read_csv_record
from .._model._building import G
from .._runtime._io import write_json
from . import _building
from ._arguments import _add_output_arguments, _add_structure_arguments
from ._common import PROG, CLIError, _number, _Output
from ._schema import RECORDS_COLUMNS, finite, ratio, row, status, stroke_problem
from ._tables import save_records, shown, table
from .random import (
    add_bounds_arguments,
    build_case,
    case_inputs,
    design_bounds,
    document,
    tuned,
    wrapped,
)

UNITS = ("g", "m/s2")
EXACT_NOTE = ("the friction width relative to a forcing needs a stationary load: exact "
              "Coulomb friction (friction_width 0) under the records")


def _add_records_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "records",
        help="peaks and RMS under recorded ground motions, and the TID designed over them",
        description="The response with the inerter's friction (from rest) under each "
        "recorded ground motion, scaled to --pga, with the given tuning and with the TID's "
        "k and c designed over the suite (the least mean peak, Nelder-Mead, within "
        "--stiffness-bounds and --damping-bounds, every record's stroke peak within "
        "--stroke-limit, default 0.07 m). The system is "
        "under ground acceleration: the paper's host by default, or a [structure] in "
        "--config ([load] on = 'ground'). The friction is exact Coulomb friction unless "
        "--friction-width gives a width (m/s). Prints a table and saves records.csv, "
        "records.json, records_config.toml, records_histories.png and records_peaks.png "
        "to --out.",
    )
    parser.add_argument(
        "files", nargs="+", metavar="FILE",
        help="ground motion records: PEER NGA .AT2 files (accelerations in g), or "
        "two-column CSV files (time in s, evenly spaced; acceleration in --units; a header "
        "line is allowed)")
    group = parser.add_argument_group("records")
    group.add_argument("--units", choices=UNITS, default="g",
                       help="units of the accelerations of the CSV records (default g)")
    group.add_argument("--pga", type=float, metavar="G",
                       help="scale each record to this peak ground acceleration [g] "
                       "(default: as recorded)")
    group.add_argument("--time-step", dest="time_step", type=float, metavar="S",
                       help="hold the friction over substeps of at most S [s] (default: "
                       "exact friction on a rigid device is stepped exactly, events "
                       "located; otherwise the first mode's period / 200)")
    add_bounds_arguments(parser.add_argument_group("design limits"))
    _add_structure_arguments(
        parser,
        "TOML file with the structure and device keys, as for the other commands, "
        "[structure], [tid], [load] (on = 'ground') and [response] tables",
    )
    _add_output_arguments(parser)
    parser.set_defaults(amplitudes=None, band_hz=None, n_frequencies=None)


def _read(path: str, units: str, pga: float | None) -> GroundMotion:
    """The record of the file `path` (by its suffix), scaled to `pga` (g) if given."""
    suffix = Path(path).suffix.lower()
    if suffix == ".at2":
        motion = read_at2(path)
    elif suffix == ".csv":
        motion = read_csv_record(path, units=units)
    else:
        raise CLIError(f"{path}: a record must be a PEER .AT2 file or a .csv file, got "
                       f"{suffix or 'no suffix'!r}")
    return motion if pga is None else motion.scaled_to(pga)


def _run_records(args) -> int:
    inputs = case_inputs(args)
    on = inputs.get("load", {}).get("on", "ground")
    if on != "ground":
        raise CLIError(f"{PROG} records needs a ground acceleration: [load] on = 'ground', "
                       f"got {on!r}")
    inputs["load"] = {**inputs.get("load", {}), "on": on}
    case = build_case(inputs, on)
    note = None
    if case.system.friction_width is None:
        case = case._replace(system=case.system.replace(friction_width=0.0))
        note = EXACT_NOTE
    system, quantity = case.system, case.quantity
    # (None: exact friction on a rigid device is stepped exactly, as in the design)
    time_step = (None if args.time_step is None
                 else _number("--time-step", args.time_step, "positive"))
    pga = None if args.pga is None else _number("--pga", args.pga, "positive")
    bounds = design_bounds(args, system)
    if bounds is not None:
        check_bounds(bounds)  # (before any computation)
    motions = [_read(path, args.units, pga) for path in args.files]
    output = _Output(args)
    output.say(f"{len(motions)} record(s){'' if pga is None else f' scaled to {pga:g} g'}, "
               f"with the given tuning and designed over the suite; {case.description}"
               + ("" if note is None else f"; {note}"))
    with output.steps(2 * len(motions) + 1) as step:
        before = []
        for i, motion in enumerate(motions):
            before.append(friction_history(system, motion, quantity, time_step=time_step))
            step(f"record {i + 1}/{len(motions)} {motion.name}: peak "
                 f"{float(before[-1].peak):.4g} {quantity.unit} with the given tuning")
        limit = inputs["stroke_limit"]
        design = design_for_records(system, motions, quantity,
                                    bounds=bounds, stroke_limit=limit,
                                    time_step=time_step)
        designed = tuned(system, design.tid_stiffness, design.tid_damping)
        step(f"designed over the suite: k = {float(design.tid_stiffness):.5g} N/m, c = "
             f"{float(design.tid_damping):.4g} N s/m"
             + ("" if bool(design.converged) else " (Nelder-Mead not converged)")
             + ("" if bool(design.within_stroke_limit)
                else f" (a stroke peak over the limit, {1e3 * limit:g} mm)"))
        after = []
        for i, motion in enumerate(motions):
            after.append(friction_history(designed, motion, quantity, time_step=time_step))
            step(f"record {i + 1}/{len(motions)} {motion.name}: peak "
                 f"{float(after[-1].peak):.4g} {quantity.unit} with the design")
    records = _records(motions, args.files, before, after, design, quantity.unit, limit)
    save_records(output, "records.csv", RECORDS_COLUMNS, records)
    _building.save_config(inputs, output, "records")
    _save_plots(output, case, motions, before, after, records, limit)
    json_path = output.path("records.json")
    data = document("records", inputs, case, output, load={"on": "ground"},
                    friction_note=note, units=args.units, pga_g=pga, time_step=time_step,
                    tid_stiffness=float(design.tid_stiffness),
                    tid_damping=float(design.tid_damping), converged=bool(design.converged),
                    stroke_limit=limit, within_stroke_limit=bool(design.within_stroke_limit),
                    stiffness_bounds=[float(v) for v in design.stiffness_bounds],
                    damping_bounds=[float(v) for v in design.damping_bounds],
                    at_bound=bool(design.at_bound),
                    mean_peak=float(np.mean([r["peak_before"] for r in records])),
                    mean_peak_after=float(np.mean([r["peak_after"] for r in records])),
                    results=records)
    write_json(json_path, data)
    return output.finish(data, _table(records, case, data))


def _records(motions, files, before, after, design, unit, limit) -> list[dict]:
    """One record per ground motion, keyed by `RECORDS_COLUMNS`: its peak, RMS and stroke
    with the given tuning (before) and with the design over the suite (after)."""
    converged = bool(design.converged)
    records = []
    for i, (motion, path, given, mine) in enumerate(zip(motions, files, before, after,
                                                       strict=True)):
        stroke_before = float(np.max(np.abs(np.asarray(given.stroke))))
        stroke_after = float(np.max(np.abs(np.asarray(mine.stroke))))
        peak_after = float(design.peak_after[i])
        records.append(row(
            RECORDS_COLUMNS, name=motion.name, file=str(path), amplitude=float(motion.peak),
            amplitude_unit="m/s2", duration_s=float(motion.duration),
            k_N_per_m=float(design.tid_stiffness), c_N_s_per_m=float(design.tid_damping),
            peak_unit=unit, peak_before=finite(given.peak), peak_after=finite(peak_after),
            peak_after_over_before=ratio(peak_after, given.peak),
            rms_before=finite(given.rms), rms_after=finite(design.rms_after[i]),
            stroke_before_m=stroke_before, stroke_after_m=stroke_after, stroke_limit_m=limit,
            within_stroke_limit=stroke_after <= limit, converged=converged,
            status=status(converged, stroke_problem(stroke_after, limit),
                          base=None if converged else "not converged: the design's "
                          "Nelder-Mead search over the suite did not converge")))
    return records


def _save_plots(output, case, motions, before, after, records, limit) -> None:
    described = case.quantity.describe(case.system.floors)
    unit = case.quantity.unit
    panels = []
    for motion, given, mine in zip(motions, before, after, strict=True):
        name = f"{motion.name} (PGA {motion.peak / G:.3g} g)"
        time = np.asarray(given.time)
        panels += [(name, f"{described} [{unit}]", time,
                    {"given tuning": np.asarray(given.quantity),
                     "designed over the suite": np.asarray(mine.quantity)}),
                   (f"{name}: TID stroke", "stroke [mm]", time,
                    {"given tuning": 1e3 * np.asarray(given.stroke),
                     "designed over the suite": 1e3 * np.asarray(mine.stroke)}, 1e3 * limit)]
    plot.save_figure(plot.plot_histories(
        panels, title=wrapped(f"Under the records: {case.description}")),
        output.path("records_histories.png"))
    plot.save_figure(plot.plot_record_peaks(
        [r["name"] for r in records],
        {"given tuning": [r["peak_before"] for r in records],
         "designed over the suite": [r["peak_after"] for r in records]},
        ylabel=f"peak {described} [{unit}]"), output.path("records_peaks.png"))


def _table(records, case, data) -> str:
    unit = case.quantity.unit
    columns = [shown("record", "name", "s"), shown("PGA (g)", "amplitude", ".3g", unit=G),
               shown(f"peak given ({unit})", "peak_before", ".4g"),
               shown(f"peak designed ({unit})", "peak_after", ".4g"),
               shown(f"RMS given ({unit})", "rms_before", ".4g"),
               shown(f"RMS designed ({unit})", "rms_after", ".4g"),
               shown("stroke given (mm)", "stroke_before_m", ".3g", unit=1e-3),
               shown("stroke designed (mm)", "stroke_after_m", ".3g", unit=1e-3),
               shown("status", "status", "s")]
    given = data["given_tuning"]
    title = (f"Under {len(records)} record(s): given k = {given['tid_stiffness']:.5g} N/m, "
             f"c = {given['tid_damping']:.4g} N s/m; designed over the suite k = "
             f"{data['tid_stiffness']:.5g} N/m, c = {data['tid_damping']:.4g} N s/m"
             f"{'' if data['converged'] else ' (not converged)'}"
             f"{'' if data['within_stroke_limit'] else ' (stroke over the limit)'} with "
             f"strokes within {1e3 * data['stroke_limit']:g} mm, mean peak "
             f"{data['mean_peak']:.4g} -> {data['mean_peak_after']:.4g} {unit}; "
             f"{case.description}")
    return title + "\n" + table(columns, records)
