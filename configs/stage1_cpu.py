"""Stage 1 sized for a 2-core CPU, continuing from the flat-ground policy (the training campaign).

Differs from stage1.py in: the CPU network of cpu.py / flat.py (LSTM 64, heads (128, 64)) so that
it starts from the shipped flat policy (policies/flat; the critic's new height-scan inputs start
with zero weights, see foottof/ppo/storage/checkpoint.py), 512 envs x 40-step rollouts (20,480
samples per update; the truncated-backprop window of 0.8 s covers the ~0.6-0.75 s between what a front-foot
sensor sees and where a hind foot lands), a 10 x 10 map whose columns follow the evaluation
ensemble's types (grid 3, two-row 2, mixed-row 3, platform gap 2; no boxes: they are not in the
ensemble), checkpoints every 10 iterations (a few minutes on 2 cores), a long run meant to be
continued in chunks with --resume, and the action std capped at 0.4 (network.max_noise_std: with
a learned std of 0.67 an earlier campaign policy fell in 36 % of its episodes on the easiest tiles,
without noise in 10 %). Terrain, sensors, noise, rewards and PPO are otherwise stage 1's. The
recipe and what was measured for it: docs/campaign.md.
"""

from configs import base


def get_config():
    c = base.get_config()
    c.stage = 1  # terrain mix and degradation uppers of stage 1
    c.terrain.num_levels = 10  # curriculum levels (stage1.py: 10)
    c.terrain.num_cols = 10  # columns split by stage1_weights below
    c.terrain.stage1_weights.grid_stones = 0.3  # 3 columns
    c.terrain.stage1_weights.two_row_stones = 0.2  # 2 columns
    c.terrain.stage1_weights.rough_boxes = 0.0  # not in the evaluation ensemble
    c.terrain.stage1_weights.platform_gap = 0.2  # 2 columns
    c.terrain.stage1_weights.mixed_row_stones = 0.3  # 3 columns
    c.env.critic_height_scan = True  # privileged base-centred height scan for the critic
    c.ppo.num_envs = 512  # parallel envs (CPU; 1024 runs at the same env-steps/s)
    c.ppo.num_steps = 40  # rollout = truncated-backprop window: 0.8 s
    c.ppo.num_minibatches = 4  # minibatches per epoch (128 envs each)
    c.ppo.num_epochs = 4  # passes over each rollout
    c.network.lstm_hidden_size = 64  # LSTM units (cpu.py's: policies/flat's shape)
    c.network.actor_hidden = (128, 64)  # actor MLP head
    c.network.critic_hidden = (128, 64)  # critic MLP head
    c.train.num_iterations = 10000  # 10000 x 512 x 40 = 205M env steps, run in --resume chunks
    c.train.checkpoint_every = 10  # checkpoint every N iterations
    c.network.max_noise_std = 0.4  # cap on the action std (stage1.py: no cap)
    c.ppo.learning_rate = 2e-4  # start where the adaptive rule settled (1e-3 moved the flat
    # policy by KL 0.78 in its first update)
    c.train.init_from = "policies/flat"  # flat-ground policy: params + normalizer
    c.train.run_name = "stage1_cpu"  # run directory name under train.run_root
    return c
