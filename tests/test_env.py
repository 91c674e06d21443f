"""Tests of the goal-reaching ToF environment: shapes, NaN-free rollouts, terminations, rewards."""

import jax
import jax.numpy as jp
import ml_collections
import numpy as np
import pytest

from configs import smoke, teacher_cpu
from foottof import constants, renames
from foottof.envs import make_env
from foottof.envs import rewards as rw
from foottof.envs.terminations import FAIL_REASONS
from foottof.terrain import TERRAIN_TYPES

NUM_ENVS = len(TERRAIN_TYPES)  # one env per column: every terrain type is covered


def _arrive(cfg):
    """The goal-reaching task of configs/teacher_cpu.py (its reward and gamma) on ``cfg``, in
    place, without the teacher's foot-edge price."""
    teacher = teacher_cpu.get_config()
    cfg.reward = teacher.reward
    cfg.reward.scales.foot_edge = 0.0
    cfg.ppo.gamma = teacher.ppo.gamma


def _cfg():
    cfg = smoke.get_config()
    cfg.stage = 2  # all nine types
    cfg.terrain.num_cols = len(TERRAIN_TYPES)
    cfg.terrain.num_levels = 2
    cfg.terrain.init_level_max = 1
    return cfg


@pytest.fixture(scope="module")
def env():
    return make_env(_cfg())


@pytest.fixture(scope="module")
def fns(env):
    return jax.jit(jax.vmap(env.reset)), jax.jit(jax.vmap(env.step))


@pytest.fixture(scope="module")
def reset_perturbed(env):
    """(keys (NUM_ENVS, 2), joint offset, odometry level) -> State; one compile for the module."""
    return jax.jit(jax.vmap(env.reset_perturbed, in_axes=(0, None, None)))


@pytest.fixture(scope="module")
def on_columns(env):
    """A batch with env i on column i (level 0): explicit tiles; one compile for the module."""
    keys = jax.random.split(jax.random.PRNGKey(7), NUM_ENVS)
    cols = jp.arange(NUM_ENVS) % env.tmap.num_cols
    return jax.jit(jax.vmap(env._reset_episode))(keys, jp.zeros(NUM_ENVS, jp.int32), cols)


def _with(state, env_index, **task_updates):
    """Copy of a batched state with TaskState fields of one env replaced."""
    task = state.info["task"]
    new = {}
    for k, v in task_updates.items():
        new[k] = getattr(task, k).at[env_index].set(v)
    info = dict(state.info)
    info["task"] = task.replace(**new)
    return state.replace(info=info)


def test_shapes_and_no_nan_on_every_terrain(env, fns, on_columns):
    _, step = fns
    state = on_columns
    sizes = env.observation_size
    assert state.obs["state"].shape == (NUM_ENVS, sizes["state"])
    assert state.obs["privileged_state"].shape == (NUM_ENVS, sizes["privileged_state"])
    cols_seen = set(np.asarray(state.info["task"].col).tolist())
    types_seen = {TERRAIN_TYPES[int(env.tmap.col_type[c])] for c in cols_seen}
    assert types_seen == set(TERRAIN_TYPES)
    key = jax.random.PRNGKey(1)
    dones = 0
    for _ in range(250):  # 5 s: random actions fall well before
        key, k = jax.random.split(key)
        action = jax.random.uniform(k, (NUM_ENVS, 12), minval=-1.0, maxval=1.0)
        state = step(state, action)
        for leaf in (state.obs["state"], state.obs["privileged_state"], state.reward):
            assert np.all(np.isfinite(np.asarray(leaf)))
        dones += int(np.sum(np.asarray(state.done)))
    assert state.obs["state"].shape == (NUM_ENVS, sizes["state"])
    assert dones > 0  # random actions end episodes (falls) and they auto-reset


@pytest.mark.integration
def test_reset_perturbed_replaces_only_the_perturbation(env, fns, reset_perturbed):
    """Evaluation hook: the same draws as reset(), with the joint-reading offset and odometry level
    replaced. Actor obs layout: readings (F*Z), validity (F*Z), frame age (F), joint positions
    (12), joint velocities (12), gravity (3), linear velocity estimate (3), ..."""
    keys = jax.random.split(jax.random.PRNGKey(3), NUM_ENVS)  # the shapes compiled once
    base = fns[0](keys)
    pert = reset_perturbed(keys, 0.1, 0.0)
    p = pert.info["task"].params
    np.testing.assert_array_equal(p.joint_offset_rad, np.full((NUM_ENVS, 12), 0.1, np.float32))
    np.testing.assert_array_equal(p.odometry_level, np.zeros(NUM_ENVS, np.float32))
    assert float(env.cfg.env.randomization.odometry_level) > 0  # the config's level differs
    np.testing.assert_array_equal(pert.pipeline_state.qpos, base.pipeline_state.qpos)
    np.testing.assert_array_equal(pert.obs["privileged_state"], base.obs["privileged_state"])
    nf, nz = env.sensing.num_sensors, env.sensing.num_zones
    j0 = 2 * nf * nz + nf  # joint positions
    v0 = j0 + 12 + 12 + 3  # linear velocity estimate
    a, b = np.asarray(pert.obs["state"]), np.asarray(base.obs["state"])
    np.testing.assert_array_equal(a[:, : 2 * nf * nz], b[:, : 2 * nf * nz])  # tof: true poses
    np.testing.assert_allclose(a[:, j0 : j0 + 12] - b[:, j0 : j0 + 12], 0.1, atol=1e-5)
    np.testing.assert_array_equal(a[:, v0 : v0 + 3], 0.0)  # at rest, no odometry noise: exact
    assert np.abs(b[:, v0 : v0 + 3]).max() > 1e-3  # the config's noise is not zero


