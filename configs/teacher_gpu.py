"""The privileged teacher at GPU scale: configs/teacher_cpu.py on 4096 envs, started from
policies/teacher (train.init_from) on the size-first stone curriculum, as the CPU run
configs/experiments/teacher_stones_cpu.py does on 512 envs. The first step of the GPU pipeline
(then configs/distill_gpu.py, configs/student_finetune_gpu.py); bench/gpu_check.py trains it.

What differs from the CPU teacher, and why (anchors: legged_gym's ANYmal rough task and Isaac
Lab's ANYmal-D rough task on rsl_rl: 4096 envs, 24 steps, 5 epochs, 4 minibatches, 512-256-128
actor and critic, 1500 iterations saved every 50):
- ppo.num_envs 512 -> 4096, the anchors' count.
- ppo.num_epochs 4 -> 5, the anchors' passes over each rollout.
- train.num_iterations 10000 -> 1250: 1250 x 4096 x 40 = 205M env steps, the CPU run's budget.
- train.checkpoint_every 10 -> 50, the anchors' save interval (~8M env steps here).
- reward.guidance_decay_*_iteration 500 / 1500 -> 62 / 187: the CPU schedule in env steps
  (10.2M / 30.7M; an iteration holds 8x the CPU's env steps).
Kept from the CPU teacher: ppo.num_steps 40 (the anchors: 24; a 0.8 s truncated-backprop window
covers the time from what a front foot's sensor sees to where a hind foot lands,
configs/stage1_cpu.py), so a minibatch holds 40,960 samples (the anchors: 24,576); 4 minibatches;
the 10 x 10 map whose columns follow the evaluation ensemble; and the network (LSTM 64, obs_skip,
actor 512-256, critic 128-64): init_from restores the saved layers, a wider actor head at most
(foottof.ppo.storage.input_growth), so the anchors' third layer or wider critic would not start as
the saved policy, and the CPU run can take this run's parameters back.
"""

from configs import teacher_cpu


def get_config():
    c = teacher_cpu.get_config()
    c.terrain.stone_curriculum = "size_first"  # stones shrink first (the default since 12-07)
    c.ppo.num_envs = 4096  # parallel envs (teacher_cpu: 512)
    c.ppo.num_epochs = 5  # passes over each rollout (teacher_cpu: 4)
    c.reward.guidance_decay_start_iteration = 62  # 10.2M env steps, as the CPU's 500
    c.reward.guidance_decay_end_iteration = 187  # 30.7M env steps, as the CPU's 1500
    c.train.num_iterations = 1250  # 1250 x 4096 x 40 = 205M env steps
    c.train.checkpoint_every = 50  # checkpoint every N iterations (~8M env steps)
    c.train.init_from = "policies/teacher"  # the CPU teacher: params + normalizer
    c.train.run_name = "teacher_gpu"  # run directory name under train.run_root
    return c
