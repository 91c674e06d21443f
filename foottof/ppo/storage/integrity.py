"""SHA-256 integrity records of checkpoint folders, and the digest that names a policy's files.

Orbax reads only the byte ranges a restore needs and checks nothing else, so a truncated or
missing file can go unnoticed or surface as a TensorStore error deep in a traceback. Each
checkpoint therefore also holds INTEGRITY_FILE: the size and SHA-256 of every file in it, written
(atomically, by process 0 of a multi-process run) after orbax finished; checkpoints written
before the record existed have none (``integrity_problem`` is then None).
"""

import hashlib
import json
import os

from foottof.files import write_atomic
from foottof.ppo.storage.run_dir import CHECKPOINT_SUBDIR

INTEGRITY_FILE = "foottof_files.json"  # in each checkpoint's step folder: sizes and SHA-256


def _sha256(path: str) -> str:
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def _file_digests(step_dir: str) -> dict[str, list]:
    out = {}
    for root, _, files in os.walk(step_dir):
        for f in sorted(files):
            path = os.path.join(root, f)
            rel = os.path.relpath(path, step_dir)
            if rel.startswith(INTEGRITY_FILE):  # the record, or its temporary while written
                continue
            out[rel] = [os.path.getsize(path), _sha256(path)]
    return out


def write_integrity(step_dir: str) -> None:
    """Records the size and SHA-256 of every file of a finished checkpoint (atomic write)."""
    files = _file_digests(step_dir)
    record = json.dumps({"version": 1, "files": files}, indent=0)
    write_atomic({os.path.join(step_dir, INTEGRITY_FILE): record.encode()})


def policy_digest(path: str) -> str:
    """SHA-256 (16 hex digits) of the policy files (params and normalizer) of the checkpoint an
    evaluation loads from ``path`` (a run directory, its checkpoints/ folder or one step folder;
    the latest finished step, as load_params_and_normalizer): equal digests, equal policies.

    Raises:
      FileNotFoundError if there is no finished checkpoint there."""
    path = os.path.abspath(path)
    if os.path.isdir(os.path.join(path, CHECKPOINT_SUBDIR)):
        path = os.path.join(path, CHECKPOINT_SUBDIR)
    if not (os.path.basename(path).isdigit() and os.path.isdir(path)):
        steps = [int(d) for d in os.listdir(path) if d.isdigit()] if os.path.isdir(path) else []
        if not steps:
            raise FileNotFoundError(f"no checkpoint found in {path}")
        path = os.path.join(path, str(max(steps)))
    files = _file_digests(path)
    kept = {k: v for k, v in files.items() if k.split(os.sep)[0] in ("params", "normalizer")}
    if not kept:
        raise FileNotFoundError(f"{path}: no params/normalizer files")
    return hashlib.sha256(json.dumps(kept, sort_keys=True).encode()).hexdigest()[:16]


def integrity_problem(step_dir: str) -> str | None:
    """Why the files of checkpoint folder ``step_dir`` do not match its integrity record (None:
    they match, or the checkpoint predates the record)."""
    record = os.path.join(step_dir, INTEGRITY_FILE)
    if not os.path.isdir(step_dir):
        return "the checkpoint folder is missing"
    if not os.path.exists(record):
        return None
    try:
        with open(record) as f:
            expected = json.load(f)["files"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        return f"its file list {INTEGRITY_FILE} is garbled ({type(e).__name__})"
    for rel, (size, digest) in sorted(expected.items()):
        path = os.path.join(step_dir, rel)
        if not os.path.isfile(path):
            return f"file {rel} is missing"
        actual = os.path.getsize(path)
        if actual != size:
            return f"file {rel} has {actual} bytes, {size} were written (truncated or partial copy)"
        if _sha256(path) != digest:
            return f"file {rel} differs from what was written (corrupted)"
    return None
