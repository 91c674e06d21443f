"""Results files of the robustness evaluation: JSON/CSV per sweep, the figure, atomic writes."""

from __future__ import annotations

import csv
import glob
import hashlib
import io
import json
import math
import os

import numpy as np

from foottof import renames
from foottof.files import write_atomic

SCHEMA_VERSION = 4  # 2: adds "ensemble" (difficulty, stone share, actions); 3: mean_speed_mps;
# 4: the ensemble records the action std cap of sampled actions (older files: migrate_ensemble)
RESULT_KEYS = (  # exact key set (and CSV column order) of one result row
    "source",
    "perturbation",
    "level",
    "episodes",
    "successes",
    "success_rate",
    "ci_low",
    "ci_high",
    "mean_speed_mps",
    "falls",
)
TOP_KEYS = ("schema_version", "checkpoint", "episode_length_s", "ensemble", "results")
ENSEMBLE_KEYS = (  # exact key set of the "ensemble" entry (ensemble_setting)
    "difficulty_fraction",
    "stone_fraction",
    "stone_types",
    "gap_types",
    "deterministic",
    "action_std_cap",  # network.max_noise_std of sampled actions (0: no cap); None: mean actions
    "fingerprint",
)

# Per-episode outcomes (episodes_<source>_<perturbation>.json), for paired comparisons of two
# policies on the same episode draws (foottof.eval.paired).
EPISODES_SCHEMA_VERSION = 2  # 2: mean_speed_ms renamed mean_speed_mps (1 is read, migrated)
EPISODE_KEYS = ("terrain", "success", "failed", "finished", "length", "mean_speed_mps")  # (n,)
# Config sections that decide the episode draws (map, spawn/goal, sensor noise) and outcomes of an
# evaluation; the policy's own sections (ppo, network, train) and the top-level training seed
# do not. Leaves of c.eval that only choose what runs or where it goes are left out too.
DRAW_SECTIONS = ("env", "eval", "noise", "reward", "sensor", "stage", "terrain")
_NOT_DRAW_EVAL_KEYS = (
    "episodes",
    "out_dir",
    "sources",
    "joint_offset_levels",
    "shank_length_levels",
    "odometry_levels",
)
# Env fields that change what the actor reads and no draw: a teacher (env.actor_terrain) and its
# ToF student run the same episodes, so their evaluations pair.
_NOT_DRAW_ENV_KEYS = ("actor_terrain", "actor_terrain_seen", "actor_terrain_fine")


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
        "mean_speed_mps": float(np.mean(outcomes["mean_speed_mps"])) if n else float("nan"),
        "falls": int(outcomes["failed"].sum()),
    }


def results_document(
    rows: list[dict], checkpoint: str | None, episode_length_s: float, ensemble: dict
) -> dict:
    """The results JSON document (keys TOP_KEYS; each row keys RESULT_KEYS; ``ensemble`` from
    :func:`ensemble_setting`)."""
    for r in rows:
        if tuple(r) != RESULT_KEYS:
            raise ValueError(f"result row keys {tuple(r)} differ from {RESULT_KEYS}")
    if tuple(ensemble) != ENSEMBLE_KEYS:
        raise ValueError(f"ensemble keys {tuple(ensemble)} differ from {ENSEMBLE_KEYS}")
    return {
        "schema_version": SCHEMA_VERSION,
        "checkpoint": checkpoint or "untrained (fresh init)",
        "episode_length_s": float(episode_length_s),
        "ensemble": ensemble,
        "results": rows,
    }


def action_std_cap(cfg) -> float | None:
    """The action std cap an evaluation sampled at: network.max_noise_std (0: no cap) when
    eval.deterministic is False; None for mean actions (no std is used)."""
    return None if cfg.eval.deterministic else float(cfg.network.max_noise_std)


def ensemble_setting(cfg) -> dict:
    """What an evaluation ran on (the results file's "ensemble"): eval.difficulty_fraction,
    stone_fraction, stone/gap types, deterministic, the action std cap of sampled actions
    (:func:`action_std_cap`) and draws_fingerprint (equal fingerprints: the same terrain,
    episode draws and env settings). Only results of equal settings share a figure."""
    e = cfg.eval
    return {
        "difficulty_fraction": float(e.difficulty_fraction),
        "stone_fraction": float(e.stone_fraction),
        "stone_types": list(e.stone_types),
        "gap_types": list(e.gap_types),
        "deterministic": bool(e.deterministic),
        "action_std_cap": action_std_cap(cfg),
        "fingerprint": draws_fingerprint(cfg),
    }


