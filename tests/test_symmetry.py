"""Left-right mirror symmetry: the maps against MuJoCo, and the mirrored sequences in PPO/DAgger."""

import glob
import hashlib
import importlib
import os

import jax
import jax.numpy as jp
import numpy as np
import pytest
import toy_envs
from helpers import REPO, small_cfg, tree_equal

from configs import smoke
from foottof.envs import make_training_env
from foottof.envs import observations as obs_lib
from foottof.envs import symmetry as sym
from foottof.ppo import distill, losses
from foottof.ppo import symmetry as ppo_sym
from foottof.ppo import train as train_lib
from foottof.ppo.storage import checkpoint as ckpt
from foottof.robot import model as robot_model
from foottof.terrain.heightfield import Heightfield
from foottof.terrain.terrain_map import TerrainMap, TerrainMapSpec


# ------------------------------------------------------------------------------------ the maps
def _user_configs():
    paths = sorted(glob.glob(os.path.join(REPO, "configs", "*.py")))
    paths += sorted(glob.glob(os.path.join(REPO, "configs", "experiments", "*.py")))
    names = [os.path.relpath(p, REPO)[:-3].replace(os.sep, ".") for p in paths]
    return [n for n in names if not n.split(".")[-1].startswith("_")]


@pytest.mark.parametrize("name", _user_configs())
def test_every_shipped_layout_has_self_inverse_signed_permutations(name):
    """Each config's maps cover its observation sizes (4 sensors x 16 zones: actor 181, + 153
    or 306 teacher inputs, + 372 fine ones; critic 223, + 171 scan) and are signed permutations with
    mirror(mirror(x)) == x; the student's view of a teacher's inputs mirrors among itself."""
    cfg = importlib.import_module(name).get_config()
    m = sym.make_mirror(cfg)
    f, z = len(cfg.sensor.sites), int(cfg.sensor.grid) ** 2
    actor = 2 * f * z + f + 49
    if cfg.env.get("actor_terrain", False):
        actor += obs_lib.actor_terrain_size(bool(cfg.env.get("actor_terrain_seen", False)))
    if cfg.env.get("actor_terrain_fine", False):
        actor += 372  # the 5 cm points between the 10 cm ones (envs.fine_terrain)
    critic = 2 * f * z + f + 49 + 36 + 4 + 2 + (171 if cfg.env.get("critic_height_scan") else 0)
    assert m.obs["state"].size == actor and m.obs["privileged_state"].size == critic
    x = {
        k: jax.random.normal(jax.random.PRNGKey(i), (3, v.size))
        for i, (k, v) in enumerate(m.obs.items())
    }
    for k, mp in m.maps().items():
        v = x.get(k, jax.random.normal(jax.random.PRNGKey(7), (3, mp.size)))
        assert sorted(mp.perm.tolist()) == list(range(mp.size))
        assert set(np.abs(mp.sign).tolist()) == {1.0}
        np.testing.assert_array_equal(mp(mp(v)), v)
        np.testing.assert_array_equal(mp(np.asarray(v)), np.asarray(mp(v)))  # NumPy = JAX
    assert m.obs["state"].first(actor if actor == 181 else 181 + 36).size > 0


def test_a_map_that_is_not_its_own_inverse_or_not_a_permutation_is_refused():
    with pytest.raises(ValueError, match="own inverse"):
        sym.SignedPerm([1, 2, 0], [1.0, 1.0, 1.0])  # a 3-cycle
    with pytest.raises(ValueError, match="own inverse"):
        sym.SignedPerm([1, 0], [1.0, -1.0])  # a swap with one sign: x -> (x1, -x0), twice -x
    with pytest.raises(ValueError, match="not a signed permutation"):
        sym.SignedPerm([0, 0], [1.0, 1.0])
    with pytest.raises(ValueError, match="do not mirror among themselves"):
        sym.make_mirror(smoke.get_config()).obs["state"].first(181 + 1)  # half a ToF grid ...
    cfg = smoke.get_config()
    cfg.env.actor_terrain = True
    teacher = sym.make_mirror(cfg).obs["state"]
    for n in (181, 181 + 36, 181 + 153):  # the student's inputs (+ privileged: 36, all)
        assert teacher.first(n).size == n
    with pytest.raises(ValueError, match="do not mirror among themselves"):
        teacher.first(181 + 40)  # 4 of the base scan's first row


