"""Tests of the LSTM PPO trainer: GAE, memory task, Brax env, checkpoints, resume, export."""

import csv
import os
import re
import warnings

import jax
import jax.numpy as jp
import numpy as np
import pytest
import toy_envs
from brax.envs.base import State
from helpers import small_cfg, tiny_cfg, tree_equal

from configs import _ppo
from foottof.ppo import export, losses, runner
from foottof.ppo import networks as net
from foottof.ppo import train as train_lib
from foottof.ppo.storage import checkpoint as ckpt


def train_history(env, cfg, iterations: int):
    trainer = train_lib.make_train(env, cfg)
    state = trainer.init(jax.random.PRNGKey(0))
    history = []
    for _ in range(iterations):
        state, metrics = trainer.iteration(state)
        history.append({k: float(v) for k, v in metrics.items()})
    return trainer, state, history


# ------------------------------------------------------------------------------------- losses
def test_gae_hand_computed():
    # gamma = lam = 0.5, so gamma * lam = 0.25. Two envs, T = 4.
    # Env 0: truncation at t=1 (done=1, truncation=1): r_1 <- 2 + 0.5 * V_1 * 1 = 2.5.
    #   r = [1, 2.5, 0, 1], V = [0.5, 1, 2, 1], V_T = 4.
    #   delta_3 = 1 + 0.5*4 - 1 = 2;  delta_2 = 0 + 0.5*1 - 2 = -1.5;
    #   delta_1 = 2.5 - 1 = 1.5 (done: no next value);  delta_0 = 1 + 0.5*1 - 0.5 = 1.
    #   A_3 = 2; A_2 = -1.5 + 0.25*2 = -1; A_1 = 1.5 (done cuts); A_0 = 1 + 0.25*1.5 = 1.375.
    #   returns = A + V = [1.875, 2.5, 1, 3].
    # Env 1: termination at t=2 (done=1, truncation=0):
    #   r = [0, 1, 3, 2], V = [1, 2, 1, 0.5], V_T = 2.
    #   delta_3 = 2 + 0.5*2 - 0.5 = 2.5; delta_2 = 3 - 1 = 2; delta_1 = 1 + 0.5*1 - 2 = -0.5;
    #   delta_0 = 0 + 0.5*2 - 1 = 0.  A = [0 + 0.25*0, -0.5 + 0.25*2, 2, 2.5] = [0, 0, 2, 2.5].
    #   returns = [1, 2, 3, 3].
    rewards = jp.array([[1.0, 0.0], [2.0, 1.0], [0.0, 3.0], [1.0, 2.0]])
    values = jp.array([[0.5, 1.0], [1.0, 2.0], [2.0, 1.0], [1.0, 0.5]])
    dones = jp.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    truncation = jp.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    last_value = jp.array([4.0, 2.0])
    r = losses.bootstrap_truncation(rewards, values, truncation, gamma=0.5)
    adv, ret = losses.compute_gae(r, values, dones, last_value, gamma=0.5, lam=0.5)
    np.testing.assert_allclose(adv[:, 0], [1.375, 1.5, -1.0, 2.0], rtol=1e-6)
    np.testing.assert_allclose(ret[:, 0], [1.875, 2.5, 1.0, 3.0], rtol=1e-6)
    np.testing.assert_allclose(adv[:, 1], [0.0, 0.0, 2.0, 2.5], atol=1e-6)
    np.testing.assert_allclose(ret[:, 1], [1.0, 2.0, 3.0, 3.0], rtol=1e-6)


def test_adaptive_learning_rate_rule():
    lr = lambda lr0, kl: float(train_lib.adapt_learning_rate(lr0, kl, 0.01, 1e-5, 1e-2))
    assert lr(1e-3, 0.03) == pytest.approx(1e-3 / 1.5)  # kl > 2 * desired
    assert lr(1e-3, 0.004) == pytest.approx(1.5e-3)  # 0 < kl < desired / 2
    assert lr(1e-3, 0.01) == pytest.approx(1e-3)  # in band
    assert lr(1e-3, 0.0) == pytest.approx(1e-3)  # kl == 0: rsl_rl leaves lr alone
    assert lr(1.2e-5, 0.05) == pytest.approx(1e-5)  # clamped below
    assert lr(8e-3, 0.001) == pytest.approx(1e-2)  # clamped above


def test_gaussian_helpers_against_jax_scipy():
    key_x, key_m, key_s = jax.random.split(jax.random.PRNGKey(3), 3)
    x = jax.random.normal(key_x, (5, 3))
    mean = jax.random.normal(key_m, (5, 3))
    log_std = 0.3 * jax.random.normal(key_s, (3,))
    ref = jax.scipy.stats.norm.logpdf(x, mean, jp.exp(log_std)).sum(-1)
    np.testing.assert_allclose(net.gaussian_log_prob(x, mean, log_std), ref, rtol=1e-5)
    # Entropy of N(0, s^2) per dim = 0.5 * log(2 pi e s^2).
    ref_h = jp.sum(0.5 * jp.log(2 * jp.pi * jp.e * jp.exp(2 * log_std)))
    np.testing.assert_allclose(net.gaussian_entropy(log_std), ref_h, rtol=1e-6)
    # KL(N(0,1) || N(1, 2^2)) = log 2 + (1 + 1) / 8 - 0.5 = 0.44314718.
    kl = net.gaussian_kl(jp.zeros(1), jp.ones(1), jp.ones(1), 2 * jp.ones(1))
    np.testing.assert_allclose(kl, np.log(2) + 0.25 - 0.5, rtol=1e-6)