def test_auto_reset_keeps_the_perturbation(env, fns, reset_perturbed):
    """A perturbation given at reset stays with the env: the auto-reset episode has it too."""
    _, step = fns
    keys = jax.random.split(jax.random.PRNGKey(5), NUM_ENVS)
    state = reset_perturbed(keys, 0.1, 2.0)
    state = _with(state, 0, step=env.episode_steps - 1)  # env 0 reaches its time limit
    state = step(state, jp.zeros((NUM_ENVS, 12)))
    assert float(state.done[0]) == 1.0 and int(state.info["task"].step[0]) == 0
    p = state.info["task"].params
    np.testing.assert_array_equal(p.joint_offset_rad, np.full((NUM_ENVS, 12), 0.1, np.float32))
    np.testing.assert_array_equal(p.odometry_level, np.full(NUM_ENVS, 2.0, np.float32))


def test_robot_dropped_into_gap_terminates(env, fns):
    reset, step = fns
    state = reset(jax.random.split(jax.random.PRNGKey(3), NUM_ENVS))
    # Env 0 hovers at stance height above z = 0 over the pit beside the beam of the top level
    # (beam <= 0.2 m wide at the tile's centre line; 1 m to the side there is pit for ~0.8 m in
    # y, the whole course in x). Platform gaps are too narrow to be sure to swallow the robot:
    # it could stand across a gap narrower than its stance, as it should.
    col = int(np.where(np.asarray(env.tmap.col_type) == TERRAIN_TYPES.index("beam"))[0][0])
    tile, hf = env.tmap.spec.tile, env.hfield
    x = col * tile.length_m + tile.length_m / 2
    y = (env.tmap.num_levels - 0.5) * tile.width_m + 1.0
    gx, gy = np.meshgrid(np.linspace(x - 0.6, x + 0.6, 31), np.linspace(y - 0.45, y + 0.45, 23))
    below = np.asarray(hf.height_at(jp.stack([gx.ravel(), gy.ravel()], axis=-1)))
    assert np.all(below <= hf.z_floor_m + 1e-6), "the robot's footprint must be over the pit"
    qpos = state.pipeline_state.qpos
    qpos = qpos.at[0, 0:3].set(jp.array([x, y, env._stand_height + 0.05]))
    state = state.replace(pipeline_state=state.pipeline_state.replace(qpos=qpos))
    task = state.info["task"]  # every env is pushed at its 3rd step (a draw of the step's keys)
    params = task.params.replace(push_step=jp.full_like(task.params.push_step, 2))
    state = state.replace(info=dict(state.info, task=task.replace(params=params)))
    failed = False
    physics = jax.jit(jax.vmap(env.step_physics))
    reasons = jax.jit(jax.vmap(env.fail_reasons))
    action = jp.zeros((NUM_ENVS, 12))
    for _ in range(40):  # 0.8 s of free fall is enough to drop > 1 m
        d_end, diverged = physics(state, action)  # the pose this step reaches, before a reset
        before = state
        state = step(state, action)
        going = np.asarray(state.done) < 0.5
        np.testing.assert_array_equal(  # step_physics is the step's own physics
            np.asarray(d_end.qpos)[going], np.asarray(state.pipeline_state.qpos)[going]
        )
        if float(state.metrics["episode/failed"][0]) > 0:
            failed = True
            break
    assert failed
    assert float(state.done[0]) == 1.0
    assert float(state.info["truncation"][0]) == 0.0
    # Why: the feet or the base went down into the pit, not a contact, flip or divergence.
    why = {k: bool(v[0]) for k, v in reasons(d_end).items()}
    assert sorted(why) == sorted(FAIL_REASONS) and not bool(diverged[0])
    assert (why["fell"] or why["foot_deep"]) and not (why["body_contact"] or why["flipped"])
    assert not any(bool(v[0]) for v in reasons(before.pipeline_state).values())  # the step before


