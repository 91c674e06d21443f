"""Curriculum levels per terrain type read from a checkpoint (foottof/lab/levels.py).

Oracle: where each env spawned. Tiles are tile_length_m x tile_width_m rectangles laid out with
map column i at world x in [i L, (i + 1) L) and level j at y in [j W, (j + 1) W), so the spawn
position saved in the env state gives each env's column and level without the saved `col` and
`level` leaves the tool reads.
"""

import json
import os

import numpy as np
import pytest

from foottof.lab import levels
from foottof.terrain.terrain_map import TERRAIN_TYPES, allocate_columns

RUN = os.path.join(os.path.dirname(__file__), "..", "policies", "stage1")
SPAWN_LEAF = "['env_state'].info['task'].spawn"


def test_level_counts_match_the_tiles_the_envs_spawned_on():
    with open(os.path.join(RUN, "config.json")) as f:
        cfg = json.load(f)
    t = cfg["terrain"]
    counts = levels.level_counts(RUN)
    spawn = levels.read_rollout_leaves(RUN, (SPAWN_LEAF,))[SPAWN_LEAF]
    col = np.floor(spawn[:, 0] / t["tile_length_m"]).astype(int)
    level = np.floor(spawn[:, 1] / t["tile_width_m"]).astype(int)
    col_types = allocate_columns(t["stage1_weights"], t["num_cols"])
    expected = {}
    for c, lv in zip(col, level, strict=True):
        name = TERRAIN_TYPES[col_types[c]]
        expected.setdefault(name, np.zeros(t["num_levels"], int))[lv] += 1
    assert set(counts) == set(expected)
    for name, c in counts.items():
        np.testing.assert_array_equal(c, expected[name], err_msg=name)
    assert sum(int(c.sum()) for c in counts.values()) == cfg["ppo"]["num_envs"]


def test_unknown_step_names_the_saved_ones():
    with pytest.raises(ValueError, match=r"step=1 is not a checkpoint .* it has \[\d+"):
        levels.level_counts(RUN, step=1)


def test_cli_names_a_bad_run_dir_in_one_line(tmp_path):
    step_dir = tmp_path / "checkpoints" / "50"
    step_dir.mkdir(parents=True)
    with pytest.raises(SystemExit, match=r"^error: no checkpoint in .*give its run directory"):
        levels.main([str(step_dir)])
    with pytest.raises(SystemExit, match=r"^error: step=1 is not a checkpoint"):
        levels.main([RUN, "--step", "1"])


def test_cli_prints_one_row_per_type(capsys):
    levels.main([RUN])
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("envs per curriculum level, checkpoint ")
    rows = {line.split()[0] for line in out[2:]}
    with open(os.path.join(RUN, "config.json")) as f:
        weights = json.load(f)["terrain"]["stage1_weights"]
    assert rows == {name for name, w in weights.items() if w > 0}  # the run's column types


def test_failure_causes_from_step_records():
    """foottof.eval.failures.classify on hand-made step records (T=4 steps, 6 envs)."""
    import numpy as np

    from foottof.eval.failures import CAUSES, classify

    done = np.array(
        [[0, 1, 0, 0, 0, 0], [1, 0, 1, 0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0]]
    )
    success = np.zeros((4, 6))
    success[1, 0] = 1  # env 0: success at step 1
    failed = np.zeros((4, 6))
    failed[0, 1] = failed[1, 2] = failed[2, 3] = 1  # envs 1-3 failed
    stuck = np.zeros((4, 6))
    stuck[0, 1] = 1  # env 1: a foot in a gap
    base_z = np.full((4, 6), 0.5)
    base_z[1, 2] = -0.3  # env 2: base down in a gap
    # env 3: another fall; env 4: done without success or failure (timeout); env 5: never ended
    got = [CAUSES[i] for i in classify(done, success, failed, stuck, base_z)]
    assert got == ["success", "foot_stuck", "fell_base_low", "other_fall", "timeout", "timeout"]


