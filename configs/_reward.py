"""Reward section: named terms and their scales (reward.scales.<term>), logged as reward/<term>."""

import ml_collections


def get_section() -> ml_collections.ConfigDict:
    r = ml_collections.ConfigDict()
    r.success_radius_m = 0.5  # ending within this distance of the goal is a success [m]
    r.guidance_max_speed_mps = 1.0  # dense guidance saturates at this speed toward the goal [m/s]
    r.guidance_peaked = False  # True: above guidance_max_speed_mps the guidance falls (2 vmax - v)
    r.guidance_goal_pay = True  # guidance pays its full rate within the success radius
    r.guidance_decay_start_iteration = 0  # guidance weight 1 until this training iteration ...
    r.guidance_decay_end_iteration = 0  # ... then linearly to 0 here (0: no decay) [iterations]
    r.task_window_s = 2.0  # task term: paid only in the last seconds of the episode [s]
    r.stall_toward_goal = False  # stall counts speed toward the goal (True) or any speed [-]
    r.stall_speed_mps = 0.1  # below this speed while far from the goal counts as stalling [m/s]
    r.stall_grace_s = 2.0  # no stall penalty during the first seconds of an episode [s]
    r.jump_grace_s = 0.2  # no jump penalty while the spawn drop lands [s]
    r.edge_radius_m = 0.04  # foot_edge: terrain sampled this far from the foot centre [m]
    r.edge_height_m = 0.05  # foot_edge: height spread of those samples that makes an edge [m]
    r.clearance_target_m = 0.12  # foot_clearance: swing height asked of moving feet [m]
    r.overspeed_mps = 0.6  # overspeed: horizontal base speed above this is penalized [m/s]
    r.overall_scale = 1.0  # multiplies every scaled term: value targets' size, not the pricing
    r.only_positive = True  # clip the dense sum at 0 per step; reach/termination added after [-]
    s = ml_collections.ConfigDict()
    s.reach = 10.0  # sparse: +1 at the last step if within success_radius_m of the goal
    s.guidance = (
        5.0  # dense: base velocity toward the goal, clipped at guidance_max_speed_mps [per s]
    )
    s.task = 0.0  # dense: 1 / (task_window_s (1 + d^2)) in the last task_window_s, d the goal
    # distance [m]; the window pays 1 / (1 + d^2) x scale in all (0 = off) [per s]
    s.termination = (
        -1.0
    )  # sparse: 1 on a failure termination (fall, base contact, flip, divergence)
    s.timeout = 0.0  # sparse: 1 at the time limit outside success_radius_m (0 = off)
    s.torques = -1e-5  # sum of squared joint torques [(N m)^2]
    s.joint_acc = -2.5e-7  # sum of squared joint accelerations [(rad/s^2)^2]
    s.action_rate = -0.01  # sum of squared action differences between control steps
    s.foot_slip = -0.05  # sum over feet in contact of squared horizontal foot speed [(m/s)^2]
    s.orientation = -1.0  # squared norm of the horizontal part of projected gravity
    s.stall = -0.5  # 1 while stalling (slow and not within success radius) after the grace period
    s.jump = -1.0  # 1 while all four feet are off the ground (no foot within the contact margin)
    s.posture = (
        -0.5
    )  # after reaching the goal: sum of squared deviations from the default pose [rad^2]
    s.collision = -1.0  # number of knee spheres touching the terrain (not a termination) [per s]
    s.foot_edge = 0.0  # number of feet touching the terrain at a height step (0 = off) [per s]
    s.foot_clearance = 0.0  # moving feet below clearance_target_m: sum tanh(2|v|) shortfall^2
    # (0 = off, and not computed) [m^2 per s]
    s.overspeed = 0.0  # horizontal base speed above overspeed_mps (0 = off) [(m/s) per s]
    r.scales = s
    return r


def arrive(c) -> None:
    """The anchors' goal-reaching task (Rudin et al. 2022, arXiv 2209.12827; Zhang et al. 2024,
    arXiv 2311.10484), set on the full config ``c`` in place: a task reward paid only in the last
    2 s (arriving early earns nothing more), a guidance bias that pays progress up to 0.6 m/s and
    decays to zero over training iterations 500-1500, a stall penalty on progress (slow toward
    the goal, not slow), a fall priced above the whole task reward, no clip of the dense sum and
    a discount that sees the window from the stones. The pricing of each figure, with the
    measured success and fall rates: docs/campaign.md ("Stones, third round: pricing")."""
    r = c.reward
    r.only_positive = False  # the dense sum is negative once the bias is gone: keep its penalties
    r.task_window_s = 2.0  # Zhang et al.'s T_r (Rudin et al.: 1 s)
    r.guidance_goal_pay = False  # nothing paid for standing at the goal early
    r.guidance_max_speed_mps = 0.6  # the bias pays progress up to 0.6 m/s (the paper: 0.52 m/s)
    r.guidance_decay_start_iteration = 500  # 10.2M env steps at 512 x 40
    r.guidance_decay_end_iteration = 1500  # 30.7M env steps: the bias is gone
    r.stall_toward_goal = True  # walking about on the start platform is stalling
    r.stall_speed_mps = 0.2  # Zhang et al.'s "don't wait" threshold
    s = r.scales
    s.task = 10.0  # the window pays 10 / (1 + d^2) in all: 10 at the goal, 8 at 0.5 m
    s.reach = 0.0  # the task term pays arriving
    s.guidance = 2.0  # bias: at most 1.2 per s (0.6 m/s toward the goal)
    s.termination = -15.0  # above the task's 10, below what makes a try worse than a refusal
    s.stall = -2.0  # per s: refusing costs ~17 over an episode
    # Returns of -15 to +10 give value losses ~100x the old task's (~0.5), and one gradient-norm
    # clip spans actor and critic: scale the reward as a whole so the value loss stays ~0.5.
    r.overall_scale = 0.1
    c.ppo.gamma = 0.998  # the window 6.7-8.7 s after the stones is weighted 0.51-0.42 (0.99: 0.03)
