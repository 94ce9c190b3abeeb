"""Compiled programs kept on disk, for entry points (the CLI, experiment scripts).

Tracing, lowering and compiling the batched steady-state and retuning programs takes
most of a short run. With the cache on, every program is kept on disk twice over:

- JAX's persistent compilation cache keeps the compiled executable;
- `compiled` keeps the traced and lowered program itself (a serialized `jax.export`),
  under a key made of its static arguments, the shapes and dtypes of its arrays, the
  sources of this package and the versions of JAX and its libraries, and beside it the
  program's executable for this machine (`jax.experimental.serialize_executable`).

A later run on the same machine then neither traces nor compiles it again, and loads the
executable without lowering the program again to find it in JAX's cache.
"""

import functools as ft
import hashlib
import importlib.metadata
import inspect
import io
import os
import pickle
import platform
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import equinox._errors
import jax
from jax.experimental import serialize_executable

CACHE_ENVIRONMENT_VARIABLE = "TID_JAX_CACHE_DIR"
_OFF = ("", "0", "off", "false", "no", "none")
_LIBRARIES = ("jax", "jaxlib", "equinox", "diffrax", "optimistix", "lineax")
PROGRAMS = "programs"

_programs_folder: Path | None = None
# Called before this process traces a program to keep it, or compiles one, that the cache
# does not hold (see `before_compiling`).
_before_compiling: Callable[[], None] | None = None
# Kept programs unused for this long are deleted (those of older sources or library
# versions, which no key can reach again), when the cache is turned on.
STALE_DAYS = 30


# This thread's last compilation: whether it missed JAX's cache (compiled afresh), and
# the serialized executable that cache gave it, if any. An executable loaded from that
# cache serializes again without its compiled functions: one loaded is kept as the cache
# held it (`_Program._compile`).
_compilation = threading.local()


def _note_cache_miss(event: str, **_) -> None:
    if event == "/jax/compilation_cache/cache_misses":
        _compilation.missed = True


def _watch_cache_reads() -> None:
    """Have every read of JAX's cache in this process leave the serialized executable it
    found in `_compilation.read`."""
    from jax._src import compilation_cache

    extract = getattr(compilation_cache, "extract_executable_and_time", None)
    if extract is None or getattr(extract, "watched", False):
        return  # (without it, executables JAX's cache serves are not kept)

    def watched(executable_and_time):
        serialized, compile_time = extract(executable_and_time)
        _compilation.read = serialized
        return serialized, compile_time

    watched.watched = True
    compilation_cache.extract_executable_and_time = watched


jax.monitoring.register_event_listener(_note_cache_miss)


def default_cache_dir() -> Path | None:
    """The folder of the compilation cache.

    **Arguments:** none; `$TID_JAX_CACHE_DIR` and `$XDG_CACHE_HOME` are read.

    **Returns:** `$TID_JAX_CACHE_DIR` if set (`off`, `0` or empty turn the cache off:
    `None`), else `tid_jax/` in the user's cache folder (`$XDG_CACHE_HOME`, default
    `~/.cache`).
    """
    value = os.environ.get(CACHE_ENVIRONMENT_VARIABLE)
    if value is not None:
        return None if value.strip().lower() in _OFF else Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "tid_jax"


def enable_compilation_cache(directory: str | os.PathLike | None = None) -> Path | None:
    """Keep compiled programs on disk: JAX's persistent compilation cache for every
    program, however quickly it compiles (the small ones of the array operations between
    the solves add up to seconds), and the traced programs of this package's entry points
    in its `programs/`. Call it before the first computation.

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
    # JAX neither saves nor exports programs holding host callbacks, and equinox's run-time
    # checks (diffrax's of its inputs, never failing here: every solve reports its own
    # status) are host callbacks unless they are set to return NaN, as `EQX_ON_ERROR=nan`
    # does when set before equinox is imported.
    equinox._errors.EQX_ON_ERROR = "nan"
    jax.config.update("jax_compilation_cache_dir", str(folder))
    # Nor XLA's own GPU caches inside the folder: JAX would write their paths into every
    # program's compile options, hence into its key, so that a folder copied or moved
    # (a CI cache restored elsewhere, another user's home) would hold no program found.
    jax.config.update("jax_persistent_cache_enable_xla_caches", None)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    _watch_cache_reads()
    _programs_folder = folder / PROGRAMS
    _prune(_programs_folder, time.time() - STALE_DAYS * 86400)
    return folder


def cache_folder() -> Path | None:
    """The folder of the compilation cache if `enable_compilation_cache` turned it on in
    this process, else `None`."""
    return None if _programs_folder is None else _programs_folder.parent


def compiles_watchable() -> bool:
    """Whether `before_compiling` can watch compilations: whether this version of JAX
    has its compiler's hook where its persistent cache misses."""
    from jax._src import compiler

    write = getattr(compiler, "_compile_and_write_cache", None)
    expected = ["backend", "computation", "executable_devices", "compile_options",
                "host_callbacks", "module_name", "cache_key"]
    return (hasattr(compiler, "_cache_read") and write is not None
            and list(inspect.signature(write).parameters) == expected)


