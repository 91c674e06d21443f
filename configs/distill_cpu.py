"""Distil the privileged teacher (configs/teacher_cpu.py) into the ToF student by DAgger.

The student is configs/stage1_arrive_cpu.py's policy (sensors only, LSTM 64): the env is stepped
with its sampled actions, and it learns the teacher's action means (foottof/ppo/distill.py). It
starts cut from the teacher (actor without the terrain inputs, the teacher's critic), so
fine-tuning it with PPO (configs/student_finetune_cpu.py) starts from a trained critic.
`train.teacher` is the teacher's run or policy folder.
"""

from configs import stage1_arrive_cpu


def get_config():
    c = stage1_arrive_cpu.get_config()
    c.train.teacher = "policies/teacher"  # a run or policy folder trained with env.actor_terrain
    c.train.init_from = ""  # the student is cut from the teacher (distill.student_from_teacher)
    c.ppo.lr_schedule = "fixed"  # no KL to adapt to (rsl_rl's distillation: a fixed rate)
    c.ppo.learning_rate = 5e-4
    c.ppo.num_epochs = 2  # passes over each rollout (rsl_rl's distillation: 1)
    c.train.run_name = "distill_cpu"
    return c
