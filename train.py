"""Train the LSTM PPO policy: python train.py --config configs/stage1.py [--config.ppo.num_envs=...]."""

import os
import sys

from absl import app, flags, logging
from ml_collections import config_flags

from foottof.renames import old_override  # imports no JAX

# A renamed field (e.g. --config.reward.stall_speed_ms): one line with its new name. Checked before
# DEFINE_config_file, which applies the --config.* overrides as it is defined.
if __name__ == "__main__" and (_MESSAGE := old_override(sys.argv[1:])):
    sys.exit(_MESSAGE)

_CONFIG = config_flags.DEFINE_config_file(
    "config", "configs/cpu.py", "Config file (configs/*.py).", lock_config=True
)
_RESUME = flags.DEFINE_bool(
    "resume",
    False,
    "Continue a run from its latest checkpoint: --run_dir, else the latest run "
    "<train.run_root>/<train.run_name>.",
)
_RUN_DIR = flags.DEFINE_string(
    "run_dir",
    None,
    "Run directory. Default: a new <train.run_root>/<train.run_name>-<time> per run, with the "
    "link <train.run_root>/<train.run_name> to the latest.",
)


def main(argv):
    del argv
    logging.set_verbosity(logging.WARNING)  # orbax logs every checkpoint write at INFO
    from foottof import config_check, files
    from foottof.ppo import distributed
    from foottof.ppo.storage import run_dir as run_dirs

    cfg = _CONFIG.value
    t = cfg.train
    try:  # checks that need no JAX, env or compile come first: bad input fails in a second
        setup = distributed.parse_env()  # several processes (README_multihost.md), or None
        config_check.check_config(cfg)
        if setup and setup.num_processes > 1 and not _RUN_DIR.value:
            raise ValueError(
                f"{setup.num_processes} processes ({setup.source}) write one run: give them "
                f"the same --run_dir (a folder every process can see)"
            )
        run_dir, latest = run_dirs.resolve_run_dir(
            t.run_root, t.run_name, _RUN_DIR.value, _RESUME.value
        )
        if os.path.isdir(run_dir) and (setup is None or setup.process_id == 0):
            files.FolderLock(run_dir, "train.py").acquire()  # held until exit (runner.run too)
    except (ValueError, FileNotFoundError, FileExistsError, files.FolderLocked) as e:
        sys.exit(f"error: {e}")
    if _RESUME.value:  # a resumed run keeps the stone curriculum it trained on
        overrides = config_flags.get_override_values(flags.FLAGS["config"])
        cfg, note = run_dirs.with_run_curriculum(
            cfg, os.path.join(run_dir, "config.json"), overrides
        )
        if note:
            print(f"[train] {note}")
    init_from = None if _RESUME.value else (t.init_from or None)
    if init_from and not os.path.exists(init_from):
        sys.exit(
            f"error: train.init_from={init_from!r} does not exist; train stage 1 first "
            f"(python train.py --config configs/stage1.py) or pass --config.train.init_from=PATH"
        )
    try:  # before any other JAX call; then the global device count is known, before compiling
        distributed.initialize()
        import jax

        distributed.check_num_envs(
            cfg.ppo.num_envs, cfg.ppo.num_minibatches, jax.device_count(), jax.process_count()
        )
    except ValueError as e:
        sys.exit(f"error: {e}")
    except distributed.ProcessLost as e:  # a peer never joined: stop now, as in training
        distributed.exit_at_once(str(e))
    what = "continuing" if _RESUME.value else "new run"
    print(f"[train] {what} in {run_dir}" + (f" ({latest} links to it)" if latest else ""))
    from foottof.envs import make_training_env
    from foottof.ppo import runner
    from foottof.ppo.storage.checkpoint import CheckpointUnreadable

    try:
        init_params = None
        if t.teacher:  # distillation: the teacher's env and the student's init
            from foottof.ppo import teacher

            env, init_params = teacher.make_distill_env(cfg)  # runner.run records it
        else:
            env = make_training_env(cfg)
        runner.run(
            cfg,
            env,
            run_dir,
            resume=_RESUME.value,
            init_from=init_from,
            latest_link=latest,
            init_params=init_params,
        )
    except (
        ValueError,
        FileNotFoundError,
        FileExistsError,
        runner.NonFiniteError,
        CheckpointUnreadable,
        files.FolderLocked,
        files.DiskFull,
    ) as e:  # several processes: all stop (one line each), none waits at a barrier for this one
        distributed.stop_run(f"error: {e}")
    except distributed.ProcessLost as e:  # another process died: stop now, without waiting for it
        distributed.exit_at_once(str(e))
    config_file = config_flags.get_config_filename(flags.FLAGS["config"])
    print(
        f"[train] done: {run_dir}. Evaluate: python evaluate.py --checkpoint {run_dir}; train "
        f"longer: python train.py --config {config_file} --run_dir {run_dir} --resume "
        f"--config.train.num_iterations=N"
    )


if __name__ == "__main__":
    app.run(main)
