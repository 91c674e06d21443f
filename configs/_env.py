"""Env section: robot model physics (env.model), joint PD control (env.control) and the task."""

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
    m.iterations = 10  # max solver iterations per step (2: MuJoCo C falls, bench/NOTES.md)
    m.ls_iterations = 10  # max line-search iterations per solver iteration
    m.cone = "pyramidal"  # friction cone: pyramidal | elliptic
    m.impratio = 100.0  # friction-to-normal impedance ratio [-]; 1 lets standing feet creep
    m.eulerdamp = False  # implicit joint damping in the Euler integrator (off: faster)
    m.timestep = 0.005  # physics step [s] (200 Hz); must divide constants.CONTROL_DT_S
    return m


def get_control_section() -> ml_collections.ConfigDict:
    """Keyword arguments of foottof.robot.pd_torque and the physics backends (same names)."""
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
    e.model = get_model_section()  # physics: make_model(hfield, **env.model)
    e.control = get_control_section()  # PD law: pd_torque(q_target, q, qd, **env.control)
    return _add_task_fields(e)


def _add_task_fields(e: ml_collections.ConfigDict) -> ml_collections.ConfigDict:
    """Adds the goal-reaching task fields: episode, observations, terminations, randomization."""
    e.source = "tof"  # foot-reading source: tof | mock_ideal | mock_aggre
    e.episode_length_s = 10.0  # episode length: the goal is ~4.7 m from the spawn on a 6 m tile [s]
    e.clip_actions = 5.0  # actions are clipped to +-this before scaling [-]
    e.clip_observations = 100.0  # observations are clipped to +-this (rsl_rl convention) [-]
    e.clip_reward = 100.0  # each scaled reward term is clipped to +-this per step [-]
    e.max_joint_speed_rads = 100.0  # faster joints/base mean the simulation diverged: fail [rad/s]
    e.contact_margin_m = 0.01  # a foot within this of the surface counts as in contact [m]
    e.body_contact_margin_m = (
        0.0  # base sphere clearance below this terminates; knees: see below [m]
    )
    e.knee_contact_terminates = (
        False  # knee contact ends the episode (else reward.scales.collision)
    )
    e.bootstrap_time_limit = False  # bootstrap V at the deadline; False: the deadline is terminal
    e.fall_height_above_floor_m = 0.5  # base below pit floor + this terminates (fell in a gap) [m]
    e.foot_fall_z_m = -0.45  # a foot below this world z terminates (deep in a gap) [m]
    # A foot centre this far below the highest terrain within 5 cm of it, beside a gap, terminates
    # (the foot went into a gap: wedged or falling; 0 = off); logged as episode/foot_stuck [m].
    e.foot_stuck_depth_m = 0.12
    e.actor_terrain = False  # teacher: the actor also reads true foot patches + a 0.6 m scan
    # teacher: those terrain inputs only where a foot ToF ray has hit this episode, + seen flags
    e.actor_terrain_seen = False
    # teacher: also the points between those 10 cm samples, 5 cm apart (foottof.envs.fine_terrain)
    e.actor_terrain_fine = False
    e.critic_height_scan = False  # critic also sees 171 terrain heights around/ahead of the base
    e.max_tilt_deg = 60.0  # base tilt beyond this terminates [deg]
    e.init_joint_noise_rad = 0.05  # initial joint angles ~ default + U(+-this) [rad]
    e.init_roll_pitch_rad = 0.0  # initial roll, pitch ~ U(+-this) [rad] (wider in stage 2)
    e.spawn_height_offset_m = 0.02  # spawn the feet this high above the platform [m]
    e.push_interval_s = 6.0  # mean time between random pushes [s]
    r = ml_collections.ConfigDict()
    r.enabled = True  # per-episode domain randomization on/off
    r.nominal_friction = 1.0  # foot friction when randomization is off [-]
    r.friction_range = (0.4, 1.2)  # foot friction ~ U(range) [-]
    r.added_mass_kg_range = (-2.0, 5.0)  # base mass offset ~ U(range) [kg]
    r.motor_strength_range = (0.9, 1.1)  # PD torque multiplier ~ U(range) [-]
    r.kp_scale_range = (0.9, 1.1)  # stiffness multiplier ~ U(range) [-]
    r.kd_scale_range = (0.9, 1.1)  # damping multiplier ~ U(range) [-]
    r.joint_pos_noise_rad = 0.01  # joint position noise std ~ U[0, this] per episode [rad]
    r.joint_vel_noise_rads = 0.5  # joint velocity noise std ~ U[0, this] per episode [rad/s]
    r.push_vel_mps = 0.5  # push: base velocity change ~ U(+-this) per horizontal axis [m/s]
    r.joint_offset_rad = 0.0  # static offset on all joint readings (evaluation only) [rad]
    r.odometry_level = 1.0  # odometry noise as a multiple of the 100% level [-]
    e.randomization = r
    return e
