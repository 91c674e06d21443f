"""Tiny config used by the tests: a 2-level map, 8 envs, a tiny LSTM."""

from configs import base


def get_config():
    c = base.get_config()
    c.terrain.num_levels = 2  # levels of the tiny map
    c.terrain.num_cols = 5  # one column per stage-1 type
    c.ppo.num_envs = 8  # parallel envs
    c.ppo.num_steps = 8  # rollout length [control steps]
    c.ppo.num_minibatches = 2  # minibatches per epoch
    c.ppo.num_epochs = 2  # passes over each rollout
    c.network.lstm_hidden_size = 16  # LSTM units
    c.network.actor_hidden = (32,)  # actor MLP head
    c.network.critic_hidden = (32,)  # critic MLP head
    c.train.num_iterations = 2  # iterations
    c.train.checkpoint_every = 1  # checkpoint every iteration
    c.train.tensorboard = False  # CSV only
    c.train.run_name = "smoke"  # run directory name under train.run_root
    return c
