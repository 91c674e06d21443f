"""Stage 1 on the anchors' goal-reaching task (configs/_reward.py `arrive`), sized for 2 cores.

configs/stage1_cpu.py (network, map, envs, rollout, start from policies/flat) with the reward of
Rudin et al. 2022 and Zhang et al. 2024: the task reward paid only in the last 2 s, a guidance
bias decayed to zero over iterations 500-1500, a stall penalty on progress toward the goal, a
termination penalty of 15 and gamma 0.998. Issue "Stones, third round"; pricing and results:
docs/campaign.md.
"""

from configs import _reward, stage1_cpu


def get_config():
    c = stage1_cpu.get_config()
    _reward.arrive(c)
    c.train.run_name = "stage1_arrive_cpu"  # run directory name under train.run_root
    return c
