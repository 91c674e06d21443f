"""Tests of foottof.sensors: ray caster vs mj_ray, VL53L5CX zones, timing, degradation, fit."""

import math

import jax
import jax.numpy as jp
import ml_collections
import mujoco
import numpy as np
import pytest

from configs import _sensor
from foottof.sensors import (
    MISS,
    TimingSpec,
    ToFReading,
    ToFSpec,
    bounds_from_config,
    characterize,
    degrade,
    init,
    make_spec,
    make_timing_spec,
    ray_heightfield,
    ray_heightfield_normal,
    raycast,
    reset,
    sample_levels,
    sense,
    step,
    zero_levels,
)
from foottof.sensors import noise_model as nm
from foottof.sensors.tof import zone_minimum
from foottof.terrain.heightfield import Heightfield, hfield_xml, write_to_mjmodel

CELL = 0.04
N_GRID = 81  # square hfield, 3.2 m x 3.2 m
X0, Y0 = -1.3, -1.7
R_ORACLE = 6.0  # longer than any chord of the hfield box: every mj_ray hit is in range
DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # site x fwd, z down
T_HALF = math.tan(math.radians(22.5))
SENSE = jax.jit(sense, static_argnums=0)  # spec static: one compile per spec and shape
DEGRADE = jax.jit(degrade, static_argnums=(4, 5))
ZONE_MIN = jax.jit(zone_minimum, static_argnums=0)


def _stones_over_pit(seed: int) -> np.ndarray:
    """Stepping stones (0.08-0.32 m squares, tops -0.1..0.15 m) and gaps over a -0.5 m pit."""
    rng = np.random.default_rng(seed)
    h = np.full((N_GRID, N_GRID), -0.5)
    for _ in range(40):
        i, j = rng.integers(0, N_GRID - 5, 2)
        a, b = rng.integers(2, 8, 2)
        h[i : i + a, j : j + b] = rng.uniform(-0.1, 0.15)
    h[:, :10] = 0.0  # start platform
    h[:, -10:] = 0.05  # goal platform
    return h


def _mj_model(hf: Heightfield):
    asset, geom = hfield_xml(hf)
    m = mujoco.MjModel.from_xml_string(
        f"<mujoco><asset>{asset}</asset><worldbody>{geom}</worldbody></mujoco>"
    )
    write_to_mjmodel(m, hf)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    return m, d


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _oracle_rays(h: np.ndarray, rng) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Ray families (origins, unit directions). Origins avoid the hfield's outer boundary lines,
    where MuJoCo's own inside/outside decision depends on the 1e-6 rounding of the MJCF pos."""
    xs = lambda n: rng.uniform(X0 - 0.2, X0 + 3.4, n)
    ys = lambda n: rng.uniform(Y0 - 0.2, Y0 + 3.4, n)
    out = {}
    n = 10_000
    out["random"] = (
        np.stack([xs(n), ys(n), rng.uniform(-1.3, 1.0, n)], -1),
        _unit(rng.normal(size=(n, 3))),
    )
    n = 1500
    o = np.stack([xs(n), ys(n), rng.uniform(-0.45, 1.0, n)], -1)
    o[:500, 0] = X0 + rng.integers(1, N_GRID - 1, 500) * CELL  # on interior grid lines
    o[500:1000, 1] = Y0 + rng.integers(1, N_GRID - 1, 500) * CELL
    out["straight_down"] = (o, np.tile([0.0, 0.0, -1.0], (n, 1)))
    # Grazing stone corners: rays through points within 0.1 mm of vertices on stone edges.
    edges = np.argwhere(np.abs(np.diff(h, axis=1)) > 0.02)
    sel = edges[rng.integers(0, len(edges), n)]
    i, j = sel[:, 0], sel[:, 1] + rng.integers(0, 2, n)
    p = np.stack([X0 + j * CELL, Y0 + i * CELL, h[i, j]], -1) + rng.uniform(-1e-4, 1e-4, (n, 3))
    dd = rng.normal(size=(n, 3))
    dd[:, 2] = -np.abs(dd[:, 2]) * rng.uniform(0.0, 2.0, n)
    dd = _unit(dd)
    out["grazing_corners"] = (p - 0.7 * dd, dd)
    # Along the (one-cell-wide, steep) stone faces: near-horizontal rays skimming grid lines.
    o = np.stack(
        [
            np.full(n, X0 - 0.05),
            Y0 + rng.integers(1, N_GRID - 1, n) * CELL,
            rng.uniform(-0.5, 0.2, n),
        ],
        -1,
    )
    o[:, 1] += rng.choice([-1.0, 1.0], n) * rng.uniform(1e-4, 1e-3, n)
    dd = _unit(np.stack([np.ones(n), rng.uniform(-1e-3, 1e-3, n), rng.uniform(-0.05, 0.05, n)], -1))
    out["along_faces_x"] = (o, dd)
    o = np.stack(
        [
            X0 + rng.integers(1, N_GRID - 1, n) * CELL,
            np.full(n, Y0 - 0.05),
            rng.uniform(-0.5, 0.2, n),
        ],
        -1,
    )
    o[:, 0] += rng.choice([-1.0, 1.0], n) * rng.uniform(1e-4, 1e-3, n)
    out["along_faces_y"] = (o, dd[:, [1, 0, 2]])
    # Starting below the surface (inside stones / the pit solid).
    o = np.stack([xs(n), ys(n), np.zeros(n)], -1)
    hz = np.array([_height_np(h, x, y) for x, y in o[:, :2]])
    o[:, 2] = hz - rng.uniform(1e-3, 0.3, n)
    out["below_surface"] = (o, _unit(rng.normal(size=(n, 3))))
    return out


