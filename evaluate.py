"""Robustness evaluation, rollout analysis and policy export.

  python evaluate.py --source mock_aggre [--perturbation odometry] [--levels 0,1,2,4]
                     [--episodes 1000] [--checkpoint PATH] [--out DIR] [--config configs/...]
  python evaluate.py --source all --perturbation joint_offset     # every source
  python evaluate.py --source all --perturbation all              # the whole robustness figure
  python evaluate.py --analyze --source tof --out DIR             # one episode: PNG, MP4, .npz
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
    "perturbation", "none", "none | joint_offset | shank_length | odometry | all (the 3 sweeps)."
)
_LEVELS = flags.DEFINE_list("levels", None, "Perturbation levels (default: the c.eval sweep).")
_EPISODES = flags.DEFINE_integer("episodes", None, "Episodes per cell (default c.eval.episodes).")
_CHECKPOINT = flags.DEFINE_string("checkpoint", None, "Run dir, its checkpoints/ or a step dir.")
_OUT = flags.DEFINE_string("out", None, "Output directory (default c.eval.out_dir).")
_ANALYZE = flags.DEFINE_bool("analyze", False, "Rollout analysis of one episode instead.")
_VIDEO = flags.DEFINE_enum("video", "mp4", ["mp4", "gif", "none"], "--analyze: rollout video.")
_VIDEO_STRIDE = flags.DEFINE_integer("video_stride", 2, "--analyze: render every k-th step.")
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
            "(`make demo` on a CPU, python train.py --config configs/stage1.py on a GPU), pass "
            "--checkpoint PATH, or --untrained to check the pipeline with a fresh policy"
        )
    return found


def _levels(rb, cfg, pert: str) -> dict[str, tuple[float, ...]]:
    """{perturbation: levels} from the flags (--levels, else the c.eval sweep of each)."""
    if pert == "all":
        if _LEVELS.value:
            raise ValueError("--levels cannot be given with --perturbation all (each sweep "
                             "uses its c.eval levels)")
        return {p: rb.check_levels(p, rb.default_levels(cfg.eval, p))
                for p in rb.PERTURBATIONS[1:]}
    if _LEVELS.value and pert == "none":
        raise ValueError(f"--levels {_LEVELS.value} given with --perturbation none")
    given = _LEVELS.value or (rb.default_levels(cfg.eval, pert) if pert in rb.PERTURBATIONS
                              else ())
    return {pert: rb.check_levels(pert, given)}


def _check_analyze(sources, pert: str, levels: dict) -> None:
    if len(sources) != 1:
        raise ValueError("--analyze needs one --source, not 'all'")
    if pert == "all" or len(levels[pert]) != 1:
        raise ValueError(f"--analyze runs one cell: give one perturbation and one level "
                         f"(--levels), got {pert} with levels {list(levels.get(pert, ()))}")
    if _VIDEO_STRIDE.value < 1:
        raise ValueError(f"--video_stride {_VIDEO_STRIDE.value}: must be >= 1")


def _analyze(cfg, source: str, pert: str, levels: dict, ckpt, key, out: str) -> None:
    """One episode: analysis PNG, trace (.npz) and rollout video with the ToF rays."""
    from tqdm import tqdm

    from foottof.eval import analysis

    level = levels[pert][0]
    env, trace = analysis.record_episode(cfg, source, ckpt, key, pert, level)
    tag = source if pert == "none" else f"{source}_{pert}_{level:g}"
    written = analysis.write_analysis(
        env, trace, out, tag, _VIDEO.value, _VIDEO_STRIDE.value,
        progress=lambda n: tqdm(total=n, unit="frame", desc="render"),
    )
    print(f"[evaluate] episode: {len(trace['qpos'])} steps, success={trace['success']}, "
          f"failed={trace['failed']}; wrote {', '.join(written)}")


def main(argv):
    del argv
    logging.set_verbosity(logging.WARNING)
    from foottof import config_check

    try:  # before JAX is imported: a bad config value fails in a second
        config_check.check_config(_CONFIG.value)
    except ValueError as e:
        sys.exit(f"error: {e}")
    import jax
    from tqdm import tqdm

    from foottof.eval import robustness as rb
    from foottof.perception import check_source

    cfg = _CONFIG.value
    out = _OUT.value or cfg.eval.out_dir
    try:
        sources = check_source(_SOURCE.value)
        pert = _PERT.value
        levels = _levels(rb, cfg, pert)
        if _EPISODES.value is not None:
            if _EPISODES.value < 1:
                raise ValueError(f"--episodes {_EPISODES.value}: must be >= 1")
            cfg.eval.episodes = _EPISODES.value
        if _ANALYZE.value:  # flags checked before any policy is looked for or env built
            _check_analyze(sources, pert, levels)
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
            _analyze(cfg, sources[0], pert, levels, ckpt, key, out)
            return
        perts = rb.PERTURBATIONS[1:] if pert == "all" else (pert,)
        cells = [(p, lv) for p in perts for lv in levels.get(p, ())]
        rows = []
        total = len(sources) * len(cells) * int(cfg.eval.episodes)
        with tqdm(total=total, unit="ep", desc="evaluate") as bar:
            for source in sources:  # one key for all: every cell sees the same map and draws
                for p in perts:
                    bar.set_postfix(source=source, perturbation=p)
                    rows += rb.evaluate_sweep(cfg, source, p, levels[p], ckpt, key, bar)
        doc = rb.results_document(rows, ckpt, float(cfg.env.episode_length_s))
        paths = rb.write_results(out, _SOURCE.value, pert, doc)
    except (ValueError, FileNotFoundError, RuntimeError) as e:
        sys.exit(f"error: {e}")
    print(rb.format_table(rows))
    print("[evaluate] wrote " + ", ".join(paths.values()))


if __name__ == "__main__":
    app.run(main)
