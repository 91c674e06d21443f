"""Tests of foottof.terrain: tiles (geometry measured from the arrays), terrain map, curriculum."""

import dataclasses
import time

import jax
import jax.numpy as jp
import ml_collections
import mujoco
import numpy as np
import pytest
from helpers import hfield_mj_model
from scipy import ndimage

from configs import _eval, _terrain
from foottof.envs.stuck_probe import foot_gap_depth, foot_stuck
from foottof.terrain import (
    SPAWN_X,
    SPAWN_Y,
    SPAWN_YAW,
    SPAWN_Z,
    STAGE1_TYPES,
    TERRAIN_TYPES,
    Heightfield,
    TerrainMapSpec,
    TileSpec,
    allocate_columns,
    build_terrain_map,
    generate_tile,
    make_eval_map_spec,
    progress_fraction,
    sample_spawn_goal,
    tile_at,
    update_levels,
)
from foottof.terrain.heightfield import write_to_mjx
from foottof.terrain.terrain_map import tile_generator
from foottof.terrain.tiles import (
    STONE_CURRICULUM_NAMES,
    STONE_TYPES,
    crack_sag_m,
    stone_params,
)

SPEC = TileSpec()
# The drawing tests below were written against the gaps-first stone curriculum (stones shrink
# last) and keep it; the size-first curriculum has its own tests (test_size_first_*).
GAPS_FIRST = TileSpec(stone_curriculum="gaps_first")
CELL = SPEC.cell_m
PIT = SPEC.pit_z_m
DIFFS = (0.0, 0.5, 1.0)
NSEED = 20


@pytest.fixture(scope="module")
def tiles():
    """name -> (len(DIFFS), NSEED, ny, nx) heights; one jit per type, vmapped over seeds x diffs."""
    keys = jax.random.split(jax.random.key(1234), NSEED)
    out = {}
    for name in TERRAIN_TYPES:
        per_seed = jax.vmap(lambda k, d, n=name: generate_tile(n, k, d, GAPS_FIRST), (0, None))
        gen = jax.jit(jax.vmap(per_seed, (None, 0)))  # -> (difficulty, seed, ny, nx)
        out[name] = np.asarray(gen(keys, jp.asarray(DIFFS)))
    return out


# ------------------------------------------------------------------ measurements on the arrays


def _course(z):
    return z[..., SPEC.n_start : SPEC.nx - SPEC.n_goal]


def _stone_sizes_x(z):
    """Flat-top length along x [m] of every stone (4-connected vertices above the pit) that lies
    wholly inside the course, not touching its borders."""
    solid = _course(z) > PIT + 0.5
    labels, n = ndimage.label(solid)
    sizes = []
    for sl in ndimage.find_objects(labels):
        ys, xs = sl
        if xs.start == 0 or xs.stop == solid.shape[1] or ys.start == 0 or ys.stop == solid.shape[0]:
            continue
        sizes.append((xs.stop - xs.start - 1) * CELL)
    return sizes


