"""Tests of foottof.perception: cameras, ideal scan, aggregated map, odometry, mock readings."""

import math

import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest
from helpers import hfield_mj_model

from foottof import constants, perception
from foottof.perception import cameras as cam_lib
from foottof.perception import elevation_map as em
from foottof.perception import odometry as odom
from foottof.perception import sources
from foottof.robot import kinematics as kin
from foottof.sensors import tof
from foottof.terrain.heightfield import Heightfield
from foottof.terrain.tiles import TileSpec, generate_tile

SPEC = TileSpec()
DT = constants.CONTROL_DT_S
GROUND_REL = -0.59  # flat ground relative to a level base at nominal height [m]


def _tile_hf(heights) -> Heightfield:
    return Heightfield(
        heights=jp.asarray(heights, jp.float32),
        x0_m=0.0,
        y0_m=0.0,
        cell_m=SPEC.cell_m,
        z_floor_m=SPEC.pit_z_m,
        z_range_m=SPEC.z_range_m,
    )


@pytest.fixture(scope="module")
def stones_hf() -> Heightfield:
    """Grid stepping stones at 90 % difficulty (the evaluation's terrain)."""
    return _tile_hf(generate_tile("grid_stones", jax.random.key(7), 0.9))


def _quat(roll, pitch, yaw) -> np.ndarray:
    """ZYX Euler -> (w, x, y, z)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


# ----------------------------------------------------------------------------------- cameras


def test_camera_frustum_boundary_hand_computed():
    """front_lower: 0.42 m ahead, 0.06 m below the base, pitched 45 deg with a 58 deg vertical FoV,
    so its lowest ray is 45 + 29 = 74 deg below horizontal and meets ground 0.53 m below it at
    x = 0.42 + 0.53 / tan(74 deg) = 0.572 m. Its range is [0.3, 3] m."""
    cam = tuple(c for c in cam_lib.CAMERAS if c.name == "front_lower")
    x_edge = 0.42 + (-0.06 - GROUND_REL) / math.tan(math.radians(74.0))
    c45 = math.cos(math.radians(45.0))
    pts = jp.array(
        [
            [x_edge - 0.01, 0.0, GROUND_REL],  # just inside the blind zone
            [x_edge + 0.01, 0.0, GROUND_REL],  # just inside the view
            [0.42 + 2.95 * c45, 0.0, -0.06 - 2.95 * c45],  # on the optical axis, 2.95 m away
            [0.42 + 3.05 * c45, 0.0, -0.06 - 3.05 * c45],  # 3.05 m: beyond max range
            [0.42 + 0.25 * c45, 0.0, -0.06 - 0.25 * c45],  # 0.25 m: closer than min range
            [1.0, 0.0, 0.5],  # above the base: behind the frustum's upper edge
        ]
    )
    expected = [False, True, True, False, False, False]
    np.testing.assert_array_equal(cam_lib.visible(pts, cam), expected)


def test_camera_blind_zones_cover_belly_and_feet():
    """Flat ground under a level base: the belly and the four stance feet are unseen, the ground
    1.5 m ahead, behind and to the sides is seen, and far corners (> 3 m) are not."""
    fk_feet = [(0.495, 0.31), (0.495, -0.31), (-0.495, 0.31), (-0.495, -0.31), (0.0, 0.0)]
    blind = jp.array([[x, y, GROUND_REL] for x, y in fk_feet])
    seen = jp.array(
        [[1.5, 0, GROUND_REL], [-1.5, 0, GROUND_REL], [0, 1.2, GROUND_REL], [0, -1.2, GROUND_REL]]
    )
    far = jp.array([[2.45, 2.45, GROUND_REL]])
    assert not np.any(cam_lib.visible(blind))
    assert np.all(cam_lib.visible(seen))
    assert not np.any(cam_lib.visible(far))


def test_camera_bad_fov_raises():
    bad = (cam_lib.CAMERAS[0]._replace(hfov_deg=190.0),)
    with pytest.raises(ValueError, match="hfov_deg=190"):
        cam_lib.visible(jp.zeros((1, 3)), bad)


# ----------------------------------------------------------------------------- ideal scan


def test_height_scan_matches_mj_ray(stones_hf):
    """Vertical mj_ray on the compiled MuJoCo hfield at every scan vertex (rotated base)."""
    m, d = hfield_mj_model(stones_hf)
    base = np.array([3.0, 2.0, 0.6])
    yaw = 0.7
    scan = np.asarray(em.height_scan(stones_hf, jp.asarray(base, jp.float32), jp.float32(yaw)))
    xy = np.asarray(em.scan_xy())
    c, s = math.cos(yaw), math.sin(yaw)
    wx = base[0] + c * xy[..., 0] - s * xy[..., 1]
    wy = base[1] + s * xy[..., 0] + c * xy[..., 1]
    inside = (wx > 0.05) & (wx < SPEC.length_m - 0.1) & (wy > 0.05) & (wy < SPEC.width_m - 0.1)
    assert inside.sum() > 5000
    geomid = np.zeros(1, np.int32)
    errs = []
    for i, j in zip(*np.nonzero(inside), strict=True):
        dist = mujoco.mj_ray(
            m, d, np.array([wx[i, j], wy[i, j], 5.0]), np.array([0, 0, -1.0]), None, 1, -1, geomid
        )
        errs.append(abs((5.0 - dist) - (scan[i, j] + base[2])))
    assert max(errs) < 1e-4
    # The scan reads the 2 x 2 vertices with one gather; the four-gather lookup agrees exactly,
    # also on vertices and at and beyond the edges (clamped), of this and of a random terrain.
    rng = np.random.default_rng(0)
    rough = Heightfield(heights=jp.asarray(rng.uniform(0, 1, (37, 153)), jp.float32), cell_m=0.04)
    for hf in (stones_hf, rough):
        lo = np.array([hf.x0_m, hf.y0_m])
        hi = lo + 2 * np.array(hf.half_extents_m)
        pts = [rng.uniform(lo - 0.2, hi + 0.2, (4000, 2)), np.stack([wx, wy], -1).reshape(-1, 2)]
        pts += [lo + hf.cell_m * rng.integers(0, [hf.ncol, hf.nrow], (500, 2)), [lo, hi, hi + 1]]
        pts = jp.asarray(np.concatenate(pts), jp.float32)
        np.testing.assert_array_equal(hf.height_at(pts, True), hf.height_at(pts))


def test_scan_heightfield_bad_shape_raises():
    with pytest.raises(ValueError, match=r"\(\.\.\., 101, 101\)"):
        em.scan_heightfield(jp.zeros((100, 101)))


# ------------------------------------------------------------------- aggregated elevation map


def _walk(n_steps: int, v_fwd: float, yaw_rate: float, start=(2.0, 2.0, 0.6)):
    """A walking-like base trajectory integrated with 10 substeps per control step.

    Returns per step k = 1..n: true pos (n, 3), quat (n, 4), and the base-frame linear and angular
    velocities (n, 3) a perfect estimator would report at that step (finite differences).
    """
    sub = 10
    h = DT / sub
    t = np.arange(n_steps * sub + 1) * h
    yaw = yaw_rate * t
    vy = 0.1 * np.sin(2 * np.pi * 1.0 * t)
    vx_w = v_fwd * np.cos(yaw) - vy * np.sin(yaw)
    vy_w = v_fwd * np.sin(yaw) + vy * np.cos(yaw)
    x = start[0] + np.concatenate([[0], np.cumsum(vx_w[:-1] * h)])
    y = start[1] + np.concatenate([[0], np.cumsum(vy_w[:-1] * h)])
    z = start[2] + 0.02 * np.sin(2 * np.pi * 2.0 * t)
    roll = 0.03 * np.sin(2 * np.pi * 2.0 * t)
    pitch = 0.03 * np.cos(2 * np.pi * 2.0 * t)
    idx = np.arange(0, n_steps * sub + 1, sub)
    pos = np.stack([x, y, z], -1)[idx]
    quat = np.stack(
        [_quat(r, p, w) for r, p, w in zip(roll[idx], pitch[idx], yaw[idx], strict=True)]
    )
    rot = np.asarray(em.tilt_rotation(jp.asarray(quat)))  # (n+1, 3, 3) roll/pitch only
    rz = np.asarray(em._rot_z(jp.asarray(yaw[idx])))
    r_full = rz @ rot
    v_world = np.diff(pos, axis=0) / DT
    v_base = np.einsum("kji,kj->ki", r_full[1:], v_world)
    # Angular velocity from consecutive orientations: R_{k-1}^T R_k = exp([w] dt) (base frame).
    rel = np.einsum("kji,kjl->kil", r_full[:-1], r_full[1:])
    w_base = np.stack(
        [rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]], -1
    ) / (2 * DT)
    f32 = lambda a: jp.asarray(a, jp.float32)
    return f32(pos), f32(quat), f32(v_base), f32(w_base)


def _run_map(hf, traj, levels, keys, see_all=False):
    """Scan an elevation map along ``traj`` for each (level, key); returns final states and the
    ideal scan at the final pose. vmapped over the leading axis of levels/keys (one compile)."""
    pos, quat, v_base, w_base = traj

    def one(level, key):
        state = em.aggre_init(hf, pos[0], quat[0], see_all=see_all)

        def step(state, xs):
            p, q, v, w, k = xs
            v_est, w_est = odom.noisy_odometry(k, v, w, level)
            return em.aggre_update(state, hf, p, q, v_est, w_est, DT, see_all=see_all), None

        ks = jax.random.split(key, pos.shape[0] - 1)
        state, _ = jax.lax.scan(step, state, (pos[1:], quat[1:], v_base, w_base, ks))
        return state

    states = jax.jit(jax.vmap(one))(levels, keys)
    ideal = em.height_scan(hf, pos[-1], kin.yaw_from_quat(quat[-1]))
    return states, ideal


@pytest.fixture(scope="module")
def drift_runs(stones_hf):
    """Walk 0.8 s (40 steps) at 0.8 m/s, turning at 0.3 rad/s, at noise levels 0, 1, 2, 4 with
    5 seeds each."""
    traj = _walk(40, 0.8, 0.3)
    levels = np.repeat([0.0, 1.0, 2.0, 4.0], 5).astype(np.float32)
    keys = jax.random.split(jax.random.key(3), levels.size)
    states, ideal = _run_map(stones_hf, traj, jp.asarray(levels), keys)
    return levels, states, ideal


def test_drift_grows_with_odometry_noise(drift_runs):
    levels, states, ideal = drift_runs
    err, n = jax.vmap(em.memory_error, (0, None))(states, ideal)
    err = np.asarray(err)
    assert np.all(np.asarray(n) > 500)  # the blind zone under the robot is remembered
    means = [err[levels == lv].mean() for lv in (0.0, 1.0, 2.0, 4.0)]
    print("memory error by level 0/1/2/4 [m]:", means)
    assert np.all(np.diff(means) > 0.0), means
    assert means[0] < 0.03  # without noise only the 5 cm resampling error remains (~1.7 cm)
    assert means[3] > 3.0 * means[0]


def test_update_with_reset_equals_a_fresh_map(drift_runs, stones_hf):
    """aggre_update(..., reset=True) on a drifted map (4x odometry noise) is aggre_init at the new
    pose (the env restarts auto-reset episodes' maps this way): flags and indices exactly, heights
    to float rounding (< 0.1 mm, two differently fused programs); reset=False is the plain
    update."""
    _, states, _ = drift_runs
    drifted = jax.tree.map(lambda a: a[-1], states)
    pos, quat, _, _ = _walk(3, 0.8, 0.3)
    p, q = pos[2] + jp.array([0.3, -0.2, 0.0]), quat[2]
    v, w = jp.array([0.9, 0.1, 0.0]), jp.array([0.0, 0.0, 0.4])
    upd = jax.jit(em.aggre_update, static_argnames=("dt",))
    fresh = jax.jit(em.aggre_init)(stones_hf, p, q)
    got = upd(drifted, stones_hf, p, q, v, w, dt=DT, reset=jp.asarray(True))
    for name, a, b in zip(
        fresh.__dataclass_fields__, jax.tree.leaves(got), jax.tree.leaves(fresh), strict=True
    ):
        if np.issubdtype(np.asarray(a).dtype, np.floating):  # two compiles: rounding only
            np.testing.assert_allclose(a, b, atol=1e-4, rtol=0, err_msg=name)
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)
    plain = upd(drifted, stones_hf, p, q, v, w, dt=DT, reset=jp.asarray(False))
    ref = em.aggre_update(drifted, stones_hf, p, q, v, w, DT)
    np.testing.assert_allclose(plain.scan, ref.scan, atol=1e-4, rtol=0)
    np.testing.assert_allclose(plain.pose_est, ref.pose_est, atol=1e-6, rtol=0)
    assert np.abs(np.asarray(drifted.pose_est[:2])).max() > 0.1  # a real restart, not a no-op


def test_cells_in_view_equal_ground_truth(drift_runs):
    levels, states, ideal = drift_runs
    in_view = np.asarray(states.scan_in_view)
    diff = np.abs(np.asarray(states.scan) - np.asarray(ideal)[None])
    assert in_view.mean() > 0.5
    assert diff[in_view].max() < 1e-4  # float32 rounding of world coordinates on 1 m walls
    # The blind zone around the belly is not in view at any noise level.
    assert not in_view[:, 50, 50].any()


@pytest.fixture(scope="module")
def straight_walk():
    """2.5 m/s along x over ridged terrain, no turning, no noise: the base moves exactly one 5 cm
    cell per step (12 steps). Returns (terrain, final pos, final quat, final map state)."""
    hf = _ridge_hf(3)
    n = 12
    pos = jp.stack(
        [jp.array([2.0, 2.0, 0.65]) + jp.array([0.05, 0.0, 0.0]) * k for k in range(n + 1)]
    )
    quat = jp.tile(jp.array([1.0, 0.0, 0.0, 0.0]), (n + 1, 1))
    v = jp.tile(jp.array([2.5, 0.0, 0.0]), (n, 1))
    states, _ = _run_map(
        hf, (pos, quat, v, jp.zeros((n, 3))), jp.zeros(1), jax.random.split(jax.random.key(0), 1)
    )
    return hf, pos[-1], quat[-1], jax.tree.map(lambda a: a[0], states)


def test_straight_walk_by_whole_cells_remembers_exactly(straight_walk):
    """Remembered cells are shifted copies of the ideal scan (no resampling error)."""
    hf, pos, quat, state = straight_walk
    ideal = em.height_scan(hf, pos, kin.yaw_from_quat(quat))
    err, count = em.memory_error(state, ideal)
    assert int(count) > 500
    assert float(err) < 1e-5


def test_map_forgets_cells_that_leave_its_window(stones_hf):
    """The stored map is a ring buffer: an odometry jump of 5 m (100 cells) and back relabels
    its slots; the cells under the belly that left the window come back unknown (not with the
    heights of the cells their slots held meanwhile), and the map's masks and scan agree."""
    pos, quat = jp.array([2.0, 2.0, 0.6]), jp.array([1.0, 0.0, 0.0, 0.0])
    upd = jax.jit(em.aggre_update, static_argnames=("dt", "with_flags"))
    state = em.aggre_init(stones_hf, pos, quat)
    assert bool(state.scan_known[50, 50]) and bool(state.known.all())
    jump = jp.array([5.0 / DT, 0.0, 0.0])  # odometry: 5 m in one step (the true base stays)
    away = upd(state, stones_hf, pos, quat, jump, jp.zeros(3), dt=DT)
    np.testing.assert_array_equal(away.center_idx, [100, 0])
    back = upd(away, stones_hf, pos, quat, -jump, jp.zeros(3), dt=DT)
    np.testing.assert_array_equal(back.center_idx, [0, 0])
    assert not bool(back.scan_known[50, 50])  # the belly zone: not in view, forgotten
    assert float(back.scan[50, 50]) == em.UNKNOWN_HEIGHT_M
    assert 0.3 < float(back.known.mean()) < 0.95  # what the cameras saw meanwhile
    # Without the masks (as the env updates it): the same scan to float rounding.
    lean = upd(away, stones_hf, pos, quat, -jump, jp.zeros(3), dt=DT, with_flags=False)
    assert lean.scan_known is None and lean.scan_in_view is None
    np.testing.assert_allclose(lean.scan, back.scan, atol=1e-4, rtol=0)
    with pytest.raises(ValueError, match="with_flags=True"):
        em.memory_error(lean, lean.scan)


def test_update_bad_dt_and_level_raise(stones_hf):
    state = em.aggre_init(stones_hf, jp.array([2.0, 2.0, 0.6]), jp.array([1.0, 0, 0, 0]))
    with pytest.raises(ValueError, match="dt=0.0"):
        em.aggre_update(
            state,
            stones_hf,
            jp.array([2.0, 2.0, 0.6]),
            jp.array([1.0, 0, 0, 0]),
            jp.zeros(3),
            jp.zeros(3),
            0.0,
        )
    with pytest.raises(ValueError, match="level=-1"):
        odom.noisy_odometry(jax.random.key(0), jp.zeros(3), jp.zeros(3), -1.0)


def test_map_without_prior_starts_blind_under_the_belly(stones_hf):
    pos, quat = jp.array([2.0, 2.0, 0.6]), jp.array([1.0, 0.0, 0.0, 0.0])
    state = em.aggre_init(stones_hf, pos, quat, full_prior=False)
    assert not bool(state.scan_known[50, 50])
    assert float(state.scan[50, 50]) == em.UNKNOWN_HEIGHT_M
    full = em.aggre_init(stones_hf, pos, quat, full_prior=True)
    np.testing.assert_allclose(full.scan, em.height_scan(stones_hf, pos, 0.0), atol=1e-4)


# ------------------------------------------------------------------------ mock foot readings

TOF = tof.ToFSpec()
KNOT_M = 0.2  # common multiple of the 4 cm terrain and 5 cm scan spacings


def _ridge_hf(seed: int) -> Heightfield:
    """z = f(x) + g(y), f and g piecewise linear with knots every 0.2 m: planar inside every 4 cm
    and every 5 cm cell, so both MuJoCo triangulations represent it exactly when the scan grid is
    aligned with the world grid (base xy on the 5 cm lattice, yaw a multiple of 90 deg)."""
    rng = np.random.default_rng(seed)
    x = np.arange(SPEC.nx) * SPEC.cell_m
    y = np.arange(SPEC.ny) * SPEC.cell_m
    fx = np.interp(x, np.arange(0, 6.4, KNOT_M), rng.uniform(-0.15, 0.15, 32))
    gy = np.interp(y, np.arange(0, 4.4, KNOT_M), rng.uniform(-0.15, 0.15, 22))
    return _tile_hf(fx[None, :] + gy[:, None])


def _poses(hf, n, seed, aligned):
    """n random base poses over the course and joint angles near the default stance."""
    rng = np.random.default_rng(seed)
    xy = np.stack([rng.uniform(2.0, 4.0, n), rng.uniform(1.6, 2.4, n)], -1)
    if aligned:
        xy = np.round(xy / 0.05) * 0.05
        yaw = rng.integers(0, 4, n) * (np.pi / 2)
    else:
        yaw = rng.uniform(-np.pi, np.pi, n)
    z = np.asarray(hf.height_at(jp.asarray(xy, jp.float32))) + rng.uniform(0.62, 0.75, n)
    quat = np.stack([_quat(rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), w) for w in yaw])
    q = np.asarray(constants.DEFAULT_POSE)[None] + rng.uniform(-0.25, 0.25, (n, 12))
    f32 = lambda a: jp.asarray(a, jp.float32)
    return f32(np.concatenate([xy, z[:, None]], -1)), f32(quat), f32(q)


