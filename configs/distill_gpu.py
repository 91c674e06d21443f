"""Distillation at GPU scale: configs/distill_cpu.py (DAgger into the ToF student, belief decoder,
rsl_rl's distillation settings) on 4096 envs, from the GPU teacher (configs/teacher_gpu.py's run).
The second step of the GPU pipeline (then configs/student_finetune_gpu.py).

Built on configs/teacher_cpu.py, as distill_cpu.py is (a config chain holds at most three
files), with distill_cpu.py's student settings repeated below; tests/test_gpu_check.py holds the
two equal but for these fields (anchors: rsl_rl's distillation and legged_gym's ANYmal rough
task, 4096 envs):
- ppo.num_envs 512 -> 4096, the anchors' count.
- train.teacher policies/teacher -> runs/teacher_gpu, the teacher trained at this scale (the same
  network: the student is cut from either; --config.train.teacher=policies/teacher distils the
  CPU teacher).
- train.num_iterations 10000 -> 1250: 1250 x 4096 x 40 = 205M env steps, the CPU run's budget.
- train.checkpoint_every 10 -> 50, the anchors' save interval (~8M env steps here).
Kept: one pass over each rollout (rsl_rl's distillation; the anchors' PPO: 5), 4 minibatches of
40,960 samples, the 0.8 s window (ppo.num_steps 40), Adam 1e-3 at a fixed rate, the student's
network (the teacher's actor without its terrain inputs: LSTM 64, 512-256 head, obs_skip, a
36-height decoder), and the size-first stone curriculum (the default).
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    # the student and its distillation: configs/distill_cpu.py's fields
    c.env.actor_terrain = False  # the student reads the sensors only
    c.reward.scales.foot_edge = 0.0  # the teacher's price; DAgger pays no reward
    c.train.init_from = ""  # the student is cut from the teacher (distill.student_from_teacher)
    c.network.reconstruct = 36  # the teacher's foot patches (the first of its terrain inputs)
    c.ppo.reconstruction_weight = 0.5  # Miki et al. 2022: action loss + 0.5 x reconstruction
    c.network.max_noise_std = 0.1  # rsl_rl's StudentTeacherRecurrent: init_noise_std 0.1
    c.ppo.lr_schedule = "fixed"  # no KL to adapt to (rsl_rl's distillation: a fixed rate)
    c.ppo.learning_rate = 1e-3  # rsl_rl's Distillation
    c.ppo.num_epochs = 1  # passes over each rollout (rsl_rl's distillation: 1)
    # GPU scale
    c.ppo.num_envs = 4096  # parallel envs (distill_cpu: 512)
    c.train.teacher = "runs/teacher_gpu"  # the GPU teacher's run (distill_cpu: policies/teacher)
    c.train.num_iterations = 1250  # 1250 x 4096 x 40 = 205M env steps
    c.train.checkpoint_every = 50  # checkpoint every N iterations (~8M env steps)
    c.train.run_name = "distill_gpu"  # run directory name under train.run_root
    return c
