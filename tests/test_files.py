"""Faults of the disk and of two writers (foottof/files.py): a full disk mid-save, a torn row, a
second train.py on a live run, a lock left by a killed process, two evaluations into one --out."""

import csv
import errno
import os
import signal
import subprocess
import sys
import time

import pytest
import toy_envs
from etils import epath
from helpers import REPO, run_cli, tiny_cfg, tree_equal

from foottof import files
from foottof.ppo import integrity, runner

ENV = toy_envs.make_memory_env()


def _rows(run_dir) -> list[dict]:
    with open(os.path.join(run_dir, "metrics.csv"), newline="") as f:
        return list(csv.DictReader(f))


def _untimed(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if not k.startswith(("time/", "training/"))} for r in rows]


# ------------------------------------------------------------------------------- a full disk
def test_is_disk_full_reads_python_and_tensorstore_errors():
    assert files.is_disk_full(OSError(errno.ENOSPC, "No space left on device"))
    assert files.is_disk_full(OSError(errno.EDQUOT, "Disk quota exceeded"))
    tensorstore = ValueError(  # what orbax 0.12.8 raised on a 4 MB tmpfs (TensorStore's text)
        'RESOURCE_EXHAUSTED: Error writing local file "/r/checkpoints/4.orbax-checkpoint-tmp/'
        'normalizer.orbax-checkpoint-tmp/_sharding": Failed to write 1231 bytes to file 41: No '
        "space left on device [os_error_code='28']"
    )
    assert files.is_disk_full(tensorstore)
    try:
        try:
            raise tensorstore
        except ValueError as inner:
            raise RuntimeError("orbax save failed") from inner
    except RuntimeError as wrapped:
        assert files.is_disk_full(wrapped)
    assert not files.is_disk_full(OSError(errno.EACCES, "Permission denied"))
    assert not files.is_disk_full(ValueError("RESOURCE_EXHAUSTED: Out of memory"))


def _fail_writes_into(monkeypatch, fragment: str) -> list:
    """Python writes of orbax (epath) under a path containing `fragment` raise ENOSPC, as a full
    disk does: the checkpoint's array files are written, its manifest is not."""
    real = epath.gpath.PosixGPath.write_text
    hits = []

    def write_text(self, *args, **kwargs):
        if fragment in str(self):
            hits.append(str(self))
            raise OSError(errno.ENOSPC, "No space left on device", str(self))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(epath.gpath.PosixGPath, "write_text", write_text)
    return hits


def test_disk_full_mid_save_stops_in_one_line_and_resumes_bit_exactly(tmp_path, monkeypatch):
    """Checkpoints every 2 iterations; the save of checkpoint 4 meets a full disk (ENOSPC at its
    manifest's write, after orbax wrote its arrays into 4.orbax-checkpoint-tmp). Training stops
    with DiskFull, one line naming the run folder and the space a checkpoint needs; checkpoint 2
    is intact and nothing of 4 is left; metrics.csv holds whole rows. With the space back, a
    resume continues from 2 to 6 exactly as a run that never stopped (params, optimizer, env
    state; metrics but the wall clock)."""
    cfg = tiny_cfg(num_iterations=6, checkpoint_every=2, tensorboard=False)
    straight = runner.run(cfg, ENV, str(tmp_path / "straight"))
    run = tmp_path / "full"
    hits = _fail_writes_into(monkeypatch, os.path.join("checkpoints", "4.orbax-checkpoint-tmp"))
    with pytest.raises(files.DiskFull) as e:
        runner.run(cfg, ENV, str(run))
    assert hits
    line = str(e.value)
    assert "\n" not in line
    assert line.startswith(f"disk full in {run} while saving checkpoint 4: it needs about ")
    assert line.endswith(
        f"checkpoint 2 is the last complete one. Free space there, then continue from it "
        f"(train.py --resume --run_dir {run})"
    )
    assert sorted(os.listdir(run / "checkpoints")) == ["2"]  # the partial folder is gone
    assert integrity.integrity_problem(str(run / "checkpoints" / "2")) is None
    rows = _rows(run)
    assert [r["iteration"] for r in rows] == ["1", "2", "3", "4"]
    assert all(None not in r and all(v != "" for v in r.values()) for r in rows)  # none torn

    monkeypatch.undo()  # space is back
    resumed = runner.run(cfg, ENV, str(run), resume=True)
    assert tree_equal(resumed, straight)
    assert _untimed(_rows(run)) == _untimed(_rows(tmp_path / "straight"))


