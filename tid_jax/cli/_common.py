"""What the commands share: their constants, inputs (flags and TOML to library objects),
what a run starts from, its output folder and progress, and the worker processes. (Their
shared arguments are in `_arguments`, their records and tables in `_tables`.)"""

import argparse
import contextlib
import math
import shutil
import sys
import time
import tomllib
from pathlib import Path
from typing import NamedTuple

import numpy as np
from tqdm import tqdm

from .. import __version__
from .._model._checks import check_steady_state_device
from .._model._linear import (
    den_hartog_tuning,
    host_receptance,
    stuck_receptance,
)
from .._model._system import (
    DEFAULT_FRICTION_WIDTH,
    DEVICE_TERMS,
    PAPER_AMPLITUDES,
    PAPER_FRICTION_FORCE,
    PAPER_HOST_DAMPING_RATIO,
    PAPER_HOST_FREQUENCY_HZ,
    PAPER_HOST_MASS,
    PAPER_INERTANCE,
    PAPER_STROKE,
    TIDSystem,
)
from .._orbit._settings import SolverSettings
from .._peaks import DEFAULT_FREQUENCIES, default_omegas
from .._runtime._cache import cache_folder
from .._runtime._io import check_writable_dir, json_text
from .._runtime._parallel import ProcessMap, serial
from ._building_config import BUILDING_TABLES, amplitude_value, check_harmonic, check_tables
from ._pool import import_library, requested_workers

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
    ("friction_width", "m/s", "velocity scale of the smoothed friction sign; 0: exact "
     "Coulomb friction with sticking (the default of a rigid device); 'relative': 0.02 "
     "omega A/K at each forcing point (the default of a compliant device)",
     "non-negative"),
    ("tid_stiffness", "N/m", "TID spring stiffness k (default: Den Hartog)", "positive"),
    ("tid_damping", "N s/m", "TID damping c (default: Den Hartog)", "non-negative"),
    ("parasitic_damping", "N s/m", "parasitic viscous damping of the inerter, in parallel with "
     "its inertance (default 0)", "non-negative"),
    ("terminal_mass", "kg", "moving mass at the inerter's driven terminal (default 0)",
     "non-negative"),
    ("series_stiffness", "N/m", "stiffness of screw, nut and mounts in series with the "
     "inerter mechanism (default: rigid; a compliant device needs terminal_mass > 0, and "
     "smoothed friction)", "positive"),
    ("backlash", "m", "total free play in that series connection (default 0; needs "
     "series_stiffness)", "non-negative"),
    ("stroke_limit", "m", "inerter stroke limit, +-", "positive"),
)
# The `friction_width` that takes the width relative to each forcing point's motion
# (`TIDSystem`'s None).
RELATIVE_WIDTH = "relative"
GRID_INPUTS = ("amplitudes", "band_hz", "n_frequencies")
INPUT_KEYS = tuple(key for key, *_ in PHYSICAL_INPUTS) + GRID_INPUTS
SOLVER_TABLE = "solver"
# The inerter device's keys: at the top level of a config or in its [inerter] table (the
# configs that commands write use the table).
INERTER_TABLE = "inerter"
INERTER_KEYS = ("inertance", "friction_force", "friction_width", *DEVICE_TERMS)
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
DEVICE_UNITS = {key: unit for key, unit, *_ in PHYSICAL_INPUTS if key in DEVICE_TERMS}


class CLIError(Exception):
    """A problem with the user's input, reported as one line."""


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)  # a mistyped flag is an error, not a guess
        super().__init__(*args, **kwargs)

    def error(self, message):
        raise CLIError(f"{message} (see '{self.prog} --help')")


# --- from flags and TOML to library objects ---------------------------------------------


