"""Several processes (hosts, or one per GPU) as one trainer: JAX's distributed runtime from env vars.

Which variables start it (read by `parse_env`, which imports no JAX):
- `JAX_COORDINATOR_ADDRESS` (host:port of process 0, the same on all processes),
  `JAX_NUM_PROCESSES` and `JAX_PROCESS_ID` (0..num-1, one per process): all three, or none;
- else a SLURM step of several tasks (`srun` with `SLURM_NTASKS` > 1): the process count and id are
  `SLURM_NTASKS` / `SLURM_PROCID`, and JAX derives the coordinator (the step's first node, a port
  from the job id; `JAX_COORDINATOR_ADDRESS` / `JAX_COORDINATOR_PORT` override it) and gives each
  task the GPU `SLURM_LOCALID` (`JAX_LOCAL_DEVICE_IDS=0,1,..` to give it several).
A SLURM job of one task (`sbatch` / `salloc` shells) stays a single process with all its GPUs: JAX's
own detection would start the runtime there and keep one GPU only, so we do not call it.
`JAX_LOCAL_DEVICE_IDS` is read by JAX itself. Without these variables nothing changes.
`FOOTTOF_HEARTBEAT_TIMEOUT_S` (optional): after how many seconds of silence a process counts as
dead (HEARTBEAT_TIMEOUT_S).

When a process dies the others stop (`ProcessLost`, `lost_process_message`, `exit_at_once`): see
README_multihost.md, "When a process dies". From start-up on (`initialize`) each process also
watches the others' heartbeats of its own (`PeerWatch`): one silent for half the heartbeat
timeout, or a start-up that not all join within it, ends the others with one line and status
EXIT_PROCESS_LOST, before JAX's own abort (a stack dump) at the full timeout. When JAX's runtime
itself gives up (process 0, which holds the coordination service, is gone: JAX aborts the others
at once), `_on_runtime_error` says so in one line with the same status instead. A process that
stops on an error of its own (a full disk on the one that hit it) ends the others with it,
each in one line, none waiting for a barrier: `stop_run`.
"""

import ctypes
import os
import socket
import sys
import threading
import time
from collections.abc import Mapping
from typing import NamedTuple, NoReturn

JAX_VARS = ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID")
SLURM_VARS = (
    "SLURM_JOB_ID",
    "SLURM_STEP_NODELIST",
    "SLURM_NTASKS",
    "SLURM_PROCID",
    "SLURM_LOCALID",
)

# A process that stops sending heartbeats to the coordination service (on process 0) for this
# long counts as dead, and JAX then aborts every other process (JAX's default: 100 s). This bounds
# the wait where no collective notices the loss first: a host gone without closing its sockets, a
# process hung, or one waiting in a barrier instead of a collective. A killed process is noticed
# at once by the next collective (its sockets close): ProcessLost below. Override with the
# variable HEARTBEAT_VAR (seconds).
HEARTBEAT_TIMEOUT_S = 60
HEARTBEAT_VAR = "FOOTTOF_HEARTBEAT_TIMEOUT_S"
EXIT_PROCESS_LOST = 75  # exit status of a process that stopped because another died (EX_TEMPFAIL)


class Setup(NamedTuple):
    """What `jax.distributed.initialize` is called with."""

    coordinator_address: str | None  # host:port; None: JAX derives it (SLURM)
    num_processes: int
    process_id: int  # 0..num_processes-1
    source: str  # 'env' (JAX_* variables) or 'slurm'
    heartbeat_timeout_s: int = HEARTBEAT_TIMEOUT_S  # a process silent this long is dead


def _int(environ: Mapping[str, str], name: str) -> int:
    text = environ[name]
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"{name}={text!r} is not an integer") from None


def _slurm_tasks(environ: Mapping[str, str]) -> int:
    """SLURM_NTASKS of a SLURM step (0 outside one)."""
    if not all(environ.get(v) for v in SLURM_VARS):
        return 0
    return _int(environ, "SLURM_NTASKS")


