"""The teacher's fine terrain inputs (env.actor_terrain_fine, foottof.envs.fine_terrain).

Oracles: MuJoCo C's mj_ray straight down on the heightfield geom, hand-counted grids, MuJoCo's
own rotation of the base heading; the mirror checked on a terrain and its mirror image."""

import os

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from brax.training.acme import running_statistics
from helpers import REPO
from test_critic_inputs import _mj_ray_heights

from configs import teacher_cpu
from foottof.config_check import ConfigError, check_config
from foottof.envs import fine_terrain as ft
from foottof.envs import observations as obs_lib
from foottof.envs.symmetry import make_mirror
from foottof.ppo import checkpoint as ckpt
from foottof.ppo.networks import make_networks
from foottof.ppo.teacher import student_view_size
from foottof.terrain import Heightfield

TEACHER = os.path.join(REPO, "policies", "teacher")


def test_fine_points_fill_the_5cm_grids_between_the_10cm_samples():
    # 5 x 5 patch at 5 cm minus the 3 x 3 at 10 cm = 16; 25 x 17 scan minus 13 x 9 = 308
    assert ft.PATCH_OFFSETS.shape == (16, 2) and ft.SCAN_POINTS.shape == (308, 2)
    assert ft.NUM_INPUTS == 4 * 16 + 308 == 372
    coarse_patch = np.asarray(obs_lib.FOOT_PATCH_OFFSETS_M)
    both = np.round(np.concatenate([coarse_patch, ft.PATCH_OFFSETS]) / 0.05).astype(int)
    assert sorted(map(tuple, both)) == [(i, j) for i in range(-2, 3) for j in range(-2, 3)]
    coarse_scan = np.asarray(obs_lib.critic_scan_points())[: obs_lib.ACTOR_SCAN_POINTS]
    both = np.round(np.concatenate([coarse_scan, ft.SCAN_POINTS]) / 0.05).astype(int)
    assert sorted(map(tuple, both)) == [(i, j) for i in range(-12, 13) for j in range(-8, 9)]


def test_fine_heights_match_mj_ray_on_a_turned_base():
    rng = np.random.default_rng(3)
    heights = rng.uniform(-0.5, 0.3, (70, 80)).astype(np.float32)
    hf = Heightfield(heights=jp.asarray(heights), cell_m=0.04, z_floor_m=-1.0, z_range_m=2.0)
    base = np.array([1.5, 1.3, 0.5])
    quat = np.zeros(4)
    mujoco.mju_euler2Quat(quat, np.array([0.1, 0.15, -0.9]), "xyz")
    feet = np.array([[1.8, 1.5, 0.0], [1.8, 1.1, 0.02], [1.2, 1.5, -0.03], [1.2, 1.1, 0.05]])
    out = np.asarray(ft.fine_terrain(hf.height_at, jp.asarray(feet), jp.asarray(base), quat))
    assert out.shape == (372,)
    patch_xy = (feet[:, None, :2] + ft.PATCH_OFFSETS[None]).reshape(-1, 2)
    expect_patch = _mj_ray_heights(hf, patch_xy) - np.repeat(feet[:, 2], 16)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    heading = np.arctan2(mat[3], mat[0])
    c, s = np.cos(heading), np.sin(heading)
    world = base[:2] + ft.SCAN_POINTS @ np.array([[c, -s], [s, c]]).T
    expect_scan = _mj_ray_heights(hf, world) - base[2]
    np.testing.assert_allclose(out[:64], np.clip(expect_patch, -1, 1), atol=2e-4)
    np.testing.assert_allclose(out[64:], np.clip(expect_scan, -1, 1), atol=2e-4)


