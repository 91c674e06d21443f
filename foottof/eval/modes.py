"""The one-cell modes of evaluate.py: ``--analyze`` (one episode: plots, trace, video) and
``--export`` (the actor as NumPy .npz or ONNX), with their argument checks."""

from __future__ import annotations

import os

EXPORT_FORMATS = (".npz", ".onnx")


def check_analyze(sources, plan, video_stride: int) -> None:
    """ValueError unless the plan is one source, one perturbation and one level."""
    if len(sources) != 1:
        raise ValueError("--analyze needs one --source, not 'all'")
    if len(plan) != 1 or len(plan[0][2]) != 1:
        perts = sorted({p for _, p, _ in plan})
        levels = [lv for _, _, lvs in plan for lv in lvs]
        raise ValueError(
            f"--analyze runs one cell: give one perturbation and one level "
            f"(--levels), got {'/'.join(perts)} with levels {levels}"
        )
    if video_stride < 1:
        raise ValueError(f"--video_stride {video_stride}: must be >= 1")


def analyze(cfg, plan, ckpt, key, out: str, video: str, video_stride: int) -> None:
    """One episode: analysis PNG, trace (.npz) and rollout video with the ToF rays."""
    from tqdm import tqdm

    from foottof.eval import analysis

    source, pert, (level,) = plan[0]
    env, trace = analysis.record_episode(cfg, source, ckpt, key, pert, level)
    tag = source if pert == "none" else f"{source}_{pert}_{level:g}"
    written = analysis.write_analysis(
        env,
        trace,
        out,
        tag,
        video,
        video_stride,
        progress=lambda n: tqdm(total=n, unit="frame", desc="render"),
    )
    print(
        f"[evaluate] episode: {len(trace['qpos'])} steps, success={trace['success']}, "
        f"failed={trace['failed']}; wrote {', '.join(written)}"
    )


def check_export_path(path: str) -> None:
    """ValueError naming the bad path: an unknown suffix or a folder that does not exist."""
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in EXPORT_FORMATS:
        raise ValueError(
            f"--export {path!r}: unknown suffix {suffix or '(none)'!r}; valid: "
            f"{', '.join(EXPORT_FORMATS)} (the suffix picks the format)"
        )
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise ValueError(f"--export {path!r}: folder {folder!r} does not exist")
    if os.path.isdir(path):
        raise ValueError(f"--export {path!r} is a folder; give a file name ending in {suffix}")


def export(cfg, source: str, ckpt, key, path: str) -> None:
    """The policy's actor as a NumPy .npz (foottof.ppo.export) or ONNX model (export_onnx)."""
    from foottof.eval.harness import make_eval_env_and_policy

    env, nets, params, norm = make_eval_env_and_policy(cfg, source, ckpt, key, key)
    if path.lower().endswith(".onnx"):
        try:
            from foottof.ppo import export_onnx
        except ImportError as e:
            raise RuntimeError(
                f"--export {path!r}: ONNX export needs the 'export' extra "
                f"(pip install -e '.[export]'): {e}"
            ) from None
        meta = export_onnx.deployment_metadata(cfg, env, ckpt)
        written = export_onnx.export_onnx(path, nets, params, norm, meta)
    else:
        from foottof.ppo.export import export_policy

        written = export_policy(path, nets, params, norm)
    print(f"[evaluate] wrote {written}")
