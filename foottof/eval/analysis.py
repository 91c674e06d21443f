"""One-episode rollout analysis: readings, foot heights, poses, policy I/O and the ToF rays."""

from __future__ import annotations

import io
import os

import jax
import jax.numpy as jp
import numpy as np

from foottof.eval.harness import make_eval_env_and_policy, perturbed_reset
from foottof.files import write_atomic
from foottof.robot import kinematics
from foottof.sensors import tof


def record_episode(
    cfg,
    source: str,
    checkpoint: str | None,
    key: jax.Array,
    perturbation: str = "none",
    level: float = 0.0,
):
    """Runs one evaluation episode and records it (mean actions, or sampled ones if
    ``cfg.eval.deterministic`` is False, as in the robustness cells).

    The env and policy come from ``harness.make_eval_env_and_policy`` (the robustness test
    ensemble with one perturbation cell applied, default none).

    Args:
      cfg: full config.
      source: foot-reading source, one of foottof.perception.SOURCES.
      checkpoint: checkpoint path, or None for a freshly initialized policy.
      key: PRNG key (terrain map, policy init, episode).
      perturbation, level: the perturbation cell (see foottof.eval.robustness).

    Returns:
      (env, trace): the env that ran it (``env.mj_model`` renders it) and a dict of NumPy arrays
      over the T control steps of the first episode (the step whose ``done`` starts the next
      episode is cut, since its state already shows the reset pose). Step k:
        ``policy_obs`` (T, O) actor observation the policy was given, ``actions`` (T, 12) its
        action; after the step: ``tof`` (T, F, Z) actor readings [m], ``valid`` (T, F, Z) bool,
        ``foot_z`` (T, 4) foot-centre heights [m], ``qpos`` (T, 19) physics state;
      plus ``success`` / ``failed`` (bool, the episode's outcome if it ended within T steps),
      ``dt`` [s] and ``source``.
    """
    key_map, key_init, key_run = jax.random.split(key, 3)
    env, networks, params, normalizer = make_eval_env_and_policy(
        cfg, source, checkpoint, key_map, key_init, perturbation, level
    )
    shank = env.shank_scale
    reset = jax.jit(jax.vmap(perturbed_reset(env, perturbation), in_axes=(0, None)))
    step = jax.vmap(env.step)
    state = reset(key_init[None], jp.float32(level))
    act = networks.policy_fn(params, normalizer, deterministic=bool(cfg.eval.deterministic))
    nf, nz = env.sensing.num_sensors, env.sensing.num_zones

    @jax.jit
    def run(state, key):
        def body(carry, k):
            state, lstm, first = carry
            obs_in = state.obs["state"][0]
            lstm, action = act(lstm, state.obs, first, k)
            state = step(state, action)
            qpos = state.pipeline_state.qpos[0]
            fz = kinematics.world_foot_kinematics(qpos, shank).foot_pos[:, 2]
            o = state.obs["state"][0]  # actor obs: readings (F x Z), then validity (F x Z), ...
            out = (
                obs_in,
                action[0],
                o[: nf * nz],
                o[nf * nz : 2 * nf * nz],
                fz,
                qpos,
                state.done[0],
                state.metrics["episode/success"][0],
                state.metrics["episode/failed"][0],
            )
            return (state, lstm, jp.zeros((1,), bool)), out

        init = (state, networks.init_carry(1), jp.ones((1,), bool))
        _, outs = jax.lax.scan(body, init, jax.random.split(key, env.episode_steps))
        return outs

    obs_in, actions, rd, valid, fz, qpos, done, succ, fail = jax.device_get(run(state, key_run))
    ended = bool((done > 0.5).any())
    first = int(np.argmax(done > 0.5)) if ended else len(done)
    end = max(first, 1)
    last = min(first, len(done) - 1)
    return env, {
        "policy_obs": np.asarray(obs_in[:end]),
        "actions": np.asarray(actions[:end]),
        "tof": np.asarray(rd[:end]).reshape(end, nf, nz),
        "valid": np.asarray(valid[:end]).reshape(end, nf, nz) > 0.5,
        "foot_z": np.asarray(fz[:end]),
        "qpos": np.asarray(qpos[:end]),
        "success": bool(succ[last] > 0.5),
        "failed": bool(fail[last] > 0.5),
        "dt": float(env.dt),
        "source": source,
    }


