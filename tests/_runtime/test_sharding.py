"""Sharding the batch over several devices gives the single-device answer.

The four (simulated CPU) devices run in a fresh subprocess, since the number of devices is
fixed when JAX starts."""

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import tid_jax as tj


# 2 amplitudes x 5 frequencies = 10 points: not a multiple of 4 devices, so padding is used.
# On four devices, chunks of 2 points make the batched solves run chunk by chunk (on each
# device's part). The retune (2 amplitudes) optimises on one device and checks its designs
# on all four. The answer on one device is computed in this process with the default
# chunks and the band of `conftest`, in programs that other tests compile too.
def measure(chunk: int | None = None) -> dict:
    """The batch and retune computed on every device of this process, as a dict."""
    import tid_jax._response
    from tid_jax._runtime._sharding import batch_sharding, per_device, sharded_batch

    # Where do the solve's outputs live (before they are trimmed and gathered)? Recorded on
    # the way out of the solve that `frequency_response` shards.
    solve_devices = []
    shard = tid_jax._response.sharded_batch

    def recorded(function, *batch):
        def solve(*placed):
            out = function(*placed)
            solve_devices.append(len(jax.tree.leaves(out)[0].devices()))
            return out

        return shard(solve, *batch)

    settings = tj.SolverSettings() if chunk is None else tj.SolverSettings(chunk=chunk)
    system = tj.paper_system()
    omegas = np.linspace(0.8, 1.2, 5) * np.sqrt(system.host_stiffness / system.host_mass)
    tid_jax._response.sharded_batch = recorded
    try:
        response = tj.frequency_response(system, omegas, [100.0, 400.0], settings=settings)
    finally:
        tid_jax._response.sharded_batch = shard
    band = np.asarray(tj.default_omegas(system, 21))
    retuned = tj.retune(system, [200.0, 600.0], omegas=band, tol=1e-5, settings=settings)
    seen = sharded_batch(lambda a: a * 1.0, jax.numpy.arange(10.0))
    # The part of a batch of 8 that `per_device` hands to the function on each device.
    parts = []
    doubled = jax.jit(lambda a: per_device(lambda part: parts.append(part.shape[0]) or 2 * part,
                                           a))(jax.numpy.arange(8.0))
    sharding = batch_sharding()
    # The package's programs are compiled with their XLA options on any number of
    # devices: one that XLA does not know fails the compilation.
    from tid_jax._runtime._cache import compiled

    @compiled(options=lambda a: {"xla_no_such_option": True})
    def unknown(a):
        return 2 * a

    try:
        unknown(jax.numpy.arange(8.0))
        options_reached = False
    except jax.errors.JaxRuntimeError as error:
        options_reached = "xla_no_such_option" in str(error)
    return dict(
        options_reached=options_reached,
        devices=len(jax.devices()),
        devices_used=1 if sharding is None else len(sharding.mesh.devices.reshape(-1)),
        padded_devices=len(jax.device_put(jax.numpy.arange(12.0), sharding).devices())
        if sharding is not None else 1,
        trimmed=len(seen),
        part=parts[0],
        doubled=np.asarray(doubled).tolist(),
        solve_devices=solve_devices[0],
        x_max=np.asarray(response.x_max).tolist(),
        y_max=np.asarray(response.y_max).tolist(),
        converged=np.asarray(response.converged).tolist(),
        retune_stiffness=np.asarray(retuned.tid_stiffness).tolist(),
        retune_damping=np.asarray(retuned.tid_damping).tolist(),
        retune_x_peak=np.asarray(retuned.x_peak).tolist(),
        retune_status=np.asarray(retuned.status).tolist(),
        retune_iterations=np.asarray(retuned.iterations).tolist(),
    )


SCRIPT = """
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
sys.path.insert(0, {root!r})
from tests._runtime.test_sharding import measure
print(json.dumps(measure(chunk=2)))
"""


def _start(device_count: int) -> subprocess.Popen:
    env = dict(os.environ)
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={device_count}"
    env["JAX_ENABLE_X64"] = "1"
    env["JAX_PLATFORMS"] = "cpu"
    root = str(Path(__file__).resolve().parents[2])
    return subprocess.Popen(
        [sys.executable, "-c", SCRIPT.format(root=root)], env=env, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True,
    )


def _result(process: subprocess.Popen) -> dict:
    stdout, stderr = process.communicate(timeout=400)
    assert process.returncode == 0, stderr[-4000:]
    return json.loads(stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def runs():
    # Four devices in a process of their own (the number of devices is fixed when JAX
    # starts), one in this process meanwhile.
    process = _start(4)
    try:
        single = measure()
        return single, _result(process)
    finally:
        if process.poll() is None:
            process.kill()


# Batches of different widths round differently (vectorised arithmetic): agreement to
# 1e-8, far below the solver tolerances, not bit for bit.
def test_four_devices_match_one(runs):
    single, sharded = runs
    assert single["devices"] == 1 and single["devices_used"] == 1
    assert sharded["devices"] == 4 and sharded["devices_used"] == 4
    assert sharded["padded_devices"] == 4
    assert sharded["trimmed"] == 10
    assert sharded["part"] == 2 and single["part"] == 8
    assert sharded["doubled"] == single["doubled"] == [2.0 * i for i in range(8)]
    assert sharded["solve_devices"] == 4 and single["solve_devices"] == 1
    assert sharded["options_reached"] and single["options_reached"]
    assert np.all(single["converged"]) and sharded["converged"] == single["converged"]
    for key in ("x_max", "y_max"):
        np.testing.assert_allclose(sharded[key], single[key], rtol=1e-8, atol=0)


def test_retune_on_four_devices_matches_one(runs):
    single, sharded = runs
    assert single["retune_status"] == [0, 0] and sharded["retune_status"] == [0, 0]
    assert min(single["retune_iterations"]) > 0
    # Rounding differences move the optimiser's path slightly; both runs converge to the
    # same design within its tolerance, most loosely along the flat direction of c.
    for key in ("retune_stiffness", "retune_damping"):
        np.testing.assert_allclose(sharded[key], single[key], rtol=1e-4, atol=0)
    np.testing.assert_allclose(sharded["retune_x_peak"], single["retune_x_peak"], rtol=1e-5)


def test_map_batch_matches_vmap_and_skips_chunks_without_valid_entries():
    from tid_jax._runtime._sharding import map_batch

    x = jax.numpy.arange(23.0)
    valid = x < 9  # chunks of 4: entries 0-8 valid, chunks from the fourth on all padding
    def square(v):
        return {"square": v**2, "sign": jax.numpy.sign(v)}

    out = jax.jit(lambda a, m: map_batch(square, a, 4, m))(x, valid)
    np.testing.assert_array_equal(out["square"][:9], np.arange(9.0) ** 2)
    np.testing.assert_array_equal(out["sign"][:9], np.sign(np.arange(9.0)))
    # A chunk holding a valid entry is computed in full (padding included); a chunk without
    # one is skipped and reads zero.
    np.testing.assert_array_equal(out["square"][9:12], np.arange(9.0, 12.0) ** 2)
    assert not np.any(np.asarray(out["square"][12:]))
    everything = map_batch(square, x, 4)
    np.testing.assert_array_equal(everything["square"], np.arange(23.0) ** 2)