@jax.jit
def _aggre_and_ideal(state, hf, pos, quat, q):
    """(mock_aggre, mock_ideal) readings of one robot (one compile shared by several tests)."""
    return (
        sources.mock_aggre_readings(TOF, state, quat, q),
        sources.mock_ideal_readings(TOF, hf, pos, quat, q),
    )


@jax.jit
def _tof_and_mock(hf, pos, quat, q_true, q_meas):
    """tof readings at the true joints and mock_ideal readings from the measured joints, for a
    batch of poses; also whether each sensor site lies above the terrain (>= 2 cm)."""

    def one(p, qu, qt, qm):
        fk = kin.world_foot_kinematics(jp.concatenate([p, qu, qt]))
        real = tof.sense(TOF, hf, fk.tof_pos, fk.tof_rot)
        mock = sources.mock_ideal_readings(TOF, hf, p, qu, qm)
        above = fk.tof_pos[:, 2] > hf.height_at(fk.tof_pos[:, :2]) + 0.02
        return real, mock, above

    return jax.vmap(one)(pos, quat, q_true, q_meas)


def _compare(real, mock, above):
    """Per-zone |distance difference| where both are valid, and the valid-flag agreement, over
    the sensors above the terrain."""
    m = np.broadcast_to(np.asarray(above)[..., None], real.valid.shape)
    rv, mv = np.asarray(real.valid)[m], np.asarray(mock.valid)[m]
    dd = np.abs(np.asarray(real.distance_m)[m] - np.asarray(mock.distance_m)[m])[rv & mv]
    return dd, np.mean(rv == mv), rv.mean()


