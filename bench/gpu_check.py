"""The GPU check: install, MJX throughput at 1024 / 4096 / 8192 envs, the teacher trained 3 minutes.

    python3 bench/gpu_check.py                 # on the GPU machine, from the repo root (<= 8 min)
    python3 bench/gpu_check.py --dry_run       # the same stages on the CPU at 32 envs (fast suite)

Stages, each a subprocess with a time budget (seconds; killed at it, the next stage goes on):
  install      45   the stages' Python: .venv/bin/python or this one if either imports foottof and
                    its packages; else a .venv (with this Python's site packages, e.g. a CUDA JAX)
                    and `pip install --no-index --find-links wheels foottof` from `make wheels`
                    (online `pip install -e .` where there is no wheels/)
  envs 4096   100   --config at that many envs: its reset, env step (zero actions) and training
  teacher     215   iteration compiled side by side, then 20 env steps and 3 iterations timed;
  envs 1024    60   env-steps/s and the device's peak memory (jax memory_stats, GPUs only)
  envs 8192    60   teacher: train.py's path (runner.run) on --config from its train.init_from
                    for --train_s (180) after the first iteration, then a Ctrl-C (the runner saves
                    a checkpoint); stopped early, with that checkpoint, when the budget runs out
Everything runs on MJX (env.physics=mjx; on the CPU too, where MuJoCo C programs, holding host
callbacks, could not be cached), one XLA cache per check: the teacher reuses what "envs 4096"
compiled. Writes to --out ($OUT, else the run folder): gpu_check.txt (the table),
gpu_check.json, gpu_check.log (every stage's output), teacher_metrics.csv and
teacher_checkpoint.tar.gz (the teacher's run config and last checkpoint, without env state).
Prints the table; exits 1 naming each step that failed. --dry_run: JAX on the CPU, 32 envs, 2 env
steps, 1 iteration, the teacher stopped after its first iteration (whatever --train_s says).
bench/NOTES.md ("The GPU check"); README "On a GPU".
"""

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tarfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
IMPORTS = "import foottof, jax, mujoco.mjx, brax, flax, optax, orbax.checkpoint, ml_collections"
GPU_SIZES = (4096, 1024, 8192)  # run order: 4096 first, so the teacher finds its programs cached
GPU_BUDGET_S = {"install": 45, 1024: 60, 4096: 100, 8192: 60}
TEACHER_OVERHEAD_S = 35  # teacher budget = --train_s + this (start, cached compiles, saving)
SAVE_MARGIN_S = 15  # the teacher stops training this long before its budget ends
DRY_ENVS = 32
DRY_BUDGET_S = 900  # per stage on a loaded 2-core CPU (a hang guard, not a target)
MAX_OUT_FILE_BYTES = 16 * 2**20  # what one file in $OUT may hold to come back from a lease


# ---------------------------------------------------------------------------------------------
# Stages (run in a subprocess: `gpu_check.py --stage ...`); they import JAX, the orchestrator not.


def _stage_config(path: str, num_envs: int):
    from configs import load_config
    from foottof import config_check

    cfg = load_config(os.path.join(ROOT, path) if not os.path.isabs(path) else path)
    cfg.ppo.num_envs = num_envs
    cfg.env.physics = "mjx"  # the GPU's physics, on the CPU too (the dry run)
    config_check.check_config(cfg)
    return cfg


def _setup_jax(cache_dir: str, dry_run: bool):
    import jax

    jax.config.update("jax_compilation_cache_dir", cache_dir)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    backend = jax.default_backend()
    if not dry_run and backend != "gpu":
        raise RuntimeError(
            f"JAX runs on {backend}, not a GPU: install JAX's CUDA wheels "
            f"(pip install 'jax[cuda12]', or make wheels WHEEL_EXTRA='jax[cuda12]')"
        )
    return jax


def _peak_gib(jax) -> float | None:
    """Peak device memory of this process so far [GiB]; None where JAX does not report it."""
    stats = jax.devices()[0].memory_stats() or {}
    peak = stats.get("peak_bytes_in_use")
    return None if peak is None else peak / 2**30