def _height_np(h, x, y):
    u = np.clip((x - X0) / CELL, 0.0, N_GRID - 1.000001)
    v = np.clip((y - Y0) / CELL, 0.0, N_GRID - 1.000001)
    j, i = int(u), int(v)
    fu, fv = u - j, v - i
    if fu >= fv:
        return h[i, j] + fu * (h[i, j + 1] - h[i, j]) + fv * (h[i + 1, j + 1] - h[i, j + 1])
    return h[i, j] + fv * (h[i + 1, j] - h[i, j]) + fu * (h[i + 1, j + 1] - h[i + 1, j])


@pytest.fixture(scope="module")
def oracle():
    """Our distances and mj_ray's for all ray families, from one compiled call."""
    h = _stones_over_pit(0)
    hf = Heightfield(heights=jp.asarray(h, jp.float32), x0_m=X0, y0_m=Y0, cell_m=CELL)
    m, d = _mj_model(hf)
    fams = _oracle_rays(h, np.random.default_rng(1))
    o = np.concatenate([v[0] for v in fams.values()])
    dd = np.concatenate([v[1] for v in fams.values()])
    ours = np.asarray(jax.jit(lambda o, d: ray_heightfield(hf, o, d, R_ORACLE))(o, dd))
    gid = np.zeros(1, np.int32)
    ref = np.array([mujoco.mj_ray(m, d, o[i], dd[i], None, 1, -1, gid) for i in range(len(o))])
    names = np.concatenate([[k] * len(v[0]) for k, v in fams.items()])
    return {"ours": ours, "ref": ref, "names": names, "hf": hf, "h": h}


def test_ray_matches_mj_ray(oracle):
    ours, ref, names = oracle["ours"], oracle["ref"], oracle["names"]
    assert len(ours) >= 10_000
    assert np.all(ref <= R_ORACLE)
    hit_o, hit_r = ours >= 0, ref >= 0
    for fam in np.unique(names):
        sel = names == fam
        assert np.array_equal(hit_o[sel], hit_r[sel]), f"hit/miss disagreement in {fam}"
        assert 0.02 < hit_r[sel].mean() or fam == "random"
    both = hit_o & hit_r
    err = np.abs(ours - ref)[both]
    assert (err <= 1e-3).mean() >= 0.999, f"only {(err <= 1e-3).mean():.5f} within 1 mm"
    assert np.all(ours[~hit_o] == MISS)
    assert hit_r.mean() > 0.3 and (~hit_r).sum() > 100  # both outcomes exercised