def test_mock_ideal_equals_tof_on_exactly_representable_terrain():
    """Zero perturbation on terrain both grids represent exactly: the same rays give the same
    readings up to one 1 mm quantization step (rounding of nearly equal floats)."""
    hf = _ridge_hf(0)
    pos, quat, q = _poses(hf, 24, 0, aligned=True)
    real, mock, above = _tof_and_mock(hf, pos, quat, q, q)
    dd, agree, valid_frac = _compare(real, mock, above)
    assert np.asarray(above).mean() > 0.7 and valid_frac > 0.7
    assert agree == 1.0
    assert dd.max() <= 1.0e-3 + 1e-6


@pytest.mark.slow  # the exactly-representable test above stays in the fast suite
def test_mock_ideal_close_to_tof_on_stepping_stones(stones_hf):
    """Zero perturbation on 90 %-difficulty grid stones at random yaw. The 5 cm scan resamples the
    4 cm terrain: stone edges move by up to half a scan-cell diagonal (3.5 cm) and 1 m walls
    become 5 cm ramps, so zones whose nearest point is an edge differ by a few cm. Measured
    (32 poses): median 1.2 cm, 90th percentile 6 cm; bounds below leave a margin."""
    pos, quat, q = _poses(stones_hf, 24, 1, aligned=False)
    real, mock, above = _tof_and_mock(stones_hf, pos, quat, q, q)
    dd, agree, _ = _compare(real, mock, above)
    assert dd.size > 500
    assert np.median(dd) < 0.025
    assert np.percentile(dd, 90) < 0.10
    assert agree > 0.9


