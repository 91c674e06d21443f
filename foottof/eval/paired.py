"""Paired comparison of two evaluations of the same episodes (two checkpoints, two branches).

``python -m foottof.eval.paired NAME=OUT_DIR NAME=OUT_DIR [--out FILE.csv]`` reads the
per-episode files (``episodes_<source>_<perturbation>.json``) that ``evaluate.py`` writes next to
its results, pairs the cells both folders hold (same source, perturbation and level) episode by
episode, and prints per cell: the successes of each, the discordant episodes (succeeded in one
only) and the exact two-sided McNemar p-value (a binomial test of the discordant episodes at
1/2). Evaluations pair only when they ran the same draws: the same ``eval.seed``, batch size,
episode count and config fingerprint (``results.draws_fingerprint``); anything else is an error
that names what differs. Mean and sampled actions of the same draws pair (one line before the
table names how each acted when they differ).

``python -m foottof.eval.paired --figure OUT_DIR [--out FILE.csv]`` pairs sources instead, within
one robustness-figure folder (every source there ran the same draws): per panel, ``tof`` against
the panel's mock (FIGURE_PANELS: ``mock_ideal`` for joint offset and shank length, ``mock_aggre``
for odometry), level by level, as the paper compares them.

Why paired: with 200 episodes per cell a Wilson interval is about +-0.07 wide, so two
independent rates must differ by ~0.1 to tell apart. On the same draws most episodes end the
same way for both policies, and only the discordant ones carry the difference.
"""

from __future__ import annotations

import argparse
import csv
import glob
import io
import json
import math
import os

from foottof import files, renames
from foottof.eval import results

PAIRED_KEYS = (  # CSV columns of --out
    "source",
    "perturbation",
    "level",
    "episodes",
    "successes_a",
    "successes_b",
    "a_only",
    "b_only",
    "p_value",
    "falls_a",
    "falls_b",
    "timeouts_a",  # neither a success nor a fall: the deadline away from the goal
    "timeouts_b",
)


def parse_branch(arg: str) -> tuple[str, str]:
    """``NAME=DIR`` -> (name, dir); a bare ``DIR`` is named by its base name (the paired tool's
    folders and the A/B tool's run directories, foottof.lab.compare, which sits above eval/)."""
    name, sep, path = arg.partition("=")
    if not sep:
        name, path = os.path.basename(os.path.normpath(arg)), arg
    if not name or not path:
        raise ValueError(f"branch {arg!r}: expected NAME=DIR")
    return name, path


def mcnemar_exact(a_only: int, b_only: int) -> float:
    """Exact two-sided McNemar p-value: P(as extreme a split of the a_only + b_only discordant
    pairs under Binomial(n, 1/2)); 1 when there are none."""
    if a_only < 0 or b_only < 0:
        raise ValueError(f"discordant counts {a_only}, {b_only}: must be >= 0")
    n = a_only + b_only
    if n == 0:
        return 1.0
    k = min(a_only, b_only)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0**n
    return min(1.0, 2.0 * tail)


def load_episodes(path: str) -> dict:
    """An episodes_*.json document (results.episodes_document), checked for its schema."""
    with open(path) as f:
        doc = json.load(f)
    version = doc.get("schema_version") if isinstance(doc, dict) else None
    if version not in (1, results.EPISODES_SCHEMA_VERSION):
        raise ValueError(
            f"{path}: episodes schema version {version!r}; this code reads 1 and "
            f"{results.EPISODES_SCHEMA_VERSION}"
        )
    if version == 1:  # mean_speed_ms -> mean_speed_mps (foottof.renames)
        doc = dict(doc, schema_version=results.EPISODES_SCHEMA_VERSION)
        doc["cells"] = [renames.migrate_row(c) for c in doc["cells"]]
    return doc


def check_same_draws(doc_a: dict, doc_b: dict, names=("a", "b")) -> None:
    """Raises ValueError naming the first draw setting the two evaluations differ in."""
    da, db = doc_a["draws"], doc_b["draws"]
    for k in ("seed", "num_envs", "episodes", "fingerprint"):
        if da.get(k) != db.get(k):
            what = (
                "config (env/eval/noise/reward/sensor/stage/terrain)" if k == "fingerprint" else k
            )
            raise ValueError(
                f"not the same episodes: {what} differs ({names[0]}: {da.get(k)!r}, "
                f"{names[1]}: {db.get(k)!r}); evaluate both with the same config, "
                "--episodes and eval.seed"
            )