def test_a_failed_append_leaves_no_torn_row(tmp_path):
    """A file-size limit (RLIMIT_FSIZE: the write stops part-way, as at a full disk) hits an
    append: the file is cut back to its whole rows and the error is raised."""
    path = tmp_path / "metrics.csv"
    path.write_text("iteration,loss\n1,0.5\n")
    code = (
        "import resource, signal, sys\n"
        "from foottof import files\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (40, 40))\n"
        "try:\n"
        f"    files.append_whole({str(path)!r}, '2,' + '7' * 100 + '\\n')\n"
        "except OSError as e:\n"
        "    sys.exit(f'raised {e.errno}')\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert r.stderr.strip() == f"raised {errno.EFBIG}", r.stderr
    assert path.read_text() == "iteration,loss\n1,0.5\n"


# ------------------------------------------------------------------------- two writers, one run
def _holder(folder) -> subprocess.Popen:
    """A process holding train.py's lock on `folder` until killed."""
    code = (
        "import sys, time\n"
        "from foottof import files\n"
        f"files.FolderLock({str(folder)!r}, 'train.py').acquire()\n"
        "print('held', flush=True)\n"
        "time.sleep(600)\n"
    )
    p = subprocess.Popen([sys.executable, "-c", code], cwd=REPO, stdout=subprocess.PIPE, text=True)
    assert p.stdout.readline().strip() == "held"
    return p


def test_second_train_py_on_a_live_run_refuses_naming_the_pid(tmp_path):
    """A live process writes the run (holds its lock): train.py on that --run_dir is one line
    naming the holder's pid, before JAX starts; the run folder is not touched."""
    run = tmp_path / "run"
    holder = _holder(run)
    try:
        before = sorted(os.listdir(run))
        r = run_cli("train.py", "--config", "configs/smoke.py", "--run_dir", str(run), timeout=120)
    finally:
        holder.kill()
        holder.communicate()
    assert r.returncode != 0
    assert r.stderr.strip().splitlines() == [
        f"error: {run} is being written by pid {holder.pid} on {os.uname().nodename} (train.py); "
        "train.py refuses a second writer: wait for it to end, or stop it first"
    ], r.stderr[-2000:]
    assert sorted(os.listdir(run)) == before


def test_a_lock_left_by_a_killed_process_is_taken_over(tmp_path, capfd):
    """kill -9 of the writer leaves its lock file (naming its pid) but not the kernel's lock:
    the next run takes it over, says so in one line, and trains."""
    run = tmp_path / "run"
    holder = _holder(run)
    with pytest.raises(files.FolderLocked, match=f"being written by pid {holder.pid} "):
        runner.run(tiny_cfg(num_iterations=1, tensorboard=False), ENV, str(run))
    assert not os.path.exists(run / "config.json")  # the refused call wrote nothing
    holder.send_signal(signal.SIGKILL)
    holder.communicate()
    assert f"pid={holder.pid}" in (run / files.LOCK_FILE).read_text()
    capfd.readouterr()
    runner.run(tiny_cfg(num_iterations=1, tensorboard=False), ENV, str(run))
    out = capfd.readouterr().out
    assert f"[runner] took over {run / files.LOCK_FILE} from pid {holder.pid} (not running)" in out
    assert (run / files.LOCK_FILE).read_text() == ""  # released at the end of the run
    assert [r["iteration"] for r in _rows(run)] == ["1"]


# -------------------------------------------------------------------- two evaluations, one --out
_WRITER = """
import os, sys, time
from foottof.eval import results
out, source, pause = sys.argv[1], sys.argv[2], sys.argv[3]
if pause != "-":  # stop before the first rename, once every temporary file is written
    real = os.replace
    def replace(src, dst):
        os.replace = real
        open(pause + ".paused", "w").close()
        while not os.path.exists(pause + ".go"):
            time.sleep(0.01)
        real(src, dst)
    os.replace = replace
ENSEMBLE = dict(difficulty_fraction=0.9, stone_fraction=0.8, stone_types=["a"], gap_types=["b"],
                deterministic=True, action_std_cap=None, fingerprint="f")
assert tuple(ENSEMBLE) == results.ENSEMBLE_KEYS
row = dict.fromkeys(results.RESULT_KEYS, 0)
row.update(source=source, perturbation="none", level=0.0, episodes=10, successes=7,
           success_rate=0.7, ci_low=0.4, ci_high=0.9)
results.write_run(out, source, "none", [row], None, 20.0, ensemble=ENSEMBLE)
print("done", flush=True)
"""


def _write_results(out, source: str, pause: str = "-") -> subprocess.Popen:
    """evaluate.py's writer (results.write_run) of one result row of `source` into `out`, in a
    process of its own; with `pause`, it stops before its first rename (every temporary file
    written) until the file `pause`.go exists, and says so by creating `pause`.paused."""
    return subprocess.Popen(
        [sys.executable, "-c", _WRITER, str(out), source, pause],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_two_evaluations_into_one_out_leave_both_results_readable(tmp_path):
    """Two evaluate.py runs write their results into one --out, interleaved at the worst point:
    the first has written all its files' temporaries (its results and the shared figure,
    robustness.png) but renamed none when the second writes and renames all of its own; then
    the first goes on. Both must succeed, and leave both results files whole, a whole figure
    and no temporary file (with one temporary name per target, `robustness.png.tmp`, the second
    run's write replaced the first one's temporary and the first run's rename failed)."""
    import json

    from foottof.eval import results

    out, pause = tmp_path / "out", str(tmp_path / "first")
    first = _write_results(out, "tof", pause)
    try:
        while not os.path.exists(pause + ".paused"):
            assert first.poll() is None, first.communicate()[1][-2000:]
            time.sleep(0.01)
        second = _write_results(out, "mock_ideal")
        stdout, stderr = second.communicate(timeout=300)
        assert second.returncode == 0 and stdout.strip() == "done", stderr[-2000:]
        open(pause + ".go", "w").close()
        stdout, stderr = first.communicate(timeout=300)
    finally:
        first.kill()
    assert first.returncode == 0 and stdout.strip() == "done", stderr[-2000:]
    for source in ("tof", "mock_ideal"):
        with open(out / (results.result_basename(source, "none") + ".json")) as f:
            doc = json.load(f)
        assert [(r["source"], r["successes"]) for r in doc["results"]] == [(source, 7)]
        with open(out / (results.result_basename(source, "none") + ".csv")) as f:
            assert [r["source"] for r in csv.DictReader(f)] == [source]
    assert sorted(os.listdir(out)) == [
        "results_mock_ideal_none.csv",
        "results_mock_ideal_none.json",
        "results_tof_none.csv",
        "results_tof_none.json",
        "robustness.png",
    ]
    from PIL import Image

    with Image.open(out / "robustness.png") as png:
        png.load()  # whole: a torn PNG raises here


def test_write_atomic_gives_each_writer_its_own_temporary(tmp_path, monkeypatch):
    """Two writers of one path never share a temporary file (the old `path.tmp` was shared)."""
    names = []
    real = os.replace
    monkeypatch.setattr(os, "replace", lambda a, b: (names.append(a), real(a, b)))
    target = str(tmp_path / "a.json")
    files.write_atomic({target: b"1"})
    files.write_atomic({target: b"2"})
    assert len(set(names)) == 2 and all(n.startswith(target + ".") for n in names)
    assert open(target).read() == "2" and os.listdir(tmp_path) == ["a.json"]
    assert oct(os.stat(target).st_mode & 0o777) == "0o644"
