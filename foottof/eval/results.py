"""Results files of the robustness evaluation: JSON/CSV per sweep, the figure, atomic writes."""

from __future__ import annotations

import csv
import glob
import io
import json
import math
import os

import numpy as np

SCHEMA_VERSION = 1
RESULT_KEYS = (  # exact key set (and CSV column order) of one result row
    "source",
    "perturbation",
    "level",
    "episodes",
    "successes",
    "success_rate",
    "ci_low",
    "ci_high",
    "mean_speed_ms",
    "falls",
)
TOP_KEYS = ("schema_version", "checkpoint", "episode_length_s", "results")


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % for the default z).

    Returns (low, high) in [0, 1]; (0, 1) for n = 0.
    """
    if n < 0 or successes < 0 or successes > n:
        raise ValueError(f"successes={successes}, n={n}: need 0 <= successes <= n")
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def summarize(source: str, perturbation: str, level: float, outcomes: dict) -> dict:
    """One result row (keys RESULT_KEYS) from concatenated first-episode outcomes."""
    n = int(outcomes["success"].shape[0])
    k = int(outcomes["success"].sum())
    lo, hi = wilson_interval(k, n)
    return {
        "source": source,
        "perturbation": perturbation,
        "level": float(level),
        "episodes": n,
        "successes": k,
        "success_rate": k / n if n else float("nan"),
        "ci_low": lo,
        "ci_high": hi,
        "mean_speed_ms": float(np.mean(outcomes["mean_speed_ms"])) if n else float("nan"),
        "falls": int(outcomes["failed"].sum()),
    }


def results_document(rows: list[dict], checkpoint: str | None, episode_length_s: float) -> dict:
    """The results JSON document (keys TOP_KEYS; each row keys RESULT_KEYS)."""
    for r in rows:
        if tuple(r) != RESULT_KEYS:
            raise ValueError(f"result row keys {tuple(r)} differ from {RESULT_KEYS}")
    return {
        "schema_version": SCHEMA_VERSION,
        "checkpoint": checkpoint or "untrained (fresh init)",
        "episode_length_s": float(episode_length_s),
        "results": rows,
    }


def csv_text(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=RESULT_KEYS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    return buf.getvalue()


def format_table(rows: list[dict]) -> str:
    """Human-readable table of result rows."""
    head = (
        f"{'source':<11}{'perturbation':<14}{'level':>7}{'episodes':>9}{'success':>9}"
        f"{'rate':>7}  {'95% CI':<13}{'speed m/s':>10}{'falls':>7}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['source']:<11}{r['perturbation']:<14}{r['level']:>7.3g}{r['episodes']:>9d}"
            f"{r['successes']:>9d}{r['success_rate']:>7.3f}  "
            f"[{r['ci_low']:.3f},{r['ci_high']:.3f}]{r['mean_speed_ms']:>10.3f}{r['falls']:>7d}"
        )
    return "\n".join(lines)


def write_atomic(files: dict[str, bytes]) -> None:
    """Writes every {path: bytes} to path.tmp first, then renames all (no partial outputs)."""
    tmps = []
    try:
        for path, data in files.items():
            os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
            tmp = path + ".tmp"
            with open(tmp, "wb") as f:
                f.write(data)
            tmps.append((tmp, path))
    except BaseException:
        for tmp, _ in tmps:
            if os.path.exists(tmp):
                os.remove(tmp)
        raise
    for tmp, path in tmps:
        os.replace(tmp, path)


def result_basename(source: str, perturbation: str) -> str:
    return f"results_{source}_{perturbation}"


def write_results(out_dir: str, source_flag: str, perturbation: str, doc: dict) -> dict:
    """Writes results_<source>_<perturbation>.{json,csv} and robustness.png (all results in
    out_dir on shared axes); returns {kind: path}."""
    from foottof.eval.plots import robustness_png

    base = os.path.join(out_dir, result_basename(source_flag, perturbation))
    paths = {
        "json": base + ".json",
        "csv": base + ".csv",
        "png": os.path.join(out_dir, "robustness.png"),
    }
    others = [p for p in glob.glob(os.path.join(out_dir, "results_*.json")) if p != paths["json"]]
    rows = list(doc["results"])
    seen = {(r["source"], r["perturbation"], r["level"]) for r in rows}
    for p in sorted(others, key=os.path.getmtime, reverse=True):  # newest first wins
        try:
            with open(p) as f:
                more = [r for r in json.load(f)["results"] if tuple(r) == RESULT_KEYS]
        except (OSError, ValueError, KeyError, TypeError):
            continue  # a foreign or damaged file: not plotted
        for r in more:
            if (r["source"], r["perturbation"], r["level"]) not in seen:
                seen.add((r["source"], r["perturbation"], r["level"]))
                rows.append(r)
    write_atomic(
        {
            paths["json"]: json.dumps(doc, indent=2).encode(),
            paths["csv"]: csv_text(doc["results"]).encode(),
            paths["png"]: robustness_png(rows),
        }
    )
    return paths


def write_run(
    out_dir: str,
    source_flag: str,
    perturbation_flag: str | None,
    rows: list[dict],
    checkpoint: str | None,
    episode_length_s: float,
) -> list[str]:
    """Writes the rows of one evaluate.py run (write_results); returns the paths written.

    One results file named by the --perturbation flag; without the flag (each source's default
    sweep) one file per perturbation that ran, so a later explicit run of it replaces it.
    """
    names = (
        [perturbation_flag]
        if perturbation_flag
        else list(dict.fromkeys(r["perturbation"] for r in rows))
    )
    paths = []
    for name in names:
        sel = rows if perturbation_flag else [r for r in rows if r["perturbation"] == name]
        doc = results_document(sel, checkpoint, episode_length_s)
        written = write_results(out_dir, source_flag, name, doc).values()
        paths += [p for p in written if p not in paths]
    return paths