def parse_env(environ: Mapping[str, str] | None = None) -> Setup | None:
    """The distributed setup the environment asks for, checked; None: one process (no runtime).

    Args:
      environ: the variables (default os.environ).

    Returns:
      Setup, or None when neither the JAX_* variables nor a SLURM step of several tasks are set.

    Raises:
      ValueError: one line naming the variables and values: some JAX_* variables set but not all
        (outside a SLURM step), a value that is not an integer, a process count < 1, a process
        id outside 0..count-1, an address without a numeric port, a heartbeat timeout < 1 s.
    """
    environ = os.environ if environ is None else environ
    given = {v: environ[v] for v in JAX_VARS if environ.get(v)}
    slurm_tasks = _slurm_tasks(environ)
    if slurm_tasks > 1:  # a SLURM step of several tasks; JAX_* variables override its values
        source = "slurm"
        num = _int(environ, "JAX_NUM_PROCESSES" if "JAX_NUM_PROCESSES" in given else "SLURM_NTASKS")
        pid = _int(environ, "JAX_PROCESS_ID" if "JAX_PROCESS_ID" in given else "SLURM_PROCID")
        names = (
            "JAX_NUM_PROCESSES" if "JAX_NUM_PROCESSES" in given else "SLURM_NTASKS",
            "JAX_PROCESS_ID" if "JAX_PROCESS_ID" in given else "SLURM_PROCID",
        )
    elif given:
        source = "env"
        if missing := [v for v in JAX_VARS if v not in given]:
            have = ", ".join(f"{k}={v}" for k, v in given.items())
            raise ValueError(
                f"{', '.join(missing)} not set ({have}): set all of {', '.join(JAX_VARS)} to run "
                f"several processes, or none for one"
            )
        num, pid = _int(environ, "JAX_NUM_PROCESSES"), _int(environ, "JAX_PROCESS_ID")
        names = ("JAX_NUM_PROCESSES", "JAX_PROCESS_ID")
    else:
        return None
    if num < 1:
        raise ValueError(f"{names[0]}={num}: the process count must be >= 1")
    if not 0 <= pid < num:
        raise ValueError(
            f"{names[1]}={pid} is out of range for {names[0]}={num} (ids are 0..{num - 1})"
        )
    address = given.get("JAX_COORDINATOR_ADDRESS")
    if address is not None:
        host, _, port = address.rpartition(":")
        if not host or not port.isdigit():
            raise ValueError(
                f"JAX_COORDINATOR_ADDRESS={address!r} is not host:port (e.g. host0:1234, the "
                f"address of process 0)"
            )
    heartbeat_s = _int(environ, HEARTBEAT_VAR) if environ.get(HEARTBEAT_VAR) else None
    if heartbeat_s is not None and heartbeat_s < 1:
        raise ValueError(f"{HEARTBEAT_VAR}={heartbeat_s}: the heartbeat timeout must be >= 1 s")
    return Setup(address, num, pid, source, heartbeat_s or HEARTBEAT_TIMEOUT_S)


