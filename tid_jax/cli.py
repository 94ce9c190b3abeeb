"""The `tid-jax` command-line tool: argument parsing, configuration files, printing.

Each subcommand is a pair `_add_<name>_parser(subparsers)` / `_run_<name>(args) -> int`
registered in `_COMMANDS`. The shared pieces are `_add_system_arguments` (the physical
parameters, amplitudes, band and `--config`), `_add_output_arguments` (`--out`, `--json`,
`--quiet`), `_inputs`/`_system`/`_settings`/`_frequencies` (from flags and TOML to library
objects), `_Output` (output folder, progress, files written) and the error handling in
`main`: any `CLIError`, `ValueError` or `OSError` becomes one line
`tid-jax: error: <problem>` on stderr and exit status 2.
"""

import argparse
import contextlib
import math
import shutil
import sys
import time
import tomllib
from pathlib import Path

import jax
import numpy as np
from tqdm import tqdm

from . import __version__, plot
from ._cache import CACHE_ENVIRONMENT_VARIABLE, enable_compilation_cache
from ._design import PARAMETER_UNITS, ROBUST_SHARPNESS, best_tunings
from ._io import check_writable_dir, json_text, write_csv, write_json, write_toml
from ._linear import (
    breakaway_amplitude,
    den_hartog_tuning,
    linear_receptance,
    stuck_receptance,
)
from ._response import frequency_response
from ._retune import DEFAULT_FREQUENCIES, RetuneSettings, default_omegas, retune
from ._robust import robust_tune, tuning_performance
from ._sensitivity import sensitivities
from ._steady_state import SolverSettings
from ._substructuring import GUESSED_FORCES, PREDICTIONS, SCHEMES, simulate_substructuring
from ._system import (
    PAPER_AMPLITUDES,
    PAPER_FRICTION_FORCE,
    PAPER_HOST_DAMPING_RATIO,
    PAPER_HOST_FREQUENCY_HZ,
    PAPER_HOST_MASS,
    PAPER_INERTANCE,
    PAPER_STROKE,
    TIDSystem,
)

PROG = "tid-jax"
EXIT_ERROR = 2
EXIT_INTERRUPTED = 130

# Physical inputs: (key, unit, description, allowed values). The key is the TOML key and,
# with '-' for '_', the flag. Frequencies are in Hz here; the library works in rad/s.
PHYSICAL_INPUTS = (
    ("host_mass", "kg", "modal mass M of the host structure", "positive"),
    ("host_frequency_hz", "Hz", "natural frequency sqrt(K/M)/(2 pi) of the host", "positive"),
    ("host_stiffness", "N/m", "host stiffness K (instead of host_frequency_hz)", "positive"),
    ("host_damping_ratio", "-", "host damping ratio C/(2 sqrt(K M))", "non-negative"),
    ("host_damping", "N s/m", "host damping C (instead of host_damping_ratio)", "non-negative"),
    ("inertance", "kg", "inertance b of the inerter", "positive"),
    ("friction_force", "N", "dry friction force ff of the inerter (0: ideal TID)", "non-negative"),
    ("friction_width", "m/s", "velocity scale of the smoothed friction sign (default: "
     "0.02 omega A/K at each forcing point)", "positive"),
    ("tid_stiffness", "N/m", "TID spring stiffness k (default: Den Hartog)", "positive"),
    ("tid_damping", "N s/m", "TID damping c (default: Den Hartog)", "non-negative"),
    ("stroke_limit", "m", "inerter stroke limit, +-", "positive"),
)
GRID_INPUTS = ("amplitudes", "band_hz", "n_frequencies")
INPUT_KEYS = tuple(key for key, *_ in PHYSICAL_INPUTS) + GRID_INPUTS
SOLVER_TABLE = "solver"
# Pairs of which at most one may be given; the first has a default.
ALTERNATIVES = (("host_frequency_hz", "host_stiffness"), ("host_damping_ratio", "host_damping"))
DEFAULTS = {
    "host_mass": PAPER_HOST_MASS,
    "host_frequency_hz": PAPER_HOST_FREQUENCY_HZ,
    "host_damping_ratio": PAPER_HOST_DAMPING_RATIO,
    "inertance": PAPER_INERTANCE,
    "friction_force": PAPER_FRICTION_FORCE,
    "stroke_limit": PAPER_STROKE,
    "amplitudes": list(PAPER_AMPLITUDES),
    "n_frequencies": DEFAULT_FREQUENCIES,
}
MIN_FREQUENCIES = 5


class CLIError(Exception):
    """A problem with the user's input, reported as one line."""


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)  # a mistyped flag is an error, not a guess
        super().__init__(*args, **kwargs)

    def error(self, message):
        raise CLIError(f"{message} (see '{self.prog} --help')")


# --- shared arguments -------------------------------------------------------------------


def _add_structure_arguments(parser: argparse.ArgumentParser, config_help: str) -> None:
    """The "structure and device" group: --config and a flag per physical input."""
    group = parser.add_argument_group(
        "structure and device",
        "SI units, frequencies in Hz. Defaults: the paper's system (1500 kg, 4 Hz, 2% "
        "damping, b = 75 kg, ff = 20 N, Den Hartog k and c). Flags override --config.",
    )
    group.add_argument("--config", metavar="FILE.toml", help=config_help)
    for key, unit, description, _ in PHYSICAL_INPUTS:
        group.add_argument(
            f"--{key.replace('_', '-')}",
            dest=key,
            type=float,
            metavar="RATIO" if unit == "-" else unit,
            help=f"{description} [{unit}]"
            + (f", default {DEFAULTS[key]:g}" if key in DEFAULTS else ""),
        )


def _add_system_arguments(parser: argparse.ArgumentParser) -> None:
    _add_structure_arguments(
        parser,
        "TOML file with any of the keys below (flag names with '_' for "
        "'-') and an optional [solver] table; see the README",
    )
    grid = parser.add_argument_group("forcing and frequency band")
    grid.add_argument(
        "--amplitudes",
        nargs="+",
        type=float,
        metavar="N",
        help="forcing amplitudes A of A sin(wt) [N] (default: the paper's twelve, 100-3000 N)",
    )
    grid.add_argument(
        "--band-hz",
        dest="band_hz",
        nargs=2,
        type=float,
        metavar=("LOW", "HIGH"),
        help="forcing frequency band [Hz] (default: 0.65-1.4 times the host "
        "frequency, both resonance peaks)",
    )
    grid.add_argument(
        "--n-frequencies",
        dest="n_frequencies",
        type=int,
        metavar="N",
        help=f"frequencies in the band (default {DEFAULT_FREQUENCIES})",
    )


