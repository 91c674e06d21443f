"""Helpers shared by the test modules: tiny trainer configs, pytree equality, a CLI runner."""

import os
import subprocess
import sys

import jax
import ml_collections
import mujoco
import numpy as np

from configs import _ppo

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def small_cfg(policy: str = "lstm", **ppo) -> ml_collections.ConfigDict:
    cfg = ml_collections.ConfigDict()
    cfg.seed = 0
    cfg.ppo = _ppo.get_section()
    cfg.network = _ppo.get_network_section()
    cfg.train = _ppo.get_train_section()
    cfg.ppo.num_envs = 64
    cfg.ppo.num_steps = 16
    cfg.ppo.num_minibatches = 2
    cfg.ppo.num_epochs = 4
    cfg.ppo.entropy_coef = 0.0
    cfg.ppo.update(ppo)
    cfg.network.policy = policy
    cfg.network.lstm_hidden_size = 32
    cfg.network.actor_hidden = (32,)
    cfg.network.critic_hidden = (32,)
    cfg.train.tensorboard = True
    return cfg


def tiny_cfg(**train) -> ml_collections.ConfigDict:
    cfg = small_cfg(num_envs=8, num_steps=4, num_epochs=2)
    cfg.network.lstm_hidden_size = 8
    cfg.network.actor_hidden = (8,)
    cfg.network.critic_hidden = (8,)
    cfg.train.update(train)
    return cfg


def tree_equal(a, b) -> bool:
    eq = jax.tree.map(lambda x, y: bool(np.array_equal(np.asarray(x), np.asarray(y))), a, b)
    return all(jax.tree.leaves(eq)) and jax.tree.structure(a) == jax.tree.structure(b)


def run_cli(script: str, *args: str, timeout: int = 600) -> subprocess.CompletedProcess:
    """Runs ``python <script> args`` from the repo root on the CPU; returns the finished process
    (text stdout / stderr)."""
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    return subprocess.run(
        [sys.executable, os.path.join(REPO, script), *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
    )


def hfield_mj_model(hf, geom_attrs: str = "", bodies: str = "", option: str = ""):
    """(MjModel, MjData after mj_forward) of heightfield ``hf`` alone or with ``bodies`` (MJCF
    <body> elements), its heights written in: the MuJoCo C oracle of the terrain tests."""
    from foottof.terrain.heightfield import hfield_xml, write_to_mjmodel

    asset, geom = hfield_xml(hf, geom_attrs=geom_attrs)
    m = mujoco.MjModel.from_xml_string(
        f"<mujoco>{option}<asset>{asset}</asset><worldbody>{geom}{bodies}</worldbody></mujoco>"
    )
    write_to_mjmodel(m, hf)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    return m, d