def test_max_noise_std_caps_the_sampled_actions_and_the_logged_std():
    # Raw log std at log(1.0) (init_noise_std), cap 0.2: every action the trainer samples, the
    # behaviour std stored for the PPO ratio and the logged std must all be 0.2.
    env = toy_envs.make_memory_env()
    cfg = tiny_cfg()
    cfg.ppo.entropy_coef = 0.01  # pushes the raw std up: the cap must hold it
    cfg.network.init_noise_std = 1.0
    cfg.network.max_noise_std = 0.2
    trainer, state, history = train_history(env, cfg, 3)
    assert [round(h["ppo/action_std"], 6) for h in history] == [0.2, 0.2, 0.2]
    assert np.allclose(np.exp(state.params["params"]["log_std"]), 1.0)  # no gradient above the cap
    networks = trainer.networks
    obs = jax.tree.map(lambda v: jp.zeros((4096,) + v.shape[1:]), state.env_state.obs)
    act = networks.policy_fn(state.params, state.normalizer, deterministic=False)
    _, a = act(networks.init_carry(4096), obs, jp.ones((4096,), bool), jax.random.PRNGKey(1))
    _, m = networks.policy_fn(state.params, state.normalizer)(
        networks.init_carry(4096), obs, jp.ones((4096,), bool), None
    )
    np.testing.assert_allclose(np.std(np.asarray(a - m), axis=0), 0.2, rtol=0.06)
    cfg.network.max_noise_std = -0.1
    with pytest.raises(ValueError, match=r"network.max_noise_std=-0.1: must be a number >= 0"):
        train_lib.make_train(env, cfg)


# --------------------------------------------------------------------- iteration parts alone
def test_epoch_minibatches_hold_each_env_once_in_time_order():
    """train.epoch_minibatches alone: 8 envs x 3 steps into 4 minibatches of 2 envs; entry
    (t, n) of every field encodes 100 t + n, so each minibatch must hold whole env sequences."""
    t_steps, n_envs = 3, 8
    code = 100.0 * jp.arange(t_steps)[:, None] + jp.arange(n_envs)[None]  # (T, N)
    data = losses.Minibatch(
        carry=(jp.arange(n_envs, dtype=jp.float32)[:, None] * jp.ones((1, 5)),),  # (N, H)
        obs={"state": code[..., None] * jp.ones(2)},  # (T, N, 2)
        resets=code, actions=code[..., None], log_probs=code, means=code[..., None],
        log_std=jp.array([0.25]), values=code, advantages=code, returns=code,
    )  # fmt: skip
    mb = train_lib.epoch_minibatches(data, jax.random.PRNGKey(3), num_minibatches=4)
    assert mb.resets.shape == (4, t_steps, 2) and mb.obs["state"].shape == (4, t_steps, 2, 2)
    assert mb.carry[0].shape == (4, 2, 5) and mb.log_std.shape == (4, 1)
    envs = np.asarray(mb.resets[:, 0, :])  # (M, B): the env each column holds
    assert sorted(envs.ravel().tolist()) == list(range(n_envs))  # each env exactly once
    want = 100.0 * np.arange(t_steps)[None, :, None] + envs[:, None, :]  # whole sequences
    for field in (mb.resets, mb.log_probs, mb.values, mb.advantages, mb.returns):
        np.testing.assert_array_equal(np.asarray(field), want)
    np.testing.assert_array_equal(np.asarray(mb.obs["state"][..., 1]), want)
    np.testing.assert_array_equal(np.asarray(mb.carry[0][..., 0]), envs)  # carry of the same env
    np.testing.assert_array_equal(np.asarray(mb.log_std), 0.25)
    other = train_lib.epoch_minibatches(data, jax.random.PRNGKey(4), num_minibatches=4)
    assert not np.array_equal(np.asarray(other.resets), np.asarray(mb.resets))  # a new shuffle


def test_rollout_alone_books_episodes():
    """train.rollout alone (no mesh, no jit) on the cue task, episodes of 3 steps over 7 steps:
    dones at t = 2 and 5, carry resets at t = 0 (fresh state), 3 and 6, each finished episode's
    length 3 and return the sum of its rewards, and 1 step of the running episode left over."""
    env = toy_envs.make_memory_env(episode_length=3)
    trainer = train_lib.make_train(env, tiny_cfg())
    state = trainer.init(jax.random.PRNGKey(0))
    carry, traj, last_value = train_lib.rollout(
        env, trainer.networks, state, jax.random.PRNGKey(1), num_steps=7
    )
    dones, resets = np.asarray(traj.dones), np.asarray(traj.resets)
    assert dones.shape == (7, 8) and last_value.shape == (8,)
    np.testing.assert_array_equal(dones, np.isin(np.arange(7), (2, 5))[:, None] * np.ones(8))
    np.testing.assert_array_equal(resets, np.isin(np.arange(7), (0, 3, 6))[:, None] * np.ones(8))
    rewards = np.asarray(traj.rewards)
    np.testing.assert_array_equal(np.asarray(traj.finished_length), 3.0 * dones)
    np.testing.assert_allclose(traj.finished_return[2], rewards[0:3].sum(0), rtol=1e-6)
    np.testing.assert_allclose(traj.finished_return[5], rewards[3:6].sum(0), rtol=1e-6)
    env_state, _, prev_done, ep_return, ep_length = carry
    np.testing.assert_array_equal(np.asarray(ep_length), 1.0)
    np.testing.assert_allclose(ep_return, rewards[6], rtol=1e-6)
    assert not np.asarray(prev_done).any()


