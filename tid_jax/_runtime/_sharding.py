"""Spreading a flat batch of independent problems over every JAX device.

Batched solves (one steady-state orbit per (amplitude, frequency) point) are
independent along the batch axis, so they split across devices with no
communication: the batch is padded to a multiple of the device count, placed
with `NamedSharding(Mesh(devices, ("batch",)), PartitionSpec("batch"))`, and
the jitted solve runs each device's slice on that device on its own
(`per_device`, a `shard_map`: no device waits in its loops for another's). The
outputs are trimmed back to the original length. On a single device this is a
no-op.

Several GPUs of one node are used automatically: `jax.devices()` lists them
all. For several hosts, every process calls `jax.distributed.initialize()`
(with `coordinator_address=`, `num_processes=`, `process_id=`, or from the
cluster environment, e.g. SLURM) before any other JAX call; the same program
then sees the devices of all hosts in `jax.devices()` and the batch is
sharded over all of them. On CPU, several devices can be simulated with
`XLA_FLAGS=--xla_force_host_platform_device_count=N` (set before importing
JAX).
"""

import equinox as eqx
import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

BATCH_AXIS = "batch"


def batch_sharding() -> NamedSharding | None:
    """The sharding of a batch axis over every JAX device (`jax.devices()`), or `None`
    when there is only one device."""
    devices = jax.devices()
    if len(devices) < 2:
        return None
    return NamedSharding(Mesh(np.asarray(devices), (BATCH_AXIS,)), PartitionSpec(BATCH_AXIS))


def _pad(array, size: int):
    """`array` with its leading axis extended to `size` by repeating its last entry (a valid
    problem, so padding never produces failures of its own)."""
    extra = size - array.shape[0]
    if extra == 0:
        return array
    return jax.numpy.concatenate([array, jax.numpy.repeat(array[-1:], extra, axis=0)])


def sharded_batch(function, *batch):
    """`function(*batch)` with every array of `batch` (pytrees of arrays with the same
    leading length n) padded to a multiple of the device count and sharded over the
    devices along its leading axis; every array of the returned pytree is trimmed back to
    its first n entries. Calls `function(*batch)` unchanged on one device."""
    sharding = batch_sharding()
    if sharding is None:
        return function(*batch)
    size = jax.tree_util.tree_leaves(batch)[0].shape[0]
    count = sharding.mesh.size
    padded = -(-size // count) * count
    placed = jax.tree_util.tree_map(
        lambda array: jax.device_put(_pad(array, padded), sharding), batch
    )
    out = function(*placed)
    return jax.tree_util.tree_map(lambda value: value[:size], out)


def map_batch(function, batch, chunk: int, valid=None):
    """`jax.vmap(function)(batch)` (a pytree of arrays with leading length n) computed
    `chunk` entries at a time with `jax.lax.map`, so that the while loops of a chunk wait
    only for that chunk's slowest entry. The batch is padded to whole chunks (repeating its
    last entry), so that one chunk's computation is compiled, not a second one for a
    remainder. Where `valid` (a boolean per entry) is False throughout a chunk, that
    chunk is skipped and its outputs are zero."""
    size = jax.tree_util.tree_leaves(batch)[0].shape[0]
    if size <= chunk:
        return jax.vmap(function)(batch)
    chunks = -(-size // chunk)
    if valid is None:
        valid = jax.numpy.ones(size, bool)

    def split(a):
        return _pad(a, chunks * chunk).reshape(chunks, chunk, *a.shape[1:])

    # Traced once, here: the chunks' computation and the shapes of its outputs (for the
    # zeros of a skipped chunk) both come from this one trace. (`lax.cond` hashes its
    # branches, which a closure-converted Module is not: it is called from a lambda.)
    mapped = eqx.filter_closure_convert(
        jax.vmap(function), jax.tree.map(lambda a: a[:chunk], batch)
    )
    shapes = mapped.out_struct

    def one_chunk(args):
        chunk_batch, chunk_valid = args
        return jax.lax.cond(
            jax.numpy.any(chunk_valid), lambda b: mapped(b),
            lambda _: jax.tree.map(lambda s: jax.numpy.zeros(s.shape, s.dtype), shapes),
            chunk_batch,
        )

    out = jax.lax.map(one_chunk, jax.tree_util.tree_map(split, (batch, valid)))
    return jax.tree_util.tree_map(lambda a: a.reshape(chunks * chunk, *a.shape[2:])[:size], out)


def per_device(function, *batch):
    """`function(*batch)` (pytrees of arrays with leading length n, results too), inside a
    jitted program, on one part of the batch per device where n divides evenly over
    several devices (`shard_map`): each device computes its part on its own, its loops
    waiting for none of the others' (a batch placed by `sharded_batch` is already split
    so). On the whole batch otherwise. Values that `function` closes over are the same on
    every device."""
    sharding = batch_sharding()
    size = jax.tree_util.tree_leaves(batch)[0].shape[0]
    if sharding is None or size % sharding.mesh.size:
        return function(*batch)
    return jax.shard_map(function, mesh=sharding.mesh, in_specs=sharding.spec,
                         out_specs=sharding.spec, check_vma=False)(*batch)
