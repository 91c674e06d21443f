"""LSTM trainer: networks, algorithms (PPO, distillation), train (make_train), runner, storage/,
export (the toy envs its tests train on are in tests/toy_envs.py).

Nothing is imported here, so `foottof.ppo.export.NumpyPolicy` loads without JAX.
"""
