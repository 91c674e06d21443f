"""The observation layout: the actor's blocks in order, the critic's terrain inputs and height scan."""

from __future__ import annotations

import jax
import jax.numpy as jp

from foottof.robot import kinematics

# The teacher's scan (env.actor_terrain): the critic scan's rows up to 0.6 m ahead of the base
# (13 x 9 = 117 points), about as far as the front feet's ToF sensors have looked; the 1.2 m of
# the critic's would let a teacher act on terrain no student has seen.
ACTOR_SCAN_ROWS = 13
ACTOR_SCAN_POINTS = ACTOR_SCAN_ROWS * 9
ACTOR_TERRAIN_INPUTS = 4 * 9 + ACTOR_SCAN_POINTS  # what env.actor_terrain appends (153)


def actor_terrain_size(seen: bool) -> int:
    """How many inputs env.actor_terrain appends: 153 heights, and with env.actor_terrain_seen
    their 153 seen flags after them (306)."""
    return ACTOR_TERRAIN_INPUTS * (2 if seen else 1)


# The critic's terrain patch around each foot centre: a 3 x 3 grid, 10 cm apart [m].
FOOT_PATCH_OFFSETS_M = tuple((dx, dy) for dx in (-0.1, 0.0, 0.1) for dy in (-0.1, 0.0, 0.1))


def actor_obs_layout(num_sensors: int, num_zones: int) -> list[tuple[str, int, int, str]]:
    """(name, start, stop, what) of each block of the actor observation ``obs['state']``, in
    order (see :func:`actor_observation`); stop of the last block = the observation size."""
    blocks = [
        ("tof_distance", num_sensors * num_zones, "zone distances, sensor-major [m]"),
        ("tof_valid", num_sensors * num_zones, "zone validity {0, 1}"),
        ("tof_age", num_sensors, "age of each sensor's frame [s]"),
        ("joint_pos", 12, "joint positions minus the default pose [rad] (JOINT_NAMES order)"),
        ("joint_vel", 12, "joint velocities x 0.05 [rad/s]"),
        ("projected_gravity", 3, "gravity unit vector in the base frame"),
        ("base_lin_vel", 3, "base linear velocity estimate, base frame [m/s]"),
        ("base_ang_vel", 3, "base angular velocity estimate x 0.25 [rad/s]"),
        ("goal", 4, "goal distance clipped at 5 m [m], direction in the base frame (2), time left"),
        ("last_action", 12, "previous action (before scaling)"),
    ]
    out, start = [], 0
    for name, n, what in blocks:
        out.append((name, start, start + n, what))
        start += n
    return out


def actor_observation(
    tof, valid, age_s, q, qd, gravity, lin_vel, ang_vel, goal, last_action, default_q
) -> jax.Array:
    """The actor's sensor-and-body blocks concatenated in :func:`actor_obs_layout` order.

    Args:
      tof, valid: (F, Z) zone distances [m] and validity {0, 1}; age_s: (F,) frame ages [s].
      q, qd: (12,) joint positions [rad] and velocities [rad/s]; default_q: (12,) default pose.
      gravity: (3,) projected gravity; lin_vel, ang_vel: (3,) base velocities, base frame.
      goal: (4,) goal distance [m], direction (2), time left; last_action: (12,).

    Returns:
      (2 F Z + F + 49,) array, e.g. (181,) for 4 sensors x 16 zones.
    """
    return jp.concatenate(
        [
            tof.reshape(-1),  # F sensors x Z zones [m]
            valid.reshape(-1),  # F x Z {0, 1}
            age_s,  # F frame ages [s]
            q - default_q,  # 12 joint positions rel. to default [rad]
            qd * 0.05,  # 12 joint velocities [rad/s] scaled
            gravity,  # 3 projected gravity
            lin_vel,  # 3 base linear velocity estimate [m/s]
            ang_vel * 0.25,  # 3 base angular velocity estimate [rad/s] scaled
            goal,  # 4 goal distance [m], direction (2), time left
            last_action,  # 12
        ]
    )


def foot_patches(height_at, foot_pos: jax.Array) -> jax.Array:
    """(4 x 9,) true terrain heights at FOOT_PATCH_OFFSETS_M around each foot centre, relative
    to the foot centre, clipped to +-1 m [m] (the critic's; a teacher's actor's too)."""
    pts = foot_patch_points(foot_pos)  # (4, 9, 2)
    heights = height_at(pts) - foot_pos[:, None, 2]  # rel. to foot centre
    return jp.clip(heights.reshape(-1), -1.0, 1.0)


def critic_height_scan(height_at, base_pos: jax.Array, base_quat: jax.Array) -> jax.Array:
    """(P,) terrain heights relative to the base at :func:`critic_scan_points`, turned with the
    base's heading (yaw only), clipped to +-1 m [m]."""
    pts = world_scan_points(base_pos, base_quat)
    return jp.clip(height_at(pts) - base_pos[2], -1.0, 1.0)


def foot_patch_points(foot_pos: jax.Array) -> jax.Array:
    """(4, 9, 2) world x, y where :func:`foot_patches` samples the terrain around each foot."""
    return foot_pos[:, None, :2] + jp.array(FOOT_PATCH_OFFSETS_M, jp.float32)[None]


def world_scan_points(base_pos: jax.Array, base_quat: jax.Array) -> jax.Array:
    """(P, 2) world x, y of :func:`critic_scan_points`, turned with the base's heading (yaw)."""
    return base_yaw_to_world(critic_scan_points(), base_pos, base_quat)


def base_yaw_to_world(points: jax.Array, base_pos: jax.Array, base_quat: jax.Array) -> jax.Array:
    """(P, 2) world x, y of base-yaw-frame points (P, 2): turned with the base's heading (yaw
    only), then shifted to the base's x, y."""
    fwd = kinematics.quat_to_mat(base_quat)[:2, 0]  # base x axis, horizontal part
    fwd = fwd / jp.maximum(jp.linalg.norm(fwd), 1e-6)
    rot = jp.array([[fwd[0], -fwd[1]], [fwd[1], fwd[0]]])  # yaw rotation
    return base_pos[None, 0:2] + points @ rot.T


def critic_scan_points() -> jax.Array:
    """(P, 2) base-yaw-frame x, y of the critic's height scan: x -0.6..1.2 m, y -0.4..0.4 m,
    10 cm apart (19 x 9 = 171 points; legged_gym's grid, shifted forward to see the next gaps)."""
    xs = jp.linspace(-0.6, 1.2, 19)
    ys = jp.linspace(-0.4, 0.4, 9)
    gx, gy = jp.meshgrid(xs, ys, indexing="ij")
    return jp.stack([gx.reshape(-1), gy.reshape(-1)], axis=-1)
