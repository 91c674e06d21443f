"""Files written whole or not at all, a full disk named in one line, one writer per folder.

- ``write_atomic``: each file to a temporary name of its own in the same folder (two writers
  never share one), flushed to disk, then renamed over the target; on any error the temporaries
  are removed and the targets keep their old contents.
- ``append_whole``: appends text to a file (metrics.csv rows) or, on an error such as a full
  disk, cuts the file back to its length before (no torn row).
- ``is_disk_full`` / ``DiskFull`` / ``disk_full_message``: ENOSPC (or a quota) anywhere in an
  error's chain, as Python (OSError errno 28) or TensorStore (orbax: 'RESOURCE_EXHAUSTED: ...
  No space left on device [os_error_code='28']') reports it.
- ``FolderLock``: an exclusive ``fcntl.flock`` on ``<folder>/.foottof.lock`` holding the writer's
  pid. The kernel drops the lock when its process ends, however it ends (kill -9 included), so a
  lock left by a dead process is taken over by the next writer; a live one refuses in one line
  naming the holder's pid (``FolderLocked``).

Imports no JAX.
"""

import errno
import fcntl
import os
import shutil
import socket
import tempfile

LOCK_FILE = ".foottof.lock"  # in a locked folder: the pid, host and command of its writer
_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
_FULL_TEXT = ("no space left on device", "disk quota exceeded", "os_error_code='28'")


def write_atomic(files: dict[str, bytes]) -> None:
    """Writes every {path: bytes} to a temporary file next to it, then renames all (no partial
    outputs; concurrent writers of one path each rename a whole file, the last one wins).

    Raises:
      OSError: a write failed (e.g. a full disk); no target was changed, no temporary is left.
    """
    tmps = []
    try:
        for path, data in files.items():
            folder = os.path.dirname(os.path.abspath(path))
            os.makedirs(folder, exist_ok=True)
            fd, tmp = tempfile.mkstemp(
                prefix=os.path.basename(path) + ".", suffix=".tmp", dir=folder
            )
            tmps.append((tmp, path))
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, 0o644)  # mkstemp makes 0o600
    except BaseException:
        for tmp, _ in tmps:
            if os.path.exists(tmp):
                os.remove(tmp)
        raise
    for tmp, path in tmps:
        os.replace(tmp, path)


def append_whole(path: str, text: str) -> None:
    """Appends ``text`` to ``path`` (created if missing), all of it or none.

    Raises:
      OSError: the write failed; the file was cut back to its length before the call.
    """
    data = text.encode()
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        start = os.fstat(fd).st_size
        try:
            done = 0
            while done < len(data):  # a write may stop part-way (a full disk): go on or fail
                done += os.write(fd, data[done:])
        except BaseException:
            os.ftruncate(fd, start)
            raise
    finally:
        os.close(fd)


def is_disk_full(error: BaseException) -> bool:
    """Whether ``error`` (or an error in its cause/context chain) says the disk or quota is full."""
    seen = set()
    e = error
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        if isinstance(e, OSError) and e.errno in _FULL_ERRNOS:
            return True
        if any(s in str(e).lower() for s in _FULL_TEXT):
            return True
        e = e.__cause__ or e.__context__
    return False


class DiskFull(OSError):
    """The disk of a run or output folder filled; the message is one line (disk_full_message)."""


def _mb(n: float) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 1e5 else f"{n / 1e3:.0f} kB"


def free_bytes(folder: str) -> int:
    """Bytes free to this user in the file system of ``folder`` (or its nearest parent)."""
    path = os.path.abspath(folder)
    while not os.path.exists(path):
        path = os.path.dirname(path)
    return shutil.disk_usage(path).free


def disk_full_message(folder: str, doing: str, needed_bytes: int, then: str) -> str:
    """One line: the disk of ``folder`` filled while ``doing``, how much is needed and free, and
    ``then`` (what was kept and how to continue)."""
    return (
        f"disk full in {folder} while {doing}: it needs about {_mb(needed_bytes)} free, "
        f"{_mb(free_bytes(folder))} is; {then}"
    )


class FolderLocked(RuntimeError):
    """Another live process writes the folder; the message is one line naming its pid."""


def _read_holder(path: str) -> dict:
    try:
        with open(path) as f:
            fields = dict(line.split("=", 1) for line in f.read().splitlines() if "=" in line)
    except OSError:
        return {}
    return fields


_HELD: dict[str, list] = {}  # real path of a locked folder -> [fd, depth] held by this process


class FolderLock:
    """One writer per folder, for as long as this object is open (a context manager); this
    process may take it again while it holds it (train.py first, then runner.run).

    Args:
      folder: the folder (created if missing).
      what: how errors name the folder's user, e.g. "train.py" or "evaluate.py --out".

    Raises (on enter / acquire):
      FolderLocked: a live process holds it (one line: folder, pid, host, command).
    """

    def __init__(self, folder: str, what: str):
        self.folder, self.what = folder, what
        self.path = os.path.join(folder, LOCK_FILE)
        self._key = None
        self.took_over_pid = None  # pid in a lock file whose process was killed (lock gone)

    def acquire(self) -> "FolderLock":
        os.makedirs(self.folder, exist_ok=True)
        key = os.path.realpath(self.path)
        if key in _HELD:
            _HELD[key][1] += 1
            self._key = key
            return self
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            holder = _read_holder(self.path)
            raise FolderLocked(
                f"{self.folder} is being written by pid {holder.get('pid', '?')} on "
                f"{holder.get('host', '?')} ({holder.get('command', '?')}); {self.what} refuses a "
                f"second writer: wait for it to end, or stop it first"
            ) from None
        old = _read_holder(self.path).get("pid")
        if old and old.isdigit() and int(old) != os.getpid():
            self.took_over_pid = int(old)
        record = f"pid={os.getpid()}\nhost={socket.gethostname()}\ncommand={self.what}\n"
        os.ftruncate(fd, 0)
        os.pwrite(fd, record.encode(), 0)
        _HELD[key], self._key = [fd, 1], key
        return self

    def release(self) -> None:
        """Lets go (the outermost release of this process empties the file and drops the
        lock: a file that still names a pid was left by a process that did not end normally)."""
        if self._key is None:
            return
        held = _HELD[self._key]
        held[1] -= 1
        if held[1] == 0:
            os.ftruncate(held[0], 0)
            os.close(held[0])
            del _HELD[self._key]
        self._key = None

    def __enter__(self) -> "FolderLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
