"""What the mock sources read under standing feet on flat ground, per robustness-sweep level.

    python scripts/mock_stance_readings.py   # a few seconds on 1 core

The robot stands level in ``constants.DEFAULT_POSE`` on flat ground with the true (physics)
shank scale s, so the mapped ground lies ``kinematics.nominal_base_height(DEFAULT_POSE, s)``
below the base. The mocks place the sensors by the *nominal* kinematics of the *measured* joints
(true joints + the static offset), ``sources.sensor_sites_in_scan_frame``, and read the flat scan
through ``sources.readings_from_scan`` (the one path of mock_ideal and mock_aggre). For each
shank_length and joint_offset level, one line per foot: the believed site's height over the
mapped ground, the true site's (what ``tof`` sees), and the mock's median reading and number of
valid zones (of 16); for comparison the ``tof`` reading of the true sensor on the same ground.
"""

import os
import sys

import jax
import jax.numpy as jp
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from foottof import constants  # noqa: E402
from foottof.perception import elevation_map as em  # noqa: E402
from foottof.perception import sources  # noqa: E402
from foottof.robot import kinematics as kin  # noqa: E402
from foottof.sensors import tof  # noqa: E402

SPEC = tof.ToFSpec()
LEVEL_QUAT = jp.array([1.0, 0.0, 0.0, 0.0], jp.float32)  # level base (IMU roll = pitch = 0)
CASES = (  # (perturbation, level, shank scale, joint offset [rad])
    ("shank_length", 0.8, 0.8, 0.0),
    ("shank_length", 0.9, 0.9, 0.0),
    ("shank_length", 1.0, 1.0, 0.0),
    ("shank_length", 1.1, 1.1, 0.0),
    ("shank_length", 1.2, 1.2, 0.0),
    ("joint_offset", 0.05, 1.0, 0.05),
    ("joint_offset", 0.1, 1.0, 0.1),
)


@jax.jit
def _readings(scan, q_true_sites, q_measured):
    """(mock reading, tof reading of the true sites) on the flat scan."""
    pos, rot = q_true_sites
    return (
        sources.readings_from_scan(SPEC, scan, LEVEL_QUAT, q_measured),
        tof.sense(SPEC, em.scan_heightfield(scan), pos, rot),
    )


def stance_rows(shank_scale: float, joint_offset_rad: float) -> list[dict]:
    """One dict per foot (constants.FEET order) for one sweep level."""
    q = np.asarray(constants.DEFAULT_POSE, np.float64)
    ground = -kin.nominal_base_height(q, shank_scale)  # flat ground relative to the base [m]
    true = kin.forward_kinematics(jp.asarray(q, jp.float32), shank_scale)
    q_meas = jp.asarray(q + joint_offset_rad, jp.float32)  # static offset on all 12 readings
    believed, _ = sources.sensor_sites_in_scan_frame(LEVEL_QUAT, q_meas)
    scan = jp.full((em.SCAN_N, em.SCAN_N), ground, jp.float32)
    mock, real = _readings(scan, (true.tof_pos, true.tof_rot), q_meas)
    rows = []
    for f, leg in enumerate(constants.FEET):
        rows.append(
            {
                "foot": leg,
                "believed_site_over_ground_m": float(believed[f, 2]) - ground,
                "true_site_over_ground_m": float(true.tof_pos[f, 2]) - ground,
                "mock_median_m": float(np.median(np.asarray(mock.distance_m[f]))),
                "mock_valid": int(np.asarray(mock.valid[f]).sum()),
                "tof_median_m": float(np.median(np.asarray(real.distance_m[f]))),
                "tof_valid": int(np.asarray(real.valid[f]).sum()),
            }
        )
    return rows


def main() -> None:
    print(
        "perturbation  level foot  believed_site_m  true_site_m  mock_median_m  mock_valid"
        "  tof_median_m  tof_valid"
    )
    for name, level, scale, offset in CASES:
        for r in stance_rows(scale, offset):
            print(
                f"{name:13s} {level:5.2f} {r['foot']:4s} {r['believed_site_over_ground_m']:+15.4f}"
                f" {r['true_site_over_ground_m']:+12.4f} {r['mock_median_m']:14.3f}"
                f" {r['mock_valid']:7d}/16 {r['tof_median_m']:13.3f} {r['tof_valid']:7d}/16"
            )


if __name__ == "__main__":
    main()
