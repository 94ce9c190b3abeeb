import os
import tempfile

import jax

jax.config.update("jax_enable_x64", True)

# The command line turns JAX's persistent compilation cache on: in the tests it lives in a
# folder of this session (shared with the commands run as subprocesses), not the user's.
os.environ.setdefault("TID_JAX_CACHE_DIR", tempfile.mkdtemp(prefix="tid_jax_test_cache_"))
