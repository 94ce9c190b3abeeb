import json
import os
import shutil
import subprocess
import sys
import textwrap
import time

import numpy as np

# Each run is a fresh process (as a second `tid-jax` run is): it counts how often the
# decorated functions are traced, and prints their results.
SCRIPT = textwrap.dedent(
    """
    import json, sys
    import equinox as eqx
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import tid_jax as tj
    from tid_jax._cache import compiled

    traces = {"plain": 0, "callback": 0}

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

    if sys.argv[1] != "off":
        tj.enable_compilation_cache(sys.argv[1])
    x = jnp.linspace(-1.0, 2.0, 7)
    kept = [plain.is_kept(x, 2, shift=0.5)]
    out = [plain(x, 2, shift=0.5), plain(x, 3, shift=0.5), plain(x, 3, shift=0.5), callback(x)]
    kept += [plain.is_kept(x, 2, shift=0.5), plain.is_kept(x, 4, shift=0.5),
             plain.is_kept(x[:3], 2, shift=0.5)]
    print(json.dumps({
        "traces": traces,
        "y": [[float(v) for v in o["y"]] for o in out[:3]],
        "n": [[int(v) for v in o["n"]] for o in out[:3]],
        "m": [[type(o["m"]).__name__, float(o["m"].low), float(o["m"].high)] for o in out[:3]],
        "callback": [float(v) for v in out[3]],
        "kept": kept,
    }))
    """
)


def _run(cache) -> dict:
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(cache)], capture_output=True,
                          text=True, timeout=300, env=dict(os.environ))
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_programs_are_kept_on_disk_and_reused_without_tracing(tmp_path):
    off = _run("off")
    # Without the cache: one trace per distinct static argument, as with `eqx.filter_jit`.
    assert off["traces"] == {"plain": 2, "callback": 1}
    assert off["kept"] == [False] * 4  # nothing is kept without the cache
    first = _run(tmp_path)
    # Kept once run, for those arguments only (another static value or shape is not).
    assert first["kept"] == [False, True, False, False]
    kept = sorted(path.name for path in (tmp_path / "programs").iterdir())
    # Two programs of `plain` (powers 2 and 3), each with its executable; the host
    # callback cannot be kept, and is marked so that later runs do not try again.
    named = [(name.split("-")[0], name.rsplit(".", 1)[1]) for name in kept]
    assert named == [("callback", "skip"), ("plain", "bin"), ("plain", "exe"),
                     ("plain", "bin"), ("plain", "exe")], kept
    second = _run(tmp_path)
    # The second process loads both programs: `plain` is not traced again.
    assert second["traces"] == {"plain": 0, "callback": 1}
    assert second["kept"] == [True, True, False, False]
    for run in (first, second):
        assert run["y"] == off["y"] and run["n"] == off["n"]
        assert run["m"] == off["m"]  # a Module in the output is restored as that Module
        assert run["callback"] == off["callback"]
    # A kept program of other sources or library versions is never loaded: the key holds
    # a fingerprint of both, so a changed file name means a changed program.
    assert sorted(path.name for path in (tmp_path / "programs").iterdir()) == kept


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
    # The programs this run used were deleted too (last used a month ago) and kept again,
    # with their executables (as JAX's cache holds them).
    assert again["traces"]["plain"] == 2
    assert sorted(programs.iterdir()) == sorted([*kept, recent])


def test_a_damaged_program_file_is_replaced(tmp_path):
    _run(tmp_path)
    for path in (tmp_path / "programs").iterdir():
        if path.suffix in (".bin", ".exe"):
            path.write_bytes(b"not a program")
    # Unreadable programs are not used: the functions are traced afresh, results unchanged.
    again = _run(tmp_path)
    assert again["traces"]["plain"] == 2
    assert again["y"] == _run("off")["y"]


def test_a_damaged_or_foreign_executable_is_replaced_from_its_program(tmp_path):
    _run_prepare(tmp_path, "prepare")
    [executable] = (tmp_path / "programs").glob("*.exe")
    data = executable.read_bytes()
    # One byte changed (a damaged file), or the digest of another machine: the program is
    # loaded, not traced, and compiled from JAX's cache; its executable is kept again, as
    # that cache holds it, and serves the next process.
    for changed in (data[:-1] + bytes([data[-1] ^ 1]), bytes(32) + data[32:]):
        executable.write_bytes(changed)
        called = _run_prepare(tmp_path, "call")
        assert called["traces"] == 0 and called["hits"] == 1 and called["misses"] == 0
        np.testing.assert_allclose(called["out"], np.cos(np.linspace(0.0, 1.0, 5)) ** 3,
                                   rtol=1e-14)
        _assert_served(_run_prepare(tmp_path, "call"))