def test_joint_offset_moves_mock_readings_only():
    """A static 0.1 rad offset on all joint readings: mock_ideal then reads what a real sensor
    would read at the *offset* joints (the robot believes its feet are there), which differs from
    the tof readings at the true joints (tof never sees the measured joints)."""
    hf = _ridge_hf(1)
    pos, quat, q = _poses(hf, 24, 2, aligned=True)
    q_meas = q + 0.1
    real, mock, above = _tof_and_mock(hf, pos, quat, q, q_meas)
    real_off, mock0, above_off = _tof_and_mock(hf, pos, quat, q_meas, q)
    both = np.asarray(above) & np.asarray(above_off)
    # mock(q + offset) == tof(true joints = q + offset) ...
    dd, agree, _ = _compare(real_off, mock, both)
    assert agree == 1.0 and dd.max() <= 1.0e-3 + 1e-6
    # ... while tof(q) is what the unperturbed mock reads, and differs from the perturbed mock.
    dd0, _, _ = _compare(real, mock0, both)
    assert dd0.max() <= 1.0e-3 + 1e-6
    diff, _, _ = _compare(real, mock, both)
    assert np.mean(diff) > 0.02 and np.mean(diff > 0.01) > 0.5


@pytest.mark.integration
def test_shank_scale_changes_physics_not_the_kinematic_model():
    """The shank_length perturbation (x1.2) scales the *physics* model: MuJoCo C puts its feet and
    ToF sites 20 % further along the shank, so the env's tof readings (true sensor poses) change;
    the mock sources keep the nominal kinematics (the robot does not know), so their readings at
    the same measured joints are unchanged."""
    from types import SimpleNamespace

    from configs import smoke
    from foottof.envs.sensing import Measurements, Sensing
    from foottof.robot import make_model

    hf = _ridge_hf(2)
    pos, quat, q = _poses(hf, 8, 3, aligned=True)
    pos = pos.at[:, 2].add(0.15)  # keep the longer legs' sensors above the terrain too
    # MuJoCo C: the scaled model's ToF sites sit 20 % further from the knee (KFE) than nominal.
    ext = []
    for scale in (1.0, 1.2):
        m = make_model(None, shank_scale=scale)
        d = mujoco.MjData(m)
        d.qpos[:] = np.concatenate(
            [np.asarray(pos[0], float), np.asarray(quat[0], float), np.asarray(q[0], float)]
        )
        mujoco.mj_kinematics(m, d)
        sites = [m.site(n).id for n in constants.TOF_SITES]
        knees = [m.body(f"{leg}_shank").id for leg in constants.FEET]
        ext.append(np.linalg.norm(d.site_xpos[sites] - d.xpos[knees], axis=-1))
    np.testing.assert_allclose(ext[1], 1.2 * ext[0], rtol=1e-6)

    cfg = smoke.get_config()
    nominal, scaled = (Sensing(cfg, "mock_ideal", hf, s) for s in (1.0, 1.2))

    @jax.jit
    def readings(p, qu, qq):
        d = SimpleNamespace(qpos=jp.concatenate([p, qu, qq]))
        meas = Measurements(q=qq, lin_vel=jp.zeros(3), ang_vel=jp.zeros(3))
        out = []
        for s in (nominal, scaled):
            true = s.true_reading(d)
            out.append((true, s._source_reading(d, meas, None, true)))
        return out

    (tof_a, mock_a), (tof_b, mock_b) = jax.vmap(readings)(pos, quat, q)
    np.testing.assert_array_equal(mock_a.distance_m, mock_b.distance_m)
    np.testing.assert_array_equal(mock_a.valid, mock_b.valid)
    both = np.asarray(tof_a.valid & tof_b.valid)
    assert both.mean() > 0.5
    diff = np.abs(np.asarray(tof_a.distance_m) - np.asarray(tof_b.distance_m))[both]
    assert np.median(diff) > 0.03  # the sensors moved ~7 cm along the shank


