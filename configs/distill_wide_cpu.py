"""Distillation of the wide teacher (configs/teacher_wide_cpu.py, shipped as policies/teacher_wide)
into the ToF student: configs/distill_belief_cpu.py (belief decoder, rsl_rl's settings) with
that teacher, and the student shaped as the teacher's actor (network.obs_skip, an actor head of
512-256) so that it starts cut from it (distill.student_from_teacher drops the terrain rows of the
LSTM input kernels and of the heads' observation rows: the heads read [h, obs], the terrain
inputs last). Issue "A privileged teacher and its distillation"; results: docs/campaign.md.
"""

from configs import distill_belief_cpu


def get_config():
    c = distill_belief_cpu.get_config()
    c.train.teacher = "policies/teacher_wide"  # a run or policy folder of the wide teacher
    c.network.obs_skip = True  # as the teacher: heads read [LSTM output, normalized observation]
    c.network.actor_hidden = (512, 256)  # as the teacher (distill_belief_cpu: 128-64)
    c.train.run_name = "distill_wide_cpu"
    return c
