"""Python training loop: run dir, config, logs, checkpoints, resume, NaN guard, Ctrl-C."""

import csv
import io
import json
import math
import os
import time
from collections.abc import Callable

import jax
import jax.numpy as jp
import ml_collections
import numpy as np

from foottof import files, renames
from foottof.ppo import checkpoint as ckpt
from foottof.ppo import distributed, teacher
from foottof.ppo import run_dir as run_dirs
from foottof.ppo import train as train_lib
from foottof.ppo.distill import TeacherEnv

# Above these sizes on a CPU backend a run is GPU-sized: warn. bench/: 1024 envs run at the same
# env-steps/s as 256 on 2 cores (configs/stage1_cpu.py uses 512); LSTM 256 is stage1.py's GPU net.
CPU_MAX_NUM_ENVS = 1024
CPU_MAX_LSTM = 128
_WATCHED = ("loss/policy", "loss/value", "loss/entropy", "ppo/kl")  # NaN guard (plus params)


_CACHE: dict = {}  # (id(env), ppo+network json) -> (env, Train, compiled iteration); last 4 runs
_CACHE_SIZE = 4


def _cache_key(env, cfg: ml_collections.ConfigDict) -> tuple:
    dump = lambda c: c.to_json_best_effort(sort_keys=True)
    return id(env), dump(cfg.ppo), dump(cfg.network), tuple(str(d) for d in jax.devices())


def _trainer(env, cfg: ml_collections.ConfigDict):
    """make_train + compiled iteration, reused by run() calls with the same env and sections."""
    key = _cache_key(env, cfg)
    hit = _CACHE.get(key)
    if hit is not None and hit[0] is env:
        return hit[1], hit[2], True
    trainer = train_lib.make_train(env, cfg)
    if len(_CACHE) >= _CACHE_SIZE:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = (env, trainer, None)
    return trainer, None, False


class NonFiniteError(FloatingPointError):
    """A loss or a parameter became NaN/inf; training stopped, the last good checkpoint is kept."""


def _prepare_cfg(cfg: ml_collections.ConfigDict) -> ml_collections.ConfigDict:
    cfg = cfg.copy_and_resolve_references()
    cfg.lock()  # typos in later overrides raise instead of adding keys
    t = cfg.train
    for name in ("num_iterations", "checkpoint_every", "max_checkpoints", "log_every"):
        if int(t[name]) < 1:
            raise ValueError(f"train.{name}={t[name]}; must be a positive integer")
    return cfg


def _fmt_duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    return f"{seconds // 3600:d}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


def format_line(it: int, total: int, sps: float, eta_s: float, m: dict) -> str:
    """One progress line (what the runner prints per iteration)."""
    g = lambda k: m.get(k, float("nan"))
    parts = [
        f"it {it}/{total}",
        f"{sps / 1e3:.1f}k steps/s",
        f"ETA {_fmt_duration(eta_s)}",
        f"return {g('train/episode_return'):.3g}",
        f"len {g('train/episode_length'):.3g}",
    ]
    if "episode/success" in m:
        parts.append(f"success {g('episode/success'):.3f}")
    if "curriculum/level" in m:
        parts.append(f"level {g('curriculum/level'):.2f}")
    parts.append(
        f"loss pi {g('loss/policy'):.3g} v {g('loss/value'):.3g} ent {g('loss/entropy'):.3g}"
    )
    parts.append(
        f"kl {g('ppo/kl'):.3g} lr {g('ppo/learning_rate_mean'):.2e} std {g('ppo/action_std'):.3g}"
    )
    rewards = [
        f"{k[len('reward/') :]} {v:.3g}" for k, v in sorted(m.items()) if k.startswith("reward/")
    ]
    if rewards:
        parts.append("reward: " + " ".join(rewards))
    return " | ".join(parts)


