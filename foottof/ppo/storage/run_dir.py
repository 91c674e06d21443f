"""Run folders: train.py's timestamped folder per run and latest link; evaluate.py's policy lookup.

Imports no JAX.
"""

import copy
import glob
import os
import shutil
import time

from foottof.renames import read_saved_config

CHECKPOINT_SUBDIR = "checkpoints"  # <run_dir>/checkpoints/<iteration>/ (storage.checkpoint)
SHIPPED_POLICY_DIRS = ("policies/latest",)  # checked (relative to the repo root) before runs/


def has_checkpoint(run_dir: str) -> bool:
    """Whether run_dir/checkpoints holds at least one step."""
    d = os.path.join(run_dir, CHECKPOINT_SUBDIR)
    return os.path.isdir(d) and any(n.isdigit() for n in os.listdir(d))


def latest_checkpoint(run_dir: str) -> int | None:
    """The newest complete checkpoint's iteration in run_dir/checkpoints (None: none).

    Orbax writes a checkpoint into <iteration>.orbax-checkpoint-tmp-<time> and renames it to
    <iteration> only when every process has written its part, so a number is a complete one."""
    d = os.path.join(run_dir, CHECKPOINT_SUBDIR)
    steps = [int(n) for n in os.listdir(d) if n.isdigit()] if os.path.isdir(d) else []
    return max(steps, default=None)


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


def find_checkpoint(repo_root: str) -> str | None:
    """Default checkpoint: a shipped policy (policies/latest), else the newest run under runs/."""
    for rel in SHIPPED_POLICY_DIRS:
        path = os.path.join(repo_root, rel)
        if has_checkpoint(path):
            return path
    runs = [d for d in glob.glob(os.path.join(repo_root, "runs", "*")) if has_checkpoint(d)]
    if not runs:
        return None
    return max(runs, key=lambda d: os.path.getmtime(os.path.join(d, CHECKPOINT_SUBDIR)))


def resolve_checkpoint(checkpoint: str | None, untrained: bool, repo_root: str) -> str | None:
    """The policy evaluate.py runs: --checkpoint, else find_checkpoint; None = --untrained.

    Raises:
      FileNotFoundError: --checkpoint does not exist, or no policy was found (says what to do).
    """
    if untrained:
        return None
    if checkpoint:
        if not os.path.exists(checkpoint):
            raise FileNotFoundError(f"--checkpoint {checkpoint!r} does not exist")
        return checkpoint
    found = find_checkpoint(repo_root)
    if found is None:
        raise FileNotFoundError(
            "no policy found (looked in policies/latest and runs/*/checkpoints): train first "
            "(`make demo` on a CPU, python train.py --config configs/stage1.py on a GPU), pass "
            "--checkpoint PATH, or --untrained to check the pipeline with a fresh policy"
        )
    return found


def run_config_path(checkpoint: str) -> str | None:
    """config.json of the run holding `checkpoint` (run dir, checkpoints/ or a step dir)."""
    p = os.path.abspath(checkpoint)
    for _ in range(3):
        if os.path.isfile(os.path.join(p, "config.json")):
            return os.path.join(p, "config.json")
        p = os.path.dirname(p)
    return None


# Env fields that shape the network's inputs: taken from the run config along with c.network.
RUN_INPUT_FIELDS = (
    "critic_height_scan",
    "actor_terrain",
    "actor_terrain_seen",
    "actor_terrain_fine",
)


# Network fields that do not shape the parameters: a command-line value may differ from the run's.
# network.max_noise_std caps the std that actions are sampled at (eval.deterministic=False).
RUN_NETWORK_FREE_FIELDS = ("max_noise_std",)


CURRICULUM_FIELD = "terrain.stone_curriculum"


def with_run_curriculum(cfg, run_config: str | None, overrides=()):
    """`cfg` with the stone curriculum its run trained on (``terrain.stone_curriculum`` of the
    run's config.json at ``run_config``, read migrated: "gaps_first" where it was saved before
    the field existed), unless the command line set it (``overrides``): a resumed run keeps its
    curriculum, and a policy is evaluated on the curriculum it learned (at the ensemble's
    difficulty every curriculum draws the same stones). A copy; ``cfg`` when nothing changes.

    Returns:
      (config, note): note is a line saying what was taken from the run, or None."""
    if run_config is None or not os.path.isfile(run_config) or CURRICULUM_FIELD in set(overrides):
        return cfg, None
    saved = read_saved_config(run_config)
    if "terrain" not in saved:
        return cfg, None
    value = str(saved["terrain"]["stone_curriculum"])
    if cfg.terrain.stone_curriculum == value:
        return cfg, None
    c = copy.deepcopy(cfg)
    with c.unlocked():
        c.terrain.stone_curriculum = value
    note = (
        f"{CURRICULUM_FIELD}={value!r} as its run trained ({run_config}); "
        f"--config.{CURRICULUM_FIELD}=NAME sets another"
    )
    return c, note


def with_run_network(cfg, checkpoint: str | None, overrides=()):
    """`cfg` (a ConfigDict) with c.network, and the env fields that shape the network's inputs
    (RUN_INPUT_FIELDS), from the checkpoint's run config (if it has one), read migrated: a field
    added since the run was saved takes its old-behaviour default (renames.ADDED_FIELDS).

    Args:
      overrides: the dotted names the user set on the command line (e.g. the keys of
        ml_collections' ``config_flags.get_override_values``). Such a value of a field in
        RUN_NETWORK_FREE_FIELDS is kept; one of any other field the run sets must equal the run's.

    Raises:
      ValueError: a command-line value of a network or input field differs from the run's.
    """
    path = run_config_path(checkpoint) if checkpoint else None
    if path is None:
        return cfg
    saved = read_saved_config(path)  # migrated: fields added since the run at their old default
    if "network" not in saved:
        return cfg
    overrides = set(overrides)
    c = copy.deepcopy(cfg)
    runs = [
        ("network", k, tuple(v) if isinstance(v, list) else v) for k, v in saved["network"].items()
    ]
    runs += [("env", k, bool(saved["env"][k])) for k in RUN_INPUT_FIELDS if "env" in saved]
    with c.unlocked():
        for section, key, value in runs:
            name = f"{section}.{key}"
            if key not in c[section]:
                continue
            if name in overrides:
                if section == "network" and key in RUN_NETWORK_FREE_FIELDS:
                    continue
                if c[section][key] != value:
                    raise ValueError(
                        f"{name}={c[section][key]!r} on the command line, but the policy's run "
                        f"({path}) has {value!r}: the network comes from its run; of its fields "
                        f"only {', '.join('network.' + f for f in RUN_NETWORK_FREE_FIELDS)} may differ"
                    )
            c[section][key] = value
    return c