def test_failure_feet_line_counts_each_foot():
    import numpy as np

    from foottof.eval.failures import format_feet

    line = format_feet(np.array([-1, 0, 2, 2, 3, -1, 2]))  # -1: not a foot_stuck episode
    assert line.endswith("LF 1, RF 0, LH 3, RH 1")


def test_gap_direction_on_hand_made_gaps():
    """foottof.eval.failures.gap_direction on analytic terrains: 0 m stone, -1 m pit."""
    import numpy as np

    from foottof.eval.failures import GAP_DIRECTIONS, gap_direction

    def terrain(pit):  # height function over (..., 2) points from a pit predicate of x, y
        return lambda p: np.where(pit(np.asarray(p)[..., 0], np.asarray(p)[..., 1]), -1.0, 0.0)

    crossing = terrain(lambda x, y: np.abs(x) < 0.1)  # 0.2 m gap across the path (x = 0)
    along = terrain(lambda x, y: np.abs(y) < 0.1)  # 0.2 m gap along the course
    junction = terrain(lambda x, y: (np.abs(x) < 0.1) | (np.abs(y) < 0.1))
    hole = terrain(lambda x, y: (np.abs(x) < 0.1) & (np.abs(y) < 0.1))
    wide = terrain(lambda x, y: np.abs(x) < 1.0)  # a 2 m pit: nothing within reach ahead/behind
    feet = np.array([[0.0, 0.0], [0.05, -0.03]])  # centre of the gap and off-centre
    for fn, want in [
        (crossing, "crossing"),
        (along, "along"),
        (junction, "junction"),
        (hole, "hole"),
        (wide, "junction"),
    ]:
        got = [GAP_DIRECTIONS[i] for i in gap_direction(feet, fn)]
        assert got == [want, want], (want, got)
    # A crossing gap 0.37 m wide (two-row stones' widest) is still found bounded ahead and behind.
    wide_crossing = terrain(lambda x, y: np.abs(x) < 0.185)
    assert GAP_DIRECTIONS[gap_direction(np.zeros((1, 2)), wide_crossing)[0]] == "crossing"


def test_stone_distance_on_hand_made_gaps_and_its_lines():
    """foottof.eval.failures.stone_distance against distances worked out by hand on analytic
    terrains (0 m stone, -1 m pit; the error is at most one diagonal step of the 1 cm sampling
    grid), and format_rims."""
    import numpy as np

    from foottof.eval.failures import RIM_GRID_STEP_M, feet_over_gap, format_rims, stone_distance

    def terrain(pit):
        return lambda p: np.where(pit(np.asarray(p)[..., 0], np.asarray(p)[..., 1]), -1.0, 0.0)

    crossing = terrain(lambda x, y: np.abs(x) < 0.15)  # 0.3 m gap across the path
    feet = np.array([[0.0, 0.0], [0.1, 0.02], [-0.13, -0.2]])
    want = np.array([0.15, 0.05, 0.02])  # to the nearer rim x = +-0.15
    tol = RIM_GRID_STEP_M * np.sqrt(2.0)
    got = stone_distance(feet, crossing)
    np.testing.assert_allclose(got, want, atol=tol)
    # A junction: stone only where x > 0.1 and y > 0.1; from (0, 0) the corner (0.1, 0.1).
    corner = terrain(lambda x, y: ~((x > 0.1) & (y > 0.1)))
    got = stone_distance(np.array([[0.0, 0.0], [0.15, -0.05]]), corner)
    np.testing.assert_allclose(got, [np.hypot(0.1, 0.1), 0.15], atol=tol)
    # feet_over_gap: the pit floor (-1 m) under a foot centre, or stone (0 m); two envs.
    feet4 = np.zeros((2, 4, 3))
    feet4[0, :, 0] = (0.0, 0.14, 0.16, 0.5)  # in the crossing gap: the first two
    feet4[1, :, 0] = (0.2, 0.3, -0.2, -0.3)  # all on stone
    assert feet_over_gap(feet4, crossing, -1.0).tolist() == [2, 0]
    # No stone within 0.3 m (a 2 m pit), and flat ground: inf.
    wide = terrain(lambda x, y: np.abs(x) < 1.0)
    flat = terrain(lambda x, y: np.zeros_like(x, bool))
    assert np.isinf(stone_distance(np.zeros((1, 2)), wide)).all()
    assert np.isinf(stone_distance(np.zeros((1, 2)), flat)).all()

    rim = np.array([0.02, 0.05, np.nan, 0.2, 0.1])
    gap = np.array([0, 0, -1, 2, 2])
    lines = format_rims(rim, gap).splitlines()
    assert lines[0] == (
        "foot_stuck, all (4): the foot centre was a median 7.5 cm from the nearest stone top; "
        "< 4 cm 1, 4-8 cm 1, 8-15 cm 1, >= 15 cm 1"
    )
    assert lines[1].startswith("foot_stuck, crossing (2): the foot centre was a median 3.5 cm")
    assert lines[2].startswith("foot_stuck, junction (2)") and len(lines) == 3


