"""Several devices and processes (foottof/ppo/distributed.py, README_multihost.md).

The setup read from env vars, the sharded update against the unsharded one, 2 processes x 1
device against 1 process x 2 devices.

The JAX side of the multi-device tests runs in fresh processes (tests/multidevice_worker.py): the
device count and the distributed runtime are fixed when JAX starts.
"""

import csv
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import multidevice_worker as w
import numpy as np
import pytest

from foottof.ppo import distributed

TESTS = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(TESTS)
WORKER = os.path.join(TESTS, "multidevice_worker.py")
U = 2.0**-24  # float32 unit roundoff


_env = distributed.local_cpu_environ
_free_port = distributed.free_local_port


def _start(cmd: list[str], n: int, **extra) -> list[subprocess.Popen]:
    """`cmd` started as processes 0..n-1 of one distributed run on localhost."""
    address = f"localhost:{_free_port()}"
    return [
        subprocess.Popen(
            cmd,
            cwd=ROOT,
            env=_env(
                JAX_COORDINATOR_ADDRESS=address,
                JAX_NUM_PROCESSES=str(n),
                JAX_PROCESS_ID=str(i),
                **extra,
            ),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(n)
    ]


def _finish(p: subprocess.Popen, timeout: float) -> subprocess.CompletedProcess:
    stdout, stderr = p.communicate(timeout=timeout)
    return subprocess.CompletedProcess(p.args, p.returncode, stdout, stderr)


def _processes(cmd: list[str], n: int, timeout: int, **extra) -> list[subprocess.CompletedProcess]:
    """`cmd` as processes 0..n-1 of one distributed run on localhost; their finished results."""
    return [_finish(p, timeout) for p in _start(cmd, n, **extra)]


# ------------------------------------------------------------------------ setup from env vars
JAX3 = {"JAX_COORDINATOR_ADDRESS": "host0:1234", "JAX_NUM_PROCESSES": "2", "JAX_PROCESS_ID": "1"}
SLURM = {
    "SLURM_JOB_ID": "777",
    "SLURM_STEP_NODELIST": "node[001-002]",
    "SLURM_NTASKS": "4",
    "SLURM_PROCID": "3",
    "SLURM_LOCALID": "1",
}


def test_parse_env_reads_the_jax_and_slurm_variables():
    assert distributed.parse_env({}) is None  # one process: nothing starts
    assert distributed.parse_env({"HOME": "/root", "JAX_PLATFORMS": "cpu"}) is None
    beat = 60  # the default heartbeat timeout [s] foottof/ppo/README_multihost.md documents
    assert distributed.parse_env(JAX3) == ("host0:1234", 2, 1, "env", beat)
    # A SLURM step of 4 tasks: count and id from SLURM, the address left to JAX (nodelist).
    assert distributed.parse_env(SLURM) == (None, 4, 3, "slurm", beat)
    over = {**SLURM, "JAX_COORDINATOR_ADDRESS": "node001:5555"}
    assert distributed.parse_env(over) == ("node001:5555", 4, 3, "slurm", beat)
    fast = {**JAX3, "FOOTTOF_HEARTBEAT_TIMEOUT_S": "10"}
    assert distributed.parse_env(fast) == ("host0:1234", 2, 1, "env", 10)
    # A SLURM job of one task (sbatch, salloc shell) stays one process with all its GPUs.
    one = {**SLURM, "SLURM_NTASKS": "1", "SLURM_PROCID": "0", "SLURM_LOCALID": "0"}
    assert distributed.parse_env(one) is None
    # An allocation without a step (no SLURM_STEP_NODELIST): not a SLURM step.
    assert distributed.parse_env({k: v for k, v in SLURM.items() if "STEP" not in k}) is None


@pytest.mark.parametrize(
    "environ, message",
    [
        (
            {**JAX3, "JAX_PROCESS_ID": "2"},
            "JAX_PROCESS_ID=2 is out of range for JAX_NUM_PROCESSES=2 (ids are 0..1)",
        ),
        (
            {**JAX3, "JAX_PROCESS_ID": "-1"},
            "JAX_PROCESS_ID=-1 is out of range for JAX_NUM_PROCESSES=2 (ids are 0..1)",
        ),
        (
            {**JAX3, "JAX_NUM_PROCESSES": "0", "JAX_PROCESS_ID": "0"},
            "JAX_NUM_PROCESSES=0: the process count must be >= 1",
        ),
        ({**JAX3, "JAX_PROCESS_ID": "one"}, "JAX_PROCESS_ID='one' is not an integer"),
        (
            {"JAX_COORDINATOR_ADDRESS": "host0:1234", "JAX_PROCESS_ID": "0"},
            "JAX_NUM_PROCESSES not set (JAX_COORDINATOR_ADDRESS=host0:1234, JAX_PROCESS_ID=0): "
            "set all of JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES, JAX_PROCESS_ID to run "
            "several processes, or none for one",
        ),
        (
            {**JAX3, "JAX_COORDINATOR_ADDRESS": "host0"},
            "JAX_COORDINATOR_ADDRESS='host0' is not host:port (e.g. host0:1234, the address of "
            "process 0)",
        ),
        (
            {**SLURM, "SLURM_PROCID": "4"},
            "SLURM_PROCID=4 is out of range for SLURM_NTASKS=4 (ids are 0..3)",
        ),
        (
            {**SLURM, "JAX_PROCESS_ID": "5"},
            "JAX_PROCESS_ID=5 is out of range for SLURM_NTASKS=4 (ids are 0..3)",
        ),
        (
            {**JAX3, "FOOTTOF_HEARTBEAT_TIMEOUT_S": "0"},
            "FOOTTOF_HEARTBEAT_TIMEOUT_S=0: the heartbeat timeout must be >= 1 s",
        ),
        (
            {**JAX3, "FOOTTOF_HEARTBEAT_TIMEOUT_S": "1m"},
            "FOOTTOF_HEARTBEAT_TIMEOUT_S='1m' is not an integer",
        ),
    ],
)
def test_parse_env_bad_setup_is_one_line_naming_the_values(environ, message):
    with pytest.raises(ValueError) as e:
        distributed.parse_env(environ)
    assert str(e.value) == message


def test_check_num_envs_names_the_global_device_count():
    distributed.check_num_envs(16, 2, 4, 2)  # 16 envs = 4 devices x 2 minibatches x 2 envs
    with pytest.raises(ValueError) as e:
        distributed.check_num_envs(12, 2, 4, 2)
    assert str(e.value) == (
        "ppo.num_envs=12 is not divisible by ppo.num_minibatches * devices = 2 * 4 (4 device(s) "
        "over 2 processes); each device steps num_envs / devices envs in whole minibatches"
    )
    with pytest.raises(ValueError, match=r"= 2 \* 3 \(3 device\(s\)\);"):
        distributed.check_num_envs(8, 2, 3)


def test_train_py_bad_setup_fails_in_one_line_before_jax(tmp_path):
    """train.py reads the setup first: a process id out of range, or several processes without a
    shared --run_dir, is one error line, before JAX is even imported (a `jax` package that fails
    on import comes first on the path) and before any run folder is written."""
    fake = tmp_path / "fake" / "jax"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('jax imported before the setup check')")
    path = os.pathsep.join([str(fake.parent), ROOT, os.environ.get("PYTHONPATH", "")])
    train = [sys.executable, "train.py", "--config", "configs/smoke.py"]
    root = f"--config.train.run_root={tmp_path / 'runs'}"

    def run(args, **variables):
        return subprocess.run(
            [*train, root, *args],
            cwd=ROOT,
            env=_env(**variables, PYTHONPATH=path),
            capture_output=True,
            text=True,
            timeout=120,
        )

    r = run(["--run_dir", str(tmp_path / "run")], **{**JAX3, "JAX_PROCESS_ID": "2"})
    assert r.returncode != 0
    assert r.stderr.strip().splitlines() == [
        "error: JAX_PROCESS_ID=2 is out of range for JAX_NUM_PROCESSES=2 (ids are 0..1)"
    ]
    r = run([], **JAX3)
    assert r.returncode != 0
    assert r.stderr.strip().splitlines() == [
        "error: 2 processes (env) write one run: give them the same --run_dir (a folder every "
        "process can see)"
    ]
    assert not os.path.exists(tmp_path / "run") and not os.path.exists(tmp_path / "runs")


# ------------------------------------------------------------------------ a process dies
GLOO_RESET = (  # what process 0 caught when process 1 was killed (jaxlib 0.10.2, CPU)
    "UNKNOWN: Gloo all-reduce failed: [external/gloo/gloo/transport/tcp/pair.cc:538] Read error "
    "[127.0.0.1]:42731: Connection reset by peer"
)


def test_lost_process_message_names_the_process_and_the_checkpoint():
    e = RuntimeError(GLOO_RESET + "\nsecond line")
    assert distributed.lost_process_message(e, 0, 2, 7, "/runs/a", 6) == (
        f"[distributed] process 1 of 2 stopped responding after iteration 7 ({GLOO_RESET}); "
        "process 0 stops. Resume: start all 2 again with --resume --run_dir /runs/a; they "
        "continue from iteration 6, the last complete checkpoint"
    )
    line = distributed.lost_process_message(RuntimeError("x" * 500), 3, 8, 0, "/runs/b", None)
    assert line == (
        f"[distributed] another of the 8 processes stopped responding after iteration 0 "
        f"({'x' * 197}...); process 3 stops. No checkpoint is complete: start all of them again "
        "without --resume"
    )


def test_only_communication_errors_count_as_a_lost_process():
    assert distributed.is_lost_process(RuntimeError(GLOO_RESET))
    assert distributed.is_lost_process(
        RuntimeError("UNAVAILABLE: Task 1 heartbeat timeout. This indicates that the remote task")
    )
    assert not distributed.is_lost_process(
        RuntimeError("RESOURCE_EXHAUSTED: Out of memory while trying to allocate 1.2GiB")
    )
    assert not distributed.is_lost_process(RuntimeError("INVALID_ARGUMENT: shape mismatch"))


# ------------------------------------------------------------------- sharded = unsharded update
def _update_tolerance(one, name: str, lr: float) -> float:
    """atol of the leaf `name` (see test_sharded_update_equals_unsharded)."""
    n = w.UPDATE_ENVS * w.UPDATE_STEPS  # terms of every batch mean
    steps = w.update_cfg().ppo.num_epochs  # one minibatch per epoch
    scale = float(np.max(np.abs(one))) if one.size else 0.0
    if name.startswith("[0]"):  # params
        return steps * (2 * U * scale + 2 * n * U * lr)
    if ".nu" in name:  # Adam's second moment, ~ g^2
        return 2 * n * U * scale
    if name.startswith("[3]"):  # metrics: losses are means of O(1) terms
        return n * U * max(scale, 1.0)
    return n * U * scale  # gradients (Adam's first moment), normalizer, counts


def test_sharded_update_equals_unsharded(tmp_path):
    """The same rollout batch (16 envs x 8 steps of the memory task, episodes of 3 steps) updated
    on 1 device and split over 2 (8 envs each) gives the same gradients and new params.

    One minibatch per epoch (3 epochs): every SGD step then reads all local envs, so each device
    computes the gradient of the mean over its half and `pmean` makes the mean over all; only the
    order of the float32 sums differs (the shuffle permutes envs inside a mean). Tolerance, per
    leaf, from that order: a sum of n = 16 x 8 = 128 (time, env) terms summed in another order
    moves by at most about n u sum|terms| (Higham, Accuracy and Stability, ch. 4), u = 2^-24:
    - gradients (Adam's first moment, and the normalizer): n u max|leaf| = 7.6e-6 max|leaf|;
      Adam's second moment (~ g^2) twice that;
    - losses, KL and grad norm (means of O(1) terms: unit-variance advantages, ratio ~ 1):
      n u max(|x|, 1);
    - params after K = 3 Adam steps: each step lr m/sqrt(v) is scale-free in g, so a relative
      gradient error n u moves it by <= 2 n u lr, and the subtraction rounds by <= 2 u |p|
      (an ulp): K (2 u max|p| + 2 n u lr).
    Measured on a 2-core x86 CPU: every leaf within 1/5 of its tolerance (params ~1e-7, 1 ulp).
    The params must also have moved by far more than the tolerance (the update did something).
    """
    out = tmp_path / "update.npz"
    r = subprocess.run(
        [sys.executable, WORKER, "update", str(out)],
        cwd=ROOT,
        env=_env(devices=2),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    d = np.load(out)
    assert d["devices"].tolist() == [1, 2]
    lr = float(np.max(d["one[3]['ppo/learning_rate_mean']"]))
    names = [k[len("one") :] for k in d if k.startswith("one")]
    assert len(names) > 50
    bad = []
    for name in names:
        one, split = d["one" + name], d["split" + name]
        atol = _update_tolerance(one, name, lr)
        err = float(np.max(np.abs(one - split))) if one.size else 0.0
        if not err <= atol:
            bad.append(f"{name}: |1 device - 2 devices| = {err:.3g} > {atol:.3g}")
    assert not bad, "\n".join(bad)
    moved = [
        float(np.max(np.abs(d["one" + n] - d["before" + n])))
        for n in names
        if n.startswith("[0]") and "lstm_0']['if']" not in n  # the forget gate's input rows: 0
    ]
    params_tol = max(_update_tolerance(d["one" + n], n, lr) for n in names if n.startswith("[0]"))
    assert min(moved) > 100 * params_tol, (min(moved), params_tol)


# -------------------------------------------------- 2 processes x 1 device = 1 process x 2 devices
def _metrics(run_dir) -> list[dict]:
    """metrics.csv rows without the wall-clock columns."""
    with open(os.path.join(run_dir, "metrics.csv")) as f:
        rows = list(csv.DictReader(f))
    return [
        {k: v for k, v in r.items() if not k.startswith(("time/", "training/sps"))} for r in rows
    ]


def _ok(r: subprocess.CompletedProcess) -> str:
    assert r.returncode == 0, (r.stdout[-2000:], r.stderr[-4000:])
    return r.stdout


@pytest.mark.slow
def test_two_processes_equal_two_devices_and_resume(tmp_path):  # ~2.5 min on a busy 2-core CPU
    """The tiny toy config (8 envs x 4 steps) for 5 iterations: 1 process x 2 devices straight
    through, against 2 processes x 1 device on localhost (jax.distributed, gloo CPU collectives)
    for 3 iterations into one run folder, then resumed by 2 new processes to 5. Both meshes hold
    2 devices and device i draws fold_in(key, i), so the streams match; an all-reduce over 2
    values, (a + b) / 2, rounds the same in either order, so metrics (wall clock aside), params,
    Adam state and normalizer must be bit-identical; every checkpoint of the 2-process run reads
    back (its integrity record, written by process 0, matches its files)."""
    from foottof.ppo import integrity

    one = tmp_path / "one_process"
    _ok(
        subprocess.run(
            [sys.executable, WORKER, "run", str(one), "5"],
            cwd=ROOT,
            env=_env(devices=2),
            capture_output=True,
            text=True,
            timeout=600,
        )
    )
    two = tmp_path / "two_processes"
    for mode, n in (("run", "3"), ("resume", "5")):
        results = _processes([sys.executable, WORKER, mode, str(two), n], 2, timeout=600)
        for r in results:
            _ok(r)
        assert "2 process(es), 2 devices" in results[1].stdout
    assert "[runner] resumed from iteration 3" in results[0].stdout
    assert "it 5/5" in results[0].stdout and "it 5/5" not in results[1].stdout  # process 0 logs

    assert [r["iteration"] for r in _metrics(two)] == ["1", "2", "3", "4", "5"]
    assert _metrics(two) == _metrics(one)
    a, b = np.load(one / "final.npz"), np.load(two / "final.npz")
    assert sorted(a) == sorted(b) and len(a) > 50
    assert all(np.array_equal(a[k], b[k]) for k in a), [
        k for k in a if not np.array_equal(a[k], b[k])
    ]
    checkpoints = two / "checkpoints"
    assert sorted(os.listdir(checkpoints)) == ["1", "2", "3", "4", "5"]
    for step in range(1, 6):
        assert (checkpoints / str(step) / integrity.INTEGRITY_FILE).exists(), step
        assert integrity.integrity_problem(str(checkpoints / str(step))) is None, step


@pytest.mark.slow
def test_train_py_two_processes_check_envs_against_all_devices(tmp_path):  # ~6 s
    """train.py in 2 processes x 1 device: the distributed runtime starts (the error counts both
    processes' devices) and 6 envs in 2 minibatches do not split over 2 devices: one line on
    each process, before the env is built or anything compiles."""
    cmd = [sys.executable, "train.py", "--config", "configs/smoke.py", "--config.ppo.num_envs=6"]
    results = _processes([*cmd, "--run_dir", str(tmp_path / "run")], 2, timeout=300)
    for r in results:
        assert r.returncode != 0
        assert r.stderr.strip().splitlines()[-1] == (
            "error: ppo.num_envs=6 is not divisible by ppo.num_minibatches * devices = 2 * 2 "
            "(2 device(s) over 2 processes); each device steps num_envs / devices envs in whole "
            "minibatches"
        )
    assert not os.path.exists(tmp_path / "run")


def _wait_until(done, procs: list[subprocess.Popen], timeout: float, what: str) -> None:
    """Waits until `done()` while every process of `procs` runs."""
    deadline = time.time() + timeout
    while not done():
        for i, p in enumerate(procs):
            if p.poll() is not None:
                r = _finish(p, 10)
                raise AssertionError(
                    f"process {i} ended first ({r.returncode}): {r.stderr[-3000:]}"
                )
        assert time.time() < deadline, f"no {what} after {timeout} s"
        time.sleep(0.1)


def _logged(run_dir, iteration: int) -> bool:
    """Whether process 0 has written the metrics row of `iteration`."""
    path = os.path.join(run_dir, "metrics.csv")
    return os.path.exists(path) and any(r["iteration"] == str(iteration) for r in _metrics(run_dir))


LOST_LINE = re.compile(
    r"\[distributed\] process 1 of 2 stopped responding after iteration (\d+) \((.+)\); process 0 "
    r"stops\. Resume: start all 2 again with --resume --run_dir (\S+); they continue from "
    r"iteration (\d+), the last complete checkpoint"
)


@pytest.mark.slow
def test_killed_process_stops_the_run_and_a_resume_continues(tmp_path):  # ~1 min, busy 2 cores
    """2 processes x 1 device on localhost, a checkpoint every 4 iterations. Once checkpoint 4 is
    complete (process 0 has written its integrity record, after orbax renamed the folder) and
    iteration 5 is logged, process 1 is killed (SIGKILL). Process 0 must stop within seconds
    (its next collective fails at once; the heartbeat timeout, 10 s here, bounds every other
    wait), with one line on stderr naming process 1 and checkpoint 4, and status
    EXIT_PROCESS_LOST: not a traceback, nor JAX's abort at the heartbeat timeout. It can have
    finished iterations 5 to 7 (each needs both processes), so the rows after the checkpoint
    must go. A half-written checkpoint (what a kill during a save leaves, planted newer than
    all) is never read: 2 new processes with --resume continue from iteration 4, and
    metrics.csv continues without a gap or a repeated iteration."""
    from foottof.ppo import integrity
    from foottof.ppo import run_dir as run_dirs

    run = tmp_path / "run"
    checkpoints = run / "checkpoints"
    cmd = [sys.executable, WORKER, "run", str(run), "1000", "4"]  # 1000 iterations: stopped early
    procs = _start(cmd, 2, FOOTTOF_HEARTBEAT_TIMEOUT_S="10")
    try:
        complete = checkpoints / "4" / integrity.INTEGRITY_FILE
        _wait_until(lambda: complete.exists() and _logged(run, 5), procs, 600, "iteration 5")
        procs[1].send_signal(signal.SIGKILL)
        killed = time.time()
        r = _finish(procs[0], timeout=60)
        stop_s = time.time() - killed
    finally:
        for p in procs:
            p.kill()
            p.communicate()
    assert r.returncode == distributed.EXIT_PROCESS_LOST, (r.returncode, r.stderr[-3000:])
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and (m := LOST_LINE.fullmatch(lines[0])), r.stderr[-3000:]
    assert stop_s < 5, stop_s  # a collective noticed it, not the heartbeat (10 s)
    after, cause, run_dir, resumed = int(m[1]), m[2], m[3], int(m[4])
    assert "Gloo" in cause and run_dir == str(run)
    assert resumed == 4 and 5 <= after <= 7, (resumed, after)
    assert run_dirs.latest_checkpoint(str(run)) == 4
    assert sorted(s for s in os.listdir(checkpoints) if s.isdigit()) == ["4"]
    assert integrity.integrity_problem(str(checkpoints / "4")) is None
    before = _metrics(run)
    assert [int(row["iteration"]) for row in before] == list(range(1, after + 1))

    end = resumed + 2
    # What a kill during the save of `end` leaves (the name orbax 0.12.8 writes into; the kill
    # above may have left one): newer than every complete checkpoint, every other file missing,
    # the others cut in half.
    half = checkpoints / f"{end}.orbax-checkpoint-tmp"
    if not half.exists():
        shutil.copytree(checkpoints / str(resumed), half)
        for i, f in enumerate(sorted(p for p in half.rglob("*") if p.is_file())):
            if i % 2:
                f.unlink()
            else:
                f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])

    results = _processes([sys.executable, WORKER, "resume", str(run), str(end), "2"], 2, 600)
    for res in results:
        _ok(res)
    assert f"[runner] resumed from iteration {resumed} in" in results[0].stdout
    assert f"it {end}/{end}" in results[0].stdout
    rows = _metrics(run)
    assert [int(row["iteration"]) for row in rows] == list(range(1, end + 1))
    assert rows[:resumed] == before[:resumed]  # the rows up to the checkpoint are kept
    assert integrity.integrity_problem(str(checkpoints / str(end))) is None  # written anew
    assert not half.exists()  # orbax replaced the half-written folder