def initialize(environ: Mapping[str, str] | None = None) -> Setup | None:
    """Starts JAX's distributed runtime if the environment asks for it (see `parse_env`).

    Call it before any other JAX call (it must come before the backend starts). CPU processes
    talk through gloo collectives. Blocks until all processes have joined, at most
    Setup.heartbeat_timeout_s; then starts this process's `PeerWatch`.

    Returns:
      The Setup, or None for a single process (nothing was started).

    Raises:
      ValueError: a bad setup, one line (`parse_env`), or JAX's process count differs from it.
      ProcessLost: not every process joined within the heartbeat timeout (one line; end the
        process with `exit_at_once`).
    """
    setup = parse_env(environ)
    if setup is None:
        return None
    import jax

    if jax.config.jax_cpu_collectives_implementation in (None, "none"):  # older JAX: none
        jax.config.update("jax_cpu_collectives_implementation", "gloo")

    def lost(cause: str) -> str:
        return (
            f"[distributed] not all {setup.num_processes} processes joined within "
            f"{setup.heartbeat_timeout_s} s at start-up ({cause}); process {setup.process_id} "
            f"stops. Start all {setup.num_processes} again ({HEARTBEAT_VAR} sets this wait)"
        )

    # JAX's own start-up timeout ends in its abort (a stack dump): this timer comes first.
    joined = threading.Event()
    timer = threading.Thread(
        target=lambda: (
            joined.wait(setup.heartbeat_timeout_s)
            or exit_at_once(lost("no answer from all of them"))
        ),
        daemon=True,
    )
    timer.start()
    if setup.num_processes > 1:
        _catch_runtime_errors(setup)
    try:
        jax.distributed.initialize(
            coordinator_address=setup.coordinator_address,
            num_processes=setup.num_processes,
            process_id=setup.process_id,
            initialization_timeout=2 * setup.heartbeat_timeout_s,
            heartbeat_timeout_seconds=setup.heartbeat_timeout_s,
        )
    except Exception as e:  # JaxRuntimeError: DEADLINE_EXCEEDED, UNAVAILABLE, ...
        raise ProcessLost(lost(_first_line(e))) from None
    finally:
        joined.set()
        _client_callback(None)
    if jax.process_count() != setup.num_processes:
        raise ValueError(
            f"jax.process_count()={jax.process_count()} after initialize, but the setup "
            f"({setup.source}) asked for {setup.num_processes} processes"
        )
    if setup.num_processes > 1:
        from jax._src import distributed as jax_distributed  # the runtime's key-value client

        global _WATCH
        _WATCH = PeerWatch(
            jax_distributed.global_state.client,
            setup.process_id,
            setup.num_processes,
            setup.heartbeat_timeout_s / 2,
        )
        _WATCH.start()
    return setup


# ------------------------------------------------- when JAX's runtime gives up (the coordinator)
# JAX ends every process whose coordination client polls an error from the service (process 0
# gone: its sockets close, and the others' poll fails at once) with its own fatal log and a stack
# dump (SIGABRT). The client takes a callback for that error instead: `_on_runtime_error`. In
# jaxlib 0.10.2 the callback is never reached (its absl::Status argument has no Python type:
# std::bad_cast, so std::terminate), hence the terminate handler, which says the same line when
# the exception that ends the process is that std::bad_cast, and leaves any other to the C++
# runtime's own handler (a message, then abort).
_SETUP: Setup | None = None  # this process's setup, from _catch_runtime_errors on
_TERMINATE = ctypes.CFUNCTYPE(None)
_terminate_kept: list = []  # the installed handler and the one before it (kept alive)


def _client_callback(callback) -> None:
    """Makes jax.distributed.initialize create its client with `callback` as the runtime's error
    callback (None: as JAX does)."""
    from jax._src.lib import _jax

    real = getattr(_jax.get_distributed_runtime_client, "_foottof_real", None)
    if callback is None:
        if real is not None:
            _jax.get_distributed_runtime_client = real
        return
    real = real or _jax.get_distributed_runtime_client

    def client(*args, **kwargs):
        kwargs.setdefault("missed_heartbeat_callback", callback)
        return real(*args, **kwargs)

    client._foottof_real = real
    _jax.get_distributed_runtime_client = client


def _catch_runtime_errors(setup: Setup) -> None:
    """Puts `_on_runtime_error` before JAX's abort (see above); call it before initialize."""
    global _SETUP
    _SETUP = setup
    _client_callback(_on_runtime_error)
    if _terminate_kept:
        return
    try:
        libstdcxx = ctypes.CDLL("libstdc++.so.6")
        set_terminate = libstdcxx._ZSt13set_terminatePFvvE  # std::set_terminate
        current_type = libstdcxx.__cxa_current_exception_type
    except (OSError, AttributeError):  # another C++ runtime: JAX's abort stays
        return
    set_terminate.restype, set_terminate.argtypes = ctypes.c_void_p, [_TERMINATE]
    current_type.restype = ctypes.c_void_p

    def on_terminate() -> None:
        info = current_type()  # std::type_info*: [vtable, const char* name]; None: no exception
        name = info and ctypes.c_char_p.from_address(info + ctypes.sizeof(ctypes.c_void_p)).value
        if name and name.endswith(b"bad_cast"):
            _on_runtime_error(None)
        if previous:
            _TERMINATE(previous)()  # "terminate called after throwing ...", then abort

    handler = _TERMINATE(on_terminate)
    previous = set_terminate(handler)
    _terminate_kept.extend([handler, previous])


