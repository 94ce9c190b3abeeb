"""The `tid-jax` command: its parser, and `main`, which turns any `CLIError`, `ValueError`
or `OSError` into one line `tid-jax: error: <problem>` on stderr and exit status 2.

Each subcommand is a module of this package with a pair `_add_<name>_parser(subparsers)`
/ `_run_<name>(args) -> int`, registered in `_COMMANDS`. Their shared arguments are in
`_arguments` (`_add_system_arguments`, `_add_output_arguments`); `_common` has
`_inputs`/`_system`/`_settings`/`_frequencies` (from flags and TOML to library objects),
`lane_map` (the processes a command's lanes are mapped over: `args.map_lanes`) and
`_Output` (output folder, progress, files written); `_tables` the records and tables.
"""

import argparse
import contextlib
import sys

import jax

from .. import __version__
from .._runtime._cache import enable_compilation_cache
from .._runtime._parallel import ProcessMap, serial
from ._common import EXIT_ERROR, EXIT_INTERRUPTED, PROG, CLIError, _Parser, lane_map
from ._pool import COMMANDS_WITH_LANES
from .frf import _add_frf_parser, _run_frf
from .identify import _add_identify_parser, _run_identify
from .random import _add_random_parser, _run_random
from .records import _add_records_parser, _run_records
from .retune import _add_retune_parser, _run_retune
from .robust import _add_robust_parser, _run_robust
from .rtds import _add_rtds_parser, _run_rtds
from .sensitivity import _add_sensitivity_parser, _run_sensitivity

_COMMANDS = {
    "retune": (_add_retune_parser, _run_retune),
    "frf": (_add_frf_parser, _run_frf),
    "rtds": (_add_rtds_parser, _run_rtds),
    "sensitivity": (_add_sensitivity_parser, _run_sensitivity),
    "robust": (_add_robust_parser, _run_robust),
    "identify": (_add_identify_parser, _run_identify),
    "random": (_add_random_parser, _run_random),
    "records": (_add_records_parser, _run_records),
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


def main(argv: list[str] | None = None, *, started: ProcessMap | None = None) -> int:
    """Run `tid-jax` with the arguments `argv` (default `sys.argv[1:]`); returns the exit
    status: 0 on success, 2 on bad input (one line on stderr), 130 if interrupted.
    `started`: the command's worker processes, started before JAX was imported
    (`_pool.early_pool`), if any."""
    try:
        return _main(argv, started)
    finally:
        if started is not None:
            started.close()


def _main(argv: list[str] | None, started: ProcessMap | None) -> int:
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
        lanes = (lane_map(args, started) if args.command in COMMANDS_WITH_LANES
                 else contextlib.nullcontext(serial))
        with lanes as args.map_lanes:
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