def test_mock_aggre_equals_mock_ideal_when_all_cells_in_view(stones_hf):
    """0 % odometry noise (here even a wrong estimate) and every cell in view: the map is the
    ideal scan, so the readings are mock_ideal's."""
    pos, quat, _, _ = _walk(3, 0.8, 0.3)
    q = jp.asarray(constants.DEFAULT_POSE, jp.float32)
    state = em.aggre_init(stones_hf, pos[0], quat[0], see_all=True)
    for k in range(1, 4):
        state = em.aggre_update(
            state,
            stones_hf,
            pos[k],
            quat[k],
            jp.array([0.8, 0.0, 0.0]),
            jp.array([0.0, 0.0, 0.3]),
            DT,
            see_all=True,
        )
    assert bool(state.scan_in_view.all())
    np.testing.assert_array_equal(
        state.scan, em.height_scan(stones_hf, pos[3], kin.yaw_from_quat(quat[3]))
    )
    a, b = _aggre_and_ideal(state, stones_hf, pos[3], quat[3], q)
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_array_equal(a.distance_m, b.distance_m)


def test_mock_aggre_reads_remembered_cells_like_mock_ideal(straight_walk):
    """The feet stand in the cameras' blind zone, so their readings come from remembered cells,
    and they equal mock_ideal's."""
    hf, pos, quat, state = straight_walk
    q = jp.asarray(constants.DEFAULT_POSE, jp.float32)
    fk = kin.forward_kinematics(q)
    feet_ij = np.round((np.asarray(fk.foot_pos[:, :2]) + 2.5) / 0.05).astype(int)
    assert not np.asarray(state.scan_in_view)[feet_ij[:, 1], feet_ij[:, 0]].any()
    a, b = _aggre_and_ideal(state, hf, pos, quat, q)
    assert np.asarray(b.valid).mean() > 0.5
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_allclose(a.distance_m, b.distance_m, atol=1.0e-3 + 1e-6)


