"""Distillation (foottof.ppo.distill) on the toy memory task: a teacher that sees the cue at every
step, a student that must remember it; resume; export of the student."""

import json

import jax
import jax.numpy as jp
import numpy as np
import pytest
import toy_envs
from helpers import small_cfg, tiny_cfg, tree_equal

from foottof.ppo import distill, export, runner, teacher
from foottof.ppo import train as train_lib

EPISODE = 8  # steps; steps 1..7 are rewarded


def _greedy_reward(env, networks, params, normalizer, key, n_envs=256, steps=4 * EPISODE):
    """Mean reward per step of the deterministic policy (action means) over n_envs x steps."""
    act = jax.jit(networks.policy_fn(params, normalizer, deterministic=True))
    step = jax.jit(env.step)
    state = jax.jit(env.reset)(jax.random.split(key, n_envs))
    carry, reset, total = networks.init_carry(n_envs), jp.ones((n_envs,), bool), 0.0
    for _ in range(steps):
        carry, action = act(carry, state.obs, reset, None)
        state = step(state, action)
        reset = state.done.astype(bool)
        total += float(jp.mean(state.reward))
    return total / steps


@pytest.fixture(scope="module")
def teacher_and_student():
    # Teacher: a memoryless MLP trained by PPO on the teacher view (it sees the cue every step).
    tenv = toy_envs.make_memory_env(EPISODE, teacher=True)
    ttrain = train_lib.make_train(tenv, small_cfg("mlp"))
    tstate = ttrain.init(jax.random.PRNGKey(0))
    for _ in range(30):
        tstate, _ = ttrain.iteration(tstate)
    teacher = (ttrain.networks, tstate.params, tstate.normalizer)
    # Student: an LSTM reading the first 2 inputs (cue at t = 0 only), distilled by DAgger.
    denv = distill.TeacherEnv(tenv, teacher, student_obs_size=2)
    cfg = small_cfg("lstm", lr_schedule="fixed", learning_rate=3e-3)
    cfg.train.teacher = "toy"
    strain = train_lib.make_train(denv, cfg)
    sstate = strain.init(jax.random.PRNGKey(1))
    history = []
    for _ in range(30):
        sstate, m = strain.iteration(sstate)
        history.append({k: float(v) for k, v in m.items()})
    return tenv, denv, teacher, strain, sstate, history


def test_distilled_student_reaches_its_teacher(teacher_and_student):
    """Bound: the reward -|clip(a) - c| is 1-Lipschitz in a, so per rewarded step the student
    loses at most |a_s - a_t| to its teacher, on average <= sqrt(E (a_s - a_t)^2) = sqrt(loss)
    (Cauchy-Schwarz); the toy's observations do not depend on the actions, so the training
    rollouts' imitation loss holds on the evaluation's states. With 7 of 8 steps rewarded:
    r_student >= r_teacher - 7/8 sqrt(loss) (+ 0.02 for the evaluation's other cue draws)."""
    tenv, denv, teacher, strain, sstate, history = teacher_and_student
    key = jax.random.PRNGKey(11)
    r_teacher = _greedy_reward(tenv, *teacher, key)
    r_student = _greedy_reward(denv, strain.networks, sstate.params, sstate.normalizer, key)
    loss = history[-1]["loss/imitation"]
    assert r_teacher > -0.2, r_teacher  # the teacher solved its (memoryless) task
    assert history[0]["loss/imitation"] > 10 * loss and loss < 0.01, (history[0], loss)
    assert r_student >= r_teacher - 7 / 8 * np.sqrt(loss) - 0.02, (r_student, r_teacher, loss)
    assert r_student > -0.3  # a memoryless student earns <= -7/8: the cue was remembered
    assert all(h["ppo/params_finite"] == 1.0 for h in history)


def _mlp_teacher_action(params, normalizer, x) -> np.ndarray:
    """The MLP teacher's action mean worked out in NumPy (float64) from its parameters, not
    through the networks module: the actor input normalized by the running mean and std, then
    Dense -> elu per hidden layer and the linear 'out' layer."""
    actor = jax.tree.map(lambda v: np.asarray(v, np.float64), params["params"]["actor"])
    mean, std = (np.asarray(v["state"], np.float64) for v in (normalizer.mean, normalizer.std))
    h = (np.asarray(x, np.float64) - mean) / std
    for i in range(len(actor) - 1):
        h = h @ actor[f"dense_{i}"]["kernel"] + actor[f"dense_{i}"]["bias"]
        h = np.where(h > 0.0, h, np.expm1(h))  # elu
    return h @ actor["out"]["kernel"] + actor["out"]["bias"]