def before_compiling(hook: Callable[[], None]) -> None:
    """Call `hook()` in this process each time it is about to trace a program to keep it
    (`compiled`) or to compile a program, because the cache holds neither, and look in
    the cache again once `hook` returns: another process may have kept the program
    meanwhile. Compilations are watched where `compiles_watchable()`; kept traces always.

    **Arguments:** `hook`, a function of no arguments.
    """
    global _before_compiling
    _before_compiling = hook
    from jax._src import compiler

    if not compiles_watchable():
        return
    write, read = compiler._compile_and_write_cache, compiler._cache_read
    if getattr(write, "watched", False):
        return

    def compile_and_write(backend, computation, executable_devices, compile_options,
                          host_callbacks, module_name, cache_key):
        if _before_compiling is not None:
            _before_compiling()
            executable, _ = read(module_name, cache_key, compile_options, backend,
                                 executable_devices)
            if executable is not None:
                _compilation.missed = False  # loaded from the cache after all
                return executable
        return write(backend, computation, executable_devices, compile_options,
                     host_callbacks, module_name, cache_key)

    compile_and_write.watched = True
    compiler._compile_and_write_cache = compile_and_write


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


class _Program:
    """`eqx.filter_jit(function)` whose traced programs are kept on disk while the cache
    is on (`enable_compilation_cache`), each compiled with the XLA options that
    `options(*args, **kwargs)` gives (if `options` is given; then also while the cache is
    off, or on several devices, in memory). Calls inside a transformation (arguments that
    are tracers), and the others without options (on several devices, or of programs
    that cannot be exported: holding host callbacks) go to `eqx.filter_jit` as usual."""

    def __init__(self, function, options: Callable[..., dict] | None = None):
        self.function = function
        self.jitted = eqx.filter_jit(function)
        self.options = options
        self.loaded = {}
        self.in_memory = {}
        ft.update_wrapper(self, function)

    def __call__(self, *args, **kwargs):
        folder = _programs_folder
        if _is_traced((args, kwargs)):
            return self.jitted(*args, **kwargs)
        several = len(jax.devices()) > 1
        if folder is None or several:
            if self.options is None:
                return self.jitted(*args, **kwargs)
            return self._in_memory(args, kwargs, place=not several)
        key, static, structure, leaves, options = self._key(args, kwargs)
        if key not in self.loaded:
            self.loaded[key] = self._load(self._path(folder, key), static, structure, leaves)
        run, skeleton = self.loaded[key]
        if run is None:
            return self.jitted(*args, **kwargs)
        # Arrays placed on the device (committed) at every call, as the outputs of an
        # earlier program are: one compilation serves both.
        leaves = jax.device_put(leaves, jax.devices()[0])
        if not isinstance(run, jax.stages.Compiled):
            run = self._compile(self._path(folder, key), key, run, skeleton, leaves, options)
        return jax.tree.unflatten(jax.tree.structure(skeleton), run(*leaves))

    def _in_memory(self, args, kwargs, place: bool = True):
        """The call, its program compiled with its options and kept in this process; its
        arrays placed on the device first (`place`), or as given (sharded over several
        devices: compiled for their shardings)."""
        key, static, structure, leaves, options = self._key(args, kwargs)
        if place:
            leaves = jax.device_put(leaves, jax.devices()[0])
        if key not in self.in_memory:
            flat, skeletons = self._flat(static, structure)
            self.in_memory[key] = jax.jit(flat, compiler_options=options), skeletons
        run, skeletons = self.in_memory[key]
        out = run(*leaves)
        return jax.tree.unflatten(jax.tree.structure(skeletons[-1]), out)

    def _key(self, args, kwargs):
        """The key of the program for these arguments, its static part, the structure
        and leaves of its arrays, and its XLA options (a dict, or None)."""
        dynamic, static = eqx.partition((args, kwargs), eqx.is_array)
        leaves, structure = jax.tree.flatten(dynamic)
        options = None if self.options is None else self.options(*args, **kwargs) or None
        description = [
            _fingerprint(), self.function.__module__, self.function.__qualname__,
            str(structure), str(jax.tree.structure(static)), repr(jax.tree.leaves(static)),
            repr(sorted((options or {}).items())),
        ] + [f"{leaf.shape} {leaf.dtype} {getattr(leaf, 'weak_type', False)}" for leaf in leaves]
        key = hashlib.sha256("\n".join(description).encode()).hexdigest()[:32]
        return key, static, structure, leaves, options

    def _path(self, folder: Path, key: str) -> Path:
        return folder / f"{self.function.__name__}-{key}.bin"

    def is_kept(self, *args, **kwargs) -> bool:
        """Whether the program for these arguments is kept on disk (or loaded in this
        process): a call then neither traces nor, as a rule, compiles it."""
        folder = _programs_folder
        if folder is None:
            return False
        key = self._key(args, kwargs)[0]
        return key in self.loaded or self._path(folder, key).exists()

    def prepare(self, *args, **kwargs) -> None:
        """Trace, keep and compile the program for these arguments without running it
        (only their shapes and static values matter): into the cache, from which
        another process then loads it. Nothing happens while the cache is off."""
        folder = _programs_folder
        if folder is None or len(jax.devices()) > 1:
            return
        key, static, structure, leaves, options = self._key(args, kwargs)
        if key not in self.loaded:
            self.loaded[key] = self._load(self._path(folder, key), static, structure, leaves)
        run, skeleton = self.loaded[key]
        if run is not None and not isinstance(run, jax.stages.Compiled):
            # placed as `__call__` places them: the same executable
            self._compile(self._path(folder, key), key, run, skeleton,
                          jax.device_put(leaves, jax.devices()[0]), options)

    def _load(self, path: Path, static, structure, leaves):
        """The kept program at `path`, else the program exported now and kept there:
        `(run, skeleton)`, `skeleton` the output with its leaves replaced by 0 and `run`
        the executable kept beside the program if it loads, else the program to compile,
        or None if it cannot be exported."""
        skip = path.with_suffix(".skip")  # marks a program that cannot be exported
        if skip.exists():
            _used(skip)
            return None, None
        executable = _load_executable(path.with_suffix(".exe"))
        if executable is not None:
            _used(path)
            return executable
        if not path.exists() and _before_compiling is not None:
            _before_compiling()
        if not path.exists():
            blob = self._export(static, structure, leaves)
            if blob is None:
                skip.touch()
                return None, None
            _write(path, blob)
        # A new program runs as later runs will load it, so that they find it compiled.
        try:
            exported, skeleton = pickle.loads(path.read_bytes())
            _used(path)
            return jax.jit(jax.export.deserialize(exported).call), skeleton
        except (OSError, EOFError, pickle.UnpicklingError, ValueError, TypeError):
            return None, None

    def _compile(self, path: Path, key: str, run, skeleton, leaves,
                 options: dict | None) -> jax.stages.Compiled:
        """Compile the program `run` (from JAX's cache if it holds it) for `leaves` with
        the XLA `options`, keep its executable in this process under `key` and beside the
        program at `path`."""
        _compilation.missed, _compilation.read = False, None
        executable = run.lower(*leaves).compile(compiler_options=options)
        self.loaded[key] = executable, skeleton
        read = None if _compilation.missed else _compilation.read
        if not _compilation.missed and read is None:
            return executable  # compiled earlier in this process: kept then
        if not _runs_kept_executables():
            return executable  # no later run would load it
        try:
            payload, in_tree, out_tree = _serialized(executable, read)
            blob = pickle.dumps((payload, in_tree, out_tree, skeleton))
        except (AttributeError, ValueError, TypeError, NotImplementedError,
                pickle.PicklingError):
            return executable  # not serializable: loaded from JAX's cache in each run
        _write(path.with_suffix(".exe"), hashlib.sha256(_host() + blob).digest() + blob)
        return executable

    def _export(self, static, structure, leaves) -> bytes | None:
        """The serialized program and the structure of its output, or None for a program
        that cannot be exported (holding a host callback, or an output that cannot be
        pickled)."""
        flat, skeletons = self._flat(static, structure)
        try:
            exported = jax.export.export(jax.jit(flat))(*leaves)
            return pickle.dumps((exported.serialize(), skeletons[-1]))
        except (ImportError, ValueError, TypeError, NotImplementedError, pickle.PicklingError):
            return None

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