@pytest.mark.parametrize("offset_m,expect", [(0.4, True), (0.6, False)])
def test_sparse_reward_at_timeout(env, fns, offset_m, expect):
    reset, step = fns
    state = reset(jax.random.split(jax.random.PRNGKey(4), NUM_ENVS))
    task = state.info["task"]
    base_xy = state.pipeline_state.qpos[0, 0:2]
    goal = base_xy + jp.array([offset_m, 0.0])
    level0 = int(task.level[0])
    state = _with(state, 0, goal=goal, step=env.episode_steps - 1)
    state = step(state, jp.zeros((NUM_ENVS, 12)))
    # The deadline is terminal (env.bootstrap_time_limit = False): nothing is bootstrapped there.
    assert float(state.info["truncation"][0]) == 0.0
    assert float(state.done[0]) == 1.0
    reach = float(state.metrics["reward/reach"][0])
    success = float(state.metrics["episode/success"][0])
    if expect:
        assert reach == pytest.approx(float(_cfg().reward.scales.reach))
        assert success == 1.0
        # curriculum: a success moves the env up a level (or to a random one from the top)
        new_level = int(state.info["task"].level[0])
        if level0 < env.tmap.num_levels - 1:
            assert new_level == level0 + 1
    else:
        assert reach == 0.0
        assert success == 0.0
        # far from the goal (progress < 0.5) -> moves down (not below 0)
        assert int(state.info["task"].level[0]) == max(level0 - 1, 0)


def test_auto_reset_restores_valid_state_and_leaves_others(env, fns):
    reset, step = fns
    state = reset(jax.random.split(jax.random.PRNGKey(5), NUM_ENVS))
    state = step(state, jp.zeros((NUM_ENVS, 12)))
    forced = _with(state, 0, step=env.episode_steps - 1)
    a = step(forced, jp.zeros((NUM_ENVS, 12)))
    b = step(state, jp.zeros((NUM_ENVS, 12)))
    # env 0 restarted: step counter 0, standing pose at its spawn, zero velocity, finite obs.
    assert int(a.info["task"].step[0]) == 0
    spawn = np.asarray(a.info["task"].spawn[0])
    q0 = np.asarray(a.pipeline_state.qpos[0])
    np.testing.assert_allclose(q0[0:2], spawn[0:2], atol=1e-5)
    np.testing.assert_allclose(np.asarray(a.pipeline_state.qvel[0]), 0.0)
    assert np.all(np.isfinite(np.asarray(a.obs["state"][0])))
    # every other env is exactly what it would have been without the forced reset.
    for leaf_a, leaf_b in zip(
        jax.tree.leaves((a.pipeline_state.qpos, a.obs, a.reward)),
        jax.tree.leaves((b.pipeline_state.qpos, b.obs, b.reward)),
        strict=True,
    ):
        np.testing.assert_array_equal(np.asarray(leaf_a)[1:], np.asarray(leaf_b)[1:])


def test_same_key_same_trajectory(env, fns):
    reset, step = fns
    keys = jax.random.split(jax.random.PRNGKey(6), NUM_ENVS)
    outs = []
    for _ in range(2):
        s = reset(keys)
        for t in range(5):
            s = step(s, jp.full((NUM_ENVS, 12), 0.1 * t, jp.float32))  # not weak: no recompile
        outs.append(np.asarray(s.obs["state"]))
    np.testing.assert_array_equal(outs[0], outs[1])


# ---------------------------------------------------------------------------------------------
# Reward terms on constructed states (no physics).
def _inputs(**kw):
    base = dict(
        base_pos=jp.array([0.0, 0.0, 0.6]),
        base_lin_vel=jp.zeros(3),
        goal_xy=jp.array([3.0, 4.0]),
        projected_gravity=jp.array([0.0, 0.0, -1.0]),
        torques=jp.zeros(12),
        qvel=jp.zeros(12),
        last_qvel=jp.zeros(12),
        action=jp.zeros(12),
        last_action=jp.zeros(12),
        foot_vel=jp.zeros((4, 3)),
        foot_contact=jp.ones(4),
        q=jp.asarray(constants.DEFAULT_POSE),
        default_q=jp.asarray(constants.DEFAULT_POSE),
        time_s=jp.asarray(5.0),
        failed=jp.asarray(0.0),
        truncated=jp.asarray(0.0),
        knee_contact=jp.zeros(4),
        foot_edge=jp.zeros(4),
        time_left_s=jp.asarray(5.0),
        guidance_weight=jp.asarray(1.0),
    )
    base.update(kw)
    return rw.RewardInputs(**base)


def _spec(rcfg) -> rw.RewardSpec:
    return rw.RewardSpec.from_config(rcfg)


def _terms(**kw):
    return {
        k: float(v) for k, v in rw.compute_terms(_inputs(**kw), _spec(_cfg().reward), 0.02).items()
    }


