"""The actor's and critic's observations of a physics state, assembled in the observations.py layout."""

from __future__ import annotations

import jax
import jax.numpy as jp

from foottof.envs import fine_terrain, sensing
from foottof.envs import observations as obs_lib
from foottof.envs.seen_map import SeenGrid
from foottof.envs.step_kinematics import foot_contact, projected_gravity
from foottof.envs.task_spec import TaskSpec
from foottof.robot import kinematics


class Observer:
    """Builds ``{'state': actor obs, 'privileged_state': critic obs}`` of one env's state.

    Args:
      spec: the task's settings (the observation flags, clip, contact margin).
      hfield: the (clipped) terrain heightfield (``height_at``, ``z_floor_m``).
      seen_grid: the grid of ray-hit cells (env.actor_terrain_seen).
      default_q: (12,) the default joint pose [rad].
      shank_scale: the policy-side kinematics' shank length scale.
      foot_radius_m: the foot sphere's radius [m].
      stand_height_m: the nominal base height over flat ground [m].
      episode_steps: control steps per episode (time left = 1 - step / episode_steps).
    """

    def __init__(
        self,
        spec: TaskSpec,
        hfield,
        seen_grid: SeenGrid,
        default_q: jax.Array,
        shank_scale: float,
        foot_radius_m: float,
        stand_height_m: float,
        episode_steps: int,
    ):
        self.spec = spec
        self.hfield = hfield
        self.seen_grid = seen_grid
        self.default_q = default_q
        self.shank_scale = shank_scale
        self.foot_radius_m = foot_radius_m
        self.stand_height_m = stand_height_m
        self.episode_steps = episode_steps

    def __call__(self, d, task, sense, meas: sensing.Measurements, seen=None) -> dict:
        """Actor and critic observations.

        Actor ``state`` (size 181 for 4 sensors x 16 zones): tof readings (F x Z [m]) + validity
        (F x Z) + frame age (F [s]) + joint positions rel. to default (12, measured) + joint
        velocities (12, noisy, x0.05) + projected gravity (3) + base linear velocity estimate (3,
        base frame) + base angular velocity estimate (3, x0.25) + goal distance (1, clipped at
        5 m) + goal direction in the base frame (2, unit) + time left (1, fraction) + last
        action (12); with ``env.actor_terrain`` (a teacher) also the true terrain heights
        around each foot (4 x 9, as the critic's) and the base scan up to 0.6 m ahead (117, the
        first ACTOR_SCAN_ROWS rows of the critic's); with ``env.actor_terrain_seen`` those only
        where a foot ray has hit, and 153 seen flags (:meth:`actor_terrain`); the layout:
        foottof.envs.observations.
        Critic ``privileged_state``: the same without noise (true readings, joints, velocities)
        + true terrain heights around each foot relative to the foot centre (4 x 9, 10 cm grid)
        + foot contacts (4) + friction (1) + added base mass (1, x0.1) + with
        ``env.critic_height_scan``, the terrain heights relative to the base at
        :func:`~foottof.envs.observations.critic_scan_points` (171, base-yaw frame, clipped to
        +-1 m).

        Args:
          d: the physics state; task: the env's TaskState; sense: this step's sensing output;
          meas: the noisy joint and odometry readings; seen: (origin, grid) of the ray-hit cells
          (env.actor_terrain_seen), else None.
        """
        p = task.params
        qpos, qvel = d.qpos, d.qvel
        base_quat = qpos[3:7]
        qd = qvel[6:18]
        qd_meas = qd + p.joint_vel_noise_rads * jax.random.normal(task.rng, (12,))
        gravity = projected_gravity(base_quat)
        lin_b = kinematics.quat_rotate_inv(base_quat, qvel[0:3])
        goal_feats = self._goal_features(task, qpos, base_quat)

        def actor(tof, valid, q_in, qd_in, lin, ang):
            return obs_lib.actor_observation(
                tof, valid, sense.age_s, q_in, qd_in, gravity, lin, ang, goal_feats,
                task.last_action, self.default_q,
            )  # fmt: skip

        state_obs = actor(sense.distance, sense.valid, meas.q, qd_meas, meas.lin_vel, meas.ang_vel)
        clean = actor(sense.true_distance, sense.true_valid, qpos[7:19], qd, lin_b, qvel[3:6])
        fk = kinematics.world_foot_kinematics(qpos, self.shank_scale)
        patches = obs_lib.foot_patches(self.hfield.height_at, fk.foot_pos)
        contact = foot_contact(
            self.hfield.height_at, fk.foot_pos, self.foot_radius_m, self.spec.contact_margin_m
        )
        parts = [
            clean,
            patches,  # 4 feet x 9 heights [m]
            contact,  # 4
            p.friction[None],  # 1
            p.added_mass_kg[None] * 0.1,  # 1
        ]
        scan = None
        if self.spec.critic_height_scan or self.spec.actor_terrain:  # static
            scan = obs_lib.critic_height_scan(self.hfield.height_at, qpos[0:3], base_quat)  # 171
        if self.spec.critic_height_scan:
            parts.append(scan)
        priv = jp.concatenate(parts)
        if self.spec.actor_terrain:  # static: a teacher's actor also sees the terrain, true
            terrain = self.actor_terrain(seen, fk, patches, scan, qpos[0:3], base_quat)
            state_obs = jp.concatenate([state_obs, terrain])
        if self.spec.actor_terrain_fine:  # static: and 5 cm apart in between (372)
            fine = fine_terrain.fine_terrain(
                self.hfield.height_at, fk.foot_pos, qpos[0:3], base_quat
            )
            state_obs = jp.concatenate([state_obs, fine])
        lim = self.spec.clip_observations
        return {
            "state": jp.clip(jp.nan_to_num(state_obs), -lim, lim),
            "privileged_state": jp.clip(jp.nan_to_num(priv), -lim, lim),
        }

    def _goal_features(self, task, qpos, base_quat) -> jax.Array:
        """(4,) goal distance clipped at 5 m [m], unit direction in the base frame (2), time
        left (fraction of the episode)."""
        to_goal_w = jp.concatenate([task.goal - qpos[0:2], jp.zeros(1)])
        to_goal_b = kinematics.quat_rotate_inv(base_quat, to_goal_w)[:2]
        dist = jp.linalg.norm(to_goal_b)
        direction = to_goal_b / jp.maximum(dist, 1e-6)
        time_left = 1.0 - task.step.astype(jp.float32) / self.episode_steps
        return jp.concatenate([jp.minimum(dist, 5.0)[None], direction, time_left[None]])

    def actor_terrain(self, seen, fk, patches, scan, base_pos, base_quat) -> jax.Array:
        """The teacher's terrain inputs (env.actor_terrain): the foot patches (36) and the base
        scan up to 0.6 m ahead (117), true heights; with env.actor_terrain_seen, each point only
        where a foot sensor's ray has hit its cell this episode, else flat ground at the nominal
        stance (a patch: -foot radius below the foot centre; the scan: -stand height below the
        base), followed by the 153 seen flags {0, 1}."""
        n = obs_lib.ACTOR_SCAN_POINTS
        heights = jp.concatenate([patches, scan[:n]])
        if not self.spec.actor_terrain_seen:  # static
            return heights
        pts = jp.concatenate(
            [
                obs_lib.foot_patch_points(fk.foot_pos).reshape(-1, 2),
                obs_lib.world_scan_points(base_pos, base_quat)[:n],
            ]
        )
        flags = self.seen_grid.lookup(seen[0], seen[1], pts)
        fill = jp.concatenate(
            [jp.full(patches.shape, -self.foot_radius_m), jp.full((n,), -self.stand_height_m)]
        )
        return jp.concatenate([jp.where(flags, heights, fill), flags.astype(jp.float32)])
