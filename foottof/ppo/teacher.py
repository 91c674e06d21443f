"""The teacher of a distillation run: loaded from its run or policy folder, checked against the
env's observation, and the ToF env built for it (``make_distill_env``, what ``train.py`` calls
when ``train.teacher`` is set). The algorithm itself (TeacherEnv, the loss) is foottof.ppo.distill.
"""

from __future__ import annotations

import hashlib
import json
import os

import jax
import jax.numpy as jp
import numpy as np

from foottof.ppo import checkpoint as ckpt
from foottof.ppo import networks as net
from foottof.ppo.distill import TeacherEnv, student_from_teacher
from foottof.renames import read_saved_config


def load_teacher(path: str, env, network_cfg):
    """(Networks, params, normalizer) of the teacher at ``path`` (a run or policy folder, or one
    checkpoint) for the batched ``env`` whose actor observation it must read.

    Raises:
      ValueError: one line naming the teacher and both input sizes when its actor was trained on
        another observation layout (e.g. without env.actor_terrain).
    """
    shape = jax.eval_shape(env.reset, jax.ShapeDtypeStruct((1, 2), jp.uint32))
    obs = jax.tree.map(lambda s: jp.zeros((1,) + s.shape[1:], s.dtype), shape.obs)
    networks = net.make_networks(env.action_size, network_cfg)
    # as the trainer builds them (jitted: every leaf an array, the normalizer's std_eps too)
    params = jax.jit(networks.init_params)(jax.random.PRNGKey(0), obs)
    normalizer = jax.jit(networks.init_normalizer)(obs)
    try:
        params, normalizer = ckpt.load_params_and_normalizer(path, params, normalizer, grow=False)
    except ckpt.CheckpointMismatch as e:
        want = obs[net.ACTOR_KEY].shape[-1] if isinstance(obs, dict) else obs.shape[-1]
        raise ValueError(
            f"train.teacher={path!r} does not fit this env's teacher observation ({want} actor "
            f"inputs; a teacher is trained with env.actor_terrain=True and the same sensor and "
            f"critic layout as the student's config): {e}"
        ) from None
    return networks, params, normalizer


def teacher_network_cfg(path: str, default):
    """The teacher's c.network from its run config (config.json beside or above ``path``, read
    migrated); the student's ``default`` where it has none, without the student's belief
    decoder."""
    import ml_collections

    out = ml_collections.ConfigDict(dict(default))
    if "reconstruct" in out:
        out.reconstruct = (
            0  # the student's belief decoder (network.reconstruct) is not the teacher's
        )
    for k, v in (_saved_run_config(path).get("network") or {}).items():
        if k in out:
            out[k] = tuple(v) if isinstance(v, list) else v
    return out


def teacher_sees_only_seen(path: str) -> bool:
    """The teacher's env.actor_terrain_seen, from its run config (False where it has none)."""
    return _run_env_flag(path, "actor_terrain_seen")


def teacher_reads_fine(path: str) -> bool:
    """The teacher's env.actor_terrain_fine, from its run config (False where it has none)."""
    return _run_env_flag(path, "actor_terrain_fine")


def _run_env_flag(path: str, key: str) -> bool:
    """env.<key> of the run config beside or above ``path`` (False where it has no env section)."""
    env = _saved_run_config(path).get("env")
    return bool(env is not None and env[key])


def _saved_run_config(path: str) -> dict:
    """The run config (config.json beside or above ``path``) as a dict, migrated
    (renames.read_saved_config: a field added since it was saved at its old-behaviour default);
    {} where it has none."""
    from foottof.ppo import run_dir as run_dirs

    config = run_dirs.run_config_path(path)
    return {} if config is None else read_saved_config(config)


TEACHER_RECORD = "teacher.json"  # in a distillation run folder: which teacher it learns from


def teacher_fingerprint(params, normalizer) -> str:
    """A short hash of the teacher's params and normalizer (every leaf's dtype, shape, bytes):
    equal for the same checkpoint wherever it is copied, different once the teacher trained on."""
    h = hashlib.sha256()
    for leaf in jax.tree.leaves((params, normalizer)):
        a = np.asarray(leaf)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def check_teacher_record(
    run_dir: str, path: str, fingerprint: str, resume: bool, change_ok: bool = False
) -> dict:
    """Records in ``run_dir``/teacher.json the teacher a distillation run learns from (a new run),
    or checks that a resumed run still reads the same one: ``train.teacher`` names a folder, and
    a shipped teacher folder may since hold a later checkpoint. Returns the record written or
    found. A run saved before the record existed gets one (one line says so). A ``path`` that is
    no checkpoint folder (a teacher built in memory, e.g. a notebook's) is recorded with step None.

    Raises:
      ValueError: one message naming both teachers (path, step, fingerprint) and the two ways on,
        when a resumed run's teacher differs from its record and ``change_ok`` is False.
    """
    from foottof.files import write_atomic
    from foottof.ppo import run_dir as run_dirs

    step = ckpt.checkpoint_location(path)[1] if os.path.isdir(path) else None
    now = {"teacher": path, "step": step, "fingerprint": fingerprint}
    file = os.path.join(run_dir, TEACHER_RECORD)
    if resume and os.path.exists(file):
        with open(file) as f:
            old = json.load(f)
        if old.get("fingerprint") == fingerprint:
            return old
        was = f"{old.get('teacher')!r} at checkpoint {old.get('step')} ({old.get('fingerprint')})"
        if not change_ok:
            raise ValueError(
                f"train.teacher={path!r} is now checkpoint {step} ({fingerprint}), but this run "
                f"was distilled from {was} ({file}). Point train.teacher at that checkpoint "
                f"(e.g. --config.train.teacher=PATH/checkpoints/{old.get('step')}), or pass "
                f"--config.train.teacher_change_ok=True to go on with the new teacher"
            )
        print(f"[teacher] the teacher changes: {was} -> {path!r} at checkpoint {step}")
        now["previous"] = list(old.get("previous", [])) + [
            {k: old.get(k) for k in ("teacher", "step", "fingerprint", "from_iteration")}
        ]
    elif resume:
        print(f"[teacher] {file} is missing (a run from before it existed): recording {path!r}")
    latest = run_dirs.latest_checkpoint(run_dir)
    if not resume and latest is not None:
        return now  # the runner refuses a new run in a folder with checkpoints: keep its record
    now["from_iteration"] = latest if resume else 0
    if jax.process_index() == 0:
        write_atomic({file: json.dumps(now, indent=1).encode()})
    return now


