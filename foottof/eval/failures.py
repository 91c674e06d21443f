"""Why episodes fail: each env's first episode on the evaluation ensemble sorted into a cause.

``python -m foottof.eval.failures RUN_DIR [--config configs/stage1_cpu.py] [--difficulty_fraction
0.111] [--episodes 100] [--seed 5]`` runs the run's policy (mean actions) for one episode per env
on the evaluation map at ``eval.difficulty_fraction`` of the stage-1 range and prints, per terrain
type, how many episodes ended in each cause with the mean step and progress at the end, and
which feet went into the gaps:

- ``success``: ended at the deadline within the success radius;
- ``foot_stuck``: a foot went into a gap (``env.foot_stuck_depth_m``);
- ``fell_base_low``: another failure with the base below the terrain's top (into a gap);
- ``other_fall``: another failure (base or knee contact, flip, divergence);
  for these two, which terminations held in the pose the episode ended in (:data:`REASONS`,
  from a re-run of the ending step's physics: ``AnymalToF.step_physics``, ``fail_reasons``);
- ``timeout``: reached the deadline away from the goal (slow or stuck in place).

For each ``foot_stuck`` episode it also says which way the gap that took the foot runs, from the
terrain around that foot before the last step (:func:`gap_direction`; the course runs along +x):
``crossing`` (stone ahead of and behind the foot, open to the sides: a gap across the path),
``along`` (stone to both sides, open ahead and behind: a gap running along the course, between
columns of stones), ``junction`` (open both ways: where gaps cross, or a wide pit) and
``hole`` (stone all around). And how far from the nearest stone top that foot was
(:func:`stone_distance`): grazing a rim, or put down in the open.

With ``--training_level L`` it runs on the training map of ``--config`` instead, every env at
curriculum level L, one column after another (so every terrain type of the stage is covered),
with that config's randomization and sensor degradation: where the training curriculum stalls,
and why (e.g. ``--config configs/stage2_cpu.py --training_level 0`` for the stage-2 start).

With ``--sightings`` it also asks whether the robot could have known: for each ``foot_stuck``
episode, did any foot sensor's ray look at the spot where the foot went in during the second
before it dropped below the stone tops, and did that ray see a gap there (:func:`sightings`)?
A spot never looked at is a limit of the sensor's coverage; one seen as a gap and stepped into
anyway is a limit of the policy.

For each ``timeout`` it says whether the robot stood still before the deadline
(:func:`stall_step`: the base within STALL_DIST_M over every STALL_WINDOW_STEPS from then on)
and, if so, when and how far along the course it stopped: a policy that stops (its mean action
settles) rather than one that walks too slowly. And for every cause, how long the robot took to
get going: the median step at which its progress first reached START_PROGRESS (a late start
eats the slack a 10 s episode leaves).
"""

from __future__ import annotations

import argparse
from typing import NamedTuple

import numpy as np

from foottof.constants import CONTROL_DT_S

CAUSES = ("success", "foot_stuck", "fell_base_low", "other_fall", "timeout")
# Which terminations held in the pose a failed episode ended in (terminations.FAIL_REASONS, then a
# diverged simulation); more than one may hold at once.
REASONS = ("body_contact", "fell", "foot_deep", "foot_stuck", "flipped", "diverged")
PIT_FLOOR_TOL_M = 0.05  # terrain within this of the pit floor under a foot: it is over a gap [m]
GAP_DIRECTIONS = ("crossing", "along", "junction", "hole")
# Probe distances from the foot centre along +-x and +-y [m]: gaps of the stage-1 stones are
# 0.05-0.37 m wide, so a foot anywhere in one has its stone within 0.3 m on a bounded side.
GAP_PROBE_REACH_M = (0.04, 0.08, 0.12, 0.16, 0.2, 0.25, 0.3)
GAP_STONE_STEP_M = 0.05  # terrain within this of the highest probed point counts as stone [m]


