"""Finished cells of an evaluation kept on disk, so that an interrupted sweep resumes.

A robustness figure at the paper's ensemble is hours of CPU (1000 episodes per cell, ~12 min a
``mock_aggre`` cell on 2 cores), longer than a working session. evaluate.py writes each cell
(one source x perturbation x level: its result row and per-episode outcomes) to
``<out>/cells/`` as it finishes; the same command run again loads the cells whose identity
matches instead of running them, and removes the cell files once the results files are written.

A cell is reused only when everything that decides its outcomes is equal: the policy files
(integrity.policy_digest), the episode draws (results.episode_draws: seed, batch size, episode
count, config fingerprint) and the action mode (mean, or sampled at a std capped at
network.max_noise_std). Anything else (another checkpoint, seed, episode count or config value)
runs the cell again and replaces the file.
"""

from __future__ import annotations

import glob
import json
import os

import numpy as np

from foottof.eval.results import EPISODE_KEYS, RESULT_KEYS
from foottof.files import write_atomic

CELLS_SUBDIR = "cells"
CELL_SCHEMA_VERSION = 1


def cell_identity(
    policy: str, draws: dict, deterministic: bool, max_noise_std: float | None = None
) -> dict:
    """What must be equal for a stored cell to stand for a new run of it.

    Args:
      policy: integrity.policy_digest of the evaluated checkpoint, or "untrained".
      draws: results.episode_draws of the config.
      deterministic: eval.deterministic (mean actions).
      max_noise_std: with sampled actions, network.max_noise_std (the cap on the std they are
        sampled at; evaluate.py may set it apart from the run's); ignored for mean actions.
    """
    identity = {"policy": str(policy), "draws": dict(draws), "deterministic": bool(deterministic)}
    if not deterministic:
        identity["max_noise_std"] = None if max_noise_std is None else float(max_noise_std)
    return identity


def cell_path(out_dir: str, source: str, perturbation: str, level: float) -> str:
    name = f"cell_{source}_{perturbation}_{float(level)!r}.json"
    return os.path.join(out_dir, CELLS_SUBDIR, name)


class CellStore:
    """Reads and writes the finished cells of one evaluation under ``<out_dir>/cells``."""

    def __init__(self, out_dir: str, identity: dict):
        self.out_dir, self.identity = out_dir, identity
        self.loaded, self.written = [], []  # paths, for the run's report and cleanup

    def load(self, source: str, perturbation: str, level: float) -> tuple[dict, dict] | None:
        """(result row, per-episode outcomes as (n,) arrays) of a stored cell with this store's
        identity; None when there is none, it was run with something else, or it is damaged."""
        path = cell_path(self.out_dir, source, perturbation, level)
        try:
            with open(path) as f:
                doc = json.load(f)
            if doc.get("schema_version") != CELL_SCHEMA_VERSION:
                return None
            if doc.get("identity") != json.loads(json.dumps(self.identity)):
                return None
            row, outcomes = doc["row"], doc["outcomes"]
            if tuple(row) != RESULT_KEYS or set(outcomes) != set(EPISODE_KEYS):
                return None
            if (row["source"], row["perturbation"]) != (source, perturbation):
                return None
            if float(row["level"]) != float(level):
                return None
            arrays = {k: np.asarray(v) for k, v in outcomes.items()}
            if any(a.shape != (row["episodes"],) for a in arrays.values()):
                return None
            if int(arrays["success"].sum()) != row["successes"]:
                return None  # the row and its episodes disagree: damaged
            if int(arrays["failed"].sum()) != row["falls"]:
                return None
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return None
        self.loaded.append(path)
        return row, arrays

    def save(self, row: dict, outcomes: dict) -> str:
        """Writes one finished cell (atomically); returns its path."""
        path = cell_path(self.out_dir, row["source"], row["perturbation"], row["level"])
        doc = {
            "schema_version": CELL_SCHEMA_VERSION,
            "identity": self.identity,
            "row": row,
            "outcomes": {k: np.asarray(outcomes[k]).tolist() for k in EPISODE_KEYS},
        }
        write_atomic({path: json.dumps(doc).encode()})
        self.written.append(path)
        return path

    def clear(self) -> None:
        """Removes this run's cell files (after its results files are written) and the folder
        when nothing else is left in it."""
        for path in dict.fromkeys(self.loaded + self.written):
            if os.path.exists(path):
                os.remove(path)
        folder = os.path.join(self.out_dir, CELLS_SUBDIR)
        if os.path.isdir(folder) and not glob.glob(os.path.join(folder, "*")):
            os.rmdir(folder)