@pytest.mark.parametrize(
    "first, max_range",
    [
        (0, 0.3),
        # None: the shipped ROUNDS (test_ray_matches_mj_ray runs them against mj_ray too)
        pytest.param(None, 1.0, marks=pytest.mark.slow),
        pytest.param(4, R_ORACLE, marks=pytest.mark.slow),
    ],
)
def test_adaptive_walk_equals_walking_every_strip(oracle, monkeypatch, first, max_range):
    """The adaptive strip walk (most rays stop after a few strips, the rest are gathered and walk
    on) gives bit-identical distances and normals to every ray walking every strip, for one ray
    set and under vmap (whose rule walks the rays of all batch elements together), also when the
    unfinished rays need several gathering rounds and passes (tiny shares), and with the shipped
    rounds."""
    hf = oracle["hf"]
    fams = _oracle_rays(oracle["h"], np.random.default_rng(2))
    pick = np.random.default_rng(3).permutation(sum(len(v[0]) for v in fams.values()))[:4000]
    o = np.concatenate([v[0] for v in fams.values()])[pick].astype(np.float32)  # every family
    d = np.concatenate([v[1] for v in fams.values()])[pick].astype(np.float32)
    d[:7] = 0.0  # zero directions stay misses
    full = jax.jit(lambda o, d: raycast._cast(hf, o, d, max_range, True, adaptive=False))(o, d)
    if first is not None:  # else the shipped raycast.ROUNDS
        # 0 first strips: every ray is gathered; tiny shares: many passes per round
        monkeypatch.setattr(raycast, "ROUNDS", ((first, 1.0), (1, 0.01), (3, 0.02), (None, 0.01)))
    one = jax.jit(lambda o, d: raycast._cast(hf, o, d, max_range, True))(o, d)
    batched = jax.jit(
        jax.vmap(lambda o, d: raycast._cast(hf, o, d, max_range, True))  # 40 "envs"
    )(o.reshape(40, -1, 3), d.reshape(40, -1, 3))
    for got in (one, tuple(x.reshape(full[i].shape) for i, x in enumerate(batched))):
        np.testing.assert_array_equal(got[0], full[0])
        np.testing.assert_array_equal(got[1], full[1])
    assert (full[0] >= 0).mean() > 0.2 and (full[0] < 0).sum() > 100
    # A terrain per "env" (as each env's height scan): rays read their own terrain.
    shift = np.arange(40) % 7 * 3  # terrain k = the oracle's heights rolled by a few cells
    terrains = jp.stack([jp.roll(hf.heights, int(k), axis=int(k) % 2) for k in shift])

    def per_env(adaptive):
        def cast(h, o, d):
            return raycast._cast(hf.replace(heights=h), o, d, max_range, True, adaptive)

        return jax.jit(jax.vmap(cast))(terrains, o.reshape(40, -1, 3), d.reshape(40, -1, 3))

    own = per_env(False)
    for a, b in zip(per_env(True), own, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(own[0].reshape(-1), full[0])  # the terrains differ


def test_ray_max_range_and_miss(oracle):
    hf = oracle["hf"]
    o = jp.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.05]])
    d = jp.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -3.0], [0.0, 0.0, 1.0]])
    z = _height_np(oracle["h"], 0.0, 0.0)
    cast = jax.jit(lambda o, d: ray_heightfield(hf, o, d, 3.0))
    t_far = cast(o, d)
    assert t_far[0] == pytest.approx(1.0 - z, abs=1e-5)
    assert t_far[1] == MISS  # pointing up into the sky
    assert t_far[2] == pytest.approx(1.0 - z, abs=1e-5)  # direction normalized
    assert t_far[3] == pytest.approx(0.05, abs=1e-5)  # inside the base box: exits its top face
    # From 3 m + 1 mm above the surface the hit lies beyond max_range (3 m), from 3 m - 1 mm not.
    o_far = o.at[0, 2].set(z + 3.001).at[2, 2].set(z + 2.999)
    t_short = cast(o_far, d)  # same shapes: no recompilation
    assert t_short[0] == MISS
    assert t_short[2] == pytest.approx(2.999, abs=1e-4)
    with pytest.raises(ValueError, match="max_range"):
        ray_heightfield(hf, o, d, -1.0)
    with pytest.raises(ValueError, match="shape"):
        ray_heightfield(hf, o[:, :2], d[:, :2], 1.0)


def test_ray_normal_on_slope_and_wall():
    slope = 0.3  # z = 0.3 x
    xs = X0 + np.arange(N_GRID) * CELL
    h = np.tile(slope * xs, (N_GRID, 1))
    hf = Heightfield(heights=jp.asarray(h, jp.float32), x0_m=X0, y0_m=Y0, cell_m=CELL)
    rng = np.random.default_rng(0)
    n = 200
    o = np.stack([rng.uniform(-0.5, 1.0, n), rng.uniform(-1.0, 1.0, n), np.full(n, 0.9)], -1)
    d = _unit(np.stack([rng.uniform(-0.2, 0.2, n), rng.uniform(-0.2, 0.2, n), -np.ones(n)], -1))
    cast = jax.jit(lambda o, d: ray_heightfield_normal(hf, o, d, 2.0))
    t, nrm = cast(o, d)
    assert np.all(np.asarray(t) > 0)
    expect = _unit(np.array([-slope, 0.0, 1.0]))
    np.testing.assert_allclose(np.asarray(nrm), np.tile(expect, (n, 1)), atol=1e-5)
    hit = o + np.asarray(t)[:, None] * d
    np.testing.assert_allclose(hit[:, 2], slope * hit[:, 0], atol=1e-5)
    # A horizontal ray from outside at x < x0 below the edge profile hits the -x side wall.
    o_w, d_w = np.tile([[X0 - 0.5, 0.0, -0.9]], (n, 1)), np.tile([[1.0, 0.0, 0.0]], (n, 1))
    t_w, n_w = cast(o_w, d_w)  # same shapes: no recompilation
    assert float(t_w[0]) == pytest.approx(0.5, abs=1e-5)
    np.testing.assert_allclose(np.asarray(n_w[0]), [-1.0, 0.0, 0.0])


# ----------------------------------------------------------------------------- VL53L5CX zones


