"""The `tid-jax` command-line tool (`main`; the console script `run`).

Nothing here imports JAX or equinox: `run` first sets `EQX_ON_ERROR=nan` in the
environment and starts the worker processes of a command that maps lanes (`_pool`) (equinox's documented switch, read when it is imported), so that programs
holding equinox's run-time checks can be kept in the compilation cache; every solve
reports its own status, so a failed point is flagged, not raised.
"""

import os
import sys


def main(argv: list[str] | None = None, *, started=None) -> int:
    """Run `tid-jax` with the arguments `argv` (default `sys.argv[1:]`); returns the exit
    status: 0 on success, 2 on bad input (one line on stderr), 130 if interrupted.
    `started`: the command's worker processes if already started (`run`)."""
    from ._main import main as run_main

    return run_main(argv, started=started)


def run() -> None:
    """The `tid-jax` command: equinox's run-time checks set to NaN (unless
    `$EQX_ON_ERROR` says otherwise), the worker processes of a command that maps lanes
    started (they import JAX and the library while this process does), then `main` on
    the command line's arguments."""
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    from ._pool import early_pool

    status = main(started=early_pool(sys.argv[1:]))
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except OSError:  # a closed pipe (`tid-jax ... | head`)
            pass
    # Every file written is complete and closed, and the worker processes have ended: the
    # interpreter's teardown of JAX (about a second) is skipped. (`python -m tid_jax.cli`
    # exits as usual, for tools that act at exit: profilers, coverage.)
    os._exit(status)