def test_fine_block_mirrors_with_the_terrain():
    """The block read by a robot on a terrain equals, mirrored, the block read by its mirror
    image (feet swapped, y negated) on the mirrored terrain; the map is its own inverse."""
    perm, sign = ft.mirror_perm()
    np.testing.assert_array_equal(perm[perm], np.arange(372))
    rng = np.random.default_rng(5)
    heights = rng.uniform(-0.4, 0.2, (61, 61)).astype(np.float32)
    cell = 0.05
    # centred on y = 0: grid row i at y = (i - 30) cell; the mirror flips the rows
    hf = Heightfield(heights=jp.asarray(heights), cell_m=cell, z_floor_m=-1.0, z_range_m=2.0)
    hf_m = Heightfield(
        heights=jp.asarray(heights[::-1].copy()), cell_m=cell, z_floor_m=-1.0, z_range_m=2.0
    )
    y0 = 30 * cell
    # Every sample lies on a grid line x = k cell, along which MuJoCo's triangulated surface
    # interpolates linearly: elsewhere its triangle split (diagonal (i, j) -> (i+1, j+1)) is not
    # mirror-symmetric. The heading's rotation is checked against MuJoCo above.
    base = np.array([1.4, y0 + 0.07, 0.5])
    quat = quat_m = np.array([1.0, 0.0, 0.0, 0.0])
    feet = np.array([[1.7, y0 + 0.3, 0.0], [1.7, y0 - 0.2, 0.01], [1.1, y0 + 0.25, 0.0],
                     [1.1, y0 - 0.15, 0.02]])  # fmt: skip

    def mirror_y(p):
        q = np.array(p, dtype=np.float64)
        q[..., 1] = 2 * y0 - q[..., 1]
        return q

    feet_m = mirror_y(feet)[[1, 0, 3, 2]]
    a = np.asarray(ft.fine_terrain(hf.height_at, jp.asarray(feet), jp.asarray(base), quat))
    b = np.asarray(
        ft.fine_terrain(hf_m.height_at, jp.asarray(feet_m), jp.asarray(mirror_y(base)), quat_m)
    )
    np.testing.assert_allclose(a[perm] * sign, b, atol=1e-5)
    assert np.std(a) > 0.05  # the terrain is not flat: a wrong permutation would show


def test_teacher_config_with_the_fine_block():
    cfg = teacher_cpu.get_config()
    cfg.env.actor_terrain_fine = True
    check_config(cfg)
    mirror = make_mirror(cfg)
    assert mirror.obs["state"].size == 181 + 153 + 372
    assert student_view_size(181 + 153 + 372, fine=True) == 181
    cfg.env.actor_terrain_seen = True
    with pytest.raises(ConfigError, match="env.actor_terrain_fine"):
        check_config(cfg)
    cfg.env.actor_terrain_seen, cfg.env.actor_terrain = False, False
    with pytest.raises(ConfigError, match="env.actor_terrain_fine"):
        check_config(cfg)


def test_env_appends_the_fine_block_after_the_10cm_one():
    from foottof.envs import make_env
    from foottof.robot import kinematics

    cfg = teacher_cpu.get_config()
    cfg.terrain.num_levels, cfg.terrain.num_cols = 2, 2
    cfg.env.actor_terrain_fine = True
    env = make_env(cfg)
    n = 181 + 153  # the teacher's inputs before the block (4 sensors x 16 zones)
    assert env.observation_size["state"] == n + 372
    assert env.observation_size["privileged_state"] == 223 + 171
    s = jax.jit(env.reset)(jax.random.PRNGKey(4))
    q = s.pipeline_state.qpos
    fk = kinematics.world_foot_kinematics(q, env.shank_scale)
    patches = obs_lib.foot_patches(env.hfield.height_at, fk.foot_pos)
    np.testing.assert_allclose(np.asarray(s.obs["state"][181:217]), np.asarray(patches), atol=1e-6)
    want = ft.fine_terrain(env.hfield.height_at, fk.foot_pos, q[0:3], q[3:7])
    np.testing.assert_allclose(np.asarray(s.obs["state"][n:]), np.asarray(want), atol=1e-6)


