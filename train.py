"""Train the LSTM PPO policy: python train.py --config configs/stage1.py [--config.ppo.num_envs=...]."""

import os
import sys

from absl import app, flags, logging
from ml_collections import config_flags

_CONFIG = config_flags.DEFINE_config_file(
    "config", "configs/cpu.py", "Config file (configs/*.py).", lock_config=True
)
_RESUME = flags.DEFINE_bool("resume", False, "Continue the run in --run_dir from its latest checkpoint.")
_RUN_DIR = flags.DEFINE_string(
    "run_dir", None, "Run directory (default: <train.run_root>/<train.run_name>)."
)


def main(argv):
    del argv
    logging.set_verbosity(logging.WARNING)  # orbax logs every checkpoint write at INFO
    from foottof.envs import make_training_env
    from foottof.ppo import runner

    cfg = _CONFIG.value
    run_dir = _RUN_DIR.value or os.path.join(cfg.train.run_root, cfg.train.run_name)
    init_from = cfg.train.init_from or None
    if _RESUME.value:
        init_from = None
    elif init_from and not os.path.exists(init_from):
        sys.exit(
            f"error: train.init_from={init_from!r} does not exist; train stage 1 first "
            f"(python train.py --config configs/stage1.py) or pass --config.train.init_from=PATH"
        )
    try:
        env = make_training_env(cfg)
        runner.run(cfg, env, run_dir, resume=_RESUME.value, init_from=init_from)
    except (ValueError, FileNotFoundError, FileExistsError) as e:
        sys.exit(f"error: {e}")


if __name__ == "__main__":
    app.run(main)