# -------------------------------------------------------------------------------- memory task
@pytest.fixture(scope="module")
def lstm_memory_run():
    # Privileged (dict) observations: the critic also sees the cue, the actor only at t = 0.
    env = toy_envs.make_memory_env(episode_length=8, privileged=True)
    return env, *train_history(env, small_cfg("lstm"), 40)


def test_memory_task_solved_by_lstm_not_by_mlp(lstm_memory_run):
    # Mean reward per step over all 8 steps: recall earns ~0, any memoryless policy <= -7/8.
    _, _, _, lstm_hist = lstm_memory_run
    env = toy_envs.make_memory_env(episode_length=8, privileged=True)
    _, _, mlp_hist = train_history(env, small_cfg("mlp"), 40)
    lstm_final = np.mean([h["train/reward"] for h in lstm_hist[-5:]])
    mlp_final = np.mean([h["train/reward"] for h in mlp_hist[-5:]])
    assert lstm_hist[0]["train/reward"] < -0.7
    assert lstm_final > -0.3, lstm_final
    assert mlp_final < -0.7, mlp_final
    assert np.mean([h["episode/success"] for h in lstm_hist[-5:]]) > 0.9
    for h in lstm_hist:
        assert h["ppo/params_finite"] == 1.0
        assert 1e-5 <= h["ppo/learning_rate"] <= 1e-2
        assert h["train/episode_length"] == 8.0  # every finished episode has 8 steps


def test_episode_metrics_match_env(lstm_memory_run):
    # 64 envs x 16 steps with episodes of 8 steps: exactly 128 episodes end per rollout.
    _, _, _, hist = lstm_memory_run
    assert all(h["train/episodes"] == 128 for h in hist)
    # reward/recall is the step reward averaged over all steps = train/reward.
    for h in hist:
        assert h["reward/recall"] == pytest.approx(h["train/reward"], rel=1e-5)
        assert h["train/episode_return"] == pytest.approx(8 * h["train/reward"], rel=1e-4)


# ----------------------------------------------------------------------------------- export
def test_export_numpy_policy_matches_jax(lstm_memory_run, tmp_path):
    env, trainer, state, _ = lstm_memory_run
    networks = trainer.networks
    path = export.export_policy(str(tmp_path / "policy"), networks, state.params, state.normalizer)
    policy = export.NumpyPolicy(path)
    act = jax.jit(networks.policy_fn(state.params, state.normalizer, deterministic=True))

    # Record 20 steps of one env (an episode boundary at t = 8 and 16) with the JAX policy.
    env_state = env.reset(jax.random.PRNGKey(7)[None])
    carry = networks.init_carry(1)
    reset = jp.ones((1,), bool)
    obs_seq, jax_actions, resets = [], [], []
    for _ in range(20):
        carry, action = act(carry, env_state.obs, reset, None)
        obs_seq.append(np.asarray(env_state.obs["state"][0]))
        jax_actions.append(np.asarray(action[0]))
        resets.append(bool(reset[0]))
        env_state = env.step(env_state, action)
        reset = env_state.done.astype(bool)
    assert sum(resets) == 3  # t = 0, 8, 16

    np_actions = []
    for obs, r in zip(obs_seq, resets, strict=True):
        if r:
            policy.reset()
        np_actions.append(policy(obs))
    np.testing.assert_allclose(np.array(np_actions), np.array(jax_actions), atol=1e-5)
    assert np.abs(np.array(jax_actions)).max() > 0.5  # trained actions, not ~0


def test_numpy_policy_at_default_size(tmp_path):
    """Default sizes (LSTM 256, MLP 512-256-128) export and run; its 50 Hz budget is measured by
    bench/bench_export.py, not here."""
    cfg = _ppo.get_network_section()
    networks = net.make_networks(12, cfg)
    obs = jp.zeros((1, 48))
    params = jax.jit(networks.init_params)(jax.random.PRNGKey(0), obs)
    normalizer = networks.init_normalizer(obs)
    policy = export.NumpyPolicy(
        export.export_policy(str(tmp_path / "p.npz"), networks, params, normalizer)
    )
    x = np.random.default_rng(0).normal(size=48).astype(np.float32)
    a = policy(x)
    assert a.shape == (12,) and a.dtype == np.float32 and np.all(np.isfinite(a))
    assert [len(c[0]) for c in policy.carry] == [cfg.lstm_hidden_size] * cfg.lstm_num_layers
    with pytest.raises(ValueError, match=r"obs shape \(47,\)"):
        policy(x[:47])