def _stats(mean, std, count=1e8):
    mean, std = jp.asarray(mean, jp.float32), jp.asarray(std, jp.float32)
    return running_statistics.RunningStatisticsState(
        count=jp.asarray(count, jp.float32),
        mean={"state": mean},
        std={"state": std},
        summed_variance={"state": std**2 * count},
    )


def test_seed_normalizer_copies_the_nearest_10cm_sample():
    n = 181 + 153
    rng = np.random.default_rng(0)
    mean = np.concatenate([rng.normal(size=n), np.zeros(372)])
    std = np.concatenate([rng.uniform(0.1, 2, size=n), np.ones(372)])
    out, seeded = ft.seed_normalizer(_stats(mean, std))
    assert seeded
    got_mean, got_std = np.asarray(out.mean["state"]), np.asarray(out.std["state"])
    np.testing.assert_array_equal(got_mean[:n], mean[:n].astype(np.float32))
    # hand-picked: LF's fine point (-0.1, -0.05) sits between coarse (-0.1, -0.1) and (-0.1, 0):
    # the lower index, patch entry 0; the scan's fine point (-0.55, -0.4) -> coarse (-0.6, -0.4)
    # = scan entry 0 (36 in the block); RH's (0.1, 0.05) -> its (0.1, 0.0) = 3 * 9 + 7
    assert np.isclose(got_mean[n], mean[181 + 0])
    i_scan = n + 64 + int(np.flatnonzero(np.all(np.isclose(ft.SCAN_POINTS, [-0.55, -0.4]), 1))[0])
    assert np.isclose(got_std[i_scan], std[181 + 36])
    i_rh = n + 3 * 16 + int(np.flatnonzero(np.all(np.isclose(ft.PATCH_OFFSETS, [0.1, 0.05]), 1))[0])
    assert np.isclose(got_mean[i_rh], mean[181 + 3 * 9 + 7])
    # a trained normalizer (its fine entries already moved) is left as it is
    again, seeded = ft.seed_normalizer(out)
    assert not seeded and again is out


@pytest.mark.skipif(not os.path.isdir(TEACHER), reason="policies/teacher not shipped")
def test_init_from_the_teacher_acts_as_it_whatever_the_fine_block_reads():
    cfg = teacher_cpu.get_config()
    nets = make_networks(12, cfg.network)
    n_act, n_crit = 181 + 153, 223 + 171
    obs_old = {"state": jp.zeros((1, n_act)), "privileged_state": jp.zeros((1, n_crit))}
    obs_new = {**obs_old, "state": jp.zeros((1, n_act + 372))}
    key = jax.random.PRNGKey(0)
    norm = lambda obs: jax.tree.map(jp.asarray, nets.init_normalizer(obs))  # noqa: E731
    p_old, n_old = ckpt.load_params_and_normalizer(
        TEACHER, nets.init_params(key, obs_old), norm(obs_old)
    )
    p_new, n_new = ckpt.load_params_and_normalizer(
        TEACHER, nets.init_params(key, obs_new), norm(obs_new), grow_actor=True
    )
    n_new, seeded = ft.seed_normalizer(n_new)
    assert seeded
    rng = np.random.default_rng(1)
    a = jp.asarray(rng.normal(size=(5, n_act)), jp.float32)
    c = jp.asarray(rng.normal(size=(5, n_crit)), jp.float32)
    fine = jp.asarray(rng.uniform(-1, 1, size=(5, 372)), jp.float32)
    reset, carry = jp.ones(5, bool), nets.init_carry(5)
    _, m_old, _, v_old = nets.step(p_old, n_old, carry, {"state": a, "privileged_state": c}, reset)
    obs = {"state": jp.concatenate([a, fine], -1), "privileged_state": c}
    _, m_new, _, v_new = nets.step(p_new, n_new, carry, obs, reset)
    np.testing.assert_allclose(np.asarray(m_new), np.asarray(m_old), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(np.asarray(v_new), np.asarray(v_old), rtol=1e-6, atol=1e-6)
