"""Orbax checkpoints of the whole TrainState (atomic, keep-last-N) and init_from loading.

Layout: <run_dir>/checkpoints/<iteration>/ with orbax items 'params', 'opt_state', 'normalizer',
'progress' (PRNG key, iteration), optionally 'rollout' (env state, LSTM carries, episode
accumulators) and 'manifest' (JSON: leaf names, shapes, dtypes of every item). Each item is saved
as a flat dict of leaves named in the manifest (foottof.ppo.storage.leaves), so any pytree
round-trips and a mismatch error names the leaf. Orbax writes into a temporary folder and renames
it when done.

Damage. Each checkpoint also holds the size and SHA-256 of every file in it
(foottof.ppo.storage.integrity, written after orbax finished). A checkpoint whose files do not
match that record, or that orbax cannot read, is *unreadable* (:class:`CheckpointUnreadable`, one
line naming the path and the cause); one whose leaves differ from the model *does not fit*
(:class:`CheckpointMismatch`, a ValueError). ``Checkpointer.restore`` falls back to the newest
checkpoint that reads; checkpoints written before the record existed are checked by reading them
only. A network with more inputs than the saved one restores it grown
(foottof.ppo.storage.input_growth).

A full disk. A save that fails for want of space raises :class:`foottof.files.DiskFull` (one
line: the run folder, the space a checkpoint needs and the last complete checkpoint) after
removing, in a run of one process, what it wrote of the failed one (orbax's
``<step>.orbax-checkpoint-tmp*`` folder; with several processes it stays, as the others may still
write into it); no restore reads such a folder, and the checkpoints before it are untouched (orbax
deletes old ones only after a save completes).
"""

import contextlib
import gc
import os
import shutil
import sys
from typing import Any

import jax
import numpy as np
import orbax.checkpoint as ocp

from foottof import files
from foottof.ppo.storage import input_growth as growth
from foottof.ppo.storage.integrity import integrity_problem, write_integrity
from foottof.ppo.storage.leaves import (  # noqa: F401 (RECOMPUTED_LEAF_PREFIX re-exported)
    RECOMPUTED_LEAF_PREFIX,
    CheckpointMismatch,
    abstract_leaves,
    check_compatible,
    flatten,
    unflatten,
)
from foottof.ppo.storage.run_dir import CHECKPOINT_SUBDIR
from foottof.ppo.train import TrainState

ITEMS = {
    "params": ("params",),
    "opt_state": ("opt_state",),
    "normalizer": ("normalizer",),
    "progress": ("key", "iteration"),
    # mirror_carry: None (no leaves) unless ppo.symmetry, so other runs save what they did before
    "rollout": ("env_state", "carry", "prev_done", "ep_return", "ep_length", "mirror_carry"),
}


def _sub(state: TrainState, item: str) -> dict:
    return {f: getattr(state, f) for f in ITEMS[item]}


class CheckpointUnreadable(RuntimeError):
    """A checkpoint that cannot be read completely (damaged, partial copy, missing files); the
    message is one line naming the path and the cause."""


@contextlib.contextmanager
def _quiet_failed_reads():
    """Orbax reads array chunks concurrently: when one read fails, the others' failures end up
    as 'Exception ignored in <coroutine ...>' tracebacks on stderr when collected. The first
    failure is reported (as one line) by the caller; these are dropped."""
    previous = sys.unraisablehook

    def hook(unraisable):
        code = getattr(unraisable.object, "cr_code", None)  # a coroutine's code object
        if "orbax" not in getattr(code, "co_filename", ""):
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        gc.collect()
        sys.unraisablehook = previous


DAMAGED_SUBDIR = "checkpoints_damaged"  # unreadable checkpoints a resume skipped go here


def _one_line(e: BaseException) -> str:
    """The root cause's first line (orbax wraps TensorStore's error, e.g. 'OUT_OF_RANGE: Error
    reading ... Requested byte range [..) is not valid for value of size 10', in dozens)."""
    while e.__cause__ is not None or (e.__context__ is not None and not e.__suppress_context__):
        e = e.__cause__ or e.__context__
    text = str(e).strip().splitlines()
    line = text[0].split(" See full TensorStore details")[0] if text else ""
    return f"{type(e).__name__}: {line[:240]}" if line else type(e).__name__


