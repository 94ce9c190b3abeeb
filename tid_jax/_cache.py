"""JAX's persistent compilation cache, for entry points (the CLI, experiment scripts).

Compiling the batched steady-state and retuning programs takes most of a short run. With
the cache on, a compiled program is saved on disk and loaded by later runs on the same
machine (and the same JAX version) instead of being compiled again.
"""

import os
from pathlib import Path

import equinox._errors
import jax

CACHE_ENVIRONMENT_VARIABLE = "TID_JAX_CACHE_DIR"
_OFF = ("", "0", "off", "false", "no", "none")


def default_cache_dir() -> Path | None:
    """The folder of the compilation cache: `$TID_JAX_CACHE_DIR` if set (`off`, `0`
    or empty turn the cache off: `None`), else `tid_jax/` in the user's cache folder
    (`$XDG_CACHE_HOME`, default `~/.cache`)."""
    value = os.environ.get(CACHE_ENVIRONMENT_VARIABLE)
    if value is not None:
        return None if value.strip().lower() in _OFF else Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "tid_jax"


def enable_compilation_cache(directory: str | os.PathLike | None = None) -> Path | None:
    """Turn on JAX's persistent compilation cache in `directory` (default
    `default_cache_dir()`), for every program that takes more than 0.1 s to compile.
    Call it before the first computation. Returns the folder, or `None` (and changes
    nothing) when the cache is turned off or its folder cannot be created."""
    folder = default_cache_dir() if directory is None else Path(directory).expanduser()
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    # JAX does not save programs holding host callbacks, and equinox's run-time checks
    # (diffrax's of its inputs, never failing here: every solve reports its own status)
    # are host callbacks unless they are set to return NaN, as `EQX_ON_ERROR=nan` does
    # when set before equinox is imported.
    equinox._errors.EQX_ON_ERROR = "nan"
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.1)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return folder