def test_gap_lines_count_per_type():
    import numpy as np

    from foottof.eval.failures import format_gaps

    gap = np.array([0, 1, -1, 1, 2])
    types = ["grid_stones", "grid_stones", "grid_stones", "mixed_row_stones", "platform_gap"]
    lines = format_gaps(gap, types).splitlines()
    assert lines[0] == "foot_stuck gaps, grid_stones: crossing 1, along 1, junction 0, hole 0"
    assert lines[1] == "foot_stuck gaps, mixed_row_stones: crossing 0, along 1, junction 0, hole 0"
    assert lines[-1] == "foot_stuck gaps, all: crossing 1, along 2, junction 1, hole 0"


def test_sightings_on_hand_made_rays():
    """foottof.eval.failures.sightings: rays from a sensor 0.1 m above the stone-top plane z = 0,
    hit distances set by hand (the hand-computed crossing of a 45-degree ray is x = 0.1 m)."""
    import numpy as np

    from foottof.eval.failures import sightings

    o = np.array([[0.0, 0.0, 0.1]])  # one sensor
    s45 = np.sqrt(0.5)
    down, slant, up = [0.0, 0.0, -1.0], [s45, 0.0, -s45], [0.0, 0.0, 1.0]
    d = np.array([[down, slant, up]])  # (F=1, R=3, 3)

    def see(spot, t_hit, origin=o, top=0.0):
        looked, gap = sightings(spot, top, origin, d, np.array([t_hit]), max_range_m=1.0)
        return bool(looked[0]), bool(gap[0])

    assert see([0.0, 0.0], [0.1, -1, -1]) == (True, False)  # stone under the sensor
    assert see([0.0, 0.0], [0.9, -1, -1]) == (True, True)  # 0.8 m below the tops: a gap
    assert see([0.0, 0.0], [-1, -1, -1]) == (True, True)  # nothing within range: a gap
    assert see([0.0, 0.0], [0.12, -1, -1]) == (True, False)  # 2 cm beyond: still stone
    assert see([0.1, 0.0], [0.1, -1, -1]) == (True, True)  # the slant ray looked at x = 0.1
    assert see([0.1, 0.0], [0.1, 0.1414, -1]) == (True, False)  # ... and hit the stone there
    assert see([0.1, 0.0], [0.1, 0.05, -1]) == (False, False)  # ... stopped by an edge before
    assert see([0.3, 0.0], [0.1, -1, -1]) == (False, False)  # no ray crossed near x = 0.3
    assert see([0.0, 0.0], [-1, -1, -1], origin=o + [0, 0, 0.9]) == (False, False)  # out of range
    many = sightings(
        [0.0, 0.0],
        0.0,
        np.zeros((5, 1, 3)) + o,
        np.broadcast_to(d, (5, 1, 3, 3)),
        np.full((5, 1, 3), -1.0),
        1.0,
    )
    assert many[0].shape == (5, 1) and many[1].all()  # leading axes (steps) are kept


