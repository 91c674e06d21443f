"""Distil the privileged teacher (policies/teacher, configs/teacher_cpu.py) into the ToF student
(policies/student) by DAgger, sized for 2 cores.

The student reads the sensors only (no env.actor_terrain) on the teacher's task; the env is
stepped with its sampled actions and it learns the teacher's action means (foottof/ppo/distill.py).
It is shaped as the teacher's actor (network.obs_skip, a 512-256 head) and starts cut from it
(distill.student_from_teacher drops the terrain rows), with a belief decoder (Miki et al. 2022)
that reconstructs the teacher's foot patches (4 x 9 heights) beside the action loss, and
rsl_rl's distillation settings (std 0.1, Adam 1e-3 at a fixed rate, one pass).

The run pins its teacher (teacher.json): policies/student was distilled from the teacher at
checkpoint 4530, and policies/teacher now holds a later one; resume it with that checkpoint
restored (docs/campaign.md names the commit) or --config.train.teacher_change_ok=True to follow
the new one. Results: docs/campaign.md.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    c.env.actor_terrain = False  # the student reads the sensors only
    c.reward.scales.foot_edge = 0.0  # the teacher's price; DAgger pays no reward
    c.train.teacher = "policies/teacher"  # a run or policy folder trained with env.actor_terrain
    c.train.init_from = ""  # the student is cut from the teacher (distill.student_from_teacher)
    c.network.reconstruct = 36  # the teacher's foot patches (the first of its terrain inputs)
    c.ppo.reconstruction_weight = 0.5  # Miki et al. 2022: action loss + 0.5 x reconstruction
    c.network.max_noise_std = 0.1  # rsl_rl's StudentTeacherRecurrent: init_noise_std 0.1
    c.ppo.lr_schedule = "fixed"  # no KL to adapt to (rsl_rl's distillation: a fixed rate)
    c.ppo.learning_rate = 1e-3  # rsl_rl's Distillation
    c.ppo.num_epochs = 1  # passes over each rollout (rsl_rl's distillation: 1)
    c.train.run_name = "distill_cpu"  # run directory name under train.run_root
    return c
