"""bench/gpu_check.py on the CPU (its --dry_run), and the GPU configs of the pipeline."""

import csv
import json
import os
import sys
import tarfile

import jax
import pytest
from helpers import REPO, run_cli

from configs import load_config

sys.path.insert(0, os.path.join(REPO, "bench"))
import gpu_check  # noqa: E402


def _flat(cfg) -> dict:
    out = {}

    def walk(d, prefix):
        for k, v in d.items():
            if hasattr(v, "items"):
                walk(v, f"{prefix}{k}.")
            else:
                out[prefix + k] = tuple(v) if isinstance(v, list) else v

    walk(cfg.to_dict(), "")
    return out


def _differing(a: str, b: str) -> dict:
    fa, fb = _flat(load_config(os.path.join(REPO, a))), _flat(load_config(os.path.join(REPO, b)))
    return {k: (fa.get(k), fb.get(k)) for k in sorted(set(fa) | set(fb)) if fa.get(k) != fb.get(k)}


GUIDANCE = ("reward.guidance_decay_start_iteration", "reward.guidance_decay_end_iteration")


@pytest.mark.parametrize(
    "gpu, cpu, fields",
    [
        (
            "configs/teacher_gpu.py",
            "configs/teacher_cpu.py",
            {"ppo.num_envs", "ppo.num_epochs", *GUIDANCE, "train.num_iterations"}
            | {"train.checkpoint_every", "train.init_from", "train.run_name"},
        ),
        (
            "configs/distill_gpu.py",
            "configs/distill_cpu.py",
            {"ppo.num_envs", "train.teacher", "train.num_iterations", "train.checkpoint_every"}
            | {"train.run_name"},
        ),
        (
            "configs/student_finetune_gpu.py",
            "configs/teacher_gpu.py",
            {"env.actor_terrain", "network.reconstruct", *GUIDANCE, "train.init_from"}
            | {"train.run_name"},
        ),
    ],
    ids=lambda x: os.path.basename(x) if isinstance(x, str) else "",
)
def test_gpu_config_differs_from_its_cpu_config_in_the_fields_it_names(gpu, cpu, fields):
    """Each GPU config repeats the fields of the config it scales up (a chain holds at most three
    files): they must stay equal but for the fields its docstring names, each of them named."""
    diff = _differing(gpu, cpu)
    assert set(diff) == fields, diff
    doc = open(os.path.join(REPO, gpu)).read().split('"""')[1]
    for field in fields - {"train.run_name", *GUIDANCE}:
        assert field in doc, field
    # the env-step budget of the CPU run, and the curriculum the teacher's CPU run trains on
    cfg = load_config(os.path.join(REPO, gpu))
    base = load_config(os.path.join(REPO, "configs/teacher_cpu.py"))
    assert cfg.ppo.num_envs == 4096 and cfg.terrain.stone_curriculum == "size_first"
    steps = lambda c: c.train.num_iterations * c.ppo.num_envs * c.ppo.num_steps
    assert abs(steps(cfg) / steps(base) - 1) < 0.01


def test_a_stage_over_its_budget_is_killed_and_named(tmp_path):
    with open(tmp_path / "log", "w") as log:
        s = gpu_check._Stage("slow", ["sleep", "30"], 1.0, log)
    assert s.timed_out and s.wall_s < 10
    assert s.failure() == "timed out after 1 s"
    with open(tmp_path / "log", "w") as log:
        s = gpu_check._Stage("bad", [sys.executable, "-c", "raise ValueError('x')"], 30, log)
    assert s.failure() == "exit 1: ValueError: x"


@pytest.fixture(scope="module")
def dry_run(tmp_path_factory):
    work = tmp_path_factory.mktemp("gpu_check")
    r = run_cli("bench/gpu_check.py", "--dry_run", "--work", str(work), "--out", str(work / "out"))
    return r, work