def test_scan_sightings_on_hand_made_points():
    """foottof.eval.failures.scan_sightings: a teacher's sample points near and far from a spot
    on stone tops at z = 0, heights set by hand (a gap when more than 5 cm below the tops)."""
    import numpy as np

    from foottof.eval.failures import scan_sightings

    def see(points, heights, spot=(0.0, 0.0)):
        looked, gap = scan_sightings(spot, 0.0, np.array(points), np.array(heights))
        return bool(looked[0]), bool(gap[0])

    assert see([[0.05, 0.0], [0.3, 0.0]], [0.0, -0.5]) == (True, False)  # near one is stone
    assert see([[0.05, 0.0], [0.3, 0.0]], [-0.5, 0.0]) == (True, True)  # near one in the gap
    assert see([[0.05, 0.0]], [-0.04]) == (True, False)  # 4 cm below: still stone
    assert see([[0.0, 0.09]], [-0.5]) == (False, False)  # 9 cm away: beyond the 8 cm radius
    assert see([[0.06, 0.05]], [-0.5]) == (True, True)  # 7.8 cm away (hand-computed)
    steps = scan_sightings((0.0, 0.0), 0.0, np.zeros((5, 3, 2)), np.full((5, 3), -1.0))
    assert steps[0].shape == (5, 1) and steps[1].all()  # leading axes (steps) are kept
    # a seen teacher (env.actor_terrain_seen) read only its flagged points: an unflagged near
    # point in the gap was the flat fill to it, so it neither looked there nor saw the gap
    pts, hs = np.array([[0.05, 0.0], [0.0, 0.05]]), np.array([-0.5, 0.0])
    assert not scan_sightings((0.0, 0.0), 0.0, pts, hs, np.array([False, False]))[0][0]
    assert [
        bool(x[0]) for x in scan_sightings((0.0, 0.0), 0.0, pts, hs, np.array([False, True]))
    ] == [True, False]
    assert [
        bool(x[0]) for x in scan_sightings((0.0, 0.0), 0.0, pts, hs, np.array([True, False]))
    ] == [True, True]