class Checkpointer:
    """Saves/restores TrainStates under <run_dir>/checkpoints (synchronous, atomic)."""

    def __init__(self, run_dir: str, max_to_keep: int = 5, save_env_state: bool = True):
        if max_to_keep < 1:
            raise ValueError(f"max_to_keep={max_to_keep}; must be >= 1")
        self.directory = os.path.abspath(os.path.join(run_dir, CHECKPOINT_SUBDIR))
        self.save_env_state = save_env_state
        self._manager = ocp.CheckpointManager(
            self.directory,
            options=ocp.CheckpointManagerOptions(
                max_to_keep=max_to_keep, create=True, enable_async_checkpointing=False
            ),
        )

    def save(self, state: TrainState) -> int:
        """Writes `state` as checkpoint number state.iteration; returns that number."""
        step = int(state.iteration)
        items = [i for i in ITEMS if i != "rollout" or self.save_env_state]
        args, manifest = {}, {}
        for item in items:
            flat, manifest[item] = flatten(_sub(state, item))
            args[item] = ocp.args.StandardSave(flat)
        args["manifest"] = ocp.args.JsonSave(manifest)
        try:
            self._manager.save(step, args=ocp.args.Composite(**args), force=True)
            self._manager.wait_until_finished()
            if jax.process_index() == 0:  # one writer: orbax has gathered every process's files
                write_integrity(os.path.join(self.directory, str(step)))
        except Exception as e:
            if not files.is_disk_full(e):
                raise
            raise files.DiskFull(self._disk_full(step, state)) from None
        return step

    def checkpoint_bytes(self, state: TrainState) -> int:
        """Bytes of the arrays a checkpoint of `state` holds (what a save needs, about)."""
        items = [i for i in ITEMS if i != "rollout" or self.save_env_state]
        leaves = [x for item in items for x in jax.tree.leaves(_sub(state, item))]
        return sum(int(np.size(x)) * np.dtype(x.dtype).itemsize for x in leaves)

    def _disk_full(self, step: int, state: TrainState) -> str:
        """Removes what a failed save of `step` wrote (its orbax temporary folders; a folder
        orbax already renamed to `step` is complete and stays) and says so in one line. With
        several processes the others may still write into it: it stays (no restore reads it,
        orbax replaces it at the next save of `step`)."""
        if jax.process_count() == 1:
            for name in os.listdir(self.directory):
                if name.startswith(f"{step}.orbax-checkpoint-tmp"):
                    shutil.rmtree(os.path.join(self.directory, name), ignore_errors=True)
        self._manager.reload()
        needed = self.checkpoint_bytes(state)
        last = self._manager.latest_step()
        run_dir = os.path.dirname(self.directory)
        then = (
            f"checkpoint {last} is the last complete one. Free space there, then continue "
            f"from it (train.py --resume --run_dir {run_dir})"
            if last is not None
            else "no checkpoint is complete: free space there and start the run again"
        )
        return files.disk_full_message(run_dir, f"saving checkpoint {step}", needed, then)

    def latest_step(self) -> int | None:
        return self._manager.latest_step()

    def all_steps(self) -> list[int]:
        return list(self._manager.all_steps())

    def manifest(self, step: int) -> dict:
        return self._manager.restore(
            step, args=ocp.args.Composite(manifest=ocp.args.JsonRestore())
        ).manifest

    def restore(self, target: TrainState, step: int | None = None) -> tuple[TrainState, bool]:
        """Restores checkpoint `step` (default: the newest that reads completely) into the
        structure/shardings of `target`.

        Without `step`, each newer checkpoint that is unreadable is skipped with a one-line
        warning naming it and the cause.

        A model whose network reads more inputs than the saved one (input_growth.INPUT_LEAVES,
        e.g. network.obs_skip heads) gets the saved kernels with zero rows for the new inputs, and
        for them zero first Adam moments and second ones at the saved leaf's mean
        (input_growth.seed_second_moment); a wider actor head (network.actor_hidden) gets the saved
        layers with its new units cut off from the saved ones (input_growth.grow_width): it
        acts as the saved one did.

        Returns:
          (state, restored_rollout): fields of items missing in the checkpoint ('rollout' when
          saved with save_env_state=False) keep `target`'s values.

        Raises:
          FileNotFoundError: no checkpoint at all.
          CheckpointUnreadable: `step` (or, without it, every checkpoint) cannot be read.
          CheckpointMismatch: a readable checkpoint does not fit `target`.
        """
        steps = sorted(self.all_steps(), reverse=True) if step is None else [step]
        if not steps:
            raise FileNotFoundError(f"no checkpoint in {self.directory}")
        problems = []
        for s in steps:
            try:
                restored = self._restore_step(target, s)
            except CheckpointUnreadable as e:
                problems.append((s, str(e)))
                if step is None:
                    print(f"[checkpoint] WARNING: skipping checkpoint {e}")
                continue
            if problems and step is None:
                self._move_aside([step_ for step_, _ in problems])
            return restored
        if step is not None:
            raise CheckpointUnreadable(problems[0][1])
        raise CheckpointUnreadable(
            f"no readable checkpoint in {os.path.dirname(self.directory)} (tried "
            f"{', '.join(str(s) for s in steps)}; newest: {problems[0][1]})"
        )

    def _move_aside(self, steps: list[int]) -> None:
        """Moves skipped (unreadable) checkpoints out of the way of the run's next saves, into
        <run_dir>/checkpoints_damaged/<step> (kept, not deleted), one line each."""
        dest_root = os.path.join(os.path.dirname(self.directory), DAMAGED_SUBDIR)
        os.makedirs(dest_root, exist_ok=True)
        for s in steps:
            dest = os.path.join(dest_root, str(s))
            n = 1
            while os.path.exists(dest):
                dest, n = os.path.join(dest_root, f"{s}.{n}"), n + 1
            shutil.move(os.path.join(self.directory, str(s)), dest)
            print(f"[checkpoint] moved unreadable checkpoint {s} to {dest}")
        self._manager.reload()

    def _restore_step(self, target: TrainState, step: int) -> tuple[TrainState, bool]:
        path = os.path.join(self.directory, str(step))
        problem = integrity_problem(path)
        if problem:
            raise CheckpointUnreadable(f"{path}: {problem}")
        try:
            manifest = self.manifest(step)
        except Exception as e:  # orbax/JSON errors of a damaged manifest
            raise CheckpointUnreadable(f"{path}: manifest unreadable ({_one_line(e)})") from None
        items = [i for i in ITEMS if i in manifest]
        grown, saved_like = {}, {}
        for item in items:
            sub = _sub(target, item)
            grown[item] = (
                growth.grown_leaves(manifest[item], sub) if item in growth.GROWABLE_ITEMS else {}
            )
            saved_like[item] = growth.shaped_as_saved(sub, grown[item])
            check_compatible(item, manifest[item], saved_like[item], f"checkpoint {step}")
        args = {
            i: ocp.args.StandardRestore(
                abstract_leaves(saved_like[i], manifest[i], with_extra=True)
            )
            for i in items
        }
        try:
            with _quiet_failed_reads():
                restored = self._manager.restore(step, args=ocp.args.Composite(**args))
        except Exception as e:  # TensorStore/orbax errors of damaged data
            raise CheckpointUnreadable(f"{path}: data unreadable ({_one_line(e)})") from None
        fields = {}
        for item in items:
            tree = unflatten(saved_like[item], restored[item], manifest[item])
            if grown[item]:
                tree = growth.grow_tree(tree, _sub(target, item), grown[item])
                print(
                    f"[checkpoint] {item}: inputs grown on {len(grown[item])} leaves "
                    f"(new inputs and units start with zero weight on the saved ones)"
                )
            fields.update(tree)
        return target.replace(**fields), "rollout" in items

    def close(self) -> None:
        self._manager.close()


