"""The wide teacher with the foot-edge term (configs/teacher_wide_edge_cpu.py) and a quarter of
its envs acting at a quarter of the action std (ppo.low_noise_share, ppo.low_noise_scale).

Why: the wide teacher's mean action stands still half way along the course where its sampled
actions walk on (3800, 200 episodes, seed 4242: at difficulty 0.1 mean actions end 37 episodes
in a timeout at progress ~0.5, actions sampled at std 0.15 14, at the training std 0.4 5; at
0.36: 35 against 11 at std 0.15). The robot and evaluate.py run the mean action. The reward
already prices the stall (-2 per s stalling far from the goal, and the 2 s task window is
missed: about -27 unscaled for a stop half way against +8 to +10 for arriving, with or
without noise), but PPO learns from rollouts at std 0.4, which almost never stall (2-3 %
timeouts in training), so no gradient reaches the mean action's standstill. The quarter of
envs at std 0.1 visits it; their ratios are taken at their own std and their surrogate weighted
by 0.25 (foottof.ppo.losses.ppo_loss), and their episodes are logged as low_noise/episode/*.
Branched from policies/teacher_wide_edge (3920) side by side with the edge continuation; issue
"A privileged teacher and its distillation"; results: docs/campaign.md.
"""

from configs import teacher_wide_edge_cpu


def get_config():
    c = teacher_wide_edge_cpu.get_config()
    c.ppo.low_noise_share = 0.25  # a quarter of the envs (spread over the index and types)
    c.ppo.low_noise_scale = 0.25  # act at 0.25 x the std (0.1 at the 0.4 cap)
    c.train.run_name = "teacher_wide_edge_lownoise_cpu"  # run directory name under train.run_root
    return c