@pytest.mark.slow  # ~4.5 min of MJX compiles on 2 CPU cores: CI runs it in `make test-integration`
def test_dry_run_times_each_step_trains_the_teacher_and_hands_back_its_checkpoint(dry_run):
    """The whole check on the CPU at 32 envs: one table, every step ok, the teacher's
    metrics.csv and a checkpoint that passes its SHA-256 record, in --out."""
    from foottof.ppo.storage.integrity import integrity_problem

    r, work = dry_run
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    out = work / "out"
    assert sorted(os.listdir(out)) == [
        "gpu_check.json",
        "gpu_check.log",
        "gpu_check.txt",
        "teacher_checkpoint.tar.gz",
        "teacher_metrics.csv",
    ]
    rows = json.loads((out / "gpu_check.json").read_text())["rows"]
    assert [(x["step"], x.get("envs")) for x in rows] == [
        ("install", None),
        ("env step", 32),
        ("train iteration", 32),
        ("teacher", 32),
    ]
    for x in rows[1:]:
        assert x["status"].startswith("ok"), x
        assert x["compile_s"] > 0 and x["sps"] > 0, x
    assert (out / "gpu_check.txt").read_text().strip().endswith(rows[-1]["status"])
    metrics = list(csv.DictReader(open(out / "teacher_metrics.csv")))
    assert len(metrics) >= 1 and int(metrics[0]["env_steps"]) == 32 * 40
    with tarfile.open(out / "teacher_checkpoint.tar.gz") as tar:
        tar.extractall(work / "unpacked", filter="data")
    step_dir = work / "unpacked" / "teacher_gpu" / "checkpoints" / metrics[-1]["iteration"]
    assert integrity_problem(str(step_dir)) is None
    config = json.loads((work / "unpacked" / "teacher_gpu" / "config.json").read_text())
    assert config["train"]["init_from"] == "policies/teacher"
    assert config["env"]["physics"] == "mjx" and config["ppo"]["num_envs"] == 32
    assert "[runner] params and normalizer initialized from policies/teacher" in r.stdout


def test_a_failed_step_is_named_and_the_exit_is_not_zero(tmp_path):
    r = run_cli(
        "bench/gpu_check.py", "--dry_run", "--work", str(tmp_path), "--config", "configs/nope.py"
    )
    assert r.returncode == 1
    last = r.stdout.strip().splitlines()[-1]
    assert last == "[gpu_check] FAILED: env step 32, train iteration 32, teacher 32", last
    assert "nope.py" in (tmp_path / "gpu_check.log").read_text()


def _small(cfg):
    """``cfg`` at the tests' scale: 8 envs x 4 steps on a 2 x 5 map; its network as it is."""
    cfg.ppo.num_envs = 8
    cfg.ppo.num_steps = 4
    cfg.terrain.num_levels = 2
    cfg.terrain.num_cols = 5
    return cfg


@pytest.mark.parametrize(
    "name, start",
    [("distill_gpu", "policies/teacher"), ("student_finetune_gpu", "policies/student")],
)
def test_gpu_pipeline_config_starts_from_the_shipped_policy_and_lowers(name, start):
    """The GPU distillation and fine-tuning at small scale: they take the shipped teacher /
    distilled student (shaped as runs/teacher_gpu and runs/distill_gpu will be; the teacher's
    config is compiled in the dry run above), and their training iteration traces and lowers to
    XLA. Not compiled: XLA's CPU compile of it takes about a minute, and a GPU compiles its own."""
    from foottof.envs import make_training_env
    from foottof.ppo import teacher
    from foottof.ppo import train as train_lib
    from foottof.ppo.storage import checkpoint as ckpt

    cfg = _small(load_config(os.path.join(REPO, "configs", f"{name}.py")))
    if cfg.train.teacher:  # loads the teacher: its network must read this env's observation
        cfg.train.teacher = start
        env, _ = teacher.make_distill_env(cfg)
    else:
        env = make_training_env(cfg)
    trainer = train_lib.make_train(env, cfg)
    abstract = jax.tree.map(
        lambda s, sharding: jax.ShapeDtypeStruct(s.shape, s.dtype, sharding=sharding),
        jax.eval_shape(trainer.init, jax.random.PRNGKey(0)),
        trainer.state_sharding,
    )
    if not cfg.train.teacher:  # init_from: the saved student fits this network, leaf by leaf
        model = (abstract.params, abstract.normalizer)
        started = ckpt.load_params_and_normalizer(start, *model)
        shape = lambda tree: jax.tree.map(lambda x: (x.shape, x.dtype), tree)
        assert shape(started) == shape(model)
    hlo = trainer.iteration.lower(abstract).as_text()
    assert "while" in hlo  # the rollout's and the update's scans
