"""The JAX side of tests/test_distributed.py, one fresh process per call (MODE below).

The device count and the distributed runtime are fixed when JAX starts, hence processes:
python tests/multidevice_worker.py MODE OUT.

  update OUT.npz  the PPO update of one rollout batch on 1 device and split over all devices
                  (start with XLA_FLAGS=--xla_force_host_platform_device_count=2)
  run OUT_DIR [N [K]]      N (default 3) iterations of the tiny toy config through runner.run in
  resume OUT_DIR N [K]    OUT_DIR (resume: continue its run to N), a checkpoint every K (default
                          1), after foottof.ppo.distributed.initialize() (with JAX_* variables:
                          one of several processes); process 0 writes OUT_DIR/final.npz (params,
                          opt_state, normalizer); another process lost: train.py's one line and
                          exit status; FOOTTOF_TEST_DISK_FULL=P:N: process P finds the disk full
                          while saving checkpoint N (train.py's one line and exit status)
  collectives             all-gathers over all processes until stopped (with JAX_* variables)
  stall                   starts the runtime as train.py does, then waits (a long first compile)
"""

import os
import sys

TESTS = os.path.dirname(os.path.abspath(__file__))
UPDATE_ENVS, UPDATE_STEPS = 16, 8  # the update test's rollout batch


def _flat(prefix: str, tree) -> dict:
    import jax
    import numpy as np

    leaves = jax.tree_util.tree_flatten_with_path(jax.device_get(tree))[0]
    return {prefix + jax.tree_util.keystr(p): np.asarray(x) for p, x in leaves}


def update_cfg():
    """tiny_cfg with one minibatch per epoch: each SGD step then sees all local envs, so the update
    of a batch split over D devices is the same computation as on 1 device (with several
    minibatches each device draws its own minibatches: another, equally valid, SGD run)."""
    from helpers import tiny_cfg

    cfg = tiny_cfg()
    cfg.ppo.num_envs = UPDATE_ENVS
    cfg.ppo.num_steps = UPDATE_STEPS
    cfg.ppo.num_minibatches = 1
    cfg.ppo.num_epochs = 3
    return cfg


def _behaviour_batch(trainer, env, state, key, num_steps: int):
    """Batch of `num_steps` steps of the policy in `state` from its fresh envs (what the trainer's
    rollout stores, written out here on one device)."""
    import jax
    import jax.numpy as jp

    from foottof.ppo import networks as net
    from foottof.ppo import train as train_lib

    nets, params, normalizer = trainer.networks, state.params, state.normalizer
    log_std = nets.action_log_std(params)

    def step(c, key_step):
        env_state, carry, prev_done = c
        carry, mean, _, value = nets.step(params, normalizer, carry, env_state.obs, prev_done)
        action = mean + jp.exp(log_std) * jax.random.normal(key_step, mean.shape)  # ~ N(mean, std)
        new = env.step(env_state, action)
        done = new.done.astype(bool)
        zero = jp.zeros_like(new.reward)
        tr = train_lib.Transition(
            obs=env_state.obs, resets=prev_done, actions=action,
            log_probs=net.gaussian_log_prob(action, mean, log_std), means=mean, values=value,
            rewards=new.reward, dones=new.done, truncation=new.info["truncation"],
            finished_return=zero, finished_length=zero, metrics={},
        )  # fmt: skip
        return (new, carry, done), tr

    c0 = (state.env_state, state.carry, state.prev_done)
    (env_state, carry, prev_done), traj = jax.lax.scan(step, c0, jax.random.split(key, num_steps))
    _, _, _, last_value = nets.step(params, normalizer, carry, env_state.obs, prev_done)
    return train_lib.Batch(traj, state.carry, last_value)


