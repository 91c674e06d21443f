"""Flat ground: the stage-1 task, observations and CPU-sized network of cpu.py on flat tiles.

The learning check of the pipeline (``make learn``): walking to a goal ~4.7 m away within 10 s,
with the same sensors, noise, randomization, rewards and LSTM as stage 1, but every tile flat
(``terrain.flat``), so success measures the task and the trainer rather than the terrain.
Differs from cpu.py in: flat tiles, 128 envs, initial action std 0.5, a longer run.
"""

from configs import cpu


def get_config():
    c = cpu.get_config()
    c.terrain.flat = True  # every tile flat at z = 0
    c.ppo.num_envs = 128  # parallel envs (CPU)
    c.network.init_noise_std = 0.5  # initial action std: std 1 with kp 150 mostly stumbles
    c.train.num_iterations = 2000  # 2000 x 128 x 24 = 6.1M env steps
    c.train.checkpoint_every = 25  # checkpoint every N iterations (~1 min on 2 cores)
    c.train.run_name = "flat"  # run directory name under train.run_root
    return c