class _Logs:
    """metrics.csv (appended on resume) + TensorBoard event files in the run dir."""

    def __init__(self, run_dir: str, tensorboard: bool):
        self.path = os.path.join(run_dir, "metrics.csv")
        self.fields = None
        if os.path.exists(self.path):
            with open(self.path) as f:
                header = f.readline().strip()
            self.fields = header.split(",") if header else None
        self.writer = None
        if tensorboard:
            from tensorboardX import SummaryWriter

            self.writer = SummaryWriter(run_dir)

    def write(self, row: dict, step: int) -> None:
        new = self.fields is None
        if new:
            self.fields = list(row)
        elif missing := [k for k in row if k not in self.fields]:
            self._add_columns(missing)
        buf = io.StringIO()
        w = csv.DictWriter(buf, fieldnames=self.fields, extrasaction="ignore")
        if new:
            w.writeheader()
        w.writerow(row)
        try:
            files.append_whole(self.path, buf.getvalue())  # a full disk leaves no torn row
        except OSError:
            if new:
                self.fields = None
            raise
        if self.writer is not None:
            for k, v in row.items():
                if k != "iteration" and math.isfinite(v):
                    self.writer.add_scalar(k, v, step)

    def _add_columns(self, names: list[str]) -> None:
        """A resumed run logs metrics the file lacks (new code): rewrite it with them appended
        to the header (empty in the older rows), atomically, so no column is silently dropped."""
        with open(self.path, newline="") as f:
            rows = list(csv.DictReader(f))
        self.fields = self.fields + names
        _rewrite_csv(self.path, self.fields, rows)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


def _write_config(cfg: ml_collections.ConfigDict, run_dir: str) -> None:
    path = os.path.join(run_dir, "config.json")
    text = cfg.to_json_best_effort(indent=2, sort_keys=True)
    if os.path.exists(path):
        old = renames.read_saved_config(path)
        new = json.loads(text)
        changed = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
        if changed:
            print(f"[runner] config differs from the saved one in sections {changed}; overwriting")
    files.write_atomic(
        {path: text.encode(), os.path.join(run_dir, "config.yaml"): cfg.to_yaml().encode()}
    )


