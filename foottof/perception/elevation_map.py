"""Robot-centric height scans: the ideal top-down scan and a camera-aggregated elevation map."""

from __future__ import annotations

import jax
import jax.numpy as jp
from flax import struct

from foottof.perception import cameras as cam_lib
from foottof.robot.kinematics import quat_to_mat, yaw_from_quat
from foottof.terrain.heightfield import Heightfield

# Robot-centric scan grid (paper: 5 m x 5 m at 5 cm). Frame: gravity aligned, rotated by the base
# yaw, origin at the base; vertex (i, j) at x = -2.5 + 0.05 j, y = -2.5 + 0.05 i (Heightfield
# layout), value = terrain height minus base z [m].
SCAN_CELL_M = 0.05  # scan vertex spacing [m]
SCAN_HALF_SIZE_M = 2.5  # scan half extent along x and y [m]
SCAN_N = 101  # vertices per side (5 m / 5 cm + 1)
SCAN_Z_FLOOR_M = -4.0  # lowest representable relative height [m] (Heightfield z_floor_m)
SCAN_Z_RANGE_M = 6.0  # representable relative heights [-4, +2] m (Heightfield z_range_m)
# Value of cells the map has never seen: a hole 4 m below the base, far beyond the 1 m ToF range,
# so a foot ray that would hit an unknown cell gets no return (the same reading as over a deep gap).
UNKNOWN_HEIGHT_M = SCAN_Z_FLOOR_M

# Stored map: a grid fixed in the estimated odometry frame (axes of the initial base yaw frame),
# moved by whole cells to stay centred on the estimated base. 145 vertices (+-3.6 m) cover the
# 5 m x 5 m scan at any yaw (2.5 * sqrt(2) = 3.54 m) plus one cell of slack. It is a ring buffer,
# as grid_map's (ANYbotics' elevation mapping): odometry cell (kx, ky) lives in slot
# [ky mod 145, kx mod 145], so moving the map relabels slots instead of copying the grid, and
# unknown vertices hold NaN (grid_map's convention).
MAP_N = 145  # stored vertices per side
_MAP_C = (MAP_N - 1) // 2  # window offset of the centre vertex


def scan_heightfield(heights: jax.Array) -> Heightfield:
    """Wrap (101, 101) robot-centric heights [m, rel. to base z] as a static-origin Heightfield."""
    if heights.shape[-2:] != (SCAN_N, SCAN_N):
        raise ValueError(
            f"scan heights must have shape (..., {SCAN_N}, {SCAN_N}), got {heights.shape}"
        )
    return Heightfield(
        heights=heights,
        x0_m=-SCAN_HALF_SIZE_M,
        y0_m=-SCAN_HALF_SIZE_M,
        cell_m=SCAN_CELL_M,
        z_floor_m=SCAN_Z_FLOOR_M,
        z_range_m=SCAN_Z_RANGE_M,
    )


def scan_xy() -> jax.Array:
    """(101, 101, 2) x, y of the scan vertices in the robot-centric yaw frame [m]."""
    c = jp.linspace(-SCAN_HALF_SIZE_M, SCAN_HALF_SIZE_M, SCAN_N)
    x, y = jp.meshgrid(c, c)  # x varies along columns j, y along rows i
    return jp.stack([x, y], axis=-1)


def _rot_z(yaw: jax.Array) -> jax.Array:
    c, s = jp.cos(yaw), jp.sin(yaw)
    o, z = jp.ones_like(yaw), jp.zeros_like(yaw)
    rows = [jp.stack([c, -s, z], -1), jp.stack([s, c, z], -1), jp.stack([z, z, o], -1)]
    return jp.stack(rows, -2)


def tilt_rotation(base_quat: jax.Array) -> jax.Array:
    """(..., 3, 3) base axes in the yaw frame: roll and pitch only (``Rz(-yaw) @ R_base``)."""
    r = quat_to_mat(base_quat)
    return jp.swapaxes(_rot_z(yaw_from_quat(base_quat)), -1, -2) @ r


def _terrain_rel(
    hfield: Heightfield, base_pos: jax.Array, base_yaw: jax.Array, r_xy: jax.Array, patch=False
):
    """Terrain height minus base z at yaw-frame points (..., 2) [m]."""
    c, s = jp.cos(base_yaw), jp.sin(base_yaw)
    wx = base_pos[0] + c * r_xy[..., 0] - s * r_xy[..., 1]
    wy = base_pos[1] + s * r_xy[..., 0] + c * r_xy[..., 1]
    return hfield.height_at(jp.stack([wx, wy], axis=-1), patch) - base_pos[2]