def test_unknown_cells_give_no_return(straight_walk):
    """Never-seen cells hold UNKNOWN_HEIGHT_M, 4 m below the base: beyond the 1 m ToF range, so a
    foot over unknown cells reads max range and invalid, like over a deep gap."""
    hf, pos, quat, state = straight_walk
    state = state.replace(scan=jp.full_like(state.scan, em.UNKNOWN_HEIGHT_M))
    r, _ = _aggre_and_ideal(state, hf, pos, quat, jp.asarray(constants.DEFAULT_POSE, jp.float32))
    assert not np.asarray(r.valid).any()
    np.testing.assert_array_equal(r.distance_m, TOF.max_range_m)


LEVEL = jp.array([1.0, 0.0, 0.0, 0.0], jp.float32)  # level base orientation (w, x, y, z)


def _flat_hf(z: float) -> Heightfield:
    """Flat world terrain at height z [m] (the tile geometry)."""
    return _tile_hf(np.full((SPEC.ny, SPEC.nx), z, np.float32))


def test_mock_sensor_below_flat_surface_reads_contact():
    """Issue 52: with a shorter real shank, nominal kinematics put the believed sensor below the
    ground the real foot stands on. Both mocks then read contact (0 m, valid, incidence 0 in every
    zone), not 'no ground' (max range, invalid: rays from inside the solid pass through it).
    With the ground 3 cm below the believed sensors the readings stay tof.sense's."""
    q = jp.asarray(constants.DEFAULT_POSE, jp.float32)
    sites, rots = sources.sensor_sites_in_scan_frame(LEVEL, q)
    site_z = float(sites[0, 2])
    np.testing.assert_allclose(sites[:, 2], site_z, atol=1e-6)  # DEFAULT_POSE: all 4 level
    hf = _flat_hf(0.0)
    for ground_over_site, contact in ((0.02, True), (-0.03, False)):
        pos = jp.array([2.0, 2.0, -(site_z + ground_over_site)], jp.float32)  # ground at z = 0
        state = em.aggre_init(hf, pos, LEVEL, see_all=True)
        for r in _aggre_and_ideal(state, hf, pos, LEVEL, q):
            if contact:
                np.testing.assert_array_equal(r.distance_m, 0.0)
                assert bool(np.asarray(r.valid).all())
                np.testing.assert_array_equal(r.incidence_rad, 0.0)
            else:
                scan = jp.full((em.SCAN_N, em.SCAN_N), -float(pos[2]), jp.float32)
                ref = tof.sense(TOF, em.scan_heightfield(scan), sites, rots)
                assert bool(np.asarray(ref.valid).all())
                np.testing.assert_allclose(r.distance_m, ref.distance_m, atol=1.0e-3 + 1e-6)
                np.testing.assert_array_equal(r.valid, ref.valid)


