"""CPU-sized config: a small map, 64 envs and a small LSTM, to see learning within minutes on CPU."""

from configs import base


def get_config():
    c = base.get_config()
    c.stage = 1  # stage-1 terrain mix
    c.terrain.num_levels = 4  # curriculum levels of the small map
    c.terrain.num_cols = 5  # one column per stage-1 type
    c.ppo.num_envs = 64  # parallel envs (CPU)
    c.ppo.num_steps = 24  # rollout length [control steps]
    c.ppo.num_minibatches = 4  # minibatches per epoch (16 envs each)
    c.ppo.num_epochs = 4  # passes over each rollout
    c.network.lstm_hidden_size = 64  # LSTM units
    c.network.actor_hidden = (128, 64)  # actor MLP head
    c.network.critic_hidden = (128, 64)  # critic MLP head
    c.train.num_iterations = 40  # ~ 60k env steps
    c.train.checkpoint_every = 10  # checkpoint every N iterations
    c.train.run_name = "cpu"  # run directory name under train.run_root
    return c
