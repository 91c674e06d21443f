"""Robustness evaluation, rollout analysis and policy export.

  python evaluate.py --source mock_aggre [--perturbation odometry] [--levels 0,1,2,4]
                     [--episodes 1000] [--checkpoint PATH] [--out DIR] [--config configs/...]
  python evaluate.py --source mock_aggre     # its default sweep: odometry (the paper's panel C)
  python evaluate.py --source all --perturbation joint_offset     # every source
  python evaluate.py --source all --perturbation all              # the whole robustness figure
  python evaluate.py --analyze --source tof --out DIR             # one episode: PNG, MP4, .npz
  python evaluate.py --export PATH.npz|PATH.onnx [--checkpoint PATH]  # NumPy or ONNX actor

Without --checkpoint: policies/latest if present, else the newest run under runs/.
"""

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
    "config", "configs/base.py", "Config file (configs/*.py)."
)
_SOURCE = flags.DEFINE_string("source", "tof", "tof | mock_ideal | mock_aggre | all.")
_PERT = flags.DEFINE_string(
    "perturbation",
    None,
    "none | joint_offset | shank_length | odometry | all (the 3 sweeps). Default: each source's "
    "sweep in the paper's robustness figure: tof -> joint_offset, mock_ideal -> joint_offset, "
    "mock_aggre -> odometry (robustness.HEADLINE_SWEEPS); none with --analyze / --export.",
)
_LEVELS = flags.DEFINE_list("levels", None, "Perturbation levels (default: the c.eval sweep).")
_EPISODES = flags.DEFINE_integer("episodes", None, "Episodes per cell (default c.eval.episodes).")
_CHECKPOINT = flags.DEFINE_string("checkpoint", None, "Run dir, its checkpoints/ or a step dir.")
_OUT = flags.DEFINE_string("out", None, "Output directory (default c.eval.out_dir).")
_ANALYZE = flags.DEFINE_bool("analyze", False, "Rollout analysis of one episode instead.")
_VIDEO = flags.DEFINE_enum("video", "mp4", ["mp4", "gif", "none"], "--analyze: rollout video.")
_VIDEO_STRIDE = flags.DEFINE_integer("video_stride", 2, "--analyze: render every k-th step.")
_EXPORT = flags.DEFINE_string(
    "export",
    None,
    "Write the actor to this path: .npz (NumPy) or .onnx (ONNX, explicit LSTM state).",
)
_UNTRAINED = flags.DEFINE_bool(
    "untrained", False, "Use a freshly initialized policy (pipeline checks only)."
)

REPO_ROOT = os.path.dirname(os.path.abspath(__file__))


def _cell_store(cfg, out: str, ckpt: str | None, draws: dict):
    """The finished-cell store of this evaluation (foottof.eval.cells): a rerun of an
    interrupted command loads the cells it already finished."""
    from foottof.eval import results
    from foottof.eval.cells import CellStore, cell_identity
    from foottof.ppo.storage.integrity import policy_digest

    policy = policy_digest(ckpt) if ckpt else "untrained"
    cap = results.action_std_cap(cfg)
    return CellStore(out, cell_identity(policy, draws, bool(cfg.eval.deterministic), cap))


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

    from foottof.eval import modes, results
    from foottof.eval import robustness as rb
    from foottof.perception import check_source
    from foottof.ppo.storage.run_dir import (
        resolve_checkpoint,
        run_config_path,
        with_run_curriculum,
        with_run_network,
    )

    cfg = _CONFIG.value
    out = _OUT.value or cfg.eval.out_dir
    try:
        sources = check_source(_SOURCE.value)
        pert = _PERT.value or ("none" if _ANALYZE.value or _EXPORT.value else None)
        plan = rb.sweep_plan(cfg.eval, sources, pert, _LEVELS.value)
        if _EPISODES.value is not None:
            if _EPISODES.value < 1:
                raise ValueError(f"--episodes {_EPISODES.value}: must be >= 1")
            cfg.eval.episodes = _EPISODES.value
        if not (_ANALYZE.value or _EXPORT.value):
            print(rb.plan_line(plan, int(cfg.eval.episodes), int(cfg.eval.num_envs)), flush=True)
        if _ANALYZE.value:  # flags checked before any policy is looked for or env built
            modes.check_analyze(sources, plan, _VIDEO_STRIDE.value)
        if _EXPORT.value:
            modes.check_export_path(_EXPORT.value)
        ckpt = resolve_checkpoint(_CHECKPOINT.value, _UNTRAINED.value, REPO_ROOT)
        overrides = config_flags.get_override_values(flags.FLAGS["config"])
        cfg = with_run_network(cfg, ckpt, overrides)
        cfg, note = with_run_curriculum(cfg, ckpt and run_config_path(ckpt), overrides)
        if note:
            print(f"[evaluate] {note}")
        cap = results.action_std_cap(cfg)
        acts = "mean actions" if cap is None else "actions sampled at the action std"
        acts += f", capped at {cap:g}" if cap else ""
        print(f"[evaluate] policy: {ckpt or 'untrained (fresh init)'} ({acts})")
        key = jax.random.PRNGKey(int(cfg.eval.seed))
        if _EXPORT.value:
            modes.export(cfg, sources[0], ckpt, key, _EXPORT.value)
            return
        if _ANALYZE.value:
            modes.analyze(cfg, plan, ckpt, key, out, _VIDEO.value, _VIDEO_STRIDE.value)
            return
        draws = results.episode_draws(cfg)
        store = _cell_store(cfg, out, ckpt, draws)
        total = sum(len(levels) for _, _, levels in plan) * int(cfg.eval.episodes)
        with tqdm(total=total, unit="ep", desc="evaluate") as bar:
            rows, outcomes = rb.run_sweeps(cfg, plan, ckpt, key, bar, True, store)
        if store.loaded:
            print(f"[evaluate] {len(store.loaded)} cell(s) resumed from {out}/cells")
        paths = results.write_run(
            out,
            _SOURCE.value,
            pert,
            rows,
            ckpt,
            float(cfg.env.episode_length_s),
            outcomes,
            draws,
            ensemble=results.ensemble_setting(cfg),
        )
    except (ValueError, FileNotFoundError, RuntimeError) as e:
        sys.exit(f"error: {e}")
    store.clear()  # the results files now hold every cell
    print(results.format_table(rows))
    per_episode = results.episodes_document(list(zip(rows, outcomes, strict=True)), ckpt, draws)
    print(results.format_terrain_breakdown(results.terrain_breakdown(per_episode)))
    print("[evaluate] wrote " + ", ".join(paths))


if __name__ == "__main__":
    app.run(main)