def test_the_joint_and_foot_maps_follow_the_names_and_axes():
    """LF <-> RF and LH <-> RH; HAA (axis +x, in the mirror plane) flips, HFE/KFE (+y) do not."""
    assert sym.FOOT_PERM == (1, 0, 3, 2)
    m = robot_model.make_model()
    for i, name in enumerate(robot_model.constants.JOINT_NAMES):
        j = int(sym.JOINTS.perm[i])
        other = robot_model.constants.JOINT_NAMES[j]
        assert name[0] != other[0] and name[1:] == other[1:]
        axis = m.jnt_axis[m.joint(name).id]
        # a rotation about a in the mirror image is one about -S a: the sign of its y component
        assert sym.JOINTS.sign[i] == (1.0 if abs(axis[1]) == 1.0 else -1.0)
        # the mirrored joint's body sits at the mirror image (y -> -y) of this one's
        b, bo = m.body(m.jnt_bodyid[m.joint(name).id]), m.body(m.jnt_bodyid[m.joint(other).id])
        np.testing.assert_allclose(m.body_pos[bo.id], m.body_pos[b.id] * [1, -1, 1], atol=1e-12)


def test_a_sensor_layout_without_a_mirror_partner_has_no_mirror():
    cfg = smoke.get_config()
    cfg.sensor.tilt_x_deg = (5.0, 0.0, 0.0, 0.0)  # the LF sensor turned, RF not
    with pytest.raises(ValueError, match="no mirror partner"):
        sym.make_mirror(cfg)
    cfg.sensor.tilt_x_deg = (5.0, -5.0, 0.0, 0.0)  # both turned outward alike: a mirror pair
    cfg.sensor.offset_m = ((0.0, 0.01, 0.0), (0.0, -0.01, 0.0), (0.0,) * 3, (0.0,) * 3)
    sym.make_mirror(cfg)


# ------------------------------------------------------------------- MuJoCo as the oracle
Y_START_M = 1.2  # robot A starts at y = +1.2 m, its mirror image B at y = -1.2 m
AIR_STEPS = 9  # control steps before the first foot touches the terrain (spawned 0.3 m up)
TOL = 1e-5  # float32 rounding of the JAX side; MuJoCo C steps the two in float64


def _terrain_and_its_mirror_image(cfg):
    """A map whose half y > 0 is a terrain around robot A and whose half y < 0 is its mirror
    image (y -> -y): steps and a trench across x, and across y a slope, a ledge and a pit on
    A's left, a dip on its right. Heights are f(x) + g(|y|): every cell is planar, so MuJoCo's
    triangulation (one diagonal per cell, not mirror-symmetric) is the same surface both ways."""
    xs = -2.0 + 0.04 * np.arange(151)
    ys = 0.04 * (np.arange(151) - 75)
    f = np.select(
        [(xs > 0.45) & (xs < 0.85), (xs >= 0.85) & (xs < 1.05), xs >= 1.05], [0.08, -0.3, 0.05], 0.0
    )
    y = np.abs(ys)
    g = 0.06 * (y - Y_START_M) + np.select(
        [(y > 1.45) & (y < 1.75), (y > 1.85) & (y < 2.4), (y > 0.55) & (y < 0.8)],
        [0.07, -0.6, -0.1],
        0.0,
    )
    heights = f[None, :] + g[:, None]  # rows along +y
    assert np.array_equal(heights, heights[::-1])
    hf = Heightfield(jp.asarray(heights, jp.float32), x0_m=-2.0, y0_m=-3.0, cell_m=0.04)
    spec = TerrainMapSpec.from_config(cfg.terrain, 1)
    L, C = spec.num_levels, spec.num_cols
    spawn = jp.broadcast_to(jp.array([0.0, Y_START_M, 0.0, 0.0]), (L, C, 4))
    goal = jp.broadcast_to(jp.array([4.5, Y_START_M]), (L, C, 2))
    return TerrainMap(hf, spawn, goal, jp.zeros(C, jp.int32), jp.zeros(L), jp.zeros((L, C)), spec)


