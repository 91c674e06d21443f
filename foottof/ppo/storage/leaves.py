"""Checkpoint items as flat leaf dicts with a manifest (leaf names, shapes, dtypes), and the fit check.

Each orbax item is saved as a flat dict {'leaf_0000': array, ...} in jax.tree_util flatten order;
the manifest names the leaves (`jax.tree_util.keystr`), so any pytree (flax structs, optax states,
MJX data) round-trips and a mismatch error names the leaf.
"""

from typing import Any

import jax
import numpy as np


def flatten(tree: Any) -> tuple[dict, list]:
    leaves = jax.tree_util.tree_flatten_with_path(tree)[0]
    # Zero-size leaves (e.g. unused MJX data fields) cannot be saved by orbax: they are rebuilt
    # from the target's structure on restore (see unflatten).
    flat = {f"leaf_{i:04d}": leaf for i, (_, leaf) in enumerate(leaves) if np.size(leaf) > 0}
    manifest = [
        [jax.tree_util.keystr(path), list(np.shape(leaf)), str(getattr(leaf, "dtype", "float"))]
        for path, leaf in leaves
    ]
    return flat, manifest


# Per-step env metrics (reward terms, task metrics) are outputs of the last step, recomputed by
# the next one and read by nothing else: a checkpoint written before a metric existed restores
# with that leaf taken from the target (its fresh value), and one that holds a metric this code
# no longer has (removed or renamed, foottof.renames.METRICS) restores without it, so metric
# changes do not break a resume.
RECOMPUTED_LEAF_PREFIX = "['env_state'].metrics["


def leaf_names(tree: Any) -> list[str]:
    return [jax.tree_util.keystr(path) for path, _ in jax.tree_util.tree_flatten_with_path(tree)[0]]


def saved_index(target: Any, saved_manifest: list | None) -> list[int | None]:
    """For each leaf of `target`: its index in the saved item (None: not saved, keep target's).

    Without a manifest (or with the same leaves) this is the identity, as flatten numbers them.
    """
    names = leaf_names(target)
    if saved_manifest is None:
        return list(range(len(names)))
    index = {entry[0]: i for i, entry in enumerate(saved_manifest)}
    return [index.get(n) for n in names]


def abstract_leaves(
    target: Any, saved_manifest: list | None = None, with_extra: bool = False
) -> dict:
    """Abstract arrays of the saved leaves, keyed as saved, shaped/sharded like `target`'s
    (without a manifest: every non-empty leaf of `target`, numbered as flatten does).

    with_extra: also the saved leaves `target` lacks (metrics of older code, which orbax must
    read to restore the item; they are dropped by unflatten), shaped as the manifest says."""
    leaves = jax.tree.leaves(target)
    out = {
        f"leaf_{j:04d}": jax.ShapeDtypeStruct(
            x.shape, x.dtype, sharding=getattr(x, "sharding", None)
        )
        for x, j in zip(leaves, saved_index(target, saved_manifest), strict=True)
        if j is not None and np.size(x) > 0
    }
    if with_extra and saved_manifest is not None:
        by_shape = {np.shape(x): getattr(x, "sharding", None) for x in reversed(leaves)}
        for j, (_, shape, dtype) in enumerate(saved_manifest):
            key = f"leaf_{j:04d}"
            if key not in out and int(np.prod(shape)) > 0:  # sharded as a target leaf its shape
                sharding = by_shape.get(tuple(shape), next(iter(by_shape.values()), None))
                out[key] = jax.ShapeDtypeStruct(tuple(shape), np.dtype(dtype), sharding=sharding)
    return out


def unflatten(target: Any, flat: dict, saved_manifest: list | None = None) -> Any:
    """Inverse of flatten on the structure of `target` (zero-size leaves, and leaves the
    checkpoint does not hold, taken from `target`)."""
    treedef = jax.tree.structure(target)
    leaves = [
        flat[f"leaf_{j:04d}"] if (j is not None and np.size(x) > 0) else x
        for x, j in zip(jax.tree.leaves(target), saved_index(target, saved_manifest), strict=True)
    ]
    return jax.tree.unflatten(treedef, leaves)


class CheckpointMismatch(ValueError):
    """A readable checkpoint whose leaves do not fit the model (names the leaf and shapes)."""


def check_compatible(item: str, saved_manifest: list, target: Any, source: str) -> None:
    """Raises CheckpointMismatch naming the first leaf whose name or shape differs from `target`
    (a per-step env metric the checkpoint lacks or holds in excess is no mismatch:
    RECOMPUTED_LEAF_PREFIX)."""
    _, expected = flatten(jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype), target))
    saved = {name: tuple(shape) for name, shape, _ in saved_manifest}
    for name, shape, _ in expected:
        if name not in saved and name.startswith(RECOMPUTED_LEAF_PREFIX):
            continue
        if name not in saved:
            raise CheckpointMismatch(f"{source}: {item} leaf {name} is missing in the checkpoint")
        if saved[name] != tuple(shape):
            raise CheckpointMismatch(
                f"{source}: {item} leaf {name} has shape {saved[name]} in the checkpoint but "
                f"{tuple(shape)} in this model"
            )
    extra = sorted(set(saved) - {name for name, _, _ in expected})
    extra = [n for n in extra if not n.startswith(RECOMPUTED_LEAF_PREFIX)]
    if extra:
        raise CheckpointMismatch(
            f"{source}: {item} leaf {extra[0]} is in the checkpoint but not in this model"
        )