def _write(path: str, result: dict) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(result, f)
    os.replace(tmp, path)


def _compile_side_by_side(lowered: dict) -> tuple[dict, dict]:
    """Compiles each jax Lowered of ``lowered`` on its own thread (XLA releases the GIL):
    ({name: compiled}, {name: seconds its compile took})."""
    compiled, seconds, errors = {}, {}, {}

    def one(name):
        t0 = time.perf_counter()
        try:
            compiled[name] = lowered[name].compile()
        except Exception as e:  # re-raised below, on the main thread
            errors[name] = e
        seconds[name] = time.perf_counter() - t0

    threads = [threading.Thread(target=one, args=(n,)) for n in lowered]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for e in errors.values():
        raise e
    return compiled, seconds


def stage_envs(args) -> None:
    """Compiles and times the env step and one training iteration at ``args.envs`` envs."""
    sys.path.insert(0, os.path.join(ROOT, "bench"))
    jax = _setup_jax(args.cache_dir, args.dry_run)
    import jax.numpy as jp
    from bench_backends import time_iterations, time_steps

    from foottof.envs import make_training_env
    from foottof.ppo import train as train_lib

    n = args.envs
    result = {"device": jax.devices()[0].device_kind, "jax": jax.__version__, "rows": {}}
    cfg = _stage_config(args.config, n)
    t0 = time.perf_counter()
    env = make_training_env(cfg)
    trainer = train_lib.make_train(env, cfg)
    result["physics"] = type(env.physics).__name__
    key = jax.random.PRNGKey(int(cfg.seed))
    abstract = jax.eval_shape(trainer.init, key)
    env_sharding = trainer.state_sharding.env_state
    actions = jp.zeros((n, env.action_size), jp.float32)
    step = jax.jit(
        lambda s: env.step(s, actions), in_shardings=(env_sharding,), out_shardings=env_sharding
    )
    lowered = {
        "init": trainer.init.lower(key),
        "env step": step.lower(abstract.env_state),
        "train iteration": trainer.iteration.lower(abstract),
    }
    result["build_s"] = time.perf_counter() - t0
    print(f"[envs {n}] env and trainer built, traced in {result['build_s']:.1f} s", flush=True)
    compiled, compile_s = _compile_side_by_side(lowered)
    print(f"[envs {n}] compiled side by side: {compile_s}", flush=True)
    state = jax.block_until_ready(compiled["init"](key))

    env_state = jax.block_until_ready(compiled["env step"](state.env_state))  # warm-up
    _, step_s = time_steps(compiled["env step"], env_state, args.steps)
    del env_state
    result["rows"]["env step"] = {
        "compile_s": compile_s["env step"],
        "sps": n / step_s,
        "peak_gib": _peak_gib(jax),
    }
    _write(args.result, result)
    print(f"[envs {n}] env step: {n / step_s:,.0f} env-steps/s", flush=True)

    _, iteration_s = time_iterations(compiled["train iteration"], state, args.iterations)
    result["rows"]["train iteration"] = {
        "compile_s": compile_s["train iteration"],
        "sps": trainer.steps_per_iteration / iteration_s,
        "peak_gib": _peak_gib(jax),
        "init_compile_s": compile_s["init"],
    }
    _write(args.result, result)
    print(
        f"[envs {n}] training: {trainer.steps_per_iteration / iteration_s:,.0f} env-steps/s",
        flush=True,
    )


def stage_teacher(args) -> None:
    """Trains --config from its train.init_from for --train_s after the first iteration."""
    started = time.perf_counter()
    jax = _setup_jax(args.cache_dir, args.dry_run)
    from foottof.envs import make_training_env
    from foottof.ppo import runner

    cfg = _stage_config(args.config, args.envs)
    cfg.train.checkpoint_env_state = False  # params, optimizer, normalizer: a few MB to carry back
    cfg.train.tensorboard = False  # metrics.csv is what comes back
    env = make_training_env(cfg)
    first = []  # time of the first iteration's end

    def stop(it, metrics, state):
        now = time.perf_counter()
        first.append(first[0] if first else now)
        if args.dry_run or now - first[0] >= args.train_s or now - started >= args.stop_by_s:
            raise KeyboardInterrupt  # the runner saves this iteration, as on a Ctrl-C

    try:
        runner.run(cfg, env, args.run_dir, init_from=cfg.train.init_from or None, on_iteration=stop)
    except KeyboardInterrupt:
        pass
    trained_s = time.perf_counter() - first[0] if first else 0.0
    _write(
        args.result,
        {
            "device": jax.devices()[0].device_kind,
            "peak_gib": _peak_gib(jax),
            "after_first_s": trained_s,
        },
    )


