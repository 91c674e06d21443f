"""Reward terms of the goal-reaching task: pure functions of a RewardInputs struct, scaled by config."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jp
from flax import struct

from foottof import config_check

# Terms that are rates (multiplied by the control dt) vs. events (counted once).
DENSE_TERMS = (
    "task",
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
    "overspeed",
)
SPARSE_TERMS = ("reach", "termination")
REWARD_TERMS = SPARSE_TERMS + DENSE_TERMS


@dataclasses.dataclass(frozen=True)
class RewardSpec:
    """The ``reward`` section, read once (``RewardSpec.from_config(cfg.reward)``, a complete one:
    a saved run config is read migrated, renames.read_saved_config): what the env's phases and
    :func:`compute_terms` read, not the config."""

    success_radius_m: float  # ending within this distance of the goal is a success [m]
    guidance_max_speed_mps: float
    guidance_goal_pay: bool
    guidance_decay: tuple[int, int]  # (start, end) training iteration; end 0: no decay
    task_window_s: float
    stall_toward_goal: bool
    stall_speed_mps: float
    stall_grace_s: float
    jump_grace_s: float
    edge_radius_m: float
    edge_height_m: float
    overspeed_mps: float  # the overspeed term counts base speed above this [m/s]
    overall_scale: float  # multiplies every scaled term
    only_positive: bool
    scales: tuple[tuple[str, float], ...]  # (term, scale) in REWARD_TERMS order

    def __post_init__(self):
        start, end = self.guidance_decay  # the rule lives in foottof.config_check
        config_check.check_fields(
            "reward",
            {"guidance_decay_start_iteration": start, "guidance_decay_end_iteration": end},
        )

    @classmethod
    def from_config(cls, rcfg) -> RewardSpec:
        check_scales(rcfg.scales)
        return cls(
            success_radius_m=float(rcfg.success_radius_m),
            guidance_max_speed_mps=float(rcfg.guidance_max_speed_mps),
            guidance_goal_pay=bool(rcfg.guidance_goal_pay),
            guidance_decay=(
                int(rcfg.guidance_decay_start_iteration),
                int(rcfg.guidance_decay_end_iteration),
            ),
            task_window_s=float(rcfg.task_window_s),
            stall_toward_goal=bool(rcfg.stall_toward_goal),
            stall_speed_mps=float(rcfg.stall_speed_mps),
            stall_grace_s=float(rcfg.stall_grace_s),
            jump_grace_s=float(rcfg.jump_grace_s),
            edge_radius_m=float(rcfg.edge_radius_m),
            edge_height_m=float(rcfg.edge_height_m),
            overspeed_mps=float(rcfg.overspeed_mps),
            overall_scale=float(rcfg.overall_scale),
            only_positive=bool(rcfg.only_positive),
            scales=tuple((name, float(rcfg.scales[name])) for name in REWARD_TERMS),
        )

    def scale(self, name: str) -> float:
        """The scale of term ``name`` (reward.scales)."""
        return dict(self.scales)[name]


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
      time_left_s: time until the episode's deadline after this step [s] (0 at the last step).
      guidance_weight: weight of the guidance bias this step, in [0, 1] (`guidance_weight`).
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
    time_left_s: jax.Array
    guidance_weight: jax.Array


def guidance_weight(iteration: jax.Array, start_iteration: int, end_iteration: int) -> jax.Array:
    """Weight of the guidance bias after ``iteration`` training iterations: 1 until
    ``start_iteration``, then linearly down to 0 at ``end_iteration`` and 0 after (Zhang et al.
    2024 pay their move-in-direction reward only early in training; Rudin et al. 2022 remove
    their bias once the task is learned). ``end_iteration <= 0`` means no decay: always 1.

    Args:
      iteration: training iterations done (float or int, traced).
      start_iteration, end_iteration: the decay's start and end (static ints, start < end).
    """
    if end_iteration <= 0:
        return jp.ones_like(jp.asarray(iteration, jp.float32))
    span = float(end_iteration - start_iteration)
    w = (float(end_iteration) - jp.asarray(iteration, jp.float32)) / span
    return jp.clip(w, 0.0, 1.0)


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


def goal_distance(x: RewardInputs) -> jax.Array:
    """Horizontal distance from the base to the goal [m]."""
    return jp.linalg.norm(x.goal_xy - x.base_pos[:2])


def compute_terms(x: RewardInputs, spec: RewardSpec, control_dt_s: float) -> dict[str, jax.Array]:
    """Unscaled reward terms (each a scalar), keyed by REWARD_TERMS.

    Args:
      x: the inputs of this step.
      spec: the reward section (radii, speeds, grace times; RewardSpec.from_config).
      control_dt_s: control period, used for joint accelerations [s].
    """
    dist = goal_distance(x)
    at_goal = (dist < spec.success_radius_m).astype(jp.float32)
    to_goal = (x.goal_xy - x.base_pos[:2]) / jp.maximum(dist, 1e-6)
    v_toward = jp.dot(x.base_lin_vel[:2], to_goal)
    vmax = spec.guidance_max_speed_mps
    # Dense guidance: speed toward the goal (clipped); full credit once within the success radius.
    paid = jp.clip(v_toward, -vmax, vmax)
    # static: full credit within the success radius (the old task), or nothing paid there
    guidance = (
        jp.where(at_goal > 0, vmax if spec.guidance_goal_pay else 0.0, paid) * x.guidance_weight
    )
    # Task (Rudin et al. 2022): 1 / (T_r (1 + d^2)) per second, paid only in the last T_r seconds,
    # so the window pays 1 / (1 + d^2) in all however early the goal was reached.
    window = spec.task_window_s
    in_window = (x.time_left_s < window - 0.5 * control_dt_s).astype(jp.float32)
    task = in_window / (window * (1.0 + jp.square(dist)))
    # Stall: slow (or, with stall_toward_goal, slow toward the goal: walking about does not
    # count as moving) and outside the success radius, after the grace period.
    horizontal_speed = jp.linalg.norm(x.base_lin_vel[:2])
    speed = v_toward if spec.stall_toward_goal else horizontal_speed  # static
    stalling = (speed < spec.stall_speed_mps) & (at_goal == 0) & (x.time_s > spec.stall_grace_s)
    foot_speed_sq = jp.sum(jp.square(x.foot_vel[:, :2]), axis=-1)
    return {
        "reach": x.truncated * at_goal,
        "termination": x.failed,
        "task": task,
        "guidance": guidance,
        "torques": jp.sum(jp.square(x.torques)),
        "joint_acc": jp.sum(jp.square((x.qvel - x.last_qvel) / control_dt_s)),
        "action_rate": jp.sum(jp.square(x.action - x.last_action)),
        "foot_slip": jp.sum(x.foot_contact * foot_speed_sq),
        "orientation": jp.sum(jp.square(x.projected_gravity[:2])),
        "stall": stalling.astype(jp.float32),
        # all feet off the ground, once the spawn drop (env.spawn_height_offset_m) has landed
        "jump": (jp.all(x.foot_contact < 0.5) & (x.time_s > spec.jump_grace_s)).astype(jp.float32),
        "posture": at_goal * jp.sum(jp.square(x.q - x.default_q)),
        "collision": jp.sum(x.knee_contact),
        "foot_edge": jp.sum(x.foot_edge),
        # The paper's "overly aggressive gaits" regularizer: horizontal base speed above
        # overspeed_mps, linear in the excess (arriving early earns nothing on the arrive task).
        "overspeed": jp.maximum(horizontal_speed - spec.overspeed_mps, 0.0),
    }


def scaled_terms(
    terms: dict[str, jax.Array], scales, control_dt_s: float, overall: float = 1.0
) -> dict[str, jax.Array]:
    """Scale each term by config; dense terms are also multiplied by the control dt.

    ``overall`` (``reward.overall_scale``) multiplies every term: it leaves every ratio of the
    reward, and so what it prices, unchanged, and scales the value targets (with normalized
    advantages the policy gradient does not change, the value loss by ``overall**2``)."""
    out = {}
    for name in REWARD_TERMS:
        dt = control_dt_s if name in DENSE_TERMS else 1.0
        out[name] = terms[name] * float(scales[name]) * dt * float(overall)
    return out


def total_reward(terms: dict[str, jax.Array], only_positive: bool, valid: jax.Array) -> jax.Array:
    """The step reward from scaled terms: dense sum (clipped at 0 if ``only_positive``) + sparse.

    ``only_positive`` is legged_gym's ``only_positive_rewards`` ("avoids early termination
    problems"): the dense terms can make a step worth nothing but never negative, so a policy
    learning to walk is not paid less than one standing still for each stumble; the sparse
    ``reach`` and ``termination`` are added after the clip (as legged_gym adds
    termination).

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
    missing = sorted(set(REWARD_TERMS) - keys)  # every term (saved run configs: read migrated)
    if unknown:
        raise ValueError(f"unknown reward term(s) {unknown}; valid terms: {list(REWARD_TERMS)}")
    if missing:
        raise ValueError(
            f"reward.scales is missing term(s) {missing}; valid terms: {list(REWARD_TERMS)}"
        )
