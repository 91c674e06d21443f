"""One compiled LSTM-PPO iteration (rollout + update epochs), data-parallel over a 'data' mesh.

The update epochs minimize the algorithm's loss (foottof.ppo.algorithms: PPO, or distillation
where train.teacher is set), chosen once in make_train; the rest of the iteration is shared.

Env contract (batched, Brax-style): `reset(keys (N, 2)) -> State`,
`step(state, actions (N, A)) -> State`, auto-reset inside `step`, `State.obs` an (N, obs) array
or a dict {'state': actor obs, 'privileged_state': critic obs}, `State.reward` (N,),
`State.done` (N,), `State.info['truncation']` (N,) (1 where the episode ended by its time limit),
`State.metrics` a dict of (N,) arrays, and an `action_size` attribute.
Every leaf of the batched State must have the env axis first (it is sharded over devices).
`wrap_brax_env` makes such an env from any single Brax `Env`; `VmapEnv` from a single env that
auto-resets itself (our locomotion env); both live in foottof.envs.wrappers (re-exported here).
"""

import dataclasses
import functools
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jp
import ml_collections
import numpy as np
import optax
from brax.training.acme import running_statistics
from flax import struct
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from foottof import config_check
from foottof.envs.wrappers import VmapEnv, wrap_brax_env  # noqa: F401 (re-exported)
from foottof.limits import LR_SCHEDULES  # noqa: F401 (re-exported)
from foottof.ppo import algorithms, losses
from foottof.ppo import networks as net
from foottof.ppo import symmetry as sym

AXIS = "data"  # mesh axis over envs (all devices of all hosts)

EPISODE_PREFIX = "episode/"  # env metrics with this prefix are averaged over done steps only


@struct.dataclass
class TrainState:
    """Everything one iteration reads and writes; N envs, H LSTM units."""

    params: Any  # network variables (replicated)
    opt_state: Any  # optax inject_hyperparams state; opt_state.hyperparams['learning_rate']
    normalizer: running_statistics.RunningStatisticsState  # running obs statistics (replicated)
    env_state: Any  # batched env State, leaves (N, ...) (sharded over 'data')
    carry: Any  # LSTM carry before the next step, (N, H) leaves
    prev_done: jax.Array  # (N,) bool: the last step ended an episode -> reset carry before acting
    ep_return: jax.Array  # (N,) return of the running episode so far
    ep_length: jax.Array  # (N,) steps of the running episode so far
    key: jax.Array  # (2,) uint32 PRNG key of the next iteration
    iteration: jax.Array  # () int32 completed iterations
    # ppo.symmetry: the policy's LSTM carry on the mirrored observations (foottof.ppo.symmetry),
    # (N, H) leaves (sharded over 'data'); None (no leaves) without it
    mirror_carry: Any = None


class Transition(NamedTuple):
    """One rollout step for the local envs; leaves (T, N, ...) after the scan."""

    obs: Any
    resets: jax.Array  # episode starts at this step (carry reset before acting)
    actions: jax.Array
    log_probs: jax.Array
    means: jax.Array
    values: jax.Array
    rewards: jax.Array
    dones: jax.Array
    truncation: jax.Array
    finished_return: jax.Array  # episode return where done, else 0
    finished_length: jax.Array  # episode length where done, else 0
    metrics: dict


class Batch(NamedTuple):
    """One rollout of the envs, what an update reads; the env axis is sharded over 'data'."""

    traj: Transition  # leaves (T, N, ...)
    carry: Any  # LSTM carry before the rollout's first step, (N, H) leaves
    last_value: jax.Array  # (N,) value of the state after the last step
    mirror_carry: Any = None  # ppo.symmetry: the mirrored sequences' first carry, (N, H) leaves