# ---------------------------------------------------------------------------------------------
# The orchestrator: standard library only, so that it runs before anything is installed.


class _Stage:
    """One stage's subprocess: its output streamed to stdout and the log; killed at its budget."""

    def __init__(self, name: str, cmd: list[str], budget_s: float, log, env=None):
        self.name, self.budget_s = name, budget_s
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            cmd,
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
            start_new_session=True,  # its own process group: a timeout ends it and its children
        )
        self.tail: list[str] = []
        reader = threading.Thread(target=self._read, args=(proc, log), daemon=True)
        reader.start()
        try:
            proc.wait(timeout=budget_s)
            self.timed_out = False
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            self.timed_out = True
        reader.join(timeout=10)
        self.returncode = proc.returncode
        self.wall_s = time.perf_counter() - t0

    def _read(self, proc, log) -> None:
        for line in proc.stdout:
            line = line.rstrip("\n")
            print(f"  {self.name} | {line}", flush=True)
            log.write(f"{self.name} | {line}\n")
            self.tail = (self.tail + [line])[-20:]
        log.flush()

    def failure(self) -> str | None:
        """None if it ended well; else one line: the timeout, or its last error line."""
        if self.timed_out:
            return f"timed out after {self.budget_s:.0f} s"
        if self.returncode != 0:
            errors = [x for x in self.tail if "Error" in x or "error" in x] or self.tail or ["?"]
            return f"exit {self.returncode}: {errors[-1].strip()[:160]}"
        return None


def _imports_ok(python: str) -> bool:
    if not python or not os.path.exists(python):
        return False
    r = subprocess.run([python, "-c", IMPORTS], cwd=ROOT, capture_output=True)
    return r.returncode == 0


def _install_cmd(wheels: str) -> str:
    """The shell command that makes .venv (with this Python's site packages: a preinstalled CUDA
    JAX stays) and installs foottof: offline from ``wheels`` (README "Install") if it is a folder,
    else from the package index."""
    pip = ".venv/bin/python -m pip install --quiet"
    venv = f"{sys.executable} -m venv --system-site-packages .venv"
    if os.path.isdir(os.path.join(ROOT, wheels)):
        return f"{venv} && {pip} --no-index --find-links {wheels} foottof"
    return f"{venv} && {pip} -e ."


def _fmt(x, spec: str) -> str:
    return "-" if x is None else format(x, spec)


def _table(rows: list[dict]) -> str:
    head = f"{'step':<16} {'envs':>5} {'compile s':>9} {'env-steps/s':>12} {'peak GiB':>8} {'wall s':>7}  status"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['step']:<16} {_fmt(r.get('envs'), 'd'):>5} {_fmt(r.get('compile_s'), '.1f'):>9} "
            f"{_fmt(r.get('sps'), ',.0f'):>12} {_fmt(r.get('peak_gib'), '.2f'):>8} "
            f"{_fmt(r.get('wall_s'), '.1f'):>7}  {r['status']}"
        )
    return "\n".join(lines)