def height_scan(hfield: Heightfield, base_pos: jax.Array, base_yaw: jax.Array) -> jax.Array:
    """Ideal, noise-free top-down scan of the terrain around the base (mock_ideal).

    Each vertex samples MuJoCo's triangulated terrain surface straight below it (a vertical ray
    against the terrain only, no robot).

    Args:
      hfield: world terrain.
      base_pos: (3,) world base position [m].
      base_yaw: () base yaw [rad].

    Returns:
      (101, 101) terrain height minus base z [m] at the scan vertices (see SCAN_* constants).
    """
    # One gather per vertex: the scan is read twice by the ray caster, so XLA's CPU backend
    # materializes this lookup (see _compose_scan).
    return _terrain_rel(hfield, base_pos, base_yaw, scan_xy(), patch=True)


@struct.dataclass
class ElevationMapState:
    """Aggregated elevation map of one env (mock_aggre).

    Memory lives in a grid fixed in the *estimated* odometry frame (the initial base yaw frame,
    propagated by dead reckoning) and moved by whole cells, so cells outside the cameras' view
    are never re-interpolated step after step (no numerical blur); they move into the current base
    frame only through the estimated pose. The robot-centric ``scan`` is rebuilt every update.

    Attributes:
      heights: (145, 145) stored terrain z in the odometry frame [m], NaN where never seen (or
        moved out of the window); a ring buffer: the vertex of odometry cell (kx, ky), at
        x = 0.05 kx, y = 0.05 ky, is slot [ky mod 145, kx mod 145], for the cells within 72 of
        ``center_idx`` (:func:`window_cells`).
      center_idx: (2,) int32 odometry (x, y) cell index of the window's centre vertex.
      pose_est: (4,) estimated base x, y, z [m] and yaw [rad] in the odometry frame.
      tilt_prev: (3, 3) roll/pitch rotation of the base at the last update (IMU).
      scan: (101, 101) robot-centric heights relative to the base z [m] (scan_heightfield
        layout): fresh ground truth in view, the moved prior elsewhere, UNKNOWN_HEIGHT_M if never
        seen.
        Every update rebuilds it (the previous one is not read), so a carrier may drop it (the
        env carries None).
      scan_known: (101, 101) bool, the scan vertex is in view or was seen before; None when
        the update was asked for no flags (``with_flags=False``, as the env does).
      scan_in_view: (101, 101) bool, the scan vertex is seen by a camera at this step (None
        likewise).
    """

    heights: jax.Array
    center_idx: jax.Array
    pose_est: jax.Array
    tilt_prev: jax.Array
    scan: jax.Array
    scan_known: jax.Array | None = None
    scan_in_view: jax.Array | None = None

    @property
    def known(self) -> jax.Array:
        """(145, 145) bool, the stored vertex has been seen (per ring-buffer slot)."""
        return ~jp.isnan(self.heights)