def _serialized(executable: jax.stages.Compiled, read: bytes | None):
    """`jax.experimental.serialize_executable.serialize(executable)`, with the XLA
    executable's own bytes `read` where given (as JAX's cache held them)."""

    unloaded = executable._executable._unloaded_executable

    class Pickler(serialize_executable._JaxPjrtPickler):
        def persistent_id(self, obj):
            if read is not None and obj is unloaded.xla_executable:
                return "exec", read
            return super().persistent_id(obj)

    if getattr(unloaded, "mut", None) and unloaded.mut.in_mut:
        raise ValueError("a program with mutable array references is not kept")
    if executable._params.const_args:
        raise NotImplementedError("a program with constant arguments is not kept")
    args_info, in_tree = jax.tree.flatten(executable.args_info)
    with io.BytesIO() as file:
        Pickler(file).dump((unloaded, args_info, executable._no_kwargs))
        return file.getvalue(), in_tree, executable.out_tree


@ft.cache
def _host() -> bytes:
    """The machine an executable is compiled for: JAX's platform, the processor's
    architecture and its features (XLA compiles for the processor it runs on)."""
    text = f"{jax.devices()[0].client.platform_version} {platform.machine()}"
    try:
        with open("/proc/cpuinfo") as file:
            text += next((line for line in file if line.startswith(("flags", "Features"))), "")
    except OSError:
        pass
    return text.encode()