def _teacher_rows(run_dir: str, stage: _Stage, result: dict, args, out: str) -> dict:
    """The teacher's row from its metrics.csv; copies metrics.csv and a tarball of its config and
    last checkpoint to ``out``."""
    import csv
    import statistics

    row = {"step": "teacher", "envs": args.teacher_envs, "wall_s": stage.wall_s}
    metrics = os.path.join(run_dir, "metrics.csv")
    ckpts = os.path.join(run_dir, "checkpoints")
    steps = sorted(int(s) for s in os.listdir(ckpts) if s.isdigit()) if os.path.isdir(ckpts) else []
    if not os.path.exists(metrics) or not steps:
        row["status"] = "FAILED: " + (stage.failure() or "no metrics.csv or no checkpoint")
        return row
    with open(metrics, newline="") as f:
        rows = list(csv.DictReader(f))
    shutil.copyfile(metrics, os.path.join(out, "teacher_metrics.csv"))
    tarball = os.path.join(out, "teacher_checkpoint.tar.gz")
    with tarfile.open(tarball, "w:gz") as tar:
        tar.add(os.path.join(run_dir, "config.json"), arcname="teacher_gpu/config.json")
        tar.add(os.path.join(ckpts, str(steps[-1])), arcname=f"teacher_gpu/checkpoints/{steps[-1]}")
    train_s = sum(float(r["time/iteration_s"]) for r in rows)
    row.update(
        compile_s=float(rows[0]["time/compile_s"]),
        sps=statistics.median(float(r["training/sps"]) for r in rows[1:] or rows),
        peak_gib=result.get("peak_gib"),
    )
    env_steps = int(float(rows[-1]["env_steps"]))
    what = (
        f"{len(rows)} iterations, {env_steps:,} env steps, {train_s:.0f} s training, "
        f"checkpoint {steps[-1]}"
    )
    problem = stage.failure()
    if tarball and os.path.getsize(tarball) > MAX_OUT_FILE_BYTES:
        problem = f"teacher_checkpoint.tar.gz is {os.path.getsize(tarball) / 2**20:.0f} MiB"
    elif not args.dry_run and result.get("after_first_s", 0.0) < args.train_s:
        problem = f"trained {result.get('after_first_s', 0.0):.0f} s of {args.train_s:.0f} s"
    row["status"] = f"FAILED: {problem}; {what}" if problem else f"ok: {what}"
    return row


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--dry_run", action="store_true", help="JAX on the CPU, 32 envs, tiny counts")
    p.add_argument("--config", default="configs/teacher_gpu.py", help="the teacher's config")
    p.add_argument("--out", default=os.environ.get("OUT", ""), help="default: $OUT, else --work")
    p.add_argument("--work", default="", help="run folder (default runs/gpu_check-<time>)")
    p.add_argument("--train_s", type=float, default=180.0, help="teacher training [s]")
    p.add_argument("--wheels", default="wheels", help="`make wheels` folder for the install")
    # a stage (internal: the orchestrator starts them)
    p.add_argument("--stage", choices=("envs", "teacher"), help=argparse.SUPPRESS)
    p.add_argument("--envs", type=int, default=0, help=argparse.SUPPRESS)
    p.add_argument("--result", help=argparse.SUPPRESS)
    p.add_argument("--cache_dir", help=argparse.SUPPRESS)
    p.add_argument("--run_dir", help=argparse.SUPPRESS)
    p.add_argument("--steps", type=int, default=20, help=argparse.SUPPRESS)
    p.add_argument("--iterations", type=int, default=3, help=argparse.SUPPRESS)
    p.add_argument("--stop_by_s", type=float, default=0.0, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.stage:
        sys.path.insert(0, ROOT)
        (stage_envs if args.stage == "envs" else stage_teacher)(args)
        return 0
    return orchestrate(args)


def orchestrate(args) -> int:
    t_start = time.perf_counter()
    work = os.path.abspath(
        args.work or os.path.join(ROOT, "runs", time.strftime("gpu_check-%Y%m%d-%H%M%S"))
    )
    out = os.path.abspath(args.out or work)
    os.makedirs(work, exist_ok=True)
    os.makedirs(out, exist_ok=True)
    cache = os.path.join(work, "xla_cache")  # new per check: compile times are measured, not read
    sizes = (DRY_ENVS,) if args.dry_run else GPU_SIZES
    args.teacher_envs = DRY_ENVS if args.dry_run else 4096
    budget = lambda key: DRY_BUDGET_S if args.dry_run else GPU_BUDGET_S[key]
    teacher_budget = DRY_BUDGET_S if args.dry_run else args.train_s + TEACHER_OVERHEAD_S
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    if args.dry_run:
        env["JAX_PLATFORMS"] = "cpu"
    total = budget("install") + sum(budget(n) for n in sizes) + teacher_budget
    print(f"[gpu_check] {'dry run, CPU' if args.dry_run else 'GPU'}; budget {total:.0f} s; {out}")
    rows: list[dict] = []
    log = open(os.path.join(out, "gpu_check.log"), "w")

    # install
    python = next(
        (x for x in (os.path.join(ROOT, ".venv/bin/python"), sys.executable) if _imports_ok(x)),
        None,
    )
    if python:
        rows.append({"step": "install", "wall_s": 0.0, "status": f"ok: present ({python})"})
    else:
        s = _Stage(
            "install", ["bash", "-c", _install_cmd(args.wheels)], budget("install"), log, env
        )
        python = os.path.join(ROOT, ".venv/bin/python")
        problem = s.failure() or (None if _imports_ok(python) else f"{IMPORTS!r} fails after it")
        rows.append(
            {
                "step": "install",
                "wall_s": s.wall_s,
                "status": f"FAILED: {problem}" if problem else "ok: installed",
            }
        )
    meta = {}
    if rows[-1]["status"].startswith("ok"):
        common = ["--config", args.config, "--cache_dir", cache] + (
            ["--dry_run"] if args.dry_run else []
        )
        plan = [("envs", n) for n in sizes]
        plan.insert(1, ("teacher", args.teacher_envs))
        for kind, n in plan:
            result = os.path.join(work, f"{kind}_{n}.json")
            cmd = [
                python,
                os.path.abspath(__file__),
                "--stage",
                kind,
                "--envs",
                str(n),
                "--result",
                result,
                *common,
            ]
            if kind == "envs":
                counts = ["--steps", "2", "--iterations", "1"] if args.dry_run else []
                s = _Stage(f"envs {n}", cmd + counts, budget(n), log, env)
                got = json.load(open(result)) if os.path.exists(result) else {}
                meta.update({k: got[k] for k in ("device", "jax", "physics") if k in got})
                for step in ("env step", "train iteration"):
                    r = got.get("rows", {}).get(step)
                    row = {
                        "step": step,
                        "envs": n,
                        "wall_s": s.wall_s if step == "env step" else None,
                    }
                    if r:
                        row.update(
                            compile_s=r["compile_s"],
                            sps=r["sps"],
                            peak_gib=r["peak_gib"],
                            status="ok",
                        )
                    else:
                        row["status"] = "FAILED: " + (s.failure() or "no result")
                    rows.append(row)
            else:
                run_dir = os.path.join(work, "teacher_gpu")
                stop_by = teacher_budget - SAVE_MARGIN_S
                extra = [
                    "--run_dir",
                    run_dir,
                    "--train_s",
                    str(args.train_s),
                    "--stop_by_s",
                    str(stop_by),
                ]
                s = _Stage("teacher", cmd + extra, teacher_budget, log, env)
                got = json.load(open(result)) if os.path.exists(result) else {}
                rows.append(_teacher_rows(run_dir, s, got, args, out))
    log.close()
    wall = time.perf_counter() - t_start
    table = _table(rows)
    header = (
        f"gpu_check {'--dry_run ' if args.dry_run else ''}on {meta.get('device', '?')} "
        f"(JAX {meta.get('jax', '?')}, physics {meta.get('physics', '?')}), config {args.config}, "
        f"{wall:.0f} s of a {total:.0f} s budget"
    )
    print(f"\n{header}\n{table}")
    with open(os.path.join(out, "gpu_check.txt"), "w") as f:
        f.write(f"{header}\n{table}\n")
    with open(os.path.join(out, "gpu_check.json"), "w") as f:
        json.dump(
            {"header": header, "wall_s": wall, "budget_s": total, **meta, "rows": rows}, f, indent=1
        )
    failed = [
        f"{r['step']}" + (f" {r['envs']}" if r.get("envs") else "")
        for r in rows
        if not r["status"].startswith("ok")
    ]
    if failed:
        print(f"[gpu_check] FAILED: {', '.join(failed)}")
        return 1
    print("[gpu_check] all steps ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