def test_numpy_policy_on_large_inputs_warns_not_and_equals_jax(tmp_path):
    """Normalized inputs of +-1000 drive the LSTM gates' and the SiLU head's sigmoids to +-1e3-ish
    arguments, where exp(-x) of float32 overflows past 88: the NumPy policy must not warn
    ("overflow encountered in exp") and must still give the JAX actor's actions."""
    cfg = tiny_cfg().network
    cfg.activation, cfg.obs_skip = "silu", True  # the head's SiLU reads the raw normalized obs
    networks = net.make_networks(3, cfg)
    obs = jp.zeros((1, 6))
    params = networks.init_params(jax.random.PRNGKey(0), obs)
    normalizer = networks.init_normalizer(obs)  # mean 0, std 1: normalized = raw
    path = export.export_policy(str(tmp_path / "p"), networks, params, normalizer)
    policy = export.NumpyPolicy(path)
    xs = 1000.0 * np.random.default_rng(0).choice([-1.0, 1.0], size=(4, 6)).astype(np.float32)
    carry, reset = networks.init_carry(1), jp.ones((1,), bool)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        np_actions = np.array([policy(x) for x in xs])
    jax_actions = []
    for x in xs:
        carry, mean, _, _ = networks.step(params, normalizer, carry, jp.asarray(x)[None], reset)
        jax_actions.append(np.asarray(mean[0]))
        reset = jp.zeros((1,), bool)
    np.testing.assert_allclose(np_actions, np.array(jax_actions), rtol=1e-5, atol=1e-5)
    assert np.abs(np_actions).max() > 1.0  # the large inputs reached the output


# ------------------------------------------------------------------------------- brax env
@pytest.mark.slow
def test_brax_inverted_pendulum_improves():  # ~20 s alone, ~65 s on a loaded 2-core machine
    from brax import envs

    env = train_lib.wrap_brax_env(
        envs.get_environment("inverted_pendulum", backend="positional"), episode_length=200
    )
    cfg = small_cfg("lstm", num_envs=32, num_steps=32)
    _, _, hist = train_history(env, cfg, 20)
    first = hist[0]["train/episode_length"]
    late = np.nanmean([h["train/episode_length"] for h in hist[10:]])
    assert first < 40, first
    assert late > 3 * first, (first, late)


# ------------------------------------------------------------------------- checkpoints/runner
# One env object for the runner tests: runner.run reuses the compiled iteration for the same env
# and ppo/network sections, so these tests compile it once.
MEMORY_ENV = toy_envs.make_memory_env()


@pytest.fixture(scope="module")
def trained_once():
    """A trainer and its state after one iteration (compiled once for the checkpoint tests)."""
    env = toy_envs.make_memory_env(privileged=True)
    trainer = train_lib.make_train(env, tiny_cfg())
    state, _ = trainer.iteration(trainer.init(jax.random.PRNGKey(0)))
    return trainer, state


def test_checkpoint_round_trip_exact(tmp_path, trained_once):
    trainer, state = trained_once
    saved = jax.device_get(state)
    checkpointer = ckpt.Checkpointer(str(tmp_path))
    assert checkpointer.save(state) == 1
    restored, with_rollout = checkpointer.restore(trainer.init(jax.random.PRNGKey(1)))
    checkpointer.close()
    assert with_rollout
    assert tree_equal(saved, jax.device_get(restored))


def test_checkpoint_without_a_new_env_metric_restores_by_leaf_name(tmp_path, trained_once):
    """Code that adds a per-step env metric resumes an older checkpoint: every saved leaf comes
    back under its name (the new leaf shifts the flatten order of all later ones), the new
    metric keeps the target's fresh value; any other missing leaf is still an error."""
    trainer, state = trained_once
    saved = jax.device_get(state)
    checkpointer = ckpt.Checkpointer(str(tmp_path))
    checkpointer.save(state)

    def with_extra(s, where):
        es = s.env_state
        fresh = jp.full_like(es.metrics["reward/recall"], 7.0)
        if where == "metrics":  # sorts before "reward/recall": every later leaf moves by one
            return s.replace(env_state=es.replace(metrics={**es.metrics, "reward/aaa": fresh}))
        return s.replace(env_state=es.replace(info={**es.info, "aaa": fresh}))

    target = with_extra(trainer.init(jax.random.PRNGKey(1)), "metrics")
    restored, _ = checkpointer.restore(target)
    restored = jax.device_get(restored)
    assert np.all(restored.env_state.metrics.pop("reward/aaa") == 7.0)
    assert tree_equal(saved, restored)
    with pytest.raises(ValueError, match=r"\['env_state'\].info\['aaa'\].*missing"):
        checkpointer.restore(with_extra(trainer.init(jax.random.PRNGKey(1)), "info"))
    checkpointer.close()


def test_checkpoint_with_a_renamed_env_metric_restores_without_it(tmp_path, trained_once):
    """A checkpoint written by code whose env had a metric this code renamed or removed (e.g.
    'episode/speed_ms' -> 'episode/speed_mps', foottof.renames) resumes: the old leaf is left
    unread and every other leaf comes back; an extra leaf outside the metrics is still an error."""
    trainer, state = trained_once
    es = state.env_state
    old = jp.full_like(es.metrics["reward/recall"], 3.0)
    with_old = state.replace(env_state=es.replace(metrics={**es.metrics, "episode/aaa_ms": old}))
    checkpointer = ckpt.Checkpointer(str(tmp_path / "metrics"))
    checkpointer.save(with_old)
    restored, with_rollout = checkpointer.restore(trainer.init(jax.random.PRNGKey(1)))
    checkpointer.close()
    assert with_rollout and "episode/aaa_ms" not in restored.env_state.metrics
    assert tree_equal(jax.device_get(state), jax.device_get(restored))

    with_info = state.replace(env_state=es.replace(info={**es.info, "aaa": old}))
    checkpointer = ckpt.Checkpointer(str(tmp_path / "info"))
    checkpointer.save(with_info)
    with pytest.raises(ValueError, match=r"\['env_state'\].info\['aaa'\].*not in this model"):
        checkpointer.restore(trainer.init(jax.random.PRNGKey(1)))
    checkpointer.close()