def _rewrite_csv(path: str, fields: list[str], rows: list[dict]) -> None:
    """Atomically replaces the CSV at ``path`` with ``rows`` under ``fields`` (missing cells
    empty, keys outside ``fields`` dropped)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields, restval="", extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    files.write_atomic({path: buf.getvalue().encode()})


WALL_COLUMN = "time/total_h"  # cumulative wall-clock hours of the run, over all resumed chunks


def trim_metrics(run_dir: str, iteration: int) -> float:
    """Makes metrics.csv end at ``iteration`` (the checkpoint a resume starts from).

    Rows logged after the last checkpoint of a killed run are dropped, so the resumed run's rows
    follow on without repeated iterations (in a file that already repeats iterations, from before
    this trim existed, the later rows win). A file written before the cumulative wall-clock
    column existed gets it (summed from ``time/iteration_s``); renamed metric columns get their
    new names (foottof.renames.METRICS). Atomic rewrite.

    Returns:
      Cumulative wall-clock seconds of the run up to ``iteration`` (0.0 without a metrics.csv).
    """
    path = os.path.join(run_dir, "metrics.csv")
    if not os.path.exists(path):
        return 0.0
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        fields = renames.migrate_columns(list(reader.fieldnames or []))
        rows = []
        for r in reader:
            r = {
                renames.METRICS.get(k, k): v for k, v in r.items()
            }  # a row repeating an earlier iteration starts a resumed chunk: it wins
            if not r.get("iteration"):
                continue
            while rows and int(rows[-1]["iteration"]) >= int(r["iteration"]):
                rows.pop()
            rows.append(r)
    rows = [r for r in rows if int(r["iteration"]) <= iteration]
    if not fields:
        return 0.0
    if WALL_COLUMN not in fields:
        at = fields.index("time/iteration_s") + 1 if "time/iteration_s" in fields else len(fields)
        fields.insert(at, WALL_COLUMN)
        total_s = 0.0
        for r in rows:
            total_s += float(r.get("time/iteration_s") or 0.0)
            r[WALL_COLUMN] = repr(total_s / 3600.0)
    _rewrite_csv(path, fields, rows)
    return float(rows[-1][WALL_COLUMN]) * 3600.0 if rows else 0.0


def _alive(state) -> bool:
    return not any(getattr(x, "is_deleted", lambda: False)() for x in jax.tree.leaves(state))


def _params_finite(params) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(x)))) for x in jax.tree.leaves(params))


def run(
    cfg: ml_collections.ConfigDict,
    env,
    run_dir: str,
    *,
    resume: bool = False,
    init_from: str | None = None,
    on_iteration: Callable[[int, dict, train_lib.TrainState], None] | None = None,
    latest_link: str | None = None,
    init_params: Callable | None = None,
) -> train_lib.TrainState:
    """Trains for cfg.train.num_iterations iterations (counted from the start of the run).

    Args:
      cfg: full config with sections seed, ppo, network, train (copied and locked here).
      env: batched env (foottof.ppo.train module docstring).
      run_dir: folder of this run: config.json/.yaml, metrics.csv, TensorBoard events, checkpoints/.
      resume: continue from the latest checkpoint in run_dir (bit-exact when
        train.checkpoint_env_state; otherwise envs restart from a fresh reset drawn from the saved
        key folded with the iteration).
      init_from: run dir / checkpoint of another run: initial params + normalizer (stage 2 from
        stage 1); optimizer state, iteration and envs start fresh.
      on_iteration: callback(iteration, metrics, state) after each iteration (and after the NaN
        guard); `state` is donated to the next iteration, so use it only inside the callback.
      init_params: (params, normalizer) -> (params, normalizer) or None: the initial values of a
        new run without init_from (a distilled student cut from its teacher); None keeps them.
      latest_link: a symlink pointed at run_dir when the run starts (see
        run_dir.resolve_run_dir); if the run ends without any checkpoint, the link goes back to
        its previous target and run_dir, if this call created it, is removed.

    Returns:
      The final TrainState.

    Raises:
      NonFiniteError: a loss or parameter became NaN/inf (no checkpoint is written for it).
      distributed.ProcessLost: another process of a multi-process run died or stopped answering
        during training (one line naming the checkpoint to resume from); end this process with
        distributed.exit_at_once, not a normal exit, which would wait for the dead process.
      KeyboardInterrupt: re-raised after saving a checkpoint of the last finished iteration.
      foottof.files.FolderLocked: another live process writes run_dir (one line, its pid); this
        call wrote nothing. Process 0 holds the lock (run_dir/.foottof.lock) while it runs; one
        left by a killed process is taken over (a line says so).
      foottof.files.DiskFull: the disk filled (one line: run_dir, the space a checkpoint needs,
        the last complete checkpoint); no partial checkpoint or torn metrics row is left, and a
        resume continues bit-exactly once there is space.
    """
    cfg = _prepare_cfg(cfg)
    _check_start(run_dir, resume, init_from)
    main = jax.process_index() == 0  # only process 0 writes config, logs and progress lines
    created = not os.path.exists(run_dir)
    lock = files.FolderLock(run_dir, "train.py") if main else None
    if lock is not None:
        lock.acquire()  # FolderLocked: another live writer; nothing written
        if lock.took_over_pid is not None:
            print(f"[runner] took over {lock.path} from pid {lock.took_over_pid} (not running)")
    os.makedirs(run_dir, exist_ok=True)
    linked, previous = False, None
    if latest_link and main:
        try:
            previous, linked = run_dirs.point_latest(latest_link, run_dir), True
        except FileExistsError as e:
            print(f"[runner] WARNING: {e}")
    try:
        if isinstance(env, TeacherEnv) and cfg.train.teacher:
            teacher.record_teacher(run_dir, cfg, env, resume)  # teacher.json: pins the teacher
        return _run(cfg, env, run_dir, resume, init_from, on_iteration, main, init_params)
    except Exception as e:  # a collective of start-up, restore or compile failed: a peer is gone
        if isinstance(e, distributed.ProcessLost) or jax.process_count() == 1:
            raise
        if not distributed.is_lost_process(e):
            raise
        raise distributed.ProcessLost(
            distributed.lost_process_message(
                e,
                jax.process_index(),
                jax.process_count(),
                None,  # before the training loop
                run_dir,
                run_dirs.latest_checkpoint(run_dir),
            )
        ) from None
    finally:
        if lock is not None:
            lock.release()
        if linked and not run_dirs.has_checkpoint(run_dir):
            run_dirs.forget_run(latest_link, previous, run_dir if created else None)


def _check_start(run_dir: str, resume: bool, init_from: str | None) -> None:
    """Raises ValueError (resume and init_from both given), FileNotFoundError (resume without a
    checkpoint in ``run_dir``) or FileExistsError (a new run in a folder that holds checkpoints)."""
    if resume and init_from:
        raise ValueError("give resume=True or init_from, not both")
    has_ckpt = run_dirs.has_checkpoint(run_dir)
    if resume and not has_ckpt:
        raise FileNotFoundError(
            f"resume: no checkpoint in {run_dir}/{ckpt.CHECKPOINT_SUBDIR} (train.py: drop --resume)"
        )
    if not resume and has_ckpt:
        raise FileExistsError(
            f"{run_dir} already holds checkpoints; pass resume=True or a new run dir "
            f"(train.py: --resume, or another --run_dir)"
        )


def gpu_sized_warning(cfg, backend: str) -> str | None:
    """A warning line when a GPU-sized config (envs or LSTM above the CPU sizes) runs on a CPU."""
    envs, lstm = int(cfg.ppo.num_envs), int(cfg.network.lstm_hidden_size)
    if backend != "cpu" or (envs <= CPU_MAX_NUM_ENVS and lstm <= CPU_MAX_LSTM):
        return None
    return (
        f"[runner] WARNING: ppo.num_envs={envs}, network.lstm_hidden_size={lstm} is a GPU-sized "
        f"config (CPU: <= {CPU_MAX_NUM_ENVS} envs, LSTM <= {CPU_MAX_LSTM}) but JAX runs on CPU; "
        f"use a CPU config (configs/cpu.py, configs/stage1_cpu.py, configs/stage2_cpu.py)"
    )


def _starting_state(cfg, trainer, state, checkpointer, resume, init_from, init_params):
    """The state a run starts from: restored (resume), its params and normalizer read from
    ``init_from`` or made by ``init_params``, else ``state`` as initialized. Closes the
    checkpointer when reading fails (an open manager leaves orbax's event loop to fail at exit)."""
    if resume:
        try:
            state, restored_rollout = checkpointer.restore(state)
        except BaseException:
            checkpointer.close()  # an open manager leaves orbax's event loop to fail at exit
            raise
        if not restored_rollout:
            fresh = trainer.init(jax.random.fold_in(state.key, state.iteration))
            state = state.replace(**{f: getattr(fresh, f) for f in ckpt.ITEMS["rollout"]})
        print(f"[runner] resumed from iteration {int(state.iteration)} in {checkpointer.directory}")
        state = _fixed_rate_from_config(cfg, state)
    elif init_from:
        try:
            params, normalizer = ckpt.load_params_and_normalizer(
                init_from,
                state.params,
                state.normalizer,
                # a teacher (env.actor_terrain) may start from a sensor-only policy; a config
                # without the ToF env's section (a toy env's) has none
                grow_actor=bool("env" in cfg and cfg.env.actor_terrain),
            )
        except ckpt.CheckpointUnreadable as e:
            checkpointer.close()
            raise ckpt.CheckpointUnreadable(f"train.init_from {init_from!r}: {e}") from None
        except BaseException:
            checkpointer.close()
            raise
        if "env" in cfg and cfg.env.actor_terrain_fine:
            from foottof.envs import fine_terrain

            normalizer, seeded = fine_terrain.seed_normalizer(normalizer)
            if seeded:
                print("[runner] the 5 cm terrain inputs' statistics start as their 10 cm sample's")
        state = state.replace(params=params, normalizer=normalizer)
        print(f"[runner] params and normalizer initialized from {init_from}")
    elif init_params is not None:
        initial = init_params(state.params, state.normalizer)
        if initial is not None:
            shardings = jax.tree.map(lambda x: x.sharding, (state.params, state.normalizer))
            params, normalizer = jax.device_put(initial, shardings)
            state = state.replace(params=params, normalizer=normalizer)
            print("[runner] params and normalizer initialized by init_params")
    return state


def _fixed_rate_from_config(cfg, state: train_lib.TrainState) -> train_lib.TrainState:
    """A resumed run with ``ppo.lr_schedule = "fixed"`` learns at its config's rate: the
    checkpoint's optimizer state holds the rate it was saved with, which a resume that changes
    ``ppo.learning_rate`` (a branch) would otherwise keep. An adaptive rate carries on as saved."""
    if cfg.ppo.get("lr_schedule", "adaptive") != "fixed":
        return state
    saved = state.opt_state.hyperparams["learning_rate"]
    lr = float(cfg.ppo.learning_rate)
    if float(saved) != np.float32(lr):
        print(f"[runner] fixed learning rate {float(saved):.3g} -> {lr:.3g} (ppo.learning_rate)")
    new = jax.device_put(jp.asarray(lr, saved.dtype), saved.sharding)
    return state.replace(opt_state=train_lib.set_learning_rate(state.opt_state, new))


def _check_finite(metrics: dict, it: int, last_saved, directory) -> None:
    """Raises NonFiniteError naming the watched metrics (and params) that are not finite."""
    bad = [k for k in _WATCHED if not math.isfinite(metrics[k])]
    if metrics["ppo/params_finite"] < 1.0:
        bad.append("params")
    if bad:
        raise NonFiniteError(
            f"non-finite {', '.join(bad)} at iteration {it}; training stopped. Last good "
            f"checkpoint: iteration {last_saved} in {directory}"
        )


def _disk_full_logging(run_dir: str, checkpointer, it: int, state) -> str:
    """One line for a full disk met while logging iteration `it` (metrics.csv was cut back to
    its last whole row); the space needed is that of the next checkpoint."""
    last = checkpointer.latest_step()
    then = (
        f"checkpoint {last} is the last complete one. Free space there, then continue from it "
        f"(train.py --resume --run_dir {run_dir})"
        if last is not None
        else "no checkpoint is complete: free space there and start the run again"
    )
    need = checkpointer.checkpoint_bytes(state)
    return files.disk_full_message(run_dir, f"logging iteration {it}", need, then)


def _write_config_or_disk_full(cfg, run_dir: str) -> None:
    """Writes config.json and config.yaml; a full disk raises files.DiskFull (one line)."""
    try:
        _write_config(cfg, run_dir)
    except OSError as e:
        if not files.is_disk_full(e):
            raise
        size = len(cfg.to_json_best_effort(indent=2)) + len(cfg.to_yaml())
        raise files.DiskFull(
            files.disk_full_message(run_dir, "writing config.json", size, "nothing changed")
        ) from None


def _save_interrupted(state, checkpointer, last_saved: int | None) -> None:
    """On Ctrl-C: saves the last finished iteration unless it is saved or the state is gone
    (donated) or not finite; one line says which."""
    if _alive(state) and _params_finite(state.params):
        step = int(state.iteration)
        if step not in checkpointer.all_steps():
            checkpointer.save(state)
        print(f"[runner] interrupted: saved iteration {step} in {checkpointer.directory}")
    else:
        print(f"[runner] interrupted: kept checkpoint {last_saved} (state not saveable)")


def _run(
    cfg, env, run_dir, resume, init_from, on_iteration, main, init_params=None
) -> train_lib.TrainState:
    """run() after the run-dir checks; see there."""
    t = cfg.train
    if main:
        _write_config_or_disk_full(cfg, run_dir)

    warning = gpu_sized_warning(cfg, jax.default_backend())
    if warning:
        print(warning)

    trainer, iteration, cached = _trainer(env, cfg)
    key = jax.random.PRNGKey(int(cfg.get("seed", 0)))
    t_init = time.time()
    state = trainer.init(key)  # compiles env reset + network init, then dispatches it
    init_s = time.time() - t_init
    checkpointer = ckpt.Checkpointer(run_dir, int(t.max_checkpoints), bool(t.checkpoint_env_state))
    state = _starting_state(cfg, trainer, state, checkpointer, resume, init_from, init_params)
    wall_before_s = trim_metrics(run_dir, int(state.iteration)) if (resume and main) else 0.0

    t0 = time.time()  # wall clock of this chunk starts before the compile
    if iteration is None:
        iteration = trainer.iteration.lower(state).compile()
        _CACHE[_cache_key(env, cfg)] = (env, trainer, iteration)
    compile_s = time.time() - t0
    print(
        f"[runner] {len(trainer.mesh.devices.flat)} {jax.default_backend()} device(s), "
        f"{trainer.num_envs} envs x {cfg.ppo.num_steps} steps, "
        f"{train_lib.num_params(state.params)} params; init {init_s:.1f} s, "
        f"compiled in {compile_s:.1f} s" + (" (cached)" if cached else "")
    )

    logs = _Logs(run_dir, bool(t.tensorboard)) if main else None
    total = int(t.num_iterations)
    it = int(state.iteration)
    last_saved = checkpointer.latest_step()
    run_start, run_start_it = time.time(), it
    lost = None
    try:
        while it < total:
            t_it = time.time()
            state, metrics = iteration(state)
            metrics = {k: float(v) for k, v in jax.device_get(metrics).items()}
            it += 1
            dt = time.time() - t_it
            _check_finite(metrics, it, last_saved, checkpointer.directory)
            sps = trainer.steps_per_iteration / dt
            avg = (time.time() - run_start) / (it - run_start_it)
            row = {
                "iteration": it,
                "env_steps": train_lib.env_steps(it, trainer),
                "time/iteration_s": dt,
                WALL_COLUMN: (wall_before_s + time.time() - t0) / 3600.0,
                "time/compile_s": compile_s,
                "training/sps": sps,
                **metrics,
            }
            if main:
                logs.write(row, it)
            if main and (it % int(t.log_every) == 0 or it == total):
                print(format_line(it, total, sps, avg * (total - it), metrics), flush=True)
            if on_iteration is not None:
                on_iteration(it, metrics, state)
            if it % int(t.checkpoint_every) == 0 or it == total:
                last_saved = checkpointer.save(state)
    except files.DiskFull:
        raise
    except Exception as e:  # a collective's failure: JaxRuntimeError, or ValueError from jit
        if files.is_disk_full(e):  # a metrics row (cut back whole); a save raises DiskFull
            raise files.DiskFull(_disk_full_logging(run_dir, checkpointer, it, state)) from None
        if jax.process_count() == 1 or not distributed.is_lost_process(e):
            raise
        newest = run_dirs.latest_checkpoint(run_dir)
        lost = distributed.lost_process_message(
            e, jax.process_index(), jax.process_count(), it, run_dir, newest
        )
        raise distributed.ProcessLost(lost) from None
    except KeyboardInterrupt:
        _save_interrupted(state, checkpointer, last_saved)
        raise
    finally:
        if logs is not None:
            logs.close()
        if lost is None:  # after a lost process, closing could wait for it
            checkpointer.close()
    return state
