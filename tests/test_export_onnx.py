"""ONNX export of the actor: parity with the JAX policy and NumpyPolicy, checker, CLI errors."""

import json
import os

import jax
import jax.numpy as jp
import numpy as np
import pytest
from helpers import REPO, run_cli

from configs import flat
from foottof.ppo import export
from foottof.ppo.networks import make_networks
from foottof.ppo.storage import checkpoint as ckpt
from foottof.ppo.storage.run_dir import with_run_network

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")
from foottof.ppo import export_onnx  # noqa: E402

FLAT = os.path.join(REPO, "policies", "flat")
EPISODE = os.path.join(REPO, "tests", "data", "flat_episode.npz")

# Tolerance: the three compute the same float32 ops in different orders (XLA fuses and
# reassociates the 181 x 256 and 64 x 256 products; NumPy and ONNX Runtime use their own BLAS).
# Each product's rounding error is ~1e-7 relative; through the LSTM's 500 recurrent steps and the
# 64-128-64-12 head the actions (|a| <~ 3) were measured to agree within 5e-7 (max over the
# episode: 4.8e-7 on the shipped flat policy). 1e-5 leaves a 20x margin and is the goal; a wrong
# gate order or a missed reset moves actions by > 1e-2.
ATOL = 1e-5


@pytest.fixture(scope="module")
def flat_policy():
    cfg = with_run_network(flat.get_config(), FLAT)
    nets = make_networks(12, cfg.network)
    obs = {"state": jp.zeros((1, 181)), "privileged_state": jp.zeros((1, 223))}
    params = nets.init_params(jax.random.PRNGKey(0), obs)
    norm = jax.tree.map(jp.asarray, nets.init_normalizer(obs))
    params, norm = ckpt.load_params_and_normalizer(FLAT, params, norm)
    return nets, params, norm


@pytest.fixture(scope="module")
def exported(flat_policy, tmp_path_factory):
    nets, params, norm = flat_policy
    d = tmp_path_factory.mktemp("export")
    onnx_path = export_onnx.export_onnx(str(d / "flat.onnx"), nets, params, norm, {"x": 1})
    npz_path = export.export_policy(str(d / "flat.npz"), nets, params, norm)
    return onnx_path, npz_path


def _jax_actions(nets, params, norm, obs, first):
    privileged = jp.zeros((obs.shape[0], 1, 223))  # the critic's input does not reach actions
    carry = nets.init_carry(1)

    def body(carry, xs):
        o, f, p = xs
        carry, mean, _, _ = nets.step(params, norm, carry, {"state": o, "privileged_state": p}, f)
        return carry, mean[0]

    xs = (jp.asarray(obs)[:, None], jp.asarray(first)[:, None], privileged)
    return np.asarray(jax.lax.scan(body, carry, xs)[1])


def _onnx_actions(path, obs, first):
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = opts.inter_op_num_threads = 1
    sess = ort.InferenceSession(path, opts, providers=["CPUExecutionProvider"])
    meta = json.loads(onnx.load(path).metadata_props[0].value)
    h = np.zeros((meta["lstm_num_layers"], 1, meta["lstm_hidden_size"]), np.float32)
    c = np.zeros_like(h)
    out = []
    for o, f in zip(obs, first, strict=True):
        if f:
            h, c = np.zeros_like(h), np.zeros_like(c)
        a, h, c = sess.run(None, {"obs": o[None], "h_in": h, "c_in": c})
        out.append(a[0])
    return np.asarray(out)


def test_onnx_runtime_equals_jax_and_numpy_on_a_recorded_episode(flat_policy, exported):
    nets, params, norm = flat_policy
    onnx_path, npz_path = exported
    with np.load(EPISODE) as f:
        obs, first = f["obs"], f["first"]
    assert obs.shape == (500, 181) and np.flatnonzero(first).tolist() == [0, 200, 400]
    want = _jax_actions(nets, params, norm, obs, first)
    got = _onnx_actions(onnx_path, obs, first)
    np_policy = export.NumpyPolicy(npz_path)
    numpy_actions = []
    for o, f in zip(obs, first, strict=True):
        if f:
            np_policy.reset()
        numpy_actions.append(np_policy(o))
    np.testing.assert_allclose(got, want, atol=ATOL, rtol=0)
    np.testing.assert_allclose(got, np.asarray(numpy_actions), atol=ATOL, rtol=0)
    assert np.abs(want).max() > 0.1  # a policy that acts, not zeros
    # Without the resets (state carried over), actions after step 200 differ: the state matters.
    carried = _onnx_actions(onnx_path, obs, np.arange(500) == 0)
    assert np.abs(carried[200:] - want[200:]).max() > 1e-2


