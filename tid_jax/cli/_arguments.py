"""The arguments that the commands share: the structure and device, the forcing and the
frequency band, the output, the compilation cache and the processes."""

import argparse

from .._peaks import DEFAULT_FREQUENCIES
from .._runtime._cache_folder import CACHE_ENVIRONMENT_VARIABLE
from ._common import DEFAULTS, PHYSICAL_INPUTS, RELATIVE_WIDTH
from ._pool import WORKERS_ENVIRONMENT_VARIABLE


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
            type=_width_flag if key == "friction_width" else float,
            metavar="RATIO" if unit == "-" else unit,
            help=f"{description} [{unit}]"
            + (f", default {DEFAULTS[key]:g}" if key in DEFAULTS else ""),
        )


def _width_flag(text: str) -> float | str:
    if text == RELATIVE_WIDTH:
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be a number (m/s) or {RELATIVE_WIDTH!r}, got {text!r}") from None


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
    _add_band_arguments(grid)


def _add_band_arguments(group) -> None:
    """--band-hz and --n-frequencies."""
    group.add_argument(
        "--band-hz",
        dest="band_hz",
        nargs=2,
        type=float,
        metavar=("LOW", "HIGH"),
        help="forcing frequency band [Hz] (default: 0.65-1.4 times the host "
        "frequency, both resonance peaks)",
    )
    group.add_argument(
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
    processes = parser.add_argument_group("processes")
    processes.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="worker processes that share the independent lanes on a CPU (the optimised "
        "amplitudes, shares of the batches of steady states, identify's scan of starting "
        f"values) (default: ${WORKERS_ENVIRONMENT_VARIABLE}, else one per CPU core; 1: "
        "none, this process computes alone)",
    )
