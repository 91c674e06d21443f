"""Terrain curriculum: pure level updates from episode outcomes (jit/vmap-able, explicit keys)."""

from __future__ import annotations

import jax
import jax.numpy as jp


def _check_levels(num_levels: int) -> None:
    if int(num_levels) != num_levels or num_levels < 1:
        raise ValueError(f"num_levels={num_levels!r} must be an integer >= 1")


def progress_fraction(spawn_xy: jax.Array, goal_xy: jax.Array, xy: jax.Array) -> jax.Array:
    """Fraction of the spawn-to-goal distance covered: ``(|g - s| - |g - p|) / |g - s|``.

    Args:
      spawn_xy, goal_xy, xy: (..., 2) world x, y at spawn, of the goal, and now [m].

    Returns:
      (...) progress: 1 at the goal, 0 at the spawn distance, negative when farther than at spawn.
    """
    d0 = jp.linalg.norm(goal_xy - spawn_xy, axis=-1)
    d = jp.linalg.norm(goal_xy - xy, axis=-1)
    return (d0 - d) / jp.maximum(d0, 1e-6)


def update_levels(
    key: jax.Array,
    level: jax.Array,
    done: jax.Array,
    reached_goal: jax.Array,
    progress: jax.Array,
    num_levels: int,
    down_progress_frac: float = 0.5,
    up_progress_frac: float = 1.0,
    failed: jax.Array | None = None,
) -> jax.Array:
    """New curriculum levels of envs whose episode ended (others keep theirs).

    An env that reached its goal, or covered at least ``up_progress_frac`` of the distance to it
    (legged_gym promotes on distance walked, not on full success) without failing (a fall near
    the goal does not promote: it would pay rushing), moves up one level; one that
    solved the top level goes to a random level ~ U{0, ..., num_levels - 1}; one that did not reach
    the goal and covered less than
    ``down_progress_frac`` of the distance moves down one level (not below 0); any other stays.

    Args:
      key: PRNG key (for the random level after solving the top level).
      level: (N,) int current levels in [0, num_levels - 1].
      done: (N,) bool, the episode ended (only these envs change level).
      reached_goal: (N,) bool, the env reached its goal.
      progress: (N,) fraction of the goal distance covered (see :func:`progress_fraction`).
      num_levels: number of levels (static).
      down_progress_frac: threshold on ``progress`` to move down (static), in [0, 1].
      up_progress_frac: threshold on ``progress`` to move up without reaching the goal (static),
        in [down_progress_frac, 1]; 1 (default) = only reaching the goal promotes.
      failed: (N,) bool, the episode ended in a failure (None: no failures); a failed episode is
        not promoted on progress.

    Returns:
      (N,) int32 new levels.
    """
    _check_levels(num_levels)
    if not 0.0 <= down_progress_frac <= 1.0:
        raise ValueError(
            f"down_progress_frac={down_progress_frac!r} outside the valid range [0, 1]"
        )
    if not down_progress_frac <= up_progress_frac <= 1.0:
        raise ValueError(
            f"up_progress_frac={up_progress_frac!r} outside the valid range "
            f"[down_progress_frac={down_progress_frac}, 1]"
        )
    level = jp.asarray(level, jp.int32)
    far = jp.asarray(progress) >= up_progress_frac
    if failed is not None:
        far = far & ~jp.asarray(failed, bool)
    up = jp.asarray(reached_goal, bool) | far
    down = ~up & (jp.asarray(progress) < down_progress_frac)
    new = level + up.astype(jp.int32) - down.astype(jp.int32)
    random_level = jax.random.randint(key, level.shape, 0, num_levels, dtype=jp.int32)
    new = jp.where(new >= num_levels, random_level, jp.maximum(new, 0))
    return jp.where(jp.asarray(done, bool), new, level)