@pytest.mark.slow
def test_hung_process_ends_the_others_within_the_heartbeat_timeout():  # ~20 s
    """A process that stops (SIGSTOP: its sockets stay open, so no collective fails; as a host
    that vanished, or a hang) is noticed by the heartbeat, here FOOTTOF_HEARTBEAT_TIMEOUT_S=5 s
    (JAX's default 100 s): process 0, blocked in an all-gather, is ended by JAX's abort (its own
    message and stack dump; no Python hook can run) within the timeout."""
    procs = _start([sys.executable, WORKER, "collectives"], 2, FOOTTOF_HEARTBEAT_TIMEOUT_S="5")
    try:
        for line in procs[0].stdout:  # until the first all-gather is done (gloo says hello first)
            if line.startswith("[worker] collectives running"):
                break
        else:
            raise AssertionError(_finish(procs[0], 30).stderr[-3000:])
        procs[1].send_signal(signal.SIGSTOP)
        stopped = time.time()
        r = _finish(procs[0], timeout=60)
        stop_s = time.time() - stopped
    finally:
        for p in procs:
            p.kill()
            p.communicate()
    assert r.returncode != 0 and "heartbeat" in r.stderr, (r.returncode, r.stderr[-3000:])
    assert stop_s < 15, stop_s  # measured: 5.0 and 5.9 s; JAX's default would be 100 s


