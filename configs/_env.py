"""Env section: robot model physics (env.model) and joint PD control (env.control)."""

import ml_collections


def get_model_section() -> ml_collections.ConfigDict:
    """Keyword arguments of foottof.robot.make_model (defaults = model.DEFAULT_TUNING)."""
    m = ml_collections.ConfigDict()
    m.shank_scale = 1.0  # KFE->foot offset scale, physics only (model-mismatch sweep) [-], 0.8..1.2
    m.foot_radius_m = 0.0315  # foot contact sphere radius [m], 0.02..0.05
    m.armature = 0.02  # reflected rotor inertia on every leg joint (tuning, not public) [kg m^2]
    m.joint_damping = 0.0  # passive joint damping in MuJoCo; PD damping is control.kd [N m s/rad]
    m.foot_friction = 1.0  # foot sliding friction coefficient [-]
    m.body_friction = 0.6  # base/knee sphere sliding friction coefficient [-]
    m.body_condim = 3  # contact dimension of base/knee spheres: 1 (frictionless) or 3
    m.body_collision = True  # base/knee spheres collide with the terrain (False: ~3x faster MJX)
    m.solref_timeconst = 0.02  # contact stiffness time constant [s], >= 2 * timestep
    m.solref_dampratio = 1.0  # contact damping ratio [-]
    m.solver = "newton"  # MuJoCo constraint solver: newton | cg
    m.iterations = 2  # solver iterations per physics step
    m.ls_iterations = 4  # line-search iterations per solver iteration
    m.cone = "pyramidal"  # friction cone: pyramidal | elliptic
    m.impratio = 100.0  # friction-to-normal impedance ratio [-]; 1 lets standing feet creep
    m.eulerdamp = False  # implicit joint damping in the Euler integrator (off: faster)
    m.timestep = 0.005  # physics step [s] (200 Hz); must divide constants.CONTROL_DT_S
    return m


def get_control_section() -> ml_collections.ConfigDict:
    """Keyword arguments of foottof.robot.pd_torque / control_step (same names)."""
    c = ml_collections.ConfigDict()
    c.kp = 150.0  # joint PD stiffness [N m/rad] (80 sags 3 cm, dips 7 cm on landing)
    c.kd = 5.0  # joint PD damping [N m s/rad]
    c.torque_limit = 80.0  # continuous joint torque limit [N m]
    c.velocity_limit = 8.5  # speed where drive torque along the motion hits 0 [rad/s]
    c.saturation_torque = 120.0  # DC-motor line peak torque [N m]; None = constant clip only
    return c


def get_section() -> ml_collections.ConfigDict:
    e = ml_collections.ConfigDict()
    e.physics = "auto"  # auto (MuJoCo C on a CPU JAX backend, else MJX) | mjx | mujoco
    e.physics_threads = 0  # MuJoCo C threads (env.physics = mujoco); 0 = os.cpu_count()
    e.model = get_model_section()  # physics: make_model(hfield, tof_tilt_deg=..., **env.model)
    e.control = get_control_section()  # PD law: pd_torque(q_target, q, qd, **env.control)
    return e