def _add_output_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("output")
    group.add_argument(
        "--out",
        default="tid-results",
        metavar="DIR",
        help="folder for the CSV, JSON, TOML and PNG files (default: ./tid-results/)",
    )
    group.add_argument(
        "--json",
        action="store_true",
        help="print the machine-readable result (the saved JSON) on stdout instead of the table",
    )
    group.add_argument("--quiet", action="store_true", help="no progress messages")
    cache = parser.add_argument_group("compilation cache")
    cache.add_argument(
        "--cache-dir",
        dest="cache_dir",
        metavar="DIR",
        help=f"folder of the compiled-program cache that makes later runs start fast "
        f"(default: ${CACHE_ENVIRONMENT_VARIABLE}, else ~/.cache/tid_jax)",
    )
    cache.add_argument(
        "--no-cache",
        dest="no_cache",
        action="store_true",
        help=f"compile afresh and save nothing (also: {CACHE_ENVIRONMENT_VARIABLE}=off)",
    )


# --- from flags and TOML to library objects ---------------------------------------------


def _read_config(path: str) -> dict:
    try:
        with open(path, "rb") as file:
            config = tomllib.load(file)
    except tomllib.TOMLDecodeError as error:
        raise CLIError(f"config {path} is not valid TOML: {error}") from None
    except OSError as error:
        raise CLIError(f"cannot read config {path}: {error.strerror}") from None
    unknown = [key for key in config if key not in INPUT_KEYS and key != SOLVER_TABLE]
    if unknown:
        raise CLIError(
            f"config {path}: unknown key {unknown[0]!r}; "
            f"allowed keys are {', '.join(INPUT_KEYS)} and a [{SOLVER_TABLE}] table"
        )
    solver = config.get(SOLVER_TABLE, {})
    if not isinstance(solver, dict):
        raise CLIError(f"config {path}: {SOLVER_TABLE} must be a table [{SOLVER_TABLE}]")
    fields = tuple(SolverSettings.__dataclass_fields__)
    unknown = [key for key in solver if key not in fields]
    if unknown:
        raise CLIError(
            f"config {path}: unknown key {unknown[0]!r} in [{SOLVER_TABLE}]; "
            f"allowed keys are {', '.join(fields)}"
        )
    return config


