"""The teacher's fine terrain inputs (env.actor_terrain_fine): heights every 5 cm where the feet land.

The teacher's terrain inputs (env.actor_terrain) sample every 10 cm: a 3 x 3 patch around each
foot and a 13 x 9 base scan up to 0.6 m ahead (foottof.envs.observations). On 0.27-0.30 m
stones that is three samples across a stone, and a rim lies anywhere within 10 cm of the nearest
sample: the teacher's stuck feet landed a median 4.0 cm past rims its inputs had shown
(docs/campaign.md, issue "Stones, fourth round"). The paper's ideal scan samples every 5 cm.

This block adds the points between the 10 cm samples, so that together with them the teacher
reads a 5 x 5 patch, 5 cm apart, around each foot and a 25 x 17 base scan, 5 cm apart, over the
same area (x -0.6..0.6 m, y -0.4..0.4 m): 4 x 16 + 308 = 372 inputs, appended after the 10 cm
ones. The 10 cm inputs keep their place, so a teacher trained without the block starts from its
own weights with zero weights on the new inputs (init_from, foottof.ppo.input_growth) and acts as
before; :func:`seed_normalizer` gives the new inputs the running statistics of their nearest
10 cm sample, since a normalizer restored with ~10^8 samples would otherwise keep the new
entries at mean 0 / std 1 for good.

Heights are relative to the foot centre (patches) and the base (scan), clipped to +-1 m, true
terrain everywhere (no env.actor_terrain_seen variant: a config with both is refused).
"""

from __future__ import annotations

import jax
import jax.numpy as jp
import numpy as np

from foottof.envs import observations as obs_lib

STEP_M = 0.05  # the fine grid's spacing
_PATCH_AXIS = np.round(np.arange(-2, 3) * STEP_M, 4)  # -0.1 .. 0.1 (5)
_SCAN_X = np.round(np.arange(-12, 13) * STEP_M, 4)  # -0.6 .. 0.6 (25): the actor scan's rows
_SCAN_Y = np.round(np.arange(-8, 9) * STEP_M, 4)  # -0.4 .. 0.4 (17)


def _coarse(v: np.ndarray) -> np.ndarray:
    """True where v lies on the 10 cm grid."""
    return np.isclose(np.round(v / 0.1) * 0.1, v, atol=1e-6)


def _grid(xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """(n, 2) row-major (x outer, y inner) points of xs x ys that are not on the 10 cm grid."""
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    pts = np.stack([gx.reshape(-1), gy.reshape(-1)], axis=-1)
    return pts[~(_coarse(pts[:, 0]) & _coarse(pts[:, 1]))].astype(np.float32)


PATCH_OFFSETS = _grid(_PATCH_AXIS, _PATCH_AXIS)  # (16, 2) around a foot centre, world-aligned
SCAN_POINTS = _grid(_SCAN_X, _SCAN_Y)  # (308, 2) base-yaw frame
NUM_INPUTS = 4 * PATCH_OFFSETS.shape[0] + SCAN_POINTS.shape[0]  # 372


def fine_terrain(height_at, foot_pos: jax.Array, base_pos: jax.Array, base_quat: jax.Array):
    """(372,) the fine block: 4 feet x 16 patch heights relative to the foot centre, then 308 scan
    heights relative to the base, clipped to +-1 m [m].

    Args:
      height_at: (..., 2) world x, y -> (...) terrain height [m].
      foot_pos: (4, 3) world foot centres; base_pos: (3,); base_quat: (4,) wxyz.
    """
    patch_pts = foot_pos[:, None, :2] + jp.asarray(PATCH_OFFSETS)[None]  # (4, 16, 2)
    patches = height_at(patch_pts) - foot_pos[:, None, 2]
    scan_xy = obs_lib.base_yaw_to_world(jp.asarray(SCAN_POINTS), base_pos, base_quat)
    scan = height_at(scan_xy) - base_pos[2]
    return jp.clip(jp.concatenate([patches.reshape(-1), scan]), -1.0, 1.0)


def coarse_sources() -> np.ndarray:
    """(372,) for each fine input, the index within the 10 cm terrain block (observations:
    36 foot patches then the 117-point scan) of its nearest 10 cm sample (same foot for a patch
    point; ties go to the lower index)."""
    coarse_patch = np.asarray(obs_lib.FOOT_PATCH_OFFSETS_M, np.float32)  # (9, 2)
    coarse_scan = np.asarray(obs_lib.critic_scan_points())[: obs_lib.ACTOR_SCAN_POINTS]
    out = []
    for foot in range(4):
        d = np.linalg.norm(PATCH_OFFSETS[:, None] - coarse_patch[None], axis=-1)
        out.append(foot * 9 + np.argmin(d + 1e-6 * np.arange(9), axis=1))
    d = np.linalg.norm(SCAN_POINTS[:, None] - coarse_scan[None], axis=-1)
    out.append(36 + np.argmin(d + 1e-6 * np.arange(coarse_scan.shape[0]), axis=1))
    return np.concatenate(out).astype(np.int64)


def mirror_perm() -> tuple[np.ndarray, np.ndarray]:
    """(perm, sign) of the block under the left-right mirror (foottof.envs.symmetry): the feet
    swap (LF <-> RF, LH <-> RH) and every point's y (dy, base y) changes sign; heights keep their
    sign."""
    from foottof.envs.symmetry import FOOT_PERM

    def match(pts):
        mirrored = pts * np.array([1.0, -1.0], np.float32)
        d = np.linalg.norm(mirrored[:, None] - pts[None], axis=-1)
        return np.argmin(d, axis=1)

    n = PATCH_OFFSETS.shape[0]
    within = match(PATCH_OFFSETS)
    perm = [FOOT_PERM[f] * n + within for f in range(4)]
    perm.append(4 * n + match(SCAN_POINTS))
    perm = np.concatenate(perm)
    return perm, np.ones(perm.shape[0], np.float32)


def seed_normalizer(normalizer, key: str = "state"):
    """``normalizer`` with the fine block's entries (the last 372 of ``key``; the 153 10 cm
    terrain inputs before them) set to the running statistics of their nearest 10 cm sample (:func:`coarse_sources`) where
    they still hold input growth's fill (mean exactly 0 and std exactly 1 over the whole block:
    a normalizer just grown by init_from); otherwise ``normalizer`` unchanged.

    Args:
      normalizer: brax running_statistics.RunningStatisticsState over a dict observation.
      key: the observation key of the actor's inputs.

    Returns:
      (normalizer, seeded): the normalizer and whether it was seeded.
    """
    mean = np.asarray(normalizer.mean[key])
    start = mean.shape[-1] - NUM_INPUTS
    base_inputs = start - obs_lib.ACTOR_TERRAIN_INPUTS
    if base_inputs < 0:
        raise ValueError(
            f"the normalizer's {key!r} has {mean.shape[-1]} entries; a teacher with "
            f"env.actor_terrain_fine has at least {obs_lib.ACTOR_TERRAIN_INPUTS + NUM_INPUTS}"
        )
    std = np.asarray(normalizer.std[key])
    if not (np.all(mean[start:] == 0.0) and np.all(std[start:] == 1.0)):
        return normalizer, False
    src = base_inputs + coarse_sources()

    def seeded(tree):
        x = np.array(tree[key])
        x[start:] = x[src]
        return {**tree, key: jax.device_put(x, tree[key].sharding)}

    return (
        normalizer.replace(
            mean=seeded(normalizer.mean),
            std=seeded(normalizer.std),
            summed_variance=seeded(normalizer.summed_variance),
        ),
        True,
    )
