"""A batch axis sharded over every device JAX sees (``jax.sharding``), for the vmapped
programs of batch inference, SBC replicates and the ray tracer's configurations."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

BATCH_AXIS = "batch"


def shard_batch(tree, devices: list | None = None):
    """``tree``'s leaves (one leading batch axis) padded to a multiple of the number of devices
    (by repeating the last entry) and sharded over ``devices`` (default every device JAX sees,
    those of other processes included) along that axis (``jax.sharding``: a 1-D ``Mesh`` and
    ``NamedSharding``), so that a vmapped program runs a part of the batch on each device;
    unchanged on one device. Callers drop the padding from the results (the first ``n``
    entries are the original batch)."""
    devices = jax.devices() if devices is None else devices
    if len(devices) == 1:
        return tree
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    count = jax.tree_util.tree_leaves(tree)[0].shape[0]
    extra = -count % len(devices)

    def pad(leaf):
        leaf = jnp.asarray(leaf)
        if extra == 0:
            return leaf
        return jnp.concatenate([leaf, jnp.repeat(leaf[-1:], extra, axis=0)])

    sharding = NamedSharding(Mesh(np.array(devices), (BATCH_AXIS,)), PartitionSpec(BATCH_AXIS))

    def place(leaf):  # every process holds the whole batch; each device takes its part
        host = np.asarray(pad(leaf))
        return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])

    return jax.tree_util.tree_map(place, tree)


def gather_batch(tree):
    """The whole of sharded results on every process (several hosts: ``process_allgather``;
    results on this process's devices alone: ``device_get``)."""
    leaves = jax.tree_util.tree_leaves(tree)
    if jax.process_count() == 1 or all(
        getattr(leaf, "is_fully_addressable", True) for leaf in leaves
    ):
        return jax.device_get(tree)
    from jax.experimental import multihost_utils

    return multihost_utils.process_allgather(tree, tiled=True)