def test_reward_terms_hand_checked():
    rcfg = _cfg().reward
    # Guidance: goal at (3, 4) -> direction (0.6, 0.8); v = (1, 0) -> 0.6 m/s toward the goal.
    assert _terms(base_lin_vel=jp.array([1.0, 0.0, 0.0]))["guidance"] == pytest.approx(0.6)
    # ... clipped at guidance_max_speed_mps (1.0): v = (3, 4) -> 5 m/s toward -> 1.0
    assert _terms(base_lin_vel=jp.array([3.0, 4.0, 0.0]))["guidance"] == pytest.approx(1.0)
    # Torques: 12 joints at 2 N m -> 12 * 4 = 48.
    assert _terms(torques=jp.full(12, 2.0))["torques"] == pytest.approx(48.0)
    # Joint acc: one joint 0.1 rad/s faster over 0.02 s -> (5 rad/s^2)^2 = 25.
    assert _terms(qvel=jp.zeros(12).at[3].set(0.1))["joint_acc"] == pytest.approx(25.0)
    # Action rate: (0.5 - 0)^2 + (0 - (-0.5))^2 = 0.5.
    t = _terms(action=jp.zeros(12).at[0].set(0.5), last_action=jp.zeros(12).at[1].set(-0.5))
    assert t["action_rate"] == pytest.approx(0.5)
    # Foot slip: only feet in contact count: foot 0 slides (0.3, 0.4) -> 0.25; foot 1 in the air.
    fv = jp.zeros((4, 3)).at[0].set(jp.array([0.3, 0.4, 1.0])).at[1].set(jp.array([2.0, 0, 0]))
    t = _terms(foot_vel=fv, foot_contact=jp.array([1.0, 0.0, 1.0, 1.0]))
    assert t["foot_slip"] == pytest.approx(0.25)
    # Orientation: gravity (0.6, 0, -0.8) -> 0.36.
    assert _terms(projected_gravity=jp.array([0.6, 0.0, -0.8]))["orientation"] == pytest.approx(
        0.36
    )
    # Stall: slow and far after the grace period -> 1; before grace -> 0; at goal -> 0.
    assert _terms()["stall"] == 1.0
    assert _terms(time_s=jp.asarray(rcfg.stall_grace_s / 2))["stall"] == 0.0
    assert _terms(goal_xy=jp.array([0.3, 0.0]))["stall"] == 0.0
    # Jump: all four feet off the ground -> 1.
    assert _terms(foot_contact=jp.zeros(4))["jump"] == 1.0
    assert _terms(foot_contact=jp.array([0.0, 0.0, 0.0, 1.0]))["jump"] == 0.0
    assert _terms(foot_contact=jp.zeros(4), time_s=jp.asarray(rcfg.jump_grace_s / 2))["jump"] == 0.0
    # Posture: only within the success radius: one joint 0.2 rad off -> 0.04.
    q = jp.asarray(constants.DEFAULT_POSE).at[2].add(0.2)
    assert _terms(q=q, goal_xy=jp.array([0.3, 0.0]))["posture"] == pytest.approx(0.04)
    assert _terms(q=q)["posture"] == 0.0
    # Reach: only at the time limit and within 0.5 m.
    assert _terms(goal_xy=jp.array([0.4, 0.0]), truncated=jp.asarray(1.0))["reach"] == 1.0
    assert _terms(goal_xy=jp.array([0.6, 0.0]), truncated=jp.asarray(1.0))["reach"] == 0.0
    assert _terms(goal_xy=jp.array([0.4, 0.0]))["reach"] == 0.0
    # Termination.
    assert _terms(failed=jp.asarray(1.0))["termination"] == 1.0
    # Collision: number of knees touching the terrain.
    assert _terms(knee_contact=jp.array([1.0, 0.0, 1.0, 0.0]))["collision"] == 2.0
    # Foot edge: number of feet at an edge.
    assert _terms(foot_edge=jp.array([1.0, 0.0, 1.0, 1.0]))["foot_edge"] == 3.0
    # Scaling: dense terms get the control dt, sparse ones not.
    scaled = rw.scaled_terms({k: jp.asarray(1.0) for k in rw.REWARD_TERMS}, rcfg.scales, 0.02)
    assert float(scaled["reach"]) == pytest.approx(rcfg.scales.reach)
    assert float(scaled["torques"]) == pytest.approx(rcfg.scales.torques * 0.02)