def _flat(z=0.0):
    return Heightfield(heights=jp.full((61, 61), z, jp.float32), x0_m=-1.2, y0_m=-1.2, cell_m=CELL)


def _rot_x(deg):
    a = math.radians(deg)
    return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])


def _brute_zone_min(spec: ToFSpec, rot: np.ndarray, height: float, n: int = 400) -> np.ndarray:
    """Dense sampling of the closed-form radial distance height / (-dir . z_world) per zone."""
    g = spec.grid
    edges = np.linspace(-T_HALF, T_HALF, g + 1)
    out = np.zeros((g, g))
    for r in range(g):
        for c in range(g):
            tx, ty = np.meshgrid(
                np.linspace(edges[r], edges[r + 1], n), np.linspace(edges[c], edges[c + 1], n)
            )
            v = _unit(np.stack([tx, ty, np.ones_like(tx)], -1)) @ rot.T
            out[r, c] = np.min(height / -v[..., 2])
    return out.reshape(-1)


# One spec and terrain shape for the zone tests below: SENSE compiles once for all of them.
SPEC2 = ToFSpec(num_sensors=2, tilt_deg=((0.0, 0.0), (17.0, 0.0)), offset_m=((0.0, 0.0, 0.0),) * 2)


def test_flat_floor_zone_minimum_closed_form():
    spec = SPEC2
    h = 0.4
    pos = jp.array([[0.1, 0.2, h], [-0.1, 0.0, h]])
    rot = jp.asarray(np.stack([DOWN, DOWN]))
    r = SENSE(spec, _flat(), pos, rot)
    got = np.asarray(r.distance_m)
    assert np.all(np.asarray(r.valid))
    # Untilted, looking straight down: centre zones h, edge zones h sqrt(1 + T^2/4), corners
    # h sqrt(1 + T^2/2) (nearest point = the zone corner closest to the optical axis).
    centre, edge, corner = h, h * math.sqrt(1 + T_HALF**2 / 4), h * math.sqrt(1 + T_HALF**2 / 2)
    expect = np.array(
        [
            [corner, edge, edge, corner],
            [edge, centre, centre, edge],
            [edge, centre, centre, edge],
            [corner, edge, edge, corner],
        ]
    ).reshape(-1)
    np.testing.assert_allclose(got[0], expect, atol=0.6e-3)  # 1 mm quantization
    # Tilted 17 deg about x: the perpendicular foot of the floor lies inside the FoV on a zone
    # row boundary, off the ray lattice; the two zones sharing it read exactly h, although none
    # of their 5 rays alone reads less than h + 1 mm (the interpolation matters).
    tilted = DOWN @ _rot_x(17.0)
    np.testing.assert_allclose(got[1], _brute_zone_min(spec, tilted, h), atol=0.6e-3)
    foot = np.linalg.solve(tilted, [0.0, 0.0, -1.0])
    col = int((foot[1] / foot[2] + T_HALF) // (2 * T_HALF / 4))
    assert abs(foot[0]) < 1e-9 and 0 <= col < 4
    dirs = spec.ray_directions() @ tilted.T
    for zone in (1 * 4 + col, 2 * 4 + col):
        assert got[1][zone] == pytest.approx(h, abs=1e-6)
        ray_min = np.min(h / -dirs[spec.zone_rays()[zone], 2])
        assert ray_min > h + 1e-3
    # Incidence at the hit on a flat floor = angle of the nearest ray from vertical.
    assert float(np.asarray(r.incidence_rad)[0][5]) == pytest.approx(0.0, abs=1e-3)


def _brute_patch_min(points: np.ndarray, ok: np.ndarray, n: int = 240) -> float:
    """Nearest |p| over a zone's interpolation patch by dense sampling (float64 NumPy): the fan
    triangles (centre, corner_i, corner_i+1) whose 3 points are valid, the segments between valid
    neighbouring corners and from valid corners to a valid centre, and the valid points.
    points (5, 3): 4 corners in cyclic order, then the centre; ok (5,) bool. inf if none."""
    w = np.linspace(0.0, 1.0, n + 1)
    a_, b_ = np.meshgrid(w, w)
    keep = a_ + b_ <= 1.0
    a_, b_ = a_[keep][:, None], b_[keep][:, None]  # barycentric grid incl. edges and vertices
    best = min([np.linalg.norm(points[i]) for i in range(5) if ok[i]], default=np.inf)
    c = points[4]
    for i in range(4):
        j = (i + 1) % 4
        for u, v in ((i, j), (i, 4)):
            if ok[u] and ok[v]:
                seg = points[u] + w[:, None] * (points[v] - points[u])
                best = min(best, np.min(np.linalg.norm(seg, axis=-1)))
        if ok[i] and ok[j] and ok[4]:
            tri = c + a_ * (points[i] - c) + b_ * (points[j] - c)
            best = min(best, np.min(np.linalg.norm(tri, axis=-1)))
    return best


@pytest.mark.parametrize("surface", ["plane", "rough"])
@pytest.mark.parametrize("seed", range(2))
def test_zone_minimum_equals_its_sampled_patch(surface, seed):
    """Random returns on the 2 sensors of SPEC2, 15 % misses: a plane tilted up to 20 deg from
    sensor 0's optical axis, 0.2-0.6 m away (its nearest point can lie inside a fan triangle,
    between the rays, where only the triangle term finds it: seed 0), or rough (each ray
    0.15-0.9 m). Every zone must read the nearest point of its interpolation patch, found here
    by dense sampling: the samples lie on the patch, so the reading may not exceed their minimum
    (beyond float32 rounding), and sampling every ~3 mm overestimates a minimum by < 2e-5 m."""
    spec = SPEC2
    rng = np.random.default_rng(seed)
    rays = spec.ray_directions()
    dirs = np.stack([rays @ DOWN.T, rays @ (DOWN @ _rot_x(17.0)).T])  # (2, R, 3)
    hit = rng.uniform(size=(2, spec.num_rays)) > 0.15
    if surface == "plane":
        tilt = np.radians(rng.uniform(0.0, 20.0, 2))
        az = rng.uniform(0.0, 2.0 * np.pi, 2)
        m = np.stack(  # plane normal, away from the sensor (axis of sensor 0: -z)
            [np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), -np.cos(tilt)], -1
        )
        h = rng.uniform(0.2, 0.6, (2, 1))
        t = h / np.einsum("frk,fk->fr", dirs, m)
    else:
        t = rng.uniform(0.15, 0.9, hit.shape)
    t = np.where(hit, t, -1.0)
    got = np.asarray(
        ZONE_MIN(spec, jp.asarray(t, jp.float32), jp.asarray(hit), jp.asarray(dirs, jp.float32))[0]
    )
    zr = spec.zone_rays()
    for f in range(2):
        for z in range(spec.num_zones):
            expect = _brute_patch_min(t[f, zr[z], None] * dirs[f, zr[z]], hit[f, zr[z]])
            if not np.isfinite(expect):
                assert np.isinf(got[f, z])
            else:
                assert expect - 1e-4 <= got[f, z] <= expect + 1e-5, (f, z, got[f, z], expect)


