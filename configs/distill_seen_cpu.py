"""Distillation of the seen teacher (configs/teacher_seen_cpu.py, shipped as
policies/teacher_seen) into the ToF student: configs/distill_belief_cpu.py (belief decoder,
rsl_rl's settings) with that teacher. The teacher's terrain inputs are true only where a foot
ray has hit, so it acts on nothing its student's sensors cannot have seen; the decoder
reconstructs its (masked) foot patches. The env is built with the teacher's env.actor_terrain_seen
from its run config. Issue "A privileged teacher and its distillation"; results: docs/campaign.md.
"""

from configs import distill_belief_cpu


def get_config():
    c = distill_belief_cpu.get_config()
    c.train.teacher = "policies/teacher_seen"  # a run or policy folder of a seen teacher
    c.train.run_name = "distill_seen_cpu"
    return c