def _read_config(path: str) -> dict:
    """The checked contents of the config file `path`, its [inerter] table merged into
    the top level."""
    try:
        with open(path, "rb") as file:
            config = tomllib.load(file)
    except tomllib.TOMLDecodeError as error:
        raise CLIError(f"config {path} is not valid TOML: {error}") from None
    except OSError as error:
        raise CLIError(f"cannot read config {path}: {error.strerror}") from None
    tables = (SOLVER_TABLE, INERTER_TABLE, *BUILDING_TABLES)
    unknown = [key for key in config if key not in INPUT_KEYS + tables]
    if unknown:
        raise CLIError(
            f"config {path}: unknown key {unknown[0]!r}; allowed keys are "
            f"{', '.join(INPUT_KEYS)}, an [{INERTER_TABLE}] and a [{SOLVER_TABLE}] table, "
            f"and for a building [{'], ['.join(BUILDING_TABLES)}]"
        )
    # the friction model follows friction_width (0: exact), not a solver setting
    solver_keys = tuple(name for name in SolverSettings.__dataclass_fields__
                        if name != "exact_friction")
    for table, allowed in ((SOLVER_TABLE, solver_keys), (INERTER_TABLE, INERTER_KEYS)):
        entries = config.get(table, {})
        if not isinstance(entries, dict):
            raise CLIError(f"config {path}: {table} must be a table [{table}]")
        unknown = [key for key in entries if key not in allowed]
        if unknown:
            raise CLIError(
                f"config {path}: unknown key {unknown[0]!r} in [{table}]; "
                f"allowed keys are {', '.join(allowed)}"
            )
    if any(name in config for name in BUILDING_TABLES):
        try:
            check_tables(config, path)
        except ValueError as error:
            raise CLIError(str(error)) from None
    inerter = config.pop(INERTER_TABLE, {})
    twice = [key for key in inerter if key in config]
    if twice:
        raise CLIError(f"config {path}: {twice[0]!r} is given both at the top level and in "
                       f"[{INERTER_TABLE}]; give it once")
    return {**config, **inerter}


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
    if "structure" in config:  # a building: its tables, and amplitudes that may be "0.2g"
        inputs.update({name: config[name] for name in BUILDING_TABLES if name in config})
        if "amplitudes" in given:
            inputs["amplitudes_given"] = True
            amplitudes = given["amplitudes"]
            try:
                inputs["amplitudes"] = [
                    amplitude_value(a) for a in (amplitudes if isinstance(amplitudes, list)
                                                 else [amplitudes])]
            except ValueError as error:
                raise CLIError(str(error)) from None
    else:  # the single-storey host: the load and the response of `random` and `records`
        inputs.update({name: config[name] for name in ("load", "response") if name in config})
    try:
        check_harmonic(inputs.get("load", {}), getattr(args, "command", None))
    except ValueError as error:
        raise CLIError(str(error)) from None
    for key, _, _, allowed in PHYSICAL_INPUTS:
        if key in inputs and not (key == "friction_width" and inputs[key] == RELATIVE_WIDTH):
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
        friction_width=_friction_width(inputs),
        **{name: inputs[name] for name in DEVICE_TERMS if name in inputs},
    )


def _friction_width(inputs: dict) -> float | None:
    width = inputs.get("friction_width", DEFAULT_FRICTION_WIDTH)
    return None if width == RELATIVE_WIDTH else width


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


class _Start(NamedTuple):
    """What a command starts from: its inputs (flags over TOML over defaults), the system,
    the solver settings, the band (Hz and rad/s), the amplitudes (N) and the checked
    output folder."""

    inputs: dict
    system: TIDSystem
    settings: SolverSettings
    frequencies_hz: np.ndarray
    omegas: np.ndarray
    amplitudes: np.ndarray
    output: "_Output"


def _start(args) -> _Start:
    """The inputs of a command and what follows from them."""
    inputs = _inputs(args)
    system = _system(inputs)
    check_steady_state_device(system, f"{PROG} {args.command}")
    frequencies_hz, omegas = _frequencies(inputs, system)
    # The settings as given (the library fits them to the system, which
    # `check_steady_state_device` has checked it can): the compiled programs are then
    # those of a library call with the same settings, each serving the other from the cache.
    return _Start(inputs, system, _settings(inputs), frequencies_hz, omegas,
                  np.asarray(inputs["amplitudes"]), _Output(args))