def test_step_edge_lights_forward_zones():
    h = np.zeros((61, 61), np.float32)
    xs = -1.2 + np.arange(61) * CELL
    h[:, xs >= 0.2] = 0.2  # a 0.2 m step, edge at x = 0.2 (vertices >= 0.2)
    hf = Heightfield(heights=jp.asarray(h), x0_m=-1.2, y0_m=-1.2, cell_m=CELL)
    # Sensor 0 (untilted) above x = 0.2 + 1 cell: rows 2, 3 (sensor +x = world +x) see the top.
    pos = jp.array([[0.24, 0.0, 0.5], [-0.5, 0.0, 0.5]])
    r = SENSE(SPEC2, hf, pos, jp.asarray(np.stack([DOWN, DOWN])))
    z = np.asarray(r.distance_m)[0].reshape(4, 4)
    assert np.all(z[2:] < 0.33) and np.all(z[2:] > 0.29)  # 0.3 m to the step top
    assert np.all(z[:1] > 0.45)  # far back rows: the floor 0.5 m down
    assert np.all(z[2:].max() < z[:1].min())


def test_clipping_at_max_range():
    rot = jp.asarray(np.stack([DOWN, DOWN]))
    # The untilted sensor 0 at 1.2 m and at 0.97 m (sensor 1, tilted, is not looked at).
    r = [
        SENSE(SPEC2, _flat(), jp.array([[0.0, 0.0, z], [0.0, 0.0, 0.5]]), rot) for z in (1.2, 0.97)
    ]
    dist = np.stack([np.asarray(x.distance_m)[0] for x in r]).reshape(2, 4, 4)
    valid = np.stack([np.asarray(x.valid)[0] for x in r]).reshape(2, 4, 4)
    assert not valid[0].any() and np.all(dist[0] == 1.0)
    corners = np.zeros((4, 4), bool)
    corners[[0, 0, 3, 3], [0, 3, 0, 3]] = True
    # At 0.97 m: corner zones 0.97 * 1.0425 > 1 m -> clipped, invalid; the rest valid.
    assert not valid[1][corners].any() and np.all(dist[1][corners] == 1.0)
    assert valid[1][~corners].all() and np.all(dist[1][~corners] < 1.0)
    assert dist[1][1, 1] == pytest.approx(0.97, abs=1e-6)


