import os
import shutil
import tempfile

import jax
import numpy as np
import pytest

# Before the package is imported, so that nothing it makes at import is single precision.
jax.config.update("jax_enable_x64", True)

import tid_jax as tj  # noqa: E402
from tid_jax._cache import enable_compilation_cache  # noqa: E402

# Compiled programs are kept on disk for the whole test session, as the command line keeps
# them for a user: in a folder of this session (made by the first process, shared by the
# parallel test workers and by the commands run as subprocesses, which inherit the
# variable), never the user's; the process that made it deletes it at the end.
_session_cache = None
if "TID_JAX_CACHE_DIR" not in os.environ:
    _session_cache = tempfile.mkdtemp(prefix="tid_jax_test_cache_")
    os.environ["TID_JAX_CACHE_DIR"] = _session_cache
enable_compilation_cache()
# The test workers (pytest-xdist) already take every core: no worker processes of the
# library's own (`_workers`), unless a test asks for them.
os.environ.setdefault("TID_JAX_WORKERS", "1")


def pytest_sessionfinish(session):
    if _session_cache is not None:
        shutil.rmtree(_session_cache, ignore_errors=True)


# The modules, slowest first, as measured on two cores (each compiles programs of its
# own, integrates a reference or starts processes of its own): the parallel workers
# (pytest-xdist, one file per worker at a time) take the next in turn, and finish
# together. Except that `test_coulomb` goes ahead of its turn: it compiles the
# sensitivity kernel of exact friction on the default band that `test_sensitivity` then
# loads (run side by side, both compiled it). The modules not named, each a few seconds,
# follow in their usual order.
SLOWEST_FIRST = (
    "test_device.py",
    "test_retune.py",
    "test_coulomb.py",
    "test_identify.py",
    "test_response.py",
    "test_reach.py",
    "test_sensitivity.py",
    "test_gradients.py",
    "test_workers.py",
    "test_cli.py",
    "test_robust.py",
    "test_sharding.py",
    "test_substructuring.py",
    "test_cache.py",
)


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(scope="module")
def system():
    """The paper's system (section 4: M = 1500 kg, 4 Hz, 2%; b = 75 kg, ff = 20 N; Den
    Hartog's tuning) with its default model, exact Coulomb friction: the model the design
    tests are about (`test_reach` takes the design entry points through the smoothed
    friction of the relative width, `test_device` and `test_response` the steady states)."""
    return tj.paper_system()


@pytest.fixture(scope="module")
def band(system):
    """A coarse band for the design tests: the default band (0.65-1.4 times the host
    frequency) at 21 frequencies, rad/s."""
    return np.asarray(tj.default_omegas(system, 21))
