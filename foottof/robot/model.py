"""ANYmal-D MuJoCo model built from primitives (MJCF written here), for MJX simulation."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from foottof import config_check, constants
from foottof.robot import kinematics as kin
from foottof.terrain.heightfield import Heightfield, hfield_xml, write_to_mjmodel

# Inertials of the ANYmal-D URDF (ANYbotics/anymal_d_simple_description urdf/anymal.urdf, links
# joined by fixed joints lumped): mass [kg], COM [m] rel. to the body origin, inertia about the
# COM in base-aligned axes (Ixx, Iyy, Izz, Ixy, Ixz, Iyz) [kg m^2]. Leg figures are for LF.
BASE_INERTIAL = (
    26.3631,
    (-0.0164, 0.0007, -0.0120),
    (0.2518, 1.4679, 1.5340, 0.0051, 0.0239, 0.0006),
)
LEG_INERTIALS = {
    "hip": (
        0.36586,
        (0.03505, -0.00123, 0.0),
        (2.385e-4, 5.582e-4, 4.433e-4, 3.26e-6, 1.3e-8, 1.8e-8),
    ),
    "thigh": (
        5.13220,
        (-0.00009, 0.09051, -0.14019),
        (0.1080, 0.1049, 0.01393, 1.42e-4, 4.03e-4, 0.02006),
    ),
    "shank": (
        0.79598,
        (0.05093, 0.00809, -0.09002),
        (0.01666, 0.01891, 2.531e-3, 5.43e-5, 3.549e-3, 6.23e-5),
    ),
}
TOTAL_MASS_KG = BASE_INERTIAL[0] + 4 * sum(v[0] for v in LEG_INERTIALS.values())  # 51.539 kg

# Joint ranges of the ANYmal-D URDF [rad]: HAA of the left legs (mirrored for right legs); HFE/KFE +-3 pi.
HAA_RANGE_LEFT = (-0.7854, 0.6109)
FLEX_RANGE = (-9.4248, 9.4248)

# Collision proxies: spheres only. MJX collides a geom with a square patch of
# ceil(2 * radius / cell) + 1 hfield cells per side (2 prisms per cell), so the cost grows with
# (radius / cell)^2. The radii are just below multiples of 2 cm so that on a 4 cm grid the patches
# are 3x3 (feet), 4x4 (knees) and 5x5 (base) cells.
# Base: 4 spheres along the underside of the 0.894 x 0.16 x 0.256 m base box (centre z = +0.016,
# bottom at z = -0.112): their bottoms touch the box bottom, together they span x = +-0.447.
BASE_SPHERE_RADIUS_M = 0.0795
BASE_SPHERE_CENTRES_M = tuple(
    (x, 0.0, -0.112 + BASE_SPHERE_RADIUS_M) for x in (-0.3675, -0.1175, 0.1175, 0.3675)
)
KNEE_SPHERE_RADIUS_M = 0.0595  # one per knee, centred on the KFE axis (shank cylinder r = 0.071)

# Physics tuning defaults (mirrored field by field in configs/_env.py, section env.model).
DEFAULT_TUNING = {
    "armature": 0.02,  # reflected rotor inertia added to every leg joint [kg m^2]
    "joint_damping": 0.0,  # passive viscous joint damping (MuJoCo side) [N m s/rad]
    "foot_friction": 1.0,  # sliding friction coefficient of the foot spheres [-]
    "body_friction": 0.6,  # sliding friction coefficient of base and knee spheres [-]
    "body_condim": 3,  # contact dimension of base and knee spheres: 1 frictionless | 3
    "body_collision": True,  # base/knee spheres collide (False: kept, named, but not colliding)
    "solref_timeconst": 0.02,  # contact solref[0] time constant [s] (>= 2 * timestep)
    "solref_dampratio": 1.0,  # contact solref[1] damping ratio [-]
    "solver": "newton",  # constraint solver: newton | cg
    "iterations": 10,  # max solver iterations (1 lets standing feet slide ~14 cm in 5 s; at 2
    # MuJoCo C's unconverged solve fails 22 % of random-action episodes, bench/NOTES.md)
    "ls_iterations": 10,  # max line-search iterations
    "cone": "pyramidal",  # friction cone: pyramidal | elliptic
    "impratio": 100.0,  # frictional-to-normal impedance ratio [-] (1 lets feet creep ~26 cm/20 s)
    "eulerdamp": False,  # implicit joint damping in the Euler integrator (off: faster)
    "timestep": constants.PHYSICS_DT_S,  # physics step [s]
}
_SOLVER_MJCF = {"newton": "Newton", "cg": "CG"}


def _f(x) -> str:
    return " ".join(f"{float(v):.10g}" for v in np.atleast_1d(x))


def _mirror_inertia(inertia, leg: str) -> np.ndarray:
    """LF (Ixx, Iyy, Izz, Ixy, Ixz, Iyz) -> ``leg``: Ixy *= sx sy, Ixz *= sx, Iyz *= sy."""
    sx, sy = kin.leg_signs(leg)
    return np.asarray(inertia, dtype=np.float64) * np.array([1, 1, 1, sx * sy, sx, sy])


def _inertial(mass, com, inertia) -> str:
    return f'<inertial pos="{_f(com)}" mass="{_f(mass)}" fullinertia="{_f(inertia)}"/>'


def _validate_tuning(
    tuning: dict, shank_scale: float = 1.0, foot_radius_m: float = constants.FOOT_RADIUS_M
) -> dict:
    """The tuning (DEFAULT_TUNING updated by ``tuning``) after config_check's env.model rules
    (on it and on the model geometry ``shank_scale``, ``foot_radius_m``).

    Raises:
      ValueError: an unknown key, or a value outside its rule (config_check's one-line error).
    """
    unknown = sorted(set(tuning) - set(DEFAULT_TUNING))
    if unknown:
        raise ValueError(f"unknown tuning keys {unknown}; valid keys: {sorted(DEFAULT_TUNING)}")
    t = {**DEFAULT_TUNING, **tuning}
    config_check.check_fields(  # the env.model.* rules, held once (foottof.config_check)
        "env.model",
        {"shank_scale": float(shank_scale), "foot_radius_m": float(foot_radius_m), **t},
    )
    return t


def _leg_xml(leg: str, shank_scale: float, tof_tilt_deg: float, foot_radius_m: float) -> str:
    sx, sy = kin.leg_signs(leg)
    hip = kin.mirror(kin.HIP_OFFSET_M, leg)
    hfe = kin.mirror(kin.HAA_TO_HFE_M, leg)
    kfe = kin.mirror(kin.HFE_TO_KFE_M, leg)
    foot = shank_scale * kin.mirror(kin.KFE_TO_FOOT_M, leg)
    haa_range = HAA_RANGE_LEFT if sy > 0 else (-HAA_RANGE_LEFT[1], -HAA_RANGE_LEFT[0])
    inert = {
        k: (m, kin.mirror(com, leg), _mirror_inertia(i, leg))
        for k, (m, com, i) in LEG_INERTIALS.items()
    }
    rot = kin.tof_site_rotation(leg, tof_tilt_deg)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot.reshape(-1))
    return f"""
    <body name="{leg}_hip" pos="{_f(hip)}">
      {_inertial(*inert["hip"])}
      <joint name="{leg}_HAA" axis="1 0 0" range="{_f(haa_range)}"/>
      <geom class="visual" type="capsule" size="0.05" fromto="0 0 0 {_f(hfe)}"/>
      <body name="{leg}_thigh" pos="{_f(hfe)}">
        {_inertial(*inert["thigh"])}
        <joint name="{leg}_HFE" axis="0 1 0" range="{_f(FLEX_RANGE)}"/>
        <geom class="visual" type="capsule" size="0.04" fromto="0 0 0 {_f(kfe)}"/>
        <body name="{leg}_shank" pos="{_f(kfe)}">
          {_inertial(*inert["shank"])}
          <joint name="{leg}_KFE" axis="0 1 0" range="{_f(FLEX_RANGE)}"/>
          <geom class="visual" type="capsule" size="0.0175" fromto="0 0 0 {_f(foot)}"/>
          <geom name="{leg}_knee" class="body_collision" size="{KNEE_SPHERE_RADIUS_M}"/>
          <geom name="{leg}_foot" class="foot" pos="{_f(foot)}" size="{_f(foot_radius_m)}"/>
          <site name="{leg}_tof" pos="{_f(foot)}" quat="{_f(quat)}" size="0.01"/>
        </body>
      </body>
    </body>"""


def make_model_xml(
    hfield: Heightfield | None = None,
    *,
    shank_scale: float = 1.0,
    tof_tilt_deg: float = constants.TOF_TILT_DEG,
    foot_radius_m: float = constants.FOOT_RADIUS_M,
    **tuning,
) -> str:
    """MJCF text of the robot on a plane or a heightfield (see :func:`make_model`)."""
    kin.check_tof_tilt(tof_tilt_deg)
    t = _validate_tuning(tuning, shank_scale, foot_radius_m)

    terrain_attrs = 'contype="0" conaffinity="1" condim="3" rgba="0.5 0.55 0.6 1"'
    if hfield is None:
        asset = ""
        ground = f'<geom name="terrain" type="plane" size="0 0 0.05" {terrain_attrs}/>'
    else:
        asset, ground = hfield_xml(hfield, "terrain", terrain_attrs)

    h0 = kin.nominal_base_height(constants.DEFAULT_POSE, shank_scale, foot_radius_m)
    key_qpos = _f([0.0, 0.0, h0, 1.0, 0.0, 0.0, 0.0, *constants.DEFAULT_POSE])
    legs = "".join(
        _leg_xml(leg, shank_scale, tof_tilt_deg, foot_radius_m) for leg in constants.FEET
    )
    base_spheres = "".join(
        f'<geom name="base_{i}" class="body_collision" pos="{_f(c)}" '
        f'size="{BASE_SPHERE_RADIUS_M}"/>'
        for i, c in enumerate(BASE_SPHERE_CENTRES_M)
    )
    ctrlrange = _f([-constants.TORQUE_LIMIT_NM, constants.TORQUE_LIMIT_NM])
    actuators = "".join(
        f'<motor name="{j}" joint="{j}" ctrlrange="{ctrlrange}"/>' for j in constants.JOINT_NAMES
    )
    solref = _f([t["solref_timeconst"], t["solref_dampratio"]])
    eulerdamp = "enable" if t["eulerdamp"] else "disable"
    body_con = 1 if t["body_collision"] else 0
    return f"""<mujoco model="anymal_d">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{_f(t["timestep"])}" integrator="Euler" solver="{_SOLVER_MJCF[t["solver"]]}"
          iterations="{int(t["iterations"])}" ls_iterations="{int(t["ls_iterations"])}"
          cone="{t["cone"]}" impratio="{_f(t["impratio"])}">
    <flag eulerdamp="{eulerdamp}"/>
  </option>
  <default>
    <joint armature="{_f(t["armature"])}" damping="{_f(t["joint_damping"])}"/>
    <geom solref="{solref}"/>
    <default class="visual">
      <geom contype="0" conaffinity="0" group="1" density="0" rgba="0.3 0.3 0.3 1"/>
    </default>
    <default class="body_collision">
      <geom type="sphere" contype="{body_con}" conaffinity="0" condim="{int(t["body_condim"])}"
            priority="1" group="3" friction="{_f(t["body_friction"])} 0.005 0.0001"
            rgba="0.8 0.3 0.3 0.4"/>
    </default>
    <default class="foot">
      <geom type="sphere" contype="1" conaffinity="0" condim="3" priority="1"
            friction="{_f(t["foot_friction"])} 0.005 0.0001" rgba="0.1 0.1 0.1 1"/>
    </default>
  </default>
  <asset>{asset}</asset>
  <worldbody>
    <light name="sun" pos="0 0 5" dir="0 0 -1" directional="true"/>
    {ground}
    <body name="{constants.BASE_BODY}" pos="0 0 {_f(h0)}">
      <freejoint name="root"/>
      {_inertial(*BASE_INERTIAL)}
      <geom class="visual" type="box" size="0.447 0.08075 0.128" pos="0 0 0.016"/>
      {base_spheres}{legs}
    </body>
  </worldbody>
  <actuator>{actuators}</actuator>
  <keyframe>
    <key name="standing" qpos="{key_qpos}" ctrl="{_f(np.zeros(constants.NUM_JOINTS))}"/>
  </keyframe>
</mujoco>
"""


def make_model(
    hfield: Heightfield | None = None,
    *,
    shank_scale: float = 1.0,
    tof_tilt_deg: float = constants.TOF_TILT_DEG,
    foot_radius_m: float = constants.FOOT_RADIUS_M,
    **tuning,
) -> mujoco.MjModel:
    """Compiled ANYmal-D model on flat ground (``hfield=None``) or on a heightfield.

    Bodies ``base`` (free joint: qpos[0:7] = pos, quat wxyz) and ``{leg}_hip/_thigh/_shank``;
    hinge joints constants.JOINT_NAMES (qpos[7:19], qvel[6:18]); 12 ``motor`` actuators in the
    same order (ctrl = joint torque [N m], ctrlrange +-80). The ground geom is named ``terrain``
    (a plane, or an hfield whose data is written from ``hfield``). Only robot-vs-terrain contacts:
    foot spheres ``{leg}_foot``, knee spheres ``{leg}_knee`` and base spheres ``base_<i>``. ToF
    sites ``{leg}_tof`` sit at the foot-sphere centres (axes: see kinematics.tof_site_rotation).
    Keyframe ``standing``: DEFAULT_POSE with the feet touching z = 0.

    Args:
      hfield: terrain heights, or None for a plane at z = 0.
      shank_scale: scale of the KFE -> foot offset (foot sphere, ToF site, visual shank) in
        [0.8, 1.2]; masses and inertias unchanged.
      tof_tilt_deg: outward tilt of the ToF optical axis in [0, 45] deg.
      foot_radius_m: foot sphere radius in foottof.limits.FOOT_RADIUS_RANGE_M [m].
      **tuning: physics settings, keys of DEFAULT_TUNING (configs/_env.py section ``env.model``).

    Returns:
      The compiled ``mujoco.MjModel``.
    """
    xml = make_model_xml(
        hfield,
        shank_scale=shank_scale,
        tof_tilt_deg=tof_tilt_deg,
        foot_radius_m=foot_radius_m,
        **tuning,
    )
    m = mujoco.MjModel.from_xml_string(xml)
    if hfield is not None:
        write_to_mjmodel(m, hfield, "terrain")
    return m


def default_qpos(
    base_height: float | None = None,
    *,
    xy=(0.0, 0.0),
    yaw: float = 0.0,
    shank_scale: float = 1.0,
    foot_radius_m: float = constants.FOOT_RADIUS_M,
) -> np.ndarray:
    """(19,) qpos of the nominal stance (DEFAULT_POSE), level base.

    Args:
      base_height: world z of the base [m]; None = feet touching a flat ground at z = 0.
      xy: world (x, y) of the base [m].
      yaw: heading about +z [rad].
      shank_scale, foot_radius_m: model geometry used for the default height.
    """
    if base_height is None:
        base_height = kin.nominal_base_height(constants.DEFAULT_POSE, shank_scale, foot_radius_m)
    quat = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
    return np.array([xy[0], xy[1], base_height, *quat, *constants.DEFAULT_POSE], dtype=np.float64)
