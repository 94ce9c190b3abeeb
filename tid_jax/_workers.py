"""Independent lanes solved at once in worker processes, one per CPU core.

XLA runs each program on one core of a CPU, and the retune's lanes (one amplitude or
scenario each, optimised independently) are solved one after another on one device. On a
CPU with several cores, `run_lanes` deals them out to this process and to worker
processes, each taking the next lane as it finishes one.
Processes, not threads: two threads of one process executing XLA's CPU programs at once
can deadlock in its runtime. The workers start when first needed (those of the `tid-jax`
command before it imports JAX: `_launch`) and serve every later call of this process;
they compute as this process does (the same precision and the same compilation cache,
which they load their programs from) and end with it, even where it is killed outright
in the middle of a task.

The number of processes is `$TID_JAX_WORKERS` (1: no workers), else the CPU cores this
process may use; off the CPU or with several devices there are no workers (the lanes are
sharded over the devices instead, `_sharding`).
"""

import atexit
import importlib
import os
import pickle
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence

import equinox._errors
import jax
import numpy as np

from ._cache import (
    before_compiling,
    cache_folder,
    compiles_watchable,
    enable_compilation_cache,
)
from ._launch import WORKERS_ENVIRONMENT_VARIABLE, cpu_cores, spawn_worker, take_started

_pool: list["_Worker"] = []


def process_count(lanes: int) -> int:
    """The processes (this one and its workers) that `run_lanes` uses for `lanes` lanes.

    **Arguments:** `lanes`, the number of lanes; `$TID_JAX_WORKERS` is read.

    **Returns:** `$TID_JAX_WORKERS` if set, else the CPU cores available to this process,
    at most `lanes`; 1 off the CPU or with several JAX devices.

    **Raises:** `ValueError` if `$TID_JAX_WORKERS` is not a whole number >= 1.
    """
    value = os.environ.get(WORKERS_ENVIRONMENT_VARIABLE)
    if value is None:
        count = cpu_cores()
    else:
        try:
            count = int(value)
        except ValueError:
            count = 0
        if count < 1:
            raise ValueError(f"${WORKERS_ENVIRONMENT_VARIABLE} must be a whole number of "
                             f"processes >= 1 (1: no worker processes), got {value!r}")
    if jax.default_backend() != "cpu" or len(jax.devices()) > 1:
        return 1
    return max(1, min(count, lanes))


def start_workers(lanes: int, warm_up: tuple[Callable, tuple] | None = None, *,
                  serves: Callable | None = None) -> bool:
    """Start the worker processes that `run_lanes` will use for `lanes` lanes, so that
    they load while this process computes. With `warm_up = (function, task)` and the
    compilation cache on, a worker not already warming up runs `function(*task)`
    meanwhile, its result (or error) dropped: it compiles the programs of the function
    `serves` (default `function`), or loads them from the cache, while this process
    computes something else. `run_lanes` of `serves` waits for it before it deals out
    tasks, then finds them in the cache; `run_lanes` of any other function deals that
    worker tasks once it has ended. Where every worker is warming up, the warm-up is
    dropped: this process compiles those programs when it needs them.

    Returns whether a worker started the warm-up (never without the cache, whose
    programs the warm-up would leave for the others to load)."""
    workers = _workers(process_count(lanes) - 1)
    if warm_up is None or cache_folder() is None:
        return False
    idle = [worker for worker in workers if not worker.warming_up()]
    if idle:
        idle[0].warm_up(*warm_up, serves=warm_up[0] if serves is None else serves)
    return bool(idle)


