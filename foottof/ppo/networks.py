"""Flax LSTM actor-critic (rsl_rl ActorCriticRecurrent semantics) with running obs normalization."""

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jp
import ml_collections
from brax.training.acme import running_statistics

from foottof import config_check, limits

Carry = (
    Any  # {'actor': ((c, h), ...), 'critic': ((c, h), ...)} per LSTM layer, each (B, H); () for MLP
)
Params = Any  # flax variables {'params': {...}}
Obs = Any  # (B, obs) array, or {'state': (B, obs_actor), 'privileged_state': (B, obs_critic)}

ACTIVATIONS = {"elu": nn.elu, "relu": nn.relu, "tanh": nn.tanh, "silu": nn.silu}
assert tuple(ACTIVATIONS) == limits.ACTIVATIONS  # the names config_check allows
POLICIES = limits.POLICIES
ACTOR_KEY = "state"  # Brax/Playground key of the actor observation in a dict observation
CRITIC_KEY = "privileged_state"  # key of the critic (privileged) observation


class MLP(nn.Module):
    """Dense layers with an activation between them and a linear output layer."""

    hidden: Sequence[int]
    out: int
    activation: str
    out_scale: float  # orthogonal init gain of the output layer

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        act = ACTIVATIONS[self.activation]
        for i, width in enumerate(self.hidden):
            x = nn.Dense(
                width, kernel_init=nn.initializers.orthogonal(math.sqrt(2.0)), name=f"dense_{i}"
            )(x)
            x = act(x)
        return nn.Dense(
            self.out, kernel_init=nn.initializers.orthogonal(self.out_scale), name="out"
        )(x)


class Memory(nn.Module):
    """Stacked LSTM (flax OptimizedLSTMCell; parameters 'ii','if','ig','io','hi','hf','hg','ho')."""

    hidden_size: int
    num_layers: int

    @nn.compact
    def __call__(self, carry: tuple, x: jax.Array) -> tuple[tuple, jax.Array]:
        new_carry = []
        for i in range(self.num_layers):
            layer_carry, x = nn.OptimizedLSTMCell(self.hidden_size, name=f"lstm_{i}")(carry[i], x)
            new_carry.append(layer_carry)
        return tuple(new_carry), x


class ActorCritic(nn.Module):
    """Separate memories for actor and critic, MLP heads, state-independent log std.

    One call is one control step: (carry, actor_obs (B, oa), critic_obs (B, oc)) ->
    (carry, action mean (B, A), log_std (A,), value (B,)). With `obs_skip` (recurrent only) each
    head reads its (normalized) observation beside its LSTM's output, [h, obs], so the current
    readings reach the head without passing the LSTM; the observation rows of the heads' first
    kernels are the last ones (a checkpoint without them grows into this model with those rows
    zero: foottof.ppo.storage.checkpoint).
    """

    action_size: int
    recurrent: bool
    lstm_hidden_size: int
    lstm_num_layers: int
    actor_hidden: Sequence[int]
    critic_hidden: Sequence[int]
    activation: str
    init_noise_std: float
    max_noise_std: float = 0.0  # cap on the action std (0: none); see Networks.action_log_std
    obs_skip: bool = False  # heads read [LSTM output, obs] (network.obs_skip)
    reconstruct_size: int = 0  # a decoder of this many privileged inputs (network.reconstruct)

    @nn.compact
    def __call__(self, carry: Carry, actor_obs: jax.Array, critic_obs: jax.Array):
        xa, xc = actor_obs, critic_obs
        if self.recurrent:
            carry_a, xa = Memory(self.lstm_hidden_size, self.lstm_num_layers, name="memory_a")(
                carry["actor"], xa
            )
            carry_c, xc = Memory(self.lstm_hidden_size, self.lstm_num_layers, name="memory_c")(
                carry["critic"], xc
            )
            carry = {"actor": carry_a, "critic": carry_c}
            if self.obs_skip:
                xa = jp.concatenate([xa, actor_obs], axis=-1)
                xc = jp.concatenate([xc, critic_obs], axis=-1)
        mean = MLP(self.actor_hidden, self.action_size, self.activation, 0.01, name="actor")(xa)
        if self.reconstruct_size:  # static: a student's belief decoder (read by distillation)
            recon = MLP(
                self.actor_hidden, self.reconstruct_size, self.activation, 1.0, name="decoder"
            )
            self.sow("intermediates", "reconstruction", recon(xa))
        value = MLP(self.critic_hidden, 1, self.activation, 1.0, name="critic")(xc)[..., 0]
        log_std = self.param(
            "log_std", nn.initializers.constant(math.log(self.init_noise_std)), (self.action_size,)
        )
        return carry, mean, cap_log_std(log_std, self.max_noise_std), value