def _gaps_x(z):
    """Gap [m] after every stone wholly inside the course, along x through the stone's centre row:
    from its last solid vertex to the next solid vertex (k pit vertices between = k + 1 cells)."""
    solid = _course(z) > PIT + 0.5
    labels, _ = ndimage.label(solid)
    gaps = []
    for sl in ndimage.find_objects(labels):
        ys, xs = sl
        if xs.start == 0 or xs.stop == solid.shape[1] or ys.start == 0 or ys.stop == solid.shape[0]:
            continue
        row = solid[(ys.start + ys.stop - 1) // 2, xs.stop :]
        if row.any():  # a stone follows before the goal region
            gaps.append((np.argmax(row) + 1) * CELL)
    return gaps


def _row_gaps_x(z):
    """Widths [m] of every pit run along x bounded by solid vertices, over all rows."""
    gaps = []
    for row in z > PIT + 0.5:
        jumps = np.diff(np.flatnonzero(row))
        gaps.extend((jumps[jumps > 1] * CELL).tolist())
    return gaps


def _solid_tops(z):
    c = _course(z)
    return c[c > PIT + 0.5]


def _steps_x(z, min_step=0.005):
    """|dz| between x-neighbours where both are above the pit and |dz| > min_step [m]."""
    c = _course(z)
    dz = np.abs(np.diff(c, axis=-1))
    ok = (c[..., 1:] > PIT + 0.5) & (c[..., :-1] > PIT + 0.5) & (dz > min_step)
    return dz[ok]


def _beam_widths(z):
    """Width [m] of the solid run in each course column that has any solid vertex."""
    widths = []
    for col in (_course(z) > PIT + 0.5).T:
        if col.any():
            widths.append((col.sum() - 1) * CELL)
    return widths


def _mean_over_seeds(tiles_d, fn):
    vals = [v for z in tiles_d for v in np.atleast_1d(fn(z))]
    assert len(vals) > 0
    return float(np.mean(vals))


def _strictly_monotone(values, decreasing, margin):
    pairs = zip(values[:-1], values[1:], strict=True)
    if decreasing:
        return all(a - b > margin for a, b in pairs)
    return all(b - a > margin for a, b in pairs)


# ----------------------------------------------------------------------------- tile properties


def test_types_in_paper_order():
    assert TERRAIN_TYPES == (
        "grid_stones",
        "two_row_stones",
        "rough_boxes",
        "platform_gap",
        "mixed_row_stones",
        "beam",
        "stairs",
        "pyramid_up",
        "pyramid_down",
    )
    assert STAGE1_TYPES == TERRAIN_TYPES[:5]
    assert SPEC.shape == (100, 150)


@pytest.mark.parametrize("name", TERRAIN_TYPES)
def test_heights_finite_bounded_platforms_flat(tiles, name):
    z = tiles[name]
    assert z.shape == (len(DIFFS), NSEED, SPEC.ny, SPEC.nx) and z.dtype == np.float32
    assert np.isfinite(z).all()
    # Everything is either exactly the pit floor or a surface within +-0.8 m of the start platform
    # (stairs rise or drop at most 0.8 m, pyramids 0.6 m + roughness, stones 0.2 m).
    is_pit = z == np.float32(PIT)
    assert (is_pit | (np.abs(z) <= 0.8 + 1e-6)).all()
    assert np.all(z[..., : SPEC.n_start] == 0.0), "start platform must be flat at z = 0"
    assert np.all(z[..., SPEC.nx - SPEC.n_goal :] == 0.0), "goal region must be flat at z = 0"
    # The start platform's last column meets the course: its neighbours exist (no NaN edge).
    assert z.shape[-1] == SPEC.n_start + (SPEC.nx - SPEC.n_start - SPEC.n_goal) + SPEC.n_goal


@pytest.mark.parametrize("name", ("grid_stones", "two_row_stones", "mixed_row_stones"))
def test_stones_shrink_and_gaps_widen(tiles, name):
    # Easy end walkable blind: ~5 cm nominal gaps, mostly narrower than a cell and then not drawn
    # (tiles.py, Rendering): most stones join into one surface; along the rows that carry stones
    # (two_row_stones: the two bands), < 10 % of the vertices are pit.
    easy = tiles[name][0]
    solid_rows = [r for z in easy for r in (_course(z) > PIT + 0.5).mean(axis=-1) if r > 0.5]
    pit_frac = 1.0 - np.mean(solid_rows)
    easy_gaps = [g for z in easy for g in _gaps_x(z)]
    assert pit_frac < 0.1, pit_frac
    assert not easy_gaps or np.median(easy_gaps) <= 0.05 + 2 * CELL, easy_gaps
    # From the middle on, isolated stones: tops shrink, gaps widen. Hard end at/beyond the
    # hardware scale: <= 20 x 20 cm tops, wide gaps.
    sizes = [_mean_over_seeds(t, _stone_sizes_x) for t in tiles[name][1:]]
    gaps = [_mean_over_seeds(t, _gaps_x) for t in tiles[name][1:]]
    assert _strictly_monotone(sizes, decreasing=True, margin=0.05), sizes
    assert _strictly_monotone(gaps, decreasing=False, margin=0.05), gaps
    assert sizes[0] >= 0.3 and sizes[-1] <= 0.20 and gaps[-1] >= 0.3, (sizes, gaps)


@pytest.mark.parametrize(
    "name", ("grid_stones", "two_row_stones", "platform_gap", "mixed_row_stones")
)
def test_height_variation_grows(tiles, name):
    spread = [_mean_over_seeds(t, lambda z: np.std(_solid_tops(z))) for t in tiles[name]]
    assert spread[0] < 0.005, spread  # easy: level tops
    # Stones keep level tops while their gaps widen (d <= 0.4), then spread: d = 0.5 is early.
    assert _strictly_monotone(spread, decreasing=False, margin=0.005), spread


def test_mixed_rows_reach_20cm_height_changes(tiles):
    hard = tiles["mixed_row_stones"][-1]
    ranges = [np.ptp(_solid_tops(z)) for z in hard]
    assert np.mean(ranges) >= 0.35, ranges  # low bricks -20 cm and high stones +20 cm


def test_drawn_tops_and_gaps_match_their_nominal_size():
    """The piecewise-linear heightfield draws a solid's flat top from its first to its last solid
    vertex and a gap's top opening from the last solid vertex to the next: on average these equal
    the generator's nominal sizes (hand-computed from its parameters), not one cell less / more."""
    d = 0.6
    # two_row_stones at d = 0.6, between the knots 0.4 and 0.72 (t = 0.625): size 0.80 ->
    # 0.2976, each x U(f_lo, 1) with f_lo 1.0 -> 0.9196; gap 0.24 -> 0.338 (the rows, 0.6 m
    # apart, no longer touch: each stone is measured alone).
    t = (d - 0.4) / 0.32
    size = (0.80 + (0.2976 - 0.80) * t) * (1 + 1.0 + (0.9196 - 1.0) * t) / 2
    gap = 0.24 + (0.338 - 0.24) * t
    zs = [
        np.asarray(generate_tile("two_row_stones", jax.random.PRNGKey(s), d, GAPS_FIRST))
        for s in range(40)
    ]
    sizes = [v for z in zs for v in _stone_sizes_x(z)]
    gaps = [v for z in zs for v in _gaps_x(z)]
    assert len(sizes) > 50 and len(gaps) > 50
    assert abs(np.mean(sizes) - size) < 0.01, (np.mean(sizes), size)  # 1 cell = 0.04
    assert abs(np.mean(gaps) - gap) < 0.02, (np.mean(gaps), gap)
    # platform_gap at d: largest gap 0.05 + 0.70 d, each x U(0.85, 1).
    gap = (0.05 + 0.70 * d) * 0.925
    zs = [np.asarray(generate_tile("platform_gap", jax.random.PRNGKey(s), d)) for s in range(16)]
    gaps = [v for z in zs for v in _row_gaps_x(z[SPEC.ny // 2 : SPEC.ny // 2 + 1])]
    assert len(gaps) > 20 and abs(np.mean(gaps) - gap) < 0.015, (np.mean(gaps), gap)


def test_platform_gaps_widen_to_60cm(tiles):
    # The easiest gaps (4.25-5 cm) are narrower than the foot: drawn as shallow cracks, no pit.
    assert not (_course(tiles["platform_gap"][0]) == PIT).any()
    gaps = [_mean_over_seeds(t, _row_gaps_x) for t in tiles["platform_gap"][1:]]
    assert _strictly_monotone(gaps, decreasing=False, margin=0.1), gaps
    max_hard = [max(_row_gaps_x(z)) for z in tiles["platform_gap"][-1]]
    assert min(max_hard) >= 0.6, max_hard


def test_beam_narrows(tiles):
    widths = [_mean_over_seeds(t, _beam_widths) for t in tiles["beam"]]
    assert _strictly_monotone(widths, decreasing=True, margin=0.1), widths
    assert widths[-1] <= 0.2 and widths[0] >= 0.7, widths
    # Reachable: the beam's gaps along x stay short (<= 20 cm) at every difficulty.
    for tiles_d in tiles["beam"]:
        for z in tiles_d:
            centre = (z > PIT + 0.5).any(axis=0)  # columns with any beam vertex
            runs = np.diff(np.flatnonzero(centre))
            assert runs.max() * CELL <= 0.2


@pytest.mark.parametrize("name", ("rough_boxes", "stairs"))
def test_step_height_grows(tiles, name):
    steps = [_mean_over_seeds(t, _steps_x) for t in tiles[name]]
    assert _strictly_monotone(steps, decreasing=False, margin=0.02), steps
    if name == "stairs":
        assert 0.04 <= steps[0] <= 0.06 and steps[-1] >= 0.2, steps


@pytest.mark.parametrize("name", ("pyramid_up", "pyramid_down"))
def test_pyramids_steepen(tiles, name):
    sign = 1.0 if name == "pyramid_up" else -1.0
    peak = [np.mean([np.max(sign * z) for z in t]) for t in tiles[name]]
    slope = [
        _mean_over_seeds(t, lambda z: np.median(np.abs(np.diff(_course(z), axis=-1))) / CELL)
        for t in tiles[name]
    ]
    assert _strictly_monotone(peak, decreasing=False, margin=0.1), peak
    assert _strictly_monotone(slope, decreasing=False, margin=0.05), slope


@pytest.mark.parametrize("name", TERRAIN_TYPES)
def test_same_key_same_tile_and_jit_equals_eager(tiles, name):
    key = jax.random.split(jax.random.key(1234), NSEED)[0]
    with jax.disable_jit():
        eager = np.asarray(generate_tile(name, key, 0.5, GAPS_FIRST))
    np.testing.assert_allclose(eager, tiles[name][1, 0], atol=1e-5)  # vmap + jit == eager
    # Different keys give different tiles (placement is random).
    assert not np.array_equal(tiles[name][1, 0], tiles[name][1, 1])


def test_same_key_same_tile_repeat():
    gen = jax.jit(generate_tile, static_argnums=0)
    a = gen("grid_stones", jax.random.key(7), 0.3)
    b = gen("grid_stones", jax.random.key(7), 0.3)
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


# --------------------------------------------------------------------------------- bad input


def test_height_colours_run_dark_to_light():
    """The figure's and the video's terrain colour: luminance rises with height, a pit floor
    (-1 m) near black, a top at 0 m light, +-0.1 m stone tops visibly apart."""
    from foottof.terrain.preview import height_rgb

    z = np.linspace(-1.2, 1.0, 221)
    lum = height_rgb(z) @ np.array([0.299, 0.587, 0.114])
    assert np.all(np.diff(lum) >= 0) and np.diff(lum).sum() > 0.8
    pit, top, low, high = height_rgb([-1.0, 0.0, -0.1, 0.1]) @ np.array([0.299, 0.587, 0.114])
    assert pit < 0.1 < 0.6 < top and high - low > 0.3


def test_bad_name_and_difficulty_raise():
    key = jax.random.key(0)
    with pytest.raises(ValueError, match=r"'stepping'.*grid_stones.*pyramid_down"):
        generate_tile("stepping", key, 0.5)
    for bad in (-0.1, 1.5, float("nan"), np.array([0.2, 1.2])):
        with pytest.raises(ValueError, match=r"outside the valid range \[0, 1\]"):
            generate_tile("beam", key, bad)
    with pytest.raises(ValueError, match="cell_m"):
        TileSpec(cell_m=0.05)
    with pytest.raises(ValueError, match=r"multiple of terrain\.cell_m"):
        TileSpec(platform_length_m=1.5)


def test_traced_difficulty_is_clipped():
    gen = jax.jit(generate_tile, static_argnums=0)
    key = jax.random.key(3)
    np.testing.assert_array_equal(
        np.asarray(gen("grid_stones", key, jp.float32(1.7))),
        np.asarray(gen("grid_stones", key, jp.float32(1.0))),
    )


# -------------------------------------------------------------- physics oracle: dropped spheres


def _sphere_targets(z, num):
    """Stones with >= 2 flat cells around a centre vertex; returns [(x, y, top_z)] local [m] of
    ``num`` of them spread over the top heights (highest, lowest, then in between)."""
    solid = z > PIT + 0.5
    solid[:, : SPEC.n_start] = False
    solid[:, SPEC.nx - SPEC.n_goal :] = False
    labels, n = ndimage.label(solid)
    dist = ndimage.distance_transform_cdt(solid, metric="chessboard")
    picks = []
    for lab in range(1, n + 1):
        d = np.where(labels == lab, dist, 0)
        i, j = np.unravel_index(np.argmax(d), d.shape)
        if d[i, j] >= 3:
            picks.append((j * CELL, i * CELL, float(z[i, j])))
    picks.sort(key=lambda p: p[2])
    order = [len(picks) - 1, 0, *range(1, len(picks) - 1)]
    return [picks[k] for k in order[:num]]


def _drop_model(z, targets, pit_xy, radius):
    hf = Heightfield(heights=jp.asarray(z), cell_m=CELL, z_floor_m=PIT, z_range_m=SPEC.z_range_m)
    bodies = "".join(
        f'<body pos="{x} {y} {top + radius + 0.15}"><freejoint/>'
        f'<geom type="sphere" size="{radius}" mass="0.5" contype="1" conaffinity="2"/></body>'
        for x, y, top in [*targets, (*pit_xy, PIT)]
    )
    m, _ = hfield_mj_model(hf, 'contype="2" conaffinity="1"', bodies, '<option timestep="0.002"/>')
    return m, hf


@pytest.fixture(scope="module")
def drop_setup(tiles):
    z = tiles["mixed_row_stones"][2, 0]  # d = 1: bricks at -20 cm, high stones at +20 cm
    targets = _sphere_targets(z, 3)
    assert len(targets) == 3
    pit_mask = np.pad(_course(z) == PIT, 1)  # outside the course counts as not-pit
    clear = ndimage.distance_transform_cdt(pit_mask, metric="chessboard")[1:-1, 1:-1]
    i, j = np.unravel_index(np.argmax(clear), clear.shape)
    j += SPEC.n_start
    assert np.all(z[max(i - 2, 0) : i + 3, j - 2 : j + 3] == PIT)  # clear of stones: clean drop
    pit_xy = (j * CELL, i * CELL)
    radius = 0.05
    m, hf = _drop_model(z, targets, pit_xy, radius)
    expected = np.array([top for _, _, top in targets] + [PIT]) + radius
    return m, hf, expected


def test_sphere_rests_on_stone_tops_mujoco_c(drop_setup):
    m, _, expected = drop_setup
    d = mujoco.MjData(m)
    for _ in range(750):  # 1.5 s
        mujoco.mj_step(m, d)
    z_rest = d.qpos.reshape(-1, 7)[:, 2]
    np.testing.assert_allclose(z_rest, expected, atol=3e-3)
    assert np.ptp(expected[:-1]) > 0.15  # stone tops at clearly different heights


def test_sphere_rests_on_stone_tops_mjx(drop_setup):
    from mujoco import mjx

    m, hf, expected = drop_setup
    mx = write_to_mjx(mjx.put_model(m), hf)
    dx = mjx.put_data(m, mujoco.MjData(m))

    @jax.jit
    def run(mx, dx):
        return jax.lax.fori_loop(0, 750, lambda _, d: mjx.step(mx, d), dx)

    z_rest = np.asarray(run(mx, dx).qpos).reshape(-1, 7)[:, 2]
    np.testing.assert_allclose(z_rest, expected, atol=3e-3)


# ----------------------------------------------- cracks and stuck feet: loaded foot, MuJoCo C

FOOT_R = SPEC.foot_radius_m
FOOT_LOAD_N = 130.0  # a quarter of ANYmal-D's weight (~53 kg x 9.81 / 4)
STUCK_DEPTH_M = 0.12  # configs/_env.py env.foot_stuck_depth_m


def _drop_loaded_feet(z, points_xy):
    """MuJoCo C: 3.15 cm foot spheres, each pressed down with FOOT_LOAD_N, dropped from 5 cm above
    the tile at ``points_xy`` (local [m]); (N, 3) foot-centre positions after 1.5 s."""
    hf = Heightfield(heights=jp.asarray(z), cell_m=CELL, z_floor_m=PIT, z_range_m=SPEC.z_range_m)
    bodies = "".join(
        f'<body pos="{x} {y} {FOOT_R + 0.05}"><freejoint/><geom type="sphere" size="{FOOT_R}" '
        'mass="1" friction="1" contype="1" conaffinity="2"/></body>'
        for x, y in points_xy
    )
    m, d = hfield_mj_model(
        hf,
        geom_attrs='contype="2" conaffinity="1"',
        bodies=bodies,
        option='<option timestep="0.002" impratio="100" cone="pyramidal"/>',
    )
    d.xfrc_applied[1:, 2] = -(FOOT_LOAD_N - 9.81)  # gravity carries 1 kg of the load
    for _ in range(750):
        mujoco.mj_step(m, d)
    return d.qpos.reshape(-1, 7)[:, :3].copy(), hf


def _crack_centres(z, deep: bool, num: int = 8):
    """Local (x, y) of up to ``num`` course vertices inside drawn gaps (deep: at the pit floor;
    else: shallow cracks, below both x-neighbours or both y-neighbours, >= 3 cells from the pit),
    spread over the tile."""
    c = z.copy()
    course = np.zeros_like(c, bool)
    course[2:-2, SPEC.n_start + 1 : SPEC.nx - SPEC.n_goal - 1] = True
    if deep:
        # Narrowest first: pit vertices with solid on both sides along x or y (1-vertex notches).
        pit = c == PIT
        solid = ~pit
        notch = (np.roll(solid, 1, 1) & np.roll(solid, -1, 1)) | (
            np.roll(solid, 1, 0) & np.roll(solid, -1, 0)
        )
        mask = pit & notch & course
    else:
        lx = (c < np.roll(c, 1, 1) - 2e-3) & (c < np.roll(c, -1, 1) - 2e-3)
        ly = (c < np.roll(c, 1, 0) - 2e-3) & (c < np.roll(c, -1, 0) - 2e-3)
        near_pit = ndimage.maximum_filter(c == PIT, size=7)  # a stone's edge: it can roll off
        mask = (lx | ly) & ~near_pit & course
    ii, jj = np.nonzero(mask)
    picks = []
    for i, j in zip(ii, jj, strict=True):
        if all(abs(i - a) + abs(j - b) > 8 for a, b in picks):
            picks.append((i, j))
    return [(j * CELL, i * CELL) for i, j in picks[:num]]


@pytest.mark.parametrize("name", (*STONE_TYPES, "platform_gap"))
def test_loaded_foot_sinks_no_deeper_than_the_nominal_crack_mujoco_c(name):
    """At level 0 every gap is narrower than the foot. A real crack of width w with vertical walls
    lets a sphere of radius r dip by the sagitta r - sqrt(r^2 - (w/2)^2); on the drawing the
    loaded foot dropped onto the drawn cracks stays within that bound for the widest gap the
    generator can draw at d = 0 (hand-computed: stones 5 cm x (1 + 2 x 0.1 jitter) = 6 cm ->
    0.0315 - sqrt(0.0315^2 - 0.03^2) = 2.19 cm; platform gaps <= 5 cm -> 1.23 cm), plus 3 mm
    of soft-contact penetration under 130 N. (The drawing before: 1 m V-notches that held the
    foot 0.26 m deep, ../shared/probes/crack_notch_drop.py.)"""
    widest = 0.06 if name in STONE_TYPES else 0.05
    bound = FOOT_R - np.sqrt(FOOT_R**2 - (widest / 2) ** 2)
    assert abs(float(crack_sag_m(widest, FOOT_R)) - bound) < 1e-6
    points = []
    for seed in range(12):  # platform gaps of 4.25-5 cm hold a vertex only now and then
        z = np.asarray(generate_tile(name, jax.random.PRNGKey(seed), 0.0))
        assert not _crack_centres(z, deep=True), "level 0 draws no notch to the pit floor"
        points += [(z, p) for p in _crack_centres(z, deep=False, num=4)]
        if len(points) >= 4:
            break
    assert points, "level 0 should draw cracks"
    for z, p in points:
        (pos,), _ = _drop_loaded_feet(z, [p])
        assert pos[2] - FOOT_R >= -(bound + 3e-3), (name, p, pos)


@pytest.mark.parametrize("name", (*STONE_TYPES, "platform_gap"))
def test_foot_in_a_gap_wider_than_the_foot_ends_the_episode_mujoco_c(name):
    """From level 1 on every gap is wider than the foot (drawn to the pit floor). A loaded foot
    dropped into the narrowest drawn gaps (one-vertex notches, which wedge it) ends the episode:
    the env's stuck-foot predicate fires, or it fell below env.foot_fall_z_m = -0.45 m."""
    d = 0.8 / 9  # level 1 of 10 over (0, 0.8)
    z = np.asarray(generate_tile(name, jax.random.PRNGKey(0), d))
    points = _crack_centres(z, deep=True, num=6)
    assert points, "level 1 should draw gaps to the pit floor"
    pos, hf = _drop_loaded_feet(z, points)
    # The tile's local frame: Heightfield vertex (i, j) at x0 + j cell, y0 + i cell.
    world = pos + np.array([hf.x0_m, hf.y0_m, 0.0])
    stuck = np.asarray(foot_stuck(jp.asarray(world), hf.height_at, STUCK_DEPTH_M))
    ended = stuck | (pos[:, 2] < -0.45)
    assert ended.all(), (name, pos, stuck)
    # foot_gap_depth (which foot went in, for the failure analysis) agrees with the predicate.
    depth = np.asarray(foot_gap_depth(jp.asarray(world), hf.height_at))
    np.testing.assert_array_equal(depth > STUCK_DEPTH_M, stuck)
    assert np.all(depth[stuck] > STUCK_DEPTH_M)


@pytest.mark.parametrize("name", ("rough_boxes", "stairs", "pyramid_up", "pyramid_down"))
def test_no_stuck_foot_on_gap_free_terrain(tiles, name):
    """Steps are not gaps: a foot resting anywhere on the hardest gap-free tiles (boxes 0.30 m
    spread, stair rises up to 0.29 m) or hovering 10 cm below a step's top edge is never stuck."""
    z = tiles[name][-1, 0]
    hf = Heightfield(heights=jp.asarray(z), cell_m=CELL, z_floor_m=PIT, z_range_m=SPEC.z_range_m)
    rng = np.random.default_rng(0)
    xy = np.stack(
        [
            hf.x0_m + rng.uniform(SPEC.course_x0_m, SPEC.course_x1_m, 4000),
            hf.y0_m + rng.uniform(0.2, SPEC.width_m - 0.2, 4000),
        ],
        axis=-1,
    ).astype(np.float32)
    ground = np.asarray(hf.height_at(jp.asarray(xy)))
    for lift in (FOOT_R, FOOT_R + 0.1):
        feet = jp.asarray(np.concatenate([xy, (ground + lift)[:, None]], axis=-1))
        assert not np.asarray(foot_stuck(feet, hf.height_at, STUCK_DEPTH_M)).any()
        assert np.all(np.asarray(foot_gap_depth(feet, hf.height_at)) == -np.inf)  # no gap around


def test_stone_schedules_keep_the_evaluation_ensemble():
    """From d = 0.72 (the ensemble: 90 % of the stage-1 range (0, 0.8)) on, the stone parameters
    equal the earlier linear schedules (hand values: grid size 0.60 -> 0.18, gap 0.05 -> 0.35,
    spread 0 -> 0.20, jitter 0.25; two-row gap 0.05 -> 0.45, spread 0 -> 0.15, lateral 0 ->
    0.05, jitter 0.2; mixed size 0.50 -> 0.18, gap 0.05 -> 0.40, keep 1 -> 0.85, f_lo 0.95 ->
    0.75), and the easy end is few large stones with level tops."""
    lerp = lambda a, b, d: a + (b - a) * d  # noqa: E731
    old = {
        "grid_stones": lambda d: dict(
            size=lerp(0.6, 0.18, d), gap=lerp(0.05, 0.35, d), dz=lerp(0, 0.2, d), jitter=0.25
        ),
        "two_row_stones": lambda d: dict(
            size=lerp(0.6, 0.18, d),
            gap=lerp(0.05, 0.45, d),
            dz=lerp(0, 0.15, d),
            jitter=0.2,
            lateral=lerp(0, 0.05, d),
        ),
        "mixed_row_stones": lambda d: dict(
            size=lerp(0.5, 0.18, d),
            gap=lerp(0.05, 0.4, d),
            dz=lerp(0, 0.2, d),
            jitter=0.25,
            keep=lerp(1, 0.85, d),
            f_lo=lerp(0.95, 0.75, d),
        ),
    }
    for curriculum in STONE_CURRICULUM_NAMES:
        for name, fn in old.items():
            for d in (0.72, 0.8, 0.9, 1.0):
                new = stone_params(name, d, curriculum)
                for k, v in fn(d).items():
                    assert abs(float(new[k]) - v) < 1e-5, (curriculum, name, d, k, float(new[k]), v)
            easy = stone_params(name, 0.0, curriculum)
            assert float(easy["size"]) >= 0.8 and float(easy["dz"]) == 0.0
            assert float(easy["gap"]) * (1 + 2 * float(easy["jitter"])) < 2 * FOOT_R
            one = stone_params(name, 0.8 / 9, curriculum)  # level 1: every gap wider than the foot
            assert float(one["gap"]) * (1 - 2 * float(one["jitter"])) > 2 * FOOT_R


@pytest.mark.parametrize("name", STONE_TYPES)
def test_both_stone_curricula_draw_the_same_ensemble(name):
    """The evaluation ensemble (difficulty 0.9 x 0.8 = 0.72, taken to float32 as the map does)
    and everything harder draw the same heights, bit for bit, whichever curriculum: the knot's
    values at the knot."""
    gaps, size = TileSpec(stone_curriculum="gaps_first"), TileSpec(stone_curriculum="size_first")
    for d in (0.9 * 0.8, 0.8, 1.0):
        for seed in range(3):
            key = jax.random.PRNGKey(seed)
            a = np.asarray(generate_tile(name, key, np.float32(d), gaps))
            b = np.asarray(generate_tile(name, key, np.float32(d), size))
            np.testing.assert_array_equal(a, b, err_msg=f"{name} d={d} seed={seed}")
    # ... and not below it (the curricula differ: the check above can fail).
    a = np.asarray(generate_tile(name, jax.random.PRNGKey(0), 0.36, gaps))
    b = np.asarray(generate_tile(name, jax.random.PRNGKey(0), 0.36, size))
    assert not np.array_equal(a, b)


# Hand values of the size-first curriculum's stages (the issue "Stones, fourth round"): the
# ensemble's stone (0.72) is reached at d = 0.36 with 0.10 m gaps and level tops, the ensemble's
# gap at 0.54 with level tops, the ensemble's height spread at 0.72.
ENSEMBLE = {  # at d = 0.72: size, gap, dz
    "grid_stones": (0.2976, 0.266, 0.144),
    "two_row_stones": (0.2976, 0.338, 0.108),
    "mixed_row_stones": (0.2696, 0.302, 0.144),
}


@pytest.mark.parametrize("name", STONE_TYPES)
def test_size_first_shrinks_then_widens_then_spreads(name):
    size, gap, dz = ENSEMBLE[name]
    at = lambda d: {k: float(v) for k, v in stone_params(name, d, "size_first").items()}  # noqa: E731
    small = at(0.36)
    assert abs(small["size"] - size) < 1e-6 and abs(small["gap"] - 0.10) < 1e-6, small
    assert small["dz"] == 0.0, small
    wide = at(0.54)
    assert abs(wide["size"] - size) < 1e-6 and abs(wide["gap"] - gap) < 1e-6, wide
    assert wide["dz"] == 0.0, wide
    ens = at(0.72)
    assert abs(ens["dz"] - dz) < 1e-6, ens
    # Every parameter moves one way over d: sizes never grow, gaps and spreads never narrow, and
    # no stage starts before the one before it has ended.
    ds = np.linspace(0.0, 1.0, 201)
    rows = [at(d) for d in ds]
    sizes, gaps, dzs = (np.array([r[k] for r in rows]) for k in ("size", "gap", "dz"))
    assert np.all(np.diff(sizes) <= 1e-6) and np.all(np.diff(dzs) >= -1e-6)
    assert np.all(np.diff(gaps[ds >= 0.08]) >= -1e-6)
    assert np.all(gaps[(ds >= 0.08) & (ds <= 0.36)] <= 0.10 + 1e-6)  # narrow while shrinking
    assert np.all(dzs[ds <= 0.54] == 0.0)  # level tops until the gaps are the ensemble's
    # Level by level (10 over (0, 0.8)): no level shrinks the stones by more than 30 %.
    levels = [at(0.8 * k / 9)["size"] for k in range(10)]
    assert all(b / a >= 0.70 for a, b in zip(levels[:-1], levels[1:], strict=True)), levels


@pytest.mark.parametrize("name", STONE_TYPES)
def test_size_first_draws_small_stones_at_narrow_gaps(name):
    """Measured on generated tiles at d = 0.36 (level ~4): the stones' flat tops average the
    ensemble's nominal size x the mean size factor (hand-computed from the table) within a cell,
    and the gaps crossed along x (grid and two-row stones) average the nominal 0.10 m within half
    a cell."""
    size, _, _ = ENSEMBLE[name]
    f_lo = float(stone_params(name, 0.36, "size_first")["f_lo"])
    spec = TileSpec(stone_curriculum="size_first")
    zs = [np.asarray(generate_tile(name, jax.random.PRNGKey(s), 0.36, spec)) for s in range(12)]
    sizes = [v for z in zs for v in _stone_sizes_x(z)]
    gaps = [v for z in zs for v in _gaps_x(z) if v < 1.0]  # not a line along a row gap
    assert len(sizes) > 50 and len(gaps) > 50
    expect = size * (1 + f_lo) / 2
    assert abs(np.mean(sizes) - expect) < CELL, (np.mean(sizes), expect)
    if name != "mixed_row_stones":  # (mixed rows shift each column across y: no x-line gap)
        assert abs(np.mean(gaps) - 0.10) < CELL / 2, np.mean(gaps)


def test_saved_config_without_stone_curriculum_keeps_gaps_first():
    """A run config saved before terrain.stone_curriculum existed trained (and evaluates) on the
    gaps-first curriculum (read migrated, foottof.renames); a fresh config trains size-first; a
    bad name is one clear error."""
    from configs import _terrain
    from foottof import renames

    fresh = _terrain.get_section()
    assert TileSpec.from_config(fresh).stone_curriculum == "size_first"
    saved = fresh.to_dict()
    del saved["stone_curriculum"]
    migrated = ml_collections.ConfigDict(renames.migrate_config_dict({"terrain": saved})["terrain"])
    assert TileSpec.from_config(migrated).stone_curriculum == "gaps_first"
    with pytest.raises(ValueError, match="stone_curriculum.*size_first"):
        TileSpec(stone_curriculum="dense")


# ------------------------------------------------------------------------------- terrain map

SMALL_TILE = TileSpec(length_m=4.0, width_m=2.0, platform_length_m=1.2, goal_length_m=0.8)
SMALL_MAP = TerrainMapSpec(
    tile=SMALL_TILE,
    num_levels=3,
    col_types=(0, 0, 3, 5),  # grid_stones x 2, platform_gap, beam
    col_difficulty=((0.0, 1.0), (0.0, 1.0), (0.2, 0.6), (0.5, 0.5)),
    border_m=0.4,
)
# The same tile types and geometry, another size and difficulty table.
_BIGGER_MAP = dataclasses.replace(
    SMALL_MAP,
    num_levels=5,
    col_types=(0, 3, 3, 5, 5),
    col_difficulty=((0.1, 0.9), (0.0, 1.0), (0.3, 0.4), (0.2, 0.6), (0.0, 0.0)),
)


@pytest.fixture(scope="module")
def small_map():
    return build_terrain_map(jax.random.key(5), SMALL_MAP)


def test_map_layout_matches_tiles(small_map):
    tm = small_map
    s, t = SMALL_MAP, SMALL_TILE
    b = s.border_cells
    assert tm.hfield.shape == s.hfield_shape == (3 * t.ny + 2 * b, 4 * t.nx + 2 * b)
    assert tm.hfield.x0_m == tm.hfield.y0_m == pytest.approx(-0.4)
    assert tm.hfield.z_floor_m == PIT and tm.hfield.cell_m == CELL
    h = np.asarray(tm.hfield.heights)
    assert np.all(h[:b] == 0) and np.all(h[:, :b] == 0) and np.all(h[-b:] == 0)
    np.testing.assert_allclose(np.asarray(tm.difficulty[:, 2]), [0.2, 0.4, 0.6], atol=1e-6)
    np.testing.assert_allclose(np.asarray(tm.level_difficulty), [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(np.asarray(tm.col_type), s.col_types)
    keys = jax.random.split(jax.random.key(5), (3, 4))
    gen = jax.jit(generate_tile, static_argnums=(0, 3))
    for lvl, col in ((0, 0), (2, 1), (1, 2), (2, 3)):
        name = TERRAIN_TYPES[s.col_types[col]]
        tile = np.asarray(gen(name, keys[lvl, col], tm.difficulty[lvl, col], t))
        block = h[b + lvl * t.ny : b + (lvl + 1) * t.ny, b + col * t.nx : b + (col + 1) * t.nx]
        np.testing.assert_allclose(block, tile, atol=1e-5)
        # World placement: the vertex at tile-local (i, j) is at (col * L_x + j c, lvl * L_y + i c).
        xy = jp.array([col * t.length_m + 60 * CELL + 1e-4, lvl * t.width_m + 17 * CELL + 1e-4])
        assert float(tm.hfield.height_at(xy)) == pytest.approx(float(tile[17, 60]), abs=1e-3)


def test_spawn_and_goal_on_flat_regions(small_map):
    tm = small_map
    sp, goal = np.asarray(tm.spawn), np.asarray(tm.goal)
    assert sp.shape == (3, 4, 4) and goal.shape == (3, 4, 2)
    assert np.all(sp[..., SPAWN_YAW] == 0) and np.all(sp[..., SPAWN_Z] == 0)
    hs = np.asarray(tm.hfield.height_at(jp.asarray(sp[..., :2])))
    hg = np.asarray(tm.hfield.height_at(jp.asarray(goal)))
    np.testing.assert_array_equal(hs, sp[..., SPAWN_Z])
    np.testing.assert_array_equal(hg, 0.0)
    # A 1 m x 0.6 m robot footprint around the spawn lies on the flat start platform.
    for dx in (-0.5, 0.0, 0.5):
        for dy in (-0.3, 0.3):
            off = jp.array([dx, dy])
            assert np.all(np.asarray(tm.hfield.height_at(jp.asarray(sp[..., :2]) + off)) == 0)
    lvl, col = tile_at(tm, jp.asarray(sp[..., :2]))
    ll, cc = np.meshgrid(np.arange(3), np.arange(4), indexing="ij")
    np.testing.assert_array_equal(np.asarray(lvl), ll)
    np.testing.assert_array_equal(np.asarray(col), cc)
    lvl, col = tile_at(tm, jp.asarray(goal))
    np.testing.assert_array_equal(np.asarray(col), cc)
    assert np.all(goal[..., 0] > sp[..., SPAWN_X] + 2.0)
    np.testing.assert_allclose(goal[..., 1], sp[..., SPAWN_Y])


def _compiles_of_tile_generators() -> int:
    return sum(tile_generator(t, SMALL_TILE)._cache_size() for t in set(SMALL_MAP.col_types))


def test_map_regenerates_without_recompiling(small_map):
    """A new key, or another map of the same tile types and geometry (more levels and columns,
    another difficulty table) compiles nothing: each type's tile generator is compiled once."""
    before = _compiles_of_tile_generators()
    assert before >= len(set(SMALL_MAP.col_types))  # at least one per type, from the fixture
    other = build_terrain_map(jax.random.key(6), SMALL_MAP)
    again = build_terrain_map(jax.random.key(5), SMALL_MAP)
    bigger = build_terrain_map(jax.random.key(8), _BIGGER_MAP)
    assert _compiles_of_tile_generators() == before
    assert bigger.hfield.heights.shape[0] > small_map.hfield.heights.shape[0]
    assert not np.array_equal(
        np.asarray(other.hfield.heights), np.asarray(small_map.hfield.heights)
    )
    np.testing.assert_array_equal(
        np.asarray(again.hfield.heights), np.asarray(small_map.hfield.heights)
    )


def test_sample_spawn_goal_spread(small_map):
    s = SMALL_MAP
    n = 2000
    level = jp.arange(n) % 3
    col = jp.arange(n) % 4
    spawn, goal = jax.jit(sample_spawn_goal)(jax.random.key(0), small_map, level, col)
    dev = np.asarray(spawn - small_map.spawn[level, col])
    gdev = np.asarray(goal - small_map.goal[level, col])
    for k, lim in (
        (SPAWN_X, s.spawn_x_spread_m),
        (SPAWN_Y, s.spawn_y_spread_m),
        (SPAWN_YAW, s.spawn_yaw_spread_rad),
    ):
        assert np.abs(dev[:, k]).max() <= lim + 1e-6 and np.abs(dev[:, k]).max() > 0.9 * lim
    assert np.all(dev[:, SPAWN_Z] == 0)
    assert np.abs(gdev[:, 0]).max() <= s.goal_x_spread_m + 1e-6
    assert np.abs(gdev[:, 1]).max() > 0.9 * s.goal_y_spread_m
    assert np.corrcoef(dev[:, 0], gdev[:, 0])[0, 1] < 0.1  # independent draws
    assert np.all(np.asarray(small_map.hfield.height_at(spawn[:, :2])) == 0)
    assert np.all(np.asarray(small_map.hfield.height_at(goal)) == 0)


def test_stage_specs_from_config():
    cfg = _terrain.get_section()
    s1 = TerrainMapSpec.from_config(cfg, 1)
    s2 = TerrainMapSpec.from_config(cfg, 2)
    assert s1.num_cols == s2.num_cols == cfg.num_cols
    assert set(s1.col_types) == set(range(5))
    assert set(s2.col_types) == set(range(9))
    stones = {TERRAIN_TYPES.index(n) for n in ("grid_stones", "two_row_stones", "mixed_row_stones")}
    assert np.mean([t in stones for t in s1.col_types]) >= 0.6  # mostly stepping stones
    lo1 = {t: r[0] for t, r in zip(s1.col_types, s1.col_difficulty, strict=True)}
    lo2 = {t: r[0] for t, r in zip(s2.col_types, s2.col_difficulty, strict=True)}
    assert all(lo2[t] > lo1[t] for t in range(5))  # stage-1 types shifted harder in stage 2
    assert s1.hfield_shape == (10 * 100 + 50, 20 * 150 + 50)
    with pytest.raises(ValueError, match="stage=3"):
        TerrainMapSpec.from_config(cfg, 3)


def test_eval_ensemble_spec():
    cfg = _terrain.get_section()
    ev = _eval.get_section()  # the paper's ensemble: 80 % stones (3 types), 20 % gaps, 90 %
    e = make_eval_map_spec(
        cfg,
        ev.stone_types + ev.gap_types,
        (0.8 / 3,) * 3 + (0.2,),
        ev.difficulty_fraction,
        ev.num_levels,
        num_cols=10,
    )
    names = [TERRAIN_TYPES[t] for t in e.col_types]
    assert names.count("platform_gap") == 2 and len(names) == 10  # 20 % gaps, 80 % stones
    lo, hi = cfg.stage1_difficulty.grid_stones
    assert all(r == pytest.approx((lo + 0.9 * (hi - lo),) * 2) for r in e.col_difficulty)
    with pytest.raises(ValueError, match="'stairs'"):
        make_eval_map_spec(
            cfg, types=("stairs",), weights=(1.0,), progress=0.9, num_levels=5, num_cols=10
        )


def test_allocate_columns():
    cols = allocate_columns({"grid_stones": 0.5, "beam": 0.25, "stairs": 0.25}, 8)
    assert cols == (0, 0, 0, 0, 5, 5, 6, 6)
    cols = allocate_columns({"grid_stones": 0.98, "beam": 0.01, "stairs": 0.01}, 3)
    assert sorted(set(cols)) == [0, 5, 6]  # every positive weight keeps a column
    with pytest.raises(ValueError, match="'rocks'.*valid choices"):
        allocate_columns({"rocks": 1.0}, 4)
    with pytest.raises(ValueError, match="num_cols"):
        allocate_columns({"beam": 1.0}, 0)


@pytest.mark.slow
def test_full_training_map_builds_fast():
    spec = TerrainMapSpec.from_config(_terrain.get_section(), 2)
    build_terrain_map(jax.random.key(0), spec).hfield.heights.block_until_ready()
    t0 = time.perf_counter()
    for i in range(3):
        build_terrain_map(jax.random.key(i + 1), spec).hfield.heights.block_until_ready()
    assert (time.perf_counter() - t0) / 3 < 2.0


# -------------------------------------------------------------------------------- curriculum


def test_progress_fraction_hand_values():
    s, g = jp.array([0.0, 0.0]), jp.array([4.0, 0.0])
    xy = jp.array([[4.0, 0.0], [2.0, 0.0], [0.0, 0.0], [-1.0, 0.0], [4.0, 3.0]])
    # distances to goal 0, 2, 4, 5, 3 out of 4 -> 1, 0.5, 0, -0.25, 0.25
    np.testing.assert_allclose(np.asarray(progress_fraction(s, g, xy)), [1, 0.5, 0, -0.25, 0.25])


def test_update_levels_rules():
    num_levels = 5
    level = jp.array([2, 2, 2, 0, 3, 2, 4])
    done = jp.array([True, True, True, True, True, False, False])
    reached = jp.array([True, False, False, False, True, True, True])
    progress = jp.array([1.0, 0.2, 0.7, 0.0, 1.0, 1.0, 1.0])
    new = update_levels(jax.random.key(0), level, done, reached, progress, num_levels, 0.5)
    # up, down (< half), stay (>= half), floor at 0, up, not done, not done
    np.testing.assert_array_equal(np.asarray(new), [3, 1, 2, 0, 4, 2, 4])
    # Single env with Python scalars (bools must not turn into ~True == -2).
    key = jax.random.key(0)
    assert int(update_levels(key, 2, True, False, 0.7, num_levels)) == 2
    assert int(update_levels(key, 2, True, False, 0.2, num_levels)) == 1
    assert int(update_levels(key, 2, False, True, 1.0, num_levels)) == 2
    # Promotion on distance: covered >= up_progress_frac without reaching the goal -> up.
    assert int(update_levels(key, 2, True, False, 0.85, num_levels, 0.5, 0.8)) == 3
    assert int(update_levels(key, 2, True, False, 0.75, num_levels, 0.5, 0.8)) == 2
    assert int(update_levels(key, 2, True, False, 0.85, num_levels)) == 2  # default: goal only
    with pytest.raises(ValueError, match="up_progress_frac=0.3"):
        update_levels(key, 2, True, False, 0.85, num_levels, 0.5, 0.3)
    # A fall at >= up_progress_frac does not promote (it would pay rushing); reaching the goal
    # still does, and a fall that covered < down_progress_frac still demotes.
    assert int(update_levels(key, 2, True, False, 0.85, num_levels, 0.5, 0.8, True)) == 2
    assert int(update_levels(key, 2, True, False, 0.85, num_levels, 0.5, 0.8, False)) == 3
    assert int(update_levels(key, 2, True, True, 1.0, num_levels, 0.5, 0.8, True)) == 3
    assert int(update_levels(key, 2, True, False, 0.2, num_levels, 0.5, 0.8, True)) == 1


def test_update_levels_top_level_goes_random():
    n, num_levels = 4000, 6
    level = jp.full((n,), num_levels - 1)
    ones = jp.ones((n,), bool)
    new = jax.jit(update_levels, static_argnums=(5, 6))(
        jax.random.key(1), level, ones, ones, jp.ones((n,)), num_levels, 0.5
    )
    counts = np.bincount(np.asarray(new), minlength=num_levels)
    assert counts.sum() == n and len(counts) == num_levels
    assert np.all(np.abs(counts - n / num_levels) < 5 * np.sqrt(n / num_levels))  # ~ uniform


def test_update_levels_bad_fraction_raises():
    with pytest.raises(ValueError, match="down_progress_frac=1.5"):
        update_levels(
            jax.random.key(0), jp.zeros(2, int), *(jp.ones(2, bool),) * 2, jp.ones(2), 3, 1.5
        )


def test_levels_table_level_zero_is_hazard_free():
    """python -m foottof.lab.levels_table: level 0 of every stage-1 pit type crosses no gap to
    the pit floor; level 1's narrowest drawn gap is wider than the foot (the top opening of a
    one-vertex gap spans two cells, 8 cm > 6.3 cm)."""
    from configs import stage1_cpu
    from foottof.lab import levels_table

    rows = levels_table.table(stage1_cpu.get_config().terrain, seeds=1)
    assert {r["type"] for r in rows} == set(levels_table.TABLE_TYPES)
    for r in rows:
        if r["level"] == 0:
            assert r["hazards_per_m"] == 0.0, r
        if r["level"] == 1:
            assert r["hazards_per_m"] > 0.5 and r["narrowest"] >= 2 * CELL, r
    md = levels_table.format_markdown(rows)
    assert md.count("\n") == len(rows) + 2