def run_lanes(function: Callable, tasks: Sequence[tuple], *, compiles: bool = False) -> list:
    """`[function(*task) for task in tasks]`, the tasks dealt out to this process and its
    workers (`process_count(len(tasks))` processes in all), each taking the next as it
    finishes one.

    `function` must be a module-level function of this package (it is sent to the workers
    by name), and its arguments and results picklable (NumPy arrays, not JAX arrays). An
    error raised by `function` is raised here (the one of the first such task); a task
    whose worker died is done in this process. With `compiles`, `function` runs compiled
    programs that a worker may not find in the compilation cache: this process runs the
    last task first, compiling them (or loading them from the cache), and a worker about
    to compile a program (or trace one to keep it) waits for that task to end, then
    loads the program from the cache if it is there by then, instead of compiling it at
    the same time; programs found in the cache it loads at once. Where the worker
    cannot watch its compilations, it waits for that task before it takes its first
    task of `function`. Without the cache there is nothing to share: every process
    compiles its own programs, at once.
    """
    tasks = list(tasks)
    for worker in _pool:
        if worker.warming_for is function:
            worker.settle()
    workers = _workers(process_count(len(tasks)) - 1)
    if not workers:
        return [function(*task) for task in tasks]
    results: list = [None] * len(tasks)
    errors: dict[int, BaseException] = {}
    left = list(range(len(tasks)))[::-1]
    lock = threading.Lock()
    compiled_here = threading.Event()

    def take(last=False):
        with lock:
            return left.pop(0 if last else -1) if left and not errors else None

    def serve(worker: "_Worker"):
        worker.settle()  # a warm-up for another function
        # A worker that cannot tell what it will compile (no watch on the cache it
        # shares) waits before it takes its first task of `function`. (Without the
        # cache it compiles its own programs: at once, beside this process.)
        if compiles and worker.cached and not worker.watched and function not in worker.ran:
            compiled_here.wait()
        while (i := take()) is not None:
            try:
                results[i] = worker.run(function, tasks[i],
                                        compiled_here.wait if compiles else None)
                worker.ran.add(function)
            except _WorkerLost:
                with lock:
                    left.append(i)
                worker.stop()  # so that the next call starts another
                return
            except Exception as error:
                errors[i] = error

    def run_here(i: int):
        try:
            results[i] = function(*tasks[i])
        except Exception as error:
            errors[i] = error

    threads = [threading.Thread(target=serve, args=(worker,), daemon=True)
               for worker in workers]
    for thread in threads:
        thread.start()
    if compiles and (i := take(last=True)) is not None:
        run_here(i)
    compiled_here.set()
    while (i := take()) is not None:
        run_here(i)
    for thread in threads:
        thread.join()
    # Tasks of workers that died after this process ran out of its own.
    while (i := take()) is not None:
        run_here(i)
    if errors:
        raise errors[min(errors)]
    return results


def run_shares(function: Callable, lanes: tuple, *args, here: bool = False) -> tuple:
    """`function(*lanes, *args)`, the lanes (a tuple of arrays, or pytrees of them, with
    a leading axis of lanes) dealt out in turn to the `process_count` processes, one
    share to each (`run_lanes` with `compiles`); `function` returns a tuple of arrays (or
    pytrees of them) over its share's lanes, here put back together in the lanes'
    order as NumPy arrays. With `here`, every share is run in this process, one after
    another: the programs of the shares' shapes are then compiled (or loaded) for a
    later call of the same shapes."""
    n = jax.tree.leaves(lanes)[0].shape[0]
    count = process_count(n)
    shares = [np.arange(n)[i::count] for i in range(count)]
    tasks = [(*jax.tree.map(lambda a, share=share: np.asarray(a)[share], lanes), *args)
             for share in shares]
    parts = ([function(*task) for task in tasks] if here
             else run_lanes(function, tasks, compiles=True))
    order = np.argsort(np.concatenate(shares))
    return jax.tree.map(lambda *values: np.concatenate(values)[order], *parts)


class _WorkerLost(Exception):
    """The worker process ended (killed, or out of memory) before it answered."""