def test_sense_vmap_over_envs_and_8x8():
    spec = ToFSpec(grid=8, rate_hz=15.0)
    assert spec.num_rays == 145 and spec.num_zones == 64
    rng = np.random.default_rng(0)
    pos = jp.asarray(
        np.concatenate([rng.uniform(-0.5, 0.5, (3, 4, 2)), rng.uniform(0.05, 0.8, (3, 4, 1))], -1)
    )
    rot = jp.asarray(np.broadcast_to(DOWN, (3, 4, 3, 3)))
    hf = _flat()
    batched = jax.jit(jax.vmap(lambda p, m: sense(spec, hf, p, m)))(pos, rot)
    single = SENSE(spec, hf, pos[1], rot[1])
    np.testing.assert_allclose(
        np.asarray(batched.distance_m[1]), np.asarray(single.distance_m), atol=1e-6
    )
    assert np.asarray(batched.valid).any()
    assert batched.distance_m.shape == (3, 4, 64)


# ----------------------------------------------------------------------------- timing


def _reading(values, valid=True):
    v = jp.asarray(values, jp.float32)
    return ToFReading(distance_m=v, valid=jp.full(v.shape, valid), incidence_rad=jp.zeros_like(v))


def _zero_bounds(lo, hi):
    n = _sensor.get_noise_section()
    for k in ("offset_m", "proportional", "gaussian_m", "missing_rate", "model_scale"):
        n.stage1[k] = 0.0
    n.stage1.min_delay_steps, n.stage1.max_delay_steps = lo, hi
    return bounds_from_config(n, 1)


def _run(spec, bounds, phase, n_steps, key=0):
    """Feed reading value = 0.1 + 0.001 * step for n_steps; return obs distances and ages."""
    model = nm.load_model()
    f, z = spec.num_sensors, spec.num_zones
    state, obs = reset(
        spec,
        bounds,
        model,
        jax.random.PRNGKey(key),
        _reading(np.full((f, z), 0.1)),
        phase_s=jp.asarray(phase, jp.float32),
    )
    dists, delay = [obs.distance_m[:, 0]], int(state.delay_steps)

    def body(st, n):
        st, ob = step(
            spec, model, st, _reading(jp.full((f, z), 0.1) + 0.001 * n), jax.random.PRNGKey(n)
        )
        return st, (ob.distance_m[:, 0], ob.age_s)

    _, (d, a) = jax.lax.scan(body, state, jp.arange(1, n_steps + 1))
    return np.asarray(jp.concatenate([jp.stack(dists), d])), np.asarray(a), delay


@pytest.mark.parametrize("k", [0, 1, 3])
def test_delay_returns_reading_k_steps_earlier(k):
    spec = TimingSpec(
        ToFSpec(
            num_sensors=2,
            rate_hz=50.0,
            tilt_deg=((0.0, 0.0),) * 2,
            offset_m=((0.0, 0.0, 0.0),) * 2,
        ),
        delay_capacity_steps=4,
    )
    d, age, delay = _run(spec, _zero_bounds(k, k), [0.0, 0.0], 12)
    assert delay == k
    for n in range(13):  # frames at every control step (50 Hz, phase 0): value of step n - k
        np.testing.assert_allclose(d[n], 0.1 + 0.001 * max(n - k, 0), atol=1e-6)
    t = 0.02 * np.arange(1, 13)
    np.testing.assert_allclose(age[:, 0], t - 0.02 * np.maximum(np.arange(1, 13) - k, 0), atol=1e-5)


def test_delay_draw_and_capacity():
    spec = TimingSpec(ToFSpec(), delay_capacity_steps=4)
    bounds = _zero_bounds(1, 4)
    keys = jax.random.split(jax.random.PRNGKey(0), 256)
    rd = _reading(np.zeros((4, 16)))
    model = nm.load_model()
    states = jax.jit(jax.vmap(lambda k: reset(spec, bounds, model, k, rd)[0]))(keys)
    ks = np.asarray(states.delay_steps)
    assert set(ks.tolist()) == {1, 2, 3, 4}
    ph = np.asarray(states.phase_s)
    assert ph.min() >= 0.0 and ph.max() < 1 / 60 and ph.std() > 0.003  # random per sensor
    n = _sensor.get_noise_section()
    n.stage2.max_delay_steps = 5
    with pytest.raises(ValueError, match="delay range"):
        bounds_from_config(n, 2, spec)
    with pytest.raises(ValueError, match="stage"):
        bounds_from_config(n, 3)