def test_mock_sensors_at_a_gap_edge_hand_computed():
    """Four straight-down sensors 2 cm below a stone top (z = -0.50) at y = 0, the stone ending
    at x = 0 and a gap floor at z = -0.80 from x = 0.05 (the 5 cm scan cell between is the ramp
    z = -0.5 - 6 x of the triangulated scan; the edge runs along y, so both triangles agree).
    Sensor z = -0.52; sensor +x = world +x, so zone rows 0-1 look back at the stone.

    (a) x = -0.02 over the stone: below the surface -> contact (0 m, valid) in every zone.
    (b) x = +0.002 on the ramp: surface -0.512 there, still 8 mm above -> contact.
    (c) x = +0.004 on the ramp: surface -0.524, 4 mm below -> no contact; the rays hit the ramp
        (and forward rays the floor). A ray (tx, ty, -1) hits the ramp at depth
        u = 0.004 / (1 - 6 tx) (tx < 1/6), range u sqrt(1 + tx^2 + ty^2), smallest at the zone's
        tx nearest -t (t = tan 22.5 deg = 0.4142) and |ty| nearest 0:
        row 0 (tx = -t): 0.004 * 1.0824 / 3.485 = 0.0012 -> 1 mm (|ty| = t/2: 0.0013 -> 1 mm);
        row 1 (tx = -t/2): 0.004 * 1.0212 / 2.243 = 0.0018 -> 2 mm (0.0019 -> 2 mm);
        row 2: its tx = 0 corners hit the ramp straight below: 4 mm (0.004 * 1.0212 -> 4 mm);
        row 3 (tx >= t/2 > 1/6: the ramp falls away faster than the ray) hits the floor 0.28 m
        below: 0.28 * sqrt(1 + (t/2)^2) = 0.2859 -> 0.286 (outer columns 0.28 * 1.0420 -> 0.292).
    (d) x = +0.30 over the gap: below the stone top but outside the solid, not in contact; all
        rays hit the floor 0.28 m below (back rays reach x >= 0.30 - 0.28 t = 0.18 > 0.05):
        0.28 sqrt(1 + tx_min^2 + ty_min^2) = 0.280 / 0.286 / 0.292 m by the zone's nearest corner.
    """
    xs = np.asarray(em.scan_xy())[0, :, 0]  # vertex x along a row [m]
    scan = np.where(xs[None, :] <= 1e-6, -0.50, -0.80) * np.ones((em.SCAN_N, 1))
    hf = em.scan_heightfield(jp.asarray(scan, jp.float32))
    pos = jp.array([[-0.02, 0, -0.52], [0.002, 0, -0.52], [0.004, 0, -0.52], [0.30, 0, -0.52]])
    down = jp.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]]).T  # columns: site x, y, z axes
    r = jax.jit(lambda p, rot: sources.sense_mapped(TOF, hf, p, rot))(
        pos, jp.broadcast_to(down, (4, 3, 3))
    )
    dist, valid = np.asarray(r.distance_m).reshape(4, 4, 4), np.asarray(r.valid)
    assert valid.all()
    np.testing.assert_array_equal(dist[:2], 0.0)  # (a), (b): contact
    np.testing.assert_array_equal(r.incidence_rad[:2], 0.0)
    ramp = [[1, 1, 1, 1], [2, 2, 2, 2], [4, 4, 4, 4], [292, 286, 286, 292]]  # (c) [mm]
    floor = [[292, 286, 286, 292], [286, 280, 280, 286], [286, 280, 280, 286], [292, 286, 286, 292]]
    np.testing.assert_allclose(dist[2], np.asarray(ramp) / 1000.0, atol=1e-6)
    np.testing.assert_allclose(dist[3], np.asarray(floor) / 1000.0, atol=1e-6)
    ref = tof.sense(TOF, hf, pos, jp.broadcast_to(down, (4, 3, 3)))  # (c), (d): tof's pipeline
    np.testing.assert_array_equal(r.distance_m[2:], ref.distance_m[2:])
    np.testing.assert_allclose(r.incidence_rad[2:], ref.incidence_rad[2:], atol=1e-6)  # jit/eager


