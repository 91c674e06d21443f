"""Robot names, foot order and physical constants of ANYmal-D (ANYmal-D public URDF, IsaacLab)."""

FEET = ("LF", "RF", "LH", "RH")  # foot order used everywhere
JOINT_KINDS = ("HAA", "HFE", "KFE")
JOINT_NAMES = tuple(f"{leg}_{j}" for leg in FEET for j in JOINT_KINDS)  # 12 actuated joints
NUM_JOINTS = 12
NUM_FEET = 4

# Sites and geoms (names created by foottof.robot.make_model).
FOOT_GEOMS = tuple(f"{leg}_foot" for leg in FEET)  # collision spheres
TOF_SITES = tuple(f"{leg}_tof" for leg in FEET)  # ToF sensor frames, z axis = optical axis
BASE_BODY = "base"

# Timing.
PHYSICS_DT_S = 0.005  # 200 Hz physics
CONTROL_DT_S = 0.02  # 50 Hz policy
DECIMATION = 4  # physics steps per control step

# Actuation (ANYmal-D URDF, S6).
TORQUE_LIMIT_NM = 80.0
VELOCITY_LIMIT_RADS = 8.5

# Nominal standing pose (IsaacLab ANYMAL_D_CFG): HAA, HFE, KFE per leg in FEET order.
DEFAULT_POSE = (
    0.0,
    0.4,
    -0.8,  # LF
    0.0,
    0.4,
    -0.8,  # RF
    0.0,
    -0.4,
    0.8,  # LH
    0.0,
    -0.4,
    0.8,  # RH
)
NOMINAL_BASE_HEIGHT_M = 0.589  # base height over flat ground in DEFAULT_POSE, feet touching
ACTION_SCALE = 0.5  # joint target = DEFAULT_POSE + ACTION_SCALE * action

# Foot ToF sensor (STMicroelectronics VL53L5CX).
TOF_FOV_DEG = 45.0
TOF_GRID = 4  # 4x4 zones
TOF_MAX_RANGE_M = 1.0
TOF_RATE_HZ = 60.0
TOF_TILT_DEG = 15.0  # optical axis tilted outward about the body's forward axis
FOOT_RADIUS_M = 0.0315