def test_sample_and_hold_ages_60hz_and_15hz():
    for grid, rate in ((4, 60.0), (8, 15.0)):
        spec = TimingSpec(
            ToFSpec(
                num_sensors=2,
                grid=grid,
                rate_hz=rate,
                tilt_deg=((0.0, 0.0),) * 2,
                offset_m=((0.0, 0.0, 0.0),) * 2,
            ),
            delay_capacity_steps=0,
        )
        phase = np.array([0.3, 0.7]) / rate  # no completion exactly between two steps
        d, age, _ = _run(spec, _zero_bounds(0, 0), phase, 30)
        period = 1 / rate
        for f in range(2):
            for n in range(1, 31):
                t = 0.02 * n
                m = math.floor((t - phase[f]) / period + 1e-5)
                tau = phase[f] + m * period  # completion time of the newest frame
                assert age[n - 1, f] == pytest.approx(t - tau, abs=1e-5)
                assert -1e-6 <= age[n - 1, f] < period + 1e-6
                # Content: reading of the control step nearest to tau (0.1 + 0.001 * step).
                near = round(tau / 0.02) if tau > 0 else 0
                near = max(near, 0)
                assert d[n, f] == pytest.approx(0.1 + 0.001 * near, abs=1e-6)
        if rate == 15.0:  # held over 3-4 control steps
            changes = np.count_nonzero(np.diff(d[:, 0]))
            assert 6 <= changes <= 9


# ----------------------------------------------------------------------------- degradation


def _random_reading(key, f=4, z=16):
    k1, k2, k3 = jax.random.split(key, 3)
    d = jp.round(jax.random.uniform(k1, (f, z), minval=0.02, maxval=1.0) * 1000) / 1000
    valid = jax.random.uniform(k2, (f, z)) > 0.2
    return ToFReading(jp.where(valid, d, 1.0), valid, jax.random.uniform(k3, (f, z), maxval=1.4))


def test_degradation_level_zero_is_identity():
    model = nm.load_model()
    keys = jax.random.split(jax.random.PRNGKey(3), 64)

    def one(k):
        rd = _random_reading(k)
        d, v = degrade(jax.random.fold_in(k, 1), zero_levels(4), rd, model, 1.0, 0.001)
        return rd.distance_m, rd.valid, d, v

    d0, v0, d, v = jax.jit(jax.vmap(one))(keys)
    np.testing.assert_array_equal(np.asarray(d), np.asarray(d0))
    np.testing.assert_array_equal(np.asarray(v), np.asarray(v0))


def test_degradation_levels_and_effects():
    model = nm.load_model()
    noise = _sensor.get_noise_section()
    b2 = bounds_from_config(noise, 2)
    lv = jax.jit(jax.vmap(lambda k: sample_levels(k, b2, 4)))(
        jax.random.split(jax.random.PRNGKey(0), 2000)
    )
    for f in ("proportional", "gaussian_m", "missing_rate", "model_scale"):
        x = np.asarray(getattr(lv, f))
        bound = float(getattr(b2, f))
        assert x.min() >= 0 and x.max() <= bound and abs(x.mean() - bound / 2) < 0.05 * bound
    assert np.abs(np.asarray(lv.offset_m)).max() <= float(b2.offset_m)
    # Gaussian only: residual std = level; missing only: dropped fraction = level, set to 0.
    rd = ToFReading(jp.full((4, 4096), 0.5), jp.ones((4, 4096), bool), jp.zeros((4, 4096)))
    z = zero_levels(4)
    d, v = DEGRADE(
        jax.random.PRNGKey(1), z.replace(gaussian_m=jp.float32(0.01)), rd, model, 1.0, 0.001
    )
    assert np.std(np.asarray(d) - 0.5) == pytest.approx(0.01, rel=0.05) and np.asarray(v).all()
    d, v = DEGRADE(
        jax.random.PRNGKey(2), z.replace(missing_rate=jp.float32(0.2)), rd, model, 1.0, 0.001
    )
    v = np.asarray(v)
    assert (~v).mean() == pytest.approx(0.2, abs=0.01) and np.all(np.asarray(d)[~v] == 0.0)
    off = z.replace(offset_m=jp.array([0.01, -0.02, 0.0, 0.6], jp.float32))
    d, v = DEGRADE(jax.random.PRNGKey(3), off, rd, model, 1.0, 0.001)
    np.testing.assert_allclose(np.asarray(d)[:3, 0], [0.51, 0.48, 0.5], atol=1e-6)
    assert np.all(np.asarray(d)[3] == 1.0) and not np.asarray(v)[3].any()  # pushed beyond 1 m
    # Characterized model: noisier and more often missing at range and oblique incidence.
    near = ToFReading(jp.full((4, 4096), 0.2), jp.ones((4, 4096), bool), jp.zeros((4, 4096)))
    far = ToFReading(jp.full((4, 4096), 0.9), jp.ones((4, 4096), bool), jp.full((4, 4096), 1.0))
    one = z.replace(model_scale=jp.float32(1.0))
    dn, vn = DEGRADE(jax.random.PRNGKey(4), one, near, model, 1.0, 0.001)
    df, vf = DEGRADE(jax.random.PRNGKey(5), one, far, model, 1.0, 0.001)
    assert np.std(np.asarray(df)[np.asarray(vf)]) > 3 * np.std(np.asarray(dn)[np.asarray(vn)])
    assert (~np.asarray(vf)).mean() > 5 * (~np.asarray(vn)).mean()


