"""Tests of the one-episode analysis, the rollout video and the policy export on a real episode
(foottof/eval/analysis.py, video.py, foottof/ppo/export.py).

One env compile: a 25-step tof episode of an untrained policy on the evaluation ensemble, in a
module fixture. Oracles: MuJoCo C (site poses from mj_kinematics, mj_rayHfield) and a
decoder of the written video (imageio/ffmpeg).
"""

import os
import warnings

import imageio.v2 as imageio
import jax
import jax.numpy as jp
import mujoco
import numpy as np
import pytest

from configs import smoke
from foottof import constants
from foottof.eval import analysis, harness, video
from foottof.ppo import export

KEY = jax.random.PRNGKey(3)


def tiny_cfg():
    c = smoke.get_config()
    c.env.episode_length_s = 0.5  # 25 control steps
    c.eval.num_levels = 2
    c.eval.num_cols = 5
    return c


@pytest.fixture(scope="module")
def episode():
    cfg = tiny_cfg()
    env, trace = analysis.record_episode(cfg, "tof", None, KEY)
    return cfg, env, trace


def test_trace_shapes_and_values(episode):
    _, env, trace = episode
    t = len(trace["qpos"])
    nz = int(env.cfg.sensor.grid) ** 2
    assert 1 <= t <= env.episode_steps - 1  # the done step (reset pose) is cut
    if not trace["failed"]:
        assert t == env.episode_steps - 1
    assert trace["policy_obs"].shape == (t, env.observation_size["state"])
    assert trace["actions"].shape == (t, constants.NUM_JOINTS)
    assert trace["tof"].shape == trace["valid"].shape == (t, 4, nz)
    assert trace["foot_z"].shape == (t, 4) and trace["qpos"].shape == (t, 19)
    assert trace["valid"].dtype == bool and trace["valid"].mean() > 0.5
    # Readings: 1 mm steps in [0, 1 m] (0 = dropped reading).
    r = trace["tof"]
    assert r.min() >= 0.0 and r.max() <= float(env.cfg.sensor.max_range_m) + 1e-6
    np.testing.assert_allclose(r * 1000.0, np.round(r * 1000.0), atol=2e-3)
    # The readings in the trace are the observation the policy sees at the next step.
    np.testing.assert_array_equal(trace["policy_obs"][1:, : 4 * nz], r[:-1].reshape(t - 1, -1))
    # Foot heights are MuJoCo's foot-geom heights (mj_kinematics on the physics model).
    m, d = env.mj_model, mujoco.MjData(env.mj_model)
    ids = [m.geom(n).id for n in constants.FOOT_GEOMS]
    for k in (0, t // 2, t - 1):
        d.qpos[:] = trace["qpos"][k]
        mujoco.mj_kinematics(m, d)
        np.testing.assert_allclose(trace["foot_z"][k], d.geom_xpos[ids, 2], atol=1e-4)


def test_ray_segments_match_mujoco_c(episode):
    """Ray origins = MuJoCo's ToF site positions; hit lengths = mj_rayHfield on the terrain geom
    from the same origins and directions."""
    _, env, trace = episode
    m, d = env.mj_model, mujoco.MjData(env.mj_model)
    steps = np.linspace(0, len(trace["qpos"]) - 1, 4).astype(int)
    rays = analysis.ray_segments(env, trace["qpos"][steps])
    sites = [m.site(n).id for n in constants.TOF_SITES]
    terrain = m.geom("terrain").id
    max_range = env.sensing.spec.max_range_m
    errs, agree, n = [], 0, 0
    for i, k in enumerate(steps):
        d.qpos[:] = trace["qpos"][k]
        mujoco.mj_kinematics(m, d)
        np.testing.assert_allclose(rays["origins"][i], d.site_xpos[sites], atol=2e-4)
        for f in range(4):
            o = rays["origins"][i, f].astype(np.float64)
            for r in range(rays["ends"].shape[2]):
                v = rays["ends"][i, f, r] - o
                length = np.linalg.norm(v)
                dist = mujoco.mj_rayHfield(m, d, terrain, o, v / length)
                c_hit = 0.0 <= dist <= max_range
                n += 1
                agree += c_hit == rays["hit"][i, f, r]
                if c_hit and rays["hit"][i, f, r]:
                    errs.append(abs(dist - length))
                if not rays["hit"][i, f, r]:
                    assert length == pytest.approx(max_range, abs=1e-4)
    assert agree / n > 0.99 and len(errs) > 0.5 * n
    assert np.percentile(errs, 99) < 1e-3


def test_numpy_export_matches_jax_over_recorded_episode(episode, tmp_path):
    """The exported NumPy policy reproduces the JAX policy's actions over the recorded ANYmal
    observations (LSTM carried over the episode), with a non-trivial normalizer and output."""
    cfg, env, trace = episode
    c, _ = harness.eval_config(cfg, "none", 0.0)
    obs0 = {
        "state": jp.asarray(trace["policy_obs"][:1]),
        "privileged_state": jp.zeros((1, env.observation_size["privileged_state"])),
    }
    # The fresh policy that record_episode ran (same key split) reproduces its actions.
    key_init = jax.random.split(KEY, 3)[1]
    nets, params, norm = harness.load_policy(c, env, obs0, None, key_init)

    def replay(params, norm):
        act = jax.jit(nets.policy_fn(params, norm, deterministic=True))
        carry, out = nets.init_carry(1), []
        for k, o in enumerate(trace["policy_obs"]):
            obs = dict(obs0, state=jp.asarray(o)[None])
            carry, a = act(carry, obs, jp.array([k == 0]), None)
            out.append(np.asarray(a[0]))
        return np.array(out)

    np.testing.assert_allclose(replay(params, norm), trace["actions"], atol=1e-5)
    # Make it non-trivial: a large output layer and a non-identity normalizer.
    rng = np.random.default_rng(0)
    p = jax.tree_util.tree_map_with_path(
        lambda path, x: x * 100.0 if "out" in jax.tree_util.keystr(path) else x, params
    )
    size = trace["policy_obs"].shape[1]
    norm = norm.replace(
        mean=dict(norm.mean, state=jp.asarray(rng.normal(size=size), jp.float32)),
        std=dict(norm.std, state=jp.asarray(rng.uniform(0.5, 2.0, size), jp.float32)),
    )
    expect = replay(p, norm)
    assert np.abs(expect).max() > 0.5
    policy = export.NumpyPolicy(export.export_policy(str(tmp_path / "p"), nets, p, norm))
    got = np.array([policy(o) for o in trace["policy_obs"]])
    np.testing.assert_allclose(got, expect, atol=1e-4 * np.abs(expect).max())


def test_rays_are_drawn(episode):
    _, env, trace = episode
    q = trace["qpos"][-1]
    rays = analysis.ray_segments(env, q[None])
    with video.RolloutRenderer(env.mj_model, 320, 240) as r:
        plain = r.render(q).astype(int)
        drawn = r.render(q, rays["origins"][0], rays["ends"][0], rays["hit"][0]).astype(int)
    assert plain.shape == (240, 320, 3) and plain.std() > 5  # a scene, not a blank frame

    def green(img):  # the ray colour (RAY_HIT_RGBA): green well above red and blue
        return (
            (img[..., 1] > 150)
            & (img[..., 1] > img[..., 0] + 60)
            & (img[..., 1] > img[..., 2] + 60)
        )

    assert green(drawn).sum() > green(plain).sum() + 20
    assert (np.abs(drawn - plain).sum(-1) > 30).mean() < 0.2  # rays, not a different scene


def test_write_analysis_outputs(episode, tmp_path, monkeypatch):
    # imageio-ffmpeg's reader starts ffmpeg with preexec_fn=os.setpgrp unless this is set: a
    # preexec_fn makes Python fork the interpreter, which JAX warns about (os.fork ... deadlock)
    monkeypatch.setenv("IMAGEIO_FFMPEG_NO_PREVENT_SIGINT", "1")
    _, env, trace = episode
    stride = 8
    paths = analysis.write_analysis(env, trace, str(tmp_path), "tof", "mp4", stride)
    assert sorted(os.path.basename(p) for p in paths) == [
        "analysis_tof.png",
        "episode_tof.npz",
        "rollout_tof.mp4",
    ]
    assert sorted(os.listdir(tmp_path)) == sorted(os.path.basename(p) for p in paths)
    frames = imageio.mimread(str(tmp_path / "rollout_tof.mp4"))
    assert len(frames) == -(-len(trace["qpos"]) // stride)
    assert frames[0].shape == (480, 640, 3)
    with np.load(tmp_path / "episode_tof.npz") as f:
        np.testing.assert_array_equal(f["qpos"], trace["qpos"])
        assert bool(f["success"]) == trace["success"]
    with open(tmp_path / "analysis_tof.png", "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    gif = analysis.write_analysis(env, trace, str(tmp_path / "g"), "x", "gif", 12)[-1]
    assert len(imageio.mimread(gif)) == -(-len(trace["qpos"]) // 12)
    assert analysis.write_analysis(env, trace, str(tmp_path / "n"), "x", "none")[-1].endswith(
        "episode_x.npz"
    )


def test_terrain_is_coloured_by_height_where_it_lies():
    """A 2 m x 2 m heightfield at z = 0 with a 0.8 m deep pit in its low-y, high-x quarter, seen
    from straight above (image up = +y, right = +x): the pit's quarter of the frame is dark and
    the other three are light (a texture flipped in x or y, or none, fails)."""
    n, cell = 51, 0.04  # vertices per side, spacing [m]
    z = np.zeros((n, n))  # rows along +y, columns along +x
    z[: n // 2, n // 2 + 1 :] = -0.8
    r_m = (n - 1) * cell / 2
    m = mujoco.MjModel.from_xml_string(
        f"""<mujoco><asset><hfield name="terrain" nrow="{n}" ncol="{n}" size="{r_m} {r_m} 2 0.1"/>
        </asset><worldbody><light pos="0 0 5" dir="0 0 -1" directional="true"/>
        <geom name="terrain" type="hfield" hfield="terrain" pos="0 0 -1"/>
        <body pos="0 0 3"><freejoint/><geom size="0.01"/></body></worldbody></mujoco>"""
    )
    m.hfield_data[:] = ((z + 1.0) / 2.0).ravel()
    with video.RolloutRenderer(m, 240, 240, 2.6, 90.0, -90.0) as r:
        img = r.render(np.array([0.0, 0.0, 0.0, 1, 0, 0, 0])).mean(-1)
    q = 50  # a 50 px square inside each quarter, clear of the pit walls and the frame edge
    quarter = {
        (row, col): img[sr : sr + q, sc : sc + q].mean()
        for row, sr in (("high_y", 50), ("low_y", 240 - 50 - q))
        for col, sc in (("low_x", 50), ("high_x", 240 - 50 - q))
    }
    dark = quarter.pop(("low_y", "high_x"))
    assert dark < 60 and min(quarter.values()) > 2.5 * dark, (dark, quarter)


@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")  # the oracle (imageio's reader) forks
def test_mp4_encoder_starts_without_forking_jax(tmp_path):
    """With JAX's backend up, writing an MP4 starts ffmpeg without an os.fork of this process
    (JAX warns "os.fork() was called" from its at-fork hook, which only a fork runs), and the
    frames come back from the decoder."""
    jp.zeros(()).block_until_ready()  # JAX's backend (and its at-fork hook) up
    frames = np.zeros((3, 16, 32, 3), np.uint8)
    frames[1, :, 16:] = 255  # frame 1: right half white
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        path = video.write_video(str(tmp_path / "a.mp4"), frames, 10.0)
    assert [str(w.message) for w in caught if "fork" in str(w.message)] == []
    back = np.array(imageio.mimread(path))
    assert back.shape == frames.shape
    np.testing.assert_allclose(back, frames, atol=8)  # H.264 at CRF 15: near-lossless on flats


def test_bad_video_inputs(episode, tmp_path):
    _, env, trace = episode
    frames = np.zeros((2, 16, 16, 3), np.uint8)
    with pytest.raises(ValueError, match=r"extension must be one of \['mp4', 'gif'\]"):
        video.write_video(str(tmp_path / "a.avi"), frames, 25)
    with pytest.raises(ValueError, match="fps=0"):
        video.write_video(str(tmp_path / "a.mp4"), frames, 0)
    with pytest.raises(ValueError, match="H.264 needs even sides"):
        video.write_video(str(tmp_path / "a.mp4"), np.zeros((2, 15, 16, 3), np.uint8), 25)
    with pytest.raises(ValueError, match=r"qpos has shape \(3, 7\); expected \(T, 19\)"):
        video.render_rollout(env.mj_model, np.zeros((3, 7)))
    with pytest.raises(ValueError, match="stride=0"):
        video.render_rollout(env.mj_model, trace["qpos"], stride=0)
    with pytest.raises(ValueError, match=r"video format 'avi'"):
        analysis.write_analysis(env, trace, str(tmp_path), "t", "avi")
    with pytest.raises(ValueError, match="video stride 0"):
        analysis.write_analysis(env, trace, str(tmp_path), "t", "mp4", 0)
    assert os.listdir(tmp_path) == []  # nothing half-written


def test_no_gl_is_a_clear_error(monkeypatch):
    monkeypatch.setattr(video, "available_backends", lambda: [])
    with pytest.raises(RuntimeError, match=r"no headless OpenGL .*make render-deps"):
        video._gl_context(64, 64)


@pytest.mark.slow
def test_the_demo_episode_crosses_stones_to_the_goal():
    """`make demo`'s stone episode, as its evaluate.py command builds it (the Makefile's
    DEMO_SEED, checkpoint, config and difficulty; the run's network and stone curriculum): the
    policy ends at the goal without a fall, on a stepping-stone tile (the tile of the nearest
    nominal spawn). ~5 min on 2 CPU cores."""
    import re

    from configs import load_config
    from foottof.ppo.storage import run_dir
    from foottof.terrain import TERRAIN_TYPES

    repo = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    make = open(os.path.join(repo, "Makefile")).read()
    seed = int(re.search(r"^DEMO_SEED := (\d+)$", make, re.M).group(1))
    line = next(x for x in make.splitlines() if "--out $(DEMO_OUT)/stones" in x)
    ckpt = os.path.join(repo, re.search(r"--checkpoint (\S+)", line).group(1))
    cfg = load_config(os.path.join(repo, re.search(r"--config (\S+)", line).group(1)))
    cfg.eval.difficulty_fraction = float(re.search(r"difficulty_fraction=(\S+)", line).group(1))
    assert "--config.eval.seed=$(DEMO_SEED)" in line
    cfg.eval.seed = seed
    cfg = run_dir.with_run_network(cfg, ckpt)
    cfg, _ = run_dir.with_run_curriculum(cfg, run_dir.run_config_path(ckpt))
    env, trace = analysis.record_episode(cfg, "tof", ckpt, jax.random.PRNGKey(seed))
    assert trace["success"] and not trace["failed"]
    spawn = np.asarray(env.tmap.spawn)[..., :2]  # (rows, cols, 2)
    d2 = np.sum((spawn - trace["qpos"][0][:2]) ** 2, axis=-1)
    col = np.unravel_index(np.argmin(d2), d2.shape)[1]
    assert TERRAIN_TYPES[int(np.asarray(env.tmap.col_type)[col])].endswith("_stones")
