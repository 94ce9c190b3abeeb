"""Independent lanes mapped over processes, at the edge.

A library function that solves independent lanes (the retune's amplitudes, shares of a
batch of steady states, the identification's scan of starting values) takes them through
a keyword `map_lanes`: a callable `map_lanes(function, tasks)` that returns
`[function(*task) for task in tasks]`. The default, `serial`, runs them here one after
another; `ProcessMap` runs them in a `concurrent.futures` process pool. Only the command
line and the experiment scripts decide on processes.

Processes, not threads: XLA's CPU runtime runs each program on one core, and two threads
of one process executing its programs at once can deadlock in it.
"""

import concurrent.futures
import multiprocessing
from collections.abc import Callable, Sequence

import numpy as np


def serial(function: Callable, tasks: Sequence[tuple]) -> list:
    """`[function(*task) for task in tasks]`, in this process (the default `map_lanes`)."""
    return [function(*task) for task in tasks]


class ProcessMap:
    """A `map_lanes` over a pool of `processes` worker processes (`concurrent.futures`,
    started by spawning) that compute as this process does when the pool is made: in
    the same precision, with the same compilation cache (`enable_compilation_cache`),
    then set up by `initializer(*initargs)` (a module-level function) if given.
    `function` and the tasks must be picklable: a module-level function, NumPy arrays,
    equinox Modules. Use it as a context manager, or `close()` it.

    ```python
    with tj.ProcessMap(2) as pool:
        result = tj.retune(system, amplitudes, map_lanes=pool)
    ```

    An entry point that makes the pool before it imports JAX (so that the workers start
    meanwhile) gives their precision `x64` and compilation cache folder `cache_dir`
    (None: no cache) instead.
    """

    def __init__(self, processes: int, *, initializer: Callable | None = None,
                 initargs: tuple = (), x64: bool | None = None,
                 cache_dir: str | None | type[Ellipsis] = ...):
        if not (isinstance(processes, int) and not isinstance(processes, bool)
                and processes >= 1):
            raise ValueError(f"processes must be a whole number >= 1, got {processes!r}")
        if x64 is None:
            import jax

            x64 = bool(jax.config.jax_enable_x64)
        if cache_dir is ...:
            from ._cache import cache_folder

            folder = cache_folder()
            cache_dir = None if folder is None else str(folder)
        self.processes = processes
        self.cache_dir = cache_dir
        self._executor = concurrent.futures.ProcessPoolExecutor(
            processes, mp_context=multiprocessing.get_context("spawn"),
            initializer=_set_up, initargs=(x64, cache_dir, initializer, initargs))

    def start(self) -> None:
        """Start the worker processes now (they are set up while this process goes on),
        rather than at the first call: the pool spawns a process for each task submitted
        while none is idle."""
        for _ in range(self.processes):
            self._executor.submit(_nothing)

    def __call__(self, function: Callable, tasks: Sequence[tuple]) -> list:
        futures = [self._executor.submit(function, *task) for task in tasks]
        try:
            return [future.result() for future in futures]
        except BaseException:
            for future in futures:
                future.cancel()
            raise

    def close(self) -> None:
        """Shut the pool down: tasks not yet started are cancelled, and this process waits
        for the worker processes to end (a process that ends before them would leave
        them running)."""
        self._executor.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> "ProcessMap":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def _nothing() -> None:
    return None


def _set_up(x64: bool, cache: str | None, initializer: Callable | None, initargs: tuple):
    """A worker process's start: the precision and compilation cache of the process that
    made the pool, then its `initializer`."""
    import jax

    from ._cache import enable_compilation_cache

    jax.config.update("jax_enable_x64", x64)
    if cache is not None:
        enable_compilation_cache(cache)
    if initializer is not None:
        initializer(*initargs)


def process_count(map_lanes: Callable) -> int:
    """The processes `map_lanes` spreads its tasks over: its `processes`, else 1."""
    return int(getattr(map_lanes, "processes", 1))


def map_shares(map_lanes: Callable, function: Callable, lanes: tuple, *args) -> tuple:
    """`function(*lanes, *args)` with the lanes (a tuple of arrays, or pytrees of them,
    with a leading axis of lanes) dealt out in turn into one share per process of
    `map_lanes`; `function` returns a tuple of arrays over its share's lanes (or pytrees of
    them), here put back together in the lanes' order as NumPy arrays."""
    import jax  # (the pool above starts without JAX)

    n = jax.tree.leaves(lanes)[0].shape[0]
    count = max(1, min(process_count(map_lanes), n))
    shares = [np.arange(n)[i::count] for i in range(count)]
    tasks = [(*jax.tree.map(lambda a, share=share: np.asarray(a)[share], lanes), *args)
             for share in shares]
    parts = map_lanes(function, tasks)
    order = np.argsort(np.concatenate(shares))
    return jax.tree.map(lambda *values: np.concatenate(values)[order], *parts)