def _reachable(address: str | None, tries: int = 10, timeout_s: float = 1.0) -> bool:
    """Whether TCP connections to host:port open, `tries` times 0.2 s apart (a process that is
    being killed may accept one more)."""
    host, _, port = (address or "").rpartition(":")
    for _ in range(tries):
        try:
            with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s):
                pass
        except (OSError, ValueError):
            return False
        time.sleep(0.2)
    return True


def _on_runtime_error(status=None) -> None:
    """JAX's runtime gave up on this run: one line and EXIT_PROCESS_LOST (a process already
    stopping with a line of its own, `stop_run`, ends with that)."""
    if _STOPPING is not None:
        exit_at_once(*_STOPPING)
    setup = _SETUP
    n, me = (setup.num_processes, setup.process_id) if setup else ("all", "this")
    from jax._src import distributed as jax_distributed

    address = jax_distributed.global_state.coordinator_address
    if me != 0 and not _reachable(address):
        what = f"process 0 of {n} (the coordinator, {address}) is gone"
    else:
        what = "JAX's coordination service reported a lost process" + (
            f" ({_first_line(Exception(str(status)))})" if status is not None else ""
        )
    exit_at_once(_again(f"[distributed] {what}; process {me} stops", n))


def _again(line: str, n) -> str:
    """`line` and how to go on."""
    return (
        f"{line}. Start all {n} again as before, with --resume where the run has a complete "
        f"checkpoint"
    )


def _first_line(error: BaseException, limit: int = 200) -> str:
    cause = (str(error).strip().splitlines() or [type(error).__name__])[0]
    return cause if len(cause) <= limit else cause[: limit - 3] + "..."


BEAT_PREFIX = "foottof/beat/"  # key-value keys of PeerWatch: BEAT_PREFIX + process id
BEAT_DONE = "done"  # the beat of a process that ended normally: no longer watched
BEAT_STOP = "stop:"  # the beat of a process that stops the run: BEAT_STOP + its line (stop_run)
_WATCH: "PeerWatch | None" = None  # this process's watch (initialize, several processes)
_STOPPING: tuple[str, int] | None = None  # (line, status) of this process once it stops the run