# ----------------------------------------------------------------------------- noise model


def test_fit_recovers_generating_parameters(tmp_path):
    true = nm.NoiseModel(jp.array([-6.3, 1.8, 0.7, 0.4]), jp.array([-5.5, 3.5, 1.2, 0.8]))
    data = nm.synthesize(
        true, 7, np.linspace(0.1, 1.0, 10), [0.0, 15.0, 30.0, 45.0, 60.0, 70.0], 1500
    )
    path = tmp_path / "bench.csv"
    nm.write_bench_csv(str(path), data, "synthetic")
    fit, _ = nm.fit(nm.read_bench_csv(str(path)))
    np.testing.assert_allclose(
        np.asarray(fit.log_std_coef), np.asarray(true.log_std_coef), atol=0.12
    )
    np.testing.assert_allclose(
        np.asarray(fit.logit_missing_coef), np.asarray(true.logit_missing_coef), atol=0.4
    )
    dd, aa = np.meshgrid(np.linspace(0.1, 1.0, 10), np.radians([0, 30, 60]))
    np.testing.assert_allclose(nm.noise_std(fit, dd, aa), nm.noise_std(true, dd, aa), rtol=0.06)
    np.testing.assert_allclose(
        nm.missing_prob(fit, dd, aa), nm.missing_prob(true, dd, aa), atol=0.02
    )


def test_characterize_cli_roundtrip(tmp_path):
    csv_path, js, png = tmp_path / "b.csv", tmp_path / "m.json", tmp_path / "m.png"
    assert characterize.main(["--synthesize", str(csv_path), "--seed", "1", "--samples", "40"]) == 0
    assert "SYNTHETIC" in csv_path.read_text().splitlines()[0]
    assert characterize.main([str(csv_path), "--json", str(js), "--png", str(png)]) == 0
    model = nm.load_model(str(js))
    default = nm.load_model()
    np.testing.assert_allclose(
        nm.noise_std(model, 0.5, 0.3), nm.noise_std(default, 0.5, 0.3), rtol=0.2
    )
    assert png.stat().st_size > 10_000
    # The shipped example CSV parses and fits.
    nm.fit(nm.read_bench_csv(str(nm.resources.files("foottof").joinpath("data", nm.EXAMPLE_CSV))))


def test_bad_inputs(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("nominal_distance_m,incidence_deg,valid\n0.1,0,1\n")
    with pytest.raises(ValueError, match="missing column.*measured_m"):
        nm.read_bench_csv(str(p))
    p.write_text("nominal_distance_m,incidence_deg,measured_m,valid\n0.1,0,abc,1\n")
    with pytest.raises(ValueError, match="row 1.*measured_m.*not numeric"):
        nm.read_bench_csv(str(p))
    p.write_text("nominal_distance_m,incidence_deg,measured_m,valid\n0.1,95,0.1,1\n")
    with pytest.raises(ValueError, match="incidence_deg"):
        nm.read_bench_csv(str(p))
    with pytest.raises(ValueError, match="does not exist"):
        nm.read_bench_csv(str(tmp_path / "none.csv"))
    with pytest.raises(ValueError, match="grid"):
        ToFSpec(grid=6)
    with pytest.raises(ValueError, match="rate_hz"):
        ToFSpec(grid=8, rate_hz=60.0)
    with pytest.raises(ValueError, match="tilt"):
        ToFSpec(tilt_deg=((0.0, 0.0),) * 3 + ((95.0, 0.0),))
    cfg = _sensor.get_section()
    cfg.tilt_x_deg = (0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="tilt_x_deg"):
        make_spec(cfg)
    cfg = _sensor.get_section()
    cfg.grid = 5
    with pytest.raises(ValueError, match="grid"):
        make_spec(cfg)
    with pytest.raises(ValueError, match="site_pos"):
        sense(ToFSpec(), _flat(), jp.zeros((3, 3)), jp.zeros((3, 3, 3)))


def test_config_sections_build_spec_and_bounds():
    cfg = ml_collections.ConfigDict(
        {"sensor": _sensor.get_section(), "noise": _sensor.get_noise_section()}
    )
    spec = make_spec(cfg.sensor)
    tspec = make_timing_spec(spec, cfg.noise)
    assert (spec.num_sensors, spec.num_zones, spec.num_rays, tspec.delay_capacity_steps) == (
        4,
        16,
        41,
        4,
    )
    b1, b2 = bounds_from_config(cfg.noise, 1, tspec), bounds_from_config(cfg.noise, 2, tspec)
    for f in ("offset_m", "proportional", "gaussian_m", "missing_rate", "model_scale"):
        assert float(getattr(b1, f)) < float(getattr(b2, f))
    st = init(tspec)
    assert st.ring_m.shape == (5, 4, 16) and st.held_time_s.shape == (4,)