def test_arrive_task_terms_hand_checked():
    """The anchors' task (configs/teacher_cpu.py): window, goal pay, bias weight, stall."""
    cfg = _cfg()
    _arrive(cfg)
    r = cfg.reward

    def terms(**kw):
        return {k: float(v) for k, v in rw.compute_terms(_inputs(**kw), _spec(r), 0.02).items()}

    # Task: goal (3, 4) is 5 m away -> 1 / (2 s * (1 + 25)) per s inside the 2 s window only.
    assert terms(time_left_s=jp.asarray(1.0))["task"] == pytest.approx(1.0 / 52.0)
    assert terms(time_left_s=jp.asarray(0.0))["task"] == pytest.approx(1.0 / 52.0)
    assert terms(time_left_s=jp.asarray(2.5))["task"] == 0.0
    # ... at the goal 1 / 2 per s; 0.5 m away 1 / (2 * 1.25) = 0.4 per s.
    at = terms(goal_xy=jp.array([0.0, 0.0]), time_left_s=jp.asarray(0.5))["task"]
    assert at == pytest.approx(0.5)
    half = terms(goal_xy=jp.array([0.3, 0.4]), time_left_s=jp.asarray(0.5))["task"]
    assert half == pytest.approx(0.4)
    # ... and the whole window (100 steps of 0.02 s, time left 1.98 .. 0) pays 10 / (1 + d^2).
    total = sum(
        rw.scaled_terms(
            rw.compute_terms(
                _inputs(goal_xy=jp.array([0.3, 0.4]), time_left_s=jp.asarray(k * 0.02)),
                _spec(r),
                0.02,
            ),
            r.scales,
            0.02,
        )["task"]
        for k in range(0, 101)  # time left 2.0 (k = 100) is outside the window
    )
    assert float(total) == pytest.approx(10.0 / 1.25, rel=1e-4)
    # Guidance: progress toward the goal, capped at 0.6 m/s, nothing at the goal, times the weight.
    assert terms(base_lin_vel=jp.array([0.3, 0.4, 0.0]))["guidance"] == pytest.approx(0.5)
    assert terms(base_lin_vel=jp.array([3.0, 4.0, 0.0]))["guidance"] == pytest.approx(0.6)
    w = jp.asarray(0.25)
    assert terms(base_lin_vel=jp.array([3.0, 4.0, 0.0]), guidance_weight=w)[
        "guidance"
    ] == pytest.approx(0.15)
    assert terms(goal_xy=jp.array([0.3, 0.0]), base_lin_vel=jp.array([1.0, 0, 0]))[
        "guidance"
    ] == pytest.approx(0.0)
    # Stall on progress: 1 m/s along (0.8, -0.6), perpendicular to the goal direction (0.6, 0.8),
    # stalls; 0.3 m/s toward the goal does not.
    assert terms(base_lin_vel=jp.array([0.8, -0.6, 0.0]))["stall"] == 1.0
    assert terms(base_lin_vel=jp.array([0.18, 0.24, 0.0]))["stall"] == 0.0
    assert terms(base_lin_vel=jp.array([0.06, 0.08, 0.0]))["stall"] == 1.0  # 0.1 < 0.2 m/s
    # The old task's stall: the same sideways walk is moving.
    assert _terms(base_lin_vel=jp.array([0.8, -0.6, 0.0]))["stall"] == 0.0
    # The old task pays no task term (scale 0) and full guidance at the goal.
    assert _cfg().reward.scales.task == 0.0


def test_overspeed_term_hand_checked():
    """overspeed: horizontal base speed above reward.overspeed_mps, linear, off by default."""
    r = _cfg().reward
    assert r.scales.overspeed == 0.0 and r.overspeed_mps == 0.6

    def term(v, limit=0.6):
        r.overspeed_mps = limit
        x = _inputs(base_lin_vel=jp.asarray(v, jp.float32))
        return float(rw.compute_terms(x, _spec(r), 0.02)["overspeed"])

    assert term([0.3, 0.4, 0.0]) == 0.0  # 0.5 m/s is below 0.6
    assert term([0.6, 0.8, 0.0]) == pytest.approx(0.4)  # 1.0 m/s: 0.4 above
    assert term([0.6, 0.8, 3.0]) == pytest.approx(0.4)  # vertical speed does not count
    assert term([-0.9, -1.2, 0.0]) == pytest.approx(0.9)  # any direction: 1.5 m/s
    assert term([0.6, 0.8, 0.0], limit=0.0) == pytest.approx(1.0)
    # Scaled as a rate: -2 per (m/s) per s over a 0.02 s step at 1.0 m/s -> -2 * 0.4 * 0.02.
    r.overspeed_mps = 0.6
    r.scales.overspeed = -2.0
    x = _inputs(base_lin_vel=jp.array([0.6, 0.8, 0.0]))
    scaled = rw.scaled_terms(rw.compute_terms(x, _spec(r), 0.02), r.scales, 0.02)
    assert float(scaled["overspeed"]) == pytest.approx(-0.016)
    # A config saved before the term existed reads it as off (read migrated, foottof.renames).
    saved = r.to_dict()
    del saved["scales"]["overspeed"]
    old = ml_collections.ConfigDict(renames.migrate_config_dict({"reward": saved})["reward"])
    assert rw.RewardSpec.from_config(old).scale("overspeed") == 0.0


@pytest.mark.integration
def test_guidance_weight_counts_training_steps_across_resets(env):
    """The env's step counter (info['env_steps']) survives auto-resets and sets the bias weight:
    decay over iterations 0-2 at 2 steps per iteration, 3-step episodes."""
    cfg = _cfg()
    _arrive(cfg)
    cfg.reward.guidance_decay_start_iteration = 0
    cfg.reward.guidance_decay_end_iteration = 2
    cfg.ppo.num_steps = 2
    cfg.env.episode_length_s = 0.06  # 3 control steps
    aenv = make_env(cfg)
    state = jax.jit(aenv.reset)(jax.random.PRNGKey(3))
    assert int(state.info["env_steps"]) == 0
    step = jax.jit(aenv.step)
    weights, dones = [], []
    for _ in range(5):
        state = step(state, jp.zeros(12))
        weights.append(float(state.metrics["task/guidance_weight"]))
        dones.append(float(state.done))
    # counter before step k (1-based) is k - 1 -> iteration (k - 1) / 2 -> weight 1 - it / 2
    np.testing.assert_allclose(weights, [1.0, 0.75, 0.5, 0.25, 0.0])
    assert dones[2] == 1.0  # the deadline reset the episode, not the counter
    assert int(state.info["env_steps"]) == 5
    # without the decay the env carries no counter and the weight is 1
    assert "env_steps" not in env.reset(jax.random.PRNGKey(3)).info