def _assert_same_policy(trainer_a, state_a, trainer_b, state_b) -> None:
    """Equal action means and values of two models on random observations shaped like state_a's
    (random, so every observation row of a grown kernel is used)."""
    leaves, treedef = jax.tree.flatten(state_a.env_state.obs)
    keys = jax.random.split(jax.random.PRNGKey(5), len(leaves))
    obs = jax.tree.unflatten(
        treedef, [jax.random.normal(k, x.shape) for k, x in zip(keys, leaves, strict=True)]
    )
    resets = jp.zeros(state_a.prev_done.shape, bool)
    _, mean_a, _, value_a = trainer_a.networks.step(
        state_a.params, state_a.normalizer, state_a.carry, obs, resets
    )
    _, mean_b, _, value_b = trainer_b.networks.step(
        state_b.params, state_b.normalizer, state_b.carry, obs, resets
    )
    np.testing.assert_allclose(mean_b, mean_a, atol=1e-6)
    np.testing.assert_allclose(value_b, value_a, atol=1e-6)


def test_resume_into_obs_skip_heads_keeps_the_policy_and_grows_zero_rows(
    tmp_path, trained_once, capsys
):
    """A checkpoint of heads that read the LSTM output only resumes into network.obs_skip heads:
    the new observation rows of both heads' first kernels (and their first Adam moments) start at
    zero, their second moments at the saved leaf's mean (input_growth.seed_second_moment), every
    other leaf comes back as saved, so actions and values are the saved model's."""
    trainer, state = trained_once
    saved = jax.device_get(state)
    checkpointer = ckpt.Checkpointer(str(tmp_path))
    checkpointer.save(state)
    cfg = tiny_cfg()
    cfg.network.obs_skip = True
    skip_trainer = train_lib.make_train(toy_envs.make_memory_env(privileged=True), cfg)
    restored, with_rollout = checkpointer.restore(skip_trainer.init(jax.random.PRNGKey(1)))
    checkpointer.close()
    restored = jax.device_get(restored)
    assert with_rollout and int(restored.iteration) == int(saved.iteration)
    out = capsys.readouterr().out
    assert "params: inputs grown on 2 leaves" in out  # actor and critic dense_0 kernels
    assert "opt_state: inputs grown on 4 leaves" in out  # their Adam mu and nu
    h = cfg.network.lstm_hidden_size
    for head in ("actor", "critic"):
        old = saved.params["params"][head]["dense_0"]["kernel"]
        new = restored.params["params"][head]["dense_0"]["kernel"]
        assert old.shape[0] == h and new.shape[0] > h
        np.testing.assert_array_equal(new[:h], old)
        assert not np.any(new[h:])
    old_moments = jax.tree_util.tree_flatten_with_path(saved.opt_state)[0]
    new_moments = jax.tree.leaves(restored.opt_state)
    assert len(old_moments) == len(new_moments)
    for (path, old), new in zip(old_moments, new_moments, strict=True):
        old, new = np.asarray(old), np.asarray(new)
        if old.shape != new.shape:  # a grown kernel's moments: saved rows, then the new rows'
            np.testing.assert_array_equal(new[: old.shape[0]], old)
            if ".nu[" in jax.tree_util.keystr(path):  # second moment: the saved leaf's mean
                np.testing.assert_allclose(new[old.shape[0] :], old.mean(), rtol=1e-6)
                assert old.mean() > 0
            else:  # first moment: zero
                assert not np.any(new[old.shape[0] :])
        else:
            np.testing.assert_array_equal(new, old)
    assert tree_equal(saved.normalizer, restored.normalizer)
    assert tree_equal(saved.env_state, restored.env_state)

    _assert_same_policy(trainer, saved, skip_trainer, restored)


