"""Ship a run's checkpoint into the repo: one resumable policy folder, small enough to commit.

``python -m foottof.lab.ship RUN_DIR DEST [--step N] [--max_mb 20]`` copies into DEST (e.g.
``policies/stage1``) the newest checkpoint of RUN_DIR whose files match their integrity record
(or the one ``--step`` names), with the run's ``config.json``, ``config.yaml`` and ``metrics.csv``
cut at that iteration, so that ``train.py --run_dir DEST --resume`` and ``evaluate.py --checkpoint
DEST`` read it. A training run that keeps writing checkpoints meanwhile is not disturbed (the run's
files are only read). DEST is replaced as a whole and only once the new folder is complete and
under the size limit: an interrupted or refused ship leaves the previous one in place.
"""

from __future__ import annotations

import argparse
import os
import shutil

from foottof.ppo.runner import trim_metrics
from foottof.ppo.storage.integrity import INTEGRITY_FILE, integrity_problem, write_integrity
from foottof.ppo.storage.run_dir import CHECKPOINT_SUBDIR

RUN_FILES = ("config.json", "config.yaml", "metrics.csv", "teacher.json")  # those the run has
DEFAULT_MAX_MB = 20.0  # the repo's limit for a shipped policy


def _folder_bytes(path: str) -> int:
    return sum(
        os.path.getsize(os.path.join(root, f)) for root, _, files in os.walk(path) for f in files
    )


def shippable_step(run_dir: str, step: int | None = None) -> int:
    """The checkpoint of ``run_dir`` to ship: ``step`` if given (it must be intact), else the
    newest finished step whose files match their integrity record.

    Raises:
      FileNotFoundError: no checkpoint folder, no finished step, or ``step`` absent.
      ValueError: ``step`` is damaged, or every step is.
    """
    root = os.path.join(run_dir, CHECKPOINT_SUBDIR)
    steps = sorted(int(d) for d in os.listdir(root) if d.isdigit()) if os.path.isdir(root) else []
    if not steps:
        raise FileNotFoundError(f"no finished checkpoint in {root}")
    if step is not None:
        if step not in steps:
            raise FileNotFoundError(f"--step {step}: not in {root} (steps there: {steps})")
        problem = integrity_problem(os.path.join(root, str(step)))
        if problem:
            raise ValueError(f"--step {step}: checkpoint {root}/{step} is damaged: {problem}")
        return step
    problems = []
    for s in reversed(steps):
        problem = integrity_problem(os.path.join(root, str(s)))
        if problem is None:
            return s
        problems.append(f"{s}: {problem}")
    raise ValueError(f"every checkpoint in {root} is damaged ({'; '.join(problems)})")


def ship(run_dir: str, dest: str, step: int | None = None, max_mb: float = DEFAULT_MAX_MB) -> int:
    """Replaces ``dest`` with checkpoint ``step`` (default: newest intact) of ``run_dir`` and the
    run's config and metrics cut at that iteration. Returns the shipped step.

    Raises:
      FileNotFoundError / ValueError: as :func:`shippable_step`; ValueError also when the folder
      would exceed ``max_mb`` (``dest`` is then left as it was) or ``dest`` is ``run_dir``.
    """
    if max_mb <= 0:
        raise ValueError(f"--max_mb {max_mb}: must be > 0")
    if os.path.abspath(dest) == os.path.abspath(run_dir):
        raise ValueError(f"DEST {dest} is the run folder itself; ship into another folder")
    step = shippable_step(run_dir, step)
    new = dest.rstrip("/") + ".shipping"
    shutil.rmtree(new, ignore_errors=True)
    src_step = os.path.join(run_dir, CHECKPOINT_SUBDIR, str(step))
    dst_step = os.path.join(new, CHECKPOINT_SUBDIR, str(step))
    try:
        shutil.copytree(src_step, dst_step)
    except (OSError, shutil.Error) as e:  # e.g. the running run rotated this step out meanwhile
        shutil.rmtree(new, ignore_errors=True)
        raise ValueError(f"copying {src_step} failed ({type(e).__name__}); run ship again") from e
    # The copy is checked against the run's record (a file the run rewrote meanwhile is caught);
    # a checkpoint from before the record existed gets one now.
    problem = integrity_problem(dst_step)
    if problem:
        shutil.rmtree(new)
        raise ValueError(f"the copy of {src_step} does not match its record: {problem}")
    if not os.path.exists(os.path.join(dst_step, INTEGRITY_FILE)):
        write_integrity(dst_step)
    for name in RUN_FILES:
        if os.path.exists(os.path.join(run_dir, name)):
            shutil.copy2(os.path.join(run_dir, name), os.path.join(new, name))
    trim_metrics(new, step)
    size_mb = _folder_bytes(new) / 2**20
    if size_mb > max_mb:
        shutil.rmtree(new)
        raise ValueError(
            f"checkpoint {step} of {run_dir} takes {size_mb:.1f} MB, over --max_mb {max_mb:g}; "
            f"{dest} left as it was"
        )
    old = dest.rstrip("/") + ".replaced"
    shutil.rmtree(old, ignore_errors=True)
    if os.path.exists(dest):
        os.replace(dest, old)
    os.replace(new, dest)
    shutil.rmtree(old, ignore_errors=True)
    return step


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("run_dir", help="training run folder (train.py --run_dir)")
    p.add_argument("dest", help="folder to replace, e.g. policies/stage1")
    p.add_argument("--step", type=int, default=None, help="iteration (default: newest intact)")
    p.add_argument("--max_mb", type=float, default=DEFAULT_MAX_MB, help="size limit of DEST")
    a = p.parse_args(argv)
    try:
        step = ship(a.run_dir, a.dest, a.step, a.max_mb)
    except (FileNotFoundError, ValueError) as e:
        raise SystemExit(f"[ship] {e}") from None
    size_mb = _folder_bytes(a.dest) / 2**20
    print(f"[ship] {a.run_dir} checkpoint {step} -> {a.dest} ({size_mb:.1f} MB)")


if __name__ == "__main__":
    main()
