"""Compiled programs kept on disk between runs, through JAX's public switches.

Tracing, lowering and compiling the batched steady-state and retuning programs takes
most of a short run. With the cache on (`enable_compilation_cache`):

- JAX's persistent compilation cache keeps every compiled executable;
- `compiled` keeps the traced and lowered program of this package's entry points, as a
  serialized `jax.export`, under a key made of its static arguments, the shapes and
  dtypes of its arrays, the sources of this package and the versions of JAX and its
  libraries. A later run loads it instead of tracing the function again, and finds its
  executable in JAX's cache.

JAX neither exports nor caches programs holding host callbacks; equinox's run-time checks
are host callbacks unless `EQX_ON_ERROR=nan` is in the environment before equinox is
imported (its documented switch), as the `tid-jax` command sets it.
"""

import functools as ft
import hashlib
import importlib.metadata
import os
import pickle
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import jax

from ._cache_folder import default_cache_dir

_LIBRARIES = ("jax", "jaxlib", "equinox", "diffrax", "optimistix", "lineax")
PROGRAMS = "programs"
# Kept programs unused for this long are deleted (those of older sources or library
# versions, which no key can reach again), when the cache is turned on.
STALE_DAYS = 30

_programs_folder: Path | None = None


def enable_compilation_cache(directory: str | os.PathLike | None = None) -> Path | None:
    """Keep compiled programs on disk: JAX's persistent compilation cache for every
    program, however quickly it compiles (the small ones between the solves add up to
    seconds), and the traced programs of this package's entry points in its `programs/`.
    Call it before the first computation.

    **Arguments:**

    - `directory`: the cache folder (default `default_cache_dir()`).

    **Returns:** the folder, or `None` (and nothing changes) when the cache is turned off
    or its folder cannot be created.
    """
    global _programs_folder
    folder = default_cache_dir() if directory is None else Path(directory).expanduser()
    if folder is None:
        return None
    try:
        (folder / PROGRAMS).mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    # Nor XLA's own GPU caches inside the folder: JAX would write their paths into every
    # program's compile options, hence into its key, so that a folder copied or moved
    # would hold no program found.
    jax.config.update("jax_persistent_cache_enable_xla_caches", None)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _programs_folder = folder / PROGRAMS
    _prune(_programs_folder, time.time() - STALE_DAYS * 86400)
    return folder


def cache_folder() -> Path | None:
    """The folder of the compilation cache if `enable_compilation_cache` turned it on in
    this process, else `None`."""
    return None if _programs_folder is None else _programs_folder.parent


def _used(path: Path) -> None:
    """Mark the kept program at `path` as in use (not stale)."""
    try:
        os.utime(path)
    except OSError:
        pass


def _prune(folder: Path, before: float) -> None:
    """Delete the kept programs in `folder` last used before the time `before`."""
    for path in folder.iterdir():
        try:
            if path.stat().st_mtime < before:
                path.unlink()
        except OSError:  # gone already, or not ours to delete
            pass


@ft.cache
def _fingerprint() -> str:
    """Hash of this package's sources, the versions of JAX and its libraries, and the
    platform and precision JAX computes with: a kept program is valid only for these."""
    digest = hashlib.sha256()
    for path in sorted(Path(__file__).parent.rglob("*.py")):
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    for library in _LIBRARIES:
        digest.update(f"{library}={importlib.metadata.version(library)}".encode())
    digest.update(f"{jax.default_backend()} x64={jax.config.jax_enable_x64}".encode())
    return digest.hexdigest()


def _is_traced(tree) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(tree))


def _write(path: Path, blob: bytes) -> None:
    """Write `blob` to `path` whole or not at all (other processes may be reading it)."""
    with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as file:
        file.write(blob)
    os.replace(file.name, path)