def test_actor_terrain_adds_the_teachers_inputs():
    """env.actor_terrain appends the critic's foot patches (36) and the first 117 scan points
    (x <= 0.6 m) to the actor's observation; the rest is unchanged."""
    from foottof.envs.observations import ACTOR_SCAN_POINTS, critic_scan_points

    cfg = _cfg()
    cfg.env.critic_height_scan = True
    plain = make_env(cfg).reset(jax.random.PRNGKey(4))
    cfg.env.actor_terrain = True
    teacher = make_env(cfg).reset(jax.random.PRNGKey(4))
    n = plain.obs["state"].shape[-1]
    assert ACTOR_SCAN_POINTS == 117
    assert float(jp.max(critic_scan_points()[:ACTOR_SCAN_POINTS, 0])) == pytest.approx(0.6)
    assert float(jp.min(critic_scan_points()[ACTOR_SCAN_POINTS:, 0])) > 0.6
    assert teacher.obs["state"].shape[-1] == n + 36 + 117
    np.testing.assert_array_equal(teacher.obs["state"][:n], plain.obs["state"])
    np.testing.assert_array_equal(teacher.obs["privileged_state"], plain.obs["privileged_state"])
    priv = plain.obs["privileged_state"]
    m = n  # the critic's clean copy of the actor obs comes first, then the 36 foot heights
    np.testing.assert_allclose(teacher.obs["state"][n : n + 36], priv[m : m + 36])
    np.testing.assert_allclose(teacher.obs["state"][n + 36 :], priv[-171:][:117])


def test_guidance_weight_schedule():
    # 1 until 500, linear to 0 at 1500, 0 after; no decay (end 0) -> always 1.
    its = jp.array([0.0, 500.0, 750.0, 1000.0, 1500.0, 4000.0])
    np.testing.assert_allclose(
        np.asarray(rw.guidance_weight(its, 500, 1500)), [1.0, 1.0, 0.75, 0.5, 0.0, 0.0]
    )
    np.testing.assert_allclose(np.asarray(rw.guidance_weight(its, 0, 0)), np.ones(6))


def test_reward_scales_added_terms_default_off():
    # A config saved before the task term existed, read migrated (foottof.renames): the term
    # scales to 0. Unmigrated, it lacks a term the env reads.
    saved = _cfg().reward.to_dict()
    del saved["scales"]["task"]
    with pytest.raises(ValueError, match="missing term.*task"):
        rw.check_scales(saved["scales"])
    scales = renames.migrate_config_dict({"reward": saved})["reward"]["scales"]
    rw.check_scales(scales)
    ones = {k: jp.asarray(1.0) for k in rw.REWARD_TERMS}
    assert float(rw.scaled_terms(ones, ml_collections.ConfigDict(scales), 0.02)["task"]) == 0.0
    # overall_scale multiplies every term, dense and sparse
    tenth = rw.scaled_terms(ones, ml_collections.ConfigDict(scales), 0.02, 0.1)
    assert float(tenth["reach"]) == pytest.approx(0.1 * scales["reach"])
    assert float(tenth["torques"]) == pytest.approx(0.1 * 0.02 * scales["torques"])
    del scales["reach"]  # a term missing: an error
    with pytest.raises(ValueError, match="missing term.*reach"):
        rw.check_scales(scales)


def test_bad_inputs():
    with pytest.raises(ValueError, match="unknown source 'lidar'.*tof"):
        make_env(_cfg(), source="lidar")
    cfg = _cfg()
    cfg.lock()  # train.py / evaluate.py lock the config: a typo in a key is an error
    with pytest.raises(AttributeError, match="episode_lenght_s"):
        cfg.env.episode_lenght_s = 5.0
    cfg = _cfg()
    cfg.reward.scales.bogus = 1.0
    with pytest.raises(ValueError, match="unknown reward term.*bogus"):
        make_env(cfg)
    from foottof.terrain import generate_tile

    with pytest.raises(ValueError, match="lava"):
        generate_tile("lava", jax.random.PRNGKey(0), 0.5)