def _pair_row(ca: dict, cb: dict, source: str) -> dict:
    """One PAIRED_KEYS row from two cells of the same episodes."""
    sa, sb = ca["success"], cb["success"]
    if len(sa) != len(sb):
        raise ValueError(
            f"cell {ca['source']}/{ca['perturbation']}/{ca['level']} vs "
            f"{cb['source']}/{cb['perturbation']}/{cb['level']}: {len(sa)} vs {len(sb)} episodes"
        )
    a_only = sum(1 for x, y in zip(sa, sb, strict=True) if x and not y)
    b_only = sum(1 for x, y in zip(sa, sb, strict=True) if y and not x)
    return {
        "source": source,
        "perturbation": ca["perturbation"],
        "level": ca["level"],
        "episodes": len(sa),
        "successes_a": sum(sa),
        "successes_b": sum(sb),
        "a_only": a_only,
        "b_only": b_only,
        "p_value": mcnemar_exact(a_only, b_only),
        "falls_a": sum(ca["failed"]),
        "falls_b": sum(cb["failed"]),
        "timeouts_a": _timeouts(ca),
        "timeouts_b": _timeouts(cb),
    }


def _timeouts(cell: dict) -> int:
    """Episodes of a cell that ended neither in a success nor in a fall (the deadline, or no end
    within the rollout)."""
    return sum(1 for s, f in zip(cell["success"], cell["failed"], strict=True) if not s and not f)


def pair_cells(doc_a: dict, doc_b: dict, names=("a", "b")) -> list[dict]:
    """One row (PAIRED_KEYS) per cell present in both documents, in doc_a's order."""
    check_same_draws(doc_a, doc_b, names)
    cells_b = {(c["source"], c["perturbation"], c["level"]): c for c in doc_b["cells"]}
    rows = []
    for ca in doc_a["cells"]:
        cb = cells_b.get((ca["source"], ca["perturbation"], ca["level"]))
        if cb is not None:
            rows.append(_pair_row(ca, cb, ca["source"]))
    return rows


# The robustness figure's panels: the perturbation and the mock that `tof` is compared with.
FIGURE_PANELS = {
    "joint_offset": "mock_ideal",
    "shank_length": "mock_ideal",
    "odometry": "mock_aggre",
}


def pair_sources(doc_tof: dict, doc_mock: dict) -> list[dict]:
    """``tof`` (a) against a mock (b) on the same episodes, one row per level both hold, in
    doc_tof's order; the row's source reads ``tof|<mock>``."""
    check_same_draws(doc_tof, doc_mock, ("tof", "mock"))
    cells_m = {(c["perturbation"], c["level"]): c for c in doc_mock["cells"]}
    rows = []
    for ct in doc_tof["cells"]:
        cm = cells_m.get((ct["perturbation"], ct["level"]))
        if cm is not None:
            rows.append(_pair_row(ct, cm, f"{ct['source']}|{cm['source']}"))
    return rows


def pair_figure(out_dir: str) -> list[dict]:
    """pair_sources for each FIGURE_PANELS panel whose two sweeps the folder holds.

    Raises:
      FileNotFoundError: no such folder, or not one panel with both sweeps in it.
    """
    if not os.path.isdir(out_dir):
        raise FileNotFoundError(f"{out_dir}: no such evaluation folder")
    rows, missing = [], []
    for pert, mock in FIGURE_PANELS.items():
        paths = [os.path.join(out_dir, f"episodes_{s}_{pert}.json") for s in ("tof", mock)]
        if not all(os.path.exists(p) for p in paths):
            missing.append(" + ".join(os.path.basename(p) for p in paths))
            continue
        rows += pair_sources(*(load_episodes(p) for p in paths))
    if not rows:
        raise FileNotFoundError(
            f"{out_dir}: no panel of the figure with both sweeps (needs {'; or '.join(missing)}); "
            "evaluate.py --source tof and the mock with the same --out, --episodes and eval.seed"
        )
    return rows


def pair_folders(dir_a: str, dir_b: str, names=("a", "b")) -> list[dict]:
    """pair_cells over every episodes_*.json file the two evaluation folders share."""
    files = {}
    for d in (dir_a, dir_b):
        if not os.path.isdir(d):
            raise FileNotFoundError(f"{d}: no such evaluation folder")
        files[d] = {os.path.basename(p) for p in glob.glob(os.path.join(d, "episodes_*.json"))}
    common = sorted(files[dir_a] & files[dir_b])
    if not common:
        raise FileNotFoundError(
            f"no per-episode file (episodes_*.json) in both {dir_a} ({sorted(files[dir_a])}) and "
            f"{dir_b} ({sorted(files[dir_b])}); evaluate.py writes them next to its results"
        )
    rows = []
    for name in common:
        a = load_episodes(os.path.join(dir_a, name))
        b = load_episodes(os.path.join(dir_b, name))
        rows += pair_cells(a, b, names)
    if not rows:
        raise ValueError(f"{dir_a} and {dir_b} share no (source, perturbation, level) cell")
    return rows


