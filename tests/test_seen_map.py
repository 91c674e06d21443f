"""env.actor_terrain_seen: the teacher's terrain inputs only where a foot ToF ray has hit.

Oracles: hand-computed cells of a small grid; MuJoCo C (mj_kinematics for the sensor sites,
mj_rayHfield for the ray hits) for the cells an episode's rays have hit.
"""

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import hfield_mj_model

from configs import smoke
from foottof import constants
from foottof.envs import make_env
from foottof.envs.seen_map import SeenGrid
from foottof.sensors import tof
from foottof.terrain import Heightfield


def test_seen_grid_marks_and_reads_hand_computed_cells():
    g = SeenGrid(cell_m=0.1, back_m=1.0, ahead_m=2.0, half_width_m=0.5)
    assert g.shape == (30, 10)
    origin, seen = g.init(jp.array([3.0, 4.0]))
    np.testing.assert_allclose(origin, [2.0, 3.5])  # spawn - (back, half width)
    pts = jp.array(
        [
            [2.05, 3.55, 0.3],  # cell (0, 0)
            [4.99, 4.49, 0.0],  # cell (29, 9), the far corner
            [5.01, 4.00, 0.0],  # beyond ahead_m: outside, dropped
            [2.55, 3.85, 0.0],  # cell (5, 3), but not ok
        ]
    )
    seen = g.mark(origin, seen, pts, jp.array([True, True, True, False]))
    expected = np.zeros((30, 10), bool)
    expected[0, 0] = expected[29, 9] = True
    np.testing.assert_array_equal(seen, expected)
    queries = jp.array(
        [
            [2.09, 3.59],  # cell (0, 0): seen
            [4.91, 4.41],  # cell (29, 9): seen
            [2.55, 3.85],  # cell (5, 3): not marked
            [1.99, 3.55],  # behind the grid: never seen
            [5.01, 4.00],  # ahead of it: never seen (not the clipped edge cell)
        ]
    )
    np.testing.assert_array_equal(g.lookup(origin, seen, queries), [1, 1, 0, 0, 0])
    # batched like the env: one grid per env
    origins, grids = jax.vmap(g.init)(jp.array([[3.0, 4.0], [0.0, 0.0]]))
    grids = jax.vmap(g.mark, in_axes=(0, 0, None, None))(origins, grids, pts, jp.ones(4, bool))
    assert grids[0].sum() == 3 and grids[1].sum() == 0  # (0, 0), (29, 9), (5, 3); none at 0, 0
    with pytest.raises(ValueError, match="cell_m=0.0"):
        SeenGrid(cell_m=0.0)


def test_ray_hits_are_mujoco_hits_within_range_over_a_pit():
    """sense_and_hits: each ray's hit point and flag are mj_ray's on the hfield geom, and a ray
    whose hit lies beyond the 1 m range (down into a 1.2 m pit) is no hit."""
    heights = np.zeros((40, 40), np.float32)
    heights[:, 20:] = -1.2  # a pit from x = 0.8 m on
    hf = Heightfield(heights=jp.asarray(heights), cell_m=0.04, z_floor_m=-1.5, z_range_m=2.0)
    m, d = hfield_mj_model(hf)
    spec = tof.ToFSpec.from_config(smoke.get_config().sensor)
    site_pos = jp.array([[0.5, 0.8, 0.1], [0.78, 0.8, 0.12], [0.9, 0.5, 0.2], [1.2, 1.0, 0.05]])
    tilt = np.deg2rad(20.0)  # site z (the sensor axis) down, pitched a little; axes as columns
    rot = np.array([[np.cos(tilt), 0, np.sin(tilt)], [0, 1, 0], [-np.sin(tilt), 0, np.cos(tilt)]])
    rot = rot @ np.diag([1.0, -1.0, -1.0])
    site_rot = jp.asarray(np.broadcast_to(rot, (4, 3, 3)), jp.float32)
    _, points, hit = tof.sense_and_hits(spec, hf, site_pos, site_rot)
    pos, dirs = (np.asarray(x, np.float64) for x in tof.sensor_rays(spec, site_pos, site_rot))
    geomid = np.zeros(1, np.int32)
    for f in range(4):
        for r in range(dirs.shape[1]):
            dist = mujoco.mj_ray(m, d, pos[f], dirs[f, r], None, 1, -1, geomid)
            ok = 0 <= dist <= spec.max_range_m
            assert bool(hit[f, r]) == ok, (f, r, dist)
            if ok:
                np.testing.assert_allclose(points[f, r], pos[f] + dist * dirs[f, r], atol=2e-4)
    assert 0 < int(hit.sum()) < hit.size  # the pit's rays miss, the ground's hit


def _cfg(seen: bool):
    c = smoke.get_config()
    c.env.actor_terrain = True
    c.env.actor_terrain_seen = seen
    return c


def _oracle_cells(env, qpos, origin) -> set:
    """Cells of the grid at ``origin`` hit by every foot sensor's rays at pose ``qpos``: sites by
    mj_kinematics, hits by mj_rayHfield on the terrain geom (within the 1 m range)."""
    m, d = env.mj_model, mujoco.MjData(env.mj_model)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    sites = [m.site(n).id for n in constants.TOF_SITES]
    spec = env.sensing.spec
    pos, dirs = tof.sensor_rays(
        spec, jp.asarray(d.site_xpos[sites]), jp.asarray(d.site_xmat[sites].reshape(-1, 3, 3))
    )
    pos, dirs = np.asarray(pos, np.float64), np.asarray(dirs, np.float64)
    terrain = m.geom("terrain").id
    g = env.seen_grid
    nx, ny = g.shape
    cells = set()
    for f in range(pos.shape[0]):
        for r in range(dirs.shape[1]):
            dist = mujoco.mj_rayHfield(m, d, terrain, pos[f], dirs[f, r])
            if 0 <= dist <= spec.max_range_m:
                p = pos[f] + dist * dirs[f, r]
                i, j = np.floor((p[:2] - origin) / g.cell_m).astype(int)
                if 0 <= i < nx and 0 <= j < ny:
                    cells.add((int(i), int(j)))
    return cells