class Train(NamedTuple):
    """What make_train returns; `init`, `iteration` and `update` are jitted (iteration donates its
    input)."""

    init: Callable[[jax.Array], TrainState]  # key (2,) -> TrainState
    iteration: Callable[[TrainState], tuple[TrainState, dict]]  # state -> (state, scalar metrics)
    # (params, opt_state, normalizer, Batch, key (2,)) -> (params, opt_state, normalizer, metrics
    # (num_epochs, num_minibatches) per SGD step): the update epochs of `iteration` alone
    update: Callable
    networks: net.Networks
    mesh: Mesh
    state_sharding: Any  # TrainState of NamedSharding
    num_envs: int
    steps_per_iteration: int  # env steps per iteration over all envs (num_envs * num_steps)


def _validate(cfg: ml_collections.ConfigDict, num_devices: int) -> None:
    """The ppo rules of foottof.config_check (held there once; the network's are checked by
    net.make_networks, which builds it), and the one rule that needs the devices: whole
    minibatches of envs on every device."""
    config_check.check_sections(cfg, ("ppo",))
    ppo = cfg.ppo
    if ppo.num_envs % num_devices:
        raise ValueError(
            f"ppo.num_envs={ppo.num_envs} is not divisible by the device count {num_devices}"
        )
    if (ppo.num_envs // num_devices) % ppo.num_minibatches:
        raise ValueError(
            f"ppo.num_envs={ppo.num_envs} is not divisible by ppo.num_minibatches * devices = "
            f"{ppo.num_minibatches} * {num_devices}"
        )


def _check_env_state(state_shape, num_envs: int) -> None:
    for path, leaf in jax.tree_util.tree_flatten_with_path(state_shape)[0]:
        if leaf.ndim == 0 or leaf.shape[0] != num_envs:
            raise ValueError(
                f"env state leaf {jax.tree_util.keystr(path)} has shape {leaf.shape}; every leaf "
                f"of the batched State needs the env axis first (num_envs={num_envs})"
            )


def _make_optimizer(learning_rate: float, max_grad_norm: float) -> optax.GradientTransformation:
    """Global-norm clip + Adam; the learning rate lives in opt_state.hyperparams (adaptive rule)."""

    def inner(learning_rate):
        return optax.chain(optax.clip_by_global_norm(max_grad_norm), optax.adam(learning_rate))

    return optax.inject_hyperparams(inner)(learning_rate=learning_rate)


def set_learning_rate(opt_state, lr):
    return opt_state._replace(hyperparams={**opt_state.hyperparams, "learning_rate": lr})


def adapt_learning_rate(lr, kl, desired_kl: float, lr_min: float, lr_max: float):
    """rsl_rl rule: kl > 2 desired -> lr / 1.5; 0 < kl < desired / 2 -> lr * 1.5; then clamp."""
    lr = jp.where(kl > 2.0 * desired_kl, jp.maximum(lr / 1.5, lr_min), lr)
    return jp.where((kl < 0.5 * desired_kl) & (kl > 0.0), jp.minimum(lr * 1.5, lr_max), lr)


@dataclasses.dataclass(frozen=True)
class Settings:
    """The static numbers of one iteration, read once from c.ppo (and c.train.teacher)."""

    num_steps: int  # rollout length per env
    num_minibatches: int  # per epoch, split along the env axis
    num_epochs: int
    gamma: float
    gae_lambda: float
    normalize_advantage: bool
    adaptive_lr: bool  # ppo.lr_schedule == "adaptive": the rsl_rl KL rule (adapt_learning_rate)
    desired_kl: float
    lr_min: float
    lr_max: float
    algorithm: algorithms.Algorithm  # PPO, or distillation where train.teacher is set
    symmetry: bool = False  # ppo.symmetry: mirrored copies of the sequences join each minibatch
    mirror: Any = None  # with symmetry: the env's mirror maps (foottof.envs.symmetry.Mirror)

    @classmethod
    def from_config(cls, cfg: ml_collections.ConfigDict) -> "Settings":
        ppo = cfg.ppo
        return cls(
            num_steps=int(ppo.num_steps),
            num_minibatches=int(ppo.num_minibatches),
            num_epochs=int(ppo.num_epochs),
            gamma=float(ppo.gamma),
            gae_lambda=float(ppo.gae_lambda),
            normalize_advantage=bool(ppo.normalize_advantage),
            adaptive_lr=ppo.lr_schedule == "adaptive",
            desired_kl=float(ppo.desired_kl),
            lr_min=float(ppo.lr_min),
            lr_max=float(ppo.lr_max),
            algorithm=algorithms.from_config(cfg),
            symmetry=bool(ppo.symmetry),
        )


# The functions of one iteration, each callable alone. Those that take a mesh axis (`local_*`,
# `sgd_step`) run on one device's share of the envs inside `jax.shard_map` (or `jax.vmap` with
# ``axis_name=AXIS``): their collectives reduce over AXIS.


def init_state(
    env, networks: net.Networks, optimizer, mesh: Mesh, num_envs: int, obs_example, key,
    symmetry: bool = False,
):  # fmt: skip
    """A fresh TrainState: network, optimizer and normalizer initialized, every env reset.

    Args:
      obs_example: an observation with a batch axis of 1 (shapes the network's inputs).
      key: (2,) PRNG key; split into the params, the env resets and the next iteration's key.
      symmetry: also a fresh carry for the mirrored observations (ppo.symmetry).
    """
    key_params, key_env, key_next = jax.random.split(key, 3)
    params = networks.init_params(key_params, obs_example)
    opt_state = optimizer.init(params)
    normalizer = networks.init_normalizer(obs_example)
    keys = jax.random.split(key_env, num_envs)  # one reset key per env
    reset = jax.shard_map(
        functools.partial(_reset_envs, env, networks),
        mesh=mesh,
        in_specs=P(AXIS),
        out_specs=P(AXIS),
        check_vma=False,
    )
    env_state, carry, prev_done, ep_return, ep_length = reset(keys)
    return TrainState(
        params=params, opt_state=opt_state, normalizer=normalizer, env_state=env_state,
        carry=carry, prev_done=prev_done, ep_return=ep_return, ep_length=ep_length,
        key=key_next, iteration=jp.zeros((), jp.int32),
        mirror_carry=jax.tree.map(jp.zeros_like, carry) if symmetry else None,
    )  # fmt: skip


def _reset_envs(env, networks: net.Networks, keys):
    env_state = env.reset(keys)
    n = keys.shape[0]
    return (
        env_state,
        networks.init_carry(n),
        jp.ones((n,), bool),
        jp.zeros((n,), jp.float32),
        jp.zeros((n,), jp.float32),
    )


def rollout_step(
    env, networks: net.Networks, params, normalizer, log_std, carry, key_step, mirror=None
):
    """One env step of the rollout: act ~ N(mean, std), step the envs, book the episode.

    Args:
      log_std: (A,) log std of the actions.
      carry: (env_state, LSTM carry, prev_done (N,), ep_return (N,), ep_length (N,)), and with
        ``mirror`` the carry on the mirrored observations last.
      key_step: (2,) PRNG key of this step's action noise.
      mirror: ppo.symmetry: the env's mirror maps; the policy also steps on the mirrored
        observation (foottof.ppo.symmetry.mirror_carry_step), only for its carry.

    Returns:
      (the next carry, this step's Transition (leaves (N, ...))).
    """
    env_state, net_carry, prev_done, ep_return, ep_length = carry[:5]
    obs = env_state.obs
    mirrored = ()
    if mirror is not None:  # static
        args = (networks, params, normalizer, mirror, carry[5], obs, prev_done)
        mirrored = (sym.mirror_carry_step(*args),)
    net_carry, mean, _, value = networks.step(params, normalizer, net_carry, obs, prev_done)
    action = mean + jp.exp(log_std) * jax.random.normal(key_step, mean.shape)  # ~ N(mean, std)
    log_prob = net.gaussian_log_prob(action, mean, log_std)
    env_state = env.step(env_state, action)
    done = env_state.done.astype(bool)
    reward = env_state.reward.astype(jp.float32)
    ep_return = ep_return + reward
    ep_length = ep_length + 1.0
    tr = Transition(
        obs=obs, resets=prev_done, actions=action, log_probs=log_prob, means=mean,
        values=value, rewards=reward, dones=done.astype(jp.float32),
        truncation=env_state.info["truncation"].astype(jp.float32),
        finished_return=jp.where(done, ep_return, 0.0),
        finished_length=jp.where(done, ep_length, 0.0),
        metrics={k: v.astype(jp.float32) for k, v in env_state.metrics.items()},
    )  # fmt: skip
    ep_return = jp.where(done, 0.0, ep_return)
    ep_length = jp.where(done, 0.0, ep_length)
    return (env_state, net_carry, done, ep_return, ep_length) + mirrored, tr


def rollout(env, networks: net.Networks, state: TrainState, key, num_steps: int, mirror=None):
    """``num_steps`` steps of the envs in `state` under its policy (no collectives).

    Args:
      mirror: ppo.symmetry: the env's mirror maps; the carry on the mirrored observations
        (``state.mirror_carry``) steps along and comes last in the returned carry.

    Returns:
      (the carry after the last step (as rollout_step's), Transition with leaves (T, N, ...),
      (N,) value of the state after the last step).
    """
    params, normalizer = state.params, state.normalizer
    log_std = networks.action_log_std(params)
    step = functools.partial(rollout_step, env, networks, params, normalizer, log_std)
    carry0 = (state.env_state, state.carry, state.prev_done, state.ep_return, state.ep_length)
    if mirror is not None:  # static
        step = functools.partial(step, mirror=mirror)
        carry0 = carry0 + (state.mirror_carry,)
    carry, traj = jax.lax.scan(step, carry0, jax.random.split(key, num_steps))
    env_state, net_carry, prev_done = carry[:3]
    _, _, _, last_value = networks.step(params, normalizer, net_carry, env_state.obs, prev_done)
    return carry, traj, last_value


def sgd_step(networks: net.Networks, optimizer, settings: Settings, carry, mb: losses.Minibatch):
    """One gradient step on a minibatch, gradients and metrics averaged over AXIS.

    Args:
      carry: (params, opt_state, normalizer); the normalizer is read, not updated.

    Returns:
      (the new carry, this step's metrics: the loss's, 'ppo/learning_rate_mean' (the rate this
      step used) and 'ppo/grad_norm').
    """
    params, opt_state, normalizer = carry
    loss_kwargs = {}
    if settings.symmetry:  # static: the mirrored copies of the minibatch's sequences join it
        loss_kwargs["kl_envs"] = mb.advantages.shape[1]  # the KL over the originals (rsl_rl)
        mb = sym.augment(mb, settings.mirror)
    grad_fn = jax.value_and_grad(settings.algorithm.loss, has_aux=True)
    (_, metrics), grads = grad_fn(params, networks, normalizer, mb, **loss_kwargs)
    grads = jax.lax.pmean(grads, AXIS)
    metrics = jax.lax.pmean(metrics, AXIS)
    if settings.adaptive_lr:
        lr = adapt_learning_rate(
            opt_state.hyperparams["learning_rate"],
            metrics["ppo/kl"],
            settings.desired_kl,
            settings.lr_min,
            settings.lr_max,
        )
        opt_state = set_learning_rate(opt_state, lr)
    metrics["ppo/learning_rate_mean"] = opt_state.hyperparams["learning_rate"]  # this update's
    updates, opt_state = optimizer.update(grads, opt_state, params)
    params = optax.apply_updates(params, updates)
    metrics["ppo/grad_norm"] = optax.global_norm(grads)
    return (params, opt_state, normalizer), metrics


def epoch_minibatches(data: losses.Minibatch, key, num_minibatches: int) -> losses.Minibatch:
    """One epoch's minibatches: the envs shuffled and split, each env's time order kept.

    Args:
      data: the whole rollout, leaves (T, N, ...) (carry (N, ...), log_std (A,)).
      key: (2,) PRNG key of the shuffle.

    Returns:
      Minibatch with a leading minibatch axis: leaves (M, T, N / M, ...) (carry (M, N / M, ...),
      log_std (M, A)); every env in exactly one minibatch.
    """
    n_local = data.advantages.shape[1]
    perm = jax.random.permutation(key, n_local)  # shuffle envs, keep time order
    idx = perm.reshape(num_minibatches, n_local // num_minibatches)

    def take(i):
        return losses.Minibatch(
            carry=jax.tree.map(lambda x: x[i], data.carry),
            obs=jax.tree.map(lambda x: x[:, i], data.obs),
            resets=data.resets[:, i], actions=data.actions[:, i],
            log_probs=data.log_probs[:, i], means=data.means[:, i], log_std=data.log_std,
            values=data.values[:, i], advantages=data.advantages[:, i],
            returns=data.returns[:, i],
            mirror_carry=jax.tree.map(lambda x: x[i], data.mirror_carry),
        )  # fmt: skip

    minibatches = jax.vmap(take)(idx)  # leading minibatch axis
    return minibatches._replace(
        log_std=jp.broadcast_to(data.log_std, (num_minibatches,) + data.log_std.shape)
    )


def _epoch(sgd, data: losses.Minibatch, num_minibatches: int, carry, key_epoch):
    return jax.lax.scan(sgd, carry, epoch_minibatches(data, key_epoch, num_minibatches))


def local_update(
    networks: net.Networks, optimizer, settings: Settings, params, opt_state, normalizer,
    batch: Batch, key_update,
):  # fmt: skip
    """The update epochs of one iteration on this device's envs: GAE (advantages normalized
    over AXIS), num_epochs x num_minibatches sgd_steps, then the normalizer's statistics.

    Args:
      key_update: (2,) PRNG key, the same on every device (each folds in its index).

    Returns:
      (params, opt_state, normalizer, metrics with leaves (num_epochs, num_minibatches)).
    """
    key_update = jax.random.fold_in(key_update, jax.lax.axis_index(AXIS))
    traj, carry_start, last_value = batch.traj, batch.carry, batch.last_value
    gamma = settings.gamma
    rewards = losses.bootstrap_truncation(traj.rewards, traj.values, traj.truncation, gamma)
    advantages, returns = losses.compute_gae(
        rewards, traj.values, traj.dones, last_value, gamma, settings.gae_lambda
    )
    if settings.normalize_advantage:
        mean = jax.lax.pmean(jp.mean(advantages), AXIS)
        var = jax.lax.pmean(jp.mean((advantages - mean) ** 2), AXIS)
        advantages = (advantages - mean) / (jp.sqrt(var) + 1e-8)

    data = losses.Minibatch(
        carry=carry_start, obs=traj.obs, resets=traj.resets, actions=traj.actions,
        log_probs=traj.log_probs, means=traj.means, log_std=networks.action_log_std(params),
        values=traj.values, advantages=advantages, returns=returns,
        mirror_carry=batch.mirror_carry,
    )  # fmt: skip
    sgd = functools.partial(sgd_step, networks, optimizer, settings)
    (new_params, opt_state, _), sgd_metrics = jax.lax.scan(
        functools.partial(_epoch, sgd, data, settings.num_minibatches),
        (params, opt_state, normalizer),
        jax.random.split(key_update, settings.num_epochs),
    )
    if networks.normalize_observations:  # after the update: the loss used the rollout's stats
        normalizer = running_statistics.update(
            normalizer, net.select_obs(traj.obs), pmap_axis_name=AXIS
        )
    return new_params, opt_state, normalizer, sgd_metrics


def local_iteration(env, networks: net.Networks, optimizer, settings: Settings, state: TrainState):
    """One iteration on this device's envs: rollout, local_update, metrics reduced over AXIS.

    Returns:
      (the next TrainState, scalar metrics (see `_iteration_metrics`)).
    """
    key, key_rollout, key_update = jax.random.split(state.key, 3)
    # Each device gets its own rollout stream; the state key stays replicated.
    key_rollout = jax.random.fold_in(key_rollout, jax.lax.axis_index(AXIS))
    carry_start = state.carry  # stored initial carry of this rollout (before any reset)
    mirror = settings.mirror if settings.symmetry else None
    carry, traj, last_value = rollout(env, networks, state, key_rollout, settings.num_steps, mirror)
    env_state, net_carry, prev_done, ep_return, ep_length = carry[:5]
    mirror_carry = carry[5] if mirror is not None else None
    params, opt_state, normalizer, sgd_metrics = local_update(
        networks,
        optimizer,
        settings,
        state.params,
        state.opt_state,
        state.normalizer,
        Batch(traj, carry_start, last_value, state.mirror_carry),
        key_update,
    )
    log_std = networks.action_log_std(params)
    metrics = _iteration_metrics(traj, sgd_metrics, log_std, params, opt_state)
    new_state = TrainState(
        params=params, opt_state=opt_state, normalizer=normalizer, env_state=env_state,
        carry=net_carry, prev_done=prev_done, ep_return=ep_return, ep_length=ep_length,
        key=key, iteration=state.iteration + 1, mirror_carry=mirror_carry,
    )  # fmt: skip
    return new_state, metrics


def _tree_spec(tree_spec, like):
    """Broadcasts each TrainState field's PartitionSpec to all leaves of that field."""
    return jax.tree.map(
        lambda s, sub: jax.tree.map(lambda _: s, sub),
        tree_spec,
        like,
        is_leaf=lambda x: isinstance(x, P),
    )


def _check_env(env_shape, num_envs: int) -> None:
    """The env's batched State has the env axis first, a truncation flag and no metric under a
    trainer prefix."""
    _check_env_state(env_shape, num_envs)
    for name in ("truncation",):
        if name not in env_shape.info:
            raise ValueError(
                f"env State.info lacks {name!r} (N,); wrap Brax envs with wrap_brax_env"
            )
    clash = {"train/", "loss/", "ppo/"}
    for k in env_shape.metrics:
        if any(k.startswith(c) for c in clash):
            raise ValueError(
                f"env metric {k!r} clashes with trainer metric prefixes {sorted(clash)}"
            )


def make_train(env, cfg: ml_collections.ConfigDict, devices=None) -> Train:
    """Builds the pure, jitted init and iteration functions.

    Args:
      env: batched env (see module docstring).
      cfg: config with sections `ppo` and `network` (configs/_ppo.py).
      devices: devices of the 'data' mesh; default all devices of all hosts (`jax.devices()`).

    Returns:
      Train(init, iteration, ...). `init(key) -> TrainState`; `iteration(state) -> (state, metrics)`
      runs one rollout of ppo.num_steps steps in all envs and ppo.num_epochs x ppo.num_minibatches
      gradient steps; metrics is a dict of scalars (see `_iteration_metrics`).
    """
    ppo = cfg.ppo
    devices = list(jax.devices() if devices is None else devices)
    _validate(cfg, len(devices))
    settings = Settings.from_config(cfg)
    if settings.symmetry:  # static: the env's mirror maps ride along with the static settings
        settings = dataclasses.replace(settings, mirror=sym.env_mirror(env))
    num_envs = int(ppo.num_envs)
    networks = net.make_networks(env.action_size, cfg.network)
    optimizer = _make_optimizer(float(ppo.learning_rate), float(ppo.max_grad_norm))
    mesh = Mesh(np.array(devices), (AXIS,))

    env_shape = jax.eval_shape(env.reset, jax.ShapeDtypeStruct((num_envs, 2), jp.uint32))
    _check_env(env_shape, num_envs)
    obs_example = jax.tree.map(lambda s: jp.zeros((1,) + s.shape[1:], s.dtype), env_shape.obs)

    # Partition specs: params & co replicated, everything with an env axis sharded over AXIS.
    spec = TrainState(
        params=P(), opt_state=P(), normalizer=P(), env_state=P(AXIS), carry=P(AXIS),
        prev_done=P(AXIS), ep_return=P(AXIS), ep_length=P(AXIS), key=P(), iteration=P(),
        mirror_carry=P(AXIS) if settings.symmetry else None,
    )  # fmt: skip
    init_fn = functools.partial(
        init_state, env, networks, optimizer, mesh, num_envs, obs_example,
        symmetry=settings.symmetry,
    )  # fmt: skip
    state_shape = jax.eval_shape(init_fn, jax.ShapeDtypeStruct((2,), jp.uint32))
    state_spec = _tree_spec(spec, state_shape)
    state_sharding = jax.tree.map(
        lambda s: NamedSharding(mesh, s), state_spec, is_leaf=lambda x: isinstance(x, P)
    )
    iteration_sharded = jax.shard_map(
        functools.partial(local_iteration, env, networks, optimizer, settings),
        mesh=mesh,
        in_specs=(state_spec,),
        out_specs=(state_spec, P()),
        check_vma=False,
    )
    # The update alone (tests: the same batch on 1 device and split over several).
    mirror_spec = P(AXIS) if settings.symmetry else None
    update_sharded = jax.shard_map(
        functools.partial(local_update, networks, optimizer, settings),
        mesh=mesh,
        in_specs=(P(), P(), P(), Batch(P(None, AXIS), P(AXIS), P(AXIS), mirror_spec), P()),
        out_specs=P(),
        check_vma=False,
    )
    return Train(
        init=jax.jit(init_fn, out_shardings=state_sharding),
        iteration=jax.jit(
            iteration_sharded,
            in_shardings=(state_sharding,),
            out_shardings=(state_sharding, NamedSharding(mesh, P())),
            donate_argnums=0,
        ),
        update=jax.jit(update_sharded),
        networks=networks,
        mesh=mesh,
        state_sharding=state_sharding,
        num_envs=num_envs,
        steps_per_iteration=num_envs * settings.num_steps,
    )


def _iteration_metrics(traj: Transition, sgd_metrics: dict, log_std, params, opt_state) -> dict:
    """Scalar metrics of one iteration, reduced over all devices.

    'train/episode_return', 'train/episode_length': means over episodes finished in the rollout
    (NaN if none finished); 'train/episodes': their count; 'train/reward': mean reward per step;
    env metrics under their own names ('episode/*' averaged over done steps, others over all
    steps); 'loss/*', 'ppo/kl', 'ppo/clip_fraction', 'ppo/grad_norm' averaged over minibatches;
    'ppo/learning_rate' after the update, 'ppo/learning_rate_mean' the mean rate the
    minibatch updates used; 'ppo/action_std' mean std; 'ppo/params_finite' 1 or 0.
    """
    psum = lambda x: jax.lax.psum(x, AXIS)
    n_done = psum(jp.sum(traj.dones))
    n_steps = psum(jp.asarray(traj.dones.size, jp.float32))
    per_episode = lambda x: jp.where(n_done > 0, psum(jp.sum(x)) / jp.maximum(n_done, 1.0), jp.nan)
    m = {
        "train/episode_return": per_episode(traj.finished_return),
        "train/episode_length": per_episode(traj.finished_length),
        "train/episodes": n_done,
        "train/reward": psum(jp.sum(traj.rewards)) / n_steps,
    }
    for k, v in traj.metrics.items():
        if k.startswith(EPISODE_PREFIX):
            m[k] = per_episode(v * traj.dones)
        else:
            m[k] = psum(jp.sum(v)) / n_steps
    m.update(jax.tree.map(jp.mean, sgd_metrics))
    m["ppo/learning_rate"] = opt_state.hyperparams["learning_rate"]
    m["ppo/action_std"] = jp.mean(jp.exp(log_std))
    finite = [jp.all(jp.isfinite(x)) for x in jax.tree.leaves(params)]
    m["ppo/params_finite"] = jp.all(jp.stack(finite)).astype(jp.float32)
    return {k: jp.asarray(v, jp.float32) for k, v in m.items()}


def env_steps(iteration: int, train: Train) -> int:
    """Env steps done after `iteration` iterations."""
    return int(iteration) * train.steps_per_iteration


def num_params(params) -> int:
    return int(sum(math.prod(x.shape) for x in jax.tree.leaves(params)))


__all__ = [
    "Batch",
    "Train",
    "TrainState",
    "Transition",
    "VmapEnv",
    "Settings",
    "adapt_learning_rate",
    "env_steps",
    "epoch_minibatches",
    "init_state",
    "local_iteration",
    "local_update",
    "make_train",
    "rollout",
    "rollout_step",
    "sgd_step",
    "wrap_brax_env",
]
