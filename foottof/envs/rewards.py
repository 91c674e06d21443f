"""Reward terms of the goal-reaching task: pure functions of a RewardInputs struct, scaled by config."""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from foottof.renames import added_default

# Terms that are rates (multiplied by the control dt) vs. events (counted once).
DENSE_TERMS = (
    "guidance",
    "torques",
    "joint_acc",
    "action_rate",
    "foot_slip",
    "orientation",
    "stall",
    "jump",
    "posture",
    "collision",
    "foot_edge",
    "foot_clearance",
)
SPARSE_TERMS = ("reach", "termination")
REWARD_TERMS = SPARSE_TERMS + DENSE_TERMS


@struct.dataclass
class RewardInputs:
    """Everything the reward terms read, for one env at one control step (world frame unless noted).

    Attributes:
      base_pos: (3,) base position [m].
      base_lin_vel: (3,) base linear velocity [m/s].
      goal_xy: (2,) goal position [m].
      projected_gravity: (3,) gravity direction in the base frame (unit).
      torques: (12,) applied joint torques [N m] (last substep).
      qvel: (12,) joint velocities now [rad/s].
      last_qvel: (12,) joint velocities one control step earlier [rad/s].
      action: (12,) action now; last_action: (12,) previous action.
      foot_vel: (4, 3) foot velocities [m/s]; foot_contact: (4,) 1.0 where a foot touches the ground.
      q: (12,) joint positions [rad]; default_q: (12,) nominal stance [rad].
      time_s: time since the episode started [s].
      failed: 1.0 on a failure termination; truncated: 1.0 at the time limit.
      knee_contact: (4,) 1.0 where a knee sphere touches the terrain.
      foot_edge: (4,) 1.0 where a foot touches the terrain next to a height step (`foot_edges`).
      foot_clearance: (4,) height of each foot's bottom above the highest terrain around it
        (`foot_clearances`) [m]; zeros where the foot_clearance term is off.
    """

    base_pos: jax.Array
    base_lin_vel: jax.Array
    goal_xy: jax.Array
    projected_gravity: jax.Array
    torques: jax.Array
    qvel: jax.Array
    last_qvel: jax.Array
    action: jax.Array
    last_action: jax.Array
    foot_vel: jax.Array
    foot_contact: jax.Array
    q: jax.Array
    default_q: jax.Array
    time_s: jax.Array
    failed: jax.Array
    truncated: jax.Array
    knee_contact: jax.Array
    foot_edge: jax.Array
    foot_clearance: jax.Array


def _probe_heights(foot_pos: jax.Array, height_at, radius_m: float) -> jax.Array:
    """(4, 5) terrain heights under each foot centre and ``radius_m`` away along +-x, +-y."""
    r = float(radius_m)
    offsets = jp.array([[0.0, 0.0], [r, 0.0], [-r, 0.0], [0.0, r], [0.0, -r]], jp.float32)
    return height_at(foot_pos[:, None, :2] + offsets[None])


def foot_edges(
    foot_pos: jax.Array,
    height_at,
    foot_radius_m: float,
    contact_margin_m: float,
    edge_radius_m: float,
    edge_height_m: float,
) -> jax.Array:
    """(4,) 1.0 where a foot stands on or against an edge of the terrain (Extreme Parkour's
    ``feet_edge``, Cheng et al. 2023, from a height lookup instead of a precomputed edge mask).

    The terrain is sampled under the foot centre and ``edge_radius_m`` away from it along +-x
    and +-y. A foot is at an edge when those five heights span more than ``edge_height_m`` and
    the foot is within ``foot_radius_m + contact_margin_m`` of the highest of them: resting on
    the rim of a stone counts, and so does a foot slipping down its side into the crack (which
    the contact test under the foot centre alone misses: the centre is over the crack).

    Args:
      foot_pos: (4, 3) world foot-centre positions [m].
      height_at: terrain height lookup, (..., 2) xy -> (...) z [m] (Heightfield.height_at).
      foot_radius_m, contact_margin_m: as the foot contact test [m].
      edge_radius_m: horizontal distance of the four side samples from the foot centre [m].
      edge_height_m: height spread that makes an edge [m].
    """
    heights = _probe_heights(foot_pos, height_at, edge_radius_m)  # (4, 5)
    top = jp.max(heights, axis=-1)
    touching = foot_pos[:, 2] - top < foot_radius_m + contact_margin_m
    spread = top - jp.min(heights, axis=-1)
    return (touching & (spread > edge_height_m)).astype(jp.float32)


def foot_clearances(
    foot_pos: jax.Array, height_at, foot_radius_m: float, edge_radius_m: float
) -> jax.Array:
    """(4,) height of each foot's bottom above the highest terrain under it [m].

    The terrain is sampled where ``foot_edges`` samples it (under the foot centre and
    ``edge_radius_m`` away along +-x, +-y), so a foot swinging past the rim of a stone is measured
    from the rim, and one over the middle of a gap from the gap's floor (no clearance is owed there).

    Args:
      foot_pos: (4, 3) world foot-centre positions [m].
      height_at: terrain height lookup, (..., 2) xy -> (...) z [m] (Heightfield.height_at).
      foot_radius_m: foot sphere radius [m].
      edge_radius_m: horizontal distance of the four side samples from the foot centre [m].
    """
    top = jp.max(_probe_heights(foot_pos, height_at, edge_radius_m), axis=-1)  # (4,)
    return foot_pos[:, 2] - foot_radius_m - top