def test_mock_sensor_exactly_on_the_surface_is_not_in_contact():
    """The contact rule's boundary (sources.sense_mapped: contact only strictly below the
    surface). Straight-down sensors with their origins exactly on flat ground at z = 0, on a
    vertex and inside a cell: every ray starts on the surface, so it hits at 0 m (as mj_ray on
    the same MuJoCo heightfield says), valid, and the zone's incidence is the angle between the
    vertical and one of its rays (tx, ty, -1). Zone (i, j) spans tan angles -t + i t/2 ..
    -t + (i + 1) t/2 on each axis (t = tan 22.5 deg), so its incidence lies between atan of
    sqrt(tx^2 + ty^2) at its nearest and farthest corner: >= atan(t / 2) = 0.204 rad in the 12
    zones off the centre, where contact would read 0. A micrometre lower the origins are inside
    the solid: contact, 0 m, valid, incidence 0 in every zone."""
    hf = _flat_hf(0.0)
    down = jp.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]]).T  # columns: site x, y, z axes
    xy = [[2.0, 2.0], [2.013, 1.977]]  # a vertex of the 4 cm grid; inside a cell
    on = jp.array([[*p, 0.0] for p in xy] * 2, jp.float32)
    below = on.at[:, 2].set(-1e-6)
    rot = jp.broadcast_to(down, (4, 3, 3))
    sense = jax.jit(lambda p: sources.sense_mapped(TOF, hf, p, rot))  # one compile for both
    r_on, r_below = sense(on), sense(below)

    m, d = hfield_mj_model(hf)
    t = math.tan(math.radians(22.5))
    geom = np.zeros(1, np.int32)
    for p in xy:
        for ray in ([0.0, 0.0, -1.0], [-t, -t, -1.0], [t / 2, -t / 4, -1.0]):
            origin = np.array([*p, 0.0])
            assert mujoco.mj_ray(m, d, origin, np.array(ray), None, 1, -1, geom) == 0.0
    np.testing.assert_array_equal(r_on.distance_m, 0.0)
    assert bool(np.asarray(r_on.valid).all())
    edges = -t + t / 2 * np.arange(5)  # zone boundaries in tan angle
    near = np.where(edges[:-1] * edges[1:] < 0, 0.0, np.minimum(abs(edges[:-1]), abs(edges[1:])))
    far = np.maximum(abs(edges[:-1]), abs(edges[1:]))
    lo = np.arctan(np.hypot(near[:, None], near[None, :])).reshape(-1)  # (16,) zone (i, j)
    hi = np.arctan(np.hypot(far[:, None], far[None, :])).reshape(-1)
    inc = np.asarray(r_on.incidence_rad)  # (4, 16)
    assert (inc >= lo - 1e-5).all() and (inc <= hi + 1e-5).all(), (inc, lo, hi)
    off_centre = np.ones((4, 4), bool)
    off_centre[1:3, 1:3] = False
    assert (inc[:, off_centre.reshape(-1)] > 0.2).all(), inc

    np.testing.assert_array_equal(r_below.distance_m, 0.0)
    assert bool(np.asarray(r_below.valid).all())
    np.testing.assert_array_equal(r_below.incidence_rad, 0.0)


def test_jit_equals_no_jit(stones_hf):
    """Scan, sensor poses and map update: eager == jit (the ray caster's own jit == no-jit is
    tested with foottof.sensors)."""
    pos, quat, q = _poses(stones_hf, 1, 5, aligned=False)
    pos, quat, q = pos[0], quat[0], q[0]
    yaw = kin.yaw_from_quat(quat)
    np.testing.assert_allclose(
        em.height_scan(stones_hf, pos, yaw), jax.jit(em.height_scan)(stones_hf, pos, yaw), atol=1e-4
    )
    for a, b in zip(
        sources.sensor_sites_in_scan_frame(quat, q),
        jax.jit(sources.sensor_sites_in_scan_frame)(quat, q),
        strict=True,
    ):
        np.testing.assert_allclose(a, b, atol=1e-6)
    state = em.aggre_init(stones_hf, pos, quat)
    args = (
        stones_hf,
        pos + jp.array([0.01, 0.0, 0.0]),
        quat,
        jp.array([0.5, 0.0, 0.0]),
        jp.array([0.0, 0.0, 0.2]),
        DT,
    )
    s_eager = em.aggre_update(state, *args)
    s_jit = jax.jit(em.aggre_update, static_argnums=6)(state, *args)
    for a, b in zip(jax.tree.leaves(s_eager), jax.tree.leaves(s_jit), strict=True):
        np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), atol=1e-4)


def test_bad_sensor_feet_and_source_raise(stones_hf):
    q = jp.asarray(constants.DEFAULT_POSE, jp.float32)
    with pytest.raises(ValueError, match="sensor_feet"):
        sources.readings_from_scan(
            TOF, jp.zeros((101, 101)), jp.array([1.0, 0, 0, 0]), q, sensor_feet=(0, 1, 2, 7)
        )
    with pytest.raises(ValueError, match="mock_ideal"):
        perception.check_source("mock_height")