def test_world_scan_points_are_where_the_teacher_reads():
    """observations.world_scan_points, critic_height_scan, foot_patch_points and foot_patches
    against hand-worked geometry. Base at (1, 2, z) turned 30 degrees: the first scan point
    (x -0.6, y -0.4 in the base frame) lands at the hand-rotated place. On a plane rising
    1 m per m along the heading, h = c x + s y (c, s = cos, sin 30 deg), a point at base-frame
    (x, y) lies at height c + 2 s + x, so with the base at that height, z = c + 2 s, the scan
    reads the documented grid's x (-0.6 to 1.2 m, 10 cm apart, the same in all 9 columns),
    clipped at 1 m; on the plane rising across it, h = -s x + c y, it reads y (-0.4 to 0.4 m in
    every row). Foot patches on h = x + 0.5 y, worked out below; a foot 2 m under the terrain
    reads the 1 m clip."""
    import jax.numpy as jp
    import numpy as np

    from foottof.envs import observations as obs_lib

    yaw = np.deg2rad(30.0)
    c, s = np.cos(yaw), np.sin(yaw)
    quat = jp.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    base = jp.array([1.0, 2.0, 0.5])
    pts = np.asarray(obs_lib.world_scan_points(base, quat))
    assert pts.shape == (19 * 9, 2)
    np.testing.assert_allclose(
        pts[0], [1.0 - 0.6 * c + 0.4 * s, 2.0 - 0.6 * s - 0.4 * c], atol=1e-6
    )
    grid_x = np.arange(-6, 13) / 10.0  # 19 rows: -0.6 .. 1.2 m
    grid_y = np.arange(-4, 5) / 10.0  # 9 columns: -0.4 .. 0.4 m
    along = obs_lib.critic_height_scan(
        lambda p: c * p[..., 0] + s * p[..., 1], base.at[2].set(c + 2 * s), quat
    )
    want = np.repeat(np.minimum(grid_x, 1.0)[:, None], 9, axis=1)  # rows 1.1, 1.2 m clip to 1
    np.testing.assert_allclose(np.asarray(along).reshape(19, 9), want, atol=1e-5)
    across = obs_lib.critic_height_scan(
        lambda p: -s * p[..., 0] + c * p[..., 1], base.at[2].set(-s + 2 * c), quat
    )
    np.testing.assert_allclose(
        np.asarray(across).reshape(19, 9), np.repeat(grid_y[None], 19, axis=0), atol=1e-5
    )

    feet = jp.array([[0.3, 0.2, 0.1], [0.3, -0.2, 0.0], [-0.3, 0.2, 0.05], [-0.3, -0.2, -2.0]])
    fp = obs_lib.foot_patch_points(feet)
    assert fp.shape == (4, 9, 2)
    np.testing.assert_allclose(fp[2, 0], [-0.4, 0.1], atol=1e-6)  # offset (-0.1, -0.1)
    patches = np.asarray(obs_lib.foot_patches(lambda p: p[..., 0] + 0.5 * p[..., 1], feet))
    patches = patches.reshape(4, 3, 3)  # (foot, dx -0.1 / 0 / 0.1, dy -0.1 / 0 / 0.1)
    # foot 2 at (-0.3, 0.2), 5 cm high: x + 0.5 y - 0.05 at x -0.4..-0.2, y 0.1..0.3
    want2 = [[-0.4, -0.35, -0.3], [-0.3, -0.25, -0.2], [-0.2, -0.15, -0.1]]
    np.testing.assert_allclose(patches[2], want2, atol=1e-6)
    # foot 0 at (0.3, 0.2), 10 cm high: centre 0.3 + 0.1 - 0.1 = 0.3; +-0.1 per dx, +-0.05 per dy
    np.testing.assert_allclose(patches[0, 1, 1], 0.3, atol=1e-6)
    np.testing.assert_allclose(patches[0, 2, 0], 0.35, atol=1e-6)
    np.testing.assert_allclose(patches[3], 1.0)  # 1.45 .. 1.75 m above the foot: clipped


def test_sighting_summary_counts_steps_before_the_drop():
    import numpy as np

    from foottof.eval.failures import SIGHT_WINDOW_STEPS, sighting_summary

    foot_z = np.array([0.03] * 10 + [-0.05, -0.2, -0.4])  # on the tops until step 9
    gap = np.zeros((13, 2), bool)
    gap[4, 1] = gap[6, 0] = True
    looked = gap.copy()
    looked[2, 0] = True
    # the foot stood (centre 3 cm above the tops: bottom on them), then slid in
    assert sighting_summary(foot_z, 0.0, 12, looked, gap) == (9, 5, 7, False)
    assert sighting_summary(foot_z, 0.0, 12, looked, np.zeros_like(gap)) == (9, -1, 7, False)
    at_drop = np.zeros_like(gap)
    at_drop[9, 0] = True  # seen only at the drop step itself: not before it
    assert sighting_summary(foot_z, 0.0, 12, at_drop, at_drop)[1:3] == (-1, -1)
    lifted = foot_z.copy()
    lifted[5] = 0.09  # bottom 5.85 cm above the tops 4 steps before the drop: a swing
    assert sighting_summary(lifted, 0.0, 12, looked, gap)[3]
    lifted[5] = 0.045  # 1.35 cm: still standing (within SWING_LIFT_M)
    assert not sighting_summary(lifted, 0.0, 12, looked, gap)[3]
    long_z = np.concatenate([np.full(SIGHT_WINDOW_STEPS + 11, 0.03), [-0.3]])
    early = np.zeros((len(long_z), 1), bool)
    early[0] = True  # seen 60 steps before the drop: outside the window
    assert sighting_summary(long_z, 0.0, len(long_z) - 1, early, early) == (60, -1, -1, False)