def test_total_reward_clips_dense_and_drops_diverged_steps():
    names = rw.REWARD_TERMS
    terms = {k: jp.asarray(0.0) for k in names}
    terms.update(guidance=jp.asarray(0.1), foot_slip=jp.asarray(-80.0), reach=jp.asarray(10.0))
    terms.update(termination=jp.asarray(-1.0))
    # Hand-summed: dense 0.1 - 80 = -79.9; sparse 10 - 1 = 9.
    f = lambda pos, valid: float(rw.total_reward(terms, pos, jp.asarray(valid)))
    assert f(False, 1.0) == pytest.approx(-70.9)
    assert f(True, 1.0) == pytest.approx(9.0)  # dense clipped at 0, sparse added after the clip
    assert f(False, 0.0) == pytest.approx(9.0)  # diverged step: dense terms dropped
    terms.update(foot_slip=jp.asarray(0.0))
    assert f(True, 1.0) == pytest.approx(9.1)


def test_deadline_value_target_stays_bounded(env, fns):
    """The at-goal state at the deadline: repeatedly fitting V to its own target (what PPO's value
    regression does) converges to the reach reward, not to reach / (1 - gamma)."""
    from foottof.ppo import losses

    reset, step = fns
    state = reset(jax.random.split(jax.random.PRNGKey(4), NUM_ENVS))
    goal = state.pipeline_state.qpos[0, 0:2]
    state = step(_with(state, 0, goal=goal, step=env.episode_steps - 1), jp.zeros((NUM_ENVS, 12)))
    reward = jp.asarray(state.reward[0]).reshape(1, 1)
    trunc = jp.asarray(state.info["truncation"][0]).reshape(1, 1)
    done = jp.asarray(state.done[0]).reshape(1, 1)
    assert float(done[0, 0]) == 1.0 and float(state.metrics["reward/reach"][0]) > 0
    gamma = float(_cfg().ppo.gamma)

    def fit(_, v):  # V <- its own GAE target (with bootstrapping V would run to 10 / (1 - gamma))
        r = losses.bootstrap_truncation(reward, v, trunc, gamma)
        return losses.compute_gae(r, v, done, jp.zeros(1), gamma, 0.95)[1]

    v = jax.jit(lambda v: jax.lax.fori_loop(0, 300, fit, v))(jp.zeros((1, 1)))
    assert float(v[0, 0]) == pytest.approx(float(reward[0, 0]), rel=1e-5)
    assert float(v[0, 0]) < 2 * float(_cfg().reward.scales.reach)


def test_diverged_step_pays_termination_only(env, fns):
    reset, step = fns
    state = reset(jax.random.split(jax.random.PRNGKey(8), NUM_ENVS))
    qvel = state.pipeline_state.qvel.at[0, 6:18].set(1e4)  # absurd joint speeds: diverged
    state = state.replace(pipeline_state=state.pipeline_state.replace(qvel=qvel))
    state = step(state, jp.zeros((NUM_ENVS, 12)))
    assert float(state.done[0]) == 1.0 and float(state.metrics["episode/failed"][0]) == 1.0
    assert float(state.reward[0]) == pytest.approx(float(_cfg().reward.scales.termination))


def _kneeling(env, base_xy, knee_depth_m):
    """qpos in the default pose, level, with the lowest knee sphere ``knee_depth_m`` into z = 0."""
    from foottof.robot import kinematics
    from foottof.robot.model import KNEE_SPHERE_RADIUS_M

    q = jp.concatenate([jp.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]), env._default_q])
    knee_z = float(jp.min(kinematics.world_foot_kinematics(q, env.shank_scale).knee_pos[:, 2]))
    z = -knee_z + KNEE_SPHERE_RADIUS_M - knee_depth_m
    return q.at[0:3].set(jp.array([base_xy[0], base_xy[1], z]))


@pytest.mark.parametrize("terminates", [False, True])
def test_knee_contact_is_a_penalty_unless_configured(env, on_columns, terminates):
    """Knees on flat ground, base clear: a collision penalty, a failure only on request."""
    import types

    from foottof.robot import kinematics

    xy = on_columns.info["task"].spawn[2, 0:2]  # start platform: flat at z = 0
    cfg = _cfg()
    cfg.env.knee_contact_terminates = terminates
    e = make_env(cfg) if terminates else env
    for depth, touching in ((0.01, True), (-0.01, False)):
        qpos = _kneeling(e, xy, depth)
        fk = kinematics.world_foot_kinematics(qpos, e.shank_scale)
        gravity = jp.array([0.0, 0.0, -1.0])
        failed, knees, stuck = e._failed(types.SimpleNamespace(qpos=qpos), gravity, fk)
        assert (float(jp.sum(knees)) > 0) == touching
        assert bool(failed) == (touching and terminates) and not bool(stuck)  # flat: no gap


def test_spawn_pays_no_penalty_events(fns, on_columns):
    """Standing still from the spawn: no jump, collision, termination or slip events."""
    _, step = fns
    state = on_columns
    for _ in range(25):
        state = step(state, jp.zeros((NUM_ENVS, 12)))
        for term in ("jump", "collision", "termination"):
            assert np.all(np.asarray(state.metrics[f"reward/{term}"]) == 0.0), term
        # the spawn platform is flat: no foot stands at an edge
        assert np.all(np.asarray(state.metrics["task/feet_at_edges"]) == 0.0)


