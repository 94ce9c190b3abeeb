"""The `tid-jax` command's entry point: the worker processes of a command that deals out
lanes (`_workers`) are started before this process imports JAX and the library, so that
they import them meanwhile, on the other cores, and are ready (and warmed up, where the
command warms them up) by the time the command first deals out lanes.

Nothing here imports JAX: a worker process is started with the precision and error mode
it is to compute with (as the command does: double precision), and `_workers` takes the
processes started early over when it first needs workers (`take_started`).
"""

import argparse
import gc
import os
import subprocess
import sys
from pathlib import Path

WORKERS_ENVIRONMENT_VARIABLE = "TID_JAX_WORKERS"
# The commands whose computations are dealt out to worker processes (`_workers.run_lanes`).
COMMANDS_WITH_WORKERS = ("retune", "sensitivity", "robust", "identify")

# The thresholds of Python's cyclic garbage collector in this package's own processes (the
# command and its worker processes), set before they import JAX: its youngest generation
# collected every 50,000 net allocations rather than 700. Importing JAX and this package,
# tracing and loading compiled programs make millions of small objects that live on, and
# the default thresholds walk them again and again (half a second of each import alone).
GC_THRESHOLDS = (50_000, 20, 20)

# Worker processes started early, until `_workers` takes them over.
_started: list[subprocess.Popen] = []


def spawn_worker(*, x64: bool, on_error: str) -> subprocess.Popen:
    """A worker process (`_workers._serve`) of this process, computing in double precision
    where `x64`, with equinox's run-time errors set to `on_error`; its tasks come on its
    standard input (the first message: the compilation cache's folder), its answers on its
    standard output. It collects garbage at `GC_THRESHOLDS`."""
    package_root = str(Path(__file__).resolve().parent.parent)
    path = os.environ.get("PYTHONPATH")
    env = dict(
        os.environ,
        # As this process computes (JAX reads these when imported).
        JAX_ENABLE_X64=str(bool(x64)),
        EQX_ON_ERROR=on_error,
        JAX_PLATFORMS="cpu",
        # This package from where this process has it, and no workers of its own.
        PYTHONPATH=package_root + (os.pathsep + path if path else ""),
        **{WORKERS_ENVIRONMENT_VARIABLE: "1"},
    )
    serve = (f"import gc; gc.set_threshold(*{GC_THRESHOLDS}); "
             f"from tid_jax._workers import _serve; _serve({os.getpid()})")
    return subprocess.Popen([sys.executable, "-c", serve], env=env, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE)


def cpu_cores() -> int:
    """The CPU cores this process may use."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def early_workers(argv: list[str]) -> int:
    """How many worker processes the command line `argv` (without the program's name) is
    to start at once: the CPU cores this process may use less one (or `--workers`, else
    `$TID_JAX_WORKERS`, less one) for a command of `COMMANDS_WITH_WORKERS`; none for
    another command, for help, for a count that is not a whole number, or off the CPU
    (`$JAX_PLATFORMS` naming another platform). The command itself judges its arguments
    (and `_workers.process_count` the processes it uses)."""
    if not argv or argv[0] not in COMMANDS_WITH_WORKERS or {"-h", "--help"} & set(argv):
        return 0
    if os.environ.get("JAX_PLATFORMS", "cpu").strip().lower() not in ("", "cpu"):
        return 0
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--workers")
    given = parser.parse_known_args(argv[1:])[0].workers
    given = given if given is not None else os.environ.get(WORKERS_ENVIRONMENT_VARIABLE)
    if given is None:
        return cpu_cores() - 1
    try:
        return max(0, int(given) - 1)
    except ValueError:
        return 0


def take_started() -> list[subprocess.Popen]:
    """The worker processes started early (in double precision, as the command computes),
    handed over once."""
    taken = list(_started)
    _started.clear()
    return taken


def run() -> None:
    """The `tid-jax` command (`cli.run`), its worker processes started first: in double
    precision, as the command computes, with equinox's run-time errors as set in the
    environment (the command's compilation cache turns them to NaN in each worker). Both
    collect garbage at `GC_THRESHOLDS`."""
    gc.set_threshold(*GC_THRESHOLDS)
    on_error = os.environ.get("EQX_ON_ERROR", "raise")
    for _ in range(early_workers(sys.argv[1:])):
        _started.append(spawn_worker(x64=True, on_error=on_error))
    from .cli import run as run_command

    run_command()