@pytest.mark.integration
def test_seen_cells_are_mujoco_ray_hits_and_the_teacher_reads_heights_only_there():
    """Walking with random actions beside a plain teacher's env (same draws):

    - each env's grid holds exactly the cells that MuJoCo C's rays from the four foot sensors
      hit at every step since its episode began (a done clears it; a seen cell stays seen);
    - the seen teacher's observation is the plain teacher's, its terrain heights replaced by the
      nominal flat ground where unseen, followed by the seen flags."""
    cfg_a, cfg_b = _cfg(False), _cfg(True)
    for c in (cfg_a, cfg_b):
        c.env.episode_length_s = 0.3  # 15 steps: every episode ends once within the 24
    plain, env = make_env(cfg_a), make_env(cfg_b)
    n, steps, own = 3, 24, 181  # the ToF student's inputs come first in both
    keys = jax.random.split(jax.random.PRNGKey(3), n)
    sa, state = jax.jit(jax.vmap(plain.reset))(keys), jax.jit(jax.vmap(env.reset))(keys)
    step_a, step = jax.jit(jax.vmap(plain.step)), jax.jit(jax.vmap(env.step))
    fill = np.concatenate([np.full(36, -env.foot_radius_m), np.full(117, -env._stand_height)])
    qpos = [np.asarray(state.pipeline_state.qpos, np.float64)]
    done = [np.zeros(n, bool)]
    prev = np.asarray(state.info["seen"][1])
    akey, seen_frac = jax.random.PRNGKey(4), []
    for _ in range(steps):
        akey, k = jax.random.split(akey)
        act = 0.8 * jax.random.normal(k, (n, 12))
        sa, state = step_a(sa, act), step(state, act)
        qpos.append(np.asarray(state.pipeline_state.qpos, np.float64))
        done.append(np.asarray(state.done) > 0)
        a, b = np.asarray(sa.obs["state"]), np.asarray(state.obs["state"])
        assert a.shape[-1] == own + 153 and b.shape[-1] == own + 306
        np.testing.assert_array_equal(a[:, :own], b[:, :own])
        flags = b[:, own + 153 :]
        assert set(np.unique(flags)) <= {0.0, 1.0}
        heights, on = b[:, own : own + 153], flags > 0
        np.testing.assert_array_equal(heights[on], a[:, own : own + 153][on])
        np.testing.assert_allclose(heights[~on], np.broadcast_to(fill, heights.shape)[~on], 1e-6)
        seen_frac.append(on.mean())
        grid = np.asarray(state.info["seen"][1])
        assert (grid[~done[-1]] >= prev[~done[-1]]).all()  # a seen cell stays seen
        prev = grid
    assert 0 < np.mean(seen_frac) < 0.5  # some of the teacher's points seen, most not
    assert all(np.any(dn) for dn in np.array(done).T)  # each env's grid was cleared once
    origin, grid = (np.asarray(x) for x in state.info["seen"])
    spawn = np.asarray(state.info["task"].spawn[:, :2])
    g = env.seen_grid
    np.testing.assert_allclose(origin, spawn - [g.back_m, g.half_width_m], atol=1e-6)
    total_mismatch, total = 0, 0
    for e in range(n):
        first = max(k for k in range(steps + 1) if k == 0 or done[k][e])
        cells = set()
        for k in range(first, steps + 1):
            cells |= _oracle_cells(env, qpos[k][e], origin[e].astype(np.float64))
        got = {(int(i), int(j)) for i, j in zip(*np.nonzero(grid[e]), strict=True)}
        total_mismatch += len(cells ^ got)  # float32 vs float64 at a cell border
        total += len(cells)
    assert total > 150  # the swinging feet's rays swept more than the stance footprints
    assert total_mismatch <= 0.02 * total, (total_mismatch, total)


def test_seen_needs_a_teacher_and_the_student_drops_the_flags(tmp_path):
    """env.actor_terrain_seen without env.actor_terrain is one error naming both; a student of a
    seen teacher (its run config says so) reads the teacher's inputs less the 306 terrain ones."""
    import json

    from foottof.config_check import ConfigError, check_config
    from foottof.ppo.teacher import student_view_size, teacher_sees_only_seen

    c = smoke.get_config()
    c.env.actor_terrain_seen = True
    with pytest.raises(ConfigError, match="env.actor_terrain_seen=True.*env.actor_terrain=True"):
        check_config(c)
    c.env.actor_terrain = True
    check_config(c)
    assert student_view_size(181 + 306, 0, seen=True) == 181
    assert student_view_size(181 + 306, 36, seen=True) == 181 + 36
    assert student_view_size(181 + 153, 0) == 181
    (tmp_path / "config.json").write_text(json.dumps({"env": {"actor_terrain_seen": True}}))
    assert teacher_sees_only_seen(str(tmp_path))
    (tmp_path / "config.json").write_text(json.dumps({"env": {"actor_terrain": True}}))
    assert not teacher_sees_only_seen(str(tmp_path))  # a run saved before the field: plain