class PeerWatch(threading.Thread):
    """Heartbeats of our own through the runtime's key-value store, from start-up to exit.

    Every `silence_s / 10` s this process bumps its counter under BEAT_PREFIX + id and reads the
    others'. A counter that has not moved for `silence_s` (half JAX's heartbeat timeout, so
    this comes first), or a store that stops answering (process 0, its host, is gone), ends the
    process with one line and EXIT_PROCESS_LOST: during start-up, the first compile, a restore,
    a checkpoint's barriers or the training loop alike (a killed process is usually noticed
    sooner there, by the next collective: ProcessLost). At a normal exit the beat becomes
    BEAT_DONE (an atexit hook, run before JAX's shutdown), so the others stop watching it. A
    beat BEAT_STOP + line (a process that stopped the run, `stop_run`) ends this process too,
    with one line that quotes it.
    """

    def __init__(self, client, process_id: int, num_processes: int, silence_s: float):
        super().__init__(name="foottof-peer-watch", daemon=True)
        self.client, self.me, self.n = client, process_id, num_processes
        self.silence_s = float(silence_s)
        self._stop = threading.Event()
        self._decided = threading.Lock()  # held by the first of stop_run / a peer's stop

    def _lost(self, what: str) -> None:
        if not self._stop.is_set():
            exit_at_once(_again(f"[distributed] {what}; process {self.me} stops", self.n))

    def _beat(self, value: str) -> dict[str, str]:
        """Sets this process's beat; returns every process's {id: beat}."""
        self.client.key_value_set(f"{BEAT_PREFIX}{self.me}", value, True)
        return {k.rsplit("/", 1)[-1]: v for k, v in self.client.key_value_dir_get(BEAT_PREFIX)}

    def run(self) -> None:
        seen = {p: (None, time.monotonic()) for p in range(self.n) if p != self.me}
        beat = 0
        while not self._stop.wait(self.silence_s / 10):
            try:
                values = self._beat(str(beat))
            except Exception as e:
                self._lost(f"process 0 of {self.n} (the coordinator) stopped answering "
                           f"({_first_line(e)})")  # fmt: skip
                return
            beat += 1
            now = time.monotonic()
            for p, (value, since) in list(seen.items()):
                new = values.get(str(p))
                if new is not None and new.startswith(BEAT_STOP):
                    why = f"process {p} of {self.n} did: {new[len(BEAT_STOP) :]}"
                    self.stop_run(
                        f"[distributed] process {self.me} stops because {why}", EXIT_PROCESS_LOST
                    )
                elif new == BEAT_DONE:
                    del seen[p]
                elif new != value:
                    seen[p] = (new, now)
                elif now - since > self.silence_s:
                    self._lost(
                        f"process {p} of {self.n} sent no heartbeat for {self.silence_s:g} s "
                        f"(killed, hung or its host gone)"
                    )
                    return

    def stop_run(self, message: str, status: int) -> NoReturn:
        """Ends this process with `message`, once the others have read it (see stop_run)."""
        global _STOPPING
        if not self._decided.acquire(blocking=False):  # the other thread ends the process
            threading.Event().wait()
        _STOPPING = (message, status)  # also the line if JAX's runtime gives up meanwhile
        self._stop.set()
        deadline = time.monotonic() + self.silence_s
        others = [str(p) for p in range(self.n) if p != self.me]
        while time.monotonic() < deadline:
            try:
                values = self._beat(BEAT_STOP + message)
            except Exception:  # the store is gone with process 0: no one is left to tell
                break
            if all(values.get(p, "").startswith(BEAT_STOP) or values.get(p) == BEAT_DONE
                   for p in others):  # fmt: skip
                break
            time.sleep(min(0.1, self.silence_s / 10))
        exit_at_once(message, status)

    def start(self) -> None:
        import atexit

        super().start()
        atexit.register(self.stop)

    def stop(self) -> None:
        """Ends the watch and tells the others this process ended normally."""
        if self._stop.is_set():
            return
        self._stop.set()
        try:
            self.client.key_value_set(f"{BEAT_PREFIX}{self.me}", BEAT_DONE, True)
        except Exception:  # the runtime is gone already: nothing to tell
            pass


def stop_run(message: str) -> NoReturn:
    """Ends this process on an error of its own (`message`: one line on stderr, status 1), and
    with it the run: in a run of several processes each other one stops with one line that
    quotes `message` and EXIT_PROCESS_LOST, wherever it waits (a collective, one of orbax's
    barriers). Its beat says so (BEAT_STOP); this process ends at once (`exit_at_once`, no
    barrier of JAX's shutdown) when every other process has read it, or after half the
    heartbeat timeout. One process: sys.exit(message).
    """
    if _WATCH is None:
        sys.exit(message)
    _WATCH.stop_run(message, 1)


def check_num_envs(
    num_envs: int, num_minibatches: int, num_devices: int, num_processes: int = 1
) -> None:
    """The envs split into whole minibatches on every device of every process.

    Raises:
      ValueError: one line naming ppo.num_envs, ppo.num_minibatches and the device count.
    """
    where = f"{num_devices} device(s)"
    if num_processes > 1:
        where += f" over {num_processes} processes"
    if num_envs % (num_devices * num_minibatches):
        raise ValueError(
            f"ppo.num_envs={num_envs} is not divisible by ppo.num_minibatches * devices = "
            f"{num_minibatches} * {num_devices} ({where}); each device steps num_envs / devices "
            f"envs in whole minibatches"
        )