def _number(name: str, value, allowed: str) -> float:
    """`value` as a float if it is a finite number and `allowed` ("positive" or
    "non-negative"), else `CLIError` naming `name`."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise CLIError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not (math.isfinite(value) and (value > 0 if allowed == "positive" else value >= 0)):
        raise CLIError(f"{name} must be finite and {allowed}, got {value!r}")
    return value


def _inputs(args) -> dict:
    """Config file, then flags, then defaults, checked: a dict of `INPUT_KEYS` (those
    given) and the `solver` table."""
    config = _read_config(args.config) if args.config else {}
    flags = {key: getattr(args, key) for key in INPUT_KEYS if getattr(args, key) is not None}
    for group in ALTERNATIVES:
        if any(key in flags for key in group):
            for key in group:
                config.pop(key, None)
    given = {**config, **flags}
    inputs = {**DEFAULTS, **given}
    for first, second in ALTERNATIVES:
        if first in given and second in given:
            raise CLIError(f"give {first} or {second}, not both")
        if second in given:
            del inputs[first]
    inputs = {key: inputs[key] for key in INPUT_KEYS if key in inputs}
    for key, _, _, allowed in PHYSICAL_INPUTS:
        if key in inputs:
            inputs[key] = _number(key, inputs[key], allowed)
    amplitudes = inputs["amplitudes"]
    amplitudes = amplitudes if isinstance(amplitudes, list) else [amplitudes]
    if not amplitudes:
        raise CLIError("amplitudes must not be empty")
    inputs["amplitudes"] = [_number("amplitudes", a, "positive") for a in amplitudes]
    n = inputs["n_frequencies"]
    if isinstance(n, bool) or not isinstance(n, int) or n < MIN_FREQUENCIES:
        raise CLIError(f"n_frequencies must be an integer >= {MIN_FREQUENCIES}, got {n!r}")
    if "band_hz" in inputs:
        band = inputs["band_hz"]
        if not (isinstance(band, list) and len(band) == 2):
            raise CLIError(f"band_hz must be two frequencies [LOW, HIGH] in Hz, got {band!r}")
        low, high = (_number("band_hz", f, "positive") for f in band)
        if not low < high:
            raise CLIError(f"band_hz is empty: LOW must be below HIGH, got {low:g} to {high:g} Hz")
        inputs["band_hz"] = [low, high]
    inputs[SOLVER_TABLE] = dict(config.get(SOLVER_TABLE, {}))
    return inputs


def _system(inputs: dict) -> TIDSystem:
    mass = inputs["host_mass"]
    stiffness = inputs.get("host_stiffness")
    if stiffness is None:
        stiffness = mass * (2 * math.pi * inputs["host_frequency_hz"]) ** 2
    damping = inputs.get("host_damping")
    if damping is None:
        damping = 2 * inputs["host_damping_ratio"] * math.sqrt(stiffness * mass)
    k_dh, c_dh = den_hartog_tuning(mass, stiffness, inputs["inertance"])
    return TIDSystem(
        host_mass=mass,
        host_stiffness=stiffness,
        host_damping=damping,
        inertance=inputs["inertance"],
        friction_force=inputs["friction_force"],
        tid_stiffness=inputs.get("tid_stiffness", k_dh),
        tid_damping=inputs.get("tid_damping", c_dh),
        friction_width=inputs.get("friction_width"),
    )


def _settings(inputs: dict) -> SolverSettings:
    return SolverSettings(**inputs[SOLVER_TABLE])


def _frequencies(inputs: dict, system: TIDSystem) -> tuple[np.ndarray, np.ndarray]:
    """The forcing frequencies in Hz and in rad/s."""
    n = inputs["n_frequencies"]
    if "band_hz" not in inputs:
        omegas = np.asarray(default_omegas(system, n))
        return omegas / (2 * math.pi), omegas
    frequencies_hz = np.linspace(*inputs["band_hz"], n)
    return frequencies_hz, 2 * math.pi * frequencies_hz


def _den_hartog(system: TIDSystem) -> tuple[float, float]:
    k, c = den_hartog_tuning(system.host_mass, system.host_stiffness, system.inertance)
    return float(k), float(c)


def _linear_normalised(system: TIDSystem, frequencies_hz) -> tuple[np.ndarray, np.ndarray]:
    """|x| and |y| over A / K of the frictionless TID at `frequencies_hz`."""
    receptance = linear_receptance(system, 2 * math.pi * np.asarray(frequencies_hz))
    stiffness = float(system.host_stiffness)
    return np.abs(np.asarray(receptance.host)) * stiffness, np.abs(
        np.asarray(receptance.inerter)
    ) * stiffness


def _linear_curves(system: TIDSystem, frequencies_hz, points: int = 400):
    """`(frequencies, x, y)` of the frictionless TID over A / K on a fine grid spanning
    `frequencies_hz`, for plots."""
    fine = np.linspace(frequencies_hz[0], frequencies_hz[-1], points)
    return (fine, *_linear_normalised(system, fine))


def _stuck_curve(system: TIDSystem, frequencies_hz, points: int = 400):
    """`(frequencies, x)` of the host over A / K with the inerter stuck, on a fine grid
    spanning `frequencies_hz`, for plots."""
    fine = np.linspace(frequencies_hz[0], frequencies_hz[-1], points)
    receptance = stuck_receptance(system, 2 * math.pi * fine)
    return fine, np.abs(np.asarray(receptance)) * float(system.host_stiffness)


def _host_frequency_hz(system: TIDSystem) -> float:
    return float(system.host_frequency) / (2 * math.pi)


def _describe(system: TIDSystem) -> str:
    f_n = _host_frequency_hz(system)
    return (
        f"M = {float(system.host_mass):g} kg, f_n = {f_n:.3g} Hz, "
        f"C = {float(system.host_damping):.4g} N s/m, b = {float(system.inertance):g} kg, "
        f"ff = {float(system.friction_force):g} N, k = {float(system.tid_stiffness):.5g} N/m, "
        f"c = {float(system.tid_damping):.4g} N s/m"
    )


# --- output -------------------------------------------------------------------------------


class _Output:
    """Output folder (checked before computing), progress messages and the record of the
    files written."""

    def __init__(self, args):
        self.args = args
        self.folder = Path(args.out)
        if self.folder.exists() and not self.folder.is_dir():
            raise CLIError(f"output folder {self.folder} is a file, not a folder")
        try:
            check_writable_dir(self.folder)
        except OSError as error:
            reason = error.strerror or str(error)
            raise CLIError(f"output folder {self.folder} is not writable: {reason}") from None
        self.files: list[Path] = []
        self.start = time.perf_counter()
        self.bar: tqdm | None = None

    def say(self, message: str) -> None:
        if self.args.quiet:
            return
        if self.bar is not None:
            self.bar.write(f"{PROG}: {message}", file=sys.stderr)
        else:
            print(f"{PROG}: {message}", file=sys.stderr, flush=True)

    @contextlib.contextmanager
    def steps(self, total: int):
        """A progress bar of `total` steps on stderr (on a terminal, and not with
        --quiet), with the elapsed and remaining time; yields the function that says a
        step's message above it and advances it by one step (more steps than `total`
        extend it)."""
        # (A terminal that reports no width, as some pseudo-terminals do, gets 80 columns.)
        self.bar = tqdm(total=total, file=sys.stderr, leave=False, mininterval=0,
                        ncols=shutil.get_terminal_size().columns,
                        disable=self.args.quiet or not sys.stderr.isatty(),
                        bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}<{remaining}]")

        def step(message: str) -> None:
            self.say(message)
            if self.bar.n >= self.bar.total:
                self.bar.total = self.bar.n + 1
            self.bar.update(1)

        try:
            yield step
        finally:
            self.bar.close()
            self.bar = None

    def path(self, name: str) -> Path:
        path = self.folder / name
        self.files.append(path)
        return path

    def document(
        self, command: str, inputs: dict, system: TIDSystem, settings, frequencies_hz, **results
    ) -> dict:
        """The JSON record of a run: inputs, system, solver settings, version, results."""
        k_dh, c_dh = _den_hartog(system)
        return {
            "command": f"{PROG} {command}",
            "version": __version__,
            "inputs": inputs,
            "system": system.to_dict(),
            "den_hartog": {"tid_stiffness": k_dh, "tid_damping": c_dh},
            "solver": settings.to_dict(),
            "frequencies_hz": [float(f) for f in frequencies_hz],
            **results,
            "files": [str(path) for path in self.files],
        }

    def finish(self, data: dict, table: str) -> int:
        if self.args.json:
            print(json_text(data))
        else:
            print(table)
        names = ", ".join(path.name for path in self.files)
        self.say(
            f"done in {time.perf_counter() - self.start:.0f} s; results in {self.folder}/: {names}"
        )
        return 0


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _format_table(header: list[str], rows: list[list[str]]) -> str:
    """Columns of numbers right-aligned, columns of text left-aligned."""
    columns = list(zip(header, *rows, strict=True))
    widths = [max(len(cell) for cell in column) for column in columns]
    numeric = [all(_is_number(cell) for cell in column[1:]) for column in columns]
    lines = [
        "  ".join(
            cell.rjust(width) if right else cell.ljust(width)
            for cell, width, right in zip(row, widths, numeric, strict=True)
        ).rstrip()
        for row in [header, *rows]
    ]
    lines.insert(1, "  ".join("-" * width for width in widths))
    return "\n".join(lines)


def _config_comment(command: str) -> str:
    return (
        f"Inputs of `{PROG} {command}` (tid_jax {__version__}); rerun with\n"
        f"{PROG} {command} --config THIS_FILE"
    )


def _config_data(inputs: dict) -> dict:
    return {key: value for key, value in inputs.items() if value != {}}


# --- tid-jax retune -------------------------------------------------------------------------

RETUNE_COLUMNS = (
    "amplitude_N",
    "k_over_k_den_hartog",
    "k_N_per_m",
    "c_over_c_den_hartog",
    "c_N_s_per_m",
    "x_peak_before_over_A_K",
    "x_peak_after_over_A_K",
    "peak_frequency_after_Hz",
    "stroke_before_m",
    "stroke_after_m",
    "stroke_limit_m",
    "within_stroke_limit",
    "iterations",
    "converged",
    "status",
)


def _add_retune_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "retune",
        help="retune the TID's k and c for each forcing amplitude",
        description="For each forcing amplitude, find the TID stiffness k and damping c that "
        "minimise the peak steady-state host displacement over the frequency "
        "band, starting from the given (default: Den Hartog) tuning. Prints a "
        "table and saves retune.csv, retune.json, retune_config.toml, "
        "retune_frequency_response.png and retune_summary.png to --out.",
    )
    _add_system_arguments(parser)
    _add_output_arguments(parser)


def _run_retune(args) -> int:
    inputs = _inputs(args)
    system, settings = _system(inputs), _settings(inputs)
    frequencies_hz, omegas = _frequencies(inputs, system)
    amplitudes = np.asarray(inputs["amplitudes"])
    output = _Output(args)
    output.say(
        f"retuning {amplitudes.size} amplitude(s) over {omegas.size} frequencies, "
        f"{frequencies_hz[0]:.3g}-{frequencies_hz[-1]:.3g} Hz; "
        f"{_describe(system)}"
    )
    with output.steps(RetuneSettings().progress_steps()) as step:
        result = retune(system, amplitudes, omegas=omegas, settings=settings, progress=step)

    stiffness = float(system.host_stiffness)
    # The frequency responses before and after retuning, on retune's check grid.
    check_hz = np.asarray(result.check_omegas) / (2 * math.pi)
    x_before = np.asarray(result.x_response_initial) / (amplitudes[:, None] / stiffness)
    x_after = np.asarray(result.x_response) / (amplitudes[:, None] / stiffness)

    k_dh, c_dh = _den_hartog(system)
    stroke_limit = inputs["stroke_limit"]
    static = amplitudes / stiffness
    k_ratio = np.asarray(result.tid_stiffness) / k_dh
    c_ratio = np.asarray(result.tid_damping) / c_dh
    x_peak_before = np.asarray(result.x_peak_initial) / static
    x_peak_after = np.asarray(result.x_peak) / static
    y_before, y_after = np.asarray(result.y_peak_initial), np.asarray(result.y_peak)
    within = y_after <= stroke_limit
    improved = x_peak_after <= x_peak_before
    statuses = result.status_messages()
    breakaway = breakaway_amplitude(system, omegas)
    stuck = amplitudes < float(breakaway.minimum)
    records = [
        dict(
            zip(
                RETUNE_COLUMNS,
                (
                    float(amplitudes[i]),
                    float(k_ratio[i]),
                    float(result.tid_stiffness[i]),
                    float(c_ratio[i]),
                    float(result.tid_damping[i]),
                    float(x_peak_before[i]),
                    float(x_peak_after[i]),
                    float(result.omega_peak[i]) / (2 * math.pi),
                    float(y_before[i]),
                    float(y_after[i]),
                    stroke_limit,
                    bool(within[i]),
                    int(result.iterations[i]),
                    bool(result.converged[i]),
                    statuses[i]
                    + ("" if within[i] else "; stroke over limit")
                    + ("" if improved[i] else "; peak above the initial tuning's")
                    + (f"; below the breakaway amplitude {float(breakaway.minimum):.4g} N: "
                       "with the initial tuning the inerter stays stuck" if stuck[i] else ""),
                ),
                strict=True,
            )
        )
        for i in range(amplitudes.size)
    ]

    write_csv(
        output.path("retune.csv"),
        RETUNE_COLUMNS,
        [[record[key] for key in RETUNE_COLUMNS] for record in records],
    )
    write_toml(
        output.path("retune_config.toml"), _config_data(inputs), comment=_config_comment("retune")
    )
    linear_hz, x_linear, _ = _linear_curves(system, frequencies_hz)
    plot.save_figure(
        plot.plot_retune_responses(
            check_hz,
            amplitudes,
            x_before,
            x_after,
            k_ratio,
            c_ratio,
            linear=(linear_hz, x_linear),
            host_frequency_hz=_host_frequency_hz(system),
        ),
        output.path("retune_frequency_response.png"),
    )
    plot.save_figure(
        plot.plot_retune_summary(
            amplitudes,
            k_ratio,
            c_ratio,
            x_peak_before,
            x_peak_after,
            y_before,
            y_after,
            stroke_limit=stroke_limit,
            converged=np.asarray(result.converged),
        ),
        output.path("retune_summary.png"),
    )
    json_path = output.path("retune.json")
    data = output.document("retune", inputs, system, settings, frequencies_hz, results=records)
    write_json(json_path, data)

    header = [
        "A [N]",
        "k/k_DH",
        "k [kN/m]",
        "c/c_DH",
        "c [N s/m]",
        "x/(A/K) before",
        "x/(A/K) after",
        "f_peak [Hz]",
        f"stroke [cm] (limit {100 * stroke_limit:g})",
        "status",
    ]
    rows = [
        [
            f"{r['amplitude_N']:g}",
            f"{r['k_over_k_den_hartog']:.3f}",
            f"{r['k_N_per_m'] / 1e3:.2f}",
            f"{r['c_over_c_den_hartog']:.3f}",
            f"{r['c_N_s_per_m']:.1f}",
            f"{r['x_peak_before_over_A_K']:.2f}",
            f"{r['x_peak_after_over_A_K']:.2f}",
            f"{r['peak_frequency_after_Hz']:.3f}",
            f"{100 * r['stroke_after_m']:.2f}",
            r["status"],
        ]
        for r in records
    ]
    title = (
        f"Retuned TID ({_describe(system)}); Den Hartog k_DH = {k_dh:.5g} N/m, "
        f"c_DH = {c_dh:.4g} N s/m; peaks x normalised by the static displacement A/K"
    )
    return output.finish(data, title + "\n" + _format_table(header, rows) + "\n"
                         + "With the initial tuning: " + _breakaway_line(breakaway))


# --- tid-jax frf ----------------------------------------------------------------------------

FRF_COLUMNS = (
    "amplitude_N",
    "frequency_Hz",
    "x_max_m",
    "y_max_m",
    "x_over_A_K",
    "y_over_A_K",
    "x_linear_over_A_K",
    "y_linear_over_A_K",
    "converged",
    "stable",
)


def _add_frf_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "frf",
        help="steady-state frequency response over a band and a list of amplitudes",
        description="Peak steady-state host displacement x and inerter displacement y over "
        "the frequency band for each forcing amplitude (the paper's Figure 5), "
        "beside the linear (frictionless) TID. Saves frf.csv, frf.json, "
        "frf_config.toml and frf.png to --out.",
    )
    _add_system_arguments(parser)
    _add_output_arguments(parser)


def _run_frf(args) -> int:
    inputs = _inputs(args)
    system, settings = _system(inputs), _settings(inputs)
    frequencies_hz, omegas = _frequencies(inputs, system)
    amplitudes = np.asarray(inputs["amplitudes"])
    output = _Output(args)
    output.say(
        f"frequency response at {amplitudes.size} amplitude(s) x {omegas.size} "
        f"frequencies; {_describe(system)}"
    )
    shape = (amplitudes.size, omegas.size)
    x_max, y_max = np.empty(shape), np.empty(shape)
    converged, stable = np.empty(shape, bool), np.empty(shape, bool)
    with output.steps(amplitudes.size) as step:
        for i, amplitude in enumerate(amplitudes):
            response = frequency_response(system, omegas, amplitude, settings=settings)
            x_max[i], y_max[i] = np.asarray(response.x_max), np.asarray(response.y_max)
            converged[i] = np.asarray(response.converged)
            stable[i] = np.asarray(response.stable)
            step(
                f"amplitude {i + 1}/{amplitudes.size} (A = {amplitude:g} N): "
                f"{converged[i].sum()}/{omegas.size} steady states converged"
            )

    static = (amplitudes / float(system.host_stiffness))[:, None]
    x_norm, y_norm = x_max / static, y_max / static
    x_linear, y_linear = _linear_normalised(system, frequencies_hz)
    rows = [
        [
            float(amplitudes[i]),
            float(frequencies_hz[j]),
            float(x_max[i, j]),
            float(y_max[i, j]),
            float(x_norm[i, j]),
            float(y_norm[i, j]),
            float(x_linear[j]),
            float(y_linear[j]),
            bool(converged[i, j]),
            bool(stable[i, j]),
        ]
        for i in range(amplitudes.size)
        for j in range(omegas.size)
    ]
    peak = np.argmax(np.where(converged, x_max, -np.inf), axis=1)
    summary = [
        {
            "amplitude_N": float(amplitudes[i]),
            "x_peak_over_A_K": float(x_norm[i, peak[i]]),
            "peak_frequency_Hz": float(frequencies_hz[peak[i]]),
            "stroke_m": float(np.max(np.where(converged[i], y_max[i], -np.inf))),
            "converged_points": int(converged[i].sum()),
            "unstable_points": int((converged[i] & ~stable[i]).sum()),
        }
        for i in range(amplitudes.size)
    ]

    breakaway = breakaway_amplitude(system, omegas)
    write_csv(output.path("frf.csv"), FRF_COLUMNS, rows)
    write_toml(output.path("frf_config.toml"), _config_data(inputs), comment=_config_comment("frf"))
    plot.save_figure(
        plot.plot_frequency_response(
            frequencies_hz,
            amplitudes,
            x_norm,
            y_norm,
            linear=_linear_curves(system, frequencies_hz),
            stuck=(*_stuck_curve(system, frequencies_hz), float(breakaway.minimum)),
            host_frequency_hz=_host_frequency_hz(system),
        ),
        output.path("frf.png"),
    )
    json_path = output.path("frf.json")
    data = output.document(
        "frf",
        inputs,
        system,
        settings,
        frequencies_hz,
        amplitudes_N=[float(a) for a in amplitudes],
        x_max_m=x_max.tolist(),
        y_max_m=y_max.tolist(),
        converged=converged.tolist(),
        stable=stable.tolist(),
        x_linear_over_A_K=x_linear.tolist(),
        y_linear_over_A_K=y_linear.tolist(),
        breakaway_amplitude_N=np.asarray(breakaway.amplitude).tolist(),
        breakaway_minimum_N=float(breakaway.minimum),
        breakaway_minimum_frequency_Hz=float(breakaway.omega_minimum) / (2 * math.pi),
        summary=summary,
    )
    write_json(json_path, data)

    stroke_limit = inputs["stroke_limit"]
    header = [
        "A [N]",
        "peak x/(A/K)",
        "at f [Hz]",
        f"stroke [cm] (limit {100 * stroke_limit:g})",
        "converged",
        "unstable",
    ]
    table_rows = [
        [
            f"{s['amplitude_N']:g}",
            f"{s['x_peak_over_A_K']:.2f}",
            f"{s['peak_frequency_Hz']:.3f}",
            f"{100 * s['stroke_m']:.2f}",
            f"{s['converged_points']}/{omegas.size}",
            str(s["unstable_points"]),
        ]
        for s in summary
    ]
    title = (
        f"Frequency response ({_describe(system)}); peaks on the grid, x normalised by "
        f"the static displacement A/K"
    )
    return output.finish(data, title + "\n" + _format_table(header, table_rows) + "\n"
                         + _breakaway_line(breakaway))


def _breakaway_line(breakaway) -> str:
    """What the minimum breakaway amplitude over the band means, in one line."""
    return (f"Breakaway amplitude over the band: {float(breakaway.minimum):.4g} N at "
            f"{float(breakaway.omega_minimum) / (2 * math.pi):.3f} Hz; below it the inerter "
            f"never slips and the TID acts as a spring and damper to ground.")


# --- tid-jax rtds ---------------------------------------------------------------------------

RTDS_COLUMNS = (
    "frequency_Hz",
    "amplitude_N",
    "x_whole_m",
    "y_whole_m",
    "x_test_m",
    "y_test_m",
    "x_amplitude_error",
    "y_amplitude_error",
    "x_phase_error_rad",
    "y_phase_error_rad",
    "stable",
    "diverged",
    "growth",
)
RTDS_AMPLITUDE = 200.0  # N, default forcing of `tid-jax rtds`


def _add_rtds_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "rtds",
        help="plan a real-time dynamic substructuring test of the inerter",
        description="Simulate a real-time dynamic substructuring test of the inerter (paper "
        "section 5) as a digital controller runs it: host, TID spring and damper numerical, "
        "the inerter physical behind an actuator with delay, compensated by default by "
        "harmonic forward prediction as in the paper's tests (--prediction none turns it "
        "off: with the default 10 ms delay the host amplitude is then about 10%% off). "
        "Compares the test with the "
        "whole system (amplitude and phase errors) and reports unstable tests. Prints a "
        "table and saves rtds.csv, rtds.json and rtds.png to --out.",
    )
    _add_structure_arguments(
        parser,
        "TOML file with the structure and device keys (and amplitudes, band_hz, "
        "n_frequencies), as for the other commands",
    )
    forcing = parser.add_argument_group("forcing")
    forcing.add_argument(
        "--amplitude",
        dest="amplitudes",
        type=float,
        metavar="N",
        help=f"forcing amplitude A of A sin(wt) [N] (default {RTDS_AMPLITUDE:g})",
    )
    forcing.add_argument(
        "--frequency-hz",
        dest="frequency_hz",
        nargs="+",
        type=float,
        metavar="HZ",
        help="forcing frequencies [Hz] (instead of --band-hz)",
    )
    forcing.add_argument(
        "--band-hz",
        dest="band_hz",
        nargs=2,
        type=float,
        metavar=("LOW", "HIGH"),
        help="forcing frequency band [Hz] (default: 0.65-1.4 times the host frequency)",
    )
    forcing.add_argument(
        "--n-frequencies",
        dest="n_frequencies",
        type=int,
        metavar="N",
        help=f"frequencies in the band (default {DEFAULT_FREQUENCIES})",
    )
    test = parser.add_argument_group("substructuring test")
    test.add_argument(
        "--scheme",
        choices=SCHEMES,
        default="error_feedback",
        help="feed back the measured force (conventional, unstable for any delay) or its "
        "error from the guessed inertance (error_feedback, default)",
    )
    test.add_argument(
        "--delay-ms", type=float, default=10.0, metavar="MS", help="actuator delay [ms] (10)"
    )
    test.add_argument(
        "--guessed-inertance-ratio",
        type=float,
        default=1.0,
        metavar="RATIO",
        help="guessed inertance b_g over the inerter's b (1.0)",
    )
    test.add_argument(
        "--guessed-force",
        choices=GUESSED_FORCES,
        default="acceleration",
        help="b_g times the actuator's acceleration, or the paper's -b_g w^2 y* (harmonic)",
    )
    test.add_argument(
        "--prediction",
        choices=("none", *PREDICTIONS),
        default="harmonic",
        help="compensation of the delay: forward prediction of the commanded motion "
        "(default harmonic, as in the paper's tests; none: uncompensated)",
    )
    test.add_argument(
        "--actuator-lag-ms",
        type=float,
        default=0.0,
        metavar="MS",
        help="time constant of the actuator's first-order lag [ms] (0: none)",
    )
    test.add_argument(
        "--parasitic-stiffness",
        type=float,
        metavar="N/m",
        help="stiffness in series with the physical inerter [N/m] (default: rigid)",
    )
    test.add_argument(
        "--sample-rate",
        type=float,
        default=1000.0,
        metavar="HZ",
        help="controller sample rate [Hz] (1000)",
    )
    test.add_argument(
        "--periods",
        type=int,
        default=60,
        metavar="N",
        help="simulated duration in forcing periods (60)",
    )
    _add_output_arguments(parser)


def _run_rtds(args) -> int:
    if args.amplitudes is None and not (args.config and "amplitudes" in _read_config(args.config)):
        args.amplitudes = RTDS_AMPLITUDE
    inputs = _inputs(args)
    if len(inputs["amplitudes"]) != 1:
        raise CLIError(f"rtds takes one amplitude, got {inputs['amplitudes']}")
    amplitude = inputs["amplitudes"][0]
    delay = _number("delay_ms", args.delay_ms, "non-negative") / 1e3
    ratio = _number("guessed_inertance_ratio", args.guessed_inertance_ratio, "positive")
    lag = _number("actuator_lag_ms", args.actuator_lag_ms, "non-negative") / 1e3
    rate = _number("sample_rate", args.sample_rate, "positive")
    parasitic = args.parasitic_stiffness
    if parasitic is not None:
        parasitic = _number("parasitic_stiffness", parasitic, "positive")
    system, settings = _system(inputs), _settings(inputs)
    if args.frequency_hz is not None:
        if args.band_hz is not None:
            raise CLIError("give --frequency-hz or --band-hz, not both")
        frequencies_hz = np.asarray(
            [_number("frequency_hz", f, "positive") for f in args.frequency_hz]
        )
        omegas = 2 * math.pi * frequencies_hz
    else:
        frequencies_hz, omegas = _frequencies(inputs, system)
    prediction = None if args.prediction == "none" else args.prediction
    test = {
        "scheme": args.scheme,
        "amplitude_N": amplitude,
        "delay_s": delay,
        "guessed_inertance_kg": ratio * float(system.inertance),
        "guessed_force": args.guessed_force,
        "prediction": args.prediction,
        "actuator_lag_s": lag,
        "parasitic_stiffness_N_per_m": parasitic,
        "sample_rate_Hz": rate,
        "periods": args.periods,
    }
    output = _Output(args)
    output.say(
        f"substructuring test ({args.scheme}, delay {1e3 * delay:g} ms, b_g = {ratio:g} b, "
        f"prediction {args.prediction}) at {omegas.size} frequencies, A = {amplitude:g} N; "
        f"{_describe(system)}"
    )
    result = simulate_substructuring(
        system,
        omegas,
        amplitude,
        scheme=args.scheme,
        delay=delay,
        guessed_inertance=test["guessed_inertance_kg"],
        guessed_force=args.guessed_force,
        prediction=prediction,
        actuator_lag=lag,
        parasitic_stiffness=parasitic,
        sample_rate=rate,
        periods=args.periods,
        settings=settings,
    )
    columns = {
        "x_whole_m": result.reference_x_max,
        "y_whole_m": result.reference_y_max,
        "x_test_m": result.x_max,
        "y_test_m": result.y_max,
        "x_amplitude_error": result.x_amplitude_error,
        "y_amplitude_error": result.y_amplitude_error,
        "x_phase_error_rad": result.x_phase_error,
        "y_phase_error_rad": result.y_phase_error,
        "stable": result.stable,
        "diverged": result.diverged,
        "growth": result.growth,
    }
    columns = {key: np.atleast_1d(np.asarray(value)).tolist() for key, value in columns.items()}
    rows = [
        [float(f), amplitude, *(columns[key][j] for key in RTDS_COLUMNS[2:])]
        for j, f in enumerate(frequencies_hz)
    ]
    write_csv(output.path("rtds.csv"), RTDS_COLUMNS, rows)
    label = f"test: {args.scheme}, {1e3 * delay:g} ms, b_g = {ratio:g} b"
    plot.save_figure(
        plot.plot_substructuring_response(
            frequencies_hz,
            columns["x_whole_m"],
            columns["y_whole_m"],
            [(label, columns["x_test_m"], columns["y_test_m"], columns["stable"])],
            title=f"Virtual substructuring test, A = {amplitude:g} N, {rate:g} Hz controller",
        ),
        output.path("rtds.png"),
    )
    json_path = output.path("rtds.json")
    data = output.document("rtds", inputs, system, settings, frequencies_hz, test=test, **columns)
    write_json(json_path, data)

    header = [
        "f [Hz]",
        "x whole [mm]",
        "x test [mm]",
        "x err [%]",
        "y whole [mm]",
        "y test [mm]",
        "y err [%]",
        "phase err x/y [deg]",
        "test",
    ]
    table_rows = []
    for j, f in enumerate(frequencies_hz):
        stable = columns["stable"][j]
        status = "stable" if stable else ("diverged" if columns["diverged"][j] else "growing")

        def shown(value, scale, digits, stable=stable):
            return f"{scale * value:.{digits}f}" if stable else "-"

        table_rows.append(
            [
                f"{f:.3f}",
                f"{1e3 * columns['x_whole_m'][j]:.4f}",
                shown(columns["x_test_m"][j], 1e3, 4),
                shown(columns["x_amplitude_error"][j], 100, 2),
                f"{1e3 * columns['y_whole_m'][j]:.4f}",
                shown(columns["y_test_m"][j], 1e3, 4),
                shown(columns["y_amplitude_error"][j], 100, 2),
                (
                    f"{math.degrees(columns['x_phase_error_rad'][j]):.2f}/"
                    f"{math.degrees(columns['y_phase_error_rad'][j]):.2f}"
                )
                if stable
                else "-",
                status,
            ]
        )
    title = (
        f"Substructuring test ({args.scheme}, delay {1e3 * delay:g} ms, b_g = {ratio:g} b, "
        f"prediction {args.prediction}, {rate:g} Hz) against the whole system, "
        f"A = {amplitude:g} N; {_describe(system)}"
    )
    return output.finish(data, title + "\n" + _format_table(header, table_rows))


# --- tid-jax sensitivity --------------------------------------------------------------------

SENSITIVITY_COLUMNS = (
    "amplitude_N",
    "parameter",
    "value",
    "unit",
    "host_peak_m",
    "host_derivative_m_per_unit",
    "host_elasticity",
    "stroke_peak_m",
    "stroke_derivative_m_per_unit",
    "stroke_elasticity",
    "optimum_k_N_per_m",
    "optimum_c_N_s_per_m",
    "optimum_host_elasticity",
    "optimum_stroke_elasticity",
    "optimum_stiffness_elasticity",
    "optimum_damping_elasticity",
    "converged",
    "optimum_converged",
    "optimum_damping_at_bound",
)


def _add_sensitivity_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "sensitivity",
        help="derivatives of the peak responses with respect to every parameter",
        description="For each forcing amplitude: derivatives and elasticities (d ln peak / "
        "d ln p) of the peak host displacement and inerter stroke over the band with "
        "respect to the host mass, stiffness and damping, the inertance, the friction "
        "force, the TID stiffness and damping and the amplitude, at the given tuning and "
        "at the tuning retuned for that amplitude (envelope theorem and implicit "
        "differentiation). Prints a table ranked by the host elasticity and saves "
        "sensitivity.csv, sensitivity.json, sensitivity_config.toml and, for several "
        "amplitudes, sensitivity.png to --out.",
    )
    _add_system_arguments(parser)
    parser.add_argument(
        "--no-optimum",
        action="store_true",
        help="only at the given tuning (skips finding the retuned optimum)",
    )
    _add_output_arguments(parser)


def _run_sensitivity(args) -> int:
    inputs = _inputs(args)
    system, settings = _system(inputs), _settings(inputs)
    frequencies_hz, omegas = _frequencies(inputs, system)
    amplitudes = np.asarray(inputs["amplitudes"])
    output = _Output(args)
    output.say(
        f"sensitivities at {amplitudes.size} amplitude(s) over {omegas.size} frequencies"
        f"{'' if args.no_optimum else ', with the retuned optimum'}; {_describe(system)}"
    )
    best = None
    results = []
    retune_steps = 0 if args.no_optimum else RetuneSettings().progress_steps()
    with output.steps(retune_steps + amplitudes.size) as step:
        if not args.no_optimum:
            output.say(f"retuning at {amplitudes.size} amplitude(s), all in one batch")
            best = best_tunings(system, amplitudes, omegas=omegas, settings=settings,
                                progress=step)
        for i, amplitude in enumerate(amplitudes):
            results.append(
                sensitivities(system, amplitude, omegas=omegas, optimum=not args.no_optimum,
                              best=best, settings=settings)
            )
            step(f"amplitude {i + 1}/{amplitudes.size} (A = {amplitude:g} N) done")

    records = []
    for amplitude, result in zip(amplitudes, results, strict=True):
        optimum = result.optimum
        for i, name in enumerate(result.parameters):
            at_bound = optimum is not None and bool(optimum.damping_at_bound)
            optimal = (
                [None] * 8
                if optimum is None
                else [
                    float(optimum.tid_stiffness),
                    float(optimum.tid_damping),
                    float(optimum.host_elasticity[i]),
                    float(optimum.stroke_elasticity[i]),
                    float(optimum.stiffness_elasticity[i]),
                    # Undefined (c* held at 0 by its bound): left empty.
                    None if at_bound else float(optimum.damping_elasticity[i]),
                    at_bound,
                    bool(optimum.converged),
                ]
            )
            values = [
                float(amplitude),
                name,
                float(result.values[i]),
                PARAMETER_UNITS[name],
                float(result.host_peak),
                float(result.host_derivative[i]),
                float(result.host_elasticity[i]),
                float(result.stroke_peak),
                float(result.stroke_derivative[i]),
                float(result.stroke_elasticity[i]),
                *optimal[:6],
                bool(result.converged),
                optimal[7],
                optimal[6],
            ]
            records.append(dict(zip(SENSITIVITY_COLUMNS, values, strict=True)))

    write_csv(
        output.path("sensitivity.csv"),
        SENSITIVITY_COLUMNS,
        [["" if r[key] is None else r[key] for key in SENSITIVITY_COLUMNS] for r in records],
    )
    write_toml(
        output.path("sensitivity_config.toml"),
        _config_data(inputs),
        comment=_config_comment("sensitivity"),
    )
    if amplitudes.size > 1:
        parameters = results[0].parameters

        def series(get, names):
            return {n: np.array([get(r)[parameters.index(n)] for r in results]) for n in names}

        design = ("tid_stiffness", "tid_damping")
        physical = [n for n in parameters if n not in design]
        optimum_given = not args.no_optimum
        plot.save_figure(
            plot.plot_elasticities(
                amplitudes,
                series(lambda r: np.asarray(r.host_elasticity), parameters),
                series(lambda r: np.asarray(r.stroke_elasticity), parameters),
                optimum_host=series(lambda r: np.asarray(r.optimum.host_elasticity), physical)
                if optimum_given
                else None,
                optimum_stroke=series(lambda r: np.asarray(r.optimum.stroke_elasticity), physical)
                if optimum_given
                else None,
            ),
            output.path("sensitivity.png"),
        )
    json_path = output.path("sensitivity.json")
    data = output.document("sensitivity", inputs, system, settings, frequencies_hz, results=records)
    write_json(json_path, data)

    header = ["A [N]", "parameter", "value", "unit", "d x/dp [m/unit]", "e_x", "e_y"]
    if not args.no_optimum:
        header += ["e_x retuned", "e_y retuned", "e_k*", "e_c*"]
    rows = []
    for amplitude in amplitudes:
        ranked = sorted(
            (r for r in records if r["amplitude_N"] == float(amplitude)),
            key=lambda r: -abs(r["host_elasticity"]),
        )
        for r in ranked:
            row = [
                f"{amplitude:g}",
                r["parameter"],
                f"{r['value']:.5g}",
                r["unit"],
                f"{r['host_derivative_m_per_unit']:.3e}",
                f"{r['host_elasticity']:.4f}",
                f"{r['stroke_elasticity']:.4f}",
            ]
            if not args.no_optimum:
                row += [
                    f"{r['optimum_host_elasticity']:.4f}",
                    f"{r['optimum_stroke_elasticity']:.4f}",
                    f"{r['optimum_stiffness_elasticity']:.4f}",
                    "c* at 0" if r["optimum_damping_at_bound"]
                    else f"{r['optimum_damping_elasticity']:.4f}",
                ]
            rows.append(row)
    unconverged = [
        f"{a:g} N"
        for a, r in zip(amplitudes, results, strict=True)
        if not bool(r.converged) or (r.optimum is not None and not bool(r.optimum.converged))
    ]
    title = (
        f"Sensitivities of the peak responses ({_describe(system)}); e_x, e_y: elasticities "
        f"d ln(peak) / d ln(p) of the host peak and the inerter stroke; 'retuned': at the "
        f"tuning retuned for that amplitude, e_k*, e_c*: of its k and c ('c* at 0': the "
        f"optimal damping is at its bound 0, where it stays); ranked by |e_x|"
        + (f"\nnot converged at {', '.join(unconverged)}" if unconverged else "")
    )
    return output.finish(data, title + "\n" + _format_table(header, rows))


# --- tid-jax robust -------------------------------------------------------------------------

ROBUST_COLUMNS = (
    "host_frequency_scale",
    "amplitude_N",
    "best_k_N_per_m",
    "best_c_N_s_per_m",
    "best_x_peak_m",
    "robust_x_peak_m",
    "robust_ratio",
    "robust_stroke_m",
    "given_ratio",
    "given_stroke_m",
)


def _add_robust_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "robust",
        help="one TID tuning for a range of forcing amplitudes (and host frequencies)",
        description="The TID stiffness k and damping c minimising the worst case, over the "
        "forcing amplitudes (and host frequencies), of the peak host displacement over "
        "the best achievable at that amplitude, with the inerter stroke within the "
        "stroke limit; compared with the given (default: Den Hartog) tuning. Prints a "
        "table and saves robust.csv, robust.json, robust_config.toml and robust.png "
        "to --out.",
    )
    _add_system_arguments(parser)
    parser.add_argument(
        "--host-frequency-tolerance",
        dest="host_frequency_tolerance",
        type=float,
        default=0.0,
        metavar="FRACTION",
        help="also hold for host frequencies (1 +- FRACTION) times the nominal one, "
        "e.g. 0.05 (default 0: nominal only)",
    )
    parser.add_argument(
        "--no-stroke-limit",
        action="store_true",
        help="leave the inerter stroke free",
    )
    _add_output_arguments(parser)


def _run_robust(args) -> int:
    inputs = _inputs(args)
    tolerance = args.host_frequency_tolerance
    if not (math.isfinite(tolerance) and 0 <= tolerance < 1):
        raise CLIError(f"host_frequency_tolerance must be a fraction in [0, 1), got {tolerance!r}")
    system, settings = _system(inputs), _settings(inputs)
    frequencies_hz, omegas = _frequencies(inputs, system)
    amplitudes = np.asarray(inputs["amplitudes"])
    scales = (1 - tolerance, 1.0, 1 + tolerance) if tolerance > 0 else (1.0,)
    stroke_limit = None if args.no_stroke_limit else inputs["stroke_limit"]
    output = _Output(args)
    output.say(
        f"robust tuning over {amplitudes.size} amplitude(s) x {len(scales)} host "
        f"frequencies, {omegas.size} frequencies each; {_describe(system)}"
    )
    # The retune's steps, then the robust design's: its start, its stages and its end.
    with output.steps(RetuneSettings().progress_steps() + 3 + len(ROBUST_SHARPNESS)) as step:
        result = robust_tune(
            system,
            amplitudes,
            host_frequency_scales=scales,
            stroke_limit=stroke_limit,
            omegas=omegas,
            settings=settings,
            progress=step,
        )
    given = tuning_performance(system, result.best, settings=settings)
    robust = result.performance
    best = result.best
    records = [
        dict(
            zip(
                ROBUST_COLUMNS,
                (
                    float(scale),
                    float(amplitude),
                    float(best.tid_stiffness[i, j]),
                    float(best.tid_damping[i, j]),
                    float(best.host_peak[i, j]),
                    float(robust.host_peak[i, j]),
                    float(robust.ratio[i, j]),
                    float(robust.stroke_peak[i, j]),
                    float(given.ratio[i, j]),
                    float(given.stroke_peak[i, j]),
                ),
                strict=True,
            )
        )
        for i, scale in enumerate(scales)
        for j, amplitude in enumerate(amplitudes)
    ]
    write_csv(
        output.path("robust.csv"),
        ROBUST_COLUMNS,
        [[r[key] for key in ROBUST_COLUMNS] for r in records],
    )
    write_toml(
        output.path("robust_config.toml"), _config_data(inputs), comment=_config_comment("robust")
    )
    nominal = scales.index(1.0)
    plot.save_figure(
        plot.plot_robust_comparison(
            amplitudes,
            [
                (
                    f"given tuning: worst {float(given.worst_ratio):.3f}",
                    np.asarray(given.ratio[nominal]),
                    np.asarray(given.stroke_peak[nominal]),
                    dict(color="tab:red", linestyle="--", marker="."),
                ),
                (
                    f"robust: worst {float(result.worst_ratio):.3f}",
                    np.asarray(robust.ratio[nominal]),
                    np.asarray(robust.stroke_peak[nominal]),
                    dict(color="tab:blue", linewidth=2.0, marker="."),
                ),
            ],
            stroke_limit=stroke_limit,
            title="Robust TID tuning" + (" (nominal host frequency)" if tolerance > 0 else ""),
        ),
        output.path("robust.png"),
    )
    k_dh, c_dh = _den_hartog(system)
    k, c = float(result.tid_stiffness), float(result.tid_damping)
    summary = {
        "tid_stiffness": k,
        "tid_damping": c,
        "k_over_k_den_hartog": k / k_dh,
        "c_over_c_den_hartog": c / c_dh,
        "worst_ratio": float(result.worst_ratio),
        "worst_amplitude_N": float(result.worst_amplitude),
        "worst_host_frequency_scale": float(result.worst_host_frequency_scale),
        "stroke_limit_m": stroke_limit,
        "max_stroke_m": float(result.max_stroke),
        "given_worst_ratio": float(given.worst_ratio),
        "given_worst_amplitude_N": float(given.worst_amplitude),
        "iterations": int(result.iterations),
        "converged": bool(result.converged),
        "status": result.status_messages()[0],
    }
    json_path = output.path("robust.json")
    data = output.document(
        "robust",
        inputs,
        system,
        settings,
        frequencies_hz,
        host_frequency_scales=list(scales),
        robust=summary,
        results=records,
    )
    write_json(json_path, data)

    header = [
        "f_n x",
        "A [N]",
        "best k/k_DH",
        "best c/c_DH",
        "ratio robust",
        "ratio given",
        "stroke robust [cm]",
        "stroke given [cm]",
    ]
    rows = [
        [
            f"{r['host_frequency_scale']:g}",
            f"{r['amplitude_N']:g}",
            f"{r['best_k_N_per_m'] / k_dh:.3f}",
            f"{r['best_c_N_s_per_m'] / c_dh:.3f}",
            f"{r['robust_ratio']:.3f}",
            f"{r['given_ratio']:.3f}",
            f"{100 * r['robust_stroke_m']:.2f}",
            f"{100 * r['given_stroke_m']:.2f}",
        ]
        for r in records
    ]
    limit_text = (
        "no stroke limit"
        if stroke_limit is None
        else (f"max stroke {100 * summary['max_stroke_m']:.2f} cm (limit {100 * stroke_limit:g})")
    )
    title = (
        f"Robust tuning ({_describe(system)}): k = {k:.5g} N/m ({k / k_dh:.3f} k_DH), "
        f"c = {c:.4g} N s/m ({c / c_dh:.3f} c_DH); worst ratio to the best tuning "
        f"{summary['worst_ratio']:.3f} at {summary['worst_amplitude_N']:g} N"
        + (f", host frequency x {summary['worst_host_frequency_scale']:g}" if tolerance else "")
        + f" (given tuning: {summary['given_worst_ratio']:.3f} at "
        f"{summary['given_worst_amplitude_N']:g} N); {limit_text}; {summary['status']}"
    )
    return output.finish(data, title + "\n" + _format_table(header, rows))


# --- entry point ----------------------------------------------------------------------------

_COMMANDS = {
    "retune": (_add_retune_parser, _run_retune),
    "frf": (_add_frf_parser, _run_frf),
    "rtds": (_add_rtds_parser, _run_rtds),
    "sensitivity": (_add_sensitivity_parser, _run_sensitivity),
    "robust": (_add_robust_parser, _run_robust),
}


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=PROG,
        description="Design tuned inerter dampers (TIDs) whose inerter has dry friction.",
        epilog=f"Run '{PROG} COMMAND --help' for the options of each command.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for add_parser, _ in _COMMANDS.values():
        add_parser(subparsers)
    return parser


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split()) or type(error).__name__


def main(argv: list[str] | None = None) -> int:
    """Run `tid-jax` with the arguments `argv` (default `sys.argv[1:]`); returns the exit
    status: 0 on success, 2 on bad input (one line on stderr), 130 if interrupted."""
    jax.config.update("jax_enable_x64", True)
    parser = build_parser()
    try:
        try:
            args = parser.parse_args(argv)
        except SystemExit as exit_:  # --help and --version
            return exit_.code if isinstance(exit_.code, int) else 0
        if args.command is None:
            parser.print_help()
            return 0
        if not args.no_cache:
            enable_compilation_cache(args.cache_dir)
        return _COMMANDS[args.command][1](args)
    except (CLIError, ValueError, OSError) as error:
        print(f"{PROG}: error: {_one_line(error)}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(
            f"{PROG}: interrupted; files already written are complete, none is partial",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