def _write(path: Path, blob: bytes) -> None:
    """Write `blob` to `path` whole or not at all (other processes may be reading it)."""
    with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as file:
        file.write(blob)
    os.replace(file.name, path)


@ft.cache
def _runs_kept_executables() -> bool:
    """Whether this process can run kept executables: on the CPU, with its LAPACK kernels
    initialised now (JAX initialises them as it lowers a program that calls them, and a
    kept executable is never lowered: without them it would crash)."""
    if jax.default_backend() != "cpu":
        return False
    try:
        from jax._src.lax.linalg import initialize_lapack
    except ImportError:
        return False
    initialize_lapack()
    return True


def _load_executable(path: Path):
    """The executable kept at `path` and its output's skeleton, or None where there is
    none, or it is damaged or was compiled on another machine (the digest of this
    machine and the contents leads the file)."""
    if not _runs_kept_executables():
        return None
    try:
        data = path.read_bytes()
    except OSError:
        return None
    digest, blob = data[:32], data[32:]
    if hashlib.sha256(_host() + blob).digest() != digest:
        return None
    try:
        payload, in_tree, out_tree, skeleton = pickle.loads(blob)
        executable = serialize_executable.deserialize_and_load(payload, in_tree, out_tree)
    except (EOFError, pickle.UnpicklingError, ValueError, TypeError, jax.errors.JaxRuntimeError):
        return None
    _used(path)
    return executable, skeleton


def compiled(function=None, *, options: Callable[..., dict] | None = None):
    """Decorator: `eqx.filter_jit`, with the traced program kept on disk while the cache
    is on (see `enable_compilation_cache`). With `options`, `@compiled(options=f)`: each
    program is compiled with the XLA options (a dict, empty for XLA's defaults) that
    `f` gives for the call's arguments."""
    if function is None:
        return ft.partial(compiled, options=options)
    return _Program(function, options)