class _Worker:
    """A worker process and the pipes to it: it receives `(function, args, careful)`
    pickled and answers `("ok", result)` or `("error", exception)`; while a careful task
    runs, it may also ask `("wait", None)` before it compiles a program, and go on when
    it receives `"go"`."""

    def __init__(self, process: subprocess.Popen | None = None):
        """A new worker process, or the worker `process` started earlier (`_launch`)."""
        self.warming: threading.Thread | None = None  # a warm-up in progress
        self.warming_for: Callable | None = None  # the function it prepares
        self.ran: set[Callable] = set()  # the functions it has run (programs loaded)
        folder = cache_folder()
        # Whether it shares this process's compilation cache (the folder it is sent), and
        # whether it sees its compilations coming (and asks to wait before each).
        self.cached = folder is not None
        self.watched = self.cached and compiles_watchable()
        self.process = process if process is not None else spawn_worker(
            x64=jax.config.jax_enable_x64, on_error=equinox._errors.EQX_ON_ERROR)
        self._send(None if folder is None else str(folder))

    def alive(self) -> bool:
        return self.process.poll() is None

    def _send(self, message) -> None:
        try:
            pickle.dump(message, self.process.stdin)
            self.process.stdin.flush()
        except (BrokenPipeError, OSError):
            raise _WorkerLost from None

    def run(self, function: Callable, args: tuple, wait: Callable[[], object] | None = None):
        """`function(*args)` in the worker; `wait()` (if given) is called whenever the
        worker is about to compile, and it goes on once `wait` returns."""
        self._send((function, args, wait is not None))
        while True:
            try:
                outcome, value = pickle.load(self.process.stdout)
            except (EOFError, OSError, pickle.UnpicklingError):
                raise _WorkerLost from None
            if outcome != "wait":
                break
            wait()
            self._send("go")
        if outcome == "error":
            raise value
        return value

    def warm_up(self, function: Callable, args: tuple, serves: Callable) -> None:
        """Start `function(*args)` in the worker, a warm-up for the function `serves`, in
        a thread of this process, its result and any error dropped (the task, run
        again for real, shows it), once the warm-up before it, if any, has ended."""
        self.settle()

        def run():
            try:
                self.run(function, args)
                self.ran.add(serves)
            except Exception:
                pass

        self.warming = threading.Thread(target=run, daemon=True)
        self.warming_for = serves
        self.warming.start()

    def warming_up(self) -> bool:
        """Whether a warm-up is in progress."""
        return self.warming is not None and self.warming.is_alive()

    def settle(self) -> None:
        """Wait for the warm-up in progress, if any."""
        if self.warming is not None:
            self.warming.join()
            self.warming = self.warming_for = None

    def stop(self) -> None:
        """End the worker: closing its input ends its loop; a worker that does not end
        within 5 s is killed."""
        try:
            self.process.stdin.close()
        except OSError:
            pass
        try:
            self.process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.process.stdout.close()


def _workers(count: int) -> list[_Worker]:
    """`count` running workers, started as needed and kept for later calls."""
    for worker in [worker for worker in _pool if not worker.alive()]:
        worker.stop()
        _pool.remove(worker)
    # Those the command line started early first (idle where more than `count`).
    _pool.extend(_Worker(process) for process in take_started())
    while len(_pool) < count:
        _pool.append(_Worker())
    return _pool[:max(count, 0)]


@atexit.register
def _stop_workers() -> None:
    for worker in _pool:
        worker.stop()
    _pool.clear()


def _answer(function, args):
    """What a worker sends back for `function(*args)`: an exception that cannot be sent
    becomes a `RuntimeError` with its message."""
    try:
        outcome = ("ok", function(*args))
    except Exception as error:
        outcome = ("error", error)
    try:
        return pickle.dumps(outcome)
    except Exception:
        error = outcome[1] if outcome[0] == "error" else None
        message = (f"{type(error).__name__}: {error}" if error is not None
                   else f"the result of {function.__qualname__} cannot be sent back")
        return pickle.dumps(("error", RuntimeError(message)))


def _end_with(parent: int) -> None:
    """End this process as soon as its parent, the process `parent`, has gone (it is then
    adopted by another): a parent killed outright never closes the worker's input, and a
    task, a compilation among them, would otherwise run on."""
    while os.getppid() == parent:
        time.sleep(0.5)
    os._exit(1)


def _serve(parent: int) -> None:
    """A worker's loop, for the process `parent`: tasks from stdin, answers on the
    original stdout (whatever else prints to stdout goes to stderr)."""
    threading.Thread(target=_end_with, args=(parent,), daemon=True).start()
    answers = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    tasks = sys.stdin.buffer
    # The steady-state core and the optimisers, which every task of this package runs,
    # imported while the caller prepares the first task.
    importlib.import_module(f"{__package__}._design")
    try:
        folder = pickle.load(tasks)
    except EOFError:  # started early, never used
        os._exit(0)
    if folder is not None:
        enable_compilation_cache(folder)
    careful = False

    def ask():
        # Before a compilation in a careful task: wait until this process's caller says go.
        if careful:
            answers.write(pickle.dumps(("wait", None)))
            answers.flush()
            pickle.load(tasks)  # "go"

    if folder is not None:
        before_compiling(ask)
    while True:
        try:
            function, args, careful = pickle.load(tasks)
        except EOFError:
            # The caller has closed the input and waits for this process: it ends at once,
            # without tearing down the interpreter (every answer is sent, every program
            # the cache keeps is written).
            sys.stderr.flush()
            os._exit(0)
        answers.write(_answer(function, args))
        answers.flush()
