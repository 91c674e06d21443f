"""Robustness evaluation, rollout analysis and policy export.

  python evaluate.py --source mock_aggre [--perturbation odometry] [--levels 0,1,2,4]
                     [--episodes 1000] [--checkpoint PATH] [--out DIR] [--config configs/...]
  python evaluate.py --source all --perturbation joint_offset     # every source
  python evaluate.py --analyze --source tof --out DIR             # one-episode analysis PNG
  python evaluate.py --export PATH [--checkpoint PATH]            # NumPy policy (.npz)

Without --checkpoint: policies/latest if present, else the newest run under runs/.
"""

import os
import sys

from absl import app, flags, logging
from ml_collections import config_flags

_CONFIG = config_flags.DEFINE_config_file("config", "configs/base.py", "Config file (configs/*.py).")
_SOURCE = flags.DEFINE_string("source", "tof", "tof | mock_ideal | mock_aggre | all.")
_PERT = flags.DEFINE_string(
    "perturbation", "none", "none | joint_offset | shank_length | odometry."
)
_LEVELS = flags.DEFINE_list("levels", None, "Perturbation levels (default: the c.eval sweep).")
_EPISODES = flags.DEFINE_integer("episodes", None, "Episodes per cell (default c.eval.episodes).")
_CHECKPOINT = flags.DEFINE_string("checkpoint", None, "Run dir, its checkpoints/ or a step dir.")
_OUT = flags.DEFINE_string("out", None, "Output directory (default c.eval.out_dir).")
_ANALYZE = flags.DEFINE_bool("analyze", False, "Rollout analysis of one episode instead.")
_EXPORT = flags.DEFINE_string("export", None, "Write the NumPy policy (.npz) to this path.")
_UNTRAINED = flags.DEFINE_bool(
    "untrained", False, "Use a freshly initialized policy (pipeline checks only)."
)

REPO_ROOT = os.path.dirname(os.path.abspath(__file__))


def _checkpoint(rb) -> str | None:
    if _UNTRAINED.value:
        return None
    if _CHECKPOINT.value:
        if not os.path.exists(_CHECKPOINT.value):
            raise FileNotFoundError(f"--checkpoint {_CHECKPOINT.value!r} does not exist")
        return _CHECKPOINT.value
    found = rb.find_checkpoint(REPO_ROOT)
    if found is None:
        raise FileNotFoundError(
            "no policy found (looked in policies/latest and runs/*/checkpoints): train first "
            "(python train.py --config configs/stage1.py) or pass --checkpoint PATH"
        )
    return found


def main(argv):
    del argv
    logging.set_verbosity(logging.WARNING)
    import jax
    from tqdm import tqdm

    from foottof.eval import plots
    from foottof.eval import robustness as rb

    cfg = _CONFIG.value
    out = _OUT.value or cfg.eval.out_dir
    try:
        sources = rb.check_source(_SOURCE.value)
        pert = _PERT.value
        levels = rb.check_levels(
            pert, _LEVELS.value if _LEVELS.value else rb.default_levels(cfg.eval, pert)
            if pert in rb.PERTURBATIONS else ()
        )
        if _LEVELS.value and pert == "none":
            raise ValueError(f"--levels {_LEVELS.value} given with --perturbation none")
        if _EPISODES.value is not None:
            if _EPISODES.value < 1:
                raise ValueError(f"--episodes {_EPISODES.value}: must be >= 1")
            cfg.eval.episodes = _EPISODES.value
        ckpt = _checkpoint(rb)
        cfg = rb.with_run_network(cfg, ckpt)
        print(f"[evaluate] policy: {ckpt or 'untrained (fresh init)'}")
        key = jax.random.PRNGKey(int(cfg.eval.seed))
        if _EXPORT.value:
            from foottof.envs import make_env
            from foottof.ppo.export import export_policy

            c, _ = rb.eval_config(cfg, "none", 0.0)
            env = make_env(c, source=sources[0], terrain_map=rb.eval_terrain_map(c, key))
            obs = jax.jit(jax.vmap(env.reset))(key[None]).obs
            nets, params, norm = rb.load_policy(c, env, obs, ckpt, key)
            print(f"[evaluate] wrote {export_policy(_EXPORT.value, nets, params, norm)}")
            return
        if _ANALYZE.value:
            if len(sources) != 1:
                raise ValueError("--analyze needs one --source, not 'all'")
            trace = rb.analyze_episode(cfg, sources[0], ckpt, key)
            path = os.path.join(out, f"analysis_{sources[0]}.png")
            rb.write_atomic({path: plots.analysis_png(trace, trace["dt"])})
            print(f"[evaluate] episode: {len(trace['foot_z'])} steps, success={trace['success']}, "
                  f"failed={trace['failed']}; wrote {path}")
            return
        rows = []
        total = len(sources) * len(levels) * int(cfg.eval.episodes)
        with tqdm(total=total, unit="ep", desc="evaluate") as bar:
            for source in sources:
                for level in levels:
                    key, k = jax.random.split(key)
                    bar.set_postfix(source=source, level=level)
                    rows.append(rb.evaluate_cell(cfg, source, pert, level, ckpt, k, bar))
        doc = rb.results_document(rows, ckpt, float(cfg.env.episode_length_s))
        paths = rb.write_results(out, _SOURCE.value, pert, doc)
    except (ValueError, FileNotFoundError) as e:
        sys.exit(f"error: {e}")
    print(rb.format_table(rows))
    print("[evaluate] wrote " + ", ".join(paths.values()))


if __name__ == "__main__":
    app.run(main)