def ray_segments(env, qpos) -> dict:
    """The foot sensors' rays at recorded physics poses (what ``tof`` casts; for drawing).

    Rays start at the true sensor poses of the physics model (``env.shank_scale``) and are cast
    on the true terrain, whatever the env's source (the mocks cast into a map instead).

    Args:
      env: the AnymalToFEnv that produced ``qpos``.
      qpos: (T, 19) physics states.

    Returns:
      dict of NumPy arrays: ``origins`` (T, F, 3) sensor origins [m], ``ends`` (T, F, R, 3) hit
      points, or the point at ``max_range_m`` for rays without a hit [m], ``hit`` (T, F, R) bool.
    """
    sensing = env.sensing
    spec, hfield, feet = sensing.spec, sensing.hfield, np.asarray(sensing.feet, np.int32)

    @jax.jit
    @jax.vmap
    def one(q):
        fk = kinematics.world_foot_kinematics(q, env.shank_scale)
        origins, dirs, t, _ = tof.cast_rays(spec, hfield, fk.tof_pos[feet], fk.tof_rot[feet])
        hit = t >= 0.0
        length = jp.where(hit, t, spec.max_range_m)
        return origins, origins[:, None, :] + length[..., None] * dirs, hit

    origins, ends, hit = jax.device_get(one(jp.asarray(qpos, jp.float32)))
    return {"origins": np.asarray(origins), "ends": np.asarray(ends), "hit": np.asarray(hit)}


def write_analysis(
    env,
    trace: dict,
    out_dir: str,
    tag: str,
    video_format: str = "mp4",
    video_stride: int = 2,
    progress=None,
) -> list[str]:
    """Writes one recorded episode: analysis PNG, trace .npz and the rollout video.

    Files (in ``out_dir``): ``analysis_<tag>.png`` (plots.analysis_png), ``episode_<tag>.npz``
    (every array of ``trace``) and ``rollout_<tag>.<video_format>`` (every ``video_stride``-th
    step with the ToF rays, real time). The video is rendered before anything is written, so a
    missing OpenGL leaves no files; each file is written atomically.

    Args:
      env, trace: :func:`record_episode` output.
      out_dir: output folder (created).
      tag: file-name tag (e.g. the source).
      video_format: 'mp4', 'gif' or 'none' (no video).
      video_stride: render every k-th control step (>= 1).
      progress: optional callable(total_frames) -> tqdm-like bar for the rendering.

    Returns:
      The paths written.
    """
    from foottof.eval import plots, video

    if video_format not in (*video.FORMATS, "none"):
        raise ValueError(f"video format {video_format!r}; valid: {[*video.FORMATS, 'none']}")
    if video_stride < 1:
        raise ValueError(f"video stride {video_stride}: must be >= 1")
    frames = None
    if video_format != "none":
        qpos = trace["qpos"]
        bar = progress(-(-len(qpos) // video_stride)) if progress else None
        try:
            frames = video.render_rollout(
                env.mj_model, qpos, ray_segments(env, qpos), video_stride, progress=bar
            )
        finally:
            if bar is not None:
                bar.close()
    buf = io.BytesIO()
    np.savez_compressed(buf, **{k: np.asarray(v) for k, v in trace.items()})
    files = {
        os.path.join(out_dir, f"analysis_{tag}.png"): plots.analysis_png(trace, trace["dt"]),
        os.path.join(out_dir, f"episode_{tag}.npz"): buf.getvalue(),
    }
    write_atomic(files)
    written = list(files)
    if frames is not None:
        path = os.path.join(out_dir, f"rollout_{tag}.{video_format}")
        written.append(video.write_video(path, frames, 1.0 / (trace["dt"] * video_stride)))
    return written