def _mirror_state(env, mirror, s):
    """The env State of the robot's mirror image on the mirrored half: physics (qpos, qvel,
    warm start), task (spawn, goal, last action/joint velocities), the ToF pipeline (sensors
    swapped, zone columns flipped) and the seen grid (its y axis flipped)."""
    q = s.pipeline_state.qpos
    quat = q[3:7] * jp.array([1.0, -1.0, 1.0, -1.0])  # S R S: (w, -x, y, -z)
    qpos = jp.concatenate([sym.POLAR_VEC(q[0:3]), quat, sym.JOINTS(q[7:19])])

    def velocity(v):  # free joint: world linear, body angular; then the joints
        return jp.concatenate([sym.POLAR_VEC(v[0:3]), sym.AXIAL_VEC(v[3:6]), sym.JOINTS(v[6:18])])

    d = s.pipeline_state.replace(
        qpos=qpos, qvel=velocity(s.pipeline_state.qvel),
        qacc_warmstart=velocity(s.pipeline_state.qacc_warmstart),
    )  # fmt: skip
    task = s.info["task"]
    task = task.replace(
        spawn=task.spawn * jp.array([1.0, -1.0, -1.0, 1.0]), goal=sym.POLAR_VEC(
            jp.append(task.goal, 0.0))[:2],
        last_action=sym.JOINTS(task.last_action), last_qvel=sym.JOINTS(task.last_qvel),
    )  # fmt: skip
    zones, per_sensor = sym.tof_maps(sym.FOOT_PERM, int(env.cfg.sensor.grid))

    def z(a):  # (..., F, Z)
        return zones(a.reshape(a.shape[:-2] + (-1,))).reshape(a.shape)

    t = s.info["sensor"].tof
    t = t.replace(
        levels=t.levels.replace(offset_m=per_sensor(t.levels.offset_m)),
        phase_s=per_sensor(t.phase_s), prev=jax.tree.map(z, t.prev), held_m=z(t.held_m),
        held_valid=z(t.held_valid), held_time_s=per_sensor(t.held_time_s), ring_m=z(t.ring_m),
        ring_valid=z(t.ring_valid), ring_time_s=per_sensor(t.ring_time_s),
    )  # fmt: skip
    _, grid = s.info["seen"]
    seen = (env.seen_grid.init(task.spawn[:2])[0], grid[:, ::-1])
    info = dict(s.info, task=task, sensor=s.info["sensor"].replace(tof=t), seen=seen)
    return s.replace(pipeline_state=d, info=info, obs=mirror.observation(s.obs))


@pytest.fixture(scope="module")
def mirrored_rollout():
    """(mirror, obs A (T, ...), obs B (T, ...)) of robot A and its mirror image B stepped in one
    env with mirrored random actions: a teacher that sees only what its rays hit (the largest
    actor layout: 181 + 306) and a critic with the height scan (394). No noise, no
    randomization (their draws would not mirror); the base's inertia made symmetric: ANYmal-D's
    COM sits 0.7 mm left of its middle and its products of inertia are not zero, an asymmetry of
    the robot, not of the maps. A and B are dropped from 0.3 m with an initial velocity and
    compared until the first foot lands: MuJoCo's contacts on a heightfield are not
    mirror-symmetric (one contact per triangular prism a foot overlaps, and each cell's diagonal
    runs one way), which parts the two by ~1e-2 within three steps of a touchdown. The feet count
    as in contact within 0.25 m of the terrain (env.contact_margin_m), so the contact flags vary
    in the air."""
    cfg = smoke.get_config()
    cfg.env.randomization.enabled = False
    cfg.env.randomization.odometry_level = 0.0
    for stage in ("stage1", "stage2"):
        for field in ("offset_m", "proportional", "gaussian_m", "missing_rate", "model_scale"):
            cfg.noise[stage][field] = 0.0
    cfg.env.actor_terrain = True
    cfg.env.actor_terrain_seen = True
    cfg.env.critic_height_scan = True
    cfg.env.init_roll_pitch_rad = 0.1
    cfg.env.init_joint_noise_rad = 0.1
    cfg.env.spawn_height_offset_m = 0.3
    cfg.env.contact_margin_m = 0.25
    mass, com, inertia = robot_model.BASE_INERTIAL
    symmetric = (mass, (com[0], 0.0, com[2]), (*inertia[:3], 0.0, inertia[4], 0.0))
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(robot_model, "BASE_INERTIAL", symmetric)
        env = make_training_env(cfg, terrain_map=_terrain_and_its_mirror_image(cfg))
    mirror = env.mirror
    one = jax.tree.map(lambda x: x[0], jax.jit(env.reset)(jax.random.PRNGKey(0)[None]))
    qvel = 0.3 * jax.random.normal(jax.random.PRNGKey(9), (18,))  # and 0.4 m/s up
    one = one.replace(pipeline_state=one.pipeline_state.replace(qvel=qvel.at[2].add(0.4)))
    both = jax.tree.map(lambda a, b: jp.stack([a, b]), one, _mirror_state(env.env, mirror, one))
    actions = 0.5 * jax.random.normal(jax.random.PRNGKey(5), (AIR_STEPS, 12))
    actions = jp.stack([actions, sym.ACTION(actions)], axis=1)  # (T, 2, 12)

    def body(s, a):
        s = env.step(s, a)
        return s, (s.obs, s.done)

    _, (obs, done) = jax.jit(lambda s, a: jax.lax.scan(body, s, a))(both, actions)
    assert not np.any(np.asarray(done))
    obs = {k: np.asarray(v) for k, v in obs.items()}
    return mirror, {k: v[:, 0] for k, v in obs.items()}, {k: v[:, 1] for k, v in obs.items()}


