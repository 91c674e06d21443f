"""The task's settings (TaskSpec), read once from the config: what every phase of the env's step reads."""

from __future__ import annotations

import dataclasses

from foottof.envs.randomization import RandomizationSpec
from foottof.envs.rewards import RewardSpec


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """The task's settings, read once from the config (``TaskSpec.from_config(cfg)``); every
    phase of the step reads these, not the config (a complete one: a configs/ file, or a saved
    run config read migrated, renames.read_saved_config)."""

    clip_actions: float
    kp: float
    kd: float
    max_joint_speed_rads: float
    contact_margin_m: float
    clip_reward: float
    bootstrap_time_limit: bool
    body_contact_margin_m: float
    knee_contact_terminates: bool
    fall_height_above_floor_m: float
    foot_fall_z_m: float
    foot_stuck_depth_m: float
    max_tilt_deg: float
    down_progress_frac: float
    up_progress_frac: float
    no_promotion_on_fall: bool
    init_level_max: int
    init_joint_noise_rad: float
    init_roll_pitch_rad: float
    spawn_height_offset_m: float
    clip_observations: float
    critic_height_scan: bool
    actor_terrain: bool
    actor_terrain_seen: bool  # the teacher's terrain only where a foot ray has hit (+ flags)
    actor_terrain_fine: bool  # the teacher's terrain also 5 cm apart (envs.fine_terrain)
    steps_per_iteration: int  # control steps each env takes per training iteration
    reward: RewardSpec  # the reward section (terms, scales, success radius, guidance decay)
    randomization: RandomizationSpec  # the env.randomization section

    @classmethod
    def from_config(cls, cfg) -> TaskSpec:
        e, t = cfg.env, cfg.terrain
        return cls(
            clip_actions=float(e.clip_actions),
            kp=float(e.control.kp),
            kd=float(e.control.kd),
            max_joint_speed_rads=float(e.max_joint_speed_rads),
            contact_margin_m=float(e.contact_margin_m),
            clip_reward=float(e.clip_reward),
            bootstrap_time_limit=bool(e.bootstrap_time_limit),
            body_contact_margin_m=float(e.body_contact_margin_m),
            knee_contact_terminates=bool(e.knee_contact_terminates),
            fall_height_above_floor_m=float(e.fall_height_above_floor_m),
            foot_fall_z_m=float(e.foot_fall_z_m),
            foot_stuck_depth_m=float(e.foot_stuck_depth_m),
            max_tilt_deg=float(e.max_tilt_deg),
            down_progress_frac=float(t.down_progress_frac),
            up_progress_frac=float(t.up_progress_frac),
            no_promotion_on_fall=bool(t.no_promotion_on_fall),
            init_level_max=int(t.init_level_max),
            init_joint_noise_rad=float(e.init_joint_noise_rad),
            init_roll_pitch_rad=float(e.init_roll_pitch_rad),
            spawn_height_offset_m=float(e.spawn_height_offset_m),
            clip_observations=float(e.clip_observations),
            critic_height_scan=bool(e.critic_height_scan),
            actor_terrain=bool(e.actor_terrain),
            actor_terrain_seen=bool(e.actor_terrain_seen),
            actor_terrain_fine=bool(e.actor_terrain_fine),
            steps_per_iteration=int(cfg.ppo.num_steps),
            reward=RewardSpec.from_config(cfg.reward),
            randomization=RandomizationSpec.from_config(e.randomization),
        )
