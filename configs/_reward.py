"""Reward section: named terms and their scales (reward.scales.<term>), logged as reward/<term>."""

import ml_collections


def get_section() -> ml_collections.ConfigDict:
    r = ml_collections.ConfigDict()
    r.success_radius_m = 0.5  # ending within this distance of the goal is a success [m]
    r.guidance_max_speed_mps = 1.0  # dense guidance saturates at this speed toward the goal [m/s]
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
    s.overspeed = 0.0  # horizontal base speed above overspeed_mps (0 = off) [(m/s) per s]
    r.scales = s
    return r