def _blocks(key: str):
    """(name, start, stop) of each block of the fixture's observation ``key``."""
    base = [(n, a, b) for n, a, b, _ in obs_lib.actor_obs_layout(4, 16)]
    if key == "state":
        return base + [("foot_patches", 181, 217), ("base_scan", 217, 334),
                       ("seen_patches", 334, 370), ("seen_scan", 370, 487)]  # fmt: skip
    return base + [("foot_patches", 181, 217), ("contacts", 217, 221), ("friction_mass", 221, 223),
                   ("height_scan", 223, 394)]  # fmt: skip


def test_mujoco_mirror_image_observes_the_mirrored_observations(mirrored_rollout):
    """Actor (the ToF student's 181 inputs first), teacher and critic: the mirror image's
    observation at every step equals the map of the robot's."""
    mirror, a, b = mirrored_rollout
    for key in ("state", "privileged_state"):
        err = np.abs(mirror.obs[key](a[key]) - b[key])
        worst = {n: float(err[:, s:e].max()) for n, s, e in _blocks(key)}
        assert max(worst.values()) < TOL, (key, worst)


def test_mujoco_oracle_catches_every_broken_map(mirrored_rollout):
    """The comparison above fails for any block whose map is replaced by the identity (except
    the ToF validity and the friction/mass, the same on both sides in this rollout), and for any
    single sign dropped (HAA of each leg in joints, joint velocities and last action; the y of
    gravity, velocity and goal direction; the x and z of the angular velocity)."""
    mirror, a, b = mirrored_rollout
    same_both_sides = {"tof_valid", "friction_mass"}
    for key in ("state", "privileged_state"):
        m = mirror.obs[key]
        for name, s, e in _blocks(key):
            if name in same_both_sides:
                continue
            broken = m(a[key]).copy()
            broken[:, s:e] = a[key][:, s:e]  # this block not mirrored
            assert np.abs(broken - b[key]).max() > 100 * TOL, (key, name)
        for i in np.flatnonzero(m.sign < 0):
            dropped = m(a[key]).copy()
            dropped[:, i] = -dropped[:, i]  # entry i's sign dropped (no longer an involution)
            assert np.abs(dropped - b[key]).max() > 100 * TOL, (key, i)


# --------------------------------------------------------------------------- PPO and DAgger
def _digest(tree) -> str:
    h = hashlib.sha256()
    for x in jax.tree.leaves(jax.device_get(tree)):
        h.update(np.ascontiguousarray(np.asarray(x)).tobytes())
    return h.hexdigest()[:16]


def test_flag_off_training_is_bit_identical_to_before_the_flag():
    """Params, optimizer and normalizer after 2 iterations on the cue task: digests recorded with
    the trainer before ppo.symmetry existed (commit 764808b's foottof/ppo, XLA's CPU backend at
    conftest's optimization level 1; a JAX upgrade may change them: re-record them there)."""
    if "xla_backend_optimization_level=1" not in os.environ.get("XLA_FLAGS", ""):
        pytest.skip("digests recorded at XLA's CPU optimization level 1 (tests/conftest.py)")
    expected = {
        False: ("bbda7426c2270dfe", "b204b016307b589c", "07108ece3ebe4088"),
        True: ("2e508d4d05fce6aa", "6d1da669b6ce7b3c", "1960e970a2b62c84"),
    }
    for privileged, want in expected.items():
        env = toy_envs.make_memory_env(privileged=privileged)
        trainer = train_lib.make_train(env, small_cfg(num_envs=16, num_steps=8, num_epochs=2))
        state = trainer.init(jax.random.PRNGKey(3))
        assert state.mirror_carry is None
        for _ in range(2):
            state, _ = trainer.iteration(state)
        got = (_digest(state.params), _digest(state.opt_state), _digest(state.normalizer))
        assert got == want, privileged