def cap_log_std(log_std: jax.Array, max_noise_std: float) -> jax.Array:
    """The learned log std capped at log(max_noise_std) (no cap when max_noise_std is 0).

    Above the cap the std stays at the cap and the raw parameter gets no gradient (neither from
    the policy loss nor from the entropy bonus); below it the cap changes nothing.
    """
    if max_noise_std <= 0:
        return log_std
    return jp.minimum(log_std, math.log(max_noise_std))


def split_obs(obs: Obs) -> tuple[jax.Array, jax.Array]:
    """(actor obs, critic obs): dict -> ['state'], ['privileged_state']; array -> both."""
    if isinstance(obs, dict):
        if ACTOR_KEY not in obs:
            raise ValueError(f"dict observation needs key {ACTOR_KEY!r}; got keys {sorted(obs)}")
        return obs[ACTOR_KEY], obs.get(CRITIC_KEY, obs[ACTOR_KEY])
    return obs, obs


def select_obs(obs: Obs) -> Obs:
    """The part of an observation the networks read (what the normalizer tracks)."""
    if isinstance(obs, dict):
        actor, critic = split_obs(obs)
        return {ACTOR_KEY: actor, CRITIC_KEY: critic}
    return obs


def gaussian_log_prob(x: jax.Array, mean: jax.Array, log_std: jax.Array) -> jax.Array:
    """Log density of a diagonal Gaussian, summed over the last axis: (..., A) -> (...)."""
    z = (x - mean) * jp.exp(-log_std)
    return jp.sum(-0.5 * z**2 - log_std - 0.5 * math.log(2.0 * math.pi), axis=-1)


def gaussian_entropy(log_std: jax.Array) -> jax.Array:
    """Entropy of a diagonal Gaussian summed over actions: (A,) -> ()."""
    return jp.sum(log_std + 0.5 * math.log(2.0 * math.pi * math.e))


def gaussian_kl(mean_old, std_old, mean_new, std_new) -> jax.Array:
    """KL(old || new) of diagonal Gaussians (rsl_rl formula), summed: (..., A) -> (...)."""
    return jp.sum(
        jp.log(std_new / std_old)
        + (std_old**2 + (mean_old - mean_new) ** 2) / (2.0 * std_new**2)
        - 0.5,
        axis=-1,
    )


