"""Per-type curriculum levels along a policy's lineage, from the checkpoints shipped in git.

A shipped run folder (``policies/NAME``) keeps one checkpoint; every commit that shipped a new one
left it in the history. This script takes each such checkpoint out of git (``git archive``), reads
its per-type curriculum levels (``foottof.lab.levels.level_counts``) and writes one row per
checkpoint: CSV and a PNG of the mean level of each terrain type against env steps.

    python scripts/lineage_levels.py policies/teacher:2800 policies/teacher_wide:3380 \
        policies/teacher_wide_edge --out docs/teacher_lineage_levels --mark 8.1   # -> .csv, .png

Folders are walked in the order given; ``FOLDER:N`` keeps that folder's checkpoints up to
iteration N (where the next folder branched off it), and a checkpoint is kept only when its
iteration is above the last one kept (a branch continues its parent's iteration count), so the
rows follow one lineage. Env steps are iteration x ppo.num_envs x ppo.num_steps of the folder's config.
"""

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from foottof.lab.levels import level_counts, mean_level  # noqa: E402


def shipped(folder: str) -> list[tuple[str, int]]:
    """(commit, checkpoint iteration) of each commit that changed ``folder``'s checkpoints,
    oldest first."""
    log = subprocess.run(
        ["git", "log", "--reverse", "--format=%H", "--", f"{folder}/checkpoints"],
        check=True, capture_output=True, text=True,
    ).stdout.split()  # fmt: skip
    out = []
    for commit in log:
        names = subprocess.run(
            ["git", "ls-tree", "--name-only", f"{commit}:{folder}/checkpoints"],
            capture_output=True, text=True,
        ).stdout.split()  # fmt: skip
        steps = sorted(int(n) for n in names if n.isdigit())
        if steps:
            out.append((commit, steps[-1]))
    return out


def levels_at(folder: str, commit: str, tmp: str) -> tuple[dict, int]:
    """({terrain type: mean level}, env steps per iteration) of ``folder`` as of ``commit``."""
    dest = os.path.join(tmp, commit[:12])
    os.makedirs(dest, exist_ok=True)
    tar = subprocess.run(["git", "archive", commit, folder], check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", dest], input=tar.stdout, check=True)
    run = os.path.join(dest, folder)
    with open(os.path.join(run, "config.json")) as f:
        ppo = json.load(f)["ppo"]
    means = {t: mean_level(c) for t, c in level_counts(run).items()}
    return means, int(ppo["num_envs"]) * int(ppo["num_steps"])


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "folders", nargs="+", help="shipped run folders FOLDER[:MAX_ITERATION], parent first"
    )
    p.add_argument("--out", required=True, help="output path without extension (.csv, .png)")
    p.add_argument("--mark", type=float, default=None,
                   help="draw this level as a dashed line (the ensemble: 0.9 x (levels - 1))")  # fmt: skip
    args = p.parse_args(argv)
    rows, last = [], -1
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.folders:
            folder, _, until = spec.partition(":")
            folder = folder.rstrip("/")
            if until and not until.isdigit():
                raise SystemExit(
                    f"error: {spec!r}: the part after ':' must be an iteration, got {until!r}"
                )
            for commit, it in shipped(folder):
                if it <= last or (until and it > int(until)):
                    continue
                means, per_it = levels_at(folder, commit, tmp)
                rows.append({"folder": folder, "commit": commit[:7], "iteration": it,
                             "env_steps": it * per_it, **{k: round(v, 3) for k, v in means.items()}})  # fmt: skip
                last = it
                print(json.dumps(rows[-1]))
    if not rows:
        raise SystemExit(f"error: no shipped checkpoint in git for {args.folders}")
    types = [k for k in rows[0] if k not in ("folder", "commit", "iteration", "env_steps")]
    with open(args.out + ".csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    x = [r["env_steps"] / 1e6 for r in rows]
    for t in types:
        ax.plot(x, [r[t] for r in rows], marker="o", label=t)
    for prev, r in zip(rows, rows[1:], strict=False):
        if r["folder"] != prev["folder"]:  # where a branch takes over
            ax.axvline(prev["env_steps"] / 1e6, color="0.8", lw=0.8)
    if args.mark is not None:
        ax.axhline(args.mark, color="k", ls="--", lw=0.8, label=f"level {args.mark:g}")
    ax.set_xlabel("env steps [M]")
    ax.set_ylabel("mean curriculum level")
    ax.set_title(
        " -> ".join(os.path.basename(f.split(":")[0].rstrip("/")) for f in args.folders), fontsize=9
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out + ".png", dpi=110)
    print(f"wrote {args.out}.csv, {args.out}.png")


if __name__ == "__main__":
    main()
