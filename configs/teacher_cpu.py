"""The privileged teacher (policies/teacher), sized for 2 cores: stage 1 (configs/stage1_cpu.py) on
the goal-reaching task, an actor that also reads the terrain through wide heads, and a price on
feet at a stone's edge.

- Task (Rudin et al. 2022, arXiv 2209.12827; Zhang et al. 2024, arXiv 2311.10484): the task
  reward is paid only in the last 2 s, a guidance bias pays progress up to 0.6 m/s and decays to
  zero over iterations 500-1500, a stall penalty on progress toward the goal, a fall priced above
  the whole task reward, no clip of the dense sum, gamma 0.998.
- Actor inputs (env.actor_terrain): the true terrain heights around each foot (4 x 9) and a base
  scan up to 0.6 m ahead (117 points), the extent the front feet's ToF sensors have covered, so
  that a ToF student (configs/distill_cpu.py) can infer what its teacher acts on.
- Network: the student's LSTM (64 units, policies/flat's gait), heads that read the observation
  beside the LSTM (network.obs_skip) and an actor head of 512-256 (legged_gym: 512-256-128).
- reward.scales.foot_edge -2 per foot per s at a terrain height step (Extreme Parkour's
  ``feet_edge``): stuck feet landed a median 4.5 cm past a stone's rim.

The pricing of each figure, the lineage (plain -> wide -> foot edge, from policies/flat) and
what was measured: docs/campaign.md.
"""

from configs import stage1_cpu


def get_config():
    c = stage1_cpu.get_config()
    r = c.reward
    r.only_positive = False  # the dense sum is negative once the bias is gone: keep its penalties
    r.task_window_s = 2.0  # Zhang et al.'s T_r (Rudin et al.: 1 s)
    r.guidance_goal_pay = False  # nothing paid for standing at the goal early
    r.guidance_max_speed_mps = 0.6  # the bias pays progress up to 0.6 m/s (the paper: 0.52 m/s)
    r.guidance_decay_start_iteration = 500  # 10.2M env steps at 512 x 40
    r.guidance_decay_end_iteration = 1500  # 30.7M env steps: the bias is gone
    r.stall_toward_goal = True  # walking about on the start platform is stalling
    r.stall_speed_mps = 0.2  # Zhang et al.'s "don't wait" threshold
    r.scales.task = 10.0  # the window pays 10 / (1 + d^2) in all: 10 at the goal, 8 at 0.5 m
    r.scales.reach = 0.0  # the task term pays arriving
    r.scales.guidance = 2.0  # bias: at most 1.2 per s (0.6 m/s toward the goal)
    r.scales.termination = -15.0  # above the task's 10, below making a try worse than a refusal
    r.scales.stall = -2.0  # per s: refusing costs ~17 over an episode
    r.scales.foot_edge = -2.0  # per foot per s at a height step: ~-1.5 per episode
    # Returns of -15 to +10 give value losses ~100x the old task's (~0.5), and one gradient-norm
    # clip spans actor and critic: scale the reward as a whole so the value loss stays ~0.5.
    r.overall_scale = 0.1
    c.ppo.gamma = 0.998  # the window 6.7-8.7 s after the stones is weighted 0.51-0.42 (0.99: 0.03)
    c.env.actor_terrain = True  # the actor sees the terrain (true heights)
    c.network.obs_skip = True  # heads read [LSTM output, normalized observation]
    c.network.actor_hidden = (512, 256)  # stage1_cpu: (128, 64)
    c.train.run_name = "teacher_cpu"  # run directory name under train.run_root
    return c