def migrate_ensemble(ensemble):
    """An older results file's "ensemble" in this schema's keys: a file of mean actions written
    before schema 4 gets "action_std_cap" None (it used no std); one of sampled actions keeps
    the key missing, since its cap was not recorded (it then matches no new ensemble). Anything
    that is not a dict is returned as it is."""
    if not isinstance(ensemble, dict) or "action_std_cap" in ensemble:
        return ensemble
    if ensemble.get("deterministic") is not True:
        return ensemble
    return dict(ensemble, action_std_cap=None)


def ensemble_caption(ensemble: dict, rows: list[dict], checkpoints: list[str] = ()) -> str:
    """One line naming what a figure shows, e.g. 'ensemble: 80 % stepping stones + 20 % gaps at
    90 % of the stage-1 difficulty range, mean actions, 1000 episodes per cell; policy:
    policies/latest' (``checkpoints``: those of the drawn results files, in order; more than one
    are all named)."""
    stones = round(100 * ensemble["stone_fraction"])
    counts = sorted({int(r["episodes"]) for r in rows})
    per_cell = f"{counts[0]}" if len(counts) == 1 else f"{counts[0]}-{counts[-1]}"
    cap = ensemble.get("action_std_cap")
    actions = "mean actions" if ensemble["deterministic"] else "sampled actions"
    actions += f" (std capped at {cap:g})" if cap else ""
    text = (
        f"ensemble: {stones} % stepping stones + {100 - stones} % gaps at "
        f"{100 * ensemble['difficulty_fraction']:g} % of the stage-1 difficulty range, {actions}, "
        f"{per_cell} episodes per cell"
    )
    names = list(dict.fromkeys(checkpoints))
    if names:
        text += ("; policy: " if len(names) == 1 else "; policies: ") + ", ".join(names)
    return text


def _stone_curriculum_moot(cfg) -> bool:
    """True where every stone type of the evaluation ensemble is drawn at a difficulty at or past
    tiles.ENSEMBLE_KNOT, from where all stone curricula hold the same values (exactly: a knot's
    values at the knot), so terrain.stone_curriculum does not change the episodes."""
    from foottof.limits import ENSEMBLE_KNOT, STONE_TYPES

    frac = float(cfg.eval.difficulty_fraction)
    for name in cfg.eval.stone_types:
        if name not in STONE_TYPES:
            continue
        lo, hi = cfg.terrain.stage1_difficulty[name]
        if np.float32(lo + frac * (hi - lo)) < np.float32(ENSEMBLE_KNOT):
            return False
    return True


