"""Where the compilation cache lives: read from the environment, without importing JAX
(so that an entry point can start worker processes before it imports JAX)."""

import os
from pathlib import Path

CACHE_ENVIRONMENT_VARIABLE = "TID_JAX_CACHE_DIR"
_OFF = ("", "0", "off", "false", "no", "none")


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
