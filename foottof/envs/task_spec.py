"""The task's settings (TaskSpec), read once from the config: what every phase of the env's step reads."""

from __future__ import annotations

import dataclasses

from foottof.renames import added_default


@dataclasses.dataclass(frozen=True)
class TaskSpec:
    """The task's settings, read once from the config (``TaskSpec.from_config(cfg)``); every
    phase of the step reads these, not the config."""

    clip_actions: float
    randomize: bool
    push_vel_mps: float
    kp: float
    kd: float
    max_joint_speed_rads: float
    contact_margin_m: float
    edge_radius_m: float
    edge_height_m: float
    clip_reward: float
    only_positive: bool
    success_radius_m: float
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
    stretch_prob: float
    stretch_min_level: int
    init_level_max: int
    init_joint_noise_rad: float
    init_roll_pitch_rad: float
    spawn_height_offset_m: float
    clip_observations: float
    critic_height_scan: bool
    actor_terrain: bool
    guidance_decay: tuple[int, int]  # (start, end) training iteration; end 0: no decay
    steps_per_iteration: int  # control steps each env takes per training iteration

    @classmethod
    def from_config(cls, cfg) -> TaskSpec:
        e, t = cfg.env, cfg.terrain
        return cls(
            clip_actions=float(e.clip_actions),
            randomize=bool(e.randomization.enabled),
            push_vel_mps=float(e.randomization.push_vel_mps),
            kp=float(e.control.kp),
            kd=float(e.control.kd),
            max_joint_speed_rads=float(e.max_joint_speed_rads),
            contact_margin_m=float(e.contact_margin_m),
            edge_radius_m=float(cfg.reward.edge_radius_m),
            edge_height_m=float(cfg.reward.edge_height_m),
            clip_reward=float(e.clip_reward),
            only_positive=bool(cfg.reward.only_positive),
            success_radius_m=float(cfg.reward.success_radius_m),
            bootstrap_time_limit=bool(e.bootstrap_time_limit),
            body_contact_margin_m=float(e.body_contact_margin_m),
            knee_contact_terminates=bool(e.knee_contact_terminates),
            fall_height_above_floor_m=float(e.fall_height_above_floor_m),
            foot_fall_z_m=float(e.foot_fall_z_m),
            foot_stuck_depth_m=float(e.get("foot_stuck_depth_m", 0.0)),
            max_tilt_deg=float(e.max_tilt_deg),
            down_progress_frac=float(t.down_progress_frac),
            up_progress_frac=float(t.up_progress_frac),
            no_promotion_on_fall=bool(t.get("no_promotion_on_fall", False)),
            stretch_prob=float(t.get("stretch_prob", added_default("terrain.stretch_prob"))),
            stretch_min_level=int(
                t.get("stretch_min_level", added_default("terrain.stretch_min_level"))
            ),
            init_level_max=int(t.init_level_max),
            init_joint_noise_rad=float(e.init_joint_noise_rad),
            init_roll_pitch_rad=float(e.init_roll_pitch_rad),
            spawn_height_offset_m=float(e.spawn_height_offset_m),
            clip_observations=float(e.clip_observations),
            critic_height_scan=bool(e.get("critic_height_scan", False)),
            actor_terrain=bool(e.get("actor_terrain", added_default("env.actor_terrain"))),
            guidance_decay=_guidance_decay(cfg.reward),
            steps_per_iteration=int(cfg.ppo.num_steps),
        )


def _guidance_decay(rcfg) -> tuple[int, int]:
    """(start, end) iterations of the guidance bias decay (end 0: none), checked."""
    start = int(
        rcfg.get(
            "guidance_decay_start_iteration",
            added_default("reward.guidance_decay_start_iteration"),
        )
    )
    end = int(
        rcfg.get(
            "guidance_decay_end_iteration", added_default("reward.guidance_decay_end_iteration")
        )
    )
    if end > 0 and not 0 <= start < end:
        raise ValueError(
            f"reward.guidance_decay_start_iteration={start} must be in [0, "
            f"reward.guidance_decay_end_iteration={end}) when the decay is on (end > 0)"
        )
    return start, end
