"""Distillation of the foot-edge teacher (configs/teacher_wide_edge_cpu.py, shipped as
policies/teacher_wide_edge; the best teacher on the ensemble, 0.160 at 4260) into the ToF
student: configs/distill_wide_cpu.py with that teacher. Same student shape (network.obs_skip, an
actor head of 512-256, cut from the teacher's actor), same belief decoder and rsl_rl settings.

The run pins its teacher (teacher.json); when policies/teacher_wide_edge is shipped at a later
checkpoint, resume with --config.train.teacher_change_ok=True to follow it (the old one is kept
under ``previous``) or --config.train.teacher=FOLDER/checkpoints/N to stay. Issue "A privileged
teacher and its distillation"; results: docs/campaign.md.
"""

from configs import distill_wide_cpu


def get_config():
    c = distill_wide_cpu.get_config()
    c.train.teacher = (
        "policies/teacher_wide_edge"  # a run or policy folder of the foot-edge teacher
    )
    c.train.run_name = "distill_wide_edge_cpu"
    return c