def test_stall_step_hand_worked():
    """foottof.eval.failures.stall_step: a base walking 0.03 m per step along x until step 100,
    then standing until step 199. A 50-step window starting at t moved 0.03 (100 - t) m there:
    >= 0.1 m up to t = 96, so it stands from step 97. Standing only the last 30 steps, or
    walking to the end, is no stall; nor is an episode shorter than a window."""
    from foottof.eval.failures import format_stalls, stall_step

    x = 0.03 * np.minimum(np.arange(200), 100)
    xy = np.stack([x, np.zeros(200)], axis=-1)
    assert stall_step(xy, 199) == 97
    assert stall_step(xy, 130) == -1  # stood 30 steps before the end: under one window
    assert stall_step(xy, 150) == 97  # stood steps 97-150: more than one window
    walking = np.stack([0.03 * np.arange(200), np.zeros(200)], axis=-1)
    assert stall_step(walking, 199) == -1
    assert stall_step(np.zeros((200, 2)), 199) == 0  # never moved
    assert stall_step(np.zeros((200, 2)), 30) == -1  # shorter than a window
    wobble = xy + 0.04 * np.stack([np.sin(np.arange(200)), np.cos(np.arange(200))], -1)
    assert 95 <= stall_step(wobble, 199) <= 100  # a 4 cm sway in place is standing
    cause = np.array([4, 4, 0, 4])  # three timeouts, one success
    stall = np.array([97, -1, -1, 147])
    text = format_stalls(
        cause, stall, np.array([0.5, np.nan, np.nan, 0.7]), np.full(4, 199),
        ["grid_stones", "grid_stones", "grid_stones", "platform_gap"], 0.02,
    )  # fmt: skip
    assert "timeout, all (3): stood still 2 (from a median step 122, 2.4 s in and 1.5 s" in text
    assert "progress 0.60), walked on to the deadline 1" in text
    assert "timeout, grid_stones (2): stood still 1" in text


def test_start_step_hand_worked():
    """foottof.eval.failures.start_step and format_starts: progress 0.05 per step from step 2 in
    env 0 (0.1 at step 4), never past 0.08 in env 1, 0.1 at step 6 in env 2 but that episode
    ended at step 5."""
    from foottof.eval.failures import format_starts, start_step

    t = np.arange(10)[:, None]
    progress = np.concatenate(
        [np.maximum(0, t - 2) * 0.05, np.minimum(t * 0.01, 0.08), (t >= 6) * 0.2], axis=1
    )
    start = start_step(progress, np.array([9, 9, 5]))
    np.testing.assert_array_equal(start, [4, -1, -1])
    assert start_step(progress, np.array([9, 9, 9]))[2] == 6
    text = format_starts(np.array([0, 4, 4]), np.array([4, -1, 10]), 0.5)
    assert text == "time to progress 0.1, median: success 2.0 s (0 never), timeout 5.0 s (1 never)"


