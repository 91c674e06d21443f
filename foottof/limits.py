"""Allowed values and ranges, defined once (imports no JAX): the modules that own them and
foottof.config_check (which checks a whole config before JAX is imported) both read them here."""

# Physics (foottof.physics): the env.physics backends; the physics step bound [s].
PHYSICS_BACKENDS = ("auto", "mjx", "mujoco")
MAX_TIMESTEP_S = 0.01
# Trainer (foottof.ppo): learning-rate schedules, policy kinds, MLP activations.
LR_SCHEDULES = ("adaptive", "fixed")
POLICIES = ("lstm", "mlp")
ACTIVATIONS = ("elu", "relu", "tanh", "silu")
# ToF sensor (foottof.sensors.tof): VL53L5CX 4x4 up to 60 Hz, 8x8 up to 15 Hz; |extra tilt|
# about each site axis below this [deg].
TOF_MAX_RATE_HZ = {4: 60.0, 8: 15.0}
TILT_LIMIT_DEG = 90.0
# Terrain (foottof.terrain.tiles): heightfield vertex spacing bound [m]; the stepping-stone tile
# types; the difficulty fraction from which every stone curriculum holds the same values (the
# evaluation ensemble's knot; foottof.eval.results reads both for its draws fingerprint).
MAX_CELL_M = 0.04
STONE_TYPES = ("grid_stones", "two_row_stones", "mixed_row_stones")
ENSEMBLE_KNOT = 0.72
# Robot (foottof.robot.model; the tiles draw cracks for the same foot): foot sphere radius [m].
FOOT_RADIUS_RANGE_M = (0.02, 0.05)
# Evaluation (foottof.eval.robustness): valid closed range of each perturbation's levels; the
# shank_length range is also the robot model's valid shank_scale (foottof.robot.kinematics).
LEVEL_RANGES = {
    "none": (0.0, 0.0),
    "joint_offset": (0.0, 0.3),
    "shank_length": (0.8, 1.2),
    "odometry": (0.0, 10.0),
}
# Perception (foottof.perception): the foot-reading sources.
# tof: rays cast from the simulated foot sensor sites on the terrain (foottof.sensors.tof.sense).
# mock_ideal: the same rays cast on the ideal 5 m x 5 m, 5 cm height scan around the base, from
#   sensor poses computed from the measured joints through the nominal kinematics.
# mock_aggre: as mock_ideal, on the camera-aggregated elevation map (elevation_map.aggre_*).
SOURCES = ("tof", "mock_ideal", "mock_aggre")