def window_cells(center_idx: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Odometry cell index held by each ring-buffer column and row: (kx (145,), ky (145,)).

    The window spans cells ``center_idx - 72 .. center_idx + 72``; cell k sits in slot k mod 145.
    """
    lo = center_idx - _MAP_C
    s = jp.arange(MAP_N, dtype=center_idx.dtype)
    return lo[0] + jp.mod(s - lo[0], MAP_N), lo[1] + jp.mod(s - lo[1], MAP_N)


def _map_xy(kx: jax.Array, ky: jax.Array) -> jax.Array:
    """(145, 145, 2) odometry-frame x, y of the stored vertices [m] (ring-buffer slots) from the
    cells of each column and row (:func:`window_cells`)."""
    x = kx[None, :] * SCAN_CELL_M
    y = ky[:, None] * SCAN_CELL_M
    return jp.stack(jp.broadcast_arrays(x, y), axis=-1)


def _odom_to_robot(p_xy: jax.Array, pose_est: jax.Array) -> jax.Array:
    """Odometry-frame (..., 2) points -> estimated robot-centric yaw frame (..., 2)."""
    c, s = jp.cos(pose_est[3]), jp.sin(pose_est[3])
    dx, dy = p_xy[..., 0] - pose_est[0], p_xy[..., 1] - pose_est[1]
    return jp.stack([c * dx + s * dy, -s * dx + c * dy], axis=-1)


def _robot_to_odom(r_xy: jax.Array, pose_est: jax.Array) -> jax.Array:
    c, s = jp.cos(pose_est[3]), jp.sin(pose_est[3])
    x = pose_est[0] + c * r_xy[..., 0] - s * r_xy[..., 1]
    y = pose_est[1] + s * r_xy[..., 0] + c * r_xy[..., 1]
    return jp.stack([x, y], axis=-1)


def _in_view(r_xy, h_rel, tilt, cameras, see_all: bool) -> jax.Array:
    """Camera visibility of yaw-frame terrain points (r_xy (..., 2), height h_rel (...))."""
    if see_all:
        return jp.ones(h_rel.shape, dtype=bool)
    # p_base = tilt^T p_yaw (yaw frame -> base frame), written out: a (..., 3) @ (3, 3) product
    # is slow on XLA's CPU backend.
    x, y, z = r_xy[..., 0], r_xy[..., 1], h_rel
    p_base = jp.stack([x * tilt[0, k] + y * tilt[1, k] + z * tilt[2, k] for k in range(3)], -1)
    return cam_lib.visible(p_base, cameras)


def _update_map(
    state: ElevationMapState,
    new_center,
    hfield,
    base_pos,
    base_quat,
    cameras,
    see_all,
    reset=False,
):
    """Move the window to ``new_center`` and overwrite the vertices a camera sees with ground
    truth (placed via pose_est); where ``reset`` (traced bool) every vertex counts as seen.

    Moving keeps a slot's height where it holds the same odometry cell before and after (the
    ring buffer: no copy), and forgets it (NaN) where the slot now holds a newly entered cell.
    The map has a single output on purpose: XLA's CPU backend fuses the terrain lookups (gathers)
    into the one loop that consumes them, where a second output (a separate known mask) made it
    materialize each gather, ~4x slower (bench/NOTES.md item 10).
    """
    kx_old, ky_old = window_cells(state.center_idx)
    kx, ky = window_cells(new_center)
    kept = (ky == ky_old)[:, None] & (kx == kx_old)[None, :]
    r_xy = _odom_to_robot(_map_xy(kx, ky), state.pose_est)  # where the robot thinks
    h_rel = _terrain_rel(hfield, base_pos, yaw_from_quat(base_quat), r_xy)  # what the camera sees
    seen = _in_view(r_xy, h_rel, tilt_rotation(base_quat), cameras, see_all) | reset
    stored = jp.where(kept, state.heights, jp.nan)
    heights = jp.where(seen, h_rel + state.pose_est[2], stored)
    return state.replace(heights=heights, center_idx=new_center)


def _sample_map(state: ElevationMapState, p_xy: jax.Array) -> jax.Array:
    """Bilinear sample of the stored map at odometry (..., 2) points -> z, NaN unless the point
    lies in the window and all four vertices around it are known."""
    u = p_xy[..., 0] / SCAN_CELL_M - state.center_idx[0] + _MAP_C  # fractional window column
    v = p_xy[..., 1] / SCAN_CELL_M - state.center_idx[1] + _MAP_C  # fractional window row
    inside = (u >= 0.0) & (u <= MAP_N - 1) & (v >= 0.0) & (v <= MAP_N - 1)
    j = jp.clip(jp.floor(u).astype(jp.int32), 0, MAP_N - 2)
    i = jp.clip(jp.floor(v).astype(jp.int32), 0, MAP_N - 2)
    fu, fv = jp.clip(u - j, 0.0, 1.0), jp.clip(v - i, 0.0, 1.0)
    lo = state.center_idx - _MAP_C
    j0, j1 = jp.mod(lo[0] + j, MAP_N), jp.mod(lo[0] + j + 1, MAP_N)  # ring-buffer slots
    i0, i1 = jp.mod(lo[1] + i, MAP_N), jp.mod(lo[1] + i + 1, MAP_N)
    h = state.heights
    z = (
        h[i0, j0] * (1 - fu) * (1 - fv)
        + h[i0, j1] * fu * (1 - fv)
        + h[i1, j0] * (1 - fu) * fv
        + h[i1, j1] * fu * fv
    )  # NaN if a vertex is unknown (even at weight 0)
    return jp.where(inside, z, jp.nan)


def _compose_scan(
    state: ElevationMapState, hfield, base_pos, base_quat, cameras, see_all, with_flags=True
):
    """Robot-centric scan: ground truth where a camera sees it, else the moved prior.

    ``with_flags`` (static): also the scan_known / scan_in_view masks. Without them the scan is
    the only output (one fused loop on CPU, see _update_map); the env needs only the scan.
    """
    r_xy = scan_xy()
    # One gather per vertex: the ray caster reads the scan twice (its strip walk and its wall
    # lookups), so XLA's CPU backend materializes this lookup; one 2 x 2 gather costs less
    # there than four (bench/NOTES.md item 10).
    gt = _terrain_rel(hfield, base_pos, yaw_from_quat(base_quat), r_xy, patch=True)
    seen = _in_view(r_xy, gt, tilt_rotation(base_quat), cameras, see_all)
    prior = _sample_map(state, _robot_to_odom(r_xy, state.pose_est))
    known = ~jp.isnan(prior)
    scan = jp.where(seen, gt, jp.where(known, prior - state.pose_est[2], UNKNOWN_HEIGHT_M))
    if not with_flags:
        return state.replace(scan=scan, scan_known=None, scan_in_view=None)
    return state.replace(scan=scan, scan_known=seen | known, scan_in_view=seen)


def aggre_init(
    hfield: Heightfield,
    base_pos: jax.Array,
    base_quat: jax.Array,
    cameras: tuple[cam_lib.Camera, ...] = cam_lib.CAMERAS,
    see_all: bool = False,
    full_prior: bool = True,
    with_flags: bool = True,
) -> ElevationMapState:
    """Start an elevation map at the true base pose (the odometry frame's origin).

    Args:
      hfield: world terrain.
      base_pos: (3,) world base position [m].
      base_quat: (4,) base orientation (w, x, y, z).
      cameras: static camera tuple.
      see_all: static; True makes every cell visible (the map then equals the ideal scan).
      full_prior: static; True starts from a complete ideal survey of the +-3.6 m surroundings
        (as if the robot had mapped them while standing), False from the cameras' first view only
        (the belly and feet zones start unknown).
      with_flags: static; False leaves scan_known / scan_in_view None (cheaper, see
        aggre_update).

    Returns:
      ElevationMapState with pose_est = 0.
    """
    dtype = jp.asarray(base_pos).dtype
    centre = jp.zeros(2, jp.int32)
    state = ElevationMapState(
        heights=jp.full((MAP_N, MAP_N), jp.nan, dtype),
        center_idx=centre,
        pose_est=jp.zeros(4, dtype),
        tilt_prev=tilt_rotation(jp.asarray(base_quat, dtype)),
        scan=jp.zeros((SCAN_N, SCAN_N), dtype),
    )
    prior = see_all or full_prior
    state = _update_map(state, centre, hfield, base_pos, base_quat, cameras, prior)
    return _compose_scan(state, hfield, base_pos, base_quat, cameras, see_all, with_flags)


def _so3_exp(rotvec: jax.Array) -> jax.Array:
    """(3,) rotation vector [rad] -> (3, 3) rotation matrix (Rodrigues)."""
    theta = jp.linalg.norm(rotvec)
    small = theta < 1e-8
    safe = jp.where(small, 1.0, theta)
    k = rotvec / safe
    kx = jp.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]], rotvec.dtype)
    rot = jp.eye(3, dtype=rotvec.dtype) + jp.sin(theta) * kx + (1.0 - jp.cos(theta)) * kx @ kx
    return jp.where(small, jp.eye(3, dtype=rotvec.dtype), rot)


def dead_reckon(
    pose_est: jax.Array,
    tilt_prev: jax.Array,
    base_quat: jax.Array,
    lin_vel_est_base: jax.Array,
    ang_vel_est_base: jax.Array,
    dt: float,
) -> jax.Array:
    """Zero-order integration of estimated base velocities over one step.

    Roll and pitch are known (IMU): ``tilt_prev`` at the previous step, ``base_quat`` now (its yaw
    is not used). The heading integrates the body rate held constant over ``dt``:
    ``R = Rz(yaw_est) @ tilt_prev @ exp([w dt])`` and the new yaw is that of ``R`` (integrating the
    world-z rate alone would drift when roll and pitch oscillate). The linear velocity, held
    constant over ``dt``, is rotated into the odometry frame with the new estimated orientation.

    Args:
      pose_est: (4,) estimated x, y, z [m], yaw [rad] in the odometry frame.
      tilt_prev: (3, 3) roll/pitch rotation (tilt_rotation) at the previous step.
      base_quat: (4,) true base orientation now (w, x, y, z); only roll and pitch are used.
      lin_vel_est_base: (3,) estimated linear velocity in the base frame [m/s].
      ang_vel_est_base: (3,) estimated angular velocity in the base frame [rad/s].
      dt: step duration [s].

    Returns:
      (4,) the new estimated pose.
    """
    rot = _rot_z(pose_est[3]) @ tilt_prev @ _so3_exp(ang_vel_est_base * dt)
    yaw = jp.arctan2(rot[1, 0], rot[0, 0])
    yaw = pose_est[3] + jp.remainder(yaw - pose_est[3] + jp.pi, 2.0 * jp.pi) - jp.pi  # unwrapped
    dpos = _rot_z(yaw) @ tilt_rotation(base_quat) @ lin_vel_est_base * dt
    return jp.concatenate([pose_est[:3] + dpos, yaw[None]])


def aggre_update(
    state: ElevationMapState,
    hfield: Heightfield,
    base_pos: jax.Array,
    base_quat: jax.Array,
    lin_vel_est_base: jax.Array,
    ang_vel_est_base: jax.Array,
    dt: float,
    cameras: tuple[cam_lib.Camera, ...] = cam_lib.CAMERAS,
    see_all: bool = False,
    reset=False,
    with_flags: bool = True,
) -> ElevationMapState:
    """One elevation-map update: move the prior by odometry, then overwrite what the cameras see.

    With ``reset`` (a traced bool, e.g. the env's ``done``) the result is
    ``aggre_init(hfield, base_pos, base_quat, cameras, see_all)`` (full prior; flags and indices
    exactly, heights to float rounding) in the same pass:
    the estimated pose restarts at the odometry origin and every vertex is refreshed. The env
    uses it to restart the map of auto-reset episodes without building a second map every step.

    Args:
      state: map after the previous step.
      hfield: world terrain (ground truth for the cells in view).
      base_pos: (3,) true world base position [m] (where the cameras really are).
      base_quat: (4,) true base orientation (w, x, y, z).
      lin_vel_est_base: (3,) estimated base linear velocity in the base frame [m/s] (with
        odometry noise, see noisy_odometry).
      ang_vel_est_base: (3,) estimated base angular velocity in the base frame [rad/s].
      dt: time since the previous update [s] (> 0).
      cameras: static camera tuple.
      see_all: static; True makes every cell visible.
      reset: () bool (traced), restart the map at the current pose (see above).
      with_flags: static; False leaves the diagnostic masks scan_known / scan_in_view None. The
        env passes False: the masks would be second outputs of the scan's loop, which makes
        XLA's CPU backend materialize its terrain gathers (bench/NOTES.md item 10).

    Returns:
      The updated ElevationMapState.
    """
    if isinstance(dt, (int, float)) and not dt > 0.0:
        raise ValueError(f"dt={dt} must be > 0 s")
    pose_est = dead_reckon(
        state.pose_est, state.tilt_prev, base_quat, lin_vel_est_base, ang_vel_est_base, dt
    )
    pose_est = jp.where(reset, jp.zeros_like(pose_est), pose_est)  # reset: odometry origin
    state = state.replace(pose_est=pose_est, tilt_prev=tilt_rotation(base_quat))
    centre = jp.round(pose_est[:2] / SCAN_CELL_M).astype(jp.int32)  # reset: back to 0
    state = _update_map(state, centre, hfield, base_pos, base_quat, cameras, see_all, reset)
    return _compose_scan(state, hfield, base_pos, base_quat, cameras, see_all, with_flags)


def memory_error(state: ElevationMapState, ideal_scan: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Drift of the remembered (out-of-view, known) scan cells against the ideal scan.

    Args:
      state: current map.
      ideal_scan: (101, 101) height_scan at the true pose.

    Returns:
      (mean absolute error [m], number of cells counted).
    """
    if state.scan_known is None or state.scan_in_view is None:
        raise ValueError(
            "memory_error needs the scan masks: update the map with with_flags=True (got None)"
        )
    mask = state.scan_known & ~state.scan_in_view
    n = jp.sum(mask)
    err = jp.sum(jp.where(mask, jp.abs(state.scan - ideal_scan), 0.0)) / jp.maximum(n, 1)
    return err, n