def _stone_samples(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The stone rule of :func:`gap_direction` and :func:`stone_distance`, for heights ``h``
    (N, ...) sampled around N feet: (stone: h within GAP_STONE_STEP_M of the highest sample of
    its foot, same shape as ``h``; has_stone (N,): the samples span more than GAP_STONE_STEP_M,
    else they are all pit or all flat ground and none is a stone)."""
    flat = h.reshape(len(h), -1)
    top = flat.max(axis=1)
    has_stone = top - flat.min(axis=1) > GAP_STONE_STEP_M
    stone = h > (top - GAP_STONE_STEP_M).reshape((-1,) + (1,) * (h.ndim - 1))
    return stone, has_stone


def gap_direction(foot_xy, height_at) -> np.ndarray:
    """(N,) index into GAP_DIRECTIONS of the gap around each foot.

    Args:
      foot_xy: (N, 2) foot centres (world x, y) [m]; the course runs along +x.
      height_at: terrain height function, (..., 2) points -> (...) heights [m] (NumPy or JAX).

    A side is bounded when stone (within GAP_STONE_STEP_M of the highest probed point around the
    foot) lies within GAP_PROBE_REACH_M of the foot centre on it: bounded ahead and behind only
    is ``crossing``, left and right only ``along``, neither ``junction`` (also where all probes
    lie within GAP_STONE_STEP_M of one height: a pit wider than the reach), all four ``hole``.
    """
    foot_xy = np.asarray(foot_xy, np.float64).reshape(-1, 2)
    r = np.asarray(GAP_PROBE_REACH_M)
    dirs = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])  # +x, -x, +y, -y
    pts = foot_xy[:, None, None, :] + dirs[None, :, None, :] * r[None, None, :, None]
    stone, has_stone = _stone_samples(np.asarray(height_at(pts), np.float64))  # (N, 4, R)
    stone = stone.any(axis=2) & has_stone[:, None]  # else all pit (or all flat): open
    ahead_behind = stone[:, 0] & stone[:, 1]
    sides = stone[:, 2] & stone[:, 3]
    return np.select([ahead_behind & sides, ahead_behind, sides], [3, 0, 1], default=2).astype(
        np.int64
    )


RIM_GRID_STEP_M = 0.01  # stone_distance samples the terrain on this grid around the foot [m]
RIM_REACH_M = 0.3  # ... out to this distance from the foot centre (inf: no stone that near) [m]
RIM_BINS_M = (0.04, 0.08, 0.15)  # format_rims' bins: < 4 cm is within a foot radius and a cm


def stone_distance(foot_xy, height_at) -> np.ndarray:
    """(N,) horizontal distance from each foot centre to the nearest stone top [m]: the terrain
    sampled on a RIM_GRID_STEP_M grid within RIM_REACH_M of the foot, stone = within
    GAP_STONE_STEP_M of the highest sample (as :func:`gap_direction`); inf where every sample
    lies within GAP_STONE_STEP_M of one height (a pit wider than the reach, or flat ground).

    Of a foot that went into a gap, this says how far off the stone it came down: within a foot
    radius (3.15 cm) it grazed the rim, tens of cm it was put down in the open.
    """
    foot_xy = np.asarray(foot_xy, np.float64).reshape(-1, 2)
    n = int(round(RIM_REACH_M / RIM_GRID_STEP_M))
    u = np.arange(-n, n + 1) * RIM_GRID_STEP_M
    off = np.stack(np.meshgrid(u, u, indexing="ij"), axis=-1).reshape(-1, 2)
    r = np.linalg.norm(off, axis=-1)
    off, r = off[r <= RIM_REACH_M + 1e-9], r[r <= RIM_REACH_M + 1e-9]
    stone, has_stone = _stone_samples(
        np.asarray(height_at(foot_xy[:, None, :] + off[None]), np.float64)  # (N, P)
    )
    dist = np.where(stone, r[None], np.inf).min(axis=1)
    return np.where(has_stone, dist, np.inf)


SIGHT_RADIUS_M = 0.08  # a ray looked at a spot when it crossed the stone-top plane this near [m]
SIGHT_BEYOND_M = 0.05  # ... and saw a gap there when it hit this far beyond the plane, or nothing
SIGHT_WINDOW_STEPS = 50  # how far back before the foot dropped to look for sightings (1 s)
STALL_WINDOW_STEPS = 50  # stall_step: a window of 1 s ...
STALL_DIST_M = 0.1  # ... in which the base moved less than this counts as standing still [m]
START_PROGRESS = 0.1  # the robot has got going once its progress reached this [-]
SWING_LOOKBACK_STEPS = 10  # a foot stepped in when it was in the air in the 0.2 s before the drop
SWING_LIFT_M = 0.02  # ... with its bottom this far above the stone tops (else it slid off) [m]


def sightings(spot_xy, top_z, origins, dirs, t_hit, max_range_m: float):
    """Which rays looked at a spot on the stone-top plane and which of them saw a gap there.

    A ray (origin o, unit direction d pointing down) crosses the plane z = ``top_z`` at
    s = (top_z - o_z) / d_z; it looked at the spot when that crossing lies within SIGHT_RADIUS_M
    of ``spot_xy``, within the sensor's range, and the ray was not stopped before it (hit at
    t >= s - 2 cm, or no hit). It saw a gap there when it hit more than SIGHT_BEYOND_M beyond the
    plane or nothing within range (the terrain under the spot lies below the stone tops).

    Args:
      spot_xy: (2,) the spot [m]; top_z: the stone-top height around it [m].
      origins: (..., F, 3) sensor origins [m]; dirs: (..., F, R, 3) unit ray directions.
      t_hit: (..., F, R) hit distances [m], negative where nothing was hit within range.
      max_range_m: the sensor's range [m].

    Returns:
      (looked, gap): (..., F) bool per sensor: some ray looked at the spot / saw a gap there.
    """
    o = np.asarray(origins, np.float64)[..., None, :]  # (..., F, 1, 3)
    d = np.asarray(dirs, np.float64)
    t = np.asarray(t_hit, np.float64)
    down = d[..., 2] < -1e-6
    s = np.where(down, (top_z - o[..., 2]) / np.where(down, d[..., 2], -1.0), -1.0)  # -1: never
    cross = o[..., :2] + s[..., None] * d[..., :2]
    near = np.linalg.norm(cross - np.asarray(spot_xy, np.float64), axis=-1) < SIGHT_RADIUS_M
    in_range = (s > 0.0) & (s < max_range_m - SIGHT_BEYOND_M)
    no_hit = t < 0.0
    looked = near & in_range & (no_hit | (t >= s - 0.02))
    gap = looked & (no_hit | (t > s + SIGHT_BEYOND_M))
    return looked.any(axis=-1), gap.any(axis=-1)


def scan_sightings(spot_xy, top_z, points_xy, heights, seen=None):
    """Which of a teacher's terrain inputs (env.actor_terrain: foot patches and base scan) looked
    at a spot and saw a gap there: a sample point looked when it lay within SIGHT_RADIUS_M of
    ``spot_xy``, and saw a gap when the true height there lay more than SIGHT_BEYOND_M below the
    stone tops ``top_z`` (the rays' rule of :func:`sightings`, for vertical probes). For a seen
    teacher (env.actor_terrain_seen) only the points whose ``seen`` flag is set count: the others
    read the flat fill, not the terrain.

    Args:
      spot_xy: (2,) the spot [m]; top_z: the stone-top height around it [m].
      points_xy: (..., P, 2) sample points [m]; heights: (..., P) terrain heights there [m].
      seen: None (every point is read) or (..., P) bool, the teacher's seen flags.

    Returns:
      (looked, gap): (..., 1) bool, shaped as one sensor for :func:`sighting_summary`.
    """
    p = np.asarray(points_xy, np.float64)
    near = np.linalg.norm(p - np.asarray(spot_xy, np.float64), axis=-1) < SIGHT_RADIUS_M
    if seen is not None:
        near = near & np.asarray(seen, bool)
    low = np.asarray(heights, np.float64) < top_z - SIGHT_BEYOND_M
    return near.any(axis=-1)[..., None], (near & low).any(axis=-1)[..., None]


def sighting_summary(foot_z, top_z, end_step, looked, gap) -> tuple[int, int, int, bool]:
    """For one foot_stuck episode: (step the foot dropped: the last one before the end with its
    centre at or above ``top_z``, steps before it that some sensor first saw a gap at the spot
    within SIGHT_WINDOW_STEPS (>= 1; -1: not before the drop), the same for the first look at
    the spot, whether the foot stepped in from a swing: its bottom rose more than SWING_LIFT_M
    above the stone tops in the SWING_LOOKBACK_STEPS before the drop; else it slid off an edge
    it stood on).

    foot_z: (T,) the stuck foot's centre height [m]; looked, gap: (T, F) from :func:`sightings`."""
    from foottof.constants import FOOT_RADIUS_M

    foot_z = np.asarray(foot_z)
    above = np.nonzero(foot_z[: end_step + 1] >= top_z)[0]
    drop = int(above[-1]) if above.size else 0
    lo = max(0, drop - SIGHT_WINDOW_STEPS)

    def lead(hits):
        steps = np.nonzero(np.asarray(hits)[lo:drop].any(axis=-1))[0]  # before the drop step
        return int(drop - (lo + steps[0])) if steps.size else -1

    recent = foot_z[max(0, drop - SWING_LOOKBACK_STEPS) : drop + 1]
    swung = bool(recent.max() - FOOT_RADIUS_M - top_z > SWING_LIFT_M)
    return drop, lead(gap), lead(looked), swung


def stall_step(
    base_xy: np.ndarray,
    end: int,
    window: int = STALL_WINDOW_STEPS,
    dist: float = STALL_DIST_M,
) -> int:
    """The step from which the base stood still until ``end``: the first s such that no window
    of ``window`` steps starting in [s, end - window] moved the base ``dist`` or more
    (|xy[t + window] - xy[t]|); -1 where the last such move leaves less than one window before
    ``end`` (it did not stand still for a whole window).

    Args:
      base_xy: (T, 2) base position per step [m]; end: the episode's last step (< T)."""
    xy = np.asarray(base_xy, np.float64)[: end + 1]
    if end < window:
        return -1
    moved = np.linalg.norm(xy[window:] - xy[:-window], axis=-1) >= dist  # (end + 1 - window,)
    start = int(np.nonzero(moved)[0][-1]) + 1 if moved.any() else 0
    return start if start <= end - window else -1


def start_step(progress: np.ndarray, end: np.ndarray, reach: float = START_PROGRESS) -> np.ndarray:
    """(E,) the first step of each env's episode at which its progress reached ``reach``; -1
    where it did not by its last step ``end`` (E,). progress: (T, E)."""
    p = np.asarray(progress)
    within = np.arange(p.shape[0])[:, None] <= np.asarray(end)[None]
    got = (p >= reach) & within
    return np.where(got.any(axis=0), np.argmax(got, axis=0), -1)


def format_starts(cause, start, step_s: float) -> str:
    """One line: per cause, the median time the robot took to reach START_PROGRESS, over the
    episodes that reached it, and how many did not."""
    parts = []
    for i, name in enumerate(CAUSES):
        sel = cause == i
        if not sel.any():
            continue
        got = sel & (start >= 0)
        med = f"{np.median(start[got]) * step_s:.1f} s" if got.any() else "-"
        parts.append(f"{name} {med} ({int((sel & (start < 0)).sum())} never)")
    return f"time to progress {START_PROGRESS:g}, median: " + ", ".join(parts)


def classify(done, success, failed, stuck, base_z) -> np.ndarray:
    """(E,) cause index into CAUSES of each env's first episode, from (T, E) step records; an
    env whose episode did not end within T steps counts as a timeout."""
    ended = done > 0.5
    t = np.where(ended.any(axis=0), np.argmax(ended, axis=0), done.shape[0] - 1)
    e = np.arange(done.shape[1])
    at = lambda a: a[t, e]  # noqa: E731
    return np.select(
        [
            at(success) > 0.5,
            at(stuck) > 0.5,
            (at(failed) > 0.5) & (at(base_z) < 0.2),
            at(failed) > 0.5,
        ],
        [0, 1, 2, 3],
        default=4,
    )


def training_env_and_policy(cfg, checkpoint: str | None, key, level: int):
    """The training env of ``cfg`` (its map, randomization and degradation) and the policy.

    Raises:
      ValueError: ``level`` outside the map's levels [0, terrain.num_levels - 1].
    """
    import jax.numpy as jp

    from foottof.envs import make_env
    from foottof.eval.harness import load_policy

    top = int(cfg.terrain.num_levels) - 1
    if not 0 <= level <= top:
        raise ValueError(f"training level {level} outside the map's levels [0, {top}]")
    env = make_env(cfg, source="tof")
    obs = {k: jp.zeros((1, n), jp.float32) for k, n in env.observation_size.items()}
    return (env, *load_policy(cfg, env, obs, checkpoint, key))


class Failures(NamedTuple):
    """What :func:`run` returns, one entry per env (a tuple: it unpacks in this order)."""

    cause: np.ndarray  # (N,) index into CAUSES
    types: list  # (N,) terrain type name
    end_step: np.ndarray  # (N,) the step the episode ended on
    progress: np.ndarray  # (N,) progress towards the goal at the end [-]
    foot: np.ndarray  # (N,) index into constants.FEET of the foot in the gap; -1: not foot_stuck
    gap: np.ndarray  # (N,) index into GAP_DIRECTIONS of that gap; -1: not foot_stuck
    rim: np.ndarray  # (N,) that foot's distance to the nearest stone top [m]; nan: not foot_stuck
    sightings: list | None  # one row per foot_stuck episode (sighting_summary), or None
    stall: np.ndarray  # (N,) stall_step of a timeout; -1: not a timeout, or it did not stand
    stall_progress: np.ndarray  # (N,) progress at that step [-]; nan where stall is -1
    start: np.ndarray  # (N,) first step with progress >= START_PROGRESS; -1: never in the episode
    reasons: np.ndarray  # (N, len(REASONS)) bool: the terminations that held at a failure's end
    over_gap: np.ndarray  # (N,) how many feet were over a gap (the pit floor under the foot
    # centre) before the last step


class Trace(NamedTuple):
    """What the failures rollout records at each step t (T = episode steps + 1) of env e (E),
    before the step (the pose an ending step starts from) or from its outcome."""

    done: np.ndarray  # (T, E) 1.0 where step t ended the episode
    success: np.ndarray  # (T, E) episode/success of step t
    failed: np.ndarray  # (T, E) episode/failed of step t
    foot_stuck: np.ndarray  # (T, E) episode/foot_stuck of step t
    base_z: np.ndarray  # (T, E) base height before step t [m]
    progress: np.ndarray  # (T, E) episode/progress of step t [-]
    col: np.ndarray  # (T, E) terrain column before step t
    base_xy: np.ndarray  # (T, E, 2) base x, y before step t [m]
    why: np.ndarray  # (T, E, len(REASONS)) bool: terminations in step t's pose (before a reset)
    foot_pos: np.ndarray  # (T, E, 4, 3) foot centres before step t [m]
    depth: np.ndarray  # (T, E, 4) foot depth below the terrain around (foot_gap_depth) [m]
    # with sight: ray origins (T, E, F, 3), directions (T, E, F, R, 3), hits (T, E, F, R), the
    # teacher's sample points (T, E, 153, 2) and heights (T, E, 153), (with a seen teacher)
    # their seen flags (T, E, 153); else ()
    rays: tuple


def run(
    cfg,
    checkpoint: str | None,
    episodes: int,
    seed: int,
    sight: bool = False,
    training_level: int | None = None,
):
    """With ``training_level`` None, on the evaluation ensemble (``cfg.eval``); else on the
    training map of ``cfg`` (its stage, randomization and sensor degradation as in training),
    env i on column i mod the map's columns at that curriculum level. ``checkpoint`` None: a
    fresh init. Returns :class:`Failures`: the cause per env, terrain type name per env, end
    step, progress at the end, the foot that went into the gap (index into constants.FEET, -1
    where the cause is not foot_stuck), the direction of that gap (index into GAP_DIRECTIONS, -1
    where not foot_stuck), that foot's distance to the nearest stone top before the last step
    (:func:`stone_distance` [m], nan where not foot_stuck) and, with ``sight``, one (env, drop
    step, gap lead, look lead, own-sensor gap lead, stepped in from a swing, teacher-input look
    lead, teacher-input gap lead) row per foot_stuck episode (:func:`sighting_summary`; the
    own-sensor lead from the stuck foot's sensor alone; the teacher-input leads from the
    env.actor_terrain sample points, :func:`scan_sightings`, whether or not the policy reads
    them; for a seen teacher, env.actor_terrain_seen, only the points it read as seen), else
    None."""
    import jax.numpy as jp

    from foottof.terrain import TERRAIN_TYPES

    env, tr = rollout_trace(cfg, checkpoint, episodes, seed, sight, training_level)
    cause = classify(tr.done, tr.success, tr.failed, tr.foot_stuck, tr.base_z)
    ended = tr.done > 0.5
    t = np.where(ended.any(axis=0), np.argmax(ended, axis=0), tr.done.shape[0] - 1)
    e = np.arange(episodes)
    reasons = tr.why[t, e] & (tr.failed[t, e] > 0.5)[:, None]  # (E, R), only where it failed
    types = np.asarray(env.tmap.col_type)[tr.col[0]]
    is_stuck = cause == CAUSES.index("foot_stuck")
    foot = np.where(is_stuck, np.argmax(tr.depth[t, e], axis=-1), -1)
    xy = tr.foot_pos[t, e, np.maximum(foot, 0), :2]  # (E, 2) the foot that went in
    height_at = lambda p: np.asarray(env.hfield.height_at(jp.asarray(p, jp.float32)))  # noqa: E731
    gap = np.where(is_stuck, gap_direction(xy, height_at), -1)
    rim = np.where(is_stuck, stone_distance(xy, height_at), np.nan)
    rows = _sighting_rows(env, tr, t, foot, xy, is_stuck) if sight else None
    timeout = cause == CAUSES.index("timeout")
    stall = np.array([stall_step(tr.base_xy[:, i], t[i]) if timeout[i] else -1 for i in e])
    stall_prog = np.where(stall >= 0, tr.progress[np.maximum(stall, 0), e], np.nan)
    types = [TERRAIN_TYPES[i] for i in types]
    start = start_step(tr.progress, t)
    return Failures(
        cause, types, t, tr.progress[t, e], foot, gap, rim, rows, stall, stall_prog, start,
        reasons, feet_over_gap(tr.foot_pos[t, e], height_at, env.hfield.z_floor_m),
    )  # fmt: skip


def rollout_trace(
    cfg,
    checkpoint: str | None,
    episodes: int,
    seed: int,
    sight: bool = False,
    training_level: int | None = None,
):
    """(env, :class:`Trace`) of one deterministic episode per env, the arguments as :func:`run`'s."""
    import jax
    import jax.numpy as jp

    from foottof.envs import observations as obs_lib
    from foottof.envs.anymal_tof import SEEN_KEY
    from foottof.envs.stuck_probe import foot_gap_depth
    from foottof.envs.terminations import FAIL_REASONS
    from foottof.robot.kinematics import world_foot_kinematics
    from foottof.sensors import tof

    key = jax.random.PRNGKey(seed)
    env, nets, params, norm, state = _env_policy_and_state(
        cfg, checkpoint, episodes, key, training_level
    )
    act = nets.policy_fn(params, norm, deterministic=True)
    step = jax.vmap(env.step)

    sites = np.asarray(env.sensing.feet, np.int32)  # the foot of each sensor
    seen_teacher = bool(env.spec.actor_terrain_seen)  # its inputs read terrain only where seen

    def feet(qpos):  # (4, 3) foot centres and (4,) depth below the terrain around, beside a gap
        fk = world_foot_kinematics(qpos[:19], env.shank_scale)
        out = (fk.foot_pos, foot_gap_depth(fk.foot_pos, env.hfield.height_at))
        if sight:  # every sensor ray: origins (F, 3), directions (F, R, 3), hits (F, R)
            pos, dirs, t_hit, _ = tof.cast_rays(
                env.sensing.spec, env.hfield, fk.tof_pos[sites], fk.tof_rot[sites]
            )
            out += (pos, dirs, t_hit)
            # the teacher's terrain inputs (env.actor_terrain): foot patches, then the base scan
            pts = jp.concatenate(
                [
                    obs_lib.foot_patch_points(fk.foot_pos).reshape(-1, 2),
                    obs_lib.world_scan_points(qpos[0:3], qpos[3:7])[: obs_lib.ACTOR_SCAN_POINTS],
                ]
            )
            out += (pts, env.hfield.height_at(pts))
        return out

    @jax.jit
    def rollout(state):
        def body(c, k):
            s, lstm, first = c
            lstm, a = act(lstm, s.obs, first, k)
            s2 = step(s, a)
            m = s2.metrics
            rec = (s2.done, m["episode/success"], m["episode/failed"], m["episode/foot_stuck"])
            rec += (s.pipeline_state.qpos[:, 2], m["episode/progress"], s.info["task"].col)
            rec += (s.pipeline_state.qpos[:, :2],)
            d_end, diverged = jax.vmap(env.step_physics)(s, a)  # the step's pose, before a reset
            why = jax.vmap(env.fail_reasons)(d_end)
            rec += (jp.stack([why[k] for k in FAIL_REASONS] + [diverged], axis=-1),)
            rec += jax.vmap(feet)(s.pipeline_state.qpos)  # before the step that ends it
            if sight and seen_teacher:  # static: the flags the seen teacher read at this step
                origin, grid = s.info[SEEN_KEY]
                pts = rec[-2]  # feet()'s teacher sample points (E, 153, 2), before their heights
                rec += (jax.vmap(env.seen_grid.lookup)(origin, grid, pts),)
            return (s2, lstm, s2.done > 0.5), rec

        init = (state, nets.init_carry(episodes), jp.ones((episodes,), bool))
        return jax.lax.scan(body, init, jax.random.split(key, env.episode_steps + 1))[1]

    recorded = [np.asarray(x) for x in jax.device_get(rollout(state))]
    n = len(Trace._fields) - 1
    return env, Trace(*recorded[:n], rays=tuple(recorded[n:]))


def _env_policy_and_state(cfg, checkpoint, episodes: int, key, training_level):
    """(env, networks, params, normalizer, first states of ``episodes`` envs): the evaluation
    ensemble's (training_level None) or the training map's at that level, env i on column i."""
    import jax
    import jax.numpy as jp

    from foottof.eval.harness import make_eval_env_and_policy

    if training_level is None:
        env, nets, params, norm = make_eval_env_and_policy(cfg, "tof", checkpoint, key, key)
        state = jax.jit(jax.vmap(env.reset))(jax.random.split(key, episodes))
    else:
        env, nets, params, norm = training_env_and_policy(cfg, checkpoint, key, training_level)
        cols = jp.arange(episodes, dtype=jp.int32) % env.tmap.num_cols
        levels = jp.full((episodes,), training_level, jp.int32)
        reset = jax.jit(jax.vmap(env._reset_episode))  # explicit tiles (level, column)
        state = reset(jax.random.split(key, episodes), levels, cols)
    return env, nets, params, norm, state


def _sighting_rows(env, tr: Trace, t, foot, xy, is_stuck) -> list:
    """One :func:`run` sightings row per foot_stuck episode, from a trace recorded with sight.

    Args:
      t: (E,) end steps; foot: (E,) the foot in the gap; xy: (E, 2) where it went in;
      is_stuck: (E,) the foot_stuck episodes.
    """
    sites = np.asarray(env.sensing.feet, np.int32)  # the foot of each sensor
    origins, dirs, t_hit, scan_xy, scan_h, *flags = tr.rays
    scan_seen = flags[0] if flags else None
    foot_pos, depth = tr.foot_pos, tr.depth
    rows = []
    for i in np.nonzero(is_stuck)[0]:
        f = foot[i]
        top = depth[t[i], i, f] + foot_pos[t[i], i, f, 2]  # the stone tops around the foot
        looked, seen = sightings(
            xy[i], top, origins[:, i], dirs[:, i], t_hit[:, i], env.sensing.spec.max_range_m
        )
        drop, gap_lead, look_lead, swung = sighting_summary(
            foot_pos[:, i, f, 2], top, t[i], looked, seen
        )
        own = np.nonzero(sites == f)[0]  # the stuck foot's own sensor (if it has one)
        own_lead = sighting_summary(foot_pos[:, i, f, 2], top, t[i], looked, seen[:, own])[1]
        s_looked, s_gap = scan_sightings(
            xy[i],
            top,
            scan_xy[:, i],
            scan_h[:, i],
            None if scan_seen is None else scan_seen[:, i],
        )
        scan_gap, scan_look = sighting_summary(foot_pos[:, i, f, 2], top, t[i], s_looked, s_gap)[
            1:3
        ]
        rows.append((int(i), drop, gap_lead, look_lead, own_lead, swung, scan_look, scan_gap))
    return rows


def format_sightings(rows, gap) -> str:
    """One line per gap direction of the foot_stuck episodes: how many had the spot where the
    foot went in looked at, and seen as a gap, by any sensor and by the foot's own, in the
    second before it dropped, with the median lead of the first gap sighting [steps of 20 ms],
    and how many feet stepped in from a swing (and of them, into a gap seen before) or slid off
    an edge they stood on; then how many spots a teacher's terrain inputs (env.actor_terrain: foot
    patches and the 0.6 m base scan, 10 cm grids) had sampled, and seen as a gap, in that second."""
    lines = []
    for d, name in [(None, "all")] + list(enumerate(GAP_DIRECTIONS)):
        sel = [r for r in rows if d is None or gap[r[0]] == d]
        if not sel:
            continue
        leads = np.array([r[2] for r in sel])
        seen = leads >= 0
        med = f", median lead {np.median(leads[seen]):.0f} steps" if seen.any() else ""
        lines.append(
            f"sightings, {name} ({len(sel)} foot_stuck): spot looked at "
            f"{sum(r[3] >= 0 for r in sel)}, seen as a gap {int(seen.sum())}{med}, "
            f"by the foot's own sensor {sum(r[4] >= 0 for r in sel)}; stepped in from a swing "
            f"{sum(r[5] for r in sel)} (seen before {sum(r[5] and r[2] >= 0 for r in sel)}), "
            f"slid off an edge {sum(not r[5] for r in sel)}; a teacher's terrain inputs "
            f"looked at it {sum(r[6] >= 0 for r in sel)}, saw a gap {sum(r[7] >= 0 for r in sel)}"
            + (
                f" (median lead {np.median([r[7] for r in sel if r[7] >= 0]):.0f} steps)"
                if any(r[7] >= 0 for r in sel)
                else ""
            )
        )
    return "\n".join(lines)


def format_feet(foot: np.ndarray) -> str:
    """One line: how many foot_stuck episodes each foot ended (constants.FEET order)."""
    from foottof.constants import FEET

    counts = ", ".join(f"{name} {int(np.sum(foot == i))}" for i, name in enumerate(FEET))
    return f"foot_stuck by foot (the deepest foot before the last step): {counts}"


def format_gaps(gap: np.ndarray, types) -> str:
    """One line per terrain type with foot_stuck episodes: how many went into a gap of each
    GAP_DIRECTIONS direction (gap: -1 where the episode was not foot_stuck)."""
    lines = []
    for name in sorted(set(types)) + ["all"]:
        sel = np.array([name in ("all", t) for t in types]) & (gap >= 0)
        if not sel.any():
            continue
        counts = ", ".join(
            f"{d} {int(np.sum(sel & (gap == i)))}" for i, d in enumerate(GAP_DIRECTIONS)
        )
        lines.append(f"foot_stuck gaps, {name}: {counts}")
    return "\n".join(lines)


def format_rims(rim: np.ndarray, gap: np.ndarray) -> str:
    """One line per gap direction with foot_stuck episodes: how far from the nearest stone top
    the foot was (rim: :func:`stone_distance` per episode, nan where not foot_stuck), median
    and counts in the RIM_BINS_M bins."""
    edges = (0.0,) + RIM_BINS_M + (np.inf,)
    names = [f"< {100 * RIM_BINS_M[0]:g} cm"]
    names += [
        f"{100 * a:g}-{100 * b:g} cm" for a, b in zip(RIM_BINS_M[:-1], RIM_BINS_M[1:], strict=True)
    ]
    names += [f">= {100 * RIM_BINS_M[-1]:g} cm"]
    lines = []
    for d, name in [(None, "all")] + list(enumerate(GAP_DIRECTIONS)):
        sel = ~np.isnan(rim) & ((gap == d) if d is not None else True)
        if not sel.any():
            continue
        r = rim[sel]
        counts = ", ".join(
            f"{label} {int(np.sum((r >= a) & (r < b)))}"
            for label, a, b in zip(names, edges[:-1], edges[1:], strict=True)
        )
        lines.append(
            f"foot_stuck, {name} ({int(sel.sum())}): the foot centre was a median "
            f"{100 * np.median(r):.1f} cm from the nearest stone top; {counts}"
        )
    return "\n".join(lines)


def feet_over_gap(foot_pos, height_at, z_floor_m: float) -> np.ndarray:
    """(E,) how many of each env's feet ((E, 4, 3) centres) are over a gap: the terrain under
    the centre is within PIT_FLOOR_TOL_M of the pit floor."""
    pos = np.asarray(foot_pos)
    under = height_at(pos[..., :2].reshape(-1, 2)).reshape(pos.shape[:-1])
    return (under <= z_floor_m + PIT_FLOOR_TOL_M).sum(axis=-1)


def format_reasons(cause, types, reasons, over_gap=None) -> str:
    """One line per fall cause other than foot_stuck (fell_base_low, other_fall) and terrain
    type with such episodes (and one for all): how many ended with each REASONS termination
    holding (an episode may count under more than one), and with ``over_gap``
    (:func:`feet_over_gap`) how many had a foot over a gap before the last step (a misstep)
    rather than all four on terrain (a loss of balance)."""
    cause, reasons = np.asarray(cause), np.asarray(reasons, bool)
    types = np.asarray(types)
    low = None if over_gap is None else np.asarray(over_gap) > 0
    lines = []
    for c in ("fell_base_low", "other_fall"):
        sel_c = cause == CAUSES.index(c)
        for name in [*sorted(set(types[sel_c].tolist())), "all"]:
            sel = sel_c & ((types == name) | (name == "all"))
            if not sel.any():
                continue
            counts = ", ".join(f"{r} {int(reasons[sel, j].sum())}" for j, r in enumerate(REASONS))
            if low is not None:
                counts += f"; a foot over a gap {int(low[sel].sum())}"
            lines.append(f"{c} reasons, {name} ({int(sel.sum())}): {counts}")
    return "\n".join(lines) if lines else "no falls besides foot_stuck"


def format_stalls(cause, stall, stall_progress, end_step, types, step_s: float) -> str:
    """One line per terrain type with timeouts (and one for all): how many stood still before
    the deadline, from a median step (seconds into the episode and before its end) at a median
    progress, and how many walked on to the deadline."""
    timeout = cause == CAUSES.index("timeout")
    lines = []
    for name in sorted({t for t, x in zip(types, timeout, strict=True) if x}) + ["all"]:
        sel = timeout & np.array([name in ("all", t) for t in types])
        if not sel.any():
            continue
        still = sel & (stall >= 0)
        line = f"timeout, {name} ({int(sel.sum())}): stood still {int(still.sum())}"
        if still.any():
            at, left = stall[still], end_step[still] - stall[still]
            line += (
                f" (from a median step {np.median(at):.0f}, {np.median(at) * step_s:.1f} s in and "
                f"{np.median(left) * step_s:.1f} s before the end, progress "
                f"{np.median(stall_progress[still]):.2f})"
            )
        lines.append(line + f", walked on to the deadline {int((sel & (stall < 0)).sum())}")
    return "\n".join(lines)


def format_table(cause, types, end_step, progress) -> str:
    lines = [
        "| terrain | episodes | " + " | ".join(CAUSES) + " |",
        "|---|---|" + "---|" * len(CAUSES),
    ]
    for name in sorted(set(types)) + ["all"]:
        sel = np.array([name in ("all", t) for t in types])
        cells = []
        for i in range(len(CAUSES)):
            m = sel & (cause == i)
            cells.append(
                f"{m.sum()} (step {end_step[m].mean():.0f}, prog {progress[m].mean():.2f})"
                if m.any()
                else "0"
            )
        lines.append(f"| {name} | {sel.sum()} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> None:
    from foottof.config_file import load_config  # the repo's configs/*.py (run from the repo root)

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run_dir", help="run directory, its checkpoints/ or one checkpoint")
    ap.add_argument("--config", default="configs/stage1_cpu.py")
    ap.add_argument("--difficulty_fraction", type=float, default=0.9)
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument(
        "--training_level",
        type=int,
        default=None,
        help="run on the training map of --config at this curriculum level instead (its stage, "
        "randomization and sensor degradation; env i on column i mod the map's columns)",
    )
    ap.add_argument(
        "--sightings",
        action="store_true",
        help="also say whether a sensor saw each gap a foot went into before it dropped",
    )
    args = ap.parse_args(argv)
    if not 0.0 <= args.difficulty_fraction <= 1.0:
        raise SystemExit(f"error: --difficulty_fraction={args.difficulty_fraction} outside [0, 1]")
    if args.episodes < 1:
        raise SystemExit(f"error: --episodes={args.episodes} must be >= 1")
    from foottof.ppo.storage.checkpoint import CheckpointUnreadable
    from foottof.ppo.storage.run_dir import with_run_network

    cfg = with_run_network(load_config(args.config), args.run_dir)
    cfg.eval.difficulty_fraction = args.difficulty_fraction
    try:
        f = run(cfg, args.run_dir, args.episodes, args.seed, args.sightings, args.training_level)
        print(format_table(f.cause, f.types, f.end_step, f.progress))
        print(format_feet(f.foot))
        print(format_gaps(f.gap, f.types))
        print(format_rims(f.rim, f.gap))
        print(format_reasons(f.cause, f.types, f.reasons, f.over_gap))
        print(format_stalls(f.cause, f.stall, f.stall_progress, f.end_step, f.types, CONTROL_DT_S))
        print(format_starts(f.cause, f.start, CONTROL_DT_S))
        if f.sightings is not None:
            print(format_sightings(f.sightings, f.gap))
    except (FileNotFoundError, ValueError, CheckpointUnreadable) as e:
        raise SystemExit(f"error: {e}") from None


if __name__ == "__main__":
    main()
