"""One writer per output folder: an exclusive lock held for as long as a command writes there.

The lock is ``fcntl.flock(LOCK_EX | LOCK_NB)`` on the file ``.lock`` in the folder.  The
kernel releases a flock when the last descriptor of its open file closes, which happens
when the process ends however it ends (kill -9 included): a lock left by a dead writer is
no lock, and the next writer takes it without any guess about process ids.  The file also
holds the holder's identity as one JSON line (pid, host, command, since), written after the
lock was taken, so a refused writer can name who holds it.

The file is never removed (removing it while another process has opened it but not yet
locked it would let two writers lock two different files); releasing empties it and unlocks.
flock is advisory and, on NFS, emulated by the server: every writer of this project takes
it, nothing else is stopped by it.

Linux and macOS (``fcntl``); opened with ``O_NOFOLLOW``: a symbolic link named ``.lock`` is
refused, never followed.
"""
from __future__ import annotations

import errno
import json
import os
import socket
import sys
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

__all__ = ["LOCK_NAME", "FolderLock", "FolderLocked", "LockHolder", "read_holder"]

#: The lock file's name inside the folder it guards.
LOCK_NAME = ".lock"


@dataclass(frozen=True)
class LockHolder:
    """Who holds (or last held) a folder's lock; fields None when the file does not say."""

    pid: int | None
    host: str | None
    command: str | None
    since: str | None     # ISO 8601 UTC

    def describe(self) -> str:
        """'fourbar-run (pid 123 on host h, since 2026-...)'."""
        who = self.command or "another process"
        where = [f"pid {self.pid}" if self.pid is not None else "pid unknown"]
        if self.host:
            where.append(f"on host {self.host}")
        if self.since:
            where.append(f"since {self.since}")
        return f"{who} ({', '.join(where)})"


class FolderLocked(OSError):
    """Another live process holds the folder's lock (``holder`` says who), or the lock file
    cannot be opened (a symbolic link, no permission)."""

    def __init__(self, folder: Path, message: str, holder: LockHolder | None = None):
        super().__init__(errno.EBUSY if holder is not None else errno.EACCES, message)
        self.folder = folder
        self.holder = holder
        self.message = message

    def __str__(self) -> str:
        return self.message


def read_holder(text: str) -> LockHolder:
    """The holder recorded in a lock file's text (tolerates anything: an old sweep lock holds a bare pid)."""
    pid = host = command = since = None
    try:
        data = json.loads(text) if text.strip() else {}
    except ValueError:
        data = {}
    if isinstance(data, int) and not isinstance(data, bool):
        pid = data
    elif isinstance(data, dict):
        raw_pid = data.get("pid")
        pid = raw_pid if isinstance(raw_pid, int) and not isinstance(raw_pid, bool) else None
        host, command, since = (data.get(k) if isinstance(data.get(k), str) else None
                                for k in ("host", "command", "since"))
    return LockHolder(pid=pid, host=host, command=command, since=since)


class FolderLock:
    """Context manager: hold ``folder/.lock`` exclusively (the folder must exist).

    ``acquire()`` raises :class:`FolderLocked` naming the holder when another process holds
    it; nothing in the folder is changed then.  ``command`` names this writer in the file.
    """

    def __init__(self, folder: str | os.PathLike[str], command: str | None = None):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self.command = command or Path(sys.argv[0]).name or "python"
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> "FolderLock":
        import fcntl

        if self._fd is not None:
            return self
        flags = os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | getattr(os, "O_NOFOLLOW", 0)
        try:
            fd = os.open(self.path, flags, 0o644)
        except OSError as exc:
            reason = ("is a symbolic link; the lock file must be a plain file" if exc.errno == errno.ELOOP
                      else exc.strerror or str(exc))
            raise FolderLocked(self.folder, f"{self.path}: cannot open the folder's lock file: {reason}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            try:
                text = os.pread(fd, 4096, 0).decode("utf-8", "replace")
            except OSError:
                text = ""
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                holder = read_holder(text)
                raise FolderLocked(self.folder, f"{self.folder}: another writer holds this folder: "
                                                f"{holder.describe()}; wait for it to end, or choose another "
                                                f"output folder", holder) from None
            raise FolderLocked(self.folder, f"{self.path}: cannot lock: {exc.strerror or exc}") from None
        self._fd = fd
        record = {"pid": os.getpid(), "host": socket.gethostname(), "command": self.command,
                  "since": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        try:
            data = (json.dumps(record) + "\n").encode("utf-8")
            os.ftruncate(fd, 0)
            os.pwrite(fd, data, 0)
        except OSError:
            pass       # the lock holds without its description (a full disk): a refusal says "pid unknown"
        return self

    def release(self) -> None:
        import fcntl

        fd, self._fd = self._fd, None
        if fd is None:
            return
        try:
            os.ftruncate(fd, 0)
        except OSError:
            pass
        try:
            fcntl.flock(fd, fcntl.LOCK_UN)
        finally:
            os.close(fd)

    def __enter__(self) -> "FolderLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
