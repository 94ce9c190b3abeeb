import json
import os
import shutil
import subprocess
import sys
import textwrap
import time

import numpy as np

# Each run is a fresh process (as a second `tid-jax` run is): it counts how often the
# decorated functions are traced and how JAX's compilation cache answered, and prints
# their results.
SCRIPT = textwrap.dedent(
    """
    import json, sys
    import equinox as eqx
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np
    import tid_jax as tj
    from tid_jax._runtime._cache import compiled

    traces = {"plain": 0, "callback": 0, "optioned": 0}
    events = []
    jax.monitoring.register_event_listener(lambda event, **kwargs: events.append(event))

    class Extremes(eqx.Module):
        low: jax.Array
        high: jax.Array

    @compiled
    def plain(x, power, *, shift):
        traces["plain"] += 1
        return {"y": jnp.sin(x) ** power + shift, "n": (x.shape[0], jnp.sum(x > 0)),
                "m": Extremes(jnp.min(x) * power, jnp.max(x))}

    @compiled
    def callback(x):
        traces["callback"] += 1
        return jax.pure_callback(lambda v: v * 2, jax.ShapeDtypeStruct(x.shape, x.dtype), x)

    def options(x, unknown):
        return {"xla_no_such_option": True} if unknown else {"xla_cpu_use_fusion_emitters": False}

    @compiled(options=options)
    def optioned(x, unknown):
        traces["optioned"] += 1
        return jnp.cos(x) * 2

    if sys.argv[1] != "off":
        tj.enable_compilation_cache(sys.argv[1])
    x = np.linspace(-1.0, 2.0, 7)  # no program of its own
    out = [plain(x, 2, shift=0.5), plain(x, 3, shift=0.5), plain(x, 3, shift=0.5), callback(x)]
    optioned_out = np.asarray(optioned(x, False)).tolist()
    try:
        optioned(x, True)
        unknown_option = "accepted"
    except jax.errors.JaxRuntimeError as error:
        unknown_option = "xla_no_such_option" in str(error)
    print(json.dumps({
        "traces": traces,
        "y": [[float(v) for v in o["y"]] for o in out[:3]],
        "n": [[int(v) for v in o["n"]] for o in out[:3]],
        "m": [[type(o["m"]).__name__, float(o["m"].low), float(o["m"].high)] for o in out[:3]],
        "callback": [float(v) for v in out[3]],
        "optioned": optioned_out,
        "unknown_option_refused": unknown_option,
        "misses": events.count("/jax/compilation_cache/cache_misses"),
        "hits": events.count("/jax/compilation_cache/cache_hits"),
    }))
    """
)


def _run(cache) -> dict:
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(cache)], capture_output=True,
                          text=True, timeout=300, env=dict(os.environ))
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def _kept(folder) -> list[tuple[str, str]]:
    return sorted((path.name.split("-")[0], path.suffix)
                  for path in (folder / "programs").iterdir())


def test_programs_are_kept_on_disk_and_reused_without_tracing(tmp_path):
    off = _run("off")
    # Without the cache: one trace per distinct static argument, as with `eqx.filter_jit`.
    assert off["traces"] == {"plain": 2, "callback": 1, "optioned": 2}
    first = _run(tmp_path)
    # Two programs of `plain` (powers 2 and 3) and one of `optioned` that compiled; the
    # host callback cannot be kept, and is marked so that later runs do not try again.
    assert _kept(tmp_path) == [("callback", ".skip"), ("optioned", ".bin"),
                               ("optioned", ".bin"), ("plain", ".bin"), ("plain", ".bin")]
    second = _run(tmp_path)
    # The second process loads the programs: `plain` and `optioned` are not traced again,
    # and every executable comes from JAX's compilation cache.
    assert second["traces"] == {"plain": 0, "callback": 1, "optioned": 0}
    assert second["hits"] > 0
    for run in (first, second):
        assert run["y"] == off["y"] and run["n"] == off["n"]
        assert run["m"] == off["m"]  # a Module in the output is restored as that Module
        assert run["callback"] == off["callback"]
        assert run["optioned"] == off["optioned"]
    # A kept program of other sources or library versions is never loaded: the key holds
    # a fingerprint of both, so a changed file name means a changed program.
    assert _kept(tmp_path) == _kept(tmp_path)


def test_a_program_is_compiled_with_the_options_its_arguments_give(tmp_path):
    # The options reach XLA with the cache on and off: one that XLA does not know fails
    # the compilation, a known one computes the same as XLA's defaults.
    for cache in ("off", tmp_path):
        run = _run(cache)
        assert run["unknown_option_refused"] is True
        np.testing.assert_allclose(run["optioned"], 2 * np.cos(np.linspace(-1.0, 2.0, 7)),
                                   rtol=1e-15)


def test_programs_unused_for_a_month_are_deleted(tmp_path):
    _run(tmp_path)
    programs = tmp_path / "programs"
    old, recent = programs / "older-sources.bin", programs / "other-version.bin"
    old.write_bytes(b"")
    recent.write_bytes(b"")
    month_ago = time.time() - 31 * 86400
    os.utime(old, (month_ago, month_ago))
    kept = sorted(path for path in programs.iterdir() if path not in (old, recent))
    for path in kept:  # unused for a month too, but loaded again by this run
        os.utime(path, (month_ago, month_ago))
    again = _run(tmp_path)
    assert not old.exists() and recent.exists()
    # The programs this run used were deleted too (last used a month ago) and kept again.
    assert again["traces"]["plain"] == 2
    assert sorted(programs.iterdir()) == sorted([*kept, recent])


def test_a_damaged_program_file_is_replaced(tmp_path):
    _run(tmp_path)
    for path in (tmp_path / "programs").glob("*.bin"):
        path.write_bytes(b"not a program")
    # Unreadable programs are not used: the functions are traced afresh, results unchanged,
    # and kept again for the next run.
    again = _run(tmp_path)
    assert again["traces"]["plain"] == 2
    assert again["y"] == _run("off")["y"]
    assert _run(tmp_path)["traces"]["plain"] == 0


def test_a_copied_cache_folder_serves_its_programs(tmp_path):
    # The cache folder's path is in no program's key: a copy of it (a CI cache restored
    # elsewhere) neither traces nor compiles what the original holds.
    _run(tmp_path / "original")
    shutil.copytree(tmp_path / "original", tmp_path / "copy")
    copied = _run(tmp_path / "copy")
    assert copied["traces"]["plain"] == 0 and copied["traces"]["optioned"] == 0
    assert copied["hits"] > 0
