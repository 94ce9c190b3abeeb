import gc
import os
import shutil
import tempfile

# Equinox's run-time checks return NaN rather than raise (its documented switch, read when
# it is imported), as in the `tid-jax` command: programs holding them can then be kept in
# the compilation cache, and every solve reports its own status.
os.environ.setdefault("EQX_ON_ERROR", "nan")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

# Before the package is imported, so that nothing it makes at import is single precision.
jax.config.update("jax_enable_x64", True)

import tid_jax as tj  # noqa: E402

# Compiled programs are kept on disk for the whole test session, as the command line keeps
# them for a user: in a folder of this session (made by the first process, shared by the
# parallel test workers and by the commands run as subprocesses, which inherit the
# variable), never the user's; the process that made it deletes it at the end.
_session_cache = None
if "TID_JAX_CACHE_DIR" not in os.environ:
    _session_cache = tempfile.mkdtemp(prefix="tid_jax_test_cache_")
    os.environ["TID_JAX_CACHE_DIR"] = _session_cache
tj.enable_compilation_cache()
# The test workers (pytest-xdist) already take every core: the commands run in one process
# each, unless a test asks for more.
os.environ.setdefault("TID_JAX_WORKERS", "1")


def pytest_sessionfinish(session):
    if _session_cache is not None:
        shutil.rmtree(_session_cache, ignore_errors=True)


@pytest.fixture(autouse=True, scope="module")
def _programs_per_file():
    """Each test file's compiled programs are dropped after it (those worth keeping stay in
    the session's compilation cache on disk): a test worker runs dozens of files and would
    otherwise hold every program it compiled, several GB by the end of the suite."""
    yield
    jax.clear_caches()
    gc.collect()


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