def _fresh_mirrored_carry(networks, params, normalizer, traj, mirror, n):
    """Per env: the policy run from a fresh carry over the mirrored observations from the
    latest episode start in the rollout to its end (no resets in between): its carry."""
    resets = np.asarray(traj.resets)
    out = []
    for i in range(n):
        start = int(np.flatnonzero(resets[:, i]).max())
        carry = networks.init_carry(1)
        for t in range(start, resets.shape[0]):
            obs = jax.tree.map(lambda x, t=t, i=i: x[t, i : i + 1], traj.obs)
            carry = networks.step(params, normalizer, carry, mirror.observation(obs),
                                  jp.zeros((1,), bool))[0]  # fmt: skip
        out.append(carry)
    return jax.tree.map(lambda *xs: jp.concatenate(xs), *out)


def test_rollout_tracks_the_carry_of_the_mirrored_episode():
    """With ppo.symmetry, the carry the rollout keeps for the mirrored sequences equals a fresh
    run of the policy over the mirrored observations from each episode's start (episodes of 8
    steps, a rollout of 13: every env starts one inside it)."""
    env = toy_envs.make_memory_env(privileged=True)
    trainer = train_lib.make_train(env, small_cfg(num_envs=8, num_steps=13, symmetry=True))
    state = trainer.init(jax.random.PRNGKey(0))
    state, _ = trainer.iteration(state)  # a trained policy, mid-episode carries
    mirror = env.mirror
    carry, traj, _ = train_lib.rollout(
        env, trainer.networks, state, jax.random.PRNGKey(1), 13, mirror
    )
    want = _fresh_mirrored_carry(trainer.networks, state.params, state.normalizer, traj, mirror, 8)
    jax.tree.map(lambda x, y: np.testing.assert_allclose(x, y, atol=1e-6), carry[5], want)
    policy = jax.tree.leaves(carry[1])[0]
    assert np.abs(np.asarray(jax.tree.leaves(carry[5])[0]) - np.asarray(policy)).max() > 1e-3


def test_symmetric_update_is_the_update_on_the_batch_with_its_mirrored_sequences():
    """One epoch, one minibatch, fixed rate: the update with ppo.symmetry on a rollout of N
    envs gives the params of the plain update on 2 N envs, the N sequences followed by their
    mirror images (mirrored observations and actions, the tracked mirrored carry, the same
    rewards, values and dones: advantages and returns equal the originals')."""
    env = toy_envs.make_memory_env(privileged=True)
    kw = dict(num_steps=13, num_epochs=1, num_minibatches=1, lr_schedule="fixed")
    on = train_lib.make_train(env, small_cfg(num_envs=8, symmetry=True, **kw))
    state = on.init(jax.random.PRNGKey(0))
    state, _ = on.iteration(state)
    mirror = env.mirror
    start_mirror = state.mirror_carry
    carry, traj, last_value = train_lib.rollout(
        env, on.networks, state, jax.random.PRNGKey(1), 13, mirror
    )
    batch = train_lib.Batch(traj, state.carry, last_value, start_mirror)
    args = (state.params, state.opt_state, state.normalizer)
    p_on = on.update(*args, batch, jax.random.PRNGKey(2))[0]

    off = train_lib.make_train(env, small_cfg(num_envs=16, **kw))
    cat = lambda x, y: jp.concatenate([x, y], axis=1)  # noqa: E731
    twice = jax.tree.map(lambda x: cat(x, x), traj)
    doubled = twice._replace(
        obs=jax.tree.map(cat, traj.obs, mirror.observation(traj.obs)),
        actions=cat(traj.actions, mirror.action(traj.actions)),
        means=cat(traj.means, mirror.action(traj.means)),
    )
    batch2 = train_lib.Batch(
        doubled,
        jax.tree.map(lambda x, y: jp.concatenate([x, y]), state.carry, start_mirror),
        jp.concatenate([last_value, last_value]),
    )
    p_off = off.update(*args, batch2, jax.random.PRNGKey(2))[0]
    jax.tree.map(lambda x, y: np.testing.assert_allclose(x, y, rtol=2e-5, atol=2e-6), p_on, p_off)
    p_plain = off.update(
        *args,
        train_lib.Batch(
            twice, jax.tree.map(lambda x: jp.concatenate([x, x]), state.carry), batch2.last_value
        ),
        jax.random.PRNGKey(2),
    )[0]
    assert not tree_equal(p_plain, p_off)  # the mirrored half matters


