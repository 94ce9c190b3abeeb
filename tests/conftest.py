import os
import tempfile
from pathlib import Path

import jax
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)

# Compiled programs are kept on disk for the whole test session, as the command line keeps
# them for a user: in a folder of this session (shared by the parallel test workers and by
# the commands run as subprocesses), never the user's.
if "TID_JAX_CACHE_DIR" not in os.environ:
    run = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if run is None:
        folder = tempfile.mkdtemp(prefix="tid_jax_test_cache_")
    else:
        folder = Path(tempfile.gettempdir()) / f"tid_jax_test_cache_{run}"
        folder.mkdir(exist_ok=True)
    os.environ["TID_JAX_CACHE_DIR"] = str(folder)

import tid_jax as tj  # noqa: E402
from tid_jax._cache import enable_compilation_cache  # noqa: E402

enable_compilation_cache()

# The modules that take longest (each compiles its own retune or robust design programs),
# slowest first: the parallel workers (pytest-xdist, one file per worker at a time) start
# on them, so that they finish together. Every other module follows in its usual order.
SLOWEST_FIRST = (
    "test_sensitivity.py",
    "test_sharding.py",
    "test_robust.py",
    "test_retune.py",
    "test_cli.py",
    "test_response.py",
)


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture(scope="module")
def system():
    """The paper's system (section 4: M = 1500 kg, 4 Hz, 2%; b = 75 kg, ff = 20 N; Den
    Hartog's tuning)."""
    return tj.paper_system()


@pytest.fixture(scope="module")
def band(system):
    """A coarse band for the design tests: the default band (0.65-1.4 times the host
    frequency) at 21 frequencies, rad/s."""
    return np.asarray(tj.default_omegas(system, 21))