class _Program:
    """`eqx.filter_jit(function)` whose traced programs are kept on disk while the cache
    is on, each compiled with the XLA options that `options(*args, **kwargs)` gives (if
    `options` is given; then also while the cache is off). Calls inside a transformation
    (arguments that are tracers), and the others without options while the cache is off,
    go to `eqx.filter_jit` as usual."""

    def __init__(self, function: Callable, options: Callable[..., dict] | None = None):
        self.function = function
        self.jitted = eqx.filter_jit(function)
        self.options = options
        self.programs: dict[str, tuple] = {}
        ft.update_wrapper(self, function)

    def __call__(self, *args, **kwargs):
        folder = _programs_folder
        if _is_traced((args, kwargs)) or (folder is None and self.options is None):
            return self.jitted(*args, **kwargs)
        key, leaves = self._prepared(folder, args, kwargs)
        run, skeletons = self.programs[key]
        out = run(*leaves)
        return jax.tree.unflatten(jax.tree.structure(skeletons[-1]), out)

    def compile_only(self, *args, **kwargs) -> None:
        """Compile the program for these arguments (only their shapes, dtypes and static
        values matter) without running it, into JAX's cache, where other processes find
        it, and for later calls here. Nothing happens while the cache is off."""
        folder = _programs_folder
        if folder is None or _is_traced((args, kwargs)):
            return
        key, leaves = self._prepared(folder, args, kwargs)
        run, skeletons = self.programs[key]
        if not isinstance(run, jax.stages.Compiled):
            self.programs[key] = run.lower(*leaves).compile(), skeletons

    def _prepared(self, folder: Path | None, args, kwargs):
        """The key of the program for these arguments, made ready in `programs` (loaded
        or exported while the cache is on), and the arrays it takes."""
        dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
        leaves, structure = jax.tree.flatten(dynamic)
        options = None if self.options is None else self.options(*args, **kwargs) or None
        several = len(jax.devices()) > 1
        key = self._key(static, structure, leaves, options)
        if key not in self.programs:
            kept = None if folder is None or several else self._kept(
                folder / f"{self.function.__name__}-{key}.bin", static, structure, leaves)
            if kept is None:
                flat, skeletons = self._flat(static, structure)
                self.programs[key] = jax.jit(flat, compiler_options=options), skeletons
            else:
                exported, skeleton = kept
                self.programs[key] = jax.jit(exported.call, compiler_options=options), [skeleton]
        if not several:
            # Placed on the device (committed) at every call, as the outputs of an earlier
            # program are: one compilation serves both.
            leaves = jax.device_put(leaves, jax.devices()[0])
        return key, leaves

    def _key(self, static, structure, leaves, options) -> str:
        """The key of the program for these arguments and XLA options."""
        description = [
            _fingerprint(), self.function.__module__, self.function.__qualname__,
            str(structure), str(jax.tree.structure(static)), repr(jax.tree.leaves(static)),
            repr(sorted((options or {}).items())),
        ] + [f"{leaf.shape} {leaf.dtype} {getattr(leaf, 'weak_type', False)}" for leaf in leaves]
        return hashlib.sha256("\n".join(description).encode()).hexdigest()[:32]

    def _kept(self, path: Path, static, structure, leaves):
        """The program kept at `path` (`jax.export.Exported`) and its output's skeleton,
        else the program exported now and kept there; None for one that cannot be
        exported (holding a host callback), marked so beside it."""
        skip = path.with_suffix(".skip")
        if skip.exists():
            _used(skip)
            return None
        if path.exists():
            try:
                blob, skeleton = pickle.loads(path.read_bytes())
                _used(path)
                return jax.export.deserialize(blob), skeleton
            except (OSError, EOFError, pickle.UnpicklingError, ValueError, TypeError):
                pass  # damaged: exported again
        flat, skeletons = self._flat(static, structure)
        try:
            exported = jax.export.export(jax.jit(flat))(*leaves)
            blob = pickle.dumps((exported.serialize(), skeletons[-1]))
        except (ValueError, TypeError, NotImplementedError, pickle.PicklingError):
            skip.touch()
            return None
        _write(path, blob)
        return exported, skeletons[-1]

    def _flat(self, static, structure):
        """The function of the arrays' leaves that the program computes, returning its
        output's leaves, and a list that each trace of it extends with the output's
        skeleton: the output with its leaves replaced by 0 (the treedef of an equinox
        Module does not survive pickling, the Module does)."""
        skeletons = []

        def flat(*dynamic_leaves):
            dynamic = jax.tree.unflatten(structure, dynamic_leaves)
            args, kwargs = eqx.combine(dynamic, static)
            out = self.function(*args, **kwargs)
            skeletons.append(jax.tree.map(lambda _: 0, out))
            return jax.tree.leaves(out)

        return flat, skeletons


def compiled(function=None, *, options: Callable[..., dict] | None = None):
    """Decorator: `eqx.filter_jit`, with the traced program kept on disk while the cache
    is on (see `enable_compilation_cache`). With `options`, `@compiled(options=f)`: each
    program is compiled with the XLA options (a dict, empty for XLA's defaults) that
    `f` gives for the call's arguments."""
    if function is None:
        return ft.partial(compiled, options=options)
    return _Program(function, options)