def update(out: str) -> None:
    import jax
    import numpy as np
    import toy_envs

    from foottof.ppo import train as train_lib

    assert jax.device_count() >= 2, jax.devices()
    env = toy_envs.make_memory_env(episode_length=3)  # episodes end inside the batch
    cfg = update_cfg()
    one = train_lib.make_train(env, cfg, devices=jax.devices()[:1])
    split = train_lib.make_train(env, cfg, devices=jax.devices())
    state = jax.device_get(one.init(jax.random.PRNGKey(0)))
    behaviour = jax.jit(lambda s, k: _behaviour_batch(one, env, s, k, UPDATE_STEPS))
    batch = jax.device_get(behaviour(state, jax.random.PRNGKey(1)))
    args = (state.params, state.opt_state, state.normalizer, batch, jax.random.PRNGKey(2))
    arrays = _flat("before", (state.params, state.opt_state, state.normalizer))
    for name, trainer in (("one", one), ("split", split)):
        arrays.update(_flat(name, trainer.update(*args)))
    arrays["devices"] = np.array([1, len(split.mesh.devices.flat)])
    np.savez(out, **arrays)


DISK_FULL_VAR = "FOOTTOF_TEST_DISK_FULL"  # "P:N": process P finds the disk full at checkpoint N


def _disk_full_at(step: int) -> None:
    """This process's array writes into checkpoint `step` fail as TensorStore fails on a full
    disk (what orbax 0.12.8 raised on a 4 MB tmpfs); its other writes and other processes'
    succeed."""
    from orbax.checkpoint._src.serialization import serialization

    real = serialization.async_serialize_from_host

    async def write(rslices, spec, *args, **kwargs):
        if f"/{step}.orbax-checkpoint-tmp" in str(spec):
            raise ValueError(
                f"RESOURCE_EXHAUSTED: Error writing local file in checkpoint {step}: Failed to "
                "write 1231 bytes to file 41: No space left on device [os_error_code='28']"
            )
        return await real(rslices, spec, *args, **kwargs)

    serialization.async_serialize_from_host = write


def run(out_dir: str, iterations: str = "3", every: str = "1", resume: bool = False) -> None:
    from foottof.ppo import distributed  # imports no JAX

    setup = distributed.initialize()  # before any other JAX call
    import jax
    import numpy as np
    import toy_envs
    from helpers import tiny_cfg

    from foottof import files
    from foottof.ppo import runner

    if full := os.environ.get(DISK_FULL_VAR):
        process, step = full.split(":")
        if int(process) == jax.process_index():
            _disk_full_at(int(step))
    cfg = tiny_cfg(num_iterations=int(iterations), checkpoint_every=int(every), tensorboard=False)
    try:
        state = runner.run(cfg, toy_envs.make_memory_env(), out_dir, resume=resume)
    except files.DiskFull as e:  # as train.py
        distributed.stop_run(f"error: {e}")
    except distributed.ProcessLost as e:  # as train.py
        distributed.exit_at_once(str(e))
    print(
        f"[worker] setup {setup}, {jax.process_count()} process(es), {jax.device_count()} devices"
    )
    if jax.process_index() == 0:
        np.savez(
            os.path.join(out_dir, "final.npz"),
            **_flat("", (state.params, state.opt_state, state.normalizer)),
        )


def collectives() -> None:
    """All-gathers over all processes, 10 a second, until stopped (a hung process's test)."""
    from foottof.ppo import distributed

    distributed.initialize()
    import itertools
    import time

    from jax.experimental import multihost_utils

    for i in itertools.count():
        multihost_utils.sync_global_devices(f"beat {i}")  # an all-gather of every process
        if i == 0:
            print("[worker] collectives running", flush=True)
        time.sleep(0.1)


def stall() -> None:
    """train.py's start-up, then 10 min without a collective (the first compile of a big env):
    only the heartbeats can tell that another process is gone."""
    import time

    from foottof.ppo import distributed

    try:
        distributed.initialize()
    except distributed.ProcessLost as e:  # as train.py
        distributed.exit_at_once(str(e))
    print("[worker] started", flush=True)
    time.sleep(600)


if __name__ == "__main__":
    sys.path[:0] = [os.path.dirname(TESTS), TESTS]  # the repo (configs, foottof) and helpers
    mode, args = sys.argv[1], sys.argv[2:]
    if mode == "resume":
        run(*args, resume=True)
    else:
        modes = {"update": update, "run": run, "collectives": collectives, "stall": stall}
        modes[mode](*args)
