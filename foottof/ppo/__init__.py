"""LSTM trainer: networks, algorithms (PPO, distillation), train (make_train), runner, storage/,
export, toy_envs.

Nothing is imported here, so `foottof.ppo.export.NumpyPolicy` loads without JAX.
"""