def test_model_passes_the_checker_and_carries_its_metadata(exported):
    onnx_path, _ = exported
    model = onnx.load(onnx_path)
    onnx.checker.check_model(model, full_check=True)
    props = {p.key: json.loads(p.value) for p in model.metadata_props}
    assert props["x"] == 1 and props["foottof_network"]["obs_size"] == 181
    assert [i.name for i in model.graph.input] == list(export_onnx.INPUTS)
    assert [o.name for o in model.graph.output] == list(export_onnx.OUTPUTS)


def test_deployment_metadata_layout_covers_the_observation():
    from foottof.envs import make_env

    cfg = flat.get_config()
    cfg.terrain.num_levels, cfg.terrain.num_cols = 1, 1
    env = make_env(cfg)
    meta = export_onnx.deployment_metadata(cfg, env, "policies/flat")
    layout = meta["observation_layout"]
    assert layout[0]["start"] == 0 and layout[-1]["stop"] == env.observation_size["state"]
    assert all(a["stop"] == b["start"] for a, b in zip(layout, layout[1:], strict=False))
    assert meta["control_rate_hz"] == 50.0 and meta["action_scale"] == 0.5
    assert len(meta["default_joint_pos"]) == len(meta["joint_names"]) == 12
    json.dumps(meta)


@pytest.mark.parametrize(
    "path,message",
    [
        ("policy.pt", "unknown suffix '.pt'; valid: .npz, .onnx"),
        ("policy", "unknown suffix '(none)'"),
        ("/nonexistent/dir/policy.onnx", "folder '/nonexistent/dir' does not exist"),
    ],
)
def test_cli_bad_export_path_is_one_line(path, message, tmp_path):
    p = run_cli("evaluate.py", "--export", path, "--checkpoint", FLAT, timeout=300)
    assert p.returncode == 1
    errors = [ln for ln in p.stderr.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and message in errors[0], p.stderr[-2000:]
    assert "Traceback" not in p.stderr


def test_obs_skip_heads_export_equal_jax_and_numpy(flat_policy, tmp_path):
    """network.obs_skip: the head reads [LSTM output, normalized obs]. The flat policy grown into
    that model with its observation rows set to random weights (so the skip path carries a large
    share of each action) exports to NumPy and ONNX that agree with JAX on the recorded episode."""
    _, params, norm = flat_policy
    cfg = with_run_network(flat.get_config(), FLAT)
    cfg.network.obs_skip = True
    nets = make_networks(12, cfg.network)
    obs0 = {"state": jp.zeros((1, 181)), "privileged_state": jp.zeros((1, 223))}
    skip = jax.device_get(nets.init_params(jax.random.PRNGKey(3), obs0))
    p = jax.device_get(params)
    skip["params"]["memory_a"] = p["params"]["memory_a"]
    k = skip["params"]["actor"]["dense_0"]["kernel"]  # (64 + 181, 128), orthogonal init rows
    assert k.shape == (64 + 181, 128)
    h = p["params"]["memory_a"]["lstm_0"]["hi"]["kernel"].shape[0]
    skip["params"]["actor"]["dense_0"]["kernel"] = np.concatenate(
        [p["params"]["actor"]["dense_0"]["kernel"], k[h:]], axis=0
    )
    with np.load(EPISODE) as f:
        obs, first = f["obs"][:120], f["first"][:120]
    want = _jax_actions(nets, skip, norm, obs, first)
    onnx_path = export_onnx.export_onnx(str(tmp_path / "skip.onnx"), nets, skip, norm)
    np_policy = export.NumpyPolicy(export.export_policy(str(tmp_path / "s.npz"), nets, skip, norm))
    numpy_actions = []
    for o, f in zip(obs, first, strict=True):
        if f:
            np_policy.reset()
        numpy_actions.append(np_policy(o))
    np.testing.assert_allclose(_onnx_actions(onnx_path, obs, first), want, atol=ATOL, rtol=0)
    np.testing.assert_allclose(np.asarray(numpy_actions), want, atol=ATOL, rtol=0)
    without = _jax_actions(flat_policy[0], params, norm, obs, first)  # the same LSTM, no skip
    assert np.abs(want - without).max() > 0.1  # the skip rows move the actions