def goal_distance(x: RewardInputs) -> jax.Array:
    """Horizontal distance from the base to the goal [m]."""
    return jp.linalg.norm(x.goal_xy - x.base_pos[:2])


def compute_terms(x: RewardInputs, rcfg, control_dt_s: float) -> dict[str, jax.Array]:
    """Unscaled reward terms (each a scalar), keyed by REWARD_TERMS.

    Args:
      x: the inputs of this step.
      rcfg: the `reward` config section (radii, speeds, grace time).
      control_dt_s: control period, used for joint accelerations [s].
    """
    dist = goal_distance(x)
    at_goal = (dist < rcfg.success_radius_m).astype(jp.float32)
    to_goal = (x.goal_xy - x.base_pos[:2]) / jp.maximum(dist, 1e-6)
    v_toward = jp.dot(x.base_lin_vel[:2], to_goal)
    vmax = rcfg.guidance_max_speed_mps
    # Dense guidance: speed toward the goal (clipped); full credit once within the success radius.
    paid = jp.clip(v_toward, -vmax, vmax)
    peaked = rcfg.get("guidance_peaked", added_default("reward.guidance_peaked"))
    if peaked:  # static: above vmax the pay falls as it rose
        paid = jp.where(v_toward > vmax, jp.maximum(2.0 * vmax - v_toward, -vmax), paid)
    guidance = jp.where(at_goal > 0, vmax, paid)
    speed = jp.linalg.norm(x.base_lin_vel[:2])
    stalling = (speed < rcfg.stall_speed_mps) & (at_goal == 0) & (x.time_s > rcfg.stall_grace_s)
    foot_speed_sq = jp.sum(jp.square(x.foot_vel[:, :2]), axis=-1)
    target = rcfg.get("clearance_target_m", added_default("reward.clearance_target_m"))
    return {
        "reach": x.truncated * at_goal,
        "termination": x.failed,
        "guidance": guidance,
        "torques": jp.sum(jp.square(x.torques)),
        "joint_acc": jp.sum(jp.square((x.qvel - x.last_qvel) / control_dt_s)),
        "action_rate": jp.sum(jp.square(x.action - x.last_action)),
        "foot_slip": jp.sum(x.foot_contact * foot_speed_sq),
        "orientation": jp.sum(jp.square(x.projected_gravity[:2])),
        "stall": stalling.astype(jp.float32),
        # all feet off the ground, once the spawn drop (env.spawn_height_offset_m) has landed
        "jump": (jp.all(x.foot_contact < 0.5) & (x.time_s > rcfg.jump_grace_s)).astype(jp.float32),
        "posture": at_goal * jp.sum(jp.square(x.q - x.default_q)),
        "collision": jp.sum(x.knee_contact),
        "foot_edge": jp.sum(x.foot_edge),
        # Isaac Lab's foot_clearance_reward (Spot), as a penalty on the shortfall only and from
        # the terrain under the foot: sum over feet of tanh(2 |v_xy|) max(0, target - clearance)^2,
        # so moving (swinging) feet are asked to lift to the target and standing feet not.
        "foot_clearance": jp.sum(
            jp.tanh(2.0 * jp.sqrt(foot_speed_sq))
            * jp.square(jp.maximum(target - x.foot_clearance, 0.0))
        ),
    }


def scaled_terms(terms: dict[str, jax.Array], scales, control_dt_s: float) -> dict[str, jax.Array]:
    """Scale each term by config; dense terms are also multiplied by the control dt."""
    out = {}
    for name in REWARD_TERMS:
        dt = control_dt_s if name in DENSE_TERMS else 1.0
        out[name] = terms[name] * float(getattr(scales, name)) * dt
    return out


def total_reward(terms: dict[str, jax.Array], only_positive: bool, valid: jax.Array) -> jax.Array:
    """The step reward from scaled terms: dense sum (clipped at 0 if ``only_positive``) + sparse.

    ``only_positive`` is legged_gym's ``only_positive_rewards`` ("avoids early termination
    problems"): the dense terms can make a step worth nothing but never negative, so a policy
    learning to walk is not paid less than one standing still for each stumble; the sparse
    ``reach`` and ``termination`` are added after the clip (as legged_gym adds termination).

    Args:
      terms: scaled terms keyed by REWARD_TERMS (scalars).
      only_positive: clip the dense sum at 0 (static).
      valid: 1.0 where the step's physics is valid; 0.0 on a diverged step, whose dense terms
        (from sanitized, meaningless velocities) are dropped: it is paid its sparse terms only.
    """
    dense = sum(terms[k] for k in DENSE_TERMS) * valid
    if only_positive:
        dense = jp.maximum(dense, 0.0)
    return dense + sum(terms[k] for k in SPARSE_TERMS)


def check_scales(scales) -> None:
    """Raise ValueError for unknown or missing reward terms in `reward.scales`."""
    keys = set(scales.keys())
    unknown = sorted(keys - set(REWARD_TERMS))
    missing = sorted(set(REWARD_TERMS) - keys)
    if unknown:
        raise ValueError(f"unknown reward term(s) {unknown}; valid terms: {list(REWARD_TERMS)}")
    if missing:
        raise ValueError(
            f"reward.scales is missing term(s) {missing}; valid terms: {list(REWARD_TERMS)}"
        )
