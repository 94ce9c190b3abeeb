"""`tid-jax identify`: the inerter device identified from test records."""

import csv
import math

import numpy as np

from .. import __version__, plot
from .._identify._device import Motion
from .._identify._fit import MODEL_PARAMETERS, MODELS, InerterRecord, identify_inerter
from .._optimise._design import PARAMETER_UNITS
from .._runtime._io import write_csv, write_json, write_toml
from ._arguments import _add_output_arguments
from ._common import INERTER_TABLE, PROG, CLIError, _number, _Output
from ._tables import Shown, shown, table

RECORD_COLUMNS = ("time", "displacement", "force")
OPTIONAL_COLUMN = "record"
IDENTIFY_COLUMNS = ("record", "time_s", "displacement_m", "velocity_m_per_s", "force_N",
                    "fitted_force_N", "residual_N")
# what `tid-jax retune --config` takes of the device (the TIDSystem's fields): the rigid
# device's terms, and with the terminal mass that a compliant device's node needs (given,
# not identified) its series stiffness and backlash
RIGID_KEYS = ("inertance", "friction_force", "parasitic_damping")
COMPLIANT_KEYS = ("series_stiffness", "backlash")


def _add_identify_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "identify",
        help="identify the inerter device (inertance, friction, ...) from test records",
        description="Fit an inerter device model to test records (imposed displacement "
        "across the device and the measured force, as in the paper's Figures 2-3) by "
        "nonlinear least squares; the nested models up to --model are compared. Saves "
        "identify.json, identify.csv, identify.png and identify_config.toml (which "
        f"'{PROG} retune --config' takes as the device) to --out.",
    )
    parser.add_argument(
        "records", metavar="RECORDS.csv",
        help="CSV with a header: time [s], displacement [m], force [N] and an optional "
        "record column naming the test each row belongs to",
    )
    parser.add_argument(
        "--model", choices=MODELS, default="ideal",
        help="device model: ideal (inertance and friction, the paper's), damped "
        "(+ parasitic damping), compliant (+ series stiffness), backlash (+ free play); "
        "default ideal",
    )
    parser.add_argument(
        "--terminal-mass", type=float, default=0.0, metavar="KG",
        help="the device's moving mass at its driven terminal, kg, known from the device "
        "(the records cannot tell it from the inertance): held in the fit, and with it a "
        "compliant device's series stiffness and backlash go into identify_config.toml "
        "(default 0: the inertance includes it, and the config carries the rigid terms)",
    )
    _add_output_arguments(parser)


def _read_records(path: str) -> list[InerterRecord]:
    """The records of the CSV file `path`, checked row by row."""
    try:
        with open(path, newline="") as file:
            rows = list(csv.reader(file))
    except OSError as error:
        raise CLIError(f"cannot read {path}: {error.strerror}") from None
    except (UnicodeDecodeError, csv.Error) as error:
        raise CLIError(f"{path} is not a CSV text file: {error}") from None
    if not rows:
        raise CLIError(f"{path} is empty")
    header = [name.strip() for name in rows[0]]
    for name in header:
        if name not in (*RECORD_COLUMNS, OPTIONAL_COLUMN):
            raise CLIError(f"{path}: unknown column {name!r} in the header; expected "
                           f"{', '.join(RECORD_COLUMNS)} and optionally {OPTIONAL_COLUMN}")
    for name in RECORD_COLUMNS:
        if name not in header:
            raise CLIError(f"{path}: no {name!r} column in the header ({', '.join(header)})")
    if len(set(header)) != len(header):
        raise CLIError(f"{path}: a column appears twice in the header ({', '.join(header)})")
    groups: dict[str, list[list[float]]] = {}
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) != len(header):
            raise CLIError(f"{path}: row {line} has {len(row)} values, the header "
                           f"{len(header)}")
        cells = dict(zip(header, (cell.strip() for cell in row), strict=True))
        values = []
        for name in RECORD_COLUMNS:
            try:
                value = float(cells[name])
            except ValueError:
                raise CLIError(f"{path}: row {line}, column {name!r}: {cells[name]!r} is not "
                               "a number") from None
            if not math.isfinite(value):
                raise CLIError(f"{path}: row {line}, column {name!r}: {cells[name]!r} is not "
                               "finite")
            values.append(value)
        group = groups.setdefault(cells.get(OPTIONAL_COLUMN, ""), [])
        if group and values[0] <= group[-1][1]:
            raise CLIError(f"{path}: row {line}, column 'time': {values[0]:g} s does not "
                           f"follow the record's previous time ({group[-1][1]:g} s)")
        group.append([line, *values])
    if not groups:
        raise CLIError(f"{path} has a header but no rows")
    records = []
    for name, group in groups.items():
        data = np.asarray(group)
        try:
            records.append(InerterRecord(*data[:, 1:].T, name=name))
        except ValueError as error:
            raise CLIError(f"{path}: {error} (rows {int(data[0, 0])}-{int(data[-1, 0])})") \
                from None
    return records


