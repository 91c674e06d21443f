"""Robustness evaluation (paper, robustness figure): success rate per source x perturbation x level.

Protocol: every env runs exactly one episode on the evaluation ensemble (80 % stepping-stone
tiles + 20 % gap tiles at 90 % of the stage-1 difficulty); its first ``done`` step gives the
outcome, auto-reset episodes after it are ignored. Success = the episode ran to its time limit
and ended within ``reward.success_radius_m`` (0.5 m) of the goal (``episode/success`` of the env).
Episodes are run in batches of ``eval.num_envs`` until ``eval.episodes`` are collected.

Perturbations (joint_offset and odometry levels are arguments of one compiled rollout; each
shank_length level needs its own physics model, hence its own compile):
  none          single level 0.
  joint_offset  static offset on all joint readings [rad], valid [0, 0.3].
  shank_length  shank length scale of the physics model [-], valid [0.8, 1.2].
  odometry      odometry noise, multiples of the paper's 100 % level [-], valid [0, 10].
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jp
import ml_collections
import numpy as np

from foottof.eval.harness import make_eval_env_and_policy, perturbed_reset
from foottof.eval.results import summarize
from foottof.limits import LEVEL_RANGES  # valid closed range of each perturbation's levels
from foottof.perception import check_source
from foottof.terrain import TERRAIN_TYPES

PERTURBATIONS = ("none", "joint_offset", "shank_length", "odometry")

# Each source's sweep when no perturbation is asked for: the one it is compared on in the paper's
# robustness figure (A: joint offset, tof vs mock_ideal; C: odometry, tof vs mock_aggre).
HEADLINE_SWEEPS = {"tof": "joint_offset", "mock_ideal": "joint_offset", "mock_aggre": "odometry"}
TRACED_PERTURBATIONS = ("joint_offset", "odometry")  # levels are rollout arguments (one compile)
LEVEL_UNITS = {"none": "-", "joint_offset": "rad", "shank_length": "scale", "odometry": "x100%"}
# Minutes per 1000 episodes on 2 CPU cores, compile aside: bench/NOTES.md ("Foot-reading sources",
# item 10: tof 2.0, mock_ideal 3.8) and issue 70 (mock_aggre: 5 x 1000 episodes in ~42 min).
CPU_MIN_PER_1000 = {"tof": 2.0, "mock_ideal": 3.8, "mock_aggre": 8.5}
COMPILE_MIN = 1.0  # about one minute per compiled rollout (bench: tof 47 s) on 2 CPU cores


# ---------------------------------------------------------------------------------------------
# Pure helpers (NumPy, no env)
def first_episode_outcomes(
    done: np.ndarray, success: np.ndarray, failed: np.ndarray, speed: np.ndarray
) -> dict:
    """Outcome of each env's *first* episode from per-step rollout arrays.

    Args:
      done, success, failed: (T, B) per-step flags of the env (``state.done``,
        ``episode/success``, ``episode/failed``); values > 0.5 count as set.
      speed: (T, B) horizontal base speed at each step [m/s].

    Returns:
      dict of (B,) arrays: ``finished`` (bool, a done occurred), ``success`` (bool, at the first
      done), ``failed`` (bool, at the first done), ``mean_speed_mps`` (mean speed over the steps up
      to and including the first done; over all T steps if none), ``length`` (steps of the first
      episode).
    """
    done = np.asarray(done) > 0.5
    if done.ndim != 2:
        raise ValueError(f"done has shape {done.shape}; expected (T, B)")
    t_steps, _ = done.shape
    finished = done.any(axis=0)
    first = np.where(finished, done.argmax(axis=0), t_steps - 1)  # (B,)
    cols = np.arange(done.shape[1])
    succ = (np.asarray(success)[first, cols] > 0.5) & finished
    fail = (np.asarray(failed)[first, cols] > 0.5) & finished
    mask = np.arange(t_steps)[:, None] <= first[None, :]  # steps of the first episode
    length = mask.sum(axis=0)
    mean_speed = (np.asarray(speed) * mask).sum(axis=0) / np.maximum(length, 1)
    return {
        "finished": finished,
        "success": succ,
        "failed": fail,
        "mean_speed_mps": mean_speed,
        "length": length,
    }


def check_levels(perturbation: str, levels) -> tuple[float, ...]:
    """Validates the perturbation name and its levels; 'none' has the single level 0."""
    if perturbation not in PERTURBATIONS:
        raise ValueError(
            f"unknown perturbation {perturbation!r}; valid choices: {list(PERTURBATIONS)}"
        )
    if perturbation == "none":
        return (0.0,)
    parsed = []
    for v in levels:
        try:
            parsed.append(float(v))
        except (TypeError, ValueError):
            raise ValueError(
                f"{perturbation} level {v!r} is not a number; valid range "
                f"{list(LEVEL_RANGES[perturbation])}"
            ) from None
    levels = tuple(parsed)
    if not levels:
        raise ValueError(f"no levels given for perturbation {perturbation!r}")
    lo, hi = LEVEL_RANGES[perturbation]
    for v in levels:
        if not (lo <= v <= hi) or not math.isfinite(v):
            raise ValueError(
                f"{perturbation} level {v} outside the valid range [{lo}, {hi}] "
                f"({LEVEL_UNITS[perturbation]})"
            )
    return levels


def default_levels(eval_cfg: ml_collections.ConfigDict, perturbation: str) -> tuple[float, ...]:
    """The sweep levels of c.eval for `perturbation`."""
    table = {
        "none": (0.0,),
        "joint_offset": eval_cfg.joint_offset_levels,
        "shank_length": eval_cfg.shank_length_levels,
        "odometry": eval_cfg.odometry_levels,
    }
    return tuple(float(v) for v in table[perturbation])


# ---------------------------------------------------------------------------------------------
# Rollout and sweeps
def make_rollout(
    env,
    networks,
    num_envs: int,
    steps: int,
    perturbation: str = "none",
    deterministic: bool = True,
    on_step=None,
):
    """jit-ed (params, normalizer, key, level) -> (per-step (T, B) arrays done/success/failed/
    speed, (B,) terrain column of each env's first episode).

    ``on_step``: called on the host with the index t of each step done (0 .. steps - 1) while
    the rollout runs (``jax.debug.callback``; it reads nothing back), e.g. to advance a progress
    bar within a batch; the rollout's outputs are those without it.

    ``deterministic``: act with the policy mean (the default), or sample actions at the policy's
    action std as in training (``eval.deterministic=False``: what the curriculum sees).

    ``level`` is a traced argument for the ``TRACED_PERTURBATIONS`` (given at reset by
    ``harness.perturbed_reset``), so one compile serves a whole sweep; for 'none' and
    'shank_length' it is ignored (the latter lives in the env's physics model).
    """
    if perturbation not in PERTURBATIONS:
        raise ValueError(
            f"unknown perturbation {perturbation!r}; valid choices: {list(PERTURBATIONS)}"
        )
    reset = jax.vmap(perturbed_reset(env, perturbation), in_axes=(0, None))
    step = jax.vmap(env.step)

    def rollout(params, normalizer, key, level):
        key_reset, key_run = jax.random.split(key)
        state = reset(jax.random.split(key_reset, num_envs), level)
        act = networks.policy_fn(params, normalizer, deterministic=deterministic)
        carry = networks.init_carry(num_envs)
        first = jp.ones((num_envs,), bool)

        def body(c, xs):
            state, carry, reset_flags = c
            k, t = xs if on_step is not None else (xs, None)  # static
            carry, action = act(carry, state.obs, reset_flags, k)
            state = step(state, action)
            if on_step is not None:
                jax.debug.callback(on_step, t)
            out = (
                state.done,
                state.metrics["episode/success"],
                state.metrics["episode/failed"],
                state.metrics["episode/speed_mps"],
            )
            return (state, carry, state.done > 0.5), out

        col = state.info["task"].col  # the tile column of the first episode (its terrain type)
        xs = jax.random.split(key_run, steps)
        xs = xs if on_step is None else (xs, jp.arange(steps))  # without it: the old program
        _, outs = jax.lax.scan(body, (state, carry, first), xs)
        return outs, col

    return jax.jit(rollout)


def evaluate_sweep(
    cfg: ml_collections.ConfigDict,
    source: str,
    perturbation: str,
    levels,
    checkpoint: str | None,
    key: jax.Array,
    progress=None,
    return_outcomes: bool = False,
    cells=None,
):
    """Runs eval.episodes first episodes at every level of one (source, perturbation); rows.

    Every level sees the same terrain map, policy and episode draws (spawn, goal, sensor noise):
    a paired comparison, in which only the perturbation differs. Joint-offset and odometry levels
    share one compiled rollout; every shank-length level needs its own physics model (compile).

    Args:
      cfg: full config (c.eval gives episodes, num_envs and the ensemble).
      source: foot-reading source.
      perturbation, levels: validated by check_levels.
      checkpoint: checkpoint path, or None for a freshly initialized (untrained) policy.
      key: PRNG key (terrain map, policy init, episodes).
      progress: optional tqdm bar, advanced by the episodes of each batch as its steps run.
      return_outcomes: also return each level's per-episode outcomes: the (n,) arrays of
        first_episode_outcomes and ``terrain`` (the terrain type name of the episode's tile).
        Episode i is the same draw at every level, and in every evaluation with the same
        results.episode_draws (eval.seed, batch size, eval.episodes, draws_fingerprint).
      cells: optional foottof.eval.cells.CellStore: a level stored there is loaded instead of
        run, and each level run is stored as soon as it finishes (an interrupted sweep resumes).

    Returns:
      One result row (keys RESULT_KEYS) per level, in the order of ``levels``; with
      ``return_outcomes`` a pair (rows, outcomes), one outcome dict per row.
    """
    check_source(source, allow_all=False)
    levels = check_levels(perturbation, levels)
    episodes, num_envs = int(cfg.eval.episodes), int(cfg.eval.num_envs)
    if episodes < 1 or num_envs < 1:
        raise ValueError(f"eval.episodes={episodes}, eval.num_envs={num_envs}: both must be >= 1")
    num_envs = min(num_envs, episodes)
    key_map, key_init, key_run = jax.random.split(key, 3)
    traced = perturbation in TRACED_PERTURBATIONS
    groups = [levels] if traced or perturbation == "none" else [(lv,) for lv in levels]
    stored = {
        lv: (cells.load(source, perturbation, lv) if cells is not None else None) for lv in levels
    }
    done = {}  # level -> (row, outcomes)
    for group in groups:
        todo = [lv for lv in group if stored[lv] is None]
        for lv in group:
            if stored[lv] is not None:
                done[lv] = stored[lv]
                if progress is not None:
                    progress.update(episodes)
        if not todo:
            continue  # every level of the group is stored: nothing to build or compile
        env, networks, params, normalizer = make_eval_env_and_policy(
            cfg, source, checkpoint, key_map, key_init, perturbation, group[0]
        )
        col_type = np.asarray(jax.device_get(env.tmap.col_type))  # (C,) type index per column
        ticks = None if progress is None else _StepTicks(progress, env.episode_steps)
        rollout = make_rollout(
            env,
            networks,
            num_envs,
            env.episode_steps,
            perturbation,
            deterministic=bool(cfg.eval.deterministic),
            on_step=None if ticks is None else ticks.step,
        )
        terrain_of_col = np.asarray(TERRAIN_TYPES)[col_type]  # (C,) type name per column
        run = functools.partial(rollout, params, normalizer)
        for level in todo:
            merged = _run_level(run, level, key_run, episodes, num_envs, terrain_of_col, ticks)
            done[level] = (summarize(source, perturbation, level, merged), merged)
            if cells is not None:
                cells.save(*done[level])
    rows = [done[lv][0] for lv in levels]
    outcomes = [done[lv][1] for lv in levels]
    return (rows, outcomes) if return_outcomes else rows


def _run_level(run, level, key_run, episodes: int, num_envs: int, terrain_of_col, ticks) -> dict:
    """The first-episode outcomes of ``episodes`` episodes at one level, in batches of at most
    ``num_envs`` (the key split once per batch off ``key_run``: the same draws at every level).

    Args:
      run: ``run(key, level) -> (outs, col)``, the compiled rollout with its policy bound.
      terrain_of_col: (C,) the terrain type name of each map column.
      ticks: a _StepTicks advancing the progress bar during each batch, or None.

    Returns:
      {outcome: (episodes,) array}: first_episode_outcomes and ``terrain``.
    """
    parts, collected, k_run = [], 0, key_run
    while collected < episodes:
        k_run, k = jax.random.split(k_run)
        take = min(num_envs, episodes - collected)
        if ticks is not None:
            ticks.start(take)
        outs, col = jax.device_get(run(k, jp.float32(level)))
        if ticks is not None:
            jax.effects_barrier()  # every step's callback has run
            ticks.finish()
        res = first_episode_outcomes(*outs)
        res["terrain"] = terrain_of_col[col]
        parts.append({n: v[:take] for n, v in res.items()})
        collected += take
    return {n: np.concatenate([p[n] for p in parts]) for n in parts[0]}


class _StepTicks:
    """Advances a progress bar in episodes while a batch's steps run: after step t of T, the
    batch's ``take`` episodes count (t + 1) / T done (in whole episodes)."""

    def __init__(self, bar, steps: int):
        self.bar, self.steps, self.take, self.shown = bar, int(steps), 0, 0

    def start(self, take: int) -> None:
        self.take, self.shown = int(take), 0

    def step(self, t) -> None:
        done = self.take * (int(t) + 1) // self.steps
        if done > self.shown:
            self.bar.update(done - self.shown)
            self.shown = done

    def finish(self) -> None:
        self.step(self.steps - 1)
        self.take = self.shown = 0  # a late call of this batch moves nothing


def plan_line(plan, episodes: int, num_envs: int) -> str:
    """The first line of an evaluation: its cells, episodes, an estimate of its time on 2 CPU
    cores, and the quick form.

    Args:
      plan: sweep_plan's (source, perturbation, levels) list.
      episodes, num_envs: eval.episodes per cell and the batch size.
    """
    cells = sum(len(levels) for _, _, levels in plan)
    minutes = sum(len(lv) * episodes / 1000.0 * CPU_MIN_PER_1000[s] for s, _, lv in plan)
    compiles = sum(1 if p in TRACED_PERTURBATIONS or p == "none" else len(lv) for _, p, lv in plan)
    what = "; ".join(
        f"{s} {p} {', '.join(f'{x:g}' for x in lv)}" if len(plan) <= 3 else f"{s} {p}"
        for s, p, lv in plan
    )
    perts = {p for _, p, _ in plan}
    quick = "--episodes 100"
    if len(perts) > 1:
        quick += " --perturbation none"
    elif perts != {"none"}:  # one sweep per source: its first level
        quick += f" --perturbation {plan[0][1]} --levels {plan[0][2][0]:g}"
    return (
        f"[evaluate] {cells} cell(s) x {episodes} episodes = {cells * episodes} ({what}; "
        f"batches of {min(num_envs, episodes)}): ~{minutes + compiles * COMPILE_MIN:.0f} min on "
        f"2 CPU cores with {compiles} compile(s). Quick look: {quick}"
    )


def sweep_plan(
    eval_cfg: ml_collections.ConfigDict, sources, perturbation: str | None, levels=None
) -> list[tuple[str, str, tuple[float, ...]]]:
    """The sweeps to run: (source, perturbation, levels), validated, before anything compiles.

    Args:
      eval_cfg: c.eval (the default levels of each sweep).
      sources: sources to run (foottof.perception.check_source of the --source flag).
      perturbation: one of PERTURBATIONS; 'all' (every sweep with its c.eval levels); None
        (each source's HEADLINE_SWEEPS sweep).
      levels: the --levels flag (None or empty: the c.eval levels).
    """
    if perturbation == "all" and levels:
        raise ValueError(
            "--levels cannot be given with --perturbation all (each sweep uses its c.eval levels)"
        )
    if perturbation == "none" and levels:
        raise ValueError(f"--levels {levels} given with --perturbation none")
    if perturbation is None and levels and len({HEADLINE_SWEEPS[s] for s in sources}) > 1:
        raise ValueError(
            f"--levels {levels} needs --perturbation here: the default sweeps of "
            f"{list(sources)} differ ({HEADLINE_SWEEPS})"
        )
    plan = []
    for s in sources:
        if perturbation is None:
            perts = (HEADLINE_SWEEPS[s],)
        else:
            perts = PERTURBATIONS[1:] if perturbation == "all" else (perturbation,)
        for p in perts:
            given = levels or (default_levels(eval_cfg, p) if p in PERTURBATIONS else ())
            plan.append((s, p, check_levels(p, given)))
    return plan


def run_sweeps(
    cfg,
    plan,
    checkpoint: str | None,
    key: jax.Array,
    progress=None,
    return_outcomes=False,
    cells=None,
):
    """Result rows of every sweep of ``plan`` (sweep_plan), all with the same ``key``: every
    cell sees the same map and draws. ``return_outcomes``: (rows, per-episode outcomes per row),
    as evaluate_sweep; ``cells``: a CellStore (evaluate_sweep)."""
    rows, outcomes = [], []
    for source, perturbation, levels in plan:
        if progress is not None:
            progress.set_postfix(source=source, perturbation=perturbation)
        r, o = evaluate_sweep(
            cfg, source, perturbation, levels, checkpoint, key, progress, True, cells
        )
        rows += r
        outcomes += o
    return (rows, outcomes) if return_outcomes else rows