@pytest.mark.integration
def test_resume_into_a_wider_actor_head_keeps_the_policy_and_the_new_units_learn(tmp_path, capsys):
    """A checkpoint whose actor head is (8, 6) resumes into obs_skip heads with an actor head of
    (16, 12) (input_growth.grow_width): saved blocks as saved, the new units' incoming weights
    as the fresh model's, zero weights from them (and from the new observation rows) into the
    saved units and the output, zero first Adam moments and second ones seeded at the saved
    layer's mean; the actions are the saved model's, and one iteration later the output layer
    has learned to read the new units."""
    env = toy_envs.make_memory_env(privileged=True)
    cfg = tiny_cfg()
    cfg.network.actor_hidden = (8, 6)
    trainer = train_lib.make_train(env, cfg)
    state, _ = trainer.iteration(trainer.init(jax.random.PRNGKey(0)))
    saved = jax.device_get(state)
    checkpointer = ckpt.Checkpointer(str(tmp_path))
    checkpointer.save(state)
    wide = tiny_cfg()
    wide.network.actor_hidden = (16, 12)
    wide.network.obs_skip = True
    wide_trainer = train_lib.make_train(env, wide)
    fresh = jax.device_get(wide_trainer.init(jax.random.PRNGKey(1)))
    restored, _ = checkpointer.restore(wide_trainer.init(jax.random.PRNGKey(1)))
    checkpointer.close()
    restored = jax.device_get(restored)
    assert "params: inputs grown on 6 leaves" in capsys.readouterr().out  # 3 actor kernels,
    # 2 actor biases, the critic's dense_0 kernel (obs_skip)
    old, new, init = (x.params["params"]["actor"] for x in (saved, restored, fresh))
    h = cfg.network.lstm_hidden_size
    for layer, (n_in, n_out) in {"dense_0": (h, 8), "dense_1": (8, 6), "out": (6, None)}.items():
        k_old, k_new, k_init = (np.asarray(x[layer]["kernel"]) for x in (old, new, init))
        n_out = n_out or k_old.shape[1]
        np.testing.assert_array_equal(k_new[:n_in, :n_out], k_old)
        assert not np.any(k_new[n_in:, :n_out])  # nothing new reaches a saved unit
        np.testing.assert_array_equal(k_new[:, n_out:], k_init[:, n_out:])  # fresh new units
        np.testing.assert_array_equal(np.asarray(new[layer]["bias"])[:n_out], old[layer]["bias"])
    assert np.any(np.asarray(new["dense_1"]["kernel"])[:, 6:])  # the new units are not dead
    adam_old, adam_new = (x.opt_state.inner_state[1][0] for x in (saved, restored))
    for moment in ("mu", "nu"):  # dense_1's kernel: the saved block as saved, the rest new
        old, new = (
            np.asarray(getattr(a, moment)["params"]["actor"]["dense_1"]["kernel"])
            for a in (adam_old, adam_new)
        )
        np.testing.assert_array_equal(new[:8, :6], old)
        if moment == "mu":  # no direction assumed
            assert not np.any(new[8:]) and not np.any(new[:, 6:])
        else:  # input_growth.seed_second_moment: the saved entries' mean, not 0
            assert old.mean() > 0
            np.testing.assert_allclose(new[8:], old.mean(), rtol=1e-6)
            np.testing.assert_allclose(new[:, 6:], old.mean(), rtol=1e-6)

    _assert_same_policy(trainer, saved, wide_trainer, restored)

    after, _ = wide_trainer.iteration(jax.device_put(restored))
    out_rows = np.asarray(after.params["params"]["actor"]["out"]["kernel"])[6:]
    assert np.any(out_rows)  # the output reads the new units after one update


def test_resume_equals_straight_run(tmp_path, capsys):
    env = MEMORY_ENV
    straight = runner.run(tiny_cfg(num_iterations=4), env, str(tmp_path / "a"))
    runner.run(tiny_cfg(num_iterations=2), env, str(tmp_path / "b"))
    resumed = runner.run(tiny_cfg(num_iterations=4), env, str(tmp_path / "b"), resume=True)
    assert int(resumed.iteration) == 4
    assert tree_equal(jax.device_get(straight), jax.device_get(resumed))
    run_b = tmp_path / "b"
    rows = (run_b / "metrics.csv").read_text().strip().splitlines()
    assert len(rows) == 5 and rows[0].startswith("iteration,env_steps")
    assert (run_b / "config.json").exists() and (run_b / "config.yaml").exists()
    assert any(n.startswith("events.out.tfevents") for n in os.listdir(run_b))
    out = capsys.readouterr().out
    assert "compiled in" in out and "it 4/4" in out and "success" in out and "reward: recall" in out
    assert re.search(r"params; init \d+\.\d s, compiled in \d+\.\d s", out)
    with pytest.raises(FileExistsError):
        runner.run(tiny_cfg(num_iterations=4), env, str(run_b))


def test_resume_trims_rows_after_the_checkpoint_and_sums_wall_time(tmp_path):
    """A run killed after its last checkpoint logged rows the resume will redo: they go, and the
    cumulative wall-clock column carries on from the checkpoint's row."""
    env = MEMORY_ENV
    run = tmp_path / "run"
    runner.run(tiny_cfg(num_iterations=3, checkpoint_every=2), env, str(run))
    (run / "checkpoints" / "3").rename(tmp_path / "gone")  # as if killed before saving it
    metrics = run / "metrics.csv"
    before = list(csv.DictReader(metrics.open()))
    assert [r["iteration"] for r in before] == ["1", "2", "3"]
    runner.run(tiny_cfg(num_iterations=4, checkpoint_every=2), env, str(run), resume=True)
    rows = list(csv.DictReader(metrics.open()))
    assert [r["iteration"] for r in rows] == ["1", "2", "3", "4"]
    wall = [float(r[runner.WALL_COLUMN]) for r in rows]
    assert wall[:2] == [float(r[runner.WALL_COLUMN]) for r in before[:2]]
    assert all(b > a for a, b in zip(wall[:-1], wall[1:], strict=True)), wall
    assert wall[2] > wall[1] + float(rows[2]["time/iteration_s"]) / 3600.0 * 0.99