def _run_identify(args) -> int:
    terminal_mass = _number("terminal_mass", args.terminal_mass, "non-negative")
    records = _read_records(args.records)
    output = _Output(args)
    output.say(f"identifying the {args.model} model from {len(records)} record(s), "
               f"{sum(r.time.size for r in records)} samples")
    models = MODELS[: MODELS.index(args.model) + 1]
    with output.steps(len(models)) as step:
        fit = identify_inerter(records, model=args.model, terminal_mass=terminal_mass,
                               progress=step, map_lanes=args.map_lanes)

    names = list(fit.parameters)
    estimates = {n: float(v) for n, v in zip(names, fit.estimates, strict=True)}
    errors = {n: float(v) for n, v in zip(names, fit.standard_errors, strict=True)}
    labels = [r.name or f"record {i + 1}" for i, r in enumerate(records)]
    csv_rows, figure_records = _samples(labels, records, fit)
    comparison = fit.comparison
    compared = [
        dict(model=model, parameters=list(MODEL_PARAMETERS[model]),
             rms_N=float(comparison.rms[i]), bic=float(comparison.bic[i]),
             delta_bic=float(comparison.delta_bic[i]),
             supported=bool(comparison.supported[i]), converged=bool(comparison.converged[i]))
        for i, model in enumerate(comparison.models)
    ]

    write_csv(output.path("identify.csv"), IDENTIFY_COLUMNS, csv_rows)
    plot.save_figure(
        plot.plot_identification(figure_records,
                                 title=f"inerter identified, {args.model} model"),
        output.path("identify.png"),
    )
    device = _config_device(estimates, terminal_mass)
    left_out = [n for n in names if n not in device]
    comment = (f"The inerter identified by `{PROG} identify` ({args.model} model, tid_jax "
               f"{__version__});\nuse it with {PROG} retune --config THIS_FILE")
    if left_out:
        comment += ("\nNot carried over (a compliant device's node needs the device's "
                    "terminal mass, which the records do not identify: give it with "
                    f"{PROG} identify --terminal-mass KG): "
                    + ", ".join(f"{n} = {estimates[n]:.6g} {PARAMETER_UNITS[n]}" for n in left_out))
    write_toml(output.path("identify_config.toml"), {INERTER_TABLE: device}, comment=comment)
    json_path = output.path("identify.json")
    data = {
        "command": f"{PROG} identify",
        "version": __version__,
        "records_file": args.records,
        "model": args.model,
        "terminal_mass": terminal_mass,
        "records": [dict(name=label, samples=int(r.time.size), rms_N=float(rms))
                    for label, r, rms in zip(labels, records, fit.rms, strict=True)],
        "parameters": estimates,
        "standard_errors": errors,
        "correlations": {a: {b: float(fit.correlations[i, j]) for j, b in enumerate(names)}
                         for i, a in enumerate(names)},
        "units": {n: PARAMETER_UNITS[n] for n in names},
        "converged": bool(fit.converged),
        "least_squares_steps": int(fit.steps),
        "comparison": compared,
        "files": [str(path) for path in output.files],
    }
    write_json(json_path, data)

    return output.finish(data, _table(names, estimates, errors, compared, labels, fit,
                                      terminal_mass))


def _config_device(estimates: dict, terminal_mass: float) -> dict:
    """The device as `tid-jax retune --config` takes it: the rigid terms identified, and
    with a terminal mass the compliant ones and the terminal mass itself."""
    keys = RIGID_KEYS + (COMPLIANT_KEYS if terminal_mass > 0 else ())
    device = {key: estimates[key] for key in keys if key in estimates}
    if terminal_mass > 0:
        device["terminal_mass"] = terminal_mass
    return device


def _samples(labels, records, fit):
    """The rows of identify.csv (measured and fitted force per sample) and the records
    as the figure takes them."""
    csv_rows, figure_records = [], []
    for label, record, fitted in zip(labels, records, fit.fitted_force, strict=True):
        motion = Motion.from_samples(record.time, record.displacement)
        time, displacement = np.asarray(motion.time), np.asarray(motion.displacement)
        velocity = np.asarray(motion.velocity)
        force, fitted = np.asarray(record.force), np.asarray(fitted)
        csv_rows += [[label, *row] for row in zip(time.tolist(), displacement.tolist(),
                                                  velocity.tolist(), force.tolist(),
                                                  fitted.tolist(), (fitted - force).tolist(),
                                                  strict=True)]
        figure_records.append(dict(name=label, time=time, displacement=displacement,
                                   velocity=velocity, force=force, fitted=fitted))
    return csv_rows, figure_records


# The printed tables: the estimates, and the comparison of the nested models (the first
# model, the reference, has no change in BIC).
ESTIMATES_TABLE = (
    shown("parameter", "parameter", "s"),
    shown("estimate", "estimate", ".6g"),
    shown("std. error", "standard_error", ".3g"),
    shown("unit", "unit", "s"),
)
COMPARISON_TABLE = (
    shown("model", "model", "s"),
    Shown("parameters", lambda row: str(len(row["parameters"]))),
    shown("RMS [N]", "rms_N", ".4g"),
    Shown("delta BIC", lambda row: "-" if row["first"] else f"{row['delta_bic']:.1f}"),
    Shown("term supported",
          lambda row: "-" if row["first"] else ("yes" if row["supported"] else "no")),
)


def _table(names, estimates, errors, compared, labels, fit, terminal_mass) -> str:
    """The estimates (and the terminal mass held, if any), the comparison of the nested
    models and the residuals."""
    text = table(ESTIMATES_TABLE, [
        dict(parameter=n, estimate=estimates[n], standard_error=errors[n], unit=PARAMETER_UNITS[n])
        for n in names])
    if terminal_mass > 0:
        text += f"\nterminal_mass held at {terminal_mass:g} kg (given, not fitted)"
    text += "\n\n" + table(COMPARISON_TABLE, [dict(row, first=i == 0)
                                               for i, row in enumerate(compared)])
    text += "\n\n" + "\n".join(f"{label}: residual RMS {float(rms):.4g} N"
                              for label, rms in zip(labels, fit.rms, strict=True))
    if not bool(fit.converged):
        text += "\n\nWARNING: the least squares did not converge; the estimates are unreliable."
    return text
