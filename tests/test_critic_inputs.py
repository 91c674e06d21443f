"""The critic's privileged height scan (env.critic_height_scan) and init_from a run without it."""

import os

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import REPO, hfield_mj_model

from configs import flat
from foottof.envs.observations import critic_height_scan, critic_scan_points
from foottof.ppo.networks import make_networks
from foottof.ppo.storage import checkpoint as ckpt
from foottof.terrain import Heightfield

FLAT_POLICY = os.path.join(REPO, "policies", "flat")
ACTOR_OBS, CRITIC_OBS = 181, 223  # policies/flat's observation sizes (its checkpoint manifest)


def _mj_ray_heights(hf: Heightfield, xy: np.ndarray) -> np.ndarray:
    """Oracle: MuJoCo C's mj_ray straight down onto the hfield geom at each (x, y) [m]."""
    m, d = hfield_mj_model(hf)
    top = hf.z_floor_m + hf.z_range_m + 1.0
    geomid = np.zeros(1, np.int32)
    out = []
    for x, y in xy:
        dist = mujoco.mj_ray(
            m, d, np.array([x, y, top]), np.array([0.0, 0.0, -1.0]), None, 1, -1, geomid
        )
        out.append(top - dist)
    return np.asarray(out)


def test_height_scan_matches_mj_ray_on_a_turned_base():
    rng = np.random.default_rng(0)
    heights = rng.uniform(-0.6, 0.3, (60, 70)).astype(np.float32)
    hf = Heightfield(heights=jp.asarray(heights), cell_m=0.04, z_floor_m=-1.0, z_range_m=2.0)
    base = np.array([1.4, 1.2, 0.45])
    yaw, pitch = 0.7, 0.2  # the scan turns with the heading only (pitch is ignored)
    quat = np.zeros(4)
    mujoco.mju_euler2Quat(quat, np.array([0.0, pitch, yaw]), "xyz")
    scan = np.asarray(critic_height_scan(hf.height_at, jp.asarray(base), jp.asarray(quat)))
    pts = np.asarray(critic_scan_points())
    assert scan.shape == pts.shape[:1] == (171,)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    heading = np.arctan2(mat[3], mat[0])  # MuJoCo's rotation of the base x axis, turned flat
    c, s = np.cos(heading), np.sin(heading)
    world = base[:2] + pts @ np.array([[c, -s], [s, c]]).T
    expected = np.clip(_mj_ray_heights(hf, world) - base[2], -1.0, 1.0)
    np.testing.assert_allclose(scan, expected, atol=2e-4)
    # 1.2 m ahead of the base along its heading is the scan's far end.
    assert np.isclose(pts[:, 0].max(), 1.2) and np.isclose(pts[:, 0].min(), -0.6)


def test_critic_sees_the_scan_and_the_actor_does_not():
    from foottof.envs import make_env

    cfg = flat.get_config()
    cfg.terrain.num_levels, cfg.terrain.num_cols = 1, 1
    sizes = make_env(cfg).observation_size
    cfg.env.critic_height_scan = True
    with_scan = make_env(cfg).observation_size
    assert with_scan["state"] == sizes["state"] == ACTOR_OBS
    assert with_scan["privileged_state"] == sizes["privileged_state"] + 171 == CRITIC_OBS + 171


@pytest.mark.skipif(not os.path.isdir(FLAT_POLICY), reason="policies/flat not shipped")
def test_init_from_a_run_without_the_scan_keeps_its_value_function():
    """Loading policies/flat into a critic with 171 more inputs: the actor is the saved one and
    the value of any observation does not depend on the new inputs (their weights start at 0):
    it equals the saved critic's value on the observation without them."""
    cfg = flat.get_config()
    nets = make_networks(12, cfg.network)
    obs_old = {"state": jp.zeros((1, ACTOR_OBS)), "privileged_state": jp.zeros((1, CRITIC_OBS))}
    obs_new = {**obs_old, "privileged_state": jp.zeros((1, CRITIC_OBS + 171))}
    key = jax.random.PRNGKey(0)
    norm = lambda obs: jax.tree.map(jp.asarray, nets.init_normalizer(obs))  # noqa: E731
    p_old, n_old = ckpt.load_params_and_normalizer(
        FLAT_POLICY, nets.init_params(key, obs_old), norm(obs_old)
    )
    p_new, n_new = ckpt.load_params_and_normalizer(
        FLAT_POLICY, nets.init_params(key, obs_new), norm(obs_new)
    )
    rng = np.random.default_rng(1)
    a = jp.asarray(rng.normal(size=(5, ACTOR_OBS)), jp.float32)
    c = jp.asarray(rng.normal(size=(5, CRITIC_OBS)), jp.float32)
    scan = jp.asarray(rng.uniform(-1, 1, size=(5, 171)), jp.float32)
    reset = jp.ones(5, bool)
    carry = nets.init_carry(5)
    _, mean_old, _, v_old = nets.step(
        p_old, n_old, carry, {"state": a, "privileged_state": c}, reset
    )
    obs = {"state": a, "privileged_state": jp.concatenate([c, scan], axis=-1)}
    _, mean_new, _, v_new = nets.step(p_new, n_new, carry, obs, reset)
    np.testing.assert_array_equal(np.asarray(mean_new), np.asarray(mean_old))
    np.testing.assert_allclose(np.asarray(v_new), np.asarray(v_old), rtol=1e-6, atol=1e-6)
    # The new normalizer entries: mean 0, std 1 (variance 1 over the saved count).
    np.testing.assert_array_equal(np.asarray(n_new.mean["privileged_state"][CRITIC_OBS:]), 0.0)
    np.testing.assert_array_equal(np.asarray(n_new.std["privileged_state"][CRITIC_OBS:]), 1.0)
    # The actor may not grow: a mismatch there is still an error naming the leaf.
    obs_bad = {**obs_old, "state": jp.zeros((1, ACTOR_OBS + 3))}
    with pytest.raises(ValueError, match=r"memory_a"):
        ckpt.load_params_and_normalizer(FLAT_POLICY, nets.init_params(key, obs_bad), norm(obs_bad))
    # ... unless asked (init_from into env.actor_terrain, a teacher from a sensor-only policy):
    # the 153 terrain inputs start with zero weight, so the actor acts as the saved one whatever
    # they read.
    obs_t = {**obs_old, "state": jp.zeros((1, ACTOR_OBS + 153))}
    p_t, n_t = ckpt.load_params_and_normalizer(
        FLAT_POLICY, nets.init_params(key, obs_t), norm(obs_t), grow_actor=True
    )
    terrain = jp.asarray(rng.uniform(-1, 1, size=(5, 153)), jp.float32)
    obs = {"state": jp.concatenate([a, terrain], axis=-1), "privileged_state": c}
    _, mean_t, _, v_t = nets.step(p_t, n_t, carry, obs, reset)
    np.testing.assert_array_equal(np.asarray(mean_t), np.asarray(mean_old))
    np.testing.assert_array_equal(np.asarray(n_t.std["state"][ACTOR_OBS:]), 1.0)
