"""Evaluation section: the robustness ensemble and perturbation sweeps."""

import ml_collections


def get_section() -> ml_collections.ConfigDict:
    e = ml_collections.ConfigDict()
    e.episodes = 1000  # runs per (source, perturbation, level) cell [episodes]
    e.num_envs = 250  # parallel envs per batch (episodes are run in batches of this size)
    e.num_levels = 5  # rows of the evaluation map (random redraws, same difficulty) [tiles]
    e.num_cols = 10  # columns of the evaluation map, split by type weights [tiles]
    e.stone_fraction = 0.8  # fraction of stepping-stone tiles in the test ensemble [-]
    e.stone_types = ("grid_stones", "two_row_stones", "mixed_row_stones")  # stepping-stone types
    e.gap_types = ("platform_gap",)  # gap tile types
    e.difficulty_fraction = 0.9  # difficulty = this fraction of the stage-1 curriculum range [-]
    e.sources = ("tof", "mock_ideal", "mock_aggre")  # foot-reading sources compared
    e.joint_offset_levels = (0.0, 0.025, 0.05, 0.075, 0.1)  # static joint offset sweep [rad]
    e.shank_length_levels = (0.8, 0.9, 1.0, 1.1, 1.2)  # shank scale sweep (physics only) [-]
    e.odometry_levels = (0.0, 1.0, 2.0, 3.0, 4.0)  # odometry noise sweep [x 100 % level]
    e.deterministic = True  # mean actions (False: sampled at the action std, as in training)
    e.seed = 0  # PRNG seed of the evaluation (map, policy init, episodes)
    e.out_dir = "eval_results"  # where tables, JSON/CSV and plots are written
    return e