def test_trim_metrics_adds_the_wall_column_to_old_files(tmp_path):
    (tmp_path / "metrics.csv").write_text(
        "iteration,env_steps,time/iteration_s,loss\n1,8,10.0,0.5\n2,16,20.0,0.4\n3,24,5.0,0.3\n"
    )
    assert runner.trim_metrics(str(tmp_path), 2) == pytest.approx(30.0)
    rows = list(csv.DictReader((tmp_path / "metrics.csv").open()))
    assert list(rows[0]) == ["iteration", "env_steps", "time/iteration_s", "time/total_h", "loss"]
    assert [float(r["time/total_h"]) * 3600 for r in rows] == pytest.approx([10.0, 30.0])
    assert runner.trim_metrics(str(tmp_path / "nothing"), 5) == 0.0
    # A file from before the trim: a resumed chunk repeats iterations 2 and 3; the later rows win.
    (tmp_path / "metrics.csv").write_text(
        "iteration,time/iteration_s\n1,1.0\n2,2.0\n3,3.0\n2,20.0\n3,30.0\n4,40.0\n"
    )
    assert runner.trim_metrics(str(tmp_path), 3) == pytest.approx(51.0)
    rows = list(csv.DictReader((tmp_path / "metrics.csv").open()))
    assert [(r["iteration"], r["time/iteration_s"]) for r in rows] == [
        ("1", "1.0"),
        ("2", "20.0"),
        ("3", "30.0"),
    ]


def test_resumed_run_logging_new_metrics_extends_the_csv_header(tmp_path):
    """New code logs a metric the resumed run's metrics.csv lacks: the column is added to the
    header (empty in the older rows), not silently dropped."""
    logs = runner._Logs(str(tmp_path), tensorboard=False)
    logs.write({"iteration": 1, "loss": 0.5}, 1)
    logs.write({"iteration": 2, "loss": 0.4}, 2)
    logs = runner._Logs(str(tmp_path), tensorboard=False)  # the resumed process
    logs.write({"iteration": 3, "loss": 0.3, "task/new": 7.0}, 3)
    logs.write({"iteration": 4, "task/new": 8.0, "loss": 0.2}, 4)
    rows = list(csv.DictReader((tmp_path / "metrics.csv").open()))
    assert list(rows[0]) == ["iteration", "loss", "task/new"]
    assert [(r["iteration"], r["loss"], r["task/new"]) for r in rows] == [
        ("1", "0.5", ""),
        ("2", "0.4", ""),
        ("3", "0.3", "7.0"),
        ("4", "0.2", "8.0"),
    ]
    assert not (tmp_path / "metrics.csv.tmp").exists()


class _NanAfter:
    """Memory env whose reward turns NaN once a step counter reaches `steps` (per env)."""

    def __init__(self, steps: int):
        self.env = toy_envs.CueMemoryEnv()
        self.steps = steps
        self.action_size = 1

    def reset(self, key):
        s = self.env.reset(key)
        return s.replace(info={**s.info, "count": jp.zeros((), jp.int32)})

    def step(self, state, action):
        count = state.info["count"] + 1
        s = self.env.step(
            state.replace(info={k: v for k, v in state.info.items() if k != "count"}), action
        )
        reward = jp.where(count > self.steps, jp.nan, s.reward)
        return s.replace(reward=reward, info={**s.info, "count": count})


def test_nan_guard_keeps_last_good_checkpoint(tmp_path):
    env = train_lib.VmapEnv(_NanAfter(steps=8))  # 4 steps per iteration: NaN in iteration 3
    cfg = tiny_cfg(num_iterations=5, checkpoint_every=1)
    with pytest.raises(
        runner.NonFiniteError, match="iteration 3.*Last good checkpoint: iteration 2"
    ):
        runner.run(cfg, env, str(tmp_path))
    checkpointer = ckpt.Checkpointer(str(tmp_path))
    assert checkpointer.latest_step() == 2
    trainer = train_lib.make_train(env, cfg)
    restored, _ = checkpointer.restore(trainer.init(jax.random.PRNGKey(0)))
    checkpointer.close()
    assert all(np.isfinite(np.asarray(x)).all() for x in jax.tree.leaves(restored.params))


def test_keyboard_interrupt_saves(tmp_path):
    def interrupt(it, metrics, state):
        if it == 3:
            raise KeyboardInterrupt

    cfg = tiny_cfg(num_iterations=10, checkpoint_every=100)
    with pytest.raises(KeyboardInterrupt):
        runner.run(cfg, MEMORY_ENV, str(tmp_path), on_iteration=interrupt)
    checkpointer = ckpt.Checkpointer(str(tmp_path))
    assert checkpointer.all_steps() == [3]
    checkpointer.close()


