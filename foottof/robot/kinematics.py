"""ANYmal-D leg geometry (public ANYmal-D URDF) and analytic forward kinematics in JAX."""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jp
import numpy as np

from foottof import config_check, constants

# Leg geometry of the LF leg in base-aligned axes at q = 0 [m], from the ANYmal-D URDF
# (ANYbotics/anymal_d_simple_description urdf/anymal.urdf, HEAD d5bf4dc3; fixed links merged).
# The other legs mirror it: RF y -> -y, LH x -> -x, RH both (see leg_signs). Joint axes: HAA +x,
# HFE/KFE +y.
HIP_OFFSET_M = (0.304, 0.109, 0.0)  # base origin -> HAA anchor (hip body origin)
HAA_TO_HFE_M = (0.069, 0.006, 0.0)  # HAA anchor -> HFE anchor (thigh body origin)
HFE_TO_KFE_M = (0.0, 0.1805, -0.285)  # HFE anchor -> KFE anchor (shank body origin)
KFE_TO_FOOT_M = (0.100, 0.01411, -0.36208)  # KFE anchor -> foot sphere centre (x shank_scale)

TOF_TILT_RANGE_DEG = (0.0, 45.0)  # valid outward tilt of the ToF optical axis [deg]


class FootKinematics(NamedTuple):
    """Foot and ToF-site poses in the base frame.

    Attributes:
      foot_pos: (..., 4, 3) foot-sphere centres [m], feet in constants.FEET order.
      tof_pos: (..., 4, 3) ToF site origins [m] (= foot-sphere centres).
      tof_rot: (..., 4, 3, 3) ToF site orientation; columns are the site x, y, z axes in the base
        frame (like MuJoCo's ``site_xmat`` reshaped (3, 3)); column 2 is the optical axis.
      knee_pos: (..., 4, 3) KFE joint anchors = knee-sphere centres [m].
    """

    foot_pos: jax.Array
    tof_pos: jax.Array
    tof_rot: jax.Array
    knee_pos: jax.Array


def leg_signs(leg: str) -> tuple[float, float]:
    """(sx, sy) mirror signs of a leg: sx = +1 front / -1 hind, sy = +1 left / -1 right."""
    if leg not in constants.FEET:
        raise ValueError(f"leg must be one of {constants.FEET}, got {leg!r}")
    return (1.0 if leg[1] == "F" else -1.0, 1.0 if leg[0] == "L" else -1.0)


def mirror(vec_lf, leg: str) -> np.ndarray:
    """Mirror an LF offset/COM (3,) to ``leg``: x *= sx, y *= sy."""
    sx, sy = leg_signs(leg)
    return np.asarray(vec_lf, dtype=np.float64) * np.array([sx, sy, 1.0])


def check_shank_scale(shank_scale: float) -> None:
    """config_check's env.model.shank_scale rule (limits.LEVEL_RANGES['shank_length'], the
    paper's model-mismatch study: +-20 %): its one-line ValueError if outside."""
    config_check.check_fields("env.model", {"shank_scale": float(shank_scale)})


def check_tof_tilt(tof_tilt_deg: float) -> None:
    lo, hi = TOF_TILT_RANGE_DEG
    if not lo <= float(tof_tilt_deg) <= hi:
        raise ValueError(f"tof_tilt_deg={tof_tilt_deg} outside the valid range [{lo}, {hi}] deg")


def tof_site_rotation(leg: str, tof_tilt_deg: float) -> np.ndarray:
    """(3, 3) ToF site axes (columns) in the shank frame, which is base-aligned at q = 0.

    Site +x = forward (+x); site +z = optical axis (0, sy sin t, -cos t): shank -z tilted by ``t``
    outward about x (left feet toward +y, right feet toward -y); site +y = z cross x. This is a
    rotation about x by ``pi + sy * t``.
    """
    check_tof_tilt(tof_tilt_deg)
    _, sy = leg_signs(leg)
    phi = math.pi + sy * math.radians(tof_tilt_deg)
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _rot_x(a: jax.Array) -> jax.Array:
    c, s = jp.cos(a), jp.sin(a)
    o, z = jp.ones_like(a), jp.zeros_like(a)
    return jp.stack(
        [jp.stack([o, z, z], -1), jp.stack([z, c, -s], -1), jp.stack([z, s, c], -1)], -2
    )


def _rot_y(a: jax.Array) -> jax.Array:
    c, s = jp.cos(a), jp.sin(a)
    o, z = jp.ones_like(a), jp.zeros_like(a)
    return jp.stack(
        [jp.stack([c, z, s], -1), jp.stack([z, o, z], -1), jp.stack([-s, z, c], -1)], -2
    )


def _leg_table(shank_scale: float, tof_tilt_deg: float) -> dict[str, np.ndarray]:
    """Per-leg constant offsets stacked in FEET order (NumPy, static)."""
    feet = constants.FEET
    return {
        "hip": np.stack([mirror(HIP_OFFSET_M, f) for f in feet]),  # (4, 3)
        "hfe": np.stack([mirror(HAA_TO_HFE_M, f) for f in feet]),  # (4, 3)
        "kfe": np.stack([mirror(HFE_TO_KFE_M, f) for f in feet]),  # (4, 3)
        "foot": np.stack([shank_scale * mirror(KFE_TO_FOOT_M, f) for f in feet]),  # (4, 3)
        "tof": np.stack([tof_site_rotation(f, tof_tilt_deg) for f in feet]),  # (4, 3, 3)
    }


