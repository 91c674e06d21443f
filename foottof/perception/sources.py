"""Mock foot readings: ToF rays cast into the ideal scan (mock_ideal) or the map (mock_aggre)."""

from __future__ import annotations

import jax
import jax.numpy as jp

from foottof import constants
from foottof.perception import elevation_map as em
from foottof.robot.kinematics import forward_kinematics, yaw_from_quat
from foottof.sensors import tof
from foottof.terrain.heightfield import Heightfield


def _check_sensor_feet(spec: tof.ToFSpec, sensor_feet) -> tuple[int, ...]:
    feet = tuple(range(constants.NUM_FEET)) if sensor_feet is None else tuple(sensor_feet)
    if len(feet) != spec.num_sensors or any(not 0 <= f < constants.NUM_FEET for f in feet):
        raise ValueError(
            f"sensor_feet={sensor_feet!r} must give one foot index in [0, {constants.NUM_FEET}) "
            f"(order {constants.FEET}) per sensor (num_sensors={spec.num_sensors})"
        )
    return feet


def sensor_sites_in_scan_frame(
    base_quat: jax.Array,
    q_measured: jax.Array,
    sensor_feet: tuple[int, ...] = tuple(range(constants.NUM_FEET)),
) -> tuple[jax.Array, jax.Array]:
    """ToF site poses the robot *believes* in, in the scan frame (yaw frame, origin at the base).

    Nominal kinematics (shank_scale = 1, nominal ToF tilt) of the measured joints give the site
    poses in the base frame; the known roll and pitch (IMU) rotate them into the gravity-aligned
    yaw frame. Joint offsets and unmodelled shank lengths therefore move the emulated sensors.

    Args:
      base_quat: (4,) base orientation (w, x, y, z); only roll and pitch are used.
      q_measured: (12,) measured joint positions [rad] (constants.JOINT_NAMES order).
      sensor_feet: static foot index (constants.FEET order) of each sensor's site.

    Returns:
      site_pos (F, 3) [m] relative to the base, site_rot (F, 3, 3) axes as columns.
    """
    fk = forward_kinematics(q_measured, shank_scale=1.0, tof_tilt_deg=constants.TOF_TILT_DEG)
    tilt = em.tilt_rotation(base_quat).astype(fk.tof_pos.dtype)
    idx = jp.asarray(sensor_feet)
    pos = jp.einsum("ij,fj->fi", tilt, fk.tof_pos[idx])
    rot = tilt @ fk.tof_rot[idx]
    return pos, rot


def sense_mapped(
    spec: tof.ToFSpec, hfield: Heightfield, site_pos: jax.Array, site_rot: jax.Array
) -> tof.ToFReading:
    """Emulated foot frame on a mapped surface: :func:`foottof.sensors.tof.sense`, plus contact.

    The emulated sensors sit where nominal kinematics of the measured joints put them, which can
    be inside the mapped solid (e.g. a shorter real shank: the believed foot lies below the ground
    the real foot stands on). A ray starting inside the solid passes through it, as ``mj_ray``
    does, so ``tof.sense`` would read no ground (max range, invalid) under a foot that stands.
    Contact rule: a sensor whose origin (site + ``spec.offset_m``) lies strictly below the
    surface at its xy (:meth:`Heightfield.height_at`, the triangulation the rays hit) reads the
    distance to the surface clipped at zero in every zone: 0 m, valid, incidence 0 (no hit point;
    the spec has no minimum range, and ``degradation.degrade`` clips negative readings to a
    valid 0 m the same way). Sensors on or above the surface read exactly ``tof.sense``.

    Args:
      spec: ToF sensor spec (static).
      hfield: the mapped surface (e.g. ``elevation_map.scan_heightfield(scan)``).
      site_pos: (F, 3) sensor site positions in the surface's frame [m].
      site_rot: (F, 3, 3) site axes as columns.

    Returns:
      ToFReading with (F, Z) distance_m, valid and incidence_rad.
    """
    reading = tof.sense(spec, hfield, site_pos, site_rot)
    origin, _ = tof.sensor_frames(spec, site_pos, site_rot)
    contact = (origin[:, 2] < hfield.height_at(origin[:, :2]))[:, None]  # (F, 1) inside solid
    return tof.ToFReading(
        distance_m=jp.where(contact, 0.0, reading.distance_m).astype(reading.distance_m.dtype),
        valid=reading.valid | contact,
        incidence_rad=jp.where(contact, 0.0, reading.incidence_rad).astype(
            reading.incidence_rad.dtype
        ),
    )