def test_teacher_env_shows_the_student_its_inputs_only(teacher_and_student):
    """The student sees the first 2 inputs; the teacher's action in the observation is its MLP
    on all 3, worked out in NumPy, at reset and after a step; the wrapped env steps like the
    plain one."""
    tenv, denv, teacher, *_ = teacher_and_student
    _, params, norm = teacher
    assert small_cfg("mlp").network.activation == "elu"  # what _mlp_teacher_action applies
    # the first-step flag (1 step in 8) has std ~0.33: the oracle's normalization matters
    assert abs(float(norm.std["state"][1]) - 1.0) > 0.5, norm.std
    state = denv.reset(jax.random.split(jax.random.PRNGKey(2), 4))
    plain = tenv.reset(jax.random.split(jax.random.PRNGKey(2), 4))
    a = jp.ones((4, 1))
    for wrapped, full in ((state, plain), (denv.step(state, a), tenv.step(plain, a))):
        np.testing.assert_array_equal(wrapped.obs["state"], full.obs["state"][:, :2])
        np.testing.assert_array_equal(wrapped.obs[distill.TEACHER_OBS_KEY], full.obs["state"])
        want = _mlp_teacher_action(params, norm, full.obs["state"])
        np.testing.assert_allclose(wrapped.obs[distill.TEACHER_ACTION_KEY], want, atol=1e-5)
        np.testing.assert_array_equal(wrapped.reward, full.reward)  # same cues, rewards
        np.testing.assert_array_equal(wrapped.done, full.done)


