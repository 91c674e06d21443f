"""LSTM PPO trainer: networks, losses, train (make_train), checkpoint, runner, export, toy_envs.

Nothing is imported here, so `foottof.ppo.export.NumpyPolicy` loads without JAX.
"""