def test_init_from(tmp_path):
    env = MEMORY_ENV
    source = runner.run(tiny_cfg(num_iterations=1), env, str(tmp_path / "stage1"))
    stage2 = runner.run(
        tiny_cfg(num_iterations=1),
        env,
        str(tmp_path / "stage2"),
        init_from=str(tmp_path / "stage1"),
    )
    # The loaded normalizer keeps counting: 8 envs x 4 steps per iteration in each stage.
    assert int(source.normalizer.count.lo) == 32
    assert int(stage2.normalizer.count.lo) == 64
    assert int(stage2.iteration) == 1
    zeros = jax.tree.map(jp.zeros_like, (source.params, source.normalizer))
    params, normalizer = ckpt.load_params_and_normalizer(str(tmp_path / "stage1"), *zeros)
    assert tree_equal(jax.device_get(params), jax.device_get(source.params))
    assert tree_equal(jax.device_get(normalizer), jax.device_get(source.normalizer))

    bigger = tiny_cfg(num_iterations=1)
    bigger.network.lstm_hidden_size = 16
    with pytest.raises(
        ValueError,
        match=r"leaf \['params'\]\['params'\]\['memory_a'\]\['lstm_0'\]\['hf'\]\['bias'\] "
        r"has shape \(8,\) in the checkpoint but \(16,\)",
    ):
        runner.run(bigger, env, str(tmp_path / "stage2b"), init_from=str(tmp_path / "stage1"))
    with pytest.raises(FileNotFoundError, match="init_from"):
        runner.run(tiny_cfg(), env, str(tmp_path / "stage2c"), init_from=str(tmp_path / "nope"))


# ------------------------------------------------------------------------------- bad input
def test_bad_config_values():
    env = toy_envs.make_memory_env()
    with pytest.raises(ValueError, match="ppo.num_envs=0"):
        train_lib.make_train(env, small_cfg(num_envs=0))
    with pytest.raises(ValueError, match=r"ppo.num_envs=10: .*num_minibatches"):
        train_lib.make_train(env, small_cfg(num_envs=10, num_minibatches=4))
    with pytest.raises(ValueError, match="device count 3"):
        train_lib.make_train(env, small_cfg(num_envs=64), devices=jax.devices() * 3)
    with pytest.raises(ValueError, match="ppo.lr_schedule='cosine'"):
        train_lib.make_train(env, small_cfg(lr_schedule="cosine"))
    with pytest.raises(ValueError, match="network.policy='gru'"):
        train_lib.make_train(env, small_cfg("gru"))
    locked = small_cfg()
    locked.lock()
    with pytest.raises(AttributeError, match="lerning_rate"):
        locked.ppo.lerning_rate = 1e-3


def test_obs_skip_needs_an_lstm_policy():
    cfg = _ppo.get_network_section()
    cfg.policy, cfg.obs_skip = "mlp", True
    with pytest.raises(ValueError, match=r"network.obs_skip=True needs network.policy='lstm'"):
        net.make_networks(12, cfg)
    cfg.policy = "lstm"
    assert net.make_networks(12, cfg).module.obs_skip


def test_env_state_without_env_axis_is_rejected():
    class Unbatched(train_lib.VmapEnv):
        def reset(self, keys):
            s = super().reset(keys)
            return s.replace(info={**s.info, "shared": jp.zeros(3)})

    with pytest.raises(ValueError, match=r"\['shared'\] has shape \(3,\)"):
        train_lib.make_train(Unbatched(toy_envs.CueMemoryEnv()), small_cfg())


def test_toy_env_contract():
    env = toy_envs.make_memory_env(episode_length=3)
    s = env.reset(jax.random.split(jax.random.PRNGKey(0), 5))
    assert isinstance(s, State) and s.obs.shape == (5, 2) and s.done.shape == (5,)
    cue = s.obs[:, 0]
    assert set(np.asarray(cue).tolist()) <= {-1.0, 1.0}
    s = env.step(s, cue[:, None])  # step 0 pays nothing
    assert np.all(s.reward == 0) and np.all(s.obs == 0)
    s = env.step(s, -cue[:, None])  # wrong sign: |-c - c| = 2
    np.testing.assert_allclose(s.reward, -2.0)
    s = env.step(s, -cue[:, None])
    assert np.all(s.done == 1) and np.all(s.metrics["episode/success"] == 0)
    assert np.all(s.obs[:, 1] == 1)  # auto-reset: first-step flag of a new episode


@pytest.mark.integration
def test_resume_with_a_fixed_rate_learns_at_the_configs_rate(tmp_path):
    """A branch resumed with another fixed ppo.learning_rate uses it (the checkpoint's optimizer
    state holds the saved rate); an adaptive rate carries on from where it was saved."""
    env = MEMORY_ENV

    def cfg(n, **ppo):
        c = tiny_cfg(num_iterations=n)
        c.ppo.update(ppo)
        return c

    runner.run(cfg(2, lr_schedule="fixed", learning_rate=1e-3), env, str(tmp_path / "f"))
    runner.run(
        cfg(4, lr_schedule="fixed", learning_rate=3e-3), env, str(tmp_path / "f"), resume=True
    )
    rows = list(csv.DictReader((tmp_path / "f" / "metrics.csv").open()))
    lrs = [float(r["ppo/learning_rate_mean"]) for r in rows]
    np.testing.assert_allclose(lrs, [1e-3, 1e-3, 3e-3, 3e-3], rtol=1e-6)
    runner.run(cfg(2, lr_schedule="adaptive", learning_rate=1e-3), env, str(tmp_path / "a"))
    saved = float(
        list(csv.DictReader((tmp_path / "a" / "metrics.csv").open()))[-1]["ppo/learning_rate"]
    )
    runner.run(
        cfg(3, lr_schedule="adaptive", learning_rate=3e-3), env, str(tmp_path / "a"), resume=True
    )
    last = list(csv.DictReader((tmp_path / "a" / "metrics.csv").open()))[-1]
    assert float(last["ppo/learning_rate_mean"]) == pytest.approx(saved, rel=1e-6)
