"""The privileged teacher with its action std capped at 0.25 instead of 0.4 (configs/teacher_cpu.py).

Why: the learned std has sat at stage1_cpu.py's cap of 0.4 since the start (the raw parameter
drifts just above it, so the cap freezes it). At the plain teacher's frontier (2330, stone level
6, 200 episodes, seed 4242) its mean actions succeed 0.555 of the time, actions sampled at std
0.4 only 0.305, at 0.25 0.495 and at 0.15 0.565: the curriculum, which promotes on sampled
episodes, holds it about a level below what its mean policy does. Branched from
policies/teacher (2330) side by side with the plain teacher's continuation; issue "A privileged
teacher and its distillation"; results: docs/campaign.md.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    c.network.max_noise_std = 0.25  # cap on the action std (teacher_cpu.py: 0.4)
    c.train.run_name = "teacher_lowstd_cpu"  # run directory name under train.run_root
    return c