def draws_fingerprint(cfg) -> str:
    """sha256 (16 hex digits) of the config leaves that decide an evaluation's episode draws
    and outcomes (DRAW_SECTIONS): two evaluations with equal fingerprints, seeds, batch sizes and
    episode counts ran the same episodes, so their outcomes pair episode by episode. Renamed
    fields are hashed under their old names (foottof.renames): a rename keeps the fingerprint.
    ``eval.deterministic`` is hashed as True: mean and sampled actions of one policy pair.
    ``terrain.stone_curriculum`` is left out where the ensemble's stones do not depend on it
    (difficulty at or past tiles.ENSEMBLE_KNOT, the 90 % ensemble among them)."""
    d = {k: cfg[k].to_dict() if hasattr(cfg[k], "to_dict") else cfg[k] for k in DRAW_SECTIONS}
    d = renames.legacy_config_dict(d)  # renamed fields hash under their first names
    if _stone_curriculum_moot(cfg):  # the ensemble's stones are the same in every curriculum
        d["terrain"] = {k: v for k, v in d["terrain"].items() if k != "stone_curriculum"}
    d["eval"] = dict(d["eval"])
    for k in _NOT_DRAW_EVAL_KEYS:
        d["eval"].pop(k, None)
    if "deterministic" in d["eval"]:
        # Mean or sampled actions is the policy's choice, not a draw (the action keys are split
        # off the reset keys in robustness.make_rollout): hashed as mean actions, so a sampled
        # evaluation pairs with a mean one and mean-action fingerprints are as before.
        d["eval"]["deterministic"] = True
    d["env"] = dict(d["env"])
    for k in _NOT_DRAW_ENV_KEYS:
        d["env"].pop(k, None)
    text = json.dumps(d, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def episode_draws(cfg) -> dict:
    """What two evaluations must share for their episodes to pair (episodes_document's draws):
    eval.seed, the batch size actually run, eval.episodes and draws_fingerprint."""
    episodes = int(cfg.eval.episodes)
    return {
        "seed": int(cfg.eval.seed),
        "num_envs": min(int(cfg.eval.num_envs), episodes),
        "episodes": episodes,
        "fingerprint": draws_fingerprint(cfg),
    }


def episodes_document(cells: list[tuple[dict, dict]], checkpoint: str | None, draws: dict) -> dict:
    """Per-episode outcomes of the cells of one results file.

    Args:
      cells: (result row, first-episode outcomes) per cell; the outcomes are the (n,) arrays of
        robustness.first_episode_outcomes, concatenated over the batches of the cell.
      checkpoint: the evaluated checkpoint (None: untrained).
      draws: what pairs two evaluations: {"seed", "num_envs", "episodes", "fingerprint"}.
    """
    out = []
    for row, outcomes in cells:
        n = row["episodes"]
        cell = {k: row[k] for k in ("source", "perturbation", "level")}
        for k in EPISODE_KEYS:
            v = np.asarray(outcomes[k])
            if v.shape != (n,):
                raise ValueError(f"episode outcome {k!r} has shape {v.shape}; expected ({n},)")
            if k == "terrain":
                cell[k] = [str(x) for x in v]
            elif k == "mean_speed_mps":
                cell[k] = [round(float(x), 4) for x in v]
            else:
                cell[k] = v.astype(int).tolist()
        if sum(cell["success"]) != row["successes"] or sum(cell["failed"]) != row["falls"]:
            raise ValueError(
                f"episode outcomes of {cell['source']}/{cell['perturbation']} "
                f"level {cell['level']} disagree with its result row"
            )
        out.append(cell)
    return {
        "schema_version": EPISODES_SCHEMA_VERSION,
        "checkpoint": checkpoint or "untrained (fresh init)",
        "draws": dict(draws),
        "cells": out,
    }


def terrain_breakdown(episodes_doc: dict) -> list[dict]:
    """Per cell and terrain type of an episodes document: episodes, successes, falls, rate."""
    rows = []
    for cell in episodes_doc["cells"]:
        for t in dict.fromkeys(cell["terrain"]):  # types in order of first appearance
            idx = [i for i, x in enumerate(cell["terrain"]) if x == t]
            k = sum(cell["success"][i] for i in idx)
            rows.append(
                {
                    "source": cell["source"],
                    "perturbation": cell["perturbation"],
                    "level": cell["level"],
                    "terrain": t,
                    "episodes": len(idx),
                    "successes": k,
                    "success_rate": k / len(idx),
                    "falls": sum(cell["failed"][i] for i in idx),
                }
            )
    return rows


def format_terrain_breakdown(rows: list[dict]) -> str:
    """Human-readable terrain_breakdown."""
    head = (
        f"{'source':<11}{'perturbation':<14}{'level':>7}  {'terrain':<18}{'episodes':>9}"
        f"{'success':>9}{'rate':>7}{'falls':>7}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['source']:<11}{r['perturbation']:<14}{r['level']:>7.3g}  {r['terrain']:<18}"
            f"{r['episodes']:>9d}{r['successes']:>9d}{r['success_rate']:>7.3f}{r['falls']:>7d}"
        )
    return "\n".join(lines)


def episodes_basename(source: str, perturbation: str) -> str:
    return f"episodes_{source}_{perturbation}"


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
            f"[{r['ci_low']:.3f},{r['ci_high']:.3f}]{r['mean_speed_mps']:>10.3f}{r['falls']:>7d}"
        )
    return "\n".join(lines)


