"""Input growth: a checkpoint whose network reads fewer inputs restores into one that reads more.

When a run adds inputs at the end (critic inputs such as env.critic_height_scan; network.obs_skip's
observation beside the LSTM output; on request the actor's, env.actor_terrain), init_from or a
resume from a run without them restores the saved kernels with zero rows for the new inputs and
normalizer entries of mean 0 / variance 1: the grown network acts as the saved one did. A resume
also grows the Adam moments: the new entries' first moments zero, their second moments seeded at
the saved leaf's mean (seed_second_moment; init_from starts a fresh optimizer). The names below
match inside params, the optimizer's moments and the normalizer.

Width growth: the actor head (network.actor_hidden) restores into wider layers too. A layer's saved
kernel fills the top-left block; the rows of new inputs or new units of the layer below are zero
for the saved units, and the new units' own columns (and biases) keep the fresh model's initial
values (Adam: first moment zero, second moment seeded as above). The saved units never hear from
the new ones and the output layer gets only zero rows from them, so the grown actor acts as the
saved one; the new units' outgoing rows get gradients at once (their activations are not zero), so
they join in as training goes on (the zero-outgoing-weight form of Net2Net widening, Chen et al.
2016).
"""

from typing import Any

import jax
import numpy as np

# Leaves whose first axis is a network's input (grown by init_from and a resume).
INPUT_LEAVES = (
    "['memory_c']['lstm_0']['ii']['kernel']",
    "['memory_c']['lstm_0']['if']['kernel']",
    "['memory_c']['lstm_0']['ig']['kernel']",
    "['memory_c']['lstm_0']['io']['kernel']",
    "['critic']['dense_0']['kernel']",  # the critic head's first layer (mlp policy, obs_skip)
    "['actor']['dense_0']['kernel']",  # the actor head's first layer (mlp policy, obs_skip)
    "['privileged_state']",  # normalizer mean / std / summed_variance
)
# The actor's inputs: grown only on request (init_from into env.actor_terrain, a teacher started
# from a sensor-only policy); anywhere else an actor of another layout is an error.
ACTOR_INPUT_LEAVES = (
    "['memory_a']['lstm_0']['ii']['kernel']",
    "['memory_a']['lstm_0']['if']['kernel']",
    "['memory_a']['lstm_0']['ig']['kernel']",
    "['memory_a']['lstm_0']['io']['kernel']",
    "['state']",  # normalizer mean / std / summed_variance
)
GROWABLE_ITEMS = ("params", "opt_state", "normalizer")  # a resume grows these, not 'rollout'
# The actor head's layers (kernels and biases, in params and the Adam moments): these may also
# grow along their output axis (a wider network.actor_hidden), see grow_width.
WIDTH_LEAVES = ("['actor']['dense_", "['actor']['out']")
SECOND_MOMENT = ".nu["  # optax's Adam state: mu (first moment), nu (second moment)


def _is_width_leaf(name: str) -> bool:
    return any(k in name for k in WIDTH_LEAVES)


def grown_leaves(saved_manifest: list, target: Any, actor: bool = False) -> dict[str, tuple]:
    """{leaf name: saved shape} of input leaves (INPUT_LEAVES, and ACTOR_INPUT_LEAVES if
    ``actor``) the checkpoint holds with fewer inputs (a shorter first axis, the rest equal) than
    `target`.

    Args:
      saved_manifest: one item's manifest, [[leaf name, shape, dtype], ...].
      target: that item's pytree in this model (arrays or abstract arrays)."""
    leaves = INPUT_LEAVES + (ACTOR_INPUT_LEAVES if actor else ())
    saved = {name: tuple(shape) for name, shape, _ in saved_manifest}
    out = {}
    for path, x in jax.tree_util.tree_flatten_with_path(target)[0]:
        name = jax.tree_util.keystr(path)
        old, new = saved.get(name), tuple(np.shape(x))
        if old is None or len(old) != len(new) or len(old) < 1 or old == new:
            continue
        if _is_width_leaf(name):  # the actor head: any axis may grow (grow_width)
            if all(o <= n for o, n in zip(old, new, strict=True)):
                out[name] = old
        elif any(k in name for k in leaves) and old[0] < new[0] and old[1:] == new[1:]:
            out[name] = old
    return out