def test_augmented_minibatch_holds_the_mirrored_sequences_and_the_originals_targets():
    n, t = 4, 5
    mirror = toy_envs.CueMemoryEnv(privileged=True).mirror
    k = iter(jax.random.split(jax.random.PRNGKey(0), 12))
    r = lambda *shape: jax.random.normal(next(k), shape)  # noqa: E731
    mb = losses.Minibatch(
        carry=(r(n, 3),), obs={"state": r(t, n, 2), "privileged_state": r(t, n, 3)},
        resets=jp.zeros((t, n), bool).at[0].set(True), actions=r(t, n, 1), log_probs=r(t, n),
        means=r(t, n, 1), log_std=r(1), values=r(t, n), advantages=r(t, n), returns=r(t, n),
        mirror_carry=(r(n, 3),),
    )  # fmt: skip
    aug = ppo_sym.augment(mb, mirror)
    for f in ("resets", "log_probs", "values", "advantages", "returns"):
        np.testing.assert_array_equal(getattr(aug, f), jp.concatenate([getattr(mb, f)] * 2, 1))
    np.testing.assert_array_equal(aug.actions[:, n:], -mb.actions)
    np.testing.assert_array_equal(aug.obs["state"][:, n:], mb.obs["state"] * jp.array([-1.0, 1]))
    np.testing.assert_array_equal(aug.carry[0][n:], mb.mirror_carry[0])
    np.testing.assert_array_equal(aug.obs["privileged_state"][:, :n], mb.obs["privileged_state"])


def test_symmetric_run_checkpoints_its_mirrored_carry(tmp_path):
    env = toy_envs.make_memory_env(privileged=True)
    trainer = train_lib.make_train(env, small_cfg(num_envs=8, num_steps=8, symmetry=True))
    state, _ = trainer.iteration(trainer.init(jax.random.PRNGKey(0)))
    saver = ckpt.Checkpointer(str(tmp_path))
    saver.save(state)
    target = trainer.init(jax.random.PRNGKey(1))
    restored, _ = saver.restore(target)
    saver.close()
    assert tree_equal(jax.device_get(restored.mirror_carry), jax.device_get(state.mirror_carry))
    assert not tree_equal(jax.device_get(target.mirror_carry), jax.device_get(state.mirror_carry))


def test_dagger_batch_holds_mirrored_sequences_labelled_with_the_mirrored_teacher_action():
    tenv = toy_envs.make_memory_env(8, teacher=True)
    tcfg = small_cfg(policy="mlp", num_envs=8, num_steps=8)
    ttrain = train_lib.make_train(tenv, tcfg)
    tstate = ttrain.init(jax.random.PRNGKey(0))
    denv = distill.TeacherEnv(tenv, (ttrain.networks, tstate.params, tstate.normalizer), 2)
    cfg = small_cfg(num_envs=8, num_steps=8, symmetry=True)
    cfg.train.teacher = "toy"
    strain = train_lib.make_train(denv, cfg)
    state = strain.init(jax.random.PRNGKey(1))
    carry, traj, _ = train_lib.rollout(
        denv, strain.networks, state, jax.random.PRNGKey(2), 8, denv.mirror
    )
    mb = losses.Minibatch(
        carry=state.carry, obs=traj.obs, resets=traj.resets, actions=traj.actions,
        log_probs=traj.log_probs, means=traj.means, log_std=jp.zeros(1), values=traj.values,
        advantages=traj.values, returns=traj.values, mirror_carry=state.mirror_carry,
    )  # fmt: skip
    aug = ppo_sym.augment(mb, denv.mirror)
    label = traj.obs[distill.TEACHER_ACTION_KEY]
    np.testing.assert_array_equal(aug.obs[distill.TEACHER_ACTION_KEY][:, 8:], -label)
    student = aug.obs["state"][:, 8:]
    np.testing.assert_array_equal(student, traj.obs["state"] * jp.array([-1.0, 1.0]))
    state, metrics = strain.iteration(state)  # the imitation loss over both halves
    assert np.isfinite(float(metrics["loss/imitation"])) and state.mirror_carry is not None
