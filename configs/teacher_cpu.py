"""The privileged teacher of the distillation recipe, sized for 2 cores.

configs/stage1_arrive_cpu.py (the anchors' goal-reaching task, started from policies/flat) with
env.actor_terrain: the actor also reads the true terrain heights around each foot (4 x 9) and a
base scan up to 0.6 m ahead (117 points), the extent the front feet's ToF sensors have covered,
so that a ToF student can infer what its teacher acts on. The network is the student's LSTM
(64 units): it starts from the flat policy's gait (new inputs with zero weights) instead of
learning to walk again, and the student that imitates it has the same shape. Issue "A privileged
teacher and its distillation"; results: docs/campaign.md.
"""

from configs import stage1_arrive_cpu


def get_config():
    c = stage1_arrive_cpu.get_config()
    c.env.actor_terrain = True  # the actor sees the terrain (true heights)
    c.train.run_name = "teacher_cpu"  # run directory name under train.run_root
    return c
