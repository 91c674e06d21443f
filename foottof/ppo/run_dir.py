"""Run folders of train.py: a new timestamped folder per run, a link to the latest (no JAX)."""

import os
import shutil
import time

CHECKPOINT_SUBDIR = "checkpoints"  # <run_dir>/checkpoints/<iteration>/ (foottof.ppo.checkpoint)


def has_checkpoint(run_dir: str) -> bool:
    """Whether run_dir/checkpoints holds at least one step."""
    d = os.path.join(run_dir, CHECKPOINT_SUBDIR)
    return os.path.isdir(d) and any(n.isdigit() for n in os.listdir(d))


def new_run_dir(run_root: str, run_name: str, now: float | None = None) -> str:
    """A path that does not exist yet: <run_root>/<run_name>-<YYYYmmdd-HHMMSS>[-<n>]."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(now))
    base = os.path.join(run_root, f"{run_name}-{stamp}")
    path, n = base, 1
    while os.path.lexists(path):
        n += 1
        path = f"{base}-{n}"
    return path


def resolve_run_dir(
    run_root: str, run_name: str, run_dir: str | None, resume: bool
) -> tuple[str, str | None]:
    """Where train.py writes (reads the disk, writes nothing); errors name train.py's flags.

    Without --run_dir every run gets a new folder <run_root>/<run_name>-<time> and the link
    <run_root>/<run_name> points at the latest one (what `--resume`, `evaluate.py --checkpoint
    runs/<name>` and stage 2's `train.init_from` read). With --run_dir the folder is used as given.

    Args:
      run_root, run_name: cfg.train.run_root / run_name.
      run_dir: the --run_dir flag (None: not given).
      resume: the --resume flag.

    Returns:
      (run directory, latest link to point at it or None).

    Raises:
      FileNotFoundError: --resume but nothing to continue.
      FileExistsError: --run_dir names a run with checkpoints and --resume is not given.
    """
    if run_dir:
        if resume and not has_checkpoint(run_dir):
            raise FileNotFoundError(
                f"--resume: no checkpoint in {run_dir}/{CHECKPOINT_SUBDIR} to continue; "
                f"drop --resume to start a new run there"
            )
        if not resume and has_checkpoint(run_dir):
            raise FileExistsError(
                f"--run_dir {run_dir} already holds checkpoints of a run: add --resume to continue "
                f"it, or give another --run_dir (without --run_dir each run gets a new "
                f"{os.path.join(run_root, run_name)}-<time> folder)"
            )
        return run_dir, None
    latest = os.path.join(run_root, run_name)
    if resume:
        if not has_checkpoint(latest):
            raise FileNotFoundError(
                f"--resume: no run to continue at {latest} (no checkpoint there); train once "
                f"without --resume first, or give the run with --run_dir"
            )
        if os.path.islink(latest):  # continue the run the link points at, under its own name
            return os.path.join(os.path.dirname(latest), os.readlink(latest)), None
        return latest, None
    return new_run_dir(run_root, run_name), latest


def point_latest(link: str, run_dir: str) -> str | None:
    """Makes `link` a relative symlink to `run_dir` (atomically); returns the previous target.

    Raises:
      FileExistsError: `link` is a real folder (e.g. a run from before run folders were
        timestamped); it is left alone.
    """
    if os.path.lexists(link) and not os.path.islink(link):
        raise FileExistsError(
            f"{link} is a folder from before run folders were timestamped, so it cannot link to "
            f"the latest run; rename it (mv {link} {link}-old) to get the link back"
        )
    previous = os.readlink(link) if os.path.islink(link) else None
    target = os.path.relpath(os.path.abspath(run_dir), os.path.dirname(os.path.abspath(link)))
    tmp = f"{link}.link-tmp-{os.getpid()}"
    if os.path.lexists(tmp):
        os.remove(tmp)
    os.symlink(target, tmp)
    os.replace(tmp, link)
    return previous


def forget_run(link: str, previous: str | None, created_dir: str | None) -> None:
    """Undoes a run that saved no checkpoint: `link` back to `previous`, `created_dir` removed."""
    if previous is None:
        os.remove(link)
    else:
        point_latest(link, os.path.join(os.path.dirname(link), previous))
    if created_dir is not None:
        shutil.rmtree(created_dir, ignore_errors=True)
