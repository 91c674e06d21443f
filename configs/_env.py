"""Env section, robot part: PD gains and MuJoCo physics settings (task fields: configs/_task.py)."""

import ml_collections

from foottof.robot.model import DEFAULT_TUNING


def get_section() -> ml_collections.ConfigDict:
    e = ml_collections.ConfigDict()
    e.kp = 80.0  # joint PD stiffness [N m/rad] (legged_gym ANYmal PD)
    e.kd = 2.0  # joint PD damping [N m s/rad]
    m = ml_collections.ConfigDict()
    for k, v in DEFAULT_TUNING.items():  # see foottof/robot/model.py DEFAULT_TUNING for meanings
        m[k] = v
    e.model = m  # physics settings passed to foottof.robot.make_model(**env.model)
    return e