def forward_kinematics(
    q: jax.Array, shank_scale: float = 1.0, tof_tilt_deg: float = constants.TOF_TILT_DEG
) -> FootKinematics:
    """Foot centres and ToF site poses in the base frame.

    Args:
      q: (..., 12) joint angles [rad] in constants.JOINT_NAMES order (HAA, HFE, KFE per leg).
      shank_scale: scale of the KFE -> foot offset (static, see check_shank_scale).
      tof_tilt_deg: outward tilt of the optical axis [deg] (static, in TOF_TILT_RANGE_DEG).

    Returns:
      FootKinematics with foot_pos (..., 4, 3) [m], tof_pos (..., 4, 3) [m], tof_rot (..., 4, 3, 3).
    """
    check_shank_scale(shank_scale)
    q = jp.asarray(q)
    if q.shape[-1:] != (constants.NUM_JOINTS,):
        raise ValueError(f"q must have shape (..., {constants.NUM_JOINTS}), got {q.shape}")
    t = _leg_table(shank_scale, tof_tilt_deg)
    dtype = q.dtype if jp.issubdtype(q.dtype, jp.floating) else jp.float32
    t = {k: jp.asarray(v, dtype=dtype) for k, v in t.items()}
    q = q.reshape(q.shape[:-1] + (constants.NUM_FEET, 3)).astype(dtype)  # (..., 4, 3)
    r_haa = _rot_x(q[..., 0])  # (..., 4, 3, 3) hip body orientation
    r_thigh = r_haa @ _rot_y(q[..., 1])
    r_shank = r_thigh @ _rot_y(q[..., 2])
    p_thigh = t["hip"] + jp.einsum("...ij,...j->...i", r_haa, t["hfe"])
    p_shank = p_thigh + jp.einsum("...ij,...j->...i", r_thigh, t["kfe"])
    foot = p_shank + jp.einsum("...ij,...j->...i", r_shank, t["foot"])
    tof_rot = r_shank @ t["tof"]
    return FootKinematics(foot_pos=foot, tof_pos=foot, tof_rot=tof_rot, knee_pos=p_shank)


def quat_to_mat(quat: jax.Array) -> jax.Array:
    """(..., 4) unit quaternion (w, x, y, z) -> (..., 3, 3) rotation matrix (body -> world)."""
    w, x, y, z = jp.moveaxis(quat, -1, 0)
    return jp.stack(
        [
            jp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            jp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            jp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def quat_rotate_inv(quat: jax.Array, v: jax.Array) -> jax.Array:
    """World vector(s) v (..., 3) in the frame of the unit quaternion ``quat`` (w, x, y, z)."""
    r = quat_to_mat(quat)
    return jp.einsum("ji,...j->...i", r, v)


def euler_to_quat(roll, pitch, yaw) -> jax.Array:
    """(4,) unit quaternion (w, x, y, z) of ZYX Euler angles [rad] (yaw, then pitch, then roll)."""
    cr, sr = jp.cos(roll / 2), jp.sin(roll / 2)
    cp, sp = jp.cos(pitch / 2), jp.sin(pitch / 2)
    cy, sy = jp.cos(yaw / 2), jp.sin(yaw / 2)
    return jp.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def yaw_from_quat(quat: jax.Array) -> jax.Array:
    """(..., 4) quaternion (w, x, y, z) -> (...,) yaw [rad] (ZYX Euler)."""
    w, x, y, z = jp.moveaxis(quat, -1, 0)
    return jp.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def base_to_world(pos_b: jax.Array, base_pos: jax.Array, base_quat: jax.Array) -> jax.Array:
    """Points in the base frame -> world frame.

    Args:
      pos_b: (..., K, 3) points in the base frame [m].
      base_pos: (..., 3) world base position [m] (qpos[0:3]).
      base_quat: (..., 4) base orientation (w, x, y, z) (qpos[3:7]).

    Returns:
      (..., K, 3) world points [m].
    """
    r = quat_to_mat(base_quat)
    return jp.einsum("...ij,...kj->...ki", r, pos_b) + base_pos[..., None, :]


def rot_base_to_world(rot_b: jax.Array, base_quat: jax.Array) -> jax.Array:
    """(..., K, 3, 3) frames, base frame -> world frame; base_quat (..., 4) is (w, x, y, z)."""
    return quat_to_mat(base_quat)[..., None, :, :] @ rot_b


def world_foot_kinematics(
    qpos: jax.Array, shank_scale: float = 1.0, tof_tilt_deg: float = constants.TOF_TILT_DEG
) -> FootKinematics:
    """Foot / ToF poses in the world frame from a full (..., 19) qpos (free joint + 12 joints)."""
    fk = forward_kinematics(qpos[..., 7:19], shank_scale, tof_tilt_deg)
    foot = base_to_world(fk.foot_pos, qpos[..., 0:3], qpos[..., 3:7])
    return FootKinematics(
        foot_pos=foot,
        tof_pos=foot,
        tof_rot=rot_base_to_world(fk.tof_rot, qpos[..., 3:7]),
        knee_pos=base_to_world(fk.knee_pos, qpos[..., 0:3], qpos[..., 3:7]),
    )


def nominal_base_height(
    q=constants.DEFAULT_POSE,
    shank_scale: float = 1.0,
    foot_radius_m: float = constants.FOOT_RADIUS_M,
) -> float:
    """Base height [m] over flat ground at level base orientation with the lowest foot touching."""
    fk = forward_kinematics(np.asarray(q, dtype=np.float64), shank_scale)
    return float(-np.min(np.asarray(fk.foot_pos)[:, 2]) + foot_radius_m)
