"""The worker processes of a command that maps independent lanes (`--workers`): how many,
and the pool started before JAX is imported, so that the workers start meanwhile.

Nothing here imports JAX at import.
"""

import argparse
import os
from pathlib import Path

from .._runtime._cache_folder import default_cache_dir
from .._runtime._parallel import ProcessMap

WORKERS_ENVIRONMENT_VARIABLE = "TID_JAX_WORKERS"
# The commands whose independent lanes are mapped over processes.
COMMANDS_WITH_LANES = ("retune", "sensitivity", "robust", "identify")


def cpu_cores() -> int:
    """The CPU cores this process may use."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def requested_workers(workers: int | None) -> int:
    """The worker processes asked for: `workers` (`--workers`), else `$TID_JAX_WORKERS`,
    else one per CPU core. Raises `ValueError` naming the input if not a whole number
    >= 1."""
    if workers is None:
        value = os.environ.get(WORKERS_ENVIRONMENT_VARIABLE)
        try:
            workers = cpu_cores() if value is None else int(value)
        except ValueError:
            raise ValueError(f"${WORKERS_ENVIRONMENT_VARIABLE} must be a whole number of "
                             f"processes >= 1, got {value!r}") from None
    if workers < 1:
        raise ValueError(f"--workers must be at least 1, got {workers}")
    return workers


def _on_one_cpu_device() -> bool:
    """Whether JAX will compute on one CPU device, as the environment says before JAX is
    imported (else the lanes are sharded over the devices, with no worker processes)."""
    platforms = os.environ.get("JAX_PLATFORMS", "cpu").strip().lower()
    flags = os.environ.get("XLA_FLAGS", "")
    return platforms in ("", "cpu") and "xla_force_host_platform_device_count" not in flags


def early_pool(argv: list[str]) -> ProcessMap | None:
    """The started pool of the command line `argv` (without the program's name) if its
    command maps lanes over more than one process, else None: computing in double
    precision with the compilation cache the command will use, and importing the library
    (`import_library`) while this process imports it too. The command itself judges its
    arguments; `lane_map` takes the pool over if it agrees."""
    if not argv or argv[0] not in COMMANDS_WITH_LANES or {"-h", "--help"} & set(argv):
        return None
    if not _on_one_cpu_device():
        return None
    parser = argparse.ArgumentParser(add_help=False)
    parser.add_argument("--workers")
    parser.add_argument("--cache-dir", dest="cache_dir")
    parser.add_argument("--no-cache", dest="no_cache", action="store_true")
    known = parser.parse_known_args(argv[1:])[0]
    try:
        workers = requested_workers(None if known.workers is None else int(known.workers))
    except ValueError:
        return None
    if workers == 1:
        return None
    # as `enable_compilation_cache` reads the folder, so that `lane_map` recognises it
    folder = (None if known.no_cache else
              Path(known.cache_dir).expanduser() if known.cache_dir is not None else
              default_cache_dir())
    pool = ProcessMap(workers, initializer=import_library, x64=True,
                      cache_dir=None if folder is None else str(folder))
    pool.start()
    return pool


def import_library() -> None:
    """A worker process's first step: the library's modules imported (and the figures')
    before its first task, while the command sets its inputs up."""
    from .. import _robust, _sensitivity, plot  # noqa: F401
    from .._identify import _fit  # noqa: F401