# ----------------------------------------------------------- a process lost before the loop
STARTUP_LINE = re.compile(
    r"\[distributed\] not all 2 processes joined within 3 s at start-up \((.+)\); process 0 "
    r"stops\. Start all 2 again \(FOOTTOF_HEARTBEAT_TIMEOUT_S sets this wait\)"
)


def test_a_process_that_never_joins_stops_the_start_up_in_one_line(tmp_path):
    """train.py as process 0 of 2 whose process 1 never starts (lost before it joined): after
    the heartbeat timeout (3 s here; JAX's own start-up wait is 300 s) it stops with one line
    and EXIT_PROCESS_LOST, as training does, before any run folder is written."""
    cmd = [sys.executable, "train.py", "--config", "configs/smoke.py"]
    env = _env(
        JAX_COORDINATOR_ADDRESS=f"localhost:{_free_port()}",
        JAX_NUM_PROCESSES="2",
        JAX_PROCESS_ID="0",
        FOOTTOF_HEARTBEAT_TIMEOUT_S="3",
    )
    t0 = time.time()
    r = subprocess.run(
        [*cmd, "--run_dir", str(tmp_path / "run")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == distributed.EXIT_PROCESS_LOST, (r.returncode, r.stderr[-3000:])
    lines = [line for line in r.stderr.strip().splitlines() if line.startswith("[distributed]")]
    assert len(lines) == 1 and STARTUP_LINE.fullmatch(lines[0]), r.stderr[-3000:]
    assert "Traceback" not in r.stderr and "stack trace" not in r.stderr
    assert r.stderr.strip().splitlines()[-1] == lines[0]
    assert time.time() - t0 < 60
    assert not os.path.exists(tmp_path / "run")


def _kill_one_while_stalled(killed: int):
    """2 "stall" workers (heartbeat timeout 6 s) past start-up; process ``killed`` gets SIGKILL.
    Returns (the other one's finished result, seconds from the kill to its exit)."""
    procs = _start([sys.executable, WORKER, "stall"], 2, FOOTTOF_HEARTBEAT_TIMEOUT_S="6")
    try:
        for p in procs:
            line = p.stdout.readline()
            assert line.startswith("[worker] started"), _finish(p, 30).stderr[-3000:]
        procs[killed].send_signal(signal.SIGKILL)
        t0 = time.time()
        r = _finish(procs[1 - killed], timeout=60)
        return r, time.time() - t0
    finally:
        for p in procs:
            p.kill()
            p.communicate()


def test_a_process_lost_during_the_first_compile_stops_the_others_in_one_line():
    """2 processes past start-up, then without a collective for minutes (as in a first compile):
    process 1 is killed. Process 0 stops within the heartbeat timeout (6 s here) with one line
    and EXIT_PROCESS_LOST (its own heartbeats, foottof.ppo.distributed.PeerWatch, notice at half
    the timeout), not JAX's abort and stack dump at the full timeout."""
    r, stop_s = _kill_one_while_stalled(killed=1)
    assert r.returncode == distributed.EXIT_PROCESS_LOST, (r.returncode, r.stderr[-3000:])
    assert r.stderr.strip().splitlines()[-1] == (
        "[distributed] process 1 of 2 sent no heartbeat for 3 s (killed, hung or its host gone); "
        "process 0 stops. Start all 2 again as before, with --resume where the run has a "
        "complete checkpoint"
    ), r.stderr[-3000:]
    assert "stack trace" not in r.stderr and "Traceback" not in r.stderr
    assert stop_s < 6, stop_s  # within the heartbeat timeout


def test_the_coordinator_lost_during_the_first_compile_stops_the_others_in_one_line():
    """As above, but process 0 is killed: the coordination service goes with it, and JAX ends
    process 1 at once (its poll of the service fails) with a fatal log, a stack dump and
    SIGABRT. Process 1 must stop instead with one line naming process 0 as the coordinator that
    is gone, and EXIT_PROCESS_LOST, within the heartbeat timeout; before it only the runtime's
    own log lines (warnings and errors of its RPCs, not its fatal one)."""
    r, stop_s = _kill_one_while_stalled(killed=0)
    assert r.returncode == distributed.EXIT_PROCESS_LOST, (r.returncode, r.stderr[-3000:])
    *before, last = r.stderr.strip().splitlines()
    assert re.fullmatch(
        r"\[distributed\] process 0 of 2 \(the coordinator, localhost:\d+\) is gone; process 1 "
        r"stops\. Start all 2 again as before, with --resume where the run has a complete "
        r"checkpoint",
        last,
    ), r.stderr[-3000:]
    assert not [line for line in before if re.match(r"F\d{4} ", line)], r.stderr[-3000:]
    assert "stack trace" not in r.stderr and "Traceback" not in r.stderr
    assert stop_s < 6, stop_s  # measured: 0.2-0.4 s (the probe of the coordinator's port)


# ------------------------------------------------------------- a full disk, several processes
@pytest.fixture(scope="module")
def one_process_six(tmp_path_factory):
    """1 process x 2 devices, 6 iterations, a checkpoint every 2: what 2 processes x 1 device
    give bit for bit (test_two_processes_equal_two_devices_and_resume)."""
    one = tmp_path_factory.mktemp("one_process")
    _ok(
        subprocess.run(
            [sys.executable, WORKER, "run", str(one), "6", "2"],
            cwd=ROOT,
            env=_env(devices=2),
            capture_output=True,
            text=True,
            timeout=600,
        )
    )
    return one


def _until_stopped(procs: list[subprocess.Popen], timeout: float, then_s: float):
    """Waits until every process of `procs` ends: at most `timeout` s, and at most `then_s` s
    after the first one ended or said why it stops (a line starting `error:` or
    `[distributed]`); kills any left. Returns their CompletedProcess and the seconds from that
    first sign to the last end."""
    import threading

    out = [{"stdout": [], "stderr": []} for _ in procs]
    first = []  # time of the first sign of a stop

    def read(i, name):
        for line in getattr(procs[i], name):
            out[i][name].append(line)
            if line.startswith(("error:", "[distributed]")):
                first.append(time.time())

    readers = [
        threading.Thread(target=read, args=(i, name), daemon=True)
        for i in range(len(procs))
        for name in ("stdout", "stderr")
    ]
    for t in readers:
        t.start()
    deadline = time.time() + timeout
    while any(p.poll() is None for p in procs):
        if any(p.poll() is not None for p in procs):
            first.append(time.time())
        if time.time() > (min(first) + then_s if first else deadline):
            break
        time.sleep(0.05)
    last = time.time()
    for p in procs:
        p.kill()
        p.wait()
    for t in readers:
        t.join(10)
    results = [
        subprocess.CompletedProcess(
            p.args, p.returncode, "".join(o["stdout"]), "".join(o["stderr"])
        )
        for p, o in zip(procs, out, strict=True)
    ]
    return results, last - min(first, default=last)


@pytest.mark.slow
@pytest.mark.parametrize("full", [1, 0])
def test_disk_full_on_one_process_stops_every_process_in_one_line_and_resumes(
    tmp_path, request, full
):  # ~6 min on the busy 2-core box (3 min each way)
    """2 processes x 1 device, a checkpoint every 2 iterations. Each process writes its own
    shards of a checkpoint (process 0 also the replicated arrays and the metadata); here process
    `full` finds the disk full while writing checkpoint 4 (ENOSPC as TensorStore reports it),
    the other does not and waits for it in one of orbax's barriers. The process that hit it
    stops with train.py's one line (the run, the space needed, checkpoint 2 as the last
    complete one), status 1; the other, within seconds, with one line that quotes it and
    EXIT_PROCESS_LOST; not JAX's abort, nor a wait at a barrier until a timeout. Checkpoint 2 is
    intact, no checkpoint 4 is complete, metrics.csv has whole rows; 2 new processes with
    --resume continue from 2 to 6 bit-exactly (metrics but the wall clock, params, Adam state,
    normalizer as the 1-process run)."""
    from foottof.ppo import integrity
    from foottof.ppo import run_dir as run_dirs

    run = tmp_path / "run"
    cmd = [sys.executable, WORKER, "run", str(run), "6", "2"]
    procs = _start(cmd, 2, FOOTTOF_HEARTBEAT_TIMEOUT_S="10", FOOTTOF_TEST_DISK_FULL=f"{full}:4")
    results, stop_s = _until_stopped(procs, timeout=600, then_s=30)
    hit, other = results[full], results[1 - full]
    line = hit.stderr.strip().splitlines()[-1]
    assert hit.returncode == 1, (hit.returncode, hit.stderr[-3000:])
    at = re.escape(str(run))
    assert re.fullmatch(
        rf"error: disk full in {at} while saving checkpoint 4: it needs about \S+ [kM]B free, "
        rf"\S+ [kM]B is; checkpoint 2 is the last complete one\. Free space there, then continue "
        rf"from it \(train\.py --resume --run_dir {at}\)",
        line,
    ), hit.stderr[-3000:]
    assert other.returncode == distributed.EXIT_PROCESS_LOST, (
        other.returncode,
        other.stderr[-3000:],
    )
    assert other.stderr.strip().splitlines()[-1] == (
        f"[distributed] process {1 - full} stops because process {full} of 2 did: {line}"
    ), other.stderr[-3000:]
    for r in results:  # one line of ours each (orbax logs the failed write before it)
        ours = [x for x in r.stderr.splitlines() if x.startswith(("error:", "[distributed]"))]
        assert len(ours) == 1 and "stack trace" not in r.stderr, r.stderr[-3000:]
    assert stop_s < 15, stop_s  # measured: under 1 s (the watch reads every 0.5 s here)
    assert run_dirs.latest_checkpoint(str(run)) == 2
    assert integrity.integrity_problem(str(run / "checkpoints" / "2")) is None
    rows = _metrics(run)
    assert [r["iteration"] for r in rows][:2] == ["1", "2"] and len(rows) <= 4
    assert all(None not in r and "" not in r.values() for r in rows)  # none torn

    results = _processes([sys.executable, WORKER, "resume", str(run), "6", "2"], 2, 600)
    for r in results:
        _ok(r)
    assert "[runner] resumed from iteration 2 in" in results[0].stdout
    one_process_six = request.getfixturevalue("one_process_six")  # after the stop: fails sooner
    assert _metrics(run) == _metrics(one_process_six)
    a, b = np.load(one_process_six / "final.npz"), np.load(run / "final.npz")
    assert sorted(a) == sorted(b) and len(a) > 50
    assert all(np.array_equal(a[k], b[k]) for k in a), [
        k for k in a if not np.array_equal(a[k], b[k])
    ]
