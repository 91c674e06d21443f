"""Base configuration shared by train.py and evaluate.py; stage files import it and change what differs."""

import ml_collections

from configs import _env, _eval, _ppo, _reward, _sensor, _terrain


def get_config() -> ml_collections.ConfigDict:
    c = ml_collections.ConfigDict()
    c.seed = 0  # PRNG seed of the run
    c.stage = 1  # training stage (1 or 2): selects terrain mix, sensor degradation, initial poses
    c.terrain = _terrain.get_section()  # terrain map and curriculum
    c.sensor = _sensor.get_section()  # foot ToF sensor geometry and timing
    c.noise = _sensor.get_noise_section()  # sensor degradation upper bounds and delay
    c.env = _env.get_section()  # robot, episode, observations, randomization
    c.reward = _reward.get_section()  # reward scales (reward.scales.<term>)
    c.ppo = _ppo.get_section()  # PPO hyper-parameters
    c.network = _ppo.get_network_section()  # LSTM actor-critic sizes
    c.train = _ppo.get_train_section()  # run dir, logging, checkpoints
    c.eval = _eval.get_section()  # evaluation ensemble and sweeps
    c.train.run_name = "run"  # run directory name: <train.run_root>/<train.run_name>
    c.train.init_from = ""  # run dir / checkpoint to initialize params from ("" = none)
    return c