def _den_hartog(system: TIDSystem) -> tuple[float, float]:
    k, c = den_hartog_tuning(system.host_mass, system.host_stiffness, system.inertance)
    return float(k), float(c)


def _linear_normalised(system: TIDSystem, frequencies_hz) -> tuple[np.ndarray, np.ndarray]:
    """|x| and |y| over A / K of the frictionless TID at `frequencies_hz`."""
    receptance = host_receptance(system, 2 * math.pi * np.asarray(frequencies_hz))
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
        f"ff = {float(system.friction_force):g} N"
        f"{' (exact Coulomb friction)' if system.exact_friction else ''}, "
        f"k = {float(system.tid_stiffness):.5g} N/m, "
        f"c = {float(system.tid_damping):.4g} N s/m"
        + "".join(f", {name} = {value:.4g} {DEVICE_UNITS[name]}"
                  for name, value in system.to_dict().items()
                  if name in DEVICE_TERMS and value not in (None, DEVICE_TERMS[name]))
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
        """The JSON record of a run: inputs, system, solver settings (as the system's model
        takes them), version, results."""
        k_dh, c_dh = _den_hartog(system)
        return {
            "command": f"{PROG} {command}",
            "version": __version__,
            "inputs": inputs,
            "system": system.to_dict(),
            "den_hartog": {"tid_stiffness": k_dh, "tid_damping": c_dh},
            "solver": settings.for_system(system).to_dict(),
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


def _config_comment(command: str) -> str:
    return (
        f"Inputs of `{PROG} {command}` (tid_jax {__version__}); rerun with\n"
        f"{PROG} {command} --config THIS_FILE"
    )


def _config_data(inputs: dict) -> dict:
    """`inputs` as a config file holds them: the device's keys in an [inerter] table."""
    data = {key: value for key, value in inputs.items()
            if key not in INERTER_KEYS and value != {}}
    inerter = {key: inputs[key] for key in INERTER_KEYS if key in inputs}
    return {**data, INERTER_TABLE: inerter} if inerter else data


def _breakaway_line(breakaway) -> str:
    """What the minimum breakaway amplitude over the band means, in one line."""
    return (f"Breakaway amplitude over the band: {float(breakaway.minimum):.4g} N at "
            f"{float(breakaway.omega_minimum) / (2 * math.pi):.3f} Hz; below it the inerter "
            f"never slips and the TID acts as a spring and damper to ground.")


# --- processes ------------------------------------------------------------------------


def worker_count(args) -> int:
    """The processes a command spreads its lanes over: `--workers`, else
    `$TID_JAX_WORKERS`, else one per CPU core; 1 off the CPU or with several JAX devices
    (whose lanes are sharded over the devices instead)."""
    try:
        count = requested_workers(args.workers)
    except ValueError as error:
        raise CLIError(str(error)) from None
    import jax

    if jax.default_backend() != "cpu" or len(jax.devices()) > 1:
        return 1
    return count


@contextlib.contextmanager
def lane_map(args, started: ProcessMap | None = None):
    """The `map_lanes` of a command: `serial` for one process, else a `ProcessMap` of
    `worker_count(args)` processes (computing as this one does), the pool `started`
    before JAX was imported where it has as many, else one started now; shut down when
    the command ends."""
    count = worker_count(args)
    cache = None if args.no_cache else cache_folder()
    if started is not None and (count != started.processes
                                or started.cache_dir != (None if cache is None else str(cache))):
        started.close()
        started = None
    if count == 1:
        yield serial
        return
    pool = started
    if pool is None:
        pool = ProcessMap(count, initializer=import_library)
        pool.start()
    try:
        yield pool
    finally:
        pool.close()