# `prepare` in one process; in the next, the call of the same program.
PREPARE_SCRIPT = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np
    import tid_jax as tj
    from tid_jax._cache import compiled

    traces = []
    events = []
    jax.monitoring.register_event_listener(lambda event, **kwargs: events.append(event))

    @compiled
    def scaled(x, power):
        traces.append(power)
        return jnp.cos(x) ** power

    tj.enable_compilation_cache(sys.argv[1])
    x = np.linspace(0.0, 1.0, 5)  # no program of its own
    out = None
    if sys.argv[2] == "prepare":
        scaled.prepare(x, 3)
    else:
        out = np.asarray(scaled(x, 3)).tolist()
    print(json.dumps({"traces": len(traces), "kept": scaled.is_kept(x, 3),
                      "misses": events.count("/jax/compilation_cache/cache_misses"),
                      "hits": events.count("/jax/compilation_cache/cache_hits"),
                      "out": out}))
    """
)


def _run_prepare(folder, mode) -> dict:
    done = subprocess.run([sys.executable, "-c", PREPARE_SCRIPT, str(folder), mode],
                          capture_output=True, text=True, timeout=300, env=dict(os.environ))
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def _assert_served(called: dict) -> None:
    """A `_run_prepare(..., "call")` that neither traced nor compiled its program, nor
    looked it up in JAX's cache (its executable was loaded as it is kept), and computed it
    right."""
    assert called["traces"] == 0 and called["misses"] == 0 and called["hits"] == 0
    np.testing.assert_allclose(called["out"], np.cos(np.linspace(0.0, 1.0, 5)) ** 3,
                               rtol=1e-14)


def test_a_prepared_program_is_kept_and_compiled_for_the_next_process(tmp_path):
    prepared = _run_prepare(tmp_path, "prepare")
    # Traced once, kept and compiled (a miss of the compilation cache), not run.
    assert prepared["traces"] == 1 and prepared["kept"] and prepared["misses"] == 1
    assert prepared["out"] is None
    # The next process neither traces nor compiles it: its executable is in the cache.
    _assert_served(_run_prepare(tmp_path, "call"))


def test_a_copied_cache_folder_serves_its_programs(tmp_path):
    # The cache folder's path is in no program's key: a copy of it (a CI cache restored
    # elsewhere) neither traces nor compiles what the original holds.
    _run_prepare(tmp_path / "original", "prepare")
    shutil.copytree(tmp_path / "original", tmp_path / "copy")
    _assert_served(_run_prepare(tmp_path / "copy", "call"))


def test_a_program_is_compiled_with_the_options_its_arguments_give(monkeypatch):
    # The options reach XLA with the cache on (this session's) and off (in memory): one
    # that XLA does not know fails the compilation, a known one computes the same.
    import jax
    import jax.numpy as jnp
    import pytest

    import tid_jax as tj
    from tid_jax import _cache
    from tid_jax._system import compiler_options

    seen = []

    def options(x, unknown):
        seen.append(unknown)
        return {"xla_no_such_option": True} if unknown else {"xla_cpu_use_fusion_emitters": False}

    x = np.linspace(0.0, 1.0, 5)
    for folder in (_cache._programs_folder, None):
        monkeypatch.setattr(_cache, "_programs_folder", folder)

        @_cache.compiled(options=options)
        def scaled(x, unknown):
            return jnp.sin(x) * 2

        np.testing.assert_allclose(np.asarray(scaled(x, False)), 2 * np.sin(x), rtol=1e-15)
        with pytest.raises(jax.errors.JaxRuntimeError, match="xla_no_such_option"):
            scaled(x, True)
    assert True in seen and False in seen
    # The fusion emitters are off for exact friction and for a compliant device only,
    # wherever its system is.
    exact, smoothed = tj.paper_system(), tj.paper_system(friction_width=None)
    compliant = smoothed.replace(series_stiffness=3e5, terminal_mass=2.0)
    off = {"xla_cpu_use_fusion_emitters": False}
    assert compiler_options(1.0, systems=[exact]) == off
    assert compiler_options(compliant, 2.0) == off
    assert compiler_options(smoothed, 2.0) == {}
    assert compiler_options(smoothed.replace(terminal_mass=2.0)) == {}
