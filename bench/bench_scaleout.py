"""Training throughput of the scale-out paths side by side, in one run: 1 process x 1 device,
1 process x 2 devices (fake CPU devices) and 2 processes x 1 device (JAX's distributed runtime on
localhost, gloo collectives), each a fresh `train.py` run of the same config.

    python bench/bench_scaleout.py                        # configs/cpu.py, 20 iterations each
    python bench/bench_scaleout.py --config configs/smoke.py --iterations 10

On one machine the devices share its cores, so the 2-device rows measure the overhead of the
shard_map iteration and its collectives, not a speed-up. Reads `training/sps` (env steps/s of the
whole iteration: rollout + update) from each run's metrics.csv and reports the median over the
iterations after the first `--skip` (compile and warm-up). Run it on an idle machine.
"""

import argparse
import csv
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from foottof.ppo import distributed  # noqa: E402


def _run(name: str, cmd: list[str], processes: int, devices: int, run_dir: str) -> float:
    """Runs one setup to the end; its wall time [s]. Raises with the output of a failed process."""
    address = f"localhost:{distributed.free_local_port()}"
    procs = []
    t0 = time.perf_counter()
    for i in range(processes):
        extra = {}
        if processes > 1:
            extra = {
                "JAX_COORDINATOR_ADDRESS": address,
                "JAX_NUM_PROCESSES": str(processes),
                "JAX_PROCESS_ID": str(i),
            }
        procs.append(
            subprocess.Popen(
                [*cmd, "--run_dir", run_dir],
                cwd=ROOT,
                env=distributed.local_cpu_environ(devices, **extra),
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
        )
    outs = [p.communicate()[0] for p in procs]
    wall = time.perf_counter() - t0
    for p, out in zip(procs, outs, strict=True):
        if p.returncode != 0:
            raise RuntimeError(f"{name}: exit {p.returncode}\n{out[-3000:]}")
    return wall


def _sps(run_dir: str, skip: int) -> list[float]:
    with open(os.path.join(run_dir, "metrics.csv")) as f:
        rows = list(csv.DictReader(f))
    return [float(r["training/sps"]) for r in rows[skip:]]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/cpu.py")
    p.add_argument("--iterations", type=int, default=20)
    p.add_argument("--skip", type=int, default=2, help="first iterations left out (warm-up)")
    args = p.parse_args()
    if args.iterations <= args.skip:
        raise SystemExit(
            f"error: --iterations={args.iterations} must exceed --skip={args.skip} (valid: > skip)"
        )

    cmd = [
        sys.executable,
        "train.py",
        "--config",
        args.config,
        f"--config.train.num_iterations={args.iterations}",
        f"--config.train.checkpoint_every={args.iterations}",
    ]
    setups = [  # (name, processes, devices per process)
        ("1 process x 1 device", 1, 1),
        ("1 process x 2 devices", 1, 2),
        ("2 processes x 1 device", 2, 1),
    ]
    tmp = tempfile.mkdtemp(prefix="bench_scaleout_")
    rows = []
    try:
        for i, (name, processes, devices) in enumerate(setups):
            run_dir = os.path.join(tmp, f"run{i}")
            wall = _run(name, cmd, processes, devices, run_dir)
            sps = _sps(run_dir, args.skip)
            rows.append((name, statistics.median(sps), min(sps), max(sps), wall))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    base = rows[0][1]
    print(f"{args.config}, {args.iterations} iterations per setup (first {args.skip} left out)")
    print("| setup | env steps/s (median) | min-max | vs 1 device | wall incl. compile [s] |")
    print("|---|---|---|---|---|")
    for name, med, lo, hi, wall in rows:
        print(f"| {name} | {med:,.0f} | {lo:,.0f}-{hi:,.0f} | {med / base:.2f} | {wall:.0f} |")


if __name__ == "__main__":
    main()
