"""foottof.sensors.tof: VL53L5CX zones (zone minimum, clipping, vmap, 8x8) against closed forms and sampled oracles."""

import math

import jax
import jax.numpy as jp
import numpy as np
import pytest

from foottof.sensors import (
    ToFSpec,
    sense,
)
from foottof.sensors.tof import zone_minimum
from foottof.terrain.heightfield import Heightfield

CELL = 0.04
DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # site x fwd, z down
T_HALF = math.tan(math.radians(22.5))
SENSE = jax.jit(sense, static_argnums=0)  # spec static: one compile per spec and shape
ZONE_MIN = jax.jit(zone_minimum, static_argnums=0)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


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