def checkpoint_location(path: str) -> tuple[str, int]:
    """(checkpoints directory, step) that :func:`load_params_and_normalizer` reads for ``path``:
    a run or policy folder (its newest step), its checkpoints/ folder, or one step's folder.

    Raises:
      FileNotFoundError: no checkpoint directory at ``path``, or no checkpoint in it.
    """
    path = os.path.abspath(path)
    step = None
    if os.path.isdir(os.path.join(path, CHECKPOINT_SUBDIR)):
        directory = os.path.join(path, CHECKPOINT_SUBDIR)
    elif os.path.basename(path).isdigit() and os.path.isdir(path):
        directory, step = os.path.dirname(path), int(os.path.basename(path))
    else:
        directory = path
    if not os.path.isdir(directory):
        raise FileNotFoundError(f"init_from: no checkpoint directory at {path}")
    manager = ocp.CheckpointManager(directory, options=ocp.CheckpointManagerOptions(create=False))
    try:
        step = manager.latest_step() if step is None else step
        if step is None or step not in manager.all_steps():
            raise FileNotFoundError(f"init_from: no checkpoint found in {directory}")
    finally:
        manager.close()
    return directory, int(step)


def load_params_and_normalizer(
    path: str, params: Any, normalizer: Any, grow: bool = True, grow_actor: bool = False
) -> tuple[Any, Any]:
    """Params + normalizer of another run (init_from), shaped like `params`/`normalizer`.

    A run whose critic reads more inputs than the saved one's (inputs appended at the end, e.g.
    env.critic_height_scan) starts from it too: the critic's input weights for the new inputs
    are zero and their normalizer entries mean 0 / variance 1, so its value function starts as
    the saved one's (one line says so).

    Args:
      path: a run directory, its checkpoints/ folder, or one checkpoint's step folder.
      params, normalizer: the current model's (initialized) values; give structure and sharding.
      grow: grow input leaves the saved network has fewer of (init_from); False: every leaf must
        match (a teacher, whose inputs must be the env's).
      grow_actor: also grow the actor's inputs (init_from into env.actor_terrain).

    Raises:
      FileNotFoundError if there is no checkpoint there; CheckpointUnreadable (one line: path
      and cause) if it cannot be read completely; CheckpointMismatch (a ValueError naming the
      leaf and both shapes) if the saved network does not fit this model.
    """
    directory, step = checkpoint_location(path)
    manager = ocp.CheckpointManager(directory, options=ocp.CheckpointManagerOptions(create=False))
    try:
        step_dir = os.path.join(directory, str(step))
        problem = integrity_problem(step_dir)
        if problem:
            raise CheckpointUnreadable(f"{step_dir}: {problem}")
        try:
            manifest = manager.restore(
                step, args=ocp.args.Composite(manifest=ocp.args.JsonRestore())
            ).manifest
        except Exception as e:
            raise CheckpointUnreadable(
                f"{step_dir}: manifest unreadable ({_one_line(e)})"
            ) from None
        target = {"params": {"params": params}, "normalizer": {"normalizer": normalizer}}
        grown, saved_like = {}, {}
        for item, sub in target.items():
            if item not in manifest:
                raise CheckpointUnreadable(f"{step_dir}: the checkpoint has no {item!r} item")
            grown[item] = growth.grown_leaves(manifest[item], sub, grow_actor) if grow else {}
            saved_like[item] = growth.shaped_as_saved(sub, grown[item])
            check_compatible(
                item, manifest[item], saved_like[item], f"init_from {directory}/{step}"
            )
        args = {
            item: ocp.args.StandardRestore(abstract_leaves(sub)) for item, sub in saved_like.items()
        }
        try:
            with _quiet_failed_reads():
                restored = manager.restore(step, args=ocp.args.Composite(**args))
        except Exception as e:
            raise CheckpointUnreadable(f"{step_dir}: data unreadable ({_one_line(e)})") from None
    finally:
        manager.close()
    out = []
    for item, sub in target.items():
        tree = unflatten(saved_like[item], restored[item])
        if grown[item]:
            tree = growth.grow_tree(tree, sub, grown[item])
            print(
                f"[init_from] {item}: inputs grown on {len(grown[item])} leaves "
                f"(new inputs and units start with zero weight on the saved ones)"
            )
        out.append(tree[item])
    return out[0], out[1]