@dataclasses.dataclass(frozen=True)
class Networks:
    """Pure functions around the ActorCritic module; every method is jit/vmap-able."""

    module: ActorCritic
    normalize_observations: bool
    normalizer_std_eps: float

    @property
    def recurrent(self) -> bool:
        return self.module.recurrent

    def action_log_std(self, params: Params) -> jax.Array:
        """(A,) log std of the action distribution: the parameter, capped (network.max_noise_std)."""
        return cap_log_std(params["params"]["log_std"], self.module.max_noise_std)

    def init_carry(self, batch_size: int) -> Carry:
        """Zero LSTM carry for `batch_size` envs (rsl_rl resets hidden states to zero)."""
        if not self.recurrent:
            return ()
        h = self.module.lstm_hidden_size
        layer = lambda: (jp.zeros((batch_size, h)), jp.zeros((batch_size, h)))
        n = self.module.lstm_num_layers
        return {
            "actor": tuple(layer() for _ in range(n)),
            "critic": tuple(layer() for _ in range(n)),
        }

    def init_params(self, key: jax.Array, obs: Obs) -> Params:
        """Initial variables from an example observation batch `obs` (B, ...)."""
        actor_obs, critic_obs = split_obs(obs)
        carry = self.init_carry(actor_obs.shape[0])
        return self.module.init(key, carry, actor_obs, critic_obs)

    def init_normalizer(self, obs: Obs) -> running_statistics.RunningStatisticsState:
        """Running statistics with the structure of one observation (leading batch axis dropped)."""
        one = jax.tree.map(lambda x: jp.zeros(x.shape[1:], jp.float32), select_obs(obs))
        return running_statistics.init_state(one, std_eps=self.normalizer_std_eps)

    def normalize(self, normalizer, obs: Obs) -> Obs:
        obs = select_obs(obs)
        if not self.normalize_observations:
            return obs
        return running_statistics.normalize(obs, normalizer)

    def step(self, params: Params, normalizer, carry: Carry, obs: Obs, reset: jax.Array):
        """One control step for a batch of envs.

        Args:
          params: network variables.
          normalizer: running observation statistics.
          carry: LSTM carry of the previous step (B, H) leaves.
          obs: observation batch (B, ...).
          reset: (B,) bool, True where an episode starts at this step (carry -> zeros first).

        Returns:
          (carry, mean (B, A), log_std (A,), value (B,)).
        """
        return self.module.apply(params, *self._inputs(normalizer, carry, obs, reset))

    def _inputs(self, normalizer, carry: Carry, obs: Obs, reset: jax.Array):
        """(carry zeroed where an episode starts, actor obs, critic obs), normalized."""
        if self.recurrent:
            init = self.init_carry(reset.shape[0])
            carry = jax.tree.map(lambda i, c: jp.where(reset[:, None], i, c), init, carry)
        actor_obs, critic_obs = split_obs(self.normalize(normalizer, obs))
        return carry, actor_obs, critic_obs

    def unroll(self, params: Params, normalizer, carry: Carry, obs: Obs, resets: jax.Array):
        """Re-runs the policy over a rollout from its stored initial carry (truncated BPTT).

        Args:
          obs: observations (T, B, ...); resets: (T, B) episode-start flags.

        Returns:
          (means (T, B, A), log_std (A,), values (T, B)).
        """

        def f(c, xs):
            o, r = xs
            c, mean, log_std, value = self.step(params, normalizer, c, o, r)
            return c, (mean, log_std, value)

        _, (means, log_stds, values) = jax.lax.scan(f, carry, (obs, resets))
        return means, log_stds[0], values

    def unroll_reconstruction(
        self, params: Params, normalizer, carry: Carry, obs: Obs, resets: jax.Array
    ):
        """:meth:`unroll` with the decoder's output (network.reconstruct > 0): the privileged
        inputs the actor's memory reconstructs at each step (Miki et al. 2022's belief decoder).

        Returns:
          (means (T, B, A), reconstructions (T, B, reconstruct)).
        """

        def f(c, xs):
            o, r = xs
            (c, mean, _, _), state = self.module.apply(
                params, *self._inputs(normalizer, c, o, r), mutable=["intermediates"]
            )
            return c, (mean, state["intermediates"]["reconstruction"][0])

        _, (means, recons) = jax.lax.scan(f, carry, (obs, resets))
        return means, recons

    def policy_fn(self, params: Params, normalizer, deterministic: bool = True):
        """(carry, obs, reset (B,), key) -> (carry, action (B, A)); mean if deterministic."""

        def act(carry, obs, reset, key):
            carry, mean, log_std, _ = self.step(params, normalizer, carry, obs, reset)
            if deterministic:
                return carry, mean
            return carry, mean + jp.exp(log_std) * jax.random.normal(key, mean.shape)

        return act


def make_networks(action_size: int, network_cfg: ml_collections.ConfigDict) -> Networks:
    """Builds the actor-critic from c.network (see configs/_ppo.py)."""
    n = network_cfg
    config_check.check_sections({"network": n}, ("network",))  # the rules, held there once
    max_std = float(n.max_noise_std)
    obs_skip = bool(n.obs_skip)
    if obs_skip and n.policy != "lstm":
        raise ValueError(
            f"network.obs_skip=True needs network.policy='lstm' (got {n.policy!r}: an MLP "
            f"policy's heads read the observation already)"
        )
    module = ActorCritic(
        action_size=int(action_size),
        recurrent=n.policy == "lstm",
        lstm_hidden_size=int(n.lstm_hidden_size),
        lstm_num_layers=int(n.lstm_num_layers),
        actor_hidden=tuple(int(w) for w in n.actor_hidden),
        critic_hidden=tuple(int(w) for w in n.critic_hidden),
        activation=str(n.activation),
        init_noise_std=float(n.init_noise_std),
        max_noise_std=max_std,
        obs_skip=obs_skip,
        reconstruct_size=int(n.reconstruct),
    )
    return Networks(module, bool(n.normalize_observations), float(n.normalizer_std_eps))