def record_teacher(run_dir: str, cfg, env: TeacherEnv, resume: bool) -> dict:
    """:func:`check_teacher_record` for a distillation run of ``cfg`` (train.teacher,
    train.teacher_change_ok) on ``env``: the fingerprint of the teacher ``env`` steps with."""
    return check_teacher_record(
        run_dir,
        str(cfg.train.teacher),
        teacher_fingerprint(env.teacher_params, env.teacher_normalizer),
        resume,
        bool(cfg.train.teacher_change_ok),
    )


def check_teacher_path(path: str) -> None:
    if not os.path.exists(path):
        raise FileNotFoundError(
            f"train.teacher={path!r} does not exist; train a teacher first "
            f"(python train.py --config configs/teacher_cpu.py) or pass --config.train.teacher=PATH"
        )


def student_view_size(
    teacher_obs_size: int, privileged_inputs: int = 0, seen: bool = False, fine: bool = False
) -> int:
    """How many of the teacher's actor inputs a ToF student reads: its own (the teacher's minus
    the terrain inputs env.actor_terrain appends: 153, or 306 with env.actor_terrain_seen =
    ``seen``, and 372 more with env.actor_terrain_fine = ``fine``) and the first
    ``privileged_inputs`` of those (train.student_privileged_inputs, a diagnostic: 36 = the foot
    patches).

    Raises:
      ValueError: naming the value and its range, when ``privileged_inputs`` is outside
        [0, ACTOR_TERRAIN_INPUTS].
    """
    from foottof.envs.observations import ACTOR_TERRAIN_INPUTS, actor_terrain_size

    if not 0 <= int(privileged_inputs) <= ACTOR_TERRAIN_INPUTS:
        raise ValueError(
            f"train.student_privileged_inputs={privileged_inputs} must be in "
            f"[0, {ACTOR_TERRAIN_INPUTS}] (the teacher's terrain inputs: 36 foot patches, then "
            f"the base scan)"
        )
    from foottof.envs.fine_terrain import NUM_INPUTS as fine_inputs

    terrain = actor_terrain_size(seen) + (fine_inputs if fine else 0)
    return int(teacher_obs_size) - terrain + int(privileged_inputs)


def make_distill_env(cfg):
    """(batched TeacherEnv, init function) for a distillation run of the ToF env: the env is
    built with env.actor_terrain on (the teacher's observation; ``cfg`` itself keeps the
    student's layout, so its saved run config evaluates the student), the teacher loaded from
    ``cfg.train.teacher``, and the init function cuts the student from the teacher
    (:func:`student_from_teacher`; used where the run has no train.init_from). With
    ``train.student_privileged_inputs`` = N > 0 (a diagnostic) the student also reads the first N
    terrain inputs (36: the foot patches); such a student evaluates only in this env."""
    from foottof.envs import make_training_env

    path = str(cfg.train.teacher)
    check_teacher_path(path)
    if cfg.env.actor_terrain:
        raise ValueError(
            "env.actor_terrain=True in a distillation config: the config is the student's "
            "(sensors only); the teacher's terrain inputs are added for it"
        )
    seen, fine = teacher_sees_only_seen(path), teacher_reads_fine(path)
    full = cfg.copy_and_resolve_references()
    with full.unlocked():
        full.env.actor_terrain = True
        full.env.actor_terrain_seen = seen  # as the teacher was trained
        full.env.actor_terrain_fine = fine
    env = make_training_env(full)
    teacher = load_teacher(path, env, teacher_network_cfg(path, cfg.network))
    shape = jax.eval_shape(env.reset, jax.ShapeDtypeStruct((1, 2), jp.uint32))
    student_obs_size = student_view_size(
        shape.obs[net.ACTOR_KEY].shape[-1],
        cfg.train.student_privileged_inputs,
        seen,
        fine,
    )
    _, t_params, t_norm = teacher

    def init(params, normalizer):
        return student_from_teacher(params, normalizer, t_params, t_norm)

    return TeacherEnv(env, teacher, student_obs_size), init