def actions_of(out_dir: str) -> str | None:
    """How an evaluation folder's policy acted, from its results files' "ensemble" ('mean
    actions' or 'sampled actions (std capped at S)'); None when no file records it. Mean and
    sampled evaluations of the same draws pair (results.draws_fingerprint)."""
    seen = set()
    for path in sorted(glob.glob(os.path.join(out_dir, "results_*.json"))):
        with open(path) as f:
            ens = results.migrate_ensemble(json.load(f).get("ensemble"))
        if isinstance(ens, dict) and "deterministic" in ens:
            cap = ens.get("action_std_cap")
            seen.add(
                "mean actions"
                if ens["deterministic"]
                else "sampled actions" + (f" (std capped at {cap:g})" if cap else "")
            )
    return "; ".join(sorted(seen)) or None


def format_table(rows: list[dict], names=("a", "b")) -> str:
    """The paired rows as a fixed-width table; every column at least one wider than its
    header, so long branch names stay apart."""
    a, b = names
    w = max([11] + [len(r["source"]) + 2 for r in rows])
    cols = [  # (header, minimum width, cell)
        ("level", 7, lambda r: f"{r['level']:.3g}"),
        ("n", 6, lambda r: f"{r['episodes']:d}"),
        (a, 12, lambda r: f"{r['successes_a'] / r['episodes']:.3f}"),
        (b, 12, lambda r: f"{r['successes_b'] / r['episodes']:.3f}"),
        (a + " only", 12, lambda r: f"{r['a_only']:d}"),
        (b + " only", 12, lambda r: f"{r['b_only']:d}"),
        ("McNemar p", 11, lambda r: f"{r['p_value']:.3g}"),
        ("falls " + a, 12, lambda r: f"{r['falls_a']:d}"),
        ("falls " + b, 12, lambda r: f"{r['falls_b']:d}"),
        ("timeouts " + a, 14, lambda r: f"{r['timeouts_a']:d}"),
        ("timeouts " + b, 14, lambda r: f"{r['timeouts_b']:d}"),
    ]
    widths = [max(m, len(h) + 1) for h, m, _ in cols]
    head = f"{'source':<{w}}{'perturbation':<14}" + "".join(
        f"{h:>{cw}}" for (h, _, _), cw in zip(cols, widths, strict=True)
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['source']:<{w}}{r['perturbation']:<14}"
            + "".join(f"{cell(r):>{cw}}" for (_, _, cell), cw in zip(cols, widths, strict=True))
        )
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a", nargs="?", help="NAME=OUT_DIR of the first evaluation (evaluate.py --out)")
    ap.add_argument("b", nargs="?", help="NAME=OUT_DIR of the second evaluation")
    ap.add_argument(
        "--figure",
        metavar="OUT_DIR",
        help="instead: tof against each panel's mock within one robustness-figure folder",
    )
    ap.add_argument("--out", help="write the paired rows as CSV")
    args = ap.parse_args(argv)
    positional = [x for x in (args.a, args.b) if x is not None]
    if (args.figure is None and len(positional) != 2) or (args.figure is not None and positional):
        raise SystemExit("error: give two NAME=OUT_DIR evaluations, or --figure OUT_DIR alone")
    try:
        if args.figure:
            names = ("tof", "mock")
            rows = pair_figure(args.figure)
        else:
            (na, da), (nb, db) = parse_branch(args.a), parse_branch(args.b)
            names = (na, nb)
            rows = pair_folders(da, db, names)
            acts = (actions_of(da), actions_of(db))
            if acts[0] != acts[1]:  # say what is compared when the policies acted differently
                print(
                    f"actions: {na} {acts[0] or 'not recorded'}, {nb} {acts[1] or 'not recorded'}"
                )
    except (ValueError, FileNotFoundError) as e:
        raise SystemExit(f"error: {e}") from None
    print(format_table(rows, names))
    if args.out:
        f = io.StringIO(newline="")
        w = csv.DictWriter(f, fieldnames=PAIRED_KEYS, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
        files.write_atomic({args.out: f.getvalue().encode()})
        print(f"[paired] wrote {args.out}")


if __name__ == "__main__":
    main()