def readings_from_scan(
    spec: tof.ToFSpec,
    scan: jax.Array,
    base_quat: jax.Array,
    q_measured: jax.Array,
    sensor_feet: tuple[int, ...] | None = None,
) -> tof.ToFReading:
    """Emulate the foot ToF frame by casting the sensor's rays into a robot-centric height scan.

    Uses exactly the ``tof`` source's pipeline (:func:`foottof.sensors.tof.sense`: the same 41
    rays per sensor, zone minimum, quantization and clipping, extra tilts and offsets of ``spec``)
    on ``scan`` wrapped as a Heightfield (elevation_map.scan_heightfield); only the surface and
    the sensor poses differ, plus the contact rule of :func:`sense_mapped` (a believed sensor
    below the mapped surface reads 0 m, valid). Cells the map has never seen hold
    UNKNOWN_HEIGHT_M (4 m below the base), so rays over them get no return: distance = max
    range, valid = False.

    Args:
      spec: ToF sensor spec (static).
      scan: (101, 101) heights relative to the base z [m] in the scan frame.
      base_quat: (4,) base orientation (w, x, y, z); roll and pitch are used.
      q_measured: (12,) measured joint positions [rad].
      sensor_feet: static foot index per sensor; default sensor f on foot f (needs 4 sensors).

    Returns:
      ToFReading with (F, Z) distance_m, valid and incidence_rad.
    """
    feet = _check_sensor_feet(spec, sensor_feet)
    pos, rot = sensor_sites_in_scan_frame(base_quat, q_measured, feet)
    return sense_mapped(spec, em.scan_heightfield(scan), pos, rot)


def mock_ideal_readings(
    spec: tof.ToFSpec,
    hfield: Heightfield,
    base_pos: jax.Array,
    base_quat: jax.Array,
    q_measured: jax.Array,
    sensor_feet: tuple[int, ...] | None = None,
) -> tof.ToFReading:
    """``mock_ideal`` source: foot readings emulated from the ideal height scan around the base.

    Args:
      spec: ToF sensor spec (static).
      hfield: world terrain.
      base_pos: (3,) true world base position [m] (the scan is centred on it).
      base_quat: (4,) true base orientation (w, x, y, z).
      q_measured: (12,) measured joint positions [rad] (with any static offset).
      sensor_feet: static foot index per sensor (default: one per foot).

    Returns:
      ToFReading with (F, Z) arrays, same layout as the ``tof`` source.
    """
    scan = em.height_scan(hfield, base_pos, yaw_from_quat(base_quat))
    return readings_from_scan(spec, scan, base_quat, q_measured, sensor_feet)


def mock_aggre_readings(
    spec: tof.ToFSpec,
    state: em.ElevationMapState,
    base_quat: jax.Array,
    q_measured: jax.Array,
    sensor_feet: tuple[int, ...] | None = None,
) -> tof.ToFReading:
    """``mock_aggre`` source: foot readings emulated from the aggregated elevation map.

    Call after :func:`elevation_map.aggre_update` of this step (``state.scan`` is the map in the
    current base frame as the robot believes it).

    Args:
      spec: ToF sensor spec (static).
      state: elevation map of this env.
      base_quat: (4,) base orientation (w, x, y, z); roll and pitch are used.
      q_measured: (12,) measured joint positions [rad].
      sensor_feet: static foot index per sensor (default: one per foot).

    Returns:
      ToFReading with (F, Z) arrays, same layout as the ``tof`` source.
    """
    return readings_from_scan(spec, state.scan, base_quat, q_measured, sensor_feet)