class ProcessLost(RuntimeError):
    """Another process of the run died or stopped answering; the message is one line that says
    how to resume (`lost_process_message`)."""


# What the runtime's errors say when another process is gone: gloo (CPU collectives: 'Gloo
# all-reduce failed: ... Read error [127.0.0.1]:63642: Connection reset by peer'), NCCL (GPU
# collectives), the coordination service (a missed heartbeat, a failed barrier).
_LOST_SIGNS = (
    "gloo",
    "nccl",
    "connection reset",
    "connection closed",
    "broken pipe",
    "socket closed",
    "heartbeat",
    "barrier",
    "unavailable:",
)


def is_lost_process(error: BaseException) -> bool:
    """Whether a JAX runtime error of a multi-process run says another process is gone (a
    collective or the coordination service failed), rather than a fault of this process."""
    text = str(error).lower()
    return any(sign in text for sign in _LOST_SIGNS)


def lost_process_message(
    error: BaseException,
    process_id: int,
    num_processes: int,
    iteration: int,
    run_dir: str,
    checkpoint: int | None,
) -> str:
    """One line: which process stopped, where, what the runtime said, and how to resume.

    Args:
      error: the runtime error that noticed it (its first line is quoted).
      process_id, num_processes: this process and the run's count.
      iteration: the last iteration this process finished (None: before the training loop).
      run_dir: the run folder (`--run_dir`).
      checkpoint: the newest complete checkpoint in it (None: none).
    """
    if num_processes == 2:
        other = f"process {1 - process_id} of 2"
    else:
        other = f"another of the {num_processes} processes"
    cause = _first_line(error)
    if checkpoint is None:
        then = "No checkpoint is complete: start all of them again without --resume"
    else:
        then = (
            f"Resume: start all {num_processes} again with --resume --run_dir {run_dir}; they "
            f"continue from iteration {checkpoint}, the last complete checkpoint"
        )
    return (
        f"[distributed] {other} stopped responding "
        + ("before the training loop" if iteration is None else f"after iteration {iteration}")
        + f" ({cause}); "
        f"process {process_id} stops. {then}"
    )


def exit_at_once(message: str, status: int = EXIT_PROCESS_LOST) -> NoReturn:
    """Prints `message` to stderr and ends this process now (os._exit).

    A normal exit would run JAX's shutdown, which waits at a barrier for every process, the dead
    one too, until the heartbeat timeout, and then aborts with a page of C++ log; orbax's and
    TensorBoard's exit handlers have nothing left to write (checkpoints are synchronous).
    """
    if not _EXITING.acquire(blocking=False):  # another thread is ending the process
        threading.Event().wait()
    sys.stdout.flush()
    sys.stderr.write(message + "\n")
    sys.stderr.flush()
    os._exit(status)


_EXITING = threading.Lock()  # taken by the one exit_at_once that ends the process


def local_cpu_environ(devices: int = 1, **extra: str) -> dict:
    """os.environ for a child process on ``devices`` fake CPU devices, without the distributed
    variables (``extra`` adds some back: the localhost runs of the tests and bench/)."""
    env = {k: v for k, v in os.environ.items() if k not in JAX_VARS and not k.startswith("SLURM_")}
    env["JAX_PLATFORMS"] = "cpu"
    flags = env.get("XLA_FLAGS", "")
    env["XLA_FLAGS"] = f"{flags} --xla_force_host_platform_device_count={devices}".strip()
    env.update(extra)
    return env


def free_local_port() -> int:
    """A TCP port free on localhost now (for a coordinator address of a local run)."""
    with socket.socket() as s:
        s.bind(("localhost", 0))
        return s.getsockname()[1]