@pytest.mark.parametrize("obs_skip", [False, True])
def test_student_cut_from_teacher_acts_as_teacher_without_its_extra_inputs(obs_skip):
    """student_from_teacher: an LSTM student of the teacher's size starts as the teacher with
    the extra inputs' weights dropped, so on observations whose extra inputs are at their
    normalizer mean (normalized to 0) both act alike; an MLP teacher gives None. With
    network.obs_skip (the wide teacher) the heads' first kernels read [h, obs] too: their extra
    observation rows are the last ones, and the cut drops exactly those."""
    tenv = toy_envs.make_memory_env(EPISODE, teacher=True)
    cfg = small_cfg("lstm")
    cfg.network.obs_skip = obs_skip
    ttrain = train_lib.make_train(tenv, cfg)
    tstate = ttrain.init(jax.random.PRNGKey(0))
    tstate, _ = ttrain.iteration(tstate)
    denv = distill.TeacherEnv(tenv, (ttrain.networks, tstate.params, tstate.normalizer), 2)
    strain = train_lib.make_train(denv, cfg)
    s0 = strain.init(jax.random.PRNGKey(1))
    params, norm = distill.student_from_teacher(
        s0.params, s0.normalizer, tstate.params, tstate.normalizer
    )
    obs = {"state": jp.array([[0.5, 1.0]]), "privileged_state": jp.array([[0.5, 1.0, 0.3]])}
    full = dict(obs, state=jp.array([[0.5, 1.0, float(tstate.normalizer.mean["state"][2])]]))
    reset = jp.ones((1,), bool)
    _, m_s, _, v_s = strain.networks.step(params, norm, strain.networks.init_carry(1), obs, reset)
    _, m_t, _, v_t = ttrain.networks.step(
        tstate.params, tstate.normalizer, ttrain.networks.init_carry(1), full, reset
    )
    np.testing.assert_allclose(m_s, m_t, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(v_s, v_t, rtol=1e-5, atol=1e-6)  # the critic is the teacher's
    mlp = train_lib.make_train(tenv, small_cfg("mlp")).init(jax.random.PRNGKey(0))
    assert (
        distill.student_from_teacher(s0.params, s0.normalizer, mlp.params, mlp.normalizer) is None
    )


def test_distillation_resume_is_bit_exact(teacher_and_student, tmp_path):
    tenv, _, teacher, *_ = teacher_and_student
    denv = distill.TeacherEnv(tenv, teacher, student_obs_size=2)

    def cfg(n):
        c = tiny_cfg(num_iterations=n, teacher="toy")
        c.ppo.lr_schedule = "fixed"
        return c

    straight = runner.run(cfg(4), denv, str(tmp_path / "a"))
    runner.run(cfg(2), denv, str(tmp_path / "b"))
    resumed = runner.run(cfg(4), denv, str(tmp_path / "b"), resume=True)
    assert int(resumed.iteration) == 4
    assert tree_equal(jax.device_get(straight), jax.device_get(resumed))  # teacher carry too
    assert distill.TEACHER_CARRY_KEY in resumed.env_state.info
    header = (tmp_path / "b" / "metrics.csv").read_text().splitlines()[0]
    assert "loss/imitation" in header
    assert json.loads((tmp_path / "b" / "config.json").read_text())["train"]["teacher"] == "toy"


def test_student_export_equals_its_jax_actor(teacher_and_student, tmp_path):
    """The distilled student is an ordinary policy: its NumPy export reads the student's inputs
    and acts as the JAX actor over two episodes."""
    _, denv, _, strain, sstate, _ = teacher_and_student
    nets = strain.networks
    path = export.export_policy(str(tmp_path / "student"), nets, sstate.params, sstate.normalizer)
    policy = export.NumpyPolicy(path)
    act = jax.jit(nets.policy_fn(sstate.params, sstate.normalizer, deterministic=True))
    state = denv.reset(jax.random.PRNGKey(5)[None])
    carry, reset = nets.init_carry(1), jp.ones((1,), bool)
    for _ in range(2 * EPISODE):
        carry, action = act(carry, state.obs, reset, None)
        if bool(reset[0]):
            policy.reset()
        np.testing.assert_allclose(policy(np.asarray(state.obs["state"][0])), action[0], atol=1e-5)
        state = denv.step(state, action)
        reset = state.done.astype(bool)


def test_teacher_of_another_layout_is_one_clear_error(tmp_path):
    """A teacher trained without the privileged inputs (2 actor inputs) for an env that gives 3."""
    tenv = toy_envs.make_memory_env(EPISODE, privileged=True)  # actor: 2 inputs
    runner.run(tiny_cfg(num_iterations=1), tenv, str(tmp_path / "t"))
    with pytest.raises(ValueError, match=r"train.teacher=.*does not fit.*3 actor inputs"):
        teacher.load_teacher(
            str(tmp_path / "t"), toy_envs.make_memory_env(EPISODE, teacher=True), tiny_cfg().network
        )


def test_student_view_size_counts_the_privileged_inputs_it_is_given():
    """The ToF student reads the teacher's inputs minus the 153 terrain inputs that
    env.actor_terrain appends (hand count: 36 foot patches + 117 scan points), plus the first N of
    them for the train.student_privileged_inputs diagnostic; N outside [0, 153] is one error."""
    n = 181 + 36 + 117  # the teacher's actor inputs for 4 sensors x 16 zones
    assert teacher.student_view_size(n) == 181
    assert teacher.student_view_size(n, 36) == 181 + 36
    assert teacher.student_view_size(n, 153) == n
    for bad in (-1, 154):
        with pytest.raises(
            ValueError, match=rf"student_privileged_inputs={bad} must be in \[0, 153\]"
        ):
            teacher.student_view_size(n, bad)


def test_belief_decoder_learns_the_privileged_input_the_student_remembers(teacher_and_student):
    """network.reconstruct = 1 on the toy: the decoder on the student's memory is trained to
    output the teacher's extra input (the cue, +-1, shown to the student at step 0 only). A
    memoryless decoder's best mean squared error is 7/8 (the cue's variance 1 at 7 of 8 steps);
    one reading the memory that recalls the cue gets near 0. The decoder leaves the actions and
    the cut from the teacher as without it (its own leaves keep their init)."""
    tenv, _, teacher, *_ = teacher_and_student
    obs = {"state": jp.zeros((2, 2)), distill.TEACHER_OBS_KEY: jp.array([[1.0, 2, 3], [4, 5, 6]])}
    np.testing.assert_array_equal(distill.reconstruction_target(obs, 1), [[3.0], [6.0]])
    denv = distill.TeacherEnv(tenv, teacher, student_obs_size=2)
    cfg = small_cfg("lstm", lr_schedule="fixed", learning_rate=3e-3)
    cfg.train.teacher = "toy"
    cfg.network.reconstruct = 1
    strain = train_lib.make_train(denv, cfg)
    state = strain.init(jax.random.PRNGKey(1))
    assert set(state.params["params"]["decoder"]) == {"dense_0", "out"}
    history = []
    for _ in range(30):
        state, m = strain.iteration(state)
        history.append({k: float(v) for k, v in m.items()})
    rec = [h["loss/reconstruction"] for h in history]
    assert rec[0] > 0.5 and np.mean(rec[-5:]) < 0.1, rec
    for h in history:
        want = h["loss/imitation"] + 0.5 * h["loss/reconstruction"]
        assert h["loss/policy"] == pytest.approx(want, rel=1e-5)
    # the actions are the plain unroll's
    s = jax.jit(denv.reset)(jax.random.split(jax.random.PRNGKey(3), 4))
    seq = jax.tree.map(lambda x: jp.stack([x] * 3), s.obs)
    resets = jp.array([[True] * 4, [False] * 4, [False] * 4])
    nets, carry = strain.networks, strain.networks.init_carry(4)
    means, recon = nets.unroll_reconstruction(state.params, state.normalizer, carry, seq, resets)
    plain, _, _ = nets.unroll(state.params, state.normalizer, carry, seq, resets)
    np.testing.assert_allclose(means, plain, rtol=1e-6)
    assert recon.shape == (3, 4, 1)
    # cut from an LSTM teacher of the same size: the decoder keeps its init, the rest is cut
    tcfg = small_cfg("lstm")
    ttrain = train_lib.make_train(tenv, tcfg)
    tstate = ttrain.init(jax.random.PRNGKey(0))
    s0 = strain.init(jax.random.PRNGKey(1))
    params, _ = distill.student_from_teacher(
        s0.params, s0.normalizer, tstate.params, tstate.normalizer
    )
    assert tree_equal(params["params"]["decoder"], s0.params["params"]["decoder"])
    assert tree_equal(params["params"]["actor"], tstate.params["params"]["actor"])


@pytest.mark.integration
def test_resumed_student_refuses_a_teacher_that_trained_on(tmp_path):
    """teacher.json pins the teacher of a distillation run: a resume whose train.teacher folder
    now holds a later checkpoint is one clear error; the pinned checkpoint, or
    train.teacher_change_ok, goes on (the change is recorded)."""
    tenv = toy_envs.make_memory_env(EPISODE, teacher=True)
    t_dir, s_dir = str(tmp_path / "t"), str(tmp_path / "s")
    runner.run(tiny_cfg(num_iterations=1), tenv, t_dir)

    def fp(path):
        _, params, norm = teacher.load_teacher(path, tenv, tiny_cfg().network)
        return teacher.teacher_fingerprint(params, norm)

    first = fp(t_dir)
    assert fp(t_dir + "/checkpoints/1") == first  # a step folder reads the same checkpoint
    rec = teacher.check_teacher_record(s_dir, t_dir, first, resume=False)
    assert rec == {"teacher": t_dir, "step": 1, "fingerprint": first, "from_iteration": 0}
    assert json.loads((tmp_path / "s" / "teacher.json").read_text()) == rec
    assert teacher.check_teacher_record(s_dir, t_dir, first, resume=True) == rec

    runner.run(tiny_cfg(num_iterations=2), tenv, t_dir, resume=True)  # the teacher trains on
    later = fp(t_dir)
    assert later != first
    with pytest.raises(ValueError, match=r"now checkpoint 2 .* distilled from .* checkpoint 1"):
        teacher.check_teacher_record(s_dir, t_dir, later, resume=True)
    pinned = t_dir + "/checkpoints/1"
    assert teacher.check_teacher_record(s_dir, pinned, fp(pinned), resume=True) == rec
    moved = teacher.check_teacher_record(s_dir, t_dir, later, resume=True, change_ok=True)
    assert (moved["step"], moved["fingerprint"]) == (2, later)
    assert moved["previous"][0]["fingerprint"] == first
    assert json.loads((tmp_path / "s" / "teacher.json").read_text()) == moved


@pytest.mark.integration
def test_runner_pins_the_teacher_and_a_failed_new_run_leaves_no_folder(tmp_path):
    """runner.run itself records teacher.json for a TeacherEnv (train.py and a notebook alike)
    and refuses a resume that steps with another teacher; a new run that fails before its first
    checkpoint removes its folder, record and all."""
    tenv = toy_envs.make_memory_env(EPISODE, teacher=True)
    t_dir = str(tmp_path / "t")
    runner.run(tiny_cfg(num_iterations=2), tenv, t_dir)
    cfg = tiny_cfg(num_iterations=1)
    cfg.train.teacher = t_dir

    def student_env(path, shift=0.0):
        nets, params, norm = teacher.load_teacher(path, tenv, cfg.network)
        return distill.TeacherEnv(tenv, (nets, jax.tree.map(lambda x: x + shift, params), norm), 2)

    link, failed = str(tmp_path / "latest"), str(tmp_path / "failed")
    with pytest.raises(FileNotFoundError):
        runner.run(
            cfg, student_env(t_dir), failed, init_from=str(tmp_path / "no"), latest_link=link
        )
    assert not (tmp_path / "failed").exists()
    s_dir = str(tmp_path / "s")
    runner.run(cfg, student_env(t_dir), s_dir)
    rec = json.loads((tmp_path / "s" / "teacher.json").read_text())
    assert (rec["teacher"], rec["step"], rec["from_iteration"]) == (t_dir, 2, 0)
    cfg.train.num_iterations = 2
    with pytest.raises(ValueError, match=r"now checkpoint 2 .* distilled from .* checkpoint 2"):
        runner.run(cfg, student_env(t_dir, shift=1e-3), s_dir, resume=True)  # other params
