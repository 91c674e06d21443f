"""train.py end to end: bad input gives one clear error line; the CPU config learns (slow)."""

import csv
import math
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _train(*args, timeout=600):
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    return subprocess.run(
        [sys.executable, "train.py", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )


def test_unknown_config_key_is_an_error(tmp_path):
    r = _train("--config", "configs/smoke.py", "--config.ppo.num_envz=8", "--run_dir", str(tmp_path))
    assert r.returncode != 0
    assert "num_envz" in r.stderr


def test_non_positive_env_count_is_an_error(tmp_path):
    r = _train("--config", "configs/smoke.py", "--config.ppo.num_envs=0", "--run_dir", str(tmp_path))
    assert r.returncode != 0
    assert "num_envs" in (r.stderr + r.stdout)


def test_missing_init_checkpoint_is_an_error(tmp_path):
    r = _train(
        "--config",
        "configs/stage2.py",
        f"--config.train.init_from={tmp_path}/nope",
        "--run_dir",
        str(tmp_path / "run"),
    )
    assert r.returncode != 0
    assert "init_from" in r.stderr and "nope" in r.stderr


@pytest.mark.slow
def test_cpu_config_learns(tmp_path):
    """Over the 40-iteration CPU run the policy learns to stay up: episodes get longer.

    (The return itself is dominated by regularization penalties early on, so survival is the
    signal that a few CPU minutes show; success needs GPU-scale training.)
    """
    r = _train("--config", "configs/cpu.py", "--run_dir", str(tmp_path), timeout=3000)
    assert r.returncode == 0, r.stderr[-2000:]
    rows = list(csv.DictReader(open(tmp_path / "metrics.csv")))
    key = next(k for k in rows[0] if "length" in k)
    vals = [float(x[key]) for x in rows if x[key] not in ("", "nan")]
    vals = [v for v in vals if math.isfinite(v)]
    first, last = sum(vals[:5]) / 5, sum(vals[-5:]) / 5
    assert last > first, (first, last)
