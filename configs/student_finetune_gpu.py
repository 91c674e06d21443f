"""PPO fine-tuning of the distilled ToF student at GPU scale: the GPU teacher's task, rollout and
PPO (configs/teacher_gpu.py: 4096 envs, 5 epochs, the size-first stone curriculum) for the
student of configs/distill_gpu.py, started from that run (train.init_from: its params,
normalizer and the teacher's critic it carries). The last step of the GPU pipeline.

Built on configs/teacher_cpu.py (a config chain holds at most three files) with
configs/teacher_gpu.py's fields repeated; tests/test_gpu_check.py holds it equal to
teacher_gpu.py but for these fields:
- env.actor_terrain True -> False: the student reads the sensors only.
- network.reconstruct 0 -> 36: the student's belief decoder (configs/distill_cpu.py), kept, not
  trained by PPO.
- reward.guidance_decay_*_iteration 62 / 187 -> 0 / 1: the bias is off from the first iteration;
  the student has learned the task from its teacher, the bias would only pay speed again (as in
  the CPU fine-tuning of the earlier student: docs/campaign.md).
- train.init_from policies/teacher -> runs/distill_gpu, the distilled student.
The rewards stay the teacher's (the foot-edge price too): the task the student imitated.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    # GPU scale: configs/teacher_gpu.py's fields
    c.terrain.stone_curriculum = "size_first"  # stones shrink first (the default since 12-07)
    c.ppo.num_envs = 4096  # parallel envs (teacher_cpu: 512)
    c.ppo.num_epochs = 5  # passes over each rollout (teacher_cpu: 4)
    c.train.num_iterations = 1250  # 1250 x 4096 x 40 = 205M env steps
    c.train.checkpoint_every = 50  # checkpoint every N iterations (~8M env steps)
    # the student
    c.env.actor_terrain = False  # the student reads the sensors only (teacher_gpu: True)
    c.network.reconstruct = 36  # the student's decoder (configs/distill_cpu.py): kept, not trained
    c.reward.guidance_decay_start_iteration = 0
    c.reward.guidance_decay_end_iteration = 1  # weight 0 from the first iteration on
    c.train.init_from = "runs/distill_gpu"  # the distilled student (run or policy folder)
    c.train.run_name = "student_finetune_gpu"  # run directory name under train.run_root
    return c
