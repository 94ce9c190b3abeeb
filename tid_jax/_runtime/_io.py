import contextlib
import csv
import io
import json
import math
import os
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

import tomli_w


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success it is renamed onto `path`, on any
    error it is removed, so `path` is never left half-written."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        tmp_path.chmod(0o666 & ~_umask())  # mkstemp's 0600 -> the mode `open` would give
        yield tmp_path
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write `text` to `path` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return Path(path)


def json_text(data) -> str:
    """`data` as indented, strict JSON text (no trailing newline): a number that is not
    finite (NaN, a quantity that could not be computed and is flagged beside it, or
    inf) is written as `null`, which every JSON reader takes (the bare `NaN` that
    Python's `json` writes by default, strict readers reject)."""
    return json.dumps(_finite_or_null(data), indent=2, sort_keys=False, allow_nan=False)


def _finite_or_null(value):
    """`value` (JSON data) with every non-finite float replaced by `None`."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _finite_or_null(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_null(item) for item in value]
    return value


def write_json(path: str | os.PathLike, data) -> Path:
    """Write `data` as indented JSON, atomically."""
    return write_text(path, json_text(data) + "\n")


def write_csv(path: str | os.PathLike, header: Sequence[str], rows: Sequence[Sequence]) -> Path:
    """Write a CSV table (header row, then `rows`), atomically."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return write_text(path, buffer.getvalue())


def check_writable_dir(path: str | os.PathLike) -> Path:
    """Create the folder `path` if needed and check that files can be written in it;
    raises `OSError` otherwise. Meant to be called before a long computation."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryFile(dir=path):
        pass
    return path


def write_toml(path: str | os.PathLike, data: dict, *, comment: str = "") -> Path:
    """Write `data` (numbers, strings, lists, and `dict` values as tables) as TOML
    (`tomli_w`), atomically. `comment` becomes a leading `#` comment."""
    lines = [f"# {line}\n" for line in comment.splitlines()]
    return write_text(path, "".join(lines) + tomli_w.dumps(data))
