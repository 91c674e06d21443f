"""ANYmal-D robot: MuJoCo model from primitives, analytic kinematics, and the joint PD law."""

from foottof.robot.control import pd_torque, torque_bounds
from foottof.robot.kinematics import (
    FootKinematics,
    base_to_world,
    forward_kinematics,
    nominal_base_height,
    quat_to_mat,
    rot_base_to_world,
    world_foot_kinematics,
)
from foottof.robot.model import DEFAULT_TUNING, default_qpos, make_model, make_model_xml

__all__ = [
    "DEFAULT_TUNING",
    "FootKinematics",
    "base_to_world",
    "default_qpos",
    "forward_kinematics",
    "make_model",
    "make_model_xml",
    "nominal_base_height",
    "pd_torque",
    "quat_to_mat",
    "rot_base_to_world",
    "torque_bounds",
    "world_foot_kinematics",
]