def test_foot_edges_on_a_hand_built_step():
    """A 0.2 m step between vertex columns x = 0 and x = 0.04 (bilinear ramp between them):
    heights and edge flags by hand for feet on top, on the rim, at the wall foot, far, airborne."""
    from foottof.terrain.heightfield import Heightfield

    n, cell = 11, 0.04
    x = -0.2 + cell * np.arange(n)
    heights = np.where(x[None, :] >= 0.04 - 1e-9, 0.2, 0.0) * np.ones((n, 1))
    hf = Heightfield(heights=jp.asarray(heights, jp.float32), x0_m=-0.2, y0_m=-0.2, cell_m=cell)
    r_foot, margin = 0.0315, 0.01
    feet = jp.array(
        [
            [0.12, 0.0, 0.2 + r_foot],  # on top, 8 cm from the ramp: samples all 0.2 -> no edge
            [0.06, 0.0, 0.2 + r_foot],  # on the rim: samples 0.2, 0.2, 0.1 (x = 0.02) -> edge
            [-0.02, 0.0, r_foot],  # at the wall foot: samples 0.1 (x = 0.02) .. 0 -> edge
            [-0.12, 0.0, r_foot],  # on the ground 12 cm away: all 0 -> no edge
        ]
    )
    edges = rw.foot_edges(feet, hf.height_at, r_foot, margin, 0.04, 0.05)
    np.testing.assert_array_equal(np.asarray(edges), [0.0, 1.0, 1.0, 0.0])
    # the same feet 0.3 m higher (in the air): no contact, no edge
    lifted = rw.foot_edges(
        feet + jp.array([0.0, 0.0, 0.3]), hf.height_at, r_foot, margin, 0.04, 0.05
    )
    np.testing.assert_array_equal(np.asarray(lifted), np.zeros(4))
    # a foot slipping into the crack: its centre over the low vertex (x = 0, height 0) at the
    # height of the step top touches the rim, which the contact test under the centre misses
    crack = jp.array([[0.0, 0.0, 0.2], [0.0, 0.0, 0.25], [0.3, 0.0, 0.2 + r_foot], [0, 0, 0.1]])
    edges = rw.foot_edges(crack, hf.height_at, r_foot, margin, 0.04, 0.05)
    np.testing.assert_array_equal(np.asarray(edges), [1.0, 0.0, 0.0, 1.0])
    # a spread of 0.1 m is no edge when edges need more than 0.15 m
    high = rw.foot_edges(feet, hf.height_at, r_foot, margin, 0.04, 0.15)
    np.testing.assert_array_equal(np.asarray(high), np.zeros(4))


def _lowest_foot_bottoms(env, qpos: np.ndarray) -> np.ndarray:
    """Oracle: per reset, the lowest foot sphere's bottom above the terrain under it [m], from
    MuJoCo C (foot centres by mj_kinematics, terrain by mj_rayHfield straight down)."""
    import mujoco

    m, d = env.mj_model, mujoco.MjData(env.mj_model)
    feet = [m.geom(n).id for n in constants.FOOT_GEOMS]
    terrain = m.geom("terrain").id
    top = float(env.hfield.z_floor_m + env.hfield.z_range_m + 1.0)
    out = []
    for q in qpos:
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        bottoms = []
        for g in feet:
            x, y, z = d.geom_xpos[g]
            dist = mujoco.mj_rayHfield(m, d, terrain, np.array([x, y, top]), np.array([0, 0, -1.0]))
            bottoms.append(z - m.geom_size[g, 0] - (top - dist))
        out.append(min(bottoms))
    return np.asarray(out)


def test_wide_initial_poses_start_no_foot_inside_the_terrain():
    """Stage 2's initial poses (roll/pitch U(+-0.2) rad, joints U(+-0.15) rad) put a foot up to
    ~0.13 m into the terrain at the nominal spawn height; the reset lifts the robot until the
    lowest foot sphere rests on the terrain. Poses whose feet are all above it keep the nominal
    height (stage 1's spawns), so the lift never raises a robot higher than it needs."""
    cfg = _cfg()
    cfg.env.init_roll_pitch_rad = 0.2
    cfg.env.init_joint_noise_rad = 0.15
    env = make_env(cfg)
    n = 48
    state = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(11), n))
    qpos = np.asarray(state.pipeline_state.qpos, np.float64)
    bottoms = _lowest_foot_bottoms(env, qpos)
    assert bottoms.min() > -2e-3, bottoms.min()  # no foot starts inside the terrain
    # lifted resets rest a foot on the terrain; the others keep the nominal height above it
    task = state.info["task"]
    nominal = np.asarray(task.spawn[:, 3]) + env._stand_height + env.spec.spawn_height_offset_m
    lifted = qpos[:, 2] > nominal + 1e-5
    assert 0 < lifted.sum() < n  # both kinds occur at these pose spreads
    np.testing.assert_allclose(bottoms[lifted], 0.0, atol=2e-3)
    np.testing.assert_allclose(qpos[~lifted, 2], nominal[~lifted], atol=1e-5)
    assert (bottoms[~lifted] > -2e-3).all()
