"""Stage 1 sized for a 2-core CPU, continuing from the flat-ground policy (the training campaign).

Differs from stage1.py in: the CPU network of cpu.py / flat.py (LSTM 64, heads (128, 64)) so that
it starts from the shipped flat policy (policies/flat), 256 envs, a 10 x 10 map (two columns per
stage-1 type), checkpoints every 25 iterations (a few minutes on 2 cores), a long run meant to be
continued in chunks with --resume, and the action std capped at 0.4 (network.max_noise_std, from
iteration 2826 of the campaign on: the learned std had risen to 0.67, and with that noise the
policy of iteration 2675 fell in 36 % of its episodes on the easiest tiles, without it in 10 %).
Terrain, sensors, noise, rewards and PPO are otherwise stage 1's.
"""

from configs import cpu


def get_config():
    c = cpu.get_config()  # stage 1 + the CPU network
    c.terrain.num_levels = 10  # curriculum levels (stage1.py: 10)
    c.terrain.num_cols = 10  # two columns per stage-1 type
    c.ppo.num_envs = 256  # parallel envs (CPU)
    c.train.num_iterations = 16000  # 16000 x 256 x 24 = 98M env steps, run in --resume chunks
    c.train.checkpoint_every = 25  # checkpoint every N iterations
    c.network.max_noise_std = 0.4  # cap on the action std (stage1.py: no cap)
    c.train.init_from = "policies/flat"  # flat-ground policy: params + normalizer
    c.train.run_name = "stage1_cpu"  # run directory name under train.run_root
    return c