@pytest.mark.integration
def test_failures_on_the_training_map_cover_every_column_type():
    """foottof.eval.failures.run with training_level: the stage-2 training map of the config
    (not the evaluation ensemble), env i on column i; the column types come from
    allocate_columns of the stage's weights. A level outside the map is refused, naming the
    range."""
    from configs import smoke
    from foottof.eval.failures import CAUSES, REASONS, format_reasons, run

    cfg = smoke.get_config()
    cfg.stage = 2
    cfg.terrain.num_cols = 9
    cfg.env.episode_length_s = 0.4  # 20 steps: the causes, not the walk, are under test
    f = run(cfg, None, 9, 3, training_level=1)
    cause, types, rim = f.cause, f.types, f.rim
    expected = [TERRAIN_TYPES[t] for t in allocate_columns(cfg.terrain.stage2_weights, 9)]
    assert types == expected
    assert {"beam", "stairs", "pyramid_up", "pyramid_down"} <= set(types)
    assert cause.shape == f.end_step.shape == f.progress.shape == rim.shape == (9,)
    assert f.sightings is None
    timeout = cause == CAUSES.index("timeout")
    assert f.stall.shape == f.stall_progress.shape == (9,) and (f.stall[~timeout] == -1).all()
    assert np.isnan(f.stall_progress[f.stall < 0]).all()
    assert f.start.shape == (9,) and (f.start < f.end_step + 1).all()
    stuck = cause == CAUSES.index("foot_stuck")
    assert np.isnan(rim[~stuck]).all() and not np.isnan(rim[stuck]).any()
    assert set(cause.tolist()) <= set(range(len(CAUSES)))
    assert f.reasons.shape == (9, len(REASONS)) and f.reasons.dtype == bool
    fell = np.isin(cause, [CAUSES.index(c) for c in ("foot_stuck", "fell_base_low", "other_fall")])
    assert not f.reasons[~fell].any()  # reasons only where the episode failed
    assert f.reasons[fell].any(axis=1).all()  # every failure has one
    assert (f.reasons[:, REASONS.index("foot_stuck")] == stuck).all()
    with pytest.raises(ValueError, match=r"training level 2 outside the map's levels \[0, 1\]"):
        run(cfg, None, 9, 3, training_level=2)
    # A base contact margin above the standing height: every episode fails on its first step
    # by touching the terrain, and by nothing else (the robot stands upright on its platform).
    cfg.env.body_contact_margin_m = 1.0
    f = run(cfg, None, 9, 3, training_level=0)
    assert (f.end_step == 0).all() and (f.cause == CAUSES.index("other_fall")).all()
    assert f.reasons[:, REASONS.index("body_contact")].all()
    assert f.reasons.sum(axis=1).tolist() == [1] * 9
    lines = format_reasons(f.cause, f.types, f.reasons).splitlines()
    assert lines[-1] == (
        "other_fall reasons, all (9): body_contact 9, fell 0, foot_deep 0, foot_stuck 0, "
        "flipped 0, diverged 0"
    )
    assert f.over_gap.tolist() == [0] * 9  # standing on the start platform
    over = np.zeros(9, int)
    over[[0, 4]] = (1, 3)  # two of them with feet over a gap: counted once each
    last = format_reasons(f.cause, f.types, f.reasons, over).splitlines()[-1]
    assert last.endswith("diverged 0; a foot over a gap 2")


def test_smallest_stone_is_the_size_at_the_highest_level_holding_a_share():
    """Hand values: 10 levels over (0, 0.8); level 4 is d = 0.8 x 4 / 9 = 0.3556. On size first
    that lies between the knots 0.27 (grid 0.40 m) and 0.36 (0.2976 m): 0.40 - 0.1024 x
    0.0856 / 0.09 = 0.3026 m; on gaps first the grid stones keep 1.0 m until d = 0.4. One env
    at level 9 (under 5 % of the type's) does not count; two-row stones with no env are left out."""
    from configs import _terrain

    terrain = _terrain.get_section()
    grid = np.zeros(10, int)
    grid[[2, 4, 9]] = (40, 60, 1)
    counts = {"grid_stones": grid, "two_row_stones": np.zeros(10, int), "platform_gap": grid}
    sizes = levels.smallest_stones(terrain, 1, counts)
    assert set(sizes) == {"grid_stones"}
    assert sizes["grid_stones"] == pytest.approx(0.40 - 0.1024 * (0.8 * 4 / 9 - 0.27) / 0.09, 1e-4)
    terrain.stone_curriculum = "gaps_first"
    assert levels.smallest_stones(terrain, 1, counts)["grid_stones"] == pytest.approx(1.0)
    grid[9] = 10  # now 9 % of the type's envs: level 9, d = 0.8, past the shared knot 0.72
    both = levels.smallest_stones(terrain, 1, counts)["grid_stones"]
    assert both == pytest.approx(0.2976 + (0.18 - 0.2976) * 0.08 / 0.28, 1e-4)