def shaped_as_saved(target: Any, grown: dict[str, tuple]) -> Any:
    """`target` with the leaves in `grown` ({name: saved shape}) as abstract arrays of the
    saved shape (what the checkpoint holds)."""
    return jax.tree_util.tree_map_with_path(
        lambda p, x: (
            jax.ShapeDtypeStruct(grown[jax.tree_util.keystr(p)], x.dtype)
            if jax.tree_util.keystr(p) in grown
            else x
        ),
        target,
    )


def grow_tree(tree: Any, target: Any, grown: dict[str, tuple]) -> Any:
    """The restored `tree` with its `grown` leaves embedded in `target`'s shapes (grow_rows; a
    normalizer's new entries get the variance-1 summed variance of its sample count; the actor
    head's layers by grow_width, whose new units keep `target`'s values)."""
    count = 0.0
    if "normalizer" in tree:
        c = tree["normalizer"].count
        count = float(np.asarray(getattr(c, "hi", 0))) * 2.0**32 + float(
            np.asarray(getattr(c, "lo", c))
        )

    def grow(name, x, t):
        out = grow_width(x, t) if _is_width_leaf(name) else grow_rows(name, x, np.shape(t), count)
        if SECOND_MOMENT in name:
            out = seed_second_moment(out, x)
        return out

    return jax.tree_util.tree_map_with_path(
        lambda p, x, t: (
            jax.numpy.asarray(grow(jax.tree_util.keystr(p), x, t))
            if jax.tree_util.keystr(p) in grown
            else x
        ),
        tree,
        target,
    )


def grow_width(value: Any, target: Any) -> np.ndarray:
    """A saved actor-head leaf embedded in the wider `target` leaf (module docstring): a kernel
    (in, out) keeps its saved block [:in0, :out0], zero rows [in0:, :out0] (new inputs or units
    below do not reach the saved units) and `target`'s new columns [:, out0:] (the new units'
    fresh weights); a bias (out,) keeps [:out0] and `target`'s new entries."""
    value, out = np.asarray(value), np.array(target, dtype=np.asarray(value).dtype)
    if value.ndim == 1:
        out[: value.shape[0]] = value
        return out
    if value.ndim != 2:
        raise ValueError(f"grow_width: a kernel or bias, got shape {value.shape}")
    n_in, n_out = value.shape
    out[:n_in, :n_out] = value
    out[n_in:, :n_out] = 0.0
    return out


def seed_second_moment(grown: Any, saved: Any) -> np.ndarray:
    """An Adam second moment (``nu``) grown from `saved`: its new entries (outside the saved
    leading block) set to the mean of the saved entries, the saved block as saved.

    A resume restores Adam's step count, so bias correction no longer scales a new entry's
    moments up: from nu = 0, with a steady gradient g, its steps are (1 - b1^k) / sqrt(k (1 - b2))
    times the learning rate after k steps (3x at the first, 6.5x at the tenth, still 3x at the
    hundredth), where a settled entry's are at most ~1x, until nu has caught up after ~1 / (1 -
    b2) = 1000 Adam steps (~60 iterations at 4 epochs x 4 minibatches). The wide teacher's first
    grown iterations showed it: the KL-adaptive rate fell from 1e-4 to 1.4e-5 and took ~50
    iterations to recover. Seeded at the layer's typical squared gradient, a new entry's steps
    start at the size of its neighbours' (the first moment stays zero: no direction is assumed).
    """
    saved = np.asarray(saved)
    out = np.array(grown, dtype=saved.dtype)
    if saved.size == 0:
        return out
    old = tuple(slice(0, n) for n in saved.shape)
    new = np.ones(out.shape, bool)
    new[old] = False
    out[new] = saved.mean()
    return out


def grow_rows(name: str, value: Any, shape: tuple, count: float) -> np.ndarray:
    """`value` embedded in `shape` along axis 0: new kernel rows 0 (new inputs start unused),
    new normalizer entries mean 0, std 1 and summed variance `count` (variance 1)."""
    value = np.asarray(value)
    fill = 0.0
    if ".std[" in name:
        fill = 1.0
    elif ".summed_variance[" in name:
        fill = count
    pad = np.full((shape[0] - value.shape[0], *value.shape[1:]), fill, value.dtype)
    return np.concatenate([value, pad], axis=0)
