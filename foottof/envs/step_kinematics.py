"""What the env reads of a physics state's kinematics: feet, foot velocities and contacts, gravity, edges."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jp

from foottof.envs import rewards as rw
from foottof.robot import kinematics


class StepKinematics(NamedTuple):
    """What the terminations and rewards read of the state after the physics step."""

    fk: kinematics.FootKinematics
    foot_vel: jax.Array  # (4, 3) world foot-centre velocities [m/s]
    contact: jax.Array  # (4,) float 1 where a foot is within the contact margin
    gravity: jax.Array  # (3,) projected gravity (base frame)
    foot_edge: jax.Array  # (4,) feet touching the terrain at a height step


def projected_gravity(base_quat: jax.Array) -> jax.Array:
    """(3,) the gravity direction in the base frame (unit; (0, 0, -1) when level)."""
    return kinematics.quat_rotate_inv(base_quat, jp.array([0.0, 0.0, -1.0]))


def foot_contact(height_at, foot_pos: jax.Array, foot_radius_m: float, margin_m: float):
    """(4,) float32: 1 where a foot centre is within radius + contact margin of the terrain.

    Args:
      height_at: terrain height [m] at (..., 2) world x, y.
      foot_pos: (4, 3) world foot centres [m].
      foot_radius_m, margin_m: the foot sphere's radius and the contact margin [m].
    """
    clear = foot_pos[:, 2] - height_at(foot_pos[:, :2])
    return (clear < foot_radius_m + margin_m).astype(jp.float32)


def foot_kinematics(d, shank_scale: float) -> tuple[kinematics.FootKinematics, jax.Array]:
    """World FK of the physics state ``d`` and (4, 3) world foot-centre velocities (FK Jacobian)."""
    qpos, qvel = d.qpos, d.qvel

    def fk_world(q):
        return kinematics.world_foot_kinematics(jp.concatenate([qpos[:7], q]), shank_scale)

    fk, dfk = jax.jvp(fk_world, (qpos[7:19],), (qvel[6:18],))
    omega_w = kinematics.quat_to_mat(qpos[3:7]) @ qvel[3:6]  # free-joint ang. vel. is body-frame
    lever = fk.foot_pos - qpos[0:3]
    return fk, qvel[0:3] + jp.cross(omega_w, lever) + dfk.foot_pos


def step_kinematics(d, spec, hfield, shank_scale: float, foot_radius_m: float) -> StepKinematics:
    """Foot kinematics (analytic FK on the physics model), contacts, gravity, foot edges.

    Args:
      d: the physics state after the step; spec: the task's settings (TaskSpec);
      hfield: the terrain (``height_at``); shank_scale, foot_radius_m: the physics model's.
    """
    fk, foot_vel = foot_kinematics(d, shank_scale)
    sr = spec.reward
    return StepKinematics(
        fk=fk,
        foot_vel=foot_vel,
        contact=foot_contact(hfield.height_at, fk.foot_pos, foot_radius_m, spec.contact_margin_m),
        gravity=projected_gravity(d.qpos[3:7]),
        foot_edge=rw.foot_edges(
            fk.foot_pos,
            hfield.height_at,
            foot_radius_m,
            spec.contact_margin_m,
            sr.edge_radius_m,
            sr.edge_height_m,
        ),
    )