def result_basename(source: str, perturbation: str) -> str:
    return f"results_{source}_{perturbation}"


def write_results(
    out_dir: str, source_flag: str, perturbation: str, doc: dict, episodes: dict | None = None
) -> dict:
    """Writes results_<source>_<perturbation>.{json,csv} and robustness.png (the results in
    out_dir of the same ensemble as ``doc`` on shared axes, captioned with it; files of another
    ensemble are named under the figure, not drawn), and with ``episodes`` (episodes_document)
    the per-episode outcomes episodes_<source>_<perturbation>.json; returns {kind: path}."""
    from foottof.eval.plots import robustness_png

    base = os.path.join(out_dir, result_basename(source_flag, perturbation))
    paths = {
        "json": base + ".json",
        "csv": base + ".csv",
        "png": os.path.join(out_dir, "robustness.png"),
    }
    if episodes is not None:
        paths["episodes"] = os.path.join(
            out_dir, episodes_basename(source_flag, perturbation) + ".json"
        )
    others = [p for p in glob.glob(os.path.join(out_dir, "results_*.json")) if p != paths["json"]]
    rows = list(doc["results"])
    seen = {(r["source"], r["perturbation"], r["level"]) for r in rows}
    left_out = []  # results files of another ensemble (or an older schema): not on this figure
    checkpoints = [doc["checkpoint"]]
    for p in sorted(others, key=os.path.getmtime, reverse=True):  # newest first wins
        try:
            with open(p) as f:
                other = json.load(f)
            more = [renames.migrate_row(r) for r in other["results"]]
            more = [r for r in more if tuple(r) == RESULT_KEYS]
        except (OSError, ValueError, KeyError, TypeError):
            continue  # a foreign or damaged file: not plotted
        if migrate_ensemble(other.get("ensemble")) != doc["ensemble"]:
            left_out.append(os.path.basename(p))
            continue
        drawn = [r for r in more if (r["source"], r["perturbation"], r["level"]) not in seen]
        for r in drawn:
            seen.add((r["source"], r["perturbation"], r["level"]))
            rows.append(r)
        if drawn:
            checkpoints.append(str(other.get("checkpoint")))
    caption = ensemble_caption(doc["ensemble"], rows, checkpoints)
    files = {
        paths["json"]: json.dumps(doc, indent=2).encode(),
        paths["csv"]: csv_text(doc["results"]).encode(),
        paths["png"]: robustness_png(rows, caption, sorted(left_out)),
    }
    if episodes is not None:
        files[paths["episodes"]] = json.dumps(episodes).encode()
    write_atomic(files)
    return paths


def write_run(
    out_dir: str,
    source_flag: str,
    perturbation_flag: str | None,
    rows: list[dict],
    checkpoint: str | None,
    episode_length_s: float,
    episodes: list[dict] | None = None,
    draws: dict | None = None,
    *,
    ensemble: dict,
) -> list[str]:
    """Writes the rows of one evaluate.py run (write_results); returns the paths written.

    One results file named by the --perturbation flag; without the flag (each source's default
    sweep) one file per perturbation that ran, so a later explicit run of it replaces it.
    ``episodes`` (the first-episode outcomes of each row, in row order) and ``draws`` (see
    episodes_document) add the per-episode file next to each results file. ``ensemble``
    (:func:`ensemble_setting`) is recorded in every results file.
    """
    if episodes is not None and (draws is None or len(episodes) != len(rows)):
        raise ValueError("per-episode outcomes need draws and one outcome set per result row")
    names = (
        [perturbation_flag]
        if perturbation_flag
        else list(dict.fromkeys(r["perturbation"] for r in rows))
    )
    paths = []
    for name in names:
        idx = [i for i, r in enumerate(rows) if perturbation_flag or r["perturbation"] == name]
        doc = results_document([rows[i] for i in idx], checkpoint, episode_length_s, ensemble)
        ep_doc = (
            None
            if episodes is None
            else episodes_document([(rows[i], episodes[i]) for i in idx], checkpoint, draws)
        )
        written = write_results(out_dir, source_flag, name, doc, ep_doc).values()
        paths += [p for p in written if p not in paths]
    return paths
